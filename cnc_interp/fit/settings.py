"""``FitSettings``: tolerances and corner threshold of the fit stage."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ..errors import UsageError

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    from ..machine.model import Machine


#: default maximum permissible error of the fit (mm) where neither the program (G64 P), the
#: machine (`tol`) nor `--tol` gives one: 10 µm, a contouring tolerance machinists set for
#: finishing (a CAM finishing path is itself typically within 10 µm, and parts held to
#: ±0.02 mm or coarser keep that budget); 1 µm doubles a router relief's cycle
DEFAULT_TOL_MM = 0.01

#: default tolerance for rotary axes (deg), the same figure in degrees
DEFAULT_TOL_DEG = 0.01

#: the finest tolerance a user may ask for other than 0 (the exact path), mm or deg: the
#: tolerance the fit gives exact curves (``FIT_EXACT_CURVE_TOL_MM``, 1 nm), a thousandth of
#: a fine machine's resolution. A finer one is no closer to the part, only past the fit's
#: float precision: ``--tol 1e-300`` sampled arcs into gigabytes of nodes, then divided by 0
FIT_TOL_MIN_MM = 1e-6

#: a turn sharper than this (deg) between consecutive moves splits the path; the planner stops there
DEFAULT_CORNER_DEG = 30.0

TOL_MODES = ("gcode", "stricter")
METHODS = ("nodes", "planar", "auto")


@dataclass(frozen=True)
class FitSettings:
    """How closely and how the fit follows the programmed nodes.

    Attributes:
        tol_mm: maximum permissible error for linear axes, mm, where the program gives
            none (plain ``G64``): ``--tol``, else the machine's ``tol``, else 0.001.
        tol_deg: maximum permissible error for rotary axes, deg.
        tol_cap_mm: the user's cap (``--tol``): no move gets a larger tolerance, whatever
            its ``G64 P`` says; ``None``: no cap. 0 makes every move exact (``G61``).
        corner_deg: the smooth fit rounds turns up to this within the tolerance; a
            sharper corner gets a blend (``blend_corners``) or splits the path there
            (the planner stops).
        tol_mode: how a block's ``G64 P`` combines with ``tol_mm``: ``"gcode"``
            (default) lets ``G64 P`` win, ``"stricter"`` takes the smaller one. The
            cap applies in both; ``G61`` (tolerance 0) always means exact path.
        blend_corners: a corner sharper than ``corner_deg`` is rounded by a G2 blend
            within the tolerance (``fit.blends``) rather than stopping the machine
            (N-axis fit only; the planar method and ``G61`` stop as in paper 000).
        quantum_mm / quantum_deg: the grid the program's coordinates are printed on
            (``fit.quantum``), set by ``fit_program``; half of it is added to every
            tolerance, since a printed point is only known to ±½ of its last digit.
        blend_rapids: a chain of G0 moves that turns by at most ``corner_deg`` under G64
            is fitted like a feed run, smooth through those turns within the tolerance,
            rather than stopping at every turn (sharper corners still stop). Only where
            rapids are straight lines in program space, as on a machine without
            kinematics: ``from_options`` sets it from the machine; off by default.
        period_step_mm: the smallest step of one sample period's acceleration and jerk
            limits over the machine's linear axes, min(amax·dt², jmax·dt³), mm
            (``from_options`` sets it from the machine): a corner whose moves leave a
            blend far less room than its tolerance would give it stops, unless the
            squeezed blend is no larger than this (``fit.blends``); 0: it stops.
        method: ``"nodes"`` (default: the N-axis fit everywhere), ``"planar"``
            (paper 000's planar fit for runs of lines that move exactly two axes, the
            N-axis fit otherwise; what the FPGA stage streams as segments) or
            ``"auto"`` (the same as ``"planar"``, its former name).
    """

    tol_mm: float = DEFAULT_TOL_MM
    tol_deg: float = DEFAULT_TOL_DEG
    corner_deg: float = DEFAULT_CORNER_DEG
    tol_mode: str = "gcode"
    method: str = "nodes"
    tol_cap_mm: float | None = None
    quantum_mm: float = 0.0
    quantum_deg: float = 0.0
    blend_corners: bool = True
    blend_rapids: bool = False
    period_step_mm: float = 0.0

    def __post_init__(self) -> None:
        from ..machine.model import TOL_MAX_MM

        for name in ("tol_mm", "tol_deg"):
            v = getattr(self, name)
            if not (_is_number(v) and math.isfinite(v) and 0 < v <= TOL_MAX_MM):
                raise UsageError(f"fit tolerance {name} must be a number from 0 to {TOL_MAX_MM:g}, got {v!r}")
            if v < FIT_TOL_MIN_MM:
                raise UsageError(
                    f"fit tolerance {name} = {v!r} is below {FIT_TOL_MIN_MM:g}, the finest the fit works to"
                )
        step = self.period_step_mm
        if not (_is_number(step) and math.isfinite(step) and step >= 0):
            raise UsageError(f"fit period step must be a number of mm from 0, got {step!r}")
        if not (0.0 <= self.corner_deg <= 180.0):
            raise UsageError(f"corner angle must be within [0, 180] deg, got {self.corner_deg!r}")
        cap = self.tol_cap_mm
        if cap is not None and not (_is_number(cap) and math.isfinite(cap) and 0 <= cap <= TOL_MAX_MM):
            raise UsageError(f"fit tolerance cap must be a number from 0 to {TOL_MAX_MM:g}, got {cap!r}")
        if cap is not None and 0 < cap < FIT_TOL_MIN_MM:
            raise UsageError(_below_min(cap))
        for name in ("quantum_mm", "quantum_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise UsageError(f"{name} must be a number >= 0, got {v!r}")
        if self.tol_mode not in TOL_MODES:
            raise UsageError(f"tol_mode must be one of {TOL_MODES}, got {self.tol_mode!r}")
        if self.method not in METHODS:
            raise UsageError(f"fit method must be one of {METHODS}, got {self.method!r}")

    @classmethod
    def from_options(
        cls,
        tol_mm: float | None = None,
        corner_deg: float | None = None,
        machine: Machine | None = None,
        method: str | None = None,
    ) -> FitSettings:
        """Settings from CLI options; the machine's ``tol_mm`` is used when ``--tol`` is absent,
        ``"nodes"`` when ``--fit-method`` is.

        ``--tol`` is both the tolerance of moves without ``G64 P`` and the user's cap on
        every move's (``tol_cap_mm``); a machine's ``tol`` is only the former.
        ``--tol 0`` asks for the exact path: it is kept as the smallest tolerance the
        fitter accepts for curves (``FIT_EXACT_CURVE_TOL_MM``); straight moves stop
        at every corner as under G61.
        """
        from ..constants import FIT_EXACT_CURVE_TOL_MM
        from ..machine.model import TOL_MAX_MM

        kw: dict[str, Any] = {}
        user_tol = tol_mm
        if user_tol is not None:  # the API's fit(tol_mm=-1) as --tol -1: refused, not "exact"
            if not (_is_number(user_tol) and 0 <= user_tol <= TOL_MAX_MM):
                raise UsageError(f"fit tolerance must be a number of mm from 0 to {TOL_MAX_MM:g}, got {user_tol!r}")
            if 0 < user_tol < FIT_TOL_MIN_MM:
                raise UsageError(_below_min(user_tol))
        if tol_mm is None and machine is not None and machine.tol_mm:
            tol_mm = float(machine.tol_mm)
        if user_tol is not None:
            kw["tol_cap_mm"] = max(float(user_tol), 0.0)
        if tol_mm is not None:
            kw["tol_mm"] = max(float(tol_mm), FIT_EXACT_CURVE_TOL_MM) if tol_mm > 0 else FIT_EXACT_CURVE_TOL_MM
            if tol_mm == 0:
                kw["corner_deg"] = 0.0
        if corner_deg is not None and "corner_deg" not in kw:
            kw["corner_deg"] = float(corner_deg)
        if method is not None:
            kw["method"] = method
        if machine is not None:
            from ..machine.kinematics import make_kinematics

            # rapids are straight in program space where joints are program axes
            kw["blend_rapids"] = make_kinematics(machine).is_identity
            kw["period_step_mm"] = _period_step_mm(machine)
        return cls(**kw)

    @property
    def fit_tol_mm(self) -> float:
        """The default tolerance the fit works to: ``tol_mm`` (capped) + ½ quantum."""
        t = self.tol_mm if self.tol_cap_mm is None else min(self.tol_mm, self.tol_cap_mm)
        return t + 0.5 * self.quantum_mm if t > 0 else self.tol_mm

    @property
    def fit_tol_deg(self) -> float:
        """The rotary tolerance the fit works to: ``tol_deg`` + ½ quantum."""
        return self.tol_deg + 0.5 * self.quantum_deg

    def node_tolerance(self, tol_block_mm: npt.ArrayLike) -> np.ndarray:
        """Per-move tolerance (mm) from the blocks' ``tol_mm`` (nan / 0 / G64 P) array:
        ``G64 P`` where given (``tol_mode``), else ``tol_mm``; at most the cap; 0 (exact
        path) under ``G61`` or a cap of 0; plus ½ quantum where it is not 0."""
        import numpy as np

        t = np.asarray(tol_block_mm, dtype=float)
        out = np.full(t.shape, self.tol_mm)
        p = np.isfinite(t) & (t > 0)
        if self.tol_mode == "stricter":
            out[p] = np.minimum(t[p], self.tol_mm)
        else:
            out[p] = t[p]
        if self.tol_cap_mm is not None:
            np.minimum(out, self.tol_cap_mm, out=out)
        # a G64 P finer than the finest tolerance works to it (P0.0000000000000001 made the
        # fit sample and refine for 23 GB); 0 stays the exact path
        np.maximum(out, FIT_TOL_MIN_MM, out=out, where=out > 0)
        out[np.isfinite(t) & (t == 0)] = 0.0
        if self.quantum_mm > 0:
            out[out > 0] += 0.5 * self.quantum_mm
        return out


def _period_step_mm(machine: Machine) -> float:
    """min(amax·dt², jmax·dt³) over the machine's linear axes, mm (0 without linear axes)."""
    import numpy as np

    from ..constants import LINEAR_AXES

    lin = [i for i, a in enumerate(machine.axes) if a in LINEAR_AXES]
    if not lin:
        return 0.0
    dt = float(machine.dt_s)
    amax, jmax = np.asarray(machine.amax, dtype=float)[lin], np.asarray(machine.jmax, dtype=float)[lin]
    return float(min(np.min(amax) * dt**2, np.min(jmax) * dt**3))


def _is_number(v: object) -> bool:
    import numbers

    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def _below_min(tol: float) -> str:
    return (
        f"fit tolerance {tol!r} mm is below {FIT_TOL_MIN_MM:g} mm, the finest the fit works to "
        "(0 asks for the exact path)"
    )

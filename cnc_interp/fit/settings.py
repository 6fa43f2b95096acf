"""``FitSettings``: tolerances and corner threshold of the fit stage."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..constants import DEFAULT_CORNER_DEG, DEFAULT_TOL_DEG, DEFAULT_TOL_MM
from ..errors import UsageError

TOL_MODES = ("stricter", "gcode")
METHODS = ("auto", "planar", "nodes")


@dataclass(frozen=True)
class FitSettings:
    """How closely and how the fit follows the programmed nodes.

    Attributes:
        tol_mm: maximum permissible error for linear axes, mm (``--tol``).
        tol_deg: maximum permissible error for rotary axes, deg.
        corner_deg: a turn between consecutive moves sharper than this splits
            the path there (the planner stops); below it the fit rounds the
            corner within the tolerance.
        tol_mode: how a block's ``G64 P`` combines with ``tol_mm``:
            ``"stricter"`` (default) takes the smaller one, ``"gcode"`` lets
            ``G64 P`` win. ``G61`` (tolerance 0) always means exact path.
        method: ``"auto"`` (paper 000's planar fit for runs that move exactly two
            axes, the N-axis fit otherwise), ``"planar"`` (planar wherever it
            applies) or ``"nodes"`` (N-axis fit everywhere).
    """

    tol_mm: float = DEFAULT_TOL_MM
    tol_deg: float = DEFAULT_TOL_DEG
    corner_deg: float = DEFAULT_CORNER_DEG
    tol_mode: str = "stricter"
    method: str = "auto"

    def __post_init__(self) -> None:
        for name in ("tol_mm", "tol_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise UsageError(f"fit tolerance {name} must be a positive number, got {v!r}")
        if not (0.0 <= self.corner_deg <= 180.0):
            raise UsageError(f"corner angle must be within [0, 180] deg, got {self.corner_deg!r}")
        if self.tol_mode not in TOL_MODES:
            raise UsageError(f"tol_mode must be one of {TOL_MODES}, got {self.tol_mode!r}")
        if self.method not in METHODS:
            raise UsageError(f"fit method must be one of {METHODS}, got {self.method!r}")

    @classmethod
    def from_options(cls, tol_mm: float | None = None, corner_deg: float | None = None,
                     machine=None, method: str | None = None, **extra) -> "FitSettings":
        """Settings from CLI options; the machine's ``tol_mm`` is used when ``--tol`` is absent,
        ``"auto"`` when ``--fit-method`` is.

        ``--tol 0`` asks for the exact path: it is kept as the smallest tolerance the
        fitter accepts for curves (``FIT_EXACT_CURVE_TOL_MM``); straight moves stop
        at every corner as under G61.
        """
        from ..constants import FIT_EXACT_CURVE_TOL_MM

        if tol_mm is None and machine is not None and getattr(machine, "tol_mm", None):
            tol_mm = float(machine.tol_mm)
        kw = dict(extra)
        if tol_mm is not None:
            kw["tol_mm"] = max(float(tol_mm), FIT_EXACT_CURVE_TOL_MM) if tol_mm > 0 else FIT_EXACT_CURVE_TOL_MM
            if tol_mm == 0:
                kw["corner_deg"] = 0.0
        if corner_deg is not None and "corner_deg" not in kw:
            kw["corner_deg"] = float(corner_deg)
        if method is not None:
            kw["method"] = method
        return cls(**kw)

    def node_tolerance(self, tol_block_mm):
        """Per-move tolerance (mm) from the blocks' ``tol_mm`` (nan / 0 / G64 P) array."""
        import numpy as np

        t = np.asarray(tol_block_mm, dtype=float)
        out = np.full(t.shape, self.tol_mm)
        p = np.isfinite(t) & (t > 0)
        if self.tol_mode == "stricter":
            out[p] = np.minimum(t[p], self.tol_mm)
        else:
            out[p] = t[p]
        out[np.isfinite(t) & (t == 0)] = 0.0
        return out

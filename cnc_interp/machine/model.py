"""``Machine``: per-axis limits, sample period and kinematics.

Loading (TOML, LinuxCNC INI, built-in presets) lives in ``load``; this
module holds only the type.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..constants import MCODE_MAX, MCODES_INTERPRETED, PROGRAM_UNITS_MM, ROTARY_AXES
from ..errors import MachineError, SourceLocation, UsageError

#: accepted limit ranges (exclusive of 0), mm or deg per s, s², s³: far beyond any machine,
#: far below where the planner's products (v·dt, j·dt³ and their squares) lose precision
#: or overflow float64
LIMIT_MAX = {"vmax": 1e6, "amax": 1e9, "jmax": 1e13}
#: smallest accepted limits, mm or deg per s, s², s³ (0.06 mm/min; real machines are
#: thousands of times faster): 1e-20 overflowed the planners' step sizes, 1e-9 planned for
#: hours a move of millimetres
LIMIT_MIN = {"vmax": 1e-3, "amax": 1e-3, "jmax": 1e-3}
#: most sample periods an axis may take from rest to its vmax (vmax/amax + amax/jmax s):
#: VPOp's brake buffers hold eight such ramps of samples (~100 bytes each, 1 GB at this
#: bound; measured at amax = 0.1 mm/s², vmax = 100 mm/s, dt = 1 ms: 0.86 GB). Real machines
#: take under a second (under 500 periods at 1 ms); 2^20 periods is 17 minutes at 1 ms
RAMP_MAX_PERIODS = 1 << 20
#: accepted sample periods, s: a 1 MHz servo rate to 1 s
DT_MIN_S, DT_MAX_S = 1e-6, 1.0
#: largest default fit tolerance, mm (a tolerance is a deviation from the part, not a size)
TOL_MAX_MM = 10.0
#: largest start coordinate, mm or deg (the G-code front end's coordinate bound)
START_MAX = 1e9


def ramp_problem(vmax: ArrayLike, amax: ArrayLike, jmax: ArrayLike, dt_s: float) -> tuple[int, str]:
    """(axis index, message) of the first axis that takes more than ``RAMP_MAX_PERIODS``
    sample periods from rest to its vmax, else (0, "")."""
    ramp = np.atleast_1d(np.asarray(vmax, dtype=float) / amax + np.asarray(amax, dtype=float) / jmax)
    bad = ~(ramp <= RAMP_MAX_PERIODS * dt_s)
    if not bad.any():
        return 0, ""
    k = int(np.argmax(bad))
    return k, (
        f"takes {ramp[k]:.6g} s from rest to its vmax (vmax/amax + amax/jmax), more than "
        f"{RAMP_MAX_PERIODS} sample periods of dt = {dt_s:g} s; its amax or jmax is far too low "
        "(or use a longer --dt)"
    )


@dataclass(frozen=True, eq=False)
class Machine:
    """A machine tool's axes and limits.

    Attributes (n = number of axes):
        name: human-readable name.
        axes: axis letters in machine order, e.g. ``"XYZAC"``.
        vmax: (n,) velocity limits, mm/s (deg/s for rotary axes).
        amax: (n,) acceleration limits, mm/s² (deg/s²).
        jmax: (n,) jerk limits, mm/s³ (deg/s³).
        dt_s: sample period, s.
        kinematics: ``"trivial"`` or ``"xyzac-trt"``.
        kinematics_params: parameters of the kinematics (e.g. pivot offsets, mm).
        start: (n,) machine position before the program, mm / deg.
        tol_mm: default path tolerance for the fit, mm.
        source: where it was loaded from (file name or ``preset:NAME``).
        tool_table: path of the LinuxCNC tool table (an INI's ``[EMCIO] TOOL_TABLE``), or None.
        noop_mcodes: M-codes (numbers) the machine declares no-ops for planning: its
            user M-codes (LinuxCNC's M100-M199 programs) or a controller's own codes (a
            Fanuc M29) that move no axis; the G-code reader accepts them and does nothing.
        program_units: the length units a program starts in, ``"mm"`` or ``"inch"``
            (as if it began with G21 or G20): a LinuxCNC machine's own units, its INI's
            ``[TRAJ] LINEAR_UNITS``; a G20 or G21 in the program switches as usual.
        max_path_mm_s: the tool's path speed limit over the linear axes, mm/s (LinuxCNC's
            ``[TRAJ] MAX_LINEAR_VELOCITY``), or None: the G-code reader caps every feed
            move's feed and every rapid's path speed at it where it can bind
            (``path_speed_cap_mm_s``).
        defaults: what the reader filled in because the source did not give it, as
            ``{what: the value and why}`` (e.g. ``{"jmax.X": "10/s x amax ..."}``; keys
            ``name``, ``dt``, ``kinematics``, ``kinematics.<param>``, ``jmax.<axis>``,
            ``start``, ``tol``, ``linear_units``, ``angular_units``); ``cnc-interp machines
            FILE`` prints them. It describes the source: ``with_dt`` and ``with_start`` keep it.
    """

    name: str
    axes: str
    vmax: np.ndarray
    amax: np.ndarray
    jmax: np.ndarray
    dt_s: float
    kinematics: str = "trivial"
    kinematics_params: dict[str, float] = field(default_factory=dict)
    #: (n,) mm / deg; ``None`` given is stored as zeros, so it is an array once built
    start: np.ndarray = None  # type: ignore[assignment]
    tol_mm: float | None = None
    source: str = ""
    tool_table: str | None = None
    defaults: dict[str, str] = field(default_factory=dict)
    noop_mcodes: frozenset[int] = frozenset()
    program_units: str = "mm"
    max_path_mm_s: float | None = None

    def __post_init__(self) -> None:
        n = len(self.axes)
        for name in ("vmax", "amax", "jmax"):
            arr = np.asarray(getattr(self, name), dtype=float).reshape(n)
            object.__setattr__(self, name, arr)
        start = np.zeros(n) if self.start is None else np.asarray(self.start, dtype=float).reshape(n)
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "noop_mcodes", frozenset(int(c) for c in self.noop_mcodes))
        self._check_ranges()

    def _check_ranges(self) -> None:
        """Every number finite and within its sane range, else a ``MachineError`` naming it
        (a machine file is checked with line numbers before it gets here; this also covers
        ``--dt``, ``--start`` and machines built in Python)."""
        loc = SourceLocation(file=self.source or "machine")
        for name, hi in LIMIT_MAX.items():
            arr = getattr(self, name)
            lo = LIMIT_MIN[name]
            bad = ~((arr >= lo) & (arr <= hi))
            if bad.any():
                k = int(np.argmax(bad))
                raise MachineError(f"axis {self.axes[k]} {name} = {arr[k]:g} is out of range [{lo:g}, {hi:g}]", loc)
        if not DT_MIN_S <= self.dt_s <= DT_MAX_S:
            raise MachineError(
                f"sample period dt = {self.dt_s:g} s is out of range [{DT_MIN_S:g}, {DT_MAX_S:g}] s", loc
            )
        k, why = ramp_problem(self.vmax, self.amax, self.jmax, self.dt_s)
        if why:
            raise MachineError(f"axis {self.axes[k]} {why}", loc)
        if self.tol_mm is not None and not 0 <= self.tol_mm <= TOL_MAX_MM:
            raise MachineError(f"tol = {self.tol_mm:g} mm is out of range [0, {TOL_MAX_MM:g}] mm", loc)
        if not (np.abs(self.start) <= START_MAX).all():
            raise MachineError(f"start position out of range (|coordinate| > {START_MAX:g})", loc)
        problem = noop_mcode_problem(self.noop_mcodes)
        if problem:
            raise MachineError(problem, loc)
        if self.program_units not in PROGRAM_UNITS_MM:
            known = ", ".join(PROGRAM_UNITS_MM)
            raise MachineError(f"program units '{self.program_units}' are not known (known: {known})", loc)
        if self.max_path_mm_s is not None and not LIMIT_MIN["vmax"] <= self.max_path_mm_s <= LIMIT_MAX["vmax"]:
            raise MachineError(
                f"path speed limit = {self.max_path_mm_s:g} mm/s is out of range "
                f"[{LIMIT_MIN['vmax']:g}, {LIMIT_MAX['vmax']:g}]",
                loc,
            )

    @property
    def n_axes(self) -> int:
        return len(self.axes)

    @property
    def rotary(self) -> np.ndarray:
        """(n,) bool: which axes are rotary (deg)."""
        return np.array([a in ROTARY_AXES for a in self.axes], dtype=bool)

    @property
    def path_speed_cap_mm_s(self) -> float | None:
        """``max_path_mm_s`` where it can bind, else None: a limit at or above the linear
        axes' vmax combined (the fastest any path can go, a diagonal with every linear axis
        at its vmax) never binds, so the G-code reader leaves the feeds as programmed."""
        cap = self.max_path_mm_s
        lin = ~self.rotary
        if cap is None or not lin.any() or cap >= float(np.sqrt((self.vmax[lin] ** 2).sum())):
            return None
        return cap

    def limits(self) -> np.ndarray:
        """(3, n) array of vmax, amax, jmax."""
        return np.stack([self.vmax, self.amax, self.jmax])

    def with_dt(self, dt_s: float | None) -> "Machine":
        """This machine with another sample period (``None`` keeps the current one)."""
        if dt_s is None or dt_s == self.dt_s:
            return self
        return replace(self, dt_s=float(dt_s))

    def with_start(self, start: "np.ndarray | list[float] | None") -> "Machine":
        """This machine with another start position ((n,) mm / deg; ``None`` keeps it)."""
        if start is None:
            return self
        return replace(self, start=np.asarray(start, dtype=float).reshape(self.n_axes))

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able description (for reports and MCAP metadata)."""
        return {
            "name": self.name,
            "source": self.source,
            "axes": self.axes,
            "dt_s": float(self.dt_s),
            "kinematics": self.kinematics,
            "kinematics_params": {k: float(v) for k, v in self.kinematics_params.items()},
            "tol_mm": None if self.tol_mm is None else float(self.tol_mm),
            "noop_mcodes": sorted(self.noop_mcodes),
            "program_units": self.program_units,
            "max_path_mm_s": None if self.max_path_mm_s is None else float(self.max_path_mm_s),
            "start": {a: float(v) for a, v in zip(self.axes, self.start)},
            "limits": {
                a: {"vmax": float(v), "amax": float(acc), "jmax": float(j), "unit": "deg" if a in ROTARY_AXES else "mm"}
                for a, v, acc, j in zip(self.axes, self.vmax, self.amax, self.jmax)
            },
        }


def noop_mcode_problem(codes: Iterable[int]) -> str:
    """Why ``codes`` cannot be declared no-op M-codes ("" when they can): each must be a
    whole number from 0 to ``MCODE_MAX`` that the interpreter gives no meaning of its own
    (``MCODES_INTERPRETED``: an M2 or M6 keeps its meaning)."""
    for c in sorted(codes):
        if not 0 <= c <= MCODE_MAX:
            return f"noop_mcodes: M{c} is out of range (0 to {MCODE_MAX})"
        if c in MCODES_INTERPRETED:
            return (
                f"noop_mcodes: M{c} has a meaning of its own in the G-code reader; only M-codes "
                "it does not know may be declared no-ops"
            )
    return ""


def parse_start(spec: str | None, axes: str, base: np.ndarray | None = None) -> np.ndarray | None:
    """``--start "X=1,Y=2"`` -> (n,) position on ``axes``; the axes it does not name keep
    ``base`` (the machine's start position; 0 without one). ``None`` passes."""
    if spec is None:
        return None
    out = np.zeros(len(axes)) if base is None else np.array(base, dtype=float).reshape(len(axes))
    for part in spec.replace(" ", "").split(","):
        if not part:
            continue
        name, sep, value = part.partition("=")
        name = name.upper()
        if not sep or len(name) != 1 or name not in axes:
            raise UsageError(f"bad --start item '{part}': expected AXIS=VALUE with AXIS in {axes}")
        try:
            v = float(value)
        except ValueError:
            raise UsageError(f"bad --start value in '{part}': not a number") from None
        if not np.isfinite(v) or abs(v) > START_MAX:
            raise UsageError(f"bad --start value in '{part}': not a finite coordinate within ±{START_MAX:g}")
        out[axes.index(name)] = v
    return out

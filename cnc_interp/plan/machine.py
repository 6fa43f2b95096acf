"""``Machine``: per-axis limits, sample period and kinematics.

Loading (TOML, LinuxCNC INI, built-in presets) lives in ``machine_io``; this
module holds only the type.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..constants import ROTARY_AXES


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
    """

    name: str
    axes: str
    vmax: np.ndarray
    amax: np.ndarray
    jmax: np.ndarray
    dt_s: float
    kinematics: str = "trivial"
    kinematics_params: dict = field(default_factory=dict)
    start: np.ndarray | None = None
    tol_mm: float | None = None
    source: str = ""

    def __post_init__(self) -> None:
        n = len(self.axes)
        for name in ("vmax", "amax", "jmax"):
            arr = np.asarray(getattr(self, name), dtype=float).reshape(n)
            object.__setattr__(self, name, arr)
        start = np.zeros(n) if self.start is None else np.asarray(self.start, dtype=float).reshape(n)
        object.__setattr__(self, "start", start)

    @property
    def n_axes(self) -> int:
        return len(self.axes)

    @property
    def rotary(self) -> np.ndarray:
        """(n,) bool: which axes are rotary (deg)."""
        return np.array([a in ROTARY_AXES for a in self.axes], dtype=bool)

    def limits(self) -> np.ndarray:
        """(3, n) array of vmax, amax, jmax."""
        return np.stack([self.vmax, self.amax, self.jmax])

    def with_dt(self, dt_s: float | None) -> "Machine":
        """This machine with another sample period (``None`` keeps the current one)."""
        if dt_s is None or dt_s == self.dt_s:
            return self
        return replace(self, dt_s=float(dt_s))

    def with_start(self, start) -> "Machine":
        """This machine with another start position ((n,) mm / deg; ``None`` keeps it)."""
        if start is None:
            return self
        return replace(self, start=np.asarray(start, dtype=float).reshape(self.n_axes))

    def to_dict(self) -> dict:
        """Plain JSON-able description (for reports and MCAP metadata)."""
        return {
            "name": self.name,
            "source": self.source,
            "axes": self.axes,
            "dt_s": float(self.dt_s),
            "kinematics": self.kinematics,
            "kinematics_params": {k: float(v) for k, v in self.kinematics_params.items()},
            "tol_mm": None if self.tol_mm is None else float(self.tol_mm),
            "start": {a: float(v) for a, v in zip(self.axes, self.start)},
            "limits": {
                a: {"vmax": float(v), "amax": float(acc), "jmax": float(j),
                    "unit": "deg" if a in ROTARY_AXES else "mm"}
                for a, v, acc, j in zip(self.axes, self.vmax, self.amax, self.jmax)
            },
        }

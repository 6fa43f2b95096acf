"""``Trajectory``: sampled axis setpoints at a fixed period — the planners' output."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Setpoints every ``dt_s`` from rest at the start to rest at the end.

    Attributes (K = number of samples, n = number of machine axes):
        axes: machine axis letters in machine order.
        dt_s: sample period, s.
        t: (K,) sample times, ``t[k] = k * dt_s``.
        s: (K,) cumulative path length along the whole program (rapids included), mm.
        feed: (K,) path speed, mm/s: backward difference of s (0 at k = 0).
        q: (K, n) joint setpoints, mm / deg.
        line: (K,) int, source line being executed at each sample (0 = none).
        planner: name of the planner (``"vpop"``, ``"constant"``, ``"variable"``).
        settings: the planner's settings (plain JSON-able values).
        status: ``"ok"`` or a planner status explaining a degraded result.
        profiles: planner-specific data kept for later stages (e.g. paper-000
            per-segment feed profiles for the FPGA stage); ``None`` if none.
    """

    axes: str
    dt_s: float
    t: np.ndarray
    s: np.ndarray
    feed: np.ndarray
    q: np.ndarray
    line: np.ndarray
    planner: str
    settings: dict[str, Any] = field(default_factory=dict)
    status: str = "ok"
    profiles: object = None

    @property
    def n_samples(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration_s(self) -> float:
        """Cycle time: time of the last sample."""
        return float(self.t[-1]) if self.t.size else 0.0

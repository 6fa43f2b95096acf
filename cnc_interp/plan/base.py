"""The contract between the timeline and the per-path planners.

A path planner takes one ``Path`` (already mapped to joint space by the
kinematics) and returns samples every ``dt_s`` from rest at the path's start to
rest at its end. The timeline (``plan.timeline``) strings these together with
rapids, dwells and stops into one ``Trajectory``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np


@dataclass(frozen=True, eq=False)
class PathPlan:
    """One path's samples.

    Attributes (K = samples):
        s: (K,) arc length at t = k * dt_s; s[0] = 0, s[-1] = path length.
        q: (K, n) joint setpoints; q[0] = joint start, q[-1] = joint end (exactly).
            The machine is at rest before q[0] and after q[-1] (held positions), and
            verify's finite differences over the held positions stay within limits.
        status: ``"ok"`` or a planner status string.
        profiles: planner-specific data (paper-000 segment profiles; ``None`` for VPOp).
        stats: plain JSON-able numbers (iterations, backtracks, ...).
    """

    s: np.ndarray
    q: np.ndarray
    status: str = "ok"
    profiles: object = None
    stats: dict | None = None


class JointMap(Protocol):
    """Maps program-space positions (K, n) to joint positions (K, n) (the kinematics)."""

    def __call__(self, p: np.ndarray) -> np.ndarray: ...


#: signature of a per-path planner: (path, joint map, machine, dt_s, settings) -> PathPlan
PathPlanner = Callable[..., PathPlan]

"""The contract between the timeline and the per-path planners.

A path planner takes one ``Path`` (already mapped to joint space by the
kinematics) and returns samples every ``dt_s`` from rest at the path's start to
rest at its end. The timeline (``plan.timeline``) strings these together with
rapids, dwells and stops into one stream of samples.

Two forms, registered per planner in ``plan.planners``:

* one-shot: ``planner(path, joint_map, machine, dt_s, settings) -> PathPlan``;
* streaming: ``iter_path_plan(path, joint_map, machine, dt_s, settings)`` yields
  ``PathPlan`` chunks in order, each as soon as the planner no longer needs to look
  past it (a bounded look-ahead), so a path of a million moves is planned in bounded
  memory. The concatenation of the chunks' ``s`` and ``q`` is the one-shot result,
  bit for bit; only the last chunk (``last=True``) carries ``status``, ``profiles``
  and ``stats``. Chunks may be of any size, never empty except a path's only chunk.

``one_chunk(planner)`` turns a one-shot planner into a streaming one (one chunk per
path: the whole path is in memory at once), ``collect_path_plan`` the other way.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterator, Protocol

import numpy as np


@dataclass(frozen=True, eq=False)
class PathPlan:
    """One path's samples, or one chunk of them.

    Attributes (K = samples):
        s: (K,) arc length at t = k * dt_s; s[0] = 0, s[-1] = path length (of the
            whole path: a chunk holds a consecutive slice).
        q: (K, n) joint setpoints; q[0] = joint start, q[-1] = joint end (exactly).
            The machine is at rest before q[0] and after q[-1] (held positions), and
            verify's finite differences over the held positions stay within limits.
        status: ``"ok"`` or a planner status string.
        profiles: planner-specific data (paper-000 segment profiles; ``None`` for VPOp).
        stats: plain JSON-able numbers (iterations, backtracks, ...).
        last: True for a whole path and for the last chunk of a streamed one.
    """

    s: np.ndarray
    q: np.ndarray
    status: str = "ok"
    profiles: object = None
    stats: dict | None = None
    last: bool = True


class JointMap(Protocol):
    """Maps program-space positions (K, n) to joint positions (K, n) (the kinematics)."""

    def __call__(self, p: np.ndarray) -> np.ndarray: ...


#: signature of a per-path planner: (path, joint map, machine, dt_s, settings) -> PathPlan
PathPlanner = Callable[..., PathPlan]
#: signature of a streaming planner: the same arguments -> iterator of PathPlan chunks
IterPathPlanner = Callable[..., Iterator[PathPlan]]


def one_chunk(planner: PathPlanner) -> IterPathPlanner:
    """A streaming planner that yields ``planner``'s whole result as one chunk."""

    def iter_path_plan(path, joint_map, machine, dt_s, settings=None):
        yield planner(path, joint_map, machine, dt_s, settings)

    iter_path_plan.streams = False  # the whole path is in memory at once
    iter_path_plan.__name__ = f"one_chunk({getattr(planner, '__name__', 'planner')})"
    return iter_path_plan


def collect_path_plan(chunks) -> PathPlan:
    """The one-shot ``PathPlan`` of a stream of chunks (their concatenation)."""
    parts = list(chunks)
    if not parts:
        raise ValueError("a path plan has at least one chunk")
    end = parts[-1]
    if len(parts) == 1:
        return end
    return PathPlan(
        s=np.concatenate([c.s for c in parts]),
        q=np.concatenate([c.q for c in parts], axis=0),
        status=end.status,
        profiles=end.profiles,
        stats=end.stats,
        last=True,
    )

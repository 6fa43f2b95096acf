"""Route: which sampler plans a path (the feed profile's or VPOp's), measured once.

A path goes through the profile (``profile``, ``sampling``) when its static speed limit
(curvature and jerk, ``_feed_kernels.route_measures``) is below ``tuning.route_speed`` of
its feed and axis speeds on at least ``tuning.route_share`` of its length and it lasts at
least ``tuning.route_min_s`` at those limits (plus ramps); otherwise VPOp plans it, which
is near the optimum where the feed or an axis speed binds. A path whose travel at the
feed plus ramps is under ``tuning.route_tiny_s`` takes VPOp without measuring.

``_RouteInputs`` holds what the route reads (the joint table, the feed caps, the rough
and static durations). ``batched_optimal`` routes a job's paths in program space before the
timeline streams them, all in one compiled call (``route_many``), and keeps the inputs of
the few it streams (``_ROUTED``), so each path's joint table and route are made once.
"""

from __future__ import annotations

import threading
from enum import StrEnum

import numpy as np

from ...constants import VPOP_LIMIT_SHRINK
from ..tuning import OptimalTuning


class Route(StrEnum):
    """The route of a path (``_route``), and what the selection keeps (stat "kept")."""

    #: the feed-profile LP, sampled by the time law (``profile``, ``sampling``)
    PROFILE = "profile"
    #: VPOp's step loop (``plan.vpop``)
    VPOP = "vpop"


class _RouteInputs:
    """What ``_route`` reads of a path: its joint table, feed caps and rough durations."""

    def __init__(self, path, joint_map, machine, tuning: OptimalTuning):
        from ..joint_table import JointTable

        self.machine = machine
        #: the planner's tunables (``OptimalOptions.tuning``)
        self.tuning = tuning
        self.table = table = JointTable(path, joint_map)
        self.L = table.length
        fb = np.ascontiguousarray(path.s_breaks, dtype=float).copy()
        fb[-1] = self.L
        self.FB = fb
        self.FV = np.ascontiguousarray(
            np.where(
                np.isfinite(path.feed_mm_s) & (path.feed_mm_s > 0), path.feed_mm_s * (1.0 - VPOP_LIMIT_SHRINK), 1e300
            )
        )
        dq = np.abs(table.qend - table.qstart)
        ramp = float(np.max(machine.vmax / machine.amax + machine.amax / machine.jmax))
        self.ramp_s = 2.0 * ramp
        self.rough_s = float(np.max(dq / machine.vmax)) + self.L / float(np.min(self.FV)) + self.ramp_s
        self.stats: dict = {}
        #: the path's duration at its static speed limits (feed, axis speeds, curvature,
        #: jerk; ``_route``), s: unlike ``rough_s``, it sees a curvature-limited path's length
        self.static_s = 0.0
        #: the path's route once ``_route`` has measured it ("profile" or "vpop")
        self.route: str | None = None

    @property
    def duration_s(self) -> float:
        """The longer of the rough and the static duration, s (``rough_s`` alone is the
        feed's: zigzag_0.002_0.001's 4-inch zigzag, ~1 s at F9999, lasts 34-150 s)."""
        return max(self.rough_s, self.static_s)


def route_many(paths, machine, tuning: OptimalTuning) -> list:
    """``_route`` of each of ``paths`` (joints = program axes, not rapids) in one compiled
    call (``_feed_kernels.route_batch``): a ``Route`` each, or ``None`` where the joint
    table cannot be built (the path's own planning raises that error, in order)."""
    from .. import _feed_kernels as K
    from ..joint_table import _GL_X, _GL_W, VPOP_TABLE_MAX_PIECE, VPOP_TABLE_MAX_ROUNDS, VPOP_TABLE_MAX_TRIES
    from ..joint_table import VPOP_TABLE_TOL

    if not paths:
        return []
    n_seg = np.array([p.n_seg for p in paths], dtype=np.int64)
    seg_off = np.zeros(len(paths) + 1, dtype=np.int64)
    np.cumsum(n_seg, out=seg_off[1:])
    feed = np.concatenate([p.feed_mm_s for p in paths])
    caps = np.ascontiguousarray(np.where(np.isfinite(feed) & (feed > 0), feed * (1.0 - VPOP_LIMIT_SHRINK), 1e300))
    ramp_s = 2.0 * float(np.max(machine.vmax / machine.amax + machine.amax / machine.jmax))
    paths_in = K.RoutePaths(
        np.concatenate([p.coef for p in paths]),
        np.concatenate([p.breaks for p in paths]),
        np.concatenate([p.s_breaks for p in paths]),
        np.array([p.weights for p in paths], dtype=float),
        np.array([p.length for p in paths], dtype=float),
        caps,
        seg_off,
    )
    lim = K.RouteLimits(
        np.asarray(machine.vmax, dtype=float),
        np.asarray(machine.amax, dtype=float),
        np.asarray(machine.jmax, dtype=float),
        ramp_s,
        float(tuning.route_tiny_s),
        float(tuning.route_speed),
    )
    table = (
        float(VPOP_TABLE_TOL),
        VPOP_TABLE_MAX_ROUNDS - 1,
        float(VPOP_TABLE_MAX_PIECE),
        _GL_X,
        _GL_W,
        VPOP_TABLE_MAX_TRIES,
    )
    code, static_s, share = K.route_batch(paths_in, lim, table)
    # _measured_route's thresholds on the measured paths (code 2)
    profile = (share >= tuning.route_share) & (static_s + ramp_s >= tuning.route_min_s)
    return [
        None if c < 0 else Route.PROFILE if c == 2 and pr else Route.VPOP
        for c, pr in zip(code.tolist(), profile.tolist())
    ]


class _Routed(threading.local):
    """The route inputs ``batched_optimal`` built for the paths it leaves to the stream,
    kept for their ``_Path`` in the same thread (the timeline plans a job's batch and then
    its streamed paths in one worker): each path's joint table and route are then made
    once."""

    def __init__(self):
        self.held: dict = {}

    def keep(self, held: dict) -> None:
        """Hold ``held`` ({id(path): (path, its _RouteInputs)}), dropping the last job's."""
        self.held = held

    def take(self, path, joint_map):
        """The ``_RouteInputs`` kept for ``path`` in program space, or None."""
        got = self.held.pop(id(path), None)
        if got is None or got[0] is not path or joint_map is not None:
            return None
        return got[1]


_ROUTED = _Routed()


def _route(ctx) -> Route:
    """ "profile" where curvature or jerk limit the speed on a good part of a path that
    lasts long enough to gain from it, else "vpop" (see tuning.route_*); measured once per
    ``_RouteInputs`` (kept in ``ctx.route``)."""
    if ctx.route is None:
        ctx.route = _measured_route(ctx)
    return ctx.route


def _measured_route(ctx) -> Route:
    """``_route``'s measurement (``ctx.static_s`` and the stat "limited_share" with it)."""
    T = ctx.tuning
    if ctx.rough_s < T.route_tiny_s:
        return Route.VPOP  # travel at the feed and ramps: far below the threshold anyway
    from .. import _feed_kernels as K

    m = ctx.machine
    share, t_static = K.route_measures(
        ctx.table.S,
        np.ascontiguousarray(ctx.table.C),
        ctx.FB,
        ctx.FV,
        np.asarray(m.vmax, dtype=float),
        np.asarray(m.amax, dtype=float),
        np.asarray(m.jmax, dtype=float),
        float(T.route_speed),
    )
    # duration at the static limits: a lower bound of the motion's, ramps aside
    ctx.static_s = t_static
    ctx.stats["limited_share"] = round(share, 4)
    long_enough = t_static + ctx.ramp_s >= T.route_min_s
    return Route.PROFILE if share >= T.route_share and long_enough else Route.VPOP

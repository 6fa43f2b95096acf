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
    #: the exact discrete plan of a straight path (``line``)
    LINE = "line"


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
        self.FV = _feed_caps(path.feed_mm_s)
        dq = np.abs(table.qend - table.qstart)
        self.ramp_s = _ramp_s(machine)
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


def _feed_caps(feed_mm_s: np.ndarray) -> np.ndarray:
    """Per segment, the feed as the planners bound it, mm/s (1e300 where none)."""
    f = feed_mm_s
    return np.ascontiguousarray(np.where(np.isfinite(f) & (f > 0), f * (1.0 - VPOP_LIMIT_SHRINK), 1e300))


def _ramp_s(machine) -> float:
    """Twice the longest rest-to-full-speed ramp of an axis (vmax/amax + amax/jmax), s."""
    return 2.0 * float(np.max(machine.vmax / machine.amax + machine.amax / machine.jmax))


def _takes_profile(share, static_s, ramp_s: float, tuning: OptimalTuning):
    """The route's thresholds on a measured path (scalars or arrays): limited on at least
    ``tuning.route_share`` of its length and lasting ``tuning.route_min_s`` with the ramps."""
    return (share >= tuning.route_share) & (static_s + ramp_s >= tuning.route_min_s)


def route_many(paths, machine, tuning: OptimalTuning) -> list:
    """``_route`` of each of ``paths`` (joints = program axes, not rapids) in one compiled
    call (``_feed_kernels.route_batch``): a ``Route`` each, or ``None`` where the joint
    table cannot be built (the path's own planning raises that error, in order)."""
    from .. import _feed_kernels as K
    from ..joint_table import concat_paths, identity_table_settings

    if not paths:
        return []
    coef, breaks, s_breaks, weights, lengths, feed, seg_off = concat_paths(paths)
    paths_in = K.RoutePaths(coef, breaks, s_breaks, weights, lengths, _feed_caps(feed), seg_off)
    ramp_s = _ramp_s(machine)
    lim = K.RouteLimits(
        np.asarray(machine.vmax, dtype=float),
        np.asarray(machine.amax, dtype=float),
        np.asarray(machine.jmax, dtype=float),
        ramp_s,
        float(tuning.route_tiny_s),
        float(tuning.route_speed),
    )
    code, static_s, share = K.route_batch(paths_in, lim, identity_table_settings())
    profile = _takes_profile(share, static_s, ramp_s, tuning)  # on the measured paths (code 2)
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
    return Route.PROFILE if _takes_profile(share, t_static, ctx.ramp_s, T) else Route.VPOP

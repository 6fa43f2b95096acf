"""``OptimalTuning``: every internal tunable of the optimal planner, in one frozen record.

The optimal planner (``plan.optimal``) and its stages (``route``, ``profile``,
``sampling``, ``refine``, ``select``) read their tunables from the ``OptimalTuning``
they are given (``OptimalOptions.tuning``; default ``OptimalTuning()``), never from
module globals, so a caller (a test, a benchmark) changes one by building a tuning.
``OptimalOptions`` holds the user's knobs (effort, route, ...); this record holds what a
user never sets.

Each field gives its unit and its rule in one line. The constants of a numerical method
(the LP solver's pivot tolerances in ``_ipm``, the Gauss-Legendre order of
``optimal.sampling``, the window solver's step rules in ``_refine_kernels``, the
bisection steps of ``optimal.profile``) stay named at the top of their modules: they
decide how exactly a sub-problem is solved, not what the planner plans.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from ..errors import UsageError


@dataclass(frozen=True)
class OptimalTuning:
    """The optimal planner's tunables (see the module docstring).

    Route (``optimal.route``):
        route_speed: 1; a place is limited where its static speed limit (curvature,
            jerk) is below this share of its feed and axis speeds.
        route_share: 1; a path takes the profile when at least this share of its length
            is limited ...
        route_min_s: s; ... and it lasts at least this long at its static limits (plus
            ramps); otherwise VPOp plans it.
        route_tiny_s: s; a path whose travel at the feed plus ramps is shorter takes
            VPOp without measuring.

    Feed profile LP (``optimal.profile``):
        knot_time_s: s; knot spacing in motion time at the estimated speed.
        knot_geo: 1; knot spacing at most this share of the geometry's length scales
            (radius of curvature, that of q_sss).
        knot_block: table pieces; the knot placement runs block by block of this many.
        collocation: points per knot interval where the LP's limit rows are imposed.
        commit_s: s; motion a window commits (it looks two braking times further).
        whole_knots: knot intervals; a path of at most this many is one window.
        ccp_max: iterations of the convex-concave procedure per window ...
        ccp_tol: 1; ... stopping when the traversal time changes by less than this share.
        ccp_max_restart: iterations for a window solved again from the previous
            window's whole solution.
        est_acc_factor: 1; the knot placement's speed estimate may exceed the static
            acceleration limit by this factor ...
        est_jerk_factor: 1; ... and the static jerk limit by this one.
        est_ratio_min: 1; a window's first LP is linearised at the estimate times the
            previous window's solution/estimate ratio, at least this ...
        est_ratio_keep: 1; ... and a ratio above this counts as 1.
        weight_floor: 1; the objective's time weights use ŵ at least this share of the
            estimate.
        lp_max_iter: interior-point iterations per LP at most ...
        lp_first_max_iter: ... for a window's first LP (linearised at the estimate) ...
        lp_tol: 1; ... and the solver's tolerance on the scaled problem.
        limit_share: 1; the LP's acceleration and jerk limits, as a share of the
            machine's (the sampler checks the exact ones).
        row_screen: 1; after a window's first LP, only rows with slack at most
            1 - this of their scale take part (the others are checked after each solve).
        screen_rounds: solves per LP with screened rows at most; the last takes them all.
        hat_margin: 1; where the previous window brakes, the first LP is linearised
            only so far from the estimate that the previous solution keeps this share
            of each jerk row free.

    Time law and exact sampling (``optimal.sampling``):
        timelaw_nodes: time-law nodes per knot interval of the profile.
        timelaw_min_dip: 1; a piece whose w dips between two nodes below this share of
            the smaller node value is refused.
        handover_back: samples each; stuck (no allowed position) away from the end,
            VPOp finishes the path from this many samples back (the first that works).

    Refinement (``optimal.refine``):
        refine_passes: passes over every window at coarse periods or effort max.
        full_refine_dt: s; at and above this period every window is refined; below,
            only the path's ends and the dips of the speed (targeted).
        refine_window: samples per window ...
        refine_stride: samples; ... and the stride between windows.
        end_window: samples; the window at the end of VPOp's plans (``planner._end_window``):
            30 recovers 69 % of the periods 60 does for 35 % of its solve time
            (stellabee1's first 3000 lines, 544 VPOp paths); also how far back, and
            how many samples more, the sampler lands a plan stuck stopping at the
            end (``sampling._land``).
        refine_newton: Newton steps per window solve at most.
        refine_skip: 1; a window none of whose samples keeps every limit ratio below
            this is skipped.
        refine_probe: window solves per block of the targeted pause rule ...
        refine_rate: periods; ... a block gaining less than this many per solve ...
        refine_pause: strides; ... pauses the windows this long.
        dip: 1; a step below this share of the largest in a window around it marks a
            dip of the speed (targeted windows).

    Selection (``optimal.select``):
        compare_samples: periods; a profile-routed path of at most this rough duration is
            planned whole before any sample leaves (``OptimalOptions.compare_s`` overrides).

    Threads (the plan does not depend on them):
        ahead_s: s; a refined profile-routed path of at least this static duration is
            profiled and sampled by a thread of its own ...
        ahead_blocks: sampled blocks; ... at most this many ahead of the refinement.
        feed_ahead_s: s; unrefined, a path of at least this long has its LP windows
            solved by a thread ...
        ahead_pieces: profile pieces; ... at most this many ahead of the sampling.
    """

    # route
    route_speed: float = 0.9
    route_share: float = 0.03
    route_min_s: float = 0.5
    route_tiny_s: float = 0.1
    # feed profile LP
    knot_time_s: float = 0.0015
    knot_geo: float = 0.35
    knot_block: int = 256
    collocation: int = 3
    commit_s: float = 1.0
    whole_knots: int = 1500
    ccp_max: int = 3
    ccp_tol: float = 1e-2
    ccp_max_restart: int = 12
    est_acc_factor: float = 1.5
    est_jerk_factor: float = 2.0
    est_ratio_min: float = 0.05
    est_ratio_keep: float = 0.9
    weight_floor: float = 0.01
    lp_max_iter: int = 150
    lp_first_max_iter: int = 50
    lp_tol: float = 1e-4
    limit_share: float = 0.998
    row_screen: float = 0.3
    screen_rounds: int = 4
    hat_margin: float = 1e-3
    # time law and exact sampling
    timelaw_nodes: int = 4
    timelaw_min_dip: float = 1e-3
    handover_back: tuple[int, ...] = (2, 6, 16, 40, 100, 250)
    # refinement
    refine_passes: int = 2
    full_refine_dt: float = 0.002
    refine_window: int = 60
    refine_stride: int = 20
    end_window: int = 30
    refine_newton: int = 200
    refine_skip: float = 0.99
    refine_probe: int = 30
    refine_rate: float = 0.4
    refine_pause: int = 50
    dip: float = 0.7
    # selection
    compare_samples: int = 1 << 18
    # threads
    ahead_s: float = 10.0
    ahead_blocks: int = 8
    feed_ahead_s: float = 3.0
    ahead_pieces: int = 2

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            items = v if isinstance(v, tuple) else (v,)
            if not items or not all(_number(x) and not math.isnan(x) and x >= 0 for x in items):
                raise UsageError(f"OptimalTuning.{f.name} must be a number >= 0 (or a tuple of them), got {v!r}")

    def changed(self) -> dict[str, object]:
        """The fields that differ from their defaults, by name (what ``PlanSettings``
        records)."""
        default = OptimalTuning()
        return {
            f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) != getattr(default, f.name)
        }


def _number(v: object) -> bool:
    return isinstance(v, (int, float))

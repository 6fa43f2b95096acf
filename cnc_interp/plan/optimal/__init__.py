"""The near-time-optimal planner: a feed-profile LP, an exact sampler, window refinement.

``plan_path_optimal(path, joint_map, machine, dt_s, settings)`` plans one path from rest
to rest; ``iter_path_plan_optimal`` is the same plan as a stream of ``PathPlan`` chunks
(``plan.base``'s contract: their concatenation is byte for byte the one-shot plan);
``batched_optimal`` plans a job's straight paths by ``line`` and hands the paths VPOp
plans unrefined to VPOp's compiled batch. The
knobs are ``OptimalOptions`` (``PlanSettings.optimal``); the internal tunables are its
``tuning`` (``plan.tuning.OptimalTuning``), passed down to every stage.

One module per stage, each a generator that only ever looks a bounded distance ahead:

1. ``route``: a straight path takes ``line`` (the exact discrete minimum of a rest-to-rest
   move, closed form); the feed profile where curvature or jerk limit the speed on a good
   part of a path that lasts long enough; else VPOp.
2. ``profile``: w(s) = ṡ², near-time-optimal under every axis's velocity, acceleration
   and jerk limit and the feed, as linear programs over a cubic B-spline, window by
   window (each window ends at rest and commits its first part); the LPs are solved by
   ``plan._ipm``.
3. ``sampling``: the profile's time law, one sample per period, each exact (``verify``'s
   float operations); where no position is allowed, the window solver lands a stop at
   the end, or VPOp finishes the path.
4. ``refine``: windows of samples shortened by whole periods where the discrete problem
   allows it (passes by effort and period: ``planner._refine_passes``).
5. ``select``: for a path planned whole, the shorter of the profile's plan and VPOp's.

``planner`` chains them per path; ``context`` holds the per-path context (``_Path``) and
the outcomes the decisions read. Every sample is exact at every stage. Memory: the
samples held back are those a later stage may still change.
"""

from __future__ import annotations

from .planner import batched_optimal, iter_path_plan_optimal, plan_path_optimal

__all__ = ["batched_optimal", "iter_path_plan_optimal", "plan_path_optimal"]

"""VPOp (paper 001): maximum-feed interpolation under per-axis V/A/J limits.

``plan_path_vpop`` plans one ``Path`` from rest to rest at a fixed period dt:

1. The joint positions along the path, q(s) = kin(path(s)), are tabulated as quintic
   Hermite pieces in arc length s (values, first and second s-derivatives at the
   knots, taken from ``Path.derivatives_s`` through the kinematics). Pieces are split
   until the table matches the true path to ``VPOP_TABLE_TOL`` (mm or deg) at every
   piece's quarter points; the knots are exact path points and the last one is the
   exact programmed end. The setpoints emitted are the table's positions, so they
   lie within ``VPOP_TABLE_TOL`` of the fitted path (far below the fit tolerance),
   and ``verify`` checks exactly these numbers.
2. ``step.plan_core`` (numba) runs the step loop: max step in the allowed
   set, dichotomy back to the last step from which a brake reaches rest.

Streaming (``iter_path_plan_vpop``): the loop keeps its state across calls, so where its
buffers end never changes a sample; the backtracking looks back at most
``VPOP_LOOKBACK_BRAKE_RUNS`` brake runs, and a fast-mode failure is re-planned exactly
from the last checkpoint (one every ``VPOP_CHECKPOINT_SAMPLES``; the path's start on
shorter paths, as before), so the samples before the last checkpoint are final and are
handed out while the rest of the path is planned. ``drive`` holds the compiled
driver and, for identity kinematics, the compiled preparation; ``plan_many_vpop`` plans
many short paths in one call (the same samples). ``plan_path_vpop`` is the stream
collected.

The package, one concept a module:

* ``step``: the step loop (numba), its argument bundles and its state;
* ``drive``: the compiled driver, the identity preparation and the batch of paths;
* ``planner``: the Python planner on top (``plan_path_vpop``, ``iter_path_plan_vpop``,
  ``plan_many_vpop``, ``VpopRun``).

The joint table the step loop follows (``JointTable``) is ``plan.joint_table``, shared
with the optimal and the safe planners.

Importing the package imports neither numba nor the kernels (``step``, ``drive``):
they load when a path is planned.
"""

from __future__ import annotations

from .planner import (
    VPOP_AIM_GAP_JERK_STEPS,
    VPOP_BATCH_MAX_SAMPLES,
    VPOP_BRAKE_JERK_FRACTION,
    VPOP_CHAIN_SEQUENTIAL,
    VPOP_CHECKPOINT_SAMPLES,
    VPOP_EASY_FRACTION,
    VPOP_LOOKBACK_BRAKE_RUNS,
    VPOP_STREAM_WINDOW,
    VpopFailed,
    VpopRun,
    _Prepared,
    iter_path_plan_vpop,
    iter_prepared,
    plan_many_vpop,
    plan_path_vpop,
)
from ..joint_table import (
    _GL_W,
    _GL_X,
    VPOP_TABLE_GL_ORDER,
    VPOP_TABLE_MAX_PIECE,
    VPOP_TABLE_MAX_ROUNDS,
    VPOP_TABLE_MAX_TRIES,
    VPOP_TABLE_TOL,
    JointTable,
    _eval_table,
    _hermite,
    _positions,
)

__all__ = [
    "VPOP_AIM_GAP_JERK_STEPS",
    "VPOP_BATCH_MAX_SAMPLES",
    "VPOP_BRAKE_JERK_FRACTION",
    "VPOP_CHAIN_SEQUENTIAL",
    "VPOP_CHECKPOINT_SAMPLES",
    "VPOP_EASY_FRACTION",
    "VPOP_LOOKBACK_BRAKE_RUNS",
    "VPOP_STREAM_WINDOW",
    "VPOP_TABLE_GL_ORDER",
    "VPOP_TABLE_MAX_PIECE",
    "VPOP_TABLE_MAX_ROUNDS",
    "VPOP_TABLE_MAX_TRIES",
    "VPOP_TABLE_TOL",
    "JointTable",
    "VpopFailed",
    "VpopRun",
    "_GL_W",
    "_GL_X",
    "_Prepared",
    "_eval_table",
    "_hermite",
    "_positions",
    "iter_path_plan_vpop",
    "iter_prepared",
    "plan_many_vpop",
    "plan_path_vpop",
]

"""Planning: fitted paths + machine -> setpoints every dt (``Trajectory``).

* ``timeline.iter_timeline(items, machine, settings, start)`` plans a program as a stream
  of sample blocks in bounded memory: paths (VPOp or a paper-000 planner), rapids (VPOp
  at the axes' limits), dwells and stops on one sample clock, paths planned ahead on
  worker threads; ``timeline.plan_program`` is the same in memory (a ``Trajectory``);
* ``base`` is the planners' contract (one-shot ``PathPlan`` or a stream of chunks);
* ``vpop.plan_path_vpop`` / ``vpop.iter_path_plan_vpop`` is paper 001's maximum-feed
  interpolator for one path (streaming within the path): the package ``vpop`` holds its
  joint table (``table``), compiled step loop (``step``), compiled driver and batch
  kernel (``drive``) and the planner on top (``planner``);
* ``status`` names the compiled kernels' status codes (one set);
* ``verify.verify`` re-checks every limit from the emitted setpoints;
* ``optimality`` holds the references used to measure how close to minimum time a
  plan is.

Nothing heavy is imported here: the submodules load numpy/numba only when used.
"""

from .._stage_call import make_callable  # noqa: E402

make_callable(__name__)  # ``cnc_interp.plan(fitted, machine, ...)`` is ``api.plan``

"""Planning: fitted paths + machine -> setpoints every dt (``Trajectory``).

* ``timeline.plan_program(fit_result, machine, settings)`` plans a whole program:
  paths (VPOp or a paper-000 planner), rapids (VPOp at the axes' limits), dwells and
  stops on one sample clock;
* ``vpop.plan_path_vpop`` is paper 001's maximum-feed interpolator for one path;
* ``verify.verify`` re-checks every limit from the emitted setpoints;
* ``optimality`` holds the references used to measure how close to minimum time a
  plan is.

Nothing heavy is imported here: the submodules load numpy/numba only when used.
"""

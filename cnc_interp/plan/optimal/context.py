"""The per-path context every stage of the optimal planner reads and the outcomes they share.

``_Path`` holds one path's joint table, step limits, the exact sampler's inputs, the
tunables (``OptimalTuning``), the summary stats and the typed outcomes the decisions
read: the planned route, the fallback reason and VPOp's plan alongside the profile's
(``select``). ``_Fallback`` is raised by a stage that cannot plan the path with the
profile (VPOp plans it).
"""

from __future__ import annotations

import numpy as np

from ..settings import OptimalOptions
from ..step_limits import position_scale, step_limits
from .route import Route, _RouteInputs


def exact_inputs(table, machine, dt: float):
    """The exact sampler's and refinement's view of a ``JointTable``: the table axis-major
    (``vpop.step.Table``) and the per-period step limits (``vpop.step.Limits``)."""
    from ..vpop.step import Limits, Table

    joints = Table(table.S, np.ascontiguousarray(table.C.transpose(0, 2, 1)), table.qend)
    return joints, Limits(*step_limits(machine, dt, position_scale(table.C)))


def _options(settings) -> OptimalOptions:
    """The planner's knobs (``PlanSettings.optimal``; ``None``: the defaults)."""
    return OptimalOptions() if settings is None else settings.optimal


def _or(value, default):
    """``value`` unless it is ``None`` (a knob left at its default)."""
    return default if value is None else value


class _Path(_RouteInputs):
    """What every stage needs about one path (``inputs``: its ``_RouteInputs`` already
    made, whose table and measures it takes over)."""

    def __init__(self, path, joint_map, machine, dt, settings, inputs: _RouteInputs | None = None):
        from ..vpop.step import Feed

        if inputs is None:
            super().__init__(path, joint_map, machine, _options(settings).tuning)
        else:
            self.__dict__.update(inputs.__dict__)
        table = self.table
        self.path = path
        self.joint_map = joint_map
        self.dt = dt
        self.settings = settings
        self.n = path.n_axes
        # the exact sampler's inputs (``_track_kernels.track``)
        self.joints, self.limits = exact_inputs(table, machine, dt)
        self.vl, self.al, self.jl = self.limits
        self.tol = max(4.0 * np.spacing(max(self.L, 1.0)), 1e-7 * float(np.min(self.jl)))
        self.feed_caps = Feed(float(dt), float(self.L), self.FB, self.FV)
        self.stats = {
            "lp_iterations": 0,
            "knots": 0,
            "clamped": 0,
            "handover": -1,
            "refined_periods": 0,
            "table_pieces": int(table.C.shape[0]),
        }
        if inputs is not None:
            self.stats.update(inputs.stats)  # the route's measures, as ``_route`` left them
        self._vrun = None
        self._prep = None
        #: VPOp's plan of a path planned whole, made alongside (``select.VpopAlongside``)
        self.alongside = None
        #: VPOp could not plan this path (``sampling._vpop_stage`` planned it otherwise)
        self.vpop_failed = False
        self._refine = None
        #: the whole path is held before any sample leaves (``select._better_of``)
        self.whole = False
        #: the route the path is planned on (``_iter``, ``_vpop_stage``)
        self.planned_route: Route | None = None
        #: why the profile gave the path up to VPOp (``_Fallback``), once it has
        self.fallback: str | None = None

    def vrun(self):
        from ..vpop import VpopRun

        if self._vrun is None:
            self._vrun = VpopRun(self.table, self.path, self.machine, self.dt, self.settings, self.joint_map)
        return self._vrun

    def refine_problem(self):
        """The refinement's problem of this path (``optimal.refine.refine_problem``), built once
        for every pass and knot spacing."""
        from .refine import refine_problem

        if self._refine is None:
            self._refine = refine_problem(self.table, self.path, self.joints, self.limits, self.dt)
        return self._refine

    def prepared(self):
        """VPOp's preparation of this path on the same joint table."""
        from ..vpop import _Prepared

        if self._prep is None:
            self._prep = _Prepared(self.path, self.joint_map, self.machine, self.dt, self.settings, table=self.table)
        return self._prep


class _Fallback(Exception):
    """This path cannot be planned by the profile (VPOp plans it)."""

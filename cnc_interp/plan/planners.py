"""Registry of per-path planners: name -> ``PathPlanner`` (see ``plan.base``).

Entries are imported lazily so that importing this module stays cheap.
"""

from __future__ import annotations

from importlib import import_module

from .base import PathPlanner

#: planner name -> "module:function" of a ``PathPlanner``
_ENTRIES = {
    # placeholder for H3b to merge: VPOp's per-path planner
    "vpop": "cnc_interp.plan.vpop:plan_path_vpop",
    # near-time-optimal: feed-profile LP + exact sampler (issue 13)
    "optimal": "cnc_interp.plan.optimal:plan_path_optimal",
    # paper 000 (de Santiago-Perez et al. 2010)
    "constant": "cnc_interp.plan.paper000.constant:plan_path_constant",
    "variable": "cnc_interp.plan.paper000.variable:plan_path_variable",
}


def get_planner(name: str) -> PathPlanner:
    """The per-path planner function registered as ``name`` (KeyError if unknown)."""
    module, func = _ENTRIES[name].split(":")
    return getattr(import_module(module), func)


PLANNER_NAMES = tuple(_ENTRIES)

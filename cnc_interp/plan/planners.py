"""Registry of per-path planners: name -> ``PathPlanner`` and its streaming form
(see ``plan.base``).

Entries are imported lazily so that importing this module stays cheap. A planner
without a registered streaming form streams one chunk per path (``base.one_chunk``).
"""

from __future__ import annotations

from importlib import import_module

from .base import IterPathPlanner, PathPlanner, one_chunk

#: planner name -> "module:function" of a ``PathPlanner``
_ENTRIES = {
    # placeholder for H3b to merge: VPOp's per-path planner
    "vpop": "cnc_interp.plan.vpop:plan_path_vpop",
    # near-time-optimal: feed-profile LP + exact sampler
    "optimal": "cnc_interp.plan.optimal:plan_path_optimal",
    # paper 000 (de Santiago-Perez et al. 2010)
    "constant": "cnc_interp.plan.paper000.constant:plan_path_constant",
    "variable": "cnc_interp.plan.paper000.variable:plan_path_variable",
}

#: planner name -> "module:function" of its ``IterPathPlanner`` (streams within a path)
_ITER_ENTRIES = {
    "vpop": "cnc_interp.plan.vpop:iter_path_plan_vpop",
    "optimal": "cnc_interp.plan.optimal:iter_path_plan_optimal",
}


def _load(entry: str):
    module, func = entry.split(":")
    return getattr(import_module(module), func)


def get_planner(name: str) -> PathPlanner:
    """The per-path planner function registered as ``name`` (KeyError if unknown)."""
    return _load(_ENTRIES[name])


def get_path_iterator(name: str) -> IterPathPlanner:
    """The streaming form of planner ``name``: its own generator when it has one (it
    then has ``streams = True``), else the one-shot planner as one chunk per path."""
    entry = _ITER_ENTRIES.get(name)
    if entry is None:
        return one_chunk(get_planner(name))
    it = _load(entry)
    if not hasattr(it, "streams"):
        it.streams = True
    return it


PLANNER_NAMES = tuple(_ENTRIES)

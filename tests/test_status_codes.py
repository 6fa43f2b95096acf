"""One status-code set for the compiled kernels (``plan.status``)."""

from __future__ import annotations

import importlib

import pytest

from cnc_interp.plan.status import Status

KERNEL_MODULES = [
    "cnc_interp.plan.vpop.step",
    "cnc_interp.plan.vpop.drive",
    "cnc_interp.plan._track_kernels",
    "cnc_interp.plan._table_kernels",
    "cnc_interp.plan._refine_kernels",
    "cnc_interp.plan._ipm",
]


@pytest.mark.parametrize("name", KERNEL_MODULES)
def test_a_kernel_module_uses_the_shared_codes(name):
    """A status a kernel module names has the shared value (a module of its own codes,
    where OK = 0 could mean another module's NEED_REF, fails here)."""
    mod = importlib.import_module(name)
    named = [m for m in Status.__members__ if hasattr(mod, m)]
    assert named, f"{name} names no status"
    for m in named:
        value = getattr(mod, m)
        assert type(value) is int and value == Status[m].value, f"{name}.{m} = {value!r}"


def test_the_codes_are_distinct_and_named():
    values = [s.value for s in Status]
    assert len(set(values)) == len(values)
    assert Status(Status.NEED_REF.value).name == "NEED_REF"

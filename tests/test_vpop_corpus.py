"""Corpus programs planned on a LinuxCNC configuration: within limits or a clear error.

A representative subset runs here (CI time); ``benchmarks/plan.py --sweep`` plans every
corpus program the same way and reports timings.
"""

import os

import pytest

from cnc_interp.errors import CncInterpError
from cnc_interp.pipeline import plan_part

from .conftest import CORPUS  # noqa: E402

INI = os.path.join(CORPUS, "configs", "axis_mm.ini")
SUBSET = [
    "arc-feed/basic_xy.ngc",
    "arc-feed/simple_arc3.ngc",
    "arc-feed/full_xz.ngc",  # arcs outside the machine's plane set: clear error
    "examples/g881.ngc",
    "nurbs-g5/nurbs-xy.ngc",
    "nurbs-g5/leto-xy.ngc",
    "examples/daisy.ngc",  # an A word on an XYZ machine: clear error
]

pytestmark = pytest.mark.corpus


@pytest.mark.parametrize("rel", SUBSET)
def test_corpus_program_plans_within_limits_or_fails_clearly(rel):
    path = os.path.join(CORPUS, rel)
    try:
        out = plan_part(path, INI)
    except CncInterpError as exc:
        msg = exc.format()
        assert ": error: " in msg and "bug:" not in msg, msg
        assert exc.exit_code == 2, msg
        return
    assert out.report.ok, out.report.format()
    traj = out.trajectory
    assert traj.n_samples >= 1
    assert (traj.s[1:] >= traj.s[:-1]).all()

"""Near-optimality: VPOp against the exact discrete minimum (LP) and a lower bound."""

import os

import numpy as np
import pytest

from cnc_interp.machine.model import Machine
from cnc_interp.plan.optimality import line_min_samples, path_lower_bound
from cnc_interp.plan.vpop import plan_path_vpop

from ._vpop_paths import circle_fun, hermite_path, line_path, random_curve
from .conftest import CORPUS

DT = 0.001
MILL = Machine(
    name="mill", axes="XYZ", vmax=[200, 200, 100], amax=[2000, 2000, 1000], jmax=[20000, 20000, 10000], dt_s=DT
)


@pytest.mark.parametrize("target,feed", [((3.0, 0.0, 0.0), 150.0), ((0.0, 0.0, 6.0), 80.0), ((4.0, 3.0, 0.0), 1000.0)])
def test_line_within_3_percent_of_the_discrete_minimum(target, feed):
    p = line_path([0, 0, 0], target, feed)
    plan = plan_path_vpop(p, None, MILL, DT)
    steps = plan.s.shape[0] - 1
    d = np.abs(np.asarray(target)) / p.length
    nz = d > 0
    k_min = line_min_samples(
        p.length,
        min(feed, np.min(MILL.vmax[nz] / d[nz])),
        np.min(MILL.amax[nz] / d[nz]),
        np.min(MILL.jmax[nz] / d[nz]),
        DT,
        guess=steps,
    )
    # the LP optimum is a true minimum: nothing that passes verify can be faster
    assert steps >= k_min
    assert steps <= 1.03 * k_min + 1, (steps, k_min)


def test_lp_minimum_of_a_tiny_move_is_known():
    # 1 jerk step up and down: s = 0, e, e needs |d3| = 2e <= J dt^3 -> one step
    e = 0.5 * 20000 * DT**3
    assert line_min_samples(e, 200, 2000, 20000, DT) == 1
    assert line_min_samples(1.01 * e, 200, 2000, 20000, DT) == 2


@pytest.mark.parametrize(
    "make",
    [
        lambda: hermite_path(circle_fun(8.0), 12, 300.0),
        lambda: hermite_path(random_curve(np.random.default_rng(5)), 8, 150.0),
        lambda: line_path([0, 0, 0], [50, 20, 0], 120.0),
    ],
)
def test_lower_bound_is_below_the_plan(make):
    p = make()
    plan = plan_path_vpop(p, None, MILL, DT)
    t = (plan.s.shape[0] - 1) * DT
    lb = path_lower_bound(p, None, MILL, n_grid=800)
    assert 0 < lb <= t
    # jerk costs time, but not an order of magnitude on these
    assert t / lb < 2.0


TRIDENT = os.path.join(CORPUS, "nurbs-g5", "trident-xy.ngc")


@pytest.mark.corpus
def test_trident_on_the_mikron_is_within_3_percent_of_a_lower_bound():
    from cnc_interp.pipeline import plan_part
    from cnc_interp.plan.optimality import program_lower_bound

    out = plan_part(TRIDENT, "mikron-ucp710", dt_s=0.001)
    assert out.report.ok
    lb = program_lower_bound(out, n_grid=1000)
    ratio = out.trajectory.duration_s / lb
    assert 1.0 <= ratio <= 1.03, ratio

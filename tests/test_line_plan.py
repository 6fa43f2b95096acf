"""The exact plan of a straight path from rest to rest (``optimal.line``): its profile is
the linear program's optimum, it takes the discrete minimum of periods, every limit
holds under verify's arithmetic, and only straight paths take it."""

import math

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from cnc_interp.machine.model import Machine
from cnc_interp.plan import _line_kernels as K
from cnc_interp.plan.optimal import plan_path_optimal
from cnc_interp.plan.optimal.line import plan_lines
from cnc_interp.plan.optimality import line_min_samples
from cnc_interp.plan.verify import verify_arrays
from cnc_interp.plan.vpop import plan_many_vpop

from ._vpop_paths import circle_fun, hermite_path, line_path

DT = 0.001
MILL = Machine(
    name="mill", axes="XYZ", vmax=[200, 150, 100], amax=[2000, 1500, 3000], jmax=[50000, 20000, 80000], dt_s=DT
)


def _lp_max_distance(n: int, a: float, v: float) -> float:
    """The furthest an n-period rest-to-rest profile goes with third differences <= 1,
    second <= a and first <= v (rest held before and after), by HiGHS."""
    from scipy.optimize import linprog

    rows, rhs = [], []

    def row(terms):
        r = np.zeros(n)
        for k, w in terms:
            if 1 <= k <= n:
                r[k - 1] += w
        return r

    for k in range(1, n + 3):
        r = row([(k, 1.0), (k - 1, -2.0), (k - 2, 1.0)])
        rows += [r, -r]
        rhs += [1.0, 1.0]
    for k in range(1, n + 2):
        r = row([(k, 1.0), (k - 1, -1.0)])
        rows += [r, -r]
        rhs += [a, a]
    res = linprog(-np.ones(n), A_ub=np.array(rows), b_ub=np.array(rhs), bounds=[(0.0, v)] * n, method="highs")
    assert res.status == 0
    return -res.fun


def test_lobe_sum_is_the_sum_it_names():
    rng = np.random.default_rng(3)
    for c, a in zip(rng.uniform(0, 40, 300), np.exp(rng.uniform(-1.5, 3, 300))):
        want = sum(max(0.0, min(k, a, c - k)) for k in range(1, math.ceil(c) + 1))
        assert abs(K.lobe_sum(c, a) - want) <= 1e-9 * max(1.0, want), (c, a)


@pytest.mark.parametrize("seed", range(3))
def test_profile_is_the_linear_programs_optimum_and_feasible(seed):
    rng = np.random.default_rng(seed)
    out = np.empty(200)
    for _ in range(60):
        n = int(rng.integers(1, 80))
        a = float(np.exp(rng.uniform(np.log(0.3), np.log(40))))
        v = float(np.exp(rng.uniform(np.log(0.3), np.log(500))))
        total = K.speeds(n, a, v, out)
        d = out[:n]
        x = np.concatenate([[0.0, 0.0, 0.0], d, [0.0, 0.0, 0.0]])
        assert np.all(d >= 0) and d.max() <= v * (1 + 1e-12)
        assert np.abs(np.diff(x)).max() <= a * (1 + 1e-12)
        assert np.abs(np.diff(x, 2)).max() <= 1 + 1e-12
        best = _lp_max_distance(n, a, v)
        assert total >= best * (1 - 1e-9), (n, a, v, total, best)


@pytest.mark.parametrize(
    "length,feed,machine",
    [(0.123, 400.0, MILL), (3.07, 150.0, MILL), (100.3, 83.3, MILL), (12.3, 1e9, MILL), (0.0207, 5.0, MILL)],
)
def test_a_line_takes_the_discrete_minimum_of_periods(length, feed, machine):
    # lengths off the knife edge where D(N) is the length exactly: there the limits'
    # 1e-10 shrink for rounding costs the period that a plan exactly at the limits saves
    p = line_path([0, 0, 0], [length, 0, 0], feed)
    plan = plan_path_optimal(p, None, machine, DT)
    assert plan.stats["route"] == "line"
    rep = verify_arrays(plan.q, DT, machine.vmax, machine.amax, machine.jmax)
    assert rep.ok, rep.format()
    assert_array_equal(plan.q[0], p.start)
    assert_array_equal(plan.q[-1], p.end)
    assert plan.s[0] == 0.0 and plan.s[-1] == p.length
    assert np.all(np.diff(plan.s) >= 0)
    best = line_min_samples(length, min(feed, machine.vmax[0]), machine.amax[0], machine.jmax[0], DT)
    assert plan.s.shape[0] - 1 == best


@pytest.mark.parametrize("seed", range(4))
def test_random_lines_hold_every_limit_and_never_lose_to_vpop(seed):
    rng = np.random.default_rng(40 + seed)
    paths = []
    for i in range(40):
        a = rng.uniform(-300, 300, 3)
        b = a + rng.normal(0, 10 ** rng.uniform(-3, 2), 3) * (rng.random(3) < 0.8)
        feed = float(10 ** rng.uniform(0, 3)) if rng.random() < 0.8 else np.inf
        paths.append(line_path(a, b, feed, line=i + 1, rapid=not np.isfinite(feed)))
    plans = plan_lines(paths, MILL, DT)
    vpop = plan_many_vpop(paths, MILL, DT)
    taken = 0
    for p, got, ref in zip(paths, plans, vpop):
        if p.length <= 1e-12:
            assert got is None
            continue
        assert got is not None
        taken += 1
        rep = verify_arrays(got.q, DT, MILL.vmax, MILL.amax, MILL.jmax)
        assert rep.ok, rep.format()
        assert not np.isnan(got.q).any()
        assert_array_equal(got.q[0], p.start)
        assert_array_equal(got.q[-1], p.end)
        speed = np.linalg.norm(np.diff(got.q, axis=0), axis=1) / DT
        assert speed.max() <= p.feed_mm_s[0] * (1 + 1e-9)
        assert got.s.shape[0] <= ref.s.shape[0]
    assert taken >= 30


def test_only_straight_paths_take_the_line_plan():
    bent = line_path([0, 0, 0], [5, 0, 0], 100.0)
    coef = bent.coef.copy()
    coef[0, 2, 1] = 1e-6  # a micrometre off the chord at the end: not straight
    curved = type(bent)(axes="XYZ", breaks=bent.breaks, coef=coef, line=[1], feed_mm_s=[100.0])
    circle = hermite_path(circle_fun(4.0, turns=0.5, z_per_turn=0.0), 8, 100.0)
    # two collinear segments at one feed are one line; at two feeds they are not
    two = np.zeros((2, 6, 3))
    two[0, 0], two[0, 1] = [0, 0, 0], [1, 2, 0]
    two[1, 0], two[1, 1] = [1, 2, 0], [3, 6, 0]
    chain = type(bent)(axes="XYZ", breaks=np.array([0.0, 1.0, 2.0]), coef=two, line=[1, 2], feed_mm_s=[50.0, 50.0])
    feeds = type(bent)(axes="XYZ", breaks=np.array([0.0, 1.0, 2.0]), coef=two, line=[1, 2], feed_mm_s=[50.0, 80.0])
    got = plan_lines([bent, curved, circle, chain, feeds], MILL, DT)
    assert [g is not None for g in got] == [True, False, False, True, False]
    for path in (curved, circle, feeds):
        assert plan_path_optimal(path, None, MILL, DT).stats["route"] != "line"

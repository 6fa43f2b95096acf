"""The optimal planner's parts: the banded LP solver, the B-spline basis, the feed profile,
the time law and the window refinement, each against an independent reference."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from cnc_interp.plan import _feed_kernels as FK
from cnc_interp.plan._ipm import (
    BREAKDOWN,
    OK,
    _band_cholesky,
    _band_solve,
    band4_cholesky,
    band4_solve1,
    band4_solve2,
    lp_solve,
)
from cnc_interp.machine.model import Machine
from cnc_interp.plan.safe import scurve
from cnc_interp.plan.verify import verify_arrays
from cnc_interp.plan.vpop import plan_path_vpop

from ._vpop_paths import circle_fun, hermite_path, line_path

MILL = Machine(
    name="mill", axes="XYZ", vmax=[200, 200, 200], amax=[2000, 2000, 2000], jmax=[50000, 50000, 50000], dt_s=0.001
)
UCP = Machine(
    name="ucp710", axes="XYZ", vmax=[500, 500, 500], amax=[2500, 3000, 2100], jmax=[5000, 5000, 50000], dt_s=0.006
)


def _random_lp(rng, n=120, W=4, per=5):
    first, coef, b = [], [], []
    for i in range(n - W + 1):
        for _ in range(per):
            first.append(i)
            coef.append(rng.normal(size=W))
            b.append(rng.uniform(0.5, 2.0))
    for i in range(n):  # a box keeps it bounded
        f = min(i, n - W)
        for sgn in (1.0, -1.0):
            c = np.zeros(W)
            c[i - f] = sgn
            first.append(f)
            coef.append(c)
            b.append(5.0)
    return np.array(first, dtype=np.int64), np.array(coef), np.array(b), rng.normal(size=n)


@pytest.mark.parametrize("seed", range(4))
def test_banded_lp_matches_highs(seed):
    from scipy.optimize import linprog
    from scipy.sparse import csr_matrix

    rng = np.random.default_rng(seed)
    first, coef, b, c = _random_lp(rng)
    n = c.shape[0]
    x = np.zeros(n)
    status, it, lam, s = lp_solve(n, first, coef, b, c, x, 100, 1e-9)
    assert status == OK and it < 60
    m = b.shape[0]
    A = csr_matrix((coef.ravel(), (np.repeat(np.arange(m), 4), (first[:, None] + np.arange(4)).ravel())), shape=(m, n))
    ref = linprog(c, A_ub=A, b_ub=b, bounds=[(None, None)] * n, method="highs")
    assert ref.status == 0
    assert c @ x == pytest.approx(ref.fun, rel=1e-7, abs=1e-7)
    assert np.max(A @ x - b) <= 1e-8


def test_band_cholesky_solves_like_numpy():
    rng = np.random.default_rng(5)
    n, W = 30, 4
    A = np.zeros((n, n))
    for i in range(n):
        for d in range(W):
            if i - d >= 0:
                A[i, i - d] = A[i - d, i] = rng.normal()
    A = A @ A.T + n * np.eye(n)  # SPD, bandwidth 2W-2: keep the band of A itself instead
    A = np.where(np.abs(np.subtract.outer(np.arange(n), np.arange(n))) < W, A, 0.0)
    A += 10 * n * np.eye(n)
    M = np.zeros((n, W))
    for i in range(n):
        for d in range(W):
            if i - d >= 0:
                M[i, d] = A[i, i - d]
    assert _band_cholesky(M, n, W)
    y = rng.normal(size=n)
    x = y.copy()
    _band_solve(M, n, W, x)
    assert_allclose(x, np.linalg.solve(A, y), rtol=1e-10)


@pytest.mark.parametrize("n", [1, 2, 3, 4, 9, 61])
def test_unrolled_band4_is_the_general_band_solver_bit_for_bit(n):
    """``band4_cholesky``/``band4_solve2`` are ``_band_cholesky``/``_band_solve`` at W = 4
    unrolled: the same bits (the planners' outputs do not change), also where a pivot
    is lost to rounding (the huge pivot)."""
    rng = np.random.default_rng(n)
    for trial in range(20):
        M = rng.normal(size=(n, 4))
        M[:, 0] = np.abs(M[:, 0]) * 4.0 + 3.0
        if trial % 5 == 4 and n > 2:
            M[n // 2, 0] = 0.0  # a lost pivot
        y, w = rng.normal(size=n), rng.normal(size=n)
        A, B = M.copy(), M.copy()
        _band_cholesky(A, n, 4)
        band4_cholesky(B, n)
        assert np.array_equal(A, B)
        ya, wa = y.copy(), w.copy()
        _band_solve(A, n, 4, ya)
        _band_solve(A, n, 4, wa)
        band4_solve2(B, n, y, w)
        assert np.array_equal(ya, y) and np.array_equal(wa, w)
        yb = ya.copy()
        _band_solve(A, n, 4, yb)
        band4_solve1(B, n, ya)
        assert np.array_equal(ya, yb)


def test_the_lp_solver_takes_rows_of_four_only():
    """The passes over the rows are compiled for W = 4 (``ROW_WIDTH``): other widths are
    refused with BREAKDOWN, not solved wrongly."""
    first, coef, b, c = _random_lp(np.random.default_rng(3), n=20, W=3)
    status, it, _, _ = lp_solve(20, first, coef, b, c, np.zeros(20), 100, 1e-9)
    assert status == BREAKDOWN and it == 0


def test_the_lp_row_kernels_are_the_numpy_bookkeeping():
    """``lp_gather`` joins two sets of rows, moves the fixed variables to the right-hand
    side and drops rows left without a free one, ``lp_take`` keeps the selected rows in
    order, ``lp_screen`` selects rows near their bound and then adds those a point
    violates: each as numpy computes it (the feed profile's LPs are those it built
    before)."""
    rng = np.random.default_rng(11)
    for _ in range(50):
        n, m = int(rng.integers(6, 40)), int(rng.integers(5, 300))
        first = rng.integers(0, n - 3, m).astype(np.int64)
        coef = rng.normal(size=(m, 4)) * (rng.uniform(size=(m, 4)) < 0.8)
        b = rng.uniform(0.5, 2.0, m) * (rng.uniform(size=m) < 0.9)  # some b = 0
        free = rng.uniform(size=n) < 0.7
        fixed = np.where(free, 0.0, rng.normal(size=n))
        idx = first[:, None] + np.arange(4)
        want_b = b - np.sum(coef * fixed[idx], axis=1)
        want_c = np.where(free[idx], coef, 0.0)
        want_keep = np.any(want_c != 0.0, axis=1)
        # the first `split` rows from one array (of which `count` are used), the rest from another
        split = int(rng.integers(0, m + 1))
        junk = int(rng.integers(0, 5))
        head = FK.Rows(
            np.concatenate((first[:split], np.zeros(junk, dtype=np.int64))),
            np.concatenate((coef[:split], rng.normal(size=(junk, 4)))),
            np.concatenate((b[:split], np.ones(junk))),
        )
        tail = FK.Rows(first[split:].copy(), coef[split:].copy(), b[split:].copy())
        got = FK.Rows(np.empty(m, dtype=np.int64), np.empty((m, 4)), np.empty(m))
        count = FK.lp_gather(head, split, tail, free, fixed, got)
        assert count == want_keep.sum()
        rows = FK.Rows(got.first[:count], got.coef[:count], got.b[:count])
        assert np.array_equal(rows.first, first[want_keep])
        assert np.array_equal(rows.b, want_b[want_keep]) and np.array_equal(rows.coef, want_c[want_keep])
        sel = rng.uniform(size=count) < 0.5
        out = FK.Rows(np.empty(sel.sum(), dtype=np.int64), np.empty((sel.sum(), 4)), np.empty(sel.sum()))
        FK.lp_take(rows, sel, int(sel.sum()), out)
        assert np.array_equal(out.first, rows.first[sel]) and np.array_equal(out.coef, rows.coef[sel])
        assert np.array_equal(out.b, rows.b[sel])
        first, want_b, want_c, idx = first[want_keep], want_b[want_keep], want_c[want_keep], idx[want_keep]
        m = count
        # screening at a point, then the rows another point violates
        x0, x1 = rng.uniform(0.0, 1.0, n), rng.uniform(0.0, 1.5, n)
        val0 = np.sum(want_c * x0[idx], axis=1)
        active = np.empty(m, dtype=np.bool_)
        _, n_active = FK.lp_screen(rows, x0, 0.3, active, True)
        scale = np.maximum(np.abs(want_b), 1.0)  # by slack: rows with b <= 0 too
        want_active = want_b - val0 <= 0.7 * scale + 1e-12
        assert np.array_equal(active, want_active) and n_active == want_active.sum()
        val1 = np.sum(want_c * x1[idx], axis=1)
        viol = (val1 > want_b + 1e-9 * np.maximum(np.abs(want_b), 1.0)) & ~want_active
        n_viol, n_active = FK.lp_screen(rows, x1, 0.3, active, False)
        if viol.any():
            want_active |= viol | (want_b - val1 <= 0.7 * scale)
        assert n_viol == viol.sum() and np.array_equal(active, want_active)
        assert n_active == want_active.sum()


def test_cubic_basis_matches_scipy():
    from scipy.interpolate import BSpline

    rng = np.random.default_rng(1)
    br = np.sort(np.concatenate(([0.0, 10.0], rng.uniform(0, 10, 9))))
    t = np.concatenate(([0.0] * 3, br, [10.0] * 3))
    n = t.shape[0] - 4
    x = np.concatenate(([0.0], np.sort(rng.uniform(0, 10, 40)), [10.0]))
    first = np.empty(x.shape[0], dtype=np.int64)
    B = np.empty((x.shape[0], 3, 4))
    FK.cubic_basis(t, n, x, first, B)
    c = rng.normal(size=n)
    sp = BSpline(t, c, 3)
    for d in range(3):
        mine = np.array([B[k, d] @ c[first[k] : first[k] + 4] for k in range(x.shape[0])])
        assert_allclose(mine, sp(x, d), atol=1e-12 * (1 + np.abs(sp(x, d)).max()))


def _profile_time(path, machine, dt, tuning=None):
    from cnc_interp.plan.optimal.profile import FeedProfileBuilder, spline_values
    from cnc_interp.plan.vpop import JointTable

    b = FeedProfileBuilder(JointTable(path, None), path, machine, dt, tuning)
    total = 0.0
    for piece in b.windows():
        s = np.linspace(piece.s0, piece.s1, 40001)
        v = np.sqrt(np.maximum(spline_values(piece.knots, piece.coef, s), 0.0))
        total += np.sum(2.0 * np.diff(s) / np.maximum(v[1:] + v[:-1], 1e-300))
    return total


def test_profile_of_a_line_is_the_s_curve():
    # along a line the profile, its convex-concave iterations run to convergence, is the
    # continuous time-optimal S-curve (the sampled start and stop may each start a period
    # earlier: w'(0) <= 2 J dt)
    import dataclasses

    from cnc_interp.plan.tuning import OptimalTuning

    L, F = 100.0, 83.3
    p = line_path([0, 0, 0], [L, 0, 0], F)
    share = 0.998  # the LP's own margin on acceleration and jerk
    ph = scurve(L, F, 2000.0 * share, 50000.0 * share)
    t_cont = sum(d for d, _ in ph)
    T = _profile_time(p, MILL, 0.001, dataclasses.replace(OptimalTuning(), ccp_max=12, ccp_tol=1e-6))
    assert t_cont - 0.004 <= T <= t_cont * 1.002, (T, t_cont)


@pytest.mark.parametrize(
    ("level", "expected"),
    [(0.3, 0.3), (0.95, 1.0), (0.01, 0.05), (1.7, 1.0)],
)
def test_the_windows_ratio_is_the_solutions_median_level_under_the_estimate(level, expected):
    # _ratio: median of w / estimate over the committed knot intervals, floored at
    # est_ratio_min, 1 above est_ratio_keep (a solution above the estimate too)
    from cnc_interp.plan.optimal.profile import FeedProfileBuilder
    from cnc_interp.plan.tuning import OptimalTuning
    from cnc_interp.plan.vpop import JointTable

    tuning = OptimalTuning(est_ratio_min=0.05, est_ratio_keep=0.9)  # the cases' floor and ceiling
    p = line_path([0, 0, 0], [100.0, 0, 0], 83.3)
    b = FeedProfileBuilder(JointTable(p, None), p, MILL, 0.001, tuning)
    b._br = list(np.linspace(0.0, 100.0, 21))
    est = 1000.0 + 100.0 * np.sin(np.linspace(0.0, 100.0, 1001))  # any positive estimate
    b.estimate = lambda x: np.interp(x, np.linspace(0.0, 100.0, 1001), est)
    tk = np.concatenate(([0.0] * 3, b._br, [100.0] * 3))
    # a constant spline (w = c everywhere) set to `level` of the estimate's median on 2..12
    mids = 0.5 * (np.asarray(b._br[2:12]) + np.asarray(b._br[3:13]))
    c = level * float(np.median(b.estimate(mids)))
    coef = np.full(tk.shape[0] - 4, c)
    got = b._ratio(tk, coef, 2, 12)
    if expected == level:
        # the median of c / est is c / median(est) only for an odd count: compare with it
        assert_allclose(got, float(np.median(c / b.estimate(mids))), rtol=1e-12)
        assert 0.25 < got < 0.35
    else:
        assert got == expected


def test_profile_holds_the_centripetal_limit_on_a_circle():
    # r = 10 mm, no feed limit: the profile cruises near sqrt(A r) = 141 mm/s
    p = hermite_path(circle_fun(10.0, turns=1.0), 16, 1000.0)
    T = _profile_time(p, MILL, 0.001)
    cruise = p.length / np.sqrt(2000.0 * 10.0)
    assert cruise < T < 1.25 * cruise


def _feed_numpy(b, x):
    """The segment feed at x: the builder's step function (feed_values over feed_breaks)."""
    i = np.clip(np.searchsorted(b.feed_breaks, x, side="right") - 1, 0, b.feed_values.shape[0] - 1)
    return b.feed_values[i]


def _start_curve_numpy(x, c, dt):
    k = np.maximum(np.cbrt(6.0 * np.maximum(x, 0.0) / c) - 1.0, 0.0)
    for _ in range(3):
        f = c * k * (k + 1) * (k + 2) / 6.0 - x
        k = np.maximum(k - f / np.maximum(c * (3 * k * k + 6 * k + 2) / 6.0, 1e-300), 0.0)
    v = c * k * (k + 1) / (2.0 * dt)
    return v * v


@pytest.mark.parametrize("seed", range(4))
def test_the_knot_placements_estimate_is_its_formula(seed):
    """``point_estimates`` (the static speeds inflated, the sampled start and stop) and
    ``reach_envelope`` (the speeds the tangent's acceleration and jerk reach from the
    slow points, both ways, from a carried point) against numpy's arithmetic of the
    feed profile's docstrings, on random curves with their ends."""
    from cnc_interp.plan.optimal.profile import FeedProfileBuilder
    from cnc_interp.plan.vpop import JointTable

    from ._vpop_paths import random_curve

    rng = np.random.default_rng(40 + seed)
    p = hermite_path(random_curve(rng, scale=15.0), 5, float(rng.uniform(20, 300)))
    table = JointTable(p, None)
    b = FeedProfileBuilder(table, p, MILL, 0.001)
    L = table.length
    x = np.sort(np.concatenate((rng.uniform(0.0, L, 400), [0.0, 1e-6, L - 1e-6, L], 2.0 ** -np.arange(1, 30))))
    x = x[x <= L]
    est = b._raw_estimate(x)
    q1, q2, q3 = b.derivs(x)
    with np.errstate(divide="ignore"):
        wv = np.min(np.where(np.abs(q1) > 0, (b.vmax / np.abs(q1)) ** 2, np.inf), axis=1)
        wa = np.min(np.where(np.abs(q2) > 0, b.amax / np.abs(q2), np.inf), axis=1)
        wj = np.min(np.where(np.abs(q3) > 0, (b.jmax / np.abs(q3)) ** (2.0 / 3.0), np.inf), axis=1)
        g = np.abs(q1)
        at = np.min(np.where(g > 1e-12, b.amax / g, np.inf), axis=1)
        jt = np.min(np.where(g > 1e-12, b.jmax / g, np.inf), axis=1)
    f = _feed_numpy(b, x)
    w = np.minimum.reduce([wv, f * f, b.tuning.est_acc_factor**2 * wa, b.tuning.est_jerk_factor**2 * wj])
    w = np.minimum(w, _start_curve_numpy(x, b.jt0 * 0.001**3, 0.001))
    w = np.minimum(w, _start_curve_numpy(L - x, b.jt1 * 0.001**3, 0.001))
    assert_allclose(est.w, w, rtol=1e-12)
    assert est.w[0] == 0.0 and est.w[-1] == 0.0  # rest at both ends
    assert_allclose(est.w_jerk, b.tuning.est_jerk_factor**2 * wj, rtol=1e-12)
    assert_allclose(est.k2, np.max(np.abs(q2), axis=1), rtol=1e-15)
    assert_allclose(est.k3, np.max(np.abs(q3), axis=1), rtol=1e-15)
    assert_allclose(est.at, at, rtol=1e-15) and assert_allclose(est.jt, jt, rtol=1e-15)
    # the envelope of the points past a third of the path, from rest carried from there
    sel = (x > L / 3) & (x < L)
    xs, ws = x[sel], est.w[sel]
    carry = (L / 3, 0.0)
    A = b.tuning.est_acc_factor * float(np.max(est.at[sel]))
    J = b.tuning.est_jerk_factor**2 * float(np.max(est.jt[sel]))
    xx, ww = np.concatenate(([carry[0]], xs)), np.minimum(np.concatenate(([carry[1]], ws)), 1e300)
    ww = np.minimum(ww, np.minimum.accumulate(ww - 2 * A * xx) + 2 * A * xx)
    ww = np.minimum(ww, (np.minimum.accumulate((ww + 2 * A * xx)[::-1]) - 2 * A * xx[::-1])[::-1])
    c = 2.1213203435596424 * np.sqrt(J)
    u = ww**0.75
    u = np.minimum(u, np.minimum.accumulate(u - c * xx) + c * xx)
    u = np.minimum(u, (np.minimum.accumulate((u + c * xx)[::-1]) - c * xx[::-1])[::-1])
    want = np.minimum(ww, np.maximum(u, 0.0) ** (4.0 / 3.0))[1:]
    sub = FK.Estimates(*(a[sel] for a in est))
    got = np.empty(xs.shape[0])
    FK.reach_envelope(xs, ws, sub.at, sub.jt, b.tuning.est_acc_factor, b.tuning.est_jerk_factor**2, *carry, got)
    assert_allclose(got, want, rtol=1e-12)
    assert np.all(got <= ws) and got[0] < 0.5 * ws[0]  # the rest carried in shows


def test_the_estimates_of_known_probes_are_kept_bit_for_bit():
    # the knot placement's refinement evaluates only its new probes: every field at every
    # point is the bits of evaluating all of them
    from cnc_interp.plan.optimal.profile import FeedProfileBuilder
    from cnc_interp.plan.vpop import JointTable

    from ._vpop_paths import random_curve

    rng = np.random.default_rng(7)
    p = hermite_path(random_curve(rng, scale=15.0), 5, 120.0)
    table = JointTable(p, None)
    b = FeedProfileBuilder(table, p, MILL, 0.001)
    x = np.unique(np.concatenate((rng.uniform(0.0, table.length, 300), [0.0, table.length])))
    x0 = np.sort(rng.choice(x, 120, replace=False))
    e0 = b._raw_estimate(x0)
    # a known point that is no probe is ignored (its "estimate" here is garbage)
    stray = 0.5 * (x[3] + x[4])
    at = int(np.searchsorted(x0, stray))
    x0_more = np.insert(x0, at, stray)
    e0_more = FK.Estimates(*(np.insert(f, at, -7.0) for f in e0))
    for known in ((x0, e0), (x0_more, e0_more)):
        got = FK._estimates_kept(b.S, b.C, x, b._est_in, *known)
        for name, g, w in zip(FK.Estimates._fields, got, b._raw_estimate(x)):
            assert g.tobytes() == w.tobytes(), name
    none = b._raw_estimate(np.zeros(0))
    got = FK._estimates_kept(b.S, b.C, x, b._est_in, np.zeros(0), none)
    assert all(g.tobytes() == w.tobytes() for g, w in zip(got, b._raw_estimate(x)))


@pytest.mark.parametrize("seed", range(3))
def test_a_knot_blocks_probes_are_as_dense_as_the_spacing_the_estimate_wants(seed):
    # _feed_kernels.knot_probes on a path's first block: every table point and midpoint
    # of the block is a probe, the spacing wanted is its formula of the enveloped
    # estimate (time of motion at that speed, geometry, the least step from rest), and
    # no two probes are further apart than a quarter of the spacing at either
    from cnc_interp.plan.optimal.profile import FeedProfileBuilder
    from cnc_interp.plan.vpop import JointTable

    from ._vpop_paths import random_curve

    rng = np.random.default_rng(90 + seed)
    p = hermite_path(random_curve(rng, scale=15.0), 9, float(rng.uniform(50, 300)))
    table = JointTable(p, None)
    b = FeedProfileBuilder(table, p, MILL, 0.001)
    S, m = b.S, b.S.shape[0] - 1
    p1, p2 = min(b.tuning.knot_block, m), min(2 * b.tuning.knot_block, m)
    no_known = (np.zeros(0), b._raw_estimate(np.zeros(0)))
    probe, w, h, ahead, ea = FK.knot_probes(S, b.C, b._est_in, b._knot_inputs(), 0, p1, p2, np.inf, 0.0, *no_known)
    assert np.all(np.diff(probe) > 0) and probe[0] == S[0] and probe[-1] == S[p1]
    assert np.all(np.isin(S[: p1 + 1], probe)) and np.all(np.isin(0.5 * (S[:p1] + S[1 : p1 + 1]), probe))
    est = b._raw_estimate(probe)
    assert np.all(w <= est.w) and w[0] == 0.0  # an envelope only lowers; rest at the start
    want = np.minimum(b.knot_time_s * np.sqrt(np.maximum(w, 0.0)), b.tuning.knot_geo / np.maximum(est.k2, 1e-300))
    want = np.minimum(want, b.tuning.knot_geo / np.sqrt(np.maximum(est.k3, 1e-300)))
    want = np.maximum(want, np.where(probe < 0.5 * b.L, b.hmin0, b.hmin1))
    assert_allclose(h, want, rtol=1e-15)
    assert np.all(np.diff(probe) <= 0.25 * np.minimum(h[:-1], h[1:]) * (1 + 1e-12))
    # the look-ahead: the next block's table points and midpoints, with their estimates
    assert_allclose(ahead, np.sort(np.concatenate((S[p1 + 1 : p2 + 1], 0.5 * (S[p1:p2] + S[p1 + 1 : p2 + 1])))), rtol=0)
    assert all(g.tobytes() == e.tobytes() for g, e in zip(ea, b._raw_estimate(ahead)))


@pytest.mark.parametrize("seed", range(4))
def test_a_windows_first_lp_is_linearised_where_the_previous_solution_meets_its_rows(seed):
    # _feasible_hat, against the LP's own rows (lp_rows): a window's solution ending at
    # rest meets every jerk row linearised at the points it returns over its braking
    # part; each point is the target where that allows it, else as near it as allows it
    from cnc_interp.plan.optimal.profile import FeedProfileBuilder, _Window
    from cnc_interp.plan.vpop import JointTable

    from ._vpop_paths import random_curve

    rng = np.random.default_rng(50 + seed)
    p = hermite_path(random_curve(rng, scale=15.0), 5, float(rng.uniform(40, 300)))
    b = FeedProfileBuilder(JointTable(p, None), p, MILL, 0.001)
    b._breaks_upto(60)
    b1 = min(40, len(b._br) - 4)
    coef, tk, _ = b._solve(0, b1, False, np.zeros(0), None)
    prev = _Window(tk, coef, b._br[b1 - 12], b._br[b1], 1.0)
    x, q1, q2, q3 = b._collocation(b1 - 12, b1)
    x, q1, q2, q3 = x[:-1], q1[:-1], q2[:-1], q3[:-1]  # the rest itself has no jerk row
    target = b.estimate(x) * rng.uniform(0.5, 20.0, x.shape[0])
    floor = 1e-9 * float(np.max(target))
    hat = b._feasible_hat(prev, x, q1, q2, q3, target, floor)

    def jerk_rows(w_hat):
        # each point's largest jerk row at the solution (scale 1: the variables are coef)
        nc = coef.shape[0]
        first = np.empty(x.shape[0], dtype=np.int64)
        B = np.empty((x.shape[0], 3, 4))
        FK.cubic_basis(tk, nc, x, first, B)
        n, K = int(b.moving.sum()), x.shape[0]
        m = K * (1 + 4 * n)
        rows = FK.Rows(np.empty(m, dtype=np.int64), np.empty((m, 4)), np.empty(m))
        pts = FK.Collocation(first, B, q1, q2, q3)
        lim = FK.AxisLimits(b.moving, b.amax, b.jmax)
        r = FK.lp_rows(pts, lim, np.full(K, np.inf), w_hat, np.ones(K, dtype=np.bool_), np.ones(nc), rows)
        assert r == m
        at = coef[rows.first[:, None] + np.arange(4)[None, :]]
        vals = np.einsum("kj,kj->k", rows.coef, at).reshape(K, -1)
        # per point: the velocity row, then per axis two acceleration and two jerk rows
        return vals[:, 1:].reshape(x.shape[0], n, 4)[:, :, 2:].max(axis=(1, 2))

    own = jerk_rows(np.maximum(spline_values_of(prev, x), floor))
    fits = own <= 1.0 - b.tuning.hat_margin
    assert fits.mean() > 0.5
    at_hat = jerk_rows(hat)
    assert np.all(at_hat[fits] <= 1.0 - b.tuning.hat_margin + 1e-9)
    at_target = jerk_rows(np.maximum(target, floor))
    free = at_target <= 1.0 - b.tuning.hat_margin
    assert_allclose(hat[free], np.maximum(target, floor)[free], rtol=0, atol=0)
    cut = fits & ~free
    assert cut.sum() >= 3  # the target's rows cut the solution off somewhere
    # held at the edge: a step further towards the target leaves the solution outside
    step = hat + 1e-6 * (np.maximum(target, floor) - hat)
    assert np.all(jerk_rows(step)[cut] > 1.0 - b.tuning.hat_margin - 1e-12)


def spline_values_of(window, x):
    from cnc_interp.plan.optimal.profile import spline_values

    xc = np.clip(x, window.knots[3], window.knots[-4])
    return np.maximum(spline_values(window.knots, window.coef, xc), 0.0)


@pytest.mark.parametrize("seed", range(3))
def test_the_time_law_integrates_one_over_the_speed(seed):
    """``time_nodes``: each node interval's time is ∫ ds/√w (against scipy's adaptive
    quadrature; an interval at rest by the substitution s = a + u²)."""
    from scipy.integrate import quad
    from scipy.interpolate import BSpline

    from cnc_interp.plan.optimal.sampling import time_law
    from cnc_interp.plan.tuning import OptimalTuning

    rng = np.random.default_rng(seed)
    br = np.linspace(0.0, 20.0, 11)
    knots = np.concatenate(([0.0] * 3, br, [20.0] * 3))
    coef = rng.uniform(100.0, 400.0, knots.shape[0] - 4)
    coef[0] = 0.0  # rest at the start: w ~ s there
    law = time_law(knots, coef, 0.0, 20.0, OptimalTuning())
    spline = BSpline(knots, coef, 3)
    for i in range(law.s.shape[0] - 1):
        a, b = law.s[i], law.s[i + 1]
        want = quad(lambda s: 1.0 / np.sqrt(max(spline(s), 1e-300)), a, b, limit=200)[0]
        assert law.dt[i] == pytest.approx(want, rel=2e-6 if i == 0 else 1e-9)
    assert_allclose(law.w, np.maximum(spline(law.s), 0.0), rtol=1e-12, atol=1e-9)
    assert_allclose(law.a, 0.5 * spline.derivative()(law.s), rtol=1e-9, atol=1e-9)


def test_time_law_hermite_is_consistent():
    from cnc_interp.plan import _track_kernels as TK

    ns = np.array([0.0, 1.0, 3.0, 4.0])
    nt = np.array([0.0, 1.0, 2.0, 3.0])
    nv = np.array([0.0, 2.0, 2.0, 0.0])
    na = np.array([2.0, 0.0, 0.0, -2.0])
    for t in (0.0, 0.3, 1.0, 1.7, 2.5, 3.0):
        s, _ = TK.ref_s_of_t(ns, nt, nv, na, 4, t, 0)
        back, _ = TK.ref_t_of_s(ns, nt, nv, na, 4, s, 0)
        assert back == pytest.approx(t, abs=1e-12)
    assert TK.ref_s_of_t(ns, nt, nv, na, 4, 2.0, 0)[0] == 3.0


@pytest.mark.parametrize("seed", range(6))
def test_the_ccp_line_search_takes_the_least_time_step(seed):
    # the trapezoid time of w0 + alpha (w1 - w0) against a fine grid of alpha
    from cnc_interp.plan.optimal.profile import _line_search

    rng = np.random.default_rng(seed)
    x = np.sort(rng.uniform(0.0, 10.0, 60))
    w0 = rng.uniform(1.0, 100.0, 60)
    w1 = np.maximum(w0 + rng.normal(0.0, 40.0, 60), 0.5)

    def time(a):
        v = np.sqrt(np.maximum(w0 + a * (w1 - w0), 0.0))
        return np.sum(2.0 * np.diff(x) / (v[1:] + v[:-1]))

    grid = np.linspace(0.0, 1.0, 20001)
    times = np.array([time(a) for a in grid])
    alpha, T = _line_search(x, w0, w1, 24)
    assert 0.0 <= alpha <= 1.0
    assert_allclose(T, time(alpha), rtol=1e-12)
    assert T <= times.min() * (1 + 1e-9)


def _spiral_polygon_path():
    """A fitted spiral of 16 straight moves 5 mm long turning 9 degrees each (corners
    blended at 0.01 mm), on which the profile's speed changes at every corner."""
    from cnc_interp.fit import FitSettings, fit_program
    from cnc_interp.gcode import read_program

    pts, ang, r = [(0.0, 0.0)], 0.0, 5.0
    for _ in range(16):
        x, y = pts[-1]
        pts.append((x + r * np.cos(ang), y + r * np.sin(ang)))
        ang += np.radians(9.0)
        r *= 0.97
    text = "G21 G90 G64\n" + "".join(f"G1 X{x:.4f} Y{y:.4f} F20000\n" for x, y in pts[1:]) + "M2\n"
    prog = read_program(text.encode(), "spiral.ngc", axes="XYZ", start=[0.0, 0.0, 0.0])
    fitted = fit_program(prog, FitSettings.from_options(tol_mm=0.01, machine=MILL))
    return [p for p in fitted.items if hasattr(p, "coef")][0]


def test_more_ccp_iterations_never_lengthen_the_profile():
    # each iteration's step takes the least time between the last iterate and the LP's
    # solution, so the profile's time falls (a full step to the LP's vertex oscillates)
    import dataclasses

    from cnc_interp.plan.optimal.profile import FeedProfileBuilder, spline_values
    from cnc_interp.plan.tuning import OptimalTuning
    from cnc_interp.plan.vpop import JointTable

    p = _spiral_polygon_path()
    times = []
    for k in range(1, 7):
        tuning = dataclasses.replace(OptimalTuning(), ccp_max=k, ccp_tol=0.0)
        b = FeedProfileBuilder(JointTable(p, None), p, MILL, 0.001, tuning)
        total = 0.0
        for piece in b.windows():
            s = np.linspace(piece.s0, piece.s1, 40001)
            v = np.sqrt(np.maximum(spline_values(piece.knots, piece.coef, s), 0.0))
            total += np.sum(2.0 * np.diff(s) / np.maximum(v[1:] + v[:-1], 1e-300))
        times.append(total)
    assert all(b <= a * (1 + 1e-6) for a, b in zip(times, times[1:])), times
    assert times[-1] < times[0]


@pytest.mark.parametrize("cut", [10, 30])
def test_land_brings_a_plan_cut_short_to_rest_exactly(cut):
    # VPOp's plan of an acceleration-limited circle without its last samples: the window
    # solver lands it at rest at the end, exact, in no more samples than VPOp's stop took
    from cnc_interp.plan.optimal.context import _Path
    from cnc_interp.plan.optimal.refine import land
    from cnc_interp.plan.tuning import OptimalTuning

    dt = 0.001
    p = hermite_path(circle_fun(10.0, turns=1.0), 16, 1000.0)
    plan = plan_path_vpop(p, None, MILL, dt)
    s, q = plan.s, plan.q
    N = s.shape[0]
    ctx = _Path(p, None, MILL, dt, None)
    k = N - cut  # samples kept: 0 .. k-1
    a = k - 20
    M = N - 1 - a  # VPOp's samples from a to the one before the end
    s_a, L = float(s[a - 1]), float(p.length)

    stop = np.concatenate(([s_a], s[a : N - 1], [L]))

    def stretched(m):  # VPOp's stop on m samples (the sampler starts from its reference)
        return np.interp(np.linspace(0.0, 1.0, m + 2)[1:-1], np.linspace(0.0, 1.0, M + 2), stop)

    counts = np.zeros(2, dtype=np.int64)
    got = land(ctx.refine_problem(), s[:k], q[:k], a, M - 2, stretched, OptimalTuning(), counts)
    assert got is not None
    x, qx = got
    assert x.shape[0] <= M
    s2 = np.concatenate((s[:a], x, [L]))
    q2 = np.concatenate((q[:a], qx, q[-1:]))
    rep = verify_arrays(q2, dt, MILL.vmax, MILL.amax, MILL.jmax)
    assert rep.ok, rep.format()
    assert np.all(np.diff(s2) >= 0)
    from cnc_interp.plan.vpop import _eval_table

    assert_allclose(qx, _eval_table(ctx.table.S, ctx.table.C, x), atol=1e-12)


def test_a_profile_stuck_stopping_at_the_end_is_landed_not_handed_to_vpop():
    # an acceleration-limited circle at 1 ms: the profile's exact samples cannot stop at
    # the end; landed by the window solver the plan stays far below VPOp's
    from cnc_interp.plan.optimal import plan_path_optimal

    p = hermite_path(circle_fun(10.0, turns=1.0), 16, 1000.0)
    plan = plan_path_optimal(p, None, MILL, 0.001)
    vpop = plan_path_vpop(p, None, MILL, 0.001)
    assert plan.stats.get("landed") is True and plan.stats["handover"] == -1
    rep = verify_arrays(plan.q, 0.001, MILL.vmax, MILL.amax, MILL.jmax)
    assert rep.ok, rep.format()
    assert plan.s[-1] == p.length
    assert_allclose(plan.q[-1], [10.0, 0.0, 0.0], atol=1e-9)  # the end, where it rests
    # the continuous minimum: the circle at sqrt(A r) plus S-curve ramps
    assert plan.s.shape[0] < 0.9 * vpop.s.shape[0]


@pytest.mark.parametrize("machine", [MILL, UCP])
def test_refine_keeps_plans_exact_and_never_longer(machine):
    from cnc_interp.plan.optimal.context import _Path
    from cnc_interp.plan.optimal.refine import Refiner
    from cnc_interp.plan.vpop import plan_path_vpop

    dt = machine.dt_s
    p = hermite_path(circle_fun(15.0, turns=0.6), 8, 150.0)
    plan = plan_path_vpop(p, None, machine, dt)
    ctx = _Path(p, None, machine, dt, None)
    table = ctx.table
    ref = Refiner(ctx.refine_problem(), ctx.tuning)
    s, q = plan.s, plan.q
    saved = 0
    for a in range(1, s.shape[0] - 4, 20):
        b = min(a + 60, s.shape[0] - 1)
        s, q, d = ref.window(s, q, a, b, 30)
        saved += d
    rep = verify_arrays(q, dt, machine.vmax, machine.amax, machine.jmax)
    assert rep.ok, rep.format()
    assert np.all(np.diff(s) >= 0) and s[-1] == p.length
    assert s.shape[0] == plan.s.shape[0] - saved
    # the positions are the table's at the samples (nothing moved off the path)
    from cnc_interp.plan.vpop import _eval_table

    assert_allclose(q[:-1], _eval_table(table.S, table.C, s[:-1]), atol=1e-12)
    if machine is UCP:
        assert saved >= 1  # at 6 ms VPOp's plan always leaves a period or more


def _loose_numpy(sh, qh, a, b, moving, lim, fdt, skip):
    """The window test as numpy computes it (the reference of ``_refine_kernels.loose``)."""
    vl, al, jl = lim
    lo = max(a - 3, 0)
    q = qh[lo:b]
    if lo == 0:
        q = np.concatenate((np.repeat(qh[:1], 3, axis=0), q))
    d1 = np.diff(q, axis=0)
    d2 = np.diff(d1, axis=0)
    d3 = np.diff(d2, axis=0)
    r = np.max(np.abs(d3[:, moving]) / jl[moving], axis=1)
    r = np.maximum(r, np.max(np.abs(d2[1:, moving]) / al[moving], axis=1))
    r = np.maximum(r, np.max(np.abs(d1[2:, moving]) / vl[moving], axis=1))
    steps = np.diff(sh[max(a - 1, 0) : b])
    m = min(r.shape[0], steps.shape[0])
    return bool(np.any(np.maximum(r[-m:], steps[-m:] / fdt) < skip))


def test_a_try_starts_from_the_window_retimed_by_room():
    """``_start`` with equal shares is the uniform resample; with any shares it keeps the
    positions increasing between the fixed ends. ``_room_shares`` gives equal shares to a
    window of equal room, and the floor share to periods whose rows are at their bound."""
    from cnc_interp.plan import _refine_kernels as RK

    rng = np.random.default_rng(7)
    for _ in range(300):
        M = int(rng.integers(3, 70))
        cur = np.cumsum(rng.uniform(0.01, 1.0, M + 2))
        even = np.full(M + 1, 1.0 / (M + 1))
        want = np.interp(np.linspace(0.0, 1.0, M + 1), np.linspace(0.0, 1.0, M + 2), cur)[1:-1]
        assert_allclose(RK._start(cur, even, M - 1), want, rtol=1e-12, atol=1e-12 * cur[-1])
        share = rng.dirichlet(np.full(M + 1, 0.3))
        share = 0.9 * share + 0.1 / (M + 1)  # every period keeps some time
        x = RK._start(cur, share, M - 1)
        assert np.all(np.diff(np.concatenate(([cur[0]], x, [cur[-1]]))) > 0.0)
    # a line at constant speed (half the velocity limit): equal room everywhere
    moving = np.array([True, False])
    lim = np.array([[1.0, 1.0], [1.0, 1.0], [1.0, 1.0]])
    M = 20
    P = 0.5 * np.arange(M + 6)
    Q = np.stack([P, np.zeros_like(P)], axis=1)
    share = RK._room_shares(P, Q, moving, lim, 10.0)
    assert_allclose(share, np.full(M + 1, 1.0 / (M + 1)), rtol=1e-12)
    # the same line braking at the acceleration limit from period 10 on: room 0 there
    v = np.concatenate((np.full(13, 0.5), 0.5 - 0.01 * np.arange(1, M - 6)))
    P = np.concatenate(([0.0], np.cumsum(v)))
    Q = np.stack([P, np.zeros_like(P)], axis=1)
    lim[1, 0] = 0.01 * (1.0 + 1e-12)
    share = RK._room_shares(P, Q, moving, lim, 10.0)
    floor = RK._ROOM_FLOOR
    assert_allclose(share[13:] / share[0], floor / (RK._ROOM_CLIP + floor), rtol=1e-9)
    assert_allclose(share.sum(), 1.0)


def test_refine_kernels_match_numpy_bit_for_bit():
    """The window visit's helpers compiled (``loose``, ``dip_or_end``) give numpy's
    answers exactly: the plans do not depend on where they run."""
    from cnc_interp.plan import _refine_kernels as RK

    rng = np.random.default_rng(7)
    lim = np.array([[0.5, 0.5, 0.6], [0.3, 0.3, 0.4], [0.5, 0.5, 0.6]])  # vl, al, jl
    moving = np.array([True, False, True])
    hits = 0
    for _ in range(400):
        N = int(rng.integers(12, 90))
        steps = rng.uniform(0.0, 0.2, N - 1) * (1.0 + np.sin(np.arange(N - 1) / 3.0))
        sh = np.concatenate(([0.0], np.cumsum(steps)))
        qh = np.stack([sh, 0.0 * sh, 0.5 * sh + 1e-4 * np.sin(sh * 9.0)], axis=1)
        a = int(rng.integers(1, N - 4))
        b = int(rng.integers(a + 3, N))
        skip = float(rng.uniform(0.0, 0.5))
        got = RK.loose(sh, qh, a, b, moving, lim, 0.4, skip)
        assert got == _loose_numpy(sh, qh, a, b, moving, lim, 0.4, skip)
        hits += got
        W, done, dip = int(rng.integers(5, 60)), bool(rng.integers(0, 2)), 0.7
        if a <= 2 or (done and b >= N - 2):
            want_dip = True
        else:
            inner = np.diff(sh[a - 1 : b])
            want_dip = bool(np.min(inner) < dip * np.max(np.diff(sh[max(a - W, 1) - 1 : min(b + W, N)])))
        assert RK.dip_or_end(sh, a, b, W, done, dip) == want_dip
    assert 40 < hits < 360, hits  # both answers occur


def test_the_chunks_of_a_stream_are_its_samples_cut_once_per_block():
    # _rechunk: chunks of exactly ``chunk`` samples (the last shorter) whose concatenation
    # is the stream; a block many chunks long is copied once, not once per chunk (a path
    # planned as one block was copied again for every chunk cut from it: O(n²))
    from cnc_interp.plan.optimal.planner import _rechunk

    rng = np.random.default_rng(3)
    sizes = [1, 7, 2500, 3, 64, 0, 999, 5]
    blocks = []
    start = 0
    for n in sizes:
        s = np.arange(start, start + n, dtype=float)
        blocks.append((s, np.stack((s, -s, rng.uniform(size=n)), axis=1)))
        start += n
    chunks = list(_rechunk(iter(blocks), 64))
    assert [c[0].shape[0] for c in chunks[:-1]] == [64] * (len(chunks) - 1)
    assert 0 < chunks[-1][0].shape[0] <= 64
    assert_allclose(np.concatenate([c[0] for c in chunks]), np.arange(start, dtype=float), rtol=0, atol=0)
    assert_allclose(np.concatenate([c[1] for c in chunks]), np.concatenate([b[1] for b in blocks]), rtol=0, atol=0)
    # the 2500-sample block's chunks (samples 8..2508) are cut from one copy
    inside = [c for c in chunks if c[0][0] >= 64 and c[0][-1] < 2450]
    assert len(inside) > 30 and all(c[1].base is not None and c[1].base is inside[0][1].base for c in inside)
    assert not any(np.shares_memory(blocks[2][1], c[1]) for c in chunks)  # copies, not the producer's


def test_a_windows_knots_are_the_clamped_breakpoints():
    # _knot_slice: t[j0 : j1] of the clamped knot vector (t_{i+3} = breakpoint i, three-fold
    # ends), read from the breakpoints it needs only
    from cnc_interp.plan.optimal.profile import FeedProfileBuilder
    from cnc_interp.plan.vpop import JointTable

    p = line_path([0, 0, 0], [40.0, 0, 0], 83.3)
    b = FeedProfileBuilder(JointTable(p, None), p, MILL, 0.001)
    b._breaks_upto(10**6)
    br = np.asarray(b._br)
    nb = br.shape[0] - 1
    full = np.concatenate(([br[0]] * 3, br, [br[-1]] * 3))
    assert nb > 20
    for j0, j1 in [(0, 7), (0, nb + 7), (5, 30), (nb, nb + 7), (nb - 2, nb + 7), (3, 4), (0, 1)]:
        assert_allclose(b._knot_slice(j0, j1), full[j0:j1], rtol=0, atol=0)


def _collocation_numpy(b, br, n_per):
    """``FeedProfileBuilder._collocation`` as numpy computed it before the kernel."""
    u = np.arange(n_per) / n_per
    x = np.concatenate(((br[:-1, None] + np.diff(br)[:, None] * u[None, :]).ravel(), br[-1:]))
    q1, q2, q3 = b.derivs(x)
    parts = [(x, q1, q2, q3)]
    J = b.joins
    xj = J[(J > x[0]) & (J < x[-1])]
    k = [np.empty((xj.shape[0], b.n)) for _ in range(4)]
    FK.join_derivs(b.S, b.C, xj, *k)
    parts += [(xj, k[0], k[1], k[2]), (xj, k[0], k[1], k[3])]
    x, q1, q2, q3 = (np.concatenate(u) for u in zip(*parts))
    order = np.argsort(x, kind="stable")
    return x[order], q1[order], q2[order], q3[order]


@pytest.mark.parametrize("seed", range(3))
def test_a_windows_compiled_bookkeeping_is_numpys_arithmetic(seed):
    """The window's collocation points (``collocation``: the grid and both sides of each
    join, merged in order), the knot
    placement's breakpoints (``knot_breaks``), the bound on w (``wmax_of``), the LP's
    objective (``lp_objective``) and its solution's time (``lp_profile_time``), as numpy
    computes them (bit for bit but for sums numpy orders its own way), on curves of
    several segments."""
    from cnc_interp.plan.optimal.profile import FeedProfileBuilder
    from cnc_interp.plan.vpop import JointTable

    from ._vpop_paths import random_curve

    rng = np.random.default_rng(70 + seed)
    p = hermite_path(random_curve(rng, scale=15.0), 6, float(rng.uniform(40, 300)))
    b = FeedProfileBuilder(JointTable(p, None), p, MILL, 0.001)
    b._breaks_upto(80)
    assert b.joins.size >= 3
    br = np.asarray(b._br[: min(60, len(b._br))])
    for n_per in (3, 2, 4):
        got = FK.collocation(b.S, b.C, br, n_per, b.joins)
        want = _collocation_numpy(b, br, n_per)
        assert all(np.array_equal(g, w) for g, w in zip(got, want))
        assert np.sum(np.isin(got[0], b.joins)) == 2 * np.sum((b.joins > br[0]) & (b.joins < br[-1]))
    # the breakpoints where the integral of 1 / h crosses an integer
    probe = np.sort(rng.uniform(0.0, 50.0, 300))
    h = rng.uniform(0.05, 2.0, 300)
    dens = 1.0 / h
    for cum0 in (0.0, 3.7, 12.0):
        cum = cum0 + np.concatenate(([0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(probe))))
        marks = np.arange(np.floor(cum0) + 1.0, np.floor(cum[-1]) + 1.0)
        want = [v for v in np.interp(marks, cum, probe) if 0.0 < v < 40.0]
        got, end = FK.knot_breaks(probe, h, cum0, 40.0)
        assert got.tolist() == want and end == cum[-1] and len(want) > 10
    # the bound on w: axis speeds and the feed's step function
    x, q1, q2, q3 = _collocation_numpy(b, br, 3)
    q1[::7, 0] = 0.0  # an axis at rest at some points
    want = np.minimum(
        np.min(np.where(np.abs(q1) > 0, (b.vmax / np.where(q1 != 0, np.abs(q1), 1.0)) ** 2, np.inf), axis=1),
        _feed_numpy(b, x) ** 2,
    )
    assert np.array_equal(b.wmax_at(x, q1), want)
    # the objective and the solution's time
    nc = len(br) + 2
    tk = np.concatenate(([br[0]] * 3, br, [br[-1]] * 3))
    first = np.empty(x.shape[0], dtype=np.int64)
    B = np.empty((x.shape[0], 3, 4))
    FK.cubic_basis(tk, nc, x, first, B)
    cols = first[:, None] + np.arange(4)
    scale = rng.uniform(0.5, 2.0, nc)
    free = rng.uniform(size=nc) < 0.8
    wts = rng.uniform(0.1, 3.0, x.shape[0])
    want_c = np.bincount(cols.ravel(), weights=-(wts[:, None] * B[:, 0, :] * scale[cols]).ravel(), minlength=nc)
    want_c[~free] = 0.0
    want_c /= np.max(np.abs(want_c))
    c = np.empty(nc)
    FK.lp_objective(first, B, scale, wts, free, c)
    assert np.array_equal(c, want_c)
    xv, cfix = rng.uniform(0.0, 500.0, nc), rng.uniform(0.0, 500.0, nc)
    coef, w_hat = np.empty(nc), np.empty(x.shape[0])
    finite, T = FK.lp_profile_time(first, B, xv, scale, free, cfix, x, 1e-3, coef, w_hat)
    want_coef = np.where(free, xv * scale, cfix)
    w = np.maximum(np.einsum("kj,kj->k", B[:, 0, :], want_coef[cols]), 0.0)
    v = np.sqrt(w)
    assert finite and np.array_equal(coef, want_coef)
    assert_allclose(w_hat, np.maximum(w, 1e-3), rtol=1e-14)  # (einsum's order of the sum is its own)
    assert_allclose(T, np.sum(2.0 * np.diff(x) / np.maximum(v[1:] + v[:-1], 1e-300)), rtol=1e-13)
    xv[3] = np.nan
    assert not FK.lp_profile_time(first, B, xv, scale, free, cfix, x, 1e-3, coef, w_hat)[0]


def test_step_limits_keep_the_shrink_and_the_rounding_margin():
    from numpy.testing import assert_allclose

    from cnc_interp.constants import VPOP_LIMIT_SHRINK, VPOP_ROUNDING_ULPS
    from cnc_interp.errors import PlanError
    from cnc_interp.plan.step_limits import position_scale, step_limits

    m = Machine(
        name="t",
        axes="XY",
        vmax=np.array([100.0, 50.0]),
        amax=np.array([1e3, 2e3]),
        jmax=np.array([1e4, 3e4]),
        dt_s=0.001,
    )
    C = np.zeros((4, 3, 2))
    C[2, 0, 1] = -250.0
    q_scale = position_scale(C)
    assert q_scale == 251.0
    margin = VPOP_ROUNDING_ULPS * np.finfo(float).eps * q_scale
    vl, al, jl = step_limits(m, 0.002, q_scale)
    shrink = 1.0 - VPOP_LIMIT_SHRINK
    assert_allclose(vl, m.vmax * 0.002 * shrink - 2 * margin, rtol=0, atol=0)
    assert_allclose(al, m.amax * 0.002**2 * shrink - 4 * margin, rtol=0, atol=0)
    assert_allclose(jl, m.jmax * 0.002**3 * shrink - 8 * margin, rtol=0, atol=0)
    assert np.all(jl < m.jmax * 0.002**3)
    # positions so far out that float64 cannot resolve the jerk limit's step: refused
    with pytest.raises(PlanError, match="jerk limits are too small"):
        step_limits(m, 1e-5, 1e9)


# -- the tunables: one frozen record, checked, recorded, passed down ------------------
def test_a_tuning_is_checked_on_construction_and_frozen():
    import dataclasses

    from cnc_interp.errors import UsageError
    from cnc_interp.plan.settings import OptimalOptions
    from cnc_interp.plan.tuning import OptimalTuning

    t = OptimalTuning()
    for bad in ({"knot_time_s": -0.1}, {"dip": float("nan")}, {"handover_back": ()}, {"handover_back": (2, -6)}):
        with pytest.raises(UsageError):
            OptimalTuning(**bad)
    with pytest.raises(dataclasses.FrozenInstanceError):
        t.knot_time_s = 1.0  # type: ignore[misc]
    with pytest.raises(UsageError):
        OptimalOptions(tuning={"knot_time_s": 0.01})  # type: ignore[arg-type]
    assert t.changed() == {} and OptimalTuning(commit_s=t.commit_s * 2).changed() == {"commit_s": t.commit_s * 2}


def test_a_changed_tuning_is_recorded_with_the_settings_and_a_default_one_is_not():
    import json

    from cnc_interp.plan.settings import OptimalOptions, PlanSettings
    from cnc_interp.plan.tuning import OptimalTuning

    plain = PlanSettings(planner="optimal")
    assert "tuning" not in plain.to_dict()["options"]
    tuned = PlanSettings(planner="optimal", optimal=OptimalOptions(tuning=OptimalTuning(ccp_tol=0.5, ccp_max=5)))
    got = tuned.to_dict()["options"]["tuning"]
    assert got == {"ccp_tol": 0.5, "ccp_max": 5}
    json.dumps(tuned.to_dict())  # the record stays JSON-able


def test_every_stage_reads_the_tuning_it_is_given():
    # the builder, the time law's nodes, the refiner and the sampler's nodes take the
    # tuning passed down (``_Path.tuning`` from ``OptimalOptions.tuning``), not a global
    from cnc_interp.plan.optimal.context import _Path
    from cnc_interp.plan.optimal.profile import FeedProfileBuilder
    from cnc_interp.plan.optimal.refine import Refiner
    from cnc_interp.plan.optimal.sampling import _Nodes, time_law
    from cnc_interp.plan.settings import OptimalOptions, PlanSettings
    from cnc_interp.plan.tuning import OptimalTuning

    t = OptimalTuning(commit_s=0.25, knot_time_s=0.004, timelaw_nodes=3, refine_skip=0.5)
    p = hermite_path(circle_fun(15.0, turns=0.6), 8, 150.0)
    ctx = _Path(p, None, MILL, 0.001, PlanSettings(planner="optimal", optimal=OptimalOptions(tuning=t)))
    assert ctx.tuning is t and Refiner(ctx.refine_problem(), ctx.tuning).tuning is t and _Nodes(t).tuning is t
    b = FeedProfileBuilder(ctx.table, p, MILL, 0.001, ctx.tuning)
    assert b.knot_time_s == t.knot_time_s and b.commit == max(8, int(np.ceil(t.commit_s / t.knot_time_s)))
    knots = np.concatenate(([0.0] * 3, np.linspace(0.0, 10.0, 6), [10.0] * 3))
    law = time_law(knots, np.full(knots.shape[0] - 4, 100.0), 0.0, 10.0, t)
    assert law.s.shape[0] == 5 * t.timelaw_nodes + 1  # nodes per knot interval, plus the end

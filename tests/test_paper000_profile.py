"""Paper 000's polynomial feed transition, profile data and look-ahead."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from cnc_interp.plan.paper000.profile import (
    ACC_PEAK,
    JERK_PEAK,
    SegmentProfiles,
    build_profiles,
    stretch_to_period,
    transition_distance,
    transition_time,
)


def test_peak_constants_closed_form():
    tau = np.linspace(0, 1, 200001)
    hp = 30 * tau**2 * (1 - tau) ** 2
    hpp = 60 * tau * (1 - tau) * (1 - 2 * tau)
    assert_allclose(hp.max(), ACC_PEAK, rtol=1e-9)
    assert_allclose(np.abs(hpp).max(), JERK_PEAK, rtol=1e-8)


@pytest.mark.parametrize("v0,v1,a,j", [(0, 100, 1000, 1e6), (0, 100, 1e5, 1e4), (80, 10, 500, 2e4)])
def test_transition_respects_limits_and_distance(v0, v1, a, j):
    T = float(transition_time(v1 - v0, a, j))
    length = float(transition_distance(v0, v1, a, j)) + 1.0
    prof = build_profiles("t", [0], [0], [0.0], [length], [v0], [v0], [v1], np.array([a]), np.array([j]))
    # a cruise at v0 then the transition: look at the transition only
    t0 = prof.t_acc[0] + prof.t_cruise[0]
    assert_allclose(prof.t_dec[0], T)
    t = t0 + np.linspace(0, T, 20001)
    s, v, acc = prof.evaluate(t)
    assert_allclose(v[0], v0, atol=1e-9)
    assert_allclose(v[-1], v1, atol=1e-9)
    assert_allclose(s[-1] - s[0], 0.5 * (v0 + v1) * T, rtol=1e-12)
    assert_allclose(s[-1] - s[0], transition_distance(v0, v1, a, j), rtol=1e-12)
    dt = t[1] - t[0]
    jerk = np.gradient(acc, dt)
    assert np.abs(acc).max() <= a * (1 + 1e-9)
    assert np.abs(jerk).max() <= j * (1 + 1e-3)
    # the binding limit is reached
    assert max(np.abs(acc).max() / a, np.abs(jerk).max() / j) > 0.999
    # v is the derivative of s, a of v
    assert_allclose(np.gradient(s, dt)[1:-1], v[1:-1], rtol=1e-6, atol=1e-6 * abs(v1 - v0))
    assert_allclose(np.gradient(v, dt)[2:-2], acc[2:-2], atol=1e-4 * a)


def test_acc_coef_matches_evaluate():
    prof = build_profiles(
        "t",
        [0, 1],
        [0, 1],
        [0.0, 50.0],
        [50.0, 80.0],
        [0.0, 40.0],
        [60.0, 70.0],
        [40.0, 0.0],
        np.array([800.0, 900.0]),
        np.array([1e4, 2e4]),
    )
    c = prof.acc_coef()
    for m in range(2):
        for ph, (t0, T) in enumerate(
            ((prof.t_start[m], prof.t_acc[m]), (prof.t_start[m] + prof.t_acc[m] + prof.t_cruise[m], prof.t_dec[m]))
        ):
            lt = np.linspace(0, T, 101)[1:-1]
            a_eval = prof.evaluate(t0 + lt)[2]
            a_poly = np.polynomial.polynomial.polyval(lt, c[m, ph])
            assert_allclose(a_poly, a_eval, rtol=1e-9, atol=1e-9)


def test_profiles_continuous_in_feed_and_acceleration():
    rng = np.random.default_rng(4)
    n = 12
    w = np.r_[0.0, rng.uniform(5, 50, n - 1), 0.0]
    c = np.maximum(np.maximum(w[:-1], w[1:]), rng.uniform(10, 80, n))
    a, j = rng.uniform(300, 3000, n), rng.uniform(3e3, 5e4, n)
    need = transition_distance(w[:-1], c, a, j) + transition_distance(c, w[1:], a, j)
    length = need * rng.uniform(1.0, 3.0, n)
    prof = build_profiles(
        "t", np.arange(n), np.arange(n), np.r_[0, np.cumsum(length)[:-1]], length, w[:-1], c, w[1:], a, j
    )
    t = np.linspace(0, prof.duration_s, 400001)
    s, v, acc = prof.evaluate(t)
    dt = t[1] - t[0]
    assert np.all(np.diff(s) >= -1e-12)
    assert_allclose(s[-1], length.sum(), rtol=1e-12)
    assert np.abs(np.diff(v)).max() <= (a.max() * dt) * 1.01
    assert np.abs(np.diff(acc)).max() <= (j.max() * dt) * 1.01
    assert abs(v[0]) < 1e-12 and abs(v[-1]) < 1e-9


def test_stretch_to_period():
    prof = build_profiles("t", [0], [0], [0.0], [10.0], [0.0], [30.0], [0.0], np.array([500.0]), np.array([5e3]))
    dt = 0.001
    st = stretch_to_period(prof, dt)
    k = st.duration_s / dt
    assert abs(k - round(k)) < 1e-6
    assert st.duration_s >= prof.duration_s
    assert st.v_cruise[0] <= prof.v_cruise[0]
    s_end = st.evaluate(np.array([st.duration_s]))[0][0]
    assert_allclose(s_end, 10.0, rtol=1e-12)
    assert isinstance(st, SegmentProfiles)


def test_lookahead_random_sweep():
    from cnc_interp.plan.paper000.lookahead import group_segments, lookahead, tangential_at

    rng = np.random.default_rng(7)
    for _ in range(30):
        n, nj = int(rng.integers(1, 40)), 2
        length = rng.uniform(0.01, 20, n)
        g1 = rng.uniform(0.1, 1.0, (n, nj))
        g2 = rng.uniform(0.0, 0.5, (n, nj))
        g3 = rng.uniform(0.0, 0.3, (n, nj))
        amax, jmax = rng.uniform(500, 5000, nj), rng.uniform(1e4, 1e5, nj)
        # caps that leave room (as limits.feed_caps does with its shares)
        vcap = np.minimum(rng.uniform(1, 300, n), np.sqrt(0.8 * amax / np.maximum(g2, 1e-9)).min(axis=1))
        vcap = np.minimum(vcap, np.cbrt(0.5 * jmax / np.maximum(g3, 1e-9)).min(axis=1))
        scale = rng.uniform(0.5, 1.0, n)
        wcap = np.r_[0.0, rng.uniform(0, 400, n - 1), 0.0]
        first = np.arange(n + 1)  # one segment per piece
        w, c, a, j = lookahead(first, length, vcap, g1, g2, g3, amax, jmax, 0.5, scale, wcap)
        assert w[0] == 0 and w[-1] == 0
        assert np.all(w <= wcap + 1e-12)
        assert np.all(w[1:-1] <= np.minimum(vcap[:-1], vcap[1:]) + 1e-12)
        assert np.all(c <= vcap + 1e-12) and np.all(c >= np.maximum(w[:-1], w[1:]))
        need = transition_distance(w[:-1], c, a, j) + transition_distance(c, w[1:], a, j)
        assert np.all(need <= length * (1 + 1e-12))
        # the limits used at c are the tangential limits at c, and lower at a higher feed
        for k in range(n):
            assert (a[k], j[k]) == tangential_at(c[k], g1[k], g2[k], g3[k], amax, jmax, 0.5, scale[k])
            hi = tangential_at(vcap[k], g1[k], g2[k], g3[k], amax, jmax, 0.5, scale[k])
            assert hi[0] <= a[k] + 1e-9 and hi[1] <= j[k] + 1e-9
        # two segments per piece: the piece's limits are its segments' smallest
        pairs = np.r_[np.arange(0, n, 2), n]
        plen = np.add.reduceat(length, pairs[:-1])
        pcap = np.minimum.reduceat(vcap, pairs[:-1])
        w2, c2, a2, j2 = lookahead(pairs, plen, pcap, g1, g2, g3, amax, jmax, 0.5, scale, np.r_[wcap[pairs[:-1]], 0.0])
        for k in range(pairs.size - 1):
            per = [
                tangential_at(c2[k], g1[s], g2[s], g3[s], amax, jmax, 0.5, scale[s])
                for s in range(pairs[k], pairs[k + 1])
            ]
            assert_allclose([a2[k], j2[k]], np.min(per, axis=0))
        need2 = transition_distance(w2[:-1], c2, a2, j2) + transition_distance(c2, w2[1:], a2, j2)
        assert np.all(need2 <= plen * (1 + 1e-12))
        first = group_segments(vcap, wcap, 0.1)
        assert first[0] == 0 and np.all(np.diff(first) > 0)
        for lo, hi in zip(first, np.r_[first[1:], n]):
            assert vcap[lo:hi].min() >= 0.9 * vcap[lo:hi].max() - 1e-12


def test_numba_limits_match_numpy_limits():
    from types import SimpleNamespace

    from cnc_interp.plan.paper000.limits import tangential_limits
    from cnc_interp.plan.paper000.lookahead import tangential_at

    rng = np.random.default_rng(3)
    g1, g2, g3 = rng.uniform(0.1, 1, (5, 3)), rng.uniform(0, 0.3, (5, 3)), rng.uniform(0, 0.1, (5, 3))
    m = SimpleNamespace(amax=np.array([1000.0, 2000.0, 1500.0]), jmax=np.array([2e4, 5e4, 3e4]))
    v = rng.uniform(1, 40, 5)
    a_np, j_np = tangential_limits(SimpleNamespace(g1=g1, g2=g2, g3=g3), m, v)
    for k in range(5):
        a_nb, j_nb = tangential_at(v[k], g1[k], g2[k], g3[k], m.amax, m.jmax, 0.5, 1.0)
        assert_allclose([a_nb, j_nb], [a_np[k], j_np[k]], rtol=1e-12)


def test_pos_coef_matches_evaluate():
    prof = build_profiles(
        "t",
        [0, 1],
        [0, 1],
        [0.0, 50.0],
        [50.0, 80.0],
        [0.0, 40.0],
        [60.0, 70.0],
        [40.0, 0.0],
        np.array([800.0, 900.0]),
        np.array([1e4, 2e4]),
    )
    c = prof.pos_coef()
    t0, s0, v0, dv, T = prof.phases()
    for i in range(t0.size):
        lt = np.linspace(0, T[i], 51)
        assert_allclose(
            np.polynomial.polynomial.polyval(lt, c.reshape(-1, 7)[i]),
            prof.evaluate(t0[i] + lt)[0],
            rtol=1e-12,
            atol=1e-9,
        )

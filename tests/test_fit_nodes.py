"""The N-axis fitter: lines, circles, helices, 5-axis random polylines, end constraints."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from cnc_interp.fit import FitSettings, fit_run
from cnc_interp.fit.nodes import EndState, fit_polyline, range_min, segment_sources
from cnc_interp.fit.path import Path
from cnc_interp.gcode.program import Run

from ._fit_helpers import all_finite, continuity, distance_to_path, min_speed


def _run(nodes, axes="XYZ", tol=np.nan, feed=20.0, kind="feed"):
    n = nodes.shape[0]
    return Run(
        kind,
        axes,
        np.asarray(nodes, float),
        np.arange(1, n + 1),
        np.ones(n, int),
        np.full(n, feed),
        np.full(n, tol),
        np.full(n, np.nan),
    )


NODES = FitSettings(method="nodes", tol_mm=1e-3)  # the tolerance these tests check against


def test_line_sampled_as_nodes_is_one_straight_segment():
    x = np.linspace(0, 30, 61)
    nodes = np.stack([x, 0.5 * x, -0.2 * x], axis=1)
    (path,) = fit_run(_run(nodes), NODES)
    assert all_finite(path)
    assert distance_to_path(path, nodes).max() < 1e-9
    s = np.linspace(0, path.length, 100)
    assert_allclose(np.linalg.norm(path(s, 2), axis=1), 0, atol=1e-9)
    assert path.length == pytest.approx(np.linalg.norm(nodes[-1] - nodes[0]), rel=1e-12)
    assert path.n_seg <= 3


@pytest.mark.parametrize("R, n", [(10.0, 400), (2.0, 150), (50.0, 2000)])
def test_circle_sampled_as_nodes_curvature(R, n):
    th = np.linspace(0, 1.5 * np.pi, n)
    nodes = np.stack([R * np.cos(th), R * np.sin(th), np.full(n, 3.0)], axis=1)
    tol = 1e-3
    (path,) = fit_run(_run(nodes), NODES)
    assert all_finite(path)
    assert distance_to_path(path, nodes).max() <= tol
    s = np.linspace(0.05, 0.95, 3000) * path.length  # the free ends straighten slightly
    k = np.linalg.norm(path(s, 2), axis=1)
    assert_allclose(k, 1 / R, rtol=0.05)
    assert path.length == pytest.approx(1.5 * np.pi * R, rel=1e-4)
    pos, tan, curv = continuity(path)
    assert pos < 1e-9 and tan < 1e-9 and curv < 1e-9
    assert min_speed(path) > 0.5
    assert path.n_seg < n / 4  # compression


def test_helix_third_derivative_bounded():
    th = np.linspace(0, 4 * np.pi, 800)
    nodes = np.stack([5 * np.cos(th), 5 * np.sin(th), 0.5 * th], axis=1)
    (path,) = fit_run(_run(nodes), NODES)
    s = np.linspace(0, path.length, 5000)
    q3 = path(s, 3)
    assert np.all(np.isfinite(q3))
    assert np.abs(q3).max() < 1.0  # exact helix: |q'''| = κ² · r-ish ≈ 0.04


def _random_5axis(rng, n):
    lin_turn = rng.normal(0, 0.1, (n, 3))
    d = np.cumsum(lin_turn, axis=0) + rng.normal(0, 1, 3)
    d /= np.linalg.norm(d, axis=1)[:, None]
    step = rng.uniform(0.05, 0.8, n)[:, None]
    xyz = np.cumsum(d * step, axis=0)
    ac = np.cumsum(rng.normal(0, 0.2, (n, 2)) * 0.3 + 0.05, axis=0)
    return np.round(np.concatenate([xyz, ac], axis=1), 4)


@pytest.mark.parametrize("seed", range(6))
def test_random_5axis_polylines_within_tolerance(seed):
    rng = np.random.default_rng(100 + seed)
    nodes = _random_5axis(rng, 250)
    tol_mm = 10 ** rng.uniform(-3, -1.7)
    settings = FitSettings(tol_mm=tol_mm, tol_deg=2 * tol_mm, corner_deg=45.0, method="nodes")
    paths = fit_run(_run(nodes, axes="XYZAC"), settings)
    lin = np.array([1, 1, 1, 0, 0], bool)
    covered = []
    for p in paths:
        assert all_finite(p)
        assert min_speed(p) > 0
        pos, tan, curv = continuity(p)
        # rotary axes' q_s (deg/mm) can be large where the tool barely moves: relative bound
        s = np.linspace(0, p.length, 400)
        scale1 = max(1.0, np.abs(p(s, 1)).max())
        scale2 = max(1.0, np.abs(p(s, 2)).max())
        assert pos < 1e-9 and tan < 1e-9 * scale1
        assert curv < 1e-9 * scale2
        covered.append(p)
    # every node within tolerance of some path: linear distance (mm)
    d = np.min([distance_to_path(p, nodes, lin) for p in covered], axis=0)
    assert d.max() <= tol_mm * (1 + 1e-6)
    # paths are chained exactly
    for a, b in zip(paths[:-1], paths[1:]):
        assert np.array_equal(a.end, b.start)
    assert_allclose(paths[0].start, nodes[0], atol=0)
    assert_allclose(paths[-1].end, nodes[-1], atol=1e-9)


def test_rotary_axes_within_deg_tolerance():
    rng = np.random.default_rng(7)
    nodes = _random_5axis(rng, 200)
    settings = FitSettings(tol_mm=0.002, tol_deg=0.001, corner_deg=60.0, method="nodes")
    paths = fit_run(_run(nodes, axes="XYZAC"), settings)
    for p in paths:
        assert all_finite(p)
    # the fitter's own per-node report is within the tolerance
    from cnc_interp.fit.fitter import _fit_run_raw

    _, info = _fit_run_raw(_run(nodes, axes="XYZAC"), settings)
    assert info["within_tolerance"]
    assert info["max_node_dev_deg"] <= 0.001
    assert info["max_node_dev_mm"] <= 0.002


def test_end_constraints_are_met_exactly():
    nodes = np.array([[0, 0, 0], [2, 0.1, 0], [4, 0.3, 0], [6, 0.4, 0.0]])
    lin = np.ones(3, bool)
    T0 = np.array([1.0, 0.0, 0.0])
    K0 = np.array([0.0, 0.05, 0.0])
    T1 = np.array([1.0, 0.02, 0.0]) / np.linalg.norm([1.0, 0.02, 0.0])
    K1 = np.array([0.0, -0.02, 0.0])
    K1 -= (K1 @ T1) * T1
    pf = fit_polyline(
        nodes, np.full(4, 1e-3), 1e-3, lin, lin, np.arange(4), np.ones(4), 1e-3, EndState(T0, K0), EndState(T1, K1)
    )
    path = Path("XYZ", pf.breaks, pf.coef, pf.line, pf.feed_mm_s)
    d = path.derivatives_s(np.array([0.0, path.breaks[-1]]), 2)
    assert_allclose(d[1][0], T0, atol=1e-9)
    assert_allclose(d[2][0], K0, atol=1e-9)
    assert_allclose(d[1][1], T1, atol=1e-9)
    assert_allclose(d[2][1], K1, atol=1e-9)
    assert distance_to_path(path, nodes).max() <= 1e-3


def test_segment_sources_and_range_min():
    a = np.array([5.0, 3.0, 4.0, 1.0, 7.0, 2.0, 9.0])
    lo = np.array([0, 1, 2, 4, 6, 0])
    hi = np.array([0, 3, 4, 6, 6, 6])
    assert_allclose(range_min(a, lo, hi), [5, 1, 1, 2, 9, 1])
    u = np.array([0.0, 1.0, 2.0, 3.0])
    line = np.array([10, 11, 12, 13])
    feed = np.array([5.0, 5.0, 2.0, 8.0])
    seg_line, seg_feed = segment_sources(np.array([0.0, 1.5, 3.0]), u, line, feed)
    assert list(seg_line) == [12, 13]
    assert_allclose(seg_feed, [2.0, 2.0])


@pytest.mark.parametrize("seed", range(3))
def test_evaluate012_matches_scipy_bspline(seed):
    from scipy.interpolate import BSpline

    from cnc_interp.fit import _bspline as bs

    rng = np.random.default_rng(seed)
    inner = np.sort(rng.uniform(0.0, 10.0, 9))
    t = np.concatenate((np.zeros(6), inner, np.full(6, 10.0)))
    c = rng.normal(size=(t.size - 6, 3))
    x = np.concatenate((np.unique(t), rng.uniform(0.0, 10.0, 50)))
    d = [np.empty((x.size, 3)) for _ in range(3)]
    bs.evaluate012(t, t.size - 6, c, x, *d)
    spl = BSpline(t, c, 5, extrapolate=False)
    for nu in range(3):
        ref = spl(x, nu)
        np.testing.assert_allclose(d[nu], ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())

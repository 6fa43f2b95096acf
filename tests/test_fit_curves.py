"""Arcs, helices and NURBS become quintic pieces from their exact geometry."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from cnc_interp.fit import FitSettings, fit_run
from cnc_interp.fit.curves import CurveEval, fit_curve
from cnc_interp.fit.nodes import hermite
from cnc_interp.fit.path import Path
from cnc_interp.gcode.program import Arc, CurvePiece, Nurbs, Run

from ._fit_helpers import all_finite, continuity, distance_to_path


def _arc(R=5.0, sweep=np.pi, z1=0.0, c=(10.0, 5.0), a0=-np.pi / 2):
    start = np.array([c[0] + R * np.cos(a0), c[1] + R * np.sin(a0), 0.0])
    a1 = a0 + sweep
    end = np.array([c[0] + R * np.cos(a1), c[1] + R * np.sin(a1), z1])
    return Arc(line=7, start=start, end=end, plane=(0, 1, 2), center=np.array(c), radius=R, sweep_rad=sweep)


def _path_of(pf, axes="XYZ"):
    return Path(axes, pf.breaks, pf.coef, pf.line, pf.feed_mm_s)


def test_hermite_reproduces_a_quintic():
    rng = np.random.default_rng(0)
    c = rng.normal(size=(1, 6, 2))
    h = np.array([1.7])

    def ev(t, d):
        out = np.zeros(2)
        for i in range(d, 6):
            f = np.prod(np.arange(i - d + 1, i + 1)) if d else 1.0
            out += c[0, i] * f * t ** (i - d)
        return out[None]

    got = hermite(ev(0, 0), ev(0, 1), ev(0, 2), ev(h[0], 0), ev(h[0], 1), ev(h[0], 2), h)
    assert_allclose(got, c, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("sweep", [np.pi / 3, np.pi, 1.75 * np.pi, -np.pi, 4.5 * np.pi])
def test_arc_within_tolerance_of_exact_geometry(sweep):
    arc = _arc(sweep=sweep)
    tol = 1e-4
    lin = np.ones(3, bool)
    pf = fit_curve(arc, np.ones(3), lin, tol, 1e-3, 7, 10.0)
    path = _path_of(pf)
    assert all_finite(path)
    exact = arc.points(np.linspace(0, 1, 3001))
    assert distance_to_path(path, exact).max() <= tol
    assert_allclose(path.start, arc.start, atol=0)
    assert_allclose(path.end, arc.end, atol=1e-12)
    s = np.linspace(0, path.length, 2000)
    assert_allclose(np.linalg.norm(path(s, 2), axis=1), 1 / 5.0, rtol=2e-3)
    assert path.length == pytest.approx(abs(sweep) * 5.0, rel=1e-5)
    pos, tan, curv = continuity(path)
    assert pos < 1e-9 and tan < 1e-9 and curv < 1e-9


def test_helix_pitch_and_radius():
    arc = _arc(sweep=4 * np.pi, z1=8.0)
    pf = fit_curve(arc, np.ones(3), np.ones(3, bool), 1e-4, 1e-3, 7, 10.0)
    path = _path_of(pf)
    s = np.linspace(0, path.length, 3000)
    q = path(s)
    assert_allclose(np.hypot(q[:, 0] - 10, q[:, 1] - 5), 5.0, atol=1e-4)
    assert path.length == pytest.approx(np.hypot(4 * np.pi * 5, 8.0), rel=1e-5)
    assert_allclose(path.end, arc.end, atol=1e-12)


def test_rational_nurbs_circle_is_exact_within_tolerance():
    # a quarter circle as a rational quadratic NURBS (weights 1, √2/2, 1)
    ctrl = np.array([[1.0, 0, 0], [1, 1, 0], [0, 1, 0]]) * 20
    w = np.array([1.0, np.sqrt(0.5), 1.0])
    nb = Nurbs(line=3, control=ctrl, weights=w, knots=np.array([0, 0, 0, 1, 1, 1.0]), order=3)
    pf = fit_curve(nb, np.ones(3), np.ones(3, bool), 1e-5, 1e-3, 3, 10.0)
    path = _path_of(pf)
    s = np.linspace(0, path.length, 2000)
    q = path(s)
    assert_allclose(np.hypot(q[:, 0], q[:, 1]), 20.0, atol=1e-5)
    assert_allclose(np.linalg.norm(path(s, 2), axis=1), 1 / 20, rtol=1e-3)
    assert path.length == pytest.approx(10 * np.pi, rel=1e-6)


def test_polynomial_cubic_nurbs_within_tolerance_and_g2():
    rng = np.random.default_rng(3)
    ctrl = np.cumsum(rng.normal(size=(7, 3)), axis=0)
    knots = np.array([0, 0, 0, 0, 0.2, 0.5, 0.7, 1, 1, 1, 1.0])
    nb = Nurbs(line=4, control=ctrl, weights=np.ones(7), knots=knots, order=4)
    pf = fit_curve(nb, np.ones(3), np.ones(3, bool), 1e-3, 1e-3, 4, 10.0)
    path = _path_of(pf)
    ev = CurveEval(nb)
    w = np.linspace(0, 1, 2000)
    assert distance_to_path(path, ev.points(w)).max() <= 1e-3
    pos, tan, curv = continuity(path)
    assert pos < 1e-9 and tan < 1e-9 and curv < 1e-9
    # unit speed at every break (arc-length-like pieces)
    assert_allclose(np.linalg.norm(path.coef[:, 1, :], axis=1), 1.0, rtol=1e-12)
    assert path.length == pytest.approx(
        np.linalg.norm(np.diff(ev.points(np.linspace(0, 1, 20001)), axis=0), axis=1).sum(), rel=1e-3
    )


def test_run_line_arc_line_is_g2_and_within_tolerance():
    arc = Arc(
        line=2,
        start=np.array([10.0, 0, 0]),
        end=np.array([15.0, 5, 0]),
        plane=(0, 1, 2),
        center=np.array([10.0, 5]),
        radius=5.0,
        sweep_rad=np.pi / 2,
    )
    apts = arc.points(np.linspace(0, 1, 9))
    nodes = np.vstack([[0, 0, 0], [5, 0, 0], [10, 0, 0], apts[1:], [15, 12, 0], [15, 20, 0]])
    n = nodes.shape[0]
    line = np.array([1, 1, 1] + [2] * 8 + [3, 3])
    run = Run(
        "feed",
        "XYZ",
        nodes,
        line,
        np.ones(n, int),
        np.full(n, 20.0),
        np.full(n, np.nan),
        np.full(n, np.nan),
        (CurvePiece(2, 10, arc),),
    )
    tol = 1e-3
    (path,) = fit_run(run, FitSettings(tol_mm=tol))
    assert all_finite(path)
    assert distance_to_path(path, nodes).max() <= tol
    assert distance_to_path(path, arc.points(np.linspace(0, 1, 400))).max() <= tol
    pos, tan, curv = continuity(path)
    assert pos < 1e-9 and tan < 1e-9 and curv < 1e-9
    # lines stay lines away from the junctions, the arc keeps its curvature in the middle
    q = path.derivatives_s(path.u_of_s(np.array([1.0, 10.0 + 0.25 * np.pi * 5])), 2)
    assert np.linalg.norm(q[2][0]) < 1e-3
    assert np.linalg.norm(q[2][1]) == pytest.approx(0.2, rel=1e-3)
    assert set(path.line) == {1, 2, 3}

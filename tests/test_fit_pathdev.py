"""The tolerance bounds the distance to the PROGRAMMED path everywhere, not only at nodes.

Regression for the wobble of long G1 edges between nodes (±0.24 mm on a plate contour
with R8 arcs at 1 µm tolerance): the programmed moves and exact curves are sampled
densely and their distance to the fitted paths is measured independently of the
fitter (``_fit_helpers.distance_to_path``), for the planar and the N-axis fitters.
"""

from __future__ import annotations

import numpy as np
import pytest

from cnc_interp.fit import FitSettings, fit_program, fit_run
from cnc_interp.fit.curves import CurveEval
from cnc_interp.fit.deviation import path_deviation
from cnc_interp.fit.planar import fit_planar, planar_to_path
from cnc_interp.gcode import read_program
from cnc_interp.gcode.program import Run

from ._fit_helpers import all_finite, continuity, distance_to_path, min_speed

EPS = 1e-6  # relative slack: float rounding of the projection

CONTOUR = b"""G21 G90 G17 G94
G64 P0.01
G0 X-8 Y-3 Z2
G1 Z-2 F300
G1 X0 Y-3 F900
G1 X35
G3 X43 Y5 I0 J8
G1 Y25
G3 X35 Y33 I-8 J0
G1 X5
G3 X-3 Y25 I0 J-8
G1 Y5
G3 X5 Y-3 I8 J0
G1 X8
G0 Z10
M30
"""


def _programmed_samples(run: Run, per_move: int = 100, per_curve: int = 1000) -> np.ndarray:
    """Dense points of the programmed moves and exact curves of a run."""
    pts = []
    in_curve = np.zeros(run.n_nodes - 1, dtype=bool)
    for cp in run.curves:
        in_curve[cp.first : cp.last] = True
        ev = CurveEval(cp.curve)
        pts.append(ev.points(np.linspace(ev.w0, ev.w1, per_curve)))
    f = np.linspace(0.0, 1.0, per_move)[:, None]
    for j in np.nonzero(~in_curve)[0]:
        a, b = run.nodes[j], run.nodes[j + 1]
        pts.append(a + (b - a) * f)
    return np.vstack(pts)


def _worst_distance(paths, points, mask=None, samples=32, candidates=6) -> float:
    return float(
        np.min([distance_to_path(p, points, mask, samples, candidates=candidates) for p in paths], axis=0).max()
    )


@pytest.mark.parametrize("method", ["auto", "nodes"])
def test_line_arc_contour_stays_on_the_programmed_path(method):
    prog = read_program(CONTOUR, source="contour.ngc")
    tol = 1e-3
    res = fit_program(prog, FitSettings(tol_mm=tol, tol_cap_mm=tol, method=method))  # caps G64 P0.01
    feed = [p for p in res.paths if not p.rapid]
    run = [r for r in prog.runs if r.kind == "feed"][0]
    worst = _worst_distance(feed, _programmed_samples(run))
    assert worst <= tol * (1 + EPS)
    assert res.stats["max_path_dev_mm"] <= tol * (1 + EPS)
    assert res.stats["max_path_dev_ratio"] <= 1 + EPS
    assert res.stats["within_tolerance"]
    for p in feed:
        assert all_finite(p)
        pos, tan, curv = continuity(p)
        assert pos < 1e-9 and tan < 1e-9 and curv < 1e-9
        assert min_speed(p) > 0
    # the long edges stay straight: zero curvature away from the line-arc transitions
    contour = max(feed, key=lambda p: p.length)
    s = np.linspace(0, contour.length, 40001)
    q = contour(s)
    on_edge = (np.abs(q[:, 0] - 43.0) < 0.01) & (q[:, 1] > 6.0) & (q[:, 1] < 24.0)  # the X43 edge
    assert on_edge.sum() > 1000
    assert np.abs(q[on_edge, 0] - 43.0).max() <= tol
    # nearly straight: curvature 50x below the R8 arcs' (the transitions fade fast; the
    # middle of the edge keeps a residual bend of radius ~600 mm, well within tolerance)
    assert np.linalg.norm(contour(s[on_edge], 2), axis=1).max() < 0.02 / 8


def test_contour_deviation_statistic_matches_the_independent_measure():
    """``max_path_dev_mm`` sees the old wobble: a spline bent over a whole edge."""
    from cnc_interp.fit.nodes import hermite

    # a 30 mm edge bent like the old fit: a quintic through both ends with curvature 1/8
    # imposed at both ends (the exact arcs' end state), sampled along the edge
    L = 30.0
    p0, p1 = np.zeros((1, 2)), np.array([[L, 0.0]])
    v = np.array([[1.0, 0.0]])
    a0, a1 = np.array([[0.0, 1 / 8]]), np.array([[0.0, 1 / 8]])
    coef = hermite(p0, v, a0, p1, v, a1, np.array([L]))
    nodes = np.array([[0.0, 0.0], [L, 0.0]])
    dev, ratio = path_deviation(np.array([0.0, L]), coef, nodes, np.full(2, 1e-3), np.ones(2, bool))
    t = np.linspace(0, L, 20001)
    y = sum(coef[0, i, 1] * t**i for i in range(6))
    assert dev == pytest.approx(np.abs(y).max(), rel=1e-3)
    assert ratio == pytest.approx(dev / 1e-3)
    assert dev > 1.0  # the quintic bulges by millimetres, the nodes are exact


def _mixed_polyline(rng, n_groups=12):
    """Long straight moves between finely sampled gentle curves (turns below 30 deg)."""
    pts = [np.zeros(2)]
    ang = rng.uniform(-np.pi, np.pi)
    for _ in range(n_groups):
        # a long move
        ang += rng.uniform(-0.3, 0.3)
        pts.append(pts[-1] + rng.uniform(5.0, 35.0) * np.array([np.cos(ang), np.sin(ang)]))
        # a sampled arc of radius R
        R = rng.uniform(2.0, 20.0)
        sweep = rng.uniform(0.3, 2.0) * rng.choice([-1, 1])
        k = int(rng.integers(5, 60))
        step = abs(sweep) * R / k
        for _ in range(k):
            ang += sweep / k
            pts.append(pts[-1] + step * np.array([np.cos(ang), np.sin(ang)]))
    xy = np.round(np.array(pts), 4)
    keep = np.concatenate(([True], np.linalg.norm(np.diff(xy, axis=0), axis=1) > 0))
    return xy[keep]


def _dense(nodes, per_move=24):
    f = np.linspace(0.0, 1.0, per_move)[None, :, None]
    return (nodes[:-1, None, :] + (nodes[1:] - nodes[:-1])[:, None, :] * f).reshape(-1, nodes.shape[1])


@pytest.mark.parametrize("seed", range(4))
def test_random_mixed_polylines_planar(seed):
    rng = np.random.default_rng(100 + seed)
    xy = _mixed_polyline(rng)
    nodes = np.concatenate([xy, np.full((xy.shape[0], 1), -1.0)], axis=1)
    n = nodes.shape[0]
    tol = float(10 ** rng.uniform(-3, -2))
    got = fit_planar(nodes, (0, 1), np.full(n, tol), "XYZ", np.arange(n), np.full(n, 10.0))
    assert got is not None
    planar, coef, line, feed, dev = got
    path = planar_to_path(planar, nodes[0], "XYZ", line, feed)
    assert all_finite(path)
    assert dev <= tol
    assert _worst_distance([path], _dense(nodes)) <= tol * (1 + EPS)
    pos, tan, curv = continuity(path)
    assert pos < 1e-9 and tan < 1e-9 and curv < 1e-9 * max(1.0, np.abs(path.coef).max())
    assert min_speed(path) > 0


@pytest.mark.parametrize("seed", range(4))
def test_random_mixed_polylines_nodes_3d(seed):
    rng = np.random.default_rng(200 + seed)
    xy = _mixed_polyline(rng, n_groups=8)
    z = np.cumsum(rng.uniform(-0.05, 0.05, xy.shape[0]))
    nodes = np.concatenate([xy, z[:, None]], axis=1)
    tol = float(10 ** rng.uniform(-3, -2))
    n = nodes.shape[0]
    run = Run(
        "feed",
        "XYZ",
        nodes,
        np.arange(1, n + 1),
        np.ones(n, int),
        np.full(n, 20.0),
        np.full(n, np.nan),
        np.full(n, np.nan),
    )
    settings = FitSettings(tol_mm=tol, method="nodes", corner_deg=60.0)
    paths = fit_run(run, settings)
    for p in paths:
        assert all_finite(p)
        pos, tan, curv = continuity(p)
        assert pos < 1e-9 and tan < 1e-9 and curv < 1e-9 * max(1.0, np.abs(p.coef).max())
        assert min_speed(p) > 0
    assert _worst_distance(paths, _dense(nodes)) <= tol * (1 + EPS)


# --- rotary axes ---------------------------------------------------------------
def _line_pieces(p0, p1, bulge=None):
    """One quintic piece from p0 to p1 (d,) on u in [0, 1], plus ``bulge`` (d,) * 16 u²(1-u)²."""
    coef = np.zeros((1, 6, p0.size))
    coef[0, 0], coef[0, 1] = p0, p1 - p0
    if bulge is not None:  # 16 (u² - 2u³ + u⁴): 0 at both ends, 1 at u = 1/2
        coef[0, 2], coef[0, 3], coef[0, 4] = 16 * bulge, -32 * bulge, 16 * bulge
    return np.array([0.0, 1.0]), coef


@pytest.mark.parametrize("extra_deg, expected", [(0.0, 0.0), (0.5e-3, 0.5), (2e-3, 2.0)])
def test_rotary_deviation_closed_form(extra_deg, expected):
    from cnc_interp.fit.deviation import rotary_path_deviation

    # X 0 -> 10 mm with A 0 -> 20 deg; the fit's A bulges by extra_deg in the middle
    nodes = np.array([[0.0, 0.0], [10.0, 20.0]])
    lin = np.array([True, False])
    breaks, coef = _line_pieces(nodes[0], nodes[1], np.array([0.0, extra_deg]))
    r = rotary_path_deviation(breaks, coef, nodes, np.full(2, 1e-3), 1e-3, lin, np.array([True, True]))
    # the foot point in the scaled (X, A) plane is off the programmed pose by δ cos φ
    # across the line (tan φ = 20 deg / 10 mm): ΔX = δ cos φ sin φ = 0.4 δ, ΔA = δ cos² φ = 0.2 δ;
    # the ratio is the larger over its tolerance
    cos_phi, sin_phi = np.array([10.0, 20.0]) / np.hypot(10.0, 20.0)
    assert r == pytest.approx(expected * cos_phi * sin_phi, rel=0.01, abs=1e-9)
    # rotary-only (X still): A 0 -> 20 deg, the fit's C bulges by extra_deg across it; the
    # distance in degrees against tol_deg
    nodes_r = np.array([[5.0, 0.0, 3.0], [5.0, 20.0, 3.0]])
    lin_r = np.array([True, False, False])
    breaks, coef = _line_pieces(nodes_r[0], nodes_r[1], np.array([0.0, 0.0, extra_deg]))
    r = rotary_path_deviation(breaks, coef, nodes_r, np.full(2, 1e-3), 1e-3, lin_r, np.array([False, True, False]))
    assert r == pytest.approx(expected, rel=1e-6, abs=1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_random_five_axis_polylines_hold_the_rotary_tolerance(seed):
    rng = np.random.default_rng(100 + seed)
    n = 60
    steps = rng.normal(size=(n, 5)) * np.array([1.0, 1.0, 0.3, 2.0, 5.0])
    pts = np.cumsum(steps, axis=0)
    body = "".join(f"G1 X{p[0]:.4f} Y{p[1]:.4f} Z{p[2]:.4f} A{p[3]:.4f} C{p[4]:.4f}\n" for p in pts)
    prog = read_program(
        ("G21 G90 G94\nG0 X0 Y0 Z0 A0 C0\nF1200\n" + body + "M2\n").encode(), source="five.ngc", axes="XYZAC"
    )
    res = fit_program(prog, FitSettings(tol_mm=1e-3, tol_deg=1e-3, corner_deg=60.0))
    st = res.stats
    assert st["within_tolerance"]
    assert 0.0 < st["max_path_dev_rot_ratio"] <= 1.0 + 1e-6
    assert st["max_node_dev_deg"] <= 1e-3

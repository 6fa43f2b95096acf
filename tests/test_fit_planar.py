"""Paper 000's planar method: Eq. (1) table, rotated frames, G2 continuity, tolerance."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from cnc_interp.fit.planar import (
    fit_planar,
    frame_angle,
    planar_to_path,
    rotation_angle,
    rotation_angles,
    wrap_angle,
)

from ._fit_helpers import all_finite, continuity, distance_to_path, min_speed

PI = np.pi


@pytest.mark.parametrize(
    "alpha, theta",
    [
        # third quadrant and the -π end: θ = π
        (-PI, PI),
        (-0.75 * PI, PI),
        (-0.51 * PI, PI),
        # fourth quadrant (and the lower end of the third): θ = -π/2 (corrected from "-π")
        (-0.5100001 * PI, PI),
        (-0.50999 * PI, -PI / 2),
        (-0.25 * PI, -PI / 2),
        (-0.02 * PI, -PI / 2),
        # first quadrant: θ = 0
        (-0.019 * PI, 0.0),
        (0.0, 0.0),
        (0.25 * PI, 0.0),
        (0.47 * PI, 0.0),
        # second quadrant: θ = π/2
        (0.4701 * PI, PI / 2),
        (0.75 * PI, PI / 2),
        (0.96 * PI, PI / 2),
        # near π: θ = π
        (0.9601 * PI, PI),
        (PI, PI),
    ],
)
def test_eq1_table(alpha, theta):
    assert rotation_angle(alpha) == pytest.approx(theta)
    assert rotation_angles(np.array([alpha]))[0] == pytest.approx(theta)


def test_eq1_keeps_rotated_inclination_within_049pi():
    alpha = np.linspace(-PI, PI, 200_001)
    incl = wrap_angle(alpha - rotation_angles(alpha))
    assert incl.min() >= -0.04 * PI - 1e-12
    assert incl.max() <= 0.49 * PI + 1e-12


@pytest.mark.parametrize(
    "alpha, theta",
    [
        (-PI, PI),
        (-0.76 * PI, PI),
        (-0.74 * PI, -PI / 2),
        (-0.5 * PI, -PI / 2),
        (-0.26 * PI, -PI / 2),
        (-0.24 * PI, 0.0),
        (-0.02 * PI, 0.0),
        (0.0, 0.0),
        (0.24 * PI, 0.0),
        (0.26 * PI, PI / 2),
        (0.74 * PI, PI / 2),
        (0.76 * PI, PI),
        (PI, PI),
    ],
)
def test_frame_angle_is_the_nearest_quarter(alpha, theta):
    assert frame_angle(alpha) == pytest.approx(theta)


def test_frame_angle_keeps_inclination_within_quarter_pi():
    alpha = np.linspace(-PI, PI, 20_001)
    incl = wrap_angle(alpha - np.array([frame_angle(a) for a in alpha]))
    assert np.abs(incl).max() <= 0.25 * PI + 1e-12


def _circle(R=10.0, n=2000, sweep=1.9 * PI, a0=0.0):
    th = a0 + np.linspace(0.0, sweep, n)
    return np.stack([R * np.cos(th), np.zeros(n), R * np.sin(th)], axis=1)


def _fit(nodes, plane=(0, 2), tol=1e-3):
    n = nodes.shape[0]
    got = fit_planar(nodes, plane, np.full(n, tol), "XYZ", np.arange(n), np.full(n, 10.0))
    assert got is not None
    planar, coef, line, feed, dev = got
    path = planar_to_path(planar, nodes[0], "XYZ", line, feed)
    assert_allclose(path.coef, coef)
    return path, dev


def test_circle_xz_within_tolerance_and_g2_across_frames():
    R, tol = 10.0, 1e-3
    nodes = _circle(R)
    path, dev = _fit(nodes, tol=tol)
    assert dev <= tol
    thetas = path.planar.theta
    assert len(set(np.round(thetas, 6))) >= 3  # the circle crosses several rotated frames
    assert distance_to_path(path, nodes).max() <= tol * (1 + 1e-6)
    pos, tan, curv = continuity(path)
    assert pos < 1e-9 and tan < 1e-9 and curv < 1e-9
    # the curve stays on the circle (within the tolerance plus the chord sagitta)
    s = np.linspace(0, path.length, 4000)
    q = path(s)
    r = np.hypot(q[:, 0], q[:, 2])
    sag = R * (1 - np.cos(1.9 * PI / 1999 / 2))
    assert np.abs(r - R).max() <= tol + sag + 1e-9
    assert path.length == pytest.approx(1.9 * PI * R, rel=1e-4)
    # curvature ≈ 1/R on average (the planar fit ripples within the tolerance)
    k = np.linalg.norm(path(s, 2), axis=1)
    assert np.median(k) == pytest.approx(1 / R, rel=0.03)
    assert min_speed(path) > 0.5
    assert path.planar.plane == (0, 2)


def test_line_gives_one_straight_segment():
    x = np.linspace(0, 50, 101)
    nodes = np.stack([x, np.zeros_like(x), 0.3 * x], axis=1)
    path, dev = _fit(nodes)
    assert path.n_seg == 1
    assert dev < 1e-9
    s = np.linspace(0, path.length, 50)
    assert_allclose(np.linalg.norm(path(s, 2), axis=1), 0.0, atol=1e-9)
    assert path.length == pytest.approx(np.hypot(50, 15), rel=1e-12)


def test_planar_form_matches_path_exactly():
    nodes = _circle(5.0, 500, 1.5 * PI, a0=0.3)
    path, _ = _fit(nodes)
    pl = path.planar
    for k in range(pl.theta.size):
        x = np.linspace(0, pl.x_end[k], 7)
        p = np.polynomial.polynomial.polyval(x, pl.p[k])
        c, s_ = np.cos(pl.theta[k]), np.sin(pl.theta[k])
        qh = pl.origin[k, 0] + x * c - p * s_
        qv = pl.origin[k, 1] + x * s_ + p * c
        q = path.derivatives_u(path.breaks[k] + x, 0)[0]
        assert_allclose(q[:, 0], qh, atol=1e-12)
        assert_allclose(q[:, 2], qv, atol=1e-12)
    # a0 = 0 and the end node exactly on the curve (p(x_end) = z_end)
    assert_allclose(pl.p[:, 0], 0.0, atol=0)


@pytest.mark.parametrize("seed", range(6))
def test_random_planar_polylines(seed):
    rng = np.random.default_rng(seed)
    n = 300
    # a smooth random walk in XY with bounded turning (< corner threshold), noisy nodes
    turn = rng.normal(0, 0.08, n)
    ang = np.cumsum(turn) + rng.uniform(-PI, PI)
    step = rng.uniform(0.05, 1.0, n)
    xy = np.cumsum(np.stack([step * np.cos(ang), step * np.sin(ang)], axis=1), axis=0)
    xy = np.round(xy, 3)  # CAM output: 3 decimals
    keep = np.concatenate(([True], np.linalg.norm(np.diff(xy, axis=0), axis=1) > 0))
    xy = xy[keep]
    nodes = np.concatenate([xy, np.full((xy.shape[0], 1), 5.0)], axis=1)
    tol = 10 ** rng.uniform(-3, -1.5)
    path, dev = _fit(nodes, plane=(0, 1), tol=tol)
    assert all_finite(path)
    assert dev <= tol
    assert distance_to_path(path, nodes).max() <= tol * (1 + 1e-6)
    pos, tan, curv = continuity(path)
    assert pos < 1e-9 and tan < 1e-9
    assert curv < 1e-9 * max(1.0, np.abs(path.coef).max())
    assert min_speed(path) > 0
    assert_allclose(path.coef[:, 0, 2], 5.0)


def _curvature(path, n=20_000):
    s = np.linspace(0.0, path.length, n)
    d1, d2 = path(s, 1), path(s, 2)
    return (d1[:, 0] * d2[:, 2] - d1[:, 2] * d2[:, 0]) / np.linalg.norm(d1, axis=1) ** 3


@pytest.mark.parametrize("tol", [1e-2, 5e-3])
@pytest.mark.parametrize("a0", [0.0, 0.3, 0.5 * PI, PI, -0.5 * PI])
def test_quantized_circle_keeps_curvature_near_one_over_r(tol, a0):
    # circle_small_segments_ncd.ngc in small: a 1-inch circle of 15 µm chords whose
    # coordinates are rounded to 0.0001 in. Chord angles then scatter by ±0.05π around
    # Eq. (1)'s interval ends, and three-point curvature estimates by ±10 /mm. The fit
    # used to switch frames from chord to chord and inherit those estimates: curvature
    # spikes up to 900 /mm inside the tolerance, and a 20x slower feed plan.
    R, q = 25.4, 0.00254
    n = int(0.5 * PI * R / 0.015)
    nodes = np.round(_circle(R, n=n, sweep=0.5 * PI, a0=a0) / q) * q
    path, dev = _fit(nodes, tol=tol)
    assert dev <= tol
    assert distance_to_path(path, nodes).max() <= tol * (1 + 1e-6)
    pos, tan, curv = continuity(path)
    assert pos < 1e-9 and tan < 1e-9 and curv < 1e-9
    k = _curvature(path)
    assert np.all(np.isfinite(k))
    assert np.abs(k - 1.0 / R).max() <= 1.0 / R
    assert path.n_seg <= 10


def test_noisy_line_on_an_eq1_interval_end_keeps_one_frame():
    # a line at -0.02π (where Eq. (1) switches between θ = 0 and θ = -π/2) with
    # ±1 µm noise: every segment stays in the frame θ = 0 and the line stays straight
    rng = np.random.default_rng(7)
    n = 600
    t = np.linspace(0.0, 30.0, n)
    a = -0.02 * PI
    nodes = np.zeros((n, 3))
    nodes[:, 0] = t * np.cos(a)
    nodes[:, 2] = t * np.sin(a) + rng.uniform(-1e-3, 1e-3, n)
    path, dev = _fit(nodes, tol=5e-3)
    assert dev <= 5e-3
    assert np.all(path.planar.theta == 0.0)
    assert np.abs(_curvature(path)).max() <= 0.05

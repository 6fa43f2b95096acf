"""Curvature peaks (paper 000 Eq. 3) and per-segment geometry."""

import math

import numpy as np
from numpy.testing import assert_allclose

from cnc_interp.fit.path import Path
from cnc_interp.plan.paper000 import shapes
from cnc_interp.plan.paper000.curvature import (
    general_curvature_peaks,
    planar_curvature_peaks,
    segment_geometry,
)


def helix_path(radius=5.0, pitch_per_rad=1.0, turns=1.5, n_seg=40):
    """A general (non-planar) 3-axis quintic Hermite helix in its angle parameter."""
    u = np.linspace(0, 2 * math.pi * turns, n_seg + 1)

    def d(u, k):
        c, s = np.cos(u), np.sin(u)
        return [
            np.stack([radius * c, radius * s, pitch_per_rad * u], -1),
            np.stack([-radius * s, radius * c, np.full_like(u, pitch_per_rad)], -1),
            np.stack([-radius * c, -radius * s, np.zeros_like(u)], -1),
        ][k]

    h = np.diff(u)[0]
    m = np.array(
        [
            [h**i if True else 0 for i in range(6)],
            [i * h ** (i - 1) if i else 0 for i in range(6)],
            [i * (i - 1) * h ** (i - 2) if i > 1 else 0 for i in range(6)],
        ],
        dtype=float,
    )
    coef = np.zeros((n_seg, 6, 3))
    for k in range(n_seg):
        p0, p1, p2 = (d(u[k : k + 1], i)[0] for i in range(3))
        e0, e1, e2 = (d(u[k + 1 : k + 2], i)[0] for i in range(3))
        coef[k, 0], coef[k, 1], coef[k, 2] = p0, p1, p2 / 2
        rhs = np.stack([e0 - (p0 + p1 * h + p2 / 2 * h**2), e1 - (p1 + p2 * h), e2 - p2])
        coef[k, 3:] = np.linalg.solve(m[:, 3:], rhs)
    return Path(axes="XYZ", breaks=u, coef=coef, line=np.arange(n_seg), feed_mm_s=np.full(n_seg, np.inf))


def test_eq3_on_cubic():
    # p = x^3: Eq. 3 gives (1 + 9x^4) 6 - 3 (3x^2)(6x)^2 = 6 - 270 x^4 = 0
    p = np.array([[0, 0, 0, 1.0, 0, 0]])
    k, x = planar_curvature_peaks(p, np.array([2.0]))
    x0 = 45**-0.25
    assert_allclose(x[0], x0, rtol=1e-9)
    assert_allclose(k[0], 6 * x0 / (1 + 9 * x0**4) ** 1.5, rtol=1e-12)


def test_eq3_endpoint_peak():
    # p = x^2 on [0, 1]: curvature is largest at x = 0 (2), an end, not an interior root
    k, x = planar_curvature_peaks(np.array([[0, 0, 1.0, 0, 0, 0]]), np.array([1.0]))
    assert_allclose(k[0], 2.0)
    assert x[0] == 0.0


def test_circle_curvature_planar_and_general_agree():
    for r in (0.5, 10.0, 300.0):
        c = shapes.circle(r, n_per_turn=36)
        kp = planar_curvature_peaks(c.planar.p, c.planar.x_end)[0]
        assert_allclose(kp, 1.0 / r, rtol=5e-5)  # Hermite arcs of 10 degrees
        plain = Path(axes=c.axes, breaks=c.breaks, coef=c.coef, line=c.line, feed_mm_s=c.feed_mm_s)
        assert_allclose(general_curvature_peaks(plain), kp, rtol=1e-9)


def test_helix_curvature_general():
    r, c = 5.0, 1.0
    path = helix_path(r, c)
    assert_allclose(general_curvature_peaks(path), r / (r * r + c * c), rtol=1e-4)


def test_geometry_maxima_on_circle():
    r = 8.0
    g = segment_geometry(shapes.circle(r, n_per_turn=36))
    assert_allclose(g.length.sum(), 2 * math.pi * r, rtol=1e-7)
    assert_allclose(g.g1.max(axis=0), 1.0, rtol=1e-6)
    assert_allclose(g.g2.max(axis=0), 1.0 / r, rtol=1e-4)
    assert_allclose(g.g3.max(axis=0), 1.0 / r**2, rtol=1e-3)
    assert g.jump1.max() < 1e-9 and g.jump2.max() < 1e-6


def test_geometry_sees_a_corner_and_a_joint_map():
    path = shapes.chain([("line", 10.0), ("arc", 3.0, math.pi / 2), ("line", 10.0)])
    g = segment_geometry(path)
    assert g.jump1.max() < 1e-9  # tangent-continuous ...
    assert_allclose(g.jump2.max(), 1 / 3.0, rtol=1e-3)  # ... but the curvature jumps
    scale = np.array([2.0, 0.5])
    gm = segment_geometry(path, lambda p: p * scale)
    assert_allclose(gm.g1, g.g1 * scale, rtol=1e-6, atol=1e-9)
    assert_allclose(gm.g2, g.g2 * scale, rtol=1e-4, atol=1e-7)

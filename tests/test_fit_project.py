"""The marching projection behind ``max_path_dev_mm`` (``cnc_interp.fit._project``).

Closed-form distances: points beside a straight line that is split into pieces with
curved (non-uniform) parametrisations, and beside a circle; the march must give the
exact distance in path order, never less than the exact distance in any order
(every value is the distance to a real point of the path: conservative), and the
exact distance again wherever the point is beyond its tolerance (the wider search).
"""

from __future__ import annotations

import numpy as np
import pytest

from cnc_interp.fit.deviation import distance_to_pieces, path_deviation, programmed_samples
from cnc_interp.fit.nodes import hermite


def _wavy_line(rng, n_pieces=40, length=10.0):
    """The X axis from 0 to ``length`` as pieces x(t) = a + b t + c t^2 (monotone), y = z = 0."""
    cuts = np.sort(rng.uniform(0.0, length, n_pieces - 1))
    x0 = np.concatenate(([0.0], cuts))
    x1 = np.concatenate((cuts, [length]))
    h = rng.uniform(0.5, 2.0, n_pieces) * (x1 - x0)
    # x(t) = x0 + b t + c t^2 with x(h) = x1 and x'(t) > 0 on [0, h]
    c = rng.uniform(-0.4, 0.4, n_pieces) * (x1 - x0) / h**2
    b = (x1 - x0) / h - c * h
    coef = np.zeros((n_pieces, 6, 3))
    coef[:, 0, 0] = x0
    coef[:, 1, 0] = b
    coef[:, 2, 0] = c
    return np.concatenate(([0.0], np.cumsum(h))), coef


@pytest.mark.parametrize("seed", range(3))
def test_march_is_exact_beside_a_line(seed):
    rng = np.random.default_rng(seed)
    breaks, coef = _wavy_line(rng)
    k = 3000
    x = np.sort(rng.uniform(0.0, 10.0, k))
    off = rng.uniform(-2e-3, 2e-3, k)
    pts = np.column_stack((x, off, np.zeros(k)))
    tol = np.full(k, 1e-3)
    d = distance_to_pieces(breaks, coef, pts, np.ones(3, bool), tol)
    np.testing.assert_allclose(d, np.abs(off), rtol=1e-9, atol=1e-13)
    # the exhaustive search agrees
    np.testing.assert_allclose(
        distance_to_pieces(breaks, coef, pts, np.ones(3, bool)), np.abs(off), rtol=1e-9, atol=1e-13
    )


@pytest.mark.parametrize("seed", range(3))
def test_march_out_of_order_is_conservative_and_exact_beyond_tolerance(seed):
    """Points in random order lose the march: small distances may be over-estimated
    (never under-estimated), distances beyond the tolerance are searched everywhere."""
    rng = np.random.default_rng(10 + seed)
    breaks, coef = _wavy_line(rng)
    k = 2000
    x = rng.uniform(0.0, 10.0, k)
    off = rng.uniform(-3e-3, 3e-3, k)
    pts = np.column_stack((x, off, np.zeros(k)))
    tol = np.full(k, 1e-3)
    d = distance_to_pieces(breaks, coef, pts, np.ones(3, bool), tol)
    assert np.all(np.isfinite(d))
    assert np.all(d >= np.abs(off) * (1 - 1e-9) - 1e-13)
    far = np.abs(off) > 1.01e-3
    np.testing.assert_allclose(d[far], np.abs(off[far]), rtol=1e-9, atol=1e-13)


def test_march_beside_a_circle_of_hermite_pieces():
    """A circle of radius R as quintic Hermite pieces (exact value, tangent, curvature
    at the ends): points at radius R + δ are |δ| away up to the pieces' own error."""
    R, n = 5.0, 24
    a = np.linspace(0.0, 2 * np.pi, n + 1)
    p = R * np.column_stack((np.cos(a), np.sin(a), np.zeros(n + 1)))
    v = np.column_stack((-np.sin(a), np.cos(a), np.zeros(n + 1)))
    acc = -np.column_stack((np.cos(a), np.sin(a), np.zeros(n + 1))) / R
    h = np.full(n, R * 2 * np.pi / n)
    coef = hermite(p[:-1], v[:-1], acc[:-1], p[1:], v[1:], acc[1:], h)
    breaks = np.concatenate(([0.0], np.cumsum(h)))
    # the pieces' own radial error (dense check)
    t = np.linspace(0.0, h[0], 2001)
    q = sum(coef[0, i] * t[:, None] ** i for i in range(6))
    rad_err = np.abs(np.linalg.norm(q, axis=1) - R).max()
    assert rad_err < 1e-6
    rng = np.random.default_rng(5)
    k = 4000
    phi = np.sort(rng.uniform(0.0, 2 * np.pi, k))
    delta = rng.uniform(-2e-3, 2e-3, k)
    pts = (R + delta)[:, None] * np.column_stack((np.cos(phi), np.sin(phi), np.zeros(k)))
    d = distance_to_pieces(breaks, coef, pts, np.ones(3, bool), np.full(k, 1e-3))
    assert np.abs(d - np.abs(delta)).max() <= rad_err * 1.01 + 1e-12


def test_programmed_samples_of_a_polyline():
    """Every move sampled clip(ceil(L / spacing), min, max) times, shared ends once, in order."""
    from cnc_interp.fit.deviation import PATH_DEV_MAX_SAMPLES
    from cnc_interp.fit.deviation import PATH_DEV_MIN_SAMPLES

    nodes = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.05], [1.0, 100.0]])
    tol = np.array([1e-3, 1e-3, 2e-3, 3e-3])
    pts, t = programmed_samples(nodes, tol, (), 0, 0.1)
    counts = [10, PATH_DEV_MIN_SAMPLES, PATH_DEV_MAX_SAMPLES]
    assert pts.shape == (sum(counts) + 1, 2)
    np.testing.assert_allclose(pts[0], nodes[0])
    np.testing.assert_allclose(pts[-1], nodes[-1])
    np.testing.assert_allclose(pts[counts[0]], nodes[1])
    travel = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    assert np.all(travel > 0)  # in path order, no repeated junction points
    np.testing.assert_array_equal(t, np.repeat([1e-3, 1e-3, 2e-3, 3e-3], [1] + counts))


def test_path_deviation_of_a_chord_that_bulges():
    """A fitted piece through both nodes of a straight move that bulges symmetrically
    (largest in the middle, a sample point): the statistic finds the bulge, not only
    the exact nodes."""
    L = 4.0
    p0, p1 = np.zeros((1, 2)), np.array([[L, 0.0]])
    v = np.array([[1.0, 0.0]])
    a = np.array([[0.0, 2e-4]])
    coef = hermite(p0, v, a, p1, v, a, np.array([L]))
    t = np.linspace(0, L, 40001)
    bulge = np.abs(sum(coef[0, i, 1] * t**i for i in range(6))).max()
    nodes = np.array([[0.0, 0.0], [L, 0.0]])
    dev, ratio = path_deviation(np.array([0.0, L]), coef, nodes, np.full(2, 1e-3), np.ones(2, bool))
    assert bulge > 0.5e-4
    assert dev == pytest.approx(bulge, rel=1e-6)
    assert ratio == pytest.approx(dev / 1e-3)

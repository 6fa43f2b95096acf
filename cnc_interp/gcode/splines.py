"""G5 / G5.1 splines and G5.2 / G5.3 NURBS as exact ``Nurbs`` curves plus sampled nodes.

LinuxCNC semantics (src/emc/rs274ngc/interp_convert.cc ``convert_nurbs`` /
``convert_spline`` and ``nurbs_additional_functions.cc``):

* G5.2 opens a NURBS block; the position before it is the first control point
  (weight 1, or the block's P when the G5.2 line names no coordinates); every
  following line names both plane coordinates and a positive weight P; ``L``
  sets the order (default 3, only values > 3 change it); G5.3 ends the block.
* Knots are clamped uniform: ``order`` zeros, then 1, 2, ..., n - order + 1, then
  ``order`` copies of n - order + 2, for n + 1 control points.
* G5 is a cubic Bézier: P0 = current, P1 = current + (I, J), P2 = end + (P, Q),
  P3 = end; without I/J, P1 continues the previous G5 tangent (current - (P, Q) of
  that block). G5.1 is a quadratic Bézier: P0, P1 = current + (I, J), P2 = end.

Curves live in 9-axis machine space (``ALL_AXES`` order); axes outside the plane
stay at their value before the curve.
"""

from __future__ import annotations

import numpy as np

from ..constants import CURVE_CHORD_TOL_MM, CURVE_MAX_NODES
from .arcs import GeometryError
from .program import Nurbs


#: every NURBS/spline knot span gets at least this many node segments
SPLINE_MIN_SEGMENTS_PER_SPAN = 8

#: most bisection passes when sampling a spline to CURVE_CHORD_TOL_MM
#: (CURVE_MAX_NODES bounds the work)
SPLINE_REFINE_PASSES = 48

#: a Bézier whose parameter speed falls to this share of its control polygon's largest
#: leg has a cusp there (the path reverses): it is cut into curves that meet at a stop
BEZIER_CUSP_REL_SPEED = 1e-7


def clamped_uniform_knots(n_control: int, order: int) -> np.ndarray:
    """LinuxCNC's knot vector for ``n_control`` points of ``order`` (length n_control + order)."""
    n = n_control - 1
    k = order
    knots = [0.0] * k + [float(i - k + 1) for i in range(k, n + 1)] + [float(n - k + 2)] * k
    return np.array(knots, dtype=float)


def make_nurbs(line: int, control9: np.ndarray, weights: np.ndarray, order: int) -> Nurbs:
    """A NURBS in 9-axis space from control points (M, 9), weights (M,) and order."""
    m = control9.shape[0]
    if m < order:
        raise GeometryError(f"NURBS block has {m} control points, fewer than its order L={order}")
    if np.any(weights <= 0) or not np.all(np.isfinite(weights)):
        raise GeometryError("NURBS weights P must be positive")
    return Nurbs(
        line=line,
        control=np.asarray(control9, dtype=float),
        weights=np.asarray(weights, dtype=float),
        knots=clamped_uniform_knots(m, order),
        order=order,
    )


def bezier(line: int, control9: np.ndarray) -> Nurbs:
    """A Bézier curve (G5 cubic: 4 points, G5.1 quadratic: 3 points) as a NURBS."""
    m = control9.shape[0]
    return Nurbs(
        line=line,
        control=np.asarray(control9, dtype=float),
        weights=np.ones(m),
        knots=np.array([0.0] * m + [1.0] * m),
        order=m,
    )


def bezier_cusps(control: np.ndarray) -> np.ndarray:
    """Parameters t in (0, 1), ascending, where the Bézier with ``control`` (m, d) points
    has a cusp: its derivative vanishes (to ``BEZIER_CUSP_REL_SPEED``), so the curve stops
    and turns back there, as ``G5 I10 J0 P-10 Q0 X0 Y0`` does twice."""
    ctrl = np.asarray(control, dtype=float)
    deg = ctrl.shape[0] - 1
    if deg < 2:
        return np.zeros(0)
    legs = deg * np.diff(ctrl, axis=0)  # the derivative's control points (deg, d)
    scale = float(np.abs(legs).max()) if legs.size else 0.0
    if scale == 0.0:
        return np.zeros(0)
    # B'(t) in the power basis, per coordinate: c[k] t^k
    n = legs.shape[0] - 1
    from math import comb

    power = np.zeros((n + 1, ctrl.shape[1]))
    for i in range(n + 1):
        for k in range(i, n + 1):
            power[k] += comb(n, i) * comb(n - i, k - i) * (-1) ** (k - i) * legs[i]
    # stationary points of |B'(t)|^2: roots of B'(t) . B''(t)
    dot = np.zeros(2 * n)
    for a in range(n + 1):
        for b in range(1, n + 1):
            dot[a + b - 1] += b * float(power[a] @ power[b])
    cands = np.polynomial.polynomial.polyroots(dot) if np.any(dot) else np.zeros(0)
    t = np.real(cands[np.abs(np.imag(cands)) <= 1e-9])
    t = np.unique(t[(t > 1e-9) & (t < 1.0 - 1e-9)])
    speed = np.abs(np.stack([np.polynomial.polynomial.polyval(t, power[:, c]) for c in range(ctrl.shape[1])]))
    return t[np.sqrt((speed**2).sum(axis=0)) <= BEZIER_CUSP_REL_SPEED * scale] if t.size else t


def split_bezier(control: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """The Bézier with ``control`` (m, d) cut at ``t`` into two (de Casteljau): the
    control points of [0, t] and of [t, 1]."""
    pts = np.asarray(control, dtype=float)
    left, right = [pts[0]], [pts[-1]]
    while pts.shape[0] > 1:
        pts = (1.0 - t) * pts[:-1] + t * pts[1:]
        left.append(pts[0])
        right.append(pts[-1])
    return np.array(left), np.array(right[::-1])


def sample_nurbs(curve: Nurbs) -> np.ndarray:
    """Nodes (K, 9) along ``curve`` after its start, the last being the exact end point.

    Uniform in the knot parameter (``SPLINE_MIN_SEGMENTS_PER_SPAN`` per span) and then
    bisected where the curve's midpoint lies farther than ``CURVE_CHORD_TOL_MM`` from
    the chord, at most ``SPLINE_REFINE_PASSES`` times.
    """
    knots = curve.knots
    k = curve.order - 1
    u0, u1 = float(knots[k]), float(knots[-k - 1])
    spans = np.unique(knots[k : len(knots) - k])
    if spans.size * SPLINE_MIN_SEGMENTS_PER_SPAN > CURVE_MAX_NODES:
        raise GeometryError(f"spline too large: more than {CURVE_MAX_NODES} nodes")
    u = np.concatenate(
        [np.linspace(a, b, SPLINE_MIN_SEGMENTS_PER_SPAN + 1)[:-1] for a, b in zip(spans[:-1], spans[1:])]
        + [np.array([u1])]
    )
    if u.size < 2:
        u = np.array([u0, u1])
    pts = curve.points(u)
    for _ in range(SPLINE_REFINE_PASSES):
        um = 0.5 * (u[:-1] + u[1:])
        pm = curve.points(um)
        dev = np.sqrt(((pm - 0.5 * (pts[:-1] + pts[1:])) ** 2).sum(axis=1))
        bad = dev > CURVE_CHORD_TOL_MM
        if not bad.any():
            break
        if u.size + int(bad.sum()) > CURVE_MAX_NODES:
            raise GeometryError(
                f"spline too large: more than {CURVE_MAX_NODES} nodes at {CURVE_CHORD_TOL_MM} mm chord error"
            )
        u = np.insert(u, np.nonzero(bad)[0] + 1, um[bad])
        pts = curve.points(u)
    pts = pts[1:].copy()
    # the clamped curve ends exactly on its last control point
    pts[-1] = curve.control[-1]
    if not np.all(np.isfinite(pts)):
        raise GeometryError("NURBS evaluates to a non-finite point")
    return pts

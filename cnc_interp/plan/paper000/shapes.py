"""Exact planar quintic paths for tests and benchmarks: circles, arcs and lines.

``planar_path`` turns paper 000's per-segment form (theta, origin, x_end, p) into a
``Path`` (the conversion is exact: each rotated quintic is a quintic in x*). Arcs are
quintic Hermite interpolants of the circle matching position, slope and second
derivative at both ends, so consecutive arcs join G2 and the curvature is 1/R to
within the interpolation error (about 1e-6 relative for a 30 degree arc).
"""

from __future__ import annotations

import math

import numpy as np


def planar_path(theta, origin, x_end, p, feed_mm_s=np.inf, axes: str = "XY", line=None):
    """A 2-axis ``Path`` with ``path.planar`` set, from paper 000's per-segment form."""
    from ...fit.path import Path, PlanarSegments

    theta = np.asarray(theta, dtype=float)
    origin = np.asarray(origin, dtype=float).reshape(-1, 2)
    x_end = np.asarray(x_end, dtype=float)
    p = np.asarray(p, dtype=float).reshape(-1, 6)
    n = theta.size
    ct, st = np.cos(theta)[:, None], np.sin(theta)[:, None]
    base = np.zeros((n, 6))
    base[:, 1] = 1.0
    coef = np.empty((n, 6, 2))
    coef[:, :, 0] = base * ct - p * st
    coef[:, :, 1] = base * st + p * ct
    coef[:, 0, 0] += origin[:, 0]
    coef[:, 0, 1] += origin[:, 1]
    breaks = np.concatenate(([0.0], np.cumsum(x_end)))
    feed = np.broadcast_to(np.asarray(feed_mm_s, dtype=float), (n,))
    planar = PlanarSegments(plane=(0, 1), theta=theta, origin=origin, x_end=x_end, p=p)
    return Path(
        axes=axes,
        breaks=breaks,
        coef=coef,
        line=np.arange(1, n + 1) if line is None else line,
        feed_mm_s=feed,
        planar=planar,
    )


def arc_quintic(radius: float, angle_rad: float) -> tuple[float, np.ndarray]:
    """(chord, p (6,)): quintic of a left-turning arc over its chord in the rotated frame."""
    half = 0.5 * abs(angle_rad)
    c = 2.0 * radius * math.sin(half)
    sgn = 1.0 if angle_rad > 0 else -1.0
    # a left turn starts below the chord and bends up: p'(0) = -tan(half), p'' > 0
    d1 = -sgn * math.tan(half)  # p'(0); p'(c) = -d1
    d2 = sgn / (radius * math.cos(half) ** 3)  # p''(0) = p''(c)
    rows = []
    rhs = []
    for x, (v0, v1, v2) in ((0.0, (0.0, d1, d2)), (c, (0.0, -d1, d2))):
        rows.append([x**i for i in range(6)])
        rows.append([i * x ** (i - 1) if i >= 1 else 0.0 for i in range(6)])
        rows.append([i * (i - 1) * x ** (i - 2) if i >= 2 else 0.0 for i in range(6)])
        rhs += [v0, v1, v2]
    return c, np.linalg.solve(np.array(rows), np.array(rhs))


def chain(pieces, start=(0.0, 0.0), heading_rad: float = 0.0, feed_mm_s=np.inf, n_arc: int = 12):
    """Path of consecutive ``("line", length)`` and ``("arc", radius, angle_rad)`` pieces.

    Arcs are split into ``n_arc`` segments per full turn (at least one); positive angles
    turn left. The path is tangent-continuous where the pieces are (lines into arcs are
    G1: the curvature jumps there).
    """
    theta, origin, x_end, p = [], [], [], []
    pos = np.asarray(start, dtype=float)
    head = heading_rad
    for pc in pieces:
        if pc[0] == "line":
            theta.append(head)
            origin.append(pos.copy())
            x_end.append(float(pc[1]))
            p.append(np.zeros(6))
            pos = pos + pc[1] * np.array([math.cos(head), math.sin(head)])
        else:
            _, r, ang = pc
            m = max(1, int(math.ceil(abs(ang) / (2 * math.pi) * n_arc)))
            for _ in range(m):
                da = ang / m
                c, pk = arc_quintic(r, da)
                th = head + 0.5 * da  # chord direction
                theta.append(th)
                origin.append(pos.copy())
                x_end.append(c)
                p.append(pk)
                pos = pos + c * np.array([math.cos(th), math.sin(th)])
                head += da
    return planar_path(theta, origin, x_end, p, feed_mm_s=feed_mm_s)


def circle(radius: float, turns: float = 1.0, n_per_turn: int = 12, feed_mm_s=np.inf):
    """A full circle (or several turns) of ``radius`` starting at (radius, 0) heading +Y."""
    return chain(
        [("arc", radius, 2 * math.pi * turns)],
        start=(radius, 0.0),
        heading_rad=math.pi / 2,
        feed_mm_s=feed_mm_s,
        n_arc=n_per_turn,
    )


def hermite_path(u_nodes, d0, d1, d2, axes: str, feed_mm_s=np.inf):
    """General (``planar=None``) C2 quintic path interpolating a parametric curve.

    ``d0, d1, d2`` are callables u (K,) -> (K, n): the curve and its first two
    u-derivatives. Each segment matches position, first and second derivative at both
    of its nodes, so the path is C2 in u (G2).
    """
    from ...fit.path import Path

    u = np.asarray(u_nodes, dtype=float)
    h = np.diff(u)
    p0, p1, p2 = d0(u[:-1]), d1(u[:-1]), d2(u[:-1])
    e0, e1, e2 = d0(u[1:]), d1(u[1:]), d2(u[1:])
    n_seg, n = p0.shape
    coef = np.zeros((n_seg, 6, n))
    coef[:, 0], coef[:, 1], coef[:, 2] = p0, p1, 0.5 * p2
    hh = h[:, None]
    r0 = e0 - (p0 + p1 * hh + 0.5 * p2 * hh**2)
    r1 = e1 - (p1 + p2 * hh)
    r2 = e2 - p2
    # rows: t^3, t^4, t^5 and their first two derivatives at t = h
    m = np.stack(
        [
            np.stack([h**3, h**4, h**5], -1),
            np.stack([3 * h**2, 4 * h**3, 5 * h**4], -1),
            np.stack([6 * h, 12 * h**2, 20 * h**3], -1),
        ],
        1,
    )  # (n_seg, 3, 3)
    rhs = np.stack([r0, r1, r2], 1)  # (n_seg, 3, n)
    coef[:, 3:] = np.linalg.solve(m, rhs)
    feed = np.broadcast_to(np.asarray(feed_mm_s, dtype=float), (n_seg,))
    return Path(axes=axes, breaks=u, coef=coef, line=np.arange(1, n_seg + 1), feed_mm_s=feed)


def bump(height: float = 3.0, width: float = 2.0, half_span: float = 60.0, n_seg: int = 120, feed_mm_s=np.inf):
    """G2 path y = height exp(-(x/width)^2) on |x| <= half_span: long straights, one tight bump.

    Peak curvature 2 height / width^2 at x = 0.
    """
    x = np.sinh(np.linspace(-1, 1, n_seg + 1) * np.arcsinh(half_span / width)) * width

    def f(k):
        def g(u):
            e = height * np.exp(-((u / width) ** 2))
            y = [e, -2 * u / width**2 * e, (4 * u * u / width**4 - 2 / width**2) * e][k]
            xs = [u, np.ones_like(u), np.zeros_like(u)][k]
            return np.stack([xs, y], -1)

        return g

    return hermite_path(x, f(0), f(1), f(2), "XY", feed_mm_s=feed_mm_s)

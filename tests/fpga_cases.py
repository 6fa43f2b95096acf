"""Hand-built planar paths and plans for the FPGA tests (independent of the fit and plan stages)."""

from __future__ import annotations

import numpy as np

from cnc_interp.fit.path import Path, PlanarSegments
from cnc_interp.plan.trajectory import Trajectory


def planar_path(theta, p, x_end, origin0=(0.0, 0.0), axes="XZ", plane=(0, 1), other=None, line0=10) -> Path:
    """A Path made of paper-000 segments, each starting where the previous one ends.

    theta (n,), p (n, 6) with p[:, 0] = 0, x_end (n,). ``other``: fixed values of
    the axes outside the plane.
    """
    theta = np.asarray(theta, float)
    p = np.asarray(p, float)
    x_end = np.asarray(x_end, float)
    n = theta.size
    n_axes = len(axes)
    origin = np.zeros((n, 2))
    o = np.array(origin0, float)
    coef = np.zeros((n, 6, n_axes))
    h, v = plane
    for k in range(n):
        origin[k] = o
        c, s = np.cos(theta[k]), np.sin(theta[k])
        # q_h = o_h + x c - p(x) s ; q_v = o_v + x s + p(x) c  (quintics in x)
        ch = -s * p[k]
        cv = c * p[k]
        ch = ch.copy()
        cv = cv.copy()
        ch[0] += o[0]
        cv[0] += o[1]
        ch[1] += c
        cv[1] += s
        coef[k, :, h] = ch
        coef[k, :, v] = cv
        for i in range(n_axes):
            if i not in plane:
                coef[k, 0, i] = 0.0 if other is None else other[i]
        pe = np.polynomial.polynomial.polyval(x_end[k], p[k])
        o = o + np.array([x_end[k] * c - pe * s, x_end[k] * s + pe * c])
    breaks = np.concatenate(([0.0], np.cumsum(x_end)))
    planar = PlanarSegments(plane=plane, theta=theta, origin=origin, x_end=x_end, p=p)
    return Path(
        axes=axes, breaks=breaks, coef=coef, line=np.arange(n) + line0, feed_mm_s=np.full(n, 100.0), planar=planar
    )


def gentle_curve(n_seg=6, seed=0, axes="XZ", plane=(0, 1), other=None) -> Path:
    """A gentle wavy curve with rotations 0, π/2, -π/2, π and a general angle."""
    rng = np.random.default_rng(seed)
    thetas = [0.0, np.pi / 2, 0.0, -np.pi / 2, np.pi, 0.3]
    theta = np.array([thetas[k % len(thetas)] for k in range(n_seg)])
    x_end = rng.uniform(3.0, 12.0, n_seg)
    p = np.zeros((n_seg, 6))
    for k in range(n_seg):
        # small quintic: slope and curvature stay moderate on [0, x_end]
        L = x_end[k]
        p[k, 1:] = rng.uniform(-1, 1, 5) * np.array([0.3, 0.05 / L, 0.02 / L**2, 0.01 / L**3, 0.005 / L**4])
    return planar_path(theta, p, x_end, axes=axes, plane=plane, other=other)


def quintic_plan(
    path: Path, dt_s=0.001, duration_s=None, feed_mm_s=50.0, rest_before=3, rest_after=3, s_offset=0.0, t0_index=0
) -> Trajectory:
    """Rest-to-rest plan along ``path`` with s(τ) = L(10τ³ − 15τ⁴ + 6τ⁵)."""
    L = path.length
    T = duration_s or max(1.875 * L / feed_mm_s, 10 * dt_s)
    n = int(np.ceil(T / dt_s))
    tau = np.arange(n + 1) / n
    s = L * (10 * tau**3 - 15 * tau**4 + 6 * tau**5)
    s = np.concatenate((np.zeros(rest_before), s, np.full(rest_after, L)))
    q = path(s)
    q[s <= 0] = path.start
    K = s.size
    t = (np.arange(K) + t0_index) * dt_s
    feed = np.concatenate(([0.0], np.diff(s) / dt_s))
    seg = path.segment_of_s(s)
    return Trajectory(
        axes=path.axes, dt_s=dt_s, t=t, s=s + s_offset, feed=feed, q=q, line=path.line[seg], planner="test"
    )

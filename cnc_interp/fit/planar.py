"""Paper 000's planar toolpath generator (de Santiago-Perez et al. 2010), as corrected in DESIGN.md.

For a run that moves exactly two axes (h, v) — XZ on a lathe, or any plane:

1. tangential angle α_i of every chord (atan2, in [-π, π]);
2. rotation angle θ_i of every chord by Eq. (1) with the -π/2 correction, so that
   every rotated inclination α - θ lies in [-0.04π, 0.49π];
3. segmentation: maximal groups of consecutive chords with the same θ;
4. Eq. (2): the group's nodes, translated to the segment's first node and rotated
   by -θ, become (x*, z*) with x* strictly increasing;
5. a quintic p(x*) = Σ a_i x*^i is fitted by least squares to the interior nodes
   with p(0) = 0, p(x_end) = z_end and, after the first segment of a path,
   p'(0) = ρ1, p''(0) = ρ2 taken from the previous segment's end transformed
   between the frames (tangent angle φ → φ + θ_prev - θ, curvature invariant:
   ρ2 = κ (1 + ρ1²)^{3/2}), which makes the path G2;
6. if a node is farther than the maximum permissible error the last node is
   dropped and the fit repeated (we gallop then bisect over the number of nodes
   rather than dropping one at a time: the same answer when the error grows with
   the segment, in O(r log r)); the dropped nodes start the next segment.

A tiny ∫p'''² term (``PLANAR_SMOOTHING``) keeps a segment with no interior node
well posed. Node deviation is the smaller of the vertical residual and the
distance to a Newton-projected point of the curve (both bound the true distance).

The per-segment data (θ_k, origin_k, x_end_k, a_k) are kept as ``PlanarSegments``
and convert exactly (coefficient-wise) into a ``Path``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..constants import (
    FIT_SAGITTA_ALLOWANCE,
    FIT_TOL_SAFETY,
    PLANAR_END_WEIGHT,
    PLANAR_MAX_INCLINATION_PI,
    PLANAR_SMOOTHING,
)
from .nodes import sagitta_allowance, segment_sources
from .path import Path, PlanarSegments

_PI = math.pi


@njit(cache=True)
def rotation_angle(alpha):
    """Eq. (1) as corrected in DESIGN.md: θ for a tangential angle α in [-π, π]."""
    if alpha <= -0.51 * _PI:
        return _PI
    if alpha <= -0.02 * _PI:
        return -0.5 * _PI
    if alpha <= 0.47 * _PI:
        return 0.0
    if alpha <= 0.96 * _PI:
        return 0.5 * _PI
    return _PI


def rotation_angles(alpha: np.ndarray) -> np.ndarray:
    """Vectorised Eq. (1): θ (K,) for tangential angles α (K,) in [-π, π]."""
    a = np.asarray(alpha, dtype=float)
    return _THETA_OF_BIN[np.searchsorted(_EQ1_EDGES, a, side="left")]


# Eq. (1)'s interval ends (each interval is closed on the right) and θ per interval
_EQ1_EDGES = np.array([-0.51, -0.02, 0.47, 0.96]) * np.pi
_THETA_OF_BIN = np.array([np.pi, -0.5 * np.pi, 0.0, 0.5 * np.pi, np.pi])


def wrap_angle(a):
    """Wrap angles to (-π, π]."""
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=float), 2 * np.pi)


_GLX = np.array([-0.8611363115940526, -0.3399810435848563, 0.3399810435848563, 0.8611363115940526])
_GLW = np.array([0.3478548451374538, 0.6521451548625461, 0.6521451548625461, 0.3478548451374538])


@njit(cache=True)
def _fit_segment(xs, zs, constrained, rho1, rho2, mu, b, has_end, d1_est, d2_est, w_end):
    """Fit normalised coefficients b (6,) (q(ξ) = Σ b_i ξ^i, ξ = x*/X) to nodes xs, zs (r,)
    (xs[0] = zs[0] = 0, xs[-1] = X > 0). Returns nothing; fills b."""
    r = xs.shape[0]
    X = xs[r - 1]
    Z = zs[r - 1]
    F = 2 if constrained else 4
    A = np.zeros((F, F))
    rhs = np.zeros(F)
    phi = np.empty(F)
    # basis of the affine family q = base(ξ) + Σ β_f φ_f(ξ)
    for j in range(1, r - 1):
        xi = xs[j] / X
        x2 = xi * xi
        x3 = x2 * xi
        if constrained:
            b1 = rho1 * X
            b2 = 0.5 * rho2 * X * X
            base = b1 * xi + b2 * x2 + (Z - b1 - b2) * x3
            phi[0] = x3 * xi - x3
            phi[1] = x3 * x2 - x3
        else:
            base = Z * xi
            phi[0] = x2 - xi
            phi[1] = x3 - xi
            phi[2] = x3 * xi - xi
            phi[3] = x3 * x2 - xi
        res = zs[j] - base
        for a in range(F):
            rhs[a] += phi[a] * res
            for c in range(F):
                A[a, c] += phi[a] * phi[c]
    # smoothing: mu ∫_0^1 (q''')^2 dξ, 4-point Gauss-Legendre (exact for degree 4)
    for g in range(4):
        xi = 0.5 * (_GLX[g] + 1.0)
        wq = 0.5 * _GLW[g] * mu
        if constrained:
            b1 = rho1 * X
            b2 = 0.5 * rho2 * X * X
            c0 = 6.0 * (Z - b1 - b2)
            phi[0] = 24.0 * xi - 6.0
            phi[1] = 60.0 * xi * xi - 6.0
        else:
            c0 = 0.0
            phi[0] = 0.0
            phi[1] = 6.0
            phi[2] = 24.0 * xi
            phi[3] = 60.0 * xi * xi
        for a in range(F):
            rhs[a] -= wq * phi[a] * c0
            for c in range(F):
                A[a, c] += wq * phi[a] * phi[c]
    if has_end:
        # soft end conditions: dq/dξ(1) and d²q/dξ²(1) towards the local estimates
        g1 = np.empty(F)
        g2 = np.empty(F)
        if constrained:
            b1 = rho1 * X
            b2 = 0.5 * rho2 * X * X
            R = Z - b1 - b2
            c1 = b1 + 2.0 * b2 + 3.0 * R
            c2 = 2.0 * b2 + 6.0 * R
            g1[0] = 1.0
            g1[1] = 2.0
            g2[0] = 6.0
            g2[1] = 14.0
        else:
            c1 = Z
            c2 = 0.0
            g1[0] = 1.0
            g1[1] = 2.0
            g1[2] = 3.0
            g1[3] = 4.0
            g2[0] = 2.0
            g2[1] = 6.0
            g2[2] = 12.0
            g2[3] = 20.0
        t1 = d1_est * X - c1
        t2 = d2_est * X * X - c2
        w1 = w_end * w_end
        w2 = w1 / 16.0
        for a in range(F):
            rhs[a] += w1 * g1[a] * t1 + w2 * g2[a] * t2
            for c in range(F):
                A[a, c] += w1 * g1[a] * g1[c] + w2 * g2[a] * g2[c]
    for a in range(F):
        A[a, a] += 1e-12 * (1.0 + A[a, a])
    beta = np.linalg.solve(A, rhs)
    b[0] = 0.0
    if constrained:
        b[1] = rho1 * X
        b[2] = 0.5 * rho2 * X * X
        b[4] = beta[0]
        b[5] = beta[1]
        b[3] = Z - b[1] - b[2] - b[4] - b[5]
    else:
        b[2] = beta[0]
        b[3] = beta[1]
        b[4] = beta[2]
        b[5] = beta[3]
        b[1] = Z - b[2] - b[3] - b[4] - b[5]


@njit(cache=True)
def _poly(b, xi):
    return ((((b[5] * xi + b[4]) * xi + b[3]) * xi + b[2]) * xi + b[1]) * xi + b[0]


@njit(cache=True)
def _dpoly(b, xi):
    return (((5 * b[5] * xi + 4 * b[4]) * xi + 3 * b[3]) * xi + 2 * b[2]) * xi + b[1]


@njit(cache=True)
def _ddpoly(b, xi):
    return ((20 * b[5] * xi + 12 * b[4]) * xi + 6 * b[3]) * xi + 2 * b[2]


@njit(cache=True)
def _node_error(b, X, xs, zs, j):
    """An upper bound of the distance from node j to the curve (see module docstring)."""
    xi = xs[j] / X
    vert = abs(_poly(b, xi) - zs[j])
    # Newton on d/dx |(x, p(x)) - node|^2 from the node's abscissa
    x = xs[j]
    for _ in range(3):
        t = x / X
        p = _poly(b, t)
        dp = _dpoly(b, t) / X
        ddp = _ddpoly(b, t) / (X * X)
        g = (x - xs[j]) + (p - zs[j]) * dp
        h = 1.0 + dp * dp + (p - zs[j]) * ddp
        if h <= 0.0:
            break
        x = x - g / h
        if x < 0.0:
            x = 0.0
        if x > X:
            x = X
    p = _poly(b, x / X)
    d = math.sqrt((x - xs[j]) ** 2 + (p - zs[j]) ** 2)
    return min(vert, d)


@njit(cache=True)
def _end_est(e, th, tau, kap, max_incl):
    """Local tangent slope and p'' at node e in the frame θ (estimates from the nodes)."""
    n = tau.shape[0]
    if e <= 0 or e >= n - 1:
        return False, 0.0, 0.0
    ang = tau[e] - th
    ang = _PI - ((_PI - ang) % (2.0 * _PI))
    if abs(ang) >= max_incl:
        return False, 0.0, 0.0
    d1 = math.tan(ang)
    return True, d1, kap[e] * (1.0 + d1 * d1) ** 1.5


@njit(cache=True)
def _try(xs, zs, tol, constrained, rho1, rho2, mu, b, e, th, tau, kap, max_incl, w_end, sag_allow, sag_mid):
    """Fit and return the largest node error minus its tolerance (<= 0 means accepted)."""
    has, d1, d2 = _end_est(e, th, tau, kap, max_incl)
    _fit_segment(xs, zs, constrained, rho1, rho2, mu, b, has and w_end > 0.0, d1, d2, w_end)
    r = xs.shape[0]
    X = xs[r - 1]
    s0 = e - (r - 1)
    worst = -np.inf
    for j in range(1, r - 1):
        err = _node_error(b, X, xs, zs, j) - tol[j]
        if err > worst:
            worst = err
    # between the nodes: the chord midpoints, within the tolerance plus the sagitta a
    # curve of the smaller neighbouring node curvature would have (0 next to a corner)
    for j in range(1, r):
        xm = 0.5 * (xs[j - 1] + xs[j])
        zm = 0.5 * (zs[j - 1] + zs[j])
        sag = sag_mid[s0 + j - 1]
        slope = _dpoly(b, xm / X) / X
        err = abs(_poly(b, xm / X) - zm) / math.sqrt(1.0 + slope * slope) - (tol[j] + sag_allow * sag)
        if err > worst:
            worst = err
    return worst


@njit(cache=True)
def _wrap(a):
    return _PI - ((_PI - a) % (2.0 * _PI))


@njit(cache=True)
def planar_fit_kernel(H, V, tol, alpha, theta_chord, tau, kap, w_end, max_incl, mu,
                      out_theta, out_start, out_end, out_b, sag_allow, sag_mid):
    """Segment and fit nodes (H, V) (n,); returns (n_seg, status, max_dev).

    status 0 = ok; 1 = an inherited tangent cannot be represented in the next frame.
    out_* are preallocated with n-1 rows; segment k covers nodes out_start[k]..out_end[k].
    """
    n = H.shape[0]
    s = 0
    k = 0
    constrained = False
    rho1 = 0.0
    rho2 = 0.0
    max_dev = 0.0
    b = np.zeros(6)
    bt = np.zeros(6)
    xs_all = np.empty(n)
    zs_all = np.empty(n)
    phi_abs = 0.0
    kappa = 0.0
    while s < n - 1:
        th = theta_chord[s]
        alt = False
        if constrained:
            # the inherited tangent in this frame (DESIGN.md: the tangent angle rotates,
            # the curvature is invariant)
            phi = _wrap(phi_abs - th)
            if abs(phi) > max_incl:
                # Eq. (1) applied to the inherited tangent instead of the chord: the
                # segment then takes the following chords that this frame can represent
                th = rotation_angle(_wrap(phi_abs))
                phi = _wrap(phi_abs - th)
                alt = True
                if abs(phi) > max_incl or abs(_wrap(alpha[s] - th)) >= max_incl:
                    return k, 1, max_dev
            rho1 = math.tan(phi)
            rho2 = kappa * (1.0 + rho1 * rho1) ** 1.5
        g_end = s + 1
        if alt:
            while g_end < n - 1 and abs(_wrap(alpha[g_end] - th)) < max_incl:
                g_end += 1
        else:
            while g_end < n - 1 and theta_chord[g_end] == th:
                g_end += 1
        c = math.cos(th)
        sn = math.sin(th)
        for j in range(s, g_end + 1):
            dx = H[j] - H[s]
            dz = V[j] - V[s]
            xs_all[j - s] = dx * c + dz * sn
            zs_all[j - s] = -dx * sn + dz * c
        tl = tol[s:g_end + 1]
        # gallop: largest e with a passing fit, e in [s+1, g_end]
        lo = s + 1
        hi = g_end + 1  # first known failing end (exclusive bound)
        step = 2
        e = min(s + step, g_end)
        while True:
            if e <= lo:
                break
            r = e - s + 1
            if _try(xs_all[:r], zs_all[:r], tl[:r], constrained, rho1, rho2, mu, bt,
                    e, th, tau, kap, max_incl, w_end, sag_allow, sag_mid) <= 0.0:
                lo = e
                if e == g_end:
                    break
                step *= 2
                e = min(s + step, g_end)
            else:
                hi = e
                break
        while hi - lo > 1:
            mid = (lo + hi) // 2
            r = mid - s + 1
            if _try(xs_all[:r], zs_all[:r], tl[:r], constrained, rho1, rho2, mu, bt,
                    mid, th, tau, kap, max_incl, w_end, sag_allow, sag_mid) <= 0.0:
                lo = mid
            else:
                hi = mid
        e = lo
        r = e - s + 1
        has, d1, d2 = _end_est(e, th, tau, kap, max_incl)
        _fit_segment(xs_all[:r], zs_all[:r], constrained, rho1, rho2, mu, b,
                     has and w_end > 0.0, d1, d2, w_end)
        X = xs_all[r - 1]
        for j in range(1, r - 1):
            d = _node_error(b, X, xs_all[:r], zs_all[:r], j)
            if d > max_dev:
                max_dev = d
        out_theta[k] = th
        out_start[k] = s
        out_end[k] = e
        for i in range(6):
            out_b[k, i] = b[i] / X**i
        k += 1
        if e >= n - 1:
            break
        # hand the end tangent angle (absolute) and curvature to the next segment
        p1 = _dpoly(b, 1.0) / X
        p2 = _ddpoly(b, 1.0) / (X * X)
        kappa = p2 / (1.0 + p1 * p1) ** 1.5
        phi_abs = math.atan(p1) + th
        constrained = True
        s = e
    return k, 0, max_dev


@njit(cache=True)
def node_tangents(H, V):
    """Tangent angle (rad) and signed curvature (1/mm) estimated at every node from its
    neighbours (bisector of the two chords; Menger curvature); zeros at the ends."""
    n = H.shape[0]
    tau = np.zeros(n)
    kap = np.zeros(n)
    for j in range(1, n - 1):
        ax = H[j] - H[j - 1]
        az = V[j] - V[j - 1]
        bx = H[j + 1] - H[j]
        bz = V[j + 1] - V[j]
        la = math.sqrt(ax * ax + az * az)
        lb = math.sqrt(bx * bx + bz * bz)
        ax /= la
        az /= la
        bx /= lb
        bz /= lb
        tau[j] = math.atan2(az + bz, ax + bx)
        span = math.hypot(H[j + 1] - H[j - 1], V[j + 1] - V[j - 1])
        if span > 0.0:
            kap[j] = 2.0 * (ax * bz - az * bx) / span
    return tau, kap


def fit_planar(nodes: np.ndarray, plane: tuple[int, int], tol_mm: np.ndarray, axes: str,
               line: np.ndarray, feed: np.ndarray, weights: np.ndarray | None = None):
    """Fit a 2-axis polyline (n, n_axes) in ``plane`` = (h, v) axis indices.

    Returns ``(planar, coef, line, feed_mm_s, max_dev_mm)`` (build the ``Path`` with
    ``planar_to_path`` or from ``coef`` and ``breaks_of(planar)``), or ``None`` when
    the method cannot continue (an inherited tangent outside the next frame's
    ±0.49π); the caller then uses the N-axis fitter.
    """
    h, v = plane
    H = np.ascontiguousarray(nodes[:, h], dtype=float)
    V = np.ascontiguousarray(nodes[:, v], dtype=float)
    n = H.size
    alpha = np.arctan2(np.diff(V), np.diff(H))
    theta_chord = rotation_angles(alpha)
    tol = np.asarray(tol_mm, dtype=float) * FIT_TOL_SAFETY
    out_theta = np.empty(n - 1)
    out_start = np.empty(n - 1, dtype=np.int64)
    out_end = np.empty(n - 1, dtype=np.int64)
    out_b = np.empty((n - 1, 6))
    tau, kap = node_tangents(H, V)
    k, status, max_dev = planar_fit_kernel(H, V, tol, alpha, theta_chord, tau, kap, PLANAR_END_WEIGHT,
                                           PLANAR_MAX_INCLINATION_PI * np.pi, PLANAR_SMOOTHING,
                                           out_theta, out_start, out_end, out_b, FIT_SAGITTA_ALLOWANCE,
                                           sagitta_allowance(np.hypot(np.diff(H), np.diff(V)), np.abs(kap)))
    if status != 0:
        return None
    theta = out_theta[:k].copy()
    st, en = out_start[:k], out_end[:k]
    origin = np.stack([H[st], V[st]], axis=1)
    c, s_ = np.cos(theta), np.sin(theta)
    x_end = (H[en] - H[st]) * c + (V[en] - V[st]) * s_
    planar = PlanarSegments(plane=(h, v), theta=theta, origin=origin, x_end=x_end,
                            p=out_b[:k].copy())

    # node parameter along the path: x* of each node inside its segment, offset by the breaks
    breaks = np.concatenate(([0.0], np.cumsum(x_end)))
    u = np.empty(n)
    seg_of = np.repeat(np.arange(k), en - st)
    idx = np.arange(1, n)
    u[0] = 0.0
    u[1:] = breaks[seg_of] + (H[idx] - H[st[seg_of]]) * c[seg_of] + (V[idx] - V[st[seg_of]]) * s_[seg_of]
    u[en] = breaks[1:]
    u = np.maximum.accumulate(u)
    seg_line, seg_feed = segment_sources(breaks, u, line, feed)
    return planar, planar_coef(planar, nodes[0], len(axes)), seg_line, seg_feed, float(max_dev)


def planar_to_path(planar: PlanarSegments, fixed: np.ndarray, axes: str, line: np.ndarray,
                   feed_mm_s: np.ndarray, weights: np.ndarray | None = None) -> Path:
    """Exact coefficient-wise conversion of planar segments into a ``Path``.

    ``fixed`` (n_axes,) gives the constant value of every axis outside the plane.
    """
    return Path(axes=axes, breaks=breaks_of(planar), coef=planar_coef(planar, fixed, len(axes)),
                line=line, feed_mm_s=feed_mm_s, weights=weights, planar=planar)


def breaks_of(planar: PlanarSegments) -> np.ndarray:
    """Path breakpoints of planar segments: the cumulated x_end."""
    return np.concatenate(([0.0], np.cumsum(planar.x_end)))


def planar_coef(planar: PlanarSegments, fixed: np.ndarray, n_axes: int) -> np.ndarray:
    """Power-basis coefficients (n_seg, 6, n_axes) of planar segments.

    Segment k's local parameter is x* in [0, x_end[k]]:
    q_h = o_h + x* cos θ - p(x*) sin θ,  q_v = o_v + x* sin θ + p(x*) cos θ.
    """
    h, v = planar.plane
    n_seg = planar.theta.size
    coef = np.zeros((n_seg, 6, n_axes))
    coef[:, 0, :] = fixed[None, :]
    c = np.cos(planar.theta)[:, None]
    s = np.sin(planar.theta)[:, None]
    p = planar.p
    coef[:, :, h] = -p * s
    coef[:, :, v] = p * c
    coef[:, 0, h] += planar.origin[:, 0]
    coef[:, 0, v] += planar.origin[:, 1]
    coef[:, 1, h] += c[:, 0]
    coef[:, 1, v] += s[:, 0]
    return coef

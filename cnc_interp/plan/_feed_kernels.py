"""Numba kernels of the feed-profile LP (``feedprofile``).

* ``table_derivs``: q_s, q_ss, q_sss of a joint table (``vpop.JointTable``: knots ``S``,
  power coefficients ``C`` (m, 6, n) in s - S[p]) at sorted arc lengths;
* ``cubic_basis``: the four non-zero cubic B-spline basis functions and their first
  and second derivatives at sorted points (NURBS book, A2.3);
* ``lp_rows``: the LP rows at the collocation points for one linearisation point.

The profile is w(s) = ṡ² = Σ c_j B_j(s). Along the path, axis i has (Beudaert et al.
2012, Eqs. 1-3, with ṡ = √w, s̈ = w'/2, s⃛ = √w w''/2)::

    velocity      q_s √w
    acceleration  q_ss w + q_s w'/2
    jerk          √w (q_sss w + 3/2 q_ss w' + 1/2 q_s w'')

The jerk bound |E(w)| √w <= J is not convex in w; with E linear, it is written
|E(w)| <= J/√w and the convex right-hand side is replaced by its tangent at ŵ,
J (3/2 ŵ^-1/2 - 1/2 w ŵ^-3/2), which lies below it: every solution of the LP
meets the true bound (the convex-concave procedure; iterating ŵ <- w converges).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

#: the collocation points of ``lp_rows`` (K of them): each point's first basis index
#: ``first`` (K,) int64, the basis B (K, 3, 4) of ``cubic_basis``, and the joint
#: derivatives q_s, q_ss, q_sss (K, n) of ``table_derivs``
Collocation = namedtuple("Collocation", "first B q1 q2 q3")
#: the LP's per-axis data (n,): which axes move, their acceleration (mm/s²) and jerk
#: (mm/s³) limits
AxisLimits = namedtuple("AxisLimits", "moving amax jmax")
#: the LP rows ``lp_rows`` fills, one per row: first column ``first`` int64, the four
#: coefficients ``coef`` (rows, 4) and the right-hand side ``b``
Rows = namedtuple("Rows", "first coef b")


@njit(cache=True, nogil=True)
def table_derivs(S, C, x, q1, q2, q3):
    """q_s, q_ss, q_sss (each (K, n)) of the table at sorted arc lengths x (K,)."""
    m = S.shape[0] - 1
    n = C.shape[2]
    # the first point's piece by bisection (a window far along a long path's table
    # would otherwise walk every piece before it), then walked in order
    p = 0
    if x.shape[0] > 0:
        p = min(max(np.searchsorted(S, x[0], side="right") - 1, 0), max(m - 1, 0))
    for k in range(x.shape[0]):
        xk = x[k]
        while p < m - 1 and xk >= S[p + 1]:
            p += 1
        t = xk - S[p]
        for a in range(n):
            c1 = C[p, 1, a]
            c2 = C[p, 2, a]
            c3 = C[p, 3, a]
            c4 = C[p, 4, a]
            c5 = C[p, 5, a]
            q1[k, a] = c1 + t * (2.0 * c2 + t * (3.0 * c3 + t * (4.0 * c4 + t * 5.0 * c5)))
            q2[k, a] = 2.0 * c2 + t * (6.0 * c3 + t * (12.0 * c4 + t * 20.0 * c5))
            q3[k, a] = 6.0 * c3 + t * (24.0 * c4 + t * 60.0 * c5)


@njit(cache=True, nogil=True)
def cubic_basis(knots, n_coef, x, first, B):
    """For sorted x (K,): ``first[k]`` the index of the first non-zero basis function and
    ``B[k, d, j]`` the d-th derivative (d = 0, 1, 2) of basis function first + j."""
    p = 3
    left = np.empty(p + 1)
    right = np.empty(p + 1)
    ndu = np.empty((p + 1, p + 1))
    a = np.empty((2, p + 1))
    span = p
    for k in range(x.shape[0]):
        xk = x[k]
        while span < n_coef - 1 and xk >= knots[span + 1]:
            span += 1
        first[k] = span - p
        ndu[0, 0] = 1.0
        for j in range(1, p + 1):
            left[j] = xk - knots[span + 1 - j]
            right[j] = knots[span + j] - xk
            saved = 0.0
            for r in range(j):
                ndu[j, r] = right[r + 1] + left[j - r]
                temp = ndu[r, j - 1] / ndu[j, r]
                ndu[r, j] = saved + right[r + 1] * temp
                saved = left[j - r] * temp
            ndu[j, j] = saved
        for j in range(p + 1):
            B[k, 0, j] = ndu[j, p]
        for r in range(p + 1):
            s1 = 0
            s2 = 1
            a[0, 0] = 1.0
            for kk in range(1, 3):
                d = 0.0
                rk = r - kk
                pk = p - kk
                if r >= kk:
                    a[s2, 0] = a[s1, 0] / ndu[pk + 1, rk]
                    d = a[s2, 0] * ndu[rk, pk]
                j1 = 1 if rk >= -1 else -rk
                j2 = kk - 1 if r - 1 <= pk else p - r
                for j in range(j1, j2 + 1):
                    a[s2, j] = (a[s1, j] - a[s1, j - 1]) / ndu[pk + 1, rk + j]
                    d += a[s2, j] * ndu[rk + j, pk]
                if r <= pk:
                    a[s2, kk] = -a[s1, kk - 1] / ndu[pk + 1, r]
                    d += a[s2, kk] * ndu[r, pk]
                B[k, kk, r] = d
                s1, s2 = s2, s1
        # multiply by p!/(p-k)!
        for j in range(p + 1):
            B[k, 1, j] *= p
            B[k, 2, j] *= p * (p - 1)


@njit(cache=True, nogil=True)
def lp_rows(pts, lim, wmax, w_hat, inner, scale, rows):
    """Fill the ``Rows`` rows (in x_j = c_j / scale[j]) for the ``Collocation`` pts under
    the ``AxisLimits`` lim; returns their count.

    Per point k: w <= wmax (scaled by wmax) and for each moving axis i:
    ±(q_ss w + q_s w'/2) / A_i <= 1 and, where ``inner[k]`` (w > 0 is possible),
    ±E_i(w) √ŵ / (3/2 J_i) + w / (3 ŵ) <= 1 (the tangent bound of the module docstring).
    """
    first = pts.first
    B = pts.B
    q1 = pts.q1
    q2 = pts.q2
    q3 = pts.q3
    moving = lim.moving
    amax = lim.amax
    jmax = lim.jmax
    row_first = rows.first
    row_coef = rows.coef
    row_b = rows.b
    K = first.shape[0]
    n = q1.shape[1]
    r = 0
    for k in range(K):
        f = first[k]
        # w <= wmax (w >= 0 holds everywhere: the coefficients are kept >= 0, and a
        # B-spline lies in the convex hull of its coefficients)
        for j in range(4):
            row_coef[r, j] = B[k, 0, j] * scale[f + j] / wmax[k]
        row_first[r] = f
        row_b[r] = 1.0
        r += 1
        wh = w_hat[k]
        for i in range(n):
            if not moving[i]:
                continue
            for j in range(4):
                v = scale[f + j] / amax[i] * (q2[k, i] * B[k, 0, j] + 0.5 * q1[k, i] * B[k, 1, j])
                row_coef[r, j] = v
                row_coef[r + 1, j] = -v
            row_first[r] = f
            row_first[r + 1] = f
            row_b[r] = 1.0
            row_b[r + 1] = 1.0
            r += 2
            if inner[k]:
                gj = np.sqrt(wh) / (1.5 * jmax[i])
                gt = 1.0 / (3.0 * wh)
                for j in range(4):
                    sj = scale[f + j]
                    e = sj * gj * (q3[k, i] * B[k, 0, j] + 1.5 * q2[k, i] * B[k, 1, j] + 0.5 * q1[k, i] * B[k, 2, j])
                    t = sj * gt * B[k, 0, j]
                    row_coef[r, j] = e + t
                    row_coef[r + 1, j] = -e + t
                row_first[r] = f
                row_first[r + 1] = f
                row_b[r] = 1.0
                row_b[r + 1] = 1.0
                r += 2
    return r


@njit(cache=True, nogil=True)
def join_derivs(S, C, xj, q1, q2, q3l, q3r):
    """At table knots xj (sorted, interior): q_s, q_ss (continuous there) and the third
    derivative from the piece on the left and on the right (it jumps at path joins)."""
    n = C.shape[2]
    m = S.shape[0] - 1
    # the first knot's piece by bisection, then walked in order (see table_derivs)
    p = 1
    if xj.shape[0] > 0:
        p = min(max(np.searchsorted(S, xj[0], side="left"), 1), max(m - 1, 1))
    for r in range(xj.shape[0]):
        while p < m - 1 and S[p] < xj[r]:
            p += 1
        h = S[p] - S[p - 1]
        for a in range(n):
            q1[r, a] = C[p, 1, a]
            q2[r, a] = 2.0 * C[p, 2, a]
            q3r[r, a] = 6.0 * C[p, 3, a]
            c3 = C[p - 1, 3, a]
            c4 = C[p - 1, 4, a]
            c5 = C[p - 1, 5, a]
            q3l[r, a] = 6.0 * c3 + h * (24.0 * c4 + h * 60.0 * c5)


@njit(cache=True, nogil=True)
def route_measures(S, C, FB, FV, vmax, amax, jmax, speed_share):
    """The optimal planner's route test on a joint table (``optimal._route``), at its
    knots and piece midpoints x: the share of the length where the curvature speed
    (√(amax/|q_ss|), ∛(jmax/|q_sss|), least over the axes) is below ``speed_share`` of
    the cap (the feed FV over breaks FB, vmax/|q_s|), and the duration (s) at the least
    of the two, trapezoidal in 1/v. Returns (share, t_static)."""
    m = S.shape[0] - 1
    n = C.shape[2]
    x = np.empty(2 * m + 1)
    for p in range(m):
        x[2 * p] = S[p]
        x[2 * p + 1] = 0.5 * (S[p] + S[p + 1])
    x[2 * m] = S[m]
    K = x.shape[0]
    q1 = np.empty((K, n))
    q2 = np.empty((K, n))
    q3 = np.empty((K, n))
    table_derivs(S, C, x, q1, q2, q3)
    nf = FV.shape[0]
    v = np.empty(K)
    limited = np.zeros(K, dtype=np.bool_)
    seg = 0
    for k in range(K):
        vv = np.inf
        va = np.inf
        vj = np.inf
        for a in range(n):
            g1 = abs(q1[k, a])
            g2 = abs(q2[k, a])
            g3 = abs(q3[k, a])
            if g1 > 0.0 and vmax[a] / g1 < vv:
                vv = vmax[a] / g1
            if g2 > 0.0 and np.sqrt(amax[a] / g2) < va:
                va = np.sqrt(amax[a] / g2)
            if g3 > 0.0 and np.cbrt(jmax[a] / g3) < vj:
                vj = np.cbrt(jmax[a] / g3)
        while seg < nf - 1 and FB[seg + 1] <= x[k]:
            seg += 1
        cap = min(vv, FV[seg])
        curv = min(va, vj)
        limited[k] = curv < speed_share * cap
        v[k] = max(min(cap, curv), 1e-300)
    total = 0.0
    lim = 0.0
    t = 0.0
    for k in range(K - 1):
        w = x[k + 1] - x[k]
        total += w
        if limited[k]:
            lim += w
        t += w * 2.0 / (v[k] + v[k + 1])
    return lim / max(total, 1e-300), t

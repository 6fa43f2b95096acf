"""Numba kernels of the feed-profile LP (``optimal.profile``).

* ``table_derivs``: q_s, q_ss, q_sss of a joint table (``vpop.JointTable``: knots ``S``,
  power coefficients ``C`` (m, 6, n) in s - S[p]) at sorted arc lengths;
* ``cubic_basis``: the four non-zero cubic B-spline basis functions and their first
  and second derivatives at sorted points (NURBS book, A2.3);
* ``lp_rows``: the LP rows at the collocation points for one linearisation point;
* ``lp_gather``, ``lp_take`` and ``lp_screen``: the rows of one LP with the fixed
  coefficients moved to the right-hand side, and the row screening of ``optimal.profile``;
* ``lp_objective`` and ``lp_profile_time``: a window LP's objective, and its solution's
  coefficients, next linearisation point and traversal time;
* ``point_estimates`` and ``reach_envelope``: the knot placement's speed estimate, and
  ``knot_probes``: one block of the knot placement (its probes, their enveloped estimate
  and the knot spacing wanted there);
* ``time_nodes``: the time law's node intervals (``optimal.sampling``);
* ``route_measures`` and ``route_batch``: the route test of one path's joint table, and
  of many paths' at once (``optimal.route``).

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

from ._ipm import _ax
from ._table_kernels import build_identity
from .status import OK

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
#: what the speed estimate of ``point_estimates`` reads: the axis limits (n,) of the
#: knot placement (vmax mm/s, amax mm/s², jmax mm/s³), the feed (feed_values mm/s over
#: feed_breaks, path mm), the factors (squared) the estimate may exceed the static
#: acceleration and jerk speeds by, and the sampled start and stop: c0, c1 = J_t dt³ of
#: the tangent at each end (mm), the period dt (s), the path length L (mm)
EstimateInputs = namedtuple("EstimateInputs", "vmax amax jmax feed_breaks feed_values acc_f2 jerk_f2 c0 c1 dt L")
#: per point (K,) of ``point_estimates``: the estimate w (mm²/s²), its jerk term w_jerk,
#: the largest |q_ss| and |q_sss| over the axes (k2 /mm, k3 /mm²), and the tangent's path
#: acceleration and jerk limits (at, jt: least of amax/|q_s|, jmax/|q_s| over the axes
#: with |q_s| > 1e-12; inf where none)
Estimates = namedtuple("Estimates", "w w_jerk k2 k3 at jt")
#: ``route_batch``'s paths: concatenated per-segment coef/feed, per-path breaks/s_breaks
#: (n_seg + 1 each), weights (P, n), lengths (P,) and segment offsets (P + 1,)
RoutePaths = namedtuple("RoutePaths", "coef breaks s_breaks weights lengths feed seg_off")
#: ``route_batch``'s limits (per axis), ramp and tiny durations (s) and the route's speed share
RouteLimits = namedtuple("RouteLimits", "vmax amax jmax ramp_s tiny_s speed_share")


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


@njit(cache=True, nogil=True, inline="always")
def _axis_speed2(q1, k, vmax):
    """min over the axes with q_s != 0 of (vmax / |q_s|)² at point k of q1 (K, n): the
    bound the axis speeds put on w = ṡ²."""
    wv = np.inf
    for a in range(q1.shape[1]):
        g1 = abs(q1[k, a])
        if g1 > 0.0:
            v = vmax[a] / g1
            wv = min(wv, v * v)
    return wv


@njit(cache=True, nogil=True, inline="always")
def _feed_at(xk, feed_breaks, feed_values):
    """The programmed feed (mm/s) at arc length xk: a step function, ``feed_values``
    over ``feed_breaks``."""
    i = np.searchsorted(feed_breaks, xk, side="right") - 1
    return feed_values[min(max(i, 0), feed_values.shape[0] - 1)]


@njit(cache=True, nogil=True)
def wmax_of(x, q1, vmax, feed_breaks, feed_values, out):
    """The bound on w = ṡ² at sorted arc lengths x (K,) with joint tangents q1 (K, n):
    the axis speeds' (``_axis_speed2``) and the segment's feed², into ``out`` (K,)."""
    for k in range(x.shape[0]):
        f = _feed_at(x[k], feed_breaks, feed_values)
        out[k] = min(_axis_speed2(q1, k, vmax), f * f)


@njit(cache=True, nogil=True)
def _derivs_at(S, C, x):
    """``table_derivs`` at sorted x (K,) into new arrays (K, n)."""
    n = C.shape[2]
    q1 = np.empty((x.shape[0], n))
    q2 = np.empty((x.shape[0], n))
    q3 = np.empty((x.shape[0], n))
    table_derivs(S, C, x, q1, q2, q3)
    return q1, q2, q3


@njit(cache=True, nogil=True, inline="always")
def _copy_point(x, q1, q2, q3, k, xv, p1, p2, p3, i):
    """Point k of (x, q1, q2, q3) from point i of (p1, p2, p3) at xv."""
    x[k] = xv
    for a in range(q1.shape[1]):
        q1[k, a] = p1[i, a]
        q2[k, a] = p2[i, a]
        q3[k, a] = p3[i, a]


@njit(cache=True, nogil=True)
def collocation(S, C, br, n_per, joins):
    """A window's collocation points and the joint derivatives there (see
    ``optimal.profile.FeedProfileBuilder._collocation``): ``n_per`` points per interval of
    the breakpoints br (K0,) and the last breakpoint; each segment join inside twice, with
    the third derivative from the left and then from the right. Returns x (K,) sorted
    (equal points: the grid's first, then the join's left and right) and q_s, q_ss,
    q_sss (K, n)."""
    n = C.shape[2]
    kg = (br.shape[0] - 1) * n_per + 1
    xg = np.empty(kg)
    for i in range(br.shape[0] - 1):
        h = br[i + 1] - br[i]
        for j in range(n_per):
            xg[i * n_per + j] = br[i] + h * (j / n_per)
    xg[kg - 1] = br[br.shape[0] - 1]
    g1, g2, g3 = _derivs_at(S, C, xg)
    i0 = np.searchsorted(joins, xg[0], side="right")
    i1 = np.searchsorted(joins, xg[kg - 1], side="left")
    xj = joins[i0:i1] if i1 > i0 else joins[:0]
    nj = xj.shape[0]
    j1 = np.empty((nj, n))
    j2 = np.empty((nj, n))
    j3l = np.empty((nj, n))
    j3r = np.empty((nj, n))
    join_derivs(S, C, xj, j1, j2, j3l, j3r)
    # merge the two sorted sets; equal points: grid, join (left, right)
    K = kg + 2 * nj
    x = np.empty(K)
    q1 = np.empty((K, n))
    q2 = np.empty((K, n))
    q3 = np.empty((K, n))
    k = 0
    a = 0
    c = 0
    while k < K:
        if a < kg and (c == nj or xg[a] <= xj[c]):
            _copy_point(x, q1, q2, q3, k, xg[a], g1, g2, g3, a)
            a += 1
            k += 1
        else:
            _copy_point(x, q1, q2, q3, k, xj[c], j1, j2, j3l, c)
            _copy_point(x, q1, q2, q3, k + 1, xj[c], j1, j2, j3r, c)
            c += 1
            k += 2
    return x, q1, q2, q3


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
    """The optimal planner's route test on a joint table (``optimal.route._route``), at its
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


@njit(cache=True, nogil=True)
def _start_curve(x, c, dt):
    """w of the sampled max-jerk start along a line at distance x: s_k = c k(k+1)(k+2)/6,
    v_k = c k(k+1)/(2 dt), c = J_t dt³ (k from s by Newton)."""
    k = max(np.cbrt(6.0 * max(x, 0.0) / c) - 1.0, 0.0)
    for _ in range(3):
        f = c * k * (k + 1.0) * (k + 2.0) / 6.0 - x
        df = c * (3.0 * k * k + 6.0 * k + 2.0) / 6.0
        k = max(k - f / max(df, 1e-300), 0.0)
    v = c * k * (k + 1.0) / (2.0 * dt)
    return v * v


@njit(cache=True, nogil=True)
def _start_reach(w, c, dt):
    """The distance the sampled start of ``_start_curve`` takes to reach speed² w: the k
    of v_k = √w, then s_k (inf for w = inf)."""
    if not w < np.inf:
        return np.inf
    k = 0.5 * (np.sqrt(1.0 + 8.0 * np.sqrt(max(w, 0.0)) * dt / c) - 1.0)
    return c * k * (k + 1.0) * (k + 2.0) / 6.0


@njit(cache=True, nogil=True)
def point_estimates(S, C, x, inp, out):
    """The knot placement's speed estimate at sorted arc lengths x (K,) into ``out``
    (``Estimates``): the least of the axis speeds and the feed, the static acceleration
    and jerk speeds (times ``inp.acc_f2``, ``inp.jerk_f2``) and the sampled start and
    stop from rest at either end (``optimal.profile.FeedProfileBuilder._raw_estimate``)."""
    K = x.shape[0]
    n = C.shape[2]
    q1 = np.empty((K, n))
    q2 = np.empty((K, n))
    q3 = np.empty((K, n))
    table_derivs(S, C, x, q1, q2, q3)
    for k in range(K):
        wv = _axis_speed2(q1, k, inp.vmax)
        wa = np.inf
        wj = np.inf
        k2 = 0.0
        k3 = 0.0
        at = np.inf
        jt = np.inf
        for a in range(n):
            g1 = abs(q1[k, a])
            g2 = abs(q2[k, a])
            g3 = abs(q3[k, a])
            if g1 > 1e-12:
                at = min(at, inp.amax[a] / g1)
                jt = min(jt, inp.jmax[a] / g1)
            if g2 > 0.0:
                wa = min(wa, inp.amax[a] / g2)
            if g3 > 0.0:
                wj = min(wj, (inp.jmax[a] / g3) ** (2.0 / 3.0))
            k2 = max(k2, g2)
            k3 = max(k3, g3)
        f = _feed_at(x[k], inp.feed_breaks, inp.feed_values)
        w = min(min(wv, f * f), min(inp.acc_f2 * wa, inp.jerk_f2 * wj))
        # the sampled start and stop where they can be below w (within twice the
        # distance the start takes to reach it; beyond, they are far above it)
        if x[k] < 2.0 * _start_reach(w, inp.c0, inp.dt):
            w = min(w, _start_curve(x[k], inp.c0, inp.dt))
        if inp.L - x[k] < 2.0 * _start_reach(w, inp.c1, inp.dt):
            w = min(w, _start_curve(inp.L - x[k], inp.c1, inp.dt))
        out.w[k] = w
        out.w_jerk[k] = inp.jerk_f2 * wj
        out.k2[k] = k2
        out.k3[k] = k3
        out.at[k] = at
        out.jt[k] = jt


@njit(cache=True, nogil=True)
def _slope_limit(x, v, slope):
    """v (N,) at sorted x (N,) lowered in place to what it can reach from the other points
    changing by at most ``slope`` per unit of x, both ways: the running minima of
    v -/+ slope x, each pass taking the values before it."""
    N = x.shape[0]
    m = np.inf
    for i in range(N):
        m = min(m, v[i] - slope * x[i])
        v[i] = min(v[i], m + slope * x[i])
    m = np.inf
    for i in range(N - 1, -1, -1):
        m = min(m, v[i] + slope * x[i])
        v[i] = min(v[i], m - slope * x[i])


@njit(cache=True, nogil=True)
def reach_envelope(x, w, at, jt, acc_factor, jerk_f2, carry_x, carry_w, out):
    """The reach envelope of w at sorted points x (K,) into ``out`` (K,): the speed² a
    path acceleration of ``acc_factor`` times the largest tangent limit ``at`` (w grows
    by 2 A ds) and a jerk-limited ramp (``jerk_f2`` times the largest ``jt``; w^3/4 grows
    by 2.12 √J ds, exact from rest) reach from the other points, both ways. A finite
    ``carry_x`` is a point (carry_x, carry_w) before x[0]: the envelope's last value of
    the block before (``optimal.profile.FeedProfileBuilder._envelope``)."""
    K = x.shape[0]
    A = 0.0
    J = 0.0
    for k in range(K):
        if np.isfinite(at[k]):
            A = max(A, at[k])
        if np.isfinite(jt[k]):
            J = max(J, jt[k])
    A *= acc_factor
    J *= jerk_f2
    if not (A > 0.0 and J > 0.0):
        for k in range(K):
            out[k] = w[k]
        return
    c0 = 1 if np.isfinite(carry_x) else 0
    N = K + c0
    xx = np.empty(N)
    ww = np.empty(N)
    if c0:
        xx[0] = carry_x
        ww[0] = min(carry_w, 1e300)
    for k in range(K):
        xx[k + c0] = x[k]
        ww[k + c0] = min(w[k], 1e300)
    _slope_limit(xx, ww, 2.0 * A)  # w grows by at most 2 A ds
    u = np.empty(N)
    for i in range(N):
        u[i] = ww[i] ** 0.75
    _slope_limit(xx, u, 2.1213203435596424 * np.sqrt(J))  # w^3/4 by at most 2.12 √J ds
    for k in range(K):
        out[k] = min(ww[k + c0], max(u[k + c0], 0.0) ** (4.0 / 3.0))


@njit(cache=True, nogil=True, inline="always")
def _nan_min(a, b):
    """np.minimum of two floats (NaN if either is)."""
    if a != a or b != b:
        return np.nan
    return a if a <= b else b


@njit(cache=True, nogil=True, inline="always")
def _nan_max(a, b):
    """np.maximum of two floats (NaN if either is)."""
    if a != a or b != b:
        return np.nan
    return a if a >= b else b


@njit(cache=True, nogil=True)
def estimates_of(S, C, x, inp):
    """``point_estimates`` at sorted x (K,) into new arrays (an ``Estimates``)."""
    K = x.shape[0]
    out = Estimates(np.empty(K), np.empty(K), np.empty(K), np.empty(K), np.empty(K), np.empty(K))
    point_estimates(S, C, x, inp, out)
    return out


@njit(cache=True, nogil=True)
def _estimates_kept(S, C, x, inp, x0, e0):
    """``estimates_of`` at sorted x (K,) given ``e0`` at sorted x0: the points of x also
    in x0 are taken from there, the others evaluated (a point's estimate is its own)."""
    K = x.shape[0]
    src = np.full(K, -1, dtype=np.int64)
    n_new = K
    for i in range(x0.shape[0]):
        k = np.searchsorted(x, x0[i])
        if k < K and x[k] == x0[i] and src[k] < 0:
            src[k] = i
            n_new -= 1
    xn = np.empty(n_new)
    j = 0
    for k in range(K):
        if src[k] < 0:
            xn[j] = x[k]
            j += 1
    en = estimates_of(S, C, xn, inp)
    out = Estimates(np.empty(K), np.empty(K), np.empty(K), np.empty(K), np.empty(K), np.empty(K))
    j = 0
    for k in range(K):
        if src[k] < 0:
            _copy_estimate(out, k, en, j)
            j += 1
        else:
            _copy_estimate(out, k, e0, src[k])
    return out


@njit(cache=True, nogil=True, inline="always")
def _copy_estimate(out, k, e, i):
    """Every field of ``Estimates`` e at point i into ``out`` at point k."""
    out.w[k] = e.w[i]
    out.w_jerk[k] = e.w_jerk[i]
    out.k2[k] = e.k2[i]
    out.k3[k] = e.k3[i]
    out.at[k] = e.at[i]
    out.jt[k] = e.jt[i]


#: what ``knot_probes`` reads besides the table and the estimate's inputs: the factors
#: of ``reach_envelope``, the knot spacing's time (s) and geometric constant, the least
#: spacing at either end (mm), the probe rounds and the points 2^-k of motion from the
#: path's ends (``optimal.profile.FeedProfileBuilder._knot_blocks``)
KnotInputs = namedtuple("KnotInputs", "acc_factor jerk_f2 knot_time knot_geo hmin0 hmin1 rounds geo")


@njit(cache=True, nogil=True)
def _enveloped_spacing(inp, kin, probe, ep, ahead, ea, carry_x, carry_w):
    """The reach envelope w (K,) at the probes (its estimates ``ep``; ``ahead``/``ea``:
    the points after them it looks at) and the knot spacing h (K,) wanted there."""
    K = probe.shape[0]
    N = K + ahead.shape[0]
    x = np.empty(N)
    w = np.empty(N)
    at = np.empty(N)
    jt = np.empty(N)
    x[:K] = probe
    x[K:] = ahead
    w[:K] = ep.w
    w[K:] = ea.w
    at[:K] = ep.at
    at[K:] = ea.at
    jt[:K] = ep.jt
    jt[K:] = ea.jt
    env = np.empty(N)
    reach_envelope(x, w, at, jt, kin.acc_factor, kin.jerk_f2, carry_x, carry_w, env)
    we = env[:K].copy()
    h = np.empty(K)
    half = 0.5 * inp.L
    for k in range(K):
        k2 = _nan_max(ep.k2[k], 1e-300)
        k3 = _nan_max(ep.k3[k], 1e-300)
        geo = _nan_min(kin.knot_geo / k2, kin.knot_geo / np.sqrt(k3))
        v = np.sqrt(_nan_max(we[k], 0.0))
        hmin = kin.hmin0 if probe[k] < half else kin.hmin1
        h[k] = _nan_max(_nan_min(kin.knot_time * v, geo), hmin)
    return we, h


@njit(cache=True, nogil=True)
def knot_probes(S, C, inp, kin, p0, p1, p2, carry_x, carry_w, known_x, known_e):
    """One block of the knot placement: table pieces p0..p1 probed (their ends and
    midpoints, nine even points, the points ``kin.geo`` from either end), the probes
    refined until no gap exceeds a quarter of the spacing wanted at its ends (at most
    ``kin.rounds`` rounds), under the reach envelope of the estimate that also looks at
    pieces p1..p2 and starts from (carry_x, carry_w). ``known_e`` are the estimates at
    ``known_x``, points among this block's first probes (the last block's look-ahead).
    Returns the probes x (K,), their enveloped speed² w (K,) and knot spacing h (K,), mm,
    and the look-ahead's points and estimates. The arithmetic is numpy's of
    ``optimal.profile``'s placement before it was compiled, bit for bit."""
    L = inp.L
    a = S[p0]
    b = S[p1]
    geo = kin.geo
    buf = np.empty(2 * (p1 - p0) + 10 + 2 * geo.shape[0])
    c = 0
    for i in range(p0, p1 + 1):
        buf[c] = S[i]
        c += 1
    for i in range(p0, p1):
        buf[c] = 0.5 * (S[i] + S[i + 1])
        c += 1
    step = (b - a) / 8.0  # np.linspace(a, b, 9)
    for i in range(8):
        buf[c] = float(i) * step + a
        c += 1
    buf[c] = b
    c += 1
    for i in range(geo.shape[0]):
        if geo[i] > a and geo[i] < b:
            buf[c] = geo[i]
            c += 1
    for i in range(geo.shape[0]):
        e = L - geo[i]
        if e > a and e < b:
            buf[c] = e
            c += 1
    probe = np.unique(buf[:c])
    # the next block's table points: the envelope looks that far ahead (slow points just
    # after this block lower the estimate before them)
    na = p2 - p1
    ahead = np.empty(2 * na)
    for i in range(na):
        ahead[i] = S[p1 + 1 + i]
        ahead[na + i] = 0.5 * (S[p1 + i] + S[p1 + 1 + i])
    ahead = np.sort(ahead)
    ea = estimates_of(S, C, ahead, inp)
    ep = _estimates_kept(S, C, probe, inp, known_x, known_e)
    w, h = _enveloped_spacing(inp, kin, probe, ep, ahead, ea, carry_x, carry_w)
    for _ in range(kin.rounds):
        K = probe.shape[0]
        need = np.empty(K - 1, dtype=np.int64)
        extra = 0
        for i in range(K - 1):
            gap = probe[i + 1] - probe[i]
            need[i] = np.int64(np.ceil(gap / (0.25 * _nan_min(h[i], h[i + 1]))))
            if need[i] > 1:
                extra += need[i] - 1
        if extra == 0:
            return probe, w, h, ahead, ea
        # need[i] - 1 points evenly inside each such gap
        grown = np.empty(K + extra)
        grown[:K] = probe
        c = K
        for i in range(K - 1):
            if need[i] > 1:
                gap = probe[i + 1] - probe[i]
                for k in range(1, need[i]):
                    grown[c] = probe[i] + gap * float(k) / float(need[i])
                    c += 1
        old, e_old = probe, ep
        probe = np.unique(grown)
        ep = _estimates_kept(S, C, probe, inp, old, e_old)
        w, h = _enveloped_spacing(inp, kin, probe, ep, ahead, ea, carry_x, carry_w)
    return probe, w, h, ahead, ea


@njit(cache=True, nogil=True)
def feasible_hat(p, dp, ddp, q1, q2, q3, lim, target, floor, bound, bisections, out):
    """``optimal.profile.FeedProfileBuilder._feasible_hat`` at K points: the previous window's
    solution p and its first two derivatives (K,), the joint derivatives q1..q3 (K, n)
    there, the ``AxisLimits`` lim (jerk limits as the LP uses them), the wanted
    linearisation points ``target`` (K,), the least one ``floor``, the jerk rows' share
    ``bound`` p must keep and the bisection steps; the points into ``out`` (K,).

    Per point: e = max over the moving axes of |E_i| / (3/2 J_i), E = q_sss p + 3/2 q_ss p'
    + 1/2 q_s p''; the target where e √t + p / (3 t) <= bound, else the end towards it of
    the interval around p where that holds (bisection in √ŵ), else p (at least ``floor``).
    The float operations of the numpy version it replaced, in its order."""
    moving = lim.moving
    jmax = lim.jmax
    n = q1.shape[1]
    for k in range(p.shape[0]):
        pk = p[k]
        if pk < 0.0:
            pk = 0.0
        e = 0.0
        for i in range(n):
            if not moving[i]:
                continue
            E = (q3[k, i] * pk + 1.5 * q2[k, i] * dp[k]) + 0.5 * q1[k, i] * ddp[k]
            v = abs(E) / (1.5 * jmax[i])
            e = _nan_max(e, v)
        t = target[k]
        if not t >= floor:
            t = floor if t == t else t
        p_hat = _nan_max(pk, floor)
        if e * np.sqrt(t) + pk / (3.0 * t) <= bound:
            out[k] = t
            continue
        out[k] = p_hat
        if p_hat == t or not e * np.sqrt(p_hat) + pk / (3.0 * p_hat) <= bound:
            continue
        ok_u = np.sqrt(p_hat)
        bad_u = np.sqrt(t)
        for _ in range(bisections):
            u = 0.5 * (ok_u + bad_u)
            if e * u + pk / (3.0 * u * u) <= bound:
                ok_u = u
            else:
                bad_u = u
        out[k] = ok_u * ok_u


@njit(cache=True, nogil=True)
def knot_breaks(probe, h, cum0, L):
    """The breakpoints of a block of the knot placement: where the integral of 1 / h
    (the knot spacing wanted at the probes (K,), by the trapezoid rule) crosses an
    integer, counted on from ``cum0`` (the integral before the block), strictly inside
    (0, L). Returns (breakpoints, the integral at the block's end)."""
    K = probe.shape[0]
    cum = np.empty(K)
    cum[0] = cum0
    acc = 0.0
    for k in range(1, K):
        acc += (0.5 * (1.0 / h[k] + 1.0 / h[k - 1])) * (probe[k] - probe[k - 1])
        cum[k] = cum0 + acc
    lo = np.floor(cum0) + 1.0
    hi = np.floor(cum[K - 1]) + 1.0
    marks = np.arange(lo, hi) if hi > lo else np.empty(0)
    x = np.interp(marks, cum, probe)
    out = np.empty(x.shape[0])
    j = 0
    for v in x:
        if 0.0 < v < L:
            out[j] = v
            j += 1
    return out[:j], cum[K - 1]


@njit(cache=True, nogil=True, inline="always")
def _fixed_row(first, coef, b, r, free, fixed_vals, out, j):
    """Row r of (first, coef, b) into row j of ``out`` with the fixed variables' terms on
    the right-hand side; True when a free variable is left in it."""
    f = first[r]
    acc = 0.0
    for k in range(4):
        acc += coef[r, k] * fixed_vals[f + k]
    out.b[j] = b[r] - acc
    out.first[j] = f
    nz = False
    for k in range(4):
        v = coef[r, k]
        if not free[f + k]:
            v = 0.0
        elif v != 0.0:
            nz = True
        out.coef[j, k] = v
    return nz


@njit(cache=True, nogil=True)
def lp_gather(rows, count, more, free, fixed_vals, out):
    """The LP's rows into ``out`` (``Rows``): the first ``count`` of ``rows``, then every
    row of ``more``, with the fixed variables' terms moved to the right-hand side
    (b -= Σ coef x_fixed, their coefficients zero, ``fixed_vals`` (n,) zero where free)
    and the rows left without a free variable dropped. Returns how many were kept."""
    j = 0
    for r in range(count):
        if _fixed_row(rows.first, rows.coef, rows.b, r, free, fixed_vals, out, j):
            j += 1
    for r in range(more.first.shape[0]):
        if _fixed_row(more.first, more.coef, more.b, r, free, fixed_vals, out, j):
            j += 1
    return j


@njit(cache=True, nogil=True)
def lp_objective(first, B, scale, weights, free, c):
    """The window LP's objective c (nc,) in the scaled variables: the time
    Σ_k weight_k w_k, the weights (K,) the trapezoid cells times ŵ^-3/2 (the linearisation
    point) at the collocation points (``first`` (K,), basis B (K, 3, 4)), negated (the LP
    minimises), zero on the fixed variables and scaled to max |c| = 1."""
    nc = c.shape[0]
    for j in range(nc):
        c[j] = 0.0
    for k in range(first.shape[0]):
        wt = weights[k]
        f = first[k]
        for j in range(4):
            c[f + j] += -((wt * B[k, 0, j]) * scale[f + j])
    big = 0.0
    for j in range(nc):
        if not free[j]:
            c[j] = 0.0
        big = _nan_max(big, abs(c[j]))
    if not big >= 1e-300:
        big = big if big != big else 1e-300
    for j in range(nc):
        c[j] /= big


@njit(cache=True, nogil=True)
def lp_profile_time(first, B, xv, scale, free, cfix, x, w_floor, coef, w_hat):
    """From an LP's solution ``xv`` (nc,, scaled): its coefficients into ``coef`` (nc,,
    ``cfix`` where fixed), w at the collocation points x (K,) floored at ``w_floor``
    into ``w_hat`` (the next linearisation point), and the traversal time of x by the
    trapezoid rule in 1/√w. Returns (every xv finite, time s)."""
    finite = True
    for j in range(coef.shape[0]):
        v = xv[j]
        if not np.isfinite(v):
            finite = False
        coef[j] = v * scale[j] if free[j] else cfix[j]
    T = 0.0
    v_prev = 0.0
    for k in range(first.shape[0]):
        f = first[k]
        w = (B[k, 0, 0] * coef[f] + B[k, 0, 2] * coef[f + 2]) + (B[k, 0, 1] * coef[f + 1] + B[k, 0, 3] * coef[f + 3])
        w = _nan_max(w, 0.0)
        v = np.sqrt(w)
        if k > 0:
            T += 2.0 * (x[k] - x[k - 1]) / _nan_max(v + v_prev, 1e-300)
        v_prev = v
        w_hat[k] = _nan_max(w, w_floor)
    return finite, T


@njit(cache=True, nogil=True)
def lp_take(rows, sel, count, out):
    """Copy the ``count`` rows r of ``rows`` with ``sel[r]`` into ``out`` (``Rows``), in order."""
    j = 0
    for r in range(sel.shape[0]):
        if sel[r]:
            out.first[j] = rows.first[r]
            for k in range(4):
                out.coef[j, k] = rows.coef[r, k]
            out.b[j] = rows.b[r]
            j += 1
            if j == count:
                break


@njit(cache=True, nogil=True)
def lp_screen(rows, x, screen, active, first_pass):
    """Row screening at x: the first pass (``first_pass``) marks ``active`` the rows whose
    slack b - a·x is at most 1 - ``screen`` of max(|b|, 1) (1e-12 above counts); later
    passes add the rows left out that x violates (beyond 1e-9 relative), and with them
    every row within that slack. Returns (violated rows left out, active rows)."""
    b = rows.b
    m = b.shape[0]
    val = np.empty(m)
    _ax(rows.first, rows.coef, x, val)
    viol = 0
    for r in range(m):
        if first_pass:
            active[r] = b[r] - val[r] <= (1.0 - screen) * max(abs(b[r]), 1.0) + 1e-12
        elif not active[r] and val[r] > b[r] + 1e-9 * max(abs(b[r]), 1.0):
            viol += 1
            active[r] = True
    if not first_pass and viol > 0:
        for r in range(m):
            if b[r] - val[r] <= (1.0 - screen) * max(abs(b[r]), 1.0):
                active[r] = True
    count = 0
    for r in range(m):
        if active[r]:
            count += 1
    return viol, count


@njit(cache=True, nogil=True, inline="always")
def _basis_dot(B, k, d, coef, f):
    """The d-th derivative of the spline at point k of ``cubic_basis``'s (B, first = f)."""
    return B[k, d, 0] * coef[f] + B[k, d, 1] * coef[f + 1] + B[k, d, 2] * coef[f + 2] + B[k, d, 3] * coef[f + 3]


@njit(cache=True, nogil=True)
def _w_at(knots, coef, x, first, B, w):
    """w of the cubic B-spline (knots, coef) at sorted x into ``w`` (``first``, ``B``:
    scratch of x's size)."""
    cubic_basis(knots, coef.shape[0], x, first, B)
    for k in range(x.shape[0]):
        w[k] = _basis_dot(B, k, 0, coef, first[k])


@njit(cache=True, nogil=True)
def time_nodes(knots, coef, x, gx, gw, min_dip, dt, w, w1):
    """The time law at sorted nodes x (K,) of the cubic B-spline w(s) = ṡ² (knots, coef):
    w (clipped at 0) and w' at the nodes into ``w``, ``w1`` (K,), and each node
    interval's time ∫ ds/√w into ``dt`` (K-1,) by Gauss–Legendre (points ``gx``,
    weights ``gw`` on [-1, 1]); an interval with w = 0 at an end is integrated in u with
    s = a + u² (rest at a) or s = b - u² (rest at b). Each interval's numbers depend only
    on its own two nodes. Returns False when w dips between two nodes below ``min_dip``
    of the smaller node value (the profile nearly stops there)."""
    K = x.shape[0]
    G = gx.shape[0]
    first = np.empty(K, dtype=np.int64)
    B = np.empty((K, 3, 4))
    cubic_basis(knots, coef.shape[0], x, first, B)
    for k in range(K):
        w[k] = max(_basis_dot(B, k, 0, coef, first[k]), 0.0)
        w1[k] = _basis_dot(B, k, 1, coef, first[k])
    # every interval's Gauss points at once (sorted: the points of one interval lie
    # strictly inside it)
    n = (K - 1) * G
    pts = np.empty(n)
    for i in range(K - 1):
        h = 0.5 * (x[i + 1] - x[i])
        m = 0.5 * (x[i + 1] + x[i])
        for g in range(G):
            pts[i * G + g] = m + h * gx[g]
    fp = np.empty(n, dtype=np.int64)
    Bp = np.empty((n, 3, 4))
    wp = np.empty(n)
    _w_at(knots, coef, pts, fp, Bp, wp)
    uu = np.empty(G)
    ss = np.empty(G)
    fr = np.empty(G, dtype=np.int64)
    Br = np.empty((G, 3, 4))
    wr = np.empty(G)
    for i in range(K - 1):
        h = 0.5 * (x[i + 1] - x[i])
        if w[i] > 0.0 and w[i + 1] > 0.0:
            lo = min(w[i], w[i + 1])
            acc = 0.0
            for g in range(G):
                wg = wp[i * G + g]
                if wg <= min_dip * lo:
                    return False
                acc += max(wg, 1e-300) ** -0.5 * gw[g]
            dt[i] = h * acc
            continue
        # rest at an end: s = a + u² or b - u², u in [0, √(b - a)]
        ub = np.sqrt(x[i + 1] - x[i])
        at_start = not w[i] > 0.0
        for g in range(G):
            uu[g] = 0.5 * ub * (gx[g] + 1.0)
        for g in range(G):  # sorted in s
            j = g if at_start else G - 1 - g
            ss[g] = x[i] + uu[j] * uu[j] if at_start else x[i + 1] - uu[j] * uu[j]
        _w_at(knots, coef, ss, fr, Br, wr)
        acc = 0.0
        for g in range(G):
            j = g if at_start else G - 1 - g
            acc += 2.0 * uu[g] / np.sqrt(max(wr[j], 1e-300)) * gw[g]
        dt[i] = 0.5 * ub * acc
    return True


@njit(cache=True, nogil=True)
def route_batch(paths, lim, table):
    """The route test of ``optimal.route._route`` on many paths whose joints are the
    program axes, in one call (a CAM program of short moves between stops has 1e5 paths,
    and a joint table plus the test cost more per path in Python than in here).

    Path i of ``paths`` (``RoutePaths``) is ``coef[seg_off[i]:seg_off[i+1]]`` with its
    ``breaks``/``s_breaks`` (n_seg+1 each, concatenated), ``weights[i]``, ``lengths[i]`` and
    per-segment ``feed`` (mm/s, capped as ``route._RouteInputs.FV``); ``lim`` a
    ``RouteLimits``; ``table`` = (tol, max_depth, max_piece, glx, glw,
    max_tries) of ``JointTable``. Returns (route (P,) int: 0 VPOp, 1 the profile, -1 no
    table (the path is left to its own planning, which raises the error), static_s (P,)
    s, share (P,)), the same numbers as ``_RouteInputs`` and ``_measured_route``."""
    tol, max_depth, max_piece, glx, glw, max_tries = table
    coef, breaks, s_breaks, weights, lengths, feed, seg_off = paths
    vmax, amax, jmax = lim.vmax, lim.amax, lim.jmax
    P = lengths.shape[0]
    route = np.full(P, -1, dtype=np.int64)
    static_s = np.zeros(P)
    share = np.zeros(P)
    for i in range(P):
        a = seg_off[i]
        b = seg_off[i + 1]
        # breaks and s_breaks carry n_seg + 1 entries per path: path i starts at a + i
        br = breaks[a + i : b + i + 1]
        sb = s_breaks[a + i : b + i + 1]
        status, u, S, C, max_err, qend = build_identity(
            coef[a:b], br, sb, weights[i], lengths[i], tol, max_depth, max_piece, glx, glw, max_tries
        )
        if status != OK:
            continue
        L = lengths[i]
        fv = feed[a:b]
        travel = 0.0
        for k in range(vmax.shape[0]):
            travel = max(travel, abs(qend[k] - C[0, 0, k]) / vmax[k])
        rough = travel + L / fv.min() + lim.ramp_s
        if rough < lim.tiny_s:
            route[i] = 0
            continue
        fb = sb.copy()
        fb[-1] = L
        sh, ts = route_measures(S, C, fb, fv, vmax, amax, jmax, lim.speed_share)
        static_s[i] = ts
        share[i] = sh
        route[i] = 2  # decided by the caller's thresholds on share and duration
    return route, static_s, share

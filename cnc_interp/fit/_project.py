"""Numba kernels: distance from points in path order to a piecewise quintic (marching projection).

Every distance returned is that of an actual point of the piecewise quintic (one
evaluated during the search), so a search that misses the true foot point can only
OVER-estimate the distance: the result is conservative.

Search in three tiers (``march_distances``):

1. marching: the points and the pieces are both in path order, so the foot point of
   point i+1 lies just after that of point i. Keep the current piece and local
   parameter, Newton on the squared distance from there (warm start), and slide to
   the next (previous) piece while the minimum sits on the piece's end (start).
2. a point farther than ``local_frac`` x its tolerance: every piece within
   ``window_u`` (path parameter) of the marched foot point, and its neighbours, whose
   bounding box (the Bernstein control polygon's, which contains the piece) could
   hold a closer point, searched from ``n_coarse`` + 1 samples and a safeguarded
   Newton.
3. a point still beyond its tolerance: the same within ``far_window_u``, so a point
   is only reported out of tolerance when no piece near its place along the path
   came within it. (The windows keep the search on the same pass: another turn of a
   helix or a contour's overlap lies at the same place but elsewhere along the path,
   and must not stand in for the pass being measured.)

After tiers 2/3 the march continues from the best foot point they found.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._quintic import quintic_d012

_END_REL = 1e-9  # a foot point this close (relative) to a piece's end lies on its end
_SAFE_ITERS = 60  # safeguarded Newton: enough bisections to reach rounding


@njit(cache=True)
def _eval_r2(coef, k, t, p):
    """Squared distance from p (d,) to piece k at local parameter t."""
    d = p.shape[0]
    r2 = 0.0
    for a in range(d):
        v = coef[k, 5, a]
        for j in range(4, -1, -1):
            v = v * t + coef[k, j, a]
        r = v - p[a]
        r2 += r * r
    return r2


@njit(cache=True)
def _slope(coef, k, t, p):
    """(q_k(t) - p) . q_k'(t): half the t-derivative of the squared distance."""
    d = p.shape[0]
    g = 0.0
    for a in range(d):
        v0 = coef[k, 5, a]
        v1 = 5.0 * coef[k, 5, a]
        for j in range(4, -1, -1):
            v0 = v0 * t + coef[k, j, a]
            if j >= 1:
                v1 = v1 * t + j * coef[k, j, a]
        g += (v0 - p[a]) * v1
    return g


@njit(cache=True)
def _newton(coef, k, hk, p, t, iters, best_r2, best_t):
    """Newton on |q_k(t) - p|^2 from t, clamped to [0, hk]; returns the best
    (r2, t) over the evaluated points and the incoming (best_r2, best_t)."""
    d = p.shape[0]
    for it in range(iters + 1):
        g = 0.0
        hh = 0.0
        r2 = 0.0
        q1sq = 0.0
        for a in range(d):
            v0, v1, v2 = quintic_d012(coef, k, a, t)
            r = v0 - p[a]
            r2 += r * r
            g += r * v1
            q1sq += v1 * v1
            hh += v1 * v1 + r * v2
        if r2 < best_r2:
            best_r2 = r2
            best_t = t
        if it == iters:
            break
        if hh <= 0.0:
            hh = q1sq + 1e-300
        t_new = t - g / hh
        if t_new < 0.0:
            t_new = 0.0
        elif t_new > hk:
            t_new = hk
        if abs(t_new - t) <= 1e-13 * hk:
            break
        t = t_new
    return best_r2, best_t


@njit(cache=True)
def _piece_min(coef, k, hk, p, n_coarse, iters):
    """Least squared distance (r2, t) from p to piece k: the best of n_coarse + 1
    samples, then a safeguarded Newton (rtsafe: Newton inside the bracket of the
    samples around it where the slope changes sign, bisection when a step leaves it)."""
    best_r2 = np.inf
    j = 0
    for i in range(n_coarse + 1):
        r2 = _eval_r2(coef, k, hk * i / n_coarse, p)
        if r2 < best_r2:
            best_r2 = r2
            j = i
    best_t = hk * j / n_coarse
    a = hk * max(j - 1, 0) / n_coarse
    b = hk * min(j + 1, n_coarse) / n_coarse
    ga = _slope(coef, k, a, p)
    gb = _slope(coef, k, b, p)
    if not (ga < 0.0 < gb):
        # no sign change around the best sample: it is (next to) an end minimum
        return _newton(coef, k, hk, p, best_t, iters, best_r2, best_t)
    d = p.shape[0]
    t = best_t
    if t <= a or t >= b:
        t = 0.5 * (a + b)
    for it in range(_SAFE_ITERS):
        g = 0.0
        hh = 0.0
        r2 = 0.0
        for c in range(d):
            v0, v1, v2 = quintic_d012(coef, k, c, t)
            r = v0 - p[c]
            r2 += r * r
            g += r * v1
            hh += v1 * v1 + r * v2
        if r2 < best_r2:
            best_r2 = r2
            best_t = t
        if g < 0.0:
            a = t
        elif g > 0.0:
            b = t
        else:
            break
        t_new = t - g / hh if hh > 0.0 else a - 1.0
        if not (a < t_new < b):
            t_new = 0.5 * (a + b)
        if abs(t_new - t) <= 1e-13 * hk or b - a <= 1e-13 * hk:
            break
        t = t_new
    return best_r2, best_t


@njit(cache=True)
def piece_boxes(coef, h):
    """Axis-aligned boxes (S, d) lo, hi holding each piece: the convex hull of its
    Bernstein control points (power coefficients a_i on [0, h]: c_i = a_i h^i,
    b_j = sum_{i<=j} C(j, i) / C(5, i) c_i)."""
    S = coef.shape[0]
    d = coef.shape[2]
    lo = np.empty((S, d))
    hi = np.empty((S, d))
    binom5 = np.array([1.0, 5.0, 10.0, 10.0, 5.0, 1.0])
    c = np.empty(6)
    for k in range(S):
        for a in range(d):
            hp = 1.0
            for i in range(6):
                c[i] = coef[k, i, a] * hp / binom5[i]
                hp *= h[k]
            mn = np.inf
            mx = -np.inf
            for j in range(6):
                # b_j = sum_i C(j, i) c_i (c_i already divided by C(5, i))
                b = 0.0
                cji = 1.0
                for i in range(j + 1):
                    b += cji * c[i]
                    cji = cji * (j - i) / (i + 1)
                mn = min(mn, b)
                mx = max(mx, b)
            # a little slack: rounding of the conversion must not prune the true piece
            pad = 1e-12 * (abs(mn) + abs(mx)) + 1e-300
            lo[k, a] = mn - pad
            hi[k, a] = mx + pad
    return lo, hi


@njit(cache=True)
def _box_r2(lo, hi, k, p):
    r2 = 0.0
    for a in range(p.shape[0]):
        if p[a] < lo[k, a]:
            e = lo[k, a] - p[a]
            r2 += e * e
        elif p[a] > hi[k, a]:
            e = p[a] - hi[k, a]
            r2 += e * e
    return r2


@njit(cache=True)
def march_distances(coef, h, pts, tol, local_frac, window_u, far_window_u, n_coarse, iters):
    """Distances (K,) from points pts (K, d), in path order, to the piecewise quintic
    coef (S, 6, d) with local parameters t in [0, h_k]; tol (K,) the points'
    tolerances, window_u / far_window_u the reach (path parameter units, each side
    of the marched foot point) of tiers 2 and 3 of the module docstring (inf: all
    pieces). Conservative: each distance is that of a point of the path."""
    return march_feet(coef, h, pts, tol, local_frac, window_u, far_window_u, n_coarse, iters)[0]


@njit(cache=True)
def march_feet(coef, h, pts, tol, local_frac, window_u, far_window_u, n_coarse, iters):
    """``march_distances`` with the foot points: (distance (K,), piece (K,), local t (K,))."""
    K = pts.shape[0]
    S = coef.shape[0]
    out = np.empty(K)
    foot_k = np.zeros(K, dtype=np.int64)
    foot_t = np.zeros(K)
    if K == 0 or S == 0:
        out[:] = np.inf
        return out, foot_k, foot_t
    # the pieces' boxes only serve tiers 2 and 3: made when a point first needs them
    lo = np.empty((0, 0))
    hi = np.empty((0, 0))
    u0 = np.empty(S + 1)  # piece starts along the path parameter
    u0[0] = 0.0
    for kk in range(S):
        u0[kk + 1] = u0[kk] + h[kk]
    k = 0
    t = 0.0
    r2, t = _piece_min(coef, np.int64(0), h[0], pts[0], n_coarse, iters)
    # the foot point's last advance on its piece: the next one starts that much further
    # (the samples are about evenly spaced), so Newton starts close to it
    advance = 0.0
    for i in range(K):
        p = pts[i]
        k_last = k
        t_last = t
        if i > 0:
            t0 = min(max(t + advance, 0.0), h[k])
            r2, t = _newton(coef, k, h[k], p, t0, iters, np.inf, t0)
        # slide forward while the minimum sits on the piece's end, or the distance still
        # falls there (Newton may stop short of the end in a strongly curved piece)
        moved = False
        while k + 1 < S and (t >= h[k] * (1.0 - _END_REL) or _slope(coef, k, h[k], p) < 0.0):
            r2n, tn = _piece_min(coef, k + 1, h[k + 1], p, n_coarse, iters)
            if r2n <= r2:
                k += 1
                r2 = r2n
                t = tn
                moved = True
            else:
                break
        if not moved:
            while k > 0 and (t <= h[k] * _END_REL or _slope(coef, k, np.float64(0.0), p) > 0.0):
                r2n, tn = _piece_min(coef, k - 1, h[k - 1], p, n_coarse, iters)
                if r2n < r2:
                    k -= 1
                    r2 = r2n
                    t = tn
                else:
                    break
        best = r2
        lim = local_frac * tol[i]
        if best > lim * lim:
            # tiers 2 and 3: the pieces near the marched foot point along the path (not
            # another pass over the same place: a helix's next turn, a contour's overlap)
            if lo.shape[0] == 0:
                lo, hi = piece_boxes(coef, h)
            u_foot = u0[k] + t
            k_best = k
            t_best = t
            for tier in range(2):
                if tier == 1 and not best > tol[i] * tol[i]:
                    break
                w = window_u if tier == 0 else far_window_u
                ka = k
                while ka > 0 and u0[ka] > u_foot - w:
                    ka -= 1
                kb = k
                while kb < S - 1 and u0[kb + 1] < u_foot + w:
                    kb += 1
                ka = max(min(ka, k - 1), 0)
                kb = min(max(kb, k + 1), S - 1)
                for kk in range(ka, kb + 1):
                    if _box_r2(lo, hi, kk, p) >= best:
                        continue
                    r2n, tn = _piece_min(coef, kk, h[kk], p, n_coarse, iters)
                    if r2n < best:
                        best = r2n
                        k_best = kk
                        t_best = tn
            # a march that had lost its way resumes from the foot point found
            k = k_best
            t = t_best
        out[i] = math.sqrt(best)
        foot_k[i] = k
        foot_t[i] = t
        advance = t - t_last if k == k_last else 0.0
    return out, foot_k, foot_t


@njit(cache=True)
def line_samples(nodes, tol_mm, in_curve, spacing, min_samples, max_samples):
    """Samples of the programmed moves (the chords of ``nodes`` (n, d) not flagged
    ``in_curve`` (n-1,)), in path order: each move at clip(ceil(length / spacing),
    min_samples, max_samples) + 1 equally spaced points, its start left out when it is
    the previous move's end. Returns points (K, d), the tolerance of each point's
    move (tol_mm (n,) holds that of the move ending at each node) and its sort key
    j + f / 2 (move j, fraction f) for merging with curve samples."""
    n = nodes.shape[0]
    d = nodes.shape[1]
    cnt = np.zeros(max(n - 1, 0), dtype=np.int64)
    total = 0
    for j in range(n - 1):
        if in_curve[j]:
            continue
        ln = 0.0
        for a in range(d):
            e = nodes[j + 1, a] - nodes[j, a]
            ln += e * e
        x = math.sqrt(ln) / spacing  # clipped as a float: no integer overflow
        if x >= max_samples:
            cnt[j] = max_samples
        else:
            cnt[j] = max(int(math.ceil(x)), min_samples)
        c = cnt[j]
        total += c + 1
    pts = np.empty((total, d))
    tol = np.empty(total)
    key = np.empty(total)
    m = 0
    for j in range(n - 1):
        if in_curve[j]:
            continue
        c = cnt[j]
        i_start = 1 if (j > 0 and not in_curve[j - 1]) else 0
        for i in range(i_start, c + 1):
            f = i / c
            for a in range(d):
                pts[m, a] = nodes[j, a] + (nodes[j + 1, a] - nodes[j, a]) * f
            tol[m] = tol_mm[j + 1]
            key[m] = j + 0.5 * f
            m += 1
    return pts[:m], tol[:m], key[:m]


@njit(cache=True)
def median(x):
    """np.median of a 1-D array (without numpy's per-call overhead on small arrays)."""
    return np.median(x)

"""Numba kernels of the N-axis fitter: quintic B-spline least squares with knot insertion.

Everything here works on one section of nodes in a "scaled" space where the
Euclidean norm is the fitter's metric (rotary axes multiplied by tol_mm/tol_deg).
The spline is clamped, degree 5, so it is C4 in the parameter at simple knots.
"""

from __future__ import annotations

import numpy as np
from numba import njit

K = 5  # degree


@njit(cache=True)
def find_span(t, m, x):
    """Index i with t[i] <= x < t[i+1], K <= i <= m-1 (m = number of coefficients)."""
    if x >= t[m]:
        return m - 1
    if x <= t[K]:
        return K
    lo, hi = K, m
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if t[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True)
def basis(t, i, x, p, out, left, right):
    """The p+1 non-zero B-spline basis values of degree p at x in span i (NURBS book A2.2).

    ``left``/``right`` are work arrays of length >= p+1.
    """
    out[0] = 1.0
    for j in range(1, p + 1):
        left[j] = x - t[i + 1 - j]
        right[j] = t[i + j] - x
        saved = 0.0
        for r in range(j):
            den = right[r + 1] + left[j - r]
            temp = out[r] / den if den != 0.0 else 0.0
            out[r] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        out[j] = saved


@njit(cache=True)
def end_coefs(t, m, c, y0, y1, d1s, d2s, d1e, d2e, start_mode, end_mode):
    """Fill the fixed coefficients from end positions and (optional) u-derivatives.

    mode 0: position only; 1: position, first and second derivative.
    """
    c[0, :] = y0
    c[m - 1, :] = y1
    if start_mode == 1:
        c[1, :] = c[0, :] + d1s * (t[6] - t[1]) / 5.0
        dp1 = d1s + d2s * (t[6] - t[2]) / 4.0
        c[2, :] = c[1, :] + dp1 * (t[7] - t[2]) / 5.0
    if end_mode == 1:
        b = t[m + K]
        c[m - 2, :] = c[m - 1, :] - d1e * (b - t[m - 1]) / 5.0
        dpm3 = d1e - d2e * (b - t[m - 1]) / 4.0
        c[m - 3, :] = c[m - 2, :] - dpm3 * (b - t[m - 2]) / 5.0


@njit(cache=True)
def solve_lsq(t, m, u, y, w, prior, fixed, c, lam, ridge):
    """Weighted LS for the free coefficients (``fixed[i]`` False), in place in ``c``.

    Minimises sum_j w_j^2 |q(u_j) - y_j|^2 + lam * sum_i |scaled DD3(c)_i|^2
    + ridge * sum_i |c_i - prior_i|^2 (the ridge keeps empty spans well posed).
    """
    n, d = y.shape
    idx = -np.ones(m, dtype=np.int64)
    nf = 0
    for i in range(m):
        if not fixed[i]:
            idx[i] = nf
            nf += 1
    if nf == 0:
        return
    ab = np.zeros((nf, 6))
    rhs = np.zeros((nf, d))
    nb = np.empty(6)
    wl = np.empty(6)
    wr = np.empty(6)
    tgt = np.empty(d)
    for j in range(n):
        sp = find_span(t, m, u[j])
        basis(t, sp, u[j], K, nb, wl, wr)
        ww = w[j] * w[j]
        # residual target after moving fixed coefficients to the right-hand side
        for a in range(d):
            tgt[a] = y[j, a]
        for r in range(6):
            ci = sp - K + r
            if fixed[ci]:
                for a in range(d):
                    tgt[a] -= nb[r] * c[ci, a]
        for r in range(6):
            ci = sp - K + r
            fi = idx[ci]
            if fi < 0:
                continue
            f = ww * nb[r]
            for a in range(d):
                rhs[fi, a] += f * tgt[a]
            for s_ in range(r, 6):
                fj = idx[sp - K + s_]
                if fj < 0:
                    continue
                if fj >= fi:
                    ab[fi, fj - fi] += f * nb[s_]
                else:
                    ab[fj, fi - fj] += f * nb[s_]
    # smoothing: third divided differences over the Greville abscissae, scaled by span^3
    g = np.empty(m)
    for i in range(m):
        acc = 0.0
        for r in range(1, K + 1):
            acc += t[i + r]
        g[i] = acc / K
    dd = np.empty(4)
    for i in range(m - 3):
        span = g[i + 3] - g[i]
        if span <= 0.0:
            continue
        for a in range(4):
            prod = 1.0
            for b in range(4):
                if b != a:
                    prod *= g[i + a] - g[i + b]
            dd[a] = span ** 3 / prod
        for a in range(d):
            tgt[a] = 0.0
        for a in range(4):
            if fixed[i + a]:
                for e in range(d):
                    tgt[e] -= dd[a] * c[i + a, e]
        for a in range(4):
            fa = idx[i + a]
            if fa < 0:
                continue
            for e in range(d):
                rhs[fa, e] += lam * dd[a] * tgt[e]
            for b in range(a, 4):
                fb = idx[i + b]
                if fb < 0:
                    continue
                ab[fa, fb - fa] += lam * dd[a] * dd[b]
    for i in range(m):
        fi = idx[i]
        if fi >= 0:
            ab[fi, 0] += ridge
            for a in range(d):
                rhs[fi, a] += ridge * prior[i, a]
    # banded Cholesky: ab[i, k] = U[i, i+k]
    for i in range(nf):
        s = ab[i, 0]
        for k in range(max(0, i - 5), i):
            s -= ab[k, i - k] ** 2
        if s <= 0.0:
            s = 1e-300
        ab[i, 0] = np.sqrt(s)
        for j in range(i + 1, min(i + 6, nf)):
            s = ab[i, j - i]
            for k in range(max(0, j - 5), i):
                s -= ab[k, i - k] * ab[k, j - k]
            ab[i, j - i] = s / ab[i, 0]
    # U^T z = rhs, then U x = z
    for a in range(d):
        for i in range(nf):
            s = rhs[i, a]
            for k in range(max(0, i - 5), i):
                s -= ab[k, i - k] * rhs[k, a]
            rhs[i, a] = s / ab[i, 0]
        for i in range(nf - 1, -1, -1):
            s = rhs[i, a]
            for k in range(i + 1, min(i + 6, nf)):
                s -= ab[i, k - i] * rhs[k, a]
            rhs[i, a] = s / ab[i, 0]
    for i in range(m):
        if idx[i] >= 0:
            c[i] = rhs[idx[i]]


@njit(cache=True)
def evaluate(t, m, c, x, val, der):
    """Positions val (K, d) and first derivatives der (K, d) at sorted-or-not points x."""
    d = c.shape[1]
    nb = np.empty(6)
    nd = np.empty(5)
    wl = np.empty(6)
    wr = np.empty(6)
    t1 = t[1:]
    for j in range(x.shape[0]):
        sp = find_span(t, m, x[j])
        basis(t, sp, x[j], K, nb, wl, wr)
        for a in range(d):
            acc = 0.0
            for r in range(6):
                acc += nb[r] * c[sp - K + r, a]
            val[j, a] = acc
        # derivative spline: degree 4 on t[1:], coefficient i' = 5 (c[i'+1]-c[i']) / (t[i'+6]-t[i'+1])
        basis(t1, sp - 1, x[j], K - 1, nd, wl, wr)
        for a in range(d):
            acc = 0.0
            for r in range(5):
                ci = sp - 1 - (K - 1) + r
                den = t[ci + 6] - t[ci + 1]
                if den > 0.0:
                    acc += nd[r] * K * (c[ci + 1, a] - c[ci, a]) / den
            der[j, a] = acc


@njit(cache=True)
def check(t, m, c, xc, ref, tol_lin, tol_rot, lin, metric, exp_speed, exp_lin_speed, min_ratio, bad_span,
          n_hard, hard_ratio):
    """Mark spans whose check points deviate or slow down too much.

    Returns (max linear error, max rotary error, hard failures, soft failures): any
    deviation beyond the tolerance (nodes: the first ``n_hard`` points, per axis kind;
    points on the programmed moves between them: Euclidean in the scaled metric) and a
    speed below ``hard_ratio`` of the expected one are hard; speeds between
    ``hard_ratio`` and ``min_ratio`` of the expected one are soft.

    xc (P,) check parameters, ref (P, d) reference positions, tol_lin (P,) allowed linear
    deviation, tol_rot scalar allowed rotary deviation (scaled units), exp_speed (P,) and
    exp_lin_speed (P,) the chord speeds expected there (all axes / the arc-length
    metric's axes ``metric``).
    """
    P = xc.shape[0]
    d = c.shape[1]
    val = np.empty((P, d))
    der = np.empty((P, d))
    evaluate(t, m, c, xc, val, der)
    worst_lin = 0.0
    worst_rot = 0.0
    hard = 0
    soft = 0
    for j in range(P):
        e_lin = 0.0
        e_rot = 0.0
        e_all = 0.0
        sp_all = 0.0
        sp_lin = 0.0
        for a in range(d):
            e = val[j, a] - ref[j, a]
            e_all += e * e
            sp_all += der[j, a] ** 2
            if metric[a]:
                sp_lin += der[j, a] ** 2
            if lin[a]:
                e_lin += e * e
            else:
                e_rot = max(e_rot, abs(e))
        e_all = np.sqrt(e_all)
        e_lin = np.sqrt(e_lin)
        if j < n_hard:
            dev_ok = e_lin <= tol_lin[j] and e_rot <= tol_rot
        else:
            # chord points: one Euclidean allowance in the scaled metric (it holds the sagitta)
            dev_ok = e_all <= tol_lin[j]
        speed_ok = np.sqrt(sp_all) >= min_ratio * exp_speed[j] and \
            np.sqrt(sp_lin) >= min_ratio * exp_lin_speed[j]
        # a near-stop is never accepted; a mere slow-down (a rounded corner) may remain
        stop = np.sqrt(sp_all) < hard_ratio * exp_speed[j] or \
            np.sqrt(sp_lin) < hard_ratio * exp_lin_speed[j]
        if not (dev_ok and speed_ok):
            bad_span[find_span(t, m, xc[j])] = True
            # every check point lies on the programmed path: a deviation is a failure
            if stop or not dev_ok:
                hard += 1
            else:
                soft += 1
        if j < n_hard:
            if e_lin > worst_lin:
                worst_lin = e_lin
            if e_rot > worst_rot:
                worst_rot = e_rot
    return worst_lin, worst_rot, hard, soft


@njit(cache=True)
def segment_sources_kernel(x, u, line, feed):
    """See ``nodes.segment_sources``: per segment [x_k, x_k+1], the line of the move
    containing its end and the least feed of the moves it overlaps (move j ends at node j)."""
    n = u.shape[0]
    n_seg = x.shape[0] - 1
    seg_line = np.empty(n_seg, dtype=np.int64)
    seg_feed = np.empty(n_seg)
    j = 1  # first move that may overlap the current segment
    for k in range(n_seg):
        a = x[k]
        b = x[k + 1]
        while j < n - 1 and u[j] <= a:
            j += 1
        f = np.inf
        jj = j
        while True:
            if feed[jj] < f:
                f = feed[jj]
            if jj >= n - 1 or u[jj] >= b:
                break
            jj += 1
        seg_line[k] = line[jj]
        seg_feed[k] = f
    return seg_line, seg_feed


@njit(cache=True)
def project_points(coef, h, pts, cand_seg, cand_t, iters):
    """Distance (K,) from points pts (K, d) to a piecewise quintic (coef (S, 6, d) in the
    local parameter t in [0, h_k]): Newton on the squared distance from every candidate
    (segment cand_seg[i, c], start t cand_t[i, c]) and in the two neighbouring segments
    (from their near ends); the least distance found (always that of a point of the path)."""
    K, d = pts.shape
    S = coef.shape[0]
    C = cand_seg.shape[1]
    out = np.empty(K)
    p0 = np.empty(d)
    p1 = np.empty(d)
    p2 = np.empty(d)
    for i in range(K):
        best = np.inf
        for c in range(C):
            for dk in range(-1, 2):
                k = cand_seg[i, c] + dk
                if k < 0 or k >= S:
                    continue
                hk = h[k]
                if dk == 0:
                    t = cand_t[i, c]
                elif dk < 0:
                    t = hk
                else:
                    t = 0.0
                for it in range(iters + 1):
                    g = 0.0
                    hh = 0.0
                    r2 = 0.0
                    q1sq = 0.0
                    for a in range(d):
                        v0 = coef[k, 5, a]
                        v1 = 5.0 * coef[k, 5, a]
                        v2 = 20.0 * coef[k, 5, a]
                        for j in range(4, -1, -1):
                            v0 = v0 * t + coef[k, j, a]
                            if j >= 1:
                                v1 = v1 * t + j * coef[k, j, a]
                            if j >= 2:
                                v2 = v2 * t + j * (j - 1) * coef[k, j, a]
                        r = v0 - pts[i, a]
                        r2 += r * r
                        g += r * v1
                        q1sq += v1 * v1
                        hh += v1 * v1 + r * v2
                    if r2 < best:
                        best = r2
                    if it == iters:
                        break
                    if hh <= 0.0:
                        hh = q1sq + 1e-300
                    t = t - g / hh
                    if t < 0.0:
                        t = 0.0
                    elif t > hk:
                        t = hk
        out[i] = np.sqrt(best)
    return out

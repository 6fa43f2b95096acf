"""Numba kernels of the N-axis fitter: quintic B-spline least squares with knot insertion.

Everything here works on one section of nodes in a "scaled" space where the
Euclidean norm is the fitter's metric (rotary axes multiplied by tol_mm/tol_deg).
The spline is clamped, degree 5, so it is C4 in the parameter at simple knots.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

K = 5  # degree


class FitNodes(NamedTuple):
    """One section's nodes in the scaled space (n nodes, d axes): parameters ``u`` (n,),
    positions ``y`` (n, d), tolerances ``tol`` (n,), ``chords`` (n-1, d) and their lengths
    ``clen`` (n-1,), ``lin_ratio`` (n-1,) the share of each chord on the metric's axes."""

    u: np.ndarray
    y: np.ndarray
    tol: np.ndarray
    chords: np.ndarray
    clen: np.ndarray
    lin_ratio: np.ndarray


class EndStates(NamedTuple):
    """Imposed first and second derivatives at the start and end (d,), each used when its
    mode is 1 (0: free)."""

    d1s: np.ndarray
    d2s: np.ndarray
    d1e: np.ndarray
    d2e: np.ndarray
    start_mode: int
    end_mode: int


class CheckPoints(NamedTuple):
    """Check points (P of them): parameters ``xc`` (P,), reference positions ``ref`` (P, d),
    allowed deviation ``tol`` (P,), expected chord speed of all axes ``exp_speed`` (P,)
    and of the metric's axes ``exp_lin_speed`` (P,)."""

    xc: np.ndarray
    ref: np.ndarray
    tol: np.ndarray
    exp_speed: np.ndarray
    exp_lin_speed: np.ndarray


class FitData(NamedTuple):
    """Round-invariant least-squares data and checks: the node and chord points, each
    both a check point and a data point — parameter ``xc``, position ``ref``, allowed
    deviation ``tol_c``, expected speed of the metric's axes ``exp_lin``, data weight
    ``w_data`` — and ``span_f``, the fractions of each knot span that get such points on
    the programmed moves."""

    xc: np.ndarray
    ref: np.ndarray
    tol_c: np.ndarray
    exp_lin: np.ndarray
    w_data: np.ndarray
    span_f: np.ndarray


class RefineParams(NamedTuple):
    """The fitter's settings for one section (see ``nodes.py``'s constants): the reference
    tolerance (mm) of the data weights, the rotary tolerance (scaled), the axis masks
    ``lin`` / ``metric`` (d,), safety on the tolerance between nodes, smoothing and ridge
    weights, soft and hard speed ratios, round limits, least knot span and most interior
    knots (-1: no limit)."""

    tol_ref: float
    tol_rot: float
    lin: np.ndarray
    metric: np.ndarray
    between_safety: float
    smoothing: float
    ridge: float
    min_ratio: float
    stop_ratio: float
    max_rounds: int
    stale_rounds: int
    min_span: float
    max_interior: int


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
def point_bases(t, m, x):
    """Span (P,), degree-5 basis (P, 6) and degree-4 basis (P, 5) of every point x (P,):
    ``basis`` (NURBS book A2.2) of degree 5, the degree-4 values being those its triangle
    passes through (``basis(t[1:], span - 1, x, 4)``: the first derivative's basis)."""
    P = x.shape[0]
    spans = np.empty(P, dtype=np.int64)
    n5 = np.empty((P, K + 1))
    n4 = np.empty((P, K))
    wl = np.empty(K + 1)
    wr = np.empty(K + 1)
    # the reciprocals of the knot differences of every span (a point's denominators
    # are its span's: one division per span and triangle entry, not per point)
    inv = np.empty((m, K + 1, K + 1))
    for i in range(K, m):
        for jj in range(1, K + 1):
            for r in range(jj):
                den = t[i + r + 1] - t[i + 1 - jj + r]
                inv[i, jj, r] = 1.0 / den if den != 0.0 else 0.0
    for j in range(P):
        sp = find_span(t, m, x[j])
        spans[j] = sp
        xj = x[j]
        out = n5[j]
        out[0] = 1.0
        for jj in range(1, K + 1):
            wl[jj] = xj - t[sp + 1 - jj]
            wr[jj] = t[sp + jj] - xj
            saved = 0.0
            for r in range(jj):
                temp = out[r] * inv[sp, jj, r]
                out[r] = saved + wr[r + 1] * temp
                saved = wl[jj - r] * temp
            out[jj] = saved
            if jj == K - 1:
                for r in range(K):
                    n4[j, r] = out[r]
    return spans, n5, n4


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
def solve_lsq(t, m, bases, y, w, prior, fixed, c, lam, ridge):
    """Weighted LS for the free coefficients (``fixed[i]`` False), in place in ``c``.

    Minimises sum_j w_j^2 |q(u_j) - y_j|^2 + lam * sum_i |scaled DD3(c)_i|^2
    + ridge * sum_i |c_i - prior_i|^2 (the ridge keeps empty spans well posed);
    ``bases`` = (spans, degree-5 basis, _) of the data points u (``point_bases``).
    """
    spans, n5, _ = bases
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
    tgt = np.empty(d)
    for j in range(n):
        sp = spans[j]
        nb = n5[j]
        ww = w[j] * w[j]
        f0 = idx[sp - K]
        if f0 >= 0 and idx[sp] == f0 + K:
            # the span's six coefficients all free (consecutive): the same sums, no lookups
            for r in range(6):
                f = ww * nb[r]
                for a in range(d):
                    rhs[f0 + r, a] += f * y[j, a]
                for s_ in range(r, 6):
                    ab[f0 + r, s_ - r] += f * nb[s_]
            continue
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
            dd[a] = span**3 / prod
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


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
def evaluate012(t, m, c, x, d0, d1, d2):
    """Values d0, first d1 and second derivatives d2 (K, d) of the quintic spline at x (K,)
    (each point in its span t[i] <= x < t[i+1], the last knot from the left): ``evaluate``,
    then the second-derivative spline of degree 3 on t[2:] (de Boor)."""
    evaluate(t, m, c, x, d0, d1)
    d = c.shape[1]
    nb = np.empty(6)
    wl = np.empty(6)
    wr = np.empty(6)
    t2 = t[2:]
    for j in range(x.shape[0]):
        sp = find_span(t, m, x[j])
        basis(t2, sp - 2, x[j], K - 2, nb, wl, wr)
        for a in range(d):
            acc = 0.0
            for r in range(4):
                i = sp - K + r
                den = t[i + 6] - t[i + 2]
                if den > 0.0:
                    acc += nb[r] * (K - 1) * (_d1_coef(t, c, i + 1, a) - _d1_coef(t, c, i, a)) / den
            d2[j, a] = acc


@njit(cache=True, inline="always")
def _d1_coef(t, c, i, a):
    """Coefficient i of the first-derivative spline (degree 4 on t[1:])."""
    den = t[i + 6] - t[i + 1]
    return K * (c[i + 1, a] - c[i, a]) / den if den > 0.0 else 0.0


@njit(cache=True, error_model="numpy")
def _evaluate_bases(t, c, bases, val, der):
    """``evaluate`` at the points of ``bases`` (``point_bases``): the same sums."""
    spans, n5, n4 = bases
    m, d = c.shape
    # the derivative spline's coefficients once (the same expression per point before)
    dc = np.empty((max(m - 1, 0), d))
    pos = np.empty(max(m - 1, 0), dtype=np.bool_)
    for ci in range(m - 1):
        den = t[ci + 6] - t[ci + 1]
        pos[ci] = den > 0.0
        for a in range(d):
            dc[ci, a] = K * (c[ci + 1, a] - c[ci, a]) / den if den > 0.0 else 0.0
    for j in range(spans.shape[0]):
        sp = spans[j]
        for a in range(d):
            acc = 0.0
            for r in range(6):
                acc += n5[j, r] * c[sp - K + r, a]
            val[j, a] = acc
        for a in range(d):
            acc = 0.0
            for r in range(5):
                ci = sp - 1 - (K - 1) + r
                if pos[ci]:
                    acc += n4[j, r] * dc[ci, a]
            der[j, a] = acc


@njit(cache=True, error_model="numpy")
def check(t, m, c, pts, bases, limits, bad_span, n_hard):
    """Mark spans whose check points deviate or slow down too much.

    Returns (max linear error, max rotary error, hard failures, soft failures): any
    deviation beyond the tolerance (nodes: the first ``n_hard`` points, per axis kind;
    points on the programmed moves between them: Euclidean in the scaled metric) and a
    speed below ``hard_ratio`` of the expected one are hard; speeds between
    ``hard_ratio`` and ``min_ratio`` of the expected one are soft.

    pts: the check points (``CheckPoints``) and ``bases`` their ``point_bases``;
    ``limits`` = (tol_rot: allowed rotary deviation (scaled units), lin and ``metric`` the
    linear and the arc-length metric's axes, min_ratio, hard_ratio).
    """
    xc, ref, tol_lin, exp_speed, exp_lin_speed = pts
    tol_rot, lin, metric, min_ratio, hard_ratio = limits
    spans = bases[0]
    P = xc.shape[0]
    d = c.shape[1]
    val = np.empty((P, d))
    der = np.empty((P, d))
    _evaluate_bases(t, c, bases, val, der)
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
        if j < n_hard:
            # nodes: Euclidean in the scaled metric too (linear and scaled rotary errors
            # each within the tolerance could sum to √2 of it), and each rotary axis
            dev_ok = e_all <= tol_lin[j] and e_rot <= tol_rot
        else:
            # chord points: one Euclidean allowance in the scaled metric (it holds the sagitta)
            dev_ok = e_all <= tol_lin[j]
        sp_all = np.sqrt(sp_all)
        sp_lin = np.sqrt(sp_lin)
        speed_ok = sp_all >= min_ratio * exp_speed[j] and sp_lin >= min_ratio * exp_lin_speed[j]
        # a near-stop is never accepted; a mere slow-down (a rounded corner) may remain
        stop = sp_all < hard_ratio * exp_speed[j] or sp_lin < hard_ratio * exp_lin_speed[j]
        if not (dev_ok and speed_ok):
            bad_span[spans[j]] = True
            # every check point lies on the programmed path: a deviation is a failure
            if stop or not dev_ok:
                hard += 1
            else:
                soft += 1
        if j < n_hard:
            e_lin = np.sqrt(e_lin)
            if e_lin > worst_lin:
                worst_lin = e_lin
            if e_rot > worst_rot:
                worst_rot = e_rot
    return worst_lin, worst_rot, hard, soft


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
def _interp_rows(x, xp, fp, out):
    """``out[:, a] = np.interp(x, xp, fp[:, a])`` for every column a, x and xp ascending:
    numpy's formula (slope from the two nodes around x, then slope * (x - xp[j]) + fp[j]),
    found by one walk along xp for all columns instead of a search per point and column."""
    n = xp.shape[0]
    d = fp.shape[1]
    j = 0
    for i in range(x.shape[0]):
        xv = x[i]
        while j + 1 < n and xp[j + 1] <= xv:
            j += 1
        for a in range(d):
            if xv < xp[0]:
                out[i, a] = fp[0, a]
            elif j == n - 1:  # at or beyond the last node
                out[i, a] = fp[n - 1, a]
            elif xp[j] == xv:
                out[i, a] = fp[j, a]
            else:
                slope = (fp[j + 1, a] - fp[j, a]) / (xp[j + 1] - xp[j])
                out[i, a] = slope * (xv - xp[j]) + fp[j, a]


@njit(cache=True, error_model="numpy")
def _merge_sorted(a, b):
    """``np.unique(np.concatenate((a, b)))`` of two sorted arrays, in one pass."""
    out = np.empty(a.shape[0] + b.shape[0])
    i = j = k = 0
    while i < a.shape[0] or j < b.shape[0]:
        if j >= b.shape[0] or (i < a.shape[0] and a[i] <= b[j]):
            v = a[i]
            i += 1
        else:
            v = b[j]
            j += 1
        if k == 0 or v != out[k - 1]:
            out[k] = v
            k += 1
    return out[:k].copy()


@njit(cache=True, error_model="numpy")
def refine(nodes, interior, total, ends, data, prm):
    """The knot-insertion rounds of ``nodes.fit_polyline`` (see its module docstring),
    compiled: one call instead of a Python loop with dozens of array operations per
    round. Returns (t, m, c, ok): the knot vector, coefficient count, coefficients
    (m, d) in the scaled space, and whether the last round passed (or only soft checks
    failed).

    Round-invariant inputs: the nodes (``FitNodes``), the initial ``interior`` knots and
    the ``total`` parameter length, the end states (``EndStates``), the check points and
    data (``FitData``) and the settings (``RefineParams``; no more than ``max_interior``
    interior knots are inserted).
    """
    u, y, tol, chords, clen, lin_ratio = nodes
    d1s, d2s, d1e, d2e, start_mode, end_mode = ends
    xc0, ref0, tol_c0, exp_lin0, w_data0, span_f = data
    (
        tol_ref,
        tol_rot,
        lin,
        metric,
        between_safety,
        smoothing,
        ridge,
        min_ratio,
        stop_ratio,
        max_rounds,
        stale_rounds,
        min_span,
        max_interior,
    ) = prm
    n, d = y.shape
    ns = span_f.shape[0]
    stale = 0
    last_soft = np.inf
    hard = 0
    ok = False
    P0 = xc0.shape[0]
    t = np.empty(0)
    m = 0
    c = np.zeros((0, d))
    for _ in range(max_rounds + 1):
        ni = interior.shape[0]
        m = ni + 6
        t = np.empty(ni + 12)
        t[:6] = 0.0
        t[6 : 6 + ni] = interior
        t[6 + ni :] = total
        c = np.zeros((m, d))
        end_coefs(t, m, c, y[0], y[n - 1], d1s, d2s, d1e, d2e, start_mode, end_mode)
        fixed = np.zeros(m, dtype=np.bool_)
        fixed[0] = True
        fixed[m - 1] = True
        if start_mode == 1:
            fixed[:3] = True
        if end_mode == 1:
            fixed[m - 3 :] = True
        # Greville abscissae and the chordal prior of the ridge term
        prior = np.empty((m, d))
        g = np.empty(m)
        for i in range(m):
            acc = 0.0
            for r in range(5):
                acc += 0.2 * t[i + 1 + r]
            g[i] = acc
        _interp_rows(g, u, y, prior)
        # points inside every knot span, on the programmed moves
        nsp = ni + 1
        K = nsp * ns
        P = P0 + K
        xc = np.empty(P)
        ref = np.empty((P, d))
        tol_c = np.empty(P)
        exp_lin = np.empty(P)
        exp_all = np.ones(P)
        xc[:P0] = xc0
        ref[:P0] = ref0
        tol_c[:P0] = tol_c0
        exp_lin[:P0] = exp_lin0
        w_data = np.empty(P)
        w_data[:P0] = w_data0
        q = 0
        for sp in range(nsp):
            k0 = 0.0 if sp == 0 else interior[sp - 1]
            k1 = total if sp == ni else interior[sp]
            for f in range(ns):
                x = k0 + (k1 - k0) * span_f[f]
                j = np.searchsorted(u, x, side="right") - 1
                if j < 0:
                    j = 0
                elif j > n - 2:
                    j = n - 2
                fr = (x - u[j]) / clen[j]
                ts = tol[j + 1] * between_safety
                xc[P0 + q] = x
                for a in range(d):
                    ref[P0 + q, a] = y[j, a] + chords[j, a] * fr
                tol_c[P0 + q] = ts
                exp_lin[P0 + q] = lin_ratio[j]
                w_data[P0 + q] = 0.5 * tol_ref / (ts + 1e-12)
                q += 1
        # the check points are the data points: one basis triangle each per round
        bases = point_bases(t, m, xc)
        solve_lsq(t, m, bases, ref, w_data, prior, fixed, c, smoothing, ridge)
        bad = np.zeros(m + 1, dtype=np.bool_)
        limits = (tol_rot, lin, metric, min_ratio, stop_ratio)
        worst_lin, worst_rot, hard, soft = check(
            t, m, c, CheckPoints(xc, ref, tol_c, exp_all, exp_lin), bases, limits, bad, n
        )
        if hard == 0:
            # chord points are a heuristic against bulges: stop refining for them once
            # a few rounds no longer help (the nodes are within tolerance)
            if soft >= last_soft:
                stale += 1
            else:
                stale = 0
            last_soft = soft
            if soft == 0 or stale >= stale_rounds:
                ok = True
                break
        else:
            stale = 0
            last_soft = np.inf
        # a knot at the middle node of every failing span (its middle if it has none)
        new = np.empty(m + 1)
        nn = 0
        for sp in range(m + 1):
            if not bad[sp]:
                continue
            if max_interior >= 0 and ni + nn >= max_interior:
                break
            lo_t = t[sp]
            hi_t = t[sp + 1]
            if not (hi_t - lo_t > 2.0 * min_span):
                continue
            i_lo = np.searchsorted(u, lo_t, side="right")
            i_hi = np.searchsorted(u, hi_t, side="left") - 1
            if i_hi >= i_lo:
                mid = (i_lo + i_hi) // 2
                mid = min(max(mid, 0), n - 1)
                new[nn] = u[mid]
            else:
                new[nn] = 0.5 * (lo_t + hi_t)
            nn += 1
        if nn == 0:
            break
        interior = _merge_sorted(interior, new[:nn])
    # out of rounds or of refinable spans: fine if only soft checks still fail
    ok = ok or hard == 0
    return t, m, c, ok

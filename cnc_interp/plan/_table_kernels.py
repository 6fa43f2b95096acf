"""Numba kernels of VPOp's arc-length joint table (``vpop.JointTable``).

A path is stored as quintic segments in a parameter u (``Path.coef``, ``Path.breaks``);
the table holds q(s) as quintic Hermite pieces in arc length s. Refinement is a
depth-first bisection of each initial piece in u: a piece is accepted when its
Hermite interpolant matches the true path at its quarter points, else split at its
u-midpoint. Each piece is integrated once (Gauss–Legendre on its four quarters, which
gives both its length and the arc length of its check points); pieces that pass are
never recomputed. ``build_identity`` runs the whole table of one path in one call;
``initial_pieces``, ``quarter_arcs``, ``piece_errors`` and ``hermite_check`` serve the
Python driver used with kinematics; ``curvature_bounds`` and ``speed_bound`` are the
per-piece bounds the step loop reads.

Arrays: ``coef`` (n_seg, 6, n) power coefficients in t = u - breaks[k], ``breaks``
(n_seg+1,), ``w`` (n,) arc-length metric, ``glx``/``glw`` Gauss–Legendre nodes and
weights on [-1, 1]. Knot data are (K, 3, n): q, q_s, q_ss; check positions (K, 3, n)
at the three quarter points. Lengths in mm (deg for rotary-only paths). The helpers
index the caller's arrays rather than take row views: in these hot loops a numba
view costs more (reference counting) than the arithmetic it feeds.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from ..fit._quintic import quintic_d012

# build_identity status codes
# build_identity's statuses (one set for every kernel: ``status``)
from .status import NO_LENGTH, NOT_FINITE, OK

# ``_quarters``, ``_pos`` and ``_piece_err`` run for every piece checked and are inlined
# (``inline="always"``): a call passes each of their ten-odd arrays field by field. It took
# ~5 % off VPOp's planning of stellabee1's first 3000 paths (7.43 -> 7.1 CPU-s) at no
# measurable compile cost; inlining ``_hermite`` and ``_knot`` too gained nothing more.

#: ``_quarters``' scratch: the Gauss-Legendre nodes t and squared speeds s2 of the four
#: rules (4 * len(glx),), and the quarters' half widths half (4,)
QuarterScratch = namedtuple("QuarterScratch", "t s2 half")


@njit(cache=True, nogil=True, inline="always")
def _quarters(coef, breaks, w, k, ua, ub, glx, glw, uc, sub, sc):
    """Quarter points uc (3,) of [ua, ub] and the arc lengths sub (4,) of its quarters,
    each by one Gauss–Legendre rule (scratch ``QuarterScratch`` sc)."""
    t = sc.t
    s2 = sc.s2
    half = sc.half
    base = breaks[k]
    du = ub - ua
    ng = glx.shape[0]
    prev = ua - base
    for j in range(4):
        nxt = (ub if j == 3 else ua + du * (0.25 * (j + 1))) - base
        if j < 3:
            uc[j] = nxt + base
        h = 0.5 * (nxt - prev)
        mid = 0.5 * (prev + nxt)
        half[j] = h
        for g in range(ng):
            t[j * ng + g] = mid + h * glx[g]
        prev = nxt
    for i in range(4 * ng):
        s2[i] = 0.0
    # all nodes of the four rules at once: a loop over nodes per axis vectorises
    for ax in range(coef.shape[2]):
        wa = w[ax]
        if wa == 0.0:
            continue
        d5 = 5.0 * coef[k, 5, ax]
        d4 = 4.0 * coef[k, 4, ax]
        d3 = 3.0 * coef[k, 3, ax]
        d2 = 2.0 * coef[k, 2, ax]
        d1 = coef[k, 1, ax]
        for i in range(4 * ng):
            x = t[i]
            d = (((d5 * x + d4) * x + d3) * x + d2) * x + d1
            s2[i] += wa * d * d
    for j in range(4):
        acc = 0.0
        for g in range(ng):
            acc += glw[g] * np.sqrt(s2[j * ng + g])
        sub[j] = half[j] * acc


@njit(cache=True, nogil=True)
def quarter_arcs(coef, breaks, w, seg, ua, ub, glx, glw):
    """Per piece (K,): quarter points uc (K, 3) and arc lengths of its quarters (K, 4)."""
    m = ua.shape[0]
    uc = np.empty((m, 3))
    sub = np.empty((m, 4))
    ng = glx.shape[0]
    t = np.empty(4 * ng)
    s2 = np.empty(4 * ng)
    half = np.empty(4)
    uc1 = np.empty(3)
    sub1 = np.empty(4)
    for p in range(m):
        _quarters(coef, breaks, w, seg[p], ua[p], ub[p], glx, glw, uc1, sub1, QuarterScratch(t, s2, half))
        for j in range(3):
            uc[p, j] = uc1[j]
        for j in range(4):
            sub[p, j] = sub1[j]
    return uc, sub


@njit(cache=True, nogil=True)
def _seg_of_u(breaks, u):
    """``Path.segment_of_u`` for one value: searchsorted(breaks, u, 'right') - 1, clipped."""
    lo = 0
    hi = breaks.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if breaks[mid] <= u:
            lo = mid + 1
        else:
            hi = mid
    k = lo - 1
    n_seg = breaks.shape[0] - 1
    if k < 0:
        k = 0
    if k > n_seg - 1:
        k = n_seg - 1
    return k


@njit(cache=True, nogil=True, inline="always")
def _pos(coef, k, t, out, i, j):
    """q at local t of segment k into out[i, j, :]."""
    for ax in range(coef.shape[2]):
        out[i, j, ax] = quintic_d012(coef, k, ax, t)[0]


@njit(cache=True, nogil=True)
def _knot(coef, breaks, w, u, Q, i):
    """Q[i] = q, q_s, q_ss at parameter u, as ``Path.derivatives_s`` (NaN where |q_u| = 0)."""
    k = _seg_of_u(breaks, u)
    t = u - breaks[k]
    n = coef.shape[2]
    s2 = 0.0
    dot1 = 0.0
    for ax in range(n):
        a0, a1, a2 = quintic_d012(coef, k, ax, t)
        Q[i, 0, ax] = a0
        Q[i, 1, ax] = a1
        Q[i, 2, ax] = a2
        s2 += a1 * a1 * w[ax]
        dot1 += a1 * a2 * w[ax]
    sig = np.sqrt(s2)
    if not sig > 0.0:
        sig = np.nan
    sig_u = dot1 / sig
    for ax in range(n):
        qu = Q[i, 1, ax]
        Q[i, 1, ax] = qu / sig
        Q[i, 2, ax] = Q[i, 2, ax] / sig**2 - qu * sig_u / sig**3


@njit(cache=True, nogil=True)
def _copy_knot(src, i, dst, j):
    for r in range(3):
        for ax in range(src.shape[2]):
            dst[j, r, ax] = src[i, r, ax]


@njit(cache=True, nogil=True)
def _hermite(h, QA, ia, QB, ib, C, ic):
    """C[ic] (6, n): quintic Hermite power coefficients in s - s_a over a piece of
    length h from the knot data QA[ia] to QB[ib]."""
    h2 = h * h
    h3 = h2 * h
    h4 = h3 * h
    h5 = h4 * h
    for ax in range(QA.shape[2]):
        c0 = QA[ia, 0, ax]
        c1 = QA[ia, 1, ax]
        c2 = 0.5 * QA[ia, 2, ax]
        d0 = QB[ib, 0, ax] - (c0 + h * (c1 + h * c2))
        d1 = QB[ib, 1, ax] - (c1 + 2.0 * h * c2)
        d2 = QB[ib, 2, ax] - 2.0 * c2
        C[ic, 0, ax] = c0
        C[ic, 1, ax] = c1
        C[ic, 2, ax] = c2
        C[ic, 3, ax] = (20.0 * d0 - 8.0 * d1 * h + d2 * h2) / (2.0 * h3)
        C[ic, 4, ax] = (-30.0 * d0 + 14.0 * d1 * h - 2.0 * d2 * h2) / (2.0 * h4)
        C[ic, 5, ax] = (12.0 * d0 - 6.0 * d1 * h + d2 * h2) / (2.0 * h5)


@njit(cache=True, nogil=True, inline="always")
def _piece_err(C, ic, t, QT, it, j):
    """max over the axes of |C[ic](t) - QT[it, j]|; a NaN counts as +inf."""
    e = 0.0
    for ax in range(C.shape[2]):
        d = abs(quintic_d012(C, ic, ax, t)[0] - QT[it, j, ax])
        if not d <= e:
            e = d if d == d else np.inf
    return e


@njit(cache=True, nogil=True)
def hermite_check(S, Q, off, qc):
    """Table of knots S (m+1,) and knot data Q (m+1, 3, n): coefficients C (m, 6, n)
    and each piece's largest deviation (m,) from the true positions qc (m, 3, n) at arc
    length S[p] + off[p, j] (off (m, 3), already scaled to S)."""
    m = S.shape[0] - 1
    C = np.empty((m, 6, Q.shape[2]))
    err = np.empty(m)
    for p in range(m):
        _hermite(S[p + 1] - S[p], Q, p, Q, p + 1, C, p)
        e = 0.0
        for j in range(3):
            t = (S[p] + off[p, j]) - S[p]  # as the step loop sees it: absolute s
            ej = _piece_err(C, p, t, qc, p, j)
            if not ej <= e:
                e = ej
        err[p] = e
    return C, err


@njit(cache=True, nogil=True)
def piece_errors(h, QA, QB, off, qc):
    """Pieces with their own end data QA, QB (each (K, 3, n)) and lengths h (K,): the
    largest deviation (K,) of each Hermite piece from qc (K, 3, n) at local s = off (K, 3)."""
    m = h.shape[0]
    c = np.empty((1, 6, QA.shape[2]))
    err = np.empty(m)
    for p in range(m):
        _hermite(h[p], QA, p, QB, p, c, np.int64(0))
        e = 0.0
        for j in range(3):
            ej = _piece_err(c, np.int64(0), off[p, j], qc, p, j)
            if not ej <= e:
                e = ej
        err[p] = e
    return err


@njit(cache=True, nogil=True)
def initial_pieces(breaks, s_breaks, max_piece):
    """Initial pieces (ua, ub, seg): every segment, cut into equal u parts of at most
    ``max_piece`` of arc length each."""
    n_seg = breaks.shape[0] - 1
    cnt = np.empty(n_seg, dtype=np.int64)
    tot = 0
    for k in range(n_seg):
        c = int(np.ceil((s_breaks[k + 1] - s_breaks[k]) / max_piece))
        cnt[k] = c if c > 1 else 1
        tot += cnt[k]
    ua = np.empty(tot)
    ub = np.empty(tot)
    seg = np.empty(tot, dtype=np.int64)
    p = 0
    for k in range(n_seg):
        a, b, c = breaks[k], breaks[k + 1], cnt[k]
        step = (b - a) / c
        for j in range(c):
            ua[p] = a + j * step
            ub[p] = b if j == c - 1 else a + (j + 1) * step
            seg[p] = k
            p += 1
    return ua, ub, seg


@njit(cache=True, nogil=True)
def _grow(x, cap):
    y = np.empty((cap,) + x.shape[1:], dtype=x.dtype)
    y[: x.shape[0]] = x
    return y


@njit(cache=True, nogil=True)
def _refine(coef, breaks, w, ua0, ub0, seg0, tol, scale, max_depth, glx, glw):
    """Depth-first bisection of the initial pieces (identity kinematics).

    A piece is checked as it will be in the table, with its arc lengths times ``scale``
    (the factor that makes the table's length the path's) added to the running S
    (bit for bit what ``_finish`` computes, the last knot aside). Returns the accepted
    pieces in path order (m of them): ua, ub, seg, depth, ds (unscaled arc length),
    off (m, 3) unscaled arc length from the piece start to its quarter points, err
    (m,) the deviation found there, the knot data Q (m+1, 3, n) at each
    piece's start and the last piece's end, and qc (m, 3, n) the path at the quarter
    points. Pieces of zero length are dropped (the path stands still there). Each
    knot is evaluated once: a split hands its end data down to both halves.
    """
    n = coef.shape[2]
    ng = glx.shape[0]
    cap = 4 * ua0.shape[0] + 64
    # one row per accepted piece: ua, ub, ds, err, off (3), then its start knot data
    # (3n) and the path at its quarter points (3n); the row after the last holds the
    # last piece's end knot data. One buffer: growing it is one reassignment.
    nf = 7 + 6 * n
    out = np.empty((cap + 1, nf))
    oi = np.empty((cap, 2), dtype=np.int64)
    st = max_depth + 2  # the stack grows by one entry per level
    st_a = np.empty(st)
    st_b = np.empty(st)
    st_d = np.empty(st, dtype=np.int64)
    st_qa = np.empty((st, 3, n))
    st_qb = np.empty((st, 3, n))
    qm = np.empty((1, 3, n))
    c = np.empty((1, 6, n))
    qt = np.empty((1, 3, n))
    uc = np.empty(3)
    sub = np.empty(4)
    tg = np.empty(4 * ng)
    s2 = np.empty(4 * ng)
    half = np.empty(4)
    m = 0
    p0 = 0
    s_run = 0.0  # the table's S at the next accepted piece's start, summed as _finish does
    while p0 < ua0.shape[0]:
        m0 = m
        s0 = s_run
        full = False
        k = seg0[p0]
        base = breaks[k]
        st_a[0] = ua0[p0]
        st_b[0] = ub0[p0]
        st_d[0] = 0
        _knot(coef, breaks, w, ua0[p0], st_qa, np.int64(0))
        _knot(coef, breaks, w, ub0[p0], st_qb, np.int64(0))
        top = 1
        while top > 0:
            top -= 1
            a = st_a[top]
            b = st_b[top]
            d = st_d[top]
            _quarters(coef, breaks, w, k, a, b, glx, glw, uc, sub, QuarterScratch(tg, s2, half))
            ds = sub[0] + sub[1] + sub[2] + sub[3]
            if not ds > 0.0:
                continue
            # the same floating-point operations as _finish and hermite_check: with the
            # final scale, a piece passes here exactly when it passes in the table
            _hermite((s_run + ds * scale) - s_run, st_qa, top, st_qb, top, c, np.int64(0))
            e = 0.0
            acc = 0.0
            for j in range(3):
                acc += sub[j]
                _pos(coef, k, uc[j] - base, qt, np.int64(0), j)
                ej = _piece_err(c, np.int64(0), (s_run + acc * scale) - s_run, qt, np.int64(0), j)
                if not ej <= e:
                    e = ej
            if not e <= tol and d < max_depth:
                mid = 0.5 * (a + b)
                if a < mid < b:
                    _knot(coef, breaks, w, mid, qm, np.int64(0))
                    # left half above the right one: it is processed first
                    st_a[top + 1] = a
                    st_b[top + 1] = mid
                    st_d[top + 1] = d + 1
                    _copy_knot(st_qa, top, st_qa, top + 1)
                    _copy_knot(qm, np.int64(0), st_qb, top + 1)
                    st_a[top] = mid  # (st_b[top], st_qb[top] stay b's)
                    st_d[top] = d + 1
                    _copy_knot(qm, np.int64(0), st_qa, top)
                    top += 2
                    continue
            if m == cap:
                full = True
                break
            out[m, 0] = a
            out[m, 1] = b
            out[m, 2] = ds
            out[m, 3] = e
            out[m, 4] = sub[0]
            out[m, 5] = sub[0] + sub[1]
            out[m, 6] = sub[0] + sub[1] + sub[2]
            for r in range(3):
                for ax in range(n):
                    out[m, 7 + r * n + ax] = st_qa[top, r, ax]
                    out[m, 7 + 3 * n + r * n + ax] = qt[0, r, ax]
                    out[m + 1, 7 + r * n + ax] = st_qb[top, r, ax]  # until the next piece
            oi[m, 0] = k
            oi[m, 1] = d
            m += 1
            s_run += ds * scale
        if full:  # out of rows: grow (outside the hot loop) and redo this initial piece
            m = m0
            s_run = s0
            cap *= 2
            out = _grow(out, cap + 1)
            oi = _grow(oi, cap)
            continue
        p0 += 1
    Q = np.empty((m + 1, 3, n))
    qc = np.empty((m, 3, n))
    for p in range(m + 1):
        for r in range(3):
            for ax in range(n):
                Q[p, r, ax] = out[p, 7 + r * n + ax]
                if p < m:
                    qc[p, r, ax] = out[p, 7 + 3 * n + r * n + ax]
    return (
        out[:m, 0].copy(),
        out[:m, 1].copy(),
        oi[:m, 0].copy(),
        oi[:m, 1].copy(),
        out[:m, 2].copy(),
        out[:m, 4:7].copy(),
        out[:m, 3].copy(),
        Q,
        qc,
    )


@njit(cache=True, nogil=True)
def _finish(length, ds, off, Q, qc):
    """Knots S (m+1,) scaled so that S[-1] = length exactly, then (C, err) of
    ``hermite_check`` on that table, and the scale factor."""
    m = ds.shape[0]
    total = 0.0
    for p in range(m):
        total += ds[p]
    scale = length / total
    S = np.empty(m + 1)
    S[0] = 0.0
    acc = 0.0
    for p in range(m):
        acc += ds[p] * scale
        S[p + 1] = acc
    S[m] = length
    offs = off * scale
    C, err = hermite_check(S, Q, offs, qc)
    return S, C, err, scale


@njit(cache=True, nogil=True)
def build_identity(coef, breaks, s_breaks, w, length, tol, max_depth, max_piece, glx, glw, max_tries):
    """The whole table of one path in joint = program coordinates.

    Returns (status, u, S, C, max_err, qend): status ``OK``, ``NO_LENGTH`` (no piece
    has positive arc length) or ``NOT_FINITE`` (C is not: a point of zero speed);
    u (m+1,) the knots' parameters; max_err the largest deviation at the pieces'
    quarter points in the final table; qend (n,) the path's end point, bit for bit
    ``Path.derivatives_u`` (same Horner steps). The refinement checks pieces
    with their lengths unscaled; if the scaling to ``length`` then pushes a piece
    that passed over ``tol``, the refinement is rerun with that scale (then, if
    rounding still does, with the tolerance tightened by the excess). Deterministic;
    the scale is 1 to ~1e-15 for fitted paths, so a rerun is rare.
    """
    ua0, ub0, seg0 = initial_pieces(breaks, s_breaks, max_piece)
    tol_in = tol
    sc_in = 1.0
    u = np.empty(0)
    S = np.empty(0)
    C = np.empty((0, 6, coef.shape[2]))
    err = np.empty(0)
    n_seg = breaks.shape[0] - 1
    qend = np.empty((1, 1, coef.shape[2]))
    _pos(coef, n_seg - 1, breaks[n_seg] - breaks[n_seg - 1], qend, np.int64(0), np.int64(0))
    for attempt in range(max_tries):
        ua, ub, seg, dep, ds, off, e_loc, Q, qc = _refine(
            coef, breaks, w, ua0, ub0, seg0, tol_in, sc_in, max_depth, glx, glw
        )
        total = 0.0
        for p in range(ds.shape[0]):
            total += ds[p]
        if ds.shape[0] == 0 or not total > 0.0:
            return NO_LENGTH, u, S, C, 0.0, qend[0, 0]
        S, C, err, scale = _finish(length, ds, off, Q, qc)
        m = ds.shape[0]
        u = np.empty(m + 1)
        u[:m] = ua
        u[m] = ub[m - 1]
        over = 0.0
        for p in range(m):
            # a piece that passed locally but not in the final table, and could split
            if e_loc[p] <= tol_in and dep[p] < max_depth and not err[p] <= tol:
                d = err[p] - tol
                if not d <= over:
                    over = d
        if over == 0.0:
            break
        if scale != sc_in:
            sc_in = scale
        else:  # rounding (the last knot): fail those pieces locally next time
            low = tol_in
            for p in range(m):
                if e_loc[p] <= tol_in and dep[p] < max_depth and not err[p] <= tol:
                    low = min(low, e_loc[p])
            tol_in = max(min(tol_in - 2.0 * over, low * (1.0 - 1e-9)), 0.5 * tol_in)
    max_err = 0.0
    for p in range(err.shape[0]):
        if not err[p] <= max_err:
            max_err = err[p]
    for x in C.ravel():
        if not np.isfinite(x):
            return NOT_FINITE, u, S, C, max_err, qend[0, 0]
    return OK, u, S, C, max_err, qend[0, 0]


@njit(cache=True, nogil=True)
def curvature_bounds(S, C, al, jl):
    """``JointTable.curvature_bounds`` (same sums in the same order): per piece (m,)
    max_i 1.25 max|q_ss,i|/al_i, max_i 1.25 max|q_sss,i|/jl_i and max_i 3.75 max|q_ss,i|/jl_i
    over five points of the piece."""
    m = C.shape[0]
    n = C.shape[2]
    k2 = np.empty(m)
    k3 = np.empty(m)
    k23 = np.empty(m)
    for p in range(m):
        h = S[p + 1] - S[p]
        b2 = -np.inf
        b3 = -np.inf
        b23 = -np.inf
        for ax in range(n):
            c2 = C[p, 2, ax]
            c3 = C[p, 3, ax]
            c4 = C[p, 4, ax]
            c5 = C[p, 5, ax]
            a2 = 0.0
            a3 = 0.0
            for i in range(5):
                t = h * (0.25 * i)
                q2 = 2 * c2 + t * (6 * c3 + t * (12 * c4 + t * 20 * c5))
                q3 = 6 * c3 + t * (24 * c4 + t * 60 * c5)
                a2 = max(a2, abs(q2))
                a3 = max(a3, abs(q3))
            m2 = 1.25 * a2
            m3 = 1.25 * a3
            b2 = max(b2, m2 / al[ax])
            b3 = max(b3, m3 / jl[ax])
            b23 = max(b23, 3.0 * m2 / jl[ax])
        k2[p] = b2
        k3[p] = b3
        k23[p] = b23
    return k2, k3, k23


@njit(cache=True, nogil=True)
def speed_bound(S, C, vl):
    """Per piece (m,): max_i 1.02 max|q_s,i|/vl_i over five points of the piece."""
    m = C.shape[0]
    n = C.shape[2]
    kv = np.empty(m)
    for p in range(m):
        h = S[p + 1] - S[p]
        b = -np.inf
        for ax in range(n):
            c1 = C[p, 1, ax]
            c2 = C[p, 2, ax]
            c3 = C[p, 3, ax]
            c4 = C[p, 4, ax]
            c5 = C[p, 5, ax]
            a1 = 0.0
            for i in range(5):
                t = h * (0.25 * i)
                q1 = c1 + t * (2 * c2 + t * (3 * c3 + t * (4 * c4 + t * 5 * c5)))
                a1 = max(a1, abs(q1))
            b = max(b, 1.02 * a1 / vl[ax])
        kv[p] = b
    return kv

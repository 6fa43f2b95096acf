"""Numba kernel of ``Path``'s arc-length table (adaptive composite Gauss–Legendre)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _seg_integral(dc, w, a, b, glx, glw):
    """∫_a^b |dq/dt|_w dt on one segment (local t) with one Gauss–Legendre rule; ``dc``
    (5, n) the derivative's coefficients ``i * coef[i]``, i = 1..5 (``_deriv_coef``)."""
    half = 0.5 * (b - a)
    mid = 0.5 * (b + a)
    n_ax = dc.shape[1]
    acc = 0.0
    for g in range(glx.shape[0]):
        t = mid + half * glx[g]
        s2 = 0.0
        for ax in range(n_ax):
            if w[ax] == 0.0:
                continue
            d = dc[4, ax]
            for i in range(3, -1, -1):
                d = d * t + dc[i, ax]
            s2 += w[ax] * d * d
        acc += glw[g] * np.sqrt(s2)
    return half * acc


@njit(cache=True)
def _deriv_coef(coef, k, dc):
    """``dc[i - 1] = i * coef[k, i]`` (i = 1..5): the derivative's coefficients, the same
    products Horner's rule on the derivative would form at every point."""
    for i in range(1, 6):
        for ax in range(coef.shape[2]):
            dc[i - 1, ax] = i * coef[k, i, ax]


@njit(cache=True)
def arc_length_table(coef, breaks, w, glx, glw, rel_tol, max_sub):
    """Sub-interval table: (sub_u, sub_s, sub_seg, starts) like ``Path._build_arc_length``.

    Each segment is split into 2^j equal sub-intervals, doubling until the total
    changes by at most ``rel_tol`` (relative) or ``max_sub`` is reached. The table's
    sub-integrals are those of the last doubling, kept rather than computed again.
    """
    n_seg = coef.shape[0]
    n_sub = np.empty(n_seg, dtype=np.int64)
    vals = np.empty(4 * max(n_seg, 1))  # each segment's sub-integrals, in order
    used = 0
    dc = np.empty((5, coef.shape[2]))
    for k in range(n_seg):
        _deriv_coef(coef, k, dc)
        h = breaks[k + 1] - breaks[k]
        m = 2
        prev = 0.0
        for j in range(m):
            prev += _seg_integral(dc, w, j * h / m, (j + 1) * h / m, glx, glw)
        while True:
            m *= 2
            if used + m > vals.shape[0]:
                grown = np.empty(2 * (used + m))
                grown[:used] = vals[:used]
                vals = grown
            tot = 0.0
            for j in range(m):
                v = _seg_integral(dc, w, j * h / m, (j + 1) * h / m, glx, glw)
                vals[used + j] = v
                tot += v
            if abs(tot - prev) <= rel_tol * max(tot, 1e-300) + 1e-300 or m >= max_sub:
                break
            prev = tot
        n_sub[k] = m
        used += m
    total = used
    sub_u = np.empty(total + 1)
    sub_s = np.empty(total + 1)
    sub_seg = np.empty(total, dtype=np.int64)
    starts = np.empty(n_seg + 1, dtype=np.int64)
    i = 0
    s = 0.0
    sub_s[0] = 0.0
    for k in range(n_seg):
        starts[k] = i
        h = breaks[k + 1] - breaks[k]
        m = n_sub[k]
        for j in range(m):
            a = j * h / m
            sub_u[i] = breaks[k] + a
            sub_seg[i] = k
            s += vals[i]
            sub_s[i + 1] = s
            i += 1
    starts[n_seg] = total
    sub_u[total] = breaks[n_seg]
    return sub_u, sub_s, sub_seg, starts


@njit(cache=True, nogil=True)
def arc_length_tables(coef, breaks, seg_off, w, glx, glw, rel_tol, max_sub):
    """``arc_length_table`` of many paths at once (one compiled call for a whole run).

    Path p has segments seg_off[p]..seg_off[p+1]-1 of ``coef`` (S, 6, n), breakpoints
    breaks[seg_off[p] + p .. seg_off[p+1] + p] and metric w[p] (P, n). Each path's
    table is computed by ``arc_length_table`` itself (identical values). Returns the
    concatenated sub_u/sub_s (sum of (n_sub + 1) per path), sub_seg (sum of n_sub),
    s_breaks (S + P) and the offsets sub_off (P+1,) into sub_seg (sub_u/sub_s of path p
    start at sub_off[p] + p).
    """
    n_p = seg_off.shape[0] - 1
    us = []
    ss = []
    segs = []
    sbs = []
    sub_off = np.zeros(n_p + 1, dtype=np.int64)
    for p in range(n_p):
        a, b = seg_off[p], seg_off[p + 1]
        sub_u, sub_s, seg, starts = arc_length_table(
            coef[a:b], breaks[a + p : b + p + 1], w[p], glx, glw, rel_tol, max_sub
        )
        us.append(sub_u)
        ss.append(sub_s)
        segs.append(seg)
        sbs.append(sub_s[starts])
        sub_off[p + 1] = sub_off[p] + seg.shape[0]
    n_sub = sub_off[n_p]
    all_u = np.empty(n_sub + n_p)
    all_s = np.empty(n_sub + n_p)
    all_seg = np.empty(n_sub, dtype=np.int64)
    all_sb = np.empty(seg_off[n_p] + n_p)
    for p in range(n_p):
        o = sub_off[p] + p
        m = us[p].shape[0]
        all_u[o : o + m] = us[p]
        all_s[o : o + m] = ss[p]
        all_seg[sub_off[p] : sub_off[p + 1]] = segs[p]
        all_sb[seg_off[p] + p : seg_off[p + 1] + p + 1] = sbs[p]
    return all_u, all_s, all_seg, all_sb, sub_off


@njit(cache=True, nogil=True)
def chain_ends(coef, breaks, seg_off, start, has_start):
    """Chain paths end to start: coef[first segment of p, 0] = end of path p-1 (of
    ``start`` (n,) for p = 0 when ``has_start``), in place. Returns the ends (P, n) and
    the shift (P, n) applied to each path's first point (0 where none). The end is the
    same Horner arithmetic as ``Path.end``."""
    n_p = seg_off.shape[0] - 1
    n = coef.shape[2]
    ends = np.empty((n_p, n))
    delta = np.zeros((n_p, n))
    prev = start.copy()
    for p in range(n_p):
        a, b = seg_off[p], seg_off[p + 1]
        if p > 0 or has_start:
            for ax in range(n):
                delta[p, ax] = prev[ax] - coef[a, 0, ax]
                coef[a, 0, ax] = prev[ax]
        t = breaks[b + p] - breaks[b + p - 1]
        for ax in range(n):
            acc = coef[b - 1, 5, ax] * 1.0
            for i in range(4, -1, -1):
                acc = acc * t + coef[b - 1, i, ax] * 1.0
            ends[p, ax] = acc
            prev[ax] = acc
    return ends, delta

"""Numba kernel of ``Path``'s arc-length table (adaptive composite Gauss–Legendre)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _seg_integral(coef, k, w, a, b, glx, glw):
    """∫_a^b |dq/dt|_w dt on segment k (local t) with one Gauss–Legendre rule."""
    half = 0.5 * (b - a)
    mid = 0.5 * (b + a)
    n_ax = coef.shape[2]
    acc = 0.0
    for g in range(glx.shape[0]):
        t = mid + half * glx[g]
        s2 = 0.0
        for ax in range(n_ax):
            if w[ax] == 0.0:
                continue
            d = 5.0 * coef[k, 5, ax]
            for i in range(4, 0, -1):
                d = d * t + i * coef[k, i, ax]
            s2 += w[ax] * d * d
        acc += glw[g] * np.sqrt(s2)
    return half * acc


@njit(cache=True)
def arc_length_table(coef, breaks, w, glx, glw, rel_tol, max_sub):
    """Sub-interval table: (sub_u, sub_s, sub_seg, starts) like ``Path._build_arc_length``.

    Each segment is split into 2^j equal sub-intervals, doubling until the total
    changes by at most ``rel_tol`` (relative) or ``max_sub`` is reached.
    """
    n_seg = coef.shape[0]
    n_sub = np.empty(n_seg, dtype=np.int64)
    for k in range(n_seg):
        h = breaks[k + 1] - breaks[k]
        m = 2
        prev = 0.0
        for j in range(m):
            prev += _seg_integral(coef, k, w, j * h / m, (j + 1) * h / m, glx, glw)
        while True:
            m *= 2
            tot = 0.0
            for j in range(m):
                tot += _seg_integral(coef, k, w, j * h / m, (j + 1) * h / m, glx, glw)
            if abs(tot - prev) <= rel_tol * max(tot, 1e-300) + 1e-300 or m >= max_sub:
                break
            prev = tot
        n_sub[k] = m
    total = 0
    for k in range(n_seg):
        total += n_sub[k]
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
            s += _seg_integral(coef, k, w, a, (j + 1) * h / m, glx, glw)
            sub_s[i + 1] = s
            i += 1
    starts[n_seg] = total
    sub_u[total] = breaks[n_seg]
    return sub_u, sub_s, sub_seg, starts

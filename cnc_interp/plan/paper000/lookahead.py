"""Look-ahead over the profile pieces: junction and cruise feeds (compiled with numba).

Piece k has length L_k, cruise cap V_k and tangential limits A_k(v), J_k(v) that depend
on the feed (``limits``: at a lower feed the centripetal terms leave more room). Its
feed goes w_k -> c_k -> w_{k+1} with the shortest transitions of ``profile``, each under
the limits at its larger feed, so the distance D(v0, v1) = (v0 + v1) T_min / 2 grows
with max(v0, v1). The junction feeds start at their caps (w_0 = w_m = 0); a backward
pass lowers w_k so that w_{k+1} can still be reached decelerating over piece k
(slow-downs start early enough), a forward pass lowers w_{k+1} so that it can be
reached accelerating from w_k. Afterwards D(w_k, w_{k+1}) <= L_k for every k, and the
cruise feed is the largest c_k <= V_k with D(w_k, c_k) + D(c_k, w_{k+1}) <= L_k
(bisection); both transitions of piece k then use the limits at c_k. These loops are
sequential, hence numba; this module is imported only when a plan is made.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .profile import ACC_PEAK, JERK_PEAK


#: bisection steps of the look-ahead passes (reach / cruise feed)
P000_BISECT_ITERS = 80


@njit(cache=True)
def tangential_at(v, g1, g2, g3, amax, jmax, sx, scale):
    """Tangential limits (A, J) of a piece at feeds <= v (as ``limits.tangential_limits``).

    g1, g2, g3 (n,): the piece's maxima of |q'|, |q''|, |q'''| per joint; ``scale``
    multiplies both (replans lower it).
    """
    n = g1.shape[0]
    a = np.inf
    a0 = np.inf  # the tangential acceleration at v = 0: an upper bound of a
    for i in range(n):
        room_a = max(amax[i] - g2[i] * v * v, 0.0)
        room_j = max(jmax[i] - g3[i] * v * v * v, 0.0)
        if g1[i] > 0.0:
            a = min(a, room_a / g1[i])
            a0 = min(a0, amax[i] / g1[i])
        if g2[i] > 0.0 and v > 0.0:
            a = min(a, sx * room_j / (3.0 * g2[i] * v))
    if a == np.inf:
        a = amax.min()
        a0 = a
    j = np.inf
    for i in range(n):
        if g1[i] > 0.0:
            # the cross term 3 g2 v a is at most min(3 g2 v a0, sx room_j) by the choice of a
            room_j = max(jmax[i] - g3[i] * v * v * v, 0.0)
            left = max(room_j - 3.0 * g2[i] * v * a0, (1.0 - sx) * room_j)
            j = min(j, left / g1[i])
    if j == np.inf:
        j = jmax.min()
    return max(a * scale, 1e-300), max(j * scale, 1e-300)


@njit(cache=True)
def piece_limits(v, g1, g2, g3, amax, jmax, sx, scale, lo, hi):
    """Tangential limits (A, J) at feeds <= v of the piece made of segments lo .. hi-1.

    g1, g2, g3 (n_seg, n) and scale (n_seg,) are per segment; the piece's limits are the
    smallest of its segments' (each segment's own joint maxima, no mixing).
    """
    a = np.inf
    j = np.inf
    for s in range(lo, hi):
        sa, sj = tangential_at(v, g1[s], g2[s], g3[s], amax, jmax, sx, scale[s])
        a = min(a, sa)
        j = min(j, sj)
    return a, j


@njit(cache=True)
def _dist(v0, v1, g1, g2, g3, amax, jmax, sx, scale, lo, hi):
    a, j = piece_limits(max(v0, v1), g1, g2, g3, amax, jmax, sx, scale, lo, hi)
    dv = abs(v1 - v0)
    t = max(ACC_PEAK * dv / a, math.sqrt(JERK_PEAK * dv / j))
    return 0.5 * (v0 + v1) * t


@njit(cache=True)
def _reach(v_known, length, cap, g1, g2, g3, amax, jmax, sx, scale, lo, hi):
    """Largest v <= cap (v >= v_known) with D(v_known, v) <= length."""
    if cap <= v_known:
        return cap
    if _dist(v_known, cap, g1, g2, g3, amax, jmax, sx, scale, lo, hi) <= length:
        return cap
    a = v_known
    b = cap
    for _ in range(P000_BISECT_ITERS):
        mid = 0.5 * (a + b)
        if _dist(v_known, mid, g1, g2, g3, amax, jmax, sx, scale, lo, hi) <= length:
            a = mid
        else:
            b = mid
    return a


@njit(cache=True)
def _pair(w0, c, w1, g1, g2, g3, amax, jmax, sx, scale, lo, hi):
    return _dist(w0, c, g1, g2, g3, amax, jmax, sx, scale, lo, hi) + _dist(
        c, w1, g1, g2, g3, amax, jmax, sx, scale, lo, hi
    )


@njit(cache=True)
def lookahead(first, length, vcap, g1, g2, g3, amax, jmax, sx, scale, wcap):
    """Junction feeds w (m+1,), cruise feeds c (m,) and the limits A, J (m,) at c.

    Piece k covers segments first[k] .. first[k+1]-1 (first (m+1,), last entry n_seg),
    has length[k] and cap vcap[k]; g1, g2, g3 (n_seg, n) and scale (n_seg,) are per
    segment; wcap (m+1,) caps the junction feeds.
    """
    m = length.shape[0]
    w = wcap.copy()
    w[0] = 0.0
    w[m] = 0.0
    for k in range(1, m):
        w[k] = min(w[k], vcap[k - 1], vcap[k])
    for k in range(m - 1, -1, -1):
        w[k] = min(w[k], _reach(w[k + 1], length[k], w[k], g1, g2, g3, amax, jmax, sx, scale, first[k], first[k + 1]))
    for k in range(m):
        w[k + 1] = min(
            w[k + 1], _reach(w[k], length[k], w[k + 1], g1, g2, g3, amax, jmax, sx, scale, first[k], first[k + 1])
        )
    c = np.empty(m)
    a_c = np.empty(m)
    j_c = np.empty(m)
    for k in range(m):
        lo, hi = first[k], first[k + 1]
        a = max(w[k], w[k + 1])
        b = max(vcap[k], a)
        if _pair(w[k], b, w[k + 1], g1, g2, g3, amax, jmax, sx, scale, lo, hi) <= length[k]:
            c[k] = b
        else:
            for _ in range(P000_BISECT_ITERS):
                mid = 0.5 * (a + b)
                if _pair(w[k], mid, w[k + 1], g1, g2, g3, amax, jmax, sx, scale, lo, hi) <= length[k]:
                    a = mid
                else:
                    b = mid
            c[k] = a
        a_c[k], j_c[k] = piece_limits(c[k], g1, g2, g3, amax, jmax, sx, scale, lo, hi)
    return w, c, a_c, j_c


@njit(cache=True)
def group_segments(vcap, wcap, band):
    """Group consecutive segments into profile pieces; returns first segment of each (m,).

    A segment joins the current piece while every cap in the piece stays within
    ``band`` (relative) of the piece's smallest cap and the junction it crosses does
    not cap the feed below that smallest cap; a transition can then span the whole
    piece instead of being squeezed into one short segment. ``band <= 0``: one piece
    per segment.
    """
    n = vcap.shape[0]
    first = np.empty(n, dtype=np.int64)
    first[0] = 0
    m = 1
    gmin = vcap[0]
    gmax = vcap[0]
    for k in range(1, n):
        nmin = min(gmin, vcap[k])
        nmax = max(gmax, vcap[k])
        if band > 0.0 and wcap[k] >= nmin and nmin >= (1.0 - band) * nmax:
            gmin = nmin
            gmax = nmax
        else:
            first[m] = k
            m += 1
            gmin = vcap[k]
            gmax = vcap[k]
    return first[:m]

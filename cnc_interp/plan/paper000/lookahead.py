"""Look-ahead over the segments: junction feeds and cruise feeds (compiled with numba).

Segment k has length L_k, cruise cap V_k and tangential limits A_k, J_k; its feed goes
w_k -> c_k -> w_{k+1} with the shortest transitions of ``profile`` (distance
D(v0, v1) = (v0 + v1) T_min(|v1 - v0|) / 2, increasing in max(v0, v1)). The
junction feeds start at their caps (w_0 = w_n = 0); a backward pass lowers w_k so that
w_{k+1} can still be reached decelerating over segment k (slow-downs start early
enough), a forward pass lowers w_{k+1} so that it can be reached accelerating from
w_k. Afterwards D(w_k, w_{k+1}) <= L_k for every k, and the cruise feed is the
largest c_k <= V_k with D(w_k, c_k) + D(c_k, w_{k+1}) <= L_k (bisection). These loops
are sequential, hence numba; this module is imported only when a plan is made.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ...constants import P000_BISECT_ITERS
from .profile import ACC_PEAK, JERK_PEAK


@njit(cache=True)
def _dist(v0, v1, a, j):
    dv = abs(v1 - v0)
    t = max(ACC_PEAK * dv / a, math.sqrt(JERK_PEAK * dv / j))
    return 0.5 * (v0 + v1) * t


@njit(cache=True)
def reach(v_known, length, a, j, cap):
    """Largest v <= cap (v >= v_known) with D(v_known, v) <= length."""
    if cap <= v_known:
        return cap
    if _dist(v_known, cap, a, j) <= length:
        return cap
    lo = v_known
    hi = cap
    for _ in range(P000_BISECT_ITERS):
        mid = 0.5 * (lo + hi)
        if _dist(v_known, mid, a, j) <= length:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True)
def lookahead(length, vcap, a, j, wcap):
    """Junction feeds w (n+1,) and cruise feeds c (n,) (see module docstring)."""
    n = length.shape[0]
    w = wcap.copy()
    w[0] = 0.0
    w[n] = 0.0
    for k in range(1, n):
        w[k] = min(w[k], vcap[k - 1], vcap[k])
    for k in range(n - 1, -1, -1):
        w[k] = min(w[k], reach(w[k + 1], length[k], a[k], j[k], w[k]))
    for k in range(n):
        w[k + 1] = min(w[k + 1], reach(w[k], length[k], a[k], j[k], w[k + 1]))
    c = np.empty(n)
    for k in range(n):
        lo = max(w[k], w[k + 1])
        hi = max(vcap[k], lo)
        if _dist(w[k], hi, a[k], j[k]) + _dist(hi, w[k + 1], a[k], j[k]) <= length[k]:
            c[k] = hi
            continue
        for _ in range(P000_BISECT_ITERS):
            mid = 0.5 * (lo + hi)
            if _dist(w[k], mid, a[k], j[k]) + _dist(mid, w[k + 1], a[k], j[k]) <= length[k]:
                lo = mid
            else:
                hi = mid
        c[k] = lo
    return w, c


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
    m = 0
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

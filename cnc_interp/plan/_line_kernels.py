"""Numba kernels of the exact discrete plan of a straight path from rest to rest (``optimal.line``).

On a straight path axis i is at q0_i + σ Δq_i, σ from 0 to 1, so verify's per-axis bounds
on the backward differences of the samples are bounds on σ's (per period, with the rest
padding): first differences at most vq = min_i V_i dt / |Δq_i| (and the feed's F dt / L),
second at most aq = min_i A_i dt² / |Δq_i|, third at most jq = min_i J_i dt³ / |Δq_i|.

In units of jq (a = aq / jq, v = vq / jq), the N-period profile that goes furthest has the
second differences e_k (k = 1..N+1) odd about (N+2)/2 with the up lobe

    e_k = max(0, min(k, a, c - k))    for k < (N+2)/2,

c the largest value up to (N+2)/2 whose lobe sum (the peak speed) is at most v; the first
differences are d_k = e_1 + ... + e_k and the distance D(N) = Σ d_k. The lobe puts each
unit of speed as early as jerk and acceleration allow, and the speed cruises at v between
the lobes when they end before the middle. ``tests/test_line_plan.py`` checks D(N) against
the linear program of the discrete problem. The plan takes the smallest N with
D(N) >= 1 / jq (D grows with N: an N-period plan is an (N+1)-period one that rests in its
last period), scaled by 1 / (jq D(N)) <= 1, which keeps every bound.

Every limit is shrunk by ``shrink`` (relative) and ``ulps`` ulps of the axis's largest
position (absolute), for the rounding of the stored samples, and the samples are then
checked with verify's own float operations; a path that fails any check is left to the
other routes (``done`` False).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

#: bisection steps on the lobe's end c: 2^-100 of (N+2)/2 is below any float's resolution
_LOBE_BISECTIONS = 100


@njit(cache=True)
def lobe_sum(c, a):
    """Σ_k max(0, min(k, a, c - k)) over k >= 1: the speed one lobe of second
    differences ending at c adds (units of the jerk bound)."""
    K = math.ceil(c) - 1
    if K < 1:
        return 0.0
    k1 = min(math.floor(min(a, 0.5 * c)), K)  # rising part: e_k = k
    k2 = max(math.floor(max(c - a, 0.5 * c)) + 1, k1 + 1)  # falling part from k2: e_k = c - k
    s = 0.5 * k1 * (k1 + 1)
    if k2 - 1 > k1:
        s += (min(k2 - 1, K) - k1) * a  # plateau at the acceleration bound
    if k2 <= K:
        s += (K - k2 + 1) * c - 0.5 * (K * (K + 1) - (k2 - 1) * k2)
    return s


@njit(cache=True)
def lobe_end(v, a, c_max):
    """The largest c <= ``c_max`` with ``lobe_sum(c, a) <= v``."""
    if lobe_sum(c_max, a) <= v:
        return c_max
    lo, hi = 0.0, c_max
    for _ in range(_LOBE_BISECTIONS):
        mid = 0.5 * (lo + hi)
        if lobe_sum(mid, a) <= v:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True)
def _up(k, a, c, center):
    """The up lobe's second difference at period k (0 from the middle on)."""
    if k >= center:
        return 0.0
    return max(0.0, min(min(float(k), a), c - k))


@njit(cache=True)
def speeds(n, a, v, out):
    """The first differences d_1..d_n of the n-period profile that goes furthest (module
    docstring) into ``out[:n]``; returns their sum D(n)."""
    center = 0.5 * (n + 2)
    c = lobe_end(v, a, center)
    d = 0.0
    total = 0.0
    for k in range(1, n + 1):
        d += _up(k, a, c, center) - _up(n + 2 - k, a, c, center)
        out[k - 1] = d
        total += d
    return total


@njit(cache=True)
def min_periods(length, a, v, max_n, scratch):
    """The smallest N <= ``max_n`` with D(N) >= ``length`` (units of the jerk bound), or -1."""
    hi = 4
    while speeds(min(hi, max_n), a, v, scratch) < length:
        if hi >= max_n:
            return -1
        hi *= 2
    hi = min(hi, max_n)
    lo = hi // 2  # D(lo) < length (or lo = 2: the loop above starts at 4)
    if lo < 1:
        lo = 1
    if speeds(lo, a, v, scratch) >= length:
        return lo
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if speeds(mid, a, v, scratch) >= length:
            hi = mid
        else:
            lo = mid
    return hi


@njit(cache=True)
def _straight(coef, a, b, p0, dq, dist, tol):
    """Do segments a:b of a path lie within ``tol`` of the line p0 + σ dq (|dq| = dist)?
    Each coefficient row, scaled by the segment's parameter length to a position, is
    measured across the line."""
    n = coef.shape[2]
    for k in range(a, b):
        for i in range(6):
            dot = 0.0
            for ax in range(n):
                r = coef[k, i, ax] - (p0[ax] if i == 0 else 0.0)
                dot += r * dq[ax]
            across = 0.0
            for ax in range(n):
                r = coef[k, i, ax] - (p0[ax] if i == 0 else 0.0)
                r -= dot / (dist * dist) * dq[ax]
                across += r * r
            if math.sqrt(across) > tol:
                return False
    return True


@njit(cache=True)
def _scaled_rows(coef, breaks, a, b, p):
    """coef rows of segments a:b of path p scaled by powers of their parameter length, in
    place (the position each row contributes at the segment's end)."""
    for k in range(a, b):
        h = breaks[k + p + 1] - breaks[k + p]
        f = 1.0
        for i in range(1, 6):
            f *= h
            for ax in range(coef.shape[2]):
                coef[k, i, ax] *= f


@njit(cache=True)
def _end_point(coef, breaks, k, p, out):
    """The end of segment k of path p, by ``Path.end``'s Horner arithmetic."""
    t = breaks[k + p + 1] - breaks[k + p]
    for ax in range(coef.shape[2]):
        acc = coef[k, 5, ax] * 1.0
        for i in range(4, -1, -1):
            acc = acc * t + coef[k, i, ax] * 1.0
        out[ax] = acc


@njit(cache=True)
def _sigma_limits(q0, q1, L, feed, lim, dt, shrink, ulps):
    """(vq, aq, jq): the bounds on σ's first, second and third differences (module
    docstring), each axis's limits shrunk for rounding; a bound <= 0 where rounding eats
    a limit."""
    vq = feed * dt / L if feed < 1e300 else np.inf
    aq = np.inf
    jq = np.inf
    for ax in range(q0.shape[0]):
        dq = abs(q1[ax] - q0[ax])
        if dq == 0.0:
            continue
        r = ulps * np.spacing(max(abs(q0[ax]), abs(q1[ax])))
        vq = min(vq, (lim[0, ax] * dt * (1.0 - shrink) - r) / dq)
        aq = min(aq, (lim[1, ax] * dt * dt * (1.0 - shrink) - r) / dq)
        jq = min(jq, (lim[2, ax] * dt * dt * dt * (1.0 - shrink) - r) / dq)
    return vq, aq, jq


@njit(cache=True)
def _holds(q, lim, dt):
    """Do samples ``q`` (K, n), held before and after, keep every limit under verify's
    float operations (repeated differences, each divided by dt^m)?"""
    K, n = q.shape
    scale = (dt, dt * dt, dt * dt * dt)
    x = np.empty(K + 6)
    for ax in range(n):
        for i in range(3):
            x[i] = q[0, ax]
            x[K + 3 + i] = q[K - 1, ax]
        x[3 : K + 3] = q[:, ax]
        m = K + 6
        for order in range(3):
            m -= 1
            for i in range(m):
                x[i] = x[i + 1] - x[i]
            for i in range(m):
                if abs(x[i]) / scale[order] > lim[order, ax]:
                    return False
    return True


@njit(cache=True)
def plan_lines(coef, breaks, lengths, feed, seg_off, lim, dt, settings):
    """The exact plan of each straight path of the paths (concatenated as
    ``joint_table.concat_paths`` gives them; ``coef`` is scaled in place, a copy is the
    caller's).

    ``lim`` (3, n): vmax, amax, jmax; ``settings``: (straightness tolerance in position
    units, relative shrink, rounding ulps, most periods of one plan). Returns ``done``
    (P,) bool, ``off`` (P + 1,) sample offsets, ``s`` (Σ K,) arc lengths and ``q``
    (Σ K, n) samples: path i's plan is rows off[i]:off[i+1] where done[i]."""
    tol, shrink, ulps, max_n = settings[0], settings[1], settings[2], int(settings[3])
    n_p = seg_off.shape[0] - 1
    n = coef.shape[2]
    done = np.zeros(n_p, dtype=np.bool_)
    periods = np.zeros(n_p, dtype=np.int64)
    q0 = np.empty((n_p, n))
    q1 = np.empty((n_p, n))
    ends = np.empty(n)
    prof = np.empty((n_p, 3))  # a, v and the scale 1 / (jq D(N)) of each plan
    scratch = np.empty(max_n)
    for p in range(n_p):
        a, b = seg_off[p], seg_off[p + 1]
        same_feed = True
        for k in range(a + 1, b):
            if feed[k] != feed[a]:
                same_feed = False
        if not same_feed or not (lengths[p] > 0.0):
            continue
        _end_point(coef, breaks, b - 1, p, ends)
        dist = 0.0
        for ax in range(n):
            q0[p, ax] = coef[a, 0, ax]
            q1[p, ax] = ends[ax]
            dist += (ends[ax] - coef[a, 0, ax]) ** 2
        dist = math.sqrt(dist)
        if not dist > 0.0:
            continue
        _scaled_rows(coef, breaks, a, b, p)
        if not _straight(coef, a, b, q0[p], q1[p] - q0[p], dist, tol):
            continue
        vq, aq, jq = _sigma_limits(q0[p], q1[p], lengths[p], feed[a], lim, dt, shrink, ulps)
        if not (vq > 0.0 and aq > 0.0 and jq > 0.0) or not np.isfinite(jq):
            continue
        nn = min_periods(1.0 / jq, aq / jq, vq / jq, max_n, scratch)
        if nn < 0:
            continue
        periods[p] = nn
        prof[p, 0] = aq / jq
        prof[p, 1] = vq / jq
        done[p] = True
    off = np.zeros(n_p + 1, dtype=np.int64)
    for p in range(n_p):
        off[p + 1] = off[p] + (periods[p] + 1 if done[p] else 0)
    s = np.empty(off[n_p])
    q = np.empty((off[n_p], n))
    for p in range(n_p):
        if not done[p]:
            continue
        nn = periods[p]
        o = off[p]
        total = speeds(nn, prof[p, 0], prof[p, 1], scratch)
        # σ_k = (d_1 + ... + d_k) / D(N): the profile scaled to end exactly at σ = 1
        acc = 0.0
        s[o] = 0.0
        q[o, :] = q0[p]
        for k in range(1, nn):
            acc += scratch[k - 1]
            sig = acc / total
            s[o + k] = sig * lengths[p]
            for ax in range(n):
                q[o + k, ax] = q0[p, ax] + sig * (q1[p, ax] - q0[p, ax])
        s[o + nn] = lengths[p]
        q[o + nn, :] = q1[p]
        if not _holds(q[o : o + nn + 1], lim, dt):
            done[p] = False
    return done, off, s, q

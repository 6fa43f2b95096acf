"""The exact sampler of the optimal planner (numba): follow a reference time law.

Each sample k takes the position the reference reaches one period after the
position of sample k-1 (the reference clock follows the machine: a sample that had
to deviate does not make the next ones chase the old clock) and checks it with
exactly the float operations of ``verify`` (``vpop.step._feasible``). Where the
reference would break a limit — it is the solution of a linear program imposed at
collocation points, and sampled — the nearest allowed position is taken instead
(``vpop.step._search`` on the per-axis intervals). An empty allowed set is reported
to the caller (``STUCK``), which lands the plan at the end or hands the path to VPOp.

Reference nodes (s, t, v, a) come from ``optimal.sampling.TimeLaw.nodes``; between nodes s(t) is the
quintic Hermite interpolant of (s, v, a).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from .vpop.step import Scratch, _bounds, _eval, _feasible, _search, _seed

# track's statuses (one set for every kernel: ``status``): OK, NEED_REF (the reference
# ends before the next target), STUCK (no position satisfies every limit: the caller
# lands the plan or hands it to VPOp), NEED_SPACE
from .status import NEED_REF, NEED_SPACE, OK, STUCK

#: the reference time law's nodes: s (mm), t (s), v (mm/s), a (mm/s²), each (>= n,), of
#: which the first n are used
Reference = namedtuple("Reference", "s t v a n")


@njit(cache=True)
def _herm(s0, v0, a0, s1, v1, a1, h, tau):
    """Quintic Hermite s(tau) on [0, h] with value, slope and curvature at both ends."""
    x = tau / h
    d0 = s1 - (s0 + h * (v0 + h * 0.5 * a0))
    d1 = h * (v1 - (v0 + h * a0))
    d2 = h * h * (a1 - a0)
    c3 = 10.0 * d0 - 4.0 * d1 + 0.5 * d2
    c4 = -15.0 * d0 + 7.0 * d1 - d2
    c5 = 6.0 * d0 - 3.0 * d1 + 0.5 * d2
    return s0 + h * x * (v0 + h * x * 0.5 * a0) + x * x * x * (c3 + x * (c4 + x * c5))


@njit(cache=True)
def _herm_v(s0, v0, a0, s1, v1, a1, h, tau):
    x = tau / h
    d0 = s1 - (s0 + h * (v0 + h * 0.5 * a0))
    d1 = h * (v1 - (v0 + h * a0))
    d2 = h * h * (a1 - a0)
    c3 = 10.0 * d0 - 4.0 * d1 + 0.5 * d2
    c4 = -15.0 * d0 + 7.0 * d1 - d2
    c5 = 6.0 * d0 - 3.0 * d1 + 0.5 * d2
    return v0 + h * x * a0 + x * x * (3.0 * c3 + x * (4.0 * c4 + x * 5.0 * c5)) / h


@njit(cache=True)
def _bracket(grid, n, x, hint):
    """The node interval i (0 <= i <= n-2) of x in the increasing grid (n,), searched
    from ``hint`` (the previous call's interval: the reference is walked in order)."""
    i = hint
    if i < 0:
        i = 0
    if i > n - 2:
        i = n - 2
    while i > 0 and x < grid[i]:
        i -= 1
    while i < n - 2 and x >= grid[i + 1]:
        i += 1
    return i


@njit(cache=True)
def ref_s_of_t(ns, nt, nv, na, n, t, hint):
    """s at time t (clipped to the nodes' range); returns (s, node hint)."""
    if t <= nt[0]:
        return ns[0], 0
    if t >= nt[n - 1]:
        return ns[n - 1], n - 2
    i = _bracket(nt, n, t, hint)
    h = nt[i + 1] - nt[i]
    if not h > 0.0:
        return ns[i + 1], i
    return _herm(ns[i], nv[i], na[i], ns[i + 1], nv[i + 1], na[i + 1], h, t - nt[i]), i


@njit(cache=True)
def ref_t_of_s(ns, nt, nv, na, n, s, hint):
    """The time the reference reaches s (Newton in the bracketing node interval)."""
    if s <= ns[0]:
        return nt[0], 0
    if s >= ns[n - 1]:
        return nt[n - 1], n - 2
    i = _bracket(ns, n, s, hint)
    h = nt[i + 1] - nt[i]
    if not h > 0.0:
        return nt[i], i
    lo = 0.0
    hi = h
    # start from the linear guess, keep a bracket
    span = ns[i + 1] - ns[i]
    tau = h * (s - ns[i]) / span if span > 0.0 else 0.0
    for _ in range(60):
        f = _herm(ns[i], nv[i], na[i], ns[i + 1], nv[i + 1], na[i + 1], h, tau) - s
        if f > 0.0:
            hi = tau
        else:
            lo = tau
        if hi - lo <= 1e-15 * h:
            break
        d = _herm_v(ns[i], nv[i], na[i], ns[i + 1], nv[i + 1], na[i + 1], h, tau)
        nxt = tau - f / d if d > 0.0 else 0.5 * (lo + hi)
        if not (nxt > lo and nxt < hi):
            nxt = 0.5 * (lo + hi)
        if nxt == tau:
            break
        tau = nxt
    return nt[i] + tau, i


@njit(cache=True)
def _feed_cap(s, fd, seg):
    """s + F dt with F the lowest feed of the segments from s on within reach (the
    ``vpop.step.Feed`` fd)."""
    dt = fd.dt
    L = fd.L
    FB = fd.FB
    FV = fd.FV
    m = FB.shape[0] - 1
    p = seg
    while p < m - 1 and s >= FB[p + 1]:
        p += 1
    f = FV[p]
    c = s + f * dt
    q = p
    while q < m - 1 and c > FB[q + 1]:
        q += 1
        if FV[q] < f:
            f = FV[q]
            c = s + f * dt
    if c > L:
        c = L
    return c, p


@njit(cache=True, nogil=True)
def track(ref, ref_final, T, lim, fd, sh, qh, k, tol, stats):
    """Samples k, k+1, ... following the ``Reference`` ref until it runs out, the path
    ends at rest, or no position is allowed, on the joint table T (``vpop.step.Table``)
    under the ``vpop.step.Limits`` lim and the ``vpop.step.Feed`` fd; ``tol`` is the
    searches' tolerance in s.

    ``ref_final``: the reference is final (the path's own end) — else a target past the
    last node's time asks for more (``NEED_REF``). ``sh``/``qh`` hold samples < k (rest
    before sample 0 is implied). Returns (status, k). stats: [clamped samples, steps].
    """
    ns = ref.s
    nt = ref.t
    nv = ref.v
    na = ref.a
    n_nodes = ref.n
    dt = fd.dt
    L = fd.L
    n = qh.shape[1]
    q = np.empty(n)
    qs = np.empty(n)
    lo = np.empty(n)
    hi = np.empty(n)
    wk = np.empty((3, n))
    sc = Scratch(q, qs, lo, hi, wk)
    hint = 0
    rh = 0
    # the feed segment of the first sample by bisection (``_feed_cap`` walks on from it;
    # from segment 0 it walked every segment before on each call)
    m_fb = fd.FB.shape[0] - 1
    seg = min(max(np.searchsorted(fd.FB, sh[k - 1], side="right") - 1, 0), max(m_fb - 1, 0))
    cap = sh.shape[0]
    t_last = nt[n_nodes - 1]
    while True:
        if k >= 3 and sh[k - 1] == L and sh[k - 2] == L and sh[k - 3] == L:
            return OK, k
        if k >= cap:
            return NEED_SPACE, k
        s0 = sh[k - 1]
        tc, rh = ref_t_of_s(ns, nt, nv, na, n_nodes, s0, rh)
        tn = tc + dt
        if tn > t_last and not ref_final:
            return NEED_REF, k
        x, rh = ref_s_of_t(ns, nt, nv, na, n_nodes, tn, rh)
        b, seg = _feed_cap(s0, fd, seg)
        if x > b:
            x = b
        if x < s0:
            x = s0
        stats[1] += 1
        hint = _eval(T, x, hint, q, qs)
        if not _feasible(qh, k, q, lim):
            stats[0] += 1
            if not _bounds(qh, k, lim, lo, hi):
                return STUCK, k
            # below the target first (the reference asked for too much), else above it
            ok, xm, hint = _search(T, lim, qh, k, sc, s0, x, np.bool_(True), hint, tol, _seed(x), np.bool_(True))
            if not ok:
                ok, xm, hint = _search(T, lim, qh, k, sc, x, b, np.bool_(False), hint, tol, _seed(x), np.bool_(False))
                if not ok:
                    return STUCK, k
            x = xm
            hint = _eval(T, x, hint, q, qs)
        sh[k] = x
        for i in range(n):
            qh[k, i] = q[i]
        k += 1

"""VPOp's sequential step loop, compiled with numba (imported lazily by ``vpop``).

Everything here works in *step units*: a position difference per sample. For axis i
with limits V, A, J and period dt the planner is given ``vl = V dt``, ``al = A dt²``
and ``jl = J dt³`` (already shrunk by ``VPOP_LIMIT_SHRINK``), and checks exactly the
float operations ``verify`` performs on the emitted setpoints::

    e  = q_new - q_prev        |e|  <= vl     (velocity)
    a  = e - d1                |a|  <= al     (acceleration, d1 = previous e)
    jk = a - d2                |jk| <= jl     (jerk, d2 = previous a)

The path is a table of quintic pieces in arc length s (``S`` knots, ``C`` power
coefficients in s - S[p], shaped (m, n, 6)); ``q(L)`` is returned as the exact end
point ``QEND``.

The policies:
* max: the largest s' in [s, s_cap] whose joint positions satisfy every limit
  (s_cap = min(L, s + F dt) with F the lowest feed of the segments crossed);
* brake (the "minimum" of the paper, made jerk-aware): the value of the allowed
  interval closest to the no-reversal bound (after which a jerk ramp back to zero
  path acceleration still leaves ṡ >= 0), or s itself once ṡ is below one jerk step.
  A brake run succeeds when it reaches rest (three equal samples) without an empty set.
* aim: near the end, the largest step whose continuous jerk-limited stop distance
  still fits before L (used to land exactly on the end point at rest).
When the max step's set is empty, a dichotomy finds the latest step j from which
the brake run succeeds; step j is fixed at its brake value and max resumes at j+1.
Two details keep "a stop is always recoverable" true in floating point:
* the max step reports an empty set only when the brake policy finds no sample either
  (its linearised search can miss a narrow set near a sharp turn; the brake value then
  seeds it), so the dichotomy's "braking from k fails" is never a search artefact;
* at rest, the brake value is "stay"; when the max step's continuation cannot stop
  either (a path shorter than a step from rest and the stop after it), fixing the
  brake value would repeat the same state for ever, so ``_rest_value`` bisects for
  the largest step in between whose brake run reaches rest.

Speed-ups (none changes what a committed sample must satisfy; every sample is
checked exactly):
* chain mode: right after a brake fix, the next max step is tested at once with one
  brake run (the test the dichotomy would run first) instead of re-running max steps
  up to the next failure;
* end game: when the max run fails against the end point, an aim run from the
  switch step that stops within ``gap_tol`` of L is committed whole;
* fast mode (default): a brake run may end early once the state is "easy"
  (``_easy``) or has outlived the failed max run (``_horizon``). These are
  heuristics; the step just after a fix is re-certified when its certificate runs
  out, and if a heuristic ever misleads (empty set with nothing left to back up to)
  the caller re-plans the path in exact mode (brake runs to rest).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from ...fit._quintic import quintic

# plan_core's statuses (one set for every kernel: ``status``)
from ..status import INFEASIBLE, NEED_SPACE, OK, STUCK, YIELD

_HUGE = 1e300
# "clearly outside the bounds" for a zero step: far above the rounding of _bounds
_STAY_MARGIN = 1e-6
_BIG = 1 << 62

#: numba options of every kernel here but ``plan_core``: no reference counting
#: (``_nrt=False``, numba's own option for its string and sort helpers). With it, each
#: call of a kernel increments and decrements, atomically, the count of every array it is
#: passed (bundles included) and of every view it takes: NRT_incref/NRT_decref were 35 %
#: of the planning CPU on stellabee1 (perf; 52.9 -> 35.0 CPU-s without them, identical
#: samples). Running without the count is sound because these kernels allocate nothing
#: (numba refuses to compile an allocation without it) and return no array: every array
#: they see is owned by ``plan_core`` or its caller for the whole call.
_PER_STEP = {"cache": True, "_nrt": False}
# The small kernels of the inner loops are inlined (``inline="always"``): ``_bounds``,
# ``_feasible``, ``_lin_interval``, ``_easy``, and ``_eval`` within ``_search`` (as
# ``_eval_at``). A call passes each array of its bundles field by field (data, shape,
# strides...: ~40 machine words for ``_eval``, ~100 for ``_search``); inlining these took
# stellabee1's first 3000 paths from 10.7 to 7.5 planning CPU-s, for ~5 CPU-s more
# compiling on a cold cache. ``_eval`` inlined everywhere saved ~4 % more for ~12 CPU-s.

# The kernels' arguments, bundled by concept (module level, so that numba's cache can
# name their types). Step units throughout: see the module docstring. A kernel called per
# step takes only the bundles it reads, not the whole ``Problem``.
#: the joint table: knots S (m+1,) in arc length, power coefficients C (m, n, 6) in
#: s - S[p] (each axis's six contiguous), the exact end point QEND (n,)
Table = namedtuple("Table", "S C QEND")
#: per-axis limits (n,) in step units: vl = V dt, al = A dt², jl = J dt³
Limits = namedtuple("Limits", "vl al jl")
#: the path's feed: period dt (s), length L, segment breaks FB (segments + 1,) in s with
#: FB[-1] = L, and each segment's feed FV (segments,) in s per second
Feed = namedtuple("Feed", "dt L FB FV")
#: packed range-max tables (``range_max_table``) of the curvature and speed bounds per
#: table piece that ``_easy`` reads: K2, K3, K23 (acceleration, jerk, cross term), KV
Ease = namedtuple("Ease", "K2 K3 K23 KV")
#: one path's planning problem: ``Table``, ``Limits``, the brake policy's jerk js (n,)
#: (jl * VPOP_BRAKE_JERK_FRACTION), ``Feed``, ``Ease``
Problem = namedtuple("Problem", "table lim js feed ease")
#: per-step scratch: q, qs (position and dq/ds), lo, hi (allowed step bounds), all (n,),
#: and wk (3, n) (see ``_step``)
Scratch = namedtuple("Scratch", "q qs lo hi wk")
#: the brake runs' buffers: scratch run bs (R,), bq (R, n), the last fix's certificate
#: cs (R,), cq (R, n), and the counters ``stats`` (5,) int64 (see ``plan_core``)
Runs = namedtuple("Runs", "bs bq cs cq stats")
#: a ``plan_core`` call's settings: search tolerance ``tol`` (s units), ``max_steps``
#: (global samples), ``easy_frac``, ``gap_tol``, ``fast``, ``chain_seq``, ``floor_h``
#: (see ``plan_core``)
Settings = namedtuple("Settings", "tol max_steps easy_frac gap_tol fast chain_seq floor_h")
#: ``_search``'s start: the guess x, and whether the caller already found it infeasible
#: (``bad``), with its linearised interval [L, H]
Seed = namedtuple("Seed", "x bad L H")


@njit(**_PER_STEP)
def _seed(x):
    """A guess not yet evaluated."""
    return Seed(x, np.bool_(False), np.float64(0.0), np.float64(0.0))


@njit(**_PER_STEP)
def _piece(S, x, hint):
    """Index p with S[p] <= x < S[p+1] (clipped), searching from ``hint``."""
    m = S.shape[0] - 1
    p = hint
    if p < 0:
        p = 0
    if p > m - 1:
        p = m - 1
    # the next sample is almost always in the same piece or the next one
    for _ in range(2):
        if x < S[p]:
            if p == 0:
                return 0
            p -= 1
        elif p < m - 1 and x >= S[p + 1]:
            p += 1
        else:
            return p
    lo = 0
    hi = m - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if S[mid] <= x:
            lo = mid
        else:
            hi = mid - 1
    return lo


@njit(**_PER_STEP)
def _eval(T, x, hint, q, qs):
    """q(x) and dq/ds(x) of the ``Table`` T into ``q``, ``qs``; returns the piece index
    (new hint). ``C`` is (m, n, 6): each axis's six coefficients are contiguous (one
    cache line)."""
    return _eval_at(T, x, hint, q, qs)


@njit(inline="always", **_PER_STEP)
def _eval_at(T, x, hint, q, qs):
    """``_eval`` inlined where it is called (``_search``'s iterations)."""
    S = T.S
    C = T.C
    QEND = T.QEND
    m = S.shape[0] - 1
    n = q.shape[0]
    p = _piece(S, x, hint)
    if x >= S[m]:
        t = S[m] - S[p]
        for i in range(n):
            c = C[p, i]
            q[i] = QEND[i]
            qs[i] = quintic(c[0], c[1], c[2], c[3], c[4], c[5], t)[1]
        return p
    t = x - S[p]
    for i in range(n):
        c = C[p, i]
        q[i], qs[i], _ = quintic(c[0], c[1], c[2], c[3], c[4], c[5], t)
    return p


@njit(inline="always", **_PER_STEP)
def _bounds(qh, k, lim, lo, hi):
    """Allowed interval [lo, hi] of e = q_new - q[k-1] per axis under the ``Limits`` lim;
    False if one is empty.

    ``qh`` holds samples 0..k-1; samples before 0 are the rest position q[0].
    """
    vl = lim.vl
    al = lim.al
    jl = lim.jl
    n = qh.shape[1]
    ok = True
    for i in range(n):
        q1 = qh[k - 1, i]
        q2 = qh[k - 2, i] if k >= 2 else qh[0, i]
        q3 = qh[k - 3, i] if k >= 3 else qh[0, i]
        d1 = q1 - q2
        d2 = d1 - (q2 - q3)
        l = -vl[i]
        h = vl[i]
        if d1 - al[i] > l:
            l = d1 - al[i]
        if d1 + al[i] < h:
            h = d1 + al[i]
        if d1 + d2 - jl[i] > l:
            l = d1 + d2 - jl[i]
        if d1 + d2 + jl[i] < h:
            h = d1 + d2 + jl[i]
        lo[i] = l
        hi[i] = h
        if l > h:
            ok = False
    return ok


@njit(inline="always", **_PER_STEP)
def _feasible(qh, k, q, lim):
    """Exact check, in verify's own float operations, of q as sample k (``Limits`` lim)."""
    vl = lim.vl
    al = lim.al
    jl = lim.jl
    n = q.shape[0]
    for i in range(n):
        q1 = qh[k - 1, i]
        q2 = qh[k - 2, i] if k >= 2 else qh[0, i]
        q3 = qh[k - 3, i] if k >= 3 else qh[0, i]
        e = q[i] - q1
        d1 = q1 - q2
        d2 = d1 - (q2 - q3)
        a = e - d1
        jk = a - d2
        if abs(e) > vl[i] or abs(a) > al[i] or abs(jk) > jl[i]:
            return False
    return True


@njit(inline="always", **_PER_STEP)
def _lin_interval(q, qs, qprev, lo, hi, x, a, b):
    """Linearised allowed s-interval around x, intersected with [a, b]: (lo_s, hi_s)."""
    n = q.shape[0]
    L = a
    H = b
    for i in range(n):
        e = q[i] - qprev[i]
        g = qs[i]
        if g > 1e-14:
            l = x + (lo[i] - e) / g
            h = x + (hi[i] - e) / g
        elif g < -1e-14:
            l = x + (hi[i] - e) / g
            h = x + (lo[i] - e) / g
        else:
            if e < lo[i] or e > hi[i]:
                # a stationary axis outside its window: only the exact check can tell
                continue
            continue
        if l > L:
            L = l
        if h < H:
            H = h
    return L, H


@njit(**_PER_STEP)
def _search(T, lim, qh, k, sc, a, b, want_max, hint, tol, seed, a_is_prev):
    """Largest (want_max) or smallest feasible s' in [a, b] of the allowed set's component
    found by linearisation, from the ``Seed`` seed. Returns (found, s', hint); ``sc.q``
    holds q(s') when found; ``sc.lo``/``sc.hi`` are ``_bounds``'s.

    Newton on the linearised per-axis intervals (q and dq/ds come with every evaluation,
    so each iteration costs one table evaluation), kept inside a bracket [f, u] of a
    feasible f and an infeasible u; stops when the bracket or the Newton step is below tol.
    ``seed.bad``: the caller has just found ``seed.x`` (inside [a, b]) infeasible and passes
    its linearised interval (seed.L, seed.H), which saves evaluating it again. On success
    q, qs hold q(s') and dq/ds(s'). ``wk`` (>= 2, n) is scratch. ``a_is_prev``: a is
    sample k-1's own s, where every axis's step e is exactly 0, so the bounds alone can
    rule it out (only when clearly outside them; at the margin it is evaluated).
    """
    q = sc.q
    qs = sc.qs
    lo = sc.lo
    hi = sc.hi
    wk = sc.wk
    jl = lim.jl
    n = q.shape[0]
    qprev = qh[k - 1]
    ends = b if want_max else a
    check_end = True
    if a_is_prev and not want_max:
        for i in range(n):
            if lo[i] > _STAY_MARGIN * jl[i] or hi[i] < -_STAY_MARGIN * jl[i]:
                check_end = False  # standing still is outside the allowed set
                break
    if check_end:
        hint = _eval_at(T, ends, hint, q, qs)
        if _feasible(qh, k, q, lim):
            return True, ends, hint
    # 1. a feasible point: the guess, then the middle of the linearised allowed interval
    x = seed.x
    if x < a:
        x = a
    if x > b:
        x = b
    f = 0.0
    have_f = False
    for it in range(10):
        if it == 0 and seed.bad:
            L, H = seed.L, seed.H
        else:
            hint = _eval_at(T, x, hint, q, qs)
            if _feasible(qh, k, q, lim):
                f = x
                have_f = True
                break
            L, H = _lin_interval(q, qs, qprev, lo, hi, x, a, b)
        xn = 0.5 * (L + H)
        if xn < a:
            xn = a
        if xn > b:
            xn = b
        if xn == x:
            break
        x = xn
    if not have_f:
        return False, a, hint
    qf = wk[0]
    qsf = wk[1]
    for i in range(n):
        qf[i] = q[i]
        qsf[i] = qs[i]
    u = ends  # known infeasible
    # 2. Newton towards the wanted end of the interval
    for _ in range(40):
        L, H = _lin_interval(q, qs, qprev, lo, hi, x, a, b)
        xn = H if want_max else L
        # From the infeasible end a violation at rounding level gives a Newton step of an
        # ulp or so, which would creep for ever: step at least tol into the bracket.
        if want_max:
            if x == f and xn <= f + tol:
                break
            if xn > u - tol:
                xn = u - tol
            if not (xn > f and xn < u):
                xn = 0.5 * (f + u)
        else:
            if x == f and xn >= f - tol:
                break
            if xn < u + tol:
                xn = u + tol
            if not (xn < f and xn > u):
                xn = 0.5 * (f + u)
        x = xn
        hint = _eval_at(T, x, hint, q, qs)
        if _feasible(qh, k, q, lim):
            f = x
            for i in range(n):
                qf[i] = q[i]
                qsf[i] = qs[i]
        else:
            u = x
        if abs(u - f) <= tol:
            break
    for i in range(n):
        q[i] = qf[i]
        qs[i] = qsf[i]
    return True, f, hint


@njit(**_PER_STEP)
def _cap(s, fd):
    """Largest s' allowed by the ``Feed`` fd: s' - s <= min(F over segments crossed) dt,
    s' <= L."""
    dt = fd.dt
    L = fd.L
    FB = fd.FB
    FV = fd.FV
    m = FB.shape[0] - 1
    p = 0
    lo = 0
    hi = m - 1
    while lo < hi:  # segment containing s
        mid = (lo + hi + 1) // 2
        if FB[mid] <= s:
            lo = mid
        else:
            hi = mid - 1
    p = lo
    f = FV[p]
    c = s + f * dt
    while p < m - 1 and c > FB[p + 1]:
        p += 1
        if FV[p] < f:
            f = FV[p]
            c = s + f * dt
    if c > L:
        c = L
    if c < s:
        c = s
    return c


@njit(**_PER_STEP)
def _path_limits(qs, js_lim, al):
    """One-step path jerk and acceleration (s units) the tightest axis allows at q_s = qs."""
    jd = _HUGE
    ad = _HUGE
    for i in range(qs.shape[0]):
        g = abs(qs[i])
        if g > 1e-14:
            v = js_lim[i] / g
            if v < jd:
                jd = v
            v = al[i] / g
            if v < ad:
                ad = v
    return jd, ad


@njit(**_PER_STEP)
def _stop_distance(v, a, J, A):
    """Distance of the time-optimal jerk-limited stop from speed v, acceleration a (continuous,
    step units); -1 when the state already brakes too hard to stop without reversing."""
    if a < 0.0 and v < a * a / (2.0 * J):
        return -1.0
    ap = np.sqrt(J * v + 0.5 * a * a)
    t2 = 0.0
    if ap > A:
        ap = A
        t2 = (v + a * a / (2.0 * J) - A * A / J) / A
        if t2 < 0.0:
            t2 = 0.0
    t1 = (a + ap) / J
    d = v * t1 + a * t1 * t1 / 2.0 - J * t1**3 / 6.0
    v1 = v + a * t1 - J * t1 * t1 / 2.0
    d += v1 * t2 - ap * t2 * t2 / 2.0
    v2 = v1 - ap * t2
    t3 = ap / J
    d += v2 * t3 - ap * t3 * t3 / 2.0 + J * t3**3 / 6.0
    return d


# inlined into its two callers (_brake_step and _step's fallback): 15-20% off a brake
# run; inlining _search or _step too adds minutes of compile time for a few per cent
@njit(inline="always", **_PER_STEP)
def _brake_value(T, lim, js, fd, sh, qh, k, sc, hint, tol, qs0_known):
    """The brake policy's sample k (see ``_step``) on the joint table T under ``Limits``
    lim, brake jerk js and ``Feed`` fd, given the bounds ``sc.lo``/``sc.hi`` of
    ``_bounds``. Returns (ok, s', hint); q, qs hold q(s'), dq/ds(s'). With
    ``qs0_known`` wk[2] already holds dq/ds(s0) (a brake run carries it from the step
    before)."""
    s0, d1, d2 = _path_state(sh, k)
    b = _cap(s0, fd)
    guess = s0 + d1 + d2
    q = sc.q
    qs = sc.qs
    if qs0_known:
        jd, ad = _path_limits(sc.wk[2], js, lim.al)
    else:
        hint = _eval(T, s0, hint, q, qs)
        jd, ad = _path_limits(qs, js, lim.al)
    # the least step after which a jerk ramp back to zero path acceleration still
    # leaves a non-negative speed (or a full stop once the speed is one jerk step)
    if d1 <= jd:
        target = s0
    else:
        target = s0 + d1 + jd - np.sqrt(jd * (2.0 * d1 + jd))
    if target > b:
        target = b
    hint = _eval(T, target, hint, q, qs)
    if _feasible(qh, k, q, lim):
        return True, target, hint
    # which side of the allowed interval is the target on? (linearised at the target)
    L, H = _lin_interval(q, qs, qh[k - 1], sc.lo, sc.hi, target, s0, b)
    if target < L or L > H:
        okl, xl, hint = _search(
            T, lim, qh, k, sc, s0, b, np.bool_(False), hint, tol, Seed(target, np.bool_(True), L, H), np.bool_(True)
        )
        if okl and xl >= target:
            return True, xl, hint
        if not okl:
            return False, s0, hint
    oku, xu, hint = _search(
        T, lim, qh, k, sc, s0, b, np.bool_(True), hint, tol, Seed(target, np.bool_(True), L, H), np.bool_(False)
    )
    if not oku:
        return False, s0, hint
    if xu <= target:
        return True, xu, hint
    # the linear model misled: the target lies inside; fall back to the lower end
    okl, xl, hint = _search(T, lim, qh, k, sc, s0, b, np.bool_(False), hint, tol, _seed(guess), np.bool_(True))
    if not okl:
        return False, s0, hint
    if xl >= target:
        return True, xl, hint
    # (q must hold q(xu) again)
    hint = _eval(T, xu, hint, q, qs)
    return True, xu, hint


@njit(**_PER_STEP)
def _path_state(sh, k):
    """Position, step and step difference (s units) at sample k-1; rest before sample 0."""
    s0 = sh[k - 1]
    s1 = sh[k - 2] if k >= 2 else sh[0]
    s2 = sh[k - 3] if k >= 3 else sh[0]
    d1 = s0 - s1
    return s0, d1, d1 - (s1 - s2)


# inlined into the brake run's loop (its hot call) and into _step: 3-4% of a brake run
@njit(inline="always", **_PER_STEP)
def _brake_step(T, lim, js, fd, sh, qh, k, hint, sc, tol, qs0_known):
    """``_step`` in mode 1 (brake)."""
    if not _bounds(qh, k, lim, sc.lo, sc.hi):
        return False, sh[k - 1], hint
    return _brake_value(T, lim, js, fd, sh, qh, k, sc, hint, tol, qs0_known)


@njit(**_PER_STEP)
def _step(T, lim, js, fd, sh, qh, k, mode, hint, sc, tol, qs0_known):
    """Choose sample k on the joint table T under ``Limits`` lim, brake jerk js and
    ``Feed`` fd. mode 0: max; 1: brake; 2: aim at rest exactly at L.

    Returns (ok, s', hint); on success sc.q, sc.qs hold q(s'), dq/ds(s'). ``sc.wk``
    (3, n) is scratch; with ``qs0_known`` wk[2] holds dq/ds at sample k-1. Mode 0 fails
    only when the brake policy finds no sample k either, so "max failed at k" always
    means "braking from k fails" (what the dichotomy in ``plan_core`` relies on)."""
    if mode == 1:
        return _brake_step(T, lim, js, fd, sh, qh, k, hint, sc, tol, qs0_known)
    q = sc.q
    qs = sc.qs
    if not _bounds(qh, k, lim, sc.lo, sc.hi):
        return False, sh[k - 1], hint
    s0, d1, d2 = _path_state(sh, k)
    L = fd.L
    b = _cap(s0, fd)
    guess = s0 + d1 + d2
    if mode == 0:
        ok, x, hint = _search(T, lim, qh, k, sc, s0, b, np.bool_(True), hint, tol, _seed(guess), np.bool_(False))
        if ok:
            return ok, x, hint
        # the linearised search can miss a narrow allowed set (near a sharp turn the
        # joint positions are far from linear in s); the brake value is a feasible seed
        okb, xb, hint = _brake_value(T, lim, js, fd, sh, qh, k, sc, hint, tol, qs0_known)
        if not okb:
            return False, s0, hint
        return _search(T, lim, qh, k, sc, s0, b, np.bool_(True), hint, tol, _seed(xb), np.bool_(False))
    hint = _eval(T, s0, hint, q, qs)
    jd, ad = _path_limits(qs, lim.jl, lim.al)
    # aim: the largest step whose continuous stop distance still fits before L
    okl, xl, hint = _search(T, lim, qh, k, sc, s0, b, np.bool_(False), hint, tol, _seed(guess), np.bool_(False))
    if not okl:
        return False, s0, hint
    oku, xu, hint = _search(T, lim, qh, k, sc, s0, b, np.bool_(True), hint, tol, _seed(guess), np.bool_(False))
    x = xl
    if xu >= L and L - s0 <= jd:
        x = L  # close enough to land in one jerk step
    elif L - xu >= _stop_distance(xu - s0, xu - s0 - d1, jd, ad):
        x = xu
    elif L - xl >= _stop_distance(xl - s0, xl - s0 - d1, jd, ad):
        a_ = xl
        b_ = xu
        for _ in range(50):
            m_ = 0.5 * (a_ + b_)
            if L - m_ >= _stop_distance(m_ - s0, m_ - s0 - d1, jd, ad):
                a_ = m_
            else:
                b_ = m_
            if b_ - a_ <= tol:
                break
        x = a_
    hint = _eval(T, x, hint, q, qs)
    if _feasible(qh, k, q, lim):
        return True, x, hint
    hint = _eval(T, xl, hint, q, qs)
    return True, xl, hint


#: pieces per block of the range-max table: spans shorter than two blocks are scanned
_RM_BLOCK = 32
#: header of the packed range-max table: m, blocks, levels
_RM_HEAD = 3


@njit(**_PER_STEP)
def _window_max(T, p0, p1):
    """Largest value over the table pieces p0..p1 of ``range_max_table``'s packed table:
    short spans (the usual case: a brake distance) are scanned, long ones read the
    sparse table of block maxima for the whole blocks inside."""
    B = _RM_BLOCK
    if p1 - p0 < 2 * B:
        best = T[_RM_HEAD + p0]
        for p in range(p0 + 1, p1 + 1):
            v = T[_RM_HEAD + p]
            if v > best:
                best = v
        return best
    m = int(T[0])
    nb = int(T[1])
    fb = (p0 + B - 1) // B  # first and last whole block inside [p0, p1]
    lb = (p1 + 1) // B - 1
    best = -np.inf
    for p in range(p0, fb * B):
        v = T[_RM_HEAD + p]
        if v > best:
            best = v
    for p in range((lb + 1) * B, p1 + 1):
        v = T[_RM_HEAD + p]
        if v > best:
            best = v
    span = lb - fb + 1
    lvl = 0
    while (2 << lvl) <= span:
        lvl += 1
    off = _RM_HEAD + m + lvl * nb
    a = T[off + fb]
    c = T[off + lb - (1 << lvl) + 1]
    if a > best:
        best = a
    if c > best:
        best = c
    return best


def range_max_table(K: np.ndarray) -> np.ndarray:
    """Packed range-max table of K (m,): [m, blocks, levels, K, sparse table of the block
    maxima (row l: max over 2**l blocks)], about 1.1 m values (a full sparse table of K
    would take m log2 m: gigabytes on a path of a million moves)."""
    K = np.asarray(K, dtype=float)
    m = K.shape[0]
    B = _RM_BLOCK
    nb = max(1, (m + B - 1) // B)
    pad = np.full(nb * B, -np.inf)
    pad[:m] = K
    bm = pad.reshape(nb, B).max(axis=1)
    levels = max(1, int(np.floor(np.log2(nb))) + 1)
    T = np.empty((levels, nb))
    T[0] = bm
    for lvl in range(1, levels):
        w = 1 << (lvl - 1)
        prev = T[lvl - 1]
        shifted = np.concatenate((prev[w:], np.full(w, -np.inf)))[:nb]
        T[lvl] = np.maximum(prev, shifted)
    return np.concatenate((np.array([m, nb, levels], dtype=float), K, T.ravel()))


@njit(inline="always", **_PER_STEP)
def _easy(S, K, js, al, L, bs, kk, easy_frac, qs0, hint):
    """Early end of a brake run (samples bs[:kk]): braking, slow
    enough that the path's curvature uses at most ``easy_frac`` of any axis's
    acceleration and jerk over the whole remaining stop, and the stop ends before L.
    (A heuristic; a plan it misleads is re-planned exactly.) S: the table's knots; K:
    the ``Ease`` tables; js, al: brake jerk and acceleration limits (n,)."""
    s0 = bs[kk - 1]
    d1 = s0 - bs[kk - 2]
    d2 = d1 - (bs[kk - 2] - bs[kk - 3])
    if d2 > 0.0 or d1 <= 0.0:
        return False
    p0 = _piece(S, s0, hint)
    jd, ad = _path_limits(qs0, js, al)
    # the ramp back to zero deceleration must not need a negative speed
    if d1 < 2.0 * d2 * d2 / jd:
        return False
    ab = 2.0 * ad
    D = d1 * (d1 / ad + 2.0 * ab / jd) + d1
    if s0 + 2.0 * D >= L:
        return False
    # the table pieces met by [s0, s0 + D] (found from the run's piece hint)
    p1 = _piece(S, s0 + D, p0)
    # speed limits ahead (axis velocities, segment feeds) must already be met: the
    # brake only slows down from here
    if _window_max(K.KV, p0, p1) * d1 > 1.0:
        return False
    k2 = _window_max(K.K2, p0, p1)
    if k2 * d1 * d1 > easy_frac:
        return False
    k3 = _window_max(K.K3, p0, p1)
    k23 = _window_max(K.K23, p0, p1)
    return k3 * d1**3 + k23 * d1 * ab <= easy_frac


@njit(**_PER_STEP)
def _brake_run(pb, sh, qh, j, runs, sc, cfg, mode, easy_frac, horizon):
    """Does the brake (mode 1) or aim (mode 2) policy from step j (samples < j fixed) reach
    rest? Uses the scratch run ``runs.bs``/``runs.bq``, which start with copies of samples
    j-3..j-1 at 0..2; ``easy_frac`` > 0 lets it end early (``_easy``).

    ``horizon`` > 0 (fast mode): a run that survives until main-sequence index ``horizon``
    and is no longer speeding up counts as a success. Returns (ok, scratch index after the
    last sample, main-sequence index up to which the brake continuation is certified
    (_BIG: to rest))."""
    T = pb.table
    lim = pb.lim
    js = pb.js
    fd = pb.feed
    K = pb.ease
    bs = runs.bs
    bq = runs.bq
    stats = runs.stats
    q = sc.q
    qs = sc.qs
    wk = sc.wk
    n = qh.shape[1]
    for r in range(3):
        src = j - 3 + r
        if src < 0:
            src = 0
        bs[r] = sh[src]
        for i in range(n):
            bq[r, i] = qh[src, i]
    hint = np.int64(0)
    kk = np.int64(3)
    cap = bs.shape[0]
    while True:
        if mode == 1:
            ok, x, hint = _brake_step(T, lim, js, fd, bs, bq, kk, hint, sc, cfg.tol, kk > 3)
        else:
            ok, x, hint = _step(T, lim, js, fd, bs, bq, kk, mode, hint, sc, cfg.tol, kk > 3)
        if not ok:
            return False, kk, 0
        bs[kk] = x
        stats[2] += 1
        for i in range(n):
            bq[kk, i] = q[i]
            wk[2, i] = qs[i]  # dq/ds at the new sample, for the next step and _easy
        kk += 1
        if bs[kk - 1] == bs[kk - 2] and bs[kk - 2] == bs[kk - 3]:
            return True, kk, _BIG
        if easy_frac > 0.0 and mode == 1 and _easy(T.S, K, js, lim.al, fd.L, bs, kk, easy_frac, wk[2], hint):
            return True, kk, _BIG
        if (
            horizon > 0
            and j + kk - 3 >= horizon
            and _easy(T.S, K, js, lim.al, fd.L, bs, kk, np.float64(0.6), wk[2], hint)
        ):
            return True, kk, j + kk - 3
        if kk >= cap or kk >= cfg.max_steps:
            return False, kk, 0


@njit(**_PER_STEP)
def _stays_at_rest(sh, j, x, L):
    """True when sample j = x would leave the machine at rest where it stood (three
    equal samples before j, x equal to them) short of the end: fixing that brake value
    again and again would loop for ever."""
    s0 = sh[j - 1]
    s1 = sh[j - 2] if j >= 2 else sh[0]
    s2 = sh[j - 3] if j >= 3 else sh[0]
    return x == s0 and s1 == s0 and s2 == s0 and s0 < L


@njit(**_PER_STEP)
def _rest_value(pb, sh, qh, j, runs, sc, cfg, hint):
    """Sample j when the machine is at rest before it, the brake policy would stay put
    and the max step's continuation cannot stop (e.g. a path shorter than what one
    step from rest and the stop after it allow): the largest value in (s0, max] found
    by bisection after which the brake run from j + 1 reaches rest.

    Staying put is always safe and a small enough step from rest always stops again,
    so a value > s0 exists; returns (ok, s', certified up to, hint) with q = q(s') and
    sh[j]/qh[j] set, or ok False when float resolution leaves none."""
    T = pb.table
    q = sc.q
    qs = sc.qs
    tol = cfg.tol
    n = qh.shape[1]
    s0 = sh[j - 1]
    ok, xm, hint = _step(pb.table, pb.lim, pb.js, pb.feed, sh, qh, j, np.int64(0), hint, sc, tol, np.bool_(False))
    if not ok or not xm > s0:
        return False, s0, 0, hint
    good = s0
    good_cert = 0
    bad = xm
    x = xm
    for _ in range(80):
        hint = _eval(T, x, hint, q, qs)
        if _feasible(qh, j, q, pb.lim):
            sh[j] = x
            for i in range(n):
                qh[j, i] = q[i]
            r = _brake_run(pb, sh, qh, j + 1, runs, sc, cfg, np.int64(1), cfg.easy_frac, np.int64(0))
            runs.stats[1] += 1
            passed = r[0]
        else:
            passed = False
        if passed:
            good = x
            good_cert = r[2]
        else:
            bad = x
        # a few per cent of the step is close enough to the largest value
        if good > s0 and bad - good <= 0.02 * (good - s0):
            break
        if bad - good <= tol:
            break
        x = 0.5 * (good + bad)
    if not good > s0:
        return False, s0, 0, hint
    hint = _eval(T, good, hint, q, qs)
    sh[j] = good
    for i in range(n):
        qh[j, i] = q[i]
    return True, good, good_cert, hint


@njit(**_PER_STEP)
def _brake_fix(pb, sh, qh, j, runs, sc, cfg, hint):
    """Fix sample j at the brake value (at rest where that would stay put: ``_rest_value``).
    Returns (status OK / INFEASIBLE / STUCK, the certificate of a rest value or -1, hint)."""
    n = qh.shape[1]
    ok, x, hint = _step(pb.table, pb.lim, pb.js, pb.feed, sh, qh, j, np.int64(1), hint, sc, cfg.tol, np.bool_(False))
    if not ok:
        return INFEASIBLE, -1, hint
    c = -1
    if _stays_at_rest(sh, j, x, pb.feed.L):
        ok, x, c, hint = _rest_value(pb, sh, qh, j, runs, sc, cfg, hint)
        if not ok:
            return STUCK, -1, hint
    sh[j] = x
    for i in range(n):
        qh[j, i] = sc.q[i]
    return OK, c, hint


@njit(**_PER_STEP)
def _horizon(k, j, fast):
    """Fast mode: a brake run from j that outlives the failed max run (index k) by as many
    steps again (+8) and then meets ``_easy`` at a 60% share is taken as safe; 0 (exact
    mode) asks for rest."""
    if not fast:
        return 0
    return k + (k - j) + 8


@njit(**_PER_STEP)
def _certified_run(pb, sh, qh, j, runs, sc, cfg, horizon):
    """A brake run from j; when it succeeds it is kept in runs.cs/cq as the certificate the
    chain after a fix at j bisects along. Returns (ok, certified-up-to, its length)."""
    r = _brake_run(pb, sh, qh, j, runs, sc, cfg, np.int64(1), cfg.easy_frac, horizon)
    runs.stats[1] += 1
    if not r[0]:
        return False, 0, 0
    bs = runs.bs
    bq = runs.bq
    cs = runs.cs
    cq = runs.cq
    n = bq.shape[1]
    for t in range(r[1]):
        cs[t] = bs[t]
        for i in range(n):
            cq[t, i] = bq[t, i]
    return True, r[2], r[1] - 3


@njit(**_PER_STEP)
def _put_cert(sh, qh, cs, cq, j, t0, t1):
    """Write certificate samples t0..t1-1 (main indices; the certificate starts at j)."""
    n = qh.shape[1]
    for t in range(t0, t1):
        sh[t] = cs[3 + t - j]
        for i in range(n):
            qh[t, i] = cq[3 + t - j, i]


@njit(**_PER_STEP)
def _max_then_brake(pb, sh, qh, t, x, runs, sc, cfg, last_k, last_j):
    """Sample t = x (q holds q(x)), then a brake run from t+1 with the chain's horizon:
    the run's (ok, scratch end, certified-up-to)."""
    n = qh.shape[1]
    sh[t] = x
    for i in range(n):
        qh[t, i] = sc.q[i]
    hz = (t + 1 + 2 * (last_k - last_j) + 8) if cfg.fast else 0
    r = _brake_run(pb, sh, qh, t + 1, runs, sc, cfg, np.int64(1), cfg.easy_frac, hz)
    runs.stats[1] += 1
    return r


@njit(**_PER_STEP)
def _chain_test(pb, sh, qh, j, t, runs, sc, cfg, last_k, last_j, hint):
    """Samples j+1..t-1 from the certificate, the max step at t, then a brake run from
    t+1: (passed, certified-up-to, hint)."""
    _put_cert(sh, qh, runs.cs, runs.cq, j, j + 1, t)
    ok, x, hint = _step(pb.table, pb.lim, pb.js, pb.feed, sh, qh, t, np.int64(0), hint, sc, cfg.tol, np.bool_(False))
    runs.stats[3] += 1
    if not ok:
        return False, 0, hint
    r = _max_then_brake(pb, sh, qh, t, x, runs, sc, cfg, last_k, last_j)
    return r[0], r[2], hint


@njit(**_PER_STEP)
def _chain_search(pb, sh, qh, j, m, runs, sc, cfg, last_k, last_j, hint):
    """After a brake fix at j with its brake run kept in runs.cs/cq (samples j..j+m-1): the
    first t in (j, j+m) where the max step followed by braking reaches rest, the samples
    between following the certificate. Sequentially that is one brake run per step of the
    chain; here the first ``cfg.chain_seq`` t are tested in order, the rest by bisection
    and then probes below the bisection's answer at doubling distances (the tests mostly
    pass from some t on; where they do not, an earlier pass is worth finding: the switch
    to speeding up comes sooner). Any t chosen has passed its own test: never unsafe.

    Returns (P, certified-up-to of P's run, hint); P = -1 when no t passes, with the
    samples up to j+m-1 then set to the certificate. On success sh/qh hold j..P."""
    n = qh.shape[1]
    chain_seq = cfg.chain_seq
    lo_t = j  # known: fails (or is the fix itself)
    hi_t = j + m  # no test there yet: a virtual pass
    best = -1
    best_cert = 0
    t = j + 1
    while hi_t - lo_t > 1:
        passed, cert, hint = _chain_test(pb, sh, qh, j, t, runs, sc, cfg, last_k, last_j, hint)
        if passed:
            hi_t = t
            best = t
            best_cert = cert
        else:
            lo_t = t
        if best < 0 and t - j < chain_seq and t + 1 < hi_t:
            t = t + 1  # the first few in order
        else:
            t = (lo_t + hi_t) // 2
    if best > j + chain_seq + 1:
        d = 2
        while best - d > j + chain_seq:
            t = best - d
            passed, cert, hint = _chain_test(pb, sh, qh, j, t, runs, sc, cfg, last_k, last_j, hint)
            if passed:
                best = t
                best_cert = cert
                d = 2
            else:
                d *= 2
    if best < 0:
        _put_cert(sh, qh, runs.cs, runs.cq, j, j + 1, j + m)
        return -1, 0, hint
    _put_cert(sh, qh, runs.cs, runs.cq, j, j + 1, best)
    ok, x, hint = _step(pb.table, pb.lim, pb.js, pb.feed, sh, qh, best, np.int64(0), hint, sc, cfg.tol, np.bool_(False))
    sh[best] = x
    for i in range(n):
        qh[best, i] = sc.q[i]
    return best, best_cert, hint


#: plan_core's persistent state (``st``, int64): sample k, last brake-fixed sample b, the
#: chain flag, the certificate's start c_at and length c_len, the certified-up-to index,
#: where the last max run failed and was fixed, and the table lookup hint. Indices are
#: local to the caller's buffers (global = local + the caller's base).
ST_K, ST_B, ST_CHAIN, ST_CAT, ST_CLEN, ST_CERT, ST_LASTK, ST_LASTJ, ST_HINT = range(9)
ST_SIZE = 9


def new_state() -> np.ndarray:
    """The state of a path about to be planned: sample 0 fixed (at rest), k = 1."""
    st = np.zeros(ST_SIZE, dtype=np.int64)
    st[ST_K] = 1
    st[ST_CAT] = -1
    st[ST_CERT] = _BIG
    return st


@njit(**_PER_STEP)
def _save(st, k, b, chain, c_at, c_len, cert, last_k, last_j, hint):
    st[ST_K] = k
    st[ST_B] = b
    st[ST_CHAIN] = 1 if chain else 0
    st[ST_CAT] = c_at
    st[ST_CLEN] = c_len
    st[ST_CERT] = cert
    st[ST_LASTK] = last_k
    st[ST_LASTJ] = last_j
    st[ST_HINT] = hint


@njit(cache=True, nogil=True)
def plan_core(pb, sh, qh, st, runs, cfg, stop_k, k_base):
    """Run VPOp on the ``Problem`` pb from the state ``st`` (samples < st[ST_K] fixed; see
    ``ST_*``).

    Fills ``sh`` (K,), ``qh`` (K, n) and returns the status; the state is saved in ``st``
    at every return, so a call that returns OK... YIELD or NEED_SPACE resumes exactly where
    it stopped: the result does not depend on where the caller's buffers end.
    ``runs.cs``/``runs.cq`` (brake-run sized) hold the certificate of the last fix across
    calls. Returns at the top of an iteration only: NEED_SPACE when fewer than a brake
    run's worth of samples (``runs.bs``'s length) is left in ``sh``, YIELD when k >=
    ``stop_k``. ``k_base`` is the global index of local sample 0 (for ``max_steps``).

    ``cfg`` (``Settings``): ``floor_h`` > 0 bounds the backtracking: no sample before
    k - floor_h is changed (samples up to b are final), so a caller may hand out and drop
    old samples. ``easy_frac`` > 0 lets brake runs end early (see ``_easy``); ``gap_tol``
    is how far short of L a committed aim run may stop; ``fast`` bounds brake runs by
    ``_horizon``; ``chain_seq`` is how many chain tests run in order before bisection
    (``_chain_search``); ``tol`` is the searches' tolerance in s.
    runs.stats: [backtracks, brake runs, brake-run steps, max steps, aim runs committed].
    """
    n = qh.shape[1]
    q = np.empty(n)
    qs = np.empty(n)
    lo = np.empty(n)
    hi = np.empty(n)
    wk = np.empty((3, n))
    sc = Scratch(q, qs, lo, hi, wk)
    T = pb.table
    lim = pb.lim
    js = pb.js
    fd = pb.feed
    L = fd.L
    tol = cfg.tol
    fast = cfg.fast
    floor_h = cfg.floor_h
    stats = runs.stats
    bs = runs.bs
    bq = runs.bq
    k = st[ST_K]
    b = st[ST_B]
    chain = st[ST_CHAIN] != 0  # the last sample was fixed by a backtrack
    c_at = st[ST_CAT]  # main index of the certificate's first sample (cs[3]); -1: none
    c_len = st[ST_CLEN]
    cert = st[ST_CERT]  # _BIG: sample 0 is at rest
    last_k = st[ST_LASTK]  # where the last max run failed, and the step it was fixed at
    last_j = st[ST_LASTJ]
    hint = st[ST_HINT]
    cap = sh.shape[0]
    room = bs.shape[0] + 8  # an iteration writes at most a brake run past k
    while True:
        if floor_h > 0 and k - floor_h - 1 > b:
            b = k - floor_h - 1  # a bounded look-back: older samples are final
        # done: three equal samples at the end point
        if k >= 3 and sh[k - 1] == L and sh[k - 2] == L and sh[k - 3] == L:
            _save(st, k, b, chain, c_at, c_len, cert, last_k, last_j, hint)
            return OK
        if k + room >= cap:
            _save(st, k, b, chain, c_at, c_len, cert, last_k, last_j, hint)
            return NEED_SPACE
        if k + k_base >= cfg.max_steps:
            _save(st, k, b, chain, c_at, c_len, cert, last_k, last_j, hint)
            return STUCK
        if k >= stop_k:
            _save(st, k, b, chain, c_at, c_len, cert, last_k, last_j, hint)
            return YIELD
        if chain and c_at == k - 1 and c_len >= 3 and k + c_len + 1 < cap:
            # the chain after a fix, along the fix's own brake run, by bisection
            P, pc, hint = _chain_search(pb, sh, qh, k - 1, c_len, runs, sc, cfg, last_k, last_j, hint)
            c_at = -1
            if P >= 0:
                cert = pc
                chain = np.bool_(False)
                if P - 1 > b:
                    b = P - 1
                k = P + 1
            else:
                b = k + c_len - 2
                k = k + c_len - 1
            continue
        ok, x, hint = _step(T, lim, js, fd, sh, qh, k, np.int64(0), hint, sc, tol, np.bool_(False))
        stats[3] += 1
        if ok and chain and k + 1 < cap:
            # right after a brake fix the next failure is usually imminent: test the max
            # step at once (the same test the dichotomy would run first) instead of
            # re-running max steps up to the failure
            r = _max_then_brake(pb, sh, qh, k, x, runs, sc, cfg, last_k, last_j)
            if r[0]:
                cert = r[2]
                chain = np.bool_(False)
                k += 1
                continue
            if k + 1 >= cert:
                hz = (k + 2 * (last_k - last_j) + 8) if fast else 0
                ok, cert, c_len = _certified_run(pb, sh, qh, k, runs, sc, cfg, hz)
                if not ok:
                    _save(st, k, b, chain, c_at, c_len, cert, last_k, last_j, hint)
                    return INFEASIBLE
                c_at = k
            stf, c, hint = _brake_fix(pb, sh, qh, k, runs, sc, cfg, hint)
            if stf != OK:
                _save(st, k, b, chain, c_at, c_len, cert, last_k, last_j, hint)
                return stf
            if c >= 0:
                cert = c
                c_at = -1
            b = k
            k += 1
            continue
        if ok:
            sh[k] = x
            for i in range(n):
                qh[k, i] = q[i]
            k += 1
            continue
        chain = np.bool_(False)
        last_k = k
        # empty set at k: latest j in [b+1, k-1] from which braking reaches rest
        stats[0] += 1
        lo_j = b + 1
        hi_j = k  # braking from k is impossible (its set is empty)
        if lo_j >= hi_j:
            _save(st, k, b, chain, c_at, c_len, cert, last_k, last_j, hint)
            return INFEASIBLE
        # braking from lo_j + 1 almost always succeeds (the test would fail about once
        # in 5000 backtracks): bisect above it first, and run that test only when no
        # later step passes (its run is then the certificate)
        tested = False
        if lo_j + 1 < hi_j:
            base = lo_j + 1
            lo_j = base
            while hi_j - lo_j > 1:
                mid = (lo_j + hi_j) // 2
                ok, cc, cl = _certified_run(pb, sh, qh, mid, runs, sc, cfg, _horizon(k, mid, fast))
                if ok:
                    lo_j = mid
                    tested = True
                    cert = cc
                    c_len = cl
                    c_at = mid
                else:
                    hi_j = mid
            if not tested:
                ok, cc, cl = _certified_run(pb, sh, qh, base, runs, sc, cfg, _horizon(k, base, fast))
                if ok:
                    tested = True
                    cert = cc
                    c_len = cl
                    c_at = base
                else:
                    lo_j = base - 1
        j = lo_j
        if not tested and (j + 1 >= cert or (floor_h > 0 and j <= k - floor_h)):
            # fast mode: the brake chain has run past what its last run certified; or the
            # look-back floor, not a brake fix, is all that is left below (never assumed)
            ok, cert, c_len = _certified_run(pb, sh, qh, j, runs, sc, cfg, _horizon(k, j, fast))
            if not ok:
                _save(st, k, b, chain, c_at, c_len, cert, last_k, last_j, hint)
                return INFEASIBLE
            c_at = j
        # the end is what stops us: try to land on it with the aim policy in one run
        if cfg.gap_tol > 0.0 and k >= 2 and sh[k - 1] >= L - 2.0 * (sh[k - 1] - sh[k - 2]) - tol:
            done = False
            for back in range(4):
                jj = j - back
                if jj <= b:
                    break
                r = _brake_run(pb, sh, qh, jj, runs, sc, cfg, np.int64(2), np.float64(0.0), np.int64(0))
                kk = r[1]
                if r[0] and L - bs[kk - 1] <= cfg.gap_tol:
                    need = jj + kk - 3
                    for t in range(3, kk):
                        sh[jj + t - 3] = bs[t]
                        for i in range(n):
                            qh[jj + t - 3, i] = bq[t, i]
                    k = need
                    b = k - 1
                    stats[4] += 1
                    done = True
                    break
            if done:
                continue
        stf, c, hint = _brake_fix(pb, sh, qh, j, runs, sc, cfg, hint)
        if stf != OK:
            _save(st, j, b, chain, c_at, c_len, cert, last_k, last_j, hint)
            return stf
        if c >= 0:
            cert = c
            c_at = -1
        k = j + 1
        b = j
        last_j = j
        chain = np.bool_(True)

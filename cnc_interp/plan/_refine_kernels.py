"""Shorten a window of a sampled plan by whole periods (numba): the discrete problem itself.

A plan's samples s_k (arc length at t = k dt) must keep every axis's backward
differences within the limits (Beudaert et al. 2012, Eq. 6, exactly as ``verify``
computes them). Given a feasible plan, the samples ``a .. a+M-1`` can be replaced by
M' < M others when some positions x_0 .. x_{M'-1} between the fixed samples before
(``pre``: the three samples before a) and after (``post``: the three samples that
followed the window) meet every row of the stencils they enter:

    | Σ_i c_{d,i} q(P_{e-d+i}) | <= lim_{d, axis}            (d = 1, 2, 3)
    P_e - P_{e-1} <= F dt,   P_e >= P_{e-1}

``solve_window`` minimises the largest relative violation z of these rows (z <= 0:
feasible) by a primal log-barrier method: damped Newton steps on z - μ Σ log(u_r), u_r =
bound - row > 0, with μ decreased tenfold when a step's Newton decrement is small; each
step starts a fraction of the way to the boundary of the rows' linearisation
(``_max_step``) and is halved while it leaves the interior. A row depends on at most
four consecutive samples and its Hessian in x is diagonal (it is a sum of functions of
one sample each), so the Newton matrix is a band of half-width 3 bordered by the z row:
two band solves per step. The negative part of the rows' curvature is dropped (a
Gauss–Newton-like matrix, always positive definite), and every iterate stays strictly
inside (u > 0): the method never leaves the region where the barrier is defined.

``shorten`` is one visit of a window (``optimal.refine.Refiner.window``): one fewer sample at a time,
each solve followed by ``exact_ok``, while the tries succeed; a try starts from the window
retimed so that each period gives up time in proportion to its room (``_room_shares``,
``_start``). ``loose`` and ``dip_or_end`` are the refinement's tests of which windows to
visit; they compute exactly what the numpy code they replaced did (the same operations in
the same order): a plan does not depend on where its refinement ran.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from ..fit._quintic import quintic
from ._ipm import band4_cholesky, band4_solve2
from .vpop.step import _eval, _feasible, _piece

# solve_window's statuses (one set for every kernel: ``status``): OK (the window is
# feasible), INFEASIBLE, FAILED (the start is not strictly monotone)
from .status import FAILED, INFEASIBLE, OK

#: z below which a window counts as feasible (the exact check follows)
_Z_TARGET = -1e-6
#: the barrier weight of the first μ stage (1e-2: 32 Newton steps per solve on
#: stellabee1's refinement windows; 1e-3: 23 and as many windows shortened; 1e-4 and
#: below start too close to the boundary: more steps, 1e-5 lost 16 % of the windows)
_MU0 = 1e-3
#: a μ stage that ends at z > 0 having taken off less than _STALL z since the last one
#: ends the solve as infeasible. Along the stages z_k ≈ z* + c μ_k, so the last drop is
#: 9 c μ_{k+1}; with z* <= 0 it is at least 9 z_{k+1} > _STALL z_{k+1}: a feasible window
#: is not cut short (< 9). Windows that cannot lose a period were most of the
#: refinement's time: stellabee-violation-spirals 54 -> 39 Newton steps per such window,
#: 7 of 2354 feasible solves lost
_STALL = 8.0
_MU_MIN = 1e-10
#: a Newton step starts at this fraction of the way to the nearest row's linearised
#: boundary (then halves while a row leaves the interior): half of the line search's
#: evaluations had stepped outside before (66 -> 24 per solve); 0.9 and 0.95 are slower
#: (the rows are not linear), 0.99 much slower
_TAU = 0.8
#: the barrier's log-sum takes one log per this many rows (``_log_sum``); a block's
#: product outside (_LOG_SAFE_LO, _LOG_SAFE_HI) is summed one log at a time instead
#: (it would lose precision to underflow or overflow)
_LOG_BLOCK = 8
_LOG_SAFE_LO = 1e-250
_LOG_SAFE_HI = 1e250

#: a try's start gives each period of the window a share of the one it loses in proportion
#: to its room (``_room_shares``): how far its rows could shrink in time before reaching
#: their bounds, clipped to _ROOM_CLIP, plus _ROOM_FLOOR. Spreading the loss evenly (a
#: uniform resample) broke the refined plan's structure everywhere, also where the rows
#: were at their bounds: on 50 of stellabee1's paths, stellabee-kink-test, -spirals and
#: zigzag_0.002_0.001, the refinement then took 16 % fewer Newton steps for 608 fewer
#: samples (floor 0.005: zigzag 1.1 % longer; 0.05: 4 % more steps)
_ROOM_CLIP = 1.0
_ROOM_FLOOR = 0.02

#: one path's refinement problem, as ``shorten`` needs it: the joint table (S (m + 1,),
#: C axis-major (m, n, 6), QEND (n,)) and the same as a ``vpop.step.Table`` (joints), the
#: exact check's ``vpop.step.Limits`` (limits), the moving axes (n,) bool, the step limits
#: lim (3, n) (velocity, acceleration, jerk per period), the feed per period fdt and the
#: path's length L (the rest after its end)
RefineProblem = namedtuple("RefineProblem", "S C QEND joints limits moving lim fdt L")

#: the barrier's Newton system that ``_assemble`` fills: gradient g (nfree,), band
#: Hessian H (nfree, 4), the z column hz (nfree,), and gz (2,): z's gradient and curvature
NewtonSystem = namedtuple("NewtonSystem", "g H hz gz")


@njit(cache=True, nogil=True)
def _q_d012(S, C, QEND, x, hint, q0, q1, q2):
    """q, q_s, q_ss of every axis at x (C axis-major (m, n, 6)); returns the piece (found
    from ``hint`` by ``_piece``: a walk from piece 0 along a long path's table was most of
    a window solve's time)."""
    m = S.shape[0] - 1
    n = q0.shape[0]
    p = _piece(S, x, hint)
    t = x - S[p]
    for i in range(n):
        c = C[p, i]
        q0[i], q1[i], q2[i] = quintic(c[0], c[1], c[2], c[3], c[4], c[5], t)
    if x >= S[m]:
        for i in range(n):
            q0[i] = QEND[i]
    return p


@njit(cache=True, nogil=True)
def _stencil(d, i):
    """Coefficient i (0..d) of the d-th backward difference, oldest sample first."""
    if d == 1:
        return -1.0 if i == 0 else 1.0
    if d == 2:
        return 1.0 if i != 1 else -2.0
    if i == 0:
        return -1.0
    if i == 1:
        return 3.0
    if i == 2:
        return -3.0
    return 1.0


@njit(cache=True, nogil=True)
def _evaluate(S, C, QEND, P, nfree, moving, lim, fdt, Q0, Q1, Q2):
    """Axis positions and derivatives at every sample of the sequence P (K,)."""
    K = P.shape[0]
    n = Q0.shape[1]
    hint = 0
    q0 = np.empty(n)
    q1 = np.empty(n)
    q2 = np.empty(n)
    for k in range(K):
        hint = _q_d012(S, C, QEND, P[k], hint, q0, q1, q2)
        for i in range(n):
            Q0[k, i] = q0[i]
            Q1[k, i] = q1[i]
            Q2[k, i] = q2[i]


@njit(cache=True, nogil=True)
def _rows(P, nfree, moving, ilim, ifdt, Q0, z, u_out):
    """u_r = bound - row (the barrier's arguments) for every row; returns the count and
    the largest relative violation (max over rows of row/bound - 1)."""
    n = Q0.shape[1]
    r = 0
    worst = -1e300
    # difference rows: order d ends at e = 3 .. 3 + nfree + d - 1 (sequence index)
    for d in range(1, 4):
        for e in range(3, 3 + nfree + d):
            for i in range(n):
                if not moving[i]:
                    continue
                val = 0.0
                for j in range(d + 1):
                    val += _stencil(d, j) * Q0[e - d + j, i]
                rel = val * ilim[d - 1, i]
                if rel - 1.0 > worst:
                    worst = rel - 1.0
                if -rel - 1.0 > worst:
                    worst = -rel - 1.0
                u_out[r] = 1.0 + z - rel
                u_out[r + 1] = 1.0 + z + rel
                r += 2
    # feed and monotonicity per step into/through the window
    for e in range(3, 3 + nfree + 1):
        step = P[e] - P[e - 1]
        rel = step * ifdt
        if rel - 1.0 > worst:
            worst = rel - 1.0
        u_out[r] = 1.0 + z - rel
        u_out[r + 1] = rel + 1e-12
        r += 2
    return r, worst


@njit(cache=True, nogil=True)
def _assemble(P, nfree, moving, ilim, ifdt, Q1, Q2, u, mu, ns):
    """The ``NewtonSystem`` ns: gradient g (nfree), band Hessian H (nfree, 4) and the z
    column hz, of mu Σ -log(u_r) (z's own gradient 1 added by the caller in gz[0])."""
    g = ns.g
    H = ns.H
    hz = ns.hz
    grad_z = ns.gz
    n = Q1.shape[1]
    for k in range(nfree):
        g[k] = 0.0
        hz[k] = 0.0
        for b in range(4):
            H[k, b] = 0.0
    hzz = 0.0
    gz = 0.0
    r = 0
    # scratch for one row's gradient over (up to 4) samples
    idx = np.empty(4, dtype=np.int64)
    gr = np.empty(4)
    cr = np.empty(4)
    for d in range(1, 4):
        for e in range(3, 3 + nfree + d):
            for i in range(n):
                if not moving[i]:
                    continue
                cnt = 0
                for j in range(d + 1):
                    k = e - d + j - 3  # free index
                    if 0 <= k < nfree:
                        c = _stencil(d, j) * ilim[d - 1, i]
                        idx[cnt] = k
                        gr[cnt] = c * Q1[e - d + j, i]
                        cr[cnt] = c * Q2[e - d + j, i]
                        cnt += 1
                # the pair u+ = 1 + z - row, u- = 1 + z + row (du/dx = -+gr, du/dz = 1),
                # summed once: both rows share gr, cr and the sample indices
                up = u[r]
                um = u[r + 1]
                ip = 1.0 / up
                im = 1.0 / um
                wp = mu * ip
                wm = mu * im
                w2p = wp * ip
                w2m = wm * im
                wd = wp - wm
                w2d = w2m - w2p
                w2s = w2p + w2m
                for a in range(cnt):
                    ka = idx[a]
                    ga = gr[a]
                    g[ka] += wd * ga
                    hz[ka] += w2d * ga
                    # curvature of -log u: the convex part of +-cr/u
                    ca = cr[a]
                    H[ka, 0] += ca * wp if ca > 0.0 else -ca * wm
                    for b in range(a + 1):
                        H[ka, ka - idx[b]] += w2s * ga * gr[b]
                gz -= wp + wm
                hzz += w2s
                r += 2
    for e in range(3, 3 + nfree + 1):
        k1 = e - 3  # the sample at e (free when < nfree)
        k0 = e - 4  # the sample before
        for row in range(2):
            ur = u[r]
            w = mu / ur
            w2 = mu / (ur * ur)
            if row == 0:  # u = 1 + z - (P_e - P_{e-1})/fdt
                c1 = -ifdt
                c0 = ifdt
                gz -= w
                hzz += w2
            else:  # u = (P_e - P_{e-1})/fdt + 1e-12
                c1 = ifdt
                c0 = -ifdt
            if 0 <= k1 < nfree:
                g[k1] -= w * c1
                H[k1, 0] += w2 * c1 * c1
                if row == 0:
                    hz[k1] += w2 * c1
            if 0 <= k0 < nfree:
                g[k0] -= w * c0
                H[k0, 0] += w2 * c0 * c0
                if row == 0:
                    hz[k0] += w2 * c0
            if 0 <= k1 < nfree and 0 <= k0 < nfree:
                H[k1, 1] += w2 * c1 * c0
            r += 1
    grad_z[0] = gz
    grad_z[1] = hzz


@njit(cache=True, nogil=True, inline="always")
def _to_boundary(alpha, du, ur, tau):
    """alpha, shortened so that ur + alpha du keeps (1 - tau) of ur."""
    if du < 0.0 and alpha * du < -tau * ur:
        return -tau * ur / du
    return alpha


@njit(cache=True, nogil=True)
def _max_step(nfree, moving, ilim, ifdt, Q1, u, dx, dz, tau):
    """The largest step alpha <= 1 along (dx, dz) keeping every row's linearisation at
    least (1 - tau) of its u (fraction to the boundary)."""
    n = Q1.shape[1]
    alpha = 1.0
    r = 0
    for d in range(1, 4):
        for e in range(3, 3 + nfree + d):
            for i in range(n):
                if not moving[i]:
                    continue
                drow = 0.0
                for j in range(d + 1):
                    k = e - d + j - 3
                    if 0 <= k < nfree:
                        drow += _stencil(d, j) * ilim[d - 1, i] * Q1[e - d + j, i] * dx[k]
                # u+ = 1 + z - row: du = dz - drow; u- = 1 + z + row: du = dz + drow
                alpha = _to_boundary(alpha, dz - drow, u[r], tau)
                alpha = _to_boundary(alpha, dz + drow, u[r + 1], tau)
                r += 2
    for e in range(3, 3 + nfree + 1):
        k1 = e - 3
        k0 = e - 4
        dstep = 0.0
        if 0 <= k1 < nfree:
            dstep += dx[k1]
        if 0 <= k0 < nfree:
            dstep -= dx[k0]
        alpha = _to_boundary(alpha, dz - dstep * ifdt, u[r], tau)
        alpha = _to_boundary(alpha, dstep * ifdt, u[r + 1], tau)
        r += 2
    return alpha


@njit(cache=True, nogil=True)
def _log_sum(u, r):
    """Σ log u[i] over i < r (every u[i] > 0), one log per block of _LOG_BLOCK factors
    (the barrier's value is most of a Newton step's work when every row takes a log);
    a block whose product leaves the safe range is summed term by term."""
    acc = 0.0
    i = 0
    while i < r:
        j = min(i + _LOG_BLOCK, r)
        p = 1.0
        for k in range(i, j):
            p *= u[k]
        if _LOG_SAFE_LO < p < _LOG_SAFE_HI:
            acc += np.log(p)
        else:
            for k in range(i, j):
                acc += np.log(u[k])
        i = j
    return acc


@njit(cache=True, nogil=True)
def solve_window(S, C, QEND, pre, post, x0, moving, lim, fdt, max_newton, counts):
    """Positions x (nfree,) between ``pre`` (3,) and ``post`` (3,) minimising the largest
    relative violation z; stops as soon as z < _Z_TARGET. Returns (status, x, z);
    ``counts`` (2,) int accumulates Newton steps and row evaluations."""
    nfree = x0.shape[0]
    n = C.shape[1]
    K = nfree + 6
    P = np.empty(K)
    for i in range(3):
        P[i] = pre[i]
        P[nfree + 3 + i] = post[i]
    x = x0.copy()
    for k in range(nfree):
        P[3 + k] = x[k]
    Q0 = np.empty((K, n))
    Q1 = np.empty((K, n))
    Q2 = np.empty((K, n))
    nrows = 2 * 3 * n * (nfree + 2) + 2 * (nfree + 1) + 16
    u = np.empty(nrows)
    ut = np.empty(nrows)
    _evaluate(S, C, QEND, P, nfree, moving, lim, fdt, Q0, Q1, Q2)
    # the rows are scaled by the limits' inverses (a product per term, not a quotient)
    ilim = 1.0 / lim
    ifdt = 1.0 / fdt
    r, worst = _rows(P, nfree, moving, ilim, ifdt, Q0, 0.0, u)
    z = worst + 0.1 * (1.0 + abs(worst))
    # monotonicity must hold strictly from the start
    for e in range(3, 3 + nfree + 1):
        if not P[e] - P[e - 1] > -1e-12 * fdt:
            return FAILED, x, worst
    r, worst = _rows(P, nfree, moving, ilim, ifdt, Q0, z, u)
    log_u = _log_sum(u, r)
    g = np.empty(nfree)
    H = np.empty((nfree, 4))
    hz = np.empty(nfree)
    gzz = np.empty(2)
    y1 = np.empty(nfree)
    y2 = np.empty(nfree)
    dx = np.empty(nfree)
    Pt = np.empty(K)
    mu = _MU0
    best_z = worst
    best_x = x.copy()
    stage_z = np.inf  # z where the last μ stage ended
    for it in range(max_newton):
        counts[0] += 1
        _assemble(P, nfree, moving, ilim, ifdt, Q1, Q2, u, mu, NewtonSystem(g, H, hz, gzz))
        gz = 1.0 + gzz[0]
        hzz = gzz[1]
        for k in range(nfree):
            H[k, 0] += 1e-12 * H[k, 0] + 1e-300
        band4_cholesky(H, nfree)
        for k in range(nfree):
            y1[k] = -g[k]
            y2[k] = hz[k]
        band4_solve2(H, nfree, y1, y2)
        # [H hz; hz^T hzz] [dx; dz] = -[g; gz]
        den = hzz
        num = -gz
        for k in range(nfree):
            den -= hz[k] * y2[k]
            num -= hz[k] * y1[k]
        dz = num / den if den > 0.0 else -gz
        for k in range(nfree):
            dx[k] = y1[k] - y2[k] * dz
        dec = -gz * dz
        for k in range(nfree):
            dec -= g[k] * dx[k]
        # backtracking: stay strictly inside, decrease the barrier function
        phi0 = z - mu * log_u
        alpha = _max_step(nfree, moving, ilim, ifdt, Q1, u, dx, dz, _TAU)
        accepted = False
        for _ in range(40):
            for k in range(nfree):
                Pt[3 + k] = x[k] + alpha * dx[k]
            for i in range(3):
                Pt[i] = P[i]
                Pt[nfree + 3 + i] = P[nfree + 3 + i]
            zt = z + alpha * dz
            counts[1] += 1
            _evaluate(S, C, QEND, Pt, nfree, moving, lim, fdt, Q0, Q1, Q2)
            rt, wt = _rows(Pt, nfree, moving, ilim, ifdt, Q0, zt, ut)
            ok = True
            for i in range(rt):
                if not ut[i] > 0.0:
                    ok = False
                    break
            log_ut = _log_sum(ut, rt) if ok else 0.0
            if ok and zt - mu * log_ut <= phi0 - 1e-4 * alpha * dec:
                accepted = True
                break
            alpha *= 0.5
        if not accepted:
            # no progress at this μ: restore the derivatives at the current point
            _evaluate(S, C, QEND, P, nfree, moving, lim, fdt, Q0, Q1, Q2)
            if mu <= _MU_MIN:
                break
            mu *= 0.1
            continue
        for k in range(nfree):
            x[k] = Pt[3 + k]
            P[3 + k] = x[k]
        z = zt
        log_u = log_ut
        for i in range(rt):
            u[i] = ut[i]
        if wt < best_z:
            best_z = wt
            for k in range(nfree):
                best_x[k] = x[k]
        if best_z < _Z_TARGET:
            return OK, best_x, best_z
        if dec < 1e-3 * mu * r or alpha < 1e-3:
            # near the central point of this μ: z exceeds the optimum by at most about
            # μ per row; when even that leaves it positive, the window is infeasible
            if z - mu * r > 1e-9:
                return INFEASIBLE, best_x, best_z
            # a tenfold smaller μ that took off less than _STALL z: z* > 0 (see _STALL)
            if z > 0.0 and stage_z - z < _STALL * z:
                return INFEASIBLE, best_x, best_z
            stage_z = z
            if mu <= _MU_MIN:
                break
            mu *= 0.1
    if best_z < _Z_TARGET:
        return OK, best_x, best_z
    return INFEASIBLE, best_x, best_z


@njit(cache=True, nogil=True)
def exact_ok(T, lim, sh, lo, hi, qbuf):
    """Samples lo..hi-1 of sh (with the samples before lo) pass verify's exact checks
    (the ``vpop.step.Limits`` lim) on the ``vpop.step.Table`` T; q positions go to qbuf
    (rows lo..hi-1)."""
    n = qbuf.shape[1]
    q = np.empty(n)
    qs = np.empty(n)
    hint = 0
    for k in range(lo, hi):
        hint = _eval(T, sh[k], hint, q, qs)
        if not _feasible(qbuf, k, q, lim):
            return False
        for i in range(n):
            qbuf[k, i] = q[i]
    return True


@njit(cache=True, nogil=True, inline="always")
def _row_ratios(Q, i0, i1, i2, i3, moving, lim):
    """The largest ratio to its bound of the velocity, acceleration and jerk rows (backward
    differences, as ``verify`` takes them) ending at sample i3 of Q (K, n), over the moving
    axes; i0..i2 are the three samples before (repeated at a path's start)."""
    r1 = 0.0
    r2 = 0.0
    r3 = 0.0
    for i in range(Q.shape[1]):
        if not moving[i]:
            continue
        d10 = Q[i1, i] - Q[i0, i]
        d11 = Q[i2, i] - Q[i1, i]
        d12 = Q[i3, i] - Q[i2, i]
        d20 = d11 - d10
        d21 = d12 - d11
        r1 = max(r1, abs(d12) / lim[0, i])
        r2 = max(r2, abs(d21) / lim[1, i])
        r3 = max(r3, abs(d21 - d20) / lim[2, i])
    return r1, r2, r3


@njit(cache=True, nogil=True)
def _room_shares(P, Q, moving, lim, fdt):
    """Each period's share of the one a try takes off (see _ROOM_FLOOR). P (M + 6,) the
    window's samples with the three before and after, Q (M + 6, n) their axis positions;
    period j runs from P[2 + j] to P[3 + j] (j = 0 .. M) and enters the rows ending at
    P[3 + j] .. P[5 + j]. A row of order d at ratio r to its bound allows a time scale
    of r^(-1/d) (its difference scales with the d-th power); the room is that less one."""
    K = P.shape[0]
    room = np.empty(K - 3)
    for e in range(3, K):
        r1, r2, r3 = _row_ratios(Q, e - 3, e - 2, e - 1, e, moving, lim)
        r1 = max(r1, (P[e] - P[e - 1]) / fdt)
        g = _ROOM_CLIP + 1.0
        if r1 > 0.0:
            g = min(g, 1.0 / r1)
        if r2 > 0.0:
            g = min(g, 1.0 / np.sqrt(r2))
        if r3 > 0.0:
            g = min(g, 1.0 / np.cbrt(r3))
        room[e - 3] = g - 1.0
    M = K - 6
    share = np.empty(M + 1)
    total = 0.0
    for j in range(M + 1):
        w = min(room[j], room[j + 1], room[j + 2])
        w = min(max(w, 0.0), _ROOM_CLIP) + _ROOM_FLOOR
        share[j] = w
        total += w
    for j in range(M + 1):
        share[j] /= total
    return share


@njit(cache=True, nogil=True)
def _start(cur, share, m):
    """A try's start: the window's positions cur (M + 2,: the fixed sample before, the M
    free ones, the fixed one after) retimed onto m = M - 1 free samples, period j of cur
    lasting 1 - share[j] (the shares sum to one), positions linear in time within it."""
    out = np.empty(m)
    t0 = 0.0
    t1 = 1.0 - share[0]
    j = 0
    nj = share.shape[0]
    for i in range(1, m + 1):
        ti = float(i)
        while j + 1 < nj and t1 <= ti:
            j += 1
            t0 = t1
            t1 = t0 + (1.0 - share[j])
        f = (ti - t0) / (t1 - t0)
        if f > 1.0:
            f = 1.0
        out[i - 1] = cur[j] + f * (cur[j + 1] - cur[j])
    return out


@njit(cache=True, nogil=True)
def solve_checked(prob, pre, q_pre, post, post_exact, x0, max_newton, counts):
    """``solve_window`` on the ``RefineProblem`` prob between ``pre`` (3,) and ``post`` (3,)
    from x0 (m,), then ``exact_ok`` on its positions with the samples before (``pre``,
    axis values ``q_pre`` (3, n)) and after (``post_exact`` (3,): ``post``, or the rest at
    L past the path's end). Returns (ok, x (m,), their axis values (m, n))."""
    m = x0.shape[0]
    n = q_pre.shape[1]
    st, x, _ = solve_window(
        prob.S, prob.C, prob.QEND, pre, post, x0, prob.moving, prob.lim, prob.fdt, max_newton, counts
    )
    if st != OK:
        return False, x, np.empty((0, n))
    full = np.empty(m + 6)
    full[:3] = pre
    full[3 : 3 + m] = x
    full[3 + m :] = post_exact
    qb = np.empty((m + 6, n))
    qb[:3] = q_pre
    if not exact_ok(prob.joints, prob.limits, full, 3, m + 6, qb):
        return False, x, np.empty((0, n))
    return True, x, qb[3 : 3 + m].copy()


@njit(cache=True, nogil=True)
def shorten(prob, sh, qh, a, b, max_cut, max_newton, counts):
    """One window visit of ``optimal.refine.Refiner.window`` on the ``RefineProblem`` prob:
    samples a..b-1 of (sh, qh) (1 <= a, b < len(sh)) with one fewer at a time
    (``solve_checked``, with the three samples after the window, rest at L past the end)
    while each try succeeds, at most ``max_cut``. Returns (dropped, solves, x, qx): the
    last accepted positions and their axis values (empty when none was)."""
    moving, lim, fdt, L = prob.moving, prob.lim, prob.fdt, prob.L
    N = sh.shape[0]
    n = qh.shape[1]
    pre = np.empty(3)
    post = np.empty(3)
    post_exact = np.empty(3)
    q_pre = np.empty((3, n))
    q_post = np.empty((3, n))
    for i in range(3):
        k = max(a - 3 + i, 0)
        pre[i] = sh[k]
        q_pre[i] = qh[k]
        post[i] = sh[min(b + i, N - 1)]
        q_post[i] = qh[min(b + i, N - 1)]
        post_exact[i] = sh[b + i] if b + i < N else L
    M = b - a
    # the window with the three samples before and after, positions and axis values (the
    # sample before the window is pre[2], the one after it post[0]: b < N)
    Pw = np.concatenate((pre, sh[a:b], post))
    Qw = np.concatenate((q_pre, qh[a:b], q_post))
    dropped = 0
    solves = 0
    kept_x = np.empty(0)
    kept_q = np.empty((0, n))
    while dropped < max_cut and M - 1 >= 2:
        m = M - 1
        x0 = _start(Pw[2 : M + 4], _room_shares(Pw, Qw, moving, lim, fdt), m)
        ok, x, qx = solve_checked(prob, pre, q_pre, post, post_exact, x0, max_newton, counts)
        solves += 1
        if not ok:
            break
        kept_x = x
        kept_q = qx
        Pw = np.concatenate((Pw[:3], x, Pw[M + 3 :]))
        Qw = np.concatenate((Qw[:3], kept_q, Qw[M + 3 :]))
        M = m
        dropped += 1
    return dropped, solves, kept_x, kept_q


@njit(cache=True, nogil=True)
def loose(sh, qh, a, b, moving, lim, fdt, skip):
    """``optimal.refine.Refiner.loose`` with numpy's arithmetic: has some sample of the window
    a..b-1 every limit ratio below ``skip`` (velocity, acceleration and jerk of the moving
    axes against lim (3, n), the step against the feed fdt)? Needs the three samples before a (copies of the
    first sample at the path's start)."""
    lo = max(a - 3, 0)
    pad = 3 if lo == 0 else 0
    nr = b - lo + pad - 3  # third differences in the window (and d2[1:], d1[2:])
    base = max(a - 1, 0)
    ns = b - base - 1  # steps
    m = min(nr, ns)
    for u in range(m):
        t = nr - m + u  # the rows t .. t+3 of the padded sequence
        i0 = max(lo + t - pad, lo)
        i1 = max(lo + t + 1 - pad, lo)
        i2 = max(lo + t + 2 - pad, lo)
        i3 = lo + t + 3 - pad
        r1, r2, r3 = _row_ratios(qh, i0, i1, i2, i3, moving, lim)
        r = max(r1, r2, r3)
        v = ns - m + u
        r = max(r, (sh[base + v + 1] - sh[base + v]) / fdt)
        if r < skip:
            return True
    return False


@njit(cache=True, nogil=True)
def dip_or_end(sh, la, b, W, done, dip):
    """The targeted refinement's window test (``optimal.refine._refined``): does the window
    la..b-1 hold the path's start, its end (``done``: no sample follows the buffer), or a
    step below ``dip`` times the largest step within W samples around?"""
    N = sh.shape[0]
    if la <= 2 or (done and b >= N - 2):
        return True
    if b - la < 1:
        return False
    big = -np.inf
    for k in range(max(la - W, 1), min(b + W, N)):
        big = max(big, sh[k] - sh[k - 1])
    small = np.inf
    for k in range(la, b):
        small = min(small, sh[k] - sh[k - 1])
    return small < dip * big

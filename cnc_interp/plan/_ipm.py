"""A primal-dual interior-point solver for banded linear programs (numba).

    minimise  c·x   subject to   A x <= b

Every row of A touches at most ``W`` consecutive variables: row r is
``sum_k coef[r, k] * x[first[r] + k] <= b[r]`` (k < W; ``first[r] + W <= n``, unused
entries zero). The feed-profile LP of ``optimal.profile`` has this shape (a B-spline's
basis functions overlap on ``W = degree + 1`` coefficients), so the Newton system
``A^T D A`` is a band matrix of half-width ``W - 1`` and one iteration costs
O(rows · W² + n · W²): the solve is linear in the length of the path.

Mehrotra's predictor-corrector (Nocedal & Wright, "Numerical Optimization", 2nd ed.,
Algorithm 14.3) with an infeasible start: slacks s = b - A x > 0 and multipliers
λ > 0 are driven to complementarity together with the residuals. A small diagonal
regularisation keeps the band Cholesky factorisation defined when a variable has no
active row. The caller scales rows and variables to order one.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .status import BREAKDOWN, MAX_ITER, OK  # the planning stage's shared codes

#: fraction of the distance to the boundary a step may go (s, λ stay positive)
_TO_BOUNDARY = 0.995
#: relative dual residual accepted at convergence
_DUAL_TOL = 1e-4
#: complementarity at which the iteration stops whatever the dual residual
_MU_FLOOR = 1e-13
#: a Cholesky pivot below this share of its diagonal entry counts as lost to rounding
_PIVOT_TOL = 1e-14
_HUGE_PIVOT = 1e128
#: relative diagonal regularisation of the normal matrix (variables without active rows)
_REG = 1e-12
#: the band width W of ``lp_solve``'s rows (a cubic B-spline's four basis functions): a
#: compile-time constant, so that the passes over the rows are unrolled (a third of the
#: solve's time)
ROW_WIDTH = 4


@njit(cache=True, nogil=True, inline="always")
def _pivot(acc, diag):
    """The factor's diagonal entry from the pivot acc (diag: the matrix's own entry)."""
    if not acc > _PIVOT_TOL * diag or not acc > 0.0:
        # a direction the rows do not determine (rounding has eaten the pivot): freeze it
        # with a huge pivot, as interior-point codes do
        acc = _HUGE_PIVOT
    return np.sqrt(acc)


@njit(cache=True, nogil=True, inline="always")
def _cholesky_row(M, i, W):
    """Row i of ``_band_cholesky`` (rows before i already factored)."""
    for d in range(W - 1, -1, -1):
        j = i - d
        if j < 0:
            continue
        acc = M[i, d]
        # sum over k < j within both bands: L(i, k) L(j, k)
        for e in range(1, W - d):
            k = j - e
            if k < 0:
                break
            acc -= M[i, d + e] * M[j, e]
        if d == 0:
            M[i, 0] = _pivot(acc, M[i, 0])
        else:
            M[i, d] = acc / M[j, 0]


@njit(cache=True, nogil=True)
def _band_cholesky(M, n, W):
    """In-place Cholesky of the SPD band matrix M (n, W): M[i, d] = M(i, i-d). False when
    a pivot is not positive. (The planners use its unrolled W = 4 form,
    ``band4_cholesky``; this general one is the reference the tests hold it to.)"""
    for i in range(n):
        _cholesky_row(M, i, W)
    return True


@njit(cache=True, nogil=True)
def band4_cholesky(M, n):
    """``_band_cholesky`` for W = 4 (cubic B-spline rows; the refinement's stencils),
    unrolled: the same float operations in the same order, so the same bits."""
    for i in range(min(n, 3)):
        _cholesky_row(M, i, 4)
    for i in range(3, n):
        m3 = M[i, 3] / M[i - 3, 0]
        M[i, 3] = m3
        m2 = (M[i, 2] - m3 * M[i - 2, 1]) / M[i - 2, 0]
        M[i, 2] = m2
        m1 = ((M[i, 1] - m2 * M[i - 1, 1]) - m3 * M[i - 1, 2]) / M[i - 1, 0]
        M[i, 1] = m1
        M[i, 0] = _pivot(((M[i, 0] - m1 * m1) - m2 * m2) - m3 * m3, M[i, 0])
    return True


@njit(cache=True, nogil=True)
def band4_solve2(M, n, y, w):
    """``_band_solve`` for W = 4 on two right-hand sides at once (the same bits as two
    calls)."""
    for i in range(n):
        a = y[i]
        b = w[i]
        if i >= 1:
            a -= M[i, 1] * y[i - 1]
            b -= M[i, 1] * w[i - 1]
            if i >= 2:
                a -= M[i, 2] * y[i - 2]
                b -= M[i, 2] * w[i - 2]
                if i >= 3:
                    a -= M[i, 3] * y[i - 3]
                    b -= M[i, 3] * w[i - 3]
        y[i] = a / M[i, 0]
        w[i] = b / M[i, 0]
    for i in range(n - 1, -1, -1):
        a = y[i]
        b = w[i]
        if i + 1 < n:
            a -= M[i + 1, 1] * y[i + 1]
            b -= M[i + 1, 1] * w[i + 1]
            if i + 2 < n:
                a -= M[i + 2, 2] * y[i + 2]
                b -= M[i + 2, 2] * w[i + 2]
                if i + 3 < n:
                    a -= M[i + 3, 3] * y[i + 3]
                    b -= M[i + 3, 3] * w[i + 3]
        y[i] = a / M[i, 0]
        w[i] = b / M[i, 0]


@njit(cache=True, nogil=True)
def band4_solve1(M, n, y):
    """``_band_solve`` for W = 4, unrolled (the same float operations in the same order)."""
    for i in range(n):
        a = y[i]
        if i >= 1:
            a -= M[i, 1] * y[i - 1]
            if i >= 2:
                a -= M[i, 2] * y[i - 2]
                if i >= 3:
                    a -= M[i, 3] * y[i - 3]
        y[i] = a / M[i, 0]
    for i in range(n - 1, -1, -1):
        a = y[i]
        if i + 1 < n:
            a -= M[i + 1, 1] * y[i + 1]
            if i + 2 < n:
                a -= M[i + 2, 2] * y[i + 2]
                if i + 3 < n:
                    a -= M[i + 3, 3] * y[i + 3]
        y[i] = a / M[i, 0]


@njit(cache=True, nogil=True)
def _band_solve(M, n, W, y):
    """Solve (L L^T) x = y in place with the band factor M of ``_band_cholesky``. (The
    planners use ``band4_solve1``/``band4_solve2``; this is their tests' reference.)"""
    for i in range(n):
        acc = y[i]
        for d in range(1, W):
            j = i - d
            if j < 0:
                break
            acc -= M[i, d] * y[j]
        y[i] = acc / M[i, 0]
    for i in range(n - 1, -1, -1):
        acc = y[i]
        for d in range(1, W):
            j = i + d
            if j >= n:
                break
            acc -= M[j, d] * y[j]
        y[i] = acc / M[i, 0]


@njit(cache=True, nogil=True)
def _ax(first, coef, x, out):
    m, W = coef.shape
    for r in range(m):
        f = first[r]
        acc = 0.0
        for k in range(W):
            acc += coef[r, k] * x[f + k]
        out[r] = acc


@njit(cache=True, nogil=True)
def _steps(first, coef, dx, rp, s, inv_s, lam, rc, predictor, ds, dl, adx):
    """The steps ds = -r_p - A dx and dλ = (r_c - λ ds) / s of a direction dx (r_c = -λ s
    for the predictor, else ``rc``; ``inv_s`` = 1/s), A dx into ``adx``; returns the longest steps (α_s,
    α_λ) <= 1 keeping s and λ >= 0."""
    m = coef.shape[0]
    ap = 1.0
    ad = 1.0
    for r in range(m):
        f = first[r]
        acc = 0.0
        acc += coef[r, 0] * dx[f]
        acc += coef[r, 1] * dx[f + 1]
        acc += coef[r, 2] * dx[f + 2]
        acc += coef[r, 3] * dx[f + 3]
        adx[r] = acc
        d_s = -rp[r] - acc
        rcr = -lam[r] * s[r] if predictor else rc[r]
        d_l = (rcr - lam[r] * d_s) * inv_s[r]
        ds[r] = d_s
        dl[r] = d_l
        # the longest steps without a division per row: -s/Δs < α_s is s < -α_s Δs
        if s[r] < -ap * d_s:
            ap = -s[r] / d_s
        if lam[r] < -ad * d_l:
            ad = -lam[r] / d_l
    return ap, ad


@njit(cache=True, nogil=True)
def lp_solve(n, first, coef, b, c, x, max_iter, tol):
    """Minimise c·x subject to the banded rows (see module docstring).

    ``x`` (n,) is the start and receives the solution. Returns (status, iterations,
    multipliers λ (m,), slacks s (m,)).

    Each iteration makes five passes over the rows (they are most of its time): the
    residuals, the normal matrix and the predictor's right-hand side together; the
    predictor's step and its longest steps; its complementarity; the corrector's
    right-hand side; the corrector's step and its longest steps. The step itself is
    taken at the start of the next iteration's first pass, and A x is updated with the
    step's A dx rather than formed again. The rows are ``ROW_WIDTH`` wide (status
    BREAKDOWN otherwise).
    """
    m = coef.shape[0]
    W = ROW_WIDTH
    if coef.shape[1] != W:
        return BREAKDOWN, 0, np.ones(m), np.ones(m)
    s = np.empty(m)
    inv_s = np.empty(m)
    lam = np.ones(m)
    ax = np.empty(m)
    _ax(first, coef, x, ax)
    for r in range(m):
        v = b[r] - ax[r]
        s[r] = v if v > 1.0 else 1.0
    M = np.empty((n, W))
    rd = np.empty(n)
    rp = np.empty(m)
    rhs = np.empty(n)
    dx = np.empty(n)
    adx = np.zeros(m)  # A dx of the last step
    ds = np.zeros(m)
    dl = np.zeros(m)
    dsa = np.empty(m)
    dla = np.empty(m)
    rcs = np.empty(m)  # the corrector's r_c, for pass 5
    bnorm = 1.0
    for r in range(m):
        if abs(b[r]) > bnorm:
            bnorm = abs(b[r])
    cnorm = 1.0
    for i in range(n):
        if abs(c[i]) > cnorm:
            cnorm = abs(c[i])
    status = MAX_ITER
    ap = 0.0
    ad = 0.0
    it = 0
    for it in range(max_iter):
        # pass 1: take the last step; residuals, μ, A^T λ, the normal matrix A^T D A
        # (lower band, D = λ / s) and A^T of the predictor's right-hand side
        for i in range(n):
            rd[i] = 0.0
            rhs[i] = 0.0
            for d in range(W):
                M[i, d] = 0.0
        ep = 0.0
        mu = 0.0
        for r in range(m):
            sr = s[r] + ap * ds[r]
            lr = lam[r] + ad * dl[r]
            if sr < 1e-300:
                sr = 1e-300
            if lr < 1e-300:
                lr = 1e-300
            s[r] = sr
            lam[r] = lr
            axr = ax[r] + ap * adx[r]
            ax[r] = axr
            rpr = axr + sr - b[r]
            rp[r] = rpr
            if abs(rpr) > ep:
                ep = abs(rpr)
            mu += sr * lr
            # 1/s once per row and iteration, for passes 1, 2, 4 and 5: the solve made
            # five divisions per row and iteration before (19 % of its time on
            # zigzag_0.002_0.001's LPs)
            isr = 1.0 / sr
            inv_s[r] = isr
            dr = lr * isr
            tr = dr * rpr - lr  # predictor: r_c = -λ s
            f = first[r]
            # unrolled, zeros included (adding 0.0 leaves the sums' bits as they were):
            # 12 % of the solve's time on stellabee1's LPs
            c0 = coef[r, 0]
            c1 = coef[r, 1]
            c2 = coef[r, 2]
            c3 = coef[r, 3]
            rd[f] += c0 * lr
            rd[f + 1] += c1 * lr
            rd[f + 2] += c2 * lr
            rd[f + 3] += c3 * lr
            rhs[f] += c0 * tr
            rhs[f + 1] += c1 * tr
            rhs[f + 2] += c2 * tr
            rhs[f + 3] += c3 * tr
            a0 = c0 * dr
            a1 = c1 * dr
            a2 = c2 * dr
            a3 = c3 * dr
            M[f, 0] += a0 * c0
            M[f + 1, 1] += a1 * c0
            M[f + 1, 0] += a1 * c1
            M[f + 2, 2] += a2 * c0
            M[f + 2, 1] += a2 * c1
            M[f + 2, 0] += a2 * c2
            M[f + 3, 3] += a3 * c0
            M[f + 3, 2] += a3 * c1
            M[f + 3, 1] += a3 * c2
            M[f + 3, 0] += a3 * c3
        mu /= m
        ed = 0.0
        for i in range(n):
            rd[i] += c[i]
            if abs(rd[i]) > ed:
                ed = abs(rd[i])
        # the dual residual is limited by the conditioning of λ/s near the end (the
        # normal matrix's condition grows like 1/μ): a looser bound on it, and once the
        # complementarity is at rounding level nothing is left to gain
        if ep <= tol * bnorm and mu <= tol and (ed <= _DUAL_TOL * cnorm or mu <= _MU_FLOOR):
            status = OK
            break
        for i in range(n):  # relative to each diagonal entry: λ/s spans many decades
            M[i, 0] += _REG * M[i, 0] + 1e-300
        if not band4_cholesky(M, n):
            status = BREAKDOWN
            break
        # predictor (affine scaling)
        for i in range(n):
            dx[i] = -rd[i] - rhs[i]
        band4_solve1(M, n, dx)
        # pass 2: its steps in s and λ, and the longest steps keeping them >= 0
        ap, ad = _steps(first, coef, dx, rp, s, inv_s, lam, rcs, True, dsa, dla, adx)
        # pass 3: the complementarity it would reach
        mu_aff = 0.0
        for r in range(m):
            mu_aff += (s[r] + ap * dsa[r]) * (lam[r] + ad * dla[r])
        mu_aff /= m
        sigma = (mu_aff / mu) ** 3 if mu > 0.0 else 0.0
        # pass 4: corrector, r_c = -λ s - Δs_aff Δλ_aff + σ μ
        for i in range(n):
            rhs[i] = 0.0
        for r in range(m):
            rc = -lam[r] * s[r] - dsa[r] * dla[r] + sigma * mu
            rcs[r] = rc
            tr = (rc + lam[r] * rp[r]) * inv_s[r]
            f = first[r]
            rhs[f] += coef[r, 0] * tr
            rhs[f + 1] += coef[r, 1] * tr
            rhs[f + 2] += coef[r, 2] * tr
            rhs[f + 3] += coef[r, 3] * tr
        for i in range(n):
            dx[i] = -rd[i] - rhs[i]
        band4_solve1(M, n, dx)
        # pass 5: the corrected steps and the longest steps (taken in the next pass 1)
        ap, ad = _steps(first, coef, dx, rp, s, inv_s, lam, rcs, False, ds, dl, adx)
        ap = min(1.0, _TO_BOUNDARY * ap)
        ad = min(1.0, _TO_BOUNDARY * ad)
        for i in range(n):
            x[i] += ap * dx[i]
    if status == MAX_ITER:  # the last step is not yet in s and λ
        for r in range(m):
            s[r] = max(s[r] + ap * ds[r], 1e-300)
            lam[r] = max(lam[r] + ad * dl[r], 1e-300)
    return status, it, lam, s

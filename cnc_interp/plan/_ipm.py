"""A primal-dual interior-point solver for banded linear programs (numba).

    minimise  c·x   subject to   A x <= b

Every row of A touches at most ``W`` consecutive variables: row r is
``sum_k coef[r, k] * x[first[r] + k] <= b[r]`` (k < W; ``first[r] + W <= n``, unused
entries zero). The feed-profile LP of ``optimal_ref`` has this shape (a B-spline's
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

# status codes
OK = 0
MAX_ITER = 1
BREAKDOWN = 2

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


@njit(cache=True)
def _band_cholesky(M, n, W):
    """In-place Cholesky of the SPD band matrix M (n, W): M[i, d] = M(i, i-d). False when
    a pivot is not positive."""
    for i in range(n):
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
                if not acc > _PIVOT_TOL * M[i, 0] or not acc > 0.0:
                    # a direction the rows do not determine (rounding has eaten the pivot):
                    # freeze it with a huge pivot, as interior-point codes do
                    acc = _HUGE_PIVOT
                M[i, 0] = np.sqrt(acc)
            else:
                M[i, d] = acc / M[j, 0]
    return True


@njit(cache=True)
def _band_solve(M, n, W, y):
    """Solve (L L^T) x = y in place with the band factor M of ``_band_cholesky``."""
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


@njit(cache=True)
def _ax(first, coef, x, out):
    m, W = coef.shape
    for r in range(m):
        f = first[r]
        acc = 0.0
        for k in range(W):
            acc += coef[r, k] * x[f + k]
        out[r] = acc


@njit(cache=True)
def _atx(first, coef, y, n, out):
    m, W = coef.shape
    for i in range(n):
        out[i] = 0.0
    for r in range(m):
        f = first[r]
        yr = y[r]
        for k in range(W):
            out[f + k] += coef[r, k] * yr


@njit(cache=True)
def _max_step(v, dv):
    """Largest α in (0, 1] keeping v + α dv >= 0 (before the boundary fraction)."""
    a = 1.0
    for i in range(v.shape[0]):
        if dv[i] < 0.0:
            t = -v[i] / dv[i]
            if t < a:
                a = t
    return a


@njit(cache=True)
def lp_solve(n, first, coef, b, c, x, max_iter, tol):
    """Minimise c·x subject to the banded rows (see module docstring).

    ``x`` (n,) is the start and receives the solution. Returns (status, iterations,
    multipliers λ (m,), slacks s (m,)).
    """
    m, W = coef.shape
    s = np.empty(m)
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
    tmp = np.empty(m)
    dx = np.empty(n)
    ds = np.empty(m)
    dl = np.empty(m)
    dsa = np.empty(m)
    dla = np.empty(m)
    bnorm = 1.0
    for r in range(m):
        if abs(b[r]) > bnorm:
            bnorm = abs(b[r])
    cnorm = 1.0
    for i in range(n):
        if abs(c[i]) > cnorm:
            cnorm = abs(c[i])
    status = MAX_ITER
    it = 0
    for it in range(max_iter):
        _ax(first, coef, x, ax)
        _atx(first, coef, lam, n, rd)
        ep = 0.0
        for r in range(m):
            rp[r] = ax[r] + s[r] - b[r]
            if abs(rp[r]) > ep:
                ep = abs(rp[r])
        ed = 0.0
        for i in range(n):
            rd[i] += c[i]
            if abs(rd[i]) > ed:
                ed = abs(rd[i])
        mu = 0.0
        for r in range(m):
            mu += s[r] * lam[r]
        mu /= m
        # the dual residual is limited by the conditioning of λ/s near the end (the
        # normal matrix's condition grows like 1/μ): a looser bound on it, and once the
        # complementarity is at rounding level nothing is left to gain
        if ep <= tol * bnorm and mu <= tol and (ed <= _DUAL_TOL * cnorm or mu <= _MU_FLOOR):
            status = OK
            break
        # normal matrix A^T D A (lower band), D = λ / s
        for i in range(n):
            for d in range(W):
                M[i, d] = 0.0
        for r in range(m):
            f = first[r]
            dr = lam[r] / s[r]
            for a in range(W):
                ca = coef[r, a] * dr
                if ca == 0.0:
                    continue
                for bb in range(a + 1):
                    M[f + a, a - bb] += ca * coef[r, bb]
        for i in range(n):  # relative to each diagonal entry: λ/s spans many decades
            M[i, 0] += _REG * M[i, 0] + 1e-300
        if not _band_cholesky(M, n, W):
            status = BREAKDOWN
            break
        # predictor (affine scaling): r_c = -λ s
        for r in range(m):
            tmp[r] = (-lam[r] * s[r] + lam[r] * rp[r]) / s[r]
        _atx(first, coef, tmp, n, rhs)
        for i in range(n):
            dx[i] = -rd[i] - rhs[i]
        _band_solve(M, n, W, dx)
        _ax(first, coef, dx, ds)
        for r in range(m):
            dsa[r] = -rp[r] - ds[r]
            dla[r] = (-lam[r] * s[r] - lam[r] * dsa[r]) / s[r]
        ap = _max_step(s, dsa)
        ad = _max_step(lam, dla)
        mu_aff = 0.0
        for r in range(m):
            mu_aff += (s[r] + ap * dsa[r]) * (lam[r] + ad * dla[r])
        mu_aff /= m
        sigma = (mu_aff / mu) ** 3 if mu > 0.0 else 0.0
        # corrector: r_c = -λ s - Δs_aff Δλ_aff + σ μ
        for r in range(m):
            rc = -lam[r] * s[r] - dsa[r] * dla[r] + sigma * mu
            tmp[r] = (rc + lam[r] * rp[r]) / s[r]
        _atx(first, coef, tmp, n, rhs)
        for i in range(n):
            dx[i] = -rd[i] - rhs[i]
        _band_solve(M, n, W, dx)
        _ax(first, coef, dx, ds)
        for r in range(m):
            rc = -lam[r] * s[r] - dsa[r] * dla[r] + sigma * mu
            ds[r] = -rp[r] - ds[r]
            dl[r] = (rc - lam[r] * ds[r]) / s[r]
        ap = min(1.0, _TO_BOUNDARY * _max_step(s, ds))
        ad = min(1.0, _TO_BOUNDARY * _max_step(lam, dl))
        for i in range(n):
            x[i] += ap * dx[i]
        for r in range(m):
            s[r] += ap * ds[r]
            lam[r] += ad * dl[r]
            if s[r] < 1e-300:
                s[r] = 1e-300
            if lam[r] < 1e-300:
                lam[r] = 1e-300
    return status, it, lam, s

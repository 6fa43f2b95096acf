"""The one Horner evaluation of a power-basis quintic piece and its first two derivatives,
shared by the compiled kernels of the fit (distance search) and the planner (joint table)."""

from __future__ import annotations

from numba import njit


@njit(cache=True, inline="always")
def quintic_d012(coef, k, a, t):
    """Value, first and second derivative at local parameter t of axis a of piece k of
    ``coef`` (S, 6, n) power coefficients, by Horner (inlined: it sits in inner loops)."""
    v0 = coef[k, 5, a]
    v1 = 5.0 * coef[k, 5, a]
    v2 = 20.0 * coef[k, 5, a]
    for j in range(4, -1, -1):
        v0 = v0 * t + coef[k, j, a]
        if j >= 1:
            v1 = v1 * t + j * coef[k, j, a]
        if j >= 2:
            v2 = v2 * t + j * (j - 1) * coef[k, j, a]
    return v0, v1, v2

"""The one Horner evaluation of a power-basis quintic and its first two derivatives,
shared by the compiled kernels of the fit (distance search) and the planner (the joint
table, VPOp's step loop, the refinement).

``quintic`` takes the six coefficients as numbers, so each caller reads them in its own
layout (the fit's (S, 6, n), the step loop's axis-major (m, n, 6), one cache line an
axis) and all of them run the same float operations in the same order. It is inlined
where it is called: the outputs a caller does not use are dropped by the compiler.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True, inline="always")
def quintic(c0, c1, c2, c3, c4, c5, t):
    """Value, first and second derivative at t of c0 + c1 t + ... + c5 t⁵, by Horner."""
    v0 = ((((c5 * t + c4) * t + c3) * t + c2) * t + c1) * t + c0
    v1 = (((5.0 * c5 * t + 4.0 * c4) * t + 3.0 * c3) * t + 2.0 * c2) * t + c1
    v2 = ((20.0 * c5 * t + 12.0 * c4) * t + 6.0 * c3) * t + 2.0 * c2
    return v0, v1, v2


@njit(cache=True, inline="always")
def quintic_d012(coef, k, a, t):
    """``quintic`` at local parameter t of axis a of piece k of ``coef`` (S, 6, n) power
    coefficients."""
    return quintic(coef[k, 0, a], coef[k, 1, a], coef[k, 2, a], coef[k, 3, a], coef[k, 4, a], coef[k, 5, a], t)

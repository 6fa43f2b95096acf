"""Compiled G2/G3 arcs: evaluation (``curves.CurveEval``'s arithmetic) and a run's arc table.

``arc_param_scales`` / ``arc_end_derivs``: the parameter scale g (``curves.param_scale``) and the end
derivatives (``curves.end_states``) of every arc of a run at once, for the corner split
and the compiled batch fitter (``_subrun``), instead of a ``CurveEval`` per arc. The
squares there are Python's / numpy scalars' ``x ** 2``, i.e. the C library's ``pow``
(which differs from ``x * x`` in the last bit now and then): ``curves.arc_table``
computes them between the two kernels, so the values are the Python code's bits.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from ._npexact import blas_dot, pairwise_sum

#: the run's arcs (A of them) as ``curves.CurveEval`` holds them: nodes first/last (run
#: indices), block line, quarter-turn pieces nq, start / end - start (A, d), centre
#: (A, 2), plane (A, 2) axis indices, sweep (rad), start angle a0, radii r0 / r1, the
#: parameter scale g (``curves.param_scale``), end states (A, 4, d): T0, K0, T1, K1
#: (``curves.end_states``), and ok: the values are the Python code's (False: not an arc,
#: or one the Python code treats specially, see ``curves.arc_table``)
ArcArrays = namedtuple("ArcArrays", "first last line nq start delta center plane sweep a0 r0 r1 g ends ok")


#: points per quarter-turn piece of the chord sum that gives g (``curves.param_scale``)
_G_SAMPLES = 64


@njit(cache=True, error_model="numpy")
def linspace(start, stop, num):
    """``np.linspace(start, stop, num)``: i * step + start, the last value exactly ``stop``."""
    out = np.empty(num)
    div = num - 1
    delta = stop - start
    if div > 0:
        step = delta / div
        for i in range(num):
            if step == 0.0:
                out[i] = i / div * delta + start
            else:
                out[i] = i * step + start
        out[num - 1] = stop
    else:
        for i in range(num):
            out[i] = i * delta + start
    return out


@njit(cache=True, error_model="numpy")
def arc_eval(arcs, c, w, P, P1, P2):
    """``CurveEval.eval`` of arc c at w (K,) into P, P1, P2 (K, d); P1 / P2 may be None-like
    (size 0) when only positions are wanted."""
    i = arcs.plane[c, 0]
    j = arcs.plane[c, 1]
    sw = arcs.sweep[c]
    a0 = arcs.a0[c]
    r0 = arcs.r0[c]
    r1 = arcs.r1[c]
    cx = arcs.center[c, 0]
    cy = arcs.center[c, 1]
    dr = r1 - r0
    d = P.shape[1]
    derivs = P1.shape[0] > 0
    for k in range(w.shape[0]):
        wk = w[k]
        ang = a0 + sw * wk
        r = r0 + (r1 - r0) * wk
        co = np.cos(ang)
        si = np.sin(ang)
        for a in range(d):
            P[k, a] = arcs.start[c, a] + arcs.delta[c, a] * wk
        P[k, i] = cx + r * co
        P[k, j] = cy + r * si
        if derivs:
            for a in range(d):
                P1[k, a] = arcs.delta[c, a]
                P2[k, a] = 0.0
            P1[k, i] = dr * co - r * sw * si
            P1[k, j] = dr * si + r * sw * co
            P2[k, i] = -2.0 * dr * sw * si - r * sw * sw * co
            P2[k, j] = 2.0 * dr * sw * co - r * sw * sw * si


@njit(cache=True, error_model="numpy", nogil=True)
def arc_param_scales(arcs):
    """``curves.param_scale`` of every arc (scale 1): its length from a chord sum over
    ``_G_SAMPLES`` points per piece, over its parameter range 1. (g (A,), ok (A,)): not
    ok where the length is not positive (the Python code raises there)."""
    A = arcs.nq.shape[0]
    d = arcs.start.shape[1]
    g = np.ones(A)
    ok = np.ones(A, dtype=np.bool_)
    empty = np.empty((0, d))
    buf = np.empty(max(d, 8))
    for c in range(A):
        nw = _G_SAMPLES * arcs.nq[c] + 1
        P = np.empty((nw, d))
        arc_eval(arcs, c, linspace(0.0, 1.0, nw), P, empty, empty)
        lens = np.empty(nw - 1)
        for k in range(nw - 1):
            for a in range(d):
                e = P[k + 1, a] - P[k, a]
                buf[a] = e * e
            lens[k] = np.sqrt(0.0 + pairwise_sum(buf, 0, d))
        length = 0.0 + pairwise_sum(lens, 0, nw - 1)
        if not length > 0:
            ok[c] = False
            continue
        g[c] = length / (1.0 - 0.0)
    return g, ok


@njit(cache=True, error_model="numpy", nogil=True)
def arc_end_derivs(arcs, g, g2, min_speed, ok):
    """``curves._derivs`` / ``end_states`` at both ends of every arc (scale 1), up to the
    curvature's division by the squared speed: (unit tangents T (A, 2, d), accelerations
    (A, 2, d), speeds (A, 2), A·T (A, 2), ok (A,)); g2 = g ** 2 as Python computes it. Not
    ok where the parameter speed vanishes (the Python code turns to the direction of
    travel there); arcs not ``ok`` on entry are skipped."""
    A = arcs.nq.shape[0]
    d = arcs.start.shape[1]
    T = np.zeros((A, 2, d))
    acc = np.zeros((A, 2, d))
    sp = np.ones((A, 2))
    at = np.zeros((A, 2))
    ok = ok.copy()
    w = np.array([0.0, 1.0])
    P = np.empty((2, d))
    P1 = np.empty((2, d))
    P2 = np.empty((2, d))
    V = np.empty(d)
    buf = np.empty(max(d, 8))
    for c in range(A):
        if not ok[c]:
            continue
        arc_eval(arcs, c, w, P, P1, P2)
        for e in range(2):
            for a in range(d):
                V[a] = P1[e, a] / g[c]
                acc[c, e, a] = P2[e, a] / g2[c]
                buf[a] = V[a] * V[a]
            if np.sqrt(0.0 + pairwise_sum(buf, 0, d)) < min_speed:
                ok[c] = False
            sp[c, e] = np.sqrt(blas_dot(V, V))
            for a in range(d):
                T[c, e, a] = V[a] / sp[c, e]
            at[c, e] = blas_dot(acc[c, e], T[c, e])
    return T, acc, sp, at, ok

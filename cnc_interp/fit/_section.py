"""``nodes.fit_polyline`` in one compiled call: the section's check points and data, the
knot-insertion rounds (``_bspline.refine``), the node deviations and the power-basis
pieces (``nodes._to_pieces``: the spline's values and derivatives at its knots, each span
the quintic Hermite of them, and each segment's source line and feed).

Stellabee-like programs fit ~10⁵ sections of a few nodes each; the numpy glue around the
rounds cost more than the rounds. The arithmetic is ``fit_polyline``'s, operation for
operation (numpy's sums and powers through ``_npexact``), so the pieces are the same bits.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from ._bspline import (
    FitData,
    FitNodes,
    RefineParams,
    evaluate,
    evaluate012,
    refine,
    segment_sources_kernel,
)
from ._npexact import powers345, pairwise_sum

#: one section of programmed nodes (n, d) in machine units, with per node the tolerance
#: (mm, of the move ending there), source line and feed
SectionNodes = namedtuple("SectionNodes", "nodes tol_mm line feed")

#: the fitter's settings for a section: ``tol_deg`` (rotary tolerance), ``lin`` /
#: ``metric`` (d,) bool axis masks, ``tol_ref`` (mm, the rotary axes' metric scale),
#: then ``nodes.py``'s constants: tol_safety, between_safety, smoothing, ridge,
#: min_ratio, stop_ratio, max_rounds, stale_rounds, min_span_rel, initial_step
SectionParams = namedtuple(
    "SectionParams",
    "tol_deg lin metric tol_ref tol_safety between_safety smoothing ridge min_ratio stop_ratio "
    "max_rounds stale_rounds min_span_rel initial_step",
)

#: the fitted pieces of a section: breaks (S+1,), coef (S, 6, d) machine units, line and
#: feed (S,), worst node deviations (mm, deg), every check passed
SectionFit = namedtuple("SectionFit", "breaks coef line feed max_mm max_deg ok")

#: fractions of every chord that are check points and data (``nodes._FRACS``)
_N_FRACS = 7


@njit(cache=True, error_model="numpy")
def hermite_into(coef, k, p, v, acc, i, dp, hp):
    """``nodes.hermite`` for one piece k: the quintic on [0, h] from the values (rows i and
    i + 1 of p, v, acc: position, first and second derivative); dp (d,) = p[i + 1] - p[i]
    (or a more accurate difference), hp = (h, h³, h⁴, h⁵) as ``powers345`` gives them."""
    h, h3, h4, h5 = hp
    hh2 = h * h
    j = i + 1
    for a in range(coef.shape[2]):
        v0, v1, a0, a1 = v[i, a], v[j, a], acc[i, a], acc[j, a]
        coef[k, 0, a] = p[i, a]
        coef[k, 1, a] = v0
        coef[k, 2, a] = 0.5 * a0
        coef[k, 3, a] = (20.0 * dp[a] - (8.0 * v1 + 12.0 * v0) * h - (3.0 * a0 - a1) * hh2) / (2.0 * h3)
        coef[k, 4, a] = (-30.0 * dp[a] + (14.0 * v1 + 16.0 * v0) * h + (3.0 * a0 - 2.0 * a1) * hh2) / (2.0 * h4)
        coef[k, 5, a] = (12.0 * dp[a] - 6.0 * (v1 + v0) * h - (a0 - a1) * hh2) / (2.0 * h5)


@njit(cache=True, error_model="numpy", nogil=True)
def fit_section(sec, ends, prm):
    """``nodes.fit_polyline`` of the nodes ``sec`` (``SectionNodes``) with the end states
    ``ends`` (``_bspline.EndStates`` in the scaled metric; mode 0: free) and settings
    ``prm`` (``SectionParams``): a ``SectionFit``."""
    nodes = sec.nodes
    n, d = nodes.shape
    lin = prm.lin
    metric = prm.metric
    tol_ref = prm.tol_ref
    scale = np.empty(d)
    n_rot = 0
    rot_scale = 1.0  # scale[~lin].max(initial=1.0)
    for a in range(d):
        if lin[a]:
            scale[a] = 1.0
        else:
            scale[a] = tol_ref / prm.tol_deg
            n_rot += 1
            rot_scale = max(rot_scale, scale[a])
    # relative to the first node: differences of large absolute coordinates lose digits
    y = np.empty((n, d))
    for i in range(n):
        for a in range(d):
            y[i, a] = (nodes[i, a] - nodes[0, a]) * scale[a]
    chords = np.empty((n - 1, d))
    clen = np.empty(n - 1)
    metric_len = np.empty(n - 1)
    sq = np.empty(d)
    u = np.empty(n)
    u[0] = 0.0
    for i in range(n - 1):
        nm = 0
        for a in range(d):
            chords[i, a] = y[i + 1, a] - y[i, a]
            sq[a] = chords[i, a] * chords[i, a]
        clen[i] = np.sqrt(0.0 + pairwise_sum(sq, 0, d))
        for a in range(d):
            if metric[a]:
                sq[nm] = chords[i, a] * chords[i, a]
                nm += 1
        metric_len[i] = np.sqrt(0.0 + pairwise_sum(sq, 0, nm))
        u[i + 1] = u[i] + clen[i]
    total = u[n - 1]
    tol = np.empty(n)
    for i in range(n):
        tol[i] = sec.tol_mm[i] * prm.tol_safety
    tol_rot = prm.tol_deg * prm.tol_safety * rot_scale if n_rot > 0 else np.inf

    if n == 2 and ends.start_mode == 0 and ends.end_mode == 0:
        return _straight(nodes, total, sec.line[1], sec.feed[1])

    lin_ratio = np.empty(n - 1)
    for i in range(n - 1):
        lin_ratio[i] = metric_len[i] / clen[i]
    nf = _N_FRACS
    P0 = n + (n - 1) * nf
    xc0 = np.empty(P0)
    ref0 = np.empty((P0, d))
    tol_c0 = np.empty(P0)
    exp_lin0 = np.empty(P0)
    w_data0 = np.empty(P0)
    for i in range(n):
        xc0[i] = u[i]
        for a in range(d):
            ref0[i, a] = y[i, a]
        tol_c0[i] = tol[i]
        w_data0[i] = tol_ref / max(tol[i], 1e-12)
    exp_lin0[0] = lin_ratio[0]
    exp_lin0[n - 1] = lin_ratio[n - 2]
    for i in range(1, n - 1):
        exp_lin0[i] = min(lin_ratio[i - 1], lin_ratio[i])
    q = n
    for i in range(n - 1):
        # between the nodes the deviation is only sampled: keep a margin there
        tol_ch = tol[i + 1] * prm.between_safety
        for f in range(nf):
            fr = (f + 1) / 8.0
            xc0[q] = u[i] + clen[i] * fr
            for a in range(d):
                ref0[q, a] = y[i, a] + chords[i, a] * fr
            tol_c0[q] = tol_ch
            exp_lin0[q] = lin_ratio[i]
            # chord points are data too (else a span without nodes follows only the smoothing)
            w_data0[q] = 0.5 * tol_ref / (tol_ch + 1e-12)
            q += 1
    span_f = np.empty(6)
    for f in range(6):
        span_f[f] = (f + 1) / 7.0

    step = prm.initial_step
    n_int = 0
    for i in range(step, n - 1, step):
        n_int += 1
    interior = np.empty(n_int)
    for k in range(n_int):
        interior[k] = u[step * (k + 1)]
    if n_int > 0:
        before = interior[n_int - 2] if n_int > 1 else 0.0
        if total - interior[n_int - 1] < 0.5 * (interior[n_int - 1] - before):
            interior = interior[: n_int - 1].copy()
    # a knot (a segment boundary) wherever the programmed feed changes
    feed = sec.feed
    n_brk = 0
    for i in range(1, n - 1):
        if feed[i] != feed[i + 1]:
            n_brk += 1
    if n_brk > 0:
        extra = np.empty(interior.shape[0] + n_brk)
        extra[: interior.shape[0]] = interior
        j = interior.shape[0]
        for i in range(1, n - 1):
            if feed[i] != feed[i + 1]:
                extra[j] = u[i]
                j += 1
        interior = np.unique(extra)
    # where rotary axes move, at most one segment per move
    rotary_moves = False
    for a in range(d):
        if not lin[a]:
            lo = nodes[0, a]
            hi = nodes[0, a]
            for i in range(1, n):
                lo = min(lo, nodes[i, a])
                hi = max(hi, nodes[i, a])
            if hi - lo > 0:
                rotary_moves = True
    t, m, c, ok = refine(
        FitNodes(u, y, tol, chords, clen, lin_ratio),
        interior,
        total,
        ends,
        FitData(xc0, ref0, tol_c0, exp_lin0, w_data0, span_f),
        RefineParams(
            tol_ref,
            tol_rot,
            lin,
            metric,
            prm.between_safety,
            prm.smoothing,
            prm.ridge,
            prm.min_ratio,
            prm.stop_ratio,
            prm.max_rounds,
            prm.stale_rounds,
            prm.min_span_rel * total,
            n - 2 if rotary_moves else -1,
        ),
    )
    val = np.empty((n, d))
    der = np.empty((n, d))
    evaluate(t, m, c, u, val, der)
    max_mm = 0.0
    max_deg = 0.0
    for i in range(n):
        nl = 0
        for a in range(d):
            e = val[i, a] - y[i, a]
            if lin[a]:
                sq[nl] = e * e
                nl += 1
            else:
                max_deg = max(max_deg, abs(e / scale[a]))
        if nl > 0:
            max_mm = max(max_mm, np.sqrt(0.0 + pairwise_sum(sq, 0, nl)))
    for i in range(m):
        for a in range(d):
            c[i, a] = c[i, a] / scale[a]
    return _pieces(t, m, c, u, sec, ends, scale, max_mm, max_deg, ok)


@njit(cache=True, error_model="numpy")
def _straight(nodes, length, line, feed):
    """``nodes.straight_piece`` of a two-node section."""
    d = nodes.shape[1]
    coef = np.zeros((1, 6, d))
    for a in range(d):
        coef[0, 0, a] = nodes[0, a]
        coef[0, 1, a] = (nodes[1, a] - nodes[0, a]) / length
    breaks = np.empty(2)
    breaks[0] = 0.0
    breaks[1] = length
    return SectionFit(breaks, coef, np.full(1, line), np.full(1, feed), 0.0, 0.0, True)


@njit(cache=True, error_model="numpy")
def _pieces(t, m, c, u, sec, ends, scale, max_mm, max_deg, ok):
    """``nodes._to_pieces``: each knot span as the quintic Hermite of the spline's q, q', q''
    at its two knots, with the exact end nodes and imposed end derivatives."""
    nodes = sec.nodes
    n, d = nodes.shape
    x = np.unique(t)
    nx = x.shape[0]
    d0 = np.empty((nx, d))
    d1 = np.empty((nx, d))
    d2 = np.empty((nx, d))
    evaluate012(t, m, c, x, d0, d1, d2)
    for i in range(nx):
        for a in range(d):
            d0[i, a] += nodes[0, a]
    for a in range(d):
        d0[0, a] = nodes[0, a]
        d0[nx - 1, a] = nodes[n - 1, a]
    if ends.start_mode == 1:
        for a in range(d):
            d1[0, a] = ends.d1s[a] / scale[a]
            d2[0, a] = ends.d2s[a] / scale[a]
    if ends.end_mode == 1:
        for a in range(d):
            d1[nx - 1, a] = ends.d1e[a] / scale[a]
            d2[nx - 1, a] = ends.d2e[a] / scale[a]
    h = np.empty(nx - 1)
    for k in range(nx - 1):
        h[k] = x[k + 1] - x[k]
    h3, h4, h5 = powers345(h)
    coef = np.empty((nx - 1, 6, d))
    dp = np.empty(d)
    for k in range(nx - 1):
        for a in range(d):
            dp[a] = d0[k + 1, a] - d0[k, a]
        hermite_into(coef, k, d0, d1, d2, k, dp, (h[k], h3[k], h4[k], h5[k]))
    seg_line, seg_feed = segment_sources_kernel(x, u, sec.line, sec.feed)
    breaks = np.empty(nx)
    for k in range(nx):
        breaks[k] = x[k] - x[0]
    return SectionFit(breaks, coef, seg_line, seg_feed, max_mm, max_deg, ok)

"""A batch of sub-runs fitted and measured in one compiled call.

``fitter._fit_measured`` for a run on linear axes only (the default N-axis fit): the
sub-run's sections (``fitter._fit_sections``: polylines, corner blends, the exact
moves between blends and G2/G3 arcs, joined G2), the arcs' quintic pieces
(``curves.fit_curve``), the polylines' B-splines (``_section.fit_section``) and the
measurement of the programmed path against the fit (``deviation.path_deviation`` /
``polyline_deviation``). Stellabee-like programs have ~10⁴ sub-runs of ~15 sections
each: in Python that was ~2 ms of glue per sub-run around the compiled kernels.

Every float operation is the Python code's, in the same order, with numpy's own
summation, dot products and vector powers (``_npexact``), so the paths are the same
bits. What this kernel does not cover (a NURBS, rotary axes, an arc whose parameter
speed vanishes, a fit the measurement finds outside: its repair) is left to the
Python code, which gives the same first fit.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit
from numba.typed import List

from ._arcs import arc_eval, linspace
from ._bspline import EndStates
from ._linedev import polyline_path_deviation
from ._npexact import blas_dot, numpy_arc_terms, numpy_powers, pairwise_sum
from ._project import march_feet, median
from ._section import SectionFit, SectionNodes, SectionParams, fit_section, hermite_into

#: the prepared run: nodes (N, d) (every axis linear), the fitter's tolerance per node
#: (``corners.fit_tolerance``: G61's 0 replaced), line and feed per node
RunArrays = namedtuple("RunArrays", "nodes tol line feed")

#: the run's blended corners (``blends.BlendTable``'s arrays)
BlendArrays = namedtuple("BlendArrays", "i h coef line feed t_in t_out")

#: the batch's sub-runs (B): nodes i0..i1 and their ranges of blends and arcs
SubRunTable = namedtuple("SubRunTable", "i0 i1 blend_lo blend_hi arc_lo arc_hi")

#: ``curves.py``'s constants: tol_safety, check_points, max_depth, min_speed,
#: min_piece_speed, small_piece and the 8-point Gauss-Legendre rule gl_x / gl_w
CurveParams = namedtuple(
    "CurveParams", "tol_safety check_points max_depth min_speed min_piece_speed small_piece gl_x gl_w"
)

#: the batch's settings: ``section`` (``_section.SectionParams``; its tol_ref is set per
#: sub-run), ``curve`` (``CurveParams``), ``deviation`` (``_linedev.DeviationSettings``)
BatchParams = namedtuple("BatchParams", "section curve deviation")

#: the batch's fits: status (B,) 0 fitted and measured here, 1 left to Python; each
#: sub-run's segments seg_off[s]:seg_off[s + 1] of coef / line / feed and its breaks
#: breaks[seg_off[s] + s : seg_off[s + 1] + s + 1]; worst node deviations dmm / ddeg,
#: fit_ok (every check of the fitters passed), the measured pdev (mm) and pratio
BatchFits = namedtuple("BatchFits", "status seg_off breaks coef line feed dmm ddeg fit_ok pdev pratio")

_POLY = 0
_CURVE = 1
_BLEND = 2

#: status of a sub-run left to the Python code (an arc's parameter speed vanishes)
STATUS_PYTHON = 1


@njit(cache=True, error_model="numpy")
def _row_sumsq(x, i, buf):
    """numpy's ``(x[i] ** 2).sum()`` of a row of x (n, d); ``buf`` (>= d) scratch."""
    d = x.shape[1]
    for a in range(d):
        buf[a] = x[i, a] * x[i, a]
    return 0.0 + pairwise_sum(buf, 0, d)


@njit(cache=True, error_model="numpy")
def _horner(coef, k, a, t):
    """``curves._polyval``: coef[k, :, a] at t."""
    acc = coef[k, 5, a]
    for i in range(4, -1, -1):
        acc = acc * t + coef[k, i, a]
    return acc


@njit(cache=True, error_model="numpy")
def _horner_d(coef, k, a, t):
    """``curves._polyval`` of ``curves._derivative(coef)``: the t-derivative at t (its
    padded zero coefficient first, as numpy runs it)."""
    acc = 0.0
    for i in range(4, -1, -1):
        acc = acc * t + coef[k, i + 1, a] * (i + 1.0)
    return acc


@njit(cache=True, error_model="numpy")
def fit_arc(arcs, c, ends, lin, tol_mm, tol_deg, line, feed, cp):
    """``curves.fit_curve`` of arc c (``ArcArrays``) on linear axes only (scale 1), with the
    imposed end tangent / curvature ``ends`` (``_bspline.EndStates``): (``SectionFit``,
    status), status ``STATUS_PYTHON`` where the arc's parameter speed vanishes
    (``curves._direction``'s case, left to Python)."""
    d = arcs.start.shape[1]
    g = arcs.g[c]
    wb = linspace(0.0, 1.0, arcs.nq[c] + 1)
    tl = tol_mm * cp.tol_safety
    tr = tol_deg * cp.tol_safety
    M = cp.check_points
    G = cp.gl_x.shape[0]
    tfr = np.empty(M)
    for i in range(M):
        tfr[i] = (i + 1) / (M + 1)
    buf = np.empty(max(d, 8))
    max_mm = 0.0
    max_deg = 0.0
    ok = True
    empty = np.empty((0, d))
    coef = np.empty((0, 6, d))
    h = np.empty(0)
    for depth in range(cp.max_depth + 1):
        nb = wb.shape[0]
        npc = nb - 1
        # _geometric: position, unit tangent, curvature vector, dw/dσ and d²w/dσ²
        Ps = np.empty((nb, d))
        V = np.empty((nb, d))
        A = np.empty((nb, d))
        arc_eval(arcs, c, wb, Ps, V, A)
        sp = np.empty(nb)
        for k in range(nb):
            sp[k] = np.sqrt(_row_sumsq(V, k, buf))
            if sp[k] < cp.min_speed * g:
                return SectionFit(h, coef, np.empty(0, dtype=np.int64), h, 0.0, 0.0, False), STATUS_PYTHON
        T = np.empty((nb, d))
        K = np.empty((nb, d))
        at = np.empty(nb)
        wd1 = np.empty((nb, 1))
        for k in range(nb):
            for a in range(d):
                T[k, a] = V[k, a] / sp[k]
                buf[a] = A[k, a] * T[k, a]
            at[k] = 0.0 + pairwise_sum(buf, 0, d)
            s2 = sp[k] * sp[k]
            for a in range(d):
                K[k, a] = (A[k, a] - at[k] * T[k, a]) / s2
            wd1[k, 0] = 1.0 / sp[k]
        # _piece_lengths: 8-point Gauss-Legendre of the speed and the displacement
        wa = wb[:-1]
        wz = wb[1:]
        half = np.empty(npc)
        wq = np.empty(npc * G)
        for k in range(npc):
            mid = 0.5 * (wa[k] + wz[k])
            half[k] = 0.5 * (wz[k] - wa[k])
            for q in range(G):
                wq[k * G + q] = mid + half[k] * cp.gl_x[q]
        Pq = np.empty((npc * G, d))
        D1 = np.empty((npc * G, d))
        D2 = np.empty((npc * G, d))
        arc_eval(arcs, c, wq, Pq, D1, D2)
        sp8 = np.empty((npc, G))
        for k in range(npc):
            for q in range(G):
                sp8[k, q] = np.sqrt(_row_sumsq(D1, k * G + q, buf))
        sp3, quad = numpy_arc_terms(sp, sp8, cp.gl_w)
        wd2 = np.empty((nb, 1))
        for k in range(nb):
            wd2[k, 0] = -at[k] / sp3[k]
        pa = np.empty((npc, d))
        pz = np.empty((npc, d))
        arc_eval(arcs, c, wa, pa, empty, empty)
        arc_eval(arcs, c, wz, pz, empty, empty)
        h = np.empty(npc)
        dp = np.empty((npc, d))
        dpd = np.empty((npc, d))
        for k in range(npc):
            for a in range(d):
                dpd[k, a] = pz[k, a] - pa[k, a]
            chord = np.sqrt(_row_sumsq(dpd, k, buf))
            big = abs(pa[k, 0])
            for a in range(1, d):
                big = max(big, abs(pa[k, a]))
            small = chord < cp.small_piece * max(1.0, big)
            for a in range(d):
                if small:
                    acc = 0.0
                    for q in range(G):
                        acc += D1[k * G + q, a] * cp.gl_w[q]
                    dp[k, a] = half[k] * acc
                else:
                    dp[k, a] = dpd[k, a]
            h[k] = max(half[k] * quad[k], chord)
        h3, h4, h5 = numpy_powers(h)
        # unit-speed pieces q(τ) ≈ P(w(τ)) with w(τ) the Hermite of the reparametrisation
        if ends.start_mode == 1:
            for a in range(d):
                T[0, a] = ends.d1s[a]
                K[0, a] = ends.d2s[a]
        if ends.end_mode == 1:
            for a in range(d):
                T[nb - 1, a] = ends.d1e[a]
                K[nb - 1, a] = ends.d2e[a]
        coef = np.empty((npc, 6, d))
        wcoef = np.empty((npc, 6, 1))
        wpos = np.empty((nb, 1))
        for k in range(nb):
            wpos[k, 0] = wb[k]
        dw = np.empty(1)
        for k in range(npc):
            hp = (h[k], h3[k], h4[k], h5[k])
            hermite_into(coef, k, Ps, T, K, k, dp[k], hp)
            dw[0] = wz[k] - wa[k]
            hermite_into(wcoef, k, wpos, wd1, wd2, k, dw, hp)
        # checks against the exact arc at CURVE_CHECK_POINTS points of every piece
        bad = np.zeros(npc, dtype=np.bool_)
        n_bad = 0
        tt = np.empty(M)
        wc = np.empty(M)
        ex = np.empty((M, d))
        dev = np.empty((1, d))
        max_mm = 0.0
        for k in range(npc):
            for i in range(M):
                tt[i] = tfr[i] * h[k]
                wc[i] = min(max(_horner(wcoef, k, 0, tt[i]), 0.0), 1.0)
            arc_eval(arcs, c, wc, ex, empty, empty)
            e_lin = 0.0
            slow_q = np.inf
            slow_w = np.inf
            for i in range(M):
                nl = 0
                for a in range(d):
                    if lin[a]:
                        e = _horner(coef, k, a, tt[i]) - ex[i, a]
                        buf[nl] = e * e
                        nl += 1
                e_lin = max(e_lin, np.sqrt(0.0 + pairwise_sum(buf, 0, nl)))
                for a in range(d):
                    dev[0, a] = _horner_d(coef, k, a, tt[i])
                slow_q = min(slow_q, np.sqrt(_row_sumsq(dev, 0, buf)))
                slow_w = min(slow_w, _horner_d(wcoef, k, 0, tt[i]))
            max_mm = max(max_mm, e_lin)
            # (no rotary axis: the rotary deviation is 0, never above tr)
            if e_lin > tl or 0.0 > tr or slow_q < cp.min_piece_speed or slow_w <= 0.0:
                bad[k] = True
                n_bad += 1
        if n_bad == 0:
            break
        if depth == cp.max_depth:
            ok = False
            break
        grown = np.empty(nb + n_bad)
        grown[:nb] = wb
        q = nb
        for k in range(npc):
            if bad[k]:
                grown[q] = 0.5 * (wa[k] + wz[k])
                q += 1
        wb = np.sort(grown)
    n = h.shape[0]
    for a in range(d):
        coef[0, 0, a] = arcs.start[c, a]
    breaks = np.empty(n + 1)
    breaks[0] = 0.0
    for k in range(n):
        breaks[k + 1] = breaks[k] + h[k]
    return SectionFit(breaks, coef, np.full(n, line), np.full(n, feed), max_mm, max_deg, ok), 0


@njit(cache=True, error_model="numpy")
def _straight_move(p0, p1, line, feed):
    """``nodes.straight_piece`` of the move p0 -> p1 with length ``np.linalg.norm(p1 - p0)``."""
    d = p0.shape[0]
    v = np.empty(d)
    for a in range(d):
        v[a] = p1[a] - p0[a]
    length = np.sqrt(blas_dot(v, v))
    coef = np.zeros((1, 6, d))
    for a in range(d):
        coef[0, 0, a] = p0[a]
        coef[0, 1, a] = v[a] / length
    breaks = np.empty(2)
    breaks[0] = 0.0
    breaks[1] = length
    return SectionFit(breaks, coef, np.full(1, line), np.full(1, feed), 0.0, 0.0, True)


@njit(cache=True, error_model="numpy")
def _sections(blends, arcs, a, b, lo_hi):
    """``fitter._fit_sections``' sections of sub-run a..b: kind (_POLY, _CURVE, _BLEND),
    first and last node, and the blend's or arc's index, in path order."""
    blo, bhi, clo, chi = lo_hi
    cap = 2 * ((bhi - blo) + (chi - clo)) + 1
    kind = np.empty(cap, dtype=np.int64)
    si = np.empty(cap, dtype=np.int64)
    sj = np.empty(cap, dtype=np.int64)
    obj = np.empty(cap, dtype=np.int64)
    ns = 0
    pos = a
    ib = blo
    ic = clo
    while ib < bhi or ic < chi:
        if ic < chi and (ib >= bhi or arcs.first[ic] < blends.i[ib]):
            first, last, kd, ob = arcs.first[ic], arcs.last[ic], _CURVE, ic
            ic += 1
        else:
            first, last, kd, ob = blends.i[ib], blends.i[ib] + 2, _BLEND, ib
            ib += 1
        if first > pos:
            kind[ns], si[ns], sj[ns], obj[ns] = _POLY, pos, first, -1
            ns += 1
        kind[ns], si[ns], sj[ns], obj[ns] = kd, first, last, ob
        ns += 1
        pos = last
    if pos < b:
        kind[ns], si[ns], sj[ns], obj[ns] = _POLY, pos, b, -1
        ns += 1
    return kind[:ns], si[:ns], sj[:ns], obj[:ns]


@njit(cache=True, error_model="numpy")
def _junctions(blends, arcs, kind, obj, d):
    """The end states imposed on each section (``fitter._fit_sections``): for section k,
    (has, tangent, curvature vector) at its start and at its end."""
    ns = kind.shape[0]
    # each curve's / blend's own end states
    st = np.zeros((ns, 4, d))
    for k in range(ns):
        if kind[k] == _CURVE:
            st[k] = arcs.ends[obj[k]]
        elif kind[k] == _BLEND:
            st[k, 0] = blends.t_in[obj[k]]
            st[k, 2] = blends.t_out[obj[k]]
    s_has = np.zeros(ns, dtype=np.bool_)
    e_has = np.zeros(ns, dtype=np.bool_)
    s_state = np.zeros((ns, 2, d))
    e_state = np.zeros((ns, 2, d))
    T = np.empty(d)
    K = np.empty(d)
    for k in range(ns - 1):
        ca = kind[k] != _POLY
        cb = kind[k + 1] != _POLY
        if ca and cb:
            for a in range(d):
                T[a] = st[k, 2, a] + st[k + 1, 0, a]
            nrm = np.sqrt(blas_dot(T, T))
            for a in range(d):
                T[a] = T[a] / nrm
                K[a] = 0.5 * (st[k, 3, a] + st[k + 1, 1, a])
            kt = blas_dot(K, T)
            for a in range(d):
                K[a] = K[a] - kt * T[a]
            e_has[k] = True
            s_has[k + 1] = True
            e_state[k, 0] = T
            e_state[k, 1] = K
            s_state[k + 1, 0] = T
            s_state[k + 1, 1] = K
        elif ca:
            s_has[k + 1] = True
            s_state[k + 1, 0] = st[k, 2]
            s_state[k + 1, 1] = st[k, 3]
        elif cb:
            e_has[k] = True
            e_state[k, 0] = st[k + 1, 0]
            e_state[k, 1] = st[k + 1, 1]
    return s_has, s_state, e_has, e_state


@njit(cache=True, error_model="numpy")
def _fit_subrun(run, blends, arcs, subs, s, prm):
    """``fitter._fit_sub`` of sub-run s: (its sections' fits joined, worst node deviations
    mm / deg, every fitter's check passed, status)."""
    a = subs.i0[s]
    b = subs.i1[s]
    nodes = run.nodes
    d = nodes.shape[1]
    tol = run.tol[a : b + 1]
    tol_ref = np.max(tol)
    sp = prm.section
    sprm = SectionParams(
        sp.tol_deg,
        sp.lin,
        sp.metric,
        tol_ref,
        sp.tol_safety,
        sp.between_safety,
        sp.smoothing,
        sp.ridge,
        sp.min_ratio,
        sp.stop_ratio,
        sp.max_rounds,
        sp.stale_rounds,
        sp.min_span_rel,
        sp.initial_step,
    )
    lo_hi = (subs.blend_lo[s], subs.blend_hi[s], subs.arc_lo[s], subs.arc_hi[s])
    kind, si, sj, obj = _sections(blends, arcs, a, b, lo_hi)
    s_has, s_state, e_has, e_state = _junctions(blends, arcs, kind, obj, d)
    ns = kind.shape[0]
    fits = List()
    dmm = 0.0
    ddeg = 0.0
    ok = True
    n_seg = 0
    for k in range(ns):
        ends = EndStates(
            s_state[k, 0], s_state[k, 1], e_state[k, 0], e_state[k, 1], 1 if s_has[k] else 0, 1 if e_has[k] else 0
        )
        i = si[k]
        j = sj[k]
        if kind[k] == _CURVE:
            c = obj[k]
            pf, status = fit_arc(arcs, c, ends, sp.lin, tol[j - a], sp.tol_deg, arcs.line[c], run.feed[j], prm.curve)
            if status != 0:
                return pf, 0.0, 0.0, False, status
        elif kind[k] == _BLEND:
            bl = obj[k]
            brk = np.empty(2)
            brk[0] = 0.0
            brk[1] = blends.h[bl]
            cf = np.empty((1, 6, d))
            cf[0] = blends.coef[bl]
            pf = SectionFit(brk, cf, np.full(1, blends.line[bl]), np.full(1, blends.feed[bl]), 0.0, 0.0, True)
        else:
            free_or_blend = (not s_has[k] or kind[k - 1] == _BLEND) and (not e_has[k] or kind[k + 1] == _BLEND)
            if j == i + 1 and free_or_blend:
                pf = _straight_move(nodes[i], nodes[j], run.line[j], run.feed[j])
            else:
                sec = SectionNodes(nodes[i : j + 1], tol[i - a : j - a + 1], run.line[i : j + 1], run.feed[i : j + 1])
                pf = fit_section(sec, ends, sprm)
        fits.append(pf)
        n_seg += pf.coef.shape[0]
        dmm = max(dmm, pf.max_mm)
        ddeg = max(ddeg, pf.max_deg)
        ok = ok and pf.ok
    breaks = np.empty(n_seg + 1)
    coef = np.empty((n_seg, 6, d))
    line = np.empty(n_seg, dtype=np.int64)
    feed = np.empty(n_seg)
    breaks[0] = 0.0
    off = 0.0
    q = 0
    for pf in fits:
        m = pf.coef.shape[0]
        for k in range(m):
            breaks[q + k + 1] = pf.breaks[k + 1] + off
            coef[q + k] = pf.coef[k]
            line[q + k] = pf.line[k]
            feed[q + k] = pf.feed[k]
        off += pf.breaks[m]
        q += m
    return SectionFit(breaks, coef, line, feed, 0.0, 0.0, True), dmm, ddeg, ok, 0


@njit(cache=True, error_model="numpy")
def _arc_samples(arcs, c, k):
    """``deviation.programmed_samples``' samples of arc c: its points at np.linspace(0, 1, k + 1)."""
    d = arcs.start.shape[1]
    pts = np.empty((k + 1, d))
    empty = np.empty((0, d))
    arc_eval(arcs, c, linspace(0.0, 1.0, k + 1), pts, empty, empty)
    return pts


@njit(cache=True, error_model="numpy")
def _path_deviation(run, arcs, a, b, lo_hi, fit, cfg):
    """``deviation.path_deviation`` of sub-run a..b (its arcs lo_hi = (first, end)) against
    the fit (``SectionFit``): (max distance mm, max distance / tolerance)."""
    clo, chi = lo_hi
    nodes = run.nodes[a : b + 1]
    tol_mm = run.tol[a : b + 1]
    n, d = nodes.shape
    S = fit.coef.shape[0]
    h = np.empty(S)
    for k in range(S):
        h[k] = fit.breaks[k + 1] - fit.breaks[k]
    spacing = max(median(h), 1e-9) / cfg.samples_per_span
    # which moves an arc replaces, and how many samples each move or arc gets
    curve_of = np.full(n - 1, -1, dtype=np.int64)
    first_of = np.full(n - 1, -1, dtype=np.int64)
    for c in range(clo, chi):
        first_of[arcs.first[c] - a] = c
        for j in range(arcs.first[c] - a, arcs.last[c] - a):
            curve_of[j] = c
    buf = np.empty(max(d, 8))
    cnt = np.zeros(n - 1, dtype=np.int64)
    total = 0
    for j in range(n - 1):
        if first_of[j] >= 0:
            c = first_of[j]
            ca, cb = arcs.first[c] - a, arcs.last[c] - a
            lens = np.empty(cb - ca)
            for m in range(ca, cb):
                for e in range(d):
                    x = nodes[m + 1, e] - nodes[m, e]
                    buf[e] = x * x
                lens[m - ca] = np.sqrt(0.0 + pairwise_sum(buf, 0, d))
            clen = 0.0 + pairwise_sum(lens, 0, cb - ca)
            kk = np.ceil(clen / spacing)
            kk = min(max(kk, cfg.min_samples * (cb - ca)), cfg.max_samples * (cb - ca))
            cnt[j] = int(kk)
            total += cnt[j] + 1
        elif curve_of[j] < 0:
            ln = 0.0
            for e in range(d):
                x = nodes[j + 1, e] - nodes[j, e]
                ln += x * x
            x = np.sqrt(ln) / spacing
            if x >= cfg.max_samples:
                cnt[j] = cfg.max_samples
            else:
                cnt[j] = max(int(np.ceil(x)), cfg.min_samples)
            total += cnt[j] + 1
    pts = np.empty((total, d))
    ptol = np.empty(total)
    m = 0
    for j in range(n - 1):
        if first_of[j] >= 0:
            c = first_of[j]
            cp = _arc_samples(arcs, c, cnt[j])
            tb = tol_mm[arcs.last[c] - a]
            for i in range(cnt[j] + 1):
                pts[m] = cp[i]
                ptol[m] = tb
                m += 1
        elif curve_of[j] < 0:
            cj = cnt[j]
            i_start = 1 if (j > 0 and curve_of[j - 1] < 0) else 0
            for i in range(i_start, cj + 1):
                f = i / cj
                for e in range(d):
                    pts[m, e] = nodes[j, e] + (nodes[j + 1, e] - nodes[j, e]) * f
                ptol[m] = tol_mm[j + 1]
                m += 1
    pts = pts[:m]
    ptol = ptol[:m]
    if m == 0:
        return 0.0, 0.0
    dist = march_feet(
        fit.coef,
        h,
        pts,
        ptol,
        cfg.local_frac,
        cfg.window * spacing,
        cfg.far_window * spacing,
        cfg.n_coarse,
        cfg.iters,
    )[0]
    dmax = dist[0]
    rmax = dist[0] / max(ptol[0], 1e-300)
    for i in range(1, m):
        dmax = max(dmax, dist[i])
        rmax = max(rmax, dist[i] / max(ptol[i], 1e-300))
    return dmax, rmax


@njit(cache=True, error_model="numpy", nogil=True)
def fit_batch(run, blends, arcs, subs, prm):
    """Fit and measure the sub-runs ``subs`` (``SubRunTable``) of the run ``run``
    (``RunArrays``, its ``BlendArrays`` and ``ArcArrays``) with the settings ``prm``
    (``BatchParams``): a ``BatchFits``."""
    B = subs.i0.shape[0]
    d = run.nodes.shape[1]
    status = np.zeros(B, dtype=np.int64)
    dmm = np.zeros(B)
    ddeg = np.zeros(B)
    fit_ok = np.zeros(B, dtype=np.bool_)
    pdev = np.zeros(B)
    pratio = np.zeros(B)
    seg_off = np.zeros(B + 1, dtype=np.int64)
    fits = List()
    for s in range(B):
        fit, dm, dd, ok, st = _fit_subrun(run, blends, arcs, subs, s, prm)
        fits.append(fit)
        status[s] = st
        seg_off[s + 1] = seg_off[s] + (fit.coef.shape[0] if st == 0 else 0)
        if st != 0:
            continue
        dmm[s] = dm
        ddeg[s] = dd
        fit_ok[s] = ok
        a = subs.i0[s]
        b = subs.i1[s]
        if subs.arc_hi[s] > subs.arc_lo[s]:
            pdev[s], pratio[s] = _path_deviation(run, arcs, a, b, (subs.arc_lo[s], subs.arc_hi[s]), fit, prm.deviation)
        else:
            lin = np.ones(d, dtype=np.bool_)
            pdev[s], pratio[s] = polyline_path_deviation(
                fit.breaks, fit.coef, run.nodes[a : b + 1], run.tol[a : b + 1], lin, prm.deviation
            )
    S = seg_off[B]
    breaks = np.empty(S + B)
    coef = np.empty((S, 6, d))
    line = np.empty(S, dtype=np.int64)
    feed = np.empty(S)
    for s in range(B):
        if status[s] != 0:
            continue
        fit = fits[s]
        q = seg_off[s]
        m = seg_off[s + 1] - q
        breaks[q + s : q + s + m + 1] = fit.breaks
        coef[q : q + m] = fit.coef
        line[q : q + m] = fit.line
        feed[q : q + m] = fit.feed
    return BatchFits(status, seg_off, breaks, coef, line, feed, dmm, ddeg, fit_ok, pdev, pratio)

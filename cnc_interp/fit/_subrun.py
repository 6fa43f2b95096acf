"""A batch of sub-runs fitted and measured in four compiled calls.

``fitter._fit_measured`` for a run on linear axes only (the default N-axis fit): the
sub-run's sections (``fitter._fit_sections``: polylines, corner blends, the exact
moves between blends and G2/G3 arcs, joined G2), the arcs' quintic pieces
(``curves.fit_curve``), the polylines' B-splines (``_section.fit_section``) and the
measurement of the programmed path against the fit (``deviation.path_deviation`` /
``polyline_deviation``). Stellabee-like programs have ~10⁴ sub-runs of ~15 sections
each: in Python that was ~2 ms of glue per sub-run around the compiled kernels.

Every float operation is the Python code's, in the same order, with numpy's own
summation, dot products and vector powers (``_npexact``), so the paths are the same
bits. What these kernels do not cover (a NURBS, rotary axes, an arc whose parameter
speed vanishes, a fit the measurement finds outside: its repair) is left to the
Python code, which gives the same first fit.

The four calls (``plan_sections``, ``fit_poly_sections``, ``fit_arc_sections``,
``join_and_measure``) are separate kernels: numba links a kernel's callees into its
module and optimizes the whole again, so each layer of calls re-optimizes everything
below it. First-run compile of the fit's kernels (quick-start program, cold cache,
machine at load 4-6): one batch kernel ~75 CPU-s, these four ~65, the Python fitter's
kernels before ~24.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit
from numba.typed import List

from ._arcs import arc_eval, linspace
from ._bspline import EndStates
from ._linedev import polyline_path_deviation
from ._npexact import blas_dot, arc_terms, powers345, pairwise_sum
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

#: the batch's sections (``fitter._fit_sections``), NS of them: sub-run s has sections
#: off[s]:off[s + 1]; per section its kind (_POLY, _CURVE, _BLEND, _MOVE: a move between
#: blends, the exact line), first and last node i / j, its arc's or blend's index obj,
#: the imposed end states (has (NS, 2): start, end; state (NS, 2, 2, d): start / end,
#: tangent / curvature vector) and its sub-run's tol_ref (NS,)
SectionTable = namedtuple("SectionTable", "off kind i j obj has state tol_ref")

#: the fitted pieces of some sections (K of them) of a ``SectionTable``: section k has
#: segments off[k]:off[k + 1] of coef / line / feed and breaks breaks[off[k] + k :
#: off[k + 1] + k + 1] (from 0); worst node deviations max_mm / max_deg, ok, and status
#: (0, or ``STATUS_PYTHON``)
SectionPieces = namedtuple("SectionPieces", "off breaks coef line feed max_mm max_deg ok status")

_POLY = 0
_CURVE = 1
_BLEND = 2
_MOVE = 3

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
        sp3, quad = arc_terms(sp, sp8, cp.gl_w)
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
        h3, h4, h5 = powers345(h)
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
def plan_sections(run, blends, arcs, subs):
    """The sections of the sub-runs ``subs`` (``SubRunTable``) of the run ``run``
    (``RunArrays``, its ``BlendArrays`` and ``ArcArrays``) with their imposed end
    states: a ``SectionTable`` (``fitter._fit_sections``' sections and junctions; a
    move between blends, or between a blend and the path's end, is its own kind)."""
    B = subs.i0.shape[0]
    d = run.nodes.shape[1]
    cap = 0
    for s in range(B):
        cap += 2 * ((subs.blend_hi[s] - subs.blend_lo[s]) + (subs.arc_hi[s] - subs.arc_lo[s])) + 1
    off = np.zeros(B + 1, dtype=np.int64)
    kind = np.empty(cap, dtype=np.int64)
    first = np.empty(cap, dtype=np.int64)
    last = np.empty(cap, dtype=np.int64)
    obj = np.empty(cap, dtype=np.int64)
    has = np.zeros((cap, 2), dtype=np.bool_)
    state = np.zeros((cap, 2, 2, d))
    tol_ref = np.empty(cap)
    q = 0
    for s in range(B):
        a = subs.i0[s]
        b = subs.i1[s]
        lo_hi = (subs.blend_lo[s], subs.blend_hi[s], subs.arc_lo[s], subs.arc_hi[s])
        k_s, i_s, j_s, o_s = _sections(blends, arcs, a, b, lo_hi)
        s_has, s_state, e_has, e_state = _junctions(blends, arcs, k_s, o_s, d)
        tr = np.max(run.tol[a : b + 1])
        ns = k_s.shape[0]
        for k in range(ns):
            kd = k_s[k]
            if kd == _POLY and j_s[k] == i_s[k] + 1:
                before = not s_has[k] or k_s[k - 1] == _BLEND
                after = not e_has[k] or k_s[k + 1] == _BLEND
                if before and after:
                    kd = _MOVE
            kind[q + k] = kd
            first[q + k] = i_s[k]
            last[q + k] = j_s[k]
            obj[q + k] = o_s[k]
            has[q + k, 0] = s_has[k]
            has[q + k, 1] = e_has[k]
            state[q + k, 0] = s_state[k]
            state[q + k, 1] = e_state[k]
            tol_ref[q + k] = tr
        q += ns
        off[s + 1] = q
    return SectionTable(off, kind[:q], first[:q], last[:q], obj[:q], has[:q], state[:q], tol_ref[:q])


@njit(cache=True, error_model="numpy")
def _ends(table, k):
    """The imposed end states of section k (``_bspline.EndStates``)."""
    st = table.state
    return EndStates(
        st[k, 0, 0], st[k, 0, 1], st[k, 1, 0], st[k, 1, 1], 1 if table.has[k, 0] else 0, 1 if table.has[k, 1] else 0
    )


@njit(cache=True, error_model="numpy")
def _gather(fits, status):
    """``SectionPieces`` of the fits (``SectionFit``, one per section) in order."""
    K = len(fits)
    off = np.zeros(K + 1, dtype=np.int64)
    for k in range(K):
        off[k + 1] = off[k] + fits[k].coef.shape[0]
    S = off[K]
    d = fits[0].coef.shape[2] if K > 0 else 0
    breaks = np.empty(S + K)
    coef = np.empty((S, 6, d))
    line = np.empty(S, dtype=np.int64)
    feed = np.empty(S)
    max_mm = np.empty(K)
    max_deg = np.empty(K)
    ok = np.empty(K, dtype=np.bool_)
    for k in range(K):
        f = fits[k]
        q = off[k]
        m = off[k + 1] - q
        breaks[q + k : q + k + m + 1] = f.breaks
        coef[q : q + m] = f.coef
        line[q : q + m] = f.line
        feed[q : q + m] = f.feed
        max_mm[k] = f.max_mm
        max_deg[k] = f.max_deg
        ok[k] = f.ok
    return SectionPieces(off, breaks, coef, line, feed, max_mm, max_deg, ok, status)


@njit(cache=True, error_model="numpy", nogil=True)
def fit_poly_sections(run, table, prm):
    """``nodes.fit_polyline`` (``_section.fit_section``) of every polyline section of
    ``table`` (``SectionTable``) in order: their ``SectionPieces``."""
    sp = prm.section
    nodes = run.nodes
    fits = List()
    for k in range(table.kind.shape[0]):
        if table.kind[k] != _POLY:
            continue
        i = table.i[k]
        j = table.j[k]
        sprm = SectionParams(
            sp.tol_deg,
            sp.lin,
            sp.metric,
            table.tol_ref[k],
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
        sec = SectionNodes(nodes[i : j + 1], run.tol[i : j + 1], run.line[i : j + 1], run.feed[i : j + 1])
        fits.append(fit_section(sec, _ends(table, k), sprm))
    return _gather(fits, np.zeros(len(fits), dtype=np.int64))


@njit(cache=True, error_model="numpy", nogil=True)
def fit_arc_sections(run, arcs, table, prm):
    """``curves.fit_curve`` (``fit_arc``) of every arc section of ``table`` in order: their
    ``SectionPieces`` (status ``STATUS_PYTHON``: left to Python, its pieces empty)."""
    fits = List()
    status = np.zeros(table.kind.shape[0], dtype=np.int64)
    n = 0
    lin = prm.section.lin
    for k in range(table.kind.shape[0]):
        if table.kind[k] != _CURVE:
            continue
        c = table.obj[k]
        j = table.j[k]
        tol_deg = prm.section.tol_deg
        pf, st = fit_arc(arcs, c, _ends(table, k), lin, run.tol[j], tol_deg, arcs.line[c], run.feed[j], prm.curve)
        fits.append(pf)
        status[n] = st
        n += 1
    return _gather(fits, status[:n])


@njit(cache=True, error_model="numpy", nogil=True)
def join_and_measure(run, blends, arcs, subs, table, polys, arcfits, prm):
    """Each sub-run of ``subs`` as ``fitter._fit_sub`` joins its sections (``table``; the
    polylines' and arcs' pieces ``polys`` / ``arcfits``, the blends' and the moves' own)
    and as ``fitter._fit_measured`` measures it (``deviation.path_deviation`` /
    ``polyline_deviation``): a ``BatchFits``."""
    B = subs.i0.shape[0]
    nodes = run.nodes
    d = nodes.shape[1]
    status = np.zeros(B, dtype=np.int64)
    dmm = np.zeros(B)
    ddeg = np.zeros(B)
    fit_ok = np.zeros(B, dtype=np.bool_)
    pdev = np.zeros(B)
    pratio = np.zeros(B)
    seg_off = np.zeros(B + 1, dtype=np.int64)
    # segments per sub-run, and whether an arc of it was left to Python
    kp = 0
    kc = 0
    for s in range(B):
        n_seg = 0
        for k in range(table.off[s], table.off[s + 1]):
            kd = table.kind[k]
            if kd == _POLY:
                n_seg += polys.off[kp + 1] - polys.off[kp]
                kp += 1
            elif kd == _CURVE:
                n_seg += arcfits.off[kc + 1] - arcfits.off[kc]
                if arcfits.status[kc] != 0:
                    status[s] = arcfits.status[kc]
                kc += 1
            else:
                n_seg += 1
        seg_off[s + 1] = seg_off[s] + (n_seg if status[s] == 0 else 0)
    S = seg_off[B]
    breaks = np.empty(S + B)
    coef = np.empty((S, 6, d))
    line = np.empty(S, dtype=np.int64)
    feed = np.empty(S)
    lin = np.ones(d, dtype=np.bool_)
    kp = 0
    kc = 0
    for s in range(B):
        q = seg_off[s]
        bq = q + s
        breaks[bq] = 0.0
        off = 0.0
        ok = True
        for k in range(table.off[s], table.off[s + 1]):
            kd = table.kind[k]
            if kd == _POLY or kd == _CURVE:
                src = polys if kd == _POLY else arcfits
                kk = kp if kd == _POLY else kc
                if kd == _POLY:
                    kp += 1
                else:
                    kc += 1
                if status[s] != 0:
                    continue
                a0 = src.off[kk]
                m = src.off[kk + 1] - a0
                for e in range(m):
                    breaks[bq + e + 1] = src.breaks[a0 + kk + e + 1] + off
                    coef[q + e] = src.coef[a0 + e]
                    line[q + e] = src.line[a0 + e]
                    feed[q + e] = src.feed[a0 + e]
                off += src.breaks[a0 + kk + m]
                dmm[s] = max(dmm[s], src.max_mm[kk])
                ddeg[s] = max(ddeg[s], src.max_deg[kk])
                ok = ok and src.ok[kk]
                q += m
                bq += m
                continue
            if status[s] != 0:
                continue
            if kd == _BLEND:
                # the blend's one piece (``fitter._fit_sections``' PieceFit of the Blend)
                bl = table.obj[k]
                length = blends.h[bl]
                coef[q] = blends.coef[bl]
                line[q] = blends.line[bl]
                feed[q] = blends.feed[bl]
            else:
                # the move itself (``nodes.straight_piece``, its length ``np.linalg.norm``)
                i = table.i[k]
                j = table.j[k]
                v = nodes[j] - nodes[i]
                length = np.sqrt(blas_dot(v, v))
                coef[q] = 0.0
                for e in range(d):
                    coef[q, 0, e] = nodes[i, e]
                    coef[q, 1, e] = v[e] / length
                line[q] = run.line[j]
                feed[q] = run.feed[j]
            breaks[bq + 1] = length + off
            off += length
            q += 1
            bq += 1
        if status[s] != 0:
            continue
        fit_ok[s] = ok
        q0 = seg_off[s]
        n_seg = seg_off[s + 1] - q0
        fit = SectionFit(
            breaks[q0 + s : q0 + s + n_seg + 1],
            coef[q0 : q0 + n_seg],
            line[q0 : q0 + n_seg],
            feed[q0 : q0 + n_seg],
            0.0,
            0.0,
            True,
        )
        a = subs.i0[s]
        b = subs.i1[s]
        if subs.arc_hi[s] > subs.arc_lo[s]:
            pdev[s], pratio[s] = _path_deviation(run, arcs, a, b, (subs.arc_lo[s], subs.arc_hi[s]), fit, prm.deviation)
        else:
            pdev[s], pratio[s] = polyline_path_deviation(
                fit.breaks, fit.coef, nodes[a : b + 1], run.tol[a : b + 1], lin, prm.deviation
            )
    return BatchFits(status, seg_off, breaks, coef, line, feed, dmm, ddeg, fit_ok, pdev, pratio)

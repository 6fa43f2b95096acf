"""VPOp's step-loop driver and, for identity kinematics, its whole per-path preparation,
compiled (imported lazily by ``vpop``).

``drive`` runs ``step.plan_core`` over buffers that grow, or slide once a window is
set, keeps a checkpoint of the loop every ``checkpoint`` samples and, after a fast-mode
failure, re-plans exactly from the last one (the start, on paths shorter than a
checkpoint), so samples before the last checkpoint's look-back are final: it returns
to hand them out (``HAND_OUT``) when the window is full. ``prepare_identity`` is
``vpop._Prepared`` for paths whose joints are the program axes, step for step, and
``plan_identity_batch`` plans many such paths in one call (per-path Python overhead
was half the planning time of a CAM program of 10^5 short paths). The same functions
serve one path at a time and a batch, so both give the same samples.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from . import step as core
from .._table_kernels import build_identity, curvature_bounds, speed_bound

# statuses (one set for every kernel: ``status``): drive's results OK (the path is
# done), HAND_OUT, FAILED; prepare_identity's OK, NOT_FINITE_PATH, NO_LENGTH,
# NOT_FINITE (the table), JERK_TOO_SMALL, TRIVIAL
from ..status import FAILED, HAND_OUT, JERK_TOO_SMALL, NO_LENGTH, NOT_FINITE, NOT_FINITE_PATH, OK, TRIVIAL

# the driver's state (int64 array ``ds``)
DS_BASE, DS_HANDED, DS_NEXT_CK, DS_FAST, DS_CK_LO, DS_CK_LEN, DS_CK_FIRST, DS_END, DS_STATUS = range(9)
DS_SIZE = 9

#: samples kept before a checkpoint's last fixed sample (the stencils read 3 back)
CKPT_HISTORY = 8
_RM_BLOCK = 32

# The kernels' arguments, bundled by concept (see ``step`` for the step loop's own).
#: one fitted path (``fit.path.Path``): coef (segments, 6, n) power coefficients in the
#: segment's parameter, breaks and s_breaks (segments + 1,) in parameter and arc length,
#: the rational weights w, its length (mm) and feed (segments,) in mm/s
PathData = namedtuple("PathData", "coef breaks s_breaks w length feed")
#: a machine's limits in step units before the rounding margin, per axis (n,): vl0 =
#: V dt shrink, al0 = A dt² shrink, jl0 = J dt³ shrink, jl_floor = J dt³ / 2 (below it
#: float64 cannot resolve the jerk), vmax (mm/s); and ramp (s, the longest V/A + A/J),
#: dt (s), brake_cap (samples of a brake run's buffer), shrink (1 - VPOP_LIMIT_SHRINK)
MachineSteps = namedtuple("MachineSteps", "vl0 al0 jl0 jl_floor vmax ramp dt brake_cap shrink")
#: the preparation's knobs (``vpop``'s VPOP_* constants): lookback (brake runs),
#: table_tol (mm), max_depth, max_piece, glx/glw (Gauss-Legendre nodes and weights),
#: max_tries of the joint table; rounding_ulps, brake_jerk_fraction, aim_gap_steps,
#: min_length (mm)
PrepSettings = namedtuple(
    "PrepSettings",
    "lookback table_tol max_depth max_piece glx glw max_tries rounding_ulps brake_jerk_fraction "
    "aim_gap_steps min_length",
)
#: the step loop's knobs (``vpop``'s VPOP_* constants): easy_frac, chain_seq (see
#: ``core.Settings``), checkpoint_every (samples), and fast (start in fast mode)
LoopSettings = namedtuple("LoopSettings", "easy_frac chain_seq checkpoint_every fast")
#: a checkpoint of the step loop: its state st, certificate cs/cq, and the samples sh/qh
#: from the last fixed sample's look-back on (``checkpoint``)
Checkpoint = namedtuple("Checkpoint", "st cs cq sh qh")


@njit(cache=True)
def range_max_packed(K):
    """``step.range_max_table`` compiled (the same packed table, the same values)."""
    m = K.shape[0]
    B = _RM_BLOCK
    nb = max(1, (m + B - 1) // B)
    levels = 1
    while (1 << levels) <= nb:
        levels += 1
    out = np.empty(3 + m + levels * nb)
    out[0] = m
    out[1] = nb
    out[2] = levels
    for i in range(m):
        out[3 + i] = K[i]
    off = 3 + m
    for b in range(nb):
        best = -np.inf
        for i in range(b * B, min(m, (b + 1) * B)):
            if K[i] > best:
                best = K[i]
        out[off + b] = best
    for lvl in range(1, levels):
        w = 1 << (lvl - 1)
        prev = off + (lvl - 1) * nb
        cur = off + lvl * nb
        for b in range(nb):
            a = out[prev + b]
            c = out[prev + b + w] if b + w < nb else -np.inf
            out[cur + b] = a if a >= c else c
    return out


@njit(cache=True)
def _seg_of_s(s_breaks, x):
    n_seg = s_breaks.shape[0] - 1
    k = np.searchsorted(s_breaks, x, side="right") - 1
    if k < 0:
        k = 0
    if k > n_seg - 1:
        k = n_seg - 1
    return k


@njit(cache=True)
def start_point(coef):
    """The path's first point as ``Path.derivatives_u`` evaluates it (Horner at t = 0)."""
    n = coef.shape[2]
    out = np.empty((1, n))
    for ax in range(n):
        acc = coef[0, 5, ax] * 1.0
        for i in range(4, -1, -1):
            acc = acc * 0.0 + coef[0, i, ax] * 1.0
        out[0, ax] = acc
    return out


@njit(cache=True)
def _failed(status, n, q_scale):
    """prepare_identity's result when it stops early: empty arrays. (Callers pass
    ``np.int64(status)``: a bare status constant is a literal type to numba, which would
    compile this once per status.)"""
    e1 = np.empty(0)
    en = np.empty(n)
    pb = core.Problem(
        core.Table(e1, np.empty((0, n, 6)), en),
        core.Limits(en, en, en),
        en,
        core.Feed(0.0, 0.0, e1, e1),
        core.Ease(e1, e1, e1, e1),
    )
    return status, pb, en, 0.0, 0.0, 0, 0, 0, 0, q_scale


@njit(cache=True)
def prepare_identity(path, mc, ps):
    """``vpop._Prepared`` for identity kinematics: the ``PathData`` path on the machine
    ``MachineSteps`` mc with the ``PrepSettings`` ps. Returns (status, ``core.Problem``,
    qstart, tol, gap_tol, est, max_steps, floor_h, pieces, max_err); on a status other
    than ``OK`` the arrays are empty and the last value is the position scale (the
    Python preparation then raises the right error, or plans a trivial path)."""
    coef = path.coef
    length = path.length
    feed = path.feed
    s_breaks = path.s_breaks
    dt = mc.dt
    n = coef.shape[2]
    finite = np.isfinite(length)
    for x in coef.ravel():
        if not np.isfinite(x):
            finite = False
            break
    if not finite:
        return _failed(np.int64(NOT_FINITE_PATH), n, 0.0)
    if length <= ps.min_length:
        return _failed(np.int64(TRIVIAL), n, 0.0)
    status, u, S, C, max_err, qend = build_identity(
        coef,
        path.breaks,
        s_breaks,
        path.w,
        length,
        ps.table_tol,
        ps.max_depth,
        ps.max_piece,
        ps.glx,
        ps.glw,
        ps.max_tries,
    )
    if status == NO_LENGTH:
        return _failed(np.int64(NO_LENGTH), n, 0.0)
    if status != OK:
        return _failed(np.int64(NOT_FINITE), n, 0.0)
    m = C.shape[0]
    qstart = C[0, 0].copy()
    big = 0.0
    for p in range(m):
        for ax in range(n):
            v = abs(C[p, 0, ax])
            if v > big:
                big = v
    q_scale = 1.0 + big
    margin = ps.rounding_ulps * np.finfo(np.float64).eps * q_scale
    vl = mc.vl0 - 2.0 * margin
    al = mc.al0 - 4.0 * margin
    jl = mc.jl0 - 8.0 * margin
    for ax in range(n):
        if jl[ax] <= mc.jl_floor[ax]:
            return _failed(np.int64(JERK_TOO_SMALL), n, q_scale)
    L = length
    n_seg = feed.shape[0]
    FB = s_breaks.copy()
    FB[n_seg] = L
    FV = np.empty(n_seg)
    fmin = np.inf
    for i in range(n_seg):
        f = feed[i]
        FV[i] = f * mc.shrink if (np.isfinite(f) and f > 0) else 1e300
        if FV[i] < fmin:
            fmin = FV[i]
    tq = -np.inf
    for ax in range(n):
        v = abs(qend[ax] - qstart[ax]) / mc.vmax[ax]
        if v > tq:
            tq = v
    tv = tq + L / fmin
    est = int((tv + 2 * mc.ramp) / dt) + 16
    max_steps = 200 * est + 100_000
    floor_h = ps.lookback * mc.brake_cap
    x = L if L > 1.0 else 1.0
    jmin = np.inf
    for ax in range(n):
        if jl[ax] < jmin:
            jmin = jl[ax]
    tol = max(4.0 * (np.nextafter(x, np.inf) - x), 1e-7 * jmin)
    js = jl * ps.brake_jerk_fraction
    k2, k3, k23 = curvature_bounds(S, C, al, jl)
    kv = speed_bound(S, C, vl)
    for p in range(m):
        seg = _seg_of_s(s_breaks, 0.5 * (S[p] + S[p + 1]))
        kf = 1.0 / (FV[seg] * dt)
        a = kv[p]
        if a != a or kf != kf:  # np.maximum: NaN wins
            kv[p] = np.nan
        elif kf > a:
            kv[p] = kf
    gap_tol = ps.aim_gap_steps * jmin
    Cam = np.empty((m, n, 6))
    for p in range(m):
        for ax in range(n):
            for i in range(6):
                Cam[p, ax, i] = C[p, i, ax]
    ease = core.Ease(range_max_packed(k2), range_max_packed(k3), range_max_packed(k23), range_max_packed(kv))
    pb = core.Problem(core.Table(S, Cam, qend), core.Limits(vl, al, jl), js, core.Feed(dt, L, FB, FV), ease)
    return OK, pb, qstart, tol, gap_tol, est, max_steps, floor_h, m, max_err


# -- the driver ---------------------------------------------------------------------------
@njit(cache=True)
def _shift_state(src, dst, delta):
    for i in range(core.ST_SIZE):
        dst[i] = src[i]
    dst[core.ST_K] += delta
    dst[core.ST_B] += delta
    dst[core.ST_LASTK] += delta
    dst[core.ST_LASTJ] += delta
    if src[core.ST_CAT] >= 0:
        dst[core.ST_CAT] = src[core.ST_CAT] + delta
    if src[core.ST_CERT] < core._BIG // 2:
        dst[core.ST_CERT] = src[core.ST_CERT] + delta


@njit(cache=True)
def checkpoint(sh, qh, st, runs, ds, ck, first):
    """Keep the loop's state (global indices), certificate and the samples from the last
    fixed sample's look-back on in the ``Checkpoint`` ck."""
    base = ds[DS_BASE]
    lo = st[core.ST_B] - CKPT_HISTORY
    if lo < 0:
        lo = 0
    k = st[core.ST_K]
    _shift_state(st, ck.st, base)
    ck.cs[:] = runs.cs
    ck.cq[:, :] = runs.cq
    n = k - lo
    for i in range(n):
        ck.sh[i] = sh[lo + i]
        for a in range(qh.shape[1]):
            ck.qh[i, a] = qh[lo + i, a]
    ds[DS_CK_LO] = lo + base
    ds[DS_CK_LEN] = n
    ds[DS_CK_FIRST] = 1 if first else 0


@njit(cache=True)
def _restore(sh, qh, st, runs, ds, ck):
    base = ds[DS_BASE]
    lo = ds[DS_CK_LO] - base  # >= 0: nothing from the checkpoint's look-back on was handed out
    for i in range(ds[DS_CK_LEN]):
        sh[lo + i] = ck.sh[i]
        for a in range(qh.shape[1]):
            qh[lo + i, a] = ck.qh[i, a]
    _shift_state(ck.st, st, -base)
    runs.cs[:] = ck.cs
    runs.cq[:, :] = ck.cq
    if ds[DS_CK_FIRST]:
        runs.stats[:] = 0


@njit(cache=True, nogil=True)
def drive(pb, cfg, checkpoint_every, sh, qh, st, runs, ds, ck, max_cap):
    """Run the step loop on the ``core.Problem`` pb until the path is done (``OK``,
    ds[DS_END] = global end index), the window is full of final samples (``HAND_OUT``:
    samples ds[DS_HANDED] .. ds[DS_CK_LO] - 1 are final; hand them out, set
    ds[DS_HANDED], call again) or the loop failed in exact mode (``FAILED``,
    ds[DS_STATUS]). ``cfg`` is the ``core.Settings`` of fast mode (ds[DS_FAST] says
    which mode runs: exact mode has no early ends); a checkpoint is kept every
    ``checkpoint_every`` samples; ``max_cap`` 0: no window (the buffers grow). Returns
    (result, sh, qh): the buffers may have been replaced."""
    room = runs.bs.shape[0] + 8
    n = qh.shape[1]
    while True:
        base = ds[DS_BASE]
        fast = ds[DS_FAST] != 0
        easy = cfg.easy_frac if fast else 0.0
        run_cfg = core.Settings(cfg.tol, cfg.max_steps, easy, cfg.gap_tol, fast, cfg.chain_seq, cfg.floor_h)
        status = core.plan_core(pb, sh, qh, st, runs, run_cfg, ds[DS_NEXT_CK] - base, base)
        if status == core.OK:
            ds[DS_END] = st[core.ST_K] + base
            return OK, sh, qh
        if status == core.YIELD:
            checkpoint(sh, qh, st, runs, ds, ck, np.bool_(False))
            ds[DS_NEXT_CK] += checkpoint_every
            continue
        if status == core.NEED_SPACE:
            if max_cap > 0 and ds[DS_HANDED] < ds[DS_CK_LO]:
                return HAND_OUT, sh, qh
            k = st[core.ST_K]
            cap = sh.shape[0]
            shift = min(ds[DS_CK_LO], ds[DS_HANDED]) - base
            if max_cap > 0 and shift > 0 and k - shift + room + 16 < cap:
                for i in range(k - shift):
                    sh[i] = sh[i + shift]
                    for a in range(n):
                        qh[i, a] = qh[i + shift, a]
                tmp = st.copy()
                _shift_state(tmp, st, -shift)
                ds[DS_BASE] = base + shift
                continue
            grow = max(2 * cap, k + room + 16)
            sh2 = np.zeros(grow)
            qh2 = np.zeros((grow, n))
            sh2[:k] = sh[:k]
            qh2[:k] = qh[:k]
            sh = sh2
            qh = qh2
            continue
        if fast:
            # a shortened brake run misjudged a state: plan exactly from the checkpoint
            ds[DS_FAST] = 0
            _restore(sh, qh, st, runs, ds, ck)
            continue
        ds[DS_STATUS] = status
        return FAILED, sh, qh


@njit(cache=True)
def end_index(sh, base, handed, end, L):
    """The last sample to keep (global): trailing repeats of the end point are the rest
    the contract already implies."""
    last = end - 1
    while last > handed and sh[last - 1 - base] == L:
        last -= 1
    return last


@njit(cache=True)
def new_loop(n, qstart, est, brake_cap, floor_h, room, window, checkpoint_every):
    """Buffers and states of a path about to be planned (see ``vpop._Loop``): (sh, qh, st,
    ``core.Runs``, ds, ``Checkpoint``, max_cap)."""
    cap = max(64, 2 * est) + room + 16
    max_cap = 0
    if window > 0:
        max_cap = max(window, 2 * (checkpoint_every + floor_h + room + 64))
        if cap > max_cap:
            cap = max_cap
    sh = np.zeros(cap)
    qh = np.zeros((cap, n))
    for a in range(n):
        qh[0, a] = qstart[a]
    st = np.zeros(core.ST_SIZE, dtype=np.int64)
    st[core.ST_K] = 1
    st[core.ST_CAT] = -1
    st[core.ST_CERT] = core._BIG
    cs = np.empty(brake_cap)
    cq = np.empty((brake_cap, n))
    bs = np.zeros(brake_cap)
    bq = np.zeros((brake_cap, n))
    stats = np.zeros(5, dtype=np.int64)
    ds = np.zeros(DS_SIZE, dtype=np.int64)
    span = floor_h + CKPT_HISTORY + 16
    ck_st = np.zeros(core.ST_SIZE, dtype=np.int64)
    ck_cs = np.empty(brake_cap)
    ck_cq = np.empty((brake_cap, n))
    ck_sh = np.empty(span)
    ck_qh = np.empty((span, n))
    return (sh, qh, st, core.Runs(bs, bq, cs, cq, stats), ds, Checkpoint(ck_st, ck_cs, ck_cq, ck_sh, ck_qh), max_cap)


@njit(cache=True)
def _grown(s, q, keep, need):
    """``s`` (cap,) and ``q`` (cap, n) with room for ``need`` rows: themselves when they have
    it, else new arrays at least twice as long holding their first ``keep`` rows."""
    cap = s.shape[0]
    if need <= cap:
        return s, q
    cap = max(2 * cap, need)
    s2 = np.empty(cap)
    q2 = np.empty((cap, q.shape[1]))
    s2[:keep] = s[:keep]
    q2[:keep] = q[:keep]
    return s2, q2


@njit(cache=True, nogil=True)
def plan_identity_batch(paths, seg_off, mc, ps, ls, long_samples):
    """Plan paths p = 0..P-1 (segments seg_off[p]..seg_off[p+1]-1 of the concatenated
    ``PathData`` paths: coef/feed concatenated, breaks and s_breaks concatenated with one
    extra entry per path, w and length (P,) per path) one after the other, each exactly
    as ``vpop.iter_path_plan_vpop`` would with no window: the machine ``MachineSteps``
    mc, the preparation's ``PrepSettings`` ps and the loop's ``LoopSettings`` ls.

    Returns (done (P,) bool: planned here; off (P+1,) sample offsets into s, q; s; q;
    stats (P, 7): backtracks, brake runs, brake steps, max steps, aim runs, exact, table
    pieces; table_err (P,)). A path whose preparation or loop fails, or whose rough
    estimate exceeds ``long_samples`` (it should stream), is left to the caller."""
    coef = paths.coef
    breaks = paths.breaks
    s_breaks = paths.s_breaks
    feed = paths.feed
    brake_cap = mc.brake_cap
    checkpoint_every = ls.checkpoint_every
    P = seg_off.shape[0] - 1
    n = coef.shape[2]
    done = np.zeros(P, dtype=np.bool_)
    off = np.zeros(P + 1, dtype=np.int64)
    s_all = np.empty(1024)
    q_all = np.empty((1024, n))
    pstats = np.zeros((P, 7), dtype=np.int64)
    perr = np.zeros(P)
    room = brake_cap + 8
    total = 0
    for p in range(P):
        a = seg_off[p]
        b = seg_off[p + 1]
        cf = coef[a:b]
        br = breaks[a + p : b + p + 1]
        sb = s_breaks[a + p : b + p + 1]
        r = prepare_identity(PathData(cf, br, sb, paths.w[p], paths.length[p], feed[a:b]), mc, ps)
        status = r[0]
        if status == TRIVIAL:
            q0 = start_point(cf)
            m = 1
            s_all, q_all = _grown(s_all, q_all, total, total + m)
            s_all[total] = 0.0
            q_all[total] = q0[0]
            total += 1
            off[p + 1] = total
            pstats[p, 6] = -1  # trivial: no table
            done[p] = True
            continue
        if status != OK or r[5] > long_samples:
            off[p + 1] = total
            continue
        _, pb, qstart, tol, gap_tol, est, max_steps, floor_h, pieces, max_err = r
        L = paths.length[p]
        sh, qh, st, runs, ds, ck, max_cap = new_loop(
            n, qstart, est, brake_cap, floor_h, room, np.int64(0), checkpoint_every
        )
        ds[DS_NEXT_CK] = checkpoint_every
        ds[DS_FAST] = 1 if ls.fast else 0
        checkpoint(sh, qh, st, runs, ds, ck, np.bool_(True))
        cfg = core.Settings(tol, max_steps, ls.easy_frac, gap_tol, ls.fast, ls.chain_seq, floor_h)
        res, sh, qh = drive(pb, cfg, checkpoint_every, sh, qh, st, runs, ds, ck, max_cap)
        if res != OK:
            off[p + 1] = total
            continue
        last = end_index(sh, np.int64(0), np.int64(0), ds[DS_END], L)
        m = last + 1
        s_all, q_all = _grown(s_all, q_all, total, total + m)
        s_all[total : total + m] = sh[:m]
        q_all[total : total + m] = qh[:m]
        q_all[total + m - 1] = pb.table.QEND
        total += m
        off[p + 1] = total
        for i in range(5):
            pstats[p, i] = runs.stats[i]
        pstats[p, 5] = 0 if ds[DS_FAST] != 0 else 1
        pstats[p, 6] = pieces
        perr[p] = max_err
        done[p] = True
    return done, off, s_all[:total], q_all[:total], pstats, perr

"""VPOp's planner: one path (or a batch of short paths) from rest to rest.

``_Prepared`` puts together what the step loop needs (the joint table, the limits in
step units, the feed, the bounds of ``step._easy``), ``_Loop`` runs the compiled driver
(``drive.drive``) over buffers that grow or slide, and ``iter_path_plan_vpop`` hands the
final samples out as they come (see the package docstring).
"""

from __future__ import annotations

import numpy as np

from ...constants import VPOP_LIMIT_SHRINK, VPOP_MIN_LENGTH, VPOP_ROUNDING_ULPS
from ...errors import PlanError
from ..base import PathPlan, collect_path_plan
from ..step_limits import position_scale, step_limits
from ..joint_table import JointTable, _no_length, _positions, concat_paths, identity_table_settings

#: share of each axis's jerk step the brake policy assumes it can use to end a stop
VPOP_BRAKE_JERK_FRACTION = 0.9

#: a brake run may end early once curvature uses at most this share of any axis's
#: acceleration and jerk over the rest of its stop (exact re-plan if that ever misleads)
VPOP_EASY_FRACTION = 0.25

#: an end-of-path "aim" run is committed when it stops within this many jerk steps
#: (jmax dt³ of the tightest axis) short of the end; the rest is crept from rest
VPOP_AIM_GAP_JERK_STEPS = 4.0

#: after a brake fix, how many of the following steps are tested in order for "max step,
#: then brake to rest" before the remaining ones (along the fix's own brake run) are
#: bisected and then probed below the answer (``step._chain_search``). Against testing
#: every step in order, measured on 10 programs: 1.1-3.2x less planning time,
#: cycle times -0.03..+1.4% (the worst on a helix at the acceleration limit)
VPOP_CHAIN_SEQUENTIAL = 2


#: equal samples short of the end (VPOp standing still) that count as a stall when
#: samples are handed out (``_standstill``): VPOp's own stops last three samples
VPOP_STANDSTILL_SAMPLES = 4096

#: the largest first buffer of a path's step loop (samples; it grows as needed)
VPOP_FIRST_BUFFER = 1 << 20

#: a checkpoint of the step loop is kept every this many samples; after a fast-mode failure
#: the path is re-planned exactly from the last one (the start for shorter paths), so
#: samples before it are final and can be handed out (1 min at 1 kHz)
VPOP_CHECKPOINT_SAMPLES = 1 << 16
#: the backtracking looks back at most this many brake runs (``brake_cap`` samples each)
#: before the failing step: a bounded look-ahead, so a long path streams in bounded memory
VPOP_LOOKBACK_BRAKE_RUNS = 4
#: a streamed path's own buffer (samples; at least two checkpoints' worth is kept)
VPOP_STREAM_WINDOW = 1 << 18
#: paths whose rough sample estimate exceeds this are streamed, not planned in a batch
VPOP_BATCH_MAX_SAMPLES = 1 << 17


def _core():
    from . import step

    return step


def _machine_consts(machine, dt: float):
    """Per-machine inputs of the preparation (``drive.MachineSteps``), computed once
    in Python (the same float operations as before the compiled path existed)."""
    from .drive import MachineSteps

    shrink = 1.0 - VPOP_LIMIT_SHRINK
    ramp = float(np.max(machine.vmax / machine.amax + machine.amax / machine.jmax))
    return MachineSteps(
        vl0=np.ascontiguousarray(machine.vmax * dt * shrink, dtype=float),
        al0=np.ascontiguousarray(machine.amax * dt * dt * shrink, dtype=float),
        jl0=np.ascontiguousarray(machine.jmax * dt**3 * shrink, dtype=float),
        jl_floor=np.ascontiguousarray(0.5 * machine.jmax * dt**3, dtype=float),
        vmax=np.ascontiguousarray(machine.vmax, dtype=float),
        ramp=ramp,
        dt=float(dt),
        brake_cap=8 * int(ramp / dt) + 4096,
        shrink=shrink,
    )


def _prep_settings():
    """The preparation's knobs (``drive.PrepSettings``)."""
    from .drive import PrepSettings

    return PrepSettings(
        VPOP_LOOKBACK_BRAKE_RUNS,
        *identity_table_settings(),  # table_tol .. max_tries, as JointTable builds its tables
        rounding_ulps=float(VPOP_ROUNDING_ULPS),
        brake_jerk_fraction=float(VPOP_BRAKE_JERK_FRACTION),
        aim_gap_steps=float(VPOP_AIM_GAP_JERK_STEPS),
        min_length=float(VPOP_MIN_LENGTH),
    )


def _fast(settings) -> bool:
    """Fast mode unless ``settings.vpop.exact`` (``PlanSettings``; ``None``: defaults)."""
    return settings is None or not settings.vpop.exact


class _Prepared:
    """Everything the step loop of one path needs (limits in step units, the joint table
    and its bounds, the feed per segment, sizes). Identity kinematics: one compiled call
    (``drive.prepare_identity``); other kinematics: the table through the joint map."""

    def __init__(self, path, joint_map, machine, dt_s: float, settings, table=None):
        from . import drive as D

        if path.rapid:
            joint_map = None
        self.path = path
        self.n = path.n_axes
        self.dt = dt = float(dt_s)
        mc = _machine_consts(machine, dt)
        self.brake_cap = mc.brake_cap
        self.fast = _fast(settings)
        self.trivial = False
        identity = joint_map is None or getattr(joint_map, "is_identity", False)
        if identity and table is None:
            data = D.PathData(path.coef, path.breaks, path.s_breaks, path.weights, float(path.length), path.feed_mm_s)
            r = D.prepare_identity(data, mc, _prep_settings())
            status = r[0]
            if status == D.NOT_FINITE_PATH:
                raise PlanError(f"bug: the fitted path ending at line {int(path.line[-1])} is not finite")
            if status == D.TRIVIAL:
                self.trivial = True
                self.q0 = _positions(path, path.breaks[:1], None)
                return
            if status == D.NO_LENGTH:
                _no_length(path)
            if status == D.NOT_FINITE:
                raise PlanError(
                    f"bug: the arc-length table of the path ending at line "
                    f"{int(path.line[-1])} is not finite (a point of zero speed?)"
                )
            if status == D.JERK_TOO_SMALL:
                raise PlanError(
                    f"the jerk limits are too small for dt = {dt:g} s at positions "
                    f"of {r[-1]:g} mm/deg: float64 cannot resolve them"
                )
            (_, self.pb, self.qstart, tol, gap_tol, self.est, max_steps, floor_h, self.pieces, self.max_err) = r
            self.qend = self.pb.table.QEND
            self.L = float(path.length)
            self.cfg = self._settings(tol, max_steps, gap_tol, floor_h)
            return
        self._prepare_mapped(path, joint_map, machine, dt, mc, table)

    def _prepare_mapped(self, path, joint_map, machine, dt, mc, table=None):
        """The preparation in Python, through the joint map (or on ``table``, a
        ``JointTable`` of this path already built: the optimal planner's)."""
        core = _core()
        if not (np.isfinite(path.length) and np.all(np.isfinite(path.coef))):
            raise PlanError(f"bug: the fitted path ending at line {int(path.line[-1])} is not finite")
        if path.length <= VPOP_MIN_LENGTH:
            self.trivial = True
            self.q0 = _positions(path, path.breaks[:1], joint_map)
            return
        if table is None:
            table = JointTable(path, joint_map)
        vl, al, jl = step_limits(machine, dt, position_scale(table.C))
        L = table.length
        self.L = L
        FB = np.ascontiguousarray(path.s_breaks, dtype=float).copy()
        FB[-1] = L
        FV = np.where(np.isfinite(path.feed_mm_s) & (path.feed_mm_s > 0), path.feed_mm_s * mc.shrink, 1e300)
        FV = np.ascontiguousarray(FV, dtype=float)
        # rough duration: travel at the slowest of feed and axis speeds, plus ramps
        dq = np.abs(table.qend - table.qstart)
        tv = float(np.max(dq / machine.vmax)) + L / float(np.min(FV))
        est = int((tv + 2 * mc.ramp) / dt) + 16
        self.est = est
        max_steps = 200 * est + 100_000
        floor_h = VPOP_LOOKBACK_BRAKE_RUNS * self.brake_cap
        tol = max(4.0 * np.spacing(max(L, 1.0)), 1e-7 * float(np.min(jl)))
        js = np.ascontiguousarray(jl * VPOP_BRAKE_JERK_FRACTION)
        K2, K3, K23 = (core.range_max_table(x) for x in table.curvature_bounds(al, jl))
        KV = core.range_max_table(table.speed_bounds(vl, path, FV * dt))
        gap_tol = VPOP_AIM_GAP_JERK_STEPS * float(np.min(jl))
        C_axis_major = np.ascontiguousarray(table.C.transpose(0, 2, 1))  # (m, n, 6)
        self.pb = core.Problem(
            core.Table(table.S, C_axis_major, table.qend),
            core.Limits(vl, al, jl),
            js,
            core.Feed(dt, L, FB, FV),
            core.Ease(K2, K3, K23, KV),
        )
        self.cfg = self._settings(tol, max_steps, gap_tol, floor_h)
        self.qend = table.qend
        self.qstart = table.qstart
        self.pieces = int(table.C.shape[0])
        self.max_err = float(table.max_err)

    def _settings(self, tol, max_steps, gap_tol, floor_h):
        """The step loop's ``step.Settings`` in fast mode."""
        return _core().Settings(
            tol=float(tol),
            max_steps=int(max_steps),
            easy_frac=float(VPOP_EASY_FRACTION),
            gap_tol=float(gap_tol),
            fast=True,
            chain_seq=int(VPOP_CHAIN_SEQUENTIAL),
            floor_h=int(floor_h),
        )


class VpopFailed(PlanError):
    """VPOp's step loop got stuck or found no feasible step on a path."""


class _Loop:
    """The step loop of one path (``drive.drive``): buffers that grow, or slide when
    ``window`` (samples) is set, checkpoints every ``checkpoint`` samples
    (``VPOP_CHECKPOINT_SAMPLES`` when None)."""

    def __init__(self, prep: _Prepared, window: int | None, checkpoint: int | None = None):
        from . import drive as D

        self.D = D
        self.p = prep
        self.checkpoint = VPOP_CHECKPOINT_SAMPLES if checkpoint is None else int(checkpoint)
        room = prep.brake_cap + 8
        (self.sh, self.qh, self.st, self.runs, self.ds, self.ck, self.max_cap) = D.new_loop(
            prep.n,
            prep.qstart,
            # the first buffer's size: the rough estimate, at most VPOP_FIRST_BUFFER (the
            # buffers grow): a G93 move's tiny feed on one segment made it 5e8 samples
            min(prep.est, VPOP_FIRST_BUFFER),
            prep.brake_cap,
            prep.cfg.floor_h,
            room,
            0 if window is None else max(1, int(window)),
            self.checkpoint,
        )
        self.stats = self.runs.stats
        self.ds[D.DS_NEXT_CK] = self.checkpoint
        self.ds[D.DS_FAST] = 1 if prep.fast else 0
        D.checkpoint(self.sh, self.qh, self.st, self.runs, self.ds, self.ck, True)

    def run(self) -> int:
        D, p = self.D, self.p
        res, self.sh, self.qh = D.drive(
            p.pb, p.cfg, self.checkpoint, self.sh, self.qh, self.st, self.runs, self.ds, self.ck, self.max_cap
        )
        if res == D.FAILED:
            core = _core()
            status = int(self.ds[D.DS_STATUS])
            k = int(self.st[core.ST_K])
            what = {core.STUCK: "made no progress", core.INFEASIBLE: "found no feasible step"}[status]
            raise VpopFailed(
                f"VPOp {what} on the path ending at line {int(p.path.line[-1])} "
                f"(s = {self.sh[max(k - 1, 0)]:.6g} of {p.L:.6g})"
            )
        return res

    def take(self, upto: int) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the samples from the last handed-out one up to global ``upto``."""
        D = self.D
        base, handed = int(self.ds[D.DS_BASE]), int(self.ds[D.DS_HANDED])
        a, b = handed - base, upto - base
        self.ds[D.DS_HANDED] = upto
        return self.sh[a:b].copy(), self.qh[a:b].copy()


def _final_stats(samples: int, st, exact: bool, pieces: int, max_err: float) -> dict:
    return {
        "samples": int(samples),
        "backtracks": int(st[0]),
        "brake_runs": int(st[1]),
        "brake_steps": int(st[2]),
        "max_steps": int(st[3]),
        "aim_runs": int(st[4]),
        "exact": bool(exact),
        "table_pieces": int(pieces),
        "table_err": float(max_err),
    }


def iter_path_plan_vpop(path, joint_map, machine, dt_s: float, settings=None, window: int | None = VPOP_STREAM_WINDOW):
    """VPOp on one path as a stream of ``PathPlan`` chunks (see ``plan.base``).

    Samples are handed out as soon as no later step can change them: the backtracking
    looks back at most ``VPOP_LOOKBACK_BRAKE_RUNS`` brake runs, and a fast-mode failure
    re-plans from the last checkpoint (every ``VPOP_CHECKPOINT_SAMPLES`` samples), so the
    step loop's buffers stay bounded (``window`` samples, at least two checkpoints'
    worth) however long the path. ``window=None`` keeps the whole path and yields one
    chunk. The chunks' concatenation does not depend on ``window``.

    VPOp can get stuck (rotary moves with almost no linear motion); when it
    does before handing out a sample, the safe planner (``plan.safe``), which cannot,
    plans the path (its stats carry ``fallback``).
    """
    prep = _Prepared(path, joint_map, machine, dt_s, settings)
    yield from iter_prepared(prep, joint_map, machine, settings, window)


def iter_prepared(
    prep: "_Prepared",
    joint_map,
    machine,
    settings,
    window: int | None,
    safe_fallback: bool = True,
    checkpoint: int | None = None,
):
    """``iter_path_plan_vpop`` on a prepared path (``_Prepared``); without
    ``safe_fallback`` a failure raises ``VpopFailed`` (the caller chooses the fallback).
    Samples are handed out after a checkpoint at the soonest, one every ``checkpoint``
    samples (``VPOP_CHECKPOINT_SAMPLES`` when None, the planner's own). After a
    fast-mode failure the loop re-plans exactly from the last checkpoint, so with another
    interval the samples after a failure may differ."""
    path = prep.path
    if prep.trivial:
        yield PathPlan(s=np.zeros(1), q=prep.q0, stats={"samples": 1})
        return
    loop = _Loop(prep, window, checkpoint)
    D = loop.D
    handed = False
    tail_s = tail_q = None  # the last three samples handed out (the state to brake from)
    while True:
        try:
            res = loop.run()
        except VpopFailed as exc:
            if handed:
                # samples are out: a stall mid-path is not an error either (a crawl past
                # the window, then "made no progress"): brake to rest from the last
                # sample handed out, then the safe planner for the rest
                yield rescue(prep, tail_s, tail_q, joint_map, machine, settings, str(exc))
                return
            if not safe_fallback:
                raise
            yield _safe_fallback(path, joint_map, machine, prep.dt, settings, str(exc))
            return
        if res != D.HAND_OUT:
            break
        upto = int(loop.ds[D.DS_CK_LO])
        held = _standstill(loop, upto, prep.L)
        if held is not None:
            # VPOp stands still short of the end: a stall that max_steps would only
            # report after hours of samples (a G93 A+Z move of 0.9 µm crawls, then
            # stands for millions of samples before "made no progress")
            why = (
                f"VPOp stood still for {VPOP_STANDSTILL_SAMPLES} samples on the path ending at line "
                f"{int(path.line[-1])} (s = {loop.sh[held - int(loop.ds[D.DS_BASE])]:.6g} of {prep.L:.6g})"
            )
            if not handed:
                yield _safe_fallback(path, joint_map, machine, prep.dt, settings, why)
                return
            s, q = loop.take(held + 3)  # up to the stop: the machine is at rest there
            tail_s, tail_q = _tail(tail_s, tail_q, s, q)
            if s.size:
                yield PathPlan(s=s, q=q, last=False)
            yield rescue(prep, tail_s, tail_q, joint_map, machine, settings, why)
            return
        s, q = loop.take(upto)
        if s.size:
            handed = True
            tail_s, tail_q = _tail(tail_s, tail_q, s, q)
            yield PathPlan(s=s, q=q, last=False)
    ds = loop.ds
    last = D.end_index(loop.sh, ds[D.DS_BASE], ds[D.DS_HANDED], ds[D.DS_END], prep.L)
    s, q = loop.take(int(last) + 1)
    q[-1] = prep.qend
    yield PathPlan(s=s, q=q, stats=_final_stats(last + 1, loop.stats, ds[D.DS_FAST] == 0, prep.pieces, prep.max_err))


def _standstill(loop, upto: int, L: float) -> int | None:
    """The global index of the first sample of a standstill of at least
    ``VPOP_STANDSTILL_SAMPLES`` equal samples short of the end ``L`` among the samples
    about to be handed out (up to global ``upto``), or None. VPOp stops mid-path only for
    the three samples of a stop; a long standstill is a stall."""
    D = loop.D
    base, handed = int(loop.ds[D.DS_BASE]), int(loop.ds[D.DS_HANDED])
    a = max(handed - base - 2, 0)
    s = loop.sh[a : upto - base]
    if s.shape[0] < VPOP_STANDSTILL_SAMPLES:
        return None
    same = np.concatenate(([False], s[1:] == s[:-1])) & (s < L)
    # run lengths of equal samples: a run of VPOP_STANDSTILL_SAMPLES - 1 equalities
    c = np.cumsum(~same)
    idx = np.flatnonzero(~same)
    runs = np.bincount(c - 1) if c.size else np.zeros(0, dtype=np.int64)
    long_runs = np.flatnonzero(runs >= VPOP_STANDSTILL_SAMPLES)
    if long_runs.size == 0:
        return None
    return base + a + int(idx[long_runs[0]])


def _tail(tail_s, tail_q, s, q):
    """The last three samples of what was handed out before and ``s``, ``q``."""
    if tail_s is not None:
        s = np.concatenate((tail_s, s))
        q = np.concatenate((tail_q, q))
    return s[-3:].copy(), q[-3:].copy()


class _TableView:
    """A compiled ``step.Table`` seen as a ``JointTable`` (S, C (m, 6, n), length, qend)
    for the safe planner, so that its samples follow the very table VPOp's did."""

    def __init__(self, table, L: float):
        self.S = np.ascontiguousarray(table.S, dtype=float)
        self.C = np.ascontiguousarray(np.transpose(table.C, (0, 2, 1)), dtype=float)
        self.qend = np.ascontiguousarray(table.QEND, dtype=float)
        self.length = float(L)


def rescue(prep: "_Prepared", tail_s, tail_q, joint_map, machine, settings, why: str) -> PathPlan:
    """The rest of a path after its samples up to ``tail_s[-1]`` are out (final) and the
    planner that made them stalled: VPOp's brake run to rest from the state of the last
    three samples ``tail_s`` (3,), ``tail_q`` (3, n) (exact mode, no early end: a stop is
    reachable from every sample VPOp commits), then ``safe.plan_path_safe`` from there, on
    the same joint table. The samples after ``tail_s[-1]``, as the path's last chunk
    (stats: ``fallback``, ``safe``, ``rescued_at``)."""
    from ..safe import plan_path_safe

    core = _core()
    path = prep.path
    n = prep.n
    cap = prep.brake_cap + 8
    sh = np.zeros(cap)
    qh = np.zeros((cap, n))
    sh[:3] = tail_s
    qh[:3] = tail_q
    runs = core.Runs(
        np.zeros(prep.brake_cap), np.zeros((prep.brake_cap, n)), np.zeros(prep.brake_cap),
        np.zeros((prep.brake_cap, n)), np.zeros(5, dtype=np.int64),
    )  # fmt: skip
    sc = core.Scratch(np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty((3, n)))
    c = prep.cfg
    cfg = core.Settings(c.tol, c.max_steps, 0.0, c.gap_tol, False, c.chain_seq, c.floor_h)
    ok, kk, _ = core._brake_run(prep.pb, sh, qh, np.int64(3), runs, sc, cfg, np.int64(1), 0.0, np.int64(0))
    if not ok:
        raise PlanError(f"{why}; no stop is reachable from the samples already handed out (a bug)")
    bs, bq = runs.bs[3:kk].copy(), runs.bq[3:kk].copy()
    s_stop = float(bs[-1]) if bs.size else float(tail_s[-1])
    table = _TableView(prep.pb.table, prep.L)
    rest = plan_path_safe(path, joint_map, machine, prep.dt, settings, table=table, s_start=s_stop)
    # the safe plan's first sample is the stop itself (already three times in bs)
    s = np.concatenate((bs, rest.s[1:]))
    q = np.concatenate((bq, rest.q[1:]))
    if s.size == 0 or s[-1] != prep.L:
        s = np.concatenate((s, [prep.L]))
        q = np.concatenate((q, np.asarray(prep.qend, dtype=float).reshape(1, -1)))
    q[-1] = prep.qend
    stats = dict(rest.stats or {})
    stats.update({"samples": int(s.shape[0]), "fallback": why, "safe": True, "rescued_at": float(tail_s[-1])})
    return PathPlan(s=s, q=q, stats=stats)


def _safe_fallback(path, joint_map, machine, dt, settings, why: str) -> PathPlan:
    from ..safe import plan_path_safe

    if path.rapid:
        joint_map = None
    plan = plan_path_safe(path, joint_map, machine, dt, settings)
    stats = dict(plan.stats or {})
    stats["fallback"] = why
    return PathPlan(s=plan.s, q=plan.q, status=plan.status, stats=stats)


class VpopRun:
    """VPOp's step loop on one path, prepared once (``_Prepared`` on a given joint table),
    runnable from a given history: the optimal planner hands its tail over this way.

    ``run(sh, qh, k0, b0)`` plans from sample k0 on, with samples < k0 fixed and b0 the
    last sample it may not move (0 from rest); the machine state there is whatever the
    samples before k0 say. Returns (status, k, sh, qh): ``step.OK`` and the end
    index k (samples < k planned), or the failure status; sh/qh may be new arrays.
    """

    def __init__(self, table, path, machine, dt: float, settings=None, joint_map=None):
        self.core = _core()
        self.p = p = _Prepared(path, joint_map, machine, dt, settings, table=table)
        self.L = p.L
        self.cap = max(64, 2 * p.est) + p.brake_cap + 24
        self.fast = p.fast

    def run(self, sh, qh, k0: int, b0: int):
        from . import drive as D

        core, p = self.core, self.p
        room = p.brake_cap + 8
        (_, _, st, runs, ds, ck, _) = D.new_loop(
            p.n, p.qstart, 1, p.brake_cap, p.cfg.floor_h, room, 0, VPOP_CHECKPOINT_SAMPLES
        )
        st[core.ST_K] = k0
        st[core.ST_B] = b0
        ds[D.DS_NEXT_CK] = k0 + VPOP_CHECKPOINT_SAMPLES
        ds[D.DS_FAST] = 1 if p.fast else 0
        sh = np.ascontiguousarray(sh, dtype=float)
        qh = np.ascontiguousarray(qh, dtype=float)
        if sh.shape[0] < k0 + room + 24:
            grow = k0 + room + 24 + self.cap
            sh = np.concatenate((sh, np.zeros(grow - sh.shape[0])))
            qh = np.concatenate((qh, np.zeros((grow - qh.shape[0], p.n))))
        D.checkpoint(sh, qh, st, runs, ds, ck, True)
        res, sh, qh = D.drive(p.pb, p.cfg, VPOP_CHECKPOINT_SAMPLES, sh, qh, st, runs, ds, ck, 0)
        self.fast = ds[D.DS_FAST] != 0
        self.stats = runs.stats
        if res == D.FAILED:
            return int(ds[D.DS_STATUS]), int(st[core.ST_K]), sh, qh
        return core.OK, int(ds[D.DS_END]), sh, qh


def plan_many_vpop(paths, machine, dt_s: float, settings=None, long_samples: int = VPOP_BATCH_MAX_SAMPLES):
    """VPOp on consecutive paths whose joints are the program axes (no kinematics, or
    rapids), in one compiled call: the same samples as ``iter_path_plan_vpop`` for each.
    Returns one ``PathPlan`` per path, or ``None`` for a path left to
    ``iter_path_plan_vpop`` (a long one, which should stream, or one whose preparation
    fails, so that the right error is raised there)."""
    from . import drive as D

    if not paths:
        return []
    dt = float(dt_s)
    mc = _machine_consts(machine, dt)
    coef, breaks, s_breaks, weights, lengths, feed, seg_off = concat_paths(paths)
    ls = D.LoopSettings(
        easy_frac=float(VPOP_EASY_FRACTION),
        chain_seq=int(VPOP_CHAIN_SEQUENTIAL),
        checkpoint_every=int(VPOP_CHECKPOINT_SAMPLES),
        fast=_fast(settings),
    )
    done, off, s_all, q_all, pstats, perr = D.plan_identity_batch(
        D.PathData(coef, breaks, s_breaks, weights, lengths, feed), seg_off, mc, _prep_settings(), ls, int(long_samples)
    )
    out = []
    offs = off.tolist()
    for i, ok in enumerate(done.tolist()):
        if not ok:
            out.append(None)
            continue
        a, b = offs[i], offs[i + 1]
        st = pstats[i]
        if st[6] < 0:
            out.append(PathPlan(s=s_all[a:b], q=q_all[a:b], stats={"samples": 1}))
            continue
        out.append(
            PathPlan(s=s_all[a:b], q=q_all[a:b], stats=_final_stats(b - a, st, bool(st[5]), int(st[6]), float(perr[i])))
        )
    return out


def batched_vpop(paths, joint_map, machine, dt_s: float, settings=None) -> list:
    """Which of ``paths`` ``plan_many_vpop`` plans as ``iter_path_plan_vpop`` does (the
    timeline's batch of a job's paths): every one when the joints are the program axes
    (``joint_map`` ``None``), with no stats to add ({}); ``None`` for a path to stream."""
    return [{} if joint_map is None else None for _ in paths]


iter_path_plan_vpop.batched = batched_vpop


def plan_path_vpop(path, joint_map, machine, dt_s: float, settings=None) -> PathPlan:
    """Plan one path from rest to rest with VPOp (see module docstring).

    ``joint_map`` maps program coordinates to joints (``None`` or an identity map for
    rapids, which are already in joint space). Returns a ``PathPlan`` whose q[0] and
    q[-1] are the path's exact joint start and end; the machine is at rest before and
    after, and every backward-difference limit holds. The same samples as the chunks
    of ``iter_path_plan_vpop``.
    """
    return collect_path_plan(iter_path_plan_vpop(path, joint_map, machine, dt_s, settings, window=None))

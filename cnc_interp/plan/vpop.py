"""VPOp (paper 001): maximum-feed interpolation under per-axis V/A/J limits.

``plan_path_vpop`` plans one ``Path`` from rest to rest at a fixed period dt:

1. The joint positions along the path, q(s) = kin(path(s)), are tabulated as quintic
   Hermite pieces in arc length s (values, first and second s-derivatives at the
   knots, taken from ``Path.derivatives_s`` through the kinematics). Pieces are split
   until the table matches the true path to ``VPOP_TABLE_TOL`` (mm or deg) at every
   piece's quarter points; the knots are exact path points and the last one is the
   exact programmed end. The setpoints emitted are the table's positions, so they
   lie within ``VPOP_TABLE_TOL`` of the fitted path (far below the fit tolerance),
   and ``verify`` checks exactly these numbers.
2. ``vpop_core.plan_core`` (numba) runs the step loop: max step in the allowed
   set, dichotomy back to the last step from which a brake reaches rest.

Streaming (``iter_path_plan_vpop``): the loop keeps its state across calls, so where its
buffers end never changes a sample; the backtracking looks back at most
``VPOP_LOOKBACK_BRAKE_RUNS`` brake runs, and a fast-mode failure is re-planned exactly
from the last checkpoint (one every ``VPOP_CHECKPOINT_SAMPLES``; the path's start on
shorter paths, as before), so the samples before the last checkpoint are final and are
handed out while the rest of the path is planned. ``vpop_drive`` holds the compiled
driver and, for identity kinematics, the compiled preparation; ``plan_many_vpop`` plans
many short paths in one call (the same samples). ``plan_path_vpop`` is the stream
collected.
"""

from __future__ import annotations

import numpy as np

from ..constants import VPOP_MIN_LENGTH, VPOP_LIMIT_SHRINK, VPOP_ROUNDING_ULPS
from ..errors import PlanError
from .base import PathPlan, collect_path_plan


#: largest deviation of VPOp's arc-length joint table from the true path (mm or deg)
VPOP_TABLE_TOL = 1e-9

#: longest piece of that table before refinement (mm or deg of arc length)
VPOP_TABLE_MAX_PIECE = 20.0

#: refinement rounds of the table (each halves the pieces that miss VPOP_TABLE_TOL)
VPOP_TABLE_MAX_ROUNDS = 12

#: Gauss–Legendre points per quarter piece for the table's arc lengths
VPOP_TABLE_GL_ORDER = 10

#: refinement passes of the table: when scaling it to the path's length pushes a piece
#: that passed its check over VPOP_TABLE_TOL, it is refined again against that scale
VPOP_TABLE_MAX_TRIES = 3

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
#: bisected and then probed below the answer (``vpop_core._chain_search``). Against testing
#: every step in order, measured on 10 programs: 1.1-3.2x less planning time,
#: cycle times -0.03..+1.4% (the worst on a helix at the acceleration limit)
VPOP_CHAIN_SEQUENTIAL = 2


# -- the arc-length table -------------------------------------------------------
def _joint_derivs(path, u: np.ndarray, joint_map) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q, q_s, q_ss (each (K, n)) in joint space at parameter values u."""
    d = path.derivatives_s(u, 2)
    p, ps, pss = d[0], d[1], d[2]
    identity = joint_map is None or getattr(joint_map, "is_identity", False)
    if identity:
        return p, ps, pss
    q = joint_map.to_joints(p)
    jac = getattr(joint_map, "jacobian", None)
    if jac is None:
        raise PlanError("kinematics without a jacobian cannot be planned by VPOp")
    J = jac(p)
    qs = np.einsum("kij,kj->ki", J, ps)
    # directional derivative of J along p_s by a central difference
    h = 1e-4
    Jp = jac(p + h * ps)
    Jm = jac(p - h * ps)
    dJ = (Jp - Jm) / (2 * h)
    qss = np.einsum("kij,kj->ki", J, pss) + np.einsum("kij,kj->ki", dJ, ps)
    return q, qs, qss


_GL_X, _GL_W = np.polynomial.legendre.leggauss(VPOP_TABLE_GL_ORDER)


def _kernels():
    from . import _table_kernels

    return _table_kernels


def _hermite(S, Q, Q1, Q2) -> np.ndarray:
    """Quintic Hermite power coefficients (m, 6, n) in s - S[p] for each piece."""
    h = np.diff(S)[:, None]
    c0, c1, c2 = Q[:-1], Q1[:-1], 0.5 * Q2[:-1]
    d0 = Q[1:] - (c0 + h * (c1 + h * c2))
    d1 = Q1[1:] - (c1 + 2.0 * h * c2)
    d2 = Q2[1:] - 2.0 * c2
    c3 = (20.0 * d0 - 8.0 * d1 * h + d2 * h * h) / (2.0 * h**3)
    c4 = (-30.0 * d0 + 14.0 * d1 * h - 2.0 * d2 * h * h) / (2.0 * h**4)
    c5 = (12.0 * d0 - 6.0 * d1 * h + d2 * h * h) / (2.0 * h**5)
    return np.ascontiguousarray(np.stack([c0, c1, c2, c3, c4, c5], axis=1))


def _eval_table(S, C, s):
    """Table positions (K, n) at arc lengths s (K,)."""
    p = np.clip(np.searchsorted(S, s, side="right") - 1, 0, C.shape[0] - 1)
    t = (s - S[p])[:, None]
    c = C[p]
    acc = c[:, 5]
    for i in range(4, -1, -1):
        acc = acc * t + c[:, i]
    return acc


def _refine_mapped(path, joint_map, tol: float, scale: float, max_depth: int):
    """Bisection of the initial pieces through the kinematics, one round per depth.

    Same pieces and checks as ``_table_kernels._refine`` (which serves the identity
    case in one compiled pass); only the pieces split in a round are recomputed in
    the next. Returns the accepted pieces in path order: ua, ub, seg, depth, ds
    (unscaled arc length), off (m, 3) arc length to the quarter points, qc (m, 3, n)
    joint positions there, and the local deviation found.
    """
    K = _kernels()
    coef, breaks, w = path.coef, path.breaks, path.weights
    n = path.n_axes
    ua, ub, seg = K.initial_pieces(breaks, path.s_breaks, VPOP_TABLE_MAX_PIECE)
    dep = np.zeros(ua.shape[0], dtype=np.int64)
    done = []
    while ua.shape[0]:
        uc, sub = K.quarter_arcs(coef, breaks, w, seg, ua, ub, _GL_X, _GL_W)
        ds = ((sub[:, 0] + sub[:, 1]) + sub[:, 2]) + sub[:, 3]
        keep = ds > 0  # pieces of zero length are dropped (the path stands still there)
        if not keep.all():
            ua, ub, seg, dep, uc, sub, ds = (x[keep] for x in (ua, ub, seg, dep, uc, sub, ds))
        off = np.cumsum(sub[:, :3], axis=1)
        qa = np.stack(_joint_derivs(path, ua, joint_map), axis=1)  # (K, 3, n)
        qb = np.stack(_joint_derivs(path, ub, joint_map), axis=1)
        qc = np.ascontiguousarray(_positions(path, uc.reshape(-1), joint_map).reshape(-1, 3, n))
        err = K.piece_errors(ds * scale, qa, qb, off * scale, qc)
        mid = 0.5 * (ua + ub)
        split = ~(err <= tol) & (dep < max_depth) & (ua < mid) & (mid < ub)
        ok = ~split
        done.append((ua[ok], ub[ok], seg[ok], dep[ok], ds[ok], off[ok], qc[ok], err[ok]))
        mid = mid[split]
        ua = np.concatenate((ua[split], mid))
        ub = np.concatenate((mid, ub[split]))
        seg = np.concatenate((seg[split], seg[split]))
        dep = np.concatenate((dep[split], dep[split])) + 1
    parts = [np.concatenate(x) for x in zip(*done)]
    order = np.argsort(parts[0], kind="stable")  # pieces do not overlap: u order is path order
    return [np.ascontiguousarray(x[order]) for x in parts]


def _build_mapped(path, joint_map, tol: float, max_depth: int):
    """(u, S, C, err) of the table through non-identity kinematics (see ``JointTable``)."""
    K = _kernels()
    tol_in, sc_in = tol, 1.0
    for _ in range(VPOP_TABLE_MAX_TRIES):
        ua, ub, seg, dep, ds, off, qc, e_loc = _refine_mapped(path, joint_map, tol_in, sc_in,
                                                              max_depth)
        if ds.size == 0 or not ds.sum() > 0:
            _no_length(path)
        scale = path.length / ds.sum()
        S = np.concatenate(([0.0], np.cumsum(ds * scale)))
        S[-1] = path.length
        u = np.concatenate((ua, ub[-1:]))
        Q = np.stack(_joint_derivs(path, u, joint_map), axis=1)  # (m+1, 3, n)
        C, err = K.hermite_check(S, Q, np.ascontiguousarray(off * scale), qc)
        over = (e_loc <= tol_in) & (dep < max_depth) & ~(err <= tol)
        if not over.any():
            break
        if scale != sc_in:  # check again against the scale the table gets
            sc_in = scale
        else:  # rounding (S is summed along the path): fail those pieces locally next time
            excess = float(np.max(err[over] - tol))
            low = float(np.min(e_loc[over])) * (1.0 - 1e-9)
            tol_in = max(min(tol_in - 2.0 * excess, low), 0.5 * tol_in)
    return u, S, C, err


def _no_length(path):
    raise PlanError(f"bug: the path ending at line {int(path.line[-1])} has length "
                    f"{path.length:g} but no measurable arc length")


class JointTable:
    """q(s) of one path as quintic pieces: knots ``S`` (m+1,), coefficients ``C`` (m, 6, n),
    exact end point ``qend`` (n,), and the largest deviation found at the check points
    ``max_err`` (mm / deg).

    Construction: the path's segments are cut into pieces of at most
    ``VPOP_TABLE_MAX_PIECE`` of arc length, and each piece is bisected in u until its
    quintic Hermite interpolant (ends: exact q, q_s, q_ss at path points) is within
    ``tol`` of the true path at its three quarter points, at most
    ``VPOP_TABLE_MAX_ROUNDS - 1`` times. Arc lengths come from a Gauss–Legendre rule
    (``VPOP_TABLE_GL_ORDER`` points) on each quarter of each piece, computed once per
    piece, and are scaled by one factor so that the last knot is ``path.length``
    exactly; the checks are repeated on that final table, and ``max_err`` is their
    largest result. Identity kinematics runs in one compiled pass
    (``_table_kernels.build_identity``), other kinematics round by round.
    """

    def __init__(self, path, joint_map, tol: float = VPOP_TABLE_TOL):
        max_depth = VPOP_TABLE_MAX_ROUNDS - 1
        identity = joint_map is None or getattr(joint_map, "is_identity", False)
        if identity:  # one compiled call (per-path overhead matters: CAM has 1e5 paths)
            K = _kernels()
            status, u, S, C, max_err, qend = K.build_identity(
                path.coef, path.breaks, path.s_breaks, path.weights, float(path.length),
                float(tol), max_depth, float(VPOP_TABLE_MAX_PIECE), _GL_X, _GL_W,
                VPOP_TABLE_MAX_TRIES)
            if status == K.NO_LENGTH:
                _no_length(path)
            finite = status != K.NOT_FINITE
        else:
            u, S, C, err = _build_mapped(path, joint_map, float(tol), max_depth)
            qend = np.ascontiguousarray(_positions(path, path.breaks[-1:], joint_map)[0])
            max_err = float(err.max()) if err.size else 0.0
            finite = bool(np.all(np.isfinite(C)))
        if not finite:
            raise PlanError(f"bug: the arc-length table of the path ending at line "
                            f"{int(path.line[-1])} is not finite (a point of zero speed?)")
        self.u = u
        self.S = S
        self.C = C
        self.qend = qend
        self.qstart = C[0, 0].copy()
        self.max_err = float(max_err)
        self.length = float(path.length)


    def curvature_bounds(self, al: np.ndarray, jl: np.ndarray):
        """Per piece: max_i |q_ss,i|/al_i, max_i |q_sss,i|/jl_i and max_i 3|q_ss,i|/jl_i,
        sampled at five points of the piece with a 25% margin (step units)."""
        al = np.ascontiguousarray(al, dtype=float)
        jl = np.ascontiguousarray(jl, dtype=float)
        return _kernels().curvature_bounds(self.S, self.C, al, jl)


    def speed_bounds(self, vl: np.ndarray, path, feed_step: np.ndarray) -> np.ndarray:
        """Per piece: the largest of max_i |q_s,i|/vl_i (sampled, 2% margin) and
        1/(feed step) of its path segment; d1 times it must stay <= 1 (step units)."""
        kv = _kernels().speed_bound(self.S, self.C, np.ascontiguousarray(vl, dtype=float))
        seg = path.segment_of_s(0.5 * (self.S[:-1] + self.S[1:]))
        kf = 1.0 / feed_step[seg]
        return np.ascontiguousarray(np.maximum(kv, kf))


def _positions(path, u, joint_map):
    p = path.derivatives_u(np.asarray(u, dtype=float), 0)[0]
    if joint_map is None or getattr(joint_map, "is_identity", False):
        return p
    return joint_map.to_joints(p)


# -- the planner --------------------------------------------------------------------
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
    from . import vpop_core

    return vpop_core


def _machine_consts(machine, dt: float):
    """Per-machine inputs of the preparation (``vpop_drive.MachineSteps``), computed once
    in Python (the same float operations as before the compiled path existed)."""
    from .vpop_drive import MachineSteps

    shrink = 1.0 - VPOP_LIMIT_SHRINK
    ramp = float(np.max(machine.vmax / machine.amax + machine.amax / machine.jmax))
    return MachineSteps(
        vl0=np.ascontiguousarray(machine.vmax * dt * shrink, dtype=float),
        al0=np.ascontiguousarray(machine.amax * dt * dt * shrink, dtype=float),
        jl0=np.ascontiguousarray(machine.jmax * dt**3 * shrink, dtype=float),
        jl_floor=np.ascontiguousarray(0.5 * machine.jmax * dt**3, dtype=float),
        vmax=np.ascontiguousarray(machine.vmax, dtype=float),
        ramp=ramp, dt=float(dt), brake_cap=8 * int(ramp / dt) + 4096, shrink=shrink)


def _prep_settings():
    """The preparation's knobs (``vpop_drive.PrepSettings``)."""
    from .vpop_drive import PrepSettings

    return PrepSettings(
        lookback=VPOP_LOOKBACK_BRAKE_RUNS, table_tol=float(VPOP_TABLE_TOL),
        max_depth=VPOP_TABLE_MAX_ROUNDS - 1, max_piece=float(VPOP_TABLE_MAX_PIECE), glx=_GL_X,
        glw=_GL_W, max_tries=VPOP_TABLE_MAX_TRIES, rounding_ulps=float(VPOP_ROUNDING_ULPS),
        brake_jerk_fraction=float(VPOP_BRAKE_JERK_FRACTION),
        aim_gap_steps=float(VPOP_AIM_GAP_JERK_STEPS), min_length=float(VPOP_MIN_LENGTH))


def _fast(settings) -> bool:
    get = getattr(settings, "get", lambda *_: None)
    return bool(get("vpop_exact") is not True)


class _Prepared:
    """Everything the step loop of one path needs (limits in step units, the joint table
    and its bounds, the feed per segment, sizes). Identity kinematics: one compiled call
    (``vpop_drive.prepare_identity``); other kinematics: the table through the joint map."""

    def __init__(self, path, joint_map, machine, dt_s: float, settings, table=None):
        from . import vpop_drive as D

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
            data = D.PathData(path.coef, path.breaks, path.s_breaks, path.weights,
                              float(path.length), path.feed_mm_s)
            r = D.prepare_identity(data, mc, _prep_settings())
            status = r[0]
            if status == D.NOT_FINITE_PATH:
                raise PlanError(f"bug: the fitted path ending at line {int(path.line[-1])} is "
                                "not finite")
            if status == D.TRIVIAL:
                self.trivial = True
                self.q0 = _positions(path, path.breaks[:1], None)
                return
            if status == D.NO_LENGTH:
                _no_length(path)
            if status == D.NOT_FINITE:
                raise PlanError(f"bug: the arc-length table of the path ending at line "
                                f"{int(path.line[-1])} is not finite (a point of zero speed?)")
            if status == D.JERK_TOO_SMALL:
                raise PlanError(f"the jerk limits are too small for dt = {dt:g} s at positions "
                                f"of {r[-1]:g} mm/deg: float64 cannot resolve them")
            (_, self.pb, self.qstart, tol, gap_tol, self.est, max_steps, floor_h, self.pieces,
             self.max_err) = r
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
        # Absolute margin for float rounding: a few ulps of the positions, times the 8 of
        # the jerk stencil (1, 3, 3, 1), so that one-ulp differences between what the loop
        # checked and what reaches verify (joins between paths, re-evaluated end points)
        # cannot push a low limit (jmax * dt**3 ~ 1e-6 mm) past its ratio slack.
        q_scale = 1.0 + float(np.max(np.abs(table.C[:, 0, :])))
        margin = VPOP_ROUNDING_ULPS * np.finfo(float).eps * q_scale
        vl = np.ascontiguousarray(mc.vl0 - 2.0 * margin)
        al = np.ascontiguousarray(mc.al0 - 4.0 * margin)
        jl = np.ascontiguousarray(mc.jl0 - 8.0 * margin)
        if np.any(jl <= mc.jl_floor):
            raise PlanError(f"the jerk limits are too small for dt = {dt:g} s at positions of "
                            f"{q_scale:g} mm/deg: float64 cannot resolve them")
        L = table.length
        self.L = L
        FB = np.ascontiguousarray(path.s_breaks, dtype=float).copy()
        FB[-1] = L
        FV = np.where(np.isfinite(path.feed_mm_s) & (path.feed_mm_s > 0),
                      path.feed_mm_s * mc.shrink, 1e300)
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
        self.pb = core.Problem(core.Table(table.S, C_axis_major, table.qend),
                               core.Limits(vl, al, jl), js, core.Feed(dt, L, FB, FV),
                               core.Ease(K2, K3, K23, KV))
        self.cfg = self._settings(tol, max_steps, gap_tol, floor_h)
        self.qend = table.qend
        self.qstart = table.qstart
        self.pieces = int(table.C.shape[0])
        self.max_err = float(table.max_err)

    def _settings(self, tol, max_steps, gap_tol, floor_h):
        """The step loop's ``vpop_core.Settings`` in fast mode."""
        return _core().Settings(tol=float(tol), max_steps=int(max_steps),
                                easy_frac=float(VPOP_EASY_FRACTION), gap_tol=float(gap_tol),
                                fast=True, chain_seq=int(VPOP_CHAIN_SEQUENTIAL),
                                floor_h=int(floor_h))


class VpopFailed(PlanError):
    """VPOp's step loop got stuck or found no feasible step on a path."""


class _Loop:
    """The step loop of one path (``vpop_drive.drive``): buffers that grow, or slide when
    ``window`` (samples) is set, checkpoints every ``VPOP_CHECKPOINT_SAMPLES``."""

    def __init__(self, prep: _Prepared, window: int | None):
        from . import vpop_drive as D

        self.D = D
        self.p = prep
        room = prep.brake_cap + 8
        (self.sh, self.qh, self.st, self.runs, self.ds, self.ck, self.max_cap) = D.new_loop(
            prep.n, prep.qstart, prep.est, prep.brake_cap, prep.cfg.floor_h, room,
            0 if window is None else max(1, int(window)), VPOP_CHECKPOINT_SAMPLES)
        self.stats = self.runs.stats
        self.ds[D.DS_NEXT_CK] = VPOP_CHECKPOINT_SAMPLES
        self.ds[D.DS_FAST] = 1 if prep.fast else 0
        D.checkpoint(self.sh, self.qh, self.st, self.runs, self.ds, self.ck, True)

    def run(self) -> int:
        D, p = self.D, self.p
        res, self.sh, self.qh = D.drive(p.pb, p.cfg, VPOP_CHECKPOINT_SAMPLES, self.sh, self.qh,
                                        self.st, self.runs, self.ds, self.ck, self.max_cap)
        if res == D.FAILED:
            core = _core()
            status = int(self.ds[D.DS_STATUS])
            k = int(self.st[core.ST_K])
            what = {core.STUCK: "made no progress", core.INFEASIBLE: "found no feasible step"}[status]
            raise VpopFailed(f"VPOp {what} on the path ending at line {int(p.path.line[-1])} "
                             f"(s = {self.sh[max(k - 1, 0)]:.6g} of {p.L:.6g})")
        return res

    def take(self, upto: int) -> tuple[np.ndarray, np.ndarray]:
        """Copies of the samples from the last handed-out one up to global ``upto``."""
        D = self.D
        base, handed = int(self.ds[D.DS_BASE]), int(self.ds[D.DS_HANDED])
        a, b = handed - base, upto - base
        self.ds[D.DS_HANDED] = upto
        return self.sh[a:b].copy(), self.qh[a:b].copy()


def _final_stats(samples: int, st, exact: bool, pieces: int, max_err: float) -> dict:
    return {"samples": int(samples), "backtracks": int(st[0]), "brake_runs": int(st[1]),
            "brake_steps": int(st[2]), "max_steps": int(st[3]), "aim_runs": int(st[4]),
            "exact": bool(exact), "table_pieces": int(pieces), "table_err": float(max_err)}


def iter_path_plan_vpop(path, joint_map, machine, dt_s: float, settings=None,
                        window: int | None = VPOP_STREAM_WINDOW):
    """VPOp on one path as a stream of ``PathPlan`` chunks (see ``plan.base``).

    Samples are handed out as soon as no later step can change them: the backtracking
    looks back at most ``VPOP_LOOKBACK_BRAKE_RUNS`` brake runs, and a fast-mode failure
    re-plans from the last checkpoint (every ``VPOP_CHECKPOINT_SAMPLES`` samples), so the
    step loop's buffers stay bounded (``window`` samples, at least two checkpoints'
    worth) however long the path. ``window=None`` keeps the whole path and yields one
    chunk. The chunks' concatenation does not depend on ``window``.

    VPOp can get stuck (issue 13: rotary moves with almost no linear motion); when it
    does before handing out a sample, the safe planner (``plan.safe``), which cannot,
    plans the path (its stats carry ``fallback``).
    """
    prep = _Prepared(path, joint_map, machine, dt_s, settings)
    yield from iter_prepared(prep, joint_map, machine, settings, window)


def iter_prepared(prep: "_Prepared", joint_map, machine, settings, window: int | None,
                  safe_fallback: bool = True):
    """``iter_path_plan_vpop`` on a prepared path (``_Prepared``); without
    ``safe_fallback`` a failure raises ``VpopFailed`` (the caller chooses the fallback)."""
    path = prep.path
    if prep.trivial:
        yield PathPlan(s=np.zeros(1), q=prep.q0, stats={"samples": 1})
        return
    loop = _Loop(prep, window)
    D = loop.D
    handed = False
    while True:
        try:
            res = loop.run()
        except VpopFailed as exc:
            if handed or not safe_fallback:
                raise
            yield _safe_fallback(path, joint_map, machine, prep.dt, settings, str(exc))
            return
        if res != D.HAND_OUT:
            break
        s, q = loop.take(int(loop.ds[D.DS_CK_LO]))
        if s.size:
            handed = True
            yield PathPlan(s=s, q=q, last=False)
    ds = loop.ds
    last = D.end_index(loop.sh, ds[D.DS_BASE], ds[D.DS_HANDED], ds[D.DS_END], prep.L)
    s, q = loop.take(int(last) + 1)
    q[-1] = prep.qend
    yield PathPlan(s=s, q=q, stats=_final_stats(last + 1, loop.stats, ds[D.DS_FAST] == 0,
                                                prep.pieces, prep.max_err))


def _safe_fallback(path, joint_map, machine, dt, settings, why: str) -> PathPlan:
    from .safe import plan_path_safe

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
    samples before k0 say. Returns (status, k, sh, qh): ``vpop_core.OK`` and the end
    index k (samples < k planned), or the failure status; sh/qh may be new arrays.
    """

    def __init__(self, table, path, machine, dt: float, settings=None, joint_map=None):
        self.core = _core()
        self.p = p = _Prepared(path, joint_map, machine, dt, settings, table=table)
        self.L = p.L
        self.cap = max(64, 2 * p.est) + p.brake_cap + 24
        self.fast = p.fast

    def run(self, sh, qh, k0: int, b0: int):
        from . import vpop_drive as D

        core, p = self.core, self.p
        room = p.brake_cap + 8
        (_, _, st, runs, ds, ck, _) = D.new_loop(
            p.n, p.qstart, 1, p.brake_cap, p.cfg.floor_h, room, 0, VPOP_CHECKPOINT_SAMPLES)
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


def plan_many_vpop(paths, machine, dt_s: float, settings=None,
                   long_samples: int = VPOP_BATCH_MAX_SAMPLES):
    """VPOp on consecutive paths whose joints are the program axes (no kinematics, or
    rapids), in one compiled call: the same samples as ``iter_path_plan_vpop`` for each.
    Returns one ``PathPlan`` per path, or ``None`` for a path left to
    ``iter_path_plan_vpop`` (a long one, which should stream, or one whose preparation
    fails, so that the right error is raised there)."""
    from . import vpop_drive as D

    if not paths:
        return []
    dt = float(dt_s)
    mc = _machine_consts(machine, dt)
    n_seg = np.array([p.n_seg for p in paths], dtype=np.int64)
    seg_off = np.zeros(len(paths) + 1, dtype=np.int64)
    np.cumsum(n_seg, out=seg_off[1:])
    coef = np.concatenate([p.coef for p in paths])
    breaks = np.concatenate([p.breaks for p in paths])
    s_breaks = np.concatenate([p.s_breaks for p in paths])
    weights = np.array([p.weights for p in paths], dtype=float)
    lengths = np.array([p.length for p in paths], dtype=float)
    feed = np.concatenate([p.feed_mm_s for p in paths])
    ls = D.LoopSettings(easy_frac=float(VPOP_EASY_FRACTION), chain_seq=int(VPOP_CHAIN_SEQUENTIAL),
                        checkpoint_every=int(VPOP_CHECKPOINT_SAMPLES), fast=_fast(settings))
    done, off, s_all, q_all, pstats, perr = D.plan_identity_batch(
        D.PathData(coef, breaks, s_breaks, weights, lengths, feed), seg_off, mc, _prep_settings(), ls,
        int(long_samples))
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
        out.append(PathPlan(s=s_all[a:b], q=q_all[a:b],
                            stats=_final_stats(b - a, st, bool(st[5]), int(st[6]), float(perr[i]))))
    return out


def plan_path_vpop(path, joint_map, machine, dt_s: float, settings=None) -> PathPlan:
    """Plan one path from rest to rest with VPOp (see module docstring).

    ``joint_map`` maps program coordinates to joints (``None`` or an identity map for
    rapids, which are already in joint space). Returns a ``PathPlan`` whose q[0] and
    q[-1] are the path's exact joint start and end; the machine is at rest before and
    after, and every backward-difference limit holds. The same samples as the chunks
    of ``iter_path_plan_vpop``.
    """
    return collect_path_plan(iter_path_plan_vpop(path, joint_map, machine, dt_s, settings,
                                                 window=None))

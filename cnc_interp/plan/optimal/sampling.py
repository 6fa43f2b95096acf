"""Time law and exact sampling: the profile's samples, one per period, each exact.

The time law: nodes (s_i, t_i, v_i, a_i) of a profile piece w(s) = ṡ² (``profile``), with
v = √w, a = w'/2 and t_i = ∫ ds/√w, ``tuning.timelaw_nodes`` per knot interval,
integrated with Gauss–Legendre (``TIMELAW_GL`` points; an interval that starts or ends
at rest, w = 0 with w' ≠ 0, is integrated in u with s = s_a + u² or s = s_b - u², where
the integrand is smooth). Between nodes s(t) is the quintic Hermite interpolant of
(s, v, a) at both ends: C² in time, so the sampled reference has bounded third
differences. A piece whose w dips below ``tuning.timelaw_min_dip`` between nodes is
refused: VPOp finishes the path from there.

The sampler (``_sampled_from``, with ``_track_kernels.track``): the time law one sample
per period, each checked with exactly the float operations of ``verify`` and moved to
the nearest allowed position where the reference would exceed a limit. Where no position
is allowed (the LP holds its limits at collocation points only): stuck stopping at the
end (within ``tuning.end_window`` periods of the reference's end), the refinement's
window solver lands the plan at rest from ``tuning.end_window`` samples back (``_land``,
``refine.land``); elsewhere VPOp's step loop (``vpop.VpopRun``) finishes the path from a
few samples back (``tuning.handover_back``). The sampler holds back the longest
hand-over or landing; the rest is final and leaves.

``_vpop_stage`` is the other sampler: VPOp's plan of the path as a stream of blocks
(where VPOp fails, the profile's if the path was VPOp's route, else the safe planner).
"""

from __future__ import annotations

import numpy as np

from .. import _feed_kernels as K
from ..prefetch import Prefetch
from ..tuning import OptimalTuning
from .context import _Fallback
from .route import Route

#: Gauss–Legendre points per node interval of the time integral (the quadrature's order:
#: exact for the polynomial integrands it meets, not a tunable)
TIMELAW_GL = 6

_GX, _GW = np.polynomial.legendre.leggauss(TIMELAW_GL)


class TimeLaw:
    """A profile piece's time law: nodes ``s`` (K,), mm; the time of each node interval
    ``dt`` (K-1,), s; at the nodes w = ṡ² ``w`` (K,), mm²/s², its derivative ``w1`` (K,),
    mm/s², the speed ``v`` = √w (K,), mm/s, and the acceleration ``a`` = w'/2 (K,), mm/s²."""

    __slots__ = ("s", "dt", "v", "a", "w", "w1")

    def __init__(self, s, dt, w, w1):
        self.s, self.dt, self.w, self.w1 = s, dt, w, w1
        self.v = np.sqrt(w)
        self.a = 0.5 * w1

    def nodes(self, t0: float):
        """(s, t, v, a) with the first node at time t0."""
        return self.s, t0 + np.concatenate(([0.0], np.cumsum(self.dt))), self.v, self.a


def time_law(knots, coef, s0: float, s1: float, tuning: OptimalTuning):
    """The ``TimeLaw`` of the profile piece (knots, coef) on [s0, s1], ``tuning.timelaw_nodes``
    nodes per knot interval; None when w (nearly) reaches zero inside: it dips between two
    nodes below ``tuning.timelaw_min_dip`` of the smaller node value (the sampler would
    crawl there; the planner hands over to VPOp instead)."""
    br = np.unique(knots)
    br = br[(br > s0) & (br < s1)]
    br = np.concatenate(([s0], br, [s1]))
    u = np.arange(tuning.timelaw_nodes) / tuning.timelaw_nodes
    x = (br[:-1, None] + np.diff(br)[:, None] * u[None, :]).ravel()
    x = np.concatenate((x, [s1]))
    got = _law(knots, coef, x, tuning.timelaw_min_dip)
    return None if got is None else TimeLaw(x, *got)


def _law(knots, coef, x, min_dip: float):
    """(dt, w, w1) at sorted nodes x (K,): each node interval's time (K-1,), w = ṡ² and
    w' at the nodes (w clipped at 0); None when w dips below ``min_dip`` of the smaller
    node value between two nodes (``_feed_kernels.time_nodes``)."""
    x = np.ascontiguousarray(x, dtype=float)
    K_ = x.shape[0]
    dt = np.empty(max(K_ - 1, 0))
    w = np.empty(K_)
    w1 = np.empty(K_)
    coef = np.ascontiguousarray(coef, dtype=float)
    if not K.time_nodes(knots, coef, x, _GX, _GW, min_dip, dt, w, w1):
        return None
    return dt, w, w1


class _Nodes:
    """The time-law nodes of the committed profile, appended piece by piece."""

    def __init__(self, tuning: OptimalTuning):
        self.tuning = tuning
        self.ends: list[float] = []  # each appended piece's end s1
        self.s = np.zeros(0)
        self.t = np.zeros(0)
        self.v = np.zeros(0)
        self.a = np.zeros(0)

    def append(self, knots, coef, s0, s1) -> bool:
        """Append a profile piece's nodes; False (nothing appended) if its time law is
        not finite."""
        law = time_law(knots, coef, s0, s1, self.tuning)
        if law is None:
            return False
        t0 = float(self.t[-1]) if self.t.size else 0.0
        ns, nt, nv, na = law.nodes(t0)
        if not (np.all(np.isfinite(nt)) and np.all(np.isfinite(nv)) and np.all(np.isfinite(na))):
            return False
        self.ends.append(s1)
        if self.s.size:
            ns, nt, nv, na = ns[1:], nt[1:], nv[1:], na[1:]
        self.s = np.concatenate((self.s, ns))
        self.t = np.concatenate((self.t, nt))
        self.v = np.concatenate((self.v, nv))
        self.a = np.concatenate((self.a, na))
        return True

    def drop_before(self, s_keep: float):
        """Forget the pieces (and their nodes) that end before s_keep, but the last."""
        while len(self.ends) > 1 and self.ends[0] < s_keep:
            s1 = self.ends.pop(0)
            i = int(np.searchsorted(self.s, s1, side="left"))
            self.s, self.t, self.v, self.a = self.s[i:], self.t[i:], self.v[i:], self.a[i:]


def _sampled(ctx, ahead: bool = False):
    """Yields (s, q) blocks of final samples (see module docstring).
    ``ahead``: the profile's windows are solved by a thread of their own, ahead of the
    sampling (the samples do not depend on it)."""
    from .profile import FeedProfileBuilder

    T = ctx.tuning
    builder = FeedProfileBuilder(ctx.table, ctx.path, ctx.machine, ctx.dt, T, whole=ctx.whole)
    if not ahead:
        yield from _sampled_from(ctx, builder.windows())
        return
    pieces = Prefetch(builder.windows(), ahead=T.ahead_pieces, name="cnc-interp-feed")
    try:
        yield from _sampled_from(ctx, iter(pieces))
    finally:
        pieces.close()  # the sampling may stop before the last piece (VPOp finishes)


def _sampled_from(ctx, pieces):
    """``_sampled`` on the profile's ``FeedPiece``s from the iterator ``pieces``."""
    from .. import _track_kernels as TK
    from .profile import ProfileError

    dt, n, L, T = ctx.dt, ctx.n, ctx.L, ctx.tuning
    nodes = _Nodes(T)
    final = False
    # what a hand-over or a landing may take back
    hold = max(T.handover_back[-1], T.end_window) + 8
    cap = 4 * hold + 64
    sh = np.zeros(cap)
    qh = np.zeros((cap, n))
    qh[0] = ctx.table.qstart
    k = 1  # next sample, index into the buffer
    base = 0  # global index of buffer[0]
    emitted = 0  # global index of the first sample not yet emitted
    stats = np.zeros(2, dtype=np.int64)
    # a sane bound on the samples: ten times the path's duration at its feed or static
    # limits, plus ramps (the profile is never that slow unless something went wrong)
    max_samples = int(10.0 * ctx.duration_s / dt) + 100_000
    while True:
        if base + k > max_samples:
            # the reference crawls (a bug, or a profile that nearly stops): VPOp
            # finishes the path
            ctx.stats["sample_budget"] = True
            status, final = TK.STUCK, True
        else:
            status, k = (
                (TK.NEED_REF, k)
                if nodes.s.size < 2
                else TK.track(
                    TK.Reference(nodes.s, nodes.t, nodes.v, nodes.a, nodes.s.shape[0]),
                    final,
                    ctx.joints,
                    ctx.limits,
                    ctx.feed_caps,
                    sh,
                    qh,
                    k,
                    ctx.tol,
                    stats,
                )
            )
        if status == TK.NEED_REF:
            try:
                piece = next(pieces)
            except ProfileError as exc:
                if nodes.s.size == 0:
                    raise _Fallback("profile") from exc
                piece = None
            if piece is None:  # VPOp finishes from here
                status = TK.STUCK
                final = True
            elif not _append_piece(ctx, nodes, piece):
                if nodes.s.size == 0:
                    raise _Fallback("reference")
                status = TK.STUCK  # the profile stops inside a piece: VPOp finishes
                final = True
            else:
                final = piece.s1 >= L
                continue
        if status == TK.OK:
            ctx.stats["clamped"] = int(stats[0])
            yield _final_chunk(sh, qh, k, L, emitted - base, ctx.table.qend)
            return
        if status == TK.NEED_SPACE:
            # emit what no hand-over or landing can change, then compact the buffer
            upto = base + k - hold
            if upto > emitted:
                yield sh[emitted - base : upto - base].copy(), qh[emitted - base : upto - base].copy()
                emitted = upto
            keep_from = emitted - 3 - base
            if keep_from > 0:
                sh[: k - keep_from] = sh[keep_from:k]
                qh[: k - keep_from] = qh[keep_from:k]
                base += keep_from
                k -= keep_from
                nodes.drop_before(float(sh[0]))
            if k + 16 >= sh.shape[0]:
                sh = np.concatenate((sh, np.zeros(sh.shape[0])))
                qh = np.concatenate((qh, np.zeros((qh.shape[0], n))))
            continue
        # STUCK at buffer index k
        t_here, _ = TK.ref_t_of_s(nodes.s, nodes.t, nodes.v, nodes.a, nodes.s.shape[0], sh[k - 1], 0)
        if final and nodes.t[-1] - t_here <= T.end_window * dt:
            # stuck stopping at the end: the window solver lands the plan from a few
            # samples back (VPOp's greedy stop needs many more)
            landed = _land(ctx, nodes, sh, qh, k, emitted - base)
            if landed is not None:
                sh, qh, k = landed
                ctx.stats["landed"] = True
                ctx.stats["clamped"] = int(stats[0])
                yield _final_chunk(sh, qh, k, L, emitted - base, ctx.table.qend)
                return
        # VPOp finishes the path from a few samples back (within what is held)
        done = False
        for back in T.handover_back:
            k0 = max(k - back, emitted - base + 1, 1)
            st, kk, sh2, qh2 = ctx.vrun().run(sh.copy(), qh.copy(), k0, k0 - 1)
            if st == ctx.vrun().core.OK:
                sh, qh, k, done = sh2, qh2, kk, True
                ctx.stats["handover"] = int(base + k0)  # global index of the first sample VPOp planned
                break
            if k0 <= emitted - base + 1:
                break
        if not done:
            raise _Fallback("stuck")
        status = TK.OK
        ctx.stats["clamped"] = int(stats[0])
        yield _final_chunk(sh, qh, k, L, emitted - base, ctx.table.qend)
        return


def _land(ctx, nodes, sh, qh, k: int, first: int):
    """The buffer (sh, qh) brought to rest at the end from ``tuning.end_window`` samples
    before k (not before ``first``, the first sample not yet emitted) by
    ``refine.land``, its tries starting from the reference stretched over their
    samples: (sh, qh, k) with k the new sample count, or None."""
    from .. import _track_kernels as TK
    from .refine import land

    dt, L = ctx.dt, ctx.L
    a = max(k - ctx.tuning.end_window, first + 1, 1)
    s_a = float(sh[a - 1])
    count = nodes.s.shape[0]
    t_a, _ = TK.ref_t_of_s(nodes.s, nodes.t, nodes.v, nodes.a, count, s_a, 0)
    rest = max(float(nodes.t[-1]) - t_a, dt)

    def x_ref(M: int):
        out = np.empty(M)
        hint = 0
        for j in range(M):
            out[j], hint = TK.ref_s_of_t(
                nodes.s, nodes.t, nodes.v, nodes.a, count, t_a + rest * (j + 1) / (M + 1), hint
            )
        return np.minimum(np.maximum.accumulate(np.maximum(out, s_a)), L)

    m0 = max(int(np.ceil(rest / dt)) - 1, 1)
    got = land(ctx.refine_problem(), sh[:k], qh[:k], a, m0, x_ref, ctx.tuning, np.zeros(2, dtype=np.int64))
    if got is None:
        return None
    x, qx = got
    sh = np.concatenate((sh[:a], x, [L]))
    qh = np.concatenate((qh[:a], qx, ctx.table.qend[None, :]))
    return sh, qh, a + x.shape[0] + 1


def _append_piece(ctx, nodes, piece) -> bool:
    ctx.stats["lp_iterations"] += piece.lp_iters
    if piece.restarts:
        ctx.stats["lp_restarts"] = piece.restarts
    return nodes.append(piece.knots, piece.coef, piece.s0, piece.s1)


def _final_chunk(sh, qh, k: int, L: float, first: int, qend):
    """The path's last chunk: buffer rows ``first``..the first sample at the end L (the
    repeats of L after it dropped), its last position exactly the path's end ``qend``."""
    last = k - 1
    while last > 0 and sh[last - 1] == L:
        last -= 1
    out_s = sh[first : last + 1].copy()
    out_q = qh[first : last + 1].copy()
    out_q[-1] = qend
    return out_s, out_q


def _vpop_stage(ctx, window):
    """VPOp's plan of the path as a stream of (s, q) blocks (its own stream: ``window``
    bounds its buffers, the samples do not depend on it)."""
    from ..vpop import VpopFailed, iter_prepared

    handed = False
    try:
        for c in iter_prepared(ctx.prepared(), ctx.joint_map, ctx.machine, ctx.settings, window, safe_fallback=False):
            if c.last and c.stats:
                ctx.stats["exact"] = bool(c.stats.get("exact", False))
            handed = True
            yield c.s, c.q
        return
    except VpopFailed:
        if handed:
            raise
    # VPOp got stuck (a Vectric file's A+Z moves): the profile if this path did not come
    # from it, else the safe S-curve, which cannot fail
    ctx.vpop_failed = ctx.stats["vpop_failed"] = True
    if ctx.planned_route == Route.VPOP and ctx.fallback is None:
        ctx.stats["route"] = ctx.planned_route = Route.PROFILE
        try:
            blocks = list(_sampled(ctx))  # whole: it may still give up
        except _Fallback:
            blocks = None
        if blocks is not None:
            yield from blocks
            return
    from ..safe import plan_path_safe

    plan = plan_path_safe(ctx.path, ctx.joint_map, ctx.machine, ctx.dt, ctx.settings)
    ctx.stats["safe"] = True
    yield plan.s, plan.q

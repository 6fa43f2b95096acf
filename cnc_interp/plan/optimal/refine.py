"""Refinement: shorten a feasible sampled plan window by window (the discrete problem, locally).

``_refined`` slides windows of ``tuning.refine_window`` samples along a stream of blocks
every ``tuning.refine_stride`` samples; ``Refiner.window`` asks
``_refine_kernels.solve_window`` for positions with one sample fewer between the same
three samples before and after, keeps them if every sample they touch passes
``verify``'s exact checks (``_refine_kernels.exact_ok``), and tries one fewer again (at
most half the window per visit). Each accepted window is a whole
period saved and the plan stays exact throughout. A window none of whose samples is
clearly below every limit (``tuning.refine_skip``) is skipped.

Targeted (fine periods, ``planner._targeted``): only windows at the path's ends and
around dips of the speed (``tuning.dip``), judged by blocks of ``tuning.refine_probe``
solves: a block that gained less than ``tuning.refine_rate`` periods per solve pauses the
windows for ``tuning.refine_pause`` strides.

The continuous profile of ``profile`` is the solution of a different problem: a sampled
plan may exploit that a backward difference is an average over a few periods (a
geometric feature shorter than a few samples, a jump of q_sss where two path segments
join, the start and stop from rest); these windows recover that, and VPOp's greedy
losses where a plan comes from it. A window's result depends on the plan up to three
samples past it, so the pass streams.
"""

from __future__ import annotations

import numpy as np

from .. import _refine_kernels as RK
from ..tuning import OptimalTuning


def refine_problem(table, path, joints, limits, dt: float) -> RK.RefineProblem:
    """The refinement's ``_refine_kernels.RefineProblem`` of one path: its joint table
    (``vpop.JointTable``) and the same as the exact sampler's ``vpop.step.Table`` (C
    axis-major: ``joints``), the step limits (``vpop.step.Limits``) and the period dt, s."""
    feeds = np.asarray(path.feed_mm_s, dtype=float)
    feeds = feeds[np.isfinite(feeds) & (feeds > 0)]
    # one feed per path here: windows use the lowest (segments never straddle a feed
    # change, so a path whose segments differ in feed is rare; it is only slower)
    fdt = (float(np.min(feeds)) if feeds.size else 1e300) * dt * (1.0 - 1e-10)
    return RK.RefineProblem(
        joints.S,
        joints.C,
        joints.QEND,
        joints,
        limits,
        np.ascontiguousarray(np.any(np.abs(table.C[:, 1:, :]) > 0, axis=(0, 1))),
        np.ascontiguousarray(np.stack(limits)),
        fdt,
        float(table.length),
    )


class Refiner:
    """The exact-check and window-solve machinery for one path (``refine_problem``)."""

    def __init__(self, problem: RK.RefineProblem, tuning: OptimalTuning):
        #: the path's ``_refine_kernels.RefineProblem``
        self.problem = problem
        #: the planner's tunables (``refine_skip``, ``refine_newton``)
        self.tuning = tuning
        #: Newton steps, row evaluations and window solves spent (statistics)
        self.counts = np.zeros(2, dtype=np.int64)
        self.solves = 0

    def loose(self, sh, qh, a: int, b: int) -> bool:
        """Is some sample of the window a..b-1 clearly below every limit? (A window whose
        samples all keep a limit within ``tuning.refine_skip`` of active cannot lose a period
        cheaply; it is skipped.) Needs the three samples before a."""
        p = self.problem
        return RK.loose(sh, qh, a, b, p.moving, p.lim, p.fdt, self.tuning.refine_skip)

    def window(self, sh, qh, a: int, b: int, max_cut: int):
        """Try to drop samples from the window a..b-1 of (sh, qh) (both ending at the
        end point, rest implied after), one at a time while each next one succeeds (a
        try that drops several at once costs more Newton steps than the tries it saves;
        ``_refine_kernels.shorten``). Returns the new (sh, qh, dropped); the buffers are
        spliced once, at the end."""
        dropped, solves, x, qx = RK.shorten(self.problem, sh, qh, a, b, max_cut, self.tuning.refine_newton, self.counts)
        self.solves += solves
        if not dropped:
            return sh, qh, 0
        sh = np.concatenate((sh[:a], x, sh[b:]))
        qh = np.concatenate((qh[:a], qx, qh[b:]))
        return sh, qh, dropped


def _refined(ctx, blocks, targeted: bool = False):
    """One pass of window refinement over a stream of (s, q) blocks: windows of
    ``tuning.refine_window`` samples every ``tuning.refine_stride`` samples; a window changes only
    samples from its start on, so everything before the next start is final.
    ``targeted``: only windows at the ends of the path and around dips of the speed
    (where a sampled plan gains most over the continuous profile), for fine periods
    where a pass over everything costs too much."""
    T = ctx.tuning
    ref = Refiner(ctx.refine_problem(), T)
    W = T.refine_window
    ahead = W + 4 + (W if targeted else 0)
    sh = np.zeros(0)
    qh = np.zeros((0, ctx.n))
    base = 0  # global index of sh[0]
    a = 1  # next window start, global index
    emitted = 0
    gained = 0
    blk = (0, 0)  # solves and periods gained when the current block began
    pause = 0  # strides left before the windows are tried again
    done = False
    it = iter(blocks)
    while True:
        while not done and base + sh.shape[0] < a + ahead:
            try:
                bs, bq = next(it)
            except StopIteration:
                done = True
                break
            sh = np.concatenate((sh, bs))
            qh = np.concatenate((qh, bq))
        la = a - base
        N = sh.shape[0]
        if la >= N - 1:
            break
        b = min(la + W, N - 1)
        # targeted: the windows are judged by blocks of tuning.refine_probe solves; a block
        # that gained less than tuning.refine_rate periods per solve (a window that loses k
        # periods takes k + 1 solves) pauses them for tuning.refine_pause strides
        if targeted:
            if pause > 0:
                pause -= 1
                if pause == 0:
                    blk = (ref.solves, gained)
            elif ref.solves - blk[0] >= T.refine_probe:
                if gained - blk[1] < T.refine_rate * (ref.solves - blk[0]):
                    pause = T.refine_pause
                blk = (ref.solves, gained)
        paying = pause == 0
        # targeted: only windows at the path's ends or around a dip of the speed
        if (
            paying
            and b - la >= 3
            and (not targeted or RK.dip_or_end(sh, la, b, W, done, T.dip))
            and ref.loose(sh, qh, la, b)
        ):
            sh, qh, d = ref.window(sh, qh, la, b, max(1, (b - la) // 2))  # half the window at most
            gained += d
            ctx.stats["refined_periods"] += d
        a += T.refine_stride
        upto = min(a, base + sh.shape[0])
        if upto > emitted:
            yield sh[emitted - base : upto - base].copy(), qh[emitted - base : upto - base].copy()
            emitted = upto
            cut = emitted - 3 - base  # keep three samples before the next window
            if cut > 0:
                sh, qh, base = sh[cut:], qh[cut:], base + cut
    if emitted < base + sh.shape[0]:
        yield sh[emitted - base :].copy(), qh[emitted - base :].copy()
    ctx.stats["refine_solves"] = ctx.stats.get("refine_solves", 0) + ref.solves
    ctx.stats["refine_newton"] = ctx.stats.get("refine_newton", 0) + int(ref.counts[0])
    ctx.stats["refine_evals"] = ctx.stats.get("refine_evals", 0) + int(ref.counts[1])


def path_refine_problem(path, joint_map, machine, dt: float) -> RK.RefineProblem:
    """``refine_problem`` of a path planned outside a ``_Path`` (VPOp's batch): its joint
    table and step limits made as ``_Path`` makes them."""
    from ..joint_table import JointTable
    from .context import exact_inputs

    table = JointTable(path, joint_map)
    return refine_problem(table, path, *exact_inputs(table, machine, dt), dt)


def refine_end(ref: Refiner, sh, qh, first: int):
    """The window of ``ref.tuning.end_window`` samples that ends at the path's end,
    shortened where the discrete problem allows. (sh, qh) are the path's last samples,
    ``first`` the global index of sh[0]; they hold at least the three samples before the
    window (or start at the path's start). Returns (sh, qh, periods dropped)."""
    N = sh.shape[0]
    b = N - 1
    la = max(1, first + N - 1 - ref.tuning.end_window) - first
    if b - la < 3 or not ref.loose(sh, qh, la, b):
        return sh, qh, 0
    return ref.window(sh, qh, la, b, max(1, (b - la) // 2))


def _end_refined(ctx, blocks):
    """Only the window at the path's end refined (``refine_end``), every other sample
    passed through as it comes: VPOp's plan at fine periods, whose braking into the end
    is where it loses most against the discrete optimum (a few periods a path, for a few
    window solves)."""
    keep = ctx.tuning.end_window + 4  # the window, the three samples before it and one
    sh = np.zeros(0)
    qh = np.zeros((0, ctx.n))
    first = 0  # global index of sh[0]
    for bs, bq in blocks:
        sh = np.concatenate((sh, bs))
        qh = np.concatenate((qh, bq))
        cut = sh.shape[0] - keep
        if cut > 0:
            yield sh[:cut].copy(), qh[:cut].copy()
            sh, qh, first = sh[cut:], qh[cut:], first + cut
    ref = Refiner(ctx.refine_problem(), ctx.tuning)
    sh, qh, dropped = refine_end(ref, sh, qh, first)
    ctx.stats["refined_periods"] += dropped
    ctx.stats["refine_solves"] = ctx.stats.get("refine_solves", 0) + ref.solves
    if sh.shape[0]:
        yield sh, qh


def land(problem: RK.RefineProblem, sh, qh, a: int, m0: int, x_ref, tuning: OptimalTuning, counts):
    """Samples from ``a`` on that bring the plan to rest at the path's end: the window
    solver between the three samples before ``a`` of (sh, qh) and the rest at the end,
    checked exactly (``_refine_kernels.solve_checked``), on as few samples as it finds:
    ``m0`` first, then one, two, four, ... more, at most ``tuning.end_window`` more.
    ``x_ref(M)``: M (>= 1) positions on to the end, the end excluded (a try's start).
    Returns (x (M,), qx (M, n)) or None."""
    idx = [max(a - 3 + i, 0) for i in range(3)]
    pre = np.ascontiguousarray(sh[idx])
    q_pre = np.ascontiguousarray(qh[idx])
    rest = np.full(3, problem.L)
    extra = 0
    while extra <= tuning.end_window:
        x0 = np.ascontiguousarray(x_ref(m0 + extra))
        ok, x, qx = RK.solve_checked(problem, pre, q_pre, rest, rest, x0, tuning.refine_newton, counts)
        if ok:
            return x, qx
        extra = 2 * extra if extra else 1
    return None

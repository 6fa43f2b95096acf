"""Shorten a feasible sampled plan window by window (the discrete problem, locally).

``Refiner.window`` takes one window of ``REFINE_WINDOW`` samples of a plan (the
optimal planner slides them along it every ``REFINE_STRIDE`` samples) and asks
``_refine_kernels.solve_window`` for positions with one sample fewer between the same
three samples before and after, keeps them if every sample they touch passes
``verify``'s exact checks (``_refine_kernels.exact_ok``), and tries one fewer again.
Each accepted window is a whole period saved and the plan stays exact throughout.

The continuous profile of ``feedprofile`` is the solution of a different problem: a
sampled plan may exploit that a backward difference is an average over a few
periods (a geometric feature shorter than a few samples, a jump of q_sss where two
path segments join, the start and stop from rest); these windows recover that, and
VPOp's greedy losses where a plan comes from it. A window's result depends on the
plan up to three samples past it, so the pass can stream.
"""

from __future__ import annotations

import numpy as np

from . import _refine_kernels as RK

#: samples per window, the stride between windows, Newton steps per solve
REFINE_WINDOW = 60
REFINE_STRIDE = 20
REFINE_NEWTON = 200
#: a window is shortened by at most this share of its samples per visit
REFINE_MAX_CUT = 0.5
#: a window none of whose samples has every limit ratio below this is skipped
REFINE_SKIP = 0.99


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

    def __init__(self, problem: RK.RefineProblem):
        #: the path's ``_refine_kernels.RefineProblem``
        self.problem = problem
        #: Newton steps, row evaluations and window solves spent (statistics)
        self.counts = np.zeros(2, dtype=np.int64)
        self.solves = 0

    def loose(self, sh, qh, a: int, b: int) -> bool:
        """Is some sample of the window a..b-1 clearly below every limit? (A window whose
        samples all keep a limit within REFINE_SKIP of active cannot lose a period
        cheaply; it is skipped.) Needs the three samples before a."""
        p = self.problem
        return RK.loose(sh, qh, a, b, p.moving, p.lim, p.fdt, REFINE_SKIP)

    def window(self, sh, qh, a: int, b: int, max_cut: int):
        """Try to drop samples from the window a..b-1 of (sh, qh) (both ending at the
        end point, rest implied after), one at a time while each next one succeeds (a
        try that drops several at once costs more Newton steps than the tries it saves;
        ``_refine_kernels.shorten``). Returns the new (sh, qh, dropped); the buffers are
        spliced once, at the end."""
        dropped, solves, x, qx = RK.shorten(self.problem, sh, qh, a, b, max_cut, REFINE_NEWTON, self.counts)
        self.solves += solves
        if not dropped:
            return sh, qh, 0
        sh = np.concatenate((sh[:a], x, sh[b:]))
        qh = np.concatenate((qh[:a], qx, qh[b:]))
        return sh, qh, dropped

"""Selection: the shortest of the plans a path planned whole may have.

A profile-routed path whose rough duration is at most ``tuning.compare_samples`` periods
(``OptimalOptions.compare_s``) is planned whole before any sample leaves, and
``_better_of`` keeps the shortest of:

* the profile's plan (refined);
* VPOp's own plan, made only where it may win: VPOp took over between
  ``tuning.compare_after`` and ``tuning.compare_before`` of the samples, the profile
  needed ``tuning.compare_dips`` dips or more, or VPOp's first ``tuning.probe_s`` (the
  probe) reach their arc length ``tuning.probe_ahead`` sooner than the profile's on a
  plan of at least ``tuning.probe_min_s``. With ``tuning.probe_early`` the probe is
  decided as soon as the profile's plan passes it, and when VPOp is ahead its plan is
  kept without planning the profile's rest.
"""

from __future__ import annotations

import numpy as np

from .context import _Fallback, _probe_progress
from .refine import _refined
from .route import Route
from .sampling import _vpop_stage


def _samples(blocks) -> int:
    return sum(b[0].shape[0] for b in blocks)


def _better_of(ctx, stage, passes, targeted):
    """The shorter of the profile's plan and VPOp's (both whole: bounded by
    ``tuning.compare_samples``); ``passes`` of refinement for the profile's plan, and for
    VPOp's at coarse periods. Where the profile gives up, VPOp plans the path (the caller's
    fallback)."""
    try:
        blocks, vpop_ahead = _profile_unless_vpop_ahead(ctx, stage)
        failed = None
    except _Fallback as why:
        blocks, failed, vpop_ahead = None, why, False
    if vpop_ahead:
        # VPOp's plan is kept without the profile's rest (tuning.probe_early)
        ctx.stats["kept"] = Route.VPOP
        yield from _vpop_plan(ctx, passes, targeted)
        return
    if blocks is None:
        assert failed is not None
        raise failed  # the profile did not plan the path: VPOp does (the caller's fallback)
    s = np.concatenate([b[0] for b in blocks])
    q = np.concatenate([b[1] for b in blocks])
    if ctx.fallback is None and not _vpop_may_win(ctx, s.shape[0]) and not _vpop_ahead(ctx, s):
        # the profile ran to the end (VPOp at most finished its last stop), or far enough
        # before VPOp took over: it is kept without running VPOp (over the corpus VPOp
        # won on such paths by 351 periods in all against the profile's 22k; the runs
        # cost as much as 4.6 s of planning). Also where the reference had to be lowered
        # by a few dips (tuning.compare_dips): on the sweep (axis_mm.ini) VPOp won there by
        # 51 periods in all (LHchips4) for ~7 % of stellabee1's CPU
        ctx.stats["kept"] = Route.PROFILE
        yield s, q
        return
    alt = list(_vpop_plan(ctx, passes, targeted))
    sv = np.concatenate([b[0] for b in alt])
    if sv.shape[0] < s.shape[0]:
        ctx.stats["kept"] = Route.VPOP
        yield sv, np.concatenate([b[1] for b in alt])
    else:
        ctx.stats["kept"] = Route.PROFILE
        yield s, q


def _vpop_plan(ctx, passes, targeted):
    """VPOp's whole plan of the path to compare with the profile's: (s, q) blocks, refined
    by ``passes`` where the refinement is not targeted."""
    alt = _vpop_stage(ctx, None)
    for _ in range(passes if not targeted else 0):
        alt = _refined(ctx, alt, targeted)
    return alt


def _profile_unless_vpop_ahead(ctx, stage):
    """The profile's (s, q) blocks from ``stage`` and False; or, with tuning.probe_early,
    those up to where VPOp's probe is decided ahead and True (``stage`` is closed, the
    rest not planned). The test is ``_vpop_ahead``'s, made on the first
    tuning.probe_min_s of the plan once they reach past the probe: the plan is then at least
    that long and its first samples are those the test reads at its end."""
    T = ctx.tuning
    blocks: list = []
    need = int(np.ceil(T.probe_min_s / ctx.dt))
    count = 0
    undecided = T.probe_early
    for block in stage:
        blocks.append(block)
        count += block[0].shape[0]
        if undecided and count >= need:
            progress = _probe_progress(ctx)
            if progress is None:
                undecided = False
            elif float(block[0][-1]) >= progress[1]:
                undecided = False
                if _vpop_ahead(ctx, np.concatenate([b[0] for b in blocks])):
                    stage.close()
                    return blocks, True
    return blocks, False


def _vpop_ahead(ctx, s) -> bool:
    """Does VPOp's plan reach the arc length of its first tuning.probe_s tuning.probe_ahead
    sooner than the profile's plan of samples at arc lengths s (N,)? (False for a plan
    shorter than tuning.probe_min_s, or where VPOp fails.)"""
    T = ctx.tuning
    if s.shape[0] * ctx.dt < T.probe_min_s:
        return False
    progress = _probe_progress(ctx)
    if progress is None:
        return False
    got, s_at = progress
    ahead = got < (1.0 - T.probe_ahead) * (int(np.searchsorted(s, s_at)) + 1)
    ctx.stats["probe"] = "vpop ahead" if ahead else "profile"
    return ahead


def _vpop_may_win(ctx, n_samples: int) -> bool:
    """Is VPOp's own plan worth making for comparison with the profile's plan of
    ``n_samples``: did VPOp take it over early (``_handed_over_early``), after
    tuning.compare_after and before tuning.compare_before of its samples, or did the profile
    need tuning.compare_dips dips?"""
    T = ctx.tuning
    if ctx.sampling.retries >= T.compare_dips:
        return True
    ho = ctx.sampling.handover
    return _handed_over_early(ctx, n_samples) and T.compare_after * n_samples <= ho < T.compare_before * n_samples


def _handed_over_early(ctx, n_samples: int) -> bool:
    """Did VPOp take over the profile's plan of ``n_samples`` before its last
    tuning.compare_tail_s (more than finishing the last stop)?"""
    ho = ctx.sampling.handover
    return 0 <= ho < n_samples - int(ctx.tuning.compare_tail_s / ctx.dt)

"""Selection: the shortest of the plans a path planned whole may have.

A profile-routed path whose rough duration is at most ``tuning.compare_samples`` periods
(``OptimalOptions.compare_s``) is planned whole before any sample leaves, and
``_better_of`` keeps the shortest of:

* the profile's plan (refined);
* VPOp's own plan (refined by the same passes where the refinement is not targeted),
  made for every such path by a thread of its own while the profile plans it
  (``VpopAlongside``): the profile's plan is kept only where it is not longer, so the
  optimal planner never plans such a path longer than VPOp does.

On a plan of at least ``tuning.probe_min_s`` VPOp's first ``tuning.probe_s`` (the probe)
are compared as soon as the profile's plan passes their arc length
(``tuning.probe_early``): where VPOp reaches it ``tuning.probe_ahead`` sooner, VPOp's plan
is kept without planning the profile's rest.
"""

from __future__ import annotations

import numpy as np

from ..prefetch import Prefetch
from .context import _NOT_PROBED, _Fallback
from .refine import _refined
from .route import Route
from .sampling import _vpop_stage

#: VPOp's blocks a path's comparison thread may hold ahead of the selection (it hands
#: out one block per checkpoint: a path planned whole has a few)
_ALONGSIDE_BLOCKS = 64


class VpopAlongside:
    """VPOp's whole plan of a path planned whole, made by a thread of its own while the
    profile plans the path (the samples do not depend on the thread): the selection,
    the probe and the fallback read it. ``close()`` stops the thread."""

    def __init__(self, ctx):
        ctx.prepared()  # built here, once, not by two threads
        self._feed = Prefetch(_vpop_stage(ctx, None), ahead=_ALONGSIDE_BLOCKS, name="cnc-interp-vpop")
        self._it = iter(self._feed)
        self.blocks: list = []
        self.samples = 0
        self._done = False

    def upto(self, n: int) -> list:
        """VPOp's (s, q) blocks until they hold at least ``n`` samples (or all)."""
        while not self._done and self.samples < n:
            block = next(self._it, None)
            if block is None:
                self._done = True
                break
            self.blocks.append(block)
            self.samples += block[0].shape[0]
        return self.blocks

    def whole(self) -> list:
        """VPOp's whole plan: (s, q) blocks."""
        return self.upto(np.iinfo(np.int64).max)

    def close(self) -> None:
        self._feed.close()


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
    # VPOp's own plan of every path planned whole: a profile plan longer than it is never
    # kept (compiled, VPOp's plan costs a fraction of the profile's)
    alt = _vpop_plan(ctx, passes, targeted)
    if _samples(alt) < s.shape[0]:
        ctx.stats["kept"] = Route.VPOP
        yield np.concatenate([b[0] for b in alt]), np.concatenate([b[1] for b in alt])
    else:
        ctx.stats["kept"] = Route.PROFILE
        yield s, q


def _vpop_plan(ctx, passes, targeted) -> list:
    """VPOp's whole plan of the path (``ctx.alongside``): (s, q) blocks, refined by
    ``passes`` where the refinement is not targeted."""
    alt = ctx.alongside.whole()
    for _ in range(passes if not targeted else 0):
        alt = _refined(ctx, alt, targeted)
    return list(alt)


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


def _probe_progress(ctx):
    """VPOp's first tuning.probe_s of the path (``ctx.alongside``): (how many samples, the
    arc length of the last); None where VPOp fails. Read once per path (``ctx.probe``)."""
    if ctx.probe is not _NOT_PROBED:
        return ctx.probe
    n_probe = int(ctx.tuning.probe_s / ctx.dt)
    blocks = ctx.alongside.upto(n_probe)
    if not blocks or ctx.vpop_failed:
        ctx.probe = None
    else:
        s = np.concatenate([b[0] for b in blocks])
        got = min(n_probe, s.shape[0])
        ctx.probe = (got, float(s[got - 1]))
    return ctx.probe

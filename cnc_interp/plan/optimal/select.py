"""Selection: the shorter of the plans a path planned whole may have.

A profile-routed path whose rough duration is at most ``tuning.compare_samples`` periods
(``OptimalOptions.compare_s``) is planned whole before any sample leaves, and
``_better_of`` keeps the shorter of:

* the profile's plan (refined);
* VPOp's own plan (refined by the same passes where the refinement is not targeted),
  made for every such path by a thread of its own while the profile plans it
  (``VpopAlongside``): the profile's plan is kept only where it is not longer, so the
  optimal planner never plans such a path longer than VPOp does.
"""

from __future__ import annotations

import numpy as np

from ..prefetch import Prefetch
from .refine import _refined
from .route import Route
from .sampling import _vpop_stage

#: VPOp's blocks a path's comparison thread may hold ahead of the selection
_ALONGSIDE_BLOCKS = 64


class VpopAlongside:
    """VPOp's whole plan of a path planned whole, made by a thread of its own while the
    profile plans the path (the samples do not depend on the thread): the selection
    and the fallback read it. ``close()`` stops the thread."""

    def __init__(self, ctx):
        ctx.prepared()  # built here, once, not by two threads
        self._feed = Prefetch(_vpop_stage(ctx, None), ahead=_ALONGSIDE_BLOCKS, name="cnc-interp-vpop")
        self._blocks: list | None = None

    def whole(self) -> list:
        """VPOp's whole plan: (s, q) blocks (drained from the thread once)."""
        if self._blocks is None:
            self._blocks = list(self._feed)
        return self._blocks

    def close(self) -> None:
        self._feed.close()


def _samples(blocks) -> int:
    return sum(b[0].shape[0] for b in blocks)


def _better_of(ctx, stage, passes, targeted):
    """The shorter of the profile's plan and VPOp's (both whole: bounded by
    ``tuning.compare_samples``); ``passes`` of refinement for the profile's plan, and for
    VPOp's at coarse periods. Where the profile gives up (``_Fallback``), VPOp plans the
    path (the caller's fallback)."""
    blocks = list(stage)
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

"""``--planner constant``: one feed per path, jerk-bounded start and stop.

The feed is the largest that keeps every segment within its cap (``limits.feed_caps``:
Eq. 6 at every curvature peak, per-axis limits, programmed feed F) and that leaves room
for the start and stop transitions (2 D(0, V) <= path length); the tangential limits
are the smallest over the path at that feed.

One exception to "one feed per path": a junction whose own cap (a tangent or curvature
jump, ``limits.junction_caps``) is below the feed of the section before it splits the
path there, and each corner-free section gets its own constant feed, slowing to the
junction cap at the corner. Without it, one small G1 kink would make the whole path
crawl at the kink's feed. Paths from the G2 planar fit have no such junctions.

Likewise a curvature peak where the feed is low anyway, within the start or stop ramp
of a section (a NURBS that starts with a repeated control point has unbounded
curvature at its first point), does not set the constant feed: segments closer to a
section end than the ramp distance D(0, V) keep their own caps (``constant_pieces``).

This is the variable planner's machinery with one profile piece for the constant part
of each section: the sampled plan is checked against every axis limit and replanned
with lower feeds where a sample would exceed one.
"""

from __future__ import annotations

import numpy as np

from ..base import PathPlan
from .limits import feed_caps
from .profile import transition_distance
from .variable import plan_grouped

#: fixed-point rounds for the feed / ramp-zone pair (converges in 2-3)
_ZONE_ROUNDS = 10


def constant_feed(geom, machine, feed_mm_s, settings=None) -> float:
    """The constant feed (mm/s) of a corner-free path before any replan: min of the segment caps."""
    return float(feed_caps(geom, machine, feed_mm_s, settings).min())


def constant_pieces(vcap, wcap, geom, path, machine):
    """Pieces of the constant plan: (first segment (m,), cap (m,)).

    The path is cut into sections at junctions that cap the feed below the section's
    own (``group_segments`` with band 1). In each section, the segments that lie within
    the ramp distance D(0, V) of a section end (with the largest tangential limits
    possible on the path, so the zone is never too wide) and whose cap is below V are
    single pieces with their own caps: the feed is below V there anyway. The other
    segments form pieces at the constant feed V = the smallest of their caps, iterated
    to a fixed point with the zone width.
    """
    from .lookahead import group_segments

    n = vcap.size
    with np.errstate(divide="ignore"):
        a0 = float(np.min(np.where(geom.g1 > 0, machine.amax / geom.g1, np.inf)))
        j0 = float(np.min(np.where(geom.g1 > 0, machine.jmax / geom.g1, np.inf)))
    a0 = a0 if np.isfinite(a0) else float(machine.amax.min())
    j0 = j0 if np.isfinite(j0) else float(machine.jmax.min())
    sb = path.s_breaks
    bounds = np.r_[group_segments(vcap, wcap, 1.0), n]
    firsts, caps = [], []
    for a, b in zip(bounds[:-1], bounds[1:]):
        lo, hi = sb[a:b], sb[a + 1 : b + 1]
        cap = vcap[a:b]
        v = cap.max()  # iterate down from above: the largest consistent (V, zone) pair
        zone = np.zeros(b - a, dtype=bool)
        for _ in range(_ZONE_ROUNDS):
            d = float(transition_distance(0.0, v, a0, j0))
            zone = (hi <= sb[a] + d) | (lo >= sb[b] - d)
            v_new = cap[~zone].min() if np.any(~zone) else cap.max()
            if v_new == v:
                break
            v = v_new
        zone &= cap < v  # only the segments that would otherwise lower V stand apart
        k = 0
        while k < b - a:
            if zone[k]:
                firsts.append(a + k)
                caps.append(min(cap[k], v))
                k += 1
            else:
                firsts.append(a + k)
                caps.append(v)
                while k < b - a and not zone[k]:
                    k += 1
    return np.asarray(firsts, dtype=np.int64), np.asarray(caps, dtype=float)


def plan_path_constant(path, joint_map, machine, dt_s: float, settings=None) -> PathPlan:
    """Constant-feed plan of one path: samples every ``dt_s`` from rest to rest.

    Arguments as ``plan_path_variable``. ``profiles`` is a ``SegmentProfiles`` with one
    piece per corner-free section (a single piece, start feed 0, cruise V, end feed 0,
    on a path without corners).
    """

    def pieces(vcap, wcap, geom, path):
        return constant_pieces(vcap, wcap, geom, path, machine)

    return plan_grouped(path, joint_map, machine, dt_s, settings, pieces, "constant")

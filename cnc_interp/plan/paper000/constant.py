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

This is the variable planner's machinery with every segment of a section in one
profile piece (``merge_band`` = 1): the sampled plan is checked against every axis
limit and replanned with lower feeds where a sample would exceed one.
"""

from __future__ import annotations

from ..base import PathPlan
from .limits import feed_caps
from .variable import plan_grouped


def constant_feed(geom, machine, feed_mm_s, settings=None) -> float:
    """The constant feed (mm/s) of a corner-free path before any replan: min of the segment caps."""
    return float(feed_caps(geom, machine, feed_mm_s, settings).min())


def plan_path_constant(path, joint_map, machine, dt_s: float, settings=None) -> PathPlan:
    """Constant-feed plan of one path: samples every ``dt_s`` from rest to rest.

    Arguments as ``plan_path_variable``. ``profiles`` is a ``SegmentProfiles`` with one
    piece per corner-free section (a single piece, start feed 0, cruise V, end feed 0,
    on a path without corners).
    """
    return plan_grouped(path, joint_map, machine, dt_s, settings, 1.0, "constant")

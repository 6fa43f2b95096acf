"""``--planner variable``: per-segment feeds from the curvature peaks, with look-ahead.

Each path segment k gets a cruise cap V_k (``limits.feed_caps``: Eq. 6 on its peak
curvature, the per-axis limits and the programmed feed) and tangential limits A_k, J_k.
Consecutive segments whose caps lie within ``merge_band`` of each other (and whose
junction does not cap the feed lower) form one profile piece, so that a transition may
span several short segments (``merge_band = 0`` gives one piece per segment, the
paper's literal form). ``lookahead`` picks junction and cruise feeds so that every
transition fits in its piece and every slow-down starts early enough. The resulting
``SegmentProfiles`` are sampled every dt, checked against every axis limit (finite
differences with rest padding), and any segment whose samples exceed a limit gets a
lower cap and gentler transitions before replanning.
"""

from __future__ import annotations

import numpy as np

from ...constants import VERIFY_RATIO_SLACK
from ...errors import PlanError
from ..base import PathPlan
from .common import joint_positions, sample_profile, sample_ratios, worst_ratio
from .curvature import segment_geometry
from .limits import feed_caps, junction_caps, knobs, option, shares
from .profile import build_profiles, stretch_to_period


#: verify-and-replan rounds before a plan is declared failed
P000_MAX_REPLANS = 40

#: factor applied to a violating segment's feed cap (and its square to a_t, j_t) per round
P000_REPLAN_FEED_FACTOR = 0.9

#: a segment/path shorter than this is treated as zero length (mm)
P000_MIN_LENGTH_MM = 1e-12

#: variable planner: consecutive segments whose feed caps lie within this relative band
#: share one profile piece (0 = one piece per segment, the paper's literal form)
P000_MERGE_BAND = 0.1

#: a paper-000 plan longer than this many samples is refused (a degenerate path, e.g.
#: a cusp with unbounded curvature, would otherwise crawl for days and exhaust memory)
P000_MAX_SAMPLES = 20_000_000


def _band(settings) -> float:
    return option(knobs(settings).merge_band, P000_MERGE_BAND)


def rest_plan(path, joint_map, planner: str) -> PathPlan:
    """The plan of a path with (numerically) zero length: one sample at its start."""
    s = np.zeros(1)
    return PathPlan(
        s=s,
        q=joint_positions(path, joint_map, s),
        status="ok",
        profiles=None,
        stats={"planner": planner, "replans": 0, "n_seg": int(path.n_seg)},
    )


def check_axes(q_probe: np.ndarray, machine) -> None:
    if q_probe.shape[-1] != machine.n_axes:
        raise PlanError(f"path has {q_probe.shape[-1]} joints but machine '{machine.name}' has {machine.n_axes} axes")


def plan_path_variable(path, joint_map, machine, dt_s: float, settings=None) -> PathPlan:
    """Variable-feed plan of one path: samples every ``dt_s`` from rest to rest.

    Args:
        path: ``fit.Path`` (program space).
        joint_map: kinematics, (K, n) program positions -> (K, n) joint positions, or None.
        machine: ``Machine`` (per-joint vmax, amax, jmax).
        dt_s: sample period, s.
        settings: ``PlanSettings`` (its ``paper000`` knobs: ``curv_accel_share``,
            ``curv_jerk_share``, ``cross_jerk_share``, see ``limits``, and ``merge_band``)
            or ``None`` for the defaults.
    Returns:
        ``PathPlan`` with ``profiles`` a ``SegmentProfiles`` (pieces of whole segments).
    """
    band = _band(settings)

    def pieces(vcap, wcap, geom, path):
        from .lookahead import group_segments

        first = group_segments(vcap, wcap, band)
        return first, np.minimum.reduceat(vcap, first)  # a piece's cap: its slowest segment's

    return plan_grouped(path, joint_map, machine, dt_s, settings, pieces, "variable")


def plan_grouped(path, joint_map, machine, dt_s: float, settings, pieces, planner: str) -> PathPlan:
    """Plan with segments grouped into profile pieces.

    ``pieces(vcap, wcap, geom, path) -> (first (m,), cap (m,))`` gives the first segment
    and the cruise cap of every piece from the segment caps (n_seg,) and junction caps
    (n_seg+1,).
    """
    if not (np.isfinite(path.length) and np.all(np.isfinite(path.coef))):
        raise PlanError(f"path ending at line {int(path.line[-1])} is not finite (fit failed?)")
    if path.length <= P000_MIN_LENGTH_MM:
        return rest_plan(path, joint_map, planner)
    geom = segment_geometry(path, joint_map)
    check_axes(geom.g1, machine)
    from .lookahead import lookahead

    n = path.n_seg
    vcap0 = feed_caps(geom, machine, path.feed_mm_s, settings)
    wcap = junction_caps(geom, machine, dt_s)
    sx = shares(settings)[2]
    fv = np.ones(n)
    ft = np.ones(n)
    limit = 1.0 + VERIFY_RATIO_SLACK
    for it in range(P000_MAX_REPLANS + 1):
        vcap = vcap0 * fv
        first, gcap = pieces(vcap, wcap, geom, path)
        last = np.r_[first[1:] - 1, n - 1]
        glen = np.add.reduceat(geom.length, first)
        gw = np.r_[wcap[first], 0.0]
        w, c, a_t, j_t = lookahead(
            np.r_[first, n], glen, gcap, geom.g1, geom.g2, geom.g3, machine.amax, machine.jmax, sx, ft, gw
        )
        prof = build_profiles(planner, first, last, path.s_breaks[first], glen, w[:-1], c, w[1:], a_t, j_t)
        prof = stretch_to_period(prof, dt_s)
        if prof.duration_s / dt_s > P000_MAX_SAMPLES:
            k = int(np.argmin(vcap))
            raise PlanError(
                f"{planner} feed plan would take {prof.duration_s:.3g} s: the feed must drop to "
                f"{vcap[k]:.3g} mm/s on the segment ending at line {int(path.line[k])} "
                f"(curvature {geom.kappa[k]:.3g} 1/mm over {geom.length[k]:.3g} mm); "
                f"the path is degenerate there"
            )
        s, q = sample_profile(path, joint_map, prof, dt_s)
        r = sample_ratios(q, dt_s, machine)
        if r.max(initial=0.0) <= limit:
            break
        bad = np.unique(path.segment_of_s(s[r > limit]))
        bad = np.unique(np.clip(np.concatenate([bad - 1, bad, bad + 1]), 0, n - 1))
        fv[bad] *= P000_REPLAN_FEED_FACTOR
        ft[bad] *= P000_REPLAN_FEED_FACTOR**2
    else:
        raise PlanError(
            f"{planner} feed plan still exceeds a limit after {P000_MAX_REPLANS} replans (worst ratio {r.max():.6g})"
        )
    worst = worst_ratio(q, dt_s, machine)
    if worst > limit:
        raise PlanError(f"{planner} feed plan fails verify (worst ratio {worst:.6g})")
    stats = {
        "planner": planner,
        "replans": it,
        "n_seg": int(n),
        "n_pieces": int(prof.n_pieces),
        "duration_s": float((s.size - 1) * dt_s),
        "worst_ratio": worst,
        "max_feed_mm_s": float(prof.v_cruise.max(initial=0.0)),
        "min_cruise_mm_s": float(prof.v_cruise.min()),
    }
    return PathPlan(s=s, q=q, status="ok", profiles=prof, stats=stats)

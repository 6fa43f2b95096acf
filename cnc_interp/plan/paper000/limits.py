"""Tangential limits of the feed derived from the machine's per-axis limits.

Along the path, joint i moves as q_i(s(t)), so with feed v, tangential acceleration
a_t and tangential jerk j_t (chain rule, q' = dq/ds):

    velocity      q_i' v
    acceleration  q_i'' v^2 + q_i' a_t
    jerk          q_i''' v^3 + 3 q_i'' v a_t + q_i' j_t

With g1, g2, g3 the maxima of |q_i'|, |q_i''|, |q_i'''| over a segment (``curvature``),
the triangle inequality gives sufficient conditions, applied per segment and joint:

- cruise feed cap V:  g1 V <= vmax,  g2 V^2 <= sa amax,  g3 V^3 <= sj jmax,
  and paper 000 Eq. 6, V <= sqrt(sa A_m / kappa) with A_m the smallest amax of the
  moving linear joints (sa = ``curv_accel_share``, sj = ``curv_jerk_share``);
  the programmed feed F caps V too;
- tangential acceleration at feeds <= V:
  A_t = min_i min((amax - g2 V^2) / g1,  sx (jmax - g3 V^3) / (3 g2 V));
- tangential jerk: J_t = min_i max(jmax - g3 V^3 - 3 g2 V A0, (1 - sx)(jmax - g3 V^3)) / g1
  with A0 = min_i amax / g1 >= A_t: the cross term is at most both 3 g2 V A0 and, by
  the choice of A_t, sx (jmax - g3 V^3). On a straight segment J_t = min_i jmax / g1.

A_t and J_t only decrease as V grows, so the look-ahead may evaluate them at the
feed a transition actually reaches (its larger end) instead of the segment's cap.

The shares keep A_t, J_t > 0. This is conservative (maxima taken over the whole
segment). Bounds on the continuous derivatives carry over to the sampled setpoints:
a k-th backward difference divided by dt^k is an average of the k-th derivative over
its stencil with a non-negative (B-spline) weight, so it cannot exceed the derivative's
bound. The sampled output is still checked, and replanned where the sampled maxima
g1..g3 missed a peak.

At a junction where dq/ds (or d2q/ds2) jumps (a path that is only G0/G1 there), the
sampled setpoints see a velocity (acceleration) step; its finite differences stay
within limits if  w |dq'| <= amax dt / 2,  w |dq'| <= jmax dt^2 / 2  and
w^2 |dq''| <= jmax dt / 2, which caps the junction feed w.
"""

from __future__ import annotations

import numpy as np

from ..settings import Paper000Options


#: share of each axis's amax the centripetal term q''·v² may use at cruise (Eq. 6's A_m);
#: the rest is left to the tangential acceleration of the feed transitions
P000_CURV_ACCEL_SHARE = 0.8

#: share of each axis's jmax the path-geometry jerk term q'''·v³ may use at cruise
P000_CURV_JERK_SHARE = 0.5

#: share of the jerk left after q'''·v³ that the cross term 3·q''·v·a_t may use
P000_CROSS_JERK_SHARE = 0.5


def knobs(settings) -> Paper000Options:
    """The paper-000 planners' knobs (``PlanSettings.paper000``; ``None``: the defaults)."""
    return Paper000Options() if settings is None else settings.paper000


def option(value: float | None, default: float) -> float:
    """A knob's value, or ``default`` where it is left at ``None``."""
    return default if value is None else float(value)


def shares(settings) -> tuple[float, float, float]:
    """(curv_accel_share, curv_jerk_share, cross_jerk_share) from settings or the defaults."""
    k = knobs(settings)
    return (
        option(k.curv_accel_share, P000_CURV_ACCEL_SHARE),
        option(k.curv_jerk_share, P000_CURV_JERK_SHARE),
        option(k.cross_jerk_share, P000_CROSS_JERK_SHARE),
    )


def _safe_div(num, den):
    with np.errstate(over="ignore"):  # a tiny divisor means no limit: inf is right
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.inf)


def feed_caps(geom, machine, feed_mm_s: np.ndarray, settings=None) -> np.ndarray:
    """Cruise feed cap V (n_seg,) of every segment, mm/s (see module docstring)."""
    sa, sj, _ = shares(settings)
    vmax, amax, jmax = machine.vmax[None, :], machine.amax[None, :], machine.jmax[None, :]
    cap_v = _safe_div(vmax, geom.g1).min(axis=1)
    cap_a = np.sqrt(_safe_div(sa * amax, geom.g2)).min(axis=1)
    cap_j = np.cbrt(_safe_div(sj * jmax, geom.g3)).min(axis=1)
    # paper 000 Eq. 6 with A_m the smallest acceleration limit of the moving linear joints
    a_m = np.where(geom.moving_linear, machine.amax[None, :], np.inf).min(axis=1)
    cap_eq6 = np.where(np.isfinite(a_m), np.sqrt(_safe_div(sa * a_m, geom.kappa)), np.inf)
    cap = np.minimum.reduce([cap_v, cap_a, cap_j, cap_eq6, np.asarray(feed_mm_s, dtype=float)])
    # a segment that moves no joint (degenerate) gets the slowest axis speed
    return np.where(np.isfinite(cap), cap, float(machine.vmax.min()))


def tangential_limits(geom, machine, v: np.ndarray, settings=None) -> tuple[np.ndarray, np.ndarray]:
    """Tangential acceleration and jerk limits (n_seg,) valid at every feed <= v (n_seg,)."""
    _, _, sx = shares(settings)
    v = np.asarray(v, dtype=float)[:, None]
    amax, jmax = machine.amax[None, :], machine.jmax[None, :]
    a_room = np.maximum(amax - geom.g2 * v**2, 0.0)
    j_room = np.maximum(jmax - geom.g3 * v**3, 0.0)
    a_t = np.minimum(_safe_div(a_room, geom.g1), _safe_div(sx * j_room, 3.0 * geom.g2 * v)).min(axis=1)
    a0 = _safe_div(amax, geom.g1).min(axis=1)  # a_t at v = 0: an upper bound of a_t
    a_t = np.where(np.isfinite(a_t), a_t, float(machine.amax.min()))
    a0 = np.where(np.isfinite(a0), a0, a_t)
    # the cross term 3 g2 v a_t is at most min(3 g2 v a0, sx j_room) by the choice of a_t
    left = np.maximum(j_room - 3.0 * geom.g2 * v * a0[:, None], (1.0 - sx) * j_room)
    j_t = _safe_div(left, geom.g1).min(axis=1)
    j_t = np.where(np.isfinite(j_t), j_t, float(machine.jmax.min()))
    tiny = 1e-300
    return np.maximum(a_t, tiny), np.maximum(j_t, tiny)


def junction_caps(geom, machine, dt_s: float) -> np.ndarray:
    """Feed cap (n_seg+1,) at each junction from the jumps of dq/ds and d2q/ds2; 0 at both ends."""
    amax, jmax = machine.amax[None, :], machine.jmax[None, :]
    c1 = _safe_div(0.5 * np.minimum(amax * dt_s, jmax * dt_s**2), geom.jump1).min(axis=1)
    c2 = np.sqrt(_safe_div(0.5 * jmax * dt_s, geom.jump2)).min(axis=1)
    cap = np.minimum(c1, c2)
    cap[0] = cap[-1] = 0.0
    return cap

"""The planner that cannot fail: jerk-limited S-curves under local bounds of the path.

VPOp and the optimal planner fall back to ``plan_path_safe`` when they cannot plan a
path (four A+Z moves of a Vectric file made VPOp report "made no
progress"). It is slow but always valid. The path is cut into stretches of table
pieces whose bounds differ by at most ``SAFE_SPREAD`` (a short stretch around a
spike of curvature, long ones elsewhere); each stretch is run rest to rest:

* per axis, bounds g1 >= |q_s|, g2 >= |q_ss|, g3 >= |q_sss| over the stretch
  (sampled densely on the joint table, with a margin);
* path limits v, a, j such that every axis holds its limits for any path motion with
  |ṡ| <= v, |s̈| <= a, |s⃛| <= j:  g1 v <= V,  g2 v² + g1 a <= A,
  g3 v³ + 3 g2 v a + g1 j <= J  (Beudaert et al. 2012, Eqs. 1-3, term by term);
* the time-optimal rest-to-rest S-curve in s under (v, a, j) and the feed, stretched
  to a whole number of periods, sampled every dt. A continuous motion whose third
  derivative stays within J has every third backward difference of its samples
  within J dt³ (a difference is a positive average of the derivative), so the samples
  hold the limits; the limits are shrunk by ``SAFE_SHARE`` for rounding, and if the
  exact check still failed they would be halved again (it does not, in the tests).

Stretches meet at rest: the join sample is held for three periods, as between paths.
With ``s_start`` it plans only the rest of a path from rest there (``vpop.planner.rescue``,
after a stall once samples are out).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import PlanError
from .base import PathPlan

#: share of each limit the S-curve uses (the rest absorbs the bounds' sampling and rounding)
SAFE_SHARE = 0.9
#: margin on the sampled derivative bounds (a peak between samples)
SAFE_BOUND_MARGIN = 1.25
#: sample points per table piece for the bounds
SAFE_SAMPLES = 8
#: attempts, each halving the limits, before giving up (a bug)
SAFE_TRIES = 6
#: a stretch grows while its speed limit stays above 1/SAFE_SPREAD of its first piece's
SAFE_SPREAD = 2.0
#: samples at rest between stretches (the jerk stencil spans four samples)
SAFE_REST = 3


def _bounds(table):
    """Per table piece and axis (m, n): max |q_s|, |q_ss|, |q_sss| (sampled, margin)."""
    S, C = table.S, table.C
    u = np.linspace(0.0, 1.0, SAFE_SAMPLES)
    h = np.diff(S)[:, None]
    t = (h * u[None, :])[..., None]  # (m, k, 1)
    c = C[:, None, :, :]  # (m, 1, 6, n)
    q1 = c[:, :, 1] + t * (2 * c[:, :, 2] + t * (3 * c[:, :, 3] + t * (4 * c[:, :, 4] + t * 5 * c[:, :, 5])))
    q2 = 2 * c[:, :, 2] + t * (6 * c[:, :, 3] + t * (12 * c[:, :, 4] + t * 20 * c[:, :, 5]))
    q3 = 6 * c[:, :, 3] + t * (24 * c[:, :, 4] + t * 60 * c[:, :, 5])
    return [SAFE_BOUND_MARGIN * np.max(np.abs(x), axis=1) for x in (q1, q2, q3)]


def _path_limits(g1, g2, g3, V, A, J):
    """v, a, j of the module docstring (each term takes a share of its axis's limit)."""
    v = a = j = math.inf
    for i in range(g1.shape[0]):
        if g1[i] > 0:
            v = min(v, V[i] / g1[i])
        if g2[i] > 0:
            v = min(v, math.sqrt(0.5 * A[i] / g2[i]))
        if g3[i] > 0:
            v = min(v, (J[i] / (3.0 * g3[i])) ** (1.0 / 3.0))
    for i in range(g1.shape[0]):
        if g1[i] > 0:
            a = min(a, 0.5 * A[i] / g1[i])
            j = min(j, J[i] / (3.0 * g1[i]))
        if g2[i] > 0 and v > 0:
            a = min(a, J[i] / (9.0 * g2[i] * v))
    return v, a, j


def scurve(L: float, v: float, a: float, j: float):
    """Phases (duration, jerk) of the time-optimal rest-to-rest motion over L under
    |ṡ| <= v, |s̈| <= a, |s⃛| <= j (seven phases, some of zero length)."""

    def accel(vv):
        ap = min(a, math.sqrt(vv * j))
        tj = ap / j
        tc = max(vv / ap - tj, 0.0)
        return ap, tj, tc, vv * (2 * tj + tc) / 2.0  # distance to reach vv from rest

    ap, tj, tc, d = accel(v)
    if 2.0 * d > L:  # no cruise: the largest top speed whose ramps fit
        lo, hi = 0.0, v
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if 2.0 * accel(mid)[3] <= L:
                lo = mid
            else:
                hi = mid
        v = lo
        ap, tj, tc, d = accel(v)
    tcr = max((L - 2.0 * d) / v, 0.0) if v > 0 else 0.0
    return [(tj, j), (tc, 0.0), (tj, -j), (tcr, 0.0), (tj, -j), (tc, 0.0), (tj, j)]


def scurve_positions(phases, t):
    """s at the sorted times t (K,) of the jerk phases (state carried phase by phase)."""
    out = np.empty(t.shape[0])
    s = vv = aa = 0.0
    t0 = 0.0
    i = 0
    for dur, jj in phases:
        t1 = t0 + dur
        while i < t.shape[0] and t[i] <= t1:
            tau = t[i] - t0
            out[i] = s + tau * (vv + tau * (aa / 2.0 + tau * jj / 6.0))
            i += 1
        s += dur * (vv + dur * (aa / 2.0 + dur * jj / 6.0))
        vv += dur * (aa + dur * jj / 2.0)
        aa += dur * jj
        t0 = t1
    out[i:] = s
    return out


def _stretches(g1, g2, g3, V, A, J):
    """Table pieces grouped into stretches [p0, p1) (see SAFE_SPREAD)."""
    m = g1.shape[0]
    out = []
    p0 = 0
    while p0 < m:
        v0 = _path_limits(g1[p0], g2[p0], g3[p0], V, A, J)[0]
        G1, G2, G3 = g1[p0].copy(), g2[p0].copy(), g3[p0].copy()
        p1 = p0 + 1
        while p1 < m:
            n1, n2, n3 = np.maximum(G1, g1[p1]), np.maximum(G2, g2[p1]), np.maximum(G3, g3[p1])
            v = _path_limits(n1, n2, n3, V, A, J)[0]
            v1 = _path_limits(g1[p1], g2[p1], g3[p1], V, A, J)[0]
            if v * SAFE_SPREAD < max(v0, v1):
                break
            G1, G2, G3 = n1, n2, n3
            p1 += 1
        out.append((p0, p1, G1, G2, G3))
        p0 = p1
    return out


def plan_path_safe(
    path, joint_map, machine, dt_s: float, settings=None, *, table=None, s_start: float = 0.0
) -> PathPlan:
    """Plan one path from rest to rest, slowly but always (see module docstring).

    ``s_start`` > 0 plans only the rest of the path, from rest at arc length ``s_start``
    (VPOp's rescue after a stall mid-path: ``vpop.planner``); the samples then start at
    s_start. ``table``: the joint table to follow (a ``JointTable`` or anything with its
    ``S``, ``C``, ``length`` and ``qend``), so that the samples meet another planner's on
    the same table exactly; by default the path's own ``JointTable``."""
    from .step_limits import position_scale, step_limits
    from .verify import verify_arrays
    from .joint_table import JointTable, _eval_table, _positions

    if path.rapid:
        joint_map = None
    dt = float(dt_s)
    if table is None:
        table = JointTable(path, joint_map)
    L = float(table.length)
    s_start = float(s_start)
    if not L > s_start:
        if s_start > 0.0:
            q0 = np.asarray(table.qend, dtype=float).reshape(1, -1).copy()
            return PathPlan(s=np.full(1, L), q=q0, stats={"samples": 1, "planner": "safe"})
        q0 = _positions(path, path.breaks[:1], joint_map)
        return PathPlan(s=np.zeros(1), q=q0, stats={"samples": 1, "planner": "safe"})
    vl, al, jl = step_limits(machine, dt, position_scale(table.C))  # exact step limits (checked below)
    S = table.S
    m = int(S.shape[0]) - 1
    # the first table piece with anything left after s_start
    first = min(max(int(np.searchsorted(S, s_start, side="right")) - 1, 0), m - 1)
    g1, g2, g3 = (g[first:] for g in _bounds(table))
    feeds = path.feed_mm_s[np.isfinite(path.feed_mm_s) & (path.feed_mm_s > 0)]
    feed = float(np.min(feeds)) if feeds.size else math.inf
    share = SAFE_SHARE
    for _ in range(SAFE_TRIES):
        V, A, J = machine.vmax * share, machine.amax * share, machine.jmax * share
        parts_s = [np.full(1, s_start)]
        for p0, p1, G1, G2, G3 in _stretches(g1, g2, g3, V, A, J):
            v, a, j = _path_limits(G1, G2, G3, V, A, J)
            v = min(v, feed * share)
            if not (v > 0 and a > 0 and j > 0 and math.isfinite(a) and math.isfinite(j)):
                raise PlanError(f"bug: no safe limits for the path ending at line {int(path.line[-1])}")
            s0 = max(float(S[first + p0]), s_start)
            s1 = L if p1 == g1.shape[0] else float(S[first + p1])
            phases = scurve(s1 - s0, v, a, j)
            T = sum(d for d, _ in phases)
            N = max(int(math.ceil(T / dt)), 1)
            t = np.arange(1, N + 1) * (T / N)  # stretched: every derivative scales down
            s = s0 + scurve_positions(phases, t)
            s[-1] = s1
            if p0 > 0:
                parts_s.append(np.full(SAFE_REST, s0))
            parts_s.append(np.minimum(s, s1))
        s = np.maximum.accumulate(np.concatenate(parts_s))
        q = _eval_table(table.S, table.C, s)
        q[-1] = table.qend
        rep = verify_arrays(q, dt, vl / dt, al / dt**2, jl / dt**3)
        if rep.ok:
            return PathPlan(s=s, q=q, stats={"samples": int(s.shape[0]), "planner": "safe"})
        share *= 0.5
    raise PlanError(f"bug: the safe planner failed on the path ending at line {int(path.line[-1])}")

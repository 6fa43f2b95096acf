"""How far from the minimum time is a plan? Two references.

* ``line_min_samples``: the *exact* discrete minimum for a straight rest-to-rest move
  (1-D, so every backward-difference limit is linear in the samples): the least K for
  which a linear program over s_1..s_{K-1} is feasible, found by bisection. This is
  the true discrete minimum time for the same dt that VPOp approximates.
* ``path_lower_bound``: a lower bound for any path: the continuous time-optimal
  traversal under the velocity and acceleration limits only (jerk ignored), computed
  by the classic maximum-velocity-curve + forward/backward integration in (s, ṡ²) on a
  fine grid. Any plan that respects V and A — with or without a jerk limit — takes at
  least this long (up to the grid's discretisation), so ``T_plan / bound >= 1``; the
  gap contains both the planner's loss and the price of the jerk limit.

``program_lower_bound`` sums the per-path bounds of a planned program plus its dwells.
"""

from __future__ import annotations

import math

import numpy as np


# -- exact discrete minimum of a straight move ------------------------------------------
def _line_feasible(length: float, k: int, v: float, a: float, j: float, dt: float) -> bool:
    """Is there s_0=0, ..., s_k=L (rest held before and after) within the limits?"""
    from scipy.optimize import linprog
    from scipy.sparse import diags, vstack

    if k < 1:
        return length == 0.0
    n = k - 1  # unknowns s_1..s_{k-1}
    # padded sequence: 3 x 0, s_0=0, s_1..s_{k-1}, s_k=L, 3 x L  (length n + 8)
    m = n + 8
    full = np.zeros(m)
    full[k + 3 :] = length
    if n == 0:  # nothing to choose: check the fixed sequence
        x = full
        for lim in (v * dt, a * dt * dt, j * dt**3):
            x = np.diff(x)
            if np.abs(x).max() > lim:
                return False
        return True
    # E maps unknowns into the padded sequence
    rows = np.arange(4, 4 + n)
    from scipy.sparse import csr_matrix

    E = csr_matrix((np.ones(n), (rows, np.arange(n))), shape=(m, n))
    A_list, b_list = [], []
    for order, lim in ((1, v * dt), (2, a * dt * dt), (3, j * dt**3)):
        coeffs = [math.comb(order, i) * (-1) ** (order - i) for i in range(order + 1)]
        D = diags([float(c) for c in coeffs], list(range(order + 1)), shape=(m - order, m))
        DE = D @ E
        c0 = D @ full
        A_list += [DE, -DE]
        b_list += [lim - c0, lim + c0]
    A = vstack(A_list).tocsr()
    b = np.concatenate(b_list)
    res = linprog(np.zeros(n), A_ub=A, b_ub=b, bounds=[(None, None)] * n, method="highs")
    return res.status == 0


def line_min_samples(length: float, v: float, a: float, j: float, dt: float, guess: int | None = None) -> int:
    """Least number of steps K (duration K·dt) of a rest-to-rest 1-D move of ``length``
    under |v| <= v, |a| <= a, |j| <= j as backward differences (rest padding included)."""
    if length <= 0:
        return 0
    hi = guess if guess is not None else 16
    while not _line_feasible(length, hi, v, a, j, dt):
        hi *= 2
    lo = 0
    # feasibility is monotone in K (a feasible plan can wait one more sample at the end)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if _line_feasible(length, mid, v, a, j, dt):
            hi = mid
        else:
            lo = mid
    return hi


# -- a lower bound for any path ------------------------------------------------------------
def _speed2_limits(qs: np.ndarray, qss: np.ndarray, vmax, amax, feed: np.ndarray) -> np.ndarray:
    """Largest ṡ² at each of K points (qs, qss (K, n)): the velocity limits, the feed, and
    some s̈ with every |q_s s̈ + q_ss ṡ²| <= A (bisection on ṡ², vectorised)."""
    g = np.abs(qs)
    with np.errstate(divide="ignore", invalid="ignore"):
        wv = np.where(g > 0, (vmax[None, :] / np.where(g > 0, g, 1.0)) ** 2, np.inf).min(axis=1)
    w_hi = np.minimum(np.where(np.isfinite(feed), feed * feed, np.inf), wv)
    w_hi = np.where(np.isfinite(w_hi), w_hi, 1e12)

    def ok(w):
        c = qss * w[:, None]
        still = np.abs(qs) < 1e-12
        bad = (still & (np.abs(c) > amax[None, :])).any(axis=1)
        den = np.where(still, 1.0, qs)
        x1 = (-amax[None, :] - c) / den
        x2 = (amax[None, :] - c) / den
        lo = np.where(still, -np.inf, np.minimum(x1, x2)).max(axis=1)
        hi = np.where(still, np.inf, np.maximum(x1, x2)).min(axis=1)
        return (lo <= hi) & ~bad

    good = ok(w_hi)
    a = np.zeros_like(w_hi)
    b = w_hi.copy()
    for _ in range(60):
        m = 0.5 * (a + b)
        okm = ok(m)
        a = np.where(okm, m, a)
        b = np.where(okm, b, m)
    return np.where(good, w_hi, a)


def _accel_range(qs, qss, w, amax):
    lo, hi = -np.inf, np.inf
    for i in range(qs.shape[0]):
        if abs(qs[i]) < 1e-12:
            continue
        c = qss[i] * w
        x1 = (-amax[i] - c) / qs[i]
        x2 = (amax[i] - c) / qs[i]
        lo = max(lo, min(x1, x2))
        hi = min(hi, max(x1, x2))
    return lo, hi


def path_lower_bound(path, joint_map, machine, n_grid: int = 2000) -> float:
    """Continuous V/A-limited minimum time of ``path`` from rest to rest (see module doc), s."""
    from .vpop import JointTable

    if path.length <= 0:
        return 0.0
    table = JointTable(path, None if path.rapid else joint_map)
    s = np.linspace(0.0, path.length, n_grid + 1)
    p = np.clip(np.searchsorted(table.S, s, side="right") - 1, 0, table.C.shape[0] - 1)
    t = (s - table.S[p])[:, None]
    c = table.C[p]
    qs = c[:, 1] + t * (2 * c[:, 2] + t * (3 * c[:, 3] + t * (4 * c[:, 4] + t * 5 * c[:, 5])))
    qss = 2 * c[:, 2] + t * (6 * c[:, 3] + t * (12 * c[:, 4] + t * 20 * c[:, 5]))
    seg = path.segment_of_s(s)
    feed = np.where(np.isfinite(path.feed_mm_s), path.feed_mm_s, np.inf)[seg]
    vmax, amax = machine.vmax, machine.amax
    mvc = _speed2_limits(qs, qss, vmax, amax, feed)
    ds = np.diff(s)
    w = mvc.copy()
    w[0] = 0.0
    for i in range(s.size - 1):  # forward: the most acceleration the limits allow
        hi = _accel_range(qs[i], qss[i], w[i], amax)[1]
        w[i + 1] = min(w[i + 1], w[i] + 2.0 * max(hi, 0.0) * ds[i])
    w[-1] = 0.0
    for i in range(s.size - 1, 0, -1):  # backward: the most deceleration
        lo = _accel_range(qs[i], qss[i], w[i], amax)[0]
        w[i - 1] = min(w[i - 1], w[i] + 2.0 * max(-lo, 0.0) * ds[i - 1])
    v = np.sqrt(np.maximum(w, 0.0))
    vm = v[:-1] + v[1:]
    return float(np.sum(2.0 * ds / np.where(vm > 0, vm, np.inf)))


def program_lower_bound(outcome, n_grid: int = 2000) -> float:
    """Sum of ``path_lower_bound`` over a planned program's paths plus its dwell times, s.

    ``outcome`` is a planned program with its ``fit`` (``FitResult``) and ``machine``
    (``api.PlanResult`` or ``pipeline.PlanOutcome``).
    """
    from ..gcode.program import Dwell
    from ..machine.kinematics import make_kinematics

    machine = outcome.machine
    fitted = outcome.fit
    kin = make_kinematics(machine)
    jm = None if kin.is_identity else kin
    total = 0.0
    for it in fitted.items:
        if isinstance(it, Dwell):
            total += it.seconds
        elif hasattr(it, "length"):
            total += path_lower_bound(it, jm, machine, n_grid)
    return total

"""The reference time law s(t) of a feed profile w(s) = ṡ².

Nodes (s_i, t_i, v_i, a_i) with v = √w, a = w'/2 and t_i = ∫ ds/√w, integrated piece by
piece with Gauss–Legendre (``TIMELAW_GL`` points; an interval that starts or ends at
rest, w = 0 with w' ≠ 0, is integrated in u with s = s_a + u² or s = s_b - u², where the
integrand is smooth). Between nodes s(t) is the quintic Hermite interpolant of
(s, v, a) at both ends: C² in time, so the sampled reference has bounded third
differences. ``_track_kernels`` evaluates it in compiled code.
"""

from __future__ import annotations

import numpy as np

from . import _feed_kernels as K

#: Gauss–Legendre points per node interval of the time integral
TIMELAW_GL = 6
#: nodes per knot interval of the profile
TIMELAW_NODES = 4
#: a piece whose w dips between two nodes below this share of the smaller node value is
#: refused (the sampler would crawl there; the planner hands over to VPOp instead)
TIMELAW_MIN_DIP = 1e-3

_GX, _GW = np.polynomial.legendre.leggauss(TIMELAW_GL)


class TimeLaw:
    """A profile piece's time law: nodes ``s`` (K,), mm; the time of each node interval
    ``dt`` (K-1,), s; at the nodes w = ṡ² ``w`` (K,), mm²/s², its derivative ``w1`` (K,),
    mm/s², the speed ``v`` = √w (K,), mm/s, and the acceleration ``a`` = w'/2 (K,), mm/s²."""

    __slots__ = ("s", "dt", "v", "a", "w", "w1")

    def __init__(self, s, dt, w, w1):
        self.s, self.dt, self.w, self.w1 = s, dt, w, w1
        self.v = np.sqrt(w)
        self.a = 0.5 * w1

    def nodes(self, t0: float):
        """(s, t, v, a) with the first node at time t0."""
        return self.s, t0 + np.concatenate(([0.0], np.cumsum(self.dt))), self.v, self.a


def time_law(knots, coef, s0: float, s1: float, old: TimeLaw | None = None, changed=None):
    """The ``TimeLaw`` of the profile piece (knots, coef) on [s0, s1]; None when w (nearly)
    reaches zero inside. With ``old``, this function's result for the same knots and
    interval, and ``changed`` = (j0, j1), the only coefficients that differ from old's:
    the node intervals those coefficients cannot reach keep old's numbers, which are bit
    for bit what a full computation gives (a point's w depends only on the four
    coefficients of its knot span), and only the others are computed again."""
    if old is None:
        br = np.unique(knots)
        br = br[(br > s0) & (br < s1)]
        br = np.concatenate(([s0], br, [s1]))
        u = np.arange(TIMELAW_NODES) / TIMELAW_NODES
        x = (br[:-1, None] + np.diff(br)[:, None] * u[None, :]).ravel()
        x = np.concatenate((x, [s1]))
        got = _law(knots, coef, x)
        return None if got is None else TimeLaw(x, *got)
    x = old.s
    j0, j1 = changed
    # nodes a..b span every point whose knot span touches coefficients j0..j1 (their
    # support is knots[j0] .. knots[j1 + 4]; one knot more each side)
    lo = knots[max(j0 - 1, 0)]
    hi = knots[min(j1 + 5, knots.shape[0] - 1)]
    a = max(int(np.searchsorted(x, lo, side="right")) - 1, 0)
    b = min(int(np.searchsorted(x, hi, side="left")), x.shape[0] - 1)
    if b <= a:
        return old
    got = _law(knots, coef, x[a : b + 1])
    if got is None:
        return None
    dt, w, w1 = old.dt.copy(), old.w.copy(), old.w1.copy()
    dt[a:b], w[a : b + 1], w1[a : b + 1] = got
    return TimeLaw(x, dt, w, w1)


def _law(knots, coef, x):
    """(dt, w, w1) at sorted nodes x (K,): each node interval's time (K-1,), w = ṡ² and
    w' at the nodes (w clipped at 0); None when w (nearly) reaches zero between two nodes
    (``_feed_kernels.time_nodes``)."""
    x = np.ascontiguousarray(x, dtype=float)
    K_ = x.shape[0]
    dt = np.empty(max(K_ - 1, 0))
    w = np.empty(K_)
    w1 = np.empty(K_)
    coef = np.ascontiguousarray(coef, dtype=float)
    if not K.time_nodes(knots, coef, x, _GX, _GW, TIMELAW_MIN_DIP, dt, w, w1):
        return None
    return dt, w, w1

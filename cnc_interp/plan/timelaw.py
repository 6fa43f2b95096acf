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


def _spline_w(knots, coef, x):
    """w, w' at sorted x of the cubic B-spline (knots, coef)."""
    x = np.ascontiguousarray(x, dtype=float)
    first = np.empty(x.shape[0], dtype=np.int64)
    B = np.empty((x.shape[0], 3, 4))
    K.cubic_basis(knots, coef.shape[0], x, first, B)
    cols = first[:, None] + np.arange(4)[None, :]
    c = coef[cols]
    return np.einsum("kj,kj->k", B[:, 0], c), np.einsum("kj,kj->k", B[:, 1], c)


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
    w' at the nodes (w clipped at 0); None when w (nearly) reaches zero between two nodes."""
    w, w1 = _spline_w(knots, coef, x)
    w = np.maximum(w, 0.0)
    rest_a = w <= 0.0
    # plain intervals: Gauss–Legendre on 1/√w
    a_, b_ = x[:-1], x[1:]
    h = 0.5 * (b_ - a_)
    m = 0.5 * (b_ + a_)
    pts = (m[:, None] + h[:, None] * _GX[None, :]).ravel()
    wp, _ = _spline_w(knots, coef, np.sort(pts))
    wp = wp[np.argsort(np.argsort(pts))].reshape(-1, TIMELAW_GL)
    plain = ~(rest_a[:-1] | rest_a[1:])
    ends = np.minimum(w[:-1], w[1:])[plain]
    if plain.any() and np.any(np.min(wp[plain], axis=1) <= TIMELAW_MIN_DIP * ends):
        return None  # the profile (nearly) stops between two of its nodes
    with np.errstate(divide="ignore"):
        dt = h * (np.maximum(wp, 1e-300) ** -0.5 @ _GW)
    # intervals touching rest: s = a + u² (rest at a) or s = b - u² (rest at b)
    for i in np.flatnonzero(rest_a[:-1] | rest_a[1:]):
        at_start = rest_a[i]
        span = b_[i] - a_[i]
        ub = np.sqrt(span)
        uu = 0.5 * ub * (_GX + 1.0)
        ss = a_[i] + uu * uu if at_start else b_[i] - uu * uu
        order = np.argsort(ss)
        wv, _ = _spline_w(knots, coef, ss[order])
        wv = wv[np.argsort(order)]
        f = 2.0 * uu / np.sqrt(np.maximum(wv, 1e-300))
        dt[i] = 0.5 * ub * (f @ _GW)
    return dt, w, w1

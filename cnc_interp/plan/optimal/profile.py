"""Feed profile LP: a near-time-optimal w(s) = ṡ² along one path, as linear programs.

``FeedProfileBuilder(table, path, machine, dt_s).windows()`` yields the profile piece by
piece (``FeedPiece``: a cubic B-spline of w on [s0, s1]). Each piece comes from a
linear program over the B-spline's coefficients (rows built by ``_feed_kernels``):
maximise the path speed — the first-order change of the traversal time ∫ ds/√w,
weights ŵ^-3/2 — under every axis's velocity, acceleration and jerk limit at
collocation points, the segments' feeds, and w = 0 at the ends. The jerk bound is
not convex; the convex-concave procedure of ``_feed_kernels`` makes it a few LPs,
solved by the banded interior-point method of ``_ipm``. An LP's objective is the
time's tangent at the last iterate, so its solution is a direction: the next iterate is
the point of least traversal time between the two (``_line_search``), and the time
falls at every iteration.

Knots: a spacing of ``tuning.knot_time_s`` of motion at an estimated speed (static
limits of velocity, curvature and jerk, and the sampled start and stop near the ends)
and at most ``tuning.knot_geo`` of the geometry's length scale, placed by counting
∫ ds / spacing from the path's start, block by block of the joint table: a knot
depends only on the path up to it (and the end region on the end).

Windows: ``tuning.commit_s`` of motion plus two braking times; each fixes the
coefficients the committed part uses, ends at rest (w = 0: a brake-safe end, the
window's solution can always stop) and commits all but the braking part. The profile on
[0, s] therefore depends only on the path up to s plus one window: the streaming
contract of ``iter_path_plan_optimal``. Past its committed part, a window's first LP is
linearised at the estimate lowered to the previous window's level (``tuning.est_ratio_min``),
and where the previous window brakes for its terminal rest, only as far towards it as
leaves that solution within the rows (``_feasible_hat``): the previous solution, then
rest, is a feasible point of the LP. Should it still have no solution (round-off), the
window is solved again linearised at the previous window's whole solution (``_solve``).

Collocation: ``tuning.collocation`` points per knot interval, plus the path's segment
joins, where q_sss jumps (paths are G2): there both one-sided values are imposed.

Sampled start and stop: a sampled plan may start with an acceleration of up to J dt
(its first third difference is the jerk limit), so w'(0) <= 2 J_t dt and
w'(L) >= -2 J_t dt with J_t the tangent's path jerk limit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .. import _feed_kernels as K
from .._ipm import OK as LP_OK, lp_solve
from ..tuning import OptimalTuning

#: rounds of probes added where they are further apart than a quarter of the spacing wanted
_KNOT_ROUNDS = 3
#: bisection steps of ``_feasible_hat`` (the interval shrinks 2^-30: far below what moves
#: the LP's rows)
_HAT_BISECTIONS = 30
#: golden-section steps of the CCP's line search (``_line_search``): the bracket shrinks
#: 0.618^24 ~ 1e-5, far below what moves the time
_LINE_STEPS = 24


def _line_search(x, w0, w1, steps: int):
    """The step alpha in [0, 1] from w0 (K,) towards w1 (K,) (w at the sorted x (K,))
    that minimises the traversal time by the trapezoid rule in 1/√w, and that time.
    The time is convex in alpha (1/√w is convex, w linear in alpha): golden-section
    search, ``steps`` shrinks of the bracket."""
    dx = np.diff(x)
    dw = w1 - w0

    def time(a):
        v = np.sqrt(np.maximum(w0 + a * dw, 0.0))
        return float(np.sum(2.0 * dx / np.maximum(v[1:] + v[:-1], 1e-300)))

    g = 0.5 * (np.sqrt(5.0) - 1.0)
    lo, hi = 0.0, 1.0
    a, b = hi - g * (hi - lo), lo + g * (hi - lo)
    ta, tb = time(a), time(b)
    for _ in range(steps):
        if ta <= tb:
            hi, b, tb = b, a, ta
            a = hi - g * (hi - lo)
            ta = time(a)
        else:
            lo, a, ta = a, b, tb
            b = lo + g * (hi - lo)
            tb = time(b)
    best = min(((time(1.0), 1.0), (ta, a), (tb, b), (time(0.0), 0.0)))
    return best[1], best[0]


class _Window(NamedTuple):
    """A window's whole solution, as the next window sees it: the B-spline of w
    (``knots`` (nc + 4,), ``coef`` (nc,)), where it starts braking for its terminal rest
    and where that rest is (``s_brake``, ``s_end``, mm), and how far below the estimate
    it ran (``ratio``: ``FeedProfileBuilder._ratio``)."""

    knots: np.ndarray
    coef: np.ndarray
    s_brake: float
    s_end: float
    ratio: float


class ProfileError(Exception):
    """The profile LP could not be solved (the planner then falls back to VPOp)."""


@dataclass(frozen=True, eq=False)
class FeedPiece:
    """A committed part of the profile: w(s) on [s0, s1] as cubic B-spline data.

    Attributes:
        knots: (nc + 4,) the knot vector of the basis functions of ``coef``.
        coef: (nc,) coefficients of w (mm²/s² or deg²/s²).
        s0, s1: the arc-length range this piece is final on, mm.
        lp_iters: interior-point iterations spent (statistics).
        restarts: windows solved again so far, this one included (statistics).
    """

    knots: np.ndarray
    coef: np.ndarray
    s0: float
    s1: float
    lp_iters: int
    restarts: int = 0


def spline_values(knots, coef, x, nu: int = 0):
    """The nu-th derivative (nu <= 2) of the cubic B-spline (knots, coef) at sorted x."""
    B, at = _basis_at(knots, coef, x)
    return np.einsum("kj,kj->k", B[:, nu], at)


def spline_derivs(knots, coef, x):
    """The cubic B-spline (knots, coef) and its first two derivatives at sorted x (each
    (K,), the bits of ``spline_values``), from one evaluation of the basis."""
    B, at = _basis_at(knots, coef, x)
    return tuple(np.einsum("kj,kj->k", B[:, nu], at) for nu in range(3))


def _basis_at(knots, coef, x):
    """``cubic_basis`` at sorted x (B (K, 3, 4)) and the coefficients each point uses (K, 4)."""
    x = np.ascontiguousarray(x, dtype=float)
    first = np.empty(x.shape[0], dtype=np.int64)
    B = np.empty((x.shape[0], 3, 4))
    K.cubic_basis(knots, coef.shape[0], x, first, B)
    return B, coef[first[:, None] + np.arange(4)[None, :]]


class FeedProfileBuilder:
    """Builds the profile of one path window by window (see module docstring)."""

    def __init__(
        self,
        table,
        path,
        machine,
        dt_s: float,
        tuning: OptimalTuning | None = None,
        limit_share: float | None = None,
        whole: bool = False,
    ):
        #: the planner's tunables (``OptimalTuning``; default: the defaults)
        self.tuning = tuning = OptimalTuning() if tuning is None else tuning
        self.knot_time_s = float(tuning.knot_time_s)
        self.L = float(table.length)
        self.dt = float(dt_s)
        self.n = table.C.shape[2]
        share = float(tuning.limit_share if limit_share is None else limit_share)
        # velocity and feed are bounds on w itself, exact at every point: only the shrink
        # every planner keeps; acceleration and jerk get the collocation's margin
        keep = 1.0 - 1e-9
        self.vmax = np.asarray(machine.vmax, dtype=float) * keep
        self.amax = np.ascontiguousarray(np.asarray(machine.amax, dtype=float) * share)
        self.jmax = np.ascontiguousarray(np.asarray(machine.jmax, dtype=float) * share)
        self.S = np.ascontiguousarray(table.S)
        self.C = np.ascontiguousarray(table.C)
        self.moving = np.ascontiguousarray(np.any(np.abs(table.C[:, 1:, :]) > 0, axis=(0, 1)))
        self.limits = K.AxisLimits(self.moving, self.amax, self.jmax)  # the LP's rows' limits
        # segment joins of the path, as table knots (the table keeps every path break)
        sb = np.asarray(path.s_breaks, dtype=float)[1:-1] * (self.L / float(path.length))
        if sb.size:
            ti = np.clip(np.searchsorted(self.S, sb), 1, self.S.shape[0] - 1)
            near = np.where(np.abs(self.S[ti - 1] - sb) < np.abs(self.S[ti] - sb), ti - 1, ti)
            self.joins = np.unique(self.S[np.clip(near, 1, self.S.shape[0] - 2)])
        else:
            self.joins = np.zeros(0)
        # segment feeds (path s) as a step function
        fb = np.asarray(path.s_breaks, dtype=float).copy()
        fb[-1] = self.L
        fv = np.where(np.isfinite(path.feed_mm_s) & (path.feed_mm_s > 0), path.feed_mm_s, np.inf)
        self.feed_breaks = fb
        self.feed_values = fv.astype(float) * keep
        q1e, _, _ = self.derivs(np.array([0.0, self.L]))
        self.jt0 = self._tangent_jerk(q1e[0])
        self.jt1 = self._tangent_jerk(q1e[1])
        # no knot interval shorter than the first sampled step from rest (J_t dt³, with
        # the tangent's path jerk of the nearer end: a knot depends on local data only)
        self.hmin0 = self.jt0 * self.dt**3
        self.hmin1 = self.jt1 * self.dt**3
        self._est_in = K.EstimateInputs(
            np.ascontiguousarray(self.vmax),
            self.amax,
            self.jmax,
            np.ascontiguousarray(self.feed_breaks),
            np.ascontiguousarray(self.feed_values),
            self.tuning.est_acc_factor**2,
            self.tuning.est_jerk_factor**2,
            self.hmin0,
            self.hmin1,
            self.dt,
            self.L,
        )
        t_brake = float(np.max(np.minimum(self.vmax, np.max(self.feed_values)) / self.amax + self.amax / self.jmax))
        # window: a committed part of tuning.commit_s of motion, then two braking times for
        # the terminal rest to stay out of it
        self.commit = max(8, int(np.ceil(self.tuning.commit_s / self.knot_time_s)))
        self.brake = int(np.ceil(2.0 * t_brake / self.knot_time_s)) + 8
        self.window = self.commit + self.brake
        # incremental knot placement state
        self._br = [0.0]
        self._knots = self._knot_blocks()
        self._ex = np.zeros(0)  # probes (x, enveloped w) from the current window on
        self._ew = np.zeros(0)
        self.knots_done = False
        #: the caller holds the whole path anyway: a short one may be one window
        self.whole = bool(whole)
        #: windows solved again from the previous window's whole solution (``_solve``)
        self.restarts = 0

    # -- geometry -----------------------------------------------------------------
    def derivs(self, x):
        x = np.ascontiguousarray(x, dtype=float)
        q1 = np.empty((x.shape[0], self.n))
        q2 = np.empty_like(q1)
        q3 = np.empty_like(q1)
        K.table_derivs(self.S, self.C, x, q1, q2, q3)
        return q1, q2, q3

    def _tangent_jerk(self, q1row):
        g = np.abs(q1row)
        ok = g > 1e-12
        return float(np.min(self.jmax[ok] / g[ok])) if ok.any() else float(np.min(self.jmax))

    def wmax_at(self, x, q1):
        """The bound on w at sorted x (K,) with joint tangents q1 (K, n): axis speeds and
        the feed (``_feed_kernels.wmax_of``)."""
        out = np.empty(x.shape[0])
        K.wmax_of(np.ascontiguousarray(x, dtype=float), q1, self.vmax, self.feed_breaks, self.feed_values, out)
        return out

    def _raw_estimate(self, x):
        """Estimated speed² at sorted x (K,) from the geometry there (static limits
        inflated, sampled start and stop near the ends): ``_feed_kernels.Estimates``."""
        return K.estimates_of(self.S, self.C, np.ascontiguousarray(x, dtype=float), self._est_in)

    def estimate(self, x):
        """Estimated speed² at sorted x (K,): ``_raw_estimate`` under the reach envelope
        of the knot placement's probes (a speed the tangent's acceleration and jerk can
        reach from the slow points around, see ``_feed_kernels.knot_probes``)."""
        x = np.ascontiguousarray(x, dtype=float)
        w = self._raw_estimate(x).w
        ex, ew = self._ex, self._ew
        if ex.shape[0] >= 2:
            inside = (x >= ex[0]) & (x <= ex[-1])
            w = np.where(inside, np.minimum(w, np.interp(x, ex, ew)), w)
        return w

    # -- knots, block by block ----------------------------------------------------
    def _knot_inputs(self):
        """``_feed_kernels.KnotInputs`` of this path."""
        return K.KnotInputs(
            self.tuning.est_acc_factor,
            self.tuning.est_jerk_factor**2,
            self.knot_time_s,
            self.tuning.knot_geo,
            self.hmin0,
            self.hmin1,
            _KNOT_ROUNDS,
            min(self.L / 2, 1.0) * 2.0 ** -np.arange(1, 40),  # geometric points from either end
        )

    def _knot_blocks(self):
        """The knot placement, one block of tuning.knot_block table pieces after the other:
        yields (breakpoints placed in the block (list), its probes x (K,), their enveloped
        speed² w (K,), last block?); ``_extend_knots`` takes them as the windows need.
        The probes of a block and the spacing wanted there are ``_feed_kernels.knot_probes``'s;
        a breakpoint falls wherever the integral of 1 / spacing crosses an integer."""
        S, L = self.S, self.L
        m = S.shape[0] - 1
        kin = self._knot_inputs()
        p0, cum0, carry = 0, 0.0, (np.inf, 0.0)
        known = (np.zeros(0), self._raw_estimate(np.zeros(0)))  # the last look-ahead's estimates
        while True:
            p1 = min(p0 + self.tuning.knot_block, m)
            p2 = min(p1 + self.tuning.knot_block, m)
            probe, w, h, *known = K.knot_probes(S, self.C, self._est_in, kin, p0, p1, p2, *carry, *known)
            carry = (float(probe[-1]), float(w[-1]))
            brk, cum0 = K.knot_breaks(probe, h, cum0, L)
            br = brk.tolist()
            yield br, probe, w, p1 == m
            if p1 == m:
                return
            p0 = p1

    def _extend_knots(self):
        """Take the knot placement's next block (``_knot_blocks``)."""
        br, probe, w, last = next(self._knots)
        self._ex = np.concatenate((self._ex, probe))
        self._ew = np.concatenate((self._ew, w))
        self._br.extend(br)
        if last:
            L = self.L
            br = self._br
            if br[-1] >= L:
                br.pop()
            br.append(L)
            if len(br) < 5:  # at least four intervals (end conditions use two coefficients)
                self._br = list(np.linspace(0.0, L, 5))
            self.knots_done = True

    def _breaks_upto(self, i: int) -> int:
        """Make breakpoints 0..i known (or all of them); returns the number known."""
        while not self.knots_done and len(self._br) <= i:
            self._extend_knots()
        return len(self._br)

    def _knot_slice(self, j0: int, j1: int):
        """Global clamped knots t[j0 : j1] (t_{i+3} = breakpoint i, three-fold ends)."""
        nb = len(self._br) - 1
        lo = min(max(j0 - 3, 0), nb)
        hi = min(max(j1 - 4, 0), nb)
        # only the breakpoints used: the list grows with the path (a window far along a
        # long path would otherwise convert all of it: O(n²) over its windows)
        part = np.asarray(self._br[lo : hi + 1])
        return part[np.clip(np.arange(j0, j1) - 3, 0, nb) - lo]

    # -- the LP of one window -------------------------------------------------------
    def windows(self):
        """Yield ``FeedPiece``s in path order (see module docstring)."""
        b0 = 0
        fixed = np.zeros(0)  # coefficients b0 .. b0+2 (committed), global indices
        prev = None  # the previous window's whole solution (``_Window``)
        # when the caller holds the whole path (``whole``), one of at most
        # tuning.whole_knots intervals is one window: windows overlap by their braking part
        # (about as long again as what they commit) and each costs a few LPs, so on a
        # short path one LP over everything is cheaper, and its optimum is the whole
        # path's (a streaming caller keeps the windows: bounded look-ahead)
        if self.whole:
            self._breaks_upto(self.tuning.whole_knots + 1)
            if self.knots_done and len(self._br) - 1 <= self.tuning.whole_knots:
                self.window = max(self.window, len(self._br) - 1)
        while True:
            self._breaks_upto(b0 + self.window + 4)
            nb = len(self._br) - 1
            if self.knots_done and nb - b0 <= self.window + 3:
                b1, at_end = nb, True
            else:
                b1, at_end = b0 + self.window, False  # three breakpoints of look-ahead remain
            coef, tk, it = self._solve(b0, b1, at_end, fixed, prev)
            # coef / tk: coefficients b0 .. b1+2 and their knots t[b0 : b1+7]
            if at_end:
                yield FeedPiece(tk, coef, self._br[b0], self.L, it, self.restarts)
                return
            commit = min(self.commit, max(b1 - b0 - self.brake, 1))
            bc = b0 + commit
            n_keep = bc - b0 + 3
            yield FeedPiece(
                tk[: n_keep + 4].copy(),
                coef[:n_keep].copy(),
                self._br[b0],
                self._br[bc],
                it,
                self.restarts,
            )
            fixed = coef[commit : commit + 3].copy()
            prev = _Window(tk, coef, self._br[max(b1 - self.brake, bc)], self._br[b1], self._ratio(tk, coef, b0, bc))
            b0 = bc
            # forget the estimate's probes before the next window (bounded memory)
            i = max(int(np.searchsorted(self._ex, self._br[b0], side="right")) - 2, 0)
            self._ex, self._ew = self._ex[i:], self._ew[i:]

    def _collocation(self, b0, b1):
        """The collocation points of the window [b0, b1] and the joint derivatives there
        (``_feed_kernels.collocation``): tuning.collocation per knot interval and both
        sides of each segment join. Returns x (K,) and q1, q2, q3 (K, n)."""
        br = np.asarray(self._br[b0 : b1 + 1])
        return K.collocation(self.S, self.C, br, self.tuning.collocation, self.joins)

    def _ratio(self, tk, coef, b0, bc) -> float:
        """The median ratio of the solution (knots ``tk``, ``coef``) to the estimate at the
        midpoints of the committed knot intervals b0..bc: at least tuning.est_ratio_min, 1
        above tuning.est_ratio_keep."""
        xs = np.asarray(self._br[b0 : bc + 1])
        xs = 0.5 * (xs[1:] + xs[:-1])
        w = spline_values(tk, coef, np.clip(xs, tk[3], tk[-4]))
        est = self.estimate(xs)
        ok = np.isfinite(est) & (est > 0.0)
        if not ok.any():
            return 1.0
        ratio = float(np.median(w[ok] / est[ok]))
        return 1.0 if ratio > self.tuning.est_ratio_keep else max(ratio, self.tuning.est_ratio_min)

    def _solve(self, b0, b1, at_end, fixed, prev):
        """The LPs of the window [b0, b1]: coefficients b0 .. b1+2, their knots, iterations.

        The rows are linearised at the previous window's solution up to where it brakes
        for its terminal rest (``prev.s_brake``), at the estimate lowered by ``prev.ratio``
        beyond, held near enough to the previous solution up to its rest that it meets
        them (``_feasible_hat``). Should that LP still have no solution (the previous one
        met its rows only to the solver's tolerance), the window is solved again
        linearised at the previous solution up to its end (``prev.s_end``).
        """
        try:
            s_brake = None if prev is None else prev.s_brake
            return self._solve_from(
                b0, b1, at_end, fixed, prev, s_brake, self.tuning.ccp_max, self.tuning.lp_first_max_iter
            )
        except ProfileError:
            if prev is None:
                raise
            self.restarts += 1
            return self._solve_from(b0, b1, at_end, fixed, prev, prev.s_end, self.tuning.ccp_max_restart)

    def _feasible_hat(self, prev, x, q1, q2, q3, target, floor):
        """Linearisation points (K,) at the sorted x (K,) where the previous window brakes:
        each as near ``target`` (K,) as keeps its solution p within the jerk rows there.

        With E_i the jerk's linear part at p (``_feed_kernels``), p meets the row of axis i
        linearised at ŵ when h(ŵ) = e √ŵ + p / (3 ŵ) <= 1, e = max_i |E_i| / (3/2 J_i);
        h(p) <= 1 is p's own jerk bound, and h is convex in √ŵ, so the allowed ŵ form an
        interval around p: the target where h(target) <= 1 - tuning.hat_margin, else its end
        towards the target (bisection in √ŵ), else p. ``q1``..``q3`` (K, n) are the joint
        derivatives at x; ``floor`` (mm²/s²) the least ŵ.
        """
        p, dp, ddp = spline_derivs(prev.knots, prev.coef, np.clip(x, prev.knots[3], prev.knots[-4]))
        out = np.empty(x.shape[0])
        K.feasible_hat(
            p, dp, ddp, q1, q2, q3, self.limits, target, floor, 1.0 - self.tuning.hat_margin, _HAT_BISECTIONS, out
        )
        return out

    def _solve_from(self, b0, b1, at_end, fixed, prev, s_prev, ccp_max, first_max_iter: int | None = None):
        """``_solve`` with the rows linearised at ``prev`` up to ``s_prev``; the first LP
        gets at most ``first_max_iter`` interior-point iterations (default
        ``tuning.lp_max_iter``)."""
        if first_max_iter is None:
            first_max_iter = self.tuning.lp_max_iter
        tk = self._knot_slice(b0, b1 + 7)
        nc = b1 - b0 + 3
        x, q1, q2, q3 = self._collocation(b0, b1)
        npt = x.shape[0]
        first = np.empty(npt, dtype=np.int64)
        B = np.empty((npt, 3, 4))
        K.cubic_basis(tk, nc, x, first, B)
        wmax = np.maximum(self.wmax_at(x, q1), 1e-300)
        finite = np.isfinite(wmax)
        W0 = float(np.max(wmax[finite])) if finite.any() else 1.0
        wmax = np.minimum(wmax, 1e3 * W0)
        w_est = np.minimum(np.maximum(self.estimate(x), 1e-12 * W0), wmax)
        # the first LP's linearisation: the estimate, lowered to the previous window's
        # level (tuning.est_ratio_min)
        w_hat = np.maximum(w_est * (1.0 if prev is None else prev.ratio), 1e-9 * W0)
        if prev is not None:
            # linearise at the previous window's solution where it is not braking for its
            # terminal rest: where fixed coefficients act its rows are then exactly those
            # it met (a tangent elsewhere would cut it off), and further on it is a
            # better start than the estimate
            near = x <= max(self._br[min(b0 + 3, len(self._br) - 1)], s_prev)
            wc = spline_values(prev.knots, prev.coef, np.clip(x[near], prev.knots[3], prev.knots[-4]))
            w_hat[near] = np.maximum(wc, 1e-9 * W0)
            # on to its rest: as near the estimate as keeps it a solution
            far = ~near & (x < prev.s_end)
            if far.any():
                w_hat[far] = self._feasible_hat(prev, x[far], q1[far], q2[far], q3[far], w_hat[far], 1e-9 * W0)
        # fixed coefficients: the committed three (b0 > 0), w(0) = 0, w(L) = 0
        free = np.ones(nc, dtype=bool)
        cfix = np.zeros(nc)
        if b0 > 0:
            free[:3] = False
            cfix[:3] = fixed
        else:
            free[0] = False
        if at_end:
            free[-1] = False
        # variables scaled by the estimate at each basis function's Greville abscissa
        grev = (tk[1 : nc + 1] + tk[2 : nc + 2] + tk[3 : nc + 3]) / 3.0
        scale = np.minimum(self.estimate(grev), self.wmax_at(grev, self.derivs(grev)[0]))
        scale = np.ascontiguousarray(np.maximum(scale, 1e-9 * W0))
        inner = (x > 0.0) & (x < self.L)
        if not at_end:
            inner[-1] = False  # the window's terminal rest
        rows_max = npt * (1 + 4 * int(self.moving.sum())) + 8
        row_first = np.empty(rows_max, dtype=np.int64)
        row_coef = np.empty((rows_max, 4))
        row_b = np.empty(rows_max)
        cell = np.zeros(npt)
        dx = np.diff(x)
        cell[:-1] += 0.5 * dx
        cell[1:] += 0.5 * dx
        fixed_vals = np.where(free, 0.0, cfix / scale)
        xv = fixed_vals
        end = self._end_rows(tk, nc, scale, b0, b1, at_end)
        # an LP's rows, the fixed coefficients' terms on the right-hand side
        size = rows_max + end.b.shape[0]
        lp = K.Rows(np.empty(size, dtype=np.int64), np.empty((size, 4)), np.empty(size))
        c = np.empty(nc)
        coef = np.empty(nc)
        prev_T = np.inf
        best = None
        w_last = w_hat
        iters = 0
        for ccp in range(ccp_max):
            r = K.lp_rows(
                K.Collocation(first, B, q1, q2, q3),
                self.limits,
                wmax,
                w_hat,
                inner,
                scale,
                K.Rows(row_first, row_coef, row_b),
            )
            m = K.lp_gather(K.Rows(row_first, row_coef, row_b), r, end, free, fixed_vals, lp)
            # the weights in numpy: its power's last bits are not libm's (a kernel's)
            wts = cell * np.maximum(w_hat, self.tuning.weight_floor * w_est) ** -1.5
            K.lp_objective(first, B, scale, wts, free, c)
            max_iter = first_max_iter if ccp == 0 else self.tuning.lp_max_iter
            rows = K.Rows(lp.first[:m], lp.coef[:m], lp.b[:m])
            status, it, xv_new = self._lp(rows, c, xv, free, ccp > 0, max_iter)
            iters += it
            finite, T = K.lp_profile_time(first, B, xv_new, scale, free, cfix, x, 1e-9 * W0, coef, w_hat)
            if status != LP_OK or not finite:
                if best is None:
                    raise ProfileError(f"feed-profile LP failed (status {status})")
                break  # keep the last solved iterate (feasible for the true limits)
            if best is not None:
                # the LP's objective is the time's tangent: its full step may lengthen
                # the profile. Every point between the last iterate and the LP's
                # solution meets the rows linearised at the last iterate (a convex set
                # holding both): the step takes the least time on that segment
                alpha, T = _line_search(x, w_last, w_hat, _LINE_STEPS)
                coef[:] = best + alpha * (coef - best)
                xv_new = xv + alpha * (xv_new - xv)
                w_hat[:] = np.maximum(w_last + alpha * (w_hat - w_last), 1e-9 * W0)
            w_last = w_hat.copy()
            xv = xv_new
            best = coef.copy()
            if abs(prev_T - T) <= self.tuning.ccp_tol * T:
                break
            prev_T = T
        return best, tk, iters

    def _lp(self, rows, c, xv, free, screen: bool, max_iter: int | None = None):
        """Solve the LP of ``rows`` (``Rows``: ``_feed_kernels.lp_gather``'s) in the free
        variables, from ``xv`` (nc,), with row screening when ``screen``; returns (status,
        iterations, x); at most ``max_iter`` iterations per solve (default
        ``tuning.lp_max_iter``)."""
        if max_iter is None:
            max_iter = self.tuning.lp_max_iter
        nc = free.shape[0]
        m = rows.b.shape[0]
        x = np.where(free, xv, 0.0)
        active = np.ones(m, dtype=np.bool_)
        count = m
        if screen:
            _, count = K.lp_screen(rows, x, self.tuning.row_screen, active, True)
        iters = 0
        attempt = 1
        while True:
            if attempt >= self.tuning.screen_rounds:
                active[:] = True  # the last solve takes every row: never a point outside one
                count = m
            sub = rows
            if count < m:
                sub = K.Rows(np.empty(count, dtype=np.int64), np.empty((count, 4)), np.empty(count))
                K.lp_take(rows, active, count, sub)
            x_try = x.copy()
            status, it, _, _ = lp_solve(nc, sub.first, sub.coef, sub.b, c, x_try, max_iter, self.tuning.lp_tol)
            iters += it
            if status != LP_OK or count == m:  # every row solved: nothing left out to check
                return status, iters, x_try
            viol, count = K.lp_screen(rows, x_try, self.tuning.row_screen, active, False)
            if not viol:
                return status, iters, x_try
            attempt += 1

    def _end_rows(self, tk, nc, scale, b0, b1, at_end):
        """The window's rows besides the collocation rows (``Rows``, local indices): its end
        conditions and every coefficient >= 0. They do not depend on the linearisation:
        made once per window, appended to each LP's collocation rows."""
        ef, ec, eb = [], [], []
        if b0 == 0:  # w'(0) = 3 c1 / t[4] <= 2 J_t dt
            ef.append(0)
            ec.append([0.0, 3.0 * scale[1] / tk[4] / (2.0 * self.jt0 * self.dt), 0.0, 0.0])
            eb.append(1.0)
        if at_end:  # w'(L) = -3 c_{n-2} / (L - t[n-1]) >= -2 J_t dt
            ef.append(nc - 4)
            ec.append([0.0, 0.0, 3.0 * scale[nc - 2] / (self.L - tk[nc - 1]) / (2.0 * self.jt1 * self.dt), 0.0])
            eb.append(1.0)
        else:  # the window ends at rest at its last breakpoint: w = 0, w' >= -2 J_t dt
            xe = np.array([self._br[b1]])
            fe = np.empty(1, dtype=np.int64)
            Be = np.empty((1, 3, 4))
            K.cubic_basis(tk, nc, xe, fe, Be)
            jt = self._tangent_jerk(self.derivs(xe)[0][0])
            sc = scale[fe[0] : fe[0] + 4]
            ef += [int(fe[0])] * 3
            ec += [list(Be[0, 0] * sc), list(-Be[0, 0] * sc), list(-Be[0, 1] * sc / (2.0 * jt * self.dt))]
            eb += [0.0, 0.0, 1.0]
        # every coefficient >= 0: then w >= 0 everywhere (convex hull), not only at
        # collocation points (a profile dipping below zero between them would stop)
        jj = np.arange(nc)
        nf = np.minimum(jj, nc - 4)
        nn = np.zeros((nc, 4))
        nn[jj, jj - nf] = -1.0
        rf = np.concatenate((np.asarray(ef, dtype=np.int64), nf))
        rc = np.concatenate((np.asarray(ec, dtype=float).reshape(-1, 4), nn))
        rb = np.concatenate((np.asarray(eb, dtype=float), np.zeros(nc)))
        # a band must fit in [0, nc): shift rows that start too late (zero-padded; the
        # collocation rows never do, ``cubic_basis`` keeps first <= nc - 4)
        over = rf + 4 - nc
        for i in np.flatnonzero(over > 0):
            sft = over[i]
            rc[i, sft:] = rc[i, : 4 - sft].copy()
            rc[i, :sft] = 0.0
            rf[i] -= sft
        return K.Rows(rf, rc, rb)

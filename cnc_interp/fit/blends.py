"""Corner blends: a corner sharper than the smooth-fit range is rounded by a
G2 quintic within the tolerance instead of stopping the machine (as LinuxCNC's
``G64 P`` and Siemens' G642 round corners).

At a corner node V between two straight moves with unit directions t_in, t_out
(the fitter's scaled metric), the blend replaces the last distance d of the move
into V and the first d of the move out of it by the quintic Hermite piece

    q(0) = V - d t_in,  q'(0) = t_in,  q''(0) = 0,
    q(h) = V + d t_out, q'(h) = t_out, q''(h) = 0,      h = r d,

which is tangent to both moves with zero curvature where it meets them: with the
neighbouring fits ending on the moves with the same tangent and zero curvature
(imposed end states), the path stays G2. θ is the turn angle. For given θ and r the
shape is fixed and every length scales with d: the deviation is dev₁(θ, r)·d —
the larger of the programmed corner's distance from the blend and the blend's
largest distance from the two moves (for r near 3 the blend first swings slightly
outwards, S-shaped, and stays within the tolerance on both sides of the moves) —
and the peak |dκ/ds| is c_j(θ, r)/d².

Per corner, every r of a grid is tried with d = min(tolerance / dev₁, half of the
shorter move) and the one with the smallest peak |dκ/ds| wins (the jerk of driving
through the blend at a given speed grows with it; under jerk limits it, not the
curvature, sets the corner speed at tolerances up to millimetres). Where the moves
are long, that is r ≈ 3.1: a blend about 45x the tolerance long on each side at
90°, with a third of the |dκ/ds| of the best blend that stays inside the corner;
where the moves are short, a smaller r that uses the tolerance within the length
there is. dev₁ and c_j come from 257 samples of the unit blend per r, on a 1°
grid of θ (the larger of the two neighbouring grid angles' dev₁, times
``_DEV_MARGIN``), computed once per grid angle used (about 1 ms each).

A corner is not blended — the path stops there, as before — under ``G61`` (the
caller never asks), next to an exact curve, where the turn exceeds
``FIT_BLEND_MAX_TURN_DEG`` (a near-reversal: the blend would be a near-cusp),
where the tool's own path (the linear axes) reverses or turns more than that
while rotary axes move, where the linear motion through the blend would nearly
stop (``FIT_BLEND_MIN_LIN_SPEED``), where the blend would be shorter than
``FIT_BLEND_MIN_MM``, or where the moves leave it less than 1/``FIT_BLEND_MAX_CROWDING``
of the length the tolerance would give it (squeezed, the blend's |dκ/ds| grows as
1/d²: past that crowding driving through it takes longer than stopping).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .nodes import hermite


#: corner blends (fit/blends.py): a corner turning more than this (deg) is a near-reversal
#: and stops the path (the blend would be a near-cusp: parameter speed 0.64 at 175°)
FIT_BLEND_MAX_TURN_DEG = 175.0

#: share of the tolerance a blend may use (the rest absorbs the tabulated deviation's
#: interpolation and float rounding; the deviation is measured independently after)
FIT_BLEND_TOL_SHARE = 0.95

#: a corner whose blend, at its tolerance, would be more than this many times longer than
#: the room its moves leave (half the shorter move) stops instead: a blend squeezed that
#: far is a near-cusp that is slower to drive through than a stop. Up to this crowding a
#: blend is faster than stopping on the corpus: at 32 the corpus sweep's VPOp cycle is
#: 13.7 % below that at 4 (stellabee1 17.7 %), 12 of 138 programs at most 0.74 % longer
#: (LHchips4); with no cap, 3D_Chips becomes one path and takes 6 % longer. A blend
#: squeezed past it but within one period's acceleration and jerk step
#: (``FitSettings.period_step_mm``) still blends: on LinuxCNC's configuration of the corpus
#: (jerk 1e6 mm/s³, 1 µm) random_lines_0.001in plans 18 % shorter; at axis_mm's own jerk
#: the step, 5 nm, is below any blend
FIT_BLEND_MAX_CROWDING = 32.0

#: shortest blend (mm, scaled metric): below it (moves of nanometres) the path stops instead
FIT_BLEND_MIN_MM = 1e-5

#: with rotary axes: least share of the linear axes in either move's direction (scaled metric)
#: for a blend; below it the tool's own path would nearly stop inside the blend
FIT_BLEND_MIN_LIN_SPEED = 0.05

#: candidate shapes r = h / d (the blend is a near-loop beyond 16/5, where its middle
#: reaches the corner)
BLEND_R = np.linspace(0.2, 3.16, 38)
#: grid of turn angles (deg) the unit blends are tabulated on
_ANGLE_STEP_DEG = 1.0
#: samples of a unit blend
_SAMPLES = 257
#: least parameter speed of a unit blend (its ends have 1): no near-cusp
_MIN_PARAM_SPEED = 0.05
#: margin on the tabulated deviation (sampling of the unit blend, interpolation in θ)
_DEV_MARGIN = 1.02
_TABLE: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}


@dataclass(frozen=True)
class Blend:
    """A blended corner in a prepared run: nodes ``i`` (the blend's start on the move in),
    ``i + 1`` (the programmed corner) and ``i + 2`` (its end on the move out).

    coef (6, n) power coefficients in machine units over [0, h]; line: the corner's
    block; feed_mm_s: the slower of the two moves' feeds; t_in / t_out (n,) unit
    directions in the scaled metric (the end states imposed on the neighbours).
    """

    i: int
    h: float
    coef: np.ndarray
    line: int
    feed_mm_s: float
    t_in: np.ndarray
    t_out: np.ndarray


@dataclass(frozen=True, eq=False)
class BlendTable:
    """The blended corners of a prepared run as arrays, in path order (K blends, n axes):
    ``i`` (K,), ``h`` (K,), ``coef`` (K, 6, n), ``line`` (K,), ``feed_mm_s`` (K,),
    ``t_in`` / ``t_out`` (K, n), each as in ``Blend``. ``table[k]`` is the k-th ``Blend``
    and ``table[a:b]`` a table of those blends: a run of 10⁵ corners holds 7 arrays, not
    10⁵ objects (stellabee1: 111k blends, 64 MB of objects)."""

    i: np.ndarray
    h: np.ndarray
    coef: np.ndarray
    line: np.ndarray
    feed_mm_s: np.ndarray
    t_in: np.ndarray
    t_out: np.ndarray

    def __len__(self) -> int:
        return int(self.i.shape[0])

    def __getitem__(self, k):
        if isinstance(k, slice):
            return BlendTable(
                self.i[k], self.h[k], self.coef[k], self.line[k], self.feed_mm_s[k], self.t_in[k], self.t_out[k]
            )
        i, h, line, feed = int(self.i[k]), float(self.h[k]), int(self.line[k]), float(self.feed_mm_s[k])
        return Blend(i, h, self.coef[k], line, feed, self.t_in[k], self.t_out[k])

    def __iter__(self):
        for k in range(len(self)):
            yield self[k]


def unit_blends(theta: float, rs: np.ndarray, samples: int = _SAMPLES):
    """The blends with d = 1 of a corner at the origin (t_in = (1, 0)) for shapes rs (R,):
    (deviation (R,), peak curvature (R,), peak |dκ/ds| (R,), least parameter speed (R,))."""
    R = rs.size
    tin = np.array([1.0, 0.0])
    tout = np.array([np.cos(theta), np.sin(theta)])
    z = np.zeros((R, 2))
    c = hermite(np.tile(-tin, (R, 1)), np.tile(tin, (R, 1)), z, np.tile(tout, (R, 1)), np.tile(tout, (R, 1)), z, rs)
    # q^(k)(r τ) = Σ_i c_i i!/(i-k)! r^(i-k) τ^(i-k): one product with the powers of τ
    tau = np.linspace(0.0, 1.0, samples)
    powers = tau[:, None] ** np.arange(6)[None, :]  # (S, 6)
    rp = rs[:, None] ** np.arange(6)[None, :]  # (R, 6)

    def deriv(k):
        fac = np.array([float(np.prod(np.arange(i - k + 1, i + 1))) if i >= k else 0.0 for i in range(6)])
        ck = np.zeros_like(c)  # (R, 6, 2): coefficients of the k-th derivative in τ^(i-k)
        ck[:, : 6 - k] = c[:, k:] * fac[k:, None] * rp[:, : 6 - k, None]
        return np.matmul(powers, ck)  # (S, 6) @ (R, 6, 2) -> (R, S, 2)

    p, d1, d2, d3 = deriv(0), deriv(1), deriv(2), deriv(3)
    sp = np.linalg.norm(d1, axis=2)
    cross = d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]
    kappa = cross / sp**3
    dcross = d1[..., 0] * d3[..., 1] - d1[..., 1] * d3[..., 0]
    dsp = (d1 * d2).sum(axis=2) / sp
    dk_ds = (dcross / sp**3 - 3.0 * cross * dsp / sp**4) / sp
    corner = np.linalg.norm(p, axis=2).min(axis=1)  # the programmed corner to the blend
    off = np.minimum(_segment_distance(p, -tin, np.zeros(2)), _segment_distance(p, np.zeros(2), tout))
    dev = np.maximum(corner, off.max(axis=1))  # and the blend to the programmed moves
    return dev, np.abs(kappa).max(axis=1), np.abs(dk_ds).max(axis=1), sp.min(axis=1)


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)


def _table(k: int):
    """(dev₁, c_j, usable) (R,) at grid angle k·``_ANGLE_STEP_DEG``, cached."""
    got = _TABLE.get(k)
    if got is None:
        dev, _, dk, sp = unit_blends(np.radians(k * _ANGLE_STEP_DEG), BLEND_R)
        got = _TABLE[k] = (dev, dk, sp >= _MIN_PARAM_SPEED)
    return got


def choose_shapes(theta: np.ndarray, tol: np.ndarray, d_max: np.ndarray):
    """Per corner (K,): the shape r, distance d and deviation of the blend with the smallest
    peak |dκ/ds| within tolerance ``tol`` and d <= ``d_max`` (see module docstring)."""
    deg = np.degrees(theta) / _ANGLE_STEP_DEG
    lo = np.floor(deg).astype(np.int64)
    grid = np.unique(lo)
    # per grid angle used, the tables of the interval [k, k + 1] it starts
    dev1 = np.empty((grid.size, BLEND_R.size))
    cj = np.empty((grid.size, BLEND_R.size))
    usable = np.empty((grid.size, BLEND_R.size), dtype=bool)
    for g, k in enumerate(grid.tolist()):
        dev_a, cj_a, ok_a = _table(k)
        dev_b, cj_b, ok_b = _table(k + 1)
        dev1[g] = np.maximum(dev_a, dev_b) * _DEV_MARGIN
        cj[g] = np.maximum(cj_a, cj_b)
        usable[g] = ok_a & ok_b
    which = np.searchsorted(grid, lo)
    best, d = _choose_kernel(which, np.asarray(tol, dtype=float), np.asarray(d_max, dtype=float), dev1, cj, usable)
    return BLEND_R[best], d, dev1[which, best] * d


@njit(cache=True, nogil=True)
def _choose_kernel(which, tol, d_max, dev1, cj, usable):
    """``choose_shapes``' search per corner: the first r of the least cj / d² over the
    usable shapes, d = min(tol / dev₁, d_max) (numpy's operations, one corner at a time)."""
    K = which.shape[0]
    R = dev1.shape[1]
    best = np.zeros(K, dtype=np.int64)
    d = np.empty(K)
    for i in range(K):
        g = which[i]
        b = 0  # numpy's argmin: the first shape when none is usable
        b_score = np.inf
        b_d = min(tol[i] / dev1[g, 0], d_max[i])
        for r in range(R):
            dd = min(tol[i] / dev1[g, r], d_max[i])
            score = cj[g, r] / (dd * dd) if usable[g, r] else np.inf
            if score < b_score:
                b_score = score
                b = r
                b_d = dd
        best[i] = b
        d[i] = b_d
    return best, d


def plan_blends(
    nodes_s: np.ndarray,
    lin: np.ndarray,
    tol: np.ndarray,
    cand: np.ndarray,
    forced: np.ndarray | None = None,
    tol_rot_scaled: float = np.inf,
    step_mm: float = 0.0,
):
    """Shapes and sizes of the blends at candidate corners.

    nodes_s (n, d) in the scaled metric, lin (d,) linear axes, tol (n,) tolerance of the
    move ending at each node, cand (n,) bool corners the caller allows to blend;
    ``forced`` (n,) corners a repair blends whatever the crowding (else they stop);
    ``tol_rot_scaled``: the rotary tolerance in the scaled metric, the most a blend may
    deviate where rotary axes move (a ``G64 P`` above the default tolerance widens the
    position's tolerance, not the orientation's). ``step_mm``: the machine's smallest
    step of a period's acceleration and jerk limits (``FitSettings.period_step_mm``): a
    blend squeezed past the crowding cap but no larger than that still blends.
    Returns (ok (n,) bool: blended, d (n,) blend distance from the corner along each
    move in scaled units, r (n,) shape). Two blends on one move never overlap.
    """
    n = nodes_s.shape[0]
    ok = np.zeros(n, dtype=bool)
    dist = np.zeros(n)
    shape = np.zeros(n)
    j = np.nonzero(cand[1 : n - 1])[0] + 1
    if j.size == 0:
        return ok, dist, shape
    chords = np.diff(nodes_s, axis=0)
    clen = np.linalg.norm(chords, axis=1)
    t_in = chords[j - 1] / clen[j - 1, None]
    t_out = chords[j] / clen[j, None]
    theta = np.arccos(np.clip((t_in * t_out).sum(axis=1), -1.0, 1.0))
    good = np.degrees(theta) <= FIT_BLEND_MAX_TURN_DEG
    if (~lin).any() and lin.any():
        # the tool's own path: its speed through the blend runs from |t_in_lin| to
        # |t_out_lin| along a Hermite; it must not turn back or nearly stop
        li, lo = t_in[:, lin], t_out[:, lin]
        ni, no = np.linalg.norm(li, axis=1), np.linalg.norm(lo, axis=1)
        cos_lin = (li * lo).sum(axis=1) / np.maximum(ni * no, 1e-300)
        good &= np.degrees(np.arccos(np.clip(cos_lin, -1.0, 1.0))) <= FIT_BLEND_MAX_TURN_DEG
        good &= np.minimum(ni, no) >= FIT_BLEND_MIN_LIN_SPEED
    tol_c = np.minimum(tol[j], tol[j + 1])
    if (~lin).any():
        rot_moves = (np.abs(t_in[:, ~lin]) + np.abs(t_out[:, ~lin])).max(axis=1) > 0
        tol_c = np.where(rot_moves, np.minimum(tol_c, tol_rot_scaled), tol_c)
    tol_c = tol_c * FIT_BLEND_TOL_SHARE
    th = np.minimum(theta, np.radians(FIT_BLEND_MAX_TURN_DEG))
    room = 0.5 * np.minimum(clen[j - 1], clen[j])
    r, d, _ = choose_shapes(th, tol_c, room)
    good &= d >= FIT_BLEND_MIN_MM
    # a blend squeezed into far less room than the tolerance would give it is slower than
    # a stop (measured with VPOp on dense CAM corners): stop there instead, unless the
    # blend is within one period's step of the acceleration and jerk limits, where the
    # sampled plan's differences pass it as they pass a straight move
    _, d_free, _ = choose_shapes(th, tol_c, np.full(room.shape, np.inf))
    roomy = (d_free <= FIT_BLEND_MAX_CROWDING * room) | (d <= step_mm)
    if forced is not None:
        roomy |= forced[j]
    good &= roomy
    ok[j[good]] = True
    dist[j[good]] = d[good]
    shape[j[good]] = r[good]
    return ok, dist, shape


def blend_piece(
    p_a: np.ndarray,
    p_b: np.ndarray,
    t_in: np.ndarray,
    t_out: np.ndarray,
    d: np.ndarray,
    r: np.ndarray,
    scale: np.ndarray,
):
    """Coefficients (K, 6, n) in machine units and parameter lengths h (K,) of K blends of
    shapes r (K,) from p_a to p_b (K, n) (machine units, at distances d (K,) before / after
    the corners along the moves); t_in/t_out (K, n) unit directions in the scaled metric.
    Each piece starts exactly at p_a and ends at p_b up to the rounding of one Hermite
    evaluation."""
    h = np.asarray(r, dtype=float) * np.asarray(d, dtype=float)
    z = np.zeros_like(t_in)
    c = hermite(p_a * scale, t_in, z, p_b * scale, t_out, z, h, dp=(p_b - p_a) * scale)
    c = c / scale[None, None, :]
    c[:, 0] = p_a
    return c, h

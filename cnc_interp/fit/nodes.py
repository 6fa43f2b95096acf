"""General N-axis fitter: a clamped quintic B-spline fitted to the nodes.

Method (robust, O(n) per round; the rounds run in one numba kernel, ``_bspline.refine``):

* parameter u = cumulative chord length in the fitter's metric (linear axes in mm,
  rotary axes scaled to mm by tol_mm / tol_deg), so |dq/du| ≈ 1;
* a clamped quintic B-spline with interior knots at every
  ``FIT_INITIAL_NODES_PER_SPAN``-th node is fitted by weighted least squares to the
  nodes (weight tol_ref / tol_node) and to points on every chord (half that weight), with a
  small third-divided-difference smoothing term and a
  vanishing ridge (both keep knot spans without data well posed); its end positions
  are the end nodes exactly, and optionally its end derivatives in u are imposed (a
  G2 junction with an exact curve);
* checks: every node within its tolerance (Euclidean over linear axes in mm, each
  rotary axis in deg) and every check point on the programmed moves — seven
  fractions of every chord plus ``FIT_SPAN_CHECKS`` points inside every knot span,
  which are data of the least squares too — within ``FIT_BETWEEN_NODES_SAFETY`` of
  the tolerance (the tolerance bounds the distance to the programmed path
  everywhere, so no sagitta allowance: a smooth curve may not bulge off a move) —
  hard; the speed |dq/du| (all axes and the arc-length axes) at least
  ``FIT_MIN_SPEED_RATIO`` of the chord's — soft, and below ``FIT_STOP_SPEED_RATIO``
  (a stop, a cusp) — hard;
* every knot span with a failing point gets a knot at its middle node (or its
  middle if it holds no node; where rotary axes move, no more knots than moves: at
  most one segment per move); repeat until everything passes, or until only soft
  checks fail and ``FIT_SOFT_STALE_ROUNDS`` rounds did not reduce them.

A quintic B-spline is C4 in u at simple knots, hence C2 in arc length and G2
where the speed is positive. Each knot span becomes the quintic Hermite piece of
q, q', q'' at its two knots (exact for a quintic; neighbours share the very same
end values), in coordinates relative to the first node.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constants import FIT_BETWEEN_NODES_SAFETY, FIT_TOL_SAFETY
from ._npexact import hermite_powers


#: N-axis fitter: weight of the 3rd-divided-difference smoothing term (in tolerance units)
FIT_SMOOTHING = 1e-4

#: N-axis fitter: most knot-insertion rounds before the fit falls back to a knot per node
FIT_MAX_ROUNDS = 40

#: N-axis fitter: nodes per span of the initial knot vector
FIT_INITIAL_NODES_PER_SPAN = 512

#: N-axis fitter: least fitted speed |dq/du| relative to the chord's, at nodes and mid-chords
FIT_MIN_SPEED_RATIO = 0.25

#: N-axis fitter: a fitted speed below this share of the chord's is a stop and never accepted
FIT_STOP_SPEED_RATIO = 0.01

#: N-axis fitter: rounds without fewer chord-point failures before refinement stops
FIT_SOFT_STALE_ROUNDS = 3

#: N-axis fitter: smallest knot span relative to the run's parameter length
FIT_MIN_SPAN_REL = 1e-6

#: N-axis fitter: check points per knot span between the nodes (on the programmed moves)
FIT_SPAN_CHECKS = 6

_FRACS = np.arange(1, 8) / 8.0
_RIDGE = 1e-10
_FACT = np.array([1.0, 1.0, 2.0, 6.0, 24.0, 120.0])


@dataclass(frozen=True)
class EndState:
    """Imposed end derivatives in the fitter's unit-speed parameter: tangent (d,), curvature vector (d,)."""

    d1: np.ndarray
    d2: np.ndarray


@dataclass(frozen=True)
class PieceFit:
    """Power-basis pieces of one fitted section (local parameter starting at 0).

    breaks (n_seg+1,), coef (n_seg, 6, d) in machine units, line (n_seg,),
    feed_mm_s (n_seg,), max_dev_mm / max_dev_deg: worst node deviation found,
    ok: every check passed.
    """

    breaks: np.ndarray
    coef: np.ndarray
    line: np.ndarray
    feed_mm_s: np.ndarray
    max_dev_mm: float
    max_dev_deg: float
    ok: bool
    n_nodes: int


def straight_piece(p0: np.ndarray, p1: np.ndarray, length: float, line: int, feed: float) -> PieceFit:
    """One exact straight segment from p0 to p1 with parameter length ``length``."""
    coef = np.zeros((1, 6, p0.shape[0]))
    coef[0, 0] = p0
    coef[0, 1] = (p1 - p0) / length
    return PieceFit(np.array([0.0, length]), coef, np.array([line]), np.array([feed]), 0.0, 0.0, True, 2)


def _kernel_array(a, dtype=float) -> np.ndarray:
    """``a`` contiguous and writeable: a read-only view (a frozen Path's arrays) would be a
    separate numba specialization of the kernel, compiled again on a first run."""
    a = np.ascontiguousarray(a, dtype=dtype)
    return a if a.flags.writeable else a.copy()


def fit_polyline(
    nodes: np.ndarray,
    tol_mm: np.ndarray,
    tol_deg: float,
    lin: np.ndarray,
    metric: np.ndarray,
    line: np.ndarray,
    feed: np.ndarray,
    tol_ref_mm: float,
    start: EndState | None = None,
    end: EndState | None = None,
) -> PieceFit:
    """Fit one section of nodes (n, d) without corners or duplicate nodes.

    ``tol_mm`` (n,) per node (tolerance of the move ending there; node 0 that of
    move 1), ``tol_deg`` for rotary axes, ``lin`` (d,) bool linear axes,
    ``metric`` (d,) bool axes of the arc-length metric, ``line``/``feed`` (n,)
    per node. ``start``/``end`` impose u-derivatives in the scaled space.

    ``_section.fit_section`` is the same fit in one compiled call (the batch fitter's);
    this one serves the runs the batch fitter leaves (NURBS, rotary axes, repairs, short
    runs before its kernels are cached) and compiles only the rounds' kernel.
    """
    from . import _bspline as bs

    n, d = nodes.shape
    scale = np.where(lin, 1.0, tol_ref_mm / tol_deg)
    # relative to the first node: differences of large absolute coordinates lose digits
    y = (nodes - nodes[0]) * scale
    chords = np.diff(y, axis=0)
    clen = np.linalg.norm(chords, axis=1)
    u = np.concatenate(([0.0], np.cumsum(clen)))
    total = float(u[-1])
    tol = np.asarray(tol_mm, dtype=float) * FIT_TOL_SAFETY
    tol_rot = tol_deg * FIT_TOL_SAFETY * scale[~lin].max(initial=1.0) if (~lin).any() else np.inf

    if n == 2 and start is None and end is None:
        return straight_piece(nodes[0], nodes[1], total, int(line[1]), float(feed[1]))

    # check points: nodes and fractions of each chord
    metric_len = np.sqrt((chords[:, metric] ** 2).sum(axis=1))
    lin_ratio = metric_len / clen
    # check points on the programmed moves: fractions of every chord (more on long chords
    # than their neighbours' scale would need is left to the per-span points below); the
    # tolerance is a bound on the distance to the programmed path everywhere, so no
    # allowance beyond the tolerance (a smooth curve may not bulge off a chord)
    f = _FRACS
    xc_ch = (u[:-1, None] + clen[:, None] * f[None, :]).ravel()
    ref_ch = (y[:-1, None, :] + chords[:, None, :] * f[None, :, None]).reshape(-1, d)
    # between the nodes the deviation is only sampled: keep a margin there
    tol_ch = np.repeat(tol[1:], f.size) * FIT_BETWEEN_NODES_SAFETY
    node_ratio = np.empty(n)
    node_ratio[0] = lin_ratio[0]
    node_ratio[-1] = lin_ratio[-1]
    node_ratio[1:-1] = np.minimum(lin_ratio[:-1], lin_ratio[1:])
    xc0 = np.concatenate((u, xc_ch))
    ref0 = np.concatenate((y, ref_ch))
    tol_c0 = np.concatenate((tol, tol_ch))
    exp_lin0 = np.concatenate((node_ratio, np.repeat(lin_ratio, f.size)))
    w = tol_ref_mm / np.maximum(tol, 1e-12)
    # chord points are data too (else a span without nodes follows only the smoothing):
    # the check points are the data points
    w_ch = 0.5 * tol_ref_mm / (tol_ch + 1e-12)
    w_data0 = np.concatenate((w, w_ch))
    span_f = np.arange(1, FIT_SPAN_CHECKS + 1) / (FIT_SPAN_CHECKS + 1)

    step = FIT_INITIAL_NODES_PER_SPAN
    interior = u[step : n - 1 : step].copy()
    if interior.size and total - interior[-1] < 0.5 * (interior[-1] - (interior[-2] if interior.size > 1 else 0.0)):
        interior = interior[:-1]
    # a knot (a segment boundary) wherever the programmed feed changes: every segment
    # then lies within one feed (``segment_sources``) and each move keeps its own F
    f_in = np.asarray(feed, dtype=float)
    brk = np.nonzero(f_in[1:-1] != f_in[2:])[0] + 1 if n > 2 else np.zeros(0, dtype=np.int64)
    if brk.size:
        interior = np.unique(np.concatenate((interior, u[brk])))
    zero = np.zeros(d)
    d1s = start.d1 if start is not None else zero
    d2s = start.d2 if start is not None else zero
    d1e = end.d1 if end is not None else zero
    d2e = end.d2 if end is not None else zero
    f64 = _kernel_array

    # where rotary axes move, at most one segment per move (knots chasing the soft speed
    # check of the tool's own path, whose share of the motion jumps from move to move,
    # multiplied the segments several times over)
    rotary_moves = bool(np.any(np.ptp(nodes[:, ~lin], axis=0) > 0)) if (~lin).any() else False
    # the knot-insertion rounds (compiled; see bs.refine)
    t, m, c, ok = bs.refine(
        bs.FitNodes(f64(u), f64(y), f64(tol), f64(chords), f64(clen), f64(lin_ratio)),
        f64(interior),
        float(total),
        bs.EndStates(
            f64(d1s, dtype=float),
            f64(d2s, dtype=float),
            f64(d1e, dtype=float),
            f64(d2e, dtype=float),
            0 if start is None else 1,
            0 if end is None else 1,
        ),
        bs.FitData(f64(xc0), f64(ref0), f64(tol_c0), f64(exp_lin0), f64(w_data0), f64(span_f)),
        bs.RefineParams(
            float(tol_ref_mm),
            float(tol_rot),
            f64(lin, dtype=np.bool_),
            f64(metric, dtype=np.bool_),
            FIT_BETWEEN_NODES_SAFETY,
            FIT_SMOOTHING,
            _RIDGE,
            FIT_MIN_SPEED_RATIO,
            FIT_STOP_SPEED_RATIO,
            FIT_MAX_ROUNDS,
            FIT_SOFT_STALE_ROUNDS,
            FIT_MIN_SPAN_REL * total,
            n - 2 if rotary_moves else -1,
        ),
    )
    val = np.empty((n, d))
    der = np.empty((n, d))
    bs.evaluate(t, m, c, u, val, der)
    dev = val - y
    max_mm = float(np.sqrt((dev[:, lin] ** 2).sum(axis=1)).max()) if lin.any() else 0.0
    max_deg = float(np.abs(dev[:, ~lin] / scale[~lin]).max()) if (~lin).any() else 0.0
    ends = (
        None if start is None else (start.d1 / scale, start.d2 / scale),
        None if end is None else (end.d1 / scale, end.d2 / scale),
    )
    return _to_pieces(t, c / scale, u, line, feed, nodes[0], nodes[-1], max_mm, max_deg, ok, ends)


def _to_pieces(t, c, u, line, feed, p0, p_end, max_mm, max_deg, ok, ends=(None, None)) -> PieceFit:
    """Power-basis pieces of the B-spline: each span is the quintic Hermite interpolant of
    q, q', q'' at its two knots (exact for a quintic), so neighbouring pieces share the
    very same end values and the joins are C2 up to the rounding of one Hermite solve
    (converting via 5th derivatives would lose digits next to tiny spans)."""
    from . import _bspline as bs

    x = np.unique(t)
    c = np.ascontiguousarray(c, dtype=float)
    d0, d1, d2 = (np.empty((x.size, c.shape[1])) for _ in range(3))
    bs.evaluate012(np.ascontiguousarray(t, dtype=float), t.size - 6, c, x, d0, d1, d2)
    # (the last knot is evaluated from the left.) Exact end values: the end nodes and any imposed end derivatives
    d0 += p0
    d0[0] = p0
    d0[-1] = p_end
    if ends[0] is not None:
        d1[0], d2[0] = ends[0]
    if ends[1] is not None:
        d1[-1], d2[-1] = ends[1]
    h = np.diff(x)
    coef = hermite(d0[:-1], d1[:-1], d2[:-1], d0[1:], d1[1:], d2[1:], h)
    seg_line, seg_feed = segment_sources(x, u, line, feed)
    return PieceFit(x - x[0], coef, seg_line, seg_feed, max_mm, max_deg, ok, int(u.size))


def section_params(tol_deg: float, lin: np.ndarray, metric: np.ndarray, tol_ref_mm: float):
    """The compiled section fitter's settings (``_section.SectionParams``): this module's constants."""
    from ._section import SectionParams

    return SectionParams(
        float(tol_deg),
        _kernel_array(lin, dtype=np.bool_),
        _kernel_array(metric, dtype=np.bool_),
        float(tol_ref_mm),
        FIT_TOL_SAFETY,
        FIT_BETWEEN_NODES_SAFETY,
        FIT_SMOOTHING,
        _RIDGE,
        FIT_MIN_SPEED_RATIO,
        FIT_STOP_SPEED_RATIO,
        FIT_MAX_ROUNDS,
        FIT_SOFT_STALE_ROUNDS,
        FIT_MIN_SPAN_REL,
        FIT_INITIAL_NODES_PER_SPAN,
    )


def hermite(p0, v0, a0, p1, v1, a1, h, dp=None):
    """Quintic Hermite power coefficients (K, 6, d) on [0, h] (K,) from end values (K, d).

    ``dp`` (K, d) may give p1 - p0 more accurately than the subtraction (tiny pieces far
    from the origin).
    """
    hh = h[:, None]
    if dp is None:
        dp = p1 - p0
    c = np.empty(p0.shape[:1] + (6,) + p0.shape[1:])
    c[:, 0] = p0
    c[:, 1] = v0
    c[:, 2] = 0.5 * a0
    h3, h4, h5 = hermite_powers(hh)  # the compiled twin's (``_section.hermite_into``) powers
    c[:, 3] = (20 * dp - (8 * v1 + 12 * v0) * hh - (3 * a0 - a1) * hh**2) / (2 * h3)
    c[:, 4] = (-30 * dp + (14 * v1 + 16 * v0) * hh + (3 * a0 - 2 * a1) * hh**2) / (2 * h4)
    c[:, 5] = (12 * dp - 6 * (v1 + v0) * hh - (a0 - a1) * hh**2) / (2 * h5)
    return c


def segment_sources(x: np.ndarray, u: np.ndarray, line: np.ndarray, feed: np.ndarray):
    """Source line (block whose move contains the segment's end) and least feed of the
    moves each segment [x_k, x_k+1] overlaps; u (n,) node parameters."""
    from ._bspline import segment_sources_kernel

    return segment_sources_kernel(
        np.ascontiguousarray(x, dtype=float),
        np.ascontiguousarray(u, dtype=float),
        np.ascontiguousarray(line, dtype=np.int64),
        np.ascontiguousarray(feed, dtype=float),
    )


def range_min(a: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """min(a[lo_k..hi_k]) (inclusive) for every k, with a sparse table (vectorised)."""
    levels = [a]
    while (1 << len(levels)) <= a.size:
        h = 1 << (len(levels) - 1)
        prev = levels[-1]
        levels.append(np.minimum(prev[:-h], prev[h:]))
    length = hi - lo + 1
    lev = np.floor(np.log2(np.maximum(length, 1))).astype(np.int64)
    out = np.empty(lo.size)
    for k in np.unique(lev):
        sel = lev == k
        tab = levels[k]
        out[sel] = np.minimum(tab[lo[sel]], tab[hi[sel] - (1 << k) + 1])
    return out

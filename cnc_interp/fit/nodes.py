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


def turn_angles(v_in: np.ndarray, v_out: np.ndarray) -> np.ndarray:
    """Angle (rad) between direction vectors row by row; 0 where one is zero."""
    n1 = np.linalg.norm(v_in, axis=-1)
    n2 = np.linalg.norm(v_out, axis=-1)
    dot = (v_in * v_out).sum(axis=-1)
    cross = np.sqrt(np.maximum((n1 * n2) ** 2 - dot**2, 0.0))
    ang = np.arctan2(cross, dot)
    return np.where((n1 > 0) & (n2 > 0), ang, 0.0)


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
    """
    from . import _bspline as bs
    from ._section import SectionNodes, fit_section

    zero = np.zeros(nodes.shape[1])
    f64 = _kernel_array
    got = fit_section(
        SectionNodes(f64(nodes), f64(tol_mm), f64(line, dtype=np.int64), f64(feed)),
        bs.EndStates(
            f64(start.d1) if start is not None else zero,
            f64(start.d2) if start is not None else zero,
            f64(end.d1) if end is not None else zero,
            f64(end.d2) if end is not None else zero,
            0 if start is None else 1,
            0 if end is None else 1,
        ),
        section_params(tol_deg, lin, metric, tol_ref_mm),
    )
    return PieceFit(got.breaks, got.coef, got.line, got.feed, got.max_mm, got.max_deg, got.ok, int(nodes.shape[0]))


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
    c[:, 3] = (20 * dp - (8 * v1 + 12 * v0) * hh - (3 * a0 - a1) * hh**2) / (2 * hh**3)
    c[:, 4] = (-30 * dp + (14 * v1 + 16 * v0) * hh + (3 * a0 - 2 * a1) * hh**2) / (2 * hh**4)
    c[:, 5] = (12 * dp - 6 * (v1 + v0) * hh - (a0 - a1) * hh**2) / (2 * hh**5)
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

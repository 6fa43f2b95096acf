"""Corners and stops: where a feed run is split into paths planned from rest to rest.

A run is prepared (duplicate nodes merged, per-node tolerance resolved, curve
pieces re-indexed) and split at node j when

* the turn between the move into j and the move out of j is sharper than
  ``corner_deg`` (directions: chords, or a curve's exact end tangent);
* the move into or out of j is under ``G61`` (tolerance 0) and j is not collinear
  (so G61 gives exact straight lines with a stop at every real corner);
* one move moves linear axes and the other only rotary axes (the arc-length
  metric changes; a rotary-only path is measured in degrees).

Turn angles are measured in the fitter's metric (linear axes in mm, rotary axes
scaled to mm by ``tol_mm / tol_deg``) and, with rotary axes, also on the linear axes
alone. Nodes strictly inside a curve never split.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit

from ..constants import FIT_COLLINEAR_DEG, FIT_EXACT_CURVE_TOL_MM, LINEAR_AXES, LINEAR_MOTION_MIN_MM
from ..gcode.program import CurvePiece, Run
from ._npexact import pairwise_sum
from .blends import BlendTable


#: nodes closer than this (mm, combined metric) to the last node kept are merged before
#: fitting: half the finest tolerance the fit works to (``settings.FIT_TOL_MIN_MM``), far
#: below any printed quantum (6 decimals: 1e-6 mm), so no shape the fit could follow is
#: lost. At 1e-9 mm, ``o1 repeat [1000000] G91 G1 X0.000000001`` kept its million nodes,
#: one section of them: 2.25 GB to fit 0.001 mm of path
FIT_DUPLICATE_NODE_MM = 5e-7


@dataclass(frozen=True)
class PreparedRun:
    """A feed run ready to fit (N' nodes after merging duplicates).

    nodes (N', n), line/feed_mm_s (N',) of the move ending at each node (node 0
    repeats node 1), tol_mm (N',) resolved tolerance (0 = G61), curves re-indexed,
    lin (n,) linear axes, scale (n,) metric scale, rot_only (N'-1,) per move;
    blends: the blended corners (``add_blends``, a ``blends.BlendTable``); orig_index (N',): each row's node
    before blend points were inserted (-1 for an inserted point); stops: nodes where
    the path must stop (a repair's corner that cannot be blended).
    """

    axes: str
    nodes: np.ndarray
    line: np.ndarray
    feed_mm_s: np.ndarray
    tol_mm: np.ndarray
    curves: tuple[CurvePiece, ...]
    lin: np.ndarray
    scale: np.ndarray
    rot_only: np.ndarray
    blends: tuple | BlendTable = ()
    orig_index: np.ndarray | None = None
    stops: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    def __post_init__(self) -> None:
        if self.orig_index is None:
            object.__setattr__(self, "orig_index", np.arange(self.nodes.shape[0]))


@dataclass(frozen=True)
class SubRun:
    """Nodes i0..i1 (inclusive) of a prepared run, fitted as one path.

    kind: ``"straight"`` (collinear G61 moves: one exact line) or ``"fit"``;
    rotary: the path moves rotary axes only (metric in degrees); blends: the
    blended corners inside (``blends.Blend``), rows ``blend_range`` = (first, end) of
    the prepared run's table.
    """

    i0: int
    i1: int
    kind: str
    rotary: bool
    curves: tuple[CurvePiece, ...]
    blends: tuple | BlendTable = ()
    blend_range: tuple[int, int] = (0, 0)


def prepare_run(run: Run, settings) -> PreparedRun:
    """Merge duplicate nodes, resolve tolerances and re-index curve pieces."""
    nodes = np.asarray(run.nodes, dtype=float)
    lin = np.array([a in LINEAR_AXES for a in run.axes], dtype=bool)
    tol = settings.node_tolerance(run.tol_mm)
    if tol.size > 1:
        tol[0] = tol[1]
    # rotary axes count tol_ref / tol_deg mm per degree, tol_ref the run's largest
    # tolerance (the sub-runs' fit and measurement use theirs: the same where G64 P is
    # constant), so corners are judged in the metric the fit works in
    ref = float(tol.max()) if tol.size and tol.max() > 0 else settings.fit_tol_mm
    scale = np.where(lin, 1.0, ref / settings.fit_tol_deg)
    feed = np.asarray(run.feed_mm_s, dtype=float).copy()
    line = np.asarray(run.line, dtype=np.int64)
    n = nodes.shape[0]
    keep = _distinct_nodes(nodes * scale, FIT_DUPLICATE_NODE_MM)
    # a merged node keeps the last block's line/feed/tolerance (the move that ends there)
    new_index = np.cumsum(keep) - 1
    last_of = np.zeros(int(keep.sum()), dtype=np.int64)
    last_of[new_index] = np.arange(n)
    nodes_k = nodes[keep]
    if n >= 2 and not keep[-1]:
        nodes_k[-1] = nodes[-1]  # the run ends exactly on its programmed end point
    line_k, feed_k, tol_k = line[last_of], feed[last_of], tol[last_of]
    # the first node's line is the block that started the run
    line_k[0] = line[0]
    curves = []
    for cp in run.curves:
        first, last = int(new_index[cp.first]), int(new_index[cp.last])
        if last > first:
            curves.append(CurvePiece(first, last, cp.curve))
    d = np.diff(nodes_k, axis=0)
    lin_len = np.sqrt((d[:, lin] ** 2).sum(axis=1)) if lin.any() else np.zeros(len(d))
    rot_only = (lin_len <= LINEAR_MOTION_MIN_MM) & (~lin).any()
    if not (~lin).any():
        rot_only = np.zeros(len(d), dtype=bool)
    return PreparedRun(
        run.axes, nodes_k, line_k, feed_k, tol_k, tuple(sorted(curves, key=lambda c: c.first)), lin, scale, rot_only
    )


def _distinct_nodes(scaled: np.ndarray, threshold: float) -> np.ndarray:
    """``keep`` mask of the nodes ``(n, n_axes)`` farther than ``threshold`` from the last
    KEPT node (the first is always kept). Comparing with the previous raw node instead
    would drop a whole chain of sub-threshold steps and lose their sum."""
    n = scaled.shape[0]
    if n < 2:
        return np.ones(n, dtype=bool)
    step = np.linalg.norm(np.diff(scaled, axis=0), axis=1)
    keep = np.concatenate(([True], step > threshold))
    if keep.all():
        return keep
    return _distinct_nodes_seq(np.ascontiguousarray(scaled, dtype=np.float64), threshold)


def _distinct_nodes_seq(scaled: np.ndarray, threshold: float) -> np.ndarray:
    from ._dedup import distinct_nodes

    return distinct_nodes(scaled, threshold)


def corner_turns(pr: PreparedRun, evals: dict | None = None, arcs=None):
    """Turn angle (deg) at every node (n,) in the fitter's metric (and, with rotary axes,
    the larger of that and the linear axes' own turn), and the nodes strictly inside a
    curve (n,) bool. ``arcs`` (``curves.arc_table`` of ``pr.curves``, linear axes only)
    gives the end tangents of the curves it has."""
    from .curves import curve_eval, end_states

    d = pr.nodes.shape[1]
    K = len(pr.curves)
    first = np.fromiter((cp.first for cp in pr.curves), dtype=np.int64, count=K)
    last = np.fromiter((cp.last for cp in pr.curves), dtype=np.int64, count=K)
    if arcs is not None:
        t0 = np.ascontiguousarray(arcs.ends[:, 0], dtype=float)
        t1 = np.ascontiguousarray(arcs.ends[:, 2], dtype=float)
        todo = np.nonzero(~np.asarray(arcs.ok, dtype=bool))[0].tolist()
    else:
        t0 = np.zeros((K, d))
        t1 = np.zeros((K, d))
        todo = range(K)
    for k in todo:
        (t0[k], _), (t1[k], _) = end_states(curve_eval(pr.curves[k].curve, evals), pr.scale)
    nodes = np.ascontiguousarray(pr.nodes, dtype=float)
    scale = np.ascontiguousarray(pr.scale, dtype=float)
    inside = _inside_curves(nodes.shape[0], first, last)
    turn = _turns(nodes, scale, first, last, t0, t1, np.ones(d, dtype=bool))
    if (~pr.lin).any() and pr.lin.any():
        # the tool's own path (linear axes) must not turn sharply either, however much
        # the rotary axes move: a corner there would be a near-stop of the arc length s
        turn = np.maximum(turn, _turns(nodes, scale, first, last, t0, t1, np.asarray(pr.lin, dtype=bool)))
    return turn, inside


def _turns(nodes, scale, first, last, t0, t1, axes) -> np.ndarray:
    """``corner_turns``' angles (deg) over the axes ``axes`` (d,) bool between the chords in
    and out of each node (a curve's end tangents at its ends): arctan2(|d_in x d_out|,
    d_in . d_out), 0 where either is zero. The arctangent is numpy's (the C library's
    differs in the last bit), so the angles are those of the same formula in numpy."""
    cross, dot, ok = _turn_parts(nodes, scale, first, last, t0, t1, axes, bool(axes.all()))
    return np.degrees(np.where(ok, np.arctan2(cross, dot), 0.0))


@njit(cache=True, nogil=True)
def _inside_curves(n, first, last):
    """(n,) bool: the nodes strictly inside a curve (first[k] < i < last[k])."""
    inside = np.zeros(n, dtype=np.bool_)
    for k in range(first.shape[0]):
        for i in range(first[k] + 1, last[k]):
            inside[i] = True
    return inside


@njit(cache=True, nogil=True)
def _turn_parts(nodes, scale, first, last, t0, t1, axes, pairwise):
    """Per node (n,): |d_in x d_out| (as sqrt(max(|d_in|² |d_out|² - dot², 0))), d_in . d_out
    and whether both are nonzero, with numpy's arithmetic for that formula. d_in/d_out: the
    chords of ``nodes * scale`` into and out of each node (zero at the run's ends), replaced
    at a curve's first node (d_out = t0) and last node (d_in = t1). ``pairwise``: numpy sums
    a contiguous row pairwise (``pairwise_sum``), but the rows of a column selection
    (``d_in[:, lin]``, laid out column by column) left to right; the two differ from 8
    terms on."""
    n, d = nodes.shape
    cross = np.zeros(n)
    dot = np.zeros(n)
    ok = np.zeros(n, dtype=np.bool_)
    # the tangent override of each node, if any (-1: the chord)
    out_of = np.full(n, -1, dtype=np.int64)
    in_of = np.full(n, -1, dtype=np.int64)
    for k in range(first.shape[0]):
        out_of[first[k]] = k
        in_of[last[k]] = k
    vi = np.zeros(d)
    vo = np.zeros(d)
    b1 = np.empty(d)
    b2 = np.empty(d)
    b3 = np.empty(d)
    for i in range(n):
        for a in range(d):
            if in_of[i] >= 0:
                vi[a] = t1[in_of[i], a]
            elif i > 0:
                vi[a] = nodes[i, a] * scale[a] - nodes[i - 1, a] * scale[a]
            else:
                vi[a] = 0.0
            if out_of[i] >= 0:
                vo[a] = t0[out_of[i], a]
            elif i < n - 1:
                vo[a] = nodes[i + 1, a] * scale[a] - nodes[i, a] * scale[a]
            else:
                vo[a] = 0.0
        m = 0
        for a in range(d):
            if axes[a]:
                b1[m] = vi[a] * vi[a]
                b2[m] = vo[a] * vo[a]
                b3[m] = vi[a] * vo[a]
                m += 1
        if pairwise:
            s1 = pairwise_sum(b1, 0, m)
            s2 = pairwise_sum(b2, 0, m)
            p = pairwise_sum(b3, 0, m)
        else:
            s1 = 0.0
            s2 = 0.0
            p = 0.0
            for a in range(m):
                s1 += b1[a]
                s2 += b2[a]
                p += b3[a]
        n1 = np.sqrt(s1)
        n2 = np.sqrt(s2)
        nn = n1 * n2
        c = nn * nn - p * p
        cross[i] = np.sqrt(c if c > 0.0 else 0.0)
        dot[i] = p
        ok[i] = n1 > 0.0 and n2 > 0.0
    return cross, dot, ok


def split_run(pr: PreparedRun, settings, evals: dict | None = None, arcs=None) -> Iterator[SubRun]:
    """Cut a prepared run into sub-runs at corners, G61 nodes and metric changes; a
    blended corner (``pr.blends``) does not cut. The sub-runs are made one at a time, in
    path order (a long run has 10⁴ of them).

    ``evals`` optionally shares each curve's ``CurveEval`` with the fitter; ``arcs`` see
    ``corner_turns``."""
    n = pr.nodes.shape[0]
    if n < 2:
        return
    turn, inside = corner_turns(pr, evals, arcs)
    cut = np.zeros(n, dtype=bool)
    j = np.arange(1, n - 1)
    tol_move = pr.tol_mm  # tolerance of the move ending at each node
    g61 = (tol_move[j] == 0) | (tol_move[j + 1] == 0)
    cut[j] = (turn[j] > settings.corner_deg) | (g61 & (turn[j] > FIT_COLLINEAR_DEG))
    cut[j] |= pr.rot_only[j - 1] != pr.rot_only[j]
    cut &= ~inside
    corner = np.asarray(pr.blends.i, dtype=np.int64) + 1 if len(pr.blends) else np.zeros(0, dtype=np.int64)
    cut[corner] = False
    stops = pr.stops[(pr.stops > 0) & (pr.stops < n - 1)]
    cut[stops[~inside[stops]]] = True
    edges = np.concatenate(([0], np.nonzero(cut)[0], [n - 1]))
    # curves never straddle a cut (their inner nodes do not split): sub-run of each curve
    firsts = np.array([c.first for c in pr.curves], dtype=np.int64)
    owner = np.searchsorted(edges, firsts, side="right") - 1
    by_sub: dict[int, list] = {}
    for c, o in zip(pr.curves, owner):
        by_sub.setdefault(int(o), []).append(c)
    # blends are in path order: each sub-run's are a range of the table
    bl_owner = np.searchsorted(edges, corner, side="right") - 1
    n_sub = edges.size - 1
    bl_lo = np.searchsorted(bl_owner, np.arange(n_sub), side="left").tolist()
    bl_hi = np.searchsorted(bl_owner, np.arange(n_sub), side="right").tolist()
    zero = pr.tol_mm == 0
    n_zero = np.concatenate(([0], np.cumsum(zero)))
    for k, (a, b) in enumerate(zip(edges[:-1].tolist(), edges[1:].tolist())):
        cs = tuple(by_sub.get(k, ()))
        bs = pr.blends[bl_lo[k] : bl_hi[k]] if bl_hi[k] > bl_lo[k] else ()
        exact = not cs and not bs and (n_zero[b + 1] - n_zero[a + 1]) == b - a
        yield SubRun(a, b, "straight" if exact else "fit", bool(pr.rot_only[a]), cs, bs, (bl_lo[k], bl_hi[k]))


def slice_run(pr: PreparedRun, first: int, last: int) -> PreparedRun:
    """Nodes ``first..last`` of ``pr`` (without blends; curves inside re-indexed; stops
    inside kept) as a prepared run of their own: a sub-run's repair works on it alone."""
    sl = slice(first, last + 1)
    curves = tuple(
        CurvePiece(cp.first - first, cp.last - first, cp.curve)
        for cp in pr.curves
        if first <= cp.first and cp.last <= last
    )
    stops = pr.stops[(pr.stops > first) & (pr.stops < last)] - first
    return PreparedRun(
        pr.axes,
        pr.nodes[sl],
        pr.line[sl],
        pr.feed_mm_s[sl],
        pr.tol_mm[sl],
        curves,
        pr.lin,
        pr.scale,
        pr.rot_only[first:last],
        stops=stops,
    )


def add_blends(
    pr: PreparedRun, settings, evals: dict | None = None, force: np.ndarray | None = None, arcs=None
) -> PreparedRun:
    """``pr`` with its sharp corners blended (``blends.py``): a node at each blend's
    start and end is inserted on the two moves (taking that move's line, feed and
    tolerance), and ``blends`` lists them. A corner is a candidate when it turns more
    than ``corner_deg`` (or ``force`` (n,) marks it), both its moves are straight (no
    exact curve) and within one metric, and neither is under G61. ``arcs`` see
    ``corner_turns``."""
    from .blends import blend_piece, plan_blends

    n = pr.nodes.shape[0]
    if n < 3:
        return pr if force is None else replace(pr, stops=np.nonzero(force)[0])
    turn, inside = corner_turns(pr, evals, arcs)
    cand = turn > settings.corner_deg
    if force is not None:
        cand |= force & (turn > FIT_COLLINEAR_DEG)
    cand[0] = cand[-1] = False
    j = np.arange(1, n - 1)
    cand[j] &= (pr.tol_mm[j] > 0) & (pr.tol_mm[j + 1] > 0) & (pr.rot_only[j - 1] == pr.rot_only[j])
    for cp in pr.curves:  # the moves into and out of a corner must be straight
        cand[cp.first : cp.last + 1] = False
    # forced nodes that cannot be blended are stops
    no_blend = np.zeros(n, dtype=bool) if force is None else force.copy()
    if not cand.any():
        return replace(pr, stops=np.nonzero(no_blend)[0])
    scaled = pr.nodes * pr.scale
    tol_rot = settings.fit_tol_deg * float(pr.scale[~pr.lin].max()) if (~pr.lin).any() else np.inf
    ok, dist, shape = plan_blends(
        scaled, pr.lin, pr.tol_mm, cand, force, tol_rot_scaled=tol_rot, step_mm=settings.period_step_mm
    )
    no_blend &= ~ok
    corners = np.nonzero(ok)[0]
    if corners.size == 0:
        return replace(pr, stops=np.nonzero(no_blend)[0])
    chords = np.diff(scaled, axis=0)
    clen = np.linalg.norm(chords, axis=1)
    # new rows on move m (node m -> m+1): the end of the blend at m (dist[m] after node m)
    # and the start of the blend at m+1 (dist[m+1] before node m+1); one shared point where
    # the two meet (both at the move's middle)
    f_end = np.where(ok[:-1], dist[:-1] / clen, -1.0)  # fraction along move m, or none
    f_start = np.where(ok[1:], 1.0 - dist[1:] / clen, -1.0)
    shared = (f_end >= 0) & (f_start >= 0) & (f_start - f_end <= 1e-12)
    has_end = f_end >= 0
    has_start = (f_start >= 0) & ~shared
    extra = np.concatenate((has_end.astype(np.int64) + has_start, [0]))
    new_index = np.concatenate(([0], np.cumsum(1 + extra)[:-1]))
    total = int(new_index[-1]) + 1
    # each row: a point on move src -> src + 1 at fraction frac (0: the programmed node)
    src = np.empty(total, dtype=np.int64)
    frac = np.zeros(total)
    take = np.empty(total, dtype=np.int64)  # row of line / feed / tol it takes
    src[new_index] = np.arange(n)
    take[new_index] = np.arange(n)
    at_end = np.full(n, -1, dtype=np.int64)  # row of the blend-at-m's end point
    at_start = np.full(n, -1, dtype=np.int64)  # row of the blend-at-m's start point
    m = np.nonzero(has_end)[0]
    at_end[m] = new_index[m] + 1
    src[at_end[m]] = m
    frac[at_end[m]] = np.where(shared[m], 0.5, f_end[m])
    m = np.nonzero(has_start)[0]
    rows = new_index[m] + 1 + has_end[m]
    at_start[m + 1] = rows
    src[rows] = m
    frac[rows] = f_start[m]
    m = np.nonzero(shared)[0]
    at_start[m + 1] = at_end[m]
    inserted = frac > 0
    take[inserted] = src[inserted] + 1  # a point on move m -> m+1 takes that move's data
    nodes = pr.nodes[src].copy()
    k = np.nonzero(inserted)[0]
    nodes[k] += (pr.nodes[src[k] + 1] - pr.nodes[src[k]]) * frac[k, None]
    ia, ib = at_start[corners], at_end[corners]
    t_in = chords[corners - 1] / clen[corners - 1, None]
    t_out = chords[corners] / clen[corners, None]
    coef, h = blend_piece(nodes[ia], nodes[ib], t_in, t_out, dist[corners], shape[corners], pr.scale)
    feed = np.minimum(pr.feed_mm_s[corners], pr.feed_mm_s[corners + 1])
    blends = BlendTable(ia.astype(np.int64), h, coef, pr.line[corners], feed, t_in, t_out)
    curves = tuple(CurvePiece(int(new_index[cp.first]), int(new_index[cp.last]), cp.curve) for cp in pr.curves)
    rot_only = pr.rot_only[take[1:] - 1]
    orig = np.full(nodes.shape[0], -1, dtype=np.int64)
    orig[new_index] = np.arange(n)
    return PreparedRun(
        pr.axes,
        nodes,
        pr.line[take],
        pr.feed_mm_s[take],
        pr.tol_mm[take],
        curves,
        pr.lin,
        pr.scale,
        rot_only,
        blends,
        orig,
        new_index[np.nonzero(no_blend)[0]],
    )


def fit_tolerance(tol_mm: np.ndarray) -> np.ndarray:
    """Tolerances the fitter works with: G61's 0 becomes ``FIT_EXACT_CURVE_TOL_MM``."""
    return np.where(tol_mm > 0, tol_mm, FIT_EXACT_CURVE_TOL_MM)

"""Distance from the PROGRAMMED path to the fitted path, everywhere (not only at nodes).

The programmed geometry of a sub-run is its G1 moves (straight segments between
the nodes) and its exact curves (``CurvePiece``: arcs, helices, NURBS, splines).
Both are sampled densely — every move at a number of points proportional to its
length over the fitted path's typical knot spacing (``PATH_DEV_SAMPLES_PER_SPAN``
per span, between ``PATH_DEV_MIN_SAMPLES`` and ``PATH_DEV_MAX_SAMPLES`` per move),
every curve likewise from its exact geometry — and each sample is projected onto
the fitted path by a compiled marching projection (``_project.py``): samples and
segments are both in path order, so each foot point is searched from the previous
one (Newton, sliding on to the next segment while the distance still falls), with a
wider search for the samples that come out farther than ``PATH_DEV_LOCAL_FRAC`` of
their tolerance. Every distance is that of an actual point of the fitted path, so
a missed foot point can only over-estimate a deviation (conservative).

This is an independent measurement: it uses neither the fitter's node parameters
nor its check points. Distances are Euclidean over the linear axes (mm);
``rotary_path_deviation`` measures the runs whose rotary axes move.
"""

from __future__ import annotations

import numpy as np


#: path deviation: samples of the programmed path per typical fitted knot span
PATH_DEV_SAMPLES_PER_SPAN = 4

#: path deviation: fewest / most samples of one programmed move (or per node of a curve)
PATH_DEV_MIN_SAMPLES = 3

PATH_DEV_MAX_SAMPLES = 64

#: path deviation: coarse samples per fitted segment before Newton (a segment entered afresh)
PATH_DEV_FIT_SAMPLES = 8

#: path deviation: Newton steps of the projection onto the fitted path
PATH_DEV_NEWTON_ITERS = 8

#: path deviation: a marched distance above this share of the tolerance is searched
#: again among the segments nearby along the path (beyond the tolerance: farther)
PATH_DEV_LOCAL_FRAC = 0.5

#: path deviation: reach of that second search along the path, in sample spacings each side
PATH_DEV_WINDOW = 8

#: path deviation: reach of the search for a point beyond its tolerance, in sample spacings
PATH_DEV_FAR_WINDOW = 256


def distance_to_pieces(
    breaks: np.ndarray,
    coef: np.ndarray,
    points: np.ndarray,
    mask: np.ndarray,
    tol: np.ndarray | None = None,
    spacing: float | None = None,
) -> np.ndarray:
    """Distance (K,) over the axes ``mask`` (n,) from points (K, n), in path order, to the
    piecewise quintic (breaks (S+1,), coef (S, 6, n), local parameter t = u - breaks[k]);
    see ``project_onto_pieces``."""
    return project_onto_pieces(breaks, coef, points, mask, tol, spacing)[0]


def project_onto_pieces(
    breaks: np.ndarray,
    coef: np.ndarray,
    points: np.ndarray,
    mask: np.ndarray,
    tol: np.ndarray | None = None,
    spacing: float | None = None,
):
    """Distance (K,) over the axes ``mask`` from points (K, n), in path order, to the pieces,
    and the foot points: their piece (K,) and local parameter (K,).

    A marching projection (``_project.march_feet``): the foot point of each point
    is searched from the previous one's; points farther than ``PATH_DEV_LOCAL_FRAC`` x
    their tolerance ``tol`` (K,) are searched again among the pieces within
    ``PATH_DEV_WINDOW`` x ``spacing`` (u units, the samples' spacing) along the path,
    and beyond their tolerance within ``PATH_DEV_FAR_WINDOW`` x ``spacing``. Each
    result is the distance to an actual point of the path, so a missed foot point can
    only OVER-estimate the distance (never report a deviation as smaller than it is).
    Without ``tol`` every point gets the wider searches; without ``spacing`` they
    reach every piece (the distance to the whole path as a set).
    """
    from ._project import march_feet

    if points.shape[0] == 0:
        return np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(0)
    if tol is None:
        tol = np.zeros(points.shape[0])
    near = far = np.inf
    if spacing is not None:
        near, far = PATH_DEV_WINDOW * spacing, PATH_DEV_FAR_WINDOW * spacing
    return march_feet(
        np.ascontiguousarray(coef[:, :, mask], dtype=float),
        np.ascontiguousarray(np.diff(breaks), dtype=float),
        np.ascontiguousarray(points[:, mask], dtype=float),
        np.ascontiguousarray(tol, dtype=float),
        PATH_DEV_LOCAL_FRAC,
        float(near),
        float(far),
        PATH_DEV_FIT_SAMPLES,
        PATH_DEV_NEWTON_ITERS,
    )


def programmed_samples(nodes: np.ndarray, tol_mm: np.ndarray, curves, i0: int, spacing: float):
    """Dense samples of the programmed path through ``nodes`` (n, d) (sub-run nodes i0..),
    in path order.

    Moves inside a curve (``curves``: CurvePiece with run indices) are replaced by the
    exact curve. ``tol_mm`` (n,) is the tolerance of the move ending at each node.
    Returns (points (K, d), tolerance (K,)).
    """
    from ._project import line_samples
    from .curves import CurveEval

    n, d = nodes.shape
    in_curve = np.zeros(max(n - 1, 0), dtype=np.bool_)
    pts, tols, keys = [], [], []
    for cp in curves:
        a, b = cp.first - i0, cp.last - i0
        in_curve[a:b] = True
        ev = CurveEval(cp.curve)
        clen = float(np.linalg.norm(np.diff(nodes[a : b + 1], axis=0), axis=1).sum())
        k = int(np.clip(np.ceil(clen / spacing), PATH_DEV_MIN_SAMPLES * (b - a), PATH_DEV_MAX_SAMPLES * (b - a)))
        w = np.linspace(ev.w0, ev.w1, k + 1)
        pts.append(ev.points(w))
        tols.append(np.full(k + 1, float(tol_mm[b])))
        keys.append(a + np.linspace(0.0, 0.5, k + 1))
    # the moves (a numba kernel: this runs on every fitted sub-run)
    lp, lt, lk = line_samples(
        np.ascontiguousarray(nodes, dtype=float),
        np.ascontiguousarray(tol_mm, dtype=float),
        in_curve,
        float(spacing),
        PATH_DEV_MIN_SAMPLES,
        PATH_DEV_MAX_SAMPLES,
    )
    if not pts:
        return lp, lt  # already in path order
    pts.append(lp)
    tols.append(lt)
    keys.append(lk)
    order = np.argsort(np.concatenate(keys), kind="stable")
    return np.concatenate(pts)[order], np.concatenate(tols)[order]


def deviation_settings():
    """This module's PATH_DEV_* knobs as the compiled measurement's ``DeviationSettings``."""
    from ._linedev import DeviationSettings

    return DeviationSettings(
        samples_per_span=PATH_DEV_SAMPLES_PER_SPAN,
        min_samples=PATH_DEV_MIN_SAMPLES,
        max_samples=PATH_DEV_MAX_SAMPLES,
        local_frac=PATH_DEV_LOCAL_FRAC,
        window=PATH_DEV_WINDOW,
        far_window=PATH_DEV_FAR_WINDOW,
        n_coarse=PATH_DEV_FIT_SAMPLES,
        iters=PATH_DEV_NEWTON_ITERS,
    )


def polyline_deviation(breaks: np.ndarray, coef: np.ndarray, nodes: np.ndarray, tol_mm: np.ndarray, lin: np.ndarray):
    """``path_deviation`` for a sub-run of G1 moves only (no curves), in one compiled call
    (``_linedev``): the same samples, search and result, without the Python glue that
    dominates on programs of many short paths."""
    from ._linedev import polyline_path_deviation

    cfg = deviation_settings()
    breaks = np.ascontiguousarray(breaks, dtype=float)
    return polyline_path_deviation(breaks, np.ascontiguousarray(coef, dtype=float), nodes, tol_mm, lin, cfg)


def _sample_spacing(breaks: np.ndarray) -> float:
    """Spacing of the programmed samples: |dq/du| ≈ 1, so a typical knot span in mm,
    sampled ``PATH_DEV_SAMPLES_PER_SPAN`` times."""
    from ._project import median

    return max(median(np.diff(breaks)), 1e-9) / PATH_DEV_SAMPLES_PER_SPAN


def path_deviation(
    breaks: np.ndarray, coef: np.ndarray, nodes: np.ndarray, tol_mm: np.ndarray, lin: np.ndarray, curves=(), i0: int = 0
):
    """Worst distance of the programmed path (nodes (n, d) with ``curves``) to the fitted
    pieces, over the linear axes ``lin``: (max distance mm, max distance / tolerance)."""
    if not lin.any() or nodes.shape[0] < 2:
        return 0.0, 0.0
    spacing = _sample_spacing(breaks)
    pts, tol = programmed_samples(nodes, tol_mm, curves, i0, spacing)
    dist = distance_to_pieces(breaks, coef, pts, lin, tol, spacing)
    if dist.size == 0:
        return 0.0, 0.0
    ratio = dist / np.maximum(tol, 1e-300)
    return float(dist.max()), float(ratio.max())


def rotary_path_deviation(
    breaks: np.ndarray,
    coef: np.ndarray,
    nodes: np.ndarray,
    tol_mm: np.ndarray,
    tol_deg: float,
    lin: np.ndarray,
    moving: np.ndarray,
    curves=(),
    i0: int = 0,
    tol_ref: float | None = None,
) -> float:
    """Worst deviation of the programmed path from the fit where rotary axes move, over
    the tolerance (<= 1 is within); ``moving`` (d,) marks the axes that move.

    Without linear motion: the distance over the rotary axes (deg) against ``tol_deg``.
    Otherwise each programmed sample is projected onto the fit in a space where every
    rotary axis is scaled by tol_mm / tol_deg, and at that foot point (a real point of
    the fit) the position and every rotary axis are compared with their own
    tolerances: the ratio is max(|Δ position| / tol_mm, |Δ rotary| / tol_deg). A ratio
    r <= 1 thus means one point of the fit lies within r·tol_mm in position and r·tol_deg
    in each rotary axis: the tool's position and orientation there are both within
    their tolerances. A missed foot point can only over-estimate the ratio.
    """
    if not (moving & ~lin).any() or nodes.shape[0] < 2:
        return 0.0
    rot = ~lin
    if not (moving & lin).any():
        tol = np.full(nodes.shape[0], float(tol_deg))
        if curves:
            return path_deviation(breaks, coef, nodes, tol, rot, curves, i0)[1]
        return polyline_deviation(breaks, coef, nodes, tol, rot)[1]
    spacing = _sample_spacing(breaks)
    pts, tol = programmed_samples(nodes, tol_mm, curves, i0, spacing)
    if pts.shape[0] == 0:
        return 0.0
    # the projection's metric: rotary axes scaled by the largest linear tolerance (or
    # ``tol_ref``, that of the whole sub-run a part of it is measured for) over tol_deg
    ref = float(np.max(tol)) if tol_ref is None else float(tol_ref)
    s_path = np.where(rot, ref / float(tol_deg), 1.0)
    _, kf, tf = project_onto_pieces(breaks, coef * s_path, pts * s_path, np.ones_like(lin), tol, spacing)
    c = coef[kf]  # (K, 6, d)
    q = c[:, 5]
    for i in range(4, -1, -1):
        q = q * tf[:, None] + c[:, i]
    diff = q - pts
    r_lin = np.sqrt((diff[:, lin] ** 2).sum(axis=1)) / np.maximum(tol, 1e-300)
    r_rot = np.abs(diff[:, rot]).max(axis=1) / float(tol_deg)
    return float(np.maximum(r_lin, r_rot).max())

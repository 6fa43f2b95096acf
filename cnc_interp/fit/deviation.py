"""Distance from the PROGRAMMED path to the fitted path, everywhere (not only at nodes).

The programmed geometry of a sub-run is its G1 moves (straight segments between
the nodes) and its exact curves (``CurvePiece``: arcs, helices, NURBS, splines).
Both are sampled densely — every move at a number of points proportional to its
length over the fitted path's typical knot spacing (``PATH_DEV_SAMPLES_PER_SPAN``
per span, between ``PATH_DEV_MIN_SAMPLES`` and ``PATH_DEV_MAX_SAMPLES`` per move),
every curve likewise from its exact geometry — and each sample is projected onto
the fitted path: the nearest of a dense sampling of the path (KD-tree), then
Newton on the squared distance in that segment and its two neighbours.

Distances are Euclidean over the linear axes (mm). Everything is vectorised.
"""

from __future__ import annotations

import numpy as np

from ..constants import (
    PATH_DEV_PARAM_WEIGHT,
    PATH_DEV_CANDIDATES,
    PATH_DEV_FIT_SAMPLES,
    PATH_DEV_MAX_SAMPLES,
    PATH_DEV_MIN_SAMPLES,
    PATH_DEV_NEWTON_ITERS,
    PATH_DEV_SAMPLES_PER_SPAN,
)


def _eval(coef_k: np.ndarray, t: np.ndarray, d: int) -> np.ndarray:
    """d-th derivative (K, n) of rows coef_k (K, 6, n) at local parameters t (K,)."""
    acc = np.zeros((t.size, coef_k.shape[2]))
    for i in range(5, d - 1, -1):
        f = 1.0
        for m in range(d):
            f *= i - m
        acc = acc * t[:, None] + coef_k[:, i, :] * f
    return acc


def distance_to_pieces(breaks: np.ndarray, coef: np.ndarray, points: np.ndarray,
                       mask: np.ndarray, spacing: float | None = None,
                       along: np.ndarray | None = None) -> np.ndarray:
    """Distance (K,) over the axes ``mask`` (n,) from points (K, n) to the piecewise
    quintic (breaks (S+1,), coef (S, 6, n), local parameter t = u - breaks[k]).

    Each result is the distance to an actual point of the path, so it never
    underestimates; the search (nearest ``PATH_DEV_CANDIDATES`` path samples, Newton in
    their segments and neighbours) makes it the true distance in practice.
    ``spacing`` (u units) bounds the sample spacing on long segments; ``along`` (K,)
    optionally gives the travelled length of each point along its own (programmed)
    path, in path order, to guide the search.
    """
    from scipy.spatial import cKDTree

    if points.shape[0] == 0:
        return np.zeros(0)
    c_all = coef[:, :, mask]
    pts = points[:, mask]
    h = np.diff(breaks)
    n_seg = h.size
    m = np.full(n_seg, PATH_DEV_FIT_SAMPLES, dtype=np.int64)
    if spacing is not None and spacing > 0:
        m = np.clip(np.ceil(h / spacing), PATH_DEV_FIT_SAMPLES, 8 * PATH_DEV_MAX_SAMPLES).astype(np.int64)
    seg = np.repeat(np.arange(n_seg), m + 1)
    starts = np.cumsum(m + 1) - (m + 1)
    t = (np.arange(seg.size) - starts[seg]) / m[seg] * h[seg]
    q = _eval(c_all[seg], t, 0)
    k_nn = min(PATH_DEV_CANDIDATES, q.shape[0])
    # search in (position, PATH_DEV_PARAM_WEIGHT x travelled length): the foot point lies
    # near the same share of the path's length, which keeps the search off other
    # parts of the path that pass close by (helix turns, a contour's second pass)
    sig = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(q, axis=0), axis=1))))
    lam = PATH_DEV_PARAM_WEIGHT
    if along is None:
        along = np.zeros(pts.shape[0])
        lam = 0.0
    else:
        along = along * (sig[-1] / along[-1] if along[-1] > 0 else 1.0)
    _, idx = cKDTree(np.column_stack((q, lam * sig))).query(np.column_stack((pts, lam * along)), k=k_nn)
    idx = idx.reshape(pts.shape[0], k_nn)
    from ._bspline import project_points

    return project_points(np.ascontiguousarray(c_all), np.ascontiguousarray(h, dtype=float),
                          np.ascontiguousarray(pts, dtype=float), np.ascontiguousarray(seg[idx]),
                          np.ascontiguousarray(t[idx]), PATH_DEV_NEWTON_ITERS)


def programmed_samples(nodes: np.ndarray, tol_mm: np.ndarray, curves, i0: int, spacing: float):
    """Dense samples of the programmed path through ``nodes`` (n, d) (sub-run nodes i0..),
    in path order.

    Moves inside a curve (``curves``: CurvePiece with run indices) are replaced by the
    exact curve. ``tol_mm`` (n,) is the tolerance of the move ending at each node.
    Returns (points (K, d), tolerance (K,), travelled length (K,) over all axes).
    """
    from .curves import CurveEval

    n, d = nodes.shape
    in_curve = np.zeros(max(n - 1, 0), dtype=bool)
    pts, tols, keys = [], [], []
    for cp in curves:
        a, b = cp.first - i0, cp.last - i0
        in_curve[a:b] = True
        ev = CurveEval(cp.curve)
        clen = float(np.linalg.norm(np.diff(nodes[a:b + 1], axis=0), axis=1).sum())
        k = int(np.clip(np.ceil(clen / spacing), PATH_DEV_MIN_SAMPLES * (b - a),
                        PATH_DEV_MAX_SAMPLES * (b - a)))
        w = np.linspace(ev.w0, ev.w1, k + 1)
        pts.append(ev.points(w))
        tols.append(np.full(k + 1, float(tol_mm[b])))
        keys.append(a + np.linspace(0.0, 0.5, k + 1))
    lines = np.nonzero(~in_curve)[0]
    if lines.size:
        p0, p1 = nodes[lines], nodes[lines + 1]
        clen = np.linalg.norm(p1 - p0, axis=1)
        cnt = np.clip(np.ceil(clen / spacing), PATH_DEV_MIN_SAMPLES, PATH_DEV_MAX_SAMPLES).astype(np.int64)
        which = np.repeat(np.arange(lines.size), cnt + 1)
        starts = np.cumsum(cnt + 1) - (cnt + 1)
        f = (np.arange(which.size) - starts[which]) / cnt[which]
        # a move's start is the previous move's end: sample it once
        first = (f == 0.0) & (lines[which] > 0) & ~in_curve[np.maximum(lines[which] - 1, 0)]
        which, f = which[~first], f[~first]
        pts.append(p0[which] + (p1 - p0)[which] * f[:, None])
        tols.append(tol_mm[lines + 1][which])
        keys.append(lines[which] + 0.5 * f)
    if not pts:
        return np.zeros((0, d)), np.zeros(0), np.zeros(0)
    order = np.argsort(np.concatenate(keys), kind="stable")
    p = np.concatenate(pts)[order]
    along = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))))
    return p, np.concatenate(tols)[order], along


def path_deviation(breaks: np.ndarray, coef: np.ndarray, nodes: np.ndarray, tol_mm: np.ndarray,
                   lin: np.ndarray, curves=(), i0: int = 0):
    """Worst distance of the programmed path (nodes (n, d) with ``curves``) to the fitted
    pieces, over the linear axes ``lin``: (max distance mm, max distance / tolerance)."""
    if not lin.any() or nodes.shape[0] < 2:
        return 0.0, 0.0
    h = np.diff(breaks)
    # |dq/du| ≈ 1: a typical knot span in mm, sampled PATH_DEV_SAMPLES_PER_SPAN times
    spacing = max(float(np.median(h)), 1e-9) / PATH_DEV_SAMPLES_PER_SPAN
    pts, tol, along = programmed_samples(nodes, tol_mm, curves, i0, spacing)
    dist = distance_to_pieces(breaks, coef, pts, lin, spacing, along)
    if dist.size == 0:
        return 0.0, 0.0
    ratio = dist / np.maximum(tol, 1e-300)
    return float(dist.max()), float(ratio.max())

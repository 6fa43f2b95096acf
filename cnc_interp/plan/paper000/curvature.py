"""Curvature peaks (paper 000 Eq. 3) and the per-segment joint-space geometry.

Planar segments (``path.planar``): the curvature of p_k(x*) is
kappa = |p''| / (1 + p'^2)^(3/2) (Eq. 4 without V_T^2, invariant under the rotation),
and its extrema are the roots of Eq. 3 (corrected): (1 + p'^2) p''' - 3 p' p''^2 = 0.
The roots in [0, x_end] are found by sign changes on a grid and bisection
(vectorised over segments); the peak is the largest kappa at the roots, the grid
points and the segment ends.

General parametric paths: kappa(u)^2 = (|q_u|^2 |q_uu|^2 - (q_u . q_uu)^2) / |q_u|^6 in the
path's arc-length metric; the largest grid value per segment is refined by a
vectorised golden-section search.

``segment_geometry`` also returns, per segment and joint, the maxima of |dq/ds|,
|d2q/ds2|, |d3q/ds3| (joint space), from which ``limits`` derives the tangential
limits, and the jumps of dq/ds and d2q/ds2 at the junctions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


#: geometry samples per segment when taking the maxima of |q'|, |q''|, |q'''|
P000_GEOM_SAMPLES = 33

#: safety factor applied to those sampled maxima (grid may miss a peak slightly)
P000_GEOM_MARGIN = 1.0

#: golden-section iterations refining a numerical curvature peak
P000_CURV_REFINE_ITERS = 30


_GOLD = 0.5 * (np.sqrt(5.0) - 1.0)


def _pder(c: np.ndarray, d: int) -> np.ndarray:
    """d-th derivative of ascending polynomial coefficients along the last axis."""
    for _ in range(d):
        n = c.shape[-1]
        c = c[..., 1:] * np.arange(1, n)
        if c.shape[-1] == 0:
            c = np.zeros(c.shape[:-1] + (1,))
    return c


def _peval(c: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Evaluate ascending coefficients c (n, m) at x (n, K) with Horner."""
    acc = np.broadcast_to(c[:, -1:], x.shape).copy()
    for i in range(c.shape[1] - 2, -1, -1):
        acc = acc * x + c[:, i : i + 1]
    return acc


def planar_curvature_peaks(
    p: np.ndarray, x_end: np.ndarray, n_grid: int = 64, n_bisect: int = 60
) -> tuple[np.ndarray, np.ndarray]:
    """Peak curvature of each planar quintic segment from the roots of Eq. 3.

    Args:
        p: (n_seg, 6) ascending coefficients of p_k(x*), mm.
        x_end: (n_seg,) end abscissa of each segment in its rotated frame, mm.
    Returns:
        kappa_max (n_seg,) in 1/mm and the abscissa x* (n_seg,) where it occurs.
    """
    p = np.asarray(p, dtype=float)
    x_end = np.asarray(x_end, dtype=float)
    p1, p2, p3 = _pder(p, 1), _pder(p, 2), _pder(p, 3)

    def eq3(x):
        d1, d2, d3 = _peval(p1, x), _peval(p2, x), _peval(p3, x)
        return (1.0 + d1 * d1) * d3 - 3.0 * d1 * d2 * d2

    def kappa(x):
        d1, d2 = _peval(p1, x), _peval(p2, x)
        return np.abs(d2) / (1.0 + d1 * d1) ** 1.5

    n = p.shape[0]
    x = x_end[:, None] * np.linspace(0.0, 1.0, n_grid)[None, :]
    f = eq3(x)
    k_grid = kappa(x)
    # sign changes of Eq. 3 between grid points bracket its roots
    sc = np.signbit(f[:, :-1]) != np.signbit(f[:, 1:])
    rows, cols = np.nonzero(sc)
    best = k_grid.max(axis=1)
    where = x[np.arange(n), k_grid.argmax(axis=1)]
    if rows.size:
        lo, hi = x[rows, cols].copy(), x[rows, cols + 1].copy()
        flo = f[rows, cols]
        pr1, pr2, pr3 = p1[rows], p2[rows], p3[rows]
        for _ in range(n_bisect):
            mid = 0.5 * (lo + hi)
            m = mid[:, None]
            d1, d2, d3 = _peval(pr1, m)[:, 0], _peval(pr2, m)[:, 0], _peval(pr3, m)[:, 0]
            fm = (1.0 + d1 * d1) * d3 - 3.0 * d1 * d2 * d2
            same = np.signbit(fm) == np.signbit(flo)
            lo = np.where(same, mid, lo)
            flo = np.where(same, fm, flo)
            hi = np.where(same, hi, mid)
        root = 0.5 * (lo + hi)
        kr = np.abs(_peval(pr2, root[:, None])[:, 0]) / (1.0 + _peval(pr1, root[:, None])[:, 0] ** 2) ** 1.5
        order = np.lexsort((kr, rows))  # per row, the largest root value last
        last = np.r_[rows[order][1:] != rows[order][:-1], True]
        r_rows, r_k, r_x = rows[order][last], kr[order][last], root[order][last]
        better = r_k > best[r_rows]
        best[r_rows[better]] = r_k[better]
        where[r_rows[better]] = r_x[better]
    return best, where


def _dcoefs(coef: np.ndarray, order: int) -> list[np.ndarray]:
    """Coefficients of the u-derivatives 0..order: list of (n_seg, n, 6-d) arrays."""
    c = np.moveaxis(coef, 1, 2)
    return [np.ascontiguousarray(_pder(c, d)) for d in range(order + 1)]


def _local_derivs(
    coef: np.ndarray, seg: np.ndarray, t: np.ndarray, order: int, dc: list[np.ndarray] | None = None
) -> np.ndarray:
    """u-derivatives (order+1, K, n) of segment ``seg`` (K,) at local parameter t (K,)."""
    if dc is None:
        dc = _dcoefs(coef, order)
    tt = t[:, None]
    out = np.empty((order + 1, t.shape[0], coef.shape[2]))
    for d in range(order + 1):
        cd = dc[d] if seg is None else dc[d][seg]  # (K, n, 6-d); None: every segment once
        acc = cd[..., -1]
        for i in range(cd.shape[-1] - 2, -1, -1):
            acc = acc * tt + cd[..., i]
        out[d] = acc
    return out


def general_curvature_peaks(path, n_grid: int = 64) -> np.ndarray:
    """Peak curvature (n_seg,) of each segment of a general path (1/mm), numerically."""
    w = path.weights
    h = np.diff(path.breaks)
    n = path.n_seg
    frac = np.linspace(0.0, 1.0, n_grid)
    seg = np.repeat(np.arange(n), n_grid)
    t = (h[:, None] * frac[None, :]).reshape(-1)

    dc = _dcoefs(path.coef, 2)

    def kappa(seg, t):
        d = _local_derivs(path.coef, seg, t, 2, dc)
        qu, quu = d[1], d[2]
        a = (qu * qu * w).sum(-1)
        b = (quu * quu * w).sum(-1)
        c = (qu * quu * w).sum(-1)
        num = np.maximum(a * b - c * c, 0.0)
        return np.where(a > 0, np.sqrt(num) / np.where(a > 0, a, 1.0) ** 1.5, 0.0)

    k = kappa(seg, t).reshape(n, n_grid)
    j = k.argmax(axis=1)
    best = k[np.arange(n), j]
    # golden-section refinement on the two grid cells around each maximum
    lo = h * frac[np.maximum(j - 1, 0)]
    hi = h * frac[np.minimum(j + 1, n_grid - 1)]
    segs = None  # one point per segment, in order
    x1 = hi - _GOLD * (hi - lo)
    x2 = lo + _GOLD * (hi - lo)
    f1, f2 = kappa(segs, x1), kappa(segs, x2)
    for _ in range(P000_CURV_REFINE_ITERS):
        left = f1 >= f2  # the maximum lies in [lo, x2]: x1 becomes the new x2
        hi = np.where(left, x2, hi)
        lo = np.where(left, lo, x1)
        xn = np.where(left, hi - _GOLD * (hi - lo), lo + _GOLD * (hi - lo))
        fn = kappa(segs, xn)
        x1, x2, f1, f2 = (
            np.where(left, xn, x2),
            np.where(left, x1, xn),
            np.where(left, fn, f2),
            np.where(left, f1, fn),
        )
    return np.maximum(best, np.maximum(f1, f2))


def curvature_peaks(path) -> np.ndarray:
    """Peak curvature per segment (n_seg,), 1/mm: Eq. 3 for planar paths, numeric otherwise."""
    if path.planar is not None:
        return planar_curvature_peaks(path.planar.p, path.planar.x_end)[0]
    return general_curvature_peaks(path)


@dataclass(frozen=True, eq=False)
class Geometry:
    """Per-segment geometry of a path in joint space (n_seg segments, n joints).

    Attributes:
        length: (n_seg,) arc length of each segment (Eq. 7), mm.
        kappa: (n_seg,) peak curvature (Eq. 3), 1/mm (program space).
        g1, g2, g3: (n_seg, n) maxima of |dq/ds|, |d2q/ds2|, |d3q/ds3| of each joint,
            times ``P000_GEOM_MARGIN``.
        jump1, jump2: (n_seg+1, n) |jump| of dq/ds and d2q/ds2 at each junction (0 at the ends).
        moving_linear: (n_seg, n) bool, linear joints counted in s that move on the segment.
    """

    length: np.ndarray
    kappa: np.ndarray
    g1: np.ndarray
    g2: np.ndarray
    g3: np.ndarray
    jump1: np.ndarray
    jump2: np.ndarray
    moving_linear: np.ndarray


def _chain_to_s(qd: np.ndarray, pd: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Joint u-derivatives qd (4, K, n) -> s-derivatives, with s from program derivatives pd."""
    pu, puu, puuu = pd[1], pd[2], pd[3]
    sig = np.sqrt((pu * pu * w).sum(-1))[:, None]
    sig = np.where(sig > 0, sig, np.nan)
    dot1 = (pu * puu * w).sum(-1)[:, None]
    sig_u = dot1 / sig
    dot2 = (puu * puu * w).sum(-1)[:, None] + (pu * puuu * w).sum(-1)[:, None]
    sig_uu = dot2 / sig - dot1**2 / sig**3
    qu, quu, quuu = qd[1], qd[2], qd[3]
    q1 = qu / sig
    q2 = quu / sig**2 - qu * sig_u / sig**3
    q3 = quuu / sig**3 - 3.0 * quu * sig_u / sig**4 - qu * sig_uu / sig**4 + 3.0 * qu * sig_u**2 / sig**5
    return np.stack([qd[0], q1, q2, q3])


def _joint_derivs(path, joint_map, seg, t, identity: bool) -> np.ndarray:
    """Joint-space s-derivatives (4, K, n) at local parameter t of segment seg."""
    pd = _local_derivs(path.coef, seg, t, 3)
    if identity:
        return _chain_to_s(pd, pd, path.weights)
    # 5-point stencils in u on the segment's own polynomial (it extends smoothly past its ends)
    h = 5e-3 * (path.breaks[seg + 1] - path.breaks[seg])
    pts = [joint_map(_local_derivs(path.coef, seg, t + k * h, 0)[0]) for k in (-2, -1, 0, 1, 2)]
    m2, m1, z0, p1, p2 = pts
    hh = h[:, None]
    qu = (m2 - 8 * m1 + 8 * p1 - p2) / (12 * hh)
    quu = (-m2 + 16 * m1 - 30 * z0 + 16 * p1 - p2) / (12 * hh**2)
    quuu = (-m2 + 2 * m1 - 2 * p1 + p2) / (2 * hh**3)
    return _chain_to_s(np.stack([z0, qu, quu, quuu]), pd, path.weights)


def _is_identity(path, joint_map) -> bool:
    if joint_map is None:
        return True
    probe = _local_derivs(path.coef, np.arange(path.n_seg), np.zeros(path.n_seg), 0)[0]
    try:
        out = np.asarray(joint_map(probe))
    except Exception:  # pragma: no cover - a map that cannot take a batch is not identity
        return False
    return out.shape == probe.shape and np.array_equal(out, probe)


def segment_geometry(path, joint_map=None, n_samples: int = P000_GEOM_SAMPLES) -> Geometry:
    """Geometry of every segment of ``path`` as seen by the joints (see ``Geometry``)."""
    n_seg = path.n_seg
    identity = _is_identity(path, joint_map)
    h = np.diff(path.breaks)
    frac = np.linspace(0.0, 1.0, n_samples)
    seg = np.repeat(np.arange(n_seg), n_samples)
    t = (h[:, None] * frac[None, :]).reshape(-1)
    d = _joint_derivs(path, joint_map, seg, t, identity)
    n = d.shape[2]
    d = np.nan_to_num(d, nan=0.0)
    ad = np.abs(d[1:]).reshape(3, n_seg, n_samples, n)
    g = ad.max(axis=2) * P000_GEOM_MARGIN
    first = d[:, ::n_samples]  # (4, n_seg, n) at t = 0 of each segment
    last = d[:, n_samples - 1 :: n_samples]  # at t = h of each segment
    jump1 = np.zeros((n_seg + 1, n))
    jump2 = np.zeros((n_seg + 1, n))
    jump1[1:-1] = np.abs(first[1, 1:] - last[1, :-1])
    jump2[1:-1] = np.abs(first[2, 1:] - last[2, :-1])
    length = np.diff(path.s_breaks)
    lin = np.asarray(path.weights, dtype=float) > 0
    if n == lin.size:
        moving_linear = (g[0] > 1e-9) & lin[None, :]
    else:
        moving_linear = g[0] > 1e-9
    return Geometry(
        length=length,
        kappa=curvature_peaks(path),
        g1=g[0],
        g2=g[1],
        g3=g[2],
        jump1=jump1,
        jump2=jump2,
        moving_linear=moving_linear,
    )

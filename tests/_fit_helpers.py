"""Independent checks for fitted paths (used by the tests/test_fit_*.py files)."""

from __future__ import annotations

import numpy as np

from cnc_interp.fit.path import Path


def _eval(coef_k: np.ndarray, t: np.ndarray, d: int) -> np.ndarray:
    """d-th t-derivative of rows coef_k (K, 6, n) at t (K,)."""
    out = np.zeros((t.size, coef_k.shape[2]))
    for i in range(d, 6):
        f = 1.0
        for m in range(d):
            f *= i - m
        out += coef_k[:, i, :] * f * (t ** (i - d))[:, None]
    return out


def distance_to_path(
    path: Path, points: np.ndarray, axes_mask: np.ndarray | None = None, samples_per_seg: int = 48, candidates: int = 1
) -> np.ndarray:
    """Distance (K,) from points (K, n) to the path, over the axes in ``axes_mask``.

    Dense sampling + KD-tree for the nearest sample, then Newton on the squared
    distance within that segment: an accurate local distance (no use of the fitter's
    own node parameters).
    """
    from scipy.spatial import cKDTree

    mask = np.ones(path.n_axes, dtype=bool) if axes_mask is None else np.asarray(axes_mask)
    h = np.diff(path.breaks)
    seg = np.repeat(np.arange(path.n_seg), samples_per_seg + 1)
    frac = np.tile(np.linspace(0.0, 1.0, samples_per_seg + 1), path.n_seg)
    t = frac * h[seg]
    q = _eval(path.coef[seg], t, 0)[:, mask]
    tree = cKDTree(q)
    k_nn = min(candidates, q.shape[0])
    _, idx_all = tree.query(points[:, mask], k=k_nn)
    idx_all = np.asarray(idx_all).reshape(points.shape[0], k_nn)
    best = np.linalg.norm(q[idx_all[:, 0]] - points[:, mask], axis=1)
    # Newton in the segments of the nearest samples (several: another part of the path
    # may pass close by) and in their neighbours (the foot may lie just across a break)
    for col in range(k_nn):
        idx = idx_all[:, col]
        k0 = seg[idx]
        for dk, t_start in ((0, None), (-1, "end"), (1, "start")):
            k = np.clip(k0 + dk, 0, path.n_seg - 1)
            if t_start is None:
                tt = t[idx].copy()
            elif t_start == "end":
                tt = h[k].copy()
            else:
                tt = np.zeros(k.size)
            c = path.coef[k][:, :, mask]
            for _ in range(16):
                p0 = _eval(c, tt, 0)
                p1 = _eval(c, tt, 1)
                p2 = _eval(c, tt, 2)
                r = p0 - points[:, mask]
                g = (r * p1).sum(axis=1)
                hh = (p1 * p1).sum(axis=1) + (r * p2).sum(axis=1)
                hh = np.where(hh > 0, hh, (p1 * p1).sum(axis=1) + 1e-300)
                tt = np.clip(tt - g / hh, 0.0, h[k])
            best = np.minimum(best, np.linalg.norm(_eval(c, tt, 0) - points[:, mask], axis=1))
    return best


def continuity(path: Path) -> tuple[float, float, float]:
    """Largest jumps of q, q_s, q_ss across the interior breaks (left vs right limits)."""
    if path.n_seg < 2:
        return 0.0, 0.0, 0.0
    k = np.arange(path.n_seg - 1)
    h = np.diff(path.breaks)[k]
    w = path.weights
    left = [_eval(path.coef[k], h, d) for d in range(3)]
    right = [_eval(path.coef[k + 1], np.zeros(k.size), d) for d in range(3)]

    def s_derivs(q):
        sig = np.sqrt((q[1] ** 2 * w).sum(axis=1))[:, None]
        dot = (q[1] * q[2] * w).sum(axis=1)[:, None]
        return q[1] / sig, q[2] / sig**2 - q[1] * dot / sig**4

    t_l, c_l = s_derivs(left)
    t_r, c_r = s_derivs(right)
    return (float(np.abs(left[0] - right[0]).max()), float(np.abs(t_l - t_r).max()), float(np.abs(c_l - c_r).max()))


def min_speed(path: Path, samples_per_seg: int = 32) -> float:
    """Smallest |dq/du| in the path's arc-length metric over dense samples."""
    h = np.diff(path.breaks)
    seg = np.repeat(np.arange(path.n_seg), samples_per_seg + 1)
    t = np.tile(np.linspace(0.0, 1.0, samples_per_seg + 1), path.n_seg) * h[seg]
    d1 = _eval(path.coef[seg], t, 1)
    return float(np.sqrt((d1**2 * path.weights).sum(axis=1)).min())


def all_finite(path: Path) -> bool:
    return bool(np.all(np.isfinite(path.coef)) and np.all(np.isfinite(path.breaks)) and np.isfinite(path.length))

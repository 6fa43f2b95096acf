"""``deviation.path_deviation`` for a sub-run without exact curves, in one compiled call.

Stellabee-like programs have tens of thousands of short fitted sub-runs; the Python
glue around the measurement's kernels (sampling, masking, projection) then costs more
than the kernels. This is the same measurement — the same kernels (``_project``) with
the same arguments and arithmetic, so the same numbers — without that glue.

Numba keys this module's cache on this file alone; ``cnc_interp._kernel_cache.refresh``
drops it at import when ``_project`` (or anything else it imports) changes.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from ._project import line_samples, march_distances, median

#: the measurement's knobs (``deviation``'s PATH_DEV_* constants): samples_per_span,
#: min_samples, max_samples (samples per move), local_frac, window and far_window (in
#: sample spacings), n_coarse (samples of the coarse search) and iters (Newton steps)
DeviationSettings = namedtuple(
    "DeviationSettings", "samples_per_span min_samples max_samples local_frac window far_window n_coarse iters"
)


@njit(cache=True)
def polyline_path_deviation(breaks, coef, nodes, tol_mm, lin, cfg):
    """(max distance mm, max distance / tolerance) of the moves through ``nodes`` (n, d)
    to the pieces (breaks (S+1,), coef (S, 6, d)) over the axes ``lin`` (d,) bool;
    ``tol_mm`` (n,) the tolerance of the move ending at each node; ``cfg`` the
    ``DeviationSettings``. As ``path_deviation(breaks, coef, nodes, tol_mm, lin)`` with
    no curves."""
    samples_per_span = cfg.samples_per_span
    n, d = nodes.shape
    n_lin = 0
    for a in range(d):
        if lin[a]:
            n_lin += 1
    if n_lin == 0 or n < 2:
        return 0.0, 0.0
    S = coef.shape[0]
    h = np.empty(S)
    for k in range(S):
        h[k] = breaks[k + 1] - breaks[k]
    spacing = max(median(h), 1e-9) / samples_per_span
    in_curve = np.zeros(n - 1, dtype=np.bool_)
    pts, tol, _ = line_samples(nodes, tol_mm, in_curve, spacing, cfg.min_samples, cfg.max_samples)
    K = pts.shape[0]
    if K == 0:
        return 0.0, 0.0
    cm = np.empty((S, 6, n_lin))
    pm = np.empty((K, n_lin))
    j = 0
    for a in range(d):
        if lin[a]:
            cm[:, :, j] = coef[:, :, a]
            pm[:, j] = pts[:, a]
            j += 1
    dist = march_distances(
        cm, h, pm, tol, cfg.local_frac, cfg.window * spacing, cfg.far_window * spacing, cfg.n_coarse, cfg.iters
    )
    dmax = dist[0]
    rmax = dist[0] / max(tol[0], 1e-300)
    for i in range(1, K):
        if dist[i] > dmax:
            dmax = dist[i]
        r = dist[i] / max(tol[i], 1e-300)
        if r > rmax:
            rmax = r
    return dmax, rmax

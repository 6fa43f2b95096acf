"""Compiled sequential pass for ``corners._distinct_nodes`` (only runs that hold tiny steps
reach it, so the common case needs no compile)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def distinct_nodes(scaled, threshold):
    """``keep`` mask: node i is kept when its distance to the last kept node exceeds
    ``threshold`` (same metric as ``scaled``, shape (n, n_axes))."""
    n, m = scaled.shape
    keep = np.zeros(n, dtype=np.bool_)
    keep[0] = True
    last = 0
    thr2 = threshold * threshold
    for i in range(1, n):
        d2 = 0.0
        for k in range(m):
            d = scaled[i, k] - scaled[last, k]
            d2 += d * d
        if d2 > thr2:
            keep[i] = True
            last = i
    return keep

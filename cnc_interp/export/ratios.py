"""Per-sample limit ratios of a plan (for the MCAP ``/limits`` channel and the plots).

``plan.verify`` reports only the worst value per axis; here every sample gets its
signed velocity, acceleration and jerk over the limit, with the same differences
(paper 001, Eq. 6: repeated backward differences of the stored setpoints) and the
same rest padding before the first sample.
"""

from __future__ import annotations

import numpy as np


def limit_ratios(q: np.ndarray, dt_s: float, limits: np.ndarray) -> np.ndarray:
    """(3, K, n) signed v/vmax, a/amax, j/jmax of ``q`` (K, n) against ``limits`` (3, n).

    Row k uses samples k-3..k, the machine at rest before the first sample
    (``q[-1] = q[-2] = q[-3] = q[0]``). A zero limit gives 0 where the axis does not
    move and +-inf where it does; NaN setpoints give NaN.
    """
    q = np.asarray(q, dtype=float)
    K, n = q.shape
    out = np.zeros((3, K, n))
    if K == 0:
        return out
    lim = np.asarray(limits, dtype=float).reshape(3, n)
    for i in range(n):  # one contiguous column at a time: a few times faster on long plans
        x = np.empty(K + 3)
        x[:3] = q[0, i]
        x[3:] = q[:, i]
        for m in range(3):
            x = np.diff(x)  # m+1-th difference; its last K values end at 0..K-1
            d = x[-K:] / dt_s ** (m + 1)
            if lim[m, i] > 0:
                out[m, :, i] = d / lim[m, i]
            else:
                with np.errstate(divide="ignore", invalid="ignore"):
                    out[m, :, i] = np.where(d == 0.0, 0.0, d / lim[m, i])
    return out

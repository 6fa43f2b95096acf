"""Line: the exact discrete plan of a straight path from rest to rest.

A path whose every segment lies on the chord from its start to its end (a G1 line between
two stops, a rapid, a chain of collinear moves at one feed) is one dimensional, and its
minimum-time discrete plan under verify's per-axis bounds has a closed form
(``_line_kernels``): the fewest periods any plan of that chord can take, one compiled call
for a job's paths. Where a path is not straight, or rounding would break a bound, the
other routes plan it.
"""

from __future__ import annotations

import numpy as np

from ...constants import VPOP_LIMIT_SHRINK, VPOP_MIN_LENGTH, VPOP_ROUNDING_ULPS
from ..base import PathPlan

#: a segment within this of its path's chord (mm or deg, per coefficient row) is on it:
#: far below any fit tolerance, above the rounding of a fitted straight segment
LINE_STRAIGHT_TOL = 1e-9
#: the most periods one line's plan takes here (2^20: 17 min at 1 kHz, 25 MB of samples
#: for 3 axes); a longer one streams through the other routes
LINE_MAX_PERIODS = 1 << 20


def plan_lines(paths, machine, dt_s: float) -> list:
    """The exact plan (``PathPlan``, stats {"route": "line"}) of each straight path of
    ``paths`` (joint space = program space), ``None`` for the others."""
    from .. import _line_kernels as K
    from ..joint_table import concat_paths
    from .route import Route

    out: list = [None] * len(paths)
    idx = [
        i
        for i, p in enumerate(paths)
        if p.length > VPOP_MIN_LENGTH and np.isfinite(p.length) and np.all(np.isfinite(p.coef))
    ]
    if not idx:
        return out
    sel = [paths[i] for i in idx]
    coef, breaks, _s_breaks, _weights, lengths, feed, seg_off = concat_paths(sel)
    lim = np.ascontiguousarray(np.stack([machine.vmax, machine.amax, machine.jmax]), dtype=float)
    settings = np.array([LINE_STRAIGHT_TOL, VPOP_LIMIT_SHRINK, VPOP_ROUNDING_ULPS, float(LINE_MAX_PERIODS)])
    done, off, s, q = K.plan_lines(coef, breaks, lengths, feed, seg_off, lim, float(dt_s), settings)
    offs = off.tolist()
    for j, ok in enumerate(done.tolist()):
        if ok:
            a, b = offs[j], offs[j + 1]
            out[idx[j]] = PathPlan(s=s[a:b], q=q[a:b], stats={"route": Route.LINE, "samples": b - a})
    return out

"""Shared by both paper-000 planners: sampling a profile, checking samples, joint maps."""

from __future__ import annotations

import numpy as np

from .profile import SegmentProfiles, n_periods

#: rest samples padded on each side of a plan by the checks (3 covers the jerk stencil)
_PAD = 3


def joint_positions(path, joint_map, s: np.ndarray) -> np.ndarray:
    """Joint setpoints (K, n) at arc lengths s; the last one is exactly the path's end."""
    from .arclength import positions

    p = positions(path, s)
    if s.size and s[-1] >= path.length:
        p[-1] = path.end
    if s.size and s[0] <= 0.0:
        p[0] = path.start
    return p if joint_map is None else np.asarray(joint_map(p), dtype=float)


def sample_profile(path, joint_map, prof: SegmentProfiles, dt_s: float):
    """Samples every dt of a profile stretched to whole periods: (s (K,), q (K, n))."""
    k = n_periods(prof, dt_s)
    if k == 0 or path.length <= 0.0:
        s = np.zeros(1)
    else:
        t = np.arange(k + 1) * dt_s
        s = prof.evaluate(t)[0]
        s = np.clip(np.maximum.accumulate(s), 0.0, path.length)
        s[0] = 0.0
        s[-1] = path.length
    return s, joint_positions(path, joint_map, s)


def sample_ratios(q: np.ndarray, dt_s: float, machine) -> np.ndarray:
    """Worst |v|, |a|, |j| ratio to the limits (K,) touching each sample (paper 001 Eq. 6).

    Backward finite differences over the samples padded with rest on both sides; each
    difference's ratio is charged to every sample of its stencil.
    """
    k = q.shape[0]
    qp = np.concatenate([np.repeat(q[:1], _PAD, axis=0), q, np.repeat(q[-1:], _PAD, axis=0)])
    out = np.zeros(k + 2 * _PAD)
    d = qp
    for order, lim in enumerate((machine.vmax, machine.amax, machine.jmax), start=1):
        d = np.diff(d, axis=0) / dt_s
        r = (np.abs(d) / lim).max(axis=1)  # r[i] uses padded samples i .. i+order
        for off in range(order + 1):
            out[off : off + r.size] = np.maximum(out[off : off + r.size], r)
    return out[_PAD : _PAD + k]


def worst_ratio(q: np.ndarray, dt_s: float, machine) -> float:
    """Worst ratio over the plan by the project's ``verify_arrays`` (rest padding included)."""
    from ..verify import verify_arrays

    return verify_arrays(q, dt_s, machine.vmax, machine.amax, machine.jmax).worst_ratio

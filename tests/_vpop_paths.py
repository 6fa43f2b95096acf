"""Hand-built ``Path`` objects for the planner tests (no fit stage needed)."""

from __future__ import annotations

import numpy as np

from cnc_interp.fit.path import Path
from cnc_interp.plan.vpop import _hermite


def line_path(a, b, feed_mm_s: float, axes: str = "XYZ", line: int = 1, rapid: bool = False) -> Path:
    """One straight segment from a to b."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    coef = np.zeros((1, 6, a.shape[0]))
    coef[0, 0] = a
    coef[0, 1] = b - a
    return Path(axes=axes, breaks=np.array([0.0, 1.0]), coef=coef, line=[line], feed_mm_s=[feed_mm_s], rapid=rapid)


def hermite_path(fun, n_seg: int, feed_mm_s: float, axes: str = "XYZ", u1: float = 1.0, line0: int = 1) -> Path:
    """Quintic Hermite interpolation of a smooth curve ``fun(u) -> (p, p_u, p_uu)`` on [0, u1].

    Each segment matches position, first and second derivatives at its ends, so the
    path is C2 in u (G2 as a curve).
    """
    u = np.linspace(0.0, u1, n_seg + 1)
    p, d1, d2 = (np.asarray(x, dtype=float) for x in fun(u))
    coef = _hermite(u, p, d1, d2)  # the planner's own quintic Hermite construction
    return Path(
        axes=axes, breaks=u, coef=coef, line=np.arange(line0, line0 + n_seg), feed_mm_s=np.full(n_seg, feed_mm_s)
    )


def random_curve(rng: np.random.Generator, n_axes: int = 3, scale: float = 20.0, n_waves: int = 3):
    """A smooth random curve: sum of sines, returns fun(u) for ``hermite_path``."""
    amp = rng.normal(0, scale, (n_waves, n_axes)) / np.arange(1, n_waves + 1)[:, None]
    freq = rng.uniform(0.3, 2.0, (n_waves, n_axes)) * np.arange(1, n_waves + 1)[:, None]
    phase = rng.uniform(0, 2 * np.pi, (n_waves, n_axes))
    drift = rng.normal(0, scale, n_axes)

    def fun(u):
        u = np.asarray(u, dtype=float)[:, None, None]
        arg = freq * u + phase
        p = (amp * np.sin(arg)).sum(axis=1) + drift * u[:, 0]
        p1 = (amp * freq * np.cos(arg)).sum(axis=1) + drift
        p2 = (-amp * freq**2 * np.sin(arg)).sum(axis=1)
        return p, p1, p2

    return fun


def circle_fun(radius: float, turns: float = 1.0, z_per_turn: float = 0.0):
    """Helix / circle in XY starting at (radius, 0, 0)."""
    w = 2 * np.pi * turns

    def fun(u):
        u = np.asarray(u, dtype=float)
        c, s = np.cos(w * u), np.sin(w * u)
        p = np.stack([radius * c, radius * s, z_per_turn * turns * u], axis=1)
        p1 = np.stack([-radius * w * s, radius * w * c, np.full_like(u, z_per_turn * turns)], axis=1)
        p2 = np.stack([-radius * w * w * c, -radius * w * w * s, np.zeros_like(u)], axis=1)
        return p, p1, p2

    return fun

"""Dense corners at high feed: a "bear-like" CAM program — thousands of short G1
moves with sharp and gentle turns at F6000, coordinates to 4 decimals, as a relief
carving's raster/contour passes come out of CAM (CAMotics' bear example: 15k lines at
F6000): the bear-like rows of the corner table in ``docs/fit-and-planning.md``.
"""

from __future__ import annotations

import numpy as np


def bear_like_program(
    n_moves: int = 15000, seed: int = 14, g64_p_mm: float | None = None, feed_mm_min: float = 6000.0
) -> str:
    """A seeded walk of ``n_moves`` G1 moves of 0.2-1.5 mm in XY with small Z steps: half
    the turns gentle (< 20°), half sharp (40-150°), as a contour-parallel relief pass.
    ``g64_p_mm``: the program's ``G64 P`` (None: plain G64, the default tolerance)."""
    rng = np.random.default_rng(seed)
    length = rng.uniform(0.2, 1.5, n_moves)
    sharp = rng.random(n_moves) < 0.5
    turn = np.where(sharp, rng.uniform(40, 150, n_moves), rng.uniform(0, 20, n_moves))
    turn *= rng.choice([-1.0, 1.0], n_moves)
    heading = np.radians(np.cumsum(turn))
    xy = np.cumsum(np.stack([length * np.cos(heading), length * np.sin(heading)], axis=1), axis=0)
    # keep the walk on a 100 x 100 mm stock: fold it back at the edges
    xy = 50.0 - np.abs(np.mod(xy + 50.0, 200.0) - 100.0)
    z = -1.0 - 0.5 * (1 + np.sin(np.arange(n_moves) * 0.01))
    head = [
        "G21 G90 G17 G94",
        "G64" + (f" P{g64_p_mm:g}" if g64_p_mm else ""),
        "G0 X0 Y0 Z5",
        "G1 Z-1 F1000",
        f"F{feed_mm_min:g}",
    ]
    body = [f"G1 X{x:.4f} Y{y:.4f} Z{zz:.4f}" for (x, y), zz in zip(xy, z)]
    return "\n".join(head + body + ["G0 Z5", "M2"]) + "\n"

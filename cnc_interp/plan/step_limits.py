"""The per-axis limits of one sample step, with the margins every sampled planner keeps.

VPOp (its Python preparation; the compiled one, ``vpop.drive.prepare_identity``, computes
the same values with the same float operations), the optimal planner's exact sampler and
the safe fallback check each sample's backward differences against these, so that what
they accept, ``verify`` accepts: the limits are shrunk by ``VPOP_LIMIT_SHRINK`` and keep
an absolute margin of ``VPOP_ROUNDING_ULPS`` ulps of the positions, times the weights of
the difference stencils (2, 4 and 8 for velocity, acceleration and jerk), so that one-ulp
differences between what a planner checked and what reaches ``verify`` (joins between
paths, re-evaluated end points) cannot push a low limit (jmax dt³ ~ 1e-6 mm) past its
ratio slack.
"""

from __future__ import annotations

import numpy as np

from ..constants import VPOP_LIMIT_SHRINK, VPOP_ROUNDING_ULPS
from ..errors import PlanError


def position_scale(C: np.ndarray) -> float:
    """1 + the largest |position| of a joint table's nodes ``C`` (n, 3, n_axes): the
    scale of the positions' rounding."""
    return 1.0 + float(np.max(np.abs(C[:, 0, :])))


def step_limits(machine, dt_s: float, q_scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vl, al, jl), each (n_axes,): the largest |first, second, third backward
    difference| of a joint's positions over one step of ``dt_s`` (mm or deg), for
    positions of magnitude up to ``q_scale``. Raises ``PlanError`` where the jerk limits
    are below what float64 resolves at that scale."""
    dt = float(dt_s)
    shrink = 1.0 - VPOP_LIMIT_SHRINK
    margin = VPOP_ROUNDING_ULPS * np.finfo(float).eps * q_scale
    vl = np.ascontiguousarray(machine.vmax * dt * shrink - 2.0 * margin, dtype=float)
    al = np.ascontiguousarray(machine.amax * dt * dt * shrink - 4.0 * margin, dtype=float)
    jl = np.ascontiguousarray(machine.jmax * dt**3 * shrink - 8.0 * margin, dtype=float)
    if np.any(jl <= 0.5 * machine.jmax * dt**3):
        raise PlanError(
            f"the jerk limits are too small for dt = {dt:g} s at positions of "
            f"{q_scale:g} mm/deg: float64 cannot resolve them"
        )
    return vl, al, jl

"""The machine's limits on the device side: what the golden model outputs must pass ``verify``.

A device outputs positions rounded to the position LSB, so even exact setpoints carry a
rounding error of up to LSB/2 per sample, i.e. up to LSB/dt, 2·LSB/dt² and 4·LSB/dt³ of
velocity, acceleration and jerk in verify's backward differences. A plan that runs
exactly at a limit (VPOp does, by design) therefore cannot be reproduced by any
quantized device without breaking that limit by this much. The stream takes two
measures (docs/fpga-protocol.md, "Limits on the device side"):

1. **Margin.** ``stream`` plans against the machine's limits scaled by 1 − δ, with δ a
   fixed base (``FPGA_LIMIT_MARGIN``) plus twice the rounding budget above for the
   machine's tightest axis (``device_margin``). Rounding then always fits.
2. **Check and repair.** ``build_program`` runs the golden model over the quantized
   program and evaluates verify's differences against the *real* limits; every segment
   whose samples take part in a difference above a limit (its profile fit moved a sample
   too much for the jerk budget) is re-sent as exact setpoints, until no segment does.
   What remains can only be rounding, which the margin covers; ``stream`` still checks
   the final result with ``verify`` and refuses to send anything that fails it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..constants import FPGA_LIMIT_MARGIN, VERIFY_REST_PADDING
from ..errors import PlanError, SourceLocation


#: the rounding budget (LSB/dt, 2 LSB/dt², 4 LSB/dt³ over the limits) counts this many times
FPGA_MARGIN_QUANTA = 2.0

#: a margin above this (a dt too short for the position LSB) is refused
FPGA_LIMIT_MARGIN_MAX = 1e-2


def rounding_budget(limits: np.ndarray, dt_s: float, lsb: float) -> float:
    """Largest ratio (over axes and v/a/j) that rounding to ``lsb`` can add: limits (3, n)."""
    worst = np.array([lsb, 2.0 * lsb, 4.0 * lsb])[:, None] / (
        np.asarray(limits, dtype=float) * np.array([dt_s, dt_s**2, dt_s**3])[:, None]
    )
    return float(worst.max())


def device_margin(machine, fmts, source: str = "<input>") -> float:
    """Relative margin δ the stream plans with (see module docstring); refuses a hopeless one."""
    q = rounding_budget(machine.limits(), machine.dt_s, fmts.pos.lsb)
    delta = FPGA_LIMIT_MARGIN + FPGA_MARGIN_QUANTA * q
    if delta > FPGA_LIMIT_MARGIN_MAX:
        raise PlanError(
            f"dt = {machine.dt_s:g} s is too short for the device's position LSB "
            f"({fmts.pos.lsb:.3g} mm): rounding alone would use {100 * q:.2g} % of a "
            f"limit; use a longer --dt",
            SourceLocation(file=source),
        )
    return delta


def with_margin(machine, delta: float):
    """The machine with every limit scaled by 1 − δ (what the stream plans against)."""
    k = 1.0 - float(delta)
    return replace(machine, vmax=machine.vmax * k, amax=machine.amax * k, jmax=machine.jmax * k)


def excess_samples(q_mm: np.ndarray, dt_s: float, limits: np.ndarray) -> np.ndarray:
    """Sample indices whose verify stencil (backward differences, rest padding) exceeds a limit.

    q_mm (K, n) positions; limits (3, n). Returns the sorted indices of every sample that
    takes part in a difference above its limit (ratio > 1, computed as ``verify`` does).
    """
    q = np.asarray(q_mm, dtype=float)
    K = q.shape[0]
    pad = VERIFY_REST_PADDING
    bad = np.zeros(K + 2 * pad, dtype=bool)
    for i in range(q.shape[1]):
        x = np.concatenate([np.full(pad, q[0, i]), q[:, i], np.full(pad, q[-1, i])])
        for m in range(3):
            x = np.diff(x)
            r = np.abs(x) / dt_s ** (m + 1) / limits[m, i]
            hit = np.nonzero(r > 1.0)[0]
            for o in range(m + 2):  # difference j of order m+1 spans padded samples j..j+m+1
                bad[hit + o] = True
    idx = np.nonzero(bad)[0] - pad
    return idx[(idx >= 0) & (idx < K)]

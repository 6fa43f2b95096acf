"""Refuse, before planning, a plan that cannot fit in memory.

A plan holds every sample in memory (positions, path position, feed, source line, and the
verify pass's differences). ``--dt 1e-6`` on an hour-long program asks for billions of
samples: without this check the process grows until the operating system kills it, with
no message. The check uses a lower bound of the cycle time (``min_cycle_time_s``), so it
never refuses a plan that would fit.
"""

from __future__ import annotations

import os

import numpy as np

from ..constants import PLAN_BUDGET_MARGIN, PLAN_PEAK_BYTES_PER_SAMPLE_COLUMN
from ..errors import PlanError, SourceLocation


def min_cycle_time_s(paths, machine=None) -> float:
    """A lower bound (s) of the cycle time of ``paths``; dwells count as zero.

    Each feed path takes at least its length over its largest programmed feed (no planner
    exceeds F). Every path starts and ends at rest, so with ``machine`` and trivial
    kinematics (program axes are the joints) each axis i that moves by d_i takes at least
    max(d_i / vmax_i, 2 sqrt(d_i / amax_i), (32 d_i / jmax_i)^(1/3)): the least times to
    cover d_i from rest to rest under each limit alone.
    """
    paths = [p for p in paths if p.coef.shape[0]]
    if not paths:
        return 0.0
    t = np.zeros(len(paths))
    for i, p in enumerate(paths):
        feed = float(p.feed_mm_s.max())
        if not p.rapid and np.isfinite(feed) and feed > 0:
            t[i] = float(p.length) / feed
    if machine is not None and machine.kinematics == "trivial":
        start = np.array([p.coef[0, 0] for p in paths])  # (P, n)
        last = np.array([p.coef[-1] for p in paths])  # (P, 6, n): the last piece at its end
        h = np.array([p.breaks[-1] - p.breaks[-2] for p in paths])[:, None]
        end = last[:, 5]
        for k in range(4, -1, -1):
            end = end * h + last[:, k]
        d = np.abs(end - start)
        t_axis = np.maximum.reduce([d / machine.vmax, 2.0 * np.sqrt(d / machine.amax),
                                    np.cbrt(32.0 * d / machine.jmax)])
        t = np.maximum(t, t_axis.max(axis=1))
    return float(t.sum())


def available_memory_bytes() -> int | None:
    """Memory the system can give this process now (Linux ``MemAvailable``, and no more
    than an address-space limit leaves: ``ulimit -v``), or None when unknown."""
    avail = None
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        try:
            avail = int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
        except (OSError, ValueError, AttributeError):
            avail = None
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            with open("/proc/self/status", encoding="ascii") as fh:
                used = next(int(ln.split()[1]) * 1024 for ln in fh if ln.startswith("VmSize:"))
            left = max(soft - used, 0)
            avail = left if avail is None else min(avail, left)
    except (ImportError, OSError, ValueError, StopIteration):
        pass
    return avail


def held_time_s(items) -> float:
    """Time (s) the timeline ``items`` holds the machine still on purpose: its dwells.
    Held samples take memory like moving ones."""
    from ..gcode.program import Dwell

    return float(sum(it.seconds for it in items if isinstance(it, Dwell)))


def check_sample_budget(paths, machine, dt_s: float, source: str,
                        available: int | None = None, held_s: float = 0.0) -> None:
    """Raise ``PlanError`` (exit 1: the plan cannot be made) when even the shortest
    possible plan of ``paths`` on ``machine`` at ``dt_s``, plus ``held_s`` seconds of
    dwells (``held_time_s``), needs more memory than is available (``available`` bytes;
    default: ``available_memory_bytes``)."""
    # the margin is for the paths' lower bound; a dwell's time is exact
    n_min = (PLAN_BUDGET_MARGIN * min_cycle_time_s(paths, machine) + held_s) / dt_s
    need = n_min * PLAN_PEAK_BYTES_PER_SAMPLE_COLUMN * (5 + machine.n_axes)
    if available is None:
        available = available_memory_bytes()
    if available is None or need <= available:
        return
    raise PlanError(
        f"planning at dt = {dt_s:g} s needs at least {n_min:.3g} samples (about "
        f"{need / 1e9:.3g} GB of memory) but {available / 1e9:.3g} GB are available; "
        f"use a larger --dt", SourceLocation(source))

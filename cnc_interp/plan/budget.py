"""Refuse, before planning, a plan that cannot fit in memory.

An in-memory plan (``plan_program``, ``plan_part``: batch, the FPGA stage) holds every
sample (positions, path position, feed, source line, and the verify pass's
differences). ``--dt 1e-6`` on an hour-long program asks for billions of samples:
without this check the process grows until the operating system kills it, with no
message. ``check_sample_budget`` uses a lower bound of the cycle time
(``min_cycle_time_s``), so it never refuses a plan that would fit.

The streaming plan (``cnc-interp plan``) holds a window, not the cycle: ``WindowBudget``
checks what one window needs (one whole path for planners that do not stream within a
path). Both count the joint table VPOp builds for a path before its first sample
(``table_bytes``): its size grows with the path's length, not its duration, so one
straight move of 10^8 mm needed 2.3 GB however it was streamed.
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import PlanError, SourceLocation


#: plan memory check: peak bytes per sample and per column (t, s, feed, line, verify, one per
#: axis: 5 + n_axes), measured: stellabee1 on generic-mill, 8.61 M samples, 2.06 GB peak
PLAN_PEAK_BYTES_PER_SAMPLE_COLUMN = 30.0

#: plan memory check: share of the lower-bound sample count that must fit (a safety factor
#: on the bound, so that the check never refuses a plan that would fit)
PLAN_BUDGET_MARGIN = 0.5

#: plan memory check: peak bytes per piece of VPOp's joint table and per column (one per
#: axis and the arc length) while it is built, a little under the measured: G1 X1e8 on
#: generic-mill, 5e6 pieces, 2.15 GB over an empty plan's peak (108 bytes a piece-column)
PLAN_TABLE_PEAK_BYTES_PER_PIECE_COLUMN = 100.0


def path_min_times_s(paths, machine=None) -> np.ndarray:
    """A lower bound (s) of each path's planned time (P,); dwells are not paths.

    Each feed path takes at least its length over its largest programmed feed (no planner
    exceeds F). Every path starts and ends at rest, so with ``machine`` and trivial
    kinematics (program axes are the joints) each axis i that moves by d_i takes at least
    max(d_i / vmax_i, 2 sqrt(d_i / amax_i), (32 d_i / jmax_i)^(1/3)): the least times to
    cover d_i from rest to rest under each limit alone.
    """
    paths = list(paths)
    t = np.zeros(len(paths))
    real = [i for i, p in enumerate(paths) if p.coef.shape[0]]
    if not real:
        return t
    for i in real:
        p = paths[i]
        feed = float(p.feed_mm_s.max())
        if not p.rapid and np.isfinite(feed) and feed > 0:
            t[i] = float(p.length) / feed
    if machine is not None and machine.kinematics == "trivial":
        sel = [paths[i] for i in real]
        start = np.array([p.coef[0, 0] for p in sel])  # (P, n)
        last = np.array([p.coef[-1] for p in sel])  # (P, 6, n): the last piece at its end
        h = np.array([p.breaks[-1] - p.breaks[-2] for p in sel])[:, None]
        end = last[:, 5]
        for k in range(4, -1, -1):
            end = end * h + last[:, k]
        d = np.abs(end - start)
        t_axis = np.maximum.reduce(
            [d / machine.vmax, 2.0 * np.sqrt(d / machine.amax), np.cbrt(32.0 * d / machine.jmax)]
        )
        t[real] = np.maximum(t[real], t_axis.max(axis=1))
    return t


def table_bytes(paths, n_axes: int) -> tuple[float, object]:
    """A lower bound (bytes) of the memory VPOp's joint table of the longest of ``paths``
    needs while it is built, and that path (None without paths): it has at least one piece
    per ``VPOP_TABLE_MAX_PIECE`` of the path's arc length."""
    from .joint_table import VPOP_TABLE_MAX_PIECE

    longest = max(paths, key=lambda p: float(p.length), default=None)
    if longest is None:
        return 0.0, None
    pieces = float(longest.length) / VPOP_TABLE_MAX_PIECE
    return pieces * PLAN_TABLE_PEAK_BYTES_PER_PIECE_COLUMN * (1 + n_axes), longest


def _table_error(need: float, available: float, path, source: str) -> PlanError:
    return PlanError(
        f"the move ending at line {int(path.line[-1])} is {float(path.length):.6g} mm (or deg) long: "
        f"planning it needs at least {need / 1e9:.3g} GB of memory but {available / 1e9:.3g} GB are available",
        SourceLocation(source),
    )


def min_cycle_time_s(paths, machine=None) -> float:
    """A lower bound (s) of the cycle time of ``paths``; dwells count as zero (the sum of
    ``path_min_times_s``)."""
    return float(path_min_times_s(paths, machine).sum())


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


def check_sample_budget(
    paths,
    machine,
    dt_s: float,
    source: str,
    available: int | None = None,
    held_s: float = 0.0,
    tables: bool = True,
) -> None:
    """Raise ``PlanError`` (exit 1: the plan cannot be made) when even the shortest
    possible plan of ``paths`` on ``machine`` at ``dt_s``, plus ``held_s`` seconds of
    dwells (``held_time_s``), and the joint table of its longest path (``table_bytes``;
    with ``tables``, else of its longest rapid: the planner is not VPOp's) needs more
    memory than is available (``available`` bytes; default: ``available_memory_bytes``)."""
    # the margin is for the paths' lower bound; a dwell's time is exact
    n_min = (PLAN_BUDGET_MARGIN * min_cycle_time_s(paths, machine) + held_s) / dt_s
    need = n_min * PLAN_PEAK_BYTES_PER_SAMPLE_COLUMN * (5 + machine.n_axes)
    table, longest = table_bytes(paths if tables else [p for p in paths if p.rapid], machine.n_axes)
    if available is None:
        available = available_memory_bytes()
    if available is None or need + table <= available:
        return
    if table > available:
        raise _table_error(table, available, longest, source)
    raise PlanError(
        f"planning at dt = {dt_s:g} s needs at least {n_min:.3g} samples (about "
        f"{need / 1e9:.3g} GB of memory) but {available / 1e9:.3g} GB are available; "
        f"use a larger --dt",
        SourceLocation(source),
    )


class WindowBudget:
    """The memory check of the streaming timeline (``plan.timeline.iter_timeline``).

    What is in memory at once is a window of the program, not the whole cycle: for a
    planner that streams within a path (VPOp) the window is bounded by its settings, so
    nothing is refused; a planner that returns a whole path at once (one chunk) needs
    that path's samples in memory, so each path is checked, before it is planned, with
    the same lower bound of its time (``path_min_times_s``) that ``check_sample_budget``
    sums over the whole program.
    """

    def __init__(self, machine, dt_s: float, source: str, streams: bool, window=None):
        self.machine = machine
        self.dt_s = float(dt_s)
        self.source = source
        self.streams = streams
        self.available: int | None = None
        self._asked = False
        self._vmin = float(np.min(machine.vmax))
        self._ramp = float(np.max(machine.vmax / machine.amax + machine.amax / machine.jmax))

    def rough_samples(self, path) -> float:
        """A rough sample count of ``path`` (to size the timeline's jobs; not a bound)."""
        feed = float(path.feed_mm_s.max()) if not path.rapid else self._vmin
        v = min(feed, self._vmin) if feed > 0 else self._vmin
        return (float(path.length) / v + 2.0 * self._ramp) / self.dt_s

    def check(self, paths) -> None:
        """Raise ``PlanError`` when one of ``paths``, planned whole, or its joint table
        (``table_bytes``: VPOp's, which plans the rapids and, with the planners that stream,
        the feed paths) cannot fit in memory."""
        if not paths:
            return
        feed_paths = [p for p in paths if not p.rapid]  # rapids are always streamed (VPOp)
        with_table = paths if self.streams else [p for p in paths if p.rapid]
        table, longest_path = table_bytes(with_table, self.machine.n_axes)
        need = 0.0
        n_min = 0.0
        if not self.streams and feed_paths:
            longest = float(path_min_times_s(feed_paths, self.machine).max())
            n_min = PLAN_BUDGET_MARGIN * longest / self.dt_s
            need = n_min * PLAN_PEAK_BYTES_PER_SAMPLE_COLUMN * (5 + self.machine.n_axes)
        if need + table <= 0:
            return
        if not self._asked:
            self.available = available_memory_bytes()
            self._asked = True
        if self.available is None or need + table <= self.available:
            return
        if table > self.available or need <= 0:
            raise _table_error(table, self.available, longest_path, self.source)
        raise PlanError(
            f"planning at dt = {self.dt_s:g} s needs at least {n_min:.3g} samples of one path "
            f"in memory (about {need / 1e9:.3g} GB of memory) but {self.available / 1e9:.3g} GB are "
            f"available; use a larger --dt",
            SourceLocation(self.source),
        )

"""Plan for LinuxCNC's ``halstreamer``: one line per servo period, the axis positions.

``halstreamer`` (LinuxCNC's user-space feeder of the ``streamer`` HAL component) reads
one line per period of the thread the streamer runs in, whitespace-separated numbers
matching the component's ``cfg=`` pin types; lines starting with ``#`` are comments.
A plan ``-o PLAN.halstream`` is that file: a few ``#`` lines naming the columns, the
period and the ``loadrt`` line, then one line per sample with the position of every
machine axis in machine order (mm; deg for A, B, C), each number Python's shortest
round-trip form (``repr``), which ``strtod`` reads back to the same float64. With
trivial kinematics each column is a joint's position command. The same trajectory gives
the same bytes (the header holds no date and no sample count: the file is written while
the plan is made). ``docs/outputs.md`` gives the HAL lines that play it.
"""

from __future__ import annotations

from typing import BinaryIO

import numpy as np

#: the file name ending that selects this format (``cnc-interp plan -o PLAN.halstream``)
HALSTREAM_SUFFIX = ".halstream"
#: nanoseconds per second: HAL thread periods are given in ns
NS_PER_S = 1_000_000_000


def header(axes: str, dt_s: float) -> bytes:
    """The comment lines that open the file: columns, units, period and HAL lines."""
    period_ns = round(dt_s * NS_PER_S)
    units = ", ".join(f"{a} {'deg' if a in 'ABC' else 'mm'}" for a in axes)
    lines = (
        "# cnc-interp plan for LinuxCNC halstreamer: one line per servo period",
        f"# columns: {' '.join(axes)} ({units}), streamer.0.pin.0 to .{len(axes) - 1}",
        f"# period: {dt_s!r} s = {period_ns} ns (the thread that runs streamer.0)",
        f"# loadrt streamer depth=... cfg={'f' * len(axes)}",
    )
    return ("\n".join(lines) + "\n").encode("ascii")


def format_positions(q: np.ndarray) -> bytes:
    """Rows of ``q`` (K, n) as K lines of n space-separated numbers (``repr`` of each)."""
    from ._repr import format_table

    return format_table(np.asarray(q, dtype=float).T).replace(b",", b" ")


class HalstreamPlanWriter:
    """Writes a plan as a halstreamer file while it is planned: the header, then ``write``
    blocks of samples in order (the same signature as ``CsvPlanWriter.write``)."""

    def __init__(self, fh: BinaryIO, axes: str, dt_s: float):
        self.fh = fh
        self.rows = 0
        fh.write(header(axes, dt_s))

    def write(self, t, s, feed, q) -> None:
        """Append the positions ``q`` (K, n) of K samples (t, s and feed are not written)."""
        q = np.asarray(q, dtype=float)
        self.fh.write(format_positions(q))
        self.rows += q.shape[0]


def write_halstream_to(traj, fh: BinaryIO) -> int:
    """Write ``traj`` as a halstreamer file to an open binary file; returns the rows."""
    w = HalstreamPlanWriter(fh, traj.axes, traj.dt_s)
    w.write(traj.t, traj.s, traj.feed, traj.q)
    return w.rows


def read_halstream(path: str) -> np.ndarray:
    """The positions of a halstreamer file, (K, n) (comment lines skipped), for tests and
    checks."""
    rows = []
    with open(path, "rb") as fh:
        for line in fh:
            if line.startswith(b"#") or not line.strip():
                continue
            rows.append([float(x) for x in line.split()])
    return np.asarray(rows, dtype=float)

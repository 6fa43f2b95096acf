"""Size and write speed of the MCAP output against the CSV of the same plan.

Usage:
    python benchmarks/export_mcap.py [SAMPLES]          synthetic smooth XYZ plan (default 10^6)
    python benchmarks/export_mcap.py PART.ngc [MACHINE] plan a part program first (not timed)
    python benchmarks/export_mcap.py PLAN.csv [MACHINE] a plan written by `cnc-interp plan`
                                                        (a CSV has no source lines: no segments)

Prints, for CSV and MCAP (with /limits when a machine is known): seconds, samples/s,
messages/s, file size and the MCAP's time and size against the CSV's and against the CSV
compressed with zstd (level 3, the ``zstd`` tool's default); then the MCAP read-back time.
Writes them to ``benchmarks/RESULTS.md`` (its "MCAP against CSV" section) unless
``--no-write``.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time

import numpy as np
import zstandard

from cnc_interp.export.csv_io import read_csv, write_csv
from cnc_interp.export.mcap_io import read_mcap, write_mcap
from cnc_interp.machine.model import Machine
from cnc_interp.plan.trajectory import Trajectory

from _results import command_line, md_table, write_section

#: zstd level of the compressed CSV compared with (the zstd tool's default)
ZSTD_LEVEL = 3


def synthetic(k: int) -> tuple[Trajectory, Machine]:
    """A helical arc over k samples at 1 ms (smooth, full-precision numbers)."""
    dt = 1e-3
    t = np.arange(k) * dt
    tau = t / t[-1]
    u = tau**4 * (35 - 84 * tau + 70 * tau**2 - 20 * tau**3)
    phi = 40 * np.pi * u
    q = np.column_stack([123.4 + 50 * np.cos(phi), -77.7 + 50 * np.sin(phi), -3.0 * u])
    step = np.linalg.norm(np.diff(q, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(step)])
    feed = np.concatenate([[0.0], step / dt])
    line = 10 + (u * 5000).astype(np.int64)
    traj = Trajectory(axes="XYZ", dt_s=dt, t=t, s=s, feed=feed, q=q, line=line, planner="bench")
    machine = Machine(name="bench", axes="XYZ", vmax=[500.0] * 3, amax=[5000.0] * 3, jmax=[50000.0] * 3, dt_s=dt)
    return traj, machine


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def main() -> None:
    no_write = "--no-write" in sys.argv
    argv = [a for a in sys.argv if a != "--no-write"]
    arg = argv[1] if len(argv) > 1 else "1000000"
    if arg.isdigit():
        traj, machine = synthetic(int(arg))
        name = f"synthetic helix, {traj.n_samples:,} samples"
    elif arg.lower().endswith(".csv"):
        traj = read_csv(arg)
        machine = None
        if len(argv) > 2:
            from cnc_interp.machine.load import load_machine

            machine = load_machine(argv[2])
        name = f"{os.path.basename(arg)}, {traj.n_samples:,} samples, axes {traj.axes}"
    else:
        from cnc_interp.pipeline import plan_part

        outcome, tp = timed(lambda: plan_part(arg, argv[2] if len(argv) > 2 else None))
        traj, machine = outcome.trajectory, outcome.machine
        name = (
            f"{os.path.basename(arg)} on {machine.name}: {traj.n_samples:,} samples, "
            f"axes {traj.axes} (planned in {tp:.1f} s)"
        )
    k = traj.n_samples
    print(name)
    with tempfile.TemporaryDirectory() as d:
        csv_path, mcap_path = os.path.join(d, "p.csv"), os.path.join(d, "p.mcap")
        write_csv(traj, csv_path)  # once untimed: the formatter's kernels load on first use
        _, tc = timed(lambda: write_csv(traj, csv_path))
        csv_mb = os.path.getsize(csv_path) / 1e6
        with open(csv_path, "rb") as fh:
            zst_mb = len(zstandard.ZstdCompressor(level=ZSTD_LEVEL).compress(fh.read())) / 1e6
        print(f"  CSV : {tc:6.2f} s  {k / tc:>10,.0f} rows/s  {csv_mb:8.1f} MB, zstd -{ZSTD_LEVEL}: {zst_mb:.1f} MB")
        table = [
            ["CSV write", f"{tc:.2f} s", f"{k / tc:,.0f}", "", f"{csv_mb:.1f} MB", "1", "1"],
            [f"CSV + zstd -{ZSTD_LEVEL} (size only)", "", "", "", f"{zst_mb:.1f} MB", "", f"{zst_mb / csv_mb:.2f}"],
        ]
        for m, label in ((None, "MCAP (setpoints + segments)"), (machine, "MCAP (+ /limits)")):
            if label.endswith("limits)") and machine is None:
                continue
            n, tm = timed(lambda: write_mcap(traj, mcap_path, {"input": {"name": name}}, m))
            mb = os.path.getsize(mcap_path) / 1e6
            print(
                f"  {label}: {tm:6.2f} s  {k / tm:>10,.0f} samples/s  {n / tm:>10,.0f} msg/s  "
                f"{mb:8.1f} MB  ({n:,} messages): {tm / tc:.2f}x the CSV's time, "
                f"{mb / zst_mb:.2f}x the zstd CSV's size"
            )
            table.append(
                [
                    f"{label} write",
                    f"{tm:.2f} s",
                    f"{k / tm:,.0f}",
                    f"{n / tm:,.0f}",
                    f"{mb:.1f} MB",
                    f"{tm / tc:.2f}",
                    f"{mb / csv_mb:.2f} ({mb / zst_mb:.2f} of zstd)",
                ]
            )
        _, tr = timed(lambda: read_mcap(mcap_path))
        print(f"  MCAP read back: {tr:6.2f} s  {k / tr:>10,.0f} samples/s")
        table.append(["MCAP read back", f"{tr:.2f} s", f"{k / tr:,.0f}", "", "", f"{tr / tc:.2f}", ""])
    if not no_write:
        write_section(
            "MCAP against CSV",
            "export_mcap.py",
            command_line("export_mcap.py"),
            md_table(["step", "wall", "samples/s", "messages/s", "size", "time / CSV", "size / CSV"], table),
            f"Plan: {name}. MCAP: ros1 messages (packed float64 setpoints, float32 limit ratios), "
            "zstd level-1 chunks of 4 MiB, message indexes; /limits one message per 10 samples.",
        )


if __name__ == "__main__":
    main()

"""Speed of `verify` and of the plan CSV writer/reader.

Usage: python benchmarks/verify_csv.py [ROWS] [--no-write]   (default 1,000,000 rows, 6 axes)
Prints samples/s for verify and rows/s + MB/s for CSV write and read, then the wall time of
the whole `cnc-interp verify` and `cnc-interp plot` commands on that file (the figures a user
waits for; the target is under 10 s each at 5.6 M rows), and writes them to
``benchmarks/RESULTS.md`` (its "verify and the CSV reader" section) unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from cnc_interp.export.csv_io import read_csv, write_csv
from cnc_interp.plan.trajectory import Trajectory
from cnc_interp.plan.verify import verify_arrays

from _results import command_line, md_table, write_section


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rows", nargs="?", type=int, default=1_000_000, help="samples (default 1,000,000)")
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    k = args.rows
    axes = "XYZABC"
    dt = 1e-3
    rng = np.random.default_rng(0)
    # smooth-ish positions with realistic magnitudes (hundreds of mm, full digits)
    q = np.cumsum(np.cumsum(rng.normal(size=(k, len(axes))), axis=0), axis=0) * 1e-6 + 123.456
    s = np.cumsum(np.abs(rng.normal(size=k))) * 1e-2
    tr = Trajectory(
        axes=axes,
        dt_s=dt,
        t=np.arange(k) * dt,
        s=s,
        feed=np.concatenate([[0.0], np.diff(s) / dt]),
        q=q,
        line=np.zeros(k, dtype=int),
        planner="bench",
    )
    t0 = time.perf_counter()
    verify_arrays(q, dt, 1e9, 1e9, 1e9, axes=axes)
    tv = time.perf_counter() - t0
    print(f"verify: {k:,} samples x {len(axes)} axes in {tv:.3f} s = {k / tv / 1e6:.1f} M samples/s")
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "plan.csv")
        t0 = time.perf_counter()
        write_csv(tr, path)
        tw = time.perf_counter() - t0
        size = os.path.getsize(path) / 1e6
        print(
            f"csv write: {k:,} rows x {3 + len(axes)} cols in {tw:.2f} s = "
            f"{k / tw / 1e3:.0f} k rows/s, {size / tw:.0f} MB/s ({size:.0f} MB)"
        )
        t0 = time.perf_counter()
        back = read_csv(path)
        tr_ = time.perf_counter() - t0
        assert np.array_equal(back.q, q)
        print(f"csv read:  {k:,} rows in {tr_:.2f} s = {k / tr_ / 1e3:.0f} k rows/s (bit-exact)")
        machine = os.path.join(d, "m.toml")
        with open(machine, "w") as fh:
            for a in axes:
                fh.write(f"[axes.{a}]\nvmax = 1e6\namax = 1e9\njmax = 1e13\n")
            # the plan starts where the machine does (verify checks it)
            fh.write("[start]\n" + "".join(f"{a} = {float(v)!r}\n" for a, v in zip(axes, q[0])))
        table = [
            ["verify_arrays", f"{tv:.3f} s", f"{k / tv / 1e6:.1f} M samples/s", ""],
            ["CSV write", f"{tw:.2f} s", f"{k / tw / 1e3:.0f} k rows/s, {size / tw:.0f} MB/s", f"{size:.0f} MB"],
            ["CSV read", f"{tr_:.2f} s", f"{k / tr_ / 1e3:.0f} k rows/s", "bit-exact"],
        ]
        exe = os.path.join(os.path.dirname(sys.executable), "cnc-interp")
        for cmd in (["verify", path, "-m", machine], ["plot", path, "-m", machine, "-o", os.path.join(d, "p.png")]):
            t0 = time.perf_counter()
            r = subprocess.run([exe, *cmd], capture_output=True)
            dt_cmd = time.perf_counter() - t0
            print(f"cnc-interp {cmd[0]}: {k:,} rows in {dt_cmd:.2f} s wall (exit {r.returncode})")
            table.append([f"`cnc-interp {cmd[0]}`", f"{dt_cmd:.2f} s", "whole command", f"exit {r.returncode}"])
    if not args.no_write:
        write_section(
            "verify and the CSV reader",
            "verify_csv.py",
            command_line("verify_csv.py", argv),
            md_table(["step", "wall", "rate", "note"], table),
            f"{k:,} synthetic samples of {len(axes)} axes ({axes}) at 1 ms.",
        )


if __name__ == "__main__":
    main()

"""Speed of `verify` and of the plan CSV writer/reader.

Usage: python benchmarks/verify_csv.py [ROWS]   (default 1,000,000 rows, 6 axes)
Prints samples/s for verify and rows/s + MB/s for CSV write and read.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time

import numpy as np

from cnc_interp.export.csv_io import read_csv, write_csv
from cnc_interp.plan.trajectory import Trajectory
from cnc_interp.plan.verify import verify_arrays


def main() -> None:
    k = int(sys.argv[1]) if len(sys.argv) > 1 else 1_000_000
    axes = "XYZABC"
    dt = 1e-3
    rng = np.random.default_rng(0)
    # smooth-ish positions with realistic magnitudes (hundreds of mm, full digits)
    q = np.cumsum(np.cumsum(rng.normal(size=(k, len(axes))), axis=0), axis=0) * 1e-6 + 123.456
    s = np.cumsum(np.abs(rng.normal(size=k))) * 1e-2
    tr = Trajectory(axes=axes, dt_s=dt, t=np.arange(k) * dt, s=s,
                    feed=np.concatenate([[0.0], np.diff(s) / dt]), q=q,
                    line=np.zeros(k, dtype=int), planner="bench")
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
        print(f"csv write: {k:,} rows x {3 + len(axes)} cols in {tw:.2f} s = "
              f"{k / tw / 1e3:.0f} k rows/s, {size / tw:.0f} MB/s ({size:.0f} MB)")
        t0 = time.perf_counter()
        back = read_csv(path)
        tr_ = time.perf_counter() - t0
        assert np.array_equal(back.q, q)
        print(f"csv read:  {k:,} rows in {tr_:.2f} s = {k / tr_ / 1e3:.0f} k rows/s (bit-exact)")


if __name__ == "__main__":
    main()

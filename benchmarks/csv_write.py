"""CSV writing speed: the plan writer's compiled ``repr`` formatter on plan-like columns.

    .venv/bin/python benchmarks/csv_write.py [ROWS] [OUT] [--no-write]

Builds ROWS (default 4,000,000) samples of a 3-axis plan (t = k*dt, s, feed, X and Y
moving along arcs, Z mostly at rest, as in a 2.5D program) and writes them with
``CsvPlanWriter`` (blocks of 65,536 rows, as ``cnc-interp plan`` does) to OUT
(default /dev/null), then checks a sample of rows against Python's ``repr``. Prints
MB/s on wall and CPU time (the CPU figure is the steadier one on a shared machine) and
writes them to ``benchmarks/RESULTS.md`` (its "CSV writer" section) unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from _results import command_line, md_table, write_section

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))


def columns(rows: int, dt: float = 0.001):
    k = np.arange(rows)
    t = k * dt
    ang = 0.002 * k
    x = 50.0 + 30.0 * np.cos(ang)
    y = 40.0 + 30.0 * np.sin(ang)
    z = np.where((k // 20000) % 2 == 0, -1.5, 5.0)  # at rest, with occasional moves
    z = z + np.where((k % 20000) < 300, 0.01 * (k % 300), 0.0)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    feed = np.concatenate([[0.0], np.diff(s) / dt])
    return t, s, feed, np.stack([x, y, z], axis=1)


def main(argv=None) -> int:
    from cnc_interp.export.csv_io import CsvPlanWriter

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rows", nargs="?", type=int, default=4_000_000, help="samples (default 4,000,000)")
    ap.add_argument("out", nargs="?", default=os.devnull, help="output file (default /dev/null)")
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    rows, out = args.rows, args.out
    t, s, feed, q = columns(rows)
    # compile / load the formatter outside the measurement
    with open(os.devnull, "wb") as fh:
        CsvPlanWriter(fh, "XYZ").write(t[:10], s[:10], feed[:10], q[:10])
    block = 65536
    w0, c0 = time.perf_counter(), time.process_time()
    with open(out, "wb", buffering=1 << 20) as fh:
        w = CsvPlanWriter(fh, "XYZ")
        for a in range(0, rows, block):
            b = min(rows, a + block)
            w.write(t[a:b], s[a:b], feed[a:b], q[a:b])
        size = fh.tell() if out != os.devnull else None
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    if size is None:
        from cnc_interp.export.csv_io import format_rows

        size = sum(
            len(format_rows(np.stack([t[a : a + block], s[a : a + block], feed[a : a + block], *q[a : a + block].T])))
            for a in range(0, rows, block)
        ) + len(b"t,s,feed,X,Y,Z\n")
    print(
        f"{rows} rows, {size / 1e6:.0f} MB: {size / wall / 1e6:.0f} MB/s wall "
        f"({rows / wall / 1e6:.2f} M rows/s), {size / cpu / 1e6:.0f} MB/s CPU "
        f"(load {os.getloadavg()[0]:.1f})"
    )
    rng = np.random.default_rng(0)
    from cnc_interp.export.csv_io import format_rows

    for i in rng.integers(0, rows, 200).tolist():
        text = format_rows(np.array([[t[i]], [s[i]], [feed[i]], *q[i : i + 1].T])).decode()
        want = ",".join(repr(float(v)) for v in (t[i], s[i], feed[i], *q[i])) + "\n"
        assert text == want, (text, want)
    if not args.no_write:
        table = md_table(
            ["rows", "axes", "MB", "target", "MB/s wall", "M rows/s wall", "MB/s CPU", "200 rows as repr"],
            [
                [
                    f"{rows:,}",
                    "XYZ",
                    f"{size / 1e6:.0f}",
                    "/dev/null" if out == os.devnull else "file",
                    f"{size / wall / 1e6:.0f}",
                    f"{rows / wall / 1e6:.2f}",
                    f"{size / cpu / 1e6:.0f}",
                    "same",
                ]
            ],
        )
        write_section("CSV writer", "csv_write.py", command_line("csv_write.py", argv), table)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Fit-stage throughput: nodes fitted per second (best of several runs).

Usage: .venv/bin/python benchmarks/fit.py [FILE.ngc ...] [--tol MM] [--method nodes|planar|auto] [--repeat N]
                                          [--threads N] [--no-write]

Defaults to two corpus files of dense CAM segments (circle_small_segments_ncd.ngc and
3D_Chips.ngc). Parsing is excluded from the timing; building the Paths (their
arc-length tables) is included. Numba kernels are compiled (or loaded from the
cache) by one warm-up run that is not timed. Wall time and CPU time (process_time)
are both reported (best and median of the runs): on a shared machine the CPU figure is the
steadier one. ``--threads``: the batch fitter's worker threads (default: ``fit_program``'s,
the CPUs this process may use, at most 4).
``path/tol`` is the largest distance of the programmed path (moves and exact
curves, sampled densely) from the fitted path over its tolerance: <= 1 is within.
Writes the table to ``benchmarks/RESULTS.md`` (its "Fit" section) unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from _results import command_line, md_table, write_section

CORPUS = os.environ.get(
    "CNC_CORPUS",
    os.path.normpath(
        os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "corpus", "linuxcnc")
    ),
)
DEFAULT_FILES = [
    os.path.join(CORPUS, "performance", "circle_small_segments_ncd.ngc"),
    os.path.join(CORPUS, "performance", "3D_Chips.ngc"),
]


def main(argv=None) -> int:
    from cnc_interp.fit import FitSettings, fit_program
    from cnc_interp.fit.report import fit_statistics
    from cnc_interp.gcode import read_program

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*", default=DEFAULT_FILES)
    ap.add_argument("--tol", type=float, default=None, help="fit tolerance, mm (default 0.001)")
    ap.add_argument("--method", default="nodes", choices=("nodes", "planar", "auto"))
    ap.add_argument("--repeat", type=int, default=10)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    table = []
    settings = FitSettings.from_options(tol_mm=args.tol, method=args.method)
    from cnc_interp.fit import fitter

    fitter._kernels_ready = True  # the batch fitter whatever the run's length (compiled in the warm-up)
    print(
        f"{'file':40s} {'nodes':>8s} {'segs':>7s} {'seg/node':>8s} {'best s':>8s} {'nodes/s':>10s} "
        f"{'median s':>8s} {'cpu s':>8s} {'nodes/cpu-s':>11s} {'max dev mm':>10s} {'path/tol':>8s}"
    )
    for f in args.files:
        with open(f, "rb") as fh:
            prog = read_program(fh.read(), source=f)
        fit_program(prog, settings, threads=args.threads)  # warm-up: numba compile / cache load
        walls = []
        best_cpu = float("inf")
        for _ in range(args.repeat):
            t0, c0 = time.perf_counter(), time.process_time()
            res = fit_program(prog, settings, threads=args.threads)
            walls.append(time.perf_counter() - t0)
            best_cpu = min(best_cpu, time.process_time() - c0)
        best = min(walls)
        median = sorted(walls)[len(walls) // 2]
        st = fit_statistics(res)
        n = st["nodes_in"]
        print(
            f"{os.path.basename(f)[:40]:40s} {n:8d} {st['segments_out']:7d} {st['segments_per_node']:8.3f} "
            f"{best:8.3f} {n / best:10.0f} {median:8.3f} {best_cpu:8.3f} {n / best_cpu:11.0f} "
            f"{st['max_node_dev_mm']:10.2e} {st['max_path_dev_ratio']:8.4f}"
        )
        table.append(
            [
                os.path.basename(f),
                n,
                st["segments_out"],
                f"{st['segments_per_node']:.3f}",
                f"{best:.3f}",
                f"{n / best:,.0f}",
                f"{median:.3f}",
                f"{best_cpu:.3f}",
                f"{n / best_cpu:,.0f}",
                f"{st['max_node_dev_mm']:.2e}",
                f"{st['max_path_dev_ratio']:.4f}",
            ]
        )
    if not args.no_write:
        write_section(
            "Fit",
            "fit.py",
            command_line("fit.py", argv),
            md_table(
                [
                    "file",
                    "nodes",
                    "segments",
                    "seg/node",
                    "best s",
                    "nodes/s",
                    "median s",
                    "CPU s",
                    "nodes/CPU-s",
                    "max dev mm",
                    "path/tol",
                ],
                table,
            ),
            f"Method {args.method}, tolerance {args.tol or 0.001} mm, {args.repeat} runs (parsing excluded); "
            "path/tol <= 1 is within the tolerance.",
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())

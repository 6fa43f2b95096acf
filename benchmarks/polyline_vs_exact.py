"""Polyline vs exact: cycle time of a CAM polyline against the same curve given
exactly, under one machine.

    .venv/bin/python benchmarks/polyline_vs_exact.py                    # mikron-ucp710
    .venv/bin/python benchmarks/polyline_vs_exact.py --fit-method planar --json out.json
    .venv/bin/python benchmarks/polyline_vs_exact.py --no-write                # print only

For every case of ``tests/_polyline_cases.py`` (NURBS, arcs, a helix, a spiral, a
5-axis arc) and every chord error (1, 5, 10 µm; coordinates rounded to 4 decimals;
both programs with ``G64 P<chord error>``) it plans the exact program and the
polyline with VPOp and prints both cycle times and their ratio (target <= 1.02), and
writes the table to ``benchmarks/RESULTS.md`` (its "Polyline against exact" section).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

from _results import command_line, md_table, write_section

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))


def plan_text(text: str, machine: str, fit_method: str | None, workdir: str, name: str):
    from cnc_interp.pipeline import plan_part

    path = os.path.join(workdir, name + ".ngc")
    with open(path, "w") as fh:
        fh.write(text)
    t0 = time.process_time()
    out = plan_part(path, machine, "vpop", None, fit_method=fit_method)
    return out, time.process_time() - t0


def main(argv=None) -> None:
    from tests._polyline_cases import CHORD_ERRORS_MM, cases, exact_program, polyline_program

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-m", "--machine", default="mikron-ucp710")
    ap.add_argument("--fit-method", default=None)
    ap.add_argument("--case", action="append", default=None, help="only these cases (repeatable)")
    ap.add_argument("--json", default=None)
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    rows = []
    names = args.case or list(cases())
    print(
        f"{'case':16s} {'chord':>6s} {'nodes':>6s} {'exact s':>9s} {'polyline s':>10s} {'ratio':>7s} "
        f"{'segments':>8s} {'cpu s':>6s}"
    )
    with tempfile.TemporaryDirectory() as d:
        for name in names:
            for e in CHORD_ERRORS_MM:
                ex, _ = plan_text(exact_program(name, e), args.machine, args.fit_method, d, "exact")
                poly_text = polyline_program(name, e)
                po, cpu = plan_text(poly_text, args.machine, args.fit_method, d, "poly")
                te, tp = ex.trajectory.duration_s, po.trajectory.duration_s
                nodes = poly_text.count("\nG1 ")
                segs = po.fit_stats.get("segments_out")
                row = dict(
                    case=name,
                    chord_mm=e,
                    nodes=nodes,
                    exact_s=te,
                    polyline_s=tp,
                    ratio=tp / te,
                    segments=segs,
                    cpu_s=cpu,
                    fit_method=po.fit_stats.get("method"),
                )
                rows.append(row)
                print(
                    f"{name:16s} {e * 1000:4.0f}µm {nodes:6d} {te:9.3f} {tp:10.3f} {tp / te:7.4f} {segs:8d} {cpu:6.2f}",
                    flush=True,
                )
    worst = max(r["ratio"] for r in rows)
    total_e = sum(r["exact_s"] for r in rows)
    total_p = sum(r["polyline_s"] for r in rows)
    print(f"worst ratio {worst:.4f}; total exact {total_e:.3f} s, polyline {total_p:.3f} s ({total_p / total_e:.4f})")
    if not args.no_write:
        table = md_table(
            ["case", "chord error", "nodes", "exact s", "polyline s", "ratio", "segments", "CPU s"],
            [
                [
                    r["case"],
                    f"{r['chord_mm'] * 1000:.0f} µm",
                    r["nodes"],
                    f"{r['exact_s']:.3f}",
                    f"{r['polyline_s']:.3f}",
                    f"{r['ratio']:.4f}",
                    r["segments"],
                    f"{r['cpu_s']:.2f}",
                ]
                for r in rows
            ],
        )
        write_section(
            "Polyline against exact",
            "polyline_vs_exact.py",
            command_line("polyline_vs_exact.py", argv),
            table,
            f"Machine {args.machine}, VPOp, fit method {args.fit_method or 'auto'}. Worst ratio {worst:.4f} "
            f"(target <= 1.02); total exact {total_e:.3f} s, polyline {total_p:.3f} s ({total_p / total_e:.4f}).",
        )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)


if __name__ == "__main__":
    main()

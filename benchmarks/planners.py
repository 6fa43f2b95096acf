"""Cycle time of the three planners side by side: constant, variable (paper 000), VPOp (paper 001).

Usage: python benchmarks/planners.py [PROGRAM[@PRESET] ...] [--dt S] [--tol MM] [--feed F]
                                    [--json FILE] [--no-write]

Each program is parsed and fitted once; the same fit is then planned by every planner
(``plan.timeline.plan_program``) and the result checked with ``verify``. Prints a
Markdown table: cycle time per planner (s), the planners' wall time, and the worst
limit ratio of each plan. Without arguments it runs the trident of paper 001 on the
Mikron UCP 710 preset and a handful of corpus programs. Writes the table to
``benchmarks/RESULTS.md`` (its "Planners side by side" section) unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import time

from _results import command_line, write_section

HERE = os.path.dirname(os.path.abspath(__file__))
CORPUS = os.path.normpath(os.path.join(HERE, "..", "..", "shared", "corpus", "linuxcnc"))
PLANNERS = ("constant", "variable", "vpop")
DEFAULT_PROGRAMS = (
    "nurbs-g5/trident-xy.ngc@mikron-ucp710",
    "nurbs-g5/butterfly-xy.ngc@mikron-ucp710",
    "nurbs-g5/leto-xy.ngc@mikron-ucp710",
    "arc-feed/full_xy.ngc@generic-mill",
    "examples/daisy.ngc@mikron-ucp710",
    "performance/spiral_lines.ngc@generic-mill",
    "performance/tight-corner-tolerance.ngc@generic-mill",
)


def _with_feed(data: bytes, feed_mm_min: float) -> bytes:
    """The program with every F word replaced by ``feed_mm_min`` (benchmark what-if)."""
    return re.sub(rb"([Ff])\s*[-+]?[0-9]*\.?[0-9]+", b"F%r" % feed_mm_min, data)


def run_one(spec: str, dt_s: float | None, tol_mm: float | None, feed_mm_min: float | None = None) -> dict:
    """Parse and fit ``spec`` (PATH[@PRESET]) once, plan it with every planner."""
    from cnc_interp.errors import CncInterpError
    from cnc_interp.fit.settings import FitSettings
    from cnc_interp.gcode import read_program
    from cnc_interp.pipeline import fit_loaded
    from cnc_interp.machine.load import load_machine
    from cnc_interp.plan.settings import PlanSettings
    from cnc_interp.plan.timeline import plan_program
    from cnc_interp.plan.verify import verify

    path, _, preset = spec.partition("@")
    full = path if os.path.isabs(path) else os.path.join(CORPUS, path)
    machine = load_machine(preset or "mikron-ucp710")
    row = {
        "program": path + ("" if feed_mm_min is None else f" (F{feed_mm_min:g})"),
        "machine": preset or "mikron-ucp710",
    }
    try:
        base = PlanSettings.from_options(planner="vpop", dt_s=dt_s, tol_mm=tol_mm, machine=machine)
        machine = machine.with_dt(base.dt_s)
        with open(full, "rb") as fh:
            data = fh.read()
        if feed_mm_min is not None:
            data = _with_feed(data, feed_mm_min)
        program = read_program(data, source=full, axes=machine.axes, start=machine.start)
        t0 = time.perf_counter()
        fitted = fit_loaded(program, FitSettings.from_options(tol_mm=tol_mm, machine=machine))
        row["fit_s"] = time.perf_counter() - t0
        row["segments"] = sum(int(p.n_seg) for p in fitted.paths)
        row["dt_s"] = base.dt_s
    except CncInterpError as exc:
        row["error"] = exc.format()
        return row
    for name in PLANNERS:
        settings = PlanSettings.from_options(planner=name, dt_s=base.dt_s, tol_mm=tol_mm, machine=machine)
        try:
            t0 = time.perf_counter()
            traj = plan_program(fitted, machine, settings)
            wall = time.perf_counter() - t0
            rep = verify(traj, machine)
            row[name] = {
                "cycle_s": traj.duration_s,
                "plan_wall_s": wall,
                "worst_ratio": rep.worst_ratio,
                "samples": traj.n_samples,
                "length_mm": float(traj.s[-1]) if traj.n_samples else 0.0,
            }
        except CncInterpError as exc:
            row[name] = {"error": exc.format()}
    return row


def _cell(res: dict | None, key: str, fmt: str) -> str:
    if not res:
        return "-"
    if "error" in res:
        return "error"
    return format(res[key], fmt)


def table(rows: list[dict]) -> str:
    head = (
        "| program | machine | segments | constant (s) | variable (s) | VPOp (s) "
        "| plan wall c / v / p (s) | worst ratio c / v / p |"
    )
    out = [head, "|" + "---|" * 8]
    for r in rows:
        if "error" in r:
            out.append(f"| {r['program']} | {r['machine']} | error: {r['error']} |||||| ")
            continue
        cyc = [_cell(r.get(p), "cycle_s", ".3f") for p in PLANNERS]
        wall = " / ".join(_cell(r.get(p), "plan_wall_s", ".2f") for p in PLANNERS)
        worst = " / ".join(_cell(r.get(p), "worst_ratio", ".4f") for p in PLANNERS)
        out.append(
            f"| {r['program']} | {r['machine']} | {r['segments']} | {cyc[0]} | {cyc[1]} | {cyc[2]} | {wall} | {worst} |"
        )
    return "\n".join(out)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("programs", nargs="*", default=list(DEFAULT_PROGRAMS))
    ap.add_argument("--dt", type=float, default=None, help="sample period, s (default: machine's)")
    ap.add_argument("--tol", type=float, default=None, help="fit tolerance, mm")
    ap.add_argument("--json", default=None, help="also write the raw rows as JSON here")
    ap.add_argument(
        "--feed",
        type=float,
        default=None,
        help="what-if: replace every F word by this feed (mm/min or the program's units)",
    )
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    rows = []
    for spec in args.programs:
        rows.append(run_one(spec, args.dt, args.tol, args.feed))
        print(f"done {spec}", flush=True)
    print(table(rows))
    errors = {
        r["program"]: {p: r[p]["error"] for p in PLANNERS if "error" in r.get(p, {})} for r in rows if "error" not in r
    }
    for prog, errs in errors.items():
        for p, msg in errs.items():
            print(f"{prog} [{p}]: {msg}")
    if not args.no_write:
        notes = [f"{prog} [{p}]: {msg}" for prog, errs in errors.items() for p, msg in errs.items()]
        write_section(
            "Planners side by side",
            "planners.py",
            command_line("planners.py", argv),
            table(rows),
            "Cycle time per planner (c constant, v variable, p VPOp), each plan checked by `verify`."
            + ("\n\n" + "\n".join(f"- {n}" for n in notes) if notes else ""),
        )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)


if __name__ == "__main__":
    main()

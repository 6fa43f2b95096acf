"""Planning speed and near-optimality: setpoints per second and "x real time".

    .venv/bin/python benchmarks/plan.py                  # trident + a corpus selection
    .venv/bin/python benchmarks/plan.py --sweep          # every corpus program (slow)
    .venv/bin/python benchmarks/plan.py --json out.json
    .venv/bin/python benchmarks/plan.py --sweep --planner optimal --baseline vpop.json
    .venv/bin/python benchmarks/plan.py --no-write       # print only

For each program: parse + fit + plan (VPOp) + verify, with the plan stage timed on
its own (numba compiled beforehand; the selection keeps the fastest of ``--repeat`` runs).
"x real time" = cycle time / planning wall time.
The sweep plans every corpus program on a LinuxCNC configuration (``--ini``, default
jerk where the INI has none); a program that names an axis the INI lacks (A, B, ...) is
planned on the corpus INI with the fewest axes that has it (``XYZ.ini`` is XYZA,
``9axis.ini`` all nine). The corpus does not ship the tool tables its INIs name, so the
sweep gives every program a stand-in table of tools 1-99 with zero length and diameter.
It checks every limit and lists failures with their error message. Every run ends with the programs below
the 100x real-time target (and their share of the cycle); ``--baseline`` an earlier
run's ``--json`` (VPOp's sweep, or one from an older checkout) compares the total plan time
and cycle of the programs both planned. The table goes to ``benchmarks/RESULTS.md`` (section
"Planning speed, selection" or "Corpus sweep", per planner and effort) unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import sys
import tempfile
import time

from _results import command_line, md_table, write_section

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

CORPUS = os.environ.get(
    "CNC_CORPUS", os.path.join(os.path.dirname(__file__), "..", "..", "shared", "corpus", "linuxcnc")
)
TRIDENT = os.path.join(CORPUS, "nurbs-g5", "trident-xy.ngc")
#: the planning-speed target per 3-axis corpus program, x real time at 1 kHz
TARGET_X_REAL_TIME = 100.0
SELECTION = [
    ("nurbs-g5/trident-xy.ngc", "mikron-ucp710"),
    ("nurbs-g5/trident-xy.ngc", "generic-mill"),
    ("nurbs-g5/butterfly-xy.ngc", "generic-mill"),
    ("examples/3dtest.ngc", "generic-mill"),
    ("performance/cap.ngc", "generic-mill"),
    ("arc-feed", "generic-mill"),
]


def corpus_programs():
    exts = ("*.ngc", "*.nc", "*.gcode", "*.tap")
    files = []
    for e in exts:
        files += glob.glob(os.path.join(CORPUS, "**", e), recursive=True)
    return sorted(set(files))


#: corpus INIs to fall back on, fewest axes first, for programs naming an axis the sweep's INI lacks
AXIS_FALLBACK_INIS = ("XYZ.ini", "9axis.ini")
#: tools of the sweep's stand-in tool table (zero length and diameter)
STANDIN_TOOLS = range(1, 100)


def standin_tool_table(directory: str) -> str:
    """Write the sweep's stand-in LinuxCNC tool table into ``directory``; returns its path."""
    path = os.path.join(directory, "standin.tbl")
    with open(path, "w") as fh:
        fh.writelines(f"T{t} P{t} Z0 D0 ;stand-in\n" for t in STANDIN_TOOLS)
    return path


def sweep_one(path: str, ini: str, tool_table: str, planner: str, effort: str | None) -> dict:
    """``plan_one`` on ``ini``, or on the first fallback INI that has the program's axes."""
    rec = plan_one(path, ini, planner=planner, effort=effort, tool_table=tool_table)
    for name in AXIS_FALLBACK_INIS:
        if rec["status"] == "ok" or "is not on this machine" not in rec["message"]:
            break
        rec = plan_one(
            path, os.path.join(CORPUS, "configs", name), planner=planner, effort=effort, tool_table=tool_table
        )
    return rec


def plan_one(
    path: str,
    machine: str,
    dt_s: float | None = 0.001,
    optimality: bool = False,
    planner: str = "vpop",
    effort: str | None = None,
    tool_table: str | None = None,
) -> dict:
    from cnc_interp.errors import CncInterpError
    from cnc_interp.pipeline import plan_part

    t0 = time.perf_counter()
    try:
        c0 = time.process_time()
        out = plan_part(path, machine, planner, dt_s, effort=effort, tool_table=tool_table)
        cpu = time.process_time() - c0
    except CncInterpError as exc:
        return {
            "program": os.path.relpath(path, CORPUS),
            "machine": machine,
            "status": "error",
            "exit_code": exc.exit_code,
            "message": exc.format(),
            "wall_s": time.perf_counter() - t0,
        }
    traj = out.trajectory
    plan_s = out.timings["plan"]
    rec = {
        "program": os.path.relpath(path, CORPUS),
        "machine": machine,
        "status": "ok",
        "planner": planner,
        "effort": effort,
        "cpu_s": cpu,
        "samples": traj.n_samples,
        "cycle_time_s": traj.duration_s,
        "plan_s": plan_s,
        "setpoints_per_s": traj.n_samples / plan_s if plan_s else None,
        "x_real_time": traj.duration_s / plan_s if plan_s else None,
        "worst_ratio": out.report.worst_ratio,
        "timings": out.timings,
        "stats": traj.settings.get("stats", {}),
        "wall_s": time.perf_counter() - t0,
    }
    if optimality:
        from cnc_interp.plan.optimality import program_lower_bound

        lb = program_lower_bound(out)
        rec["lower_bound_s"] = lb
        rec["ratio_to_bound"] = traj.duration_s / lb if lb > 0 else None
    return rec


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sweep", action="store_true", help="every corpus program on a LinuxCNC INI")
    ap.add_argument("--ini", default=os.path.join(CORPUS, "configs", "axis_mm.ini"))
    ap.add_argument("--json", default=None)
    ap.add_argument(
        "--baseline",
        default=None,
        metavar="B.json",
        help="an earlier run's --json (another planner, or an older checkout): total plan "
        "time and cycle of the programs both planned, against it",
    )
    ap.add_argument("--planner", default="vpop", help="the per-path planner (default vpop)")
    ap.add_argument("--effort", default=None, help="the optimal planner's --effort (fast, normal, max)")
    ap.add_argument("--no-bound", action="store_true", help="skip the V/A lower bound")
    ap.add_argument(
        "--exclude",
        action="append",
        default=[],
        metavar="TEXT",
        help="skip sweep programs whose path contains TEXT (repeatable)",
    )
    ap.add_argument(
        "--repeat",
        type=int,
        default=3,
        help="selection runs per program; the fastest plan stage counts (a plan of "
        "a few tens of ms is dominated by first-run effects otherwise)",
    )
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    # compile once outside the timings
    plan_one(TRIDENT, "generic-mill", planner=args.planner, effort=args.effort)
    rows = []
    if args.sweep:
        with tempfile.TemporaryDirectory() as tmp:
            tool_table = standin_tool_table(tmp)
            for f in corpus_programs():
                if any(x in f for x in args.exclude):
                    continue
                rec = sweep_one(f, args.ini, tool_table, args.planner, args.effort)
                rows.append(rec)
                _print(rec)
    else:
        for rel, machine in SELECTION:
            targets = [os.path.join(CORPUS, rel)]
            if os.path.isdir(targets[0]):
                targets = sorted(glob.glob(os.path.join(targets[0], "*.ngc")))[:3]
            for f in targets:
                rec = plan_one(f, machine, optimality=not args.no_bound, planner=args.planner, effort=args.effort)
                for _ in range(max(args.repeat, 1) - 1):
                    again = plan_one(f, machine, planner=args.planner, effort=args.effort)
                    if again["status"] == "ok" and again["plan_s"] < rec["plan_s"]:
                        for key in ("plan_s", "setpoints_per_s", "x_real_time", "timings", "cpu_s"):
                            rec[key] = again[key]
                rows.append(rec)
                _print(rec)
    ok = [r for r in rows if r["status"] == "ok"]
    if ok:
        tot_cycle = sum(r["cycle_time_s"] for r in ok)
        tot_plan = sum(r["plan_s"] for r in ok)
        tot_cpu = sum(r.get("cpu_s", 0.0) for r in ok)
        tot_samples = sum(r["samples"] for r in ok)
        print(
            f"TOTAL {len(ok)}/{len(rows)} ok: {tot_samples} setpoints, cycle {tot_cycle:.2f} s, "
            f"plan {tot_plan:.2f} s -> {tot_samples / tot_plan:,.0f} setpoints/s, "
            f"{tot_cycle / tot_plan:.1f}x real time (process CPU {tot_cpu:.2f} s)"
        )
        # the target is per program: the slow ones, and how much of the cycle
        # they carry (programs that do not move are left out)
        slow = [r for r in ok if r["cycle_time_s"] > 0 and r["x_real_time"] < TARGET_X_REAL_TIME]
        slow_cycle = sum(r["cycle_time_s"] for r in slow)
        print(
            f"BELOW {TARGET_X_REAL_TIME:g}x: {len(slow)} programs, {slow_cycle:.2f} s of cycle "
            f"({100.0 * slow_cycle / max(tot_cycle, 1e-300):.1f} %), {sum(r['plan_s'] for r in slow):.2f} s of plan"
        )
        against = _compare(ok, args.baseline) if args.baseline else None
        if not args.no_write:
            _write(args, argv, rows, ok, tot_plan, tot_cycle, tot_cpu, tot_samples, slow, slow_cycle, against)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)


def _write(args, argv, rows, ok, tot_plan, tot_cycle, tot_cpu, tot_samples, slow, slow_cycle, against) -> None:
    """The run's section of RESULTS.md: per program for the selection, the totals for a sweep."""
    who = args.planner + (f", effort {args.effort}" if args.effort else "")
    summary = (
        f"Total: {len(ok)}/{len(rows)} planned, {tot_samples:,} setpoints, cycle {tot_cycle:,.2f} s, plan "
        f"{tot_plan:.2f} s ({tot_samples / tot_plan:,.0f} setpoints/s, {tot_cycle / tot_plan:.1f}x real time, "
        f"process CPU {tot_cpu:.2f} s). Below {TARGET_X_REAL_TIME:g}x real time: {len(slow)} programs, "
        f"{slow_cycle:.2f} s of cycle ({100.0 * slow_cycle / max(tot_cycle, 1e-300):.1f} %)."
    )
    if against:
        summary += " " + against
    if args.sweep:
        title = f"Corpus sweep, {who}"
        failed = [r for r in rows if r["status"] != "ok"]
        table = md_table(
            [
                "programs",
                "planned",
                "failed",
                "setpoints",
                "cycle",
                "plan",
                "x real time",
                f"below {TARGET_X_REAL_TIME:g}x",
            ],
            [
                [
                    len(rows),
                    len(ok),
                    len(failed),
                    f"{tot_samples:,}",
                    f"{tot_cycle:,.1f} s",
                    f"{tot_plan:.1f} s",
                    f"{tot_cycle / tot_plan:.1f}",
                    len(slow),
                ]
            ],
        )
        others = sorted({os.path.basename(r["machine"]) for r in rows} - {os.path.basename(args.ini)})
        notes = (
            f"Machine {os.path.basename(args.ini)}"
            + (f" ({', '.join(others)} for programs naming axes it lacks)" if others else "")
            + ", stand-in tool table, 1 ms. "
            + summary
        )
        if failed:
            notes += "\n\nFailed:\n\n" + "\n".join(f"- {r['program']}: {_reason(r['message'])}" for r in failed)
    else:
        title = f"Planning speed, selection, {who}"
        table = md_table(
            [
                "program",
                "machine",
                "samples",
                "cycle s",
                "plan s",
                "x real time",
                "CPU s",
                "worst ratio",
                "cycle / bound",
            ],
            [
                [
                    r["program"],
                    os.path.basename(r["machine"]),
                    r["samples"],
                    f"{r['cycle_time_s']:.3f}",
                    f"{r['plan_s']:.3f}",
                    f"{r['x_real_time']:.1f}",
                    f"{r.get('cpu_s', 0):.3f}",
                    f"{r['worst_ratio']:.9f}",
                    f"{r['ratio_to_bound']:.3f}" if r.get("ratio_to_bound") else "-",
                ]
                if r["status"] == "ok"
                else [r["program"], os.path.basename(r["machine"]), "error", r["message"].splitlines()[0][:80]]
                + [""] * 5
                for r in rows
            ],
        )
        notes = f"1 ms; plan stage fastest of {args.repeat}. " + summary
    write_section(title, "plan.py", command_line("plan.py", argv), table, notes)


def _reason(message: str) -> str:
    """An error message's first line without its file:line prefix."""
    first = message.strip().splitlines()[0] if message.strip() else "?"
    _, sep, rest = first.partition("error: ")
    return (rest if sep else first)[:100]


def _compare(ok: list, baseline_path: str) -> str:
    """Total plan time and cycle of the programs planned here and in the baseline run."""
    with open(baseline_path) as fh:
        base = {(r["program"], os.path.basename(r["machine"])): r for r in json.load(fh) if r.get("status") == "ok"}
    pairs = [(r, base[key]) for r in ok if (key := (r["program"], os.path.basename(r["machine"]))) in base]
    if not pairs:
        print(f"AGAINST {baseline_path}: no program in common")
        return f"Against {os.path.basename(baseline_path)}: no program in common."
    plan, plan0 = sum(r["plan_s"] for r, _ in pairs), sum(b["plan_s"] for _, b in pairs)
    cyc, cyc0 = sum(r["cycle_time_s"] for r, _ in pairs), sum(b["cycle_time_s"] for _, b in pairs)
    print(
        f"AGAINST {os.path.basename(baseline_path)} ({len(pairs)} programs): plan {plan:.2f} s vs "
        f"{plan0:.2f} s ({plan / max(plan0, 1e-300):.2f}x), cycle {cyc:.2f} s vs {cyc0:.2f} s "
        f"({100.0 * (cyc / max(cyc0, 1e-300) - 1.0):+.2f} %)"
    )
    worst = sorted(pairs, key=lambda p: p[1]["plan_s"] - p[0]["plan_s"])[:5]
    for r, b in worst:
        print(f"  {r['program']:48s} plan {r['plan_s']:8.2f} s vs {b['plan_s']:8.2f} s")
    return (
        f"Against {os.path.basename(baseline_path)} ({len(pairs)} programs): plan {plan:.2f} s vs {plan0:.2f} s, "
        f"cycle {cyc:.2f} s vs {cyc0:.2f} s ({100.0 * (cyc / max(cyc0, 1e-300) - 1.0):+.2f} %)."
    )


def _print(r: dict) -> None:
    if r["status"] != "ok":
        print(f"{r['program']:48s} {r['machine'][-20:]:>20s} ERROR {r['message'][:100]}", flush=True)
        return
    extra = f" bound-ratio {r['ratio_to_bound']:.3f}" if r.get("ratio_to_bound") else ""
    print(
        f"{r['program']:48s} {os.path.basename(r['machine'])[-20:]:>20s} {r['samples']:8d} samples "
        f"cycle {r['cycle_time_s']:8.3f} s plan {r['plan_s']:7.3f} s "
        f"{r['x_real_time']:7.1f}x RT cpu {r.get('cpu_s', 0):6.3f} s worst {r['worst_ratio']:.9f}{extra}",
        flush=True,
    )


if __name__ == "__main__":
    main()

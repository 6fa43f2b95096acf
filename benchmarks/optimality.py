"""Cycle time of each planner against the discrete-time minimum on the same path.

    .venv/bin/python benchmarks/optimality.py                     # every case, cached oracle
    .venv/bin/python benchmarks/optimality.py --cases trident-6ms line-1ms
    .venv/bin/python benchmarks/optimality.py --list
    .venv/bin/python benchmarks/optimality.py --json out.json --markdown

For each case (a program, a machine, a sample period): plan it with every planner
(``--planners``, default ``optimal vpop``; ``optimal:fast`` is the optimal planner at
``--effort fast``), write the plan as CSV, and run the oracle
``optimum_gap.py`` (``../shared/tools``; CasADi + IPOPT: a measuring tool, not a
dependency of the package; ``CNC_ORACLE_PYTHON`` names an interpreter that has them)
on the plan's main move: the longest run of samples in
which the machine moves, from rest to rest. The oracle rebuilds the geometry from the
plan's samples and computes the least number of periods that path can be run in
under the same limits. Its result depends on the path, not on the plan it was given,
so it runs once per case (on the first planner's plan) and is cached in
``--cache`` (default ``~/.cache/cnc-interp/optimality.json``, keyed on the case's
program, machine and period, and the fitted path's length: a change of the fit is a
new geometry) because it takes seconds to minutes per case.

The ratio of a planner is its main move's periods over the oracle's; the table goes to
``benchmarks/RESULTS.md`` (its "Optimality" section) unless ``--no-write``. Without the oracle
(no CasADi) and no cached optimum there is no ratio: the script says so and leaves the
section out. Programs come
inline (synthetic) or as excerpts of corpus files read in place (``CNC_CORPUS``).
CPU time of each plan stage is printed next to its wall time: the machine is shared.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import subprocess
import sys
import tempfile
import time

from _results import command_line, write_section

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

HERE = os.path.dirname(os.path.abspath(__file__))
CORPUS = os.environ.get("CNC_CORPUS", os.path.join(HERE, "..", "..", "shared", "corpus", "linuxcnc"))
ORACLE = os.environ.get("CNC_OPTIMUM_GAP", os.path.join(HERE, "..", "..", "shared", "tools", "optimum_gap.py"))
#: the interpreter that runs the oracle: one with CasADi (it is not the package's dependency,
#: so it may live in a separate environment)
ORACLE_PYTHON = os.environ.get("CNC_ORACLE_PYTHON", sys.executable)

MIKRON_TOML = """name = "Mikron UCP 710"
dt = 0.006
kinematics = "xyzac-trt"
[axes.X]
vmax = 500.0
amax = 2500.0
jmax = 5000.0
[axes.Y]
vmax = 500.0
amax = 3000.0
jmax = 5000.0
[axes.Z]
vmax = 500.0
amax = 2100.0
jmax = 50000.0
[axes.A]
vmax = 90.0
amax = 298.8
jmax = 1800.0
[axes.C]
vmax = 120.0
amax = 298.8
jmax = 36000.0
"""

MILL_TOML = """name = "Generic 3-axis mill"
dt = 0.001
kinematics = "trivial"
[axes.X]
vmax = 200.0
amax = 2000.0
jmax = 50000.0
[axes.Y]
vmax = 200.0
amax = 2000.0
jmax = 50000.0
[axes.Z]
vmax = 200.0
amax = 2000.0
jmax = 50000.0
"""

TRIDENT = """G21 G90 G17 G94
G0 X10 Y0
F2500
G5.2 P1 L4
    X10 Y0 P1
    X20 Y20 P1
    X12 Y8 P1
    X10 Y20 P1
    X8 Y8 P1
    X0 Y20 P1
    X10 Y0 P1
G5.3
M2
"""


def _trident_polyline() -> str:
    """The trident above as G1 chords: the parser's own sampling of the NURBS
    (chord error <= 0.25 um), written back as G1 moves."""
    from cnc_interp.gcode import read_program

    prog = read_program(TRIDENT.encode(), source="trident", axes="XYZ")
    run = max(prog.runs, key=lambda r: r.nodes.shape[0])
    lines = ["G21 G90 G17 G94", "G0 X10 Y0", "F2500"]
    for x, y, _ in run.nodes[1:]:
        lines.append(f"G1 X{x:.6f} Y{y:.6f}")
    lines.append("M2")
    return "\n".join(lines) + "\n"


def _five_axis() -> str:
    """268 G1 moves of a ball-nose sweep: XYZ a flattened helix, A tilting, C turning.
    The feed (F50000) does not bind: the oracle measures the feed on the joints' XYZ,
    not on the program's path as the planners do under xyzac-trt kinematics."""
    lines = ["G21 G90 G17 G94", "G0 X0 Y-20 Z0 A0 C0", "F50000"]
    for i in range(1, 269):
        u = i / 268.0
        ang = 2.0 * math.pi * u
        x = 20.0 * math.sin(ang)
        y = -20.0 * math.cos(ang) + 5.0 * u
        z = -3.0 * u + 1.5 * math.sin(3 * ang) * u
        a = -30.0 * math.sin(math.pi * u)
        c = 360.0 * u
        lines.append(f"G1 X{x:.4f} Y{y:.4f} Z{z:.4f} A{a:.4f} C{c:.4f}")
    lines.append("M2")
    return "\n".join(lines) + "\n"


def _excerpt(rel: str, head: int, lo: int, hi: int, feed: str | None = None) -> str:
    """Corpus lines 1..head (setup) plus lo..hi (1-based, inclusive) and M2."""
    with open(os.path.join(CORPUS, rel), encoding="latin-1") as fh:
        text = fh.read().splitlines()
    body = text[:head] + text[lo - 1 : hi]
    if feed:
        body.insert(head, feed)
    return "\n".join(body + ["M2"]) + "\n"


#: name, program (text or callable), machine TOML, dt, start (X=..), fit method, oracle feed
CASES = [
    ("line-1ms", "G21 G90\nG1 X100 F5000\nM2\n", MILL_TOML, 0.001, None, None, 5000),
    ("line-6ms", "G21 G90\nG1 X100 F5000\nM2\n", MIKRON_TOML, 0.006, None, None, 5000),
    ("corner-1ms", "G21 G90\nG1 X20 F6000\nG1 X40 Y7.279\nM2\n", MILL_TOML, 0.001, None, None, 6000),
    ("circle-1ms", "G21 G90 G17\nG1 X5 F6000\nG2 X5 Y0 I-5 J0\nM2\n", MILL_TOML, 0.001, "X=5", None, 6000),
    ("helix-1ms", "G21 G90 G17\nG1 X5 F4000\nG2 X5 Y0 Z-3 I-5 J0 P3\nM2\n", MILL_TOML, 0.001, "X=5", None, 4000),
    ("arc-accel-1ms", "G21 G90 G17\nG1 X10 F60000\nG2 X10 Y0 I-10 J0\nM2\n", MILL_TOML, 0.001, "X=10", None, 60000),
    ("trident-nurbs-6ms", TRIDENT, MIKRON_TOML, 0.006, "X=10", None, 2500),
    ("trident-nurbs-1ms", TRIDENT, MIKRON_TOML, 0.001, "X=10", None, 2500),
    ("trident-g1-6ms", _trident_polyline, MIKRON_TOML, 0.006, "X=10", "nodes", 2500),
    ("five-axis-6ms", _five_axis, MIKRON_TOML, 0.006, "Y=-20", None, 50000),
    (
        "spiral-lines-1ms",
        lambda: _excerpt("performance/spiral_lines.ngc", 2, 5, 20),
        MILL_TOML,
        0.001,
        "X=43.8058052,Y=-25.7233674",
        None,
        999 * 25.4,
    ),
    ("trochoidal-1ms", lambda: _excerpt("performance/trochoidal.ngc", 13, 18, 110), MILL_TOML, 0.001, None, None, 3600),
    ("3dchips-1ms", lambda: _excerpt("performance/3D_Chips.ngc", 21, 22, 160), MILL_TOML, 0.001, None, None, 225000),
    (
        "circle-segments-1ms",
        lambda: _excerpt("performance/circle_small_segments_ncd.ngc", 6, 7, 600),
        MILL_TOML,
        0.001,
        "Y=25.4",
        None,
        9999 * 25.4,
    ),
]


def _program(case) -> str:
    prog = case[1]
    return prog() if callable(prog) else prog


def _key(case, text: str, length_mm: float) -> str:
    h = hashlib.sha256()
    for part in (text, case[2], repr(case[3]), repr(case[4]), repr(case[5]), repr(case[6]), f"{length_mm:.6f}"):
        h.update(part.encode())
    return h.hexdigest()[:20]


def _plan(case, text: str, planner: str, work: str) -> dict:
    from cnc_interp.export.csv_io import write_csv
    from cnc_interp.pipeline import plan_part

    name = case[0]
    part = os.path.join(work, f"{name}.ngc")
    mach = os.path.join(work, f"{name}.toml")
    with open(part, "w") as fh:
        fh.write(text)
    with open(mach, "w") as fh:
        fh.write(case[2])
    name_only, _, effort = planner.partition(":")
    kw = {"start": case[4], "fit_method": case[5], "effort": effort or None}
    plan_part(part, mach, name_only, case[3], **kw)  # warm up
    c0 = time.process_time()
    out = plan_part(part, mach, name_only, case[3], **kw)
    cpu = time.process_time() - c0
    csv = os.path.join(work, f"{name}.{planner.replace(':', '-')}.csv")
    write_csv(out.trajectory, csv)
    traj = out.trajectory
    steps = _main_move(traj.q)
    return {
        "planner": planner,
        "csv": csv,
        "machine": mach,
        "cycle_s": traj.duration_s,
        "main_steps": steps,
        "length_mm": float(traj.s[-1]),
        "plan_wall_s": out.timings["plan"],
        "plan_cpu_s": cpu,
        "worst_ratio": out.report.worst_ratio,
    }


def _main_move(q) -> int:
    """Periods of the longest run of moving samples (the oracle's default stretch)."""
    import numpy as np

    moving = np.abs(np.diff(q, axis=0)).max(axis=1) > 1e-9
    best = run = 0
    for m in moving:
        run = run + 1 if m else 0
        best = max(best, run)
    return int(best)


def _oracle(case, plan: dict, cache: dict, key: str, timeout: float) -> dict | None:
    if key in cache:
        return cache[key]
    cmd = [
        ORACLE_PYTHON,
        ORACLE,
        plan["csv"],
        plan["machine"],
        "--feed",
        str(case[6]),
        "--dt",
        repr(case[3]),
        "--json",
    ]
    t0 = time.perf_counter()
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"oracle timed out after {timeout:g} s"}
    if res.returncode != 0:
        tail = (res.stderr.strip().splitlines() or ["?"])[-1]
        return {"error": f"oracle exit {res.returncode}: {tail}"}
    data = json.loads(res.stdout)
    out = {
        "N": data["optimum"]["N"],
        "T": data["optimum"]["T"],
        "verified": data["optimum"]["verify"]["ok"],
        "wall_s": time.perf_counter() - t0,
        "warnings": data.get("warnings", []),
        "midpoint_err": data["geometry"]["midpoint_err"],
        "plan_N": data["plan"]["N"],
    }
    cache[key] = out
    return out


def oracle_missing() -> str | None:
    """Why the oracle cannot run here, or None."""
    if not os.path.exists(ORACLE):
        return f"the oracle {ORACLE} is absent (CNC_OPTIMUM_GAP names it)"
    r = subprocess.run([ORACLE_PYTHON, "-c", "import casadi"], capture_output=True)
    if r.returncode != 0:
        return f"{ORACLE_PYTHON} has no CasADi (CNC_ORACLE_PYTHON names an interpreter that has it)"
    return None


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="*", help="case names (default: all)")
    ap.add_argument("--planners", nargs="*", default=["optimal", "vpop"])
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    ap.add_argument("--no-oracle", action="store_true", help="plan only (cached optima still used)")
    ap.add_argument("--cache", default=os.path.join(os.path.expanduser("~"), ".cache", "cnc-interp", "optimality.json"))
    ap.add_argument("--oracle-timeout", type=float, default=3600.0)
    ap.add_argument("--json", default=None)
    ap.add_argument("--markdown", action="store_true", help="print the markdown table")
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    if args.list:
        for c in CASES:
            print(f"{c[0]:22s} dt={c[3]:g} fit={c[5] or 'auto'} feed={c[6]:g} mm/min")
        return
    cases = [c for c in CASES if not args.cases or c[0] in args.cases]
    try:
        with open(args.cache) as fh:
            cache = json.load(fh)
    except (OSError, ValueError):
        cache = {}
    missing = None if args.no_oracle else oracle_missing()
    if missing:
        print(f"no oracle: {missing}; cached optima only", flush=True)
        args.no_oracle = True
    rows = []
    with tempfile.TemporaryDirectory(prefix="cnc-opt-") as work:
        for case in cases:
            text = _program(case)
            plans = [_plan(case, text, p, work) for p in args.planners]
            key = _key(case, text, plans[0]["length_mm"])
            opt = cache.get(key)
            if opt is None and not args.no_oracle:
                best = min(plans, key=lambda r: r["main_steps"])
                opt = _oracle(case, best, cache, key, args.oracle_timeout)
                os.makedirs(os.path.dirname(args.cache), exist_ok=True)
                with open(args.cache, "w") as fh:
                    json.dump(cache, fh, indent=1, sort_keys=True)
            row = {"case": case[0], "dt_s": case[3], "oracle": opt, "plans": []}
            for p in plans:
                ratio = (p["main_steps"] / opt["N"]) if opt and "N" in opt else None
                rec = {k: v for k, v in p.items() if k not in ("csv", "machine")}
                rec["ratio"] = ratio
                row["plans"].append(rec)
            rows.append(row)
            _print(row)
    if args.markdown:
        print("\n" + _markdown(rows, args.planners))
    if not args.no_write:
        if any((r["oracle"] or {}).get("N") for r in rows):
            write_section(
                "Optimality",
                "optimality.py",
                command_line("optimality.py", argv),
                _markdown(rows, args.planners),
                "Periods of each plan's main move (the longest run of moving samples) and their ratio to the "
                "discrete-time minimum of the same path computed by `optimum_gap.py`.",
            )
        else:
            print("no optimum for any case (no oracle, none cached): RESULTS.md's section left out")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)


def _print(row: dict) -> None:
    opt = row["oracle"] or {}
    on = opt.get("N")
    head = (
        f"{row['case']:22s} dt {row['dt_s'] * 1e3:.0f} ms  optimum "
        + (f"{on:6d} steps" if on else f"{'-':>6s}      ")
        + (f" ({opt['error']})" if "error" in opt else "")
    )
    print(head, flush=True)
    for p in row["plans"]:
        r = f"{p['ratio']:.4f}" if p["ratio"] else "   -  "
        print(
            f"    {p['planner']:12s} {p['main_steps']:6d} steps  ratio {r}  cycle {p['cycle_s']:8.3f} s"
            f"  plan {p['plan_wall_s'] * 1e3:8.1f} ms wall {p['plan_cpu_s'] * 1e3:8.1f} ms cpu"
            f"  worst {p['worst_ratio']:.9f}",
            flush=True,
        )


def _markdown(rows, planners) -> str:
    out = ["| case | dt | optimum (periods) | " + " | ".join(f"{p} (periods, ratio)" for p in planners) + " |"]
    out.append("|---|---|---|" + "---|" * len(planners))
    for row in rows:
        opt = row["oracle"] or {}
        cells = []
        for p in row["plans"]:
            r = f"{p['ratio']:.3f}" if p["ratio"] else "-"
            cells.append(f"{p['main_steps']} ({r})")
        out.append(f"| {row['case']} | {row['dt_s'] * 1e3:g} ms | {opt.get('N', '-')} | " + " | ".join(cells) + " |")
    return "\n".join(out)


if __name__ == "__main__":
    main()

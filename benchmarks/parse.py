"""Parse speed and memory of ``read_program`` (G-code text -> Program).

Usage:
    .venv/bin/python benchmarks/parse.py [--lines 1000000] [--repeat 1] [--no-write] [FILE ...]

Generates a CAM-style program (G1 with N and F words, a G2/G3 arc every 40 lines,
a few rapids) of ``--lines`` lines, then times ``read_program`` end to end (bytes in,
Program out) on it, on the corpus's ``stellabee1.ngc`` and on any FILE given. Each
measurement runs in a fresh subprocess so that the peak resident memory
(``ru_maxrss``) belongs to that parse alone. Prints a table with wall-clock and
CPU-time rates (the latter is steadier on a shared machine); targets are at least
150,000 lines/s and under 500 MB for the 1,000,000-line file. Writes the table to
``benchmarks/RESULTS.md`` (its "Parse" section) unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import subprocess
import sys
import tempfile

from _results import command_line, md_table, write_section

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
STELLABEE = os.path.join(ROOT, "..", "shared", "corpus", "linuxcnc", "performance", "stellabee1.ngc")

_CHILD = r"""
import json, resource, sys, time
from cnc_interp.gcode import read_program
path = sys.argv[1]
with open(path, "rb") as fh:
    data = fh.read()
best = best_cpu = None
prog = None
for _ in range(int(sys.argv[2])):
    prog = None  # free the previous result first: peak memory is one parse's
    t0, c0 = time.perf_counter(), time.process_time()
    prog = read_program(data, source=path)
    dt, dc = time.perf_counter() - t0, time.process_time() - c0
    best = dt if best is None else min(best, dt)
    best_cpu = dc if best_cpu is None else min(best_cpu, dc)
nodes = sum(r.n_nodes for r in prog.runs)
rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
print(json.dumps({"seconds": best, "cpu_seconds": best_cpu, "lines": prog.line_count,
                  "nodes": nodes, "rss_mb": rss_mb}))
"""


def generate_cam_file(path: str, n_lines: int, seed: int = 1) -> None:
    """Write a deterministic CAM-style program of ``n_lines`` lines to ``path``."""
    rng = random.Random(seed)
    out = [
        "%",
        "(generated CAM-style benchmark program)",
        "G21 G90 G17 G94 G64 P0.01",
        "G0 Z5.000",
        "G0 X0.000 Y0.000",
        "G1 Z-1.000 F300",
    ]
    x = y = 0.0
    z = -1.0
    heading = 0.0
    n = 10
    after_arc = False
    while len(out) < n_lines - 2:
        k = len(out)
        n += 10
        if k % 40 == 0:
            # a quarter-ish arc, tangent-ish continuation, I/J incremental
            r = rng.uniform(0.5, 3.0)
            cx, cy = x - r * math.sin(heading), y + r * math.cos(heading)
            sweep = rng.uniform(0.3, 1.2)
            a0 = math.atan2(y - cy, x - cx)
            ex, ey = cx + r * math.cos(a0 + sweep), cy + r * math.sin(a0 + sweep)
            # round like a CAM post would, then keep the exact rounded centre
            ex, ey = round(ex, 4), round(ey, 4)
            i, j = round(cx - x, 4), round(cy - y, 4)
            cx, cy = x + i, y + j
            r_end = math.hypot(ex - cx, ey - cy)
            ex = cx + (ex - cx) * (math.hypot(i, j) / r_end)
            ey = cy + (ey - cy) * (math.hypot(i, j) / r_end)
            ex, ey = round(ex, 4), round(ey, 4)
            out.append(f"N{n} G3 X{ex:.4f} Y{ey:.4f} I{i:.4f} J{j:.4f}")
            x, y = ex, ey
            heading += sweep
            after_arc = True
        elif k % 5000 == 1:
            out.append(f"N{n} G0 Z5.000")
            out.append(f"N{n + 5} G0 X{x:.4f} Y{y:.4f}")
            out.append(f"N{n + 7} G1 Z{z:.4f} F300")
        else:
            heading += rng.uniform(-0.2, 0.2)
            step = rng.uniform(0.05, 0.5)
            x += step * math.cos(heading)
            y += step * math.sin(heading)
            z = -1.0 + 0.2 * math.sin(0.001 * k)
            if k % 3 == 0 or after_arc:
                after_arc = False
                out.append(f"N{n} G1 X{x:.4f} Y{y:.4f} Z{z:.4f} F{rng.choice((800, 1000, 1200))}")
            else:
                out.append(f"N{n} X{x:.4f} Y{y:.4f} Z{z:.4f}")
    out += ["M5", "M30"]
    with open(path, "w") as fh:
        fh.write("\n".join(out[:n_lines]) + "\n")


def measure(path: str, repeat: int) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    res = subprocess.run(
        [sys.executable, "-c", _CHILD, path, str(repeat)], capture_output=True, text=True, env=env, check=False
    )
    if res.returncode != 0:
        raise SystemExit(f"parse of {path} failed:\n{res.stderr}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("files", nargs="*")
    ap.add_argument("--lines", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=1, help="best of N parses per file")
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        gen = os.path.join(tmp, f"cam_{args.lines}.ngc")
        generate_cam_file(gen, args.lines)
        targets = [(f"generated CAM ({args.lines:,} lines)", gen)]
        if os.path.exists(STELLABEE):
            targets.append(("stellabee1.ngc", STELLABEE))
        targets += [(os.path.basename(f), f) for f in args.files]
        for name, path in targets:
            r = measure(path, args.repeat)
            if args.repeat > 1:  # peak memory of one parse, without heap fragmentation of N
                r["rss_mb"] = measure(path, 1)["rss_mb"]
            rows.append(
                (
                    name,
                    r["lines"],
                    r["nodes"],
                    r["seconds"],
                    r["lines"] / r["seconds"],
                    r["lines"] / r["cpu_seconds"],
                    r["rss_mb"],
                )
            )
    print(
        f"{'program':34s} {'lines':>10s} {'nodes':>10s} {'wall s':>7s} {'lines/s':>9s} "
        f"{'lines/CPU-s':>11s} {'peak MB':>8s}"
    )
    for name, lines, nodes, sec, lps, lpc, mb in rows:
        print(f"{name:34s} {lines:10,d} {nodes:10,d} {sec:7.2f} {lps:9,.0f} {lpc:11,.0f} {mb:8.0f}")
    if os.getloadavg()[0] > (os.cpu_count() or 1):
        print(
            f"note: load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs; wall-clock "
            "figures are inflated, lines/CPU-s is the steadier figure"
        )
    if not args.no_write:
        table = md_table(
            ["program", "lines", "nodes", "wall s", "lines/s", "lines/CPU-s", "peak MB"],
            [
                [name, f"{lines:,}", f"{nodes:,}", f"{sec:.2f}", f"{lps:,.0f}", f"{lpc:,.0f}", f"{mb:.0f}"]
                for name, lines, nodes, sec, lps, lpc, mb in rows
            ],
        )
        write_section(
            "Parse",
            "parse.py",
            command_line("parse.py", argv),
            table,
            f"`read_program`, bytes in, Program out, best of {args.repeat}; peak MB is the parsing "
            "process's peak resident memory. Targets: 150,000 lines/s and 500 MB on the 1,000,000-line file.",
        )


if __name__ == "__main__":
    main()

"""``cnc-interp estimate`` against ``cnc-interp plan -o /dev/null``: wall time, CPU time and
peak memory, on a program and on its body repeated ten times.

    .venv/bin/python benchmarks/estimate.py                 # Cereal.ngc and its 10x
    .venv/bin/python benchmarks/estimate.py PART.ngc [-m MACHINE] [--no-write]

Each figure is the best of ``--repeat`` runs (3; the largest peak RSS) of the installed
console script, the two commands taking turns (numba kernels compiled beforehand by a short
plan); CPU time (user + system) and peak RSS come from ``wait4``. ``estimate``
plans the same samples and verifies them as ``plan`` does, then counts them instead of
formatting CSV, so it should take no longer; its peak memory, like ``plan``'s, is a window
of the program, so the 10x program (ten times the cycle) should peak where the program
does. The table goes to ``benchmarks/RESULTS.md`` unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time

from _results import command_line, md_table, write_section

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
CORPUS = os.environ.get("CNC_CORPUS", os.path.join(ROOT, "..", "shared", "corpus", "linuxcnc"))
DEFAULT_PART = os.path.join(CORPUS, "performance", "Cereal.ngc")
#: lines that end a program (M2, M30) or delimit it (%): left out of the repeated body
_END_LINE = re.compile(rb"^\s*(%|[Mm]0*(2|30)(?![0-9.]))")


def console_script() -> str:
    exe = os.path.join(os.path.dirname(sys.executable), "cnc-interp")
    return exe if os.path.exists(exe) else "cnc-interp"


def make_10x(part: str, work: str) -> str:
    """``part``'s lines without its end (M2/M30, %) ten times over, then M2."""
    out = os.path.join(work, os.path.splitext(os.path.basename(part))[0] + "_x10.ngc")
    with open(part, "rb") as fh:
        body = b"".join(ln for ln in fh.read().splitlines(keepends=True) if not _END_LINE.match(ln))
    if not body.endswith(b"\n"):
        body += b"\n"
    with open(out, "wb") as fh:
        for _ in range(10):
            fh.write(body)
        fh.write(b"M2\n")
    return out


def run(args: list[str]) -> dict:
    """One run of ``cnc-interp ARGS``: its JSON, wall s, CPU s, peak RSS MB."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [console_script(), *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL
    )
    out = proc.stdout.read()
    err = proc.stderr.read()
    _, status, ru = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        raise SystemExit(f"{' '.join(args)}: exit {code}: {err.decode(errors='replace').strip()}")
    return {
        "json": json.loads(out),
        "wall_s": wall,
        "cpu_s": ru.ru_utime + ru.ru_stime,
        "rss_mb": ru.ru_maxrss / 1024.0,
    }


def _best(runs: list[dict]) -> dict:
    """The fastest wall and CPU times and the largest peak RSS of ``runs``."""
    return {
        "json": runs[0]["json"],
        "wall_s": min(r["wall_s"] for r in runs),
        "cpu_s": min(r["cpu_s"] for r in runs),
        "rss_mb": max(r["rss_mb"] for r in runs),
    }


def measure(part: str, machine: str, repeat: int) -> dict:
    plans, ests = [], []
    for _ in range(max(1, repeat)):
        plans.append(run(["plan", part, "-m", machine, "-o", os.devnull, "-q", "--json"]))
        ests.append(run(["estimate", part, "-m", machine, "-q", "--json"]))
    plan, est = _best(plans), _best(ests)
    cycle = est["json"]["cycle_time_s"]
    if abs(cycle - plan["json"]["cycle_time_s"]) > 1e-9 * max(1.0, cycle):
        raise SystemExit(f"{part}: estimate's cycle {cycle} s differs from plan's {plan['json']['cycle_time_s']} s")
    return {"part": part, "cycle_s": cycle, "samples": est["json"]["samples"], "plan": plan, "estimate": est}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("part", nargs="?", default=DEFAULT_PART)
    ap.add_argument("-m", "--machine", default="generic-mill")
    ap.add_argument("--work", default=None, help="folder for the 10x program (default: a temporary one)")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each command (best taken)")
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    opts = ap.parse_args()
    run(["plan", os.path.join(ROOT, "samples", "gcode", "mill-contour.ngc"), "-o", os.devnull, "-q", "--json"])
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = opts.work or tmp
        os.makedirs(work, exist_ok=True)
        for label, part in (("program", opts.part), ("10x", make_10x(opts.part, work))):
            r = measure(part, opts.machine, opts.repeat)
            p, e = r["plan"], r["estimate"]
            rows.append(
                [
                    f"{os.path.basename(opts.part)} {label}",
                    f"{r['cycle_s']:.1f}",
                    r["samples"],
                    f"{p['wall_s']:.2f}",
                    f"{e['wall_s']:.2f}",
                    f"{p['cpu_s']:.2f}",
                    f"{e['cpu_s']:.2f}",
                    f"{p['rss_mb']:.0f}",
                    f"{e['rss_mb']:.0f}",
                ]
            )
            print(" | ".join(str(c) for c in rows[-1]), flush=True)
    table = md_table(
        [
            "program",
            "cycle s",
            "samples",
            "plan wall s",
            "estimate wall s",
            "plan CPU s",
            "estimate CPU s",
            "plan peak MB",
            "estimate peak MB",
        ],
        rows,
    )
    print(table)
    if not opts.no_write:
        write_section(
            "Cycle estimate",
            "estimate.py",
            command_line("estimate.py"),
            table,
            notes=(
                f"`plan` is `plan PART -m {opts.machine} -o /dev/null`; `estimate` is `estimate PART -m "
                f"{opts.machine} --json`. 10x: the program's body ten times over (ten times the cycle). "
                f"Best of {opts.repeat} runs each, taking turns; CPU is user + system, peak MB the "
                "process's maximum RSS (the largest of the runs)."
            ),
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())

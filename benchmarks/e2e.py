"""End to end: ``cnc-interp plan PART -o OUT`` as a user runs it.

    .venv/bin/python benchmarks/e2e.py                      # stellabee1, then the 10x program
    .venv/bin/python benchmarks/e2e.py --only stellabee1 --json out.json
    .venv/bin/python benchmarks/e2e.py PART.ngc [-m MACHINE]
    .venv/bin/python benchmarks/e2e.py --no-write           # print only

For each program, two runs of the installed console script (numba kernels compiled
beforehand by a short plan):

* ``-o OUT.csv``: wall time, CPU time (user + system, from ``wait4``), peak RSS of the
  process, the output's size and write rate, and the stage figures of ``--json``
  (``timings_s``: parse thread CPU, fit time, planning threads' CPU, verify, write);
* ``-o -`` into a pipe read by this script: time until the first CSV row arrives, and
  the whole run's wall time, CPU time and peak RSS (no disk involved).

The 10x program is stellabee1's body repeated ten times (generated into --work); its
file run writes ~8 GB, so it is skipped unless --file-10x is given (the pipe run gives
its memory and time). The machine's load average before and after each run is printed:
figures taken while other jobs load the machine are provisional (CPU time is the steadier
figure). The table goes to ``benchmarks/RESULTS.md`` (its "End to end" section) unless
``--no-write``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

from _results import command_line, md_table, write_section

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
CORPUS = os.environ.get("CNC_CORPUS", os.path.join(ROOT, "..", "shared", "corpus", "linuxcnc"))
STELLABEE = os.path.join(CORPUS, "performance", "stellabee1.ngc")


def console_script() -> str:
    exe = os.path.join(os.path.dirname(sys.executable), "cnc-interp")
    return exe if os.path.exists(exe) else "cnc-interp"


def make_10x(work: str) -> str:
    """stellabee1's body (everything before its M2) ten times, then M2."""
    out = os.path.join(work, "stellabee1_x10.ngc")
    if not os.path.exists(out):
        with open(STELLABEE, "rb") as fh:
            lines = fh.read().splitlines(keepends=True)
        assert lines[-1].strip() == b"M2", "stellabee1 should end with M2"
        body = b"".join(lines[:-1])
        with open(out, "wb") as fh:
            for _ in range(10):
                fh.write(body)
            fh.write(b"M2\n")
    return out


def _wait(proc) -> tuple[int, float, float]:
    """(exit status, CPU s, peak RSS MB) of a finished child, from wait4."""
    _, status, ru = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return proc.returncode, ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024.0


def run_file(part: str, machine: str, out: str) -> dict:
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    proc = subprocess.Popen(
        [console_script(), "plan", part, "-m", machine, "-o", out, "--json", "-q"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
    )
    summary = proc.stdout.read()
    err = proc.stderr.read()
    code, cpu, rss = _wait(proc)
    wall = time.perf_counter() - t0
    if code != 0:
        raise SystemExit(f"plan failed ({code}): {err.decode()}")
    s = json.loads(summary)
    size = os.path.getsize(out)
    return {
        "mode": "file",
        "wall_s": wall,
        "cpu_s": cpu,
        "peak_rss_mb": rss,
        "bytes": size,
        "write_mb_s_overall": size / wall / 1e6,
        "samples": s["samples"],
        "cycle_time_s": s["cycle_time_s"],
        "timings_s": s["timings_s"],
        "load_before": load0,
        "load_after": os.getloadavg()[0],
    }


def run_pipe(part: str, machine: str) -> dict:
    t0 = time.perf_counter()
    load0 = os.getloadavg()[0]
    proc = subprocess.Popen(
        [console_script(), "plan", part, "-m", machine, "-o", "-", "-q"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        bufsize=0,
    )
    first = None
    total = 0
    rows = 0
    while True:
        chunk = proc.stdout.read(1 << 20)
        if not chunk:
            break
        if first is None and chunk.count(b"\n") >= 2:  # the header and a row
            first = time.perf_counter() - t0
        total += len(chunk)
        rows += chunk.count(b"\n")
    err = proc.stderr.read()
    code, cpu, rss = _wait(proc)
    wall = time.perf_counter() - t0
    if code != 0:
        raise SystemExit(f"plan failed ({code}): {err.decode()}")
    return {
        "mode": "pipe",
        "wall_s": wall,
        "cpu_s": cpu,
        "peak_rss_mb": rss,
        "first_row_s": first,
        "bytes": total,
        "rows": rows - 1,
        "load_before": load0,
        "load_after": os.getloadavg()[0],
    }


def warm_up(machine: str) -> None:
    """Compile (or load) the numba kernels once, outside the measurements."""
    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "w.ngc")
        with open(p, "w") as fh:
            fh.write("G21 G90\nG0 X1 Y1\nG1 X5 Y3 F600\nG2 X7 Y5 I1 J1\nG1 X5 Z-1\nM2\n")
        subprocess.run(
            [console_script(), "plan", p, "-m", machine, "-o", os.path.join(d, "w.csv"), "-q"],
            check=True,
            stdin=subprocess.DEVNULL,
        )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("parts", nargs="*", help="programs (default: stellabee1 and its 10x)")
    ap.add_argument("-m", "--machine", default="generic-mill")
    ap.add_argument("--only", choices=("stellabee1", "x10"), default=None)
    ap.add_argument("--work", default=None, help="folder for outputs and the 10x program")
    ap.add_argument("--file-10x", action="store_true", help="also write the 10x plan to a file")
    ap.add_argument("--json", default=None, help="write the figures here")
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    work = args.work or tempfile.mkdtemp(prefix="cnc-e2e-")
    os.makedirs(work, exist_ok=True)
    jobs = []
    if args.parts:
        jobs = [(p, True) for p in args.parts]
    else:
        if args.only in (None, "stellabee1"):
            jobs.append((STELLABEE, True))
        if args.only in (None, "x10"):
            jobs.append((make_10x(work), args.file_10x))
    warm_up(args.machine)
    results = []
    for part, to_file in jobs:
        name = os.path.basename(part)
        rec = {"program": name, "machine": args.machine, "cpus": os.cpu_count()}
        if to_file:
            out = os.path.join(work, os.path.splitext(name)[0] + ".csv")
            rec["file"] = run_file(part, args.machine, out)
            os.unlink(out)
            f = rec["file"]
            print(
                f"{name} -o file: wall {f['wall_s']:.1f} s, CPU {f['cpu_s']:.1f} s, peak RSS "
                f"{f['peak_rss_mb']:.0f} MB, {f['samples']} samples, {f['bytes'] / 1e6:.0f} MB "
                f"(load {f['load_before']:.1f} -> {f['load_after']:.1f}); stages "
                + ", ".join(f"{k} {v:.1f}" for k, v in sorted(f["timings_s"].items())),
                flush=True,
            )
        rec["pipe"] = p = run_pipe(part, args.machine)
        print(
            f"{name} -o - | reader: first row {p['first_row_s']:.2f} s, wall {p['wall_s']:.1f} s, "
            f"CPU {p['cpu_s']:.1f} s, peak RSS {p['peak_rss_mb']:.0f} MB, {p['rows']} rows "
            f"(load {p['load_before']:.1f} -> {p['load_after']:.1f})",
            flush=True,
        )
        results.append(rec)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=2)
    if not args.no_write:
        write_section(
            "End to end",
            "e2e.py",
            command_line("e2e.py", argv),
            table(results),
            f"`cnc-interp plan PART -m {args.machine}`, kernels compiled beforehand. Load is the one-minute "
            "load average before and after the run; CPU time is the steadier figure on a shared machine.",
        )
    return 0


def table(results: list[dict]) -> str:
    rows = []
    for rec in results:
        for mode in ("file", "pipe"):
            r = rec.get(mode)
            if r is None:
                continue
            rows.append(
                [
                    rec["program"],
                    "`-o file.csv`" if mode == "file" else "`-o -` into a pipe",
                    f"{r['wall_s']:.1f} s",
                    f"{r['cpu_s']:.1f} s",
                    f"{r['peak_rss_mb']:.0f} MB",
                    f"{r['first_row_s']:.2f} s" if r.get("first_row_s") is not None else "",
                    f"{r.get('samples', r.get('rows')):,}",
                    f"{r['bytes'] / 1e6:.0f} MB",
                    f"{r['load_before']:.1f} → {r['load_after']:.1f}",
                ]
            )
    return md_table(
        ["program", "output", "wall", "CPU", "peak RSS", "first row", "samples", "size", "load"],
        rows,
    )


if __name__ == "__main__":
    sys.exit(main())

"""A first run's compile: one cold plan, the next one, and N cold plans at once.

Each cold case runs on an empty kernel cache of its own (``NUMBA_CACHE_DIR`` in a temporary
folder), so the repository's cache is left alone. Measures, for ``--planner`` (default
``vpop``, the default planner) on the quick start's sample:

- the estimate a first run announces (``precompile.estimate_s``) and the cold plan's wall
  time, the worker processes left after it (must be 0);
- the second run's wall time and the kernels it compiled (must be 0 files added);
- N cold plans started at once (``--concurrent``, default 3): the wall time until the last
  ends, against one.

Writes the figures to ``benchmarks/RESULTS.md`` (its "First run" section) unless
``--no-write``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

from _results import command_line, md_table, write_section

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
PART = os.path.join(REPO, "samples", "gcode", "mill-contour.ngc")


def console_script() -> str:
    return os.path.join(os.path.dirname(sys.executable), "cnc-interp")


def _plan_cmd(planner: str, out: str) -> list[str]:
    return [console_script(), "plan", PART, "-m", "generic-mill", "--planner", planner, "-q", "-o", out]


def _cache_files(cache: str) -> int:
    return sum(len(files) for _, _, files in os.walk(cache))


def _workers() -> int:
    r = subprocess.run(["pgrep", "-f", "cnc_interp.precompile --worker"], capture_output=True, text=True)
    return len(r.stdout.split())


def measure(planner: str, concurrent: int) -> dict:
    from cnc_interp import precompile

    out: dict = {"planner": planner}
    with tempfile.TemporaryDirectory() as d:
        env = dict(os.environ, NUMBA_CACHE_DIR=os.path.join(d, "cache"))
        os.environ["NUMBA_CACHE_DIR"] = env["NUMBA_CACHE_DIR"]
        try:
            out["estimate_s"] = precompile.estimate_s(precompile.missing_groups(planner))
        finally:
            del os.environ["NUMBA_CACHE_DIR"]
        t0 = time.perf_counter()
        subprocess.run(_plan_cmd(planner, os.path.join(d, "a.csv")), env=env, check=True)
        out["cold_s"] = time.perf_counter() - t0
        out["workers_left"] = _workers()
        files = _cache_files(env["NUMBA_CACHE_DIR"])
        t0 = time.perf_counter()
        subprocess.run(_plan_cmd(planner, os.path.join(d, "b.csv")), env=env, check=True)
        out["second_s"] = time.perf_counter() - t0
        out["second_cache_files_added"] = _cache_files(env["NUMBA_CACHE_DIR"]) - files
        with open(os.path.join(d, "a.csv"), "rb") as a, open(os.path.join(d, "b.csv"), "rb") as b:
            out["same_bytes"] = a.read() == b.read()
    with tempfile.TemporaryDirectory() as d:
        env = dict(os.environ, NUMBA_CACHE_DIR=os.path.join(d, "cache"))
        t0 = time.perf_counter()
        procs = [subprocess.Popen(_plan_cmd(planner, os.path.join(d, f"{i}.csv")), env=env) for i in range(concurrent)]
        codes = [p.wait() for p in procs]
        out["concurrent"] = concurrent
        out["concurrent_s"] = time.perf_counter() - t0
        out["concurrent_ok"] = all(c == 0 for c in codes)
        out["concurrent_workers_left"] = _workers()
    return out


def table(rows: list[dict]) -> str:
    return md_table(
        [
            "planner",
            "estimate",
            "cold plan",
            "workers left",
            "second run",
            "kernels compiled by it",
            "same bytes",
            "N cold at once",
            "all N",
            "ratio to one",
        ],
        [
            [
                r["planner"],
                f"{r['estimate_s']:.0f} s",
                f"{r['cold_s']:.1f} s",
                r["workers_left"],
                f"{r['second_s']:.1f} s",
                f"{r['second_cache_files_added']} files",
                r["same_bytes"],
                r["concurrent"],
                f"{r['concurrent_s']:.1f} s",
                f"{r['concurrent_s'] / r['cold_s']:.2f}",
            ]
            for r in rows
        ],
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--planner", action="append", help="planner(s) to measure (default vpop)")
    ap.add_argument("--concurrent", type=int, default=3, help="cold plans started at once (default 3)")
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    rows = [measure(p, args.concurrent) for p in (args.planner or ["vpop"])]
    for r in rows:
        print(r)
    if not args.no_write:
        write_section("First run", "first_run.py", command_line("first_run.py", argv), table(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Batch throughput: programs per minute over the LinuxCNC corpus.

Usage: python benchmarks/batch.py [CORPUS_DIR] [--machine SPEC] [--timeout S] [--skip-dask]
                                  [--report FILE.json] [--no-write]

Runs `cnc-interp batch`'s engine twice over every program under CORPUS_DIR
(default ../shared/corpus/linuxcnc): with 2 local worker processes, and on a
2-worker Dask LocalCluster (processes, loopback). Prints programs/minute, the
status counts, and whether both runs gave the same report (wall time and memory
excluded). The table goes to ``benchmarks/RESULTS.md`` (its "Batch" section) unless
``--no-write``.
"""

from __future__ import annotations

import argparse
import os
import time

from _results import command_line, md_table, write_section
from cnc_interp.batch import VOLATILE_FIELDS, BatchOptions, build_report, write_report

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_CORPUS = os.path.normpath(os.path.join(HERE, "..", "..", "shared", "corpus", "linuxcnc"))
DEFAULT_MACHINE = os.path.join(DEFAULT_CORPUS, "configs", "axis_mm.ini")


def _stable(report: dict) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in VOLATILE_FIELDS} for r in report["programs"]]


def _line(label: str, report: dict) -> str:
    s = report["summary"]
    counts = ", ".join(f"{n} {k}" for k, n in s["status_counts"].items())
    return (
        f"{label:<22} {s['programs']} programs in {s['wall_s']:.1f} s = "
        f"{s['programs_per_minute']:.1f} programs/min ({counts})"
    )


def _row(label: str, report: dict) -> list:
    s = report["summary"]
    counts = ", ".join(f"{n} {k}" for k, n in s["status_counts"].items())
    return [label, s["programs"], f"{s['wall_s']:.1f} s", f"{s['programs_per_minute']:.1f}", counts]


def _write(args, argv, rows: list, notes: str) -> None:
    if args.no_write:
        return
    write_section(
        "Batch",
        "batch.py",
        command_line("batch.py", argv),
        md_table(["engine", "programs", "wall", "programs/min", "status"], rows),
        f"Corpus {os.path.relpath(args.corpus)}, machine {os.path.basename(args.machine)}, timeout "
        f"{args.timeout:g} s per program. " + notes,
    )


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("corpus", nargs="?", default=DEFAULT_CORPUS)
    ap.add_argument("--machine", default=DEFAULT_MACHINE)
    ap.add_argument("--timeout", type=float, default=120.0)
    ap.add_argument("--skip-dask", action="store_true")
    ap.add_argument("--report", default=None, help="also write the local run's JSON report here")
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)

    base = dict(paths=(args.corpus,), machine_spec=args.machine, jobs=2, timeout_s=args.timeout, quiet=True)
    local = build_report(BatchOptions(**base))
    print(_line("local, 2 workers:", local))
    if args.report:
        write_report(local, args.report)
    rows = [_row("local, 2 worker processes", local)]
    if args.skip_dask:
        _write(args, argv, rows, "Dask run skipped (`--skip-dask`).")
        return
    from distributed import LocalCluster

    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    ) as cluster:
        t0 = time.monotonic()
        dask = build_report(BatchOptions(**base, dask_address=cluster.scheduler_address))
        print(_line("dask LocalCluster, 2:", dask))
        total = time.monotonic() - t0
        print(f"  (cluster start-up excluded; total incl. first-task warm-up {total:.1f} s)")
    rows.append(_row("Dask LocalCluster, 2 workers", dask))
    if args.report:
        write_report(dask, args.report.replace(".json", "") + ".dask.json")
    same = _stable(local) == _stable(dask)
    print("reports identical (wall time, memory excluded):", same)
    _write(
        args,
        argv,
        rows,
        f"Dask: cluster start-up excluded, {total:.1f} s with the first task's warm-up. "
        f"Both reports the same (wall time and memory excluded): {same}.",
    )
    if not same:
        for a, b in zip(_stable(local), _stable(dask)):
            if a != b:
                diff = {k: (a[k], b[k]) for k in a if a[k] != b[k]}
                print(f"  differs: {a['key']}: {diff}")


if __name__ == "__main__":
    main()

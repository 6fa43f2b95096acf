"""``cnc-interp batch``: regression runs of many part programs, locally or on Dask.

Every program under the given paths goes through parse -> fit -> plan -> verify
in its own forked worker process (``batch_workers``), ``--jobs`` at a time, or as
tasks on a Dask distributed cluster (``--dask ADDRESS``; each task forks the same
isolated child on its worker). One program's failure — bad G-code, a crash, a
timeout, running out of memory — is that program's status; the batch goes on.

Report (``--report FILE.json`` / ``.csv``, or ``--json`` on stdout): per program
``key`` (path relative to the argument it was found under, prefixed by that
argument's name), ``status`` (ok / violation / error / timeout / crash), message
and line of an error, lines, nodes, segments, path length (mm), cycle time (s),
worst limit ratio, max fit deviation (mm), planning wall time (s) and the worker's
peak memory (MB), and the number of Python warnings the stages raised (with the
first one; they are counted, not printed). Wall time and memory vary run to run; everything else is
deterministic, so local and Dask runs give the same report apart from those.

The summary counts three kinds of trouble apart: **errors**, programs the reader or a
stage refused as bad input (status ``error``, what ``plan`` exits 2 for); **failures**,
programs whose plan violates a limit, crashed or timed out; **regressions**, against
``--baseline``, programs whose status changed or whose cycle time grew by more than
``--max-slowdown``. With a baseline, an error, crash or timeout the baseline records for
the same program is known, not counted again.

Exit status: 1 when there is any error, failure or regression, otherwise 0; 2 for bad
usage or machine.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import sys
import time
from dataclasses import dataclass

from .errors import SourceLocation, UsageError, printable
from .plan.settings import DEFAULT_PLANNER

#: file name endings taken as part programs when a directory is given
GCODE_SUFFIXES = (".ngc", ".nc", ".gcode", ".gc", ".g", ".tap", ".cnc")
#: report format version (bump on incompatible changes)
REPORT_VERSION = 2
#: result fields, in report / CSV column order
FIELDS = (
    "key",
    "status",
    "message",
    "error_line",
    "lines",
    "nodes",
    "segments",
    "path_length_mm",
    "cycle_time_s",
    "samples",
    "worst_ratio",
    "max_fit_dev_mm",
    "warnings",
    "first_warning",
    "wall_s",
    "peak_mem_mb",
)
#: fields that differ from run to run (excluded when comparing runs for identity)
VOLATILE_FIELDS = ("wall_s", "peak_mem_mb")
#: how long to try to reach a Dask scheduler before giving up (s)
DASK_CONNECT_TIMEOUT_S = 20
#: per-program time limit by default, s: a hung program must not hold a regression run
#: forever (stellabee1, 169k lines and a 2 h 24 min cycle, takes about 100 s)
DEFAULT_TIMEOUT_S = 1800.0
#: statuses that count as a regression by themselves
_BAD_STATUS = ("violation",)


@dataclass(frozen=True)
class BatchOptions:
    """What ``cnc-interp batch`` was asked to do (see ``cli.batch``)."""

    paths: tuple[str, ...]
    machine_spec: str
    planner: str = DEFAULT_PLANNER
    dt_s: float | None = None
    tol_mm: float | None = None
    fit_method: str | None = None
    effort: str | None = None
    jobs: int | None = None
    report: str | None = None
    baseline: str | None = None
    max_slowdown: str = "1%"
    timeout_s: float | None = DEFAULT_TIMEOUT_S
    dask_address: str | None = None
    quiet: bool = False
    as_json: bool = False


# --- inputs ------------------------------------------------------------------
def parse_slowdown(text: str) -> float:
    """``"1%"`` -> 0.01, ``"0.05"`` -> 0.05; a ``UsageError`` for anything else."""
    t = str(text).strip()
    try:
        value = float(t[:-1]) / 100.0 if t.endswith("%") else float(t)
    except ValueError:
        value = float("nan")
    if not math.isfinite(value) or value < 0:
        raise UsageError(f"--max-slowdown must be a non-negative fraction or percentage like 1% or 0.01, not '{text}'")
    return value


def collect_programs(paths) -> list[tuple[str, str]]:
    """(key, path) of every part program under ``paths``, sorted by key, no duplicates."""
    found: dict[str, str] = {}
    for arg in paths:
        arg = os.fspath(arg)
        if os.path.isdir(arg):
            root = os.path.normpath(arg)
            base = os.path.basename(os.path.abspath(root))
            for dirpath, dirnames, filenames in os.walk(root):
                dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
                for name in filenames:
                    path = os.path.join(dirpath, name)
                    # regular files only: a FIFO would block, a link to /dev/zero never ends
                    if name.lower().endswith(GCODE_SUFFIXES) and not name.startswith(".") and os.path.isfile(path):
                        rel = os.path.relpath(path, root).replace(os.sep, "/")
                        found.setdefault(f"{base}/{rel}", path)
        elif os.path.isfile(arg):
            found.setdefault(os.path.basename(arg), arg)
        elif os.path.exists(arg):
            raise UsageError("not a regular file or a directory", SourceLocation(file=arg))
        else:
            raise UsageError("no such file or directory", SourceLocation(file=arg))
    if not found:
        raise UsageError(
            f"no part programs found (looked for {', '.join(GCODE_SUFFIXES)})",
            SourceLocation(file=" ".join(map(str, paths))),
        )
    return sorted(found.items())


def load_baseline(path: str) -> dict:
    """A previous ``--report`` JSON: ``{key: result}``; errors are ``UsageError`` with location."""
    import stat

    try:
        with open(path, "rb") as fh:
            if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):  # /dev/zero would never end
                raise UsageError("baseline is not a regular file", SourceLocation(file=path))
            text = fh.read().decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise UsageError(
            f"cannot read baseline: {getattr(exc, 'strerror', None) or exc}", SourceLocation(file=path)
        ) from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise UsageError(f"baseline is not JSON: {exc.msg}", SourceLocation(path, exc.lineno, exc.colno)) from None
    except RecursionError:  # arrays or objects nested thousands deep
        raise UsageError("baseline is not a batch report: nested too deeply", SourceLocation(path, 1, 1)) from None
    programs = data.get("programs") if isinstance(data, dict) else None
    if not isinstance(programs, list) or not all(
        isinstance(p, dict) and isinstance(p.get("key"), str) for p in programs
    ):
        raise UsageError(
            "baseline is not a cnc-interp batch JSON report (no 'programs' list)", SourceLocation(file=path)
        )
    return {p["key"]: p for p in programs}


# --- running -----------------------------------------------------------------
def _default_jobs() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)


def _make_jobs(programs, machine, opts: BatchOptions, embed: bool) -> list[dict]:
    jobs = []
    for key, path in programs:
        job = {
            "key": key,
            "path": path,
            "machine": machine,
            "planner": opts.planner,
            "dt_s": opts.dt_s,
            "tol_mm": opts.tol_mm,
            "fit_method": opts.fit_method,
            "effort": opts.effort,
            "data": None,
        }
        if embed:  # Dask workers may not share our file system: ship the program text
            with open(path, "rb") as fh:
                job["data"] = fh.read()
        jobs.append(job)
    return jobs


def warm_up_program(axes: str) -> bytes:
    """A tiny program on ``axes`` touching every stage: a rapid, lines, an arc, a dwell."""
    if "X" in axes and ("Y" in axes or "Z" in axes):
        b, plane, off = ("Y", "G17", "J") if "Y" in axes else ("Z", "G18", "K")
        text = f"G21 G90 {plane}\nG0 X1 {b}1\nG1 X2 {b}1 F600\nG2 X4 {b}1 I1 {off}0\nG4 P0.01\nG1 X4 {b}2\nM2\n"
    else:
        a = axes[0]
        text = f"G21 G90\nG0 {a}1\nG1 {a}2 F600\nG4 P0.01\nG1 {a}3\nM2\n"
    return text.encode("ascii")


def warm_up(machine, planner: str) -> dict:
    """Import the stages and run a tiny program once, so forked children start warm
    (compiled numba functions and imported modules are inherited, not rebuilt)."""
    from .batch_workers import run_job

    # run_job never raises for a program's own failure; warming is best effort anyway
    return run_job(
        {
            "key": "warm-up",
            "path": "<warm-up>",
            "machine": machine,
            "planner": planner,
            "dt_s": None,
            "tol_mm": None,
            "data": warm_up_program(machine.axes),
        }
    )


def _run_local(jobs, opts: BatchOptions, on_done) -> list[dict]:
    from .batch_workers import run_pool

    return run_pool(jobs, opts.jobs or _default_jobs(), opts.timeout_s, on_done=on_done)


def _dask_task(job: dict, timeout_s: float | None) -> dict:
    """The Dask task: warm the worker once, then run the job in an isolated child."""
    from . import batch_workers

    if not getattr(batch_workers, "_warm", False):
        try:
            warm_up(job["machine"], job["planner"])
        finally:
            batch_workers._warm = True
    return batch_workers.run_isolated(job, timeout_s)


def _run_dask(jobs, opts: BatchOptions, on_done) -> list[dict]:
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise UsageError("--dask needs the 'distributed' package (pip install 'cnc-interp[dask]')") from None
    try:
        client = Client(opts.dask_address, timeout=f"{DASK_CONNECT_TIMEOUT_S}s")
    except Exception as exc:  # noqa: BLE001 - any connection failure is the user's address
        raise UsageError(f"cannot connect to the Dask scheduler at {opts.dask_address}: {exc}") from None
    results: list[dict | None] = [None] * len(jobs)
    try:
        futures = {client.submit(_dask_task, job, opts.timeout_s, pure=False): i for i, job in enumerate(jobs)}
        for fut in as_completed(list(futures)):
            i = futures[fut]
            try:
                res = fut.result()
            except Exception as exc:  # noqa: BLE001 - a lost worker is that program's crash
                res = {
                    "status": "crash",
                    "message": f"dask task failed: {type(exc).__name__}: {exc}",
                    "error_line": 0,
                    "wall_s": None,
                    "peak_mem_mb": None,
                }
            results[i] = res
            on_done(i, res)
    finally:
        client.close()
    return results  # type: ignore[return-value]


def run_jobs(programs, machine, opts: BatchOptions, on_done=None) -> list[dict]:
    """Run every (key, path) program; returns the per-program records in key order."""
    on_done = on_done or (lambda i, r: None)
    if opts.dask_address:
        raw = _run_dask(_make_jobs(programs, machine, opts, embed=True), opts, on_done)
    else:
        warm_up(machine, opts.planner)
        raw = _run_local(_make_jobs(programs, machine, opts, embed=False), opts, on_done)
    return [_record(key, res) for (key, _), res in zip(programs, raw)]


def _clean(value):
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _record(key: str, res: dict) -> dict:
    rec = {f: None for f in FIELDS}
    rec.update({k: _clean(v) for k, v in res.items() if k in FIELDS})
    rec["key"] = key
    rec["message"] = rec["message"] or ""
    # where the cycle goes (JSON report only: nested, not a CSV column)
    rec["estimate"] = res.get("estimate")
    rec["error_line"] = int(rec["error_line"] or 0)
    return rec


# --- comparison and summary --------------------------------------------------
def compare(records: list[dict], baseline: dict | None, max_slowdown: float) -> dict:
    """What went wrong in this run, by kind: ``input_errors`` (status ``error``),
    ``violations`` and ``failed`` (crash or timeout), and against a baseline
    ``status_changed`` and ``slower`` (cycle time grown by more than ``max_slowdown``, a
    fraction); with their counts ``errors`` (input errors), ``failures`` (violations,
    crashes, timeouts) and ``regressions`` (status changes, slowdowns). A program the
    baseline records with the same status is known, not counted again."""
    out: dict = {"violations": [], "status_changed": [], "slower": [], "faster": [], "new": [], "missing": []}
    for r in records:
        if r["status"] in _BAD_STATUS:
            out["violations"].append({"key": r["key"], "worst_ratio": r["worst_ratio"]})
    if baseline is not None:
        keys = {r["key"] for r in records}
        out["missing"] = sorted(k for k in baseline if k not in keys)
        for r in records:
            b = baseline.get(r["key"])
            if b is None:
                out["new"].append(r["key"])
                continue
            if b.get("status") != r["status"]:
                out["status_changed"].append(
                    {"key": r["key"], "was": b.get("status"), "now": r["status"], "message": r["message"]}
                )
                continue
            was, now = b.get("cycle_time_s"), r["cycle_time_s"]
            if isinstance(was, (int, float)) and isinstance(now, (int, float)) and was > 0:
                change = now / was - 1.0
                item = {"key": r["key"], "was_s": was, "now_s": now, "change": change}
                if change > max_slowdown:
                    out["slower"].append(item)
                elif change < -max_slowdown:
                    out["faster"].append(item)
    # a program that did not plan counts unless the baseline knows it: a program the
    # baseline has with another status is a status change instead
    unknown = [r for r in records if baseline is None or r["key"] not in baseline]
    out["input_errors"] = [
        {"key": r["key"], "message": r["message"], "line": r.get("error_line") or 0}
        for r in unknown
        if r["status"] == "error"
    ]
    out["failed"] = [
        {"key": r["key"], "status": r["status"], "message": r["message"]}
        for r in unknown
        if r["status"] in ("crash", "timeout")
    ]
    out["errors"] = len(out["input_errors"])
    out["failures"] = len(out["violations"]) + len(out["failed"])
    out["regressions"] = len(out["status_changed"]) + len(out["slower"])
    return out


def exit_status(comparison: dict) -> int:
    """The batch's exit status: 1 when there is any error, failure or regression, else 0."""
    return 1 if comparison["errors"] or comparison["failures"] or comparison["regressions"] else 0


def summarise(records: list[dict], wall_s: float) -> dict:
    counts: dict[str, int] = {}
    for r in records:
        counts[r["status"]] = counts.get(r["status"], 0) + 1
    ok = [r for r in records if r["status"] in ("ok", "violation")]
    return {
        "programs": len(records),
        "status_counts": dict(sorted(counts.items())),
        "total_cycle_time_s": sum(r["cycle_time_s"] or 0.0 for r in ok),
        "worst_ratio": max((r["worst_ratio"] for r in ok if r["worst_ratio"] is not None), default=None),
        "wall_s": wall_s,
        "programs_per_minute": 60.0 * len(records) / wall_s if wall_s > 0 else None,
    }


def _fmt(v, spec: str) -> str:
    return "-" if v is None else format(v, spec)


def format_table(report: dict) -> str:
    """The human summary printed on stdout."""
    rows = [f"{'status':<9} {'lines':>7} {'segs':>6} {'cycle_s':>10} {'worst':>9} {'wall_s':>7} {'mem_MB':>7}  program"]
    for r in report["programs"]:
        rows.append(
            f"{r['status']:<9} {_fmt(r['lines'], 'd'):>7} {_fmt(r['segments'], 'd'):>6} "
            f"{_fmt(r['cycle_time_s'], '.3f'):>10} {_fmt(r['worst_ratio'], '.6f'):>9} "
            f"{_fmt(r['wall_s'], '.2f'):>7} {_fmt(r['peak_mem_mb'], '.0f'):>7}  {r['key']}"
        )
        if r["message"] and r["status"] != "ok":
            rows.append(f"{'':<9} {r['message']}")
        if r.get("warnings"):
            rows.append(f"{'':<9} {r['warnings']} warning(s), first: {r.get('first_warning')}")
    s = report["summary"]
    counts = ", ".join(f"{n} {k}" for k, n in s["status_counts"].items())
    ppm = s["programs_per_minute"]
    rows.append(
        f"{s['programs']} programs: {counts}; total cycle time {s['total_cycle_time_s']:.3f} s; "
        f"wall {s['wall_s']:.1f} s ({_fmt(ppm, '.1f')} programs/min)"
    )
    c = report["comparison"]
    for v in c["input_errors"]:
        rows.append(f"ERROR: {v['key']}: {v['message']}")
    for v in c["violations"]:
        rows.append(f"FAILURE violation: {v['key']} (worst ratio {_fmt(v['worst_ratio'], '.9f')})")
    for v in c["failed"]:
        rows.append(f"FAILURE {v['status']}: {v['key']}: {v['message']}")
    for v in c["status_changed"]:
        rows.append(f"REGRESSION status {v['was']} -> {v['now']}: {v['key']}")
    for v in c["slower"]:
        rows.append(
            f"REGRESSION slower {v['change'] * 100:+.2f}%: {v['key']} ({v['was_s']:.4f} s -> {v['now_s']:.4f} s)"
        )
    for v in c["faster"]:
        rows.append(f"faster {v['change'] * 100:+.2f}%: {v['key']}")
    for k in c["new"]:
        rows.append(f"new (not in baseline): {k}")
    for k in c["missing"]:
        rows.append(f"missing (in baseline only): {k}")
    rows.append(f"{c['errors']} error(s), {c['failures']} failure(s), {c['regressions']} regression(s)")
    return "\n".join(rows)


#: accepted endings of ``--report`` (any case) and their formats; the first is the default
REPORT_FORMATS = {".json": "json", ".csv": "csv"}


def report_format(path: str) -> str:
    """``"json"`` or ``"csv"`` for the ``--report`` path; another ending is a
    ``UsageError`` naming the accepted ones (``outfile.output_format``)."""
    from .outfile import output_format

    return output_format(path, REPORT_FORMATS, "a batch report")


def write_report(report: dict, path: str) -> None:
    """``.csv``: one row per program; ``.json``: the JSON report. Written atomically."""
    from .outfile import atomic_write

    if report_format(path) == "csv":
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(FIELDS)
        for r in report["programs"]:
            w.writerow(["" if r[f] is None else (repr(r[f]) if isinstance(r[f], float) else r[f]) for f in FIELDS])
        data = buf.getvalue().encode("utf-8")
    else:
        data = (json.dumps(report, indent=2, sort_keys=True, allow_nan=False) + "\n").encode("utf-8")
    with atomic_write(path) as fh:
        fh.write(data)


# --- entry point -------------------------------------------------------------
def build_report(opts: BatchOptions) -> dict:
    """Run the batch and return the report dict (no printing, no exit code)."""
    from . import __version__
    from .machine.load import load_machine
    from .plan.settings import PlanSettings

    if not isinstance(opts.machine_spec, str):
        raise UsageError("batch needs a machine: -m MACHINE (a TOML or INI file, or a preset name)")
    machine = load_machine(opts.machine_spec)
    # a usage error before any job
    PlanSettings.from_options(planner=opts.planner, dt_s=opts.dt_s, machine=machine, effort=opts.effort)
    slowdown = parse_slowdown(opts.max_slowdown)
    baseline = load_baseline(opts.baseline) if opts.baseline else None
    programs = collect_programs(opts.paths)
    if opts.report:
        from .outfile import check_writable

        # every file the batch reads is an input the report must not replace
        inputs = (opts.machine_spec, machine.tool_table, opts.baseline, *(path for _, path in programs))
        check_writable(opts.report, inputs=inputs)
        report_format(opts.report)  # an unknown ending: exit 2 before any program runs

    from .export.progress import progress

    t0 = time.monotonic()
    with progress(len(programs), "batch", enabled=not opts.quiet) as tick:
        records = run_jobs(programs, machine, opts, on_done=lambda i, r: tick(1))
    wall = time.monotonic() - t0
    return {
        "version": REPORT_VERSION,
        "tool": f"cnc-interp {__version__}",
        "machine": machine.to_dict(),
        "planner": opts.planner,
        "dt_s": machine.with_dt(opts.dt_s).dt_s,
        "tol_mm": opts.tol_mm,
        "fit_method": opts.fit_method or "nodes",
        "effort": opts.effort,
        "max_slowdown": slowdown,
        "executor": "dask" if opts.dask_address else "local",
        "programs": records,
        "summary": summarise(records, wall),
        "comparison": compare(records, baseline, slowdown),
    }


def run_batch(opts: BatchOptions) -> int:
    """``cnc-interp batch``: run, print the summary (or JSON), write the report; exit code."""
    report = build_report(opts)
    if opts.report:
        write_report(report, opts.report)
    if opts.as_json:
        sys.stdout.write(json.dumps(report, indent=2, sort_keys=True, allow_nan=False) + "\n")
    else:
        sys.stdout.write(printable(format_table(report), lines=True) + "\n")
    sys.stdout.flush()
    return exit_status(report["comparison"])

"""The pipeline as plain functions: the core that ``cli.py`` and ``batch`` share.

This is the only module besides ``cli.py`` that knows every stage: it reads a part
program, loads the machine, fits, plans, verifies and writes outputs. It holds no
algorithm of its own.
"""

from __future__ import annotations

import contextlib

import numpy as np

from .errors import SourceLocation
from .api import read_part  # noqa: F401  (re-exported: the CLI and batch read parts here)
from .machine.model import parse_start  # noqa: F401  (re-exported: the plan and stream commands' --start)
from .plan.settings import DEFAULT_PLANNER


def _loc(name: str):

    return SourceLocation(file=name)


def load_machine_spec(spec: str | None):
    """Machine from a TOML/INI file or preset name; ``None`` gives ``None``."""
    if spec is None:
        return None
    from .machine.load import load_machine

    return load_machine(spec)


def load_program_for(
    part: str,
    machine_spec: str | None,
    require_machine: bool = True,
    start: np.ndarray | None = None,
    tool_table: str | None = None,
):
    """Parse ``part`` for the machine named by ``machine_spec``: (Program, Machine | None).

    Without ``machine_spec`` the default preset, as ``plan`` (``require_machine=False``:
    no machine, the program's own axes, at least XYZ). ``tool_table``
    (a LinuxCNC tool table file) overrides the machine's (``[EMCIO] TOOL_TABLE``).
    """
    from .api import read_program

    machine = load_machine_spec(machine_spec)
    if machine is None and require_machine:
        from .machine.load import load_machine, DEFAULT_PRESET

        machine = load_machine(DEFAULT_PRESET)
    name, data = read_part(part)
    program = read_program(data, machine, name=name, start=start, tool_table=tool_table)
    return program, machine


def summarise_part(part: str, machine_spec: str | None, tool_table: str | None = None) -> dict:
    """``cnc-interp parse``: the program summary (``gcode.summary``) of ``part`` for the
    machine named by ``machine_spec`` (without one, the default preset, as ``plan``: an
    axis word the machine lacks is the same error at the same place), read as a
    stream: each run is counted and dropped, so a 50-byte ``G81 ... L1000000`` (a million
    holes, 8 kB each in a ``Program``) is summarised in bounded memory."""
    from .gcode.stream import ProgramStream
    from .gcode.summary import stream_summary
    from .machine.load import DEFAULT_PRESET

    machine = load_machine_spec(machine_spec if machine_spec is not None else DEFAULT_PRESET)
    name, data = read_part(part)
    table = tool_table if tool_table is not None else machine.tool_table
    stream = ProgramStream(
        data,
        name,
        machine.axes,
        machine.start,
        table,
        noop_mcodes=machine.noop_mcodes,
        program_units=machine.program_units,
        max_path_mm_s=machine.path_speed_cap_mm_s,
    )
    del data
    return stream_summary(stream)


def fit_loaded(program, settings):
    """Fit every run of a parsed program (see ``cnc_interp.fit.fit_program``); a fit outside
    its tolerance that could not be repaired is a ``FitError`` (exit 1) naming its line."""
    from .fit import fit_program
    from .fit.result import require_within_tolerance

    return require_within_tolerance(fit_program(program, settings))


# --- batch: one program from bytes to a result record ----------
def process_program(
    name: str,
    data: bytes,
    machine,
    planner: str = DEFAULT_PLANNER,
    dt_s: float | None = None,
    tol_mm: float | None = None,
    fit_method: str | None = None,
    effort: str | None = None,
) -> dict:
    """Parse, fit, plan and verify one program; the batch's per-program record.

    Raises ``CncInterpError`` for bad input (the batch records it as an error).
    Returns plain JSON-able values: ``status`` ("ok" or "violation"), ``lines``,
    ``nodes``, ``segments``, ``path_length_mm`` (rapids included), ``cycle_time_s``,
    ``worst_ratio`` (verify), ``worst`` (axis/limit/sample of it), ``max_fit_dev_mm``,
    ``estimate`` (where the cycle goes: ``Estimate.to_dict``'s breakdowns).
    """
    from .api import load_machine

    # the plan streams through verify and the summary as `plan`'s does, writing nothing:
    # memory is a window of the program, whatever its cycle
    m = load_machine(machine)
    opts = PlanOptions(
        part=name, planner=planner, dt_s=dt_s, tol_mm=tol_mm, fit_method=fit_method, out=None, effort=effort
    )
    summary = stream_plan(opts, threads=1, data=data, machine=m, on_violation=lambda report: None, breakdown=True)
    w = summary["worst"]
    ratio = summary["worst_ratio"]
    fit = summary["fit"]
    return {
        "status": "ok" if summary["ok"] else "violation",
        "message": "" if summary["ok"] else f"{w['axis']} {w['limit']} ratio {ratio:.9f} at sample {w['sample']}",
        "error_line": 0,
        "lines": summary["lines"],
        # one definition with `parse` and `fit`: nodes of feed runs, fitted feed segments
        "nodes": int(fit["nodes_in"] or 0),
        "segments": int(fit["segments_out"] or 0),
        "path_length_mm": float(summary["path_length_mm"]),
        "cycle_time_s": float(summary["cycle_time_s"]),
        "samples": int(summary["samples"]),
        "worst_ratio": None if summary["nan_found"] else float(ratio),
        "worst": w,
        "max_fit_dev_mm": _max_fit_deviation(fit),
        "plan_status": summary["status"],
        "estimate": _breakdowns(summary["estimate"]),
    }


#: ``Estimate.to_dict``'s keys that a batch record has already
_RECORD_KEYS = ("part", "machine", "planner", "dt_s", "samples", "cycle_time_s", "path_length_mm")


def _breakdowns(estimate) -> dict:
    """An ``Estimate``'s breakdowns, without what the batch record says already."""
    out = estimate.to_dict()
    for key in _RECORD_KEYS:
        out.pop(key, None)
    return out


def _max_fit_deviation(stats: dict) -> float | None:
    """The fit's largest node deviation (mm) from its statistics, if it reports one."""
    for key in ("max_node_dev_mm", "max_deviation_mm", "max_dev_mm"):
        value = stats.get(key) if isinstance(stats, dict) else None
        if isinstance(value, (int, float)):
            return float(value)
    return None


# -- plan ---------------------------------------------------------------------
from dataclasses import dataclass  # noqa: E402


@dataclass(frozen=True)
class PlanOptions:
    """What ``cnc-interp plan`` was asked to do (the CLI's options, unchanged)."""

    part: str
    machine_spec: str | None = None
    planner: str = DEFAULT_PLANNER
    dt_s: float | None = None
    tol_mm: float | None = None
    fit_method: str | None = None
    start: str | None = None
    tool_table: str | None = None
    out: str | None = "-"  # None: nothing written (the plan verified and summarised)
    quiet: bool = False
    summary_json: bool = False
    effort: str | None = None


@dataclass(frozen=True, eq=False)
class PlanOutcome:
    """A planned and verified program: the trajectory, its verify report, the
    machine and settings used, the fit's statistics and the wall times (s) per stage."""

    trajectory: object
    report: object
    machine: object
    settings: object
    fit_stats: dict
    timings: dict
    source: str
    input_meta: dict | None = None
    fit: object = None  # the FitResult planned

    def summary(self) -> dict:
        """Plain JSON-able summary (what ``plan`` prints on stderr)."""
        traj, rep = self.trajectory, self.report
        axis, kind, ratio, idx = rep.worst()
        plan_s = self.timings.get("plan", 0.0)
        return {
            "part": self.source,
            "machine": self.machine.name,
            "planner": traj.planner,
            # the planner's knobs that differ from their defaults (``--effort``)
            "options": dict(traj.settings.get("options", {})),
            "dt_s": traj.dt_s,
            "samples": traj.n_samples,
            "cycle_time_s": traj.duration_s,
            "path_length_mm": float(traj.s[-1]) if traj.n_samples else 0.0,
            "worst_ratio": rep.worst_ratio,
            "worst": {"axis": axis, "limit": kind, "sample": idx},
            "status": traj.status,
            "timings_s": self.timings,
            "fit_method": self.fit_stats.get("method"),
            "x_real_time": (traj.duration_s / plan_s) if plan_s > 0 else None,
        }


def plan_part(
    part: str,
    machine_spec: str | None = None,
    planner: str = DEFAULT_PLANNER,
    dt_s: float | None = None,
    tol_mm: float | None = None,
    start: str | np.ndarray | None = None,
    progress=None,
    fit_method: str | None = None,
    tool_table: str | None = None,
    effort: str | None = None,
) -> PlanOutcome:
    """Parse, fit, plan and verify one part program (no output written).

    Raises ``PlanError`` (exit 1) when the plan violates a limit: that is a bug.
    """
    from .api import run
    from .machine.load import DEFAULT_PRESET, load_machine
    from .plan.settings import PlanSettings

    machine = load_machine(machine_spec if machine_spec is not None else DEFAULT_PRESET)
    if isinstance(start, str):
        start = parse_start(start, machine.axes, machine.start)
    name, data = read_part(part)
    res = run(
        data,
        machine,
        tol_mm=tol_mm,
        fit_method=fit_method,
        plan_settings=PlanSettings.from_options(
            planner=planner, dt_s=dt_s, tol_mm=tol_mm, machine=machine, effort=effort
        ),
        start=start,
        tool_table=tool_table,
        name=name,
        progress=progress,
    )
    return PlanOutcome(
        trajectory=res.trajectory,
        report=res.report,
        machine=res.machine,
        settings=res.settings,
        fit_stats=dict(res.fit.stats or {}),
        timings=res.timings_s,
        source=res.program.source,
        input_meta=_input_meta(name, data),
        fit=res.fit,
    )


def _input_meta(name: str, data: bytes) -> dict:
    from .export.mcap_io import input_metadata

    return input_metadata(name, data)


def stream_plan(
    opts: PlanOptions,
    progress=None,
    window=None,
    threads: int | None = None,
    *,
    data: bytes | None = None,
    machine=None,
    on_violation=None,
    breakdown: bool = False,
) -> dict:
    """Parse, fit, plan, verify and write ``opts.out`` as one stream (``cnc-interp plan``).

    The stages overlap: the parse runs in a thread, the fit hands over each run's paths as
    they are fitted, worker threads plan jobs of paths ahead (``plan.timeline``), and every
    block of samples is verified (``StreamVerifier``, carrying the last samples across
    blocks) before it is written, so peak memory is a window of the program, not its
    cycle. The output goes through ``atomic_write``: a file appears only complete. The
    bytes do not depend on ``window`` or ``threads``.

    Returns the summary (``PlanOutcome.summary``'s keys) with ``timings_s``: ``parse``
    (the parse thread's CPU time), ``fit`` (the fit
    thread's CPU time), ``plan`` (the planning threads' CPU time), ``verify``, ``write``,
    ``first_row`` (from the start until the first samples were written) and ``total``
    (wall time), ``ok`` (every limit held and the plan starts at the start position),
    ``lines`` (of the program) and ``fit`` (the fit's ``nodes_in``, ``segments_out`` and
    ``max_node_dev_mm``). Raises ``PlanError`` (exit 1) when a block violates a limit (a
    bug), before that block is written.

    ``opts.out = None`` writes no setpoints: the plan is verified and summarised only, in
    the same bounded memory (``batch``). ``data`` is the program's text when it is not
    read from ``opts.part``; ``machine`` a loaded ``Machine`` instead of
    ``opts.machine_spec``; ``on_violation(report)`` replaces the ``PlanError`` (it may
    return: the plan then goes on and the summary says it is not ``ok``).
    ``breakdown=True`` also counts where the cycle goes (``plan.breakdown``): the summary's
    ``estimate`` is then an ``Estimate``, in the same bounded memory.
    """
    import sys
    import time

    from .errors import PlanError
    from .outfile import atomic_write
    from .fit.fitter import iter_fit
    from .fit.settings import FitSettings
    from .gcode.stream import ProgramStream
    from .machine.load import DEFAULT_PRESET, load_machine
    from .plan.prefetch import Prefetch
    from .plan.settings import PlanSettings
    from .plan.timeline import TimelineInfo, iter_timeline

    t_start = time.perf_counter()
    out = opts.out
    _few_malloc_arenas()
    if machine is None:
        machine = load_machine(opts.machine_spec if opts.machine_spec is not None else DEFAULT_PRESET)
    if out is not None and machine.tool_table is not None:  # an INI's [EMCIO] TOOL_TABLE is an input too
        from .outfile import check_writable

        check_writable(out, inputs=(machine.tool_table,))
    fmt = None
    if out is not None:
        from .export.formats import plan_format

        fmt = plan_format(out)  # an unknown ending: exit 2 before any work
    start = opts.start
    if isinstance(start, str):
        start = parse_start(start, machine.axes, machine.start)
    machine = machine.with_start(start)
    settings = PlanSettings.from_options(
        planner=opts.planner, dt_s=opts.dt_s, tol_mm=opts.tol_mm, machine=machine, effort=opts.effort
    )
    machine = machine.with_dt(settings.dt_s)
    _warm_kernels(settings.planner, sys.stderr if not opts.quiet and _is_terminal(sys.stderr) else None)
    dt = float(settings.dt_s)
    if data is None:
        name, data = read_part(opts.part)
    else:
        name = opts.part
    input_meta = _input_meta(name, data)
    tool_table = opts.tool_table if opts.tool_table is not None else machine.tool_table
    program = ProgramStream(
        data,
        name,
        machine.axes,
        machine.start,
        tool_table,
        marks=breakdown,
        noop_mcodes=machine.noop_mcodes,
        program_units=machine.program_units,
        max_path_mm_s=machine.path_speed_cap_mm_s,
    )
    del data
    fit_settings = FitSettings.from_options(tol_mm=opts.tol_mm, machine=machine, method=opts.fit_method)
    fit_stats: dict = {}
    # the fit runs in a thread of its own, a bounded number of items ahead
    fitted = Prefetch(iter_fit(program, fit_settings, fit_stats, source=name))

    n = machine.n_axes
    start_pos = np.zeros(n) if machine.start is None else np.asarray(machine.start, dtype=float)
    info = TimelineInfo()
    blocks = iter_timeline(
        fitted,
        machine,
        settings,
        start_pos,
        window=window,
        info=info,
        progress=progress,
        source=name,
        threads=threads,
        events=breakdown,
    )
    mcap = fmt == "mcap"

    def violation(report):
        if on_violation is not None:
            return on_violation(report)
        _violation(report, name, PlanError)

    sink = None
    counter = None
    try:
        with atomic_write(out) if out is not None else contextlib.nullcontext() as fh:
            from .export.sink import PlanSink

            sink = PlanSink(fh, machine, dt, mcap, violation, halstream=fmt == "halstream")
            if breakdown:
                from .plan.breakdown import Breakdown

                counter = Breakdown(machine, dt, program.line_count)
                sink.observe = counter.add
            reach = getattr(progress, "reach", None)  # a bar: its share done by source line
            if reach is not None:
                progress.measure(program.line_count, "line")
            try:
                for block in blocks:
                    sink.put(block)
                    if reach is not None and block.n:
                        reach(int(block.line.max()))
                planner = None
                meta = None
                if mcap:
                    from .export.mcap_io import planner_record

                    stats_settings = settings.to_dict()
                    stats_settings["stats"] = dict(info.stats)
                    planner = planner_record(
                        settings.planner, info.status, dt, machine.axes, info.samples, stats_settings
                    )
                    meta = {"planner": settings.to_dict(), "input": input_meta}
                report = sink.finish(planner, meta)
            except BaseException:
                sink.abort()
                raise
    except PlanError as exc:
        raise exc.in_file(name) from None  # name the part program
    finally:
        blocks.close()
        fitted.close()
    first_row = (sink.first_row_at - t_start) if sink.first_row_at is not None else None
    last_s = sink.last_s
    samples = info.samples
    cycle = float((samples - 1) * dt) if samples else 0.0
    total = time.perf_counter() - t_start
    timings = {
        "parse": program.thread_cpu_s,
        "fit": fitted.cpu_s,
        "plan": info.plan_cpu_s,
        "verify": sink.verify_s,
        "write": sink.write_s,
        "first_row": first_row if first_row is not None else total,
        "total": total,
    }
    axis, kind, ratio, idx = report.worst()
    summary = {
        "part": name,
        "machine": machine.name,
        "planner": settings.planner,
        "options": settings.options(),
        "dt_s": dt,
        "samples": samples,
        "cycle_time_s": cycle,
        "path_length_mm": last_s,
        "worst_ratio": report.worst_ratio,
        "worst": {"axis": axis, "limit": kind, "sample": idx},
        "status": info.status,
        "timings_s": timings,
        "fit_method": fit_stats.get("method"),
        "x_real_time": (cycle / total) if total > 0 else None,
        "ok": bool(report.ok),
        "nan_found": bool(report.nan_found),
        "lines": int(program.line_count),
        "fit": {k: fit_stats.get(k) for k in ("nodes_in", "segments_out", "max_node_dev_mm")},
    }
    if counter is not None:
        summary["estimate"] = counter.result(name, machine.name, settings.planner, last_s)
    return summary


#: glibc malloc arenas for the streaming plan's threads (mallopt M_ARENA_MAX): the
#: default (8 per core) lets each thread keep its own freed blocks, ~100 MB more RSS
MALLOC_ARENAS = 2
#: blocks from this size (bytes) are mmapped and returned to the system when freed, and the
#: heap's free top is trimmed from this size (M_MMAP_THRESHOLD, M_TRIM_THRESHOLD). glibc
#: raises its mmap threshold to every freed mmapped block's size (up to 32 MB), after which
#: a run's big temporary arrays stay in the heap as fragments: stellabee1 ten times over
#: peaked at 603 MB with the default, 514 MB with these, at the same CPU time
MALLOC_MMAP_THRESHOLD_BYTES = 256 * 1024


def _few_malloc_arenas() -> None:
    """Ask glibc for few malloc arenas and a fixed mmap threshold (no effect elsewhere)."""
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-8, MALLOC_ARENAS)  # M_ARENA_MAX
        libc.mallopt(-3, MALLOC_MMAP_THRESHOLD_BYTES)  # M_MMAP_THRESHOLD (fixes it)
        libc.mallopt(-1, MALLOC_MMAP_THRESHOLD_BYTES)  # M_TRIM_THRESHOLD
    except (OSError, AttributeError):
        pass


def _warm_kernels(planner: str, stream=None) -> None:
    """Compile the kernel groups the planner needs that are not cached yet (a first run,
    ``precompile.ensure``, saying so on ``stream``), then load the CSV formatter's and
    VPOp's kernels in a thread while the program is read: loading them takes about a
    second, and the first rows wait for it."""
    import threading

    from .precompile import ensure, warm_up

    ensure(planner, stream=stream)

    def load():
        try:
            for group in ("csv", "vpop-batch"):
                warm_up(group)
        except Exception:  # noqa: BLE001 - only a head start; the real call reports errors
            pass

    threading.Thread(target=load, daemon=True, name="cnc-interp-warm").start()


def _violation(report, name: str, error) -> None:
    axis, kind, ratio, idx = report.worst()
    raise error(
        f"bug: plan violates the {axis} {kind} limit (ratio {ratio:.12g} at sample "
        f"{idx}, t = {idx * report.dt_s:.6g} s); please report it",
        _loc(name),
    )


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def run_plan(opts: PlanOptions) -> None:
    """``cnc-interp plan``: plan, verify and write CSV or MCAP as a stream; summary on
    stderr (``stream_plan``)."""
    import json
    import sys

    from .outfile import check_writable
    from .export.progress import progress as progress_bar

    out = opts.out or "-"
    check_writable(out, inputs=(opts.part, opts.machine_spec, opts.tool_table))
    with progress_bar(None, "plan", enabled=not opts.quiet, unit="mm") as tick:
        summary = stream_plan(opts, progress=tick)
    if opts.summary_json:
        # JSON goes to stdout unless stdout carries the plan itself; --quiet never hides it
        stream = sys.stderr if out == "-" else sys.stdout
        stream.write(json.dumps(summary, indent=2, sort_keys=True, allow_nan=False) + "\n")
        stream.flush()
        return
    if opts.quiet:
        return
    from .errors import printable

    # the same words as `verify`'s report when the machine is the default preset
    default = " (default)" if opts.machine_spec is None else ""
    sys.stderr.write(
        f"{printable(summary['part'])}: {summary['planner']} on {printable(summary['machine'])}{default}: "
        f"cycle time {summary['cycle_time_s']:.6g} s, {summary['samples']} samples at "
        f"dt = {summary['dt_s']:g} s, path {summary['path_length_mm']:.6g} mm, "
        f"worst limit ratio {summary['worst_ratio']:.9f} "
        f"({summary['worst']['axis']} {summary['worst']['limit']})\n"
    )
    sys.stderr.flush()


#: ``estimate`` suggests ``--compare-tol`` when less than this share of the feed time runs
#: at programmed feed (a fine tolerance is one cause of the rest)
ESTIMATE_HINT_AT_FEED_SHARE = 0.5


def run_estimate(opts: PlanOptions, compare_tol: tuple[float, ...] = ()) -> None:
    """``cnc-interp estimate``: the plan's cycle and where it goes (``plan.breakdown``),
    planned and verified as ``plan`` does, no setpoints written (``opts.out`` is
    ignored); a table on stdout, or the ``Estimate`` as JSON with ``opts.summary_json``.
    Each of ``compare_tol`` (mm) plans the part again at that ``--tol``: its cycle shows
    what the tolerance in effect costs."""
    import json
    import sys
    from dataclasses import replace

    from .export.progress import progress as progress_bar
    from .plan.breakdown import format_estimate

    with progress_bar(None, "estimate", enabled=not opts.quiet, unit="mm") as tick:
        summary = stream_plan(replace(opts, out=None), progress=tick, breakdown=True)
    est = summary["estimate"]
    others = []
    for tol in compare_tol:
        with progress_bar(None, f"--tol {tol:g}", enabled=not opts.quiet, unit="mm") as tick:
            other = stream_plan(replace(opts, out=None, tol_mm=tol), progress=tick)
        others.append({"tol_mm": tol, "cycle_time_s": other["cycle_time_s"]})
    if opts.summary_json:
        out = est.to_dict()
        out["worst_ratio"] = summary["worst_ratio"]
        out["status"] = summary["status"]
        out["compare_tol"] = others
        text = json.dumps(out, indent=2, sort_keys=True, allow_nan=False)
    else:
        text = format_estimate(est)
        cycle = est.cycle_time_s
        for o in others:
            change = f" ({100.0 * (o['cycle_time_s'] - cycle) / cycle:+.1f} %)" if cycle > 0 else ""
            text += f"\ncycle at --tol {o['tol_mm']:g}: {o['cycle_time_s']:.3f} s{change}"
        share = est.at_feed_share
        if not others and share is not None and share < ESTIMATE_HINT_AT_FEED_SHARE:
            text += (
                f"\n{100.0 * (1.0 - share):.0f} % of the feed time is below programmed feed; "
                "--compare-tol MM shows what a coarser tolerance would save"
            )
    sys.stdout.write(text + "\n")
    sys.stdout.flush()

"""The ``cnc-interp`` command line: option parsing and error-to-exit-code mapping only.

Every command hands its options to one function of a stage package; nothing here
computes. Stage modules are imported inside the commands so that ``--help`` and
``import cnc_interp.cli`` stay fast and never import matplotlib, numba or USB.

Exit status: 0 done, 1 the plan or the device failed, 2 bad input or usage.
"""

from __future__ import annotations

import json
import os
import sys

import click

from . import __version__
from .errors import CncInterpError, printable
from .plan.settings import DEFAULT_PLANNER, OPTIMAL_EFFORTS

PLANNERS = ("optimal", "vpop", "constant", "variable")


def _emit_json(obj) -> None:
    click.echo(json.dumps(obj, indent=2, sort_keys=True, allow_nan=False))


def _echo_text(text: str) -> None:
    """A human-readable summary on stdout, its control characters escaped (a machine or a
    file named with ESC or BEL must not drive the terminal)."""
    click.echo(printable(text, lines=True))


class _Finite(click.FloatRange):
    """A float option within [lo, hi]; NaN, which every comparison lets through, is refused."""

    def convert(self, value, param, ctx):
        v = super().convert(value, param, ctx)
        if v != v:
            self.fail(f"{value!r} is not a number.", param, ctx)
        return v


def _planner_option(f):
    # plan and batch (stream quantizes paper 000's plan by default: its own option)
    return click.option(
        "--planner",
        type=click.Choice(PLANNERS),
        default=DEFAULT_PLANNER,
        show_default=True,
        help="optimal (near-time-optimal: feed-profile LP, exact sampler), VPOp "
        "(paper 001), or paper 000's constant / variable feedrate planner.",
    )(f)


def _effort_option(f):
    # plan, batch and stream; the optimal planner's OptimalOptions.effort
    return click.option(
        "--effort",
        type=click.Choice(OPTIMAL_EFFORTS),
        default=None,
        help="--planner optimal only: fast (no window refinement below 2 ms periods: over "
        "the corpus at 1 ms, about half the planning time for cycles 1.9 % longer), normal "
        "(default) or max (every window of every path refined: the shortest cycles, "
        "the longest planning).",
    )(f)


def _dt_option(f):
    # the same range a machine file accepts (machine/model.py)
    return click.option(
        "--dt",
        "dt_s",
        type=_Finite(min=1e-6, max=1.0),
        default=None,
        help="Sample period in seconds, 1e-6 to 1 (default: the machine's).",
    )(f)


def _tol_option(f):
    return click.option(
        "--tol",
        "tol_mm",
        type=_Finite(min=0, max=10.0),
        default=None,
        help="Maximum permissible fit error in mm: 0 (the exact path) or 1e-6 to 10 "
        "(default: the machine's tol, else 0.01).",
    )(f)


def _fit_method_option(f):
    return click.option(
        "--fit-method",
        "fit_method",
        type=click.Choice(("nodes", "planar", "auto")),
        default=None,
        help="nodes (default; stream: planar): the N-axis fit everywhere; planar: "
        "paper 000's planar fit for runs of lines that move exactly two axes, "
        "the N-axis fit elsewhere; auto: the same as planar.",
    )(f)


def _tool_table_option(f):
    return click.option(
        "--tool-table",
        "tool_table",
        default=None,
        metavar="FILE",
        type=click.Path(exists=True, dir_okay=False),
        help="LinuxCNC tool table (T1 P1 Z+12.5 ...) for G43 Hn tool lengths "
        "(default: the INI machine's [EMCIO] TOOL_TABLE; without one, "
        "G43 Hn applies length 0 with a warning).",
    )(f)


def _machine_option(required: bool = False):
    # no ``default`` with ``required``: click (8.2 and later) counts an explicit default,
    # even None, as a value, and `batch` without -m reached the machine loader with None
    extra = {} if required else {"default": None}

    def deco(f):
        return click.option(
            "-m",
            "--machine",
            "machine_spec",
            required=required,
            **extra,
            metavar="MACHINE",
            help="Machine: TOML file, LinuxCNC INI file or preset name (see `cnc-interp machines`).",
        )(f)

    return deco


class _ReaderClosed(Exception):
    """Standard output's reader closed early (``| head``)."""


class _Group(click.Group):
    def invoke(self, ctx):
        # click turns EPIPE into exit status 1 itself; hand it to ``run`` instead
        try:
            return super().invoke(ctx)
        except BrokenPipeError:
            raise _ReaderClosed() from None


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="cnc-interp")
def main() -> None:
    """G-code in, jerk-limited axis setpoints out.

    \b
    Pipeline: parse -> fit -> plan -> CSV / MCAP, or -> FPGA frames -> USB.
    Errors are printed as FILE:LINE:COL: error: MESSAGE.
    """


# -- parse --------------------------------------------------------------------
@main.command()
@click.argument("part", type=click.Path(allow_dash=True, dir_okay=False))
@_machine_option()
@_tool_table_option
@click.option("--json", "as_json", is_flag=True, help="Machine-readable summary on stdout.")
def parse(part: str, machine_spec: str | None, tool_table: str | None, as_json: bool) -> None:
    """Read PART (a file or - for stdin) and summarise its runs and nodes."""
    from .gcode.summary import format_summary
    from .pipeline import summarise_part

    summary = summarise_part(part, machine_spec, tool_table)
    if as_json:
        _emit_json(summary)
    else:
        _echo_text(format_summary(summary))


# -- fit ----------------------------------------------------------------------
@main.command()
@click.argument("part", type=click.Path(allow_dash=True, dir_okay=False))
@_machine_option()
@_tool_table_option
@_tol_option
@click.option(
    "--corner-deg",
    type=click.FloatRange(min=0, max=180),
    default=None,
    help="Turns up to this are rounded by the smooth fit; sharper corners get a G2 "
    "blend within the tolerance, or a stop where none fits (default 30).",
)
@_fit_method_option
@click.option("-o", "--output", "out", default=None, metavar="SEGMENTS.json", help="Write the fitted segments as JSON.")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable statistics on stdout.")
def fit(part, machine_spec, tool_table, tol_mm, corner_deg, fit_method, out, as_json) -> None:
    """Fit PART's tool path with G2-continuous quintic segments."""
    from .fit.report import fit_statistics, format_statistics, write_segments_json
    from .fit.settings import FitSettings
    from .pipeline import fit_loaded, load_program_for

    if out:
        from .outfile import check_writable, output_format

        check_writable(out, inputs=(part, machine_spec, tool_table))
    # without -m, the default machine, as `plan` (its axes, its tolerance)
    program, machine = load_program_for(part, machine_spec, require_machine=True, tool_table=tool_table)
    if out and machine is not None and machine.tool_table is not None:
        check_writable(out, inputs=(machine.tool_table,))  # an INI's [EMCIO] TOOL_TABLE
    if out:
        output_format(out, {".json": "json"}, "fitted segments", stdout="json")
    settings = FitSettings.from_options(tol_mm=tol_mm, corner_deg=corner_deg, machine=machine, method=fit_method)
    result = fit_loaded(program, settings)
    if out:
        write_segments_json(result, out)
    stats = fit_statistics(result)
    if as_json:
        _emit_json(stats)
    else:
        _echo_text(format_statistics(stats))


# -- plan ---------------------------------------------------------------------
_start_option = click.option(
    "--start",
    "start",
    default=None,
    metavar="X=..,Y=..",
    help="Machine position before the program (default: the machine's, else all 0); axes not named keep the machine's.",
)


def _plan_inputs(f):
    """PART and the options that say how to plan it (``plan`` and ``estimate`` alike)."""
    for option in (
        _start_option,
        _fit_method_option,
        _tol_option,
        _dt_option,
        _effort_option,
        _planner_option,
        _tool_table_option,
        _machine_option(),
        click.argument("part", type=click.Path(allow_dash=True, dir_okay=False)),
    ):
        f = option(f)
    return f


@main.command()
@_plan_inputs
@click.option(
    "-o",
    "--output",
    "out",
    default="-",
    metavar="OUT",
    help="OUT.csv, OUT.mcap or OUT.halstream (LinuxCNC halstreamer); - (default) writes CSV to stdout.",
)
@click.option(
    "--quiet", "-q", is_flag=True, help="No progress bar and no summary line on stderr (--json is still written)."
)
@click.option(
    "--json", "as_json", is_flag=True, help="Summary as JSON on stdout (on stderr when stdout carries the plan, -o -)."
)
def plan(out, quiet, as_json, **inputs) -> None:
    """Plan PART into setpoints every dt for MACHINE's axes."""
    from .outfile import watch_interrupts

    # Ctrl-C taken by a thread of its own, before numpy's and the stream's threads start
    # (they inherit SIGINT blocked); a signal landing in any of them would wait for the
    # main thread to wake up on its own
    watch_interrupts()
    from .pipeline import PlanOptions, run_plan

    # ``inputs``: PART and the planning options of ``_plan_inputs``, named as PlanOptions' fields
    run_plan(PlanOptions(**inputs, out=out, quiet=quiet, summary_json=as_json))


# -- estimate -----------------------------------------------------------------
@main.command()
@_plan_inputs
@click.option("--quiet", "-q", is_flag=True, help="No progress bar (the table or --json is still written).")
@click.option("--json", "as_json", is_flag=True, help="The estimate as JSON on stdout instead of the table.")
@click.option(
    "--compare-tol",
    "compare_tol",
    type=_Finite(min=0, max=10.0),
    multiple=True,
    metavar="MM",
    help="Also plan at this --tol and report the cycle it gives (repeatable): what the tolerance costs.",
)
def estimate(quiet, as_json, compare_tol, **inputs) -> None:
    """Cycle time of PART and where it goes, planned as `plan` does, no setpoints written.

    \b
    Time by kind (rapid, feed, dwell, rest), tool (T.. M6), operation (comment
    headers), source lines and binding limit, and the share at programmed feed;
    with --compare-tol, the cycle at other tolerances.
    """
    from .outfile import watch_interrupts

    watch_interrupts()
    from .pipeline import PlanOptions, run_estimate

    run_estimate(PlanOptions(**inputs, out=None, quiet=quiet, summary_json=as_json), compare_tol=compare_tol)


# -- machines -----------------------------------------------------------------
@main.command()
@click.argument("machine_spec", metavar="[MACHINE]", required=False, default=None)
@click.option("--json", "as_json", is_flag=True, help="Machine-readable list or description.")
def machines(machine_spec: str | None, as_json: bool) -> None:
    """List the built-in machine presets and their limits, or show how MACHINE (a TOML
    file, a LinuxCNC INI file or a preset name) is read: its axes, limits, sample
    period, tolerance, start, kinematics and the defaults applied."""
    from .machine.load import describe_machine, format_machine, format_presets, preset_table

    if machine_spec is None:
        table = preset_table()
        if as_json:
            _emit_json(table)
        else:
            _echo_text(format_presets(table))
        return
    desc = describe_machine(machine_spec)
    if as_json:
        _emit_json(desc)
    else:
        _echo_text(format_machine(desc))


# -- verify -------------------------------------------------------------------
@main.command()
@click.argument("plan_file", metavar="OUT", type=click.Path(exists=True, dir_okay=False))
@_machine_option()
@_start_option
@click.option("--json", "as_json", is_flag=True, help="Machine-readable report.")
def verify(plan_file, machine_spec, start, as_json) -> None:
    """Check a CSV or MCAP plan against MACHINE's limits and start position (exit 1 on a
    violation).

    Without -m, an MCAP plan's own machine (a preset or a file, loaded now), else the
    default preset, as `plan` uses without -m (a CSV names no machine)."""
    from .export.verify_file import verify_file

    report = verify_file(plan_file, machine_spec, start)
    if as_json:
        _emit_json(report.to_dict())
    else:
        click.echo(report.format())
    if not report.ok:
        sys.exit(1)


# -- plot ---------------------------------------------------------------------
@main.command()
@click.argument("plan_file", metavar="OUT", type=click.Path(exists=True, dir_okay=False))
@_machine_option()
@click.option("-o", "--output", "out", default=None, metavar="FIG.png", help="Image file (default: OUT with .png).")
@click.option("--from", "t_from", type=float, default=None, metavar="S", help="Show the plan from S seconds on.")
@click.option("--to", "t_to", type=float, default=None, metavar="S", help="Show the plan up to S seconds.")
def plot(plan_file, machine_spec, out, t_from, t_to) -> None:
    """Plot a plan: tool path coloured by feed, and axis limits against time."""
    from .export.plot import plot_file

    written = plot_file(plan_file, machine_spec, out, t_from=t_from, t_to=t_to)
    click.echo(written)


# -- FPGA ---------------------------------------------------------------------
@main.command()
@click.argument("frames", metavar="FRAMES.bin", type=click.Path(exists=True, dir_okay=False))
@click.option("-o", "--output", "out", default="-", metavar="OUT.csv", help="Setpoints CSV (default stdout).")
def emulate(frames, out) -> None:
    """Replay a frame file through the bit-exact FPGA model into plan CSV."""
    from .fpga.commands import emulate_file

    emulate_file(frames, out)


@main.command()
@click.argument("part", type=click.Path(allow_dash=True, dir_okay=False))
@_machine_option(required=True)
@click.option(
    "--planner",
    type=click.Choice(PLANNERS),
    default="variable",
    show_default=True,
    help="The planner whose plan is quantized (variable: paper 000's, whose segments the device evaluates).",
)
@_effort_option
@_dt_option
@_tol_option
@_fit_method_option
@click.option("--device", default=None, metavar="VID:PID", help="USB device (hex VID:PID).")
@click.option(
    "--dry-run", "dry_run", default=None, metavar="FRAMES.bin", help="Write the frames to a file instead of a device."
)
@click.option(
    "--resume-from",
    "resume_from",
    type=int,
    default=None,
    metavar="SEQ",
    help="Resume a broken stream after the last acknowledged sequence number.",
)
@click.option("--quiet", "-q", is_flag=True, help="No summary lines on stderr.")
def stream(part, machine_spec, planner, effort, dt_s, tol_mm, fit_method, device, dry_run, resume_from, quiet) -> None:
    """Quantize PART's plan to fixed point and stream it to the FPGA over USB."""
    from .fpga.commands import StreamOptions, run_stream

    # the FPGA evaluates paper 000's planar segments: stream keeps that fit by default
    run_stream(
        StreamOptions(
            part=part,
            machine_spec=machine_spec,
            planner=planner,
            effort=effort,
            dt_s=dt_s,
            tol_mm=tol_mm,
            fit_method=fit_method or "planar",
            device=device,
            dry_run=dry_run,
            resume_from=resume_from,
            quiet=quiet,
        )
    )


# -- batch --------------------------------------------------------------------
@main.command()
@click.argument("paths", nargs=-1, required=True, type=click.Path(exists=True))
@_machine_option(required=True)
@_planner_option
@_effort_option
@_dt_option
@_tol_option
@_fit_method_option
@click.option("--jobs", "-j", type=click.IntRange(min=1), default=None, help="Worker processes.")
@click.option(
    "--report",
    "report",
    default=None,
    metavar="FILE.json|FILE.csv",
    help="Write the per-program report (JSON, or CSV by extension).",
)
@click.option(
    "--baseline",
    default=None,
    metavar="FILE.json",
    help="A previous --report JSON: status changes and slowdowns are regressions.",
)
@click.option(
    "--max-slowdown",
    default="1%",
    show_default=True,
    help="Cycle-time growth against --baseline that counts as a regression.",
)
@click.option(
    "--timeout",
    "timeout_s",
    type=_Finite(min=0, min_open=True),
    default=1800.0,
    show_default=True,
    help="Per-program time limit, s.",
)
@click.option(
    "--dask", "dask_address", default=None, metavar="ADDRESS", help="Run on an existing Dask distributed scheduler."
)
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
@click.option("--json", "as_json", is_flag=True, help="The report as JSON on stdout instead of the table.")
def batch(
    paths,
    machine_spec,
    planner,
    effort,
    dt_s,
    tol_mm,
    fit_method,
    jobs,
    report,
    baseline,
    max_slowdown,
    timeout_s,
    dask_address,
    quiet,
    as_json,
) -> None:
    """Run every program under PATHS through parse, fit, plan and verify."""
    from .batch import BatchOptions, run_batch

    code = run_batch(
        BatchOptions(
            paths=paths,
            machine_spec=machine_spec,
            planner=planner,
            effort=effort,
            dt_s=dt_s,
            tol_mm=tol_mm,
            fit_method=fit_method,
            jobs=jobs,
            report=report,
            baseline=baseline,
            max_slowdown=max_slowdown,
            timeout_s=timeout_s,
            dask_address=dask_address,
            quiet=quiet,
            as_json=as_json,
        )
    )
    sys.exit(code)


def run() -> None:
    """Console-script entry point: map errors to exit codes, never a traceback for bad input."""
    from .outfile import guard_standard_streams

    guard_standard_streams()  # `>&-`, `2>&-`: one clear line, or a quiet success
    _warnings_as_lines()
    try:
        main.main(standalone_mode=False)
    except click.exceptions.Exit as exc:
        sys.exit(exc.exit_code)
    except click.ClickException as exc:
        # One line, like every other error; `--help` shows the usage.
        _stderr(f"cnc-interp: error: {exc.format_message()}")
        sys.exit(exc.exit_code if isinstance(exc, click.UsageError) else 2)
    except click.exceptions.Abort:  # Ctrl-C inside click: it has printed its newline
        from .outfile import interrupt_reported

        interrupt_reported()
        sys.exit(130)
    except CncInterpError as exc:
        _stderr(exc.format())
        sys.exit(exc.exit_code)
    except (BrokenPipeError, _ReaderClosed):
        # The reader closed early (`| head`): stop quietly.
        _silence_stdout()
        sys.exit(0)
    except KeyboardInterrupt:
        _interrupted()
    except MemoryError:
        _stderr("cnc-interp: error: out of memory")
        sys.exit(1)
    except Exception as exc:  # a bug: one line, and the traceback only on request
        if _caused_by_interrupt(exc):
            # Ctrl-C while compiled code returned: numba reports the pending
            # KeyboardInterrupt as a SystemError whose cause it is
            _interrupted()
        if os.environ.get("CNC_INTERP_DEBUG"):
            raise
        _stderr(
            f"cnc-interp: internal error: {type(exc).__name__}: {exc} "
            "(please report it; set CNC_INTERP_DEBUG=1 for the traceback)"
        )
        sys.exit(1)
    _flush_stdout()


def _interrupted() -> None:
    from .outfile import interrupt_reported

    _stderr("cnc-interp: interrupted")
    interrupt_reported()
    sys.exit(130)


def _warnings_as_lines() -> None:
    """Print our warnings as their one line (no Python file/line prefix), each once."""
    import warnings

    from .errors import CncInterpWarning

    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, CncInterpWarning):
            _stderr(printable(str(message)))
        else:
            shown(message, category, filename, lineno, file, line)

    warnings.showwarning = show


def _caused_by_interrupt(exc: BaseException) -> bool:
    """True when a KeyboardInterrupt is in the exception's cause/context chain."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def _stderr(msg: str) -> None:
    try:
        sys.stderr.write(msg + "\n")
        sys.stderr.flush()
    except Exception:  # pragma: no cover - stderr gone too
        pass


def _silence_stdout() -> None:
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except Exception:  # pragma: no cover
        pass


def _flush_stdout() -> None:
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        _silence_stdout()
    except CncInterpError as exc:  # standard output closed (outfile.guard_standard_streams)
        _stderr(exc.format())
        sys.exit(exc.exit_code)


if __name__ == "__main__":  # pragma: no cover
    run()

"""The public Python API: one call per stage, the same sequence the CLI runs.

::

    import cnc_interp as ci
    m = ci.load_machine("generic-mill")
    traj = ci.plan(ci.fit(ci.read_program("samples/gcode/mill-contour.ngc", machine=m)), m)
    assert ci.verify(traj, m).ok
    ci.write(traj, "plan.csv")

Each stage takes the previous stage's frozen result (``Program`` → ``FitResult`` →
``Trajectory`` → ``VerifyReport``) and raises a ``CncInterpError`` with the source location
on bad input, as the CLI does (``error.format()`` is its one line, ``error.exit_code`` its
exit status). ``run`` is the whole sequence in one call with its result (``PlanResult``);
``cnc-interp plan`` streams the same stages in bounded windows (``pipeline.stream_plan``)
and writes byte-identical samples.
"""

from __future__ import annotations

import os
import weakref
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable

if TYPE_CHECKING:  # the stages are imported when called: ``import cnc_interp`` stays cheap
    import numpy as np

    from .fit.result import FitResult
    from .fit.settings import FitSettings
    from .gcode.tooltable import ToolTable
    from .gcode.program import Program
    from .machine.model import Machine
    from .plan.settings import PlanSettings
    from .plan.trajectory import Trajectory
    from .plan.verify import VerifyReport
    from .plan.breakdown import Estimate

__all__ = [
    "load_machine",
    "read_program",
    "fit",
    "plan",
    "verify",
    "write",
    "run",
    "estimate",
    "PlanResult",
    "Progress",
    "DEFAULT_PLANNER",
]

from .plan.settings import DEFAULT_PLANNER  # noqa: E402  (a string; plan.settings is light)

#: the machine each program was read for (``fit`` takes its tolerance from it); keyed by
#: id with a finalizer, since a ``Program`` holds arrays and is not hashable
_MACHINE_OF: dict[int, "Machine"] = {}


def load_machine(spec: "str | os.PathLike[str] | Machine") -> "Machine":
    """A machine from a preset name (``cnc-interp machines`` lists them), a TOML file or a
    LinuxCNC INI file; a ``Machine`` is returned as it is. Raises ``MachineError`` (with the
    file's line) on a bad machine file."""
    from .machine.model import Machine
    from .machine.load import load_machine as _load

    if isinstance(spec, Machine):
        return spec
    _expect(spec, (str, os.PathLike), "machine", "a preset name, a machine file's path or a Machine")
    return _load(os.fspath(spec))


def read_program(
    source: "str | bytes | os.PathLike[str]",
    machine: "Machine | str | None" = None,
    *,
    name: str | None = None,
    start: "np.ndarray | None" = None,
    tool_table: "str | ToolTable | None" = None,
) -> "Program":
    """Interpret a part program for ``machine`` (its axes, start position and tool table).

    Args:
        source: a file path, or the G-code itself (``bytes``, or a ``str`` with a newline).
        machine: a ``Machine`` or anything ``load_machine`` takes; ``None``: the program's
            own axes (at least XYZ), no tool table.
        name: the name errors use (default: the path, or ``"<string>"``).
        start: machine position before the program, (n_axes,) mm/deg (default: the
            machine's start, else 0).
        tool_table: a LinuxCNC tool table path or ``ToolTable`` (default: the machine's).
    Returns:
        ``Program`` in machine coordinates, mm / deg / s. Raises ``GCodeError`` (exit 2)
        with ``FILE:LINE:COL`` on bad input.
    """
    from .gcode import read_program as _read

    _expect(source, (str, bytes, os.PathLike), "source", "a path, G-code bytes or G-code text")
    _expect(name, (str, type(None)), "name", "a string")
    _expect(tool_table, (str, os.PathLike, dict, type(None)), "tool_table", "a tool table's path or a ToolTable")
    data, name = _source_bytes(source, name)
    m = load_machine(machine) if machine is not None else None
    start = _position(start, "start")
    if m is not None:
        start = m.start if start is None else start
        tool_table = m.tool_table if tool_table is None else tool_table
    program: Program = _read(
        data,
        source=name,
        axes=m.axes if m is not None else None,
        start=start,
        tool_table=tool_table,
        noop_mcodes=m.noop_mcodes if m is not None else frozenset(),
        program_units=m.program_units if m is not None else "mm",
        max_path_mm_s=m.path_speed_cap_mm_s if m is not None else None,
    )
    if m is not None:
        key = id(program)
        _MACHINE_OF[key] = m
        weakref.finalize(program, _MACHINE_OF.pop, key, None)
    return program


def fit(
    program: "Program",
    tol_mm: float | None = None,
    *,
    machine: "Machine | str | None" = None,
    method: str | None = None,
    corner_deg: float | None = None,
    settings: "FitSettings | None" = None,
) -> "FitResult":
    """Fit the program's moves with quintic segments within the path tolerance.

    Args:
        program: from ``read_program``.
        tol_mm: the tolerance of moves without ``G64 P`` and the cap on every move's
            (``--tol``); default: the machine's ``tol``, else the fit's default.
        machine: whose ``tol`` applies (default: the machine the program was read for).
        method: ``"nodes"`` (default) or ``"auto"`` (``--fit-method``).
        corner_deg: corners sharper than this stop (default: the fit's).
        settings: a ``FitSettings`` built by the caller, used as it is (then ``tol_mm``,
            ``method`` and ``corner_deg`` must be left out: ``UsageError``).
    Returns:
        ``FitResult`` (items in program order, statistics). Raises ``FitError`` (exit 1)
        naming the lines whose fit misses its tolerance.
    """
    from .fit import fit_program
    from .fit.result import require_within_tolerance
    from .fit.settings import FitSettings
    from .gcode.program import Program

    _expect(program, Program, "program", "a Program (from read_program)", "fit")
    _expect(settings, (FitSettings, type(None)), "settings", "a FitSettings", "fit")
    for value, what in ((tol_mm, "tol_mm"), (corner_deg, "corner_deg")):
        _expect_number(value, what, "fit")
    if settings is None:
        m = load_machine(machine) if machine is not None else _MACHINE_OF.get(id(program))
        settings = FitSettings.from_options(tol_mm=tol_mm, corner_deg=corner_deg, machine=m, method=method)
    elif tol_mm is not None or method is not None or corner_deg is not None:
        from .errors import UsageError

        raise UsageError("fit: give either settings or tol_mm/method/corner_deg, not both")
    result: FitResult = require_within_tolerance(fit_program(program, settings))
    return result


#: ``progress(mm)``: told the path length planned since its last call
Progress = Callable[[float], None]


def plan(
    fitted: "FitResult",
    machine: "Machine | str",
    planner: str | None = None,
    dt_s: float | None = None,
    tol_mm: float | None = None,
    progress: Progress | None = None,
    *,
    settings: "PlanSettings | None" = None,
) -> "Trajectory":
    """Plan the fitted program's feed under ``machine``'s limits, sampled every ``dt_s``.

    Args:
        fitted: from ``fit``.
        machine: limits, kinematics and (by default) the sample period.
        planner: one of ``planners`` (``cnc-interp plan --planner``; default
            ``DEFAULT_PLANNER``).
        dt_s: sample period, s (default: the machine's).
        tol_mm: the tolerance recorded with the plan (default: the machine's).
        progress: optional ``progress(mm)`` told the path length planned since its last call.
        settings: a ``PlanSettings`` built by the caller (planner, period, the planners'
            knobs: ``OptimalOptions``, ``VpopOptions``, ``Paper000Options``), used as it
            is (then ``planner``, ``dt_s`` and ``tol_mm`` must be left out: ``UsageError``).
    Returns:
        ``Trajectory`` from rest to rest. Raises ``PlanError`` (exit 1) when the plan cannot
        be made (e.g. more samples than memory holds). It is not verified: ``verify`` is
        the independent check.
    """
    m = load_machine(machine)
    traj, _ = _plan(fitted, m, _plan_settings(m, planner, dt_s, tol_mm, settings), progress)
    return traj


def _check_plan_args(fitted: object, machine: "Machine", progress: object) -> None:
    """``plan``'s arguments of the right kinds, the program read for ``machine``'s axes."""
    from .errors import UsageError
    from .fit.result import FitResult

    _expect(fitted, FitResult, "fitted", "a FitResult (from fit)", "plan")
    if progress is not None and not callable(progress):
        raise UsageError(f"plan: progress must be a function of the millimetres planned, not {_kind(progress)}")
    axes = fitted.program.axes  # type: ignore[attr-defined]
    if axes != machine.axes:
        raise UsageError(
            f"plan: the program was read for axes {axes}, machine '{machine.name}' has {machine.axes}: "
            "read it with this machine (read_program(..., machine=...))"
        )


def _plan_settings(
    machine: "Machine",
    planner: str | None,
    dt_s: float | None,
    tol_mm: float | None,
    settings: "PlanSettings | None",
) -> "PlanSettings":
    """The caller's ``settings``, or settings from the arguments and the machine."""
    from .errors import UsageError
    from .plan.settings import PlanSettings

    _expect(settings, (PlanSettings, type(None)), "settings", "a PlanSettings", "plan")
    _expect(planner, (str, type(None)), "planner", "a planner's name", "plan")
    for value, what in ((dt_s, "dt_s"), (tol_mm, "tol_mm")):
        _expect_number(value, what, "plan")
    if settings is None:
        return PlanSettings.from_options(planner=planner or DEFAULT_PLANNER, dt_s=dt_s, tol_mm=tol_mm, machine=machine)
    if planner is not None or dt_s is not None or tol_mm is not None:
        raise UsageError("plan: give either settings or planner/dt_s/tol_mm, not both")
    return settings


def _plan(
    fitted: "FitResult",
    machine: "Machine",
    settings: "PlanSettings",
    progress: Progress | None,
) -> "tuple[Trajectory, PlanSettings]":
    from .errors import PlanError
    from .plan.budget import check_sample_budget, held_time_s
    from .plan.timeline import plan_program

    _check_plan_args(fitted, machine, progress)
    machine = machine.with_dt(settings.dt_s)
    source = fitted.program.source
    check_sample_budget(
        fitted.paths,
        machine,
        settings.dt_s,
        source,
        held_s=held_time_s(fitted.items),
        tables=settings.planner in ("vpop", "optimal"),  # the planners that build VPOp's tables
    )
    try:
        traj: Trajectory = plan_program(fitted, machine, settings, progress=progress)
        return traj, settings
    except PlanError as exc:
        raise exc.in_file(source) from None  # name the part program


def verify(traj: "Trajectory", machine: "Machine | str") -> "VerifyReport":
    """The independent check: per-axis finite-difference velocity, acceleration and jerk
    of the samples against ``machine``'s limits (``VerifyReport.ok``, ``worst()``)."""
    from .plan.trajectory import Trajectory
    from .plan.verify import verify as _verify

    _expect(traj, Trajectory, "traj", "a Trajectory (from plan)", "verify")
    report: VerifyReport = _verify(traj, load_machine(machine))
    return report


def write(
    traj: "Trajectory",
    path: "str | os.PathLike[str]",
    machine: "Machine | str | None" = None,
    metadata: "dict[str, Any] | None" = None,
) -> None:
    """Write the samples to ``path``: MCAP when it ends in ``.mcap`` (with ``machine``'s
    limits and ``metadata`` records), a LinuxCNC halstreamer file for ``.halstream``, CSV
    for ``.csv`` (any case; another ending is a ``UsageError``, as for ``plan -o``);
    ``"-"`` is standard output (CSV). The file appears only complete (written to a
    temporary file, then renamed)."""
    from .plan.trajectory import Trajectory

    _expect(traj, Trajectory, "traj", "a Trajectory (from plan)", "write")
    _expect(path, (str, os.PathLike), "path", "a file name", "write")
    _expect(metadata, (dict, type(None)), "metadata", "a dict", "write")
    path = os.fspath(path)
    from .export.formats import plan_format

    fmt = plan_format(path)
    if fmt == "halstream":
        from .export.halstream import write_halstream_to
        from .outfile import atomic_write

        with atomic_write(path) as fh:
            write_halstream_to(traj, fh)
    elif fmt == "mcap":
        from .export.mcap_io import write_mcap

        m = load_machine(machine) if machine is not None else None
        if m is not None and not set(traj.axes) <= set(m.axes):
            from .errors import UsageError

            raise UsageError(f"write: the plan has axes {traj.axes}, machine '{m.name}' has {m.axes}")
        write_mcap(traj, path, metadata=metadata, machine=m)
    else:
        from .export.csv_io import write_csv

        write_csv(traj, path)


@dataclass(frozen=True, eq=False)
class PlanResult:
    """One part program planned and verified: every stage's result.

    ``program`` (``Program``), ``fit`` (``FitResult``), ``trajectory`` (``Trajectory``),
    ``report`` (``VerifyReport``), ``machine`` (the ``Machine`` used, its ``dt_s`` the
    plan's), ``settings`` (``PlanSettings``) and ``timings_s`` (wall time per stage, s)."""

    program: "Program"
    fit: "FitResult"
    trajectory: "Trajectory"
    report: "VerifyReport"
    machine: "Machine"
    settings: "PlanSettings"
    timings_s: "dict[str, float]" = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """True when every sample is within the limits."""
        return bool(self.report.ok)


def run(
    source: "str | bytes | os.PathLike[str]",
    machine: "Machine | str",
    *,
    planner: str | None = None,
    dt_s: float | None = None,
    tol_mm: float | None = None,
    fit_method: str | None = None,
    fit_settings: "FitSettings | None" = None,
    plan_settings: "PlanSettings | None" = None,
    start: "np.ndarray | None" = None,
    tool_table: "str | ToolTable | None" = None,
    name: str | None = None,
    progress: Progress | None = None,
    check: bool = True,
) -> PlanResult:
    """``read_program`` → ``fit`` → ``plan`` → ``verify`` in one call.

    With ``check`` (the default) a plan that violates a limit raises ``PlanError``
    (exit 1: a bug of the planner, never an expected outcome); without it the report
    says so. ``fit_settings`` and ``plan_settings`` are ``fit``'s and ``plan``'s
    ``settings`` (``tol_mm`` then goes to neither; ``fit_method``, ``planner`` and
    ``dt_s`` must be left out of the stage given settings). Other arguments as the
    stages take them.
    """
    import time

    from .errors import PlanError, SourceLocation

    from .precompile import ensure

    t0 = time.perf_counter()
    from .fit.settings import FitSettings
    from .plan.settings import PlanSettings

    _expect(fit_settings, (FitSettings, type(None)), "fit_settings", "a FitSettings", "run")
    _expect(plan_settings, (PlanSettings, type(None)), "plan_settings", "a PlanSettings", "run")
    m = load_machine(machine)
    start = _position(start, "start", m)
    m = m.with_start(start)
    program = read_program(source, m, name=name, tool_table=tool_table)
    plan_tol_mm = tol_mm if plan_settings is None else None
    settings = _plan_settings(m, planner, dt_s, plan_tol_mm, plan_settings)
    ensure(settings.planner)  # a first run: the kernels compiled once, on two cores
    t1 = time.perf_counter()
    if fit_settings is None:
        fitted = fit(program, tol_mm, machine=m, method=fit_method)
    else:
        fitted = fit(program, method=fit_method, settings=fit_settings)
    t2 = time.perf_counter()
    traj, settings = _plan(fitted, m, settings, progress)
    m = m.with_dt(settings.dt_s)
    t3 = time.perf_counter()
    report = verify(traj, m)
    t4 = time.perf_counter()
    if check and not report.ok:
        axis, kind, ratio, idx = report.worst()
        raise PlanError(
            f"bug: plan violates the {axis} {kind} limit (ratio {ratio:.12g} at "
            f"sample {idx}, t = {idx * traj.dt_s:.6g} s); please report it",
            SourceLocation(file=program.source),
        )
    return PlanResult(
        program=program,
        fit=fitted,
        trajectory=traj,
        report=report,
        machine=m,
        settings=settings,
        timings_s={"parse": t1 - t0, "fit": t2 - t1, "plan": t3 - t2, "verify": t4 - t3},
    )


def estimate(
    source: "str | bytes | os.PathLike[str]",
    machine: "Machine | str",
    *,
    planner: str | None = None,
    dt_s: float | None = None,
    tol_mm: float | None = None,
    fit_method: str | None = None,
    effort: str | None = None,
    start: "np.ndarray | None" = None,
    tool_table: "str | ToolTable | None" = None,
    name: str | None = None,
) -> "Estimate":
    """The cycle of ``source`` on ``machine`` and where it goes (``cnc-interp estimate``):
    planned and verified as ``cnc-interp plan`` plans (one stream, memory bounded by a
    window of the program, not its cycle), no setpoints kept. Returns an ``Estimate``
    (``cnc_interp.plan.breakdown``): times by kind, tool, operation, source lines and
    binding limit, each summing to ``cycle_time_s``. A plan that violates a limit raises
    ``PlanError``; arguments as ``run`` takes them.
    """
    from .pipeline import PlanOptions, stream_plan

    for what, value in (("dt_s", dt_s), ("tol_mm", tol_mm)):
        _expect_number(value, what, "estimate")
    m = load_machine(machine)
    start = _position(start, "start", m)
    if start is not None:
        m = m.with_start(start)
    data, display = _source_bytes(source, name)
    opts = PlanOptions(
        part=display,
        planner=planner or DEFAULT_PLANNER,
        dt_s=dt_s,
        tol_mm=tol_mm,
        fit_method=fit_method,
        # a ToolTable passes through to the program stream as a file name does
        tool_table=tool_table,  # type: ignore[arg-type]
        out=None,
        quiet=True,
        effort=effort,
    )
    # text as the block reader takes it: one byte per character (latin-1)
    data_bytes = data.encode("latin-1", "replace") if isinstance(data, str) else data
    summary = stream_plan(opts, data=data_bytes, machine=m, breakdown=True)
    result: Estimate = summary["estimate"]
    return result


def _source_bytes(source: "str | bytes | os.PathLike[str]", name: str | None) -> tuple[bytes | str, str]:
    """(G-code, display name) of a path, ``bytes`` or G-code text."""
    if isinstance(source, bytes):
        return source, name or "<bytes>"
    if isinstance(source, str) and ("\n" in source or "\r" in source):
        return source, name or "<string>"
    display, data = read_part(os.fspath(source))
    return data, name or display


def read_part(part: str) -> tuple[str, bytes]:
    """Read a part program given as a path or ``-`` (stdin): (display name, raw bytes),
    bounded (``inputfile.read_bounded``)."""
    import sys

    from .errors import SourceLocation, UsageError

    from .inputfile import read_bounded

    if part == "-":
        return "<stdin>", read_bounded(sys.stdin.buffer, "<stdin>")
    try:
        with open(part, "rb") as fh:
            return part, read_bounded(fh, part)
    except OSError as exc:
        raise UsageError(f"cannot read part program: {exc.strerror}", SourceLocation(file=part)) from None


# -- arguments of the wrong kind: a UsageError naming the argument, not a TypeError inside ------
def _kind(value: object) -> str:
    return "None" if value is None else type(value).__name__


def _expect(value: object, types: "type | tuple[type, ...]", what: str, want: str, call: str = "") -> None:
    """``UsageError`` unless ``value`` is one of ``types`` (``want`` says what is expected)."""
    if not isinstance(value, types):
        from .errors import UsageError

        raise UsageError(f"{call + ': ' if call else ''}{what} must be {want}, not {_kind(value)}")


def _expect_number(value: object, what: str, call: str) -> None:
    """``UsageError`` unless ``value`` is ``None`` or a real number (not a bool)."""
    import numbers

    if value is not None and (isinstance(value, bool) or not isinstance(value, numbers.Real)):
        from .errors import UsageError

        raise UsageError(f"{call}: {what} must be a number, not {_kind(value)}")


def _position(value: object, what: str, machine: "Machine | None" = None) -> "np.ndarray | None":
    """``value`` (a position, one number per axis of ``machine``) as a float array, or a
    ``UsageError`` naming ``what``; ``None`` passes."""
    if value is None:
        return None
    import numpy as np

    from .errors import UsageError

    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise UsageError(f"{what} must be a sequence of numbers, one per axis, not {_kind(value)}") from None
    if arr.ndim != 1 or (machine is not None and arr.size != machine.n_axes):
        n = f"{machine.n_axes} numbers, one per axis {machine.axes}" if machine is not None else "one number per axis"
        raise UsageError(f"{what} must be {n}; got shape {arr.shape}")
    return arr

"""``cnc-interp verify``: check a written plan (CSV or MCAP) against a machine's limits."""

from __future__ import annotations

import os

from ..errors import SourceLocation, UsageError


def read_plan(path: str, dt_s: float | None = None):
    """Read a plan file into a ``Trajectory``: ``.mcap`` as MCAP, anything else as CSV.

    ``dt_s`` is the period of a one-sample CSV (the plan of a program without motion: the
    machine held at its start), whose rows cannot show one."""
    from ..inputfile import require_regular_file

    require_regular_file(os.fspath(path), "plan file")
    if os.fspath(path).lower().endswith(".mcap"):
        from .mcap_io import read_mcap

        return read_mcap(path)
    from .csv_io import read_csv

    return read_csv(path, dt_s)


#: every sample's time may differ from k·dt by this share of dt: far above the rounding of
#: a written k·dt (the CSV prints it exactly; an MCAP's ``t`` is the same float64), far
#: below anything that changes a finite difference the check reads
TIME_REL_DT_TOL = 1e-6
#: the recorded period may differ from the data's by this share (the data's period is a
#: mean over the plan, exact to a few ulps)
DT_REL_TOL = 1e-9


def verify_file(path: str, machine_spec: str | None, start: str | None = None):
    """Read the plan at ``path`` and verify it against ``machine_spec`` (file or preset;
    ``None``: the machine an MCAP plan names, else the default preset, see
    ``plan_machine``), starting at the machine's start position or ``start`` (``--start``
    syntax, ``"X=1,Y=2"``).

    Returns the ``VerifyReport`` (its ``ok`` is false when any ratio exceeds 1 + the
    documented slack, a setpoint is not finite, or the first sample is not the start
    position; its ``machine`` ends in ``, default`` when the default preset was taken).
    Before that, the plan itself must be checkable (``check_plan``). Raises
    ``MachineError`` for a bad machine, ``UsageError`` for an unreadable plan or one that
    cannot be checked against the machine.
    """
    from dataclasses import replace

    from ..machine.model import parse_start
    from ..plan.verify import machine_label, verify

    machine, how = resolve_plan_machine(path, machine_spec)
    machine = machine.with_start(parse_start(start, machine.axes, machine.start))
    traj = read_plan(path, machine.dt_s)
    check_plan(traj, machine, str(path))
    report = verify(traj, machine)
    if how == "default":
        report = replace(report, machine=default_label(machine_label(machine)))
    return report


def default_label(label: str) -> str:
    """``"NAME (SOURCE)"`` marked as the default machine: ``"NAME (SOURCE, default)"``."""
    return label[:-1] + ", default)" if label.endswith(")") else label + " (default)"


def plan_machine(path: str, machine_spec: str | None):
    """The machine a plan file is checked or drawn against (``resolve_plan_machine``)."""
    return resolve_plan_machine(path, machine_spec)[0]


def resolve_plan_machine(path: str, machine_spec: str | None):
    """``(machine, how)``: the machine a plan file is checked or drawn against, found the
    same way for every command that reads a plan: ``machine_spec`` when given (``how =
    "given"``); else, for an MCAP plan, the preset or machine file its ``machine`` record
    names, loaded from that file now (the limits copied into the plan are never trusted;
    ``"plan"``); else the default preset that ``cnc-interp plan`` uses without ``-m``
    (``"default"``: a CSV names no machine, and one planned without ``-m`` is checked
    against the machine it was planned for). An MCAP naming a machine file that is gone
    is a ``UsageError`` asking for ``-m``."""
    from ..machine.load import DEFAULT_PRESET, load_machine

    if machine_spec:
        return load_machine(machine_spec), "given"
    loc = SourceLocation(file=str(path))
    if os.fspath(path).lower().endswith(".mcap"):
        from .mcap_io import read_mcap_machine_record

        rec = read_mcap_machine_record(path) or {}
        source = rec.get("source") or None
        if source:
            spec = source.removeprefix("preset:")
            if spec != source or os.path.isfile(spec):
                return load_machine(spec), "plan"
            raise UsageError(
                f"the plan names machine file {source!r}, which is not found; give the machine with -m MACHINE", loc
            )
    return load_machine(DEFAULT_PRESET), "default"


def check_plan(traj, machine, path: str) -> None:
    """What ``verify`` takes on trust, checked from the data: every machine axis is a
    column, t, s and feed are finite, and t is uniform at the period the data shows, which
    a recorded ``dt_s`` must agree with. Raises ``UsageError`` (exit 2) naming the row."""
    import numpy as np

    loc = SourceLocation(file=path)
    missing = [a for a in machine.axes if a not in traj.axes]
    if missing:
        raise UsageError(
            f"the plan has no column for machine axis {', '.join(missing)} "
            f"(machine {machine.axes}, plan {traj.axes or 'none'}); it cannot be "
            "verified",
            loc,
        )
    for name in ("t", "s", "feed"):
        col = np.asarray(getattr(traj, name), dtype=float)
        bad = ~np.isfinite(col)
        if bad.any():
            raise UsageError(f"non-finite {name} at sample {int(np.argmax(bad))}", loc)
    t = np.asarray(traj.t, dtype=float)
    if t.size < 2:
        return
    dt_data = float(t[-1] - t[0]) / (t.size - 1)
    if not dt_data > 0:
        raise UsageError("t does not increase from the first sample to the last", loc)
    # tolerances relative to the period, never to the clock: a time far from 0 cannot
    # resolve a period at all, so a plan starts at t = 0 as every writer here writes it
    tol = TIME_REL_DT_TOL * dt_data
    if abs(float(t[0])) > tol:
        raise UsageError(f"the plan's time starts at t = {float(t[0])!r} s; a plan starts at t = 0", loc)
    off = np.abs(t - np.arange(t.size) * dt_data)
    if (off > tol).any():
        raise UsageError(f"t is not sampled at a fixed period (sample {int(np.argmax(off > tol))})", loc)
    if not abs(traj.dt_s - dt_data) <= DT_REL_TOL * dt_data:
        raise UsageError(
            f"the recorded sample period dt_s = {traj.dt_s!r} s disagrees with the samples' period {dt_data!r} s", loc
        )

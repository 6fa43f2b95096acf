"""``cnc-interp verify``: check a written plan (CSV or MCAP) against a machine's limits."""

from __future__ import annotations

import os

from ..errors import SourceLocation, UsageError


def read_plan(path: str):
    """Read a plan file into a ``Trajectory``: ``.mcap`` as MCAP, anything else as CSV."""
    if os.fspath(path).lower().endswith(".mcap"):
        from .mcap_io import read_mcap

        return read_mcap(path)
    from .csv_io import read_csv

    return read_csv(path)


#: samples' times may differ from t0 + k·dt by this share of the plan's duration (the CSV
#: writer prints k·dt exactly; an MCAP stores integer nanoseconds)
TIME_BASE_REL_TOL = 1e-9
#: absolute allowance for the MCAP's nanosecond log times, s
TIME_BASE_ABS_TOL_S = 1e-9


def verify_file(path: str, machine_spec: str | None):
    """Read the plan at ``path`` and verify it against ``machine_spec`` (file or preset;
    ``None`` takes the machine an MCAP plan records).

    Returns the ``VerifyReport`` (its ``ok`` is false when any ratio exceeds 1 + the
    documented slack, or a setpoint is not finite). Before that, the plan itself must be
    checkable (``check_plan``). Raises ``MachineError`` for a bad machine, ``UsageError`` for
    an unreadable plan or one that cannot be checked against the machine.
    """
    from ..machine.load import load_machine
    from ..plan.verify import verify

    machine = None
    if machine_spec:
        machine = load_machine(machine_spec)
    elif os.fspath(path).lower().endswith(".mcap"):
        from .mcap_io import read_mcap_machine

        machine = read_mcap_machine(path)
    if machine is None:
        raise UsageError("verify needs a machine (-m MACHINE); this plan records none", SourceLocation(file=str(path)))
    traj = read_plan(path)
    check_plan(traj, machine, str(path))
    return verify(traj, machine)


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
    dt_data = (t[-1] - t[0]) / (t.size - 1)
    tol = TIME_BASE_REL_TOL * max(1.0, abs(float(t[-1]))) + TIME_BASE_ABS_TOL_S
    off = np.abs(t - (t[0] + np.arange(t.size) * dt_data))
    if not dt_data > 0 or (off > tol).any():
        raise UsageError(f"t is not sampled at a fixed period (sample {int(np.argmax(off > tol))})", loc)
    if not abs(traj.dt_s - dt_data) <= tol / max(1, t.size - 1) + TIME_BASE_REL_TOL * dt_data:
        raise UsageError(
            f"the recorded sample period dt_s = {traj.dt_s!r} s disagrees with the samples' period {dt_data!r} s", loc
        )

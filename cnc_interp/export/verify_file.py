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


def verify_file(path: str, machine_spec: str | None):
    """Read the plan at ``path`` and verify it against ``machine_spec`` (file or preset).

    Returns the ``VerifyReport`` (its ``ok`` is false when any ratio exceeds 1).
    Raises ``MachineError`` for a bad machine or one that lacks an axis of the plan,
    and ``UsageError`` for an unreadable plan.
    """
    from ..plan.machine_io import load_machine
    from ..plan.verify import verify

    if not machine_spec:
        raise UsageError("verify needs a machine (-m MACHINE)", SourceLocation(file=str(path)))
    machine = load_machine(machine_spec)
    traj = read_plan(path)
    return verify(traj, machine)

"""The pipeline as plain functions: the core that ``cli.py`` and ``batch`` share.

This is the only module besides ``cli.py`` that knows every stage: it reads a part
program, loads the machine, fits, plans, verifies and writes outputs. It holds no
algorithm of its own.
"""

from __future__ import annotations

import numpy as np

from .errors import UsageError


def read_part(part: str) -> tuple[str, bytes]:
    """Read a part program given as a path or ``-`` (stdin): (display name, raw bytes)."""
    import sys

    if part == "-":
        return "<stdin>", sys.stdin.buffer.read()
    try:
        with open(part, "rb") as fh:
            return part, fh.read()
    except OSError as exc:
        raise UsageError(f"cannot read part program: {exc.strerror}", _loc(part)) from None


def _loc(name: str):
    from .errors import SourceLocation

    return SourceLocation(file=name)


def load_machine_spec(spec: str | None):
    """Machine from a TOML/INI file or preset name; ``None`` gives ``None``."""
    if spec is None:
        return None
    from .plan.machine_io import load_machine

    return load_machine(spec)


def load_program_for(part: str, machine_spec: str | None, require_machine: bool = False,
                     start: np.ndarray | None = None):
    """Parse ``part`` for the machine named by ``machine_spec``: (Program, Machine | None).

    Without a machine the program's own axes are used (at least XYZ).
    """
    from .gcode import read_program

    machine = load_machine_spec(machine_spec)
    if machine is None and require_machine:
        from .plan.machine_io import load_machine, DEFAULT_PRESET

        machine = load_machine(DEFAULT_PRESET)
    name, data = read_part(part)
    axes = machine.axes if machine is not None else None
    if start is None and machine is not None:
        start = machine.start
    program = read_program(data, source=name, axes=axes, start=start)
    return program, machine


def fit_loaded(program, settings):
    """Fit every run of a parsed program (see ``cnc_interp.fit.fit_program``)."""
    from .fit import fit_program

    return fit_program(program, settings)

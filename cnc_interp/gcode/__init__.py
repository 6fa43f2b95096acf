"""G-code front end: RS274NGC text -> ``Program`` (runs of nodes, dwells, stops).

``read_program`` is the entry point; ``blocks`` (language layer: tokens,
parameters, expressions, O-words) feeds ``interp`` (modal interpreter).
"""

from __future__ import annotations

import gc
import os
import warnings

import numpy as np

from ..constants import ALL_AXES, PROGRAM_UNITS_MM
from ..errors import CncInterpWarning, UsageError
from .program import Arc, CurvePiece, Dwell, Nurbs, Program, Run, Stop

__all__ = ["read_program", "Program", "Run", "Arc", "Nurbs", "CurvePiece", "Dwell", "Stop"]


def read_program(
    data: bytes | str,
    source: str,
    axes: str | None = None,
    start: np.ndarray | None = None,
    params=None,
    tool_table=None,
    noop_mcodes=frozenset(),
    program_units: str = "mm",
    max_path_mm_s: float | None = None,
) -> Program:
    """Interpret a whole part program.

    Args:
        data: the program text (bytes are decoded by the language layer).
        source: file name used in error messages (``"<stdin>"`` for standard input).
        axes: machine axis letters in machine order (e.g. ``"XYZ"``, ``"XZ"``,
            ``"XYZAC"``); a program word for another axis is a ``GCodeError`` at that
            word. ``None``: the program's own axes in XYZABCUVW order, at least XYZ.
        start: machine position before the program, (len(axes),) mm/deg; with
            ``axes=None`` it may have 3 (XYZ) or 9 (XYZABCUVW) values. Default 0.
        params: an optional ``ParamStore`` (e.g. with preset work offsets).
        tool_table: a tool table file's path or a ``ToolTable`` (tool length offsets for
            ``G43 Hn``); ``None``: ``G43 Hn`` applies zero length with one warning.
        noop_mcodes: M-code numbers the machine declares no-ops (``Machine.noop_mcodes``):
            accepted and ignored; any other M-code the reader does not know is an error.
        program_units: the length units the program starts in (``Machine.program_units``:
            ``"mm"`` or ``"inch"``), as if it began with G21 or G20.
        max_path_mm_s: the machine's path speed limit over the linear axes, mm/s, where it
            can bind (``Machine.path_speed_cap_mm_s``): every feed and rapid is capped at
            it (``runs.cap_path_speed``); ``None``: no cap.

    Returns:
        The ``Program`` in machine coordinates, mm / deg / s.
    """
    from .blocks import iter_blocks
    from .interp import Interpreter

    if axes is not None:
        axes = axes.upper()
        bad = [a for a in axes if a not in ALL_AXES]
        if not axes or bad or len(set(axes)) != len(axes):
            raise UsageError(f"bad axis list {axes!r} (letters from {ALL_AXES}, each once)")
    start9 = [0.0] * 9
    if start is not None:
        st = np.asarray(start, dtype=float).ravel()
        names = axes if axes is not None else ("XYZ" if st.size == 3 else ALL_AXES)
        if st.size != len(names) or not np.all(np.isfinite(st)):
            raise UsageError(f"start position needs {len(names)} finite values for axes {names}")
        for a, v in zip(names, st):
            start9[ALL_AXES.index(a)] = float(v)
    live = params is None
    if live:
        params = _LiveParams()
    interp = Interpreter(source, params, axes, start9, len_unit=program_len_unit(program_units))
    interp.noop_mcodes = frozenset(noop_mcodes)
    if isinstance(tool_table, (str, os.PathLike)):
        interp.tool_table_path = os.fspath(tool_table)  # read when a G43 first needs it
    elif tool_table is not None:
        from .tooltable import ToolTable

        interp.tool_table = ToolTable(tool_table)  # a copy: G10 L1 may edit it
        interp.tool_table.source = getattr(tool_table, "source", "")
    if live:
        params.interp = interp
    # The parse allocates millions of short-lived tuples and no reference cycles;
    # pausing the cyclic collector saves ~15% of the time on CAM-sized programs.
    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        interp.run(iter_blocks(data, source, params))
    finally:
        if gc_was_enabled:
            gc.enable()
    program = interp.program(_count_lines(data))
    if max_path_mm_s is not None:
        from dataclasses import replace

        from .runs import cap_path_speed

        items = tuple(cap_path_speed(it, max_path_mm_s) if isinstance(it, Run) else it for it in program.items)
        program = replace(program, items=items)
    _check_ranges(program)
    for text in program.metadata.get("warnings", ()):
        warnings.warn(CncInterpWarning(text), stacklevel=2)
    return program


def program_len_unit(program_units: str) -> float:
    """mm per program length unit at the start of a program in ``program_units``
    (``"mm"`` or ``"inch"``, ``PROGRAM_UNITS_MM``); another name is a ``UsageError``."""
    if program_units not in PROGRAM_UNITS_MM:
        raise UsageError(f"bad program units {program_units!r} (known: {', '.join(PROGRAM_UNITS_MM)})")
    return PROGRAM_UNITS_MM[program_units]


#: largest machine coordinate accepted, mm or deg (1000 km: far beyond any machine, far
#: below where lengths and sample counts overflow float64 or int64)
MAX_COORDINATE = 1e9
#: longest dwell accepted, s (31 years; a longer one is refused by the memory check anyway,
#: but must not overflow a sample count first)
MAX_DWELL_S = 1e9


def _check_ranges(program: Program) -> None:
    """Every node coordinate finite and within ``MAX_COORDINATE``, every feed positive (a
    rapid's is infinite), every dwell finite and within ``MAX_DWELL_S``: a ``GCodeError``
    at the first block that breaks this (the geometry downstream would overflow)."""
    from ..errors import GCodeError, SourceLocation

    def fail(msg: str, line: int):
        raise GCodeError(msg, SourceLocation(file=program.source, line=int(line), col=1))

    for item in program.items:
        if isinstance(item, Run):
            bad = ~(np.abs(item.nodes) <= MAX_COORDINATE).all(axis=1)
            if bad.any():
                i = int(np.argmax(bad))
                fail(f"position out of range (|coordinate| > {MAX_COORDINATE:g} mm or deg)", item.line[i])
            f = item.feed_mm_s
            badf = ~((f > 0) & ((f <= MAX_COORDINATE) | (np.isinf(f) & (item.kind == "rapid"))))
            if badf[1:].any():
                i = int(np.argmax(badf[1:])) + 1
                fail(f"feed rate out of range (0 < F, at most {MAX_COORDINATE * 60:g} per minute)", item.line[i])
        elif isinstance(item, Dwell):
            if not (0 <= item.seconds <= MAX_DWELL_S):
                fail(f"dwell time out of range (0 to {MAX_DWELL_S:g} s)", item.line)


def _live_params_class():
    from .params import ParamStore

    class LiveParams(ParamStore):
        """A ParamStore whose #5420-#5428 read the interpreter's current position.

        The interpreter's hot path does not write those nine parameters after every
        move; they are computed when a program reads them.
        """

        __slots__ = ("interp",)

        def __init__(self) -> None:
            super().__init__()
            self.interp = None

        def get(self, key, loc=None):
            if key.__class__ is int and 5420 <= key <= 5428 and self.interp is not None:
                return self.interp.program_position()[key - 5420]
            return super().get(key, loc)

    return LiveParams


def _LiveParams():
    global _LIVE
    if _LIVE is None:
        _LIVE = _live_params_class()
    return _LIVE()


_LIVE = None


def _count_lines(data: bytes | str) -> int:
    """Lines as the language layer splits them: LF, CRLF or CR alone ends a line."""
    if not data:
        return 0
    nl, cr = (b"\n", b"\r") if isinstance(data, bytes) else ("\n", "\r")
    n = data.count(nl) + data.count(cr) - data.count(cr + nl)
    return n if data.endswith(nl) or data.endswith(cr) else n + 1

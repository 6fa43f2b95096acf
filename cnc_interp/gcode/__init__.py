"""G-code front end: RS274NGC text -> ``Program`` (runs of nodes, dwells, stops).

``read_program`` is the entry point; ``blocks`` (language layer: tokens,
parameters, expressions, O-words) feeds ``interp`` (modal interpreter).
"""

from __future__ import annotations

import gc

import numpy as np

from ..constants import ALL_AXES
from ..errors import UsageError
from .program import Arc, CurvePiece, Dwell, Nurbs, Program, Run, Stop

__all__ = ["read_program", "Program", "Run", "Arc", "Nurbs", "CurvePiece", "Dwell", "Stop"]


def read_program(data: bytes | str, source: str, axes: str | None = None,
                 start: np.ndarray | None = None, params=None) -> Program:
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
    interp = Interpreter(source, params, axes, start9)
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
    return interp.program(_count_lines(data))


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
    if not data:
        return 0
    nl = b"\n" if isinstance(data, bytes) else "\n"
    n = data.count(nl)
    return n if data.endswith(nl) else n + 1

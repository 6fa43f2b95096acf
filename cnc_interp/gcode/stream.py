"""A part program's items as a stream: the interpreter runs in a thread and hands over
every run, dwell and stop as soon as it is closed, through a channel bounded in nodes.

``iter_program`` gives the same items as ``read_program(...).items`` (the same
``finish_run`` of the same builders, the same range checks), so a long program is
fitted and planned while it is still being read, and only the nodes in flight are in
memory (``STREAM_NODES_AHEAD``), not the whole program. Errors are raised where the
consumer reaches them; warnings are issued when the stream ends.
"""

from __future__ import annotations

import os
import threading
import warnings

import numpy as np

from ..constants import ALL_AXES
from ..errors import CncInterpWarning, UsageError
from .program import Dwell, Program, Run, Stop

#: nodes read ahead of the consumer (about 100 bytes each); a longer run is read on only
#: while the consumer waits for it, and passes whole (the fit needs all of a run)
STREAM_NODES_AHEAD = 50_000
#: blocks interpreted between two looks for closed items
_DRAIN_EVERY = 256

_END = object()


class _Channel:
    """A FIFO whose puts block while the items waiting weigh more than ``budget``
    (one item always passes), and give up when ``stop`` is set."""

    def __init__(self, budget: int):
        self.budget = budget
        self.items: list = []
        self.weight = 0
        self.cond = threading.Condition()
        self.stop = False
        self.asking = False  # the consumer waits for the next item

    def put(self, item, weight: int) -> bool:
        with self.cond:
            # an item heavier than the budget (a long run) is handed over only when the
            # consumer asks for it: the interpreter does not start on the next run while
            # one waits and another is being fitted
            while not self.stop and (
                (self.items and self.weight + weight > self.budget) or (weight > self.budget and not self.asking)
            ):
                self.cond.wait(0.1)
            if self.stop:
                return False
            self.items.append((item, weight))
            self.weight += weight
            self.cond.notify_all()
            return True

    def wait_for_ask(self) -> bool:
        """Block until the consumer asks for an item (it has finished what it holds): the
        interpreter does not grow a second long run while one is being fitted. False when
        the stream was closed."""
        with self.cond:
            while not self.asking and not self.stop:
                self.cond.wait(0.1)
            return not self.stop

    def get(self):
        with self.cond:
            while not self.items:
                self.asking = True
                self.cond.notify_all()
                self.cond.wait()
            self.asking = False
            item, weight = self.items.pop(0)
            self.weight -= weight
            self.cond.notify_all()
            return item

    def close(self) -> None:
        with self.cond:
            self.stop = True
            self.cond.notify_all()


class ProgramStream:
    """Iterate over it for the items; after the end, ``program`` holds a ``Program`` with
    the counts and metadata (its items empty: they were handed out).

    ``axes=None`` reads the program for its own axes as ``read_program(axes=None)`` does,
    which are known only at its end: the items then come on all nine axes (XYZABCUVW, an
    axis the program never names held at its start) and ``program.axes`` says which the
    program uses (``cnc-interp parse`` summarises a program so, in bounded memory).

    ``marks=True`` also hands on a ``Mark`` at every tool change and operation header
    (``estimate``'s attribution; no consumer without it sees one). ``noop_mcodes``,
    ``program_units`` and ``max_path_mm_s`` are the machine's, as for ``read_program``."""

    def __init__(
        self,
        data: bytes | str,
        source: str,
        axes: str | None,
        start=None,
        tool_table=None,
        nodes_ahead: int = STREAM_NODES_AHEAD,
        marks: bool = False,
        noop_mcodes=frozenset(),
        program_units: str = "mm",
        max_path_mm_s: float | None = None,
    ):
        from . import _LiveParams, _count_lines, program_len_unit
        from .interp import Interpreter

        names = ALL_AXES
        if axes is not None:
            names = axes = axes.upper()
            bad = [a for a in axes if a not in ALL_AXES]
            if not axes or bad or len(set(axes)) != len(axes):
                raise UsageError(f"bad axis list {axes!r} (letters from {ALL_AXES}, each once)")
        start9 = [0.0] * 9
        if start is not None:
            st = np.asarray(start, dtype=float).ravel()
            if axes is None and st.size == 3:
                names = "XYZ"
            if st.size != len(names) or not np.all(np.isfinite(st)):
                raise UsageError(f"start position needs {len(names)} finite values for axes {names}")
            for a, v in zip(names, st):
                start9[ALL_AXES.index(a)] = float(v)
        self.data = data
        self.source = source
        params = _LiveParams()
        self.interp = interp = Interpreter(source, params, axes, start9, len_unit=program_len_unit(program_units))
        self.max_path_mm_s = max_path_mm_s  # the machine's path speed cap (runs.cap_path_speed)
        interp.noop_mcodes = frozenset(noop_mcodes)  # the machine's declared no-op M-codes
        if isinstance(tool_table, (str, os.PathLike)):
            interp.tool_table_path = os.fspath(tool_table)
        elif tool_table is not None:
            from .tooltable import ToolTable

            interp.tool_table = ToolTable(tool_table)
            interp.tool_table.source = getattr(tool_table, "source", "")
        params.interp = interp
        interp.on_items = self._hand_on
        interp.marks = bool(marks)
        self.params = params
        self.line_count = _count_lines(data)
        self.channel = _Channel(nodes_ahead)
        self.program: Program | None = None
        self.thread_cpu_s = 0.0
        self.wait_s = 0.0  # time the consumer waited for the parse
        self._order = interp.out_order if axes is not None else tuple(range(len(ALL_AXES)))
        self._axes = axes if axes is not None else ALL_AXES
        self._sel = list(self._order)

    # -- the parse thread --------------------------------------------------------------
    def _finish(self, entry):
        from . import _check_ranges
        from .runs import cap_path_speed, finish_run

        kind, obj, extra = entry
        if kind == "mark":
            return obj
        if kind == "run":
            item = cap_path_speed(finish_run(obj, self._order, self._axes, extra), self.max_path_mm_s)
        elif kind == "dwell":
            item = Dwell(line=obj.line, seconds=obj.seconds, position=np.array(extra, dtype=float)[self._sel])
        else:
            item = Stop(line=obj.line, code=obj.code, position=np.array(extra, dtype=float)[self._sel])
        _check_ranges(Program(self.source, self._axes, (item,), np.zeros(len(self._axes)), 0))
        return item

    def _drain(self) -> bool:
        pending = self.interp.items
        while pending:
            entry = pending.pop(0)
            item = self._finish(entry)
            weight = item.n_nodes if isinstance(item, Run) else 1
            if not self.channel.put(item, weight):
                return False
        return True

    def _hand_on(self) -> None:
        """``Interpreter.on_items``: many items closed inside one block (a canned cycle's
        L repeats) go to the consumer now."""
        if not self._drain():
            raise _Stopped()

    def _blocks(self):
        from .blocks import iter_blocks

        interp = self.interp
        count = 0
        for blk in iter_blocks(self.data, self.source, self.params):
            yield blk
            count += 1
            if count >= _DRAIN_EVERY:
                count = 0
                if interp.items and not self._drain():
                    raise _Stopped()
                rb = interp.rb
                if rb is not None and rb.n > self.channel.budget and not self.channel.wait_for_ask():
                    raise _Stopped()

    def _run(self) -> None:
        import time

        t0 = time.thread_time()
        try:
            self.interp.run(self._blocks())
            if self._drain():
                self.program = self.interp.program(self.line_count)
                self.channel.put(_END, 0)
        except _Stopped:
            pass
        except BaseException as exc:  # raised in the consumer, where the stream reaches it
            self.channel.put(exc, 0)
        finally:
            self.thread_cpu_s = time.thread_time() - t0

    # -- the consumer ------------------------------------------------------------------
    def __iter__(self):
        thread = threading.Thread(target=self._run, daemon=True, name="cnc-interp-parse")
        thread.start()
        import time

        try:
            while True:
                t0 = time.perf_counter()
                got = self.channel.get()
                self.wait_s += time.perf_counter() - t0
                if got is _END:
                    break
                if isinstance(got, BaseException):
                    raise got
                yield got
            thread.join()
            for text in self.program.metadata.get("warnings", ()):
                warnings.warn(CncInterpWarning(text), stacklevel=2)
        finally:
            self.channel.close()


class _Stopped(Exception):
    """The consumer went away: stop interpreting."""


def iter_program(
    data: bytes | str,
    source: str,
    axes: str,
    start=None,
    tool_table=None,
    noop_mcodes=frozenset(),
    program_units: str = "mm",
    max_path_mm_s: float | None = None,
):
    """The items of ``read_program(data, source, axes, start, tool_table=...)`` as a
    stream (see module docstring); ``axes`` (the machine's) is required here."""
    stream = ProgramStream(
        data,
        source,
        axes,
        start,
        tool_table,
        noop_mcodes=noop_mcodes,
        program_units=program_units,
        max_path_mm_s=max_path_mm_s,
    )
    return iter(stream)

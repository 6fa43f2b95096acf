"""The end of the streaming plan: every block of samples verified, then written, in a
thread of its own (formatting releases the GIL, so it overlaps the fit and planning).

``PlanSink.put`` hands a ``SampleBlock`` over (blocking while ``SINK_BLOCKS_AHEAD``
wait); the thread checks it with ``StreamVerifier`` and writes it only when every
limit holds; a failure (a violation, a closed pipe, a full disk) is raised in the
caller at its next ``put`` or at ``finish``. The writers see the samples in order and
produce the same bytes however the stream was cut into blocks.
"""

from __future__ import annotations

import queue
import threading
import time

import numpy as np

#: blocks waiting for the writer thread
SINK_BLOCKS_AHEAD = 2

_END = object()


class PlanSink:
    """Verify-then-write of a sample stream into ``fh`` as CSV, MCAP (``mcap``) or a
    halstreamer file (``halstream``); with ``fh = None``, verify only (the plan
    summarised, no setpoints written)."""

    def __init__(self, fh, machine, dt_s: float, mcap: bool, on_violation, halstream: bool = False):
        from ..plan.verify import StreamVerifier

        self.fh = fh
        self.machine = machine
        self.dt = float(dt_s)
        self.mcap = mcap
        self.halstream = halstream
        self.on_violation = on_violation  # report -> raises
        self.verifier = StreamVerifier.for_machine(machine, dt_s)
        self.observe = None  # called with every block verified, before it is written
        self.writer = None
        self.s_prev = None
        self.last_s = 0.0
        self.first_row_at: float | None = None
        self.verify_s = 0.0
        self.write_s = 0.0
        self.error: BaseException | None = None
        self.queue: queue.Queue = queue.Queue(maxsize=SINK_BLOCKS_AHEAD)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True, name="cnc-interp-write")
        self.thread.start()

    # -- the writer thread ---------------------------------------------------------------
    def _open(self):
        # only once the first samples are planned: a plan that fails at once writes
        # nothing, not even a header, to standard output
        if self.mcap:
            from .mcap_io import McapPlanWriter

            return McapPlanWriter(self.fh, self.machine.axes, self.dt, self.machine)
        if self.halstream:
            from .halstream import HalstreamPlanWriter

            return HalstreamPlanWriter(self.fh, self.machine.axes, self.dt)
        from .csv_io import CsvPlanWriter

        return CsvPlanWriter(self.fh, self.machine.axes)

    def _write(self, block) -> None:
        from ..plan.timeline import feed_of

        t0 = time.perf_counter()
        ok = self.verifier.add(block.q)
        t1 = time.perf_counter()
        self.verify_s += t1 - t0
        if not ok:
            self.on_violation(self.verifier.report())
        if self.observe is not None:
            self.observe(block)
        if self.fh is None:
            self.last_s = float(block.s[-1])
            if self.first_row_at is None:
                self.first_row_at = time.perf_counter()
            return
        if self.writer is None:
            self.writer = self._open()
        t = np.arange(block.k0, block.k0 + block.n) * self.dt
        feed = feed_of(block.s, self.s_prev, self.dt)
        self.s_prev = float(block.s[-1])
        if self.mcap:
            self.writer.write(t, block.s, feed, block.q, block.line)
        else:
            self.writer.write(t, block.s, feed, block.q)
        if self.first_row_at is None:
            if not self.mcap:
                self.fh.flush()  # the first rows reach a pipe now, not when a buffer fills
            self.first_row_at = time.perf_counter()
        self.last_s = self.s_prev
        self.write_s += time.perf_counter() - t1

    def _loop(self) -> None:
        while True:
            block = self.queue.get()
            if block is _END or self.stop.is_set():
                return
            if self.error is not None:
                continue  # drain: the caller raises the error
            try:
                self._write(block)
            except BaseException as exc:  # raised in the caller
                self.error = exc

    # -- the caller ----------------------------------------------------------------------
    def _raise(self) -> None:
        if self.error is not None:
            err, self.error = self.error, None
            self.stop.set()
            raise err

    def put(self, block) -> None:
        """Hand the next block over (raises a failure of an earlier one)."""
        self._raise()
        while True:
            try:
                self.queue.put(block, timeout=0.1)
                return
            except queue.Full:
                self._raise()

    def finish(self, planner_record: dict | None = None, metadata: dict | None = None):
        """Wait for every block to be written, check the end (the rest padding) and close
        the file's format. Returns the verify report."""
        self.queue.put(_END)
        self.thread.join()
        self._raise()
        report = self.verifier.report()
        if not report.ok:
            self.on_violation(report)
        if self.fh is None:
            return report
        if self.writer is None:
            self.writer = self._open()
        if self.mcap:
            t1 = time.perf_counter()
            self.writer.finish(planner_record, metadata)
            self.write_s += time.perf_counter() - t1
        return report

    def abort(self) -> None:
        """Stop the writer thread (an error or Ctrl-C in the caller): it writes no more
        and is waited for, so the file can be discarded."""
        self.stop.set()
        try:
            while True:
                self.queue.get_nowait()
        except queue.Empty:
            pass
        try:
            self.queue.put_nowait(_END)
        except queue.Full:
            pass
        self.thread.join(timeout=30)

"""The device side of the protocol: receive frames, check sequence numbers, run the datapath.

``DeviceCore`` is what the FPGA's USB front end and sequencer do; the pyusb
simulator (``device_sim``) and ``emulate`` both drive it. Frames are applied
exactly once: a frame is accepted only with seq = last accepted + 1 and a good
CRC; an older seq is a duplicate (ignored, acknowledged again), a newer one means
a frame was lost (rejected, flagged, the host resends).

Real time (``clocked=True``; ``advance(n)`` lets n sample periods pass): START arms the
device, whose sample clock starts once ``prefill`` samples are buffered (or STOP arrived,
or the buffer is full); a sample the clock needs that has not arrived is an UNDERRUN
(state and error flag; the output holds its last value). HOLD (unsequenced) lets the
clock run on to the next sample where the output is at rest — that sample and the three
before it equal, so velocity, acceleration and jerk are zero there — and holds it
(state HELD) until RESUME; the limits hold through a feed hold. ABORT stops at once,
drops every buffered frame (state ABORTED) and waits for a new program (CONFIG seq 1).
Without ``clocked`` (``emulate``) samples count as output when they are computed.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from .fixed import FixedPointOverflow
from .frames import (
    ErrorFlag,
    Frame,
    FrameError,
    FrameParser,
    FrameType,
    HEADER_SIZE,
    CONTROL_TYPES,
    START,
    STOP,
    TRAILER_SIZE,
    Status,
    decode_config,
    decode_profile,
    decode_segment,
    decode_setpoints,
    status_frame,
)
from .model import DatapathState


#: emulated device receive buffer (bytes)
FPGA_DEVICE_BUFFER = 16384

IDLE, CONFIGURED, RUNNING, DONE, ARMED, HELD, UNDERRUN, ABORTED = range(8)
STATE_NAMES = ("idle", "configured", "running", "done", "armed", "held", "underrun", "aborted")


class DeviceCore:
    """Receive buffer, sequencing and datapath of the emulated controller.

    ``buffer_bytes``: receive FIFO size; accepted frames occupy it until executed.
    ``drain_per_poll``: bytes the datapath consumes per status poll (models the
    device executing samples while the host waits), ``None`` = everything.
    """

    def __init__(
        self,
        buffer_bytes: int = FPGA_DEVICE_BUFFER,
        drain_per_poll: int | None = None,
        clocked: bool = False,
        samples_per_poll: int = 0,
        sink=None,
    ):
        self.buffer_bytes = buffer_bytes
        self.sink = sink  # the datapath's sink (``DatapathState``): samples handed on as computed
        self.drain_per_poll = drain_per_poll
        self.clocked = clocked
        self.samples_per_poll = samples_per_poll  # sample periods that pass per status poll
        self.reset()

    def reset(self) -> None:
        self.parser = FrameParser()
        self.last_seq = 0
        self.errors = 0
        self.state = IDLE
        self.bytes_accepted = 0
        self.datapath: DatapathState | None = None
        self.n_samples = 0
        self.dt_s = 0.0
        self.program_id = 0
        self.applied: list[int] = []  # seq of every applied frame, in order (tests check it)
        self._fifo: deque[int] = deque()  # sizes of accepted, not yet executed frames
        self._used = 0
        self._pending = None  # (segment, n_pieces, pieces so far)
        self.responses: deque[bytes] = deque()  # STATUS frames waiting for IN transfers
        self._crc_seen = 0
        self.prefill = 0
        self.stopped = False  # STOP accepted
        self.samples_out = 0  # samples the sample clock has output
        self.hold_pending = False
        self.output: list[tuple[int, ...]] = []  # clocked: the position at every sample period
        self._last_out: tuple[int, ...] | None = None
        self._start: tuple[int, ...] = ()
        self.run_period = -1

    # -- flow control ------------------------------------------------------------------
    @property
    def free_bytes(self) -> int:
        return max(0, self.buffer_bytes - self._used - len(self.parser.buf))

    def drain(self, budget: int | None = None) -> None:
        """Execute accepted frames (frees their buffer space)."""
        budget = self.drain_per_poll if budget is None else budget
        while self._fifo and (budget is None or budget > 0):
            take = self._fifo[0] if budget is None else min(budget, self._fifo[0])
            self._fifo[0] -= take
            self._used -= take
            if budget is not None:
                budget -= take
            if self._fifo[0] == 0:
                self._fifo.popleft()

    # -- real time -------------------------------------------------------------------
    def _received(self) -> int:
        return self.datapath.next_sample if self.datapath is not None else 0

    def _sample(self, k: int) -> tuple[int, ...]:
        """Output sample k (k < received); before sample 0 the start position."""
        if k < 0:
            return self._start
        out = self.datapath
        for blk in out.q_blocks:  # blocks are few per test; a device reads its output FIFO
            if k < blk.shape[0]:
                return tuple(int(v) for v in blk[k])
            k -= blk.shape[0]
        raise IndexError(k)

    def _at_rest(self, k: int) -> bool:
        """Sample k equals the three before it (zero velocity, acceleration and jerk)."""
        q = self._sample(k)
        return all(self._sample(k - i) == q for i in (1, 2, 3))

    def advance(self, periods: int) -> None:
        """Let ``periods`` sample periods pass (clocked mode): the sample clock outputs samples."""
        for _ in range(int(periods)):
            if self.state == ARMED:
                full = self.free_bytes < 2 * (HEADER_SIZE + TRAILER_SIZE + 4096)
                if self._received() >= self.prefill or self.stopped or full:
                    self.state = RUNNING
                    self.run_period = len(self.output)  # the period of the first sample out
            if self.state == RUNNING:
                if self.samples_out < self._received():
                    k = self.samples_out
                    self._last_out = self._sample(k)
                    self.samples_out += 1
                    if self.hold_pending and self._at_rest(k):
                        self.state, self.hold_pending = HELD, False
                    if self.stopped and self.samples_out == self.n_samples:
                        self.state = DONE
                else:
                    self.state = UNDERRUN
                    self.errors |= ErrorFlag.UNDERRUN
            if self._last_out is not None:
                self.output.append(self._last_out)

    def _control(self, f: Frame) -> None:
        if f.type == FrameType.HOLD and self.state in (RUNNING, ARMED):
            self.hold_pending = True
        elif f.type == FrameType.RESUME:
            self.hold_pending = False
            if self.state == HELD:
                self.state = RUNNING if self.samples_out < self.n_samples or not self.stopped else DONE
        elif f.type == FrameType.ABORT and self.state not in (IDLE,):
            self.state = ABORTED
            self.hold_pending = False
            self._fifo.clear()
            self._used = 0
            self._pending = None
            self.parser.buf.clear()

    def status(self, poll_id: int = 0) -> Status:
        """Current status; error flags are cleared once reported."""
        if self.clocked and self.samples_per_poll:
            self.advance(self.samples_per_poll)
        self.drain()
        done = self.samples_out if self.clocked else self._received()
        st = Status(
            self.free_bytes, self.last_seq, self.errors, self.state, done, self.bytes_accepted, poll_id, self.program_id
        )
        self.errors = 0
        return st

    # -- receiving ----------------------------------------------------------------------
    def receive(self, data: bytes) -> int:
        """Bytes from the OUT endpoint; returns how many fit the buffer (the rest is refused)."""
        room = self.free_bytes
        if len(data) > room:
            self.errors |= ErrorFlag.OVERFLOW
            data = data[:room]
        frames = self.parser.feed(bytes(data))
        if self.parser.crc_errors != self._crc_seen:
            self._crc_seen = self.parser.crc_errors
            self.errors |= ErrorFlag.CRC
        for f in frames:
            self.handle(f)
        return len(data)

    def handle(self, f: Frame) -> bool:
        """Apply one decoded frame if it is the next in sequence; True if accepted."""
        size = HEADER_SIZE + len(f.payload) + TRAILER_SIZE
        if f.type in CONTROL_TYPES:
            # unsequenced: act at once, answer with exactly one STATUS on the IN endpoint
            if f.type != FrameType.POLL:
                self._control(f)
            self.responses.append(status_frame(self.status(f.seq)))
            return False
        restart = f.type == FrameType.CONFIG and f.seq == 1 and self.state in (IDLE, DONE, ABORTED)
        if restart and self.state in (DONE, ABORTED):
            self.reset()
        if self.state == ABORTED:
            self.errors |= ErrorFlag.BAD_FRAME  # nothing but a new program after an abort
            return False
        if f.seq <= self.last_seq:
            self.errors |= ErrorFlag.DUPLICATE
            return False
        if f.seq != self.last_seq + 1:
            self.errors |= ErrorFlag.SEQ_GAP
            return False
        try:
            self._apply(f)
        except (FrameError, ValueError, KeyError):
            self.errors |= ErrorFlag.BAD_FRAME
            return False
        except FixedPointOverflow:
            self.errors |= ErrorFlag.OVERRUN
            return False
        self.last_seq = f.seq
        self.bytes_accepted += size
        self.applied.append(f.seq)
        self._fifo.append(size)
        self._used += size
        return True

    def _apply(self, f: Frame) -> None:
        t = f.type
        if t == FrameType.CONFIG:
            if f.seq != 1:
                raise FrameError("CONFIG must be the first frame")
            cfg = decode_config(f.payload)
            if not _fits(np.array(cfg.start, dtype=np.int64), cfg.formats.pos):
                raise FrameError("CONFIG start position outside the position format")
            self.datapath = DatapathState(cfg.axes, cfg.formats, cfg.start, cfg.source, sink=self.sink)
            self._start = tuple(int(v) for v in cfg.start)
            self._last_out = self._start if self.clocked else None
            self.n_samples = cfg.n_samples
            self.dt_s = cfg.dt_s
            self.program_id = cfg.program_id
            self.state = CONFIGURED
            return
        if self.datapath is None:
            raise FrameError("frame before CONFIG")
        if t == FrameType.START:
            if self.state != CONFIGURED:
                raise FrameError("START twice")
            _total, self.prefill = START.unpack(f.payload)
            self.state = ARMED if self.clocked else RUNNING
        elif t == FrameType.SEGMENT:
            if self._pending is not None:
                raise FrameError("SEGMENT before the previous segment's profile is complete")
            seg, n_pieces = decode_segment(f.payload)
            if seg.start_sample != self.datapath.next_sample:
                raise FrameError("segment does not start at the next sample")
            n_axes = len(self.datapath.axes)
            if not (seg.plane[0] < n_axes and seg.plane[1] < n_axes and seg.plane[0] != seg.plane[1]):
                raise FrameError(f"segment plane {seg.plane} is not two of the {n_axes} axes")
            self._pending = (seg, n_pieces, [])
        elif t == FrameType.PROFILE:
            if self._pending is None:
                raise FrameError("PROFILE without SEGMENT")
            seg, n_pieces, have = self._pending
            index, first, pieces = decode_profile(f.payload)
            if index != seg.index or first != len(have) or len(have) + len(pieces) > n_pieces:
                raise FrameError("PROFILE out of order")
            have = have + pieces
            # every length is checked against the program before anything is allocated
            if seg.start_sample + sum(p.n_samples for p in have) > self.n_samples:
                raise FrameError("PROFILE runs past the program's sample count")
            if len(have) == n_pieces:
                from dataclasses import replace

                self.datapath.apply(replace(seg, pieces=tuple(have)))
                self._pending = None
            else:
                self._pending = (seg, n_pieces, have)
        elif t == FrameType.SETPOINTS:
            if self._pending is not None:
                raise FrameError("SETPOINTS inside a segment")
            blk = decode_setpoints(f.payload)
            if blk.start_sample + blk.q.shape[0] > self.n_samples:
                raise FrameError("SETPOINTS run past the program's sample count")
            if blk.q.shape[1] != len(self.datapath.axes):
                raise FrameError("SETPOINTS axis count differs from CONFIG")
            if not _fits(blk.q, self.datapath.formats.pos):
                raise FrameError("SETPOINTS position outside the position format")
            self.datapath.apply(blk)
        elif t == FrameType.STOP:
            total, _n_items = STOP.unpack(f.payload)
            if self._pending is not None or total != self.datapath.next_sample:
                raise FrameError("STOP before every sample arrived")
            self.stopped = True
            if not self.clocked or self.samples_out == self.n_samples:
                self.state = DONE
        else:
            raise FrameError(f"unexpected frame type {t.name}")


def _fits(q: np.ndarray, fmt) -> bool:
    """Every int64 of ``q`` within the signed fixed-point format ``fmt`` (its ``word`` bits):
    a frame may carry any 64-bit value, the device's position registers hold ``word``."""
    if fmt.word >= 64 or q.size == 0:
        return True
    return bool(q.min() >= fmt.min_int and q.max() <= fmt.max_int)

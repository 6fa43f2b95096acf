"""The device side of the protocol: receive frames, check sequence numbers, run the datapath.

``DeviceCore`` is what the FPGA's USB front end and sequencer do; the pyusb
simulator (``device_sim``) and ``emulate`` both drive it. Frames are applied
exactly once: a frame is accepted only with seq = last accepted + 1 and a good
CRC; an older seq is a duplicate (ignored, acknowledged again), a newer one means
a frame was lost (rejected, flagged, the host resends).
"""

from __future__ import annotations

from collections import deque

from ..constants import FPGA_DEVICE_BUFFER
from .fixed import FixedPointOverflow
from .frames import (
    ErrorFlag,
    Frame,
    FrameError,
    FrameParser,
    FrameType,
    HEADER_SIZE,
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

IDLE, CONFIGURED, RUNNING, DONE = 0, 1, 2, 3


class DeviceCore:
    """Receive buffer, sequencing and datapath of the emulated controller.

    ``buffer_bytes``: receive FIFO size; accepted frames occupy it until executed.
    ``drain_per_poll``: bytes the datapath consumes per status poll (models the
    device executing samples while the host waits), ``None`` = everything.
    """

    def __init__(self, buffer_bytes: int = FPGA_DEVICE_BUFFER, drain_per_poll: int | None = None):
        self.buffer_bytes = buffer_bytes
        self.drain_per_poll = drain_per_poll
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

    def status(self, poll_id: int = 0) -> Status:
        """Current status; error flags are cleared once reported."""
        self.drain()
        done = self.datapath.next_sample if self.datapath is not None else 0
        st = Status(self.free_bytes, self.last_seq, self.errors, self.state, done, self.bytes_accepted,
                    poll_id, self.program_id)
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
        if f.type == FrameType.POLL:
            # unsequenced: answer with exactly one STATUS on the IN endpoint
            self.responses.append(status_frame(self.status(f.seq)))
            return False
        restart = f.type == FrameType.CONFIG and f.seq == 1 and self.state in (IDLE, DONE)
        if restart and self.state == DONE:
            self.reset()
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
            self.datapath = DatapathState(cfg.axes, cfg.formats, cfg.start, cfg.source)
            self.n_samples = cfg.n_samples
            self.dt_s = cfg.dt_s
            self.program_id = cfg.program_id
            self.state = CONFIGURED
            return
        if self.datapath is None:
            raise FrameError("frame before CONFIG")
        if t == FrameType.START:
            self.state = RUNNING
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
            self.datapath.apply(blk)
        elif t == FrameType.STOP:
            total, _n_items = STOP.unpack(f.payload)
            if self._pending is not None or total != self.datapath.next_sample:
                raise FrameError("STOP before every sample arrived")
            self.state = DONE
        else:
            raise FrameError(f"unexpected frame type {t.name}")

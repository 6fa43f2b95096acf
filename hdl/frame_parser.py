"""The device's frame layer in Amaranth: byte stream in, accepted frames and STATUS out.

Mirrors ``cnc_interp.fpga.frames.FrameParser`` and the sequencing of
``cnc_interp.fpga.device.DeviceCore.handle`` (docs/fpga-protocol.md sections 2 and 3):

- received bytes go into a circular buffer (``BUFFER_BYTES``, block RAM); the parser reads
  them back, one byte per cycle through a registered read pipeline, so that after a bad
  header or CRC it can drop one byte and search again from the byte after the failed
  frame's start, exactly as the Python parser re-scans its buffer;
- an accepted CONFIG/SEGMENT/PROFILE/SETPOINTS payload is read a second time for the
  decoder (``dec_*``), through a second read port, while the parser already checks the
  next frame: a byte costs one parser cycle and one decoder cycle, in parallel; a frame's
  bytes are freed when its payload is decoded;
- magic ``CNCF``, version, length ≤ 4096 and the header CRC-32 are checked when the 20
  header bytes are in; the frame CRC-32 (IEEE, reflected, computed bytewise by an unrolled
  8-step XOR network) when the trailer is; an unknown type counts as a CRC error (as
  ``decode_frame`` does);
- sequenced frames are accepted only with seq = last + 1 (older: DUPLICATE, newer:
  SEQ_GAP); CONFIG seq 1 restarts an idle, finished or aborted device (counters and flags
  cleared); a frame before CONFIG, CONFIG with seq ≠ 1, START twice, a STATUS frame sent to
  the device, and anything after ABORT are BAD_FRAME;
- POLL, HOLD, RESUME, ABORT are acted on at once and answered by a STATUS snapshot
  (``status_valid``): last seq, error flags (then cleared), state, bytes accepted, the
  command id (the header's seq) and the program id (CRC-32 field of the CONFIG payload).

Not here (see the issue note): decoding SEGMENT/PROFILE/SETPOINTS payloads into the
datapath's FIFOs and their content checks, and the sample clock (prefill, underrun).
"""

from __future__ import annotations

from amaranth import Cat, Module, Mux, Signal
from amaranth.lib import wiring
from amaranth.lib.memory import Memory
from amaranth.lib.wiring import In, Out

from cnc_interp.fpga.frames import MAGIC, MAX_PAYLOAD, VERSION, ErrorFlag, FrameType

BUFFER_BITS = 14  # 16 KiB receive buffer (the device buffer of the protocol)
CRC_POLY = 0xEDB88320
CONFIG_HEAD = 55  # bytes of the CONFIG payload before the start positions
IDLE, CONFIGURED, RUNNING, DONE, ARMED, HELD, UNDERRUN, ABORTED = range(8)


def crc32_byte(m: Module, crc, byte):
    """Next CRC-32 register after one byte (reflected, as zlib): an unrolled XOR network
    (one signal per bit step, so that no expression is duplicated)."""
    c = Signal(32, name="crc_in")
    m.d.comb += c.eq(crc ^ byte)  # the byte enters the low 8 bits
    for i in range(8):
        n = Signal(32, name=f"crc_step{i}")
        m.d.comb += n.eq(Mux(c[0], (c >> 1) ^ CRC_POLY, c >> 1))
        c = n
    return c


class FrameParser(wiring.Component):
    """in_data/in_valid/in_ready: bytes from the USB OUT endpoint.

    Per accepted sequenced frame: acc_valid (one cycle) with acc_type, acc_seq, acc_len.
    Per control frame: status_valid with st_last_seq, st_errors, st_state, st_bytes,
    st_poll_id, st_program_id (the values a STATUS frame carries).
    """

    def __init__(self, clocked: bool = False, buffer_bits: int = BUFFER_BITS):
        self.clocked = clocked
        self.buffer_bits = buffer_bits
        super().__init__(
            {
                "in_data": In(8),
                "in_valid": In(1),
                "in_ready": Out(1),
                "acc_valid": Out(1),
                "acc_type": Out(8),
                "acc_seq": Out(32),
                "acc_len": Out(16),
                "status_valid": Out(1),
                "st_last_seq": Out(32),
                "st_errors": Out(8),
                "st_state": Out(3),
                "st_bytes": Out(64),
                "st_poll_id": Out(32),
                "st_program_id": Out(32),
                # second pass over an accepted CONFIG/SEGMENT/PROFILE/SETPOINTS payload, for the decoder
                "dec_valid": Out(1),
                "dec_ready": In(1),
                "dec_data": Out(8),
                "dec_pos": Out(16),
                "dec_type": Out(8),
            }
        )

    def elaborate(self, platform):
        m = Module()
        B = self.buffer_bits
        n = 1 << B
        m.submodules.mem = mem = Memory(shape=8, depth=n, init=[])
        wp = mem.write_port()
        # not transparent: a byte is read only after the cycle it was written in (pos < avail),
        # and the writer never overwrites a byte still held (wr − base < n), so no bypass logic
        rp = mem.read_port()
        # a second read port for the decoder's pass over an accepted payload, so that it runs
        # while the parser checks the next frame (the buffer is duplicated in block RAM)
        dp = mem.read_port()

        wr = Signal(B + 1)  # bytes written (mod 2n)
        base = Signal(B + 1)  # start of the frame being parsed
        d_busy = Signal()  # the decoder holds an accepted frame's payload
        d_base = Signal(B + 1)  # start of that frame
        hold = Signal(B + 1)  # first byte still needed
        m.d.comb += hold.eq(Mux(d_busy, d_base, base))
        m.d.comb += self.in_ready.eq((wr - hold)[: B + 1] < n)
        m.d.comb += [wp.addr.eq(wr[:B]), wp.data.eq(self.in_data), wp.en.eq(self.in_valid & self.in_ready)]
        with m.If(self.in_valid & self.in_ready):
            m.d.sync += wr.eq(wr + 1)
        avail = Signal(B + 1)
        m.d.comb += avail.eq(wr - base)

        # device state
        last_seq = Signal(32)
        errors = Signal(8)
        state = Signal(3)
        bytes_acc = Signal(64)
        program_id = Signal(32)
        configured = Signal()
        # frame being parsed
        crc = Signal(32)
        hcrc = Signal(32)  # header CRC as computed over bytes 0..15
        ftype = Signal(8)
        version = Signal(8)
        seq = Signal(32)
        length = Signal(32)
        rx = Signal(32)  # received CRC field (header or trailer), little-endian
        n_axes = Signal(8)
        pid = Signal(32)

        # the decoder's pass (below): offset of its next read, address, end, frame type
        d_pos = Signal(16)
        d_addr = Signal(B)
        d_end = Signal(16)  # 20 + payload length: first offset past the payload
        d_type = Signal(8)

        # -- read pipeline: one byte per cycle -------------------------------------------------
        # stage 0 requests the byte at offset rd_pos (address rd_addr = base + rd_pos, kept as
        # a register so that the block RAM's address comes straight from flip-flops); stage 1
        # is the block RAM's read (its data on rp.data); stage 2 registers that byte (so the
        # RAM's slow clock-to-out ends at a flip-flop) and stage C uses it the next cycle. A
        # frame start that fails and a frame's end restart the pipeline at a new offset
        # (``restart``: the bytes in flight are dropped).
        rd_pos = Signal(16)
        rd_addr = Signal(B)
        s1_valid = Signal()
        s1_pos = Signal(16)
        s2_valid = Signal()
        s2_pos = Signal(16)
        byte = Signal(8)  # stage 2's byte
        issue = Signal()
        pos = s2_pos
        m.d.comb += rp.addr.eq(rd_addr)
        m.d.sync += [s2_valid.eq(s1_valid), s2_pos.eq(s1_pos), byte.eq(rp.data), s1_valid.eq(issue), s1_pos.eq(rd_pos)]
        with m.If(issue):
            m.d.sync += [rd_pos.eq(rd_pos + 1), rd_addr.eq(rd_addr + 1)]

        def restart(new_base, offset=0):
            # drop the bytes in flight; read on from offset ``offset`` of ``new_base``
            return [
                base.eq(new_base),
                rd_pos.eq(offset),
                rd_addr.eq((new_base + offset)[:B]),
                s1_valid.eq(0),
                s2_valid.eq(0),
            ]

        m.d.sync += [self.acc_valid.eq(0), self.status_valid.eq(0)]

        def snapshot(poll_id):
            return [
                self.status_valid.eq(1),
                self.st_last_seq.eq(last_seq),
                self.st_errors.eq(errors),
                self.st_state.eq(state),
                self.st_bytes.eq(bytes_acc),
                self.st_poll_id.eq(poll_id),
                self.st_program_id.eq(program_id),
                errors.eq(0),
            ]

        def fail():
            # drop one byte and search again from the next (a CRC error, as in Python)
            return restart(base + 1) + [errors.eq(errors | ErrorFlag.CRC)]

        total = Signal(32)
        m.d.comb += total.eq(length + 24)

        with m.FSM():
            with m.State("READ"):
                m.d.comb += issue.eq(rd_pos < avail)
                with m.If(s2_valid):
                    nxt = crc32_byte(m, Mux(pos == 0, 0xFFFFFFFF, crc), byte)
                    with m.If((pos < 20) | (pos < 20 + length)):  # the trailer is not in its own CRC
                        m.d.sync += crc.eq(nxt)
                    with m.If(pos < 4):
                        magic = Mux(pos == 0, MAGIC[0], Mux(pos == 1, MAGIC[1], Mux(pos == 2, MAGIC[2], MAGIC[3])))
                        with m.If(byte != magic):
                            # not a frame start: advance the search by one byte (no error)
                            m.d.sync += restart(base + 1)
                    with m.Elif(pos == 4):
                        m.d.sync += version.eq(byte)
                    with m.Elif(pos == 5):
                        m.d.sync += ftype.eq(byte)
                    with m.Elif((pos >= 8) & (pos < 12)):
                        m.d.sync += seq.eq(Cat(seq[8:], byte))
                    with m.Elif((pos >= 12) & (pos < 16)):
                        m.d.sync += length.eq(Cat(length[8:], byte))
                    with m.If(pos == 15):
                        m.d.sync += hcrc.eq(~nxt)
                    with m.If((pos >= 16) & (pos < 20)):
                        m.d.sync += rx.eq(Cat(rx[8:], byte))
                    with m.If(pos == 19):
                        hdr = Cat(rx[8:], byte)
                        with m.If((hdr != hcrc) | (version != VERSION) | (length > MAX_PAYLOAD)):
                            m.d.sync += fail()
                    # CONFIG payload fields: n_axes, then the program id after the start positions
                    with m.If(pos == 20):
                        m.d.sync += n_axes.eq(byte)
                    pid_at = Signal(16)
                    m.d.comb += pid_at.eq(20 + CONFIG_HEAD + (n_axes << 3))
                    with m.If((pos >= pid_at) & (pos < pid_at + 4) & (pos >= 21)):
                        m.d.sync += pid.eq(Cat(pid[8:], byte))
                    with m.If((pos >= 20) & (pos + 4 >= total) & (pos < total)):
                        m.d.sync += rx.eq(Cat(rx[8:], byte))
                    with m.If((pos >= 20) & (pos + 1 == total)):
                        frame_crc = Cat(rx[8:], byte)
                        known = (ftype >= FrameType.CONFIG) & (ftype <= FrameType.ABORT)
                        with m.If((frame_crc != ~crc) | ~known):
                            m.d.sync += fail()
                        with m.Else():
                            # hold the frame's bytes; the reads past it are dropped
                            m.d.sync += restart(base)
                            m.next = "HANDLE"
            with m.State("HANDLE"):
                # the frame's bytes stay in the buffer until its payload is decoded
                m.d.sync += restart(base + total)
                m.next = "READ"
                control = (
                    (ftype == FrameType.POLL)
                    | (ftype == FrameType.HOLD)
                    | (ftype == FrameType.RESUME)
                    | (ftype == FrameType.ABORT)
                )
                restart_dev = (
                    (ftype == FrameType.CONFIG) & (seq == 1) & ((state == IDLE) | (state == DONE) | (state == ABORTED))
                )
                with m.If(control):
                    with m.If((ftype == FrameType.ABORT) & (state != IDLE)):
                        m.d.sync += state.eq(ABORTED)
                        m.d.sync += snapshot(seq)
                        m.d.sync += self.st_state.eq(ABORTED)
                    with m.Else():
                        m.d.sync += snapshot(seq)
                with m.Else():
                    cur_last = Mux(restart_dev, 0, last_seq)
                    cur_state = Mux(restart_dev, IDLE, state)
                    cur_cfg = Mux(restart_dev, 0, configured)
                    cur_err = Mux(restart_dev, 0, errors)
                    cur_bytes = Mux(restart_dev, 0, bytes_acc)
                    with m.If(restart_dev):
                        m.d.sync += [
                            last_seq.eq(0),
                            state.eq(IDLE),
                            configured.eq(0),
                            errors.eq(0),
                            bytes_acc.eq(0),
                            program_id.eq(0),
                        ]
                    bad = Signal()
                    m.d.comb += bad.eq(
                        ((ftype == FrameType.CONFIG) & (seq != 1))
                        | ((ftype != FrameType.CONFIG) & ~cur_cfg)
                        | ((ftype == FrameType.START) & (cur_state != CONFIGURED))
                        | (ftype == FrameType.STATUS)
                    )
                    with m.If(cur_state == ABORTED):
                        m.d.sync += errors.eq(cur_err | ErrorFlag.BAD_FRAME)
                    with m.Elif(seq <= cur_last):
                        m.d.sync += errors.eq(cur_err | ErrorFlag.DUPLICATE)
                    with m.Elif(seq != cur_last + 1):
                        m.d.sync += errors.eq(cur_err | ErrorFlag.SEQ_GAP)
                    with m.Elif(bad):
                        m.d.sync += errors.eq(cur_err | ErrorFlag.BAD_FRAME)
                    with m.Else():
                        m.d.sync += [
                            last_seq.eq(seq),
                            bytes_acc.eq(cur_bytes + total),
                            self.acc_valid.eq(1),
                            self.acc_type.eq(ftype),
                            self.acc_seq.eq(seq),
                            self.acc_len.eq(length),
                        ]
                        with m.If(
                            (
                                (ftype == FrameType.CONFIG)
                                | (ftype == FrameType.SEGMENT)
                                | (ftype == FrameType.PROFILE)
                                | (ftype == FrameType.SETPOINTS)
                            )
                            & (length != 0)
                        ):
                            m.d.sync += restart(base)
                            m.next = "HANDOFF"
                        with m.Switch(ftype):
                            with m.Case(FrameType.CONFIG):
                                m.d.sync += [configured.eq(1), state.eq(CONFIGURED), program_id.eq(pid)]
                            with m.Case(FrameType.START):
                                m.d.sync += state.eq(ARMED if self.clocked else RUNNING)
                            with m.Case(FrameType.STOP):
                                m.d.sync += state.eq(DONE)
            with m.State("HANDOFF"):
                # give the payload to the decoder once it has finished the previous one, then
                # parse on from the next frame while it is decoded
                with m.If(~d_busy):
                    m.d.sync += [
                        d_busy.eq(1),
                        d_base.eq(base),
                        d_pos.eq(20),
                        d_addr.eq((base + 20)[:B]),
                        d_end.eq(20 + length),
                        d_type.eq(ftype),
                    ]
                    m.d.sync += restart(base + total)
                    m.next = "READ"

        # -- decoder's pass over an accepted CONFIG/SEGMENT/PROFILE/SETPOINTS payload ---------
        # the same three stages as the parser's reads, on the second port; one byte per cycle
        # while the decoder takes them (``dec_ready``), every stage held while it does not
        d1_valid = Signal()
        d1_pos = Signal(16)
        d2_valid = Signal()
        d2_last = Signal()
        d2_dpos = Signal(16)  # offset in the payload
        d_byte = Signal(8)
        d_stall = Signal()
        d_issue = Signal()
        m.d.comb += [
            d_stall.eq(d2_valid & ~self.dec_ready),
            d_issue.eq(d_busy & (d_pos < d_end) & ~d_stall),
            dp.addr.eq(d_addr),
            dp.en.eq(~d_stall),
        ]
        with m.If(~d_stall):
            m.d.sync += [
                d2_valid.eq(d1_valid),
                d2_dpos.eq(d1_pos - 20),
                d2_last.eq(d1_pos + 1 == d_end),
                d_byte.eq(dp.data),
                d1_valid.eq(d_issue),
                d1_pos.eq(d_pos),
            ]
            with m.If(d_issue):
                m.d.sync += [d_pos.eq(d_pos + 1), d_addr.eq(d_addr + 1)]
        m.d.comb += [
            self.dec_valid.eq(d2_valid),
            self.dec_data.eq(d_byte),
            self.dec_pos.eq(d2_dpos),
            self.dec_type.eq(d_type),
        ]
        with m.If(d2_valid & self.dec_ready & d2_last):
            m.d.sync += d_busy.eq(0)
        return m

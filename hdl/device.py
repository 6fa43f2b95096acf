"""The whole device in Amaranth: USB bytes in, every axis's setpoint out, per sample.

``FrameParser`` → payload decoder → (segment FIFO, piece FIFO → ``Datapath``; setpoint FIFO)
→ sample merger, with an item FIFO keeping segments and setpoint blocks in program order:

- the decoder takes the parser's second pass over each accepted payload: CONFIG gives the
  number of axes and the start position; a SEGMENT's 112 bytes become one segment FIFO word
  (and an item tag with its plane); every 61-byte piece of a PROFILE one piece FIFO word;
  a SETPOINTS block an item tag with its sample count and one setpoint FIFO word per value;
- the merger holds the position of every axis (up to ``MAX_AXES``) and emits each sample
  as ``n_axes`` words (``smp_valid``, ``smp_axis``, ``smp_value``): a segment's samples set
  its two plane axes (the others hold), a setpoint block's samples set every axis.

The content checks the Python device makes on these payloads (order of segments and
pieces, sample counts against CONFIG) are not here; the frames' CRC and sequence checks
are the parser's.
"""

from __future__ import annotations

from amaranth import Cat, Const, Module, Signal, signed
from amaranth.lib import fifo, wiring
from amaranth.lib.wiring import In, Out

from cnc_interp.fpga.fixed import FpgaFormats
from cnc_interp.fpga.frames import FrameType

from .datapath import SAMPLE_CYCLES, Datapath
from .frame_parser import FrameParser

MAX_AXES = 6
# the merger writes and emits a segment sample in 2 + n_axes cycles, while the datapath already
# computes the next one (see the tick below): that needs a datapath sample to take longer
assert SAMPLE_CYCLES > MAX_AXES + 2
SEGMENT_BYTES = 112
PROFILE_HEAD_BYTES = 10
PIECE_BYTES = 61
SETPOINTS_HEAD_BYTES = 17
CONFIG_START_AT = 55


class Device(wiring.Component):
    def __init__(self, fmts: FpgaFormats | None = None, buffer_bits: int = 14):
        self.f = fmts or FpgaFormats()
        self.buffer_bits = buffer_bits
        super().__init__(
            {
                "in_data": In(8),
                "in_valid": In(1),
                "in_ready": Out(1),
                "tick": In(1),
                "smp_valid": Out(1),
                "smp_axis": Out(4),
                "smp_value": Out(signed(self.f.pos.word)),
                "status_valid": Out(1),
                "st_last_seq": Out(32),
                "st_errors": Out(8),
                "st_state": Out(3),
                "overflow": Out(1),
            }
        )

    def elaborate(self, platform):
        m = Module()
        f = self.f
        W = f.pos.word
        m.submodules.parser = ps = FrameParser(buffer_bits=self.buffer_bits)
        m.submodules.dp = dp = Datapath(f)
        m.submodules.sp_fifo = spf = fifo.SyncFIFOBuffered(width=W, depth=512)  # block RAM
        m.submodules.tag_fifo = tf = fifo.SyncFIFOBuffered(width=1 + 4 + 4 + 32, depth=512)
        m.d.comb += [
            ps.in_data.eq(self.in_data),
            ps.in_valid.eq(self.in_valid),
            self.in_ready.eq(ps.in_ready),
            self.status_valid.eq(ps.status_valid),
            self.st_last_seq.eq(ps.st_last_seq),
            self.st_errors.eq(ps.st_errors),
            self.st_state.eq(ps.st_state),
            self.overflow.eq(dp.overflow),
        ]

        n_axes = Signal(4)
        pos = [Signal(signed(W), name=f"pos{i}") for i in range(MAX_AXES)]
        # one write bus into the axis registers (a register file with one write port: each
        # register is a clock enable, not a multiplexer of every source)
        wen = Signal()
        widx = Signal(4)
        wval = Signal(signed(W))
        m.d.comb += [wen.eq(0), widx.eq(0), wval.eq(0)]
        for i in range(MAX_AXES):
            with m.If(wen & (widx == i)):
                m.d.sync += pos[i].eq(wval)

        # -- payload decoder ----------------------------------------------------------
        byte, p = ps.dec_data, ps.dec_pos
        ready = Signal()
        # from flip-flops only, like the datapath's readies: two places free a cycle ago (at most
        # one write a cycle) leaves one now
        fifos_ok = Signal()
        m.d.sync += fifos_ok.eq((spf.w_level < spf.depth - 1) & (tf.w_level < tf.depth - 1))
        m.d.comb += [ready.eq(dp.seg_ready & dp.piece_ready & fifos_ok), ps.dec_ready.eq(ready)]
        seg_sr = Signal(8 * (SEGMENT_BYTES - 1))
        piece_sr = Signal(8 * (PIECE_BYTES - 1))
        w64 = Signal(56)
        piece_byte = Signal(range(PIECE_BYTES))
        sp_n = Signal(32)
        take = ps.dec_valid & ready

        def le(buf, off, n):  # little-endian field of a completed shift register
            return buf[8 * off : 8 * (off + n)]

        seg_full = Cat(seg_sr, byte)
        piece_full = Cat(piece_sr, byte)
        val64 = Cat(w64, byte)
        m.d.comb += [dp.seg_valid.eq(0), dp.piece_valid.eq(0), spf.w_en.eq(0), tf.w_en.eq(0)]
        m.d.comb += dp.seg_data.eq(
            Cat(
                le(seg_full, 18, 8)[: f.trig.word],
                le(seg_full, 26, 8)[: f.trig.word],
                le(seg_full, 34, 8)[:W],
                le(seg_full, 42, 8)[:W],
                le(seg_full, 50, 1),
                le(seg_full, 51, 8)[: f.mult_word],
                le(seg_full, 59, 1),
                *[le(seg_full, 60 + 8 * i, 8)[: f.coef_word] for i in range(6)],
                le(seg_full, 108, 4)[:16],
            )
        )
        m.d.comb += dp.piece_data.eq(
            Cat(
                le(piece_full, 0, 4),
                le(piece_full, 4, 8)[: f.param.word],
                le(piece_full, 12, 1),
                *[le(piece_full, 13 + 8 * i, 8)[: f.coef_word] for i in range(6)],
            )
        )
        m.d.comb += spf.w_data.eq(val64[:W])
        with m.If(take):
            with m.Switch(ps.dec_type):
                with m.Case(FrameType.CONFIG):
                    m.d.sync += w64.eq(val64[8:])
                    with m.If(p == 0):
                        m.d.sync += n_axes.eq(byte)
                    k = Signal(16)
                    m.d.comb += k.eq(p - CONFIG_START_AT)
                    with m.If((p >= CONFIG_START_AT) & (k[:3] == 7) & (k[3:] < MAX_AXES)):
                        m.d.comb += [wen.eq(1), widx.eq(k[3:]), wval.eq(val64[:W])]
                with m.Case(FrameType.SEGMENT):
                    m.d.sync += seg_sr.eq(seg_full[8:])
                    with m.If(p == SEGMENT_BYTES - 1):
                        m.d.comb += [
                            dp.seg_valid.eq(1),
                            tf.w_en.eq(1),
                            tf.w_data.eq(
                                Cat(Const(0, 1), le(seg_full, 16, 1)[:4], le(seg_full, 17, 1)[:4], Const(0, 32))
                            ),
                        ]
                with m.Case(FrameType.PROFILE):
                    with m.If(p == 0):
                        m.d.sync += piece_byte.eq(0)
                    with m.If(p >= PROFILE_HEAD_BYTES):
                        m.d.sync += [piece_sr.eq(piece_full[8:]), piece_byte.eq(piece_byte + 1)]
                        with m.If(piece_byte == PIECE_BYTES - 1):
                            m.d.comb += dp.piece_valid.eq(1)
                            m.d.sync += piece_byte.eq(0)
                with m.Case(FrameType.SETPOINTS):
                    m.d.sync += w64.eq(val64[8:])
                    with m.If((p >= 8) & (p < 12)):
                        m.d.sync += sp_n.eq(Cat(sp_n[8:], byte))
                    with m.If(p == SETPOINTS_HEAD_BYTES - 1):
                        m.d.comb += [tf.w_en.eq(1), tf.w_data.eq(Cat(Const(1, 1), Const(0, 8), sp_n))]
                    with m.If((p >= SETPOINTS_HEAD_BYTES) & ((p - SETPOINTS_HEAD_BYTES)[:3] == 7)):
                        m.d.comb += spf.w_en.eq(1)

        # -- sample merger ------------------------------------------------------------
        kind = Signal()
        ph = Signal(4)
        pv = Signal(4)
        count = Signal(32)
        axis = Signal(4)
        last = Signal()
        held_v = Signal(signed(W))
        m.d.comb += [tf.r_en.eq(0), spf.r_en.eq(0)]
        m.d.sync += self.smp_valid.eq(0)
        with m.FSM() as merger:
            with m.State("IDLE"):
                with m.If(tf.r_rdy):
                    m.d.comb += tf.r_en.eq(1)
                    m.d.sync += [
                        kind.eq(tf.r_data[0]),
                        ph.eq(tf.r_data[1:5]),
                        pv.eq(tf.r_data[5:9]),
                        count.eq(tf.r_data[9:41]),
                    ]
                    with m.If(tf.r_data[0]):
                        m.next = "SETP"
                    with m.Else():
                        m.next = "SEG"
            with m.State("SEG"):
                with m.If(dp.out_valid):
                    m.d.comb += [wen.eq(1), widx.eq(ph), wval.eq(dp.out_h)]
                    m.d.sync += [axis.eq(0), last.eq(dp.out_last), held_v.eq(dp.out_v)]
                    m.next = "SEG_V"
            with m.State("SEG_V"):
                m.d.comb += [wen.eq(1), widx.eq(pv), wval.eq(held_v)]
                m.next = "EMIT"
            with m.State("SETP"):
                with m.If(count == 0):
                    m.next = "IDLE"
                with m.Else():
                    m.d.sync += axis.eq(0)
                    m.next = "LOAD"
            with m.State("LOAD"):
                with m.If(axis == n_axes):
                    m.d.sync += [axis.eq(0), count.eq(count - 1), last.eq(count == 1)]
                    m.next = "EMIT"
                with m.Elif(spf.r_rdy):
                    m.d.comb += [spf.r_en.eq(1), wen.eq(1), widx.eq(axis), wval.eq(spf.r_data)]
                    m.d.sync += axis.eq(axis + 1)
            with m.State("EMIT"):
                m.d.sync += [self.smp_valid.eq(1), self.smp_axis.eq(axis)]
                for i in range(MAX_AXES):
                    with m.If(axis == i):
                        m.d.sync += self.smp_value.eq(pos[i])
                m.d.sync += axis.eq(axis + 1)
                with m.If(axis + 1 == n_axes):
                    with m.If(kind):
                        m.next = "SETP"
                    with m.Elif(last):
                        m.next = "IDLE"
                    with m.Else():
                        m.next = "SEG"
        # the datapath may start the next sample of the same segment while this one is still
        # being written and emitted: its next output comes SAMPLE_CYCLES later, long after the
        # merger is back in SEG (so segment samples cost the datapath's cycles, not + n_axes)
        m.d.comb += dp.tick.eq(
            self.tick & (merger.ongoing("SEG") | ((merger.ongoing("SEG_V") | merger.ongoing("EMIT")) & ~kind & ~last))
        )
        return m

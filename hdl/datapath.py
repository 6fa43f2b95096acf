"""The FPGA datapath of paper 000 in Amaranth, bit-exact with ``cnc_interp.fpga.model``.

Per sample of a planar segment (golden model ``run_segment``):

    profile Horner  ξ = rs(H(m_j, τ), e_j − fx)       5 products
    abscissa        x* = rs(ξ·x_mant, fx + x_exp − fp)  1 product
    path Horner     z* = rs(H(P, ξ), e_P − fp)         5 products
    increments      Δx* = x* − x*₋₁, Δz* = z* − z*₋₁
    rotation        I_h += c·Δx* − s·Δz*, I_v += s·Δx* + c·Δz*   4 products
    output          q = origin + rs(I, ft)

with rs(v, k) the round-half-up shift of the golden model. All 15 products go through
one shared, pipelined 35×35 signed multiplier built from four 18×18 partial products
(four MULT18X18D on an ECP5); the order of operations is a fixed schedule (``SCHEDULE``)
so each sample takes ``SAMPLE_CYCLES`` + 1 clock cycles (two more at a piece change). Segment descriptors and profile
pieces arrive through two FIFOs (the segment FIFO of the issue); the host-side frame
handler fills them. ``tick`` starts a sample (the sample clock, every dt); tie it high to
run as fast as the datapath can.

Multiplier pipeline (issue at cycle c): c: operands registered; c+1: four partial
products registered (the DSP blocks' own registers); c+2: the 70-bit product registered;
c+3: the consumer uses it. A Horner step therefore takes four cycles.
"""

from __future__ import annotations

import functools
import operator

from amaranth import Cat, Const, Module, Mux, Signal, signed, unsigned
from amaranth.lib import fifo, wiring
from amaranth.lib.wiring import In, Out

from cnc_interp.fpga.fixed import SHIFT_LEFT_MAX, SHIFT_RIGHT_MAX, FpgaFormats

#: cycle of a sample at which each multiplication is issued (see module docstring)
PROFILE_ISSUE = (0, 4, 8, 12, 16)  # profile Horner steps (m5·τ, then acc·τ)
SHIFT_XI = 20  # ξ: variable shift of the profile accumulator (result usable 3 cycles later)
ISSUE_X = 23  # ξ·x_mant
PATH_ISSUE = (24, 28, 32, 36, 40)  # path Horner steps
SHIFT_X = 26  # x*: variable shift of the product
DIFF_X = 29  # Δx*
ISSUE_CDX, ISSUE_SDX = 30, 31
SHIFT_Z = 44  # z*: variable shift of the path accumulator
DIFF_Z = 47
ISSUE_SDZ, ISSUE_CDZ = 48, 49
OUTPUT = 53  # q = origin + rs(I, ft)
SAMPLE_CYCLES = 55  # OUTPUT + 1 (outputs valid) + 1 (next sample's bookkeeping); + 1 in WAIT
MUL_LATENCY = 3  # issue at c, product usable at c + 3

SCHEDULE = {
    "profile": PROFILE_ISSUE,
    "x": ISSUE_X,
    "path": PATH_ISSUE,
    "rotation": (ISSUE_CDX, ISSUE_SDX, ISSUE_SDZ, ISSUE_CDZ),
    "output": OUTPUT,
    "cycles_per_sample": SAMPLE_CYCLES,
}


def segment_layout(f: FpgaFormats) -> list[tuple[str, int]]:
    """Fields of a segment FIFO entry, low bits first: (name, bits)."""
    return (
        [
            ("cos", f.trig.word),
            ("sin", f.trig.word),
            ("origin_h", f.pos.word),
            ("origin_v", f.pos.word),
            ("x_exp", 8),
            ("x_mant", f.mult_word),
            ("p_exp", 8),
        ]
        + [(f"p_mant{i}", f.coef_word) for i in range(6)]
        + [("n_pieces", 16)]
    )


def piece_layout(f: FpgaFormats) -> list[tuple[str, int]]:
    """Fields of a profile-piece FIFO entry, low bits first."""
    return [("n_samples", 32), ("dtau", f.param.word), ("exp", 8)] + [(f"mant{i}", f.coef_word) for i in range(6)]


def pack(layout, values: dict) -> int:
    """Integer FIFO word from field values (two's complement per field)."""
    word, off = 0, 0
    for name, bits in layout:
        v = int(values[name])
        if not -(1 << bits) < v < (1 << bits):
            raise ValueError(f"{name} = {v} does not fit {bits} bits")
        word |= (v & ((1 << bits) - 1)) << off
        off += bits
    return word


def width(layout) -> int:
    return sum(b for _, b in layout)


def _fields(data, layout):
    """Slice a FIFO word into named fields (registered copies are made by the caller)."""
    out, off = {}, 0
    for name, bits in layout:
        out[name] = data[off : off + bits]
        off += bits
    return out


def _one_hot(at, pairs):
    """OR of ``value`` gated by its step's flip-flop ``at(step)``: the value of the step that is
    on (the steps are one-hot), 0 when none is."""
    return functools.reduce(operator.or_, [Mux(at(c), v, 0) for c, v in pairs])


class Multiplier35(wiring.Component):
    """Pipelined signed W×W multiplier from four ≤18×18 partial products (W ≤ 35).

    a, b: operands (registered at the issue cycle); p: product, two cycles later.
    """

    def __init__(self, w: int = 35):
        assert 19 <= w <= 35
        self.w = w
        super().__init__({"a": In(signed(w)), "b": In(signed(w)), "p": Out(signed(2 * w))})

    def elaborate(self, platform):
        m = Module()
        w = self.w
        lo = 17  # unsigned low part; the high part (w - 17 <= 18 bits) carries the sign
        a_lo = Signal(signed(18))
        b_lo = Signal(signed(18))
        a_hi = Signal(signed(w - lo))
        b_hi = Signal(signed(w - lo))
        m.d.comb += [
            a_lo.eq(Cat(self.a[:lo], Const(0, 1))),
            b_lo.eq(Cat(self.b[:lo], Const(0, 1))),
            a_hi.eq(self.a[lo:]),
            b_hi.eq(self.b[lo:]),
        ]
        ll = Signal(unsigned(2 * lo))
        lh = Signal(signed(w + 1))
        hl = Signal(signed(w + 1))
        hh = Signal(signed(2 * (w - lo)))
        # one DSP each; registered outputs
        m.d.sync += [ll.eq(a_lo * b_lo), lh.eq(a_lo * b_hi), hl.eq(a_hi * b_lo), hh.eq(a_hi * b_hi)]
        mid = Signal(signed(w + 2))
        m.d.comb += mid.eq(lh + hl)
        # hh·2^34 + ll is a concatenation (ll < 2^34); one adder adds the middle terms
        base = Signal(signed(2 * w))
        m.d.comb += base.eq(Cat(ll, hh))
        m.d.sync += self.p.eq(base + (mid << lo))
        return m


class RoundShift(wiring.Component):
    """Variable round-half-up shift of the golden model, two cycles.

    v: value (``win`` bits); amount: shift (signed; > 0 rounds right, <= 0 shifts left);
    out: result (``wout`` bits), valid two cycles after v and amount.
    """

    def __init__(self, win: int, wout: int):
        self.win, self.wout = win, wout
        super().__init__({"v": In(signed(win)), "amount": In(signed(9)), "out": Out(signed(wout))})

    def elaborate(self, platform):
        m = Module()
        t = Signal(signed(max(self.win, self.wout) + 1))
        right = Signal()
        amt = self.amount
        # stage 1: t = v >> (k - 1) for k > 0 (then (t + 1) >> 1 rounds half up), v << -k otherwise
        rsh = Signal(range(SHIFT_RIGHT_MAX + 1))
        lsh = Signal(range(SHIFT_LEFT_MAX + 1))
        m.d.comb += [rsh.eq(amt - 1), lsh.eq(-amt)]
        with m.If(amt > 0):
            m.d.sync += [t.eq(self.v >> rsh), right.eq(1)]
        with m.Else():
            m.d.sync += [t.eq(self.v << lsh), right.eq(0)]
        m.d.sync += self.out.eq(Mux(right, (t + 1) >> 1, t))
        return m


class Datapath(wiring.Component):
    """Segment FIFO + piece FIFO in, one planar sample out every ``SAMPLE_CYCLES`` cycles.

    The FIFOs are 512 deep so that they map to block RAM (DP16KD) rather than LUTs.
    Inputs: seg_data/seg_valid (ready: seg_ready), piece_data/piece_valid (piece_ready),
    tick (may a sample start). Outputs per sample (out_valid for one cycle): out_h, out_v
    (positions of the plane axes), out_xi, out_x, out_z (ξ, x*, z*, for test benches),
    out_last (the segment's last sample);
    busy; overflow (sticky: a register left its width, the golden model's OVERRUN).
    """

    def __init__(self, fmts: FpgaFormats | None = None, seg_depth: int = 512, piece_depth: int = 512):
        self.f = f = fmts or FpgaFormats()
        self.seg_layout = segment_layout(f)
        self.piece_layout = piece_layout(f)
        self.seg_depth, self.piece_depth = seg_depth, piece_depth
        super().__init__(
            {
                "seg_data": In(width(self.seg_layout)),
                "seg_valid": In(1),
                "seg_ready": Out(1),
                "piece_data": In(width(self.piece_layout)),
                "piece_valid": In(1),
                "piece_ready": Out(1),
                "tick": In(1),
                "out_valid": Out(1),
                "out_h": Out(signed(f.pos.word)),
                "out_v": Out(signed(f.pos.word)),
                "out_xi": Out(signed(f.param.word)),
                "out_x": Out(signed(f.pos.word)),
                "out_z": Out(signed(f.pos.word)),
                "out_last": Out(1),
                "busy": Out(1),
                "overflow": Out(1),
            }
        )

    def elaborate(self, platform):
        m = Module()
        f = self.f
        W = f.mult_word
        fx, fp, ft = f.param.frac, f.pos.frac, f.trig.frac

        m.submodules.seg_fifo = sf = fifo.SyncFIFOBuffered(width=width(self.seg_layout), depth=self.seg_depth)
        m.submodules.piece_fifo = pf = fifo.SyncFIFOBuffered(width=width(self.piece_layout), depth=self.piece_depth)
        m.d.comb += [
            sf.w_data.eq(self.seg_data),
            sf.w_en.eq(self.seg_valid & self.seg_ready),
            pf.w_data.eq(self.piece_data),
            pf.w_en.eq(self.piece_valid & self.piece_ready),
        ]
        # ready from a flip-flop (the writer's whole decode logic hangs on it): "two places free
        # a cycle ago" leaves at least one now, as at most one word is written per cycle
        m.d.sync += [
            self.seg_ready.eq(sf.w_level < self.seg_depth - 1),
            self.piece_ready.eq(pf.w_level < self.piece_depth - 1),
        ]
        sfd = _fields(sf.r_data, self.seg_layout)
        pfd = _fields(pf.r_data, self.piece_layout)

        # segment registers
        cos = Signal(signed(f.trig.word))
        sin = Signal(signed(f.trig.word))
        org_h = Signal(signed(f.pos.word))
        org_v = Signal(signed(f.pos.word))
        x_exp = Signal(signed(8))
        x_mant = Signal(signed(W))
        p_exp = Signal(signed(8))
        p_mant = [Signal(signed(f.coef_word), name=f"p_mant{i}") for i in range(6)]
        pieces_left = Signal(16)
        # piece registers
        left = Signal(32)
        dtau = Signal(signed(f.param.word))
        e_exp = Signal(signed(8))
        mant = [Signal(signed(f.coef_word), name=f"mant{i}") for i in range(6)]
        tau = Signal(signed(f.param.word))
        # shift amounts of ξ, x*, z* (piece / segment constants)
        amt_xi = Signal(signed(9))
        amt_x = Signal(signed(9))
        amt_z = Signal(signed(9))

        # datapath registers
        acc = Signal(signed(f.horner_word))
        xi = Signal(signed(f.param.word))
        x = Signal(signed(f.pos.word))
        z = Signal(signed(f.pos.word))
        x_prev = Signal(signed(f.pos.word))
        z_prev = Signal(signed(f.pos.word))
        dx = Signal(signed(W))
        dz = Signal(signed(W))
        i_h = Signal(signed(f.int_word))
        i_v = Signal(signed(f.int_word))
        ovf = Signal()
        m.d.comb += self.overflow.eq(ovf)

        m.submodules.mul = mul = Multiplier35(W)
        m.submodules.shift = sh = RoundShift(2 * W, f.pos.word + 2)
        a_op = Signal(signed(W))
        b_op = Signal(signed(W))
        m.d.sync += [mul.a.eq(a_op), mul.b.eq(b_op)]
        p = mul.p

        # the sample's cycle as a one-hot shift register: each scheduled step is enabled by one
        # flip-flop (no counter compare in front of the wide adders and the shifter)
        hot = Signal(SAMPLE_CYCLES)

        def at(c):
            return hot[c]

        def fits(v, bits):
            # v is within the signed range of ``bits``
            return (v >> (bits - 1) == 0) | (v >> (bits - 1) == -1)

        # Horner post-processing: acc <- rs(p, fx) + m_i
        horner_next = Signal(signed(2 * W - fx + 2))
        m_sel = Signal(signed(f.coef_word))
        m.d.comb += horner_next.eq(((p >> (fx - 1)) + 1 >> 1) + m_sel)

        m.d.comb += [a_op.eq(0), b_op.eq(0), sh.v.eq(0), sh.amount.eq(0), m_sel.eq(0)]

        running = Signal()
        m.d.comb += self.busy.eq(running | sf.r_rdy | pf.r_rdy)
        m.d.sync += self.out_valid.eq(0)

        with m.FSM():
            with m.State("IDLE"):
                with m.If(sf.r_rdy):
                    m.d.comb += sf.r_en.eq(1)
                    m.d.sync += [
                        cos.eq(sfd["cos"]),
                        sin.eq(sfd["sin"]),
                        org_h.eq(sfd["origin_h"]),
                        org_v.eq(sfd["origin_v"]),
                        x_exp.eq(sfd["x_exp"]),
                        x_mant.eq(sfd["x_mant"]),
                        p_exp.eq(sfd["p_exp"]),
                        pieces_left.eq(sfd["n_pieces"]),
                        i_h.eq(0),
                        i_v.eq(0),
                        x_prev.eq(0),
                        z_prev.eq(0),
                        amt_x.eq(fx + sfd["x_exp"].as_signed() - fp),
                        amt_z.eq(sfd["p_exp"].as_signed() - fp),
                    ]
                    m.d.sync += [p_mant[i].eq(sfd[f"p_mant{i}"]) for i in range(6)]
                    m.next = "PIECE"
            with m.State("PIECE"):
                with m.If(pieces_left == 0):
                    m.next = "IDLE"
                with m.Elif(pf.r_rdy):
                    m.d.comb += pf.r_en.eq(1)
                    m.d.sync += [
                        left.eq(pfd["n_samples"]),
                        dtau.eq(pfd["dtau"]),
                        e_exp.eq(pfd["exp"]),
                        tau.eq(0),
                        pieces_left.eq(pieces_left - 1),
                        amt_xi.eq(pfd["exp"].as_signed() - fx),
                    ]
                    m.d.sync += [mant[i].eq(pfd[f"mant{i}"]) for i in range(6)]
                    m.next = "WAIT"
            with m.State("WAIT"):
                with m.If(left == 0):
                    m.next = "PIECE"
                with m.Elif(self.tick):
                    m.d.sync += hot.eq(1)
                    m.next = "RUN"
            with m.State("RUN"):
                m.d.comb += running.eq(1)
                m.d.sync += hot.eq(hot << 1)
                # -- multiplier issues: an AND-OR of the one-hot steps (one level of OR tree,
                # not a chain of 15 priority multiplexers in front of the multiplier's registers)
                issues = (
                    [(c, mant[5] if k == 0 else acc, tau) for k, c in enumerate(PROFILE_ISSUE)]
                    + [(ISSUE_X, xi, x_mant)]
                    + [(c, p_mant[5] if k == 0 else acc, xi) for k, c in enumerate(PATH_ISSUE)]
                    + [(ISSUE_CDX, cos, dx), (ISSUE_SDX, sin, dx), (ISSUE_SDZ, sin, dz), (ISSUE_CDZ, cos, dz)]
                )
                m.d.comb += [
                    a_op.eq(_one_hot(at, [(c, u) for c, u, _ in issues])),
                    b_op.eq(_one_hot(at, [(c, v) for c, _, v in issues])),
                ]
                # -- Horner posts (product usable MUL_LATENCY cycles after the issue)
                posts = [
                    (c + MUL_LATENCY, coefs[4 - k])
                    for coefs, issues in ((mant, PROFILE_ISSUE), (p_mant, PATH_ISSUE))
                    for k, c in enumerate(issues)
                ]
                m.d.comb += m_sel.eq(_one_hot(at, posts))
                for c, _ in posts:
                    with m.If(at(c)):
                        m.d.sync += acc.eq(horner_next)
                        with m.If(~fits(horner_next, f.horner_word)):
                            m.d.sync += ovf.eq(1)
                # -- variable shifts (two cycles each; the unit is free in between); the
                # amounts are per piece / per segment registers
                m.d.comb += [
                    sh.v.eq(_one_hot(at, [(SHIFT_XI, acc), (SHIFT_X, p), (SHIFT_Z, acc)])),
                    sh.amount.eq(_one_hot(at, [(SHIFT_XI, amt_xi), (SHIFT_X, amt_x), (SHIFT_Z, amt_z)])),
                ]
                with m.If(at(SHIFT_XI + 2)):
                    m.d.sync += xi.eq(sh.out)
                    with m.If(~fits(sh.out, f.param.word)):
                        m.d.sync += ovf.eq(1)
                with m.If(at(SHIFT_X + 2)):
                    m.d.sync += x.eq(sh.out)
                with m.If(at(DIFF_X)):
                    m.d.sync += [dx.eq(x - x_prev), x_prev.eq(x)]
                    with m.If(~fits(x - x_prev, W)):
                        m.d.sync += ovf.eq(1)
                with m.If(at(SHIFT_Z + 2)):
                    m.d.sync += z.eq(sh.out)
                with m.If(at(DIFF_Z)):
                    m.d.sync += [dz.eq(z - z_prev), z_prev.eq(z)]
                    with m.If(~fits(z - z_prev, W)):
                        m.d.sync += ovf.eq(1)
                # -- integrators
                for c, reg, sign in (
                    (ISSUE_CDX, i_h, 1),
                    (ISSUE_SDX, i_v, 1),
                    (ISSUE_SDZ, i_h, -1),
                    (ISSUE_CDZ, i_v, 1),
                ):
                    with m.If(at(c + MUL_LATENCY)):
                        nxt = reg + p if sign > 0 else reg - p
                        m.d.sync += reg.eq(nxt)
                        with m.If(~fits(nxt, f.int_word)):
                            m.d.sync += ovf.eq(1)
                # -- output
                with m.If(at(OUTPUT)):
                    qh = org_h + ((i_h >> (ft - 1)) + 1 >> 1)
                    qv = org_v + ((i_v >> (ft - 1)) + 1 >> 1)
                    m.d.sync += [
                        self.out_h.eq(qh),
                        self.out_v.eq(qv),
                        self.out_xi.eq(xi),
                        self.out_x.eq(x),
                        self.out_z.eq(z),
                        self.out_valid.eq(1),
                        self.out_last.eq((left == 1) & (pieces_left == 0)),
                    ]
                    with m.If(~fits(qh, f.pos.word) | ~fits(qv, f.pos.word)):
                        m.d.sync += ovf.eq(1)
                with m.If(at(SAMPLE_CYCLES - 1)):
                    m.d.sync += [tau.eq(tau + dtau), left.eq(left - 1)]
                    m.next = "WAIT"
        return m

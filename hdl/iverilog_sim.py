"""Fast bit-exact simulation: the datapath's generated Verilog under Verilator (or Icarus).

Amaranth's own simulator runs the datapath at about 100 samples/s (and Icarus Verilog
is no faster on this design), too slow for the ≥150k-sample comparison; Verilator
(Debian's ``verilator``) compiles the Verilog that Amaranth generates from the same
design into a C++ model that is orders of magnitude faster. The test bench
reads the segment and piece FIFO words with ``$readmemh``, pushes them through the
ready/valid ports, and writes every sample's (ξ, x*, z*, q_h, q_v) in hex.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile

from cnc_interp.fpga.fixed import FpgaFormats

from .datapath import Datapath, width
from .sim import SimResult, piece_words, segment_word

TB = """`timescale 1ns/1ps
module tb;
  reg clk = 0;
  reg rst = 1;
  always #5 clk = ~clk;
  reg [{sw}-1:0] segs [0:{ns}-1];
  reg [{pw}-1:0] pieces [0:{np}-1];
  integer si = 0, pi = 0, n = 0, cycles = 0, fd;
  wire seg_ready, piece_ready, out_valid, busy, overflow;
  wire seg_valid = (si < {ns});
  wire piece_valid = (pi < {np});
  wire [{sw}-1:0] seg_data = segs[si];
  wire [{pw}-1:0] piece_data = pieces[pi];
  wire [{xw}-1:0] out_xi;
  wire [{qw}-1:0] out_x, out_z, out_h, out_v;
  datapath dut(.clk(clk), .rst(rst), .seg_data(seg_data), .seg_valid(seg_valid),
               .seg_ready(seg_ready), .piece_data(piece_data), .piece_valid(piece_valid),
               .piece_ready(piece_ready), .tick(1'b1), .out_valid(out_valid), .out_h(out_h),
               .out_v(out_v), .out_xi(out_xi), .out_x(out_x), .out_z(out_z), .busy(busy),
               .overflow(overflow));
  initial begin
    $readmemh("segs.hex", segs);
    $readmemh("pieces.hex", pieces);
    fd = $fopen("out.hex", "w");
    @(posedge clk);
    @(posedge clk);
    rst <= 0;
  end
  always @(posedge clk) if (!rst) begin
    cycles <= cycles + 1;
    if (seg_valid && seg_ready) si <= si + 1;
    if (piece_valid && piece_ready) pi <= pi + 1;
    if (out_valid) begin
      $fwrite(fd, "%h %h %h %h %h\\n", out_xi, out_x, out_z, out_h, out_v);
      n = n + 1;
      if (n == {total}) begin
        $fwrite(fd, "cycles %0d overflow %0d\\n", cycles + 1, overflow);
        $fclose(fd);
        $finish;
      end
    end
    if (cycles > {limit}) begin
      $fwrite(fd, "timeout %0d\\n", cycles);
      $fclose(fd);
      $finish;
    end
  end
endmodule
"""


def available() -> str | None:
    """The fastest simulator installed: "verilator", "iverilog" or None."""
    if shutil.which("verilator"):
        return "verilator"
    if shutil.which("iverilog") and shutil.which("vvp"):
        return "iverilog"
    return None


def _signed(text: str, bits: int) -> int:
    v = int(text, 16)
    return v - (1 << bits) if v >> (bits - 1) else v


def simulate(segments, fmts: FpgaFormats | None = None, workdir: str | None = None) -> SimResult:
    """Run the segments through the generated Verilog under Icarus; every sample's outputs."""
    from amaranth.back import verilog

    fmts = fmts or FpgaFormats()
    dp = Datapath(fmts)
    segs = list(segments)
    total = sum(s.n_samples for s in segs)
    if not total:
        return SimResult([], 0, False)
    sw, pw = width(dp.seg_layout), width(dp.piece_layout)
    tmp = workdir or tempfile.mkdtemp(prefix="cnc-hdl-")
    os.makedirs(tmp, exist_ok=True)
    try:
        with open(os.path.join(tmp, "datapath.v"), "w") as fh:
            fh.write(verilog.convert(dp, name="datapath"))
        seg_lines = [format(segment_word(dp, s), f"0{(sw + 3) // 4}x") for s in segs]
        piece_lines = [format(w, f"0{(pw + 3) // 4}x") for s in segs for w in piece_words(dp, s)]
        with open(os.path.join(tmp, "segs.hex"), "w") as fh:
            fh.write("\n".join(seg_lines) + "\n")
        with open(os.path.join(tmp, "pieces.hex"), "w") as fh:
            fh.write("\n".join(piece_lines) + "\n")
        with open(os.path.join(tmp, "tb.v"), "w") as fh:
            fh.write(
                TB.format(
                    sw=sw,
                    pw=pw,
                    ns=len(seg_lines),
                    np=len(piece_lines),
                    total=total,
                    xw=fmts.param.word,
                    qw=fmts.pos.word,
                    limit=100 * total + 10_000,
                )
            )
        tool = available()
        if tool == "verilator":
            subprocess.run(
                [
                    "verilator",
                    "--binary",
                    "--timing",
                    "-j",
                    "2",
                    "-O3",
                    "-Wno-fatal",
                    "-Wno-lint",
                    "-Wno-style",
                    "--top-module",
                    "tb",
                    "-o",
                    "tbsim",
                    "tb.v",
                    "datapath.v",
                ],
                cwd=tmp,
                check=True,
                capture_output=True,
            )
            subprocess.run([os.path.join(tmp, "obj_dir", "tbsim")], cwd=tmp, check=True, capture_output=True)
        elif tool == "iverilog":
            subprocess.run(
                ["iverilog", "-g2012", "-o", "tb.vvp", "tb.v", "datapath.v"], cwd=tmp, check=True, capture_output=True
            )
            subprocess.run(["vvp", "-n", "tb.vvp"], cwd=tmp, check=True, capture_output=True)
        else:
            raise RuntimeError("no Verilog simulator: install verilator or iverilog")
        samples, cycles, ovf = [], 0, False
        with open(os.path.join(tmp, "out.hex")) as fh:
            for line in fh:
                parts = line.split()
                if parts[0] == "cycles":
                    cycles, ovf = int(parts[1]), parts[3] != "0"
                elif parts[0] == "timeout":
                    raise RuntimeError(f"HDL simulation timed out after {parts[1]} cycles")
                else:
                    xi = _signed(parts[0], fmts.param.word)
                    x, z, qh, qv = (_signed(p, fmts.pos.word) for p in parts[1:])
                    samples.append((xi, x, z, qh, qv))
        return SimResult(samples, cycles, ovf)
    finally:
        if workdir is None:
            shutil.rmtree(tmp, ignore_errors=True)

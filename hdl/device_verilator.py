"""The whole HDL device under Verilator (or Icarus), fed a frame file's bytes.

Amaranth's simulator runs the device at about 100 samples/s; this runs the generated
Verilog at thousands, so whole ``stream --dry-run`` frame files can be compared with the
Python device (``benchmarks/hdl.py``, ``tests/test_hdl_device.py``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile

import numpy as np

from cnc_interp.fpga.fixed import FpgaFormats

from .device import Device
from .iverilog_sim import available

TB = """`timescale 1ns/1ps
module tb;
  reg clk = 0;
  reg rst = 1;
  always #5 clk = ~clk;
  reg [7:0] bytes [0:{nb}-1];
  integer bi = 0, nv = 0, cycles = 0, idle = 0, fd;
  wire in_ready, smp_valid, status_valid, overflow;
  wire [3:0] smp_axis;
  wire [{qw}-1:0] smp_value;
  wire [31:0] st_last_seq;
  wire [7:0] st_errors;
  wire [2:0] st_state;
  wire in_valid = (bi < {nb});
  wire [7:0] in_data = bytes[bi];
  device dut(.clk(clk), .rst(rst), .in_data(in_data), .in_valid(in_valid), .in_ready(in_ready),
             .tick(1'b1), .smp_valid(smp_valid), .smp_axis(smp_axis), .smp_value(smp_value),
             .status_valid(status_valid), .st_last_seq(st_last_seq), .st_errors(st_errors),
             .st_state(st_state), .overflow(overflow));
  initial begin
    $readmemh("bytes.hex", bytes);
    fd = $fopen("out.txt", "w");
    @(posedge clk);
    @(posedge clk);
    rst <= 0;
  end
  always @(posedge clk) if (!rst) begin
    cycles <= cycles + 1;
    if (in_valid && in_ready) bi <= bi + 1;
    if (smp_valid) begin
      $fwrite(fd, "v %h %0d\\n", smp_value, cycles);
      nv = nv + 1;
      idle = 0;
    end else if (bi >= {nb}) idle = idle + 1;
    if (status_valid) $fwrite(fd, "s %0d %0d %0d\\n", st_last_seq, st_errors, st_state);
    if (idle > {idle_limit} || cycles > {limit}) begin
      $fwrite(fd, "end %0d %0d\\n", cycles, overflow);
      $fclose(fd);
      $finish;
    end
  end
endmodule
"""


def run_device(data: bytes, n_axes: int, fmts: FpgaFormats | None = None, workdir: str | None = None):
    """(samples (K, n_axes) int64, STATUS answers [(last seq, errors, state)], stamps (K,) int64).

    stamps[k]: the clock cycle (counted from reset, bytes offered one per cycle from cycle 0)
    at which the device put out the last axis of sample k."""
    from amaranth.back import verilog

    fmts = fmts or FpgaFormats()
    tool = available()
    if tool is None:
        raise RuntimeError("no Verilog simulator: install verilator or iverilog")
    tmp = workdir or tempfile.mkdtemp(prefix="cnc-dev-")
    os.makedirs(tmp, exist_ok=True)
    try:
        with open(os.path.join(tmp, "device.v"), "w") as fh:
            fh.write(verilog.convert(Device(fmts), name="device"))
        with open(os.path.join(tmp, "bytes.hex"), "w") as fh:
            fh.write("\n".join(f"{b:02x}" for b in data) + "\n")
        with open(os.path.join(tmp, "tb.v"), "w") as fh:
            # the parser reads every byte twice (one cycle each): a full 16 KiB buffer is ~32k
            # cycles without a sample out; the run ends after 300k idle cycles
            fh.write(
                TB.format(nb=len(data), qw=fmts.pos.word, idle_limit=300_000, limit=200 * len(data) + 1_000_000_000)
            )
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
                    "device.v",
                ],
                cwd=tmp,
                check=True,
                capture_output=True,
            )
            subprocess.run([os.path.join(tmp, "obj_dir", "tbsim")], cwd=tmp, check=True, capture_output=True)
        else:
            subprocess.run(
                ["iverilog", "-g2012", "-o", "tb.vvp", "tb.v", "device.v"], cwd=tmp, check=True, capture_output=True
            )
            subprocess.run(["vvp", "-n", "tb.vvp"], cwd=tmp, check=True, capture_output=True)
        vals, stamps, sts = [], [], []
        bits = fmts.pos.word
        with open(os.path.join(tmp, "out.txt")) as fh:
            for line in fh:
                parts = line.split()
                if parts[0] == "v":
                    v = int(parts[1], 16)
                    vals.append(v - (1 << bits) if v >> (bits - 1) else v)
                    stamps.append(int(parts[2]))
                elif parts[0] == "s":
                    sts.append(tuple(int(x) for x in parts[1:]))
        q = np.array(vals[: len(vals) - len(vals) % n_axes], dtype=np.int64).reshape(-1, n_axes)
        k = q.shape[0]
        return q, sts, np.array(stamps[n_axes - 1 : k * n_axes : n_axes], dtype=np.int64)
    finally:
        if workdir is None:
            shutil.rmtree(tmp, ignore_errors=True)

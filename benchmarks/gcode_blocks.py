"""Speed of the G-code language layer alone (``gcode.blocks.iter_blocks``).

Usage:
    .venv/bin/python benchmarks/gcode_blocks.py [--lines 1000000] [--repeat 3] [--no-write] [FILE ...]

Times iterating all Blocks (tokenising, no modal interpretation) of: a generated
CAM-style program (``N123 G1 X1.234 Y-5.6 F1200``, a G2 with I J every 10th line,
a comment every 500th), the corpus's ``stellabee1.ngc``, an O-word loop program,
and any FILE given. Reports lines/s from wall time and from CPU time (the machine
is shared; CPU time is the steadier figure), with the cyclic GC on (default Python)
and paused (as a caller may do around a whole parse). Target for this layer alone:
>= 500,000 lines/s on plain CAM lines. Writes the table to ``benchmarks/RESULTS.md`` (its
"G-code blocks" section) unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import gc
import os
import random
import sys
import time

from _results import command_line, md_table, write_section

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
STELLABEE = os.path.join(ROOT, "..", "shared", "corpus", "linuxcnc", "performance", "stellabee1.ngc")


def cam_program(n_lines: int, seed: int = 1) -> bytes:
    """A deterministic CAM-style program of ``n_lines`` lines."""
    rng = random.Random(seed)
    out = []
    x = y = 0.0
    for i in range(n_lines):
        x += rng.uniform(-1, 1)
        y += rng.uniform(-1, 1)
        if i % 500 == 0:
            out.append(f"(pass {i})")
        elif i % 10 == 0:
            out.append(f"N{i} G2 X{x:.4f} Y{y:.4f} I{rng.uniform(-1, 1):.4f} J{rng.uniform(-1, 1):.4f}")
        else:
            out.append(f"N{i} G1 X{x:.4f} Y{y:.4f} F1200")
    return ("\n".join(out) + "\n").encode()


def oword_program(n_iter: int) -> bytes:
    """A while loop with an expression-valued move: 4 executed lines per iteration."""
    return (
        f"#1 = 0\no100 while [#1 LT {n_iter}]\n  G1 X[#1 * 0.01] Y[SIN[#1]] F1000\n  #1 = [#1 + 1]\no100 endwhile\nM2\n"
    ).encode()


def measure(data: bytes, executed_lines: int, repeat: int, gc_on: bool) -> tuple[float, float]:
    from cnc_interp.gcode.blocks import iter_blocks
    from cnc_interp.gcode.params import ParamStore

    best_wall = best_cpu = float("inf")
    for _ in range(repeat):
        if not gc_on:
            gc.disable()
        try:
            w0, c0 = time.perf_counter(), time.process_time()
            for _b in iter_blocks(data, "bench", ParamStore()):
                pass
            w1, c1 = time.perf_counter(), time.process_time()
        finally:
            gc.enable()
        best_wall = min(best_wall, w1 - w0)
        best_cpu = min(best_cpu, c1 - c0)
    return executed_lines / best_wall, executed_lines / best_cpu


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("files", nargs="*")
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    import numpy  # noqa: F401  (import cost is not part of the measurement)

    cases = [(f"generated CAM ({args.lines:,} lines)", cam_program(args.lines), args.lines)]
    if os.path.exists(STELLABEE):
        data = open(STELLABEE, "rb").read()
        cases.append(("stellabee1.ngc", data, data.count(b"\n")))
    n_iter = 50_000
    cases.append((f"O-word while loop ({n_iter:,} iterations)", oword_program(n_iter), 3 * n_iter))
    for f in args.files:
        data = open(f, "rb").read()
        cases.append((os.path.basename(f), data, data.count(b"\n")))
    print(f"{'program':42s} {'lines':>10s} {'GC on: wall':>12s} {'cpu':>10s} {'GC off: wall':>13s} {'cpu':>10s}")
    table = []
    for name, data, n in cases:
        on = measure(data, n, args.repeat, True)
        off = measure(data, n, args.repeat, False)
        print(f"{name:42s} {n:10,d} {on[0]:12,.0f} {on[1]:10,.0f} {off[0]:13,.0f} {off[1]:10,.0f}")
        table.append([name, f"{n:,}", f"{on[0]:,.0f}", f"{on[1]:,.0f}", f"{off[0]:,.0f}", f"{off[1]:,.0f}"])
    print("(lines/s; O-word row counts executed lines)")
    if not args.no_write:
        write_section(
            "G-code blocks",
            "gcode_blocks.py",
            command_line("gcode_blocks.py", argv),
            md_table(["program", "lines", "GC on: lines/s", "lines/CPU-s", "GC off: lines/s", "lines/CPU-s"], table),
            f"`iter_blocks` alone (no modal interpretation), best of {args.repeat}; the O-word row counts "
            "executed lines. Target: 500,000 lines/s on plain CAM lines.",
        )


if __name__ == "__main__":
    main()

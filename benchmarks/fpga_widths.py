"""Width sweep of the FPGA formats: which words keep the round trip within 0.02 µm and the limits.

For each candidate (position fraction bits; multiplier operand word, which sets the
trig, parameter and Horner words and, three bits narrower, the coefficient mantissas),
every program is planned as ``stream`` plans it (with the device margin of that position
LSB), quantized with the limit check, and run through the golden model. Printed per
candidate: the device margin δ, the worst deviation from the float plan (µm), the worst
verify ratio of the device's setpoints against the real machine, the share of samples
the segments carry (the rest needed exact setpoints), and overflows.

    .venv/bin/python benchmarks/fpga_widths.py [--quick] [--no-write]

The table goes to ``benchmarks/RESULTS.md`` (its "FPGA word widths" section; "FPGA word widths,
quick" for ``--quick``) unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from _results import command_line, write_section

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)

CORPUS = os.path.join(ROOT, "..", "shared", "corpus", "linuxcnc")
XYZ_INI = os.path.join(CORPUS, "configs", "XYZ.ini")
PARTS = [
    ("lathe-profile", os.path.join(ROOT, "samples", "gcode", "lathe-profile.ngc"), "xz-lathe"),
    ("mill-contour", os.path.join(ROOT, "samples", "gcode", "mill-contour.ngc"), "generic-mill"),
    ("arc-arc-test", os.path.join(CORPUS, "quick-tests", "arc-arc-test.ngc"), XYZ_INI),
    ("zigzag_0.002_0.001", os.path.join(CORPUS, "performance", "zigzag_0.002_0.001.ngc"), XYZ_INI),
]


def formats(pos_frac: int, mult: int, int_bits: int = 14):
    from cnc_interp.fpga.fixed import FixedFormat, FpgaFormats

    pos = FixedFormat(pos_frac + int_bits, pos_frac)
    return FpgaFormats(
        pos=pos,
        trig=FixedFormat(mult, mult - 2),
        param=FixedFormat(mult, mult - 2),
        coef_word=mult - 3,
        horner_word=mult,
        int_word=pos.word + mult - 2 + 1,
        mult_word=mult,
    )


def main(argv=None) -> int:
    from cnc_interp.errors import CncInterpError
    from cnc_interp.fpga.commands import StreamOptions, plan_for_stream
    from cnc_interp.fpga.program import build_program

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="two programs, fewer candidates")
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    parts = PARTS[:2] if args.quick else PARTS
    pos_fracs = (24, 28, 32) if args.quick else (22, 24, 26, 28, 30, 32)
    mults = (18, 27, 35) if args.quick else (18, 24, 27, 31, 35)
    lines = [
        "| pos format | operand word | margin δ | max dev µm | worst device ratio | on segments | notes |",
        "|---|---|---|---|---|---|---|",
    ]
    print("\n".join(lines))
    plans = {}
    for pf in pos_fracs:
        for mw in mults:
            fm = formats(pf, mw)
            devs, ratios, seg_s, tot_s, notes, margin = [], [], 0, 0, [], 0.0
            t0 = time.perf_counter()
            for name, part, machine in parts:
                key = (pf, name)
                try:
                    if key not in plans:
                        plans[key] = plan_for_stream(
                            StreamOptions(part=part, machine_spec=machine, planner="variable", quiet=True),
                            formats=fm,
                            with_machine=True,
                        )
                    fit, traj, m = plans[key]
                    idx = [m.axes.index(a) for a in traj.axes]
                    prog = build_program(traj, fit.paths, formats=fm, limits=m.limits()[:, idx])
                except CncInterpError as exc:
                    notes.append(f"{name}: {exc.args[0][:70]}")
                    continue
                from cnc_interp.fpga.limits import device_margin

                margin = max(margin, device_margin(m, fm))
                st = prog.stats
                devs.append(st["max_dev_mm"])
                ratios.append(st["verify_ratio"])
                seg_s += st["planar_samples"]
                tot_s += prog.n_samples
            dev = f"{max(devs) * 1e3:.4f}" if devs else "—"
            rat = f"{max(ratios):.9f}" if ratios else "—"
            share = f"{100 * seg_s / max(1, tot_s):.1f} %"
            lines.append(
                f"| Q{14}.{pf} ({pf + 14} bits) | {mw} | {margin:.2e} | {dev} | {rat} | {share} | "
                f"{'; '.join(notes) or ''} ({time.perf_counter() - t0:.0f} s) |"
            )
            print(lines[-1], flush=True)
    if not args.no_write:
        write_section(
            "FPGA word widths" + (", quick" if args.quick else ""),
            "fpga_widths.py",
            command_line("fpga_widths.py", argv),
            "\n".join(lines),
            "Programs: " + ", ".join(p[0] for p in parts) + " (variable planner). Per candidate the worst over "
            "the programs; the seconds in the notes column are the candidate's wall time.",
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""FPGA round trip: plan as ``stream`` does -> fixed point -> frames -> device model -> verify.

Per program and planner: samples, planar segments, share of samples sent as segments,
frame bytes per sample, segments re-sent as setpoints for the limits, worst deviation of
the device's setpoints from the float plan (µm), verify's worst ratio of the device's
setpoints against the real machine (must be <= 1 + 1e-9), wall times. The last line sums
it up: ``fpga round trip: R runs, V verify failures, worst ratio X, worst deviation D µm``.
The table goes to ``benchmarks/RESULTS.md`` (its "FPGA round trip" section) unless
``--no-write``.

    .venv/bin/python benchmarks/fpga_roundtrip.py               # the sample programs
    .venv/bin/python benchmarks/fpga_roundtrip.py [--planner all|vpop|...] [-m MACHINE] PART...
    .venv/bin/python benchmarks/fpga_roundtrip.py --done-when   # samples + 21 corpus programs
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from _results import command_line, write_section

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)

from cnc_interp.errors import CncInterpError  # noqa: E402
from cnc_interp.fpga.commands import StreamOptions, build_stream_full  # noqa: E402
from cnc_interp.fpga.device import DeviceCore  # noqa: E402
from cnc_interp.fpga.frames import decode_frame  # noqa: E402
from cnc_interp.fpga.model import to_mm  # noqa: E402
from cnc_interp.plan.verify import verify_arrays  # noqa: E402

CORPUS = os.path.join(ROOT, "..", "shared", "corpus", "linuxcnc")
XYZ_INI = os.path.join(CORPUS, "configs", "XYZ.ini")
SAMPLES = [
    ("drilling-cycles.ngc", "generic-mill"),
    ("five-axis-xyzac.ngc", "mikron-ucp710"),
    ("lathe-profile.ngc", "xz-lathe"),
    ("mill-contour.ngc", "generic-mill"),
    ("nurbs-trident.ngc", "mikron-ucp710"),
]
CORPUS_20 = [
    "quick-tests/" + n
    for n in (
        "arc-arc-concave-convex.ngc",
        "arc-arc-sawtooth.ngc",
        "arc-arc-test.ngc",
        "arc-terminal.ngc",
        "corner_decel.ngc",
        "dodecagon_0.1in.ngc",
        "g0_corners.ngc",
        "line-arc.ngc",
        "linearc.ngc",
        "long-kink.ngc",
        "naive_cam_corner1.ngc",
        "parabolic_bump.ngc",
        "ramp_test.ngc",
        "rapid_3d_corners.ngc",
        "sawtooth.ngc",
        "single_circle.ngc",
        "square.ngc",
        "square_spiral.ngc",
        "straight_segments.ngc",
        "tangent_helix.ngc",
    )
] + ["nurbs-g5/trident-xy.ngc"]


def run_one(part: str, machine: str, planner: str) -> dict:
    opts = StreamOptions(part=part, machine_spec=machine, planner=planner, quiet=True)
    t0 = time.perf_counter()
    prog, frames, _, traj, m = build_stream_full(opts)
    t1 = time.perf_counter()
    core = DeviceCore(buffer_bytes=1 << 31)
    for f in frames:
        assert core.handle(decode_frame(f))
    q = to_mm(core.datapath.output().q, prog.formats)
    idx = [m.axes.index(a) for a in traj.axes]
    rep = verify_arrays(q, traj.dt_s, m.vmax[idx], m.amax[idx], m.jmax[idx], axes=traj.axes)
    st = prog.stats
    return {
        "samples": prog.n_samples,
        "segments": st["segments"],
        "share": st["planar_samples"] / max(1, prog.n_samples),
        "bytes_per_sample": sum(map(len, frames)) / max(1, prog.n_samples),
        "bytes": sum(map(len, frames)),
        "repaired": st["repaired_segments"],
        "dev_um": float(np.max(np.abs(q - traj.q))) * 1e3,
        "ratio": rep.worst_ratio,
        "ok": rep.ok,
        "t": t1 - t0,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("parts", nargs="*")
    ap.add_argument("-m", "--machine", default=XYZ_INI)
    ap.add_argument("--planner", default="all", help="vpop, constant, variable or all")
    ap.add_argument(
        "--done-when", action="store_true", help="every sample program (own machine) and 21 corpus programs (XYZ.ini)"
    )
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    planners = ("vpop", "constant", "variable") if args.planner == "all" else (args.planner,)
    jobs = [(p, args.machine) for p in args.parts]
    if not jobs or args.done_when:
        jobs = [(os.path.join(ROOT, "samples", "gcode", n), m) for n, m in SAMPLES]
    if args.done_when:
        jobs += [(os.path.join(CORPUS, n), XYZ_INI) for n in CORPUS_20]
    lines = [
        "| program | planner | samples | on segments | bytes/sample | re-sent | max dev µm | device verify ratio | s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    print("\n".join(lines))
    runs = fails = errors = 0
    worst_ratio = worst_dev = 0.0
    for part, machine in jobs:
        for planner in planners:
            name = os.path.basename(part)
            try:
                r = run_one(part, machine, planner)
            except CncInterpError as exc:
                errors += 1
                lines.append(f"| {name} | {planner} | error: {exc.format()[:100]} |||||||")
                print(lines[-1], flush=True)
                continue
            runs += 1
            fails += not r["ok"]
            worst_ratio = max(worst_ratio, r["ratio"])
            worst_dev = max(worst_dev, r["dev_um"])
            lines.append(
                f"| {name} | {planner} | {r['samples']} | {100 * r['share']:.1f} % | "
                f"{r['bytes_per_sample']:.2f} | {r['repaired']} | {r['dev_um']:.4f} | "
                f"{r['ratio']:.12f} | {r['t']:.1f} |"
            )
            print(lines[-1], flush=True)
    summary = (
        f"fpga round trip: {runs} runs, {fails} verify failures, {errors} errors, worst ratio "
        f"{worst_ratio:.12f}, worst deviation {worst_dev:.4f} µm"
    )
    print(summary)
    if not args.no_write:
        write_section(
            "FPGA round trip",
            "fpga_roundtrip.py",
            command_line("fpga_roundtrip.py", argv),
            "\n".join(lines),
            "Plan as `stream` does, fixed point, frames, device model, then `verify` of the device's "
            "setpoints against the real machine (ratio must be <= 1 + 1e-9); max dev is the device's "
            "worst deviation from the float plan. " + summary[0].upper() + summary[1:] + ".",
        )
    return 1 if fails else 0


if __name__ == "__main__":
    sys.exit(main())

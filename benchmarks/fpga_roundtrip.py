"""FPGA round trip over corpus programs: plan -> fixed point -> frames -> golden model.

Prints, per program: samples, planar segments, share of samples streamed as
segments, frame bytes, worst deviation from the float plan (µm), worst
segment-end drift before resynchronisation (µm), and the deviation the paper's
p'-Euler integrator would have on the same samples (µm), plus wall times.

    .venv/bin/python benchmarks/fpga_roundtrip.py [-m MACHINE] [--planner P] PART...
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from cnc_interp.errors import CncInterpError  # noqa: E402
from cnc_interp.fpga.commands import StreamOptions, plan_for_stream  # noqa: E402
from cnc_interp.fpga.device import DeviceCore  # noqa: E402
from cnc_interp.fpga.frames import decode_frame, program_frames  # noqa: E402
from cnc_interp.fpga.model import to_mm  # noqa: E402
from cnc_interp.fpga.program import assign_paths, build_program  # noqa: E402


def euler_deviation_mm(traj, paths) -> float:
    """Worst |z*| error of paper 000's p'-integrator (Δz* = p'(x*)·Δx*) on the planned abscissae."""
    worst = 0.0
    for path, a, b, s0 in assign_paths(traj, paths):
        pl = path.planar
        if pl is None or path.rapid or b <= a:
            continue
        h, v = pl.plane
        seg = path.segment_of_s(traj.s[a:b] - s0)
        q = traj.q[a:b]
        for k in np.unique(seg):
            m = seg == k
            c, s = np.cos(pl.theta[k]), np.sin(pl.theta[k])
            d = q[m][:, [h, v]] - pl.origin[k]
            x = np.concatenate(([0.0], d[:, 0] * c + d[:, 1] * s))
            p = pl.p[k]
            dp = np.polynomial.polynomial.polyder(p)
            z_euler = np.cumsum(np.polynomial.polynomial.polyval(x[:-1], dp) * np.diff(x))
            z_true = np.polynomial.polynomial.polyval(x[1:], p)
            worst = max(worst, float(np.max(np.abs(z_euler - z_true))))
    return worst


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("parts", nargs="+")
    ap.add_argument("-m", "--machine", default=None)
    ap.add_argument("--planner", default="variable")
    args = ap.parse_args()
    print("| program | samples | segments | on segments | frame bytes | max dev µm | end drift µm | "
          "p'-Euler dev µm | plan s | fpga s |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for part in args.parts:
        name = os.path.basename(part)
        opts = StreamOptions(part=part, machine_spec=args.machine, planner=args.planner)
        t0 = time.perf_counter()
        try:
            fit, traj = plan_for_stream(opts)
        except CncInterpError as exc:
            print(f"| {name} | error: {exc.format()[:80]} |")
            continue
        t1 = time.perf_counter()
        prog = build_program(traj, fit.paths, source=part)
        frames, _ = program_frames(prog)
        core = DeviceCore(buffer_bytes=1 << 62)
        for f in frames:
            assert core.handle(decode_frame(f))
        q = to_mm(core.datapath.output().q, prog.formats)
        t2 = time.perf_counter()
        dev = float(np.max(np.abs(q - traj.q)))
        st = prog.stats
        share = st["planar_samples"] / max(1, prog.n_samples)
        eul = euler_deviation_mm(traj, fit.paths)
        print(f"| {name} | {prog.n_samples} | {st['segments']} | {100 * share:.1f}% | "
              f"{sum(map(len, frames))} | {dev * 1e3:.5f} | {st['max_segment_end_drift_mm'] * 1e3:.2e} | "
              f"{eul * 1e3:.3g} | {t1 - t0:.2f} | {t2 - t1:.2f} |")
        for why in st["fallback_paths"][:3]:
            print(f"|   setpoints: {why} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

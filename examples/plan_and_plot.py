"""Plan one part program from Python, write its setpoints and plot them.

    python examples/plan_and_plot.py samples/gcode/mill-contour.ngc generic-mill out/

writes ``out/<part>.csv`` (the setpoints, as ``cnc-interp plan`` writes them) and
``out/<part>.png`` (path, feed and limit ratios; needs matplotlib, ``pip install
cnc-interp[plot]``), and prints the cycle time and the worst limit ratio.
"""

import os
import sys

import cnc_interp as ci


def main(part: str, machine_spec: str, out_dir: str) -> int:
    machine = ci.load_machine(machine_spec)
    try:
        result = ci.run(part, machine)  # read_program -> fit -> plan -> verify
    except ci.CncInterpError as exc:
        print(exc.format(), file=sys.stderr)  # FILE:LINE:COL: error: ...
        return exc.exit_code
    traj = result.trajectory
    stem = os.path.splitext(os.path.basename(part))[0]
    os.makedirs(out_dir, exist_ok=True)
    ci.write(traj, os.path.join(out_dir, stem + ".csv"))

    from cnc_interp.export.plot import plot_trajectory

    plot_trajectory(traj, result.machine, os.path.join(out_dir, stem + ".png"), title=part)
    axis, kind, ratio, _ = result.report.worst()
    print(
        f"{part}: {traj.n_samples} samples every {traj.dt_s * 1e3:g} ms, "
        f"cycle {traj.duration_s:.3f} s, worst {axis} {kind} at {ratio:.4f} of its limit"
    )
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    sys.exit(main(*sys.argv[1:]))

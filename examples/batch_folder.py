"""Plan every part program in a folder and print one line per program.

    python examples/batch_folder.py samples/gcode generic-mill

Each program is read, fitted, planned and verified (``cnc_interp.run``); a program the
machine cannot run (bad G-code, an axis it lacks) gets its one error line instead. The
exit status is 0 when every program planned within the limits, else 1.
(``cnc-interp batch`` does the same in parallel, with reports and baselines.)
"""

import os
import sys

import cnc_interp as ci

PART_SUFFIXES = (".ngc", ".nc", ".gcode", ".tap")


def main(folder: str, machine_spec: str) -> int:
    machine = ci.load_machine(machine_spec)
    failed = 0
    total_s = 0.0
    for name in sorted(os.listdir(folder)):
        if not name.lower().endswith(PART_SUFFIXES):
            continue
        path = os.path.join(folder, name)
        try:
            result = ci.run(path, machine)
        except ci.CncInterpError as exc:
            print(f"{name:32s} {exc.format()}")
            failed += 1
            continue
        traj = result.trajectory
        total_s += traj.duration_s
        print(f"{name:32s} cycle {traj.duration_s:9.3f} s  worst ratio {result.report.worst_ratio:.6f}")
    print(f"total cycle {total_s:.3f} s, {failed} program(s) not planned")
    return 1 if failed else 0


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    sys.exit(main(*sys.argv[1:]))

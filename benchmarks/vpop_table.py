"""Build time of VPOp's arc-length joint table (``JointTable``) and its bounds.

    .venv/bin/python benchmarks/vpop_table.py                      # the two default programs
    .venv/bin/python benchmarks/vpop_table.py performance/cap.ngc --machine generic-mill

Each program is parsed and fitted once; then every path's table is built (numba
compiled beforehand) and timed in CPU seconds (``time.process_time``, best of
``--repeat``), with ``curvature_bounds`` + ``speed_bounds`` timed separately. Writes the table
to ``benchmarks/RESULTS.md`` (its "VPOp joint table" section) unless ``--no-write``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from _results import command_line, md_table, write_section

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

CORPUS = os.environ.get(
    "CNC_CORPUS", os.path.join(os.path.dirname(__file__), "..", "..", "shared", "corpus", "linuxcnc")
)
DEFAULT = ["performance/circle_small_segments_ncd.ngc", "performance/3D_Chips.ngc"]


def fitted_paths(rel: str, machine_spec: str):
    from cnc_interp.fit.settings import FitSettings
    from cnc_interp.gcode import read_program
    from cnc_interp.pipeline import fit_loaded
    from cnc_interp.machine.kinematics import make_kinematics
    from cnc_interp.machine.load import load_machine

    m = load_machine(machine_spec)
    with open(os.path.join(CORPUS, rel), "rb") as f:
        data = f.read()
    prog = read_program(data, source=rel, axes=m.axes, start=m.start)
    fitted = fit_loaded(prog, FitSettings.from_options(tol_mm=None, machine=m))
    kin = make_kinematics(m)
    joint_map = None if kin.is_identity else kin
    return m, [(p, None if p.rapid else joint_map) for p in fitted.items if hasattr(p, "coef")]


def main(argv=None) -> None:
    import numpy as np

    from cnc_interp.plan.vpop import JointTable

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("programs", nargs="*", default=DEFAULT, help="paths relative to the corpus")
    ap.add_argument("--machine", default="generic-mill")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-write", action="store_true", help="print only; leave RESULTS.md alone")
    args = ap.parse_args(argv)
    table = []
    print(f"{'program':44s} {'paths':>5s} {'pieces':>7s} {'max_err':>8s} {'table s':>8s} {'bounds s':>8s}")
    for rel in args.programs:
        m, items = fitted_paths(rel, args.machine)
        JointTable(*items[0])  # load the compiled kernels
        dt = m.dt_s
        al, jl, vl = m.amax * dt * dt, m.jmax * dt**3, m.vmax * dt
        best_t = best_b = np.inf
        for _ in range(max(1, args.repeat)):
            t0 = time.process_time()
            tabs = [JointTable(p, jm) for p, jm in items]
            t1 = time.process_time()
            for (p, _), t in zip(items, tabs):
                t.curvature_bounds(al, jl)
                t.speed_bounds(vl, p, np.full(p.n_seg, 1.0))
            t2 = time.process_time()
            best_t, best_b = min(best_t, t1 - t0), min(best_b, t2 - t1)
        pieces = sum(t.C.shape[0] for t in tabs)
        err = max(t.max_err for t in tabs)
        print(f"{rel:44s} {len(items):5d} {pieces:7d} {err:8.2g} {best_t:8.3f} {best_b:8.3f}")
        table.append([rel, len(items), pieces, f"{err:.2g}", f"{best_t * 1e3:.2f}", f"{best_b * 1e3:.2f}"])
    if not args.no_write:
        write_section(
            "VPOp joint table",
            "vpop_table.py",
            command_line("vpop_table.py", argv),
            md_table(["program", "paths", "pieces", "max err", "table CPU ms", "bounds CPU ms"], table),
            f"Machine {args.machine}; best of {args.repeat}.",
        )


if __name__ == "__main__":
    main()

"""A LinuxCNC machine's ``[TRAJ] MAX_LINEAR_VELOCITY`` caps the tool's path speed over the
linear axes: a long rapid and a fast feed move both run at the cap (the planned samples'
path speed never above it, and within 1 % of it), and the plan still holds every axis
limit."""

from __future__ import annotations

import numpy as np
import pytest

import cnc_interp as ci

#: a mm XYZ machine: 100 mm/s, 1000 mm/s² on every axis (jerk: the INI default, 10/s x amax)
INI = """\
[EMC]
MACHINE = capped
[TRAJ]
COORDINATES = X Y Z
LINEAR_UNITS = mm
{extra}
[AXIS_X]
MAX_VELOCITY = 100
MAX_ACCELERATION = 1000
[AXIS_Y]
MAX_VELOCITY = 100
MAX_ACCELERATION = 1000
[AXIS_Z]
MAX_VELOCITY = 100
MAX_ACCELERATION = 1000
"""

#: (cap mm/s, program): a cap below every axis's vmax on moves along X, and one above
#: each axis's vmax (100) but below the diagonal's (141 mm/s) on XY diagonals; each
#: program's rapid (line 1) and its feed (line 2, programmed at 1000 mm/s) are long enough
#: to reach the cap
CASES = {
    "along-x": (60.0, "G0 X300\nG1 X0 F60000\n"),
    "diagonal": (120.0, "G0 X300 Y300\nG1 X0 Y0 F60000\n"),
}


def path_speed(traj) -> np.ndarray:
    """(K,) speed over X, Y, Z of the samples, mm/s (backward differences; 0 at k = 0)."""
    d = np.diff(traj.q[:, :3], axis=0)
    return np.concatenate([[0.0], np.sqrt((d * d).sum(axis=1)) / traj.dt_s])


@pytest.mark.parametrize("planner", ["optimal", "vpop"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_rapid_and_feed_run_at_the_path_speed_limit(tmp_path, case, planner):
    cap, program = CASES[case]
    ini = tmp_path / "capped.ini"
    ini.write_text(INI.format(extra=f"MAX_LINEAR_VELOCITY = {cap:g}"))
    m = ci.load_machine(str(ini))
    assert m.max_path_mm_s == cap
    res = ci.run(program.encode(), m, planner=planner)
    traj = res.trajectory
    assert ci.verify(traj, m).ok
    v = path_speed(traj)
    assert v.max() <= cap * (1 + 1e-9), (case, v.max())
    for line in (1, 2):  # the rapid, then the feed move
        top = float(v[traj.line == line].max())
        assert top >= 0.99 * cap, (case, line, top)
    # without the key the same program runs faster: the axes' own limits, the feed
    free = tmp_path / "free.ini"
    free.write_text(INI.format(extra=""))
    fast = path_speed(ci.run(program.encode(), ci.load_machine(str(free)), planner=planner).trajectory)
    assert fast.max() > 1.3 * cap if case == "along-x" else fast.max() > 1.1 * cap


def test_the_streamed_plan_caps_the_same(tmp_path):
    # `cnc-interp plan` reads the program as a stream (pipeline.stream_plan): the same cap
    from ._contract_helpers import run_inproc

    cap, program = CASES["diagonal"]
    ini = tmp_path / "capped.ini"
    ini.write_text(INI.format(extra=f"MAX_LINEAR_VELOCITY = {cap:g}"))
    part = tmp_path / "part.ngc"
    part.write_text(program)
    out = tmp_path / "plan.csv"
    r = run_inproc("plan", part, "-m", ini, "-o", out, "-q")
    assert r.code == 0, r.explain()
    q = np.loadtxt(out, delimiter=",", skiprows=1, usecols=(3, 4, 5))
    v = np.sqrt((np.diff(q, axis=0) ** 2).sum(axis=1)) / ci.load_machine(str(ini)).dt_s
    assert cap * 0.99 <= v.max() <= cap * (1 + 1e-9)

"""The whole-program timeline: rapids, cuts, dwells and stops on one sample clock."""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from cnc_interp.errors import PlanError
from cnc_interp.fit.result import FitResult
from cnc_interp.gcode.program import Dwell, Program, Stop
from cnc_interp.machine.model import Machine
from cnc_interp.plan.settings import PlanSettings
from cnc_interp.plan.timeline import plan_program
from cnc_interp.plan.verify import verify

from ._vpop_paths import circle_fun, hermite_path, line_path

DT = 0.001
MILL = Machine(
    name="mill", axes="XYZ", vmax=[200, 200, 100], amax=[2000, 2000, 1000], jmax=[20000, 20000, 10000], dt_s=DT
)


def program(start, items):
    return Program(source="<test>", axes="XYZ", items=(), start=np.asarray(start, float), line_count=20)


def build():
    """rapid -> cut (line) -> dwell 0.25 s -> M0 -> cut (circle) -> rapid -> M2."""
    start = np.array([0.0, 0.0, 10.0])
    circle = hermite_path(circle_fun(10.0), 8, 80.0, line0=10)
    c0 = circle.start
    items = [
        line_path(start, [30.0, 0.0, 0.0], np.inf, line=2, rapid=True),
        line_path([30.0, 0.0, 0.0], c0, 50.0, line=3),
        Dwell(line=4, seconds=0.25, position=c0.copy()),
        Stop(line=5, code="M0", position=c0.copy()),
        circle,
        line_path(circle.end, [0.0, 0.0, 10.0], np.inf, line=19, rapid=True),
        Stop(line=20, code="M2", position=np.array([0.0, 0.0, 10.0])),
    ]
    return FitResult(program=program(start, items), items=tuple(items)), items


def test_program_with_rapids_dwell_and_stop():
    fit, items = build()
    settings = PlanSettings(planner="vpop", dt_s=DT)
    done = []
    traj = plan_program(fit, MILL, settings, progress=done.append)
    rep = verify(traj, MILL.with_start(fit.program.start))  # the machine is where the program starts
    assert rep.ok, rep.format()
    k = traj.n_samples
    assert_allclose(traj.t, np.arange(k) * DT, rtol=0, atol=0)
    assert_array_equal(traj.q[0], [0.0, 0.0, 10.0])
    assert_array_equal(traj.q[-1], [0.0, 0.0, 10.0])
    # s is cumulative over every path, rapids included; feed is its backward difference
    total = sum(it.length for it in items if hasattr(it, "length"))
    assert traj.s[-1] == pytest.approx(total, rel=1e-12)
    assert np.all(np.diff(traj.s) >= 0)
    assert_allclose(traj.feed[1:], np.diff(traj.s) / DT)
    assert traj.feed[0] == 0.0
    assert sum(done) == pytest.approx(total)
    # the dwell: at least ceil(0.25 / dt) samples held at the circle's start, on line 4
    held = traj.line == 4
    assert held.sum() >= math.ceil(0.25 / DT)
    assert np.all(traj.q[held] == items[1].end)
    # every line of the program shows up, in order
    seen = [int(x) for x in np.unique(traj.line)]
    for ln in (2, 3, 4, 10, 17, 19):
        assert ln in seen
    first = {ln: int(np.argmax(traj.line == ln)) for ln in (2, 3, 4, 10, 19)}
    assert first[2] < first[3] < first[4] < first[10] < first[19]
    # the cutting feed is respected on the cut, the rapid may go faster
    on_cut = traj.line == 3
    assert traj.feed[on_cut].max() <= 50.0 * (1 + 1e-9)
    assert traj.feed.max() > 100.0
    assert traj.planner == "vpop" and traj.settings["dt_s"] == DT


def _rest_runs(traj):
    """(start sample, length) of each run of periods in which no axis moves."""
    moving = np.any(np.diff(traj.q, axis=0) != 0, axis=1)
    runs, count = [], 0
    for k, flag in enumerate(~moving):
        if flag:
            count += 1
        elif count:
            runs.append((k - count, count))
            count = 0
    return runs


def test_motions_are_separated_by_rest():
    fit, _ = build()
    traj = plan_program(fit, MILL, PlanSettings(dt_s=DT))
    assert verify(traj, MILL.with_start(fit.program.start)).ok
    # wherever motion stops and restarts, at least one period at rest sits in between
    runs = _rest_runs(traj)
    assert runs and min(n for _, n in runs) >= 1


def _joint_program(a, b, c):
    """Two cuts a -> b -> c with the machine at rest at b (two paths)."""
    first = line_path(a, b, 50.0, line=2)
    second = line_path(b, c, 50.0, line=3)
    items = (first, second)
    return FitResult(program=program(a, items), items=items)


@pytest.mark.parametrize("planner", ["vpop", "optimal"])
def test_a_reversal_rests_one_period_between_paths(planner):
    # back the way it came: the joint's jerk stencil adds two steps of opposite sign
    fit = _joint_program([0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    traj = plan_program(fit, MILL, PlanSettings(planner=planner, dt_s=DT))
    rep = verify(traj, MILL.with_start(fit.program.start))
    assert rep.ok, rep.format()
    middle = [n for k, n in _rest_runs(traj) if 0 < k < traj.n_samples - 4]
    assert middle == [1]


@pytest.mark.parametrize("planner", ["vpop", "optimal"])
def test_going_on_the_same_way_keeps_two_periods_of_rest_where_jerk_needs_them(planner):
    # a 10 degree kink: the last step in and the first step out add up on X, past the
    # jerk limit of one period, so the joint keeps the longer rest and the limits hold
    fit = _joint_program([0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [10.0, 5.0 * math.tan(math.radians(10)), 0.0])
    traj = plan_program(fit, MILL, PlanSettings(planner=planner, dt_s=DT))
    rep = verify(traj, MILL.with_start(fit.program.start))
    assert rep.ok, rep.format()
    (k, n) = [(k, n) for k, n in _rest_runs(traj) if 0 < k < traj.n_samples - 4][0]
    step_in = traj.q[k] - traj.q[k - 1]
    step_out = traj.q[k + n + 1] - traj.q[k + n]
    jerk_if_short = np.abs(step_in + step_out) / DT**3
    assert np.any(jerk_if_short > MILL.jmax)  # one period at rest would break the limit
    assert n == 2


def test_empty_program_is_one_sample_at_the_start():
    fit = FitResult(program=program([1.0, 2.0, 3.0], []), items=())
    traj = plan_program(fit, MILL, PlanSettings(dt_s=DT))
    assert traj.n_samples == 1
    assert_array_equal(traj.q[0], [1.0, 2.0, 3.0])


def test_path_not_starting_where_the_machine_is_is_a_bug():
    p = line_path([5.0, 0, 0], [10.0, 0, 0], 50.0)
    fit = FitResult(program=program([0.0, 0.0, 0.0], [p]), items=(p,))
    with pytest.raises(PlanError, match="starts at"):
        plan_program(fit, MILL, PlanSettings(dt_s=DT))


@pytest.mark.parametrize("planner", ["constant", "variable"])
def test_paper000_planners_share_the_timeline(planner):
    fit, _ = build()
    traj = plan_program(fit, MILL, PlanSettings(planner=planner, dt_s=DT))
    rep = verify(traj, MILL.with_start(fit.program.start))  # the machine is where the program starts
    assert rep.ok, rep.format()
    assert traj.planner == planner
    assert_array_equal(traj.q[-1], [0.0, 0.0, 10.0])


@pytest.mark.parametrize("planner", ["vpop", "constant", "variable"])
def test_low_jerk_limit_holds_across_path_joins(planner):
    """A jerk limit of 2000 mm/s^3 at dt = 1 ms is 2e-6 mm of third difference: a
    one-ulp mismatch where an arc's end meets the next line (~1e-14 mm) used to
    show as a ratio of 1.0000000028. Every planner must keep rounding margin."""
    from cnc_interp.fit import FitSettings, fit_program
    from cnc_interp.gcode import read_program

    text = "G21 G90 G17\nG0 X20 Y10\nG1 X20 Y10 F2400\nG2 X30 Y0 I5 J-5\nG4 P0.05\nG1 X40 Y5\nM2\n"
    machine = Machine(name="low jerk", axes="XYZ", vmax=[100.0] * 3, amax=[2000.0] * 3, jmax=[2000.0] * 3, dt_s=0.001)
    fitted = fit_program(read_program(text, "arc.ngc", axes="XYZ"), FitSettings.from_options())
    traj = plan_program(fitted, machine, PlanSettings.from_options(planner=planner, dt_s=0.001))
    report = verify(traj, machine)
    assert report.ok, report.format()
    assert_allclose(traj.q[-1], [40.0, 5.0, 0.0], rtol=0, atol=1e-12)


def test_a_job_queue_holds_at_most_samples_ahead_samples():
    """A worker waits for room by samples, not by chunks: a job of many short paths
    must be able to run ahead of the consumer (a bound of 16 chunks made the second
    worker wait on stellabee1's short paths), and a long path must not."""
    from cnc_interp.plan.base import PathPlan
    from cnc_interp.plan.timeline import _DONE, _Job

    def chunk(k):
        return PathPlan(s=np.arange(float(k)), q=np.zeros((k, 3)))

    job = _Job([None] * 50, samples_ahead=100)
    for i in range(50):  # fifty one-sample chunks: far more than sixteen
        assert job.put((i, chunk(1)), timeout=0.01)
    assert job.put((50, chunk(50)), timeout=0.01)  # 100 samples held: full
    assert not job.put((51, chunk(1)), timeout=0.01)
    assert job.get()[0] == 0
    assert job.put((51, chunk(1)), timeout=0.01)  # one sample of room again
    empty = _Job([None], samples_ahead=10)
    assert empty.put((0, chunk(1000)), timeout=0.01)  # a first chunk goes in whatever its size
    assert empty.put(_DONE, timeout=0.01)  # the end marker takes no room
    assert empty.get()[1].s.shape[0] == 1000 and empty.get() is _DONE and empty.held == 0

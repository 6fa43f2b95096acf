"""VPOp on single paths: limits hold exactly, ends are exact, lines match the optimum."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from cnc_interp.constants import VERIFY_RATIO_SLACK, VPOP_TABLE_TOL
from cnc_interp.fit.path import Path
from cnc_interp.plan.kinematics import make_kinematics
from cnc_interp.plan.machine import Machine
from cnc_interp.plan.settings import PlanSettings
from cnc_interp.plan.verify import verify_arrays
from cnc_interp.plan.vpop import JointTable, plan_path_vpop

from ._vpop_paths import circle_fun, hermite_path, line_path, random_curve

DT = 0.001
MILL = Machine(name="mill", axes="XYZ", vmax=[200, 200, 100], amax=[2000, 2000, 1000],
               jmax=[20000, 20000, 10000], dt_s=DT)


def check(plan, machine, q_start, q_end, dt=DT):
    """Every limit holds with rest padding, and the plan starts and ends exactly."""
    rep = verify_arrays(plan.q, dt, machine.vmax, machine.amax, machine.jmax)
    assert rep.ok, rep.format()
    assert not np.isnan(plan.q).any()
    assert_array_equal(plan.q[0], q_start)
    assert_array_equal(plan.q[-1], q_end)
    assert np.all(np.diff(plan.s) >= 0)
    return rep


def ruckig_time(length, v, a, j):
    from ruckig import InputParameter, Result, Ruckig, Trajectory

    inp = InputParameter(1)
    inp.current_position = [0.0]
    inp.target_position = [length]
    inp.max_velocity = [v]
    inp.max_acceleration = [a]
    inp.max_jerk = [j]
    traj = Trajectory(1)
    assert Ruckig(1).calculate(inp, traj) == Result.Working
    return traj.duration


@pytest.mark.parametrize("target,feed", [((100.0, 50.0, 0.0), 150.0), ((3.0, 0.0, 0.0), 150.0),
                                         ((0.0, 40.0, 30.0), 1000.0)])
def test_straight_line_matches_ruckig(target, feed):
    p = line_path([0, 0, 0], target, feed)
    plan = plan_path_vpop(p, None, MILL, DT)
    check(plan, MILL, p.start, p.end)
    d = np.asarray(target) / p.length
    g = np.abs(d)[np.abs(d) > 0]
    lim = [np.min(x[np.abs(d) > 0] / g) for x in (MILL.vmax, MILL.amax, MILL.jmax)]
    t_opt = ruckig_time(p.length, min(lim[0], feed), lim[1], lim[2])
    t_plan = (plan.s.shape[0] - 1) * DT
    # discrete time cannot beat the continuous optimum by more than a sample or two,
    # and VPOp should stay within a few samples of it
    assert t_opt - 2 * DT <= t_plan <= t_opt + 6 * DT, (t_plan, t_opt)


def test_feed_limit_per_segment():
    # two collinear segments: 100 mm/s then 30 mm/s
    coef = np.zeros((2, 6, 3))
    coef[0, 0] = [0, 0, 0]
    coef[0, 1] = [50, 0, 0]
    coef[1, 0] = [50, 0, 0]
    coef[1, 1] = [50, 0, 0]
    p = Path(axes="XYZ", breaks=np.array([0.0, 1.0, 2.0]), coef=coef, line=[1, 2],
             feed_mm_s=[100.0, 30.0])
    plan = plan_path_vpop(p, None, MILL, DT)
    check(plan, MILL, p.start, p.end)
    v = np.diff(plan.s) / DT
    assert v.max() <= 100.0 * (1 + VERIFY_RATIO_SLACK)
    # every step that ends beyond the break (s = 50) is within the second segment's feed
    after = plan.s[1:] > 50.0 + 1e-9
    assert v[after].max() <= 30.0 * (1 + VERIFY_RATIO_SLACK)
    assert v.max() > 99.0  # and the first segment does reach its feed


@pytest.mark.parametrize("seed", range(5))
def test_random_curves_hold_limits_and_end_exactly(seed):
    rng = np.random.default_rng(seed)
    p = hermite_path(random_curve(rng, scale=15.0), int(rng.integers(4, 12)), float(rng.uniform(30, 250)))
    plan = plan_path_vpop(p, None, MILL, DT)
    check(plan, MILL, p.start, p.end)
    assert plan.s[0] == 0.0 and plan.s[-1] == p.length


def test_circle_speed_is_curvature_limited():
    # r = 5 mm circle: centripetal acceleration v²/r <= 2000 -> v <= 100 mm/s
    p = hermite_path(circle_fun(5.0), 16, 500.0)
    plan = plan_path_vpop(p, None, MILL, DT)
    check(plan, MILL, p.start, p.end)
    v = np.diff(plan.s) / DT
    assert v.max() <= 100.0 * 1.01
    assert v.max() > 40.0


def test_exact_mode_gives_the_same_kind_of_plan():
    rng = np.random.default_rng(3)
    p = hermite_path(random_curve(rng, scale=10.0), 6, 120.0)
    fast = plan_path_vpop(p, None, MILL, DT)
    exact = plan_path_vpop(p, None, MILL, DT, PlanSettings(options={"vpop_exact": True}))
    check(exact, MILL, p.start, p.end)
    assert exact.stats["exact"]
    # the shortcuts only end brake runs early (exact mode asks every brake run to reach
    # rest, which is more conservative): the fast plan is never slower
    assert fast.s.shape[0] <= exact.s.shape[0] + 2


def test_rotary_only_move():
    m = Machine(name="rot", axes="XYZA", vmax=[100, 100, 100, 90], amax=[1000, 1000, 1000, 300],
                jmax=[1e4, 1e4, 1e4, 1800], dt_s=DT)
    p = line_path([5, 5, 5, 0], [5, 5, 5, 120], 60.0, axes="XYZA")
    assert p.length == pytest.approx(120.0)  # s is the angle when no linear axis moves
    plan = plan_path_vpop(p, None, m, DT)
    check(plan, m, p.start, p.end)
    assert_array_equal(plan.q[:, :3], np.broadcast_to([5.0, 5.0, 5.0], (plan.q.shape[0], 3)))
    assert (np.diff(plan.s) / DT).max() <= 60.0 * (1 + VERIFY_RATIO_SLACK)


def test_five_axis_xyzac_trt():
    m = Machine(name="5ax", axes="XYZAC", vmax=[500, 500, 500, 90, 120],
                amax=[2500, 3000, 2100, 298.8, 298.8], jmax=[5000, 5000, 50000, 1800, 36000],
                dt_s=DT, kinematics="xyzac-trt",
                kinematics_params={"z_rot_point": -50.0, "y_offset": 2.0})
    kin = make_kinematics(m)

    def fun(u):
        u = np.asarray(u, dtype=float)
        z = np.zeros_like(u)
        o = np.ones_like(u)
        p = np.stack([20 * np.cos(u), 20 * np.sin(u), 5 * u, 10 * u, 40 * u], axis=1)
        p1 = np.stack([-20 * np.sin(u), 20 * np.cos(u), 5 * o, 10 * o, 40 * o], axis=1)
        p2 = np.stack([-20 * np.cos(u), -20 * np.sin(u), z, z, z], axis=1)
        return p, p1, p2

    p = hermite_path(fun, 8, 200.0, axes="XYZAC", u1=1.5)
    plan = plan_path_vpop(p, kin, m, DT)
    q0 = kin.to_joints(p.start[None])[0]
    q1 = kin.to_joints(p.end[None])[0]
    check(plan, m, q0, q1)
    # the setpoints are the joint images of points of the programmed path
    back = kin.to_program(plan.q)
    u = p.u_of_s(plan.s)
    assert_allclose(back, p.derivatives_u(u, 0)[0], atol=1e-6)


def test_table_matches_path_within_its_tolerance():
    rng = np.random.default_rng(11)
    p = hermite_path(random_curve(rng, scale=30.0), 7, 100.0)
    t = JointTable(p, None)
    s = np.sort(rng.uniform(0, p.length, 2000))
    from cnc_interp.plan.vpop import _eval_table

    assert t.max_err <= VPOP_TABLE_TOL
    assert np.abs(_eval_table(t.S, t.C, s) - p(s)).max() <= 10 * VPOP_TABLE_TOL


def test_zero_length_path_is_one_sample():
    p = line_path([1, 2, 3], [1, 2, 3], 100.0)
    plan = plan_path_vpop(p, None, MILL, DT)
    assert plan.q.shape == (1, 3)
    assert_array_equal(plan.q[0], [1, 2, 3])


def test_other_periods():
    p = hermite_path(circle_fun(20.0, turns=0.5), 6, 300.0)
    for dt in (0.004, 0.0005):
        plan = plan_path_vpop(p, None, MILL, dt)
        check(plan, MILL, p.start, p.end, dt=dt)

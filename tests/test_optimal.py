"""The near-time-optimal planner: limits hold exactly, ends are exact, it is faster than
VPOp where VPOp is weak, its chunks are the one-shot plan, and nothing makes it fail."""

import dataclasses
import os

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from cnc_interp.machine.kinematics import make_kinematics
from cnc_interp.machine.model import Machine
from cnc_interp.errors import UsageError
from cnc_interp.plan.optimal import batched_optimal, iter_path_plan_optimal, plan_path_optimal
from cnc_interp.plan.optimality import line_min_samples
from cnc_interp.plan.safe import plan_path_safe
from cnc_interp.plan.settings import OptimalOptions, PlanSettings
from cnc_interp.plan.tuning import OptimalTuning
from cnc_interp.plan.verify import verify_arrays
from cnc_interp.plan.vpop import plan_path_vpop

from ._vpop_paths import circle_fun, hermite_path, line_path, random_curve
from .conftest import CORPUS, needs_corpus

DT = 0.001
MILL = Machine(
    name="mill", axes="XYZ", vmax=[200, 200, 200], amax=[2000, 2000, 2000], jmax=[50000, 50000, 50000], dt_s=DT
)
#: paper 001's Mikron UCP 710 (linear axes) at its 6 ms period: jerk binds
UCP = Machine(
    name="ucp710", axes="XYZ", vmax=[500, 500, 500], amax=[2500, 3000, 2100], jmax=[5000, 5000, 50000], dt_s=0.006
)


def check(plan, machine, q_start, q_end, dt):
    """Every limit holds with rest padding, nothing is NaN, the ends are exact."""
    rep = verify_arrays(plan.q, dt, machine.vmax, machine.amax, machine.jmax)
    assert rep.ok, rep.format()
    assert np.all(np.isfinite(plan.q)) and np.all(np.isfinite(plan.s))
    assert_array_equal(plan.q[0], q_start)
    assert_array_equal(plan.q[-1], q_end)
    assert np.all(np.diff(plan.s) >= 0)
    return rep


def periods(plan):
    return plan.s.shape[0] - 1


#: the optimal planner's default tunables
TUNING = OptimalTuning()


def tuned(settings: PlanSettings | None = None, **changes) -> PlanSettings:
    """``settings`` (default: the defaults) with the optimal planner's tunables ``changes``."""
    settings = settings or PlanSettings(planner="optimal")
    opt = settings.optimal
    return dataclasses.replace(
        settings, optimal=dataclasses.replace(opt, tuning=dataclasses.replace(opt.tuning, **changes))
    )


# -- closed form: a straight line against its exact discrete minimum ------------------
@pytest.mark.parametrize(
    "length,feed,machine", [(100.0, 83.3, MILL), (3.0, 150.0, MILL), (100.0, 83.3, UCP), (12.0, 400.0, UCP)]
)
def test_line_within_a_few_periods_of_the_discrete_minimum(length, feed, machine):
    # at 6 ms the windows of ``refine`` find the minimum within a period or two; at 1 ms
    # lines keep VPOp's plan: its stop is up to three periods slower (windows on every
    # short path would cost more planning time than they save)
    dt = machine.dt_s
    p = line_path([0, 0, 0], [length, 0, 0], feed)
    plan = plan_path_optimal(p, None, machine, dt)
    check(plan, machine, p.start, p.end, dt)
    best = line_min_samples(length, min(feed, machine.vmax[0]), machine.amax[0], machine.jmax[0], dt)
    slack = 2 if dt >= 0.002 else 3 + int(0.004 * best)
    assert best <= periods(plan) <= best + slack, (periods(plan), best)


# -- curves: exact limits, and the cycle time ------------------------------------------
def _trident_like(u):
    """A curve whose curvature changes sign (x 30 mm, y 6 sin(3πu)): value, first and
    second derivative at u."""
    u = np.asarray(u, dtype=float)
    w = 3.0 * np.pi
    p = np.stack([30 * u, 6 * np.sin(w * u), 0 * u], axis=1)
    p1 = np.stack([30 + 0 * u, 6 * w * np.cos(w * u), 0 * u], axis=1)
    p2 = np.stack([0 * u, -6 * w * w * np.sin(w * u), 0 * u], axis=1)
    return p, p1, p2


def test_trident_like_curve_at_6ms_beats_vpop_by_far():
    # paper 001's machine at 6 ms on a curve whose curvature changes sign: jerk binds and
    # VPOp's greedy steps lose (~20 % on the trident)
    p = hermite_path(_trident_like, 24, 60.0)
    opt = plan_path_optimal(p, None, UCP, UCP.dt_s)
    check(opt, UCP, p.start, p.end, UCP.dt_s)
    vp = plan_path_vpop(p, None, UCP, UCP.dt_s)
    assert opt.stats["route"] == "profile"
    assert periods(opt) <= 0.9 * periods(vp), (periods(opt), periods(vp))


@pytest.mark.parametrize("seed", range(4))
def test_random_curves_hold_limits_and_never_lose_to_vpop(seed):
    rng = np.random.default_rng(100 + seed)
    p = hermite_path(random_curve(rng, scale=15.0), int(rng.integers(4, 12)), float(rng.uniform(30, 250)))
    for machine in (MILL, UCP):
        dt = machine.dt_s
        opt = plan_path_optimal(p, None, machine, dt)
        check(opt, machine, p.start, p.end, dt)
        assert opt.s[0] == 0.0 and opt.s[-1] == p.length
        vp = plan_path_vpop(p, None, machine, dt)
        # a plan may follow a different profile; it may be a period slower at a place,
        # never slower over the path than 1 % plus two periods
        assert periods(opt) <= 1.01 * periods(vp) + 2, (periods(opt), periods(vp))


def test_the_batch_route_is_each_paths_own():
    """``route_many`` (one compiled call for a job's paths) routes every path as the
    per-path test does, over paths of both routes and a tiny one."""
    from cnc_interp.plan.optimal.route import Route, _route, _RouteInputs, route_many

    rng = np.random.default_rng(7)
    paths = [
        hermite_path(random_curve(rng, scale=s), int(rng.integers(2, 12)), f)
        for s, f in [(15.0, 250.0), (0.05, 30.0), (40.0, 2000.0), (2.0, 5.0), (25.0, 100.0)]
    ]
    paths += [line_path([0, 0, 0], [1e-4, 0, 0], 50.0), line_path([0, 0, 0], [80, 5, 0], 3000.0)]
    paths.append(hermite_path(circle_fun(3.0, turns=4.0, z_per_turn=0.5), 32, 400.0))
    for machine in (MILL, UCP):
        got = route_many(paths, machine, OptimalTuning())
        want = [_route(_RouteInputs(p, None, machine, OptimalTuning())) for p in paths]
        assert got == want
        assert {Route.PROFILE, Route.VPOP} <= set(got)


@pytest.mark.parametrize(
    "sample,preset",
    [
        ("mill-contour.ngc", "generic-mill"),
        ("drilling-cycles.ngc", "generic-mill"),
        ("nurbs-trident.ngc", "mikron-ucp710"),
        ("lathe-profile.ngc", "xz-lathe"),
        ("five-axis-xyzac.ngc", "mikron-ucp710"),
    ],
)
def test_the_default_planner_never_loses_to_vpop_on_the_samples(sample, preset):
    """Each bundled sample, whole, with the default planner: within every limit (plan_part
    verifies, the machine at rest after the last sample), ending on the program's last point,
    and no longer than VPOp's plan."""
    from cnc_interp.pipeline import plan_part
    from cnc_interp.plan.settings import DEFAULT_PLANNER

    part = os.path.join(os.path.dirname(__file__), "..", "samples", "gcode", sample)
    default = plan_part(part, preset, DEFAULT_PLANNER, None)
    vpop = plan_part(part, preset, "vpop", None)
    assert DEFAULT_PLANNER == "optimal"
    assert default.report.worst_ratio <= 1.0 + 1e-9
    assert np.array_equal(default.trajectory.q[-1], vpop.trajectory.q[-1])
    assert default.trajectory.duration_s <= vpop.trajectory.duration_s


def test_circle_at_the_acceleration_limit():
    # r = 10 mm, no feed limit: v²/r = 2000 mm/s² at v ~ 141 mm/s, the centripetal
    # acceleration takes the whole limit and VPOp's brake test (stop from here) keeps
    # failing: it creeps below the speed it could hold (corpus arc_maxvel_xy.ngc)
    p = hermite_path(circle_fun(10.0, turns=1.0), 16, 1000.0)
    opt = plan_path_optimal(p, None, MILL, DT)
    check(opt, MILL, p.start, p.end, DT)
    vp = plan_path_vpop(p, None, MILL, DT)
    assert periods(opt) < 0.9 * periods(vp), (periods(opt), periods(vp))


def test_five_axis_xyzac_trt():
    m = Machine(
        name="5ax",
        axes="XYZAC",
        vmax=[500, 500, 500, 90, 120],
        amax=[2500, 3000, 2100, 298.8, 298.8],
        jmax=[5000, 5000, 50000, 1800, 36000],
        dt_s=0.006,
        kinematics="xyzac-trt",
        kinematics_params={"z_rot_point": -50.0, "y_offset": 2.0},
    )
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
    for route in ("profile", "vpop"):
        plan = plan_path_optimal(p, kin, m, m.dt_s, PlanSettings(optimal=OptimalOptions(route=route)))
        check(plan, m, kin.to_joints(p.start[None])[0], kin.to_joints(p.end[None])[0], m.dt_s)
    vp = plan_path_vpop(p, kin, m, m.dt_s)
    opt = plan_path_optimal(p, kin, m, m.dt_s)
    assert periods(opt) <= periods(vp)


@pytest.mark.parametrize("dt", [0.0005, 0.002, 0.004])
def test_other_periods(dt):
    p = hermite_path(circle_fun(20.0, turns=0.5), 6, 300.0)
    for route in ("profile", "vpop"):
        plan = plan_path_optimal(p, None, MILL, dt, PlanSettings(optimal=OptimalOptions(route=route)))
        check(plan, MILL, p.start, p.end, dt)


def test_feed_limit_per_segment():
    coef = np.zeros((2, 6, 3))
    coef[0, 1] = [50, 0, 0]
    coef[1, 0] = [50, 0, 0]
    coef[1, 1] = [50, 1, 0]
    from cnc_interp.fit.path import Path

    p = Path(axes="XYZ", breaks=np.array([0.0, 1.0, 2.0]), coef=coef, line=[1, 2], feed_mm_s=[100.0, 30.0])
    for route in ("profile", "vpop"):
        plan = plan_path_optimal(p, None, MILL, DT, PlanSettings(optimal=OptimalOptions(route=route)))
        check(plan, MILL, p.start, p.end, DT)
        v = np.diff(plan.s) / DT
        assert v.max() <= 100.0 * (1 + 1e-9)
        assert v[plan.s[1:] > 50.0 + 1e-9].max() <= 30.0 * (1 + 1e-9)


def test_zero_length_and_rotary_only():
    p = line_path([1, 2, 3], [1, 2, 3], 100.0)
    plan = plan_path_optimal(p, None, MILL, DT)
    assert plan.q.shape == (1, 3)
    m = Machine(
        name="rot",
        axes="XYZA",
        vmax=[100, 100, 100, 90],
        amax=[1000, 1000, 1000, 300],
        jmax=[1e4, 1e4, 1e4, 1800],
        dt_s=DT,
    )
    p = line_path([5, 5, 5, 0], [5, 5, 5, 120], 60.0, axes="XYZA")
    plan = plan_path_optimal(p, None, m, DT)
    check(plan, m, p.start, p.end, DT)


# -- streaming: chunks are the one-shot plan, byte for byte ----------------------------
@pytest.mark.parametrize("route", ["profile", "vpop"])
def test_tiny_chunks_give_the_same_bytes_as_one_chunk(route):
    p = hermite_path(circle_fun(4.0, turns=1.5, z_per_turn=-0.5), 18, 180.0)
    whole = PlanSettings(optimal=OptimalOptions(route=route, chunk_samples=10**9))
    one = list(iter_path_plan_optimal(p, None, MILL, DT, whole))
    # tiny chunks, and VPOp's own stream window as small as it goes
    small = PlanSettings(optimal=OptimalOptions(route=route, chunk_samples=7))
    tiny = list(iter_path_plan_optimal(p, None, MILL, DT, small, window=1))
    assert len(one) == 1 and len(tiny) > 10
    assert all(c.s.shape[0] == 7 and not c.last for c in tiny[:-1])
    assert one[0].last and tiny[-1].last and tiny[-1].stats["route"] == route
    assert tiny[-1].stats["samples"] == one[0].s.shape[0]
    s1, q1 = one[0].s, one[0].q
    s2 = np.concatenate([c.s for c in tiny])
    q2 = np.concatenate([c.q for c in tiny])
    assert s1.tobytes() == s2.tobytes() and q1.tobytes() == q2.tobytes()
    plan = plan_path_optimal(p, None, MILL, DT, PlanSettings(optimal=OptimalOptions(route=route)))
    assert plan.s.tobytes() == s1.tobytes() and plan.q.tobytes() == q1.tobytes()


def test_a_sample_does_not_depend_on_the_path_far_ahead():
    # the same 3-turn helix, then a 200 mm straight run or nothing: samples in the first
    # profile window (0.5 s of motion plus two braking times) cannot see the difference.
    # They agree to the LPs' tolerance, not to the bit: the joint table scales its arc
    # lengths by one factor per path (1 + ~1e-15), and the interior-point method, solved
    # to 1e-6, turns that into differences of ~1e-7 of the profile. (Without the tail a
    # sample after the first window would differ by far more: it brakes for the end.)
    from cnc_interp.fit.path import Path

    pa = hermite_path(circle_fun(20.0, turns=3.0, z_per_turn=-1.0), 48, 120.0)
    tail = np.zeros((1, 6, 3))
    tail[0, 0] = pa.end
    tail[0, 1] = pa.derivatives_u(pa.breaks[-1:], 1)[1][0] * 0 + [0.0, 200.0, 0.0]
    pb = Path(
        axes="XYZ",
        breaks=np.concatenate((pa.breaks, [pa.breaks[-1] + 1.0])),
        coef=np.concatenate((pa.coef, tail)),
        line=np.arange(1, 50),
        feed_mm_s=np.full(49, 120.0),
    )
    opts = PlanSettings(optimal=OptimalOptions(route="profile", compare_s=0))
    sa = plan_path_optimal(pa, None, MILL, DT, opts)
    sb = plan_path_optimal(pb, None, MILL, DT, opts)
    n = 400
    assert sa.s.shape[0] > 3 * n
    np.testing.assert_allclose(sa.s[:n], sb.s[:n], rtol=0, atol=1e-5)
    np.testing.assert_allclose(sa.q[:n], sb.q[:n], rtol=0, atol=1e-5)
    m = sa.s.shape[0] - 50  # near the end of the helix-only path: braking, not the same
    assert abs(sa.s[m] - sb.s[m]) > 1e-3


# -- nothing makes it fail --------------------------------------------------------------
def test_a_plus_z_moves_plan_with_both_planners(tmp_path):
    from cnc_interp.pipeline import plan_part

    part = tmp_path / "az.ngc"
    part.write_text(
        "G21 G90\nG0 X4.842 Z20.477 A353.409\nF3000\nG1A339.786Z20.000\n"
        "G1A13.622Z20.009\nG1A2.417Z20.472\nG1A0.000Z20.532\nM2\n"
    )
    mach = tmp_path / "xyza.toml"
    mach.write_text(
        'name = "XYZA"\ndt = 0.001\nkinematics = "trivial"\n'
        + "".join(f"[axes.{a}]\nvmax = 200.0\namax = 2000.0\njmax = 50000.0\n" for a in "XYZ")
        + "[axes.A]\nvmax = 180.0\namax = 1800.0\njmax = 45000.0\n"
    )
    cycles = {}
    for planner in ("vpop", "optimal"):
        out = plan_part(str(part), str(mach), planner)
        assert out.report.ok
        q = out.trajectory.q
        np.testing.assert_allclose(q[-1], [4.842, 0.0, 20.532, 0.0], atol=1e-12)
        cycles[planner] = out.trajectory.duration_s
    assert cycles["optimal"] <= cycles["vpop"]


def test_a_profile_that_would_crawl_after_a_sharp_corner_plans(tmp_path, monkeypatch):
    # corpus stellabee1.ngc lines 29179-29184 on axis_mm.ini: knots placed at the static
    # speed estimate right after a sharp corner left one long knot interval where the
    # profile nearly stopped (the sampler crawled until its sample budget). The reach
    # envelope of the estimate fixes the knots.
    from cnc_interp.pipeline import plan_part

    part = tmp_path / "sb1.ngc"
    part.write_text(
        "G20 G18 G90 G94 G64\nF999.0\nG0 X2.6260 Y3.8500 Z-0.1392\n"
        "G1 X2.6320 Z-0.1428\nX2.6500 Z-0.1441\nX2.6580 Z-0.1467\n"
        "X2.6620 Z-0.1500\nG3 X2.6660 Y3.8500 Z-0.1634 I-0.0228 K-0.0141\n"
        "G1 X2.6740 Z-0.2157\nX2.6760 Z-0.2128\nX2.6880 Z-0.1638\nM2\n"
    )
    mach = tmp_path / "axis_mm.toml"
    mach.write_text(
        'name = "axis_mm"\ndt = 0.001\nkinematics = "trivial"\n'
        + "".join(f"[axes.{a}]\nvmax = 30.48\namax = 508.0\njmax = 5080.0\n" for a in "XYZ")
    )
    cycles = {}
    for planner in ("vpop", "optimal"):
        out = plan_part(str(part), str(mach), planner)
        assert out.report.ok
        cycles[planner] = out.trajectory.duration_s
    assert cycles["optimal"] <= cycles["vpop"]
    # without the envelope (no acceleration to reach with: ``reach_envelope`` returns w)
    # the profile crawls, and VPOp's plan of the path is kept
    from cnc_interp.plan.optimal.profile import FeedProfileBuilder

    inputs = FeedProfileBuilder._knot_inputs
    monkeypatch.setattr(FeedProfileBuilder, "_knot_inputs", lambda self: inputs(self)._replace(acc_factor=0.0))
    out = plan_part(str(part), str(mach), "optimal")
    assert out.report.ok and out.trajectory.duration_s <= 1.001 * cycles["vpop"]


@pytest.mark.parametrize("seed", range(3))
def test_safe_planner_holds_limits(seed):
    rng = np.random.default_rng(200 + seed)
    p = hermite_path(random_curve(rng, scale=10.0), 6, float(rng.uniform(30, 200)))
    for machine in (MILL, UCP):
        plan = plan_path_safe(p, None, machine, machine.dt_s)
        check(plan, machine, p.start, p.end, machine.dt_s)


def test_safe_scurve_is_the_time_optimal_line_in_continuous_time():
    from cnc_interp.plan.safe import scurve, scurve_positions

    # 100 mm at v 83.3, a 2000, j 50000: accel phase sqrt... closed form
    v, a, j, L = 83.3, 2000.0, 50000.0, 100.0
    ph = scurve(L, v, a, j)
    T = sum(d for d, _ in ph)
    ap = min(a, np.sqrt(v * j))
    t_ramp = v / ap + ap / j
    assert T == pytest.approx(L / v + t_ramp, rel=1e-12)
    s = scurve_positions(ph, np.array([T]))
    assert s[0] == pytest.approx(L, rel=1e-12)


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("CNC_INTERP_SLOW"), reason="set CNC_INTERP_SLOW=1")
@pytest.mark.parametrize("seed", range(40))
def test_random_sweep_slow(seed):
    rng = np.random.default_rng(1000 + seed)
    p = hermite_path(
        random_curve(rng, scale=float(rng.uniform(2, 40)), n_waves=int(rng.integers(1, 5))),
        int(rng.integers(2, 20)),
        float(rng.uniform(5, 400)),
    )
    for machine in (MILL, UCP):
        dt = machine.dt_s * float(rng.choice([0.5, 1.0, 2.0]))
        for route in ("profile", "vpop"):
            plan = plan_path_optimal(p, None, machine, dt, PlanSettings(optimal=OptimalOptions(route=route)))
            check(plan, machine, p.start, p.end, dt)


#: the fit tolerance (mm) the corpus scenarios below were found at: a coarser one fits
#: other paths, which no longer make the planner take the branch a test is about
SCENARIO_TOL_MM = 0.001
#: the profile's knot spacing (s of motion) the corpus scenarios below were found at: at
#: the default, finer spacing the profile plans these paths without the branch a test is
#: about (no window solved again, no dips, VPOp not ahead)
SCENARIO_KNOT_TIME_S = 0.006


def _corpus_paths(rel: str):
    """generic-mill and the fitted paths (feed moves and rapids) of the corpus program at
    ``rel``, fitted to ``SCENARIO_TOL_MM``."""
    from cnc_interp.fit import FitSettings, fit_program
    from cnc_interp.gcode import read_program
    from cnc_interp.machine.load import load_machine

    src = os.path.join(CORPUS, rel)
    m = load_machine("generic-mill")
    prog = read_program(open(src, "rb").read(), src, axes=m.axes, start=m.start)
    fitted = fit_program(prog, FitSettings.from_options(tol_mm=SCENARIO_TOL_MM, machine=m))
    return m, [p for p in fitted.items if hasattr(p, "coef")]


def _spiral_window_by_window(**tuning):
    """generic-mill, corpus spiral_tangent_test.ngc's 21 mm spiral, and settings that plan
    it window by window, unrefined (compare_s = 0), with the tunables ``tuning``: some
    windows are solved again. The windows commit 0.5 s each (``commit_s``; at 1.0 the
    spiral is five windows, too few for the counts the tests make)."""
    m, paths = _corpus_paths(os.path.join("quick-tests", "spiral_tangent_test.ngc"))
    path = max((p for p in paths if not p.rapid), key=lambda p: p.length)
    settings = dataclasses.replace(
        PlanSettings.from_options(planner="optimal", machine=m),
        optimal=OptimalOptions(
            compare_s=0.0,
            refine_passes=0,
            tuning=dataclasses.replace(TUNING, commit_s=0.5, knot_time_s=SCENARIO_KNOT_TIME_S, **tuning),
        ),
    )
    return m, path, settings


def _profile(path, machine, settings):
    """The feed profile of ``path`` alone, planned whole or window by window as
    ``settings`` say (no sampling): (pieces, windows solved again, LP iterations, its
    traversal time in s)."""
    from cnc_interp.plan.optimal.planner import _planned_whole
    from cnc_interp.plan.optimal.profile import FeedProfileBuilder
    from cnc_interp.plan.optimal.route import _RouteInputs
    from cnc_interp.plan.optimal.sampling import _Nodes

    T = settings.optimal.tuning
    inputs = _RouteInputs(path, None, machine, T)
    whole = _planned_whole(settings.optimal, machine.dt_s, inputs.rough_s)
    builder = FeedProfileBuilder(inputs.table, path, machine, machine.dt_s, T, whole=whole)
    pieces = list(builder.windows())
    nodes = _Nodes(T)
    assert all(nodes.append(p.knots, p.coef, p.s0, p.s1) for p in pieces)
    assert pieces[-1].s1 == inputs.L  # the profile reaches the end
    return pieces, pieces[-1].restarts, sum(p.lp_iters for p in pieces), float(nodes.t[-1])


def _linearise_at_the_estimate(monkeypatch, near_previous: bool = False) -> None:
    """Past where the previous window brakes, a window's first LP linearised at the speed
    estimate itself (not lowered to the previous window's level), and unless
    ``near_previous`` not held near the previous solution either (``_feasible_hat``): the
    rows some windows of ``_spiral_window_by_window`` have no solution under."""
    from cnc_interp.plan.optimal import profile

    monkeypatch.setattr(profile.FeedProfileBuilder, "_ratio", lambda *args: 1.0)
    if not near_previous:
        monkeypatch.setattr(profile.FeedProfileBuilder, "_feasible_hat", lambda self, *a: a[-2])


def _recorded(monkeypatch, cls, name: str) -> list:
    """Every value the method ``cls.name`` returns from now on, in a list."""
    values = []
    method = getattr(cls, name)

    def recording(self, *args):
        values.append(method(self, *args))
        return values[-1]

    monkeypatch.setattr(cls, name, recording)
    return values


@needs_corpus
def test_a_window_that_cannot_brake_under_the_estimate_is_solved_again(monkeypatch):
    # corpus spiral_tangent_test.ngc, its 21 mm spiral, planned window by window
    # (compare_s = 0): a window's LP linearised at the speed estimate itself past where
    # the previous window brakes has no solution (the estimate lies ~4x above the
    # solution in w there, and the state inherited cannot brake under rows that tight);
    # it used to end the profile, and VPOp planned the rest. (Lowered to the previous
    # window's level, or held near the previous solution, no window there needs it: the
    # next tests)
    from cnc_interp.plan.optimal import profile

    _linearise_at_the_estimate(monkeypatch)
    m, path, settings = _spiral_window_by_window()
    _, restarts, _, _ = _profile(path, m, settings)
    assert restarts >= 1
    # without the second solve the profile ends at the first such window
    solve_from = profile.FeedProfileBuilder._solve_from

    def no_restart(self, b0, b1, at_end, fixed, prev, s_prev, ccp_max, *first_max_iter):
        if s_prev is not None and prev is not None and s_prev == prev.s_end:
            raise profile.ProfileError("no restart")
        return solve_from(self, b0, b1, at_end, fixed, prev, s_prev, ccp_max, *first_max_iter)

    monkeypatch.setattr(profile.FeedProfileBuilder, "_solve_from", no_restart)
    with pytest.raises(profile.ProfileError):
        _profile(path, m, settings)


@needs_corpus
def test_a_windows_first_lp_is_linearised_at_the_estimate_lowered_to_the_previous_windows_level(monkeypatch):
    # the same spiral: the solution runs at ~0.25 of the estimate's w, and the first LP
    # of each window linearised there (``est_ratio_min``) solves: no window is solved
    # again, a fifth of the LP iterations, and no slower a plan than with the estimate
    # itself (12 windows solved again)
    from cnc_interp.plan.optimal import profile

    ratios = _recorded(monkeypatch, profile.FeedProfileBuilder, "_ratio")
    m, path, settings = _spiral_window_by_window()
    _, restarts, iterations, time_s = _profile(path, m, settings)
    assert len(ratios) >= 5 and all(0.1 < r < 0.5 for r in ratios)
    assert restarts == 0
    _linearise_at_the_estimate(monkeypatch)
    _, restarts_at, iterations_at, time_at_s = _profile(path, m, settings)
    assert restarts_at >= 5
    assert 3 * iterations < iterations_at
    assert time_s <= time_at_s * (1 + 1e-3)


@needs_corpus
def test_a_windows_first_lp_held_near_the_previous_solution_always_has_one(monkeypatch):
    # the same spiral linearised at the estimate itself (12 windows solved again), but
    # where the previous window brakes only as far from its solution as leaves it within
    # the rows (``_feasible_hat``): no window is solved again, for a plan no longer
    from cnc_interp.plan.optimal import profile

    _linearise_at_the_estimate(monkeypatch, near_previous=True)
    m, path, settings = _spiral_window_by_window()
    held = _recorded(monkeypatch, profile.FeedProfileBuilder, "_feasible_hat")
    _, restarts, _, time_s = _profile(path, m, settings)
    assert len(held) >= 5 and restarts == 0
    _linearise_at_the_estimate(monkeypatch)
    _, restarts_unheld, _, time_unheld_s = _profile(path, m, settings)
    assert restarts_unheld >= 5
    assert time_s <= time_unheld_s * (1 + 1e-3)


def _screened_lps(monkeypatch) -> list:
    """Every feed-profile LP from now on: (screened, solves it took, the largest excess
    of its solution over its rows relative to the largest |b|, at least 1: the
    interior-point solver's measure of its primal residual)."""
    from cnc_interp.plan.optimal import profile

    calls, solves = [], []
    lp, lp_solve = profile.FeedProfileBuilder._lp, profile.lp_solve

    def counting(*args):
        solves[-1] += 1
        return lp_solve(*args)

    def recording(self, rows, c, xv, free, screen, *rest):
        solves.append(0)
        status, it, x = lp(self, rows, c, xv, free, screen, *rest)
        # the LP's rows, the fixed coefficients moved to b (lp_gather)
        rf, rc, rb = rows
        live = np.any(rc != 0.0, axis=1)
        val = np.sum(rc * x[rf[:, None] + np.arange(4)], axis=1)
        excess = np.max((val - rb)[live]) / max(np.max(np.abs(rb[live])), 1.0)
        calls.append((screen, solves[-1], float(excess)))
        return status, it, x

    monkeypatch.setattr(profile, "lp_solve", counting)
    monkeypatch.setattr(profile.FeedProfileBuilder, "_lp", recording)
    return calls


@needs_corpus
def test_a_screened_lp_finds_its_rows_in_about_one_solve(monkeypatch):
    # rows are screened by their slack at the previous solution: rows with b <= 0
    # (coefficients >= 0, the terminal rest, rows the fixed coefficients shifted) screened
    # by value >= 0.3 |b| were left out at zero slack, and each one violated cost a solve
    # from scratch (the spiral: 2.9 solves per screened LP, four rounds and then a
    # solution outside some rows, by 3e-4)

    calls = _screened_lps(monkeypatch)
    m, path, settings = _spiral_window_by_window()
    _profile(path, m, settings)
    screened = [n for screen, n, _ in calls if screen]
    assert len(screened) >= 20 and np.mean(screened) <= 1.5, screened
    assert max(e for _, _, e in calls) <= settings.optimal.tuning.lp_tol  # the solver's own


@needs_corpus
def test_a_screened_lp_that_keeps_finding_rows_takes_every_row_last(monkeypatch):
    # a screen that leaves out every other row it would keep, and two solves at most:
    # where the first solve violates rows left out, the second takes every row, so no
    # solution lies outside a row of its LP (they used to after the last solve)
    from cnc_interp.plan.optimal import profile

    screen_rows = profile.K.lp_screen

    def thinned(rows, x, screen, active, first_pass):
        out = screen_rows(rows, x, screen, active, first_pass)
        if not first_pass:
            return out
        active[::2] = False
        return out[0], int(np.count_nonzero(active))

    monkeypatch.setattr(profile.K, "lp_screen", thinned)
    calls = _screened_lps(monkeypatch)
    m, path, settings = _spiral_window_by_window(screen_rounds=2)
    _profile(path, m, settings)
    assert sum(n == 2 for screen, n, _ in calls if screen) >= 5
    assert max(e for _, _, e in calls) <= settings.optimal.tuning.lp_tol


@needs_corpus
def test_a_path_planned_whole_is_never_longer_than_vpops_plan_of_it():
    # corpus sam_vel_violation.ngc, the path ending at line 14 on axis_mm.ini (lines and
    # arcs at F100000): the profile's plan of the whole path is longer than VPOp's, whose
    # plan is kept
    from cnc_interp.fit import FitSettings, fit_program
    from cnc_interp.gcode import read_program
    from cnc_interp.machine.load import load_machine

    m = load_machine(os.path.join(CORPUS, "configs", "axis_mm.ini"))
    src = os.path.join(CORPUS, "violation_checks", "sam_vel_violation.ngc")
    prog = read_program(open(src, "rb").read(), src, axes=m.axes, start=m.start)
    fitted = fit_program(prog, FitSettings.from_options(tol_mm=0.01, machine=m))
    path = next(p for p in fitted.items if hasattr(p, "coef") and int(p.line[-1]) == 14)
    plan = plan_path_optimal(path, None, m, m.dt_s, PlanSettings.from_options(planner="optimal", machine=m))
    check(plan, m, plan.q[0], plan.q[-1], m.dt_s)
    assert plan.stats["route"] == "profile" and plan.stats["kept"] == "vpop"
    assert periods(plan) == periods(plan_path_vpop(path, None, m, m.dt_s))


def _profile_jerk_share(builder, pieces, end_mm=0.05):
    """The largest |axis jerk| / J of the committed continuous profile on a grid of 20
    points per knot interval (the sampled start and stop, ``end_mm`` at each end, left
    out: they may break the continuous limit by design)."""
    from cnc_interp.plan.optimal.profile import spline_derivs

    worst = 0.0
    for p in pieces:
        kn = p.knots
        t = np.unique(kn[(kn >= p.s0) & (kn <= p.s1)])
        x = (t[:-1, None] + np.diff(t)[:, None] * (np.arange(20) / 20.0)[None, :]).ravel()
        x = x[(x > end_mm) & (x < builder.L - end_mm)]
        w, dw, ddw = spline_derivs(kn, p.coef, np.clip(x, kn[3], kn[-4]))
        q1, q2, q3 = builder.derivs(x)
        v = np.sqrt(np.maximum(w, 0.0))[:, None]
        jerk = (q3 * w[:, None] + 1.5 * q2 * dw[:, None] + 0.5 * q1 * ddw[:, None]) * v
        mv = builder.moving
        worst = max(worst, float(np.max(np.abs(jerk[:, mv]) / builder.jmax[mv], initial=0.0)))
    return worst


@needs_corpus
def test_the_profile_nearly_holds_the_jerk_between_its_collocation_points():
    # corpus line-contouring-xz.ngc, the path through line 51 on generic-mill (G1 lines,
    # G64 Q0.03): the fitted q_sss bumps inside the segments, between the collocation
    # points. At the default knot spacing the points lie close enough that the continuous
    # profile keeps within 5 % of the jerk limit there (1.044: the exact sampler holds
    # the rest); at knots 6 ms apart it broke it by 28 % (1.2823)
    from cnc_interp.plan.optimal import profile
    from cnc_interp.plan.vpop import JointTable

    m, paths = _corpus_paths(os.path.join("performance", "line-contouring-xz.ngc"))
    path = next(p for p in paths if int(p.line[0]) <= 51 <= int(p.line[-1]))

    def worst(tuning):
        b = profile.FeedProfileBuilder(JointTable(path, None), path, m, m.dt_s, tuning)
        return _profile_jerk_share(b, list(b.windows()))

    assert worst(TUNING) < 1.05
    assert worst(dataclasses.replace(TUNING, knot_time_s=SCENARIO_KNOT_TIME_S)) > 1.2


def _fifty_turns():
    """Fifty turns of a circle of 10 mm at F1000: 22 s at MILL's acceleration limit."""
    return hermite_path(circle_fun(10.0, turns=50.0), 800, 1000.0)


def test_a_long_circle_keeps_the_profiles_shorter_plan():
    # fifty turns of a circle at the acceleration limit (22 s), planned whole: the
    # profile's plan is shorter than VPOp's and kept
    path = _fifty_turns()
    plan = plan_path_optimal(path, None, MILL, DT)
    check(plan, MILL, plan.q[0], plan.q[-1], DT)
    assert plan.stats["kept"] == "profile"
    assert periods(plan) < periods(plan_path_vpop(path, None, MILL, DT))


@pytest.mark.parametrize("turns", [50.0, 12.0])
def test_a_long_paths_windows_solved_in_a_thread_of_their_own_give_the_same_samples(monkeypatch, turns):
    # at effort fast a path's windows are solved by a thread ahead of the sampling from
    # ``feed_ahead_s`` on, and a whole path's VPOp plan by another; the samples and stats
    # are those of one thread (the 50-turn circle: 22 s; 12 turns: ~5 s, under ``ahead_s``)
    from cnc_interp.plan import prefetch

    threads = []
    init = prefetch.Prefetch.__init__

    def counting(self, *args, **kwargs):
        threads.append(kwargs.get("name"))
        init(self, *args, **kwargs)

    monkeypatch.setattr(prefetch.Prefetch, "__init__", counting)
    path = hermite_path(circle_fun(10.0, turns=turns), int(16 * turns), 1000.0)
    fast = PlanSettings(planner="optimal", optimal=OptimalOptions(effort="fast"))
    plans = {}
    least = TUNING.feed_ahead_s
    for ahead_s in (least, np.inf):
        plans[ahead_s] = plan_path_optimal(path, None, MILL, DT, tuned(fast, feed_ahead_s=ahead_s))
    assert sorted(threads) == ["cnc-interp-feed", "cnc-interp-vpop", "cnc-interp-vpop"]  # the feed: the first plan only
    threaded, alone = plans[least], plans[np.inf]
    check(threaded, MILL, path.start, path.end, DT)
    assert threaded.s.tobytes() == alone.s.tobytes() and threaded.q.tobytes() == alone.q.tobytes()
    assert threaded.stats == alone.stats and threaded.stats["kept"] == "profile"
    if turns == 12.0:
        assert least * 1.2 < periods(threaded) * DT < TUNING.ahead_s


# -- the paths routed to VPOp go through VPOp's compiled batch ------------------------
def _mixed_paths():
    """Short arcs at low feeds (VPOp's route) around a curvature-limited circle (the
    profile's), and a straight line (the exact line plan)."""
    return [
        hermite_path(circle_fun(2.0, turns=0.25, z_per_turn=0.0), 4, 50.0, line0=1),
        hermite_path(circle_fun(3.0, turns=0.3, z_per_turn=0.6), 4, 20.0, line0=5),
        hermite_path(circle_fun(4.0, turns=1.5, z_per_turn=-0.5), 18, 180.0, line0=10),
        hermite_path(circle_fun(5.0, turns=0.2, z_per_turn=0.0), 4, 60.0, line0=30),
        line_path([0, 0, 0], [40, 0, 0], 150.0, line=40),
    ]


def test_the_paths_routed_to_vpop_are_planned_by_vpops_batch_byte_for_byte():
    from cnc_interp.plan.base import PathPlan
    from cnc_interp.plan.vpop import plan_many_vpop

    paths = _mixed_paths()
    marks = batched_optimal(paths, None, MILL, DT)
    streamed = [plan_path_optimal(p, None, MILL, DT) for p in paths]
    routes = [s.stats["route"] for s in streamed]
    assert routes == ["vpop", "vpop", "profile", "vpop", "line"]
    # the batch plans the line and VPOp's paths (end window refined), the same bytes as
    # their streamed plans, also when they stream in chunks of a few samples
    tiny = PlanSettings(optimal=OptimalOptions(chunk_samples=7))
    for i, (m, r) in enumerate(zip(marks, routes)):
        if r == "profile":
            assert m is None
            continue
        assert isinstance(m, PathPlan) and m.stats["route"] == r
        for plan in (streamed[i], plan_path_optimal(paths[i], None, MILL, DT, tiny)):
            assert m.q.tobytes() == plan.q.tobytes() and m.s.tobytes() == plan.s.tobytes()
    # the end window only ever drops periods from VPOp's own plan, and here it does
    sel = [i for i, r in enumerate(routes) if r == "vpop"]
    own = plan_many_vpop([paths[i] for i in sel], MILL, DT)
    for i, got in zip(sel, own):
        assert marks[i].s.shape[0] == got.s.shape[0] - marks[i].stats["refined_periods"]
        assert_allclose(marks[i].q[-1], got.q[-1], rtol=0, atol=0)
    assert sum(marks[i].stats["refined_periods"] for i in sel) > 0
    # effort fast, or the refinement asked for: VPOp's unrefined plans go to the
    # timeline's batch, or the planner streams them
    fast = PlanSettings(optimal=OptimalOptions(effort="fast"))
    assert [m == {"route": "vpop"} for m in batched_optimal(paths, None, MILL, DT, fast)] == [
        r == "vpop" for r in routes
    ]
    # a path refined (coarse periods, or asked for): this planner streams every path
    # but the line itself; the profile asked for, or a joint map: every path
    lines_only = [None, None, None, None, True]
    assert [m if m is None else True for m in batched_optimal(paths, None, UCP, 0.006)] == lines_only
    refined = PlanSettings(optimal=OptimalOptions(refine_passes=1))
    assert [m if m is None else True for m in batched_optimal(paths, None, MILL, DT, refined)] == lines_only
    profile = PlanSettings(optimal=OptimalOptions(route="profile"))
    assert batched_optimal(paths, None, MILL, DT, profile) == [None] * len(paths)
    assert batched_optimal(paths, object(), MILL, DT) == [None] * len(paths)
    # asked for VPOp's route everywhere, every path goes to VPOp's batch
    every = batched_optimal(paths, None, MILL, DT, PlanSettings(optimal=OptimalOptions(route="vpop", effort="fast")))
    assert all(m == {"route": "vpop"} for m in every)


def test_a_streamed_paths_joint_table_and_route_come_from_the_batchs_routing(monkeypatch):
    # batched_optimal builds each path's joint table to route it; the path it leaves to
    # the stream (the circle) takes that table and route over in the same thread: one
    # table per path, and the same plan and stats as routing it again
    from cnc_interp.plan.optimal import route
    from cnc_interp.plan import joint_table as vpop_table

    paths = _mixed_paths()
    circle = paths[2]
    built = []
    init = vpop_table.JointTable.__init__

    def counted(self, path, *args, **kwargs):
        built.append(path)
        init(self, path, *args, **kwargs)

    monkeypatch.setattr(vpop_table.JointTable, "__init__", counted)
    marks = batched_optimal(paths, None, MILL, DT)
    assert marks[2] is None and sum(m is not None for m in marks) == 4
    assert built.count(circle) == 1
    kept = plan_path_optimal(circle, None, MILL, DT)
    assert built.count(circle) == 1  # taken over, not built again
    again = plan_path_optimal(circle, None, MILL, DT)  # nothing held now: routed again
    assert built.count(circle) == 2
    assert kept.q.tobytes() == again.q.tobytes() and kept.s.tobytes() == again.s.tobytes()
    assert kept.stats == again.stats and kept.stats["route"] == "profile" and "limited_share" in kept.stats
    # another job's batch drops what the last one held; a path in joint space never takes it
    batched_optimal(paths, None, MILL, DT)
    batched_optimal(paths[:2], None, MILL, DT)
    assert route._ROUTED.take(circle, None) is None
    batched_optimal(paths, None, MILL, DT)
    assert route._ROUTED.take(circle, object()) is None


def test_the_timeline_gives_the_same_plan_and_route_counts_with_the_batch(monkeypatch):
    import cnc_interp as ci
    from cnc_interp.plan import optimal

    m = ci.load_machine("generic-mill")
    src = (
        b"G21 G90 G17 G61\nG0 X0 Y0 Z0\nG1 X2 F3000\nG1 Y3\nG2 X2 Y3 I-4 J0 F10000\nG3 X2 Y5 I0 J1 F300\n"
        b"G1 Z-1 F600\nG1 X40 F9000\nM2\n"
    )
    fitted = ci.fit(ci.read_program(src, m, name="mixed.ngc"))
    batched = ci.plan(fitted, m, planner="optimal")
    monkeypatch.delattr(optimal.iter_path_plan_optimal, "batched")
    streamed = ci.plan(fitted, m, planner="optimal")
    routes = batched.settings["stats"]["routes"]
    assert routes == streamed.settings["stats"]["routes"]
    assert routes.get("line", 0) == 4 and routes.get("vpop", 0) == 1 and routes.get("profile", 0) == 1, routes
    assert batched.q.tobytes() == streamed.q.tobytes()
    assert ci.verify(batched, m).ok


# -- the planning effort (``OptimalOptions.effort``, ``--effort``) ---------------------
def test_the_effort_trades_planning_time_for_cycle_time():
    # fine periods: "fast" leaves the profile's plan unrefined and gives VPOp's paths to
    # the batch; "normal" refines the profile's dips and ends and the window at the end
    # of VPOp's plans (their stops lose a few periods to VPOp's greedy steps); "max"
    # every window of every path. A line's plan is exact at every effort (and made in
    # the batch)
    paths = _mixed_paths()
    plans = {}
    for effort in ("fast", "normal", "max"):
        settings = PlanSettings(planner="optimal", optimal=OptimalOptions(effort=effort))
        plans[effort] = [plan_path_optimal(p, None, MILL, DT, settings) for p in paths]
        for p, plan in zip(paths, plans[effort]):
            check(plan, MILL, p.start, p.end, DT)
        marks = batched_optimal(paths, None, MILL, DT, settings)
        assert [m is not None for m in marks] == [
            plan.stats["route"] == "line" or (effort != "max" and plan.stats["route"] == "vpop")
            for plan in plans[effort]
        ]
    line = [p.stats["route"] for p in plans["normal"]].index("line")
    assert len({periods(plans[e][line]) for e in plans}) == 1
    refined = {e: [p.stats.get("refined_periods", 0) for i, p in enumerate(plans[e]) if i != line] for e in plans}
    n = {e: [periods(p) for p in plans[e]] for e in plans}
    assert refined["fast"] == [0] * (len(paths) - 1)
    assert all(r > 0 for r in refined["normal"]) and all(r > 0 for r in refined["max"])
    assert all(a < b for i, (a, b) in enumerate(zip(n["normal"], n["fast"])) if i != line)
    # max visits every window: never longer than normal, for more solves
    assert all(a <= b for a, b in zip(n["max"], n["normal"]))
    solves = {e: sum(p.stats.get("refine_solves", 0) for p in plans[e]) for e in plans}
    assert solves["max"] > solves["normal"] > solves["fast"] == 0
    # the default is "normal", to the byte
    default = [plan_path_optimal(p, None, MILL, DT) for p in paths]
    assert [p.q.tobytes() for p in default] == [p.q.tobytes() for p in plans["normal"]]
    # coarse periods: fast still refines, once (cheap there, and it carries the most)
    p = hermite_path(_trident_like, 24, 60.0)
    fast = PlanSettings(planner="optimal", dt_s=UCP.dt_s, optimal=OptimalOptions(effort="fast"))
    plan = plan_path_optimal(p, None, UCP, UCP.dt_s, fast)
    check(plan, UCP, p.start, p.end, UCP.dt_s)
    assert plan.stats["refined_periods"] > 0
    with pytest.raises(UsageError, match="effort"):
        OptimalOptions(effort="fastest")


def _zigzag_path(machine):
    """corpus zigzag_0.002_0.001.ngc with ``G64 P0.001`` first (the LinuxCNC
    comparison): its 4-inch zigzag of 2000 G1 lines, fitted for ``machine``."""
    from cnc_interp.fit import FitSettings, fit_program
    from cnc_interp.gcode import read_program

    src = os.path.join(CORPUS, "performance", "zigzag_0.002_0.001.ngc")
    prog = read_program(b"G64 P0.001\n" + open(src, "rb").read(), src, axes=machine.axes, start=machine.start)
    fitted = fit_program(prog, FitSettings.from_options(tol_mm=SCENARIO_TOL_MM, machine=machine))
    return max((p for p in fitted.items if hasattr(p, "coef") and not p.rapid), key=lambda p: p.length)


#: the LinuxCNC comparison's machine: XYZ, 203.2 mm/s, 762 mm/s², the jerk out of the way
LINUXCNC_XYZ = Machine(name="linuxcnc-xyz", axes="XYZ", vmax=[203.2] * 3, amax=[762.0] * 3, jmax=[1e6] * 3, dt_s=DT)


@needs_corpus
def test_a_curvature_limited_zigzag_is_planned_by_the_profile_shorter_than_by_vpop():
    # the zigzag lasts ~1 s at its feed (F9999 in/min) but 33 s at its curvature limit;
    # the profile plans it exactly, rest to rest, shorter than VPOp
    m = LINUXCNC_XYZ
    path = _zigzag_path(m)
    settings = tuned(
        PlanSettings.from_options(planner="optimal", machine=m, effort="fast"),
        knot_geo=0.5,
        knot_time_s=SCENARIO_KNOT_TIME_S,
    )
    plan = plan_path_optimal(path, None, m, DT, settings)
    check(plan, m, plan.q[0], plan.q[-1], DT)
    assert plan.stats["route"] == "profile"
    assert plan.stats.get("kept") != "vpop"
    assert periods(plan) < periods(plan_path_vpop(path, None, m, DT))


@needs_corpus
def test_a_windows_first_lp_without_a_solution_gives_up_early_for_the_same_plan(monkeypatch):
    # the interior-point solver has no infeasibility test: a window's first LP without a
    # solution ran to ``lp_max_iter`` before the window was solved again. Capped at
    # ``lp_first_max_iter`` (below what the first LPs that solve take), the same
    # profile for fewer iterations (corpus spiral_tangent_test.ngc linearised at the
    # estimate itself: windows without a solution, see the tests above)
    from cnc_interp.plan.optimal import profile

    _linearise_at_the_estimate(monkeypatch)
    m, path, settings = _spiral_window_by_window()
    spent = []  # every LP's iterations, those without a solution too
    lp_solve = profile.lp_solve

    def counting(*args):
        out = lp_solve(*args)
        spent.append(out[1])
        return out

    monkeypatch.setattr(profile, "lp_solve", counting)
    capped, restarts, _, _ = _profile(path, m, settings)
    capped_spent, spent[:] = sum(spent), []
    T = settings.optimal.tuning
    saved = T.lp_max_iter - T.lp_first_max_iter
    uncapped, _, _, _ = _profile(path, m, tuned(settings, lp_first_max_iter=T.lp_max_iter))
    assert restarts >= 1
    for a, b in zip(capped, uncapped, strict=True):
        assert_array_equal(a.coef, b.coef)
        assert_array_equal(a.knots, b.knots)
    assert capped_spent <= sum(spent) - restarts * saved, (capped_spent, sum(spent))

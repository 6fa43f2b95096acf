"""Paper 000's constant and variable feed planners: closed forms, limits, verify."""

import math

from pathlib import Path

import numpy as np
import pytest

from .conftest import CORPUS as CORPUS_DIR
from numpy.testing import assert_allclose

from cnc_interp.constants import VERIFY_RATIO_SLACK
from cnc_interp.plan.paper000.limits import P000_CURV_JERK_SHARE
from cnc_interp.plan.paper000.limits import P000_CURV_ACCEL_SHARE
from cnc_interp.machine.model import Machine
from cnc_interp.plan.paper000 import shapes
from cnc_interp.plan.paper000.constant import constant_feed, plan_path_constant
from cnc_interp.plan.paper000.curvature import segment_geometry
from cnc_interp.plan.paper000.variable import plan_path_variable
from cnc_interp.plan.verify import verify_arrays
from cnc_interp.plan.settings import Paper000Options, PlanSettings

PLANNERS = (plan_path_constant, plan_path_variable)


def machine(v=500.0, a=2000.0, j=50000.0, axes="XY"):
    n = len(axes)
    return Machine(name="test", axes=axes, vmax=np.full(n, v), amax=np.full(n, a), jmax=np.full(n, j), dt_s=0.001)


def check_plan(plan, path, m, dt, joint_map=None):
    """Every output: passes verify, starts at 0 and ends exactly at the path end, no NaN."""
    assert plan.status == "ok"
    assert np.all(np.isfinite(plan.q)) and np.all(np.isfinite(plan.s))
    rep = verify_arrays(plan.q, dt, m.vmax, m.amax, m.jmax)
    assert rep.worst_ratio <= 1 + VERIFY_RATIO_SLACK, rep.format()
    assert plan.s[0] == 0.0 and plan.s[-1] == path.length
    assert np.all(np.diff(plan.s) >= 0)
    end = path.end if joint_map is None else joint_map(path.end[None])[0]
    start = path.start if joint_map is None else joint_map(path.start[None])[0]
    assert np.array_equal(plan.q[-1], end)
    assert np.array_equal(plan.q[0], start)
    prof = plan.profiles
    assert_allclose(prof.duration_s, (plan.s.size - 1) * dt, rtol=1e-9)
    assert_allclose(prof.v_end[:-1], prof.v_start[1:])
    assert prof.v_start[0] == 0.0 and prof.v_end[-1] == 0.0
    return rep.worst_ratio


@pytest.mark.parametrize("share", [None, 0.95])
def test_circle_constant_feed_is_sqrt_a_over_kappa(share):
    r, dt = 10.0, 0.001
    m = machine(v=1000.0, a=2000.0, j=1e8)  # acceleration binds
    path = shapes.circle(r, turns=3, n_per_turn=36)
    settings = None if share is None else PlanSettings(paper000=Paper000Options(curv_accel_share=share))
    a_m = (P000_CURV_ACCEL_SHARE if share is None else share) * 2000.0
    expect = math.sqrt(a_m / (1.0 / r))  # Eq. 6: V = sqrt(A_m / kappa)
    geom = segment_geometry(path)
    assert_allclose(constant_feed(geom, m, path.feed_mm_s, settings), expect, rtol=1e-4)
    plan = plan_path_constant(path, None, m, dt, settings)
    check_plan(plan, path, m, dt)
    v = plan.profiles.v_cruise[0]
    assert_allclose(v, expect, rtol=2e-3)  # only the stretch to whole periods lowers it
    feed = np.diff(plan.s) / dt
    mid = feed[feed.size // 2 - 50 : feed.size // 2 + 50]
    assert_allclose(mid, v, rtol=1e-6)
    # centripetal acceleration at cruise is A_m: the acceleration really binds
    q = plan.q[plan.q.shape[0] // 2 - 200 : plan.q.shape[0] // 2 + 200]
    acc = np.abs(np.diff(q, 2, axis=0)).max() / dt**2
    assert_allclose(acc, v * v / r, rtol=1e-3)


def test_circle_constant_feed_jerk_bound():
    r, dt = 5.0, 0.001
    m = machine(v=1000.0, a=1e6, j=20000.0)  # jerk binds: kappa^2 V^3 <= sj J
    path = shapes.circle(r, n_per_turn=36)
    expect = (P000_CURV_JERK_SHARE * 20000.0 * r * r) ** (1 / 3)
    geom = segment_geometry(path)
    assert_allclose(constant_feed(geom, m, path.feed_mm_s), expect, rtol=1e-3)
    check_plan(plan_path_constant(path, None, m, dt), path, m, dt)


def test_programmed_feed_caps_a_line():
    path = shapes.chain([("line", 200.0)], feed_mm_s=50.0)
    m = machine()
    for planner in PLANNERS:
        plan = planner(path, None, m, 0.001)
        check_plan(plan, path, m, 0.001)
        assert plan.profiles.v_cruise.max() <= 50.0
        assert plan.profiles.v_cruise.max() > 49.9


def test_short_path_lowers_the_feed():
    path = shapes.chain([("line", 0.05)], feed_mm_s=200.0)
    m = machine()
    for planner in PLANNERS:
        plan = planner(path, None, m, 0.001)
        check_plan(plan, path, m, 0.001)
        assert plan.profiles.v_cruise.max() < 20.0


def test_variable_beats_constant_on_g2_bump():
    # G2 path (no corner splits the constant plan): straights at F, one tight bump
    path = shapes.bump(height=3.0, width=2.0, half_span=60.0, feed_mm_s=250.0)
    m = machine(v=300.0, a=3000.0, j=2e6)  # acceleration binds on the bump
    pc = plan_path_constant(path, None, m, 0.001)
    pv = plan_path_variable(path, None, m, 0.001)
    check_plan(pc, path, m, 0.001)
    check_plan(pv, path, m, 0.001)
    assert pc.profiles.n_pieces == 1
    # constant: one feed for the whole path, set by the bump's curvature 2 h / w^2 = 1.5
    assert_allclose(pc.profiles.v_cruise[0], math.sqrt(P000_CURV_ACCEL_SHARE * 3000 / 1.5), rtol=2e-3)
    assert pv.s.size < 0.5 * pc.s.size
    assert pv.profiles.v_cruise.max() > 200.0  # near F on the straights (band 10%)


def test_variable_beats_constant_on_mixed_path():
    path = shapes.chain(
        [("line", 80.0), ("arc", 1.0, math.pi), ("line", 80.0), ("arc", 20.0, -math.pi / 2), ("line", 40.0)],
        feed_mm_s=250.0,
    )
    m = machine(v=300.0, a=3000.0, j=60000.0)
    pc = plan_path_constant(path, None, m, 0.001)
    pv = plan_path_variable(path, None, m, 0.001)
    check_plan(pc, path, m, 0.001)
    check_plan(pv, path, m, 0.001)
    # the line/arc junctions (curvature jumps) split the constant plan into sections
    assert pc.profiles.n_pieces > 1
    # the slow-down for the tight arc starts early enough: feed on the arc is within its cap
    seg = path.segment_of_s(pv.s[1:])
    feed = np.diff(pv.s) / 0.001
    tight = (seg >= 1) & (seg <= 6)  # the six segments of the radius-1 half turn
    assert_allclose(path.s_breaks[7] - path.s_breaks[1], math.pi, rtol=1e-4)
    assert feed[tight].max() <= math.sqrt(P000_CURV_ACCEL_SHARE * 3000.0 * 1.0) * 1.001


def test_per_segment_profiles_merge_band_zero():
    path = shapes.circle(4.0, n_per_turn=24)
    m = machine()
    plan = plan_path_variable(path, None, m, 0.001, PlanSettings(paper000=Paper000Options(merge_band=0.0)))
    check_plan(plan, path, m, 0.001)
    assert plan.profiles.n_pieces == path.n_seg
    merged = plan_path_variable(path, None, m, 0.001)
    assert merged.profiles.n_pieces == 1
    check_plan(merged, path, m, 0.001)


def test_profile_data_matches_samples():
    path = shapes.chain([("line", 30.0), ("arc", 2.0, math.pi / 2), ("line", 30.0)], feed_mm_s=150.0)
    m = machine()
    plan = plan_path_variable(path, None, m, 0.001)
    prof = plan.profiles
    t = np.arange(plan.s.size) * 0.001
    s, v, a = prof.evaluate(t)
    assert_allclose(s, plan.s, atol=1e-9)
    assert np.all(prof.seg_first <= prof.seg_last)
    assert_allclose(prof.length.sum(), path.length, rtol=1e-12)
    # a regenerated from the polynomial coefficients at the start of every phase is 0
    c = prof.acc_coef()
    assert np.all(c[:, :, :2] == 0.0)


def test_joint_map_is_respected():
    path = shapes.chain([("line", 20.0), ("arc", 5.0, math.pi), ("line", 20.0)], feed_mm_s=200.0)
    m = machine(v=200.0, a=1500.0, j=30000.0)
    rot = np.array([[math.cos(0.3), -math.sin(0.3)], [math.sin(0.3), math.cos(0.3)]]) * [2.0, 0.7]

    def jmap(p):
        return p @ rot.T

    for planner in PLANNERS:
        plan = planner(path, jmap, m, 0.001)
        check_plan(plan, path, m, 0.001, joint_map=jmap)


def test_replans_when_the_caps_are_too_optimistic(monkeypatch):
    import cnc_interp.plan.paper000.variable as var

    from dataclasses import replace

    real = var.segment_geometry

    def optimistic(*a, **k):  # a geometry sampler that misses most of the curvature
        g = real(*a, **k)
        return replace(g, kappa=g.kappa / 4, g2=g.g2 / 4, g3=g.g3 / 16, jump2=g.jump2 / 4)

    monkeypatch.setattr(var, "segment_geometry", optimistic)
    path = shapes.chain([("line", 10.0), ("arc", 2.0, math.pi), ("line", 10.0)], feed_mm_s=400.0)
    m = machine()
    plan = var.plan_path_variable(path, None, m, 0.001)
    check_plan(plan, path, m, 0.001)
    assert plan.stats["replans"] > 0


def test_corner_between_lines():
    # a G1 corner of 20 degrees: the junction feed is capped, the output still verifies
    path = shapes.planar_path(
        [0.0, math.radians(20)], [[0, 0], [10.0, 0]], [10.0, 10.0], np.zeros((2, 6)), feed_mm_s=100.0
    )
    m = machine()
    for planner in PLANNERS:
        plan = planner(path, None, m, 0.001)
        check_plan(plan, path, m, 0.001)


def test_random_sweep_limits_hold():
    rng = np.random.default_rng(2026)
    for case in range(6):
        pieces = []
        for _ in range(int(rng.integers(1, 5))):
            if rng.random() < 0.4:
                pieces.append(("line", float(rng.uniform(0.5, 40))))
            else:
                pieces.append(("arc", float(rng.uniform(0.3, 30)), float(rng.uniform(-3, 3))))
        path = shapes.chain(pieces, feed_mm_s=float(rng.uniform(10, 400)))
        m = Machine(
            name="r",
            axes="XY",
            vmax=rng.uniform(50, 600, 2),
            amax=rng.uniform(200, 5000, 2),
            jmax=rng.uniform(2e3, 2e5, 2),
            dt_s=0.001,
        )
        dt = float(rng.choice([0.0005, 0.001, 0.004]))
        for planner in PLANNERS:
            plan = planner(path, None, m, dt)
            check_plan(plan, path, m, dt)


def test_general_3d_path():
    from tests.test_paper000_curvature import helix_path

    path = helix_path(5.0, 1.0, turns=1.0, n_seg=24)
    m = machine(v=300.0, a=2000.0, j=40000.0, axes="XYZ")
    for planner in PLANNERS:
        check_plan(planner(path, None, m, 0.001), path, m, 0.001)


def test_registry_entries():
    from cnc_interp.plan.planners import get_planner

    assert get_planner("constant") is plan_path_constant
    assert get_planner("variable") is plan_path_variable


def test_plan_settings_options_are_read():
    path = shapes.circle(10.0, turns=3, n_per_turn=36)
    m = machine(v=1000.0, a=2000.0, j=1e8)
    ps = PlanSettings(planner="constant", dt_s=0.001, paper000=Paper000Options(curv_accel_share=0.95))
    a = plan_path_constant(path, None, m, 0.001, ps)
    b = plan_path_constant(path, None, m, 0.001, PlanSettings(planner="constant", dt_s=0.001))
    assert_allclose(a.profiles.v_cruise[0], math.sqrt(0.95 * 2000 * 10.0), rtol=2e-3)
    assert_allclose(b.profiles.v_cruise[0], math.sqrt(P000_CURV_ACCEL_SHARE * 2000 * 10.0), rtol=2e-3)
    # recorded with the plan by the flat name it always had
    assert ps.to_dict()["options"] == {"curv_accel_share": 0.95}


@pytest.mark.parametrize(
    "knobs", [{"curv_accel_share": 0.0}, {"curv_jerk_share": 1.5}, {"merge_band": -0.1}, {"cross_jerk_share": "x"}]
)
def test_paper000_knobs_out_of_range_are_usage_errors(knobs):
    from cnc_interp.errors import UsageError

    with pytest.raises(UsageError):
        Paper000Options(**knobs)


def test_non_finite_path_is_a_plan_error():
    from cnc_interp.errors import PlanError

    path = shapes.chain([("line", 10.0)])
    bad = type(path)(
        axes=path.axes, breaks=path.breaks, coef=path.coef * np.nan, line=path.line, feed_mm_s=path.feed_mm_s
    )
    for planner in PLANNERS:
        with pytest.raises(PlanError):
            planner(bad, None, machine(), 0.001)


def test_deterministic():
    path = shapes.bump(n_seg=60, feed_mm_s=200.0)
    m = machine()
    a = plan_path_variable(path, None, m, 0.001)
    b = plan_path_variable(path, None, m, 0.001)
    assert np.array_equal(a.q, b.q) and np.array_equal(a.s, b.s)


def test_degenerate_cusp_is_refused_not_crawled():
    from cnc_interp.errors import PlanError

    # x = t^2 - t^3 doubles back at t = 2/3 (zero speed): unbounded curvature there
    path = shapes.chain([("line", 1.0)])
    cusp = type(path)(
        axes="XY",
        breaks=np.array([0.0, 1.0]),
        coef=np.array([[[0, 0], [0, 0], [1, 1e-9], [-1, 0], [0, 0], [0, 0]]], float),
        line=[7],
        feed_mm_s=[100.0],
    )
    m = machine()
    for planner in PLANNERS:
        with pytest.raises(PlanError, match="degenerate.*|line 7"):
            planner(cusp, None, m, 0.001)


def test_constant_feed_ignores_a_peak_inside_the_start_ramp():
    # G2 path: a tight bump 0.3 mm after the start, then 100 mm straight. The constant
    # feed is not set by the bump (the feed is low there anyway, ramping up from rest).
    h, wd, x0 = 0.05, 0.1, 0.3

    def f(k):
        def g(u):
            e = h * np.exp(-(((u - x0) / wd) ** 2))
            z = (u - x0) / wd
            y = [e, -2 * z / wd * e, (4 * z * z - 2) / wd**2 * e][k]
            xs = [u, np.ones_like(u), np.zeros_like(u)][k]
            return np.stack([xs, y], -1)

        return g

    x = np.r_[np.linspace(0, 1.0, 41), np.linspace(1.0, 100.0, 21)[1:]]
    path = shapes.hermite_path(x, f(0), f(1), f(2), "XY", feed_mm_s=100.0)
    m = machine(v=500.0, a=2000.0, j=50000.0)
    geom = segment_geometry(path)
    assert constant_feed(geom, m, path.feed_mm_s) < 20.0  # the bump's own cap
    plan = plan_path_constant(path, None, m, 0.001)
    check_plan(plan, path, m, 0.001)
    assert plan.profiles.v_cruise.max() > 99.0


CORPUS = Path(CORPUS_DIR)


@pytest.mark.parametrize("planner", ["constant", "variable"])
@pytest.mark.parametrize(
    "part,preset",
    [
        ("samples/gcode/lathe-profile.ngc", "xz-lathe"),
        ("samples/gcode/nurbs-trident.ngc", "mikron-ucp710"),
        (str(CORPUS / "nurbs-g5" / "trident-xy.ngc"), "mikron-ucp710"),
        (str(CORPUS / "performance" / "spiral_lines.ngc"), "generic-mill"),
    ],
)
@pytest.mark.slow
def test_golden_runs_verify(part, preset, planner):
    """Whole programs through parse, fit, timeline and verify (plan_part raises on a violation)."""
    import os

    from cnc_interp.pipeline import plan_part

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    full = part if os.path.isabs(part) else os.path.join(root, part)
    if not os.path.exists(full):
        pytest.skip(f"corpus file not present: {full}")
    out = plan_part(full, preset, planner=planner)
    traj = out.trajectory
    assert out.report.ok and traj.planner == planner
    assert np.all(np.isfinite(traj.q))
    assert traj.profiles is not None

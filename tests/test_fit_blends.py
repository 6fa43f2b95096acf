"""Corner blends: sharp corners are rounded by G2 quintics within the tolerance
instead of stopping the machine; stops remain where the tolerance cannot round a corner.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from cnc_interp.fit import FitSettings, Path, fit_program, fit_run
from cnc_interp.fit.blends import BLEND_R, blend_piece, choose_shapes, plan_blends, unit_blends
from cnc_interp.gcode import read_program
from cnc_interp.gcode.program import Run

from ._fit_helpers import all_finite, continuity, distance_to_path, min_speed


def _run(nodes, tol=np.nan, axes="XYZ", feed=50.0):
    nodes = np.asarray(nodes, float)
    n = nodes.shape[0]
    return Run(
        "feed",
        axes,
        nodes,
        np.arange(1, n + 1),
        np.ones(n, int),
        np.full(n, feed),
        np.broadcast_to(np.asarray(tol, float), (n,)).copy(),
        np.full(n, np.nan),
    )


def _dense_polyline(nodes, per=400):
    return np.concatenate(
        [nodes[k] + (nodes[k + 1] - nodes[k]) * np.linspace(0, 1, per)[:, None] for k in range(len(nodes) - 1)]
    )


def _hermite_eval(coef, t, k=0):
    out = np.zeros((t.size, coef.shape[1]))
    for i in range(k, 6):
        f = float(np.prod(np.arange(i - k + 1, i + 1))) if k else 1.0
        out += f * coef[i] * (t ** (i - k))[:, None]
    return out


@pytest.mark.parametrize("deg", [35.0, 90.0, 150.0])
def test_blend_piece_is_g2_with_both_moves_and_within_tolerance(deg):
    th = np.radians(deg)
    v = np.array([3.0, -2.0, 1.0])
    t_in = np.array([1.0, 0.0, 0.0])
    t_out = np.array([np.cos(th), np.sin(th), 0.0])
    tol = 0.01
    (r,), (d,), (dev,) = choose_shapes(np.array([th]), np.array([tol]), np.array([np.inf]))
    assert dev <= tol * (1 + 1e-12)
    p_a, p_b = v - d * t_in, v + d * t_out
    (coef,), (h,) = blend_piece(p_a[None], p_b[None], t_in[None], t_out[None], np.array([d]), np.array([r]), np.ones(3))
    ends = np.array([0.0, h])
    q, q1, q2 = (_hermite_eval(coef, ends, k) for k in range(3))
    assert_allclose(q, [p_a, p_b], atol=1e-12)
    assert_allclose(q1 / np.linalg.norm(q1, axis=1)[:, None], [t_in, t_out], atol=1e-12)
    assert_allclose(q2, 0.0, atol=1e-9)  # zero curvature where it meets the moves
    # independent: the corner's distance from the blend, and the blend's from the two moves
    t = np.linspace(0, h, 20001)
    pts = _hermite_eval(coef, t)
    assert np.linalg.norm(pts - v, axis=1).min() <= tol
    legs = np.array([p_a, v, p_b])
    path = Path(axes="XYZ", breaks=np.array([0.0, h]), coef=coef[None], line=[1], feed_mm_s=[1.0])
    assert distance_to_path(path, _dense_polyline(legs)).max() <= tol * (1 + 1e-9)
    seg = [(p_a, v), (v, p_b)]
    off = np.min([np.linalg.norm(np.cross(pts - a, (b - a) / np.linalg.norm(b - a)), axis=1) for a, b in seg], axis=0)
    assert off.max() <= tol * (1 + 1e-9)


def test_unit_blend_table_matches_a_direct_computation():
    # closed form at θ = 0: a straight blend has no deviation at any shape
    dev, kap, dk, sp = unit_blends(0.0, BLEND_R)
    assert_allclose(dev, 0.0, atol=1e-12) and assert_allclose(kap, 0.0, atol=1e-9)
    # the chosen shape's deviation against 20k samples of the same blend
    th = np.radians(73.0)
    (r,), (d,), (dev_c,) = choose_shapes(np.array([th]), np.array([1.0]), np.array([np.inf]))
    (coef,), (h,) = blend_piece(
        np.array([[-d, 0.0]]),
        d * np.array([[np.cos(th), np.sin(th)]]),
        np.array([[1.0, 0.0]]),
        np.array([[np.cos(th), np.sin(th)]]),
        np.array([d]),
        np.array([r]),
        np.ones(2),
    )
    pts = _hermite_eval(coef, np.linspace(0, h, 20001))
    true_dev = np.linalg.norm(pts, axis=1).min()
    assert true_dev <= dev_c <= 1.05 * max(true_dev, 1e-12) + 0.03


def test_square_is_one_g2_path_within_tolerance_and_faster_than_stops():
    text = "G21 G90 G64 P0.05\nG0 X0 Y0 Z0\nG1 X10 F3000\nY10\nX0\nY0\nM2\n"
    prog = read_program(text, source="sq.ngc")
    res = fit_program(prog, FitSettings())
    (p,) = [q for q in res.paths if not q.rapid]
    assert all_finite(p) and min_speed(p) > 0
    pos, tan, curv = continuity(p)
    assert pos < 1e-9 and tan < 1e-9 and curv < 1e-6
    sq = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0], [0, 0, 0.0]])
    assert distance_to_path(p, _dense_polyline(sq), samples_per_seg=400, candidates=8).max() <= 0.05 * (1 + 1e-9)
    assert res.stats["within_tolerance"] and res.stats["max_path_dev_ratio"] <= 1 + 1e-6

    from cnc_interp.machine.load import load_machine
    from cnc_interp.plan.settings import PlanSettings
    from cnc_interp.plan.timeline import plan_program
    from cnc_interp.plan.verify import verify

    m = load_machine("generic-mill")
    st = PlanSettings.from_options(planner="vpop", dt_s=None, machine=m)
    blended = plan_program(res, m, st)
    stops = plan_program(fit_program(prog, FitSettings(blend_corners=False)), m, st)
    assert verify(blended, m).ok and verify(stops, m).ok
    # four 90° corners at G64 P0.05: 0.98 s blended against 1.07 s stopping (generic-mill)
    assert blended.duration_s < stops.duration_s


@pytest.mark.parametrize("seed", range(4))
def test_seeded_sharp_polylines_blend_within_tolerance(seed):
    rng = np.random.default_rng(1400 + seed)
    n = 60
    turn = np.radians(rng.uniform(-170, 170, n))
    heading = np.cumsum(turn)
    step = rng.uniform(0.05, 3.0, n)[:, None] * np.stack([np.cos(heading), np.sin(heading)], 1)
    xy = np.concatenate([[[0.0, 0.0]], np.cumsum(step, axis=0)])
    nodes = np.concatenate([xy, rng.uniform(-0.01, 0.01, (n + 1, 1)).cumsum(0)], axis=1)
    tol = float(10 ** rng.uniform(-3, -1.3))
    paths = fit_run(_run(nodes), FitSettings(tol_mm=tol))
    for p in paths:
        assert all_finite(p) and min_speed(p) > 0
        pos, tan, curv = continuity(p)
        assert pos < 1e-9 and tan < 1e-9 and curv < 1e-6 * max(1.0, np.abs(p.coef).max())
    dist = np.min(
        [distance_to_path(p, _dense_polyline(nodes, 60), samples_per_seg=200, candidates=8) for p in paths], axis=0
    )
    assert dist.max() <= tol * (1 + 1e-6)
    # most corners are blended: far fewer paths than corners sharper than 30°
    sharp = (np.degrees(np.abs(turn[1:])) > 30).sum()
    assert len(paths) < 0.5 * sharp


def test_stops_remain_under_g61_and_at_near_reversals():
    g61 = "G21 G90 G61\nG0 X0 Y0 Z0\nG1 X10 F3000\nY10\nX0\nM2\n"
    res = fit_program(read_program(g61, source="g61.ngc"), FitSettings())
    assert sum(not p.rapid for p in res.paths) == 3
    # a 179° turn (a zig-zag) cannot be rounded: the path stops there
    zz = "G21 G90 G64 P0.01\nG0 X0 Y0 Z0\nG1 X10 F3000\nX0 Y0.1\nM2\n"
    res = fit_program(read_program(zz, source="zz.ngc"), FitSettings())
    assert sum(not p.rapid for p in res.paths) == 2


def test_plan_blends_respects_room_and_crowding():
    # two 90° corners 0.02 mm apart at a 0.05 mm tolerance: the blend the tolerance allows
    # (about 45× the tolerance each side) would need over 100× the 0.01 mm the short move
    # leaves: stops; 0.2 mm apart (about 20× the room) it is squeezed into the room
    cand = np.array([False, True, True, False])
    for gap, blended in ((0.02, False), (0.2, True)):
        nodes = np.array([[0, 0], [10, 0], [10, gap], [0, gap]], float)
        ok, dist, _ = plan_blends(nodes, np.ones(2, bool), np.full(4, 0.05), cand)
        assert ok[1] == ok[2] == blended
        if blended:  # within the room: half the short move on each side
            assert np.all(dist[1:3] <= 0.5 * gap + 1e-15)
    nodes = np.array([[0, 0], [10, 0], [10, 0.2], [0, 0.2]], float)
    ok, dist, _ = plan_blends(nodes, np.ones(2, bool), np.full(4, 0.001), cand)
    assert ok[1] and ok[2] and np.all(dist[1:3] <= 0.1 + 1e-15)


def test_a_crowded_blend_within_one_periods_step_still_blends():
    # 90° corners 0.2 µm apart at a 1 µm tolerance: crowded past the cap, so they stop,
    # unless the squeezed blend (0.1 µm) is within the machine's acceleration and jerk
    # step of one period, where the sampled plan passes it as a straight move
    cand = np.array([False, True, True, False])
    nodes = np.array([[0, 0], [10, 0], [10, 2e-4], [0, 2e-4]], float)
    tol = np.full(4, 1e-3)
    for step_mm, blended in ((0.0, False), (5e-5, False), (2e-4, True)):
        ok, dist, _ = plan_blends(nodes, np.ones(2, bool), tol, cand, step_mm=step_mm)
        assert ok[1] == ok[2] == blended, step_mm
        if blended:
            assert np.all(dist[1:3] <= 1e-4 + 1e-15)  # within the room


def test_fit_settings_take_the_period_step_from_the_linear_axes():
    from cnc_interp.errors import UsageError
    from cnc_interp.machine.model import Machine

    m = Machine(
        name="t", axes="XYZA", vmax=[100, 100, 50, 360], amax=[1000, 800, 900, 5],
        jmax=[1e6, 2e6, 5e5, 1.0], dt_s=0.001,
    )  # fmt: skip
    # min(800 · 1e-6, 5e5 · 1e-9) mm: A's limits are not a linear step
    assert FitSettings.from_options(machine=m).period_step_mm == pytest.approx(5e-4, rel=1e-12)
    assert FitSettings().period_step_mm == 0.0
    with pytest.raises(UsageError):
        FitSettings(period_step_mm=-1.0)


@pytest.mark.parametrize("n_axes", [2, 3, 5, 8, 9])
def test_compiled_corner_turns_are_numpys(n_axes):
    # corner_turns' compiled pass must give numpy's numbers for the angle formula bit for
    # bit (a corner at the threshold is cut or not the same way): numpy sums a whole row
    # pairwise but a column selection (the linear axes alone) left to right, which differ
    # from 8 axes on
    from cnc_interp.fit.corners import PreparedRun, corner_turns

    def turn_angles(v_in, v_out):  # the numpy reference (rad), 0 where a vector is zero
        n1 = np.linalg.norm(v_in, axis=-1)
        n2 = np.linalg.norm(v_out, axis=-1)
        dot = (v_in * v_out).sum(axis=-1)
        cross = np.sqrt(np.maximum((n1 * n2) ** 2 - dot**2, 0.0))
        return np.where((n1 > 0) & (n2 > 0), np.arctan2(cross, dot), 0.0)

    rng = np.random.default_rng(n_axes)
    n = 4000
    steps = rng.standard_normal((n, n_axes)) * rng.choice([1e-4, 1e-2, 1.0, 100.0], size=(n, 1))
    steps[rng.random(n) < 0.05] = 0.0  # zero moves: no turn
    nodes = np.cumsum(steps, axis=0)
    for lin_count in sorted({1, n_axes - 1, n_axes} - {0}):
        lin = np.arange(n_axes) < lin_count
        scale = np.where(lin, 1.0, 0.37)
        pr = PreparedRun(
            "XYZABCUVW"[:n_axes],
            nodes,
            np.arange(n),
            np.ones(n),
            np.full(n, 0.01),
            (),
            lin,
            scale,
            np.zeros(n - 1, bool),
        )
        chords = np.diff(nodes * scale, axis=0)
        d_in = np.zeros_like(nodes)
        d_out = np.zeros_like(nodes)
        d_in[1:] = chords
        d_out[:-1] = chords
        want = np.degrees(turn_angles(d_in, d_out))
        if not lin.all():
            want = np.maximum(want, np.degrees(turn_angles(d_in[:, lin], d_out[:, lin])))
        turn, inside = corner_turns(pr)
        np.testing.assert_array_equal(turn, want)
        assert not inside.any()

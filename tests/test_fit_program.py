"""fit_program: timeline, corners, G61 / G64 P tolerances, rotary-only moves, report, CLI."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from numpy.testing import assert_allclose

from cnc_interp.errors import UsageError
from cnc_interp.fit import FitResult, FitSettings, Path, fit_program, fit_run
from cnc_interp.fit.report import fit_statistics, format_statistics, segments_document, write_segments_json
from cnc_interp.gcode.program import Dwell, Program, Run, Stop

from ._fit_helpers import all_finite, distance_to_path

SAMPLES = os.path.join(os.path.dirname(__file__), "..", "samples", "gcode")


def _run(nodes, axes="XYZ", tol=np.nan, kind="feed", feed=20.0):
    nodes = np.asarray(nodes, float)
    n = nodes.shape[0]
    tol_arr = np.broadcast_to(np.asarray(tol, float), (n,)).copy()
    return Run(
        kind,
        axes,
        nodes,
        np.arange(1, n + 1),
        np.ones(n, int),
        np.full(n, np.inf if kind == "rapid" else feed),
        tol_arr,
        np.full(n, np.nan),
    )


def _polygon(n_sides, R=10.0, laps=1.0):
    a = np.linspace(0, 2 * np.pi * laps, int(n_sides * laps) + 1)
    return np.stack([R * np.cos(a), R * np.sin(a), np.zeros_like(a)], axis=1)


def test_timeline_rapids_dwell_stop_and_exact_chaining():
    feed_nodes = np.array([[0, 0, -1], [10, 0, -1], [10, 10, -1], [0, 10, -1.0]])
    items = (
        _run([[0, 0, 0], [0, 0, 5], [0, 0, -1]], kind="rapid"),
        _run(feed_nodes),
        Dwell(line=9, seconds=0.5, position=feed_nodes[-1]),
        _run([[0, 10, -1], [0, 10, 5]], kind="rapid"),
        Stop(line=12, code="M2", position=np.array([0, 10, 5.0])),
    )
    prog = Program("t.ngc", "XYZ", items, np.zeros(3), 12)
    res = fit_program(prog, FitSettings())
    assert isinstance(res, FitResult)
    kinds = [type(it).__name__ + ("-rapid" if isinstance(it, Path) and it.rapid else "") for it in res.items]
    # two rapid moves, one feed path (its 90° corners are blended), dwell, one rapid, stop
    assert kinds == ["Path-rapid", "Path-rapid", "Path", "Dwell", "Path-rapid", "Stop"]
    stops = fit_program(prog, FitSettings(blend_corners=False))
    assert sum(isinstance(it, Path) and not it.rapid for it in stops.items) == 3  # corners stop
    paths = [it for it in res.items if isinstance(it, Path)]
    for a, b in zip(res.items[:-1], res.items[1:]):
        if isinstance(a, Path) and isinstance(b, Path):
            assert np.array_equal(a.end, b.start)
    for p in paths:
        assert all_finite(p)
        if p.rapid:
            assert p.n_seg == 1 and np.all(p.coef[0, 2:] == 0)
            assert np.isinf(p.feed_mm_s).all()
    st = fit_statistics(res)
    assert st["nodes_in"] == 4 and st["rapid_moves"] == 3 and st["within_tolerance"]
    assert "continuity" in st and st["paths"] == 4
    text = format_statistics(st)
    assert "segments out" in text and "max node deviation" in text


def test_corner_threshold_splits_or_rounds():
    sq = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0], [0, 0, 0.0]])
    split = fit_run(_run(sq), FitSettings(corner_deg=30, blend_corners=False))
    assert len(split) == 4 and all(p.n_seg == 1 for p in split)
    # blended (the default): one path, a line and a G2 blend per corner, within 1 µm
    (blended,) = fit_run(_run(sq), FitSettings(tol_mm=1e-3, corner_deg=30))
    assert blended.n_seg == 7
    assert distance_to_path(blended, sq).max() <= 1e-3
    tol = 0.01
    rounded = fit_run(_run(sq), FitSettings(tol_mm=tol, corner_deg=120, method="nodes"))
    assert len(rounded) == 1
    assert distance_to_path(rounded[0], sq).max() <= tol
    s = np.linspace(0, rounded[0].length, 4000)
    assert np.all(np.isfinite(rounded[0](s, 3)))


def test_polygon_below_threshold_is_rounded_within_tolerance():
    nodes = _polygon(36)  # 10° turns
    tol = 0.005
    (path,) = fit_run(_run(nodes), FitSettings(tol_mm=tol))
    assert distance_to_path(path, nodes).max() <= tol


def test_g61_exact_lines_stop_at_every_corner_and_merge_collinear():
    nodes = np.array([[0, 0, 0], [5, 0, 0], [10, 0, 0], [15, 1, 0], [20, 2, 0], [25, 4, 0.0]])
    paths = fit_run(_run(nodes, tol=0.0), FitSettings())
    # (0..10 collinear) | 10->15->20 collinear | 20->25
    assert len(paths) == 3
    for p in paths:
        assert p.n_seg == 1
        assert np.all(p.coef[0, 2:] == 0)
    assert_allclose(paths[0].end, [10, 0, 0], atol=1e-12)
    assert_allclose(paths[1].end, [20, 2, 0], atol=1e-12)


def test_g64_p_tolerance_modes():
    rng = np.random.default_rng(3)
    nodes = _polygon(400, R=20, laps=0.75) + np.concatenate([rng.normal(0, 0.01, (301, 2)), np.zeros((301, 1))], 1)
    run = _run(nodes, tol=0.05)
    prog = Program("a", "XYZ", (run,), nodes[0], 1)
    st_strict = fit_statistics(fit_program(prog, FitSettings(tol_mm=0.01, tol_mode="stricter")))
    # the default: G64 P wins where the program gives one
    st_gcode = fit_statistics(fit_program(prog, FitSettings(tol_mm=0.01)))
    # --tol is the user's cap on every move's tolerance
    st_cap = fit_statistics(fit_program(prog, FitSettings.from_options(tol_mm=0.02)))
    assert st_strict["max_node_dev_mm"] <= 0.01
    assert 0.01 < st_gcode["max_node_dev_mm"] <= 0.05
    assert st_gcode["segments_out"] < st_strict["segments_out"]
    assert st_cap["tol_cap_mm"] == 0.02 and st_cap["max_tol_mm"] == 0.02
    assert st_cap["max_node_dev_mm"] <= 0.02 and st_cap["max_path_dev_ratio"] <= 1 + 1e-6
    # nan (G64 without P) takes --tol
    st_nan = fit_statistics(fit_program(Program("a", "XYZ", (_run(nodes),), nodes[0], 1), FitSettings(tol_mm=0.02)))
    assert st_nan["max_node_dev_mm"] <= 0.02


def test_rotary_only_moves_get_their_own_path():
    nodes = np.array([[0, 0, 0, 0], [5, 0, 0, 0], [5, 0, 0, 30], [5, 0, 0, 60], [10, 0, 0, 60.0]])
    paths = fit_run(_run(nodes, axes="XYZA"), FitSettings())
    assert len(paths) == 3
    assert_allclose(paths[1].weights, [0, 0, 0, 1])
    assert paths[1].length == pytest.approx(60.0)
    assert_allclose(paths[0].weights, [1, 1, 1, 0])


def test_duplicate_nodes_are_merged():
    nodes = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 0], [2, 0.1, 0], [2, 0.1, 0], [3, 0.3, 0.0]])
    (p,) = fit_run(_run(nodes), FitSettings(tol_mm=1e-3))
    assert all_finite(p)
    assert distance_to_path(p, nodes).max() <= 1e-3


def test_settings_validation_and_from_options():
    with pytest.raises(UsageError):
        FitSettings(tol_mm=-1)
    with pytest.raises(UsageError):
        FitSettings(tol_mode="loose")
    with pytest.raises(UsageError):
        FitSettings(corner_deg=200)

    class M:
        tol_mm = 0.02
        kinematics, kinematics_params = "trivial", {}
        axes, amax, jmax, dt_s = "XYZAC", [1000.0] * 5, [1e6] * 5, 0.001

    class Trt(M):
        kinematics = "xyzac-trt"

    assert FitSettings.from_options(machine=M()).tol_mm == 0.02
    # rapids blend where they are straight in program space: no kinematics
    assert FitSettings.from_options(machine=M()).blend_rapids
    assert not FitSettings.from_options(machine=Trt()).blend_rapids
    assert not FitSettings.from_options().blend_rapids and not FitSettings().blend_rapids
    assert FitSettings.from_options(machine=M()).tol_cap_mm is None  # a machine's tol is a default
    assert FitSettings.from_options(tol_mm=0.005, machine=M()).tol_mm == 0.005
    assert FitSettings.from_options(tol_mm=0.005, machine=M()).tol_cap_mm == 0.005
    assert FitSettings.from_options(corner_deg=45).corner_deg == 45
    exact = FitSettings.from_options(tol_mm=0.0)
    assert exact.corner_deg == 0.0 and exact.tol_mm > 0
    blocks = np.array([np.nan, 0.0, 0.005, 0.5])  # plain G64, G61, G64 P0.005, G64 P0.5
    assert_allclose(FitSettings(tol_mm=0.01).node_tolerance(blocks), [0.01, 0.0, 0.005, 0.5])
    assert_allclose(FitSettings(tol_mm=0.01, tol_mode="stricter").node_tolerance(blocks), [0.01, 0.0, 0.005, 0.01])
    assert_allclose(FitSettings(tol_mm=0.01, tol_cap_mm=0.02).node_tolerance(blocks), [0.01, 0.0, 0.005, 0.02])
    assert_allclose(FitSettings(tol_mm=0.01, tol_cap_mm=0.0).node_tolerance(blocks), [0, 0, 0, 0])
    # half the printed quantum is added wherever the path is not exact
    assert_allclose(FitSettings(tol_mm=0.01, quantum_mm=0.002).node_tolerance(blocks), [0.011, 0.0, 0.006, 0.501])
    with pytest.raises(UsageError):
        FitSettings(tol_cap_mm=-1.0)


def test_segments_json_is_documented_and_deterministic(tmp_path):
    x = np.linspace(0, 2 * np.pi, 200)
    nodes = np.stack([10 * np.cos(x), np.zeros_like(x), 10 * np.sin(x) * 0.5], axis=1)
    prog = Program("lathe.ngc", "XYZ", (_run(nodes),), nodes[0], 200)
    res = fit_program(prog, FitSettings(method="planar"))
    out1, out2 = tmp_path / "a.json", tmp_path / "b.json"
    write_segments_json(res, str(out1))
    write_segments_json(fit_program(prog, FitSettings(method="planar")), str(out2))
    assert out1.read_bytes() == out2.read_bytes()
    assert not [f for f in os.listdir(tmp_path) if f.endswith(".tmp")]
    doc = json.loads(out1.read_text())
    assert doc["format"] == "cnc-interp-segments" and doc["axes"] == "XYZ"
    seg = doc["items"][0]["segments"][0]
    assert set(seg) >= {"line", "u0", "u1", "coef", "feed_mm_s", "planar"}
    assert len(seg["coef"]) == 3 and len(seg["coef"][0]) == 6
    assert seg["planar"]["plane"] == "XZ" and len(seg["planar"]["p"]) == 6
    # the planar extras reproduce the power-basis coefficients
    pl = seg["planar"]
    x_ = np.linspace(0, pl["x_end"], 5)
    p = np.polynomial.polynomial.polyval(x_, pl["p"])
    qh = pl["origin"][0] + x_ * np.cos(pl["theta_rad"]) - p * np.sin(pl["theta_rad"])
    assert_allclose(np.polynomial.polynomial.polyval(x_, seg["coef"][0]), qh, atol=1e-12)
    assert segments_document(res)["version"] == 1


def test_cli_fit_on_samples(tmp_path):
    from click.testing import CliRunner

    from cnc_interp.cli import main

    files = sorted(f for f in os.listdir(SAMPLES) if f.endswith(".ngc"))
    assert files
    runner = CliRunner()
    for f in files:
        out = tmp_path / (f + ".json")
        m = ["-m", "mikron-ucp710"] if f == "five-axis-xyzac.ngc" else []  # not an XYZ part
        r = runner.invoke(main, ["fit", os.path.join(SAMPLES, f), "--json", "-o", str(out), *m])
        assert r.exit_code == 0, (f, r.output)
        st = json.loads(r.output)
        assert st["within_tolerance"], f
        # (a sample's G64 P may allow more than the default tolerance)
        assert st["max_node_dev_mm"] <= max(st["tol_mm"], st["max_tol_mm"]) * (1 + 1e-9)
        assert st["max_path_dev_ratio"] <= 1 + 1e-6
        assert json.loads(out.read_text())["format"] == "cnc-interp-segments"
    r = runner.invoke(main, ["fit", os.path.join(SAMPLES, files[0]), "--tol", "0.01"])
    assert r.exit_code == 0 and "segments out" in r.output


def test_rapids_along_one_line_are_one_path_and_plan_without_stopping():
    # G91 repeats of one G0 (and Z5 then Z10): one straight rapid path each chain, no
    # stop between their moves; a turn or a reversal starts a new path
    from cnc_interp.machine.load import load_machine
    from cnc_interp.plan.settings import PlanSettings
    from cnc_interp.plan.timeline import plan_program

    steps = [[0.5 * k, 0.125 * k, 0.0] for k in range(21)]
    nodes = steps + [[10.0, 2.5, 5.0], [10.0, 2.5, 7.0], [10.0, 2.5, 10.0], [10.0, 2.5, 2.0], [0.0, 0.0, 2.0]]
    prog = Program("t.ngc", "XYZ", (_run(nodes, kind="rapid"),), np.zeros(3), len(nodes))
    fitted = fit_program(prog, FitSettings())
    paths = [it for it in fitted.items if isinstance(it, Path)]
    # the 20 steps; Z0 -> Z5 -> Z7 -> Z10; Z down (a reversal); home
    assert len(paths) == 4 and all(p.rapid for p in paths)
    assert paths[0].length == pytest.approx(20 * np.hypot(0.5, 0.125), rel=1e-12)
    assert paths[1].length == pytest.approx(10.0, rel=1e-12)
    assert np.array_equal(paths[0].end, nodes[20]) and np.array_equal(paths[1].end, nodes[23])
    for a, b in zip(paths[:-1], paths[1:]):
        assert np.array_equal(a.end, b.start)
    # planned: the chain of twenty moves takes as long as one move of its length
    m = load_machine("generic-mill")
    one = Program("t.ngc", "XYZ", (_run([nodes[0], nodes[20]], kind="rapid"),), np.zeros(3), 2)
    settings = PlanSettings.from_options(machine=m)
    single = plan_program(fit_program(one, FitSettings()), m, settings)
    chained = plan_program(fitted, m, settings)

    def arrival(traj):
        return int(np.flatnonzero(np.all(traj.q == nodes[20], axis=1))[0])

    assert arrival(chained) == arrival(single)


def _kinked_rapids(tol=np.nan, turn_deg=None):
    """long-kink.ngc in mm: G0 X25.4, G0 X25.654 Y0.0254 (a 5.7° turn), G0 X50.8; with
    ``turn_deg``, G0 X25.4 and then 25.4 mm turned by that."""
    nodes = [[0.0, 0.0, 0.0], [25.4, 0.0, 0.0], [25.654, 0.0254, 0.0], [50.8, 0.0254, 0.0]]
    if turn_deg is not None:
        a = np.radians(turn_deg)
        nodes = [[0.0, 0.0, 0.0], [25.4, 0.0, 0.0], [25.4 * (1 + np.cos(a)), 25.4 * np.sin(a), 0.0]]
    return Program("t.ngc", "XYZ", (_run(nodes, kind="rapid", tol=tol),), np.zeros(3), len(nodes)), np.array(nodes)


def test_rapids_that_turn_gently_are_one_smooth_path_within_the_tolerance():
    prog, nodes = _kinked_rapids()
    blended = fit_program(prog, FitSettings(blend_rapids=True))
    (path,) = blended.paths
    assert path.rapid and np.all(np.isinf(path.feed_mm_s))
    assert np.array_equal(path.start, nodes[0]) and np.array_equal(path.end, nodes[-1])
    # the path passes the kinks within the tolerance, without a stop
    tol = FitSettings().fit_tol_mm
    assert distance_to_path(path, nodes).max() <= tol * (1 + 1e-6)
    assert blended.stats["max_path_dev_mm"] <= tol * (1 + 1e-6)
    stops = fit_program(prog, FitSettings(blend_rapids=False))
    assert len(stops.paths) == 3 and all(p.rapid and p.coef.shape[0] == 1 for p in stops.paths)
    # under G61 the rapids stop at each turn as before
    exact, _ = _kinked_rapids(tol=0.0)
    assert len(fit_program(exact, FitSettings(blend_rapids=True)).paths) == 3
    # a corner sharper than corner_deg stops: Z up, then across
    up = [[0.0, 0.0, 0.0], [0.0, 0.0, 5.0], [30.0, 0.0, 5.0]]
    square = Program("t.ngc", "XYZ", (_run(up, kind="rapid"),), np.zeros(3), 3)
    paths = fit_program(square, FitSettings(blend_rapids=True)).paths
    assert len(paths) == 2 and all(p.rapid and p.coef.shape[0] == 1 for p in paths)


def test_blended_rapids_plan_shorter_within_the_limits():
    from cnc_interp.machine.load import load_machine
    from cnc_interp.plan.settings import PlanSettings
    from cnc_interp.plan.timeline import plan_program
    from cnc_interp.plan.verify import verify

    m = load_machine("generic-mill")
    for deg in (5.7, 29.0):  # up to corner_deg, the smooth path beats two lines and a stop
        prog, nodes = _kinked_rapids(turn_deg=deg)
        periods = {}
        for blend in (True, False):
            fitted = fit_program(prog, FitSettings(blend_rapids=blend))
            traj = plan_program(fitted, m, PlanSettings.from_options(machine=m))
            rep = verify(traj, m)
            assert rep.ok, rep.format()
            assert np.array_equal(traj.q[-1], nodes[-1])
            periods[blend] = traj.n_samples
        assert periods[True] < periods[False], deg


def test_blended_rapids_on_a_machine_with_kinematics_are_refused():
    from cnc_interp.errors import PlanError
    from cnc_interp.machine.model import Machine
    from cnc_interp.plan.settings import PlanSettings
    from cnc_interp.plan.timeline import plan_program

    five = Machine(
        name="t", axes="XYZAC", vmax=np.full(5, 100.0), amax=np.full(5, 1e3), jmax=np.full(5, 1e4),
        dt_s=0.001, kinematics="xyzac-trt",
    )  # fmt: skip
    nodes = [[0.0, 0, 0, 0, 0], [25.4, 0, 0, 0, 0], [25.654, 0.0254, 0, 0, 0], [50.8, 0.0254, 0, 0, 0]]
    prog = Program("t.ngc", "XYZAC", (_run(nodes, axes="XYZAC", kind="rapid"),), np.zeros(5), 4)
    fitted = fit_program(prog, FitSettings(blend_rapids=True))
    with pytest.raises(PlanError, match="fitted with blends"):
        plan_program(fitted, five, PlanSettings(dt_s=0.001))
    assert FitSettings.from_options(machine=five).blend_rapids is False

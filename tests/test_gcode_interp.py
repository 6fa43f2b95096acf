"""Modal interpreter: moves, runs, units, offsets, path control, dwells and stops."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from cnc_interp.errors import GCodeError, UnsupportedError
from cnc_interp.gcode import Stop

from .conftest import program_of as prog


def all_nodes(p):
    return np.vstack([r.nodes for r in p.runs])


# -- straight moves and runs ----------------------------------------------------------
def test_rapid_then_feed_runs_start_where_the_machine_is():
    p = prog("G21 G90\nG0 X10 Y5\nG1 Z-1 F600\nX20\nG0 Z5\nM2\n")
    r0, r1, r2 = p.runs
    assert (r0.kind, r1.kind, r2.kind) == ("rapid", "feed", "rapid")
    assert_allclose(r0.nodes, [[0, 0, 0], [10, 5, 0]])
    assert_allclose(r1.nodes, [[10, 5, 0], [10, 5, -1], [20, 5, -1]])
    assert_allclose(r2.nodes[0], r1.nodes[-1])
    assert (r0.end_reason, r1.end_reason, r2.end_reason) == ("feed", "rapid", "end")
    assert_allclose(r1.feed_mm_s, [10.0, 10.0, 10.0])  # 600 mm/min
    assert np.all(np.isinf(r0.feed_mm_s))
    assert list(r1.line) == [3, 3, 4]
    assert list(r1.col) == [1, 1, 1]
    assert list(prog("G21\nF60 Y0 G1 X1\n   Y2\n").runs[0].col) == [8, 8, 4]
    assert isinstance(p.items[-1], Stop) and p.items[-1].code == "M2"
    assert p.axes == "XYZ"


def test_incremental_and_absolute_distance():
    p = prog("G91 G1 X1 Y2 F60\nX1\nG90 X0\n")
    assert_allclose(p.runs[0].nodes, [[0, 0, 0], [1, 2, 0], [2, 2, 0], [0, 2, 0]])


def test_inch_units_convert_positions_and_feed_once():
    p = prog("G20 G1 X1 F10\n")
    r = p.runs[0]
    assert_allclose(r.nodes[-1], [25.4, 0, 0])
    assert_allclose(r.feed_mm_s[-1], 10 * 25.4 / 60)


def test_rotary_only_move_feed_is_degrees_per_minute_even_in_inch():
    p = prog("G20 G1 A90 F600\n")
    assert p.axes == "XYZA"
    assert_allclose(p.runs[0].nodes[-1], [0, 0, 0, 90])
    assert_allclose(p.runs[0].feed_mm_s[-1], 10.0)


def test_zero_length_moves_are_dropped_but_counted():
    p = prog("G1 X1 F100\nX1\nX1 Y0\nX2\n")
    assert p.runs[0].n_nodes == 3
    assert p.metadata["zero_length_moves"] == 2
    assert p.metadata["zero_length_lines"] == [2, 3]


def test_start_position_is_nodes_zero():
    p = prog("G0 X1\n", start=np.array([5.0, 6.0, 7.0]))
    assert_allclose(p.start, [5, 6, 7])
    assert_allclose(p.runs[0].nodes, [[5, 6, 7], [1, 6, 7]])


def test_machine_axes_order_and_missing_axis_error():
    p = prog("G0 X1 Z2\n", axes="ZX")
    assert p.axes == "ZX"
    assert_allclose(p.runs[0].nodes[-1], [2, 1])
    with pytest.raises(GCodeError) as ei:
        prog("G0 X1\nG0 Y2\n", axes="XZ")
    assert ei.value.location.line == 2 and ei.value.location.col == 4
    assert "axis Y" in ei.value.message


def test_program_axes_grow_when_a_new_axis_appears_mid_run():
    p = prog("G1 X1 F100\nX2 C30\nX3\n")
    assert p.axes == "XYZC"
    assert_allclose(p.runs[0].nodes, [[0, 0, 0, 0], [1, 0, 0, 0], [2, 0, 0, 30], [3, 0, 0, 30]])


def test_feed_errors():
    with pytest.raises(GCodeError, match="zero or missing feed"):
        prog("G1 X1\n")
    with pytest.raises(GCodeError, match="zero or missing feed"):
        prog("F0 G1 X1\n")
    with pytest.raises(UnsupportedError, match="G95"):
        prog("G95 G1 X1 F1\n")


def test_inverse_time_feed():
    # G93: F is 1/min: a 30 mm move with F2 takes 30 s -> 1 mm/s
    p = prog("G93 G1 X30 F2\nG1 X40 F6\n")
    assert_allclose(p.runs[0].feed_mm_s[1:], [1.0, 1.0])
    with pytest.raises(GCodeError, match="inverse time"):
        prog("G93 G1 X30 F2\nX40\n")


def test_two_motion_codes_in_one_block_is_an_error_with_location():
    with pytest.raises(GCodeError) as ei:
        prog("G21\nG0 G1 X1 F10\n")
    loc = ei.value.location
    assert (loc.line, loc.col) == (2, 4)
    assert "same modal group" in ei.value.message
    assert "t.ngc:2:4: error:" in ei.value.format()


def test_g80_with_a_motion_code_is_accepted():
    p = prog("G0 G80 X1\n")
    assert_allclose(p.runs[0].nodes[-1], [1, 0, 0])


@pytest.mark.parametrize(
    "code,name",
    [
        ("G41 D1", "G41"),
        ("G42", "G42"),
        ("G38.2 Z-1 F10", "G38.2"),
        ("G33 Z-1 K1", "G33"),
        ("G76 P1 Z-1", "G76"),
        ("M98 P100", "M98"),
        ("M99", "M99"),
        ("G95", "G95"),
        ("M66 P0 L0", "M66"),
    ],
)
def test_unsupported_constructs_are_named(code, name):
    with pytest.raises(UnsupportedError) as ei:
        prog(f"G21\n{code}\n")
    assert name in ei.value.message
    assert ei.value.location.line == 2


@pytest.mark.parametrize("code", ["G12", "G5.9", "M200", "G150"])
def test_unknown_codes(code):
    with pytest.raises(GCodeError, match="unknown"):
        prog(f"{code}\n")


def test_noop_codes_are_accepted():
    p = prog("G17 G40 G49 G94 G97 G8 M3 S1000 M8\nG43 H0 M9\nM5 M7 M48\nG0 X1\n")
    assert p.runs[0].n_nodes == 2


def test_axis_words_without_motion_mode():
    with pytest.raises(GCodeError, match="without a motion mode"):
        prog("X1\n")


# -- path control, dwell, stops -----------------------------------------------------
def test_path_control_tolerances_per_node():
    p = prog("G1 X1 F60\nG61 X2\nG64 P0.05 Q0.01 X3\nG64 X4\nG20 G64 P0.001 X5\n")
    r = p.runs[0]
    assert np.isnan(r.tol_mm[1]) and r.tol_mm[2] == 0.0
    assert_allclose(r.tol_mm[3], 0.05)
    assert_allclose(r.naive_tol_mm[3], 0.01)
    assert np.isnan(r.tol_mm[4]) and np.isnan(r.naive_tol_mm[4])
    assert_allclose(r.tol_mm[5], 0.0254)


def test_exact_stop_splits_every_move():
    p = prog("G61.1 G1 X1 F60\nX2\nX3\nG64 X4\nX5\n")
    runs = p.runs
    assert [r.n_nodes for r in runs] == [2, 2, 2, 3]
    assert [r.end_reason for r in runs] == ["exact-stop"] * 3 + ["end"]


def test_dwell_and_stops_split_runs():
    p = prog("G1 X1 F60\nG4 P1.5\nX2\nM0\nX3\nM1\nX4\nT2 M6\nX5\nM30\nX6\n")
    kinds = [type(it).__name__ for it in p.items]
    assert kinds == ["Run", "Dwell", "Run", "Stop", "Run", "Stop", "Run", "Stop", "Run", "Stop"]
    assert [r.end_reason for r in p.runs] == ["dwell", "stop", "stop", "tool-change", "end"]
    assert p.items[1].seconds == 1.5
    assert_allclose(p.items[1].position, [1, 0, 0])
    assert [it.code for it in p.items if isinstance(it, Stop)] == ["M0", "M1", "M6", "M30"]
    # M30 ends the program: X6 is never read
    assert_allclose(p.runs[-1].nodes[-1], [5, 0, 0])


def test_dwell_needs_p():
    with pytest.raises(GCodeError, match="G4"):
        prog("G4\n")


def test_block_order_dwell_before_motion_and_stop_after():
    p = prog("G4 P1 G1 X1 F60 M0\n")
    assert [type(it).__name__ for it in p.items] == ["Dwell", "Run", "Stop"]


# -- offsets --------------------------------------------------------------------------
def test_work_offsets_g10_l2_and_g55():
    p = prog("G10 L2 P2 X100 Y50\nG55 G0 X1 Y1\nG54 G0 X1 Y1\n")
    n = all_nodes(p)
    assert_allclose(n[1], [101, 51, 0])
    assert_allclose(n[-1], [1, 1, 0])


def test_g10_l2_p0_is_the_current_system_and_l20_sets_current_coordinates():
    p = prog("G0 X10\nG10 L20 P0 X0\nG0 X5\nG10 L2 P0 X1\nG0 X0\n")
    n = all_nodes(p)
    assert_allclose(n[2], [15, 0, 0])
    assert_allclose(n[-1], [1, 0, 0])


def test_g92_family():
    p = prog("G0 X10\nG92 X0\nG0 X5\nG92.2\nG0 X5\nG92.3\nG0 X1\nG92.1\nG0 X2\n")
    xs = [row[0] for row in all_nodes(p)]
    # X10; G92 makes it 0 -> X5 = 15; G92.2 off -> 5; G92.3 restores -> 11; G92.1 -> 2
    assert_allclose(sorted(set(np.round(xs, 9))), sorted({0, 10, 15, 5, 11, 2}))
    assert_allclose(p.metadata["final_position"], [2, 0, 0])


def test_g53_machine_coordinates():
    p = prog("G10 L2 P1 X100\nG0 X1\nG53 G0 X1\nG1 X2 F60\n")
    n = all_nodes(p)
    assert_allclose(n[1], [101, 0, 0])
    assert_allclose(p.runs[0].nodes[-1], [1, 0, 0])
    assert_allclose(p.runs[1].nodes[-1], [102, 0, 0])


def test_g28_home_and_g28_1():
    p = prog("G0 X5 Y5\nG28.1\nG0 X10 Y0\nG28\n")
    assert_allclose(p.metadata["final_position"], [5, 5, 0])
    p = prog("#5161=1 #5162=2\nG0 X5 Y5 Z5\nG28 Z10\n")
    assert_allclose(all_nodes(p)[-2:], [[5, 5, 10], [5, 5, 0]])


def test_g30_uses_its_own_home_and_m60_stops():
    p = prog("#5181=7 #5182=8 #5183=9\nG0 X1 Y1 Z1\nG30\nM60\n")
    assert_allclose(p.metadata["final_position"], [7, 8, 9])
    assert isinstance(p.items[-1], Stop) and p.items[-1].code == "M60"
    assert p.runs[-1].end_reason == "stop"


def test_tool_and_coordinate_system_parameters():
    p = prog("T7 M6\nG55\nG0 X#5400 Y#5220\n")
    assert_allclose(p.metadata["final_position"], [7, 2, 0])


def test_parameters_from_the_language_layer():
    p = prog("#1=5\n#<depth>=-2\nG1 X[#1*2] Z#<depth> F[60*2]\n")
    assert_allclose(p.runs[0].nodes[-1], [10, 0, -2])
    assert_allclose(p.runs[0].feed_mm_s[-1], 2.0)


def test_position_and_offset_parameters_are_readable():
    p = prog("G10 L2 P1 X3\nG0 X1 Y2\n#1=#5420\n#2=#5221\nG0 X[#1+#2] Y#5421\n")
    assert_allclose(p.metadata["final_position"], [7, 2, 0])


def test_units_switch_keeps_offsets_physical():
    p = prog("G21 G10 L2 P1 X25.4\nG20\nG0 X1\n")
    assert_allclose(p.metadata["final_position"], [50.8, 0, 0])


@pytest.mark.parametrize(
    "text,letter",
    [
        ("G1 X1 I5 F60\n", "I"),
        ("G0 X1 R2\n", "R"),
        ("G1 X1 Q1 F60\n", "Q"),
        ("G0 X1 L2\n", "L"),
        ("G0 X1 P1\n", "P"),
        ("G1 X1 D1 F60\n", "D"),
        ("G0 X1 H1\n", "H"),
    ],
)
def test_words_no_code_uses_are_errors(text, letter):
    with pytest.raises(GCodeError, match=f"{letter} word with no code") as ei:
        prog(text)
    assert ei.value.location.col == text.index(letter) + 1


def _random_program(rng) -> str:
    lines = ["G21 G90 G17", "G0 X0 Y0 Z5", "G1 Z0 F300"]
    x = y = 0.0
    for k in range(300):
        r = rng.random()
        if r < 0.15:
            # a tangent-ish arc with an exactly representable centre
            i, j = rng.uniform(-3, 3), rng.uniform(-3, 3)
            cx, cy = x + i, y + j
            ang = rng.uniform(-3, 3)
            rad = math.hypot(i, j)
            a0 = math.atan2(y - cy, x - cx)
            ex, ey = cx + rad * math.cos(a0 + ang), cy + rad * math.sin(a0 + ang)
            code = "G3" if rng.random() < 0.5 else "G2"
            lines.append(f"{code} X{ex!r} Y{ey!r} I{i!r} J{j!r}" + (" F500" if k % 7 == 0 else ""))
            x, y = ex, ey
            lines.append("G1")
        elif r < 0.2:
            lines.append(f"G0 Z{rng.uniform(1, 5)!r}")
            lines.append(f"G1 Z0 F{rng.choice([100, 200])}")
        else:
            x += rng.uniform(-1, 1)
            y += rng.uniform(-1, 1)
            z = rng.uniform(-1, 0) if rng.random() < 0.3 else None
            w = f"X{x!r} Y{y!r}" + (f" Z{z!r}" if z is not None else "")
            lines.append(("G1 " if rng.random() < 0.3 else "") + w)
        if rng.random() < 0.05:
            lines.append("G91 G1 X0.5\nG90")
            x += 0.5
    return "\n".join(lines) + "\nM2\n"


@pytest.mark.parametrize("seed", range(5))
def test_fast_and_general_paths_agree(seed):
    """Adding a no-op G94 to every block sends it through the general path: same result."""
    import random

    text = _random_program(random.Random(seed))
    a = prog(text)
    slow = "\n".join((ln + " G94") if ln.strip() and not ln.startswith("M2") else ln for ln in text.split("\n"))
    b = prog(slow)
    assert len(a.items) == len(b.items)
    for ra, rb_ in zip(a.runs, b.runs):
        assert ra.kind == rb_.kind and ra.end_reason == rb_.end_reason
        assert_allclose(ra.nodes, rb_.nodes, rtol=0, atol=0)
        assert_allclose(ra.feed_mm_s, rb_.feed_mm_s)
        assert list(ra.line) == list(rb_.line)
        assert len(ra.curves) == len(rb_.curves)
    assert sum(len(r.curves) for r in a.runs) > 10
    assert np.all(np.isfinite(all_nodes(a)))


def test_coordinate_system_rotation_g10_l2_r():
    # G54 rotated 90 deg about its origin at X10: program +X is machine +Y
    p = prog("G10 L2 P1 X10 R90\nG0 X1 Y0\nG1 X1 Y2 F60\nG91 X1\nG90\n#1=#5420\n#2=#5421\nG0 X#1 Y[#2+1]\n")
    assert_allclose(p.runs[0].nodes[-1], [10, 1, 0], atol=1e-12)
    assert_allclose(p.runs[1].nodes[1:], [[8, 1, 0], [8, 2, 0]], atol=1e-12)
    assert_allclose(p.metadata["final_position"], [7, 2, 0], atol=1e-12)


def test_rotation_with_arcs_and_g92():
    p = prog("G10 L2 P1 R90\nG0 X1 Y0\nG3 X0 Y1 I-1 J0 F60\nG92 X0 Y0\nG0 X1\n")
    arc = [cp.curve for r in p.runs for cp in r.curves][0]
    assert_allclose(arc.center, [0, 0], atol=1e-12)
    assert_allclose(arc.sweep_rad, math.pi / 2)
    assert_allclose(arc.end, [-1, 0, 0], atol=1e-12)
    # after G92 the current point reads 0,0; program +X is machine +Y
    assert_allclose(p.metadata["final_position"], [-1, 1, 0], atol=1e-12)
    with pytest.raises(UnsupportedError, match="rotated"):
        prog("G10 L2 P1 R30\nG0 Z5\nG81 X1 Y1 Z-1 R1 F60\n")


def test_inverse_time_feed_of_a_nearly_rotary_move_uses_the_fitters_metric():
    # X moves 1e-7 mm (below LINEAR_MOTION_MIN_MM) while A turns 4.37 deg: the fitter
    # measures the path in degrees, so the G93 feed must be degrees per second, or the
    # 0.1 s move is planned 4.37e7 times too slowly
    from cnc_interp.gcode import read_program

    p = read_program("G0 X0 A0\nG93 G1 X0.0000001 A-4.37 F600\nM2\n", "t.ngc", axes="XYZA")
    feed = [r for r in p.runs if r.kind == "feed"][0]
    assert feed.feed_mm_s[-1] == pytest.approx(43.7)
    # a real linear move keeps the linear length
    p = read_program("G0 X0 A0\nG93 G1 X0.01 A-4.37 F600\nM2\n", "t.ngc", axes="XYZA")
    feed = [r for r in p.runs if r.kind == "feed"][0]
    assert feed.feed_mm_s[-1] == pytest.approx(0.1)

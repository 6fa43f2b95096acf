"""G2/G3 arcs (planes, IJK/R, turns, helices) and G5/G5.1/G5.2 splines with exact geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from cnc_interp.constants import CURVE_CHORD_TOL_MM
from cnc_interp.errors import GCodeError
from cnc_interp.gcode import Arc, Nurbs
from cnc_interp.gcode.splines import clamped_uniform_knots

from .conftest import program_of as prog


def only_curve(p):
    pieces = [cp for r in p.runs for cp in r.curves]
    assert len(pieces) == 1
    return pieces[0]


def feed_run(p):
    return [r for r in p.runs if r.kind == "feed"][0]


def check_piece_nodes(run, piece, tol=CURVE_CHORD_TOL_MM * 1.01):
    """The piece's nodes lie on the exact curve and its ends match the run's nodes."""
    nodes = run.nodes[piece.first : piece.last + 1]
    c = piece.curve
    if isinstance(c, Arc):
        i, j, _ = c.plane
        rr = np.hypot(nodes[:, i] - c.center[0], nodes[:, j] - c.center[1])
        assert_allclose(
            rr,
            c.radius,
            atol=1e-9 + abs(np.hypot(*(c.start[[i, j]] - c.center)) - np.hypot(*(c.end[[i, j]] - c.center))),
        )
    assert_allclose(nodes[0], run.nodes[piece.first])
    assert_allclose(nodes[-1], c.points(np.array([1.0]))[0] if isinstance(c, Arc) else c.control[-1], atol=1e-9)
    # midpoints of consecutive nodes are within the chord tolerance of the curve
    if isinstance(c, Arc):
        i, j, _ = c.plane
        mid = 0.5 * (nodes[1:] + nodes[:-1])
        sag = c.radius - np.hypot(mid[:, i] - c.center[0], mid[:, j] - c.center[1])
        assert np.all(sag <= tol)


# -- G17 arcs ---------------------------------------------------------------------------
def test_g3_quarter_arc_ijk():
    p = prog("G1 X10 Y0 F600\nG3 X0 Y10 I-10 J0\n")
    run = feed_run(p)
    piece = only_curve(p)
    arc = piece.curve
    assert isinstance(arc, Arc)
    assert arc.plane == (0, 1, 2)
    assert_allclose(arc.center, [0, 0])
    assert_allclose(arc.radius, 10)
    assert_allclose(arc.sweep_rad, math.pi / 2)
    assert_allclose(run.nodes[-1], [0, 10, 0])
    assert piece.last == run.n_nodes - 1 and piece.first == 1
    assert run.n_nodes - 2 >= 4
    check_piece_nodes(run, piece)
    # every node of the arc carries the arc's line and feed
    assert set(run.line[piece.first + 1 :]) == {2}
    assert_allclose(run.feed_mm_s, 10.0)


def test_g2_is_clockwise():
    p = prog("G0 X10\nG2 X0 Y-10 I-10 J0 F60\n")
    arc = only_curve(p).curve
    assert_allclose(arc.sweep_rad, -math.pi / 2)
    mid = arc.points(np.array([0.5]))[0]
    assert_allclose(mid, [10 / math.sqrt(2), -10 / math.sqrt(2), 0], atol=1e-12)


def test_r_format_short_and_long_arc():
    p = prog("G0 X0 Y0\nG2 X10 Y0 R5 F60\n")
    arc = only_curve(p).curve
    assert_allclose(arc.center, [5, 0], atol=1e-9)
    assert_allclose(abs(arc.sweep_rad), math.pi)
    p = prog("G0 X0 Y0\nG3 X10 Y0 R10 F60\n")
    arc = only_curve(p).curve
    assert_allclose(arc.sweep_rad, math.pi / 3)
    assert_allclose(arc.center, [5, math.sqrt(75)])  # CCW, short way: centre above
    p = prog("G0 X0 Y0\nG3 X10 Y0 R-10 F60\n")
    arc = only_curve(p).curve
    assert_allclose(arc.sweep_rad, 2 * math.pi - math.pi / 3)
    assert_allclose(arc.center, [5, -math.sqrt(75)])


def test_full_circle_and_p_turns():
    p = prog("G0 X5 Y0\nG3 X5 Y0 I-5 J0 F60\n")
    arc = only_curve(p).curve
    assert_allclose(arc.sweep_rad, 2 * math.pi)
    p = prog("G0 X5 Y0\nG2 X5 Y0 I-5 J0 P3 F60\n")
    arc = only_curve(p).curve
    assert_allclose(arc.sweep_rad, -6 * math.pi)
    run = feed_run(p)
    # three turns: the node count covers 6 pi at the arc's density
    assert run.n_nodes > 3 * 72


def test_helix_pitch_is_linear_in_the_normal_axis():
    p = prog("G0 X3 Y0 Z0\nG3 X3 Y0 Z-6 I-3 J0 P3 F60\n")
    run = feed_run(p)
    arc = only_curve(p).curve
    ang = np.unwrap(np.arctan2(run.nodes[:, 1], run.nodes[:, 0]))
    # dz / dangle = -6 / (6 pi): 1 mm per 180 deg
    slope = np.polyfit(ang - ang[0], run.nodes[:, 2], 1)[0]
    assert_allclose(slope, -6 / (6 * math.pi), rtol=1e-9)
    assert_allclose(run.nodes[-1], [3, 0, -6])
    assert_allclose(arc.points(np.array([0.5]))[0], [-3, 0, -3], atol=1e-12)


def test_absolute_arc_centres_g90_1_use_work_offsets():
    p = prog("G10 L2 P1 X100\nG90.1 G0 X10 Y0\nG3 X0 Y10 I0 J0 F60\n")
    arc = only_curve(p).curve
    assert_allclose(arc.center, [100, 0])
    p = prog("G91.1 G0 X10 Y0\nG3 X0 Y10 I-10 J0 F60\n")
    assert_allclose(only_curve(p).curve.center, [0, 0])


def test_arc_end_point_off_the_circle_is_an_error():
    with pytest.raises(GCodeError) as ei:
        prog("G0 X10 Y0\nG3 X0 Y10.5 I-10 J0 F60\n")
    assert ei.value.location.line == 2
    assert "not on the circle" in ei.value.message
    with pytest.raises(GCodeError, match="too small"):
        prog("G0 X0 Y0\nG2 X10 Y0 R4 F60\n")
    with pytest.raises(GCodeError, match="R and I/J/K"):
        prog("G2 X10 Y0 R5 I5 F60\n")
    with pytest.raises(GCodeError, match="K word"):
        prog("G2 X10 Y0 I5 K1 F60\n")


def test_arc_inch_units():
    p = prog("G20 G0 X1 Y0\nG3 X0 Y1 I-1 J0 F10\n")
    arc = only_curve(p).curve
    assert_allclose(arc.radius, 25.4)
    assert_allclose(feed_run(p).nodes[-1], [0, 25.4, 0])


# -- other planes --------------------------------------------------------------------------
def test_g18_arc_direction_follows_rs274ngc():
    # G18 is the Z-X plane: G2 is clockwise looking from +Y, i.e. from +X towards +Z
    # around a centre at the origin, starting at X1 Z0.
    p = prog("G18 G0 X1 Z0\nG2 X0 Z1 I-1 K0 F60\n")
    arc = only_curve(p).curve
    assert arc.plane == (2, 0, 1)
    assert_allclose(arc.sweep_rad, -math.pi / 2)
    mid = arc.points(np.array([0.5]))[0]
    assert_allclose(mid, [math.sqrt(0.5), 0, math.sqrt(0.5)], atol=1e-12)
    # G3 between the same points goes the long way round (through X<0 or Z<0)
    p = prog("G18 G0 X1 Z0\nG3 X0 Z1 I-1 K0 F60\n")
    arc = only_curve(p).curve
    assert_allclose(arc.sweep_rad, 3 * math.pi / 2)
    assert np.min(feed_run(p).nodes[:, 2]) < -0.99


def test_g19_arc_and_helix_on_x():
    p = prog("G19 G0 Y1 Z0\nG3 Y0 Z1 J-1 K0 X2 F60\n")
    arc = only_curve(p).curve
    assert arc.plane == (1, 2, 0)
    assert_allclose(arc.sweep_rad, math.pi / 2)
    assert_allclose(arc.points(np.array([0.5]))[0], [1, math.sqrt(0.5), math.sqrt(0.5)])


def test_xz_lathe_machine_g18_arc():
    p = prog("G18 G0 X6 Z-10\nG2 X9 Z-13 I3 K0 F60\n", axes="XZ")
    assert p.axes == "XZ"
    arc = only_curve(p).curve
    assert arc.plane == (1, 0, -1)
    assert_allclose(feed_run(p).nodes[-1], [9, -13])
    assert_allclose(arc.sweep_rad, -math.pi / 2)


# -- splines ----------------------------------------------------------------------------
def _cox_de_boor(u, knots, k, i):
    """B-spline basis N_{i,k} (order k) by the textbook recursion (closed interval end)."""
    if k == 1:
        last = knots[-1]
        if knots[i] <= u < knots[i + 1] or (u == last and knots[i] < knots[i + 1] == last):
            return 1.0
        return 0.0
    out = 0.0
    if knots[i + k - 1] > knots[i]:
        out += (u - knots[i]) / (knots[i + k - 1] - knots[i]) * _cox_de_boor(u, knots, k - 1, i)
    if knots[i + k] > knots[i + 1]:
        out += (knots[i + k] - u) / (knots[i + k] - knots[i + 1]) * _cox_de_boor(u, knots, k - 1, i + 1)
    return out


def test_linuxcnc_knot_vector():
    assert_allclose(clamped_uniform_knots(7, 4), [0, 0, 0, 0, 1, 2, 3, 4, 4, 4, 4])
    assert_allclose(clamped_uniform_knots(3, 3), [0, 0, 0, 1, 1, 1])
    assert_allclose(clamped_uniform_knots(5, 3), [0, 0, 0, 1, 2, 3, 3, 3])


def test_g5_2_nurbs_first_control_point_is_the_current_position():
    text = "G0 X10 Y0 Z1\nF600\nG5.2 P1 L4\nX22 Y20 P1\nX13 Y9 P2\nX10 Y22 P1\nX7 Y9 P2\nX-2 Y20 P1\nX10 Y0 P1\nG5.3\n"
    p = prog(text)
    piece = only_curve(p)
    c = piece.curve
    assert isinstance(c, Nurbs)
    assert c.order == 4
    assert_allclose(c.control[:, :2], [[10, 0], [22, 20], [13, 9], [10, 22], [7, 9], [-2, 20], [10, 0]])
    assert_allclose(c.control[:, 2], 1.0)  # Z stays where it was
    assert_allclose(c.weights, [1, 1, 2, 1, 2, 1, 1])
    assert_allclose(c.knots, [0, 0, 0, 0, 1, 2, 3, 4, 4, 4, 4])
    # independent rational evaluation at a few parameters
    for u in (0.3, 1.7, 2.5, 3.9):
        bas = np.array([_cox_de_boor(u, list(c.knots), 4, i) for i in range(7)])
        wb = bas * c.weights
        expect = (wb[:, None] * c.control).sum(axis=0) / wb.sum()
        assert_allclose(c.points(np.array([u]))[0], expect, atol=1e-12)
    run = feed_run(p)
    assert_allclose(run.nodes[-1], [10, 0, 1])
    assert piece.first == 0 and piece.last == run.n_nodes - 1
    # the sampled nodes lie on the curve (dense parameter search for each node)
    uu = np.linspace(0, 4, 40001)
    dense = c.points(uu)
    for node in run.nodes[::17]:
        assert np.min(np.hypot(*(dense[:, :2] - node[:2]).T)) < 2e-3


def test_g5_2_nodes_carry_the_g5_2_line_like_the_curve():
    # the run's nodes, the curve piece and so the fit and the plan all name the G5.2 block
    p = prog("G0 X10 Y0\nF600\nG5.2 P1 L3\n  X22 Y20 P1\n  X13 Y9 P2\n  X10 Y0 P1\nG5.3\n")
    piece = only_curve(p)
    run = feed_run(p)
    assert piece.curve.line == 3
    assert set(run.line[piece.first + 1 : piece.last + 1].tolist()) == {3}
    assert set(run.col[piece.first + 1 : piece.last + 1].tolist()) == {1}


def test_g5_2_default_order_and_weight_on_the_first_line():
    p = prog("F60\nG5.2 X0 Y0 P1\nX1 Y1 P1\nX2 Y0 P1\nG5.3\n")
    c = only_curve(p).curve
    assert c.order == 3
    assert c.control.shape[0] == 4  # current position + 3 points (first repeats it)


def test_g5_2_errors():
    with pytest.raises(GCodeError, match="G5.3") as ei:
        prog("F60\nG5.2 P1 L3\nX1 Y1 P1\nX2 Y0 P1\nM2\n")
    assert ei.value.location.line == 2
    with pytest.raises(GCodeError, match="G5.3"):
        prog("F60\nG5.2 P1 L3\nX1 Y1 P1\nX2 Y0 P1\n")
    with pytest.raises(GCodeError, match="positive weight"):
        prog("F60\nG5.2\nX1 Y1\nX2 Y0 P1\nG5.3\n")
    with pytest.raises(GCodeError, match="both X and Y"):
        prog("F60\nG5.2\nX1 P1\nG5.3\n")
    with pytest.raises(GCodeError, match="fewer than its order"):
        prog("F60\nG5.2 L5\nX1 Y1 P1\nX2 Y0 P1\nG5.3\n")
    with pytest.raises(GCodeError, match="without an open"):
        prog("G5.3\n")


def test_g5_2_in_the_zx_plane():
    p = prog("G18 F60\nG0 Z0 X0\nG5.2 P1 L3\nZ0 X1 P1\nZ2 X2 P1\nZ2 X0 P1\nZ0 X0 P2\nG5.3\n")
    c = only_curve(p).curve
    assert_allclose(c.control[:, [2, 0]], [[0, 0], [0, 1], [2, 2], [2, 0], [0, 0]])


def test_g5_cubic_and_g5_1_quadratic_beziers():
    p = prog("G1 X0 Y0 F60\nG5 I1 J2 P-1 Q2 X4 Y0\n")
    c = only_curve(p).curve
    # P0 = (0,0), P1 = (1,2), P2 = end + (P,Q) = (3,2), P3 = (4,0); midpoint (P0+3P1+3P2+P3)/8
    assert_allclose(c.points(np.array([0.5]))[0][:2], [2.0, 1.5])
    p = prog("G1 X0 Y0 F60\nG5.1 I2 J2 X4 Y0\n")
    c = only_curve(p).curve
    assert_allclose(c.points(np.array([0.5]))[0][:2], [2.0, 1.0])
    # a G5 without I/J continues the previous G5's end tangent
    p = prog("G1 X0 Y0 F60\nG5 I1 J2 P-1 Q2 X4 Y0\nG5 P-1 Q-2 X8 Y0\n")
    pieces = [cp for r in p.runs for cp in r.curves]
    assert_allclose(pieces[1].curve.control[1][:2], [5, -2])
    with pytest.raises(GCodeError, match="follow another G5"):
        prog("G1 X0 Y0 F60\nG5 P-1 Q2 X4 Y0\n")
    with pytest.raises(GCodeError, match="XY plane"):
        prog("G18 G1 X0 Y0 F60\nG5.1 I1 J1 X2 Y0\n")


def test_huge_curves_are_errors_not_hangs():
    with pytest.raises(GCodeError, match="too large"):
        prog("G0 X1000000\nG3 I-1000000 J0 P9000 F60\n")
    with pytest.raises(GCodeError, match="too large"):
        prog(
            "G0 X0\nF60 G5.2 P1 L3\nX1000000000000 Y1000000000000 P1\n"
            "X-1000000000000 Y1000000000000 P0.000000001\nX0 Y1 P1000000000\nG5.3\n"
        )


def test_arc_nodes_survive_a_new_axis_later_in_the_run():
    p = prog("G1 X1 Y0 F100\nG3 X0 Y1 I-1 J0\nG1 C30\nG2 X1 Y0 I0 J-1\n")
    assert p.axes == "XYZC"
    run = feed_run(p)
    for piece in run.curves:
        check_piece_nodes(run, piece)
    first, second = run.curves
    assert np.all(run.nodes[first.first : first.last + 1, 3] == 0.0)
    assert np.all(run.nodes[second.first : second.last + 1, 3] == 30.0)
    assert first.curve.plane == (0, 1, 2)

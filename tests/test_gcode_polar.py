"""Polar coordinates: @ (distance) and ^ (angle, degrees) in the XY plane, LinuxCNC semantics
(``find_ends`` for moves, ``CYCLE_MACRO`` for canned-cycle repeats)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from cnc_interp.errors import GCodeError

from .conftest import program_of as prog
from .test_gcode_interp_cycles import moves


def ends(text: str, **kw) -> np.ndarray:
    """End points (n, 3) of every move of ``text``."""
    return np.array([p for k, p in moves(prog(text, **kw)) if k != "dwell"])


def test_absolute_polar_moves():
    e = ends("G1 F100 @10 ^30\n^120\n@5\n")
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    assert_allclose(e[0], [10 * c, 10 * s, 0], atol=1e-9)
    # ^ alone keeps the distance, @ alone keeps the angle
    assert_allclose(e[1], [10 * math.cos(math.radians(120)), 10 * math.sin(math.radians(120)), 0], atol=1e-9)
    assert_allclose(e[2], [5 * math.cos(math.radians(120)), 5 * math.sin(math.radians(120)), 0], atol=1e-9)


def test_incremental_angle_steps_a_square():
    # LinuxCNC's documentation example: only the angle is incremental, so the four
    # points lie on one circle of radius 0.5 (inch)
    e = ends("G20 F100 G1 @.5 ^90\nG91 ^90\n^90\n^90\n^90\n")
    r = np.hypot(e[:, 0], e[:, 1])
    assert_allclose(r, 12.7, atol=1e-9)
    angles = np.degrees(np.arctan2(e[:, 1], e[:, 0])) % 360
    assert_allclose(angles, [90, 180, 270, 0, 90], atol=1e-9)


def test_incremental_distance_and_angle_step_together():
    # a spiral: each block shrinks the distance, then turns (sam-circle_lines.ngc)
    e = ends("G0 X10 Y0\nG91 G1 F100 @-1 ^90\n@-1 ^90\n")
    assert_allclose(e[1], [0, 9, 0], atol=1e-9)
    assert_allclose(e[2], [-8, 0, 0], atol=1e-9)


def test_polar_origin_is_the_program_origin():
    # G92 shifts the program origin; polar coordinates measure from it
    e = ends("G0 X100 Y100\nG92 X0 Y0\nG1 F100 @10 ^0\n")
    assert_allclose(e[-1], [110, 100, 0], atol=1e-9)


def test_bolt_hole_circle_with_repeated_cycle():
    # examples/hole-circle.ngc: six holes at 60 degree steps on a 3 inch circle
    e = ends("G20 G17 G90\nG0 X1.5 Y0 Z0\nG91 G81 R.1 Z-.5 ^60 L6 F10\nM2\n")
    holes = e[np.isclose(e[:, 2], 2.54 - 12.7)]  # R 0.1 in above Z0, bottom 0.5 in below R
    assert len(holes) == 6
    assert_allclose(np.hypot(holes[:, 0], holes[:, 1]), 38.1, atol=1e-9)
    angles = np.degrees(np.arctan2(holes[:, 1], holes[:, 0])) % 360
    assert_allclose(np.sort(angles), [0, 60, 120, 180, 240, 300], atol=1e-9)


def test_absolute_polar_cycle_places_one_hole():
    e = ends("G0 X0 Y0 Z5\nG90 G81 @20 ^90 R1 Z-2 F60\n")
    holes = e[np.isclose(e[:, 2], -2)]
    assert_allclose(holes, [[0, 20, -2]], atol=1e-9)


def test_polar_arc_end_point():
    # a half circle about the origin with its end given in polar form
    e = ends("G0 X10 Y0\nG3 @10 ^180 I-10 J0 F100\n")
    assert_allclose(e[-1], [-10, 0, 0], atol=1e-9)


@pytest.mark.parametrize(
    "text, message",
    [
        ("G1 F100 @1 X2\n", "X word"),
        ("G18 G1 F100 @1 ^0\n", "G17"),
        ("G91 G1 F100 ^10\n", "origin"),
        ("G1 F100 @5\n", "angle"),
        ("G92 @1 ^0\n", "G92"),
        ("G53 G0 @1 ^0\n", "G53"),
        ("@1 ^0\n", "motion mode"),
    ],
)
def test_polar_errors_name_the_problem(text, message):
    with pytest.raises(GCodeError, match=message) as exc:
        prog(text)
    assert exc.value.location.line == 1


def test_polar_needs_x_and_y_on_the_machine():
    with pytest.raises(GCodeError, match="axis"):
        prog("G1 F100 @1 ^0\n", axes="XZ")


# -- arcs in G18/G19 under a rotated coordinate system (G10 L2 R) ---------------------


@pytest.mark.parametrize("rot_deg", [90.0, 60.0, -135.0])
def test_yz_arc_under_rotation_is_the_rotated_circle(rot_deg):
    # a half circle in the program's YZ plane about program (0, 0, 0), radius 5
    text = f"G10 L2 P0 R{rot_deg}\nG0 X0 Y5 Z0\nG19 G3 Y-5 Z0 J-5 K0 F100\n"
    p = prog(text)
    feed = [r for r in p.runs if r.kind == "feed"][0]
    pts = feed.nodes  # machine X, Y, Z
    c, s = math.cos(math.radians(rot_deg)), math.sin(math.radians(rot_deg))
    normal = np.array([c, s, 0.0])  # the program's X axis in the machine frame
    assert_allclose(np.linalg.norm(pts, axis=1), 5.0, atol=1e-9)
    assert_allclose(pts @ normal, 0.0, atol=1e-9)
    # starts at program Y=5, ends at program Y=-5 (machine: along the rotated Y axis)
    y_axis = np.array([-s, c, 0.0])
    assert_allclose(pts[0], 5 * y_axis, atol=1e-9)
    assert_allclose(pts[-1], -5 * y_axis, atol=1e-12)
    # G3 in G19 turns counter-clockwise seen from +X: Y -> Z -> -Y, so Z rises first
    assert pts[len(pts) // 2, 2] > 4.9


def test_xz_arc_under_rotation_keeps_its_length():
    # LinuxCNC's arc-feed/full_xz.ngc shape: 270 degree arc, inverse time feed from its length
    text = "G10 L2 P0 X-2 Y1 R60\nG0 X0 Y0 Z0\nG0 Y1.5 Z.5\nG18 G93 G2 X1 Z1.5 I1 F60\n"
    p = prog(text)
    feed = [r for r in p.runs if r.kind == "feed"][0]
    length = float(np.linalg.norm(np.diff(feed.nodes, axis=0), axis=1).sum())
    # radius 1 about program (X1, Z0.5): from X0 Z0.5 clockwise seen from +Y to X1 Z1.5
    assert length == pytest.approx(1.5 * math.pi, rel=2e-4)  # the chords of the sampled nodes
    assert_allclose(
        np.linalg.norm(np.diff(feed.nodes, axis=0), axis=1).max(), 1.5 * math.pi / (len(feed.nodes) - 1), rtol=1e-3
    )
    # G93 F60: the move takes 1 s, so the feed is the arc's length per second
    assert feed.feed_mm_s[-1] == pytest.approx(1.5 * math.pi, rel=1e-6)


def test_a_rotated_arc_under_g61_does_not_stop_at_its_own_nodes():
    # the arc's sampled nodes are no corners: G61 (exact path) keeps tolerance 0 at the
    # block's end only, and the whole arc plans without a stop inside it
    from cnc_interp import api

    text = "G21 G90 G61\nG10 L2 P0 R60\nG0 X0 Y5 Z0\nG19 G3 Y-5 Z0 J-5 K0 F1200\nG1 X5\nM2\n"
    feed = [r for r in prog(text).runs if r.kind == "feed"][0]
    # node 0 is the start; the exact-path zeros are the arc's end and the G1's
    zeros = np.flatnonzero(feed.tol_mm[1:] == 0.0) + 1
    assert zeros.tolist() == [len(feed.tol_mm) - 2, len(feed.tol_mm) - 1]
    res = api.run(text, machine="generic-mill")
    speed = np.linalg.norm(np.diff(res.trajectory.q, axis=0), axis=1) / res.trajectory.dt_s
    # the half circle (~15.7 mm at 20 mm/s) holds its feed after the start: no stop inside
    moving = np.flatnonzero(speed > 0)
    arc_run = speed[moving[0] : moving[0] + int(0.6 / res.trajectory.dt_s)]
    assert arc_run[int(0.2 / res.trajectory.dt_s) :].min() > 0.5 * 20.0

"""Canned cycles G81 G82 G83 G73 G85 G89 expanded into moves (LinuxCNC semantics)."""

from __future__ import annotations

import numpy as np
import pytest

from cnc_interp.errors import GCodeError
from cnc_interp.gcode import Dwell, Run

from .conftest import program_of as prog


def moves(p):
    """[(kind, end point)] of every move, dwells as ("dwell", seconds)."""
    out = []
    for it in p.items:
        if isinstance(it, Run):
            for k in range(1, it.n_nodes):
                out.append((it.kind, tuple(np.round(it.nodes[k], 9))))
        elif isinstance(it, Dwell):
            out.append(("dwell", it.seconds))
    return out


def test_g81_g98_returns_to_the_initial_level():
    p = prog("G0 X0 Y0 Z10\nG98 G81 X5 Y5 Z-2 R1 F60\nX8\nG80\n")
    assert moves(p)[1:] == [
        ("rapid", (5, 5, 10)),
        ("rapid", (5, 5, 1)),
        ("feed", (5, 5, -2)),
        ("rapid", (5, 5, 10)),
        ("rapid", (8, 5, 10)),
        ("rapid", (8, 5, 1)),
        ("feed", (8, 5, -2)),
        ("rapid", (8, 5, 10)),
    ]
    # cycles run as exact path
    feed = [r for r in p.runs if r.kind == "feed"][0]
    assert np.all(feed.tol_mm[1:] == 0.0)


def test_g81_g99_returns_to_r():
    p = prog("G0 X0 Y0 Z10\nG99 G81 X5 Y5 Z-2 R1 F60\nX8\n")
    assert moves(p)[1:] == [
        ("rapid", (5, 5, 10)),
        ("rapid", (5, 5, 1)),
        ("feed", (5, 5, -2)),
        ("rapid", (5, 5, 1)),
        ("rapid", (8, 5, 1)),
        ("feed", (8, 5, -2)),
        ("rapid", (8, 5, 1)),
    ]


def test_below_r_first_rapids_up_to_r():
    p = prog("G0 X0 Y0 Z-1\nG98 G81 X5 Z-3 R2 F60\n")
    assert moves(p)[1:] == [("rapid", (0, 0, 2)), ("rapid", (5, 0, 2)), ("feed", (5, 0, -3)), ("rapid", (5, 0, 2))]


def test_g82_dwells_at_the_bottom():
    p = prog("G0 Z5\nG82 X1 Z-1 R1 P0.25 F60\n")
    assert moves(p)[1:] == [
        ("rapid", (1, 0, 5)),
        ("rapid", (1, 0, 1)),
        ("feed", (1, 0, -1)),
        ("dwell", 0.25),
        ("rapid", (1, 0, 5)),
    ]


def test_g83_pecks_back_to_r_and_g73_backs_off():
    p = prog("G0 Z5\nG99 G83 X0 Y0 Z-5 R1 Q2.5 F60\n")
    m = moves(p)[1:]
    assert m == [
        ("rapid", (0, 0, 1)),
        ("feed", (0, 0, -1.5)),
        ("rapid", (0, 0, 1)),
        ("rapid", (0, 0, -1.246)),
        ("feed", (0, 0, -4)),
        ("rapid", (0, 0, 1)),
        ("rapid", (0, 0, -3.746)),
        ("feed", (0, 0, -5)),
        ("rapid", (0, 0, 1)),
    ]
    p = prog("G0 Z5\nG99 G73 X0 Y0 Z-5 R1 Q2.5 F60\n")
    m = moves(p)[1:]
    assert m == [
        ("rapid", (0, 0, 1)),
        ("feed", (0, 0, -1.5)),
        ("rapid", (0, 0, -1.246)),
        ("feed", (0, 0, -4)),
        ("rapid", (0, 0, -3.746)),
        ("feed", (0, 0, -5)),
        ("rapid", (0, 0, 1)),
    ]


def test_g85_feeds_out_and_g89_dwells_then_feeds_out():
    p = prog("G0 Z5\nG98 G85 X0 Y0 Z-2 R1 F60\n")
    assert moves(p)[1:] == [("rapid", (0, 0, 1)), ("feed", (0, 0, -2)), ("feed", (0, 0, 1)), ("rapid", (0, 0, 5))]
    p = prog("G0 Z5\nG98 G89 X0 Y0 Z-2 R1 P1 F60\n")
    assert moves(p)[1:] == [("rapid", (0, 0, 1)), ("feed", (0, 0, -2)), ("dwell", 1.0), ("feed", (0, 0, 5))]


def test_incremental_repeats():
    p = prog("G0 X0 Y0 Z10\nG91 G99 G81 X10 Y0 Z-5 R-8 L3 F60\n")
    # R is 8 below the initial level (Z2), the bottom 5 below R (Z-3); holes at X10, 20, 30
    bottoms = [pt for kind, pt in moves(p) if kind == "feed"]
    assert bottoms == [(10, 0, -3), (20, 0, -3), (30, 0, -3)]
    assert moves(p)[-1] == ("rapid", (30, 0, 2))


def test_sticky_r_and_z_and_required_words():
    p = prog("G0 Z5\nG81 X1 Z-1 R1 F60\nY3\nG80\n")
    assert [pt for k, pt in moves(p) if k == "feed"] == [(1, 0, -1), (1, 3, -1)]
    with pytest.raises(GCodeError, match="without R"):
        prog("G0 Z5\nG81 X1 Z-1 F60\n")
    with pytest.raises(GCodeError, match="without Z"):
        prog("G0 Z5\nG81 X1 R1 F60\n")
    with pytest.raises(GCodeError, match="below the hole bottom"):
        prog("G0 Z5\nG81 X1 Z1 R-1 F60\n")
    with pytest.raises(GCodeError, match="Q"):
        prog("G0 Z5\nG83 X1 Z-1 R1 F60\n")
    with pytest.raises(GCodeError, match="feed"):
        prog("G0 Z5\nG81 X1 Z-1 R1\n")
    with pytest.raises(GCodeError, match="inverse time"):
        prog("G0 Z5\nG93 G81 X1 Z-1 R1 F1\n")


def test_g80_cancels_and_axis_words_after_it_need_a_motion():
    with pytest.raises(GCodeError, match="motion mode"):
        prog("G0 Z5\nG81 X1 Z-1 R1 F60\nG80\nX3\n")


def test_g18_cycle_drills_along_y():
    p = prog("G18 G0 X0 Y5 Z0\nG98 G81 Z1 X2 Y-1 R1 F60\n")
    assert moves(p)[1:] == [("rapid", (2, 5, 1)), ("rapid", (2, 1, 1)), ("feed", (2, -1, 1)), ("rapid", (2, 5, 1))]

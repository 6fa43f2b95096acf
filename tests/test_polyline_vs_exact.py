"""Polyline vs exact: a CAM polyline sampled within the tolerance from a smooth
curve (chord error = G64 P, 4 decimals) plans within 2 % of the same curve given exactly.

The default run checks a few cases; ``CNC_POLYLINE_FULL=1`` runs the whole set of
``tests/_polyline_cases.py`` (every case at 1, 5 and 10 µm; about a minute), as
``benchmarks/polyline_vs_exact.py`` does for the README's table.
"""

from __future__ import annotations

import os

import pytest

from ._polyline_cases import CHORD_ERRORS_MM, cases, exact_program, polyline_program

FAST = [("arc-r25", 0.005), ("spiral-nurbs", 0.001), ("5axis-arc", 0.01), ("nurbs-cubic", 0.01)]
FULL = [(c, e) for c in cases() for e in CHORD_ERRORS_MM]


def _plan(tmp_path, name, text):
    from cnc_interp.pipeline import plan_part

    f = tmp_path / f"{name}.ngc"
    f.write_text(text)
    out = plan_part(str(f), "mikron-ucp710")
    assert out.report.ok and out.fit_stats["within_tolerance"]
    return out


def _check(tmp_path, name, chord):
    exact = _plan(tmp_path, "exact", exact_program(name, chord))
    poly = _plan(tmp_path, "poly", polyline_program(name, chord))
    assert poly.trajectory.duration_s <= 1.02 * exact.trajectory.duration_s


@pytest.mark.parametrize("name, chord", FAST)
def test_polyline_plans_within_two_percent_of_the_exact_curve(tmp_path, name, chord):
    _check(tmp_path, name, chord)


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("CNC_POLYLINE_FULL"), reason="set CNC_POLYLINE_FULL=1")
def test_polyline_vs_exact_full_set(tmp_path):
    for name, chord in FULL:
        _check(tmp_path, name, chord)


def test_polyline_sampling_respects_the_chord_error():
    """The test set itself: nodes on the exact curve, chords within the chord error."""
    import numpy as np

    from cnc_interp.fit.curves import CurveEval
    from cnc_interp.gcode import read_program

    chord = 0.005
    prog = read_program(exact_program("arc-r25", chord), source="e.ngc")
    (cp,) = [c for r in prog.runs for c in r.curves]
    poly = read_program(polyline_program("arc-r25", chord), source="p.ngc")
    nodes = [r for r in poly.runs if r.kind == "feed"][0].nodes
    ev = CurveEval(cp.curve)
    pts = ev.points(np.linspace(ev.w0, ev.w1, 200001))
    r = np.linalg.norm(nodes[:, :2], axis=1)
    assert np.abs(r - 25.0).max() <= 0.5e-4 * np.sqrt(2) + 1e-12  # on the circle, to 4 decimals
    # every chord within the chord error (+ rounding) of the circle between its ends
    mid = 0.5 * (nodes[1:, :2] + nodes[:-1, :2])
    sag = 25.0 - np.linalg.norm(mid, axis=1)
    assert sag.max() <= chord + 1e-4 and sag.max() > 0.5 * chord
    assert pts.shape[0] > 0

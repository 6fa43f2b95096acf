"""Printed precision and the program's tolerance: the coordinates' quantum is
detected and half of it added to the tolerance; G64 P sets a move's tolerance, --tol caps."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from cnc_interp.fit import FitSettings, fit_program
from cnc_interp.fit.settings import DEFAULT_TOL_MM
from cnc_interp.fit.quantum import coordinate_quantum
from cnc_interp.gcode import read_program

from .conftest import CORPUS  # noqa: E402


def _circle(decimals: int, units: str = "G21", n: int = 200, r: float = 1.0, extra: str = "") -> str:
    a = np.linspace(0, 2 * np.pi, n + 1)
    fmt = f"{{:.{decimals}f}}"
    body = [f"G1 X{fmt.format(r * np.cos(t))} Y{fmt.format(r * np.sin(t))}{extra}" for t in a[1:]]
    return "\n".join([units + " G90 G64", f"G0 X{fmt.format(r)} Y0", "F1000"] + body + ["M2"]) + "\n"


@pytest.mark.parametrize(
    "text, quantum_mm, label",
    [
        (_circle(4, "G20"), 0.00254, "0.0001 in"),
        (_circle(3), 0.001, "0.001 mm"),
        (_circle(5, r=20.0), 0.00001, "0.00001 mm"),
    ],
)
def test_quantum_of_printed_coordinates(text, quantum_mm, label):
    q = coordinate_quantum(read_program(text, source="c.ngc"))
    assert q["detected_mm"] == pytest.approx(quantum_mm, rel=1e-12)
    assert q["label_mm"] == label and q["quantum_mm"] == pytest.approx(quantum_mm, rel=1e-12)


def test_coarse_or_computed_coordinates_are_exact():
    # 0.01 mm is a hand-written program's precision: detected, but taken as exact
    q = coordinate_quantum(read_program(_circle(2, r=20.0), source="c.ngc"))
    assert q["detected_mm"] == pytest.approx(0.01) and q["quantum_mm"] == 0.0
    # coordinates from expressions fall on no decimal grid
    lines = [
        "G21 G90",
        "G0 X0 Y0",
        "F1000",
        "#1=0",
        "o100 while [#1 LT 40]",
        "G1 X[COS[#1*9]*7] Y[SIN[#1*9]*7]",
        "#1=[#1+1]",
        "o100 endwhile",
        "M2",
    ]
    q = coordinate_quantum(read_program("\n".join(lines) + "\n", source="e.ngc"))
    assert q["quantum_mm"] == 0.0 and q["detected_mm"] == 0.0
    # rotary axes have their own grid
    text = "\n".join(
        ["G21 G90", "G0 X0 Z0 A0", "F1000"] + [f"G1 Z{0.1 * k:.4f} A{1.234 * k:.3f}" for k in range(1, 40)] + ["M2"]
    )
    q = coordinate_quantum(read_program(text + "\n", source="a.ngc", axes="XYZA"))
    assert q["detected_deg"] == pytest.approx(0.001) and q["label_deg"] == "0.001 deg"


def test_fit_adds_half_the_quantum_and_reports_it():
    text = _circle(4, "G20", n=2000, r=1.0)  # 1 in circle in 0.0001 in coordinates
    res = fit_program(read_program(text, source="c.ngc"), FitSettings(tol_mm=0.001))
    st = res.stats
    assert st["quantum"]["quantum_mm"] == pytest.approx(0.00254)
    assert st["fit_tol_mm"] == pytest.approx(0.001 + 0.00127)
    assert st["within_tolerance"] and st["max_path_dev_mm"] <= st["fit_tol_mm"] * (1 + 1e-6)
    # the fit follows the circle, not the rounding: few segments, curvature close to 1/R
    (p,) = [q for q in res.paths if not q.rapid]
    assert p.n_seg < 0.05 * 2000
    s = np.linspace(0.02 * p.length, 0.98 * p.length, 4000)
    kappa = np.linalg.norm(p(s, 2), axis=1)
    assert np.percentile(kappa, 99) < 1.5 / 25.4


def test_fit_cli_reports_tolerance_and_quantum(tmp_path):
    from click.testing import CliRunner

    from cnc_interp.cli import main

    f = tmp_path / "c.ngc"
    f.write_text(_circle(4, "G20", n=400))
    r = CliRunner().invoke(main, ["fit", str(f)])
    assert r.exit_code == 0, r.output
    assert "½ quantum 0.00127 mm (coordinates printed to 0.0001 in)" in r.output
    r = CliRunner().invoke(main, ["fit", str(f), "--json"])
    st = json.loads(r.output)
    assert st["quantum"]["label_mm"] == "0.0001 in"
    assert st["fit_tol_mm"] == pytest.approx(DEFAULT_TOL_MM + 0.00127)


def test_g64_p_sets_the_tolerance_and_tol_caps_it():
    text = _circle(6, n=60, r=20.0).replace("G64", "G64 P0.05")
    prog = read_program(text, source="p.ngc")
    wide = fit_program(prog, FitSettings())  # G64 P0.05 wins over the default
    capped = fit_program(prog, FitSettings.from_options(tol_mm=0.01))  # --tol 0.01 caps it
    assert wide.stats["max_tol_mm"] == pytest.approx(0.05, rel=1e-4)  # (+ ½ of a 1e-6 quantum)
    assert capped.stats["max_tol_mm"] == pytest.approx(0.01, rel=1e-4)
    assert 0.01 < wide.stats["max_path_dev_mm"] <= wide.stats["max_tol_mm"] * (1 + 1e-6)
    assert capped.stats["max_path_dev_mm"] <= capped.stats["max_tol_mm"] * (1 + 1e-6)
    assert wide.stats["segments_out"] < capped.stats["segments_out"]
    # plain G64 keeps the default; G61 is the exact path
    plain = fit_program(read_program(_circle(6, n=60, r=20.0), source="q.ngc"), FitSettings())
    assert plain.stats["max_tol_mm"] == pytest.approx(DEFAULT_TOL_MM, rel=1e-3)


@pytest.mark.corpus
def test_circle_small_segments_plans_near_its_limits_on_the_xyza_machine():
    """A 1-inch circle in 15 µm chords at 0.0001 in, plain G64, F9999, on the
    corpus XYZA machine: 65.9 s when the fit traced the rounding; the circle's
    own limits allow about 2 s."""
    from cnc_interp.pipeline import plan_part

    out = plan_part(
        os.path.join(CORPUS, "performance", "circle_small_segments_ncd.ngc"), os.path.join(CORPUS, "configs", "XYZ.ini")
    )
    assert out.report.ok
    assert out.trajectory.duration_s < 3.0
    assert out.fit_stats["quantum"]["label_mm"] == "0.0001 in"

"""Fit status is an outcome: a fit outside its tolerance is repaired (refit
tighter, blends or stops in the failing stretch, exact lines last) or the command fails
with exit 1 naming the source line; rotary runs fit within both tolerances without
multiplying their segments."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cnc_interp.errors import FitError
from cnc_interp.fit import FitSettings, fit_program
from cnc_interp.gcode import read_program

ROT9 = """G21 G90
G0 X80.248 Z27.058 A223.009
F3000.0
G1A222.679Z27.296
G1A222.240Z27.535
G1A221.691Z27.737
G1A221.031Z27.909
G1A220.043Z28.092
G1A218.505Z28.309
G1A217.736Z28.376
G1A216.967Z28.370
G1A214.989Z28.255
M2
"""

ROT6 = """G21 G90
G0 X4.683 Z20.115 A360
G1 A356.704 Z20.129 F3000
G1 A352.859 Z20.057
G1 A350.662 Z20.000
G1 A3.955 Z20.010
G1 A0 Z20.115
M2
"""


@pytest.mark.parametrize("text", [ROT9, ROT6], ids=["rot9", "rot6"])
def test_rotary_reproducers_fit_within_tolerance_with_exit_0(tmp_path, text):
    from click.testing import CliRunner

    from cnc_interp.cli import main

    f = tmp_path / "r.ngc"
    f.write_text(text)
    r = CliRunner().invoke(main, ["fit", str(f), "-m", "mikron-ucp710", "--json"])
    assert r.exit_code == 0, r.output
    st = json.loads(r.output)
    assert st["within_tolerance"]
    assert st["max_path_dev_ratio"] <= 1 + 1e-6 and st["max_path_dev_rot_ratio"] <= 1 + 1e-6
    # no more segments than a line and a blend per move
    assert st["segments_out"] <= 2 * st["nodes_in"]
    r = CliRunner().invoke(main, ["plan", str(f), "-m", "mikron-ucp710", "-o", str(tmp_path / "p.csv")])
    assert r.exit_code == 0, r.output


def test_a_z_wrap_keeps_at_most_two_segments_per_move():
    """A Vectric-like 4-axis wrap: Z and A together, gentle and sharp turns, 3 decimals."""
    rng = np.random.default_rng(14)
    a = 223.0 - np.cumsum(rng.uniform(0.2, 2.0, 400))
    z = 27.0 + np.cumsum(rng.normal(0, 0.15, 400))
    lines = ["G21 G90", f"G0 X80 Z{z[0]:.3f} A{a[0]:.3f}", "F3000"]
    lines += [f"G1 A{x:.3f} Z{y:.3f}" for x, y in zip(a[1:], z[1:])]
    res = fit_program(read_program("\n".join(lines + ["M2"]) + "\n", source="w.ngc", axes="XYZA"), FitSettings())
    st = res.stats
    assert st["within_tolerance"] and st["max_path_dev_rot_ratio"] <= 1 + 1e-6
    assert st["segments_out"] <= 2 * st["nodes_in"]


def test_a_fit_outside_its_tolerance_fails_with_exit_1_naming_the_line(tmp_path, monkeypatch):
    from click.testing import CliRunner

    import cnc_interp.fit.fitter as fitter
    from cnc_interp.cli import main

    real = fitter._iter_run_raws

    def outside(run, settings, info, threads=1):
        # every path of the pipeline (fit_program and the streaming iter_fit) fits runs here
        yield from real(run, settings, info, threads)
        if run.kind != "rapid":
            info["within_tolerance"] = False
            info["outside_lines"] = [4, 6]

    monkeypatch.setattr(fitter, "_iter_run_raws", outside)
    f = tmp_path / "r.ngc"
    f.write_text(ROT9)
    for cmd in (
        ["fit", str(f), "-m", "mikron-ucp710"],
        ["plan", str(f), "-m", "mikron-ucp710", "-o", str(tmp_path / "p.csv")],
    ):
        r = CliRunner().invoke(main, cmd)
        # (``cli.run`` prints the error's one line and exits with its code)
        assert isinstance(r.exception, FitError) and r.exception.exit_code == 1
        assert r.exception.format().startswith(f"{f}:4:1: error: the fitted path misses the tolerance on lines 4-6")
        assert "within tolerance" not in r.output
    assert not (tmp_path / "p.csv").exists()


def test_repair_is_local_and_reported(monkeypatch):
    """A sub-run whose measured deviation misses: the repair puts blends in its failing
    section (not stops at every node) and the result is within tolerance."""
    import cnc_interp.fit.fitter as fitter

    real = fitter._fit_measured
    calls = {"n": 0}

    def first_misses(pr, sub, settings, evals, tol_share=1.0):
        m = real(pr, sub, settings, evals, tol_share)
        calls["n"] += 1
        if calls["n"] <= 2 and sub.i1 - sub.i0 > 20:  # the fit and its tighter retry
            m.ok = False
        return m

    monkeypatch.setattr(fitter, "_fit_measured", first_misses)
    # the compiled batch fitter measures without ``_fit_measured``: the Python fit only here
    monkeypatch.setattr(fitter._SubRunBatcher, "covers_run", staticmethod(lambda pr, settings: False))
    t = np.linspace(0, np.pi, 121)
    lines = ["G21 G90 G64", "G0 X20 Y0 Z0", "F3000"]
    lines += [f"G1 X{20 * np.cos(x):.4f} Y{20 * np.sin(x):.4f}" for x in t[1:]]
    res = fit_program(read_program("\n".join(lines + ["M2"]) + "\n", source="c.ngc"), FitSettings())
    run = res.stats["runs"][-1]
    assert res.stats["within_tolerance"] and run["repaired"] >= 1
    assert "line-fallback" not in run["methods"]
    assert len([p for p in res.paths if not p.rapid]) == 1  # blends, not stops

"""The public Python API (``cnc_interp``): the documented 5-line use, each stage's
contract, errors as the CLI reports them, and the examples/ scripts."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys

import numpy as np
import pytest
from numpy.testing import assert_allclose

import cnc_interp as ci
from .conftest import EXAMPLES, REPO, SAMPLES


def test_the_documented_five_lines_plan_like_the_cli(tmp_path, cli, monkeypatch):
    # README's and the package docstring's use, exactly (with the sample's path)
    monkeypatch.chdir(tmp_path)
    m = ci.load_machine("generic-mill")
    traj = ci.plan(ci.fit(ci.read_program(os.path.join(SAMPLES, "mill-contour.ngc"), machine=m)), m)
    assert ci.verify(traj, m).ok
    ci.write(traj, "plan.csv")
    r = cli("plan", os.path.join(SAMPLES, "mill-contour.ngc"), "-m", "generic-mill", "-o", "cli.csv", "-q")
    assert r.exit_code == 0, r.output
    # one sequence: the library and `cnc-interp plan` (streamed in windows) write the same bytes
    assert (tmp_path / "plan.csv").read_bytes() == (tmp_path / "cli.csv").read_bytes()


def test_the_stage_packages_are_still_packages():
    # ci.fit / ci.plan are the subpackages made callable (``_stage_call``): imports work
    import cnc_interp.fit.fitter as fitter
    import cnc_interp.plan.vpop as vpop

    assert callable(ci.fit) and callable(ci.plan)
    assert ci.fit.fit_program is fitter.fit_program and vpop.__name__ == "cnc_interp.plan.vpop"


def test_read_program_takes_text_bytes_and_paths_and_the_machine_axes():
    m = ci.load_machine("xz-lathe")
    text = "G18 G21 G90\nG0 X10 Z0\nG1 Z-5 F300\nM2\n"
    a = ci.read_program(text, machine=m)
    b = ci.read_program(text.encode(), m, name="lathe.ngc")
    assert a.axes == b.axes == "XZ" and a.source == "<string>" and b.source == "lathe.ngc"
    with pytest.raises(ci.GCodeError) as ei:
        ci.read_program("G21\nG1 Y5 F100\nM2\n", machine=m)
    # the CLI's one line: FILE:LINE:COL: error: ...
    assert ei.value.format().startswith("<string>:2:") and ei.value.exit_code == 2
    with pytest.raises(ci.UsageError):
        ci.read_program(os.path.join(SAMPLES, "no-such-part.ngc"))


def test_fit_takes_the_tolerance_of_the_machine_the_program_was_read_for(tmp_path):
    toml = tmp_path / "m.toml"
    base = ci.load_machine("generic-mill")
    lines = ['name = "tol"', "dt = 0.001", "tol = 0.05"]
    for i, a in enumerate(base.axes):
        lines += [f"[axes.{a}]", f"vmax = {base.vmax[i]}", f"amax = {base.amax[i]}", f"jmax = {base.jmax[i]}"]
    toml.write_text("\n".join(lines) + "\n")
    m = ci.load_machine(toml)
    assert m.tol_mm == 0.05
    prog = ci.read_program("G21 G90\nG1 X10 F600\nG1 X10 Y10\nG1 X0 Y10\nM2\n", machine=m)
    assert ci.fit(prog).stats["max_tol_mm"] == pytest.approx(ci.fit(prog, machine=m).stats["max_tol_mm"])
    assert ci.fit(prog, tol_mm=0.002).stats["max_tol_mm"] < ci.fit(prog).stats["max_tol_mm"]


def test_run_returns_every_stage_and_plan_keeps_its_limits():
    res = ci.run(os.path.join(SAMPLES, "lathe-profile.ngc"), "xz-lathe", planner="vpop", dt_s=0.002)
    assert res.ok and res.machine.dt_s == 0.002 and res.trajectory.dt_s == 0.002
    assert res.fit.program is res.program and res.settings.planner == "vpop"
    q = res.trajectory.q
    assert np.all(np.isfinite(q))
    assert_allclose(q[0], res.program.start, atol=1e-12)  # rest at the program's start
    assert res.report.worst_ratio <= 1 + 1e-9
    assert set(res.timings_s) == {"parse", "fit", "plan", "verify"}


def test_plan_and_fit_take_typed_settings():
    m = ci.load_machine("generic-mill")
    program = ci.read_program(os.path.join(SAMPLES, "mill-contour.ngc"), machine=m)
    fitted = ci.fit(program, 0.01)
    # settings built by the caller give what the keyword arguments give
    same = ci.fit(program, settings=ci.FitSettings.from_options(tol_mm=0.01, machine=m))
    assert [p.coef.tobytes() for p in same.paths] == [p.coef.tobytes() for p in fitted.paths]
    a = ci.plan(fitted, m, planner="variable", dt_s=0.002)
    b = ci.plan(fitted, m, settings=ci.PlanSettings(planner="variable", dt_s=0.002))
    assert a.dt_s == b.dt_s == 0.002 and np.array_equal(a.q, b.q) and a.settings == b.settings
    # a planner knob reaches the planner: on a machine where the curvature binds, a lower
    # centripetal share is a slower plan
    low = dataclasses.replace(m, amax=m.amax / 50, jmax=m.jmax / 50)
    knob = ci.Paper000Options(curv_accel_share=0.2)
    slow = ci.plan(fitted, low, settings=ci.PlanSettings(planner="variable", paper000=knob))
    assert slow.duration_s > 1.1 * ci.plan(fitted, low, planner="variable").duration_s
    assert slow.settings["options"] == {"curv_accel_share": 0.2}
    # both ways at once is ambiguous
    with pytest.raises(ci.UsageError):
        ci.plan(fitted, m, planner="vpop", settings=ci.PlanSettings())
    with pytest.raises(ci.UsageError):
        ci.fit(program, 0.01, settings=ci.FitSettings())


def test_plan_settings_record_their_knobs_by_the_flat_names():
    # the form stored with every plan (MCAP metadata): no knob set -> no option recorded
    assert ci.PlanSettings().to_dict() == {"planner": "optimal", "dt_s": 0.001, "tol_mm": None, "options": {}}
    s = ci.PlanSettings(
        planner="optimal", optimal=ci.OptimalOptions(route="vpop", compare_s=0.0), vpop=ci.VpopOptions(exact=True)
    )
    assert s.to_dict()["options"] == {"route": "vpop", "compare_s": 0.0, "vpop_exact": True}
    for bad in ({"route": "fastest"}, {"refine_passes": -1}, {"compare_s": float("nan")}, {"chunk_samples": 2.5}):
        with pytest.raises(ci.UsageError):
            ci.OptimalOptions(**bad)


def test_write_chooses_the_format_by_extension(tmp_path):
    res = ci.run(os.path.join(SAMPLES, "mill-contour.ngc"), "generic-mill")
    ci.write(res.trajectory, tmp_path / "p.mcap", machine=res.machine)
    ci.write(res.trajectory, tmp_path / "p.csv")
    from cnc_interp.export.csv_io import read_csv
    from cnc_interp.export.mcap_io import read_mcap

    a, b = read_mcap(str(tmp_path / "p.mcap")), read_csv(str(tmp_path / "p.csv"))
    assert_allclose(a.q, b.q, rtol=0, atol=0)
    assert (tmp_path / "p.mcap").read_bytes()[:8] == b"\x89MCAP0\r\n"


def test_importing_the_package_loads_no_stage():
    code = (
        "import sys, cnc_interp as ci; ci.DEFAULT_PLANNER; "
        "heavy = [m for m in sys.modules if m.split('.')[0] in "
        "('numpy', 'numba', 'scipy', 'matplotlib', 'usb', 'mcap')]; "
        "print(heavy)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True
    ).stdout.strip()
    assert out == "[]"


@pytest.mark.parametrize(
    "script, args, code",
    [
        ("plan_and_plot.py", ["mill-contour.ngc", "generic-mill"], 0),
        # five-axis-xyzac.ngc has an A axis the generic mill lacks: its error line, exit 1
        ("batch_folder.py", [".", "generic-mill"], 1),
    ],
)
def test_examples_run(tmp_path, script, args, code):
    pytest.importorskip("matplotlib")
    argv = [os.path.join(SAMPLES, a) if a != "generic-mill" else a for a in args]
    if script == "plan_and_plot.py":
        argv.append(str(tmp_path))
    else:
        argv[0] = SAMPLES
    r = subprocess.run(
        [sys.executable, os.path.join(EXAMPLES, script), *argv],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=600,
    )
    assert r.returncode == code, r.stdout + r.stderr
    assert "Traceback" not in r.stderr
    if script == "plan_and_plot.py":
        assert (tmp_path / "mill-contour.csv").stat().st_size > 0
        assert (tmp_path / "mill-contour.png").read_bytes()[:4] == b"\x89PNG"
        assert "worst X" in r.stdout or "worst Y" in r.stdout or "worst Z" in r.stdout
    else:
        assert "five-axis-xyzac.ngc:7:4: error: axis A is not on this machine" in r.stdout
        assert "1 program(s) not planned" in r.stdout

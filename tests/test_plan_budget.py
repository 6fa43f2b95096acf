"""A plan that cannot fit in memory is refused before planning, with one clear line."""

from __future__ import annotations

import numpy as np
import pytest

from cnc_interp.errors import PlanError
from cnc_interp.fit import FitSettings, fit_program
from cnc_interp.gcode import read_program
from cnc_interp.plan import budget
from cnc_interp.machine.load import load_machine

LINE = b"G21 G90 G94\nG1 X100 F6000\nM2\n"  # 100 mm at 100 mm/s


def _paths(text, machine):
    prog = read_program(text, source="part.ngc", axes=machine.axes, start=machine.start)
    return fit_program(prog, FitSettings()).paths


def test_min_cycle_time_closed_form():
    m = load_machine("generic-mill")  # X: vmax 200, amax 2000, jmax 50000
    paths = _paths(LINE, m)
    d = 100.0
    expected = max(
        d / 100.0,  # the feed
        d / 200.0,
        2 * np.sqrt(d / 2000.0),
        np.cbrt(32 * d / 50000.0),
    )
    assert budget.min_cycle_time_s(paths, m) == pytest.approx(expected, rel=1e-9)
    # without the machine only the feed counts
    assert budget.min_cycle_time_s(paths) == pytest.approx(1.0, rel=1e-9)
    # a short move is bounded by the jerk limit: (32 d / j)^(1/3)
    short = _paths(b"G21 G90 G94\nG1 X0.001 F6000\nM2\n", m)
    assert budget.min_cycle_time_s(short, m) == pytest.approx(np.cbrt(32 * 0.001 / 50000.0), rel=1e-9)


def test_min_cycle_time_is_below_the_planned_cycle():
    from cnc_interp.plan.settings import PlanSettings
    from cnc_interp.plan.timeline import plan_program

    m = load_machine("generic-mill")
    text = b"G21 G90 G94\nG0 X5 Y5\nG1 X40 Y5 F3000\nG1 X40 Y30\nG2 X20 Y30 I-10 J0\nG1 X10 Y10 F900\nG0 Z5\nM2\n"
    prog = read_program(text, source="part.ngc", axes=m.axes, start=m.start)
    fitted = fit_program(prog, FitSettings())
    traj = plan_program(fitted, m, PlanSettings(dt_s=m.dt_s))
    lb = budget.min_cycle_time_s(fitted.paths, m)
    assert 0.3 * traj.duration_s < lb <= traj.duration_s


def test_budget_refuses_before_planning(monkeypatch, tmp_path):
    from cnc_interp import pipeline

    part = tmp_path / "part.ngc"
    part.write_bytes(LINE)
    monkeypatch.setattr(budget, "available_memory_bytes", lambda: 10_000_000)  # 10 MB

    def no_planning(*a, **k):
        raise AssertionError("planning must not start")

    monkeypatch.setattr("cnc_interp.plan.timeline.plan_program", no_planning)
    with pytest.raises(PlanError) as ei:
        pipeline.plan_part(str(part), "generic-mill", dt_s=1e-6)
    msg = ei.value.format()
    assert msg.startswith(f"{part}: error: planning at dt = 1e-06 s needs at least")
    assert "use a larger --dt" in msg
    # the same program at the machine's dt fits easily
    monkeypatch.undo()
    assert pipeline.plan_part(str(part), "generic-mill").report.ok


def test_budget_passes_without_a_memory_figure(monkeypatch):
    m = load_machine("generic-mill")
    monkeypatch.setattr(budget, "available_memory_bytes", lambda: None)  # unknown: no refusal
    budget.check_sample_budget(_paths(LINE, m), m, 1e-9, "part.ngc")
    with pytest.raises(PlanError):
        budget.check_sample_budget(_paths(LINE, m), m, 1e-9, "part.ngc", available=1000)

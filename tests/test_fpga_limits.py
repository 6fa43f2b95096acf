"""The device's setpoints hold the machine's limits: margin, profile budget, repair, refusal."""

import numpy as np
import pytest

from cnc_interp.constants import FPGA_LIMIT_MARGIN, VERIFY_RATIO_SLACK
from cnc_interp.errors import PlanError
from cnc_interp.fpga.commands import StreamOptions, build_stream, plan_for_stream
from cnc_interp.fpga.fixed import FpgaFormats
from cnc_interp.fpga.limits import device_margin, excess_samples, rounding_budget, with_margin
from cnc_interp.fpga.model import run_program, to_mm
from cnc_interp.fpga.program import build_program
from cnc_interp.machine.load import load_machine
from cnc_interp.plan.verify import verify_arrays

from .fpga_cases import gentle_curve, quintic_plan

SAMPLES = "samples/gcode"


def test_rounding_budget_closed_form():
    lim = np.array([[100.0], [1000.0], [10000.0]])
    dt, lsb = 1e-3, 2.0**-28
    assert rounding_budget(lim, dt, lsb) == pytest.approx(4 * lsb / (1e4 * 1e-9))
    m = load_machine("generic-mill")
    d = device_margin(m, FpgaFormats())
    assert FPGA_LIMIT_MARGIN < d < 1e-3
    scaled = with_margin(m, d)
    np.testing.assert_allclose(scaled.jmax, m.jmax * (1 - d))
    with pytest.raises(PlanError, match="too short"):
        device_margin(m.with_dt(1e-5), FpgaFormats())


def test_excess_samples_finds_the_stencil():
    q = np.zeros((20, 1))
    q[10:, 0] = 1e-3  # a step: velocity, acceleration and jerk spikes at samples 9..13
    bad = excess_samples(q, 1e-3, np.array([[0.5], [1e9], [1e12]]))
    assert bad.tolist() == [9, 10]
    assert excess_samples(q, 1e-3, np.array([[2.0], [1e9], [1e12]])).size == 0


@pytest.mark.parametrize("planner", ["vpop", "variable", "constant"])
def test_every_planner_stream_passes_verify_on_the_device(planner):
    # the lathe sample at the machine's limits: the golden model's setpoints must verify
    opts = StreamOptions(part=f"{SAMPLES}/lathe-profile.ngc", machine_spec="xz-lathe", planner=planner)
    prog, frames, _ = build_stream(opts)
    m = load_machine("xz-lathe")
    q = to_mm(run_program(prog).q, prog.formats)
    rep = verify_arrays(q, prog.dt_s, m.vmax, m.amax, m.jmax, axes=prog.axes)
    assert rep.ok and rep.worst_ratio <= 1 + VERIFY_RATIO_SLACK
    assert prog.stats["verify_ok"] and prog.stats["segments"] > 0
    _, traj = plan_for_stream(opts)
    assert np.max(np.abs(q - traj.q)) <= 2e-5  # within 0.02 µm of the float plan


def test_unchecked_profile_breaks_jerk_and_repair_fixes_it():
    # a fast plan at dt 1 ms; without the limits the profile fit may move samples by up to
    # 0.02 µm, which is far more than the jerk budget; with them the device verifies
    path = gentle_curve(5, seed=7)
    traj = quintic_plan(path, feed_mm_s=300.0)
    d = np.diff(np.concatenate((traj.q[:3], traj.q, traj.q[-3:])), 3, axis=0)
    jerk = np.abs(d).max(axis=0) / traj.dt_s**3
    acc = np.abs(np.diff(traj.q, 2, axis=0)).max(axis=0) / traj.dt_s**2
    vel = np.abs(np.diff(traj.q, axis=0)).max(axis=0) / traj.dt_s
    limits = np.stack([vel, acc, jerk]) * (1 + 2e-3)  # the plan runs at 99.8 % of its limits
    prog = build_program(traj, [path], limits=limits)
    assert prog.stats["verify_ok"], prog.stats
    q = to_mm(run_program(prog).q, prog.formats)
    assert excess_samples(q, traj.dt_s, limits).size == 0


def test_stream_refuses_a_stream_that_breaks_the_limits(monkeypatch, tmp_path):
    # a device margin of zero leaves rounding unaccounted: a VPOp plan at its jerk limit then
    # cannot be reproduced, and stream must refuse (exit 1) rather than send it
    import cnc_interp.fpga.limits as lim

    monkeypatch.setattr(lim, "FPGA_LIMIT_MARGIN", 0.0)
    monkeypatch.setattr(lim, "FPGA_MARGIN_QUANTA", 0.0)
    opts = StreamOptions(part=f"{SAMPLES}/lathe-profile.ngc", machine_spec="xz-lathe", planner="vpop")
    with pytest.raises(PlanError, match="refusing to stream") as ei:
        build_stream(opts)
    assert ei.value.exit_code == 1
    assert ei.value.format().startswith(f"{SAMPLES}/lathe-profile.ngc: error: refusing to stream")


def _trident_g1(tmp_path):
    """Paper 001's trident (trident-xy.ngc's NURBS) as 146 G1 lines at F10000."""
    from scipy.interpolate import BSpline

    P = np.array([[10, 0], [20, 20], [12, 8], [10, 20], [8, 8], [0, 20], [10, 0]], float)
    t = np.concatenate(([0.0] * 3, np.linspace(0, 1, 5), [1.0] * 3))
    pts = BSpline(t, P, 3)(np.linspace(0, 1, 147))
    part = tmp_path / "trident147.ngc"
    part.write_text(
        "G21 G17 G90 G94\nG0 X0 Y0 Z1\nG0 X10 Y0\nG1 Z0 F10000\n"
        + "".join(f"G1 X{x:.4f} Y{y:.4f}\n" for x, y in pts[1:])
        + "G0 Z1\nM2\n"
    )
    return part


def test_vpop_trident_of_g1_lines_holds_jerk_on_the_device(tmp_path):
    # without the limit check the profile fit's few nm broke Y jerk by 3.4 %
    # (on the planar fit; the N-axis fit happens to stay inside)
    part = _trident_g1(tmp_path)
    opts = StreamOptions(part=str(part), machine_spec="mikron-ucp710", planner="vpop", quiet=True, fit_method="planar")
    fit, traj, m = plan_for_stream(opts, with_machine=True)
    unchecked = build_program(traj, fit.paths)
    q0 = to_mm(run_program(unchecked).q, unchecked.formats)
    assert not verify_arrays(q0, traj.dt_s, m.vmax, m.amax, m.jmax).ok
    prog, _, _ = build_stream(opts)
    q = to_mm(run_program(prog).q, prog.formats)
    assert verify_arrays(q, traj.dt_s, m.vmax, m.amax, m.jmax).ok
    assert prog.stats["planar_samples"] > 0.95 * prog.n_samples  # still sent as segments
    assert np.max(np.abs(q - traj.q)) <= 2e-5

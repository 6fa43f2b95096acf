"""Golden model of the FPGA datapath and the quantization of planned paths."""

from dataclasses import replace

import numpy as np
import pytest

from cnc_interp.constants import FPGA_ROUNDTRIP_TARGET_MM
from cnc_interp.fpga.fixed import FixedFormat, FixedPointOverflow, FpgaFormats
from cnc_interp.fpga.model import FixedSegment, SetpointBlock, run_program, to_mm
from cnc_interp.fpga.program import build_program

from .fpga_cases import gentle_curve, planar_path, quintic_plan


def _rs(v, sh):
    return (v + (1 << (sh - 1))) >> sh if sh > 0 else v << -sh


def sequential_segment(seg: FixedSegment, f: FpgaFormats):
    """The datapath as an HDL would clock it: one sample per iteration, plain Python ints."""
    fx, fp, ft = f.param.frac, f.pos.frac, f.trig.frac
    ih = iv = 0
    x_prev = z_prev = 0
    out = []
    for piece in seg.pieces:
        tau = 0
        for _ in range(piece.n_samples):
            a = piece.mant[5]
            for i in range(4, -1, -1):
                a = _rs(a * tau, fx) + piece.mant[i]
            xi = _rs(a, piece.exp - fx)
            x = _rs(xi * seg.x_mant, fx + seg.x_exp - fp)
            b = seg.p_mant[5]
            for i in range(4, -1, -1):
                b = _rs(b * xi, fx) + seg.p_mant[i]
            z = _rs(b, seg.p_exp - fp)
            dx, dz = x - x_prev, z - z_prev
            x_prev, z_prev = x, z
            ih += seg.cos * dx - seg.sin * dz
            iv += seg.sin * dx + seg.cos * dz
            out.append((seg.origin[0] + _rs(ih, ft), seg.origin[1] + _rs(iv, ft)))
            tau += piece.dtau
    return out


def test_gentle_curve_round_trip_under_target():
    path = gentle_curve(6)
    traj = quintic_plan(path, feed_mm_s=80.0)
    prog = build_program(traj, [path])
    st = prog.stats
    assert st["segments"] == 6 and not st["fallback_paths"]
    assert st["planar_samples"] > 0.99 * traj.q.shape[0] - 10
    assert st["max_dev_mm"] < FPGA_ROUNDTRIP_TARGET_MM
    # resynchronisation leaves only the quantization of the origins as the gap
    assert st["max_segment_end_drift_mm"] < 1e-8
    q = to_mm(run_program(prog).q, prog.formats)
    np.testing.assert_allclose(q, traj.q, atol=FPGA_ROUNDTRIP_TARGET_MM, rtol=0)


def test_vectorised_model_equals_sequential_hardware_loop():
    path = gentle_curve(6, seed=3)
    prog = build_program(quintic_plan(path, feed_mm_s=120.0), [path])
    out = run_program(prog)
    for seg in (it for it in prog.items if isinstance(it, FixedSegment)):
        ref = np.array(sequential_segment(seg, prog.formats), dtype=np.int64)
        got = out.q[seg.start_sample : seg.start_sample + seg.n_samples][:, list(seg.plane)]
        np.testing.assert_array_equal(got, ref)


@pytest.mark.parametrize("seed", range(6))
def test_random_curves_and_feeds(seed):
    rng = np.random.default_rng(100 + seed)
    path = gentle_curve(int(rng.integers(2, 9)), seed=seed)
    traj = quintic_plan(path, feed_mm_s=float(rng.uniform(5, 400)), dt_s=float(rng.choice([5e-4, 1e-3, 4e-3])))
    prog = build_program(traj, [path])
    q = to_mm(run_program(prog).q, prog.formats)
    assert np.all(np.isfinite(q))
    assert prog.stats["max_dev_mm"] < FPGA_ROUNDTRIP_TARGET_MM
    assert np.max(np.abs(q - traj.q)) == pytest.approx(prog.stats["max_dev_mm"])


def test_three_axis_plane_keeps_the_other_axis():
    path = gentle_curve(4, axes="XYZ", plane=(0, 2), other=np.array([0.0, -7.25, 0.0]))
    traj = quintic_plan(path)
    prog = build_program(traj, [path], start=traj.q[0])
    q = to_mm(run_program(prog).q, prog.formats)
    assert prog.stats["segments"] == 4
    np.testing.assert_array_equal(q[:, 1], -7.25)
    assert prog.stats["max_dev_mm"] < FPGA_ROUNDTRIP_TARGET_MM


def test_samples_off_the_planar_form_fall_back_to_exact_setpoints():
    path = gentle_curve(3)
    traj = quintic_plan(path)
    bent = replace(traj, q=traj.q + np.array([0.0, 1e-3]) * np.sin(np.arange(traj.q.shape[0]))[:, None])
    prog = build_program(bent, [path])
    assert prog.stats["segments"] == 0 and prog.stats["fallback_paths"]
    assert all(isinstance(i, SetpointBlock) for i in prog.items)
    assert prog.stats["max_dev_mm"] <= prog.formats.pos.lsb


def test_without_paths_everything_is_setpoints():
    path = gentle_curve(2)
    traj = quintic_plan(path)
    prog = build_program(traj)
    assert prog.stats["setpoint_samples"] == traj.q.shape[0]
    assert prog.stats["max_dev_mm"] <= prog.formats.pos.lsb


def test_long_straight_segment_at_high_feed():
    # 800 mm along a rotated line, 2 m/s: long segment, large x_end, many samples
    path = planar_path([0.7], np.array([[0, 0.01, 2e-6, -1e-9, 0, 0]]), [800.0], origin0=(-400.0, 300.0))
    traj = quintic_plan(path, feed_mm_s=2000.0, dt_s=2.5e-4)
    prog = build_program(traj, [path])
    assert prog.stats["max_dev_mm"] < FPGA_ROUNDTRIP_TARGET_MM


def test_overflow_names_segment_and_line():
    path = gentle_curve(3)
    traj = quintic_plan(path)
    small = FpgaFormats(pos=FixedFormat(24, 20))  # ±8 mm range: the curve leaves it
    with pytest.raises(FixedPointOverflow) as ei:
        build_program(traj, [path], formats=small, source="wave.nc")
    msg = ei.value.format()
    import re

    m = re.match(
        r"wave\.nc:(\d+):1: error: .* overflows Q4\.20 \(24 bits\) in segment (\d+), "
        r"source line (\d+)$",
        msg,
    )
    assert m, msg
    # gentle_curve numbers segment k's source line 10 + k
    assert int(m[1]) == int(m[3]) == 10 + int(m[2])


def _line_path(points, axes="XYZ", rapid=False):
    from cnc_interp.fit.path import Path

    pts = np.asarray(points, float)
    n = pts.shape[0] - 1
    coef = np.zeros((n, 6, len(axes)))
    coef[:, 0, :] = pts[:-1]
    coef[:, 1, :] = np.diff(pts, axis=0)  # u in [0, 1] per segment
    return Path(
        axes=axes,
        breaks=np.arange(n + 1, dtype=float),
        coef=coef,
        line=np.arange(n) + 5,
        feed_mm_s=np.full(n, 50.0),
        rapid=rapid,
    )


def test_straight_moves_in_a_plane_become_segments():
    from cnc_interp.fpga.program import planar_form

    path = _line_path([[0, 0, 1], [10, 5, 1], [12, -3, 1], [12, -3, 1.0 + 1e-300]][:3])
    pl = planar_form(path)
    assert pl.plane == (0, 1)
    np.testing.assert_allclose(pl.x_end, [np.hypot(10, 5), np.hypot(2, 8)])
    assert not np.any(pl.p)
    traj = quintic_plan(path, feed_mm_s=30.0)
    prog = build_program(traj, [path])
    assert prog.stats["segments"] == 2 and prog.stats["max_dev_mm"] < FPGA_ROUNDTRIP_TARGET_MM
    # one moving axis: paired with another axis; three moving axes: not planar
    assert planar_form(_line_path([[0, 0, 0], [0, 0, 7]])).plane == (0, 2)
    assert planar_form(_line_path([[0, 0, 0], [1, 2, 3]])) is None
    rapid = _line_path([[0, 0, 0], [4, 0, 3]], rapid=True)
    assert planar_form(rapid).plane == (0, 2)


def test_straight_path_with_a_nonlinear_parametrisation():
    from cnc_interp.fit.path import Path
    from cnc_interp.fpga.program import planar_form

    # X moves along a quintic in u (as the N-axis fit makes collinear nodes), Y and Z hold
    coef = np.zeros((2, 6, 3))
    coef[0, :, 0] = [0.0, 2.0, 0.5, -0.1, 0.01, 0.0]
    coef[1, :, 0] = [2.41, 1.0, 0.0, 0.2, 0.0, -0.05]
    coef[:, 0, 1] = 4.0
    path = Path(axes="XYZ", breaks=np.array([0.0, 1.0, 2.0]), coef=coef, line=[3, 4], feed_mm_s=np.full(2, 20.0))
    pl = planar_form(path)
    assert pl is not None and not np.any(pl.p)
    traj = quintic_plan(path, feed_mm_s=20.0)
    prog = build_program(traj, [path])
    assert prog.stats["segments"] == 2
    assert prog.stats["max_dev_mm"] < FPGA_ROUNDTRIP_TARGET_MM
    # a bent path is not straight
    bent = coef.copy()
    bent[0, 2, 1] = 1e-3
    assert (
        planar_form(
            Path(axes="XYZ", breaks=np.array([0.0, 1.0, 2.0]), coef=bent, line=[3, 4], feed_mm_s=np.full(2, 20.0))
        )
        is None
    )


def test_arcs_go_as_segments_split_over_their_chords():
    # a quarter circle fitted as one parametric quintic (x(u), y(u)) is no graph of one
    # quintic over its chord within 0.1 nm; it is split in u until every piece is
    from cnc_interp.fit.path import Path
    from cnc_interp.fpga.program import planar_form, planar_path

    R = 10.0
    u = np.linspace(0.0, 1.0, 400)
    ang = 0.5 * np.pi * u
    cx = np.polynomial.polynomial.polyfit(u, R * np.cos(ang), 5)
    cy = np.polynomial.polynomial.polyfit(u, R * np.sin(ang), 5)
    coef = np.zeros((1, 6, 3))
    coef[0, :, 0], coef[0, :, 1] = cx, cy
    coef[0, 0, 2] = 2.0
    path = Path(axes="XYZ", breaks=np.array([0.0, 1.0]), coef=coef, line=[12], feed_mm_s=[50.0])
    assert planar_form(path) is None
    refined, pl = planar_path(path)
    assert refined.n_seg > 1 and pl.plane == (0, 1)
    assert refined.length == pytest.approx(path.length, rel=1e-12)
    traj = quintic_plan(path, feed_mm_s=40.0)
    prog = build_program(traj, [path])
    assert prog.stats["setpoint_samples"] < 0.01 * traj.q.shape[0]
    assert prog.stats["segments"] == refined.n_seg
    assert prog.stats["max_dev_mm"] < 2e-5
    # every piece's quintic is within the match tolerance of the curve
    q = refined(np.linspace(0.0, refined.length, 2000))
    seg = refined.segment_of_s(np.linspace(0.0, refined.length, 2000))
    c, s = np.cos(pl.theta[seg]), np.sin(pl.theta[seg])
    d = q[:, :2] - pl.origin[seg]
    x, z = d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c
    pz = np.array([np.polynomial.polynomial.polyval(x[i], pl.p[seg[i]]) for i in range(x.size)])
    assert np.max(np.abs(pz - z)) < 1e-7

"""``plot``: a real, non-blank picture of a plan, written atomically and reproducibly."""

from __future__ import annotations

import os
import subprocess
import sys

from dataclasses import replace

import numpy as np
import pytest

from cnc_interp.export.csv_io import write_csv
from cnc_interp.export.mcap_io import write_mcap
from cnc_interp.export.plot import _envelope, _plane_axes, plot_file, plot_trajectory

from ._export_synth import arc_trajectory, machine_for, machine_toml
from .conftest import SAMPLES


def _pixels(path):
    import matplotlib.image as mpimg

    return mpimg.imread(path)  # (H, W, 3|4) floats in [0, 1]


def _check_picture(path, min_bytes=30_000):
    assert os.path.getsize(path) > min_bytes
    img = _pixels(path)
    rgb = img[..., :3]
    assert img.shape[0] > 400 and img.shape[1] > 800
    # Not blank: the pixels vary, and plenty of them are neither white nor grey
    # (the feed colour map and the axis curves are coloured).
    assert rgb.std() > 0.05
    saturation = rgb.max(axis=2) - rgb.min(axis=2)
    assert (saturation > 0.3).mean() > 0.005
    return img


@pytest.fixture(scope="module")
def plan_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("plot")
    traj = arc_trajectory(duration_s=1.0, axes="XYZ")
    machine = machine_for(traj, 1.25)
    (d / "m.toml").write_text(machine_toml(machine))
    machine = replace(machine, source=str(d / "m.toml"))  # the MCAP names this file
    write_csv(traj, str(d / "p.csv"))
    write_mcap(traj, str(d / "p.mcap"), None, machine)
    return d, traj, machine


def test_plot_csv_with_machine(plan_files):
    d, _, _ = plan_files
    out = plot_file(str(d / "p.csv"), str(d / "m.toml"), None)
    assert out == str(d / "p.png")
    _check_picture(out)


def test_plot_without_machine(plan_files):
    d, traj, _ = plan_files
    out = plot_trajectory(traj, None, str(d / "no_machine.png"))
    assert out == str(d / "no_machine.png")
    img = _check_picture(out, min_bytes=15_000)
    with_machine = _pixels(plot_file(str(d / "p.csv"), str(d / "m.toml"), str(d / "wm.png")))
    assert img.shape != with_machine.shape  # the limit panels make a taller figure
    # A CSV names no machine: without -m it is drawn against the default preset, as
    # `plan` plans without -m
    default = plot_file(str(d / "p.csv"), None, str(d / "default.png"))
    given = plot_file(str(d / "p.csv"), "generic-mill", str(d / "given.png"))
    assert open(default, "rb").read() == open(given, "rb").read()
    # An MCAP plan carries its machine: without -m its limits are used.
    recorded = _pixels(plot_file(str(d / "p.mcap"), None, str(d / "rec.png")))
    assert recorded.shape == with_machine.shape


def test_an_mcap_plan_is_checked_against_the_file_it_names_not_its_copied_limits(plan_files, tmp_path):
    from cnc_interp.errors import UsageError
    from cnc_interp.export.verify_file import plan_machine

    d, _, machine = plan_files
    named = plan_machine(str(d / "p.mcap"), None)
    assert named.axes == machine.axes and named.source == str(d / "m.toml")
    for lim in ("vmax", "amax", "jmax"):
        np.testing.assert_allclose(getattr(named, lim), getattr(machine, lim), rtol=1e-15)
    assert plan_machine(str(d / "p.csv"), None).source == "preset:generic-mill"  # the default
    # limits edited inside the file change nothing: the named file decides
    traj = arc_trajectory(duration_s=1.0, axes="XYZ")
    loose = replace(machine, vmax=machine.vmax * 8, amax=machine.amax * 8, jmax=machine.jmax * 8)
    write_mcap(traj, str(tmp_path / "loose.mcap"), None, loose)
    np.testing.assert_allclose(plan_machine(str(tmp_path / "loose.mcap"), None).vmax, machine.vmax, rtol=1e-15)
    # a named file that is gone is an error that asks for -m
    gone = replace(machine, source=str(tmp_path / "gone.toml"))
    write_mcap(traj, str(tmp_path / "gone.mcap"), None, gone)
    with pytest.raises(UsageError, match="not found; give the machine with -m"):
        plan_machine(str(tmp_path / "gone.mcap"), None)


@pytest.mark.parametrize("how", ["symlink", "same-name"])
def test_plot_never_writes_over_its_input(plan_files, tmp_path, how):
    import shutil

    from cnc_interp.errors import UsageError

    d, _, _ = plan_files
    if how == "symlink":
        src = tmp_path / "plan.csv"
        shutil.copy(d / "p.csv", src)
        out = tmp_path / "out.png"
        out.symlink_to(src)
        args = (str(src), str(d / "m.toml"), str(out))
    else:  # a plan named .png plotted onto its default output, itself
        src = tmp_path / "plan.png"
        shutil.copy(d / "p.csv", src)
        args = (str(src), str(d / "m.toml"), None)
    before = src.read_bytes()
    with pytest.raises(UsageError, match="refusing to overwrite"):
        plot_file(*args)
    assert src.read_bytes() == before


def test_plot_is_reproducible(plan_files, tmp_path):
    d, traj, machine = plan_files
    a, b = str(tmp_path / "a.png"), str(tmp_path / "b.png")
    plot_trajectory(traj, machine, a, title="t")
    plot_trajectory(traj, machine, b, title="t")
    assert open(a, "rb").read() == open(b, "rb").read()
    assert sorted(os.listdir(tmp_path)) == ["a.png", "b.png"]  # no temporary files left


def test_plot_svg(plan_files, tmp_path):
    _, traj, machine = plan_files
    out = plot_trajectory(traj, machine, str(tmp_path / "f.svg"))
    text = open(out).read()
    assert text.lstrip().startswith("<?xml") and "<svg" in text


def test_long_plan_is_decimated_without_losing_peaks():
    t = np.arange(1_000_001) * 1e-3
    y = np.zeros((t.size, 1))
    y[123_457, 0] = 5.0  # a single-sample spike
    y[700_001, 0] = -3.0
    te, lo, hi = _envelope(t, y)
    assert te.size < 10_000
    assert hi.max() == 5.0 and lo.min() == -3.0


def test_plane_prefers_the_linear_axes_that_move():
    traj = arc_trajectory(duration_s=0.2, axes="XYZC")
    assert _plane_axes(traj) == (0, 1)  # C moves 90 deg but is rotary
    traj = arc_trajectory(duration_s=0.2, axes="XZ")
    assert _plane_axes(traj) == (0, 1)


def test_matplotlib_not_imported_by_cli():
    code = "import cnc_interp.cli, sys; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def _mill_trajectory(cut_mm_s=3.0, rapid_mm_s=200.0):
    """A mill plan: a slow XY cut at Z -1, then a fast rapid up in Z."""
    from cnc_interp.plan.trajectory import Trajectory

    dt = 1e-3
    x = np.cumsum(np.full(2000, cut_mm_s * dt))
    z_up = -1.0 + np.cumsum(np.full(200, rapid_mm_s * dt))
    q = np.zeros((2200, 3))
    q[:2000, 0] = x
    q[:2000, 1] = np.sin(x)  # an XY contour: the path view is the top view
    q[2000:, 1] = q[1999, 1]
    q[:2000, 2] = -1.0
    q[2000:, 0] = x[-1]
    q[2000:, 2] = z_up
    feed = np.concatenate([[0.0], np.linalg.norm(np.diff(q, axis=0), axis=1) / dt])
    return Trajectory(
        axes="XYZ",
        dt_s=dt,
        t=np.arange(2200) * dt,
        s=np.concatenate([[0.0], np.cumsum(feed[1:] * dt)]),
        feed=feed,
        q=q,
        line=np.zeros(2200, dtype=np.int64),
        planner="test",
    )


def test_mill_plot_has_a_z_view_and_a_feed_scale_for_cutting_feeds():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cnc_interp.export.plot import _figure, _z_view_axis

    traj = _mill_trajectory()
    assert _z_view_axis(traj) == 2
    fig = _figure(plt, traj, None, "mill")
    try:
        labels = [ax.get_ylabel() for ax in fig.axes]
        assert "Z (mm)" in labels
        scales = {ax.get_yscale() for ax in fig.axes if ax.get_ylabel() == "feed (mm/s)"}
        assert "symlog" in scales  # 3 mm/s cutting next to 200 mm/s rapids
    finally:
        plt.close(fig)
    slow = _mill_trajectory(rapid_mm_s=6.0)  # no rapid far above the cutting feed
    fig = _figure(plt, slow, None, "mill")
    try:
        scales = {ax.get_yscale() for ax in fig.axes if ax.get_ylabel() == "feed (mm/s)"}
        assert "linear" in scales and "symlog" not in scales
    finally:
        plt.close(fig)


def _rotary_trajectory(k=6000, y_wiggle_mm=0.01):
    """An XYZA rotary job: X and Z move, A turns 720 deg, Y only wiggles."""
    from cnc_interp.plan.trajectory import Trajectory

    dt = 1e-3
    u = np.linspace(0.0, 1.0, k)
    q = np.column_stack([40 * u, y_wiggle_mm * np.sin(50 * u), -5 * np.sin(3 * u), 720 * u])
    feed = np.concatenate([[0.0], np.linalg.norm(np.diff(q[:, :3], axis=0), axis=1) / dt])
    return Trajectory(
        axes="XYZA",
        dt_s=dt,
        t=np.arange(k) * dt,
        s=np.concatenate([[0.0], np.cumsum(feed[1:] * dt)]),
        feed=feed,
        q=q,
        line=np.zeros(k, dtype=np.int64),
        planner="test",
    )


def _figure_of(traj, machine=None, span=None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cnc_interp.export.plot import _figure

    return plt, _figure(plt, traj, machine, "t", span)


def test_rotary_job_draws_xz_and_a_rotary_panel():
    traj = _rotary_trajectory()
    assert _plane_axes(traj) == (0, 2)  # X and Z: Y's 0.02 mm wiggle is a flat line
    machine = machine_for(traj, 1.5)
    plt, fig = _figure_of(traj, machine)
    try:
        rot = [ax for ax in fig.axes if ax.get_ylabel() == "rotary (deg)"]
        assert len(rot) == 1
        (line,) = [ln for ln in rot[0].get_lines() if ln.get_label() == "A"]
        assert np.max(line.get_ydata()) == pytest.approx(720.0)
        path = [ax for ax in fig.axes if ax.get_title().startswith("tool path")]
        assert path[0].get_xlabel() == "X (mm)" and path[0].get_ylabel() == "Z (mm)"
    finally:
        plt.close(fig)
    # a top view when Y really moves
    assert _plane_axes(_rotary_trajectory(y_wiggle_mm=5.0)) == (0, 1)


def test_window_restricts_every_time_panel():
    from cnc_interp.export.plot import plot_window

    traj = _rotary_trajectory()
    machine = machine_for(traj, 1.5)
    i0, i1 = plot_window(traj, 2.0, 3.5)
    assert traj.t[i0] == pytest.approx(2.0) and traj.t[i1 - 1] == pytest.approx(3.5)
    plt, fig = _figure_of(traj, machine, (i0, i1))
    try:
        timed = [ax for ax in fig.axes if not ax.get_title().startswith("tool path") and ax.get_label() != "<colorbar>"]
        assert len(timed) >= 5  # feed, v, a, j, rotary (and Z)
        for ax in timed:
            lo, hi = ax.get_xlim()
            assert lo == pytest.approx(2.0) and hi == pytest.approx(3.5)
            for ln in ax.get_lines():
                x = np.asarray(ln.get_xdata(), dtype=float)
                if x.size > 2:  # the curves, not the ±1 bounds
                    assert x.min() >= 2.0 - 1e-9 and x.max() <= 3.5 + 1e-9
        # A (turning steadily) is drawn from the window's samples only: its upper envelope
        # lies between A at the window's ends and reaches A at the end
        rot = [ax for ax in fig.axes if ax.get_ylabel() == "rotary (deg)"][0]
        a = [ln for ln in rot.get_lines() if ln.get_label() == "A"][0].get_ydata()
        assert np.min(a) >= traj.q[i0, 3] and np.max(a) == pytest.approx(traj.q[i1 - 1, 3])
        # the ratios in the window are those of the whole plan there (no restart from rest)
        from cnc_interp.export.ratios import limit_ratios

        whole = np.abs(limit_ratios(traj.q, traj.dt_s, machine.limits())).max(axis=(1, 2))
        for kind, label in enumerate(("v / vmax", "a / amax", "j / jmax")):
            ax = [ax for ax in fig.axes if ax.get_ylabel() == label][0]
            shown = float(ax.texts[0].get_text().rsplit("= ", 1)[1])
            assert shown <= whole[kind] + 1e-3  # a restart from rest would jump
        assert "shown: 2.000 to 3.500 s" in fig._suptitle.get_text()
    finally:
        plt.close(fig)


@pytest.mark.parametrize(
    "window, message",
    [
        ((3.0, 2.0), "must come before"),
        ((2.0, 2.0), "must come before"),
        ((-1.0, 2.0), "outside the plan"),
        ((1.0, 99.0), "outside the plan"),
        ((float("nan"), 2.0), "finite"),
        ((1.0, 1.0005), "fewer than 2 samples"),
    ],
)
def test_window_is_validated(window, message):
    from cnc_interp.errors import UsageError
    from cnc_interp.export.plot import plot_window

    with pytest.raises(UsageError, match=message) as ei:
        plot_window(_rotary_trajectory(), *window, "p.mcap")
    assert ei.value.exit_code == 2 and ei.value.format().startswith("p.mcap: error: ")


def test_plot_command_window(plan_files, tmp_path):
    from click.testing import CliRunner

    from cnc_interp import cli

    d, traj, _ = plan_files
    out = tmp_path / "w.png"
    args = ["plot", str(d / "p.mcap"), "-o", str(out)]
    res = CliRunner().invoke(cli.main, [*args, "--from", "0.2", "--to", "0.6"])
    assert res.exit_code == 0, res.output
    _check_picture(str(out))
    bad = CliRunner().invoke(cli.main, [*args, "--from", "0.6", "--to", "0.2"])
    err = bad.exception  # the entry point prints it as one line and exits 2
    assert err.exit_code == 2 and err.format() == f"{d / 'p.mcap'}: error: --from 0.6 s must come before --to 0.2 s"


def test_long_plan_decimated_per_pixel_column():
    """A half-hour plan: every curve against time has at most a few points per pixel
    column, and the drawing stays fast."""
    import time

    k = 1_800_000
    traj = _rotary_trajectory(k)
    t0 = time.perf_counter()
    plt, fig = _figure_of(traj)
    try:
        assert time.perf_counter() - t0 < 20
        width_px = fig.get_figwidth() * 110
        for ax in fig.axes:
            for ln in ax.get_lines():
                assert len(ln.get_xdata()) <= width_px or len(ln.get_xdata()) <= 2
    finally:
        plt.close(fig)


def test_binding_panel_shows_the_classes_the_estimate_counts():
    # the panel's rows are exactly the limit classes plan.breakdown finds in the samples
    import cnc_interp as ci
    from cnc_interp.plan.breakdown import CODE_TRANSITION, classify_limits, code_names

    m = ci.load_machine("generic-mill")
    traj = ci.plan(ci.fit(ci.read_program(os.path.join(SAMPLES, "mill-contour.ngc"), machine=m)), m)
    codes = classify_limits(traj.q, traj.dt_s, m)
    names = code_names(m.axes)
    expected = {names[c] if c != CODE_TRANSITION else "below limits" for c in np.unique(codes).tolist()}
    assert any(n.endswith(("jerk", "acceleration")) for n in expected)  # the plan meets its limits
    plt, fig = _figure_of(traj, m)
    try:
        (ax,) = [ax for ax in fig.axes if ax.get_ylabel() == "binds"]
        assert {t.get_text() for t in ax.get_yticklabels()} == expected
    finally:
        plt.close(fig)

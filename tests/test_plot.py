"""``plot``: a real, non-blank picture of a plan, written atomically and reproducibly."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from cnc_interp.export.csv_io import write_csv
from cnc_interp.export.mcap_io import write_mcap
from cnc_interp.export.plot import _envelope, _plane_axes, plot_file, plot_trajectory

from ._export_synth import arc_trajectory, machine_for, machine_toml


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
    write_csv(traj, str(d / "p.csv"))
    write_mcap(traj, str(d / "p.mcap"), None, machine)
    return d, traj, machine


def test_plot_csv_with_machine(plan_files):
    d, _, _ = plan_files
    out = plot_file(str(d / "p.csv"), str(d / "m.toml"), None)
    assert out == str(d / "p.png")
    _check_picture(out)


def test_plot_without_machine(plan_files):
    d, _, _ = plan_files
    out = plot_file(str(d / "p.csv"), None, str(d / "no_machine.png"))
    assert out == str(d / "no_machine.png")
    img = _check_picture(out, min_bytes=15_000)
    with_machine = _pixels(plot_file(str(d / "p.csv"), str(d / "m.toml"), str(d / "wm.png")))
    assert img.shape != with_machine.shape  # the limit panels make a taller figure
    # An MCAP plan carries its machine: without -m its limits are used.
    recorded = _pixels(plot_file(str(d / "p.mcap"), None, str(d / "rec.png")))
    assert recorded.shape == with_machine.shape


def test_recorded_machine(plan_files):
    from cnc_interp.export.mcap_io import read_mcap_machine

    d, _, machine = plan_files
    rec = read_mcap_machine(str(d / "p.mcap"))
    assert rec.axes == machine.axes and rec.name == machine.name
    for lim in ("vmax", "amax", "jmax"):
        np.testing.assert_array_equal(getattr(rec, lim), getattr(machine, lim))
    assert read_mcap_machine(str(d / "p.csv")) is None


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

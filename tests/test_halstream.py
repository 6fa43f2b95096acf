"""``plan -o PLAN.halstream``: LinuxCNC's ``halstreamer`` format, checked against the CSV
of the same plan and, where LinuxCNC (``linuxcnc-uspace``'s ``halrun``) is installed,
played through a real HAL session: ``streamer`` drives its pins from the file one line
per servo period and a ``sampler`` records them."""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile

import numpy as np
import pytest

from tests._contract_helpers import run_inproc

PART = "G21 G90 F3000\nG0 X1 Y1 Z2\nG1 Z0\nG1 X30 Y10\nG2 X40 Y20 R10\nG1 Y35\nG0 Z5\nM2\n"
#: halsampler prints floats with %f: six decimals
HALSAMPLER_ABS_TOL = 5e-7 + 1e-12


@pytest.fixture(scope="module")
def plans(tmp_path_factory):
    d = tmp_path_factory.mktemp("halstream")
    part = d / "p.ngc"
    part.write_text(PART)
    for name in ("p.csv", "p.halstream", "again.halstream"):
        res = run_inproc("plan", part, "-q", "-o", d / name)
        assert res.code == 0, res.explain()
    return d


def test_halstream_holds_the_csv_positions_one_line_per_period(plans):
    from cnc_interp.export.csv_io import read_csv
    from cnc_interp.export.halstream import read_halstream

    traj = read_csv(str(plans / "p.csv"))
    q = read_halstream(str(plans / "p.halstream"))
    assert q.shape == (traj.n_samples, 3)
    np.testing.assert_array_equal(q, traj.q)  # repr text: the same float64, bit for bit
    text = (plans / "p.halstream").read_text()
    head = [ln for ln in text.splitlines() if ln.startswith("#")]
    assert "# columns: X Y Z (X mm, Y mm, Z mm), streamer.0.pin.0 to .2" in head
    assert "# period: 0.001 s = 1000000 ns (the thread that runs streamer.0)" in head
    assert "# loadrt streamer depth=... cfg=fff" in head
    assert text.count("\n") == len(head) + traj.n_samples
    assert (plans / "again.halstream").read_bytes() == (plans / "p.halstream").read_bytes()


def test_write_of_a_trajectory_matches_the_streamed_file(plans, tmp_path):
    import cnc_interp as ci
    from cnc_interp.export.csv_io import read_csv

    traj = read_csv(str(plans / "p.csv"))
    ci.write(traj, str(tmp_path / "w.halstream"))
    assert (tmp_path / "w.halstream").read_bytes() == (plans / "p.halstream").read_bytes()
    with pytest.raises(ci.CncInterpError, match=r"\.csv, \.mcap, \.halstream"):
        ci.write(traj, str(tmp_path / "w.txt"))
    assert not (tmp_path / "w.txt").exists()


def _hal_env(fifo_dir: str) -> dict:
    env = dict(os.environ)
    if os.geteuid() == 0:
        # LinuxCNC's rtapi_app refuses to run as root without a user to drop to
        env["RTAPI_UID"] = str(65534)
    env["RTAPI_FIFO_PATH"] = os.path.join(fifo_dir, "rtapi_fifo")
    return env


@pytest.mark.skipif(shutil.which("halrun") is None, reason="needs LinuxCNC's halrun (Debian: linuxcnc-uspace)")
def test_halrun_plays_the_file_sample_for_sample(plans):
    """The HAL lines of docs/outputs.md, with a sampler on the streamer's pins."""
    from cnc_interp.export.halstream import read_halstream

    q = read_halstream(str(plans / "p.halstream"))
    rows = q.shape[0]
    # rtapi_app drops to an unprivileged user: its socket folder must be writable by it
    work = tempfile.mkdtemp(prefix="cnc-interp-hal-")
    try:
        os.chmod(work, 0o777)
        recorded = os.path.join(work, "recorded.txt")
        hal = os.path.join(work, "play.hal")
        with open(hal, "w") as fh:
            fh.write(
                f"loadrt streamer depth={rows + 64} cfg=fff\n"
                f"loadrt sampler depth={rows + 64} cfg=fff\n"
                "loadrt threads name1=servo period1=1000000\n"
                "addf streamer.0 servo\n"
                "addf sampler.0 servo\n"
                + "".join(f"net j{i} streamer.0.pin.{i} sampler.0.pin.{i}\n" for i in range(3))
                + f"loadusr -w halstreamer {plans / 'p.halstream'}\n"
                "start\n"
                f"loadusr -w halsampler -n {rows} {recorded}\n"
            )
        res = subprocess.run(
            ["halrun", "-f", hal], capture_output=True, text=True, timeout=120, env=_hal_env(work), cwd=work
        )
        assert res.returncode == 0, res.stdout + res.stderr
        got = np.loadtxt(recorded, ndmin=2)
    finally:
        subprocess.run(["halrun", "-U"], capture_output=True, timeout=60, env=_hal_env(work))
        shutil.rmtree(work, ignore_errors=True)
    assert got.shape == q.shape
    assert np.max(np.abs(got - q)) <= HALSAMPLER_ABS_TOL

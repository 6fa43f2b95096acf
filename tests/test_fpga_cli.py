"""`cnc-interp emulate` and `cnc-interp stream` end to end (frames file and emulated USB device)."""

import os
import subprocess
import sys

import numpy as np
import pytest

from cnc_interp.constants import FPGA_ROUNDTRIP_TARGET_MM
from cnc_interp.export.csv_io import read_csv
from cnc_interp.fpga.frames import program_frames
from cnc_interp.fpga.model import run_program, to_mm
from cnc_interp.fpga.program import build_program

from .fpga_cases import gentle_curve, quintic_plan

from .conftest import CORPUS  # noqa: E402

XZ_INI = os.path.join(CORPUS, "configs", "XZ.ini")


def cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "cnc_interp.cli", *args], capture_output=True, text=True, cwd=cwd, timeout=600
    )


@pytest.fixture(scope="module")
def frame_file(tmp_path_factory):
    path = gentle_curve(4, seed=21)
    traj = quintic_plan(path, feed_mm_s=70.0)
    prog = build_program(traj, [path], source="wave.nc")
    frames, _ = program_frames(prog)
    f = tmp_path_factory.mktemp("fr") / "wave.bin"
    f.write_bytes(b"".join(frames))
    return f, prog, traj


def test_emulate_writes_plan_csv(frame_file, tmp_path):
    f, prog, traj = frame_file
    out = tmp_path / "emu.csv"
    r = cli("emulate", str(f), "-o", str(out))
    assert r.returncode == 0, r.stderr
    back = read_csv(str(out))
    assert back.axes == "XZ" and back.dt_s == pytest.approx(traj.dt_s)
    np.testing.assert_array_equal(back.q, to_mm(run_program(prog).q, prog.formats))
    assert np.max(np.abs(back.q - traj.q)) < FPGA_ROUNDTRIP_TARGET_MM
    # same input, same bytes
    out2 = tmp_path / "emu2.csv"
    assert cli("emulate", str(f), "-o", str(out2)).returncode == 0
    assert out.read_bytes() == out2.read_bytes()


def test_emulate_damaged_file_is_a_clean_error(frame_file, tmp_path):
    f, _, _ = frame_file
    bad = tmp_path / "bad.bin"
    data = bytearray(f.read_bytes())
    data[200] ^= 0x10
    bad.write_bytes(bytes(data))
    r = cli("emulate", str(bad), "-o", str(tmp_path / "x.csv"))
    assert r.returncode == 2
    assert r.stderr.startswith(f"{bad}: error:") and "Traceback" not in r.stderr
    assert not (tmp_path / "x.csv").exists()


def _xz_part(tmp_path):
    part = tmp_path / "profile.ngc"
    part.write_text(
        "G21 G18 G90 G94\nG0 X10 Z0\nF600\nG1 X10 Z-5\nG2 X14 Z-9 R4\n"
        "G1 X14 Z-15\nG3 X20 Z-21 K-6\nG1 X22 Z-30\nG0 X30 Z5\nM2\n"
    )
    return part


@pytest.mark.slow
@pytest.mark.corpus  # the corpus's XZ.ini
def test_stream_dry_run_round_trip_matches_plan(tmp_path):
    part = _xz_part(tmp_path)
    frames = tmp_path / "p.bin"
    r = cli("stream", str(part), "-m", XZ_INI, "--dry-run", str(frames))
    assert r.returncode == 0, r.stderr
    assert "fpga:" in r.stderr
    emu = tmp_path / "emu.csv"
    assert cli("emulate", str(frames), "-o", str(emu)).returncode == 0
    # the device's setpoints hold the machine's limits (verify exits 0)
    r = cli("verify", str(emu), "-m", XZ_INI)
    assert r.returncode == 0, r.stdout + r.stderr
    # and follow the plan the stream made (the machine's limits less the device margin)
    from cnc_interp.fpga.commands import StreamOptions, plan_for_stream

    _, b = plan_for_stream(StreamOptions(part=str(part), machine_spec=XZ_INI, planner="variable"))
    a = read_csv(str(emu))
    assert a.q.shape == b.q.shape
    assert np.max(np.abs(a.q - b.q)) < FPGA_ROUNDTRIP_TARGET_MM


@pytest.mark.slow
@pytest.mark.corpus  # the corpus's XZ.ini
def test_stream_fit_method_nodes_round_trips(tmp_path):
    # a lathe profile of G1 moves in XZ: planar segments by default, N-axis ones on request
    part = tmp_path / "polyline.ngc"
    th = np.linspace(0.0, 0.5 * np.pi, 41)
    part.write_text(
        "G21 G18 G90 G94\nG0 X10 Z0\nF600\n"
        + "".join(f"G1 X{10 + 5 * np.sin(t):.4f} Z{-5 + 5 * np.cos(t):.4f}\n" for t in th[1:])
        + "G0 X30 Z5\nM2\n"
    )
    frames = {m: tmp_path / f"{m}.bin" for m in ("auto", "nodes")}
    for m, f in frames.items():
        r = cli("stream", str(part), "-m", XZ_INI, "--fit-method", m, "--dry-run", str(f))
        assert r.returncode == 0, r.stderr
        emu = tmp_path / f"{m}-emu.csv"
        assert cli("emulate", str(f), "-o", str(emu)).returncode == 0
        from cnc_interp.fpga.commands import StreamOptions, plan_for_stream

        _, b = plan_for_stream(StreamOptions(part=str(part), machine_spec=XZ_INI, planner="variable", fit_method=m))
        a = read_csv(str(emu))
        assert a.q.shape == b.q.shape
        assert np.max(np.abs(a.q - b.q)) < FPGA_ROUNDTRIP_TARGET_MM
    assert frames["auto"].read_bytes() != frames["nodes"].read_bytes()


@pytest.mark.parametrize("planner", ["constant", "vpop"])
@pytest.mark.corpus  # the corpus's XZ.ini
def test_stream_other_planners_round_trip(tmp_path, planner):
    from cnc_interp.fpga.commands import StreamOptions, build_stream, emulate_frames, plan_for_stream
    from cnc_interp.fpga.frames import decode_frame

    part = _xz_part(tmp_path)
    opts = StreamOptions(part=str(part), machine_spec=XZ_INI, planner=planner)
    _, traj = plan_for_stream(opts)
    prog, frames, _ = build_stream(opts)
    core = emulate_frames([decode_frame(f) for f in frames])
    q = to_mm(core.datapath.output().q, prog.formats)
    assert q.shape == traj.q.shape
    assert np.max(np.abs(q - traj.q)) < FPGA_ROUNDTRIP_TARGET_MM
    assert prog.stats["segments"] > 0


@pytest.mark.corpus  # the corpus's XZ.ini
def test_stream_passes_the_effort_to_the_optimal_planner(tmp_path):
    from cnc_interp.errors import UsageError
    from cnc_interp.fpga.commands import StreamOptions, plan_for_stream

    part = _xz_part(tmp_path)
    _, traj = plan_for_stream(StreamOptions(part=str(part), machine_spec=XZ_INI, planner="optimal", effort="fast"))
    assert traj.planner == "optimal" and traj.settings["options"] == {"effort": "fast"}
    with pytest.raises(UsageError, match="--effort applies to --planner optimal, not variable"):
        plan_for_stream(StreamOptions(part=str(part), machine_spec=XZ_INI, effort="fast"))


@pytest.mark.corpus  # the corpus's XZ.ini
def test_stream_to_emulated_device_with_faults(tmp_path, capsys):
    from cnc_interp.fpga.commands import StreamOptions, build_stream, run_stream
    from cnc_interp.fpga.device import DeviceCore
    from cnc_interp.fpga.device_sim import FaultPlan, SimBackend

    part = _xz_part(tmp_path)
    opts = StreamOptions(part=str(part), machine_spec=XZ_INI, planner="variable")
    prog, frames, _ = build_stream(opts)
    be = SimBackend(DeviceCore(buffer_bytes=8192, drain_per_poll=4096), FaultPlan(rate=0.2, seed=4))
    run_stream(opts, backend=be)
    assert be.core.applied == list(range(1, len(frames) + 1))
    np.testing.assert_array_equal(be.core.datapath.output().q, run_program(prog).q)
    assert "usb: sent frames 1.." in capsys.readouterr().err


@pytest.mark.corpus  # the corpus's XZ.ini
def test_stream_errors(tmp_path):
    from cnc_interp.errors import DeviceError, UsageError
    from cnc_interp.fpga.commands import StreamOptions, run_stream

    part = _xz_part(tmp_path)
    with pytest.raises(UsageError, match="--resume-from"):
        run_stream(StreamOptions(part=str(part), machine_spec=XZ_INI, dry_run=str(tmp_path / "x.bin"), resume_from=3))
    # the real libusb backend: no such device on this machine
    with pytest.raises(DeviceError, match="no USB device ffff:fffe found") as ei:
        run_stream(StreamOptions(part=str(part), machine_spec=XZ_INI, device="ffff:fffe", quiet=True))
    assert ei.value.exit_code == 1

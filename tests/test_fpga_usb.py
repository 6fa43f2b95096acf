"""USB streaming through pyusb with an emulated device backend, under injected faults.

Every test ends with the emulated device holding exactly the golden model's
setpoints of the whole program and having applied each frame exactly once.
"""

import numpy as np
import pytest

from cnc_interp.errors import DeviceError, UsageError
from cnc_interp.fpga.device import DONE, DeviceCore
from cnc_interp.fpga.device_sim import FaultPlan, SimBackend
from cnc_interp.fpga.frames import program_frames
from cnc_interp.fpga.model import run_program
from cnc_interp.fpga.program import build_program
from cnc_interp.fpga.usb_link import UsbLink, parse_device_id

from .fpga_cases import gentle_curve, quintic_plan


@pytest.fixture(scope="module")
def job():
    path = gentle_curve(8, seed=5)
    traj = quintic_plan(path, feed_mm_s=40.0, dt_s=5e-4)
    prog = build_program(traj, [path], source="wave.nc")
    frames, infos = program_frames(prog)
    # a setpoint-only version too, so that there are many large frames
    prog2 = build_program(traj, source="wave.nc")
    return prog, frames, infos, prog2


def _device(buffer_bytes=16384, drain=None, faults=None):
    return SimBackend(DeviceCore(buffer_bytes=buffer_bytes, drain_per_poll=drain), faults)


def assert_exact(be: SimBackend, prog, n_frames: int):
    core = be.core
    assert core.state == DONE
    assert core.applied == list(range(1, n_frames + 1)), "a frame was lost or applied twice"
    np.testing.assert_array_equal(core.datapath.output().q, run_program(prog).q)


def test_clean_stream(job):
    prog, frames, infos, _ = job
    be = _device()
    rep = UsbLink.open(backend=be).send(frames, infos)
    assert rep.frames_sent == len(frames) and rep.retries == 0
    assert rep.final.bytes_accepted == sum(map(len, frames))
    assert_exact(be, prog, len(frames))


@pytest.mark.parametrize("kind", ["timeout", "timeout_partial", "short", "corrupt", "stall"])
def test_each_fault_kind(job, kind):
    prog, frames, infos, _ = job
    faults = FaultPlan(at_write={2: kind, 3: kind, 8: kind, 9: kind, 10: kind})
    be = _device(faults=faults)
    rep = UsbLink.open(backend=be).send(frames, infos)
    assert [k for _, k in be.injected] == [kind] * 5
    assert_exact(be, prog, len(frames))
    if kind in ("timeout", "timeout_partial"):
        assert rep.timeouts >= 5
    if kind == "stall":
        assert rep.stalls == 5
    if kind == "short":
        assert rep.short_writes >= 1


@pytest.mark.parametrize("seed", range(8))
def test_random_faults_with_flow_control(job, seed):
    prog, _, _, prog2 = job
    use = prog if seed % 2 else prog2
    frames, infos = program_frames(use)
    faults = FaultPlan(rate=0.25, seed=seed, read_timeout_rate=0.1)
    be = _device(buffer_bytes=9000, drain=5000, faults=faults)
    rep = UsbLink.open(backend=be, retries=30).send(frames, infos)
    assert be.injected, "the sweep should inject faults"
    assert rep.status_polls > len(frames)
    assert_exact(be, use, len(frames))


def test_lost_acknowledgement_does_not_duplicate(job):
    prog, frames, infos, _ = job
    # status reads 3 and 4 time out: the host cannot see the ack of frame 2 at first
    be = _device(faults=FaultPlan(at_read={3: "read_timeout", 4: "read_timeout"}))
    UsbLink.open(backend=be).send(frames, infos)
    assert_exact(be, prog, len(frames))


def test_disconnect_reports_last_segment_and_resumes(job):
    prog, frames, infos, _ = job
    be = _device(faults=FaultPlan(disconnect_after_seq=5))
    link = UsbLink.open(backend=be)
    with pytest.raises(DeviceError) as ei:
        link.send(frames, infos, source="wave.nc")
    err = ei.value
    msg = err.format()
    import re

    acked = int(re.search(r"--resume-from (\d+)", msg).group(1))
    # the host names the last frame it saw acknowledged; the device may hold one more
    assert acked in (be.core.last_seq, be.core.last_seq - 1) and be.core.last_seq == 5
    assert "disconnected" in msg
    info = infos[acked - 1]
    assert f"segment {info.segment}" in msg and msg.startswith(f"wave.nc:{info.line}:")
    assert err.exit_code == 1
    # plugging it back in and resuming sends the rest exactly once
    be.reconnect()
    rep = UsbLink.open(backend=be).send(frames, infos, resume_from=acked, source="wave.nc")
    assert rep.first_seq == 6  # the device already held frame 5: it is not sent again
    assert_exact(be, prog, len(frames))


def test_resume_checks(job):
    prog, frames, infos, _ = job
    be = _device(faults=FaultPlan(disconnect_after_seq=3))
    with pytest.raises(DeviceError):
        UsbLink.open(backend=be).send(frames, infos)
    be.reconnect()
    with pytest.raises(DeviceError, match="--resume-from 3"):
        UsbLink.open(backend=be).send(frames, infos)  # partly sent program
    with pytest.raises(DeviceError, match="acknowledges only up to frame 3"):
        UsbLink.open(backend=be).send(frames, infos, resume_from=9)
    with pytest.raises(UsageError):
        UsbLink.open(backend=be).send(frames, infos, resume_from=10_000)
    UsbLink.open(backend=be).send(frames, infos, resume_from=3)
    assert_exact(be, prog, len(frames))


def test_full_buffer_without_progress_is_an_error(job):
    prog, frames, infos, prog2 = job
    frames2, infos2 = program_frames(prog2)
    be = _device(buffer_bytes=9000, drain=0)  # never executes anything
    with pytest.raises(DeviceError, match="buffer stays full"):
        UsbLink.open(backend=be, stall_polls=50).send(frames2, infos2)


def test_persistent_corruption_gives_up_with_location(job):
    prog, frames, infos, _ = job
    be = _device(faults=FaultPlan(rate=1.0, kinds=("corrupt",)))
    with pytest.raises(DeviceError, match="not accepted after|answered no status"):
        UsbLink.open(backend=be, retries=3).send(frames, infos, source="wave.nc")


def test_device_not_found_and_bad_ids():
    be = _device()
    be.connected = False
    with pytest.raises(DeviceError, match="no USB device 1209:0001"):
        UsbLink.open(backend=be)
    assert parse_device_id("CAFE:0b0e") == (0xCAFE, 0x0B0E)
    with pytest.raises(UsageError):
        parse_device_id("12345")


def test_resume_refuses_a_different_program(job):
    prog, frames, infos, prog2 = job
    be = _device(faults=FaultPlan(disconnect_after_seq=3))
    with pytest.raises(DeviceError):
        UsbLink.open(backend=be).send(frames, infos)
    be.reconnect()
    frames2, infos2 = program_frames(prog2)
    with pytest.raises(DeviceError, match="another program"):
        UsbLink.open(backend=be).send(frames2, infos2, resume_from=3)


def test_send_frame_file_and_infos(job, tmp_path):
    from cnc_interp.fpga.commands import frame_infos, send_frame_file
    from cnc_interp.fpga.frames import decode_frame

    prog, frames, infos, _ = job
    assert frame_infos([decode_frame(f) for f in frames]) == infos
    f = tmp_path / "p.bin"
    f.write_bytes(b"".join(frames))
    be = _device(faults=FaultPlan(rate=0.2, seed=9))
    rep = send_frame_file(str(f), backend=be)
    assert rep.final.bytes_accepted == sum(map(len, frames))
    assert_exact(be, prog, len(frames))


def test_resume_from_zero_on_a_fresh_device(job):
    prog, frames, infos, _ = job
    be = _device()
    UsbLink.open(backend=be).send(frames, infos, resume_from=0)
    assert_exact(be, prog, len(frames))

"""Real-time semantics of the device: prefill before START, underrun, feed hold, abort."""

import numpy as np
import pytest

from cnc_interp.errors import DeviceError
from cnc_interp.fpga.device import ABORTED, ARMED, DONE, HELD, RUNNING, UNDERRUN, DeviceCore
from cnc_interp.fpga.device_sim import SimBackend
from cnc_interp.fpga.frames import (
    ErrorFlag,
    FrameType,
    control_frame,
    decode_frame,
    decode_status,
    program_frames,
)
from cnc_interp.fpga.model import run_program
from cnc_interp.fpga.program import build_program
from cnc_interp.fpga.usb_link import UsbLink
from cnc_interp.plan.trajectory import Trajectory
from cnc_interp.plan.verify import verify_arrays

from .fpga_cases import gentle_curve, quintic_plan


def _two_moves():
    """Two rest-to-rest moves with a stop between them (a rest point in the middle)."""
    a = quintic_plan(gentle_curve(2, seed=1), feed_mm_s=80.0, rest_after=5)
    path = gentle_curve(2, seed=2)
    b = quintic_plan(path, feed_mm_s=80.0, rest_before=0)
    q = np.concatenate((a.q, b.q - b.q[0] + a.q[-1]))
    K = q.shape[0]
    traj = Trajectory(
        axes=a.axes,
        dt_s=a.dt_s,
        t=np.arange(K) * a.dt_s,
        s=np.zeros(K),
        feed=np.zeros(K),
        q=q,
        line=np.full(K, 7),
        planner="test",
    )
    prog = build_program(traj, source="two.nc")
    return prog, a.q.shape[0]


def _limits(q, dt):
    """The plan's own largest |v|, |a|, |j| (verify's differences, rest padding): a plan at 100 %."""
    x = np.concatenate((np.repeat(q[:1], 3, 0), q, np.repeat(q[-1:], 3, 0)))
    out = []
    for m in range(1, 4):
        x = np.diff(x, axis=0)
        out.append(np.abs(x).max(axis=0) / dt**m)
    return out


def _feed(core, frames, periods_per_frame=0):
    for f in frames:
        assert core.handle(decode_frame(f))
        core.advance(periods_per_frame)


def test_prefill_then_run_to_done():
    prog, _ = _two_moves()
    frames, _ = program_frames(prog, prefill_samples=200)
    core = DeviceCore(buffer_bytes=1 << 30, clocked=True)
    out_while_armed = []
    for f in frames:
        assert core.handle(decode_frame(f))
        if core.state == ARMED:
            out_while_armed.append(core.samples_out)
        core.advance(1)
    assert out_while_armed and max(out_while_armed) == 0  # nothing runs before the prefill
    core.advance(prog.n_samples)
    assert core.state == DONE and core.samples_out == prog.n_samples
    ref = run_program(prog).q
    got = np.array(core.output)
    # the output: the start position while armed (at least the prefill's worth of frames),
    # then exactly the program's samples, one per period
    k = core.run_period
    assert k > 0 and np.all(got[:k] == np.array(core._start))
    np.testing.assert_array_equal(got[k : k + ref.shape[0]], ref)


def test_underrun_is_a_status_and_the_output_holds():
    prog, _ = _two_moves()
    frames, _ = program_frames(prog, prefill_samples=1)
    core = DeviceCore(buffer_bytes=1 << 30, clocked=True)
    _feed(core, frames[:4])  # CONFIG, START and two setpoint frames; the rest is late
    core.advance(prog.n_samples)
    st = core.status()
    assert st.state == UNDERRUN and st.errors & ErrorFlag.UNDERRUN
    assert st.samples_done == core._received() < prog.n_samples
    assert len(set(core.output[-10:])) == 1  # held at the last sample


def test_feed_hold_stops_at_rest_and_keeps_the_limits():
    prog, split = _two_moves()
    frames, _ = program_frames(prog, prefill_samples=1)
    core = DeviceCore(buffer_bytes=1 << 30, clocked=True)
    _feed(core, frames)
    core.advance(split // 3)  # in the middle of the first move
    core.handle(decode_frame(control_frame(FrameType.HOLD, 41)))
    st = decode_status(decode_frame(core.responses.popleft()).payload)
    assert st.poll_id == 41 and st.state == RUNNING  # still moving: not yet at rest
    core.advance(split)
    assert core.state == HELD and core.samples_out < prog.n_samples
    held_at = core.samples_out
    core.advance(50)
    assert core.samples_out == held_at and len(set(core.output[-50:])) == 1
    core.handle(decode_frame(control_frame(FrameType.RESUME, 42)))
    core.advance(prog.n_samples)
    assert core.state == DONE
    # the whole output, hold included, is within the plan's own limits
    q = np.array(core.output, dtype=float) * prog.formats.pos.lsb
    ref = run_program(prog).q.astype(float) * prog.formats.pos.lsb
    v, a, j = _limits(ref, prog.dt_s)
    rep = verify_arrays(q, prog.dt_s, v, a, j)
    assert rep.ok, rep.format()
    assert q.shape[0] >= ref.shape[0] + 50


def test_abort_drops_everything_until_a_new_program():
    prog, _ = _two_moves()
    frames, _ = program_frames(prog, prefill_samples=1)
    core = DeviceCore(buffer_bytes=1 << 30, clocked=True)
    _feed(core, frames[:5], 3)
    core.handle(decode_frame(control_frame(FrameType.ABORT, 9)))
    assert core.state == ABORTED
    n = core.samples_out
    core.advance(20)
    assert core.samples_out == n
    assert not core.handle(decode_frame(frames[5]))
    assert core.status().errors & ErrorFlag.BAD_FRAME
    # a new program starts over
    _feed(core, frames)
    core.advance(prog.n_samples + 10)
    assert core.state == DONE


def test_link_reports_an_underrun():
    path = gentle_curve(3, seed=4)
    prog = build_program(quintic_plan(path, feed_mm_s=50.0))  # setpoints only: many frames
    frames, infos = program_frames(prog, prefill_samples=1)
    be = SimBackend(DeviceCore(clocked=True, samples_per_poll=2000))
    with pytest.raises(DeviceError, match="underrun"):
        UsbLink.open(backend=be).send(frames, infos)

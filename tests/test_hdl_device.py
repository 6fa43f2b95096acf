"""The whole HDL device (parser → payload decoder → datapath and setpoint FIFOs → sample merger)
fed the same bytes as the Python device: identical setpoints for every axis and identical
STATUS answers, also with corrupted, duplicated and reordered frames."""

import random

import numpy as np
import pytest

pytest.importorskip("amaranth", reason="needs the [hdl] extra (amaranth)")

from cnc_interp.fpga.frames import FrameType, poll_frame, program_frames  # noqa: E402
from cnc_interp.fpga.model import FixedSegment, SetpointBlock  # noqa: E402
from cnc_interp.fpga.program import build_program  # noqa: E402
from hdl.device_sim import run_device_hdl, run_device_python  # noqa: E402

from .fpga_cases import gentle_curve, quintic_plan  # noqa: E402


def _check(data, prog):
    qh, sh = run_device_hdl(data, len(prog.axes), prog.n_samples)
    qp, sp = run_device_python(data)
    assert qp.shape == (prog.n_samples, len(prog.axes))
    np.testing.assert_array_equal(qh, qp)
    assert sh == sp
    return sh


def _polled(chunks):
    return b"".join(c + poll_frame(500 + i) for i, c in enumerate(chunks))


@pytest.fixture(scope="module")
def three_axis():
    # XZ-plane segments on a 3-axis machine (Y held), setpoint blocks at the rests
    path = gentle_curve(3, seed=8, axes="XYZ", plane=(0, 2), other=np.array([0.0, -2.5, 0.0]))
    prog = build_program(quintic_plan(path, feed_mm_s=500.0), [path], start=None)
    kinds = {type(i) for i in prog.items}
    assert kinds == {FixedSegment, SetpointBlock}
    return prog, program_frames(prog)[0]


def test_device_outputs_every_axis_like_the_golden_model(three_axis):
    prog, frames = three_axis
    st = _check(_polled(frames), prog)
    assert st[-1][2] == 3


def test_damaged_stream_gives_the_same_setpoints(three_axis):
    prog, frames = three_axis
    rng = random.Random(3)
    chunks = []
    for f in frames:
        r = rng.random()
        if r < 0.3:
            bad = bytearray(f)
            bad[rng.randrange(len(bad))] ^= 0x40
            chunks += [bytes(bad), f]
        elif r < 0.45:
            chunks += [f, f]
        elif r < 0.6 and chunks:
            chunks.insert(len(chunks) - 1, f)
            chunks.append(f)
        else:
            chunks.append(f)
    st = _check(_polled(chunks), prog)
    assert any(s[1] for s in st)


@pytest.mark.slow
def test_dry_run_frame_file_through_the_verilog_device(tmp_path):
    # a whole `stream --dry-run` frame file (arcs as segments, rapids as setpoints), damaged on
    # the way: the generated Verilog under Verilator against the Python device
    from hdl import iverilog_sim
    from hdl.device_verilator import run_device

    if iverilog_sim.available() is None:
        import os

        if os.environ.get("CI"):
            pytest.fail("CI must install verilator (see .ci/run)")
        pytest.skip("no Verilog simulator (apt-get install verilator)")
    from cnc_interp.fpga.commands import StreamOptions, run_stream
    from cnc_interp.fpga.frames import read_frame_file

    part = tmp_path / "p.ngc"
    part.write_text(
        "G21 G18 G90 G94\nG0 X10 Z0\nF600\nG1 X10 Z-5\nG2 X14 Z-9 R4\nG1 X14 Z-15\n"
        "G3 X20 Z-21 K-6\nG1 X22 Z-30\nG0 X30 Z5\nM2\n"
    )
    out = tmp_path / "p.bin"
    run_stream(StreamOptions(part=str(part), machine_spec="xz-lathe", dry_run=str(out), quiet=True))
    frames = [f.encode() for f in read_frame_file(str(out))]
    rng = random.Random(11)
    chunks = []
    for f in frames:
        if rng.random() < 0.3:
            bad = bytearray(f)
            bad[rng.randrange(len(bad))] ^= 0x08
            chunks.append(bytes(bad))
        chunks.append(f)
    data = _polled(chunks)
    qh, sh, _ = run_device(data, 2, workdir=str(tmp_path / "sim"))
    qp, sp = run_device_python(data)
    assert qp.shape[0] > 1000
    np.testing.assert_array_equal(qh, qp)
    assert sh == sp and sp[-1][2] == 3


def test_setpoint_samples_through_the_verilog_device_at_the_byte_rate(tmp_path):
    # every sample of the program as setpoints: identical to the Python device, and the device
    # keeps up with bytes offered one per cycle — the parser's check of a frame and the decoder's
    # pass over the previous one overlap, so a 3-axis sample (24 bytes) costs about 24 cycles,
    # not the 48 of two passes one after the other (a cycle count, not a wall time)
    import dataclasses

    from hdl import iverilog_sim
    from hdl.device_verilator import run_device

    if iverilog_sim.available() is None:
        pytest.skip("no Verilog simulator (apt-get install verilator)")
    from cnc_interp.fpga.model import run_program

    path = gentle_curve(3, seed=8, axes="XYZ", plane=(0, 2), other=np.array([0.0, -2.5, 0.0]))
    prog = build_program(quintic_plan(path, feed_mm_s=60.0), [path], start=None)  # 766 samples
    sp = dataclasses.replace(prog, items=(SetpointBlock(0, 1, run_program(prog).q),))
    frames = program_frames(sp)[0]
    assert sum(f[5] == FrameType.SETPOINTS for f in frames) >= 3  # several SETPOINTS frames: the overlap is exercised
    data = _polled(frames)
    qh, sh, stamps = run_device(data, 3, workdir=str(tmp_path / "sim"))
    qp, sp_status = run_device_python(data)
    np.testing.assert_array_equal(qh, qp)
    assert sh == sp_status
    per_sample = (stamps[-1] - stamps[0]) / (len(stamps) - 1)
    assert per_sample <= 8 * 3 + 2, per_sample

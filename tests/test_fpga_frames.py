"""Frame protocol: encoding, CRC, re-synchronisation, program round trip, test vectors."""

import os
import struct
import zlib

import numpy as np
import pytest

from cnc_interp.errors import UsageError
from cnc_interp.fpga.commands import emulate_frames, trajectory_from_device
from cnc_interp.fpga.device import DONE, DeviceCore
from cnc_interp.fpga.frames import (
    HEADER_SIZE,
    MAX_PAYLOAD,
    ErrorFlag,
    FrameError,
    FrameParser,
    FrameType,
    Status,
    decode_frame,
    decode_status,
    encode_frame,
    program_frames,
    read_frame_file,
    status_frame,
)
from cnc_interp.fpga.model import run_program
from cnc_interp.fpga.program import build_program
from cnc_interp.fpga.testvectors import export_test_vectors, parse_hex_word, replay_vectors

from .fpga_cases import gentle_curve, quintic_plan


@pytest.fixture(scope="module")
def prog():
    path = gentle_curve(5, seed=11)
    traj = quintic_plan(path, feed_mm_s=60.0)
    return build_program(traj, [path], source="wave.nc"), traj


def test_header_layout_and_crc():
    raw = encode_frame(FrameType.START, 7, b"\x01\x02")
    assert raw[:4] == b"CNCF" and raw[4] == 2 and raw[5] == FrameType.START
    assert struct.unpack_from("<II", raw, 8) == (7, 2)
    assert struct.unpack_from("<I", raw, 16)[0] == zlib.crc32(raw[:16])
    assert struct.unpack_from("<I", raw, len(raw) - 4)[0] == zlib.crc32(raw[:-4])
    f = decode_frame(raw)
    assert (f.type, f.seq, f.payload) == (FrameType.START, 7, b"\x01\x02")


def test_every_single_bit_flip_is_detected():
    raw = encode_frame(FrameType.SETPOINTS, 3, bytes(range(40)))
    for i in range(len(raw)):
        for b in range(8):
            bad = bytearray(raw)
            bad[i] ^= 1 << b
            with pytest.raises(FrameError):
                decode_frame(bytes(bad))


def test_payload_limit():
    with pytest.raises(ValueError):
        encode_frame(FrameType.SETPOINTS, 1, bytes(MAX_PAYLOAD + 1))


def test_parser_resynchronises_after_garbage_and_damage():
    frames = [encode_frame(FrameType.START, i, bytes([i]) * i) for i in range(1, 6)]
    damaged = bytearray(frames[2])
    damaged[HEADER_SIZE] ^= 0xFF
    stream = b"xxCNC" + frames[0] + frames[1][:10] + frames[1] + bytes(damaged) + frames[3] + b"CN"
    p = FrameParser()
    got = []
    for k in range(0, len(stream), 7):  # arbitrary chunking
        got += p.feed(stream[k : k + 7])
    got += p.feed(frames[4])
    assert [f.seq for f in got] == [1, 2, 4, 5]
    assert p.crc_errors >= 1


def test_status_frame_round_trip():
    st = Status(1000, 17, int(ErrorFlag.CRC | ErrorFlag.DUPLICATE), 2, 12345, 99999)
    f = decode_frame(status_frame(st))
    assert f.type == FrameType.STATUS and decode_status(f.payload) == st


def test_program_frames_replay_bit_exact(prog):
    program, traj = prog
    frames, infos = program_frames(program)
    assert [i.seq for i in infos] == list(range(1, len(frames) + 1))
    assert all(len(f) <= HEADER_SIZE + MAX_PAYLOAD + 4 for f in frames)
    core = emulate_frames([decode_frame(f) for f in frames])
    assert core.state == DONE
    np.testing.assert_array_equal(core.datapath.output().q, run_program(program).q)
    out = trajectory_from_device(core)
    assert out.q.shape == traj.q.shape and out.dt_s == traj.dt_s
    assert np.max(np.abs(out.q - traj.q)) < 1e-4
    # chord length of the emulated samples vs the plan's arc length (the test curve has
    # tangent corners between segments, where chords cut across)
    assert out.s[-1] == pytest.approx(traj.s[-1], rel=1e-2)
    assert np.all(np.diff(out.s) >= 0) and out.feed[0] == 0.0


def test_long_setpoint_and_profile_data_is_split():
    path = gentle_curve(2)
    traj = quintic_plan(path, feed_mm_s=20.0, dt_s=1e-4)  # many samples
    program = build_program(traj)  # all setpoints
    frames, infos = program_frames(program)
    assert sum(i.kind == "setpoints" for i in infos) > 1
    core = emulate_frames([decode_frame(f) for f in frames])
    np.testing.assert_array_equal(core.datapath.output().q, run_program(program).q)


def test_device_rejects_out_of_order_and_duplicates(prog):
    program, _ = prog
    frames = [decode_frame(f) for f in program_frames(program)[0]]
    core = DeviceCore(buffer_bytes=1 << 30)
    assert core.handle(frames[0])
    assert not core.handle(frames[2])  # gap
    assert core.status().errors & ErrorFlag.SEQ_GAP
    assert core.handle(frames[1])
    assert not core.handle(frames[1])  # duplicate
    assert core.status().errors & ErrorFlag.DUPLICATE
    for f in frames[2:]:
        assert core.handle(f)
    assert core.applied == list(range(1, len(frames) + 1))


def test_frame_file_errors(tmp_path, prog):
    program, _ = prog
    frames, _ = program_frames(program)
    good = tmp_path / "ok.bin"
    good.write_bytes(b"".join(frames))
    assert len(read_frame_file(str(good))) == len(frames)
    bad = tmp_path / "bad.bin"
    data = bytearray(good.read_bytes())
    data[len(frames[0]) + HEADER_SIZE + 1] ^= 1
    bad.write_bytes(bytes(data))
    with pytest.raises(UsageError, match="CRC"):
        read_frame_file(str(bad))
    cut = tmp_path / "cut.bin"
    cut.write_bytes(b"".join(frames[:-1]))
    with pytest.raises(UsageError, match="STOP"):
        emulate_frames(read_frame_file(str(cut)), str(cut))


def test_test_vectors_round_trip(tmp_path, prog):
    program, _ = prog
    layout = export_test_vectors(program, str(tmp_path / "tv"), max_segments=3)
    assert layout["segments"] == 3
    with open(tmp_path / "tv" / "expected.hex") as fh:
        lines = fh.read().split()
    assert len(lines) == 5 * layout["samples"]
    assert all(len(x) == 32 for x in lines)
    expected = [tuple(parse_hex_word(x) for x in lines[i : i + 5]) for i in range(0, len(lines), 5)]
    assert replay_vectors(str(tmp_path / "tv"), program.formats) == expected
    # the q columns are the golden model's outputs for those samples
    out = run_program(program)
    first = next(i for i in program.items if hasattr(i, "pieces"))
    h, v = first.plane
    s0 = first.start_sample
    assert [e[3] for e in expected[: first.n_samples]] == list(out.q[s0 : s0 + first.n_samples, h])
    assert sorted(os.listdir(tmp_path / "tv")) == ["expected.hex", "layout.json", "pieces.hex", "segments.hex"]


def test_same_plan_gives_identical_frames():
    path = gentle_curve(5, seed=11)
    traj = quintic_plan(path, feed_mm_s=60.0)
    a, _ = program_frames(build_program(traj, [path], source="wave.nc"))
    b, _ = program_frames(build_program(traj, [path], source="wave.nc"))
    assert b"".join(a) == b"".join(b)

"""The HDL frame parser against the Python device on the same byte streams.

Identical accepted frames (type, seq, payload length) and identical STATUS answers (last
seq, error flags, state, bytes accepted, poll id, program id) for clean, corrupted,
duplicated, reordered, truncated-and-resent streams, garbage between frames, control
frames (HOLD/RESUME/ABORT) and a restart.
"""

import random

import pytest

pytest.importorskip("amaranth", reason="needs the [hdl] extra (amaranth)")

from cnc_interp.fpga.frames import FrameType, control_frame, poll_frame, program_frames  # noqa: E402
from cnc_interp.fpga.program import build_program  # noqa: E402
from hdl.parser_sim import run_hdl, run_python  # noqa: E402

from .fpga_cases import gentle_curve, quintic_plan  # noqa: E402


@pytest.fixture(scope="module")
def frames():
    path = gentle_curve(2, seed=3)
    prog = build_program(quintic_plan(path, feed_mm_s=100.0), [path], source="wave.nc")
    return program_frames(prog)[0]


def _same(data: bytes):
    hdl = run_hdl(data)
    py = run_python(data)
    assert hdl[0] == py[0], "accepted frames differ"
    assert hdl[1] == py[1], "STATUS answers differ"
    return py


def _polled(chunks):
    return b"".join(c + poll_frame(1000 + i) for i, c in enumerate(chunks))


def test_clean_stream(frames):
    acc, st = _same(_polled(frames))
    assert [s for _, s, _ in acc] == list(range(1, len(frames) + 1))
    assert st[-1][2] == 3 and st[-1][1] == 0  # done, no error


def test_dry_run_frame_file(tmp_path):
    # the very bytes `cnc-interp stream --dry-run` writes and `cnc-interp emulate` reads
    from cnc_interp.fpga.commands import StreamOptions, run_stream

    part = tmp_path / "p.ngc"
    part.write_text("G21 G18 G90 G94\nG0 X10 Z0\nF600\nG1 X10 Z-2\nG2 X12 Z-4 R2\nG1 X14 Z-6\nM2\n")
    out = tmp_path / "p.bin"
    run_stream(StreamOptions(part=str(part), machine_spec="xz-lathe", dry_run=str(out), quiet=True))
    data = out.read_bytes()
    acc, st = _same(data + poll_frame(77))
    assert st[-1][2] == 3 and st[-1][3] == len(data)


@pytest.mark.parametrize("seed", range(4))
def test_corrupted_duplicated_reordered(frames, seed):
    rng = random.Random(seed)
    chunks = []
    for f in frames:
        r = rng.random()
        if r < 0.2:  # a flipped bit, then the good copy (as the link resends)
            bad = bytearray(f)
            bad[rng.randrange(len(bad))] ^= 1 << rng.randrange(8)
            chunks += [bytes(bad), f]
        elif r < 0.35:  # sent twice
            chunks += [f, f]
        elif r < 0.5 and chunks:  # overtakes the previous frame (reordered)
            chunks.insert(len(chunks) - 1, f)
            chunks.append(f)
        elif r < 0.6:  # a partial frame, then the whole frame
            chunks += [f[: rng.randrange(1, len(f))], f]
        elif r < 0.7:  # line noise, with a stray magic
            chunks += [bytes(rng.randrange(256) for _ in range(rng.randrange(1, 40))) + b"CNCF", f]
        else:
            chunks.append(f)
    acc, st = _same(_polled(chunks))
    flags = 0
    for s in st:
        flags |= s[1]
    assert flags, "the mutations should have raised some error flag"


def test_control_frames_abort_and_restart(frames):
    data = _polled(frames[:3]) + control_frame(FrameType.HOLD, 5) + control_frame(FrameType.RESUME, 6)
    data += control_frame(FrameType.ABORT, 7) + _polled(frames[3:5])  # refused after the abort
    data += _polled(frames)  # a new program (CONFIG seq 1) starts over
    acc, st = _same(data)
    states = [s[2] for s in st]
    assert 7 in states and states[-1] == 3


def test_bad_header_fields(frames):
    import struct
    import zlib

    f = bytearray(frames[1])
    f[4] = 9  # another protocol version, with a valid header CRC: refused like a bad CRC
    struct.pack_into("<I", f, 16, zlib.crc32(bytes(f[:16])))
    acc, st = _same(_polled([frames[0], bytes(f), frames[1]]))
    assert st[1][1] & 1 and len(acc) == 2

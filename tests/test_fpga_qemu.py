"""Streaming over a real Linux USB stack (QEMU guest, dummy_hcd + FunctionFS gadget).

Opt-in: ``CNC_INTERP_QEMU=1 pytest tests/test_fpga_qemu.py``. It needs the Debian
packages qemu-system-x86 and busybox-static plus a kernel package fetched with
apt-get, and takes minutes under software emulation, so the default run leaves
it out (see ``tests/qemu/run_qemu.py``).
"""

import json
import os
import subprocess
import sys

import pytest

from cnc_interp.fpga.frames import program_frames
from cnc_interp.fpga.model import run_program
from cnc_interp.fpga.program import build_program

from .fpga_cases import gentle_curve, quintic_plan

pytestmark = pytest.mark.skipif(os.environ.get("CNC_INTERP_QEMU") != "1",
                                reason="QEMU USB integration test is opt-in (CNC_INTERP_QEMU=1)")


def test_stream_through_qemu_usb_stack(tmp_path):
    import hashlib

    path = gentle_curve(6)
    prog = build_program(quintic_plan(path, feed_mm_s=30.0), [path])
    frames, _ = program_frames(prog)
    f = tmp_path / "frames.bin"
    f.write_bytes(b"".join(frames))
    script = os.path.join(os.path.dirname(__file__), "qemu", "run_qemu.py")
    r = subprocess.run([sys.executable, script, str(f)], capture_output=True, text=True, timeout=1800)
    if r.returncode == 77:
        pytest.skip(r.stdout.strip())
    assert r.returncode == 0, r.stdout[-3000:]
    dev = json.loads(r.stdout.split("QEMU-USB-DEVICE:", 1)[1].splitlines()[0])
    assert dev["bytes_accepted"] == sum(map(len, frames))
    assert dev["last_seq"] == len(frames) and dev["in_order"] and dev["applied"] == len(frames)
    q = run_program(prog).q
    assert dev["samples"] == q.shape[0]
    assert dev["q_sha256"] == hashlib.sha256(q.astype("<i8").tobytes()).hexdigest()

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

from cnc_interp.fpga.model import run_program

pytestmark = [
    pytest.mark.qemu,
    pytest.mark.corpus,
    pytest.mark.skipif(
        os.environ.get("CNC_INTERP_QEMU") != "1", reason="QEMU USB integration test is opt-in (CNC_INTERP_QEMU=1)"
    ),
]


from .conftest import CORPUS  # noqa: E402


def test_stream_through_qemu_usb_stack(tmp_path):
    import hashlib

    from cnc_interp.fpga.commands import StreamOptions, build_stream

    # a whole corpus program (arcs as setpoint blocks, lines as segments), about 70 KB of frames
    opts = StreamOptions(
        part=os.path.join(CORPUS, "quick-tests", "arc-arc-test.ngc"),
        machine_spec=os.path.join(CORPUS, "configs", "XYZ.ini"),
    )
    prog, frames, _ = build_stream(opts)
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

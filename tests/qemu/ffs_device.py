"""The emulated controller as a real USB gadget (Linux FunctionFS), for the QEMU integration test.

    python ffs_device.py FFS_MOUNT STATE.json

Writes the descriptors and strings to FFS_MOUNT/ep0, then serves the bulk
endpoints with ``DeviceCore``: ep2 (OUT) carries frames to the core, ep1 (IN)
carries the STATUS answers to POLL frames. When the host calls
set_configuration the endpoint files return ESHUTDOWN; they are reopened after
the next ENABLE event. After every OUT transfer the device's state (last seq,
CRC-checked bytes, samples and a SHA-256 of its setpoints) is written to
STATE.json.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import struct
import sys
import threading
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", ".."))

from cnc_interp.fpga.device import DeviceCore  # noqa: E402

FS_MAGIC_V2, STR_MAGIC = 3, 2
HAS_FS, HAS_HS = 1, 2
EVENT_SIZE = 12
BIND, UNBIND, ENABLE, DISABLE, SETUP = 0, 1, 2, 3, 4


def descriptors() -> bytes:
    intf = struct.pack("<BBBBBBBBB", 9, 4, 0, 0, 2, 0xFF, 0, 0, 1)

    def eps(mps):
        return struct.pack("<BBBBHB", 7, 5, 0x81, 2, mps, 0) + struct.pack("<BBBBHB", 7, 5, 0x02, 2, mps, 0)

    body = struct.pack("<II", 3, 3) + intf + eps(64) + intf + eps(512)
    return struct.pack("<III", FS_MAGIC_V2, 12 + len(body), HAS_FS | HAS_HS) + body


def strings() -> bytes:
    body = struct.pack("<H", 0x0409) + b"cnc-interp FPGA emulator\0"
    return struct.pack("<IIII", STR_MAGIC, 16 + len(body), 1, 1) + body


def main() -> int:
    ffs, state_path = sys.argv[1], sys.argv[2]
    ep0 = os.open(os.path.join(ffs, "ep0"), os.O_RDWR)
    os.write(ep0, descriptors())
    os.write(ep0, strings())
    enabled = threading.Event()

    def events():
        while True:
            data = os.read(ep0, EVENT_SIZE * 4)
            for i in range(0, len(data), EVENT_SIZE):
                kind = data[i + 8]
                if kind == ENABLE:
                    enabled.set()
                elif kind in (DISABLE, UNBIND):
                    enabled.clear()

    threading.Thread(target=events, daemon=True).start()
    core = DeviceCore()
    ep_in = ep_out = None
    while True:
        if ep_out is None:
            enabled.wait()
            ep_in = os.open(os.path.join(ffs, "ep1"), os.O_WRONLY)
            ep_out = os.open(os.path.join(ffs, "ep2"), os.O_RDONLY)
        try:
            data = os.read(ep_out, 65536)
            core.receive(data)
            while core.responses:
                os.write(ep_in, core.responses[0])
                core.responses.popleft()
        except OSError as exc:
            if exc.errno in (errno.ESHUTDOWN, errno.ECONNRESET, errno.EINTR):
                # set_configuration / reset: reopen after the next ENABLE
                for fd in (ep_in, ep_out):
                    try:
                        os.close(fd)
                    except OSError:
                        pass
                ep_in = ep_out = None
                time.sleep(0.05)
                continue
            raise
        q = core.datapath.output().q if core.datapath is not None else None
        state = {
            "last_seq": core.last_seq,
            "bytes_accepted": core.bytes_accepted,
            "state": core.state,
            "applied": len(core.applied),
            "in_order": core.applied == list(range(1, len(core.applied) + 1)),
            "samples": 0 if q is None else int(q.shape[0]),
            "q_sha256": "" if q is None else hashlib.sha256(q.astype("<i8").tobytes()).hexdigest(),
        }
        tmp = state_path + ".tmp"
        with open(tmp, "w") as fh:
            json.dump(state, fh)
        os.replace(tmp, state_path)


if __name__ == "__main__":
    sys.exit(main())

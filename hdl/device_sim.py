"""The whole HDL device (``hdl/device.py``) fed a byte stream, against the Python device.

``run_device_hdl(data, n_axes)`` returns the samples the HDL device outputs, (K, n_axes)
ints, and its STATUS answers; ``run_device_python(data)`` the golden model's samples
(``DeviceCore`` fed the same bytes) and STATUS answers.
"""

from __future__ import annotations

import numpy as np
from amaranth.sim import Simulator

from .device import Device


def run_device_hdl(data: bytes, n_axes: int, n_samples: int, fmts=None):
    dut = Device(fmts, buffer_bits=13)
    vals: list = []
    statuses: list = []
    state = {"fed": False}

    async def feeder(ctx):
        ctx.set(dut.tick, 1)
        i = 0
        while i < len(data):
            ctx.set(dut.in_data, data[i])
            ctx.set(dut.in_valid, 1)
            await ctx.tick()
            if ctx.get(dut.in_ready):
                i += 1
        ctx.set(dut.in_valid, 0)
        state["fed"] = True

    async def watcher(ctx):
        idle = 0
        async for _c, _r, sv, sa, sval, stv, ls, er, st in ctx.tick().sample(
            dut.smp_valid, dut.smp_axis, dut.smp_value, dut.status_valid, dut.st_last_seq, dut.st_errors, dut.st_state
        ):
            if sv:
                vals.append(sval)
                idle = 0
            if stv:
                statuses.append((ls, er, st))
            if len(vals) >= n_samples * n_axes and state["fed"]:
                idle += 1
                if idle > 4 * len(data) + 500:
                    return
            elif state["fed"]:
                idle += 1
                if idle > 4 * len(data) + 200 * 64:
                    return

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(feeder, background=True)
    sim.add_testbench(watcher)
    sim.run()
    q = np.array(vals[: len(vals) - len(vals) % n_axes], dtype=np.int64).reshape(-1, n_axes)
    return q, statuses


def run_device_python(data: bytes):
    from cnc_interp.fpga.device import DeviceCore
    from cnc_interp.fpga.frames import decode_frame, decode_status

    core = DeviceCore(buffer_bytes=1 << 31)
    statuses = []
    for b in data:
        core.receive(bytes([b]))
        while core.responses:
            st = decode_status(decode_frame(core.responses.popleft()).payload)
            statuses.append((st.last_seq, st.errors, st.state))
    q = core.datapath.output().q if core.datapath is not None else np.zeros((0, 0), np.int64)
    return q, statuses

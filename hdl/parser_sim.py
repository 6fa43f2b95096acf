"""Feed a byte stream to the HDL frame parser (Amaranth simulator) and to the Python device.

``run_hdl(data)`` returns the parser's accepted frames [(type, seq, payload length)] and its
STATUS snapshots [(last seq, errors, state, bytes accepted, poll id, program id)];
``run_python(data)`` the same from ``DeviceCore`` fed byte by byte (as the device's
USB front end would hand bytes to its parser).
"""

from __future__ import annotations

from amaranth.sim import Simulator

from .frame_parser import FrameParser


def run_hdl(data: bytes, clocked: bool = False, buffer_bits: int = 13):
    dut = FrameParser(clocked, buffer_bits)
    accepted, statuses = [], []
    done = {"n": 0}

    async def feeder(ctx):
        i = 0
        ctx.set(dut.dec_ready, 1)  # no decoder behind the parser here: payloads are dropped
        while i < len(data):
            ctx.set(dut.in_data, data[i])
            ctx.set(dut.in_valid, 1)
            await ctx.tick()
            if ctx.get(dut.in_ready):
                i += 1
        ctx.set(dut.in_valid, 0)
        done["n"] = 1

    async def watcher(ctx):
        idle = 0
        async for _c, _r, av, at, aseq, alen, sv, ls, er, st, by, pid, prg in ctx.tick().sample(
            dut.acc_valid,
            dut.acc_type,
            dut.acc_seq,
            dut.acc_len,
            dut.status_valid,
            dut.st_last_seq,
            dut.st_errors,
            dut.st_state,
            dut.st_bytes,
            dut.st_poll_id,
            dut.st_program_id,
        ):
            if av:
                accepted.append((at, aseq, alen))
            if sv:
                statuses.append((ls, er, st, by, pid, prg))
            idle = idle + 1 if done["n"] else 0
            if idle > 4 * len(data) + 200:  # ample: every byte is read twice, one cycle per read
                return

    sim = Simulator(dut)
    sim.add_clock(1e-8)
    sim.add_testbench(feeder, background=True)
    sim.add_testbench(watcher)
    sim.run()
    return accepted, statuses


def run_python(data: bytes):
    from cnc_interp.fpga.device import DeviceCore
    from cnc_interp.fpga.frames import decode_frame, decode_status

    core = DeviceCore(buffer_bytes=1 << 31)
    accepted, statuses = [], []
    orig = core.handle

    def handle(f):
        ok = orig(f)
        if ok:
            accepted.append((int(f.type), f.seq, len(f.payload)))
        while core.responses:
            st = decode_status(decode_frame(core.responses.popleft()).payload)
            statuses.append((st.last_seq, st.errors, st.state, st.bytes_accepted, st.poll_id, st.program_id))
        return ok

    core.handle = handle
    for b in data:
        core.receive(bytes([b]))
    return accepted, statuses

"""``cnc-interp emulate`` and ``cnc-interp stream``: the FPGA stage's command functions."""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

from ..errors import SourceLocation, UsageError

#: the name ending of a frame file (``stream --dry-run FRAMES.bin``, ``emulate FRAMES.bin``)
FRAMES_SUFFIX = ".bin"


@dataclass(frozen=True)
class StreamOptions:
    """Options of ``cnc-interp stream`` (same planning options as ``plan``)."""

    part: str
    machine_spec: str | None
    planner: str = "variable"
    dt_s: float | None = None
    tol_mm: float | None = None
    fit_method: str | None = None
    effort: str | None = None
    device: str | None = None
    dry_run: str | None = None
    resume_from: int | None = None
    quiet: bool = False


def _say(quiet: bool, msg: str) -> None:
    if not quiet:
        sys.stderr.write(msg + "\n")
        sys.stderr.flush()


# -- emulate ---------------------------------------------------------------------------------
def emulate_frames(frames, source: str = "<frames>", sink=None):
    """Feed decoded frames to a device core in order; returns the core (raises UsageError on
    a reject). ``sink(q, line)``, if given, takes the samples as they are computed (see
    ``model.DatapathState``) instead of the core keeping them."""
    from .device import DONE, DeviceCore
    from .frames import CONTROL_TYPES, ErrorFlag

    core = DeviceCore(buffer_bytes=1 << 62, sink=sink)
    for i, f in enumerate(frames):
        if f.type in CONTROL_TYPES:  # a host request, never part of a program's stream
            raise UsageError(
                f"frame {i + 1} (seq {f.seq}) is a {f.type.name} frame; a frame file holds a program's frames only",
                SourceLocation(file=source),
            )
        if not core.handle(f):
            flags = ErrorFlag(core.status().errors)
            raise UsageError(
                f"frame {i + 1} (seq {f.seq}, {f.type.name}) rejected by the device model: {flags!r}",
                SourceLocation(file=source),
            )
    if core.state != DONE:
        raise UsageError("the frame file ends before its STOP frame (truncated?)", SourceLocation(file=source))
    return core


def trajectory_from_device(core, planner: str = "fpga-emulate"):
    """The device's setpoints as a ``Trajectory`` (s = chord length of the emulated samples)."""
    from ..gcode.program import move_lengths
    from ..plan.trajectory import Trajectory
    from .model import to_mm

    dp = core.datapath
    out = dp.output()
    q = to_mm(out.q, dp.formats)
    dt = float(core.dt_s)
    K = q.shape[0]
    step = move_lengths(q, dp.axes) if K else np.zeros(0)
    s = np.concatenate(([0.0], np.cumsum(step))) if K else np.zeros(0)
    feed = np.concatenate(([0.0], step / dt)) if K else np.zeros(0)
    return Trajectory(axes=dp.axes, dt_s=dt, t=np.arange(K) * dt, s=s, feed=feed, q=q, line=out.line, planner=planner)


def emulate_file(frames_path: str, out: str) -> None:
    """Replay a frame file through the bit-exact model and write its setpoints as plan CSV."""
    from ..outfile import atomic_write, check_writable, output_format
    from .frames import read_frame_file

    check_writable(out, inputs=(frames_path,))
    output_format(out, {".csv": "csv"}, "emulated setpoints", stdout="csv")
    frames = read_frame_file(frames_path)
    with atomic_write(out) as fh:  # nothing is left behind when a frame is refused
        sink = _CsvSink(fh, frames)
        emulate_frames(frames, frames_path, sink=sink)
        sink.finish()


class _CsvSink:
    """The emulated samples written as plan CSV as they are computed (``emulate``): the
    same bytes as ``write_csv(trajectory_from_device(core))``, in memory a block at a time
    (a frame file of 500 bytes may ask for 2^24 samples). s is the chord length, carried
    over blocks in the order ``np.cumsum`` adds; feed the chord over dt."""

    def __init__(self, fh, frames):
        from .frames import FrameError, FrameType, decode_config

        self.fh = fh
        self.writer = None
        cfg = None
        if frames and frames[0].type == FrameType.CONFIG:
            try:
                cfg = decode_config(frames[0].payload)
            except FrameError:  # the device model refuses the frame and says why
                pass
        self.axes = cfg.axes if cfg is not None else ""
        self.formats = cfg.formats if cfg is not None else None
        self.dt = float(cfg.dt_s) if cfg is not None else 0.0
        self.k = 0
        self.s = 0.0
        self.last = None  # the previous sample (mm), for the first chord of a block

    def finish(self) -> None:
        """The header alone when the program had no samples."""
        if self.writer is None:
            from ..export.csv_io import CsvPlanWriter

            self.writer = CsvPlanWriter(self.fh, self.axes)

    def __call__(self, q_int: np.ndarray, line: int) -> None:
        from ..gcode.program import move_lengths
        from .model import to_mm

        self.finish()
        m = q_int.shape[0]
        if m == 0:
            return
        q = to_mm(q_int, self.formats)
        if self.last is None:
            step = np.concatenate(([0.0], move_lengths(q, self.axes)))
        else:
            step = move_lengths(np.vstack((self.last[None, :], q)), self.axes)
        s = np.cumsum(np.concatenate(([self.s], step)))[1:]
        feed = step / self.dt
        t = np.arange(self.k, self.k + m) * self.dt
        self.writer.write(t, s, feed, q)
        self.k += m
        self.s = float(s[-1])
        self.last = q[-1].copy()


# -- stream ----------------------------------------------------------------------------------
def plan_for_stream(opts: StreamOptions, formats=None, with_machine: bool = False):
    """Parse, fit, plan and verify like ``plan`` does: (FitResult, Trajectory[, Machine]).

    ``api.run`` on the machine's limits less the device margin (``fpga/limits.py``), so
    that the device's rounded setpoints hold the real limits; ``with_machine`` also
    returns the real machine (limits unscaled).
    """
    from .fixed import FpgaFormats
    from .limits import device_margin, with_margin

    from ..api import read_part, run
    from ..machine.load import DEFAULT_PRESET, load_machine
    from ..plan.settings import PlanSettings

    machine = load_machine(opts.machine_spec if opts.machine_spec is not None else DEFAULT_PRESET)
    settings = PlanSettings.from_options(
        planner=opts.planner, dt_s=opts.dt_s, tol_mm=opts.tol_mm, machine=machine, effort=opts.effort
    )
    real = machine.with_dt(settings.dt_s)
    name, data = read_part(opts.part)
    margined = with_margin(real, device_margin(real, formats or FpgaFormats(), name))
    res = run(data, margined, tol_mm=opts.tol_mm, fit_method=opts.fit_method, plan_settings=settings, name=name)
    return (res.fit, res.trajectory, real) if with_machine else (res.fit, res.trajectory)


def build_stream(opts: StreamOptions):
    """Plan and quantize: (FpgaProgram, frames, frame infos)."""
    prog, frames, infos, _traj, _machine = build_stream_full(opts)
    return prog, frames, infos


def build_stream_full(opts: StreamOptions):
    """Plan and quantize: (FpgaProgram, frames, infos, planned Trajectory, real Machine)."""
    from .frames import program_frames
    from .program import build_program

    from ..errors import PlanError

    fit, traj, machine = plan_for_stream(opts, with_machine=True)
    source = "<stdin>" if opts.part == "-" else opts.part
    idx = [machine.axes.index(a) for a in traj.axes]
    prog = build_program(traj, fit.paths, source=source, limits=machine.limits()[:, idx])
    if not prog.stats["verify_ok"]:
        # a device must never be sent a stream that breaks the machine's limits
        raise PlanError(
            f"refusing to stream: the device's setpoints would exceed the "
            f"{prog.stats['verify_worst']} limit (ratio {prog.stats['verify_ratio']:.12g})",
            SourceLocation(file=source),
        )
    frames, infos = program_frames(prog)
    return prog, frames, infos, traj, machine


def summary_line(prog, frames) -> str:
    st = prog.stats
    return (
        f"fpga: {len(frames)} frames, {sum(map(len, frames))} bytes, {st['segments']} segments "
        f"({st['profile_pieces']} profile pieces), {st['setpoint_samples']} of {prog.n_samples} "
        f"samples as setpoint blocks; worst deviation from the float plan "
        f"{st['max_dev_mm'] * 1e3:.4f} µm, segment-end drift {st['max_segment_end_drift_mm'] * 1e3:.2e} µm; "
        f"{st.get('repaired_segments', 0)} segments re-sent as setpoints for the limits, "
        f"device verify ratio {st.get('verify_ratio', float('nan')):.9f}"
    )


def run_stream(opts: StreamOptions, backend=None) -> None:
    """``cnc-interp stream``: plan, quantize, then write frames (``--dry-run``, a ``.bin``
    file) or send them over USB."""
    from ..outfile import atomic_write, check_writable, output_format

    if opts.dry_run and opts.resume_from is not None:
        raise UsageError("--resume-from applies to a device, not to --dry-run")
    if opts.dry_run:
        from ..machine.load import DEFAULT_PRESET, load_machine

        # the machine's tool table (an INI's [EMCIO] TOOL_TABLE) is an input too
        table = load_machine(opts.machine_spec if opts.machine_spec is not None else DEFAULT_PRESET).tool_table
        check_writable(opts.dry_run, inputs=(opts.part, opts.machine_spec, table))
        output_format(opts.dry_run, {FRAMES_SUFFIX: "frames"}, "frames")
    prog, frames, infos = build_stream(opts)
    _say(opts.quiet, summary_line(prog, frames))
    for why in prog.stats.get("fallback_paths", []):
        _say(opts.quiet, f"fpga: sent as setpoints: {why}")
    if opts.dry_run:
        with atomic_write(opts.dry_run) as fh:
            fh.write(b"".join(frames))
        return
    from .usb_link import UsbLink

    link = UsbLink.open(opts.device, backend=backend)
    source = "<stdin>" if opts.part == "-" else opts.part
    rep = link.send(frames, infos, resume_from=opts.resume_from, source=source)
    fin = rep.final
    _say(
        opts.quiet,
        f"usb: sent frames {rep.first_seq}..{len(frames)} ({rep.bytes_sent} bytes); "
        f"retries {rep.retries}, timeouts {rep.timeouts}, stalls {rep.stalls}, "
        f"CRC rejects {rep.crc_rejects}; device accepted {fin.bytes_accepted} bytes, "
        f"{fin.samples_done} samples",
    )


# -- sending a frame file ------------------------------------------------------------------------
def frame_infos(frames) -> list:
    """``FrameInfo`` (kind, segment, source line) of decoded frames, for link messages."""
    import struct as _struct

    from .frames import FrameInfo, FrameType

    infos = []
    for f in frames:
        seg, line = -1, 0
        if f.type in (FrameType.SEGMENT, FrameType.PROFILE) and len(f.payload) >= 8:
            seg = _struct.unpack_from("<I", f.payload)[0]
            if f.type == FrameType.SEGMENT:
                line = _struct.unpack_from("<I", f.payload, 4)[0]
            elif infos and infos[-1].segment == seg:
                line = infos[-1].line
        elif f.type == FrameType.SETPOINTS and len(f.payload) >= 17:
            line = _struct.unpack_from("<I", f.payload, 13)[0]
        infos.append(FrameInfo(f.seq, f.type.name.lower(), seg, line))
    return infos


def send_frame_file(frames_path: str, device: str | None = None, resume_from: int | None = None, backend=None):
    """Send a ``--dry-run`` frame file to the device as it is; returns the ``LinkReport``."""
    from .frames import read_frame_file
    from .usb_link import UsbLink

    frames = read_frame_file(frames_path)
    raw = [f.encode() for f in frames]
    link = UsbLink.open(device, backend=backend)
    return link.send(raw, frame_infos(frames), resume_from=resume_from, source=frames_path)

"""Host side of the USB link: pyusb bulk transfers with flow control, retries and resume.

The host sends one frame at a time and reads the device's status after it
(stop-and-wait): the status's ``last_seq`` acknowledges the frame, its
``free_bytes`` gates the next one (flow control). A frame is resent, whole,
after a timeout, a short write that could not be completed, a stall (cleared
with CLEAR_HALT) or a CRC rejection; the device ignores a seq it already
accepted, so a resent frame is never applied twice. A disconnect ends with a
``DeviceError`` naming the last acknowledged frame, its segment and source line,
and the ``--resume-from SEQ`` that continues from there.

pyusb and the libusb backend (the ``libusb-package`` wheel) are imported lazily.
"""

from __future__ import annotations

import errno
from dataclasses import dataclass, field

from ..constants import FPGA_USB_PID, FPGA_USB_VID
from ..errors import DeviceError, SourceLocation, UsageError
from .frames import (
    ErrorFlag,
    FrameError,
    FrameInfo,
    FrameType,
    Status,
    decode_frame,
    decode_status,
    poll_frame,
)


#: USB transfer timeout (ms) and retry budget per frame
FPGA_USB_TIMEOUT_MS = 1000

FPGA_USB_RETRIES = 8

#: polls of an unchanged full buffer before the link gives up (flow-control stall)
FPGA_USB_STALL_POLLS = 10_000

_STATUS_READ_BYTES = 512
_NO_DEVICE_CODES = {-4}  # LIBUSB_ERROR_NO_DEVICE
_PIPE_CODES = {-9}  # LIBUSB_ERROR_PIPE


def parse_device_id(spec: str | None) -> tuple[int, int]:
    """``"VID:PID"`` in hex -> (vid, pid); ``None`` -> the default ids."""
    if spec is None:
        return FPGA_USB_VID, FPGA_USB_PID
    try:
        vid, pid = spec.split(":")
        v, p = int(vid, 16), int(pid, 16)
        if not (0 <= v <= 0xFFFF and 0 <= p <= 0xFFFF):
            raise ValueError
        return v, p
    except ValueError:
        raise UsageError(f"--device must be VID:PID in hex, got '{spec}'") from None


@dataclass
class LinkReport:
    """What happened on the link (counts), and the device's final status."""

    frames_sent: int = 0
    bytes_sent: int = 0
    first_seq: int = 1
    retries: int = 0
    timeouts: int = 0
    short_writes: int = 0
    stalls: int = 0
    crc_rejects: int = 0
    status_polls: int = 0
    stale_status: int = 0
    device_errors: int = 0
    final: Status | None = None
    notes: list = field(default_factory=list)


def _is_disconnect(exc) -> bool:
    return getattr(exc, "errno", None) == errno.ENODEV or getattr(exc, "backend_error_code", None) in _NO_DEVICE_CODES


def _is_stall(exc) -> bool:
    return getattr(exc, "errno", None) == errno.EPIPE or getattr(exc, "backend_error_code", None) in _PIPE_CODES


class _Disconnected(Exception):
    pass


class UsbLink:
    """An opened controller: bulk OUT for frames, bulk IN for status frames."""

    def __init__(
        self,
        dev,
        ep_out,
        ep_in,
        timeout_ms: int = FPGA_USB_TIMEOUT_MS,
        retries: int = FPGA_USB_RETRIES,
        stall_polls: int = FPGA_USB_STALL_POLLS,
    ):
        self.dev, self.ep_out, self.ep_in = dev, ep_out, ep_in
        self.timeout_ms, self.retries, self.stall_polls = timeout_ms, retries, stall_polls
        self.report = LinkReport()
        self._poll_id = 0
        self.program_id: int | None = None

    @classmethod
    def open(cls, device: str | None = None, backend=None, **kw) -> "UsbLink":
        """Find and configure the controller (``backend`` default: libusb from libusb-package)."""
        import usb.core
        import usb.util

        vid, pid = parse_device_id(device)
        if backend is None:
            import libusb_package

            backend = libusb_package.get_libusb1_backend()
            if backend is None:
                raise DeviceError("no libusb backend could be loaded (libusb-package)")
        try:
            dev = usb.core.find(idVendor=vid, idProduct=pid, backend=backend)
        except usb.core.USBError as exc:
            raise DeviceError(f"USB enumeration failed: {exc}") from None
        if dev is None:
            raise DeviceError(
                f"no USB device {vid:04x}:{pid:04x} found (is the controller plugged in, and may this user open it?)"
            )
        try:
            dev.set_configuration()
            intf = dev.get_active_configuration()[(0, 0)]
        except usb.core.USBError as exc:
            raise DeviceError(f"cannot configure USB device {vid:04x}:{pid:04x}: {exc}") from None

        def ep(direction):
            return usb.util.find_descriptor(
                intf, custom_match=lambda e: usb.util.endpoint_direction(e.bEndpointAddress) == direction
            )

        ep_out, ep_in = ep(usb.util.ENDPOINT_OUT), ep(usb.util.ENDPOINT_IN)
        if ep_out is None or ep_in is None:
            raise DeviceError(f"USB device {vid:04x}:{pid:04x} has no bulk OUT/IN endpoint pair")
        return cls(dev, ep_out, ep_in, **kw)

    # -- status ------------------------------------------------------------------------------
    def status(self) -> Status:
        """Ask for and read one status frame (POLL -> STATUS with the same poll id).

        Answers to older polls (left over after a timeout) are read and dropped;
        a poll without an answer is repeated with a new id.
        """
        import usb.core

        for _ in range(self.retries + 1):
            self._poll_id += 1
            pid = self._poll_id
            self.report.status_polls += 1
            if not self._write_all(poll_frame(pid), count=False):
                continue
            for _ in range(self.retries + 1):
                try:
                    raw = bytes(self.ep_in.read(_STATUS_READ_BYTES, self.timeout_ms))
                except usb.core.USBTimeoutError:
                    self.report.timeouts += 1
                    break
                except usb.core.USBError as exc:
                    if _is_disconnect(exc):
                        raise _Disconnected() from None
                    if _is_stall(exc):
                        self._clear(self.ep_in)
                        break
                    raise DeviceError(f"USB read failed: {exc}") from None
                try:
                    f = decode_frame(raw)
                    if f.type != FrameType.STATUS:
                        raise FrameError("not a status frame")
                    st = decode_status(f.payload)
                except FrameError:
                    self.report.crc_rejects += 1
                    continue
                if st.poll_id != pid:
                    self.report.stale_status += 1
                    continue
                if st.errors:
                    self.report.device_errors += 1
                if st.state == 6:  # UNDERRUN: the sample clock ran out of samples
                    raise DeviceError(
                        f"the device ran out of samples at sample {st.samples_done} "
                        "(underrun: the link is slower than the motion); its output "
                        "holds there"
                    )
                if st.state == 7:
                    raise DeviceError(f"the device aborted the program at sample {st.samples_done}")
                return st
        raise DeviceError(f"the device answered no status request in {self.retries + 1} attempts")

    def _clear(self, ep) -> None:
        import usb.core

        self.report.stalls += 1
        try:
            self.dev.clear_halt(ep)
        except usb.core.USBError as exc:
            if _is_disconnect(exc):
                raise _Disconnected() from None
            raise DeviceError(f"cannot clear a stalled endpoint: {exc}") from None

    def _wait_room(self, need: int, st: Status) -> Status:
        """Poll status until the device has ``need`` free bytes (flow control)."""
        idle = 0
        while st.free_bytes < need:
            prev = (st.free_bytes, st.samples_done)
            st = self.status()
            idle = idle + 1 if (st.free_bytes, st.samples_done) == prev else 0
            if idle >= self.stall_polls:
                raise DeviceError(
                    f"the device buffer stays full ({st.free_bytes} bytes free, "
                    f"{need} needed) and it reports no progress"
                )
        return st

    def _write_all(self, data: bytes, count: bool = True) -> bool:
        """Write a whole frame; False if it must be resent (timeout, stall, no progress)."""
        import usb.core

        off = 0
        while off < len(data):
            try:
                n = int(self.ep_out.write(data[off:], self.timeout_ms))
            except usb.core.USBTimeoutError:
                self.report.timeouts += 1
                return False
            except usb.core.USBError as exc:
                if _is_disconnect(exc):
                    raise _Disconnected() from None
                if _is_stall(exc):
                    self._clear(self.ep_out)
                    return False
                raise DeviceError(f"USB write failed: {exc}") from None
            if n <= 0:
                return False
            if off + n < len(data):
                self.report.short_writes += 1
            off += n
        if count:
            self.report.bytes_sent += len(data)
        return True

    # -- the stream ------------------------------------------------------------------------------
    def send(
        self, frames: list[bytes], infos: list[FrameInfo], resume_from: int | None = None, source: str = "<input>"
    ) -> LinkReport:
        """Send every frame (or those after ``resume_from``) exactly once to the device."""
        rep = self.report
        acked = resume_from or 0
        self.program_id = _program_id(frames)
        try:
            st = self.status()
            acked = self._first_seq(st, len(frames), resume_from, infos, source)
            rep.first_seq = acked + 1
            for i in range(acked, len(frames)):
                seq, data = i + 1, frames[i]
                attempts = 0
                ok_last = True
                while True:
                    if attempts > self.retries:
                        raise DeviceError(
                            f"frame {seq} ({_describe(infos[i], source)}) was not accepted after "
                            f"{attempts} attempts (last device error flags: {ErrorFlag(st.errors)!r})",
                            _loc(infos[i], source),
                        )
                    if ok_last:
                        st = self._wait_room(len(data), st)
                    ok = ok_last = self._write_all(data)
                    if not ok:
                        # resend at once: part of this frame may sit in the device's
                        # parser, and the full copy completes it and is found after it
                        attempts += 1
                        rep.retries += 1
                        continue
                    st = self.status()
                    if st.last_seq >= seq:
                        break
                    attempts += 1
                    rep.retries += 1
                    if ok and st.errors & (ErrorFlag.CRC | ErrorFlag.SEQ_GAP):
                        rep.crc_rejects += 1
                    if ok and st.errors & (ErrorFlag.BAD_FRAME | ErrorFlag.OVERRUN):
                        raise DeviceError(
                            f"the device rejected frame {seq} "
                            f"({_describe(infos[i], source)}): {ErrorFlag(st.errors)!r}",
                            _loc(infos[i], source),
                        )
                acked = seq
                rep.frames_sent += 1
            rep.final = st
        except _Disconnected:
            raise DeviceError(
                _disconnect_message(acked, infos, source),
                _loc(infos[acked - 1], source) if acked else SourceLocation(file=source),
            ) from None
        return rep

    def _first_seq(
        self, st: Status, n_frames: int, resume_from: int | None, infos: list[FrameInfo], source: str
    ) -> int:
        if resume_from is None:
            if st.last_seq and st.state not in (0, 3, 7):
                raise DeviceError(
                    f"the device holds a partly sent program (up to frame {st.last_seq}); "
                    f"resume with --resume-from {st.last_seq} or power-cycle it"
                )
            return 0
        if resume_from < 0 or resume_from > n_frames:
            raise UsageError(f"--resume-from {resume_from} is outside 0..{n_frames} (frames of this program)")
        if st.last_seq < resume_from:
            raise DeviceError(
                f"cannot resume from frame {resume_from}: the device acknowledges only "
                f"up to frame {st.last_seq} (use --resume-from {st.last_seq})"
            )
        other = self.program_id is not None and st.program_id != self.program_id
        if st.last_seq > n_frames or (st.last_seq > 0 and other):
            raise DeviceError(
                f"the device holds another program (id {st.program_id:08x}, frame "
                f"{st.last_seq}) than this one (id {self.program_id or 0:08x}, {n_frames} "
                "frames): resume with the same part, machine and planning options"
            )
        return st.last_seq


def _program_id(frames: list[bytes]) -> int | None:
    """The program id a CONFIG frame announces (None if the first frame is not a CONFIG)."""
    from .frames import decode_config

    try:
        f = decode_frame(frames[0])
        return decode_config(f.payload).program_id if f.type == FrameType.CONFIG else None
    except (FrameError, IndexError):
        return None


def _describe(info: FrameInfo, source: str) -> str:
    if info.segment >= 0:
        return f"{info.kind} frame of segment {info.segment}, {source} line {info.line}"
    if info.line > 0:
        return f"{info.kind} frame, {source} line {info.line}"
    return f"{info.kind} frame"


def _loc(info: FrameInfo, source: str) -> SourceLocation:
    return SourceLocation(file=source, line=info.line, col=1 if info.line > 0 else 0)


def _disconnect_message(acked: int, infos: list[FrameInfo], source: str) -> str:
    if acked == 0:
        return "the USB device disconnected before it acknowledged any frame; reconnect it and run again"
    return (
        f"the USB device disconnected; the last acknowledged frame is {acked} of {len(infos)} "
        f"({_describe(infos[acked - 1], source)}); reconnect it and run the same command with "
        f"--resume-from {acked}"
    )

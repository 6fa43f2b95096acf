"""The host <-> FPGA frame protocol (specified in ``docs/fpga-protocol.md``).

Every frame, little-endian::

    offset  size  field
    0       4     magic  b"CNCF"
    4       1     version (1)
    5       1     type (FrameType)
    6       2     flags (0; reserved)
    8       4     seq: sequence number, 1, 2, 3 ... per program (status frames echo the last accepted)
    12      4     length: payload bytes (<= MAX_PAYLOAD)
    16      4     header CRC-32 of bytes 0..15 (lets a receiver re-synchronise on a bad header)
    20      n     payload
    20+n    4     CRC-32 of bytes 0..20+n-1 (header and payload)

CRC-32 is zlib's (IEEE 802.3, reflected, init and final xor 0xFFFFFFFF).
"""

from __future__ import annotations

import enum
import struct
import zlib
from dataclasses import dataclass

import numpy as np

from ..constants import ALL_AXES
from .fixed import FpgaFormats
from .model import FixedSegment, FpgaProgram, ProfilePiece, SetpointBlock


#: largest frame payload (bytes); longer data is split over several frames
FPGA_MAX_PAYLOAD = 4096

#: motion the device buffers after START before its sample clock runs (s)
FPGA_PREFILL_S = 0.25

MAGIC = b"CNCF"
VERSION = 2  # 2: separate Horner/integrator widths, x_end as mantissa + exponent
HEADER = struct.Struct("<4sBBHII")
HEADER_SIZE = HEADER.size + 4
TRAILER_SIZE = 4
MAX_PAYLOAD = FPGA_MAX_PAYLOAD


class FrameType(enum.IntEnum):
    CONFIG = 1
    SEGMENT = 2
    PROFILE = 3
    SETPOINTS = 4
    START = 5
    STOP = 6
    STATUS = 7
    POLL = 8  # host asks for one STATUS; unsequenced (seq field = poll id)
    HOLD = 9  # feed hold: stop at the next sample where the plan is at rest; unsequenced
    RESUME = 10  # leave a hold (or cancel a pending one); unsequenced
    ABORT = 11  # stop at once and drop everything; unsequenced


#: control frames: acted on at once, outside the sequence, each answered by one STATUS
CONTROL_TYPES = (FrameType.POLL, FrameType.HOLD, FrameType.RESUME, FrameType.ABORT)


class ErrorFlag(enum.IntFlag):
    """Bits of the status frame's ``errors`` field (cleared when a status is read)."""

    CRC = 1  # a frame failed its CRC (header or payload)
    SEQ_GAP = 2  # a frame arrived with seq > last accepted + 1 (one was lost)
    BAD_FRAME = 4  # unknown type/version, malformed payload, item out of order
    OVERFLOW = 8  # more bytes arrived than the buffer had room for
    OVERRUN = 16  # a fixed-point overflow inside the datapath
    DUPLICATE = 32  # a frame with seq <= last accepted arrived (ignored)
    UNDERRUN = 64  # the sample clock needed a sample that had not arrived (output held)


# -- payload layouts ------------------------------------------------------------------------
#: sample periods a CONFIG frame may carry, s (the machine files' range)
CONFIG_DT_MIN_S, CONFIG_DT_MAX_S = 1e-6, 1.0
#: most samples a program may declare: 2^28 is 74 h at 1 kHz, and keeps an emulation of
#: the whole program (a few tens of bytes per sample and axis) within a workstation
MAX_PROGRAM_SAMPLES = 1 << 28
CONFIG = struct.Struct("<B16sdQQI10B")  # n_axes, axes, dt_s, dt_ns, n_samples, n_items, formats
SEGMENT = struct.Struct("<IIQBBqqqqbqb6qI")  # index, line, start, plane h, v, cos, sin, oh, ov,
#                                              x_exp, x_mant, p_exp, p_mant[6], n_pieces
PROFILE_HEAD = struct.Struct("<IIH")  # segment index, first piece, count in this frame
PIECE = struct.Struct("<IQb6q")  # n_samples, dtau, exp, mant[6]
SETPOINTS_HEAD = struct.Struct("<QIBI")  # start sample, n samples, n_axes, source line
START = struct.Struct("<QQ")  # total samples, prefill samples (run once this many are buffered)
STOP = struct.Struct("<QI")  # total samples, number of items
STATUS = struct.Struct("<IIIIQQII")  # free bytes, last seq, errors, state, samples done (output),
#                                      bytes accepted, poll id answered, program id
POLL = struct.Struct("<I")  # poll id


class FrameError(ValueError):
    """A frame that cannot be decoded (bad magic, CRC, length or payload)."""


@dataclass(frozen=True)
class Frame:
    type: FrameType
    seq: int
    payload: bytes

    def encode(self) -> bytes:
        return encode_frame(self.type, self.seq, self.payload)


@dataclass(frozen=True)
class Status:
    """What the device reports: flow control, acknowledgement and errors."""

    free_bytes: int
    last_seq: int
    errors: int
    state: int  # 0 idle, 1 configured, 2 running, 3 done, 4 armed, 5 held, 6 underrun, 7 aborted
    samples_done: int
    bytes_accepted: int
    poll_id: int = 0
    program_id: int = 0

    def pack(self) -> bytes:
        return STATUS.pack(
            self.free_bytes,
            self.last_seq,
            self.errors,
            self.state,
            self.samples_done,
            self.bytes_accepted,
            self.poll_id,
            self.program_id,
        )


def encode_frame(ftype: int, seq: int, payload: bytes) -> bytes:
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
    head = HEADER.pack(MAGIC, VERSION, int(ftype), 0, seq & 0xFFFFFFFF, len(payload))
    head += struct.pack("<I", zlib.crc32(head))
    body = head + payload
    return body + struct.pack("<I", zlib.crc32(body))


def parse_header(buf: bytes | bytearray | memoryview, off: int = 0) -> tuple[int, int, int] | None:
    """(type, seq, payload length) of a valid header at ``off``, else None (bad header)."""
    raw = bytes(buf[off : off + HEADER_SIZE])
    magic, ver, ftype, _flags, seq, length = HEADER.unpack(raw[: HEADER.size])
    if magic != MAGIC or struct.unpack("<I", raw[HEADER.size :])[0] != zlib.crc32(raw[: HEADER.size]):
        return None
    if ver != VERSION or length > MAX_PAYLOAD:
        return None
    return ftype, seq, length


def decode_frame(data: bytes) -> Frame:
    """One complete frame from bytes (raises FrameError)."""
    if len(data) < HEADER_SIZE + TRAILER_SIZE:
        raise FrameError("frame too short")
    hdr = parse_header(data)
    if hdr is None:
        raise FrameError("bad frame header")
    ftype, seq, length = hdr
    end = HEADER_SIZE + length
    if len(data) < end + TRAILER_SIZE:
        raise FrameError("frame truncated")
    if struct.unpack("<I", data[end : end + 4])[0] != zlib.crc32(data[:end]):
        raise FrameError("frame CRC mismatch")
    try:
        t = FrameType(ftype)
    except ValueError:
        raise FrameError(f"unknown frame type {ftype}") from None
    return Frame(t, seq, bytes(data[HEADER_SIZE:end]))


class FrameParser:
    """Incremental receiver: feed bytes, get whole valid frames; re-synchronises after garbage.

    A frame with a bad header or CRC is skipped by advancing one byte and
    searching for the next magic; ``crc_errors`` counts them.
    """

    def __init__(self) -> None:
        self.buf = bytearray()
        self.crc_errors = 0

    def feed(self, data: bytes) -> list[Frame]:
        self.buf += data
        out: list[Frame] = []
        while True:
            i = self.buf.find(MAGIC)
            if i < 0:
                # keep a possible partial magic at the end
                del self.buf[: max(0, len(self.buf) - (len(MAGIC) - 1))]
                return out
            if i:
                del self.buf[:i]
            if len(self.buf) < HEADER_SIZE:
                return out
            hdr = parse_header(self.buf)
            if hdr is None:
                self.crc_errors += 1
                del self.buf[:1]
                continue
            total = HEADER_SIZE + hdr[2] + TRAILER_SIZE
            if len(self.buf) < total:
                return out
            try:
                out.append(decode_frame(bytes(self.buf[:total])))
                del self.buf[:total]
            except FrameError:
                self.crc_errors += 1
                del self.buf[:1]


# -- program <-> frames ---------------------------------------------------------------------
@dataclass(frozen=True)
class FrameInfo:
    """What a frame carried, for messages: kind, segment index (or -1) and source line."""

    seq: int
    kind: str
    segment: int
    line: int


def default_prefill(prog: FpgaProgram) -> int:
    """Samples the device buffers before its sample clock starts: ``FPGA_PREFILL_S`` of motion
    (the device also starts when STOP arrived or its buffer is full)."""

    return int(min(prog.n_samples, max(1, round(FPGA_PREFILL_S / prog.dt_s))))


def program_frames(prog: FpgaProgram, prefill_samples: int | None = None) -> tuple[list[bytes], list[FrameInfo]]:
    """Encode a program: CONFIG, START, items (segments + profiles, setpoint blocks), STOP."""
    frames: list[bytes] = []
    infos: list[FrameInfo] = []

    def add(ftype: FrameType, payload: bytes, kind: str, seg: int = -1, line: int = 0) -> None:
        seq = len(frames) + 1
        frames.append(encode_frame(ftype, seq, payload))
        infos.append(FrameInfo(seq, kind, seg, line))

    n_axes = len(prog.axes)
    frames.append(b"")  # CONFIG goes first; it carries the program id of all the others
    infos.append(FrameInfo(1, "config", -1, 0))
    prefill = default_prefill(prog) if prefill_samples is None else int(prefill_samples)
    add(FrameType.START, START.pack(prog.n_samples, prefill), "start")
    per_block = (MAX_PAYLOAD - SETPOINTS_HEAD.size) // (8 * n_axes)
    per_profile = (MAX_PAYLOAD - PROFILE_HEAD.size) // PIECE.size
    n_items = 0
    for item in prog.items:
        if isinstance(item, FixedSegment):
            seg = SEGMENT.pack(
                item.index,
                item.line,
                item.start_sample,
                item.plane[0],
                item.plane[1],
                item.cos,
                item.sin,
                item.origin[0],
                item.origin[1],
                item.x_exp,
                item.x_mant,
                item.p_exp,
                *item.p_mant,
                len(item.pieces),
            )
            add(FrameType.SEGMENT, seg, "segment", item.index, item.line)
            for first in range(0, len(item.pieces), per_profile):
                chunk = item.pieces[first : first + per_profile]
                pay = PROFILE_HEAD.pack(item.index, first, len(chunk))
                pay += b"".join(PIECE.pack(p.n_samples, p.dtau, p.exp, *p.mant) for p in chunk)
                add(FrameType.PROFILE, pay, "profile", item.index, item.line)
            n_items += 1
        else:
            q = np.asarray(item.q, dtype="<i8")
            for r in range(0, q.shape[0], per_block):
                blk = q[r : r + per_block]
                pay = SETPOINTS_HEAD.pack(item.start_sample + r, blk.shape[0], n_axes, item.line)
                add(FrameType.SETPOINTS, pay + blk.tobytes(), "setpoints", -1, item.line)
                n_items += 1
    add(FrameType.STOP, STOP.pack(prog.n_samples, n_items), "stop")
    program_id = zlib.crc32(b"".join(frames[1:]))
    cfg = CONFIG.pack(
        n_axes,
        prog.axes.encode("ascii"),
        prog.dt_s,
        int(round(prog.dt_s * 1e9)),
        prog.n_samples,
        len(prog.items),
        *prog.formats.as_tuple(),
    )
    cfg += struct.pack(f"<{n_axes}qI", *prog.start, program_id)
    cfg += prog.source.encode("utf-8")[:255]
    frames[0] = encode_frame(FrameType.CONFIG, 1, cfg)
    return frames, infos


@dataclass(frozen=True)
class Config:
    axes: str
    dt_s: float
    n_samples: int
    n_items: int
    formats: FpgaFormats
    start: tuple[int, ...]
    source: str
    program_id: int = 0  # CRC-32 of every frame after CONFIG


def decode_config(payload: bytes) -> Config:
    try:
        n_axes, axes, dt_s, _dt_ns, n_samples, n_items, *fm = CONFIG.unpack_from(payload)
        *start, program_id = struct.unpack_from(f"<{n_axes}qI", payload, CONFIG.size)
        src = payload[CONFIG.size + 8 * n_axes + 4 :].decode("utf-8", "replace")
        letters = axes.rstrip(b"\0").decode("ascii")
    except (struct.error, UnicodeDecodeError, ValueError) as exc:
        raise FrameError(f"bad CONFIG payload: {exc}") from None
    # valid CRCs do not make the values sane: a device must refuse them like bad bytes
    if not letters or len(letters) != n_axes or len(set(letters)) != n_axes or any(a not in ALL_AXES for a in letters):
        raise FrameError(f"bad CONFIG payload: axes {letters!r} (letters from {ALL_AXES}, each once)")
    if not (CONFIG_DT_MIN_S <= dt_s <= CONFIG_DT_MAX_S):  # also refuses NaN
        raise FrameError(f"bad CONFIG payload: dt {dt_s!r} s outside [{CONFIG_DT_MIN_S:g}, {CONFIG_DT_MAX_S:g}]")
    if n_samples > MAX_PROGRAM_SAMPLES:
        raise FrameError(f"bad CONFIG payload: {n_samples} samples (at most {MAX_PROGRAM_SAMPLES})")
    try:
        return Config(letters, dt_s, n_samples, n_items, FpgaFormats.from_tuple(fm), tuple(start), src, program_id)
    except (struct.error, UnicodeDecodeError, ValueError) as exc:
        raise FrameError(f"bad CONFIG payload: {exc}") from None


def decode_segment(payload: bytes) -> tuple[FixedSegment, int]:
    """A SEGMENT payload: (segment without pieces, number of pieces to expect)."""
    try:
        v = SEGMENT.unpack(payload)
    except struct.error as exc:
        raise FrameError(f"bad SEGMENT payload: {exc}") from None
    seg = FixedSegment(
        index=v[0],
        line=v[1],
        start_sample=v[2],
        plane=(v[3], v[4]),
        cos=v[5],
        sin=v[6],
        origin=(v[7], v[8]),
        x_exp=v[9],
        x_mant=v[10],
        p_exp=v[11],
        p_mant=tuple(v[12:18]),
        pieces=(),
    )
    return seg, v[18]


def decode_profile(payload: bytes) -> tuple[int, int, list[ProfilePiece]]:
    try:
        index, first, count = PROFILE_HEAD.unpack_from(payload)
        if len(payload) != PROFILE_HEAD.size + count * PIECE.size:
            raise FrameError("PROFILE payload length does not match its piece count")
        pieces = []
        for j in range(count):
            n, dtau, exp, *mant = PIECE.unpack_from(payload, PROFILE_HEAD.size + j * PIECE.size)
            pieces.append(ProfilePiece(n, dtau, exp, tuple(mant)))
    except struct.error as exc:
        raise FrameError(f"bad PROFILE payload: {exc}") from None
    return index, first, pieces


def decode_setpoints(payload: bytes) -> SetpointBlock:
    try:
        start, n, n_axes, line = SETPOINTS_HEAD.unpack_from(payload)
    except struct.error as exc:
        raise FrameError(f"bad SETPOINTS payload: {exc}") from None
    if len(payload) != SETPOINTS_HEAD.size + 8 * n * n_axes:
        raise FrameError("SETPOINTS payload length does not match its sample count")
    q = np.frombuffer(payload, dtype="<i8", offset=SETPOINTS_HEAD.size).reshape(n, n_axes)
    return SetpointBlock(start, line, q.astype(np.int64))


def decode_status(payload: bytes) -> Status:
    try:
        return Status(*STATUS.unpack(payload))
    except struct.error as exc:
        raise FrameError(f"bad STATUS payload: {exc}") from None


def status_frame(st: Status) -> bytes:
    return encode_frame(FrameType.STATUS, st.last_seq, st.pack())


def poll_frame(poll_id: int) -> bytes:
    return encode_frame(FrameType.POLL, poll_id, POLL.pack(poll_id & 0xFFFFFFFF))


def control_frame(kind: FrameType, command_id: int) -> bytes:
    """HOLD, RESUME or ABORT (payload: the command id, echoed as the STATUS's poll id)."""
    if kind not in CONTROL_TYPES:
        raise ValueError(f"{kind!r} is not a control frame")
    return encode_frame(kind, command_id, POLL.pack(command_id & 0xFFFFFFFF))


def read_frame_file(path: str) -> list[Frame]:
    """All frames of a ``--dry-run`` file, strictly (any damage is a DeviceError naming the offset)."""
    from ..errors import SourceLocation, UsageError
    from ..inputfile import require_regular_file

    require_regular_file(path, "frame file")
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise UsageError(f"cannot read frame file: {exc.strerror}", SourceLocation(file=path)) from None
    out: list[Frame] = []
    off = 0
    while off < len(data):
        if len(data) - off < HEADER_SIZE:
            raise UsageError(f"truncated frame at byte {off}", SourceLocation(file=path))
        hdr = parse_header(data, off)
        if hdr is None:
            raise UsageError(f"bad frame header at byte {off}", SourceLocation(file=path))
        total = HEADER_SIZE + hdr[2] + TRAILER_SIZE
        try:
            out.append(decode_frame(data[off : off + total]))
        except FrameError as exc:
            raise UsageError(f"{exc} at byte {off} (frame {len(out) + 1})", SourceLocation(file=path)) from None
        off += total
    return out

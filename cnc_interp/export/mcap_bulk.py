"""MCAP in bulk: a writer that writes the same bytes as ``mcap``'s Writer, and a fast
reader of one channel's messages.

``mcap.writer.Writer.add_message`` costs about 5 µs of Python per message (a record
object, a dozen small buffer writes, index bookkeeping); a 10^6-sample plan has 2·10^6
messages. This writer produces byte for byte the file that ``Writer(stream,
chunk_size=..., compression=CompressionType.ZSTD)`` with its default options produces for
the same calls — same chunk boundaries, message indexes, statistics, summary and CRCs (a
test checks the equality) — but packs message records and message indexes a batch at a
time. Every record other than Message and MessageIndex is written by ``mcap.records``.

``add_records`` takes message records already packed (by numpy, a block at a time, see
``mcap_io``) as one buffer; with ``message_indexes=False`` no MessageIndex records are
written (as ``Writer(..., index_types=IndexType.ALL & ~IndexType.MESSAGE)``).

Reading has the same problem (``mcap``'s reader parses every record of every chunk in
Python); ``read_channel`` (``read_channel_fixed`` for fixed-size messages, as a numpy
array) uses the summary's chunk indexes and the per-channel message indexes, or a walk
over each chunk's record headers when there are none, to slice one channel's payloads
straight out of each decompressed chunk, after checking the chunk CRC.
"""

from __future__ import annotations

import struct
import zlib
from typing import IO, Sequence

import numpy as np

_MAGIC = b"\x89MCAP0\r\n"
_MSG_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, log, publish
_MSG_HEAD_BYTES = _MSG_HEAD.size  # 31
_MSG_FIXED = 22  # channel(2) + sequence(4) + log(8) + publish(8)
_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, record length, channel, entries length
_OP_MESSAGE = 0x05
#: the zstd level of ``mcap``'s Writer (``zstandard.compress``'s default)
ZSTD_LEVEL = 3
#: a Message record's header as a numpy record (the same layout as ``_MSG_HEAD``)
MESSAGE_HEAD_FIELDS = [("op", "u1"), ("len", "<u8"), ("ch", "<u2"), ("seq", "<u4"), ("log", "<u8"), ("pub", "<u8")]
_OP_MESSAGE_INDEX = 0x07


class BulkMcapWriter:
    """Writes an MCAP file; see the module docstring. Call order as for ``mcap`` 's Writer:
    ``start``, schemas/channels/metadata, ``add_messages`` (any number of batches),
    ``finish``."""

    def __init__(
        self,
        stream: IO[bytes],
        chunk_size: int,
        message_indexes: bool = True,
        level: int = ZSTD_LEVEL,
    ) -> None:
        """``message_indexes=False`` writes what ``Writer(..., index_types=IndexType.ALL &
        ~IndexType.MESSAGE)`` writes: no MessageIndex records (16 uncompressed bytes a
        message); readers find messages through the chunk indexes (not Foxglove's indexed
        reader: it needs them). ``level``: the chunks' zstd level (``mcap``'s Writer: 3)."""
        from mcap.data_stream import RecordBuilder

        self._level = level

        self._stream = stream
        self._chunk_size = chunk_size
        self._message_indexes = message_indexes
        self._rb = RecordBuilder()
        self._schemas: list = []
        self._channels: list = []
        self._metadata_indexes: list = []
        self._chunk_indexes: list = []
        self._channel_counts: dict[int, int] = {}  # insertion order = first message
        self._message_count = 0
        self._start_time = 0
        self._end_time = 0
        self._chunk_count = 0
        # the chunk being built
        self._parts: list[bytes | memoryview] = []
        self._size = 0
        self._n_in_chunk = 0
        self._c_start = 0
        self._c_end = 0
        self._index: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}

    # -- records written by mcap.records -------------------------------------------------
    def start(self, profile: str, library: str) -> None:
        from mcap.records import Header

        self._stream.write(_MAGIC)
        Header(profile, library).write(self._rb)
        self._flush()

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        from mcap.records import Schema

        schema = Schema(id=len(self._schemas) + 1, data=data, encoding=encoding, name=name)
        self._schemas.append(schema)
        self._to_chunk(schema)
        return schema.id

    def register_channel(
        self, topic: str, message_encoding: str, schema_id: int, metadata: dict[str, str] | None = None
    ) -> int:
        from mcap.records import Channel

        channel = Channel(
            id=len(self._channels) + 1,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata=dict(metadata or {}),
        )
        self._channels.append(channel)
        self._to_chunk(channel)
        return channel.id

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        from mcap.records import Metadata, MetadataIndex

        self._flush()
        offset = self._stream.tell()
        Metadata(name=name, metadata=data).write(self._rb)
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=self._rb.count, name=name))
        self._flush()

    def _to_chunk(self, record) -> None:
        from mcap.data_stream import RecordBuilder

        rb = RecordBuilder()
        record.write(rb)
        data = rb.end()
        self._parts.append(data)
        self._size += len(data)

    def _flush(self) -> None:
        self._stream.write(self._rb.end())

    # -- messages in bulk ------------------------------------------------------------------
    def add_messages(self, channel_ids: Sequence[int], log_times: Sequence[int], datas: Sequence[bytes]) -> None:
        """Append messages in file order (publish time = log time, sequence 0)."""
        n = len(datas)
        if n == 0:
            return
        chans = np.asarray(channel_ids, dtype=np.int64)
        times = np.asarray(log_times, dtype=np.int64)
        pack = _MSG_HEAD.pack
        recs = [
            pack(_OP_MESSAGE, _MSG_FIXED + len(d), c, 0, t, t) + d
            for c, t, d in zip(chans.tolist(), times.tolist(), datas)
        ]
        sizes = np.fromiter(map(len, recs), dtype=np.int64, count=n)
        self.add_records(chans, times, sizes, b"".join(recs))

    def add_records(self, chans: np.ndarray, times: np.ndarray, sizes: np.ndarray, buf) -> None:
        """Append message records already packed (header and payload, see ``message_head``)
        back to back in ``buf``, in file order: record i is ``sizes[i]`` bytes on channel
        ``chans[i]`` at log time ``times[i]``."""
        n = int(np.asarray(sizes).size)
        if n == 0:
            return
        chans = np.asarray(chans, dtype=np.int64)
        times = np.asarray(times, dtype=np.int64)
        sizes = np.asarray(sizes, dtype=np.int64)
        view = memoryview(buf).cast("B")
        ends = np.cumsum(sizes)  # chunk-relative end of each record, before the base size
        self._stats(chans, times)
        a = 0
        while a < n:
            base = self._size - (ends[a - 1] if a else 0)
            # mcap's Writer closes the chunk right after the first message that takes it
            # past chunk_size.
            b = max(int(np.searchsorted(ends, self._chunk_size - base, side="right")), a)
            closes = b < n
            b = min(b + 1, n) if closes else n
            offsets = base + ends[a:b] - sizes[a:b]
            lo = int(ends[a - 1]) if a else 0
            self._add_to_chunk(view[lo : int(ends[b - 1])], b - a, chans[a:b], times[a:b], offsets)
            self._size = int(base + ends[b - 1])
            if closes:
                self._finalize_chunk()
            a = b

    def _stats(self, chans: np.ndarray, times: np.ndarray) -> None:
        counts = np.bincount(chans)  # channel ids are small (1, 2, ...)
        for cid in _first_seen(chans, counts):
            self._channel_counts[cid] = self._channel_counts.get(cid, 0) + int(counts[cid])
        t_min, t_max = int(times.min()), int(times.max())
        if self._message_count == 0:
            self._start_time = t_min
        else:
            self._start_time = min(self._start_time, t_min)
        self._end_time = max(self._end_time, t_max)
        self._message_count += int(chans.size)

    def _add_to_chunk(self, data, count: int, chans, times, offsets) -> None:
        self._parts.append(data)
        t_min, t_max = int(times.min()), int(times.max())
        if self._n_in_chunk == 0:
            self._c_start = t_min
        else:
            self._c_start = min(self._c_start, t_min)
        self._c_end = max(self._c_end, t_max)
        self._n_in_chunk += count
        if not self._message_indexes:
            return
        for cid in _first_seen(chans, np.bincount(chans)):
            sel = chans == cid
            self._index.setdefault(cid, []).append((times[sel], offsets[sel]))

    def _finalize_chunk(self) -> None:
        if self._n_in_chunk == 0:
            return
        self._chunk_count += 1
        data = b"".join(self._parts)
        job = (data, self._c_start, self._c_end, self._index)
        self._parts, self._size, self._n_in_chunk, self._index = [], 0, 0, {}
        self._write_chunk(_compress(data, self._level), *job)

    def _write_chunk(self, packed: tuple[bytes, int], data: bytes, c_start: int, c_end: int, index_of) -> None:
        from mcap.records import Chunk, ChunkIndex

        compressed, crc = packed
        chunk = Chunk(
            compression="zstd",
            data=compressed,
            message_start_time=c_start,
            message_end_time=c_end,
            uncompressed_crc=crc,
            uncompressed_size=len(data),
        )
        self._flush()
        chunk_start = self._stream.tell()
        chunk.write(self._rb)
        index = ChunkIndex(
            message_start_time=c_start,
            message_end_time=c_end,
            chunk_start_offset=chunk_start,
            chunk_length=self._rb.count,
            message_index_offsets={},
            message_index_length=0,
            compression="zstd",
            compressed_size=len(compressed),
            uncompressed_size=len(data),
        )
        self._flush()
        index_start = self._stream.tell()
        written = 0
        for cid, pieces in index_of.items() if self._message_indexes else ():
            index.message_index_offsets[cid] = index_start + written
            entries = np.empty((sum(p[0].size for p in pieces), 2), dtype="<u8")
            entries[:, 0] = np.concatenate([p[0] for p in pieces])
            entries[:, 1] = np.concatenate([p[1] for p in pieces])
            body = entries.tobytes()
            rec = _INDEX_HEAD.pack(_OP_MESSAGE_INDEX, 6 + len(body), cid, len(body)) + body
            self._stream.write(rec)
            written += len(rec)
        index.message_index_length = written
        self._chunk_indexes.append(index)

    # -- summary ---------------------------------------------------------------------------
    def finish(self) -> None:
        """Close the last chunk and write the summary, footer and closing magic."""
        from mcap.data_stream import RecordBuilder
        from mcap.opcode import Opcode
        from mcap.records import DataEnd, Footer, Statistics, SummaryOffset

        self._finalize_chunk()
        DataEnd(0).write(self._rb)
        self._flush()
        summary_start = self._stream.tell()
        sb = RecordBuilder()
        offsets = []
        stats = Statistics(
            attachment_count=0,
            channel_count=len(self._channels),
            channel_message_counts=self._channel_counts,
            chunk_count=self._chunk_count,
            message_count=self._message_count,
            message_end_time=self._end_time,
            message_start_time=self._start_time,
            metadata_count=len(self._metadata_indexes),
            schema_count=len(self._schemas),
        )
        groups = (
            (Opcode.SCHEMA, self._schemas),
            (Opcode.CHANNEL, self._channels),
            (Opcode.STATISTICS, [stats]),
            (Opcode.CHUNK_INDEX, self._chunk_indexes),
            (Opcode.ATTACHMENT_INDEX, []),
            (Opcode.METADATA_INDEX, self._metadata_indexes),
        )
        for opcode, records in groups:
            group_start = sb.count
            for rec in records:
                rec.write(sb)
            offsets.append(
                SummaryOffset(
                    group_opcode=opcode, group_start=summary_start + group_start, group_length=sb.count - group_start
                )
            )
        summary_offset_start = summary_start + sb.count
        for off in offsets:
            off.write(sb)
        summary = sb.end()
        crc = zlib.crc32(summary)
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 8 + 8 + 4, summary_start, summary_offset_start), crc)
        self._stream.write(summary)
        Footer(summary_start=summary_start, summary_offset_start=summary_offset_start, summary_crc=crc).write(self._rb)
        self._flush()
        self._stream.write(_MAGIC)


def _first_seen(chans: np.ndarray, counts: np.ndarray) -> list[int]:
    """The channel ids present in ``chans`` (counts: their ``bincount``), in the order of
    their first message."""
    present = np.flatnonzero(counts)
    firsts = [int(np.argmax(chans == cid)) for cid in present.tolist()]
    return [int(cid) for _, cid in sorted(zip(firsts, present.tolist()))]


def _compress(data: bytes, level: int = ZSTD_LEVEL) -> tuple[bytes, int]:
    """A chunk's records zstd-compressed (at ``mcap``'s Writer's level, 3, the same bytes
    as it writes), and their CRC."""
    import zstandard

    return zstandard.compress(data, level), zlib.crc32(data)


# -- reading -----------------------------------------------------------------------------------
class McapReadError(ValueError):
    """The file's indexes or CRCs do not add up."""


def read_channel(fh, summary, channel_id: int) -> tuple[np.ndarray, list[bytes]] | None:
    """(log times (n,) uint64, payloads) of one channel, in file order, CRCs checked.

    Uses the summary's chunk indexes and each chunk's message index for the channel.
    Returns ``None`` when the file lacks the indexes this needs (the caller then uses
    ``mcap``'s reader); raises ``McapReadError`` on a CRC mismatch or an index that points
    at something other than a message of the channel.
    """
    found = _channel_spans(fh, summary, channel_id)
    if found is None:
        return None
    times: list[np.ndarray] = []
    datas: list[bytes] = []
    for data, starts, ends, log in found:
        datas.extend(data[a:b] for a, b in zip(starts.tolist(), ends.tolist()))
        times.append(log)
    all_times = np.concatenate(times) if times else np.zeros(0, dtype=np.uint64)
    return all_times, datas


def read_channel_fixed(fh, summary, channel_id: int, size: int) -> tuple[np.ndarray, np.ndarray] | None:
    """(log times (n,) uint64, payloads (n, size) uint8) of a channel whose messages are
    all ``size`` bytes long, in file order, CRCs checked; ``None`` as for ``read_channel``.
    Raises ``McapReadError`` naming the first message of another length."""
    found = _channel_spans(fh, summary, channel_id)
    if found is None:
        return None
    times: list[np.ndarray] = []
    rows: list[np.ndarray] = []
    seen = 0
    for data, starts, ends, log in found:
        odd = np.flatnonzero(ends - starts != size)
        if odd.size:
            k = int(odd[0])
            raise McapReadError(f"message {seen + k} of the channel is {int(ends[k] - starts[k])} bytes, not {size}")
        raw = np.frombuffer(data, dtype=np.uint8)
        rows.append(raw[starts[:, None] + np.arange(size)])
        times.append(log)
        seen += starts.size
    if not rows:
        return np.zeros(0, dtype=np.uint64), np.zeros((0, size), dtype=np.uint8)
    return np.concatenate(times), np.concatenate(rows)


def _channel_spans(fh, summary, channel_id: int):
    """Per chunk holding messages of the channel: (decompressed chunk, payload starts,
    payload ends, log times), or ``None`` when the indexes do not cover the channel."""
    if summary is None or not summary.chunk_indexes or summary.statistics is None:
        return None
    expected = summary.statistics.channel_message_counts.get(channel_id, 0)
    out = []
    count = 0
    for ci in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        if ci.message_index_length == 0:  # no message indexes: walk the chunk's records
            data = _chunk_data(fh, ci)
            starts, ends, log = _walk_chunk(data, channel_id)
            if starts.size:
                out.append((data, starts, ends, log))
                count += starts.size
            continue
        off = ci.message_index_offsets.get(channel_id)
        if off is None:
            continue
        data = _chunk_data(fh, ci)
        fh.seek(off)
        head = fh.read(_INDEX_HEAD.size)
        op, _, cid, n_bytes = _INDEX_HEAD.unpack(head)
        if op != _OP_MESSAGE_INDEX or cid != channel_id or n_bytes % 16:
            raise McapReadError(f"bad message index at offset {off}")
        entries = np.frombuffer(fh.read(n_bytes), dtype="<u8").reshape(-1, 2)
        offsets = entries[:, 1].astype(np.int64)
        if offsets.size and (offsets.min() < 0 or offsets.max() + _MSG_HEAD_BYTES > len(data)):
            raise McapReadError("message index points outside its chunk")
        raw = np.frombuffer(data, dtype=np.uint8)
        span = offsets[:, None] + np.arange(_MSG_HEAD_BYTES)
        heads = raw[span].copy().view(np.dtype(MESSAGE_HEAD_FIELDS)).reshape(-1)
        if (heads["op"] != _OP_MESSAGE).any() or (heads["ch"] != channel_id).any():
            raise McapReadError("message index points at a record of another kind or channel")
        starts = offsets + _MSG_HEAD_BYTES
        ends = offsets + 9 + heads["len"].astype(np.int64)
        if ends.size and (ends.max() > len(data) or (ends < starts).any()):
            raise McapReadError("message runs past the end of its chunk")
        out.append((data, starts, ends, heads["log"].astype(np.uint64)))
        count += starts.size
    if count != expected:
        return None  # the indexes do not cover every message: let mcap's reader decide
    return out


def _walk_chunk(data: bytes, channel_id: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(payload starts, payload ends, log times) of the channel's messages in the
    decompressed chunk ``data``, record by record."""
    unpack = _MSG_HEAD.unpack_from
    head = struct.Struct("<BQ").unpack_from
    n = len(data)
    pos = 0
    starts: list[int] = []
    ends: list[int] = []
    logs: list[int] = []
    while pos < n:
        if pos + 9 > n:
            raise McapReadError("a record runs past the end of its chunk")
        op, length = head(data, pos)
        end = pos + 9 + length
        if end > n:
            raise McapReadError("a record runs past the end of its chunk")
        if op == _OP_MESSAGE:
            if length < _MSG_FIXED:
                raise McapReadError("a message record too short for its header")
            _, _, ch, _, log, _ = unpack(data, pos)
            if ch == channel_id:
                starts.append(pos + _MSG_HEAD_BYTES)
                ends.append(end)
                logs.append(log)
        pos = end
    return (
        np.array(starts, dtype=np.int64),
        np.array(ends, dtype=np.int64),
        np.array(logs, dtype=np.uint64),
    )


def _chunk_data(fh, ci) -> bytes:
    """The decompressed records of the chunk at ``ci``, its CRC checked."""
    import io as _io

    from mcap.data_stream import ReadDataStream
    from mcap.records import Chunk

    fh.seek(ci.chunk_start_offset)
    raw = fh.read(ci.chunk_length)
    if len(raw) < 9 or raw[0] != 0x06:
        raise McapReadError(f"no chunk at offset {ci.chunk_start_offset}")
    chunk = Chunk.read(ReadDataStream(_io.BytesIO(raw[9:])))
    if chunk.compression == "zstd":
        import zstandard

        data = zstandard.decompress(chunk.data, chunk.uncompressed_size)
    elif chunk.compression == "lz4":
        import lz4.frame  # type: ignore[import-not-found]

        data = lz4.frame.decompress(chunk.data)
    elif chunk.compression == "":
        data = chunk.data
    else:
        raise McapReadError(f"unsupported chunk compression {chunk.compression!r}")
    if len(data) != chunk.uncompressed_size:
        raise McapReadError("chunk size does not match its header")
    if chunk.uncompressed_crc != 0 and zlib.crc32(data) != chunk.uncompressed_crc:
        raise McapReadError(f"chunk CRC mismatch at offset {ci.chunk_start_offset}")
    return data

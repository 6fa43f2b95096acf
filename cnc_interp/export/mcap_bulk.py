"""MCAP in bulk: a writer that writes the same bytes as ``mcap``'s Writer, and a fast
reader of one channel's messages.

``mcap.writer.Writer.add_message`` costs about 5 µs of Python per message (a record
object, a dozen small buffer writes, index bookkeeping); a 10^6-sample plan has 2·10^6
messages. This writer produces byte for byte the file that ``Writer(stream,
chunk_size=..., compression=CompressionType.ZSTD)`` with its default options produces for
the same calls — same chunk boundaries, message indexes, statistics, summary and CRCs (a
test checks the equality) — but packs message records and message indexes a batch at a
time. Every record other than Message and MessageIndex is written by ``mcap.records``.

Reading has the same problem (``mcap``'s reader parses every record of every chunk in
Python); ``read_channel`` uses the summary's chunk indexes and the per-channel message
indexes to slice one channel's payloads straight out of each decompressed chunk, after
checking the chunk CRC.
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
_OP_MESSAGE_INDEX = 0x07


class BulkMcapWriter:
    """Writes an MCAP file; see the module docstring. Call order as for ``mcap`` 's Writer:
    ``start``, schemas/channels/metadata, ``add_messages`` (any number of batches),
    ``finish``."""

    def __init__(self, stream: IO[bytes], chunk_size: int) -> None:
        from mcap.data_stream import RecordBuilder

        self._stream = stream
        self._chunk_size = chunk_size
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
        self._parts: list[bytes] = []
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
            self._add_to_chunk(recs[a:b], chans[a:b], times[a:b], offsets)
            self._size = int(base + ends[b - 1])
            if closes:
                self._finalize_chunk()
            a = b

    def _stats(self, chans: np.ndarray, times: np.ndarray) -> None:
        ids, first, counts = np.unique(chans, return_index=True, return_counts=True)
        for i in np.argsort(first, kind="stable"):
            cid = int(ids[i])
            self._channel_counts[cid] = self._channel_counts.get(cid, 0) + int(counts[i])
        t_min, t_max = int(times.min()), int(times.max())
        if self._message_count == 0:
            self._start_time = t_min
        else:
            self._start_time = min(self._start_time, t_min)
        self._end_time = max(self._end_time, t_max)
        self._message_count += int(chans.size)

    def _add_to_chunk(self, recs, chans, times, offsets) -> None:
        self._parts.extend(recs)
        t_min, t_max = int(times.min()), int(times.max())
        if self._n_in_chunk == 0:
            self._c_start = t_min
        else:
            self._c_start = min(self._c_start, t_min)
        self._c_end = max(self._c_end, t_max)
        self._n_in_chunk += len(recs)
        ids, first = np.unique(chans, return_index=True)
        for i in np.argsort(first, kind="stable"):
            cid = int(ids[i])
            sel = chans == cid
            self._index.setdefault(cid, []).append((times[sel], offsets[sel]))

    def _finalize_chunk(self) -> None:
        if self._n_in_chunk == 0:
            return
        import zstandard
        from mcap.records import Chunk, ChunkIndex

        self._chunk_count += 1
        data = b"".join(self._parts)
        compressed = zstandard.compress(data)
        chunk = Chunk(
            compression="zstd",
            data=compressed,
            message_start_time=self._c_start,
            message_end_time=self._c_end,
            uncompressed_crc=zlib.crc32(data),
            uncompressed_size=len(data),
        )
        self._flush()
        chunk_start = self._stream.tell()
        chunk.write(self._rb)
        index = ChunkIndex(
            message_start_time=self._c_start,
            message_end_time=self._c_end,
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
        for cid, pieces in self._index.items():
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
        self._parts, self._size, self._n_in_chunk, self._index = [], 0, 0, {}

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
    if summary is None or not summary.chunk_indexes or summary.statistics is None:
        return None
    expected = summary.statistics.channel_message_counts.get(channel_id, 0)
    times: list[np.ndarray] = []
    datas: list[bytes] = []
    for ci in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        if ci.message_index_length == 0:
            return None  # no message indexes written: cannot tell which chunks hold what
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
        heads = (
            raw[span]
            .copy()
            .view(
                np.dtype([("op", "u1"), ("len", "<u8"), ("ch", "<u2"), ("seq", "<u4"), ("log", "<u8"), ("pub", "<u8")])
            )
        )
        heads = heads.reshape(-1)
        if (heads["op"] != _OP_MESSAGE).any() or (heads["ch"] != channel_id).any():
            raise McapReadError("message index points at a record of another kind or channel")
        starts = offsets + _MSG_HEAD_BYTES
        ends = offsets + 9 + heads["len"].astype(np.int64)
        if ends.size and ends.max() > len(data):
            raise McapReadError("message runs past the end of its chunk")
        datas.extend(data[a:b] for a, b in zip(starts.tolist(), ends.tolist()))
        times.append(heads["log"].astype(np.uint64))
    if len(datas) != expected:
        return None  # the indexes do not cover every message: let mcap's reader decide
    all_times = np.concatenate(times) if times else np.zeros(0, dtype=np.uint64)
    return all_times, datas


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

"""MCAP output for Foxglove (and anything else that reads MCAP), and reading it back.

Channels (``ros1`` messages under ``ros1msg`` schemas: fixed-size packed little-endian
numbers, which Foxglove decodes and plots; log time = publish time = the sample time in
ns from the start of the plan):

- ``/setpoints`` (``cnc_interp/Setpoint``): one message per sample: ``t`` (s), ``s``
  (mm), ``feed`` (mm/s) as float64, ``line`` (int32, source line executing, 0 = none)
  and one float64 per machine axis letter (mm, or deg for A/B/C).
- ``/segments`` (``cnc_interp/Segment``): one message per fitted segment, at the time
  the tool enters it: ``line``, ``s_start``/``s_end`` (mm), ``t_start``/``t_end`` (s),
  ``feed_min``/``feed_max`` (planned feed over the segment, mm/s) and ``samples``.
- ``/limits`` (``cnc_interp/LimitRatios``, when a machine is given): one message per
  ``MCAP_LIMITS_EVERY`` samples, at the time of the last of them: ``v``, ``a``, ``j``
  (``cnc_interp/AxisRatios``, for each axis the float32 signed ratio of largest magnitude
  over those samples: velocity / vmax, ...; within limits means |ratio| <= 1), from
  rest-padded backward differences of the setpoints (the ``verify`` convention), and
  ``worst`` = the largest |ratio| among them.

Metadata records: ``machine`` (name, axes, kinematics, dt, and every axis's vmax/amax/jmax),
``input`` (name, sha256, lines — as given by the caller, see ``input_metadata``),
``planner`` (name, status, dt, settings) and ``tool`` (name, version, mcap library).

The file is a pure function of its inputs: fixed chunk size and zstd level, no wall-clock
times, fixed field order. Setpoints are the planned float64 values bit for bit (non-finite ones
as NaN/inf), so ``verify`` of the MCAP checks exactly the planned values; the
``/limits`` ratios, which are for looking at, are float32 (7 significant digits).
``read_mcap`` also reads the ``json`` setpoints of files from earlier versions.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import operator
from typing import Mapping

import numpy as np

from ..errors import SourceLocation, UsageError


#: MCAP chunk size (uncompressed bytes); fixed so the same plan gives the same file
MCAP_CHUNK_BYTES = 4 * 1024 * 1024

#: zstd level of the chunks: level 1 compresses this binary data twice as fast as the
#: default 3 (about 460 against 250 MB/s) into 10-15 % more bytes
MCAP_ZSTD_LEVEL = 1

#: a /segments message covers at most this many samples (a longer run of one source
#: line, e.g. a long dwell, is split): the messages of an open segment wait for its end
MCAP_SEGMENT_MAX_SAMPLES = 1 << 16

#: a /limits message covers this many samples (at the time of its last one): the signed
#: ratio of largest magnitude of each axis and kind over them, so no peak is lost, at a
#: tenth of the bytes and writing time of one message per sample
MCAP_LIMITS_EVERY = 10

#: samples formatted per batch (bounds memory for very long plans)
_BATCH = 65536

#: a setpoint's log time may differ from its ``t`` by this much, ns: the writer rounds
#: t·1e9 to the nearest integer ns
LOG_TIME_TOL_NS = 1.0

#: what a setpoint field may hold once parsed: a JSON number, or null for a non-finite one
_NUMBER_TYPES = {int, float, type(None)}

SETPOINTS_TOPIC = "/setpoints"
SEGMENTS_TOPIC = "/segments"
LIMITS_TOPIC = "/limits"

#: schemas are ROS 1 message definitions and messages are ROS 1 serialised (packed
#: little-endian numbers): Foxglove reads them, numpy packs them a block at a time, and
#: ROS 1 field names may be upper case (the axis letters)
SCHEMA_ENCODING = "ros1msg"
MESSAGE_ENCODING = "ros1"
SETPOINT_TYPE = "cnc_interp/Setpoint"
SEGMENT_TYPE = "cnc_interp/Segment"
LIMITS_TYPE = "cnc_interp/LimitRatios"
AXIS_RATIOS_TYPE = "cnc_interp/AxisRatios"
_ROS1_SEPARATOR = "=" * 80

#: the largest source line a setpoint can name (an int32 field)
_LINE_MAX = 2**31 - 1


# -- public API ----------------------------------------------------------------------------
def input_metadata(name: str, data: bytes) -> dict:
    """The ``input`` metadata record for a part program read as ``data`` from ``name``."""
    lines = data.count(b"\n") + (1 if data and not data.endswith(b"\n") else 0)
    return {"name": name, "sha256": hashlib.sha256(data).hexdigest(), "lines": lines, "bytes": len(data)}


def write_mcap(traj, out: str, metadata: Mapping | None = None, machine=None, segments=None, progress=None) -> int:
    """Write ``traj`` as an MCAP file at ``out`` (``-`` = stdout), atomically.

    Args:
        traj: the ``Trajectory`` to write.
        out: output path, or ``-`` for standard output.
        metadata: extra metadata records, ``{record name: {key: value}}``; values that are
            not strings are stored as compact JSON. Pass ``{"input": input_metadata(...)}``
            for the part program. Keys given for the ``machine``, ``planner`` or ``tool``
            records are added to (and override) the ones built here.
        machine: the ``Machine`` the plan was made for: adds ``/limits`` and the
            ``machine`` record.
        segments: optional (m, 3) array-like of ``(line, s_start_mm, s_end_mm)`` in the
            trajectory's arc length; by default one segment per run of equal ``traj.line``
            (split every ``MCAP_SEGMENT_MAX_SAMPLES``).
        progress: optional ``tick(n)`` callable, called with samples written.

    Returns:
        The number of messages written.
    """
    from ..outfile import atomic_write

    with atomic_write(out) as fh:
        w = McapPlanWriter(fh, traj.axes, traj.dt_s, machine)
        if segments is not None:
            w.fixed = _fixed_segments(traj, segments, w.seg_rec, w.seg_chan)
        K = traj.n_samples
        for b0 in range(0, K, _BATCH):
            b1 = min(b0 + _BATCH, K)
            w.write(traj.t[b0:b1], traj.s[b0:b1], traj.feed[b0:b1], traj.q[b0:b1], traj.line[b0:b1])
            if progress is not None:
                progress(b1 - b0)
        return w.finish(_planner_record(traj), metadata)


def _planner_record(traj) -> dict:
    return {
        "name": traj.planner,
        "status": traj.status,
        "dt_s": float(traj.dt_s),
        "axes": traj.axes,
        "samples": traj.n_samples,
        "duration_s": traj.duration_s,
        "settings": _dumps(traj.settings),
    }


def planner_record(planner: str, status: str, dt_s: float, axes: str, samples: int, settings: dict) -> dict:
    """The ``planner`` metadata record of a streamed plan (known at its end)."""
    duration = float((samples - 1) * dt_s) if samples else 0.0
    return {
        "name": planner,
        "status": status,
        "dt_s": float(dt_s),
        "axes": axes,
        "samples": int(samples),
        "duration_s": duration,
        "settings": _dumps(settings),
    }


class _Tell:
    """A write-only stream that counts what it writes (the MCAP writer needs ``tell``;
    a pipe has none)."""

    def __init__(self, fh):
        self.fh = fh
        self.pos = 0

    def write(self, data) -> int:
        self.fh.write(data)
        self.pos += len(data)
        return len(data)

    def tell(self) -> int:
        return self.pos


class McapPlanWriter:
    """Writes a plan as MCAP while it is planned: ``write`` blocks of samples in order,
    then ``finish``. The file does not depend on how the samples are split into blocks.

    Every message of a channel has a fixed size, so a block's setpoint records are packed
    by numpy as one structured array (``_pack_rows``), headers included, windows of them
    and their /limits record as another (``_with_limits``), and handed to the MCAP writer
    as one buffer. A ``/segments`` message is written at the sample where
    its segment starts, but holds the segment's end (time, feed range, samples): the
    samples of an open segment wait until it closes, at a change of source line or after
    ``MCAP_SEGMENT_MAX_SAMPLES`` samples (a long segment is split), which bounds what
    waits. The metadata records, which hold what is known only at the end (samples,
    status, statistics), follow the messages.
    """

    def __init__(self, fh, axes: str, dt_s: float, machine=None):
        from .. import __version__
        from .mcap_bulk import BulkMcapWriter

        self.axes = axes
        self.dt_s = float(dt_s)
        self.machine = machine
        # The bytes of mcap.writer.Writer(fh, chunk_size, CompressionType.ZSTD) but for the
        # zstd level, faster. The message indexes (16 uncompressed bytes a message) stay:
        # Foxglove's indexed reader refuses a chunk without them.
        self.writer = writer = BulkMcapWriter(_Tell(fh), chunk_size=MCAP_CHUNK_BYTES, level=MCAP_ZSTD_LEVEL)
        # A fixed library string: no timestamps, nothing host-specific in the header.
        writer.start(profile="", library=f"cnc-interp/{__version__}")
        sp_schema = writer.register_schema(SETPOINT_TYPE, SCHEMA_ENCODING, _setpoint_msg(axes).encode())
        self.sp_chan = writer.register_channel(
            SETPOINTS_TOPIC, MESSAGE_ENCODING, sp_schema, {"axes": axes, "units": _units(axes)}
        )
        seg_schema = writer.register_schema(SEGMENT_TYPE, SCHEMA_ENCODING, _segment_msg().encode())
        self.seg_chan = writer.register_channel(SEGMENTS_TOPIC, MESSAGE_ENCODING, seg_schema, {})
        self.seg_rec = _record_dtype(_SEGMENT_FIELDS)
        self.row = _record_dtype(_setpoint_fields(axes))  # a /setpoints record
        # the fields every record has alike, and where the numbers start
        self.template = np.zeros((), self.row)
        _fill_head(self.template["head"], self.sp_chan, np.zeros(()), self.row["body"].itemsize)
        body = self.row["body"]
        self.sp_at = self.row.fields["body"][1]
        self.axes_at = self.sp_at + (body.fields[axes[0]][1] if axes else 0)
        self.lim_chan = None
        self.lim_axes = ""
        if machine is not None:
            self.lim_axes = "".join(a for a in axes if a in machine.axes)
            lim_schema = writer.register_schema(LIMITS_TYPE, SCHEMA_ENCODING, _limits_msg(self.lim_axes).encode())
            self.lim_chan = writer.register_channel(
                LIMITS_TOPIC, MESSAGE_ENCODING, lim_schema, {"axes": self.lim_axes, "samples": str(MCAP_LIMITS_EVERY)}
            )
            self.lim_idx = [axes.index(a) for a in self.lim_axes]
            self.limits = machine.limits()[:, [machine.axes.index(a) for a in self.lim_axes]]
            self.lim_rec = _record_dtype(_limits_fields(self.lim_axes))
            self.lim_template = np.zeros((), self.lim_rec)
            _fill_head(self.lim_template["head"], self.lim_chan, np.zeros(()), self.lim_rec["body"].itemsize)
            self.lim_at = self.lim_rec.fields["body"][1]
            self.acc = np.zeros((0, 3 * len(self.lim_axes)))  # ratios of the open window
            self.last_ns = 0  # log time of the last sample
        # (starts, records) of segments given for a whole trajectory (``write_mcap``)
        self.fixed: tuple[np.ndarray, np.ndarray] | None = None
        self.k = 0  # samples written
        self.count = 0
        self.hist: np.ndarray | None = None  # the last 3 samples (limit ratios' stencils)
        self.pend = np.zeros(0, self.row)  # the samples of the open segment
        self.lim_pos = np.zeros(0, dtype=np.int64)  # waiting /limits records: their sample
        self.lim_recs = np.zeros(0, self.lim_rec) if self.lim_chan is not None else None

    def write(self, t, s, feed, q, line) -> None:
        """Append the next samples (t, s, feed (K,), q (K, n), line (K,))."""
        t = np.asarray(t, dtype=float)
        K = t.shape[0]
        if not K:
            return
        q = np.asarray(q, dtype=float).reshape(K, -1)
        rows = _pack_rows(self, t, s, feed, q, line)
        k0 = self.k
        self.k += K
        lim_pos, lim_recs = self._limits(q, rows, k0)
        if self.fixed is not None:
            starts, recs = self.fixed
            sel = (starts >= k0) & (starts < k0 + K)
            self._emit(rows, starts[sel] - k0, recs[sel], lim_pos - k0, lim_recs)
            return
        if self.lim_recs is not None and lim_pos.size:
            self.lim_pos = np.concatenate([self.lim_pos, lim_pos])
            self.lim_recs = _join_records(self.lim_recs, lim_recs)
        self.pend = _join_records(self.pend, rows)
        self._close_segments(final=False)

    def _limits(self, q: np.ndarray, rows: np.ndarray, k0: int):
        """The /limits records of the windows of ``MCAP_LIMITS_EVERY`` samples that end
        among these samples (rows, from sample ``k0``): (sample index of each window's
        last sample, records), the window still open kept for the next samples."""
        if self.lim_chan is None:
            return np.zeros(0, dtype=np.int64), None
        K = q.shape[0]
        sub = q[:, self.lim_idx]
        h = self.hist if self.hist is not None else np.repeat(sub[:1], 3, axis=0)
        qh = np.concatenate([h, sub])
        self.hist = qh[-3:]
        ratios = np.concatenate([self.acc, _ratio_rows(qh, self.dt_s, self.limits)])
        N = MCAP_LIMITS_EVERY
        m = ratios.shape[0] // N
        self.acc = ratios[m * N :]
        self.last_ns = int(rows["head"]["log"][-1])
        first = k0 + K - ratios.shape[0]  # the sample of ratios[0]
        pos = first + N - 1 + N * np.arange(m, dtype=np.int64)
        env = _with_worst(_extremes(ratios[: m * N].reshape(m, N, ratios.shape[1])))
        recs = self._limit_records(env, rows["head"]["log"][pos - k0])
        return pos, recs

    def _limit_records(self, env: np.ndarray, ns: np.ndarray) -> np.ndarray:
        recs = np.empty(env.shape[0], self.lim_rec)
        recs[...] = self.lim_template
        recs["head"]["log"] = ns
        recs["head"]["pub"] = ns
        _columns(recs, self.lim_at, env.shape[1], "<f4")[:] = env
        return recs

    def _close_segments(self, final: bool) -> None:
        """Write every segment of the waiting samples that is known to have ended (at the
        end of the plan, ``final``, the last one too) and the samples before the open one."""
        pend = self.pend
        n = pend.size
        if not n:
            return
        body = pend["body"]
        line = body["line"]
        starts = _segment_starts(line, MCAP_SEGMENT_MAX_SAMPLES)
        if final:
            closed, ends, release = starts, np.append(starts[1:], n - 1), n
        else:
            closed, ends, release = starts[:-1], starts[1:], int(starts[-1])
        if not release:
            return
        feed = np.ascontiguousarray(body["feed"])
        feed = np.where(np.isfinite(feed), feed, np.nan)  # the feed range ignores non-finite values
        lo = np.fmin(np.fmin.reduceat(feed, starts)[: closed.size], feed[ends])
        hi = np.fmax(np.fmax.reduceat(feed, starts)[: closed.size], feed[ends])
        keep = line[closed] != 0
        a, c = closed[keep], ends[keep]
        segs = np.zeros(a.size, self.seg_rec)
        _fill_head(segs["head"], self.seg_chan, pend["head"]["log"][a], self.seg_rec["body"].itemsize)
        sb = segs["body"]
        sb["line"] = line[a]
        sb["s_start"], sb["s_end"] = body["s"][a], body["s"][c]
        sb["t_start"], sb["t_end"] = body["t"][a], body["t"][c]
        sb["feed_min"], sb["feed_max"] = lo[keep], hi[keep]
        sb["samples"] = c - a + 1
        k_first = self.k - n  # the sample of pend[0]
        lim_pos = np.zeros(0, dtype=np.int64)
        lim_recs = None
        if self.lim_recs is not None:
            out = self.lim_pos < k_first + release
            lim_pos, lim_recs = self.lim_pos[out] - k_first, self.lim_recs[out]
            self.lim_pos, self.lim_recs = self.lim_pos[~out], self.lim_recs[~out]
        self._emit(pend[:release], a, segs, lim_pos, lim_recs)
        self.pend = pend[release:].copy()

    def _emit(self, rows: np.ndarray, at: np.ndarray, segs: np.ndarray, lim_at: np.ndarray, lims) -> None:
        """Write the setpoint records ``rows`` with the segment records ``segs`` before the
        samples ``at`` and the /limits records ``lims`` after the samples ``lim_at``
        (ascending, local to ``rows``)."""
        n = rows.size
        R = self.row.itemsize
        ns = rows["head"]["log"].astype(np.int64)
        chans = np.full(n, self.sp_chan)
        sizes = np.full(n, R)
        times = ns
        if lim_at.size:
            L = self.lim_rec.itemsize
            buf = self._with_limits(rows, lim_at, lims)
            chans = np.insert(chans, lim_at + 1, self.lim_chan or 0)
            sizes = np.insert(sizes, lim_at + 1, L)
            times = np.insert(times, lim_at + 1, lims["head"]["log"].astype(np.int64))
        else:
            L = 0
            buf = rows.view(np.uint8).reshape(-1)
        if at.size:
            # the segment records go before their samples: cut where those samples start
            S = self.seg_rec.itemsize
            lims_before = np.searchsorted(lim_at, at, side="left")
            cuts = (at * R + lims_before * L).tolist()
            mem = memoryview(buf).cast("B")
            seg_mem = memoryview(segs.view(np.uint8).reshape(-1))
            pieces: list = []
            prev = 0
            for j, c in enumerate(cuts):
                pieces.append(mem[prev:c])
                pieces.append(seg_mem[j * S : (j + 1) * S])
                prev = c
            pieces.append(mem[prev:])
            buf = b"".join(pieces)
            idx = at + lims_before
            chans = np.insert(chans, idx, self.seg_chan)
            sizes = np.insert(sizes, idx, S)
            times = np.insert(times, idx, segs["head"]["log"].astype(np.int64))
        self.writer.add_records(chans, times, sizes, buf)
        self.count += int(chans.size)

    def _with_limits(self, rows: np.ndarray, lim_at: np.ndarray, lims: np.ndarray) -> bytes:
        """The bytes of ``rows`` with ``lims[g]`` after row ``lim_at[g]``: runs of whole
        windows (``MCAP_LIMITS_EVERY`` rows, then their /limits record) packed by numpy as
        one array each, the rest piece by piece."""
        N = MCAP_LIMITS_EVERY
        group = np.dtype([("sp", self.row, (N,)), ("lim", self.lim_rec)])
        raw = rows.view(np.uint8).reshape(-1)
        R = self.row.itemsize
        lim_raw = lims.view(np.uint8).reshape(lims.size, -1)
        # where a run of evenly spaced windows breaks
        breaks = np.flatnonzero(np.diff(lim_at) != N) + 1
        pieces: list = []
        prev = 0  # the next row to write
        for g0, g1 in zip([0, *breaks.tolist()], [*breaks.tolist(), lim_at.size]):
            first = int(lim_at[g0]) - N + 1  # the first row of window g0
            if first < prev:  # window g0 began before these rows (or a shorter last one)
                pieces.append(raw[prev * R : (int(lim_at[g0]) + 1) * R])
                pieces.append(lim_raw[g0])
                prev = int(lim_at[g0]) + 1
                g0 += 1
                if g0 == g1:
                    continue
                first = int(lim_at[g0]) - N + 1
            pieces.append(raw[prev * R : first * R])
            run = np.empty(g1 - g0, group)
            run["sp"] = rows[first : first + (g1 - g0) * N].reshape(g1 - g0, N)
            run["lim"] = lims[g0:g1]
            pieces.append(run.view(np.uint8).reshape(-1))
            prev = int(lim_at[g1 - 1]) + 1
        pieces.append(raw[prev * R :])
        return b"".join(pieces)

    # -- the end -----------------------------------------------------------------------------
    def finish(self, planner: dict, metadata: Mapping | None = None) -> int:
        """Close the last segment, write the metadata records and the summary. Returns
        the number of messages written."""
        from mcap import __version__ as mcap_version

        if self.lim_chan is not None and self.acc.shape[0]:
            # the last window, shorter: at the last sample
            recs = self._limit_records(_with_worst(_extremes(self.acc[None])), np.array([self.last_ns]))
            if self.fixed is not None:
                none = np.zeros(0, dtype=np.int64)
                self._emit(np.zeros(0, self.row), none, np.zeros(0, self.seg_rec), np.array([-1]), recs)
            else:
                self.lim_pos = np.append(self.lim_pos, self.k - 1)
                self.lim_recs = _join_records(self.lim_recs, recs)
            self.acc = self.acc[:0]
        if self.fixed is None:
            self._close_segments(final=True)
        self.writer._finalize_chunk()
        for name, record in _metadata_records(planner, metadata, self.machine, mcap_version):
            self.writer.add_metadata(name, record)
        self.writer.finish()
        return self.count


def read_mcap(path: str):
    """Read a plan written by ``write_mcap`` back into a ``Trajectory`` (CRCs validated).

    Reads ``ros1`` setpoints (what ``write_mcap`` writes) and ``json`` ones (the layout
    of earlier versions, one JSON object per sample)."""
    from mcap.reader import make_reader

    from ..plan.trajectory import Trajectory

    loc = SourceLocation(file=str(path))
    try:
        with open(path, "rb") as fh:
            reader = make_reader(fh, validate_crcs=True)
            summary = reader.get_summary()
            meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
            axes, channel = _setpoints_channel(summary, loc)
            schema = summary.schemas.get(channel.schema_id) if summary is not None else None
            if channel.message_encoding == MESSAGE_ENCODING:
                times, table, line = _read_ros1_setpoints(fh, reader, summary, channel, schema, axes, loc)
            elif channel.message_encoding == "json":
                times, table, line = _read_json_setpoints(fh, reader, summary, channel.id, axes, loc)
            else:
                raise UsageError(f"{SETPOINTS_TOPIC} messages in an unknown encoding {channel.message_encoding!r}", loc)
    except OSError as exc:
        raise UsageError(f"cannot read MCAP file: {exc.strerror or exc}", loc) from None
    except (UsageError, MemoryError):
        raise
    except Exception as exc:  # noqa: BLE001 - any decoding failure of the file is bad input
        raise UsageError(f"not a readable MCAP plan: {type(exc).__name__}: {exc}", loc) from None
    # the log time is what a player schedules by: it must be the sample's own t
    log_ns = times.astype(np.float64)
    t_ns = table[:, 0] * 1e9
    with np.errstate(invalid="ignore"):
        off = ~(np.abs(log_ns - t_ns) <= LOG_TIME_TOL_NS + np.spacing(np.abs(t_ns)))
    if off.any():
        k = int(np.argmax(off))
        raise UsageError(
            f"{SETPOINTS_TOPIC} message {k}: log time {int(times[k])} ns is not its t = {table[k, 0]!r} s", loc
        )
    planner = meta.get("planner", {})
    try:
        settings = json.loads(planner.get("settings", "{}"))
    except ValueError:
        settings = {}
    t = table[:, 0]
    dt_s = _float_or(planner.get("dt_s"), float(t[1] - t[0]) if t.size > 1 else 0.0)
    return Trajectory(
        axes=axes,
        dt_s=dt_s,
        t=t,
        s=table[:, 1],
        feed=table[:, 2],
        q=table[:, 3:],
        line=line,
        planner=planner.get("name", "unknown"),
        settings=settings,
        status=planner.get("status", "ok"),
    )


def _read_ros1_setpoints(fh, reader, summary, channel, schema, axes: str, loc):
    """(log times, (K, 3 + n) table of t, s, feed and the axes, line) of ros1 setpoints,
    in time order."""
    from .mcap_bulk import read_channel_fixed

    if schema is None or schema.encoding != SCHEMA_ENCODING:
        raise UsageError(f"{SETPOINTS_TOPIC} has no {SCHEMA_ENCODING} schema", loc)
    dtype = np.dtype(message_fields(schema.data.decode("utf-8")))
    names = dtype.names or ()
    missing = [f for f in ("t", "s", "feed", *axes) if f not in names]
    if missing:
        raise UsageError(f"the {SETPOINTS_TOPIC} schema lacks the field {missing[0]!r}", loc)
    found = read_channel_fixed(fh, summary, channel.id, dtype.itemsize)
    if found is None:  # not indexed the way write_mcap indexes: the generic reader
        msgs = [
            (m.log_time, m.data) for _, _, m in reader.iter_messages(topics=[SETPOINTS_TOPIC], log_time_order=False)
        ]
        bad = [len(d) for _, d in msgs if len(d) != dtype.itemsize]
        if bad:
            raise UsageError(f"a {SETPOINTS_TOPIC} message is {bad[0]} bytes, not {dtype.itemsize}", loc)
        found = (
            np.array([m[0] for m in msgs], dtype=np.uint64),
            np.frombuffer(b"".join(m[1] for m in msgs), dtype=np.uint8).reshape(len(msgs), dtype.itemsize),
        )
    times, payload = found
    if not times.size:
        raise UsageError(f"MCAP file has no {SETPOINTS_TOPIC} messages", loc)
    order = np.argsort(times, kind="stable")  # file order, then a stable sort by time
    rec = payload[order].view(dtype).reshape(-1)
    table = np.empty((rec.size, 3 + len(axes)))
    for i, f in enumerate(("t", "s", "feed", *axes)):
        table[:, i] = rec[f]
    line = rec["line"].astype(np.int64) if "line" in names else np.zeros(rec.size, dtype=np.int64)
    return times[order], table, line


def _read_json_setpoints(fh, reader, summary, channel_id: int, axes: str, loc):
    """(log times, table, line) of JSON setpoints (one object per sample), in time order."""
    from .mcap_bulk import read_channel

    found = read_channel(fh, summary, channel_id)
    if found is None:  # not indexed the way write_mcap indexes: the generic reader
        msgs = [
            (m.log_time, m.data) for _, _, m in reader.iter_messages(topics=[SETPOINTS_TOPIC], log_time_order=False)
        ]
        found = (np.array([m[0] for m in msgs], dtype=np.uint64), [m[1] for m in msgs])
    # File order, then a stable sort by time (mcap's own time ordering is a Python
    # heap, slower than everything else here).
    times, payloads = found
    order = np.argsort(times, kind="stable")
    datas = [payloads[i] for i in order.tolist()]
    if not datas:
        raise UsageError(f"MCAP file has no {SETPOINTS_TOPIC} messages", loc)
    try:
        rows = json.loads(b"[" + b",".join(datas) + b"]")
        pick = operator.itemgetter("t", "s", "feed", *axes)
        picked = list(map(pick, rows))
        # JSON numbers only (null: a non-finite value as written, read as NaN): a string
        # or a boolean would pass numpy's float conversion
        kinds = set(map(type, itertools.chain.from_iterable(picked)))
        if not kinds <= _NUMBER_TYPES:
            odd = sorted(k.__name__ for k in kinds - _NUMBER_TYPES)
            raise UsageError(f"a {SETPOINTS_TOPIC} message holds a {', '.join(odd)} where a number belongs", loc)
        table = np.array(picked, dtype=float).reshape(len(rows), 3 + len(axes))
        del picked
        line = np.array([r.get("line") or 0 for r in rows], dtype=np.int64)
    except KeyError as exc:
        raise UsageError(f"a {SETPOINTS_TOPIC} message lacks the field {exc}", loc) from None
    except (ValueError, TypeError, AttributeError) as exc:
        raise UsageError(f"bad {SETPOINTS_TOPIC} message: {exc}", loc) from None
    return times[order], table, line


def read_mcap_machine_record(path: str) -> dict[str, str] | None:
    """The ``machine`` metadata record of an MCAP plan (name, source, axes, limits as
    written), or ``None`` when the file has none or cannot be read."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as fh:
            return next((dict(m.metadata) for m in make_reader(fh).iter_metadata() if m.name == "machine"), None)
    except Exception:  # noqa: BLE001 - unreadable: read_mcap reports it properly
        return None


# -- writing -------------------------------------------------------------------------------
def _time_ns(t: np.ndarray) -> np.ndarray:
    """Sample times in integer ns (MCAP times are unsigned)."""
    ns = np.rint(np.asarray(t, dtype=float) * 1e9)
    ns = np.where(np.isfinite(ns), ns, 0.0)
    return np.maximum(ns, 0).astype(np.int64)


# -- message packing -----------------------------------------------------------------------
def _record_dtype(fields: list[tuple[str, str]]) -> np.dtype:
    """A Message record (MCAP header, then the packed ros1 payload) as a numpy dtype."""
    from .mcap_bulk import MESSAGE_HEAD_FIELDS

    return np.dtype([("head", np.dtype(MESSAGE_HEAD_FIELDS)), ("body", np.dtype(fields))])


def _fill_head(head: np.ndarray, channel: int, ns: np.ndarray, payload_bytes: int) -> None:
    """Message headers: channel, sequence 0, log time = publish time = ``ns``."""
    from .mcap_bulk import _MSG_FIXED, _OP_MESSAGE

    head["op"] = _OP_MESSAGE
    head["len"] = _MSG_FIXED + payload_bytes
    head["ch"] = channel
    head["seq"] = 0
    head["log"] = ns
    head["pub"] = ns


def _pack_rows(w: "McapPlanWriter", t, s, feed, q, line) -> np.ndarray:
    """The /setpoints records of samples (t, s, feed (K,), q (K, n), line (K,))."""
    K = t.shape[0]
    rows = np.empty(K, w.row)
    rows[...] = w.template  # the constant header fields, one copy a row
    ns = _time_ns(t)
    ln = np.asarray(line, dtype=np.int64)
    if ln.size and (ln.min() < 0 or ln.max() > _LINE_MAX):
        raise ValueError(f"source line numbers must lie in 0..{_LINE_MAX}")
    rows["head"]["log"] = ns
    rows["head"]["pub"] = ns
    _columns(rows, w.sp_at, 3, "<f8")[:] = np.column_stack([t, s, feed])
    rows["body"]["line"] = ln
    _columns(rows, w.axes_at, q.shape[1], "<f8")[:] = q
    return rows


def _join_records(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Records ``a`` then ``b`` (np.concatenate promotes structured dtypes field by field,
    slowly)."""
    if not a.size:
        return b
    out = np.empty(a.size + b.size, a.dtype)
    out[: a.size] = a
    out[a.size :] = b
    return out


def _extremes(windows: np.ndarray) -> np.ndarray:
    """(m, F) the value of largest magnitude, with its sign, of each column over each
    window of ``windows`` (m, N, F); NaN where a window holds a NaN."""
    if not windows.shape[0]:
        return np.zeros((0, windows.shape[2]))
    with np.errstate(invalid="ignore"):
        i = np.argmax(np.abs(windows), axis=1)  # a NaN is the largest: it is kept
    return np.take_along_axis(windows, i[:, None, :], axis=1)[:, 0, :]


def _columns(rows: np.ndarray, offset: int, n: int, kind: str) -> np.ndarray:
    """(K, n) view of ``n`` consecutive numbers of type ``kind`` at byte ``offset`` of
    every row of ``rows``."""
    if not rows.shape[0]:
        return np.zeros((0, n), dtype=kind)
    return np.ndarray(
        (rows.shape[0], n), dtype=kind, buffer=rows, offset=offset, strides=(rows.itemsize, np.dtype(kind).itemsize)
    )


def _segment_starts(line: np.ndarray, max_samples: int) -> np.ndarray:
    """Where segments start among samples of source lines ``line``: at 0, at every change
    of line, and every ``max_samples`` samples into a longer run of one line."""
    n = line.shape[0]
    b = np.concatenate([[0], np.flatnonzero(line[1:] != line[:-1]) + 1]).astype(np.int64)
    extra = (np.diff(np.append(b, n)) - 1) // max_samples  # splits of each run
    if not extra.any():
        return b
    reps = extra + 1
    first = np.repeat(np.cumsum(reps) - reps, reps)
    return np.repeat(b, reps) + (np.arange(int(reps.sum())) - first) * max_samples


def _ratio_rows(qh: np.ndarray, dt_s: float, limits: np.ndarray) -> np.ndarray:
    """(K, 3n) signed v, a, j ratios per axis (grouped by kind) of the samples qh[3:],
    qh[:3] being the three samples before them: ``ratios.limit_ratios``' differences and
    zero-limit convention, all axes at once."""
    n = qh.shape[1]
    K = qh.shape[0] - 3
    table = np.empty((K, 3 * n))
    d = np.asarray(qh, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        for m in range(3):
            d = np.diff(d, axis=0)  # the (m+1)-th difference; its last K rows end at the samples
            out = table[:, m * n : (m + 1) * n]
            np.divide(d[-K:] / dt_s ** (m + 1), limits[m], out=out)
            if not (limits[m] > 0).all():
                out[:, ~(limits[m] > 0)] = np.where(d[-K:, ~(limits[m] > 0)] == 0.0, 0.0, out[:, ~(limits[m] > 0)])
    return table


def _with_worst(env: np.ndarray) -> np.ndarray:
    """(m, 3n+1): the ratios ``env`` (m, 3n) and the largest |ratio| of each row (NaN
    when one is NaN)."""
    out = np.empty((env.shape[0], env.shape[1] + 1))
    out[:, :-1] = env
    out[:, -1] = np.abs(env).max(axis=1) if env.shape[1] else 0.0
    return out


def _fixed_segments(traj, segments, seg_rec: np.dtype, channel: int) -> tuple[np.ndarray, np.ndarray]:
    """Sample index where each given segment (line, s_start, s_end) starts (ascending)
    and its record (``seg_rec``), from a whole trajectory."""
    t, s, feed = traj.t, traj.s, traj.feed
    K = traj.n_samples
    if K == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, seg_rec)
    seg = np.asarray(segments, dtype=float).reshape(-1, 3)
    lines = seg[:, 0].astype(np.int64)
    starts = np.clip(np.searchsorted(s, seg[:, 1], side="left"), 0, K - 1)
    ends = np.clip(np.searchsorted(s, seg[:, 2], side="left"), 0, K - 1)
    ends = np.maximum(ends, starts)
    order = np.argsort(starts, kind="stable")
    starts, ends, lines = starts[order], ends[order], lines[order]
    recs = np.zeros(starts.size, seg_rec)
    _fill_head(recs["head"], channel, _time_ns(t[starts]), seg_rec["body"].itemsize)
    fin = np.where(np.isfinite(feed), feed, np.nan)
    body = recs["body"]
    body["line"] = lines
    body["s_start"], body["s_end"] = s[starts], s[ends]
    body["t_start"], body["t_end"] = t[starts], t[ends]
    for j, (i0, i1) in enumerate(zip(starts.tolist(), ends.tolist())):
        part = fin[i0 : i1 + 1]
        ok = part[~np.isnan(part)]
        body["feed_min"][j] = ok.min() if ok.size else np.nan
        body["feed_max"][j] = ok.max() if ok.size else np.nan
    body["samples"] = ends - starts + 1
    return np.asarray(starts, dtype=np.int64), recs


def _num(x) -> str:
    x = float(x)
    return repr(x) if math.isfinite(x) else "null"


# -- schemas and metadata ------------------------------------------------------------------
def _unit(axis: str) -> str:
    from ..constants import ROTARY_AXES

    return "deg" if axis in ROTARY_AXES else "mm"


def _units(axes: str) -> str:
    return _dumps({"t": "s", "s": "mm", "feed": "mm/s", "line": "", **{a: _unit(a) for a in axes}})


def _setpoint_fields(axes: str) -> list[tuple[str, str]]:
    return [("t", "<f8"), ("s", "<f8"), ("feed", "<f8"), ("line", "<i4")] + [(a, "<f8") for a in axes]


def _limits_fields(axes: str) -> list[tuple[str, str]]:
    return [(f"{k}.{a}", "<f4") for k in "vaj" for a in axes] + [("worst", "<f4")]


_SEGMENT_FIELDS = [
    ("line", "<i4"),
    ("s_start", "<f8"),
    ("s_end", "<f8"),
    ("t_start", "<f8"),
    ("t_end", "<f8"),
    ("feed_min", "<f8"),
    ("feed_max", "<f8"),
    ("samples", "<u4"),
]

#: ros1msg type names of the numpy field types used here
_ROS1_TYPES = {"<f8": "float64", "<f4": "float32", "<i4": "int32", "<u4": "uint32", "<i8": "int64", "<u8": "uint64"}
_NUMPY_TYPES = {v: k for k, v in _ROS1_TYPES.items()}


def _setpoint_msg(axes: str) -> str:
    notes = {
        "t": "time since the start of the plan, s",
        "s": "path length travelled since the start, mm",
        "feed": "path speed, mm/s (backward difference of s)",
        "line": "source line executing (0 = none)",
    }
    notes.update({a: f"axis {a} setpoint, {_unit(a)} (NaN if not finite)" for a in axes})
    body = "\n".join(f"{_ROS1_TYPES[k]} {f}  # {notes[f]}" for f, k in _setpoint_fields(axes))
    return f"# {SETPOINT_TYPE}: one sample of the plan\n{body}\n"


def _segment_msg() -> str:
    notes = {
        "line": "source line of the segment",
        "s_start": "path length where the segment starts, mm",
        "s_end": "path length where the segment ends, mm",
        "t_start": "time the tool enters the segment, s",
        "t_end": "time the tool leaves the segment, s",
        "feed_min": "lowest planned feed on the segment, mm/s (NaN if none is finite)",
        "feed_max": "highest planned feed on the segment, mm/s (NaN if none is finite)",
        "samples": "samples on the segment",
    }
    body = "\n".join(f"{_ROS1_TYPES[k]} {f}  # {notes[f]}" for f, k in _SEGMENT_FIELDS)
    return f"# {SEGMENT_TYPE}: one fitted segment, at the time the tool enters it\n{body}\n"


def _limits_msg(axes: str) -> str:
    kinds = (("v", "velocity", "vmax"), ("a", "acceleration", "amax"), ("j", "jerk", "jmax"))
    top = "\n".join(f"{AXIS_RATIOS_TYPE} {k}  # signed {name} / {lim} per axis" for k, name, lim in kinds)
    inner = "\n".join(f"float32 {a}  # axis {a}" for a in axes)
    return (
        f"# {LIMITS_TYPE}: signed ratios of each axis's motion to its limits (|ratio| <= 1 within)\n"
        f"{top}\nfloat32 worst  # largest |ratio| of the sample (> 1 = limit exceeded)\n"
        f"{_ROS1_SEPARATOR}\nMSG: {AXIS_RATIOS_TYPE}\n{inner}\n"
    )


def message_fields(definition: str) -> list[tuple[str, str]]:
    """The packed layout of a ``ros1msg`` definition made of fixed-size numbers and
    nested messages of them: ``[(field, numpy type)]``, nested fields named
    ``outer.inner``. Raises ``ValueError`` on anything else (strings, arrays, ...)."""
    blocks: list[list[str]] = [[]]
    for raw in definition.splitlines():
        text = raw.split("#", 1)[0].strip()
        if raw.strip().startswith("=="):
            blocks.append([])
        elif text:
            blocks[-1].append(text)
    named: dict[str, list[str]] = {}
    for block in blocks[1:]:
        if not block or not block[0].startswith("MSG:"):
            raise ValueError("a nested definition does not start with MSG:")
        named[block[0][4:].strip()] = block[1:]

    def expand(lines: list[str], prefix: str, depth: int) -> list[tuple[str, str]]:
        if depth > 8:
            raise ValueError("message definitions nest too deep")
        out: list[tuple[str, str]] = []
        for text in lines:
            if "=" in text:
                continue  # a constant: not serialised
            parts = text.split()
            if len(parts) != 2:
                raise ValueError(f"cannot read the definition line {text!r}")
            kind, name = parts
            if kind in _NUMPY_TYPES:
                out.append((prefix + name, _NUMPY_TYPES[kind]))
            else:
                sub = named.get(kind) or next((v for k, v in named.items() if k.endswith("/" + kind)), None)
                if sub is None:
                    raise ValueError(f"unsupported field type {kind!r}")
                out.extend(expand(sub, f"{prefix}{name}.", depth + 1))
        return out

    return expand(blocks[0], "", 0)


def decode_message(schema, data: bytes) -> dict:
    """One message of a plan as a dict (nested for ``/limits``' v, a, j): ``json``
    messages parsed, ``ros1`` ones unpacked by their schema. For tools and tests."""
    if schema.encoding != SCHEMA_ENCODING:
        return json.loads(data)
    dtype = np.dtype(message_fields(schema.data.decode("utf-8")))
    if len(data) != dtype.itemsize:
        raise ValueError(f"a {schema.name} message is {len(data)} bytes, not {dtype.itemsize}")
    rec = np.frombuffer(data, dtype=dtype)[0]
    out: dict = {}
    for name in dtype.names or ():
        *outer, leaf = name.split(".")
        node = out
        for key in outer:
            node = node.setdefault(key, {})
        node[leaf] = rec[name].item()
    return out


def _metadata_records(planner: dict, metadata, machine, mcap_version) -> list[tuple[str, dict]]:
    from .. import __version__

    records: dict[str, dict] = {}
    if machine is not None:
        rec = {
            "name": machine.name,
            "axes": machine.axes,
            "kinematics": machine.kinematics,
            "dt_s": float(machine.dt_s),
            "source": machine.source,
            "kinematics_params": machine.kinematics_params,
            "start": np.asarray(machine.start, dtype=float).tolist(),
        }
        for i, a in enumerate(machine.axes):
            for lim, arr in (("vmax", machine.vmax), ("amax", machine.amax), ("jmax", machine.jmax)):
                rec[f"{a}.{lim}"] = float(arr[i])
        records["machine"] = rec
    records["planner"] = dict(planner)
    records["tool"] = {"name": "cnc-interp", "version": __version__, "mcap_library": f"mcap-python/{mcap_version}"}
    for name, rec in (metadata or {}).items():
        # The caller's keys add to (and override) the ones built here.
        records.setdefault(str(name), {}).update(rec)
    return [(name, {str(k): _meta_value(v) for k, v in sorted(rec.items())}) for name, rec in sorted(records.items())]


def _meta_value(v) -> str:
    if isinstance(v, str):
        return v
    if isinstance(v, (float, np.floating)):
        return _num(v)
    return _dumps(v)


def _dumps(obj) -> str:
    """Compact, key-sorted JSON with non-finite numbers as null."""
    return json.dumps(_finite(obj), sort_keys=True, separators=(",", ":"), allow_nan=False)


def _finite(obj):
    if isinstance(obj, dict):
        return {str(k): _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _finite(obj.tolist())
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, (str, int, bool)) or obj is None:
        return obj
    return str(obj)


# -- reading helpers -----------------------------------------------------------------------
def _setpoints_channel(summary, loc):
    """(axis letters, channel) of the ``/setpoints`` channel."""
    if summary is None:
        raise UsageError("MCAP file has no summary section", loc)
    for ch in summary.channels.values():
        if ch.topic == SETPOINTS_TOPIC:
            axes = ch.metadata.get("axes")
            if axes is None:
                schema = summary.schemas[ch.schema_id]
                if schema.encoding == SCHEMA_ENCODING:
                    names = [f for f, _ in message_fields(schema.data.decode("utf-8"))]
                else:
                    names = list(json.loads(schema.data)["properties"])
                axes = "".join(k for k in names if len(k) == 1 and k.isupper())
            return axes, ch
    raise UsageError(f"MCAP file has no {SETPOINTS_TOPIC} channel", loc)


def _float_or(text, default: float) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        return default

"""MCAP output for Foxglove (and anything else that reads MCAP), and reading it back.

Channels (all ``json`` messages under a ``jsonschema`` schema; log time = publish time =
the sample time in ns from the start of the plan):

- ``/setpoints``: one message per sample: ``t`` (s), ``s`` (mm), ``feed`` (mm/s),
  ``line`` (source line executing, 0 = none) and one field per machine axis letter
  (mm, or deg for A/B/C).
- ``/segments``: one message per fitted segment, at the time the tool enters it:
  ``line``, ``s_start``/``s_end`` (mm), ``t_start``/``t_end`` (s), ``feed_min``/``feed_max``
  (planned feed over the segment, mm/s) and ``samples``.
- ``/limits`` (when a machine is given): one message per sample: ``v``, ``a``, ``j``
  objects with one signed ratio per axis (velocity / vmax, ...; within limits means
  |ratio| <= 1), from rest-padded backward differences of the setpoints (the
  ``verify`` convention), and ``worst`` = the largest |ratio| of the sample.

Metadata records: ``machine`` (name, axes, kinematics, dt, and every axis's vmax/amax/jmax),
``input`` (name, sha256, lines — as given by the caller, see ``input_metadata``),
``planner`` (name, status, dt, settings) and ``tool`` (name, version, mcap library).

The file is a pure function of its inputs: fixed chunk size, no wall-clock times,
fixed key order, non-finite numbers written as ``null``. Setpoint numbers are written
with ``repr`` (the shortest form that reads back as the same float64, as in the CSV), so
``verify`` of the MCAP checks exactly the planned values; the ``/limits`` ratios, which are
for looking at, carry 9 significant digits.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import operator
from typing import Iterable, Mapping

import numpy as np

from ..errors import SourceLocation, UsageError


#: MCAP chunk size (uncompressed bytes); fixed so the same plan gives the same file
MCAP_CHUNK_BYTES = 4 * 1024 * 1024

#: a /segments message covers at most this many samples (a longer run of one source
#: line, e.g. a long dwell, is split): the messages of an open segment wait for its end
MCAP_SEGMENT_MAX_SAMPLES = 1 << 16

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

#: ratios are for looking at: 9 significant digits (half the size and time of repr)
RATIO_FORMAT = "%.9g"

_SEG_FIELDS = ("line", "s_start", "s_end", "t_start", "t_end", "feed_min", "feed_max", "samples")


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

    fixed = _fixed_segments(traj, segments) if segments is not None else None
    with atomic_write(out) as fh:
        w = McapPlanWriter(fh, traj.axes, traj.dt_s, machine, fixed_segments=fixed)
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

    A ``/segments`` message is written at the sample where its segment starts, but holds
    the segment's end (time, feed range, samples): the messages of an open segment wait
    until it closes, at a change of source line or after ``MCAP_SEGMENT_MAX_SAMPLES``
    samples (a long segment is split), which bounds what waits. The metadata records,
    which hold what is known only at the end (samples, status, statistics), follow the
    messages.
    """

    def __init__(self, fh, axes: str, dt_s: float, machine=None, fixed_segments=None):
        from .. import __version__
        from .mcap_bulk import BulkMcapWriter

        self.axes = axes
        self.dt_s = float(dt_s)
        self.machine = machine
        # Same bytes as mcap.writer.Writer(fh, chunk_size, CompressionType.ZSTD), faster.
        self.writer = writer = BulkMcapWriter(_Tell(fh), chunk_size=MCAP_CHUNK_BYTES)
        # A fixed library string: no timestamps, nothing host-specific in the header.
        writer.start(profile="", library=f"cnc-interp/{__version__}")
        sp_schema = writer.register_schema(
            "cnc_interp.Setpoint", "jsonschema", _schema_json(_setpoint_schema(axes)).encode()
        )
        self.sp_chan = writer.register_channel(
            SETPOINTS_TOPIC, "json", sp_schema, {"axes": axes, "units": _units(axes)}
        )
        seg_schema = writer.register_schema(
            "cnc_interp.Segment", "jsonschema", _schema_json(_segment_schema()).encode()
        )
        self.seg_chan = writer.register_channel(SEGMENTS_TOPIC, "json", seg_schema, {})
        self.lim_chan = None
        self.lim_axes = ""
        if machine is not None:
            self.lim_axes = "".join(a for a in axes if a in machine.axes)
            lim_schema = writer.register_schema(
                "cnc_interp.LimitRatios", "jsonschema", _schema_json(_limits_schema(self.lim_axes)).encode()
            )
            self.lim_chan = writer.register_channel(LIMITS_TOPIC, "json", lim_schema, {"axes": self.lim_axes})
            self.lim_idx = [axes.index(a) for a in self.lim_axes]
            self.limits = machine.limits()[:, [machine.axes.index(a) for a in self.lim_axes]]
        self.sp_fmt = _template(("t", "s", "feed", "line", *axes))
        self.lim_fmt = _limits_template(self.lim_axes) if self.lim_chan is not None else None
        self.seg_fmt = _template(_SEG_FIELDS)
        self.fixed = fixed_segments  # (starts, messages) computed from a whole trajectory
        self.k = 0  # samples written
        self.count = 0
        self.hist: np.ndarray | None = None  # the last 3 samples (limit ratios' stencils)
        # the open segment: its first sample, its samples' t/s/feed/line, waiting messages
        self.seg0 = 0
        self.pend_tsf = np.zeros((0, 3))
        self.pend_line = np.zeros(0, dtype=np.int64)
        self.pend: list[tuple[np.ndarray, np.ndarray, np.ndarray, list]] = []

    # -- messages of one block -------------------------------------------------------------
    def _messages(self, t, s, feed, q, line):
        K = t.shape[0]
        k = np.arange(self.k, self.k + K, dtype=np.int64)
        ns = _time_ns(t)
        datas = _format_rows(self.sp_fmt, [t, s, feed, np.asarray(line, dtype=np.int64), *q.T])
        chans = [np.full(K, self.sp_chan)]
        times = [ns]
        keys = [3 * k + 1]
        if self.lim_chan is not None:
            sub = q[:, self.lim_idx]
            h = self.hist if self.hist is not None else np.repeat(sub[:1], 3, axis=0)
            ratios = _ratio_rows(np.concatenate([h, sub]), self.dt_s, self.limits)
            datas += _format_rows(self.lim_fmt, list(ratios.T), RATIO_FORMAT)
            chans.append(np.full(K, self.lim_chan))
            times.append(ns)
            keys.append(3 * k + 2)
            self.hist = np.concatenate([h, sub])[-3:]
        return np.concatenate(chans), np.concatenate(times), np.concatenate(keys), datas

    def write(self, t, s, feed, q, line) -> None:
        """Append the next samples (t, s, feed (K,), q (K, n), line (K,))."""
        t = np.asarray(t, dtype=float)
        K = t.shape[0]
        if not K:
            return
        s = np.asarray(s, dtype=float)
        feed = np.asarray(feed, dtype=float)
        q = np.asarray(q, dtype=float).reshape(K, -1)
        line = np.asarray(line, dtype=np.int64)
        chans, times, keys, datas = self._messages(t, s, feed, q, line)
        k0 = self.k
        self.k += K
        if self.fixed is not None:
            self._release_fixed(chans, times, keys, datas, k0, K)
            return
        self.pend.append((chans, times, keys, datas))
        self.pend_tsf = np.concatenate([self.pend_tsf, np.stack([t, s, feed], axis=1)])
        self.pend_line = np.concatenate([self.pend_line, line])
        self._close_segments(final=False)

    def _close_segments(self, final: bool) -> None:
        """Write every segment of the waiting samples that is known to have ended (at the
        end of the plan, ``final``, the last one too)."""
        line = self.pend_line
        n = line.shape[0]
        a = 0
        while a < n:
            # the segment starting at local sample a ends where the next begins: at the next
            # change of line, or MCAP_SEGMENT_MAX_SAMPLES samples on
            top = min(n, a + MCAP_SEGMENT_MAX_SAMPLES + 1)
            change = np.flatnonzero(line[a + 1 : top] != line[a])
            if change.size:
                c = a + 1 + int(change[0])
            elif top - a > MCAP_SEGMENT_MAX_SAMPLES:
                c = a + MCAP_SEGMENT_MAX_SAMPLES
            elif final:
                self._emit_segment(a, n - 1, n)  # the last segment ends at the last sample
                a = n
                break
            else:
                break
            self._emit_segment(a, c, c)
            a = c
        if a:
            self.pend_tsf = self.pend_tsf[a:]
            self.pend_line = self.pend_line[a:]
            self.seg0 += a

    def _emit_segment(self, a: int, c: int, release: int) -> None:
        """The segment of waiting samples a..c (c: where the next begins, or the last
        sample), then the waiting messages of samples a..release-1."""
        ln = int(self.pend_line[a])
        tsf = self.pend_tsf
        i0 = self.seg0 + a
        out_c, out_t, out_k, out_d = [], [], [], []
        if ln != 0:
            fseg = tsf[a : c + 1, 2]
            fin = fseg[np.isfinite(fseg)]
            vals = (
                ln,
                _num(tsf[a, 1]),
                _num(tsf[c, 1]),
                _num(tsf[a, 0]),
                _num(tsf[c, 0]),
                _num(fin.min()) if fin.size else "null",
                _num(fin.max()) if fin.size else "null",
                int(c - a + 1),
            )
            out_c.append(np.array([self.seg_chan]))
            out_t.append(_time_ns(tsf[a : a + 1, 0]))
            out_k.append(np.array([3 * i0], dtype=np.int64))
            out_d.append([(self.seg_fmt % vals).encode()])
        lim_key = 3 * (self.seg0 + release)
        keep = []
        for chans, times, keys, datas in self.pend:
            sel = keys < lim_key
            if sel.all():
                out_c.append(chans), out_t.append(times), out_k.append(keys), out_d.append(datas)
            elif sel.any():
                idx = np.flatnonzero(sel)
                rest = np.flatnonzero(~sel)
                out_c.append(chans[idx]), out_t.append(times[idx]), out_k.append(keys[idx])
                out_d.append([datas[i] for i in idx.tolist()])
                keep.append((chans[rest], times[rest], keys[rest], [datas[i] for i in rest.tolist()]))
            else:
                keep.append((chans, times, keys, datas))
        self.pend = keep
        self._add(out_c, out_t, out_k, out_d)

    def _add(self, chans, times, keys, datas) -> None:
        if not chans:
            return
        keys = np.concatenate(keys)
        order = np.argsort(keys, kind="stable")
        flat = [d for part in datas for d in part]
        self.writer.add_messages(
            np.concatenate(chans)[order], np.concatenate(times)[order], [flat[i] for i in order.tolist()]
        )
        self.count += len(flat)

    def _release_fixed(self, chans, times, keys, datas, k0: int, K: int) -> None:
        starts, msgs = self.fixed
        sel = np.flatnonzero((starts >= k0) & (starts < k0 + K))
        c, t, k, d = [chans], [times], [keys], [datas]
        if sel.size:
            c.append(np.full(sel.size, self.seg_chan))
            t.append(times[starts[sel] - k0])
            k.append(3 * starts[sel])
            d.append([msgs[i] for i in sel.tolist()])
        self._add(c, t, k, d)

    # -- the end -----------------------------------------------------------------------------
    def finish(self, planner: dict, metadata: Mapping | None = None) -> int:
        """Close the last segment, write the metadata records and the summary. Returns
        the number of messages written."""
        from mcap import __version__ as mcap_version

        if self.fixed is None:
            self._close_segments(final=True)
        self.writer._finalize_chunk()
        for name, record in _metadata_records(planner, metadata, self.machine, mcap_version):
            self.writer.add_metadata(name, record)
        self.writer.finish()
        return self.count


def read_mcap(path: str):
    """Read a plan written by ``write_mcap`` back into a ``Trajectory`` (CRCs validated)."""
    from mcap.reader import make_reader

    from ..plan.trajectory import Trajectory
    from .mcap_bulk import read_channel

    loc = SourceLocation(file=str(path))
    try:
        with open(path, "rb") as fh:
            reader = make_reader(fh, validate_crcs=True)
            summary = reader.get_summary()
            meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
            axes, channel_id = _axes_from_summary(summary, loc)
            found = read_channel(fh, summary, channel_id)
            if found is None:  # not indexed the way write_mcap indexes: the generic reader
                msgs = [
                    (msg.log_time, msg.data)
                    for _, _, msg in reader.iter_messages(topics=[SETPOINTS_TOPIC], log_time_order=False)
                ]
                found = (np.array([m[0] for m in msgs], dtype=np.uint64), [m[1] for m in msgs])
            # File order, then a stable sort by time (mcap's own time ordering is a Python
            # heap, slower than everything else here).
            times, payloads = found
            order = np.argsort(times, kind="stable")
            datas = [payloads[i] for i in order.tolist()]
    except OSError as exc:
        raise UsageError(f"cannot read MCAP file: {exc.strerror or exc}", loc) from None
    except (UsageError, MemoryError):
        raise
    except Exception as exc:  # noqa: BLE001 - any decoding failure of the file is bad input
        raise UsageError(f"not a readable MCAP plan: {type(exc).__name__}: {exc}", loc) from None
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
    # the log time is what a player schedules by: it must be the sample's own t
    log_ns = times[order].astype(np.float64)
    t_ns = table[:, 0] * 1e9
    off = np.abs(log_ns - t_ns) > LOG_TIME_TOL_NS + np.spacing(np.abs(t_ns))
    if off.any():
        k = int(np.argmax(off))
        raise UsageError(
            f"{SETPOINTS_TOPIC} message {k}: log time {int(times[order][k])} ns is not its t = {table[k, 0]!r} s", loc
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


# -- message formatting --------------------------------------------------------------------
def _template(fields: Iterable[str]) -> str:
    """A ``%``-template producing ``{"f1":v1,"f2":v2,...}`` for fields in a fixed order."""
    return "{" + ",".join(f"{json.dumps(f)}:%s" for f in fields) + "}"


def _limits_template(lim_axes: str) -> str:
    groups = []
    for key in ("v", "a", "j"):
        inner = ",".join(f"{json.dumps(a)}:%s" for a in lim_axes)
        groups.append(f'"{key}":{{{inner}}}')
    return "{" + ",".join(groups) + ',"worst":%s}'


def _format_rows(fmt: str, columns: list[np.ndarray], spec: str = "%r") -> list[bytes]:
    """Format row k of the given columns into ``fmt`` (a template of ``%s`` slots).

    Values print with ``spec``: ``%r`` (default) is the shortest form that reads back as
    the same float64 (integer columns print as integers); non-finite values print as
    ``null``.
    """
    finite = all(c.dtype.kind in "iub" or bool(np.isfinite(c).all()) for c in columns)
    rows = zip(*(c.tolist() for c in columns))
    if finite:
        fast = fmt.replace("%s", spec)
        out = [fast % r for r in rows]
    else:
        out = [fmt % tuple(spec % v if math.isfinite(v) else "null" for v in r) for r in rows]
    return [m.encode() for m in out]


def _ratio_rows(qh: np.ndarray, dt_s: float, limits: np.ndarray) -> np.ndarray:
    """(K, 3n+1) signed v, a, j ratios per axis (grouped by kind) and the worst |ratio| of
    the samples qh[3:], qh[:3] being the three samples before them (rest before 0)."""
    from .ratios import limit_ratios

    r = limit_ratios(qh, dt_s, limits)[:, 3:]  # (3, K, n)
    n = qh.shape[1]
    K = qh.shape[0] - 3
    table = np.empty((K, 3 * n + 1))
    for kind in range(3):
        table[:, kind * n : (kind + 1) * n] = r[kind]
    with np.errstate(invalid="ignore"):
        table[:, -1] = np.abs(r).max(axis=(0, 2)) if n else 0.0
    return table


def _fixed_segments(traj, segments) -> tuple[np.ndarray, list[bytes]]:
    """Sample index where each given segment (line, s_start, s_end) starts (ascending)
    and its encoded message, from a whole trajectory."""
    t, s, feed = traj.t, traj.s, traj.feed
    K = traj.n_samples
    if K == 0:
        return np.zeros(0, dtype=np.int64), []
    seg = np.asarray(segments, dtype=float).reshape(-1, 3)
    lines = seg[:, 0].astype(np.int64)
    starts = np.clip(np.searchsorted(s, seg[:, 1], side="left"), 0, K - 1)
    ends = np.clip(np.searchsorted(s, seg[:, 2], side="left"), 0, K - 1)
    ends = np.maximum(ends, starts)
    order = np.argsort(starts, kind="stable")
    starts, ends, lines = starts[order], ends[order], lines[order]
    fmt = _template(_SEG_FIELDS)
    msgs = []
    for i0, i1, ln in zip(starts.tolist(), ends.tolist(), lines.tolist()):
        fseg = feed[i0 : i1 + 1]
        fin = fseg[np.isfinite(fseg)]
        vals = (
            int(ln),
            _num(s[i0]),
            _num(s[i1]),
            _num(t[i0]),
            _num(t[i1]),
            _num(fin.min()) if fin.size else "null",
            _num(fin.max()) if fin.size else "null",
            int(i1 - i0 + 1),
        )
        msgs.append((fmt % vals).encode())
    return np.asarray(starts, dtype=np.int64), msgs


def _num(x) -> str:
    x = float(x)
    return repr(x) if math.isfinite(x) else "null"


# -- schemas and metadata ------------------------------------------------------------------
def _unit(axis: str) -> str:
    from ..constants import ROTARY_AXES

    return "deg" if axis in ROTARY_AXES else "mm"


def _units(axes: str) -> str:
    return _dumps({"t": "s", "s": "mm", "feed": "mm/s", "line": "", **{a: _unit(a) for a in axes}})


def _number(desc: str, nullable: bool = False) -> dict:
    # One type name only: Foxglove's JSON-schema reader rejects type lists such as
    # ["number", "null"]. A null value still parses (and plots as a gap).
    return {"type": "number", "description": desc + (" (null if not finite)" if nullable else "")}


def _setpoint_schema(axes: str) -> dict:
    props = {
        "t": _number("time since the start of the plan, s"),
        "s": _number("path length travelled since the start, mm"),
        "feed": _number("path speed, mm/s (backward difference of s)"),
        "line": {"type": "integer", "description": "source line executing (0 = none)"},
    }
    for a in axes:
        props[a] = _number(f"axis {a} setpoint, {_unit(a)}", nullable=True)
    return {"title": "cnc_interp.Setpoint", "type": "object", "properties": props, "required": list(props)}


def _segment_schema() -> dict:
    props = {
        "line": {"type": "integer", "description": "source line of the segment"},
        "s_start": _number("path length where the segment starts, mm"),
        "s_end": _number("path length where the segment ends, mm"),
        "t_start": _number("time the tool enters the segment, s"),
        "t_end": _number("time the tool leaves the segment, s"),
        "feed_min": _number("lowest planned feed on the segment, mm/s", nullable=True),
        "feed_max": _number("highest planned feed on the segment, mm/s", nullable=True),
        "samples": {"type": "integer", "description": "samples on the segment"},
    }
    return {"title": "cnc_interp.Segment", "type": "object", "properties": props, "required": list(props)}


def _limits_schema(axes: str) -> dict:
    def group(kind, lim):
        return {
            "type": "object",
            "description": f"signed {kind} / {lim} per axis",
            "properties": {a: _number(f"axis {a} {kind} / {lim}", nullable=True) for a in axes},
            "required": list(axes),
        }

    props = {
        "v": group("velocity", "vmax"),
        "a": group("acceleration", "amax"),
        "j": group("jerk", "jmax"),
        "worst": _number("largest |ratio| of the sample (> 1 = limit exceeded)", nullable=True),
    }
    return {"title": "cnc_interp.LimitRatios", "type": "object", "properties": props, "required": list(props)}


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


def _schema_json(schema: dict) -> str:
    """A schema as JSON, fields in message order (the order built here is fixed)."""
    return json.dumps(schema, separators=(",", ":"), allow_nan=False)


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
def _axes_from_summary(summary, loc) -> tuple[str, int]:
    """(axis letters, channel id) of the ``/setpoints`` channel."""
    if summary is None:
        raise UsageError("MCAP file has no summary section", loc)
    for ch in summary.channels.values():
        if ch.topic == SETPOINTS_TOPIC:
            axes = ch.metadata.get("axes")
            if axes is None:
                schema = summary.schemas[ch.schema_id]
                props = json.loads(schema.data)["properties"]
                axes = "".join(k for k in props if len(k) == 1 and k.isupper())
            return axes, ch.id
    raise UsageError(f"MCAP file has no {SETPOINTS_TOPIC} channel", loc)


def _float_or(text, default: float) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        return default

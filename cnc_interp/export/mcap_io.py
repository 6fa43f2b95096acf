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
import io
import json
import math
import operator
from typing import Iterable, Mapping

import numpy as np

from ..constants import MCAP_CHUNK_BYTES
from ..errors import SourceLocation, UsageError

#: samples formatted per batch (bounds memory for very long plans)
_BATCH = 65536

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
    return {"name": name, "sha256": hashlib.sha256(data).hexdigest(), "lines": lines,
            "bytes": len(data)}


def write_mcap(traj, out: str, metadata: Mapping | None = None, machine=None,
               segments=None, progress=None) -> int:
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
            trajectory's arc length; by default one segment per run of equal ``traj.line``.
        progress: optional ``tick(n)`` callable, called with samples written.

    Returns:
        The number of messages written.
    """
    from .atomic import atomic_write

    if out == "-":
        import sys

        # The MCAP writer seeks nothing but needs tell(); a pipe has none, so buffer.
        buf = io.BytesIO()
        count = _write(buf, traj, metadata, machine, segments, progress)
        sys.stdout.buffer.write(buf.getvalue())
        sys.stdout.buffer.flush()
        return count
    with atomic_write(out) as fh:
        return _write(fh, traj, metadata, machine, segments, progress)


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
                msgs = [(msg.log_time, msg.data) for _, _, msg in
                        reader.iter_messages(topics=[SETPOINTS_TOPIC], log_time_order=False)]
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
        table = np.array(list(map(pick, rows)), dtype=float).reshape(len(rows), 3 + len(axes))
        line = np.array([r.get("line") or 0 for r in rows], dtype=np.int64)
    except KeyError as exc:
        raise UsageError(f"a {SETPOINTS_TOPIC} message lacks the field {exc}", loc) from None
    except (ValueError, TypeError, AttributeError) as exc:
        raise UsageError(f"bad {SETPOINTS_TOPIC} message: {exc}", loc) from None
    planner = meta.get("planner", {})
    try:
        settings = json.loads(planner.get("settings", "{}"))
    except ValueError:
        settings = {}
    t = table[:, 0]
    dt_s = _float_or(planner.get("dt_s"), float(t[1] - t[0]) if t.size > 1 else 0.0)
    return Trajectory(axes=axes, dt_s=dt_s, t=t, s=table[:, 1], feed=table[:, 2],
                      q=table[:, 3:], line=line, planner=planner.get("name", "unknown"),
                      settings=settings, status=planner.get("status", "ok"))


def read_mcap_machine(path: str):
    """The ``Machine`` recorded in an MCAP plan's ``machine`` metadata, or ``None``."""
    from mcap.reader import make_reader

    from ..errors import MachineError
    from ..plan.machine import Machine

    try:
        with open(path, "rb") as fh:
            rec = next((dict(m.metadata) for m in make_reader(fh).iter_metadata()
                        if m.name == "machine"), None)
    except Exception:  # noqa: BLE001 - unreadable: read_mcap reports it properly
        return None
    if not rec or "axes" not in rec:
        return None
    axes = rec["axes"]
    try:
        limits = [[float(rec[f"{a}.{lim}"]) for a in axes] for lim in ("vmax", "amax", "jmax")]
        return Machine(name=rec.get("name", "machine"), axes=axes, vmax=limits[0],
                       amax=limits[1], jmax=limits[2], dt_s=float(rec.get("dt_s", "nan")),
                       kinematics=rec.get("kinematics", "trivial"),
                       source=f"{path} (recorded machine)")
    except (KeyError, ValueError, MachineError):  # incomplete or insane: not a usable machine
        return None


# -- writing -------------------------------------------------------------------------------
def _write(fh, traj, metadata, machine, segments, progress) -> int:
    from mcap import __version__ as mcap_version

    from .. import __version__
    from .mcap_bulk import BulkMcapWriter

    axes = traj.axes
    # Same bytes as mcap.writer.Writer(fh, chunk_size, CompressionType.ZSTD), faster.
    writer = BulkMcapWriter(fh, chunk_size=MCAP_CHUNK_BYTES)
    # A fixed library string: no timestamps, nothing host-specific in the header.
    writer.start(profile="", library=f"cnc-interp/{__version__}")

    sp_schema = writer.register_schema("cnc_interp.Setpoint", "jsonschema",
                                       _schema_json(_setpoint_schema(axes)).encode())
    sp_chan = writer.register_channel(SETPOINTS_TOPIC, "json", sp_schema,
                                      {"axes": axes, "units": _units(axes)})
    seg_schema = writer.register_schema("cnc_interp.Segment", "jsonschema",
                                        _schema_json(_segment_schema()).encode())
    seg_chan = writer.register_channel(SEGMENTS_TOPIC, "json", seg_schema, {})
    lim_chan = None
    lim_axes = ""
    if machine is not None:
        lim_axes = "".join(a for a in axes if a in machine.axes)
        lim_schema = writer.register_schema("cnc_interp.LimitRatios", "jsonschema",
                                            _schema_json(_limits_schema(lim_axes)).encode())
        lim_chan = writer.register_channel(LIMITS_TOPIC, "json", lim_schema, {"axes": lim_axes})

    for name, record in _metadata_records(traj, metadata, machine, mcap_version):
        writer.add_metadata(name, record)

    count = _write_messages(writer, traj, machine, lim_axes, segments,
                            sp_chan, seg_chan, lim_chan, progress)
    writer.finish()
    return count


def _write_messages(writer, traj, machine, lim_axes, segments, sp_chan, seg_chan, lim_chan,
                    progress) -> int:
    """All messages in time order: at each sample its segment (if one starts there), its
    setpoint, then its limit ratios. Returns the number of messages."""
    K = traj.n_samples
    axes = traj.axes
    ns = _time_ns(traj.t)
    seg_start, seg_msgs = _segment_messages(traj, segments)
    seg_start = np.asarray(seg_start, dtype=np.int64)
    sp_fmt = _template(("t", "s", "feed", "line", *axes))
    lim_fmt = _limits_template(lim_axes) if lim_chan is not None else None

    count = 0
    for b0 in range(0, K, _BATCH):
        b1 = min(b0 + _BATCH, K)
        k = np.arange(b0, b1, dtype=np.int64)
        datas = _format_rows(sp_fmt, [traj.t[b0:b1], traj.s[b0:b1], traj.feed[b0:b1],
                                      np.asarray(traj.line[b0:b1], dtype=np.int64),
                                      *traj.q[b0:b1].T])
        chans = [np.full(k.size, sp_chan)]
        times = [ns[b0:b1]]
        keys = [3 * k + 1]
        if lim_chan is not None:
            ratios = _ratio_table(traj, machine, lim_axes, b0, b1)
            datas += _format_rows(lim_fmt, list(ratios.T), RATIO_FORMAT)
            chans.append(np.full(k.size, lim_chan))
            times.append(ns[b0:b1])
            keys.append(3 * k + 2)
        sel = np.flatnonzero((seg_start >= b0) & (seg_start < b1))
        if sel.size:
            datas += [seg_msgs[i] for i in sel.tolist()]
            chans.append(np.full(sel.size, seg_chan))
            times.append(ns[seg_start[sel]])
            keys.append(3 * seg_start[sel])
        order = np.argsort(np.concatenate(keys), kind="stable")
        writer.add_messages(np.concatenate(chans)[order], np.concatenate(times)[order],
                            [datas[i] for i in order.tolist()])
        count += len(datas)
        if progress is not None:
            progress(b1 - b0)
    return count


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


def _ratio_table(traj, machine, lim_axes: str, b0: int, b1: int) -> np.ndarray:
    """(b1-b0, 3n+1): samples b0..b1-1's signed v, a, j ratios per axis (grouped by kind)
    and the worst |ratio|. Computed a batch at a time to bound memory."""
    from .ratios import limit_ratios

    idx_t = [traj.axes.index(a) for a in lim_axes]
    idx_m = [machine.axes.index(a) for a in lim_axes]
    limits = machine.limits()[:, idx_m]  # (3, n)
    # Three samples of history give the differences at b0 exactly; limit_ratios pads with
    # rest only before sample 0.
    h0 = max(b0 - 3, 0)
    r = limit_ratios(traj.q[h0:b1, idx_t], traj.dt_s, limits)[:, b0 - h0:]  # (3, m, n)
    n = len(lim_axes)
    table = np.empty((b1 - b0, 3 * n + 1))
    for kind in range(3):
        table[:, kind * n:(kind + 1) * n] = r[kind]
    with np.errstate(invalid="ignore"):
        table[:, -1] = np.abs(r).max(axis=(0, 2)) if n else 0.0
    return table


def _segment_messages(traj, segments) -> tuple[list[int], list[bytes]]:
    """Sample index where each segment starts (ascending) and its encoded message."""
    t, s, feed = traj.t, traj.s, traj.feed
    K = traj.n_samples
    if K == 0:
        return [], []
    if segments is None:
        line = np.asarray(traj.line)
        change = np.flatnonzero(np.diff(line) != 0) + 1
        starts = np.concatenate([[0], change])
        ends = np.concatenate([change, [K - 1]])  # a segment ends where the next begins
        keep = line[starts] != 0
        starts, ends, lines = starts[keep], ends[keep], line[starts][keep]
    else:
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
        fseg = feed[i0:i1 + 1]
        fin = fseg[np.isfinite(fseg)]
        vals = (int(ln), _num(s[i0]), _num(s[i1]), _num(t[i0]), _num(t[i1]),
                _num(fin.min()) if fin.size else "null", _num(fin.max()) if fin.size else "null",
                int(i1 - i0 + 1))
        msgs.append((fmt % vals).encode())
    return starts.tolist(), msgs


def _num(x) -> str:
    x = float(x)
    return repr(x) if math.isfinite(x) else "null"


# -- schemas and metadata ------------------------------------------------------------------
def _unit(axis: str) -> str:
    from ..constants import ROTARY_AXES

    return "deg" if axis in ROTARY_AXES else "mm"


def _units(axes: str) -> str:
    return _dumps({"t": "s", "s": "mm", "feed": "mm/s", "line": "",
                   **{a: _unit(a) for a in axes}})


def _number(desc: str, nullable: bool = False) -> dict:
    # One type name only: Foxglove's JSON-schema reader rejects type lists such as
    # ["number", "null"]. A null value still parses (and plots as a gap).
    return {"type": "number", "description": desc + (" (null if not finite)" if nullable else "")}


def _setpoint_schema(axes: str) -> dict:
    props = {"t": _number("time since the start of the plan, s"),
             "s": _number("path length travelled since the start, mm"),
             "feed": _number("path speed, mm/s (backward difference of s)"),
             "line": {"type": "integer", "description": "source line executing (0 = none)"}}
    for a in axes:
        props[a] = _number(f"axis {a} setpoint, {_unit(a)}", nullable=True)
    return {"title": "cnc_interp.Setpoint", "type": "object", "properties": props,
            "required": list(props)}


def _segment_schema() -> dict:
    props = {"line": {"type": "integer", "description": "source line of the segment"},
             "s_start": _number("path length where the segment starts, mm"),
             "s_end": _number("path length where the segment ends, mm"),
             "t_start": _number("time the tool enters the segment, s"),
             "t_end": _number("time the tool leaves the segment, s"),
             "feed_min": _number("lowest planned feed on the segment, mm/s", nullable=True),
             "feed_max": _number("highest planned feed on the segment, mm/s", nullable=True),
             "samples": {"type": "integer", "description": "samples on the segment"}}
    return {"title": "cnc_interp.Segment", "type": "object", "properties": props,
            "required": list(props)}


def _limits_schema(axes: str) -> dict:
    def group(kind, lim):
        return {"type": "object", "description": f"signed {kind} / {lim} per axis",
                "properties": {a: _number(f"axis {a} {kind} / {lim}", nullable=True)
                               for a in axes},
                "required": list(axes)}

    props = {"v": group("velocity", "vmax"), "a": group("acceleration", "amax"),
             "j": group("jerk", "jmax"),
             "worst": _number("largest |ratio| of the sample (> 1 = limit exceeded)",
                              nullable=True)}
    return {"title": "cnc_interp.LimitRatios", "type": "object", "properties": props,
            "required": list(props)}


def _metadata_records(traj, metadata, machine, mcap_version) -> list[tuple[str, dict]]:
    from .. import __version__

    records: dict[str, dict] = {}
    if machine is not None:
        rec = {"name": machine.name, "axes": machine.axes, "kinematics": machine.kinematics,
               "dt_s": float(machine.dt_s), "source": machine.source,
               "kinematics_params": machine.kinematics_params,
               "start": np.asarray(machine.start, dtype=float).tolist()}
        for i, a in enumerate(machine.axes):
            for lim, arr in (("vmax", machine.vmax), ("amax", machine.amax),
                             ("jmax", machine.jmax)):
                rec[f"{a}.{lim}"] = float(arr[i])
        records["machine"] = rec
    records["planner"] = {"name": traj.planner, "status": traj.status,
                          "dt_s": float(traj.dt_s), "axes": traj.axes,
                          "samples": traj.n_samples, "duration_s": traj.duration_s,
                          "settings": _dumps(traj.settings)}
    records["tool"] = {"name": "cnc-interp", "version": __version__,
                       "mcap_library": f"mcap-python/{mcap_version}"}
    for name, rec in (metadata or {}).items():
        # The caller's keys add to (and override) the ones built here.
        records.setdefault(str(name), {}).update(rec)
    return [(name, {str(k): _meta_value(v) for k, v in sorted(rec.items())})
            for name, rec in sorted(records.items())]


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


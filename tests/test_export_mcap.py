"""MCAP export: read back with the mcap reader (CRCs validated) and compare with the CSV."""

from __future__ import annotations

import hashlib
import json
import os
import re
from typing import NamedTuple

import numpy as np
import pytest
from mcap.reader import make_reader
from numpy.testing import assert_allclose, assert_array_equal

import cnc_interp
from cnc_interp.export.csv_io import read_csv, write_csv
from cnc_interp.export.mcap_io import decode_message, input_metadata, message_fields, read_mcap, write_mcap
from cnc_interp.plan.trajectory import Trajectory
from cnc_interp.plan.verify import verify

from ._export_synth import arc_trajectory, machine_for

PROGRAM = b"G21 G90\nG1 X20 Y0 F600\nG2 X0 Y-20 I-20 J0\nM2\n"


class _Msg(NamedTuple):
    log_time: int
    publish_time: int
    data: bytes
    row: dict  # the message decoded by its schema


def _read_all(path):
    with open(path, "rb") as fh:
        reader = make_reader(fh, validate_crcs=True)
        summary = reader.get_summary()
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        msgs = {}
        for schema, channel, msg in reader.iter_messages(log_time_order=True):
            row = decode_message(schema, msg.data)
            msgs.setdefault(channel.topic, []).append(_Msg(msg.log_time, msg.publish_time, msg.data, row))
    return summary, meta, msgs


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    d = tmp_path_factory.mktemp("mcap")
    traj = arc_trajectory(duration_s=1.5, axes="XYZC")
    machine = machine_for(traj, 1.25, name="test mill")
    mcap_path = str(d / "plan.mcap")
    csv_path = str(d / "plan.csv")
    n = write_mcap(traj, mcap_path, {"input": input_metadata("part.ngc", PROGRAM)}, machine)
    write_csv(traj, csv_path)
    return traj, machine, mcap_path, csv_path, n


def test_channels_and_schemas(written):
    traj, machine, path, _, n = written
    summary, _, msgs = _read_all(path)
    topics = {c.topic: c for c in summary.channels.values()}
    assert set(topics) == {"/setpoints", "/segments", "/limits"}
    fields = {}
    for topic, ch in topics.items():
        assert ch.message_encoding == "ros1"
        schema = summary.schemas[ch.schema_id]
        assert schema.encoding == "ros1msg"
        fields[topic] = message_fields(schema.data.decode())
    assert [f for f, _ in fields["/setpoints"]] == ["t", "s", "feed", "line", "X", "Y", "Z", "C"]
    assert dict(fields["/setpoints"])["X"] == "<f8"  # the planned float64, exactly
    lim = [f for f, _ in fields["/limits"]]
    assert lim == [f"{k}.{a}" for k in "vaj" for a in "XYZC"] + ["worst"]
    assert topics["/setpoints"].metadata["axes"] == "XYZC"
    # Every message has its schema's size, and the statistics agree with the file.
    counts = summary.statistics.channel_message_counts
    for topic, ch in topics.items():
        assert counts[ch.id] == len(msgs[topic])
        size = np.dtype(fields[topic]).itemsize
        assert {len(m.data) for m in msgs[topic]} == {size}
    assert sum(counts.values()) == n == summary.statistics.message_count


_ROS1_PRIMITIVES = {"bool", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64"}
_ROS1_PRIMITIVES |= {"float32", "float64", "string", "time", "duration", "byte", "char"}


def _foxglove_fields(definition: str) -> list[str]:
    """Check a ros1msg definition the way Foxglove's parser (@foxglove/rosmsg, ros1
    grammar) does: definitions split at lines starting "==", nested ones named by "MSG:",
    each field "type name" with a name matching ^[a-zA-Z][a-zA-Z0-9_]*$ and a primitive
    or defined type. Returns the field paths."""
    blocks: list[list[str]] = [[]]
    for line in definition.split("\n"):
        line = line.strip()
        if line.startswith("=="):
            blocks.append([])
        elif line and not line.startswith("#"):
            blocks[-1].append(line)
    named = {b[0].split()[1]: b[1:] for b in blocks[1:]}
    assert all(b[0].startswith("MSG: ") for b in blocks[1:])

    def walk(lines, path):
        out = []
        for line in lines:
            kind, name = line.split("#")[0].split()
            assert re.fullmatch(r"[a-zA-Z][a-zA-Z0-9_]*", name), f"Foxglove rejects the field name {name!r}"
            if kind in _ROS1_PRIMITIVES:
                out.append(f"{path}.{name}")
            else:
                assert kind in named, f"no definition of {kind}"
                out += walk(named[kind], f"{path}.{name}")
        return out

    return walk(blocks[0], "")


def test_schemas_readable_by_foxglove(written):
    _, _, path, _, _ = written
    summary, _, _ = _read_all(path)
    paths = {}
    for ch in summary.channels.values():
        paths[ch.topic] = _foxglove_fields(summary.schemas[ch.schema_id].data.decode())
    assert ".X" in paths["/setpoints"] and ".feed" in paths["/setpoints"]
    assert ".j.C" in paths["/limits"] and ".worst" in paths["/limits"]
    assert ".feed_max" in paths["/segments"]


def test_setpoints_match_csv(written):
    traj, _, path, csv_path, _ = written
    _, _, msgs = _read_all(path)
    csv = read_csv(csv_path)
    sp = msgs["/setpoints"]
    assert len(sp) == traj.n_samples == csv.n_samples
    rows = [m.row for m in sp]
    for key, col in (("t", csv.t), ("s", csv.s), ("feed", csv.feed)):
        assert_array_equal(np.array([r[key] for r in rows]), col)  # repr round-trips exactly
    for i, a in enumerate(csv.axes):
        assert_array_equal(np.array([r[a] for r in rows]), csv.q[:, i])
    assert_array_equal(np.array([r["line"] for r in rows]), traj.line)
    times = np.array([m.log_time for m in sp])
    assert_array_equal(times, np.array([m.publish_time for m in sp]))
    assert_array_equal(times, np.rint(traj.t * 1e9).astype(np.int64))
    assert times[1] - times[0] == 1_000_000  # dt = 1 ms in ns


def _extremes(a: np.ndarray, n: int) -> np.ndarray:
    """The value of largest magnitude (signed) of each column of ``a`` (K, F) over each
    run of ``n`` rows (the last one shorter), computed one window at a time."""
    out = []
    for w in range(0, a.shape[0], n):
        part = a[w : w + n]
        out.append(part[np.argmax(np.abs(part), axis=0), np.arange(a.shape[1])])
    return np.array(out)


def test_limits_channel_agrees_with_verify(written):
    from cnc_interp.export.mcap_io import MCAP_LIMITS_EVERY as N

    traj, machine, path, _, _ = written
    _, _, msgs = _read_all(path)
    rows = [m.row for m in msgs["/limits"]]
    K = traj.n_samples
    assert len(rows) == -(-K // N)  # one message per N samples, the last window shorter
    # each at the time of its window's last sample
    ends = np.minimum(np.arange(len(rows)) * N + N - 1, K - 1)
    assert [m.log_time for m in msgs["/limits"]] == np.rint(traj.t[ends] * 1e9).astype(np.int64).tolist()
    report = verify(traj, machine)
    for k, kind in enumerate("vaj"):
        worst = np.array([[abs(r[kind][a]) for a in traj.axes] for r in rows]).max(axis=0)
        # The synthetic motion starts and ends smoothly, so the worst values are inside
        # the plan and the per-sample ratios reach verify's worst ratio (to the float32
        # the channel carries).
        assert_allclose(worst, report.ratios[:, k], rtol=1e-6)
    overall = max(r["worst"] for r in rows)
    assert_allclose(overall, report.worst_ratio, rtol=1e-6)
    assert overall == pytest.approx(0.8, rel=1e-6)  # machine_for(margin=1.25)
    # Signed: the velocity ratio of X is the v_X / vmax_X of largest magnitude in the window.
    vx = np.diff(traj.q[:, 0], prepend=traj.q[0, 0]) / traj.dt_s / machine.vmax[0]
    assert_allclose([r["v"]["X"] for r in rows], _extremes(vx[:, None], N)[:, 0], rtol=1e-6, atol=1e-12)
    assert (np.array([r["v"]["X"] for r in rows]) < 0).any()  # the sign is kept


def test_segments_channel(written):
    traj, _, path, _, _ = written
    _, _, msgs = _read_all(path)
    rows = [m.row for m in msgs["/segments"]]
    runs = np.flatnonzero(np.diff(traj.line)) + 1
    assert len(rows) == len(runs) + 1
    assert [r["line"] for r in rows] == [int(traj.line[0])] + traj.line[runs].tolist()
    assert rows[0]["s_start"] == 0.0 and rows[-1]["s_end"] == traj.s[-1]
    for r, nxt in zip(rows, rows[1:]):
        assert r["s_end"] == nxt["s_start"]  # contiguous
        assert r["t_end"] == nxt["t_start"]
    for r, m in zip(rows, msgs["/segments"]):
        sel = (traj.t >= r["t_start"]) & (traj.t <= r["t_end"])
        assert r["feed_min"] == traj.feed[sel].min() and r["feed_max"] == traj.feed[sel].max()
        assert r["samples"] == sel.sum()
        assert m.log_time == round(r["t_start"] * 1e9)


def test_metadata_records(written):
    traj, machine, path, _, _ = written
    _, meta, _ = _read_all(path)
    assert set(meta) == {"input", "machine", "planner", "tool"}
    assert meta["input"]["sha256"] == hashlib.sha256(PROGRAM).hexdigest()
    assert meta["input"]["lines"] == "4" and meta["input"]["name"] == "part.ngc"
    assert meta["machine"]["name"] == "test mill"
    assert float(meta["machine"]["C.jmax"]) == machine.jmax[3]
    assert float(meta["machine"]["X.vmax"]) == machine.vmax[0]
    assert meta["planner"]["name"] == "synthetic"
    assert json.loads(meta["planner"]["settings"]) == traj.settings
    assert meta["tool"]["version"] == cnc_interp.__version__


def test_read_mcap_round_trip(written):
    traj, _, path, _, _ = written
    back = read_mcap(path)
    assert isinstance(back, Trajectory)
    assert back.axes == traj.axes and back.planner == traj.planner
    assert back.dt_s == traj.dt_s and back.settings == traj.settings
    for name in ("t", "s", "feed", "q", "line"):
        assert_array_equal(getattr(back, name), getattr(traj, name))


def test_byte_identical_repeat(tmp_path):
    traj = arc_trajectory(duration_s=0.5)
    machine = machine_for(traj, 2.0)
    meta = {"input": input_metadata("a.ngc", PROGRAM)}
    a, b = str(tmp_path / "a.mcap"), str(tmp_path / "b.mcap")
    write_mcap(traj, a, meta, machine)
    write_mcap(arc_trajectory(duration_s=0.5), b, meta, machine)
    assert open(a, "rb").read() == open(b, "rb").read()


def test_many_chunks_valid(tmp_path, monkeypatch):
    """A plan spread over many chunks (small chunk size) reads back whole and in order."""
    import cnc_interp.export.mcap_io as mio

    monkeypatch.setattr(mio, "MCAP_CHUNK_BYTES", 4096)
    monkeypatch.setattr(mio, "_BATCH", 1000)
    traj = arc_trajectory(duration_s=3.0)
    path = str(tmp_path / "c.mcap")
    write_mcap(traj, path, None, machine_for(traj, 1.1))
    summary, _, msgs = _read_all(path)
    assert summary.statistics.chunk_count > 20
    assert len(msgs["/setpoints"]) == traj.n_samples
    assert_array_equal(read_mcap(path).q, traj.q)


def test_nan_written_as_nan(tmp_path):
    traj = arc_trajectory(duration_s=0.2)
    q = traj.q.copy()
    q[50, 1] = np.nan
    bad = Trajectory(
        axes=traj.axes,
        dt_s=traj.dt_s,
        t=traj.t,
        s=traj.s,
        feed=traj.feed,
        q=q,
        line=traj.line,
        planner="x",
        settings={"w": float("inf")},
    )
    path = str(tmp_path / "n.mcap")
    write_mcap(bad, path, {"input": {"note": float("nan")}}, machine_for(traj, 1.5))
    _, meta, msgs = _read_all(path)
    row = msgs["/setpoints"][50].row
    assert np.isnan(row["Y"]) and row["X"] == q[50, 0]
    lim = [m.row for m in msgs["/limits"]]  # samples 50..59 are the sixth window
    assert np.isnan(lim[5]["v"]["Y"]) and np.isnan(lim[5]["worst"])
    assert np.isfinite(lim[4]["v"]["Y"]) and np.isfinite(lim[5]["v"]["X"])
    assert json.loads(meta["planner"]["settings"]) == {"w": None}
    assert meta["input"]["note"] == "null"
    assert np.isnan(read_mcap(path).q[50, 1])


def test_without_machine_and_explicit_segments(tmp_path):
    traj = arc_trajectory(duration_s=0.4)
    path = str(tmp_path / "s.mcap")
    L = traj.s[-1]
    write_mcap(traj, path, {}, None, segments=[(7, 0.0, L / 2), (9, L / 2, L)])
    summary, meta, msgs = _read_all(path)
    assert {c.topic for c in summary.channels.values()} == {"/setpoints", "/segments"}
    assert "machine" not in meta
    segs = [m.row for m in msgs["/segments"]]
    assert [s["line"] for s in segs] == [7, 9]
    assert segs[0]["s_start"] == 0.0 and segs[1]["s_end"] == L
    assert segs[0]["t_end"] == segs[1]["t_start"] > 0


def test_write_to_stdout(capfdbinary):
    traj = arc_trajectory(duration_s=0.1)
    write_mcap(traj, "-", None, None)
    out = capfdbinary.readouterr().out
    assert out.startswith(b"\x89MCAP0\r\n") and out.endswith(b"\x89MCAP0\r\n")


def test_interrupted_write_leaves_no_file(tmp_path):
    traj = arc_trajectory(duration_s=0.3)
    path = tmp_path / "x.mcap"

    def tick(n):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_mcap(traj, str(path), None, None, progress=tick)
    assert os.listdir(tmp_path) == []


def test_bad_mcap_is_usage_error(tmp_path):
    from cnc_interp.errors import CncInterpError

    p = tmp_path / "junk.mcap"
    p.write_bytes(b"not an mcap file at all")
    with pytest.raises(CncInterpError) as ei:
        read_mcap(str(p))
    assert ei.value.exit_code == 2 and "junk.mcap" in ei.value.format()


@pytest.mark.parametrize("message_indexes", [True, False])
@pytest.mark.parametrize("chunk_size", [1, 300, 5000, 1 << 20])
def test_bulk_writer_matches_mcap_writer(chunk_size, message_indexes):
    """The bulk writer produces exactly the bytes of mcap's own Writer for the same calls."""
    import io

    from mcap.writer import CompressionType, IndexType, Writer

    from cnc_interp.export.mcap_bulk import BulkMcapWriter

    rng = np.random.default_rng(chunk_size)
    n = 700
    chans = rng.integers(1, 4, size=n)
    chans[:5] = [3, 3, 1, 2, 1]  # first appearance order differs from registration order
    times = np.sort(rng.integers(0, 10**9, size=n))
    times[100:110] = times[100]  # equal times
    datas = [bytes(rng.integers(32, 127, size=int(rng.integers(0, 90))).astype(np.uint8)) for _ in range(n)]

    def calls(w):
        w.start(profile="", library="test")
        s1 = w.register_schema("a", "jsonschema", b'{"type":"object"}')
        s2 = w.register_schema("b", "jsonschema", b"{}")
        w.register_channel("/one", "json", s1, {"k": "v"})
        w.register_channel("/two", "json", s2, {})
        w.register_channel("/three", "json", s1, {"x": "1", "y": "2"})
        w.add_metadata("m1", {"a": "1"})
        w.add_metadata("m2", {"b": "2", "c": "3"})

    ref = io.BytesIO()
    kinds = IndexType.ALL if message_indexes else IndexType.ALL & ~IndexType.MESSAGE
    w = Writer(ref, chunk_size=chunk_size, compression=CompressionType.ZSTD, index_types=kinds)
    calls(w)
    for c, t, d in zip(chans.tolist(), times.tolist(), datas):
        w.add_message(c, t, d, t)
    w.finish()

    out = io.BytesIO()
    b = BulkMcapWriter(out, chunk_size=chunk_size, message_indexes=message_indexes)
    calls(b)
    for lo, hi in ((0, 1), (1, 250), (250, 251), (251, 700)):  # uneven batches
        b.add_messages(chans[lo:hi], times[lo:hi], datas[lo:hi])
    b.finish()
    assert out.getvalue() == ref.getvalue()


def test_bulk_writer_no_messages_matches_mcap_writer():
    import io

    from mcap.writer import CompressionType, Writer

    from cnc_interp.export.mcap_bulk import BulkMcapWriter

    outs = []
    for cls in (Writer, BulkMcapWriter):
        buf = io.BytesIO()
        w = (
            cls(buf, chunk_size=1024)
            if cls is BulkMcapWriter
            else cls(buf, chunk_size=1024, compression=CompressionType.ZSTD)
        )
        w.start(profile="", library="x")
        w.register_channel("/c", "json", w.register_schema("s", "jsonschema", b"{}"), {})
        w.add_metadata("m", {})
        w.finish()
        outs.append(buf.getvalue())
    assert outs[0] == outs[1]


def _copy_with_mcap_writer(src, dst, **writer_options):
    """Rewrite ``src`` with mcap's own Writer (e.g. without indexes)."""
    from mcap.writer import CompressionType, Writer

    with open(src, "rb") as fh, open(dst, "wb") as out:
        reader = make_reader(fh, validate_crcs=True)
        summary = reader.get_summary()
        w = Writer(out, compression=CompressionType.ZSTD, **writer_options)
        w.start(profile="", library="copy")
        for sc in summary.schemas.values():
            w.register_schema(sc.name, sc.encoding, sc.data)
        for ch in summary.channels.values():
            w.register_channel(ch.topic, ch.message_encoding, ch.schema_id, ch.metadata)
        for m in reader.iter_metadata():
            w.add_metadata(m.name, m.metadata)
        for _, ch, msg in reader.iter_messages(log_time_order=False):
            w.add_message(ch.id, msg.log_time, msg.data, msg.publish_time)
        w.finish()


def test_fast_reader_matches_mcap_reader(tmp_path, monkeypatch):
    import cnc_interp.export.mcap_io as mio
    from cnc_interp.export.mcap_bulk import read_channel

    monkeypatch.setattr(mio, "MCAP_CHUNK_BYTES", 10_000)
    traj = arc_trajectory(duration_s=1.0)
    path = str(tmp_path / "f.mcap")
    write_mcap(traj, path, None, machine_for(traj, 1.1))
    with open(path, "rb") as fh:
        reader = make_reader(fh, validate_crcs=True)
        summary = reader.get_summary()
        assert len(summary.chunk_indexes) > 5
        cid = next(c.id for c in summary.channels.values() if c.topic == "/setpoints")
        times, datas = read_channel(fh, summary, cid)
        ref = [(m.log_time, m.data) for _, _, m in reader.iter_messages(topics=["/setpoints"])]
    assert datas == [d for _, d in ref]
    assert times.tolist() == [t for t, _ in ref]


def test_unindexed_file_read_with_generic_reader(tmp_path):
    from mcap.writer import IndexType

    traj = arc_trajectory(duration_s=0.3)
    src, dst = str(tmp_path / "a.mcap"), str(tmp_path / "b.mcap")
    write_mcap(traj, src, None, machine_for(traj, 1.1))
    _copy_with_mcap_writer(src, dst, index_types=IndexType.NONE, chunk_size=5000)
    back = read_mcap(dst)
    assert_array_equal(back.q, traj.q)
    assert_array_equal(back.line, traj.line)


def test_file_without_message_indexes_read_by_walking_its_chunks(tmp_path):
    """Chunk indexes but no message indexes: the fast reader walks each chunk's records
    and finds what mcap's own reader finds."""
    from mcap.writer import IndexType

    from cnc_interp.export.mcap_bulk import read_channel

    traj = arc_trajectory(duration_s=0.6)
    src, dst = str(tmp_path / "a.mcap"), str(tmp_path / "b.mcap")
    write_mcap(traj, src, None, machine_for(traj, 1.1))
    _copy_with_mcap_writer(src, dst, index_types=IndexType.ALL & ~IndexType.MESSAGE, chunk_size=3000)
    with open(dst, "rb") as fh:
        reader = make_reader(fh, validate_crcs=True)
        summary = reader.get_summary()
        assert len(summary.chunk_indexes) > 5 and all(c.message_index_length == 0 for c in summary.chunk_indexes)
        for ch in summary.channels.values():
            times, datas = read_channel(fh, summary, ch.id)
            ref = [(m.log_time, m.data) for _, _, m in reader.iter_messages(topics=[ch.topic], log_time_order=False)]
            assert datas == [d for _, d in ref] and times.tolist() == [t for t, _ in ref]
    back = read_mcap(dst)
    assert_array_equal(back.q, traj.q)
    assert_array_equal(back.line, traj.line)


def test_corrupted_chunk_is_detected(tmp_path):
    from cnc_interp.errors import CncInterpError

    traj = arc_trajectory(duration_s=0.3)
    path = tmp_path / "c.mcap"
    write_mcap(traj, str(path), None, None)
    data = bytearray(path.read_bytes())
    with open(path, "rb") as fh:
        ci = make_reader(fh).get_summary().chunk_indexes[0]
    # flip a byte in the middle of the compressed chunk body
    data[ci.chunk_start_offset + ci.chunk_length // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(CncInterpError) as ei:
        read_mcap(str(path))
    assert ei.value.exit_code == 2


def test_plan_command_mcap_matches_its_csv(tmp_path):
    """End to end: `plan -o x.mcap` and `plan -o x.csv` of one program agree sample for
    sample, and the MCAP passes verify against the machine it records."""
    from click.testing import CliRunner

    from cnc_interp import cli

    part = tmp_path / "part.ngc"
    part.write_text("G21 G90 G17\nG0 X0 Y0 Z1\nG1 Z0 F300\nG1 X10 F1200\nG2 X20 Y0 I5 J0\nG1 Y-5\nG0 Z5\nM2\n")
    runner = CliRunner()
    for ext in ("csv", "mcap"):
        res = runner.invoke(cli.main, ["plan", str(part), "-q", "-o", str(tmp_path / f"p.{ext}")])
        assert res.exit_code == 0, res.output
    csv = read_csv(str(tmp_path / "p.csv"))
    summary, meta, msgs = _read_all(str(tmp_path / "p.mcap"))
    assert {c.topic for c in summary.channels.values()} == {"/setpoints", "/segments", "/limits"}
    rows = [m.row for m in msgs["/setpoints"]]
    assert len(rows) == csv.n_samples > 100
    assert len(msgs["/limits"]) == -(-csv.n_samples // 10)
    for key, col in (("t", csv.t), ("s", csv.s), ("feed", csv.feed)):
        assert_array_equal([r[key] for r in rows], col)
    for i, a in enumerate(csv.axes):
        assert_array_equal([r[a] for r in rows], csv.q[:, i])
    assert {r["line"] for r in rows} >= {4, 5, 6}  # the G1, G2 and G1 lines
    assert meta["machine"]["axes"] == csv.axes and meta["tool"]["version"] == cnc_interp.__version__
    res = runner.invoke(cli.main, ["verify", str(tmp_path / "p.mcap"), "-m", "generic-mill"])
    assert res.exit_code == 0, res.output


@pytest.mark.parametrize("batch", [2, 7, 500])
def test_limits_batches_join_exactly(tmp_path, monkeypatch, batch):
    """The ratios computed a batch at a time equal the ones of the whole plan at once."""
    import cnc_interp.export.mcap_io as mio
    from cnc_interp.export.ratios import limit_ratios

    monkeypatch.setattr(mio, "_BATCH", batch)
    traj = arc_trajectory(duration_s=0.05 if batch < 100 else 1.2)
    machine = machine_for(traj, 1.3)
    path = str(tmp_path / "b.mcap")
    write_mcap(traj, path, None, machine)
    _, _, msgs = _read_all(path)
    got = np.array([[m.row[k][a] for k in "vaj" for a in traj.axes] for m in msgs["/limits"]])
    want = limit_ratios(traj.q, traj.dt_s, machine.limits())  # (3, K, n)
    want = _extremes(np.concatenate(list(want), axis=1), mio.MCAP_LIMITS_EVERY)
    assert_allclose(got, want, rtol=1e-6, atol=1e-12)  # float32 ratios


def test_file_does_not_depend_on_the_blocks(tmp_path, monkeypatch):
    """Blocks of any size (splitting windows of /limits and segments anywhere) give the
    same bytes, with and without given segments."""
    import cnc_interp.export.mcap_io as mio

    traj = arc_trajectory(duration_s=0.4)
    machine = machine_for(traj, 1.3)
    L = traj.s[-1]
    outs = {}
    for batch in (3, 7, 10, 64, 65536):
        monkeypatch.setattr(mio, "_BATCH", batch)
        for segs in (None, [(7, 0.0, L / 3), (9, L / 3, L)]):
            path = tmp_path / f"{batch}-{segs is None}.mcap"
            write_mcap(traj, str(path), None, machine, segments=segs)
            outs.setdefault(segs is None, set()).add(path.read_bytes())
    assert len(outs[True]) == 1 and len(outs[False]) == 1


@pytest.mark.parametrize("case", ["short message", "field missing", "string field"])
def test_bad_ros1_setpoints_are_one_usage_error(tmp_path, case):
    """A /setpoints message of the wrong size, or a schema without an axis or with a
    field that is no number, is bad input (exit 2), never a traceback."""
    from mcap.writer import Writer

    from cnc_interp.errors import CncInterpError
    from cnc_interp.export.mcap_io import _setpoint_msg

    text = _setpoint_msg("XYZ")
    size = 3 * 8 + 4 + 3 * 8  # t, s, feed, line, X, Y, Z
    if case == "field missing":
        text = text.replace("float64 Z", "float64 W")
    if case == "string field":
        text = text.replace("float64 Z", "string Z")
    path = tmp_path / "bad.mcap"
    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema("cnc_interp/Setpoint", "ros1msg", text.encode())
        cid = w.register_channel("/setpoints", "ros1", sid, {"axes": "XYZ"})
        for k in range(5):
            payload = np.array([k * 1e-3, 0, 0], "<f8").tobytes() + b"\0\0\0\0" + np.zeros(3, "<f8").tobytes()
            assert len(payload) == size
            w.add_message(cid, k * 1_000_000, payload[:-4] if case == "short message" else payload, k * 1_000_000)
        w.finish()
    with pytest.raises(CncInterpError) as ei:
        read_mcap(str(path))
    assert ei.value.exit_code == 2 and "\n" not in ei.value.format()
    assert ei.value.format().startswith(f"{path}: error: ")

"""Hostile input: every reproducer of the adversarial passes stays fixed.

Each test names the item it guards. The rule under test is always the same: a clean
one-line error with the documented exit code (2 bad input, 1 the plan or the output
failed), or the right result — never a traceback, a hang, or a destroyed file.
"""

from __future__ import annotations

import errno
import os
import re
import signal
import stat
import struct
import subprocess
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests._contract_helpers import SAMPLES, console_script, one_error_line, run_inproc, run_proc

PART = os.path.join(SAMPLES, "mill-contour.ngc")
LATHE = os.path.join(SAMPLES, "lathe-profile.ngc")
SHORT = "G21 G90 F600\nG1 X10 Y5\nG1 X20\nM2\n"


@pytest.fixture
def part(tmp_path):
    p = tmp_path / "p.ngc"
    p.write_text(SHORT)
    return p


# -- 1, 2: outputs never destroy ------------------------------------------------------------
def test_output_onto_a_fifo_is_written_through_not_replaced(tmp_path, part):
    fifo = tmp_path / "out.fifo"
    os.mkfifo(fifo)
    # the reader's output goes to a file: a pipe nobody reads until the plan ends would
    # stall the stream after ~200 KB (the plan is written as it is planned)
    with open(tmp_path / "got", "wb") as got:
        reader = subprocess.Popen(["cat", str(fifo)], stdout=got)
        res = run_proc("plan", part, "-o", fifo, "-q")
        reader.wait(timeout=60)
    out = (tmp_path / "got").read_bytes()
    assert res.code == 0, res.explain()
    assert out.startswith(b"t,s,feed,X,Y,Z\n") and out.count(b"\n") > 100
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)  # still the FIFO, not a regular file


def test_output_onto_dev_null_keeps_the_device(part):
    res = run_inproc("plan", part, "-o", os.devnull, "-q")
    assert res.code == 0, res.explain()
    assert stat.S_ISCHR(os.stat(os.devnull).st_mode)


@pytest.mark.parametrize("cmd", [["plan", "-q"], ["fit"]])
def test_output_equal_to_the_input_is_refused(part, cmd):
    before = part.read_bytes()
    res = run_inproc(cmd[0], part, "-o", part, *cmd[1:])
    assert "is the input" in one_error_line(res)
    assert part.read_bytes() == before


def test_output_through_a_symlink_to_the_input_is_refused(tmp_path, part):
    link = tmp_path / "link.csv"
    link.symlink_to(part)
    res = run_inproc("plan", part, "-o", link, "-q")
    assert "is the input" in one_error_line(res)
    assert part.read_text() == SHORT


def test_output_that_is_a_directory_is_refused(tmp_path, part):
    for cmd in (["fit", part, "-o", tmp_path], ["plan", part, "-q", "-o", tmp_path]):
        assert "Is a directory" in one_error_line(run_inproc(*cmd))


def test_replaced_output_keeps_its_mode_and_a_new_one_gets_the_umask(tmp_path, part):
    old = tmp_path / "old.csv"
    old.write_text("old")
    os.chmod(old, 0o640)
    assert run_inproc("plan", part, "-o", old, "-q").code == 0
    assert stat.S_IMODE(os.stat(old).st_mode) == 0o640
    seg = tmp_path / "seg.json"
    assert run_inproc("fit", part, "-o", seg).code == 0
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(os.stat(seg).st_mode) == 0o666 & ~mask  # not mkstemp's 0600


def test_output_symlink_keeps_pointing_at_its_target(tmp_path, part):
    target = tmp_path / "target.csv"
    target.write_text("old")
    link = tmp_path / "link.csv"
    link.symlink_to(target)
    assert run_inproc("plan", part, "-o", link, "-q").code == 0
    assert link.is_symlink() and target.read_text().startswith("t,s,feed")


def test_disk_full_is_exit_1_and_keeps_the_old_file(tmp_path, part, monkeypatch):
    import cnc_interp.outfile as outfile

    old = tmp_path / "old.csv"
    old.write_text("previous plan")

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(outfile.os, "fsync", full)
    res = run_inproc("plan", part, "-o", old, "-q")
    assert "No space left on device" in one_error_line(res, code=1)
    assert old.read_text() == "previous plan"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.csv", "p.ngc"]


def test_disk_full_on_a_device_is_exit_1():
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full")
    res = run_inproc("plan", PART, "-o", "/dev/full", "-q")
    assert "No space left" in one_error_line(res, code=1)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_termination_leaves_no_temporary_file(tmp_path, sig):
    # a long enough plan that the signal lands mid-run
    prog = tmp_path / "long.ngc"
    prog.write_text("G21 G90 F600\n" + "".join(f"G1 X{(i % 2) * 50} Y{i * 0.1:.1f}\n" for i in range(400)) + "M2\n")
    proc = subprocess.Popen(
        [console_script(), "plan", str(prog), "-o", "out.csv", "-q"], cwd=tmp_path, stderr=subprocess.PIPE
    )
    time.sleep(2.0)
    proc.send_signal(sig)
    proc.wait(timeout=120)
    assert sorted(p.name for p in tmp_path.iterdir()) in (["long.ngc"], ["long.ngc", "out.csv"])


def test_reader_closing_early_exits_0():
    proc = subprocess.Popen(
        f"'{console_script()}' plan '{PART}' | head -1",
        shell=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        executable="/bin/bash",
    )
    out, err = proc.communicate(timeout=300)
    assert out == b"t,s,feed,X,Y,Z\n"
    status = subprocess.run(
        ["bash", "-c", f"'{console_script()}' plan '{PART}' | head -1 >/dev/null; echo ${{PIPESTATUS[0]}}"],
        capture_output=True,
        timeout=300,
    )
    assert status.stdout.strip() == b"0", (status.stdout, status.stderr)
    assert b"rror" not in err


# -- 3: sub-nanometre steps accumulate --------------------------------------------------------
def test_chain_of_sub_nanometre_steps_keeps_its_sum(tmp_path):
    n = 20000
    prog = tmp_path / "tiny.ngc"
    prog.write_text("G21 G90 F600\nG1 X1 Y0\nG91\n" + "G1 Y0.0000000009\n" * n + "M2\n")
    res = run_inproc("plan", prog, "-q")
    assert res.code == 0, res.explain()
    last = res.out.decode().strip().splitlines()[-1].split(",")
    assert float(last[4]) == pytest.approx(n * 0.9e-9, rel=1e-6)


def test_distinct_nodes_compares_with_the_last_kept_node():
    from cnc_interp.fit.corners import _distinct_nodes

    pts = np.zeros((7, 2))
    pts[:, 1] = np.arange(7) * 0.6  # each step 0.6, the threshold 1
    keep = _distinct_nodes(pts, 1.0)
    assert keep.tolist() == [True, False, True, False, True, False, True]
    assert _distinct_nodes(np.array([[0.0], [2.0], [4.0]]), 1.0).all()


# -- 5: G20/G21 keep the physical feed ----------------------------------------------------------
def test_units_switch_keeps_the_feed_in_effect():
    from cnc_interp.gcode import read_program

    prog = read_program(b"G21 G90 F600\nG1 X10\nG20\nG1 X1\nM2\n", "u.ngc")
    run = prog.items[0]
    np.testing.assert_allclose(run.feed_mm_s[1:], [10.0, 10.0])  # 600 mm/min both moves
    prog = read_program(b"G20 G90 F10\nG1 X1\nG21\nG1 X50\nM2\n", "u.ngc")
    np.testing.assert_allclose(prog.items[0].feed_mm_s[1:], [254.0 / 60] * 2)


# -- numbers at the boundary ---------------------------------------------------------------------
@pytest.mark.parametrize(
    "text",
    [
        "G1 X[1*10**308]",
        "G1 X[10**300]",
        "G1 X1e9 Y1e9 X2e9",
        "G4 P[10**300]",
        "G1 X[-10**12]",
        "G0 Z[10**10]",
    ],
)
def test_huge_numbers_in_gcode_are_located_errors(tmp_path, text):
    prog = tmp_path / "big.ngc"
    prog.write_text(f"G21 G90 F600\n{text}\nM2\n")
    line = one_error_line(run_inproc("plan", prog, "-q", "-o", tmp_path / "o.csv"))
    assert line.startswith(f"{prog}:2:")
    assert not (tmp_path / "o.csv").exists()


@pytest.mark.parametrize(
    "opt",
    [
        ["--dt", "1e300"],
        ["--dt", "100"],
        ["--dt", "nan"],
        ["--dt", "1e-9"],
        ["--tol", "nan"],
        ["--tol", "1e154"],
        ["--tol", "inf"],
        ["--start", "X=1e300"],
        ["--start", "X=nan"],
    ],
)
def test_out_of_range_options_are_usage_errors(opt):
    res = run_inproc("plan", PART, "-q", "-o", os.devnull, *opt)
    assert res.code == 2 and "Traceback" not in res.err, res.explain()
    assert len(res.err.strip().splitlines()) == 1


MACHINE = (
    "{top}[axes.X]\nvmax = {v}\namax = 1000\njmax = 1e5\n[axes.Y]\nvmax = 100\namax = 1000\n"
    "jmax = 1e5\n[axes.Z]\nvmax = 100\namax = 1000\njmax = 1e5\n"
)


@pytest.mark.parametrize(
    "top,v,where",
    [
        ("", "1e300", ":2:"),
        ("", "nan", ":2:"),
        ("", "123456789012345678901234567890", ":2:"),
        ("tol = 1e300\n", "100", ":1:"),
        ("dt = 100\n", "100", ":1:"),
        ("dt = 1e-12\n", "100", ":1:"),
    ],
)
def test_insane_machine_values_are_located_errors(tmp_path, top, v, where):
    m = tmp_path / "m.toml"
    m.write_text(MACHINE.format(top=top, v=v))
    line = one_error_line(run_inproc("plan", PART, "-m", m, "-q", "-o", os.devnull))
    assert line.startswith(f"{m}{where}")


def test_deeply_nested_toml_is_an_error(tmp_path):
    m = tmp_path / "deep.toml"
    m.write_text("a = " + "[" * 10000 + "]" * 10000 + "\n")
    assert "nested too deeply" in one_error_line(run_inproc("plan", PART, "-m", m, "-q"))


def test_machine_files_must_be_regular_and_small(tmp_path):
    fifo = tmp_path / "m.fifo"
    os.mkfifo(fifo)
    for spec in ("/dev/zero", fifo):
        assert "not a regular file" in one_error_line(run_inproc("plan", PART, "-m", spec, "-q"))
    big = tmp_path / "big.toml"
    big.write_text("# x\n" * 300000)
    assert "larger than" in one_error_line(run_inproc("plan", PART, "-m", big, "-q"))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.floats(allow_nan=True, allow_infinity=True))
def test_any_float_in_a_coordinate_plans_or_fails_cleanly(value):
    from cnc_interp.errors import CncInterpError
    from cnc_interp.gcode import read_program

    text = f"G21 G90 F600\nG1 X[{value!r}]\nM2\n".replace("nan", "[0/0]").replace("inf", "[10**400]")
    try:
        prog = read_program(text.encode(), "h.ngc")
    except CncInterpError as exc:
        assert exc.location.line == 2
        return
    for it in prog.items:
        if hasattr(it, "nodes"):
            assert np.isfinite(it.nodes).all() and (np.abs(it.nodes) <= 1e9).all()


# -- lexical -----------------------------------------------------------------------------------
def test_cr_only_line_ends_and_a_bom_read_as_lines():
    from cnc_interp.gcode import read_program

    ref = read_program(b"G21 G90 F600\nG1 X10\nG1 Y10\nM2\n", "a.ngc")
    for data in (
        b"G21 G90 F600\rG1 X10\rG1 Y10\rM2\r",
        b"\xef\xbb\xbfG21 G90 F600\nG1 X10\nG1 Y10\nM2\n",
        b"G21 G90 F600\r\nG1 X10\r\nG1 Y10\r\nM2\r\n",
    ):
        prog = read_program(data, "b.ngc")
        np.testing.assert_array_equal(prog.items[0].nodes, ref.items[0].nodes)
        assert prog.line_count == 4


def test_control_bytes_are_escaped_in_messages(tmp_path):
    prog = tmp_path / "e\x1bx.ngc"
    prog.write_bytes(b"G21 G90 F600\nG1 X10 #<\x1b[2Jfoo>\x07\nM2\n")
    line = one_error_line(run_inproc("parse", prog))
    assert "\x1b" not in line and "\x07" not in line and "\\x1b" in line


# -- bounded work ------------------------------------------------------------------------------
def test_nested_loops_share_one_iteration_budget(monkeypatch):
    from cnc_interp.errors import GCodeError
    from cnc_interp.gcode import oword, read_program

    monkeypatch.setattr(oword, "LOOP_TOTAL_ITERATION_LIMIT", 5000)
    text = b"G21 G90 F600\no1 repeat [100]\no2 repeat [100]\n#1=[#1+1]\no2 endrepeat\no1 endrepeat\nM2\n"
    with pytest.raises(GCodeError, match="in all"):
        read_program(text, "n.ngc")
    read_program(text.replace(b"[100]", b"[50]"), "n.ngc")  # 2,550 iterations pass


def test_dwells_count_in_the_memory_check(tmp_path):
    """An in-memory plan (``plan_part``: batch, the FPGA stage) counts dwells in its memory
    check. (``cnc-interp plan`` streams held samples in blocks: a dwell takes no memory.)"""
    from cnc_interp.errors import PlanError
    from cnc_interp.pipeline import plan_part

    prog = tmp_path / "dwell.ngc"
    prog.write_text("G21 G90 F600\nG4 P1000000\nM2\n")  # 11.6 days of held samples
    t0 = time.monotonic()
    with pytest.raises(PlanError, match="GB of memory"):
        plan_part(str(prog), "generic-mill")
    assert time.monotonic() - t0 < 60


def test_held_time_enters_the_budget():
    from cnc_interp.errors import PlanError
    from cnc_interp.plan.budget import check_sample_budget
    from cnc_interp.machine.load import load_machine

    m = load_machine("generic-mill")
    check_sample_budget([], m, 1e-3, "x", available=10**9, held_s=10.0)
    with pytest.raises(PlanError):
        check_sample_budget([], m, 1e-3, "x", available=10**9, held_s=1e5)


# -- emulate -----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def lathe_frames(tmp_path_factory):
    d = tmp_path_factory.mktemp("frames")
    out = d / "f.bin"
    res = run_inproc("stream", LATHE, "-m", "xz-lathe", "--dry-run", out, "-q")
    assert res.code == 0, res.explain()
    from cnc_interp.fpga.frames import read_frame_file

    return read_frame_file(str(out))


def _write_frames(path, frames):
    path.write_bytes(b"".join(f.encode() for f in frames))


def _with_config(frames, **change):
    from dataclasses import replace

    from cnc_interp.fpga.frames import CONFIG

    cfg = frames[0]
    fields = list(CONFIG.unpack_from(cfg.payload))
    if "axes" in change:
        fields[1] = change["axes"]
    if "dt" in change:
        fields[2] = change["dt"]
    if "n_samples" in change:
        fields[4] = change["n_samples"]
    payload = CONFIG.pack(*fields) + cfg.payload[CONFIG.size :]
    return [replace(cfg, payload=payload)] + list(frames[1:])


@pytest.mark.parametrize(
    "change",
    [
        {"dt": float("nan")},
        {"dt": 0.0},
        {"dt": -0.001},
        {"dt": float("inf")},
        {"axes": b"QQ"},
        {"axes": b"XX"},
        {"n_samples": 0xFFFFFFFF},
    ],
)
def test_emulate_refuses_insane_config_with_valid_crc(tmp_path, lathe_frames, change):
    f = tmp_path / "bad.bin"
    _write_frames(f, _with_config(lathe_frames, **change))
    out = tmp_path / "o.csv"
    one_error_line(run_inproc("emulate", f, "-o", out))
    assert not out.exists()


def test_emulate_refuses_a_poll_frame_and_pieces_past_the_program(tmp_path, lathe_frames):
    from dataclasses import replace

    from cnc_interp.fpga.frames import PIECE, PROFILE_HEAD, FrameType, decode_frame, poll_frame

    f = tmp_path / "poll.bin"
    _write_frames(f, list(lathe_frames[:1]) + [decode_frame(poll_frame(7))] + list(lathe_frames[1:]))
    assert "POLL" in one_error_line(run_inproc("emulate", f, "-o", tmp_path / "o.csv"))
    i = next((k for k, fr in enumerate(lathe_frames) if fr.type == FrameType.PROFILE), None)
    if i is None:
        pytest.skip("the lathe stream has no profile frame")
    fr = lathe_frames[i]
    payload = bytearray(fr.payload)
    struct.pack_into("<I", payload, PROFILE_HEAD.size, 0xFFFFFFFF)  # first piece's n_samples
    assert len(payload) >= PROFILE_HEAD.size + PIECE.size
    frames = list(lathe_frames)
    frames[i] = replace(fr, payload=bytes(payload))
    f2 = tmp_path / "long.bin"
    _write_frames(f2, frames)
    t0 = time.monotonic()
    one_error_line(run_inproc("emulate", f2, "-o", tmp_path / "o2.csv"))
    assert time.monotonic() - t0 < 60


# -- batch -------------------------------------------------------------------------------------
def test_batch_skips_fifos_and_device_links_and_refuses_them_as_arguments(tmp_path):
    d = tmp_path / "progs"
    d.mkdir()
    (d / "ok.ngc").write_text(SHORT)
    os.mkfifo(d / "fifo.ngc")
    (d / "zero.ngc").symlink_to("/dev/zero")
    from cnc_interp.batch import collect_programs

    assert [k for k, _ in collect_programs([str(d)])] == ["progs/ok.ngc"]
    res = run_inproc("batch", d / "fifo.ngc", "-m", "generic-mill", "-q")
    assert "not a regular file" in one_error_line(res)


def test_batch_baseline_with_a_list_key_is_an_error(tmp_path):
    b = tmp_path / "b.json"
    b.write_text('{"programs": [{"key": ["a"], "status": "ok"}]}')
    prog = tmp_path / "p.ngc"
    prog.write_text(SHORT)
    res = run_inproc("batch", prog, "-m", "generic-mill", "--baseline", b, "-q")
    assert "baseline" in one_error_line(res)


def test_a_crashed_program_fails_the_batch_without_a_baseline():
    from cnc_interp.batch import compare

    recs = [
        {"key": "a", "status": "ok", "worst_ratio": 0.9, "cycle_time_s": 1.0, "message": ""},
        {"key": "b", "status": "crash", "worst_ratio": None, "cycle_time_s": None, "message": "signal 11"},
    ]
    assert compare(recs, None, 0.01)["failures"] == 1
    assert compare(recs[:1], None, 0.01)["failures"] == 0
    base = {"a": recs[0], "b": dict(recs[1], status="ok")}
    assert compare(recs, base, 0.01)["regressions"] == 1  # status changed
    assert compare(recs, {"a": recs[0], "b": recs[1]}, 0.01)["failures"] == 0  # known crash
    err = [dict(recs[1], status="error", message="bad G-code")]
    assert compare(err, None, 0.01)["errors"] == 1  # an input error without a baseline
    assert compare(err, {"b": err[0]}, 0.01)["errors"] == 0


def test_batch_has_a_default_timeout():
    from cnc_interp.batch import DEFAULT_TIMEOUT_S, BatchOptions

    assert BatchOptions(paths=("x",), machine_spec="generic-mill").timeout_s == DEFAULT_TIMEOUT_S


def test_sigterm_to_a_batch_kills_its_workers(tmp_path):
    prog = tmp_path / "slow.ngc"
    # a program that keeps a worker busy for a long time
    prog.write_text("G21 G90 F600\n" + "".join(f"G1 X{(i % 2) * 50} Y{i * 0.1:.1f}\n" for i in range(3000)) + "M2\n")
    proc = subprocess.Popen(
        [console_script(), "batch", str(prog), "-m", "generic-mill", "-q", "-j", "1"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    time.sleep(3.0)
    children = subprocess.run(["pgrep", "-P", str(proc.pid)], capture_output=True, text=True)
    kids = [int(x) for x in children.stdout.split()]
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=60)
    time.sleep(0.5)
    for pid in kids:
        assert not os.path.exists(f"/proc/{pid}") or open(f"/proc/{pid}/stat").read().split()[2] == "Z", (
            f"worker {pid} survived"
        )


# -- verify as a proof -------------------------------------------------------------------------
@pytest.fixture(scope="module")
def plan_csv(tmp_path_factory):
    d = tmp_path_factory.mktemp("verify")
    out = d / "p.csv"
    assert run_inproc("plan", PART, "-q", "-o", out).code == 0
    return out


def _edit_csv(src, dst, fn):
    lines = src.read_text().splitlines()
    dst.write_text("\n".join(fn(lines)) + "\n")
    return dst


def test_verify_needs_every_machine_axis(tmp_path, plan_csv):
    no_z = _edit_csv(plan_csv, tmp_path / "noz.csv", lambda ls: [",".join(ln.split(",")[:5]) for ln in ls])
    only = _edit_csv(plan_csv, tmp_path / "only.csv", lambda ls: [",".join(ln.split(",")[:3]) for ln in ls])
    for f in (no_z, only):
        assert "no column for machine axis" in one_error_line(run_inproc("verify", f, "-m", "generic-mill"))


@pytest.mark.parametrize("col", [0, 1, 2])
def test_verify_refuses_non_finite_time_path_and_feed(tmp_path, plan_csv, col):
    def poison(ls):
        f = ls[10].split(",")
        f[col] = "nan"
        ls[10] = ",".join(f)
        return ls

    bad = _edit_csv(plan_csv, tmp_path / "nan.csv", poison)
    res = run_inproc("verify", bad, "-m", "generic-mill")
    assert res.code != 0 and "Traceback" not in res.err


def test_verify_fails_on_a_violation_just_past_the_documented_slack(tmp_path, plan_csv):
    from cnc_interp.constants import VERIFY_RATIO_SLACK

    def scale(k):
        def fn(ls):
            out = [ls[0]]
            for ln in ls[1:]:
                f = ln.split(",")
                out.append(",".join(f[:3] + [repr(float(x) * k) for x in f[3:]]))
            return out

        return fn

    # positions scale every derivative by k: scale the plan's own worst ratio to just inside and
    # just past 1 + slack (a plan need not touch its limits exactly)
    ok = run_inproc("verify", plan_csv, "-m", "generic-mill").out.decode()
    worst = float(re.search(r"ok: worst ([0-9.]+)", ok).group(1))
    within = _edit_csv(plan_csv, tmp_path / "in.csv", scale((1.0 + 0.1 * VERIFY_RATIO_SLACK) / worst))
    assert run_inproc("verify", within, "-m", "generic-mill").code == 0
    past = _edit_csv(plan_csv, tmp_path / "past.csv", scale((1.0 + 10 * VERIFY_RATIO_SLACK) / worst))
    res = run_inproc("verify", past, "-m", "generic-mill")
    assert res.code == 1 and "FAIL" in res.out.decode()
    assert "1 + 1e-09" in run_inproc("verify", plan_csv, "-m", "generic-mill").out.decode()


def test_verify_mcap_dt_comes_from_the_data(tmp_path):
    from dataclasses import replace

    from cnc_interp.export.mcap_io import read_mcap, write_mcap
    from cnc_interp.export.verify_file import check_plan
    from cnc_interp.errors import UsageError
    from cnc_interp.machine.load import load_machine

    m = load_machine("generic-mill")
    out = tmp_path / "p.mcap"
    assert run_inproc("plan", PART, "-q", "-o", out).code == 0
    assert run_inproc("verify", out).code == 0  # the MCAP records its machine
    traj = read_mcap(str(out))
    for dt in (1.0, -0.001, 0.002):
        with pytest.raises(UsageError, match="disagrees|fixed period"):
            check_plan(replace(traj, dt_s=dt), m, "p.mcap")
    # and written into a real file's metadata
    bad = tmp_path / "bad.mcap"
    write_mcap(replace(traj, dt_s=1.0), str(bad), machine=m)
    assert "disagrees" in one_error_line(run_inproc("verify", bad, "-m", "generic-mill"))

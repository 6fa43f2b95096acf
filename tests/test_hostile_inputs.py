"""Hostile inputs: tiny inputs that destroyed files, raised internal errors or
took unbounded memory. Each test names the reproducer it guards.

The rule is ``test_hostile.py``'s: a clean one-line ``FILE:LINE:COL: error: ...`` with the
documented exit code, or the right result — never a traceback, a hang or a destroyed file.
"""

from __future__ import annotations

import glob
import os
import shlex
import subprocess
import time
import tracemalloc
from dataclasses import replace

import numpy as np
import pytest

from tests._contract_helpers import PROC_TIMEOUT_S, SAMPLES, Result, console_script, parse_plan_csv, run_inproc
from tests.test_hostile import SHORT, _write_frames, lathe_frames, one_error_line  # noqa: F401  (a fixture)

TOOL_PART = "G21 G90 F600\nG43 H1\nG0 Z5\nG1 X10\nM2\n"
TOOL_TABLE = "T1 P1 Z+12.5 D6 ;comment\n"


@pytest.fixture
def part_file(tmp_path):
    p = tmp_path / "p.ngc"
    p.write_text(SHORT)
    return p


@pytest.fixture
def tooled(tmp_path):
    """A program that reads a tool table, the table, and an INI machine naming it."""
    part = tmp_path / "ptool.ngc"
    part.write_text(TOOL_PART)
    tbl = tmp_path / "tt.tbl"
    tbl.write_text(TOOL_TABLE)
    ini = tmp_path / "m.ini"
    ini.write_text(
        "[EMC]\nMACHINE = m\n[TRAJ]\nCOORDINATES = XYZ\n[EMCIO]\nTOOL_TABLE = tt.tbl\n"
        + "".join(f"[AXIS_{a}]\nMAX_VELOCITY = 100\nMAX_ACCELERATION = 1000\n" for a in "XYZ")
    )
    return part, tbl, ini


# -- outputs that destroyed files ---------------------------------------------------------------
@pytest.mark.parametrize("cmd", [["plan", "-q"], ["fit"]])
def test_output_equal_to_the_tool_table_is_refused(tooled, cmd):
    """``plan ptool.ngc --tool-table tt.tbl -o tt.tbl`` replaced the table with the plan."""
    part, tbl, _ = tooled
    res = run_inproc(cmd[0], part, "--tool-table", tbl, "-o", tbl, *cmd[1:])
    assert "is the input" in one_error_line(res)
    assert tbl.read_text() == TOOL_TABLE


@pytest.mark.parametrize("cmd", [["plan", "-q", "-o"], ["fit", "-o"], ["stream", "-q", "--dry-run"]])
def test_output_equal_to_the_machines_tool_table_is_refused(tooled, cmd):
    """An INI machine's ``[EMCIO] TOOL_TABLE`` is an input of every command that reads it."""
    part, tbl, ini = tooled
    res = run_inproc(cmd[0], part, "-m", ini, *cmd[1:], tbl)
    assert "is the input" in one_error_line(res)
    assert tbl.read_text() == TOOL_TABLE


def test_batch_report_onto_an_input_is_refused(tmp_path, tooled):
    """``batch p2.ngc -m generic-mill --report p2.ngc`` replaced the program with the report;
    the machine, its tool table, the baseline and the programs found in a folder are inputs too."""
    part, tbl, ini = tooled
    prog = tmp_path / "p2.ngc"
    prog.write_text(SHORT)
    folder = tmp_path / "progs"
    folder.mkdir()
    inside = folder / "a.ngc"
    inside.write_text(SHORT)
    base = tmp_path / "base.json"
    assert run_inproc("batch", prog, "-m", "generic-mill", "-q", "--report", base).code == 0
    baseline = base.read_bytes()
    for args in (
        [prog, "-m", "generic-mill", "--report", prog],
        [folder, "-m", "generic-mill", "--report", inside],
        [prog, "-m", ini, "--report", ini],
        [prog, "-m", ini, "--report", tbl],
        [prog, "-m", "generic-mill", "--baseline", base, "--report", base],
    ):
        assert "is the input" in one_error_line(run_inproc("batch", *args, "-q"))
    assert prog.read_text() == SHORT and inside.read_text() == SHORT
    assert tbl.read_text() == TOOL_TABLE and base.read_bytes() == baseline


def test_batch_report_in_a_missing_folder_fails_before_the_run(tmp_path, monkeypatch):
    """The report was checked only when written, after the whole batch had run."""
    import cnc_interp.batch as batch

    def no_run(*args, **kwargs):
        raise AssertionError("the batch ran")

    monkeypatch.setattr(batch, "run_jobs", no_run)
    prog = tmp_path / "p.ngc"
    prog.write_text(SHORT)
    res = run_inproc("batch", prog, "-m", "generic-mill", "-q", "--report", tmp_path / "no" / "r.json")
    assert "No such file or directory" in one_error_line(res)


def test_batch_and_stream_need_a_machine(tmp_path):
    """``batch p.ngc`` without ``-m`` was a TypeError (click took the explicit default None
    as a value); ``stream`` planned on the default preset although ``-m`` is required."""
    prog = tmp_path / "p.ngc"
    prog.write_text(SHORT)
    for cmd in ("batch", "stream"):
        assert "Missing option '-m'" in one_error_line(run_inproc(cmd, prog, "-q"))
    from cnc_interp.batch import BatchOptions, build_report
    from cnc_interp.errors import UsageError

    with pytest.raises(UsageError, match="needs a machine"):
        build_report(BatchOptions(paths=(str(prog),), machine_spec=None, quiet=True))  # type: ignore[arg-type]
    assert os.listdir(tmp_path) == ["p.ngc"]


# -- internal errors --------------------------------------------------------------------------
def _shell(args, redirect: str, cwd=None):
    """``cnc-interp ARGS REDIRECT`` in bash (``>&-`` closes standard output)."""
    cmd = " ".join(shlex.quote(str(a)) for a in (console_script(), *args))
    env = {k: v for k, v in os.environ.items() if k != "CNC_INTERP_DEBUG"}
    r = subprocess.run(
        ["bash", "-c", f"{cmd} {redirect}"], capture_output=True, timeout=PROC_TIMEOUT_S, env=env, cwd=cwd
    )
    return Result(r.returncode, r.stdout, r.stderr.decode("utf-8", "replace"))


@pytest.mark.parametrize("args", [["plan"], ["parse", "--json"], ["parse"], ["fit"], ["plan", "-o", "-", "--json"]])
def test_closed_stdout_is_one_error_line(part_file, args):
    """``plan p.ngc >&-`` was an internal AttributeError, ``parse --json >&-`` a traceback."""
    res = _shell([args[0], part_file, *args[1:]], ">&-")
    assert "standard output is closed" in one_error_line(res)


def test_closed_stdout_does_not_matter_to_a_plan_written_to_a_file(part_file, tmp_path):
    res = _shell(["plan", part_file, "-o", tmp_path / "o.csv"], ">&-")
    assert res.code == 0 and res.err.count("worst limit ratio") == 1, res.explain()
    assert (tmp_path / "o.csv").read_text().startswith("t,s,feed,X,Y,Z\n")


def test_closed_stderr_keeps_a_complete_plan_a_success(part_file, tmp_path):
    """``plan p.ngc -o x.csv 2>&-`` planned everything and exited 1."""
    for extra in ([], ["--json"]):
        res = _shell(["plan", part_file, "-o", tmp_path / "o.csv", *extra], "2>&-")
        assert res.code == 0, res.explain()
        assert (tmp_path / "o.csv").read_text().startswith("t,s,feed,X,Y,Z\n")
        assert (b'"status": "ok"' in res.out) == bool(extra)


def test_closed_stdin_is_one_error_line():
    res = _shell(["plan", "-", "-q", "-o", os.devnull], "<&-")
    assert "standard input is closed" in one_error_line(res)


def _mill_toml(path, vmax="100", top=""):
    path.write_text(
        top + "".join(f"[axes.{a}]\nvmax = {vmax if a == 'X' else 100}\namax = 1000\njmax = 1e5\n" for a in "XYZ")
    )
    return path


def test_machine_integer_of_thousands_of_digits_is_a_located_error(tmp_path, part_file):
    """A TOML integer of 5000 digits made tomllib raise a plain ValueError."""
    m = _mill_toml(tmp_path / "m.toml", vmax="9" * 5000)
    line = one_error_line(run_inproc("plan", part_file, "-m", m, "-q", "-o", os.devnull))
    assert line.startswith(f"{m}:2:8: error: invalid TOML: a number of thousands of digits")


def test_machine_that_is_a_directory_is_an_error(tmp_path, part_file):
    """``-m /tmp`` was an internal IsADirectoryError."""
    for cmd in (["plan", part_file, "-q", "-o", os.devnull], ["parse", part_file]):
        line = one_error_line(run_inproc(*cmd, "-m", tmp_path))
        assert line == f"{tmp_path}: error: machine file is not a regular file"


def test_deeply_nested_baseline_is_an_error(tmp_path, part_file):
    """A ``--baseline`` of 100,000 nested arrays was an internal RecursionError."""
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100000 + "]" * 100000)
    res = run_inproc("batch", part_file, "-m", "generic-mill", "--baseline", deep, "-q")
    assert "nested too deeply" in one_error_line(res)
    res = run_inproc("batch", part_file, "-m", "generic-mill", "--baseline", "/dev/zero", "-q")
    assert "not a regular file" in one_error_line(res)


def _api_cases():
    import cnc_interp as ci

    m = ci.load_machine("generic-mill")
    lathe = ci.load_machine("xz-lathe")
    prog = ci.read_program(SHORT, machine=m)
    fitted = ci.fit(prog)
    traj = ci.plan(fitted, m)
    return {
        "load_machine(123)": lambda: ci.load_machine(123),
        "load_machine(None)": lambda: ci.load_machine(None),
        "read_program(None)": lambda: ci.read_program(None),
        "read_program(machine=5)": lambda: ci.read_program(SHORT, machine=5),
        "read_program(start='abc')": lambda: ci.read_program(SHORT, machine=m, start="abc"),
        "read_program(tool_table=5)": lambda: ci.read_program(SHORT, machine=m, tool_table=5),
        "fit('x')": lambda: ci.fit("x"),
        "fit(tol_mm='a')": lambda: ci.fit(prog, tol_mm="a"),
        "fit(tol_mm=-1)": lambda: ci.fit(prog, tol_mm=-1),
        "fit(tol_mm=1e-300)": lambda: ci.fit(prog, tol_mm=1e-300),
        "fit(settings=5)": lambda: ci.fit(prog, settings=5),
        "plan(program)": lambda: ci.plan(prog, m),
        "plan(another machine)": lambda: ci.plan(fitted, lathe),
        "plan(dt_s='a')": lambda: ci.plan(fitted, m, dt_s="a"),
        "plan(settings=5)": lambda: ci.plan(fitted, m, settings=5),
        "plan(progress=5)": lambda: ci.plan(fitted, m, progress=5),
        "verify(fitted)": lambda: ci.verify(fitted, m),
        "write(fitted)": lambda: ci.write(fitted, "x.csv"),
        "write(path=5)": lambda: ci.write(traj, 5),
        "write(mcap, another machine)": lambda: ci.write(traj, "x.mcap", lathe),
        "run(5)": lambda: ci.run(5, m),
        "run(start=[1])": lambda: ci.run(SHORT, m, start=np.array([1.0])),
        "run(fit_settings=5)": lambda: ci.run(SHORT, m, fit_settings=5),
        "run(plan_settings=5)": lambda: ci.run(SHORT, m, plan_settings=5),
    }


def test_api_wrong_arguments_are_usage_errors(tmp_path, monkeypatch):
    """Wrong types, a program fitted for another machine, ``fit(tol_mm=-1)``: raw TypeError,
    ValueError, IndexError (or a silent "exact" fit) before; each now a ``UsageError``
    naming the argument."""
    from cnc_interp.errors import UsageError

    monkeypatch.chdir(tmp_path)
    for name, call in _api_cases().items():
        with pytest.raises(UsageError) as ei:
            call()
        assert ei.value.format().startswith("cnc-interp: error: "), name
    assert os.listdir(tmp_path) == []


def test_fit_settings_and_fit_agree_on_the_tolerance_range():
    from cnc_interp.errors import UsageError
    from cnc_interp.fit.settings import FIT_TOL_MIN_MM, FitSettings

    for bad in (-1.0, 1e-300, FIT_TOL_MIN_MM / 2, 11.0, float("nan")):
        with pytest.raises(UsageError):
            FitSettings.from_options(tol_mm=bad)
        with pytest.raises(UsageError):
            FitSettings(tol_mm=0.001, tol_cap_mm=bad)
    for good in (0.0, FIT_TOL_MIN_MM, 0.01, 10.0):
        assert FitSettings.from_options(tol_mm=good).tol_cap_mm == good


@pytest.mark.parametrize("tol", ["1e-300", "5e-7"])
def test_tol_below_the_finest_is_a_usage_error(part_file, tol):
    """``--tol 1e-300`` (then inside the documented 0 to 10): 14 s, 1.5 GB, ZeroDivisionError."""
    res = run_inproc("plan", part_file, "-q", "-o", os.devnull, "--tol", tol)
    assert "below 1e-06 mm" in one_error_line(res)


def test_control_bytes_are_escaped_in_summaries(tmp_path):
    """A machine named ``evil<ESC>[31m<BEL>`` and a part named ``e<ESC>x<BEL>.ngc`` were
    printed raw by the summaries (``test_control_bytes_are_escaped_in_messages`` covers
    the error lines)."""
    prog = tmp_path / "e\x1bx\x07.ngc"
    prog.write_text(SHORT)
    m = _mill_toml(tmp_path / "m.toml", top='name = "evil\\u001b[31m\\u0007"\n')
    runs = [
        run_inproc("plan", prog, "-m", m, "-o", tmp_path / "o.csv"),
        run_inproc("parse", prog, "-m", m),
        run_inproc("fit", prog, "-m", m),
        run_inproc("batch", prog, "-m", m, "-q"),
        run_inproc("machines", m),
    ]
    for res in runs:
        assert res.code == 0, res.explain()
        text = res.out.decode() + res.err
        assert "\x1b" not in text and "\x07" not in text, text
        assert "\\x1b" in text
    assert "evil\\x1b[31m\\x07" in runs[0].err and "evil\\x1b[31m\\x07" in runs[4].out.decode()


# -- emulate ------------------------------------------------------------------------------------


def _setpoints_frame(frames):
    from cnc_interp.fpga.frames import FrameType

    i = next((k for k, f in enumerate(frames) if f.type == FrameType.SETPOINTS), None)
    if i is None:
        pytest.skip("the lathe stream has no setpoint frame")
    return i


@pytest.mark.parametrize("value", [1 << 62, -(1 << 62)])
def test_emulate_refuses_setpoints_outside_the_position_format(tmp_path, lathe_frames, value):  # noqa: F811
    """A SETPOINTS frame (valid CRC) carrying 2^62 was replayed silently."""
    from cnc_interp.fpga.frames import SETPOINTS_HEAD

    frames = list(lathe_frames)
    i = _setpoints_frame(frames)
    payload = bytearray(frames[i].payload)
    payload[SETPOINTS_HEAD.size : SETPOINTS_HEAD.size + 8] = value.to_bytes(8, "little", signed=True)
    frames[i] = replace(frames[i], payload=bytes(payload))
    f = tmp_path / "big.bin"
    _write_frames(f, frames)
    out = tmp_path / "o.csv"
    assert "rejected by the device model" in one_error_line(run_inproc("emulate", f, "-o", out))
    assert not out.exists()


# -- end point ----------------------------------------------------------------------------------
@pytest.mark.parametrize("radius", ["1000000000", "100000000", "1"])
def test_an_arc_of_huge_radius_ends_on_its_programmed_point(tmp_path, radius):
    """``G2 X1 Y0 R1000000000`` ended at X = 0.99999986: the arc's end, computed from a
    centre a billion mm away, lost seven digits to cancellation."""
    prog = tmp_path / "r.ngc"
    prog.write_text(f"G21 G90 F600\nG2 X1 Y0 R{radius}\nM2\n")
    res = run_inproc("plan", prog, "-q")
    assert res.code == 0, res.explain()
    q = parse_plan_csv(res.out).q
    assert q[-1].tolist() == [1.0, 0.0, 0.0]
    import cnc_interp as ci

    fitted = ci.fit(ci.read_program(str(prog), machine="generic-mill"))
    assert fitted.paths[-1].end.tolist() == [1.0, 0.0, 0.0]


# -- machine limits --------------------------------------------------------------------------
def _limits_toml(path, vmax="100", amax="1000", jmax="1e5", top=""):
    path.write_text(top + "".join(f"[axes.{a}]\nvmax = {vmax}\namax = {amax}\njmax = {jmax}\n" for a in "XYZ"))
    return path


@pytest.mark.parametrize(
    "limits,where",
    [
        ({"vmax": "1e-20"}, ":2:1:"),
        ({"amax": "1e-20"}, ":3:1:"),
        ({"jmax": "1e-20"}, ":4:1:"),
        ({"vmax": "1e-300"}, ":2:1:"),
        ({"amax": "1e-300"}, ":3:1:"),
        ({"jmax": "1e-300"}, ":4:1:"),
        ({"vmax": "1e-9"}, ":2:1:"),
        ({"amax": "1e-3"}, ":1:1:"),  # 1e5 s from rest to vmax: the ramp rule, at [axes.X]
    ],
)
def test_tiny_machine_limits_are_located_errors(tmp_path, part_file, limits, where):
    """Limits of 1e-20 or 1e-300 were an internal OverflowError or ValueError, vmax = 1e-9
    a plan of more than a minute, amax = 1e-3 (vmax 100) brake buffers beyond memory."""
    m = _limits_toml(tmp_path / "m.toml", **limits)
    line = one_error_line(run_inproc("plan", part_file, "-m", m, "-q", "-o", os.devnull))
    assert line.startswith(f"{m}{where} error: ")


def test_a_dt_too_short_for_a_slow_ramp_is_refused(tmp_path, part_file):
    m = _limits_toml(tmp_path / "m.toml", amax="1")  # 100 s from rest to 100 mm/s
    assert run_inproc("plan", part_file, "-m", m, "-q", "-o", os.devnull).code == 0
    line = one_error_line(run_inproc("plan", part_file, "-m", m, "-q", "-o", os.devnull, "--dt", "1e-5"))
    assert "axis X takes 100 s from rest to its vmax" in line
    from cnc_interp.errors import MachineError
    from cnc_interp.machine.model import Machine

    with pytest.raises(MachineError, match="out of range"):
        Machine("m", "X", [1e-9], [1.0], [1.0], 0.001)


def _one_piece_program(n_samples: int):
    """A program of one planar segment whose single profile piece holds ``n_samples``
    samples (all at the origin): what a 500-byte frame file may ask for."""
    from cnc_interp.fpga.fixed import FpgaFormats
    from cnc_interp.fpga.model import FixedSegment, FpgaProgram, ProfilePiece

    f = FpgaFormats()
    piece = ProfilePiece(n_samples, 3, 0, (0,) * 6)
    seg = FixedSegment(0, 1, (0, 1), (1 << f.trig.frac) - 1, 0, (0, 0), 0, 0, 0, (0,) * 6, 0, (piece,))
    return FpgaProgram("XZ", 0.001, f, (0, 0), n_samples, (seg,), "big")


def test_emulate_holds_a_chunk_of_a_long_piece_not_the_piece(monkeypatch):
    """A 515-byte frame file with one 2^24-sample piece took 3.8 GB, then ran out of memory:
    the model evaluated the whole segment at once on arrays of Python ints, and ``emulate``
    kept every sample. Now the segment is evaluated a chunk at a time and ``emulate`` writes
    the samples as they come (measured: 2^24 samples, 3.2 GB before, 0.2 GB after)."""
    import cnc_interp.fpga.model as model

    prog = _one_piece_program(1 << 16)
    monkeypatch.setattr(model, "FPGA_MODEL_CHUNK_SAMPLES", 4096)
    got = []
    st = model.DatapathState(prog.axes, prog.formats, prog.start, sink=lambda q, line: got.append(q.shape[0]))
    tracemalloc.start()
    try:
        st.apply(prog.items[0])
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert sum(got) == 1 << 16 and max(got) == 4096
    assert peak < 5e6, peak  # the whole piece at once: ~22 MB


def test_chunked_segments_and_streamed_emulation_give_the_same_numbers(tmp_path, lathe_frames):  # noqa: F811
    from cnc_interp.export.csv_io import write_csv
    from cnc_interp.fpga.commands import emulate_frames, trajectory_from_device
    from cnc_interp.fpga.frames import FrameType, decode_profile, decode_segment, program_frames
    from cnc_interp.fpga.model import run_segment, segment_chunks

    f = tmp_path / "f.bin"
    _write_frames(f, lathe_frames)
    assert run_inproc("emulate", f, "-o", tmp_path / "streamed.csv").code == 0
    write_csv(trajectory_from_device(emulate_frames(list(lathe_frames))), str(tmp_path / "whole.csv"))
    assert (tmp_path / "streamed.csv").read_bytes() == (tmp_path / "whole.csv").read_bytes()
    core = emulate_frames(list(lathe_frames))
    fmts = core.datapath.formats
    segs = [decode_segment(fr.payload)[0] for fr in lathe_frames if fr.type == FrameType.SEGMENT]
    pieces = [decode_profile(fr.payload) for fr in lathe_frames if fr.type == FrameType.PROFILE]
    assert segs and pieces
    seg = replace(segs[0], pieces=tuple(p for idx, _, ps in pieces if idx == segs[0].index for p in ps))
    whole = run_segment(seg, fmts)
    parts = list(segment_chunks(seg, fmts, chunk=7))
    for k, name in enumerate(("xi", "x", "z", "q")):
        assert np.array_equal(np.concatenate([p[k] for p in parts]), getattr(whole, name))
    big = tmp_path / "big.bin"
    big.write_bytes(b"".join(program_frames(_one_piece_program(100_000))[0]))
    assert big.stat().st_size < 600
    res = run_inproc("emulate", big, "-o", tmp_path / "big.csv")
    assert res.code == 0, res.explain()
    assert (tmp_path / "big.csv").read_bytes().count(b"\n") == 100_001


# -- memory bounds ------------------------------------------------------------------------------
@pytest.mark.parametrize("planner", ["vpop", "optimal"])
def test_one_long_move_enters_the_memory_check(tmp_path, monkeypatch, planner):
    """One ``G1 X30000000`` took 841 MB, ``X1e8`` 2.3 GB and ``X3e8`` ran out of memory:
    VPOp's joint table has a piece per 20 mm of the path, however the samples are
    streamed. The memory check now counts it and refuses before building it. (The
    command runs in a process of 3 GB of address space, timed: without the check it ran out
    of memory, or planned 10^8 mm for hours.)"""
    import resource

    from cnc_interp.plan import budget

    prog = tmp_path / "long.ngc"
    prog.write_text("G21 G90 F12000\nG1 X300000000\nM2\n")
    cmd = [console_script(), "plan", str(prog), "--planner", planner, "-q", "-o", str(tmp_path / "o.csv")]

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))

    env = {k: v for k, v in os.environ.items() if k != "CNC_INTERP_DEBUG"}
    r = subprocess.run(cmd, capture_output=True, timeout=120, preexec_fn=limit, env=env)
    res = Result(r.returncode, r.stdout, r.stderr.decode("utf-8", "replace"))
    line = one_error_line(res, code=1)
    assert line.startswith(f"{prog}: error: the move ending at line 2 is 3e+08 mm")
    assert "planning it needs at least 6 GB of memory" in line
    assert not (tmp_path / "o.csv").exists()
    monkeypatch.setattr(budget, "available_memory_bytes", lambda: 500_000_000)
    t0 = time.monotonic()
    from cnc_interp.errors import PlanError
    from cnc_interp.pipeline import plan_part  # the in-memory plan: batch, the FPGA stage

    with pytest.raises(PlanError, match="the move ending at line 2"):
        plan_part(str(prog), "generic-mill", planner=planner)
    assert time.monotonic() - t0 < 60
    # a move of a metre is far from it
    budget.check_sample_budget(_paths("G21 G90 F12000\nG1 X1000\nM2\n"), _mill(), 1e-3, "p", available=10**8)


def _mill():
    from cnc_interp.machine.load import load_machine

    return load_machine("generic-mill")


def _paths(text: str):
    import cnc_interp as ci

    return ci.fit(ci.read_program(text, machine=_mill())).paths


def test_parse_summarises_a_canned_cycle_of_many_holes_in_bounded_memory(tmp_path):
    """``G91 G81 X1 Y0 Z-1 R1 L1000000`` (50 bytes): ``parse`` grew past 5.4 GB in 60 s, 8.7 kB
    a hole: the whole ``Program`` was kept, and a stream drained only between blocks (one
    block, a million holes). ``parse`` now counts each run as it is read; the interpreter
    hands runs on inside a block (measured: L1000000, 112 MB peak, 250 s)."""
    from cnc_interp.pipeline import summarise_part

    prog = tmp_path / "drill.ngc"
    prog.write_text("G21 F600\nG91 G81 X1 Y0 Z-1 R1 L10000\nM2\n")
    tracemalloc.start()
    try:
        summary = summarise_part(str(prog), None)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert summary["runs"] == 20001 and summary["nodes"] == 20000 and summary["axes"] == "XYZ"
    assert summary["bounds"]["X"] == [0.0, 10000.0]
    assert peak < 40e6, peak  # the whole program: ~80 MB
    from cnc_interp.gcode import read_program
    from cnc_interp.gcode.summary import program_summary

    assert program_summary(read_program(prog.read_bytes(), str(prog))) == summary


@pytest.mark.parametrize("machine", [None, "generic-mill", "mikron-ucp710"])
def test_streamed_summary_is_the_programs(machine):
    """``parse`` reads as a stream (the program's own axes known only at its end): the
    same summary as ``program_summary`` of the whole ``Program``."""
    from cnc_interp.gcode.summary import program_summary
    from cnc_interp.pipeline import load_program_for, summarise_part

    for part in sorted(glob.glob(os.path.join(SAMPLES, "*.ngc"))):
        try:
            program, _ = load_program_for(part, machine)
        except Exception as exc:  # noqa: BLE001 - the stream must fail the same way
            with pytest.raises(type(exc)):
                summarise_part(part, machine)
            continue
        assert summarise_part(part, machine) == program_summary(program), part


def test_a_million_picometre_steps_fit_in_little_memory():
    """``o1 repeat [1000000] / G1 X0.000000001 / o1 endrepeat`` (G91): 2.25 GB peak in
    ``plan``. Nodes 1e-9 mm apart were all kept (the merge distance was 1e-9 mm) and
    fitted as one section, ~2.2 kB a node; they are now merged below half the finest
    tolerance (measured: the million steps, 0.47 GB peak in ``plan``, the parse's share)."""
    import cnc_interp as ci

    text = "G21 G91 F600\no1 repeat [100000]\nG1 X0.000000001\no1 endrepeat\nM2\n"
    prog = ci.read_program(text, machine="generic-mill")
    tracemalloc.start()
    try:
        fitted = ci.fit(prog)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 60e6, peak  # 100,000 nodes kept: ~230 MB
    (path,) = fitted.paths
    assert path.coef.shape[0] < 1000
    assert path.end[0] == prog.items[0].nodes[-1, 0]  # the sum of the steps, exactly


def test_a_g64_p_finer_than_the_finest_tolerance_works_to_it(tmp_path):
    """``G64 P0.0000000000000001`` (found beside ``--tol 1e-300``): killed for memory at
    23.6 GB after 328 s; a move's G64 P now works to ``FIT_TOL_MIN_MM`` at the finest."""
    from cnc_interp.fit.settings import DEFAULT_TOL_MM, FIT_TOL_MIN_MM, FitSettings

    tol = FitSettings().node_tolerance(np.array([np.nan, 0.0, 1e-16, 5e-7, 0.02]))
    assert tol.tolist() == [DEFAULT_TOL_MM, 0.0, FIT_TOL_MIN_MM, FIT_TOL_MIN_MM, 0.02]
    prog = tmp_path / "p.ngc"
    prog.write_text("G21 G90 F600 G64 P0.0000000000000001\nG1 X10 Y5\nG1 X20\nM2\n")
    t0 = time.monotonic()
    res = run_inproc("plan", prog, "-q", "-o", tmp_path / "o.csv")
    assert res.code == 0, res.explain()
    assert time.monotonic() - t0 < 60

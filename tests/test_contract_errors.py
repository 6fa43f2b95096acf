"""Bad input to ``cnc-interp plan``: exactly one ``FILE:LINE:COL: error: ...`` line on
stderr, exit 2, no traceback, nothing on stdout and no output file (DESIGN.md "Command-line
contract"). Exit 1 is for a plan that failed.
"""

from __future__ import annotations

import os
import random
import re
import resource

import pytest

from ._contract_helpers import SAMPLES, run_inproc, run_proc


def _check_one_error_line(res, prefix: str, line: int | None, col: int | None, what: str):
    err = res.err
    assert "Traceback" not in err, err
    assert err.endswith("\n") and err.count("\n") == 1, f"want exactly one stderr line:\n{err}"
    assert len(err.splitlines()) == 1, f"stray line separators in:\n{err!r}"
    if line is None:
        head = re.escape(prefix) + r": error: "
    elif col is None:
        head = re.escape(prefix) + rf":{line}:\d+: error: "
    else:
        head = re.escape(prefix) + rf":{line}:{col}: error: "
    assert re.match(head, err), f"want {head!r}, got {err!r}"
    assert what.lower() in err.lower(), f"{what!r} not in {err!r}"
    assert res.out == b""


# -- G-code ---------------------------------------------------------------------------------
def _garbage() -> bytes:
    rng = random.Random(20261122)
    return bytes(rng.randrange(256) for _ in range(3000))


GCODE_CASES = [
    # id, program bytes, machine, line, col, text the message must contain
    ("unterminated-comment", b"G21\nG1 X1 (unterminated\n", "generic-mill", 2, 7, "comment"),
    ("letter-without-number", b"G21\nG1 X F100\n", "generic-mill", 2, 4, "no value"),
    ("two-motion-codes", b"G21\nG0 G1 X1 F100\n", "generic-mill", 2, 4, "same modal group"),
    ("arc-off-circle", b"G21\nG0 X10\nG3 X0 Y11 I-10 J0 F60\n", "generic-mill", 3, 1, "not on the circle"),
    ("arc-radius-too-small", b"G21\nG2 X10 Y0 R4 F60\n", "generic-mill", 2, None, "radius"),
    ("missing-feed", b"G21\nG1 X5\n", "generic-mill", 2, 1, "feed"),
    ("zero-feed", b"G21\nG1 X5 F0\n", "generic-mill", 2, None, "feed"),
    ("division-by-zero", b"G21\nG1 X[1/0] F100\n", "generic-mill", 2, 7, "division by zero"),
    ("undefined-parameter", b"G21\nG1 X#<nope> F100\n", "generic-mill", 2, 5, "undefined parameter"),
    ("unterminated-bracket", b"G21\nG1 X[1+2 F100\n", "generic-mill", 2, None, "]"),
    ("nan", b"G21\nG1 X[SQRT[-1]] F100\n", "generic-mill", 2, None, "SQRT"),
    ("exponent", b"G21\nG1 X1e999 F100\n", "generic-mill", 2, None, "exponent"),
    ("unterminated-g5.2", b"G21 F60\nG5.2 P1\nX1 Y1 P1\n", "generic-mill", 2, 1, "G5.3"),
    ("unknown-g-code", b"G21\nG7.5 X1\n", "generic-mill", 2, 1, "G7.5"),
    ("endless-loop", b"o100 while [1]\no100 endwhile\n", "generic-mill", 1, 1, "loop"),
    ("g41-unsupported", b"G21\nG41 D1\nG1 X1 F100\n", "generic-mill", 2, 1, "G41"),
    ("g95-unsupported", b"G21\nG95 G1 X1 F1\n", "generic-mill", 2, 1, "G95"),
    ("axis-the-machine-lacks", b"G21\nG1 A10 F100\n", "generic-mill", 2, 4, "axis A is not on this machine"),
    ("lathe-has-no-y", b"G18 G21\nG1 X1 Y1 F100\n", "xz-lathe", 2, 7, "axis Y"),
    ("binary-garbage", _garbage(), "generic-mill", 1, None, ""),
    ("2mb-line", b"G1 X" + b"1" * 2_000_000 + b" F100\n", "generic-mill", 1, None, "long"),
]


@pytest.mark.parametrize("data,machine,line,col,what", [pytest.param(*c[1:], id=c[0]) for c in GCODE_CASES])
def test_bad_gcode(tmp_path, data, machine, line, col, what):
    part = tmp_path / "part.ngc"
    part.write_bytes(data)
    out = tmp_path / "out.csv"
    res = run_inproc("plan", part, "-m", machine, "-o", out)
    assert res.code == 2, res.explain()
    _check_one_error_line(res, str(part), line, col, what)
    assert os.listdir(tmp_path) == ["part.ngc"], "no output or temporary file on error"


def test_bad_gcode_on_stdin():
    res = run_inproc("plan", "-", stdin=b"G21\nG0 G1 X1 F100\n")
    assert res.code == 2, res.explain()
    _check_one_error_line(res, "<stdin>", 2, 4, "same modal group")


def test_sample_for_the_wrong_machine():
    part = os.path.join(SAMPLES, "mill-contour.ngc")
    res = run_inproc("plan", part, "-m", "xz-lathe")
    assert res.code == 2
    _check_one_error_line(res, part, 10, 12, "axis Y is not on this machine")


def test_console_script_reports_bad_input_without_traceback(tmp_path):
    """The real process, not just the in-process entry point: garbage and a missing file."""
    part = tmp_path / "garbage.ngc"
    part.write_bytes(_garbage())
    res = run_proc("plan", part, "-o", tmp_path / "out.csv")
    assert res.code == 2, res.explain()
    _check_one_error_line(res, str(part), 1, None, "")
    res = run_proc("plan", tmp_path / "missing.ngc")
    assert res.code == 2, res.explain()
    _check_one_error_line(res, str(tmp_path / "missing.ngc"), None, None, "cannot read")
    assert sorted(os.listdir(tmp_path)) == ["garbage.ngc"]


def test_missing_part_file(tmp_path):
    res = run_inproc("plan", tmp_path / "nope.ngc", "-o", tmp_path / "out.csv")
    assert res.code == 2
    _check_one_error_line(res, str(tmp_path / "nope.ngc"), None, None, "No such file")
    assert os.listdir(tmp_path) == []


# -- machine files --------------------------------------------------------------------------
_AXES_OK = "".join(f"[axes.{a}]\nvmax = 100.0\namax = 1000.0\njmax = 10000.0\n" for a in "YZ")

MACHINE_CASES = [
    # id, file name, contents, line (None: no line), text the message must contain
    ("toml-syntax", "m.toml", 'name = "x"\ndt = 0.001\n[axes.X\nvmax = 1\n', 3, "TOML"),
    ("no-axis-table", "m.toml", 'name = "x"\ndt = 0.001\n', None, "axes"),
    (
        "negative-limit",
        "m.toml",
        'name = "x"\n[axes.X]\nvmax = 100.0\namax = -5.0\njmax = 1000.0\n' + _AXES_OK,
        4,
        "amax",
    ),
    (
        "unknown-key",
        "m.toml",
        'name = "x"\nfoo = 3\n[axes.X]\nvmax = 1.0\namax = 1.0\njmax = 1.0\n' + _AXES_OK,
        2,
        "unknown key 'foo'",
    ),
    ("unknown-axis-key", "m.toml", "[axes.X]\nvmax = 1.0\namax = 1.0\njmax = 1.0\nvmx = 2\n" + _AXES_OK, 5, "vmx"),
    ("missing-jmax", "m.toml", "[axes.X]\nvmax = 1.0\namax = 1.0\n" + _AXES_OK, 1, "jmax"),
    ("nan-limit", "m.toml", "[axes.X]\nvmax = nan\namax = 1.0\njmax = 1.0\n" + _AXES_OK, 2, "finite"),
    ("negative-dt", "m.toml", "dt = -0.001\n[axes.X]\nvmax = 1.0\namax = 1.0\njmax = 1.0\n" + _AXES_OK, 1, "dt"),
    (
        "unknown-kinematics",
        "m.toml",
        'kinematics = "warp"\n[axes.X]\nvmax = 1.0\namax = 1.0\njmax = 1.0\n' + _AXES_OK,
        1,
        "warp",
    ),
    ("not-utf8", "m.toml", b"\xff\xfe garbage", 1, "UTF-8"),
    (
        "ini-negative-velocity",
        "m.ini",
        "[TRAJ]\nCOORDINATES = X Y Z\nLINEAR_UNITS = mm\n"
        "[AXIS_X]\nMAX_VELOCITY = -3\nMAX_ACCELERATION = 10\n[AXIS_Y]\nMAX_VELOCITY = 3\n"
        "MAX_ACCELERATION = 10\n[AXIS_Z]\nMAX_VELOCITY = 3\nMAX_ACCELERATION = 10\n",
        5,
        "MAX_VELOCITY",
    ),
    ("ini-no-axes", "m.ini", "[TRAJ]\nLINEAR_UNITS = mm\n", 1, "COORDINATES"),
]


@pytest.mark.parametrize("name,text,line,what", [pytest.param(*c[1:], id=c[0]) for c in MACHINE_CASES])
def test_bad_machine_file(tmp_path, name, text, line, what):
    part = tmp_path / "part.ngc"
    part.write_text("G21\nG1 X1 Y1 Z-1 F600\n")
    mfile = tmp_path / name
    mfile.write_bytes(text if isinstance(text, bytes) else text.encode())
    res = run_inproc("plan", part, "-m", mfile, "-o", tmp_path / "out.csv")
    assert res.code == 2, res.explain()
    _check_one_error_line(res, str(mfile), line, None, what)
    assert not (tmp_path / "out.csv").exists()


def test_machine_without_an_axis_the_program_moves(tmp_path):
    part = tmp_path / "part.ngc"
    part.write_text("G21\nG1 Z1 F100\n")
    mfile = tmp_path / "xy.toml"
    mfile.write_text('name = "xy"\n' + "".join(f"[axes.{a}]\nvmax = 1.0\namax = 1.0\njmax = 1.0\n" for a in "XY"))
    res = run_inproc("plan", part, "-m", mfile)
    assert res.code == 2
    _check_one_error_line(res, str(part), 2, 4, "axis Z is not on this machine")


@pytest.mark.parametrize(
    "spec,what", [("nosuchpreset", "no machine file or preset"), ("/nonexistent/m.toml", "not found")]
)
def test_unknown_machine(tmp_path, spec, what):
    part = tmp_path / "part.ngc"
    part.write_text("G21\nG1 X1 F100\n")
    res = run_inproc("plan", part, "-m", spec)
    assert res.code == 2
    _check_one_error_line(res, spec, None, None, what)


# -- options --------------------------------------------------------------------------------
#: options click rejects itself (its own usage message)
CLICK_OPTION_CASES = [
    pytest.param(["--dt", "-1"], id="dt-negative"),
    pytest.param(["--dt", "0"], id="dt-zero"),
    pytest.param(["--dt", "abc"], id="dt-not-a-number"),
    pytest.param(["--tol", "-1"], id="tol-negative"),
    pytest.param(["--planner", "foo"], id="unknown-planner"),
    pytest.param(["--bogus"], id="unknown-option"),
]


@pytest.fixture()
def good_part(tmp_path):
    part = tmp_path / "part.ngc"
    part.write_text("G21\nG1 X1 Y1 F600\n")
    return part


@pytest.mark.parametrize("opts", CLICK_OPTION_CASES)
def test_bad_option_exit_2_without_traceback(good_part, tmp_path, opts):
    res = run_inproc("plan", good_part, "-o", tmp_path / "out.csv", *opts)
    assert res.code == 2, res.explain()
    assert "Traceback" not in res.err and "error" in res.err.lower(), res.err
    assert res.out == b"" and not (tmp_path / "out.csv").exists()


@pytest.mark.parametrize("opts", CLICK_OPTION_CASES)
def test_bad_option_is_one_error_line(good_part, opts):
    res = run_inproc("plan", good_part, *opts)
    assert res.code == 2
    assert res.err.count("\n") == 1 and ": error: " in res.err, res.err


@pytest.mark.parametrize(
    "opts,what",
    [
        (["--start", "Q=1"], "--start"),
        (["--start", "X=abc"], "--start"),
        (["--dt", "nan"], "'--dt'"),
        (["--dt", "inf"], "'--dt'"),
        (["--dt", "100"], "'--dt'"),
        (["--tol", "nan"], "'--tol'"),
    ],
)
def test_bad_option_value_one_line(good_part, opts, what):
    res = run_inproc("plan", good_part, *opts)
    assert res.code == 2, res.explain()
    assert "Traceback" not in res.err
    assert res.err.count("\n") == 1 and ": error: " in res.err and what in res.err, res.err
    assert res.out == b""


def test_unwritable_output(good_part, tmp_path):
    out = tmp_path / "no" / "such" / "dir" / "out.csv"
    res = run_inproc("plan", good_part, "-o", out)
    assert res.code == 2
    _check_one_error_line(res, str(out), None, None, "cannot write output")


@pytest.mark.parametrize("where", ["missing-dir", "is-dir"])
def test_unwritable_output_fails_before_planning(good_part, tmp_path, monkeypatch, where):
    """The output is checked before the (possibly long) planning starts."""
    import cnc_interp.pipeline as pipeline

    def no_planning(*args, **kwargs):
        raise AssertionError("planned although the output cannot be written")

    monkeypatch.setattr(pipeline, "plan_part", no_planning)
    out = tmp_path / "no" / "out.csv" if where == "missing-dir" else tmp_path
    res = run_inproc("plan", good_part, "-o", out)
    assert res.code == 2, res.explain()
    _check_one_error_line(res, str(out), None, None, "cannot write output")


# -- exit 1: the plan failed ----------------------------------------------------------------
def _limit_memory():  # pragma: no cover - runs in the child
    resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))


def test_plan_too_big_for_memory_is_exit_1(tmp_path):
    """F0.001 mm/min over 10 mm: ~6e8 samples at 1 ms in one path, more than 3 GB allows
    for a planner that returns a whole path at once (paper 000's constant feed; VPOp
    streams within the path and would plan it, for hours). The plan fails (exit 1, one
    line), without a traceback or a partial output file: refused before planning the path
    (the window check) where the system's free memory is known to be too small, else by
    the MemoryError of the 3 GB limit."""
    import subprocess

    from ._contract_helpers import console_script

    part = tmp_path / "slow.ngc"
    part.write_text("G21\nG1 X10 F0.001\n")
    r = subprocess.run(
        [console_script(), "plan", str(part), "--planner", "constant", "-o", str(tmp_path / "out.csv")],
        capture_output=True,
        timeout=300,
        preexec_fn=_limit_memory,
        stdin=subprocess.DEVNULL,
    )
    err = r.stderr.decode("utf-8", "replace")
    assert r.returncode == 1, err
    assert "Traceback" not in err and err.count("\n") == 1 and "error" in err, err
    assert sorted(os.listdir(tmp_path)) == ["slow.ngc"]


# -- verify on a doctored plan file ---------------------------------------------------------
@pytest.mark.parametrize(
    "col,value,code,line",
    [
        (4, "nan", 1, None),  # a NaN setpoint: the plan fails verify
        (4, "inf", 1, None),
        (0, "0.0495", 2, 51),  # t off the k*dt grid: not a plan file (bad input, its line)
        (4, "abc", 2, 51),  # not a number
    ],
)
def test_verify_doctored_file(tmp_path, col, value, code, line):
    res = run_inproc("plan", "-", "-q", stdin=b"G21\nG1 X1 Y1 F600\nM2\n")
    assert res.code == 0, res.explain()
    rows = res.out.decode().split("\n")
    fields = rows[50].split(",")
    fields[col] = value
    rows[50] = ",".join(fields)
    path = tmp_path / "doctored.csv"
    path.write_text("\n".join(rows))
    got = run_inproc("verify", path, "-m", "generic-mill")
    assert got.code == code, got.out.decode() + got.err
    assert "Traceback" not in got.err
    if code == 2:
        _check_one_error_line(got, str(path), line, None, "")

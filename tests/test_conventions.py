"""One convention across the commands: where a plan's machine comes from, which output
names each command accepts, how ``parse`` checks axes, and how ``batch`` names what
went wrong.

- Machine: ``-m`` when given; an MCAP plan's recorded machine; else the default preset,
  the same for ``plan``, ``parse``, ``fit``, ``verify`` and ``plot`` (a CSV names no
  machine), said as ``(default)`` in ``plan``'s summary and ``verify``'s report.
- Outputs: each ``-o`` (and ``--dry-run``, ``--report``) takes only its documented
  endings, in any case; anything else is one error line, exit 2, nothing written.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from tests._contract_helpers import SAMPLES, one_error_line, run_inproc

PART = os.path.join(SAMPLES, "mill-contour.ngc")
SHORT = "G21 G90 F600\nG1 X10 Y5\nG1 X20\nM2\n"


@pytest.fixture
def short(tmp_path):
    p = tmp_path / "p.ngc"
    p.write_text(SHORT)
    return p


# -- output names ---------------------------------------------------------------------
@pytest.mark.parametrize(
    "args, out, accepted",
    [
        (["plan", "{part}", "-q", "-o"], "out.txt", (".csv", ".mcap", ".halstream", "standard output")),
        (["plan", "{part}", "-q", "-o"], "out", (".csv", ".mcap", ".halstream")),
        (["fit", "{part}", "-o"], "seg.txt", (".json",)),
        (["stream", "{part}", "-m", "generic-mill", "-q", "--dry-run"], "frames.dat", (".bin",)),
        (["batch", "{part}", "-m", "generic-mill", "-q", "--report"], "r.txt", (".json", ".csv")),
    ],
)
def test_an_unknown_output_ending_is_one_error_and_writes_nothing(tmp_path, short, args, out, accepted):
    target = tmp_path / out
    res = run_inproc(*[a.format(part=short) for a in args], target)
    line = one_error_line(res)
    assert line.startswith(f"{target}: error: ")
    for name in accepted:
        assert name in line
    assert not target.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.ngc"]  # no temporary file either


def test_plot_and_emulate_refuse_unknown_endings(tmp_path, short):
    plan = tmp_path / "p.csv"
    assert run_inproc("plan", short, "-q", "-o", plan).code == 0
    for bad in ("fig", "fig.txt"):
        line = one_error_line(run_inproc("plot", plan, "-o", tmp_path / bad))
        assert ".png" in line and ".svg" in line
        assert not (tmp_path / bad).exists()
    frames = tmp_path / "f.bin"
    assert run_inproc("stream", short, "-m", "generic-mill", "-q", "--dry-run", frames).code == 0
    line = one_error_line(run_inproc("emulate", frames, "-o", tmp_path / "e.txt"))
    assert ".csv" in line and not (tmp_path / "e.txt").exists()


def test_endings_are_case_insensitive_and_select_the_format(tmp_path, short):
    for name in ("P.CSV", "P.Mcap", "P.HALSTREAM"):
        assert run_inproc("plan", short, "-q", "-o", tmp_path / name).code == 0, name
    assert (tmp_path / "P.CSV").read_bytes().startswith(b"t,s,feed,X,Y,Z\n")
    assert (tmp_path / "P.Mcap").read_bytes().startswith(b"\x89MCAP")
    assert (tmp_path / "P.HALSTREAM").read_bytes().startswith(b"# cnc-interp plan for LinuxCNC halstreamer")


def test_output_format_rules(tmp_path):
    from cnc_interp.errors import UsageError
    from cnc_interp.outfile import output_format

    formats = {".csv": "csv", ".mcap": "mcap"}
    assert output_format("a.CsV", formats, "a plan") == "csv"
    assert output_format("-", formats, "a plan", stdout="csv") == "csv"
    assert output_format(os.devnull, formats, "a plan") == "csv"  # a device: the default
    with pytest.raises(UsageError, match="standard output"):
        output_format("-", formats, "a plan")  # no stdout for this output
    with pytest.raises(UsageError, match=r"'\.txt'.*\.csv or \.mcap"):
        output_format(str(tmp_path / "a.txt"), formats, "a plan")


# -- the machine of a plan ------------------------------------------------------------
def test_a_csv_planned_without_m_verifies_and_plots_without_m(tmp_path, short):
    plan = tmp_path / "p.csv"
    res = run_inproc("plan", short, "-o", plan)
    assert res.code == 0, res.explain()
    assert "on Generic 3-axis mill (default):" in res.err
    res = run_inproc("verify", plan)
    assert res.code == 0, res.explain()
    assert b"machine: Generic 3-axis mill (preset:generic-mill, default)" in res.out
    given = run_inproc("verify", plan, "-m", "generic-mill", "--json")
    assert json.loads(given.out)["machine"] == "Generic 3-axis mill (preset:generic-mill)"
    # the default is a real check: a machine too slow for the plan fails it
    slow = tmp_path / "slow.toml"
    slow.write_text("".join(f"[axes.{a}]\nvmax = 1.0\namax = 100.0\njmax = 1000.0\n" for a in "XYZ"))
    assert run_inproc("verify", plan, "-m", slow).code == 1


def test_plot_of_a_csv_draws_the_default_machines_limits(tmp_path, short):
    pytest.importorskip("matplotlib")
    from cnc_interp.export.plot import plot_file

    plan = tmp_path / "p.csv"
    assert run_inproc("plan", short, "-q", "-o", plan).code == 0
    a = plot_file(str(plan), None, str(tmp_path / "a.png"))
    b = plot_file(str(plan), "generic-mill", str(tmp_path / "b.png"))
    assert open(a, "rb").read() == open(b, "rb").read()


def test_verify_of_a_csv_for_another_machine_without_m_names_the_mismatch(tmp_path):
    part = tmp_path / "lathe.ngc"
    part.write_text("G21 G90 G18\nG0 X10 Z5\nG1 Z-10 F300\nG1 X20\nM2\n")
    plan = tmp_path / "lathe.csv"
    assert run_inproc("plan", part, "-m", "xz-lathe", "-q", "-o", plan).code == 0
    line = one_error_line(run_inproc("verify", plan))
    assert "no column for machine axis Y" in line
    assert run_inproc("verify", plan, "-m", "xz-lathe").code == 0


# -- parse checks axes as plan does ------------------------------------------------------
@pytest.mark.parametrize(
    "text, machine",
    [
        ("G21 G90\nG0 X1 A5\nG1 X2 F100\nM2\n", None),  # A on the default XYZ machine
        ("G21 G90\nG0 X1 Y5\nM2\n", "xz-lathe"),  # Y on an XZ lathe
    ],
)
def test_parse_fit_and_plan_reject_an_axis_the_machine_lacks_alike(tmp_path, text, machine):
    part = tmp_path / "a.ngc"
    part.write_text(text)
    m = ["-m", machine] if machine else []
    lines = {
        cmd: one_error_line(run_inproc(cmd, part, *m, *extra))
        for cmd, extra in (("parse", ()), ("fit", ()), ("plan", ("-q", "-o", tmp_path / "o.csv")))
    }
    assert lines["parse"] == lines["plan"] == lines["fit"]
    assert lines["parse"].startswith(f"{part}:2:") and "is not on this machine" in lines["parse"]


def test_parse_without_m_reads_for_the_default_machine(tmp_path):
    part = tmp_path / "xz.ngc"
    part.write_text("G21 G90 G18\nG0 X10 Z5\nG1 Z-10 F300\nM2\n")
    default = json.loads(run_inproc("parse", part, "--json").out)
    given = json.loads(run_inproc("parse", part, "-m", "generic-mill", "--json").out)
    assert default == given and default["axes"] == "XYZ"


# -- batch: errors, failures and regressions apart ------------------------------------------
def _rec(key, status="ok", cycle=1.0, worst=0.9, message=""):
    from cnc_interp.batch import FIELDS

    rec = dict.fromkeys(FIELDS)
    rec.update(key=key, status=status, cycle_time_s=cycle, worst_ratio=worst, message=message)
    rec["error_line"] = 3 if status == "error" else 0
    return rec


def test_batch_counts_errors_failures_and_regressions_apart():
    from cnc_interp.batch import compare, exit_status, format_table, summarise

    recs = [
        _rec("a.ngc"),
        _rec("b.ngc", status="error", cycle=None, worst=None, message="b.ngc:3:1: error: bad word"),
        _rec("c.ngc", status="error", cycle=None, worst=None, message="c.ngc:3:1: error: bad word"),
    ]
    c = compare(recs, None, 0.01)
    assert (c["errors"], c["failures"], c["regressions"]) == (2, 0, 0)
    assert [e["key"] for e in c["input_errors"]] == ["b.ngc", "c.ngc"]
    assert exit_status(c) == 1  # an input error still fails the batch
    text = format_table({"programs": recs, "summary": summarise(recs, 1.0), "comparison": c})
    assert "2 error(s), 0 failure(s), 0 regression(s)" in text
    assert "ERROR: b.ngc: b.ngc:3:1: error: bad word" in text and "REGRESSION" not in text

    more = recs + [_rec("d.ngc", status="violation", worst=1.5), _rec("e.ngc", status="crash", cycle=None)]
    c = compare(more, None, 0.01)
    assert (c["errors"], c["failures"], c["regressions"]) == (2, 2, 0)

    base = {r["key"]: r for r in more}
    now = [_rec("a.ngc", cycle=1.5), *more[1:3], _rec("d.ngc"), more[4]]
    c = compare(now, base, 0.01)
    # known errors and crashes are not counted again; a slowdown and a status change are
    assert (c["errors"], c["failures"], c["regressions"]) == (0, 0, 2)
    assert exit_status(c) == 1
    assert exit_status(compare(more[1:3], {r["key"]: r for r in more[1:3]}, 0.01)) == 0


# -- M-codes a machine declares no-ops --------------------------------------------------------
def _toml(tmp_path, extra: str, name: str = "m.toml"):
    p = tmp_path / name
    p.write_text("".join(f"[axes.{a}]\nvmax = 100.0\namax = 1000.0\njmax = 20000.0\n" for a in "XYZ") + extra)
    return str(p)


def test_a_declared_mcode_is_a_no_op_and_an_undeclared_one_says_how(tmp_path):
    from cnc_interp.api import load_machine, read_program
    from cnc_interp.errors import GCodeError

    with_m = "G21 G90 F600\nG1 X10 Y5\nM29 S500\nM100 P1\nG1 X20\nM2\n"
    without = "G21 G90 F600\nG1 X10 Y5\nG1 X20\nM2\n"
    m = load_machine(_toml(tmp_path, "[gcode]\nnoop_mcodes = [29, 100]\n"))
    assert m.noop_mcodes == frozenset({29, 100})
    a, b = read_program(with_m.encode(), m), read_program(without.encode(), m)
    assert len(a.items) == len(b.items)
    for x, y in zip(a.items, b.items):
        assert type(x) is type(y)
        where = "nodes" if hasattr(x, "nodes") else "position"  # nothing moves for M29, M100
        np.testing.assert_array_equal(getattr(x, where), getattr(y, where))
    plain = load_machine(_toml(tmp_path, "", "plain.toml"))
    with pytest.raises(GCodeError) as err:
        read_program(with_m.encode(), plain)
    msg = err.value.format()
    assert msg.startswith("<bytes>:3:1: error: unknown M-code M29") and "noop_mcodes = [29]" in msg
    with pytest.raises(GCodeError, match="user-defined M-code M100.*noop_mcodes = \\[100\\]"):
        read_program(b"G21\nM100\nM2\n", plain)


def test_the_cli_plans_a_part_with_declared_mcodes(tmp_path):
    part = tmp_path / "p.ngc"
    part.write_text("G21 G90 F600\nG1 X10 Y5\nM29\nG1 X20\nM2\n")
    bare = tmp_path / "bare.ngc"
    bare.write_text("G21 G90 F600\nG1 X10 Y5\nG1 X20\nM2\n")
    m = _toml(tmp_path, "[gcode]\nnoop_mcodes = [29]\n")
    assert run_inproc("plan", part, "-m", m, "-q", "-o", tmp_path / "a.csv").code == 0
    assert run_inproc("plan", bare, "-m", m, "-q", "-o", tmp_path / "b.csv").code == 0
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()
    assert run_inproc("parse", part, "-m", m).code == 0
    line = one_error_line(run_inproc("parse", part))
    assert line.startswith(f"{part}:3:1: error: unknown M-code M29")
    assert "M29" in run_inproc("machines", m).out.decode()


@pytest.mark.parametrize(
    "extra, match, line",
    [
        ("[gcode]\nnoop_mcodes = [2]\n", "M2 has a meaning of its own", 14),
        ("[gcode]\nnoop_mcodes = [6, 100]\n", "M6 has a meaning of its own", 14),
        ("[gcode]\nnoop_mcodes = [-1]\n", "out of range", 14),
        ("[gcode]\nnoop_mcodes = [29.5]\n", "list of M-code numbers", 14),
        ('[gcode]\nnoop_mcodes = "M29"\n', "list of M-code numbers", 14),
        ("[gcode]\nnoop = [29]\n", "unknown key 'noop' in \\[gcode\\]", 14),
    ],
)
def test_bad_noop_mcodes_are_machine_errors_at_their_line(tmp_path, extra, match, line):
    from cnc_interp.errors import MachineError
    from cnc_interp.machine.load import load_machine

    with pytest.raises(MachineError, match=match) as err:
        load_machine(_toml(tmp_path, extra))
    assert err.value.location.line == line


def test_a_machine_built_in_python_is_checked_too():
    from dataclasses import replace

    from cnc_interp.errors import MachineError
    from cnc_interp.machine.load import load_machine

    m = load_machine("generic-mill")
    assert replace(m, noop_mcodes=[29]).noop_mcodes == frozenset({29})
    with pytest.raises(MachineError, match="M30 has a meaning"):
        replace(m, noop_mcodes=[30])


def test_interpreted_mcodes_match_the_readers_tables():
    from cnc_interp.constants import MCODES_INTERPRETED
    from cnc_interp.gcode.codes import M6, M_NOOP, M_STOPS, M_UNSUPPORTED

    assert MCODES_INTERPRETED == M_NOOP | set(M_STOPS) | {M6} | set(M_UNSUPPORTED)


def test_an_ini_declares_its_user_mcodes_by_their_files(tmp_path):
    from cnc_interp.api import load_machine, read_program
    from cnc_interp.errors import GCodeError

    mcodes = tmp_path / "mcodes"
    mcodes.mkdir()
    for name in ("M101", "M150", "m102", "M200", "notes.txt"):
        (mcodes / name).write_text("#!/bin/sh\nexit 0\n")
    (tmp_path / "prefix").mkdir()
    (tmp_path / "prefix" / "M199").write_text("#!/bin/sh\n")
    ini = tmp_path / "m.ini"
    ini.write_text(
        "[EMCMOT]\nSERVO_PERIOD = 1000000\n[TRAJ]\nCOORDINATES = X Y Z\nLINEAR_UNITS = mm\n"
        "[RS274NGC]\nUSER_M_PATH = mcodes:missing\n[DISPLAY]\nPROGRAM_PREFIX = prefix\n"
        + "".join(f"[AXIS_{a}]\nMAX_VELOCITY = 100\nMAX_ACCELERATION = 1000\n" for a in "XYZ")
    )
    m = load_machine(str(ini))
    # LinuxCNC runs M100-M199 named exactly so; m102 (lower case) and M200 are not user M-codes
    assert m.noop_mcodes == frozenset({101, 150, 199})
    read_program(b"G21\nM101\nM150 P1 Q2\nM199\nM2\n", m)
    with pytest.raises(GCodeError, match="user-defined M-code M102"):
        read_program(b"G21\nM102\nM2\n", m)

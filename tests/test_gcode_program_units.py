"""What a LinuxCNC machine gives the G-code reader: the units a program starts in
(``[TRAJ] LINEAR_UNITS``: an inch machine reads a program without G20/G21 in inches) and
the path speed limit (``[TRAJ] MAX_LINEAR_VELOCITY``: every feed and rapid capped at it),
through every entry point that reads a program for a machine."""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose

import cnc_interp as ci
from cnc_interp.constants import MM_PER_INCH
from cnc_interp.gcode import read_program
from cnc_interp.gcode.stream import iter_program
from cnc_interp.pipeline import summarise_part

from ._contract_helpers import run_inproc

#: a small XYZA LinuxCNC machine; LINEAR_UNITS and the [TRAJ] extra line are filled in
INI = """\
[EMC]
MACHINE = units test
[TRAJ]
COORDINATES = X Y Z A
LINEAR_UNITS = {units}
ANGULAR_UNITS = degree
{extra}
[AXIS_X]
MAX_VELOCITY = {v}
MAX_ACCELERATION = {a}
[AXIS_Y]
MAX_VELOCITY = {v}
MAX_ACCELERATION = {a}
[AXIS_Z]
MAX_VELOCITY = {v}
MAX_ACCELERATION = {a}
[AXIS_A]
MAX_VELOCITY = 90
MAX_ACCELERATION = 900
"""


def machine_file(tmp_path, units: str = "inch", extra: str = "", name: str = "m.ini") -> str:
    # limits of 4 in/s, 40 in/s^2 (or mm) : any program here is read, not planned
    p = tmp_path / name
    p.write_text(INI.format(units=units, extra=extra, v=4, a=40))
    return str(p)


def end_of(program) -> np.ndarray:
    return program.runs[-1].nodes[-1]


def test_inch_machine_reads_a_program_without_g20_g21_in_inches(tmp_path):
    m = ci.load_machine(machine_file(tmp_path))
    assert m.program_units == "inch"
    p = ci.read_program("G1 X1 Y-2 F10\nG91 G1 Z0.5\n", machine=m)
    assert_allclose(end_of(p), [MM_PER_INCH, -2 * MM_PER_INCH, 0.5 * MM_PER_INCH, 0.0])
    assert_allclose(p.runs[-1].feed_mm_s, 10 * MM_PER_INCH / 60)  # F10 is 10 in/min
    # a G21 in the program switches to mm, before its coordinates, as on LinuxCNC
    metric = ci.read_program("G21 G1 X1 F10\n", machine=m)
    assert_allclose(end_of(metric), [1, 0, 0, 0])
    assert_allclose(metric.runs[0].feed_mm_s, 10 / 60)
    # a rotary-only move's F stays in deg/min
    assert_allclose(ci.read_program("G1 A10 F10\n", machine=m).runs[0].feed_mm_s, 10 / 60)


def test_inch_start_converts_offsets_as_g20(tmp_path):
    m = ci.load_machine(machine_file(tmp_path))
    p = ci.read_program("G10 L2 P1 X1\nG54 G0 X0\nG1 X1 F10\n", machine=m)
    assert_allclose(end_of(p)[0], 2 * MM_PER_INCH)  # the G54 offset is 1 inch too
    mixed = "G10 L2 P1 X1\nG21\nG54 G0 X0\n"  # set in inches, read after a switch to mm
    assert_allclose(end_of(ci.read_program(mixed, machine=m))[0], MM_PER_INCH)


def test_mm_machine_and_presets_read_mm(tmp_path):
    m = ci.load_machine(machine_file(tmp_path, units="mm"))
    assert m.program_units == "mm"
    assert_allclose(end_of(ci.read_program("G1 X1 F10\n", machine=m))[0], 1.0)
    assert_allclose(end_of(ci.read_program("G20 G1 X1 F10\n", machine=m))[0], MM_PER_INCH)
    assert_allclose(end_of(ci.read_program("G1 X1 F10\n", machine="generic-mill"))[0], 1.0)
    # the reader itself starts in mm unless told otherwise
    assert_allclose(end_of(read_program("G1 X1 F10\n", "t"))[0], 1.0)
    assert_allclose(end_of(read_program("G1 X1 F10\n", "t", program_units="inch"))[0], MM_PER_INCH)
    with pytest.raises(ci.CncInterpError, match="bad program units 'cm'"):
        read_program("G1 X1 F10\n", "t", program_units="cm")


def test_stream_and_parse_summary_read_the_machines_units(tmp_path):
    m = ci.load_machine(machine_file(tmp_path))
    text = "G0 X1\nG1 Y2 F20\n"
    whole = ci.read_program(text, machine=m)
    streamed = list(iter_program(text, "t", m.axes, m.start, program_units=m.program_units))
    assert [it.kind for it in streamed] == [r.kind for r in whole.runs]
    for a, b in zip(streamed, whole.runs):
        assert_allclose(a.nodes, b.nodes)
        assert_allclose(a.feed_mm_s, b.feed_mm_s)
    part = tmp_path / "p.ngc"
    part.write_text(text)
    summary = summarise_part(str(part), machine_file(tmp_path))
    assert_allclose(summary["bounds"]["X"], [0.0, MM_PER_INCH])
    assert_allclose(summary["bounds"]["Y"], [0.0, 2 * MM_PER_INCH])


def test_machines_command_shows_the_program_units_and_path_speed(tmp_path):
    inch = machine_file(tmp_path, extra="MAX_LINEAR_VELOCITY = 3")
    r = run_inproc("machines", inch)
    assert r.code == 0, r.explain()
    out = r.out.decode()
    assert "  program units inch: a program without G20/G21 is read in inches (G20)\n" in out
    assert f"  path speed limit {3 * MM_PER_INCH:g} mm/s over the linear axes: binds on every linear move" in out
    d = json.loads(run_inproc("machines", inch, "--json").out)
    assert d["program_units"] == "inch" and d["max_path_mm_s"] == pytest.approx(3 * MM_PER_INCH)
    mm = run_inproc("machines", machine_file(tmp_path, units="mm", name="mm.ini")).out.decode()
    assert "  program units mm: a program without G20/G21 is read in mm (G21)\n" in mm
    assert "path speed limit" not in mm
    # where the limit binds: along one axis, only on diagonals, never
    for cap, where in ((5, "binds on diagonal moves only"), (7, "never binds")):
        ini = machine_file(tmp_path, "mm", f"MAX_LINEAR_VELOCITY = {cap}", f"cap{cap}.ini")
        assert where in run_inproc("machines", ini).out.decode()


def test_path_speed_limit_caps_feeds_and_rapids(tmp_path):
    m = ci.load_machine(machine_file(tmp_path, units="mm", extra="MAX_LINEAR_VELOCITY = 3"))
    assert m.max_path_mm_s == 3.0
    p = ci.read_program("G0 X10 A5\nG0 A20\nG1 X0 F600\nG1 Y1 F60\nG1 A30 F600\n", machine=m)
    rapid, feed = p.runs
    assert rapid.kind == "rapid" and feed.kind == "feed"
    assert_allclose(rapid.feed_mm_s, [3.0, 3.0, np.inf])  # the rotary-only rapid keeps the axes' limits
    assert_allclose(feed.feed_mm_s, [3.0, 3.0, 1.0, 10.0])  # 600 mm/min capped; 60 below; A in deg/s
    # the stream caps the same
    streamed = [it for it in iter_program("G0 X10\nG1 X0 F600\n", "t", m.axes, max_path_mm_s=3.0)]
    assert [float(it.feed_mm_s[-1]) for it in streamed] == [3.0, 3.0]
    # without the key: rapids infinite, feeds as programmed
    free = ci.load_machine(machine_file(tmp_path, units="mm", name="free.ini"))
    assert free.max_path_mm_s is None
    q = ci.read_program("G0 X10\nG1 X0 F600\n", machine=free)
    assert np.isinf(q.runs[0].feed_mm_s).all() and (q.runs[1].feed_mm_s == 10.0).all()
    # nor with a limit that cannot bind: at or above the axes' vmax combined (6.93 mm/s)
    never = ci.load_machine(machine_file(tmp_path, units="mm", extra="MAX_LINEAR_VELOCITY = 7", name="never.ini"))
    assert never.max_path_mm_s == 7.0 and never.path_speed_cap_mm_s is None
    q = ci.read_program("G0 X10 Y10 Z10\nG1 X0 F600\n", machine=never)
    assert np.isinf(q.runs[0].feed_mm_s).all() and (q.runs[1].feed_mm_s == 10.0).all()


def test_plan_and_estimate_read_the_machines_units(tmp_path):
    # the streamed commands (pipeline.stream_plan) start in the machine's units too
    ini = machine_file(tmp_path)
    part = tmp_path / "p.ngc"
    part.write_text("G1 X1 F600\n")
    out = tmp_path / "plan.csv"
    r = run_inproc("plan", part, "-m", ini, "-o", out, "-q")
    assert r.code == 0, r.explain()
    last = np.loadtxt(out, delimiter=",", skiprows=1)[-1]
    assert_allclose(last[3:], [MM_PER_INCH, 0, 0, 0])
    est = json.loads(run_inproc("estimate", part, "-m", ini, "--json").out)
    g21 = tmp_path / "g21.ngc"
    g21.write_text("G21 G1 X1 F600\n")
    metric = json.loads(run_inproc("estimate", g21, "-m", ini, "--json").out)
    assert est["cycle_time_s"] > 2 * metric["cycle_time_s"]  # 25.4 mm at 600 in/min against 1 mm at 600 mm/min

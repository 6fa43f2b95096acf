"""The example machine files in ``examples/machines/``: each loads with the values its
comments give, ``cnc-interp machines FILE`` prints how it was read (limits, start,
kinematics, the defaults applied), and each plans a short program within its limits."""

from __future__ import annotations

import glob
import json
import os
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose

import cnc_interp as ci
from cnc_interp.machine.kinematics import make_kinematics

from ._contract_helpers import run_inproc
from .conftest import EXAMPLES

MACHINES = os.path.join(EXAMPLES, "machines")

#: file -> what it must load as: name, axes, dt (s), kinematics, (vmax, amax, jmax) per
#: axis (mm or deg per s, s², s³), start, tol (mm), the keys of Machine.defaults
EXPECTED = {
    "mill-3axis.toml": dict(
        name="Small 3-axis VMC",
        axes="XYZ",
        dt_s=0.001,
        kinematics="trivial",
        limits={"X": (250, 3000, 60000), "Y": (250, 3000, 60000), "Z": (200, 2500, 50000)},
        start={"X": 0, "Y": 0, "Z": 50},
        tol_mm=0.005,
        defaults=set(),
    ),
    "router.ini": dict(
        name="Gantry router 1250x2500",
        axes="XYZ",
        dt_s=0.001,
        kinematics="trivial",
        # no MAX_JERK: jmax = 10/s x amax
        limits={"X": (400, 1500, 15000), "Y": (400, 1200, 12000), "Z": (150, 1000, 10000)},
        start={"X": 0, "Y": 0, "Z": 0},
        tol_mm=None,
        defaults={"jmax.X", "jmax.Y", "jmax.Z", "start", "tol"},
    ),
    "mill-4axis-xyza.toml": dict(
        name="Mill with A rotary table",
        axes="XYZA",
        dt_s=0.001,
        kinematics="trivial",
        limits={"X": (200, 2000, 40000), "Y": (200, 2000, 40000), "Z": (150, 1500, 30000), "A": (120, 600, 6000)},
        start={"X": 0, "Y": 0, "Z": 50, "A": 0},
        tol_mm=None,
        defaults={"start", "tol"},
    ),
    "lathe-xz.toml": dict(
        name="Small CNC lathe",
        axes="XZ",
        dt_s=0.001,
        kinematics="trivial",
        limits={"X": (100, 1500, 30000), "Z": (150, 2000, 40000)},
        start={"X": 25, "Z": 10},
        tol_mm=0.002,
        defaults=set(),
    ),
    "5axis-xyzac-trt.toml": dict(
        name="5-axis trunnion VMC",
        axes="XYZAC",
        dt_s=0.002,
        kinematics="xyzac-trt",
        limits={
            "X": (500, 2500, 25000),
            "Y": (500, 2500, 25000),
            "Z": (500, 2000, 20000),
            "A": (90, 300, 1800),
            "C": (180, 600, 6000),
        },
        start={"X": 0, "Y": 0, "Z": 100, "A": 0, "C": 0},
        tol_mm=0.005,
        defaults={"start"},
    ),
}

#: file -> (a short program in its axes, its last programmed point in machine order)
PROGRAMS = {
    "mill-3axis.toml": (
        "G17 G21 G90 G94\nG0 X0 Y0 Z1\nG1 Z-0.5 F300\nG1 X3 F1200\nG2 X5 Y-2 I0 J-2\nG1 Y-4\nM2\n",
        [5, -4, -0.5],
    ),
    "router.ini": (
        "G17 G21 G90 G94\nG0 X0 Y0 Z1\nG1 Z-0.5 F300\nG1 X3 F3000\nG2 X5 Y-2 I0 J-2\nG1 Y-4\nM2\n",
        [5, -4, -0.5],
    ),
    "mill-4axis-xyza.toml": (
        # an engraving pass on the cylinder: X with A, then A alone (F in deg/min)
        "G17 G21 G90 G94\nG0 X0 Y0 Z1 A0\nG1 Z-0.2 F300\nG1 X3 A10 F600\nG1 A20 F1800\nG2 X5 Y-2 I0 J-2 F600\nM2\n",
        [5, -2, -0.2, 20],
    ),
    "lathe-xz.toml": (
        # samples/gcode/lathe-profile.ngc's first features: face, chamfer, turn, fillet
        "G18 G21 G90 G94\nG0 X5 Z1\nG1 Z0 F120\nG1 X6 Z-1\nG1 Z-4\nG2 X8 Z-6 I2 K0\nG1 X9\nG0 X12\nM2\n",
        [12, -6],
    ),
    "5axis-xyzac-trt.toml": (
        "G17 G21 G90 G94\nG0 X0 Y0 Z5 A0 C0\nG1 Z1 F600\nG1 X2 Y1 Z0.5 A3 C5\nG1 X3 Y2 A5 C10\nM2\n",
        [3, 2, 0.5, 5, 10],
    ),
}

FILES = sorted(os.path.basename(p) for p in glob.glob(os.path.join(MACHINES, "*")))


def path_of(name: str) -> str:
    return os.path.join(MACHINES, name)


def test_every_example_machine_is_listed_here():
    assert FILES == sorted(EXPECTED) == sorted(PROGRAMS)


@pytest.mark.parametrize("name", FILES)
def test_example_loads_with_the_values_it_documents(name):
    want = EXPECTED[name]
    m = ci.load_machine(path_of(name))
    assert (m.name, m.axes, m.kinematics) == (want["name"], want["axes"], want["kinematics"])
    assert m.dt_s == want["dt_s"] and m.tol_mm == want["tol_mm"] and m.source == path_of(name)
    limits = np.array([want["limits"][a] for a in m.axes], dtype=float).T
    assert_allclose(m.limits(), limits, rtol=0, atol=0)
    assert_allclose(m.start, [want["start"][a] for a in m.axes], rtol=0, atol=0)
    assert set(m.defaults) == want["defaults"]


@pytest.mark.parametrize("name", FILES)
def test_example_says_what_it_models_and_gives_units(name):
    text = open(path_of(name), encoding="utf-8").read()
    lines = text.splitlines()
    assert lines[0].startswith("# A "), "the file opens with a comment saying what it models"
    if name.endswith(".toml"):
        for line in lines:  # every limit with its unit in a comment
            m = re.match(r"\s*(vmax|amax|jmax)\s*=", line)
            if m:
                power = {"vmax": "/s", "amax": "/s^2", "jmax": "/s^3"}[m.group(1)]
                assert re.search(rf"#\s*(mm|deg){re.escape(power)}(\s|$)", line), line
    else:  # the INI: every axis section's limits under a comment with their units
        comments = re.findall(r"^\[AXIS_\w\]\n(#[^\n]*)\n", text, re.M)
        assert len(comments) == len(re.findall(r"^\[AXIS_\w\]", text, re.M)) == 3
        for comment in comments:
            assert "mm/s" in comment and "mm/s^2" in comment, comment


def test_trt_example_declares_its_pivot():
    m = ci.load_machine(path_of("5axis-xyzac-trt.toml"))
    assert m.kinematics_params == {
        "x_rot_point": 0.0,
        "y_rot_point": 0.0,
        "z_rot_point": -80.0,
        "y_offset": 0.0,
        "z_offset": 0.0,
        "tool_offset": 0.0,
    }


# -- cnc-interp machines FILE -----------------------------------------------------------------
def _row(axis: str, lim: tuple[float, float, float], unit: str) -> str:
    # the limits table's row as `machines` prints it
    v, a, j = lim
    return f"{axis:>4} {v:>10.6g} {a:>10.6g} {j:>10.6g}  {unit}/s, {unit}/s^2, {unit}/s^3"


@pytest.mark.parametrize("name", FILES)
def test_machines_file_prints_how_it_was_read(cli, name):
    want = EXPECTED[name]
    r = cli("machines", path_of(name))
    assert r.exit_code == 0, r.output
    out = r.output
    kind = "LinuxCNC INI file" if name.endswith(".ini") else "TOML machine file"
    assert out.startswith(f"{path_of(name)}: {want['name']} ({kind})\n")
    assert f"axes {want['axes']}, dt {want['dt_s'] * 1000:g} ms, kinematics {want['kinematics']}\n" in out
    for axis, lim in want["limits"].items():
        assert _row(axis, lim, "deg" if axis in "ABC" else "mm") in out, (axis, out)
    unit = {a: "deg" if a in "ABC" else "mm" for a in want["axes"]}
    assert "start " + ", ".join(f"{a} {v:g} {unit[a]}" for a, v in want["start"].items()) + "\n" in out
    assert ("tol not set\n" if want["tol_mm"] is None else f"tol {want['tol_mm']:g} mm\n") in out
    if want["defaults"]:
        listed = out.split("defaults applied (not given by the source):\n")[1].splitlines()
        assert {line.split(":")[0].strip() for line in listed} == want["defaults"]
    else:
        assert out.rstrip().endswith("defaults applied: none")


def test_machines_file_names_the_ini_jerk_default_and_the_pivot(cli):
    out = cli("machines", path_of("router.ini")).output
    assert "jmax.X: 10/s x amax = 15000 mm/s^3 (no MAX_JERK in [AXIS_X])" in out
    assert "jmax.Y: 10/s x amax = 12000 mm/s^3 (no MAX_JERK in [AXIS_Y])" in out
    assert "start: 0 on every axis" in out
    out = cli("machines", path_of("5axis-xyzac-trt.toml")).output
    assert "kinematics parameters: x_rot_point 0 mm, y_rot_point 0 mm, z_rot_point -80 mm," in out
    assert "start: 0 on X, Y, A, C (not in the [start] table)" in out


@pytest.mark.parametrize("name", FILES)
def test_machines_file_json(cli, name):
    want = EXPECTED[name]
    r = cli("machines", path_of(name), "--json")
    assert r.exit_code == 0, r.output
    d = json.loads(r.output)
    assert d["format"] == ("ini" if name.endswith(".ini") else "toml") and d["spec"] == path_of(name)
    assert (d["name"], d["axes"], d["dt_s"], d["kinematics"], d["tol_mm"]) == (
        want["name"],
        want["axes"],
        want["dt_s"],
        want["kinematics"],
        want["tol_mm"],
    )
    assert {a: (lim["vmax"], lim["amax"], lim["jmax"]) for a, lim in d["limits"].items()} == want["limits"]
    assert d["start"] == want["start"] and set(d["defaults"]) == want["defaults"]


def test_machines_preset_name_and_the_list(cli):
    r = cli("machines", "xz-lathe")
    assert r.exit_code == 0, r.output
    assert r.output.startswith("xz-lathe: XZ lathe (built-in preset) - 2-axis XZ lathe, 1 kHz servo\n")
    assert _row("Z", (100, 1500, 30000), "mm") in r.output
    d = json.loads(cli("machines", "mikron-ucp710", "--json").output)
    assert d["format"] == "preset" and d["kinematics"] == "xyzac-trt" and d["limits"]["X"]["vmax"] == 500.0
    assert set(d["defaults"]) == {"start", "tol"} | {f"kinematics.{k}" for k in d["kinematics_params"]}
    # without an argument: the presets, as before
    listing = json.loads(cli("machines", "--json").output)
    assert [row["preset"] for row in listing] == ["generic-mill", "mikron-ucp710", "xz-lathe"]
    assert "generic-mill (default): Generic 3-axis mill" in cli("machines").output


def test_defaults_name_everything_a_file_leaves_out(tmp_path, cli):
    toml = tmp_path / "bare.toml"
    toml.write_text(
        'kinematics = "xyzac-trt"\n' + "".join(f"[axes.{a}]\nvmax = 1\namax = 2\njmax = 3\n" for a in "XYZAC")
    )
    m = ci.load_machine(str(toml))
    assert set(m.defaults) == {"name", "dt", "start", "tol"} | {f"kinematics.{k}" for k in m.kinematics_params}
    assert m.defaults["name"] == "'bare', the file name (no name key)"
    assert m.defaults["dt"] == "0.001 s (no dt key)"
    ini = tmp_path / "bare.ini"
    ini.write_text(
        "[TRAJ]\nCOORDINATES = X A\n[AXIS_X]\nMAX_VELOCITY = 10\nMAX_ACCELERATION = 100\nMAX_JERK = 5000\n"
        "[AXIS_A]\nMAX_VELOCITY = 1\nMAX_ACCELERATION = 2\n"
    )
    m = ci.load_machine(str(ini))
    assert m.defaults == {
        "linear_units": "mm (no [TRAJ] LINEAR_UNITS)",
        "angular_units": "degree (no [TRAJ] ANGULAR_UNITS)",
        "jmax.A": "10/s x amax = 20 deg/s^3 (no MAX_JERK in [AXIS_A])",
        "dt": "0.001 s (no [EMCMOT] SERVO_PERIOD)",
        "name": "'bare', the file name (no [EMC] MACHINE)",
        "kinematics": "trivial (no [KINS] KINEMATICS)",
        "start": "0 on every axis (an INI gives no start position)",
        "tol": "none: the fit's default tolerance or --tol (an INI gives no tolerance)",
    }
    assert m.jmax.tolist() == [5000.0, 20.0]
    out = cli("machines", ini).output
    assert "    jmax.A: 10/s x amax = 20 deg/s^3 (no MAX_JERK in [AXIS_A])\n" in out and "jmax.X" not in out


@pytest.mark.parametrize("json_flag", [(), ("--json",)])
def test_machines_bad_file_is_one_error_line(tmp_path, json_flag):
    bad = tmp_path / "bad.toml"
    text = open(path_of("mill-3axis.toml"), encoding="utf-8").read()
    bad.write_text(text.replace("amax = 2500.0", "amax = -2500.0"))
    line = text.splitlines().index(next(x for x in text.splitlines() if x.startswith("amax = 2500.0"))) + 1
    r = run_inproc("machines", bad, *json_flag)
    assert r.code == 2 and r.out == b""
    assert r.err.count("\n") == 1 and "Traceback" not in r.err
    assert re.match(rf"{re.escape(str(bad))}:{line}:1: error: axis Z amax \(mm/s\^2\) must be positive", r.err), r.err
    bad_ini = tmp_path / "bad.ini"
    text = open(path_of("router.ini"), encoding="utf-8").read()
    bad_ini.write_text(text.replace("MAX_VELOCITY = 150.0", ""))
    line = text.splitlines().index("[AXIS_Z]") + 1  # the section without the key
    r = run_inproc("machines", bad_ini, *json_flag)
    assert (r.code, r.out) == (2, b"")
    assert r.err == f"{bad_ini}:{line}:1: error: [AXIS_Z] has no MAX_VELOCITY: '[AXIS_Z]'\n"
    r = run_inproc("machines", tmp_path / "missing.toml", *json_flag)
    assert (r.code, r.err) == (2, f"{tmp_path / 'missing.toml'}: error: machine file not found\n")


# -- a short plan on each ---------------------------------------------------------------------
@pytest.mark.parametrize("name", FILES)
def test_example_plans_a_short_program_within_its_limits(name):
    text, last = PROGRAMS[name]
    m = ci.load_machine(path_of(name))
    res = ci.run(text, m, name=f"{name}.ngc")
    traj, report = res.trajectory, res.report
    assert res.ok and report.worst_ratio <= 1 + 1e-9 and not report.nan_found
    assert traj.axes == m.axes and traj.dt_s == m.dt_s
    assert_allclose(report.limits, m.limits().T, rtol=0, atol=0)  # checked against the file's limits
    assert_allclose(traj.q[0], m.start, atol=1e-9)  # from rest at the file's start
    end = make_kinematics(m).to_joints(np.asarray([last], dtype=float))[0]
    assert_allclose(traj.q[-1], end, atol=1e-6)  # to rest on the last programmed point
    assert 0.1 < traj.duration_s < 10.0
    # the plan uses the machine: some limit is reached (the planners run at the limits)
    assert report.worst_ratio > 0.5

"""Machine loading: TOML files, LinuxCNC INI files, presets, and their errors."""

import glob
import math
import os

import numpy as np
import pytest
from numpy.testing import assert_allclose

from .conftest import CORPUS

from cnc_interp.constants import MM_PER_INCH
from cnc_interp.errors import MachineError
from cnc_interp.machine.load import (
    DEFAULT_JERK_PER_ACCEL_1_S,
    DEFAULT_PRESET,
    PRESETS,
    format_presets,
    load_machine,
    preset_table,
)

#: LinuxCNC's sample configurations in the corpus (conftest's path, or CNC_CORPUS)
CORPUS_CONFIGS = os.path.join(CORPUS, "configs")

GOOD = """\
name = "Test mill"
dt = 0.002
kinematics = "trivial"
tol = 0.005
[start]
Z = 50.0
[axes.X]
vmax = 500.0
amax = 2500.0
jmax = 5000.0
[axes.Y]
vmax = 400.0
amax = 2000
jmax = 4000.0
[axes.Z]
vmax = 300.0
amax = 1500.0
jmax = 3000.0
"""


def write(tmp_path, text, name="m.toml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def test_toml_good(tmp_path):
    m = load_machine(write(tmp_path, GOOD))
    assert m.name == "Test mill" and m.axes == "XYZ" and m.dt_s == 0.002
    assert_allclose(m.vmax, [500, 400, 300])
    assert_allclose(m.amax, [2500, 2000, 1500])
    assert_allclose(m.jmax, [5000, 4000, 3000])
    assert_allclose(m.start, [0, 0, 50])
    assert m.tol_mm == 0.005 and m.kinematics == "trivial"
    d = m.to_dict()
    assert d["limits"]["Y"]["amax"] == 2000.0 and d["start"]["Z"] == 50.0


def test_toml_axis_order_is_machine_order(tmp_path):
    text = "[axes.Z]\nvmax=1\namax=1\njmax=1\n[axes.X]\nvmax=2\namax=2\njmax=2\n"
    m = load_machine(write(tmp_path, text))
    assert m.axes == "ZX"
    assert_allclose(m.vmax, [1, 2])


def test_kinematics_table_form(tmp_path):
    text = '[kinematics]\ntype = "xyzac-trt"\nz-offset = 12.5\n' + "".join(
        f"[axes.{a}]\nvmax=100\namax=1000\njmax=10000\n" for a in "XYZAC"
    )
    m = load_machine(write(tmp_path, text))
    assert m.kinematics == "xyzac-trt"
    assert m.kinematics_params["z_offset"] == 12.5 and m.kinematics_params["y_offset"] == 0.0


@pytest.mark.parametrize(
    "text,line,fragment",
    [
        # (file text, expected line, message fragment)
        ("dt = 0.001\n", 0, "no [axes.X]"),
        (GOOD.replace("amax = 2000\n", "amax = -2000\n"), 13, "must be positive"),
        (GOOD.replace("jmax = 3000.0", "jmax = 0"), 18, "must be positive"),
        (GOOD.replace("vmax = 400.0", "vmax = nan"), 12, "must be finite"),
        (GOOD.replace("vmax = 400.0", "vmax = inf"), 12, "must be finite"),
        (GOOD.replace("vmax = 400.0", 'vmax = "fast"'), 12, "must be a number"),
        (GOOD.replace("jmax = 4000.0", "jerk = 4000.0"), 14, "unknown key 'jerk'"),
        (GOOD.replace("jmax = 4000.0\n", ""), 11, "has no jmax"),
        (GOOD.replace("tol = 0.005", "tolerance = 0.005"), 4, "unknown key 'tolerance'"),
        (GOOD.replace('kinematics = "trivial"', 'kinematics = "scara"'), 3, "unknown kinematics 'scara'"),
        (GOOD.replace("dt = 0.002", "dt = 0"), 2, "dt"),
        (GOOD.replace("dt = 0.002", "dt = 6"), 2, "seconds"),
        (GOOD.replace("dt = 0.002", "dt = -1e-3"), 2, "must be positive"),
        (GOOD.replace("[axes.Y]", "[axes.x]"), 11, "defined twice"),
        (GOOD.replace("[axes.Y]", "[axes.Q]"), 11, "unknown axis 'Q'"),
        (GOOD.replace("Z = 50.0", "B = 50.0"), 6, "not an axis"),
        (GOOD.replace('kinematics = "trivial"', 'kinematics = "xyzac-trt"'), 3, "missing A, C"),
        (GOOD.replace("[axes.Y]", "[axes.X]"), 11, "TOML"),  # duplicate table: TOML error
        (GOOD.replace("amax = 2000", "amax = = 2000"), 13, "invalid TOML"),
    ],
)
def test_toml_errors_have_locations(tmp_path, text, line, fragment):
    path = write(tmp_path, text)
    with pytest.raises(MachineError) as info:
        load_machine(path)
    err = info.value
    assert fragment in err.message, err.format()
    assert err.location.file == path
    assert err.location.line == line, err.format()
    assert err.format().startswith(f"{path}:{line}:" if line else f"{path}: error")


def test_unknown_spec():
    with pytest.raises(MachineError, match="no machine file or preset named 'nope'"):
        load_machine("nope")
    with pytest.raises(MachineError, match="not found"):
        load_machine("/no/such/machine.toml")


def test_presets_valid_and_listed():
    assert DEFAULT_PRESET == "generic-mill"
    for name in PRESETS:
        m = load_machine(name)
        assert m.source == f"preset:{name}"
        for arr in (m.vmax, m.amax, m.jmax):
            assert np.all(np.isfinite(arr)) and np.all(arr > 0)
        assert 0 < m.dt_s <= 0.01
    table = preset_table()
    assert [r["preset"] for r in table] == sorted(PRESETS)
    text = format_presets(table)
    for name in PRESETS:
        assert name in text
    import json

    json.dumps(table, allow_nan=False)


def test_mikron_preset_is_paper_table1():
    m = load_machine("mikron-ucp710")
    assert m.axes == "XYZAC" and m.dt_s == 0.006 and m.kinematics == "xyzac-trt"
    assert_allclose(m.vmax, [500, 500, 500, 15 * 6, 20 * 6])  # 30 m/min; rpm -> deg/s
    assert_allclose(m.amax, [2500, 3000, 2100, 0.83 * 360, 0.83 * 360])
    assert_allclose(m.jmax, [5000, 5000, 50000, 5 * 360, 100 * 360])
    assert all(v == 0.0 for v in m.kinematics_params.values())
    assert load_machine("xz-lathe").axes == "XZ"


@pytest.mark.corpus
def test_corpus_ini_files_load():
    paths = sorted(glob.glob(os.path.join(CORPUS_CONFIGS, "*.ini")))
    assert len(paths) >= 4
    for p in paths:
        m = load_machine(p)
        assert m.dt_s == 0.001
        assert np.all(m.vmax > 0) and np.all(m.jmax > 0)


@pytest.mark.corpus
def test_ini_units_inch_to_mm():
    m = load_machine(os.path.join(CORPUS_CONFIGS, "XYZ.ini"))
    assert m.axes == "XYZA" and m.name == "LinuxCNC-Circular-Blend-Tester-XYZ"
    assert_allclose(m.vmax, [8 * MM_PER_INCH] * 3 + [25.0])  # A stays in deg/s
    assert_allclose(m.amax, [30 * MM_PER_INCH] * 3 + [800.0])
    assert_allclose(m.jmax, DEFAULT_JERK_PER_ACCEL_1_S * m.amax)
    xz = load_machine(os.path.join(CORPUS_CONFIGS, "XZ.ini"))  # old [AXIS_0], [AXIS_2] numbering
    assert xz.axes == "XZ"
    assert_allclose(xz.vmax, [8 * MM_PER_INCH] * 2)
    mm = load_machine(os.path.join(CORPUS_CONFIGS, "axis_mm.ini"))
    assert_allclose(mm.vmax, [30.48] * 3)  # already mm
    nine = load_machine(os.path.join(CORPUS_CONFIGS, "9axis.ini"))
    assert nine.axes == "XYZABCUVW"
    assert_allclose(nine.vmax, [1.2 * MM_PER_INCH] * 3 + [90.0] * 3 + [1.2 * MM_PER_INCH] * 3)


INI = """\
[EMC]
MACHINE = tiny
[EMCMOT]
SERVO_PERIOD = 500000
[TRAJ]
COORDINATES = X Y Y Z C
LINEAR_UNITS = mm
ANGULAR_UNITS = radian
[AXIS_X]
MAX_VELOCITY = 10
MAX_ACCELERATION = 100
MAX_JERK = 1000
[AXIS_Y]
MAX_VELOCITY = 10
MAX_ACCELERATION = 100
[JOINT_3]
MAX_VELOCITY = 20
MAX_ACCELERATION = 200
[AXIS_C]
MAX_VELOCITY = 1
MAX_ACCELERATION = 2
"""


def test_ini_modern_sections_jerk_gantry_radians(tmp_path):
    m = load_machine(write(tmp_path, INI, "t.ini"))
    assert m.axes == "XYZC" and m.dt_s == 0.0005 and m.name == "tiny"
    assert_allclose(m.jmax[:2], [1000, 1000])  # X explicit, Y default 10*amax
    assert_allclose(m.vmax[2], 20)  # Z from JOINT_3 (gantry: X Y Y Z)
    assert_allclose(m.vmax[3], math.degrees(1))  # rad/s -> deg/s


@pytest.mark.parametrize(
    "old,new,line,fragment",
    [
        ("MAX_ACCELERATION = 100\nMAX_JERK", "MAX_ACCELERATION = -100\nMAX_JERK", 11, "positive"),
        ("MAX_VELOCITY = 1\n", "MAX_VELOCITY = fast\n", 20, "must be a number"),
        ("LINEAR_UNITS = mm", "LINEAR_UNITS = furlong", 7, "unknown unit"),
        ("COORDINATES = X Y Y Z C", "COORDINATES = X Y Q", 6, "axis letters"),
        ("[AXIS_C]\nMAX_VELOCITY = 1\n", "[AXIS_C]\n", 19, "no MAX_VELOCITY"),
    ],
)
def test_ini_errors(tmp_path, old, new, line, fragment):
    assert old in INI
    path = write(tmp_path, INI.replace(old, new), "bad.ini")
    with pytest.raises(MachineError) as info:
        load_machine(path)
    assert fragment in info.value.message
    assert info.value.location.line == line, info.value.format()


def test_with_dt_and_start():
    m = load_machine("generic-mill")
    assert m.with_dt(None) is m
    assert m.with_dt(0.004).dt_s == 0.004 and m.dt_s == 0.001
    assert_allclose(m.with_start([1, 2, 3]).start, [1, 2, 3])


def test_ini_kins_section(tmp_path):
    base = (
        INI.replace("COORDINATES = X Y Y Z C", "COORDINATES = X Y Z A C").replace("[JOINT_3]", "[AXIS_Z]")
        + "[AXIS_A]\nMAX_VELOCITY = 1\nMAX_ACCELERATION = 2\n"
    )
    m = load_machine(write(tmp_path, base + "[KINS]\nKINEMATICS = xyzac-trt-kins\nJOINTS = 5\n", "k.ini"))
    assert m.kinematics == "xyzac-trt" and m.kinematics_params["z_offset"] == 0.0
    m = load_machine(write(tmp_path, base + "[KINS]\nKINEMATICS = trivkins coordinates=XYZAC\n", "k2.ini"))
    assert m.kinematics == "trivial"
    with pytest.raises(MachineError, match="'corexykins' is not supported") as info:
        load_machine(write(tmp_path, base + "[KINS]\nKINEMATICS = corexykins\n", "k3.ini"))
    assert info.value.location.line == base.count("\n") + 2


def test_ini_without_coordinates_uses_axis_sections_or_axes(tmp_path):
    old = INI.replace("COORDINATES = X Y Y Z C\n", "").replace("[JOINT_3]", "[AXIS_Z]")
    m = load_machine(write(tmp_path, old, "old.ini"))
    assert m.axes == "XYZC"  # the [AXIS_*] sections, canonical order
    joints = (
        "[TRAJ]\nAXES = 2\nLINEAR_UNITS = inch\n[JOINT_0]\nMAX_VELOCITY = 1\nMAX_ACCELERATION = 2\n"
        "[JOINT_1]\nMAX_VELOCITY = 3\nMAX_ACCELERATION = 4\n"
    )
    m = load_machine(write(tmp_path, joints, "joints.ini"))
    assert m.axes == "XY" and m.dt_s == 0.001
    assert_allclose(m.vmax, [25.4, 3 * 25.4])


@pytest.mark.parametrize(
    "units,expected",
    [
        ("inch", "inch"),
        ("in", "inch"),
        ("mm", "mm"),
        ("0.03937", "inch"),  # the old form, machine units per mm: an inch
        ("1", "mm"),
        ("0.1", "mm"),  # a centimetre: nearer 1 mm than 1 inch
        (None, "mm"),  # no LINEAR_UNITS: mm, as the limits
    ],
)
def test_ini_program_units_follow_linear_units(tmp_path, units, expected):
    old = "LINEAR_UNITS = mm\n"
    text = INI.replace(old, "" if units is None else f"LINEAR_UNITS = {units}\n")
    assert load_machine(write(tmp_path, text, "u.ini")).program_units == expected


def test_toml_program_units_and_presets(tmp_path):
    assert load_machine(write(tmp_path, GOOD)).program_units == "mm"  # no [gcode] table
    m = load_machine(write(tmp_path, GOOD + '[gcode]\nprogram_units = "inch"\n', "inch.toml"))
    assert m.program_units == "inch" and "program_units" not in m.defaults
    for name in PRESETS:
        assert load_machine(name).program_units == "mm"
    with pytest.raises(MachineError, match='program_units must be "mm" or "inch"') as info:
        load_machine(write(tmp_path, GOOD + '[gcode]\nprogram_units = "furlong"\n', "bad.toml"))
    assert info.value.location.line == GOOD.count("\n") + 2


def test_ini_max_linear_velocity_is_the_path_speed_limit(tmp_path):
    assert load_machine(write(tmp_path, INI, "none.ini")).max_path_mm_s is None
    cap = INI.replace("ANGULAR_UNITS", "MAX_LINEAR_VELOCITY = 7.5\nANGULAR_UNITS")
    assert load_machine(write(tmp_path, cap, "cap.ini")).max_path_mm_s == 7.5
    inch = cap.replace("LINEAR_UNITS = mm", "LINEAR_UNITS = inch")
    assert_allclose(load_machine(write(tmp_path, inch, "inch.ini")).max_path_mm_s, 7.5 * MM_PER_INCH)
    old = INI.replace("ANGULAR_UNITS", "MAX_VELOCITY = 6\nANGULAR_UNITS")  # its name before LinuxCNC 2.8
    assert load_machine(write(tmp_path, old, "old.ini")).max_path_mm_s == 6.0
    both = cap.replace("ANGULAR_UNITS", "MAX_VELOCITY = 6\nANGULAR_UNITS")
    assert load_machine(write(tmp_path, both, "both.ini")).max_path_mm_s == 7.5  # the newer name wins
    display = INI + "[DISPLAY]\nMAX_LINEAR_VELOCITY = 3\n"  # the GUI's slider, not the machine's limit
    assert load_machine(write(tmp_path, display, "display.ini")).max_path_mm_s is None
    with pytest.raises(MachineError, match="positive") as info:
        load_machine(write(tmp_path, cap.replace("= 7.5", "= -1"), "bad.ini"))
    assert info.value.location.line == 8
    with pytest.raises(MachineError, match="out of range") as info:
        load_machine(write(tmp_path, cap.replace("= 7.5", "= 1e-9"), "slow.ini"))
    assert info.value.location.line == 8


def test_machine_program_units_and_path_speed_checked():
    m = load_machine("generic-mill")
    assert m.program_units == "mm" and m.max_path_mm_s is None
    assert m.to_dict()["program_units"] == "mm" and m.to_dict()["max_path_mm_s"] is None
    from dataclasses import replace

    with pytest.raises(MachineError, match="program units 'cm' are not known"):
        replace(m, program_units="cm")
    with pytest.raises(MachineError, match="path speed limit = 0 mm/s is out of range"):
        replace(m, max_path_mm_s=0.0)


@pytest.mark.corpus
def test_corpus_ini_program_units_and_path_speed():
    xyz = load_machine(os.path.join(CORPUS_CONFIGS, "XYZ.ini"))  # LINEAR_UNITS = inch
    assert xyz.program_units == "inch"
    assert_allclose(xyz.max_path_mm_s, 12 * MM_PER_INCH)  # [TRAJ], not [DISPLAY]'s
    mm = load_machine(os.path.join(CORPUS_CONFIGS, "axis_mm.ini"))
    assert mm.program_units == "mm" and mm.max_path_mm_s == 53.34

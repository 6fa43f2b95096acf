"""``cnc-interp parse``: text and JSON summaries, stdin, and FILE:LINE:COL errors with exit 2."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from click.testing import CliRunner

from cnc_interp.cli import main

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SAMPLES = os.path.join(ROOT, "samples", "gcode")
SAMPLE_FILES = sorted(f for f in os.listdir(SAMPLES) if f.endswith(".ngc"))
EXE = os.path.join(os.path.dirname(sys.executable), "cnc-interp")


def run_cli(*args, stdin: bytes | None = None):
    """The installed console script (its error handling included)."""
    cmd = [EXE, *args] if os.path.exists(EXE) else [sys.executable, "-m", "cnc_interp.cli", *args]
    return subprocess.run(cmd, input=stdin, capture_output=True, cwd=ROOT, timeout=120)


#: samples the default machine (generic-mill, XYZ) cannot run: the machine each is for
SAMPLE_MACHINES = {"five-axis-xyzac.ngc": "mikron-ucp710"}


@pytest.mark.parametrize("name", SAMPLE_FILES)
def test_every_sample_parses_to_json(name):
    m = ["-m", SAMPLE_MACHINES[name]] if name in SAMPLE_MACHINES else []
    res = CliRunner().invoke(main, ["parse", os.path.join(SAMPLES, name), "--json", *m])
    assert res.exit_code == 0, res.output
    s = json.loads(res.output)
    assert s["runs"] >= 2 and s["nodes"] > 0
    assert s["feed_length_mm"] > 0 and s["time_estimate_s"] > 0
    assert set(s["bounds"]) == set(s["axes"])


def test_sample_contents():
    def summ(name, *extra):
        res = CliRunner().invoke(main, ["parse", os.path.join(SAMPLES, name), "--json", *extra])
        assert res.exit_code == 0, res.output
        return json.loads(res.output)

    assert summ("lathe-profile.ngc", "-m", "xz-lathe")["axes"] == "XZ"
    assert summ("lathe-profile.ngc")["arcs"] == 3
    assert summ("nurbs-trident.ngc")["splines"] == 1
    five = summ("five-axis-xyzac.ngc", "-m", "mikron-ucp710")
    assert five["axes"] == "XYZAC"
    assert five["bounds"]["C"] == [0.0, 360.0]
    drill = summ("drilling-cycles.ngc")
    assert drill["dwells"] == 1 and drill["stops"] == {"M6": 2, "M30": 1}
    mill = summ("mill-contour.ngc", "-m", "generic-mill")
    assert mill["arcs"] == 10
    assert mill["bounds"]["X"] == [-8.0, 43.0]


def test_text_summary():
    res = CliRunner().invoke(main, ["parse", os.path.join(SAMPLES, "mill-contour.ngc")])
    assert res.exit_code == 0
    assert "mill-contour.ngc: 49 lines" in res.output
    assert "rapids excluded" in res.output


def test_stdin():
    res = run_cli("parse", "-", "--json", stdin=b"G21\nG0 X1 Y2\nG1 Z-1 F60\n")
    assert res.returncode == 0, res.stderr
    s = json.loads(res.stdout)
    assert s["source"] == "<stdin>"
    assert s["bounds"]["Y"] == [0.0, 2.0]
    assert abs(s["feed_time_s"] - 1.0) < 1e-12


@pytest.mark.parametrize(
    "text,where,what",
    [
        (b"G21\nG0 G1 X1\n", ":2:4: error:", "same modal group"),
        (b"G1 X1\n", ":1:1: error:", "feed"),
        (b"G0 X10\nG3 X0 Y11 I-10 J0 F60\n", ":2:1: error:", "not on the circle"),
        (b"G41 D1\n", ":1:1: error:", "cutter radius compensation"),
        (b"F60\nG5.2 P1\nX1 Y1 P1\n", ":2:1: error:", "G5.3"),
    ],
)
def test_errors_exit_2_with_location(text, where, what):
    res = run_cli("parse", "-", stdin=text)
    assert res.returncode == 2
    err = res.stderr.decode()
    assert err.startswith("<stdin>" + where), err
    assert what in err
    assert "Traceback" not in err
    assert err.count("\n") == 1


def test_machine_without_the_axis_is_an_error():
    res = run_cli("parse", os.path.join("samples", "gcode", "mill-contour.ngc"), "-m", "xz-lathe")
    assert res.returncode == 2
    assert "axis Y is not on this machine" in res.stderr.decode()


def test_missing_file_is_a_usage_error():
    res = run_cli("parse", "no-such-file.ngc")
    assert res.returncode == 2
    assert "Traceback" not in res.stderr.decode()


def test_binary_garbage_is_a_clean_error():
    import random

    data = bytes(random.Random(7).randrange(256) for _ in range(4000))
    res = run_cli("parse", "-", stdin=data)
    assert res.returncode == 2
    err = res.stderr.decode("utf-8", "replace")
    assert err.startswith("<stdin>:") and ": error: " in err
    assert "Traceback" not in err


def test_parse_fit_and_batch_count_nodes_and_segments_alike(tmp_path):
    """One definition of node and segment across the commands: rapids' end
    points are not nodes, and every command counts the same feed nodes and fitted segments."""
    from cnc_interp.pipeline import process_program
    from cnc_interp.machine.load import load_machine

    part = tmp_path / "p.ngc"
    part.write_text(
        "G21 G90\nG0 X5 Y5 Z2\nG0 X5 Y5 Z2\nG1 Z0 F600\nG1 X20\nG2 X30 Y15 R10\n"
        "G1 Y40\nG0 Z5\nG0 X0 Y0\nG1 Z-1 F300\nG1 X3 Y4\nM2\n"
    )
    parsed = json.loads(CliRunner().invoke(main, ["parse", str(part), "--json"]).output)
    fitted = json.loads(CliRunner().invoke(main, ["fit", str(part), "--json"]).output)
    record = process_program(str(part), part.read_bytes(), load_machine("generic-mill"))
    assert parsed["nodes"] == fitted["nodes_in"] == record["nodes"]
    assert fitted["segments_out"] == record["segments"]
    assert parsed["rapid_moves"] == fitted["rapid_moves"] == 3  # the repeated G0 moves nothing

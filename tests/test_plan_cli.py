"""``cnc-interp plan`` end to end: files, pipes, summaries, errors, determinism."""

import json
import subprocess
import sys

import numpy as np
import pytest

from cnc_interp.pipeline import parse_start, plan_part

PROGRAM = """\
G21 G90 G94
G0 X10 Y5 Z2
G1 Z0 F600
G1 X40 Y5 F1200
G1 X40 Y25
G4 P0.2
M0
G2 X20 Y25 I-10 J0
G1 X10 Y5
G0 Z5
M2
"""


def run(args, stdin=None):
    cmd = [sys.executable, "-m", "cnc_interp.cli", "plan"] + list(args)
    return subprocess.run(cmd, input=stdin, capture_output=True, timeout=600)


@pytest.fixture(scope="module")
def part(tmp_path_factory):
    d = tmp_path_factory.mktemp("plan")
    p = d / "part.ngc"
    p.write_text(PROGRAM)
    return p


def read_csv(data: bytes):
    lines = data.decode().splitlines()
    header = lines[0].split(",")
    rows = np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]])
    return header, rows


def test_plan_to_file_and_verify(part, tmp_path):
    out = tmp_path / "out.csv"
    r = run([str(part), "-m", "generic-mill", "-o", str(out)])
    assert r.returncode == 0, r.stderr.decode()
    err = r.stderr.decode()
    assert "cycle time" in err and "worst limit ratio" in err
    header, rows = read_csv(out.read_bytes())
    assert header == ["t", "s", "feed", "X", "Y", "Z"]
    assert np.allclose(rows[:, 0], np.arange(rows.shape[0]) * 0.001, rtol=0, atol=1e-12)
    assert np.array_equal(rows[0, 3:], [0, 0, 0])  # machine start: all zero
    assert np.allclose(rows[-1, 3:], [10, 5, 5], atol=1e-9)
    v = subprocess.run(
        [sys.executable, "-m", "cnc_interp.cli", "verify", str(out), "-m", "generic-mill"],
        capture_output=True,
        timeout=600,
    )
    assert v.returncode == 0, v.stdout.decode() + v.stderr.decode()
    # same input, same bytes
    out2 = tmp_path / "out2.csv"
    r2 = run([str(part), "-o", str(out2), "--quiet"])
    assert r2.returncode == 0 and r2.stderr == b""
    assert out2.read_bytes() == out.read_bytes()


def test_stdin_to_stdout_json_summary_and_start():
    r = run(["-", "--json", "--start", "X=1,Y=2"], stdin=PROGRAM.encode())
    assert r.returncode == 0, r.stderr.decode()
    header, rows = read_csv(r.stdout)
    assert np.array_equal(rows[0, 3:], [1, 2, 0])
    summary = json.loads(r.stderr.decode())
    assert summary["samples"] == rows.shape[0]
    assert summary["cycle_time_s"] == pytest.approx(rows[-1, 0])
    assert summary["worst_ratio"] <= 1 + 1e-9
    assert summary["planner"] == "optimal"  # the default


def test_bad_gcode_and_bad_start_exit_2(tmp_path):
    bad = tmp_path / "bad.ngc"
    bad.write_text("G1 X10 F100\nG1 X#<nope> Y\n")
    r = run([str(bad), "-o", str(tmp_path / "x.csv")])
    assert r.returncode == 2
    assert r.stderr.decode().startswith(f"{bad}:2:")
    assert not (tmp_path / "x.csv").exists()
    r = run([str(bad), "--start", "Q=1"])
    assert r.returncode == 2 and "error:" in r.stderr.decode()


def test_mcap_output(part, tmp_path):
    out = tmp_path / "out.mcap"
    r = run([str(part), "-o", str(out), "--quiet"])
    assert r.returncode == 0, r.stderr.decode()
    from cnc_interp.export.mcap_io import read_mcap

    traj = read_mcap(str(out))
    assert traj.q.shape[1] == 3 and traj.n_samples > 1000


def test_plan_part_api(part):
    outcome = plan_part(str(part), "generic-mill")
    assert outcome.report.ok
    s = outcome.summary()
    assert s["samples"] == outcome.trajectory.n_samples
    assert set(outcome.timings) >= {"parse", "fit", "plan", "verify"}


def test_parse_start():
    assert np.array_equal(parse_start("x=1, Z=-2.5", "XYZ"), [1, 0, -2.5])
    # the axes not named keep the machine's start position
    assert np.array_equal(parse_start("Y=3", "XYZ", np.array([1.0, 2.0, 50.0])), [1, 3, 50])
    assert parse_start(None, "XYZ") is None
    from cnc_interp.errors import UsageError

    for bad in ("X1", "X=abc", "A=1", "X=inf"):
        with pytest.raises(UsageError):
            parse_start(bad, "XYZ")


def _polygon_arc_program(n=120):
    """A quarter circle as n G1 moves in XY (a two-axis run of lines)."""
    th = np.linspace(0.0, 0.5 * np.pi, n + 1)
    lines = ["G21 G90 G94", "G0 X20 Y0", "G1 F3000"]
    lines += [f"G1 X{20 * np.cos(t):.4f} Y{20 * np.sin(t):.4f}" for t in th[1:]]
    return "\n".join(lines + ["M2", ""])


def test_fit_method_option_selects_the_fitter(tmp_path):
    part = tmp_path / "arc.ngc"
    part.write_text(_polygon_arc_program())
    planar = plan_part(str(part), "generic-mill", fit_method="planar")
    nodes = plan_part(str(part), "generic-mill")  # the default
    assert planar.report.ok and nodes.report.ok
    methods = lambda o: {m for r in o.fit_stats["runs"] for m in r.get("methods", [])}  # noqa: E731
    assert methods(planar) == {"planar-XY"} and methods(nodes) == {"nodes"}
    assert planar.summary()["fit_method"] == "planar" and nodes.summary()["fit_method"] == "nodes"
    r = run([str(part), "--fit-method", "nodes", "--json", "-o", str(tmp_path / "n.csv")])
    assert r.returncode == 0, r.stderr.decode()
    assert json.loads(r.stdout.decode())["fit_method"] == "nodes"
    r = subprocess.run(
        [sys.executable, "-m", "cnc_interp.cli", "fit", str(part), "--fit-method", "nodes", "--json"],
        capture_output=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr.decode()
    stats = json.loads(r.stdout.decode())
    assert stats["method"] == "nodes" and stats["within_tolerance"]
    r = run([str(part), "--fit-method", "spline", "-o", str(tmp_path / "x.csv")])
    assert r.returncode == 2 and b"--fit-method" in r.stderr
    assert not (tmp_path / "x.csv").exists()


def test_start_keeps_the_machines_position_on_unnamed_axes(tmp_path):
    m = tmp_path / "m.toml"
    m.write_text(
        'name = "m"\ndt = 0.001\nstart = { X = 0.0, Y = 0.0, Z = 50.0 }\n'
        + "".join(f"[axes.{a}]\nvmax = 200.0\namax = 2000.0\njmax = 50000.0\n" for a in "XYZ")
    )
    r = run(["-", "-m", str(m), "--start", "Y=3"], stdin=PROGRAM.encode())
    assert r.returncode == 0, r.stderr.decode()
    _, rows = read_csv(r.stdout)
    assert np.array_equal(rows[0, 3:], [0, 3, 50])


def test_effort_is_the_optimal_planners_and_recorded(part, tmp_path):
    fast = run([str(part), "--planner", "optimal", "--effort", "fast", "--json", "-o", str(tmp_path / "f.csv")])
    assert fast.returncode == 0, fast.stderr.decode()
    summary = json.loads(fast.stdout.decode())
    assert summary["planner"] == "optimal" and summary["options"] == {"effort": "fast"}
    normal = run([str(part), "--planner", "optimal", "--json", "-o", str(tmp_path / "n.csv")])
    assert json.loads(normal.stdout.decode())["options"] == {}
    assert summary["worst_ratio"] <= 1.0 + 1e-9
    # another planner has no effort to set: a usage error, one line, nothing written
    r = run([str(part), "--planner", "vpop", "--effort", "fast", "-o", str(tmp_path / "v.csv")])
    assert r.returncode == 2
    lines = r.stderr.decode().strip().splitlines()
    assert lines == ["cnc-interp: error: --effort applies to --planner optimal, not vpop"]
    assert not (tmp_path / "v.csv").exists()
    r = run([str(part), "--planner", "optimal", "--effort", "fastest", "-o", str(tmp_path / "x.csv")])
    assert r.returncode == 2 and b"--effort" in r.stderr

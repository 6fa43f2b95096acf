"""Hostile plan files: ``verify`` is never fooled, ``plot`` never destroys its input, and
the commands that read a plan agree on what one is.

Each defect found by a hostile pass is a test here first. The rule is the one of
``test_hostile.py``: a clean one-line error with the documented exit code, or the right
result.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from tests._contract_helpers import run_inproc
from tests.test_hostile import PART, one_error_line


@pytest.fixture(scope="module")
def plans(tmp_path_factory):
    """A real plan of the mill sample as CSV and MCAP, and its trajectory."""
    from cnc_interp.export.csv_io import read_csv

    d = tmp_path_factory.mktemp("hostile_plans")
    for name in ("p.csv", "p.mcap"):
        assert run_inproc("plan", PART, "-q", "-o", d / name).code == 0
    return d, read_csv(str(d / "p.csv"))


def _write_csv(traj, path):
    from cnc_interp.export.csv_io import write_csv

    write_csv(traj, str(path))
    return path


def _forged(traj, t0_s=0.0, dt_s=None, q_scale=1.0, q_offset=0.0):
    """``traj`` with its clock moved to ``t0_s`` (and period ``dt_s``) and its positions
    scaled and offset: the same rows, other numbers."""
    dt_s = traj.dt_s if dt_s is None else dt_s
    k = np.arange(traj.t.size)
    return replace(traj, t=t0_s + k * dt_s, dt_s=dt_s, q=traj.q * q_scale + q_offset)


def test_the_honest_plan_passes_and_names_its_machine(plans):
    d, _ = plans
    for name in ("p.csv", "p.mcap"):
        res = run_inproc("verify", d / name, "-m", "generic-mill")
        assert res.code == 0, res.explain()
        assert res.out.decode().startswith("machine: Generic 3-axis mill (preset:generic-mill)\n")
    res = run_inproc("verify", d / "p.mcap", "--json")  # the MCAP names its preset
    assert res.code == 0 and json.loads(res.out)["machine"] == "Generic 3-axis mill (preset:generic-mill)"


@pytest.mark.parametrize("t0_s", [1000.0, 1e6, 1e12])
@pytest.mark.parametrize("fmt", ["csv", "mcap"])
def test_a_clock_offset_cannot_hide_a_violation(plans, tmp_path, t0_s, fmt):
    """Positions x8 at honest 1 ms rows break every limit 8-fold; a large clock offset
    (whose float spacing swallows the period) must not make that pass."""
    d, traj = plans
    bad = _forged(traj, t0_s=t0_s, q_scale=8.0)
    out = tmp_path / f"off.{fmt}"
    if fmt == "csv":
        _write_csv(bad, out)
    else:  # log times 1 ms apart from 0 (an MCAP log time cannot reach 1e12 s)
        rows = [
            dict(zip(("t", "s", "feed", "X", "Y", "Z"), map(float, (t, s, f, *q))))
            for t, s, f, q in zip(bad.t, bad.s, bad.feed, bad.q)
        ]
        _mcap_with_rows(out, rows, [k * 1_000_000 for k in range(len(rows))])
    res = run_inproc("verify", out, "-m", "generic-mill")
    assert res.code != 0, res.explain()
    if res.code == 2:
        assert "t = 0" in one_error_line(res) or "fixed period" in res.err or "log time" in res.err
    # honest times: the violation shows
    honest = _write_csv(_forged(traj, q_scale=8.0), tmp_path / "honest.csv")
    res = run_inproc("verify", honest, "-m", "generic-mill", "--json")
    assert res.code == 1 and json.loads(res.out)["worst_ratio"] == pytest.approx(8.0, rel=1e-6)


def test_a_recorded_period_that_disagrees_with_the_clock_is_refused(plans, tmp_path):
    from cnc_interp.export.mcap_io import write_mcap
    from cnc_interp.machine.load import load_machine

    _, traj = plans
    # rows 1 ms apart at t from 1000 s, a recorded period of 2 ms, positions x8
    forged = replace(_forged(traj, t0_s=1000.0, q_scale=8.0), dt_s=0.002)
    out = tmp_path / "dt.mcap"
    write_mcap(forged, str(out), None, load_machine("generic-mill"))
    assert run_inproc("verify", out, "-m", "generic-mill").code == 2


def test_a_plan_that_does_not_start_at_the_machines_start_fails(plans, tmp_path):
    _, traj = plans
    # a whole plan moved by a constant keeps every difference: only the start shows it
    moved = _write_csv(replace(traj, q=traj.q + np.array([500.0, 0.0, 0.0])), tmp_path / "moved.csv")
    res = run_inproc("verify", moved, "-m", "generic-mill")
    assert res.code == 1 and "does not start at the machine's start position (X off by 500" in res.out.decode()
    # the start a plan was made with is given to verify as to plan
    other = tmp_path / "other.csv"
    assert run_inproc("plan", PART, "-q", "--start", "X=10,Y=-5", "-o", other).code == 0
    assert "X off by 10" in run_inproc("verify", other, "-m", "generic-mill").out.decode()
    assert run_inproc("verify", other, "-m", "generic-mill", "--start", "X=10,Y=-5").code == 0


def test_limits_edited_inside_an_mcap_are_not_trusted(plans, tmp_path):
    """An MCAP whose copied machine record allows 8x passes only against the file it names,
    which is loaded now."""
    from cnc_interp.export.mcap_io import read_mcap, write_mcap
    from cnc_interp.machine.load import load_machine

    d, _ = plans
    traj = read_mcap(str(d / "p.mcap"))
    m = load_machine("generic-mill")
    loose = replace(m, vmax=m.vmax * 8, amax=m.amax * 8, jmax=m.jmax * 8)
    out = tmp_path / "loose.mcap"
    write_mcap(_forged(traj, q_scale=8.0), str(out), None, loose)
    res = run_inproc("verify", out)
    assert res.code == 1 and res.out.decode().startswith("machine: Generic 3-axis mill (preset:generic-mill)")


def _mcap_with_rows(path, rows, log_times_ns=None):
    """An MCAP with one ``/setpoints`` channel holding ``rows`` (dicts) as JSON."""
    from mcap.writer import Writer

    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema("cnc_interp.Setpoint", "jsonschema", b"{}")
        cid = w.register_channel("/setpoints", "json", sid, {"axes": "XYZ"})
        for i, r in enumerate(rows):
            t_ns = log_times_ns[i] if log_times_ns is not None else round(r["t"] * 1e9)
            w.add_message(cid, log_time=t_ns, data=json.dumps(r).encode(), publish_time=t_ns)
        w.finish()
    return path


def _rows(n=50, dt_s=0.001):
    return [{"t": i * dt_s, "s": 0.0, "feed": 0.0, "line": 0, "X": 0.0, "Y": 0.0, "Z": 0.0} for i in range(n)]


@pytest.mark.parametrize("value", ["0.0", True, {"x": 0.0}, [0.0]])
def test_mcap_setpoints_must_be_numbers(tmp_path, value):
    from cnc_interp.export.mcap_io import read_mcap

    rows = _rows()
    assert read_mcap(str(_mcap_with_rows(tmp_path / "ok.mcap", rows))).q.shape == (50, 3)
    rows[7]["Y"] = value
    res = run_inproc("verify", _mcap_with_rows(tmp_path / "odd.mcap", rows), "-m", "generic-mill")
    assert "/setpoints" in one_error_line(res)


def test_a_null_setpoint_is_a_non_finite_one_and_fails(tmp_path):
    """The writer stores a non-finite number as null: read back as NaN, it fails verify."""
    rows = _rows()
    rows[7]["Y"] = None
    res = run_inproc("verify", _mcap_with_rows(tmp_path / "null.mcap", rows), "-m", "generic-mill")
    assert res.code == 1 and "NaN" in res.out.decode()


def test_mcap_log_times_must_be_the_samples_times(tmp_path):
    rows = _rows()
    log = [round(r["t"] * 1e9) for r in rows]
    log[20] += 5_000  # 5 us late: a player would schedule it there
    res = run_inproc("verify", _mcap_with_rows(tmp_path / "late.mcap", rows, log), "-m", "generic-mill")
    assert "log time" in one_error_line(res)


# -- programs at the edge of the geometry ---------------------------------------------------
@pytest.mark.parametrize(
    "body, length_mm",
    [
        # collinear control points: out to x = 10/sqrt(12), back to -10/sqrt(12), home
        ("G5 I10 J0 P-10 Q0 X0 Y0", 4 * 10 / np.sqrt(12)),
        # quadratic out to x = 5 and back
        ("G5.1 I10 J0 X0 Y0", 10.0),
        # two coincident middle points: out to x = 7.5 and back
        ("G5 I10 J0 P10 Q0 X0 Y0", 15.0),
    ],
)
def test_a_spline_with_cusps_plans_as_curves_meeting_at_stops(body, length_mm):
    """A valid degenerate spline whose direction reverses plans end to end (each arc of it
    between cusps a curve of its own) within limits, along its whole length."""
    import cnc_interp as ci

    text = f"G21 G90 G17 F600\n{body}\nM2\n"
    res = ci.run(text.encode(), "generic-mill", name="loop.ngc")
    traj = res.trajectory
    assert res.report.ok
    assert traj.s[-1] == pytest.approx(length_mm, rel=1e-6)
    np.testing.assert_allclose(traj.q[-1], [0.0, 0.0, 0.0], atol=1e-12)
    # the farthest point is a cusp: the tool comes to rest there
    apex = int(np.argmax(traj.q[:, 0]))
    assert traj.feed[apex] <= 0.01 * traj.feed.max()


def test_the_spline_cusp_parameters_are_exact():
    from cnc_interp.gcode.splines import bezier_cusps, split_bezier

    loop = np.array([[0.0, 0.0], [10.0, 0.0], [-10.0, 0.0], [0.0, 0.0]])
    np.testing.assert_allclose(bezier_cusps(loop), [(3 - np.sqrt(3)) / 6, (3 + np.sqrt(3)) / 6], rtol=1e-12)
    assert bezier_cusps(np.array([[0.0, 0.0], [10.0, 5.0], [-10.0, 5.0], [1.0, 0.0]])).size == 0
    head, tail = split_bezier(loop, 0.5)
    np.testing.assert_allclose(head, [[0, 0], [5, 0], [2.5, 0], [0, 0]], atol=1e-15)
    np.testing.assert_allclose(tail, [[0, 0], [-2.5, 0], [-5, 0], [0, 0]], atol=1e-15)


# -- a plan without motion -------------------------------------------------------------------
@pytest.mark.parametrize("program", ["G21\nM2\n", "G21 G90\nG1 X0 Y0 F100\nM2\n"])
@pytest.mark.parametrize("fmt", ["csv", "mcap"])
def test_plan_verify_and_plot_agree_on_a_plan_without_motion(tmp_path, program, fmt):
    """The plan of a program that does not move is one sample, the machine at its start:
    plan writes it, verify passes it, plot draws it."""
    part = tmp_path / "still.ngc"
    part.write_text(program)
    out = tmp_path / f"still.{fmt}"
    assert run_inproc("plan", part, "-q", "-o", out).code == 0
    res = run_inproc("verify", out, "-m", "generic-mill", "--json")
    assert res.code == 0, res.explain()
    rep = json.loads(res.out)
    assert rep["ok"] and rep["n_samples"] == 1 and rep["start_ok"]
    pytest.importorskip("matplotlib")
    res = run_inproc("plot", out, "-m", "generic-mill", "-o", tmp_path / "still.png")
    assert res.code == 0 and (tmp_path / "still.png").stat().st_size > 1000, res.explain()


# -- endless inputs --------------------------------------------------------------------------
@pytest.mark.parametrize(
    "args, says",
    [
        (("plan", "/dev/zero", "-q", "-o", "{tmp}/z.csv"), "line is longer than"),
        (("parse", "/dev/zero"), "line is longer than"),
        (("verify", "/dev/zero", "-m", "generic-mill"), "must be a regular file"),
        (("plot", "/dev/zero", "-o", "{tmp}/z.png"), "must be a regular file"),
        (("emulate", "/dev/zero"), "must be a regular file"),
    ],
)
def test_an_endless_input_is_refused_not_read_until_memory_runs_out(tmp_path, args, says):
    res = run_inproc(*(a.format(tmp=tmp_path) for a in args))
    assert says in one_error_line(res)


def test_a_part_read_from_a_stream_is_capped(monkeypatch):
    """Text past the cap on standard input ends in one error, whatever its lines."""
    import io

    from cnc_interp import inputfile
    from cnc_interp.errors import UsageError

    endless = io.BytesIO(b"G1 X1 F100\n" * 10_000)
    with pytest.raises(UsageError, match="larger than 65536 bytes"):
        inputfile.read_bounded(endless, "<stdin>", limit=65536)
    monkeypatch.setattr(inputfile, "READ_CHUNK_BYTES", 1000)  # the line check spans chunks
    one_line = io.BytesIO(b"(" + b"x" * (inputfile.MAX_LINE_CHARS + 5000) + b")\n")
    with pytest.raises(UsageError, match="longer than") as err:
        inputfile.read_bounded(one_line, "p.ngc")
    assert err.value.location.line == 1
    text = b"G21\nG1 X1 F100\nM2\n"
    assert inputfile.read_bounded(io.BytesIO(text), "p.ngc") == text


def test_verify_escapes_control_bytes_in_the_machine_name(tmp_path):
    from cnc_interp.plan.trajectory import Trajectory
    from cnc_interp.export.csv_io import write_csv

    (tmp_path / "m.toml").write_text(
        'name = "evil\\u001b[2Jname\\u0007"\n'
        + "".join(f"[axes.{a}]\nvmax = 100.0\namax = 1000.0\njmax = 10000.0\n" for a in "XYZ")
    )
    traj = Trajectory(
        axes="XYZ",
        dt_s=0.001,
        t=np.arange(3) * 0.001,
        s=np.zeros(3),
        feed=np.zeros(3),
        q=np.zeros((3, 3)),
        line=np.zeros(3, dtype=np.int64),
        planner="csv",
    )
    write_csv(traj, str(tmp_path / "p.csv"))
    res = run_inproc("verify", tmp_path / "p.csv", "-m", tmp_path / "m.toml")
    out = res.out.decode()
    assert res.code == 0 and "\x1b" not in out and "\x07" not in out and "evil\\x1b" in out

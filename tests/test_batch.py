"""`cnc-interp batch`: program discovery, baseline rules, reports; full runs locally and on Dask."""

import csv
import json

import pytest

from cnc_interp.batch import (
    FIELDS,
    VOLATILE_FIELDS,
    BatchOptions,
    collect_programs,
    compare,
    format_table,
    load_baseline,
    parse_slowdown,
    summarise,
    write_report,
)
from cnc_interp.errors import UsageError


def rec(key, status="ok", cycle=1.0, worst=0.5, **kw):
    r = {f: None for f in FIELDS}
    r.update(
        key=key,
        status=status,
        message=kw.pop("message", ""),
        error_line=0,
        cycle_time_s=cycle,
        worst_ratio=worst,
        wall_s=0.1,
        peak_mem_mb=50.0,
    )
    r.update(kw)
    return r


def test_parse_slowdown():
    assert parse_slowdown("1%") == 0.01
    assert parse_slowdown(" 2.5 %") == 0.025
    assert parse_slowdown("0.05") == 0.05
    for bad in ("fast", "-1%", "nan", ""):
        with pytest.raises(UsageError):
            parse_slowdown(bad)


def test_collect_programs(tmp_path):
    d = tmp_path / "progs"
    (d / "sub").mkdir(parents=True)
    (d / "a.ngc").write_text("M2\n")
    (d / "sub" / "b.NC").write_text("M2\n")
    (d / "notes.txt").write_text("x")
    (d / ".hidden.ngc").write_text("M2\n")
    single = tmp_path / "c.gcode"
    single.write_text("M2\n")
    found = collect_programs([str(d), str(single), str(d / "a.ngc")])
    assert [k for k, _ in found] == ["a.ngc", "c.gcode", "progs/a.ngc", "progs/sub/b.NC"]
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(UsageError, match="no part programs"):
        collect_programs([str(empty)])
    with pytest.raises(UsageError, match="no such file"):
        collect_programs([str(tmp_path / "missing")])


def test_compare_rules():
    base = {r["key"]: r for r in [rec("a"), rec("b", cycle=2.0), rec("c", status="error"), rec("d"), rec("gone")]}
    cur = [
        rec("a", cycle=1.005),
        rec("b", cycle=2.1),
        rec("c", status="error"),
        rec("d", status="violation", worst=1.2),
        rec("new", cycle=3.0),
    ]
    out = compare(cur, base, 0.01)
    assert [s["key"] for s in out["slower"]] == ["b"]  # +5% > 1%; a is +0.5%
    assert [s["key"] for s in out["status_changed"]] == ["d"]  # ok -> violation
    assert [v["key"] for v in out["violations"]] == ["d"]
    assert out["new"] == ["new"] and out["missing"] == ["gone"]
    # a slowdown and a status change are regressions; the violation is a failure
    assert (out["errors"], out["failures"], out["regressions"]) == (0, 1, 2)
    # an already-broken program that stays broken is not counted again
    known = compare([rec("c", status="error")], {"c": rec("c", status="error")}, 0.01)
    assert known["errors"] == known["failures"] == known["regressions"] == 0
    # without a baseline violations are failures, programs refused as bad input errors
    out = compare(cur, None, 0.01)
    assert (out["errors"], out["failures"], out["regressions"]) == (1, 1, 0)
    faster = compare([rec("b", cycle=1.0)], {"b": rec("b", cycle=2.0)}, 0.01)
    assert faster["regressions"] == 0 and faster["faster"][0]["key"] == "b"


def test_reports_round_trip(tmp_path):
    records = [
        rec("x.ngc", lines=10, segments=3),
        rec("y.ngc", status="error", cycle=None, worst=None, message="y.ngc:3:1: error: bad word"),
    ]
    report = {"programs": records, "summary": summarise(records, 2.0), "comparison": compare(records, None, 0.01)}
    jpath, cpath = str(tmp_path / "r.json"), str(tmp_path / "r.csv")
    write_report(report, jpath)
    write_report(report, cpath)
    assert load_baseline(jpath)["y.ngc"]["status"] == "error"
    rows = list(csv.DictReader(open(cpath)))
    assert [r["key"] for r in rows] == ["x.ngc", "y.ngc"] and rows[1]["cycle_time_s"] == ""
    assert tuple(rows[0]) == FIELDS
    text = format_table(report)
    assert "bad word" in text and "2 programs: 1 error, 1 ok" in text
    assert "1 error(s), 0 failure(s), 0 regression(s)" in text
    assert set(VOLATILE_FIELDS) <= set(FIELDS)


def test_bad_baseline(tmp_path):
    p = tmp_path / "b.json"
    p.write_text('{"programs": [\n  {"key": 1,}\n]}')
    with pytest.raises(UsageError) as info:
        load_baseline(str(p))
    assert info.value.location.line == 2
    p.write_text('{"other": []}')
    with pytest.raises(UsageError, match="not a cnc-interp batch"):
        load_baseline(str(p))


def test_options_defaults():
    o = BatchOptions(paths=("a",), machine_spec="generic-mill")
    assert o.planner == "optimal" and o.max_slowdown == "1%" and o.dask_address is None


# --- full runs through parse, fit, plan, verify --------------------------------
PROGRAMS = {
    "square.ngc": "G21 G90 G17\nG0 X0 Y0 Z1\nG1 Z0 F600\nG1 X20 F3000\nG1 Y20\nG1 X0\nG1 Y0\nM2\n",
    "arc.ngc": "G21 G90 G17\nG0 X20 Y10\nG1 X20 Y10 F2400\nG2 X30 Y0 I5 J-5\nG4 P0.05\nG1 X40 Y5\nM2\n",
    "sub/broken.ngc": "G21 G90\nG1 X5 F1000\nG1 X10 Q\nM2\n",
}

MACHINE = """\
name = "batch test mill"
dt = 0.001
[axes.X]
vmax = 200.0
amax = 2000.0
jmax = {jmax}
[axes.Y]
vmax = 200.0
amax = 2000.0
jmax = {jmax}
[axes.Z]
vmax = 100.0
amax = 1000.0
jmax = {jmax}
"""


@pytest.fixture()
def folder(tmp_path):
    root = tmp_path / "progs"
    for name, text in PROGRAMS.items():
        p = root / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    return root


def machine_file(tmp_path, jmax, name="m.toml"):
    p = tmp_path / name
    p.write_text(MACHINE.format(jmax=jmax))
    return str(p)


def run_cli(args):
    from click.testing import CliRunner

    from cnc_interp.cli import main

    return CliRunner().invoke(main, args, catch_exceptions=False)


def stable(report):
    return [{k: v for k, v in r.items() if k not in VOLATILE_FIELDS} for r in report["programs"]]


def test_batch_with_broken_program_and_baseline_rules(tmp_path, folder):
    m = machine_file(tmp_path, 20000.0)
    rep = str(tmp_path / "r.json")
    res = run_cli(["batch", str(folder), "-m", m, "--jobs", "2", "--report", rep, "-q"])
    assert res.exit_code == 1, res.output  # without a baseline, a failure fails the run
    report = json.load(open(rep))
    by = {r["key"]: r for r in report["programs"]}
    assert sorted(by) == ["progs/arc.ngc", "progs/square.ngc", "progs/sub/broken.ngc"]
    bad = by["progs/sub/broken.ngc"]
    assert bad["status"] == "error" and bad["error_line"] == 3 and "broken.ngc:3:" in bad["message"]
    for key in ("progs/arc.ngc", "progs/square.ngc"):
        r = by[key]
        assert r["status"] == "ok" and r["worst_ratio"] <= 1 + 1e-9
        assert r["cycle_time_s"] > 0 and r["segments"] >= 1 and r["lines"] >= 7
        assert r["path_length_mm"] > 20 and r["peak_mem_mb"] > 0 and r["wall_s"] > 0
    assert "progs/sub/broken.ngc" in res.output and "1 error, 2 ok" in res.output
    # same run against itself: no regression; CSV report too
    res2 = run_cli(["batch", str(folder), "-m", m, "--baseline", rep, "--report", str(tmp_path / "r.csv"), "-q"])
    assert res2.exit_code == 0, res2.output
    assert "0 error(s), 0 failure(s), 0 regression(s)" in res2.output
    assert open(tmp_path / "r.csv").readline().startswith("key,status,message")
    # the broken program fixed: its status changed -> regression by the baseline rules
    (folder / "sub" / "broken.ngc").write_text("G21 G90\nG1 X5 F1000\nM2\n")
    res3 = run_cli(["batch", str(folder), "-m", m, "--baseline", rep, "-q", "--json"])
    assert res3.exit_code == 1
    out = json.loads(res3.output)
    assert [c["key"] for c in out["comparison"]["status_changed"]] == ["progs/sub/broken.ngc"]


def test_baseline_flags_lowered_jerk_as_slower(tmp_path, folder):
    (folder / "sub" / "broken.ngc").unlink()
    rep = str(tmp_path / "base.json")
    assert run_cli(["batch", str(folder), "-m", machine_file(tmp_path, 20000.0), "--report", rep, "-q"]).exit_code == 0
    slow = machine_file(tmp_path, 2000.0, "slow.toml")
    res = run_cli(["batch", str(folder), "-m", slow, "--baseline", rep, "--max-slowdown", "1%", "-q", "--json"])
    assert res.exit_code == 1
    out = json.loads(res.output)
    slower = {s["key"] for s in out["comparison"]["slower"]}
    assert "progs/square.ngc" in slower
    # every program is flagged: slower, or (if the planner broke a limit) a status change
    flagged = slower | {s["key"] for s in out["comparison"]["status_changed"]}
    assert flagged == {"progs/arc.ngc", "progs/square.ngc"}
    assert all(s["change"] > 0.01 for s in out["comparison"]["slower"])
    # a generous allowance accepts the same slowdown
    worst = max(s["change"] for s in out["comparison"]["slower"])
    res2 = run_cli(
        [
            "batch",
            str(folder),
            "-m",
            slow,
            "--baseline",
            rep,
            "--max-slowdown",
            f"{worst * 100 + 1:.3f}%",
            "-q",
            "--json",
        ]
    )
    assert json.loads(res2.output)["comparison"]["slower"] == []
    assert res2.exit_code == (1 if out["comparison"]["status_changed"] else 0)


def test_timeout_is_a_status_not_a_failure(tmp_path, folder):
    from cnc_interp.batch import build_report

    report = build_report(
        BatchOptions(
            paths=(str(folder),), machine_spec=machine_file(tmp_path, 20000.0), jobs=2, timeout_s=1e-4, quiet=True
        )
    )
    assert {r["status"] for r in report["programs"]} <= {"timeout", "error"}
    assert any(r["status"] == "timeout" for r in report["programs"])


def test_bad_machine_and_usage_exit_2(tmp_path, folder):
    import subprocess
    import sys

    proc = subprocess.run(
        [sys.executable, "-m", "cnc_interp.cli", "batch", str(folder), "-m", "no-such-preset"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2 and "error: no machine file or preset named" in proc.stderr
    from cnc_interp.batch import run_batch
    from cnc_interp.errors import MachineError

    with pytest.raises(MachineError):
        run_batch(BatchOptions(paths=(str(folder),), machine_spec="no-such-preset"))
    with pytest.raises(UsageError):
        run_batch(BatchOptions(paths=(str(folder),), machine_spec="generic-mill", max_slowdown="x"))


def test_dask_local_cluster_matches_local(tmp_path, folder):
    distributed = pytest.importorskip("distributed")
    from cnc_interp.batch import build_report

    m = machine_file(tmp_path, 20000.0)
    local = build_report(BatchOptions(paths=(str(folder),), machine_spec=m, jobs=2, quiet=True))
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    ) as cluster:
        remote = build_report(
            BatchOptions(paths=(str(folder),), machine_spec=m, quiet=True, dask_address=cluster.scheduler_address)
        )
    assert remote["executor"] == "dask" and local["executor"] == "local"
    assert stable(remote) == stable(local)
    assert remote["comparison"] == local["comparison"]
    assert {r["status"] for r in local["programs"]} == {"ok", "error"}


def test_dask_unreachable_scheduler_is_usage_error(tmp_path, folder, monkeypatch):
    pytest.importorskip("distributed")
    import cnc_interp.batch as batch_mod
    from cnc_interp.batch import run_batch

    monkeypatch.setattr(batch_mod, "DASK_CONNECT_TIMEOUT_S", 1)

    with pytest.raises(UsageError, match="cannot connect"):
        run_batch(
            BatchOptions(
                paths=(str(folder),), machine_spec="generic-mill", quiet=True, dask_address="tcp://127.0.0.1:9"
            )
        )


def test_fit_method_reaches_the_workers(tmp_path, folder):
    from cnc_interp.batch import build_report

    import numpy as np

    th = np.linspace(0.0, 0.5 * np.pi, 61)  # a quarter circle of G1 moves: the planar fit's case
    moves = "".join(f"G1 X{20 * np.cos(t):.4f} Y{20 * np.sin(t):.4f}\n" for t in th[1:])
    (folder / "polygon.ngc").write_text("G21 G90 G17\nG0 X20 Y0\nG1 F3000\n" + moves + "M2\n")
    m = machine_file(tmp_path, 20000.0)
    auto = build_report(BatchOptions(paths=(str(folder),), machine_spec=m, jobs=1, quiet=True, fit_method="planar"))
    nodes = build_report(BatchOptions(paths=(str(folder),), machine_spec=m, jobs=1, quiet=True))
    assert auto["fit_method"] == "planar" and nodes["fit_method"] == "nodes"
    ok = [k for k, r in enumerate(auto["programs"]) if r["status"] == "ok"]
    assert ok and all(nodes["programs"][k]["status"] == "ok" for k in ok)
    # the two fitters give different segmentations of at least one program
    assert any(auto["programs"][k]["segments"] != nodes["programs"][k]["segments"] for k in ok)


def test_effort_reaches_the_workers_and_needs_the_optimal_planner(tmp_path, folder):
    from cnc_interp.batch import build_report, run_batch

    # a small circle at a high feed: curvature binds, the optimal planner's profile route
    (folder / "circle.ngc").write_text("G21 G90 G17\nG0 X4 Y0\nG2 X4 Y0 I-4 J0 F10000\nM2\n")
    m = machine_file(tmp_path, 20000.0)
    reps = {
        e: build_report(
            BatchOptions(paths=(str(folder),), machine_spec=m, planner="optimal", effort=e, jobs=1, quiet=True)
        )
        for e in ("fast", None)
    }
    assert reps["fast"]["effort"] == "fast" and reps[None]["effort"] is None
    cycle = {e: {r["key"]: r for r in rep["programs"]} for e, rep in reps.items()}
    circle = next(k for k in cycle[None] if k.endswith("circle.ngc"))
    assert cycle[None][circle]["status"] == cycle["fast"][circle]["status"] == "ok"
    # the refinement gains on the circle; fast leaves it out
    assert cycle[None][circle]["samples"] < cycle["fast"][circle]["samples"]
    with pytest.raises(UsageError, match="--effort"):
        run_batch(BatchOptions(paths=(str(folder),), machine_spec=m, planner="vpop", effort="fast", quiet=True))

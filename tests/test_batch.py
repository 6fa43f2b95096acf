"""`cnc-interp batch`: program discovery, baseline rules, reports; full runs locally and on Dask."""

import csv
import json
import os

import pytest

from cnc_interp.batch import (
    FIELDS, VOLATILE_FIELDS, BatchOptions, collect_programs, compare, format_table,
    load_baseline, parse_slowdown, summarise, write_report)
from cnc_interp.errors import UsageError


def rec(key, status="ok", cycle=1.0, worst=0.5, **kw):
    r = {f: None for f in FIELDS}
    r.update(key=key, status=status, message=kw.pop("message", ""), error_line=0,
             cycle_time_s=cycle, worst_ratio=worst, wall_s=0.1, peak_mem_mb=50.0)
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
    base = {r["key"]: r for r in [rec("a"), rec("b", cycle=2.0), rec("c", status="error"),
                                  rec("d"), rec("gone")]}
    cur = [rec("a", cycle=1.005), rec("b", cycle=2.1), rec("c", status="error"),
           rec("d", status="violation", worst=1.2), rec("new", cycle=3.0)]
    out = compare(cur, base, 0.01)
    assert [s["key"] for s in out["slower"]] == ["b"]             # +5% > 1%; a is +0.5%
    assert [s["key"] for s in out["status_changed"]] == ["d"]     # ok -> violation
    assert [v["key"] for v in out["violations"]] == ["d"]
    assert out["new"] == ["new"] and out["missing"] == ["gone"]
    assert out["regressions"] == 3
    # an already-broken program that stays broken is no regression
    assert compare([rec("c", status="error")], {"c": rec("c", status="error")}, 0.01)["regressions"] == 0
    # without a baseline only violations count
    assert compare(cur, None, 0.01)["regressions"] == 1
    faster = compare([rec("b", cycle=1.0)], {"b": rec("b", cycle=2.0)}, 0.01)
    assert faster["regressions"] == 0 and faster["faster"][0]["key"] == "b"


def test_reports_round_trip(tmp_path):
    records = [rec("x.ngc", lines=10, segments=3), rec("y.ngc", status="error", cycle=None, worst=None,
                                                       message="y.ngc:3:1: error: bad word")]
    report = {"programs": records, "summary": summarise(records, 2.0),
              "comparison": compare(records, None, 0.01)}
    jpath, cpath = str(tmp_path / "r.json"), str(tmp_path / "r.csv")
    write_report(report, jpath)
    write_report(report, cpath)
    assert load_baseline(jpath)["y.ngc"]["status"] == "error"
    rows = list(csv.DictReader(open(cpath)))
    assert [r["key"] for r in rows] == ["x.ngc", "y.ngc"] and rows[1]["cycle_time_s"] == ""
    assert tuple(rows[0]) == FIELDS
    text = format_table(report)
    assert "bad word" in text and "2 programs: 1 error, 1 ok" in text and "0 regression(s)" in text
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
    assert o.planner == "vpop" and o.max_slowdown == "1%" and o.dask_address is None

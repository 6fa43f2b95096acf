"""``cnc-interp estimate`` and ``plan.breakdown``: every breakdown sums to the cycle, the
attribution (tools, operations, kinds, dwells) matches what the program says, the limit
classifier's codes, the CLI's JSON and its errors."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

import cnc_interp as ci
from cnc_interp.plan.breakdown import (
    CODE_FEED,
    CODE_LIMIT0,
    CODE_REST,
    CODE_TRANSITION,
    KINDS,
    classify_limits,
    code_names,
)

from ._contract_helpers import run_proc
from .conftest import CORPUS, SAMPLES

#: the sample programs and the machines they are written for
SAMPLE_CASES = [
    ("mill-contour.ngc", "generic-mill"),
    ("drilling-cycles.ngc", "generic-mill"),
    ("lathe-profile.ngc", "xz-lathe"),
    ("nurbs-trident.ngc", "generic-mill"),
    ("five-axis-xyzac.ngc", "mikron-ucp710"),
]
#: corpus programs with tool changes (M6) and the tools they load
CORPUS_CASES = [
    (os.path.join(CORPUS, "nurbs-g5", "Curva_Mazatrol #1=1_G5.ngc"), [0]),
    (os.path.join(CORPUS, "nurbs-g5", "Curva_Delfino #1=1_G5.ngc"), [0]),
    (os.path.join(CORPUS, "violation_checks", "sam_zero_length_move.ngc"), [15]),
]


def assert_sums(est) -> None:
    """Every breakdown adds up to the cycle within one period."""
    cycle, dt = est.cycle_time_s, est.dt_s
    assert cycle == pytest.approx((est.samples - 1) * dt, abs=1e-9)
    sums = {
        "by_kind": sum(est.by_kind.values()),
        "by_tool": sum(t.time_s for t in est.by_tool),
        "by_operation": sum(o.time_s for o in est.by_operation),
        "by_lines": sum(r.time_s for r in est.by_lines),
        "limits": sum(est.limits.values()),
        "limits_by_kind": sum(sum(v.values()) for v in est.limits_by_kind.values()),
    }
    for name, total in sums.items():
        assert abs(total - cycle) <= dt, f"{name} sums to {total}, the cycle is {cycle}"
    for kind, per in est.limits_by_kind.items():
        assert sum(per.values()) == pytest.approx(est.by_kind[kind], abs=dt)
    assert 0.0 <= est.at_feed_s <= est.by_kind["feed"] + 1e-12


@pytest.mark.parametrize("name,machine", SAMPLE_CASES, ids=[c[0] for c in SAMPLE_CASES])
def test_samples_sum_to_the_cycle(name, machine):
    est = ci.estimate(os.path.join(SAMPLES, name), machine)
    assert est.samples > 1 and set(est.by_kind) == set(KINDS)
    assert_sums(est)


def test_marks_and_events_change_no_sample():
    """The estimate plans the same samples as ``plan`` (marks and events only observe)."""
    from cnc_interp.pipeline import PlanOptions, stream_plan

    part = os.path.join(SAMPLES, "drilling-cycles.ngc")
    plain = stream_plan(PlanOptions(part=part, out=None, quiet=True))
    est = ci.estimate(part, "generic-mill")
    assert est.samples == plain["samples"]
    assert est.path_length_mm == plain["path_length_mm"]
    # the sample's tools and operation headers, in program order
    assert [(t.tool, t.line) for t in est.by_tool] == [(3, 5), (4, 14)]
    names = [o.name for o in est.by_operation]
    assert names[1:] == [
        "G81 spot drill, retract to the initial level between holes: G98",
        "G83 deep peck, retract to R between holes: G99",
        "G73 chip breaking, incremental row of 3 holes 12 mm apart",
        "G82 counterbore with a 0.5 s dwell",
    ]
    assert [o.tool for o in est.by_operation[1:]] == [3, 4, 4, 4]
    # G82 P0.5 dwells at each of its holes: one hole here
    assert est.by_kind["dwell"] == pytest.approx(0.5, abs=est.dt_s)


@pytest.mark.corpus
@pytest.mark.filterwarnings("ignore:.*G43 H15 with no tool table")
@pytest.mark.parametrize("part,tools", CORPUS_CASES, ids=[os.path.basename(c[0]) for c in CORPUS_CASES])
def test_corpus_programs_with_tool_changes(part, tools):
    est = ci.estimate(part, "generic-mill")
    assert_sums(est)
    assert [t.tool for t in est.by_tool if t.time_s > 0] == tools


# -- closed forms ------------------------------------------------------------------------
def test_dwell_rapid_and_feed_kinds():
    """G4 P2 is 2 s of dwell; a G0 is rapid only, a G1 feed only; a long straight G1 is at
    its feed all but its two ramps."""
    m = ci.load_machine("generic-mill")
    f_mm_s, length = 50.0, 100.0
    text = f"G21 G90\nG0 X10\nG4 P2\nG1 X{10 + length:g} F{f_mm_s * 60:g}\nM2\n"
    est = ci.estimate(text, m)
    assert_sums(est)
    dt = est.dt_s
    assert est.by_kind["dwell"] == pytest.approx(2.0, abs=dt)
    assert est.limits_by_kind["dwell"] == {"rest": pytest.approx(2.0, abs=dt)}
    # the rapid: 10 mm, at most vmax (200 mm/s) and at least its ramps
    assert 10.0 / m.vmax[0] <= est.by_kind["rapid"] <= 1.0
    # the feed: at least length / feed; at feed for all but the two jerk-limited ramps
    ramp = f_mm_s / m.amax[0] + m.amax[0] / m.jmax[0]
    assert est.by_kind["feed"] >= length / f_mm_s - dt
    assert length / f_mm_s - 2 * ramp <= est.at_feed_s <= length / f_mm_s + dt
    assert est.limits.get("feed", 0.0) > 0.9 * (length / f_mm_s - 2 * ramp)
    assert est.at_feed_share is not None and 0.9 < est.at_feed_share <= 1.0


def test_two_tools_match_the_halves_planned_apart():
    """Each tool's time is its half of the program planned on its own (paths are planned
    from rest to rest: only the rest padding at the joint differs)."""
    m = ci.load_machine("generic-mill")
    half1 = "G21 G90\nG0 Z5\nG1 X40 Y10 F1200\nG2 X60 Y30 R20\nG0 Z20\n"
    half2 = "G0 X0 Y50\nG1 Z-1 F300\nG1 X30 F900\nG1 Y70\nG0 Z20\n"
    whole = "G21 G90\n(first op)\nT1 M6\n" + half1 + "(second op)\nT2 M6\n" + half2 + "M2\n"
    est = ci.estimate(whole, m)
    assert_sums(est)
    first = ci.estimate(half1 + "M2\n", m)
    second = ci.estimate("G21 G90\n" + half2 + "M2\n", m, start=np.array([60.0, 30.0, 20.0]))
    times = {t.tool: t.time_s for t in est.by_tool}
    dt = est.dt_s
    assert set(times) == {1, 2}
    assert times[1] == pytest.approx(first.cycle_time_s, abs=6 * dt)
    assert times[2] == pytest.approx(second.cycle_time_s, abs=6 * dt)
    ops = {o.name: o for o in est.by_operation}
    assert ops["first op"].time_s == pytest.approx(times[1], abs=6 * dt)
    assert ops["second op"].tool == 1 and ops["second op"].time_s == pytest.approx(times[2], abs=6 * dt)


def test_header_inside_a_run_waits_for_its_end():
    """A header between two feed moves of one run does not cut the run: it takes effect when
    the run ends; MSG comments are no headers."""
    text = "G21 G90\n(cut)\nG1 X10 F600\n(finish)\nG1 X20\n(MSG, hello)\nG0 Z5\nM2\n"
    est = ci.estimate(text, "generic-mill")
    assert_sums(est)
    ops = {o.name: o.time_s for o in est.by_operation}
    assert set(ops) == {"cut", "finish"}
    # rest samples (at most a few at each joint and end) are the only slack
    assert ops["cut"] == pytest.approx(est.by_kind["feed"], abs=6 * est.dt_s)
    assert ops["finish"] == pytest.approx(est.by_kind["rapid"], abs=6 * est.dt_s)


# -- the classifier ------------------------------------------------------------------------
class _M:
    axes = "XY"
    vmax = np.array([100.0, 200.0])
    amax = np.array([1000.0, 1000.0])
    jmax = np.array([1e5, 1e5])


def test_classify_limits_codes():
    dt = 0.001
    m = _M()
    k = np.arange(50)[:, None]
    still = np.zeros((50, 2))
    assert (classify_limits(still, dt, m) == CODE_REST).all()
    # Y at constant speed, the samples before carried in (no start transient)
    for frac, code in ((0.5, CODE_TRANSITION), (1.0, CODE_LIMIT0 + 3 * 1 + 0)):
        step = np.array([0.0, frac * m.vmax[1] * dt])
        q = (k + 3) * step
        head = np.arange(3)[:, None] * step
        codes = classify_limits(q, dt, m, head=head)
        assert (codes == code).all(), (frac, np.unique(codes))
        assert (
            classify_limits(q, dt, m, head=head, at_feed=np.ones(50, bool)) == (CODE_FEED if frac < 1 else code)
        ).all()
    # from rest without a head: the first step is an acceleration (and jerk) jump
    q = k * np.array([0.01, 0.0])
    codes = classify_limits(q, dt, m)
    names = code_names(m.axes)
    assert names[codes[1]] == "X jerk" and codes[0] == CODE_REST
    assert len(names) == CODE_LIMIT0 + 3 * len(m.axes)


# -- the command line ----------------------------------------------------------------------
def test_cli_json_schema(cli):
    res = cli("estimate", os.path.join(SAMPLES, "mill-contour.ngc"), "--json", "-q")
    assert res.exit_code == 0, res.output
    d = json.loads(res.output)
    for key, kind in {
        "cycle_time_s": float,
        "dt_s": float,
        "samples": int,
        "by_kind": dict,
        "by_tool": list,
        "by_operation": list,
        "by_lines": list,
        "limits": dict,
        "limits_by_kind": dict,
        "at_feed_s": float,
        "at_feed_share": float,
        "worst_ratio": float,
        "status": str,
    }.items():
        assert isinstance(d[key], kind), key
    assert set(d["by_kind"]) == set(KINDS)
    assert set(d["by_tool"][0]) == {"tool", "time_s", "line"}
    assert set(d["by_operation"][0]) == {"index", "name", "line", "tool", "time_s"}
    assert set(d["by_lines"][0]) == {"first", "last", "time_s"}
    assert d["worst_ratio"] <= 1.0
    assert abs(sum(d["by_kind"].values()) - d["cycle_time_s"]) <= d["dt_s"]


def test_cli_table(cli):
    res = cli("estimate", os.path.join(SAMPLES, "drilling-cycles.ngc"), "-q")
    assert res.exit_code == 0, res.output
    for heading in ("by kind", "by tool", "by operation", "by source lines", "binding limit"):
        assert heading in res.output
    assert "T4 (M6 at line 14)" in res.output


def test_compare_tol_replans_at_each_tolerance(cli):
    part = os.path.join(SAMPLES, "mill-contour.ngc")
    res = cli("estimate", part, "--json", "-q", "--tol", "0.02", "--compare-tol", "0.02", "--compare-tol", "0.002")
    assert res.exit_code == 0, res.output
    d = json.loads(res.output)
    assert [o["tol_mm"] for o in d["compare_tol"]] == [0.02, 0.002]
    # the tolerance in effect plans the same cycle again; another one plans its own
    assert d["compare_tol"][0]["cycle_time_s"] == d["cycle_time_s"]
    finer = cli("estimate", part, "--json", "-q", "--tol", "0.002")
    assert d["compare_tol"][1]["cycle_time_s"] == json.loads(finer.output)["cycle_time_s"]
    table = cli("estimate", part, "-q", "--tol", "0.02", "--compare-tol", "0.002")
    assert "cycle at --tol 0.002: " in table.output
    # a tolerance out of --tol's range is a usage error before anything is planned
    bad = cli("estimate", part, "-q", "--compare-tol", "-1")
    assert bad.exit_code == 2 and "--compare-tol" in bad.output


def test_bad_input_is_one_line_exit_2(tmp_path):
    bad = tmp_path / "bad.ngc"
    bad.write_text("G21 G90\nG1 X F100\n")
    r = run_proc("estimate", bad)
    assert r.code == 2
    lines = r.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"{bad}:2:") and "error:" in lines[0]
    r = run_proc("estimate", tmp_path / "missing.ngc")
    assert r.code == 2 and len(r.err.strip().splitlines()) == 1


def test_batch_record_has_the_breakdown():
    from cnc_interp.pipeline import process_program

    data = open(os.path.join(SAMPLES, "drilling-cycles.ngc"), "rb").read()
    rec = process_program("drilling-cycles.ngc", data, "generic-mill")
    est = rec["estimate"]
    assert abs(sum(est["by_kind"].values()) - rec["cycle_time_s"]) <= 0.001 + 1e-12
    assert [t["tool"] for t in est["by_tool"]] == [3, 4]
    json.dumps(rec, allow_nan=False)

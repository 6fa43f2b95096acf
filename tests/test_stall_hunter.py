"""No path ends in "VPOp made no progress" — a stall falls back to the safe
planner, whole or (once samples are out) after a brake to rest; the stall hunter's
seeded slices (``benchmarks/stall_hunter.py``) and the failures it found."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest
from numpy.testing import assert_array_equal

import cnc_interp

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "benchmarks"))

import stall_hunter  # noqa: E402

XZA = stall_hunter.MACHINES["xza-rotary"]

#: stall hunter seed 2, program 431 (XZA, a rotary machine's limits): a G93 Z+A move of 0.9 µm
#: at 7.9e-5 mm/s. VPOp crawled 0.068 µm and stood still until max_steps (2.4 million
#: samples): whole, it fell back to the safe planner; streamed (``cnc-interp plan``'s
#: windows) it had handed samples out and ended in "VPOp made no progress" (exit 1)
G93_ZA = """G21 G90 G94 G17
G64 P0.05
G0 X3.3205 Z-4.5637 A0
G93
G0 X3.3203 Z-4.5637 A0.0741
G1 X3.3203 Z-4.0919 A2.996 F28.512
G1 X3.3203 Z-4.092 A-40.9573 F47.13
G1 X3.3203 Z-4.0927 A-49.7945 F545.946
G94
M2
"""
G93_ZA_END = [3.3203, -4.0927, -49.7945]

#: stall hunter seed 2, program 263 (the XYZAC trunnion example): C turns with Z steps of
#: 0.1-3 µm; VPOp stalls mid-path (s = 0.00049 of 0.0041) and the safe planner plans it
TRUNNION = """G21 G90 G94 G17
G0 X4.10165 Y-1.2263 Z100.07309 A0 C0
G1 X4.10165 Y-1.2263 Z100.08649 A-2.34166 C7.57783 F17138.29
G1 X4.10166 Y-1.22629 Z100.08648 A-2.34166 C8.24713
G0 X4.10166 Y-1.22629 Z100.08641 A-2.34166 C59.31122
G1 X4.10166 Y-1.22629 Z100.08651 A-2.34166 C-10.87077
G1 X4.10166 Y-1.22629 Z100.08986 A-2.34166 C-27.08881 F14346.5
G1 X4.10166 Y-1.22629 Z100.08986 A-2.34166 C-27.08881
G0 X4.10166 Y-1.22629 Z100.08391 A-2.34166 C1.69156
M2
"""


#: stall hunter seed 11, program 186 (XZA): G93 A turns with sub-µm X/Z steps; one
#: 0.00014° move at F86 (2e-4 °/s) made VPOp's rough duration 5e8 samples and its first
#: buffer a MemoryError (the first buffer is now at most ``VPOP_FIRST_BUFFER``)
G93_TURNS = """G21 G90 G94 G17
G64 P0.05
G0 X-1.74959 Z1.7817 A-79.45251
G93
G0 X-1.74959 Z1.7817 A-79.45251
G1 X-1.74959 Z1.7817 A-120.33655 F3249.529
G1 X-1.7496 Z1.7817 A-120.30868 F282.66
G1 X-1.74968 Z1.78179 A-252.90701 F143.853
G1 X-1.74968 Z1.78179 A-252.90715 F86.096
G1 X-1.74968 Z1.78179 A-359.45123 F336.971
G1 X-1.74982 Z1.78161 A-359.45168 F4983.014
G94
M2
"""


@pytest.mark.parametrize("stream", [False, True], ids=["whole", "streamed"])
def test_g93_tiny_feed_segment_plans(stream):
    gen = stall_hunter.Generated(G93_TURNS, "xza-rotary", [-1.74982, 1.78161, -359.45168])
    out = stall_hunter.check(gen, "vpop", name="g93-turns.ngc", stream=stream)
    assert out.what == "ok", out.message


def _machine(name: str):
    return stall_hunter.load(name)


@pytest.mark.parametrize("stream", [False, True], ids=["whole", "streamed"])
def test_g93_za_crawl_falls_back(stream):
    gen = stall_hunter.Generated(G93_ZA, "xza-rotary", G93_ZA_END)
    out = stall_hunter.check(gen, "vpop", name="g93-za.ngc", stream=stream)
    assert out.what == "ok", out.message
    assert out.safe >= 1  # the stalled path went to the safe planner


def test_trunnion_stall_mid_path_falls_back():
    gen = stall_hunter.Generated(TRUNNION, "xyzac-trt-example", [4.10166, -1.22629, 100.08391, -2.34166, 1.69156])
    out = stall_hunter.check(gen, "vpop", name="trunnion.ngc")
    assert out.what == "ok", out.message


def test_streamed_and_whole_plans_are_the_same():
    """The stall is found at the first hand-out, before any sample is out: the streamed
    plan is the whole one (the safe planner's from the start)."""
    m = _machine("xza-rotary")
    whole = cnc_interp.run(G93_ZA.encode(), m, planner="vpop", name="g93-za.ngc")
    streamed = stall_hunter._run_streamed(G93_ZA.encode(), m, "vpop", "g93-za.ngc")
    assert_array_equal(whole.trajectory.q, streamed.trajectory.q)


@pytest.mark.parametrize("cut", [0.2, 0.5, 0.9])
def test_rescue_from_mid_path_holds_the_limits(cut):
    """``vpop.planner.rescue``: from any state VPOp handed out, a brake to rest and the
    safe planner for the rest, on VPOp's own table: every limit holds across the join
    and the plan ends exactly on the path's end."""
    from cnc_interp.fit.path import Path
    from cnc_interp.plan.verify import verify_arrays
    from cnc_interp.plan.vpop import plan_path_vpop
    from cnc_interp.plan.vpop.planner import _Prepared, rescue

    m = _machine("xyza-rotary")
    prog = cnc_interp.read_program(b"G0 X0 Y0 Z0 A0\nG1 X5 Y2 Z-1 A40 F3000\nG1 X9 Y-3 A-20\nM2\n", machine=m)
    path = [p for p in cnc_interp.fit(prog, machine=m).items if isinstance(p, Path) and not p.rapid][0]
    full = plan_path_vpop(path, None, m, m.dt_s)
    k = int(cut * full.s.shape[0])
    prep = _Prepared(path, None, m, m.dt_s, None)
    rest = rescue(prep, full.s[k - 3 : k], full.q[k - 3 : k], None, m, None, "test")
    s = np.concatenate((full.s[:k], rest.s))
    q = np.concatenate((full.q[:k], rest.q))
    rep = verify_arrays(q, m.dt_s, m.vmax, m.amax, m.jmax)
    assert rep.ok, rep.format()
    assert np.all(np.diff(s) >= 0)
    assert s[-1] == prep.L
    assert_array_equal(q[-1], full.q[-1])
    assert rest.stats["safe"] and rest.stats["fallback"] == "test"


def test_safe_from_s_start_matches_the_table():
    """``plan_path_safe(s_start=...)`` starts at rest at s_start and ends on the end."""
    from cnc_interp.fit.path import Path
    from cnc_interp.plan.safe import plan_path_safe
    from cnc_interp.plan.verify import verify_arrays
    from cnc_interp.plan.vpop import JointTable, _eval_table

    m = _machine("xza-rotary")
    prog = cnc_interp.read_program(b"G0 X0 Z0 A0\nG1 X0.01 Z-0.02 A90 F100\nG1 X0.02 A180\nM2\n", machine=m)
    path = [p for p in cnc_interp.fit(prog, machine=m).items if isinstance(p, Path) and not p.rapid][0]
    table = JointTable(path, None)
    s0 = 0.4 * table.length
    plan = plan_path_safe(path, None, m, m.dt_s, table=table, s_start=s0)
    assert plan.s[0] == s0 and plan.s[-1] == table.length
    assert_array_equal(plan.q[0], _eval_table(table.S, table.C, np.array([s0]))[0])
    rep = verify_arrays(plan.q, m.dt_s, m.vmax, m.amax, m.jmax)
    assert rep.ok, rep.format()


def _slice(planner: str, count: int, seed: int, stream: bool = False):
    fig = stall_hunter.hunt(count, seed, planner, log=lambda *a: None, stream=stream)
    assert fig["failed"] == 0, fig["messages"]


def test_hunter_is_seeded():
    a, b = stall_hunter.generate(3, 17), stall_hunter.generate(3, 17)
    assert a.text == b.text and a.machine == b.machine
    assert stall_hunter.generate(3, 18).text != a.text


def test_hunter_slice_vpop():
    _slice("vpop", 200, 11)


def test_hunter_slice_vpop_streamed():
    _slice("vpop", 60, 12, stream=True)


def test_hunter_slice_optimal():
    _slice("optimal", 40, 13)


@pytest.mark.slow
@pytest.mark.parametrize("planner", ["vpop", "optimal", "constant", "variable"])
def test_hunter_big(planner):
    # sized for CI's slow lane (a few minutes); benchmarks/stall_hunter.py runs the thousands
    _slice(planner, 600 if planner == "vpop" else 150, 21)

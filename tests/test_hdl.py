"""The Amaranth datapath (hdl/) is bit-exact with the golden model (CI subset of benchmarks/hdl.py).

The whole comparison (≥150k samples) and the synthesis are ``benchmarks/hdl.py``'s job;
here: ≥10k samples from the lathe sample's stream and seeded random curves, through the
Verilog Amaranth generates, under Verilator (Icarus as a fallback), plus a short run in
Amaranth's own simulator and the overflow flag.
"""

import os

import numpy as np
import pytest

amaranth = pytest.importorskip("amaranth", reason="needs the [hdl] extra (amaranth)")

from cnc_interp.fpga.commands import StreamOptions, build_stream  # noqa: E402
from cnc_interp.fpga.fixed import FpgaFormats  # noqa: E402
from cnc_interp.fpga.model import FixedSegment  # noqa: E402
from cnc_interp.fpga.program import build_program  # noqa: E402
from hdl import iverilog_sim  # noqa: E402
from hdl.datapath import SAMPLE_CYCLES  # noqa: E402
from hdl.sim import compare, golden_samples  # noqa: E402

from .fpga_cases import gentle_curve, quintic_plan  # noqa: E402


def _segments(prog):
    return [it for it in prog.items if isinstance(it, FixedSegment)]


def _random_segments(n, seed0=500):
    segs = []
    for seed in range(n):
        rng = np.random.default_rng(seed0 + seed)
        path = gentle_curve(int(rng.integers(3, 9)), seed=seed0 + seed)
        traj = quintic_plan(path, feed_mm_s=float(rng.uniform(5, 300)), dt_s=float(rng.choice([5e-4, 1e-3, 2e-3])))
        segs += _segments(build_program(traj, [path]))
    return segs


def test_amaranth_simulator_matches_golden_model():
    path = gentle_curve(3, seed=1)
    prog = build_program(quintic_plan(path, feed_mm_s=200.0), [path])
    bad, n, res = compare(prog)
    assert n > 150 and bad == 0 and not res.overflow
    # one sample every SAMPLE_CYCLES + 1 cycles, a few more at piece and segment changes
    assert SAMPLE_CYCLES + 1 <= res.cycles / n <= 64


@pytest.mark.slow
def test_verilog_datapath_bit_exact_ci_subset(tmp_path):
    tool = iverilog_sim.available()
    if tool is None:
        if os.environ.get("CI"):
            pytest.fail("CI must install verilator (see .ci/run)")
        pytest.skip("no Verilog simulator (apt-get install verilator)")
    prog, _, _ = build_stream(
        StreamOptions(part="samples/gcode/lathe-profile.ngc", machine_spec="xz-lathe", planner="variable", quiet=True)
    )
    segs = _segments(prog) + _random_segments(12)
    ref = golden_samples(segs, prog.formats)
    assert len(ref) >= 10_000
    res = iverilog_sim.simulate(segs, prog.formats, workdir=str(tmp_path))
    assert len(res.samples) == len(ref)
    mismatches = [k for k, (a, b) in enumerate(zip(res.samples, ref)) if tuple(a) != tuple(b)]
    assert mismatches == [], f"first mismatch at sample {mismatches[:1]}"
    assert not res.overflow
    assert res.cycles / len(ref) <= 64


def test_overflow_flag_is_raised_when_a_register_leaves_its_width(tmp_path):
    # a profile whose ξ overshoots the parameter word: the golden model refuses it, and the
    # hardware raises its sticky overflow flag (OVERRUN) instead of wrapping silently
    from dataclasses import replace

    from cnc_interp.fpga.fixed import FixedPointOverflow
    from cnc_interp.fpga.model import run_segment
    from hdl.sim import simulate

    path = gentle_curve(2, seed=3)
    prog = build_program(quintic_plan(path, feed_mm_s=100.0), [path])
    seg = _segments(prog)[0]
    big = replace(seg.pieces[0], exp=-10)  # ξ scaled by 2^43: far beyond Q2.33
    bad = replace(seg, pieces=(big,) + seg.pieces[1:])
    with pytest.raises(FixedPointOverflow):
        run_segment(bad, FpgaFormats())
    assert simulate([bad]).overflow
    assert not simulate([seg]).overflow

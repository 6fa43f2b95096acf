"""``stream`` and ``plan`` are the same motion: the device's setpoints (the frames of
``stream --dry-run`` run through the bit-exact model, as ``emulate`` does) pass ``verify``
against the machine's real limits, end on the plan's last point, and last as long as
``plan``'s setpoints up to the cost of the device margin (docs/fpga-protocol.md): the
stream plans against every limit scaled by 1 − δ, which makes a plan of ``constant`` or
``variable`` at most 1/(1 − δ) longer. VPOp's cycle is not continuous in the limits (its
braking decisions fall on whole samples), nor is the optimal planner's where it keeps
VPOp's plan: there the two may differ by up to ``JUMPY_REL``, either way.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from .conftest import CORPUS, SAMPLES

PLANNERS = ("optimal", "vpop", "constant", "variable")

#: samples the margin's bound may be off by: each path's plan ends on a whole sample
ROUNDING_SAMPLES = 2

#: planners whose cycle follows the limits continuously
CONTINUOUS = ("constant", "variable")
#: how far VPOp's cycle may move under the margin, relative (measured: 12 % on
#: arc_maxvel_xy, whose VPOp cycle moves 9 % when the limits change by 1e-6)
JUMPY_REL = 0.15


def _agree(part: str, machine_spec: str, planner: str) -> None:
    import cnc_interp as ci
    from cnc_interp.fpga.commands import StreamOptions, build_stream, emulate_frames
    from cnc_interp.fpga.fixed import FpgaFormats
    from cnc_interp.fpga.frames import decode_frame
    from cnc_interp.fpga.limits import device_margin
    from cnc_interp.fpga.model import to_mm
    from cnc_interp.machine.load import load_machine
    from cnc_interp.plan.verify import verify_arrays

    machine = load_machine(machine_spec)
    prog, frames, _ = build_stream(StreamOptions(part=part, machine_spec=machine_spec, planner=planner))
    device_q = to_mm(emulate_frames([decode_frame(f) for f in frames]).datapath.output().q, prog.formats)
    report = verify_arrays(
        device_q, machine.dt_s, machine.vmax, machine.amax, machine.jmax, axes=machine.axes, start=machine.start
    )
    assert report.ok, report.format()
    plan = ci.run(part, machine, planner=planner).trajectory
    delta = device_margin(machine, FpgaFormats())
    k_stream, k_plan = device_q.shape[0], plan.n_samples
    if planner in CONTINUOUS:
        assert k_plan - ROUNDING_SAMPLES <= k_stream <= k_plan / (1.0 - delta) + ROUNDING_SAMPLES, (k_stream, k_plan)
    else:
        assert abs(k_stream / k_plan - 1.0) <= JUMPY_REL, (k_stream, k_plan)
    # the same motion: the device ends where the plan ends
    np.testing.assert_allclose(device_q[-1], plan.q[-1], atol=1e-6)


@pytest.mark.parametrize("planner", PLANNERS)
def test_the_stream_is_the_plan_on_the_nurbs_sample(planner):
    _agree(os.path.join(SAMPLES, "nurbs-trident.ngc"), "generic-mill", planner)


@pytest.mark.slow
@pytest.mark.parametrize("planner", PLANNERS)
@pytest.mark.parametrize("sample", ["mill-contour.ngc", "drilling-cycles.ngc", "five-axis-xyzac.ngc"])
def test_the_stream_is_the_plan_on_every_sample(sample, planner):
    machine = "mikron-ucp710" if "five-axis" in sample else "generic-mill"
    _agree(os.path.join(SAMPLES, sample), machine, planner)


def _corpus_programs(n: int) -> list[str]:
    """The ``n`` smallest 3-axis corpus programs that plan on generic-mill (by name, stable)."""
    if not os.path.isdir(CORPUS):
        return [os.path.join(CORPUS, "absent.ngc")]
    found = []
    for d, _, files in os.walk(CORPUS):
        for f in files:
            if f.endswith(".ngc"):
                found.append(os.path.join(d, f))
    found.sort(key=lambda p: (os.path.getsize(p), p))
    return found[: n * 3]


@pytest.mark.slow
@pytest.mark.corpus
@pytest.mark.parametrize("planner", PLANNERS)
def test_the_stream_is_the_plan_on_twenty_corpus_programs(planner):
    from cnc_interp.errors import CncInterpError

    done = 0
    for part in _corpus_programs(20):
        try:
            _agree(part, "generic-mill", planner)
        except CncInterpError:
            continue  # a program this machine cannot run (an axis it lacks, a construct): not ours here
        done += 1
        if done == 20:
            break
    assert done == 20

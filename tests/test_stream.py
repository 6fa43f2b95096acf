"""The streaming plan: the same bytes whatever the window, bounded buffers, a path of
many moves streamed within itself, the parse and fit streams equal to the whole-program
stages, no output left on Ctrl-C mid-stream."""

from __future__ import annotations

import os
import signal
import subprocess
import time

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from cnc_interp.pipeline import PlanOptions, plan_part, stream_plan
from cnc_interp.plan.timeline import Window

from ._contract_helpers import SAMPLES, console_script

from .conftest import CORPUS  # noqa: E402

#: the smallest window there is: blocks of 7 samples, one path per job, nothing ahead
TINY = Window(block_samples=7, job_paths=1, job_samples=1, jobs_ahead=1, samples_ahead=1, path_window=1)

SAMPLE_MACHINES = {"five-axis-xyzac.ngc": "mikron-ucp710", "lathe-profile.ngc": "xz-lathe"}
CORPUS_PROGRAMS = [
    "quick-tests/arc-arc-test.ngc",
    "quick-tests/square_spiral.ngc",
    "quick-tests/tangent_helix.ngc",
    "quick-tests/sawtooth.ngc",
    "quick-tests/long-kink.ngc",
    "quick-tests/rapid_3d_corners.ngc",
    "quick-tests/spiral_tight_circular.ngc",
    "quick-tests/parabolic_varying.ngc",
    "performance/cap.ngc",
    "nurbs-g5/trident-xy.ngc",
]


def _plan_bytes(part, machine, out, window, threads, planner="vpop") -> bytes:
    stream_plan(
        PlanOptions(part=str(part), machine_spec=machine, planner=planner, out=str(out), quiet=True),
        window=window,
        threads=threads,
    )
    with open(out, "rb") as fh:
        return fh.read()


def _invariant(tmp_path, part, machine, planner="vpop"):
    for ext in ("csv", "mcap"):
        whole = _plan_bytes(part, machine, tmp_path / f"whole.{ext}", Window.whole(), 1, planner)
        tiny = _plan_bytes(part, machine, tmp_path / f"tiny.{ext}", TINY, 2, planner)
        default = _plan_bytes(part, machine, tmp_path / f"default.{ext}", None, 2, planner)
        assert whole == tiny, f"{part} {ext}: the tiny window changed the bytes"
        assert whole == default, f"{part} {ext}: the default window changed the bytes"
    return whole


@pytest.mark.parametrize("name", sorted(f for f in os.listdir(SAMPLES) if f.endswith(".ngc")))
def test_window_size_does_not_change_the_bytes_samples(tmp_path, name):
    _invariant(tmp_path, os.path.join(SAMPLES, name), SAMPLE_MACHINES.get(name, "generic-mill"))


@pytest.mark.corpus
@pytest.mark.parametrize("rel", CORPUS_PROGRAMS)
def test_window_size_does_not_change_the_bytes_corpus(tmp_path, rel):
    part = os.path.join(CORPUS, rel)
    _invariant(tmp_path, part, "generic-mill")


@pytest.mark.parametrize("name", ["mill-contour.ngc", "nurbs-trident.ngc"])
def test_window_size_does_not_change_the_bytes_optimal(tmp_path, name):
    _invariant(tmp_path, os.path.join(SAMPLES, name), SAMPLE_MACHINES.get(name, "generic-mill"), "optimal")


@pytest.mark.parametrize("planner", ["vpop", "optimal"])
def test_window_size_does_not_change_the_bytes_with_smooth_rapids_and_short_rests(tmp_path, planner):
    # a rapid chain with gentle kinks (one smooth path, which the optimal planner plans
    # itself), then cuts that stop and reverse: one period of rest at each joint
    part = tmp_path / "kinks.ngc"
    part.write_text(
        "G21 G90 G64 P0.01\nG0 X25.4\nG0 X25.654 Y0.0254\nG0 X50.8 Z2\nG1 Z0 F600\n"
        "G1 X40\nG1 X50.8\nG1 X40 Y1.9\nG1 X45 Y0\nG0 Z5\nM2\n"
    )
    _invariant(tmp_path, part, "generic-mill", planner)


@pytest.mark.parametrize("planner", ["constant", "variable"])
@pytest.mark.slow
def test_window_size_does_not_change_the_bytes_paper000(tmp_path, planner):
    _invariant(tmp_path, os.path.join(SAMPLES, "mill-contour.ngc"), "generic-mill", planner)


@pytest.mark.parametrize("planner", ["vpop", "optimal"])
def test_stream_equals_the_in_memory_plan(tmp_path, planner):
    """``cnc-interp plan`` (streamed) writes what ``plan_part`` plans (whole program)."""
    from cnc_interp.export.csv_io import write_csv
    from cnc_interp.export.mcap_io import read_mcap

    part = os.path.join(SAMPLES, "drilling-cycles.ngc")
    streamed = _plan_bytes(part, "generic-mill", tmp_path / "s.csv", None, 2, planner)
    outcome = plan_part(part, "generic-mill", planner)
    write_csv(outcome.trajectory, str(tmp_path / "m.csv"))
    assert streamed == (tmp_path / "m.csv").read_bytes()
    _plan_bytes(part, "generic-mill", tmp_path / "s.mcap", None, 2, planner)
    back = read_mcap(str(tmp_path / "s.mcap"))
    assert_array_equal(back.q, outcome.trajectory.q)
    assert back.settings["stats"] == outcome.trajectory.settings["stats"]


# -- one path of many moves streams within itself ------------------------------------------
def _spiral_path(n_moves: int):
    from cnc_interp.fit import FitSettings, fit_program
    from cnc_interp.gcode import read_program
    from cnc_interp.machine.load import load_machine

    m = load_machine("generic-mill")
    th = np.linspace(0.0, 40 * np.pi, n_moves)
    r = 5.0 + th
    lines = ["G21 G90 G64 F3000", f"G0 X{r[0]:.4f} Y0"]
    lines += [f"G1 X{r[i] * np.cos(th[i]):.4f} Y{r[i] * np.sin(th[i]):.4f} Z{0.001 * i:.4f}" for i in range(n_moves)]
    prog = read_program("\n".join(lines + ["M2"]).encode(), "spiral", axes=m.axes, start=m.start)
    paths = [p for p in fit_program(prog, FitSettings.from_options(machine=m)).paths if not p.rapid]
    assert len(paths) == 1
    return paths[0], m


@pytest.fixture()
def small_checkpoints(monkeypatch):
    """Checkpoints every 2048 samples, so that a path of a few 10^4 samples slides its
    buffers many times (the result depends on the checkpoint spacing only when a
    fast-mode failure is re-planned from one)."""
    from cnc_interp.plan.vpop import planner

    monkeypatch.setattr(planner, "VPOP_CHECKPOINT_SAMPLES", 2048)


def test_a_long_path_streams_in_bounded_chunks(small_checkpoints):
    from cnc_interp.plan.base import collect_path_plan
    from cnc_interp.plan.verify import verify_arrays
    from cnc_interp.plan.vpop import iter_path_plan_vpop, plan_path_vpop

    path, m = _spiral_path(4000)
    one = plan_path_vpop(path, None, m, m.dt_s)
    chunks = list(iter_path_plan_vpop(path, None, m, m.dt_s, window=1))
    assert len(chunks) >= 3, "the path was not handed out in pieces"
    assert all(not c.last for c in chunks[:-1]) and chunks[-1].last
    # each piece is at most the buffer (two checkpoints, the look-back and a brake run)
    assert max(c.s.shape[0] for c in chunks[:-1]) < one.s.shape[0]
    both = collect_path_plan(chunks)
    assert_array_equal(both.s, one.s)
    assert_array_equal(both.q, one.q)
    assert both.stats == one.stats
    assert verify_arrays(both.q, m.dt_s, m.vmax, m.amax, m.jmax).ok


@pytest.mark.slow
def test_a_fast_mode_failure_replans_from_the_last_checkpoint(small_checkpoints, monkeypatch):
    """A failure of the fast mode far into a path re-plans exactly from the last checkpoint
    (never from the start, which may have been handed out): the streamed and the whole
    result agree, and every limit holds."""
    from cnc_interp.plan.vpop import step as vpop_core
    from cnc_interp.plan.base import collect_path_plan
    from cnc_interp.plan.verify import verify_arrays
    from cnc_interp.plan.vpop import iter_path_plan_vpop

    path, m = _spiral_path(4000)
    real = vpop_core.plan_core.py_func
    calls = {"n": 0}

    def failing(*a):
        status = real(*a)
        calls["n"] += 1
        fast = a[5].fast  # plan_core(pb, sh, qh, st, runs, cfg, stop_k, k_base)
        if fast and status == vpop_core.YIELD and calls["n"] == 6:
            return vpop_core.INFEASIBLE  # as if a shortened brake run misjudged a state
        return status

    import cnc_interp.plan.vpop.drive as D

    monkeypatch.setattr(D.core, "plan_core", failing)
    monkeypatch.setattr(D, "drive", D.drive.py_func)
    calls["n"] = 0
    whole = collect_path_plan(iter_path_plan_vpop(path, None, m, m.dt_s, window=None))
    calls["n"] = 0
    streamed = collect_path_plan(iter_path_plan_vpop(path, None, m, m.dt_s, window=1))
    assert whole.stats["exact"] and streamed.stats["exact"]
    assert_array_equal(whole.q, streamed.q)
    assert verify_arrays(whole.q, m.dt_s, m.vmax, m.amax, m.jmax).ok


# -- the stages' streams ---------------------------------------------------------------------
@pytest.mark.parametrize("name", ["drilling-cycles.ngc", "mill-contour.ngc", "nurbs-trident.ngc"])
def test_parse_and_fit_streams_equal_the_whole_program(name):
    from cnc_interp.fit import FitSettings, fit_program
    from cnc_interp.fit.fitter import iter_fit
    from cnc_interp.fit.path import Path
    from cnc_interp.gcode import read_program
    from cnc_interp.gcode.stream import iter_program
    from cnc_interp.machine.load import load_machine

    m = load_machine("generic-mill")
    data = open(os.path.join(SAMPLES, name), "rb").read()
    whole = read_program(data, name, axes=m.axes, start=m.start)
    items = list(iter_program(data, name, m.axes, m.start))
    assert [type(i) for i in items] == [type(i) for i in whole.items]
    for a, b in zip(items, whole.items):
        for f in ("nodes", "line", "feed_mm_s", "position"):
            if hasattr(a, f) and getattr(a, f) is not None:
                assert_array_equal(getattr(a, f), getattr(b, f))
    fitted = fit_program(whole, FitSettings())
    stats: dict = {}
    streamed = list(iter_fit(items, FitSettings(), stats, batch=3))
    assert len(streamed) == len(fitted.items)
    for a, b in zip(streamed, fitted.items):
        assert type(a) is type(b)
        if isinstance(a, Path):
            assert_array_equal(a.coef, b.coef)
            assert_array_equal(a.s_breaks, b.s_breaks)
    assert stats["segments_out"] == fitted.stats["segments_out"]


def test_a_parse_error_reaches_the_consumer_where_it_is():
    from cnc_interp.errors import GCodeError
    from cnc_interp.gcode.stream import iter_program

    text = b"G21 G90 F600\nG1 X1\nG1 X2\nG1 Q7\n"
    got = []
    with pytest.raises(GCodeError) as ei:
        for item in iter_program(text, "bad.ngc", "XYZ"):
            got.append(item)
    assert ei.value.location.line == 4


# -- Ctrl-C mid-stream -----------------------------------------------------------------------
def _written_bytes(pid: int, folder) -> int:
    """Size of the (unnamed) file process ``pid`` has open in ``folder``, or -1."""
    prefix = os.path.realpath(folder) + os.sep
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
            if target.startswith(prefix):
                return os.stat(f"/proc/{pid}/fd/{fd}").st_size
        except OSError:
            pass
    return -1


@pytest.mark.slow
@pytest.mark.corpus
def test_ctrl_c_after_rows_were_written_leaves_no_file(tmp_path):
    """SIGINT once rows are in the (unnamed) output file: no output file, no temporary."""
    part = os.path.join(CORPUS, "performance", "stellabee1.ngc")
    if not os.path.exists(part):
        pytest.skip("corpus not beside the repository")
    work = tmp_path / "run"
    work.mkdir()
    proc = subprocess.Popen(
        [console_script(), "plan", part, "-m", "generic-mill", "-o", "out.csv"],
        cwd=work,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        t0 = time.monotonic()
        while proc.poll() is None and time.monotonic() - t0 < 240:
            if _written_bytes(proc.pid, work) > 1_000_000:
                break
            time.sleep(0.02)
        assert proc.poll() is None, "the plan finished before it could be interrupted"
        assert _written_bytes(proc.pid, work) > 1_000_000, "no rows were written"
        assert os.listdir(work) == []
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=120)
        err = proc.stderr.read().decode("utf-8", "replace")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert os.listdir(work) == [], f"left behind: {os.listdir(work)}"
    assert code in (130, -signal.SIGINT), (code, err)
    assert "Traceback" not in err, err

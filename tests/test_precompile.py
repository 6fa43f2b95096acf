"""First run: VPOp's step loop compiled by a child process (``plan.precompile``)."""

from __future__ import annotations

import os
import sys
import time

import pytest

from cnc_interp.plan import precompile


@pytest.fixture
def sleeping_children(monkeypatch):
    """Children that sleep instead of compiling, on a cache that looks cold."""
    monkeypatch.setattr(
        precompile, "_command", lambda job, also=(): [sys.executable, "-c", "import time; time.sleep(60)"]
    )
    monkeypatch.setattr("cnc_interp._kernel_cache.missing_kernels", lambda root, modules=None: ["plan.vpop.step"])
    yield
    precompile.stop()


def test_no_children_when_the_planner_kernels_are_cached(monkeypatch):
    # (a fit kernel of the plan missing: no child; the batch fitter's: cached)
    monkeypatch.setattr(
        "cnc_interp._kernel_cache.missing_kernels", lambda root, modules=None: [] if modules else ["fit._arclen"]
    )
    monkeypatch.setattr("cnc_interp._kernel_cache.kernel_cached", lambda root, module, function: True)
    assert not precompile.start()
    assert precompile._children == []
    t0 = time.perf_counter()
    precompile.wait()  # nothing to wait for
    assert time.perf_counter() - t0 < 0.1


def test_one_child_per_job_and_stop_kills_them(sleeping_children):
    assert precompile.start()
    assert precompile.start()  # a second call starts no more
    procs = list(precompile._children)
    assert len(procs) == len(precompile.JOBS) and all(p.poll() is None for p in procs)
    precompile.stop()
    assert all(p.poll() is not None for p in procs) and precompile._children == []


def test_wait_gives_up_on_a_child_that_hangs(sleeping_children):
    assert precompile.start()
    procs = list(precompile._children)
    t0 = time.perf_counter()
    precompile.wait(timeout_s=0.2)
    assert time.perf_counter() - t0 < 5
    assert all(p.poll() is not None for p in procs) and precompile._children == []


def _ready_then_sleep(job, also=()):
    return [sys.executable, "-c", "import os, time; os.write(1, b'ready\\n'); time.sleep(60)"]


def test_a_ready_child_is_waited_for_only_until_its_line(monkeypatch):
    """The parent waits for the step loop (the ready line), not for the batch driver the
    child compiles next; it plans path by path meanwhile, and leaves the child to finish
    when the command ends (Ctrl-C or an error still kill it: ``stop``)."""
    monkeypatch.setattr(precompile, "_command", _ready_then_sleep)
    monkeypatch.setattr("cnc_interp._kernel_cache.missing_kernels", lambda root, modules=None: ["plan.vpop.step"])
    try:
        assert precompile.start()
        (proc,) = precompile._children
        t0 = time.perf_counter()
        assert precompile.wait(timeout_s=30) == [0]
        assert time.perf_counter() - t0 < 20 and proc.poll() is None
        assert precompile.batch_pending()
        precompile._at_exit()
        assert proc.poll() is None  # still compiling the batch driver
    finally:
        precompile.stop()
    assert proc.poll() is not None and not precompile.batch_pending()


def test_only_the_batch_missing_starts_a_child_nobody_waits_for(monkeypatch):
    monkeypatch.setattr(
        precompile,
        "_command",
        lambda job, also=(): [sys.executable, "-c", f"import time; assert {job!r} == 'batch'; time.sleep(60)"],
    )
    monkeypatch.setattr("cnc_interp._kernel_cache.missing_kernels", lambda root, modules=None: [])
    monkeypatch.setattr("cnc_interp._kernel_cache.kernel_cached", lambda root, module, function: False)
    try:
        assert precompile.start()
        t0 = time.perf_counter()
        assert precompile.wait() == []
        assert time.perf_counter() - t0 < 0.5 and precompile.batch_pending()
    finally:
        precompile.stop()


@pytest.mark.parametrize("planner", ["vpop", "optimal"])
def test_paths_planned_one_at_a_time_while_the_batch_compiles(monkeypatch, planner):
    """While a child compiles the batch driver, VPOp plans each path on its own (and the
    optimal planner each path it routes to VPOp): the same samples as the batch (the
    first run's output is the next runs')."""
    import numpy as np

    from cnc_interp import api

    m = api.load_machine("generic-mill")
    fitted = api.fit(api.read_program("samples/gcode/mill-contour.ngc", machine=m))
    batch = api.plan(fitted, m, planner=planner)
    monkeypatch.setattr(precompile, "batch_pending", lambda: True)
    one_by_one = api.plan(fitted, m, planner=planner)
    assert one_by_one.settings["stats"].get("routes") == batch.settings["stats"].get("routes")
    np.testing.assert_array_equal(one_by_one.q, batch.q)
    np.testing.assert_array_equal(one_by_one.s, batch.s)
    np.testing.assert_array_equal(one_by_one.line, batch.line)


def test_unknown_job_is_a_usage_error(capsys):
    assert precompile.main(["everything"]) == 2
    assert "usage" in capsys.readouterr().err
    assert precompile.main(["loop", "export._repr.warm_up"]) == 2  # not module:function
    assert "usage" in capsys.readouterr().err


def test_the_child_command_names_its_job_and_the_callers_warm_ups():
    cmd = precompile._command("loop", ("export._repr:warm_up",))
    assert cmd[1:] == ["-m", "cnc_interp.plan.precompile", "loop", "export._repr:warm_up"]


@pytest.mark.slow
def test_the_child_leaves_the_step_loop_cached(tmp_path, monkeypatch):
    """On an empty cache, after the child, this process loads the batch driver (with the
    step loop below it) from the cache and does not compile it (a signature that differs
    from the real call's would make it compile the tree again: the work would be done
    twice)."""
    import subprocess

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    code = (
        "from cnc_interp.plan import precompile\n"
        "from cnc_interp.plan.vpop import drive as D\n"
        "from cnc_interp import api\n"
        "assert precompile.start(also=('export._repr:warm_up',))\n"
        "precompile.compile_preparation()\n"
        "assert precompile.wait() == [0], 'the child failed'\n"
        "assert precompile.finish() == [0], 'the batch job failed'\n"
        "from cnc_interp.export import _repr\n"
        "_repr.warm_up()\n"
        "assert sum(_repr._format_table.stats.cache_hits.values()) == 1, _repr._format_table.stats\n"
        "m = api.load_machine('generic-mill')\n"
        "api.run('samples/gcode/mill-contour.ngc', machine=m)\n"
        "assert sum(D.drive.stats.cache_misses.values()) == 0, D.drive.stats\n"
        "assert sum(D.prepare_identity.stats.cache_misses.values()) == 1\n"
        "assert sum(D.plan_identity_batch.stats.cache_hits.values()) == 1, D.plan_identity_batch.stats\n"
        "assert sum(D.plan_identity_batch.stats.cache_misses.values()) == 0\n"
    )
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    r = subprocess.run([sys.executable, "-c", code], cwd=root, env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]


def test_the_fit_does_not_compile_what_a_child_compiles(monkeypatch):
    """While a first run's child compiles the batch fitter's kernels, even a long run
    keeps the Python fitter (the same paths) instead of compiling them a second time."""
    from cnc_interp import _kernel_cache
    from cnc_interp.fit import fitter

    monkeypatch.setattr(fitter, "_kernels_ready", False)
    monkeypatch.setattr(_kernel_cache, "background_check", lambda: True)
    assert not fitter._batch_kernels_ready(10 * fitter.FIT_KERNEL_COMPILE_NODES)
    assert not fitter._kernels_ready
    monkeypatch.setattr(_kernel_cache, "background_check", lambda: False)
    assert fitter._batch_kernels_ready(10 * fitter.FIT_KERNEL_COMPILE_NODES)


@pytest.mark.parametrize("planner,child", [("vpop", True), ("optimal", True), ("constant", False)])
def test_a_first_run_of_the_planners_that_use_vpops_step_loop_starts_the_child(monkeypatch, planner, child):
    from cnc_interp import pipeline

    started = []
    monkeypatch.setattr(precompile, "start", lambda also=(): started.append(also) or False)
    pipeline._warm_kernels(planner)
    assert bool(started) == child

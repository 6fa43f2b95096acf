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
    monkeypatch.setattr("cnc_interp._kernel_cache.missing_kernels", lambda root: ["plan.vpop.step"])
    yield
    precompile.stop()


def test_no_children_when_the_planner_kernels_are_cached(monkeypatch):
    monkeypatch.setattr("cnc_interp._kernel_cache.missing_kernels", lambda root: ["fit._arclen"])
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
    """On an empty cache, after the child, this process loads the step loop from the cache
    and does not compile it (a signature that differs from the real call's would make it
    compile the tree again: the work would be done twice)."""
    import subprocess

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    code = (
        "from cnc_interp.plan import precompile\n"
        "from cnc_interp.plan.vpop import drive as D\n"
        "from cnc_interp import api\n"
        "assert precompile.start(also=('export._repr:warm_up',))\n"
        "precompile.compile_preparation()\n"
        "assert precompile.wait() == [0], 'the child failed'\n"
        "from cnc_interp.export import _repr\n"
        "_repr.warm_up()\n"
        "assert sum(_repr._format_table.stats.cache_hits.values()) == 1, _repr._format_table.stats\n"
        "m = api.load_machine('generic-mill')\n"
        "api.run('samples/gcode/mill-contour.ngc', machine=m)\n"
        "assert sum(D.drive.stats.cache_hits.values()) == 1, D.drive.stats\n"
        "assert sum(D.drive.stats.cache_misses.values()) == 0, D.drive.stats\n"
        "assert sum(D.prepare_identity.stats.cache_misses.values()) == 1\n"
        "assert sum(D.plan_identity_batch.stats.cache_misses.values()) == 1\n"
    )
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    r = subprocess.run([sys.executable, "-c", code], cwd=root, env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]

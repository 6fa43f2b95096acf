"""First run: the kernel groups a planner needs, compiled once per cache (``precompile``)."""

from __future__ import annotations

import io
import os
import subprocess
import sys
import textwrap
import time

import pytest

from cnc_interp import precompile

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


class _Tty(io.StringIO):
    def isatty(self):
        return True


@pytest.mark.parametrize("planner", sorted(precompile.PLANNER_GROUPS))
def test_the_schedule_compiles_each_group_once_after_what_it_links(planner):
    names = list(precompile.PLANNER_GROUPS[planner])
    costs = {n: precompile.GROUPS[n].cost_s for n in names}
    shares, total = precompile._schedule(names, costs)
    assert sorted(shares[0] + shares[1]) == sorted(names)
    # two processes: never faster than half the work (plus the worker's start), never
    # slower than one process doing everything
    assert sum(costs.values()) / 2 <= total <= sum(costs.values()) + precompile.WORKER_START_S
    for share in shares:  # within one process a group comes after its dependencies there
        for i, g in enumerate(share):
            assert not set(precompile.GROUPS[g].after) & set(share[i + 1 :])


def test_the_schedule_in_closed_form():
    # ranked a, b, c: this process takes a at 0, the worker b once started
    # (WORKER_START_S); c needs both, so this process waits for b and then compiles it
    groups = {
        "a": precompile.KernelGroup("a", (), "", 10.0),
        "b": precompile.KernelGroup("b", (), "", 20.0),
        "c": precompile.KernelGroup("c", (), "", 5.0, ("a", "b")),
    }
    saved = dict(precompile.GROUPS)
    try:
        precompile.GROUPS.update(groups)
        costs = {n: g.cost_s for n, g in groups.items()}
        shares, total = precompile._schedule(["a", "b", "c"], costs)
        # ranked b first: this process takes b at 0, the worker a at WORKER_START_S
        shares_b, total_b = precompile._schedule(["a", "b", "c"], costs, ["b", "a", "c"])
        order, best = precompile.best_order(["a", "b", "c"])
    finally:
        precompile.GROUPS.clear()
        precompile.GROUPS.update(saved)
    assert shares == [["a", "c"], ["b"]]
    assert total == pytest.approx(precompile.WORKER_START_S + 20.0 + 5.0)
    assert shares_b == [["b", "c"], ["a"]] and total_b == pytest.approx(25.0)
    assert order == ["b", "a", "c"] and best == pytest.approx(25.0)


def test_nothing_missing_takes_no_lock_and_compiles_nothing(monkeypatch, tmp_path):
    monkeypatch.setattr(precompile, "missing_groups", lambda planner, root=None: [])
    monkeypatch.setattr(precompile, "_CacheLock", None)  # would raise if used
    tty = _Tty()
    assert precompile.ensure("vpop", stream=tty, root=str(tmp_path)) == []
    assert tty.getvalue() == ""


def test_a_process_that_finds_the_cache_locked_waits_and_then_compiles_nothing(monkeypatch, tmp_path):
    # another process holds the lock while it compiles; when it lets go, the groups are
    # cached and this one has nothing left to do
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    root = tmp_path / "pkg"
    (root / "__pycache__").mkdir(parents=True)
    lock = root / "__pycache__" / precompile.LOCK_NAME
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import fcntl, os, sys, time\n"
            f"fd = os.open({str(lock)!r}, os.O_RDWR | os.O_CREAT)\n"
            "fcntl.flock(fd, fcntl.LOCK_EX)\nprint('locked', flush=True)\ntime.sleep(1.5)\n",
        ],
        stdout=subprocess.PIPE,
    )
    try:
        assert holder.stdout.readline() == b"locked\n"
        calls = []

        def missing(planner, root=None):
            calls.append(time.perf_counter())
            return ["csv"] if len(calls) == 1 else []

        compiled = []
        monkeypatch.setattr(precompile, "missing_groups", missing)
        monkeypatch.setattr(precompile, "_compile", lambda names, stream: compiled.append(names))
        tty = _Tty()
        t0 = time.perf_counter()
        assert precompile.ensure("vpop", stream=tty, root=str(root)) == []
        assert time.perf_counter() - t0 > 0.5  # it waited for the holder
        assert "waiting for another cnc-interp process" in tty.getvalue()
        assert compiled == [] and len(calls) == 2
    finally:
        holder.kill()
        holder.wait()


def test_a_first_run_says_its_estimate_and_each_group_compiled(monkeypatch, tmp_path):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    done = []
    names = ["fit", "csv", "vpop-prep"]
    monkeypatch.setattr(precompile, "missing_groups", lambda planner, root=None: [] if done else list(names))
    monkeypatch.setattr(precompile, "warm_up", lambda name: done.append(name))
    monkeypatch.setattr(precompile._Worker, "start", classmethod(lambda cls: None))  # all here
    tty = _Tty()
    assert precompile.ensure("constant", stream=tty, root=str(tmp_path)) == names
    lines = tty.getvalue().splitlines()
    est = precompile.estimate_s(names)
    assert lines[0] == (
        f"cnc-interp: first run: compiling the constant planner's kernels, about {est:.0f} s "
        "on 2 cores, cached for next time"
    )
    assert [line.split()[2] for line in lines[1:]] == precompile.best_order(names)[0]
    assert sorted(done) == sorted(names) and lines[-1].startswith("cnc-interp: compiled ") and "3 of 3" in lines[-1]


def test_a_worker_that_fails_leaves_its_group_to_this_process(monkeypatch):
    class Failing:
        sent: list = []
        closed = False

        def send(self, name):
            self.sent.append(name)
            return True

        def word(self, name, timeout_s=None):
            return False if timeout_s is None else None

        def close(self):
            Failing.closed = True

    done = []
    monkeypatch.setattr(precompile._Worker, "start", classmethod(lambda cls: Failing()))
    monkeypatch.setattr(precompile, "warm_up", lambda name: done.append(name))
    names = list(precompile.PLANNER_GROUPS["vpop"])
    precompile._compile(names, None)
    assert sorted(done) == sorted(names) and Failing.closed
    assert Failing.sent and Failing.sent[0] in done  # the worker's group, done here after all


def test_the_worker_compiles_what_it_is_sent_and_ends_with_its_input():
    worker = precompile._Worker.start()
    assert worker is not None
    try:
        assert worker.send("csv")
        assert worker.word("csv") is True
        assert worker.send("no-such-group")
        assert worker.word("no-such-group") is False
        assert worker.proc.poll() is None
    finally:
        worker.close()
    assert worker.proc.returncode is not None


def test_the_worker_ends_when_the_command_that_started_it_dies():
    # the command is killed (SIGKILL: no clean-up of its own): the worker's input closes
    # and it ends at once, even in the middle of a compile
    code = textwrap.dedent(
        """
        import os, sys
        from cnc_interp import precompile
        w = precompile._Worker.start()
        w.send("optimal")
        print(w.proc.pid, flush=True)
        sys.stdin.read()
        """
    )
    parent = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, cwd=REPO)
    pid = int(parent.stdout.readline())
    parent.kill()
    parent.wait()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and _alive(pid):
        time.sleep(0.05)
    assert not _alive(pid), "the worker outlived the command"


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def test_the_worker_command_without_its_flag_is_a_usage_error():
    r = subprocess.run([sys.executable, "-m", "cnc_interp.precompile"], capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 2 and "usage" in r.stderr


@pytest.mark.slow
def test_after_a_first_run_the_plans_compile_nothing(tmp_path):
    """On an empty cache, ``ensure`` compiles every group of the optimal planner (in this
    process and the worker), leaves no process behind, and plans of samples with both
    planners then load every grouped kernel from the cache: a warm-up signature that
    differed from a real call's would compile it again."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    first = subprocess.run(
        [sys.executable, "-c", "from cnc_interp import precompile; print(precompile.ensure('optimal'))"],
        env=env,
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert first.returncode == 0, first.stderr[-3000:]
    assert "optimal" in first.stdout
    code = textwrap.dedent(
        """
        import sys
        from numba.core.registry import CPUDispatcher
        from cnc_interp import api, precompile
        assert precompile.missing_groups("optimal") == [], precompile.missing_groups("optimal")
        m = api.load_machine("generic-mill")
        for part in ("samples/gcode/mill-contour.ngc", "samples/gcode/nurbs-trident.ngc"):
            for planner in ("vpop", "optimal"):
                api.run(part, m, planner=planner)
        api.run(precompile.WARM_PROGRAM, m, planner="optimal")
        compiled = []
        for name, mod in list(sys.modules.items()):
            if not name.startswith("cnc_interp."):
                continue
            for attr, f in vars(mod).items():
                if isinstance(f, CPUDispatcher) and sum(f.stats.cache_misses.values()):
                    compiled.append(f"{name}.{attr}")
        grouped = [
            e.partition(":")[0] for g in precompile.PLANNER_GROUPS["optimal"] for e in precompile.GROUPS[g].cached
        ]
        print(sorted(c for c in compiled if any(c.startswith("cnc_interp." + m + ".") for m in grouped)))
        """
    )
    second = subprocess.run(
        [sys.executable, "-c", code], env=env, cwd=REPO, capture_output=True, text=True, timeout=900
    )
    assert second.returncode == 0, second.stderr[-3000:]
    assert second.stdout.strip().splitlines()[-1] == "[]"
    left = subprocess.run(["pgrep", "-f", "cnc_interp.precompile --worker"], capture_output=True, text=True)
    assert left.stdout == ""

"""The batch's isolated worker pool: results, crashes, timeouts, order."""

import os
import signal
import time

from cnc_interp.batch_workers import run_isolated, run_pool


def _square(job):
    return {"status": "ok", "value": job["x"] ** 2, "pid": os.getpid()}


def _misbehave(job):
    kind = job["kind"]
    if kind == "raise":
        raise ValueError("bad thing")
    if kind == "segv":
        os.kill(os.getpid(), signal.SIGSEGV)
    if kind == "exit":
        os._exit(3)
    if kind == "sleep":
        time.sleep(30)
    if kind == "big":
        return {"status": "ok", "blob": b"x" * 3_000_000}
    return {"status": "ok"}


def test_results_in_job_order_in_separate_processes():
    jobs = [{"x": i} for i in range(7)]
    seen = []
    res = run_pool(jobs, 3, None, func=_square, on_done=lambda i, r: seen.append(i))
    assert [r["value"] for r in res] == [i * i for i in range(7)]
    assert sorted(seen) == list(range(7))
    assert all(r["pid"] != os.getpid() for r in res)
    assert all(r["wall_s"] >= 0 and r["peak_mem_mb"] > 0 for r in res)


def test_failures_are_isolated():
    kinds = ["ok", "raise", "segv", "exit", "sleep", "big", "ok"]
    t0 = time.monotonic()
    res = run_pool([{"kind": k} for k in kinds], 2, 1.0, func=_misbehave)
    assert time.monotonic() - t0 < 20
    status = [r["status"] for r in res]
    assert status == ["ok", "crash", "crash", "crash", "timeout", "ok", "ok"]
    assert "ValueError: bad thing" in res[1]["message"]
    assert "SIGSEGV" in res[2]["message"]
    assert "status 3" in res[3]["message"]
    assert len(res[5]["blob"]) == 3_000_000  # large results cross the pipe intact


def test_run_isolated_single():
    assert run_isolated({"x": 4}, None, func=_square)["value"] == 16
    assert run_isolated({"kind": "sleep"}, 0.3, func=_misbehave)["status"] == "timeout"

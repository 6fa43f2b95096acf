"""Crash-isolated execution of batch jobs: one forked child process per program.

A child runs one job and sends its result dict back through a pipe. Whatever the
job does — raise, segfault, exhaust memory, loop forever — only that child dies:
the parent reads a crash, out-of-memory or timeout status for that program and
carries on. ``os.fork`` is used directly (POSIX) rather than ``multiprocessing``:
it is cheap once numpy and the stages are imported in the parent (the children
share them copy-on-write), and it also works inside Dask's daemonic worker
processes, where ``multiprocessing`` may not start children.

Peak memory is the child's maximum resident set size from ``os.wait4`` (it
includes the pages inherited from the parent that the child keeps mapped).
"""

from __future__ import annotations

import os
import pickle
import select
import signal
import time
import traceback
from dataclasses import dataclass, field
from typing import Callable

#: bytes read from a child's pipe per call
_READ_CHUNK = 1 << 16


def run_job(job: dict) -> dict:
    """``_run_job`` with Python warnings counted into the result instead of printed
    (a batch's standard error is for its progress bar and its own errors)."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = _run_job(job)
    result["warnings"] = len(caught)
    if caught:
        first = caught[0]
        result["first_warning"] = (
            f"{first.category.__name__}: {first.message} ({os.path.basename(first.filename)}:{first.lineno})"
        )
    return result


def _run_job(job: dict) -> dict:
    """Run one program through parse, fit, plan and verify; never raises for bad input.

    Returns the per-program result dict of ``pipeline.process_program`` with
    ``status`` "ok" / "violation", or status "error" with the message and line of
    a ``CncInterpError``, or "crash" for an unexpected exception (a bug).
    """
    from .errors import CncInterpError

    data = job.get("data")
    try:
        from .pipeline import process_program

        if data is None:
            from .inputfile import read_bounded

            with open(job["path"], "rb") as fh:
                data = read_bounded(fh, job["path"])
        return process_program(
            job["path"],
            data,
            job["machine"],
            planner=job["planner"],
            dt_s=job.get("dt_s"),
            tol_mm=job.get("tol_mm"),
            fit_method=job.get("fit_method"),
            effort=job.get("effort"),
        )
    except CncInterpError as exc:
        return {"status": "error", "message": exc.format(), "error_line": exc.location.line}
    except MemoryError:
        return {"status": "error", "message": "out of memory", "error_line": 0}
    except OSError as exc:
        return {"status": "error", "message": f"cannot read: {exc.strerror}", "error_line": 0}
    except Exception as exc:  # a bug in a stage: report it, keep the batch going
        tb = traceback.extract_tb(exc.__traceback__)
        where = f" at {os.path.basename(tb[-1].filename)}:{tb[-1].lineno}" if tb else ""
        return {"status": "crash", "message": f"internal error: {type(exc).__name__}: {exc}{where}", "error_line": 0}


def _child(func: Callable[[dict], dict], job: dict, wfd: int) -> None:
    """Body of a forked child: run, send the pickled result, exit without cleanup."""
    code = 0
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and kills us
        import faulthandler

        faulthandler.disable()  # a crash is reported as this job's status, not a dump on stderr
        from .fit.fitter import cap_default_threads

        cap_default_threads(1)  # the batch runs a child per core already
        result = func(job)
        payload = pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL)
    except BaseException as exc:  # noqa: BLE001 - nothing may escape a forked child
        payload = pickle.dumps({"status": "crash", "message": f"worker: {type(exc).__name__}: {exc}", "error_line": 0})
        code = 1
    try:
        view = memoryview(payload)
        while view:
            n = os.write(wfd, view)
            view = view[n:]
    except BaseException:  # noqa: BLE001
        code = 2
    finally:
        os._exit(code)  # never run the parent's atexit handlers or flush its buffers


@dataclass
class _Running:
    pid: int
    fd: int
    index: int
    started: float
    deadline: float
    chunks: list = field(default_factory=list)


def _finish(run: _Running, timed_out: bool) -> dict:
    """Reap a child and turn what it sent (or how it died) into a result dict."""
    if timed_out:
        try:
            os.kill(run.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    _, status, usage = os.wait4(run.pid, 0)
    os.close(run.fd)
    wall = time.monotonic() - run.started
    peak_mb = usage.ru_maxrss / 1024.0  # Linux reports KiB
    if timed_out:
        result = {"status": "timeout", "message": "time limit exceeded", "error_line": 0}
    else:
        raw = b"".join(run.chunks)
        result = None
        if raw:
            try:
                result = pickle.loads(raw)
            except Exception:  # noqa: BLE001 - a truncated pipe from a dying child
                result = None
        if result is None:
            if os.WIFSIGNALED(status):
                sig = os.WTERMSIG(status)
                name = signal.Signals(sig).name if sig in signal.valid_signals() else str(sig)
                hint = " (killed: out of memory?)" if sig == signal.SIGKILL else ""
                msg = f"worker died from signal {name}{hint}"
            else:
                msg = f"worker exited with status {os.WEXITSTATUS(status)} without a result"
            result = {"status": "crash", "message": msg, "error_line": 0}
    result["wall_s"] = wall
    result["peak_mem_mb"] = peak_mb
    return result


def run_pool(
    jobs: list[dict],
    workers: int,
    timeout_s: float | None,
    func: Callable[[dict], dict] = run_job,
    on_done: Callable[[int, dict], None] | None = None,
) -> list[dict]:
    """Run ``func(job)`` for every job in forked children, ``workers`` at a time.

    Returns the results in job order; ``on_done(index, result)`` is called as each
    finishes. ``timeout_s`` (per job) kills a child that runs longer. A Ctrl-C
    kills every running child and re-raises ``KeyboardInterrupt``.
    """
    results: list[dict | None] = [None] * len(jobs)
    pending = list(range(len(jobs)))[::-1]
    running: dict[int, _Running] = {}
    workers = max(1, int(workers))
    previous = _catch_termination()
    try:
        while pending or running:
            while pending and len(running) < workers:
                i = pending.pop()
                rfd, wfd = os.pipe()
                pid = os.fork()
                if pid == 0:  # pragma: no cover - runs in the child
                    for sig in _TERMINATING:
                        signal.signal(sig, signal.SIG_DFL)
                    os.close(rfd)
                    _child(func, jobs[i], wfd)
                os.close(wfd)
                now = time.monotonic()
                deadline = now + timeout_s if timeout_s else float("inf")
                running[rfd] = _Running(pid, rfd, i, now, deadline)
            now = time.monotonic()
            wait = min(r.deadline for r in running.values()) - now
            ready, _, _ = select.select(list(running), [], [], max(0.0, min(wait, 1.0)))
            for fd in ready:
                run = running[fd]
                chunk = os.read(fd, _READ_CHUNK)
                if chunk:
                    run.chunks.append(chunk)
                    continue
                del running[fd]
                results[run.index] = _finish(run, timed_out=False)
                if on_done:
                    on_done(run.index, results[run.index])
            now = time.monotonic()
            for fd, run in list(running.items()):
                if now >= run.deadline:
                    del running[fd]
                    results[run.index] = _finish(run, timed_out=True)
                    if on_done:
                        on_done(run.index, results[run.index])
    except BaseException as exc:
        for run in running.values():
            try:
                os.kill(run.pid, signal.SIGKILL)
                os.waitpid(run.pid, 0)
                os.close(run.fd)
            except OSError:
                pass
        _restore(previous)
        if isinstance(exc, _Signalled):  # die of the signal, as without the handler
            signal.signal(exc.signum, signal.SIG_DFL)
            os.kill(os.getpid(), exc.signum)
        raise
    _restore(previous)
    return results  # type: ignore[return-value]


#: signals that end a batch: its workers are killed first, not orphaned
_TERMINATING = (signal.SIGTERM, signal.SIGHUP)


class _Signalled(BaseException):
    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def _catch_termination() -> dict | None:
    """Turn SIGTERM/SIGHUP into ``_Signalled`` while the pool runs (main thread only)."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum, frame):
        raise _Signalled(signum)

    return {sig: signal.signal(sig, handler) for sig in _TERMINATING}


def _restore(previous: dict | None) -> None:
    for sig, old in (previous or {}).items():
        signal.signal(sig, old)


def run_isolated(job: dict, timeout_s: float | None = None, func: Callable[[dict], dict] = run_job) -> dict:
    """One job in one forked child (used as the Dask task: isolation on the worker too)."""
    return run_pool([job], 1, timeout_s, func=func)[0]

"""First run: compile VPOp's step loop in a child process while this one parses and fits.

Numba compiles on one core and holds the GIL while it does, so a warm-up *thread* cannot
share the work with the fit's own compile; a process can. The planner's kernels fall into
two independent trees below ``vpop.drive.plan_identity_batch`` (the call that plans a run
of short paths): the preparation (``prepare_identity``: arc-length table, bounds) and the
step loop (``drive``). On a cold cache one child compiles the step loop (the larger tree)
on a tiny rapid move and numba writes it to its on-disk cache; this process compiles the
fit's kernels and the preparation (``compile_preparation``, in the warm-up thread), and
the planner's first call waits for the child (``wait``) and then only compiles
``plan_identity_batch`` itself, loading the step loop. The child also compiles the CSV
formatter after the step loop (the caller names it: ``start(also=...)``), which evens the
two processes' shares.

Measured on the project's 2-core machine, cold cache, kernels of the quick-start plan of
``mill-contour.ngc`` (CPU-s): the fit's ~20, the preparation ~17, the step loop ~30,
``plan_identity_batch`` ~7 (one process: 65-74 s wall). Two children (one per tree) were
tried: every process also compiles numba's own helpers and the kernels both trees share,
and three processes on two cores came to 95 CPU-s, more wall time than this split.

``plan_identity_batch`` itself took another ~9 s after the wait (numba optimises the
kernel's module with what it links in), on the critical path. So the child says it is
ready (a line on its standard output) once the step loop and the warm-ups are cached, and
then compiles ``plan_identity_batch`` and the batch fitter's kernels (the ``batch`` job,
~50 CPU-s); while it does, VPOp plans each path on its own (``plan_many_vpop`` leaves
them to ``iter_path_plan_vpop``: the same samples) and the fit keeps its Python fitter
(the same paths), and the child may outlive this process to cache them. A later run that
finds only these missing starts a ``batch`` child and waits for nothing.

A child that fails or is killed costs nothing but time: whatever it did not cache, this
process compiles on its first call, as it would without children.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading

#: the children's jobs: the step-loop tree of VPOp's kernels (this process compiles the
#: preparation, ``compile_preparation``, while the fit compiles too), then the ``batch``
#: job; or the ``batch`` job alone when only its kernels are missing
JOBS = ("loop",)

#: how long the planner waits for the children before compiling by itself (s): a child
#: normally ends within a minute; one that hangs must not hang the plan
PRECOMPILE_WAIT_S = 600.0

#: what a child writes on its standard output when the parent's share is cached
READY_LINE = b"ready\n"

#: the kernel the child compiles after saying it is ready (module, function)
BATCH_KERNEL = ("plan.vpop.drive", "plan_identity_batch")
#: and the batch fitter's kernels (~40 CPU-s; a plan compiles them only for a run of
#: ``fit.fitter.FIT_KERNEL_COMPILE_NODES`` nodes or more)
FIT_KERNEL_MODULES = ("fit._subrun",)
#: a program whose fit runs through every batch-fitter kernel (lines, an arc, a corner)
_FIT_WARM_PROGRAM = b"G21 G90\nG0 X1 Y1\nG1 X5 Y3 F600\nG2 X7 Y5 I1 J1\nG1 X5 Z-1\nM2\n"

_children: list[subprocess.Popen] = []
_ready: set[int] = set()  # pids of children past their ready line (compiling the batch)
_lock = threading.Lock()
_wait_lock = threading.Lock()  # held by the thread reading the children's lines


def _root() -> str:
    return os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def start(root: str | None = None, also: tuple[str, ...] = ()) -> bool:
    """Start a child when VPOp's kernels are not cached yet (a first run, or the first
    after an update changed them); returns whether it started one. ``also``: more
    warm-up functions for the child to call after the step loop, before it says it is
    ready, as ``"module:function"`` below the package (the caller's floor decides what;
    this module imports none)."""
    from .._kernel_cache import kernel_cached, missing_kernels

    root = root or _root()
    need_loop = any(m.startswith("plan.") for m in missing_kernels(root))
    if not need_loop and kernel_cached(root, *BATCH_KERNEL) and not missing_kernels(root, FIT_KERNEL_MODULES):
        return False
    job = "loop" if need_loop else "batch"
    with _lock:
        if _children:
            return True
        try:
            proc = subprocess.Popen(
                _command(job, also if need_loop else ()),
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                close_fds=True,
            )
        except OSError:  # no process to spare: this process compiles everything
            return False
        _children.append(proc)
        if job == "batch":  # nothing this process waits for
            _ready.add(proc.pid)
    import atexit

    from .. import _kernel_cache

    _kernel_cache.background_check = batch_pending
    atexit.register(_at_exit)
    return True


def _command(job: str, also: tuple[str, ...] = ()) -> list[str]:
    return [sys.executable, "-m", __name__, job, *also]


def wait(timeout_s: float = PRECOMPILE_WAIT_S) -> list[int]:
    """Block until every child has cached this process's share (its ready line, or its
    end); at once when none was started. Returns the status of each child waited for: 0
    ready, else its exit status (a child that hangs past ``timeout_s`` is killed)."""
    with _wait_lock:  # two threads waiting on one pipe: one reads the line, one waits
        return _wait_for_lines(timeout_s)


def _wait_for_lines(timeout_s: float) -> list[int]:
    import select

    with _lock:
        procs = [p for p in _children if p.pid not in _ready]
    out = []
    for proc in procs:
        line = b""
        if proc.stdout is not None:
            if select.select([proc.stdout], [], [], timeout_s)[0]:
                line = proc.stdout.readline()
            else:  # it hangs: this process compiles what it needs
                proc.kill()
        if line == READY_LINE:
            out.append(0)
            with _lock:
                _ready.add(proc.pid)
            continue
        out.append(proc.wait())  # it ended (or was killed) before its line
        with _lock:
            if proc in _children:
                _children.remove(proc)
    return out


def batch_pending() -> bool:
    """Whether a child is compiling VPOp's batch driver now: the planner then plans
    paths one at a time instead of compiling the same kernel itself."""
    return bool(_reap())


def _reap() -> list[subprocess.Popen]:
    """Forget the children that have ended; returns those still running."""
    with _lock:
        for proc in [p for p in _children if p.poll() is not None]:
            _children.remove(proc)
            _ready.discard(proc.pid)
        return list(_children)


def finish(timeout_s: float = PRECOMPILE_WAIT_S) -> list[int]:
    """Wait for the children to end (their batch job included); returns their exit
    statuses. For tests and benchmarks that need the whole cache."""
    with _lock:
        procs = list(_children)
    for proc in procs:
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    _reap()
    return [proc.returncode for proc in procs]


def stop() -> None:
    """Kill children still compiling (the plan ended early: an error, Ctrl-C)."""
    with _lock:
        procs = list(_children)
        _children.clear()
        _ready.clear()
    for proc in procs:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _at_exit() -> None:
    """At the end of the command: kill a child still compiling this process's share (the
    command ended without planning); a child compiling the batch driver finishes it."""
    with _lock:
        procs = [p for p in _children if p.pid not in _ready]
    for proc in procs:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _tiny_path():
    """A 1 mm rapid move of the default machine, fitted: the smallest real input."""
    from ..fit.fitter import fit_run
    from ..gcode import read_program
    from ..machine.load import DEFAULT_PRESET, load_machine

    m = load_machine(DEFAULT_PRESET)
    prog = read_program(b"G21 G90\nG0 X1\n", "precompile", axes=m.axes, start=m.start)
    return fit_run(prog.runs[0])[0], m


def compile_preparation() -> None:
    """The preparation tree (``vpop.drive.prepare_identity``), compiled (or loaded) in this
    process."""
    from .vpop import planner

    path, m = _tiny_path()
    planner._Prepared(path, None, m, m.dt_s, None)


def _job_loop() -> None:
    """The step-loop tree (``vpop.drive.drive``), reached through the joint-map route of
    the preparation (Python and small kernels) so that ``prepare_identity`` is left to the
    parent."""
    from ..machine.kinematics import Kinematics
    from .vpop import planner
    from .vpop.table import JointTable

    class _MappedIdentity(Kinematics):
        """The identity, presented as a joint map: VPOp prepares it in Python."""

        @property
        def is_identity(self) -> bool:
            return False

    path, m = _tiny_path()
    joint_map = _MappedIdentity(m.axes)
    table = JointTable(path, joint_map)
    prep = planner._Prepared(path, joint_map, m, m.dt_s, None, table=table)
    for _ in planner.iter_prepared(prep, joint_map, m, None, None):
        pass


def _job_batch() -> None:
    """VPOp's batch driver (``vpop.drive.plan_identity_batch``), compiled through the
    planner's own call (the same signature as a plan's), loading both trees below it;
    then the batch fitter's kernels, through the fit's own call."""
    from ..fit import fitter
    from ..gcode import read_program
    from .vpop.planner import plan_many_vpop

    path, m = _tiny_path()
    plan_many_vpop([path], m, m.dt_s)
    fitter._kernels_ready = True  # the batch fitter whatever the run's length
    prog = read_program(_FIT_WARM_PROGRAM, "precompile", axes=m.axes, start=m.start)
    for run in prog.runs:
        fitter.fit_run(run)


def main(argv: list[str]) -> int:
    import signal

    # the parent may block SIGINT (``outfile.watch_interrupts``) and the mask is inherited:
    # Ctrl-C on the terminal must end the children too
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    import importlib

    jobs = {"loop": _job_loop, "batch": _job_batch}
    if not argv or argv[0] not in jobs or not all(":" in a for a in argv[1:]):
        sys.stderr.write(f"usage: python -m {__name__} {{{','.join(jobs)}}} [module:function ...]\n")
        return 2
    jobs[argv[0]]()
    package = (__package__ or "cnc_interp").split(".")[0]  # (``__name__`` is "__main__" under -m)
    for spec in argv[1:]:
        module, _, function = spec.partition(":")
        getattr(importlib.import_module(f"{package}.{module}"), function)()
    if argv[0] == "loop":
        _say_ready()
        _job_batch()
    return 0


def _say_ready() -> None:
    """The ready line, then standard output closed (the parent may be gone by the end)."""
    try:
        os.write(1, READY_LINE)
    except OSError:  # the parent has gone: the batch is still worth caching
        pass
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.close(devnull)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

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

A child that fails or is killed costs nothing but time: whatever it did not cache, this
process compiles on its first call, as it would without children.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading

#: the children's jobs: the step-loop tree of VPOp's kernels (this process compiles the
#: preparation, ``compile_preparation``, while the fit compiles too)
JOBS = ("loop",)

#: how long the planner waits for the children before compiling by itself (s): a child
#: normally ends within a minute; one that hangs must not hang the plan
PRECOMPILE_WAIT_S = 600.0

_children: list[subprocess.Popen] = []
_lock = threading.Lock()


def start(root: str | None = None, also: tuple[str, ...] = ()) -> bool:
    """Start the children when VPOp's kernels are not cached yet (a first run, or the
    first after an update changed them); returns whether it started them. ``also``:
    more warm-up functions for the child to call after its job, as ``"module:function"``
    below the package (the caller's floor decides what; this module imports none)."""
    from .._kernel_cache import missing_kernels

    root = root or os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    if not any(m.startswith("plan.") for m in missing_kernels(root)):
        return False
    with _lock:
        if _children:
            return True
        for job in JOBS:
            try:
                proc = subprocess.Popen(
                    _command(job, also),
                    stdin=subprocess.DEVNULL,
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL,
                    close_fds=True,
                )
            except OSError:  # no process to spare: this process compiles everything
                break
            _children.append(proc)
        started = bool(_children)
    if started:
        import atexit

        atexit.register(stop)
    return started


def _command(job: str, also: tuple[str, ...] = ()) -> list[str]:
    return [sys.executable, "-m", __name__, job, *also]


def wait(timeout_s: float = PRECOMPILE_WAIT_S) -> list[int]:
    """Block until the children have finished (at once when none was started); returns
    their exit statuses."""
    with _lock:
        procs = list(_children)
    for proc in procs:
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    with _lock:
        for proc in procs:
            if proc in _children:
                _children.remove(proc)
    return [proc.returncode for proc in procs]


def stop() -> None:
    """Kill children still compiling (the plan ended early: an error, Ctrl-C)."""
    with _lock:
        procs = list(_children)
        _children.clear()
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


def main(argv: list[str]) -> int:
    import signal

    # the parent may block SIGINT (``outfile.watch_interrupts``) and the mask is inherited:
    # Ctrl-C on the terminal must end the children too
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    import importlib

    jobs = {"loop": _job_loop}
    if not argv or argv[0] not in jobs or not all(":" in a for a in argv[1:]):
        sys.stderr.write(f"usage: python -m {__name__} {{{','.join(JOBS)}}} [module:function ...]\n")
        return 2
    jobs[argv[0]]()
    package = (__package__ or "cnc_interp").split(".")[0]  # (``__name__`` is "__main__" under -m)
    for spec in argv[1:]:
        module, _, function = spec.partition(":")
        getattr(importlib.import_module(f"{package}.{module}"), function)()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

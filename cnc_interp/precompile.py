"""Compile the numba kernels a run needs before it uses them, once per kernel cache.

Numba compiles a kernel on its first call and caches the machine code on disk (next to
the sources, ``_kernel_cache``). Left to itself, a first run would compile some 80-150
CPU-s of kernels on one core (numba holds the GIL while it compiles), silently, in the
middle of the plan; and every process started before the cache is complete would compile
the same kernels again.

Here the kernels fall into groups (``GROUPS``), each compiled by a warm-up call that goes
through the real code on a tiny input, so that it caches exactly the signatures a real
run calls. ``ensure(planner)`` compiles the groups the planner needs that are missing:

- under a cross-process lock (``fcntl.flock`` on a file in the kernel cache's folder):
  one process compiles, any other that needs the same cache waits for it and then loads
  what it cached;
- on two cores: this process and one worker process take the groups in dependency order,
  the worker the costlier of the ready ones (``_schedule``). The worker reads group names
  on its standard input and ends when that closes: with the command, whichever way the
  command ends (nothing outlives it);
- with a message on a terminal that gives the estimate (the schedule's length with the
  groups' measured costs, ``KernelGroup.cost_s``) and one line per group compiled.

Kernels outside the groups (curves that few programs use, the batch fitter of very long
runs) still compile on their first call.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from dataclasses import dataclass

#: the planners whose kernels are grouped here, and what each needs (in compile order)
PLANNER_GROUPS = {
    "vpop": ("fit", "csv", "vpop-prep", "vpop-loop", "vpop-batch"),
    "optimal": ("fit", "csv", "vpop-prep", "vpop-loop", "vpop-batch", "optimal"),
    "constant": ("fit", "csv"),
    "variable": ("fit", "csv"),
}

#: the lock file's name, in the folder of the package's kernel cache
LOCK_NAME = "cnc-interp-compile.lock"

#: seconds a worker process takes to start and import numpy, numba and the package
#: before it compiles (measured on the project's 2-core machine: 1.5-2 s)
WORKER_START_S = 2.0

#: a program whose fit and plan run through every grouped kernel: lines, a corner, a
#: contour of lines and tangent arcs (I J and R), an arc of 1 mm radius at a feed its
#: curvature limits for 8 turns (the optimal planner's feed-profile route) and rapids
WARM_PROGRAM = (
    b"G21 G90 G17\nG0 X0 Y0 Z1\nG1 Z0 F600\nG2 X0 Y0 I1 J0 P8 F6000\n"
    b"G1 X20 Y5 F6000\nG1 X21 Y-3\nG0 Z5\nG0 X0 Y-3\nG1 Z-2 F300\nG1 X35 F900\n"
    b"G3 X43 Y5 I0 J8\nG1 Y25\nG3 X35 Y33 R8\nG1 X5\nG0 Z5\nM2\n"
)


@dataclass(frozen=True)
class KernelGroup:
    """Kernels compiled together by one warm-up call.

    ``cached``: ``"module"`` (cached once it has any kernel in the cache) or
    ``"module:function"`` entries, dotted below the package; the group is cached when all
    are. ``warm``: the name of this module's function that compiles (or loads) them.
    ``cost_s``: CPU seconds to compile them from scratch on the project's 2-core machine
    (``NUMBA_OPT=1``, as the command line sets it), with the groups in ``after`` cached
    (they are linked, not compiled again).
    """

    name: str
    cached: tuple[str, ...]
    warm: str
    cost_s: float
    after: tuple[str, ...] = ()


GROUPS = {
    g.name: g
    for g in (
        KernelGroup(
            "fit",
            ("fit._arclen", "fit._project", "fit._bspline", "fit._npexact", "fit._section", "fit._arcs"),
            "_warm_fit",
            16.7,
        ),
        KernelGroup("csv", ("export._repr",), "_warm_csv", 5.5),
        KernelGroup("vpop-prep", ("plan._table_kernels", "plan.vpop.drive:prepare_identity"), "_warm_vpop_prep", 19.1),
        KernelGroup("vpop-loop", ("plan.vpop.step", "plan.vpop.drive:drive"), "_warm_vpop_loop", 31.7),
        KernelGroup(
            "vpop-batch", ("plan.vpop.drive:plan_identity_batch",), "_warm_vpop_batch", 10.2, ("vpop-prep", "vpop-loop")
        ),
        # the feed profile uses the preparation's arc-length table kernels (13 CPU-s of
        # vpop-prep's 19): compiled after them, not a second time beside them
        KernelGroup(
            "optimal",
            ("plan._feed_kernels", "plan._ipm", "plan._refine_kernels", "plan._track_kernels"),
            "_warm_optimal",
            31.4,
            ("fit", "vpop-prep"),
        ),
    )
}


def _root() -> str:
    return os.path.dirname(os.path.abspath(__file__))


def missing_groups(planner: str, root: str | None = None) -> list[str]:
    """The groups ``planner`` needs that are not in the kernel cache, in compile order."""
    from ._kernel_cache import kernel_cached, missing_kernels

    root = root or _root()
    out = []
    for name in PLANNER_GROUPS.get(planner, ()):
        for entry in GROUPS[name].cached:
            module, _, function = entry.partition(":")
            if (function and not kernel_cached(root, module, function)) or (
                not function and missing_kernels(root, (module,))
            ):
                out.append(name)
                break
    return out


def _schedule(names: list[str], costs: dict[str, float], worker: bool = True) -> tuple[list[list[str]], float]:
    """What ``_compile`` does with ``names`` when each group takes ``costs[name]`` seconds:
    the groups this process and the worker compile, in order, and the wall time (s). A
    group is ready once the groups of its ``after`` that are among ``names`` are done;
    the idle worker takes the costliest ready group, this process the costliest of the
    rest, and waits for the worker when none is left for it."""
    todo, done = list(names), set()
    shares: list[list[str]] = [[], []]
    t, worker_free, worker_end, at_worker = 0.0, WORKER_START_S, 0.0, None
    use_worker = worker and len(names) > 1
    while todo or at_worker:
        ready = [g for g in todo if all(d in done or d not in names for d in GROUPS[g].after)]
        if use_worker and at_worker is None and ready:
            at_worker = max(ready, key=lambda n: costs[n])
            todo.remove(at_worker)
            ready.remove(at_worker)
            worker_end = max(worker_free, t) + costs[at_worker]
            shares[1].append(at_worker)
        if ready or (todo and at_worker is None):
            name = max(ready, key=lambda n: costs[n]) if ready else todo[0]
            todo.remove(name)
            t += costs[name]
            done.add(name)
            shares[0].append(name)
        else:
            t = max(t, worker_end)
        if at_worker is not None and worker_end <= t:
            done.add(at_worker)
            worker_free, at_worker = worker_end, None
    return shares, t


def estimate_s(names: list[str]) -> float:
    """Wall seconds to compile the groups ``names`` on two cores (``_schedule``)."""
    return _schedule(names, {n: GROUPS[n].cost_s for n in names})[1]


def ensure(planner: str, stream=None, root: str | None = None) -> list[str]:
    """Compile the kernel groups ``planner`` needs that are not cached yet (see the module
    docstring); returns the groups compiled here (none when another process had compiled
    them, or all were cached). ``stream``: where to say what happens (a terminal), or
    None for silence."""
    root = root or _root()
    if not missing_groups(planner, root):
        return []
    with _CacheLock(root, stream):
        names = missing_groups(planner, root)  # another process may have compiled them
        if not names:
            return []
        _say(
            stream,
            f"first run: compiling the {planner} planner's kernels, about {estimate_s(names):.0f} s "
            "on 2 cores, cached for next time",
        )
        _compile(names, stream)
        return names


def _say(stream, text: str) -> None:
    if stream is not None:
        stream.write(f"cnc-interp: {text}\n")
        stream.flush()


class _CacheLock:
    """An exclusive ``flock`` on the kernel cache's lock file for the ``with`` block; a
    process that has to wait says so. Where no lock file can be made, no lock."""

    def __init__(self, root: str, stream):
        from ._kernel_cache import _cache_folder

        self.path = os.path.join(_cache_folder(root), LOCK_NAME)
        self.stream = stream
        self.fd: int | None = None

    def __enter__(self):
        import fcntl

        try:
            os.makedirs(os.path.dirname(self.path), exist_ok=True)
            self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError:
            return self
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            _say(self.stream, "waiting for another cnc-interp process that is compiling the kernels")
            fcntl.flock(self.fd, fcntl.LOCK_EX)
        return self

    def __exit__(self, *exc):
        if self.fd is not None:
            os.close(self.fd)  # releases the lock
            self.fd = None
        return False


def _compile(names: list[str], stream) -> None:
    """Compile ``names`` here and in one worker process, as ``_schedule`` lays out."""
    t0 = time.perf_counter()
    worker = _Worker.start() if len(names) > 1 else None
    todo = list(names)
    done: set[str] = set()
    at_worker: str | None = None

    def finished(name: str) -> None:
        done.add(name)
        _say(stream, f"compiled {name} kernels ({len(done)} of {len(names)}, {time.perf_counter() - t0:.0f} s)")

    try:
        while todo or at_worker:
            ready = [g for g in todo if all(d in done or d not in names for d in GROUPS[g].after)]
            if worker is not None and at_worker is None and ready:
                name = max(ready, key=lambda n: GROUPS[n].cost_s)
                if worker.send(name):
                    at_worker = name
                    todo.remove(name)
                    ready.remove(name)
                else:  # the worker is gone: everything here
                    worker = None
            word: bool | None = None
            if ready or (todo and at_worker is None):
                name = max(ready, key=lambda n: GROUPS[n].cost_s) if ready else todo[0]
                todo.remove(name)
                warm_up(name)
                finished(name)
            elif at_worker is not None:
                assert worker is not None
                word = worker.word(at_worker)
            else:
                continue
            if at_worker is not None and worker is not None:
                if word is None:
                    word = worker.word(at_worker, timeout_s=0.0)
                if word:
                    finished(at_worker)
                elif word is False:  # the worker failed or ended: this process compiles it
                    todo.insert(0, at_worker)
                    worker.close()
                    worker = None
                if word is not None:
                    at_worker = None
    finally:
        if worker is not None:
            worker.close()


def warm_up(name: str) -> None:
    """Compile (or load) the kernels of the group ``name`` in this process."""
    globals()[GROUPS[name].warm]()


class _Worker:
    """The worker process: group names in on its standard input, ``done NAME`` or
    ``fail NAME`` lines out."""

    def __init__(self, proc: subprocess.Popen):
        self.proc = proc

    @classmethod
    def start(cls) -> _Worker | None:
        try:
            proc = subprocess.Popen(
                [sys.executable, "-m", __name__, "--worker"],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                close_fds=True,
            )
        except OSError:  # no process to spare: this one compiles everything
            return None
        return cls(proc)

    def send(self, name: str) -> bool:
        try:
            assert self.proc.stdin is not None
            self.proc.stdin.write(name.encode() + b"\n")
            self.proc.stdin.flush()
            return True
        except (OSError, ValueError):
            return False

    def word(self, name: str, timeout_s: float | None = None) -> bool | None:
        """The worker's word on ``name``: True compiled, False failed (or the worker
        ended), None none within ``timeout_s`` (None: wait for it)."""
        import select

        assert self.proc.stdout is not None
        if timeout_s is not None and not select.select([self.proc.stdout], [], [], timeout_s)[0]:
            return None
        return self.proc.stdout.readline().decode(errors="replace").strip() == f"done {name}"

    def close(self) -> None:
        """End the worker: its input closed, then killed if it is still compiling."""
        try:
            assert self.proc.stdin is not None
            self.proc.stdin.close()
        except OSError:
            pass
        try:
            self.proc.wait(timeout=2.0)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def _worker_main() -> int:
    """The worker: compile each group named on standard input; end at its end. A reader
    thread ends the process as soon as the input closes (the parent has ended, or is
    done), even in the middle of a compile."""
    import queue
    import signal
    import threading

    # the parent may block SIGINT (``outfile.watch_interrupts``) and the mask is inherited:
    # Ctrl-C on the terminal must end the worker too
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    names: queue.Queue = queue.Queue()

    def read() -> None:
        for line in sys.stdin.buffer:
            names.put(line.decode(errors="replace").strip())
        os._exit(0)

    threading.Thread(target=read, daemon=True).start()
    while True:
        name = names.get()
        try:
            warm_up(name)
            reply = f"done {name}\n"
        except Exception:  # noqa: BLE001 - the parent compiles it itself
            reply = f"fail {name}\n"
        os.write(1, reply.encode())


# --- the warm-up calls: the real code on tiny inputs (the signatures of real runs) -------


def _warm_machine_program():
    from .gcode import read_program
    from .machine.load import DEFAULT_PRESET, load_machine

    m = load_machine(DEFAULT_PRESET)
    return m, read_program(WARM_PROGRAM, "precompile", axes=m.axes, start=m.start)


def _tiny_path():
    """A 1 mm rapid move of the default machine, fitted."""
    from .fit.fitter import fit_run
    from .gcode import read_program
    from .machine.load import DEFAULT_PRESET, load_machine

    m = load_machine(DEFAULT_PRESET)
    prog = read_program(b"G21 G90\nG0 X1\n", "precompile", axes=m.axes, start=m.start)
    return fit_run(prog.runs[0])[0], m


def _warm_fit() -> None:
    from .fit import FitSettings, fit_program

    m, prog = _warm_machine_program()
    fit_program(prog, FitSettings.from_options(machine=m))


def _warm_csv() -> None:
    from .export._repr import warm_up

    warm_up()


def _warm_vpop_prep() -> None:
    """The preparation tree (``vpop.drive.prepare_identity``)."""
    from .plan.vpop import planner

    path, m = _tiny_path()
    planner._Prepared(path, None, m, m.dt_s, None)


def _warm_vpop_loop() -> None:
    """The step-loop tree (``vpop.drive.drive``), reached through the joint-map route of
    the preparation (Python and small kernels), which leaves ``prepare_identity`` to the
    ``vpop-prep`` group."""
    from .machine.kinematics import Kinematics
    from .plan.vpop import planner
    from .plan.vpop.table import JointTable

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


def _warm_vpop_batch() -> None:
    """VPOp's batch driver (``vpop.drive.plan_identity_batch``), through the planner's own
    call (the signature of a plan's)."""
    from .plan.vpop.planner import plan_many_vpop

    path, m = _tiny_path()
    plan_many_vpop([path], m, m.dt_s)


def _warm_optimal() -> None:
    """The optimal planner's feed profile, sampler and refinement, on the warm program's
    arc (the path its curvature limits)."""
    from .fit import FitSettings, fit_program
    from .plan.optimal import plan_path_optimal
    from .plan.settings import PlanSettings

    m, prog = _warm_machine_program()
    paths = fit_program(prog, FitSettings.from_options(machine=m)).paths
    arc = max(paths, key=lambda p: p.length / max(float(p.feed_mm_s.min()), 1e-9))
    plan_path_optimal(arc, None, m, m.dt_s, PlanSettings.from_options(planner="optimal", machine=m))


if __name__ == "__main__":
    if sys.argv[1:] == ["--worker"]:
        sys.exit(_worker_main())
    sys.stderr.write(f"usage: python -m {__name__} --worker\n")
    sys.exit(2)

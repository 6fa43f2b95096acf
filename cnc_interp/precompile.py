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
- on two cores: this process compiles in its main thread while a second thread hands one
  worker process its next group as soon as it is free, each taking the first-ranked group
  whose dependencies are done; the ranking is the one whose schedule (``_schedule``, with
  the groups' measured costs ``KernelGroup.cost_s``) is shortest (``best_order``). The
  worker reads group names on its standard input and ends when that closes: with the
  command, whichever way the command ends (nothing outlives it);
- with a message on a terminal that gives the estimate (that schedule's length) and one
  line per group compiled.

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
_VPOP_GROUPS = ("fit", "csv", "vpop-prep", "vpop-loop", "vpop-batch")
PLANNER_GROUPS = {
    "vpop": _VPOP_GROUPS,
    "optimal": (*_VPOP_GROUPS, "optimal"),  # VPOp plans the paths the profile does not
    "constant": ("fit", "csv"),
    "variable": ("fit", "csv"),
}

#: the lock file's name, in the folder of the package's kernel cache
LOCK_NAME = "cnc-interp-compile.lock"

#: seconds a worker process takes to start and import numpy, numba and the package
#: before it compiles (measured on the project's 2-core machine: 1.5-2 s)
WORKER_START_S = 2.0

#: a program whose fit runs through every grouped fit kernel: lines, a corner, a contour
#: of lines and tangent arcs (I J and R), and rapids
WARM_PROGRAM = (
    b"G21 G90 G17\nG0 X0 Y0 Z1\nG1 Z0 F600\nG1 X20 Y5 F6000\nG1 X21 Y-3\nG0 Z5\n"
    b"G0 X0 Y-3\nG1 Z-2 F300\nG1 X35 F900\nG3 X43 Y5 I0 J8\nG1 Y25\nG3 X35 Y33 R8\nG1 X5\n"
    b"G0 Z5\nM2\n"
)
#: an arc of 1 mm radius for 8 turns at a feed its curvature limits: the optimal planner
#: plans it through its feed profile, sampler and refinement
WARM_ARC_PROGRAM = b"G21 G90 G17\nG0 X0 Y0 Z0\nG2 X0 Y0 I1 J0 P8 F6000\nM2\n"


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
            ("fit._arclen", "fit._project", "fit._bspline", "fit._npexact", "fit.corners", "fit.blends"),
            "_warm_fit",
            30.3,
        ),
        KernelGroup("csv", ("export._repr",), "_warm_csv", 3.5),
        KernelGroup("vpop-prep", ("plan._table_kernels", "plan.vpop.drive:prepare_identity"), "_warm_vpop_prep", 15.5),
        KernelGroup("vpop-loop", ("plan.vpop.step", "plan.vpop.drive:drive"), "_warm_vpop_loop", 33.7),
        KernelGroup(
            "vpop-batch", ("plan.vpop.drive:plan_identity_batch",), "_warm_vpop_batch", 11.5, ("vpop-prep", "vpop-loop")
        ),
        # the feed profile uses the preparation's arc-length table kernels (13 CPU-s of
        # vpop-prep's 19): compiled after them, not a second time beside them
        KernelGroup(
            "optimal",
            ("plan._feed_kernels", "plan._ipm", "plan._refine_kernels", "plan._track_kernels", "plan._line_kernels"),
            "_warm_optimal",
            37.3,
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


def _schedule(
    names: list[str], costs: dict[str, float], order: list[str] | None = None
) -> tuple[list[list[str]], float]:
    """What ``_compile`` does with ``names`` when each group takes ``costs[name]`` seconds
    and ``order`` ranks them (default: ``names``' order): the groups this process and the
    worker compile, in order, and the wall time (s). Whenever a process is free (the
    worker from WORKER_START_S on) it takes the first-ranked group whose ``after`` groups
    among ``names`` are done, or waits for the next one to finish."""
    rank = {n: i for i, n in enumerate(order or names)}
    todo = sorted(names, key=rank.__getitem__)
    free = [0.0, WORKER_START_S] if len(names) > 1 else [0.0, float("inf")]
    done_at: dict[str, float] = {}
    shares: list[list[str]] = [[], []]
    while todo:
        p = 0 if free[0] <= free[1] else 1
        t = free[p]
        ready = [g for g in todo if all(d not in names or done_at.get(d, float("inf")) <= t for d in GROUPS[g].after)]
        if not ready:
            later = [e for e in done_at.values() if e > t]
            if not later:  # (an inconsistent table) the first-ranked group regardless
                ready = todo[:1]
            else:
                free[p] = min(later)
                continue
        name = ready[0]
        todo.remove(name)
        done_at[name] = free[p] = t + costs[name]
        shares[p].append(name)
    return shares, max(done_at.values(), default=0.0)


def _ready(name: str, names: list[str], done: set[str]) -> bool:
    return all(d in done or d not in names for d in GROUPS[name].after)


def best_order(names: list[str]) -> tuple[list[str], float]:
    """The ranking of ``names`` whose ``_schedule`` is shortest with the groups' costs
    (every permutation is tried: a planner needs at most a handful of groups), and that
    schedule's wall time (s); the first such ranking on ties."""
    from itertools import permutations

    costs = {n: GROUPS[n].cost_s for n in names}
    best: tuple[float, list[str]] = (float("inf"), list(names))
    for order in permutations(names):
        total = _schedule(names, costs, list(order))[1]
        if total < best[0] - 1e-9:
            best = (total, list(order))
    return best[1], best[0]


def estimate_s(names: list[str]) -> float:
    """Wall seconds to compile the groups ``names`` on two cores (``best_order``)."""
    return best_order(names)[1]


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
    """Compile ``names`` here and in one worker process, in ``best_order``'s ranking: a
    thread feeds the worker its next group as soon as it is free (as ``_schedule`` plays
    it out) while this thread compiles."""
    import threading

    order, _ = best_order(names)
    todo = sorted(names, key=order.index)
    done: set[str] = set()
    busy: set[str] = set()  # groups being compiled
    cond = threading.Condition()
    t0 = time.perf_counter()

    def next_ready() -> str | None:
        for g in todo:
            if _ready(g, names, done):
                todo.remove(g)
                busy.add(g)
                return g
        return None

    def finished(name: str) -> None:  # with cond held
        busy.discard(name)
        done.add(name)
        cond.notify_all()
        _say(stream, f"compiled {name} kernels ({len(done)} of {len(names)}, {time.perf_counter() - t0:.0f} s)")

    def feed(worker: _Worker) -> None:
        while True:
            with cond:
                name = next_ready()
                while name is None and todo:
                    cond.wait()
                    name = next_ready()
                if name is None:
                    return
            ok = worker.send(name) and worker.word(name)
            with cond:
                if ok:
                    finished(name)
                else:  # the worker failed or ended: this thread's share from now on
                    busy.discard(name)
                    todo.insert(0, name)
                    cond.notify_all()
                    return

    worker = _Worker.start() if len(names) > 1 else None
    feeder = threading.Thread(target=feed, args=(worker,), daemon=True) if worker is not None else None
    try:
        if feeder is not None:
            feeder.start()
        while True:
            with cond:
                name = next_ready()
                while name is None and (todo or busy):
                    if not busy:  # (an inconsistent table) the first group regardless
                        name = todo.pop(0)
                        busy.add(name)
                        break
                    cond.wait()
                    name = next_ready()
                if name is None:
                    break
            warm_up(name)
            with cond:
                finished(name)
    finally:
        if worker is not None:
            worker.close()
        if feeder is not None:
            feeder.join(timeout=5.0)


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


def _warm_machine_program(text: bytes = WARM_PROGRAM):
    from .gcode import read_program
    from .machine.load import DEFAULT_PRESET, load_machine

    m = load_machine(DEFAULT_PRESET)
    return m, read_program(text, "precompile", axes=m.axes, start=m.start)


def _tiny_path():
    """A 1 mm rapid move of the default machine, fitted."""
    from .fit.fitter import fit_run

    m, prog = _warm_machine_program(b"G21 G90\nG0 X1\n")
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
    from .plan.joint_table import JointTable

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
    """The optimal planner's feed profile, sampler, refinement and batch route, on
    ``WARM_ARC_PROGRAM``, and its line plan on a tiny line."""
    from .fit import FitSettings, fit_program
    from .plan.optimal import plan_path_optimal
    from .plan.settings import PlanSettings

    m, prog = _warm_machine_program(WARM_ARC_PROGRAM)
    (arc,) = fit_program(prog, FitSettings.from_options(machine=m)).paths
    plan = plan_path_optimal(arc, None, m, m.dt_s, PlanSettings.from_options(planner="optimal", machine=m))
    if plan.stats.get("route") != "profile":  # the warm-up would miss the profile's kernels
        raise RuntimeError(f"the warm-up arc took the {plan.stats.get('route')!r} route")
    from .plan.optimal.route import route_many
    from .plan.tuning import OptimalTuning

    route_many([arc], m, OptimalTuning())  # a job's batch of short paths: their routes at once
    from .plan.optimal.line import plan_lines

    rapid, rm = _tiny_path()
    (line,) = plan_lines([rapid], rm, rm.dt_s)  # straight paths' exact plans
    if line is None:
        raise RuntimeError("the warm-up line took no line plan")


if __name__ == "__main__":
    if sys.argv[1:] == ["--worker"]:
        sys.exit(_worker_main())
    sys.stderr.write(f"usage: python -m {__name__} --worker\n")
    sys.exit(2)

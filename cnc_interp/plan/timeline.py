"""The whole-program timeline: every fitted item planned onto one sample clock.

``iter_timeline`` walks fitted items (a ``FitResult``'s, or the fit's stream) in order
and yields the samples as ``SampleBlock``s, in bounded memory:

* ``Path`` (cutting): the chosen per-path planner (``plan.planners``) through the
  machine's kinematics, from rest to rest, as the planner's stream of chunks;
* ``Path(rapid=True)``: straight in joint space, at the axes' own limits and the
  machine's path speed cap if it has one (its feed; none on non-trivial kinematics,
  where the rapid is re-made in joint space); planned by VPOp, or by the planner's batch
  where it plans rapids (the optimal planner's exact line plan, ``optimal.line``);
* ``Dwell``: the position held for ceil(seconds / dt) samples;
* ``Stop`` (M0, M1, M6, ...): the machine is already at rest between paths; the
  stop is marked by the held position (no extra time is modelled for the pause);
* ``Mark`` (tool change, operation header; only from a stream asked for them): no
  samples, noted in the blocks' ``events`` when the timeline gives them.

The pieces are joined on t = k·dt. Between two paths the machine rests for one period
(two equal samples) where the one jerk stencil that then spans the joint holds
(``_short_rest``: the last step of the path before and the first step of the next, added,
within one period's jerk limit), else for two (three equal samples); every other backward
difference across the joint is then one the per-path plans already checked against
rest. Before a stop, a dwell and at the ends the machine holds at least three equal
samples. ``s`` is the cumulative
path length (rapids included), ``feed`` its backward difference and ``line`` the
source line executed at each sample.

Paths are planned independently (rest to rest), so consecutive paths are grouped into
jobs that worker threads plan ahead (the compiled step loops release the GIL) while the
caller consumes the samples in program order. The look-ahead is bounded (``Window``),
and the samples do not depend on it: ``plan_program`` (everything in one window) and
the stream with the smallest window give the same bytes.
"""

from __future__ import annotations

import math
import queue
import threading
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import PlanError
from .base import PathPlan
from .trajectory import Trajectory


#: most threads the timeline plans paths on (CNC_INTERP_THREADS overrides)
PLAN_MAX_THREADS = 4

#: samples at rest needed between motions (v, a, j stencils all at rest)
_REST_RUN = 3
#: equal samples between two paths where the jerk stencil spanning the joint allows it
_SHORT_REST_RUN = 2
#: the start of a path may differ from where the machine is by float rounding only
_JOIN_TOL = 1e-6
#: samples in the first block handed out (then each block doubles up to the window's)
_FIRST_BLOCK = 256

#: ``SampleBlock.events`` codes: from sample k on, the samples are ...
SPAN_REST = 0  #: held at rest between motions, at a stop and at the ends
SPAN_DWELL = 1  #: held for a G4 dwell
SPAN_PATH = 2  #: a path's (rapid or feed; ``obj`` is the ``Path``, ``s_off`` its start's s)
EVENT_MARK = 3  #: a ``Mark`` (tool change, operation header) takes effect at sample k


@dataclass(frozen=True)
class Window:
    """How much of the program is in flight at once (memory and parallelism; never the
    result).

    Attributes:
        block_samples: samples per ``SampleBlock`` handed to the consumer.
        job_paths: most paths planned as one job by a worker.
        job_samples: a job is closed once its paths' rough sample estimate reaches this.
        jobs_ahead: most jobs planned ahead of the one being consumed.
        samples_ahead: most samples of one job's chunks waiting for the consumer (a
            job's first chunk is taken whatever its size). A bound on chunks instead
            stalled the workers on programs of many short paths: a job ahead filled
            its queue with one chunk per path and waited for the consumer, so one
            worker planned at a time (stellabee1's first 20k lines, optimal: 1.15x
            from a second thread).
        path_window: a streaming planner's own buffer (samples), ``None`` = whole path.
    """

    block_samples: int = 1 << 16
    job_paths: int = 256
    job_samples: int = 1 << 15
    jobs_ahead: int = 8
    samples_ahead: int = 1 << 19
    path_window: int | None = 1 << 18

    @classmethod
    def whole(cls) -> "Window":
        """Everything at once (what ``plan_program`` uses)."""
        big = 1 << 62
        return cls(
            block_samples=big, job_paths=big, job_samples=big, jobs_ahead=big, samples_ahead=big, path_window=None
        )


@dataclass(frozen=True, eq=False)
class SampleBlock:
    """Consecutive samples k0 .. k0+K-1 of the timeline.

    Attributes (K samples, n machine axes): k0 index of the first sample (t = k·dt);
    s (K,) cumulative path length, mm; q (K, n) joint setpoints, mm / deg; line (K,)
    int64 source line executing (0 = none); events: only when the timeline is asked for
    them (``iter_timeline(events=True)``), (k, code, obj, s_off) in order, k absolute:
    what the samples from k on are (``SPAN_*``) and the ``Mark``s (``EVENT_MARK``).
    """

    k0: int
    s: np.ndarray
    q: np.ndarray
    line: np.ndarray
    events: tuple = ()

    @property
    def n(self) -> int:
        return int(self.s.shape[0])


@dataclass
class TimelineInfo:
    """What the stream knows at its end: samples, planner status, item counts and the
    planners' profiles (kept only when asked: they are for the FPGA stage)."""

    samples: int = 0
    status: str = "ok"
    stats: dict = field(default_factory=lambda: {"paths": 0, "rapids": 0, "dwells": 0, "stops": 0})
    profiles: list = field(default_factory=list)
    path_length_mm: float = 0.0
    plan_cpu_s: float = 0.0  # CPU time of the planning (all threads)


def _plan_threads() -> int:
    """Threads planning paths at once: CNC_INTERP_THREADS, else the CPUs (at most PLAN_MAX_THREADS)."""
    import os

    env = os.environ.get("CNC_INTERP_THREADS")
    if env and env.isdigit() and int(env) > 0:
        return int(env)
    return max(1, min(os.cpu_count() or 1, PLAN_MAX_THREADS))


def _joint_rapid(path, kin):
    """The straight joint-space line between a rapid path's end points (one segment).
    A rapid the fit blended (``FitSettings.blend_rapids``) is not straight: it was fitted
    for a machine without kinematics, and planning it here would skip its turns."""
    from ..fit.path import Path

    if not _straight(path):
        raise PlanError(
            f"the rapids ending at line {int(path.line[-1])} were fitted with blends, which a machine "
            f"with kinematics ({kin.name}) cannot follow: fit the program for this machine"
        )
    ends = kin.to_joints(np.stack([path.start, path.end]))
    coef = np.zeros((1, 6, ends.shape[1]))
    coef[0, 0] = ends[0]
    coef[0, 1] = ends[1] - ends[0]
    if not np.any(coef[0, 1]):
        return path  # no joint moves: VPOp plans the (zero-length) item as it is
    return Path(path.axes, np.array([0.0, 1.0]), coef, line=path.line[-1:], feed_mm_s=np.array([np.inf]), rapid=True)


def _straight(path) -> bool:
    """Do a path's segment ends lie on the chord from its start to its end (within the
    join tolerance; a fitted line's end snap moves them by rounding only)?"""
    pts = np.concatenate((path.coef[:, 0, :], path.end[None, :]))
    chord = pts[-1] - pts[0]
    rel = pts - pts[0]
    length2 = float(chord @ chord)
    if length2 > 0:
        rel = rel - np.outer(rel @ chord / length2, chord)
    return bool(np.all(np.abs(rel) <= _JOIN_TOL * np.maximum(1.0, np.abs(pts).max(axis=0))))


def _short_rest(last_step: np.ndarray, first_step: np.ndarray, q_now: np.ndarray, machine, dt: float) -> bool:
    """May the next path start after one period at rest (two equal samples) rather than
    two? Each path was planned from and to rest, so with samples ..., A, R, R, B1 (R the
    joint) every backward difference but one is one a plan checked: the jerk at B1,
    (B1 - R) + (A - R) over dt³ per joint, the first step of the next path plus the last
    of the one before (``last_step``, ``first_step``: (n,) joint steps, mm or deg). It
    is held to the step limits the planners keep (``step_limits``), at the scale of
    ``q_now``: a reversal passes (the steps cancel), a path going on the same way may not."""
    from .step_limits import step_limits

    try:
        _, _, jl = step_limits(machine, dt, 1.0 + float(np.max(np.abs(q_now))))
    except PlanError:  # limits float64 cannot resolve here: the full rest
        return False
    return bool(np.all(np.abs(last_step + first_step) <= jl))


def _count_planner_stats(stats: dict, path_stats) -> None:
    """Program-level counts of how the paths were planned (the optimal planner's route,
    which plan it kept, fallbacks)."""
    if not path_stats:
        return
    for key in ("route", "kept"):
        value = path_stats.get(key)
        if value is not None:
            bucket = stats.setdefault(f"{key}s", {})
            bucket[value] = bucket.get(value, 0) + 1
    if "fallback" in path_stats:
        stats["fallbacks"] = stats.get("fallbacks", 0) + 1
    if path_stats.get("planner") == "safe" or path_stats.get("safe"):
        stats["safe"] = stats.get("safe", 0) + 1


# -- workers ------------------------------------------------------------------------------
_DONE = object()


class _Job:
    """Consecutive paths planned by one worker; their chunks arrive in ``out`` in order
    as (path index in the job, chunk), then ``_DONE`` (or the exception raised). The
    samples waiting in ``out`` are at most ``samples_ahead`` (``put`` waits for room)."""

    __slots__ = ("paths", "out", "cap", "held", "room")

    def __init__(self, paths: list, samples_ahead: int):
        self.paths = paths
        self.out: queue.Queue = queue.Queue()
        self.cap = max(1, samples_ahead)
        self.held = 0  # samples in ``out``
        self.room = threading.Condition()

    def put(self, value, timeout: float) -> bool:
        """Queue ``value`` once there is room for its samples (or ``out`` is empty; the
        end marker and an exception take no room); False if there was none within
        ``timeout`` seconds."""
        n = _samples_of(value)
        with self.room:
            if not self.room.wait_for(lambda: n == 0 or self.held == 0 or self.held + n <= self.cap, timeout):
                return False
            self.held += n
        self.out.put(value)
        return True

    def get(self):
        value = self.out.get()
        n = _samples_of(value)
        if n:
            with self.room:
                self.held -= n
                self.room.notify()
        return value


def _samples_of(value) -> int:
    """Samples in a job's queue entry: (path index, chunk), ``_DONE`` or an exception."""
    return int(value[1].s.shape[0]) if isinstance(value, tuple) else 0


class _Workers:
    """Daemon threads planning jobs in submission order (FIFO: the oldest job always has
    a thread, so a worker blocked on a full queue of a later job cannot stall it). Daemon
    threads never keep an interrupted process alive."""

    def __init__(self, count: int, plan_chunks, info: TimelineInfo, plan_many=None):
        self.info = info
        self.plan_many = plan_many
        self.lock = threading.Lock()
        self.jobs: queue.Queue = queue.Queue()
        self.stop = threading.Event()
        self.plan_chunks = plan_chunks
        self.threads = [
            threading.Thread(target=self._loop, daemon=True, name=f"cnc-interp-plan-{i}") for i in range(count)
        ]
        for t in self.threads:
            t.start()

    def submit(self, job: _Job) -> None:
        self.jobs.put(job)

    def _put(self, job: _Job, value) -> bool:
        while not self.stop.is_set():
            if job.put(value, timeout=0.1):
                return True
        return False

    def _loop(self) -> None:
        import time

        while not self.stop.is_set():
            job = self.jobs.get()
            if job is None:
                return
            t0 = time.thread_time()
            try:
                for item in _plan_job(job, self.plan_chunks, self.plan_many):
                    if not self._put(job, item):
                        return
                self._put(job, _DONE)
            except BaseException as exc:  # handed to the consumer, raised there
                self._put(job, exc)
            finally:
                with self.lock:
                    self.info.plan_cpu_s += time.thread_time() - t0

    def close(self) -> None:
        self.stop.set()
        for _ in self.threads:
            self.jobs.put(None)


class _Inline:
    """The same interface without threads: a job is planned when it is consumed."""

    def __init__(self, plan_chunks, info: TimelineInfo, plan_many=None):
        self.plan_chunks = plan_chunks
        self.info = info
        self.plan_many = plan_many

    def submit(self, job: _Job) -> None:
        pass

    def results(self, job: _Job):
        import time

        it = _plan_job(job, self.plan_chunks, self.plan_many)
        while True:
            t0 = time.thread_time()
            got = next(it, None)
            self.info.plan_cpu_s += time.thread_time() - t0
            if got is None:
                break
            yield got

    def close(self) -> None:
        pass


_FLUSH = object()


def _closing(items, ready, pending):
    """``items``, with ``_FLUSH`` before a pull that would wait for the fit while a job is
    being filled (jobs only group paths for the workers: where they end changes no sample)."""
    it = iter(items)
    while True:
        if ready is not None and pending() and not ready():
            yield _FLUSH
        try:
            item = next(it)
        except StopIteration:
            return
        yield item


def _plan_job(job: _Job, plan_chunks, plan_many):
    """(path index, chunk) of a job's paths in order: the paths ``plan_many`` plans in one
    call, the others through their planner's stream."""
    pre = plan_many(job.paths) if plan_many is not None else None
    for i, path in enumerate(job.paths):
        got = pre[i] if pre is not None else None
        if got is not None:
            yield i, got
            continue
        for chunk in plan_chunks(path):
            yield i, chunk


def _job_results(pool, job: _Job):
    if isinstance(pool, _Inline):
        yield from pool.results(job)
        return
    while True:
        got = job.get()
        if got is _DONE:
            return
        if isinstance(got, BaseException):
            raise got
        yield got


# -- the stream -----------------------------------------------------------------------------
class _Blocks:
    """Collects samples into blocks of ``size`` (copies: the pieces may be views)."""

    def __init__(self, size: int, n: int, events: bool = False):
        self.events: list | None = [] if events else None
        self.full = max(1, int(size))
        # the first blocks are small (the first rows reach the consumer early), then double
        self.size = min(self.full, _FIRST_BLOCK)
        self.n = n
        self.k = 0  # samples handed out
        self.parts: list = []
        self.count = 0

    def add(self, s: np.ndarray, q: np.ndarray, line: np.ndarray):
        """Append samples; yields the blocks that are full."""
        a = 0
        m = s.shape[0]
        while a < m:
            b = min(m, a + self.size - self.count)
            self.parts.append((s[a:b], q[a:b], line[a:b]))
            self.count += b - a
            a = b
            if self.count >= self.size:
                yield self.flush()

    def note(self, code: int, obj=None, s_off: float = 0.0) -> None:
        """An event at the next sample (kept only when the blocks carry events)."""
        if self.events is not None:
            self.events.append((self.k + self.count, code, obj, s_off))

    def flush(self, last: bool = False) -> SampleBlock | None:
        if not self.count:
            return None
        if len(self.parts) == 1:
            s, q, line = (np.array(x) for x in self.parts[0])
        else:
            s = np.concatenate([p[0] for p in self.parts])
            q = np.concatenate([p[1] for p in self.parts], axis=0)
            line = np.concatenate([p[2] for p in self.parts])
        events: tuple = ()
        if self.events:
            end = self.k + self.count
            cut = len(self.events) if last else sum(1 for e in self.events if e[0] < end)
            events, self.events = tuple(self.events[:cut]), self.events[cut:]
        block = SampleBlock(self.k, s, q, line, events)
        self.k += self.count
        self.parts, self.count = [], 0
        self.size = min(self.full, 2 * self.size)
        return block


def iter_timeline(
    items,
    machine,
    settings,
    start,
    window: Window | None = None,
    info: TimelineInfo | None = None,
    progress=None,
    keep_profiles: bool = False,
    source: str = "",
    threads: int | None = None,
    events: bool = False,
):
    """Plan fitted ``items`` (an iterable, consumed lazily) onto one sample clock.

    Args:
        items: fitted items in program order (``Path``, ``Dwell``, ``Stop``).
        machine: ``Machine`` (limits, kinematics); ``settings.dt_s`` is the period.
        settings: ``PlanSettings``.
        start: (n,) program-space position before the first item.
        window: the look-ahead (``Window``; default ``Window()``).
        info: a ``TimelineInfo`` filled in as the stream runs (complete at its end).
        progress: optional callable told how much path length (mm) has been planned.
        keep_profiles: collect the planners' profiles in ``info.profiles``.
        source: the part program's name (for the memory check's message).
        threads: worker threads (default ``_plan_threads()``; 1 plans inline).
        events: give every block its ``events`` (what each sample is, the ``Mark``s
            among the items); the samples are the same either way.
    Yields:
        ``SampleBlock``s, from rest at the start to rest at the end.
    """
    from ..fit.path import Path
    from ..gcode.program import Dwell, Mark, Stop
    from .budget import WindowBudget
    from ..machine.kinematics import make_kinematics
    from .planners import get_path_iterator
    from .vpop import iter_path_plan_vpop

    window = window or Window()
    info = info if info is not None else TimelineInfo()
    dt = float(settings.dt_s)
    kin = make_kinematics(machine)
    joint_map = None if kin.is_identity else kin
    planner = get_path_iterator(settings.planner)
    streams = bool(getattr(planner, "streams", False))
    start_prog = np.asarray(start, dtype=float).reshape(1, -1)
    q_now = kin.to_joints(start_prog)[0] if joint_map is not None else start_prog[0].copy()
    n = machine.n_axes
    if q_now.shape[0] != n:
        raise PlanError(f"bug: the program has {q_now.shape[0]} axes, the machine {n}")
    budget = WindowBudget(machine, dt, source, streams, window)
    pw = window.path_window

    batched = getattr(planner, "batched", None)
    # the optimal planner plans the rapids its batch leaves (a rapid chain fitted smooth
    # through gentle turns); VPOp plans them for the others
    own_rapids = bool(getattr(planner, "plans_rapids", False))

    def plan_many(paths):
        """The plans of a job's paths made in one call: those the planner's ``batched``
        returns planned (the optimal planner's straight paths and rapids), and VPOp's
        compiled batch for the other rapids (unless the planner plans its own) and the
        paths the planner would plan exactly as VPOp does in joint = program space (every
        path without kinematics when VPOp is the planner, the optimal planner's
        VPOp-routed ones): the same samples, the planner's own stats for the path added."""
        from .vpop import plan_many_vpop

        extra = batched(paths, joint_map, machine, dt, settings) if batched is not None else [None] * len(paths)
        out: list = [e if isinstance(e, PathPlan) else None for e in extra]  # planned by the planner's batch
        to_vpop = [(p.rapid and not own_rapids) or e is not None for p, e in zip(paths, extra)]
        sel = [i for i, p in enumerate(paths) if out[i] is None and to_vpop[i]]
        if sel:
            got = plan_many_vpop([paths[i] for i in sel], machine, dt, settings)
            for i, g in zip(sel, got):
                if g is not None and extra[i]:
                    g = replace(g, stats={**(g.stats or {}), **extra[i]})
                out[i] = g
        return out

    def plan_chunks(item):
        if item.rapid and not own_rapids:
            return iter_path_plan_vpop(item, None, machine, dt, settings, window=pw)
        if streams:
            return planner(item, joint_map, machine, dt, settings, window=pw)
        return planner(item, joint_map, machine, dt, settings)

    ready = getattr(items, "ready", None)  # a prefetching source tells if a pull would wait

    def units():
        """Jobs of consecutive paths, and the dwells and stops between them. The first
        jobs are small (the first samples come out early), then each doubles up to the
        window's size."""
        job: list = []
        est = 0.0
        limit = [1, 1.0]  # paths, samples of the job being filled
        for item in _closing(items, ready, lambda: bool(job)):
            if item is _FLUSH:  # the fit has nothing yet: plan what is there
                yield "job", job
                job, est = [], 0.0
                continue
            if isinstance(item, Path):
                if joint_map is not None and item.rapid:
                    item = _joint_rapid(item, kin)
                if item.axes != machine.axes:
                    raise PlanError(f"bug: path axes {item.axes} differ from machine axes {machine.axes}")
                job.append(item)
                est += budget.rough_samples(item)
                if len(job) >= min(limit[0], window.job_paths) or est >= min(limit[1], window.job_samples):
                    yield "job", job
                    job, est = [], 0.0
                    limit = [2 * limit[0], 2.0 * max(limit[1], 64.0)]
            elif isinstance(item, (Dwell, Stop, Mark)):
                if job:
                    yield "job", job
                    job, est = [], 0.0
                yield "item", item
            else:
                raise PlanError(f"bug: unknown timeline item {type(item).__name__}")
        if job:
            yield "job", job

    workers = threads if threads is not None else _plan_threads()
    pool = _Workers(workers, plan_chunks, info, plan_many) if workers > 1 else _Inline(plan_chunks, info, plan_many)
    ahead: deque = deque()
    source_units = units()
    in_flight = 0
    exhausted = False
    blocks = _Blocks(window.block_samples, n, events)
    rest = _REST_RUN  # the machine is at rest before the first sample
    last_step = np.zeros(n)  # the last step of the motion before, for ``_short_rest``
    last_line = 0
    s_off = 0.0
    stats = info.stats

    def refill():
        nonlocal in_flight, exhausted
        while not exhausted and in_flight < max(1, window.jobs_ahead):
            if ahead and ready is not None and not ready():
                break  # consume what is planned rather than wait for the fit
            u = next(source_units, None)
            if u is None:
                exhausted = True
                break
            if u[0] == "job":
                budget.check(u[1])
                job = _Job(u[1], window.samples_ahead)
                pool.submit(job)
                in_flight += 1
                ahead.append(("job", job))
            else:
                ahead.append(u)

    def hold(count: int, line: int, span: int = SPAN_REST):
        nonlocal last_step
        if count > 0:
            last_step = np.zeros(n)
            blocks.note(span)
            yield from blocks.add(
                np.full(count, s_off), np.repeat(q_now[None, :], count, axis=0), np.full(count, line, dtype=np.int64)
            )

    try:
        blocks.note(SPAN_REST)
        yield from blocks.add(np.zeros(1), q_now[None, :].copy(), np.zeros(1, dtype=np.int64))
        while True:
            refill()
            if not ahead:
                break
            kind, unit = ahead.popleft()
            if kind == "item":
                if isinstance(unit, Mark):
                    blocks.note(EVENT_MARK, unit)
                    continue
                if isinstance(unit, Dwell):
                    count = int(math.ceil(unit.seconds / dt - 1e-9)) if unit.seconds > 0 else 0
                    last_line = int(unit.line)
                    yield from hold(count, last_line, SPAN_DWELL)
                    rest += count
                    stats["dwells"] += 1
                else:  # stop: come to rest (already at rest between paths)
                    last_line = int(unit.line)
                    yield from hold(_REST_RUN - rest, last_line)
                    rest = max(rest, _REST_RUN)
                    stats["stops"] += 1
                continue
            in_flight -= 1
            cur = -1
            spanned = False
            first = False
            item = None
            for i, chunk in _job_results(pool, unit):
                if i != cur:  # a new path's first chunk
                    cur, item, first, spanned = i, unit.paths[i], True, False
                s, q = chunk.s, chunk.q
                if first:
                    q0 = q[0]
                    if not np.all(np.abs(q0 - q_now) <= _JOIN_TOL * np.maximum(1.0, np.abs(q_now))):
                        raise PlanError(
                            f"bug: path at line {int(item.line[0])} starts at "
                            f"{q0.tolist()}, the machine is at {q_now.tolist()}"
                        )
                    s, q = s[1:], q[1:]
                    if s.shape[0] or not chunk.last:
                        moving = True
                    else:
                        moving = False
                    if moving:
                        need = _REST_RUN
                        if rest == 1 and s.shape[0] and _short_rest(last_step, q[0] - q_now, q_now, machine, dt):
                            need = _SHORT_REST_RUN
                        yield from hold(need - rest, last_line)
                        rest = 1
                    first = False
                if s.shape[0]:
                    if not spanned:
                        blocks.note(SPAN_PATH, item, s_off)
                        spanned = True
                    seg = item.segment_of_s(s)
                    yield from blocks.add(s_off + s, q, item.line[seg])
                    last_step = q[-1] - (q[-2] if q.shape[0] > 1 else q_now)
                    q_now = q[-1].copy()
                    last_line = int(item.line[-1])
                if chunk.last:
                    if item.rapid:
                        stats["rapids"] += 1
                    else:
                        stats["paths"] += 1
                        _count_planner_stats(stats, chunk.stats)
                        if keep_profiles and chunk.profiles is not None:
                            info.profiles.append(chunk.profiles)
                    if chunk.status != "ok":
                        info.status = chunk.status
                    s_off += float(item.length)
                    if progress is not None:
                        progress(float(item.length))
        # the program ends at rest even without M2/M30: the held samples make it explicit
        yield from hold(_REST_RUN - rest, last_line)
        last = blocks.flush(last=True)
        if last is not None:
            yield last
        info.samples = blocks.k
        info.path_length_mm = s_off
    finally:
        pool.close()


def plan_program(fit_result, machine, settings, progress=None, window: Window | None = None) -> Trajectory:
    """Plan every item of ``fit_result`` on one timeline, in memory (see module docstring).

    Args:
        fit_result: ``FitResult`` (items in program order).
        machine: ``Machine`` (limits, kinematics); ``settings.dt_s`` is the period.
        settings: ``PlanSettings``.
        progress: optional callable ``progress(n)`` told how much path length (mm)
            has been planned since its last call.
        window: the look-ahead (default: everything at once); the result is the same.
    Returns:
        ``Trajectory`` on the machine's axes, from rest at the start to rest at the end.
    """
    info = TimelineInfo()
    blocks = list(
        iter_timeline(
            fit_result.items,
            machine,
            settings,
            fit_result.program.start,
            window=window or Window.whole(),
            info=info,
            progress=progress,
            keep_profiles=True,
            source=fit_result.program.source,
        )
    )
    return trajectory_of(blocks, machine, settings, info)


def feed_of(s: np.ndarray, s_prev: float | None, dt: float) -> np.ndarray:
    """Path speed (K,) of samples s: backward difference, 0 at the very first sample
    (``s_prev`` None); the same values whatever the blocks are."""
    feed = np.empty(s.shape[0])
    if s.shape[0] == 0:
        return feed
    feed[0] = 0.0 if s_prev is None else (s[0] - s_prev) / dt
    if s.shape[0] > 1:
        feed[1:] = np.diff(s) / dt
    return feed


def trajectory_of(blocks, machine, settings, info: TimelineInfo) -> Trajectory:
    """A ``Trajectory`` from the whole stream's blocks."""
    dt = float(settings.dt_s)
    n = machine.n_axes
    if blocks:
        s = np.concatenate([b.s for b in blocks])
        q = np.concatenate([b.q for b in blocks], axis=0)
        line = np.concatenate([b.line for b in blocks])
    else:
        s, q, line = np.zeros(0), np.zeros((0, n)), np.zeros(0, dtype=np.int64)
    k = q.shape[0]
    settings_dict = settings.to_dict() if hasattr(settings, "to_dict") else dict(settings)
    settings_dict["stats"] = dict(info.stats)
    return Trajectory(
        axes=machine.axes,
        dt_s=dt,
        t=np.arange(k) * dt,
        s=s,
        feed=feed_of(s, None, dt),
        q=q,
        line=line,
        planner=settings.planner,
        settings=settings_dict,
        status=info.status,
        profiles=info.profiles or None,
    )

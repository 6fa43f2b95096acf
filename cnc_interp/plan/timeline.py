"""The whole-program timeline: every fitted item planned onto one sample clock.

``plan_program`` walks a ``FitResult``'s items in order:

* ``Path`` (cutting): the chosen per-path planner (``plan.planners``) through the
  machine's kinematics, from rest to rest;
* ``Path(rapid=True)``: always VPOp with no feed limit (the axes' own limits),
  straight in joint space;
* ``Dwell``: the position held for ceil(seconds / dt) samples;
* ``Stop`` (M0, M1, M6, ...): the machine is already at rest between paths; the
  stop is marked by the held position (no extra time is modelled for the pause).

The pieces are joined on t = k·dt. Between two motions there are always at least
three equal samples, so every backward difference (up to jerk) across the joint
sees the machine at rest, as each per-path plan assumed. ``s`` is the cumulative
path length (rapids included), ``feed`` its backward difference and ``line`` the
source line executed at each sample.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import PlanError
from .trajectory import Trajectory

#: samples at rest needed between motions (v, a, j stencils all at rest)
_REST_RUN = 3
#: the start of a path may differ from where the machine is by float rounding only
_JOIN_TOL = 1e-6


def _plan_threads() -> int:
    """Threads planning paths at once: CNC_INTERP_THREADS, else the CPUs (at most PLAN_MAX_THREADS)."""
    import os

    from ..constants import PLAN_MAX_THREADS

    env = os.environ.get("CNC_INTERP_THREADS")
    if env and env.isdigit() and int(env) > 0:
        return int(env)
    return max(1, min(os.cpu_count() or 1, PLAN_MAX_THREADS))


def _item_kind(item) -> str:
    from ..fit.path import Path
    from ..gcode.program import Dwell, Stop

    if isinstance(item, Path):
        return "path"
    if isinstance(item, Dwell):
        return "dwell"
    if isinstance(item, Stop):
        return "stop"
    raise PlanError(f"bug: unknown timeline item {type(item).__name__}")


def _joint_rapid(path, kin):
    """The straight joint-space line between a rapid path's end points (one segment)."""
    from ..fit.path import Path

    ends = kin.to_joints(np.stack([path.start, path.end]))
    coef = np.zeros((1, 6, ends.shape[1]))
    coef[0, 0] = ends[0]
    coef[0, 1] = ends[1] - ends[0]
    if not np.any(coef[0, 1]):
        return path  # no joint moves: VPOp plans the (zero-length) item as it is
    return Path(path.axes, np.array([0.0, 1.0]), coef, line=path.line[-1:],
                feed_mm_s=np.array([np.inf]), rapid=True)


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


def plan_program(fit_result, machine, settings, progress=None) -> Trajectory:
    """Plan every item of ``fit_result`` on one timeline (see module docstring).

    Args:
        fit_result: ``FitResult`` (items in program order).
        machine: ``Machine`` (limits, kinematics); ``settings.dt_s`` is the period.
        settings: ``PlanSettings``.
        progress: optional callable ``progress(n)`` told how much path length (mm)
            has been planned since its last call.
    Returns:
        ``Trajectory`` on the machine's axes, from rest at the start to rest at the end.
    """
    from .kinematics import make_kinematics
    from .planners import get_planner
    from .vpop import plan_path_vpop

    dt = float(settings.dt_s)
    kin = make_kinematics(machine)
    joint_map = None if kin.is_identity else kin
    planner = get_planner(settings.planner)
    start_prog = np.asarray(fit_result.program.start, dtype=float).reshape(1, -1)
    q_now = kin.to_joints(start_prog)[0] if joint_map is not None else start_prog[0].copy()
    n = machine.n_axes
    if q_now.shape[0] != n:
        raise PlanError(f"bug: the program has {q_now.shape[0]} axes, the machine {n}")

    qs = [q_now[None, :]]
    ss = [np.zeros(1)]
    lines = [np.zeros(1, dtype=np.int64)]
    s_off = 0.0
    rest = _REST_RUN  # the machine is at rest before the first sample
    last_line = 0
    status = "ok"
    stats = {"paths": 0, "rapids": 0, "dwells": 0, "stops": 0}
    profiles = []

    def hold(count: int, line: int) -> None:
        if count > 0:
            qs.append(np.repeat(qs[-1][-1:], count, axis=0))
            ss.append(np.full(count, s_off))
            lines.append(np.full(count, line, dtype=np.int64))

    def plan_one(item):
        if item.rapid:
            return plan_path_vpop(item, None, machine, dt, settings)
        return planner(item, joint_map, machine, dt, settings)

    # Rapids are straight in joint space: under non-trivial kinematics the fitted
    # (program-space) rapid is replaced by the joint-space line between its ends.
    items = tuple(_joint_rapid(it, kin) if (joint_map is not None and _item_kind(it) == "path"
                                            and it.rapid) else it
                  for it in fit_result.items)
    paths = [it for it in items if _item_kind(it) == "path"]
    for it in paths:
        if it.axes != machine.axes:
            raise PlanError(f"bug: path axes {it.axes} differ from machine axes {machine.axes}")
    # paths are planned independently (rest to rest): spread them over threads (the
    # compiled step loop releases the GIL) and join them in program order
    workers = min(_plan_threads(), len(paths))
    if workers > 1:
        from concurrent.futures import ThreadPoolExecutor

        pool = ThreadPoolExecutor(max_workers=workers)
        futures = iter([pool.submit(plan_one, it) for it in paths])
    else:
        pool = None
        futures = None

    for item in items:
        kind = _item_kind(item)
        if kind == "path":
            try:
                plan = next(futures).result() if futures is not None else plan_one(item)
            except BaseException:
                if pool is not None:
                    pool.shutdown(wait=False, cancel_futures=True)
                raise
            if item.rapid:
                stats["rapids"] += 1
            else:
                stats["paths"] += 1
                if plan.profiles is not None:
                    profiles.append(plan.profiles)
                _count_planner_stats(stats, plan.stats)
            if plan.status != "ok":
                status = plan.status
            q0 = plan.q[0]
            if not np.all(np.abs(q0 - q_now) <= _JOIN_TOL * np.maximum(1.0, np.abs(q_now))):
                raise PlanError(f"bug: path at line {int(item.line[0])} starts at {q0.tolist()}, "
                                f"the machine is at {q_now.tolist()}")
            moves = plan.q.shape[0] > 1
            if moves:
                hold(_REST_RUN - rest, last_line)
                seg = item.segment_of_s(plan.s[1:])
                qs.append(plan.q[1:])
                ss.append(s_off + plan.s[1:])
                lines.append(item.line[seg])
                last_line = int(item.line[-1])
                q_now = plan.q[-1].copy()
                rest = 1
            s_off += float(item.length)
            if progress is not None:
                progress(float(item.length))
        elif kind == "dwell":
            count = int(math.ceil(item.seconds / dt - 1e-9)) if item.seconds > 0 else 0
            last_line = int(item.line)
            hold(count, last_line)
            rest += count
            stats["dwells"] += 1
        else:  # stop: come to rest (already at rest between paths)
            last_line = int(item.line)
            hold(_REST_RUN - rest, last_line)
            rest = max(rest, _REST_RUN)
            stats["stops"] += 1

    # the program ends at rest even without M2/M30: the held samples make it explicit
    hold(_REST_RUN - rest, last_line)
    if pool is not None:
        pool.shutdown()
    q = np.concatenate(qs, axis=0)
    s = np.concatenate(ss)
    line = np.concatenate(lines)
    k = q.shape[0]
    feed = np.zeros(k)
    if k > 1:
        feed[1:] = np.diff(s) / dt
    settings_dict = settings.to_dict() if hasattr(settings, "to_dict") else dict(settings)
    settings_dict["stats"] = stats
    return Trajectory(axes=machine.axes, dt_s=dt, t=np.arange(k) * dt, s=s, feed=feed, q=q,
                      line=line, planner=settings.planner, settings=settings_dict,
                      status=status, profiles=profiles or None)

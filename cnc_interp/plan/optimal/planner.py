"""The optimal planner's driver: one path through route, sampling, refinement and selection.

``iter_path_plan_optimal`` streams a path's plan as ``PathPlan`` chunks (``plan.base``'s
contract: their concatenation is the one-shot plan, ``plan_path_optimal``);
``batched_optimal`` plans a job's straight paths (``line``) and gives the VPOp-routed
ones to VPOp's compiled batch (their end window refined, ``_end_window``).

Per path: the route (``route``); the sampled plan of the profile (``sampling``) or
VPOp's; ``_refine_passes`` passes of window refinement (``refine``) by the effort and the
period; for a path planned whole, the selection (``select``) against VPOp's plan of it,
made alongside on a thread of its own. Long profile-routed paths
run a stage on a thread of its own (``prefetch.Prefetch``; the samples do not depend
on it): the profile and its sampling ahead of the refinement from ``tuning.ahead_s`` of
static duration, or, unrefined, the LP windows ahead of the sampling from
``tuning.feed_ahead_s``. Where the profile gives up (``_Fallback``) before any sample
left, VPOp plans the path; after, the path brakes to rest from the last sample out and
the safe planner plans the rest (``vpop.planner.rescue``).
"""

from __future__ import annotations

import numpy as np

from ...constants import VPOP_MIN_LENGTH
from ...errors import PlanError
from ..base import PathPlan, collect_path_plan
from ..prefetch import Prefetch
from ..settings import OPTIMAL_CHUNK, OptimalOptions
from .context import _Fallback, _options, _or, _Path
from .line import plan_lines
from .refine import Refiner, _end_refined, _refined, path_refine_problem, refine_end
from .route import _ROUTED, Route, _route, _RouteInputs, route_many
from .sampling import _sampled, _vpop_stage
from .select import VpopAlongside, _better_of


def _refine_passes(opts: OptimalOptions, dt: float, route: Route) -> int:
    """Passes of window refinement for a path on ``route`` at ``opts.effort``: every
    window at coarse periods or at the max effort; at fine ones only the profile's dips
    and ends, once (VPOp's plans there are within a few periods per path of the discrete
    optimum, and windows on every short path would cost more than planning). Fast: none
    at fine periods, one pass at coarse ones (where it is cheap and carries the most:
    paper 001's trident at 6 ms, 324 periods unrefined, 296 after one pass as after two);
    ``opts.refine_passes`` when set."""
    T = opts.tuning
    if opts.refine_passes is not None:
        return int(opts.refine_passes)
    if opts.effort == "fast":
        return 0 if dt < T.full_refine_dt else 1
    if opts.effort == "max" or dt >= T.full_refine_dt:
        return T.refine_passes
    return 1 if route == Route.PROFILE else 0


def _end_window(opts: OptimalOptions, dt: float, route: Route) -> bool:
    """Is the window at the end of VPOp's plan refined once more, after the refinement
    passes (``refine._end_refined``)? At every effort but fast, unless the passes are
    asked for: VPOp's braking into the end loses a few periods a path against the
    discrete optimum, which that window (``tuning.end_window``) recovers
    (stellabee1's first 3000 lines: 1463 periods of 544 paths, for about 4 window solves
    a path; at fine periods the normal effort refines no other window of VPOp's plans,
    which would cost more than planning)."""
    return route == Route.VPOP and opts.refine_passes is None and opts.effort != "fast"


def _planned_whole(opts: OptimalOptions, dt: float, rough_s: float) -> bool:
    """Is a profile-routed path of rough duration ``rough_s`` planned whole before any
    sample leaves, and compared with VPOp's plan (``select``)? At most
    ``opts.compare_s``, default ``tuning.compare_samples`` periods."""
    return rough_s <= float(_or(opts.compare_s, opts.tuning.compare_samples * dt))


def _targeted(opts: OptimalOptions, dt: float) -> bool:
    """Does the refinement visit only the dips and ends, under the pause rule (fine
    periods), rather than every window?"""
    return dt < opts.tuning.full_refine_dt and opts.effort != "max"


def _rechunk(blocks, chunk: int):
    """Re-cut a stream of (s, q) blocks into chunks of ``chunk`` samples (the last shorter)."""
    buf_s, buf_q, held = [], [], 0
    for bs, bq in blocks:
        buf_s.append(bs)
        buf_q.append(bq)
        held += bs.shape[0]
        if held < chunk:
            continue
        # one copy per block, then chunks cut from it (joining the rest again for each
        # chunk copied a whole path planned as one block once per chunk: O(n²))
        s = np.concatenate(buf_s)
        q = np.concatenate(buf_q)
        start = 0
        while held - start >= chunk:
            yield s[start : start + chunk], q[start : start + chunk]
            start += chunk
        buf_s, buf_q, held = [s[start:]], [q[start:]], held - start
    if held:
        yield np.concatenate(buf_s), np.concatenate(buf_q)


def iter_path_plan_optimal(path, joint_map, machine, dt_s: float, settings=None, window: int | None = None):
    """The plan of one path as a stream of ``PathPlan`` chunks (``plan.base``'s contract):
    chunks of ``settings.optimal.chunk_samples`` (default ``OPTIMAL_CHUNK``) samples as soon
    as no later stage can change them; only the last (``last=True``) carries the stats.
    Their concatenation is the one-shot plan whatever ``window`` (VPOp's own stream
    buffer on paths VPOp plans; ``None``: whole) and chunk size."""
    stats = {}
    pending = None
    for s, q in _iter(path, joint_map, machine, dt_s, settings, stats, window):
        if pending is not None:
            yield PathPlan(s=pending[0], q=pending[1], last=False)
        pending = (s, q)
    stats["samples"] = stats.get("samples_total", 0)
    stats.pop("samples_total", None)
    yield PathPlan(s=pending[0], q=pending[1], stats=stats)


iter_path_plan_optimal.streams = True
#: the timeline gives this planner the rapids too (a straight one takes ``line``'s plan,
#: a rapid chain fitted smooth through gentle turns the planner's routes, in joint space)
iter_path_plan_optimal.plans_rapids = True


def batched_optimal(paths, joint_map, machine, dt_s: float, settings=None) -> list:
    """The plans of a job's ``paths`` this planner makes in one call, where the joints
    are the program axes: straight paths by ``line``, and the paths VPOp plans whole
    by ``vpop.plan_many_vpop``, one compiled call for a job's short paths instead of a
    VPOp run per path on this planner's own table (5-9x the planning time of flowsnake
    and zigzag_0.002_0.0005, whose every path goes to VPOp), their end window refined
    where ``_end_window`` says so. Returns, per path, a ``PathPlan`` (the same samples
    as the path's streamed plan), the stats it adds to the timeline's VPOp batch
    ({"route": Route.VPOP}: VPOp's plan unrefined, or a long path the batch leaves to
    VPOp's stream), or ``None``: a path this planner streams."""
    out: list = [None] * len(paths)
    opts = _options(settings)
    dt = float(dt_s)
    held: dict = {}
    _ROUTED.keep(held)
    if opts.route is None:
        # straight paths take their exact plan (rapids are in joint space already)
        take = [i for i, p in enumerate(paths) if p.rapid or joint_map is None]
        for i, plan in zip(take, plan_lines([paths[i] for i in take], machine, dt)):
            out[i] = plan
    if joint_map is not None or opts.route == Route.PROFILE or _refine_passes(opts, dt, Route.VPOP):
        return out
    eligible = [
        i
        for i, path in enumerate(paths)
        if out[i] is None
        and not path.rapid
        and path.length > VPOP_MIN_LENGTH
        and np.isfinite(path.length)
        and np.all(np.isfinite(path.coef))
    ]
    routes = route_many([paths[i] for i in eligible], machine, opts.tuning)
    for i, route in zip(eligible, routes):
        if route is None:
            continue  # no joint table: the error is raised in order when the path is streamed
        if opts.route:
            route = Route(opts.route)
        if route == Route.VPOP:
            out[i] = {"route": Route.VPOP}
        else:
            # the few the profile plans: their inputs (joint table, route) made once, here
            inputs = _RouteInputs(paths[i], None, machine, opts.tuning)
            _route(inputs)
            held[id(paths[i])] = (paths[i], inputs)
    if _end_window(opts, dt, Route.VPOP):
        _plan_vpop_ends(paths, out, machine, dt, settings, opts)
    return out


def _plan_vpop_ends(paths, out, machine, dt: float, settings, opts: OptimalOptions) -> None:
    """The VPOp-routed paths of ``out`` planned in VPOp's batch and their end window
    refined (``_end_window``), in place: the same samples as their streamed plan. A path
    the batch leaves (a long one, which streams) keeps its mark."""
    from ..vpop import plan_many_vpop

    sel = [i for i, m in enumerate(out) if isinstance(m, dict)]
    for i, got in zip(sel, plan_many_vpop([paths[i] for i in sel], machine, dt, settings)):
        if got is None:
            continue
        ref = Refiner(path_refine_problem(paths[i], None, machine, dt), opts.tuning)
        s, q, dropped = refine_end(ref, got.s, got.q, 0)
        stats = {**(got.stats or {}), "route": Route.VPOP, "refined_periods": dropped, "refine_solves": ref.solves}
        out[i] = PathPlan(s=s, q=q, stats=stats)


iter_path_plan_optimal.batched = batched_optimal


def _iter(path, joint_map, machine, dt_s, settings, stats, window):
    """(s, q) chunks of the plan (see ``iter_path_plan_optimal``); fills ``stats``."""
    from ..joint_table import _positions

    if path.rapid:
        joint_map = None
    dt = float(dt_s)
    if not (np.isfinite(path.length) and np.all(np.isfinite(path.coef))):
        raise PlanError(f"bug: the fitted path ending at line {int(path.line[-1])} is not finite")
    opts = _options(settings)
    T = opts.tuning
    chunk = max(1, int(_or(opts.chunk_samples, OPTIMAL_CHUNK)))
    if path.length <= VPOP_MIN_LENGTH:
        stats["samples_total"] = 1
        yield np.zeros(1), _positions(path, path.breaks[:1], joint_map)
        return
    routed = _ROUTED.take(path, joint_map)  # a path the batch routed is no line
    if routed is None and opts.route is None and (joint_map is None or path.rapid):
        (line,) = plan_lines([path], machine, dt)
        if line is not None:
            stats.update(line.stats)
            stats["samples_total"] = line.s.shape[0]
            yield from _rechunk([(line.s, line.q)], chunk)
            return
    ctx = _Path(path, joint_map, machine, dt, settings, routed)
    ctx.window = window
    targeted = _targeted(opts, dt)
    route = Route(opts.route) if opts.route else _route(ctx)
    ctx.stats["route"] = ctx.planned_route = route
    passes = _refine_passes(opts, dt, route)
    ctx.whole = route == Route.PROFILE and _planned_whole(opts, dt, ctx.rough_s)
    long_path = route == Route.PROFILE and ctx.duration_s >= (T.ahead_s if passes else T.feed_ahead_s)
    # a long path's second thread: the profile's windows ahead of the sampling without
    # refinement, else the profile and its sampling ahead of the refinement
    stage = _sampled(ctx, ahead=long_path and not passes) if route == Route.PROFILE else _vpop_stage(ctx, window)
    if long_path and passes:
        # the refinement of one stretch while the next is profiled
        stage = Prefetch(stage, ahead=T.ahead_blocks, name="cnc-interp-profile")
    stage = _refine_stages(ctx, stage, passes, targeted, _end_window(opts, dt, route))
    if ctx.whole:
        ctx.alongside = VpopAlongside(ctx)  # VPOp's plan to compare, on a thread of its own
        stage = _better_of(ctx, stage, passes, targeted)
    try:
        yield from _drain(ctx, stage, chunk, window, opts, targeted, stats)
    finally:
        if ctx.alongside is not None:
            ctx.alongside.close()


def _drain(ctx, stage, chunk: int, window, opts: OptimalOptions, targeted: bool, stats):
    """``stage``'s samples in chunks of ``chunk``; where the profile gives up (``_Fallback``)
    VPOp's plan, or after samples are out, the rescue (see ``_iter``)."""
    path, machine, settings, dt = ctx.path, ctx.machine, ctx.settings, ctx.dt
    produced = 0
    tail_s = tail_q = None  # the last three samples out (a rescue brakes from them)
    try:
        for s, q in _rechunk(stage, chunk):
            produced += s.shape[0]
            tail_s, tail_q = _tail(tail_s, tail_q, s, q)
            yield s, q
    except _Fallback as why:
        if produced:
            # samples are out: brake to rest from the last one, the safe planner for
            # the rest (a stall is an outcome, not an error)
            from ..vpop.planner import rescue

            what = f"the optimal planner gave up on the path ending at line {int(path.line[-1])} ({why})"
            plan = rescue(ctx.prepared(), tail_s, tail_q, ctx.joint_map, machine, settings, what)
            ctx.stats.update({k: plan.stats[k] for k in ("fallback", "safe", "rescued_at")})
            ctx.fallback = str(plan.stats["fallback"])
            produced += plan.s.shape[0]
            yield plan.s, plan.q
            stats.update(ctx.stats)
            stats["samples_total"] = produced
            return
        ctx.stats["fallback"] = ctx.fallback = str(why)
        passes = _refine_passes(opts, dt, Route.VPOP)
        vpop = ctx.alongside.whole() if ctx.alongside is not None else _vpop_stage(ctx, window)
        stage = _refine_stages(ctx, vpop, passes, targeted, _end_window(opts, dt, Route.VPOP))
        for s, q in _rechunk(stage, chunk):
            produced += s.shape[0]
            yield s, q
    stats.update(ctx.stats)
    stats["samples_total"] = produced


def _refine_stages(ctx, stage, passes: int, targeted: bool, end_window: bool):
    """``stage`` through ``passes`` of window refinement, then the end window if asked."""
    for _ in range(passes):
        stage = _refined(ctx, stage, targeted)
    return _end_refined(ctx, stage) if end_window else stage


def _tail(tail_s, tail_q, s, q):
    """The last three samples of those out before and ``s``, ``q``."""
    if tail_s is not None and s.shape[0] < 3:
        s, q = np.concatenate((tail_s, s)), np.concatenate((tail_q, q))
    return s[-3:].copy(), q[-3:].copy()


def plan_path_optimal(path, joint_map, machine, dt_s: float, settings=None) -> PathPlan:
    """Plan one path from rest to rest (see the package docstring): the concatenation of
    ``iter_path_plan_optimal``'s chunks."""
    return collect_path_plan(iter_path_plan_optimal(path, joint_map, machine, dt_s, settings))

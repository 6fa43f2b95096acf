"""The near-time-optimal planner: a feed-profile LP, an exact sampler, window refinement.

``plan_path_optimal(path, joint_map, machine, dt_s, settings)`` plans one path from
rest to rest; ``iter_path_plan_optimal`` is the same plan as a generator of
``PathPlan`` chunks (``plan.base``'s streaming contract: their concatenation is byte for
byte the one-shot plan). Stages, each a generator
that only ever looks a bounded distance ahead:

1. profile (``feedprofile``): w(s) = ṡ², near-time-optimal under every axis's
   velocity, acceleration and jerk limit and the feed, as a linear program over a
   cubic B-spline, window by window (each window ends at rest and commits its first
   half);
2. sampling (``timelaw`` + ``_track_kernels.track``): the profile's time law, one
   sample per period, each checked with exactly the float operations of ``verify``
   and moved to the nearest allowed position where the reference would exceed a
   limit. Where no position is allowed (the LP holds its limits at collocation
   points), the reference is lowered by a smooth dip around that place and the
   stretch is sampled again; near the end, or after ``OPT_RETRY_DEPTHS`` dips, VPOp's
   step loop (``vpop.VpopRun``) takes over from a few samples back;
3. refinement (``refine``): windows of samples shortened by whole periods where the
   discrete problem allows it (averaging over a few periods: short geometric features,
   jumps of q_sss at segment joins, the start and the stop).

Where a path is planned whole (``OPT_COMPARE_SAMPLES``), one the profile planned with
trouble (VPOp took over early, or many dips), or a long one on which VPOp's first seconds
run ahead of the profile's (``OPT_PROBE_*``), is also planned by VPOp and the shorter plan
kept (``_better_of``).

Every sample is exact at every stage. Memory: the samples held back are those a
later stage may still change (``OPT_HOLD_S`` of motion plus a window).
"""

from __future__ import annotations

import threading

import numpy as np

from ..constants import VPOP_LIMIT_SHRINK, VPOP_MIN_LENGTH
from ..errors import PlanError
from .base import PathPlan, collect_path_plan
from .prefetch import Prefetch
from .settings import OptimalOptions
from .step_limits import position_scale, step_limits

#: depths of the successive dips of w around a place where the sampler got stuck
OPT_RETRY_DEPTHS = (0.04, 0.1, 0.2, 0.4)
#: every stuck place gets the dips above; a path gets at most OPT_RETRY_PLACES places
#: worth plus one dip per OPT_RETRY_PER_S of its rough duration
OPT_RETRY_PLACES = 4
OPT_RETRY_PER_S = 0.05
#: a dip spans this much motion at the reference speed before the stuck place (half as
#: much after it), s: wide enough that the lowered reference stays smooth
OPT_RETRY_SPAN_S = 0.1
#: when the sampler gets stuck within this much reference time of the end (or after the
#: last dip), VPOp finishes the path from so many samples back (the first that works)
OPT_TAIL_S = 0.5
OPT_HANDOVER_BACK = (2, 6, 16, 40, 100, 250)
#: samples held back by the sampler for dips and hand-overs: this much motion plus the
#: longest hand-over
OPT_HOLD_S = 0.25
#: passes of the window refinement over the sampled plan
OPT_REFINE_PASSES = 2
#: periods at and above which every window is refined; below, only the path's ends and
#: dips of the speed (targeted), the rest costs more than it gains
OPT_FULL_REFINE_DT = 0.002
#: targeted refinement (fine periods) is judged by blocks of OPT_REFINE_PROBE window
#: solves: a block that gained less than OPT_REFINE_RATE periods per solve pauses it for
#: OPT_REFINE_PAUSE strides (each solve costs ~0.4-3 ms of CPU: refining every dip of
#: stellabee1's short CAM paths cost ~0.25 s a path; zigzag_0.002_0.001 gains 0.89
#: period per solve on axis_mm.ini, 27 % of its cycle, and on LinuxCNC's XYZ machine
#: (the LinuxCNC comparison) blocks of 0.4-0.6, 10 % of its cycle: 0.6 left it slower than LinuxCNC)
OPT_REFINE_PROBE = 30
OPT_REFINE_RATE = 0.4
OPT_REFINE_PAUSE = 50
#: a profile-routed path planned whole is also planned with the profile's knots this
#: share of ``feedprofile.FEED_KNOT_TIME_S`` apart, and the shorter plan kept (on
#: generic-mill: LHchips4 531 periods shorter, 3D_Chips 136; the trochoidal excerpt of
#: ``benchmarks/optimality.py`` 1564 -> 1547)
OPT_ALT_KNOT_SHARE = 0.5
#: ... when VPOp took its plan over early (or the profile gave up) and it lasts at most this
#: long, s (a longer path costs too much to plan twice: zigzag_0.002_0.001, one 50 s path,
#: 15 CPU-s more for nothing)
OPT_ALT_KNOT_MAX_S = 2.5
#: a step below this share of the largest within a window around it marks a dip
OPT_DIP = 0.7
#: a path goes through the profile when its static speed limit (curvature, jerk) is
#: below OPT_ROUTE_SPEED of its feed and axis speeds on at least OPT_ROUTE_SHARE of its
#: length and it lasts at least OPT_ROUTE_MIN_S at those limits (plus ramps); otherwise
#: VPOp, which is within a fraction of a per cent of the optimum where the feed or an
#: axis speed binds, and on short paths (the profile's windows cost ~30 ms per path
#: there for ~1 %: stellabee1)
OPT_ROUTE_SPEED = 0.9
OPT_ROUTE_SHARE = 0.03
OPT_ROUTE_MIN_S = 0.5
#: paths whose travel at the feed plus ramps is shorter than this take VPOp at once
OPT_ROUTE_TINY_S = 0.1
#: a profile-routed path whose rough duration is at most this many samples is planned
#: whole before any of its samples leaves (this bounds the memory a path takes, like
#: VPOp's own stream window): it is one LP window when short enough
#: (``feedprofile.FEED_WHOLE_KNOTS``), and when the profile got stuck for good before its
#: last OPT_COMPARE_TAIL_S (VPOp planned the rest) it is also planned by VPOp and the
#: shorter plan kept. Longer paths stream the profile's plan. The
#: ``OptimalOptions.compare_s`` overrides it: 0 makes every sample depend on the path up to one
#: profile window ahead only, as a streaming pipeline wants.
OPT_COMPARE_SAMPLES = 1 << 18
#: ... unless the profile reached the path's end (no hand-over to VPOp, or one within
#: this much motion of the end): then it is kept as it is
OPT_COMPARE_TAIL_S = 0.3
#: ... and only when VPOp took the profile's plan over before this share of its samples
#: (after the hand-over the plan is VPOp's own, and the profile's part before it is
#: mostly shorter than VPOp's: on stellabee1, axis_mm.ini, VPOp's plan won on 37 of the
#: 334 paths handed over before half their plan, by 1,167 periods, and on 1 of the 871
#: handed over later, by 1 period; those runs cost ~8 % of the fast effort's CPU there)
OPT_COMPARE_BEFORE = 0.5
#: ... and after this share: a plan handed over within its first 5 % is VPOp's own but
#: for its start, and VPOp's plan from the start gains little more than that start could.
#: Over the axis_mm.ini sweep (fast) three paths were handed over that soon; VPOp's plans
#: of them were longer (13,606 against 13,594 samples on stellabee1, 59,412 and 118,387
#: against 59,409 and 118,379 on trochoidal), and planning them again cost 191k VPOp
#: samples, about 2 of trochoidal's 7 planning CPU-s
OPT_COMPARE_AFTER = 0.05
#: ... or when the profile's plan reached its end through at least this many dips (each
#: lowers the reference around a stuck place). Over the axis_mm.ini sweep (fast) VPOp's
#: plan was shorter on 11 of the 3,199 paths with dips, by 2,051 periods, 1,847 of them on
#: trochoidal's path to line 11370 (356 dips: 94,232 against 92,385); 12 paths have 50
#: dips or more (335k samples to plan again), and that path is among them
OPT_COMPARE_DIPS = 50
#: ... or, for a profile's plan of at least OPT_PROBE_MIN_S (s), when VPOp's plan reaches
#: the arc length of its first OPT_PROBE_S (s) OPT_PROBE_AHEAD sooner than the profile's
#: (VPOp's stream stops there otherwise: the probe costs VPOp's preparation of the path
#: and its first samples, ~0.055 s on zigzag_0.002_0.001's 74k table pieces).
#: The continuous profile runs slower than VPOp on G1 trochoids (trochoidal's path to
#: line 4766 on generic-mill: 44,463 periods against 42,865), and once the profile met
#: the jerk where q_sss peaks (feedprofile.FEED_PEAK_SHARE) it no longer dipped there.
#: VPOp hands samples out only after a checkpoint, so the probe runs with checkpoints every
#: OPT_PROBE_S (its buffers then hold about twice that plus the braking distance). Over
#: the axis_mm.ini sweep (fast): trochoidal -3.1 s, spiral_lines -2.0 s, -5.1 s of cycle
#: in all for 1.7 CPU-s (trochoidal's VPOp runs); with paths from 4 s on, the same cycle
#: and stellabee1 +15 CPU-s (measured beside a CI run): its many shorter paths' probes
OPT_PROBE_S = 2.0
OPT_PROBE_MIN_S = 20.0
OPT_PROBE_AHEAD = 0.01
#: decide the probe as soon as the profile's plan is OPT_PROBE_MIN_S long and past the
#: probe's arc length (``_profile_unless_vpop_ahead``), and when VPOp is ahead keep its
#: plan without planning the profile's rest. Over the axis_mm.ini sweep VPOp was ahead
#: on two paths (trochoidal's, at fast and normal) and its plan won both at the end
#: (92,368 and 92,385 samples against 93,881 and 93,893 at fast); the profile's rest of
#: them cost ~1 of trochoidal's 7 planning CPU-s
OPT_PROBE_EARLY = True
#: a profile-routed path lasting at least this long (at its static limits, s) is profiled and
#: sampled by a thread of its own ahead of its refinement (``prefetch.Prefetch``: the two
#: stages on two cores; the samples do not depend on it): a long path is otherwise one
#: core's work however many the timeline has (zigzag_0.002_0.001, one 50 s path). Shorter
#: paths keep one thread: the timeline's workers already keep the cores busy on a program
#: of many (stellabee1 whole: 5:02 wall and 529 user-s with no thread, 5:39 and 582 with
#: 1 s here, 5:20 and 551 with 10 s)
OPT_AHEAD_S = 10.0
#: ... and that thread runs at most this many sampled blocks ahead
OPT_AHEAD_BLOCKS = 8
#: without refinement (effort fast) a profile-routed path's LP windows are solved by a
#: thread ahead of its sampling from this long on (at its static limits), s: the sampling
#: is lighter than a refinement, and a path of a few seconds was one core's work
#: (arceye-circle-slowdown, one 9.6 s path, the corpus's slowest at fast after the
#: zigzag: 132 -> 149x and 127 -> 144x real time in two pairs of sweeps). The axis_mm.ini
#: sweep at fast, 3 s against 10 s: 66.1 against 68.3 s of planning, then 70.0 against
#: 68.2 s (124.3 / 129.7, then 131.2 / 129.7 CPU-s): the same within this machine's noise
OPT_FEED_AHEAD_S = 3.0
#: ... at most this many pieces ahead of the sampling (a piece is FEED_COMMIT_S of motion), and
#: a whole path's VPOp probe (OPT_PROBE_*) runs meanwhile. zigzag_0.002_0.001 (axis_mm.ini,
#: one 114 s path), the same process alternating: 1.149 -> 1.064 s of planning (median
#: of 10) with the thread, 1.281 -> 1.080 s with the probe as well (the solver's thread
#: is then the critical path: its LPs are 55 % of it). trochoidal, whose paths the
#: timeline's two workers already share: 3.55 -> 3.63 s and +0.6 CPU-s (two of its
#: probes made early were not needed: VPOp was compared on those paths anyway)
OPT_AHEAD_PIECES = 2
#: samples per chunk of ``iter_path_plan_optimal`` (the plan does not depend on it)
OPT_CHUNK = 4096
#: a profile piece whose time law spends more than OPT_CRAWL times the estimated time on
#: node intervals (the profile nearly stops where nothing asks for it) is refused, and VPOp
#: finishes the path from there, unless those intervals take at most OPT_CRAWL_SHARE of
#: the rest of the path's duration (at its static limits) beyond the estimate: less than
#: VPOp's plan of the rest would lose (its cycle is 5.3 % longer over the corpus sweep at
#: --effort fast, 25 % on zigzag_0.002_0.001). There, on axis_mm.ini, windows solved again
#: from the previous one's terminal rest dip to ~0.01 mm/s at it for 0.02-0.25 s; refusing
#: them handed 96 % of the 150 s path to VPOp (153.3 s; kept: 120.4 s). After the sharp
#: corner of test_a_profile_that_would_crawl_after_a_sharp_corner_plans a crawl of 0.22 s
#: on a path of 0.44 s at its static limits is refused
OPT_CRAWL = 50.0
OPT_CRAWL_SHARE = 0.02


def _options(settings) -> OptimalOptions:
    """The planner's knobs (``PlanSettings.optimal``; ``None``: the defaults)."""
    return OptimalOptions() if settings is None else settings.optimal


def _or(value, default):
    """``value`` unless it is ``None`` (a knob left at its default)."""
    return default if value is None else value


def _refine_passes(opts: OptimalOptions, dt: float, route: str) -> int:
    """Passes of window refinement for a path on ``route`` at ``opts.effort``: every
    window at coarse periods or at the max effort; at fine ones only the profile's dips
    and ends, once (VPOp's plans there are within a few periods per path of the discrete
    optimum, and windows on every short path would cost more than planning). Fast: none
    at fine periods, one pass at coarse ones (where it is cheap and carries the most:
    paper 001's trident at 6 ms, 324 periods unrefined, 296 after one pass as after two);
    ``opts.refine_passes`` when set."""
    if opts.refine_passes is not None:
        return int(opts.refine_passes)
    if opts.effort == "fast":
        return 0 if dt < OPT_FULL_REFINE_DT else 1
    if opts.effort == "max" or dt >= OPT_FULL_REFINE_DT:
        return OPT_REFINE_PASSES
    return 1 if route == "profile" else 0


def _targeted(opts: OptimalOptions, dt: float) -> bool:
    """Does the refinement visit only the dips and ends, under the pause rule (fine
    periods), rather than every window?"""
    return dt < OPT_FULL_REFINE_DT and opts.effort != "max"


class _RouteInputs:
    """What ``_route`` reads of a path: its joint table, feed caps and rough durations."""

    def __init__(self, path, joint_map, machine):
        from .vpop import JointTable

        self.machine = machine
        self.table = table = JointTable(path, joint_map)
        self.L = table.length
        fb = np.ascontiguousarray(path.s_breaks, dtype=float).copy()
        fb[-1] = self.L
        self.FB = fb
        self.FV = np.ascontiguousarray(
            np.where(
                np.isfinite(path.feed_mm_s) & (path.feed_mm_s > 0), path.feed_mm_s * (1.0 - VPOP_LIMIT_SHRINK), 1e300
            )
        )
        dq = np.abs(table.qend - table.qstart)
        ramp = float(np.max(machine.vmax / machine.amax + machine.amax / machine.jmax))
        self.ramp_s = 2.0 * ramp
        self.rough_s = float(np.max(dq / machine.vmax)) + self.L / float(np.min(self.FV)) + self.ramp_s
        self.stats: dict = {}
        #: the path's duration at its static speed limits (feed, axis speeds, curvature,
        #: jerk; ``_route``), s: unlike ``rough_s``, it sees a curvature-limited path's length
        self.static_s = 0.0
        #: the path's route once ``_route`` has measured it ("profile" or "vpop")
        self.route: str | None = None

    @property
    def duration_s(self) -> float:
        """The longer of the rough and the static duration, s (``rough_s`` alone is the
        feed's: zigzag_0.002_0.001's 4-inch zigzag, ~1 s at F9999, lasts 34-150 s)."""
        return max(self.rough_s, self.static_s)


class _Routed(threading.local):
    """The route inputs ``batched_optimal`` built for the paths it leaves to the stream,
    kept for their ``_Path`` in the same thread (the timeline plans a job's batch and then
    its streamed paths in one worker): each path's joint table and route are then made
    once (on stellabee1's first 20k lines 1123 -> 710 tables; building them took 7.5 of
    stellabee1's 142 planning CPU-s at --effort fast)."""

    def __init__(self):
        self.held: dict = {}

    def keep(self, held: dict) -> None:
        """Hold ``held`` ({id(path): (path, its _RouteInputs)}), dropping the last job's."""
        self.held = held

    def take(self, path, joint_map):
        """The ``_RouteInputs`` kept for ``path`` in program space, or None."""
        got = self.held.pop(id(path), None)
        if got is None or got[0] is not path or joint_map is not None:
            return None
        return got[1]


_ROUTED = _Routed()


_NOT_PROBED = object()


class _Path(_RouteInputs):
    """What every stage needs about one path (``inputs``: its ``_RouteInputs`` already
    made, whose table and measures it takes over)."""

    def __init__(self, path, joint_map, machine, dt, settings, inputs: _RouteInputs | None = None):
        from .vpop.step import Feed, Limits, Table

        if inputs is None:
            super().__init__(path, joint_map, machine)
        else:
            self.__dict__.update(inputs.__dict__)
        table = self.table
        self.path = path
        self.joint_map = joint_map
        self.dt = dt
        self.settings = settings
        self.vl, self.al, self.jl = step_limits(machine, dt, position_scale(table.C))
        self.n = path.n_axes
        # the exact sampler's inputs (``_track_kernels.track``)
        self.joints = Table(table.S, np.ascontiguousarray(table.C.transpose(0, 2, 1)), table.qend)
        self.limits = Limits(self.vl, self.al, self.jl)
        self.tol = max(4.0 * np.spacing(max(self.L, 1.0)), 1e-7 * float(np.min(self.jl)))
        self.feed_caps = Feed(float(dt), float(self.L), self.FB, self.FV)
        self.stats = {
            "lp_iterations": 0,
            "knots": 0,
            "clamped": 0,
            "retries": 0,
            "handover": -1,
            "refined_periods": 0,
            "table_pieces": int(table.C.shape[0]),
        }
        if inputs is not None:
            self.stats.update(inputs.stats)  # the route's measures, as ``_route`` left them
        self._vrun = None
        self._prep = None
        #: ``_probe_progress``'s outcome, once made
        self.probe = _NOT_PROBED
        self._refine = None
        #: the whole path is held before any sample leaves (``_better_of``)
        self.whole = False

    def vrun(self):
        from .vpop import VpopRun

        if self._vrun is None:
            self._vrun = VpopRun(self.table, self.path, self.machine, self.dt, self.settings, self.joint_map)
        return self._vrun

    def refine_problem(self):
        """The refinement's problem of this path (``refine.refine_problem``), built once
        for every pass and knot spacing."""
        from .refine import refine_problem

        if self._refine is None:
            self._refine = refine_problem(self.table, self.path, self.joints, self.limits, self.dt)
        return self._refine

    def prepared(self):
        """VPOp's preparation of this path on the same joint table."""
        from .vpop import _Prepared

        if self._prep is None:
            self._prep = _Prepared(self.path, self.joint_map, self.machine, self.dt, self.settings, table=self.table)
        return self._prep


class _Nodes:
    """The time-law nodes of the committed profile, appended piece by piece."""

    def __init__(self):
        self.parts = []  # [knots, coef, s0, s1, timelaw.TimeLaw]
        self.s = np.zeros(0)
        self.t = np.zeros(0)
        self.v = np.zeros(0)
        self.a = np.zeros(0)

    def append(self, knots, coef, s0, s1, estimate=None, crawl_s: float = 0.0) -> bool:
        """Append a profile piece's nodes; False (nothing appended) if its time law is
        not finite or, given the profile's speed estimate, crawls (node intervals taking
        more than OPT_CRAWL times the estimate's time, more than ``crawl_s`` beyond it in
        all)."""
        from .timelaw import time_law

        law = time_law(knots, coef, s0, s1)
        return law is not None and self._add(knots, coef, s0, s1, law, estimate, crawl_s)

    def _add(self, knots, coef, s0, s1, law, estimate=None, crawl_s: float = 0.0) -> bool:
        """``append`` with the piece's time law known."""
        t0 = float(self.t[-1]) if self.t.size else 0.0
        ns, nt, nv, na = law.nodes(t0)
        if not (np.all(np.isfinite(nt)) and np.all(np.isfinite(nv)) and np.all(np.isfinite(na))):
            return False
        if estimate is not None and ns.shape[0] >= 2:
            ve = np.sqrt(np.maximum(estimate(ns), 0.0))
            with np.errstate(divide="ignore"):
                t_est = np.diff(ns) / np.maximum(ve[:-1], ve[1:])
            dt_law = np.diff(nt)
            crawl = dt_law > OPT_CRAWL * t_est
            if crawl.any() and np.sum(dt_law[crawl] - t_est[crawl]) > crawl_s:
                return False
        self.parts.append([knots, coef.copy(), s0, s1, law])
        if self.s.size:
            ns, nt, nv, na = ns[1:], nt[1:], nv[1:], na[1:]
        self.s = np.concatenate((self.s, ns))
        self.t = np.concatenate((self.t, nt))
        self.v = np.concatenate((self.v, nv))
        self.a = np.concatenate((self.a, na))
        return True

    def drop_before(self, s_keep: float):
        """Forget parts (and nodes) that end before s_keep."""
        while len(self.parts) > 1 and self.parts[0][3] < s_keep:
            s1 = self.parts[0][3]
            self.parts.pop(0)
            i = int(np.searchsorted(self.s, s1, side="left"))
            self.s, self.t, self.v, self.a = self.s[i:], self.t[i:], self.v[i:], self.a[i:]

    def dip(self, s_bad: float, depth: float, reach: float, s_floor: float) -> bool:
        """Lower w by a smooth dip of the given depth on [s_bad - reach, s_bad + reach/2]
        (not before s_floor) and recompute the nodes from there. False if impossible."""
        from .timelaw import time_law

        lo = max(s_bad - reach, s_floor)
        hi = min(s_bad + 0.5 * reach, self.parts[-1][3] if self.parts else s_bad)
        if not lo < s_bad < hi:
            return False
        parts = []
        for knots, coef, s0, s1, law in self.parts:
            nc = coef.shape[0]
            g = (knots[1 : nc + 1] + knots[2 : nc + 2] + knots[3 : nc + 3]) / 3.0
            u = np.where(g < s_bad, (g - s_bad) / (s_bad - lo), (g - s_bad) / (hi - s_bad))
            phi = np.where(np.abs(u) < 1.0, 0.5 * (1.0 + np.cos(np.pi * u)), 0.0)
            hit = np.flatnonzero(phi > 0)
            if hit.size:
                parts.append((knots, coef * (1.0 - depth * phi), s0, s1, law, (int(hit[0]), int(hit[-1]))))
            else:
                parts.append((knots, coef, s0, s1, law, None))
        if all(p[5] is None for p in parts):
            return False
        # the nodes again from the first part (their times change from the dip on); a
        # part's time law is computed again only where its coefficients changed
        self.parts = []
        self.s = self.t = self.v = self.a = np.zeros(0)
        for knots, coef, s0, s1, law, changed in parts:
            if changed is not None:
                law = time_law(knots, coef, s0, s1, old=law, changed=changed)
            if law is None or not self._add(knots, coef, s0, s1, law):
                return False
        return True


def _sampled(ctx, knot_time_s: float | None = None, ahead: bool = False):
    """Stage 2: yields (s, q) blocks of final samples (see module docstring); the profile's
    knots ``knot_time_s`` of motion apart (default ``feedprofile.FEED_KNOT_TIME_S``).
    ``ahead``: the profile's windows are solved by a thread of their own, ahead of the
    sampling, and a whole path's VPOp probe (``_probe_progress``) is made meanwhile (the
    samples do not depend on it)."""
    from .feedprofile import FEED_KNOT_TIME_S, FeedProfileBuilder

    builder = FeedProfileBuilder(
        ctx.table, ctx.path, ctx.machine, ctx.dt, whole=ctx.whole, knot_time_s=knot_time_s or FEED_KNOT_TIME_S
    )
    if not ahead:
        yield from _sampled_from(ctx, builder, builder.windows())
        return
    pieces = Prefetch(builder.windows(), ahead=OPT_AHEAD_PIECES, name="cnc-interp-feed")
    try:
        if ctx.whole and ctx.duration_s >= OPT_PROBE_MIN_S:
            # a plan this long at least is probed at its end (``_better_of``): VPOp's
            # first samples while the thread solves the first windows, not after
            _probe_progress(ctx)
        yield from _sampled_from(ctx, builder, iter(pieces))
    finally:
        pieces.close()  # the sampling may stop before the last piece (VPOp finishes)


def _sampled_from(ctx, builder, pieces):
    """``_sampled`` on the profile's ``FeedPiece``s from the iterator ``pieces``."""
    from . import _track_kernels as TK
    from .feedprofile import ProfileError

    dt, n, L = ctx.dt, ctx.n, ctx.L
    nodes = _Nodes()
    final = False
    hold = int(OPT_HOLD_S / dt) + OPT_HANDOVER_BACK[-1] + 8
    cap = 4 * hold + 64
    sh = np.zeros(cap)
    qh = np.zeros((cap, n))
    qh[0] = ctx.table.qstart
    k = 1  # next sample, index into the buffer
    base = 0  # global index of buffer[0]
    emitted = 0  # global index of the first sample not yet emitted
    stats = np.zeros(2, dtype=np.int64)
    retries_here = 0
    dip_hi = -1.0  # the end of the last dip: a stuck place beyond it is a new one
    # dips per path at most (each re-samples a stretch): a path stuck that often goes to VPOp
    # (per second of its duration at the static limits too: zigzag_0.002_0.001 on issue
    # 13's LinuxCNC machine, 34 s of motion but ~1 s at its feed, ran out after 40 dips and
    # VPOp planned its last 42 %: 35.405 s against 34.217 s with 85 dips)
    dip_budget = OPT_RETRY_PLACES * len(OPT_RETRY_DEPTHS) + int(ctx.duration_s / OPT_RETRY_PER_S)
    final_handover = False
    # a sane bound on the samples: ten times the path's duration at its feed or static
    # limits, plus ramps (the profile is never that slow unless something went wrong)
    max_samples = int(10.0 * ctx.duration_s / dt) + 100_000
    while True:
        if base + k > max_samples and not final_handover:
            # the reference crawls (a bug, or a profile the crawl check let through):
            # VPOp finishes the path
            ctx.stats["sample_budget"] = True
            status, final, retries_here, final_handover = TK.STUCK, True, len(OPT_RETRY_DEPTHS), True
        else:
            status, k = (
                (TK.NEED_REF, k)
                if nodes.s.size < 2
                else TK.track(
                    TK.Reference(nodes.s, nodes.t, nodes.v, nodes.a, nodes.s.shape[0]),
                    final,
                    ctx.joints,
                    ctx.limits,
                    ctx.feed_caps,
                    sh,
                    qh,
                    k,
                    ctx.tol,
                    stats,
                )
            )
        if status == TK.NEED_REF:
            try:
                piece = next(pieces)
            except ProfileError as exc:
                if nodes.s.size == 0:
                    raise _Fallback("profile") from exc
                piece = None
            if piece is None:  # VPOp finishes from here
                status = TK.STUCK
                final = True
                retries_here, final_handover = len(OPT_RETRY_DEPTHS), True
            elif not _append_piece(ctx, nodes, piece, builder):
                if nodes.s.size == 0:
                    raise _Fallback("reference")
                status = TK.STUCK  # the profile stops inside a piece: VPOp finishes
                final = True
                retries_here, final_handover = len(OPT_RETRY_DEPTHS), True
            else:
                final = piece.s1 >= L
                continue
        if status == TK.OK:
            ctx.stats["clamped"] = int(stats[0])
            yield _final_chunk(sh, qh, k, L, emitted - base, ctx.table.qend)
            return
        if status == TK.NEED_SPACE:
            # emit what no retry can change, then compact the buffer
            upto = base + k - hold
            if upto > emitted:
                yield sh[emitted - base : upto - base].copy(), qh[emitted - base : upto - base].copy()
                emitted = upto
            keep_from = emitted - 3 - base
            if keep_from > 0:
                sh[: k - keep_from] = sh[keep_from:k]
                qh[: k - keep_from] = qh[keep_from:k]
                base += keep_from
                k -= keep_from
                nodes.drop_before(float(sh[0]))
            if k + 16 >= sh.shape[0]:
                sh = np.concatenate((sh, np.zeros(sh.shape[0])))
                qh = np.concatenate((qh, np.zeros((qh.shape[0], n))))
            continue
        # STUCK at buffer index k
        t_here, _ = TK.ref_t_of_s(nodes.s, nodes.t, nodes.v, nodes.a, nodes.s.shape[0], sh[k - 1], 0)
        near_end = final and nodes.t[-1] - t_here <= OPT_TAIL_S
        s_bad = float(sh[k - 1])
        if s_bad > dip_hi and not final_handover and ctx.stats["retries"] < dip_budget:
            # stuck at a new place, past the last dip: it gets dips of its own (the
            # budget was per path: after four places anywhere VPOp planned the rest)
            retries_here = 0
        if not near_end and retries_here < len(OPT_RETRY_DEPTHS):
            i = min(int(np.searchsorted(nodes.s, s_bad)), nodes.v.shape[0] - 1)
            v_here = max(float(np.max(nodes.v[max(i - 8, 0) : i + 8])), 1e-9)
            reach = max(OPT_RETRY_SPAN_S * v_here, 20.0 * dt * v_here, 1e-6)
            s_floor = float(sh[emitted - base]) if emitted > base else float(sh[0])
            if nodes.dip(s_bad, OPT_RETRY_DEPTHS[retries_here], reach, s_floor):
                retries_here += 1
                dip_hi = max(dip_hi, min(s_bad + 0.5 * reach, L))
                ctx.stats["retries"] += 1
                # restart before the dip (every sample there is unchanged)
                lo = max(s_bad - reach, s_floor)
                kr = int(np.searchsorted(sh[:k], lo, side="left"))
                k = max(kr, emitted - base + 1, 1)
                continue
        # VPOp finishes the path from a few samples back (within what is held)
        done = False
        for back in OPT_HANDOVER_BACK:
            k0 = max(k - back, emitted - base + 1, 1)
            st, kk, sh2, qh2 = ctx.vrun().run(sh.copy(), qh.copy(), k0, k0 - 1)
            if st == ctx.vrun().core.OK:
                sh, qh, k, done = sh2, qh2, kk, True
                ctx.stats["handover"] = int(base + k0)
                break
            if k0 <= emitted - base + 1:
                break
        if not done:
            raise _Fallback("stuck")
        status = TK.OK
        ctx.stats["clamped"] = int(stats[0])
        yield _final_chunk(sh, qh, k, L, emitted - base, ctx.table.qend)
        return


def _append_piece(ctx, nodes, piece, builder) -> bool:
    ctx.stats["lp_iterations"] += piece.lp_iters
    if piece.restarts:
        ctx.stats["lp_restarts"] = piece.restarts

    def estimate(x):  # the builder's estimate as it was when the piece was committed
        return builder.estimate(x, piece.envelope)

    rest_s = ctx.duration_s * max(ctx.L - piece.s0, 0.0) / ctx.L
    if nodes.append(piece.knots, piece.coef, piece.s0, piece.s1, estimate, OPT_CRAWL_SHARE * rest_s):
        return True
    ctx.stats["crawl"] = ctx.stats.get("crawl", 0) + 1
    return False


class _Fallback(Exception):
    """This path cannot be planned by the profile (VPOp plans it)."""


def _refined(ctx, blocks, targeted: bool = False):
    """Stage 3: one pass of window refinement over a stream of (s, q) blocks: windows of
    ``REFINE_WINDOW`` samples every ``REFINE_STRIDE`` samples; a window changes only
    samples from its start on, so everything before the next start is final.
    ``targeted``: only windows at the ends of the path and around dips of the speed
    (where a sampled plan gains most over the continuous profile), for fine periods
    where a pass over everything costs too much."""
    from . import _refine_kernels as RK
    from .refine import REFINE_STRIDE, REFINE_WINDOW, Refiner

    ref = Refiner(ctx.refine_problem())
    W = REFINE_WINDOW
    ahead = W + 4 + (W if targeted else 0)
    sh = np.zeros(0)
    qh = np.zeros((0, ctx.n))
    base = 0  # global index of sh[0]
    a = 1  # next window start, global index
    emitted = 0
    gained = 0
    blk = (0, 0)  # solves and periods gained when the current block began
    pause = 0  # strides left before the windows are tried again
    done = False
    it = iter(blocks)
    while True:
        while not done and base + sh.shape[0] < a + ahead:
            try:
                bs, bq = next(it)
            except StopIteration:
                done = True
                break
            sh = np.concatenate((sh, bs))
            qh = np.concatenate((qh, bq))
        la = a - base
        N = sh.shape[0]
        if la >= N - 1:
            break
        b = min(la + W, N - 1)
        # targeted: the windows are judged by blocks of OPT_REFINE_PROBE solves; a block
        # that gained less than OPT_REFINE_RATE periods per solve (a window that loses k
        # periods takes k + 1 solves) pauses them for OPT_REFINE_PAUSE strides
        if targeted:
            if pause > 0:
                pause -= 1
                if pause == 0:
                    blk = (ref.solves, gained)
            elif ref.solves - blk[0] >= OPT_REFINE_PROBE:
                if gained - blk[1] < OPT_REFINE_RATE * (ref.solves - blk[0]):
                    pause = OPT_REFINE_PAUSE
                blk = (ref.solves, gained)
        paying = pause == 0
        # targeted: only windows at the path's ends or around a dip of the speed
        if (
            paying
            and b - la >= 3
            and (not targeted or RK.dip_or_end(sh, la, b, W, done, OPT_DIP))
            and ref.loose(sh, qh, la, b)
        ):
            sh, qh, d = ref.window(sh, qh, la, b, max(1, (b - la) // 2))
            gained += d
            ctx.stats["refined_periods"] += d
        a += REFINE_STRIDE
        upto = min(a, base + sh.shape[0])
        if upto > emitted:
            yield sh[emitted - base : upto - base].copy(), qh[emitted - base : upto - base].copy()
            emitted = upto
            cut = emitted - 3 - base  # keep three samples before the next window
            if cut > 0:
                sh, qh, base = sh[cut:], qh[cut:], base + cut
    if emitted < base + sh.shape[0]:
        yield sh[emitted - base :].copy(), qh[emitted - base :].copy()
    ctx.stats["refine_solves"] = ctx.stats.get("refine_solves", 0) + ref.solves
    ctx.stats["refine_newton"] = ctx.stats.get("refine_newton", 0) + int(ref.counts[0])
    ctx.stats["refine_evals"] = ctx.stats.get("refine_evals", 0) + int(ref.counts[1])


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
    chunks of ``settings.optimal.chunk_samples`` (default ``OPT_CHUNK``) samples as soon
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


def batched_optimal(paths, joint_map, machine, dt_s: float, settings=None) -> list:
    """Which of ``paths`` this planner gives to VPOp whole and leaves unrefined, where
    the joints are the program axes: their plans are ``vpop.plan_many_vpop``'s, one
    compiled call for a job's short paths (the timeline's batch) instead of a VPOp run
    per path on this planner's own table (5-9x the planning time of flowsnake and
    zigzag_0.002_0.0005, whose every path goes to VPOp). Returns, per path, the stats it
    adds to the batch's ({"route": "vpop"}), or ``None``: a path this planner streams."""
    out: list = [None] * len(paths)
    opts = _options(settings)
    dt = float(dt_s)
    held: dict = {}
    _ROUTED.keep(held)
    if joint_map is not None or opts.route == "profile" or _refine_passes(opts, dt, "vpop"):
        return out
    for i, path in enumerate(paths):
        if path.rapid or not (np.isfinite(path.length) and np.all(np.isfinite(path.coef))):
            continue
        if path.length <= VPOP_MIN_LENGTH:
            continue
        try:
            inputs = _RouteInputs(path, None, machine)
            route = opts.route or _route(inputs)
        except PlanError:
            continue  # raised again in order when the path is streamed
        if route == "vpop":
            out[i] = {"route": "vpop"}
        else:
            held[id(path)] = (path, inputs)
    return out


iter_path_plan_optimal.batched = batched_optimal


def _iter(path, joint_map, machine, dt_s, settings, stats, window):
    """(s, q) chunks of the plan (see ``iter_path_plan_optimal``); fills ``stats``."""
    from .vpop import _positions

    if path.rapid:
        joint_map = None
    dt = float(dt_s)
    if not (np.isfinite(path.length) and np.all(np.isfinite(path.coef))):
        raise PlanError(f"bug: the fitted path ending at line {int(path.line[-1])} is not finite")
    opts = _options(settings)
    chunk = max(1, int(_or(opts.chunk_samples, OPT_CHUNK)))
    if path.length <= VPOP_MIN_LENGTH:
        stats["samples_total"] = 1
        yield np.zeros(1), _positions(path, path.breaks[:1], joint_map)
        return
    ctx = _Path(path, joint_map, machine, dt, settings, _ROUTED.take(path, joint_map))
    ctx.window = window
    targeted = _targeted(opts, dt)
    route = opts.route or _route(ctx)
    ctx.stats["route"] = route
    passes = _refine_passes(opts, dt, route)
    limit_s = float(_or(opts.compare_s, OPT_COMPARE_SAMPLES * dt))
    ctx.whole = route == "profile" and ctx.rough_s <= limit_s
    long_path = route == "profile" and ctx.duration_s >= (OPT_AHEAD_S if passes else OPT_FEED_AHEAD_S)
    # a long path's second thread: the profile's windows ahead of the sampling without
    # refinement, else the profile and its sampling ahead of the refinement
    stage = _sampled(ctx, ahead=long_path and not passes) if route == "profile" else _vpop_stage(ctx, window)
    if long_path and passes:
        # the refinement of one stretch while the next is profiled
        stage = Prefetch(stage, ahead=OPT_AHEAD_BLOCKS, name="cnc-interp-profile")
    for _ in range(passes):
        stage = _refined(ctx, stage, targeted)
    if ctx.whole:
        stage = _better_of(ctx, stage, passes, targeted)
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
            from .vpop.planner import rescue

            what = f"the optimal planner gave up on the path ending at line {int(path.line[-1])} ({why})"
            plan = rescue(ctx.prepared(), tail_s, tail_q, ctx.joint_map, machine, settings, what)
            ctx.stats.update({k: plan.stats[k] for k in ("fallback", "safe", "rescued_at")})
            produced += plan.s.shape[0]
            yield plan.s, plan.q
            stats.update(ctx.stats)
            stats["samples_total"] = produced
            return
        ctx.stats["fallback"] = str(why)
        passes = _refine_passes(opts, dt, "vpop")
        stage = _vpop_stage(ctx, window)
        for _ in range(passes):
            stage = _refined(ctx, stage, targeted)
        for s, q in _rechunk(stage, chunk):
            produced += s.shape[0]
            yield s, q
    stats.update(ctx.stats)
    stats["samples_total"] = produced


def _tail(tail_s, tail_q, s, q):
    """The last three samples of those out before and ``s``, ``q``."""
    if tail_s is not None and s.shape[0] < 3:
        s, q = np.concatenate((tail_s, s)), np.concatenate((tail_q, q))
    return s[-3:].copy(), q[-3:].copy()


def _samples(blocks) -> int:
    return sum(b[0].shape[0] for b in blocks)


def _better_of(ctx, stage, passes, targeted):
    """The shortest of the profile's plan, the profile's with knots OPT_ALT_KNOT_SHARE as
    far apart, and VPOp's (all whole: bounded by ``OPT_COMPARE_SAMPLES``); ``passes`` of
    refinement for the profile's plans, and for VPOp's at coarse periods."""
    from .feedprofile import FEED_KNOT_TIME_S

    try:
        blocks, vpop_ahead = _profile_unless_vpop_ahead(ctx, stage)
        failed = None
    except _Fallback as why:
        blocks, failed, vpop_ahead = None, why, False
    if vpop_ahead:
        # VPOp's plan is kept without the profile's rest (OPT_PROBE_EARLY)
        ctx.stats["kept"] = "vpop"
        yield from _vpop_plan(ctx, passes, targeted)
        return
    # where the profile's tracking gave up early (VPOp took over before the last stop, or
    # nothing planned), its outcome moves by up to ±15 % with the knot spacing: a second
    # spacing is the hedge (a profile that reached the end is kept: the second plan would
    # double its cost). Dips of the reference alone are no trouble: the second spacing
    # gained 0.2 % on such paths (stellabee1's, stellabee-kink-test) at 9 % of the CPU,
    # against 2.7 % on paths handed over early (LHchips4, 3D_Chips, blur_torus)
    planned_s = ctx.dt * _samples(blocks) if blocks is not None else 0.0
    # (VPOp finishing the last stop is no trouble: arc_maxvel_xy's helix handed over one
    # sample before its end and was planned twice)
    troubled = blocks is None or _handed_over_early(ctx, _samples(blocks))
    if troubled and planned_s <= OPT_ALT_KNOT_MAX_S:
        kept = dict(ctx.stats)  # the second run's stats stand only if its plan is kept
        try:
            alt = _sampled(ctx, FEED_KNOT_TIME_S * OPT_ALT_KNOT_SHARE)
            for _ in range(passes):
                alt = _refined(ctx, alt, targeted)
            alt_blocks: list | None = list(alt)
        except _Fallback:
            alt_blocks = None
        if alt_blocks is not None and (blocks is None or _samples(alt_blocks) < _samples(blocks)):
            blocks = alt_blocks
            ctx.stats["knot_time_s"] = FEED_KNOT_TIME_S * OPT_ALT_KNOT_SHARE
        else:
            ctx.stats.clear()
            ctx.stats.update(kept)
    if blocks is None:
        assert failed is not None
        raise failed  # neither spacing planned the path: VPOp does (the caller's fallback)
    s = np.concatenate([b[0] for b in blocks])
    q = np.concatenate([b[1] for b in blocks])
    if "fallback" not in ctx.stats and not _vpop_may_win(ctx, s.shape[0]) and not _vpop_ahead(ctx, s):
        # the profile ran to the end (VPOp at most finished its last stop), or far enough
        # before VPOp took over: it is kept without running VPOp (over the corpus VPOp
        # won on such paths by 351 periods in all against the profile's 22k; the runs
        # cost as much as 4.6 s of planning). Also where the reference had to be lowered
        # by a few dips (OPT_COMPARE_DIPS): on the sweep (axis_mm.ini) VPOp won there by
        # 51 periods in all (LHchips4) for ~7 % of stellabee1's CPU
        ctx.stats["kept"] = "profile"
        yield s, q
        return
    alt = list(_vpop_plan(ctx, passes, targeted))
    sv = np.concatenate([b[0] for b in alt])
    if sv.shape[0] < s.shape[0]:
        ctx.stats["kept"] = "vpop"
        yield sv, np.concatenate([b[1] for b in alt])
    else:
        ctx.stats["kept"] = "profile"
        yield s, q


def _vpop_plan(ctx, passes, targeted):
    """VPOp's whole plan of the path to compare with the profile's: (s, q) blocks, refined
    by ``passes`` where the refinement is not targeted."""
    alt = _vpop_stage(ctx, None)
    for _ in range(passes if not targeted else 0):
        alt = _refined(ctx, alt, targeted)
    return alt


def _profile_unless_vpop_ahead(ctx, stage):
    """The profile's (s, q) blocks from ``stage`` and False; or, with OPT_PROBE_EARLY,
    those up to where VPOp's probe is decided ahead and True (``stage`` is closed, the
    rest not planned). The test is ``_vpop_ahead``'s, made on the first
    OPT_PROBE_MIN_S of the plan once they reach past the probe: the plan is then at least
    that long and its first samples are those the test reads at its end."""
    blocks: list = []
    need = int(np.ceil(OPT_PROBE_MIN_S / ctx.dt))
    count = 0
    undecided = OPT_PROBE_EARLY
    for block in stage:
        blocks.append(block)
        count += block[0].shape[0]
        if undecided and count >= need:
            progress = _probe_progress(ctx)
            if progress is None:
                undecided = False
            elif float(block[0][-1]) >= progress[1]:
                undecided = False
                if _vpop_ahead(ctx, np.concatenate([b[0] for b in blocks])):
                    stage.close()
                    return blocks, True
    return blocks, False


def _vpop_ahead(ctx, s) -> bool:
    """Does VPOp's plan reach the arc length of its first OPT_PROBE_S OPT_PROBE_AHEAD
    sooner than the profile's plan of samples at arc lengths s (N,)? (False for a plan
    shorter than OPT_PROBE_MIN_S, or where VPOp fails.)"""
    if s.shape[0] * ctx.dt < OPT_PROBE_MIN_S:
        return False
    progress = _probe_progress(ctx)
    if progress is None:
        return False
    got, s_at = progress
    ahead = got < (1.0 - OPT_PROBE_AHEAD) * (int(np.searchsorted(s, s_at)) + 1)
    ctx.stats["probe"] = "vpop ahead" if ahead else "profile"
    return ahead


def _probe_progress(ctx):
    """VPOp's first samples of the path: (how many, the arc length of the last), at least
    OPT_PROBE_S worth; None where VPOp fails. Made once per path (``ctx.probe``)."""
    from .vpop import VpopFailed, iter_prepared

    if ctx.probe is not _NOT_PROBED:
        return ctx.probe
    n_probe = int(OPT_PROBE_S / ctx.dt)
    got, s_at = 0, 0.0
    try:
        # checkpoints (hence samples handed out) every n_probe: only counted here
        stream = iter_prepared(
            ctx.prepared(), ctx.joint_map, ctx.machine, ctx.settings, n_probe, safe_fallback=False, checkpoint=n_probe
        )
        for c in stream:
            got += c.s.shape[0]
            s_at = float(c.s[-1])
            if got >= n_probe:
                break
        ctx.probe = (got, s_at)
    except VpopFailed:
        ctx.probe = None
    return ctx.probe


def _vpop_may_win(ctx, n_samples: int) -> bool:
    """Is VPOp's own plan worth making for comparison with the profile's plan of
    ``n_samples``: did VPOp take it over early (``_handed_over_early``), after
    OPT_COMPARE_AFTER and before OPT_COMPARE_BEFORE of its samples, or did the profile
    need OPT_COMPARE_DIPS dips?"""
    if int(ctx.stats.get("retries", 0)) >= OPT_COMPARE_DIPS:
        return True
    ho = int(ctx.stats.get("handover", -1))
    return _handed_over_early(ctx, n_samples) and OPT_COMPARE_AFTER * n_samples <= ho < OPT_COMPARE_BEFORE * n_samples


def _handed_over_early(ctx, n_samples: int) -> bool:
    """Did VPOp take over the profile's plan of ``n_samples`` before its last
    OPT_COMPARE_TAIL_S (more than finishing the last stop)?"""
    ho = int(ctx.stats.get("handover", -1))
    return 0 <= ho < n_samples - int(OPT_COMPARE_TAIL_S / ctx.dt)


def _route(ctx) -> str:
    """ "profile" where curvature or jerk limit the speed on a good part of a path that
    lasts long enough to gain from it, else "vpop" (see OPT_ROUTE_*); measured once per
    ``_RouteInputs`` (kept in ``ctx.route``)."""
    if ctx.route is None:
        ctx.route = _measured_route(ctx)
    return ctx.route


def _measured_route(ctx) -> str:
    """``_route``'s measurement (``ctx.static_s`` and the stat "limited_share" with it)."""
    if ctx.rough_s < OPT_ROUTE_TINY_S:
        return "vpop"  # travel at the feed and ramps: far below the threshold anyway
    from . import _feed_kernels as K

    m = ctx.machine
    share, t_static = K.route_measures(
        ctx.table.S,
        np.ascontiguousarray(ctx.table.C),
        ctx.FB,
        ctx.FV,
        np.asarray(m.vmax, dtype=float),
        np.asarray(m.amax, dtype=float),
        np.asarray(m.jmax, dtype=float),
        float(OPT_ROUTE_SPEED),
    )
    # duration at the static limits: a lower bound of the motion's, ramps aside
    ctx.static_s = t_static
    ctx.stats["limited_share"] = round(share, 4)
    long_enough = t_static + ctx.ramp_s >= OPT_ROUTE_MIN_S
    return "profile" if share >= OPT_ROUTE_SHARE and long_enough else "vpop"


def _vpop_stage(ctx, window):
    """VPOp's plan of the path as a stream of (s, q) blocks (its own stream: ``window``
    bounds its buffers, the samples do not depend on it)."""
    from .vpop import VpopFailed, iter_prepared

    handed = False
    try:
        for c in iter_prepared(ctx.prepared(), ctx.joint_map, ctx.machine, ctx.settings, window, safe_fallback=False):
            if c.last and c.stats:
                ctx.stats["exact"] = bool(c.stats.get("exact", False))
            handed = True
            yield c.s, c.q
        return
    except VpopFailed:
        if handed:
            raise
    # VPOp got stuck (a Vectric file's A+Z moves): the profile if this path did not come
    # from it, else the safe S-curve, which cannot fail
    ctx.stats["vpop_failed"] = True
    if ctx.stats.get("route") == "vpop" and "fallback" not in ctx.stats:
        ctx.stats["route"] = "profile"
        try:
            blocks = list(_sampled(ctx))  # whole: it may still give up
        except _Fallback:
            blocks = None
        if blocks is not None:
            yield from blocks
            return
    from .safe import plan_path_safe

    plan = plan_path_safe(ctx.path, ctx.joint_map, ctx.machine, ctx.dt, ctx.settings)
    ctx.stats["safe"] = True
    yield plan.s, plan.q


def plan_path_optimal(path, joint_map, machine, dt_s: float, settings=None) -> PathPlan:
    """Plan one path from rest to rest (see module docstring): the concatenation of
    ``iter_path_plan_optimal``'s chunks."""
    return collect_path_plan(iter_path_plan_optimal(path, joint_map, machine, dt_s, settings))


def _final_chunk(sh, qh, k: int, L: float, first: int, qend):
    """The path's last chunk: buffer rows ``first``..the first sample at the end L (the
    repeats of L after it dropped), its last position exactly the path's end ``qend``."""
    last = k - 1
    while last > 0 and sh[last - 1] == L:
        last -= 1
    out_s = sh[first : last + 1].copy()
    out_q = qh[first : last + 1].copy()
    out_q[-1] = qend
    return out_s, out_q

"""Where a plan's cycle goes: its time by tool, operation, source lines, kind of motion
and binding limit, counted from the stream of sample blocks (``cnc-interp estimate``).

Every sample period (k-1, k], k = 1 .. K-1, is one count in exactly one bucket of each
breakdown, so every breakdown sums to the cycle, (K - 1)·dt, and memory is a few
counters per tool, operation and line range, whatever the cycle. A period goes to what
sample k is (``plan.timeline``'s ``SampleBlock.events``):

* kind: ``rapid`` (a G0 path), ``feed`` (a cutting path), ``dwell`` (G4) or ``rest``
  (held at rest: between motions, at stops and tool changes, at the ends);
* tool: the tool the last M6 loaded (0 before the first);
* operation: the last operation header (``gcode.program.Mark``) before it;
* line range: the source line executing (``SampleBlock.line``) in ranges of equal width;
* limit: ``classify_limits``'s code (table below).

A feed sample is **at programmed feed** when its path speed is within ``AT_FEED_REL`` of
the programmed feed, or of the fastest the axes' velocity limits allow in the direction
it moves, whichever is lower (a feed above the machine's is clamped to it).

Limit codes (``classify_limits``, ``code_names``), for the samples' axis velocity,
acceleration and jerk as backward differences (``plan.verify``'s, the three samples
before a block carried over):

====================  =======================================================
code                  meaning
====================  =======================================================
0 ``rest``            no axis moves from the sample before
1 ``feed``            no limit binds and the sample is at programmed feed
2 ``transition``      no limit binds, not at programmed feed: speeding up or
                      slowing down under the planner's look-ahead, a rapid
                      below its limits
3 + 3·a + m           ``<axis> velocity|acceleration|jerk``: the ratio of axis a's
                      limit m (0 velocity, 1 acceleration, 2 jerk) is the largest
                      of the sample's ratios and reaches ``BINDING_RATIO``
====================  =======================================================

Curvature and path tolerance are not classes of their own: the planners meet them
through the axes' acceleration and jerk (a tight corner binds an axis's acceleration),
which is how they appear here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike


class Limits(Protocol):
    """What the classifier needs of a machine (``Machine`` has it): axis letters and the
    (n,) velocity, acceleration and jerk limits, mm or deg per s, s², s³."""

    axes: str
    vmax: ArrayLike
    amax: ArrayLike
    jmax: ArrayLike


#: a feed sample within this fraction of its programmed feed (or of the axes' velocity
#: limit in its direction) is at programmed feed: above the planners' rounding, below
#: any real slow-down
AT_FEED_REL = 0.01
#: a limit binds at a sample whose |v|/vmax, |a|/amax or |j|/jmax reaches this ratio
BINDING_RATIO = 0.95
#: source-line ranges a breakdown has by default (their width is the program's lines
#: over this, rounded up)
LINE_RANGES = 20

CODE_REST = 0
CODE_FEED = 1
CODE_TRANSITION = 2
#: the first limit code: axis a's limit m (0 velocity, 1 acceleration, 2 jerk) is 3 + 3·a + m
CODE_LIMIT0 = 3
_LIMITS = ("velocity", "acceleration", "jerk")

#: motion kinds (``Breakdown``'s order)
KINDS = ("rest", "dwell", "rapid", "feed")
_K_REST, _K_DWELL, _K_RAPID, _K_FEED = range(4)
#: samples of the held rest before the first block's differences (``plan.verify``'s padding)
_HEAD = 3


def code_names(axes: str) -> tuple[str, ...]:
    """Names of the limit codes for machine ``axes`` (index = code)."""
    return ("rest", "feed", "transition") + tuple(f"{a} {m}" for a in axes for m in _LIMITS)


def limit_ratios(q: np.ndarray, dt_s: float, machine: Limits, head: np.ndarray | None = None) -> np.ndarray:
    """|v|/vmax, |a|/amax, |j|/jmax (K, 3, n) of every axis at samples ``q`` (K, n), mm or
    deg, by backward differences over period ``dt_s`` (s). ``head`` (h, n), h <= 3: the
    samples before ``q[0]``; missing ones are ``q[0]``'s held (the machine at rest before
    the first sample). ``machine``: anything with ``vmax``, ``amax``, ``jmax`` (n,)."""
    q = np.asarray(q, dtype=float)
    k, n = q.shape
    h = np.zeros((0, n)) if head is None else np.asarray(head, dtype=float).reshape(-1, n)[-_HEAD:]
    first = h[0] if h.shape[0] else (q[0] if k else np.zeros(n))
    pad = np.repeat(first[None, :], _HEAD - h.shape[0], axis=0)
    x = np.concatenate([pad, h, q], axis=0)
    out = np.empty((k, 3, n))
    limits = (machine.vmax, machine.amax, machine.jmax)
    d = x
    for m in range(3):
        d = np.diff(d, axis=0)  # d[i] ends at x[i + m + 1]; q[j] is x[j + 3]
        out[:, m, :] = np.abs(d[_HEAD - 1 - m :]) / (np.asarray(limits[m], dtype=float) * dt_s ** (m + 1))
    return out


def codes_of(
    ratios: np.ndarray, moving: np.ndarray, at_feed: np.ndarray | None = None, threshold: float = BINDING_RATIO
) -> np.ndarray:
    """Limit codes (K,) int16 from ``limit_ratios`` (K, 3, n), whether each sample moves
    (K,) bool and whether it is at programmed feed (K,) bool (None: never)."""
    k, _, n = ratios.shape
    flat = ratios.transpose(0, 2, 1).reshape(k, 3 * n)  # column 3·a + m
    best = np.argmax(flat, axis=1) if k else np.zeros(0, dtype=np.int64)
    top = flat[np.arange(k), best]
    codes = np.full(k, CODE_TRANSITION, dtype=np.int16)
    if at_feed is not None:
        codes[at_feed] = CODE_FEED
    bind = top >= threshold
    codes[bind] = (CODE_LIMIT0 + best[bind]).astype(np.int16)
    codes[~moving] = CODE_REST
    return codes


def classify_limits(
    q: np.ndarray,
    dt_s: float,
    machine: Limits,
    head: np.ndarray | None = None,
    at_feed: np.ndarray | None = None,
    threshold: float = BINDING_RATIO,
) -> np.ndarray:
    """The limit code (K,) int16 of every sample ``q`` (K, n) (module docstring's table):
    ``head`` as ``limit_ratios``'s, ``at_feed`` (K,) bool marks samples at programmed
    feed (None: no sample is ``feed``), ``threshold`` the ratio from which a limit binds."""
    q = np.asarray(q, dtype=float)
    ratios = limit_ratios(q, dt_s, machine, head)
    return codes_of(ratios, _moving(q, head), at_feed, threshold)


def _moving(q: np.ndarray, head: np.ndarray | None) -> np.ndarray:
    """(K,) bool: sample k differs from the one before (``head``'s last, else q[0])."""
    if q.shape[0] == 0:
        return np.zeros(0, dtype=bool)
    prev = q[0] if head is None or len(head) == 0 else np.asarray(head, dtype=float)[-1]
    d = np.empty(q.shape, dtype=bool)
    d[0] = q[0] != prev
    d[1:] = q[1:] != q[:-1]
    return np.asarray(d.any(axis=1), dtype=bool)


# -- the result -----------------------------------------------------------------------
@dataclass(frozen=True)
class ToolTime:
    """Time (s) with ``tool`` in the spindle; ``line``: where it was first loaded (0:
    the tool at the start)."""

    tool: int
    time_s: float
    line: int


@dataclass(frozen=True)
class OperationTime:
    """One operation, in program order: ``name`` (its header comment; ``None`` before
    the first header), its header's ``line``, the ``tool`` at its start, its time (s)."""

    index: int
    name: str | None
    line: int
    tool: int
    time_s: float


@dataclass(frozen=True)
class LineRangeTime:
    """Time (s) executing source lines ``first`` .. ``last`` (samples of no line, the
    first rest, count in the first range)."""

    first: int
    last: int
    time_s: float


@dataclass(frozen=True)
class Estimate:
    """A plan's cycle and where it goes (module docstring). Times in s; every breakdown
    (``by_kind``, ``by_tool``, ``by_operation``, ``by_lines``, ``limits``) sums to
    ``cycle_time_s``. ``limits_by_kind`` splits ``limits`` by kind; ``at_feed_s`` is the
    part of ``by_kind["feed"]`` at programmed feed (``at_feed_share`` of it, None
    without feed moves)."""

    part: str
    machine: str
    planner: str
    dt_s: float
    samples: int
    cycle_time_s: float
    path_length_mm: float
    by_kind: dict[str, float]
    by_tool: tuple[ToolTime, ...]
    by_operation: tuple[OperationTime, ...]
    by_lines: tuple[LineRangeTime, ...]
    at_feed_s: float
    limits: dict[str, float]
    limits_by_kind: dict[str, dict[str, float]] = field(default_factory=dict)

    @property
    def at_feed_share(self) -> float | None:
        feed = self.by_kind.get("feed", 0.0)
        return self.at_feed_s / feed if feed > 0 else None

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able values (``estimate --json``, ``batch``'s report)."""
        return {
            "part": self.part,
            "machine": self.machine,
            "planner": self.planner,
            "dt_s": self.dt_s,
            "samples": self.samples,
            "cycle_time_s": self.cycle_time_s,
            "path_length_mm": self.path_length_mm,
            "by_kind": dict(self.by_kind),
            "by_tool": [{"tool": t.tool, "time_s": t.time_s, "line": t.line} for t in self.by_tool],
            "by_operation": [
                {"index": o.index, "name": o.name, "line": o.line, "tool": o.tool, "time_s": o.time_s}
                for o in self.by_operation
            ],
            "by_lines": [{"first": r.first, "last": r.last, "time_s": r.time_s} for r in self.by_lines],
            "at_feed_s": self.at_feed_s,
            "at_feed_share": self.at_feed_share,
            "limits": dict(self.limits),
            "limits_by_kind": {k: dict(v) for k, v in self.limits_by_kind.items()},
        }


# -- the accumulator ---------------------------------------------------------------------
class Breakdown:
    """Counts a plan's sample blocks (``add``, in order, each with its ``events``) into
    the breakdowns of an ``Estimate`` (``result``)."""

    def __init__(self, machine: Limits, dt_s: float, line_count: int, lines_per_range: int | None = None):
        self.machine = machine
        self.dt = float(dt_s)
        self.names = code_names(machine.axes)
        width = lines_per_range or max(1, math.ceil(max(1, int(line_count)) / LINE_RANGES))
        self.width = int(width)
        self.ranges = np.zeros(max(1, math.ceil(max(1, int(line_count)) / self.width)), dtype=np.int64)
        self.by_code = np.zeros((len(KINDS), len(self.names)), dtype=np.int64)
        self.tools: list[int] = [0]  # tool numbers by index
        self.tool_line: list[int] = [0]
        self.tool_counts = np.zeros(1, dtype=np.int64)
        self.ops: list[list[Any]] = [[None, 0, 0]]  # name, line, tool number at its start
        self.op_counts = np.zeros(1, dtype=np.int64)
        self.at_feed = 0
        self.samples = 0
        self.head: np.ndarray | None = None
        self.s_prev: float | None = None
        # the state at the next sample: span (code, path, s offset), tool index, operation
        self.span: tuple[int, Any, float] = (0, None, 0.0)
        self.tool = 0
        self.op = 0

    def _mark(self, mark: Any) -> None:
        if mark.tool is not None:
            t = int(mark.tool)
            if t not in self.tools:
                self.tools.append(t)
                self.tool_line.append(int(mark.line))
                self.tool_counts = np.append(self.tool_counts, 0)
            self.tool = self.tools.index(t)
        if mark.operation is not None:
            self.ops.append([mark.operation, int(mark.line), self.tools[self.tool]])
            self.op_counts = np.append(self.op_counts, 0)
            self.op = len(self.ops) - 1

    def _fill(
        self, a: int, b: int, s: np.ndarray, kind: np.ndarray, tool: np.ndarray, op: np.ndarray, fprog: np.ndarray
    ) -> None:
        code, path, s_off = self.span
        tool[a:b] = self.tool
        op[a:b] = self.op
        if code == 2:  # a path (timeline.SPAN_PATH)
            if path.rapid:
                kind[a:b] = _K_RAPID
            else:
                kind[a:b] = _K_FEED
                fprog[a:b] = path.feed_mm_s[path.segment_of_s(s[a:b] - s_off)]
        else:
            kind[a:b] = _K_DWELL if code == 1 else _K_REST

    def add(self, block: Any) -> None:
        """Count one ``SampleBlock`` (the next in the stream)."""
        from .timeline import EVENT_MARK, feed_of

        k = block.n
        if k == 0:
            return
        q = np.asarray(block.q, dtype=float)
        s = np.asarray(block.s, dtype=float)
        kind = np.empty(k, dtype=np.int8)
        tool = np.empty(k, dtype=np.int64)
        op = np.empty(k, dtype=np.int64)
        fprog = np.full(k, np.inf)
        a = 0
        for ek, code, obj, s_off in block.events:
            i = min(max(int(ek) - block.k0, 0), k)
            if i > a:
                self._fill(a, i, s, kind, tool, op, fprog)
                a = i
            if code == EVENT_MARK:
                self._mark(obj)
            else:
                self.span = (code, obj, s_off)
        if a < k:
            self._fill(a, k, s, kind, tool, op, fprog)
        speed = feed_of(s, self.s_prev, self.dt)
        ratios = limit_ratios(q, self.dt, self.machine, self.head)
        moving = _moving(q, self.head)
        # at programmed feed: within AT_FEED_REL of the feed, or of the axes' velocity
        # limit in this direction (speed / the largest velocity ratio), whichever is lower
        v_ratio = ratios[:, 0, :].max(axis=1) if q.shape[1] else np.zeros(k)
        at_feed = (kind == _K_FEED) & moving & ((speed >= (1.0 - AT_FEED_REL) * fprog) | (v_ratio >= 1.0 - AT_FEED_REL))
        codes = codes_of(ratios, moving, at_feed)
        i0 = 1 if block.k0 == 0 else 0  # sample 0 ends no period
        kind_i = kind[i0:].astype(np.int64)
        self.by_code += np.bincount(kind_i * len(self.names) + codes[i0:], minlength=self.by_code.size).reshape(
            self.by_code.shape
        )
        self.tool_counts += np.bincount(tool[i0:], minlength=self.tool_counts.size)
        self.op_counts += np.bincount(op[i0:], minlength=self.op_counts.size)
        rng = np.clip((block.line[i0:] - 1) // self.width, 0, self.ranges.size - 1)
        self.ranges += np.bincount(rng, minlength=self.ranges.size)
        self.at_feed += int(np.count_nonzero(at_feed[i0:]))
        self.samples += k
        self.head = np.concatenate([self.head, q[-_HEAD:]])[-_HEAD:] if self.head is not None else q[-_HEAD:].copy()
        self.s_prev = float(s[-1])

    def result(self, part: str = "", machine: str = "", planner: str = "", path_length_mm: float = 0.0) -> Estimate:
        """The ``Estimate`` of the blocks counted so far (all of them: the whole plan)."""
        dt = self.dt
        kinds = self.by_code.sum(axis=1)
        periods = max(self.samples - 1, 0)
        limits = self.by_code.sum(axis=0)
        return Estimate(
            part=part,
            machine=machine,
            planner=planner,
            dt_s=dt,
            samples=self.samples,
            cycle_time_s=periods * dt,
            path_length_mm=float(path_length_mm),
            by_kind={name: int(c) * dt for name, c in zip(KINDS, kinds)},
            by_tool=tuple(
                ToolTime(tool=t, time_s=int(c) * dt, line=ln)
                for t, c, ln in zip(self.tools, self.tool_counts, self.tool_line)
                if c or ln
            ),
            by_operation=tuple(
                OperationTime(index=i, name=o[0], line=o[1], tool=o[2], time_s=int(c) * dt)
                for i, (o, c) in enumerate(zip(self.ops, self.op_counts))
                if c or o[0] is not None
            ),
            by_lines=tuple(
                LineRangeTime(first=i * self.width + 1, last=(i + 1) * self.width, time_s=int(c) * dt)
                for i, c in enumerate(self.ranges)
                if c
            ),
            at_feed_s=self.at_feed * dt,
            limits={name: int(c) * dt for name, c in zip(self.names, limits) if c},
            limits_by_kind={
                kname: {name: int(c) * dt for name, c in zip(self.names, row) if c}
                for kname, row in zip(KINDS, self.by_code)
                if row.any()
            },
        )


#: longest operation name a table shows (characters; JSON has it whole)
TABLE_NAME_CHARS = 44


def format_estimate(est: Estimate) -> str:
    """A readable table of ``est`` (what ``cnc-interp estimate`` prints)."""
    from ..errors import printable

    cycle = est.cycle_time_s

    def pct(t: float) -> str:
        return f"{100.0 * t / cycle:6.1f}" if cycle > 0 else "     -"

    def row(label: str, t: float) -> str:
        return f"  {label:<{TABLE_NAME_CHARS + 2}} {t:12.3f} {pct(t)}"

    head = f"  {'':<{TABLE_NAME_CHARS + 2}} {'time s':>12} {'%':>6}"
    out = [
        f"{printable(est.part)}: {est.planner} on {printable(est.machine)}, dt = {est.dt_s:g} s",
        f"cycle time {cycle:.3f} s ({est.samples} samples), path {est.path_length_mm:.3f} mm",
        "",
        "by kind" + head[7:],
    ]
    for name in KINDS:
        out.append(row(name, est.by_kind.get(name, 0.0)))
    share = est.at_feed_share
    if share is not None:
        out.append(row("feed at programmed feed", est.at_feed_s) + f"  ({100.0 * share:.1f} % of feed)")
    out += ["", "by tool" + head[7:]]
    for tt in est.by_tool:
        out.append(row(f"T{tt.tool}" + (f" (M6 at line {tt.line})" if tt.line else " (at the start)"), tt.time_s))
    if any(o.name is not None for o in est.by_operation):
        out += ["", "by operation" + head[12:]]
        for o in est.by_operation:
            name = "(before the first header)" if o.name is None else printable(o.name)
            if len(name) > TABLE_NAME_CHARS - 12:
                name = name[: TABLE_NAME_CHARS - 15] + "..."
            label = f"{name} (line {o.line}, T{o.tool})" if o.name is not None else name
            out.append(row(label, o.time_s))
    out += ["", "by source lines" + head[15:]]
    for r in est.by_lines:
        out.append(row(f"{r.first}-{r.last}", r.time_s))
    out += ["", "binding limit" + head[13:]]
    for name, t in sorted(est.limits.items(), key=lambda kv: -kv[1]):
        out.append(row(name, t))
    return "\n".join(out)

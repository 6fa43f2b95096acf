"""``cnc-interp parse`` output: a JSON-able summary of a ``Program`` and its text form."""

from __future__ import annotations

import numpy as np

from .program import Arc, Dwell, Program, Run, Stop, move_lengths


def _segment_lengths(run: Run) -> np.ndarray:
    """Per-move lengths (N-1,) by the feed convention: linear axes, else rotary (mm / deg)."""
    return move_lengths(run.nodes, run.axes)


def program_summary(program: Program) -> dict:
    """Counts, bounds, lengths and a programmed-feed time estimate of ``program``.

    The time estimate is feed moves only: sum of move length / programmed feed, plus
    dwells. Rapids are excluded (their speed is the machine's, not the program's), so
    it is a lower bound of the cycle time; ``cnc-interp plan`` gives the real one.
    """
    acc = SummaryAccumulator(program.start)
    for it in program.items:
        acc.add(it)
    return acc.result(program)


def stream_summary(stream) -> dict:
    """``program_summary`` of a ``ProgramStream``'s program, item by item as it is read
    (the items are dropped once counted: a 50-byte ``G81 ... L1000000`` is a million holes).
    A stream read without axes gives items on all nine axes; the bounds are reported for
    the axes the program uses, as ``read_program`` would have given them."""
    from ..constants import ALL_AXES

    start9 = np.array(stream.interp.start9, dtype=float)
    acc = SummaryAccumulator(start9[list(stream._order)])
    for it in stream:
        acc.add(it)
    program = stream.program
    if stream._axes != program.axes:  # read without axes: keep the program's own
        sel = [ALL_AXES.index(a) for a in program.axes]
        acc.lo, acc.hi = acc.lo[sel], acc.hi[sel]
    return acc.result(program)


class SummaryAccumulator:
    """The running sums of ``program_summary``, one item at a time (``add``)."""

    def __init__(self, start: np.ndarray):
        self.lo = np.array(start, dtype=float)
        self.hi = self.lo.copy()
        self.feed_len = self.rapid_len = self.feed_time = self.dwell_time = 0.0
        self.n_nodes = self.n_rapid_moves = self.n_feed_runs = self.n_rapid_runs = 0
        self.n_arcs = self.n_nurbs = self.n_dwell = 0
        self.stops: dict[str, int] = {}
        self.end_reasons: dict[str, int] = {}

    def add(self, it) -> None:
        if isinstance(it, Run):
            self.lo = np.minimum(self.lo, it.nodes.min(axis=0))
            self.hi = np.maximum(self.hi, it.nodes.max(axis=0))
            seg = _segment_lengths(it)
            self.end_reasons[it.end_reason] = self.end_reasons.get(it.end_reason, 0) + 1
            if it.kind == "feed":
                self.n_nodes += it.n_nodes  # one definition with fit and batch: feed-run nodes
                self.n_feed_runs += 1
                self.feed_len += float(seg.sum())
                self.feed_time += float((seg / it.feed_mm_s[1:]).sum())
            else:
                self.n_rapid_runs += 1
                self.n_rapid_moves += max(it.n_nodes - 1, 0)
                self.rapid_len += float(seg.sum())
            for cp in it.curves:
                if isinstance(cp.curve, Arc):
                    self.n_arcs += 1
                else:
                    self.n_nurbs += 1
        elif isinstance(it, Dwell):
            self.n_dwell += 1
            self.dwell_time += it.seconds
        elif isinstance(it, Stop):
            self.stops[it.code] = self.stops.get(it.code, 0) + 1

    def result(self, program: Program) -> dict:
        """The summary, with the counts of ``program`` (its items need not be there)."""
        axes = program.axes
        lo, hi = self.lo, self.hi
        bounds = {a: [float(lo[k]), float(hi[k])] for k, a in enumerate(axes)} if axes else {}
        return {
            "source": program.source,
            "axes": axes,
            "lines": int(program.line_count),
            "blocks": int(program.block_count),
            "runs": self.n_feed_runs + self.n_rapid_runs,
            "feed_runs": self.n_feed_runs,
            "rapid_runs": self.n_rapid_runs,
            "run_end_reasons": self.end_reasons,
            "nodes": int(self.n_nodes),
            "rapid_moves": int(self.n_rapid_moves),
            "arcs": self.n_arcs,
            "splines": self.n_nurbs,
            "dwells": self.n_dwell,
            "stops": self.stops,
            "zero_length_moves": int(program.metadata.get("zero_length_moves", 0)),
            "bounds": bounds,
            "feed_length_mm": self.feed_len,
            "rapid_length_mm": self.rapid_len,
            "feed_time_s": self.feed_time,
            "dwell_time_s": self.dwell_time,
            "time_estimate_s": self.feed_time + self.dwell_time,
            "time_estimate_note": "programmed feed moves and dwells only; rapids excluded",
        }


def _fmt_time(s: float) -> str:
    if s < 60:
        return f"{s:.2f} s"
    m, sec = divmod(s, 60.0)
    if m < 60:
        return f"{int(m)} min {sec:04.1f} s"
    h, m = divmod(m, 60.0)
    return f"{int(h)} h {int(m):02d} min {sec:04.1f} s"


def format_summary(summary: dict) -> str:
    """Human-readable text of ``program_summary``'s dict."""
    s = summary
    lines = [
        f"{s['source']}: {s['lines']} lines, {s['blocks']} blocks, axes {s['axes']}",
        f"  runs       {s['runs']} ({s['feed_runs']} feed, {s['rapid_runs']} rapid), "
        f"{s['nodes']} nodes, {s['rapid_moves']} rapid moves",
        f"  curves     {s['arcs']} arcs, {s['splines']} splines/NURBS",
        f"  dwells     {s['dwells']} ({s['dwell_time_s']:.3f} s)",
    ]
    if s["stops"]:
        stops = ", ".join(f"{k} x{v}" for k, v in sorted(s["stops"].items()))
        lines.append(f"  stops      {stops}")
    if s["zero_length_moves"]:
        lines.append(f"  dropped    {s['zero_length_moves']} zero-length moves")
    lines.append("  bounds")
    for a, (lo, hi) in s["bounds"].items():
        unit = "deg" if a in "ABC" else "mm"
        lines.append(f"    {a}  {lo:12.4f} .. {hi:12.4f} {unit}")
    lines.append(f"  length     feed {s['feed_length_mm']:.3f} mm, rapid {s['rapid_length_mm']:.3f} mm")
    lines.append(
        f"  time       {_fmt_time(s['time_estimate_s'])} at programmed feed (feed moves and dwells; rapids excluded)"
    )
    return "\n".join(lines)

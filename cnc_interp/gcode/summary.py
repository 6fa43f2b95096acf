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
    axes = program.axes
    n_axes = len(axes)
    lo = np.array(program.start, dtype=float)
    hi = lo.copy()
    feed_len = rapid_len = feed_time = dwell_time = 0.0
    n_nodes = n_rapid_moves = n_feed_runs = n_rapid_runs = n_arcs = n_nurbs = n_dwell = 0
    stops: dict[str, int] = {}
    end_reasons: dict[str, int] = {}
    for it in program.items:
        if isinstance(it, Run):
            lo = np.minimum(lo, it.nodes.min(axis=0))
            hi = np.maximum(hi, it.nodes.max(axis=0))
            seg = _segment_lengths(it)
            end_reasons[it.end_reason] = end_reasons.get(it.end_reason, 0) + 1
            if it.kind == "feed":
                n_nodes += it.n_nodes  # one definition with fit and batch: feed-run nodes
                n_feed_runs += 1
                feed_len += float(seg.sum())
                feed_time += float((seg / it.feed_mm_s[1:]).sum())
            else:
                n_rapid_runs += 1
                n_rapid_moves += max(it.n_nodes - 1, 0)
                rapid_len += float(seg.sum())
            for cp in it.curves:
                if isinstance(cp.curve, Arc):
                    n_arcs += 1
                else:
                    n_nurbs += 1
        elif isinstance(it, Dwell):
            n_dwell += 1
            dwell_time += it.seconds
        elif isinstance(it, Stop):
            stops[it.code] = stops.get(it.code, 0) + 1
    bounds = {a: [float(lo[k]), float(hi[k])] for k, a in enumerate(axes)} if n_axes else {}
    return {
        "source": program.source,
        "axes": axes,
        "lines": int(program.line_count),
        "blocks": int(program.block_count),
        "runs": n_feed_runs + n_rapid_runs,
        "feed_runs": n_feed_runs,
        "rapid_runs": n_rapid_runs,
        "run_end_reasons": end_reasons,
        "nodes": int(n_nodes),
        "rapid_moves": int(n_rapid_moves),
        "arcs": n_arcs,
        "splines": n_nurbs,
        "dwells": n_dwell,
        "stops": stops,
        "zero_length_moves": int(program.metadata.get("zero_length_moves", 0)),
        "bounds": bounds,
        "feed_length_mm": feed_len,
        "rapid_length_mm": rapid_len,
        "feed_time_s": feed_time,
        "dwell_time_s": dwell_time,
        "time_estimate_s": feed_time + dwell_time,
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

"""Assembling ``Run`` objects: growable flat arrays during interpretation, numpy at the end.

The interpreter appends one node per move into ``array('d')`` buffers (no per-node
Python objects, 8 bytes per value). Node values are stored for the axes that are
*active* at that moment (``layout``, indices into ``ALL_AXES``); when a program
names a new axis mid-run the buffer is re-laid out once (the new axis held still
until then). G2/G3 arcs only reserve their node rows; ``finish_run`` fills the rows
of all arcs of a run in one vectorised pass, builds the exact ``Arc`` objects and
maps the run onto the program's final axes.
"""

from __future__ import annotations

from array import array
from dataclasses import replace

import numpy as np

from .arcs import fill_arc_nodes
from .program import Arc, CurvePiece, Nurbs, Run, linear_moves


class RunBuilder:
    """One run being built. ``start9`` is the 9-axis position before its first move."""

    __slots__ = ("kind", "layout", "start9", "nodes", "line", "col", "feed", "tol", "naive", "curves")

    def __init__(
        self, kind: str, layout: tuple[int, ...], pos9: list[float], line: int, col: int, tol: float, naive: float
    ):
        self.kind = kind
        self.layout = layout
        self.start9 = list(pos9)
        self.nodes = array("d", [pos9[i] for i in layout])
        self.line = array("q", [line])
        self.col = array("q", [col])
        self.feed = array("d", [0.0])  # replaced by feed[1] in finish
        self.tol = array("d", [tol])
        self.naive = array("d", [naive])
        self.curves: list[tuple[int, int, object]] = []  # (first, last, 9-axis curve)

    @property
    def n(self) -> int:
        """Number of nodes so far (the hot path appends without counting)."""
        return len(self.line)

    def widen(self, new_layout: tuple[int, ...], pos9: list[float]) -> None:
        """Re-lay the buffer out for ``new_layout``; new axes get their (unchanged) value."""
        old = np.frombuffer(self.nodes, dtype=float).reshape(self.n, len(self.layout))
        out = np.empty((self.n, len(new_layout)))
        for j, ax in enumerate(new_layout):
            if ax in self.layout:
                out[:, j] = old[:, self.layout.index(ax)]
            else:
                out[:, j] = pos9[ax]
        self.nodes = array("d")
        self.nodes.frombytes(out.tobytes())
        self.layout = new_layout

    def reserve(self, k: int, line: int, col: int, feed: float, tol: float, naive: float) -> tuple[int, int]:
        """Append ``k`` node slots (zeros, filled by ``finish_run``); returns (first, last)."""
        first = self.n - 1
        self.nodes.frombytes(bytes(8 * k * len(self.layout)))
        self.line.extend(array("q", (line,)) * k)
        self.col.extend(array("q", (col,)) * k)
        self.feed.extend(array("d", (feed,)) * k)
        self.tol.extend(array("d", (tol,)) * k)
        self.naive.extend(array("d", (naive,)) * k)
        return first, self.n - 1

    def add_many(self, pts: np.ndarray, line: int, col: int, feed: float, tol: float, naive: float) -> tuple[int, int]:
        """Append sampled nodes (K, 9) or (K, len(layout)); returns the piece's (first, last)."""
        k = pts.shape[0]
        first = self.n - 1
        if pts.shape[1] != len(self.layout):
            pts = pts[:, list(self.layout)]
        self.nodes.frombytes(np.ascontiguousarray(pts, dtype=float).tobytes())
        self.line.extend(array("q", (line,)) * k)
        self.col.extend(array("q", (col,)) * k)
        self.feed.extend(array("d", (feed,)) * k)
        self.tol.extend(array("d", (tol,)) * k)
        self.naive.extend(array("d", (naive,)) * k)
        return first, self.n - 1


def finish_run(rb: RunBuilder, axes_idx: tuple[int, ...], axes: str, end_reason: str) -> Run:
    """The frozen ``Run`` for builder ``rb`` in the final axes ``axes_idx``."""
    n = rb.n
    ncol = len(rb.layout)
    raw = np.frombuffer(rb.nodes, dtype=float).reshape(n, ncol)
    arcs = [p for p in rb.curves if p[2].__class__ is tuple]
    if arcs:
        fill_arc_nodes(raw, rb.layout, arcs)
    if rb.layout == axes_idx:
        nodes = raw  # shares the buffer; the builder is dropped after this
    else:
        nodes = np.empty((n, len(axes_idx)))
        for j, ax in enumerate(axes_idx):
            if ax in rb.layout:
                nodes[:, j] = raw[:, rb.layout.index(ax)]
            else:
                nodes[:, j] = rb.start9[ax]
    feed = np.frombuffer(rb.feed, dtype=float)
    if n > 1:
        feed[0] = feed[1]
    sel = list(axes_idx)
    where = {ax: j for j, ax in enumerate(axes_idx)}
    curves = []
    for first, last, c in rb.curves:
        if c.__class__ is tuple:  # an arc recorded by the interpreter: make the exact Arc
            line, s9, e9, plane, c1, c2, r1, r2, sweep = c
            cur = Arc(
                line=line,
                start=np.array([s9[i] for i in sel]),
                end=np.array([e9[i] for i in sel]),
                plane=tuple(where.get(p, -1) for p in plane),
                center=np.array((c1, c2)),
                radius=0.5 * (r1 + r2),
                sweep_rad=float(sweep),
            )
        elif isinstance(c, Arc):
            plane = tuple(where.get(p, -1) for p in c.plane)
            cur = Arc(
                line=c.line,
                start=c.start[sel].copy(),
                end=c.end[sel].copy(),
                plane=plane,
                center=c.center,
                radius=c.radius,
                sweep_rad=c.sweep_rad,
            )
        else:
            assert isinstance(c, Nurbs)
            cur = Nurbs(
                line=c.line,
                control=np.ascontiguousarray(c.control[:, sel]),
                weights=c.weights,
                knots=c.knots,
                order=c.order,
            )
        curves.append(CurvePiece(first=first, last=last, curve=cur))
    return Run(
        kind=rb.kind,
        axes=axes,
        nodes=nodes,
        line=np.frombuffer(rb.line, dtype=np.int64),
        col=np.frombuffer(rb.col, dtype=np.int64),
        feed_mm_s=feed,
        tol_mm=np.frombuffer(rb.tol, dtype=float),
        naive_tol_mm=np.frombuffer(rb.naive, dtype=float),
        curves=tuple(curves),
        end_reason=end_reason,
    )


def cap_path_speed(run: Run, max_path_mm_s: float | None) -> Run:
    """``run`` with the feed of every move that moves a linear axis capped at
    ``max_path_mm_s`` (mm/s over the linear axes: ``Machine.path_speed_cap_mm_s``, LinuxCNC's
    ``[TRAJ] MAX_LINEAR_VELOCITY``): a feed move's programmed feed, and a rapid's, which is
    otherwise infinite (the axes' own limits). A rotary-only move (its feed in deg/s,
    ``program.linear_moves``) keeps its feed. ``None``: ``run`` as it is."""
    if max_path_mm_s is None or run.n_nodes < 2:
        return run
    linear = linear_moves(np.asarray(run.nodes, dtype=float), run.axes)
    feed = np.array(run.feed_mm_s, dtype=float)
    feed[1:] = np.where(linear, np.minimum(feed[1:], max_path_mm_s), feed[1:])
    feed[0] = feed[1]
    return replace(run, feed_mm_s=feed)

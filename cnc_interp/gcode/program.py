"""The front end's output types: a ``Program`` as a timeline of items.

Everything here is in machine coordinates (G53 frame), mm for linear axes and
degrees for rotary axes, feeds in mm/s (deg/s for rotary-only moves), times in s.
Inch, mm/min, work offsets, G92 and incremental modes have already been applied.

A program is a sequence of items on one timeline:

* ``Run``   – continuous motion: a polyline of nodes (G1/G2/G3/G5.x, or G0 rapids),
  with exact curve pieces (arcs, NURBS, splines) attached to the node ranges
  they span;
* ``Dwell`` – G4, the machine holds still for ``seconds``;
* ``Stop``  – M0/M1/M2/M30/M6/M60: the machine comes to rest.

Every run starts where the previous item left the machine (``nodes[0]``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Arc:
    """An exact circular or helical arc (G2/G3).

    ``plane`` holds three axis indices (first, second, normal) into the machine
    axes, e.g. (0, 1, 2) for G17 on XYZ. The arc turns about ``center`` (2,),
    given in the plane's two coordinates, by ``sweep_rad`` (positive =
    counter-clockwise seen from +normal; |sweep| may exceed 2π for P turns).
    Every other axis (the normal axis for a helix, rotary axes) moves linearly
    with the swept angle from ``start`` to ``end`` (both (n_axes,)).
    """

    line: int
    start: np.ndarray
    end: np.ndarray
    plane: tuple[int, int, int]
    center: np.ndarray
    radius: float
    sweep_rad: float

    def points(self, frac: np.ndarray) -> np.ndarray:
        """Positions at fractions ``frac`` (K,) of the sweep, shape (K, n_axes)."""
        frac = np.asarray(frac, dtype=float)
        i, j, _ = self.plane
        a0 = np.arctan2(self.start[j] - self.center[1], self.start[i] - self.center[0])
        ang = a0 + self.sweep_rad * frac
        out = self.start[None, :] + (self.end - self.start)[None, :] * frac[:, None]
        # The radius may vary linearly from start to end within the arc tolerance
        # (LinuxCNC does the same, it makes the end point exact).
        r0 = float(np.hypot(self.start[i] - self.center[0], self.start[j] - self.center[1]))
        r1 = float(np.hypot(self.end[i] - self.center[0], self.end[j] - self.center[1]))
        r = r0 + (r1 - r0) * frac
        out[:, i] = self.center[0] + r * np.cos(ang)
        out[:, j] = self.center[1] + r * np.sin(ang)
        result: np.ndarray = out
        return result


@dataclass(frozen=True)
class Nurbs:
    """An exact NURBS curve (G5.2/G5.3), or a G5/G5.1 spline as a Bézier NURBS.

    ``control`` (M, n_axes) are the control points in machine coordinates, the
    first being the position before the block (LinuxCNC semantics); axes that the
    block does not name stay at their current value. ``weights`` (M,),
    ``knots`` (M + order,) clamped, ``order`` = degree + 1.
    """

    line: int
    control: np.ndarray
    weights: np.ndarray
    knots: np.ndarray
    order: int

    def points(self, u: np.ndarray) -> np.ndarray:
        """Positions at knot-parameter values ``u`` (K,), shape (K, n_axes)."""
        from scipy.interpolate import BSpline

        k = self.order - 1
        w = self.weights
        num = BSpline(self.knots, self.control * w[:, None], k)(u)
        den = BSpline(self.knots, w, k)(u)
        points: np.ndarray = num / den[:, None]
        return points


Curve = Arc | Nurbs


@dataclass(frozen=True)
class CurvePiece:
    """An exact curve spanning nodes ``first``..``last`` (inclusive) of its run.

    The nodes in that range are samples of the curve (for statistics, plots and
    the fitter's cheap path); the fitter may use ``curve`` for exact geometry.
    """

    first: int
    last: int
    curve: Curve


@dataclass(frozen=True)
class Run:
    """Continuous motion through ``nodes`` without a programmed stop.

    Attributes (N = number of nodes, n = number of machine axes):
        kind: ``"feed"`` (G1/G2/G3/G5.x, canned-cycle feeds) or ``"rapid"`` (G0,
            straight in joint space, at the axes' speed limits and the machine's path
            speed cap).
        axes: machine axis letters in machine order, e.g. ``"XYZ"``.
        nodes: (N, n) positions, mm / deg; ``nodes[0]`` is where the run starts.
        line: (N,) int, source line of the block that ends at node i
            (``line[0]`` is the line of the block that started the run).
        col: (N,) int, source column of that block's motion word (1-based).
        feed_mm_s: (N,) feed limit of the move ending at node i, mm/s (deg/s for a
            rotary-only move); G93 inverse time is already converted; ``inf`` for
            rapids; both capped at the machine's path speed limit where it has one
            (``runs.cap_path_speed``); ``feed_mm_s[0]`` repeats ``feed_mm_s[1]``.
        tol_mm: (N,) path tolerance of the move ending at node i: ``nan`` = G64
            without P (use the default/--tol), ``0`` = G61 exact path, > 0 = G64 P.
        naive_tol_mm: (N,) G64 Q value (naive CAM tolerance), ``nan`` if none.
        curves: exact curve pieces attached to node ranges.
        end_reason: why the run ended: ``"rapid"``, ``"feed"`` (rapid run followed
            by feed motion), ``"stop"``, ``"tool-change"``, ``"dwell"``,
            ``"exact-stop"`` (G61.1), ``"end"``.
    """

    kind: str
    axes: str
    nodes: np.ndarray
    line: np.ndarray
    col: np.ndarray
    feed_mm_s: np.ndarray
    tol_mm: np.ndarray
    naive_tol_mm: np.ndarray
    curves: tuple[CurvePiece, ...] = ()
    end_reason: str = "end"

    @property
    def n_nodes(self) -> int:
        return int(self.nodes.shape[0])

    def length_mm(self) -> float:
        """Polyline length through the nodes (linear axes; rotary if none move)."""
        return float(polyline_length(self.nodes, self.axes))


@dataclass(frozen=True)
class Dwell:
    """G4: hold still for ``seconds`` at ``position`` (n_axes,)."""

    line: int
    seconds: float
    position: np.ndarray


@dataclass(frozen=True)
class Stop:
    """A programmed stop: ``code`` is ``"M0"``, ``"M1"``, ``"M2"``, ``"M30"``, ``"M6"`` or ``"M60"``."""

    line: int
    code: str
    position: np.ndarray


@dataclass(frozen=True)
class Mark:
    """A change of what the machine runs, in program order: the tool an M6 loads
    (``tool``), or an operation header, the first comment of a group of comment-only
    lines (``operation``, its text). Only a stream asked for them carries marks
    (``ProgramStream(marks=True)``: ``estimate`` and ``batch`` use them to attribute
    time); ``Program.items`` never holds one. A header read while a run is open takes
    effect when that run ends (runs are not cut for a comment)."""

    line: int
    tool: int | None = None
    operation: str | None = None


Item = Run | Dwell | Stop


@dataclass(frozen=True)
class Program:
    """A whole part program as a timeline.

    Attributes:
        source: file name as given by the user (``"<stdin>"`` for ``-``).
        axes: machine axis letters in machine order.
        items: the timeline (runs, dwells, stops) in execution order.
        start: (n_axes,) machine position before the first item.
        line_count: number of source lines read.
        block_count: number of blocks interpreted (after loops/calls are expanded).
    """

    source: str
    axes: str
    items: tuple[Item, ...]
    start: np.ndarray
    line_count: int
    block_count: int = 0
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def runs(self) -> tuple[Run, ...]:
        return tuple(it for it in self.items if isinstance(it, Run))


def move_lengths(points: np.ndarray, axes: str) -> np.ndarray:
    """Lengths (K-1,) of the moves between consecutive points (K, n_axes) by LinuxCNC's
    feed convention: the linear axes' distance (mm), or the rotary axes' (deg) where no
    linear axis moves more than ``LINEAR_MOTION_MIN_MM`` (the fitter's arc-length metric).
    The one definition: the feed of a move, the program summary, the FPGA emulator's path
    length (``interp._move_length`` is its scalar form)."""
    lin_len, rot_len, linear = _move_parts(points, axes)
    lengths: np.ndarray = np.where(linear, lin_len, rot_len)
    return lengths


def linear_moves(points: np.ndarray, axes: str) -> np.ndarray:
    """(K-1,) bool: which moves between consecutive points (K, n_axes) take their feed over
    the linear axes (mm/s), as ``move_lengths`` measures them; the others are rotary-only
    (deg/s)."""
    linear: np.ndarray = _move_parts(points, axes)[2]
    return linear


def _move_parts(points: np.ndarray, axes: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per move: the linear axes' distance, the rotary axes' and whether the move is linear
    (a linear axis moves more than ``LINEAR_MOTION_MIN_MM``, or no rotary axis moves)."""
    from ..constants import LINEAR_AXES, LINEAR_MOTION_MIN_MM

    d = np.diff(points, axis=0)
    lin = np.array([a in LINEAR_AXES for a in axes], dtype=bool)
    lin_len = np.sqrt((d[:, lin] ** 2).sum(axis=1)) if lin.any() else np.zeros(len(d))
    rot_len = np.sqrt((d[:, ~lin] ** 2).sum(axis=1)) if (~lin).any() else np.zeros(len(d))
    return lin_len, rot_len, (lin_len > LINEAR_MOTION_MIN_MM) | (rot_len == 0)


def polyline_length(nodes: np.ndarray, axes: str) -> float:
    """Length of a polyline by LinuxCNC's feed convention (``move_lengths``)."""
    if nodes.shape[0] < 2:
        return 0.0
    return float(move_lengths(nodes, axes).sum())

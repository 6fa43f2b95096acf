"""``fit_program`` / ``fit_run``: the fit stage's entry points.

Which fitter handles what:

* rapid runs: one straight ``Path(rapid=True)`` per G0 move, or per chain of G0 moves
  along one line in one direction;
* G61 stretches: exact straight lines, a stop at every non-collinear node (one
  segment per feed in a collinear chain: each move keeps its F);
* with ``FitSettings.method`` = "planar"/"auto", feed paths without exact curves
  that move exactly two axes: paper 000's planar method (``planar.py``), with the
  N-axis fitter as fallback when an inherited tangent leaves the next frame;
* everything else (the default "nodes" everywhere): sharp corners between straight
  moves get G2 blends (``blends.py``, ``corners.add_blends``); then sections — exact
  curves (``curves.py``), blends, and the polylines between them (``nodes.py``),
  joined G2: a polyline next to a curve or blend takes its exact tangent and
  curvature vector at the junction, two curves meet at their averaged tangent /
  curvature.

Every fitted sub-run is measured against the programmed path (``deviation.py``);
one outside its tolerance is refitted tighter, then repaired locally over a few
rounds (blends, or stops where a corner cannot be blended, at nodes of its failing
sections), and as the last resort becomes its exact moves with stops. A fit still
outside is reported in the statistics; ``result.require_within_tolerance`` turns
that into a ``FitError`` for the commands.
"""

from __future__ import annotations

import os
import threading
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace

import numpy as np

from ..constants import ARC_LENGTH_MAX_SUB, ARC_LENGTH_REL_TOL
from ..gcode.program import Dwell, Mark, Program, Run, Stop
from .deviation import path_deviation, polyline_deviation, rotary_path_deviation
from .corners import PreparedRun, SubRun, add_blends, fit_tolerance, prepare_run, slice_run, split_run
from .curves import arc_table
from .nodes import EndState, fit_polyline, straight_piece
from .path import Path, PlanarSegments
from .result import FitResult, fit_outside_error
from .settings import FitSettings


#: path deviation: relative slack over the tolerance (float rounding of the projection)
PATH_DEV_SLACK = 1e-6

#: consecutive rapids whose unit directions differ by at most this (relative) are one
#: straight chain: the same line, float rounding aside (G91 repeats, Z5 then Z10)
RAPID_COLLINEAR_TOL = 1e-12

#: a fit the measurement finds outside its tolerance is fitted again aiming at this share
#: of it before the sub-run is split (the fitter checks sampled points; the measurement is
#: denser, so a miss is usually by a few per cent)
FIT_REPAIR_TOL_SHARE = 0.7

#: repair rounds of a run whose fit the measurement finds outside its tolerance: each puts
#: blends (stops where a corner cannot be blended) at FIT_REPAIR_SPLITS nodes spread over
#: every failing section and refits; the last one at every node of the sections still failing
FIT_REPAIR_ROUNDS = 4

FIT_REPAIR_SPLITS = 8

#: a fitted path ends on its programmed point: an end off by at most this share of its
#: last segment's length (rounding: an arc of radius 1e9 mm ends 1.4e-7 mm off, its centre
#: a billion mm away) is moved there by a quintic blend over that segment, which keeps the
#: segment's start and its end tangent and curvature; a larger gap is left as fitted
FIT_END_SNAP_MAX_REL = 1e-6


@dataclass
class _Raw:
    """A path before construction (so that its start can be chained exactly)."""

    axes: str
    breaks: np.ndarray
    coef: np.ndarray
    line: np.ndarray
    feed: np.ndarray
    weights: np.ndarray
    rapid: bool = False
    planar: PlanarSegments | None = None
    #: (kind, first node, last node, first segment, end segment) per section of a sub-run
    sections: list | None = None

    def build(self, start: np.ndarray | None = None) -> Path:
        coef = self.coef
        planar = self.planar
        if start is not None:
            coef = coef.copy()
            delta = start - coef[0, 0]
            coef[0, 0] = start
            if planar is not None:
                h, v = planar.plane
                origin = planar.origin.copy()
                origin[0] += delta[[h, v]]
                planar = replace(planar, origin=origin)
        return Path(
            axes=self.axes,
            breaks=self.breaks,
            coef=coef,
            line=self.line,
            feed_mm_s=self.feed,
            weights=self.weights,
            rapid=self.rapid,
            planar=planar,
        )


#: paths built per compiled call while streaming a run (any value gives the same paths)
FIT_STREAM_BATCH = 128

#: most worker threads ``fit_program`` gives the batch fitter by default: one thread
#: collects the batches in order (Python), so more workers than that gain little
FIT_MAX_THREADS = 4


_thread_cap = FIT_MAX_THREADS


def default_fit_threads() -> int:
    """``fit_program``'s default worker threads: the CPUs this process may use, capped
    (by ``FIT_MAX_THREADS`` and ``cap_default_threads``)."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        cpus = os.cpu_count() or 1
    return max(1, min(cpus, _thread_cap))


def cap_default_threads(n: int) -> None:
    """Cap ``default_fit_threads`` for this process (a batch runs a program per core in
    its own process already: its children fit on their own thread)."""
    global _thread_cap
    _thread_cap = max(1, int(n))


def fit_program(program: Program, settings: FitSettings | None = None, threads: int | None = None) -> FitResult:
    """Fit every run of ``program``; dwells and stops pass through (see ``FitResult``).
    ``threads``: worker threads of the batch fitter's kernels (default: the CPUs this
    process may use, at most ``FIT_MAX_THREADS``); the paths do not depend on it."""
    stats: dict = {}
    n_threads = default_fit_threads() if threads is None else threads
    items = tuple(iter_fit(program.items, settings, stats, threads=n_threads))
    return FitResult(program=program, items=items, stats=stats)


def iter_fit(
    items,
    settings: FitSettings | None = None,
    stats: dict | None = None,
    batch: int = FIT_STREAM_BATCH,
    source: str | None = None,
    threads: int = 1,
):
    """Fit a program's items lazily, in order: each run's paths as soon as they are
    fitted (``batch`` at a time), dwells and stops passed through. ``stats`` (a dict) is
    filled with ``fit_program``'s statistics, complete when the iteration ends. The paths
    are the same as ``fit_program``'s, whatever ``batch`` is. A run is fitted whole (its
    repair rounds refit the whole run), so a run's paths come out together. With
    ``source`` (the part program's name), a run whose fit stays outside its tolerance
    raises ``FitError`` before any of its paths is handed on. ``threads`` > 1 runs the
    batch fitter's kernels on that many worker threads (the same paths)."""
    from .quantum import QuantumDetector

    settings = settings or FitSettings()
    quantum = QuantumDetector()
    runs_info = []
    prev_end = None
    totals = dict(
        nodes_in=0,
        segments_out=0,
        feed_paths=0,
        rapid_moves=0,
        max_node_dev_mm=0.0,
        max_node_dev_deg=0.0,
        max_path_dev_mm=0.0,
        max_path_dev_ratio=0.0,
        max_path_dev_rot_ratio=0.0,
        within_tolerance=True,
        max_tol_mm=0.0,
    )
    for idx, it in enumerate(items):
        if isinstance(it, Run):
            # half the printed quantum of the moves so far widens the tolerance (quantum.py)
            quantum.add_run(it)
            q = quantum.result()
            run_settings = replace(settings, quantum_mm=q["quantum_mm"], quantum_deg=q["quantum_deg"])
            info = _run_info(it)
            info["item"] = idx
            # a run's paths are built and handed on ``batch`` at a time as its sub-runs are
            # fitted (stellabee1 is one run of 258k nodes: holding all its fits costs 250 MB)
            # with worker threads, a batch's arc-length tables are computed on one of them
            # while the next batch is fitted, and its paths handed on after that
            pending: list[_Raw] = []
            ahead: deque = deque()  # futures of the batches' _PathParts, not yet handed on
            n_raws = 0

            def build(raws: list[_Raw]):
                if threads <= 1:
                    return _build_paths(raws, prev_end)
                parts = _PathParts(raws)
                ahead.append(_fit_pool(threads).submit(parts.compute_tables))
                if len(ahead) < 2:
                    return [], prev_end
                return _finish_paths(ahead.popleft().result(), prev_end)

            for raw in _iter_run_raws(it, run_settings, info, threads):
                pending.append(raw)
                n_raws += 1
                if len(pending) >= batch:
                    if source is not None and not info["within_tolerance"]:
                        raise fit_outside_error(info, source)
                    paths, prev_end = build(pending)
                    pending = []
                    yield from paths
            runs_info.append(info)
            if source is not None and not info["within_tolerance"]:
                raise fit_outside_error(info, source)
            if pending:
                paths, prev_end = build(pending)
                yield from paths
            while ahead:
                paths, prev_end = _finish_paths(ahead.popleft().result(), prev_end)
                yield from paths
            if it.kind == "rapid":
                totals["rapid_moves"] += n_raws
            else:
                totals["nodes_in"] += info["nodes_in"]
                totals["segments_out"] += info["segments_out"]
                totals["feed_paths"] += n_raws
            if "max_tol_mm" in info:  # fitted as a feed run (a blended rapid chain too)
                totals["max_node_dev_mm"] = max(totals["max_node_dev_mm"], info["max_node_dev_mm"])
                totals["max_node_dev_deg"] = max(totals["max_node_dev_deg"], info["max_node_dev_deg"])
                totals["max_path_dev_mm"] = max(totals["max_path_dev_mm"], info["max_path_dev_mm"])
                totals["max_path_dev_ratio"] = max(totals["max_path_dev_ratio"], info["max_path_dev_ratio"])
                totals["max_path_dev_rot_ratio"] = max(totals["max_path_dev_rot_ratio"], info["max_path_dev_rot_ratio"])
                totals["within_tolerance"] &= info["within_tolerance"]
                totals["max_tol_mm"] = max(totals["max_tol_mm"], info.get("max_tol_mm", 0.0))
        elif isinstance(it, (Dwell, Stop)):
            yield it
            prev_end = None
        elif isinstance(it, Mark):  # moves nothing: the next run still joins the last
            yield it
        else:  # pragma: no cover - the item type is closed
            raise TypeError(type(it))
    out = dict(totals)
    out["segments_per_node"] = (totals["segments_out"] / totals["nodes_in"]) if totals["nodes_in"] else 0.0
    out["tol_mm"] = settings.tol_mm
    out["tol_deg"] = settings.tol_deg
    out["tol_cap_mm"] = settings.tol_cap_mm
    q = quantum.result()
    out["quantum"] = q
    final = replace(settings, quantum_mm=q["quantum_mm"], quantum_deg=q["quantum_deg"])
    out["fit_tol_mm"] = final.fit_tol_mm
    out["fit_tol_deg"] = final.fit_tol_deg
    out["corner_deg"] = settings.corner_deg
    out["tol_mode"] = settings.tol_mode
    out["method"] = settings.method
    out["runs"] = runs_info
    if stats is not None:
        stats.update(out)


def fit_run(run: Run, settings: FitSettings | None = None) -> list[Path]:
    """Fit one run: a list of paths, planned rest to rest, each starting where the last ended."""
    raws, _ = _fit_run_raw(run, settings or FitSettings())
    return _build_paths(raws, None)[0]


def _build_paths(raws: list[_Raw], start: np.ndarray | None):
    """Build the paths of one run, chained (each starts where the previous ended, the
    first at ``start`` if given): (paths, end of the last path, or ``start`` if none).

    The same values as ``raw.build(prev_end)`` one by one, with the chaining and every
    arc-length table computed by two compiled calls for the whole run (small paths
    are otherwise dominated by per-path overhead)."""
    return _finish_paths(_PathParts(raws).compute_tables(), start)


class _PathParts:
    """``_build_paths``' first half, which does not depend on the start: the raws'
    arrays concatenated and their arc-length tables (a compiled call without the GIL,
    so a worker thread may compute it while the next raws are fitted)."""

    def __init__(self, raws: list[_Raw]):
        self.raws = raws
        self.valid = False
        self.tables = None
        if not raws:
            return
        n_p = len(raws)
        self.axes = axes = raws[0].axes
        n_ax = len(axes)
        nseg = np.array([r.coef.shape[0] for r in raws], dtype=np.int64)
        seg_off = np.zeros(n_p + 1, dtype=np.int64)
        np.cumsum(nseg, out=seg_off[1:])
        valid = all(
            r.axes == axes
            and r.coef.ndim == 3
            and r.coef.shape[1:] == (6, n_ax)
            and r.breaks.shape == (r.coef.shape[0] + 1,)
            for r in raws
        ) and bool(nseg.min() >= 1)
        if valid:
            breaks = np.concatenate([r.breaks for r in raws]).astype(float, copy=False)
            steps = np.diff(breaks) > 0
            steps[seg_off[1:-1] + np.arange(n_p - 1)] = True  # junctions between paths
            valid = bool(steps.all())
        if not valid:  # Path's own checks raise the error
            return
        self.valid = True
        coef = np.concatenate([r.coef for r in raws]).astype(float, copy=False)
        if len(raws) == 1 and coef is raws[0].coef:
            coef = coef.copy()
        self.seg_off = seg_off
        self.breaks = breaks
        self.coef = coef
        self.line = np.concatenate([np.asarray(r.line, dtype=np.int64).reshape(-1) for r in raws])
        self.feed = np.concatenate([np.asarray(r.feed, dtype=float).reshape(-1) for r in raws])
        self.weights = np.array([r.weights for r in raws], dtype=float).reshape(n_p, n_ax)

    def compute_tables(self) -> "_PathParts":
        """The arc-length tables (from the derivatives only: the chaining, which moves
        each path's first point, does not change them)."""
        from ._arclen import arc_length_tables
        from .path import _GL_W, _GL_X

        if self.valid:
            self.tables = arc_length_tables(
                self.coef, self.breaks, self.seg_off, self.weights, _GL_X, _GL_W, ARC_LENGTH_REL_TOL, ARC_LENGTH_MAX_SUB
            )
        return self


def _finish_paths(parts: _PathParts, start: np.ndarray | None):
    """``_build_paths``' second half: chain the paths of ``parts`` from ``start``."""
    from ._arclen import chain_ends

    raws = parts.raws
    if not raws:
        return [], start
    if not parts.valid:
        out = []
        for raw in raws:
            out.append(raw.build(start))
            start = out[-1].end
        return out, start
    coef, breaks, seg_off = parts.coef, parts.breaks, parts.seg_off
    n_ax = len(parts.axes)
    has_start = start is not None
    ends, delta = chain_ends(
        coef, breaks, seg_off, np.asarray(start, dtype=float) if has_start else np.zeros(n_ax), has_start
    )
    assert parts.tables is not None
    sub_u, sub_s, sub_seg, s_breaks, sub_off = parts.tables
    out = []
    so = seg_off.tolist()
    uo = sub_off.tolist()
    for p, r in enumerate(raws):
        a, b = so[p], so[p + 1]
        ua, ub = uo[p], uo[p + 1]
        planar = r.planar
        if planar is not None and (p > 0 or has_start):
            h, v = planar.plane
            origin = planar.origin.copy()
            origin[0] += delta[p, [h, v]]
            planar = replace(planar, origin=origin)
        out.append(
            Path._from_parts(
                parts.axes,
                breaks[a + p : b + p + 1],
                coef[a:b],
                parts.line[a:b],
                parts.feed[a:b],
                parts.weights[p],
                r.rapid,
                planar,
                sub_u[ua + p : ub + p + 1],
                sub_s[ua + p : ub + p + 1],
                sub_seg[ua:ub],
                s_breaks[a + p : b + p + 1],
            )
        )
    return out, ends[-1]


def _weights(lin: np.ndarray, rotary: bool) -> np.ndarray:
    w = lin.astype(float)
    return (1.0 - w) if rotary else w


def _run_info(run: Run) -> dict:
    return dict(
        kind=run.kind,
        first_line=int(run.line[0]) if run.n_nodes else 0,
        last_line=int(run.line[-1]) if run.n_nodes else 0,
        nodes_in=0,
        segments_out=0,
        paths=0,
        methods=[],
        max_node_dev_mm=0.0,
        max_node_dev_deg=0.0,
        max_path_dev_mm=0.0,
        max_path_dev_ratio=0.0,
        max_path_dev_rot_ratio=0.0,
        within_tolerance=True,
    )


def _fit_run_raw(run: Run, settings: FitSettings):
    """Fit one run: (its raw paths in order, its statistics ``_run_info``)."""
    info = _run_info(run)
    raws = list(_iter_run_raws(run, settings, info))
    return raws, info


def _iter_run_raws(run: Run, settings: FitSettings, info: dict, threads: int = 1):
    """The raw paths of one run in order, each sub-run's as soon as it is fitted; ``info``
    (``_run_info``) holds the statistics of what was yielded so far. With ``threads`` > 1
    the batch fitter's kernels run on that many worker threads, a few batches ahead of
    this one, which builds the results in order (the same paths)."""
    lin = np.array([a in "XYZUVW" for a in run.axes], dtype=bool)
    if run.kind == "rapid":
        if not (settings.blend_rapids and _rapid_turns(run, lin, settings)):
            raws = _rapid_raws(run, lin)
            info["paths"] = len(raws)
            yield from raws
            return
        # a chain of rapids that turns gently under G64: fitted as a feed run is, its
        # turns up to ``corner_deg`` smooth, its sharper corners stops (not blended: from
        # rapid speed a small blend is slower than the exact plans of two lines); each
        # of its paths still a rapid
        for raw in _iter_feed_raws(run, replace(settings, blend_corners=False), info, threads):
            raw.rapid = True
            yield raw
        return
    yield from _iter_feed_raws(run, settings, info, threads)


def _rapid_turns(run: Run, lin: np.ndarray, settings: FitSettings) -> bool:
    """Does a rapid run turn by at most ``corner_deg`` at a node where its tolerance is
    not 0 (G64, ``--tol`` not 0), so that ``_rapid_raws`` would stop where the smooth fit
    goes on?"""
    if run.n_nodes < 3:
        return False
    nodes = np.asarray(run.nodes, dtype=float)
    tol = settings.node_tolerance(run.tol_mm)
    cos_gentle = float(np.cos(np.radians(settings.corner_deg)))
    prev = None  # the last move's direction in its metric and its tolerance
    for j in range(1, nodes.shape[0]):
        d = nodes[j] - nodes[j - 1]
        length, rotary = _rapid_move(d, lin)
        if not length > 0:
            continue
        u = np.where(lin != rotary, d, 0.0) / length  # on the axes its length is measured on
        if prev is not None:
            u0, tol0 = prev
            if not _same_line(u, u0) and float(u @ u0) >= cos_gentle and tol[j] != 0 and tol0 != 0:
                return True
        prev = (u, tol[j])
    return False


def _rapid_move(d: np.ndarray, lin: np.ndarray) -> tuple[float, bool]:
    """A rapid move's length and whether it is measured on its rotary axes (no linear
    axis moves), for the move ``d`` (n,) between two nodes."""
    ll = float(np.sqrt((d[lin] ** 2).sum()))
    rotary = not ll > 0
    return (ll if not rotary else float(np.sqrt((d[~lin] ** 2).sum()))), rotary


def _same_line(direction: np.ndarray, other: np.ndarray) -> bool:
    """Are two rapid directions the same, float rounding aside (``RAPID_COLLINEAR_TOL``)?"""
    return bool(np.abs(direction - other).max() <= RAPID_COLLINEAR_TOL * max(1.0, float(np.abs(direction).max())))


def _iter_feed_raws(run: Run, settings: FitSettings, info: dict, threads: int):
    """``_iter_run_raws`` of a run fitted as a feed run: corners, blends, sections."""
    pr = prepare_run(run, settings)
    evals: dict = {}  # CurveEval per curve, shared by the corner split and the fit
    info["nodes_in"] = int(run.n_nodes)
    info["max_tol_mm"] = float(pr.tol_mm.max()) if pr.tol_mm.size else 0.0
    blend = settings.blend_corners and settings.method == "nodes"
    # the compiled batch fitter's runs: their arcs' constants and end states once, as
    # arrays (the corner split needs the end tangents too)
    covered = _SubRunBatcher.covers_run(pr, settings)
    arcs = arc_table(pr.curves, pr.nodes.shape[1]) if covered and pr.curves else None
    prb = add_blends(pr, settings, evals, arcs=arcs) if blend else pr
    if arcs is not None:  # the same arcs, at their nodes in the blended run
        arcs = arcs._replace(
            first=np.array([cp.first for cp in prb.curves], dtype=np.int64),
            last=np.array([cp.last for cp in prb.curves], dtype=np.int64),
        )
    # only a repair needs the run without its blends again, and repairs are rare: it is
    # prepared again then (the same arrays) rather than kept for the whole run
    kept: list[PreparedRun] = [pr] if prb is pr else []
    del pr

    def unblended() -> PreparedRun:
        if not kept:
            kept.append(prepare_run(run, settings))
        return kept[0]

    methods: set[str] = set()
    # the sub-runs the compiled batch fitter covers are fitted FIT_KERNEL_BATCH at a time
    # (the same fits: ``_subrun``); the others, and any fit found outside its tolerance,
    # by the Python code, in path order
    batcher = _SubRunBatcher(prb, settings, arcs) if covered else None
    pending: list[tuple[SubRun, int]] = []  # with the index of its first curve

    def emit(sub: SubRun, results: list, where: PreparedRun):
        for m in results:
            _snap_end(m.raw, where.nodes[m.i1])
            methods.add(m.method)
            info["max_node_dev_mm"] = max(info["max_node_dev_mm"], m.dev_mm)
            info["max_node_dev_deg"] = max(info["max_node_dev_deg"], m.dev_deg)
            info["max_path_dev_mm"] = max(info["max_path_dev_mm"], m.path_dev_mm)
            info["max_path_dev_ratio"] = max(info["max_path_dev_ratio"], m.path_ratio)
            info["max_path_dev_rot_ratio"] = max(info["max_path_dev_rot_ratio"], m.rot_ratio)
            if not m.ok:
                if "outside_lines" not in info:
                    info["outside_lines"] = [int(where.line[m.i0 + 1]), int(where.line[m.i1])]
                info["within_tolerance"] = False
            info["segments_out"] += int(m.raw.coef.shape[0])
            info["paths"] += 1
            info["methods"] = sorted(methods)
            yield m.raw
        for cp in sub.curves:  # fitted: its exact evaluation is not needed again
            evals.pop(id(cp.curve), None)

    # what is fitted but not yet handed on, in path order: a batch with its kernels'
    # result (a future on the worker threads), or a sub-run for the Python fitter
    queue: deque = deque()
    pool = _fit_pool(threads) if batcher is not None and threads > 1 else None
    n_batches = 0  # batches in the queue

    def fit_python(sub: SubRun):
        yield from emit(sub, *_fit_sub_repaired(unblended, prb, sub, settings, evals, info, blend))

    def hand_on():
        nonlocal n_batches
        batch, got = queue.popleft()
        if batch is None:  # got: a sub-run the batch fitter does not cover
            yield from fit_python(got)
            return
        assert batcher is not None
        n_batches -= 1
        got = got.result() if pool is not None else got
        for (sub, _), m in zip(batch, batcher.collect(batch, got)):
            yield from (emit(sub, [m], prb) if m is not None else fit_python(sub))

    def launch():
        nonlocal n_batches
        assert batcher is not None
        batch = pending.copy()
        pending.clear()
        queue.append((batch, pool.submit(batcher.launch, batch) if pool is not None else batcher.launch(batch)))
        n_batches += 1
        # a few batches ahead per worker keep the workers busy while this thread hands on
        while n_batches > FIT_BATCHES_AHEAD * threads:
            yield from hand_on()

    try:
        c_pos = 0  # the sub-runs take the run's curves in order
        for sub in split_run(prb, settings, evals, arcs):
            if batcher is not None and batcher.covers(sub, c_pos):
                pending.append((sub, c_pos))
                c_pos += len(sub.curves)
                if len(pending) >= FIT_KERNEL_BATCH:
                    yield from launch()
                continue
            c_pos += len(sub.curves)
            if pending:
                yield from launch()
            if n_batches == 0:
                yield from fit_python(sub)
            else:
                queue.append((None, sub))
        if pending:
            yield from launch()
        while queue:
            yield from hand_on()
    finally:
        for batch, got in queue:  # abandoned (an error downstream): let the workers go
            if batch is not None and pool is not None:
                got.cancel()


#: sub-runs fitted per call of the compiled batch fitter (any value gives the same paths;
#: a batch's paths are handed on together)
FIT_KERNEL_BATCH = 32

#: batches queued per worker thread of the batch fitter: enough that a worker never waits
#: for the collecting thread, few enough that the fits held stay small (a batch ~100 kB)
FIT_BATCHES_AHEAD = 2

_pools: dict[int, ThreadPoolExecutor] = {}
_pools_lock = threading.Lock()


def _fit_pool(threads: int) -> ThreadPoolExecutor:
    """The process's worker threads for the batch fitter's kernels (made once per size)."""
    with _pools_lock:
        pool = _pools.get(threads)
        if pool is None:
            pool = _pools[threads] = ThreadPoolExecutor(threads, thread_name_prefix="cnc-fit")
        return pool


if hasattr(os, "register_at_fork"):
    # a forked child (a batch job) has none of its parent's threads, and the lock may be
    # held by one of them: the child starts with no pools
    os.register_at_fork(after_in_child=lambda: globals().update(_pools={}, _pools_lock=threading.Lock()))

#: nodes of a run from which the batch fitter's kernels are compiled when numba has not
#: cached them yet: they cost ~40 CPU-s to compile and save ~70 µs a node, so a shorter
#: run is fitted by the Python fitter (the same paths) until a long one has compiled them
FIT_KERNEL_COMPILE_NODES = 50_000

_kernels_ready = False


def _batch_kernels_ready(n_nodes: int) -> bool:
    """Whether the batch fitter fits a run of ``n_nodes`` (see FIT_KERNEL_COMPILE_NODES)."""
    global _kernels_ready
    if not _kernels_ready:
        from .._kernel_cache import missing_kernels

        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        _kernels_ready = n_nodes >= FIT_KERNEL_COMPILE_NODES or not missing_kernels(root, ("fit._subrun",))
    return _kernels_ready


class _SubRunBatcher:
    """The compiled batch fitter (``_subrun``) for one prepared run: the run's
    arrays once, each batch's arcs and sub-run table, and the results as ``_Measured``
    (None where the Python code must fit the sub-run: the kernel left it, or the
    measurement finds the fit outside its tolerance, which the Python code repairs)."""

    @staticmethod
    def covers_run(pr: PreparedRun, settings: FitSettings) -> bool:
        n = pr.nodes.shape[0]
        return settings.method == "nodes" and bool(np.all(pr.lin)) and n >= 2 and _batch_kernels_ready(n)

    def __init__(self, pr: PreparedRun, settings: FitSettings, arcs):
        from . import _subrun as sr
        from .curves import (
            _MIN_PIECE_SPEED,
            _MIN_SPEED,
            _PIECE_GL_W,
            _PIECE_GL_X,
            _SMALL_PIECE,
            CURVE_CHECK_POINTS,
            CURVE_MAX_DEPTH,
        )
        from .deviation import deviation_settings
        from .nodes import section_params
        from ..constants import FIT_TOL_SAFETY

        self.pr = pr
        self.weights = _weights(pr.lin, False)
        d = pr.nodes.shape[1]
        self.arcs = arcs if arcs is not None else arc_table((), d)
        self.arc_ok = self.arcs.ok.tolist()
        self.run = sr.RunArrays(
            np.ascontiguousarray(pr.nodes, dtype=float),
            np.ascontiguousarray(fit_tolerance(pr.tol_mm), dtype=float),
            np.ascontiguousarray(pr.line, dtype=np.int64),
            np.ascontiguousarray(pr.feed_mm_s, dtype=float),
        )
        bl = pr.blends
        if len(bl):
            self.blends = sr.BlendArrays(
                np.ascontiguousarray(bl.i, dtype=np.int64),
                np.ascontiguousarray(bl.h, dtype=float),
                np.ascontiguousarray(bl.coef, dtype=float),
                np.ascontiguousarray(bl.line, dtype=np.int64),
                np.ascontiguousarray(bl.feed_mm_s, dtype=float),
                np.ascontiguousarray(bl.t_in, dtype=float),
                np.ascontiguousarray(bl.t_out, dtype=float),
            )
        else:
            z = np.zeros(0)
            self.blends = sr.BlendArrays(
                np.zeros(0, dtype=np.int64),
                z,
                np.zeros((0, 6, d)),
                np.zeros(0, dtype=np.int64),
                z,
                np.zeros((0, d)),
                np.zeros((0, d)),
            )
        self.prm = sr.BatchParams(
            section_params(settings.fit_tol_deg, pr.lin, pr.lin, 0.0),
            sr.CurveParams(
                FIT_TOL_SAFETY,
                CURVE_CHECK_POINTS,
                CURVE_MAX_DEPTH,
                _MIN_SPEED,
                _MIN_PIECE_SPEED,
                _SMALL_PIECE,
                _PIECE_GL_X,
                _PIECE_GL_W,
            ),
            deviation_settings(),
        )

    def covers(self, sub: SubRun, c_pos: int) -> bool:
        """Whether the kernel fits ``sub`` (its curves from the run's ``c_pos``-th)."""
        if sub.kind != "fit" or sub.rotary:
            return False
        if not sub.curves:
            return sub.i1 - sub.i0 > 1
        return all(self.arc_ok[c_pos : c_pos + len(sub.curves)])

    def launch(self, batch: list[tuple[SubRun, int]]):
        """The kernels' ``BatchFits`` of the (sub-run, index of its first curve) pairs
        (they release the GIL, so batches may run on worker threads; they only read the
        run's arrays)."""
        from . import _subrun as sr

        table = sr.SubRunTable(
            np.array([sub.i0 for sub, _ in batch], dtype=np.int64),
            np.array([sub.i1 for sub, _ in batch], dtype=np.int64),
            np.array([sub.blend_range[0] for sub, _ in batch], dtype=np.int64),
            np.array([sub.blend_range[1] for sub, _ in batch], dtype=np.int64),
            np.array([c for _, c in batch], dtype=np.int64),
            np.array([c + len(sub.curves) for sub, c in batch], dtype=np.int64),
        )
        sections = sr.plan_sections(self.run, self.blends, self.arcs, table)
        polys = sr.fit_poly_sections(self.run, sections, self.prm)
        arcfits = sr.fit_arc_sections(self.run, self.arcs, sections, self.prm)
        return sr.join_and_measure(self.run, self.blends, self.arcs, table, sections, polys, arcfits, self.prm)

    def collect(self, batch: list[tuple[SubRun, int]], got) -> list:
        """The ``_Measured`` of each sub-run of ``batch`` from ``launch``'s ``BatchFits``,
        or None where the Python code must fit it."""
        pr = self.pr
        out: list = []
        so = got.seg_off.tolist()
        for s, (sub, _) in enumerate(batch):
            if got.status[s] != 0:
                out.append(None)
                continue
            pratio = float(got.pratio[s])
            ok = bool(got.fit_ok[s]) and max(pratio, 0.0) <= 1.0 + PATH_DEV_SLACK
            if not ok:
                out.append(None)
                continue
            q0, q1 = so[s], so[s + 1]
            raw = _Raw(
                pr.axes,
                got.breaks[q0 + s : q1 + s + 1],
                got.coef[q0:q1],
                got.line[q0:q1],
                got.feed[q0:q1],
                self.weights,
            )
            method = "curves+nodes" if sub.curves else "nodes"
            out.append(
                _Measured(
                    sub.i0,
                    sub.i1,
                    raw,
                    method,
                    float(got.dmm[s]),
                    float(got.ddeg[s]),
                    float(got.pdev[s]),
                    pratio,
                    0.0,
                    True,
                )
            )
        return out


def _fit_sub_repaired(
    unblended, prb: PreparedRun, sub: SubRun, settings: FitSettings, evals: dict, info: dict, blend: bool
) -> tuple[list, PreparedRun]:
    """Fit one sub-run of ``prb`` (the run ``unblended()`` with its corners blended); where the measurement
    finds it outside its tolerance, repair it on its own programmed nodes: blends (or,
    where a corner cannot be blended, stops) at nodes inside its failing sections, then
    refit, over ``FIT_REPAIR_ROUNDS`` rounds, the last forcing every node there.
    Returns (measured fits in path order, the prepared run their indices refer to)."""
    results, more = _fit_run_once(prb, [sub], settings, evals, info, 0)
    if not more.size:
        return results, prb
    # the sub-run's ends are cuts: programmed nodes, never inserted blend points
    first, last = int(prb.orig_index[sub.i0]), int(prb.orig_index[sub.i1])
    local = slice_run(unblended(), first, last)
    force = np.zeros(local.nodes.shape[0], dtype=bool)
    force[_original_index(prb, more) - first] = True
    lb = local
    for attempt in range(1, FIT_REPAIR_ROUNDS + 1):
        info["repaired"] = info.get("repaired", 0) + 1
        if blend:
            lb = add_blends(local, settings, evals, force=force)
        else:
            lb = replace(local, stops=np.nonzero(force)[0])
        results, more = _fit_run_once(lb, split_run(lb, settings, evals), settings, evals, info, attempt)
        if not more.size:
            break
        force[_original_index(lb, more)] = True
    info["repair_stops"] = info.get("repair_stops", 0) + int(lb.stops.size)
    return results, lb


def _original_index(prb: PreparedRun, idx: np.ndarray) -> np.ndarray:
    """Indices in the unblended run of nodes ``idx`` of ``prb`` (it with blend points
    inserted, which are never asked for: the nodes to force are programmed ones)."""
    return prb.orig_index[idx]


def _fit_run_once(pr: PreparedRun, subs: list[SubRun], settings: FitSettings, evals: dict, info: dict, attempt: int):
    """Fit sub-runs ``subs`` of a prepared run (repair round ``attempt``): (measured fits in
    path order, nodes of ``pr`` where the next round should put blends or stops; empty when
    all are within). In the last round a sub-run still outside becomes its exact moves."""
    last = attempt == FIT_REPAIR_ROUNDS
    results = []
    more = []
    lin_all, rot_all = _weights(pr.lin, False), _weights(pr.lin, True)
    for sub in subs:
        a, b = sub.i0, sub.i1
        if b - a == 1 and not sub.curves:
            # a single move: the exact line through its two nodes. Node and path deviation
            # are 0 by construction (the programmed path IS the fitted segment), so neither
            # the generic fitter nor the sampled path-deviation check is run for it.
            raw = _single_move_raw(pr, a, b, rot_all if sub.rotary else lin_all)
            results.append(_Measured(a, b, raw, "line", 0.0, 0.0, 0.0, 0.0, 0.0, True))
            continue
        m = _fit_measured(pr, sub, settings, evals)
        if not m.ok and not sub.curves:
            retry = _fit_measured(pr, sub, settings, evals, FIT_REPAIR_TOL_SHARE)
            if retry.ok:
                info["repaired"] = info.get("repaired", 0) + 1
                m = retry
        if not m.ok and not sub.curves:
            nodes = np.zeros(0, dtype=np.int64)
            if not last:
                nodes = _repair_nodes(pr, sub, m, settings, attempt == FIT_REPAIR_ROUNDS - 1)
            if nodes.size:
                more.append(nodes)
            else:
                # nothing left to blend: the moves themselves, exact lines with a stop at
                # each node, are within any tolerance (slower, but never outside the part)
                w = rot_all if sub.rotary else lin_all
                for j in range(a, b):
                    results.append(
                        _Measured(
                            j, j + 1, _single_move_raw(pr, j, j + 1, w), "line-fallback", 0.0, 0.0, 0.0, 0.0, 0.0, True
                        )
                    )
                info["fallback_lines"] = info.get("fallback_lines", []) + [int(pr.line[a + 1]), int(pr.line[b])]
                continue
        results.append(m)
    more = np.unique(np.concatenate(more)) if more else np.zeros(0, dtype=np.int64)
    return results, more


def _repair_nodes(pr: PreparedRun, sub: SubRun, m: "_Measured", settings: FitSettings, every: bool) -> np.ndarray:
    """Programmed nodes of a failing sub-run to blend (or stop at) in the next round: in
    every polyline section the measurement finds outside (all of them if none alone is),
    ``FIT_REPAIR_SPLITS`` nodes spread over it, or with ``every`` all its nodes."""
    sections = m.raw.sections or [("poly", sub.i0, sub.i1, 0, m.raw.coef.shape[0])]
    polys = [sec for sec in sections if sec[0] == "poly" and sec[2] - sec[1] >= 2]
    bad = [sec for sec in polys if not _section_ok(pr, sub, m.raw, sec, settings)]
    if not bad:
        bad = polys
    out = []
    inserted = pr.orig_index < 0
    for _, i, j, _, _ in bad:
        inner = np.arange(i + 1, j)
        inner = inner[~inserted[inner]]
        if inner.size == 0:
            continue
        if not every and inner.size > FIT_REPAIR_SPLITS:
            pick = np.linspace(0, inner.size - 1, FIT_REPAIR_SPLITS + 2)[1:-1]
            inner = inner[np.unique(np.rint(pick).astype(np.int64))]
        out.append(inner)
    return np.concatenate(out) if out else np.zeros(0, dtype=np.int64)


def _section_ok(pr: PreparedRun, sub: SubRun, raw: _Raw, sec, settings: FitSettings) -> bool:
    """The measurement of one polyline section against its own fitted segments."""
    _, i, j, k0, k1 = sec
    breaks = raw.breaks[k0 : k1 + 1] - raw.breaks[k0]
    coef = raw.coef[k0:k1]
    nodes = pr.nodes[i : j + 1]
    tol = fit_tolerance(pr.tol_mm[i : j + 1])
    measured = pr.lin if not sub.rotary else np.zeros_like(pr.lin)
    _, ratio = polyline_deviation(breaks, coef, nodes, tol, measured)
    moving = np.ptp(nodes, axis=0) > 0
    if (moving & ~pr.lin).any():
        # in the sub-run's rotary scale (its largest tolerance), as the whole measurement
        tol_ref = float(np.max(fit_tolerance(pr.tol_mm[sub.i0 : sub.i1 + 1])))
        ratio = max(
            ratio,
            rotary_path_deviation(breaks, coef, nodes, tol, settings.fit_tol_deg, pr.lin, moving, tol_ref=tol_ref),
        )
    return ratio <= 1.0 + PATH_DEV_SLACK


@dataclass
class _Measured:
    """One fitted sub-run (nodes i0..i1) and its independently measured deviations."""

    i0: int
    i1: int
    raw: _Raw
    method: str
    dev_mm: float
    dev_deg: float
    path_dev_mm: float
    path_ratio: float
    rot_ratio: float
    ok: bool


def _fit_measured(
    pr: PreparedRun, sub: SubRun, settings: FitSettings, evals: dict, tol_share: float = 1.0
) -> _Measured:
    """Fit a sub-run (to ``tol_share`` of its tolerance) and measure the programmed path
    (moves and exact curves) against the fit everywhere."""
    a, b = sub.i0, sub.i1
    raw, meth, dmm, ddeg, ok = _fit_sub(pr, sub, settings, evals, tol_share)
    measured = pr.lin if not sub.rotary else np.zeros_like(pr.lin)  # rotary-only: no linear axis
    tol_sub = fit_tolerance(pr.tol_mm[a : b + 1])
    if sub.curves:
        pdev, pratio = path_deviation(raw.breaks, raw.coef, pr.nodes[a : b + 1], tol_sub, measured, sub.curves, a)
    else:
        pdev, pratio = polyline_deviation(raw.breaks, raw.coef, pr.nodes[a : b + 1], tol_sub, measured)
    # where rotary axes move: position and orientation at one point of the fit
    moving = np.ptp(pr.nodes[a : b + 1], axis=0) > 0
    rratio = 0.0
    if (moving & ~pr.lin).any():
        rratio = rotary_path_deviation(
            raw.breaks, raw.coef, pr.nodes[a : b + 1], tol_sub, settings.fit_tol_deg, pr.lin, moving, sub.curves, a
        )
    sub_ok = bool(ok) and max(pratio, rratio) <= 1.0 + PATH_DEV_SLACK
    return _Measured(a, b, raw, meth, dmm, ddeg, pdev, pratio, rratio, sub_ok)


def _single_move_raw(pr: PreparedRun, a: int, b: int, weights: np.ndarray) -> _Raw:
    """The exact straight path of the move from node a to node b = a + 1 (the same
    arithmetic as ``straight_piece`` on the sub-run, without its generic machinery)."""
    p0, p1 = pr.nodes[a], pr.nodes[b]
    d = p1 - p0
    length = float(np.linalg.norm(d * pr.scale))
    coef = np.zeros((1, 6, p0.shape[0]))
    coef[0, 0] = p0
    coef[0, 1] = d / length
    # (line/feed/weights may be views: _build_paths copies them into the Path)
    return _Raw(pr.axes, np.array([0.0, length]), coef, pr.line[b : b + 1], pr.feed_mm_s[b : b + 1], weights)


def _rapid_raws(run: Run, lin: np.ndarray) -> list[_Raw]:
    """One straight rapid path per G0 move, or per chain of consecutive G0 moves along the
    same line in the same direction (each move of a chain keeps its feed: a rapid's feed
    is infinite, the axes' own limits, or the machine's path speed cap). A chain does not
    stop where one move ends and the next goes on straight."""
    out = []
    nodes = np.asarray(run.nodes, dtype=float)
    feeds = np.asarray(run.feed_mm_s, dtype=float)
    chain: list[tuple[int, float]] = []  # the chain's moves: (end j of nodes j-1 -> j, length)
    chain_dir = None
    chain_rotary = False

    def flush() -> None:
        if not chain:
            return
        a, b = chain[0][0] - 1, chain[-1][0]
        if len(chain) == 1:
            pf = straight_piece(nodes[a], nodes[b], chain[0][1], int(run.line[b]), float(feeds[b]))
            breaks, coef, seg_line, seg_feed = pf.breaks, pf.coef, pf.line, pf.feed_mm_s
        else:
            scale = (~lin if chain_rotary else lin).astype(float)
            breaks, coef, seg_line, seg_feed = _straight_chain(
                nodes[a : b + 1], run.line[a : b + 1], feeds[a : b + 1], scale
            )
        out.append(_Raw(run.axes, breaks, coef, seg_line, seg_feed, _weights(lin, chain_rotary), rapid=True))
        _snap_end(out[-1], nodes[b])
        chain.clear()

    for j in range(1, nodes.shape[0]):
        d = nodes[j] - nodes[j - 1]
        length, rotary = _rapid_move(d, lin)
        if not length > 0:
            flush()
            continue
        direction = d / length
        if not (chain and rotary == chain_rotary and _same_line(direction, chain_dir)):
            flush()
            chain_dir, chain_rotary = direction, rotary
        chain.append((j, length))
    flush()
    return out


def _snap_end(raw: _Raw, target: np.ndarray) -> None:
    """Make ``raw`` end on ``target`` (its programmed end point), in place, when rounding
    left it off by at most ``FIT_END_SNAP_MAX_REL`` of its last segment: the gap d is
    added to that segment as d (10x³ - 15x⁴ + 6x⁵), x = τ/h, which is 0 with its first
    and second derivatives at τ = 0 and d, 0, 0 at τ = h (the path stays G2; no point
    moves by more than |d|). Paths that carry paper 000's planar form are left alone
    (the FPGA stage evaluates that form)."""
    if raw.planar is not None or raw.coef.shape[0] == 0:
        return
    h = float(raw.breaks[-1] - raw.breaks[-2])
    c = raw.coef[-1]
    end = c[5] * 1.0
    for i in range(4, -1, -1):  # Path.end's arithmetic
        end = end * h + c[i]
    gap = np.asarray(target, dtype=float) - end
    if not gap.any() or not (h > 0 and np.abs(gap).max() <= FIT_END_SNAP_MAX_REL * h):
        return
    coef = raw.coef.copy()
    coef[-1, 3] += 10.0 * gap / h**3
    coef[-1, 4] -= 15.0 * gap / h**4
    coef[-1, 5] += 6.0 * gap / h**5
    raw.coef = coef


def _fit_sub(pr: PreparedRun, sub: SubRun, settings: FitSettings, evals: dict | None = None, tol_share: float = 1.0):
    """Fit one sub-run: (raw path, method name, max dev mm, max dev deg, ok); the fitters
    aim at ``tol_share`` of the tolerance (a repair's retry)."""
    a, b = sub.i0, sub.i1
    nodes = pr.nodes[a : b + 1]
    line = pr.line[a : b + 1]
    feed = pr.feed_mm_s[a : b + 1]
    weights = _weights(pr.lin, sub.rotary)
    metric = weights > 0
    if sub.kind == "straight" or (b - a == 1 and not sub.curves):
        # collinear G61 chain: the straight line from the first to the last node, with a
        # segment boundary wherever the programmed feed changes (each move keeps its F)
        breaks, coef, seg_line, seg_feed = _straight_chain(nodes, line, feed, pr.scale)
        dev = _line_dev(nodes, pr.lin)
        raw = _Raw(pr.axes, breaks, coef, seg_line, seg_feed, weights)
        return raw, "line", dev, 0.0, True
    tol = fit_tolerance(pr.tol_mm[a : b + 1])
    tol_fit = tol * tol_share
    moving = np.ptp(nodes, axis=0) > 0
    if (
        not sub.curves
        and settings.method in ("auto", "planar")
        and int(moving.sum()) == 2
        and bool(np.all(pr.lin[moving]))
    ):
        from .planar import breaks_of, fit_planar

        plane = tuple(int(i) for i in np.nonzero(moving)[0])
        got = fit_planar(nodes, plane, tol_fit, pr.axes, line, feed, weights)
        if got is not None:
            planar, coef, seg_line, seg_feed, dev = got
            raw = _Raw(pr.axes, breaks_of(planar), coef, seg_line, seg_feed, weights, planar=planar)
            return raw, "planar-" + pr.axes[plane[0]] + pr.axes[plane[1]], dev, 0.0, True
    pieces, dmm, ddeg, ok, spans = _fit_sections(pr, sub, tol, metric, settings, evals, tol_fit)
    breaks = [np.zeros(1)]
    off = 0.0
    for pf in pieces:
        breaks.append(pf.breaks[1:] + off)
        off += pf.breaks[-1]
    raw = _Raw(
        pr.axes,
        np.concatenate(breaks),
        np.concatenate([p.coef for p in pieces]),
        np.concatenate([p.line for p in pieces]),
        np.concatenate([p.feed_mm_s for p in pieces]),
        weights,
    )
    seg0 = np.concatenate(([0], np.cumsum([p.coef.shape[0] for p in pieces])))
    raw.sections = [(kind, i, j, int(seg0[k]), int(seg0[k + 1])) for k, (kind, i, j) in enumerate(spans)]
    return raw, ("curves+nodes" if sub.curves else "nodes"), dmm, ddeg, ok


def _straight_chain(nodes: np.ndarray, line: np.ndarray, feed: np.ndarray, scale: np.ndarray):
    """The straight line nodes[0] -> nodes[-1] of a collinear chain (n, d) as one segment per
    run of equal feeds: breaks (K+1,), coef (K, 6, d), line (K,), feed (K,). A boundary
    sits at the projection onto the line of each node where the feed changes (the
    chain's nodes lie on it within ``FIT_COLLINEAR_DEG``)."""
    n, d = nodes.shape
    chord = (nodes[-1] - nodes[0]) * scale
    length = float(np.linalg.norm(chord))
    f = np.asarray(feed, dtype=float)
    brk = np.nonzero(f[1:-1] != f[2:])[0] + 1 if n > 2 else np.zeros(0, dtype=np.int64)
    direction = chord / length
    pos = np.clip(((nodes[brk] - nodes[0]) * scale) @ direction, 0.0, length)
    # (collinear forward moves project in order; a break that would give an empty
    # segment is dropped and its moves merge with the next ones)
    ok = (pos > 0) & (pos < length) & np.concatenate(([True], np.diff(pos) > 0))
    u = np.concatenate(([0.0], pos[ok], [length]))
    ends = np.concatenate((brk[ok], [n - 1]))
    k = u.size - 1
    coef = np.zeros((k, 6, d))
    step = (nodes[-1] - nodes[0]) / length
    coef[:, 0] = nodes[0] + u[:-1, None] * step
    coef[0, 0] = nodes[0]
    coef[:, 1] = step
    starts = np.concatenate(([0], ends[:-1]))
    seg_feed = np.array([f[a + 1 : b + 1].min() for a, b in zip(starts, ends)])
    return u, coef, np.asarray(line)[ends], seg_feed


def _line_dev(nodes: np.ndarray, lin: np.ndarray) -> float:
    """Largest distance (linear axes) of the nodes from the chord first -> last."""
    p = nodes[:, lin]
    if p.shape[0] <= 2 or p.shape[1] == 0:
        return 0.0
    d = p[-1] - p[0]
    L2 = float(d @ d)
    if L2 == 0:
        return float(np.linalg.norm(p - p[0], axis=1).max())
    t = np.clip((p - p[0]) @ d / L2, 0, 1)
    return float(np.linalg.norm(p - (p[0] + t[:, None] * d), axis=1).max())


def _fit_sections(
    pr: PreparedRun,
    sub: SubRun,
    tol: np.ndarray,
    metric: np.ndarray,
    settings: FitSettings,
    evals: dict | None = None,
    tol_fit: np.ndarray | None = None,
):
    """Curves, corner blends and the polylines between them, joined G2 (see module
    docstring): a polyline next to a curve or blend takes its exact tangent and
    curvature vector at the junction, two curves meet at their averaged tangent and
    curvature, and a straight move between two blends is the exact line."""
    from .curves import curve_eval, end_states, fit_curve
    from .nodes import PieceFit

    a, b = sub.i0, sub.i1
    # the rotary axes' metric scale tol_ref / tol_deg: the sub-run's largest tolerance,
    # as in the measurement (``rotary_path_deviation``), so that a fit within the scaled
    # Euclidean tolerance is within both tolerances at the measured foot points; every
    # imposed end state is expressed in it
    tol_ref = float(np.max(tol))
    scale = np.where(pr.lin, 1.0, tol_ref / settings.fit_tol_deg)
    if tol_fit is not None:  # a repair's retry aims below the tolerance
        tol = tol_fit
    items = sorted(
        [(cp.first, cp.last, "curve", cp) for cp in sub.curves] + [(bl.i, bl.i + 2, "blend", bl) for bl in sub.blends],
        key=lambda x: x[0],
    )
    secs = []  # ("poly", i, j), ("curve", CurvePiece) or ("blend", Blend)
    pos = a
    for first, last, kind, obj in items:
        if first > pos:
            secs.append(("poly", pos, first))
        secs.append((kind, obj))
        pos = last
    if pos < b:
        secs.append(("poly", pos, b))
    # exact end states of the curves and blends, then the states imposed at each junction
    evs = [curve_eval(s_[1].curve, evals) if s_[0] == "curve" else None for s_ in secs]
    states = []
    zero = np.zeros(scale.size)
    same = bool(np.array_equal(scale, pr.scale))  # always without rotary axes
    for s_, ev in zip(secs, evs):
        if ev is not None:
            states.append(end_states(ev, scale))
        elif s_[0] == "blend":
            bl = s_[1]
            if same:
                states.append(((bl.t_in, zero), (bl.t_out, zero)))
            else:
                t0, t1 = (_unit(t / pr.scale * scale) for t in (bl.t_in, bl.t_out))
                states.append(((t0, zero), (t1, zero)))
        else:
            states.append(None)
    start_of = [None] * len(secs)
    end_of = [None] * len(secs)
    for k in range(len(secs) - 1):
        ca, cb = secs[k][0] != "poly", secs[k + 1][0] != "poly"
        if ca and cb:
            (t1, k1), (t2, k2) = states[k][1], states[k + 1][0]
            T = t1 + t2
            T = T / np.linalg.norm(T)
            K = 0.5 * (k1 + k2)
            K = K - (K @ T) * T
            end_of[k] = (T, K)
            start_of[k + 1] = (T, K)
        elif ca:
            T, K = states[k][1]
            start_of[k + 1] = (T, K)
        elif cb:
            T, K = states[k + 1][0]
            end_of[k] = (T, K)
    pieces = []
    dmm = ddeg = 0.0
    ok = True
    for k, s_ in enumerate(secs):
        if s_[0] == "curve":
            cp = s_[1]
            t_c = float(tol[cp.last - a])
            pf = fit_curve(
                evs[k],
                scale,
                pr.lin,
                t_c,
                settings.fit_tol_deg,
                cp.curve.line,
                float(pr.feed_mm_s[cp.last]),
                start=start_of[k],
                end=end_of[k],
            )
        elif s_[0] == "blend":
            bl = s_[1]
            pf = PieceFit(
                np.array([0.0, bl.h]), bl.coef[None], np.array([bl.line]), np.array([bl.feed_mm_s]), 0.0, 0.0, True, 3
            )
        else:
            i, j = s_[1], s_[2]
            free_or_blend = (start_of[k] is None or secs[k - 1][0] == "blend") and (
                end_of[k] is None or secs[k + 1][0] == "blend"
            )
            if j == i + 1 and free_or_blend:
                # a move between blends (or a blend and the path's end): the move itself,
                # G2 with the blends (their ends lie on it, tangent, with zero curvature)
                length = float(np.linalg.norm((pr.nodes[j] - pr.nodes[i]) * pr.scale))
                pf = straight_piece(pr.nodes[i], pr.nodes[j], length, int(pr.line[j]), float(pr.feed_mm_s[j]))
            else:
                st = EndState(*start_of[k]) if start_of[k] is not None else None
                en = EndState(*end_of[k]) if end_of[k] is not None else None
                pf = fit_polyline(
                    pr.nodes[i : j + 1],
                    tol[i - a : j - a + 1],
                    settings.fit_tol_deg,
                    pr.lin,
                    metric,
                    pr.line[i : j + 1],
                    pr.feed_mm_s[i : j + 1],
                    tol_ref,
                    st,
                    en,
                )
        pieces.append(pf)
        dmm = max(dmm, pf.max_dev_mm)
        ddeg = max(ddeg, pf.max_dev_deg)
        ok &= pf.ok
    spans = []
    for s_ in secs:
        if s_[0] == "poly":
            spans.append(s_)
        elif s_[0] == "curve":
            spans.append(("curve", s_[1].first, s_[1].last))
        else:
            spans.append(("blend", s_[1].i, s_[1].i + 2))
    return pieces, dmm, ddeg, ok, spans


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)

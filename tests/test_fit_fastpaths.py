"""The fit stage's per-path fast paths give exactly what the generic machinery gives.

* ``_build_paths`` (chaining and arc-length tables of a whole run in compiled calls)
  against ``_Raw.build`` + ``Path.end`` path by path;
* ``polyline_path_deviation`` (one compiled call) against ``deviation.path_deviation``;
* single moves (no fitter, no sampled deviation check) against the exact line.

The fits here stop at sharp corners (``blend_corners=False``): the single-move machinery
serves the corners that cannot be blended.
"""

from __future__ import annotations

import numpy as np
import pytest

from cnc_interp.fit.deviation import PATH_DEV_FAR_WINDOW
from cnc_interp.fit.deviation import PATH_DEV_WINDOW
from cnc_interp.fit.deviation import PATH_DEV_LOCAL_FRAC
from cnc_interp.fit.deviation import PATH_DEV_NEWTON_ITERS
from cnc_interp.fit.deviation import PATH_DEV_FIT_SAMPLES
from cnc_interp.fit.deviation import PATH_DEV_MAX_SAMPLES
from cnc_interp.fit.deviation import PATH_DEV_MIN_SAMPLES
from cnc_interp.fit.deviation import PATH_DEV_SAMPLES_PER_SPAN
from cnc_interp.fit import FitSettings, Path, fit_program
from cnc_interp.fit._linedev import DeviationSettings, polyline_path_deviation
from cnc_interp.fit.deviation import path_deviation
from cnc_interp.fit.fitter import _build_paths, _fit_run_raw
from cnc_interp.gcode.program import Program, Run, Stop


def _run(nodes, axes="XYZ", kind="feed"):
    nodes = np.asarray(nodes, float)
    n = nodes.shape[0]
    return Run(
        kind,
        axes,
        nodes,
        np.arange(1, n + 1),
        np.ones(n, int),
        np.full(n, np.inf if kind == "rapid" else 20.0),
        np.full(n, np.nan),
        np.full(n, np.nan),
    )


def _zigzag(seed, n=40):
    """Random polyline with sharp corners (many single moves) and smooth stretches."""
    rng = np.random.default_rng(seed)
    a = np.cumsum(rng.uniform(-0.3, 0.3, n))
    a[rng.integers(1, n - 1, n // 4)] += np.pi * 0.8  # sharp corners
    step = rng.uniform(0.05, 2.0, n)
    xy = np.cumsum(np.stack([step * np.cos(a), step * np.sin(a)], axis=1), axis=0)
    z = np.cumsum(rng.choice([0.0, 0.0, 0.1], n))
    return np.column_stack([xy + 100.0, z])


def _same_path(p: Path, q: Path):
    for name in ("breaks", "coef", "line", "feed_mm_s", "weights", "s_breaks", "_sub_u", "_sub_s", "_sub_seg"):
        np.testing.assert_array_equal(getattr(p, name), getattr(q, name), err_msg=name)
    assert p.length == q.length and p.rapid == q.rapid and p.axes == q.axes
    assert (p.planar is None) == (q.planar is None)
    if p.planar is not None:
        for name in ("theta", "origin", "x_end", "p"):
            np.testing.assert_array_equal(getattr(p.planar, name), getattr(q.planar, name))
    np.testing.assert_array_equal(p.end, q.end)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("start", [None, "shifted"])
def test_build_paths_equals_path_by_path_build(seed, start):
    run = _run(_zigzag(seed))
    raws, _ = _fit_run_raw(run, FitSettings(blend_corners=False))
    assert len(raws) > 3
    s0 = None if start is None else run.nodes[0] + 1e-7
    got, end = _build_paths(raws, s0)
    prev = s0
    for raw, p in zip(raws, got):
        q = raw.build(prev)
        _same_path(p, q)
        prev = q.end
    np.testing.assert_array_equal(end, prev)
    # the rapids too, and an empty run keeps the start
    rap = _run(_zigzag(seed, 8), kind="rapid")
    raws, _ = _fit_run_raw(rap, FitSettings(blend_corners=False))
    got, _ = _build_paths(raws, None)
    prev = None
    for raw, p in zip(raws, got):
        q = raw.build(prev)
        _same_path(p, q)
        prev = q.end
    assert _build_paths([], s0)[1] is s0


def test_build_paths_rejects_bad_breaks_like_path():
    raws, _ = _fit_run_raw(_run(_zigzag(1)), FitSettings(blend_corners=False))
    raws[1].breaks = raws[1].breaks[::-1].copy()
    with pytest.raises(ValueError):
        _build_paths(raws, None)


@pytest.mark.parametrize("seed", range(8))
def test_compiled_polyline_deviation_equals_path_deviation(seed):
    rng = np.random.default_rng(100 + seed)
    nodes = _zigzag(seed, 12)[:, : 2 + seed % 2]
    nodes = np.ascontiguousarray(nodes)
    d = nodes.shape[1]
    # a perturbed piecewise quintic along the polyline: nonzero distances everywhere
    S = 5
    breaks = np.concatenate(([0.0], np.cumsum(rng.uniform(0.5, 3.0, S))))
    coef = rng.normal(0.0, 0.02, (S, 6, d))
    pts = nodes[np.linspace(0, nodes.shape[0] - 1, S + 1).astype(int)]
    for k in range(S):
        h = breaks[k + 1] - breaks[k]
        coef[k, 0] = pts[k]
        coef[k, 1] = (pts[k + 1] - pts[k]) / h
        coef[k, 2:] /= h ** np.arange(2, 6)[:, None]
    tol = rng.uniform(1e-3, 1e-2, nodes.shape[0])
    lin = np.ones(d, dtype=bool)
    if seed % 3 == 0:
        lin[-1] = False
    want = path_deviation(breaks, coef, nodes, tol, lin)
    cfg = DeviationSettings(
        PATH_DEV_SAMPLES_PER_SPAN,
        PATH_DEV_MIN_SAMPLES,
        PATH_DEV_MAX_SAMPLES,
        PATH_DEV_LOCAL_FRAC,
        PATH_DEV_WINDOW,
        PATH_DEV_FAR_WINDOW,
        PATH_DEV_FIT_SAMPLES,
        PATH_DEV_NEWTON_ITERS,
    )
    got = polyline_path_deviation(breaks, coef, nodes, tol, lin, cfg)
    assert want[0] > 0
    assert got == want
    assert polyline_path_deviation(breaks, coef, nodes, tol, np.zeros(d, dtype=bool), cfg) == (0.0, 0.0)


def test_single_moves_are_exact_lines_with_zero_deviation():
    # a square: four sharp corners, every side a single move
    sq = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0], [0, 0, 0]], float) + 1000.0
    res = fit_program(
        Program("sq", "XYZ", (_run(sq), Stop(5, "M2", sq[-1])), sq[0], 6), FitSettings(blend_corners=False)
    )
    paths = res.paths
    assert len(paths) == 4
    for k, p in enumerate(paths):
        assert p.n_seg == 1
        np.testing.assert_array_equal(p.start, sq[k])
        np.testing.assert_allclose(p.end, sq[k + 1], rtol=0, atol=1e-12)
        np.testing.assert_allclose(p.length, 10.0, rtol=1e-15)
        np.testing.assert_allclose(p(np.array([2.5]))[0], sq[k] + 0.25 * (sq[k + 1] - sq[k]), atol=1e-12)
    st = res.stats
    assert st["within_tolerance"] and st["max_path_dev_mm"] == 0.0 and st["segments_out"] == 4
    assert st["runs"][0]["methods"] == ["line"]

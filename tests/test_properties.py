"""Property tests (hypothesis): for any program of the kinds generated, the parse keeps the
numbers written, the fit stays within its tolerance, and every planner's samples keep every
limit with nothing NaN. Examples are few and derandomized so the suite stays reproducible;
``HYPOTHESIS_PROFILE=long`` runs many more."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

import cnc_interp as ci

settings.register_profile(
    "ci", max_examples=12, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
settings.register_profile("long", max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

coord = st.decimals(min_value=-200, max_value=200, places=3, allow_nan=False, allow_infinity=False)
moves = st.lists(st.tuples(coord, coord, coord), min_size=1, max_size=12)


def _program(points, feed_mm_min: int, inch: bool = False) -> str:
    lines = ["G20" if inch else "G21", "G90 G94", f"F{feed_mm_min}"]
    lines += [f"G1 X{x} Y{y} Z{z}" for x, y, z in points]
    return "\n".join(lines + ["M2"]) + "\n"


@given(moves, st.booleans())
def test_parse_keeps_the_coordinates_written(points, inch):
    prog = ci.read_program(_program(points, 600, inch), machine="generic-mill")
    nodes = np.concatenate([r.nodes[1:] for r in prog.runs if r.kind != "rapid"]) if prog.runs else np.zeros((0, 3))
    # zero-length moves are dropped: compare the distinct consecutive targets
    want = [np.array([float(v) for v in p]) * (25.4 if inch else 1.0) for p in points]
    dedup = []
    prev = np.zeros(3)
    for w in want:
        if not np.array_equal(w, prev):
            dedup.append(w)
        prev = w
    assert nodes.shape == (len(dedup), 3)
    if dedup:
        assert_allclose(nodes, np.array(dedup), rtol=0, atol=1e-9)


def _wiggle(seed: int, n: int, step_mm: float, turn_deg: float) -> list[tuple[float, float, float]]:
    rng = np.random.default_rng(seed)
    heading = np.cumsum(np.radians(rng.uniform(-turn_deg, turn_deg, n)))
    xy = np.cumsum(np.stack([np.cos(heading), np.sin(heading)], axis=1) * step_mm, axis=0)
    z = np.cumsum(rng.normal(0, step_mm * 0.05, n))
    return [(round(x, 4), round(y, 4), round(zz, 4)) for (x, y), zz in zip(xy, z)]


@given(
    st.integers(0, 10_000),
    st.integers(3, 60),
    st.floats(0.05, 5.0),
    st.floats(1.0, 120.0),
    st.sampled_from([0.001, 0.005, 0.02]),
)
def test_the_fit_stays_within_its_tolerance(seed, n, step_mm, turn_deg, tol_mm):
    pts = _wiggle(seed, n, step_mm, turn_deg)
    text = "G21 G90\nF3000\n" + "".join(f"G1 X{x} Y{y} Z{z}\n" for x, y, z in pts) + "M2\n"
    res = ci.fit(ci.read_program(text, machine="generic-mill"), tol_mm=tol_mm)
    stats = res.stats
    assert stats["within_tolerance"]
    assert stats["max_path_dev_ratio"] <= 1 + 1e-9
    for path in res.paths:
        assert np.all(np.isfinite(path.coef))


limit = st.floats(0.5, 2.0)


@pytest.mark.parametrize("planner", ["optimal", "vpop", "constant", "variable"])
@given(st.integers(0, 10_000), st.integers(2, 15), limit, limit, limit, st.sampled_from([0.001, 0.002, 0.006]))
def test_every_planner_keeps_every_limit(planner, seed, n, kv, ka, kj, dt_s):
    base = ci.load_machine("generic-mill")
    from dataclasses import replace

    m = replace(base, vmax=base.vmax * kv, amax=base.amax * ka, jmax=base.jmax * kj, dt_s=dt_s)
    pts = _wiggle(seed, n, 3.0, 60.0)
    text = "G21 G90\nF6000\n" + "".join(f"G1 X{x} Y{y} Z{z}\n" for x, y, z in pts) + "M2\n"
    res = ci.run(text, m, planner=planner, check=False)
    q = res.trajectory.q
    assert np.all(np.isfinite(q)) and q.shape[0] > 1
    assert res.report.worst_ratio <= 1 + 1e-9, res.report.worst()
    # exact end point (at rest: verify pads the end with it and still finds every limit held)
    assert_allclose(q[-1], np.array(pts[-1]), rtol=0, atol=1e-9)

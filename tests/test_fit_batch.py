"""The compiled batch fitter (``fit._subrun``, ``fit._section``) gives exactly the Python fit.

The fit of a run on linear axes is done for batches of sub-runs in compiled code; the
Python fitter (``fitter._fit_sub_repaired``) still serves everything else and every
repair, and both must give the same bits. ``_npexact`` reproduces numpy's summation,
BLAS's dot product and numpy's vector powers: each is checked against numpy here.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from .conftest import CORPUS, needs_corpus
from cnc_interp.fit import FitSettings, Path, fit_program
from cnc_interp.fit._npexact import (
    arc_terms,
    blas_dot,
    cube,
    hermite_powers,
    pairwise_sum,
    powers345,
    weighted_rows,
)
from cnc_interp.gcode import read_program


def test_pairwise_sum_is_numpys_sum():
    rng = np.random.default_rng(1)
    for n in list(range(0, 300)) + [1000, 4097, 8192, 8193, 30000]:
        a = rng.standard_normal(n) * 10.0 ** rng.uniform(-8, 8, n)
        assert 0.0 + pairwise_sum(a, 0, n) == a.sum(), n
    x = rng.standard_normal((40, 9)) * 10.0 ** rng.uniform(-8, 8, (40, 9))
    for d in range(1, 10):
        rows = np.ascontiguousarray(x[:, :d])
        want = rows.sum(axis=1)
        assert all(0.0 + pairwise_sum(rows[i].copy(), 0, d) == want[i] for i in range(40))


def test_blas_dot_is_numpys_dot_and_norm():
    rng = np.random.default_rng(2)
    for d in range(1, 10):
        for _ in range(2000):
            x = rng.standard_normal(d) * 10.0 ** rng.uniform(-6, 6, d)
            y = rng.standard_normal(d) * 10.0 ** rng.uniform(-6, 6, d)
            assert blas_dot(x, y) == x @ y
            assert np.sqrt(blas_dot(x, x)) == np.linalg.norm(x)


def test_kernel_powers_and_arc_terms_are_the_python_fitters():
    # the compiled fitter and the Python fitter must give the same bits: both take the
    # powers by products and the quadrature left to right (numpy's vector pow and BLAS
    # would differ in the last bit); and these are the powers, to rounding
    rng = np.random.default_rng(3)
    h = rng.uniform(1e-6, 10.0, 5000)
    p3, p4, p5 = powers345(h)
    for got, want, k in zip((p3, p4, p5), hermite_powers(h), (3, 4, 5)):
        np.testing.assert_array_equal(got, want)
        np.testing.assert_allclose(got, h**k, rtol=4e-16 * k, atol=0)
    sp = rng.uniform(0.1, 3.0, (37, 8))
    w = np.polynomial.legendre.leggauss(8)[1]
    s3, quad = arc_terms(h[:37].copy(), sp, w)
    np.testing.assert_array_equal(s3, cube(h[:37]))
    np.testing.assert_array_equal(quad, weighted_rows(sp, w))
    np.testing.assert_allclose(s3, h[:37] ** 3, rtol=1e-15, atol=0)
    np.testing.assert_allclose(quad, sp @ w, rtol=1e-14, atol=0)


def _mixed_program() -> str:
    """Polylines with gentle and sharp (blended) corners, feed changes inside a
    polyline, G17 / G18 arcs and a helix, arcs meeting arcs and lines, far from the origin."""
    rng = np.random.default_rng(7)
    out = ["G21 G90 G64 P0.01", "G0 X100 Y200 Z5", "G1 Z0 F1200"]
    x, y = 100.0, 200.0
    for k in range(12):
        for _ in range(int(rng.integers(3, 25))):
            a = rng.uniform(-0.4, 0.4) + (k % 4) * np.pi / 2
            x, y = x + rng.uniform(0.05, 1.5) * np.cos(a), y + rng.uniform(0.05, 1.5) * np.sin(a)
            f = " F900" if rng.random() < 0.1 else ""
            out.append(f"G1 X{x:.4f} Y{y:.4f}{f}")
        r = rng.uniform(0.5, 5.0)
        if k % 3 == 0:
            out.append(f"G2 X{x + 2 * r:.4f} Y{y:.4f} I{r:.4f} J0")
            out.append(f"G3 X{x + 4 * r:.4f} Y{y:.4f} I{r:.4f} J0")
            x += 4 * r
        elif k % 3 == 1:
            out.append(f"G3 X{x:.4f} Y{y + 2 * r:.4f} Z-0.5 I0 J{r:.4f}")
            out.append("G1 Z0")
            y += 2 * r
        else:
            out += ["G18", f"G2 X{x + 2 * r:.4f} Z0 I{r:.4f} K0", "G17"]
            x += 2 * r
    out.append("M2")
    return "\n".join(out) + "\n"


def _excerpt(name: str, lines: int) -> bytes:
    with open(os.path.join(CORPUS, name), "rb") as fh:
        text = fh.read().split(b"\n")
    return b"\n".join(text[:lines] + [b"M2", b""])


def _same_fit(a, b):
    pa = [p for p in a.items if isinstance(p, Path)]
    pb = [p for p in b.items if isinstance(p, Path)]
    assert len(pa) == len(pb)
    for p, q in zip(pa, pb):
        for name in ("breaks", "coef", "line", "feed_mm_s", "weights", "s_breaks"):
            np.testing.assert_array_equal(getattr(p, name), getattr(q, name), err_msg=name)
    sa, sb = dict(a.stats), dict(b.stats)
    for s in (sa, sb):
        for run in s["runs"]:
            run.pop("repaired", None)  # the Python fit counts the repairs it attempts
    assert sa == sb


def _program(case):
    if case == "mixed":
        return read_program(_mixed_program(), source="mixed.ngc")
    name, lines = case
    return read_program(_excerpt(name, lines), source=name)


@pytest.mark.parametrize(
    "case",
    [
        "mixed",
        pytest.param(("violation_checks/stellabee-kink-test.ngc", 2000), marks=needs_corpus),
        pytest.param(("performance/3D_Chips.ngc", 1500), marks=needs_corpus),
        pytest.param(("performance/stellabee1.ngc", 3000), marks=needs_corpus),
    ],
)
def test_batch_fit_equals_python_fit(case, monkeypatch):
    import cnc_interp.fit._subrun as sr
    import cnc_interp.fit.fitter as fitter

    prog = _program(case)
    calls = {"n": 0}
    real = sr.join_and_measure

    def counted(*args):
        calls["n"] += 1
        return real(*args)

    monkeypatch.setattr(sr, "join_and_measure", counted)
    monkeypatch.setattr(fitter, "_kernels_ready", True)  # whatever numba has cached
    batched = fit_program(prog, FitSettings())
    assert calls["n"] > 0
    monkeypatch.setattr(fitter._SubRunBatcher, "covers_run", staticmethod(lambda pr, settings: False))
    python = fit_program(prog, FitSettings())
    _same_fit(batched, python)
    assert batched.stats["within_tolerance"]


@pytest.mark.parametrize("case", ["mixed", pytest.param(("performance/stellabee1.ngc", 3000), marks=needs_corpus)])
def test_worker_threads_give_the_same_fit(case, monkeypatch):
    """The batch fitter's kernels and the arc-length tables on worker threads, many small
    batches in flight, interleaved with sub-runs the Python fitter takes: the same paths
    in the same order as one thread."""
    import cnc_interp.fit.fitter as fitter
    from cnc_interp.fit.fitter import iter_fit
    from cnc_interp.fit.result import FitResult

    prog = _program(case)
    monkeypatch.setattr(fitter, "_kernels_ready", True)
    one = fit_program(prog, FitSettings(), threads=1)
    monkeypatch.setattr(fitter, "FIT_KERNEL_BATCH", 3)
    launched = []
    real = fitter._SubRunBatcher.launch

    def launch(self, batch):
        launched.append(len(batch))
        return real(self, batch)

    monkeypatch.setattr(fitter._SubRunBatcher, "launch", launch)
    stats: dict = {}
    items = tuple(iter_fit(prog.items, FitSettings(), stats, batch=5, threads=3))
    assert len(launched) > 5
    _same_fit(one, FitResult(program=prog, items=items, stats=stats))

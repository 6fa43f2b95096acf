"""Feed per move: no fitted segment straddles a change of the programmed F.

Each move keeps its own feed inside a merged path: the fit puts a segment boundary
at every node where F changes (nodes fitter: a knot there; planar fit: a segment end;
G61 collinear chains: one straight segment per feed), and VPOp's feed cap (the least
F over the segments a step touches) keeps the slower move at or below its F.
"""

from __future__ import annotations

import numpy as np
import pytest

from .conftest import fitted_of

FEEDS3 = "G21 G90 G64\nG0 X0 Y0 Z0\nG1 X10 F6000\nG1 X20 F60\nG1 X30 F6000\nM2\n"


def _feed_at_x(paths, x):
    """Feed of the segment whose x range contains x (straight paths along X)."""
    for p in paths:
        if p.rapid:
            continue
        for k in range(p.n_seg):
            x0 = p.coef[k, 0, 0]
            x1 = np.polynomial.polynomial.polyval(p.breaks[k + 1] - p.breaks[k], p.coef[k, :, 0])
            if min(x0, x1) < x < max(x0, x1):
                return p.feed_mm_s[k]
    raise AssertionError(f"no segment at x = {x}")


@pytest.mark.parametrize("g61", [False, True])
def test_collinear_moves_keep_their_own_feed(g61):
    text = FEEDS3.replace("G64", "G61") if g61 else FEEDS3
    res = fitted_of(text)
    feed_paths = [p for p in res.paths if not p.rapid]
    assert len(feed_paths) == 1  # collinear: one path, no stop
    for x, f in ((5, 100.0), (15, 1.0), (25, 100.0)):
        assert _feed_at_x(feed_paths, x) == pytest.approx(f)
    p = feed_paths[0]
    # the boundaries sit on the programmed nodes X10 and X20
    xb = [p.coef[k, 0, 0] for k in range(1, p.n_seg)]
    assert np.allclose(sorted(xb), [10.0, 20.0], atol=1e-9)


@pytest.mark.parametrize("method", ["planar", "nodes"])
@pytest.mark.slow
def test_curved_polyline_segments_never_straddle_a_feed_change(method):
    # a polyline of an arc (XY, two axes: the planar fit applies) with F changing every
    # 25 moves: each segment must lie inside one feed's moves
    a = np.linspace(0, np.pi, 101)
    lines = ["G21 G90 G64", f"G0 X{20 * np.cos(a[0]):.6f} Y{20 * np.sin(a[0]):.6f}"]
    feeds = []
    for j in range(1, a.size):
        f = 3000 if (j - 1) // 25 % 2 == 0 else 600
        feeds.append(f / 60.0)
        lines.append(f"G1 X{20 * np.cos(a[j]):.6f} Y{20 * np.sin(a[j]):.6f} F{f}")
    res = fitted_of("\n".join(lines) + "\nM2\n", method=method, tol_mm=0.001)
    (p,) = [q for q in res.paths if not q.rapid]
    assert set(np.unique(p.feed_mm_s)) == {50.0, 10.0}
    # every segment's end point lies on the programmed arc part of its own feed
    ang = np.arctan2(
        *[np.polynomial.polynomial.polyval(np.diff(p.breaks), p.coef[:, :, i].T, tensor=False) for i in (1, 0)]
    )
    ang0 = np.arctan2(p.coef[:, 0, 1], p.coef[:, 0, 0])
    ang, ang0 = (np.where(x < -0.5 * np.pi, x + 2 * np.pi, x) for x in (ang, ang0))
    # (1e-3 of a move is 0.6 µm of arc: the fit lies within 1 µm of the nodes)
    for k in range(p.n_seg):
        first = int(np.floor(ang0[k] / (np.pi / 100) + 1e-3))  # move index the segment starts in
        last = int(np.ceil(ang[k] / (np.pi / 100) - 1e-3)) - 1  # move it ends in
        want = {feeds[j] for j in range(max(first, 0), min(last, 99) + 1)}
        assert want == {p.feed_mm_s[k]}, (k, first, last, want, p.feed_mm_s[k])


def test_feed_reproducer_plans_in_about_ten_seconds():
    """G1 X10 F6000 / X20 F60 / X30 F6000: 10 s for the slow move plus the two fast
    moves' jerk-limited ramps (~0.19 s each on generic-mill), never faster than F60."""
    import tempfile
    import os

    from cnc_interp.pipeline import plan_part

    with tempfile.TemporaryDirectory() as d:
        f = os.path.join(d, "f.ngc")
        with open(f, "w") as fh:
            fh.write(FEEDS3)
        out = plan_part(f, "generic-mill")
    traj = out.trajectory
    assert 10.38 <= traj.duration_s <= 10.6
    x = traj.q[:, traj.axes.index("X")] if hasattr(traj, "axes") else traj.q[:, 0]
    v = np.diff(x) / traj.dt_s
    touching = (x[1:] > 10) & (x[:-1] < 20)
    assert v[touching].max() <= 1.0 * (1 + 1e-9)

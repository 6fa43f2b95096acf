"""VPOp's arc-length joint table (``JointTable``): closed forms, random paths, kinematics."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from cnc_interp.plan.vpop import VPOP_TABLE_MAX_TRIES
from cnc_interp.plan.vpop import VPOP_TABLE_MAX_ROUNDS
from cnc_interp.plan.vpop import VPOP_TABLE_TOL
from cnc_interp.errors import PlanError
from cnc_interp.fit.path import Path
from cnc_interp.machine.kinematics import Kinematics, make_kinematics
from cnc_interp.machine.model import Machine
from cnc_interp.plan.vpop import _GL_W, _GL_X, JointTable, _eval_table

from ._vpop_paths import circle_fun, hermite_path, line_path, random_curve

TOL = VPOP_TABLE_TOL


def _basic(t: JointTable, path: Path):
    """Invariants of every table: finite, increasing knots ending at the path's length,
    knots on the path, the checks within tolerance."""
    assert np.all(np.isfinite(t.C)) and np.all(np.isfinite(t.S))
    assert t.S[0] == 0.0 and t.S[-1] == path.length
    assert np.all(np.diff(t.S) > 0)
    assert t.C.shape == (t.S.shape[0] - 1, 6, path.n_axes)
    assert t.max_err <= TOL


def test_straight_line_with_uneven_parameter():
    # q(u) = a + d g(u), g = u + 0.8 u^2 - 0.5 u^5 increasing on [0, 1]: s(u) = |d| g(u)
    a = np.array([1.0, -2.0, 3.0])
    d = np.array([30.0, 40.0, 0.0])  # |d| = 50
    g = np.array([0.0, 1.0, 0.8, 0.0, 0.0, -0.5])
    coef = a[None, None, :] * (np.arange(6) == 0)[None, :, None] + g[None, :, None] * d[None, None, :]
    p = Path("XYZ", np.array([0.0, 1.0]), coef, line=[1], feed_mm_s=[100.0])
    t = JointTable(p, None)
    _basic(t, p)
    L = 50.0 * g.sum()
    assert_allclose(t.length, L, rtol=1e-14)
    gu = np.polynomial.polynomial.polyval(t.u, g)
    assert_allclose(t.S, 50.0 * gu, rtol=1e-13, atol=1e-13)  # knots at their exact arc length
    s = np.linspace(0.0, L, 2001)
    assert_allclose(_eval_table(t.S, t.C, s), a + np.outer(s / 50.0, d), rtol=0, atol=1e-10)
    assert_allclose(t.qend, a + d * g.sum(), rtol=0, atol=1e-13)


def test_circle_arc():
    R = 20.0
    p = hermite_path(circle_fun(R, turns=0.5), 64, 100.0)  # a half circle to ~1e-11 mm
    t = JointTable(p, None)
    _basic(t, p)
    assert_allclose(t.S[-1], np.pi * R, rtol=1e-12)
    s = np.linspace(0.0, np.pi * R, 3001)
    exact = np.stack([R * np.cos(s / R), R * np.sin(s / R), np.zeros_like(s)], axis=1)
    assert_allclose(_eval_table(t.S, t.C, s), exact, rtol=0, atol=1e-10)
    # knots: exact path points at the path's own arc length (adaptive Gauss–Legendre)
    assert_allclose(t.C[:, 0], p.derivatives_u(t.u[:-1], 0)[0], rtol=0, atol=1e-13)
    assert_allclose(t.S, p.s_of_u(t.u), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", range(8))
def test_random_quintic_paths_within_tolerance(seed):
    rng = np.random.default_rng(100 + seed)
    n_axes = int(rng.integers(2, 6))
    n_seg = int(rng.integers(1, 30))
    p = hermite_path(
        random_curve(rng, n_axes=n_axes, scale=float(rng.uniform(1, 80))),
        n_seg,
        100.0,
        axes="XYZUV"[:n_axes],
        u1=float(rng.uniform(0.5, 4.0)),
    )
    t = JointTable(p, None)
    _basic(t, p)
    assert_array_equal(t.qend, p.end)  # the exact programmed end, to the bit
    assert_array_equal(t.qstart, p.start)
    assert_allclose(t.S, p.s_of_u(t.u), rtol=1e-12, atol=1e-12)
    # dense comparison with the true path (its own u(s) inverse, to ~1e-12)
    s = np.sort(rng.uniform(0.0, p.length, 3000))
    assert np.abs(_eval_table(t.S, t.C, s) - p(s)).max() <= 10 * TOL
    # deterministic to the bit
    t2 = JointTable(p, None)
    assert_array_equal(t.S, t2.S)
    assert_array_equal(t.C, t2.C)


def test_many_pieces_from_one_segment():
    # one quintic for a whole (rough) circle: the kernel's output buffers must grow
    p = hermite_path(circle_fun(50.0, turns=1.0), 1, 100.0)
    t = JointTable(p, None)
    _basic(t, p)
    assert t.C.shape[0] > 4 * 13 + 64  # more rows than the kernel first allocates
    assert_allclose(t.S, p.s_of_u(t.u), rtol=1e-12, atol=1e-12)
    s = np.linspace(0.0, p.length, 5001)
    assert np.abs(_eval_table(t.S, t.C, s) - p(s)).max() <= 10 * TOL


def test_tolerance_drives_the_piece_count():
    rng = np.random.default_rng(5)
    p = hermite_path(random_curve(rng, scale=30.0), 5, 100.0)
    coarse = JointTable(p, None, tol=1e-6)
    fine = JointTable(p, None)
    assert coarse.max_err <= 1e-6 and fine.max_err <= TOL
    assert coarse.C.shape[0] < fine.C.shape[0]
    # the fine table refines the coarse one: every coarse knot is a fine knot
    assert np.isin(coarse.u, fine.u).all()


def test_rerun_when_the_length_scale_matters():
    """A table scaled to a length 1e-7 off its pieces' sum still meets the tolerance
    (its pieces are checked again against that scale)."""
    from cnc_interp.plan import _table_kernels as K

    rng = np.random.default_rng(3)
    p = hermite_path(random_curve(rng, scale=30.0), 7, 100.0)
    args = (
        p.coef,
        p.breaks,
        p.s_breaks,
        p.weights,
        p.length * (1 + 1e-7),
        TOL,
        VPOP_TABLE_MAX_ROUNDS - 1,
        20.0,
        _GL_X,
        _GL_W,
    )
    status, u, S, C, err, qend = K.build_identity(*args, 1)
    assert status == K.OK and err > TOL  # one pass: the stretch shows
    status, u, S, C, err, qend = K.build_identity(*args, VPOP_TABLE_MAX_TRIES)
    assert status == K.OK and err <= TOL
    assert S[-1] == p.length * (1 + 1e-7)
    assert_array_equal(qend, p.end)


class _PlainIdentity(Kinematics):
    """The identity, but not declared as one: takes the kinematics route."""

    @property
    def is_identity(self) -> bool:
        return False


def test_kinematics_route_matches_identity_route():
    rng = np.random.default_rng(21)
    p = hermite_path(random_curve(rng, scale=25.0), 9, 100.0)
    a = JointTable(p, None)
    b = JointTable(p, _PlainIdentity("XYZ"))
    _basic(b, p)
    assert b.S[-1] == a.S[-1]
    s = np.linspace(0.0, p.length, 4001)
    assert np.abs(_eval_table(a.S, a.C, s) - _eval_table(b.S, b.C, s)).max() <= 2 * TOL
    assert abs(a.C.shape[0] - b.C.shape[0]) <= 0.01 * a.C.shape[0]


def test_xyzac_trt_table_follows_the_joint_path():
    m = Machine(
        name="5ax",
        axes="XYZAC",
        vmax=[500] * 5,
        amax=[2500] * 5,
        jmax=[5000] * 5,
        dt_s=0.001,
        kinematics="xyzac-trt",
        kinematics_params={"z_rot_point": -50.0, "y_offset": 2.0},
    )
    kin = make_kinematics(m)

    def fun(u):
        u = np.asarray(u, dtype=float)
        z, o = np.zeros_like(u), np.ones_like(u)
        p = np.stack([20 * np.cos(u), 20 * np.sin(u), 5 * u, 10 * u, 40 * u], axis=1)
        p1 = np.stack([-20 * np.sin(u), 20 * np.cos(u), 5 * o, 10 * o, 40 * o], axis=1)
        p2 = np.stack([-20 * np.cos(u), -20 * np.sin(u), z, z, z], axis=1)
        return p, p1, p2

    p = hermite_path(fun, 8, 200.0, axes="XYZAC", u1=1.5)
    t = JointTable(p, kin)
    _basic(t, p)
    assert_array_equal(t.qend, kin.to_joints(p.end[None])[0])
    assert_allclose(t.C[:, 0], kin.to_joints(p.derivatives_u(t.u[:-1], 0)[0]), rtol=0, atol=1e-12)
    s = np.linspace(0.0, p.length, 3001)
    q = kin.to_joints(p(s))
    assert np.abs(_eval_table(t.S, t.C, s) - q).max() <= 10 * TOL
    # in program space the same path needs a different table (the kinematics bends it)
    ident = JointTable(p, None)
    assert_array_equal(ident.S[-1], t.S[-1])
    assert np.abs(_eval_table(ident.S, ident.C, s) - q).max() > 1.0


def test_rotary_only_path():
    p = line_path([5, 5, 5, 0], [5, 5, 5, 120], 60.0, axes="XYZA")
    t = JointTable(p, None)
    _basic(t, p)
    assert t.length == pytest.approx(120.0)
    s = np.linspace(0, 120.0, 101)
    assert_allclose(_eval_table(t.S, t.C, s), np.stack([np.full_like(s, 5.0)] * 3 + [s], 1), rtol=0, atol=1e-12)


def test_cusp_is_a_clear_error_not_nan():
    # q = (t - 1)^2 d: the path stops at t = 1 and turns back; q_s is undefined there
    d = np.array([3.0, 4.0, 0.0])
    coef = np.zeros((1, 6, 3))
    coef[0, 0], coef[0, 1], coef[0, 2] = d, -2 * d, d
    p = Path("XYZ", np.array([0.0, 2.0]), coef, line=[7], feed_mm_s=[100.0])
    with pytest.raises(PlanError, match="line 7"):
        JointTable(p, None)


def test_zero_length_path_is_an_error():
    p = line_path([1, 2, 3], [1, 2, 3], 100.0)
    with pytest.raises(PlanError):
        JointTable(p, None)


def _bounds_reference(t: JointTable, al, jl, vl):
    """The bounds' definition in plain numpy: five samples per piece, margins 25% / 2%."""
    h = np.diff(t.S)
    tt = (h[:, None] * np.linspace(0.0, 1.0, 5)[None, :])[..., None]  # (m, 5, 1)
    c = t.C[:, None, :, :]
    q1 = c[:, :, 1] + tt * (2 * c[:, :, 2] + tt * (3 * c[:, :, 3] + tt * (4 * c[:, :, 4] + tt * 5 * c[:, :, 5])))
    q2 = 2 * c[:, :, 2] + tt * (6 * c[:, :, 3] + tt * (12 * c[:, :, 4] + tt * 20 * c[:, :, 5]))
    q3 = 6 * c[:, :, 3] + tt * (24 * c[:, :, 4] + tt * 60 * c[:, :, 5])
    m2 = 1.25 * np.abs(q2).max(axis=1)
    m3 = 1.25 * np.abs(q3).max(axis=1)
    kv = (1.02 * np.abs(q1).max(axis=1) / vl).max(axis=1)
    return (m2 / al).max(axis=1), (m3 / jl).max(axis=1), (3.0 * m2 / jl).max(axis=1), kv


def test_curvature_and_speed_bounds_follow_their_definition():
    rng = np.random.default_rng(8)
    p = hermite_path(random_curve(rng, scale=40.0), 12, 100.0)
    t = JointTable(p, None)
    al, jl = np.array([2e-3, 1e-3, 3e-3]), np.array([5e-5, 2e-5, 1e-5])
    vl = np.array([0.2, 0.1, 0.3])
    k2, k3, k23, kv = _bounds_reference(t, al, jl, vl)
    got = t.curvature_bounds(al, jl)
    for a, b in zip(got, (k2, k3, k23)):
        assert_allclose(a, b, rtol=1e-15, atol=0)
    feed_step = np.full(p.n_seg, 0.05)
    feed_step[3] = 1e-3  # a slow segment: its pieces are bounded by the feed
    got_v = t.speed_bounds(vl, p, feed_step)
    seg = p.segment_of_s(0.5 * (t.S[:-1] + t.S[1:]))
    assert_allclose(got_v, np.maximum(kv, 1.0 / feed_step[seg]), rtol=1e-15, atol=0)
    assert (got_v[seg == 3] == 1e3).all()
    # the bounds hold: dense samples of |q_ss| / al never exceed k2 on any piece
    s = np.linspace(0.0, p.length, 20001)
    piece = np.clip(np.searchsorted(t.S, s, side="right") - 1, 0, t.C.shape[0] - 1)
    x = (s - t.S[piece])[:, None]
    c = t.C[piece]
    q2 = 2 * c[:, 2] + x * (6 * c[:, 3] + x * (12 * c[:, 4] + x * 20 * c[:, 5]))
    assert ((np.abs(q2) / al).max(axis=1) <= got[0][piece]).all()

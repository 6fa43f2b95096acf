"""Kinematics: identity, xyzac-trt round trips, a known point, the Jacobian."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from cnc_interp.errors import MachineError
from cnc_interp.machine.kinematics import make_kinematics
from cnc_interp.machine.model import Machine


def machine(axes="XYZAC", kind="xyzac-trt", **params):
    n = len(axes)
    return Machine(
        name="t",
        axes=axes,
        vmax=np.ones(n),
        amax=np.ones(n),
        jmax=np.ones(n),
        dt_s=0.001,
        kinematics=kind,
        kinematics_params=params,
    )


PARAMS = dict(x_rot_point=10.0, y_rot_point=-20.0, z_rot_point=5.0, y_offset=3.0, z_offset=-7.0, tool_offset=2.0)


def test_trivial_is_identity():
    k = make_kinematics(machine("XYZ", "trivial"))
    p = np.random.default_rng(1).normal(size=(50, 3))
    assert_allclose(k.to_joints(p), p, rtol=0, atol=0)
    assert_allclose(k.to_program(p), p, rtol=0, atol=0)
    assert_allclose(k.jacobian(p), np.broadcast_to(np.eye(3), (50, 3, 3)))
    assert k.is_identity and np.array_equal(k(p), p)


@pytest.mark.parametrize("params", [{}, PARAMS])
def test_xyzac_round_trip(params):
    k = make_kinematics(machine(**params))
    rng = np.random.default_rng(7)
    p = np.column_stack([rng.uniform(-200, 200, (1000, 3)), rng.uniform(-120, 120, 1000), rng.uniform(-720, 720, 1000)])
    q = k.to_joints(p)
    assert_allclose(k.to_program(q), p, rtol=0, atol=1e-9)
    assert_allclose(q[:, 3:], p[:, 3:], rtol=0, atol=0)  # rotary joints are the angles
    # rotations about a pivot keep distances to it (offsets 0 case)
    if not params:
        assert_allclose(np.linalg.norm(q[:, :3], axis=1), np.linalg.norm(p[:, :3], axis=1), rtol=1e-12)


def test_xyzac_known_points():
    k = make_kinematics(machine())
    # C = 90 deg turns the workpiece point (10, 0, 0) to (0, 10, 0) in the machine frame
    q = k.to_joints(np.array([[10.0, 0, 0, 0, 90.0]]))
    assert_allclose(q[0, :3], [0, 10, 0], atol=1e-12)
    # A = 90 deg then tilts (0, 10, 0) about X to (0, 0, 10)
    q = k.to_joints(np.array([[10.0, 0, 0, 90.0, 90.0]]))
    assert_allclose(q[0, :3], [0, 0, 10], atol=1e-12)
    # with the pivot at r, the pivot itself never moves
    k2 = make_kinematics(machine(x_rot_point=10.0, y_rot_point=-20.0, z_rot_point=5.0))
    q = k2.to_joints(np.array([[10.0, -20.0, 5.0, 33.0, 71.0]]))
    assert_allclose(q[0, :3], [10, -20, 5], atol=1e-12)


def test_xyzac_matches_linuxcnc_inverse_formula():
    # LinuxCNC xyzac-trt-kins inverse, written out term by term (trtfuncs)
    k = make_kinematics(machine(**PARAMS))
    rng = np.random.default_rng(3)
    p = np.column_stack([rng.uniform(-50, 50, (20, 3)), rng.uniform(-90, 90, 20), rng.uniform(0, 360, 20)])
    rx, ry, rz = PARAMS["x_rot_point"], PARAMS["y_rot_point"], PARAMS["z_rot_point"]
    dy, dz = PARAMS["y_offset"], PARAMS["z_offset"] + PARAMS["tool_offset"]
    a, c = np.radians(p[:, 3]), np.radians(p[:, 4])
    x, y, z = p[:, 0] - rx, p[:, 1] - ry, p[:, 2] - rz
    jx = np.cos(c) * x - np.sin(c) * y + rx
    jy = (
        np.sin(c) * np.cos(a) * x
        + np.cos(c) * np.cos(a) * y
        - np.sin(a) * z
        - np.cos(a) * dy
        + np.sin(a) * dz
        + dy
        + ry
    )
    jz = (
        np.sin(c) * np.sin(a) * x
        + np.cos(c) * np.sin(a) * y
        + np.cos(a) * z
        - np.sin(a) * dy
        - np.cos(a) * dz
        + dz
        + rz
    )
    assert_allclose(k.to_joints(p)[:, :3], np.column_stack([jx, jy, jz]), atol=1e-10)


def test_xyzac_jacobian_matches_finite_differences():
    k = make_kinematics(machine(axes="XYZACW", **PARAMS))
    rng = np.random.default_rng(11)
    p = np.column_stack(
        [rng.uniform(-50, 50, (5, 3)), rng.uniform(-90, 90, 5), rng.uniform(0, 360, 5), rng.uniform(-5, 5, 5)]
    )
    jac = k.jacobian(p)
    h = 1e-6
    for j in range(6):
        e = np.zeros(6)
        e[j] = h
        fd = (k.to_joints(p + e) - k.to_joints(p - e)) / (2 * h)
        assert_allclose(jac[:, :, j], fd, atol=1e-6)
    assert_allclose(k.to_joints(p)[:, 5], p[:, 5])  # W passes through


def test_xyzac_needs_axes_and_known_params():
    with pytest.raises(MachineError, match="lacks A, C"):
        make_kinematics(machine(axes="XYZ"))
    with pytest.raises(MachineError, match="unknown parameter 'pivot'"):
        make_kinematics(machine(pivot=1.0))
    with pytest.raises(MachineError, match="unknown kinematics"):
        make_kinematics(machine(kind="hexapod"))

"""Kinematics: program (workpiece) coordinates <-> machine joint positions.

A G-code program describes the tool tip in the workpiece frame (X, Y, Z in mm,
rotary words A, B, C in deg). The planner's limits apply to the machine's joints.
A ``Kinematics`` maps one to the other, vectorised over K points:
``to_joints(p)`` with p of shape (K, n) -> q (K, n), ``to_program(q)`` back, and
``jacobian(p)`` (K, n, n) with ``J[k, i, j] = dq_i / dp_j``. Axis order is the
machine's (``Machine.axes``); units are mm and deg on both sides.

``trivial``
    The identity (LinuxCNC ``trivkins``): every joint is its coordinate. The feed
    F applies to the XYZ path; a move with no linear motion uses the rotary angle
    (that metric lives in ``fit.path.Path``).

``xyzac-trt``
    Table-rotary-tilting 5-axis machine as LinuxCNC's ``xyzac-trt-kins``: the
    table tilts about X (joint A) and carries a rotary table turning about Z
    (joint C); the spindle moves in X, Y, Z. Parameters (mm, all default 0):
    ``x_rot_point, y_rot_point, z_rot_point`` (where the C axis crosses the
    A axis, machine coordinates), ``y_offset, z_offset`` (C axis centre relative
    to the A axis) and ``tool_offset`` (tool length, added to ``z_offset``).
    With r = rot point, P the program's tool tip, dy = y_offset,
    dz = z_offset + tool_offset, a = A, c = C (rad), the inverse map is::

        jx = cos c (Px-rx) - sin c (Py-ry) + rx
        jy = sin c cos a (Px-rx) + cos c cos a (Py-ry) - sin a (Pz-rz)
             - cos a dy + sin a dz + dy + ry
        jz = sin c sin a (Px-rx) + cos c sin a (Py-ry) + cos a (Pz-rz)
             - sin a dy - cos a dz + dz + rz
        jA = A,  jC = C

    i.e. q = r + Rx(a) (Rz(c) (P - r) - d) + d with d = (0, dy, dz): the workpiece
    point is turned by C about Z, then tilted by A about X around the pivot. The
    forward map is its exact inverse (transposed rotations). Other axes of the
    machine (U, V, W, B) pass through unchanged.

See ``docs/kinematics.md`` for the derivation and the arc-length convention.
"""

from __future__ import annotations

import math

from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import MachineError

if TYPE_CHECKING:
    from .model import Machine

#: kinematics name -> (axes it needs, {parameter: default})
KINEMATICS: dict[str, tuple[str, dict[str, float]]] = {
    "trivial": ("", {}),
    "xyzac-trt": (
        "XYZAC",
        {
            "x_rot_point": 0.0,
            "y_rot_point": 0.0,
            "z_rot_point": 0.0,
            "y_offset": 0.0,
            "z_offset": 0.0,
            "tool_offset": 0.0,
        },
    ),
}


def normalise_params(kind: str, params: dict[str, Any]) -> dict[str, float]:
    """Check a kinematics' parameters: known names (``-`` read as ``_``), finite numbers.

    Returns the full parameter dict with defaults filled in; raises ``MachineError``
    naming an unknown kinematics or parameter (the caller adds the location).
    """
    if kind not in KINEMATICS:
        raise MachineError(f"unknown kinematics '{kind}' (known: {', '.join(KINEMATICS)})")
    _, defaults = KINEMATICS[kind]
    out = dict(defaults)
    for key, value in params.items():
        name = key.replace("-", "_").lower()
        if name not in defaults:
            known = ", ".join(defaults) or "none"
            raise MachineError(f"unknown parameter '{key}' for kinematics '{kind}' (known: {known})")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise MachineError(f"kinematics parameter '{key}' must be a finite number")
        out[name] = float(value)
    return out


class Kinematics:
    """Identity kinematics (``trivial``); base class of the others."""

    name = "trivial"

    def __init__(self, axes: str, params: dict[str, Any] | None = None):
        self.axes = axes
        self.params = dict(params or {})

    def to_joints(self, p: np.ndarray) -> np.ndarray:
        """Program coordinates (K, n) -> joint positions (K, n)."""
        return np.array(p, dtype=float, copy=True)

    def to_program(self, q: np.ndarray) -> np.ndarray:
        """Joint positions (K, n) -> program coordinates (K, n)."""
        return np.array(q, dtype=float, copy=True)

    def jacobian(self, p: np.ndarray) -> np.ndarray:
        """(K, n, n) derivative of ``to_joints`` at program points p (K, n)."""
        p = np.asarray(p, dtype=float)
        k, n = p.shape
        return np.broadcast_to(np.eye(n), (k, n, n)).copy()

    @property
    def is_identity(self) -> bool:
        return True

    def __call__(self, p: np.ndarray) -> np.ndarray:  # the planner's JointMap protocol
        return self.to_joints(p)


class XyzacTrt(Kinematics):
    """LinuxCNC ``xyzac-trt``: tilting table A (about X) carrying rotary table C (about Z)."""

    name = "xyzac-trt"

    def __init__(self, axes: str, params: dict[str, Any] | None = None):
        super().__init__(axes, normalise_params(self.name, params or {}))
        missing = [a for a in "XYZAC" if a not in axes]
        if missing:
            raise MachineError(
                f"kinematics 'xyzac-trt' needs axes X, Y, Z, A, C; the machine lacks {', '.join(missing)}"
            )
        self._ix = [axes.index(a) for a in "XYZAC"]
        pr = self.params
        self._r = np.array([pr["x_rot_point"], pr["y_rot_point"], pr["z_rot_point"]])
        self._d = np.array([0.0, pr["y_offset"], pr["z_offset"] + pr["tool_offset"]])

    @property
    def is_identity(self) -> bool:
        return False

    def _angles(self, arr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        ia, ic = self._ix[3], self._ix[4]
        a = np.deg2rad(arr[:, ia])
        c = np.deg2rad(arr[:, ic])
        return np.cos(a), np.sin(a), np.cos(c), np.sin(c)

    def to_joints(self, p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, dtype=float)
        q = p.copy()
        ix, iy, iz = self._ix[:3]
        ca, sa, cc, sc = self._angles(p)
        rx, ry, rz = self._r
        dy, dz = self._d[1], self._d[2]
        x, y, z = p[:, ix] - rx, p[:, iy] - ry, p[:, iz] - rz
        # u = Rz(c) (P - r); then q = r + Rx(a) (u - d) + d
        ux = cc * x - sc * y
        uy = sc * x + cc * y
        q[:, ix] = ux + rx
        q[:, iy] = ca * uy - sa * z - ca * dy + sa * dz + dy + ry
        q[:, iz] = sa * uy + ca * z - sa * dy - ca * dz + dz + rz
        return q

    def to_program(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        p = q.copy()
        ix, iy, iz = self._ix[:3]
        ca, sa, cc, sc = self._angles(q)
        rx, ry, rz = self._r
        dy, dz = self._d[1], self._d[2]
        # invert q = r + Rx(a) (u - d) + d:  u = Rx(-a) (q - r - d) + d, P = r + Rz(-c) u
        gx = q[:, ix] - rx
        gy = q[:, iy] - ry - dy
        gz = q[:, iz] - rz - dz
        uy = ca * gy + sa * gz + dy
        z = -sa * gy + ca * gz + dz
        p[:, ix] = cc * gx + sc * uy + rx
        p[:, iy] = -sc * gx + cc * uy + ry
        p[:, iz] = z + rz
        return p

    def jacobian(self, p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, dtype=float)
        k, n = p.shape
        jac = np.broadcast_to(np.eye(n), (k, n, n)).copy()
        ix, iy, iz, ia, ic = self._ix
        ca, sa, cc, sc = self._angles(p)
        rx, ry, rz = self._r
        dy, dz = self._d[1], self._d[2]
        x, y, z = p[:, ix] - rx, p[:, iy] - ry, p[:, iz] - rz
        ux = cc * x - sc * y
        uy = sc * x + cc * y
        deg = math.pi / 180.0
        # d/dc of (ux, uy) = (-uy, ux)
        jac[:, ix, ix], jac[:, ix, iy], jac[:, ix, ic] = cc, -sc, -uy * deg
        jac[:, iy, ix], jac[:, iy, iy], jac[:, iy, iz] = ca * sc, ca * cc, -sa
        jac[:, iy, ia] = (-sa * uy - ca * z + sa * dy + ca * dz) * deg
        jac[:, iy, ic] = ca * ux * deg
        jac[:, iz, ix], jac[:, iz, iy], jac[:, iz, iz] = sa * sc, sa * cc, ca
        jac[:, iz, ia] = (ca * uy - sa * z - ca * dy + sa * dz) * deg
        jac[:, iz, ic] = sa * ux * deg
        return jac


_CLASSES = {"trivial": Kinematics, "xyzac-trt": XyzacTrt}


def make_kinematics(machine: Machine) -> Kinematics:
    """The ``Kinematics`` of a ``Machine`` (by ``machine.kinematics`` and its params)."""
    kind = machine.kinematics
    if kind not in _CLASSES:
        raise MachineError(f"unknown kinematics '{kind}' (known: {', '.join(_CLASSES)})")
    return _CLASSES[kind](machine.axes, machine.kinematics_params)

"""Synthetic plans for the export tests: smooth jerk-limited motions built in closed form,
so the export tests do not depend on the parser, fit or planners."""

from __future__ import annotations

import numpy as np

from cnc_interp.machine.model import Machine
from cnc_interp.plan.trajectory import Trajectory


def smooth_step(tau: np.ndarray) -> np.ndarray:
    """7th-order smoothstep on [0, 1]: zero velocity, acceleration and jerk at both ends."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau**4 * (35 - 84 * tau + 70 * tau**2 - 20 * tau**3)


def arc_trajectory(
    duration_s: float = 2.0,
    dt_s: float = 0.001,
    radius_mm: float = 20.0,
    sweep_deg: float = 270.0,
    dz_mm: float = -5.0,
    axes: str = "XYZ",
    n_lines: int = 12,
    planner: str = "synthetic",
) -> Trajectory:
    """A helical arc (XY circle of ``radius_mm``, Z ramp) travelled rest to rest.

    The angle follows ``smooth_step`` in time, so every axis's velocity, acceleration and
    jerk is smooth and bounded. ``line`` splits the motion into ``n_lines`` equal-time
    pieces numbered 10, 20, ... Extra axes beyond XYZ stay at 0 (A/B/C rotate slowly).
    """
    K = int(round(duration_s / dt_s)) + 1
    t = np.arange(K) * dt_s
    u = smooth_step(t / duration_s)
    phi = np.deg2rad(sweep_deg) * u
    q = np.zeros((K, len(axes)))
    cols = {
        "X": radius_mm * np.cos(phi),
        "Y": radius_mm * np.sin(phi),
        "Z": dz_mm * u,
        "A": 30.0 * u,
        "B": -15.0 * u,
        "C": 90.0 * u,
    }
    for i, a in enumerate(axes):
        q[:, i] = cols.get(a, 0.0)
    lin = [i for i, a in enumerate(axes) if a in "XYZUVW"]
    step = np.linalg.norm(np.diff(q[:, lin], axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(step)])
    feed = np.concatenate([[0.0], step / dt_s])
    line = 10 * (1 + np.minimum((t / duration_s * n_lines).astype(int), n_lines - 1))
    return Trajectory(
        axes=axes,
        dt_s=dt_s,
        t=t,
        s=s,
        feed=feed,
        q=q,
        line=line,
        planner=planner,
        settings={"duration_s": duration_s, "note": "synthetic"},
    )


def worst_ratio_limits(traj: Trajectory) -> np.ndarray:
    """(3, n) largest |v|, |a|, |j| per axis (rest-padded backward differences)."""
    q = traj.q
    pad = np.concatenate([np.repeat(q[:1], 3, axis=0), q, np.repeat(q[-1:], 3, axis=0)])
    v = np.diff(pad, axis=0) / traj.dt_s
    a = np.diff(v, axis=0) / traj.dt_s
    j = np.diff(a, axis=0) / traj.dt_s
    return np.stack([np.abs(v).max(0), np.abs(a).max(0), np.abs(j).max(0)])


def machine_for(traj: Trajectory, margin: float, name: str = "synthetic") -> Machine:
    """A machine whose limits are ``margin`` times the trajectory's worst values
    (``margin`` > 1: the plan respects it; < 1: it violates every limit)."""
    worst = np.maximum(worst_ratio_limits(traj), 1e-3) * margin
    return Machine(
        name=name,
        axes=traj.axes,
        vmax=worst[0],
        amax=worst[1],
        jmax=worst[2],
        dt_s=traj.dt_s,
        source="synthetic",
        start=traj.q[0].copy(),  # the machine starts where its plan does
    )


def machine_toml(machine: Machine) -> str:
    """The TOML text of ``machine`` (for the CLI tests)."""
    lines = [f'name = "{machine.name}"', f"dt = {machine.dt_s!r}"]
    start = ", ".join(f"{a} = {float(x)!r}" for a, x in zip(machine.axes, machine.start))
    lines.append(f"start = {{{start}}}")
    for i, a in enumerate(machine.axes):
        lines += [
            f"[axes.{a}]",
            f"vmax = {float(machine.vmax[i])!r}",
            f"amax = {float(machine.amax[i])!r}",
            f"jmax = {float(machine.jmax[i])!r}",
        ]
    return "\n".join(lines) + "\n"

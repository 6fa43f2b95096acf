"""Polyline vs exact: smooth curves given exactly (G2/G3, G5.2) and the same
curves as CAM writes them — G1 moves sampled at a chord error, coordinates rounded to
4 decimals — for ``benchmarks/polyline_vs_exact.py`` and the tests.

Every case is an exact program; ``polyline_program`` samples the exact curves the
interpreter builds from it (``Arc`` / ``Nurbs`` objects, so both programs describe the
very same geometry), greedily: each chord is the longest whose distance to the curve
(linear axes) stays within the chord error. Rotary axes of a 5-axis arc move linearly
with its angle, so their chords are exact. Both programs carry ``G64 P<chord error>``:
the CAM tolerance is the controller's.
"""

from __future__ import annotations

import numpy as np

#: feed of every case (mm/min): fast enough that the machine's limits, not F, bind
FEED_MM_MIN = 10000.0
#: chord errors of the polylines (mm)
CHORD_ERRORS_MM = (0.001, 0.005, 0.01)
#: decimals CAM output is rounded to
DECIMALS = 4


def _spiral_nurbs_text(turns=3.0, r0=3.0, pitch=4.0, n_ctrl=40, order=4):
    """An Archimedean spiral r = r0 + pitch·θ/2π as a G5.2 NURBS (least-squares control
    points on LinuxCNC's clamped uniform knots); the NURBS is the exact curve."""
    from scipy.interpolate import make_lsq_spline

    from cnc_interp.gcode.splines import clamped_uniform_knots

    th = np.linspace(0, 2 * np.pi * turns, 4001)
    r = r0 + pitch * th / (2 * np.pi)
    pts = np.stack([r * np.cos(th), r * np.sin(th)], axis=1)
    s = np.concatenate(([0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))))
    knots = clamped_uniform_knots(n_ctrl, order)
    x = s / s[-1] * knots[-1]
    spl = make_lsq_spline(x, pts, knots, k=order - 1)
    c = spl.c
    c[0], c[-1] = pts[0], pts[-1]
    lines = [f"G0 X{c[0, 0]:.6f} Y{c[0, 1]:.6f} Z0", f"G5.2 P1 L{order}"]
    lines += [f"X{p[0]:.6f} Y{p[1]:.6f} P1" for p in c[1:]]
    lines.append("G5.3")
    return lines


def cases() -> dict[str, tuple[str, list[str]]]:
    """name -> (axes of the machine it needs, exact program body lines)."""
    wave = [(0, 0), (15, 25), (30, -20), (45, 30), (60, -25), (75, 20), (90, -10), (105, 5)]
    out = {
        "nurbs-cubic": ("XYZ", ["G0 X0 Y0 Z0", "G5.2 P1 L4"] + [f"X{x} Y{y} P1" for x, y in wave[1:]] + ["G5.3"]),
        "nurbs-rational": (
            "XYZ",
            [
                "G0 X0 Y0 Z0",
                "G5.2 P1 L3",
                "X20 Y40 P3",
                "X50 Y40 P0.5",
                "X70 Y0 P2",
                "X100 Y30 P1",
                "X120 Y-10 P1",
                "G5.3",
            ],
        ),
        "arc-r5": ("XYZ", ["G0 X5 Y0 Z0", "G3 X5 Y0 I-5 J0"]),
        "arc-r25": ("XYZ", ["G0 X25 Y0 Z0", "G3 X25 Y0 I-25 J0"]),
        "arc-r100-90deg": ("XYZ", ["G0 X100 Y0 Z0", "G3 X0 Y100 I-100 J0"]),
        "helix-r10": ("XYZ", ["G0 X10 Y0 Z0", "G2 X10 Y0 Z-6 I-10 J0 P3"]),
        "spiral-nurbs": ("XYZ", _spiral_nurbs_text()),
        "5axis-arc": (
            "XYZAC",
            ["G0 X20 Y0 Z0 A0 C0", "G3 X-20 Y0 Z-5 I-20 J0 A20 C90", "G3 X20 Y0 Z-10 I20 J0 A-10 C180"],
        ),
    }
    return out


def exact_program(name: str, chord_mm: float) -> str:
    axes, body = cases()[name]
    head = ["G21 G90 G17 G94", f"G64 P{chord_mm:g}", f"F{FEED_MM_MIN:g}"]
    return "\n".join(head + body + ["M2"]) + "\n"


def _sample_chords(pts: np.ndarray, lin: np.ndarray, chord_mm: float) -> np.ndarray:
    """Indices of dense curve samples pts (K, n) kept as nodes: greedy longest chords whose
    distance to the samples between them (linear axes) stays within chord_mm."""
    p = pts[:, lin]
    keep = [0]
    i = 0
    K = p.shape[0]

    def ok(i, j):
        a, b = p[i], p[j]
        ab = b - a
        L2 = float(ab @ ab)
        q = p[i + 1 : j] - a
        if L2 == 0:
            return bool(np.all(np.linalg.norm(q, axis=1) <= chord_mm))
        t = np.clip(q @ ab / L2, 0, 1)
        return bool(np.all(np.linalg.norm(q - t[:, None] * ab, axis=1) <= chord_mm))

    while i < K - 1:
        step = 1
        while i + 2 * step < K and ok(i, i + 2 * step):
            step *= 2
        lo, hi = i + step, min(i + 2 * step, K - 1)
        if ok(i, hi):
            lo = hi
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if ok(i, mid):
                lo = mid
            else:
                hi = mid
        keep.append(lo)
        i = lo
    return np.array(keep)


def polyline_program(name: str, chord_mm: float, samples_per_curve: int = 200_000) -> str:
    """The exact case's curves as G1 moves at ``chord_mm``, rounded to ``DECIMALS``."""
    from cnc_interp.constants import LINEAR_AXES
    from cnc_interp.fit.curves import CurveEval
    from cnc_interp.gcode import read_program

    axes, _ = cases()[name]
    prog = read_program(exact_program(name, chord_mm), source=name, axes=axes)
    lin = np.array([a in LINEAR_AXES for a in axes])
    feed_runs = [r for r in prog.runs if r.kind == "feed"]
    nodes = [feed_runs[0].nodes[0]]
    for run in feed_runs:
        for cp in run.curves:
            ev = CurveEval(cp.curve)
            w = np.linspace(ev.w0, ev.w1, samples_per_curve + 1)
            pts = ev.points(w)
            idx = _sample_chords(pts, lin, chord_mm)
            nodes.extend(pts[idx[1:]])
    nodes = np.round(np.asarray(nodes), DECIMALS)
    fmt = "".join(f"{a}{{{i}:.{DECIMALS}f}}" for i, a in enumerate(axes))
    start = " ".join(f"{a}{v:.{DECIMALS}f}" for a, v in zip(axes, nodes[0]))
    head = ["G21 G90 G17 G94", f"G64 P{chord_mm:g}", f"F{FEED_MM_MIN:g}", f"G0 {start}"]
    body = ["G1 " + fmt.format(*n) for n in nodes[1:]]
    return "\n".join(head + body + ["M2"]) + "\n"

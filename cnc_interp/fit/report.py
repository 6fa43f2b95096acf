"""Fit statistics and the segments JSON file.

JSON format (``write_segments_json``), version 1::

    {
      "format": "cnc-interp-segments", "version": 1,
      "source": "part.ngc", "axes": "XYZ",
      "units": {"linear": "mm", "rotary": "deg", "feed": "mm/s"},
      "settings": {"tol_mm": ..., "tol_deg": ..., "corner_deg": ..., "tol_mode": ...},
      "items": [
        {"type": "path", "rapid": false, "weights": [1, 1, 1], "length_mm": L,
         "segments": [
           {"line": 12, "u0": 0.0, "u1": 1.25, "feed_mm_s": 20.0,
            "coef": [[a0, a1, a2, a3, a4, a5],      # one row per axis, in "axes" order:
                     ...],                          # q(u) = sum_i coef[axis][i] * (u - u0)**i
            "planar": {"plane": "XZ", "theta_rad": 1.5708, "origin": [x, z],
                       "x_end": 0.8, "p": [p0, ..., p5]}}   # only for planar fits
         ]},
        {"type": "dwell", "line": 20, "seconds": 0.5, "position": [...]},
        {"type": "stop", "line": 30, "code": "M0", "position": [...]}
      ]
    }

A planar segment's curve is q_h = o_h + x cos θ - p(x) sin θ,
q_v = o_v + x sin θ + p(x) cos θ for x = u - u0 in [0, x_end] (paper 000, Eq. 2
inverted). Numbers are written with ``repr`` precision; the same result gives
the same bytes.
"""

from __future__ import annotations

import json

import numpy as np

from ..outfile import atomic_write
from ..gcode.program import Dwell, Stop
from .path import Path
from .result import FitResult


def continuity_residuals(path: Path) -> dict:
    """Largest jumps at interior breaks of q (mm), dq/ds (-) and d²q/ds² (1/mm), comparing
    each segment's right end with the next segment's start; ``curvature_rel`` divides the
    curvature jump by max(1 mm⁻¹, |d²q/ds²|) there."""
    zero = dict(position_mm=0.0, tangent=0.0, curvature_1_mm=0.0, curvature_rel=0.0)
    if path.n_seg < 2:
        return zero
    k = np.arange(path.n_seg - 1)
    h = np.diff(path.breaks)[k]
    w = path.weights

    def derivs(c, t):
        out = []
        for d in range(3):
            acc = np.zeros((c.shape[0], c.shape[2]))
            for i in range(5, d - 1, -1):
                fac = 1.0
                for m_ in range(d):
                    fac *= i - m_
                acc = acc * t[:, None] + c[:, i, :] * fac
            out.append(acc)
        q, q1, q2 = out
        sig = np.sqrt((q1**2 * w).sum(axis=1))[:, None]
        dot = (q1 * q2 * w).sum(axis=1)[:, None]
        return q, q1 / sig, q2 / sig**2 - q1 * dot / sig**4

    ql, tl, cl = derivs(path.coef[k], h)
    qr, tr, cr = derivs(path.coef[k + 1], np.zeros(k.size))
    dc = np.abs(cl - cr).max(axis=1)
    mag = np.maximum(1.0, np.abs(cr).max(axis=1))
    return dict(
        position_mm=float(np.abs(ql - qr).max()),
        tangent=float(np.abs(tl - tr).max()),
        curvature_1_mm=float(dc.max()),
        curvature_rel=float((dc / mag).max()),
    )


def fit_statistics(result: FitResult) -> dict:
    """Plain-JSON statistics: the fitter's own figures plus continuity residuals."""
    st = {k: v for k, v in result.stats.items() if k != "runs"}
    worst = dict(position_mm=0.0, tangent=0.0, curvature_1_mm=0.0, curvature_rel=0.0)
    for p in result.paths:
        r = continuity_residuals(p)
        for k in worst:
            worst[k] = max(worst[k], r[k])
    st["continuity"] = worst
    st["source"] = result.program.source
    st["axes"] = result.program.axes
    st["paths"] = len(result.paths)
    st["runs"] = result.stats.get("runs", [])
    return _jsonable(st)


def format_statistics(stats: dict) -> str:
    """Human-readable summary of ``fit_statistics``."""
    c = stats["continuity"]
    methods = sorted({m for r in stats.get("runs", []) for m in r.get("methods", [])})
    lines = [
        f"{stats['source']}: axes {stats['axes']}",
        f"  nodes in           {stats['nodes_in']}",
        f"  segments out       {stats['segments_out']}  ({stats['segments_per_node']:.4f} per node)",
        f"  paths              {stats['paths']}  ({stats['feed_paths']} feed, {stats['rapid_moves']} rapid)",
        _tolerance_line(stats),
        f"  max node deviation {stats['max_node_dev_mm']:.3e} mm, {stats['max_node_dev_deg']:.3e} deg",
        f"  max path deviation {stats.get('max_path_dev_mm', 0.0):.3e} mm"
        f"  ({stats.get('max_path_dev_ratio', 0.0):.3f} of the tolerance; programmed moves and curves)",
        f"  with rotary axes   {stats.get('max_path_dev_rot_ratio', 0.0):.3f} of the tolerances"
        f" (position and orientation at one point of the fit; 0 when no rotary axis moves)",
        f"  within tolerance   {'yes' if stats['within_tolerance'] else 'NO'}",
        f"  continuity         position {c['position_mm']:.1e} mm, tangent {c['tangent']:.1e},"
        f" curvature {c['curvature_1_mm']:.1e} 1/mm ({c['curvature_rel']:.1e} relative)",
        f"  methods            {', '.join(methods) if methods else '-'}",
    ]
    return "\n".join(lines)


def _tolerance_line(stats: dict) -> str:
    """The tolerance the fit worked to: the default (plain G64), the cap, G64 P, and the
    half quantum of the printed coordinates added to it."""
    tol = stats["tol_mm"]
    cap = stats.get("tol_cap_mm")
    q = stats.get("quantum") or {}
    parts = [f"{tol:g} mm, {stats['tol_deg']:g} deg"]
    if cap is not None:
        parts.append(f"--tol cap {cap:g} mm")
    text = f"  tolerance          {', '.join(parts)}"
    if q.get("quantum_mm") or q.get("quantum_deg"):
        add = []
        if q.get("quantum_mm"):
            add.append(f"{0.5 * q['quantum_mm']:.6g} mm")
        if q.get("quantum_deg"):
            add.append(f"{0.5 * q['quantum_deg']:.6g} deg")
        labels = ", ".join(x for x in (q.get("label_mm"), q.get("label_deg")) if x)
        text += (
            f"; + ½ quantum {' / '.join(add)} (coordinates printed to {labels})"
            f" = {stats.get('fit_tol_mm', tol):g} mm, {stats.get('fit_tol_deg', 0.0):g} deg"
        )
    elif q.get("detected_mm") or q.get("detected_deg"):
        labels = ", ".join(x for x in (q.get("label_mm"), q.get("label_deg")) if x)
        text += f"; coordinates printed to {labels}, taken as exact"
    top = stats.get("max_tol_mm", 0.0)
    if top and abs(top - stats.get("fit_tol_mm", tol)) > 1e-12:
        text += f"; largest move tolerance {top:g} mm (G64 P)"
    return text


def segments_document(result: FitResult) -> dict:
    """The JSON document described in the module docstring."""
    prog = result.program
    items = []
    for it in result.items:
        if isinstance(it, Path):
            segs = []
            pl = it.planar
            for k in range(it.n_seg):
                seg = {
                    "line": int(it.line[k]),
                    "u0": float(it.breaks[k]),
                    "u1": float(it.breaks[k + 1]),
                    "feed_mm_s": _num(it.feed_mm_s[k]),
                    "coef": it.coef[k].T.tolist(),
                }
                if pl is not None:
                    seg["planar"] = {
                        "plane": it.axes[pl.plane[0]] + it.axes[pl.plane[1]],
                        "theta_rad": float(pl.theta[k]),
                        "origin": pl.origin[k].tolist(),
                        "x_end": float(pl.x_end[k]),
                        "p": pl.p[k].tolist(),
                    }
                segs.append(seg)
            items.append(
                {
                    "type": "path",
                    "rapid": bool(it.rapid),
                    "weights": it.weights.tolist(),
                    "length_mm": float(it.length),
                    "segments": segs,
                }
            )
        elif isinstance(it, Dwell):
            items.append(
                {
                    "type": "dwell",
                    "line": int(it.line),
                    "seconds": float(it.seconds),
                    "position": np.asarray(it.position, dtype=float).tolist(),
                }
            )
        elif isinstance(it, Stop):
            items.append(
                {
                    "type": "stop",
                    "line": int(it.line),
                    "code": it.code,
                    "position": np.asarray(it.position, dtype=float).tolist(),
                }
            )
    st = result.stats
    return {
        "format": "cnc-interp-segments",
        "version": 1,
        "source": prog.source,
        "axes": prog.axes,
        "units": {"linear": "mm", "rotary": "deg", "feed": "mm/s"},
        "settings": {
            k: st.get(k)
            for k in (
                "tol_mm",
                "tol_deg",
                "corner_deg",
                "tol_mode",
                "method",
                "tol_cap_mm",
                "fit_tol_mm",
                "fit_tol_deg",
            )
        },
        "items": items,
    }


def write_segments_json(result: FitResult, path: str) -> None:
    """Write ``segments_document`` atomically (``cnc_interp.outfile``); ``-`` = stdout."""
    text = json.dumps(segments_document(result), indent=1, sort_keys=True, allow_nan=False) + "\n"
    with atomic_write(path) as fh:
        fh.write(text.encode("utf-8"))


def _num(x: float):
    """JSON has no infinity: an unlimited feed (rapid) is written as null."""
    x = float(x)
    return x if np.isfinite(x) else None


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if np.isfinite(v) else None
    return obj

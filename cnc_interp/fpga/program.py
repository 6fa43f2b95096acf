"""Quantize a fitted and planned program into an ``FpgaProgram``.

Planar paths (``path.planar`` from the paper-000 fit, and straight moves of at
most two axes, rapids included, which are planar with p ≡ 0) become ``FixedSegment``s:
rotation, origin, x_end and the normalised quintic P(ξ) = p(ξ·x_end), plus a
*parametric profile*: piecewise quintics ξ(τ) fitted to the planned samples so
that the device's profile generator reproduces the plan's abscissa at every
sample within ``FPGA_PROFILE_TOL_MM`` along the path. The profile is built from
the plan's samples, so any planner (constant, variable, VPOp) can drive it.

Everything else (rapids, non-planar paths, dwells, held positions, and any path
whose samples do not lie on its planar form) is sent as quantized setpoint
blocks. Planned samples are matched to paths by cumulative arc length ``s``.
"""

from __future__ import annotations

import numpy as np

from ..constants import FPGA_LIMIT_MARGIN
from ..errors import SourceLocation
from .fixed import FixedFormat, FixedPointOverflow, FpgaFormats, Where, quantize_block
from .model import (
    FixedSegment,
    FpgaProgram,
    ProfilePiece,
    SetpointBlock,
    profile_xi,
    run_program,
    to_mm,
)


#: largest error the fitted parametric profile ξ(τ) may add along the path (mm)
FPGA_PROFILE_TOL_MM = 2e-5

#: a planar path is streamed as segments only if its samples lie on its planar form within this (mm)
FPGA_PLANAR_MATCH_MM = 1e-7

_DEG = 5


def assign_paths(traj, paths) -> list[tuple[object, int, int, float]]:
    """For each path in program order: (path, first sample, end sample, s at path start).

    A path owns the samples with S0 < s <= S0 + length (S0: length of everything
    before it); samples at rest where a path starts belong to whatever precedes it.
    S0 is summed in the same order as the timeline sums it, so the comparisons are
    exact (a jerk-limited start moves by far less than any relative epsilon).
    """
    s = np.asarray(traj.s, dtype=float)
    out = []
    s0 = 0.0
    for path in paths:
        s1 = s0 + float(path.length)
        a = int(np.searchsorted(s, s0, side="right"))
        b = int(np.searchsorted(s, s1, side="right"))
        out.append((path, a, b, s0))
        s0 = s1
    return out


def _poly_d1(p: np.ndarray, x: np.ndarray) -> np.ndarray:
    """p'(x) for rows p (K, 6) at x (K,)."""
    acc = 5.0 * p[:, 5]
    for i in range(4, 0, -1):
        acc = acc * x + i * p[:, i]
    return acc


def _poly(p: np.ndarray, x: np.ndarray) -> np.ndarray:
    acc = p[:, 5].copy()
    for i in range(4, -1, -1):
        acc = acc * x + p[:, i]
    return acc


def planar_form(path):
    """The path's paper-000 planar form: the fit's own, or exact for straight moves.

    A path that moves at most two axes (rapids included) and whose segments are
    all straight (every point within ``FPGA_PLANAR_MATCH_MM`` of the chord, however
    the fit parametrised it) is a planar path with p ≡ 0 and θ the direction of each
    chord: the profile carries the parametrisation. Returns ``None`` otherwise.
    """
    if path.planar is not None and not path.rapid:
        return path.planar
    coef = path.coef
    n_axes = coef.shape[2]
    if n_axes < 2:
        return None
    moving = np.nonzero(np.any(coef[:, 1:, :] != 0, axis=(0, 1)))[0].tolist()
    if len(moving) > 2:
        return None
    others = [i for i in range(n_axes) if i not in moving]
    plane = tuple(sorted((moving + others)[:2]))
    h, v = plane
    du = np.diff(path.breaks)
    terms = coef[:, 1:, :][:, :, [h, v]] * (du[:, None] ** np.arange(1, 6))[:, :, None]  # (n, 5, 2)
    d = terms.sum(axis=1)
    length = np.hypot(d[:, 0], d[:, 1])
    if np.any(length <= 0):
        return None
    unit = d / length[:, None]
    # distance of any point from the chord is at most the sum of the terms' normal parts
    normal = np.abs(terms[:, :, 1] * unit[:, None, 0] - terms[:, :, 0] * unit[:, None, 1]).sum(axis=1)
    from ..fit.path import PlanarSegments

    theta = np.arctan2(d[:, 1], d[:, 0])
    p = np.zeros((coef.shape[0], 6))
    if np.any(normal > FPGA_PLANAR_MATCH_MM):
        # a planar curve (an arc, a spline, a NURBS of the plane): each segment as a graph
        # z = p(x) over its chord, if a quintic follows it within the match tolerance
        p = _chord_quintics(coef[:, :, [h, v]], du, theta, length)
        if p is None:
            return None
    return PlanarSegments(plane=plane, theta=theta, origin=coef[:, 0, :][:, [h, v]].copy(), x_end=length, p=p)


#: points per segment at which a curve's chord-frame quintic is fitted and checked
_CURVE_FIT_POINTS = 97


def _chord_quintic(c2: np.ndarray, du: float):
    """(θ, x_end, p) of one segment as a graph z = p(x) over its chord, or None.

    c2 (6, 2) power-basis coefficients of the plane's two axes in t ∈ [0, du]; p is the
    quintic with p(0) = p(x_end) = 0 fitted by least squares at ``_CURVE_FIT_POINTS``
    points, accepted when every point is within half ``FPGA_PLANAR_MATCH_MM`` of it (and
    the segment never turns back over its chord)."""
    tk = np.linspace(0.0, du, _CURVE_FIT_POINTS)
    pts = (tk[:, None] ** np.arange(6)[None, :]) @ c2
    d = pts[-1] - pts[0]
    L = float(np.hypot(d[0], d[1]))
    if L <= 0:
        return None
    th = float(np.arctan2(d[1], d[0]))
    c, s = np.cos(th), np.sin(th)
    dxy = pts - pts[0]
    x = dxy[:, 0] * c + dxy[:, 1] * s
    z = -dxy[:, 0] * s + dxy[:, 1] * c
    if np.any(np.diff(x) <= 0):
        return None
    # p(x) = x (x - L) (a0 + a1 x + a2 x^2 + a3 x^3): p(0) = p(L) = 0 by construction
    A = (x * (x - L))[:, None] * x[:, None] ** np.arange(4)[None, :]
    scale = np.abs(A).max(axis=0)
    scale[scale == 0] = 1.0
    a = np.linalg.lstsq(A / scale, z, rcond=None)[0] / scale
    if np.max(np.abs(A @ a - z)) > 0.5 * FPGA_PLANAR_MATCH_MM:
        return None
    return th, L, np.polynomial.polynomial.polymul([0.0, -L, 1.0], a)[:6]


def _chord_quintics(coef2: np.ndarray, du: np.ndarray, theta: np.ndarray, length: np.ndarray):
    """Per segment, the chord-frame quintic (see ``_chord_quintic``); None if one fails.
    coef2 (n, 6, 2), du (n,)."""
    out = np.zeros((coef2.shape[0], 6))
    for k in range(coef2.shape[0]):
        got = _chord_quintic(coef2[k], float(du[k]))
        if got is None:
            return None
        out[k] = got[2]
    return out


def _shift_poly(c: np.ndarray, h: float) -> np.ndarray:
    """Coefficients (6, n_axes) of c(t + h) (Taylor shift)."""
    from math import comb

    out = np.zeros_like(c)
    for i in range(6):
        for j in range(i, 6):
            out[i] += comb(j, i) * h ** (j - i) * c[j]
    return out


#: a curved segment is halved at most this many times to follow it with chord quintics
_CURVE_MAX_SPLITS = 6


def planar_path(path):
    """(path, PlanarSegments) to stream ``path`` as segments, or None.

    A planar curve whose segments are too long for one chord-frame quintic each (a whole
    arc fitted as one parametric quintic) is split in its parameter until every piece is
    one (at most ``_CURVE_MAX_SPLITS`` halvings); the returned path is then that refined
    path (same geometry, same arc length)."""
    pl = planar_form(path)
    if pl is not None:
        return path, pl
    if path.planar is not None and not path.rapid:
        return None
    coef = path.coef
    moving = np.nonzero(np.any(coef[:, 1:, :] != 0, axis=(0, 1)))[0].tolist()
    if len(moving) != 2:
        return None
    h, v = moving
    du = np.diff(path.breaks)
    pieces: list[tuple[np.ndarray, float, int, float]] = []

    def split(c: np.ndarray, d: float, depth: int, k: int) -> bool:
        if _chord_quintic(c[:, [h, v]], d) is not None:
            pieces.append((c, d, int(path.line[k]), float(path.feed_mm_s[k])))
            return True
        if depth >= _CURVE_MAX_SPLITS:
            return False
        half = 0.5 * d
        return split(c, half, depth + 1, k) and split(_shift_poly(c, half), half, depth + 1, k)

    for k in range(path.n_seg):
        if not split(coef[k], float(du[k]), 0, k):
            return None
    from ..fit.path import Path

    breaks = path.breaks[0] + np.concatenate(([0.0], np.cumsum([p[1] for p in pieces])))
    refined = Path(
        axes=path.axes,
        breaks=breaks,
        coef=np.stack([p[0] for p in pieces]),
        line=[p[2] for p in pieces],
        feed_mm_s=[p[3] for p in pieces],
        weights=path.weights,
        rapid=path.rapid,
    )
    pl = planar_form(refined)
    return (refined, pl) if pl is not None else None


def _planar_samples(path, pl, q: np.ndarray, s_loc: np.ndarray, held: np.ndarray, pos: FixedFormat):
    """Segment index and rotated abscissa of each sample, or a reason why the path is not planar."""
    h, v = pl.plane
    seg = path.segment_of_s(s_loc)
    th = pl.theta[seg]
    c, s = np.cos(th), np.sin(th)
    d_h = q[:, h] - pl.origin[seg, 0]
    d_v = q[:, v] - pl.origin[seg, 1]
    x = d_h * c + d_v * s
    z = -d_h * s + d_v * c
    resid = np.abs(z - _poly(pl.p[seg], x))
    x_end = pl.x_end[seg]
    slack = FPGA_PLANAR_MATCH_MM
    if resid.size and float(resid.max()) > slack:
        return None, f"samples leave the planar form by {float(resid.max()):.3g} mm"
    if np.any(x < -slack) or np.any(x > x_end + slack):
        return None, "samples outside their segment"
    others = [i for i in range(q.shape[1]) if i not in (h, v)]
    if others:
        qi = np.floor(np.ldexp(q[:, others], pos.frac) + 0.5)
        hi = np.floor(np.ldexp(held[others], pos.frac) + 0.5)
        if np.any(qi != hi[None, :]):
            return None, "an axis outside the plane moves"
    return (seg, np.clip(x, 0.0, x_end)), ""


def _budget_ok(e: np.ndarray, carry: np.ndarray, budget: np.ndarray | None) -> bool:
    """Whether the error sequence (mm along the path), after the carried errors of the samples
    before it, has |Δe|, |Δ²e|, |Δ³e| within ``budget`` (3,) mm per sample."""
    if budget is None:
        return True
    x = np.concatenate((carry, e))
    for m in range(3):
        x = np.diff(x)
        if x.size and float(np.abs(x).max()) > budget[m]:
            return False
    return True


def _fit_piece(
    xi: np.ndarray,
    scale: np.ndarray,
    fmts: FpgaFormats,
    tol: float,
    where: Where,
    budget: np.ndarray | None = None,
    carry: np.ndarray | None = None,
):
    """Fit one profile piece to ξ samples: (piece, max error along the path in mm, errors (n,))
    or (None, err, None) when the piece must be split (too far from the samples, or its
    error changes too fast for the limits' budget after the ``carry`` errors before it)."""
    n = xi.shape[0]
    fx = fmts.param.frac
    if n == 1:
        dtau, deg = 0, 0
        tau = np.zeros(1)
    else:
        dtau = int(np.floor(np.ldexp(1.0, fx) / (n - 1) + 0.5))
        deg = min(_DEG, n - 1)
        tau = np.ldexp(np.arange(n, dtype=float) * dtau, -fx)
    if deg == 0:
        coef = np.array([xi.mean()])
    else:
        # power basis on τ in [0, 1]; scaling by the column norms keeps lstsq accurate
        vand = tau[:, None] ** np.arange(deg + 1)[None, :]
        coef = np.linalg.lstsq(vand, xi, rcond=None)[0]
    fl = np.polynomial.polynomial.polyval(tau, coef)
    err_f = float(np.max(np.abs(fl - xi) * scale))
    short = n <= _DEG + 1
    if err_f > 0.5 * tol and not short:
        return None, err_f, None
    full = np.zeros(_DEG + 1)
    full[: deg + 1] = coef
    exp, mant = quantize_block(full, fmts.coef_word, "profile coefficient", where, fmts.param.frac)
    piece = ProfilePiece(n, dtau, exp, tuple(mant))
    # the device's own ξ (integer Horner, bit-exact), as an error along the path
    xi_dev = np.ldexp(profile_xi([piece], fmts, where).astype(float), -fx)
    e = (xi_dev - xi) * scale
    err = float(np.max(np.abs(e)))
    if not short and (err > tol or not _budget_ok(e, carry if carry is not None else np.zeros(0), budget)):
        return None, err, None
    return piece, err, e


def fit_profile(
    xi: np.ndarray,
    scale: np.ndarray,
    fmts: FpgaFormats,
    tol_mm: float,
    where: Where,
    budget: np.ndarray | None = None,
    carry: np.ndarray | None = None,
):
    """Piecewise quintic ξ(τ) through the samples: (pieces, worst error along the path in mm,
    the last three errors (mm) to carry into the next segment).

    ``scale`` (n,) converts a ξ error into mm along the path (x_end·sqrt(1+p'²)).
    ``budget`` (3,): largest |Δe|, |Δ²e|, |Δ³e| per sample (mm) the profile's error may
    have, checked with the device's integer ξ and across piece and segment joins (``carry``:
    errors of the samples before the first); pieces of at most six samples are kept as
    they come (the program-level limit check re-sends a segment as setpoints if needed).
    Pieces grow geometrically from the last accepted length and halve on failure,
    so the work stays linear in the number of samples.
    """
    pieces: list[ProfilePiece] = []
    worst = 0.0
    carry = np.zeros(0) if carry is None else np.asarray(carry, float)[-3:]
    i, m = 0, xi.shape[0]
    length = m
    while i < m:
        length = min(m - i, max(2 * length, _DEG + 1))
        while True:
            piece, err, e = _fit_piece(xi[i : i + length], scale[i : i + length], fmts, tol_mm, where, budget, carry)
            if piece is not None:
                break
            length = max(1, length // 2)
        pieces.append(piece)
        worst = max(worst, err)
        carry = np.concatenate((carry, e))[-3:]
        i += length
    return pieces, worst, carry


def _setpoint_block(q: np.ndarray, start: int, line: int, pos: FixedFormat, file: str) -> SetpointBlock:
    scaled = np.floor(np.ldexp(q, pos.frac) + 0.5)
    lim = float(1 << min(pos.word - 1, 62))
    if not np.all(np.isfinite(scaled)) or np.any(np.abs(scaled) >= lim):
        pos.quantize(q, "setpoint", Where(-1, line, file))  # raises with the message
        raise FixedPointOverflow(
            f"setpoint exceeds the int64 range of the position format at source line {line}",
            SourceLocation(file=file, line=line),
        )
    return SetpointBlock(start, int(line), scaled.astype(np.int64))


def build_program(
    traj,
    paths=(),
    formats: FpgaFormats | None = None,
    source: str = "<input>",
    start=None,
    profile_tol_mm: float = FPGA_PROFILE_TOL_MM,
    limits: np.ndarray | None = None,
) -> FpgaProgram:
    """Quantize a planned ``Trajectory`` (and the ``Path``s it was planned from) for the FPGA.

    ``paths``: the program's paths in order (rapids included), as in
    ``FitResult.paths``; their planar parts become segments. ``start``: position
    before the first sample (default ``traj.q[0]``). ``limits`` (3, n_axes): the
    machine's vmax, amax, jmax; with them, every segment whose reproduction takes part
    in a verify difference above a limit is sent as exact setpoints instead
    (``fpga/limits.py``), and ``stats["verify_ratio"]`` is the golden model's worst ratio.
    """
    fmts = formats or FpgaFormats()
    pos = fmts.pos
    q = np.asarray(traj.q, dtype=float)
    K, n_axes = q.shape
    lines = np.asarray(traj.line, dtype=np.int64) if traj.line is not None else np.zeros(K, np.int64)
    start_f = q[0] if start is None else np.asarray(start, dtype=float)
    start_q = pos.quantize(start_f, "start position", Where(-1, 0, source))
    start_i = tuple(int(v) for v in np.asarray(start_q, dtype=object).reshape(-1))

    items: list = []
    planar_mask = np.zeros(K, dtype=bool)
    # per axis, how much the profile's error may change per sample: half the base margin of
    # each limit (the other half and the rounding budget are the device margin's, limits.py)
    budget = None
    if limits is not None:
        dt = float(traj.dt_s)
        budget = 0.5 * FPGA_LIMIT_MARGIN * np.asarray(limits, float) * np.array([dt, dt**2, dt**3])[:, None]
    fallback: list[str] = []
    seg_counter = 0
    profile_err = 0.0
    n_pieces = 0
    cursor = 0

    def flush_setpoints(upto: int) -> None:
        nonlocal cursor
        if upto > cursor:
            items.append(_setpoint_block(q[cursor:upto], cursor, int(lines[cursor]), pos, source))
            cursor = upto

    for path, a, b, s0 in assign_paths(traj, paths):
        n_seg_path = path.n_seg
        got_form = planar_path(path) if b > a else None
        if got_form is None:
            seg_counter += n_seg_path
            continue
        path, pl = got_form
        n_seg_path = path.n_seg
        held = q[a - 1] if a > 0 else start_f
        got, why = _planar_samples(path, pl, q[a:b], traj.s[a:b] - s0, held, pos)
        if got is None:
            fallback.append(f"path ending on line {int(path.line[-1])}: {why}")
            seg_counter += n_seg_path
            continue
        seg, x = got
        flush_setpoints(a)
        carry = np.zeros(3)  # the samples before a path are exact setpoints (or at rest)
        budget_path = None if budget is None else budget[:, list(pl.plane)].min(axis=1)
        for k in range(n_seg_path):
            idx = np.nonzero(seg == k)[0]
            gid = seg_counter + k
            if idx.size == 0:
                continue
            line = int(path.line[k])
            where = Where(gid, line, source)
            x_end = float(pl.x_end[k])
            xk = x[idx]
            xi = xk / x_end
            scale = x_end * np.sqrt(1.0 + _poly_d1(np.repeat(pl.p[k][None, :], idx.size, 0), xk) ** 2)
            pieces, err, carry = fit_profile(xi, scale, fmts, profile_tol_mm, where, budget_path, carry)
            profile_err = max(profile_err, err)
            n_pieces += len(pieces)
            pn = pl.p[k] * x_end ** np.arange(6)
            p_exp, p_mant = quantize_block(pn, fmts.coef_word, "path coefficient", where, pos.frac)
            x_exp, x_mant = quantize_block([x_end], fmts.mult_word, "segment x_end", where, pos.frac - fmts.param.frac)
            th = float(pl.theta[k])
            cos_i = int(fmts.trig.quantize(np.cos(th), "cos θ", where))
            sin_i = int(fmts.trig.quantize(np.sin(th), "sin θ", where))
            org = pos.quantize(pl.origin[k], "segment origin", where)
            items.append(
                FixedSegment(
                    index=gid,
                    line=line,
                    plane=(int(pl.plane[0]), int(pl.plane[1])),
                    cos=cos_i,
                    sin=sin_i,
                    origin=(int(org[0]), int(org[1])),
                    x_exp=x_exp,
                    x_mant=x_mant[0],
                    p_exp=p_exp,
                    p_mant=tuple(p_mant),
                    start_sample=a + int(idx[0]),
                    pieces=tuple(pieces),
                )
            )
        planar_mask[a:b] = True
        cursor = b
        seg_counter += n_seg_path
    flush_setpoints(K)

    repaired = 0
    if limits is not None:
        items, repaired = _repair_limits(items, q, traj, fmts, start_i, source, np.asarray(limits, float))
        for it in items:
            if isinstance(it, SetpointBlock):
                planar_mask[it.start_sample : it.start_sample + it.n_samples] = False
    prog = FpgaProgram(
        axes=traj.axes,
        dt_s=float(traj.dt_s),
        formats=fmts,
        start=start_i,
        n_samples=K,
        items=tuple(items),
        source=source,
    )
    stats = deviation_stats(prog, q, planar_mask, limits)
    stats.update(
        segments=sum(isinstance(i, FixedSegment) for i in items),
        repaired_segments=repaired,
        profile_pieces=n_pieces,
        profile_fit_err_mm=profile_err,
        setpoint_samples=int(K - planar_mask.sum()),
        planar_samples=int(planar_mask.sum()),
        fallback_paths=fallback,
    )
    return FpgaProgram(**{**prog.__dict__, "stats": stats})


def _repair_limits(items, q, traj, fmts, start_i, source, limits):
    """Re-send as setpoints every segment whose reproduction breaks a limit; (items, count)."""
    from .limits import excess_samples

    items = list(items)
    repaired = 0
    while True:
        prog = FpgaProgram(
            axes=traj.axes,
            dt_s=float(traj.dt_s),
            formats=fmts,
            start=start_i,
            n_samples=q.shape[0],
            items=tuple(items),
            source=source,
        )
        qe = to_mm(run_program(prog).q, fmts)
        bad = excess_samples(qe, float(traj.dt_s), limits)
        if bad.size == 0:
            return items, repaired
        starts = np.array([it.start_sample for it in items], dtype=np.int64)
        owners = np.unique(np.searchsorted(starts, bad, side="right") - 1)
        hit = [k for k in owners.tolist() if isinstance(items[k], FixedSegment)]
        if not hit:
            return items, repaired  # rounding only: the margin's job; verify has the last word
        for k in hit:
            seg = items[k]
            a = seg.start_sample
            items[k] = _setpoint_block(q[a : a + seg.n_samples], a, seg.line, fmts.pos, source)
        repaired += len(hit)


def deviation_stats(
    prog: FpgaProgram, q_plan: np.ndarray, planar_mask: np.ndarray | None = None, limits: np.ndarray | None = None
) -> dict:
    """Run the golden model and compare with the float plan: worst deviations and end drift (mm);
    with ``limits`` (3, n_axes) also verify's worst ratio of the device's setpoints."""
    out = run_program(prog)
    qe = to_mm(out.q, prog.formats)
    dev = np.abs(qe - q_plan)
    stats = {
        "max_dev_mm": float(dev.max()) if dev.size else 0.0,
        "max_dev_euclid_mm": float(np.sqrt((dev**2).sum(axis=1)).max()) if dev.size else 0.0,
    }
    if planar_mask is not None and planar_mask.any():
        stats["max_dev_planar_mm"] = float(dev[planar_mask].max())
    gaps = np.array(out.segment_end_gap, dtype=float).reshape(-1, 2)
    stats["max_segment_end_drift_mm"] = float(np.abs(gaps).max() * prog.formats.pos.lsb) if gaps.size else 0.0
    if limits is not None and qe.shape[0]:
        from ..plan.verify import verify_arrays

        rep = verify_arrays(qe, prog.dt_s, *np.asarray(limits, float), axes=prog.axes)
        axis, kind, ratio, idx = rep.worst()
        stats.update(verify_ok=bool(rep.ok), verify_ratio=float(ratio), verify_worst=f"{axis} {kind} at sample {idx}")
    return stats

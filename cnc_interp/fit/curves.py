"""Exact curves (G2/G3 arcs and helices, G5.2 NURBS, G5/G5.1 splines) -> quintic pieces.

A curve is converted from its exact geometry, never from the sampled nodes:
the curve's parameter range is cut into pieces (arcs: at most a quarter turn;
NURBS: at every distinct knot) and each piece becomes the quintic Hermite
interpolant of the exact position, first and second derivative at its two ends.
Every piece is checked against the exact curve at ``CURVE_CHECK_POINTS``
interior points and halved until it is within the tolerance. Inside a curve the
pieces share exact end values, so the result is C2 in the parameter (G2).

The parameter of the pieces is u = g·w (w the curve's own parameter: arc
fraction or NURBS knot value) with one scale g per curve (its length over its
parameter range), so |dq/du| ≈ 1 like the node fitter's chord length.

At the two ends of a curve the caller may impose another tangent and curvature
vector (a G2 junction with a neighbouring curve); the pieces touching the end
are then subdivided until the modified interpolant is within tolerance too.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..constants import FIT_TOL_SAFETY
from ..gcode.program import Arc, Nurbs
from ._npexact import cube, weighted_rows
from .nodes import PieceFit, hermite

if TYPE_CHECKING:
    from ._arcs import ArcArrays


#: curves: exact-geometry check points per quintic piece when converting arcs / NURBS
CURVE_CHECK_POINTS = 16

#: curves: deepest halving of a curve piece before giving up (2**depth pieces)
CURVE_MAX_DEPTH = 30


class CurveEval:
    """Exact position and derivatives of one curve, vectorised over its parameter w."""

    def __init__(self, curve):
        self.curve = curve
        if isinstance(curve, Arc):
            self.w0, self.w1 = 0.0, 1.0
            n_q = max(1, int(np.ceil(abs(curve.sweep_rad) / (0.5 * np.pi))))
            self.breaks = np.linspace(0.0, 1.0, n_q + 1)
            # the arc's constants, once (the same expressions as Arc.points, so that
            # positions come out bit-identical to it)
            c = curve
            i, j, _ = c.plane
            self._a0 = np.arctan2(c.start[j] - c.center[1], c.start[i] - c.center[0])
            self._r0 = float(np.hypot(c.start[i] - c.center[0], c.start[j] - c.center[1]))
            self._r1 = float(np.hypot(c.end[i] - c.center[0], c.end[j] - c.center[1]))
            self._d = c.end - c.start
        elif isinstance(curve, Nurbs):
            from scipy.interpolate import BSpline

            k = curve.order - 1
            kn = np.asarray(curve.knots, dtype=float)
            self.w0, self.w1 = float(kn[k]), float(kn[-k - 1])
            w = np.asarray(curve.weights, dtype=float)
            self._num = BSpline(kn, curve.control * w[:, None], k)
            self._den = BSpline(kn, w, k)
            inner = kn[(kn > self.w0) & (kn < self.w1)]
            self.breaks = np.unique(np.concatenate(([self.w0], inner, [self.w1])))
        else:  # pragma: no cover - the type is closed
            raise TypeError(type(curve))

    def eval(self, w: np.ndarray):
        """(P, P', P'') at w (K,), each (K, n_axes), derivatives with respect to w."""
        w = np.asarray(w, dtype=float)
        c = self.curve
        if isinstance(c, Arc):
            i, j, _ = c.plane
            sw = c.sweep_rad
            ang = self._a0 + sw * w
            r0, r1 = self._r0, self._r1
            r = r0 + (r1 - r0) * w
            dr = r1 - r0
            co, si = np.cos(ang), np.sin(ang)
            # P as Arc.points(w) computes it (same expressions), sharing cos/sin
            P = c.start[None, :] + self._d[None, :] * w[:, None]
            P[:, i] = c.center[0] + r * co
            P[:, j] = c.center[1] + r * si
            P1 = np.repeat(self._d[None, :], w.size, axis=0)
            P2 = np.zeros_like(P)
            P1[:, i] = dr * co - r * sw * si
            P1[:, j] = dr * si + r * sw * co
            P2[:, i] = -2 * dr * sw * si - r * sw * sw * co
            P2[:, j] = 2 * dr * sw * co - r * sw * sw * si
            return P, P1, P2
        A = self._num(w)
        A1 = self._num(w, nu=1)
        A2 = self._num(w, nu=2)
        W = self._den(w)[:, None]
        W1 = self._den(w, nu=1)[:, None]
        W2 = self._den(w, nu=2)[:, None]
        P = A / W
        P1 = (A1 - W1 * P) / W
        P2 = (A2 - 2 * W1 * P1 - W2 * P) / W
        return P, P1, P2

    def points(self, w: np.ndarray) -> np.ndarray:
        c = self.curve
        if isinstance(c, Arc):
            # Arc.points with the arc's constants computed once (bit-identical)
            w = np.asarray(w, dtype=float)
            i, j, _ = c.plane
            ang = self._a0 + c.sweep_rad * w
            out = c.start[None, :] + self._d[None, :] * w[:, None]
            r = self._r0 + (self._r1 - self._r0) * w
            out[:, i] = c.center[0] + r * np.cos(ang)
            out[:, j] = c.center[1] + r * np.sin(ang)
            return out
        return self.eval(w)[0]


def curve_eval(curve, cache: dict | None = None) -> CurveEval:
    """``CurveEval(curve)``, shared through ``cache`` (keyed by the curve object's id;
    the caller keeps the curves alive) so that its cached scale and end states are
    computed once per curve."""
    if cache is None:
        return CurveEval(curve)
    ev = cache.get(id(curve))
    if ev is None or ev.curve is not curve:
        ev = cache[id(curve)] = CurveEval(curve)
    return ev


def _direction(ev: CurveEval, w: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Unit direction of travel (K, d) at w from exact points a small step around it
    (used where the curve's own derivative vanishes, e.g. repeated control points)."""
    span = ev.w1 - ev.w0
    dw = _DIR_STEP * span
    lo = np.clip(w - dw, ev.w0, ev.w1)
    hi = np.clip(w + dw, ev.w0, ev.w1)
    d = (ev.points(hi) - ev.points(lo)) * scale
    return d / np.linalg.norm(d, axis=1)[:, None]


def _derivs(ev: CurveEval, w: np.ndarray, scale: np.ndarray, g: float):
    """Scaled (P, dP/du, d²P/du²) at w with u = g·w; a vanishing speed is replaced by unit
    speed along the direction of travel and zero acceleration (no cusp in the path)."""
    P, P1, P2 = ev.eval(w)
    Ps, V, A = P * scale, P1 * scale / g, P2 * scale / g**2
    sp = np.linalg.norm(V, axis=1)
    weak = sp < _MIN_SPEED
    if weak.any():
        V[weak] = _direction(ev, w[weak], scale)
        A[weak] = 0.0
    return Ps, V, A


def param_scale(ev: CurveEval, scale: np.ndarray) -> float:
    """g = curve length / parameter range (from a fine chord sum), cached on ``ev``."""
    key = tuple(np.asarray(scale, dtype=float).tolist())
    cache = ev.__dict__.setdefault("_g", {})
    if key not in cache:
        ws = np.linspace(ev.w0, ev.w1, 64 * (ev.breaks.size - 1) + 1)
        pts = ev.points(ws) * scale
        length = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
        if not length > 0:
            raise ValueError("zero-length curve")
        cache[key] = length / (ev.w1 - ev.w0)
    return cache[key]


def end_states(ev: CurveEval, scale: np.ndarray):
    """Unit tangent and curvature vector (scaled space) at the curve's start and end,
    exactly as the quintic pieces see them (same stop-of-parameter treatment)."""
    key = tuple(np.asarray(scale, dtype=float).tolist())
    cache = ev.__dict__.setdefault("_ends", {})
    if key in cache:
        return cache[key]
    g = param_scale(ev, scale)
    _, V, A = _derivs(ev, np.array([ev.w0, ev.w1]), scale, g)
    out = []
    for k in range(2):
        sp = np.linalg.norm(V[k])
        T = V[k] / sp
        K = (A[k] - (A[k] @ T) * T) / sp**2
        T.flags.writeable = False  # shared through the cache
        K.flags.writeable = False
        out.append((T, K))
    cache[key] = out
    return out


_MIN_SPEED = 1e-3  # |dP/du| below this (u ≈ arc length) counts as a stop of the parameter
_MIN_PIECE_SPEED = 0.25  # least |dq/dτ| inside a unit-speed piece
_DIR_STEP = 1e-7  # relative parameter step for the direction of travel there


def _polyval(coef: np.ndarray, t: np.ndarray) -> np.ndarray:
    """coef (K, 6, d), t (K, M) -> (K, M, d)."""
    acc = coef[:, None, 5, :]  # (K, 1, d): the first Horner step broadcasts it over t
    for i in range(4, -1, -1):
        acc = acc * t[..., None] + coef[:, None, i, :]
    return acc


def _derivative(coef: np.ndarray) -> np.ndarray:
    """Coefficients (K, 6, d) of the t-derivative (degree 4, padded with a zero)."""
    d = np.zeros_like(coef)
    d[:, :5] = coef[:, 1:] * np.arange(1, 6)[None, :, None]
    return d


def _geometric(ev: CurveEval, w: np.ndarray, scale: np.ndarray, g: float):
    """At w (K,): scaled position, unit tangent T, curvature vector K, and dw/dσ, d²w/dσ²
    of the arc-length reparametrisation σ (a parameter stop uses the direction of travel,
    K = 0 and a finite dw/dσ)."""
    P, P1, P2 = ev.eval(w)
    Ps, V, A = P * scale, P1 * scale, P2 * scale
    sp = np.linalg.norm(V, axis=1)
    weak = sp < _MIN_SPEED * g
    sp_safe = np.where(weak, _MIN_SPEED * g, sp)
    T = V / sp_safe[:, None]
    if weak.any():
        T[weak] = _direction(ev, w[weak], scale)
    at = (A * T).sum(axis=1)
    K = (A - at[:, None] * T) / sp_safe[:, None] ** 2
    K[weak] = 0.0
    wd1 = 1.0 / sp_safe
    wd2 = np.where(weak, 0.0, -at / cube(sp_safe))
    return Ps, T, K, wd1, wd2


def _piece_lengths(ev: CurveEval, wa: np.ndarray, wz: np.ndarray, scale: np.ndarray):
    """Arc length (K,) and displacement (K, d) (scaled metric) of each piece [wa, wz].

    Both by 8-point Gauss–Legendre over P'(w): for a tiny piece far from the origin the
    difference P(wz) - P(wa) of two absolute positions would lose digits (and the
    Hermite's third to fifth coefficients divide it by h³..h⁵). Large pieces take the
    difference of the exact end points, where quadrature would be the less accurate.
    """
    x, wts = _PIECE_GL_X, _PIECE_GL_W
    mid, half = 0.5 * (wa + wz), 0.5 * (wz - wa)
    w = (mid[:, None] + half[:, None] * x[None, :]).ravel()
    d1 = (ev.eval(w)[1] * scale).reshape(wa.size, x.size, -1)
    sp = np.linalg.norm(d1, axis=2)
    L = half * weighted_rows(sp, wts)
    dp_quad = half[:, None] * np.einsum("kgd,g->kd", d1, wts)
    pa = ev.points(wa)
    dp_diff = (ev.points(wz) - pa) * scale
    chord = np.linalg.norm(dp_diff, axis=1)
    small = chord < _SMALL_PIECE * np.maximum(1.0, np.abs(pa * scale).max(axis=1))
    dp = np.where(small[:, None], dp_quad, dp_diff)
    return np.maximum(L, chord), dp


_SMALL_PIECE = 1e-2  # relative size below which a piece's displacement comes from quadrature
# the 8-point rule of _piece_lengths, computed once (leggauss costs more than the arc itself)
_PIECE_GL_X, _PIECE_GL_W = np.polynomial.legendre.leggauss(8)


def _retarget(v, a, T, K):
    """End derivatives (v, a) (scaled) turned to tangent T and curvature vector K, keeping
    the speed and the tangential acceleration."""
    sp = np.linalg.norm(v)
    at = a @ (v / sp)
    return sp * T, at * T + sp**2 * K


def fit_curve(
    curve,
    scale: np.ndarray,
    lin: np.ndarray,
    tol_mm: float,
    tol_deg: float,
    line: int,
    feed: float,
    start=None,
    end=None,
) -> PieceFit:
    """Quintic pieces of one exact curve within ``tol_mm`` (linear, Euclidean) / ``tol_deg``.

    ``scale`` (d,) maps machine units to the fitter's metric (1 on linear axes);
    ``start``/``end`` optionally impose (T, K) unit tangent and curvature vector in
    that metric at the curve's ends.
    """
    ev = curve if isinstance(curve, CurveEval) else CurveEval(curve)
    curve = ev.curve
    wb = ev.breaks
    # one parameter scale per curve: length / parameter range
    g = param_scale(ev, scale)
    tl = tol_mm * FIT_TOL_SAFETY
    tr = tol_deg * FIT_TOL_SAFETY
    tfr = np.arange(1, CURVE_CHECK_POINTS + 1) / (CURVE_CHECK_POINTS + 1)
    max_mm = max_deg = 0.0
    ok = True
    for _ in range(CURVE_MAX_DEPTH + 1):
        wa, wz = wb[:-1], wb[1:]
        Ps, T, K, wd1, wd2 = _geometric(ev, wb, scale, g)
        v0, a0 = T[:-1].copy(), K[:-1].copy()
        v1, a1 = T[1:].copy(), K[1:].copy()
        if start is not None:
            v0[0], a0[0] = start
        if end is not None:
            v1[-1], a1[-1] = end
        h, dp = _piece_lengths(ev, wa, wz, scale)
        # unit-speed (arc-length-like) pieces: q(τ) ≈ P(w(τ)), with w(τ) the quintic
        # Hermite of the arc-length reparametrisation's w, w', w'' at both ends
        coef = hermite(Ps[:-1], v0, a0, Ps[1:], v1, a1, h, dp)
        wcoef = hermite(wa[:, None], wd1[:-1, None], wd2[:-1, None], wz[:, None], wd1[1:, None], wd2[1:, None], h)
        tt = tfr[None, :] * h[:, None]
        q = _polyval(coef, tt)
        wc = np.clip(_polyval(wcoef, tt)[..., 0], ev.w0, ev.w1)
        ex = ev.points(wc.ravel()).reshape(wc.shape + (-1,)) * scale
        dev = q - ex
        e_lin = np.sqrt((dev[..., lin] ** 2).sum(axis=-1)).max(axis=1) if lin.any() else np.zeros(h.size)
        e_rot = (np.abs(dev[..., ~lin]) / scale[~lin]).max(axis=(1, 2)) if (~lin).any() else np.zeros(h.size)
        # no stop inside a piece (|dq/dτ| ≈ 1), and w(τ) must run forward
        dq = _polyval(_derivative(coef), tt)
        dw = _polyval(_derivative(wcoef), tt)[..., 0]
        slow = (np.linalg.norm(dq, axis=-1).min(axis=1) < _MIN_PIECE_SPEED) | (dw.min(axis=1) <= 0)
        bad = (e_lin > tl) | (e_rot > tr) | slow
        max_mm, max_deg = float(e_lin.max()), float(e_rot.max())
        if not bad.any():
            break
        if _ == CURVE_MAX_DEPTH:
            ok = False
            break
        mids = 0.5 * (wa[bad] + wz[bad])
        wb = np.sort(np.concatenate((wb, mids)))
    coef = coef / scale[None, None, :]
    coef[0, 0] = curve_start(curve)
    breaks = np.concatenate(([0.0], np.cumsum(h)))
    n = h.size
    return PieceFit(breaks, coef, np.full(n, line, dtype=np.int64), np.full(n, feed), max_mm, max_deg, ok, 0)


def arc_table(pieces, n_axes: int) -> "ArcArrays":
    """The arcs among the curve pieces ``pieces`` (``CurvePiece``, node indices as given) of
    a run on ``n_axes`` linear axes only (scale 1) as arrays (``_arcs.ArcArrays``): what
    ``CurveEval``, ``param_scale`` and ``end_states`` give for each, the same bits, for all
    of them in two compiled calls. Entries that are not arcs, or arcs whose length or end
    speed vanishes (``param_scale`` raises, ``_derivs`` turns to ``_direction``), are not
    ok: the Python code handles those."""
    from ._arcs import ArcArrays, arc_end_derivs, arc_param_scales

    A = len(pieces)
    is_arc = np.array([isinstance(cp.curve, Arc) for cp in pieces], dtype=bool)
    d = n_axes
    first = np.array([cp.first for cp in pieces], dtype=np.int64)
    last = np.array([cp.last for cp in pieces], dtype=np.int64)
    line = np.array([cp.curve.line for cp in pieces], dtype=np.int64)
    arcs = [cp.curve if isinstance(cp.curve, Arc) else None for cp in pieces]
    start = np.zeros((A, d))
    end = np.zeros((A, d))
    center = np.zeros((A, 2))
    plane = np.zeros((A, 2), dtype=np.int64)
    sweep = np.zeros(A)
    for k, c in enumerate(arcs):
        if c is not None:
            start[k], end[k], center[k] = c.start, c.end, c.center
            plane[k] = c.plane[:2]
            sweep[k] = c.sweep_rad
    # CurveEval's constants, elementwise as it computes them
    rows = np.arange(A)
    si, sj = start[rows, plane[:, 0]], start[rows, plane[:, 1]]
    ei, ej = end[rows, plane[:, 0]], end[rows, plane[:, 1]]
    a0 = np.arctan2(sj - center[:, 1], si - center[:, 0])
    r0 = np.hypot(si - center[:, 0], sj - center[:, 1])
    r1 = np.hypot(ei - center[:, 0], ej - center[:, 1])
    nq = np.maximum(1, np.ceil(np.abs(sweep) / (0.5 * np.pi)).astype(np.int64))
    zero = np.zeros(A)
    table = ArcArrays(
        first, last, line, nq, start, end - start, center, plane, sweep, a0, r0, r1, zero, np.zeros((A, 4, d)), is_arc
    )
    g, ok_g = arc_param_scales(table)
    g2 = np.array([v**2 for v in g.tolist()])  # Python's g ** 2 (``_derivs``)
    T, acc, sp, at, ok = arc_end_derivs(table, g, g2, _MIN_SPEED, is_arc & ok_g)
    sp2 = np.array([v**2 for v in sp.ravel().tolist()]).reshape(sp.shape)  # numpy scalars' sp ** 2
    ends = np.empty((A, 4, d))
    ends[:, 0::2] = T
    ends[:, 1::2] = (acc - at[..., None] * T) / sp2[..., None]
    return table._replace(g=g, ends=ends, ok=ok)


def curve_start(curve) -> np.ndarray:
    """The exact first point of a curve (machine units)."""
    if isinstance(curve, Arc):
        return np.asarray(curve.start, dtype=float)
    return CurveEval(curve).points(np.array([CurveEval(curve).w0]))[0]

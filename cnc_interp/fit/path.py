"""``Path``: a piecewise quintic tool path with an accurate arc-length map.

The path is stored like scipy's ``PPoly``: breakpoints ``breaks`` (n_seg+1,) in a
global parameter u, and power-basis coefficients ``coef`` (n_seg, 6, n_axes) in
the local parameter t = u - breaks[k] of each segment::

    q_a(u) = sum_i coef[k, i, a] * t**i,   breaks[k] <= u <= breaks[k+1]

It is evaluated with respect to arc length s, ``path(s, nu)`` for nu = 0..3, by
the chain rule through u(s). Arc length follows LinuxCNC's feed convention: the
Euclidean length of the linear axes' motion (``weights`` = 1 on linear axes),
or of the rotary axes' motion for a path that moves no linear axis.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..constants import (
    ARC_LENGTH_GL_ORDER,
    ARC_LENGTH_MAX_SUB,
    ARC_LENGTH_NEWTON_ITERS,
    ARC_LENGTH_REL_TOL,
    LINEAR_AXES,
)

_GL_X, _GL_W = np.polynomial.legendre.leggauss(ARC_LENGTH_GL_ORDER)


@dataclass(frozen=True)
class PlanarSegments:
    """Paper 000's per-segment data for a planar (2-axis) fit.

    Segment k is the quintic ``p_k(x*) = sum_i p[k, i] x*^i`` on 0 <= x* <= x_end[k]
    in a frame rotated by ``theta[k]`` (rad) about ``origin[k]`` (2,), in the
    plane of machine axes ``plane`` = (horizontal, vertical) indices, e.g. (X, Z):

        q_h = origin_h + x* cos(theta) - p(x*) sin(theta)
        q_v = origin_v + x* sin(theta) + p(x*) cos(theta)

    Shapes: theta (n_seg,), origin (n_seg, 2), x_end (n_seg,), p (n_seg, 6).
    """

    plane: tuple[int, int]
    theta: np.ndarray
    origin: np.ndarray
    x_end: np.ndarray
    p: np.ndarray


@dataclass(frozen=True, eq=False)
class Path:
    """A piecewise quintic path (see module docstring).

    Attributes:
        axes: machine axis letters, e.g. ``"XYZ"``.
        breaks: (n_seg+1,) strictly increasing global parameter values.
        coef: (n_seg, 6, n_axes) power-basis coefficients in t = u - breaks[k];
            mm for linear axes, deg for rotary axes.
        line: (n_seg,) source line of each segment (last block it covers).
        feed_mm_s: (n_seg,) programmed feed limit on each segment, mm/s
            (deg/s for rotary-only paths); ``inf`` for rapids.
        weights: (n_axes,) arc-length metric (1 = axis counts in s, 0 = it does not).
            ``None`` picks LinuxCNC's convention from the motion.
        rapid: True for a G0 move: straight in joint space, no feed limit.
        planar: paper 000's per-segment form when the path came from the planar fit.

    Derived (computed once, on construction):
        s_breaks: (n_seg+1,) arc length at the breakpoints, s_breaks[0] = 0.
        length: total arc length.
    """

    axes: str
    breaks: np.ndarray
    coef: np.ndarray
    line: np.ndarray
    feed_mm_s: np.ndarray
    weights: np.ndarray | None = None
    rapid: bool = False
    planar: PlanarSegments | None = None
    s_breaks: np.ndarray = field(init=False, repr=False)
    length: float = field(init=False)
    _sub_u: np.ndarray = field(init=False, repr=False)
    _sub_s: np.ndarray = field(init=False, repr=False)
    _sub_seg: np.ndarray = field(init=False, repr=False)

    # -- construction ---------------------------------------------------------
    def __post_init__(self) -> None:
        breaks = np.ascontiguousarray(self.breaks, dtype=float)
        coef = np.ascontiguousarray(self.coef, dtype=float)
        n_seg = breaks.shape[0] - 1
        if coef.shape != (n_seg, 6, len(self.axes)):
            raise ValueError(f"coef shape {coef.shape} != ({n_seg}, 6, {len(self.axes)})")
        if n_seg < 1 or not np.all(np.diff(breaks) > 0):
            raise ValueError("breaks must be strictly increasing with at least one segment")
        object.__setattr__(self, "breaks", breaks)
        object.__setattr__(self, "coef", coef)
        object.__setattr__(self, "line", np.asarray(self.line, dtype=np.int64).reshape(n_seg))
        object.__setattr__(self, "feed_mm_s", np.asarray(self.feed_mm_s, dtype=float).reshape(n_seg))
        if self.weights is None:
            object.__setattr__(self, "weights", self._default_weights())
        else:
            object.__setattr__(self, "weights", np.asarray(self.weights, dtype=float))
        self._build_arc_length()

    def _default_weights(self) -> np.ndarray:
        lin = np.array([a in LINEAR_AXES for a in self.axes], dtype=float)
        # total variation bound of each axis: sum of |coefficients| is enough to tell motion apart
        moves = np.abs(self.coef[:, 1:, :]).sum(axis=(0, 1)) > 0
        if np.any(moves & (lin > 0)):
            return lin
        return (1.0 - lin) if np.any(moves) else lin

    @property
    def n_seg(self) -> int:
        return int(self.coef.shape[0])

    @property
    def n_axes(self) -> int:
        return len(self.axes)

    # -- evaluation with respect to the parameter u ----------------------------
    def segment_of_u(self, u: np.ndarray) -> np.ndarray:
        """Segment index (K,) containing each parameter value (clipped to the path)."""
        k = np.searchsorted(self.breaks, u, side="right") - 1
        return np.clip(k, 0, self.n_seg - 1)

    def derivatives_u(self, u: np.ndarray, order: int = 3) -> np.ndarray:
        """q and its u-derivatives up to ``order``: shape (order+1, K, n_axes)."""
        u = np.atleast_1d(np.asarray(u, dtype=float))
        k = self.segment_of_u(u)
        t = (u - self.breaks[k])[:, None]
        c = self.coef[k]  # (K, 6, n)
        out = np.empty((order + 1, u.shape[0], self.n_axes))
        for d in range(order + 1):
            # Horner on the d-th derivative's coefficients
            acc = c[:, 5, :] * _FALLING[d][5]
            for i in range(4, d - 1, -1):
                acc = acc * t + c[:, i, :] * _FALLING[d][i]
            out[d] = acc
        return out

    def _speed_local(self, seg: np.ndarray, t: np.ndarray) -> np.ndarray:
        """|dq/du| in the arc-length metric at local parameter t of segment(s) seg."""
        c = self.coef[seg]  # (..., 6, n)
        tt = t[..., None]
        acc = 5.0 * c[..., 5, :]
        for i in range(4, 0, -1):
            acc = acc * tt + i * c[..., i, :]
        return np.sqrt((acc * acc * self.weights).sum(axis=-1))

    # -- arc length -------------------------------------------------------------
    def _gl_integrals(self, seg: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """∫_a^b speed dt (local t) with one Gauss–Legendre rule per row."""
        half = 0.5 * (b - a)
        mid = 0.5 * (b + a)
        t = mid[:, None] + half[:, None] * _GL_X[None, :]
        sp = self._speed_local(np.broadcast_to(seg[:, None], t.shape), t)
        return half * (sp @ _GL_W)

    @classmethod
    def _from_parts(
        cls,
        axes: str,
        breaks: np.ndarray,
        coef: np.ndarray,
        line: np.ndarray,
        feed_mm_s: np.ndarray,
        weights: np.ndarray,
        rapid: bool,
        planar: PlanarSegments | None,
        sub_u: np.ndarray,
        sub_s: np.ndarray,
        sub_seg: np.ndarray,
        s_breaks: np.ndarray,
    ) -> "Path":
        """A Path whose arrays are already validated and converted (float breaks/coef/
        feed/weights, int64 line, shapes as ``__post_init__`` makes them) and whose
        arc-length table was computed by ``_arclen.arc_length_table`` — the fit stage
        builds the tables of a whole run in one compiled call (``arc_length_tables``)."""
        p = object.__new__(cls)
        # plain instance attributes, as __init__ stores them (one update, not 13 setattrs)
        p.__dict__.update(
            axes=axes,
            breaks=breaks,
            coef=coef,
            line=line,
            feed_mm_s=feed_mm_s,
            weights=weights,
            rapid=rapid,
            planar=planar,
            _sub_u=sub_u,
            _sub_s=sub_s,
            _sub_seg=sub_seg,
            s_breaks=s_breaks,
            length=float(sub_s[-1]),
        )
        return p

    def _build_arc_length(self) -> None:
        from ._arclen import arc_length_table

        sub_u, sub_s, seg, starts = arc_length_table(
            self.coef, self.breaks, self.weights, _GL_X, _GL_W, ARC_LENGTH_REL_TOL, ARC_LENGTH_MAX_SUB
        )
        object.__setattr__(self, "_sub_u", sub_u)
        object.__setattr__(self, "_sub_s", sub_s)
        object.__setattr__(self, "_sub_seg", seg)
        object.__setattr__(self, "s_breaks", sub_s[starts])
        object.__setattr__(self, "length", float(sub_s[-1]))

    def s_of_u(self, u: np.ndarray) -> np.ndarray:
        """Arc length at global parameter values u (vectorised, Gauss–Legendre)."""
        u = np.clip(np.asarray(u, dtype=float), self.breaks[0], self.breaks[-1])
        shape = u.shape
        u = u.reshape(-1)
        i = np.clip(np.searchsorted(self._sub_u, u, side="right") - 1, 0, self._sub_seg.size - 1)
        seg = self._sub_seg[i]
        a = self._sub_u[i] - self.breaks[seg]
        b = u - self.breaks[seg]
        return (self._sub_s[i] + self._gl_integrals(seg, a, b)).reshape(shape)

    def u_of_s(self, s: np.ndarray) -> np.ndarray:
        """Global parameter at arc lengths s (monotone, vectorised; s clipped to [0, length])."""
        s = np.clip(np.asarray(s, dtype=float), 0.0, self.length)
        shape = s.shape
        s = s.reshape(-1)
        n_sub = self._sub_seg.size
        i = np.clip(np.searchsorted(self._sub_s, s, side="right") - 1, 0, n_sub - 1)
        a0 = self._sub_u[i]
        lo, hi = a0, self._sub_u[i + 1]
        s_lo, s_hi = self._sub_s[i], self._sub_s[i + 1]
        span = np.where(s_hi > s_lo, s_hi - s_lo, 1.0)
        u = lo + (hi - lo) * np.clip((s - s_lo) / span, 0.0, 1.0)
        seg = self._sub_seg[i]
        base = self.breaks[seg]
        for _ in range(ARC_LENGTH_NEWTON_ITERS):
            f = s_lo + self._gl_integrals(seg, a0 - base, u - base) - s
            # keep a bracket so that a bad Newton step falls back to bisection
            lo = np.where(f < 0, u, lo)
            hi = np.where(f > 0, u, hi)
            sp = self._speed_local(seg, u - base)
            un = u - f / np.where(sp > 0, sp, np.inf)
            bad = (un < lo) | (un > hi) | ~np.isfinite(un)
            u = np.where(bad, 0.5 * (lo + hi), un)
        return u.reshape(shape)

    # -- evaluation with respect to arc length ------------------------------
    def __call__(self, s, nu: int = 0) -> np.ndarray:
        """Position (nu=0) or nu-th derivative with respect to arc length, nu <= 3.

        ``s`` scalar gives (n_axes,); ``s`` of shape (K,) gives (K, n_axes).
        """
        if nu not in (0, 1, 2, 3):
            raise ValueError("nu must be 0, 1, 2 or 3")
        scalar = np.ndim(s) == 0
        u = self.u_of_s(np.atleast_1d(s))
        out = self.derivatives_s(u, nu)[nu]
        return out[0] if scalar else out

    def derivatives_s(self, u: np.ndarray, order: int = 3) -> np.ndarray:
        """q, q_s, q_ss, q_sss at parameter values u: shape (order+1, K, n_axes)."""
        d = self.derivatives_u(u, max(order, 1))
        q_u = d[1]
        w = self.weights
        sig = np.sqrt((q_u * q_u * w).sum(axis=1))[:, None]
        sig = np.where(sig > 0, sig, np.nan)
        out = np.empty((order + 1,) + d.shape[1:])
        out[0] = d[0]
        if order >= 1:
            out[1] = q_u / sig
        if order >= 2:
            q_uu = d[2]
            dot1 = (q_u * q_uu * w).sum(axis=1)[:, None]
            sig_u = dot1 / sig
            out[2] = q_uu / sig**2 - q_u * sig_u / sig**3
        if order >= 3:
            q_uuu = d[3]
            dot2 = (q_uu * q_uu * w).sum(axis=1)[:, None] + (q_u * q_uuu * w).sum(axis=1)[:, None]
            sig_uu = dot2 / sig - dot1**2 / sig**3
            out[3] = (
                q_uuu / sig**3 - 3.0 * q_uu * sig_u / sig**4 - q_u * sig_uu / sig**4 + 3.0 * q_u * sig_u**2 / sig**5
            )
        return out

    def segment_of_s(self, s: np.ndarray) -> np.ndarray:
        """Segment index (K,) at arc lengths s."""
        k = np.searchsorted(self.s_breaks, s, side="right") - 1
        return np.clip(k, 0, self.n_seg - 1)

    @property
    def start(self) -> np.ndarray:
        return self.coef[0, 0, :].copy()

    @property
    def end(self) -> np.ndarray:
        # Horner on the last segment at its end: the same arithmetic as derivatives_u
        # (called for every path built, so without its general machinery)
        c = self.coef[-1]
        t = self.breaks[-1] - self.breaks[-2]
        acc = c[5] * _FALLING[0][5]
        for i in range(4, -1, -1):
            acc = acc * t + c[i] * _FALLING[0][i]
        return acc


def _ragged_arange(counts: np.ndarray) -> np.ndarray:
    """concatenate([arange(c) for c in counts]) without a Python loop."""
    counts = np.asarray(counts, dtype=np.int64)
    total = int(counts.sum())
    starts = np.cumsum(counts) - counts
    return np.arange(total) - np.repeat(starts, counts)


# _FALLING[d][i] = i! / (i-d)!  (coefficient factor of t^(i-d) in the d-th derivative)
_FALLING = [[0.0] * 6 for _ in range(4)]
for _d in range(4):
    for _i in range(6):
        f = 1.0
        for _m in range(_d):
            f *= _i - _m
        _FALLING[_d][_i] = f if _i >= _d else 0.0

"""Paper 000's planar toolpath generator (de Santiago-Perez et al. 2010), as corrected in DESIGN.md.

For a run that moves exactly two axes (h, v) — XZ on a lathe, or any plane:

1. tangential angle α_i of every chord (atan2, in [-π, π]);
2. a rotated frame θ (a multiple of π/2) per segment. Eq. (1) (with the -π/2
   correction, ``rotation_angle``) assigns each chord the frame that puts its
   inclination α - θ in [-0.04π, 0.49π]. Used as is, a noisy polyline near one of its
   interval ends switches frames from chord to chord, with one-chord segments that
   start on a steep inherited tangent and curvature spikes (measured on quantized
   circles). So the frames are centred (``frame_angle``: |α - θ| <= π/4) and a segment
   keeps its predecessor's frame while the inherited tangent and its first chord stay
   within ±``PLANAR_KEEP_INCLINATION_PI``·π of it (hysteresis);
3. segmentation: maximal groups of consecutive chords within ±``PLANAR_GROUP_INCLINATION_PI``·π
   of the frame (wider than the keep band: a segment that keeps its frame has room);
4. Eq. (2): the group's nodes, translated to the segment's first node and rotated
   by -θ, become (x*, z*) with x* strictly increasing;
5. a quintic p(x*) = Σ a_i x*^i is fitted by least squares to the interior nodes
   with p(0) = 0, p(x_end) = z_end and, after the first segment of a path,
   p'(0) = ρ1, p''(0) = ρ2 taken from the previous segment's end transformed
   between the frames (tangent angle φ → φ + θ_prev - θ, curvature invariant:
   ρ2 = κ (1 + ρ1²)^{3/2}), which makes the path G2. The free end is pulled softly
   (``PLANAR_END_WEIGHT``) towards the slope and curvature of a least-squares
   quadratic through the nodes around it (``PLANAR_END_WINDOW``), which keeps the
   forward propagation of p', p'' from following the coordinate noise;
6. if a node, or a point along a chord (the programmed move: the tolerance bounds
   the distance to it everywhere), is farther than the maximum permissible error the last node is
   dropped and the fit repeated (we gallop then bisect over the number of nodes
   rather than dropping one at a time: the same answer when the error grows with
   the segment, in O(r log r)); the dropped nodes start the next segment.

Before fitting, ``densify_chords`` puts extra nodes on moves that need room for a
short transition (a long line after a finely sampled curve, a coarse polygon whose
curvature would bulge off its chords); a chord that still cannot follow the
curvature it inherits gets more nodes close to its start and the kernel resumes
there (``PLANAR_MAX_RETRIES``), else the caller falls back to the N-axis fitter.

A tiny ∫p'''² term (``PLANAR_SMOOTHING``) keeps a segment with no interior node
well posed. Node deviation is the smaller of the vertical residual and the
distance to a Newton-projected point of the curve (both bound the true distance).

The per-segment data (θ_k, origin_k, x_end_k, a_k) are kept as ``PlanarSegments``
and convert exactly (coefficient-wise) into a ``Path``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..constants import FIT_BETWEEN_NODES_SAFETY, FIT_TOL_SAFETY
from .nodes import segment_sources
from .path import Path, PlanarSegments


#: N-axis / planar fitter: check points per chord are at most this many
FIT_MAX_CHORD_CHECKS = 16

#: planar fit: inclinations are kept within ±this (rad/π) of the frame, as Eq. (1) guarantees
PLANAR_MAX_INCLINATION_PI = 0.49

#: planar fit: a segment keeps its predecessor's frame while the inherited tangent and its
#: first chord stay within ±this (rad/π) of it, else takes the nearest of the frames π/2
#: apart (hysteresis of 0.05π on either side of their π/4 boundary: quantized chords scatter)
PLANAR_KEEP_INCLINATION_PI = 0.3

#: planar fit: a segment takes the chords within ±this (rad/π) of its frame
PLANAR_GROUP_INCLINATION_PI = 0.4

#: planar fit: weight of the ∫p'''² smoothing term relative to the node residuals
PLANAR_SMOOTHING = 1e-6

#: planar fit: weight of the soft end conditions (slope, curvature from the neighbouring
#: nodes) that keep the forward propagation of p', p'' stable; 0 = the paper's bare method
#: (unstable: the fit then falls back to the N-axis fitter). Of 0.06-4, 0.25 gave the
#: shortest cycles over the corpus's two-axis programs at 1 and 2 µm (none better at 10 µm)
PLANAR_END_WEIGHT = 0.25

#: planar fit: the end conditions' tangent and curvature come from a least-squares quadratic
#: over the nodes within ± this fraction of the segment's length around its end node (a
#: three-point estimate on quantized coordinates is off by ~2δ/ℓ² and becomes a spike)
PLANAR_END_WINDOW = 0.25

#: planar fit: check points along a chord per whole segment length (3 more on every chord)
PLANAR_CHECKS_PER_SEGMENT = 32

#: planar fit: a chord longer than this many times its shorter neighbour gets extra nodes at
#: geometrically growing distances from its ends (room for a short curvature transition)
PLANAR_LONG_CHORD_RATIO = 4.0

#: planar fit: most resumptions with extra nodes on a chord that could not be fitted before
#: falling back to the N-axis fitter
PLANAR_MAX_RETRIES = 256


class PlanarNodes(NamedTuple):
    """The nodes of one planar fit (n): horizontal and vertical coordinates ``H``, ``V``
    (n,) in the plane, tolerances ``tol`` (n,), chord angles ``alpha`` (n-1,) and
    cumulative chord lengths ``S`` (n,) (``_chord_frames``)."""

    H: np.ndarray
    V: np.ndarray
    tol: np.ndarray
    alpha: np.ndarray
    S: np.ndarray


class PlanarParams(NamedTuple):
    """The planar method's settings (the module's constants, angles in rad)."""

    w_end: float
    w_win: float
    max_incl: float
    keep: float
    band: float
    mu: float
    per_x: int
    max_checks: int


class PlanarOut(NamedTuple):
    """The segments' output rows (n-1 each): frame angle, first and last node, and the
    six polynomial coefficients in the segment's frame."""

    theta: np.ndarray
    start: np.ndarray
    end: np.ndarray
    b: np.ndarray


class PlanarState(NamedTuple):
    """Where a fit starts: node ``s``, segments ``k`` already in the output, and the state
    the next segment inherits (constrained, tangent angle, curvature, deviation so far)."""

    s: int
    k: int
    constrained: bool
    phi: float
    kappa: float
    max_dev: float


_PARAMS = PlanarParams(
    PLANAR_END_WEIGHT,
    PLANAR_END_WINDOW,
    PLANAR_MAX_INCLINATION_PI * np.pi,
    PLANAR_KEEP_INCLINATION_PI * np.pi,
    PLANAR_GROUP_INCLINATION_PI * np.pi,
    PLANAR_SMOOTHING,
    PLANAR_CHECKS_PER_SEGMENT,
    FIT_MAX_CHORD_CHECKS,
)

_PI = math.pi


@njit(cache=True)
def rotation_angle(alpha):
    """Eq. (1) as corrected in DESIGN.md: θ for a tangential angle α in [-π, π] (the
    paper's frame choice; the fit uses the centred ``frame_angle`` with hysteresis)."""
    if alpha <= -0.51 * _PI:
        return _PI
    if alpha <= -0.02 * _PI:
        return -0.5 * _PI
    if alpha <= 0.47 * _PI:
        return 0.0
    if alpha <= 0.96 * _PI:
        return 0.5 * _PI
    return _PI


@njit(cache=True)
def _wrap(a):
    return _PI - ((_PI - a) % (2.0 * _PI))


@njit(cache=True)
def frame_angle(alpha):
    """The frame the fit uses for a tangent angle α (any real): the multiple of π/2 nearest to α
    (so |α - θ| <= π/4; π rather than -π). Eq. (1)'s intervals are shifted by up to
    0.23π from these: they put inclinations up to 0.47π in a frame (slope 10), where
    an inherited curvature is scaled by (1 + p'²)^{3/2} ~ 1000."""
    q = math.floor(_wrap(alpha) / (0.5 * _PI) + 0.5)
    if q <= -2.0 or q >= 2.0:
        return _PI
    return 0.5 * _PI * q


def rotation_angles(alpha: np.ndarray) -> np.ndarray:
    """Vectorised Eq. (1): θ (K,) for tangential angles α (K,) in [-π, π]."""
    a = np.asarray(alpha, dtype=float)
    return _THETA_OF_BIN[np.searchsorted(_EQ1_EDGES, a, side="left")]


# Eq. (1)'s interval ends (each interval is closed on the right) and θ per interval
_EQ1_EDGES = np.array([-0.51, -0.02, 0.47, 0.96]) * np.pi
_THETA_OF_BIN = np.array([np.pi, -0.5 * np.pi, 0.0, 0.5 * np.pi, np.pi])


def wrap_angle(a):
    """Wrap angles to (-π, π]."""
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=float), 2 * np.pi)


_GLX = np.array([-0.8611363115940526, -0.3399810435848563, 0.3399810435848563, 0.8611363115940526])
_GLW = np.array([0.3478548451374538, 0.6521451548625461, 0.6521451548625461, 0.3478548451374538])


@njit(cache=True)
def _solve_spd(A, rhs, F):
    """Solve A x = rhs in place (x in rhs) for the leading F x F block of a symmetric
    positive definite A (Cholesky; A is overwritten)."""
    for i in range(F):
        s = A[i, i]
        for k in range(i):
            s -= A[i, k] * A[i, k]
        if s <= 0.0:
            s = 1e-300
        A[i, i] = math.sqrt(s)
        for j in range(i + 1, F):
            s = A[j, i]
            for k in range(i):
                s -= A[j, k] * A[i, k]
            A[j, i] = s / A[i, i]
    for i in range(F):
        s = rhs[i]
        for k in range(i):
            s -= A[i, k] * rhs[k]
        rhs[i] = s / A[i, i]
    for i in range(F - 1, -1, -1):
        s = rhs[i]
        for k in range(i + 1, F):
            s -= A[k, i] * rhs[k]
        rhs[i] = s / A[i, i]


@njit(cache=True)
def _fit_segment(xs, zs, constrained, rho1, rho2, mu, b, has_end, d1_est, d2_est, w_end, work):
    """Fit normalised coefficients b (6,) (q(ξ) = Σ b_i ξ^i, ξ = x*/X) to nodes xs, zs (r,)
    (xs[0] = zs[0] = 0, xs[-1] = X > 0). Returns nothing; fills b. ``work`` (8, 4) is
    scratch space (no allocation per fit: this runs tens of thousands of times)."""
    r = xs.shape[0]
    X = xs[r - 1]
    Z = zs[r - 1]
    F = 2 if constrained else 4
    A = work[:4]
    rhs = work[4]
    phi = work[5]
    g1 = work[6]
    g2 = work[7]
    for a in range(F):
        rhs[a] = 0.0
        for c in range(F):
            A[a, c] = 0.0
    # basis of the affine family q = base(ξ) + Σ β_f φ_f(ξ)
    for j in range(1, r - 1):
        xi = xs[j] / X
        x2 = xi * xi
        x3 = x2 * xi
        if constrained:
            b1 = rho1 * X
            b2 = 0.5 * rho2 * X * X
            base = b1 * xi + b2 * x2 + (Z - b1 - b2) * x3
            phi[0] = x3 * xi - x3
            phi[1] = x3 * x2 - x3
        else:
            base = Z * xi
            phi[0] = x2 - xi
            phi[1] = x3 - xi
            phi[2] = x3 * xi - xi
            phi[3] = x3 * x2 - xi
        res = zs[j] - base
        for a in range(F):
            rhs[a] += phi[a] * res
            for c in range(F):
                A[a, c] += phi[a] * phi[c]
    # smoothing: mu ∫_0^1 (q''')^2 dξ, 4-point Gauss-Legendre (exact for degree 4)
    for g in range(4):
        xi = 0.5 * (_GLX[g] + 1.0)
        wq = 0.5 * _GLW[g] * mu
        if constrained:
            b1 = rho1 * X
            b2 = 0.5 * rho2 * X * X
            c0 = 6.0 * (Z - b1 - b2)
            phi[0] = 24.0 * xi - 6.0
            phi[1] = 60.0 * xi * xi - 6.0
        else:
            c0 = 0.0
            phi[0] = 0.0
            phi[1] = 6.0
            phi[2] = 24.0 * xi
            phi[3] = 60.0 * xi * xi
        for a in range(F):
            rhs[a] -= wq * phi[a] * c0
            for c in range(F):
                A[a, c] += wq * phi[a] * phi[c]
    if has_end:
        # soft end conditions: dq/dξ(1) and d²q/dξ²(1) towards the local estimates
        if constrained:
            b1 = rho1 * X
            b2 = 0.5 * rho2 * X * X
            R = Z - b1 - b2
            c1 = b1 + 2.0 * b2 + 3.0 * R
            c2 = 2.0 * b2 + 6.0 * R
            g1[0] = 1.0
            g1[1] = 2.0
            g2[0] = 6.0
            g2[1] = 14.0
        else:
            c1 = Z
            c2 = 0.0
            g1[0] = 1.0
            g1[1] = 2.0
            g1[2] = 3.0
            g1[3] = 4.0
            g2[0] = 2.0
            g2[1] = 6.0
            g2[2] = 12.0
            g2[3] = 20.0
        t1 = d1_est * X - c1
        t2 = d2_est * X * X - c2
        w1 = w_end * w_end
        w2 = w1 / 16.0
        for a in range(F):
            rhs[a] += w1 * g1[a] * t1 + w2 * g2[a] * t2
            for c in range(F):
                A[a, c] += w1 * g1[a] * g1[c] + w2 * g2[a] * g2[c]
    for a in range(F):
        A[a, a] += 1e-12 * (1.0 + A[a, a])
    _solve_spd(A, rhs, F)
    beta = rhs
    b[0] = 0.0
    if constrained:
        b[1] = rho1 * X
        b[2] = 0.5 * rho2 * X * X
        b[4] = beta[0]
        b[5] = beta[1]
        b[3] = Z - b[1] - b[2] - b[4] - b[5]
    else:
        b[2] = beta[0]
        b[3] = beta[1]
        b[4] = beta[2]
        b[5] = beta[3]
        b[1] = Z - b[2] - b[3] - b[4] - b[5]


@njit(cache=True)
def _poly(b, xi):
    return ((((b[5] * xi + b[4]) * xi + b[3]) * xi + b[2]) * xi + b[1]) * xi + b[0]


@njit(cache=True)
def _dpoly(b, xi):
    return (((5 * b[5] * xi + 4 * b[4]) * xi + 3 * b[3]) * xi + 2 * b[2]) * xi + b[1]


@njit(cache=True)
def _ddpoly(b, xi):
    return ((20 * b[5] * xi + 12 * b[4]) * xi + 6 * b[3]) * xi + 2 * b[2]


@njit(cache=True)
def _point_error(b, X, px, pz):
    """An upper bound of the distance from the point (px, pz) (rotated frame, 0 <= px <= X)
    to the curve: the smaller of the vertical residual and the distance to a
    Newton-projected point of the curve."""
    vert = abs(_poly(b, px / X) - pz)
    x = px
    for _ in range(3):
        t = x / X
        p = _poly(b, t)
        dp = _dpoly(b, t) / X
        ddp = _ddpoly(b, t) / (X * X)
        g = (x - px) + (p - pz) * dp
        h = 1.0 + dp * dp + (p - pz) * ddp
        if h <= 0.0:
            break
        x = x - g / h
        if x < 0.0:
            x = 0.0
        if x > X:
            x = X
    p = _poly(b, x / X)
    d = math.sqrt((x - px) ** 2 + (p - pz) ** 2)
    return min(vert, d)


@njit(cache=True)
def _node_error(b, X, xs, zs, j):
    """An upper bound of the distance from node j to the curve (see module docstring)."""
    return _point_error(b, X, xs[j], zs[j])


@njit(cache=True)
def _local_frame(H, V, S, e, h):
    """Tangent angle and signed curvature at node e from a least-squares quadratic
    (H(s), V(s) against chord length s) over the nodes within s_e ± h (at least its two
    neighbours). On a noisy or quantized polyline three-point estimates are off by
    about δ/ℓ and 2δ/ℓ² (δ the coordinate noise, ℓ the chord), which the next segment
    would inherit as a curvature spike; a window that grows with the segment averages
    the noise out where the segment is long. Returns (ok, angle, kappa)."""
    n = H.shape[0]
    lo = e
    while lo > 0 and S[e] - S[lo - 1] <= h:
        lo -= 1
    hi = e
    while hi < n - 1 and S[hi + 1] - S[e] <= h:
        hi += 1
    if lo == e and e > 0:
        lo = e - 1
    if hi == e and e < n - 1:
        hi = e + 1
    if hi - lo < 2:
        return False, 0.0, 0.0
    scale = max(S[e] - S[lo], S[hi] - S[e])
    if not scale > 0.0:
        return False, 0.0, 0.0
    # normal equations of (1, t, t^2), t = (s - s_e) / scale in [-1, 1]
    m0 = 0.0
    m1 = 0.0
    m2 = 0.0
    m3 = 0.0
    m4 = 0.0
    h0 = 0.0
    h1 = 0.0
    h2 = 0.0
    v0 = 0.0
    v1 = 0.0
    v2 = 0.0
    for j in range(lo, hi + 1):
        t = (S[j] - S[e]) / scale
        t2 = t * t
        dh = H[j] - H[e]
        dv = V[j] - V[e]
        m0 += 1.0
        m1 += t
        m2 += t2
        m3 += t2 * t
        m4 += t2 * t2
        h0 += dh
        h1 += dh * t
        h2 += dh * t2
        v0 += dv
        v1 += dv * t
        v2 += dv * t2
    # Cramer's rule for the symmetric 3 x 3 system [[m0 m1 m2] [m1 m2 m3] [m2 m3 m4]]
    c00 = m2 * m4 - m3 * m3
    c01 = m2 * m3 - m1 * m4
    c02 = m1 * m3 - m2 * m2
    c11 = m0 * m4 - m2 * m2
    c12 = m1 * m2 - m0 * m3
    c22 = m0 * m2 - m1 * m1
    det = m0 * c00 + m1 * c01 + m2 * c02
    if not abs(det) > 1e-12 * m0 * m2 * m4:
        return False, 0.0, 0.0
    a1 = (c01 * h0 + c11 * h1 + c12 * h2) / det
    a2 = (c02 * h0 + c12 * h1 + c22 * h2) / det
    b1 = (c01 * v0 + c11 * v1 + c12 * v2) / det
    b2 = (c02 * v0 + c12 * v1 + c22 * v2) / det
    speed2 = a1 * a1 + b1 * b1
    if not speed2 > 0.0:
        return False, 0.0, 0.0
    # curvature of (H, V)(t): (H' V'' - V' H'') / |(H', V')|^3 (any parameter)
    kappa = (a1 * 2.0 * b2 - b1 * 2.0 * a2) / speed2**1.5
    return True, math.atan2(b1, a1), kappa


@njit(cache=True)
def _end_est(e, th, H, V, S, h, max_incl):
    """Local tangent slope and p'' at node e in the frame θ (estimates from the nodes
    within arc length ±h, ``_local_frame``)."""
    n = H.shape[0]
    if e <= 0 or e >= n - 1:
        return False, 0.0, 0.0
    ok, tang, kap = _local_frame(H, V, S, e, h)
    if not ok:
        return False, 0.0, 0.0
    ang = _wrap(tang - th)
    if abs(ang) >= max_incl:
        return False, 0.0, 0.0
    d1 = math.tan(ang)
    return True, d1, kap * (1.0 + d1 * d1) ** 1.5


@njit(cache=True)
def _try(xs, zs, tol, constrained, rho1, rho2, b, e, th, nd, prm, work):
    """Fit and test the segment ending at node e (its rotated nodes xs, zs): True when
    every node and every point along every chord (the programmed moves; the tolerance
    bounds the distance to the programmed path everywhere) is within its tolerance. Stops at
    the first failure, checking from the
    segment's end (where a too long segment fails first); the vertical residual
    bounds the distance, so the Newton projection runs only where it exceeds the
    tolerance. The end is pulled towards the slope and curvature of the nodes within
    ``w_win`` times the segment's length around node e (``_end_est``). ``nd`` the nodes
    (``PlanarNodes``), ``prm`` the settings (``PlanarParams``)."""
    H, V, S = nd.H, nd.V, nd.S
    w_end, w_win, max_incl, _, _, mu, per_x, max_checks = prm
    r = xs.shape[0]
    X = xs[r - 1]
    has, d1, d2 = _end_est(e, th, H, V, S, w_win * X, max_incl)
    _fit_segment(xs, zs, constrained, rho1, rho2, mu, b, has and w_end > 0.0, d1, d2, w_end, work)
    for j in range(r - 1, 0, -1):
        if j < r - 1:
            # node j
            if not abs(_poly(b, xs[j] / X) - zs[j]) <= tol[j] and not _node_error(b, X, xs, zs, j) <= tol[j]:
                return False  # (a NaN fails too)
        # along chord j-1 -> j: more points on a chord that is a larger share of the segment
        dx = xs[j] - xs[j - 1]
        dz = zs[j] - zs[j - 1]
        m = 3 + int(math.ceil(per_x * dx / X))
        if m > max_checks:
            m = max_checks
        tj = tol[j] * FIT_BETWEEN_NODES_SAFETY  # sampled only: keep a margin
        for i in range(1, m + 1):
            f = i / (m + 1.0)
            px = xs[j - 1] + f * dx
            pz = zs[j - 1] + f * dz
            if abs(_poly(b, px / X) - pz) <= tj:
                continue  # the vertical residual already bounds the distance
            if not _point_error(b, X, px, pz) <= tj:
                return False
    return True


@njit(cache=True)
def _rotate(H, V, s, r, n_rot, c, sn, xs_all, zs_all):
    """Eq. (2) for nodes s + n_rot .. s + r - 1 (translate to node s, rotate by -θ);
    returns the new count of rotated nodes."""
    for j in range(s + n_rot, s + r):
        dx = H[j] - H[s]
        dz = V[j] - V[s]
        xs_all[j - s] = dx * c + dz * sn
        zs_all[j - s] = -dx * sn + dz * c
    return max(n_rot, r)


@njit(cache=True)
def planar_fit_kernel(nd, prm, out, next_brk, state):
    """Segment and fit nodes (H, V) (n,); returns (n_seg, status, max_dev, s,
    constrained, phi_abs, kappa): on status 2, the failing segment's first node s and the
    state it inherits, from which a call with s0..kappa0 (and out_* rows < n_seg kept)
    resumes after nodes were inserted behind s.

    status 0 = ok; 1 = an inherited tangent cannot be represented in the next frame;
    2 = a single chord cannot be fitted within the tolerance (an inherited curvature
    too strong for it): the caller falls back to the N-axis fitter.
    out_* are preallocated with n-1 rows; segment k covers nodes out_start[k]..out_end[k].
    ``next_brk`` (n,): for every node the next node at which a segment must end (a
    change of the programmed feed: no segment straddles one), n - 1 if none.

    nd: the nodes and their chord frames (``PlanarNodes``); prm: the settings
    (``PlanarParams``); out: the output rows (``PlanarOut``); state: where to start
    (``PlanarState``: all zero for a fresh fit).
    """
    H, V, tol, alpha = nd.H, nd.V, nd.tol, nd.alpha
    max_incl, keep, band = prm.max_incl, prm.keep, prm.band
    out_theta, out_start, out_end, out_b = out
    s0, k0, constrained0, phi0, kappa0, max_dev0 = state
    n = H.shape[0]
    s = s0
    k = k0
    constrained = constrained0
    rho1 = 0.0
    rho2 = 0.0
    max_dev = max_dev0
    b = np.zeros(6)
    bt = np.zeros(6)
    work = np.zeros((8, 4))
    xs_all = np.empty(n)
    zs_all = np.empty(n)
    phi_abs = phi0
    kappa = kappa0
    th = out_theta[k0 - 1] if k0 > 0 else 0.0
    g_th = np.nan  # the frame and group end of the last scan (valid for any s before it)
    g_cached = -1
    while s < n - 1:
        if constrained:
            # keep the previous frame while the inherited tangent and the next chord stay
            # within ±keep of it. Eq. (1) has no hysteresis: on a noisy polyline near one
            # of its interval ends the frame flips from chord to chord, every segment is
            # one or two chords long and starts with a steep inherited tangent, and the
            # curvature spikes
            if not (abs(_wrap(phi_abs - th)) <= keep and abs(_wrap(alpha[s] - th)) <= keep):
                th = frame_angle(phi_abs)
                if abs(_wrap(alpha[s] - th)) >= max_incl:
                    th = frame_angle(alpha[s])
                    if abs(_wrap(phi_abs - th)) > max_incl:
                        return k, 1, max_dev, s, constrained, phi_abs, kappa
            # the inherited tangent in this frame (DESIGN.md: the tangent angle rotates,
            # the curvature is invariant)
            phi = _wrap(phi_abs - th)
            rho1 = math.tan(phi)
            rho2 = kappa * (1.0 + rho1 * rho1) ** 1.5
        else:
            th = frame_angle(alpha[s])
        # the group: chord s and the following chords within ±band of the frame (wider
        # than ±keep, so that a segment that keeps its frame has room to grow)
        if th == g_th and s < g_cached:
            g_end = g_cached
        else:
            g_end = s + 1
            while g_end < n - 1 and abs(_wrap(alpha[g_end] - th)) <= band:
                g_end += 1
            g_th = th
            g_cached = g_end
        if g_end > next_brk[s]:
            g_end = next_brk[s]  # a segment ends where the programmed feed changes
        c = math.cos(th)
        sn = math.sin(th)
        # Eq. (2) for the nodes s..s+n_rot-1 (rotated on demand: a group can hold many
        # more nodes than the segment that starts it)
        n_rot = 0
        tl = tol[s : g_end + 1]
        # gallop: largest e with a passing fit, e in [s+1, g_end]; b keeps the fit of
        # the largest passing e tried (the same fit the accepted segment gets)
        lo = s + 1
        lo_fit = False
        hi = g_end + 1  # first known failing end (exclusive bound)
        step = 2
        e = min(s + step, g_end)
        while True:
            if e <= lo:
                break
            r = e - s + 1
            n_rot = _rotate(H, V, s, r, n_rot, c, sn, xs_all, zs_all)
            if _try(xs_all[:r], zs_all[:r], tl[:r], constrained, rho1, rho2, bt, e, th, nd, prm, work):
                lo = e
                lo_fit = True
                b[:] = bt
                if e == g_end:
                    break
                step *= 2
                e = min(s + step, g_end)
            else:
                hi = e
                break
        while hi - lo > 1:
            mid = (lo + hi) // 2
            r = mid - s + 1
            n_rot = _rotate(H, V, s, r, n_rot, c, sn, xs_all, zs_all)
            if _try(xs_all[:r], zs_all[:r], tl[:r], constrained, rho1, rho2, bt, mid, th, nd, prm, work):
                lo = mid
                lo_fit = True
                b[:] = bt
            else:
                hi = mid
        e = lo
        r = e - s + 1
        n_rot = _rotate(H, V, s, r, n_rot, c, sn, xs_all, zs_all)
        if not lo_fit:
            # a single chord (never tried yet)
            if not _try(xs_all[:r], zs_all[:r], tl[:r], constrained, rho1, rho2, bt, e, th, nd, prm, work):
                return k, 2, max_dev, s, constrained, phi_abs, kappa
            b[:] = bt
        X = xs_all[r - 1]
        for j in range(1, r - 1):
            d = _node_error(b, X, xs_all[:r], zs_all[:r], j)
            if d > max_dev:
                max_dev = d
        out_theta[k] = th
        out_start[k] = s
        out_end[k] = e
        for i in range(6):
            out_b[k, i] = b[i] / X**i
        k += 1
        if e >= n - 1:
            break
        # hand the end tangent angle (absolute) and curvature to the next segment
        p1 = _dpoly(b, np.float64(1.0)) / X
        p2 = _ddpoly(b, np.float64(1.0)) / (X * X)
        kappa = p2 / (1.0 + p1 * p1) ** 1.5
        phi_abs = math.atan(p1) + th
        constrained = True
        s = e
    return k, 0, max_dev, s, constrained, phi_abs, kappa


@njit(cache=True)
def node_curvatures(H, V):
    """Signed curvature (1/mm) at every node from its two neighbours (Menger curvature);
    zeros at the ends. (``densify_chords`` only needs its order of magnitude; the fit's
    end conditions use ``_local_frame``.)"""
    n = H.shape[0]
    kap = np.zeros(n)
    for j in range(1, n - 1):
        ax = H[j] - H[j - 1]
        az = V[j] - V[j - 1]
        bx = H[j + 1] - H[j]
        bz = V[j + 1] - V[j]
        la = math.sqrt(ax * ax + az * az)
        lb = math.sqrt(bx * bx + bz * bz)
        ax /= la
        az /= la
        bx /= lb
        bz /= lb
        span = math.hypot(H[j + 1] - H[j - 1], V[j + 1] - V[j - 1])
        if span > 0.0:
            kap[j] = 2.0 * (ax * bz - az * bx) / span
    return kap


def fit_planar(
    nodes: np.ndarray,
    plane: tuple[int, int],
    tol_mm: np.ndarray,
    axes: str,
    line: np.ndarray,
    feed: np.ndarray,
    weights: np.ndarray | None = None,
):
    """Fit a 2-axis polyline (n, n_axes) in ``plane`` = (h, v) axis indices.

    Returns ``(planar, coef, line, feed_mm_s, max_dev_mm)`` (build the ``Path`` with
    ``planar_to_path`` or from ``coef`` and ``breaks_of(planar)``), or ``None`` when
    the method cannot continue (an inherited tangent outside the next frame's
    ±0.49π, or a chord that cannot be followed within the tolerance even after
    ``PLANAR_MAX_RETRIES`` rounds of extra nodes there); the caller then uses the
    N-axis fitter. Extra nodes on the programmed moves (``densify_chords``) give the
    segments room for short transitions; the tolerance holds along every move.
    """
    h, v = plane
    nodes, line, feed, tol_mm = densify_chords(
        nodes, plane, line, feed, np.asarray(tol_mm, dtype=float) * FIT_TOL_SAFETY
    )
    tol_mm = tol_mm / FIT_TOL_SAFETY
    state = (0, 0, False, 0.0, 0.0, 0.0)  # PlanarState of a fresh fit
    kept = None
    last_fail = -1
    for attempt in range(PLANAR_MAX_RETRIES + 1):
        H = np.ascontiguousarray(nodes[:, h], dtype=float)
        V = np.ascontiguousarray(nodes[:, v], dtype=float)
        n = H.size
        alpha, S = _chord_frames(H, V)
        tol = np.asarray(tol_mm, dtype=float) * FIT_TOL_SAFETY
        out_theta = np.empty(n - 1)
        out_start = np.empty(n - 1, dtype=np.int64)
        out_end = np.empty(n - 1, dtype=np.int64)
        out_b = np.empty((n - 1, 6))
        if kept is not None:  # segments accepted before the insertion stay as they are
            k0 = kept[0].size
            out_theta[:k0], out_start[:k0], out_end[:k0], out_b[:k0] = kept
        k, status, max_dev, s_fail, cons, phi_abs, kappa = planar_fit_kernel(
            PlanarNodes(H, V, tol, alpha, S),
            _PARAMS,
            PlanarOut(out_theta, out_start, out_end, out_b),
            feed_breaks(feed),
            PlanarState(*state),
        )
        if status != 2 or attempt == PLANAR_MAX_RETRIES or s_fail == last_fail:
            break
        # the chord after node s_fail cannot follow the curvature it inherits: nodes on it
        # close to s_fail (only behind it: the accepted segments keep their nodes) let a
        # segment end soon after s_fail; then resume from there
        last_fail = s_fail
        kept = (out_theta[:k].copy(), out_start[:k].copy(), out_end[:k].copy(), out_b[:k].copy())
        state = (s_fail, k, cons, phi_abs, kappa, max_dev)
        nodes, line, feed, tol_mm = _insert_after(nodes, line, feed, tol_mm, s_fail)
    if status != 0:
        return None
    theta = out_theta[:k].copy()
    st, en = out_start[:k], out_end[:k]
    origin = np.empty((st.size, 2))  # np.stack([H[st], V[st]], axis=1) without its overhead
    origin[:, 0] = H[st]
    origin[:, 1] = V[st]
    c, s_ = np.cos(theta), np.sin(theta)
    x_end = (H[en] - H[st]) * c + (V[en] - V[st]) * s_
    planar = PlanarSegments(plane=(h, v), theta=theta, origin=origin, x_end=x_end, p=out_b[:k].copy())

    breaks = np.concatenate(([0.0], np.cumsum(x_end)))
    u = _node_params(H, V, st, en, c, s_, breaks)
    seg_line, seg_feed = segment_sources(breaks, u, line, feed)
    return planar, planar_coef(planar, nodes[0], len(axes)), seg_line, seg_feed, float(max_dev)


def feed_breaks(feed: np.ndarray) -> np.ndarray:
    """For every node (n,) the next node after it where the programmed feed changes
    (``feed[j]`` is the move ending at node j), n - 1 if none: the nodes where a
    segment must end so that each segment keeps its own move's feed."""
    f = np.asarray(feed, dtype=float)
    n = f.size
    brk = np.nonzero(f[1:-1] != f[2:])[0] + 1 if n > 2 else np.zeros(0, dtype=np.int64)
    stops = np.concatenate((brk, [n - 1])).astype(np.int64)
    return stops[np.searchsorted(stops, np.arange(n), side="right").clip(max=stops.size - 1)]


@njit(cache=True)
def _chord_frames(H, V):
    """Per chord the tangential angle α (n-1,), per node the cumulated chord length (n,)."""
    n = H.shape[0]
    alpha = np.empty(n - 1)
    S = np.empty(n)
    S[0] = 0.0
    for j in range(n - 1):
        alpha[j] = math.atan2(V[j + 1] - V[j], H[j + 1] - H[j])
        S[j + 1] = S[j] + math.hypot(H[j + 1] - H[j], V[j + 1] - V[j])
    return alpha, S


@njit(cache=True)
def _node_params(H, V, st, en, c, s, breaks):
    """Path parameter (n,) of every node: x* of the node inside its segment (start st,
    end en, frame cos c / sin s) offset by the segment's break, the segment ends
    exactly on the breaks, made non-decreasing."""
    n = H.shape[0]
    u = np.empty(n)
    u[0] = 0.0
    for k in range(st.shape[0]):
        for i in range(st[k] + 1, en[k] + 1):
            u[i] = breaks[k] + (H[i] - H[st[k]]) * c[k] + (V[i] - V[st[k]]) * s[k]
        u[en[k]] = breaks[k + 1]
    for i in range(1, n):
        if u[i] < u[i - 1]:
            u[i] = u[i - 1]
    return u


def densify_chords(nodes: np.ndarray, plane: tuple[int, int], line: np.ndarray, feed: np.ndarray, tol_mm: np.ndarray):
    """Extra nodes on the programmed moves where the fit needs room for a short transition.

    At each end of a chord a first distance l is chosen: the neighbouring chord's length
    when the chord is more than ``PLANAR_LONG_CHORD_RATIO`` times longer (a line after a
    finely sampled curve), and sqrt(tol / (2 κ)) when the curvature κ estimated at that
    node would bend a curve off the chord by more than the tolerance (a coarse polygon);
    nodes go at l, 2l, 4l... from that end up to the chord's middle. They lie on the
    move, so the fit can keep it straight, and a segment can end shortly after the
    junction: an inherited curvature then fades within the tolerance instead of
    bending the whole move. Inserted nodes take the move's line, feed and tolerance.
    Returns (nodes, line, feed, tol_mm) with M >= n rows."""
    n = nodes.shape[0]
    if n < 2:
        return nodes, line, feed, tol_mm
    src, frac = _densify_plan(
        np.ascontiguousarray(nodes[:, plane[0]], dtype=float),
        np.ascontiguousarray(nodes[:, plane[1]], dtype=float),
        np.ascontiguousarray(tol_mm, dtype=float),
        PLANAR_LONG_CHORD_RATIO,
    )
    if src.size == n:
        return nodes, line, feed, tol_mm
    out, take = _densify_nodes(np.ascontiguousarray(nodes, dtype=float), src, frac)
    return (out, np.asarray(line)[take], np.asarray(feed, dtype=float)[take], np.asarray(tol_mm, dtype=float)[take])


@njit(cache=True)
def _densify_nodes(nodes, src, frac):
    """Rows of ``densify_chords``: an inserted node (frac > 0) lies on the move
    src -> src + 1 and takes that move's data (row ``take`` of line, feed, tol)."""
    M = src.shape[0]
    d = nodes.shape[1]
    out = np.empty((M, d))
    take = np.empty(M, dtype=np.int64)
    for i in range(M):
        j = src[i]
        f = frac[i]
        if f > 0.0:
            for a in range(d):
                out[i, a] = nodes[j, a] + (nodes[j + 1, a] - nodes[j, a]) * f
            take[i] = j + 1
        else:
            for a in range(d):
                out[i, a] = nodes[j, a]
            take[i] = j
    return out, take


@njit(cache=True)
def _densify_plan(H, V, tol_mm, long_ratio):
    """Where ``densify_chords`` puts its nodes: for every output row the source node j
    and the fraction f along the move j -> j+1 (0 for an original node), in path order."""
    n = H.shape[0]
    clen = np.empty(n - 1)
    for j in range(n - 1):
        clen[j] = math.hypot(H[j + 1] - H[j], V[j + 1] - V[j])
    kap = node_curvatures(H, V)
    # first distance from each end of each chord (inf: no extra nodes from that end)
    first = np.empty((n - 1, 2))
    total = n
    for j in range(n - 1):
        L = clen[j]
        tol = tol_mm[j + 1]
        for side in range(2):
            nb = np.inf
            if side == 0 and j > 0:
                nb = clen[j - 1]
            elif side == 1 and j < n - 2:
                nb = clen[j + 1]
            k_end = abs(kap[j + side])
            ell = nb if L > long_ratio * nb else np.inf
            # a circle of curvature κ leaves its tangent by κ d² / 2 after a distance d
            if k_end * L * L / 8.0 > 0.25 * tol:
                ell = min(ell, math.sqrt(0.5 * tol / max(k_end, 1e-300)))
            first[j, side] = min(ell, 0.5 * L)
        if first[j, 0] < 0.5 * L or first[j, 1] < 0.5 * L:
            total += 1 + _n_geometric(first[j, 0], L) + _n_geometric(first[j, 1], L)
    src = np.empty(total, dtype=np.int64)
    frac = np.zeros(total)
    m = 0
    for j in range(n - 1):
        src[m] = j
        m += 1
        L = clen[j]
        if not (first[j, 0] < 0.5 * L or first[j, 1] < 0.5 * L):
            continue
        ell = first[j, 0]
        for i in range(_n_geometric(ell, L)):
            src[m] = j
            frac[m] = ell * 2.0**i / L
            m += 1
        src[m] = j
        frac[m] = 0.5
        m += 1
        ell = first[j, 1]
        for i in range(_n_geometric(ell, L) - 1, -1, -1):
            src[m] = j
            frac[m] = 1.0 - ell * 2.0**i / L
            m += 1
    src[m] = n - 1
    return src, frac


@njit(cache=True)
def _n_geometric(ell, L):
    """Number of distances ell * 2^i (i = 0, 1, ...) below L / 2."""
    c = 0
    if not ell < 0.5 * L:
        return 0
    x = ell
    while x / L < 0.5:
        c += 1
        x = ell * 2.0**c
    return c


def _insert_after(nodes, line, feed, tol_mm, j):
    """Nodes on the move out of node j at 1/4, 1/8 ... 1/1024 of its length from j."""
    f = 2.0 ** -np.arange(2, 11)[::-1]
    new = nodes[j] + (nodes[j + 1] - nodes[j]) * f[:, None]
    m = f.size

    def ins(a, b):
        return np.concatenate((a[: j + 1], b, a[j + 1 :]))

    line = np.asarray(line)
    feed = np.asarray(feed, dtype=float)
    tol_mm = np.asarray(tol_mm, dtype=float)
    return (
        ins(nodes, new),
        ins(line, np.full(m, line[j + 1])),
        ins(feed, np.full(m, feed[j + 1])),
        ins(tol_mm, np.full(m, tol_mm[j + 1])),
    )


def planar_to_path(
    planar: PlanarSegments,
    fixed: np.ndarray,
    axes: str,
    line: np.ndarray,
    feed_mm_s: np.ndarray,
    weights: np.ndarray | None = None,
) -> Path:
    """Exact coefficient-wise conversion of planar segments into a ``Path``.

    ``fixed`` (n_axes,) gives the constant value of every axis outside the plane.
    """
    return Path(
        axes=axes,
        breaks=breaks_of(planar),
        coef=planar_coef(planar, fixed, len(axes)),
        line=line,
        feed_mm_s=feed_mm_s,
        weights=weights,
        planar=planar,
    )


def breaks_of(planar: PlanarSegments) -> np.ndarray:
    """Path breakpoints of planar segments: the cumulated x_end."""
    return np.concatenate(([0.0], np.cumsum(planar.x_end)))


def planar_coef(planar: PlanarSegments, fixed: np.ndarray, n_axes: int) -> np.ndarray:
    """Power-basis coefficients (n_seg, 6, n_axes) of planar segments.

    Segment k's local parameter is x* in [0, x_end[k]]:
    q_h = o_h + x* cos θ - p(x*) sin θ,  q_v = o_v + x* sin θ + p(x*) cos θ.
    """
    h, v = planar.plane
    n_seg = planar.theta.size
    coef = np.zeros((n_seg, 6, n_axes))
    coef[:, 0, :] = fixed[None, :]
    c = np.cos(planar.theta)[:, None]
    s = np.sin(planar.theta)[:, None]
    p = planar.p
    coef[:, :, h] = -p * s
    coef[:, :, v] = p * c
    coef[:, 0, h] += planar.origin[:, 0]
    coef[:, 0, v] += planar.origin[:, 1]
    coef[:, 1, h] += c[:, 0]
    coef[:, 1, v] += s[:, 0]
    return coef

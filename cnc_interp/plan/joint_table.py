"""The joint table every sampled planner follows: the joint positions along a path as
quintic Hermite pieces in arc length (``JointTable``), built to ``VPOP_TABLE_TOL`` of the
true path.

VPOp, the optimal planner and the safe planner sample the same table (so that one
planner can finish another's plan exactly); it lives outside each of them so that none
imports another for it. The knots are exact path points and the last one is the exact
programmed end; the compiled build for identity kinematics is ``plan._table_kernels``
(through ``vpop.drive.prepare_identity``), the build through a joint map is here.
"""

from __future__ import annotations

import numpy as np

from ..errors import PlanError

#: largest deviation of VPOp's arc-length joint table from the true path (mm or deg)
VPOP_TABLE_TOL = 1e-9

#: longest piece of that table before refinement (mm or deg of arc length)
VPOP_TABLE_MAX_PIECE = 20.0

#: refinement rounds of the table (each halves the pieces that miss VPOP_TABLE_TOL)
VPOP_TABLE_MAX_ROUNDS = 12

#: Gauss–Legendre points per quarter piece for the table's arc lengths
VPOP_TABLE_GL_ORDER = 10

#: refinement passes of the table: when scaling it to the path's length pushes a piece
#: that passed its check over VPOP_TABLE_TOL, it is refined again against that scale
VPOP_TABLE_MAX_TRIES = 3


# -- the arc-length table -------------------------------------------------------
def _joint_derivs(path, u: np.ndarray, joint_map) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q, q_s, q_ss (each (K, n)) in joint space at parameter values u."""
    d = path.derivatives_s(u, 2)
    p, ps, pss = d[0], d[1], d[2]
    identity = joint_map is None or getattr(joint_map, "is_identity", False)
    if identity:
        return p, ps, pss
    q = joint_map.to_joints(p)
    jac = getattr(joint_map, "jacobian", None)
    if jac is None:
        raise PlanError("kinematics without a jacobian cannot be planned by VPOp")
    J = jac(p)
    qs = np.einsum("kij,kj->ki", J, ps)
    # directional derivative of J along p_s by a central difference
    h = 1e-4
    Jp = jac(p + h * ps)
    Jm = jac(p - h * ps)
    dJ = (Jp - Jm) / (2 * h)
    qss = np.einsum("kij,kj->ki", J, pss) + np.einsum("kij,kj->ki", dJ, ps)
    return q, qs, qss


_GL_X, _GL_W = np.polynomial.legendre.leggauss(VPOP_TABLE_GL_ORDER)


def identity_table_settings(tol: float = VPOP_TABLE_TOL) -> tuple:
    """The settings ``_table_kernels.build_identity`` takes after a path's arrays: (tol,
    max_depth, max_piece, Gauss-Legendre points, weights, max_tries), as ``JointTable``
    builds its tables."""
    return (float(tol), VPOP_TABLE_MAX_ROUNDS - 1, float(VPOP_TABLE_MAX_PIECE), _GL_X, _GL_W, VPOP_TABLE_MAX_TRIES)


def concat_paths(paths) -> tuple:
    """The arrays of ``paths`` end to end, for one compiled call over all of them: (coef
    (Σ n_seg, 6, n), breaks and s_breaks (n_seg + 1 per path), weights (P, n), lengths (P,),
    feed (Σ n_seg,) mm/s, seg_off (P + 1,): path i's segments are seg_off[i]:seg_off[i+1])."""
    n_seg = np.array([p.n_seg for p in paths], dtype=np.int64)
    seg_off = np.zeros(len(paths) + 1, dtype=np.int64)
    np.cumsum(n_seg, out=seg_off[1:])
    return (
        np.concatenate([p.coef for p in paths]),
        np.concatenate([p.breaks for p in paths]),
        np.concatenate([p.s_breaks for p in paths]),
        np.array([p.weights for p in paths], dtype=float),
        np.array([p.length for p in paths], dtype=float),
        np.concatenate([p.feed_mm_s for p in paths]),
        seg_off,
    )


def _kernels():
    from . import _table_kernels

    return _table_kernels


def _hermite(S, Q, Q1, Q2) -> np.ndarray:
    """Quintic Hermite power coefficients (m, 6, n) in s - S[p] for each piece."""
    h = np.diff(S)[:, None]
    c0, c1, c2 = Q[:-1], Q1[:-1], 0.5 * Q2[:-1]
    d0 = Q[1:] - (c0 + h * (c1 + h * c2))
    d1 = Q1[1:] - (c1 + 2.0 * h * c2)
    d2 = Q2[1:] - 2.0 * c2
    c3 = (20.0 * d0 - 8.0 * d1 * h + d2 * h * h) / (2.0 * h**3)
    c4 = (-30.0 * d0 + 14.0 * d1 * h - 2.0 * d2 * h * h) / (2.0 * h**4)
    c5 = (12.0 * d0 - 6.0 * d1 * h + d2 * h * h) / (2.0 * h**5)
    return np.ascontiguousarray(np.stack([c0, c1, c2, c3, c4, c5], axis=1))


def _eval_table(S, C, s):
    """Table positions (K, n) at arc lengths s (K,)."""
    p = np.clip(np.searchsorted(S, s, side="right") - 1, 0, C.shape[0] - 1)
    t = (s - S[p])[:, None]
    c = C[p]
    acc = c[:, 5]
    for i in range(4, -1, -1):
        acc = acc * t + c[:, i]
    return acc


def _refine_mapped(path, joint_map, tol: float, scale: float, max_depth: int):
    """Bisection of the initial pieces through the kinematics, one round per depth.

    Same pieces and checks as ``_table_kernels._refine`` (which serves the identity
    case in one compiled pass); only the pieces split in a round are recomputed in
    the next. Returns the accepted pieces in path order: ua, ub, seg, depth, ds
    (unscaled arc length), off (m, 3) arc length to the quarter points, qc (m, 3, n)
    joint positions there, and the local deviation found.
    """
    K = _kernels()
    coef, breaks, w = path.coef, path.breaks, path.weights
    n = path.n_axes
    ua, ub, seg = K.initial_pieces(breaks, path.s_breaks, VPOP_TABLE_MAX_PIECE)
    dep = np.zeros(ua.shape[0], dtype=np.int64)
    done = []
    while ua.shape[0]:
        uc, sub = K.quarter_arcs(coef, breaks, w, seg, ua, ub, _GL_X, _GL_W)
        ds = ((sub[:, 0] + sub[:, 1]) + sub[:, 2]) + sub[:, 3]
        keep = ds > 0  # pieces of zero length are dropped (the path stands still there)
        if not keep.all():
            ua, ub, seg, dep, uc, sub, ds = (x[keep] for x in (ua, ub, seg, dep, uc, sub, ds))
        off = np.cumsum(sub[:, :3], axis=1)
        qa = np.stack(_joint_derivs(path, ua, joint_map), axis=1)  # (K, 3, n)
        qb = np.stack(_joint_derivs(path, ub, joint_map), axis=1)
        qc = np.ascontiguousarray(_positions(path, uc.reshape(-1), joint_map).reshape(-1, 3, n))
        err = K.piece_errors(ds * scale, qa, qb, off * scale, qc)
        mid = 0.5 * (ua + ub)
        split = ~(err <= tol) & (dep < max_depth) & (ua < mid) & (mid < ub)
        ok = ~split
        done.append((ua[ok], ub[ok], seg[ok], dep[ok], ds[ok], off[ok], qc[ok], err[ok]))
        mid = mid[split]
        ua = np.concatenate((ua[split], mid))
        ub = np.concatenate((mid, ub[split]))
        seg = np.concatenate((seg[split], seg[split]))
        dep = np.concatenate((dep[split], dep[split])) + 1
    parts = [np.concatenate(x) for x in zip(*done)]
    order = np.argsort(parts[0], kind="stable")  # pieces do not overlap: u order is path order
    return [np.ascontiguousarray(x[order]) for x in parts]


def _build_mapped(path, joint_map, tol: float, max_depth: int):
    """(u, S, C, err) of the table through non-identity kinematics (see ``JointTable``)."""
    K = _kernels()
    tol_in, sc_in = tol, 1.0
    for _ in range(VPOP_TABLE_MAX_TRIES):
        ua, ub, seg, dep, ds, off, qc, e_loc = _refine_mapped(path, joint_map, tol_in, sc_in, max_depth)
        if ds.size == 0 or not ds.sum() > 0:
            _no_length(path)
        scale = path.length / ds.sum()
        S = np.concatenate(([0.0], np.cumsum(ds * scale)))
        S[-1] = path.length
        u = np.concatenate((ua, ub[-1:]))
        Q = np.stack(_joint_derivs(path, u, joint_map), axis=1)  # (m+1, 3, n)
        C, err = K.hermite_check(S, Q, np.ascontiguousarray(off * scale), qc)
        over = (e_loc <= tol_in) & (dep < max_depth) & ~(err <= tol)
        if not over.any():
            break
        if scale != sc_in:  # check again against the scale the table gets
            sc_in = scale
        else:  # rounding (S is summed along the path): fail those pieces locally next time
            excess = float(np.max(err[over] - tol))
            low = float(np.min(e_loc[over])) * (1.0 - 1e-9)
            tol_in = max(min(tol_in - 2.0 * excess, low), 0.5 * tol_in)
    return u, S, C, err


def _no_length(path):
    raise PlanError(
        f"bug: the path ending at line {int(path.line[-1])} has length {path.length:g} but no measurable arc length"
    )


class JointTable:
    """q(s) of one path as quintic pieces: knots ``S`` (m+1,), coefficients ``C`` (m, 6, n),
    exact end point ``qend`` (n,), and the largest deviation found at the check points
    ``max_err`` (mm / deg).

    Construction: the path's segments are cut into pieces of at most
    ``VPOP_TABLE_MAX_PIECE`` of arc length, and each piece is bisected in u until its
    quintic Hermite interpolant (ends: exact q, q_s, q_ss at path points) is within
    ``tol`` of the true path at its three quarter points, at most
    ``VPOP_TABLE_MAX_ROUNDS - 1`` times. Arc lengths come from a Gauss–Legendre rule
    (``VPOP_TABLE_GL_ORDER`` points) on each quarter of each piece, computed once per
    piece, and are scaled by one factor so that the last knot is ``path.length``
    exactly; the checks are repeated on that final table, and ``max_err`` is their
    largest result. Identity kinematics runs in one compiled pass
    (``_table_kernels.build_identity``), other kinematics round by round.
    """

    def __init__(self, path, joint_map, tol: float = VPOP_TABLE_TOL):
        max_depth = VPOP_TABLE_MAX_ROUNDS - 1
        identity = joint_map is None or getattr(joint_map, "is_identity", False)
        if identity:  # one compiled call (per-path overhead matters: CAM has 1e5 paths)
            K = _kernels()
            status, u, S, C, max_err, qend = K.build_identity(
                path.coef, path.breaks, path.s_breaks, path.weights, float(path.length), *identity_table_settings(tol)
            )
            if status == K.NO_LENGTH:
                _no_length(path)
            finite = status != K.NOT_FINITE
        else:
            u, S, C, err = _build_mapped(path, joint_map, float(tol), max_depth)
            qend = np.ascontiguousarray(_positions(path, path.breaks[-1:], joint_map)[0])
            max_err = float(err.max()) if err.size else 0.0
            finite = bool(np.all(np.isfinite(C)))
        if not finite:
            raise PlanError(
                f"bug: the arc-length table of the path ending at line "
                f"{int(path.line[-1])} is not finite (a point of zero speed?)"
            )
        self.u = u
        self.S = S
        self.C = C
        self.qend = qend
        self.qstart = C[0, 0].copy()
        self.max_err = float(max_err)
        self.length = float(path.length)

    def curvature_bounds(self, al: np.ndarray, jl: np.ndarray):
        """Per piece: max_i |q_ss,i|/al_i, max_i |q_sss,i|/jl_i and max_i 3|q_ss,i|/jl_i,
        sampled at five points of the piece with a 25% margin (step units)."""
        al = np.ascontiguousarray(al, dtype=float)
        jl = np.ascontiguousarray(jl, dtype=float)
        return _kernels().curvature_bounds(self.S, self.C, al, jl)

    def speed_bounds(self, vl: np.ndarray, path, feed_step: np.ndarray) -> np.ndarray:
        """Per piece: the largest of max_i |q_s,i|/vl_i (sampled, 2% margin) and
        1/(feed step) of its path segment; d1 times it must stay <= 1 (step units)."""
        kv = _kernels().speed_bound(self.S, self.C, np.ascontiguousarray(vl, dtype=float))
        seg = path.segment_of_s(0.5 * (self.S[:-1] + self.S[1:]))
        kf = 1.0 / feed_step[seg]
        return np.ascontiguousarray(np.maximum(kv, kf))


def _positions(path, u, joint_map):
    p = path.derivatives_u(np.asarray(u, dtype=float), 0)[0]
    if joint_map is None or getattr(joint_map, "is_identity", False):
        return p
    return joint_map.to_joints(p)


# -- the planner --------------------------------------------------------------------

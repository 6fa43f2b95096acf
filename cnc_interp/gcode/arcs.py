"""G2/G3 geometry: centre, sweep and node sampling of circular and helical arcs.

Everything here works on 9-axis machine positions (``ALL_AXES`` order, mm/deg)
and a plane given as three indices (first, second, normal) into them, LinuxCNC's
convention: G17 = (X, Y, Z), G18 = (Z, X, Y), G19 = (Y, Z, X). A positive sweep
turns counter-clockwise seen from +normal, so G3 is positive and G2 negative in
all three planes (for G18 this is the RS274NGC rule: CCW looking from +Y down
onto the Z-X plane).

Errors are raised as ``GeometryError`` (message only); the interpreter adds the
source location.
"""

from __future__ import annotations

import math

import numpy as np

from ..constants import (ALL_AXES, ARC_MAX_SEGMENT_DEG, ARC_MIN_RADIUS_MM, ARC_MIN_SEGMENTS,
                         ARC_R_REACH_TOL_MM, ARC_RADIUS_TOL_INCH, ARC_RADIUS_TOL_MAX_INCH,
                         ARC_RADIUS_TOL_MAX_MM, ARC_RADIUS_TOL_MM, ARC_RADIUS_TOL_REL,
                         CURVE_CHORD_TOL_MM, CURVE_MAX_NODES, LINEAR_AXES, MM_PER_INCH)
from .program import Arc

TWO_PI = 2.0 * math.pi
_FRACS: dict[int, np.ndarray] = {}  # k / n for k = 1..n, by n (read-only arrays)
_LINEAR9 = [a in LINEAR_AXES for a in ALL_AXES]


class GeometryError(Exception):
    """A geometric problem with one block (the caller adds file/line/col)."""


def radius_tolerances(inch: bool) -> tuple[float, float]:
    """(tol_mm, max_mm) of the start/end radius check for mm or inch programs."""
    if inch:
        return ARC_RADIUS_TOL_INCH * MM_PER_INCH, ARC_RADIUS_TOL_MAX_INCH * MM_PER_INCH
    return ARC_RADIUS_TOL_MM, ARC_RADIUS_TOL_MAX_MM


def centre_from_ijk(ccw: bool, s1: float, s2: float, e1: float, e2: float,
                    c1: float, c2: float, turns: int,
                    inch: bool = False) -> tuple[float, float, float]:
    """Check an I/J/K arc with centre (c1, c2): returns (radius_start, radius_end, sweep_rad).

    Raises ``GeometryError`` when a radius is ~0 or the end point does not lie on the
    circle through the start point. LinuxCNC's documented rule: the two radii may differ
    by at most 0.5 mm (0.05 in), and by more than 0.005 mm (0.0005 in) only if that is
    within 0.1 % of the radius (constants ``ARC_RADIUS_TOL_*``).
    """
    r1 = math.hypot(s1 - c1, s2 - c2)
    r2 = math.hypot(e1 - c1, e2 - c2)
    if r1 < ARC_MIN_RADIUS_MM or r2 < ARC_MIN_RADIUS_MM:
        raise GeometryError(f"zero-radius arc (start radius {r1:.6g} mm, end radius {r2:.6g} mm)")
    err = abs(r1 - r2)
    tol, tol_max = radius_tolerances(inch)
    if err > tol_max or (err > tol and err > ARC_RADIUS_TOL_REL * max(r1, r2)):
        raise GeometryError(
            f"arc end point is not on the circle: radius to start {r1:.6f} mm, to end {r2:.6f} mm "
            f"(differ by {err:.3g} mm; allowed {tol:g} mm, or {ARC_RADIUS_TOL_REL:.1%} of the "
            f"radius up to {tol_max:g} mm)")
    return r1, r2, _sweep(ccw, s1, s2, e1, e2, c1, c2, turns)


def centre_from_r(ccw: bool, s1: float, s2: float, e1: float, e2: float, radius: float,
                  turns: int) -> tuple[float, float, float, float, float]:
    """Centre of an R-format arc: returns (c1, c2, r_start, r_end, sweep_rad).

    Positive R gives the arc of at most 180 degrees, negative R the longer one
    (RS274NGC). Start and end must differ and be at most 2|R| apart.
    """
    if s1 == e1 and s2 == e2:
        raise GeometryError("R-format arc with the end point equal to the start point "
                            "(a full circle needs I/J/K)")
    ar = abs(radius)
    if ar < ARC_MIN_RADIUS_MM:
        raise GeometryError(f"zero-radius arc (R {radius:g})")
    m1, m2 = (s1 + e1) / 2.0, (s2 + e2) / 2.0
    half = math.hypot(e1 - m1, e2 - m2)
    if half - ar > ARC_R_REACH_TOL_MM:
        raise GeometryError(f"arc radius {ar:.6g} mm is too small to reach the end point "
                            f"({2 * half:.6g} mm away)")
    if half / ar > 1.0 - 1e-12:
        half = ar
    chord_dir = math.atan2(e2 - s2, e1 - s1)
    # centre on the right of the chord for CW with R>0 (or CCW with R<0)
    if (not ccw and radius > 0) or (ccw and radius < 0):
        theta = chord_dir - math.pi / 2
    else:
        theta = chord_dir + math.pi / 2
    offset = ar * math.cos(math.asin(half / ar))
    c1 = m1 + offset * math.cos(theta)
    c2 = m2 + offset * math.sin(theta)
    r1 = math.hypot(s1 - c1, s2 - c2)
    r2 = math.hypot(e1 - c1, e2 - c2)
    return c1, c2, r1, r2, _sweep(ccw, s1, s2, e1, e2, c1, c2, turns)


def _sweep(ccw: bool, s1, s2, e1, e2, c1, c2, turns: int) -> float:
    """Signed sweep: end angle reached going CCW (or CW), full circle if start == end angle."""
    a0 = math.atan2(s2 - c2, s1 - c1)
    a1 = math.atan2(e2 - c2, e1 - c1)
    if ccw:
        if a1 <= a0:
            a1 += TWO_PI
        return (a1 - a0) + (turns - 1) * TWO_PI
    if a1 >= a0:
        a1 -= TWO_PI
    return (a1 - a0) - (turns - 1) * TWO_PI


def arc_length_mm(start9, end9, plane, r1: float, r2: float, sweep: float) -> float:
    """Length of the (helical) arc by the feed convention: linear axes, else rotary."""
    a, b, _ = plane
    planar = 0.5 * (r1 + r2) * abs(sweep)
    lin2 = planar * planar
    rot2 = 0.0
    for k in range(9):
        if k == a or k == b:
            continue
        d = end9[k] - start9[k]
        if _LINEAR9[k]:
            lin2 += d * d
        else:
            rot2 += d * d
    return math.sqrt(lin2) if lin2 > 0 else math.sqrt(rot2)


def segment_count(radius: float, sweep: float) -> int:
    """Node segments for an arc: chord error <= CURVE_CHORD_TOL_MM, at least ARC_MIN_SEGMENTS,
    no segment longer than ARC_MAX_SEGMENT_DEG."""
    max_ang = math.radians(ARC_MAX_SEGMENT_DEG)
    if radius > CURVE_CHORD_TOL_MM:
        # sagitta r(1 - cos(d/2)) <= tol
        max_ang = min(max_ang, 2.0 * math.acos(1.0 - CURVE_CHORD_TOL_MM / radius))
    return max(ARC_MIN_SEGMENTS, int(math.ceil(abs(sweep) / max_ang - 1e-9)))


def make_arc(line: int, start9, end9, plane, c1: float, c2: float, r1: float, r2: float,
             sweep: float) -> Arc:
    """The exact 9-axis ``Arc`` (radius = mean of the start and end radii)."""
    return Arc(line=line, start=np.array(start9, dtype=float), end=np.array(end9, dtype=float),
               plane=tuple(plane), center=np.array([c1, c2]), radius=0.5 * (r1 + r2),
               sweep_rad=float(sweep))


def arc_nodes(start9, end9, plane, c1: float, c2: float, r1: float, r2: float, sweep: float,
              layout: tuple[int, ...]) -> np.ndarray:
    """Sampled nodes (K, len(layout)) of an arc after its start; the last is the exact end.

    Same formula as ``Arc.points`` (angle linear in the fraction, radius varying
    linearly from start to end, other axes linear), evaluated only for the ``layout``
    columns; K from ``segment_count``.
    """
    n = segment_count(max(r1, r2), sweep)
    if n > CURVE_MAX_NODES:
        raise GeometryError(f"arc too large: it needs {n} nodes at {CURVE_CHORD_TOL_MM} mm chord "
                            f"error (limit {CURVE_MAX_NODES})")
    a, b, _ = plane
    frac = _FRACS.get(n)
    if frac is None:
        frac = np.arange(1, n + 1, dtype=float) / n
        frac.setflags(write=False)
        if len(_FRACS) < 4096:
            _FRACS[n] = frac
    s = np.array([start9[i] for i in layout])
    e = np.array([end9[i] for i in layout])
    pts = s + np.multiply.outer(frac, e - s)
    ang = math.atan2(start9[b] - c2, start9[a] - c1) + sweep * frac
    r = r1 + (r2 - r1) * frac if r2 != r1 else r1
    if a in layout:
        pts[:, layout.index(a)] = c1 + r * np.cos(ang)
    if b in layout:
        pts[:, layout.index(b)] = c2 + r * np.sin(ang)
    pts[-1] = e  # the end point is exact, not a rounding of cos/sin
    return pts

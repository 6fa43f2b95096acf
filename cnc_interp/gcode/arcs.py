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

from ..constants import ALL_AXES, CURVE_CHORD_TOL_MM, LINEAR_AXES, MM_PER_INCH


#: I/J/K arcs, LinuxCNC's documented rule: |r_start - r_end| is an error when it exceeds
#: ARC_RADIUS_TOL_MAX_* or (ARC_RADIUS_TOL_* and ARC_RADIUS_TOL_REL * radius). mm programs:
ARC_RADIUS_TOL_MM = 0.005

ARC_RADIUS_TOL_MAX_MM = 0.5

#: the same for inch programs (G20), in inches
ARC_RADIUS_TOL_INCH = 0.0005

ARC_RADIUS_TOL_MAX_INCH = 0.05

#: relative part of the rule (0.1 % of the radius)
ARC_RADIUS_TOL_REL = 0.001

#: an arc radius (start or end) below this is a "zero-radius arc" error (mm; LinuxCNC 0.00005 in)
ARC_MIN_RADIUS_MM = 0.00127

#: R-format arcs: how far the chord may exceed the diameter before "radius too small" (mm)
ARC_R_REACH_TOL_MM = 0.00127

#: every arc gets at least this many node segments (so curvature shows in the nodes)
ARC_MIN_SEGMENTS = 4

#: longest angle one sampled arc segment may span, deg
ARC_MAX_SEGMENT_DEG = 5.0
TWO_PI = 2.0 * math.pi
_LINEAR9 = [a in LINEAR_AXES for a in ALL_AXES]


class GeometryError(Exception):
    """A geometric problem with one block (the caller adds file/line/col)."""


def radius_tolerances(inch: bool) -> tuple[float, float]:
    """(tol_mm, max_mm) of the start/end radius check for mm or inch programs."""
    if inch:
        return ARC_RADIUS_TOL_INCH * MM_PER_INCH, ARC_RADIUS_TOL_MAX_INCH * MM_PER_INCH
    return ARC_RADIUS_TOL_MM, ARC_RADIUS_TOL_MAX_MM


def centre_from_ijk(
    ccw: bool, s1: float, s2: float, e1: float, e2: float, c1: float, c2: float, turns: int, inch: bool = False
) -> tuple[float, float, float]:
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
            f"radius up to {tol_max:g} mm)"
        )
    return r1, r2, _sweep(ccw, s1, s2, e1, e2, c1, c2, turns)


def centre_from_r(
    ccw: bool, s1: float, s2: float, e1: float, e2: float, radius: float, turns: int
) -> tuple[float, float, float, float, float]:
    """Centre of an R-format arc: returns (c1, c2, r_start, r_end, sweep_rad).

    Positive R gives the arc of at most 180 degrees, negative R the longer one
    (RS274NGC). Start and end must differ and be at most 2|R| apart.
    """
    if s1 == e1 and s2 == e2:
        raise GeometryError("R-format arc with the end point equal to the start point (a full circle needs I/J/K)")
    ar = abs(radius)
    if ar < ARC_MIN_RADIUS_MM:
        raise GeometryError(f"zero-radius arc (R {radius:g})")
    m1, m2 = (s1 + e1) / 2.0, (s2 + e2) / 2.0
    half = math.hypot(e1 - m1, e2 - m2)
    if half - ar > ARC_R_REACH_TOL_MM:
        raise GeometryError(f"arc radius {ar:.6g} mm is too small to reach the end point ({2 * half:.6g} mm away)")
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


def fill_arc_nodes(nodes: np.ndarray, layout: tuple[int, ...], pieces: list) -> None:
    """Fill the reserved node rows of many arcs at once (vectorised over all of them).

    ``nodes`` (N, len(layout)) is a run's node array; each piece is ``(first, last,
    (line, start9, end9, plane, c1, c2, r1, r2, sweep))`` with rows first+1..last to
    fill, n = last - first from ``segment_count``. Same formula as ``Arc.points``: angle
    and radius linear in the fraction k/n, every other axis linear; the last row is the
    exact end point.
    """
    m = len(pieces)
    firsts = np.fromiter((p[0] for p in pieces), dtype=np.int64, count=m)
    counts = np.fromiter((p[1] - p[0] for p in pieces), dtype=np.int64, count=m)
    specs = [p[2] for p in pieces]
    start = np.array([[sp[1][i] for i in layout] for sp in specs], dtype=float)
    end = np.array([[sp[2][i] for i in layout] for sp in specs], dtype=float)
    col_a = np.fromiter((layout.index(sp[3][0]) for sp in specs), dtype=np.int64, count=m)
    col_b = np.fromiter((layout.index(sp[3][1]) for sp in specs), dtype=np.int64, count=m)
    c1 = np.fromiter((sp[4] for sp in specs), dtype=float, count=m)
    c2 = np.fromiter((sp[5] for sp in specs), dtype=float, count=m)
    r1 = np.fromiter((sp[6] for sp in specs), dtype=float, count=m)
    r2 = np.fromiter((sp[7] for sp in specs), dtype=float, count=m)
    sweep = np.fromiter((sp[8] for sp in specs), dtype=float, count=m)
    rows_m = np.arange(m)
    a0 = np.arctan2(start[rows_m, col_b] - c2, start[rows_m, col_a] - c1)

    total = int(counts.sum())
    seg = np.repeat(rows_m, counts)  # arc of each new row
    k = np.arange(1, total + 1) - np.repeat(np.cumsum(counts) - counts, counts)  # 1..n
    frac = k / counts[seg]
    vals = start[seg] + (end - start)[seg] * frac[:, None]
    ang = a0[seg] + sweep[seg] * frac
    r = r1[seg] + (r2 - r1)[seg] * frac
    idx = np.arange(total)
    vals[idx, col_a[seg]] = c1[seg] + r * np.cos(ang)
    vals[idx, col_b[seg]] = c2[seg] + r * np.sin(ang)
    last = k == counts[seg]
    vals[last] = end[seg[last]]  # exact end points
    nodes[firsts[seg] + k] = vals

"""Canned drilling cycles G81 G82 G83 G73 G85 G89, expanded into rapid/feed moves and dwells.

Follows LinuxCNC's ``convert_cycle_xy``/``_yz``/``_zx`` and ``CYCLE_MACRO``
(src/emc/rs274ngc/interp_cycles.cc):

* plane axes (aa, bb, cc) = (X, Y, Z) for G17, (Z, X, Y) for G18, (Y, Z, X) for G19;
  the hole position is (aa, bb), cc is the drilling axis;
* R and the cc-word are sticky while the same cycle stays active; the first block
  of a cycle must give both;
* absolute (G90): R and cc are positions; incremental (G91): R is measured from
  the initial level, the bottom from R, and aa/bb words are increments repeated
  L times;
* if the tool is below R it first rapids straight up to R; the retract level is R
  for G99 and the initial level (the cc position when the cycle started, raised
  to R if lower) for G98;
* each repeat: rapid to the hole at the current height (first repeat) or the
  clear height, rapid down to R, the cycle body, retract;
* bodies: G81 feed down, rapid out; G82 adds a dwell P; G83 pecks Q with a rapid
  out to R and back to PECK_CLEARANCE_MM above the last depth; G73 pecks with a
  small rapid back-off; G85 feeds down and feeds back to R, then rapids to the
  clear level; G89 feeds down, dwells P, feeds out to the clear level.
The moves run as exact path (tolerance 0), as LinuxCNC switches to G61 inside cycles.
"""

from __future__ import annotations

import math

from ..constants import LOOP_ITERATION_LIMIT
from .codes import G17, G18, G19


#: G73/G83 peck: rapid back down to this far above the previous depth (LinuxCNC: 0.010 in)
PECK_CLEARANCE_MM = 0.254

#: plane code -> (aa, bb, cc) indices into ALL_AXES
CYCLE_AXES = {G17: (0, 1, 2), G18: (2, 0, 1), G19: (1, 2, 0)}
SUPPORTED = (81, 82, 83, 73, 85, 89)


class CycleError(Exception):
    """A canned-cycle problem; ``letter`` names the word to point at (or None)."""

    def __init__(self, message: str, letter: str | None = None):
        super().__init__(message)
        self.letter = letter


def polar_increment(x: float, y: float, dr: float | None, dtheta_deg: float | None) -> tuple[float, float]:
    """Point (x, y) moved by a G91 polar distance ``dr`` and then turned by ``dtheta_deg``
    degrees about the origin, one step after the other as LinuxCNC's ``find_ends`` and
    ``CYCLE_MACRO`` do (``None``: no such word). Raises ``CycleError`` at the origin,
    where the direction is undefined."""
    for k, step in enumerate((dr, dtheta_deg)):
        if step is None:
            continue
        if x == 0.0 and y == 0.0:
            raise CycleError("incremental polar move (G91 @ ^) from the origin has no direction")
        radius, theta = math.hypot(x, y), math.atan2(y, x)
        if k == 0:
            radius += step
        else:
            theta += math.radians(step)
        x, y = radius * math.cos(theta), radius * math.sin(theta)
    return x, y


def expand_cycle(ip, code: int, words: dict, line: int, col: int) -> None:
    """Execute one block of canned cycle G``code`` on interpreter ``ip``.

    ``words`` maps letters to (letter, value, col); axis values are program numbers.
    ``ip`` provides ``pos`` (9 machine values), ``unit_of(axis)``, ``off`` (9 offsets),
    ``distance_incremental``, ``retract_r_plane``, ``plane``, the sticky cycle state,
    and ``cycle_move(kind, target9, line, col)`` / ``cycle_dwell(seconds, line)``.
    """
    aa_i, bb_i, cc_i = CYCLE_AXES[ip.plane]
    cc_letter = "XYZ"[cc_i]
    aa_letter, bb_letter = "XYZ"[aa_i], "XYZ"[bb_i]
    same = ip.motion == code * 10  # the motion mode is stored as ten times the G number
    if ip.feed_inverse_time:
        raise CycleError("canned cycles cannot run in G93 inverse time mode")
    if ip.f_word <= 0.0:
        raise CycleError("canned cycle with zero or missing feed rate (F)")
    for r in ("A", "B", "C", "U", "V", "W"):
        if r in words:
            raise CycleError(f"{r} word in a canned cycle (only {aa_letter}{bb_letter}{cc_letter} may move)", r)
    if "R" in words:
        r_num = words["R"][1]
    elif same:
        r_num = ip.cycle_r
    else:
        raise CycleError(f"G{code} without R (retract plane) in its first block")
    if cc_letter in words:
        cc_num = words[cc_letter][1]
    elif same:
        cc_num = ip.cycle_cc
    else:
        raise CycleError(f"G{code} without {cc_letter} (hole bottom) in its first block")
    reps = 1
    if "L" in words:
        lv = words["L"][1]
        if lv != int(lv) or lv < 1 or lv > LOOP_ITERATION_LIMIT:
            raise CycleError(f"cycle repeat L must be a whole number from 1 to {LOOP_ITERATION_LIMIT}, got {lv:g}", "L")
        reps = int(lv)
    p_s = None
    if code in (82, 89):
        if "P" in words:
            p_s = words["P"][1]
        elif same:
            p_s = ip.cycle_p
        else:
            raise CycleError(f"G{code} without P (dwell seconds)")
        if p_s < 0:
            raise CycleError(f"negative dwell P {p_s:g}", "P")
    q_mm = None
    if code in (83, 73):
        if "Q" in words:
            q_num = words["Q"][1]
        elif same:
            q_num = ip.cycle_q
        else:
            raise CycleError(f"G{code} without Q (peck depth)")
        if q_num <= 0:
            raise CycleError(f"peck depth Q must be positive, got {q_num:g}", "Q")
        q_mm = q_num * ip.len_unit
        ip.cycle_q = q_num

    pos = ip.pos
    u_aa, u_bb, u_cc = ip.unit_of(aa_i), ip.unit_of(bb_i), ip.unit_of(cc_i)
    # polar words (G17 only, checked by the interpreter): program units and degrees
    polar_r = words["@"][1] * u_aa if "@" in words else None
    polar_a = words["^"][1] if "^" in words else None
    current_cc = pos[cc_i]
    if ip.cycle_il is None:
        ip.cycle_il = current_cc
    old_cc = ip.cycle_il
    if ip.distance_incremental:
        d_aa = words[aa_letter][1] * u_aa if aa_letter in words else 0.0
        d_bb = words[bb_letter][1] * u_bb if bb_letter in words else 0.0
        r = r_num * u_cc + old_cc
        bottom = r + cc_num * u_cc
        aa, bb = pos[aa_i], pos[bb_i]
    elif polar_r is not None or polar_a is not None:
        d_aa = d_bb = 0.0
        r = r_num * u_cc + ip.off[cc_i]
        bottom = cc_num * u_cc + ip.off[cc_i]
        x0, y0 = pos[0] - ip.off[0], pos[1] - ip.off[1]
        radius = polar_r if polar_r is not None else math.hypot(x0, y0)
        theta = math.radians(polar_a) if polar_a is not None else math.atan2(y0, x0)
        aa = radius * math.cos(theta) + ip.off[0]
        bb = radius * math.sin(theta) + ip.off[1]
        polar_r = polar_a = None  # absolute: the hole is placed once, not stepped
    else:
        d_aa = d_bb = 0.0
        r = r_num * u_cc + ip.off[cc_i]
        bottom = cc_num * u_cc + ip.off[cc_i]
        aa = words[aa_letter][1] * u_aa + ip.off[aa_i] if aa_letter in words else pos[aa_i]
        bb = words[bb_letter][1] * u_bb + ip.off[bb_i] if bb_letter in words else pos[bb_i]
    if r < bottom:
        raise CycleError(f"R plane ({r:g} mm) below the hole bottom {cc_letter} ({bottom:g} mm)")
    if q_mm is not None and (r - bottom) / q_mm > LOOP_ITERATION_LIMIT:
        raise CycleError(f"peck depth Q gives more than {LOOP_ITERATION_LIMIT} pecks", "Q")

    def goto(kind: str, a: float, b: float, c: float) -> None:
        t = list(ip.pos)
        t[aa_i], t[bb_i], t[cc_i] = a, b, c
        ip.cycle_move(kind, t, line, col)

    if old_cc < r:
        goto("rapid", ip.pos[aa_i], ip.pos[bb_i], r)
        old_cc = r
        current_cc = r
        ip.cycle_il = r
    clear = r if ip.retract_r_plane else old_cc

    for rep in range(reps):
        aa += d_aa
        bb += d_bb
        if polar_r is not None or polar_a is not None:  # G91: each repeat steps about the origin
            x, y = polar_increment(aa - ip.off[0], bb - ip.off[1], polar_r, polar_a)
            aa, bb = x + ip.off[0], y + ip.off[1]
        if rep == 0 and current_cc > r:
            goto("rapid", aa, bb, current_cc)
            goto("rapid", aa, bb, r)
        else:
            goto("rapid", aa, bb, clear)
            if clear > r:
                goto("rapid", aa, bb, r)
        if code == 81:
            goto("feed", aa, bb, bottom)
            goto("rapid", aa, bb, clear)
        elif code == 82:
            goto("feed", aa, bb, bottom)
            ip.cycle_dwell(p_s, line)
            goto("rapid", aa, bb, clear)
        elif code in (83, 73):
            depth = r - q_mm
            while depth > bottom:
                goto("feed", aa, bb, depth)
                if code == 83:
                    goto("rapid", aa, bb, r)
                goto("rapid", aa, bb, depth + PECK_CLEARANCE_MM)
                depth -= q_mm
            goto("feed", aa, bb, bottom)
            goto("rapid", aa, bb, clear)
        elif code == 85:
            goto("feed", aa, bb, bottom)
            goto("feed", aa, bb, r)
            goto("rapid", aa, bb, clear)
        elif code == 89:
            goto("feed", aa, bb, bottom)
            ip.cycle_dwell(p_s, line)
            goto("feed", aa, bb, clear)
    ip.cycle_r = r_num
    ip.cycle_cc = cc_num
    if p_s is not None:
        ip.cycle_p = p_s

"""The RS274NGC modal interpreter: evaluated blocks in, a ``Program`` timeline out.

The language layer (``blocks.iter_blocks``) hands over one block at a time with
every word already evaluated; this module keeps the modal state (motion mode,
plane, units, distance modes, offsets, feed, path control, canned-cycle and
NURBS state) and turns each block into machine-coordinate moves, dwells and
stops, in RS274NGC's order of execution within a block.

Internally positions are 9-axis machine coordinates (``ALL_AXES`` order: mm for
XYZUVW, degrees for ABC); inch and per-minute values are converted here, once.

Speed: a block that is a plain G0/G1 move (axis words with optional N, F, S)
takes a short path that appends floats to ``array('d')`` buffers, with no
per-node objects; a plain G2/G3 block skips the general classification too;
everything else goes through ``_general``.
"""

from __future__ import annotations

import math
from operator import itemgetter

import numpy as np

from ..constants import (
    ALL_AXES,
    CURVE_CHORD_TOL_MM,
    CURVE_MAX_NODES,
    LINEAR_AXES,
    LINEAR_MOTION_MIN_MM,
    MM_PER_INCH,
    SECONDS_PER_MINUTE,
)
from ..errors import GCodeError, SourceLocation, UnsupportedError
from .arcs import GeometryError, arc_length_mm, centre_from_ijk, centre_from_r, fill_arc_nodes, segment_count
from .canned import SUPPORTED as CYCLE_CODES, CycleError, expand_cycle, polar_increment
from .codes import (
    COORDINATE_SYSTEM,
    G0,
    G1,
    G2,
    G3,
    G4,
    G5,
    G5_1,
    G5_2,
    G5_3,
    G10,
    G17,
    G18,
    G19,
    G20,
    G28,
    G28_1,
    G30,
    G30_1,
    G43,
    G43_1,
    G43_2,
    G49,
    G53,
    G61,
    G61_1,
    G64,
    G73,
    G80,
    G81,
    G82,
    G83,
    G85,
    G89,
    G90_1,
    G91,
    G92,
    G92_1,
    G92_2,
    G92_3,
    G93,
    G99,
    G_GROUP,
    G_UNSUPPORTED,
    M2,
    M6,
    M30,
    M_GROUP,
    M_NOOP,
    M_STOPS,
    M_UNSUPPORTED,
    M_USE_P,
    M_USE_QE,
    gcode_name,
)
from .program import Dwell, Mark, Program, Stop
from .runs import RunBuilder, finish_run
from .splines import bezier, bezier_cusps, make_nurbs, sample_nurbs, split_bezier


#: closed items a streamed interpreter lets wait inside one block before it hands them on
#: (``on_items``): ``G81 ... L1000000`` is two million runs from one block (8 kB each)
ITEMS_WAITING_MAX = 4096

#: comments that are messages (LinuxCNC's MSG, DEBUG, PRINT, LOG*, PROBE*), not
#: operation headers (lower case, as the comment starts)
_MESSAGE_COMMENTS = ("msg,", "debug,", "print,", "log", "probe")

#: how an unknown M-code's error says it can be declared harmless
_NOOP_HINT = (
    " (if it moves no axis, declare it a no-op in the machine file: [gcode] noop_mcodes = [{code}];"
    " a LinuxCNC INI declares M100-M199 by their files in [RS274NGC] USER_M_PATH)"
)

#: largest G2/G3 P (full turns) accepted; more is treated as a runaway expression
ARC_MAX_TURNS = 10_000

INF = math.inf
NAN = math.nan
AXIS_INDEX = {a: i for i, a in enumerate(ALL_AXES)}
IS_LINEAR9 = tuple(a in LINEAR_AXES for a in ALL_AXES)
#: plane code -> (first, second, normal) axis indices (LinuxCNC: G18 is Z-X)
PLANES = {G17: (0, 1, 2), G18: (2, 0, 1), G19: (1, 2, 0)}
#: plane code -> centre-offset letters of (first, second) axes, and the letter not allowed
PLANE_IJK = {G17: ("I", "J", "K"), G18: ("K", "I", "J"), G19: ("J", "K", "I")}
PLANE_NAME = {G17: "XY (G17)", G18: "XZ (G18)", G19: "YZ (G19)"}
# Sets of codes compared on every general block: built once here (``code in (G2, G3)``
# would build its tuple of names at every comparison; literals were folded to constants).
#: the non-modal codes whose values are the block's axis words (no motion goes with them)
AXIS_WORD_CODES = frozenset({G10, G28, G30, G92})
#: tool length codes whose values are the block's axis words
TOOL_LENGTH_AXIS_CODES = frozenset({G43_1, G43_2})
STRAIGHT = frozenset({G0, G1})
ARCS = frozenset({G2, G3})
SPLINES = frozenset({G5, G5_1})
#: the motions a rotated coordinate system (G10 L2 R) supports
ROTATABLE = frozenset({G0, G1, G2, G3})
#: motion codes that may come without axis words (a G5.2 block may open with P alone)
AXISLESS_MOTIONS = frozenset({G0, G1, G5_2})
EXACT_PATH = frozenset({G61, G61_1})
#: which motion codes use which parameter word (``_check_unused_words``)
USES_IJ = frozenset({G2, G3, G5, G5_1})
USES_P = frozenset({G2, G3, G5, G5_2, G82, G89})
USES_Q = frozenset({G83, G73, G5})
NON_MODAL_USES_P = frozenset({G4, G10})
#: the canned cycles: a repeat of one keeps its sticky state (initial level)
CYCLE_MOTIONS = frozenset({G81, G82, G83, G73, G85, G89})
VALID_LETTERS = frozenset("ABCDFGHIJKLMNPQRSTUVWXYZ@^")

#: letter -> axis index (>= 0) or a negative tag for the fast path (N, F, S, G, arc words)
_FAST_KIND = {a: i for i, a in enumerate(ALL_AXES)}
_FAST_KIND.update({"N": -1, "F": -2, "S": -3, "G": -4, "I": -5, "J": -5, "K": -5, "R": -5, "P": -5})
_PER_MIN = 1.0 / SECONDS_PER_MINUTE
#: G value -> motion code handled by the fast path
_FAST_G = {0.0: G0, 1.0: G1, 2.0: G2, 3.0: G3}


class Interpreter:
    """Modal state of one program run. Use ``run(blocks)`` once."""

    def __init__(self, source: str, params, axes: str | None, start9: list[float], len_unit: float = 1.0):
        """``len_unit``: mm per program length unit at the start (``MM_PER_INCH``: the
        program starts in G20, as LinuxCNC starts one in an inch machine's units)."""
        self.source = source
        self.params = params
        self.fixed_axes = axes is not None
        if axes is not None:
            self.active = tuple(sorted(AXIS_INDEX[a] for a in axes))
            self.out_order = tuple(AXIS_INDEX[a] for a in axes)  # machine order as given
        else:
            self.active = (0, 1, 2)
            self.out_order = None
        self.start9 = list(start9)
        self.pos = list(start9)
        # units and modes
        self.len_unit = 1.0
        self.units9 = [1.0] * 9
        self.distance_incremental = False
        self.arc_abs = False
        self.plane = G17
        self.motion = G80  # LinuxCNC starts with no motion mode (G80)
        self.feed_inverse_time = False
        self.f_word = 0.0
        self.f_block = 0.0  # F given in the current block (G93 needs one per move)
        self.retract_r_plane = False  # G98
        self.tol = NAN  # G64 without P
        self.naive = NAN
        self.exact_stop = False
        self.tool = 0
        self.tool_selected = 0
        # offsets (mm/deg, machine)
        self.cs = 1
        self.coord_off = [0.0] * 9
        self.g92 = [0.0] * 9
        self.off = [0.0] * 9
        # tool length offset (G43/G43.1/G43.2, mm/deg, machine frame): added to every target
        self.tlo = [0.0] * 9
        self.tool_table = None  # ToolTable or None (then G43 Hn applies zero, with a warning)
        #: M-codes the machine declares no-ops (``Machine.noop_mcodes``): accepted, no effect
        self.noop_mcodes: frozenset[int] = frozenset()
        self.tool_table_path: str | None = None  # a table file, read at its first use
        self.tools_touched: set[int] = set()  # changed by G10 L10/L11 (not modelled)
        self.warnings: list[str] = []
        # XY rotation of the current coordinate system (G10 L2 R), LinuxCNC order:
        # machine_xy = offset_xy + Rot(rot) (program_xy + g92_xy)
        self.rot_deg = 0.0
        self.rot_cs = (1.0, 0.0)  # cos, sin
        # canned cycles
        self.cycle_il = None
        self.cycle_r = 0.0
        self.cycle_cc = 0.0
        self.cycle_p = 0.0
        self.cycle_q = 0.0
        # splines
        self.nurbs_cp: list | None = None
        self.nurbs_w: list | None = None
        self.nurbs_order = 3
        self.nurbs_line = 0
        self.nurbs_col = 0
        self.g5_tangent: tuple[float, float] | None = None
        # output
        self.items: list = []
        #: a stream's hook, called inside a block once ``ITEMS_WAITING_MAX`` items wait
        #: (it takes them from ``items``); between blocks the stream looks by itself
        self.on_items = None
        #: a stream's option: hand on ``Mark`` items (tool changes, operation headers)
        self.marks = False
        self._mark_pending: Mark | None = None  # an operation header read while a run is open
        self._header_block = -2  # block count of the last comment-only block
        self.rb: RunBuilder | None = None
        self.block_count = 0
        self.line_count = 0
        self.zero_length_moves = 0
        self.zero_length_lines: list[int] = []
        self.blk = None
        self._set_units(len_unit)
        self._refresh_layout()
        self._load_coordinate_system(1, write_current=True)

    # -- small helpers ------------------------------------------------------------
    def error(self, message: str, col: int = 0, unsupported: bool = False, text: str | None = None):
        """A GCodeError at the current block (column ``col``), quoting its text."""
        blk = self.blk
        line = blk.line if blk is not None else 0
        if text is None:
            text = _word_text(blk, col) if blk is not None else ""
        cls = UnsupportedError if unsupported else GCodeError
        return cls(message, SourceLocation(self.source, line, col, text))

    def unit_of(self, i: int) -> float:
        return self.units9[i]

    def _set_units(self, len_unit: float) -> None:
        self.len_unit = len_unit
        self.units9 = [len_unit if lin else 1.0 for lin in IS_LINEAR9]

    def _refresh_layout(self) -> None:
        self.getter = itemgetter(*self.active) if len(self.active) > 1 else (lambda p, _i=self.active[0]: (p[_i],))

    def _activate(self, i: int, col: int) -> None:
        if i in self.active:
            return
        if self.fixed_axes:
            a = ALL_AXES[i]
            raise self.error(
                f"axis {a} is not on this machine (axes "
                f"{''.join(ALL_AXES[k] for k in self.out_order)}); use a machine "
                f"with an {a} axis: -m with a preset that has one (cnc-interp "
                f"machines), or a machine file with an [axes.{a}] table (vmax, "
                "amax, jmax)",
                col,
            )
        self.active = tuple(sorted(self.active + (i,)))
        if self.rb is not None:
            self.rb.widen(self.active, self.pos)
        self._refresh_layout()

    def _pget(self, n: int) -> float:
        p = self.params
        try:
            if p.exists(n):
                return float(p.get(n))
        except Exception:  # a store that does not know the number: treat as 0
            return 0.0
        return 0.0

    def _pset(self, n: int, v: float) -> None:
        self.params.set(n, float(v))

    def _update_off(self) -> None:
        self.off = [c + g + t for c, g, t in zip(self.coord_off, self.g92, self.tlo)]

    def program_position(self) -> list[float]:
        """Current position in program coordinates and units (for #5420-#5428)."""
        return [q / u for q, u in zip(self._to_prog_mm(self.pos), self.units9)]

    def _to_prog_mm(self, m9: list[float]) -> list[float]:
        """Program coordinates (mm/deg, before unit scaling) of machine position ``m9``."""
        q = [m - o for m, o in zip(m9, self.off)]
        if self.rot_deg:
            c, s = self.rot_cs
            dx = m9[0] - self.coord_off[0] - self.tlo[0]
            dy = m9[1] - self.coord_off[1] - self.tlo[1]
            q[0] = c * dx + s * dy - self.g92[0]
            q[1] = -s * dx + c * dy - self.g92[1]
        return q

    def _to_machine(self, q9: list[float]) -> list[float]:
        """Machine position of program coordinates ``q9`` (mm/deg)."""
        m = [q + o for q, o in zip(q9, self.off)]
        if self.rot_deg:
            c, s = self.rot_cs
            vx, vy = q9[0] + self.g92[0], q9[1] + self.g92[1]
            m[0] = self.coord_off[0] + self.tlo[0] + c * vx - s * vy
            m[1] = self.coord_off[1] + self.tlo[1] + s * vx + c * vy
        return m

    def _set_rotation(self, deg: float) -> None:
        self.rot_deg = float(deg) % 360.0
        r = math.radians(self.rot_deg)
        self.rot_cs = (math.cos(r), math.sin(r))

    def sync_position_params(self) -> None:
        """Write #5420-#5428 (the hot path does not; ``read_program``'s store computes them)."""
        for k, v in enumerate(self.program_position()):
            self._pset(5420 + k, v)

    # -- offsets ------------------------------------------------------------------
    def _load_coordinate_system(self, cs: int, write_current: bool = True) -> None:
        base = 5201 + 20 * cs
        self.cs = cs
        self.coord_off = [self._pget(base + k) * self.units9[k] for k in range(9)]
        self._set_rotation(self._pget(base + 9))
        self._update_off()
        if write_current:
            self._pset(5220, cs)

    def _switch_units(self, len_unit: float) -> None:
        if len_unit == self.len_unit:
            return
        # LinuxCNC keeps offset parameters in the current length units: convert them
        ratio = self.len_unit / len_unit
        lin = [k for k in range(9) if IS_LINEAR9[k]]
        nums = [5161 + k for k in lin] + [5181 + k for k in lin] + [5211 + k for k in lin]
        nums += [5201 + 20 * cs + k for cs in range(1, 10) for k in lin]
        for n in nums:
            if self.params.exists(n):
                self._pset(n, self._pget(n) * ratio)
        # the feed in effect keeps its physical value (LinuxCNC re-reads it from the canon
        # level in the new units): 600 mm/min after G20 is 23.62 in/min, not 600 in/min
        self.f_word *= ratio
        self._set_units(len_unit)

    # -- runs -----------------------------------------------------------------------
    def _start_run(self, kind: str, line: int, col: int) -> RunBuilder:
        rb = self.rb
        if rb is not None:
            self._close_run(kind)  # a rapid run ends because feed follows, and vice versa
        if self._mark_pending is not None:
            self._flush_mark()
        rb = RunBuilder(kind, self.active, self.pos, line, col, self.tol, self.naive)
        self.rb = rb
        return rb

    def _close_run(self, reason: str) -> None:
        rb = self.rb
        self.rb = None
        if rb is not None and rb.n > 1:
            self.items.append(("run", rb, reason))
            if self.on_items is not None and len(self.items) >= ITEMS_WAITING_MAX:
                self.on_items()

    def _feed_value(self, start9, end9, length_mm: float | None, col: int) -> float:
        """Feed limit (mm/s, or deg/s for rotary-only moves) of one feed move."""
        if self.feed_inverse_time:
            if length_mm is None:
                length_mm = _move_length(start9, end9)
            return length_mm * self.f_block / SECONDS_PER_MINUTE
        if self.f_word <= 0.0:
            raise self.error("feed move with zero or missing feed rate (F)", col)
        if self.len_unit != 1.0 and _move_length(start9, end9, rotary=True) > 0.0:
            return self.f_word / SECONDS_PER_MINUTE  # a rotary-only move: F in deg/min
        return self.f_word * (self.len_unit * _PER_MIN)

    def straight(self, kind: str, new: list[float], line: int, col: int) -> None:
        """A G0 (``kind="rapid"``) or G1 (``"feed"``) move to 9-axis machine position ``new``."""
        pos = self.pos
        if kind == "feed":
            feed = self._feed_value(pos, new, None, col)
            tol, naive = self.tol, self.naive
        else:
            feed, tol, naive = INF, self.tol, self.naive
        if new == pos:
            self._zero_length(line)
            return
        rb = self.rb
        if rb is None or rb.kind != kind:
            rb = self._start_run(kind, line, col)
        rb.nodes.extend(self.getter(new))
        rb.line.append(line)
        rb.col.append(col)
        rb.feed.append(feed)
        rb.tol.append(tol)
        rb.naive.append(naive)
        self.pos = new
        if self.exact_stop:
            self._close_run("exact-stop")

    def _zero_length(self, line: int) -> None:
        self.zero_length_moves += 1
        if len(self.zero_length_lines) < 1000:
            self.zero_length_lines.append(line)

    def _curve(self, curve, pts9: np.ndarray, end9: list[float], line: int, col: int, feed: float) -> None:
        rb = self.rb
        if rb is None or rb.kind != "feed":
            rb = self._start_run("feed", line, col)
        first, last = rb.add_many(pts9, line, col, feed, self.tol, self.naive)
        rb.curves.append((first, last, curve))
        self.pos = list(end9)
        if self.exact_stop:
            self._close_run("exact-stop")

    # canned-cycle callbacks
    def cycle_move(self, kind: str, target9: list[float], line: int, col: int) -> None:
        tol, self.tol = self.tol, 0.0  # cycles run as exact path (G61)
        try:
            self.straight(kind, target9, line, col)
        finally:
            self.tol = tol

    def cycle_dwell(self, seconds: float, line: int) -> None:
        self._dwell(seconds, line)

    def _dwell(self, seconds: float, line: int) -> None:
        self._close_run("dwell")
        if self._mark_pending is not None:
            self._flush_mark()
        self.items.append(("dwell", Dwell(line=line, seconds=float(seconds), position=None), list(self.pos)))

    def _stop(self, code: str, line: int, reason: str) -> None:
        self._close_run(reason)
        if self._mark_pending is not None:
            self._flush_mark()
        self.items.append(("stop", Stop(line=line, code=code, position=None), list(self.pos)))

    # -- the main loop ------------------------------------------------------------
    def run(self, blocks) -> None:
        """Interpret every block (stops after M2/M30, as LinuxCNC does).

        The loop keeps the fast path's state in local variables (CPython looks them up
        far faster than attributes) and reloads them after every general block.
        """
        nblocks = 0
        fast_ok, off, u9, inc, kind_get, feed_scale = self._fast_state()
        rb = self.rb
        rb_kind = None
        getter = self.getter
        pos = self.pos
        for blk in blocks:
            nblocks += 1
            words = blk.words
            if fast_ok:
                # ---- fast path: a plain G0/G1 block of axis, N, F, S words ----
                new = None
                gcode = -1
                gcol = 0
                fw = None
                seen = 0
                arcw = False
                for L, v, c in words:
                    k = kind_get(L, -9)
                    if k >= 0:
                        if (seen >> k) & 1:
                            break
                        seen |= 1 << k
                        if new is None:
                            new = pos[:]
                            if gcol == 0:
                                gcol = c
                        if inc:
                            new[k] += v * u9[k]
                        else:
                            new[k] = v * u9[k] + off[k]
                    elif k == -1 or k == -3:
                        continue
                    elif k == -5:
                        arcw = True
                    elif k == -2 and fw is None:
                        fw = (L, v, c)
                    elif k == -4 and gcode < 0:
                        gcode = _FAST_G.get(v, -2)
                        if gcode == -2:
                            break
                        gcol = c
                    else:
                        break
                else:
                    # no break: the block is plain
                    if gcode < 0:
                        gcode = self.motion
                        explicit = False
                    else:
                        explicit = True
                    if gcode == G2 or gcode == G3:
                        # a plain G2/G3 block: skip the general classification
                        if self._fast_arc(blk, words, gcode, gcol, fw):
                            rb = None
                            pos = self.pos
                            continue
                    elif arcw:
                        pass  # I/J/K/R/P with G0/G1: the general path reports it
                    elif gcode == G1 or gcode == G0:
                        if explicit and self.motion != gcode:
                            self.motion = gcode
                            self.cycle_il = None
                        if fw is not None:
                            if fw[1] < 0:
                                self.blk = blk
                                raise self.error("negative feed rate", fw[2])
                            self.f_word = fw[1]
                        if new is None:
                            if not words and self.marks and blk.comment is not None:
                                self._header(blk, nblocks)
                            continue
                        if gcode == G1:
                            kind = "feed"
                            if self.f_word <= 0.0:
                                self.blk = blk
                                raise self.error("feed move with zero or missing feed rate (F)", gcol)
                            if feed_scale is None:
                                feed = self._feed_value(pos, new, None, gcol)
                            else:
                                feed = self.f_word * feed_scale
                        else:
                            kind = "rapid"
                            feed = INF
                        if new == pos:
                            self._zero_length(blk.line)
                            continue
                        if rb is None or rb_kind != kind:
                            rb = self.rb
                            if rb is None or rb.kind != kind:
                                rb = self._start_run(kind, blk.line, gcol)
                            rb_kind = kind
                            ext_nodes = rb.nodes.extend
                            app_line = rb.line.append
                            app_col = rb.col.append
                            app_feed = rb.feed.append
                            app_tol = rb.tol.append
                            app_naive = rb.naive.append
                            tol = self.tol
                            naive = self.naive
                        ext_nodes(getter(new))
                        app_line(blk.line)
                        app_col(gcol)
                        app_feed(feed)
                        app_tol(tol)
                        app_naive(naive)
                        self.pos = pos = new
                        continue
            # ---- everything else ----
            self.blk = blk
            if not words:
                if self.marks and blk.comment is not None:
                    self._header(blk, nblocks)
                continue
            gw, mw, d = self._split_words(words)
            if self._general(blk, gw, mw, d):
                break
            fast_ok, off, u9, inc, kind_get, feed_scale = self._fast_state()
            rb = None  # re-bind the appenders on the next fast move
            getter = self.getter
            pos = self.pos
        self.block_count += nblocks
        self.blk = None
        if self.nurbs_cp is not None:
            raise GCodeError(
                "G5.2 NURBS block never ended (missing G5.3)",
                SourceLocation(self.source, self.nurbs_line, self.nurbs_col, "G5.2"),
            )
        self._close_run("end")

    def _fast_arc(self, blk, words, gcode: int, gcol: int, fw) -> bool:
        """A G2/G3 block of axis, I, J, K, R, P, F, N, S words; False: use the general path."""
        d = {}
        for w in words:
            if w[0] in d:
                return False
            d[w[0]] = w
        axis_words = [(L, w) for L, w in d.items() if L in AXIS_INDEX]
        if not axis_words and "I" not in d and "J" not in d and "K" not in d:
            return False  # the general path reports the missing words
        self.blk = blk
        self.f_block = 0.0
        if fw is not None:
            if fw[1] < 0:
                raise self.error("negative feed rate", fw[2])
            self.f_word = fw[1]
            self.f_block = fw[1]
        if gcol == 0:
            gcol = axis_words[0][1][2] if axis_words else words[0][2]
        self._arc(gcode, gcol, d, axis_words, blk.line)
        if self.motion != gcode:
            self.motion = gcode
            self.cycle_il = None
        return True

    def _fast_state(self):
        """(fast path allowed, offsets, units, incremental, letter-kind lookup, feed scale)."""
        ok = not self.feed_inverse_time and not self.exact_stop and self.nurbs_cp is None and not self.rot_deg
        # letters of inactive axes send the block to the general path (it activates or rejects)
        kinds = dict(_FAST_KIND)
        for i, a in enumerate(ALL_AXES):
            if i not in self.active:
                kinds[a] = -9
        # mm/min -> mm/s factor of F, or None when a rotary-only move may need deg/min
        rotary = any(i in self.active for i in (3, 4, 5))
        feed_scale = None if (rotary and self.len_unit != 1.0) else self.len_unit * _PER_MIN
        return ok, self.off, self.units9, self.distance_incremental, kinds.get, feed_scale

    def _split_words(self, words):
        """(G words, M words, {letter: word}) of a block; a repeated letter is an error."""
        gw = []
        mw = []
        d = {}
        for w in words:
            L = w[0]
            if L == "G":
                gw.append(w)
            elif L == "M":
                mw.append(w)
            elif L in d:
                raise self.error(f"two {L} words in one block", w[2])
            else:
                d[L] = w
        return gw, mw, d

    # -- general blocks ---------------------------------------------------------
    # One method per step of RS274NGC's order of execution within a block (LinuxCNC's
    # "G-code order of execution" table), called in that order by ``_general``. The
    # comment, spindle, coolant, override and I/O steps do not move the machine and have
    # no method; units (16) are taken before F (4), since ``_switch_units`` converts the F
    # in effect.
    def _general(self, blk, gw, mw, d) -> bool:
        """Execute one block in RS274NGC order; True when the program ends (M2/M30)."""
        line = blk.line
        for L, w in d.items():
            if L not in VALID_LETTERS:
                raise self.error(f"unknown word letter {L}", w[2])
        groups, g80 = self._g_groups(gw)
        mgroups = self._m_groups(mw)
        g0 = groups.get(0)
        g0code = g0[0] if g0 else None
        axis_words = [(L, w) for L, w in d.items() if L in AXIS_INDEX]
        # G10, G28, G30, G92 and G43.1/G43.2 take their values from the axis words
        covets = g0code in AXIS_WORD_CODES or groups.get(8, (0,))[0] in TOOL_LENGTH_AXIS_CODES
        polar = "@" in d or "^" in d
        if polar:
            self._check_polar(d, g0code, covets)
        mcode = groups[1][0] if 1 in groups else None
        self._check_unused_words(d, groups, mgroups, mcode, g0code, covets, axis_words)

        # the numbers are the steps of LinuxCNC's "order of execution" table
        if 5 in groups:  # 3. feed mode
            self._step_feed_mode(groups[5][0])
        if 6 in groups:  # 16. units, taken before F and the coordinates ('G20 F10' is 10 in/min)
            self._step_units(groups[6][0])
        self._step_feed_rate(d.get("F"))  # 4.
        tw = d.get("T")
        if tw is not None:  # 6.
            self._step_select_tool(tw)
        if 6 in mgroups and mgroups[6][0] == M6:  # 8.
            self._step_change_tool(line)
        if g0code == G4:  # 14.
            self._step_dwell(d, g0[1], line)
        if 2 in groups:  # 15.
            self._step_plane(groups[2])
        if 8 in groups:  # 18. tool length (17, G40, changes nothing that moves)
            self._tool_length(groups[8][0], groups[8][1], d, axis_words)
        if 12 in groups:  # 19.
            self._load_coordinate_system(COORDINATE_SYSTEM[groups[12][0]])
        if 13 in groups:  # 20.
            self._step_path_control(groups[13][0], d)
        self._step_distance_modes(groups)  # 21., 22.
        self._step_axis_words(groups, g80, g0, mcode, covets, axis_words)
        g53 = False
        if g0code is not None and g0code != G4:  # 23. non-modal codes
            g53 = self._group0(g0code, g0[1], d, axis_words, line)
        if mcode is not None:  # 24. motion
            self._step_motion_code(mcode, groups[1][1], d, axis_words, line, g53)
        elif (axis_words or polar) and not covets:
            self._step_modal_motion(d, axis_words, line, g53)
        if 4 in mgroups:  # 25.
            return self._step_stop(mgroups[4][0], line)
        return False

    def _g_groups(self, gw) -> tuple[dict[int, tuple[int, int]], bool]:
        """The block's G-codes by modal group ({group: (code, col)}) and whether G80 is
        among them; an unknown or unsupported code, or two of one group, is an error."""
        groups: dict[int, tuple[int, int]] = {}
        g80 = False
        for w in gw or ():
            v = w[1]
            code = int(round(v * 10))
            if abs(v * 10 - code) > 1e-6 or code < 0:
                raise self.error(f"unknown G-code G{v:g}", w[2])
            if code in G_UNSUPPORTED and code not in G_GROUP:
                raise self.error(f"{G_UNSUPPORTED[code]} is not supported", w[2], unsupported=True)
            grp = G_GROUP.get(code)
            if grp is None:
                raise self.error(f"unknown G-code {gcode_name(code)}", w[2])
            if code == G80:
                g80 = True
                if 1 in groups:
                    continue
                groups[1] = (code, w[2])
                continue
            if grp in groups:
                prev = groups[grp][0]
                if grp == 1 and prev == G80:
                    groups[1] = (code, w[2])
                    continue
                raise self.error(f"{gcode_name(prev)} and {gcode_name(code)} are in the same modal group", w[2])
            groups[grp] = (code, w[2])
        return groups, g80

    def _m_groups(self, mw) -> dict[int, tuple[int, int]]:
        """The block's M-codes by modal group ({group: (code, col)}); an unknown or
        unsupported code, or two of one group, is an error."""
        mgroups: dict[int, tuple[int, int]] = {}
        for w in mw or ():
            v = w[1]
            code = int(round(v))
            if abs(v - code) > 1e-9 or code < 0:
                raise self.error(f"unknown M-code M{v:g}", w[2])
            if code in M_UNSUPPORTED:
                raise self.error(f"{M_UNSUPPORTED[code]} is not supported", w[2], unsupported=True)
            declared = code in self.noop_mcodes
            if 100 <= code <= 199 and not declared:
                raise self.error(
                    f"user-defined M-code M{code} is not supported{_NOOP_HINT.format(code=code)}",
                    w[2],
                    unsupported=True,
                )
            if code not in M_NOOP and code not in M_STOPS and code != M6 and not declared:
                raise self.error(f"unknown M-code M{code}{_NOOP_HINT.format(code=code)}", w[2])
            grp = M_GROUP.get(code, 100 + code)
            if grp in mgroups:
                raise self.error(f"M{mgroups[grp][0]} and M{code} are in the same modal group", w[2])
            mgroups[grp] = (code, w[2])
        return mgroups

    def _step_feed_mode(self, code: int) -> None:
        """G93 inverse time, G94 units per minute."""
        self.feed_inverse_time = code == G93

    def _step_units(self, code: int) -> None:
        """G20 inch, G21 mm (taken before F: ``_switch_units`` converts the F in effect)."""
        self._switch_units(MM_PER_INCH if code == G20 else 1.0)

    def _step_feed_rate(self, fw) -> None:
        """F: the feed in effect, and the block's own F (inverse time needs one per move)."""
        self.f_block = 0.0
        if fw is not None:
            if fw[1] < 0:
                raise self.error("negative feed rate", fw[2])
            self.f_word = fw[1]
            self.f_block = fw[1]

    def _step_select_tool(self, tw) -> None:
        """T: the tool the next M6 loads."""
        if tw[1] < 0 or tw[1] != int(tw[1]):
            raise self.error("tool number T must be a non-negative integer", tw[2])
        self.tool_selected = int(tw[1])

    def _step_change_tool(self, line: int) -> None:
        """M6: the selected tool goes in the spindle (#5400); the machine stops for it."""
        self.tool = self.tool_selected
        self._pset(5400, self.tool)
        self._stop("M6", line, "tool-change")
        if self.marks:
            self.items.append(("mark", Mark(line=line, tool=int(self.tool)), None))

    def _header(self, blk, nblocks: int) -> None:
        """A comment-only block: the first of a group of them names an operation (a
        ``Mark``, handed on once no run is open); MSG, DEBUG, PRINT, LOG and PROBE
        comments are messages, not headers."""
        follows = nblocks == self._header_block + 1
        self._header_block = nblocks
        text = " ".join(blk.comment.split())
        if follows or not text or text.lower().startswith(_MESSAGE_COMMENTS):
            return
        self._mark_pending = Mark(line=blk.line, operation=text)
        if self.rb is None:
            self._flush_mark()

    def _flush_mark(self) -> None:
        self.items.append(("mark", self._mark_pending, None))
        self._mark_pending = None

    def _step_dwell(self, d: dict, col: int, line: int) -> None:
        """G4 P seconds."""
        pw = d.get("P")
        if pw is None:
            raise self.error("G4 dwell without P (seconds)", col)
        if pw[1] < 0:
            raise self.error("negative dwell time P", pw[2])
        self._dwell(pw[1], line)

    def _step_plane(self, code_col: tuple[int, int]) -> None:
        """G17, G18, G19 (not inside a G5.2 NURBS block)."""
        newp, col = code_col
        if self.nurbs_cp is not None and newp != self.plane:
            raise self.error("plane change inside a G5.2 NURBS block", col)
        self.plane = newp

    def _step_path_control(self, code: int, d: dict) -> None:
        """G61, G61.1 exact path (G61.1 also stops at every block end); G64 [P tol] [Q tol]."""
        self.exact_stop = code == G61_1
        if code in EXACT_PATH:
            self.tol, self.naive = 0.0, NAN
            return
        self.tol, self.naive = NAN, NAN
        pw, qw = d.get("P"), d.get("Q")
        if pw is not None:
            if pw[1] < 0:
                raise self.error("negative G64 P tolerance", pw[2])
            self.tol = pw[1] * self.len_unit if pw[1] > 0 else NAN
        if qw is not None:
            if qw[1] < 0:
                raise self.error("negative G64 Q tolerance", qw[2])
            self.naive = qw[1] * self.len_unit

    def _step_distance_modes(self, groups: dict) -> None:
        """G90/G91 distance mode, G90.1/G91.1 arc centre mode, G98/G99 cycle return."""
        if 3 in groups:
            self.distance_incremental = groups[3][0] == G91
        if 4 in groups:
            self.arc_abs = groups[4][0] == G90_1
        if 10 in groups:
            self.retract_r_plane = groups[10][0] == G99

    def _step_axis_words(self, groups, g80: bool, g0, mcode, covets: bool, axis_words: list) -> None:
        """Who uses the axis words (RS274NGC's enhance_block rules); the axes they name
        become active."""
        if covets and mcode is not None and mcode != G80:
            # the code that claims them: G10/G28/G30/G92 (group 0), else G43.1/G43.2 (group 8)
            owner = g0 if g0 is not None and g0[0] in AXIS_WORD_CODES else groups[8]
            raise self.error(f"{gcode_name(owner[0])} and {gcode_name(mcode)} both use the axis words", owner[1])
        if g80 and axis_words and not covets and mcode == G80:
            raise self.error("axis words with G80 (cycle cancel) and no motion", axis_words[0][1][2])
        for L, w in axis_words:
            self._activate(AXIS_INDEX[L], w[2])

    def _step_motion_code(self, mcode: int, col: int, d: dict, axis_words: list, line: int, g53: bool) -> None:
        """The block's own motion code: G0-G3, G5-G5.3, the canned cycles, G80."""
        if mcode != self.motion or mcode == G80:
            if mcode not in CYCLE_MOTIONS:
                self.cycle_il = None
        if self.nurbs_cp is not None and mcode != G5_2:
            if mcode == G5_3:
                self._nurbs_end(line, col)
                self.motion = G80
            else:
                raise self._nurbs_unended()
        elif mcode == G5_3:
            raise self.error("G5.3 without an open G5.2 NURBS block", col)
        elif mcode == G80:
            self.motion = G80
        else:
            full_circle = mcode in ARCS and any(k in d for k in "IJK")
            polar = "@" in d or "^" in d
            if not axis_words and not polar and mcode not in AXISLESS_MOTIONS and not full_circle:
                raise self.error(f"{gcode_name(mcode)} without any axis word", col)
            self._motion(mcode, col, d, axis_words, line, g53)

    def _step_modal_motion(self, d: dict, axis_words: list, line: int, g53: bool) -> None:
        """Axis words alone: the motion mode in effect moves to them."""
        if self.motion == G80:
            col = axis_words[0][1][2] if axis_words else _polar_col(d)
            raise self.error("axis words without a motion mode (G0, G1, ...)", col)
        self._motion(self.motion, 0, d, axis_words, line, g53)

    def _step_stop(self, code: int, line: int) -> bool:
        """M0, M1, M60 pause; M2, M30 end the program (True)."""
        if code in (M2, M30):
            if self.nurbs_cp is not None:
                raise self._nurbs_unended()
            self._stop(M_STOPS[code], line, "end")
            return True
        self._stop(M_STOPS[code], line, "stop")
        return False

    def _nurbs_unended(self) -> GCodeError:
        """The error for a G5.2 block that a non-NURBS code or the program end cuts short."""
        return GCodeError(
            "G5.2 NURBS block never ended (missing G5.3)",
            SourceLocation(self.source, self.nurbs_line, self.nurbs_col, "G5.2"),
        )

    def _check_unused_words(self, d, groups, mgroups, mcode, g0code, covets, axis_words):
        """LinuxCNC rejects a parameter word no code of the block uses (e.g. I with G1)."""
        motion = mcode if mcode is not None else (self.motion if axis_words and not covets else None)
        if motion == G80:
            motion = None
        cycle = motion is not None and motion // 10 in CYCLE_CODES
        path = groups.get(13, (None,))[0]
        ms = {c for c, _ in mgroups.values()}
        user_m = bool(ms & self.noop_mcodes)  # a declared M-code takes P and Q, as LinuxCNC's M1nn
        use = {
            "I": motion in USES_IJ,
            "J": motion in USES_IJ,
            "K": motion in ARCS,
            "R": motion in ARCS or cycle or g0code == G10,
            "P": (g0code in NON_MODAL_USES_P or path == G64 or motion in USES_P or bool(ms & M_USE_P) or user_m),
            "Q": path == G64 or motion in USES_Q or bool(ms & M_USE_QE) or user_m,
            "L": g0code == G10 or cycle or motion == G5_2,
            "H": 8 in groups,
            "D": False,
            "E": bool(ms & M_USE_QE),
        }
        for L, w in d.items():
            if not use.get(L, True):
                raise self.error(f"{L} word with no code in the block that uses it", w[2])

    # -- group 0 ------------------------------------------------------------------
    def _group0(self, code: int, col: int, d: dict, axis_words: list, line: int) -> bool:
        u = self.units9
        if code == G53:
            if self.distance_incremental:
                raise self.error("G53 in incremental distance mode (G91)", col)
            return True
        if code == G10:
            self._g10(col, d, axis_words)
        elif code == G92:
            if not axis_words:
                raise self.error("G92 without axis words", col)
            q = self._to_prog_mm(self.pos)
            for L, w in axis_words:
                i = AXIS_INDEX[L]
                # keep the machine still: program value w becomes the current position
                self.g92[i] = q[i] + self.g92[i] - w[1] * u[i]
            self._update_off()
            self._pset(5210, 1.0)
            for k in range(9):
                self._pset(5211 + k, self.g92[k] / u[k])
        elif code in (G92_1, G92_2):
            self.g92 = [0.0] * 9
            self._update_off()
            self._pset(5210, 0.0)
            if code == G92_1:
                for k in range(9):
                    self._pset(5211 + k, 0.0)
        elif code == G92_3:
            self.g92 = [self._pget(5211 + k) * u[k] for k in range(9)]
            self._update_off()
            self._pset(5210, 1.0)
        elif code in (G28, G30):
            base = 5161 if code == G28 else 5181
            if axis_words:
                inter = self._target(axis_words)
                self.straight("rapid", inter, line, col)
                home = list(self.pos)
                for L, _ in axis_words:
                    i = AXIS_INDEX[L]
                    home[i] = self._pget(base + i) * u[i]
            else:
                home = [self._pget(base + k) * u[k] for k in range(9)]
                for k in range(9):
                    if home[k] != self.pos[k]:
                        self._activate(k, col)
            self.straight("rapid", home, line, col)
        elif code in (G28_1, G30_1):
            base = 5161 if code == G28_1 else 5181
            for k in range(9):
                self._pset(base + k, self.pos[k] / u[k])
        return False

    def _g10_tool(self, lv: float, d: dict, axis_words: list, col: int) -> None:
        """G10 L1 P<tool> <axes>: set the tool's offsets in the table; L10/L11 (offsets from
        the current position) are recorded, and a later G43 of that tool is refused."""
        pw = d.get("P")
        if pw is None or pw[1] < 0 or pw[1] != int(pw[1]):
            raise self.error(f"G10 L{lv:g} needs P (a tool number)", col)
        tool = int(pw[1])
        if lv != 1.0:
            self.tools_touched.add(tool)
            return
        from .tooltable import ToolTable

        self._load_tool_table()
        if self.tool_table is None:
            self.tool_table = ToolTable()
            self.tool_table.source = "(G10 L1)"
        offs = list(self.tool_table.get(tool, (0.0,) * 9))
        for L, w in axis_words:
            i = AXIS_INDEX[L]
            offs[i] = w[1] * self.units9[i]
        self.tool_table[tool] = tuple(offs)
        self.tools_touched.discard(tool)

    def _load_tool_table(self) -> None:
        """Read the tool table file on first use (a program without G43 Hn never needs it,
        so a machine whose INI names a missing table still plans such programs)."""
        if self.tool_table is None and self.tool_table_path is not None:
            from .tooltable import read_tool_table

            path, self.tool_table_path = self.tool_table_path, None
            self.tool_table = read_tool_table(path)

    def _tool_length(self, code: int, col: int, d: dict, axis_words: list) -> None:
        """G43 [H], G43.1 axes, G43.2 H|axes, G49 (LinuxCNC semantics)."""
        if code == G49:
            tlo = [0.0] * 9
        elif code == G43_1:
            if not axis_words:
                raise self.error("G43.1 without axis words (the offsets)", col)
            tlo = [0.0] * 9
            for L, w in axis_words:
                i = AXIS_INDEX[L]
                tlo[i] = w[1] * self.units9[i]
        else:
            hw = d.get("H")
            if code == G43_2 and hw is None and not axis_words:
                raise self.error("G43.2 without H or axis words", col)
            if code == G43_2 and hw is not None and axis_words:
                raise self.error("G43.2 takes H or axis words, not both", col)
            tlo = [0.0] * 9 if code == G43 else list(self.tlo)
            if hw is not None or code == G43:
                tool = self.tool if hw is None else hw[1]  # G43 alone: the tool in the spindle
                hcol = hw[2] if hw is not None else col
                if tool < 0 or tool != int(tool):
                    raise self.error("H must be a non-negative integer (a tool number)", hcol)
                add = self._tool_offsets(int(tool), hcol)
                tlo = [a + b for a, b in zip(tlo, add)]
            if code == G43_2:  # G43's axis words are a motion in the same block, not offsets
                for L, w in axis_words:
                    i = AXIS_INDEX[L]
                    tlo[i] += w[1] * self.units9[i]
        self.tlo = tlo
        self._update_off()
        for k in range(9):  # #5401-#5409: the offset in effect, program units
            self._pset(5401 + k, tlo[k] / self.units9[k])

    def _tool_offsets(self, tool: int, col: int) -> list[float]:
        """Offsets (mm/deg) of ``tool`` from the tool table; tool 0 has none."""
        if tool == 0:
            return [0.0] * 9
        if tool in self.tools_touched:
            raise self.error(
                f"tool {tool} was changed by G10 L10/L11; such tool table edits are not supported",
                col,
                unsupported=True,
            )
        self._load_tool_table()
        if self.tool_table is None:
            if not self.warnings:
                self.warnings.append(
                    f"{self.source}:{self.blk.line}:{max(col, 1)}: warning: G43 H{tool} with no "
                    "tool table (--tool-table FILE): tool lengths are taken as 0, so the "
                    "program's geometry and timing are as written"
                )
            return [0.0] * 9
        offs = self.tool_table.get(tool)
        if offs is None:
            raise self.error(f"tool {tool} is not in the tool table {self.tool_table.source}", col)
        return list(offs)

    def _g10(self, col: int, d: dict, axis_words: list) -> None:
        lw, pw = d.get("L"), d.get("P")
        if lw is None:
            raise self.error("G10 without L", col)
        lv = lw[1]
        if lv in (1.0, 10.0, 11.0):
            self._g10_tool(lv, d, axis_words, col)  # a tool table entry: nothing moves
            return
        if lv not in (2.0, 20.0):
            raise self.error(f"G10 L{lv:g} is not supported", lw[2], unsupported=True)
        if pw is None:
            raise self.error(f"G10 L{lv:g} without P (coordinate system)", col)
        p = pw[1]
        if p != int(p) or not 0 <= p <= 9:
            raise self.error("G10 P must be a coordinate system 0-9", pw[2])
        rw = d.get("R")
        cs = int(p) or self.cs
        base = 5201 + 20 * cs
        u = self.units9
        if lv == 20.0:
            if rw is not None:
                raise self.error("R (rotation) with G10 L20 is not supported", rw[2], unsupported=True)
            q = self._to_prog_mm(self.pos)
            for L, w in axis_words:
                q[AXIS_INDEX[L]] = w[1] * u[AXIS_INDEX[L]]
            # offsets that make the current machine position read as q
            rot = self.rot_deg if cs == self.cs else self._pget(base + 9) % 360.0
            r = math.radians(rot)
            c, s_ = math.cos(r), math.sin(r)
            new = [self.pos[k] - q[k] - self.g92[k] for k in range(9)]
            vx, vy = q[0] + self.g92[0], q[1] + self.g92[1]
            new[0] = self.pos[0] - (c * vx - s_ * vy)
            new[1] = self.pos[1] - (s_ * vx + c * vy)
            named = [AXIS_INDEX[L] for L, _ in axis_words]
            if rot and (0 in named or 1 in named):
                named = sorted(set(named) | {0, 1})
            for i in named:
                self._pset(base + i, new[i] / u[i])
                if cs == self.cs:
                    self.coord_off[i] = new[i]
        else:
            for L, w in axis_words:
                i = AXIS_INDEX[L]
                val_mm = w[1] * u[i]
                self._pset(base + i, val_mm / u[i])
                if cs == self.cs:
                    self.coord_off[i] = val_mm
            if rw is not None:
                self._pset(base + 9, rw[1])
                if cs == self.cs:
                    self._set_rotation(rw[1])
        self._update_off()

    # -- polar coordinates ----------------------------------------------------------
    def _check_polar(self, d: dict, g0code, covets: bool) -> None:
        """LinuxCNC's rules for @ (polar distance) and ^ (polar angle, degrees): never with
        X or Y words, G53 or a code that takes axis values, on a machine with X and Y (the
        XY plane is checked at the motion, after the block's own plane code)."""
        col = _polar_col(d)
        for L in "XY":
            if L in d:
                raise self.error(f"polar coordinates (@ ^) and a {L} word in one block", d[L][2])
        if g0code == G53:
            raise self.error("polar coordinates (@ ^) with G53", col)
        if covets:
            raise self.error("polar coordinates (@ ^) with a code that takes axis values (G10, G28, G30, G92)", col)
        self._activate(0, col)
        self._activate(1, col)

    def _polar_words(self, d: dict) -> list:
        """The X and Y words equivalent to the block's @ and ^ words (LinuxCNC's
        ``find_ends``): the polar origin is the program origin; in G90, @ and ^ replace
        the current distance and angle, in G91 they add to them."""
        col = _polar_col(d)
        cur = self.program_position()
        x0, y0 = cur[0], cur[1]
        r_word = d["@"][1] if "@" in d else None
        a_word = d["^"][1] if "^" in d else None
        if self.distance_incremental:
            try:
                x, y = polar_increment(x0, y0, r_word, a_word)
            except CycleError as exc:
                raise self.error(str(exc), col) from None
            x, y = x - x0, y - y0
        else:
            if a_word is None and x0 == 0.0 and y0 == 0.0:
                raise self.error("polar distance @ at the origin needs an angle ^", col)
            radius = r_word if r_word is not None else math.hypot(x0, y0)
            theta = math.radians(a_word) if a_word is not None else math.atan2(y0, x0)
            x, y = radius * math.cos(theta), radius * math.sin(theta)
        return [("X", ("X", x, col)), ("Y", ("Y", y, col))]

    # -- motion -------------------------------------------------------------------
    def _target(self, axis_words, machine: bool = False) -> list[float]:
        """Machine position after a move to ``axis_words`` (program values, current modes)."""
        if self.rot_deg and not machine:
            q = self._to_prog_mm(self.pos)
            u = self.units9
            for L, w in axis_words:
                i = AXIS_INDEX[L]
                if self.distance_incremental:
                    q[i] += w[1] * u[i]
                else:
                    q[i] = w[1] * u[i]
            new = self._to_machine(q)
            # axes the block does not name stay exactly where they are
            named = {AXIS_INDEX[L] for L, _ in axis_words}
            for k in range(9):
                if k not in named and not (k < 2 and (0 in named or 1 in named)):
                    new[k] = self.pos[k]
            return new
        new = self.pos[:]
        u = self.units9
        inc = self.distance_incremental and not machine
        for L, w in axis_words:
            i = AXIS_INDEX[L]
            if inc:
                new[i] += w[1] * u[i]
            elif machine:
                new[i] = w[1] * u[i]
            else:
                new[i] = w[1] * u[i] + self.off[i]
        return new

    def _motion(self, code: int, col: int, d: dict, axis_words: list, line: int, g53: bool) -> None:
        if col == 0:
            col = axis_words[0][1][2] if axis_words else _polar_col(d)
        if "@" in d or "^" in d:
            if self.plane != G17:  # the block's own G17-G19 has taken effect by now
                raise self.error("polar coordinates (@ ^) outside the G17 (XY) plane", _polar_col(d))
            if code // 10 not in CYCLE_CODES:
                axis_words = axis_words + self._polar_words(d)
        if g53 and code not in STRAIGHT:
            raise self.error("G53 needs G0 or G1", col)
        if self.rot_deg and code not in ROTATABLE:
            raise self.error(
                f"{gcode_name(code)} with a rotated coordinate system (G10 L2 R) is not supported",
                col,
                unsupported=True,
            )
        if code in STRAIGHT:
            self.motion = code
            if axis_words:
                if code == G1 and self.feed_inverse_time and self.f_block <= 0:
                    raise self.error("G93 inverse time feed move without F", col)
                self.straight("feed" if code == G1 else "rapid", self._target(axis_words, machine=g53), line, col)
            return
        if code in ARCS:
            self._arc(code, col, d, axis_words, line)
            self.motion = code
            return
        if code in SPLINES:
            self._bezier(code, col, d, axis_words, line)
            self.motion = code
            return
        if code == G5_2:
            self._nurbs_point(col, d, axis_words, line)
            return
        if code // 10 in CYCLE_CODES:
            words = dict(d)
            try:
                expand_cycle(self, code // 10, words, line, col)
            except CycleError as exc:
                wcol = d[exc.letter][2] if exc.letter and exc.letter in d else col
                raise self.error(str(exc), wcol) from None
            self.motion = code
            return
        raise self.error(f"{gcode_name(code)} is not supported", col, unsupported=True)

    def _feed_check(self, col: int) -> None:
        if self.feed_inverse_time:
            if self.f_block <= 0:
                raise self.error("G93 inverse time feed move without F", col)
        elif self.f_word <= 0:
            raise self.error("feed move with zero or missing feed rate (F)", col)

    def _arc(self, code: int, col: int, d: dict, axis_words: list, line: int) -> None:
        self._feed_check(col)
        rotated = bool(self.rot_deg) and self.plane != G17
        plane = PLANES[self.plane]
        a, b, _ = plane
        for k in (a, b):
            self._activate(k, col)
        fl, sl, bad = PLANE_IJK[self.plane]
        if bad in d:
            raise self.error(f"{bad} word in an arc in the {PLANE_NAME[self.plane]} plane", d[bad][2])
        start = self.pos
        end_m = end = self._target(axis_words)
        if rotated:
            # G18/G19 under a rotation about Z: the arc lies in a plane of the program frame,
            # not of the machine's; its geometry is worked out in the program frame
            start, end = self._to_prog_mm(start), self._to_prog_mm(end)
        turns = 1
        pw = d.get("P")
        if pw is not None:
            p = pw[1]
            if p != int(p) or p < 1 or p > ARC_MAX_TURNS:
                raise self.error(f"arc turn count P must be a whole number from 1 to {ARC_MAX_TURNS}", pw[2])
            turns = int(p)
        ccw = code == G3
        ua, ub = self.units9[a], self.units9[b]
        rw = d.get("R")
        try:
            if rw is not None:
                if fl in d or sl in d:
                    raise self.error("arc with both R and I/J/K", rw[2])
                if not any(ALL_AXES[k] in d for k in (a, b)):
                    raise self.error("R-format arc without an end point in the plane", col)
                c1, c2, r1, r2, sweep = centre_from_r(
                    ccw, start[a], start[b], end[a], end[b], rw[1] * self.len_unit, turns
                )
            else:
                if fl not in d and sl not in d:
                    raise self.error(f"arc without R or centre offsets {fl}/{sl}", col)
                if self.arc_abs:
                    for ltr in (fl, sl):
                        if ltr not in d:
                            raise self.error(f"{ltr} word missing in absolute-centre arc (G90.1)", col)
                    if rotated:
                        c1, c2 = d[fl][1] * ua, d[sl][1] * ub
                    elif self.rot_deg:
                        q = self._to_prog_mm(start)
                        q[a], q[b] = d[fl][1] * ua, d[sl][1] * ub
                        cm = self._to_machine(q)
                        c1, c2 = cm[a], cm[b]
                    else:
                        c1 = d[fl][1] * ua + self.off[a]
                        c2 = d[sl][1] * ub + self.off[b]
                else:
                    o1 = d[fl][1] * ua if fl in d else 0.0
                    o2 = d[sl][1] * ub if sl in d else 0.0
                    if self.rot_deg and not rotated:  # the offset is a vector in the rotated program frame
                        c, s_ = self.rot_cs
                        o1, o2 = c * o1 - s_ * o2, s_ * o1 + c * o2
                    c1 = start[a] + o1
                    c2 = start[b] + o2
                r1, r2, sweep = centre_from_ijk(
                    ccw, start[a], start[b], end[a], end[b], c1, c2, turns, inch=self.len_unit != 1.0
                )
        except GeometryError as exc:
            raise self.error(str(exc), col) from None
        n = segment_count(max(r1, r2), sweep)
        if n > CURVE_MAX_NODES:
            raise self.error(
                f"arc too large: it needs {n} nodes at {CURVE_CHORD_TOL_MM} mm chord error (limit {CURVE_MAX_NODES})",
                col,
            )
        if self.feed_inverse_time:
            length = arc_length_mm(start, end, plane, r1, r2, sweep)
            feed = length * self.f_block / SECONDS_PER_MINUTE
        else:
            feed = self.f_word * (self.len_unit * _PER_MIN)
        # Node slots are reserved now and filled for all arcs of the run at once, and the
        # exact Arc is built, when the run is finished (runs.finish_run).
        rb = self.rb
        if rb is None or rb.kind != "feed":
            rb = self._start_run("feed", line, col)
        if rotated:
            # nodes only (chord error as for every arc), mapped rigidly to the machine frame
            prog = np.empty((n + 1, 9))
            fill_arc_nodes(prog, tuple(range(9)), [(0, n, (line, start, end, plane, c1, c2, r1, r2, sweep))])
            pts = np.array([self._to_machine(list(row)) for row in prog[1:]])
            pts[-1] = end_m
            # the nodes inside the arc are samples of one smooth curve, already off it by up
            # to the chord error: they are no corners, so G61's exact path (tol 0) does not
            # stop at them (the block's end keeps the mode's tolerance)
            inner = self.tol if math.isnan(self.tol) else max(self.tol, CURVE_CHORD_TOL_MM)
            rb.add_many(pts[:-1], line, col, feed, inner, self.naive)
            rb.add_many(pts[-1:], line, col, feed, self.tol, self.naive)
        else:
            first, last = rb.reserve(n, line, col, feed, self.tol, self.naive)
            rb.curves.append((first, last, (line, start, end, plane, c1, c2, r1, r2, sweep)))
        self.pos = end_m
        if self.exact_stop:
            self._close_run("exact-stop")

    def _curve_feed(self, pts9: np.ndarray, start9) -> float:
        if self.feed_inverse_time:
            allp = np.vstack([np.asarray(start9)[None, :], pts9])
            length = float(np.sqrt((np.diff(allp, axis=0) ** 2).sum(axis=1)).sum())
            return length * self.f_block / SECONDS_PER_MINUTE
        return self.f_word * (self.len_unit * _PER_MIN)

    def _bezier(self, code: int, col: int, d: dict, axis_words: list, line: int) -> None:
        self._feed_check(col)
        if self.plane != G17:
            raise self.error(f"{gcode_name(code)} splines must be in the XY plane (G17)", col, unsupported=True)
        for L, w in axis_words:
            if L not in "XY":
                raise self.error(f"{gcode_name(code)} splines may only move X and Y", w[2])
        self._activate(0, col)
        self._activate(1, col)
        start = self.pos
        end = self._target(axis_words)
        u = self.len_unit
        iw, jw = d.get("I"), d.get("J")
        if code == G5_1:
            if iw is None or jw is None:
                raise self.error("G5.1 needs both I and J", col)
            p1 = list(start)
            p1[0] += iw[1] * u
            p1[1] += jw[1] * u
            ctrl = [start, p1, end]
            self.g5_tangent = None
        else:
            pw, qw = d.get("P"), d.get("Q")
            if pw is None or qw is None:
                raise self.error("G5 needs both P and Q", col)
            if iw is None and jw is None:
                if self.g5_tangent is None or self.motion != G5:
                    raise self.error("G5 without I and J must follow another G5", col)
                di, dj = self.g5_tangent
            elif iw is None or jw is None:
                raise self.error("G5 needs both I and J, or neither", col)
            else:
                di, dj = iw[1] * u, jw[1] * u
            p1 = list(start)
            p1[0] += di
            p1[1] += dj
            p2 = list(end)
            p2[0] += pw[1] * u
            p2[1] += qw[1] * u
            ctrl = [start, p1, p2, end]
            self.g5_tangent = (-pw[1] * u, -qw[1] * u)
        if end == start and all(c == start for c in ctrl):
            self._zero_length(line)
            return
        # a cusp (the curve stops and turns back) is a corner of the path: each arc of
        # the curve between cusps is a curve of its own, the block's feed on all of them
        pieces = [np.array(ctrl, dtype=float)]
        done = 0.0
        for t in bezier_cusps(pieces[0]):
            head, tail = split_bezier(pieces[-1], (t - done) / (1.0 - done))
            pieces[-1:] = [head, tail]
            done = t
        try:
            curves = [bezier(line, c) for c in pieces]
            samples = [sample_nurbs(c) for c in curves]
        except GeometryError as exc:
            raise self.error(str(exc), col) from None
        feed = self._curve_feed(np.vstack(samples), start)
        for curve, pts in zip(curves, samples):
            self._curve(curve, pts, list(curve.control[-1]), line, col, feed)
        self.pos = list(end)  # the exact end point, not the last piece's float copy

    def _nurbs_point(self, col: int, d: dict, axis_words: list, line: int) -> None:
        a, b, _ = PLANES[self.plane]
        la, lb = ALL_AXES[a], ALL_AXES[b]
        pw = d.get("P")
        lw = d.get("L")
        if self.nurbs_cp is None:
            self._feed_check(col)
            self._activate(a, col)
            self._activate(b, col)
            w0 = 1.0
            if not axis_words and pw is not None:
                w0 = pw[1]
                if w0 <= 0:
                    raise self.error("NURBS weight P must be positive", pw[2])
            self.nurbs_cp = [list(self.pos)]
            self.nurbs_w = [w0]
            self.nurbs_order = 3
            self.nurbs_line = line
            self.nurbs_col = col
            self.motion = G5_2
        if lw is not None:
            lv = lw[1]
            if lv != int(lv) or lv < 1:
                raise self.error("NURBS order L must be a positive integer", lw[2])
            if lv > 3:
                self.nurbs_order = int(lv)
        if not axis_words:
            if pw is not None and len(self.nurbs_cp) > 1:
                raise self.error("P without a control point in a G5.2 block", pw[2])
            return
        for L, w in axis_words:
            if L not in (la, lb):
                raise self.error(
                    f"{L} word in a G5.2 NURBS block (only {la} and {lb} in the {PLANE_NAME[self.plane]} plane)",
                    w[2],
                    unsupported=True,
                )
        if la not in d or lb not in d:
            raise self.error(f"a NURBS control point needs both {la} and {lb}", col)
        if pw is None or pw[1] <= 0:
            raise self.error("every NURBS control point needs a positive weight P", pw[2] if pw else col)
        cp = self._target(axis_words)
        base = self.nurbs_cp[0]
        pt = list(base)
        pt[a], pt[b] = cp[a], cp[b]
        self.nurbs_cp.append(pt)
        self.nurbs_w.append(pw[1])

    def _nurbs_end(self, line: int, col: int) -> None:
        cps = np.array(self.nurbs_cp, dtype=float)
        w = np.array(self.nurbs_w, dtype=float)
        order = self.nurbs_order
        self.nurbs_cp = None
        self.nurbs_w = None
        try:
            curve = make_nurbs(self.nurbs_line, cps, w, order)
            pts = sample_nurbs(curve)
        except GeometryError as exc:
            raise self.error(str(exc), col) from None
        end = list(cps[-1])
        start = list(self.pos)
        # The motion belongs to the G5.2 block (as the curve's own ``line`` says), not to
        # the G5.3 that closes it: nodes, runs and planned samples all name that line.
        if np.all(cps == cps[0]):
            self._zero_length(self.nurbs_line)
            return
        self._curve(curve, pts, end, self.nurbs_line, self.nurbs_col, self._curve_feed(pts, start))

    # -- result -------------------------------------------------------------------
    def program(self, line_count: int) -> Program:
        if self.out_order is not None:
            order = self.out_order
        else:
            order = tuple(sorted(self.active))
        axes = "".join(ALL_AXES[i] for i in order)
        sel = list(order)
        items = []
        for kind, obj, extra in self.items:
            if kind == "mark":
                continue  # a stream's only
            if kind == "run":
                items.append(finish_run(obj, order, axes, extra))
            elif kind == "dwell":
                items.append(Dwell(line=obj.line, seconds=obj.seconds, position=np.array(extra, dtype=float)[sel]))
            else:
                items.append(Stop(line=obj.line, code=obj.code, position=np.array(extra, dtype=float)[sel]))
        meta = {
            "zero_length_moves": self.zero_length_moves,
            "warnings": list(self.warnings),
            "zero_length_lines": list(self.zero_length_lines),
            "final_position": [float(v) for v in np.array(self.pos)[sel]],
        }
        return Program(
            source=self.source,
            axes=axes,
            items=tuple(items),
            start=np.array(self.start9, dtype=float)[sel],
            line_count=line_count,
            block_count=self.block_count,
            metadata=meta,
        )


def _polar_col(d: dict) -> int:
    """Column of the block's first polar word (@ or ^)."""
    return min(d[k][2] for k in "@^" if k in d)


def _move_length(s, e, rotary: bool = False) -> float:
    """``program.move_lengths`` for one move of the 9 axes (scalar: the interpreter's hot
    path); ``rotary=True``: the rotary length if the move counts as rotary-only, else 0."""
    lin = 0.0
    rot = 0.0
    for k in range(9):
        dv = e[k] - s[k]
        if IS_LINEAR9[k]:
            lin += dv * dv
        else:
            rot += dv * dv
    linear = lin > LINEAR_MOTION_MIN_MM * LINEAR_MOTION_MIN_MM or rot == 0.0
    if rotary:
        return 0.0 if linear else math.sqrt(rot)
    return math.sqrt(lin) if linear else math.sqrt(rot)


def _word_text(blk, col: int) -> str:
    """The source text of the word starting at 1-based ``col`` of ``blk`` (or the block)."""
    text = getattr(blk, "text", "") or ""
    if col <= 0 or col > len(text):
        return text.strip()
    cols = sorted(c for _, _, c in blk.words if c > col)
    end = cols[0] - 1 if cols else len(text)
    return text[col - 1 : end].strip()

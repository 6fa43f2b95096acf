"""The G- and M-codes the interpreter knows, as named constants, with their modal groups.

A G-code is stored as ten times its number, an integer (``G2`` is 20, ``G20`` is 200,
``G43.1`` is 431), so that decimal codes compare exactly and a block's code is found
with one dict lookup; the names below are what the interpreter compares against.
Modal groups are RS274NGC's numbers (group 1 motion, 2 plane, 3 distance mode, 4 arc
distance mode, 5 feed mode, 6 units, 7 cutter radius compensation, 8 tool length,
10 canned-cycle return, 12 coordinate system, 13 path control, 14 spindle speed mode,
15 lathe diameter mode; 0 non-modal). M-codes are whole numbers and stored as such.
"""

from __future__ import annotations

# -- motion (group 1) ------------------------------------------------------------------
G0 = 0  # rapid
G1 = 10  # feed
G2 = 20  # clockwise arc
G3 = 30  # counter-clockwise arc
G5 = 50  # cubic spline
G5_1 = 51  # quadratic spline
G5_2 = 52  # NURBS block: a control point
G5_3 = 53  # NURBS block end
G73 = 730  # canned cycles (drilling, pecking, boring)
G80 = 800  # cycle cancel: no motion mode
G81 = 810
G82 = 820
G83 = 830
G85 = 850
G89 = 890
# -- plane (group 2) -------------------------------------------------------------------
G17 = 170  # XY
G18 = 180  # ZX
G19 = 190  # YZ
# -- distance modes (groups 3 and 4) -----------------------------------------------------
G90 = 900  # absolute
G91 = 910  # incremental
G90_1 = 901  # absolute arc centres
G91_1 = 911  # incremental arc centres
# -- feed mode (group 5) and units (group 6) ---------------------------------------------
G93 = 930  # inverse time
G94 = 940  # units per minute
G20 = 200  # inch
G21 = 210  # mm
# -- cutter radius (group 7) and tool length (group 8) -----------------------------------
G40 = 400  # radius compensation off (the only one supported)
G43 = 430  # tool length from the tool table
G43_1 = 431  # tool length from the axis words
G43_2 = 432  # an added tool length (H or axis words)
G49 = 490  # tool length off
# -- canned-cycle return (group 10) -------------------------------------------------------
G98 = 980  # to the initial level
G99 = 990  # to R
# -- coordinate systems (group 12) --------------------------------------------------------
G54 = 540
G55 = 550
G56 = 560
G57 = 570
G58 = 580
G59 = 590
G59_1 = 591
G59_2 = 592
G59_3 = 593
# -- path control (group 13) --------------------------------------------------------------
G61 = 610  # exact path
G61_1 = 611  # exact path and a stop at every block end
G64 = 640  # blending within a tolerance (P, Q)
# -- spindle speed mode (group 14) ---------------------------------------------------------
G96 = 960
G97 = 970
# -- lathe diameter mode (group 15) --------------------------------------------------------
G8 = 80  # radius mode, the default (G7 diameter mode is refused)
# -- non-modal (group 0) -------------------------------------------------------------------
G4 = 40  # dwell
G10 = 100  # tool table and coordinate system data
G28 = 280  # go to the stored position #5161..
G28_1 = 281  # store the position in #5161..
G30 = 300  # go to the stored position #5181..
G30_1 = 301  # store the position in #5181..
G53 = 530  # this block's motion in machine coordinates
G92 = 920  # axis offsets
G92_1 = 921  # clear the offsets and their parameters
G92_2 = 922  # clear the offsets, keep the parameters
G92_3 = 923  # restore the offsets from the parameters

#: G code -> modal group (0 = non-modal)
G_GROUP = {
    **dict.fromkeys((G0, G1, G2, G3, G5, G5_1, G5_2, G5_3, G73, G80, G81, G82, G83, G85, G89), 1),
    **dict.fromkeys((G17, G18, G19), 2),
    **dict.fromkeys((G90, G91), 3),
    **dict.fromkeys((G90_1, G91_1), 4),
    **dict.fromkeys((G93, G94), 5),
    **dict.fromkeys((G20, G21), 6),
    G40: 7,
    **dict.fromkeys((G43, G43_1, G43_2, G49), 8),
    **dict.fromkeys((G98, G99), 10),
    **dict.fromkeys((G54, G55, G56, G57, G58, G59, G59_1, G59_2, G59_3), 12),
    **dict.fromkeys((G61, G61_1, G64), 13),
    **dict.fromkeys((G96, G97), 14),
    G8: 15,
    **dict.fromkeys((G4, G10, G28, G28_1, G30, G30_1, G53, G92, G92_1, G92_2, G92_3), 0),
}
#: coordinate-system code -> its number (1 = G54 ... 9 = G59.3)
COORDINATE_SYSTEM = {G54: 1, G55: 2, G56: 3, G57: 4, G58: 5, G59: 6, G59_1: 7, G59_2: 8, G59_3: 9}
#: codes refused with their name (none of them is in ``G_GROUP``)
G_UNSUPPORTED = {
    70: "G7 lathe diameter mode",
    330: "G33 spindle-synchronized motion",
    331: "G33.1 rigid tapping",
    380: "G38 probing",
    382: "G38.2 probing",
    383: "G38.3 probing",
    384: "G38.4 probing",
    385: "G38.5 probing",
    410: "G41 cutter radius compensation",
    420: "G42 cutter radius compensation",
    411: "G41.1 dynamic cutter radius compensation",
    421: "G42.1 dynamic cutter radius compensation",
    520: "G52 local coordinate offset",
    700: "G70 lathe finishing cycle",
    710: "G71 lathe roughing cycle",
    711: "G71.1 lathe roughing cycle",
    720: "G72 lathe roughing cycle",
    721: "G72.1 lathe roughing cycle",
    740: "G74 left-hand tapping cycle (spindle synchronized)",
    760: "G76 threading cycle",
    840: "G84 tapping cycle (spindle synchronized)",
    860: "G86 boring cycle (spindle stop)",
    870: "G87 back boring cycle",
    880: "G88 boring cycle (manual retract)",
    950: "G95 feed per revolution",
    171: "G17.1 UV plane",
    181: "G18.1 WU plane",
    191: "G19.1 VW plane",
    650: "G65 macro call",
    680: "G68 coordinate rotation",
    690: "G69 coordinate rotation",
}

# -- M-codes ----------------------------------------------------------------------------
M0, M1, M2, M30, M60 = 0, 1, 2, 30, 60  # stops (group 4); M2 and M30 end the program
M6 = 6  # tool change
#: M codes that do not affect motion (spindle, coolant, overrides, digital/analog I/O)
M_NOOP = frozenset({3, 4, 5, 7, 8, 9, 19, 48, 49, 50, 51, 52, 53, 61, 62, 63, 64, 65, 67, 68})
M_STOPS = {M0: "M0", M1: "M1", M2: "M2", M30: "M30", M60: "M60"}
M_GROUP = {M0: 4, M1: 4, M2: 4, M30: 4, M60: 4, M6: 6, 61: 6, 3: 7, 4: 7, 5: 7, 19: 7}
#: the M-codes that use P (M62-M65 digital outputs) and Q, E (M67, M68 analog outputs)
M_USE_P = frozenset({62, 63, 64, 65})
M_USE_QE = frozenset({67, 68})
M_UNSUPPORTED = {
    66: "M66 wait on input",
    70: "M70 save modal state",
    71: "M71 invalidate modal state",
    72: "M72 restore modal state",
    73: "M73 save and autorestore modal state",
    98: "M98 subprogram call (use O-word sub/call)",
    99: "M99 subprogram return (use O-word endsub)",
}


def gcode_name(code10: int) -> str:
    """``"G2"``, ``"G43.1"``: the name of a G-code stored as ten times its number."""
    return f"G{code10 // 10}" if code10 % 10 == 0 else f"G{code10 // 10}.{code10 % 10}"

"""Constants shared across modules or stages (units in the names).

A constant that one module uses lives at the top of that module, with its unit and reason;
this file holds only what several modules must agree on.
"""

# --- units -------------------------------------------------------------------
MM_PER_INCH = 25.4
SECONDS_PER_MINUTE = 60.0
#: the length units a machine starts a program in (as if it began with G21 or G20), mm
#: per program unit: ``Machine.program_units`` names one, the G-code reader applies it
PROGRAM_UNITS_MM = {"mm": 1.0, "inch": MM_PER_INCH}

# --- axes --------------------------------------------------------------------
#: every axis letter RS274NGC knows, in canonical machine order
ALL_AXES = "XYZABCUVW"
LINEAR_AXES = frozenset("XYZUVW")
ROTARY_AXES = frozenset("ABC")
#: a move whose linear axes travel no more than this (mm) while rotary axes move counts
#: as rotary-only: its arc length is in degrees and an F or G93 feed applies to that. The
#: reader's feeds and the fitter's metric must agree on it, or an inverse-time move's time
#: is off by the ratio of the two lengths
LINEAR_MOTION_MIN_MM = 1e-6

# --- gcode -------------------------------------------------------------------
#: upper bound on iterations of one while/do/repeat loop
LOOP_ITERATION_LIMIT = 1_000_000
#: deepest O-word call / nesting the interpreter accepts before a clear error
MAX_CALL_DEPTH = 200
#: longest source line accepted (characters); longer is an error, not a hang
MAX_LINE_CHARS = 1_000_000
#: numbered parameters are #1..#PARAM_NUMBERED_MAX (LinuxCNC: RS274NGC_MAX_PARAMETERS - 1)
PARAM_NUMBERED_MAX = 5601
#: #1..#30 are local to an O-word call (its arguments); saved and restored around it
PARAM_LOCAL_COUNT = 30
#: a value used as an integer (parameter number, repeat count) may be this far from one
EXPR_INTEGER_TOL = 0.0001
#: most distance between sampled nodes and the exact arc/spline (sagitta), mm: a quarter
#: of a fine 1 µm tolerance, so a fit through the nodes stays close to the exact curve
CURVE_CHORD_TOL_MM = 0.00025
#: most nodes one arc or spline may be sampled into (a bigger one is an error, not a hang)
CURVE_MAX_NODES = 1_000_000
#: M-codes the interpreter gives a meaning (stops, tool change, spindle, coolant,
#: overrides, I/O, modal state, subprograms; ``gcode.codes`` names each): a machine file
#: may not declare them no-ops (``[gcode] noop_mcodes``); ``tests/test_mcodes.py`` keeps
#: this set equal to the codes' tables
MCODES_INTERPRETED = frozenset(
    {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 19, 30, 48, 49, 50, 51, 52, 53, 60, 61, 62, 63, 64, 65, 66, 67, 68}
    | {70, 71, 72, 73, 98, 99}
)
#: largest M-code number a machine file may declare a no-op (Fanuc and LinuxCNC codes
#: stay far below)
MCODE_MAX = 9999

# --- fit ---------------------------------------------------------------------
#: Gauss–Legendre order used on each arc-length sub-interval
ARC_LENGTH_GL_ORDER = 10
#: relative accuracy the adaptive arc-length integration aims for
ARC_LENGTH_REL_TOL = 1e-12
#: most sub-intervals per segment the arc-length integration may use
ARC_LENGTH_MAX_SUB = 1024
#: Newton iterations for u(s) inside one bracketing sub-interval
ARC_LENGTH_NEWTON_ITERS = 8
#: turns below this (deg) count as collinear (G61 merges such moves into one line)
FIT_COLLINEAR_DEG = 1e-6
#: tolerance used for exact curves (arcs, NURBS) under G61 where 0 is unreachable (mm)
FIT_EXACT_CURVE_TOL_MM = 1e-6
#: share of the tolerance the fit aims for (the rest absorbs rounding)
FIT_TOL_SAFETY = 0.98
#: N-axis fitter: share of the tolerance allowed at check points between the nodes (the
#: deviation between two check points may exceed theirs slightly)
FIT_BETWEEN_NODES_SAFETY = 0.95

# --- plan --------------------------------------------------------------------
#: default sample period (s) when neither the machine nor --dt gives one
DEFAULT_DT_S = 0.001
#: verify fails when any |v|,|a|,|j| ratio to its limit exceeds 1 + this
VERIFY_RATIO_SLACK = 1e-9
#: number of held (rest) copies of the first/last setpoint verify pads with:
#: enough that every backward difference up to jerk sees the machine at rest
VERIFY_REST_PADDING = 3

# --- export ------------------------------------------------------------------


# --- plan: paper 000 (constant / variable feedrate) ----------------------------

# --- fpga ----------------------------------------------------------------------
#: relative margin below every limit that ``stream`` plans with, on top of the position
#: rounding budget (cnc_interp/fpga/limits.py): room for the profile fit's error, so that
#: most planned segments reproduce within the limits instead of falling back to setpoints
FPGA_LIMIT_MARGIN = 1e-4
#: accuracy target of the round trip plan -> frames -> emulate (mm)
FPGA_ROUNDTRIP_TARGET_MM = 1e-4
#: default USB ids of the controller (pid.codes test range)
FPGA_USB_VID = 0x1209
FPGA_USB_PID = 0x0001

# --- plan: VPOp (paper 001) ----------------------------------------------------
#: VPOp plans against limits shrunk by this relative amount, so float rounding in
#: verify's finite differences can never push a ratio past 1 + VERIFY_RATIO_SLACK
VPOP_LIMIT_SHRINK = 1e-10
#: and by this many ulps of the largest position (absolute), for one-ulp differences
#: between the values the step loop checked and those verify sees (path joins)
VPOP_ROUNDING_ULPS = 16.0
#: a path shorter than this (mm or deg of arc length) is planned as a held position
VPOP_MIN_LENGTH = 1e-12

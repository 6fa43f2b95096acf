"""Named tolerances and numeric constants, in one place.

Units are in the names. Each stage has its own section; add new constants to
your stage's section rather than scattering literals through the code.
"""

import math

# --- units -------------------------------------------------------------------
MM_PER_INCH = 25.4
SECONDS_PER_MINUTE = 60.0

# --- axes --------------------------------------------------------------------
#: every axis letter RS274NGC knows, in canonical machine order
ALL_AXES = "XYZABCUVW"
LINEAR_AXES = frozenset("XYZUVW")
ROTARY_AXES = frozenset("ABC")

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
#: of DEFAULT_TOL_MM, so a fit through the nodes stays close to the exact curve
CURVE_CHORD_TOL_MM = 0.00025
#: most nodes one arc or spline may be sampled into (a bigger one is an error, not a hang)
CURVE_MAX_NODES = 1_000_000

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
#: default jerk (per axis, as a multiple of amax per second) when a LinuxCNC INI has none
DEFAULT_JERK_PER_ACCEL_1_S = 10.0
#: number of held (rest) copies of the first/last setpoint verify pads with:
#: enough that every backward difference up to jerk sees the machine at rest
VERIFY_REST_PADDING = 3

# --- export ------------------------------------------------------------------

# --- numbers -----------------------------------------------------------------
EPS = 1e-12
PI = math.pi

# --- plan: paper 000 (constant / variable feedrate) ----------------------------
#: share of each axis's amax the centripetal term q''·v² may use at cruise (Eq. 6's A_m);
#: the rest is left to the tangential acceleration of the feed transitions
P000_CURV_ACCEL_SHARE = 0.8
#: share of each axis's jmax the path-geometry jerk term q'''·v³ may use at cruise
P000_CURV_JERK_SHARE = 0.5
#: share of the jerk left after q'''·v³ that the cross term 3·q''·v·a_t may use
P000_CROSS_JERK_SHARE = 0.5
#: geometry samples per segment when taking the maxima of |q'|, |q''|, |q'''|
P000_GEOM_SAMPLES = 33
#: safety factor applied to those sampled maxima (grid may miss a peak slightly)
P000_GEOM_MARGIN = 1.0
#: golden-section iterations refining a numerical curvature peak
P000_CURV_REFINE_ITERS = 30
#: verify-and-replan rounds before a plan is declared failed
P000_MAX_REPLANS = 40
#: factor applied to a violating segment's feed cap (and its square to a_t, j_t) per round
P000_REPLAN_FEED_FACTOR = 0.9
#: bisection steps of the look-ahead passes (reach / cruise feed)
P000_BISECT_ITERS = 80
#: a segment/path shorter than this is treated as zero length (mm)
P000_MIN_LENGTH_MM = 1e-12

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
#: variable planner: consecutive segments whose feed caps lie within this relative band
#: share one profile piece (0 = one piece per segment, the paper's literal form)
P000_MERGE_BAND = 0.1

# --- plan: VPOp (paper 001) ----------------------------------------------------
#: VPOp plans against limits shrunk by this relative amount, so float rounding in
#: verify's finite differences can never push a ratio past 1 + VERIFY_RATIO_SLACK
VPOP_LIMIT_SHRINK = 1e-10
#: and by this many ulps of the largest position (absolute), for one-ulp differences
#: between the values the step loop checked and those verify sees (path joins)
VPOP_ROUNDING_ULPS = 16.0
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
#: share of each axis's jerk step the brake policy assumes it can use to end a stop
VPOP_BRAKE_JERK_FRACTION = 0.9
#: a brake run may end early once curvature uses at most this share of any axis's
#: acceleration and jerk over the rest of its stop (exact re-plan if that ever misleads)
VPOP_EASY_FRACTION = 0.25
#: an end-of-path "aim" run is committed when it stops within this many jerk steps
#: (jmax dt³ of the tightest axis) short of the end; the rest is crept from rest
VPOP_AIM_GAP_JERK_STEPS = 4.0
#: after a brake fix, how many of the following steps are tested in order for "max step,
#: then brake to rest" before the remaining ones (along the fix's own brake run) are
#: bisected and then probed below the answer (``vpop_core._chain_search``). Against testing
#: every step in order, measured on 10 programs: 1.1-3.2x less planning time,
#: cycle times -0.03..+1.4% (the worst on a helix at the acceleration limit)
VPOP_CHAIN_SEQUENTIAL = 2
#: a paper-000 plan longer than this many samples is refused (a degenerate path, e.g.
#: a cusp with unbounded curvature, would otherwise crawl for days and exhaust memory)
P000_MAX_SAMPLES = 20_000_000
#: most threads the timeline plans paths on (CNC_INTERP_THREADS overrides)
PLAN_MAX_THREADS = 4
#: a path shorter than this (mm or deg of arc length) is planned as a held position
VPOP_MIN_LENGTH = 1e-12

#: plan memory check: peak bytes per sample and per column (t, s, feed, line, verify, one per
#: axis: 5 + n_axes), measured: stellabee1 on generic-mill, 8.61 M samples, 2.06 GB peak
PLAN_PEAK_BYTES_PER_SAMPLE_COLUMN = 30.0
#: plan memory check: share of the lower-bound sample count that must fit (a safety factor
#: on the bound, so that the check never refuses a plan that would fit)
PLAN_BUDGET_MARGIN = 0.5

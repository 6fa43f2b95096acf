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
#: I/J/K arcs, LinuxCNC's documented rule: |r_start - r_end| is an error when it exceeds
#: ARC_RADIUS_TOL_MAX_* or (ARC_RADIUS_TOL_* and ARC_RADIUS_TOL_REL * radius). mm programs:
ARC_RADIUS_TOL_MM = 0.005
ARC_RADIUS_TOL_MAX_MM = 0.5
#: the same for inch programs (G20), in inches
ARC_RADIUS_TOL_INCH = 0.0005
ARC_RADIUS_TOL_MAX_INCH = 0.05
#: relative part of the rule (0.1 % of the radius)
ARC_RADIUS_TOL_REL = 0.001
#: upper bound on iterations of one while/do/repeat loop
LOOP_ITERATION_LIMIT = 1_000_000
#: upper bound on loop iterations of a whole program, all loops and nestings together (as
#: many as a ten-million-line program has blocks)
LOOP_TOTAL_ITERATION_LIMIT = 10_000_000
#: deepest O-word call / nesting the interpreter accepts before a clear error
MAX_CALL_DEPTH = 200
#: longest source line accepted (characters); longer is an error, not a hang
MAX_LINE_CHARS = 1_000_000
#: numbered parameters are #1..#PARAM_NUMBERED_MAX (LinuxCNC: RS274NGC_MAX_PARAMETERS - 1)
PARAM_NUMBERED_MAX = 5601
#: #1..#30 are local to an O-word call (its arguments); saved and restored around it
PARAM_LOCAL_COUNT = 30
#: EQ / NE compare within this tolerance (LinuxCNC TOLERANCE_EQUAL)
EXPR_EQUAL_TOL = 0.0001
#: a value used as an integer (parameter number, repeat count) may be this far from one
EXPR_INTEGER_TOL = 0.0001
#: fast path: source lines tokenised per numpy chunk (bounds memory on huge files)
FAST_CHUNK_LINES = 32768
#: an arc radius (start or end) below this is a "zero-radius arc" error (mm; LinuxCNC 0.00005 in)
ARC_MIN_RADIUS_MM = 0.00127
#: R-format arcs: how far the chord may exceed the diameter before "radius too small" (mm)
ARC_R_REACH_TOL_MM = 0.00127
#: most distance between sampled nodes and the exact arc/spline (sagitta), mm: a quarter
#: of DEFAULT_TOL_MM, so a fit through the nodes stays close to the exact curve
CURVE_CHORD_TOL_MM = 0.00025
#: every arc gets at least this many node segments (so curvature shows in the nodes)
ARC_MIN_SEGMENTS = 4
#: longest angle one sampled arc segment may span, deg
ARC_MAX_SEGMENT_DEG = 5.0
#: every NURBS/spline knot span gets at least this many node segments
SPLINE_MIN_SEGMENTS_PER_SPAN = 8
#: most bisection passes when sampling a spline to CURVE_CHORD_TOL_MM
#: (CURVE_MAX_NODES bounds the work)
SPLINE_REFINE_PASSES = 48
#: G73/G83 peck: rapid back down to this far above the previous depth (LinuxCNC: 0.010 in)
PECK_CLEARANCE_MM = 0.254
#: largest G2/G3 P (full turns) accepted; more is treated as a runaway expression
ARC_MAX_TURNS = 10_000
#: most nodes one arc or spline may be sampled into (a bigger one is an error, not a hang)
CURVE_MAX_NODES = 1_000_000

# --- fit ---------------------------------------------------------------------
#: default maximum permissible error of the fit (mm); `--tol` overrides
DEFAULT_TOL_MM = 0.001
#: default tolerance for rotary axes (deg)
DEFAULT_TOL_DEG = 0.001
#: a turn sharper than this (deg) between consecutive moves splits the path; the planner stops there
DEFAULT_CORNER_DEG = 30.0
#: Gauss–Legendre order used on each arc-length sub-interval
ARC_LENGTH_GL_ORDER = 10
#: relative accuracy the adaptive arc-length integration aims for
ARC_LENGTH_REL_TOL = 1e-12
#: most sub-intervals per segment the arc-length integration may use
ARC_LENGTH_MAX_SUB = 1024
#: Newton iterations for u(s) inside one bracketing sub-interval
ARC_LENGTH_NEWTON_ITERS = 8
#: nodes closer than this (mm, combined metric) are merged before fitting
FIT_DUPLICATE_NODE_MM = 1e-9
#: a move whose linear axes travel less than this (mm) counts as rotary-only (zero speed in s)
FIT_LINEAR_ZERO_MM = 1e-6
#: turns below this (deg) count as collinear (G61 merges such moves into one line)
FIT_COLLINEAR_DEG = 1e-6
#: tolerance used for exact curves (arcs, NURBS) under G61 where 0 is unreachable (mm)
FIT_EXACT_CURVE_TOL_MM = 1e-6
#: N-axis fitter: weight of the 3rd-divided-difference smoothing term (in tolerance units)
FIT_SMOOTHING = 1e-4
#: N-axis fitter: most knot-insertion rounds before the fit falls back to a knot per node
FIT_MAX_ROUNDS = 40
#: N-axis fitter: nodes per span of the initial knot vector
FIT_INITIAL_NODES_PER_SPAN = 512
#: N-axis fitter: least fitted speed |dq/du| relative to the chord's, at nodes and mid-chords
FIT_MIN_SPEED_RATIO = 0.25
#: N-axis fitter: a fitted speed below this share of the chord's is a stop and never accepted
FIT_STOP_SPEED_RATIO = 0.01
#: N-axis fitter: rounds without fewer chord-point failures before refinement stops
FIT_SOFT_STALE_ROUNDS = 3
#: N-axis fitter: smallest knot span relative to the run's parameter length
FIT_MIN_SPAN_REL = 1e-6
#: share of the tolerance the fit aims for (the rest absorbs rounding)
FIT_TOL_SAFETY = 0.98
#: path deviation: samples of the programmed path per typical fitted knot span
PATH_DEV_SAMPLES_PER_SPAN = 4
#: path deviation: fewest / most samples of one programmed move (or per node of a curve)
PATH_DEV_MIN_SAMPLES = 3
PATH_DEV_MAX_SAMPLES = 64
#: path deviation: coarse samples per fitted segment before Newton (a segment entered afresh)
PATH_DEV_FIT_SAMPLES = 8
#: path deviation: Newton steps of the projection onto the fitted path
PATH_DEV_NEWTON_ITERS = 8
#: path deviation: a marched distance above this share of the tolerance is searched
#: again among the segments nearby along the path (beyond the tolerance: farther)
PATH_DEV_LOCAL_FRAC = 0.5
#: path deviation: reach of that second search along the path, in sample spacings each side
PATH_DEV_WINDOW = 8
#: path deviation: reach of the search for a point beyond its tolerance, in sample spacings
PATH_DEV_FAR_WINDOW = 256
#: path deviation: relative slack over the tolerance (float rounding of the projection)
PATH_DEV_SLACK = 1e-6
#: N-axis fitter: check points per knot span between the nodes (on the programmed moves)
FIT_SPAN_CHECKS = 6
#: N-axis fitter: share of the tolerance allowed at check points between the nodes (the
#: deviation between two check points may exceed theirs slightly)
FIT_BETWEEN_NODES_SAFETY = 0.95
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
#: quantum of printed coordinates (fit/quantum.py): decimals tried (10^-D mm and 10^-D in)
FIT_QUANTUM_MAX_DECIMALS = 6
#: only a quantum up to this (mm) widens the tolerance by its half: 0.0001 in (2.54 µm) and
#: 0.001 mm count; coordinates printed to 0.01 mm or 0.001 in are taken as exact values
FIT_QUANTUM_MAX_MM = 0.003
#: the same for rotary axes (deg): 0.001° counts, 0.01° does not
FIT_QUANTUM_MAX_DEG = 0.003
#: a displacement is on a grid q when it is within this many q of a multiple of q (float
#: rounding of inch -> mm and offsets is ~1e-11 q; a random value passes with odds 2e-6)
FIT_QUANTUM_MATCH = 1e-6
#: fewer straight feed moves than this in a program: no quantum is inferred
FIT_QUANTUM_MIN_MOVES = 16
#: corner blends (fit/blends.py): a corner turning more than this (deg) is a near-reversal
#: and stops the path (the blend would be a near-cusp: parameter speed 0.64 at 175°)
FIT_BLEND_MAX_TURN_DEG = 175.0
#: share of the tolerance a blend may use (the rest absorbs the tabulated deviation's
#: interpolation and float rounding; the deviation is measured independently after)
FIT_BLEND_TOL_SHARE = 0.95
#: a corner whose blend, at its tolerance, would be more than this many times longer than
#: the room its moves leave (half the shorter move) stops instead: squeezed blends were
#: slower than stops (a dense-corner program at G64 P0.05: 103.0 s blended, 100.3 s with
#: stops; 101.5 s at 4, and the stellabee kink test keeps its 124.5 s)
FIT_BLEND_MAX_CROWDING = 4.0
#: shortest blend (mm, scaled metric): below it (moves of nanometres) the path stops instead
FIT_BLEND_MIN_MM = 1e-5
#: with rotary axes: least share of the linear axes in either move's direction (scaled metric)
#: for a blend; below it the tool's own path would nearly stop inside the blend
FIT_BLEND_MIN_LIN_SPEED = 0.05
#: a fit the measurement finds outside its tolerance is fitted again aiming at this share
#: of it before the sub-run is split (the fitter checks sampled points; the measurement is
#: denser, so a miss is usually by a few per cent)
FIT_REPAIR_TOL_SHARE = 0.7
#: repair rounds of a run whose fit the measurement finds outside its tolerance: each puts
#: blends (stops where a corner cannot be blended) at FIT_REPAIR_SPLITS nodes spread over
#: every failing section and refits; the last one at every node of the sections still failing
FIT_REPAIR_ROUNDS = 4
FIT_REPAIR_SPLITS = 8
#: curves: exact-geometry check points per quintic piece when converting arcs / NURBS
CURVE_CHECK_POINTS = 16
#: curves: deepest halving of a curve piece before giving up (2**depth pieces)
CURVE_MAX_DEPTH = 30

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
#: rows per chunk when writing CSV (bounds memory of the string conversion)
CSV_CHUNK_ROWS = 65_536
#: relative tolerance on t[k] = t[0] + k*dt when reading a plan back
CSV_TIME_REL_TOL = 1e-9

# --- export ------------------------------------------------------------------
#: a progress bar appears only once the work has run this long (s)
PROGRESS_DELAY_S = 1.0
#: least time between two redraws of the progress bar (s)
PROGRESS_REFRESH_S = 0.1
#: widest progress line drawn, characters
PROGRESS_MAX_WIDTH = 80
#: most tool-path points a plot draws (longer plans are decimated for the picture only)
PLOT_MAX_PATH_POINTS = 100_000
#: time bins of the min/max envelope a plot draws for long plans
PLOT_ENVELOPE_BINS = 2000
#: MCAP chunk size (uncompressed bytes); fixed so the same plan gives the same file
MCAP_CHUNK_BYTES = 4 * 1024 * 1024

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
#: fixed-point defaults (word bits, fraction bits); see cnc_interp/fpga/fixed.py and the width
#: sweep in benchmarks/fpga_widths.py (docs/fpga-protocol.md section 4 gives the reasoning)
FPGA_POS_FORMAT = (42, 28)  # positions, origins, increments: ±8192 mm, LSB 3.7e-9 mm
FPGA_TRIG_FORMAT = (35, 33)  # cos θ, sin θ: one 35×35 multiplier operand (4 MULT18X18D)
FPGA_PARAM_FORMAT = (35, 33)  # normalised abscissa ξ = x*/x_end and time τ, both in [0, 1]
FPGA_COEF_WORD = 32  # polynomial mantissas (block exponent per polynomial); 3 guard bits below
FPGA_HORNER_WORD = 35  # Horner accumulator: sum of six 32-bit mantissas fits, and it is a
#                        multiplier operand; overflow is an error naming the segment
FPGA_INT_WORD = 76  # rotation integrators: position word + trig fraction + 1 (never rounded)
FPGA_MULT_WORD = 35  # every multiplier operand (increments, x_end mantissa) fits this
#: relative margin below every limit that ``stream`` plans with, on top of the position
#: rounding budget (cnc_interp/fpga/limits.py): room for the profile fit's error, so that
#: most planned segments reproduce within the limits instead of falling back to setpoints
FPGA_LIMIT_MARGIN = 1e-4
#: the rounding budget (LSB/dt, 2 LSB/dt², 4 LSB/dt³ over the limits) counts this many times
FPGA_MARGIN_QUANTA = 2.0
#: a margin above this (a dt too short for the position LSB) is refused
FPGA_LIMIT_MARGIN_MAX = 1e-2
#: largest error the fitted parametric profile ξ(τ) may add along the path (mm)
FPGA_PROFILE_TOL_MM = 2e-5
#: a planar path is streamed as segments only if its samples lie on its planar form within this (mm)
FPGA_PLANAR_MATCH_MM = 1e-7
#: accuracy target of the round trip plan -> frames -> emulate (mm)
FPGA_ROUNDTRIP_TARGET_MM = 1e-4
#: largest frame payload (bytes); longer data is split over several frames
FPGA_MAX_PAYLOAD = 4096
#: motion the device buffers after START before its sample clock runs (s)
FPGA_PREFILL_S = 0.25
#: emulated device receive buffer (bytes)
FPGA_DEVICE_BUFFER = 16384
#: USB transfer timeout (ms) and retry budget per frame
FPGA_USB_TIMEOUT_MS = 1000
FPGA_USB_RETRIES = 8
#: polls of an unchanged full buffer before the link gives up (flow-control stall)
FPGA_USB_STALL_POLLS = 10_000
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

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
#: |distance from start to centre - distance from end to centre| allowed on an arc (mm)
ARC_RADIUS_TOL_MM = 0.0005
#: relative form of the same check (LinuxCNC uses 0.001 relative)
ARC_RADIUS_TOL_REL = 0.001
#: upper bound on iterations of one while/do/repeat loop
LOOP_ITERATION_LIMIT = 1_000_000
#: deepest O-word call / nesting the interpreter accepts before a clear error
MAX_CALL_DEPTH = 200
#: longest source line accepted (characters); longer is an error, not a hang
MAX_LINE_CHARS = 1_000_000

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

# --- plan --------------------------------------------------------------------
#: default sample period (s) when neither the machine nor --dt gives one
DEFAULT_DT_S = 0.001
#: verify fails when any |v|,|a|,|j| ratio to its limit exceeds 1 + this
VERIFY_RATIO_SLACK = 1e-9
#: default jerk (per axis, as a multiple of amax per second) when a LinuxCNC INI has none
DEFAULT_JERK_PER_ACCEL_1_S = 10.0

# --- numbers -----------------------------------------------------------------
EPS = 1e-12
PI = math.pi

"""The compiled kernels' status codes: one set for the whole planning stage.

Each kernel returns an integer status (numba compiles module-level ints as constants;
an ``IntEnum`` member would be a type of its own inside a kernel). ``Status`` names the
same values for Python: ``Status(code).name`` says what a code means. A code means the
same thing wherever it is returned; which codes a kernel may return is in its
docstring. The values are internal (never written to an output) and each is distinct,
so a code passed up from one kernel to another cannot be misread.
"""

from __future__ import annotations

from enum import IntEnum, unique


@unique
class Status(IntEnum):
    """What a planning kernel reports (see the module docstring)."""

    #: done: the path (or the table, the window, the batch entry) is complete and valid
    OK = 0
    #: the caller's buffers are full: grow them (or hand samples out) and call again
    NEED_SPACE = 1
    #: the step loop made no progress (it would repeat a state), or the exact sampler
    #: found no allowed position (its caller lands the plan or hands it to VPOp)
    STUCK = 2
    #: no feasible step is left to back up to (or a refinement window has none)
    INFEASIBLE = 3
    #: the step loop stopped at the index it was asked to stop at (a checkpoint is due)
    YIELD = 4
    #: the reference time law ends before the next target: give more and call again
    NEED_REF = 5
    #: samples are final up to the last checkpoint: hand them out and call again
    HAND_OUT = 6
    #: the step loop failed in exact mode (the step loop's own status says why)
    FAILED = 7
    #: no piece of the path has a positive arc length
    NO_LENGTH = 8
    #: the arc-length table is not finite (a point of zero speed)
    NOT_FINITE = 9
    #: the fitted path itself is not finite
    NOT_FINITE_PATH = 10
    #: the jerk limits are below what float64 resolves at the path's positions
    JERK_TOO_SMALL = 11
    #: the path is shorter than VPOP_MIN_LENGTH: one sample, no table
    TRIVIAL = 12
    #: the LP solver reached its iteration limit before its tolerance
    MAX_ITER = 13
    #: the LP solver's factorisation broke down (or its rows have the wrong width)
    BREAKDOWN = 14


# the same values as plain ints, for the kernels
OK = Status.OK.value
NEED_SPACE = Status.NEED_SPACE.value
STUCK = Status.STUCK.value
INFEASIBLE = Status.INFEASIBLE.value
YIELD = Status.YIELD.value
NEED_REF = Status.NEED_REF.value
HAND_OUT = Status.HAND_OUT.value
FAILED = Status.FAILED.value
NO_LENGTH = Status.NO_LENGTH.value
NOT_FINITE = Status.NOT_FINITE.value
NOT_FINITE_PATH = Status.NOT_FINITE_PATH.value
JERK_TOO_SMALL = Status.JERK_TOO_SMALL.value
TRIVIAL = Status.TRIVIAL.value
MAX_ITER = Status.MAX_ITER.value
BREAKDOWN = Status.BREAKDOWN.value

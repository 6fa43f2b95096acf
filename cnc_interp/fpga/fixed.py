"""Fixed-point formats and the integer primitives the FPGA datapath is built from.

A value v in format Q(word, frac) is the signed integer ``round(v * 2**frac)``
held in ``word`` bits (two's complement). Rounding is "round half up"
(``floor(x + 1/2)``), the cheap hardware rounding: add half an LSB, then shift
arithmetically right. Products are formed at full width and rounded once.

Polynomial coefficients use a *block exponent* per polynomial: the mantissas
m_i (``coef_word`` bits) share one fraction length ``e`` chosen so that the
largest |m_i| fills the word (``choose_exponent``). The polynomial variable is
always normalised to [0, 1] (time τ within a profile piece, abscissa
ξ = x*/x_end within a segment), so the Horner accumulator never grows past
sum |c_i| and the word is used well whatever the segment's length or duration.

Integer arrays are numpy ``object`` arrays of Python ints where a product needs
more than 64 bits; everything here is exact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import PlanError, SourceLocation


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

#: block exponents are sent as int8; the datapath's barrel shifter rounds right by up to
#: SHIFT_RIGHT_MAX bits or shifts left by up to SHIFT_LEFT_MAX (exponent minus the output
#: fraction), so every exponent is clamped to keep the shift in that range
EXP_MIN = -16
EXP_MAX = 120
SHIFT_RIGHT_MAX = 63
SHIFT_LEFT_MAX = 31


class FixedPointOverflow(PlanError):
    """A quantity does not fit its fixed-point word (names the segment and source line)."""


@dataclass(frozen=True)
class FixedFormat:
    """Signed two's complement Q format: ``word`` bits in total, ``frac`` of them fractional."""

    word: int
    frac: int

    def __post_init__(self) -> None:
        if not (2 <= self.word <= 128) or not (0 <= self.frac < 128):
            raise ValueError(f"bad fixed-point format Q({self.word},{self.frac})")

    @property
    def lsb(self) -> float:
        """Value of one least significant bit."""
        return math.ldexp(1.0, -self.frac)

    @property
    def max_int(self) -> int:
        return (1 << (self.word - 1)) - 1

    @property
    def min_int(self) -> int:
        return -(1 << (self.word - 1))

    def quantize(self, x, what: str, where: "Where | None" = None):
        """Round float(s) to this format; an int for a scalar, an object array otherwise.

        Raises ``FixedPointOverflow`` naming ``what`` and ``where`` when a value
        does not fit the word.
        """
        arr = np.asarray(x, dtype=float)
        if not np.all(np.isfinite(arr)):
            raise FixedPointOverflow(f"{what} is not finite{_where(where)}", _loc(where))
        ints = to_ints(np.floor(np.ldexp(arr, self.frac) + 0.5))
        self.check(ints, what, where)
        return ints

    def check(self, ints, what: str, where: "Where | None" = None) -> None:
        """Raise ``FixedPointOverflow`` if any integer does not fit ``word`` bits."""
        flat = np.asarray(ints, dtype=object).reshape(-1)
        if flat.size == 0:
            return
        hi, lo = max(flat), min(flat)
        if hi > self.max_int or lo < self.min_int:
            worst = hi if hi > self.max_int else lo
            raise FixedPointOverflow(
                f"{what} = {math.ldexp(float(worst), -self.frac):.6g} overflows "
                f"Q{self.word - self.frac}.{self.frac} ({self.word} bits){_where(where)}",
                _loc(where),
            )

    def to_float(self, ints) -> np.ndarray:
        """Integers of this format back to floats (exact up to float64 rounding)."""
        return np.ldexp(np.asarray(ints, dtype=object).astype(float), -self.frac)


@dataclass(frozen=True)
class Where:
    """What an overflow message names: segment index, source line and file."""

    segment: int = -1
    line: int = 0
    file: str = "<input>"


def _where(where: Where | None) -> str:
    if where is None:
        return ""
    parts = []
    if where.segment >= 0:
        parts.append(f"segment {where.segment}")
    if where.line > 0:
        parts.append(f"source line {where.line}")
    return (" in " + ", ".join(parts)) if parts else ""


def _loc(where: Where | None) -> SourceLocation:
    if where is None:
        return SourceLocation()
    return SourceLocation(file=where.file, line=where.line, col=1 if where.line > 0 else 0)


@dataclass(frozen=True)
class FpgaFormats:
    """Every fixed-point format of the datapath (defaults from ``constants``).

    pos: positions, origins and per-sample increments (mm or deg).
    trig: cos θ and sin θ of each segment's rotation.
    param: the normalised variables τ (time in a profile piece) and ξ = x*/x_end.
    coef_word: bits of each polynomial mantissa (block exponent per polynomial; x_end too).
    horner_word: bits of the Horner accumulators (one multiplier operand each step).
    int_word: bits of the two rotation integrators (full-width products, never rounded).
    mult_word: bits of every multiplier operand; increments Δx*, Δz* must fit it.
    """

    pos: FixedFormat = FixedFormat(*FPGA_POS_FORMAT)
    trig: FixedFormat = FixedFormat(*FPGA_TRIG_FORMAT)
    param: FixedFormat = FixedFormat(*FPGA_PARAM_FORMAT)
    coef_word: int = FPGA_COEF_WORD
    horner_word: int = FPGA_HORNER_WORD
    int_word: int = FPGA_INT_WORD
    mult_word: int = FPGA_MULT_WORD

    def __post_init__(self) -> None:
        if not (
            2 <= self.coef_word <= 64
            and 2 <= self.horner_word <= 128
            and 2 <= self.int_word <= 200
            and 2 <= self.mult_word <= 128
        ):
            raise ValueError(f"bad fixed-point widths {self.as_tuple()}")
        if max(self.trig.word, self.param.word, self.horner_word) > self.mult_word:
            raise ValueError("trig, param and Horner words must fit the multiplier operand")

    @property
    def horner(self) -> FixedFormat:
        """Horner accumulator range check (fraction irrelevant for overflow)."""
        return FixedFormat(self.horner_word, 0)

    @property
    def integ(self) -> FixedFormat:
        """Rotation integrator range check."""
        return FixedFormat(self.int_word, 0)

    @property
    def operand(self) -> FixedFormat:
        """Multiplier operand range check (increments)."""
        return FixedFormat(self.mult_word, 0)

    def as_tuple(self) -> tuple[int, ...]:
        return (
            self.pos.word,
            self.pos.frac,
            self.trig.word,
            self.trig.frac,
            self.param.word,
            self.param.frac,
            self.coef_word,
            self.horner_word,
            self.int_word,
            self.mult_word,
        )

    @classmethod
    def from_tuple(cls, t) -> "FpgaFormats":
        return cls(
            FixedFormat(t[0], t[1]),
            FixedFormat(t[2], t[3]),
            FixedFormat(t[4], t[5]),
            int(t[6]),
            int(t[7]),
            int(t[8]),
            int(t[9]),
        )


# -- integer primitives -------------------------------------------------------------
def to_ints(a) -> np.ndarray | int:
    """Float array of integral values -> object array of Python ints (scalar -> int)."""
    arr = np.asarray(a)
    if arr.ndim == 0:
        return int(arr)
    if arr.dtype.kind in "iu" or (arr.size and np.abs(arr).max() < 2.0**62):
        return arr.astype(np.int64).astype(object)  # exact: integral values below 2**62
    out = np.empty(arr.shape, dtype=object)
    out.reshape(-1)[:] = [int(v) for v in arr.reshape(-1)]
    return out


def obj(a) -> np.ndarray:
    """Any integer array-like as an object array of Python ints."""
    arr = np.asarray(a)
    if arr.dtype == object:
        return arr
    return to_ints(arr) if arr.ndim else np.array(int(arr), dtype=object)


def round_shift(x, shift: int):
    """Round-half-up arithmetic right shift by ``shift`` >= 0 (left shift if negative)."""
    if shift > 0:
        return (x + (1 << (shift - 1))) >> shift
    if shift < 0:
        return x << (-shift)
    return x


def choose_exponent(coefs: np.ndarray, word: int, lo: int = EXP_MIN, hi: int = EXP_MAX) -> int:
    """Block exponent (fraction bits) so that max |coef| * 2**e fills ``word`` signed bits,
    clamped to [lo, hi] (the shifter's range)."""
    m = float(np.max(np.abs(coefs))) if np.size(coefs) else 0.0
    if m == 0.0 or not math.isfinite(m):
        return max(lo, min(hi, 0))
    _, e2 = math.frexp(m)  # m = f * 2**e2, 0.5 <= f < 1
    e = word - 1 - e2
    # rounding may push the largest mantissa to 2**(word-1): use one bit less then
    if math.floor(math.ldexp(m, e) + 0.5) > (1 << (word - 1)) - 1:
        e -= 1
    return max(lo, min(hi, e))


def exponent_range(out_frac: int) -> tuple[int, int]:
    """Exponents whose final shift (exponent - out_frac) the datapath's shifter can do."""
    return (max(EXP_MIN, out_frac - SHIFT_LEFT_MAX), min(EXP_MAX, out_frac + SHIFT_RIGHT_MAX))


def quantize_block(
    coefs, word: int, what: str, where: Where | None = None, out_frac: int | None = None
) -> tuple[int, list[int]]:
    """(exponent, mantissas) of a coefficient vector with one shared exponent.

    ``out_frac``: fraction bits of the value the polynomial is rounded to; the exponent is
    kept within the shifter's reach of it (``exponent_range``).
    """
    c = np.asarray(coefs, dtype=float)
    lo, hi = exponent_range(out_frac) if out_frac is not None else (EXP_MIN, EXP_MAX)
    e = choose_exponent(c, word, lo, hi)
    mant = FixedFormat(word, 0).quantize(np.ldexp(c, e), what, where)
    return e, [int(v) for v in np.asarray(mant, dtype=object).reshape(-1)]


def horner(
    mant,
    exp: int,
    var,
    var_frac: int,
    out_frac: int,
    acc: FixedFormat,
    what: str = "Horner accumulator",
    where: Where | None = None,
):
    """Evaluate sum_i mant[i] 2**-exp var**i exactly as the hardware does.

    ``var`` (ints, fraction ``var_frac``, in [0, 1]); each step is
    ``acc = round_shift(acc * var, var_frac) + mant[i]``; the result is rounded
    to ``out_frac`` fraction bits. Every intermediate accumulator is checked
    against ``acc`` (raises ``FixedPointOverflow``).
    """
    var = obj(var)
    a = np.full(var.shape, int(mant[-1]), dtype=object) if var.ndim else int(mant[-1])
    for m in reversed(mant[:-1]):
        a = round_shift(a * var, var_frac) + int(m)
        acc.check(a, what, where)
    return round_shift(a, exp - out_frac)

"""Fixed-point formats and integer primitives of the FPGA stage."""

from fractions import Fraction

import numpy as np
import pytest

from cnc_interp.fpga.fixed import (
    FixedFormat,
    FixedPointOverflow,
    Where,
    choose_exponent,
    horner,
    quantize_block,
    round_shift,
)


def test_quantize_rounds_half_up_and_checks_range():
    f = FixedFormat(8, 4)
    assert f.quantize(1.03125, "x") == 17  # 16.5 -> 17
    assert f.quantize(-1.03125, "x") == -16  # -16.5 -> -16 (half up)
    assert f.quantize(7.9375, "x") == 127
    with pytest.raises(FixedPointOverflow) as ei:
        f.quantize(8.0, "segment origin", Where(segment=3, line=42, file="part.nc"))
    msg = ei.value.format()
    assert msg.startswith("part.nc:42:1: error:")
    assert "segment 3" in msg and "source line 42" in msg and "segment origin" in msg


def test_quantize_rejects_nan():
    with pytest.raises(FixedPointOverflow, match="not finite"):
        FixedFormat(16, 8).quantize(np.array([1.0, np.nan]), "x")


def test_round_shift_matches_exact_rounding():
    rng = np.random.default_rng(1)
    for v in rng.integers(-(1 << 60), 1 << 60, 200):
        v = int(v)
        for sh in (1, 5, 31):
            exact = Fraction(v, 1 << sh) + Fraction(1, 2)
            assert round_shift(v, sh) == exact.numerator // exact.denominator
    assert round_shift(3, -2) == 12 and round_shift(3, 0) == 3


@pytest.mark.parametrize("m", [1e-9, 0.3, 1.0, 1.5, 123.456, 2.0**20])
def test_block_exponent_fills_the_word(m):
    word = 48
    e = choose_exponent(np.array([m, -m / 3]), word)
    mant = round(m * 2.0**e)
    assert (1 << (word - 2)) <= mant <= (1 << (word - 1)) - 1


def test_quantize_block_error_is_half_lsb():
    c = np.array([0.0, 1.234, -5.5, 0.001, 7.25, -3.0])
    e, mant = quantize_block(c, 48, "p")
    back = np.array(mant, dtype=float) * 2.0**-e
    assert np.max(np.abs(back - c)) <= 2.0 ** -(e + 1) * 1.0000001


def test_horner_equals_exact_rational_within_rounding():
    rng = np.random.default_rng(7)
    acc = FixedFormat(96, 0)
    for _ in range(50):
        c = rng.uniform(-3, 3, 6)
        e, mant = quantize_block(c, 48, "p")
        x = int(rng.integers(0, 1 << 44))
        got = horner(mant, e, x, 44, 32, acc)
        exact = sum(Fraction(m, 1 << e) * Fraction(x, 1 << 44) ** i for i, m in enumerate(mant))
        # 5 rounded steps at 2^-e each, then one rounding to 2^-32
        assert abs(Fraction(got, 1 << 32) - exact) <= Fraction(1, 1 << 33) + Fraction(6, 1 << e)


def test_horner_accumulator_overflow_names_segment():
    with pytest.raises(FixedPointOverflow, match="segment 7"):
        horner([1 << 40] * 6, 0, 1 << 20, 20, 0, FixedFormat(42, 0), where=Where(7, 12))

"""The compiled float formatter writes exactly Python's ``repr`` (the CSV's numbers)."""

import math
import struct

import numpy as np
import pytest

from cnc_interp.export._repr import format_table, repr_many


def _check(values):
    values = np.asarray(values, dtype=np.float64)
    got = repr_many(values)
    want = [repr(v) for v in values.tolist()]
    bad = [(w, g) for w, g in zip(want, got) if w != g]
    assert not bad, bad[:10]
    assert len(got) == len(want)


def test_special_values():
    _check(
        [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.1,
            0.2,
            0.3,
            1 / 3,
            2 / 3,
            math.pi,
            -math.e,
            float("inf"),
            float("-inf"),
            float("nan"),
            5e-324,
            -5e-324,
            2.2250738585072014e-308,
            2.225073858507201e-308,
            1.7976931348623157e308,
            9007199254740991.0,
            9007199254740992.0,
            9007199254740993.0,
            123456789012345678.0,
            4.35,
            0.001,
            0.016,
            786.1510000000001,
            1e22,
            1e23,
            5e-310,
        ]
    )


def test_the_format_switch_points():
    """Positional for decimal exponents in [-4, 16), else d.ddde±XX; neighbours too."""
    vals = []
    for e in range(-30, 30):
        for m in (1.0, 1.5, 9.999999999999998, 2.5):
            x = m * 10.0**e
            vals += [x, -x, np.nextafter(x, 0), np.nextafter(x, np.inf)]
    vals += [1e16, 1e15, 9999999999999998.0, 1e-5, 1e-4, 0.0001, 0.00011, 9.9999e-05, 1e100, 1e-100, 1e300, 1e-300]
    _check(vals)


def test_integer_valued_floats():
    rng = np.random.default_rng(3)
    _check(
        np.concatenate(
            [
                np.arange(-1000, 1000),
                rng.integers(-(2**62), 2**62, 20000),
                2.0 ** np.arange(0, 1024),
                -(2.0 ** -np.arange(0, 1075)),
            ]
        ).astype(float)
    )


def test_random_bit_patterns():
    """Every exponent, sign and mantissa: random 64-bit patterns (NaNs included)."""
    rng = np.random.default_rng(1)
    bits = rng.integers(0, 2**63, size=300_000, dtype=np.int64).astype(np.uint64)
    bits |= rng.integers(0, 2, size=bits.size).astype(np.uint64) << np.uint64(63)
    _check(bits.view(np.float64))


def test_subnormals_and_tiny():
    rng = np.random.default_rng(2)
    sub = rng.integers(1, 2**52, size=50_000, dtype=np.int64).astype(np.uint64).view(np.float64)
    _check(np.concatenate([sub, -sub, rng.uniform(1e-320, 1e-300, 10_000)]))


def test_values_a_plan_holds():
    rng = np.random.default_rng(4)
    _check(
        np.concatenate(
            [
                np.arange(200_000) * 0.001,
                np.arange(50_000) * 0.006,
                rng.normal(scale=300, size=100_000),
                rng.uniform(-1e-6, 1e-6, 50_000),
                np.round(rng.normal(scale=50, size=50_000), 4) * 25.4,
            ]
        )
    )


def test_table_rows_and_repeats():
    """Columns joined by ',' and rows by '\\n'; a value repeated from the row before (an
    axis at rest) is copied, the same text."""
    cols = np.array([[0.0, 0.001, 0.002], [1.5, 1.5, -0.0], [-0.0, -0.0, 3e-7]])
    assert format_table(cols) == b"0.0,1.5,-0.0\n0.001,1.5,-0.0\n0.002,-0.0,3e-07\n"
    assert format_table(np.zeros((3, 0))) == b""


@pytest.mark.parametrize("x", [1.0, 0.1, 1e-7, 123.456])
def test_bit_exact_round_trip(x):
    text = repr_many(np.array([x]))[0]
    assert struct.pack("<d", float(text)) == struct.pack("<d", x)

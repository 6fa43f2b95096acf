"""Python's ``repr(float)`` text, compiled: the CSV writer's number formatter.

``repr`` of a float64 is the shortest decimal string that reads back as the same
float64 (David Gay's shortest mode; the closest such string, ties to even), printed
positionally when the decimal exponent is in [-4, 16) and as ``d.ddde±XX`` otherwise,
with ``.0`` added to integral positional values. The digits come from Ulf Adams' Ryu
algorithm (PLDI 2018; the shortest, closest digit string, ties to even, as in
``d2s.c``), ported to numba with 64-bit arithmetic only (the 128-bit products of the
reference are split into 32-bit halves); the tables are computed here exactly with
Python integers. ``tests/test_repr.py`` checks the text against ``repr`` on random
doubles, subnormals, signed zeros, integers, powers of ten and the values at the
format's switch points.

``format_table(cols)`` writes rows of comma-separated columns (``cols`` (ncol, K)) as
CSV bytes; it releases the GIL.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_MANT_BITS = 52
_BIAS = 1023
_POW5_INV_BITCOUNT = 125
_POW5_BITCOUNT = 125
_INV_TABLE_SIZE = 342
_TABLE_SIZE = 326


def _tables():
    inv = np.zeros((_INV_TABLE_SIZE, 2), dtype=np.uint64)
    pos = np.zeros((_TABLE_SIZE, 2), dtype=np.uint64)
    mask = (1 << 64) - 1
    for i in range(_INV_TABLE_SIZE):
        p = 5**i
        j = p.bit_length() - 1 + _POW5_INV_BITCOUNT
        v = (1 << j) // p + 1
        inv[i, 0], inv[i, 1] = v & mask, v >> 64
    for i in range(_TABLE_SIZE):
        p = 5**i
        j = p.bit_length() - _POW5_BITCOUNT
        v = p >> j if j >= 0 else p << -j
        pos[i, 0], pos[i, 1] = v & mask, v >> 64
    return inv, pos


_POW5_INV_SPLIT, _POW5_SPLIT = _tables()

_U0 = np.uint64(0)
_U1 = np.uint64(1)
_U2 = np.uint64(2)
_U4 = np.uint64(4)
_U5 = np.uint64(5)
_U10 = np.uint64(10)
_U32 = np.uint64(32)
_U64 = np.uint64(64)
_MASK32 = np.uint64(0xFFFFFFFF)
_MANT_MASK = np.uint64((1 << _MANT_BITS) - 1)

#: numba options of the per-number kernels (``_d2d``, ``_put_repr``): no reference
#: counting (``_nrt=False``), which cost two atomic operations per array argument on every
#: number written; they allocate nothing and return no array (as ``plan.vpop.step``'s)
_NO_REFCOUNT = {"cache": True, "_nrt": False}


@njit(cache=True, inline="always")
def _umul128_hi_lo(a, b):
    """(high, low) 64-bit halves of the 128-bit product a * b (uint64)."""
    a_lo = a & _MASK32
    a_hi = a >> _U32
    b_lo = b & _MASK32
    b_hi = b >> _U32
    b00 = a_lo * b_lo
    b01 = a_lo * b_hi
    b10 = a_hi * b_lo
    b11 = a_hi * b_hi
    mid1 = b10 + (b00 >> _U32)
    mid2 = b01 + (mid1 & _MASK32)
    hi = b11 + (mid1 >> _U32) + (mid2 >> _U32)
    lo = (mid2 << _U32) | (b00 & _MASK32)
    return hi, lo


@njit(cache=True, inline="always")
def _mul_shift64(m, mul0, mul1, j):
    """((m * (mul1 << 64 | mul0)) >> j) for 64 < j < 128 (Ryu's mulShift64)."""
    high1, low1 = _umul128_hi_lo(m, mul1)
    high0, _ = _umul128_hi_lo(m, mul0)
    s = high0 + low1
    if s < high0:
        high1 += _U1
    dist = np.uint64(j - 64)
    return (high1 << (_U64 - dist)) | (s >> dist)


@njit(cache=True, inline="always")
def _pow5bits(e):
    return ((e * 1217359) >> 19) + 1


@njit(cache=True, inline="always")
def _log10_pow2(e):
    return (e * 78913) >> 18


@njit(cache=True, inline="always")
def _log10_pow5(e):
    return (e * 732923) >> 20


@njit(cache=True, inline="always")
def _pow5_factor(v):
    count = 0
    while True:
        q = v // _U5
        if v - _U5 * q != _U0:
            return count
        v = q
        count += 1


@njit(**_NO_REFCOUNT)
def _d2d(mant, expo, inv, pos):
    """Ryu's d2d: (digits, decimal exponent) of the shortest closest representation of
    the positive finite double with biased exponent ``expo`` and mantissa bits ``mant``."""
    if expo == 0:
        e2 = 1 - _BIAS - _MANT_BITS - 2
        m2 = mant
    else:
        e2 = expo - _BIAS - _MANT_BITS - 2
        m2 = (_U1 << np.uint64(_MANT_BITS)) | mant
    even = (m2 & _U1) == _U0
    accept = even
    mv = _U4 * m2
    mm_shift = np.uint64(1) if (mant != _U0 or expo <= 1) else np.uint64(0)
    vm_tz = False
    vr_tz = False
    if e2 >= 0:
        q = _log10_pow2(e2) - (1 if e2 > 3 else 0)
        e10 = q
        k = _POW5_INV_BITCOUNT + _pow5bits(q) - 1
        i = -e2 + q + k
        vr = _mul_shift64(_U4 * m2, inv[q, 0], inv[q, 1], i)
        vp = _mul_shift64(_U4 * m2 + _U2, inv[q, 0], inv[q, 1], i)
        vm = _mul_shift64(_U4 * m2 - _U1 - mm_shift, inv[q, 0], inv[q, 1], i)
        if q <= 21:
            if mv % _U5 == _U0:
                vr_tz = _pow5_factor(mv) >= q
            elif accept:
                vm_tz = _pow5_factor(mv - _U1 - mm_shift) >= q
            else:
                if _pow5_factor(mv + _U2) >= q:
                    vp -= _U1
    else:
        q = _log10_pow5(-e2) - (1 if -e2 > 1 else 0)
        e10 = q + e2
        i = -e2 - q
        k = _pow5bits(i) - _POW5_BITCOUNT
        j = q - k
        vr = _mul_shift64(_U4 * m2, pos[i, 0], pos[i, 1], j)
        vp = _mul_shift64(_U4 * m2 + _U2, pos[i, 0], pos[i, 1], j)
        vm = _mul_shift64(_U4 * m2 - _U1 - mm_shift, pos[i, 0], pos[i, 1], j)
        if q <= 1:
            vr_tz = True
            if accept:
                vm_tz = mm_shift == _U1
            else:
                vp -= _U1
        elif q < 63:
            vr_tz = (mv & ((_U1 << np.uint64(q)) - _U1)) == _U0
    removed = 0
    last = _U0
    if vm_tz or vr_tz:
        while vp // _U10 > vm // _U10:
            vm_tz = vm_tz and (vm % _U10 == _U0)
            vr_tz = vr_tz and last == _U0
            last = vr % _U10
            vr //= _U10
            vp //= _U10
            vm //= _U10
            removed += 1
        if vm_tz:
            while vm % _U10 == _U0:
                vr_tz = vr_tz and last == _U0
                last = vr % _U10
                vr //= _U10
                vp //= _U10
                vm //= _U10
                removed += 1
        if vr_tz and last == _U5 and vr % _U2 == _U0:
            last = np.uint64(4)  # round to even
        up = (vr == vm and (not accept or not vm_tz)) or last >= _U5
        out = vr + (_U1 if up else _U0)
    else:
        round_up = False
        if vp // np.uint64(100) > vm // np.uint64(100):
            round_up = vr % np.uint64(100) >= np.uint64(50)
            vr //= np.uint64(100)
            vp //= np.uint64(100)
            vm //= np.uint64(100)
            removed += 2
        while vp // _U10 > vm // _U10:
            round_up = vr % _U10 >= _U5
            vr //= _U10
            vp //= _U10
            vm //= _U10
            removed += 1
        out = vr + (_U1 if (vr == vm or round_up) else _U0)
    return out, e10 + removed


@njit(**_NO_REFCOUNT)
def _put_repr(u, buf, p, digits, inv, pos):
    """Write repr(x) at buf[p:] for the float64 x of bits ``u`` (uint64); returns the new
    end. ``digits`` is scratch (>= 17)."""
    neg = (u >> np.uint64(63)) != _U0
    expo = np.int64((u >> np.uint64(_MANT_BITS)) & np.uint64(0x7FF))
    mant = u & _MANT_MASK
    if expo == 0x7FF:
        if mant != _U0:
            buf[p] = 110  # nan
            buf[p + 1] = 97
            buf[p + 2] = 110
            return p + 3
        if neg:
            buf[p] = 45
            p += 1
        buf[p] = 105  # inf
        buf[p + 1] = 110
        buf[p + 2] = 102
        return p + 3
    if neg:
        buf[p] = 45
        p += 1
    if expo == 0 and mant == _U0:
        buf[p] = 48
        buf[p + 1] = 46
        buf[p + 2] = 48
        return p + 3
    out, e10 = _d2d(mant, expo, inv, pos)
    nd = 0
    while out >= np.uint64(100):  # two digits per (constant) division
        r = np.int64(out % np.uint64(100))
        out //= np.uint64(100)
        digits[nd] = r % 10
        digits[nd + 1] = r // 10
        nd += 2
    r = np.int64(out)
    if r >= 10:
        digits[nd] = r % 10
        digits[nd + 1] = r // 10
        nd += 2
    elif r > 0:
        digits[nd] = r
        nd += 1
    # digits[nd-1] is the leading digit; value = 0.d1d2... * 10^decpt
    decpt = nd + e10
    if decpt <= -4 or decpt > 16:
        buf[p] = 48 + digits[nd - 1]
        p += 1
        if nd > 1:
            buf[p] = 46
            p += 1
            for i in range(nd - 2, -1, -1):
                buf[p] = 48 + digits[i]
                p += 1
        buf[p] = 101  # e
        p += 1
        x10 = decpt - 1
        if x10 < 0:
            buf[p] = 45
            x10 = -x10
        else:
            buf[p] = 43
        p += 1
        if x10 >= 100:
            buf[p] = 48 + x10 // 100
            p += 1
            x10 %= 100
            buf[p] = 48 + x10 // 10
            buf[p + 1] = 48 + x10 % 10
            return p + 2
        buf[p] = 48 + x10 // 10
        buf[p + 1] = 48 + x10 % 10
        return p + 2
    if decpt <= 0:
        buf[p] = 48
        buf[p + 1] = 46
        p += 2
        for _ in range(-decpt):
            buf[p] = 48
            p += 1
        for i in range(nd - 1, -1, -1):
            buf[p] = 48 + digits[i]
            p += 1
        return p
    if decpt >= nd:
        for i in range(nd - 1, -1, -1):
            buf[p] = 48 + digits[i]
            p += 1
        for _ in range(decpt - nd):
            buf[p] = 48
            p += 1
        buf[p] = 46
        buf[p + 1] = 48
        return p + 2
    for i in range(nd - 1, -1, -1):
        buf[p] = 48 + digits[i]
        p += 1
        if i == nd - decpt:
            buf[p] = 46
            p += 1
    return p


#: longest repr of a float64 ("-2.2250738585072014e-308" is 24 characters) plus a separator
_MAX_FIELD = 26


@njit(cache=True, nogil=True)
def _format_table(cols, inv, pos):
    ncol, K = cols.shape
    buf = np.empty(K * ncol * _MAX_FIELD, dtype=np.uint8)
    digits = np.empty(20, dtype=np.int64)
    bits = cols.view(np.uint64)
    prev_at = np.zeros(ncol, dtype=np.int64)  # where each column's last text starts
    prev_len = np.zeros(ncol, dtype=np.int64)
    p = 0
    for k in range(K):
        for c in range(ncol):
            if c:
                buf[p] = 44  # ,
                p += 1
            if k and bits[c, k] == bits[c, k - 1]:
                # the same value as the row before (an axis at rest): copy its text
                a = prev_at[c]
                n = prev_len[c]
                for i in range(n):
                    buf[p + i] = buf[a + i]
                prev_at[c] = p
                p += n
                continue
            e = _put_repr(bits[c, k], buf, p, digits, inv, pos)
            prev_at[c] = p
            prev_len[c] = e - p
            p = e
        buf[p] = 10
        p += 1
    return buf[:p]


def format_table(cols: np.ndarray) -> bytes:
    """CSV rows of ``cols`` (ncol, K) float64: ``repr`` of each value, ``,`` between
    columns, ``\\n`` after each row."""
    cols = np.ascontiguousarray(cols, dtype=np.float64)
    return _format_table(cols, _POW5_INV_SPLIT, _POW5_SPLIT).tobytes()


def warm_up() -> None:
    """Compile (or load) the formatter (a first run's ``precompile`` group ``csv``)."""
    format_table(np.zeros((1, 1)))


def repr_many(values: np.ndarray) -> list[str]:
    """``[repr(float(v)) for v in values]``, compiled (for tests and small uses)."""
    text = format_table(np.asarray(values, dtype=np.float64).reshape(1, -1))
    return text.decode("ascii").split("\n")[:-1]

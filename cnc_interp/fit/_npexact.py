"""Numpy's own float results inside compiled kernels.

The fit's compiled kernels take over work that was written with numpy, and must give
the very same paths (same bits): elementwise arithmetic is the same IEEE operations in
both, but three things are not —

* numpy sums with pairwise summation (8 accumulators, blocks of 128), not left to
  right: ``pairwise_sum`` is that algorithm (``x.sum()``, ``add.reduce`` along a
  contiguous row, ``np.linalg.norm(x, axis=1)`` = sqrt of the row's pairwise sum of
  squares; below 8 terms it is the plain left-to-right sum). A column selection
  ``x[:, mask]`` is laid out column by column, and numpy sums its rows left to right
  whatever their length (``corners._turn_parts``);
* numpy's ``x ** 3`` (and 4, 5) on an array runs the CPU's vector pow (SVML on AVX-512
  machines), which differs in the last bit from the C library's ``pow`` in a few per
  cent of the cases, and a matrix-vector product runs BLAS's kernel. Asking numpy from
  the kernel (an object-mode block) takes the GIL once per piece set, which stalled the
  fit's worker threads; so the Python fitter computes these powers and sums by products
  and a left-to-right sum instead (``hermite_powers``, ``cube``, ``weighted_rows``),
  the kernels the same way (``powers345``, ``arc_terms``). ``x ** 2`` is ``x * x`` in both;
* a 1-D ``x @ y`` (and ``np.linalg.norm(x)`` = sqrt(x @ x)) is BLAS's ``ddot``, which
  on short vectors accumulates left to right with fused multiply-adds: ``blas_dot``
  (checked against numpy in the tests for 1..9 terms).
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import njit
from numba.core import cgutils, types
from numba.extending import intrinsic

#: numpy's pairwise summation: terms summed left to right below this count
_PW_UNROLL = 8

#: numpy's pairwise summation: largest block summed with 8 accumulators before halving
_PW_BLOCKSIZE = 128


@njit(cache=True)
def _block_sum(a, lo, n):
    """numpy's pairwise sum of a block of at most ``_PW_BLOCKSIZE`` terms."""
    if n < _PW_UNROLL:
        res = 0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    top = n - (n % 8)
    while i < top:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@njit(cache=True)
def pairwise_sum(a, lo, n):
    """numpy's sum of ``a[lo:lo + n]`` (1-D, float64): the same additions in the same order.

    numpy halves a longer range (the first half a multiple of 8 terms) and adds the two
    halves' sums; written here with an explicit stack (numba's cache does not load
    self-recursive functions reliably)."""
    if n <= _PW_BLOCKSIZE:
        return _block_sum(a, lo, n)
    depth = 64  # the halves shrink geometrically: far more than any array's depth
    s_lo = np.empty(depth, dtype=np.int64)
    s_n = np.empty(depth, dtype=np.int64)
    s_phase = np.zeros(depth, dtype=np.int64)
    s_left = np.empty(depth)
    s_lo[0] = lo
    s_n[0] = n
    top = 1
    ret = 0.0
    while top > 0:
        f = top - 1
        nf = s_n[f]
        if nf <= _PW_BLOCKSIZE:
            ret = _block_sum(a, s_lo[f], nf)
            top -= 1
            continue
        n2 = nf // 2
        n2 -= n2 % 8
        if s_phase[f] == 0:
            s_phase[f] = 1
            s_lo[top] = s_lo[f]
            s_n[top] = n2
            s_phase[top] = 0
            top += 1
        elif s_phase[f] == 1:
            s_left[f] = ret
            s_phase[f] = 2
            s_lo[top] = s_lo[f] + n2
            s_n[top] = nf - n2
            s_phase[top] = 0
            top += 1
        else:
            ret = s_left[f] + ret
            top -= 1
    return ret


@njit(cache=True)
def row_norm(x, i, buf):
    """``np.linalg.norm(x, axis=1)[i]`` for x (n, d): the square root of numpy's sum of
    the row's squares; ``buf`` a work array of length >= d."""
    d = x.shape[1]
    for a in range(d):
        buf[a] = x[i, a] * x[i, a]
    return np.sqrt(0.0 + pairwise_sum(buf, 0, d))


@njit(cache=True)
def powers345(h):
    """(h³, h⁴, h⁵) of the array ``h`` (1-D) by products — ``hermite_powers``' arithmetic,
    which the Python fitter uses, so both give the same bits without numpy's vector pow."""
    n = h.shape[0]
    p3 = np.empty(n)
    p4 = np.empty(n)
    p5 = np.empty(n)
    for i in range(n):
        h2 = h[i] * h[i]
        p3[i] = h2 * h[i]
        p4[i] = h2 * h2
        p5[i] = p4[i] * h[i]
    return p3, p4, p5


def hermite_powers(h: np.ndarray):
    """(h³, h⁴, h⁵) elementwise by products (numpy's ``h ** 3`` is a vector pow whose last
    bit a compiled kernel cannot reproduce): ``powers345``' arithmetic, for the Python
    fitter's quintic Hermites."""
    h2 = h * h
    p4 = h2 * h2
    return h2 * h, p4, p4 * h


@intrinsic
def _fma(typingctx, x, y, z):
    """x * y + z with one rounding (LLVM's fma)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        dbl = ir.DoubleType()
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(dbl, [dbl, dbl, dbl]), "llvm.fma.f64")
        return builder.call(fn, args)

    return sig, codegen


@njit(cache=True)
def blas_dot(x, y):
    """numpy's ``x @ y`` of two short 1-D float64 vectors (BLAS ddot: fused multiply-adds
    left to right)."""
    acc = 0.0
    for i in range(x.shape[0]):
        acc = _fma(x[i], y[i], acc)
    return acc


@njit(cache=True)
def arc_terms(sp, speeds, weights):
    """(sp³, the quadrature speeds @ weights) as ``cube`` and ``weighted_rows`` compute them:
    sp (K,), speeds (K, G), weights (G,)."""
    K, G = speeds.shape
    p3 = np.empty(sp.shape[0])
    for i in range(sp.shape[0]):
        p3[i] = sp[i] * sp[i] * sp[i]
    quad = np.empty(K)
    for i in range(K):
        acc = speeds[i, 0] * weights[0]
        for g in range(1, G):
            acc += speeds[i, g] * weights[g]
        quad[i] = acc
    return p3, quad


def cube(x: np.ndarray) -> np.ndarray:
    """x³ elementwise by products (``arc_terms``' arithmetic)."""
    return x * x * x


def weighted_rows(speeds: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``speeds @ weights`` (K, G) @ (G,) summed left to right (``arc_terms``' arithmetic;
    BLAS's matrix-vector product would not be reproducible in a compiled kernel)."""
    acc = speeds[:, 0] * weights[0]
    for g in range(1, speeds.shape[1]):
        acc = acc + speeds[:, g] * weights[g]
    return acc

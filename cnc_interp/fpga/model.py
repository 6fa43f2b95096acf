"""Bit-exact golden model of the FPGA trajectory interpolator (paper 000, "Proposed Architecture").

Per sample n of a planar segment (all integers, formats in ``FpgaFormats``):

1. profile generator: τ_n = j·Δτ inside the current profile piece (an accumulator
   stepping by Δτ), ξ_n = Horner(profile mantissas, τ_n): the normalised abscissa
   x*/x_end in [0, 1] (paper 000's parametric technique: the profile drives the
   curve parameter);
2. polynomial evaluation: x*_n = ξ_n·x_end (x_end as a mantissa with a block
   exponent, so it is one multiplier operand) and z*_n = Horner(P mantissas, ξ_n) with
   P(ξ) = p(ξ·x_end) (normalised so the word is used whatever the segment length);
   Δx*_n = x*_n − x*_{n−1}, Δz*_n = z*_n − z*_{n−1} (both start at 0 on the segment;
   they must fit the multiplier operand, ``mult_word`` bits);
3. rotation by θ: (Δx*·cos θ − Δz*·sin θ, Δx*·sin θ + Δz*·cos θ), products kept at
   full width (pos.frac + trig.frac fraction bits);
4. integrators: I += rotated increment (``int_word`` bits, no rounding inside the
   loop), output q = origin + round(I) in the position format. At every segment
   start the integrators are resynchronised: I = 0, q = origin of the segment
   (sent by the host), so rounding never carries from one segment to the next.

Every multiplication of the datapath has two operands of at most ``mult_word``
(35) bits, so one shared 35×35 multiplier (four ECP5 MULT18X18D) does all 15 of a
sample; the Horner accumulators (``horner_word``) and the integrators (``int_word``)
are separate registers, each range-checked (``FixedPointOverflow``).

Why p rather than p': the paper's block evaluates p' and integrates
Δz* = p'·Δx*. That is forward Euler on the curve and drifts by about ½·Δx*²·p''
per sample (0.25 µm per sample at 100 mm/s, 1 ms, 10 mm radius), three orders of
magnitude over the 0.1 µm target. Differencing Horner values of p keeps the
same blocks (profile, Horner, rotation, integrators) with exact increments.

Non-planar motion (VPOp plans, rapids, 3-axis moves) arrives as setpoint blocks:
quantized absolute positions of every axis, output unchanged.

The sequential hardware loop is evaluated here with exact vectorised integer
arithmetic (object arrays of Python ints, cumulative sums): same numbers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .fixed import FixedFormat, FpgaFormats, Where, obj, round_shift


@dataclass(frozen=True)
class ProfilePiece:
    """One piece of a segment's parametric profile ξ(τ), τ = j·dtau for j = 0..n_samples-1.

    dtau: Δτ in the param format (τ reaches ~1 at the piece's last sample).
    exp: block exponent of the mantissas; mant: 6 ints, ξ(τ) = Σ mant[i]·2^-exp·τ^i.
    """

    n_samples: int
    dtau: int
    exp: int
    mant: tuple[int, ...]


@dataclass(frozen=True)
class FixedSegment:
    """A quantized paper-000 segment and its profile.

    index: segment number in the program (0-based, counts every planar segment).
    line: source line of the G-code block the segment ends on.
    plane: machine axis indices (horizontal, vertical) of the rotated frame.
    cos, sin: rotation (trig format); origin: (2,) ints (pos format);
    x_exp, x_mant: the rotated abscissa of the segment end, x_end = x_mant·2^-x_exp mm
    (a ``coef_word`` mantissa, so x* = ξ·x_end is one multiplication);
    p_exp, p_mant: block exponent and 6 mantissas of P(ξ) = p(ξ·x_end), mm.
    start_sample: global index of the segment's first sample; pieces: its profile.
    """

    index: int
    line: int
    plane: tuple[int, int]
    cos: int
    sin: int
    origin: tuple[int, int]
    x_exp: int
    x_mant: int
    p_exp: int
    p_mant: tuple[int, ...]
    start_sample: int
    pieces: tuple[ProfilePiece, ...]

    @property
    def n_samples(self) -> int:
        return sum(p.n_samples for p in self.pieces)


@dataclass(frozen=True)
class SetpointBlock:
    """Quantized absolute setpoints q (n, n_axes) int64 (pos format) from ``start_sample``."""

    start_sample: int
    line: int
    q: np.ndarray

    @property
    def n_samples(self) -> int:
        return int(self.q.shape[0])


Item = FixedSegment | SetpointBlock


@dataclass(frozen=True)
class FpgaProgram:
    """A whole quantized program: what the host sends, in order.

    axes: machine axis letters; dt_s: sample period; start: (n_axes,) ints, the
    position held before the first sample; n_samples: total samples;
    items: segments and setpoint blocks covering samples 0..n_samples-1 in order.
    stats: plain JSON-able figures from the build (deviations, counts).
    """

    axes: str
    dt_s: float
    formats: FpgaFormats
    start: tuple[int, ...]
    n_samples: int
    items: tuple[Item, ...]
    source: str = "<input>"
    stats: dict = field(default_factory=dict)


# -- datapath pieces ---------------------------------------------------------------
def horner_rows(
    mant: np.ndarray,
    exp: np.ndarray,
    var: np.ndarray,
    var_frac: int,
    out_frac: int,
    acc: FixedFormat,
    what: str,
    where: Where | None = None,
):
    """Row-wise Horner: mant (K, 6) ints, exp (K,), var (K,) -> (K,) ints (see ``fixed.horner``)."""
    a = mant[:, -1].copy()
    for i in range(mant.shape[1] - 2, -1, -1):
        a = round_shift(a * var, var_frac) + mant[:, i]
        acc.check(a, what, where)
    sh = np.asarray(exp, dtype=np.int64) - out_frac
    shp = obj(np.maximum(sh, 0))
    shn = obj(np.maximum(-sh, 0))
    one = np.full(shp.shape, 1, dtype=object)
    half = (one << shp) >> 1
    return ((a + half) >> shp) << shn


#: samples of a segment the model evaluates at once: its arithmetic is on arrays of
#: Python ints (~200 bytes a sample), so a frame's piece of 2^24 samples took 3.8 GB whole;
#: any size gives the same numbers
FPGA_MODEL_CHUNK_SAMPLES = 1 << 16


def profile_xi(pieces, fmts: FpgaFormats, where: Where | None = None, lo: int = 0, hi: int | None = None) -> np.ndarray:
    """ξ (ints, param format) at samples ``lo`` to ``hi`` (default: every sample) of a
    segment's profile pieces."""
    counts = np.array([p.n_samples for p in pieces], dtype=np.int64)
    starts = np.cumsum(counts) - counts
    hi = int(counts.sum()) if hi is None else hi
    k = np.arange(lo, hi, dtype=np.int64)
    rep = np.searchsorted(starts + counts, k, side="right")  # the piece of each sample
    j = k - starts[rep]
    dtau = obj(np.array([p.dtau for p in pieces], dtype=object))[rep]
    tau = obj(j) * dtau
    mant = np.array([p.mant for p in pieces], dtype=object)[rep]
    exp = np.array([p.exp for p in pieces], dtype=np.int64)[rep]
    xi = horner_rows(mant, exp, tau, fmts.param.frac, fmts.param.frac, fmts.horner, "profile accumulator", where)
    fmts.param.check(xi, "profile output ξ", where)
    return xi


@dataclass(frozen=True)
class SegmentRun:
    """One segment through the datapath: outputs (n, 2) ints and diagnostics."""

    q: np.ndarray  # (n, 2) object ints, pos format: plane axes at each sample
    end: tuple[int, int]  # where the integrators would be at ξ = 1 (pos format)
    xi: np.ndarray  # (n,) profile output ξ (param format)
    x: np.ndarray  # (n,) x* (pos format)
    z: np.ndarray  # (n,) z* = P(ξ) (pos format)


def x_star(xi, seg: FixedSegment, fmts: FpgaFormats):
    """x* = ξ·x_end in the position format (one product, rounded once)."""
    return round_shift(xi * seg.x_mant, fmts.param.frac + seg.x_exp - fmts.pos.frac)


def segment_chunks(seg: FixedSegment, fmts: FpgaFormats, file: str = "<input>", chunk: int | None = None):
    """One segment through the datapath (see module docstring), ``chunk`` samples at a
    time (default ``FPGA_MODEL_CHUNK_SAMPLES``): (xi, x, z, q) of each chunk in order, q
    (m, 2) object ints (pos format). The
    increments and integrators carry over from one chunk to the next, so the numbers do
    not depend on ``chunk``."""
    where = Where(seg.index, seg.line, file)
    fp, ft, fx = fmts.pos.frac, fmts.trig.frac, fmts.param.frac
    c, s = seg.cos, seg.sin
    last_x = last_z = 0  # Δx*, Δz* start at 0 on the segment
    ih0 = iv0 = 0
    total = seg.n_samples
    step = max(1, int(chunk or FPGA_MODEL_CHUNK_SAMPLES))
    for lo in range(0, total, step):
        hi = min(total, lo + step)
        xi = profile_xi(seg.pieces, fmts, where, lo, hi)
        x = x_star(xi, seg, fmts)
        pm = np.array([seg.p_mant], dtype=object).repeat(xi.shape[0], axis=0)
        pe = np.full(xi.shape[0], seg.p_exp, dtype=np.int64)
        z = horner_rows(pm, pe, xi, fx, fp, fmts.horner, "path polynomial accumulator", where)
        dx = np.diff(np.concatenate((np.array([last_x], dtype=object), x)))
        dz = np.diff(np.concatenate((np.array([last_z], dtype=object), z)))
        last_x, last_z = x[-1], z[-1]
        fmts.operand.check(dx, "abscissa increment Δx*", where)
        fmts.operand.check(dz, "ordinate increment Δz*", where)
        ih = ih0 + np.cumsum(c * dx - s * dz)
        iv = iv0 + np.cumsum(s * dx + c * dz)
        ih0, iv0 = ih[-1], iv[-1]
        fmts.integ.check(ih, "horizontal integrator", where)
        fmts.integ.check(iv, "vertical integrator", where)
        out = np.empty((xi.shape[0], 2), dtype=object)
        out[:, 0] = seg.origin[0] + round_shift(ih, ft)
        out[:, 1] = seg.origin[1] + round_shift(iv, ft)
        fmts.pos.check(out, "position", where)
        yield xi, x, z, out


def segment_end(seg: FixedSegment, fmts: FpgaFormats) -> tuple[int, int]:
    """Diagnostic: where the integrators would be carried on to ξ = 1 (the segment's
    exact end), pos format."""
    from .fixed import horner

    fp, ft, fx = fmts.pos.frac, fmts.trig.frac, fmts.param.frac
    c, s = seg.cos, seg.sin
    one = 1 << fx
    z1 = horner(list(seg.p_mant), seg.p_exp, one, fx, fp, fmts.horner)
    x1 = x_star(one, seg, fmts)
    return (seg.origin[0] + round_shift(c * x1 - s * z1, ft), seg.origin[1] + round_shift(s * x1 + c * z1, ft))


def run_segment(seg: FixedSegment, fmts: FpgaFormats, file: str = "<input>") -> SegmentRun:
    """Evaluate one segment exactly as the hardware does (see module docstring)."""
    parts = list(segment_chunks(seg, fmts, file))
    if parts:
        xi, x, z, out = (np.concatenate(a) for a in zip(*parts))
    else:
        xi = x = z = np.zeros(0, dtype=object)
        out = np.empty((0, 2), dtype=object)
    return SegmentRun(out, segment_end(seg, fmts), xi, x, z)


@dataclass
class ModelOutput:
    """Emulated setpoints: q (K, n_axes) int64 in the pos format, line (K,) int64,
    and per-segment end drift (ints: |integrator end - next origin| per axis, pos LSB)."""

    q: np.ndarray
    line: np.ndarray
    segment_end_gap: list


class DatapathState:
    """The device's running state: current position of every axis and the next sample index.

    Items are applied in order with ``apply``; samples accumulate in ``q_blocks``.
    """

    def __init__(self, axes: str, formats: FpgaFormats, start, file: str = "<input>", sink=None):
        self.axes = axes
        #: ``sink(q, line)``, if given, takes the samples as they are computed (q (m,
        #: n_axes) int64, the source line) instead of ``q_blocks``: ``emulate`` writes them
        self.sink = sink
        self.formats = formats
        self.file = file
        self.pos = [int(v) for v in start]
        self.next_sample = 0
        self.q_blocks: list[np.ndarray] = []
        self.line_blocks: list[np.ndarray] = []
        self.segment_end_gap: list[tuple[int, int]] = []
        self._last_end: tuple[int, int] | None = None
        self._last_plane: tuple[int, int] | None = None

    def apply(self, item: Item) -> None:
        """Run one item; raises ValueError if it does not start at the next sample."""
        if item.start_sample != self.next_sample:
            raise ValueError(f"item starts at sample {item.start_sample}, expected {self.next_sample}")
        n = item.n_samples
        if isinstance(item, SetpointBlock):
            self._last_end = None
            self._emit(np.asarray(item.q, dtype=np.int64).reshape(n, len(self.axes)), item.line)
        else:
            end = segment_end(item, self.formats)
            if self._last_end is not None and self._last_plane == item.plane:
                self.segment_end_gap.append((item.origin[0] - self._last_end[0], item.origin[1] - self._last_end[1]))
            self._last_end, self._last_plane = end, item.plane
            h, v = item.plane
            held = np.array(self.pos, dtype=np.int64)  # the axes off the plane stay put
            blocks = []
            for _xi, _x, _z, part in segment_chunks(item, self.formats, self.file):
                q = np.empty((part.shape[0], len(self.axes)), dtype=np.int64)
                q[:] = held
                q[:, h] = part[:, 0].astype(np.int64)
                q[:, v] = part[:, 1].astype(np.int64)
                blocks.append(q)
                if self.sink is not None:  # handed on as computed: bounded memory
                    self._emit(blocks.pop(), item.line)
            if blocks:
                self._emit(np.concatenate(blocks) if len(blocks) > 1 else blocks[0], item.line)
            elif self.sink is None:
                self._emit(np.empty((0, len(self.axes)), dtype=np.int64), item.line)
        self.next_sample += n

    def _emit(self, q: np.ndarray, line: int) -> None:
        """Samples q (m, n_axes) computed: kept in ``q_blocks``, or handed to ``sink``."""
        if q.shape[0]:
            self.pos = [int(v) for v in q[-1]]
        if self.sink is not None:
            self.sink(q, line)
            return
        self.q_blocks.append(q)
        self.line_blocks.append(np.full(q.shape[0], line, dtype=np.int64))

    def output(self) -> ModelOutput:
        n_axes = len(self.axes)
        q = np.concatenate(self.q_blocks) if self.q_blocks else np.empty((0, n_axes), np.int64)
        line = np.concatenate(self.line_blocks) if self.line_blocks else np.empty(0, np.int64)
        return ModelOutput(q, line, self.segment_end_gap)


def run_program(prog: FpgaProgram) -> ModelOutput:
    """All samples of a program through the golden model."""
    st = DatapathState(prog.axes, prog.formats, prog.start, prog.source)
    for item in prog.items:
        st.apply(item)
    return st.output()


def to_mm(q_int: np.ndarray, fmts: FpgaFormats) -> np.ndarray:
    """Position integers -> float mm/deg."""
    return np.ldexp(np.asarray(q_int, dtype=np.int64).astype(float), -fmts.pos.frac)

"""Check emitted setpoints against the machine's limits (paper 001, Eq. 6).

Velocity, acceleration and jerk of each axis are the backward finite differences
of the setpoints q_k at the fixed period dt::

    v_k = (q_k - q_{k-1}) / dt
    a_k = (q_k - 2 q_{k-1} + q_{k-2}) / dt^2
    j_k = (q_k - 3 q_{k-1} + 3 q_{k-2} - q_{k-3}) / dt^3

with REST PADDING: the machine holds q_0 before the first sample and q_{K-1}
after the last, so three held copies on each side are part of the sequence. A
plan that starts or ends with a jump is therefore caught. The differences are
taken as repeated ``np.diff`` of the stored float64 values; consecutive values
are close, so each subtraction is exact (Sterbenz) and the check measures the
stored numbers themselves, not a rounding artefact of a 4-term stencil.

``where`` numbers a difference by the sample its stencil ends at: -2..-1 and
K..K+2 denote the held positions before the start and after the end.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ..constants import VERIFY_RATIO_SLACK, VERIFY_REST_PADDING

if TYPE_CHECKING:
    from ..machine.model import Machine
    from .trajectory import Trajectory

#: a plan's first sample may differ from the machine's start position by this much, mm or
#: deg: far above the device's fixed-point quantum (2^-28), far below any real move
VERIFY_START_TOL = 1e-6

_KINDS = ("velocity", "acceleration", "jerk")
_UNITS = ("/s", "/s^2", "/s^3")


@dataclass(frozen=True, eq=False)
class VerifyReport:
    """Worst limit ratios of a plan.

    Attributes (n = number of axes):
        axes: axis letters.
        dt_s: sample period used for the differences, s.
        n_samples: K, samples in the plan (padding excluded).
        ratios: (n, 3) worst |v|/vmax, |a|/amax, |j|/jmax per axis (NaN if the plan has NaN).
        values: (n, 3) the worst |v|, |a|, |j| themselves (mm or deg per s, s^2, s^3).
        limits: (n, 3) vmax, amax, jmax.
        where: (n, 3) int, sample index where each worst value occurs (see module doc).
        ok: every ratio <= 1 + VERIFY_RATIO_SLACK, no NaN/inf, and the plan starts at the
            start position (when one is given).
        nan_found: the setpoints contain NaN or inf.
        machine: the machine checked against, ``"NAME (SOURCE)"`` ("" for bare arrays).
        start_offset: (n,) |q_0 - start| per axis, mm or deg; ``None`` when no start
            position was given.
    """

    axes: str
    dt_s: float
    n_samples: int
    ratios: np.ndarray
    values: np.ndarray
    limits: np.ndarray
    where: np.ndarray
    ok: bool
    nan_found: bool
    machine: str = ""
    start_offset: np.ndarray | None = None

    @property
    def worst_ratio(self) -> float:
        """The largest ratio over all axes and limits (inf if the plan has NaN)."""
        if self.nan_found:
            return float("inf")
        return float(self.ratios.max()) if self.ratios.size else 0.0

    def _limits_ok(self) -> bool:
        return bool(np.all(self.ratios <= 1.0 + VERIFY_RATIO_SLACK))

    @property
    def start_ok(self) -> bool:
        """The first sample is the start position (true when none was given)."""
        return _start_within(self.start_offset)

    def worst(self) -> tuple[str, str, float, int]:
        """(axis, kind, ratio, sample index) of the worst ratio."""
        if not self.ratios.size:
            return ("", "", 0.0, 0)
        r = np.where(np.isnan(self.ratios), np.inf, self.ratios)
        i, k = np.unravel_index(int(np.argmax(r)), r.shape)
        return self.axes[i], _KINDS[k], float(self.ratios[i, k]), int(self.where[i, k])

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form (no NaN: a NaN ratio becomes ``None``)."""

        def num(x: float) -> float | None:
            x = float(x)
            return x if np.isfinite(x) else None

        per_axis = {}
        for i, a in enumerate(self.axes):
            per_axis[a] = {
                kind: {
                    "ratio": num(self.ratios[i, k]),
                    "worst": num(self.values[i, k]),
                    "limit": num(self.limits[i, k]),
                    "sample": int(self.where[i, k]),
                    "t_s": float(self.where[i, k] * self.dt_s),
                }
                for k, kind in enumerate(_KINDS)
            }
        axis, kind, ratio, idx = self.worst()
        return {
            "ok": bool(self.ok),
            "nan_found": bool(self.nan_found),
            "worst_ratio": num(self.worst_ratio) if not self.nan_found else None,
            "worst": {"axis": axis, "limit": kind, "ratio": num(ratio), "sample": idx},
            "dt_s": float(self.dt_s),
            "n_samples": int(self.n_samples),
            "slack": VERIFY_RATIO_SLACK,
            "machine": self.machine,
            "start_ok": self.start_ok,
            "start_offset": None if self.start_offset is None else dict(zip(self.axes, map(float, self.start_offset))),
            "axes": per_axis,
        }

    def format(self) -> str:
        """Human-readable table: one row per axis, worst ratio per limit."""
        from ..errors import printable

        lines = [f"machine: {printable(self.machine)}"] if self.machine else []
        lines.append(f"{'axis':>4}  {'v/vmax':>12} {'a/amax':>12} {'j/jmax':>12}   worst at")
        for i, a in enumerate(self.axes):
            k = int(np.nanargmax(self.ratios[i])) if np.isfinite(self.ratios[i]).any() else 0
            cells = " ".join(f"{r:>12.9f}" for r in self.ratios[i])
            if np.isfinite(self.ratios[i]).all() and not self.ratios[i].any():
                lines.append(f"{a:>4}  {cells}   (does not move)")
                continue
            lines.append(
                f"{a:>4}  {cells}   {_KINDS[k]} t={self.where[i, k] * self.dt_s:.6g} s (sample {self.where[i, k]})"
            )
        if not self.start_ok:
            assert self.start_offset is not None
            i = int(np.argmax(self.start_offset))
            lines.append(
                f"FAIL: the plan does not start at the machine's start position ({self.axes[i]} off by "
                f"{self.start_offset[i]:.9g}; at most {VERIFY_START_TOL:g} passes; plan --start moves it)"
            )
        if self.nan_found:
            lines.append("FAIL: the setpoints contain NaN or inf")
        else:
            axis, kind, ratio, idx = self.worst()
            verdict = "ok" if self.ok else ("FAIL: limit exceeded" if not self._limits_ok() else "FAIL")
            lines.append(
                f"{verdict}: worst {ratio:.12f} ({axis} {kind}, sample {idx}); "
                f"{self.n_samples} samples at dt = {self.dt_s:g} s; a ratio passes up "
                f"to 1 + {VERIFY_RATIO_SLACK:g} (float rounding)"
            )
        return "\n".join(lines)


def _start_within(offset: np.ndarray | None) -> bool:
    """The first sample is the start position (true when no start was given)."""
    return offset is None or bool(np.all(offset <= VERIFY_START_TOL))


def _start_offset(q: np.ndarray, start: ArrayLike | None) -> np.ndarray | None:
    """(n,) |q_0 - start|, or ``None`` without a start position or samples."""
    if start is None or not q.shape[0]:
        return None
    off = np.abs(q[0] - np.asarray(start, dtype=float).reshape(q.shape[1]))
    return np.where(np.isfinite(off), off, np.inf)


def _axis_extremes(col: np.ndarray, pad: int) -> tuple[np.ndarray, np.ndarray]:
    """Worst |d^m q| for m = 1..3 of one axis with rest padding: (values (3,), where (3,))."""
    x = np.concatenate([np.full(pad, col[0]), col, np.full(pad, col[-1])])
    vals = np.empty(3)
    where = np.empty(3, dtype=np.int64)
    for m in range(3):
        x = np.diff(x)
        ax = np.abs(x)
        i = int(np.argmax(ax))
        vals[m] = ax[i]
        # x[i] is the difference whose stencil ends at padded index i + m + 1
        # an axis that never moves has no "worst" sample: report sample 0
        where[m] = i + m + 1 - pad if ax[i] > 0 else 0
    return vals, where


def verify_arrays(
    q: np.ndarray,
    dt_s: float,
    vmax: ArrayLike,
    amax: ArrayLike,
    jmax: ArrayLike,
    axes: str | None = None,
    start: ArrayLike | None = None,
    machine: str = "",
) -> VerifyReport:
    """Verify setpoints ``q`` (K, n) at period ``dt_s`` against per-axis limits (n,) each;
    with ``start`` (n,), also that the first sample is that position."""
    q = np.asarray(q, dtype=float)
    if q.ndim == 1:
        q = q[:, None]
    k, n = q.shape
    limits = np.stack([np.broadcast_to(np.asarray(x, dtype=float), (n,)) for x in (vmax, amax, jmax)], axis=1)  # (n, 3)
    axes = axes if axes is not None else "".join(f"{i}" for i in range(n))
    scale = np.array([dt_s, dt_s**2, dt_s**3])
    values = np.zeros((n, 3))
    where = np.zeros((n, 3), dtype=np.int64)
    nan_found = False
    if k:
        finite = np.isfinite(q)
        nan_found = not bool(finite.all())
        for i in range(n):
            col = np.ascontiguousarray(q[:, i])
            if not finite[:, i].all():
                values[i] = np.nan
                where[i] = int(np.argmin(finite[:, i]))
                continue
            d, w = _axis_extremes(col, VERIFY_REST_PADDING)
            values[i] = d / scale
            where[i] = w
    with np.errstate(invalid="ignore", divide="ignore"):
        ratios = values / limits
    start_offset = _start_offset(q, start)
    ok = (not nan_found) and bool(np.all(ratios <= 1.0 + VERIFY_RATIO_SLACK))
    ok = ok and _start_within(start_offset)
    return VerifyReport(
        axes=axes,
        dt_s=float(dt_s),
        n_samples=int(k),
        ratios=ratios,
        values=values,
        limits=limits,
        where=where,
        ok=ok,
        nan_found=nan_found,
        machine=machine,
        start_offset=start_offset,
    )


def verify(traj: "Trajectory", machine: "Machine") -> VerifyReport:
    """Verify a ``Trajectory`` against a ``Machine``'s limits (axes matched by letter) and
    that it starts at the machine's start position."""
    from ..errors import MachineError, SourceLocation

    for a in traj.axes:
        if a not in machine.axes:
            raise MachineError(
                f"the plan has axis {a}, which machine '{machine.name}' ({machine.axes}) does not have",
                SourceLocation(machine.source or "<machine>"),
            )
    idx = np.array([machine.axes.index(a) for a in traj.axes], dtype=int)
    return verify_arrays(
        traj.q,
        traj.dt_s,
        machine.vmax[idx],
        machine.amax[idx],
        machine.jmax[idx],
        axes=traj.axes,
        start=np.asarray(machine.start, dtype=float)[idx],
        machine=machine_label(machine),
    )


def machine_label(machine: "Machine") -> str:
    """``NAME (SOURCE)``: how a report names the machine it checked against."""
    return f"{machine.name} ({machine.source})" if machine.source else machine.name


class StreamVerifier:
    """``verify_arrays`` over a stream of sample blocks, with the same report.

    Each block's differences are taken with the last three samples before it (the rest
    padding before the first sample), so every stencil is computed once, from the same
    stored values as on the whole array; the trailing rest padding is added by
    ``report``. ``add`` returns False as soon as a block breaks a limit (or holds NaN), so
    a caller can stop before writing it.
    """

    def __init__(
        self,
        dt_s: float,
        vmax: ArrayLike,
        amax: ArrayLike,
        jmax: ArrayLike,
        axes: str,
        start: ArrayLike | None = None,
        machine: str = "",
    ):
        n = len(axes)
        self.start = None if start is None else np.asarray(start, dtype=float).reshape(n)
        self.start_offset: np.ndarray | None = None
        self.machine = machine
        self.axes = axes
        self.dt_s = float(dt_s)
        self.limits = np.stack(
            [np.broadcast_to(np.asarray(x, dtype=float), (n,)) for x in (vmax, amax, jmax)], axis=1
        )  # (n, 3)
        self.scale = np.array([dt_s, dt_s**2, dt_s**3])
        self.best = np.zeros((n, 3))  # worst |d^m q| so far (stored values, not scaled)
        self.where = np.zeros((n, 3), dtype=np.int64)
        self.first_bad = np.full(n, -1, dtype=np.int64)  # first non-finite sample per axis
        self.k = 0
        self.tail: np.ndarray | None = None  # the last VERIFY_REST_PADDING padded samples
        self.n = n

    @classmethod
    def for_machine(cls, machine: "Machine", dt_s: float) -> "StreamVerifier":
        return cls(
            dt_s,
            machine.vmax,
            machine.amax,
            machine.jmax,
            machine.axes,
            start=machine.start,
            machine=machine_label(machine),
        )

    def _scan(self, x: np.ndarray, e0: int, skip: int) -> None:
        """Differences of the padded run ``x`` (m, n) whose first stencil of order 1 ends
        at padded index e0; stencils ending before e0 + skip were seen already."""
        pad = VERIFY_REST_PADDING
        d = x
        for m in range(3):
            d = np.diff(d, axis=0)
            # d[i] ends at padded index e0 + i (order m+1 starts one later each time)
            start = max(skip - m, 0)
            if start >= d.shape[0]:
                continue
            ad = np.abs(d[start:])
            i = np.argmax(ad, axis=0)
            v = ad[i, np.arange(self.n)]
            better = v > self.best[:, m]
            if better.any():
                self.best[better, m] = v[better]
                self.where[better, m] = (e0 + m + start + i[better]) - pad
        return None

    def add(self, q: np.ndarray) -> bool:
        """Check the next block of samples (K, n); False if a limit is broken in it."""
        pad = VERIFY_REST_PADDING
        q = np.asarray(q, dtype=float)
        if not q.shape[0]:
            return self.ok_so_far()
        finite = np.isfinite(q)
        if not finite.all():
            bad = ~finite.all(axis=0)
            rows = np.argmin(finite, axis=0)
            newly = bad & (self.first_bad < 0)
            self.first_bad[newly] = self.k + rows[newly]
            q = np.where(finite, q, 0.0)  # the rest of the axis is reported as NaN anyway
        if self.tail is None:
            self.tail = np.repeat(q[:1], pad, axis=0)
            self.start_offset = _start_offset(q, self.start)
        x = np.concatenate([self.tail, q], axis=0)
        # x[0] is padded index self.k (the sample k - pad); the first diff ends at +1
        self._scan(x, self.k + 1, pad - 1)
        self.tail = x[-pad:]
        self.k += q.shape[0]
        return self.ok_so_far()

    def ratios(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            ratios: np.ndarray = (self.best / self.scale) / self.limits
        return ratios

    def ok_so_far(self) -> bool:
        start_ok = _start_within(self.start_offset)
        return start_ok and bool((self.first_bad < 0).all()) and bool(np.all(self.ratios() <= 1.0 + VERIFY_RATIO_SLACK))

    def report(self) -> VerifyReport:
        """The report of everything added, with the rest padding after the last sample.
        It leaves the stream as it was: more samples may be added after it."""
        pad = VERIFY_REST_PADDING
        stream_best, stream_where = self.best.copy(), self.where.copy()
        if self.tail is not None:
            x = np.concatenate([self.tail, np.repeat(self.tail[-1:], pad, axis=0)], axis=0)
            self._scan(x, self.k + 1, pad - 1)
        # the padded extremes are the report's; the stream keeps its own
        best, where = self.best, self.where
        self.best, self.where = stream_best, stream_where
        values = best / self.scale
        where[values == 0] = 0  # an axis that never moves has no "worst" sample
        nan_found = bool((self.first_bad >= 0).any())
        for i in np.flatnonzero(self.first_bad >= 0):
            values[i] = np.nan
            where[i] = self.first_bad[i]
        with np.errstate(invalid="ignore", divide="ignore"):
            ratios = values / self.limits
        ok = (not nan_found) and bool(np.all(ratios <= 1.0 + VERIFY_RATIO_SLACK))
        ok = ok and _start_within(self.start_offset)
        return VerifyReport(
            axes=self.axes,
            dt_s=self.dt_s,
            n_samples=int(self.k),
            ratios=ratios,
            values=values,
            limits=self.limits,
            where=where,
            ok=ok,
            nan_found=nan_found,
            machine=self.machine,
            start_offset=self.start_offset,
        )

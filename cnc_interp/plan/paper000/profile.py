"""The jerk-bounded polynomial feed transition and the per-segment profile data.

Reference 22 of paper 000 (Osornio-Rios et al. 2007) generates acceleration and
deceleration with a polynomial in normalised time. This module uses the quintic
"smoothstep" velocity polynomial (a 4th-order polynomial acceleration, 3rd-order jerk):

    tau = t / T,  0 <= tau <= 1
    h(tau)  = 10 tau^3 - 15 tau^4 + 6 tau^5                 (h(0) = 0, h(1) = 1)
    v(t)    = v0 + dv * h(tau)                              dv = v1 - v0
    a(t)    = dv / T    * 30 tau^2 (1 - tau)^2              (0 at both ends)
    j(t)    = dv / T^2  * 60 tau (1 - tau)(1 - 2 tau)        (0 at both ends)
    s(t)    = v0 T tau + dv T (5/2 tau^4 - 3 tau^5 + tau^6)  s(T) = (v0 + v1) T / 2

Peaks: |a| = 15/8 |dv| / T at tau = 1/2, |j| = (10/sqrt(3)) |dv| / T^2 at
tau = (3 -+ sqrt(3)) / 6. Feed, acceleration and jerk are continuous, and every
transition starts and ends at zero acceleration and zero jerk, so segments can be
chained (and padded with rest) without any jump. The shortest transition under the
tangential limits A, J is

    T_min(dv) = max(15/8 |dv| / A, sqrt(10/sqrt(3) |dv| / J))

and it covers D(v0, v1) = (v0 + v1) T_min / 2 of arc length (the minimum-distance
transition).

Each profile piece is: accelerate v_start -> v_cruise (t_acc), cruise (t_cruise),
decelerate v_cruise -> v_end (t_dec). An FPGA regenerates the feed every sample from
the piece's three feeds and durations with a handful of multiply-adds (Horner on the
power-basis coefficients given by ``SegmentProfiles.acc_coef`` / ``pos_coef``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: peak |a| of a transition = ACC_PEAK * |dv| / T
ACC_PEAK = 15.0 / 8.0
#: peak |j| of a transition = JERK_PEAK * |dv| / T^2
JERK_PEAK = 10.0 / math.sqrt(3.0)
#: h(tau) power-basis coefficients (ascending)
H_COEF = np.array([0.0, 0.0, 0.0, 10.0, -15.0, 6.0])
#: H(tau) = integral of h from 0 (ascending); H(1) = 1/2
HINT_COEF = np.array([0.0, 0.0, 0.0, 0.0, 2.5, -3.0, 1.0])


def transition_time(dv, a_max, j_max):
    """Shortest duration (s) of a feed change |dv| under tangential limits A, J (vectorised)."""
    dv = np.abs(np.asarray(dv, dtype=float))
    return np.maximum(ACC_PEAK * dv / a_max, np.sqrt(JERK_PEAK * dv / j_max))


def transition_distance(v0, v1, a_max, j_max):
    """Arc length (mm) covered by the shortest transition v0 -> v1 (vectorised)."""
    v0 = np.asarray(v0, dtype=float)
    v1 = np.asarray(v1, dtype=float)
    return 0.5 * (v0 + v1) * transition_time(v1 - v0, a_max, j_max)


def h_shape(tau):
    """h(tau) of the module docstring (tau clipped to [0, 1])."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau**3 * (10.0 + tau * (-15.0 + 6.0 * tau))


def hint_shape(tau):
    """Integral of h from 0 to tau (tau clipped to [0, 1])."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau**4 * (2.5 + tau * (-3.0 + tau))


@dataclass(frozen=True, eq=False)
class SegmentProfiles:
    """Per-piece feed profiles of a paper-000 plan (the data the FPGA stage consumes).

    A piece covers the arc-length interval ``[s_start, s_start + length]`` of the path
    and the time interval ``[t_start, t_start + t_acc + t_cruise + t_dec]``. The
    variable planner makes one piece per path segment (``seg_first == seg_last == k``);
    the constant planner one piece for the whole path. Within a piece (local time t):

        0 <= t < t_acc:            v = v_start + (v_cruise - v_start) h(t / t_acc)
        t_acc <= t < t_acc+t_cruise: v = v_cruise
        then, for t_dec:           v = v_cruise + (v_end - v_cruise) h(t' / t_dec)

    with h the quintic smoothstep of the module docstring. Consecutive pieces share
    their junction feed (``v_end[m] == v_start[m+1]``); acceleration and jerk are zero
    at every phase boundary. Shapes: every array is (m,); feeds mm/s (deg/s on a
    rotary-only path), times s, lengths mm.
    """

    planner: str
    seg_first: np.ndarray
    seg_last: np.ndarray
    s_start: np.ndarray
    length: np.ndarray
    t_start: np.ndarray
    v_start: np.ndarray
    v_cruise: np.ndarray
    v_end: np.ndarray
    t_acc: np.ndarray
    t_cruise: np.ndarray
    t_dec: np.ndarray
    shape: str = "quintic-smoothstep (v: 5th order, a: 4th order, jerk-bounded)"

    @property
    def n_pieces(self) -> int:
        return int(self.v_start.shape[0])

    @property
    def duration_s(self) -> float:
        """End time of the last piece."""
        if self.n_pieces == 0:
            return 0.0
        return float(self.t_start[-1] + self.t_acc[-1] + self.t_cruise[-1] + self.t_dec[-1])

    def acc_coef(self) -> np.ndarray:
        """(m, 2, 5) power-basis coefficients of a(t) in local phase time (s).

        ``[:, 0]`` is the acceleration phase, ``[:, 1]`` the deceleration phase:
        a(t) = sum_i c_i t^i = dv (30 t^2/T^3 - 60 t^3/T^4 + 30 t^4/T^5); zero for T = 0.
        """
        out = np.zeros((self.n_pieces, 2, 5))
        for ph, (dv, T) in enumerate(
            ((self.v_cruise - self.v_start, self.t_acc), (self.v_end - self.v_cruise, self.t_dec))
        ):
            ok = T > 0
            Ts = np.where(ok, T, 1.0)
            out[:, ph, 2] = np.where(ok, 30.0 * dv / Ts**3, 0.0)
            out[:, ph, 3] = np.where(ok, -60.0 * dv / Ts**4, 0.0)
            out[:, ph, 4] = np.where(ok, 30.0 * dv / Ts**5, 0.0)
        return out

    def pos_coef(self) -> np.ndarray:
        """(m, 3, 7) power-basis coefficients of s(t) (mm) in local phase time (s).

        Phases: acceleration, cruise, deceleration; c_0 is the arc length at the phase
        start, c_1 its feed; s(t) = c_0 + v0 t + dv (5/2 t^4/T^3 - 3 t^5/T^4 + t^6/T^5).
        """
        t0, s0, v0, dv, T = self._phases()
        ok = T > 0
        Ts = np.where(ok, T, 1.0)
        c = np.zeros((t0.size, 7))
        c[:, 0], c[:, 1] = s0, v0
        c[:, 4] = np.where(ok, 2.5 * dv / Ts**3, 0.0)
        c[:, 5] = np.where(ok, -3.0 * dv / Ts**4, 0.0)
        c[:, 6] = np.where(ok, dv / Ts**5, 0.0)
        return c.reshape(self.n_pieces, 3, 7)

    def phases(self):
        """Flattened phases (3m,) in time order: start time, start s, start feed, dv, duration."""
        return self._phases()

    def _phases(self):
        """Flattened phases: start time, start s, v at start, dv, duration (3m,)."""
        m = self.n_pieces
        d_acc = 0.5 * (self.v_start + self.v_cruise) * self.t_acc
        d_cru = self.v_cruise * self.t_cruise
        t0 = np.stack(
            [self.t_start, self.t_start + self.t_acc, self.t_start + self.t_acc + self.t_cruise], axis=1
        ).reshape(3 * m)
        s0 = np.stack([self.s_start, self.s_start + d_acc, self.s_start + d_acc + d_cru], axis=1).reshape(3 * m)
        v0 = np.stack([self.v_start, self.v_cruise, self.v_cruise], axis=1).reshape(3 * m)
        dv = np.stack([self.v_cruise - self.v_start, np.zeros(m), self.v_end - self.v_cruise], axis=1).reshape(3 * m)
        T = np.stack([self.t_acc, self.t_cruise, self.t_dec], axis=1).reshape(3 * m)
        return t0, s0, v0, dv, T

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Arc length s (mm), feed v (mm/s) and tangential acceleration a (mm/s²) at times t (K,)."""
        t = np.asarray(t, dtype=float)
        t0, s0, v0, dv, T = self._phases()
        i = np.clip(np.searchsorted(t0, t, side="right") - 1, 0, t0.size - 1)
        Ti = T[i]
        lt = np.clip(t - t0[i], 0.0, Ti)
        Ts = np.where(Ti > 0, Ti, 1.0)
        tau = np.where(Ti > 0, lt / Ts, 1.0)
        s = s0[i] + v0[i] * lt + dv[i] * Ti * hint_shape(tau)
        v = v0[i] + dv[i] * h_shape(tau)
        a = np.where(Ti > 0, dv[i] / Ts * 30.0 * tau**2 * (1.0 - tau) ** 2, 0.0)
        return s, v, a


def build_profiles(planner: str, seg_first, seg_last, s_start, length, w0, c, w1, a_t, j_t) -> SegmentProfiles:
    """Profiles of pieces with junction feeds w0 -> cruise c -> w1 under limits (a_t, j_t).

    Every piece must be feasible (transition distances <= length); the cruise time
    takes the remaining length so that each piece covers its length exactly.
    """
    w0, c, w1 = (np.asarray(x, dtype=float) for x in (w0, c, w1))
    length = np.asarray(length, dtype=float)
    t_acc = transition_time(c - w0, a_t, j_t)
    t_dec = transition_time(w1 - c, a_t, j_t)
    d = 0.5 * (w0 + c) * t_acc + 0.5 * (c + w1) * t_dec
    rest = np.maximum(length - d, 0.0)
    t_cru = np.where(c > 0, rest / np.where(c > 0, c, 1.0), 0.0)
    dur = t_acc + t_cru + t_dec
    t_start = np.concatenate(([0.0], np.cumsum(dur)[:-1]))
    return SegmentProfiles(
        planner=planner,
        seg_first=np.asarray(seg_first, dtype=np.int64),
        seg_last=np.asarray(seg_last, dtype=np.int64),
        s_start=np.asarray(s_start, dtype=float),
        length=np.asarray(length, dtype=float),
        t_start=t_start,
        v_start=np.asarray(w0, dtype=float),
        v_cruise=np.asarray(c, dtype=float),
        v_end=np.asarray(w1, dtype=float),
        t_acc=t_acc,
        t_cruise=t_cru,
        t_dec=t_dec,
    )


def stretch_to_period(prof: SegmentProfiles, dt_s: float) -> SegmentProfiles:
    """The same profile slowed uniformly so that its duration is a whole number of periods.

    Feeds are divided and durations multiplied by f = K dt / T >= 1 (K = ceil(T / dt)),
    so distances are unchanged and feed, acceleration and jerk only decrease.
    """
    T = prof.duration_s
    if T <= 0.0:
        return prof
    k = max(1, math.ceil(T / dt_s - 1e-9))
    f = k * dt_s / T
    if f < 1.0:  # T a hair above k*dt: one more period
        k += 1
        f = k * dt_s / T
    t_acc, t_cru, t_dec = prof.t_acc * f, prof.t_cruise * f, prof.t_dec * f
    dur = t_acc + t_cru + t_dec
    t_start = np.concatenate(([0.0], np.cumsum(dur)[:-1]))
    return SegmentProfiles(
        planner=prof.planner,
        seg_first=prof.seg_first,
        seg_last=prof.seg_last,
        s_start=prof.s_start,
        length=prof.length,
        t_start=t_start,
        v_start=prof.v_start / f,
        v_cruise=prof.v_cruise / f,
        v_end=prof.v_end / f,
        t_acc=t_acc,
        t_cruise=t_cru,
        t_dec=t_dec,
        shape=prof.shape,
    )


def n_periods(prof: SegmentProfiles, dt_s: float) -> int:
    """Number of sample periods of a profile already stretched to a whole number of them."""
    return int(round(prof.duration_s / dt_s))

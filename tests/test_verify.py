"""verify: closed-form finite differences, rest padding, NaN, reports."""

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose

from cnc_interp.constants import VERIFY_RATIO_SLACK
from cnc_interp.errors import MachineError
from cnc_interp.machine.model import Machine
from cnc_interp.plan.trajectory import Trajectory
from cnc_interp.plan.verify import verify, verify_arrays


def traj(q, dt, axes):
    q = np.asarray(q, dtype=float).reshape(len(q), -1)
    k = q.shape[0]
    return Trajectory(
        axes=axes,
        dt_s=dt,
        t=np.arange(k) * dt,
        s=np.zeros(k),
        feed=np.zeros(k),
        q=q,
        line=np.zeros(k, dtype=int),
        planner="test",
    )


def test_cubic_closed_form():
    # q = c t^3 on k = 0..K-1, padded with 3 held copies each side. Interior:
    # v_k = c (3k^2 - 3k + 1) dt^2, a_k = 6 c (k - 1) dt, j_k = 6 c. The worst values
    # come from the stop after the last sample (held copies), also closed form.
    dt, c, K = 0.01, 2.0, 50
    t = np.arange(K) * dt
    q = c * t**3
    r = verify_arrays(q, dt, 1.0, 1.0, 1.0)
    v_last = c * (3 * (K - 1) ** 2 - 3 * (K - 1) + 1) * dt**2
    assert_allclose(r.values[0, 0], v_last, rtol=1e-9)
    assert r.where[0, 0] == K - 1
    # acceleration: largest magnitude is the braking step right after the end: a = -v_last/dt
    assert_allclose(r.values[0, 1], v_last / dt, rtol=1e-9)
    assert r.where[0, 1] == K
    # jerk: the first held sample after the end: (q_K - 3q_{K-1} + 3q_{K-2} - q_{K-3}) / dt^3
    qp = np.concatenate([q, [q[-1]] * 3])
    jK = (qp[K] - 3 * qp[K - 1] + 3 * qp[K - 2] - qp[K - 3]) / dt**3
    assert_allclose(r.values[0, 2], abs(jK), rtol=1e-9)
    assert r.where[0, 2] == K
    # interior jerk is 6c exactly: verify a padded-by-design cubic with no end effects
    interior = verify_arrays(np.concatenate([np.zeros(3), q]), dt, 1, 1, 1e9)
    assert interior.values[0, 2] >= 6 * c * (1 - 1e-9)


def test_smooth_rest_to_rest_within_limits_and_exact_ratio():
    # quintic rest-to-rest q(t) = D (10 u^3 - 15 u^4 + 6 u^5); known peak v, a, j
    D, T, dt = 10.0, 1.0, 1e-3
    t = np.arange(int(round(T / dt)) + 1) * dt
    u = t / T
    q = D * (10 * u**3 - 15 * u**4 + 6 * u**5)
    vpk, apk, jpk = 1.875 * D / T, 10 / np.sqrt(3) * D / T**2, 60 * D / T**3
    r = verify_arrays(q, dt, vpk, apk, jpk, axes="X")
    # backward differences average over up to 3 dt: slightly under the continuous peaks
    assert r.ok
    assert_allclose(r.ratios[0], [1, 1, 1], rtol=1e-2)
    tight = verify_arrays(q, dt, vpk * 0.9, apk, jpk, axes="X")
    assert not tight.ok and tight.worst()[1] == "velocity"


def test_rest_padding_catches_jump_start():
    dt = 1e-3
    # a plan whose first sample is already moving: 0, then constant velocity 1 mm/s
    q = np.arange(100) * dt * 1.0
    r = verify_arrays(q, dt, 2.0, 1e9, 1e12)
    assert r.ok
    # the held position before q[0] means v jumps 0 -> 1 in one step: a = 1/dt, j = 1/dt^2
    assert_allclose(r.values[0, 1], 1 / dt, rtol=1e-9)
    assert_allclose(r.values[0, 2], 1 / dt**2, rtol=1e-6)
    strict = verify_arrays(q, dt, 2.0, 10.0, 1e12)
    assert not strict.ok and strict.ratios[0, 1] > 1
    # and a plan that does not start where the held position is: shift is a step in v
    r2 = verify_arrays(np.array([0.0, 0.0, 5.0, 5.0]), dt, 1.0, 1.0, 1.0)
    assert r2.where[0, 0] == 2 and not r2.ok


def test_slack_boundary():
    dt = 0.5
    q = np.array([0.0, 0.0, 1.0, 1.0])
    vmax = 2.0  # v = 1/0.5 = 2 exactly
    assert verify_arrays(q, dt, vmax, 1e9, 1e9).ok
    assert verify_arrays(q, dt, vmax * (1 - 10 * VERIFY_RATIO_SLACK), 1e9, 1e9).ok is False


def test_nan_detected():
    q = np.zeros((10, 2))
    q[4, 1] = np.nan
    r = verify_arrays(q, 1e-3, 1, 1, 1, axes="XY")
    assert r.nan_found and not r.ok and r.where[1, 0] == 4
    d = r.to_dict()
    json.dumps(d, allow_nan=False)
    assert d["axes"]["Y"]["velocity"]["ratio"] is None
    assert "NaN" in r.format()


def test_verify_matches_machine_axes_by_letter():
    m = Machine(name="m", axes="XYZ", vmax=[1, 2, 3], amax=[10, 20, 30], jmax=[100, 200, 300], dt_s=0.01)
    tr = traj(np.zeros((5, 2)), 0.01, "ZX")
    r = verify(tr, m)
    assert_allclose(r.limits[:, 0], [3, 1])
    assert r.ok and r.worst_ratio == 0.0
    with pytest.raises(MachineError, match="axis B"):
        verify(traj(np.zeros((5, 1)), 0.01, "B"), m)


def test_report_format_and_dict():
    dt = 1e-3
    rng = np.random.default_rng(0)
    q = np.cumsum(np.cumsum(np.cumsum(rng.normal(size=(500, 3)), axis=0), axis=0), axis=0) * 1e-9
    r = verify_arrays(q, dt, 10.0, 100.0, 1000.0, axes="XYZ")
    d = r.to_dict()
    s = json.dumps(d, allow_nan=False)
    assert json.loads(s)["ok"] == r.ok
    assert set(d["axes"]) == {"X", "Y", "Z"}
    text = r.format()
    assert text.splitlines()[0].split()[0] == "axis" and len(text.splitlines()) == 5
    # vectorised result equals the plain stencil formula
    qp = np.concatenate([np.repeat(q[:1], 3, 0), q, np.repeat(q[-1:], 3, 0)])
    j = (qp[3:] - 3 * qp[2:-1] + 3 * qp[1:-2] - qp[:-3]) / dt**3
    assert_allclose(r.values[:, 2], np.abs(j).max(axis=0), rtol=1e-6)


def test_empty_and_single_sample():
    r = verify_arrays(np.zeros((1, 2)), 1e-3, 1, 1, 1)
    assert r.ok and r.worst_ratio == 0.0
    r0 = verify_arrays(np.zeros((0, 2)), 1e-3, 1, 1, 1)
    assert r0.ok


def test_a_report_mid_stream_leaves_the_stream_as_it_was():
    """``StreamVerifier.report`` can be asked at any block (a batch keeps planning past a
    violation): the final report is the whole array's, start check included."""
    from cnc_interp.plan.verify import StreamVerifier

    rng = np.random.default_rng(3)
    q = np.cumsum(np.cumsum(rng.normal(size=(500, 2)), axis=0), axis=0) * 1e-6
    q[0] += 5e-6  # off the start by more than the tolerance
    whole = verify_arrays(q, 1e-3, 1.0, 2.0, 3.0, axes="XY", start=np.zeros(2))
    sv = StreamVerifier(1e-3, 1.0, 2.0, 3.0, "XY", start=np.zeros(2))
    for a in range(0, q.shape[0], 64):
        sv.add(q[a : a + 64])
        sv.report()
    rep = sv.report()
    assert_allclose(rep.ratios, whole.ratios, rtol=1e-15)
    assert np.array_equal(rep.where, whole.where)
    assert not rep.start_ok and not whole.start_ok and rep.ok == whole.ok is False

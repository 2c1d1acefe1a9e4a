"""A discrete-time K drives the tracking law as a sampled law at its own rate (issue 19, item 1)."""

from __future__ import annotations

import pickle

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin import (
    DiscreteTrackingController,
    QuinticReference,
    TrackingController,
    hinf_fl_controller,
    ncfsyn,
    simulate,
)
from rrr_pin.robust.loopshaping import fl_plant, lag_weight

RATE = 1000.0


@pytest.fixture(scope="module")
def Kc():
    return ncfsyn(fl_plant(45.0, 1), lag_weight()).K


def _reference(robot):
    q0 = np.clip(robot.neutral(), robot.lower, robot.upper)
    return QuinticReference(q0, q0 + 0.3, 0.5)


def test_discrete_k_is_a_sampled_law(rrr, Kc):
    law = hinf_fl_controller(rrr, control.c2d(Kc, 1.0 / RATE, "tustin"))
    assert isinstance(law, DiscreteTrackingController)
    assert law.rate == RATE and law.nx == 3 * Kc.nstates


def test_step_equals_eq_8(rrr, Kc):
    """One step against eq. (8) written out, its torque by RNEA (the law uses CRBA + NLE)."""
    Kd = control.c2d(Kc, 1.0 / RATE, "tustin")
    law = hinf_fl_controller(rrr, Kd, lam=45.0)
    rng = np.random.default_rng(19)
    q, qd, r, rd, rdd = (rng.uniform(-1, 1, 3) for _ in range(5))
    x = rng.standard_normal(law.nx)
    tau, xn = law.step(0.0, q, qd, r, rd, rdd, x)
    A, B, C, D = (np.kron(np.eye(3), np.asarray(M)) for M in (Kd.A, Kd.B, Kd.C, Kd.D))
    # kron(I, .) orders the states joint by joint, as scipy.linalg.block_diag does
    e = r - q
    y = C @ x + D @ e
    taubar = rdd + 2 * 45.0 * (rd - qd) + 45.0 ** 2 * (e + y)
    # two algorithms on torques of O(1e3) N m: round-off
    assert_allclose(tau, rrr.inverse_dynamics(q, qd, taubar), rtol=1e-12, atol=1e-9)
    assert_allclose(xn, A @ x + B @ e, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("engine", ["python", "compiled"])
def test_discrete_k_runs_as_the_sampled_continuous_law(rrr, Kc, engine):
    """c2d(K) outside equals the continuous law sampled inside (Tustin, python-control both)."""
    if engine == "compiled":
        pytest.importorskip("rrr_pin.sim._rollout")
    ref = _reference(rrr)
    cont = hinf_fl_controller(rrr, Kc)
    disc = hinf_fl_controller(rrr, control.c2d(Kc, 1.0 / RATE, "tustin"))
    a = simulate(rrr, cont, ref, 0.5, rate=RATE, engine="python")
    b = simulate(rrr, disc, ref, 0.5, engine=engine)
    assert b.info["engine"] == engine
    # the same arithmetic, the states ordered alike: round-off only
    assert_allclose(b.q, a.q, rtol=0, atol=1e-12)


def test_discrete_ncfsyn_plugs_in(rrr):
    Ts = 1.0 / RATE
    res = ncfsyn(control.c2d(fl_plant(45.0, 1), Ts, "tustin"),
                 control.c2d(lag_weight(), Ts, "tustin"))
    law = hinf_fl_controller(rrr, res.K)
    tr = simulate(rrr, law, _reference(rrr), 0.2, engine="python")
    assert tr.info["rate_hz"] == RATE
    assert np.all(np.isfinite(tr.q))


def test_rate_mismatch_refused_by_name(rrr, Kc):
    law = hinf_fl_controller(rrr, control.c2d(Kc, 1.0 / RATE, "tustin"), name="hinf_d")
    with pytest.raises(ValueError, match=r"law 'hinf_d' is sampled at 1000 Hz, rate = 500"):
        simulate(rrr, law, _reference(rrr), 0.1, rate=500.0)


def test_tracking_controller_refuses_discrete_k(rrr, Kc):
    with pytest.raises(ValueError, match="discrete-time system .* hinf_fl_controller"):
        TrackingController(rrr, 45.0, control.c2d(Kc, 1e-3))


@pytest.mark.parametrize("K, match", [
    (control.ss([[0.5]], [[1.0]], [[1.0]], [[0.0]], True), "sampling time dt > 0"),
    (control.ss([[1.5]], [[1.0]], [[1.0]], [[0.0]], 1e-3), r"unstable poles \(\|z\| > 1\)"),
], ids=["no-dt", "unstable"])
def test_bad_discrete_k(rrr, K, match):
    with pytest.raises(ValueError, match=match):
        DiscreteTrackingController(rrr, 45.0, K)


def test_pickles(rrr, Kc):
    law = hinf_fl_controller(rrr, control.c2d(Kc, 1.0 / RATE, "tustin"))
    back = pickle.loads(pickle.dumps(law))
    assert type(back) is DiscreteTrackingController and back.rate == RATE
    for a, b in zip(back.discrete_matrices(), law.discrete_matrices(), strict=True):
        assert_allclose(a, b, rtol=0, atol=0)

import control
import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from rrr_pin.controllers import TrackingController, fl_controller, hinf_fl_controller
from rrr_pin.dynamics import load_robot

# The paper's eq. (18), typed from the paper (used here only as a test input).
K18 = control.tf([47.40, 47.40 * (134.75 + 12.17), 47.40 * 134.75 * 12.17],
                 [1.0, 513.37 + 0.19, 513.37 * 0.19])


@pytest.fixture(scope="module")
def rrr():
    return load_robot("rrr")


def test_on_reference_the_law_is_inverse_dynamics(rrr):
    # With q = r, qd = rd and y = 0 the law must give RNEA(q, qd, rdd): CRBA + NLE on one side,
    # the recursive Newton-Euler algorithm on the other.
    rng = np.random.default_rng(5)
    for ctrl in (fl_controller(rrr), hinf_fl_controller(rrr, K18)):
        for _ in range(20):
            q, qd, qdd = rng.uniform(-3, 3, (3, 3))
            tau = ctrl.torque(q, qd, q, qd, qdd, np.zeros(3))
            expected = pin.rnea(rrr.model, rrr.data, q, qd, qdd)
            assert_allclose(tau, expected, rtol=1e-12, atol=1e-9)  # round-off of 1e2 N m terms


def test_feedback_terms(rrr):
    # Off the reference: tau - tau_ff = M (2 lam (rd - qd) + lam^2 (e + y)), eq. (10).
    lam = 100.0
    ctrl = fl_controller(rrr, lam)
    q, qd = np.array([0.1, 0.2, 0.3]), np.array([0.0, 0.5, -0.5])
    r, rd, rdd = q + 0.01, qd + 0.1, np.zeros(3)
    y = np.array([0.001, -0.002, 0.0])
    tau = ctrl.torque(q, qd, r, rd, rdd, y)
    taubar = 2 * lam * (rd - qd) + lam**2 * (r - q + y)
    expected = rrr.M(q) @ taubar + rrr.V(q, qd) + rrr.G(q)
    assert_allclose(tau, expected, rtol=1e-12)


def test_siso_K_is_copied_on_the_diagonal(rrr):
    ctrl = hinf_fl_controller(rrr, K18)
    assert ctrl.nx == 6
    K = control.ss(*ctrl.continuous_matrices())
    for w in (0.1, 10.0, 500.0):
        expected = complex(K18(1j * w))
        assert_allclose(K(1j * w), expected * np.eye(3), rtol=1e-10, atol=1e-12)


def test_tustin_keeps_dc_gain(rrr):
    # Bilinear discretization maps s = 0 to z = 1: the DC gain is preserved exactly.
    ctrl = hinf_fl_controller(rrr, K18)
    Ad, Bd, Cd, Dd = ctrl.discretize(1000.0)
    dc = Cd @ np.linalg.solve(np.eye(len(Ad)) - Ad, Bd) + Dd
    assert_allclose(dc, float(control.dcgain(K18)) * np.eye(3), rtol=1e-9)


@pytest.mark.parametrize("kwargs,message", [
    ({"lam": 0.0}, "lam must be a positive"),
    ({"lam": float("nan")}, "lam must be a positive"),
    ({"lam": 45.0, "K": control.ss(np.eye(2) * -1, np.eye(2), np.eye(2), np.zeros((2, 2)))},
     "K must be SISO or 3 x 3"),
    ({"lam": 45.0, "K": control.tf([1.0], [1.0, -1.0])}, "unstable poles"),
    ({"lam": 45.0, "K": control.tf([1.0], [1.0, 0.5], 0.001)}, "continuous-time"),
], ids=["lam0", "lam-nan", "K-2x2", "K-unstable", "K-discrete"])
def test_bad_inputs(rrr, kwargs, message):
    with pytest.raises(ValueError, match=message):
        TrackingController(nominal=rrr, **kwargs)


def test_bad_rate(rrr):
    with pytest.raises(ValueError, match="rate must be a positive"):
        hinf_fl_controller(rrr, K18).discretize(-5.0)

"""Linear analysis (margins, robstab) on a closed chain, against closed forms and Pinocchio."""

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from rrr_pin.control.analysis import loop_at_input, loop_margins, parametric_loop
from rrr_pin.control.closed_chain import closed_chain_fl, closed_chain_pd
from rrr_pin.model.dynamics import load_robot
from rrr_pin.robust.mu import closed_loop_matrix

LAM = 100.0


@pytest.fixture(scope="module")
def fivebar():
    return load_robot("fivebar")


def _q0(chain):
    return chain.neutral() + np.array([0.05, -0.04])


def test_chain_fl_loop_without_gravity_is_the_shaped_double_integrator():
    # g = 0, model exact: tau = M_r taubar, qdd_a = M_r^-1 tau, so L(s) = c(s) I with
    # c(s) = (2 lam s + lam^2) / s^2 (as for the serial arm); margins in closed form.
    chain = load_robot("fivebar", gravity=0.0)
    q0 = _q0(chain)
    L = loop_at_input(closed_chain_fl(chain, LAM), chain, q0)
    for w in (3.0, 100.0, 2000.0):
        s = 1j * w
        # central differences at h = 1e-5 (law) and of the chain's dynamics: 1e-6 relative
        assert_allclose(L(s), (2 * LAM * s + LAM**2) / s**2 * np.eye(2), rtol=1e-6, atol=1e-7)
    m = loop_margins(L)
    wc = LAM * np.sqrt(2 + np.sqrt(5))
    pm = np.degrees(np.arctan(2 * wc / LAM))
    assert_allclose(m.crossover, wc, rtol=1e-4)
    assert_allclose(m.phase, pm, rtol=1e-4)


def test_chain_plant_linearization_equals_constraint_dynamics(fivebar):
    # A second algorithm: Pinocchio's constraintDynamics on the full tree, differenced with a
    # 10x larger step, against the loop's A, B (the reduced model M_r^-1 (tau - h_r)).
    chain = fivebar
    q0 = _q0(chain)
    n = chain.nq
    law = closed_chain_pd(chain)
    L = loop_at_input(law, chain, q0)
    tau0 = chain.G(q0)
    act = list(chain.actuated)

    def qdd(qa, tau):
        q = chain.close(qa)
        return chain.constrained_acceleration(q, np.zeros(chain.model.nv),
                                              chain.actuation(tau))[act]

    h = 1e-4
    dq = np.column_stack([(qdd(q0 + h * e, tau0) - qdd(q0 - h * e, tau0)) / (2 * h)
                          for e in np.eye(n)])
    dtau = np.column_stack([(qdd(q0, tau0 + e) - qdd(q0, tau0 - e)) / 2 for e in np.eye(n)])
    chain.close(q0)
    # rows n..2n of A (plant accelerations) and B; constraintDynamics' proximal accuracy
    # (6e-11 at mu = 1e-4) over the 1e-4 step and its O(h^2) error: 1e-5 of the largest entry
    assert_allclose(L.A[n:2 * n, :n], dq, atol=1e-5 * np.abs(dq).max())
    assert_allclose(L.B[n:2 * n], dtau, atol=1e-8 * np.abs(dtau).max())
    # FL on the exact model: the gravity stiffness cancels, closed loop (s + lam)^2 per joint
    Lfl = loop_at_input(closed_chain_fl(chain, LAM), chain, q0)
    # a double pole moves by sqrt(perturbation): 1e-3 relative
    assert_allclose(np.linalg.eigvals(Lfl.A - Lfl.B @ Lfl.C), -LAM, rtol=1e-3)


def _perturbed_chain_closed_loop(law, q, factors):
    """FL closed loop on the chain with inertial factors, written afresh from crba and S."""
    chain = law.nominal
    model = chain.model.copy()
    for j in range(1, model.njoints):
        Y = model.inertias[j]
        J, R = np.linalg.eigh(Y.inertia)
        J = J * [factors.get((j, k), 1.0) for k in range(3)]
        Y.mass = Y.mass * factors.get((j, None), 1.0)
        Y.inertia = (R * J) @ R.T
        model.inertias[j] = Y

    def mats(m, qa):
        d = m.createData()
        qf = chain.close(qa)
        S, _ = chain.S(qf)
        return S.T @ pin.crba(m, d, qf) @ S, S.T @ pin.computeGeneralizedGravity(m, d, qf)

    h, n = 1e-4, chain.nq

    def parts(m):
        Gq = np.column_stack([(mats(m, q + h * e)[1] - mats(m, q - h * e)[1]) / (2 * h)
                              for e in np.eye(n)])
        M = mats(m, q)[0]
        return 0.5 * (M + M.T), Gq

    (Mh, Gh), (M, G) = parts(chain.model), parts(model)
    chain.close(q)
    acc = np.linalg.solve(M, -LAM**2 * Mh + Gh - G)
    return np.block([[np.zeros((n, n)), np.eye(n)], [acc, np.linalg.solve(M, -2 * LAM * Mh)]])


def test_chain_parametric_lft_closes_to_the_perturbed_chain(fivebar):
    law = closed_chain_fl(fivebar, LAM)
    q0 = _q0(fivebar)
    loop = parametric_loop(law, q0, tol=0.2)
    model = fivebar.model
    index = {}
    for j in range(1, model.njoints):
        index[f"{model.names[j]}.mass"] = (j, None)
        for k in range(3):
            index[f"{model.names[j]}.J{k + 1}"] = (j, k)
    delta = np.random.default_rng(7).uniform(-1.5, 1.5, len(loop.names))
    Delta = np.diag(np.repeat(delta, [n for _, n in loop.blocks]))
    factors = {index[name]: 1 + 0.2 * d for name, d in zip(loop.names, delta, strict=True)}
    expect = np.sort_complex(np.linalg.eigvals(_perturbed_chain_closed_loop(law, q0, factors)))
    got = np.sort_complex(np.linalg.eigvals(closed_loop_matrix(loop.M, Delta)))
    # both sides difference dG_r/dq_a (steps 1e-5 and 1e-4): 1e-5 relative
    assert_allclose(got, expect, rtol=1e-5)
    assert len(loop.names) + len(loop.dropped) == 4 * (model.njoints - 1)


@pytest.mark.slow
def test_chain_parametric_margin_brackets_the_sampled_vertices(fivebar):
    from rrr_pin.control.analysis import parametric_margin, sampled_margin

    law = closed_chain_fl(fivebar, LAM)
    q0 = _q0(fivebar)
    loop, r = parametric_margin(law, q0, omega=np.concatenate([[0], np.logspace(0, 4, 10)]))
    # scaled perturbed chains (crba through S, no LFT), bisected to 1e-4
    alpha, _ = sampled_margin(law, loop, samples=16)
    assert r.margin_lower <= alpha * (1 + 1e-4)

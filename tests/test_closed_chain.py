"""Parallel mechanisms: MJCF generator, loop closure, reduced dynamics, Pinocchio 4.1 traps.

Independent references: Pinocchio's ``constraintDynamics`` (a second algorithm) for the
reduced accelerations; a Lagrangian of the 5-bar in its two actuated angles written here from
the geometry alone; the closed-form kinematics of rrr_pin.model.mechanisms (no Pinocchio) for
the loaded model's loop closure.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from rrr_pin import cli
from rrr_pin.model.closed_chain import (
    ClosedChain,
    LoopClosureError,
    SingularConfiguration,
    load_closed_chain,
)
from rrr_pin.model.dynamics import load_robot
from rrr_pin.model.mechanisms import (
    DeltaParams,
    FiveBarParams,
    MechanismError,
    delta_fk,
    delta_ik,
    fivebar_fk,
    fivebar_ik,
    mjcf_from_params,
)

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def fivebar():
    return load_closed_chain("fivebar")


@pytest.fixture(scope="module")
def delta():
    return load_closed_chain("delta")


def _random_state(chain, rng, spread=0.08):
    """A closed state at a random tip/platform point within ``spread`` [m] of home."""
    P = chain.params
    if isinstance(P, FiveBarParams):
        qa = fivebar_ik(P, np.array([P.home_x, P.home_z]) + rng.uniform(-spread, spread, 2))
    else:
        qa = delta_ik(P, np.array([0.0, 0.0, P.home_z]) + rng.uniform(-spread, spread, 3))
    q = chain.close(qa, seed=chain.home)
    return q, chain.velocity(q, rng.standard_normal(chain.nq))


@pytest.mark.parametrize("name", ["fivebar", "delta"])
def test_committed_mjcf_is_generator_output(name, tmp_path):
    assert cli.main(["mjcf", name, "--out", str(ROOT / "mjcf" / f"{name}.xml"), "--check"]) == 0
    stale = tmp_path / "stale.xml"
    stale.write_text("<mujoco/>")
    assert cli.main(["mjcf", name, "--out", str(stale), "--check"]) == 1


def test_load_robot_reports_joints_and_constraints():
    chain = load_robot("fivebar")
    assert isinstance(chain, ClosedChain)
    assert chain.joint_names == ["qa1", "qa2"]
    assert chain.passive_names == ["qp1", "qp2"]
    assert chain.constraint_names == ["loop"]
    delta = load_robot("delta")
    assert delta.joint_names == ["qa1", "qa2", "qa3"]
    assert len(delta.passive_names) == 9 and delta.constraint_names == ["loop1", "loop2", "loop3"]
    # The planar loop's out-of-plane row (world y) is identically zero and dropped.
    assert list(chain.rows) == [0, 2]


@pytest.mark.parametrize("name", ["fivebar", "delta"])
def test_reduced_accelerations_equal_constraint_dynamics(name, fivebar, delta):
    chain = {"fivebar": fivebar, "delta": delta}[name]
    rng = np.random.default_rng(7)
    for _ in range(5):
        q, qd = _random_state(chain, rng)
        tau = 5.0 * rng.standard_normal(chain.nq)
        Mr, h, S = chain.reduced_terms(q, qd)
        qdd_a = np.linalg.solve(Mr, tau - h)
        full = chain.constrained_acceleration(q, qd, chain.actuation(tau))
        # 1e-10 rad/s^2: the bound; both are direct solves (KKT vs projection).
        assert_allclose(qdd_a, full[list(chain.actuated)], rtol=0, atol=1e-10)
        assert_allclose(chain.jacobian(q) @ qd, 0.0, atol=1e-12)


def _fivebar_lagrangian(P: FiveBarParams, qa, g=9.8):
    """M_r and G_r of the 5-bar from T = 1/2 qd^T M_r qd and U, by the chain rule by hand."""
    t1, t2 = qa
    A = [np.array([-P.d / 2, 0.0]), np.array([P.d / 2, 0.0])]
    u = [np.array([np.cos(t), np.sin(t)]) for t in (t1, t2)]
    du = [np.array([-np.sin(t), np.cos(t)]) for t in (t1, t2)]
    E = [A[i] + P.l1 * u[i] for i in range(2)]
    dE = [np.outer(P.l1 * du[i], np.eye(2)[i]) for i in range(2)]  # dE_i/dqa, (2, 2)
    tip = fivebar_fk(P, qa)
    # |tip - E_i|^2 = l2^2 for i = 1, 2: (tip - E_i) . (dtip - dE_i) = 0.
    Arows = np.array([tip - E[0], tip - E[1]])
    rhs = np.array([(tip - E[i]) @ dE[i] for i in range(2)])
    dtip = np.linalg.solve(Arows, rhs)  # (2, 2)
    rho = P.radius
    I1 = P.m1 * (P.l1 ** 2 / 12 + rho ** 2 / 4)  # about the rod's centre, perpendicular
    I2 = P.m2 * (P.l2 ** 2 / 12 + rho ** 2 / 4)
    M = np.zeros((2, 2))
    Gr = np.zeros(2)
    for i in range(2):
        e = np.eye(2)[i]
        M += (I1 + P.m1 * (P.l1 / 2) ** 2) * np.outer(e, e)  # proximal about its base joint
        Gr += P.m1 * g * (P.l1 / 2) * np.cos(qa[i]) * e
        w = tip - E[i]
        dpsi = (w[0] * (dtip - dE[i])[1] - w[1] * (dtip - dE[i])[0]) / P.l2 ** 2  # (2,)
        dc = 0.5 * (dE[i] + dtip)  # distal centre of mass
        M += P.m2 * dc.T @ dc + I2 * np.outer(dpsi, dpsi)
        Gr += P.m2 * g * dc[1]
    return M, Gr


def test_fivebar_reduced_model_equals_lagrangian(fivebar):
    rng = np.random.default_rng(3)
    for _ in range(5):
        q, _ = _random_state(fivebar, rng, spread=0.06)
        qa = q[list(fivebar.actuated)]
        M_ref, G_ref = _fivebar_lagrangian(fivebar.params, qa)
        # Round-off of two exact derivations at ~1 kg m^2 scale entries.
        assert_allclose(fivebar.M(qa), M_ref, rtol=1e-10, atol=1e-12)
        assert_allclose(fivebar.G(qa), G_ref, rtol=1e-10, atol=1e-12)


def test_ik_and_fk_agree_with_the_loaded_loop(fivebar, delta):
    rng = np.random.default_rng(11)
    P5, PD = fivebar.params, delta.params
    tip = fivebar.model.getFrameId("tip1")
    for _ in range(10):
        q, _ = _random_state(fivebar, rng, spread=0.06)
        qa = q[list(fivebar.actuated)]
        p = fivebar_fk(P5, qa)
        assert_allclose(fivebar_ik(P5, p), qa, atol=1e-12)  # same working mode, round-off
        pin.framesForwardKinematics(fivebar.model, fivebar.data, q)
        assert_allclose(fivebar.data.oMf[tip].translation[[0, 2]], p, atol=1e-12)
    for _ in range(10):
        p = np.array([0.0, 0.0, PD.home_z]) + rng.uniform(-0.15, 0.15, 3)
        qa = delta_ik(PD, p)
        assert_allclose(delta_fk(PD, qa), p, atol=1e-12)
        q = delta.close(qa, seed=delta.home)
        assert_allclose(q[9:12], p, atol=1e-10)  # Newton stops at a 1e-12 m gap


def test_type_ii_singularity_is_refused_with_the_condition_number(fivebar):
    P = fivebar.params
    # Both arms opened symmetrically until the elbows are 2 l2 apart: distal links aligned.
    s = np.arcsin((2 * P.l2 - P.d) / (2 * P.l1))
    qa = np.array([np.pi / 2 + s, np.pi / 2 - s]) - np.array([1e-9, -1e-9])
    with pytest.raises(SingularConfiguration, match=r"type-II .*cond\(J_p\) = .* > 10000"):
        fivebar.close(qa, seed=fivebar.home)
    with pytest.raises(LoopClosureError, match="does not close"):
        fivebar.close(qa + np.array([0.1, -0.1]), seed=fivebar.home)


def test_loop_that_cannot_close_is_refused():
    with pytest.raises(MechanismError, match=r"5-bar loop cannot close: .*triangle"):
        FiveBarParams(d=1.0)
    with pytest.raises(MechanismError, match=r"Delta loop cannot close: .*triangle"):
        DeltaParams(R=2.0)
    with pytest.raises(ValueError, match="l1"):
        FiveBarParams(l1=-0.1)


def test_actuator_count_must_equal_mobility(tmp_path):
    text = mjcf_from_params(FiveBarParams()).replace('    <motor name="motor2" joint="qa2"/>\n',
                                                     "")
    path = tmp_path / "underactuated.xml"
    path.write_text(text)
    with pytest.raises(MechanismError, match=r"1 actuator\(s\) \(qa1\) but .* mobility is 2"):
        load_robot(path)


# --- Pinocchio 4.1.0 traps (a future version that changes them fails here) --------------------

def test_trap_constraint_data_reused_after_lcaba_is_corrupt(fivebar):
    rng = np.random.default_rng(5)
    q, qd = _random_state(fivebar, rng)
    tau = fivebar.actuation(rng.standard_normal(2))
    ref = fivebar.constrained_acceleration(q, qd, tau)
    m = fivebar.model
    d, cd = m.createData(), [c.createData() for c in fivebar.constraints]
    prox = pin.ProximalSettings(1e-14, 1e-4, 200)
    pin.initConstraintDynamics(m, d, fivebar.constraints, cd)
    pin.computeJointMinimalOrdering(m, d, fivebar.constraints)
    pin.lcaba(m, d, q, qd, tau, fivebar.constraints, cd, prox)
    d2 = m.createData()
    pin.initConstraintDynamics(m, d2, fivebar.constraints, cd)
    reused = pin.constraintDynamics(m, d2, q, qd, tau, fivebar.constraints, cd, prox)
    assert np.abs(reused - ref).max() > 1e-3  # measured 0.23 rad/s^2 on pin 4.1.0


def test_trap_parser_keeps_the_first_top_level_body(tmp_path):
    text = ('<mujoco><worldbody>'
            '<body name="a"><joint name="ja" type="hinge" axis="0 0 1"/>'
            '<inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/></body>'
            '<body name="b"><joint name="jb" type="hinge" axis="0 0 1"/>'
            '<inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/></body>'
            '</worldbody></mujoco>')
    path = tmp_path / "two.xml"
    path.write_text(text)
    model = pin.buildModelFromMJCF(str(path))
    assert list(model.names) == ["universe", "ja"]


def test_trap_build_models_with_constraints_keyword_raises():
    with pytest.raises(TypeError):
        pin.buildModelsFromMJCF(str(ROOT / "mjcf" / "fivebar.xml"), constraints=True)


def test_trap_planar_contact_3d_has_a_zero_row(fivebar):
    rng = np.random.default_rng(9)
    q, qd = _random_state(fivebar, rng)
    J = fivebar.jacobian(q)
    c = fivebar.constraints[0]
    cd = c.createData()
    pin.computeJointJacobians(fivebar.model, fivebar.data, q)
    Jc = pin.getConstraintJacobian(fivebar.model, fivebar.data, c, cd)
    assert np.abs(Jc[1]).max() == 0.0 and J.shape == (2, 4)
    tau = fivebar.actuation(rng.standard_normal(2))
    ref = fivebar.constrained_acceleration(q, qd, tau)
    m = fivebar.model
    # Pinocchio's default ProximalSettings (mu = 0) cannot invert the singular Delassus.
    d, cds = m.createData(), [c.createData()]
    pin.initConstraintDynamics(m, d, fivebar.constraints, cds)
    bad = pin.constraintDynamics(m, d, q, qd, tau, fivebar.constraints, cds)
    assert not np.isfinite(bad).all()
    # With mu = 1e-4 and one proximal iteration the error is 4e-4; converged iterations fix it.
    d, cds = m.createData(), [c.createData()]
    pin.initConstraintDynamics(m, d, fivebar.constraints, cds)
    one = pin.constraintDynamics(m, d, q, qd, tau, fivebar.constraints, cds,
                                 pin.ProximalSettings(1e-12, 1e-4, 1))
    assert np.abs(one - ref).max() > 1e-6

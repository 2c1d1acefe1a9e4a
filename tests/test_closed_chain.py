"""Parallel mechanisms: MJCF generator, loop closure, reduced dynamics, Pinocchio 4.1 traps.

Independent references: Pinocchio's ``constraintDynamics`` (a second algorithm) for the
reduced accelerations; a Lagrangian of the 5-bar in its two actuated angles written here from
the geometry alone; the closed-form kinematics of rrr_pin.model.mechanisms (no Pinocchio) for
the loaded model's loop closure and forward kinematics; for the 3-RRR, the leg equations
``|E_i - A_i| = l1``, ``|B_i - E_i| = l2`` evaluated here, its singular pose built here from
the geometry (distal lines through the platform centre), and the exact model's tracking error
(zero but for the zero-order hold, first order in the sampling period).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

import rrr_pin
from rrr_pin import cli
from rrr_pin.control.catalog import make_law
from rrr_pin.control.references import study_reference
from rrr_pin.model.closed_chain import (
    COND_LIMIT,
    ClosedChain,
    LoopClosureError,
    SingularConfiguration,
    check_chain_reference,
    load_closed_chain,
)
from rrr_pin.model.dynamics import load_robot
from rrr_pin.model.mechanisms import (
    MECHANISMS,
    DeltaParams,
    FiveBarParams,
    MechanismError,
    ThreeRRRParams,
    adept_point,
    check_mjcf,
    delta_fk,
    delta_ik,
    fivebar_fk,
    mechanism_of,
    mechanism_params,
    mjcf_from_params,
)
from rrr_pin.model.mechanisms.threerrr import threerrr_elbows, threerrr_fk, threerrr_ik

ROOT = Path(__file__).resolve().parents[1]

#: Every registered mechanism kind: the generic tests run on each.
KINDS = list(MECHANISMS)

#: Base joint angles of the 3-RRR (its module docstring), written here again.
THETA = [math.pi / 2 + 2 * math.pi * i / 3 for i in range(3)]


@pytest.fixture(params=KINDS, ids=KINDS)
def chain(request):
    """Every registered mechanism kind in turn (the shared models of tests/conftest.py)."""
    return request.getfixturevalue(request.param)


def _random_state(chain, rng, spread=0.08):
    """A closed state at a random task point within ``spread`` [m, rad] of home's (closed form).

    The 5-bar's tip ``(x, z)``, the Delta's platform ``(x, y, z)``, the 3-RRR's platform pose
    ``(x, z, phi)``; each coordinate uniform in ``[-spread, spread]`` about home's.
    """
    P = chain.params
    kind = mechanism_of(P)
    p = kind.fk(P, chain.neutral())
    qa = kind.ik(P, p + rng.uniform(-spread, spread, p.size))
    q = chain.close(qa, seed=chain.home)
    return q, chain.velocity(q, rng.standard_normal(chain.nq))


def _u(a):
    return np.array([math.cos(a), math.sin(a)])


def _pinocchio_task_point(chain, q):
    """The task point of a closed configuration from Pinocchio's frames alone."""
    pin.framesForwardKinematics(chain.model, chain.data, q)
    oMf = chain.data.oMf
    if chain.name == "fivebar":
        return oMf[chain.model.getFrameId("tip1")].translation[[0, 2]]
    M = oMf[chain.model.getFrameId("platform")]
    if chain.name == "delta":
        return M.translation.copy()
    # 3-RRR: the platform frame's x axis is (cos phi, 0, sin phi) (rotation about -y).
    return np.array([M.translation[0], M.translation[2],
                     math.atan2(M.rotation[2, 0], M.rotation[0, 0])])


@pytest.mark.parametrize("name", KINDS, ids=KINDS)
def test_committed_mjcf_is_generator_output(name, tmp_path):
    params = mechanism_params(name)
    assert check_mjcf(ROOT / "mjcf" / f"{name}.xml", params)
    stale = tmp_path / "stale.xml"
    stale.write_text("<mujoco/>")
    assert not check_mjcf(stale, params)


def test_cli_mjcf_check_exit_codes(tmp_path):
    # The command line's --check is the same check_mjcf (exit 0 up to date, 1 stale).
    assert cli.main(["mjcf", "fivebar", "--out", str(ROOT / "mjcf" / "fivebar.xml"),
                     "--check"]) == 0
    stale = tmp_path / "stale.xml"
    stale.write_text("<mujoco/>")
    assert cli.main(["mjcf", "fivebar", "--out", str(stale), "--check"]) == 1


def test_home_closes_as_the_closed_form_says(chain):
    # A parameter set's home is the closed form's (no Pinocchio; the keyframe holds it to 12
    # decimals); Pinocchio's loop gap there is round-off on ~0.3 m coordinates (a few 1e-17 m
    # measured), so the loader kept it as is.
    home = mechanism_of(chain.params).home(chain.params)
    assert_allclose(chain.home, home, rtol=0, atol=0)
    assert_allclose(chain.residual(home), 0.0, atol=1e-15)
    assert chain.passive_jacobian_cond(home) <= COND_LIMIT


@pytest.mark.parametrize("name", KINDS, ids=KINDS)
def test_perturbed_mechanism_is_closable(name):
    nominal = load_closed_chain(name)
    kind = mechanism_of(nominal.params)
    for k in range(3):
        plant, info = nominal.perturbed(np.random.default_rng([0, k]), rrr_pin.Tolerances())
        factors = info["factors"]
        # every mass (and listed inertia) by 20 %, every listed length by 5 %
        assert set(factors) == ({n for n in vars(nominal.params) if n.startswith("m")}
                                | set(kind.inertias) | set(kind.lengths))
        for n, f in factors.items():
            bound = 0.05 if n in kind.lengths else 0.2
            assert 1.0 - bound <= f <= 1.0 + bound
            assert getattr(plant.params, n) == getattr(nominal.params, n) * f
        # its own closed-form home closes its loop (round-off) away from a singularity
        assert_allclose(plant.residual(kind.home(plant.params)), 0.0, atol=1e-15)
        assert plant.passive_jacobian_cond(plant.home) <= COND_LIMIT
        # and the nominal home's actuated angles close it too (the study's start)
        q = plant.close(nominal.neutral(), seed=plant.home)
        assert np.abs(plant.residual(q)).max() <= 1e-12
        # the same seed draws the same plant
        again, _ = nominal.perturbed(np.random.default_rng([0, k]), rrr_pin.Tolerances())
        assert again.params == plant.params


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


def test_reduced_accelerations_equal_constraint_dynamics(chain):
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


def test_ik_and_fk_agree_with_the_loaded_loop(chain):
    rng = np.random.default_rng(11)
    P = chain.params
    kind = mechanism_of(P)
    for _ in range(10):
        q, _ = _random_state(chain, rng)  # closed by Pinocchio's Newton from home
        qa = q[list(chain.actuated)]
        p = kind.fk(P, qa)
        # same working mode: round-off (the 3-RRR's FK is Newton to 1e-14 m, cond < 2)
        assert_allclose(kind.ik(P, p), qa, rtol=0, atol=1e-12)
        # Newton stops at a 1e-12 m gap; the task point moves by that times cond(J_p) < 30
        assert_allclose(_pinocchio_task_point(chain, q), p, rtol=0, atol=1e-10)


@pytest.mark.parametrize("name", KINDS, ids=KINDS)
def test_actuator_count_must_equal_mobility(name, tmp_path):
    text = mjcf_from_params(mechanism_params(name))
    motors = [m.get("joint") for m in ET.fromstring(text).iter("motor")]
    last = f'    <motor name="motor{len(motors)}" joint="{motors[-1]}"/>\n'
    assert last in text
    path = tmp_path / "underactuated.xml"
    path.write_text(text.replace(last, ""))
    with pytest.raises(MechanismError, match=rf"{len(motors) - 1} actuator\(s\) .* but .* "
                                             rf"mobility is {len(motors)}"):
        load_robot(path)


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


def test_adept_cycle_is_25_305_25_mm():
    P = DeltaParams()
    period = 2.0
    half = period / 2
    corners = adept_point(P, [0.0, 0.2 * half, 0.8 * half, half, period], period)
    # The cycle's own numbers, written here independently: 25 mm up, 305 mm across, down.
    assert_allclose(corners[1] - corners[0], [0.0, 0.0, 0.025], atol=1e-15)
    assert_allclose(corners[2] - corners[1], [0.305, 0.0, 0.0], atol=1e-15)
    assert_allclose(corners[3] - corners[2], [0.0, 0.0, -0.025], atol=1e-15)
    assert_allclose(corners[4], corners[0], atol=1e-15)


def test_delta_study_reference_is_the_inverse_kinematics_of_the_adept_cycle(delta):
    ref = study_reference(delta, 2.0)
    t = ref.times[::7]
    R = ref.sample(t)[0]
    # The spline passes through its IK knots: the closed-form FK gives the path back.
    assert_allclose([delta_fk(delta.params, r) for r in R], adept_point(delta.params, t, 2.0),
                    rtol=0, atol=1e-12)


def test_delta_ik_and_fk_round_trip_across_the_workspace():
    PD = DeltaParams()
    rng = np.random.default_rng(11)
    for _ in range(10):
        p = np.array([0.0, 0.0, PD.home_z]) + rng.uniform(-0.15, 0.15, 3)
        assert_allclose(delta_fk(PD, delta_ik(PD, p)), p, atol=1e-12)  # trilateration


# --- the 3-RRR planar parallel manipulator -----------------------------------------------------

def test_threerrr_ik_and_fk_round_trip_at_random_poses():
    P = ThreeRRRParams()
    rng = np.random.default_rng(13)
    for _ in range(20):
        pose = rng.uniform([-0.05, -0.05, -0.2], [0.05, 0.05, 0.2])
        qa = threerrr_ik(P, pose)
        # The leg equations, evaluated here: every link at its length (round-off on 0.2 m),
        # every elbow on the counter-clockwise side of A_i B_i (the stated working mode).
        for th, e in zip(THETA, threerrr_elbows(P, qa), strict=True):
            A, B = P.R * _u(th), pose[:2] + P.r * _u(th + pose[2])
            assert_allclose([np.linalg.norm(e - A), np.linalg.norm(B - e)], [P.l1, P.l2],
                            rtol=0, atol=1e-15)
            (bx, bz), (ex, ez) = B - A, e - A
            assert bx * ez - bz * ex > 0.0
        # Newton from home to a 1e-14 m gap, its Jacobian's cond below 2: 1e-13 in the pose.
        assert_allclose(threerrr_fk(P, qa), pose, rtol=0, atol=1e-13)
    # The platform 0.3 m down: its top joint 0.5 m from leg 1's base joint, reach l1 + l2.
    with pytest.raises(MechanismError, match=r"out of reach of leg 1 \(0\.5 m"):
        threerrr_ik(P, (0.0, -0.3, 0.0))
    with pytest.raises(MechanismError, match=r"out of reach of leg 1"):
        ThreeRRRParams(home_z=-0.3)
    with pytest.raises(ValueError, match=r"I_platform must be .*> 0 \[kg m\^2\]"):
        ThreeRRRParams(I_platform=0.0)


def test_threerrr_fk_equals_pinocchio_platform_pose(threerrr):
    P = threerrr.params
    rng = np.random.default_rng(17)
    for _ in range(10):
        qa = threerrr.neutral() + rng.uniform(-0.15, 0.15, 3)
        q = threerrr.close(qa, seed=threerrr.home)  # Pinocchio's Newton on the loops
        # Newton's 1e-12 m gap times cond(J_p) < 30: measured 5e-12; 1e-9 m, rad asked.
        assert_allclose(_pinocchio_task_point(threerrr, q), threerrr_fk(P, qa), rtol=0,
                        atol=1e-9)
        assert_allclose(q[6:], threerrr_fk(P, qa), rtol=0, atol=1e-9)  # (px, pz, phi)


def test_threerrr_mobility_is_three_with_three_motors(threerrr):
    motors = [m.get("joint") for m in ET.fromstring(threerrr.mjcf).iter("motor")]
    assert motors == threerrr.joint_names == ["qa1", "qa2", "qa3"]
    assert threerrr.passive_names == ["qp1", "qp2", "qp3", "px", "pz", "phi"]
    assert threerrr.constraint_names == ["loop1", "loop2", "loop3"]
    # Mobility from Pinocchio's own constraint Jacobians (not the chain's rows): 9 coordinates,
    # 3 CONTACT_3D loops of which the world-y rows vanish (planar), rank 6.
    model, data = threerrr.model, threerrr.model.createData()
    pin.computeJointJacobians(model, data, threerrr.home)
    Jc = np.vstack([pin.getConstraintJacobian(model, data, c, c.createData())
                    for c in threerrr.constraints])
    sv = np.linalg.svd(Jc, compute_uv=False)
    assert model.nv == 9 and Jc.shape == (9, 9)
    assert model.nv - int(np.sum(sv > 1e-9 * sv[0])) == 3 == threerrr.nq == len(motors)
    assert list(threerrr.rows) == [0, 2, 3, 5, 6, 8]


def test_threerrr_type_ii_singularity_is_refused(threerrr):
    P = threerrr.params
    # Built here from the geometry: the distal links radial, so their three lines meet at the
    # platform centre P = 0. |E_i - A_i| = l1 with E_i = (r + l2) u(theta_i + phi): the law of
    # cosines in phi; the root in the working mode is the negative one.
    phi = -math.acos(((P.r + P.l2) ** 2 + P.R ** 2 - P.l1 ** 2) / (2 * P.R * (P.r + P.l2)))
    qa = threerrr_ik(P, (0.0, 0.0, phi))
    q = []
    for th, a, e in zip(THETA, qa, threerrr_elbows(P, qa), strict=True):
        assert_allclose(e, (P.r + P.l2) * _u(th + phi), rtol=0, atol=1e-15)
        q += [a, math.atan2(-e[1], -e[0]) - a]  # distal link along -E_i: through the centre
    q = np.array(q + [0.0, 0.0, phi])
    assert_allclose(threerrr.residual(q), 0.0, atol=1e-15)  # an assembled configuration
    with pytest.raises(SingularConfiguration, match=r"type-II .*cond\(J_p\) = .* > 10000"):
        threerrr.close(qa, seed=q)


def test_threerrr_task_path_stays_well_inside_the_workspace(threerrr):
    P = threerrr.params
    t, W, source = threerrr.task_path(2.0)
    assert source.startswith("platform circle of radius 30 mm through home, swing 0.1 rad")
    # Starts and ends at home (a closed circle, the swing back to zero).
    assert_allclose(W[[0, -1]], threerrr.neutral()[None, :].repeat(2, 0), rtol=0, atol=1e-15)
    # cond(J_p) along it: measured 18.6 (13.3 at home), 500x below the refusal limit.
    assert check_chain_reference(threerrr, t, W)["max_cond_Jp"] < 20.0
    q = threerrr.home
    worst = 1.0
    for w in W:
        q = threerrr.close(w, seed=q)
        worst = min(worst, np.abs(np.sin(q[[1, 3, 5]])).min())
    assert worst > 0.65  # no leg near stretched or folded (type I); measured 0.656
    assert np.all(np.isfinite([threerrr_fk(P, w) for w in W[::40]]))


def test_threerrr_study_fl_and_hinf_track(threerrr):
    plant = threerrr
    ref = study_reference(plant, 2.0)
    law = {name: make_law(name, load_closed_chain("threerrr")) for name in ("fl", "hinf")}
    runs = {name: rrr_pin.simulate(plant, law[name], ref, 2.0, rate=1000.0) for name in law}
    # The exact model's FL error dynamics are zero from a zero error: what is left is the
    # zero-order hold's, first order in the sampling period (halving it halves the error:
    # measured 4.77e-6 rad at 1 kHz, 2.43e-6 at 2 kHz; H-inf + FL 8.3e-7), and the loops
    # stay closed to the integrator's projection (3e-13 m measured).
    err = {name: np.abs(tr.q - tr.r).max() for name, tr in runs.items()}
    assert err["fl"] < 1e-5 and err["hinf"] < 1e-5
    fine = rrr_pin.simulate(plant, make_law("fl", load_closed_chain("threerrr")), ref, 2.0,
                            rate=2000.0)
    assert 1.8 < err["fl"] / np.abs(fine.q - fine.r).max() < 2.2
    assert max(tr.info["drift_m"] for tr in runs.values()) < 1e-11
    # One uncertain plant (the paper's tolerances): H-inf + FL tracks better than FL alone
    # (measured RMS 1.77e-5 vs 2.99e-4 rad, 17x; asked: better, here at least 5x).
    uncertain, _ = plant.perturbed(np.random.default_rng([0, 0]), rrr_pin.Tolerances())
    rms = {name: np.sqrt(np.mean((tr.q - tr.r) ** 2)) for name, tr in
           ((n, rrr_pin.simulate(uncertain, law[n], ref, 2.0, rate=1000.0)) for n in law)}
    assert rms["hinf"] < rms["fl"] / 5.0


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


# --- <connect> checked in Python before Pinocchio reads the file (issue 36) ------------------

_LOOP = '<connect name="loop" site1="tip1" site2="tip2"/>'


@pytest.mark.parametrize("connect, message", [
    # Before: a segfault (exit 139) in 4 of 10 runs, else "type-II singularity cond(J_p) = inf"
    ('<connect name="loop" site1="tip1" site2="tip99"/>',
     r"<connect loop>: site2='tip99': no such site \(the sites are tip1, tip2\)"),
    # Before: a segfault in 6 of 10 runs, else "The index of the parent joint is not valid"
    ('<connect name="loop" site1="nosuch" site2="tip2"/>', r"site1='nosuch': no such site"),
    # Before: "mobility is 4"
    ('<connect name="loop" site1="tip1" site2="tip1"/>', r"connects 'tip1' to itself"),
    # Before: Pinocchio's empty "message:"
    ('<connect name="loop"/>', r"names no target: give site1 and site2"),
    ('<connect name="loop" site1="tip1"/>', r"names site1 and site2 .*\['site1'\]"),
    ('<connect name="loop" body1="distal9" anchor="0.23 0 0"/>', r"body1='distal9': no such"),
    ('<connect name="loop" body1="distal1" body2="distal2"/>', r"needs an anchor"),
], ids=["site2", "site1", "itself", "empty", "one-site", "body", "anchor"])
def test_a_connect_naming_a_missing_or_equal_target_is_refused_in_python(
        connect, message, tmp_path):
    text = mjcf_from_params(mechanism_params("fivebar"))
    assert _LOOP in text
    path = tmp_path / "bad.xml"
    path.write_text(text.replace(_LOOP, connect))
    for _ in range(3):  # the crash was intermittent: the refusal must not be
        with pytest.raises(MechanismError, match=rf"{path}: .*{message}"):
            load_robot(path)


def test_a_home_keyframe_with_an_open_loop_names_the_gap(tmp_path):
    # Before: "2 actuator(s) ... but the mechanism's mobility is ..." (J at an open loop)
    text = mjcf_from_params(mechanism_params("fivebar"))
    root = ET.fromstring(text)
    q = [float(v) for v in root.find("keyframe/key").get("qpos").split()]
    opened = " ".join(repr(v) for v in [q[0], q[1] + 0.3, q[2], q[3]])
    path = tmp_path / "open.xml"
    path.write_text(text.replace(root.find("keyframe/key").get("qpos"), opened))
    with pytest.raises(MechanismError, match=r"<connect loop> is open by 0\.\d+ m at the home "
                                             r"keyframe"):
        load_robot(path)
    path.write_text(text.replace(root.find("keyframe/key").get("qpos"), "0 0 0"))
    with pytest.raises(MechanismError, match=r"qpos must be 4 finite numbers"):
        load_robot(path)


def test_cli_names_the_missing_site_without_a_crash(tmp_path):
    import subprocess
    import sys

    text = mjcf_from_params(mechanism_params("fivebar"))
    path = tmp_path / "bad.xml"
    path.write_text(text.replace(_LOOP, '<connect name="loop" site1="tip1" site2="tip99"/>'))
    for _ in range(3):
        run = subprocess.run([sys.executable, "-m", "rrr_pin.cli", "margins", "--robot",
                              str(path)], capture_output=True, text=True, timeout=120)
        assert run.returncode == 2, run.stderr
        assert "site2='tip99': no such site" in run.stderr and "Traceback" not in run.stderr


@pytest.mark.parametrize("old, new, message", [
    # before: margins were computed on a negative mass; a NaN mass gave Pinocchio's
    # "conversion of data to type double failed"
    ('mass="0.3"', 'mass="-0.3"', r"<body distal1> <inertial>: mass='-0.3': expected a finite"),
    ('mass="0.3"', 'mass="nan"', r"mass='nan'"),
    ('diaginertia="1.5e-05 0.00133 0.00133"', 'diaginertia="1.5e-05 0.00133"',
     r"diaginertia='1.5e-05 0.00133': expected 3 finite moments"),
], ids=["negative", "nan", "two-moments"])
def test_a_non_physical_inertial_is_refused_by_body(old, new, message, tmp_path):
    text = mjcf_from_params(mechanism_params("fivebar"))
    assert old in text
    path = tmp_path / "bad.xml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(MechanismError, match=message):
        load_robot(path)


@pytest.mark.parametrize("text, message", [
    ("<mujoco><worldbody>", r"not well-formed XML"),
    ("", r"not well-formed XML"),
    ("<mujoco/>", r"not an MJCF model \(no <mujoco><worldbody>\)"),
    ("<robot/>", r"not an MJCF model"),
], ids=["truncated", "empty", "no-worldbody", "urdf-root"])
def test_a_malformed_mjcf_is_refused_naming_the_file(text, message, tmp_path):
    # before: ParseError / AttributeError tracebacks (issue 31)
    path = tmp_path / "bad.xml"
    path.write_text(text)
    with pytest.raises(MechanismError, match=rf"{path}: {message}"):
        load_robot(path)

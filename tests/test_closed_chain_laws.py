"""Every built-in law on a closed chain's reduced model, and its frozen-configuration certificate.

Independent references: the reduced gravity as the gradient of Pinocchio's potential energy of
the closed mechanism (finite differences, no ``S`` or ``J_p``); the reduced inverse dynamics
:meth:`ClosedChain.inverse_dynamics` (``reduced_terms``, not the laws' ``reduced``); for the
certificate, the frozen plant built by hand from finite differences of Pinocchio's
``constraintDynamics`` (a second algorithm for the plant) and compared by
:func:`rrr_pin.robust.gap.nugap` on python-control series connections.
"""

from __future__ import annotations

import control
import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from rrr_pin import cli
from rrr_pin.campaign.closed_chain_study import (
    ChainStudyConfig,
    chain_reference,
    run_chain_study,
)
from rrr_pin.control.catalog import LAWS, make_law
from rrr_pin.control.closed_chain import (
    CHAIN_LAWS,
    ReducedAntiWindup,
    ReducedPD,
    ReducedTracking,
    ReducedTwoDOF,
    closed_chain_hinf_aw,
    closed_chain_hinf_fl,
    make_chain_law,
)
from rrr_pin.control.laws import PD_BANDWIDTH, SampledLaw
from rrr_pin.model.closed_chain import load_closed_chain
from rrr_pin.model.mechanisms import perturb_mechanism
from rrr_pin.robust.certificates import chain_certificate, frozen_linearization
from rrr_pin.robust.gap import nugap
from rrr_pin.robust.loopshaping import design, fl_plant
from rrr_pin.sim.closed_chain import simulate_closed_chain


@pytest.fixture(scope="module")
def fivebar():
    return load_closed_chain("fivebar")


@pytest.fixture(scope="module")
def paper():
    return design(lam=45.0, n=2)


def _state(chain, rng):
    qa = chain.neutral() + rng.uniform(-0.05, 0.05, chain.nq)
    chain.close(qa, seed=chain.home)
    return qa, rng.standard_normal(chain.nq)


def test_every_builtin_law_has_a_closed_chain_form():
    # A built-in added to the registry without a closed-chain form fails here.
    assert set(CHAIN_LAWS) == set(LAWS)


@pytest.mark.parametrize("name, cls", [("fl", ReducedTracking), ("hinf", ReducedTracking),
                                       ("pd", ReducedPD), ("hinf2dof", ReducedTwoDOF),
                                       ("hinf_aw", ReducedAntiWindup)],
                         ids=["fl", "hinf", "pd", "hinf2dof", "hinf_aw"])
def test_make_law_on_a_chain_builds_the_reduced_law_and_samples_it(name, cls, fivebar,
                                                                    paper):
    law = make_law(name, fivebar, K=paper.K_reduced, torque_limit=50.0)
    assert type(law) is cls and law.n == 2
    # fl and hinf run on the compiled closed-chain engine; the others have no compiled form
    assert (law.compiled_form() is None) == (name not in ("fl", "hinf"))
    digital = law.sampled(1000.0)
    assert isinstance(digital, SampledLaw)
    rng = np.random.default_rng(1)
    q, qd = _state(fivebar, rng)
    r, rd, rdd = q + 0.01, qd + 0.1, rng.standard_normal(2)
    x = np.zeros(law.nx)
    # Both read the state at the sample; with x = 0 the torques agree when D is the same
    # (Tustin changes D, so the comparison is for the static laws only).
    if law.nx == 0:
        assert_allclose(digital.step(0.0, q, qd, r, rd, rdd, x)[0],
                        law.torque(0.0, q, qd, r, rd, rdd, x), rtol=0, atol=0)


def test_pd_on_the_chain_is_kp_e_plus_kd_ed_plus_reduced_gravity(fivebar):
    law = make_law("pd", fivebar)
    home = fivebar.neutral()
    m = np.diag(fivebar.M(home))
    assert_allclose(np.diag(law.Kp), PD_BANDWIDTH ** 2 * m, rtol=1e-15)
    assert_allclose(np.diag(law.Kd), 2.0 * PD_BANDWIDTH * m, rtol=1e-15)
    rng = np.random.default_rng(2)
    chain = load_closed_chain("fivebar")  # a second copy for the reference gravity

    def U(qa):
        q = chain.close(qa)
        return pin.computePotentialEnergy(chain.model, chain.data, q)

    for _ in range(3):
        q, qd = _state(fivebar, rng)
        chain.close(q, seed=chain.home)
        h = 1e-3  # five-point stencil: truncation ~h^4 = 1e-12
        Gr = np.array([(8 * (U(q + h * e) - U(q - h * e)) - U(q + 2 * h * e)
                        + U(q - 2 * h * e)) / (12 * h) for e in np.eye(2)])
        r, rd = q + rng.uniform(-0.02, 0.02, 2), rng.standard_normal(2)
        tau = law.torque(0.0, q, qd, r, rd, 0.0 * rd, np.zeros(0))
        # U ~ 1 J closed to 1e-12 m (~1e-11 J) over 12 h: ~1e-9 N m.
        assert_allclose(tau, law.Kp @ (r - q) + law.Kd @ (rd - qd) + Gr, rtol=0, atol=1e-8)


def test_feedback_linearizing_laws_use_the_reduced_inverse_dynamics(fivebar, paper):
    rng = np.random.default_rng(3)
    q, qd = _state(fivebar, rng)
    r, rd, rdd = q + 0.01, qd - 0.2, rng.standard_normal(2)
    for law in (make_law("fl", fivebar), make_law("hinf", fivebar, K=paper.K_reduced)):
        x = rng.standard_normal(law.nx)
        _, _, C, D = law.continuous_matrices()
        lam = law.lam
        taubar = rdd + 2 * lam * (rd - qd) + lam ** 2 * ((r - q) + C @ x + D @ (r - q))
        # Two evaluations of the same reduced model (reduced vs reduced_terms): round-off.
        assert_allclose(law.torque(0.0, q, qd, r, rd, rdd, x),
                        fivebar.inverse_dynamics(q, qd, taubar), rtol=1e-12, atol=1e-9)
    law = make_law("hinf2dof", fivebar)
    x = rng.standard_normal(law.nx)
    A, B, C, D = law._mats
    tauhat = q + C @ x + D[:, :2] @ (r - q)
    taubar = law.lam ** 2 * (tauhat - q) - 2 * law.lam * qd
    assert_allclose(law.torque(0.0, q, qd, r, rd, rdd, x),
                    fivebar.inverse_dynamics(q, qd, taubar), rtol=1e-12, atol=1e-9)


def test_hinf_aw_unsaturated_is_hinf_and_clips_to_its_limits(fivebar, paper):
    ref = chain_reference(fivebar, 0.2)
    plant = load_closed_chain("fivebar")
    runs = []
    for law in (closed_chain_hinf_fl(load_closed_chain("fivebar"), paper.K_reduced),
                closed_chain_hinf_aw(load_closed_chain("fivebar"), paper.K_reduced,
                                     torque_limit=1e3)):
        runs.append(simulate_closed_chain(plant, law, ref, 0.05, rate=1000.0, engine="python"))
    # Never clipped (|tau| < 20 N m here): the same arithmetic, bit for bit.
    assert np.abs(runs[0].tau).max() < 1e3
    assert_allclose(runs[1].q, runs[0].q, rtol=0, atol=0)
    assert_allclose(runs[1].tau, runs[0].tau, rtol=0, atol=0)
    tight = closed_chain_hinf_aw(fivebar, paper.K_reduced, torque_limit=0.5)
    q, qd = fivebar.neutral(), np.zeros(2)
    x = np.zeros(tight.nx)
    tau = tight.torque(0.0, q, qd, q + 0.1, qd, qd, x)
    assert_allclose(np.abs(tau), 0.5, rtol=0, atol=0)


def test_refusals_name_the_law_and_the_reason(fivebar, paper):
    with pytest.raises(ValueError, match="hinf_aw.*needs torque_limit"):
        make_law("hinf_aw", fivebar)
    with pytest.raises(ValueError, match="MJCF motor has none"):
        closed_chain_hinf_aw(fivebar, paper.K_reduced, torque_limit="urdf")
    with pytest.raises(ValueError, match="unknown controller 'bogus'.*fl, hinf"):
        make_chain_law("bogus", fivebar)


# --- certificates --------------------------------------------------------------------------

def _perturbed(seed=5):
    nominal = load_closed_chain("fivebar")
    params, _ = perturb_mechanism(nominal.params, np.random.default_rng(seed), 0.2, 0.05)
    return nominal, load_closed_chain(params)


def test_nominal_chain_certificate_has_zero_nu_gap(paper):
    nominal = load_closed_chain("fivebar")
    ref = chain_reference(nominal, 2.0)
    cert = chain_certificate(nominal, load_closed_chain("fivebar"), ref, [0.0, 0.7],
                             lam=45.0, W1=paper.W1, W2=paper.W2, Ks=paper.Ks_reduced)
    # The nominal frozen plant is eq. (11) up to the central differences' round-off.
    assert_allclose(cert.nugap, 0.0, atol=1e-8)
    assert cert.certified


def _hand_plant(nominal, plant, qa, qd, qdd, lam, h=1e-5):
    """A, B of the frozen FL'd plant from constraintDynamics (the plant's second algorithm)."""
    tauhat0 = qa + (qdd + 2 * lam * qd) / lam ** 2

    def acc(qa, qd, tauhat):
        taubar = -2 * lam * qd - lam ** 2 * (qa - tauhat)
        tau = nominal.inverse_dynamics(qa, qd, taubar)
        q, v = plant.state(qa, qd)
        return plant.constrained_acceleration(q, v, plant.actuation(tau))[list(plant.actuated)]

    n = len(qa)
    A = np.zeros((2 * n, 2 * n))
    A[:n, n:] = np.eye(n)
    B = np.zeros((2 * n, n))
    for i, e in enumerate(np.eye(n) * h):
        A[n:, i] = (acc(qa + e, qd, tauhat0) - acc(qa - e, qd, tauhat0)) / (2 * h)
        A[n:, n + i] = (acc(qa, qd + e, tauhat0) - acc(qa, qd - e, tauhat0)) / (2 * h)
        B[n:, i] = (acc(qa, qd, tauhat0 + e) - acc(qa, qd, tauhat0 - e)) / (2 * h)
    return A, B


def test_chain_linearization_and_certificate_against_a_hand_built_plant(paper):
    nominal, plant = _perturbed()
    ref = chain_reference(nominal, 2.0)
    t = np.array([0.6])
    R, RD, RDD = ref.sample(t)
    cert = chain_certificate(nominal, plant, ref, t, lam=45.0, W1=paper.W1, W2=paper.W2,
                             Ks=paper.Ks_reduced)
    G = frozen_linearization(nominal, plant, R[0], RD[0], RDD[0], lam=45.0)
    A, B = _hand_plant(nominal, plant, R[0], RD[0], RDD[0], 45.0)
    # A ~ lam^2 = 2e3: the step-1e-5 differences of constraintDynamics (6e-11 rad/s^2 at
    # mu = 1e-4) and truncation leave ~1e-4 absolute.
    assert_allclose(G.B, B, rtol=1e-6, atol=1e-4)
    assert_allclose(G.A, A, rtol=1e-6, atol=1e-3)
    assert not np.allclose(B[2:], 45.0 ** 2 * np.eye(2), rtol=1e-3)  # really perturbed
    n = 2
    W1 = control.append(*[paper.W1] * n) if paper.W1.ninputs == 1 else paper.W1
    W2 = control.append(*[paper.W2] * n) if paper.W2.ninputs == 1 else paper.W2
    C, D = np.hstack([np.eye(n), np.zeros((n, n))]), np.zeros((n, n))
    Gs_k = control.series(W1, control.ss(A, B, C, D), W2)
    Gs_0 = control.series(W1, fl_plant(45.0, n), W2)
    # The nu-gap is Lipschitz in the plant: the ~1e-7 relative difference in A, B moves it
    # by about as much.
    assert_allclose(cert.nugap[0], nugap(Gs_k, Gs_0), rtol=1e-5, atol=1e-7)
    assert cert.nugap[0] > 1e-3 and cert.b == pytest.approx(0.4665, abs=1e-4)


# --- the study with any laws ---------------------------------------------------------------

def test_study_without_the_paper_pair_has_no_verdict_and_certifies():
    result = run_chain_study(ChainStudyConfig(mechanism="fivebar", samples=1, duration=0.1,
                                              controllers=("pd",), certificate_points=2))
    assert result.names == ["pd"] and result.claims == []
    assert "no verdict" in result.claims_note and "fl and hinf" in result.claims_note
    cert = result.metrics[1]["certificate"]
    assert cert["certified"] and 0.0 < cert["nugap_max"] < cert["b"]
    s = result.to_dict()["summary"]
    assert s["certificates"] == {"certified": 1, "checked": 1, "nugap_max": cert["nugap_max"],
                                 "b": cert["b"]}
    assert s["laws"]["pd"]["mean_rms_error_rad"] == result.metrics[1]["pd"]["rms_error_rad"]


def test_study_takes_a_user_law(fivebar):
    class Hold(ReducedPD):
        name = "hold"

    user = Hold(load_closed_chain("fivebar"), Kp=[50.0, 50.0], Kd=[2.0, 2.0], name="hold")
    result = run_chain_study(ChainStudyConfig(mechanism="fivebar", samples=0, duration=0.05,
                                              controllers=(), certify=False), laws=[user])
    assert result.names == ["hold"] and result.metrics[0]["hold"]["status"] == "ok"
    assert result.laws[0]["class"].endswith("Hold")
    with pytest.raises(ValueError, match="repeated: hold"):
        run_chain_study(ChainStudyConfig(mechanism="fivebar", samples=0, duration=0.05,
                                         controllers=()), laws=[user, user])


@pytest.mark.parametrize("argv, match", [
    (["--controllers", "hinf_aw"], "hinf_aw: on a closed chain the law must be told"),
    (["--controllers", "fl,bogus"], "'bogus': not a built-in controller with a closed-chain"),
    (["--controllers", "fl,fl"], "repeated fl"),
    (["--baseline", "fl"], "does not implement --baseline"),
    (["--amp", "0.3"], "does not implement --amp"),
    (["--dt", "1e-4"], "does not implement --dt"),
    (["--uncertainty", "x.json"], "does not implement --uncertainty"),
], ids=["hinf_aw", "unknown", "repeated", "baseline", "amp", "dt", "uncertainty"])
def test_reproduce_chain_refuses_options_it_does_not_implement(argv, match, tmp_path, capsys):
    assert cli.main(["reproduce", "--robot", "fivebar", *argv, "--out",
                     str(tmp_path / "x")]) == 2
    assert match in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("options, match", [
    ({"controllers": "fl,hinf"}, "tuple of built-in law names"),
    ({"controllers": ("fl", "nope")}, "'nope' not a built-in law with a closed-chain form"),
    ({"controllers": ("hinf_aw",)}, "hinf_aw on a closed chain needs torque_limit"),
    ({"certificate_points": 0}, "certificate_points"),
    ({"lam_fl": -1.0}, "lam_fl"),
], ids=["string", "unknown", "hinf_aw", "points", "lam"])
def test_chain_study_config_refuses_bad_laws(options, match):
    with pytest.raises(ValueError, match=match):
        ChainStudyConfig(**options)


def test_full_order_runs_the_full_k(paper):
    from rrr_pin.campaign.closed_chain_study import _builtin_laws

    laws = _builtin_laws(ChainStudyConfig(controllers=("hinf",), full_order=True), paper)
    # the full-order K of the design, copied per joint (a SISO K on the diagonal)
    assert laws[0].nx == 2 * control.ss(paper.K_full).nstates
    assert laws[0].nx > 2 * control.ss(paper.K_reduced).nstates

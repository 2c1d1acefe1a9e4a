"""Tests of rrr_pin.robust.certificates: frozen linearization and the nu-gap certificate.

On every kind of plant; on a closed chain against the frozen plant built here by hand from
central differences of Pinocchio's ``constraintDynamics`` (a second algorithm for the plant),
compared by :func:`rrr_pin.robust.gap.nugap` on python-control series connections.
"""

from dataclasses import replace

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.control.references import study_reference
from rrr_pin.model.dh import paper_params
from rrr_pin.model.dynamics import load_robot
from rrr_pin.model.uncertainty import Tolerances
from rrr_pin.robust.certificates import (
    CertificateSpec,
    certificate_along,
    frozen_certificate,
    frozen_linearization,
)
from rrr_pin.robust.gap import nugap
from rrr_pin.robust.loopshaping import fl_plant
from rrr_pin.robust.lti import DimensionMismatchError

Q = np.array([[0.1, 0.5, -0.4], [0.8, -0.3, 1.0], [-1.0, 1.2, 0.3]])
QD = np.array([[0.5, -0.2, 0.1], [0.0, 0.3, -0.6], [1.0, 0.5, 0.5]])


def scaled(params, c):
    """Arm with every mass and principal moment multiplied by ``c``."""
    return params.with_links([replace(link, mass=link.mass * c, J=tuple(c * j for j in link.J))
                              for link in params.links])


@pytest.fixture(scope="module")
def setup(paper):
    return paper, paper_params()


def test_nominal_linearization_is_eq11(setup):
    _, p = setup
    robot = load_robot(p)
    G = frozen_linearization(robot, robot, Q[1], QD[1], lam=45.0)
    ref = fl_plant(45.0, 3)
    # exact model: the map tauhat -> q is eq. (11); central differences, step 1e-6 -> ~1e-8
    assert_allclose(G.A, np.block([[np.zeros((3, 3)), np.eye(3)],
                                   [-45.0**2 * np.eye(3), -90.0 * np.eye(3)]]), atol=1e-5)
    assert_allclose(G.B[3:], 45.0**2 * np.eye(3), rtol=1e-12, atol=1e-9)   # solve() rounding
    w = np.logspace(-1, 3, 9)
    assert_allclose(np.asarray(G(1j * w)), np.asarray(ref(1j * w)), atol=1e-8)


def test_linearization_closed_form_without_gravity(setup):
    # no gravity, qd = 0, qdd = 0, masses and inertias times c: qdd = M^-1 Mhat taubar with
    # M = c Mhat, so A = [0 I; -lam^2/c I, -2 lam/c I], B = [0; lam^2/c I] (V is quadratic
    # in qd and vanishes with its derivative at qd = 0)
    _, p = setup
    c, lam = 2.5, 45.0
    nominal = load_robot(p, gravity=0.0)
    true = load_robot(scaled(p, c), gravity=0.0)
    G = frozen_linearization(nominal, true, Q[0], np.zeros(3), lam=lam)
    assert_allclose(G.A[3:, :3], -lam**2 / c * np.eye(3), atol=1e-5)   # FD, step 1e-6
    assert_allclose(G.A[3:, 3:], -2 * lam / c * np.eye(3), atol=1e-5)
    assert_allclose(G.B[3:], lam**2 / c * np.eye(3), rtol=1e-12, atol=1e-9)   # rounding


def test_nominal_plant_certified(setup):
    d, p = setup
    robot = load_robot(p)
    cert = frozen_certificate(robot, robot, Q, QD, lam=d.lam, W1=d.W1, W2=d.W2,
                              Ks=d.Ks_reduced)
    assert cert.certified
    assert cert.nugap_max < 1e-8                  # FD linearization error only
    # b(Gs, Ks) of the eq. (18) controller is 1 / gamma_reduced
    assert_allclose(cert.b, 1 / d.gamma_reduced, rtol=1e-9)
    assert_allclose(cert.b_frozen, cert.b, rtol=1e-6)


@pytest.mark.parametrize(("c", "certified"), [(1.2, True), (5.0, False)],
                         ids=["20%-heavier", "5x-heavier"])
def test_wrong_plants(setup, c, certified):
    d, p = setup
    cert = frozen_certificate(load_robot(p), load_robot(scaled(p, c)), Q, QD, lam=d.lam,
                              W1=d.W1, W2=d.W2, Ks=d.Ks_reduced)
    assert cert.certified == certified
    # the theorem, checked where it applies: nugap < b  =>  b_frozen >= guaranteed bound
    ok = cert.nugap < cert.b
    assert np.all(cert.b_frozen[ok] >= cert.b_lower[ok] * (1 - 1e-9))
    assert np.all(cert.b_frozen[ok] > 0)


def test_certificate_bad_input(setup):
    d, p = setup
    robot = load_robot(p)
    with pytest.raises(DimensionMismatchError, match=r"Expected q of shape \(N, 3\)"):
        frozen_certificate(robot, robot, np.zeros((2, 2)), np.zeros((2, 2)), lam=d.lam,
                           W1=d.W1, W2=d.W2, Ks=d.Ks_reduced)
    with pytest.raises(ValueError, match="finite"):
        frozen_certificate(robot, robot, np.full((1, 3), np.nan), np.zeros((1, 3)), lam=d.lam,
                           W1=d.W1, W2=d.W2, Ks=d.Ks_reduced)


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"lam": 0.0}, r"lam must be a finite number > 0 \[rad/s\], got 0\.0"),
    ({"lam": "45"}, r"lam must be a finite number > 0 \[rad/s\], got '45'"),
    ({"points": 0}, r"points must be an integer >= 1, got 0"),
    ({"points": True}, r"points must be an integer >= 1, got True"),
], ids=["lam-zero", "lam-str", "points-zero", "points-bool"])
def test_certificate_spec_checks_its_settings_once_when_made(kwargs, match):
    spec = {"lam": 45.0, "W1": ((), (), (), ((1.0,),)), "W2": ((), (), (), ((1.0,),)),
            "Ks": ((), (), (), ((1.0,),)), **kwargs}
    with pytest.raises(ValueError, match=match):
        CertificateSpec(**spec)


def test_frozen_linearization_refuses_a_bad_lam(rrr):
    with pytest.raises(ValueError, match=r"lam must be a finite number > 0 \[rad/s\], got nan"):
        frozen_linearization(rrr, rrr, np.zeros(3), np.zeros(3), lam=float("nan"))


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
def test_nominal_plant_certified_along_its_study_reference(plant, design_for):
    # The nominal frozen plant is eq. (11) up to the central differences' round-off, at every
    # point of the plant's own study reference (a closed chain: both models walked along it).
    d = design_for(plant.nq)
    twin = load_robot(plant.name)  # the plant, a second object: its own Newton seed
    cert = certificate_along(plant, twin, study_reference(plant, 2.0), [0.0, 0.7, 1.3],
                             lam=d.lam, W1=d.W1, W2=d.W2, Ks=d.Ks_reduced)
    assert_allclose(cert.nugap, 0.0, atol=1e-8)
    assert cert.certified
    # b(Gs, Ks) of the eq. (18) controller is 1 / gamma_reduced, whatever the joint count
    assert_allclose(cert.b, 1 / d.gamma_reduced, rtol=1e-9)


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


def test_chain_certificate_against_a_plant_built_from_constraint_dynamics(design_for):
    d = design_for(2)
    nominal = load_robot("fivebar")  # both models are walked along the reference: own copies
    plant, _ = nominal.perturbed(np.random.default_rng(5), Tolerances())
    ref = study_reference(nominal, 2.0)
    t = np.array([0.6])
    R, RD, RDD = ref.sample(t)
    cert = certificate_along(nominal, plant, ref, t, lam=45.0, W1=d.W1, W2=d.W2,
                             Ks=d.Ks_reduced)
    G = frozen_linearization(nominal, plant, R[0], RD[0], RDD[0], lam=45.0)
    A, B = _hand_plant(nominal, plant, R[0], RD[0], RDD[0], 45.0)
    # A ~ lam^2 = 2e3: the step-1e-5 differences of constraintDynamics (6e-11 rad/s^2 at
    # mu = 1e-4) and truncation leave ~1e-4 absolute.
    assert_allclose(G.B, B, rtol=1e-6, atol=1e-4)
    assert_allclose(G.A, A, rtol=1e-6, atol=1e-3)
    assert not np.allclose(B[2:], 45.0 ** 2 * np.eye(2), rtol=1e-3)  # really perturbed
    n = 2
    C, D = np.hstack([np.eye(n), np.zeros((n, n))]), np.zeros((n, n))
    Gs_k = control.series(d.W1, control.ss(A, B, C, D), d.W2)
    Gs_0 = control.series(d.W1, fl_plant(45.0, n), d.W2)
    # The nu-gap is Lipschitz in the plant: the ~1e-7 relative difference in A, B moves it
    # by about as much.
    assert_allclose(cert.nugap[0], nugap(Gs_k, Gs_0), rtol=1e-5, atol=1e-7)
    assert cert.nugap[0] > 1e-3
    assert_allclose(cert.b, 1 / d.gamma_reduced, rtol=1e-9)


def test_a_chain_reference_leaving_the_workspace_names_its_time(design_for):
    # Before: the certificate's walk along the reference said only "the loop does not close
    # at q_a = ...", hiding the nominal run's "reference at t = ..." (issue 31).
    from rrr_pin.control.specs import ReferenceSpec
    from rrr_pin.model.closed_chain import LoopClosureError

    d = design_for(2)
    nominal = load_robot("fivebar")
    ref = ReferenceSpec(kind="sine").build(nominal, 4.0)
    with pytest.raises(LoopClosureError, match=r"^reference at t = 0\.\d+ s: fivebar: the loop "
                                               r"does not close"):
        certificate_along(nominal, load_robot("fivebar"), ref, np.linspace(0, 4.0, 8),
                          lam=45.0, W1=d.W1, W2=d.W2, Ks=d.Ks_reduced)

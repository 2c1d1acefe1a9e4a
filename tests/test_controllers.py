"""The built-in laws on every kind of plant, against Pinocchio's algorithms and closed forms.

Independent references: RNEA for the arm's inverse dynamics (the laws use CRBA + NLE); on a
closed chain, the reduced inverse dynamics from the closed full state
(``ClosedChain.inverse_dynamics``, through ``reduced_terms``, not the laws' ``terms``); the
gravity as the gradient of Pinocchio's potential energy of the whole tree (finite
differences, no ``S`` or ``J_p``).
"""

import control
import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from rrr_pin.control.laws import (
    PD_BANDWIDTH,
    CompiledForm,
    ControlLaw,
    FLForm,
    FLLinearModel,
    PDForm,
    PDGravity,
    PDLinearModel,
    SampledLaw,
    TrackingController,
    check_law,
    fl_controller,
    hinf_2dof_controller,
    hinf_fl_controller,
    pd_controller,
)
from rrr_pin.control.references import QuinticReference
from rrr_pin.sim.simulation import simulate

# The paper's eq. (18), typed from the paper (used here only as a test input).
K18 = control.tf([47.40, 47.40 * (134.75 + 12.17), 47.40 * 134.75 * 12.17],
                 [1.0, 513.37 + 0.19, 513.37 * 0.19])


def _state(plant, rng, spread=0.05):
    """A state ``(q, qd)`` near the plant's neutral configuration, its model seeded there."""
    q = plant.neutral() + rng.uniform(-spread, spread, plant.nq)
    plant.reset(q)  # a closed chain: close the loop at q on its home branch
    return q, rng.standard_normal(plant.nq)


def test_on_reference_the_law_is_inverse_dynamics(rrr):
    # With q = r, qd = rd and x = 0 the law must give RNEA(q, qd, rdd): CRBA + NLE on one side,
    # the recursive Newton-Euler algorithm on the other.
    rng = np.random.default_rng(5)
    for ctrl in (fl_controller(rrr), hinf_fl_controller(rrr, K18)):
        for _ in range(20):
            q, qd, qdd = rng.uniform(-3, 3, (3, 3))
            tau = ctrl.torque(0.0, q, qd, q, qd, qdd, np.zeros(ctrl.nx))
            expected = pin.rnea(rrr.model, rrr.data, q, qd, qdd)
            assert_allclose(tau, expected, rtol=1e-12, atol=1e-9)  # round-off of 1e2 N m terms


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
def test_feedback_linearizing_laws_are_the_plants_inverse_dynamics(plant):
    # Off the reference and with a state x: tau = inverse_dynamics(q, qd, taubar), eq. (8)-(10)
    # with taubar = rdd + 2 lam (rd - qd) + lam^2 (e + C x + D e).
    rng = np.random.default_rng(3)
    n = plant.nq
    q, qd = _state(plant, rng)
    r, rd, rdd = q + 0.01, qd - 0.2, rng.standard_normal(n)
    for law in (fl_controller(plant), hinf_fl_controller(plant, K18)):
        x = rng.standard_normal(law.nx)
        _, _, C, D = law.continuous_matrices()
        lam = law.lam
        taubar = rdd + 2 * lam * (rd - qd) + lam ** 2 * ((r - q) + C @ x + D @ (r - q))
        # two algorithms (RNEA against CRBA + NLE; on a closed chain the reduced model from
        # the closed full state against the laws' fast path): round-off of ~1e2 N m terms
        assert_allclose(law.torque(0.0, q, qd, r, rd, rdd, x),
                        plant.inverse_dynamics(q, qd, taubar), rtol=1e-12, atol=1e-9)
    # the 2-DOF law: tauhat = q + C x + Dr (r - q), taubar = lam^2 (tauhat - q) - 2 lam qd
    law = hinf_2dof_controller(plant)
    x = rng.standard_normal(law.nx)
    tauhat = q + law.K.C @ x + law.K.D[:, :n] @ (r - q)
    taubar = law.lam ** 2 * (tauhat - q) - 2 * law.lam * qd
    assert_allclose(law.torque(0.0, q, qd, r, rd, rdd, x),
                    plant.inverse_dynamics(q, qd, taubar), rtol=1e-12, atol=1e-9)


def test_feedback_terms_with_a_static_K(rrr):
    # Off the reference, with K = k (static, y = k e): tau - (V + G) = M (2 lam (rd - qd)
    # + lam^2 (1 + k) e), eq. (10); M, V, G from Pinocchio's RNEA-based Robot methods.
    lam, k = 100.0, 0.3
    ctrl = TrackingController(rrr, lam, K=control.ss([], [], [], [[k]]))
    q, qd = np.array([0.1, 0.2, 0.3]), np.array([0.0, 0.5, -0.5])
    r, rd, rdd = q + 0.01, qd + 0.1, np.zeros(3)
    tau = ctrl.torque(0.0, q, qd, r, rd, rdd, np.zeros(0))
    taubar = 2 * lam * (rd - qd) + lam**2 * (1 + k) * (r - q)
    expected = rrr.M(q) @ taubar + rrr.V(q, qd) + rrr.G(q)
    assert_allclose(tau, expected, rtol=1e-12)


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
def test_siso_K_is_copied_on_the_diagonal(plant, paper):
    n = plant.nq
    ctrl = hinf_fl_controller(plant, K18)
    assert ctrl.nx == 2 * n
    K = control.ss(*ctrl.continuous_matrices())
    for w in (0.1, 10.0, 500.0):
        expected = complex(K18(1j * w))
        assert_allclose(K(1j * w), expected * np.eye(n), rtol=1e-10, atol=1e-12)
    # the design's full-order K (reproduce --full-order) too: one copy per actuated joint
    full = hinf_fl_controller(plant, paper.K_full)
    assert full.nx == n * control.ss(paper.K_full).nstates > ctrl.nx


def test_tustin_keeps_dc_gain(rrr):
    # Bilinear discretization maps s = 0 to z = 1: the DC gain is preserved exactly.
    ctrl = hinf_fl_controller(rrr, K18)
    Ad, Bd, Cd, Dd = ctrl.discretize(1000.0)
    dc = Cd @ np.linalg.solve(np.eye(len(Ad)) - Ad, Bd) + Dd
    assert_allclose(dc, float(control.dcgain(K18)) * np.eye(3), rtol=1e-9)


def test_pd_gravity_regulates_a_set_point(rrr):
    # PD + gravity compensation on the exact model drives any initial state to a constant
    # set point (Lyapunov, Siciliano et al. 2009, sec. 8.5.2): independent of the gains' values.
    goal = np.array([0.3, -0.4, 0.5])
    hold = QuinticReference(goal, goal, 1.0)  # at rest on the goal for all t
    traj = simulate(rrr, pd_controller(rrr), hold, 3.0, q0=goal + [0.2, -0.1, 0.15],
                    qd0=[0.5, 0.0, -0.5])
    assert np.max(np.abs(traj.error[0])) > 0.1
    assert_allclose(traj.q[-1], goal, atol=1e-4)  # 20 rad/s, critically damped: e ~ 1e-6 at 3 s


@pytest.mark.parametrize("plant", ["rrr", "fivebar", "delta"], indirect=True)
def test_pd_is_kp_e_plus_kd_ed_plus_the_gradient_of_the_potential_energy(plant):
    # tau = Kp e + Kd ed + G(q) with the default gains wn^2 diag(M(home)), 2 wn diag(M(home));
    # G the gradient of Pinocchio's potential energy of the whole tree at the configuration
    # the actuated q gives (a closed chain's passive joints solved, the loop closed).
    law = pd_controller(plant)
    home = np.clip(plant.neutral(), plant.lower, plant.upper)
    m = np.diag(plant.M(home))
    assert_allclose(np.diag(law.Kp), PD_BANDWIDTH ** 2 * m, rtol=1e-15)
    assert_allclose(np.diag(law.Kd), 2.0 * PD_BANDWIDTH * m, rtol=1e-15)
    data = plant.model.createData()

    def U(q):
        full = plant.configurations([q])[0]
        return pin.computePotentialEnergy(plant.model, data, full)

    rng = np.random.default_rng(2)
    for _ in range(3):
        q, qd = _state(plant, rng)
        h = 1e-3  # five-point stencil: truncation ~h^4 = 1e-12
        G = np.array([(8 * (U(q + h * e) - U(q - h * e)) - U(q + 2 * h * e)
                       + U(q - 2 * h * e)) / (12 * h) for e in np.eye(plant.nq)])
        r, rd = q + rng.uniform(-0.02, 0.02, plant.nq), rng.standard_normal(plant.nq)
        plant.reset(q)
        tau = law.torque(0.0, q, qd, r, rd, 0.0 * rd, np.zeros(0))
        # U ~ 1 J closed to 1e-12 m (~1e-11 J) over 12 h: ~1e-9 N m; the arm's U ~ 1e2 J at
        # round-off 1e-14 over 12 h: ~1e-11 N m.
        assert_allclose(tau, law.Kp @ (r - q) + law.Kd @ (rd - qd) + G, rtol=0, atol=1e-8)


def test_compiled_form_only_for_the_exact_class(rrr):
    class Mine(TrackingController):
        def torque(self, t, q, qd, r, rd, rdd, x):
            return np.zeros(3)

    assert type(fl_controller(rrr).compiled_form()) is FLForm
    assert type(pd_controller(rrr).compiled_form()) is PDForm
    mine = Mine(rrr, 100.0, name="mine")
    assert mine.compiled_form() is None
    assert mine.sampled(1000.0).compiled_form() is None
    assert mine.linear_model() is None


def test_fl_alone_form_is_eq_20(rrr):
    # FL alone, eq. (20): no controller states and D = 0, so y = 0 and taubar is the PD-like
    # law on e; the form carries exactly that, at the law's bandwidth.
    form = fl_controller(rrr, 80.0).compiled_form()
    assert isinstance(form, CompiledForm) and form.nominal is rrr and form.lam == 80.0
    assert [m.shape for m in (form.A, form.B, form.C, form.D)] == [(0, 0), (0, 3), (3, 0),
                                                                   (3, 3)]
    assert not np.any(form.D)


def _tf_at(Ad, Bd, Cd, Dd, z):
    """Frequency response C (zI - A)^-1 B + D of a discrete system at the complex point z."""
    return Cd @ np.linalg.solve(z * np.eye(Ad.shape[0]) - Ad, Bd) + Dd


@pytest.mark.parametrize("w", [1.0, 30.0, 400.0], ids=["1", "30", "400"])
def test_sampled_hinf_form_is_the_tustin_image_of_eq_18(rrr, w):
    # The sampled form's K(z) at z = e^{jwT} equals the paper's K(s), eq. (18), at the Tustin
    # point s = (2/T)(z - 1)/(z + 1), on the diagonal, and 0 off it (K is SISO, copied). The
    # reference is K18's own polynomials, evaluated directly (no state-space realization).
    # 1e-9: round-off of a 2-state solve, K18's poles spread over 3.5 decades.
    T = 1e-3
    form = hinf_fl_controller(rrr, K18).sampled(1.0 / T).compiled_form()
    assert type(form) is FLForm and form.A.shape == (6, 6)
    z = np.exp(1j * w * T)
    s = 2.0 / T * (z - 1.0) / (z + 1.0)
    num, den = K18.num[0][0], K18.den[0][0]
    expected = np.polyval(num, s) / np.polyval(den, s)
    assert_allclose(_tf_at(form.A, form.B, form.C, form.D, z), expected * np.eye(3), rtol=1e-9,
                    atol=1e-9 * abs(expected))


@pytest.mark.parametrize("make, match", [
    (lambda r: FLForm(r, 100.0, np.zeros((0, 0)), np.zeros((0, 2)), np.zeros((3, 0)),
                      np.zeros((3, 3))), r"Expected B of shape \(0, 3\), got \(0, 2\)"),
    (lambda r: FLForm(r, -1.0, np.zeros((0, 0)), np.zeros((0, 3)), np.zeros((3, 0)),
                      np.zeros((3, 3))), "lam must be a finite number > 0"),
    (lambda r: FLForm(r, 100.0, np.zeros((0, 0)), np.zeros((0, 3)), np.zeros((3, 0)),
                      np.full((3, 3), np.nan)), "D must be finite"),
    (lambda r: PDForm(r, np.eye(2), np.eye(3)), r"Expected Kp of shape \(3, 3\)"),
], ids=["B-shape", "lam", "D-nan", "Kp-shape"])
def test_bad_forms_name_the_field(rrr, make, match):
    with pytest.raises(ValueError, match=match):
        make(rrr)


def test_forms_are_frozen(rrr):
    form = pd_controller(rrr).compiled_form()
    with pytest.raises(AttributeError):
        form.Kp = np.eye(3)
    with pytest.raises(ValueError, match="read-only"):
        form.Kp[0, 0] = 1.0


def test_fl_linear_model_is_the_linearized_plant(rrr):
    # With the model exact, FL alone makes qdd = taubar = -lam^2 q - 2 lam qd (regulation, r = 0):
    # u = Dc [q; qd] with Dc = [-lam^2 I, -2 lam I], no state, and M^-1 = I (M cancels). Its
    # loop is L(s) = (2 lam s + lam^2) / s^2, eq. (19) with K = 0.
    lam = 100.0
    lin = fl_controller(rrr, lam).linear_model()
    assert type(lin) is FLLinearModel and lin.bandwidth(None) == lam
    Ac, Bc, Cc, Dc, Minv = lin.digital(1000.0, None)
    assert Ac.shape == (0, 0) and Bc.shape == (0, 6) and Cc.shape == (3, 0)
    assert_allclose(Dc, np.hstack([-lam ** 2 * np.eye(3), -2 * lam * np.eye(3)]), rtol=0, atol=0)
    assert_allclose(Minv, np.eye(3), rtol=0, atol=0)
    (L,) = lin.loops(None)
    s = 1j * np.array([3.0, 70.0, 900.0])
    # 1e-12: python-control's polynomial evaluation against the closed form, in double.
    assert_allclose(L(s), (2 * lam * s + lam ** 2) / s ** 2, rtol=1e-12)


def test_pd_linear_model_uses_the_coupled_inertia(rrr):
    # PD at q_h: qdd = M(q_h)^-1 u; M^-1 checked against Pinocchio's computeMinverse (a second
    # algorithm, not the inverse of CRBA), the slowest mode against the generalized symmetric
    # eigenproblem Kp v = w^2 M v (scipy.linalg.eigh). 1e-10: round-off of 3 x 3 solves.
    import scipy.linalg

    home = np.array([0.3, -0.5, 0.8])
    law = pd_controller(rrr)
    lin = law.linear_model()
    assert type(lin) is PDLinearModel
    Minv_ref = pin.computeMinverse(rrr.model, rrr.data, home)
    Minv_ref = np.triu(Minv_ref) + np.triu(Minv_ref, 1).T
    Ac, Bc, Cc, Dc, Minv = lin.digital(1000.0, home)
    assert Ac.shape == (0, 0)
    assert_allclose(Minv, Minv_ref, rtol=1e-10, atol=1e-12)
    assert_allclose(Dc, np.hstack([-law.Kp, -law.Kd]), rtol=0, atol=0)
    w2 = scipy.linalg.eigh(law.Kp, rrr.M(home), eigvals_only=True)
    assert_allclose(lin.bandwidth(home), np.sqrt(w2.min()), rtol=1e-10)


def test_pd_subclass_with_its_own_torque_has_no_linear_model(rrr):
    class Softer(PDGravity):
        def torque(self, t, q, qd, r, rd, rdd, x):
            return 0.5 * super().torque(t, q, qd, r, rd, rdd, x)

    law = Softer(rrr, Kp=[100.0] * 3, Kd=[10.0] * 3, name="softer")
    assert law.linear_model() is None and law.compiled_form() is None


def test_laws_pickle_as_themselves(rrr):
    import pickle

    class_ = hinf_fl_controller(rrr, K18)
    back = pickle.loads(pickle.dumps(class_))
    assert type(back) is TrackingController and back.name == "hinf"
    for a, b in zip(back.continuous_matrices(), class_.continuous_matrices(), strict=True):
        assert_allclose(a, b, rtol=0, atol=0)


def test_a_law_with_state_must_say_how_to_sample(rrr):
    class Integrator(ControlLaw):
        name, n, nx = "integ", 3, 3

        def torque(self, t, q, qd, r, rd, rdd, x):
            return x

    with pytest.raises(NotImplementedError, match="does not say how to discretize"):
        Integrator().sampled(1000.0)


@pytest.mark.parametrize("kwargs,message", [
    ({"lam": 0.0}, "lam must be a positive"),
    ({"lam": float("nan")}, "lam must be a positive"),
    ({"lam": 45.0, "K": control.ss(np.eye(2) * -1, np.eye(2), np.eye(2), np.zeros((2, 2)))},
     "K must be SISO or 3 x 3"),
    ({"lam": 45.0, "K": control.tf([1.0], [1.0, -1.0])}, "unstable poles"),
    ({"lam": 45.0, "K": control.tf([1.0], [1.0, 0.5], 0.001)}, "continuous-time"),
    ({"lam": 45.0, "name": "two words"}, "law name must be"),
], ids=["lam0", "lam-nan", "K-2x2", "K-unstable", "K-discrete", "name"])
def test_bad_inputs(rrr, kwargs, message):
    with pytest.raises(ValueError, match=message):
        TrackingController(nominal=rrr, **kwargs)


def test_bad_law_objects(rrr):
    with pytest.raises(TypeError, match="must subclass rrr_pin.ControlLaw"):
        check_law(lambda t: 0)

    class Two(SampledLaw):
        name, n = "two", 2

    with pytest.raises(ValueError, match="law 'two' is for 2 joints, the plant has 3"):
        check_law(Two(), 3)
    with pytest.raises(ValueError, match="Kp of shape"):
        PDGravity(rrr, Kp=[1.0, 2.0], Kd=[1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="wn must be > 0"):
        pd_controller(rrr, wn=float("nan"))


def test_bad_rate(rrr):
    with pytest.raises(ValueError, match=r"rate must be a finite number > 0 \[Hz\], got -5.0"):
        hinf_fl_controller(rrr, K18).discretize(-5.0)


# --- the 2-DOF law (hinf2dof) -------------------------------------------------------------------

@pytest.fixture(scope="module")
def design_2dof():
    """The design hinf2dof documents: ncfsyn_2dof on eq. (11), W1 of eq. (16), Tref at 90 rad/s."""
    from rrr_pin.robust.loopshaping import fl_plant, lag_weight
    from rrr_pin.robust.ncf import ncfsyn_2dof

    s = control.tf("s")
    return ncfsyn_2dof(fl_plant(45.0, 1), 90.0 ** 2 / (s + 90.0) ** 2, 1.1, lag_weight())


def test_2dof_law_follows_the_designed_closed_loop(rrr, twodof, design_2dof):
    # Exact model: FL leaves q'' = taubar per joint, so q - r(0) is the design's closed loop
    # CL = (I + G K2)^-1 G K1 (ncfsyn_2dof's own realization, not the law's implemented form)
    # driven by r - r(0). Rest-to-rest quintic, so x = 0 and the zero initial state of CL both
    # are rest. RK4 at 5e-4 s against forced_response on the same grid (input linear between
    # samples): measured 1.4e-7 rad at 5e-4 s and 5.7e-9 rad at 1e-4 s, a discretization gap
    # that shrinks as dt^2; 1e-6 rad leaves a factor 7 over the measured gap.
    start = np.array([0.2, 0.5, -0.8])
    ref = QuinticReference(start, start + np.array([0.3, -0.2, 0.25]), 0.5)
    traj = simulate(rrr, twodof, ref, 0.7, dt=5e-4, engine="python")
    CL = design_2dof.CL
    r = ref.sample(traj.t)[0]
    for j in range(3):
        lin = control.forced_response(CL, traj.t, r[:, j] - start[j]).outputs
        assert_allclose(traj.q[:, j] - start[j], lin, atol=1e-6)


def test_2dof_linear_model_is_the_feedback_block(rrr, twodof, design_2dof):
    # r = 0: the loop at the torque is L = (2 lam s + lam^2 (1 + K2)) / s^2 with K2 the design's
    # feedback block; compared at three frequencies to 1e-9 (one state-space evaluation each).
    design = design_2dof
    lin = twodof.linear_model()
    L = lin.loops(None)[0]
    lam = 45.0
    for w in (1.0, 50.0, 300.0):
        s = 1j * w
        expect = (2 * lam * s + lam * lam * (1 + design.K2(s))) / s ** 2
        assert_allclose(L(s), expect, rtol=1e-9)
    # The digital form is the sampled law's own: one step of each from the same state agrees.
    Ad, Bc, Cc, Dc, Minv = lin.digital(1000.0, None)
    law = twodof.sampled(1000.0)
    rng = np.random.default_rng(3)
    q, qd, x = rng.normal(size=3) * 0.1, rng.normal(size=3), rng.normal(size=law.nx)
    rrr_q = q + np.array([0.0, 0.5, -0.5])   # the FL cancels M and V + G exactly (same model)
    tau, x_next = law.step(0.0, rrr_q, qd, np.array([0.0, 0.5, -0.5]), 0 * q, 0 * q, x)
    taubar = np.linalg.solve(rrr.M(rrr_q), tau - rrr.V(rrr_q, qd) - rrr.G(rrr_q))
    assert_allclose(taubar, Cc @ x + Dc @ np.concatenate([q, qd]), rtol=1e-9, atol=1e-9)
    assert_allclose(x_next, Ad @ x + Bc @ np.concatenate([q, qd]), rtol=1e-12, atol=1e-12)


def test_2dof_law_pickles_and_refuses_a_bad_K(rrr, twodof):
    import pickle

    again = pickle.loads(pickle.dumps(twodof))
    assert type(again) is type(twodof)
    assert_allclose(again.discretize(1000.0)[1], twodof.discretize(1000.0)[1], rtol=1e-12)
    from rrr_pin.control.laws import TwoDOFController

    with pytest.raises(ValueError, match=r"K: K1\(0\) - K2\(0\) must be the identity"):
        TwoDOFController(rrr, 45.0, control.ss(-1.0, [[1.0, 1.0]], 1.0, [[0.0, 0.0]]))
    with pytest.raises(ValueError, match="K must be 1 x 2 or 3 x 6"):
        TwoDOFController(rrr, 45.0, K18)

"""Tests of rrr_pin.control.analysis on every kind of plant, against closed forms and Pinocchio.

Independent references: the shaped double integrator in closed form (g = 0, exact model); the
design's closed-loop poles; a perturbed closed loop written afresh from ``crba`` and the
gravity (through ``S = [I; -J_p^-1 J_a]`` on a closed chain); on a closed chain, the plant's
second algorithm, Pinocchio's ``constraintDynamics`` on the full tree, differenced here.
"""

import json

import control
import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from rrr_pin import cli
from rrr_pin.control.analysis import (
    loop_at_input,
    loop_margins,
    parametric_loop,
    parametric_margin,
    sampled_margin,
)
from rrr_pin.control.catalog import make_law
from rrr_pin.control.laws import fl_controller, pd_controller
from rrr_pin.model.dynamics import load_robot
from rrr_pin.robust.mu import closed_loop_matrix

Q = np.array([0.3, 0.6, -0.9])

#: Frozen configuration of each kind [rad]: the arm bent, a mechanism just off its home.
OFFSET = {"fivebar": [0.05, -0.04], "delta": [0.05, -0.04, 0.03]}


def frozen(plant):
    """The frozen configuration of ``plant`` (:data:`Q` for the RRR)."""
    return Q if plant.name == "rrr" else plant.neutral() + OFFSET[plant.name]


@pytest.mark.parametrize("name, atol", [("rrr", 1e-8), ("fivebar", 1e-7)])
def test_fl_loop_without_gravity_is_the_shaped_double_integrator(name, atol):
    # With g = 0 and the model exact, tau = M taubar and qdd = M^-1 tau: the loop at the
    # torque input is M c(s) M^-1 = c(s) I with c(s) = (2 lam s + lam^2) / s^2, on a closed
    # chain too (M_r in the actuated coordinates).
    robot = load_robot(name, gravity=0.0)  # its own model: the shared ones have gravity
    q = frozen(robot)
    lam = 100.0
    L = loop_at_input(fl_controller(robot, lam), robot, q)
    for w in (3.0, 100.0, 2000.0):
        s = 1j * w
        # central differences of the law: relative error O(h^2) = 1e-12, and round-off; a
        # closed chain's plant is differenced too (steps 1e-5, loop closed to 1e-12 m): atol
        # 1e-7 there
        assert_allclose(L(s), (2 * lam * s + lam**2) / s**2 * np.eye(robot.nq), rtol=1e-6,
                        atol=atol)
    m = loop_margins(L)
    # |c(jw)| = 1 at w^2 = lam^2 (2 + sqrt 5); phase margin atan(2 w_c / lam)
    wc = lam * np.sqrt(2 + np.sqrt(5))
    pm = np.degrees(np.arctan(2 * wc / lam))
    assert_allclose(m.crossover, wc, rtol=1e-4)
    assert_allclose(m.phase, pm, rtol=1e-4)
    assert_allclose(m.delay, np.radians(pm) / wc, rtol=1e-4)
    # the phase is -180 deg only at w -> 0, where |c| -> inf: python-control's gain margin is
    # that lower one, 1/|c(j0)| = 0 (any gain in (0, inf) keeps the loop stable). A plant
    # linearized by central differences (a closed chain's, 1e-9 relative) may keep the phase a
    # hair above -180 deg there, and python-control then finds no crossing at all (inf); so may
    # round-off on an exact one (measured: channel 1 of 3 on SciPy 1.17, control 0.10.2).
    assert np.all((m.gain < 1e-10) | (m.gain == np.inf)), m.gain
    # disk margin of a SISO loop: 2 / max |S - T| ... balanced: alpha = 1 / max|(1-c)/(1+c)|/2
    ww = np.logspace(-2, 5, 20001)
    c = (2 * lam * 1j * ww + lam**2) / (1j * ww) ** 2
    alpha = 1 / np.max(np.abs(0.5 * (1 - c) / (1 + c)))
    assert_allclose(m.disk, alpha, rtol=1e-3)
    # the balanced disk's gain range [1/k, k], k = (1 + alpha/2) / (1 - alpha/2), a factor
    # (before: python-control's dB figure was shown as a factor, "x15.3" for 5.83)
    assert_allclose(m.disk_gain, (1 + alpha / 2) / (1 - alpha / 2), rtol=5e-3)
    assert_allclose(m.disk_gain_db, 20 * np.log10(m.disk_gain), rtol=1e-12)


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
def test_closed_loops_at_the_torque_input_have_the_design_poles(plant):
    # FL with gravity: the gravity stiffness of the law and of the plant cancel, so the closed
    # loop is s^2 + 2 lam s + lam^2 per joint (a double pole at -lam).
    lam, q, n = 100.0, frozen(plant), plant.nq
    L = loop_at_input(fl_controller(plant, lam), plant, q)
    poles = np.linalg.eigvals(L.A - L.B @ L.C)
    # a double pole moves by sqrt(perturbation): 1e-3 relative covers the 1e-6 step (and a
    # closed chain's 1e-5 steps of its plant)
    assert_allclose(poles, -lam, rtol=1e-3)
    # PD + gravity: M qdd = -Kp q - Kd qd (gravity stiffness cancels), Kp, Kd of the law
    pd = pd_controller(plant)
    L = loop_at_input(pd, plant, q)
    M = plant.M(q)
    Kp, Kd = pd.linear_model().Kp, pd.linear_model().Kd
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M, Kp),
                                                  -np.linalg.solve(M, Kd)]])
    assert_allclose(np.sort_complex(np.linalg.eigvals(L.A - L.B @ L.C)),
                    np.sort_complex(np.linalg.eigvals(A)), rtol=1e-4)


def _scaled_model(model, factors):
    """A copy of ``model`` with the principal moments and masses scaled by ``factors``."""
    model = model.copy()
    for j in range(1, model.njoints):
        Y = model.inertias[j]
        J, R = np.linalg.eigh(Y.inertia)  # principal moments, ascending, of the nominal body
        J = J * [factors.get((j, k), 1.0) for k in range(3)]
        Y.mass = Y.mass * factors.get((j, None), 1.0)
        Y.inertia = (R * J) @ R.T
        model.inertias[j] = Y
    return model


def _fl_closed_loop(lam, Mh, Gh, M, G):
    """``M qdd + G q = Mh (-2 lam qd - lam^2 q) + Gh q`` (FL alone, K = 0) as a matrix."""
    n = len(M)
    acc = np.linalg.solve(M, -lam**2 * Mh + Gh - G)
    return np.block([[np.zeros((n, n)), np.eye(n)],
                     [acc, np.linalg.solve(M, -2 * lam * Mh)]])


def _arm_closed_loop(law, q, factors):
    """The FL closed loop on the arm with inertial factors, from crba and gravity derivatives."""
    def mats(m):
        d = m.createData()
        M = pin.crba(m, d, q)
        M = np.triu(M) + np.triu(M, 1).T
        return M, pin.computeGeneralizedGravityDerivatives(m, d, q)

    (Mh, Gh), (M, G) = mats(law.nominal.model), mats(_scaled_model(law.nominal.model, factors))
    return _fl_closed_loop(law.lam, Mh, Gh, M, G)


def _chain_closed_loop(law, q, factors):
    """The same on a closed chain: crba and gravity projected through ``S``, differenced."""
    chain = law.nominal
    chain.reset(q)

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

    (Mh, Gh), (M, G) = parts(chain.model), parts(_scaled_model(chain.model, factors))
    chain.reset(q)
    return _fl_closed_loop(law.lam, Mh, Gh, M, G)


@pytest.mark.parametrize("plant, closed_loop, rtol", [
    ("rrr", _arm_closed_loop, 1e-6),
    # both sides difference dG_r/dq_a on a closed chain (steps 1e-5 and 1e-4): 1e-5 relative
    ("fivebar", _chain_closed_loop, 1e-5),
], indirect=["plant"], ids=["rrr", "fivebar"])
def test_parametric_lft_closes_to_the_perturbed_plant(plant, closed_loop, rtol):
    law = fl_controller(plant, 100.0)
    q = frozen(plant)
    loop = parametric_loop(law, q, tol=0.2)
    model = plant.model
    index = {}
    for j in range(1, model.njoints):
        index[f"{model.names[j]}.mass"] = (j, None)
        for k in range(3):
            index[f"{model.names[j]}.J{k + 1}"] = (j, k)
    rng = np.random.default_rng(7)
    delta = rng.uniform(-1.5, 1.5, len(loop.names))
    Delta = np.diag(np.repeat(delta, [n for _, n in loop.blocks]))
    factors = {index[name]: 1 + 0.2 * d for name, d in zip(loop.names, delta, strict=True)}
    expect = np.sort_complex(np.linalg.eigvals(closed_loop(law, q, factors)))
    got = np.sort_complex(np.linalg.eigvals(closed_loop_matrix(loop.M, Delta)))
    assert_allclose(got, expect, rtol=rtol)
    # every body of the tree (a closed chain's passive links too): a mass and three moments
    assert len(loop.names) + len(loop.dropped) == 4 * (model.njoints - 1)


def test_a_chain_loop_is_linearized_from_its_constraint_dynamics(fivebar):
    # A second algorithm for the plant: Pinocchio's constraintDynamics on the full tree,
    # differenced with a 10x larger step, against the loop's A, B (the reduced model
    # M_r^-1 (tau - h_r) in the actuated coordinates).
    chain = fivebar
    q0 = frozen(chain)
    n = chain.nq
    chain.reset(q0)
    L = loop_at_input(pd_controller(chain), chain, q0)
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
    chain.reset(q0)
    # rows n..2n of A (plant accelerations) and B; constraintDynamics' proximal accuracy
    # (6e-11 at mu = 1e-4) over the 1e-4 step and its O(h^2) error: 1e-5 of the largest entry
    assert_allclose(L.A[n:2 * n, :n], dq, atol=1e-5 * np.abs(dq).max())
    assert_allclose(L.B[n:2 * n], dtau, atol=1e-8 * np.abs(dtau).max())


@pytest.mark.slow
@pytest.mark.parametrize("plant, name, samples", [("rrr", "hinf", 128), ("fivebar", "fl", 16)],
                         indirect=["plant"], ids=["rrr", "fivebar"])
def test_parametric_margin_brackets_the_sampled_vertices(plant, name, samples):
    law = make_law(name, plant)
    loop, r = parametric_margin(law, frozen(plant),
                                omega=np.concatenate([[0], np.logspace(0, 4, 10)]))
    alpha, _ = sampled_margin(law, loop, samples=samples)
    # mu's guarantee: no perturbation below margin_lower destabilizes; the sweep's bisection
    # stops at a relative 1e-4
    assert r.margin_lower <= alpha * (1 + 1e-4)
    if plant.name == "rrr":
        # here the worst case is a vertex (the true mass matrix singular at 1 - 5 x 0.2 = 0),
        # so the sweep reaches the destabilizing perturbation the mu lower bound found
        assert_allclose(alpha, r.margin_upper, rtol=1e-3)
        assert r.critical_frequency == np.inf


def test_lower_and_upper_gain_margins_bound_the_stable_loop_gains(rrr, paper):
    # issue 50: margins printed python-control's gain margin (7.54e-14/inf/0.00519/...)
    # without saying it is a lower one. Each channel's lower and upper margins are checked
    # against the closed loop's poles (an independent computation): the loop k L_i is stable
    # just inside (lower, upper) and unstable just outside a finite end.
    law = make_law("hinf", rrr, K=paper.K_reduced)
    L = loop_at_input(law, rrr, Q)
    m = loop_margins(L)
    from rrr_pin.control.analysis import loop_channel

    def stable(Li, k):
        A = Li.A - k * Li.B @ Li.C  # negative feedback of k L_i (D = 0)
        return bool(np.max(np.linalg.eigvals(A).real) < 0)

    for i in range(rrr.nq):
        Li = loop_channel(L, i)
        lo, hi = m.gain_lower[i], m.gain_upper[i]
        assert 0 < lo < 1 < hi  # the H-infinity loop has a lower margin (0.046 at q = 0)
        assert stable(Li, 1.0) and stable(Li, 1.02 * lo) and not stable(Li, 0.98 * lo)
        if np.isfinite(hi):
            assert stable(Li, 0.98 * hi) and not stable(Li, 1.02 * hi)
        else:
            assert stable(Li, 1e3)


@pytest.mark.parametrize("robot, home", [
    ("rrr", ["--home", "0.3,0.6,-0.9"]),
    ("fivebar", []),
    pytest.param("delta", [], marks=pytest.mark.slow),
], ids=["rrr", "fivebar", "delta"])
def test_cli_margins_json(robot, home, capsys):
    assert cli.main(["margins", "--robot", robot, "--controllers", "fl", *home,
                     "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    pm = out["laws"]["fl"]["phase_margin_deg"]
    # the lower and upper gain margins bracket the nominal gain 1 (checked against the poles
    # in test_lower_and_upper_gain_margins_bound_the_stable_loop_gains)
    lower, upper = (out["laws"]["fl"][f"gain_margin_{k}"] for k in ("lower", "upper"))
    assert all(0 <= lo < 1 for lo in lower)
    assert all(hi is None or hi > 1 for hi in upper)  # None: inf in strict JSON
    # FL alone, gravity cancelled exactly in the closed loop; the loop at the input still
    # carries the gravity stiffness, so only a band is asserted: near the shaped double
    # integrator's atan(2 sqrt(2 + sqrt 5)) = 76.3 deg (checked exactly at g = 0 above)
    assert len(pm) == len(out["q_rad"]) and all(60 < p < 90 for p in pm)
    assert set(out["laws"]) == {"fl"} and out["robot"] == robot


@pytest.mark.parametrize("command", ["margins", "robstab"])
def test_cli_analysis_refuses_a_lock_on_a_closed_chain(command, capsys):
    assert cli.main([command, "--robot", "fivebar", "--lock", "qa1=0.1"]) == 2
    err = capsys.readouterr().err
    assert "joints of a closed chain cannot be locked" in err and "Traceback" not in err


def test_cli_margins_refuses_a_configuration_outside_the_workspace(capsys):
    # 5-bar: both proximal links pointing away from each other, the loop cannot close
    assert cli.main(["margins", "--robot", "fivebar", "--controllers", "fl",
                     "--home", "3.0,0.0"]) == 2
    err = capsys.readouterr().err
    assert "the loop does not close at q_a = [3. 0.] rad" in err and "Traceback" not in err


@pytest.mark.parametrize("command, home, joint", [
    ("margins", "9,0,0", "joint1 = 9"), ("margins", "-9,0,0", "joint1 = -9"),
    ("robstab", "0,4,0", "joint2 = 4")], ids=["margins-9", "margins-minus-9", "robstab"])
def test_cli_refuses_a_home_outside_the_joint_limits(command, home, joint, capsys):
    # Before (issue 31): `margins --home 9,0,0` gave margins at a configuration the RRR's
    # limits [-pi, pi] exclude.
    assert cli.main([command, "--controllers", "fl", "--home", home]) == 2
    err = capsys.readouterr().err
    assert f"--home {home}: {joint} is outside its joint limits [-3.142, 3.142]" in err
    assert "Traceback" not in err


def test_loop_at_input_refuses_bad_inputs(rrr):
    law = fl_controller(rrr)
    with pytest.raises(ValueError, match="q"):
        loop_at_input(law, rrr, [0.0, np.nan, 0.0])
    with pytest.raises(TypeError, match="control law"):
        loop_at_input(object(), rrr, Q)
    with pytest.raises(TypeError, match="feedback-linearizing"):
        parametric_loop(pd_controller(rrr), Q)
    with pytest.raises(ValueError, match="tol"):
        parametric_loop(law, Q, tol=-0.1)
    assert isinstance(loop_at_input(law, rrr, Q), control.StateSpace)


@pytest.mark.parametrize("robot, name", [
    ("rrr", "fl"), pytest.param("rrr", "hinf", marks=pytest.mark.slow), ("fivebar", "fl"),
], ids=["rrr-fl", "rrr-hinf", "fivebar-fl"])
def test_delay_margin_equals_the_stress_prediction_without_gravity(robot, name):
    # campaign.stress predicts the delay boundary from the law's own SISO loop
    # (linear_model().loops(): (2 lam s + lam^2 (1 + K)) / s^2); with g = 0 and the model
    # exact, the MIMO loop at the torque input is that loop times I, on any plant.
    from rrr_pin.campaign.stress import continuous_boundary

    plant = load_robot(robot, gravity=0.0)  # its own model: the shared ones have gravity
    law = make_law(name, plant)
    m = loop_margins(loop_at_input(law, plant, frozen(plant)))
    assert_allclose(m.delay.min(), continuous_boundary(law, "delay"), rtol=1e-5)


# --- the margin's scaling law in the uncertainty scale (issue 36) ----------------------------

#: A short grid: the RRR's FL margin is set at infinite frequency (M singular as a mass factor
#: reaches 0), which the grid's last point already shows.
_GRID = np.array([0.0, 10.0, 1e4])


def test_margin_times_tol_is_constant_over_the_uncertainty_scale(rrr):
    # Before: --tol 2 gave 1.6e-33 (central differences at factors 1 +- tol reached a mass
    # factor -1, where Pinocchio's composite inertia is meaningless: M up to 1.7e34).
    law = fl_controller(rrr)
    tols = [0.2, 2.0]  # the paper's and one past a factor -1 (where the bug was)
    results = [parametric_margin(law, Q, t, omega=_GRID)[1] for t in tols]
    lower = np.array([r.margin_lower * t for r, t in zip(results, tols, strict=True)])
    upper = np.array([r.margin_upper * t for r, t in zip(results, tols, strict=True)])
    # the LFT's blocks scale with tol exactly, so mu's bounds do (measured: equal to 1e-15)
    assert_allclose(lower, lower[0], rtol=1e-9)
    assert_allclose(upper, upper[0], rtol=1e-9)
    # independent of mu: the eigenvalues of the closed loop rebuilt on the box's vertices
    # (Pinocchio's M for factors > 0, its affine extension where tol x alpha reaches 1)
    for tol in (2.0,):  # the vertices at 0.2 give the same alpha * tol (scaling, above)
        alpha, _ = sampled_margin(law, parametric_loop(law, Q, tol), samples=8)
        # mu's guarantee holds below its lower bound; the worst vertex is a mass factor
        # reaching 0 (M singular), the destabilizing perturbation mu's upper bound found
        assert lower[0] <= alpha * tol * (1 + 1e-4)
        assert_allclose(alpha * tol, upper[0], rtol=1e-3)


def test_a_non_positive_inertial_factor_is_refused_for_pinocchio(rrr):
    from rrr_pin.control.analysis import _scaled

    with pytest.raises(ValueError, match=r"must be > 0 .*\(1, 'mass'\): -0.5"):
        _scaled(rrr.model, {(1, "mass"): -0.5})


def test_the_affine_extension_equals_pinocchio_where_both_exist(rrr):
    # M and dG/dq from the slopes at factors 1 +- 0.5 against Pinocchio at factors 0.1 and 3
    from rrr_pin.control.analysis import _derivatives, _mats, _parameters, _scaled

    model = rrr.model
    Mhat, Ghat = _mats(rrr, model, Q)
    for _, j, k in _parameters(model):
        dM, dG = _derivatives(rrr, model, Q, j, k)
        for f in (0.1, 3.0):
            M, G = _mats(rrr, _scaled(model, {(j, k): f}), Q)
            assert_allclose(Mhat + (f - 1) * dM, M, rtol=0, atol=1e-12 * np.abs(M).max())
            assert_allclose(Ghat + (f - 1) * dG, G, rtol=0, atol=1e-9 * max(1, np.abs(G).max()))


def test_cli_robstab_at_tol_2_is_the_closed_form(capsys, monkeypatch):
    # Before: margin 1.6e-33. Closed form: on the vertex with every factor 1 - tol alpha, the
    # third link's mass and moments vanish together at alpha = 1 / tol, and M(q) is singular.
    # That loss is at infinite frequency, which robstab evaluates apart from its grid (the
    # limit D); the default 31-point grid gives the same margins (measured: 0.49751, 0.5, inf)
    # in 23.8 s of CPU, two points in 2.1 s, so the CLI runs here on two.
    import rrr_pin.robust.mu as mu

    monkeypatch.setattr(mu, "_default_omega", lambda sys: np.array([0.0, 10.0]))
    assert cli.main(["robstab", "--home", "0.3,0.6,-0.9", "--tol", "2", "--controllers", "fl",
                     "--samples", "8", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)["laws"]["fl"]
    assert_allclose(r["sampled_margin"], 0.5, rtol=1e-4)  # the sweep's bisection: 1e-4
    assert_allclose(r["margin_upper"], 0.5, rtol=1e-9)
    assert 0.99 * 0.5 <= r["margin_lower"] <= 0.5  # mu's real upper bound: within 1 %
    assert r["critical_frequency_rad_s"] is None  # strict JSON: inf is null, with its status
    assert r["critical_frequency_rad_s_status"] == "infinite"


def test_cli_margins_figure_names_the_laws_and_the_configuration(tmp_path, capsys, monkeypatch):
    # before: margins.png named neither the controller nor the configuration (issue 31)
    import rrr_pin.report.margins as rm

    titles = []
    real = rm.margins_figure
    monkeypatch.setattr(rm, "margins_figure",
                        lambda loops, omega=None, title=None: titles.append(title) or
                        real(loops, omega, title))
    assert cli.main(["margins", "--home", "0.3,0.6,-0.9", "--controllers", "fl",
                     "--out", str(tmp_path / "m")]) == 0
    assert titles == ["rrr: fl loops at the torque input, frozen at q = [0.3, 0.6, -0.9] rad"]
    assert (tmp_path / "m" / "margins.png").stat().st_size > 0


def test_refined_disk_margin_finds_the_peak_between_grid_points():
    # issue 50: the disk-margin requirement was verified on a frequency grid (0.4753 where a
    # finer grid gives 0.4739). A SISO loop with a sharp sensitivity peak between the points of
    # a coarse grid: the refined value equals the closed-form minimum of 1/|S - 1/2| (found
    # here by a dense evaluation of the transfer function in numpy and a bounded search on
    # it), the grid's does not; for a SISO loop the certified H-inf bound is the same number.
    from scipy.optimize import minimize_scalar

    from rrr_pin.control.analysis import refined_disk_margin

    wn, zeta = 10.0, 0.08  # lightly damped: |S| peaks sharply near wn
    L = control.ss(control.tf([wn**2], [1.0, 2 * zeta * wn, 0.0]))

    def inv_gap(logw):
        c = wn**2 / ((1j * np.exp(logw)) ** 2 + 2 * zeta * wn * 1j * np.exp(logw))
        return 1.0 / np.abs(1.0 / (1.0 + c) - 0.5)

    x = np.linspace(np.log(1e-2), np.log(1e3), 20001)
    k = int(np.argmin(inv_gap(x)))  # numpy evaluates the array at once
    exact = minimize_scalar(inv_gap, bounds=(x[max(k - 1, 0)], x[k + 1]), method="bounded",
                            options={"xatol": 1e-12}).fun
    m = refined_disk_margin(L, np.logspace(-2, 3, 40))
    assert m.grid > exact * (1 + 1e-3)  # the coarse grid misses the peak
    assert_allclose(m.alpha, exact, rtol=1e-8)  # refined: Brent to 1e-6 in log w
    assert_allclose(m.lower, exact, rtol=1e-5)  # AB13DD's tolerance (1e-6 relative on the norm)
    assert m.lower <= m.alpha <= m.grid

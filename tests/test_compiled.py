"""The compiled rollout (rrr_pin.compiled) against a plain-Python loop of the same specification."""

import math
from dataclasses import replace

import control
import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from rrr_pin import paper_params
from rrr_pin.compiled import (
    DIVERGENCE_BOUND,
    _rollout,
    available,
    compile_robot,
    floor_ms,
    rollout_compiled,
)
from rrr_pin.dynamics import load_robot
from rrr_pin.simulate import SimulationDiverged

TS = 1e-3  # control period [s] (1 kHz)
LAM = 100.0  # FL bandwidth [rad/s], the paper's value for FL alone


def reference_rollout_python(plant, nominal, lam, mats, home, amp, omega, phase, Ts, substeps,
                             n_steps, bound=DIVERGENCE_BOUND):
    """Independent plain-Python reference of the compiled rollout's specification.

    Returns (q, qd, tau, e, diverged_step); diverged_step is None for a run that stays bounded.
    """
    Ad, Bd, Cd, Dd = mats
    n = plant.nq
    pm, pd = plant.model, plant.model.createData()
    nm, nd = nominal.model, nominal.model.createData()

    def ref(t):
        arg = omega * t + phase
        return (home + amp * np.sin(arg), amp * omega * np.cos(arg),
                -amp * omega**2 * np.sin(arg))

    def f(q, qd, tau):
        return qd, pin.aba(pm, pd, q, qd, tau).copy()

    h = Ts / substeps
    Q, QD = np.full((n_steps + 1, n), np.nan), np.full((n_steps + 1, n), np.nan)
    TAU, E = np.full((n_steps, n), np.nan), np.full((n_steps, n), np.nan)
    r0, rd0, _ = ref(0.0)
    q, qd, x = r0.copy(), rd0.copy(), np.zeros(Ad.shape[0])
    Q[0], QD[0] = q, qd
    for k in range(n_steps):
        r, rd, rdd = ref(k * Ts)
        e = r - q
        y = Cd @ x + Dd @ e
        x = Ad @ x + Bd @ e
        taubar = rdd + 2.0 * lam * (rd - qd) + lam**2 * (e + y)
        Mu = pin.crba(nm, nd, q)
        M = np.triu(Mu) + np.triu(Mu, 1).T
        tau = M @ taubar + pin.nonLinearEffects(nm, nd, q, qd)
        TAU[k], E[k] = tau, e
        for _ in range(substeps):
            k1 = f(q, qd, tau)
            k2 = f(q + 0.5 * h * k1[0], qd + 0.5 * h * k1[1], tau)
            k3 = f(q + 0.5 * h * k2[0], qd + 0.5 * h * k2[1], tau)
            k4 = f(q + h * k3[0], qd + h * k3[1], tau)
            q = q + h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0])
            qd = qd + h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1])
        Q[k + 1], QD[k + 1] = q, qd
        if not (np.all(np.abs(q) <= bound) and np.all(np.abs(qd) <= bound)):
            return Q, QD, TAU, E, k + 1
    return Q, QD, TAU, E, None


def hinf_kd(n, Ts=TS):
    """The paper's H-infinity controller, eq. (18), Tustin at Ts, one copy per joint."""
    K = control.ss(control.tf([47.4, 47.4 * (134.75 + 12.17), 47.4 * 134.75 * 12.17],
                              [1.0, 513.37 + 0.19, 513.37 * 0.19]))
    K1 = control.c2d(K, Ts, "tustin")
    return control.append(*([K1] * n))


def mats_of(Kd, n):
    if Kd is None:
        return np.zeros((0, 0)), np.zeros((0, n)), np.zeros((n, 0)), np.zeros((n, n))
    return tuple(np.asarray(m, dtype=float) for m in (Kd.A, Kd.B, Kd.C, Kd.D))


@pytest.fixture(scope="module")
def rrr():
    return load_robot("rrr")


@pytest.fixture(scope="module")
def rrr_heavy():
    params = paper_params()
    links = tuple(replace(link, mass=1.1 * link.mass) for link in params.links)
    return load_robot(replace(params, links=links, name="rrr_heavy"))


@pytest.fixture(scope="module")
def ur5():
    return load_robot("ur5")


def reference_params(n):
    """A sinusoid per joint, within every arm's limits; phases so joints do not move alike."""
    home = np.linspace(-0.4, 0.6, n)
    amp = np.full(n, 0.3)
    omega = 2.0 * math.pi * np.linspace(0.3, 0.8, n)
    phase = np.linspace(0.0, 1.5, n)
    return home, amp, omega, phase


CASES = [
    ("rrr", "rrr_heavy", False, 1),
    ("rrr", "rrr_heavy", True, 1),
    ("rrr", "rrr_heavy", True, 3),
    ("ur5", "ur5", False, 1),
    ("ur5", "ur5", True, 1),
]


@pytest.mark.parametrize("nominal_name, plant_name, with_k, substeps", CASES,
                         ids=["rrr-heavy-FL", "rrr-heavy-Hinf", "rrr-heavy-Hinf-S3",
                              "ur5-FL", "ur5-Hinf"])
def test_rollout_matches_python_reference(request, nominal_name, plant_name, with_k, substeps):
    nominal, plant = request.getfixturevalue(nominal_name), request.getfixturevalue(plant_name)
    n = plant.nq
    Kd = hinf_kd(n) if with_k else None
    home, amp, omega, phase = reference_params(n)
    n_steps = 2000  # 2 s at 1 kHz
    out = rollout_compiled(plant, nominal, LAM, Kd, home, amp, omega, phase, TS, substeps,
                           n_steps)
    Q, QD, TAU, E, bad = reference_rollout_python(plant, nominal, LAM, mats_of(Kd, n), home,
                                                  amp, omega, phase, TS, substeps, n_steps)
    assert bad is None and out["status"] == "ok" and out["diverged_step"] is None
    assert out["q"].shape == (n_steps + 1, n) and out["tau"].shape == (n_steps, n)
    assert_array_equal(out["t"], TS * np.arange(n_steps + 1))
    # Same operations in a different order (Eigen vs numpy, RK4 sums): round-off of ~1e-16 per
    # step, which the stable closed loop does not amplify (measured: q within 1e-16 rad, qd
    # 5e-14 rad/s); 1e-9 rad on q is the specification.
    assert_allclose(out["q"], Q, rtol=0.0, atol=1e-9)
    assert_allclose(out["qd"], QD, rtol=0.0, atol=1e-9)
    assert_allclose(out["e"], E, rtol=0.0, atol=1e-9)
    # tau (up to 310 N m) carries that round-off times lam^2 M and K's gain (measured 1.3e-10).
    assert_allclose(out["tau"], TAU, rtol=0.0, atol=1e-8)
    # The loop really tracks (the comparison is not between two idle runs).
    assert np.ptp(out["q"], axis=0).min() > 0.3


def test_rollout_accepts_matrices_and_compiled_robots(rrr, rrr_heavy):
    Kd = hinf_kd(3)
    a = rollout_compiled(rrr_heavy, rrr, LAM, Kd, *reference_params(3), TS, 1, 200)
    b = rollout_compiled(compile_robot(rrr_heavy), compile_robot(rrr), LAM, mats_of(Kd, 3),
                         *reference_params(3), TS, 1, 200)
    assert_array_equal(a["q"], b["q"])


@pytest.mark.parametrize("name", ["rrr", "ur5"])
def test_models_pass_exactly(name):
    robot = load_robot(name)
    text = robot.model.saveToString()
    assert _rollout.CompiledModel(text).save() == text


def test_infinite_limits_pass_exactly(rrr):
    """Continuous joints are loaded with infinite limits; the text archive keeps them."""
    model = rrr.model.copy()
    model.upperPositionLimit[:] = np.inf
    model.lowerPositionLimit[:] = -np.inf
    text = model.saveToString()
    back = pin.Model()
    back.loadFromString(_rollout.CompiledModel(text).save())
    assert back == model


def test_extension_built_against_installed_pinocchio():
    assert available(), "rrr_pin._rollout is not built: pip install ."
    assert _rollout.pinocchio_version() == pin.__version__


def test_divergence_raises_with_time_and_joint(rrr):
    # lam Ts = 20: the sampled FL loop is violently unstable.
    home, amp, omega, phase = reference_params(3)
    with pytest.raises(SimulationDiverged, match=r"diverged at t = .* s: joint 'joint\d'") as info:
        rollout_compiled(rrr, rrr, 2e4, None, home, amp, omega, phase, TS, 1, 1000)
    assert isinstance(info.value, RuntimeError)
    assert info.value.joint in rrr.joint_names and 0.0 < info.value.time <= 1.0


def test_divergence_status_without_exception(rrr):
    home, amp, omega, phase = reference_params(3)
    out = rollout_compiled(rrr, rrr, 2e4, None, home, amp, omega, phase, TS, 1, 1000,
                           raise_on_divergence=False)
    _, _, _, _, bad = reference_rollout_python(rrr, rrr, 2e4, mats_of(None, 3), home, amp,
                                               omega, phase, TS, 1, 1000)
    k = out["diverged_step"]
    assert out["status"] == "diverged" and k == bad
    assert out["diverged_time"] == pytest.approx(k * TS)
    j = rrr.joint_names.index(out["diverged_joint"])
    row = np.concatenate([out["q"][k], out["qd"][k]])
    assert not np.all(np.abs(row) <= DIVERGENCE_BOUND)
    assert not (np.abs(out["q"][k, j]) <= DIVERGENCE_BOUND
                and np.abs(out["qd"][k, j]) <= DIVERGENCE_BOUND)
    assert np.all(np.isfinite(out["q"][:k])) and np.all(np.isnan(out["q"][k + 1:]))


@pytest.mark.parametrize("kwargs, match", [
    ({"Kd": control.c2d(control.ss(-1.0, 1.0, 1.0, 0.0), 2e-3) * np.eye(3)}, "dt"),
    ({"Kd": control.ss(-1.0, 1.0, 1.0, 0.0) * np.eye(3)}, "dt"),
    ({"Kd": (np.zeros((1, 1)), np.zeros((1, 2)), np.zeros((3, 1)), np.zeros((3, 3)))}, "Bd"),
    ({"amp": [0.1, 0.2]}, "amp"),
    ({"phase": [0.0, np.nan, 0.0]}, "phase"),
    ({"Ts": 0.0}, "Ts"),
    ({"substeps": 0}, "substeps"),
], ids=["Kd-dt", "Kd-continuous", "Bd-shape", "amp-shape", "phase-nan", "Ts", "substeps"])
def test_invalid_inputs(rrr, kwargs, match):
    home, amp, omega, phase = reference_params(3)
    args = {"lam": LAM, "Kd": None, "home": home, "amp": amp, "omega": omega, "phase": phase,
            "Ts": TS, "substeps": 1, "n_steps": 10} | kwargs
    with pytest.raises(ValueError, match=match):
        rollout_compiled(rrr, rrr, **args)


def test_plant_and_nominal_sizes_must_agree(rrr, ur5):
    with pytest.raises(ValueError, match="joints"):
        rollout_compiled(ur5, rrr, LAM, None, 0.0, 0.1, 1.0, 0.0, TS, 1, 10)


def test_floor_ms(rrr, rrr_heavy):
    ms = floor_ms(rrr_heavy, rrr, n_steps=1000, substeps=1, repeat=2)
    assert 0.0 < ms < 1e4


def test_concurrent_rollouts_share_compiled_robots(rrr, rrr_heavy):
    """The extension releases the GIL and each call has its own workspace (pinocchio.Data)."""
    from concurrent.futures import ThreadPoolExecutor

    plant, nominal = compile_robot(rrr_heavy), compile_robot(rrr)
    home, amp, omega, phase = reference_params(3)
    amps = [0.1, 0.2, 0.3, 0.4]

    def run(a):
        return rollout_compiled(plant, nominal, LAM, hinf_kd(3), home, a, omega, phase, TS, 1,
                                500)["q"]

    sequential = [run(a) for a in amps]
    with ThreadPoolExecutor(max_workers=2) as pool:
        concurrent = list(pool.map(run, amps))
    for s, c in zip(sequential, concurrent, strict=True):
        assert_array_equal(c, s)


# --- the package's Python reference path (rrr_pin.simulate) against the compiled path --------

@pytest.mark.parametrize("name", ["rrr", "ur5"])
def test_simulate_engines_agree(name):
    import dataclasses

    from rrr_pin import default_reference, design, fl_controller, hinf_fl_controller, simulate
    from rrr_pin.dh import paper_params

    nominal = load_robot(name)
    if name == "rrr":
        p = paper_params()
        plant = load_robot(p.with_links([dataclasses.replace(lk, mass=1.1 * lk.mass)
                                         for lk in p.links]))
    else:
        plant = nominal
    K = design(n=nominal.nq).K_reduced
    ref = default_reference(nominal)
    for ctrl in (fl_controller(nominal), hinf_fl_controller(nominal, K)):
        a = simulate(plant, ctrl, ref, 2.0, rate=1000.0, engine="python")
        b = simulate(plant, ctrl, ref, 2.0, rate=1000.0, engine="compiled")
        # Same algorithm, same operation order up to Eigen vs numpy round-off.
        assert_allclose(b.q, a.q, rtol=0, atol=1e-9)
        assert_allclose(b.tau, a.tau, rtol=1e-9, atol=1e-8)

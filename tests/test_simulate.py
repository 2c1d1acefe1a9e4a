from dataclasses import dataclass

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.control.effects import PlantEffects
from rrr_pin.control.laws import (
    ControlLaw,
    SampledLaw,
    TrackingController,
    fl_controller,
    hinf_fl_controller,
    pd_controller,
)
from rrr_pin.control.references import SineReference, default_reference, study_reference
from rrr_pin.model.dh import ArmParams, paper_params
from rrr_pin.model.dynamics import load_robot
from rrr_pin.model.plant import CAPABILITIES, JOINT_LIMITS, CapabilityError
from rrr_pin.model.uncertainty import sample_plants
from rrr_pin.sim.simulation import simulate
from rrr_pin.sim.trajectory import REASONS, SimulationDiverged, metrics

K18 = control.tf([47.40, 47.40 * (134.75 + 12.17), 47.40 * 134.75 * 12.17],
                 [1.0, 513.37 + 0.19, 513.37 * 0.19])


@pytest.fixture(scope="module")
def setup(rrr):
    nominal = rrr
    sample = sample_plants(paper_params(), 1, seed=0)[0]
    plant = load_robot(ArmParams.from_dict(sample.parameters["params"]))
    controllers = {"fl": fl_controller(nominal), "hinf": hinf_fl_controller(nominal, K18)}
    return nominal, plant, controllers, default_reference(nominal)


@pytest.mark.parametrize("key", ["fl", "hinf"])
@pytest.mark.parametrize("rate", [None, 1000.0], ids=["continuous", "sampled-1kHz"])
def test_exact_model_tracks(setup, key, rate):
    nominal, _, controllers, ref = setup
    traj = simulate(nominal, controllers[key], ref, 2.0, rate=rate)
    # Continuous laws: only the RK4 truncation remains (~1e-9 rad). Sampled at 1 kHz: the
    # zero-order hold itself leaves ~1e-7 rad. The uncertain plants' errors are ~1e-5..1e-4 rad.
    bound = 1e-8 if rate is None else 2e-6
    assert np.max(np.abs(traj.error)) < bound


@pytest.mark.parametrize("engine", ["python", "auto"])
@pytest.mark.parametrize("dt, atol", [(1e-3, 1e-7), (1e-4, 1e-9)], ids=["dt-1ms", "dt-0.1ms"])
def test_fl_transient_follows_the_closed_form(setup, engine, dt, atol):
    # FL on the exact model, started off the reference: each joint's error obeys
    # e'' + 2 lam e' + lam^2 e = 0 (eq. 10), whose solution for e(0) = e0, e'(0) = ed0 is
    # e(t) = (e0 + (lam e0 + ed0) t) exp(-lam t) (critically damped second-order system).
    nominal, _, controllers, ref = setup
    lam = controllers["fl"].lam
    r0, rd0, _ = ref(0.0)
    e0, ed0 = np.array([0.02, -0.01, 0.015]), np.array([0.5, 0.2, -0.3])
    traj = simulate(nominal, controllers["fl"], ref, 0.1, dt=dt, q0=r0 - e0, qd0=rd0 - ed0,
                    engine=engine)
    t = traj.t[:, None]
    expected = (e0 + (lam * e0 + ed0) * t) * np.exp(-lam * t)
    # RK4's global error scales as (lam dt)^4: lam dt = 0.1 (the default 1 ms step) leaves
    # ~3e-8 rad, lam dt = 0.01 ~3e-12 rad; the README states both bounds (1e-7 and 1e-9 rad).
    assert_allclose(traj.error, expected, atol=atol)


def test_halving_the_step_changes_errors_far_less_than_the_study_differences(setup):
    _, plant, controllers, ref = setup
    runs = {k: [simulate(plant, c, ref, 2.0, dt=dt) for dt in (1e-3, 5e-4)]
            for k, c in controllers.items()}
    change = max(np.max(np.abs(a.error - b.error[::2])) for a, b in runs.values())
    # The smallest difference the study reports: FL vs Hinf+FL RMS error, per joint.
    rms = {k: np.array(metrics(v[1])["rms_error"]) for k, v in runs.items()}
    smallest = np.min(np.abs(rms["fl"] - rms["hinf"]))
    assert smallest > 1e-5
    assert change < 1e-3 * smallest


def test_sampled_approaches_continuous(setup):
    # A zero-order-hold law at a high rate converges to the continuous one (first order in Ts).
    _, plant, controllers, ref = setup
    cont = simulate(plant, controllers["hinf"], ref, 1.0, dt=2.5e-4)
    gaps = []
    for rate in (1000.0, 4000.0):
        samp = simulate(plant, controllers["hinf"], ref, 1.0, rate=rate, dt=2.5e-4)
        step = int(round(1.0 / rate / 2.5e-4))
        gaps.append(np.max(np.abs(samp.error - cont.error[::step])))
    assert gaps[1] < gaps[0] / 2.5


@pytest.mark.parametrize("engine", ["python", "compiled"])
def test_divergence_names_time_and_joint(setup, engine):
    nominal, _, _, ref = setup
    # A static K = -3 makes the error dynamics s^2 + 2 lam s - 2 lam^2 unstable.
    bad = TrackingController(nominal=nominal, lam=45.0, K=control.ss([], [], [], [[-3.0]]))
    with pytest.raises(SimulationDiverged, match=r"diverged at t = .* s: joint 'joint\d'"):
        simulate(nominal, bad, ref, 2.0, engine=engine)


def test_step_too_large_for_fast_controller(setup):
    nominal, _, _, ref = setup
    fast = TrackingController(nominal=nominal, lam=45.0, K=control.tf([1.0], [1.0, 1e4]))
    with pytest.raises(ValueError, match="too large for the controller's fastest pole"):
        simulate(nominal, fast, ref, 0.1, dt=1e-3)


@pytest.mark.parametrize("kwargs,message", [
    ({"duration": 0.0}, r"duration must be a finite number > 0 \[s\], got 0\.0"),
    ({"duration": float("nan")}, r"duration must be a finite number > 0 \[s\], got nan"),
    ({"duration": 1.0, "dt": -1.0}, r"dt must be a finite number > 0 \[s\], got -1\.0"),
    ({"duration": 1.0, "rate": 0.0}, r"rate must be a finite number > 0 \[Hz\], got 0\.0"),
    ({"duration": 1e-4, "rate": 1000.0}, "shorter than one control period"),
    ({"duration": 1e-4}, "shorter than one RK4 step"),
    ({"duration": 1.0, "limit_margin": float("nan")},
     r"limit_margin must be a finite number >= 0 \[rad\], got nan"),
    ({"duration": 1.0, "q0": [0.0, 0.0]}, r"Expected q0 of shape \(3,\)"),
    ({"duration": 1.0, "q0": [0.0, 0.0, 4.0]}, "initial state of joint 'joint3'"),
    ({"duration": 1.0, "engine": "fast"}, "engine must be one of"),
], ids=["duration", "duration-nan", "dt", "rate", "short-sampled", "short-continuous",
        "margin-nan", "q0-size", "q0-limits", "engine"])
def test_bad_arguments(setup, kwargs, message):
    nominal, _, controllers, ref = setup
    with pytest.raises(ValueError, match=message):
        simulate(nominal, controllers["fl"], ref, **kwargs)


def test_reference_outside_limits_refused_up_front(setup):
    nominal, _, controllers, _ = setup
    ref = SineReference(home=[0.0, 0.0, 3.0], amp=0.5, freq=0.5, phase=0.0)
    with pytest.raises(ValueError, match="reference for joint 'joint3' spans"):
        simulate(nominal, controllers["fl"], ref, 1.0)


def test_wrong_types(setup):
    nominal, _, controllers, ref = setup
    with pytest.raises(TypeError, match="must subclass rrr_pin.ControlLaw"):
        simulate(nominal, object(), ref, 1.0)
    with pytest.raises(TypeError, match="reference must be a rrr_pin Reference"):
        simulate(nominal, controllers["fl"], lambda t: t, 1.0)


def test_package_function_is_not_shadowed_by_a_module():
    # rrr_pin.simulate is the function even after every submodule has been imported (a
    # submodule of the same name would replace it on the package).
    import rrr_pin
    import rrr_pin.campaign.runner  # noqa: F401
    import rrr_pin.campaign.study  # noqa: F401

    assert callable(rrr_pin.simulate) and rrr_pin.simulate.__module__ == "rrr_pin.sim.simulation"


@pytest.mark.parametrize("rate", [None, 500], ids=["continuous", "sampled"])
def test_trusted_settings_give_the_same_run(setup, rate):
    # check=False (settings validated by the caller, e.g. RunSettings) skips only the scalar
    # checks; ints are still converted, so the run and its record are the same, bit for bit.
    nominal, _, controllers, ref = setup
    a = simulate(nominal, controllers["fl"], ref, 1, dt=0.002, rate=rate, engine="python")
    b = simulate(nominal, controllers["fl"], ref, 1, dt=0.002, rate=rate, engine="python",
                 check=False)
    assert np.array_equal(a.q, b.q) and np.array_equal(a.tau, b.tau)
    assert a.info == b.info and repr(a.info) == repr(b.info)


# --- the time grid: realized exactly or refused, and bounded (issue 24) -----------------------

@pytest.mark.parametrize("duration, dt, rate, grid", [
    (10.0, None, 1000.0, (10000, 1, 1e-3)),
    (2.0, 1e-4, 1000.0, (2000, 10, 1e-4)),
    (0.3, 0.1, None, (3, 1, 0.1)),  # 0.3 / 0.1 = 2.9999999999999996 in floats: 3 steps
    (10.0, None, 300.0, (3000, 4, 1.0 / 1200.0)),  # the largest divisor of 1/300 s <= 1 ms
], ids=["default-1khz", "sub-steps", "decimal-roundoff", "default-300hz"])
def test_time_grid_realizes_the_settings(duration, dt, rate, grid):
    from rrr_pin.sim.simulation import time_grid

    g = time_grid(duration, dt, rate)
    assert (g.n_steps, g.substeps) == grid[:2]
    assert_allclose(g.h, grid[2], rtol=1e-15, atol=0)  # Ts / substeps, to round-off


def test_a_sampled_run_uses_the_sub_step_it_records(setup):
    rrr, _, _, ref = setup
    traj = simulate(rrr, fl_controller(rrr), ref, 0.05, rate=300.0)
    assert traj.info["substeps"] == 4 and traj.info["dt"] == 1.0 / 300.0 / 4
    assert_allclose(traj.t[-1], 15 / 300.0, rtol=1e-15)  # 0.05 s = 15 periods of 1/300 s


@pytest.mark.parametrize("kwargs, match", [
    ({"duration": 0.0015, "rate": 1000.0},
     r"duration = 0.0015 s is not a whole number of control periods 1/rate = 0.001 s"),
    ({"duration": 0.1, "rate": 1000.0, "dt": 3e-4}, r"dt = 0.0003 s does not divide"),
    ({"duration": 0.1, "rate": 1000.0, "dt": 0.5}, r"dt = 0.5 s does not divide"),
    ({"duration": 0.0105, "dt": 1e-3}, r"duration = 0.0105 s is not a whole number of RK4"),
], ids=["duration-sampled", "dt-sampled", "dt-above-period", "duration-continuous"])
def test_simulate_refuses_settings_off_the_grid(setup, kwargs, match):
    rrr, _, _, ref = setup
    duration = kwargs.pop("duration")
    with pytest.raises(ValueError, match=match):
        simulate(rrr, fl_controller(rrr), ref, duration, **kwargs)


def test_work_bound_and_force(setup, monkeypatch):
    from rrr_pin.sim import simulation

    rrr, _, _, ref = setup
    monkeypatch.setattr(simulation, "MAX_SUBSTEPS", 50)
    # 0.01 s at 1 kHz with 10 sub-steps: 100 RK4 steps > 50.
    with pytest.raises(ValueError, match=r"^duration = 0.01 s at rate = 1000 Hz is 10 control "
                                         r"periods of 10 RK4 sub-step\(s\) h = 0.0001 s: 100 "
                                         r"RK4 steps"):
        simulate(rrr, fl_controller(rrr), ref, 0.01, rate=1000.0, dt=1e-4)
    traj = simulate(rrr, fl_controller(rrr), ref, 0.01, rate=1000.0, dt=1e-4, force=True)
    assert traj.q.shape == (11, 3)
    monkeypatch.setattr(simulation, "MAX_SAMPLES", 5)
    with pytest.raises(ValueError, match=r"11 stored samples \(about 0\.002992 MB for 3 joints\)"):
        simulate(rrr, fl_controller(rrr), ref, 0.01)  # continuous: 10 steps, 11 samples


def test_limit_margin_needs_joint_limits(fivebar):
    # A closed chain's actuated joints have no position limits (the loop sets the
    # workspace): a margin beyond them is refused by that capability, before any step.
    assert not fivebar.has(JOINT_LIMITS)
    with pytest.raises(CapabilityError, match=rf"limit_margin = 0.1 rad needs "
                                              rf"{CAPABILITIES[JOINT_LIMITS]}, which the closed "
                                              rf"chain 'fivebar' does not have"):
        simulate(fivebar, fl_controller(fivebar), study_reference(fivebar, 0.5), 0.01,
                 rate=1000.0, limit_margin=0.1)


def test_auto_engine_choice_is_logged_with_its_reason(caplog):
    import logging

    from rrr_pin.control.laws import ControlLaw

    robot = load_robot("rrr")
    ref = default_reference(robot)

    class Hold(ControlLaw):
        name, n = "hold", 3

        def torque(self, t, q, qd, r, rd, rdd, x):
            return robot.G(q)

    with caplog.at_level(logging.DEBUG, logger="rrr_pin.sim.simulation"):
        fl = simulate(robot, fl_controller(robot), ref, 0.01, dt=1e-3)
        hold = simulate(robot, Hold(), ref, 0.01, dt=1e-3)
    said = [r.getMessage() for r in caplog.records if r.getMessage().startswith("engine for")]
    # the engine named is the one the run records as used, with the same reason
    assert said[0] == f"engine for law 'fl': {fl.info['engine']} ({fl.info['engine_note']})"
    assert hold.info["engine"] == "python"
    assert "law 'hold' (Hold) declares no compiled form" in hold.info["engine_note"]
    assert said[1] == f"engine for law 'hold': python ({hold.info['engine_note']})"


# --- a user's law that returns the wrong thing (issue 24) -----------------------------------

class _Out(ControlLaw):
    """A static law whose torque is ``out(t, pd_torque)`` (the wrong thing under test)."""

    def __init__(self, nominal, out, name="mylaw"):
        object.__setattr__(self, "pd", pd_controller(nominal))
        object.__setattr__(self, "out", out)
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "n", nominal.nq)

    def torque(self, t, q, qd, r, rd, rdd, x):
        return self.out(t, self.pd.torque(t, q, qd, r, rd, rdd, x))


class _SampledOut(SampledLaw):
    """The same as a SampledLaw of its own (step returns ``(out(...), x)``)."""

    def __init__(self, nominal, out, name="mysampled"):
        self.pd, self.out, self.name, self.n = pd_controller(nominal), out, name, nominal.nq

    def step(self, t, q, qd, r, rd, rdd, x):
        return self.out(t, self.pd.torque(t, q, qd, r, rd, rdd, x)), x


WRONG_OUTPUTS = {
    "scalar": (lambda t, tau: 1.0, r"1\.0 \(float\)"),
    "None": (lambda t, tau: None, r"None \(NoneType\)"),
    "list": (lambda t, tau: tau.tolist(), r"\[.*\] \(list\)"),
    "shape (4,)": (lambda t, tau: np.zeros(4), r"an array of shape \(4,\) and dtype float64"),
    "shape (3, 1)": (lambda t, tau: tau[:, None], r"an array of shape \(3, 1\) and dtype float64"),
    "int dtype": (lambda t, tau: np.zeros(3, dtype=int), r"an array of shape \(3,\) and dtype "
                                                          r"int64"),
    "NaN": (lambda t, tau: tau * np.nan, r"the non-finite \[nan, nan, nan\]"),
    "inf": (lambda t, tau: tau + np.inf, r"the non-finite \[inf, inf, inf\]"),
}


@pytest.mark.parametrize("out, words", WRONG_OUTPUTS.values(), ids=WRONG_OUTPUTS.keys())
@pytest.mark.parametrize("kind, rate", [("continuous", None), ("sampled form", 1000.0),
                                        ("SampledLaw", None)])
def test_a_wrong_first_output_is_refused_naming_the_law(setup, out, words, kind, rate):
    nominal, _, _, ref = setup
    law = _SampledOut(nominal, out) if kind == "SampledLaw" else _Out(nominal, out)
    method = "torque\\(\\)" if kind == "continuous" else "step\\(\\) torque"
    with pytest.raises(ValueError, match=rf"law '{law.name}' .*{method} returned {words} at "
                                         rf"t = 0 s; expected a finite float64 ndarray of "
                                         rf"shape \(3,\)"):
        simulate(nominal, law, ref, 0.05, rate=rate, engine="python")


def test_a_stateful_law_whose_derivative_has_the_wrong_shape_is_refused(setup):
    nominal, _, _, ref = setup

    @dataclass(frozen=True)
    class Leaky(ControlLaw):
        name: str = "leaky"
        n: int = 3
        nx: int = 2

        def initial_state(self):
            return np.zeros(2)

        def torque(self, t, q, qd, r, rd, rdd, x):
            return nominal.G(q)

        def derivative(self, t, q, qd, r, rd, rdd, x):
            return np.zeros(3)  # nx = 2

    with pytest.raises(ValueError, match=r"law 'leaky' \(Leaky\): derivative\(\) returned an "
                                         r"array of shape \(3,\)"):
        simulate(nominal, Leaky(), ref, 0.05, engine="python")


def _nan_after(t_nan):
    return lambda t, tau: tau if t < t_nan - 1e-12 else tau * np.nan


@pytest.mark.parametrize("kind, rate, t_stop", [
    # Sampled at 1 kHz: the law returns NaN at its call at t = 20 ms. Continuous, dt = 1 ms:
    # the 4th RK4 stage of the step from 19 ms is evaluated at 20 ms: that step stops the run.
    ("continuous", None, 0.019), ("sampled form", 1000.0, 0.02), ("SampledLaw", None, 0.02)])
def test_a_nan_torque_mid_run_stops_it_with_its_own_reason(setup, kind, rate, t_stop):
    nominal, _, _, ref = setup
    law = (_SampledOut if kind == "SampledLaw" else _Out)(nominal, _nan_after(0.02))
    with pytest.raises(SimulationDiverged) as info:
        simulate(nominal, law, ref, 0.05, rate=rate, engine="python")
    assert_allclose(info.value.time, t_stop, rtol=0, atol=1e-12)
    assert info.value.joint == "joint1"
    assert str(info.value) == (
        f"simulation of plant 'rrr' stopped at t = {t_stop:g} s: law '{law.name}' returned a "
        f"non-finite torque (NaN or inf) for joint 'joint1' in the step from t = {t_stop:g} s")
    assert REASONS[3] == "got a non-finite torque (NaN or inf) from the law"


def test_a_nan_torque_at_the_last_sample_stops_a_continuous_run(setup):
    # The torque at t = duration drives no RK4 step, yet it is in the trajectory (and its RMS).
    # 50 RK4 steps call the law 4 times each; call 201 is the last sample's, and only it is NaN.
    nominal, _, _, ref = setup
    calls = []

    def out(t, tau):
        calls.append(t)
        return tau * np.nan if len(calls) == 201 else tau

    with pytest.raises(SimulationDiverged, match=r"stopped at t = 0\.05 s: law 'mylaw'"):
        simulate(nominal, _Out(nominal, out), ref, 0.05, engine="python")
    assert len(calls) == 201


@pytest.mark.parametrize("effects", [PlantEffects(delay=0.005), PlantEffects(torque_limit=1000.0)],
                         ids=["delay", "saturation"])
def test_a_nan_torque_is_caught_where_the_law_returns_it_with_effects(setup, effects):
    # A 5 ms delay holds the NaN back (a law's NaN at 48 ms would reach the plant after the
    # 50 ms run); a saturation would clip an inf. Either way the run stops at the law's call.
    nominal, _, _, ref = setup
    law = _Out(nominal, lambda t, tau: tau if t < 0.048 - 1e-12 else tau + np.inf)
    with pytest.raises(SimulationDiverged, match=r"stopped at t = 0\.048 s: law 'mylaw' "
                                                 r"returned a non-finite torque"):
        simulate(nominal, law, ref, 0.05, rate=1000.0, engine="python", effects=effects)


"""Plant effects (rrr_pin.control.effects): physics against closed forms, seeds, bad input.

The physics checks run on the RRR with joints 2 and 3 locked at 0: a single joint about the
vertical axis with constant inertia I = M(q)[0, 0] and no gravity torque, driven by a law that
commands a known torque. Its motion then has closed forms independent of the simulator.

On every kind of plant (a closed chain's effects act on its actuated joints): an effect set
that is off, or a torque limit that never acts, runs the ideal loop's numbers; a transport
delay of one control period is realized too by a law that applies its previous command (a
delay line written here, independent of the engines').
"""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.optimize import brentq

from rrr_pin.control.effects import EffectsError, PlantEffects
from rrr_pin.control.laws import SampledLaw, fl_controller
from rrr_pin.control.references import QuinticReference, default_reference, study_reference
from rrr_pin.model.dynamics import load_robot
from rrr_pin.sim.simulation import simulate
from rrr_pin.validation import FieldError

TS = 1e-3  # [s] control period (1 kHz)
C = 2.0  # [N m] commanded torque after t = 0


class StepTorque(SampledLaw):
    """Zero torque at t = 0, then ``c`` (so the delay line and the actuator start at rest)."""

    name, n, nx, rate = "step", 1, 0, 1.0 / TS

    def __init__(self, c):
        self.c = c

    def step(self, t, q, qd, r, rd, rdd, x):
        """Return the step torque."""
        return np.array([self.c if t > 0 else 0.0]), x


@pytest.fixture(scope="module")
def joint1():
    return load_robot("rrr", lock={"joint2": 0.0, "joint3": 0.0})  # its own model: locked


@pytest.fixture(scope="module")
def rest(joint1):
    """A reference that stays at 0 (only the plant's limits and the law's inputs use it)."""
    return QuinticReference(start=[0.0], goal=[0.0], move_time=1.0)


def run(joint1, rest, effects, c=C, duration=0.5, dt=1e-4, engine="python"):
    return simulate(joint1, StepTorque(c), rest, duration, dt=dt, effects=effects,
                    engine=engine)


def inertia(joint1):
    return float(joint1.M(np.zeros(1))[0, 0])


def test_first_order_actuator_matches_its_exponential(joint1, rest):
    # a(t) = C (1 - exp(-wa (t - Ts))) from t = Ts on, so
    # qd(t) = C / I ((t - Ts) - (1 - exp(-wa (t - Ts))) / wa).
    wa = 40.0
    traj = run(joint1, rest, PlantEffects(actuator_bandwidth=wa))
    s = np.maximum(traj.t - TS, 0.0)
    expected = C / inertia(joint1) * (s - (1.0 - np.exp(-wa * s)) / wa)
    # RK4 with h = 1e-4 s on a smooth exponential: error ~ (wa h)^4 ~ 3e-10 relative.
    assert_allclose(traj.qd[:, 0], expected, rtol=0, atol=1e-9)


def test_delay_shifts_the_torque(joint1, rest):
    # The step commanded at t = Ts arrives at Ts + 3.7 ms, realized as 37 sub-steps of 1e-4 s.
    traj = run(joint1, rest, PlantEffects(delay=3.7e-3))
    assert traj.info["effects"]["delay_s"] == pytest.approx(3.7e-3, abs=1e-12)
    s = np.maximum(traj.t - TS - 3.7e-3, 0.0)
    # Constant torque: RK4 is exact for qd linear in t; round-off only.
    assert_allclose(traj.qd[:, 0], C / inertia(joint1) * s, rtol=0, atol=1e-11)


@pytest.mark.parametrize("delay, dt, near", [
    (1.26e-3, 5e-4, "0.001 s and 0.0015 s"),
    (4e-4, 1e-3, "0 s and 0.001 s"),  # issue 24: ran with no delay at all
    (1.6e-3, 1e-3, "0.001 s and 0.002 s"),  # issue 24: ran as 2 ms
], ids=["between", "below-one-step", "above-one-step"])
def test_a_delay_off_the_sub_step_grid_is_refused(joint1, rest, delay, dt, near):
    with pytest.raises(FieldError, match=rf"delay = {delay:g} s is not a whole number of "
                                         rf"plant sub-steps h = {dt:g} s .*: the nearest "
                                         rf"realizable values are {near}"):
        run(joint1, rest, PlantEffects(delay=delay), dt=dt)


def test_a_delay_of_two_sub_steps_is_realized_exactly(joint1, rest):
    # 2 sub-steps of h = 2.5e-4 s: the step commanded at t = Ts reaches the joint 0.5 ms later
    # (closed form qd = C / I (t - Ts - 2 h), exact for RK4 up to round-off), and the run records
    # the delay it realized.
    h = 2.5e-4
    traj = run(joint1, rest, PlantEffects(delay=2 * h), dt=h, duration=0.01)
    assert traj.info["effects"]["delay_substeps"] == 2
    assert traj.info["effects"]["delay_s"] == 2 * h
    s = np.maximum(traj.t - TS - 2 * h, 0.0)
    assert_allclose(traj.qd[:, 0], C / inertia(joint1) * s, rtol=0, atol=1e-12)


class HoldPrevious(SampledLaw):
    """A law that applies, over period k, the command ``inner`` computed at period k - 1.

    Without plant effects this is the loop with a transport delay of exactly one period
    (before t = 0 the delay line holds the first command, so period 0 applies tau_0), written
    without the engines' delay line.
    """

    def __init__(self, inner):
        self.inner, self.previous = inner, None
        self.name, self.n, self.nx, self.rate = "hold", inner.n, inner.nx, inner.rate

    def initial_state(self):
        return self.inner.initial_state()

    def step(self, t, q, qd, r, rd, rdd, x):
        tau, x = self.inner.step(t, q, qd, r, rd, rdd, x)
        out = tau if self.previous is None else self.previous
        self.previous = tau
        return out, x


RATE, DT = 1000.0, 5e-4  # Hz, s: one control period is two sub-steps


def _run(plant, law, effects=None, duration=0.1, **kwargs):
    """``law`` on ``plant`` along its study reference (0.5 s), from 0.01 rad off it."""
    ref = study_reference(plant, 0.5)
    return simulate(plant, law, ref, duration, rate=RATE, dt=DT, q0=ref(0.0)[0] + 0.01,
                    effects=effects, **kwargs)


@pytest.mark.parametrize("plant, engine", [("rrr", "python"), ("rrr", "compiled"),
                                           ("fivebar", "python")],
                         indirect=["plant"], ids=["rrr-python", "rrr-compiled", "fivebar"])
def test_a_one_period_delay_equals_holding_the_previous_command(plant, engine):
    # A delay of 2 sub-steps of 5e-4 s = one control period of 1 ms, under FL.
    fl = fl_controller(plant).sampled(RATE)
    delayed = _run(plant, fl, PlantEffects(delay=1.0 / RATE), engine=engine)
    held = _run(plant, HoldPrevious(fl), engine="python")
    assert delayed.info["effects"]["delay_substeps"] == round(1.0 / RATE / DT)
    # Same RK4 arithmetic on both sides (the delay only picks which torque is held); the
    # compiled engine adds its round-off (test_engines pins the engines to 1e-9 rad).
    assert_allclose(delayed.q, held.q, rtol=0, atol=1e-9)
    # A trajectory records the commanded torque: the held law's is the delayed one's, one
    # period later (round-off of lam^2 M times the 1e-9 rad above)
    assert_allclose(held.tau[1:-1], delayed.tau[:-2], rtol=0,
                    atol=1e-12 if engine == "python" else 1e-5)
    ideal = _run(plant, fl, engine="python")
    assert np.abs(ideal.q - held.q).max() > 1e-6  # the delay changed the run


@pytest.mark.parametrize("plant, limit", [("rrr", 400.0), ("fivebar", 50.0)],
                         indirect=["plant"], ids=["rrr", "fivebar"])
def test_each_drive_effect_runs_and_is_recorded(plant, limit):
    # Mild effects of every drive kind at once (a limit above the reference's torques): the
    # loop still tracks; a plant that closes a loop records its drift, within its bound.
    fx = PlantEffects(actuator_bandwidth=2000.0, viscous=0.01, coulomb=0.01, torque_limit=limit,
                      noise_q=1e-5, encoder_counts=2 ** 18, seed=3)
    traj = _run(plant, fl_controller(plant, 100.0), fx)
    assert traj.info["effects"]["actuator_bandwidth_rad_s"] == 2000.0
    assert traj.info["effects"]["torque_limit_Nm"] == limit
    assert np.all(np.abs(traj.tau) <= limit)
    assert ("drift_m" in traj.info) == bool(plant.loop_closures)
    if plant.loop_closures:
        assert traj.info["drift_m"] <= traj.info["drift_bound_m"]
    assert np.sqrt(np.mean(traj.error ** 2)) < 0.02


def test_saturation_clips_the_torque(joint1, rest):
    traj = run(joint1, rest, PlantEffects(torque_limit=0.5), c=100.0)
    assert np.max(np.abs(traj.tau)) == 0.5
    s = np.maximum(traj.t - TS, 0.0)
    assert_allclose(traj.qd[:, 0], 0.5 / inertia(joint1) * s, rtol=0, atol=1e-11)


def test_urdf_effort_limits(joint1, rest):
    traj = run(joint1, rest, PlantEffects(torque_limit="urdf"), c=1e6, duration=0.01)
    assert np.max(traj.tau) == joint1.model.effortLimit[0]


def test_friction_on_a_free_joint_reaches_its_terminal_speed(joint1, rest):
    # I qdd = C - Fv qd - Fc tanh(qd / v_eps): the speed settles at the root of the right-hand
    # side (scipy's brentq), with time constant I / Fv = 0.53 s; after 8 s e^-15 is left.
    Fv, Fc, veps = 50.0, 0.5, 0.001
    traj = run(joint1, rest, PlantEffects(viscous=Fv, coulomb=Fc, coulomb_velocity=veps),
               duration=8.0, dt=1e-3)
    v_end = brentq(lambda v: C - Fv * v - Fc * math.tanh(v / veps), 0.0, 1.0)
    assert_allclose(traj.qd[-1, 0], v_end, rtol=1e-4)
    assert v_end == pytest.approx((C - Fc) / Fv, rel=1e-12)  # v_end >> v_eps


def test_flexible_joint_oscillates_at_its_two_mass_frequency(joint1, rest):
    # Link inertia I and motor inertia B on a spring K: the free mode has
    # w^2 = K (1/I + 1/B) (two-mass oscillator). The spring starts unloaded and a step C drives
    # the motor: the link acceleration is C/(I + B) plus an oscillation at w, whose frequency is
    # read from the zero crossings.
    K, B = 2000.0, 0.05
    traj = run(joint1, rest, PlantEffects(stiffness=K, motor_inertia=B), duration=0.3, dt=1e-5)
    I = inertia(joint1)
    w = math.sqrt(K * (1.0 / I + 1.0 / B))
    qdd = np.gradient(traj.qd[:, 0], traj.t)
    ac = qdd - C / (I + B)  # mean acceleration of the two masses
    ac = ac[traj.t > 2 * TS]
    t = traj.t[traj.t > 2 * TS]
    crossings = t[1:][np.diff(np.sign(ac)) != 0]
    period = 2.0 * np.mean(np.diff(crossings))
    # Zero crossings located to one sample (1 ms) over ~9 periods of 31 ms: ~1 %.
    assert_allclose(2 * math.pi / period, w, rtol=0.03)


def test_quantization_measures_whole_counts(joint1, rest):
    class Spy(SampledLaw):
        name, n, nx, rate = "spy", 1, 0, 1.0 / TS
        seen = []

        def step(self, t, q, qd, r, rd, rdd, x):
            self.seen.append(q[0])
            return np.array([50.0]), x  # q(0.2 s) = 0.04 rad, about 6 counts

    counts = 1000
    simulate(joint1, Spy(), rest, 0.2, dt=1e-4,
             effects=PlantEffects(encoder_counts=counts))
    steps = np.array(Spy.seen) / (2 * math.pi / counts)
    assert_allclose(steps, np.round(steps), rtol=0, atol=1e-9)
    assert len(np.unique(steps)) > 3  # the arm moved across several counts


def test_noise_runs_are_reproducible_from_the_seed(rrr):
    law, ref = fl_controller(rrr), default_reference(rrr)

    def once(seed, engine):
        fx = PlantEffects(noise_q=1e-3, noise_qd=1e-2, seed=seed)
        return simulate(rrr, law, ref, 0.2, rate=1000, effects=fx, engine=engine).q

    a, b, c = once(7, "auto"), once(7, "auto"), once(8, "auto")
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 1e-5
    # Same noise arrays reach the Python engine: same run to round-off (see test_engines).
    assert_allclose(once(7, "python"), a, rtol=0, atol=1e-9)


@pytest.mark.parametrize("kwargs, match", [
    ({"delay": -1e-3}, r"delay = -0.001: expected finite >= 0 \[s\]"),
    ({"delay": math.nan}, r"delay = nan"),
    ({"actuator_bandwidth": 0.0}, r"actuator_bandwidth = 0.0: expected finite > 0 \[rad/s\]"),
    ({"actuator_bandwidth": -5.0}, r"actuator_bandwidth = -5.0"),
    ({"stiffness": 0.0}, r"stiffness = 0.0"),
    ({"encoder_counts": 0}, r"encoder_counts = 0"),
    ({"seed": -1}, r"seed = -1"),
    ({"noise_q": [1e-3, math.inf]}, r"noise_q"),
], ids=["neg-delay", "nan-delay", "zero-bw", "neg-bw", "zero-K", "counts", "seed", "inf-noise"])
def test_bad_effects_name_the_field(kwargs, match):
    with pytest.raises(EffectsError, match=match):
        PlantEffects(**kwargs)


def test_every_bad_field_is_named_at_once():
    with pytest.raises(EffectsError, match=r"delay = -1.*actuator_bandwidth = 0"):
        PlantEffects(delay=-1, actuator_bandwidth=0)


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
def test_effects_refuse_a_continuous_law(plant):
    with pytest.raises(ValueError, match="sampled .digital. controllers only"):
        simulate(plant, fl_controller(plant), study_reference(plant, 0.5), 0.01,
                 effects=PlantEffects(delay=1e-3))


def test_wrong_joint_count_and_too_fast_actuator(rrr):
    law, ref = fl_controller(rrr), default_reference(rrr)
    with pytest.raises(EffectsError, match="viscous: expected one value or 3"):
        simulate(rrr, law, ref, 0.1, rate=1000, effects=PlantEffects(viscous=[1.0, 2.0]))
    with pytest.raises(EffectsError, match="too fast for the plant sub-step"):
        simulate(rrr, law, ref, 0.1, rate=1000, effects=PlantEffects(actuator_bandwidth=1e5))


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
@pytest.mark.parametrize("make, error, match", [
    (lambda n: PlantEffects(delay=2.5e-4), FieldError, r"delay = 0\.00025 s is not a whole "
                                                        r"number of plant sub-steps"),
    (lambda n: PlantEffects(viscous=(0.1,) * (n + 1)), EffectsError,
     r"viscous: expected one value or \d \(one per joint\)"),
    (lambda n: {"delay": 1e-3}, TypeError, "PlantEffects or None"),
], ids=["delay-between-substeps", "per-joint-size", "not-effects"])
def test_refused_effects_name_themselves(plant, make, error, match):
    with pytest.raises(error, match=match):
        _run(plant, fl_controller(plant), make(plant.nq))


def test_a_closed_chain_has_no_urdf_effort_limits(fivebar):
    # The arm's torque_limit="urdf" is test_urdf_effort_limits; an MJCF motor carries none.
    with pytest.raises(EffectsError, match=r"torque_limit = 'urdf': the closed chain 'fivebar' "
                                           r"has no URDF effort limits; give the limit \[N m\] "
                                           r"per actuated joint \(qa1, qa2\)"):
        _run(fivebar, fl_controller(fivebar), PlantEffects(torque_limit="urdf"))


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
def test_no_effect_is_the_ideal_run(plant):
    law = fl_controller(plant)
    a = _run(plant, law)
    for off in (PlantEffects(), PlantEffects(delay=0.0, viscous=0.0, noise_q=0.0)):
        b = _run(plant, law, off)
        np.testing.assert_array_equal(a.q, b.q)  # an inactive set is no effect: the same loop
        assert "effects" not in b.info
    # A torque limit far above any torque switches the effect engine on, and never acts: the
    # effect loop's RK4 (and a closed chain's projection) must then be the ideal loop's.
    wide = _run(plant, law, PlantEffects(torque_limit=1e9))
    assert wide.info["effects"]["torque_limit_Nm"] == 1e9
    np.testing.assert_allclose(wide.q, a.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(wide.tau, a.tau, rtol=0, atol=1e-9)


def test_the_old_name_bandwidth_still_works_with_a_deprecation_warning():
    # issue 50: Python spelled the actuator PlantEffects(bandwidth=...) where the command line
    # says --actuator-bandwidth; the field is actuator_bandwidth, the old name kept a while.
    with pytest.warns(DeprecationWarning, match="actuator_bandwidth"):
        old = PlantEffects(delay=0.001, bandwidth=300.0)
    assert old == PlantEffects(delay=0.001, actuator_bandwidth=300.0)
    with pytest.warns(DeprecationWarning, match="use actuator_bandwidth"):
        assert old.bandwidth == 300.0
    with pytest.raises(TypeError, match="not both"):
        PlantEffects(bandwidth=300.0, actuator_bandwidth=200.0)
    assert "actuator_bandwidth_rad_s" in old.to_dict()

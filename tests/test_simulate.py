import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.controllers import TrackingController, fl_controller, hinf_fl_controller
from rrr_pin.dh import ArmParams, paper_params
from rrr_pin.dynamics import load_robot
from rrr_pin.simulate import SimulationDiverged, SineReference, metrics, simulate
from rrr_pin.study import default_reference
from rrr_pin.uncertainty import sample_plants

K18 = control.tf([47.40, 47.40 * (134.75 + 12.17), 47.40 * 134.75 * 12.17],
                 [1.0, 513.37 + 0.19, 513.37 * 0.19])


@pytest.fixture(scope="module")
def setup():
    nominal = load_robot("rrr")
    sample = sample_plants(paper_params(), 1, seed=0)[0]
    plant = load_robot(ArmParams.from_dict(sample.parameters["params"]))
    controllers = {"fl": fl_controller(nominal), "hinf": hinf_fl_controller(nominal, K18)}
    return nominal, plant, controllers, default_reference(nominal)


def test_reference_derivatives_by_finite_differences():
    ref = SineReference(home=[0.1, -0.2], amp=[0.5, 0.3], freq=[0.5, 2.0], phase=[0.0, 1.0])
    h = 1e-5
    for t in (0.0, 0.37, 1.9):
        r_p, rd_p, _ = ref(t + h)
        r_m, rd_m, _ = ref(t - h)
        _, rd, rdd = ref(t)
        # central differences: error O(h^2 * third derivative) ~ 1e-10 * (2 pi 2)^3 ~ 2e-7
        assert_allclose((r_p - r_m) / (2 * h), rd, atol=1e-6)
        assert_allclose((rd_p - rd_m) / (2 * h), rdd, atol=1e-5)


@pytest.mark.parametrize("key", ["fl", "hinf"])
@pytest.mark.parametrize("rate", [None, 1000.0], ids=["continuous", "sampled-1kHz"])
def test_exact_model_tracks(setup, key, rate):
    nominal, _, controllers, ref = setup
    traj = simulate(nominal, controllers[key], ref, 2.0, rate=rate)
    # Continuous laws: only the RK4 truncation remains (~1e-9 rad). Sampled at 1 kHz: the
    # zero-order hold itself leaves ~1e-7 rad. The uncertain plants' errors are ~1e-5..1e-4 rad.
    bound = 1e-8 if rate is None else 2e-6
    assert np.max(np.abs(traj.error)) < bound


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


def test_divergence_names_time_and_joint(setup):
    nominal, _, _, ref = setup
    # A static K = -3 makes the error dynamics s^2 + 2 lam s - 2 lam^2 unstable.
    bad = TrackingController(nominal=nominal, lam=45.0, K=control.ss([], [], [], [[-3.0]]))
    with pytest.raises(SimulationDiverged, match=r"diverged at t = .* s: joint 'joint\d'"):
        simulate(nominal, bad, ref, 2.0)


def test_step_too_large_for_fast_controller(setup):
    nominal, _, _, ref = setup
    fast = TrackingController(nominal=nominal, lam=45.0, K=control.tf([1.0], [1.0, 1e4]))
    with pytest.raises(ValueError, match="too large for the controller's fastest pole"):
        simulate(nominal, fast, ref, 0.1, dt=1e-3)


@pytest.mark.parametrize("kwargs,message", [
    ({"duration": 0.0}, "duration must be > 0"),
    ({"duration": 1.0, "dt": -1.0}, "dt must be > 0"),
    ({"duration": 1.0, "rate": 0.0}, "rate must be > 0"),
], ids=["duration", "dt", "rate"])
def test_bad_arguments(setup, kwargs, message):
    nominal, _, controllers, ref = setup
    with pytest.raises(ValueError, match=message):
        simulate(nominal, controllers["fl"], ref, **kwargs)


def test_reference_outside_limits_refused(setup):
    nominal = setup[0]
    ref = SineReference(home=[0.0, 0.0, 3.0], amp=0.5, freq=0.5, phase=0.0)
    with pytest.raises(ValueError, match="reference for joint 'joint3' spans"):
        ref.check_limits(nominal)

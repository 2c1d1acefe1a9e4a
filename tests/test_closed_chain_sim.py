"""Simulation of parallel mechanisms on Pinocchio's constraint dynamics.

References: the exact model's FL error dynamics ``e'' + 2 lam e' + lam^2 e = 0`` (zero from a
zero initial error, so what is left is the integrator's); energy conservation of the passive
mechanism (its RK4 error measured against the step halved).
"""

from __future__ import annotations

import numpy as np
import pytest

from rrr_pin.control.laws import ControlLaw
from rrr_pin.control.laws import fl_controller as closed_chain_fl
from rrr_pin.control.references import SineReference
from rrr_pin.model import closed_chain as ccsim
from rrr_pin.model.closed_chain import LoopClosureError, SingularConfiguration, load_closed_chain
from rrr_pin.sim.simulation import simulate


@pytest.fixture(scope="module")
def pair():
    return load_closed_chain("fivebar"), load_closed_chain("fivebar")


class _Passive(ControlLaw):
    """Zero torque: the mechanism falls under gravity."""

    name, label, n, nx = "passive", "zero torque", 2, 0

    def torque(self, t, q, qd, r, rd, rdd, x):
        return np.zeros(2)


def test_fl_on_the_exact_model_tracks_to_integrator_noise(pair):
    plant, nominal = pair
    ref = SineReference(home=plant.neutral(), amp=0.2, freq=1.0, phase=0.0)
    tr = simulate(plant, closed_chain_fl(nominal, 100.0), ref, 0.2, engine="python")
    assert tr.info["engine"] == "python"
    # The law cancels the constrained dynamics exactly: what is left is RK4's error at 1 ms
    # (a few 1e-10 rad on this 0.2 rad, 1 Hz motion) and Newton's 1e-12 m loop closure.
    assert np.abs(tr.q - tr.r).max() < 1e-8
    assert tr.info["drift_m"] <= tr.info["drift_bound_m"] == ccsim.DRIFT_BOUND


def test_passive_simulation_conserves_energy(pair):
    plant, _ = pair
    ref = SineReference(home=plant.neutral(), amp=0.0, freq=0.0, phase=0.0)
    energies = []
    for dt in (2e-3, 1e-3):
        tr = simulate(plant, _Passive(), ref, 0.05, dt=dt, qd0=np.array([1.0, -0.5]))
        energies.append(plant.energy(np.array(tr.info["final_q"]),
                                     np.array(tr.info["final_qd"])))
    q = plant.close(plant.neutral(), seed=plant.home)
    E0 = plant.energy(q, plant.velocity(q, np.array([1.0, -0.5])))
    err = [abs(E - E0) for E in energies]
    # RK4 with projection: the energy error at 1 ms is below 1e-8 J (E0 = 2.45 J; measured
    # 4.0e-11) and falls by more than 8x when the step is halved (measured 16.1x: 4th order).
    assert err[1] < 1e-8 and err[0] > 8.0 * err[1]


def test_reference_through_a_singularity_is_refused_with_time_and_cond(pair):
    plant, _ = pair
    P = plant.params
    s = np.arcsin((2 * P.l2 - P.d) / (2 * P.l1))
    # Open both arms symmetrically: the elbows reach 2 l2 apart (distal links aligned) at
    # t = 0.5 s exactly, at amplitude s around the vertical.
    home = np.array([np.pi / 2, np.pi / 2])
    ref = SineReference(home=home, amp=np.array([s, s]), freq=0.5,
                        phase=np.array([0.0, np.pi]))
    with pytest.raises(SingularConfiguration, match=r"reference at t = 0\.5 s: .*cond\(J_p\)"):
        ccsim.check_chain_reference(plant, np.array([0.0, 0.25, 0.5]), ref.sample(
            np.array([0.0, 0.25, 0.5]))[0])
    beyond = SineReference(home=home, amp=np.array([s + 0.05, s + 0.05]), freq=0.5,
                           phase=np.array([0.0, np.pi]))
    with pytest.raises(LoopClosureError, match=r"reference at t = 0\.5 s: .*does not close"):
        ccsim.check_chain_reference(plant, np.array([0.0, 0.25, 0.5]), beyond.sample(
            np.array([0.0, 0.25, 0.5]))[0])


def test_plant_reaching_a_singularity_stops_with_the_time(pair):
    plant, _ = pair
    ref = SineReference(home=plant.neutral(), amp=0.0, freq=0.0, phase=0.0)
    # Falling under gravity at these speeds, the free 5-bar reaches a type-II singularity
    # (distal links aligned) at 0.126 s.
    with pytest.raises(SingularConfiguration, match=r"plant at t = 0\.1\d+ s: .*type-II"):
        simulate(plant, _Passive(), ref, 0.2, qd0=np.array([1.0, -0.5]))


def test_a_given_initial_state_the_chain_cannot_start_at_is_refused_naming_q0(pair):
    # issue 50's probe: the 3-RRR at an impossible --q0 ran the whole study and ended on a
    # divergence that did not name the option. A q0 the caller gave is a settings error: the
    # edge check names it; a drawn plant that cannot start at the default q0 stays a result.
    from rrr_pin.sim.simulation import check_run
    from rrr_pin.validation import FieldError

    plant, _ = pair
    P = plant.params
    s = np.arcsin((2 * P.l2 - P.d) / (2 * P.l1))
    q0 = np.array([np.pi / 2 + s, np.pi / 2 - s])  # distal links aligned: type-II
    ref = SineReference(home=plant.neutral(), amp=0.0, freq=0.0, phase=0.0)
    with pytest.raises(FieldError, match=r"^q0 = \[.*\] rad: the plant cannot start there: "):
        check_run(plant, _Passive(), ref, 0.1, q0=q0)
    from rrr_pin.sim.engines import ENGINES

    assert check_run(plant, _Passive(), ref, 0.1) in ENGINES

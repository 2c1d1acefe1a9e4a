"""Plant effects and breaking points on a parallel mechanism (the 5-bar).

References: the ideal loop (an effect set that is off, or a torque limit that never acts,
runs the effect engine to the same numbers); a transport delay of one control period realized
instead by a law that outputs its previous sample's torque (an independent delay line); the
delay margin of the linear digital loop (:class:`rrr_pin.control.laws.FLLinearModel`, exact
zero-order-hold discretization) against the simulated breaking point.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from rrr_pin import cli
from rrr_pin.campaign.closed_chain_study import chain_reference
from rrr_pin.campaign.runner import RunSettings
from rrr_pin.campaign.stress import StressSettings, stress
from rrr_pin.control.closed_chain import closed_chain_fl
from rrr_pin.control.effects import PlantEffects
from rrr_pin.control.laws import SampledLaw
from rrr_pin.model.closed_chain import load_closed_chain
from rrr_pin.sim.closed_chain import simulate_closed_chain
from rrr_pin.sim.simulation import simulate
from rrr_pin.validation import FieldError

RATE, DT, DURATION = 1000.0, 5e-4, 0.1


@pytest.fixture(scope="module")
def chain():
    return load_closed_chain("fivebar")


@pytest.fixture(scope="module")
def reference(chain):
    return chain_reference(chain, 0.5)


def _law():
    """FL alone on its own nominal 5-bar (its loop-closure seed starts at home)."""
    return closed_chain_fl(load_closed_chain("fivebar"), 100.0)


def _run(chain, reference, law, effects=None, **kw):
    q0 = reference(0.0)[0] + 0.01  # off the reference: the loop has something to correct
    return simulate_closed_chain(chain, law, reference, DURATION, rate=RATE, dt=DT, q0=q0,
                                 effects=effects, **kw)


class _OneSampleLate(SampledLaw):
    """Apply ``inner``'s torque one control period late (its first torque at ``t = 0``).

    The law's state carries the last torque: a delay line written independently of the
    effects' (``Resolved.applied``), which holds the first command before ``t = 0`` too.
    """

    def __init__(self, inner: SampledLaw):
        self.inner, self.name, self.label = inner, "late", "one sample late"
        self.n, self.rate, self.nx = inner.n, inner.rate, inner.nx + inner.n

    def initial_state(self):
        return np.concatenate([self.inner.initial_state(), np.zeros(self.n)])

    def step(self, t, q, qd, r, rd, rdd, x):
        tau, xi = self.inner.step(t, q, qd, r, rd, rdd, x[:self.inner.nx])
        held = tau if t == 0.0 else x[self.inner.nx:]
        return held, np.concatenate([xi, tau])


def test_effects_of_size_zero_are_the_ideal_loop(chain, reference):
    ideal = _run(chain, reference, _law())
    off = _run(chain, reference, _law(), PlantEffects(delay=0.0, viscous=0.0, noise_q=0.0))
    assert "effects" not in off.info  # an inactive set is no effect: the same loop
    np.testing.assert_array_equal(off.q, ideal.q)
    # A torque limit far above any torque switches the effect engine on, and never acts: the
    # effect loop's RK4 and projection must then be the ideal loop's (round-off at most).
    wide = _run(chain, reference, _law(), PlantEffects(torque_limit=1e9))
    assert wide.info["effects"]["torque_limit_Nm"] == 1e9
    np.testing.assert_allclose(wide.q, ideal.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(wide.tau, ideal.tau, rtol=0, atol=1e-12)


def test_a_delay_of_one_period_is_the_law_one_sample_late(chain, reference):
    delayed = simulate(chain, _law(), reference, DURATION, rate=RATE, dt=DT,
                       q0=reference(0.0)[0] + 0.01,
                       effects=PlantEffects(delay=1.0 / RATE))
    assert delayed.info["effects"]["delay_substeps"] == round(1.0 / RATE / DT)
    late = _run(chain, reference, _OneSampleLate(_law().sampled(RATE)))
    # Same arithmetic on both paths (the delay only picks which torque is held): round-off.
    np.testing.assert_allclose(delayed.q, late.q, rtol=0, atol=1e-12)
    # The trajectory records the commanded torque: the late law's is it shifted by one period.
    np.testing.assert_allclose(late.tau[1:-1], delayed.tau[:-2], rtol=0, atol=1e-12)
    ideal = _run(chain, reference, _law())
    assert np.max(np.abs(delayed.q - ideal.q)) > 1e-6  # the delay did change the run


def test_each_drive_effect_runs_and_is_recorded(chain, reference):
    fx = PlantEffects(bandwidth=2000.0, viscous=0.01, coulomb=0.01, torque_limit=50.0,
                      noise_q=1e-5, encoder_counts=2 ** 18, seed=3)
    traj = _run(chain, reference, _law(), fx)
    assert traj.info["effects"]["bandwidth_rad_s"] == 2000.0
    assert np.all(np.abs(traj.tau) <= 50.0)
    assert traj.info["drift_m"] <= traj.info["drift_bound_m"]
    assert np.sqrt(np.mean(traj.error ** 2)) < 0.02  # mild effects: still tracking


@pytest.mark.parametrize("kwargs, error, match", [
    ({"effects": PlantEffects(delay=2.5e-4)}, FieldError, r"delay = 0\.00025 s"),
    ({"effects": PlantEffects(torque_limit="urdf")}, ValueError, "no URDF effort limits"),
    ({"effects": PlantEffects(viscous=(0.1, 0.1, 0.1))}, ValueError, "one per joint"),
    ({"effects": {"delay": 1e-3}}, TypeError, "PlantEffects or None"),
], ids=["delay-between-substeps", "urdf-limit", "per-joint-size", "not-effects"])
def test_refused_effects_name_themselves(chain, reference, kwargs, error, match):
    with pytest.raises(error, match=match):
        _run(chain, reference, _law(), **kwargs)


def test_effects_need_a_sampled_law_and_limit_margin_is_refused(chain, reference):
    with pytest.raises(ValueError, match="sampled .digital. controllers only"):
        simulate_closed_chain(chain, _law(), reference, 0.01, effects=PlantEffects(delay=1e-3))
    with pytest.raises(ValueError, match="limit_margin is not implemented"):
        simulate(chain, _law(), reference, 0.01, rate=RATE, limit_margin=0.1)


@pytest.mark.parametrize("extra, message", [
    (["--controllers", "fl,nosuch"], "'nosuch': not implemented on closed chains"),
    (["--lock", "a=1"], "does not implement --lock"),
    (["--home", "0,0"], "does not implement --home"),
    (["--engine", "compiled"], "does not implement --engine compiled"),
], ids=["unknown", "lock", "home", "compiled"])
def test_cli_stress_on_a_chain_refuses_by_name(extra, message, tmp_path, capsys):
    out = tmp_path / "o"
    argv = ["stress", "--robot", "fivebar", "--effect", "delay", "--out", str(out)]
    assert cli.main(argv + extra) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not out.exists()


@pytest.mark.slow
def test_fivebar_delay_breaking_point_matches_the_linear_margin(chain):
    # FL alone (lam = 100 rad/s) on the 5-bar's circle: the simulated boundary (delays on the
    # 0.5 ms sub-step grid) against the digital loop's delay margin (FLLinearModel, exact
    # ZOH). Band 15 %: the grid's step is 8 % of the margin, and the budget criterion (RMS
    # error over a finite run) lets a slowly unstable loop pass just past the margin.
    reference = chain_reference(chain, 2.0)
    settings = StressSettings(run=RunSettings(duration=2.0, dt=DT, rate=RATE), sweep=0)
    row = stress(chain, [_law()], reference, "delay", settings)["rows"][0]
    assert row["status"] == "found"
    lo, hi = row["bracket"]
    assert hi - lo == pytest.approx(DT)
    assert 0.85 * row["predicted"] <= row["simulated"] <= 1.15 * row["predicted"]


@pytest.mark.slow
def test_cli_stress_fivebar_writes_figure_and_json(tmp_path, capsys):
    out = tmp_path / "o"
    assert cli.main(["stress", "--robot", "fivebar", "--effect", "actuator", "--dt", "5e-4",
                     "--controllers", "fl", "--out", str(out), "--no-progress"]) == 0
    data = json.loads((out / "stress_actuator.json").read_text())
    row = data["rows"][0]
    assert data["robot"] == "fivebar" and row["controller"] == "fl"
    assert row["status"] == "found" and row["predicted"] > 0
    assert (out / "stress_actuator.png").exists()


def test_cli_stress_on_a_chain_builds_every_built_in_law():
    # The chain study's laws (make_chain_law): PD and the 2-DOF law have reduced forms too.
    args = cli.build_parser().parse_args(["stress", "--robot", "fivebar", "--effect", "delay",
                                           "--controllers", "fl,pd,hinf2dof"])
    chain, laws, _ = cli._stress_chain(args)
    assert [type(law).__name__ for law in laws] == ["ReducedTracking", "ReducedPD",
                                                    "ReducedTwoDOF"]
    assert all(law.nominal is not chain for law in laws)  # each law its own model

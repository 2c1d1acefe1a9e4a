"""Engine "codegen": parameter-input generated dynamics, batched rollouts, and their campaign.

References: Pinocchio's own CRBA, nonLinearEffects, computeGeneralizedGravity and ABA on the
same numbers (an independent implementation: Pinocchio's templates, ABA by articulated bodies,
where the generated forward dynamics solve CRBA + RNEA), and the compiled engine (Pinocchio's
dynamics in the same loop).
"""

import importlib.util
from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from rrr_pin.campaign import montecarlo as mc
from rrr_pin.campaign.runner import RunSettings, make_laws
from rrr_pin.control import catalog
from rrr_pin.control.effects import PlantEffects
from rrr_pin.control.laws import fl_controller, hinf_fl_controller, pd_controller
from rrr_pin.control.references import SineReference
from rrr_pin.model.dynamics import load_robot, robot_from_xml
from rrr_pin.model.uncertainty import Tolerances
from rrr_pin.sim import dyngen
from rrr_pin.sim.batched import GENERATED, StructureMismatch, plant_parameters
from rrr_pin.sim.extension import EXTENSION, available
from rrr_pin.sim.simulation import simulate, simulate_batch
from rrr_pin.sim.trajectory import SimulationDiverged
from rrr_pin.validation import FieldError

pytestmark = pytest.mark.skipif(not available(), reason="compiled extension not built")

ROOT = Path(__file__).resolve().parents[1]
RATE = 1000.0  # [Hz]


def _robot(name):
    source, lock = GENERATED[name]
    return load_robot(source, lock=dict(lock))


@pytest.mark.parametrize("name", list(GENERATED))
def test_generated_equals_pinocchio_on_random_parameters(name, generated_matches_pinocchio):
    generated_matches_pinocchio(name, _robot(name).model, 23, 8)


def test_committed_c_is_the_generators_output():
    spec = importlib.util.spec_from_file_location("gen_dynamics",
                                                  ROOT / "scripts/gen_dynamics.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert script.main(["--check"]) == 0
    # ... and the structures compiled in are the generated ones.
    for name, (st, nq, npar) in EXTENSION.batch_models().items():
        model = _robot(name).model
        assert (st, nq, npar) == (dyngen.structure(model), model.nq,
                                  len(dyngen.parameter_layout(model.nq)))


@pytest.fixture(scope="module")
def rrr():
    return load_robot("rrr")


@pytest.fixture(scope="module")
def ref():
    return SineReference(home=[0.1, -0.2, 0.3], amp=[0.4, 0.3, 0.5], freq=[1.0, 1.5, 2.0],
                         phase=[0.0, 1.0, 2.0])


def _scaled(robot, factor, name):
    """``robot`` with every body's mass and inertia scaled by ``factor``."""
    m = robot.model.copy()
    for i in range(1, m.njoints):
        Y = m.inertias[i]
        m.inertias[i] = pin.Inertia(factor * Y.mass, Y.lever, factor * Y.inertia)
    return replace(robot, model=m, data=m.createData(), name=name)


@pytest.fixture(scope="module")
def plants(rrr):
    return [_scaled(rrr, f, f"x{f:g}") for f in (0.7, 0.85, 1.0, 1.15, 1.3)]


@pytest.mark.parametrize("rate", [RATE, None], ids=["sampled", "continuous"])
@pytest.mark.parametrize("kind", ["fl", "hinf", "pd"])
def test_batched_equals_compiled_and_one_at_a_time(rrr, ref, plants, kind, rate):
    import control

    K = control.tf([47.40, 47.40 * (134.75 + 12.17), 47.40 * 134.75 * 12.17],
                   [1.0, 513.37 + 0.19, 513.37 * 0.19])  # the paper's eq. (18)
    law = {"fl": fl_controller(rrr), "hinf": hinf_fl_controller(rrr, K),
           "pd": pd_controller(rrr)}[kind]
    q0 = ref.sample(np.array([0.0]))[0][0] + np.array([0.05, -0.04, 0.03])
    together = simulate_batch(plants, law, ref, 0.3, rate=rate, q0=q0)
    alone = simulate_batch(plants, law, ref, 0.3, rate=rate, q0=q0, batch=1)
    for a, b, plant in zip(together, alone, plants, strict=True):
        assert a.info["engine"] == "codegen"
        # Bit-identical: no operation crosses plants, no fused multiply-add.
        for key in ("q", "qd", "tau"):
            np.testing.assert_array_equal(getattr(a, key), getattr(b, key))
        c = simulate(plant, law, ref, 0.3, rate=rate, q0=q0, engine="compiled")
        # 1e-12 rad (issue 23): the dynamics differ by round-off (~1e-15 relative, above).
        assert_allclose(a.q, c.q, rtol=0.0, atol=1e-12)
        assert_allclose(a.qd, c.qd, rtol=0.0, atol=1e-11)
    assert np.ptp(together[0].q, axis=0).max() > 0.2  # the arm moves


def test_a_diverging_plant_leaves_its_batch_unchanged(rrr, ref, plants):
    # A plant 100 times lighter than the law's model: FL's gain is 100x too high and the
    # sampled loop goes unstable; its neighbours must not notice.
    law = fl_controller(rrr)
    light = _scaled(rrr, 0.01, "light")
    mixed = plants[:2] + [light] + plants[2:]
    out = simulate_batch(mixed, law, ref, 0.3, rate=RATE)
    clean = simulate_batch(plants, law, ref, 0.3, rate=RATE)
    assert isinstance(out[2], SimulationDiverged)
    with pytest.raises(SimulationDiverged) as compiled:
        simulate(light, law, ref, 0.3, rate=RATE, engine="compiled")
    assert str(out[2]) == str(compiled.value)  # same time, joint, reason
    for a, b in zip(out[:2] + out[3:], clean, strict=True):
        np.testing.assert_array_equal(a.q, b.q)
        np.testing.assert_array_equal(a.tau, b.tau)
    # Reduced to figures (a campaign's path): the same divergence, the same neighbours.
    figs = simulate_batch(mixed, law, ref, 0.3, rate=RATE, figures=True)
    assert str(figs[2]) == str(compiled.value)
    for f, b in zip(figs[:2] + figs[3:], clean, strict=True):
        assert f.figures() == b.figures()


def test_a_structure_without_generated_code(rrr, ref):
    # A prismatic joint: no generated dynamics, not even at first use (the generator handles
    # revolute joints about x, y or z; tests/test_dyncache.py covers the structures it
    # generates and the builds that fail).
    two = robot_from_xml(
        '<robot name="pr"><link name="base"/><joint name="slide" type="prismatic">'
        '<parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>'
        '<limit lower="-1" upper="1" effort="100" velocity="1"/></joint><link name="l1">'
        '<inertial><mass value="2"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" '
        'izz="0.1"/></inertial></link><joint name="turn" type="revolute"><parent link="l1"/>'
        '<child link="l2"/><origin xyz="0 0 0.3"/><axis xyz="1 0 0"/>'
        '<limit lower="-3" upper="3" effort="100" velocity="10"/></joint><link name="l2">'
        '<inertial><origin xyz="0 0 0.2"/><mass value="1"/><inertia ixx="0.05" ixy="0" '
        'ixz="0" iyy="0.05" iyz="0" izz="0.02"/></inertial></link></robot>')
    ref2 = SineReference(home=[0.1, -0.2], amp=[0.1, 0.1], freq=[1.0, 1.0], phase=[0.0, 0.0])
    with pytest.raises(StructureMismatch, match=r"structure 'JointModelPZ@0,RX@1'.*revolute "
                                                r"joints about x, y or z.*engine='compiled'"):
        simulate(two, fl_controller(two), ref2, 0.05, rate=RATE, engine="codegen")
    # auto: the compiled engine, one plant at a time, recorded.
    (traj,) = simulate_batch([two], fl_controller(two), ref2, 0.05, rate=RATE)
    assert traj.info["engine"] == "compiled"


def test_a_closed_chain_is_refused_by_name():
    # Its generated dynamics are serial trees; auto runs a chain on the compiled engine.
    chain = load_robot("fivebar")
    ref5 = SineReference(home=chain.neutral(), amp=0.05, freq=1.0, phase=0.0)
    with pytest.raises(ValueError, match="'codegen' does not implement closed chains"):
        simulate(chain, fl_controller(load_robot("fivebar")), ref5, 0.01, rate=RATE,
                 engine="codegen")
    (traj,) = simulate_batch([chain], fl_controller(load_robot("fivebar")), ref5, 0.01,
                             rate=RATE)
    assert traj.info["engine"] == "compiled"


def test_a_parameter_vector_outside_physical_consistency(rrr, ref):
    m = rrr.model.copy()
    Y = m.inertias[2]
    I = Y.inertia.copy()
    I[2, 2] = I[0, 0] + I[1, 1] + 1.0  # breaks the triangle inequality
    m.inertias[2] = pin.Inertia(Y.mass, Y.lever, I)
    bad = replace(rrr, model=m, data=m.createData(), name="bad")
    with pytest.raises(FieldError, match="plant 'bad': body of joint 2"):
        plant_parameters(bad)
    with pytest.raises(FieldError, match="plant 'bad'"):
        simulate(bad, fl_controller(rrr), ref, 0.05, rate=RATE, engine="codegen")


def test_campaign_rows_equal_for_every_batch_size_and_the_compiled_engine(rrr):
    laws = make_laws("fl,pd", rrr)
    settings = mc.CampaignSettings(samples=5, seed=3, tolerances=Tolerances(),
                                   run=RunSettings(duration=0.2, rate=RATE))
    rows = {b: mc.run_campaign(rrr, laws, settings, jobs=1, batch=b, chunk=5).rows
            for b in (1, 4, 16)}
    assert rows[1] == rows[4] == rows[16]
    compiled = mc.run_campaign(rrr, laws, replace(
        settings, run=RunSettings(duration=0.2, rate=RATE, engine="compiled")), jobs=1).rows
    for a, c in zip(rows[4], compiled, strict=True):
        assert a["status"] == c["status"] == "ok"
        for key, value in c.items():
            if key.endswith(("_rms_error", "_max_error")) or "_rms_error_" in key:
                assert abs(a[key] - value) <= 1e-12, key  # [rad]


@pytest.mark.slow
def test_campaign_rows_equal_for_two_jobs_and_batch_sizes(rrr):
    # Worker processes start slowly (~10 s on a loaded 2-core machine): slow.
    laws = make_laws("fl,pd", rrr)
    settings = mc.CampaignSettings(samples=5, seed=3, tolerances=Tolerances(),
                                   run=RunSettings(duration=0.2, rate=RATE))
    one = mc.run_campaign(rrr, laws, settings, jobs=1, batch=1).rows
    assert mc.run_campaign(rrr, laws, settings, jobs=2, batch=16, chunk=2).rows == one


def test_campaign_rows_equal_for_one_and_two_threads(rrr):
    # Threads run batches of plants side by side; no operation crosses plants, so rows are
    # identical (==, bit for bit) for every thread count and batch size.
    laws = make_laws("fl,hinf", rrr)
    settings = mc.CampaignSettings(samples=9, seed=4, tolerances=Tolerances(),
                                   run=RunSettings(duration=0.1, rate=RATE))
    one = mc.run_campaign(rrr, laws, settings, jobs=1, threads=1, batch=16).rows
    assert mc.run_campaign(rrr, laws, settings, jobs=1, threads=2, batch=4).rows == one
    assert mc.run_campaign(rrr, laws, settings, jobs=1, threads=2, batch=1, chunk=5).rows == one
    # threads change nothing for the one-plant engines either (they run one at a time)
    compiled = replace(settings, run=RunSettings(duration=0.1, rate=RATE, engine="compiled"))
    assert (mc.run_campaign(rrr, laws, compiled, jobs=1, threads=2).rows
            == mc.run_campaign(rrr, laws, compiled, jobs=1, threads=1).rows)
    with pytest.raises(ValueError, match="threads must be an integer in"):
        mc.run_campaign(rrr, laws, settings, jobs=1, threads=0)


@pytest.mark.parametrize("rate, duration", [(RATE, 0.2), (RATE, 0.731), (None, 0.2)],
                         ids=["sampled", "sampled-odd-length", "continuous"])
def test_figures_equal_the_trajectorys_figures(rrr, ref, plants, rate, duration):
    # figures=True reduces each run inside the C++ loop (numpy's pairwise sum, streamed)
    # without storing trajectories: the same numbers, bit for bit, as numpy's reduction of
    # the trajectories (their own figures, the campaign's run_metrics). 0.731 s: 732 x 3
    # values, a pairwise tree whose leaves are not all full blocks of 8.
    law = make_laws("hinf", rrr)[0]
    trajs = simulate_batch(plants, law, ref, duration, rate=rate, batch=4, threads=2)
    figs = simulate_batch(plants, law, ref, duration, rate=rate, batch=4, figures=True)
    for t, f in zip(trajs, figs, strict=True):
        assert f.figures() == t.figures()
        assert f.info == t.info and f.info["engine"] == "codegen"
    # every trajectory owns its reference samples, though the batch shared them
    trajs[0].r[:] = 0.0
    assert np.all(trajs[1].r[1:] != 0.0)


@pytest.mark.parametrize("rate", [RATE, None], ids=["sampled", "continuous"])
def test_batched_hinf_aw_equals_compiled(rrr, ref, plants, rate):
    # The anti-windup form (FLAWForm) on the batched engine, its clip active: pinned to the
    # compiled engine (Pinocchio's dynamics, Eigen's LU on the law's M), plant by plant.
    free = simulate(rrr, make_laws("hinf", rrr)[0], ref, 0.3, rate=rate, engine="compiled")
    limit = 0.9 * np.abs(free.tau).max(axis=0)  # [N m]: below the peaks, so the clip acts
    law = make_laws("hinf_aw", rrr, torque_limit=limit)[0]
    batch = simulate_batch(plants, law, ref, 0.3, rate=rate, batch=4)
    for a, plant in zip(batch, plants, strict=True):
        assert a.info["engine"] == "codegen"
        c = simulate(plant, law, ref, 0.3, rate=rate, engine="compiled")
        assert np.any(np.abs(c.tau) >= limit)  # clipped somewhere
        # 1e-12 rad / 1e-11 rad/s, the batched engine's pinned tolerances (above)
        assert_allclose(a.q, c.q, rtol=0.0, atol=1e-12)
        assert_allclose(a.qd, c.qd, rtol=0.0, atol=1e-11)
        assert_allclose(a.tau, c.tau, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("effects", [
    PlantEffects(delay=0.0015), PlantEffects(torque_limit=60.0),
    PlantEffects(delay=0.001, torque_limit=(80.0, 60.0, 20.0)),
    PlantEffects(noise_q=1e-4, noise_qd=1e-3, encoder_counts=4096, seed=3),
    PlantEffects(actuator_bandwidth=300.0, viscous=0.5, coulomb=(1.0, 2.0, 0.5)),
    PlantEffects(stiffness=2.0e4, motor_inertia=0.05, transmission_damping=5.0,
                 torque_limit=200.0)],
    ids=["delay", "torque-limit", "both", "sensor", "actuator-friction", "flexible"])
@pytest.mark.parametrize("kind", ["fl", "hinf_aw"])
def test_batched_effects_equal_compiled(rrr, ref, plants, effects, kind):
    # Every plant effect in the batched loop (sensor -> law -> saturation -> delay ->
    # actuator -> flexible joint -> plant with friction, effects.hpp's order): pinned to the
    # compiled engine plant by plant, and bit-identical for every batch size. The limits clip
    # (the peak torque is the limit).
    law = make_laws(kind, rrr)[0]
    q0 = ref.sample(np.array([0.0]))[0][0] + np.array([0.05, -0.04, 0.03])
    go = dict(rate=RATE, dt=0.0005, q0=q0, effects=effects)
    together = simulate_batch(plants, law, ref, 0.3, **go)
    alone = simulate_batch(plants, law, ref, 0.3, batch=1, **go)
    figs = simulate_batch(plants, law, ref, 0.3, figures=True, **go)
    for a, b, f, plant in zip(together, alone, figs, plants, strict=True):
        assert a.info["engine"] == "codegen" and a.info["effects"] == b.info["effects"]
        np.testing.assert_array_equal(a.q, b.q)
        assert f.figures() == a.figures()
        c = simulate(plant, law, ref, 0.3, engine="compiled", **go)
        assert c.info["effects"] == a.info["effects"]
        # 1e-12 rad as the ideal plant's pin above (the dynamics differ by round-off)
        assert_allclose(a.q, c.q, rtol=0.0, atol=1e-12)
        assert_allclose(a.qd, c.qd, rtol=0.0, atol=1e-11)
    if effects.torque_limit is not None:
        limit = np.broadcast_to(effects.torque_limit, (3,))
        assert np.abs(together[0].tau).max(axis=0).tolist() <= limit.tolist()
        assert np.isclose(np.abs(together[0].tau).max(axis=0), limit).any()  # it clips


def test_an_effect_without_a_batched_step_is_refused_by_name(rrr, ref, plants):
    # Every effect of today's Resolved has its C++ step; a field added to it and not to
    # _ext/effects.hpp is named in the refusal (here a made-up one), never run without it.
    from dataclasses import dataclass, fields

    from rrr_pin.control.effects import Resolved
    from rrr_pin.sim import batched

    fx = PlantEffects(actuator_bandwidth=200.0).resolve(rrr, substeps=1, h=1e-3, n_steps=10)

    @dataclass(frozen=True)
    class WithBacklash(Resolved):
        backlash: float | None = None

    more = WithBacklash(**{f.name: getattr(fx, f.name) for f in fields(fx)}, backlash=0.01)
    assert batched._unbatched_effects(fx) == []
    assert batched._unbatched_effects(more) == ["backlash"]


#: The effect cases of the registry pin: the ideal plant and every effect a stress search can
#: vary (rrr_pin.control.catalog.EFFECTS), each at a mild size taken from its direction alone
#: (1e-3 in its unit where larger is harsher, 1e3 where smaller is), so an effect added there is
#: pinned here without a test edit.
EFFECT_CASES = ["ideal", *catalog.EFFECTS]


def _case_effects(effect):
    if effect == "ideal":
        return None
    stress = catalog.EFFECTS[effect]
    return PlantEffects(**stress.fields(1e-3 if stress.direction == "up" else 1e3, 5))


def assert_batched_pinned(plants, law, ref, effect):
    """Batched runs of ``law`` on ``plants`` equal the compiled engine's, run by run.

    1e-12 rad / 1e-11 rad/s (issue 23's pin: the generated dynamics differ from Pinocchio's by
    round-off); a run that diverges diverges alike on both (same time, same joint).
    """
    q0 = ref.sample(np.array([0.0]))[0][0] + np.array([0.05, -0.04, 0.03])
    go = dict(rate=RATE, dt=0.0005, q0=q0, effects=_case_effects(effect))
    batch = simulate_batch(plants, law, ref, 0.1, **go)
    for a, plant in zip(batch, plants, strict=True):
        try:
            c = simulate(plant, law, ref, 0.1, engine="compiled", **go)
        except SimulationDiverged as exc:
            assert isinstance(a, SimulationDiverged), a
            assert (a.time, a.joint) == (exc.time, exc.joint)
            continue
        assert a.info["engine"] == "codegen"
        assert_allclose(a.q, c.q, rtol=0.0, atol=1e-12)
        assert_allclose(a.qd, c.qd, rtol=0.0, atol=1e-11)
    return batch


@pytest.fixture(scope="module")
def registry_laws(rrr):
    """Every built-in law of the registry (rrr_pin.control.catalog.LAWS) on the RRR."""
    return {name: make_laws(name, rrr)[0] for name in catalog.LAWS}


@pytest.mark.parametrize("effect", EFFECT_CASES)
@pytest.mark.parametrize("name", list(catalog.LAWS))
def test_every_registered_law_and_effect_is_batched_as_compiled(rrr, ref, plants, registry_laws,
                                                                name, effect):
    # The lists read, not typed: every law of the catalog, every effect of the stress registry
    # and the ideal plant; the batched engine pinned to the compiled engine (the one list of C++
    # laws, RRR_PIN_LAWS, and effects.hpp are what both run).
    assert_batched_pinned(plants[::2], registry_laws[name], ref, effect)


def test_a_throwaway_registered_law_runs_the_generic_checks(rrr, ref, plants, monkeypatch):
    # A law registered the way a user would (a BuiltinLaw in catalog.LAWS; its compiled form a
    # built-in one) is built by name and batched as compiled, by the same checks as the
    # built-ins: nothing in the engines lists the laws.
    monkeypatch.setitem(catalog.LAWS, "pd_slow", catalog.BuiltinLaw(
        "PD + gravity compensation at 8 rad/s (throwaway)",
        lambda nominal, **_: pd_controller(nominal, 8.0, name="pd_slow")))
    law = catalog.make_law("pd_slow", rrr)
    assert law.name == "pd_slow"
    for effect in ("ideal", "delay"):
        batch = assert_batched_pinned(plants[::2], law, ref, effect)
        assert np.ptp(batch[0].q, axis=0).max() > 0.01  # the arm moves


def test_a_diverging_plant_with_effects_leaves_its_batch_unchanged(rrr, ref, plants):
    # As test_a_diverging_plant_leaves_its_batch_unchanged, with a delay, an actuator and
    # friction on: the light plant's divergence reads as the compiled engine's, in both output
    # kinds, and its neighbours' numbers are those of a batch without it.
    fx = PlantEffects(delay=0.001, actuator_bandwidth=500.0, viscous=0.3)
    law = fl_controller(rrr)
    light = _scaled(rrr, 0.01, "light")
    mixed = plants[:2] + [light] + plants[2:]
    go = dict(rate=RATE, effects=fx)
    out = simulate_batch(mixed, law, ref, 0.3, **go)
    figs = simulate_batch(mixed, law, ref, 0.3, figures=True, **go)
    clean = simulate_batch(plants, law, ref, 0.3, **go)
    with pytest.raises(SimulationDiverged) as compiled:
        simulate(light, law, ref, 0.3, engine="compiled", **go)
    assert str(out[2]) == str(figs[2]) == str(compiled.value)
    for a, f, b in zip(out[:2] + out[3:], figs[:2] + figs[3:], clean, strict=True):
        np.testing.assert_array_equal(a.q, b.q)
        assert f.figures() == b.figures()


def test_a_batch_filled_up_to_whole_lanes_gives_the_same_numbers(rrr, ref, plants):
    # 7 plants run as 8 (the last copied, its results dropped): each plant's run is the one it
    # has alone, bit for bit (no operation crosses plants).
    law = fl_controller(rrr)
    seven = (plants + plants)[:7]
    together = simulate_batch(seven, law, ref, 0.05, rate=RATE)
    for run, plant in zip(together, seven, strict=True):
        alone = simulate_batch([plant], law, ref, 0.05, rate=RATE)[0]
        assert run.info["engine"] == "codegen"
        for key in ("q", "qd", "tau"):
            np.testing.assert_array_equal(getattr(run, key), getattr(alone, key))

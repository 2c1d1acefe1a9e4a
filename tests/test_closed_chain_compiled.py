"""The compiled closed-chain engine (rrr_pin.sim.chain_compiled) against the Python engine.

References: Pinocchio's own ``crba``, ``nonLinearEffects`` and ``constraintDynamics`` through
its Python bindings, and :class:`ClosedChain`'s loop-closure Jacobian and ``gamma`` (frames and
``getFrameJacobian``/``getFrameClassicalAcceleration``, a second computation of what
``chain.cpp`` writes from joint placements); the Python engine
(:mod:`rrr_pin.sim.closed_chain`) for whole runs.
"""

from __future__ import annotations

import control
import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from rrr_pin.control.effects import PlantEffects
from rrr_pin.control.laws import FLForm, TrackingController
from rrr_pin.control.laws import fl_controller as closed_chain_fl
from rrr_pin.control.laws import hinf_fl_controller as closed_chain_hinf_fl
from rrr_pin.control.references import SineReference
from rrr_pin.model.closed_chain import (
    ConstraintDrift,
    LoopClosureError,
    SingularConfiguration,
    load_closed_chain,
)
from rrr_pin.model.mechanisms import perturb_mechanism
from rrr_pin.sim import chain_compiled
from rrr_pin.sim.extension import available
from rrr_pin.sim.simulation import simulate

pytestmark = pytest.mark.skipif(not available(), reason="compiled extension not built")

#: A stable SISO K with a direct term (the H-infinity + FL path: state, C x and D e).
K = control.tf([2.0, 30.0], [1.0, 50.0])


@pytest.fixture(scope="module")
def fivebar():
    return load_closed_chain("fivebar")


def _states(chain, rng, count):
    """Closed configurations near home and consistent velocities."""
    out = []
    for _ in range(count):
        q = chain.close(chain.neutral() + rng.uniform(-0.15, 0.15, chain.nq), seed=chain.home)
        out.append((q, chain.velocity(q, rng.uniform(-2.0, 2.0, chain.nq))))
    return out


@pytest.mark.parametrize("name", ["fivebar", "delta"])
def test_terms_equal_pinocchio_and_the_chain(name):
    chain = load_closed_chain(name)
    cm = chain_compiled.compile_chain(chain)
    rng = np.random.default_rng(22)
    for q, qd in _states(chain, rng, 4):
        M, nle, J, phi, gamma = cm.terms(q, qd)
        # Same algorithms on the same model (crba, nle): round-off only. J and gamma: frames
        # (Python) against joint placements + point kinematics (C++), two computations
        # (measured: M, nle, J, phi equal to the last bit; gamma 2.2e-16 m/s^2 apart).
        assert_allclose(M, pin.crba(chain.model, chain.data, q), rtol=0, atol=1e-12)
        assert_allclose(nle, pin.nonLinearEffects(chain.model, chain.data, q, qd), rtol=0,
                        atol=1e-12)
        assert_allclose(J, chain.jacobian(q), rtol=0, atol=1e-12)
        assert_allclose(phi, chain.residual(q), rtol=0, atol=1e-15)
        assert_allclose(gamma, chain.gamma(q, qd), rtol=0, atol=1e-12)
        # Off the constraint manifold too (J and phi are defined everywhere).
        qr = q + rng.uniform(-0.05, 0.05, q.size)
        _, _, Jr, phir, _ = cm.terms(qr, qd)
        assert_allclose(Jr, chain.jacobian(qr), rtol=0, atol=1e-12)
        assert_allclose(phir, chain.residual(qr), rtol=0, atol=1e-15)


@pytest.mark.parametrize("name", ["fivebar", "delta"])
def test_exact_kkt_equals_constraint_dynamics(name):
    chain = load_closed_chain(name)
    cm = chain_compiled.compile_chain(chain)
    rng = np.random.default_rng(5)
    for q, qd in _states(chain, rng, 3):
        u = chain.actuation(rng.uniform(-1.0, 1.0, chain.nq))
        # constraintDynamics (proximal, mu = 1e-4) converges to the exact KKT solution:
        # measured 8.5e-14 rad/s^2 (5-bar) and 2.1e-14 (Delta) here; the issue measured up to
        # 6e-11 on the 5-bar at other states, hence 1e-9.
        assert_allclose(cm.acceleration(q, qd, u), chain.constrained_acceleration(q, qd, u),
                        rtol=0, atol=1e-9)


def _perturbed():
    params, _ = perturb_mechanism(load_closed_chain("fivebar").params,
                                  np.random.default_rng(3))
    return load_closed_chain(params)


@pytest.mark.parametrize("plant_kind", ["nominal", "perturbed"])
@pytest.mark.parametrize("law_kind", ["fl", "hinf"])
def test_compiled_run_equals_the_python_engine(plant_kind, law_kind):
    plant = load_closed_chain("fivebar") if plant_kind == "nominal" else _perturbed()
    ref = SineReference(home=plant.neutral(), amp=0.1, freq=2.0, phase=0.3)
    runs = {}
    for engine in ("python", "compiled"):
        nominal = load_closed_chain("fivebar")  # a fresh law model per run: same seeds
        law = (closed_chain_fl(nominal) if law_kind == "fl"
               else closed_chain_hinf_fl(nominal, K))
        runs[engine] = simulate(plant, law, ref, 0.1, rate=1000, engine=engine)
    py, cc = runs["python"], runs["compiled"]
    assert cc.info["engine"] == "compiled" and py.info["engine"] == "python"
    # Exact KKT (C++) against proximal constraintDynamics (Python; 1e-13 rad/s^2 apart), the
    # same RK4, projection and law: measured max differences over these four runs 0.0 rad,
    # 2.2e-16 rad/s, 1.3e-15 N m. The bounds leave round-off room for another BLAS or CPU.
    assert_allclose(cc.q, py.q, rtol=0, atol=1e-12)
    assert_allclose(cc.qd, py.qd, rtol=0, atol=1e-12)
    assert_allclose(cc.tau, py.tau, rtol=0, atol=1e-10)
    assert_allclose(cc.info["final_q"], py.info["final_q"], rtol=0, atol=1e-12)
    # The drift records: present, below the bound, and the Python engine's.
    assert 0.0 < cc.info["drift_m"] <= cc.info["drift_bound_m"]
    assert_allclose(cc.info["drift_m"], py.info["drift_m"], rtol=0, atol=1e-12)
    assert_allclose(cc.info["drift_velocity_m_s"], py.info["drift_velocity_m_s"], rtol=0,
                    atol=1e-9)
    assert cc.info["reference_max_cond_Jp"] == pytest.approx(
        py.info["reference_max_cond_Jp"], rel=1e-9)
    assert set(cc.info) == set(py.info)


def test_auto_picks_compiled_and_records_why(fivebar):
    ref = SineReference(home=fivebar.neutral(), amp=0.05, freq=1.0, phase=0.0)
    tr = simulate(fivebar, closed_chain_fl(load_closed_chain("fivebar")), ref, 0.01, rate=1000)
    assert tr.info["engine"] == "compiled"
    assert "compiled form" in tr.info["engine_note"]


class _Mine(TrackingController):
    """A subclass changes the law: no compiled form."""


def test_law_without_compiled_form_is_refused_by_name(fivebar):
    ref = SineReference(home=fivebar.neutral(), amp=0.05, freq=1.0, phase=0.0)
    law = _Mine(nominal=load_closed_chain("fivebar"), lam=100.0, name="mine")
    assert law.compiled_form() is None and law.sampled(1000).compiled_form() is None
    with pytest.raises(ValueError, match=r"law 'mine' \(_Mine\) declares no compiled form"):
        simulate(fivebar, law, ref, 0.01, rate=1000, engine="compiled")
    tr = simulate(fivebar, law, ref, 0.002, rate=1000)
    assert tr.info["engine"] == "python" and "'mine'" in tr.info["engine_note"]


def test_continuous_law_and_codegen_are_refused(fivebar):
    ref = SineReference(home=fivebar.neutral(), amp=0.05, freq=1.0, phase=0.0)
    law = closed_chain_fl(load_closed_chain("fivebar"))
    assert isinstance(law.compiled_form(), FLForm)
    with pytest.raises(ValueError, match="continuous time .*sampled laws only"):
        simulate(fivebar, law, ref, 0.01, engine="compiled")
    with pytest.raises(ValueError, match="'codegen' does not implement closed chains"):
        simulate(fivebar, law, ref, 0.01, rate=1000, engine="codegen")
    with pytest.raises(ValueError, match="plant effects are not implemented"):
        simulate(fivebar, law, ref, 0.01, rate=1000, engine="compiled",
                 effects=PlantEffects(delay=0.001))


def test_drift_stop_has_the_python_message(fivebar):
    # 20 Hz with one RK4 step per period: the step leaves a gap far above DRIFT_BOUND.
    ref = SineReference(home=fivebar.neutral(), amp=0.2, freq=2.0, phase=0.0)
    msgs = []
    for engine in ("python", "compiled"):
        law = closed_chain_fl(load_closed_chain("fivebar"), 20.0)
        with pytest.raises(ConstraintDrift) as err:
            simulate(fivebar, law, ref, 0.5, rate=20, dt=0.05, engine=engine)
        msgs.append(str(err.value))
    assert "left a loop gap of" in msgs[0]
    assert msgs[0].split(" m at ")[1] == msgs[1].split(" m at ")[1]  # same time and bound


def test_singular_reference_is_refused_as_by_python(fivebar):
    # The reference of tests/test_closed_chain_sim.py: distal links aligned at t = 0.5 s, and
    # beyond (the loop cannot close there); the compiled check hands the refusal to Python's.
    P = fivebar.params
    s = np.arcsin((2 * P.l2 - P.d) / (2 * P.l1))
    home = np.array([np.pi / 2, np.pi / 2])
    law = closed_chain_fl(load_closed_chain("fivebar"))
    for amp, exc, match in ((s, SingularConfiguration, r"reference at t = 0\.5 s: .*cond"),
                            (s + 0.05, LoopClosureError, r"at t = 0\.\d+ s: .*does not close")):
        ref = SineReference(home=home, amp=np.array([amp, amp]), freq=0.5,
                            phase=np.array([0.0, np.pi]))
        msgs = []
        for engine in ("python", "compiled"):
            with pytest.raises(exc, match=match) as err:
                simulate(fivebar, law, ref, 1.0, rate=100, engine=engine)
            msgs.append(str(err.value))
        assert msgs[0] == msgs[1]


def test_delta_runs_compiled_pinned_to_python():
    plant = load_closed_chain("delta")
    ref = SineReference(home=plant.neutral(), amp=0.05, freq=2.0, phase=0.0)
    runs = {e: simulate(plant, closed_chain_fl(load_closed_chain("delta")), ref, 0.01,
                        rate=1000, engine=e) for e in ("python", "compiled")}
    # Measured after 10 steps: 0.0 rad, 4.4e-16 N m (exact KKT against constraintDynamics).
    assert_allclose(runs["compiled"].q, runs["python"].q, rtol=0, atol=1e-12)
    assert_allclose(runs["compiled"].tau, runs["python"].tau, rtol=0, atol=1e-10)
    assert runs["compiled"].info["drift_m"] <= runs["compiled"].info["drift_bound_m"]


@pytest.mark.slow
@pytest.mark.parametrize("mech,duration", [("fivebar", 1.0), ("delta", 0.3)])
def test_study_reference_on_a_perturbed_plant_pinned(mech, duration):
    # The study's own references (5-bar tip circle, Delta adept cycle) on a perturbed plant,
    # H-infinity + FL: measured 0.0 rad / 1.8e-15 N m (5-bar, 1 s) and 1.1e-16 rad /
    # 1.5e-13 N m (Delta, 0.3 s) between the engines.
    from rrr_pin.control.references import study_reference as chain_reference

    params, _ = perturb_mechanism(load_closed_chain(mech).params, np.random.default_rng(1))
    plant = load_closed_chain(params)
    ref = chain_reference(load_closed_chain(mech), duration)
    runs = {e: simulate(plant, closed_chain_hinf_fl(load_closed_chain(mech), K), ref,
                        duration, rate=1000, engine=e) for e in ("python", "compiled")}
    assert_allclose(runs["compiled"].q, runs["python"].q, rtol=0, atol=1e-12)
    assert_allclose(runs["compiled"].tau, runs["python"].tau, rtol=0, atol=1e-9)
    # The drift is round-off on the 1e-12 m Newton residual (measured 4e-17 m apart).
    assert_allclose(runs["compiled"].info["drift_m"], runs["python"].info["drift_m"], rtol=0,
                    atol=1e-15)

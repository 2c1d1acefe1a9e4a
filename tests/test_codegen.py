"""Engine "codegen" against the compiled engine, and the record of the fixed-model C.

``_ext/generated/codegen_rrr.c`` (CppADCodeGen, the nominal RRR only) stays committed for C
export; the engine runs the parameter-input dynamics of ``rrr_pin.sim.batched``
(tests/test_batched.py).

Reference: the compiled engine (``engine="compiled"``), whose dynamics are Pinocchio's generic
CRBA / nonLinearEffects / ABA on the same model; the generated C is an independent evaluation
(straight-line code of rrr_pin.sim.dyngen, forward dynamics by CRBA + RNEA + L D L^T), so
agreement checks both the generated functions and their wiring. A structure
without generated dynamics must be refused, never run on another's.
"""

import hashlib
import importlib.util
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin import paper_params
from rrr_pin.control.laws import fl_controller, hinf_fl_controller, pd_controller
from rrr_pin.control.references import SineReference
from rrr_pin.model.dynamics import load_robot, robot_from_xml
from rrr_pin.model.uncertainty import sample_plants
from rrr_pin.sim.codegen import fingerprint
from rrr_pin.sim.extension import available
from rrr_pin.sim.simulation import simulate

pytestmark = pytest.mark.skipif(not available(), reason="compiled extension not built")

ROOT = Path(__file__).resolve().parents[1]
DURATION = 0.5  # [s]: 500 control periods or RK4 steps
RATE = 1000.0  # [Hz]
# 1e-9 rad (rad/s): the engines' agreement specification (tests/test_engines.py, issue 9). The
# two evaluations of the dynamics differ by round-off only (~1e-16 relative, measured), which the
# stable closed loop does not amplify. tau (up to ~100 N m) carries that round-off times
# lam^2 Mhat: 1e-7 N m.
ATOL_Q = 1e-9
ATOL_TAU = 1e-7


def _k18():
    import control

    # The paper's H-infinity controller, eq. (18), typed from the paper.
    return control.tf([47.40, 47.40 * (134.75 + 12.17), 47.40 * 134.75 * 12.17],
                      [1.0, 513.37 + 0.19, 513.37 * 0.19])


@pytest.fixture(scope="module")
def rrr():
    return load_robot("rrr")


@pytest.fixture(scope="module")
def ref():
    return SineReference(home=[0.1, -0.2, 0.3], amp=[0.4, 0.3, 0.5], freq=[1.0, 1.5, 2.0],
                         phase=[0.0, 1.0, 2.0])


def _law(kind, nominal):
    if kind == "fl":
        return fl_controller(nominal)
    if kind == "hinf":
        return hinf_fl_controller(nominal, _k18())
    return pd_controller(nominal)


@pytest.mark.parametrize("rate", [None, RATE], ids=["continuous", "sampled"])
@pytest.mark.parametrize("kind", ["fl", "hinf", "pd"])
def test_codegen_equals_compiled_on_the_nominal_rrr(rrr, ref, kind, rate):
    law = _law(kind, rrr)
    # Start off the reference so the feedback acts (plant = model, so FL alone would track
    # exactly from r(0)).
    q0 = ref.sample(np.array([0.0]))[0][0] + np.array([0.05, -0.04, 0.03])
    a = simulate(rrr, law, ref, DURATION, rate=rate, q0=q0, engine="compiled")
    b = simulate(rrr, law, ref, DURATION, rate=rate, q0=q0, engine="codegen")
    assert (a.info["engine"], b.info["engine"]) == ("compiled", "codegen")
    assert_allclose(b.q, a.q, rtol=0.0, atol=ATOL_Q)
    assert_allclose(b.qd, a.qd, rtol=0.0, atol=ATOL_Q)
    assert_allclose(b.tau, a.tau, rtol=0.0, atol=ATOL_TAU)
    # Not two idle runs: the arm moves by tenths of a radian and the error is corrected.
    assert np.ptp(a.q, axis=0).max() > 0.2
    assert np.abs(a.error).max() > 1e-2


def _perturbed(rrr):
    return robot_from_xml(sample_plants(paper_params(), 1, 0)[0].urdf, gravity=rrr.gravity)


@pytest.mark.parametrize("case", ["perturbed plant", "perturbed nominal", "gravity 9.81", "ur5"])
def test_codegen_runs_every_plant_of_a_generated_structure(rrr, ref, case):
    # The fixed-model C refused these (fingerprint); the parameter-input C runs them, equal to
    # the compiled engine.
    if case == "ur5":
        plant = nominal = load_robot("ur5")
        ref = SineReference(home=np.zeros(6), amp=np.full(6, 0.1), freq=np.ones(6),
                            phase=np.zeros(6))
    elif case == "gravity 9.81":
        plant = nominal = load_robot("rrr", gravity=9.81)
    else:
        plant, nominal = (_perturbed(rrr), rrr) if case == "perturbed plant" else (
            rrr, _perturbed(rrr))
    law = pd_controller(nominal) if case == "gravity 9.81" else fl_controller(nominal)
    a = simulate(plant, law, ref, 0.1, rate=RATE, engine="compiled")
    b = simulate(plant, law, ref, 0.1, rate=RATE, engine="codegen")
    assert b.info["engine"] == "codegen"
    assert_allclose(b.q, a.q, rtol=0.0, atol=ATOL_Q)


def test_codegen_generates_a_structure_without_committed_code_at_first_use(rrr, ref):
    # Issue 33: a structure the extension does not compile in (the RRR with a joint locked)
    # is generated, built and cached at first use (tests/test_dyncache.py: the cache and the
    # refusals, by name, when that fails); it runs as the compiled engine does.
    two = load_robot("rrr", lock={rrr.joint_names[0]: 0.0})
    ref2 = SineReference(home=[0.1, -0.2], amp=[0.1, 0.1], freq=[1.0, 1.0], phase=[0.0, 0.0])
    fast = simulate(two, fl_controller(two), ref2, 0.1, rate=RATE, engine="codegen")
    slow = simulate(two, fl_controller(two), ref2, 0.1, rate=RATE, engine="compiled")
    assert fast.info["engine"] == "codegen"
    # 1e-12 rad, the batched engine's pinned tolerance (tests/test_batched.py)
    np.testing.assert_allclose(fast.q, slow.q, rtol=0.0, atol=1e-12)


def test_codegen_runs_plant_effects(rrr, ref):
    from rrr_pin.control.effects import PlantEffects

    # Every plant effect is batched now (tests/test_batched.py pins each to the compiled
    # engine); a continuous law with effects is refused as on every engine.
    run = simulate(rrr, fl_controller(rrr), ref, 0.1, rate=RATE, engine="codegen",
                   effects=PlantEffects(delay=1e-3, actuator_bandwidth=200.0))
    assert run.info["engine"] == "codegen"


def test_fingerprint_sees_every_change(rrr):
    base = fingerprint(rrr.model)
    assert fingerprint(load_robot("rrr").model) == base  # deterministic
    m = rrr.model.copy()
    m.inertias[2].mass = m.inertias[2].mass * (1 + 1e-15)
    assert fingerprint(m) != base
    m = rrr.model.copy()
    m.jointPlacements[3].translation = m.jointPlacements[3].translation + 1e-16
    assert fingerprint(m) != base
    m = rrr.model.copy()
    m.armature[0] = 1e-3
    assert fingerprint(m) != base


def test_committed_c_is_from_the_current_urdf():
    # The generator (tools/codegen/gen.cpp) needs a 5 GB build, so the suite checks the record
    # instead: the header's URDF sha256 and model fingerprint equal today's, and the export
    # reads the same fingerprint from the installed copy it ships.
    from rrr_pin.deploy.writer import generated_rrr_source

    spec = importlib.util.spec_from_file_location("codegen_script", ROOT / "scripts/codegen.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    rec = script.recorded()
    assert rec["urdf_sha256"] == hashlib.sha256((ROOT / "urdf/rrr.urdf").read_bytes()).hexdigest()
    assert script.check() == []
    assert rec["fingerprint"] == fingerprint(load_robot("rrr").model)
    assert generated_rrr_source() == (rec["fingerprint"], script.OUT.read_text(encoding="ascii"))
    assert float(rec["gravity"]) == load_robot("rrr").gravity

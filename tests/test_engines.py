"""The compiled engine against the Python engine, and the rule that no law is ever substituted.

The Python engine (``rrr_pin.sim.python_engine``) is the readable reference; the compiled engine
(``rrr_pin.sim.compiled``, C++) must give the same trajectory for every built-in compiled law
(FL, H-inf + FL, H-inf + FL with anti-windup, PD + gravity) on every kind of plant (the serial
RRR and UR5, the closed-chain 5-bar and Delta), nominal and perturbed, with each plant effect
alone and all together, sampled and continuous; and on the RRR with every reference kind. A law
the compiled engine does not implement (a subclass of a built-in, a law written in Python, a
compiled form of a type it does not know) must run on Python under ``engine="auto"``, and
``engine="compiled"`` must refuse it by name.
"""

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields, replace

import control
import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose, assert_array_equal

import rrr_pin
from rrr_pin import paper_params
from rrr_pin.control.effects import PlantEffects, Resolved
from rrr_pin.control.laws import (
    CompiledForm,
    ControlLaw,
    FLForm,
    PDForm,
    PDGravity,
    SampledLaw,
    TrackingController,
    compiled_forms,
    fl_controller,
    hinf_aw_controller,
    hinf_fl_controller,
    pd_controller,
)
from rrr_pin.control.references import (
    LinePath,
    QuinticReference,
    SineReference,
    SplineReference,
    default_reference,
    task_space_reference,
)
from rrr_pin.model.dynamics import load_robot, robot_from_xml
from rrr_pin.model.mechanisms import MECHANISMS
from rrr_pin.model.uncertainty import Tolerances, sample_plants
from rrr_pin.sim.compiled import acceleration_ms, compile_robot, floor_ms
from rrr_pin.sim.extension import EXTENSION, available
from rrr_pin.sim.simulation import simulate, simulate_batch
from rrr_pin.sim.trajectory import SimulationDiverged

# The paper's H-infinity controller, eq. (18), typed from the paper (not from rrr_pin.design, so
# these tests do not depend on the loop-shaping code).
K18 = control.tf([47.40, 47.40 * (134.75 + 12.17), 47.40 * 134.75 * 12.17],
                 [1.0, 513.37 + 0.19, 513.37 * 0.19])

DURATION = 0.5  # [s]: 500 control periods or RK4 steps, enough for every reference to move.
RATE = 1000.0  # [Hz]

# Engine agreement: both engines do the same floating-point operations in the same order, up to
# Eigen's vs numpy's evaluation of the small matrix products and RK4 sums (~1e-16 relative per
# step), which a stable closed loop does not amplify, and, on a closed chain, the exact KKT
# solution (C++) against Pinocchio's proximal constraintDynamics (Python), which converges to it
# (to 6e-11 rad/s^2 at worst). Measured over the 320 runs of
# test_engines_agree_on_every_plant_law_and_effect: q within 8.9e-16 rad, qd 4.2e-13 rad/s, tau
# 5.6e-11 N m. 1e-9 rad (and rad/s) is issue 9's specification, 6 orders above that round-off and
# 3 below the smallest tracking error the study reports (~1e-6 rad). tau (up to ~300 N m) carries
# the state's round-off times lam^2 Mhat: 1e-7 N m.
ATOL_Q = 1e-9
ATOL_TAU = 1e-7


@pytest.fixture(scope="module")
def rrr():
    return load_robot("rrr")


@pytest.fixture(scope="module")
def rrr_plant(rrr):
    """Sample 0 of seed 0 of the paper's uncertain RRR (20 % inertia, 5 % lengths)."""
    p = sample_plants(paper_params(), 1, 0)[0]
    return robot_from_xml(p.urdf, gravity=rrr.gravity)


def builtin_laws(nominal):
    return {"fl": fl_controller(nominal), "hinf": hinf_fl_controller(nominal, K18),
            "pd": pd_controller(nominal)}


@pytest.fixture(scope="module")
def rrr_laws(rrr):
    return builtin_laws(rrr)


@pytest.fixture(scope="module")
def rrr_refs(rrr):
    """One reference of each kind, all moving within DURATION, inside the joint limits."""
    q_start = np.array([0.3, -0.6, 1.0])
    pin.framesForwardKinematics(rrr.model, rrr.data, q_start)
    p0 = rrr.data.oMf[rrr.model.getFrameId("ee")].translation.copy()
    return {
        "sine": SineReference(home=[0.1, -0.2, 0.3], amp=[0.4, 0.3, 0.5], freq=[1.0, 1.5, 2.0],
                              phase=[0.0, 1.0, 2.0]),
        "quintic": QuinticReference(start=[0.2, -0.5, 0.8], goal=[0.9, 0.3, -0.2],
                                    move_time=0.4),
        "spline": SplineReference(times=[0.0, 0.15, 0.3, 0.45],
                                  waypoints=[[0.0, 0.0, 0.0], [0.4, -0.3, 0.5],
                                             [0.1, 0.2, 0.9], [-0.3, 0.4, 0.6]]),
        "line": task_space_reference(rrr, "ee", LinePath(p0, p0 + [-0.3, 0.2, 0.25]),
                                     move_time=0.4, q_start=q_start),
    }


def assert_same_run(a, b):
    assert_array_equal(a.t, b.t)
    assert_array_equal(a.r, b.r)
    assert_allclose(b.q, a.q, rtol=0.0, atol=ATOL_Q)
    assert_allclose(b.qd, a.qd, rtol=0.0, atol=ATOL_Q)
    assert_allclose(b.tau, a.tau, rtol=0.0, atol=ATOL_TAU)


@pytest.mark.parametrize("ref_kind", ["sine", "quintic", "spline", "line"])
@pytest.mark.parametrize("rate", [None, RATE], ids=["continuous", "sampled"])
@pytest.mark.parametrize("law", ["fl", "hinf", "pd"])
def test_engines_agree_on_every_builtin_law_and_reference(rrr_plant, rrr_laws, rrr_refs, law,
                                                          rate, ref_kind):
    ref = rrr_refs[ref_kind]
    a = simulate(rrr_plant, rrr_laws[law], ref, DURATION, rate=rate, engine="python")
    b = simulate(rrr_plant, rrr_laws[law], ref, DURATION, rate=rate, engine="compiled")
    c = simulate(rrr_plant, rrr_laws[law], ref, DURATION, rate=rate)
    assert (a.info["engine"], b.info["engine"], c.info["engine"]) == (
        "python", "compiled", "compiled")
    assert_same_run(a, b)
    assert_array_equal(c.q, b.q)
    # Not a comparison of two idle runs: the reference moves by tenths of a radian and the
    # plant-model mismatch leaves a tracking error the law acts on.
    assert np.ptp(a.r, axis=0).max() > 0.2
    assert np.abs(a.error).max() > 1e-7


# --- every built-in compiled law on every kind of plant, with every plant effect -------------

#: The plants of the pinning matrix below: two serial arms and two closed chains, by name
#: (rrr_pin.load_robot); a representative cut of the default suite's 3-minute budget.
KINDS = ("rrr", "ur5", "fivebar", "delta")
#: Every plant: the serial arms and every registered mechanism (the 3-RRR included), for the
#: per-plant checks, so that a mechanism added to the registry is checked without a test edit.
PLANTS = ("rrr", "ur5", *MECHANISMS)
#: Each effect alone, and all together (rrr_pin.control.effects.PlantEffects keywords). The
#: saturation limit is set per run (below the peak torque the law asks, so it clips); the
#: flexible joints alone need more transmission damping than with the actuator filter.
EFFECTS = {
    "delay": {"delay": 1.5e-3}, "actuator": {"actuator_bandwidth": 400.0},
    "friction": {"viscous": 0.05, "coulomb": 0.1}, "saturation": {},
    "noise": {"noise_q": 1e-4, "noise_qd": 1e-3}, "quantization": {"encoder_counts": 2 ** 12},
    "flexible": {"stiffness": 2e4, "motor_inertia": 0.05, "transmission_damping": 20.0},
    "all": {"delay": 1.5e-3, "actuator_bandwidth": 400.0, "viscous": 0.05, "coulomb": 0.1,
            "noise_q": 1e-4, "noise_qd": 1e-3, "encoder_counts": 2 ** 18, "stiffness": 2e4,
            "motor_inertia": 0.05, "transmission_damping": 1.0},
}
#: Runs: sampled on the ideal plant and with each effect, continuous on the ideal plant
#: (effects need a sampled law).
RUNS = ["sampled", "continuous"] + [f"sampled-{k}" for k in EFFECTS]
PIN_DURATION = 0.05  # [s]: 50 control periods; the reference moves by 0.05 rad
#: A stable SISO K with a direct term for the chains (H-inf + FL's path: state, C x and D e);
#: the arms take the paper's K18.
K_CHAIN = control.tf([2.0, 30.0], [1.0, 50.0])
_LOADED: dict = {}


def plant_case(kind: str, variant: str):
    """``(plant, law_models, reference, q0, limit)`` of one kind, cached for the module.

    The laws' model is another copy of the nominal plant (a closed chain's law closes its own
    loop, seeded from its own previous solution: the same copy for both engines, reset to its
    home before each run). The perturbed plant is drawn by the plant protocol,
    ``plant.perturbed(default_rng(0), Tolerances())``. The run starts 0.02 rad off the
    reference, so the feedback acts on the nominal plant too. ``limit``: 0.8 of the peak torque
    H-inf + FL asks [N m] (the anti-windup law's limit, so that it clips).
    """
    key = kind, variant
    if key not in _LOADED:
        nominal = rrr_pin.load_robot(kind)
        plant = (rrr_pin.load_robot(kind) if variant == "nominal"
                 else nominal.perturbed(np.random.default_rng(0), Tolerances())[0])
        ref = SineReference(home=nominal.neutral(), amp=0.1, freq=2.0, phase=0.3)
        q0 = ref(0.0)[0] + 0.02
        K = K_CHAIN if nominal.loop_closures else K18
        probe = simulate(plant, hinf_fl_controller(nominal, K), ref, PIN_DURATION, rate=RATE,
                         q0=q0, engine="compiled")
        limit = 0.8 * np.abs(probe.tau).max(axis=0)
        laws = {"fl": fl_controller(nominal), "hinf": hinf_fl_controller(nominal, K),
                "hinf_aw": hinf_aw_controller(nominal, K, torque_limit=limit),
                "pd": pd_controller(nominal)}
        _LOADED[key] = plant, nominal, laws, ref, q0, limit
    return _LOADED[key]


def _outcome(plant, law, nominal, ref, q0, engine, **kw):
    """The run's Trajectory, or the exception it stopped with; the law's model reset first."""
    nominal.reset()
    try:
        return simulate(plant, law, ref, PIN_DURATION, q0=q0, engine=engine, **kw)
    except (SimulationDiverged, *plant.failures) as exc:
        return exc


def assert_same_info(a, b):
    """Both engines record the same keys, and the same values to 1e-9 (drift, final state)."""
    skip = {"engine", "engine_note"}
    assert set(a.info) - skip == set(b.info) - skip
    for key in set(a.info) - skip:
        va, vb = a.info[key], b.info[key]
        if isinstance(va, dict):
            assert va.keys() == vb.keys(), key
            for k in va:
                assert_allclose(np.asarray(vb[k], dtype=float), np.asarray(va[k], dtype=float),
                                rtol=0.0, atol=1e-9, err_msg=f"{key}.{k}")
        elif isinstance(va, str):
            assert va == vb, key
        else:
            assert_allclose(np.asarray(vb, dtype=float), np.asarray(va, dtype=float), rtol=0.0,
                            atol=1e-9, err_msg=key)


@pytest.mark.parametrize("run", RUNS)
@pytest.mark.parametrize("law", ["fl", "hinf", "hinf_aw", "pd"])
@pytest.mark.parametrize("variant", ["nominal", "perturbed"])
@pytest.mark.parametrize("kind", KINDS)
def test_engines_agree_on_every_plant_law_and_effect(kind, variant, law, run):
    plant, nominal, laws, ref, q0, limit = plant_case(kind, variant)
    timing, _, effect = run.partition("-")
    kw = {"rate": RATE if timing == "sampled" else None}
    if effect:
        kw["dt"] = 5e-4
        # The same engine's run on the ideal plant: the saturation clips below its peak torque.
        ideal = _outcome(plant, laws[law], nominal, ref, q0, "compiled", **kw)
        fx = {**EFFECTS[effect], **({"torque_limit": 0.9 * np.abs(ideal.tau).max(axis=0)}
                                    if effect in ("saturation", "all") else {})}
        kw["effects"] = PlantEffects(seed=5, **fx)
    py = _outcome(plant, laws[law], nominal, ref, q0, "python", **kw)
    cc = _outcome(plant, laws[law], nominal, ref, q0, "compiled", **kw)
    auto = _outcome(plant, laws[law], nominal, ref, q0, "auto", **kw)
    assert not isinstance(py, Exception), py  # every case runs to its end
    assert (py.info["engine"], cc.info["engine"], auto.info["engine"]) == (
        "python", "compiled", "compiled")
    assert_same_run(py, cc)
    assert_array_equal(auto.q, cc.q)
    assert_same_info(py, cc)
    # Not a comparison of two idle runs: the reference moves, the law corrects an error, and
    # each effect changes the trajectory.
    assert np.ptp(py.r, axis=0).max() > 0.03 and np.abs(py.error).max() > 1e-3
    if effect:
        assert np.abs(cc.q - ideal.q).max() > 1e-9


def run_both(plant, law, ref, duration, **kwargs):
    """The SimulationDiverged each engine raises."""
    out = []
    for engine in ("python", "compiled"):
        with pytest.raises(SimulationDiverged) as info:
            simulate(plant, law, ref, duration, engine=engine, **kwargs)
        out.append(info.value)
    return out


@pytest.mark.parametrize("rate", [None, RATE], ids=["continuous", "sampled"])
def test_blow_up_diverges_at_the_same_step_and_joint(rrr, rrr_plant, rrr_refs, rate):
    # lam = 2e4 rad/s: lam^2 dt^2 = 400, far outside the stability region of the sampled loop
    # and of RK4 (|lambda dt| < 2.8), so the run blows up within a few steps.
    law = fl_controller(rrr, lam=2e4)
    py, cc = run_both(rrr_plant, law, rrr_refs["sine"], DURATION, rate=rate)
    assert (py.time, py.joint) == (cc.time, cc.joint)
    assert 0.0 < py.time < DURATION and py.joint in rrr.joint_names
    assert str(py).split(" (q = ")[0] == str(cc).split(" (q = ")[0]


@pytest.mark.parametrize("rate", [None, RATE], ids=["continuous", "sampled"])
@pytest.mark.parametrize("law", ["fl", "pd"])
def test_leaving_the_limits_diverges_at_the_same_step_and_joint(rrr, rrr_plant, rrr_laws, law,
                                                                rate):
    # Start at rest 0.14 rad below joint2's upper limit (pi) moving up at 50 rad/s: under FL
    # (lam = 100) the overshoot is ed0 / (lam e) = 0.18 rad (closed form of the critically damped
    # error); under the softer PD it is larger. Both cross pi + 0.01 rad within ~10 ms.
    q0 = np.array([0.0, 3.0, 0.0])
    ref = QuinticReference(start=q0, goal=[0.2, 3.0, 0.3], move_time=0.3)
    py, cc = run_both(rrr_plant, rrr_laws[law], ref, 0.2, rate=rate, qd0=[0.0, 50.0, 0.0],
                      limit_margin=0.01)
    assert (py.time, py.joint) == (cc.time, cc.joint)
    assert py.joint == "joint2" and 0.0 < py.time < 0.05
    assert "left its joint limits" in str(py) and "left its joint limits" in str(cc)


# --- no law is ever substituted ----------------------------------------------------------------


class ZeroTorque(TrackingController):
    """A user's subclass of a built-in: overrides the torque (the law under test is 'no law')."""

    def torque(self, t, q, qd, r, rd, rdd, x):
        return np.zeros(self.n)


@pytest.fixture(scope="module")
def sagging(rrr):
    """The reference a zero-torque arm cannot follow: it falls under gravity."""
    return default_reference(rrr)


def check_zero_torque_runs_itself(rrr, ref, rate):
    law = ZeroTorque(nominal=rrr, lam=100.0, name="zero")
    auto = simulate(rrr, law, ref, DURATION, rate=rate, engine="auto")
    py = simulate(rrr, law, ref, DURATION, rate=rate, engine="python")
    assert auto.info["engine"] == "python"
    assert_array_equal(auto.q, py.q)
    assert_array_equal(auto.tau, 0.0)
    # Independent check that the zero torque was applied: the arm falls freely. Pinocchio's ABA
    # with tau = 0 from the same start, integrated by a plain explicit Euler with 1e-4 s steps
    # (a different integrator: agreement to ~1e-3 rad, far below the ~1 rad fall).
    q, qd = ref(0.0)[0].copy(), ref(0.0)[1].copy()
    h = 1e-4
    for _ in range(int(round(DURATION / h))):
        qdd = pin.aba(rrr.model, rrr.data, q, qd, np.zeros(3))
        q, qd = q + h * qd, qd + h * qdd
    assert_allclose(py.q[-1], q, atol=5e-3)
    assert np.abs(py.error).max() > 0.5
    with pytest.raises(ValueError, match="law 'zero'.*compiled"):
        simulate(rrr, law, ref, DURATION, rate=rate, engine="compiled")


def test_subclassed_builtin_runs_itself_continuous(rrr, sagging):
    check_zero_torque_runs_itself(rrr, sagging, None)


def test_subclassed_builtin_runs_itself_sampled(rrr, sagging):
    check_zero_torque_runs_itself(rrr, sagging, RATE)


class HandPD(ControlLaw):
    """PD + gravity written by a user, continuous time."""

    def __init__(self, nominal, Kp, Kd):
        self.nominal, self.Kp, self.Kd = nominal, np.asarray(Kp), np.asarray(Kd)
        self.n, self.name, self.label = nominal.nq, "hand_pd", "hand-written PD"

    def torque(self, t, q, qd, r, rd, rdd, x):
        return self.Kp * (r - q) + self.Kd * (rd - qd) + self.nominal.G(q)


class HandSampledPD(SampledLaw):
    """The same PD written as a digital law, with a state that counts the samples."""

    nx = 1

    def __init__(self, nominal, Kp, Kd, rate):
        self.nominal, self.Kp, self.Kd, self.rate = nominal, np.asarray(Kp), np.asarray(Kd), rate
        self.n, self.name = nominal.nq, "hand_pd_sampled"

    def step(self, t, q, qd, r, rd, rdd, x):
        tau = self.Kp * (r - q) + self.Kd * (rd - qd) + self.nominal.G(q, check=False)
        return tau, x + 1.0


@pytest.mark.parametrize("rate", [None, RATE], ids=["continuous", "sampled"])
def test_a_law_written_in_python_matches_the_builtin_pd(rrr, rrr_plant, rrr_laws, rrr_refs,
                                                        rate):
    builtin = rrr_laws["pd"]
    gains = np.diag(builtin.Kp), np.diag(builtin.Kd)
    mine = HandPD(rrr, *gains) if rate is None else HandSampledPD(rrr, *gains, rate)
    ref = rrr_refs["quintic"]
    auto = simulate(rrr_plant, mine, ref, DURATION, rate=rate)
    assert auto.info["engine"] == "python"
    for engine in ("python", "compiled", "auto"):
        b = simulate(rrr_plant, builtin, ref, DURATION, rate=rate, engine=engine)
        # Same formula, computed elementwise here and as (diagonal) matrix products there: the
        # products by the zero off-diagonal entries are exact, so only round-off remains.
        assert_same_run(auto, b)
    with pytest.raises(ValueError, match=f"law '{mine.name}'"):
        simulate(rrr_plant, mine, ref, DURATION, rate=rate, engine="compiled")


@dataclass(frozen=True, eq=False)
class LQRForm(CompiledForm):
    """A compiled form the C++ loops do not implement."""

    K: np.ndarray


@dataclass(frozen=True, eq=False)
class RenamedFLForm(FLForm):
    """A subclass of a known form: it may mean another law, so it is not run as FLForm."""


class UnknownFormPD(HandPD):
    """A law declaring a compiled form of a type the C++ loops do not implement."""

    def __init__(self, nominal, Kp, Kd, form):
        super().__init__(nominal, Kp, Kd)
        self.form = form

    def compiled_form(self):
        return self.form(self.nominal)


def _lqr(nominal):
    return LQRForm(nominal, np.eye(3))


def _renamed_fl(nominal):
    n = nominal.nq
    return RenamedFLForm(nominal, 100.0, np.zeros((0, 0)), np.zeros((0, n)), np.zeros((n, 0)),
                         np.zeros((n, n)))


@pytest.mark.parametrize("rate", [None, RATE], ids=["continuous", "sampled"])
@pytest.mark.parametrize("form, name", [(_lqr, "LQRForm"), (_renamed_fl, "RenamedFLForm")],
                         ids=["new-form", "subclassed-form"])
def test_a_compiled_form_of_unknown_type_is_refused(rrr, rrr_refs, rate, form, name):
    law = UnknownFormPD(rrr, [100.0] * 3, [20.0] * 3, form)
    with pytest.raises(ValueError, match=f"compiled form {name} of law 'hand_pd' is not "
                                         f"implemented in C\\+\\+ .known: FLForm, FLAWForm, "
                                         f"PDForm"):
        simulate(rrr, law, rrr_refs["quintic"], 0.01, rate=rate, engine="compiled")


@pytest.mark.parametrize("rate", [None, RATE], ids=["continuous", "sampled"])
def test_auto_runs_an_unknown_form_on_python(rrr, rrr_plant, rrr_laws, rrr_refs, rate):
    # engine="auto" picks the engine that implements the law: Python here, whose run equals the
    # built-in PD's (same formula, see test_a_law_written_in_python_matches_the_builtin_pd).
    builtin = rrr_laws["pd"]
    law = UnknownFormPD(rrr, np.diag(builtin.Kp), np.diag(builtin.Kd), _lqr)
    ref = rrr_refs["quintic"]
    auto = simulate(rrr_plant, law, ref, DURATION, rate=rate)
    assert auto.info["engine"] == "python"
    assert_same_run(auto, simulate(rrr_plant, builtin, ref, DURATION, rate=rate,
                                   engine="compiled"))


class DeclaredPD(HandPD):
    """A user's PD in Python that declares its compiled form: the C++ loops may run it."""

    def compiled_form(self):
        return PDForm(self.nominal, np.diag(self.Kp), np.diag(self.Kd))


@pytest.mark.parametrize("rate", [None, RATE], ids=["continuous", "sampled"])
def test_a_users_law_with_a_compiled_form_runs_batched(rrr, rrr_plant, rrr_laws, rrr_refs, rate):
    # Issue 33: a user's law with a compiled form is batched like a built-in one; the batched
    # runs equal the compiled engine's to the batched engine's pinned 1e-12 rad, and the
    # user's own Python torque to 1e-9 rad (the Python engine's pin).
    builtin = rrr_laws["pd"]
    law = DeclaredPD(rrr, np.diag(builtin.Kp), np.diag(builtin.Kd))
    ref = rrr_refs["quintic"]
    plants = [rrr, rrr_plant]
    batched = simulate_batch(plants, law, ref, DURATION, rate=rate)
    for plant, run in zip(plants, batched, strict=True):
        assert run.info["engine"] == "codegen"
        compiled = simulate(plant, law, ref, DURATION, rate=rate, engine="compiled")
        assert_allclose(run.q, compiled.q, rtol=0.0, atol=1e-12)
        python = simulate(plant, law, ref, DURATION, rate=rate, engine="python")
        assert_allclose(run.q, python.q, rtol=0.0, atol=1e-9)


# --- the extension itself (ported from the former tests/test_compiled.py) ----------------------


def _structs():
    """(Python type, C++ struct) pairs: every compiled form with a C++ law, and the effects."""
    return [(cls, vars(cls)["cpp"]) for cls in compiled_forms()] + [(Resolved, "Effects")]


@pytest.mark.parametrize("form, cxx", _structs(), ids=[cls.__name__ for cls, _ in _structs()])
def test_python_and_cxx_structs_have_the_same_fields(form, cxx):
    # sim.compiled copies every field by name (nominal and info stay in Python), so a field on
    # one side only would fail loudly there; this names it here first. Every form that names a
    # C++ law is one of the extension's (the one list RRR_PIN_LAWS).
    assert cxx in EXTENSION.LAWS or form is Resolved
    obj = getattr(EXTENSION, cxx)()
    missing = [f.name for f in fields(form) if f.name not in ("nominal", "info")
               and not hasattr(obj, f.name)]
    assert missing == []


def _inputs(run):
    return {"sampled": run.sampled, "R": run.R, "RD": run.RD, "RDD": run.RDD, "q0": run.q0,
            "qd0": run.qd0, "x0": run.x0, "lower": run.lower, "upper": run.upper,
            "vlim": 50.0, "h": run.h, "substeps": run.substeps, "n_steps": len(run.t) - 1}


def _call(robot, form, inputs, effects=None):
    from rrr_pin.sim.extension import law_struct

    ins = EXTENSION.RolloutInputs()
    for key, value in inputs.items():
        setattr(ins, key, value)
    m = compile_robot(robot)._model
    return EXTENSION.rollout(m, m, law_struct(form), ins, effects)


@pytest.fixture(scope="module")
def pd_run(rrr, rrr_laws, rrr_refs):
    from rrr_pin.sim.simulation import _prepare

    run = _prepare(rrr, rrr_laws["pd"], rrr_refs["sine"], 0.05, dt=2.5e-4, rate=RATE,
                   method="tustin", q0=None, qd0=None, limit_margin=0.0)
    return run, run.law.compiled_form()


def test_all_off_effects_are_the_ideal_loop(rrr, pd_run):
    # effects.hpp: a default Effects switches every effect off, which is the ideal plant.
    run, form = pd_run
    ideal = _call(rrr, form, _inputs(run))
    off = _call(rrr, form, _inputs(run), EXTENSION.Effects())
    for key in ("Q", "QD", "TAU", "q", "qd", "step", "joint", "reason"):
        assert_array_equal(getattr(off, key), getattr(ideal, key))
    assert ideal.step == -1


@pytest.mark.parametrize("change, effects, match", [
    ({"R": np.zeros((3, 3))}, None, "reference arrays have the wrong shape"),
    ({"x0": np.zeros(2)}, None, "x0 must have the law's nx entries"),
    ({"substeps": 0}, None, "substeps >= 1"),
    ({"q0": np.zeros(2)}, None, "q0 and qd0 must be the plant's full state"),
    ({"sampled": False}, "off", "plant effects need a sampled law"),
    ({}, "bad-limit", "effect arrays have the wrong shape"),
], ids=["R-shape", "x0", "substeps", "q0", "continuous-effects", "effect-shape"])
def test_the_extension_refuses_bad_inputs(rrr, pd_run, change, effects, match):
    run, form = pd_run
    fx = None
    if effects is not None:
        fx = EXTENSION.Effects()
        if effects == "bad-limit":
            fx.limit = np.ones(2)
    with pytest.raises(ValueError, match=match):
        _call(rrr, form, {**_inputs(run), **change}, fx)


def test_a_pd_law_with_wrong_gains_is_refused_by_the_extension(rrr, pd_run):
    run, _ = pd_run
    law = EXTENSION.PDLaw()
    law.Kp, law.Kd = np.eye(2), np.eye(2)
    ins = EXTENSION.RolloutInputs()
    for key, value in _inputs(run).items():
        setattr(ins, key, value)
    m = compile_robot(rrr)._model
    with pytest.raises(ValueError, match="Kp and Kd must be nq x nq"):
        EXTENSION.rollout(m, m, law, ins)


def test_extension_built_against_installed_pinocchio():
    assert available(), "rrr_pin.sim._rollout is not built: pip install ."
    assert EXTENSION.pinocchio_version() == pin.__version__


@pytest.mark.parametrize("name", PLANTS)
def test_models_pass_exactly(name):
    plant = rrr_pin.load_robot(name)
    tree = compile_robot(plant)._model
    d = plant.description()
    assert tree.save() == d.model.saveToString()
    # The extension reads the plant's kind from the description: loops and coordinates.
    assert (tree.loops, tree.na, tree.nv) == (len(d.loop_joints), plant.nq, d.model.nv)


class _Unlimited:
    """A plant whose description is the RRR's with infinite joint limits (continuous joints)."""

    def __init__(self, robot):
        self.robot, self.name, self.joint_names = robot, "unlimited", robot.joint_names
        self.model = robot.model.copy()
        self.model.upperPositionLimit[:] = np.inf
        self.model.lowerPositionLimit[:] = -np.inf

    def description(self):
        return replace(self.robot.description(), model=self.model)


def test_infinite_limits_pass_exactly(rrr):
    """Continuous joints are loaded with infinite limits; the text archive keeps them."""
    plant = _Unlimited(rrr)
    back = pin.Model()
    back.loadFromString(compile_robot(plant)._model.save())
    assert back == plant.model


def test_concurrent_rollouts_share_compiled_robots(rrr, rrr_plant, rrr_laws, rrr_refs):
    """The extension releases the GIL and each rollout has its own pinocchio.Data."""
    compile_robot(rrr), compile_robot(rrr_plant)
    cases = [(law, ref) for law in ("fl", "hinf") for ref in ("sine", "spline")]

    def run(case):
        law, ref = case
        return simulate(rrr_plant, rrr_laws[law], rrr_refs[ref], 0.2, rate=RATE,
                        engine="compiled").q

    sequential = [run(c) for c in cases]
    with ThreadPoolExecutor(max_workers=2) as pool:
        concurrent = list(pool.map(run, cases))
    for s, c in zip(sequential, concurrent, strict=True):
        assert_array_equal(c, s)


@pytest.mark.parametrize("kind", ["fl", "pd"])
@pytest.mark.parametrize("sampled", [True, False])
def test_floor_ms_runs(rrr, rrr_plant, kind, sampled):
    # Only that it runs and returns a time: speed is never asserted in tests.
    ms = floor_ms(rrr_plant, rrr, n_steps=100, repeat=1, kind=kind, sampled=sampled)
    assert np.isfinite(ms) and ms > 0.0


@pytest.mark.parametrize("kwargs, match", [({"kind": "lqr"}, "kind"), ({"repeat": 0}, "repeat")])
def test_floor_ms_bad_input(rrr, kwargs, match):
    with pytest.raises(ValueError, match=match):
        floor_ms(rrr, rrr, n_steps=10, **kwargs)


def test_floor_ms_refuses_a_closed_chain():
    chain = rrr_pin.load_robot("fivebar")
    with pytest.raises(ValueError, match="serial trees"):
        floor_ms(chain, chain, n_steps=10, repeat=1)


@pytest.mark.parametrize("name", PLANTS)
def test_the_plant_accelerations_are_the_python_plants(name):
    # The compiled plant's acceleration (ABA, or a closed chain's exact KKT) against the Python
    # plant's (pin.aba; Pinocchio's proximal constraintDynamics, which converges to the exact
    # KKT solution: measured within 1e-13 rad/s^2 here; 1e-9 leaves the 6e-11 the issue
    # measured elsewhere), and its timing runs.
    plant = rrr_pin.load_robot(name)
    rng = np.random.default_rng(4)
    x, v = plant.start(plant.neutral() + rng.uniform(-0.1, 0.1, plant.nq),
                       rng.uniform(-1.0, 1.0, plant.nq))
    tau = rng.uniform(-1.0, 1.0, plant.nq)
    tree = compile_robot(plant)._model
    assert_allclose(tree.acceleration(x, v, tau), plant.acceleration(x, v, tau), rtol=0.0,
                    atol=1e-9)
    ms = acceleration_ms(plant, x, v, tau, 10, repeat=1)
    assert np.isfinite(ms) and ms >= 0.0


# --- plant effects (rrr_pin.control.effects) on both engines ------------------------------------


def test_engines_agree_when_a_delay_makes_the_loop_diverge(rrr, rrr_refs):
    from rrr_pin.control.effects import PlantEffects

    # FL at lam = 100 has a delay margin of ~6 ms at 1 kHz; 12 ms drives it unstable.
    py, cc = run_both(rrr, fl_controller(rrr), rrr_refs["sine"], 2.0, rate=RATE, dt=5e-4,
                      effects=PlantEffects(delay=0.012))
    assert (py.time, py.joint) == (cc.time, cc.joint)


# --- a law's NaN or inf torque: the same status on both engines (issue 24) ---------------------

def test_a_torque_overflow_at_an_rk4_stage_stops_both_engines_alike(rrr):
    # Kd = 1e306 with qd0 1e-3 rad/s off the reference: the first stage's torque is ~1e303 N m
    # (finite), the arm's acceleration ~1e302, and the second stage's Kd (rd - v2) overflows to
    # -inf. Both engines stop at the step from t = 0 with the law's reason.
    law = PDGravity(nominal=rrr, Kp=np.full(3, 1e3), Kd=np.full(3, 1e306))
    ref = default_reference(rrr)
    qd0 = ref(0.0)[1] + [1e-3, 0.0, 0.0]
    with np.errstate(over="ignore", invalid="ignore"):
        py, cc = run_both(rrr, law, ref, 0.05, qd0=qd0)
    assert str(py) == str(cc) == (
        "simulation of plant 'rrr' stopped at t = 0 s: law 'pd' returned a non-finite torque "
        "(NaN or inf) for joint 'joint1' in the step from t = 0 s")


def test_a_saturated_inf_torque_stops_both_engines_at_the_same_step(rrr):
    # Kp = 1e308 under a 1 N m saturation: the arm falls under gravity, and once |r - q| > 1.8
    # rad, Kp (r - q) overflows to inf. The saturation would clip it to 1 N m; both engines stop
    # where the law returned it instead (the same control step, the same joint).
    law = PDGravity(nominal=rrr, Kp=np.full(3, 1e308), Kd=np.zeros(3))
    ref = QuinticReference(start=np.zeros(3), goal=np.zeros(3), move_time=1.0)
    with np.errstate(over="ignore", invalid="ignore"):
        py, cc = run_both(rrr, law, ref, 1.0, rate=RATE, effects=PlantEffects(torque_limit=1.0))
    assert str(py) == str(cc)
    assert (py.time, py.joint) == (cc.time, cc.joint)
    assert py.joint == "joint2" and 0.1 < py.time < 1.0
    assert "law 'pd' returned a non-finite torque (NaN or inf)" in str(py)


@pytest.mark.parametrize("rate", [None, RATE], ids=["continuous", "sampled"])
def test_a_non_finite_first_torque_is_the_same_value_error_on_both_engines(rrr, rate):
    # 2 rad off the reference: Kp (r - q) = -2e308 overflows at the first call.
    law = PDGravity(nominal=rrr, Kp=np.full(3, 1e308), Kd=np.zeros(3))
    ref = default_reference(rrr)
    q0 = ref(0.0)[0] + [2.0, 0.0, 0.0]
    out = []
    for engine in ("python", "compiled"):
        with np.errstate(over="ignore"), pytest.raises(ValueError) as info:
            simulate(rrr, law, ref, 0.05, rate=rate, q0=q0, engine=engine)
        out.append(str(info.value))
    assert out[0] == out[1]
    assert "law 'pd'" in out[0] and "the non-finite [-inf, " in out[0]

"""H-infinity + FL told the torque limits (``hinf_aw``, rrr_pin.control.laws.AntiWindupTracking).

Against independent references: Hanus's self-conditioned controller written out from its
textbook form, ``x+ = Ad x + Bd Dd^-1 (y_hat - Cd x)`` with ``y_hat`` from Pinocchio's
``computeMinverse`` and ``rnea`` (a second algorithm for ``Mhat^-1`` and ``Vhat + Ghat``); the
unconditioned law (``hinf``) where nothing saturates; and the Python engine against the compiled
one. Then the study of issue 20: at 90 % of the peak torque ``hinf`` diverges, ``hinf_aw`` does
not. On every kind of plant (a closed chain's actuated joints too): a limit never reached runs
the ideal study's numbers, and the torque limit of ``--torque-limit P%`` is P % of the peak of
torques that Pinocchio's forward dynamics (ABA; ``constraintDynamics`` on a closed chain) turn
back into the reference's acceleration.
"""

import json
from dataclasses import fields

import control
import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from rrr_pin import cli, paper_params
from rrr_pin.campaign.runner import RunSettings, make_laws
from rrr_pin.campaign.study import StudyConfig, run_study
from rrr_pin.control.catalog import make_law
from rrr_pin.control.effects import (
    PlantEffects,
    check_torque_limit,
    peak_torque,
    torque_limit_spec,
)
from rrr_pin.control.laws import (
    AntiWindupTracking,
    FLAWForm,
    hinf_aw_controller,
    hinf_fl_controller,
)
from rrr_pin.control.references import default_reference, study_reference
from rrr_pin.model.dynamics import robot_from_xml
from rrr_pin.model.plant import EFFORT_LIMITS
from rrr_pin.model.uncertainty import Tolerances, sample_plants
from rrr_pin.sim.extension import EXTENSION, available, law_name
from rrr_pin.sim.simulation import simulate
from rrr_pin.sim.trajectory import SimulationDiverged, saturation
from rrr_pin.validation import FieldError

# The paper's H-infinity controller, eq. (18), typed from the paper (not from rrr_pin.design).
K18 = control.tf([47.40, 47.40 * (134.75 + 12.17), 47.40 * 134.75 * 12.17],
                 [1.0, 513.37 + 0.19, 513.37 * 0.19])

#: Issue 20's limits, about 10 % below the peak torque of the paper's reference [N m].
ISSUE_LIMIT = (150.0, 270.0, 45.0)

needs_ext = pytest.mark.skipif(not available(), reason="compiled extension not built")


@pytest.fixture(scope="module")
def ref(rrr):
    return default_reference(rrr)


def plants(rrr, count):
    """The paper's uncertain RRR plants 0..count-1 of seed 0 (20 % inertia, 5 % lengths)."""
    return [robot_from_xml(p.urdf, gravity=rrr.gravity, name=f"sample{p.index}")
            for p in sample_plants(paper_params(), count, 0)]


@pytest.mark.parametrize("plant, duration", [("rrr", 0.5), ("fivebar", 0.1)],
                         indirect=["plant"], ids=["rrr", "fivebar"])
@pytest.mark.parametrize("rate", [None, 1000.0], ids=["continuous", "sampled"])
def test_without_saturation_hinf_aw_is_hinf(plant, duration, rate):
    # Limits never reached (a URDF's, 1000 N m on the RRR against a peak of 299 N m; a closed
    # chain, whose MJCF carries none, is told 1000 N m): the conditioning never acts, so the
    # run on an uncertain plant is the unconditioned law's. 1e-12 rad: the issue's
    # specification (the two compute the same floating-point operations).
    uncertain, _ = plant.perturbed(np.random.default_rng([0, 0]), Tolerances())
    limit = "urdf" if plant.has(EFFORT_LIMITS) else 1e3
    aw = hinf_aw_controller(plant, K18, torque_limit=limit)
    if plant.has(EFFORT_LIMITS):
        assert_array_equal(aw.limit, plant.model.effortLimit)
    ref = study_reference(plant, duration)
    a = simulate(uncertain, aw, ref, duration, rate=rate, engine="python")
    b = simulate(uncertain, hinf_fl_controller(plant, K18), ref, duration, rate=rate,
                 engine="python")
    assert np.abs(a.tau).max() < 0.5 * aw.limit.min()
    assert_allclose(a.q, b.q, rtol=0.0, atol=1e-12)
    assert_allclose(a.tau, b.tau, rtol=0.0, atol=1e-9)
    # ... and it clips to its limits where they are reached: 0.5 N m, 0.1 rad off
    tight = hinf_aw_controller(plant, K18, torque_limit=0.5)
    q = plant.neutral()
    plant.reset(q)
    tau = tight.torque(0.0, q, 0 * q, q + 0.1, 0 * q, 0 * q, np.zeros(tight.nx))
    assert_allclose(np.abs(tau), 0.5, rtol=0, atol=0)


@pytest.mark.parametrize("make", [
    lambda plant: make_law("hinf_aw", plant),
    lambda plant: hinf_aw_controller(plant, K18),
    lambda plant: make_laws("fl,hinf_aw", plant),
], ids=["make_law", "hinf_aw_controller", "make_laws"])
def test_hinf_aw_on_a_plant_without_effort_limits_must_be_told_them(fivebar, make):
    # The default limits are the description's (EFFORT_LIMITS): an MJCF motor has none, so a
    # closed chain's hinf_aw is refused by that capability, naming the plant and the joints.
    assert not fivebar.has(EFFORT_LIMITS)
    with pytest.raises(FieldError, match=r"torque_limit = 'urdf' reads the effort limits of a "
                                         r"URDF, and the closed chain 'fivebar' carries none "
                                         r".*one per actuated joint: qa1, qa2"):
        make(fivebar)


def _textbook(rrr, law, mats, q, qd, r, rd, rdd, x):
    """Hanus's conditioned step from its textbook form, with Pinocchio's M^-1 and RNEA."""
    A, B, C, D = mats
    lam = law.lam
    e = r - q
    y = C @ x + D @ e
    taubar = rdd + 2 * lam * (rd - qd) + lam * lam * (e + y)
    tau = pin.rnea(rrr.model, rrr.data, q, qd, taubar)  # M taubar + V + G
    tau_s = np.clip(tau, -law.limit, law.limit)
    nle = pin.rnea(rrr.model, rrr.data, q, qd, np.zeros(3))
    Minv = pin.computeMinverse(rrr.model, rrr.data, q)
    Minv = np.triu(Minv) + np.triu(Minv, 1).T
    taubar_hat = Minv @ (tau_s - nle)
    y_hat = (taubar_hat - rdd - 2 * lam * (rd - qd)) / lam ** 2 - e
    e_r = np.linalg.solve(D, y_hat - C @ x)  # the realizable error
    return tau_s, A @ x + B @ e_r


@pytest.mark.parametrize("rate", [None, 1000.0], ids=["continuous", "sampled"])
def test_conditioning_is_hanus_s_form(rrr, rate):
    # A state far from the reference: every joint clips at these limits.
    law = hinf_aw_controller(rrr, K18, torque_limit=ISSUE_LIMIT)
    rng = np.random.default_rng(3)
    q, qd = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3)
    r, rd, rdd = q + 0.3, rng.uniform(-1, 1, 3), rng.uniform(-5, 5, 3)
    x = rng.uniform(-0.1, 0.1, law.nx)
    if rate is None:
        mats = law.continuous_matrices()
        tau = law.torque(0.0, q, qd, r, rd, rdd, x)
        nxt = law.derivative(0.0, q, qd, r, rd, rdd, x)
    else:
        sampled = law.sampled(rate)
        mats = law.discretize(rate)
        tau, nxt = sampled.step(0.0, q, qd, r, rd, rdd, x)
    tau_s, ref_next = _textbook(rrr, law, mats, q, qd, r, rd, rdd, x)
    assert np.all(np.abs(tau) == law.limit)  # every joint at its limit
    assert_array_equal(tau, tau_s)
    # 1e-9 relative: M^-1 by LU (the law) against computeMinverse (ABA-based), both ~1e-15
    # relative, times the conditioning's condition number (|B D^-1| ~ 3).
    assert_allclose(nxt, ref_next, rtol=1e-9, atol=1e-12)


def test_a_d_that_cannot_be_inverted_is_refused(rrr):
    with pytest.raises(ValueError, match=r"law 'hinf_aw': the self-conditioned .Hanus. form "
                                         r"needs K's D non-singular"):
        hinf_aw_controller(rrr, control.tf([1.0], [1.0, 1.0]))  # strictly proper: D = 0
    with pytest.raises(ValueError, match=r"needs a controller K with a non-singular D; got "
                                         r"K = None"):
        AntiWindupTracking(rrr, 45.0, None, name="hinf_aw")


def test_unstable_zeros_of_k_are_refused(rrr):
    # K = (s - 5)/(s + 10): D = 1, its zero at +5 rad/s is what A - B D^-1 C follows.
    with pytest.raises(ValueError, match=r"K has unstable zeros"):
        hinf_aw_controller(rrr, control.tf([1.0, -5.0], [1.0, 10.0]))


@needs_ext
@pytest.mark.parametrize("rate, fx", [(None, False), (1000.0, False), (1000.0, True)],
                         ids=["continuous", "sampled", "sampled-plant-limit"])
def test_engines_agree_on_hinf_aw_saturated(rrr, ref, rate, fx):
    # Saturated for most of the run at the issue's limits, on an uncertain plant. 1e-12 rad:
    # the issue's specification (measured: 7e-15 rad; tau within 3e-10 N m, its round-off
    # times lam^2 (1 + D) Mhat ~ 1e5 N m/rad).
    plant = plants(rrr, 1)[0]
    law = hinf_aw_controller(rrr, K18, torque_limit=ISSUE_LIMIT)
    effects = PlantEffects(torque_limit=ISSUE_LIMIT) if fx else None
    a = simulate(plant, law, ref, 0.6, rate=rate, engine="python", effects=effects)
    b = simulate(plant, law, ref, 0.6, rate=rate, engine="compiled", effects=effects)
    assert np.mean(np.abs(a.tau[:-1]) >= np.array(ISSUE_LIMIT)) > 0.1  # it does saturate
    assert_allclose(b.q, a.q, rtol=0.0, atol=1e-12)
    assert_allclose(b.qd, a.qd, rtol=0.0, atol=1e-10)
    assert_allclose(b.tau, a.tau, rtol=0.0, atol=1e-8)


@needs_ext
def test_the_compiled_form_is_plain(rrr):
    form = hinf_aw_controller(rrr, K18, torque_limit=ISSUE_LIMIT).sampled(1000.0).compiled_form()
    assert type(form) is FLAWForm and law_name(form) == "FLAWLaw"
    cxx = EXTENSION.FLAWLaw()  # sim.compiled copies every field but nominal by name
    assert [f.name for f in fields(FLAWForm)] == ["nominal", "lam", "A", "B", "C", "D", "L",
                                                 "limit"]
    assert all(hasattr(cxx, f.name) for f in fields(FLAWForm) if f.name != "nominal")
    assert_allclose(form.L @ form.D, form.B, rtol=0, atol=1e-12)  # L = B D^-1
    assert_array_equal(form.limit, ISSUE_LIMIT)


def test_saturation_counts_periods_at_the_limit():
    tau = np.array([[1.0, 0.0], [2.0, -3.0], [0.5, 3.0], [-2.0, 1.0]])
    s = saturation(tau, np.array([2.0, 3.0]), 0.01)
    assert s["per_joint_fraction"] == [0.5, 0.5] and s["fraction"] == 0.75
    assert s["seconds"] == pytest.approx(0.03, rel=1e-12)


@pytest.mark.parametrize("value, match", [
    (-1.0, r"torque_limit = -1.0: expected finite > 0"),
    ((150.0, 0.0, 45.0), r"torque_limit = \[150.0, 0.0, 45.0\]: expected finite > 0"),
    (float("nan"), r"torque_limit = nan: expected finite > 0"),
    ((150.0, 270.0), r"expected one value or 3 \(one per joint\), got 2"),
    ("max", r"expected 'urdf', a number or 3 numbers"),
    ((150.0, 100.0, 45.0), r"torque_limit of joint 'joint2' is 100 N m, below the gravity "
                           r"torque 202.41 N m at the reference's start"),
], ids=["negative", "zero", "nan", "size", "word", "below-gravity"])
def test_bad_limits_are_refused(rrr, ref, value, match):
    # Gravity at r(0) = (0, 0.433, -0.433) rad, by RNEA at rest (the check uses Robot.G).
    g = pin.rnea(rrr.model, rrr.data, ref(0.0)[0], np.zeros(3), np.zeros(3))
    assert g[1] == pytest.approx(202.41, abs=5e-3)
    with pytest.raises(FieldError, match=match):
        check_torque_limit(rrr, value, ref)


def test_peak_torque_is_the_reference_s_inverse_dynamics(rrr, ref):
    t = np.linspace(0.0, 4.0, 401)
    R, RD, RDD = ref.sample(t)
    # Independent: M (CRBA) rdd + nonLinearEffects, per sample.
    tau = [pin.crba(rrr.model, rrr.data, R[k]) @ RDD[k]
           + pin.nonLinearEffects(rrr.model, rrr.data, R[k], RD[k]) for k in range(len(t))]
    assert_allclose(peak_torque(rrr, ref, t), np.max(np.abs(tau), axis=0), rtol=1e-12)


def _under_limits(rrr, ref, plant, fraction):
    limit = fraction * peak_torque(rrr, ref, np.arange(4001) / 1000.0)
    effects = PlantEffects(torque_limit=tuple(limit))
    out = {}
    for law in (hinf_fl_controller(rrr, K18), hinf_aw_controller(rrr, K18, torque_limit=limit)):
        try:
            traj = simulate(plant, law, ref, 4.0, rate=1000.0, effects=effects)
            out[law.name] = float(np.sqrt(np.mean(traj.error ** 2)))
        except SimulationDiverged as exc:
            out[law.name] = exc
    return out


#: Bound on hinf_aw's RMS error under 90 % of the peak torque [rad]: bounded, not small. The
#: measured RMS errors (K18, 4 s, 1 kHz) are 0.107 rad on the nominal arm and up to 0.89 rad on
#: the uncertain plants; the same loop with K replaced by its static gain D does worse (0.18 and
#: 0.95 rad): under the limit, the loop's stiffness (lam^2 (1 + D), 5 times FL's), not windup,
#: sets the error. 1 rad is under the 2 rad the reference spans.
AW_RMS_BOUND = 1.0


def test_at_90_percent_hinf_diverges_and_hinf_aw_does_not(rrr, ref):
    # Issue 20: at 90 % of the peak torque (per joint), on the nominal arm and the paper's 10
    # uncertain plants (2.6 s on the compiled engine; measured: hinf diverges on the nominal arm
    # and on 8 of the 10 plants, hinf_aw on none).
    outs = [_under_limits(rrr, ref, p, 0.9) for p in [rrr] + plants(rrr, 10)]
    assert isinstance(outs[0]["hinf"], SimulationDiverged)
    assert sum(isinstance(o["hinf"], SimulationDiverged) for o in outs[1:]) >= 1
    assert all(isinstance(o["hinf_aw"], float) and o["hinf_aw"] < AW_RMS_BOUND for o in outs)


def test_study_under_a_limit_sets_aside_a_law_that_diverges_on_the_nominal_arm(rrr, ref):
    # hinf diverges on the nominal arm at 1.895 s at the issue's limits (issue 20): 2 s runs.
    run = RunSettings(duration=2.0, rate=1000.0, effects=PlantEffects(torque_limit=ISSUE_LIMIT))
    laws = make_laws("fl,hinf,hinf_aw", rrr, K=K18, torque_limit=ISSUE_LIMIT)
    result = run_study(rrr, laws, config=StudyConfig(run=run, samples=1, jobs=1),
                       reference=ref)
    assert result.names == ["fl", "hinf_aw"] and list(result.dropped) == ["hinf"]
    assert "diverged at t = 1.895 s" in result.dropped["hinf"]["nominal"]
    tl = result.to_json()["summary"]["torque_limit"]
    assert tl["limit_Nm"] == list(ISSUE_LIMIT)
    hinf = tl["laws"]["hinf"]
    assert hinf["nominal_diverged"] and hinf["nominal_rms_error"] is None
    for name in ("fl", "hinf_aw"):
        d, traj = tl["laws"][name], result.nominal[name]
        assert not d["nominal_diverged"] and d["uncertain_diverged"] == 0
        # From the trajectory's own arrays: periods with a joint at its limit, and the RMS error.
        at = np.any(np.abs(traj.tau[:-1]) >= np.array(ISSUE_LIMIT), axis=1)
        assert d["nominal_saturated"] == pytest.approx(at.mean(), abs=1e-15)
        assert 0.0 < d["nominal_saturated"] < 1.0
        assert d["nominal_rms_error"] == pytest.approx(np.sqrt(np.mean(traj.error ** 2)),
                                                       rel=1e-12)


def test_a_study_refuses_a_limit_below_gravity(rrr, ref):
    run = RunSettings(duration=0.1, rate=1000.0,
                      effects=PlantEffects(torque_limit=(150.0, 100.0, 45.0)))
    with pytest.raises(FieldError, match=r"joint 'joint2' is 100 N m, below the gravity torque "
                                         r"202.41 N m"):
        run_study(rrr, make_laws("fl", rrr), config=StudyConfig(run=run, samples=0),
                  reference=ref)


@pytest.mark.parametrize("robot, argv, message", [
    ("rrr", ["--torque-limit=-1", "--rate", "1000"],
     "--torque-limit = [-1.0]: expected finite > 0"),
    ("rrr", ["--torque-limit", "150,0,45", "--rate", "1000"],
     "--torque-limit = [150.0, 0.0, 45.0]: expected finite > 0 per joint"),
    ("rrr", ["--torque-limit", "nan,270,45", "--rate", "1000"],
     "--torque-limit = [nan, 270.0, 45.0]: expected finite > 0"),
    ("rrr", ["--torque-limit", "150,270", "--rate", "1000"],
     "expected one value or 3 (one per joint), got 2"),
    ("fivebar", ["--torque-limit", "1,2,3", "--rate", "1000"],
     "--torque-limit = [1.0, 2.0, 3.0]: expected one value or 2 (one per joint), got 3"),
    ("rrr", ["--torque-limit", "150,100,45", "--rate", "1000"],
     "--torque-limit of joint 'joint2' is 100 N m, below the gravity torque 202.41 N m"),
    ("rrr", ["--torque-limit", "50%", "--rate", "1000"],
     "--torque-limit of joint 'joint2' is 149.718 N m, below the gravity torque 202.41 N m"),
    ("rrr", ["--torque-limit", "0%", "--rate", "1000"], "the percent must be finite and > 0"),
    ("fivebar", ["--torque-limit=-5%", "--rate", "1000"], "the percent must be finite and > 0"),
    ("rrr", ["--torque-limit", "x%", "--rate", "1000"], "expected auto, P% (a number P > 0"),
    ("rrr", ["--torque-limit", "auto"], "give --rate HZ too"),
    # a closed chain's MJCF motors carry no effort limit: auto, and hinf_aw without a limit
    ("fivebar", ["--torque-limit", "auto", "--rate", "1000"],
     "--torque-limit = 'urdf' reads the effort limits of a URDF, and the closed chain "
     "'fivebar' carries none"),
    ("fivebar", ["--controllers", "fl,hinf_aw"],
     "reads the effort limits of a URDF, and the closed chain 'fivebar' carries none"),
], ids=["negative", "zero", "nan", "size", "chain-size", "below-gravity",
        "percent-below-gravity", "percent-zero", "chain-percent-negative", "percent-word",
        "no-rate", "chain-auto", "chain-aw-without-limit"])
def test_reproduce_refuses_bad_torque_limits(robot, argv, message, capsys, tmp_path):
    out = tmp_path / "o"
    assert cli.main(["reproduce", "--robot", robot, *argv, "--out", str(out),
                     "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (out / "results.json").exists()


def _checked_inverse_dynamics(plant, reference, t):
    """The reference's torques ``inverse_dynamics(r, rd, rdd)``, each checked by the plant's
    forward dynamics (ABA; a closed chain's ``constraintDynamics`` on its full closed state):
    applied at ``(r, rd)`` they give back ``rdd``."""
    R, RD, RDD = reference.sample(t)
    out = []
    for r, rd, rdd in zip(R, RD, RDD, strict=True):
        tau = plant.inverse_dynamics(r, rd, rdd)
        x, v = plant.start(r, rd)
        a = plant.acceleration(x, v, tau)
        a = a if plant.actuated_index is None else a[plant.actuated_index]
        # a second algorithm for the same dynamics: round-off (constraintDynamics' proximal
        # accuracy, 6e-11 rad/s^2 at mu = 1e-4, on a closed chain)
        assert_allclose(a, rdd, rtol=1e-9, atol=1e-8)
        out.append(tau)
    return np.array(out)


DURATION = 0.05  # s, at 1 kHz


def _limited_study(plant, laws, limit):
    run = RunSettings(duration=DURATION, rate=1000.0,
                      effects=None if limit is None else PlantEffects(torque_limit=limit))
    return run_study(plant, make_laws(laws, plant, K=K18, torque_limit=limit),
                     config=StudyConfig(run=run, samples=0))


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
def test_a_limit_never_reached_is_the_ideal_study(plant):
    # 1e9 N m: the plants run with a torque-limit effect that never acts; the ideal study
    # runs without effects (possibly on another engine, pinned to the Python one): the same
    # numbers to round-off.
    ideal = _limited_study(plant, "fl,hinf", None)
    limited = _limited_study(plant, "fl,hinf,hinf_aw", 1e9)
    for law in ("fl", "hinf"):
        a, b = ideal.nominal[law], limited.nominal[law]
        assert b.info["saturation"]["fraction"] == 0.0 and "saturation" not in a.info
        assert_allclose(b.q, a.q, rtol=0, atol=1e-12)
    # hinf_aw unsaturated is hinf (the same arithmetic on the same engine)
    assert_allclose(limited.nominal["hinf_aw"].q, limited.nominal["hinf"].q, rtol=0, atol=0)


def test_a_chain_clips_at_the_limit_and_records_the_time_there(fivebar):
    # The arm's counterpart is the study above that sets hinf aside (limits above gravity).
    # N m: above the gravity torque at r(0) (1.1 N m), below the reference's peak (285 N m:
    # the tip circle once in 50 ms)
    limit = 50.0
    traj = _limited_study(fivebar, "fl", limit).nominal["fl"]
    assert np.max(np.abs(traj.tau)) <= limit
    at = (np.abs(traj.tau[:-1]) >= limit).any(axis=1).mean()  # recount from the torques
    assert traj.info["saturation"]["fraction"] == pytest.approx(at, abs=0)
    assert at > 0.0


def _peak(plant, duration=DURATION, rate=1000.0):
    """The peak torque of the study reference over a run's control instants, checked torques."""
    t = np.arange(round(duration * rate) + 1) / rate
    return np.max(np.abs(_checked_inverse_dynamics(plant, study_reference(plant, duration),
                                                   t)), axis=0)


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
def test_percent_is_of_the_peak_torque_of_the_reference(plant):
    # 200 %: above the gravity torque at r(0) on every joint of both plants
    limit, info = torque_limit_spec(plant, "200%", study_reference(plant, DURATION), 1000.0,
                                    DURATION)
    peak = _peak(plant)
    assert_allclose(info["peak_torque_Nm"], peak, rtol=1e-12)
    assert_allclose(limit, 2.0 * peak, rtol=1e-12)
    assert (info["spec"], info["percent"]) == ("200%", 200.0)


def test_cli_records_the_torque_limit_of_a_percent(fivebar, tmp_path, capsys):
    out = tmp_path / "r"
    assert cli.main(["reproduce", "--robot", "fivebar", "--torque-limit", "200%",
                     "--samples", "0", "--duration", str(DURATION), "--rate", "1000",
                     "--no-certify", "--no-progress", "--out", str(out)]) == 0
    data = json.loads((out / "results.json").read_text())
    tl = data["summary"]["torque_limit"]
    peak = _peak(fivebar)
    assert_allclose(tl["peak_torque_Nm"], peak, rtol=1e-12)
    assert_allclose(tl["limit_Nm"], 2.0 * peak, rtol=1e-12)
    assert_allclose(data["config"]["effects"]["torque_limit_Nm"], 2.0 * peak, rtol=1e-12)
    assert tl["spec"] == "200%" and set(tl["laws"]) == {"fl", "hinf", "hinf_aw"}
    assert [c["name"] for c in data["controllers"]] == ["fl", "hinf", "hinf_aw"]
    assert " N m (200%), per controller" in capsys.readouterr().out


@pytest.mark.slow
def test_reproduce_under_a_limit_records_it(tmp_path, capsys):
    out = tmp_path / "o"
    assert cli.main(["reproduce", "--torque-limit", "90%", "--rate", "1000", "--samples", "1",
                     "--duration", "3", "--no-certify", "--no-progress", "--out", str(out)]) == 0
    tl = json.loads((out / "results.json").read_text())["summary"]["torque_limit"]
    assert tl["spec"] == "90%" and tl["percent"] == 90.0
    assert_allclose(tl["limit_Nm"], 0.9 * np.array(tl["peak_torque_Nm"]), rtol=1e-15)
    assert set(tl["laws"]) == {"fl", "hinf", "hinf_aw"}
    assert "Under the torque limit" in (out / "results.md").read_text()

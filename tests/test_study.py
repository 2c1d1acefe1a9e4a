"""The study (rrr_pin.campaign.study) on every kind of plant: a serial arm, a closed chain.

Figures are recomputed here from the trajectories the study keeps; the plants from the seed
rule ``Plant.perturbed(default_rng([seed, k]))``; the certificates against the design's
``b = 1 / gamma``.
"""

import re

import control
import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin.campaign.runner import RunSettings, make_laws
from rrr_pin.campaign.study import StudyConfig, run_study
from rrr_pin.control.laws import (
    ControlLaw,
    PDGravity,
    fl_controller,
    hinf_fl_controller,
    pd_controller,
)
from rrr_pin.report.results import results_markdown
from rrr_pin.robust.certificates import CertificateSpec

K18 = control.tf([47.40, 47.40 * (134.75 + 12.17), 47.40 * 134.75 * 12.17],
                 [1.0, 513.37 + 0.19, 513.37 * 0.19])


def _config(**kw):
    return StudyConfig(run=RunSettings(duration=0.5), **kw)


def test_results_do_not_depend_on_jobs(rrr):
    laws = [fl_controller(rrr), hinf_fl_controller(rrr, K18)]
    runs = [run_study(rrr, laws, config=_config(samples=2, jobs=j)) for j in (1, 2)]
    a, b = (r.to_json() for r in runs)
    assert a["uncertain"]["samples"] == b["uncertain"]["samples"]
    assert a["summary"] == b["summary"]


def test_summary_is_computed_from_the_samples(rrr):
    laws = make_laws("fl,hinf,pd", rrr, K=K18)
    result = run_study(rrr, laws, config=_config(samples=3, jobs=1, seed=2))
    data = result.to_json()
    s = data["summary"]
    assert s["samples_ok"] == 3 and s["baseline"] == "fl"
    # Recompute the headline ratios straight from the trajectories (not from the metrics).
    names = ("fl", "hinf", "pd")
    err = {k: np.concatenate([x["trajectories"][k].error.ravel() for x in result.samples])
           for k in names}
    tau = {k: np.concatenate([x["trajectories"][k].tau.ravel() for x in result.samples])
           for k in names}

    def rms(v):
        return np.sqrt(np.mean(v**2))

    for k in ("hinf", "pd"):
        assert_allclose(s["error_ratio_uncertain"][k], rms(err["fl"]) / rms(err[k]), rtol=1e-12)
        assert_allclose(s["torque_ratio_uncertain"][k], rms(tau[k]) / rms(tau["fl"]),
                        rtol=1e-12)
        assert len(s["error_ratio_uncertain_per_joint"][k]) == 3
    assert "fl" not in s["error_ratio_uncertain"]
    assert set(data["nominal"]) == set(names)
    assert [c["name"] for c in data["controllers"]] == list(names)
    assert data["config"]["engine"] == "auto" and data["config"]["duration_s"] == 0.5


def test_a_users_law_runs_in_the_study(rrr):
    class Stiff(ControlLaw):
        """A user's law: FL-free joint PD with gravity from the robot model."""

        name, label, n = "stiff", "my PD", 3

        def torque(self, t, q, qd, r, rd, rdd, x):
            return 4000.0 * (r - q) + 100.0 * (rd - qd) + rrr.G(q)

    laws = [pd_controller(rrr), Stiff()]
    result = run_study(rrr, laws, config=StudyConfig(run=RunSettings(duration=0.3),
                                                       samples=1, jobs=1, baseline="pd"))
    s = result.to_json()["summary"]
    assert set(s["error_ratio_uncertain"]) == {"stiff"}
    assert result.nominal["stiff"].info["engine"] == "python"
    # auto: batched generated dynamics for a generated structure (the RRR), else compiled.
    assert result.nominal["pd"].info["engine"] in ("codegen", "compiled", "python")


@pytest.mark.parametrize("kwargs,message", [
    ({"baseline": "nosuch"}, "baseline 'nosuch' is not among the controllers"),
], ids=["baseline"])
def test_bad_study(rrr, kwargs, message):
    with pytest.raises(ValueError, match=message):
        run_study(rrr, [fl_controller(rrr)], config=_config(samples=0, **kwargs))


def test_duplicate_names_refused(rrr):
    with pytest.raises(ValueError, match="names must be unique, repeated: fl"):
        run_study(rrr, [fl_controller(rrr), fl_controller(rrr, 50.0)],
                  config=_config(samples=0))


@pytest.mark.parametrize("kwargs,message", [
    ({"samples": -1}, "samples must be an integer >= 0"),
    ({"seed": -1}, "seed must be an integer >= 0"),
    ({"jobs": 0}, "jobs must be an integer >= 1"),
], ids=["samples", "seed", "jobs"])
def test_bad_config(kwargs, message):
    with pytest.raises(ValueError, match=message):
        StudyConfig(**kwargs)


@pytest.mark.parametrize("kwargs,message", [
    ({"duration": float("nan")}, "duration must be a finite number > 0"),
    ({"duration": 1e-4, "rate": 1000.0}, "shorter than one control period"),
    ({"duration": 1e-4}, "shorter than one RK4 step"),
    ({"rate": float("inf")}, "rate must be a finite number"),
    ({"engine": "gpu"}, "engine must be one of"),
    ({"limit_margin": float("nan")}, "limit_margin must be a finite number"),
], ids=["duration", "short-sampled", "short-continuous", "rate", "engine", "margin"])
def test_bad_run_settings(kwargs, message):
    with pytest.raises(ValueError, match=message):
        RunSettings(**kwargs)


def test_unknown_controller_name(rrr):
    with pytest.raises(ValueError, match="unknown controller 'lqr'; built-in controllers: fl"):
        make_laws("fl,lqr", rrr)


def test_certificates_beside_the_simulated_outcome(rrr, paper):
    # Each uncertain plant gets a frozen-configuration certificate: nu-gap < b(Gs, Ks) = 1/gamma
    # of the ncfsyn design (b = 1/gamma is checked independently in tests/test_ncf.py).
    d = paper
    spec = CertificateSpec.from_design(d, points=3)
    result = run_study(rrr, make_laws("fl,hinf", rrr), config=_config(samples=2, jobs=1),
                       certificate=spec)
    data = result.to_json()
    for s in data["uncertain"]["samples"]:
        c = s["certificate"]
        assert c["certified"] == (c["nugap_max"] < c["b"])
        assert_allclose(c["b"], 1.0 / d.gamma_reduced, rtol=1e-6)  # eq. 18 Ks on Gs
    assert data["summary"]["samples_certified"] <= 2
    assert data["certificate"]["points"] == 3


def test_report_gives_no_verdict_from_a_non_finite_ratio(rrr):
    laws = [fl_controller(rrr), hinf_fl_controller(rrr, K18)]
    result = run_study(rrr, laws, config=_config(samples=1, jobs=1))
    data = result.to_json()
    s = data["summary"]
    # A NaN per-joint ratio (0/0: a joint both laws track exactly) must not read as a verdict.
    s["error_ratio_uncertain_per_joint"]["hinf"][1] = float("nan")
    s["torque_ratio_uncertain"]["hinf"] = float("nan")
    text = results_markdown(result, data)
    joint_row = next(line for line in text.splitlines() if line.startswith("| ... per joint"))
    assert "**no verdict**" in joint_row and "every joint" not in joint_row
    torque_row = next(line for line in text.splitlines()
                      if line.startswith("| Uncertain plants: RMS torque"))
    assert "**no verdict**" in torque_row


def test_paper_claims_only_for_the_builtin_laws(rrr):
    # A user's law named "hinf" is not the paper's H-infinity + FL: no paper verdict on it.
    class Mine(ControlLaw):
        name, label, n = "hinf", "my law", 3

        def torque(self, t, q, qd, r, rd, rdd, x):
            return 4000.0 * (r - q) + 100.0 * (rd - qd) + rrr.G(q)

    mine = run_study(rrr, [fl_controller(rrr), Mine()], config=_config(samples=1, jobs=1))
    assert "The paper's claims" not in results_markdown(mine)
    paper = run_study(rrr, make_laws("fl,hinf", rrr, K=K18),
                      config=_config(samples=1, jobs=1))
    assert "The paper's claims" in results_markdown(paper)


def test_nominal_verdict_scale_for_a_closed_path(rrr):
    # A spline that returns to its start: the scale is half its peak-to-peak range, so the
    # exact-model errors (~1e-9 rad) count as equivalent, not "differs".
    from rrr_pin.control.references import SplineReference

    ref = SplineReference([0.0, 0.25, 0.5], [[0, 0, 0], [0.3, -0.2, 0.2], [0, 0, 0]])
    result = run_study(rrr, make_laws("fl,hinf", rrr, K=K18),
                       config=_config(samples=1, jobs=1), reference=ref)
    text = results_markdown(result)
    assert "| equivalent |" in text and "agrees: both below 1.5e-06 rad" in text


def test_study_and_campaign_share_one_settings_record():
    # StudyConfig and CampaignSettings are the same record (rrr_pin.campaign.settings) with
    # their own defaults: the same fields give the same recorded settings.
    import dataclasses

    from rrr_pin.campaign.montecarlo import CampaignSettings
    from rrr_pin.campaign.settings import Settings

    run = RunSettings(duration=0.5, rate=500.0)
    study, campaign = StudyConfig(samples=3, seed=2, run=run), CampaignSettings(3, 2, run)
    assert isinstance(study, Settings) and isinstance(campaign, Settings)
    assert study.to_dict() == campaign.to_dict() == Settings(3, 2, run).to_dict()
    assert [f.name for f in dataclasses.fields(Settings)] == [
        "samples", "seed", "run", "tolerances", "baseline"]
    assert [f.name for f in dataclasses.fields(StudyConfig)][-1] == "jobs"  # not recorded
    assert "jobs" not in study.to_dict()
    assert StudyConfig().samples == 10 and StudyConfig().run == RunSettings()
    with pytest.raises(dataclasses.FrozenInstanceError):
        study.samples = 4


@pytest.mark.parametrize("kwargs,error,message", [
    ({"run": {"duration": 1.0}}, TypeError, "run must be a RunSettings, got dict"),
    ({"tolerances": 0.2}, TypeError,
     "tolerances must be an UncertaintySet, got float"),
    ({"baseline": None}, TypeError, "baseline must be a str, got NoneType"),
    ({"samples": 2.5}, ValueError, "samples must be an integer >= 0, got 2.5"),
    ({"jobs": True}, TypeError, "jobs must be an integer >= 1"),
], ids=["run", "tolerances", "baseline", "samples-fraction", "jobs-bool"])
def test_config_refuses_wrong_types(kwargs, error, message):
    with pytest.raises(error, match=message):
        StudyConfig(**kwargs)


def test_plant_tasks_are_frozen_and_rrr_plants_come_from_the_papers_parameters(rrr, monkeypatch):
    # Every task sent to a worker is a frozen PlantTask; for "rrr" the plants perturb the
    # paper's DH parameters (rrr_pin.model.robots.nominal_params): plant k of seed s is
    # sample_plant(paper_params(), s, k), drawn here independently of the study.
    import dataclasses

    import rrr_pin.campaign.study as study
    from rrr_pin.model.dh import paper_params
    from rrr_pin.model.uncertainty import sample_plant

    seen = []
    real = study.run_plants

    def spy(tasks):
        seen.extend(tasks)
        return real(tasks)

    monkeypatch.setattr(study, "run_plants", spy)
    laws = [fl_controller(rrr)]
    config = _config(samples=1, jobs=1)
    a = run_study(rrr, laws, config=config)
    assert all(isinstance(t, study.PlantTask) for t in seen) and len(seen) == 2
    with pytest.raises(dataclasses.FrozenInstanceError):
        seen[0].certify = True
    assert [t.certify for t in seen[:2]] == [False, True]
    assert rrr.params == paper_params()
    expected = sample_plant(paper_params(), config.seed, 0, config.tolerances)
    assert a.plants[0].plant.urdf == expected.urdf
    # the record adds the plant's armature, damping and friction (none on the paper's RRR)
    assert a.plants[0].parameters == {**expected.parameters,
                                      "joint_dynamics": rrr.joint_dynamics()}


def test_a_study_too_large_to_keep_is_refused_before_any_work():
    from rrr_pin.campaign.study import check_study_size

    # 1001 runs of 2 laws, 40001 samples of t, q, qd, r, tau (1 + 4 x 3 floats) each.
    expected = 1001 * 2 * 40001 * 8 * (1 + 4 * 3)
    big = StudyConfig(samples=1000, run=RunSettings(duration=40.0))
    with pytest.raises(ValueError, match=r"1001 plants x 2 laws x 40001 samples of 3 joints "
                                         r"take about 8.33 GB, above .*MAX_STUDY_BYTES = 2 GB"):
        check_study_size(big, 2, 3)
    forced = StudyConfig(samples=1000, run=RunSettings(duration=40.0, force=True))
    assert check_study_size(forced, 2, 3) == expected


def test_study_logs_its_start_and_end(rrr, caplog):
    import logging
    import re

    with caplog.at_level(logging.INFO, logger="rrr_pin"):
        result = run_study(rrr, [fl_controller(rrr)],
                           config=StudyConfig(run=RunSettings(duration=0.05), samples=1, jobs=1))
    study = [r.getMessage() for r in caplog.records if r.name == "rrr_pin.campaign.study"]
    assert study[0] == ("study on rrr: 1 laws (fl), nominal + 1 uncertain plants (seed 0), "
                        "0.05 s runs")
    ok = sum(s["status"] == "ok" for s in result.samples)
    assert re.fullmatch(rf"study on rrr done in [0-9.]+ s: {ok} of 1 uncertain plants ran "
                        r"every law", study[-1])


class Hold(PDGravity):
    """A user's law: the built-in PD + gravity under its own name (Python engine only)."""


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
def test_a_user_subclass_of_a_builtin_runs_in_the_study(plant):
    user = Hold(plant, Kp=[50.0] * plant.nq, Kd=[2.0] * plant.nq, name="hold")
    result = run_study(plant, [user], config=StudyConfig(run=RunSettings(duration=0.05),
                                                         samples=0, baseline="hold"))
    assert result.names == ["hold"] and result.laws[0]["class"].endswith("Hold")
    # a subclass runs none of the built-in's compiled code: the Python engine
    assert result.nominal["hold"].info["engine"] == "python"
    with pytest.raises(ValueError, match="repeated: hold"):
        run_study(plant, [user, user], config=StudyConfig(run=RunSettings(duration=0.05),
                                                          samples=0, baseline="hold"))


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
def test_a_study_without_the_papers_pair_has_no_verdict_and_certifies(plant, design_for):
    spec = CertificateSpec.from_design(design_for(plant.nq), points=2)
    result = run_study(plant, make_laws("pd", plant),
                       config=StudyConfig(run=RunSettings(duration=0.1), samples=1, jobs=1,
                                          baseline="pd"), certificate=spec)
    assert result.names == ["pd"]
    assert "The paper's claims" not in results_markdown(result)  # fl and hinf are not there
    data = result.to_json()
    cert = data["uncertain"]["samples"][0]["certificate"]
    assert cert["certified"] and 0.0 < cert["nugap_max"] < cert["b"]
    s = data["summary"]
    assert (s["samples_certified"], s["certificate_b"], s["nugap_max"]) == (
        1, cert["b"], cert["nugap_max"])
    # the uncertain figures are the sample's own, recomputed from its trajectory
    e = result.samples[0]["trajectories"]["pd"].error
    assert_allclose(data["uncertain"]["pd"]["rms_error"], np.sqrt(np.mean(e * e, axis=0)),
                    rtol=1e-12)


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
def test_on_the_exact_model_both_laws_track_alike(plant):
    # The paper's nominal claim (Fig. 5c) on the plant's own study reference: the nominal
    # errors of FL alone and H-infinity + FL are both at the integrator's noise level, far
    # below the verdict's threshold: 1e-5 of the reference's scale, a sinusoid's amplitude
    # (the arm's), else half its peak-to-peak range over the run (a mechanism's closed path).
    result = run_study(plant, make_laws("fl,hinf", plant, K=K18),
                       config=StudyConfig(run=RunSettings(duration=0.5), samples=0))
    amp = getattr(result.reference, "amp", None)
    R = result.reference.positions(np.linspace(0.0, 0.5, 1001))
    scale = float(np.max(amp)) if amp is not None else 0.5 * float(np.max(np.ptp(R, axis=0)))
    threshold = 1e-5 * scale
    errors = [float(np.max(np.abs(result.nominal[k].error))) for k in ("fl", "hinf")]
    assert max(errors) < threshold
    row = next(line for line in results_markdown(result).splitlines()
               if line.startswith("| Nominal model: both controllers track alike"))
    assert f"agrees: both below {threshold:.2g} rad" in row


@pytest.mark.parametrize("plant, engine, names, message", [
    ("rrr", "compiled", "fl,hold",
     "law 'hold' (Hold) declares no compiled form, so the compiled engine cannot run it"),
    ("fivebar", "compiled", "fl,hold",
     "law 'hold' (Hold) declares no compiled form, so the compiled engine cannot run it"),
    ("fivebar", "codegen", "fl",
     "engine 'codegen' does not implement closed chains ('fivebar' closes loop)"),
], indirect=["plant"], ids=["rrr-compiled-user-law", "fivebar-compiled-user-law",
                            "fivebar-codegen"])
def test_an_engine_that_cannot_run_a_law_is_refused_before_any_run(plant, engine, names,
                                                                   message, monkeypatch):
    import rrr_pin.campaign.study as study

    def never(tasks):
        raise AssertionError("a plant was run")

    monkeypatch.setattr(study, "run_plants", never)
    config = StudyConfig(run=RunSettings(duration=0.01, rate=1000.0, engine=engine), samples=1)
    laws = make_laws(names.removesuffix(",hold"), plant)
    if names.endswith(",hold"):  # a user's law (no compiled form) beside a built-in
        laws.append(Hold(plant, Kp=[50.0] * plant.nq, Kd=[2.0] * plant.nq, name="hold"))
    with pytest.raises(ValueError, match=re.escape(message)):
        run_study(plant, laws, config=config)

"""Monte Carlo campaigns (rrr_pin.campaign.montecarlo) on every kind of plant.

Every figure is compared with an independent computation of the same run (a lone simulation,
the study's run of the same plant), never with a stored value; sample ``k`` of seed ``s`` is
redrawn here from the documented rule without the campaign (the paper's DH parameters for the
RRR, the mechanism's parameter set for the 5-bar). The CLI tests read one shared
``rrr-pin montecarlo`` run per kind (``montecarlo_run`` of tests/conftest.py).
"""

import csv
import json
import shutil
from dataclasses import asdict, dataclass, replace

import numpy as np
import pytest
from numpy.testing import assert_allclose

import rrr_pin.campaign.montecarlo as mc
from rrr_pin import cli
from rrr_pin.campaign.runner import RunSettings, make_laws
from rrr_pin.campaign.store import StoreError
from rrr_pin.campaign.study import StudyConfig, run_study
from rrr_pin.control.effects import PlantEffects
from rrr_pin.control.references import study_reference
from rrr_pin.model.closed_chain import DRIFT_BOUND, ConstraintDrift
from rrr_pin.model.dh import paper_params
from rrr_pin.model.dynamics import load_robot, robot_from_xml
from rrr_pin.model.mechanisms import FiveBarParams, perturb_mechanism
from rrr_pin.model.plant import CapabilityError
from rrr_pin.model.uncertainty import MechanismTolerances, Tolerances, sample_plant
from rrr_pin.robust.certificates import CertificateSpec
from rrr_pin.sim.simulation import simulate
from rrr_pin.sim.trajectory import SimulationDiverged

KINDS = ["rrr", "fivebar"]
over_kinds = pytest.mark.parametrize("plant", KINDS, indirect=True)

#: How each run is simulated: 0.3 s of 1 kHz sampled laws. The arm on the Python engine; the
#: 5-bar on the engine auto picks (its compiled closed-chain engine: 0.1 s a campaign here,
#: 2.4 s on the Python one).
RUNS = {"rrr": RunSettings(duration=0.3, rate=1000.0, engine="python"),
        "fivebar": RunSettings(duration=0.3, rate=1000.0)}


def settings_of(plant, **kwargs):
    return mc.CampaignSettings(**{"samples": 4, "run": RUNS[plant.name], **kwargs})


def redrawn(plant, seed, k):
    """Sample ``k`` of ``seed`` drawn here from the documented rule: (parameters, plant).

    The RRR: ``sample_plant(paper_params(), seed, k)``; the 5-bar: ``perturb_mechanism`` of
    the built-in parameter set with ``default_rng([seed, k])``, 20 % masses, 5 % lengths.
    Each record ends with the plant's armature, damping and friction (``joint_dynamics``).
    """
    if plant.name == "rrr":
        sample = sample_plant(paper_params(), seed, k)
        drawn = robot_from_xml(sample.urdf, gravity=plant.gravity)
        return {**sample.parameters, "joint_dynamics": drawn.joint_dynamics()}, drawn
    params, factors = perturb_mechanism(FiveBarParams(), np.random.default_rng([seed, k]),
                                        0.2, 0.05)
    drawn = load_robot(params)
    return ({"params": asdict(params), "factors": factors,
             "joint_dynamics": drawn.joint_dynamics()}, drawn)


@pytest.fixture(scope="module")
def laws(plant):
    return make_laws("fl,hinf", plant)


@pytest.fixture(scope="module")
def serial(plant, laws):
    return mc.run_campaign(plant, laws, settings_of(plant), jobs=1)


@over_kinds
def test_identical_whatever_the_jobs(plant, laws, serial):
    # Worker processes rebuild the laws' models and the plants (a closed chain pickles as its
    # MJCF text): the rows must be the same numbers, bit for bit.
    parallel = mc.run_campaign(plant, laws, settings_of(plant), jobs=2, chunk=1)
    assert parallel.rows == serial.rows and parallel.nominal == serial.nominal
    assert [r["index"] for r in serial.rows] == [0, 1, 2, 3]
    assert all(r["status"] == "ok" for r in serial.rows)


@pytest.mark.parametrize("plant", ["rrr", pytest.param("fivebar", marks=pytest.mark.slow)],
                         indirect=True)
def test_dask_cluster_gives_the_same_rows(plant, laws, serial):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        remote = mc.run_campaign(plant, laws, settings_of(plant),
                                 scheduler=cluster.scheduler_address, chunk=1)
    assert remote.rows == serial.rows and remote.nominal == serial.nominal


@over_kinds
def test_rows_agree_with_the_study(plant, laws, serial):
    # The campaign's sample k is the study's sample k (same plant, same figures), and its
    # nominal row (index -1) is the study's nominal run.
    study = run_study(plant, laws, config=StudyConfig(run=RUNS[plant.name], samples=2, jobs=1))
    for sample, row in zip(study.samples, serial.rows, strict=False):
        assert sample["seed"] == row["seed"]
        e = sample["trajectories"]["fl"].error.ravel()
        assert_allclose(row["fl_rms_error"], np.sqrt(np.mean(e**2)), rtol=1e-12)
    nominal = serial.nominal
    assert nominal["index"] == mc.NOMINAL_INDEX and nominal["seed"] is None
    for law in ("fl", "hinf"):
        traj = study.nominal[law]
        e = traj.error
        # The same simulation (plant, law, reference, step): the figures from its arrays.
        assert_allclose(nominal[f"{law}_rms_error"], np.sqrt(np.mean(e * e)), rtol=1e-12)
        assert nominal[f"{law}_max_error"] == np.max(np.abs(e))
        assert_allclose(nominal[f"{law}_rms_torque"], np.sqrt(np.mean(traj.tau ** 2)),
                        rtol=1e-12)
        # a plant that records its loop drift (a closed chain) adds <law>_drift to its rows
        assert (f"{law}_drift" in nominal) == ("drift_m" in traj.info)
        if "drift_m" in traj.info:
            assert nominal[f"{law}_drift"] == traj.info["drift_m"]
        # the engine that ran the row, not the one asked for ("auto")
        assert nominal[f"{law}_engine"] == traj.info["engine"] != "auto"
    for sample, row in zip(study.samples, serial.rows, strict=False):
        assert row["fl_engine"] == sample["trajectories"]["fl"].info["engine"]
    assert serial.per_law == (("drift",) if plant.loop_closures else ()) + ("engine",)
    counts = mc.campaign_summary(serial)["engines"]["fl"]
    assert sum(counts.values()) == len(serial.rows)


@over_kinds
def test_sample_k_is_the_seed_rule_redrawn_and_its_run_alone(plant, laws, serial):
    # The documented rule, recomputed here without the campaign; then the run of sample 1
    # redone alone on the redrawn plant with a fresh law.
    seed = serial.settings["seed"]
    for row in serial.rows:
        parameters, _ = redrawn(plant, seed, row["index"])
        assert row["seed"] == [seed, row["index"]]
        assert json.loads(json.dumps(parameters)) == row["parameters"]
    _, sample = redrawn(plant, seed, 1)
    traj = simulate(sample, make_laws("fl", plant)[0], study_reference(plant, 0.3), 0.3,
                    rate=1000.0, engine=RUNS[plant.name].engine)
    e = traj.q - traj.r
    row = serial.rows[1]
    # Same run, same operations: equal to the last bits (1e-15 allows a different summation).
    assert_allclose(row["fl_rms_error"], np.sqrt(np.mean(e * e)), rtol=1e-15)
    assert_allclose(row["fl_max_error"], np.max(np.abs(e)), rtol=1e-15)
    assert_allclose(row["fl_rms_torque"], np.sqrt(np.mean(traj.tau ** 2)), rtol=1e-15)
    assert_allclose(row["error_ratio_hinf"], row["fl_rms_error"] / row["hinf_rms_error"],
                    rtol=1e-15)
    if plant.loop_closures:
        assert row["fl_drift"] == traj.info["drift_m"] <= DRIFT_BOUND


@pytest.mark.parametrize("plant, failure, status", [
    ("rrr", SimulationDiverged("diverged at t = 0.1 s: joint 'joint2' blew up", 0.1, "joint2"),
     "diverged: hinf: diverged at t = 0.1 s: joint 'joint2' blew up"),
    # a plant's own failure (Plant.failures) is recorded with its kind
    ("fivebar", ConstraintDrift("loop gap 1e-3 m at t = 0.01 s (bound 1e-06 m)"),
     "diverged: hinf: ConstraintDrift: loop gap 1e-3 m at t = 0.01 s (bound 1e-06 m)"),
], indirect=["plant"], ids=KINDS)
def test_a_failed_run_is_recorded_and_the_campaign_goes_on(plant, laws, serial, failure,
                                                           status, monkeypatch):
    import rrr_pin.campaign.runner as runner

    real = runner.simulate_batch

    def flaky(plants, law, *args, **kwargs):
        out = real(plants, law, *args, **kwargs)
        return [failure if p.name == "sample00001" and law.name == "hinf" else r
                for p, r in zip(plants, out, strict=True)]

    monkeypatch.setattr(runner, "simulate_batch", flaky)
    campaign = mc.run_campaign(plant, laws, settings_of(plant), jobs=1)
    assert [r["status"] == "ok" for r in campaign.rows] == [True, False, True, True]
    bad = campaign.rows[1]
    assert bad["status"] == status
    assert "factors" in bad["parameters"]
    assert "hinf_rms_error" not in bad and "error_ratio_hinf" not in bad
    assert bad["fl_rms_error"] == serial.rows[1]["fl_rms_error"]  # the other law's run stays
    summary = mc.campaign_summary(campaign)
    assert summary["samples_diverged"] == 1 and summary["diverged"] == [1]
    assert summary["samples_ok"] == 3
    assert summary["error_ratio_hinf"]["count"] == 3


@over_kinds
def test_summary_statistics(serial):
    s = mc.campaign_summary(serial)
    ratios = [r["fl_rms_error"] / r["hinf_rms_error"] for r in serial.rows]
    assert_allclose(s["error_ratio_hinf"]["median"], np.median(ratios), rtol=1e-12)
    assert s["error_ratio_hinf"]["worst"] == min(ratios)
    assert s["fraction_better"]["hinf"] == np.mean([x > 1 for x in ratios])
    if "drift" in serial.per_law:  # worst drift: the largest of the rows'
        assert s["fl_drift"]["worst"] == max(r["fl_drift"] for r in serial.rows)


@over_kinds
def test_partial_store_resumes_to_identical_rows(plant, laws, serial, tmp_path):
    # A killed run: the nominal and sample 0 on disk and a torn third line; the resumed store
    # holds the same file, byte for byte, and the campaign the same rows (one worker: rows are
    # appended in index order).
    settings = settings_of(plant)
    reference = study_reference(plant, settings.run.duration)
    ref = tmp_path / "ref"
    with mc.open_store(ref, plant, laws, settings, reference) as store:
        mc.run_campaign(plant, laws, settings, jobs=1, chunk=1, store=store)
    cut = tmp_path / "cut"
    shutil.copytree(ref, cut)
    lines = (cut / "parts.jsonl").read_text().splitlines(keepends=True)
    assert len(lines) == 5  # the nominal plant and the 4 samples
    (cut / "parts.jsonl").write_text("".join(lines[:2]) + lines[2][:40])
    with pytest.raises(StoreError, match="resume"):
        mc.open_store(cut, plant, laws, settings, reference)
    with mc.open_store(cut, plant, laws, settings, reference, resume=True) as store:
        assert store.done() == {mc.NOMINAL_INDEX, 0}
        resumed = mc.run_campaign(plant, laws, settings, jobs=1, chunk=1, store=store)
    assert (cut / "parts.jsonl").read_bytes() == (ref / "parts.jsonl").read_bytes()
    assert resumed.rows == serial.rows and resumed.nominal == serial.nominal
    with pytest.raises(StoreError, match="seed"):  # a resume with other settings is refused
        mc.open_store(cut, plant, laws, replace(settings, seed=8), reference, resume=True)


@over_kinds
def test_plant_effects_reach_every_run(plant, laws):
    # A 1 ms delay: the nominal row is the lone simulation with that delay (not the ideal
    # one, which differs).
    run = RUNS[plant.name]
    delayed = replace(run, effects=PlantEffects(delay=1e-3))
    campaign = mc.run_campaign(plant, laws, settings_of(plant, samples=1, run=delayed), jobs=1)
    ref = study_reference(plant, run.duration)
    fl = make_laws("fl", plant)[0]
    by_hand = simulate(plant, fl, ref, run.duration, rate=1000.0,
                       effects=PlantEffects(delay=1e-3))
    ideal = simulate(plant, fl, ref, run.duration, rate=1000.0)
    rms = float(np.sqrt(np.mean((by_hand.q - by_hand.r) ** 2)))
    assert_allclose(campaign.nominal["fl_rms_error"], rms, rtol=1e-12)
    assert abs(rms - float(np.sqrt(np.mean((ideal.q - ideal.r) ** 2)))) > 1e-3 * rms


@pytest.mark.parametrize("plant", KINDS, indirect=True)
def test_certificate_column_matches_the_study(plant, laws, design_for):
    # The campaign's sample k is the study's sample k: the same plant gets the same certificate.
    spec = CertificateSpec.from_design(design_for(plant.nq), points=3)
    run = RUNS[plant.name]
    campaign = mc.run_campaign(plant, laws, settings_of(plant, samples=2), jobs=1,
                               certificate=spec)
    study = run_study(plant, laws, config=StudyConfig(run=run, samples=2, jobs=1),
                      certificate=spec)
    b = spec.margin(plant.nq)
    for row, sample in zip(campaign.rows, study.samples, strict=True):
        assert row["certified"] == (row["nugap_max"] < b)
        assert_allclose(row["nugap_max"], sample["certificate"]["nugap_max"], rtol=1e-12)
    assert "certified" in mc.campaign_columns(["fl", "hinf"], "fl", ["j"], certified=True)
    s = mc.campaign_summary(campaign)
    assert s["certified"] == sum(r["certified"] for r in campaign.rows)


@over_kinds
def test_chunk_tasks_are_frozen_picklable_and_give_the_rows(plant, laws, serial):
    # What crosses the process boundary is a frozen CampaignChunk of a frozen CampaignJob;
    # run in this process after a pickle round trip, it gives the campaign's rows.
    import dataclasses
    import pickle

    settings = settings_of(plant)
    job = mc.CampaignJob(settings=settings, laws=tuple(laws), nominal=plant,
                         reference=study_reference(plant, settings.run.duration))
    task = pickle.loads(pickle.dumps(mc.CampaignChunk(job, (1, 2))))
    assert mc.run_chunk(task) == serial.rows[1:3]
    with pytest.raises(dataclasses.FrozenInstanceError):
        task.indices = (0,)


def test_a_job_arrives_once_per_process(rrr):
    # Chunks of one job unpickled in one process share one job (its laws' and reference's
    # preparation made once); a job made by replace() is another job, never the cached one.
    import dataclasses
    import pickle

    laws = make_laws("fl", rrr)
    job = mc.CampaignJob(settings=settings_of(rrr), laws=tuple(laws), nominal=rrr,
                         reference=study_reference(rrr, 0.01))
    a, b = (pickle.loads(pickle.dumps(mc.CampaignChunk(job, (k,)))) for k in (0, 1))
    assert a.job is b.job and a.job is not job and a.job.laws[0].name == "fl"
    other = pickle.loads(pickle.dumps(mc.CampaignChunk(dataclasses.replace(job, batch=4),
                                                       (0,))))
    assert other.job is not a.job and other.job.batch == 4 and a.job.batch == 16
    for k in range(mc._ARRIVED_MAX + 1):  # the process keeps the last few jobs only
        pickle.loads(pickle.dumps(dataclasses.replace(job, batch=k + 1)))
    assert len(mc._ARRIVED) == mc._ARRIVED_MAX


# --- the CLI: one shared run per kind -------------------------------------------------------

@pytest.mark.parametrize("montecarlo_run, plant", [(k, k) for k in [*KINDS, "delta"]],
                         indirect=True, ids=[*KINDS, "delta"])
def test_cli_writes_the_campaign_files(montecarlo_run, plant, strict_json):
    assert montecarlo_run.code == 0, montecarlo_run.stderr
    out = montecarlo_run.out
    with open(out / "campaign.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["index"] for r in rows] == ["0", "1"]
    # seed and index are integers, and they name the plant: default_rng([seed, index])
    assert {r["seed"] for r in rows} == {"0"}
    recorded = [strict_json(line) for line in (out / "samples.jsonl").read_text().splitlines()]
    assert len(recorded) == 2
    for row, rec in zip(rows, recorded, strict=True):
        assert rec["seed"] == [int(row["seed"]), int(row["index"])]
        if plant.name in KINDS:  # the rule redrawn here (the RRR's and the 5-bar's)
            parameters, _ = redrawn(plant, int(row["seed"]), int(row["index"]))
            assert json.loads(json.dumps(parameters)) == rec["parameters"]
    last = plant.joint_names[-1]
    for col in (f"hinf_rms_error_{last}", f"pd_rms_error_{last}", "error_ratio_pd",
                "torque_ratio_hinf"):
        assert col in rows[0]
    assert {r["status"] for r in rows} == {"ok"}
    data = strict_json((out / "summary.json").read_text())
    s = data["summary"]
    assert s["samples"] == s["samples_ok"] == 2
    assert [c["name"] for c in data["controllers"]] == ["fl", "hinf", "pd"]
    assert data["settings"]["engine"] == "auto" and data["settings"]["rate_hz"] == 1000.0
    assert data["nominal"]["index"] == mc.NOMINAL_INDEX and data["nominal"]["status"] == "ok"
    # a closed chain's rows hold each run's loop drift; the summary's worst is the largest
    assert ("fl_drift" in rows[0]) == bool(plant.loop_closures)
    if plant.loop_closures:
        assert s["fl_drift"]["worst"] == max(float(r["fl_drift"]) for r in rows)
        assert s["fl_drift"]["worst"] <= DRIFT_BOUND
    assert (out / "montecarlo.png").stat().st_size > 10_000
    page = (out / "report.html").read_text()
    assert "Nominal plant" in page and f"{data['nominal']['fl_rms_error']:.4g}" in page
    assert "rollouts/s" in montecarlo_run.stdout


@over_kinds
def test_cli_partial_run_resumes_to_identical_files(montecarlo_run, plant, tmp_path, capsys):
    # A killed copy of the shared run: two rows on disk (the nominal and sample 0), a torn
    # third, no tables; resumed, its tables are the shared run's, byte for byte.
    ref = montecarlo_run.out
    cut = tmp_path / "cut"
    shutil.copytree(ref, cut)
    lines = (cut / "parts.jsonl").read_text().splitlines(keepends=True)
    (cut / "parts.jsonl").write_text("".join(lines[:2]) + lines[2][:40])
    for name in ("campaign.csv", "samples.jsonl", "summary.json", "montecarlo.png",
                 "report.html"):
        (cut / name).unlink()
    argv = [*montecarlo_run.argv, "--out", str(cut)]
    assert cli.main(argv) == 2  # not without --resume
    assert "--resume" in capsys.readouterr().err
    assert cli.main([*argv, "--resume"]) == 0
    assert "resuming: 2 of 3 plants (with the nominal)" in capsys.readouterr().out
    for name in ("campaign.csv", "samples.jsonl"):
        assert (ref / name).read_bytes() == (cut / name).read_bytes(), name
    # identical but for the list of files this run wrote
    a, b = (json.loads((d / "summary.json").read_text()) for d in (ref, cut))
    assert {k: v for k, v in a.items() if k != "written"} == \
        {k: v for k, v in b.items() if k != "written"}


def test_resume_with_other_settings_is_refused(montecarlo_run, tmp_path, capsys):
    out = tmp_path / "mc"
    shutil.copytree(montecarlo_run.out, out)  # the shared run of the RRR, copied
    argv = [*montecarlo_run.argv, "--out", str(out)]
    assert cli.main(argv + ["--seed", "3", "--resume"]) == 2
    assert "seed" in capsys.readouterr().err
    # --overwrite starts afresh; a stale figure is never reported as written by this run.
    assert cli.main(argv + ["--overwrite"]) == 0


@pytest.mark.parametrize("extra, message", [
    (["--engine", "codegen"], "engine 'codegen' does not implement closed chains"),
    (["--reference", "circle", "--radius", "0.1"],
     "--reference circle needs named frames placed by forward kinematics"),
    (["--lock", "qa1=0"], "joints of a closed chain cannot be locked"),
    (["--controllers", "fl,nosuch"], "unknown controller 'nosuch'"),
    (["--baseline", "pd"], "--baseline 'pd' is not among --controllers (fl,hinf)"),
    (["--duration", "0.0505"], "--duration = 0.0505 s is not a whole number of control periods"),
    (["--confidence", "0.9"], "--confidence 0.9 applies to plants drawn from an identification"),
], ids=["codegen", "circle", "lock", "unknown", "baseline", "off-grid", "confidence"])
def test_cli_on_a_chain_refuses_what_it_cannot_run(extra, message, tmp_path, capsys):
    out = tmp_path / "x"
    argv = ["montecarlo", "--robot", "fivebar", "--samples", "2", "--duration", "0.05",
            "--jobs", "1", "--no-progress", "--out", str(out), *extra]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    # nothing written: before, an engine's refusal came after the store was opened and left
    # campaign.json and an empty parts.jsonl behind
    assert not out.exists() or list(out.iterdir()) == []


def test_cli_confidence_without_uncertainty_is_refused(tmp_path, capsys):
    # Before (issue 31): --confidence 7 without --uncertainty ran the campaign and ignored it.
    out = tmp_path / "x"
    assert cli.main(["montecarlo", "--confidence", "7", "--samples", "1", "--duration", "0.05",
                     "--no-progress", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--confidence 7 applies to plants drawn from an identification: give " \
           "--uncertainty" in err and "Traceback" not in err
    assert not out.exists() or list(out.iterdir()) == []


def test_cli_runs_a_chain_with_effects_on_the_compiled_engine_as_on_python(tmp_path):
    # A closed chain takes every plant effect and every built-in law on the compiled engine:
    # its rows equal the Python engine's (the reference path) to the engines' pinned tolerance.
    rows = {}
    for engine in ("compiled", "python"):
        out = tmp_path / engine
        argv = ["montecarlo", "--robot", "fivebar", "--samples", "2", "--duration", "0.2",
                "--controllers", "fl,hinf,pd", "--delay", "0.001", "--actuator-bandwidth",
                "1000", "--engine", engine, "--jobs", "1", "--no-progress", "--out", str(out)]
        assert cli.main(argv) == 0
        with open(out / "campaign.csv") as f:
            rows[engine] = list(csv.DictReader(f))
        assert json.loads((out / "summary.json").read_text())["settings"]["engine"] == engine
    assert [r["status"] for r in rows["compiled"]] == ["ok", "ok"]
    for a, b in zip(rows["compiled"], rows["python"], strict=True):
        for key in a:
            if key.endswith(("_rms_error", "_max_error", "_rms_torque")):
                # one RK4 in both engines: only the order of floating-point sums differs
                assert_allclose(float(a[key]), float(b[key]), rtol=1e-9, err_msg=key)


def test_cli_refuses_an_mjcf_it_cannot_perturb(tmp_path, capsys):
    argv = ["montecarlo", "--samples", "1", "--duration", "0.05", "--no-progress"]
    assert cli.main([*argv, "--robot", str(tmp_path / "none.xml"), "--out",
                     str(tmp_path / "a")]) == 2
    assert "MJCF file not found" in capsys.readouterr().err
    mine = tmp_path / "mine.xml"  # a 5-bar as an MJCF file: no parameter set to perturb
    mine.write_text(load_robot("fivebar").source_text()[0])
    assert cli.main([*argv, "--robot", str(mine), "--out", str(tmp_path / "b")]) == 2
    assert "mine: an MJCF file without a parameter set cannot be perturbed" in \
        capsys.readouterr().err


@pytest.mark.parametrize("plant, change, error, match", [
    ("rrr", {"tolerances": MechanismTolerances()}, TypeError,
     "MechanismTolerances does not perturb a serial arm"),
    ("fivebar", {"run": RunSettings(duration=0.05, rate=1000.0, limit_margin=0.1)},
     CapabilityError, "limit_margin = 0.1 rad needs position limits on its actuated joints"),
    ("fivebar", {"baseline": "pd"}, ValueError, "baseline 'pd' is not among"),
], indirect=["plant"], ids=["arm-mechanism-tolerances", "chain-limit-margin", "baseline"])
def test_api_refuses_settings_the_plant_cannot_take(plant, laws, change, error, match):
    # Refused before any run (the uncertainty set by drawing sample 0 up front).
    with pytest.raises(error, match=match):
        mc.run_campaign(plant, laws, settings_of(plant, **change), jobs=1)


def test_a_chain_takes_the_arms_tolerances_and_any_mechanism_set(fivebar):
    # One uncertainty set for every kind (Tolerances: masses and lengths of a mechanism), and
    # the mechanism's own set too; a study records either.
    a, pa = fivebar.perturbed(np.random.default_rng([0, 1]), Tolerances())
    b, pb = fivebar.perturbed(np.random.default_rng([0, 1]), MechanismTolerances())
    assert pa == pb and a.params == b.params  # the same draw: the same tolerances
    assert StudyConfig(tolerances=MechanismTolerances()).to_dict()["uncertainty"] == \
        "MechanismTolerances"


@pytest.mark.parametrize("kwargs,message", [
    ({"samples": 0}, "samples must be an integer >= 1"),
    ({"samples": 2, "seed": -1}, "seed must be an integer >= 0"),
], ids=["samples", "seed"])
def test_bad_settings(kwargs, message):
    with pytest.raises(ValueError, match=message):
        mc.CampaignSettings(**kwargs)


def test_bad_jobs(rrr):
    with pytest.raises(ValueError, match="jobs must be an integer >= 1"):
        mc.run_campaign(rrr, make_laws("fl", rrr), settings_of(rrr), jobs=0)


def _mc(out, *extra):
    import sys

    return [sys.executable, "-m", "rrr_pin.cli", "montecarlo", "--samples", "12",
            "--duration", "0.5", "--jobs", "2", "--engine", "python", "--controllers",
            "fl,hinf", "--out", str(out), "--no-progress", *extra]


def test_interrupted_campaign_resumes_to_identical_tables(tmp_path, capsys):
    # A real interruption: start the CLI as a subprocess, send SIGINT once some samples are on
    # disk, then --resume; the final tables must equal those of an uninterrupted run. Only the
    # interrupted run needs a process of its own: the others run in this one (the same
    # command).
    import signal
    import subprocess
    import time

    ref = tmp_path / "ref"  # one process: the tables are the same whatever the workers
    assert cli.main([*_mc(ref)[3:], "--jobs", "1"]) == 0
    out = tmp_path / "cut"
    proc = subprocess.Popen(_mc(out), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    parts = out / "parts.jsonl"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if parts.exists() and len(parts.read_text().splitlines()) >= 2:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    if proc.returncode == 0:
        pytest.skip("the campaign finished before the interrupt arrived")
    assert proc.returncode == 130, err
    assert "samples done" in err and "--resume" in err and "Traceback" not in err
    kept = len(parts.read_text().splitlines())
    assert 2 <= kept < 13  # the 12 samples and the nominal plant (row -1)
    assert not (out / "campaign.csv").exists()
    # Without --resume the folder is refused; with it, only the missing samples run.
    capsys.readouterr()
    assert cli.main(_mc(out)[3:]) == 2
    assert "--resume" in capsys.readouterr().err
    assert cli.main(_mc(out, "--resume")[3:]) == 0
    assert f"{kept} of 13 plants (with the nominal) already done" in capsys.readouterr().out
    for name in ("campaign.csv", "samples.jsonl", "summary.json"):
        a, b = (ref / name).read_bytes(), (out / name).read_bytes()
        if name == "summary.json":  # identical but for the list of files this run wrote
            a, b = (json.loads(x) for x in (a, b))
        assert a == b, name


def test_campaign_settings_defaults_and_shared_record():
    from rrr_pin.campaign.settings import Settings

    s = mc.CampaignSettings(samples=3)
    assert isinstance(s, Settings)
    assert (s.run.duration, s.run.rate, s.seed, s.baseline) == (10.0, 1000.0, 0, "fl")
    with pytest.raises(TypeError, match="samples"):
        mc.CampaignSettings()  # no default count of plants
    with pytest.raises(TypeError, match="run must be a RunSettings, got dict"):
        mc.CampaignSettings(samples=2, run={"duration": 1.0})


# --- degenerate metrics (issue 24) ------------------------------------------------------------

@pytest.mark.parametrize("num, den, expected", [
    (2.0, 4.0, 0.5), (3.0, 0.0, np.inf), (0.0, 2.0, 0.0),
    (0.0, 0.0, None), (np.nan, 1.0, None), (1.0, np.inf, None), (-1.0, 1.0, None),
], ids=["plain", "x/0", "0/x", "0/0", "nan", "inf", "negative"])
def test_ratio_is_undefined_for_0_over_0_and_non_finite_figures(num, den, expected):
    from rrr_pin.campaign.runner import ratio

    assert ratio(num, den) == expected


def test_a_zero_error_of_both_laws_gives_no_ratio_but_a_stated_reason(tmp_path):
    # A reference at rest without gravity: both laws hold it exactly, RMS errors and torques are
    # 0 (exactly: the state never leaves q0 = r, tau = 0), so baseline / law is 0/0. It was
    # recorded as inf ("infinitely better") and counted in the summary.
    from rrr_pin.control.references import SineReference
    from rrr_pin.report.campaign import summary_lines, write_campaign

    robot = load_robot("rrr", gravity=0.0)
    ref = SineReference(home=np.zeros(3), amp=np.zeros(3), freq=np.zeros(3), phase=np.zeros(3))
    laws = make_laws("fl,pd", robot)
    settings = mc.CampaignSettings(samples=2, seed=0, baseline="fl",
                                   run=RunSettings(duration=0.02, rate=1000.0))
    campaign = mc.run_campaign(robot, laws, settings, reference=ref, jobs=1)
    for row in campaign.rows:
        assert row["status"] == "ok" and row["fl_rms_error"] == 0.0 == row["pd_rms_error"]
        assert "error_ratio_pd" not in row and "torque_ratio_pd" not in row
        assert row["undefined"] == (
            "error_ratio_pd undefined: RMS error of pd (0.0) and of the baseline fl (0.0) give "
            "no ratio; torque_ratio_pd undefined: RMS torque of pd (0.0) and of the baseline fl "
            "(0.0) give no ratio")
    s = write_campaign(campaign, tmp_path)
    assert s["undefined"] == {"error_ratio_pd": 2, "torque_ratio_pd": 2}
    assert "error_ratio_pd" not in s and s["fraction_better"] == {}
    with open(tmp_path / "campaign.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["error_ratio_pd"] for r in rows] == ["", ""]
    assert all(r["undefined"].startswith("error_ratio_pd undefined") for r in rows)
    assert ("error_ratio_pd undefined (no ratio: 0/0 or not finite) on 2 plants, left out; see "
            "the column 'undefined' of campaign.csv") in summary_lines(campaign, s)


def test_a_law_returning_nan_mid_run_gives_a_stated_status(rrr):
    # The campaign goes on; the status says which law returned what, and when.
    from rrr_pin.control.laws import ControlLaw, pd_controller

    robot = rrr
    pd = pd_controller(robot)

    @dataclass(frozen=True)
    class NanLater(ControlLaw):
        name: str = "nanlater"
        n: int = 3

        def torque(self, t, q, qd, r, rd, rdd, x):
            tau = pd.torque(t, q, qd, r, rd, rdd, x)
            return tau if t < 0.01 - 1e-12 else tau * np.nan

    settings = mc.CampaignSettings(samples=2, seed=0, baseline="pd",
                                   run=RunSettings(duration=0.02, rate=1000.0))
    campaign = mc.run_campaign(robot, [pd, NanLater()], settings, jobs=1)
    for row in campaign.rows:
        assert row["status"] == (
            f"diverged: nanlater: simulation of plant 'sample{row['index']:05d}' stopped at "
            f"t = 0.01 s: law 'nanlater' returned a non-finite torque (NaN or inf) for joint "
            f"'joint1' in the step from t = 0.01 s")
        assert "nanlater_rms_error" not in row and "error_ratio_nanlater" not in row
    assert mc.campaign_summary(campaign)["samples_diverged"] == 2


@pytest.mark.parametrize(("n", "size", "tail", "unit"), [(1001, 32, 4, 16), (301, 32, 4, 16),
                                                        (5, 32, 4, 16), (1001, 126, 1, 128)])
def test_chunks_cover_every_sample_once_and_shrink_at_the_end(n, size, tail, unit):
    # Hand-counted for 1001 samples of chunks of 32, 2 workers (tail 4), batches of 16: 29
    # chunks of 32 leave 73, then ceil(73 / 4) = 19 -> 32, 41 -> 11 -> 16, 25 -> 16, 9.
    blocks = list(mc._blocks(iter(range(n)), n, size, tail, unit))
    assert [k for b in blocks for k in b] == list(range(n))
    assert all(len(b) <= size for b in blocks)
    if (n, size, tail) == (1001, 32, 4):
        assert [len(b) for b in blocks[-4:]] == [32, 16, 16, 9] and len(blocks) == 33
    if tail == 1:  # an explicit chunk: all of it but the last
        assert {len(b) for b in blocks[:-1]} == {size}


def test_default_chunks_are_whole_batches():
    # 1001 samples on 2 workers: ceil(1001 / 16) = 63 -> 64 (4 batches of 16, not 16 16 16 15);
    # on 1 worker the 64 cap; a campaign too small for one batch per chunk keeps small chunks.
    assert mc._chunk_size(1001, 2, 64, 1, 16) == 64
    assert mc._chunk_size(1001, 1, 64, 1, 16) == 64
    assert mc._chunk_size(401, 2, 64, 1, 16) == 32  # ceil(401 / 16) = 26 -> 32
    assert mc._chunk_size(21, 2, 64, 1, 16) == 2
    assert mc._chunk_size(1001, 1, 128, 128, 16) == 128  # threads=2: four batches per thread

import csv
import json

import numpy as np
import pytest

import rrr_pin.campaign.montecarlo as mc
from rrr_pin import cli
from rrr_pin.campaign.runner import RunSettings, make_laws
from rrr_pin.campaign.study import StudyConfig, run_study
from rrr_pin.model.dynamics import load_robot
from rrr_pin.sim.trajectory import SimulationDiverged

RUN = RunSettings(duration=0.3, rate=1000.0, engine="python")
SETTINGS = mc.CampaignSettings(samples=4, run=RUN)


@pytest.fixture(scope="module")
def setup():
    robot = load_robot("rrr")
    return robot, make_laws("fl,hinf", robot)


@pytest.fixture(scope="module")
def serial(setup):
    robot, laws = setup
    return mc.run_campaign(robot, laws, SETTINGS, jobs=1)


def test_identical_whatever_the_jobs(setup, serial):
    robot, laws = setup
    parallel = mc.run_campaign(robot, laws, SETTINGS, jobs=2, chunk=1)
    assert parallel.rows == serial.rows


def test_dask_cluster_gives_the_same_rows(setup, serial):
    distributed = pytest.importorskip("distributed")
    robot, laws = setup
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        remote = mc.run_campaign(robot, laws, SETTINGS, scheduler=cluster.scheduler_address,
                                 chunk=1)
    assert remote.rows == serial.rows


def test_rows_agree_with_the_study(setup, serial):
    # The campaign's sample k is the study's sample k: same plant, same figures.
    robot, laws = setup
    study = run_study(robot, laws, config=StudyConfig(run=RUN, samples=2, jobs=1))
    for sample, row in zip(study.samples, serial.rows, strict=False):
        assert sample["seed"] == row["seed"]
        e = sample["trajectories"]["fl"].error.ravel()
        np.testing.assert_allclose(row["fl_rms_error"], np.sqrt(np.mean(e**2)), rtol=1e-12)


def test_diverged_sample_is_recorded_and_campaign_goes_on(setup, monkeypatch):
    robot, laws = setup
    import rrr_pin.campaign.runner as runner

    real = runner.simulate_batch

    def flaky(plants, law, *args, **kwargs):
        out = real(plants, law, *args, **kwargs)
        return [SimulationDiverged("diverged at t = 0.1 s: joint 'joint2' blew up", 0.1,
                                   "joint2")
                if plant.name == "sample00001" and law.name == "hinf" else r
                for plant, r in zip(plants, out, strict=True)]

    monkeypatch.setattr(runner, "simulate_batch", flaky)
    campaign = mc.run_campaign(robot, laws, SETTINGS, jobs=1)
    assert [r["status"] == "ok" for r in campaign.rows] == [True, False, True, True]
    assert "hinf: " in campaign.rows[1]["status"] and "joint2" in campaign.rows[1]["status"]
    assert "params" in campaign.rows[1]["parameters"]
    assert "fl_rms_error" in campaign.rows[1]  # the law that ran keeps its figures
    assert "error_ratio_hinf" not in campaign.rows[1]
    summary = mc.campaign_summary(campaign)
    assert summary["samples_diverged"] == 1 and summary["diverged"] == [1]
    assert summary["samples_ok"] == 3
    assert summary["error_ratio_hinf"]["count"] == 3


def test_summary_statistics(serial):
    s = mc.campaign_summary(serial)
    ratios = [r["fl_rms_error"] / r["hinf_rms_error"] for r in serial.rows]
    np.testing.assert_allclose(s["error_ratio_hinf"]["median"], np.median(ratios), rtol=1e-12)
    assert s["error_ratio_hinf"]["worst"] == min(ratios)
    assert s["fraction_better"]["hinf"] == np.mean([x > 1 for x in ratios])


def test_cli_three_controllers(tmp_path, capsys, strict_json):
    out = tmp_path / "mc"
    code = cli.main(["montecarlo", "--samples", "3", "--duration", "0.2", "--jobs", "1",
                     "--controllers", "fl,hinf,pd", "--engine", "python", "--out", str(out),
                     "--no-progress"])
    assert code == 0
    with open(out / "campaign.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["index"] for r in rows] == ["0", "1", "2"]
    # seed and index are integers, and they name the plant: default_rng([seed, index])
    from rrr_pin.model.dh import paper_params
    from rrr_pin.model.uncertainty import sample_plant

    assert {r["seed"] for r in rows} == {"0"}
    recorded = [strict_json(line) for line in (out / "samples.jsonl").read_text().splitlines()]
    for row, rec in zip(rows, recorded, strict=True):
        assert rec["seed"] == [int(row["seed"]), int(row["index"])]
        redrawn = sample_plant(paper_params(), int(row["seed"]), int(row["index"]))
        assert json.loads(json.dumps(redrawn.parameters)) == rec["parameters"]
    for col in ("hinf_rms_error_joint3", "pd_rms_error_joint3", "error_ratio_pd",
                "torque_ratio_hinf"):
        assert col in rows[0]
    data = strict_json((out / "summary.json").read_text())
    assert data["summary"]["samples"] == 3
    assert [c["name"] for c in data["controllers"]] == ["fl", "hinf", "pd"]
    assert data["settings"]["engine"] == "python" and data["settings"]["rate_hz"] == 1000.0
    assert (out / "montecarlo.png").stat().st_size > 10_000
    assert len((out / "samples.jsonl").read_text().splitlines()) == 3
    assert "rollouts/s" in capsys.readouterr().out


@pytest.mark.parametrize("kwargs,message", [
    ({"samples": 0}, "samples must be an integer >= 1"),
    ({"samples": 2, "seed": -1}, "seed must be an integer >= 0"),
], ids=["samples", "seed"])
def test_bad_settings(kwargs, message):
    with pytest.raises(ValueError, match=message):
        mc.CampaignSettings(**kwargs)


def test_bad_jobs(setup):
    with pytest.raises(ValueError, match="jobs must be an integer >= 1"):
        mc.run_campaign(*setup, SETTINGS, jobs=0)


def _mc(out, *extra):
    import sys

    return [sys.executable, "-m", "rrr_pin.cli", "montecarlo", "--samples", "12",
            "--duration", "0.5", "--jobs", "2", "--engine", "python", "--controllers",
            "fl,hinf", "--out", str(out), "--no-progress", *extra]


def test_interrupted_campaign_resumes_to_identical_tables(tmp_path):
    # A real interruption: start the CLI as a subprocess, send SIGINT once some samples are on
    # disk, then --resume; the final tables must equal those of an uninterrupted run.
    import signal
    import subprocess
    import time

    ref = tmp_path / "ref"
    subprocess.run(_mc(ref), check=True, capture_output=True, timeout=300)
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
    refused = subprocess.run(_mc(out), capture_output=True, text=True, timeout=60)
    assert refused.returncode == 2 and "--resume" in refused.stderr
    done = subprocess.run(_mc(out, "--resume"), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert f"{kept} of 13 plants (with the nominal) already done" in done.stdout
    for name in ("campaign.csv", "samples.jsonl", "summary.json"):
        a, b = (ref / name).read_bytes(), (out / name).read_bytes()
        if name == "summary.json":  # identical but for the list of files this run wrote
            a, b = (json.loads(x) for x in (a, b))
        assert a == b, name


def test_resume_with_other_settings_is_refused(tmp_path, capsys):
    out = tmp_path / "mc"
    argv = ["montecarlo", "--samples", "2", "--duration", "0.1", "--jobs", "1", "--out",
            str(out), "--no-progress"]
    assert cli.main(argv) == 0
    assert cli.main(argv[:-1] + ["--seed", "3", "--resume", "--no-progress"]) == 2
    assert "seed" in capsys.readouterr().err
    # --overwrite starts afresh; a stale figure is never reported as written by this run.
    assert cli.main(argv + ["--overwrite"]) == 0


def test_certificate_column_matches_the_study(setup):
    # The campaign's sample k is the study's sample k: the same plant gets the same certificate.
    from rrr_pin.robust.certificates import CertificateSpec
    from rrr_pin.robust.loopshaping import design

    robot, laws = setup
    spec = CertificateSpec.from_design(design(n=3), points=3)
    settings = mc.CampaignSettings(samples=2, run=RUN)
    campaign = mc.run_campaign(robot, laws, settings, jobs=1, certificate=spec)
    study = run_study(robot, laws, config=StudyConfig(run=RUN, samples=2, jobs=1),
                      certificate=spec)
    b = spec.margin(3)
    for row, sample in zip(campaign.rows, study.samples, strict=True):
        assert row["certified"] == (row["nugap_max"] < b)
        np.testing.assert_allclose(row["nugap_max"], sample["certificate"]["nugap_max"],
                                   rtol=1e-12)
    assert "certified" in mc.campaign_columns(["fl", "hinf"], "fl", ["j"], certified=True)
    s = mc.campaign_summary(campaign)
    assert s["certified"] == sum(r["certified"] for r in campaign.rows)


def test_campaign_settings_defaults_and_shared_record():
    from rrr_pin.campaign.settings import Settings

    s = mc.CampaignSettings(samples=3)
    assert isinstance(s, Settings)
    assert (s.run.duration, s.run.rate, s.seed, s.baseline) == (10.0, 1000.0, 0, "fl")
    with pytest.raises(TypeError, match="samples"):
        mc.CampaignSettings()  # no default count of plants
    with pytest.raises(TypeError, match="run must be a RunSettings, got dict"):
        mc.CampaignSettings(samples=2, run={"duration": 1.0})


def test_chunk_tasks_are_frozen_picklable_and_give_the_rows(setup, serial):
    # What crosses the process boundary is a frozen CampaignChunk of a frozen CampaignJob;
    # run in this process after a pickle round trip, it gives the campaign's rows.
    import dataclasses
    import pickle

    from rrr_pin.control.references import default_reference
    from rrr_pin.model.dh import paper_params

    robot, laws = setup
    assert robot.params == paper_params()
    job = mc.CampaignJob(settings=SETTINGS, laws=tuple(laws), reference=default_reference(robot),
                         nominal=robot)
    task = pickle.loads(pickle.dumps(mc.CampaignChunk(job, (1, 2))))
    assert mc.run_chunk(task) == serial.rows[1:3]
    with pytest.raises(dataclasses.FrozenInstanceError):
        task.indices = (0,)


def test_rrr_campaign_perturbs_the_papers_parameters(setup, serial):
    # The "rrr means paper_params()" rule (rrr_pin.model.robots.nominal_params): sample k of
    # seed s is sample_plant(paper_params(), s, k), drawn here independently of the campaign.
    from rrr_pin.model.dh import paper_params
    from rrr_pin.model.uncertainty import sample_plant

    robot, _ = setup
    assert robot.params == paper_params()
    for k in (0, 1):
        expected = sample_plant(paper_params(), serial.settings["seed"], k)
        assert serial.rows[k]["parameters"] == expected.parameters


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


def test_a_law_returning_nan_mid_run_gives_a_stated_status(setup):
    # The campaign goes on; the status says which law returned what, and when.
    from dataclasses import dataclass

    from rrr_pin.control.laws import ControlLaw, pd_controller

    robot, _ = setup
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

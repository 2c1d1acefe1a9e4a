import csv
import json

import numpy as np
import pytest

import rrr_pin.montecarlo as mc
from rrr_pin import cli
from rrr_pin.dynamics import load_robot
from rrr_pin.loopshaping import design
from rrr_pin.simulate import SimulationDiverged
from rrr_pin.study import StudyConfig, run_study

SMALL = {"samples": 4, "duration": 0.3, "engine": "python"}


@pytest.fixture(scope="module")
def setup():
    return load_robot("rrr"), design().K_reduced


@pytest.fixture(scope="module")
def serial(setup):
    robot, K = setup
    return mc.run_campaign(robot, K, jobs=1, **SMALL)


def test_identical_whatever_the_jobs(setup, serial):
    robot, K = setup
    parallel = mc.run_campaign(robot, K, jobs=2, chunk=1, **SMALL)
    assert parallel.rows == serial.rows


def test_dask_cluster_gives_the_same_rows(setup, serial):
    distributed = pytest.importorskip("distributed")
    robot, K = setup
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        remote = mc.run_campaign(robot, K, scheduler=cluster.scheduler_address, chunk=1,
                                 **SMALL)
    assert remote.rows == serial.rows


def test_rows_agree_with_the_study(setup, serial):
    # The campaign's sample k is the study's sample k: same plant, same figures.
    robot, K = setup
    study = run_study(robot, K, config=StudyConfig(duration=0.3, samples=2, jobs=1,
                                                   rate=1000.0))
    for sample, row in zip(study.samples, serial.rows, strict=False):
        assert sample["seed"] == row["seed"]
        e = np.concatenate([sample["trajectories"]["fl"].error.ravel()])
        np.testing.assert_allclose(row["fl_rms_error"], np.sqrt(np.mean(e**2)), rtol=1e-12)


def test_diverged_sample_is_recorded_and_campaign_goes_on(setup, monkeypatch):
    robot, K = setup
    import rrr_pin.study as study

    real = study.simulate

    def flaky(plant, *args, **kwargs):
        if plant.name == "sample00001":
            raise SimulationDiverged("diverged at t = 0.1 s: joint 'joint2' blew up", 0.1,
                                     "joint2")
        return real(plant, *args, **kwargs)

    monkeypatch.setattr(study, "simulate", flaky)
    campaign = mc.run_campaign(robot, K, jobs=1, **SMALL)
    assert [r["status"] == "ok" for r in campaign.rows] == [True, False, True, True]
    assert "joint2" in campaign.rows[1]["status"]
    assert "params" in campaign.rows[1]["parameters"]
    summary = mc.campaign_summary(campaign)
    assert summary["samples_diverged"] == 1 and summary["diverged"] == [1]
    assert summary["samples_ok"] == 3


def test_summary_statistics(serial):
    s = mc.campaign_summary(serial)
    ratios = [r["fl_rms_error"] / r["hinf_rms_error"] for r in serial.rows]
    np.testing.assert_allclose(s["error_ratio"]["median"], np.median(ratios), rtol=1e-12)
    assert s["error_ratio"]["worst"] == min(ratios)
    assert s["fraction_hinf_better"] == np.mean([x > 1 for x in ratios])


def test_cli_writes_table_summary_and_figure(tmp_path, capsys):
    out = tmp_path / "mc"
    code = cli.main(["montecarlo", "--samples", "3", "--duration", "0.2", "--jobs", "1",
                     "--engine", "python", "--out", str(out), "--no-progress"])
    assert code == 0
    with open(out / "campaign.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["index"] for r in rows] == ["0", "1", "2"]
    assert "hinf_rms_error_joint3" in rows[0]
    summary = json.loads((out / "summary.json").read_text())["summary"]
    assert summary["samples"] == 3
    assert (out / "montecarlo.png").stat().st_size > 10_000
    assert len((out / "samples.jsonl").read_text().splitlines()) == 3
    assert "rollouts/s" in capsys.readouterr().out


def test_bad_sample_count(setup):
    with pytest.raises(ValueError, match="samples must be a positive integer"):
        mc.run_campaign(*setup, samples=0)

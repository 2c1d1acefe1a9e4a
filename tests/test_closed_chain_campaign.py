"""Monte Carlo campaigns on parallel mechanisms (campaign/closed_chain_campaign.py).

Short runs (50 ms at 1 kHz: a fast circle, but every number below is compared with an
independent computation of the same run, not with a stored value).
"""

from __future__ import annotations

import csv
import json
import shutil
from dataclasses import asdict, dataclass, replace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin import cli
from rrr_pin.campaign.closed_chain_campaign import (
    NOMINAL_INDEX,
    chain_laws,
    open_chain_store,
    run_chain_campaign,
)
from rrr_pin.campaign.closed_chain_study import ChainStudyConfig, chain_reference, run_chain_study
from rrr_pin.campaign.montecarlo import CampaignSettings, run_campaign
from rrr_pin.campaign.runner import RunSettings, make_laws
from rrr_pin.campaign.store import StoreError
from rrr_pin.campaign.study import StudyConfig
from rrr_pin.control.effects import PlantEffects
from rrr_pin.model.closed_chain import load_closed_chain
from rrr_pin.model.dynamics import load_robot
from rrr_pin.model.mechanisms import FiveBarParams, perturb_mechanism
from rrr_pin.model.uncertainty import (
    MechanismTolerances,
    MechanismUncertainty,
    Tolerances,
    sample_mechanism,
)
from rrr_pin.sim.closed_chain import ConstraintDrift, simulate_closed_chain

DURATION = 0.05
RUN = RunSettings(duration=DURATION, rate=1000.0)
SETTINGS = CampaignSettings(samples=2, seed=7, run=RUN, tolerances=MechanismTolerances())


@pytest.fixture(scope="module")
def fivebar():
    chain = load_closed_chain("fivebar")
    return chain, chain_laws("fl,hinf", chain)


@pytest.fixture(scope="module")
def serial(fivebar):
    chain, laws = fivebar
    return run_chain_campaign(chain, laws, SETTINGS, jobs=1)


def test_identical_in_process_and_in_worker_processes(fivebar, serial):
    # Worker processes rebuild the laws' models and the plants from their MJCF text
    # (ClosedChain pickles by its text): the rows must be the same numbers, bit for bit.
    chain, laws = fivebar
    parallel = run_chain_campaign(chain, laws, SETTINGS, jobs=2)
    assert parallel.rows == serial.rows
    assert parallel.nominal == serial.nominal
    assert [r["index"] for r in serial.rows] == [0, 1]
    assert all(r["status"] == "ok" and r["fl_status"] == r["hinf_status"] == "ok"
               for r in serial.rows)


def test_sample_k_is_perturb_mechanism_with_the_seed_rule(fivebar, serial):
    # The documented rule, recomputed here: plant k = perturb_mechanism(nominal,
    # default_rng([seed, k]), 20 %, 5 %); then its fl run redone alone with a fresh law.
    chain, _ = fivebar
    for row in serial.rows:
        k = row["index"]
        params, factors = perturb_mechanism(FiveBarParams(),
                                            np.random.default_rng([SETTINGS.seed, k]), 0.2, 0.05)
        assert row["seed"] == [SETTINGS.seed, k]
        assert row["parameters"] == {"params": asdict(params), "factors": factors}
    params, _ = perturb_mechanism(FiveBarParams(), np.random.default_rng([SETTINGS.seed, 1]),
                                  0.2, 0.05)
    law = chain_laws("fl", chain)[0]
    traj = simulate_closed_chain(load_closed_chain(params), law,
                                 chain_reference(chain, DURATION), DURATION, rate=1000.0)
    e = traj.q - traj.r
    row = serial.rows[1]
    # Same run, same operations: equal to the last bits (1e-15 allows a different summation).
    assert_allclose(row["fl_rms_error"], np.sqrt(np.mean(e * e)), rtol=1e-15)
    assert_allclose(row["fl_max_error"], np.max(np.abs(e)), rtol=1e-15)
    assert_allclose(row["fl_rms_torque"], np.sqrt(np.mean(traj.tau ** 2)), rtol=1e-15)
    assert row["fl_drift"] == traj.info["drift_m"] <= traj.info["drift_bound_m"]
    assert_allclose(row["error_ratio_hinf"], row["fl_rms_error"] / row["hinf_rms_error"],
                    rtol=1e-15)


def test_nominal_row_is_the_studys_nominal_run(serial):
    study = run_chain_study(ChainStudyConfig(mechanism="fivebar", samples=0,
                                             duration=DURATION, rate=1000.0))
    nominal = study.metrics[0]
    assert serial.nominal["index"] == NOMINAL_INDEX and serial.nominal["seed"] is None
    for law in ("fl", "hinf"):
        # The same simulation (plant, law model reset to home, reference, step): equal numbers.
        assert serial.nominal[f"{law}_rms_error"] == nominal[law]["rms_error_rad"]
        assert serial.nominal[f"{law}_max_error"] == nominal[law]["max_error_rad"]
        assert serial.nominal[f"{law}_rms_torque"] == nominal[law]["rms_tau_Nm"]
        assert serial.nominal[f"{law}_drift"] == nominal[law]["drift_m"]


def test_every_built_in_law_runs_and_pd_nominal_is_the_studys():
    # chain_laws builds the laws with the study's factory (make_chain_law): PD's nominal row is
    # the study's PD run, number for number.
    chain = load_closed_chain("fivebar")
    laws = chain_laws("fl,pd,hinf2dof", chain)
    assert [law.name for law in laws] == ["fl", "pd", "hinf2dof"]
    campaign = run_chain_campaign(chain, laws, replace(SETTINGS, samples=1), jobs=1)
    study = run_chain_study(ChainStudyConfig(mechanism="fivebar", samples=0, duration=DURATION,
                                             rate=1000.0, controllers=("fl", "pd", "hinf2dof"),
                                             certify=False))
    for law in ("pd", "hinf2dof"):
        assert campaign.nominal[f"{law}_rms_error"] == study.metrics[0][law]["rms_error_rad"]
        assert campaign.nominal[f"{law}_rms_torque"] == study.metrics[0][law]["rms_tau_Nm"]


def test_a_failed_run_is_recorded_and_the_campaign_goes_on(fivebar, serial, monkeypatch):
    import rrr_pin.campaign.closed_chain_campaign as ccc

    chain, laws = fivebar
    real = ccc.simulate_closed_chain

    def hinf_drifts_on_sample_1(plant, law, *args, **kwargs):
        if law.name == "hinf" and plant.params.d != chain.params.d and plant.params.d == \
                sample_mechanism(chain.params, SETTINGS.seed, 1)[0].d:
            raise ConstraintDrift("loop gap 1e-3 m at t = 0.01 s (bound 1e-06 m)")
        return real(plant, law, *args, **kwargs)

    monkeypatch.setattr(ccc, "simulate_closed_chain", hinf_drifts_on_sample_1)
    job = ccc.ChainCampaignJob(settings=SETTINGS, laws=tuple(laws),
                               reference=chain_reference(chain, DURATION), params=chain.params,
                               gravity=chain.gravity, joint_names=tuple(chain.joint_names))
    ok, bad = job.rows([0, 1])  # what a worker computes for a chunk of two samples
    assert ok == serial.rows[0]
    assert bad["status"] == "failed: hinf: ConstraintDrift: loop gap 1e-3 m at t = 0.01 s " \
                            "(bound 1e-06 m)"
    assert bad["hinf_status"].startswith("failed: ConstraintDrift") and "hinf_rms_error" not in bad
    assert bad["fl_rms_error"] == serial.rows[1]["fl_rms_error"]  # the other law's run stays
    assert "error_ratio_hinf" not in bad


def test_a_user_uncertainty_set_is_an_input():
    @dataclass(frozen=True)
    class MassesOnly(MechanismUncertainty):
        inertia: float = 0.1

        def draw(self, params, rng):
            f = rng.uniform(1 - self.inertia, 1 + self.inertia, size=2)
            return replace(params, m1=params.m1 * f[0], m2=params.m2 * f[1]), {"f": f.tolist()}

        def to_dict(self):
            return {"inertia": self.inertia}

    params, drawn = sample_mechanism(FiveBarParams(), 3, 5, MassesOnly())
    f = np.random.default_rng([3, 5]).uniform(0.9, 1.1, size=2)  # the seed rule, recomputed
    assert drawn == {"f": f.tolist()}
    assert (params.m1, params.m2) == (0.5 * f[0], 0.3 * f[1])
    assert (params.d, params.l1, params.l2) == (0.12, 0.23, 0.23)
    record = CampaignSettings(samples=1, tolerances=MassesOnly()).to_dict()
    assert record["uncertainty"] == "MassesOnly" and record["inertia"] == 0.1


def test_partial_store_resumes_to_identical_rows(fivebar, serial, tmp_path):
    # A killed run: the nominal and sample 0 on disk and a torn third line; the resumed store
    # holds the same file, byte for byte, and the campaign the same rows (one worker: rows are
    # appended in index order).
    chain, laws = fivebar
    reference = chain_reference(chain, DURATION)
    ref = tmp_path / "ref"
    with open_chain_store(ref, chain, laws, SETTINGS, reference) as store:
        run_chain_campaign(chain, laws, SETTINGS, jobs=1, store=store)
    cut = tmp_path / "cut"
    shutil.copytree(ref, cut)
    lines = (cut / "parts.jsonl").read_text().splitlines(keepends=True)
    assert len(lines) == 3
    (cut / "parts.jsonl").write_text("".join(lines[:2]) + lines[2][:40])
    with pytest.raises(StoreError, match="resume"):
        open_chain_store(cut, chain, laws, SETTINGS, reference)
    with open_chain_store(cut, chain, laws, SETTINGS, reference, resume=True) as store:
        assert store.done() == {NOMINAL_INDEX, 0}
        resumed = run_chain_campaign(chain, laws, SETTINGS, jobs=1, store=store)
    assert (cut / "parts.jsonl").read_bytes() == (ref / "parts.jsonl").read_bytes()
    assert resumed.rows == serial.rows and resumed.nominal == serial.nominal
    other = replace(SETTINGS, seed=8)  # a resume with other settings is refused
    with pytest.raises(StoreError, match="seed"):
        open_chain_store(cut, chain, laws, other, reference, resume=True)


def _mc(out, *extra):
    return ["montecarlo", "--robot", "fivebar", "--samples", "2", "--duration", str(DURATION),
            "--jobs", "1", "--out", str(out), "--no-progress", *extra]


def test_cli_writes_the_campaign_files(tmp_path, capsys):
    out = tmp_path / "fb"
    assert cli.main(_mc(out)) == 0
    text = capsys.readouterr().out
    assert "nominal plant: fl RMS error" in text and "montecarlo.png" in text
    summary = json.loads((out / "summary.json").read_text())
    assert summary["nominal"]["index"] == NOMINAL_INDEX
    assert summary["settings"]["uncertainty"] == "MechanismTolerances"
    s = summary["summary"]
    assert s["samples"] == s["samples_ok"] == 2
    # The summary's worst drift is the largest of the rows' (recomputed from the CSV).
    with open(out / "campaign.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["index"]) for r in rows] == [0, 1]
    assert s["fl_drift"]["worst"] == max(float(r["fl_drift"]) for r in rows)
    assert {r["fl_status"] for r in rows} == {r["hinf_status"] for r in rows} == {"ok"}
    assert (out / "montecarlo.png").is_file()
    page = (out / "report.html").read_text()
    assert "Nominal plant" in page and f"{summary['nominal']['fl_rms_error']:.4g}" in page


@pytest.mark.slow
def test_cli_partial_run_resumes_to_identical_files(tmp_path, capsys):
    ref = tmp_path / "ref"
    assert cli.main(_mc(ref)) == 0
    capsys.readouterr()
    # A killed run: two rows on disk (the nominal and sample 0), a torn third, no tables.
    cut = tmp_path / "cut"
    shutil.copytree(ref, cut)
    lines = (cut / "parts.jsonl").read_text().splitlines(keepends=True)
    (cut / "parts.jsonl").write_text("".join(lines[:2]) + lines[2][:40])
    for name in ("campaign.csv", "samples.jsonl", "summary.json", "montecarlo.png",
                 "report.html"):
        (cut / name).unlink()
    assert cli.main(_mc(cut)) == 2  # not without --resume
    assert "--resume" in capsys.readouterr().err
    assert cli.main(_mc(cut, "--resume")) == 0
    assert "resuming: 2 of 3 plants (with the nominal)" in capsys.readouterr().out
    for name in ("campaign.csv", "samples.jsonl", "summary.json"):
        assert (ref / name).read_bytes() == (cut / name).read_bytes(), name


@pytest.mark.slow
def test_dask_cluster_gives_the_same_rows(fivebar, serial):
    distributed = pytest.importorskip("distributed")
    chain, laws = fivebar
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        remote = run_chain_campaign(chain, laws, SETTINGS, scheduler=cluster.scheduler_address)
    assert remote.rows == serial.rows and remote.nominal == serial.nominal


@pytest.mark.parametrize(("extra", "message"), [
    (["--certify"], "does not implement --certify"),
    (["--delay", "0.001", "--engine", "compiled"], "with --engine compiled"),
    (["--engine", "codegen"], "does not implement --engine codegen"),
    (["--reference", "circle"], "does not implement --reference other than sine"),
    (["--radius", "0.1"], "does not implement --radius"),
    (["--lock", "qa1=0"], "does not implement --lock"),
    (["--q0", "0,0"], "does not implement --q0"),
    (["--uncertainty", "identification.json"], "does not implement --uncertainty"),
    (["--controllers", "fl,nosuch"], "'nosuch': not implemented on closed chains"),
    (["--baseline", "pd"], "--baseline 'pd' is not among --controllers"),
    (["--duration", "0.0505"], "duration"),
], ids=["certify", "delay", "compiled", "reference", "radius", "lock", "q0", "uncertainty",
        "unknown", "baseline", "off-grid"])
def test_cli_refuses_what_closed_chains_do_not_implement(tmp_path, capsys, extra, message):
    assert cli.main(_mc(tmp_path / "x", *extra)) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (tmp_path / "x" / "parts.jsonl").exists()


def test_cli_refuses_an_mjcf_path(tmp_path, capsys):
    argv = _mc(tmp_path / "x")
    argv[2] = str(tmp_path / "mine.xml")
    assert cli.main(argv) == 2
    assert "runs the built-in fivebar and delta only" in capsys.readouterr().err


def test_plant_effects_reach_every_run(fivebar):
    # A 1 ms delay: the nominal row is the lone simulate_closed_chain run with that delay (not
    # the ideal one, which differs).
    chain, laws = fivebar
    delayed = replace(RUN, effects=PlantEffects(delay=1e-3))
    campaign = run_chain_campaign(chain, laws, replace(SETTINGS, samples=1, run=delayed),
                                  jobs=1)
    law = chain_laws("fl", chain)[0]
    ref = chain_reference(chain, DURATION)
    by_hand = simulate_closed_chain(chain, law, ref, DURATION, rate=1000.0,
                                    effects=PlantEffects(delay=1e-3))
    ideal = simulate_closed_chain(chain, chain_laws("fl", chain)[0], ref, DURATION, rate=1000.0)
    rms = float(np.sqrt(np.mean((by_hand.q - by_hand.r) ** 2)))
    assert by_hand.info["engine"] == "python"
    assert_allclose(campaign.nominal["fl_rms_error"], rms, rtol=1e-12)
    assert abs(rms - float(np.sqrt(np.mean((ideal.q - ideal.r) ** 2)))) > 1e-3 * rms


def test_api_refuses_settings_that_do_not_apply(fivebar, tmp_path):
    chain, laws = fivebar
    with pytest.raises(TypeError, match="tolerances must be a MechanismUncertainty"):
        run_chain_campaign(chain, laws, replace(SETTINGS, tolerances=Tolerances()))
    effects = replace(RUN, effects=PlantEffects(bandwidth=300.0), engine="compiled")
    with pytest.raises(ValueError, match="plant effects with engine 'compiled'"):
        run_chain_campaign(chain, laws, replace(SETTINGS, run=effects))
    with pytest.raises(ValueError, match="does not implement limit_margin"):
        run_chain_campaign(chain, laws, replace(SETTINGS, run=replace(RUN, limit_margin=0.1)))
    mine = tmp_path / "mine.xml"
    mine.write_text(chain.mjcf)
    with pytest.raises(ValueError, match="perturbs a built-in parameter set"):
        run_chain_campaign(load_closed_chain(mine), laws, SETTINGS)
    with pytest.raises(ValueError, match="baseline 'pd' is not among"):
        run_chain_campaign(chain, laws, replace(SETTINGS, baseline="pd"))
    # The serial campaign sends a closed chain, and a mechanism's uncertainty, to this one.
    with pytest.raises(TypeError, match="closed chain: run its campaign with"):
        run_campaign(chain, laws, SETTINGS)
    rrr = load_robot("rrr")
    with pytest.raises(TypeError, match="perturbs a parallel mechanism; rrr is a serial arm"):
        run_campaign(rrr, make_laws("fl,hinf", rrr), SETTINGS)
    with pytest.raises(TypeError, match="tolerances must be a Tolerances or "
                                        "IdentifiedUncertainty, got MechanismTolerances"):
        StudyConfig(tolerances=MechanismTolerances())


@pytest.mark.slow
def test_delta_campaign_on_the_cli(tmp_path, capsys):
    out = tmp_path / "delta"
    assert cli.main(["montecarlo", "--robot", "delta", "--samples", "2", "--duration", "0.2",
                     "--jobs", "2", "--out", str(out), "--no-progress"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["summary"]["samples_ok"] == 2
    assert summary["nominal"]["fl_status"] == summary["nominal"]["hinf_status"] == "ok"
    assert (out / "montecarlo.png").is_file()

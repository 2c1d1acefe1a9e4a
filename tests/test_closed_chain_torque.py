"""Torque limits on the closed-chain study (``reproduce --robot fivebar --torque-limit``).

Short runs (50 ms at 1 kHz); each figure is compared with a second computation of the same
quantity, never with a stored value.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin import cli
from rrr_pin.campaign.closed_chain_study import ChainStudyConfig, chain_reference, run_chain_study
from rrr_pin.control.effects import peak_torque
from rrr_pin.model.closed_chain import load_closed_chain

DURATION = 0.05


def _study(**kw):
    return run_chain_study(ChainStudyConfig(mechanism="fivebar", samples=0, duration=DURATION,
                                            rate=1000.0, certify=False, **kw))


def test_a_limit_never_reached_is_the_ideal_study():
    # 1e9 N m: the plants run with a torque-limit effect (the Python engine) that never acts;
    # the ideal study runs fl and hinf on the compiled engine (pinned to the Python one).
    ideal = _study(controllers=("fl", "hinf"))
    limited = _study(controllers=("fl", "hinf", "hinf_aw"), torque_limit=1e9)
    for law in ("fl", "hinf"):
        a, b = ideal.trajectories[0][law], limited.trajectories[0][law]
        assert b.info["engine"] == "python" and a.info["engine"] == "compiled"
        assert_allclose(b.q, a.q, rtol=0, atol=1e-12)
        assert limited.metrics[0][law]["saturated_fraction"] == 0.0
    # hinf_aw unsaturated is hinf (the same arithmetic on the same engine)
    assert_allclose(limited.trajectories[0]["hinf_aw"].q, limited.trajectories[0]["hinf"].q,
                    rtol=0, atol=0)


def test_the_plant_clips_at_the_limit_and_records_the_time_there():
    limit = 0.3  # N m, below the reference's peak (about 1.3 N m here)
    study = _study(controllers=("fl",), torque_limit=limit)
    traj = study.trajectories[0]["fl"]
    assert np.max(np.abs(traj.tau)) <= limit
    at = (np.abs(traj.tau[:-1]) >= limit).any(axis=1).mean()  # recount from the torques
    assert study.metrics[0]["fl"]["saturated_fraction"] == pytest.approx(at, abs=0)
    assert at > 0.0


def test_cli_percent_of_the_reduced_peak(tmp_path, capsys):
    out = tmp_path / "r"
    assert cli.main(["reproduce", "--robot", "fivebar", "--torque-limit", "150%", "--samples",
                     "0", "--duration", str(DURATION), "--rate", "1000", "--no-certify",
                     "--no-progress", "--out", str(out)]) == 0
    data = json.loads((out / "results.json").read_text())
    chain = load_closed_chain("fivebar")
    # the peak from the mechanism's own inverse dynamics, recomputed here on a fresh model
    t = np.arange(round(DURATION * 1000) + 1) / 1000.0
    peak = peak_torque(chain, chain_reference(chain, DURATION), t)
    assert_allclose(data["torque_limit"]["peak_torque_Nm"], peak, rtol=1e-12)
    assert_allclose(data["config"]["torque_limit"], 1.5 * peak, rtol=1e-12)
    assert "hinf_aw" in data["laws"]  # added, as the serial reproduce does
    assert "torque limit 150%" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["--torque-limit", "auto"], "MJCF motors of 'fivebar' have none"),
    (["--controllers", "fl,hinf_aw"], "give --torque-limit"),
    (["--torque-limit", "1,2,3"], "--torque-limit"),
    (["--torque-limit=-5%"], "finite and > 0"),
], ids=["auto", "aw-without-limit", "size", "negative"])
def test_cli_refusals(argv, message, tmp_path, capsys):
    out = tmp_path / "r"
    assert cli.main(["reproduce", "--robot", "fivebar", "--rate", "1000", "--out", str(out),
                     *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert not (out / "results.json").exists()

"""The section-5 study on parallel mechanisms (small settings) and the adept cycle."""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose

from rrr_pin import cli
from rrr_pin.campaign.closed_chain_study import (
    ChainStudyConfig,
    adept_point,
    adept_reference,
    chain_reference,
    run_chain_study,
)
from rrr_pin.model.mechanisms import (
    DeltaParams,
    FiveBarParams,
    delta_fk,
    home_configuration,
    perturb_mechanism,
)


def test_adept_cycle_is_25_305_25_mm():
    P = DeltaParams()
    period = 2.0
    half = period / 2
    corners = adept_point(P, [0.0, 0.2 * half, 0.8 * half, half, period], period)
    # The cycle's own numbers, written here independently: 25 mm up, 305 mm across, down.
    assert_allclose(corners[1] - corners[0], [0.0, 0.0, 0.025], atol=1e-15)
    assert_allclose(corners[2] - corners[1], [0.305, 0.0, 0.0], atol=1e-15)
    assert_allclose(corners[3] - corners[2], [0.0, 0.0, -0.025], atol=1e-15)
    assert_allclose(corners[4], corners[0], atol=1e-15)


def test_adept_reference_is_the_inverse_kinematics_of_the_path():
    P = DeltaParams()
    ref = adept_reference(P, period=2.0, step=0.01)
    t = ref.times[::7]
    R = ref.sample(t)[0]
    # The spline passes through its IK knots: the closed-form FK gives the path back.
    assert_allclose([delta_fk(P, r) for r in R], adept_point(P, t, 2.0), atol=1e-12)


@pytest.mark.parametrize("params", [FiveBarParams(), DeltaParams()], ids=["fivebar", "delta"])
def test_perturbed_mechanisms_stay_closable_within_tolerance(params):
    rng = np.random.default_rng(4)
    for _ in range(5):
        out, factors = perturb_mechanism(params, rng, 0.2, 0.05)
        home_configuration(out)  # closable at home (raises otherwise)
        for name, f in factors.items():
            tol = 0.2 if name.startswith("m") else 0.05
            assert 1 - tol <= f <= 1 + tol
            assert getattr(out, name) == pytest.approx(getattr(params, name) * f, rel=1e-15)
    again, _ = perturb_mechanism(params, np.random.default_rng(4), 0.2, 0.05)
    first, _ = perturb_mechanism(params, np.random.default_rng(4), 0.2, 0.05)
    assert again == first


@pytest.mark.slow
def test_study_on_the_fivebar_small():
    result = run_chain_study(ChainStudyConfig(mechanism="fivebar", samples=1, duration=0.5))
    assert [m["plant"] for m in result.metrics] == ["nominal", "sample000"]
    assert all(m[k]["status"] == "ok" for m in result.metrics for k in result.names)
    nominal = result.claims[0]
    assert nominal["holds"] is True and nominal["value"] < 1e-4
    assert len(result.claims) == 3


def test_reproduce_fivebar_writes_claims_and_figures(tmp_path, capsys):
    out = tmp_path / "fb"
    assert cli.main(["reproduce", "--robot", "fivebar", "--samples", "0", "--duration",
                     "0.2", "--rate", "1000", "--out", str(out), "--no-progress"]) == 0
    data = json.loads((out / "results.json").read_text())
    assert data["config"]["mechanism"] == "fivebar" and len(data["claims"]) == 1
    nominal = data["plants"][0]
    assert nominal["fl"]["status"] == nominal["hinf"]["status"] == "ok"
    # The claim is the larger of the two nominal RMS errors (a 50 mm circle in 0.2 s is fast:
    # the verdict at the study's 2 s is in the slow test).
    assert data["claims"][0]["value"] == max(nominal["fl"]["rms_error_rad"],
                                             nominal["hinf"]["rms_error_rad"])
    assert (out / "fig5_nominal.png").is_file() and (out / "results.md").is_file()
    printed = capsys.readouterr().out
    assert (out / "report.html").is_file() and "report.html into" in printed
    assert "(engine: compiled)" in printed  # auto: the compiled chain engine


def test_reproduce_fivebar_refuses_what_it_does_not_implement(tmp_path, capsys):
    assert cli.main(["reproduce", "--robot", "fivebar", "--engine", "codegen", "--out",
                     str(tmp_path / "x")]) == 2
    assert "does not implement --engine codegen" in capsys.readouterr().err
    # PD has no compiled form: refused by name before any run (not recorded as a failed run)
    assert cli.main(["reproduce", "--robot", "fivebar", "--engine", "compiled", "--controllers",
                     "fl,pd", "--samples", "0", "--duration", "0.01", "--rate", "1000",
                     "--no-certify", "--out", str(tmp_path / "y")]) == 2
    err = capsys.readouterr().err
    assert "engine 'compiled' cannot run" in err and "'pd'" in err and "Traceback" not in err
    assert not (tmp_path / "y" / "results.json").exists()


def test_reproduce_refuses_an_mjcf_path(tmp_path, capsys):
    assert cli.main(["reproduce", "--robot", str(tmp_path / "mine.xml"), "--out",
                     str(tmp_path / "x")]) == 2
    assert "runs the built-in fivebar and delta only" in capsys.readouterr().err


def test_a_users_own_mechanism_is_an_input(tmp_path):
    # Your own 5-bar (longer, heavier distal links): the study runs it, its nominal row is the
    # same simulation written out by hand, and the report is written for it.
    from rrr_pin.control.closed_chain import closed_chain_fl
    from rrr_pin.model.closed_chain import load_closed_chain
    from rrr_pin.report.closed_chain import write_chain_study
    from rrr_pin.sim.closed_chain import simulate_closed_chain

    mine = FiveBarParams(l2=0.25, m2=0.4, name="mybar")
    result = run_chain_study(ChainStudyConfig(mechanism=mine, samples=1, duration=0.05,
                                              controllers=("fl",), certify=False))
    assert result.trajectories[0]["fl"].plant == "mybar"
    plant = load_closed_chain(mine)
    by_hand = simulate_closed_chain(plant, closed_chain_fl(load_closed_chain(mine)),
                                    chain_reference(plant, 0.05), 0.05, rate=1000.0)
    assert result.metrics[0]["fl"]["rms_error_rad"] == float(
        np.sqrt(np.mean((by_hand.q - by_hand.r) ** 2)))
    paths = write_chain_study(result, tmp_path)
    assert "# mybar" in (tmp_path / "results.md").read_text()
    assert (tmp_path / "report.html") in paths

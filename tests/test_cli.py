import json

import pytest

from rrr_pin import cli
from rrr_pin.dynamics import load_robot

KEYS = {"rms_error", "max_error", "rms_torque", "peak_torque"}


@pytest.fixture(scope="module")
def reproduced(tmp_path_factory):
    out = tmp_path_factory.mktemp("results")
    code = cli.main(["reproduce", "--out", str(out), "--samples", "2", "--duration", "0.3",
                     "--jobs", "1", "--no-progress"])
    return code, out


def test_reproduce_writes_everything(reproduced):
    code, out = reproduced
    assert code == 0
    for name in ("fig2", "fig3", "fig4a", "fig4b", "fig5_nominal", "fig6_uncertain"):
        assert (out / f"{name}.png").stat().st_size > 10_000
    plants = sorted((out / "plants").glob("*.urdf"))
    assert [p.name for p in plants] == ["rrr_000.urdf", "rrr_001.urdf"]
    assert load_robot(plants[0]).nq == 3  # the written plants load back
    assert "| Uncertain plants: RMS error FL alone / H-inf+FL" in (out / "results.md").read_text()


def test_results_json_layout(reproduced):
    _, out = reproduced
    data = json.loads((out / "results.json").read_text())
    assert {"home_rad", "amp_rad", "freq_hz", "phase_rad", "duration_s"} <= set(data["reference"])
    for group in ("nominal", "uncertain"):
        for key in ("fl", "hinf"):
            assert set(data[group][key]) == KEYS
            assert all(len(v) == 3 for v in data[group][key].values())
    samples = data["uncertain"]["samples"]
    assert [s["seed"] for s in samples] == [[0, 0], [0, 1]]
    assert {"fl", "hinf", "parameters", "status"} <= set(samples[0])
    summary = data["summary"]
    assert set(summary["nominal_max_error"]) == {"fl", "hinf"}
    assert summary["error_ratio_uncertain"] > 0
    assert len(summary["error_ratio_uncertain_per_joint"]) == 3
    assert summary["torque_ratio_uncertain"] > 0
    # The design recorded beside the study is the paper's (eq. 18 within 0.5 %).
    assert abs(data["design"]["gamma_min"] / 2.1436 - 1) < 5e-3


@pytest.mark.parametrize("argv,message", [
    (["reproduce", "--robot", "nosuch"], "unknown robot 'nosuch'"),
    (["reproduce", "--lock", "joint1"], "--lock expects JOINT=VALUE"),
    (["reproduce", "--home", "0,0,3.0"], "reference for joint 'joint3' spans"),
    (["reproduce", "--robot", "ur5", "--lock", "nojoint=0"], "cannot lock unknown joints"),
], ids=["robot", "lock-syntax", "home-limits", "lock-unknown"])
def test_reproduce_bad_input(argv, message, capsys, tmp_path):
    assert cli.main(argv + ["--out", str(tmp_path), "--no-progress"]) == 2
    assert message in capsys.readouterr().err

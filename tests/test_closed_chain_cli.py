"""Every CLI command that takes a robot, on the 5-bar and the Delta: it works or refuses by name."""

import json

import pytest

from rrr_pin import cli

CHAINS = ["fivebar", "delta"]


@pytest.mark.parametrize("robot", CHAINS)
@pytest.mark.parametrize("argv", [
    ["export", "--rate", "1000"],
    ["identify", "--design-excitation"],
    ["identify", "--data", "measurements.csv"],
])
def test_commands_refuse_closed_chains_by_name(argv, robot, tmp_path, capsys):
    out = tmp_path / "out"
    assert cli.main([*argv, "--robot", robot, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--robot {robot}: a closed chain" in err
    assert f"{argv[0]} does not implement closed chains" in err
    assert "Traceback" not in err and not out.exists()


def test_check_dynamics_refuses_an_mjcf(capsys):
    assert cli.main(["check-dynamics", "--urdf", "mjcf/fivebar.xml"]) == 2
    err = capsys.readouterr().err
    assert "--urdf mjcf/fivebar.xml: a closed chain" in err and "closed form" in err


@pytest.mark.parametrize("command", ["margins", "robstab"])
def test_analysis_refuses_a_lock_on_a_closed_chain(command, capsys):
    assert cli.main([command, "--robot", "fivebar", "--lock", "j1=0.1"]) == 2
    assert "cannot be locked" in capsys.readouterr().err


def test_margins_refuses_a_configuration_outside_the_workspace(capsys):
    # 5-bar: both proximal links pointing away from each other, the loop cannot close
    assert cli.main(["margins", "--robot", "fivebar", "--controllers", "fl",
                     "--home", "3.0,0.0"]) == 2
    err = capsys.readouterr().err
    assert "does not close" in err or "singularity" in err


@pytest.mark.parametrize("robot", ["fivebar", pytest.param("delta", marks=pytest.mark.slow)])
def test_margins_on_closed_chains(robot, capsys):
    assert cli.main(["margins", "--robot", robot, "--controllers", "fl", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    pm = out["laws"]["fl"]["phase_margin_deg"]
    # FL on the exact reduced model: near the shaped double integrator's atan(2 sqrt(2 + sqrt 5))
    # = 76.3 deg (tests/test_closed_chain_analysis.py checks it exactly at g = 0)
    assert len(pm) == len(out["q_rad"]) and all(70 < p < 80 for p in pm)
    assert set(out["laws"]) == {"fl"} and out["robot"] == robot

from pathlib import Path

import numpy as np
import pytest
import yourdfpy
from numpy.testing import assert_allclose

from rrr_pin import cli
from rrr_pin.model.dh import forward_kinematics, paper_params
from rrr_pin.model.dynamics import load_robot
from rrr_pin.model.urdf import urdf_from_params

ROOT = Path(__file__).resolve().parents[1]
COMMITTED = ROOT / "urdf" / "rrr.urdf"


def test_committed_urdf_is_generator_output():
    assert COMMITTED.read_text() == urdf_from_params(paper_params()), (
        "urdf/rrr.urdf drifted from its generator: run `rrr-pin urdf --out urdf/rrr.urdf`")


def test_cli_check(tmp_path, capsys):
    assert cli.main(["urdf", "--out", str(COMMITTED), "--check"]) == 0
    stale = tmp_path / "stale.urdf"
    stale.write_text(COMMITTED.read_text().replace('mass value="5.0"', 'mass value="5.1"'))
    assert cli.main(["urdf", "--out", str(stale), "--check"]) == 1
    assert "differs" in capsys.readouterr().out


def test_cli_bare_check_compares_the_committed_file(tmp_path, monkeypatch, capsys):
    # `rrr-pin urdf --check` without --out checks urdf/rrr.urdf from the repository's root
    monkeypatch.chdir(ROOT)
    assert cli.main(["urdf", "--check"]) == 0
    assert capsys.readouterr().out == "urdf/rrr.urdf: up to date\n"
    monkeypatch.chdir(tmp_path)  # elsewhere: no committed file, said so, exit 1
    assert cli.main(["urdf", "--check"]) == 1
    assert "urdf/rrr.urdf: missing (run from the repository's root" in capsys.readouterr().out
    (tmp_path / "urdf").mkdir()
    (tmp_path / "urdf" / "rrr.urdf").write_text(COMMITTED.read_text() + " ")
    assert cli.main(["urdf", "--check"]) == 1
    assert "differs" in capsys.readouterr().out
    assert cli.main(["urdf", "--check", "--out", "-"]) == 2
    assert "--check compares a file" in capsys.readouterr().err


def test_cli_writes_from_params_file(tmp_path):
    params = tmp_path / "p.json"
    paper_params().save(params)
    out = tmp_path / "x" / "rrr.urdf"
    assert cli.main(["urdf", "--params", str(params), "--out", str(out)]) == 0
    assert out.read_text() == COMMITTED.read_text()


def _random_q(n, seed):
    return np.random.default_rng(seed).uniform(-np.pi, np.pi, (n, 3))


def test_pinocchio_placements_equal_dh():
    robot = load_robot(COMMITTED)
    params = paper_params()
    for q in _random_q(50, 2):
        frames = forward_kinematics(params, q)
        # tolerance: a few ulps of products of unit-size rotations and 1 m lengths
        assert_allclose(robot.frame_placement(q, "ee"), frames[-1], atol=1e-12)
        for i, oMi in enumerate(robot.joint_placements(q)):
            # joint i+1 frame = DH frame i turned by q_{i+1} about its z axis
            c, s = np.cos(q[i]), np.sin(q[i])
            rz = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
            assert_allclose(oMi, frames[i] @ rz, atol=1e-12)


def test_yourdfpy_placements_equal_dh():
    urdf = yourdfpy.URDF.load(str(COMMITTED))
    assert urdf.actuated_joint_names == ["joint1", "joint2", "joint3"]
    for q in _random_q(20, 3):
        urdf.update_cfg(q)
        assert_allclose(urdf.get_transform("ee", "base_link"),
                        forward_kinematics(paper_params(), q)[-1], atol=1e-12)


def test_inertials_in_dh_frames():
    # The centre of mass of link i sits lg_i along the link (checked in the base frame).
    robot = load_robot(COMMITTED)
    params = paper_params()
    q = np.array([0.3, -0.7, 1.1])
    frames = forward_kinematics(params, q)
    import pinocchio as pin

    pin.forwardKinematics(robot.model, robot.data, q)
    for i, link in enumerate(params.links, start=1):
        start, end = frames[i - 1][:3, 3], frames[i][:3, 3]
        expected = start + (end - start) * link.lg / link.length
        com = robot.data.oMi[i].act(robot.model.inertias[i].lever)
        assert_allclose(com, expected, atol=1e-12)


@pytest.mark.parametrize("offset", [0.0, 0.4], ids=["no-offset", "offset"])
def test_theta_offset_and_tilted_links(offset):
    import dataclasses

    p = paper_params()
    links = [dataclasses.replace(p.links[0], a=0.2, theta_offset=offset),
             dataclasses.replace(p.links[1], alpha=0.3, d=0.1, theta_offset=-offset),
             p.links[2]]
    params = p.with_links(links)
    robot = load_robot(params)
    for q in _random_q(10, 4):
        assert_allclose(robot.frame_placement(q, "ee"), forward_kinematics(params, q)[-1],
                        atol=1e-12)

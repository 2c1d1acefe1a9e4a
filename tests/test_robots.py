"""Swapping the URDF: example-robot-data arms through the same pipeline (issue: any arm)."""

import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yourdfpy
from numpy.testing import assert_allclose

from rrr_pin import cli
from rrr_pin.campaign.runner import RunSettings, make_laws
from rrr_pin.campaign.study import StudyConfig, run_study
from rrr_pin.control.laws import fl_controller, hinf_fl_controller
from rrr_pin.control.references import default_reference
from rrr_pin.model.dynamics import load_robot
from rrr_pin.model.robots import RobotModelError, erd_urdf_path
from rrr_pin.robust.loopshaping import design
from rrr_pin.sim.simulation import simulate

PANDA_LOCK = {"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0}
ARMS = [("ur5", {}), ("panda", PANDA_LOCK)]


@pytest.fixture(scope="module", params=ARMS, ids=[a[0] for a in ARMS])
def arm(request):
    name, lock = request.param
    return name, lock, load_robot(name, lock=lock)


def test_pinocchio_fk_equals_yourdfpy(arm):
    # Two independent URDF parsers and kinematics codes must place every link alike.
    name, lock, robot = arm
    ref = yourdfpy.URDF.load(str(erd_urdf_path(name)), load_meshes=False,
                             build_collision_scene_graph=False, load_collision_meshes=False,
                             filename_handler=yourdfpy.filename_handler_null)
    rng = np.random.default_rng(11)
    root = ref.base_link
    links = [f.name for f in robot.model.frames
             if f.type == pin.FrameType.BODY and f.name in ref.link_map and f.name != root]
    assert len(links) >= robot.nq
    for _ in range(10):
        q = rng.uniform(np.maximum(robot.lower, -np.pi), np.minimum(robot.upper, np.pi))
        cfg = dict(zip(robot.joint_names, q, strict=True))
        cfg.update(lock)
        ref.update_cfg({j: cfg.get(j, 0.0) for j in ref.actuated_joint_names})
        for link in links:
            # tolerance: double-precision chains of ~10 transforms of metre-size arms
            assert_allclose(robot.frame_placement(q, link), ref.get_transform(link, root),
                            atol=1e-10, err_msg=link)


@pytest.mark.parametrize("key", ["fl", "hinf"])
def test_nominal_tracking_is_negligible(arm, key):
    _, _, robot = arm
    K = design(n=robot.nq).K_reduced
    ctrl = fl_controller(robot) if key == "fl" else hinf_fl_controller(robot, K)
    traj = simulate(robot, ctrl, default_reference(robot), 0.5)
    # Exact model: only the RK4 truncation (~1e-9 rad) remains.
    assert np.max(np.abs(traj.error)) < 1e-7


def test_study_on_perturbed_plants(arm):
    _, lock, robot = arm
    laws = make_laws("fl,hinf", robot, K=design(n=robot.nq).K_reduced)
    # the locked joints' origins stay nominal (Robot.perturbed skips them)
    result = run_study(robot, laws, config=StudyConfig(run=RunSettings(duration=0.3),
                                                       samples=2, jobs=1))
    data = result.to_json()
    assert data["summary"]["samples_ok"] == 2
    for key in ("fl", "hinf"):
        assert len(data["uncertain"][key]["rms_error"]) == robot.nq
        assert all(np.isfinite(data["uncertain"][key]["rms_error"]))
    assert len(data["summary"]["error_ratio_uncertain_per_joint"]["hinf"]) == robot.nq


def test_continuous_joints_are_unbounded_angles():
    robot = load_robot("kinova")
    assert robot.nq == robot.model.nv == 6
    assert np.isinf(robot.upper).sum() == 3
    traj = simulate(robot, fl_controller(robot), default_reference(robot), 0.1)
    assert np.max(np.abs(traj.error)) < 1e-7


def test_ur3_is_not_ur5():
    # example-robot-data 5.0 maps "ur3" to the UR5's loader; we load the UR3's own URDF.
    ur3, ur5 = load_robot("ur3"), load_robot("ur5")
    assert "ur3" in Path(erd_urdf_path("ur3")).name
    assert sum(i.mass for i in ur3.model.inertias) < sum(i.mass for i in ur5.model.inertias)


def test_mimic_joint_of_a_urdf_file_must_be_locked():
    # a URDF path is the user's file: its mimic joint is refused, not locked behind their back
    # (the name "panda" locks it with a warning, test_example_robot_data_names_load_by_name...)
    with pytest.raises(RobotModelError, match="mimics 'panda_finger_joint1'.*lock it"):
        load_robot(erd_urdf_path("panda"))


def test_floating_base_refused(tmp_path):
    with pytest.raises(RobotModelError, match=r"loads 'solo12' with a floating base .*give that "
                                              r"path \(--robot PATH\)"):
        load_robot("solo12")
    text = ('<robot name="f"><link name="world"/><link name="b"><inertial><mass value="1"/>'
            '<inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link>'
            '<joint name="free" type="floating"><parent link="world"/><child link="b"/></joint>'
            '</robot>')
    path = tmp_path / "f.urdf"
    path.write_text(text)
    with pytest.raises(RobotModelError, match="joint 'free' is floating"):
        load_robot(path)


def test_arm_without_inertials_refused(tmp_path):
    text = re.sub(r"<inertial>.*?</inertial>", "", load_robot("ur5").urdf, flags=re.S)
    path = tmp_path / "bare.urdf"
    path.write_text(text)
    with pytest.raises(RobotModelError, match="moves no mass.*no <inertial> data"):
        load_robot(path)


def test_reference_leaving_limits_refused():
    robot = load_robot("panda", lock=PANDA_LOCK)
    with pytest.raises(ValueError, match="reference for joint 'panda_joint4' spans"):
        default_reference(robot, home=np.zeros(7))


def test_design_joints_cli(capsys):
    assert cli.main(["design", "--joints", "6", "--json"]) == 0
    assert '"gamma_min": 2.14' in capsys.readouterr().out


@pytest.mark.parametrize("source,lock,expected", [
    ("rrr", {}, True), ("rrr", {"joint3": 0.0}, True), ("ur5", {}, False),
], ids=["rrr", "rrr-locked", "ur5"])
def test_nominal_params_is_the_papers_for_rrr_only(source, lock, expected):
    # The one "rrr means the paper's Tables 1-2" rule, used by the study and the campaign.
    from rrr_pin.model.dh import paper_params
    from rrr_pin.model.robots import nominal_params

    params = nominal_params(load_robot(source, lock=lock))
    assert params == (paper_params() if expected else None)


def test_nominal_params_of_a_urdf_file_is_none(tmp_path):
    # The same arm read from a file carries no parameter set: its URDF is perturbed instead.
    from rrr_pin.model.robots import nominal_params
    from rrr_pin.model.urdf import write_urdf

    path = write_urdf(tmp_path / "rrr.urdf")
    assert nominal_params(load_robot(path)) is None


def test_every_listed_name_loads():
    # robot_names() lists only arms load_robot accepts; the Panda needs its mimic finger locked
    from rrr_pin.model.robots import robot_names

    for name in robot_names():
        lock = {"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0} if name == "panda" else {}
        robot = load_robot(name, lock=lock)
        assert robot.nq >= 3, name


def test_so100_by_name_says_why_and_loads_by_path():
    # example-robot-data declares the SO-ARM100 floating (SO100Loader.free_flyer = True); its
    # URDF has no floating joint, so by path it is an arm fixed at its root link (issue 24:
    # "so100 loads by path but is called floating by name").
    from rrr_pin.model.robots import erd_urdf_path

    with pytest.raises(RobotModelError, match=r"SO100Loader.free_flyer = True.*so100.urdf, has "
                                              r"no floating joint"):
        load_robot("so100")
    from example_robot_data import robots_loader

    loader = robots_loader.ROBOTS["so100"]
    path = (Path(__import__("example_robot_data").getModelPath(
        f"{loader.path}/{loader.urdf_subpath}/{loader.urdf_filename}"))
        / loader.path / loader.urdf_subpath / loader.urdf_filename)
    text = path.read_text()
    assert "floating" not in text
    arm = load_robot(str(path))
    # as many coordinates as the URDF has moving joints (a free flyer would add 7)
    assert arm.nq == len(re.findall(r'type="(?:revolute|continuous|prismatic)"', text))
    with pytest.raises(RobotModelError):
        erd_urdf_path("so100")


def test_example_robot_data_names_load_by_name_with_mimic_joints_locked(caplog):
    # Issue 31: "panda" is listed by name; its mimic finger joint (and the finger it follows)
    # is locked at 0 m, recorded in `locked`, and said in a warning.
    import logging

    with caplog.at_level(logging.WARNING, logger="rrr_pin.model.dynamics"):
        robot = load_robot("panda")
    assert robot.locked == PANDA_LOCK
    assert robot.nq == 7
    assert "panda_finger_joint2" in caplog.text and "locked" in caplog.text
    # a lock given by the user is kept, the other mimic joint still added
    assert load_robot("panda", lock={"panda_finger_joint1": 0.01}).locked == {
        "panda_finger_joint1": 0.01, "panda_finger_joint2": 0.0}


def _erd_arms():
    from rrr_pin.model.robots import ERD_ARMS

    return ERD_ARMS


@pytest.mark.parametrize("name", _erd_arms())
def test_every_listed_arm_loads_by_name(name):
    # every example-robot-data arm rrr-pin lists loads by its name (mimic joints locked): a
    # fixed base in example-robot-data's own table, and a serial chain in Pinocchio (each
    # joint's parent is the joint before it)
    from example_robot_data import robots_loader

    assert not getattr(robots_loader.ROBOTS[name], "free_flyer", False)
    robot = load_robot(name)
    assert robot.nq >= 6
    assert list(robot.model.parents)[1:] == list(range(robot.model.njoints - 1))


def test_an_unknown_arm_is_refused_naming_the_installed_example_robot_data():
    # issue 50: "iiwa" is not in example-robot-data 5.0 (the version installed here); the
    # refusal says which example-robot-data it looked in
    from importlib.metadata import version

    from example_robot_data import robots_loader

    if "iiwa" in robots_loader.ROBOTS:
        pytest.skip("this example-robot-data has iiwa")
    with pytest.raises(ValueError, match=rf"unknown robot 'iiwa'.*example-robot-data "
                                         rf"{re.escape(version('example-robot-data'))}"):
        load_robot("iiwa")

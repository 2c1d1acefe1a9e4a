"""rrr_pin.report.viewer: tracks and scenes, geometry (URDF shapes, meshes, missing meshes), the
recorded MeshCat animation checked against DH forward kinematics, the byte budget."""

import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import umsgpack
from numpy.testing import assert_allclose

from rrr_pin.model.dh import forward_kinematics, paper_params
from rrr_pin.model.dynamics import load_robot
from rrr_pin.report.geometry import geometry_models
from rrr_pin.report.viewer import (
    Scene,
    Track,
    ViewerSizeError,
    _record,
    scene_document,
    scene_html,
    write_scene_html,
)

ROOT = Path(__file__).resolve().parents[1]


def _q(t, nq, phase=0.0):
    j = np.arange(nq)
    return 0.5 * np.sin(np.pi * t[:, None] + 2 * np.pi * j / 3 + phase)


def _scene(robot, ghosts=2, duration=2.0, dt=1e-3):
    t = np.arange(0.0, duration + dt / 2, dt)
    tracks = [Track("nominal", t, _q(t, robot.nq))]
    tracks += [Track(f"plant {k}", t, _q(t, robot.nq) + 0.1 * (k + 1), opacity=0.3)
               for k in range(ghosts)]
    return Scene("test", robot, tracks)


def test_rrr_visual_cylinders_run_joint_to_joint(rrr):
    # Independent reference: DH forward kinematics (dh.py), not the URDF or Pinocchio.
    visual = pin.buildGeomFromUrdfString(rrr.model, rrr.urdf, pin.GeometryType.VISUAL)
    gdata = visual.createData()
    params = paper_params()
    q = np.array([0.3, -0.8, 1.2])
    frames = forward_kinematics(params, q)
    pin.forwardKinematics(rrr.model, rrr.data, q)
    pin.updateGeometryPlacements(rrr.model, rrr.data, visual, gdata)
    by_joint = {}
    for g, oMg in zip(visual.geometryObjects, gdata.oMg, strict=True):
        by_joint.setdefault(g.parentJoint, []).append((g, oMg))
    assert sorted(by_joint) == [0, 1, 2, 3]  # base box, and shapes on every moving link
    for i, link in enumerate(params.links, start=1):
        # the link body is the longest cylinder on the link (the other is the joint housing)
        g, M = max(((g, M) for g, M in by_joint[i] if type(g.geometry).__name__ == "Cylinder"),
                   key=lambda gm: gm[0].geometry.halfLength)
        half = g.geometry.halfLength
        ends = sorted([M.translation + s * half * M.rotation[:, 2] for s in (-1, 1)],
                      key=lambda p: np.linalg.norm(p - frames[i - 1][:3, 3]))
        # tolerance: products of unit rotations and 1 m lengths, a few ulps
        assert_allclose(ends[0], frames[i - 1][:3, 3], atol=1e-12)
        assert_allclose(ends[1], frames[i][:3, 3], atol=1e-12)
        assert_allclose(2 * half, link.length, rtol=1e-15)


def test_track_validation():
    t = np.linspace(0, 1, 5)
    with pytest.raises(ValueError, match="shape"):
        Track("a", t, np.zeros((4, 3)))
    with pytest.raises(ValueError, match="strictly increasing"):
        Track("a", t[::-1], np.zeros((5, 3)))
    q = np.zeros((5, 3))
    q[3, 1] = np.nan
    with pytest.raises(ValueError, match=r"not finite from sample 3"):
        Track("a", t, q)
    with pytest.raises(ValueError, match="opacity"):
        Track("a", t, np.zeros((5, 3)), opacity=0.0)
    with pytest.raises(ValueError, match="color"):
        Track("a", t, np.zeros((5, 3)), color=(1.0, 2.0, 0.0))
    with pytest.raises(ValueError, match="label"):
        Track(" ", t, np.zeros((5, 3)))


def test_scene_validation(rrr):
    t = np.linspace(0, 1, 5)
    with pytest.raises(ValueError, match="at least one track"):
        Scene("s", rrr, [])
    with pytest.raises(ValueError, match="nq = 3"):
        Scene("s", rrr, [Track("a", t, np.zeros((5, 2)))])
    scene = _scene(rrr, ghosts=0, duration=0.5)
    with pytest.raises(ValueError, match="fps"):
        scene_document(scene, fps=0.0)
    with pytest.raises(ValueError, match="geometry"):
        scene_document(scene, geometry="meshes")
    with pytest.raises(ValueError, match="max_bytes"):
        scene_document(scene, max_bytes=-1)


def _animation(commands):
    for c in commands:
        cmd = umsgpack.unpackb(c)
        if cmd["type"] == "set_animation":
            return cmd
    raise AssertionError("no set_animation command")


def test_animation_keyframes_follow_dh_kinematics(rrr):
    scene = _scene(rrr, ghosts=1, duration=1.0)
    static, anim, facts = _record(scene, 30.0, "auto", True, {})
    assert facts["frames"] == 31 and facts["fps"] == 30.0
    cmd = _animation(anim)
    clips = {a["path"]: a["clip"] for a in cmd["animations"]}
    clip = clips["/meshcat/arms/nominal/joint3"]
    assert clip["fps"] == 30.0
    keys = {tr["name"].lstrip("."): tr["keys"] for tr in clip["tracks"]}
    t = np.arange(31) / 30.0
    q = _q(t, 3)
    for k in (0, 7, 30):
        # joint-3 frame origin = origin of DH frame 2 (dh.py, independent of Pinocchio);
        # tolerance: keyframes are packed as float32 (relative 6e-8 of ~2 m)
        assert keys["position"][k]["time"] == k
        assert_allclose(keys["position"][k]["value"], forward_kinematics(
            paper_params(), q[k])[2][:3, 3], atol=1e-6)
    # the ghost is animated too, with its own offset trajectory
    ghost = {tr["name"].lstrip("."): tr["keys"] for tr in
             clips["/meshcat/arms/plant_0/joint3"]["tracks"]}
    assert_allclose(ghost["position"][5]["value"], forward_kinematics(
        paper_params(), q[5] + 0.1)[2][:3, 3], atol=1e-6)


def test_document_is_self_contained(rrr, tmp_path):
    path = write_scene_html(tmp_path / "scene.html", _scene(rrr, ghosts=1, duration=0.5))
    text = path.read_text()
    assert "MeshCat.Viewer" in text and "handle_command_bytearray" in text
    assert "<script src" not in text.lower()
    assert 'src="http' not in text and 'href="http' not in text


def test_decimation_keeps_the_budget(rrr):
    scene = _scene(rrr, ghosts=10, duration=10.0)
    doc_full = scene_document(scene, fps=30.0)
    budget = len(doc_full.encode()) - 300_000  # forces fewer frames
    doc = scene_document(scene, fps=30.0, max_bytes=budget)
    assert len(doc.encode()) <= budget
    cmd = _animation(_commands(doc))
    assert cmd["animations"][0]["clip"]["fps"] < 30.0
    # 1 MB holds the viewer script (0.85 MB) and the first arm only: the ghosts are left out
    assert len(scene_document(scene, max_bytes=1_000_000).encode()) <= 1_000_000
    with pytest.raises(ViewerSizeError, match="max_bytes=800000: the geometry of its first"):
        scene_document(scene, max_bytes=800_000)  # below the viewer script alone


def test_a_scene_too_heavy_for_its_budget_draws_its_first_arms_and_says_so(ur5):
    # Issue 31: reproduce --robot xarm7 failed after the whole study ("scene ... does not fit
    # max_bytes"), the geometry of 11 arms alone exceeding the page's share. UR5's visual
    # meshes take about 8.9 MB per arm: 4 arms cannot fit 23 MB (0.9 of it for the document,
    # the rest for the escaping), the first 2 can.
    scene = _scene(ur5, ghosts=3, duration=1.0)
    fragment = scene_html(scene, max_bytes=23_000_000, geometry="visual")
    assert len(fragment.encode()) <= 23_000_000
    assert "the first 2 of the 4 arms drawn" in fragment
    legend = fragment[fragment.rindex("<figcaption>"):]
    assert "nominal" in legend and "plant 0" in legend and "plant 1" not in legend


def _commands(doc):
    import base64
    import re

    block = doc[doc.index("var commands = ["):]
    return [base64.b64decode(s) for s in re.findall(r'"([A-Za-z0-9+/=]{8,})"',
                                                   block[:block.index("];")])]


def test_missing_meshes_drawn_as_shapes_with_a_warning(tmp_path):
    text = (ROOT / "urdf" / "rrr.urdf").read_text()
    start = text.index('<visual name="link2_body">')
    end = text.index("</visual>", start) + len("</visual>")
    text = text[:start] + ('<visual><origin xyz="0 0 0" rpy="0 0 0"/><geometry><mesh '
                           'filename="package://nowhere/meshes/missing_link2.stl"/></geometry>'
                           '</visual>') + text[end:]
    urdf = tmp_path / "rrr_missing.urdf"
    urdf.write_text(text)
    robot = load_robot(urdf)
    with pytest.warns(UserWarning, match="missing_link2.stl"):
        visual, _, missing = geometry_models(robot, ())
    assert missing == ["package://nowhere/meshes/missing_link2.stl"]
    # link 2 gets a cylinder from its frame to joint 3's origin: length a2 = 1 m (Table 1)
    on_link2 = [g for g in visual.geometryObjects if g.parentJoint == 2]
    lengths = sorted(2 * g.geometry.halfLength for g in on_link2
                     if hasattr(g.geometry, "halfLength"))
    assert_allclose(lengths[-1], paper_params().links[1].a, rtol=1e-12)
    with pytest.warns(UserWarning, match="missing_link2.stl"):
        doc = scene_document(_scene(robot, ghosts=0, duration=0.5))
    assert "MeshCat.Viewer" in doc


def test_example_robot_data_meshes_found(ur5):
    robot = ur5
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no mesh may be missing
        visual, collision, missing = geometry_models(robot, ())
    assert missing == []
    paths = [Path(g.meshPath) for g in visual.geometryObjects]
    assert len(paths) == 7 and all(p.is_file() and p.suffix == ".dae" for p in paths)
    stl = [Path(g.meshPath) for g in collision.geometryObjects if g.meshPath.endswith(".stl")]
    assert len(stl) == 7 and all(p.is_file() for p in stl)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_example_robot_data_scene_size(name):
    lock = {"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0} if name == "panda" else None
    robot = load_robot(name, lock=lock)
    doc = scene_document(_scene(robot, ghosts=10, duration=10.0), max_bytes=9_000_000)
    assert len(doc.encode()) <= 9_000_000


@pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
def test_scene_path_is_checked(plant):
    # A scene's path (a plant's task path, drawn as a line) is validated where it is given.
    track = Track("nominal", [0.0], [plant.neutral()])
    with pytest.raises(ValueError, match=r"expected path of shape \(K, 3\) with K >= 2, got "
                                         r"\(4, 2\)"):
        Scene(plant.name, plant, [track], path=np.zeros((4, 2)))
    with pytest.raises(ValueError, match="path must be finite"):
        Scene(plant.name, plant, [track], path=[[0.0, 0.0, 0.0], [np.nan, 0.0, 0.0]])

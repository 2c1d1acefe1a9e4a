"""Edge validation (issue 12): every bad model or input is refused with a message naming it.

Each hostile URDF or parameter file is made inside its test from a valid one with one defect,
so a test fails for its own defect only. ``test_valid_arm_loads`` pins the valid starting point.
"""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from rrr_pin import cli
from rrr_pin.cli.common import parse_lock
from rrr_pin.model.dh import (
    INERTIA_RTOL,
    ArmParams,
    check_inertial,
    check_inertials,
    paper_params,
)
from rrr_pin.model.dynamics import load_robot
from rrr_pin.model.robots import RobotModelError
from rrr_pin.model.uncertainty import perturb_inertia, perturb_urdf
from rrr_pin.model.urdf import urdf_from_params
from rrr_pin.model.urdf_checks import check_urdf_inertials

# --- a valid two-joint arm, and one defect at a time ------------------------------------------


def _inertial(mass="1", ixx="0.01", iyy="0.01", izz="0.01", ixy="0", ixz="0", iyz="0",
              origin='<origin xyz="0 0 0.1"/>', inertia=True) -> str:
    tensor = (f'<inertia ixx="{ixx}" ixy="{ixy}" ixz="{ixz}" iyy="{iyy}" iyz="{iyz}" '
              f'izz="{izz}"/>') if inertia else ""
    return f'<inertial>{origin}<mass value="{mass}"/>{tensor}</inertial>'


def _arm(l1=None, axis="0 1 0", lower="-1", upper="1", extra="") -> str:
    """Two pendulum links on revolute joints j1 (base -> l1) and j2 (l1 -> l2) about y."""
    l1 = _inertial() if l1 is None else l1
    return (
        '<robot name="arm"><link name="base"/>'
        f'<link name="l1">{l1}</link><link name="l2">{_inertial()}</link>'
        '<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>'
        f'<axis xyz="{axis}"/>'
        f'<limit lower="{lower}" upper="{upper}" effort="10" velocity="1"/></joint>'
        '<joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>'
        '<origin xyz="0 0 0.2"/><axis xyz="0 1 0"/>'
        '<limit lower="-1" upper="1" effort="10" velocity="1"/></joint>'
        f'{extra}</robot>')


def _load(tmp_path, text, **kwargs):
    path = tmp_path / "arm.urdf"
    path.write_text(text)
    return load_robot(path, **kwargs)


def test_valid_arm_loads(tmp_path):
    robot = _load(tmp_path, _arm())
    # Independent reference, by hand: at q = 0 both links hang along z. M11 = Iyy1 + m1 r1^2
    # + Iyy2 + m2 (0.2 + 0.1)^2 = 0.01 + 0.01 + 0.01 + 0.09; M12 = Iyy2 + m2 * 0.3 * 0.1 and
    # M22 = Iyy2 + m2 * 0.1^2. Exact sums of a few products: rtol 1e-12.
    assert_allclose(robot.M([0.0, 0.0]), [[0.12, 0.04], [0.04, 0.02]], rtol=1e-12)


# --- A. inertials -----------------------------------------------------------------------------

BAD_INERTIALS = [
    ("negative-mass", _inertial(mass="-1"),
     r"link 'l1': mass must be a finite number >= 0 \[kg\], got -1\.0"),
    ("nan-mass", _inertial(mass="nan"), r"link 'l1': <mass value=\"nan\"> must hold 1 finite"),
    ("nan-inertia", _inertial(ixx="nan"), r"link 'l1': <inertia ixx=\"nan\"> must hold 1 fin"),
    ("inf-inertia", _inertial(iyz="inf"), r"link 'l1': <inertia iyz=\"inf\"> must hold 1 fin"),
    ("missing-attribute", _inertial().replace(' izz="0.01"', ""),
     r"link 'l1': <inertia izz=\"\"> must hold 1 finite number"),
    ("no-inertia", _inertial(inertia=False), r"link 'l1': <inertial> has no <inertia>"),
    ("no-mass", _inertial().replace('<mass value="1"/>', ""), r"link 'l1': .*has no <mass>"),
    ("negative-moment", _inertial(ixx="-0.01"),
     r"link 'l1': inertia is not positive semi-definite: principal moments \(-0\.01, "),
    ("indefinite", _inertial(ixy="0.05"),  # eigenvalues 0.01 +- 0.05: one is -0.04
     r"link 'l1': inertia is not positive semi-definite: principal moments \(-0\.04, "),
    ("triangle", _inertial(izz="0.05"),
     r"link 'l1': inertia violates the triangle inequality: the largest principal moment "
     r"0\.05 exceeds the sum of the other two 0\.02"),
    ("massless-with-inertia", _inertial(mass="0"),
     r"link 'l1': a massless body \(mass 0 kg\) must have zero inertia"),
    ("nan-com", _inertial(origin='<origin xyz="0 nan 0.1"/>'),
     r"link 'l1' <inertial>: <origin xyz=\"0 nan 0\.1\"> must hold 3 finite numbers"),
]


@pytest.mark.parametrize(("l1", "match"), [b[1:] for b in BAD_INERTIALS],
                         ids=[b[0] for b in BAD_INERTIALS])
def test_bad_inertial_refused(tmp_path, l1, match):
    with pytest.raises(RobotModelError, match=match) as info:
        _load(tmp_path, _arm(l1=l1))
    assert str(tmp_path / "arm.urdf") in str(info.value)  # the file is named too


def test_triangle_tolerance_is_as_stated():
    # Principal moments (1, 1, 2 (1 + r)): the triangle inequality is broken by r relative to
    # the largest moment (up to a factor 2); INERTIA_RTOL = 1e-6 admits r = 0.2 * rtol and
    # refuses r = 5 * rtol. A thin rod (0, 1, 1) sits exactly on the bound and is accepted.
    check_inertial(1.0, np.diag([0.0, 1.0, 1.0]))
    check_inertial(1.0, np.diag([1.0, 1.0, 2.0 * (1.0 + 0.2 * INERTIA_RTOL)]))
    with pytest.raises(ValueError, match="triangle inequality"):
        check_inertial(1.0, np.diag([1.0, 1.0, 2.0 * (1.0 + 5.0 * INERTIA_RTOL)]))


@pytest.mark.parametrize(("mass", "inertia", "match"), [
    (True, np.eye(3), r"body: mass must be a finite number >= 0 \[kg\], got True"),
    (1.0, np.eye(2), r"Expected inertia of shape \(3, 3\), got \(2, 2\)"),
    (1.0, [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]], "inertia must be symmetric"),
    (1.0, [[1, 0, 0], [0, math.nan, 0], [0, 0, 1]], "inertia must be finite"),
], ids=["bool-mass", "shape", "asymmetric", "nan"])
def test_check_inertial_arguments(mass, inertia, match):
    with pytest.raises(ValueError, match=match):
        check_inertial(mass, inertia, name="body")


def test_check_dynamics_refuses_negative_mass(tmp_path, capsys):
    path = tmp_path / "neg.urdf"
    text = urdf_from_params()
    assert text.count('<mass value="5.0"/>') == 1
    path.write_text(text.replace('<mass value="5.0"/>', '<mass value="-5.0"/>'))
    assert cli.main(["check-dynamics", "--urdf", str(path)]) == 2
    out = capsys.readouterr()
    assert "OK" not in out.out
    assert "link 'link3': mass must be a finite number >= 0 [kg], got -5.0" in out.err
    assert "no <inertial>" not in out.err  # the old, wrong cause


def test_uncertain_plants_refuse_broken_nominal_inertial():
    with pytest.raises(RobotModelError, match="link 'l1': inertia violates the triangle"):
        perturb_urdf(_arm(l1=_inertial(izz="0.05")), np.random.default_rng(0))
    with pytest.raises(ValueError, match="I: inertia is not positive semi-definite"):
        perturb_inertia(np.diag([-1.0, 1.0, 1.0]), [1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match=r"factors must be finite, got \[1\.0, nan, 1\.0\]"):
        perturb_inertia(np.eye(3), [1.0, math.nan, 1.0])
    with pytest.raises(ValueError, match=r"factors must be 3 finite numbers > 0, got \[1\.0, 0"):
        perturb_inertia(np.eye(3), [1.0, 0.0, 1.0])


def test_uncertain_plants_are_physical():
    text, _ = perturb_urdf(_arm(), np.random.default_rng(5))
    inertials = check_urdf_inertials(text)  # the validator accepts what we write
    assert sorted(inertials) == ["l1", "l2"]
    for mass, _ in inertials.values():
        assert 0.8 <= mass <= 1.2  # 20 % around the nominal 1 kg


# --- B. models: joints, tree, files, locks -------------------------------------------------


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"axis": "0 0 0"}, r"joint 'j1': <axis xyz=\"0 0 0\"> is the zero vector"),
    ({"axis": "0 nan 1"}, r"joint 'j1': <axis xyz=\"0 nan 1\"> must hold 3 finite numbers"),
    ({"lower": "0.5", "upper": "0.5"},
     r"joint 'j1': limits lower=0\.5 and upper=0\.5 leave no range of motion"),
    ({"lower": "1", "upper": "-1"},
     r"joint 'j1': limits lower=1\.0 and upper=-1\.0 leave no range of motion"),
    ({"upper": "inf"}, r"joint 'j1': <limit upper=\"inf\"> must hold 1 finite number"),
    ({"extra": '<joint name="j3" type="fixed"><parent link="base"/><child link="l2"/></joint>'},
     r"link 'l2' is the child of two joints, 'j2' and 'j3'"),
    ({"extra": '<link name="a"/><link name="b"/>'
               '<joint name="ab" type="fixed"><parent link="a"/><child link="b"/></joint>'
               '<joint name="ba" type="fixed"><parent link="b"/><child link="a"/></joint>'},
     r"links \['a', 'b'\] are not connected to the root link 'base'"),
], ids=["zero-axis", "nan-axis", "lower-eq-upper", "lower-gt-upper", "inf-limit",
        "two-parents", "loop"])
def test_bad_joint_or_tree_refused(tmp_path, kwargs, match):
    with pytest.raises(RobotModelError, match=match):
        _load(tmp_path, _arm(**kwargs))


def test_joint_without_range_may_be_locked_at_its_value(tmp_path):
    robot = _load(tmp_path, _arm(lower="0.5", upper="0.5"), lock={"j1": 0.5})
    assert robot.joint_names == ["j2"]


@pytest.mark.parametrize(("value", "match"), [
    (math.nan, r"lock value of joint 'j1' must be finite \[rad or m\], got nan"),
    (math.inf, r"lock value of joint 'j1' must be finite"),
    (1.5, r"cannot lock joint 'j1' at 1\.5: outside its limits \[-1\.0, 1\.0\]"),
    (True, r"lock value of joint 'j1' must be a number"),
], ids=["nan", "inf", "outside-limits", "bool"])
def test_bad_lock_value_refused(tmp_path, value, match):
    with pytest.raises(RobotModelError, match=match):
        _load(tmp_path, _arm(), lock={"j1": value})


def test_cli_lock_parse_refuses_duplicates():
    with pytest.raises(ValueError, match="--lock j1 given twice"):
        parse_lock(["j1=0", "j1=0.5"])


def test_binary_urdf_names_the_file(tmp_path, capsys):
    path = tmp_path / "binary.urdf"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe" + bytes(range(256)))
    with pytest.raises(RobotModelError, match=r"binary\.urdf: not a UTF-8 text file"):
        load_robot(path)
    assert cli.main(["check-dynamics", "--urdf", str(path)]) == 2
    assert "binary.urdf: not a UTF-8 text file" in capsys.readouterr().err


# --- B. parameter files -----------------------------------------------------------------------


def _params_file(tmp_path, edit) -> str:
    data = paper_params().to_dict()
    edit(data)
    path = tmp_path / "params.json"
    path.write_text(json.dumps(data))
    return str(path)


BAD_PARAMS = [
    ("mass-true", lambda d: d["links"][1].update(mass=True),
     r"links\[1\]: mass must be a finite number > 0 \[kg\], got True"),
    ("mass-string", lambda d: d["links"][0].update(mass="five"),
     r"links\[0\]: mass must be a finite number > 0 \[kg\], got 'five'"),
    ("mass-null", lambda d: d["links"][2].update(mass=None),
     r"links\[2\]: mass must be a finite number > 0 \[kg\], got None"),
    ("J-null", lambda d: d["links"][0].update(J=None),
     r"links\[0\]: J must be a list of 3 principal moments"),
    ("Jy-string", lambda d: d["links"][0].update(J=[1, "x", 0]),
     r"links\[0\]: Jy must be a finite number >= 0 \[kg m\^2\], got 'x'"),
    ("links-int", lambda d: d.update(links=5), r"links must be a list of link objects, got 5"),
    ("links-null", lambda d: d.update(links=None), r"links must be a list of link objects"),
    ("link-int", lambda d: d["links"].__setitem__(0, 5), r"links\[0\] must be an object"),
    ("g-null", lambda d: d.update(g=None), r"g must be a finite number >= 0 \[m/s\^2\], got None"),
    ("name-null", lambda d: d.update(name=None), r"name must be a non-empty string, got None"),
    ("name-newline", lambda d: d.update(name="a\nb"), r"name must hold printable characters"),
    ("negative-mass", lambda d: d["links"][0].update(mass=-2),
     r"links\[0\]: mass must be a finite number > 0 \[kg\], got -2"),
    ("lower-eq-upper", lambda d: d["links"][0].update(lower=1, upper=1),
     r"links\[0\]: joint limits must satisfy lower < upper"),
    ("missing-field", lambda d: d["links"][0].pop("lg"), r"links\[0\] lacks the fields \['lg'\]"),
    ("unknown-field", lambda d: d["links"][0].update(colour=1),
     r"links\[0\]: unknown fields \['colour'\]"),
]


@pytest.mark.parametrize(("edit", "match"), [b[1:] for b in BAD_PARAMS],
                         ids=[b[0] for b in BAD_PARAMS])
def test_bad_params_file_refused(tmp_path, capsys, edit, match):
    path = _params_file(tmp_path, edit)
    with pytest.raises(ValueError, match=match):
        ArmParams.load(path)
    # The CLI names the file and the field, and prints no traceback.
    assert cli.main(["urdf", "--params", path]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"rrr-pin urdf: error: {path}: ")
    assert "Traceback" not in err


def test_binary_params_file_names_the_file(tmp_path):
    path = tmp_path / "p.json"
    path.write_bytes(b"\xff\xfe{}")
    with pytest.raises(ValueError, match=r"p\.json: not a UTF-8 text file"):
        ArmParams.load(path)


def test_robot_name_with_xml_special_characters(tmp_path, capsys):
    # Choice (documented in dh.check_robot_name): any printable name, escaped in the URDF.
    name = 'R&D <arm> "v2"'
    path = _params_file(tmp_path, lambda d: d.update(name=name))
    assert cli.main(["urdf", "--params", path]) == 0
    text = capsys.readouterr().out
    assert ET.fromstring(text).get("name") == name  # well-formed, and the name survives
    assert load_robot(ArmParams.load(path)).name == name


# --- B. command-line options ------------------------------------------------------------------


@pytest.mark.parametrize(("args", "match"), [
    (["--rtol", "nan"], "--rtol must be a finite number >= 0, got nan"),
    (["--rtol=-1e-9"], "--rtol must be a finite number >= 0, got -1e-09"),
    (["--samples", "0"], "--samples must be an integer in [1, 1000000], got 0"),
    (["--seed", "-1"], "--seed must be an integer >= 0, got -1"),
], ids=["rtol-nan", "rtol-negative", "samples", "seed"])
def test_check_dynamics_bad_options(capsys, args, match):
    assert cli.main(["check-dynamics", *args]) == 2
    assert match in capsys.readouterr().err


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"samples": math.inf}, r"samples must be an integer in \[1, 1000000\], got inf"),
    ({"samples": math.nan}, r"samples must be an integer in \[1, 1000000\], got nan"),
    ({"samples": "3"}, r"samples must be an integer in \[1, 1000000\], got '3'"),
    ({"samples": True}, r"samples must be an integer in \[1, 1000000\], got True"),
    ({"seed": math.nan}, "seed must be an integer >= 0, got nan"),
], ids=["samples-inf", "samples-nan", "samples-str", "samples-bool", "seed-nan"])
def test_compare_with_pinocchio_refuses_non_integers(kwargs, match):
    # int(inf) would raise OverflowError and int(nan) a message naming nothing.
    from rrr_pin.model.closed_form import compare_with_pinocchio

    params = paper_params()
    with pytest.raises(ValueError, match=match):
        compare_with_pinocchio(load_robot(params), params, **kwargs)


def test_urdf_check_missing_file(tmp_path, capsys):
    assert cli.main(["urdf", "--check", "--out", str(tmp_path / "missing.urdf")]) == 1
    out = capsys.readouterr().out
    assert "missing.urdf: missing; write it with" in out
    assert "differs" not in out


@pytest.mark.parametrize("where", ["directory", "under-a-file"])
def test_urdf_out_not_writable(tmp_path, capsys, where):
    (tmp_path / "file.txt").write_text("x")
    out = tmp_path if where == "directory" else tmp_path / "file.txt" / "rrr.urdf"
    assert cli.main(["urdf", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--out {out}: cannot write the URDF there" in err
    assert "Traceback" not in err


# --- C. fast path: check=False gives the same values ------------------------------------------

PANDA_LOCK = {"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0}


@pytest.mark.parametrize(("source", "lock"), [("rrr", {}), ("ur5", {}), ("panda", PANDA_LOCK)],
                         ids=["rrr", "ur5", "panda"])
def test_fast_path_equals_checked_path(source, lock):
    robot = load_robot(source, lock=lock)
    rng = np.random.default_rng(13)
    for _ in range(10):
        q, qd, x = (rng.uniform(-2.0, 2.0, robot.nq) for _ in range(3))
        # Same Pinocchio call on the same arrays: equal bit for bit.
        assert_array_equal(robot.M(q, check=False), robot.M(q.tolist()))
        assert_array_equal(robot.V(q, qd, check=False), robot.V(q, qd))
        assert_array_equal(robot.G(q, check=False), robot.G(list(q)))
        assert_array_equal(robot.inverse_dynamics(q, qd, x, check=False),
                           robot.inverse_dynamics(q, qd, x))
        assert_array_equal(robot.forward_dynamics(q, qd, x, check=False),
                           robot.forward_dynamics(q, qd, x))
        # Results are new arrays: a later call does not overwrite an earlier result.
        M1 = robot.M(q, check=False)
        robot.M(q + 0.5, check=False)
        assert_array_equal(M1, robot.M(q))
        # V by RNEA without gravity equals the definition nle(q, qd) - G(q) (second route);
        # both carry round-off ~ eps * |G| with |G| up to ~300 N m.
        assert_allclose(robot.V(q, qd), robot.inverse_dynamics(q, qd, np.zeros(robot.nq))
                        - robot.G(q), rtol=0, atol=1e-11 * max(1.0, np.abs(robot.G(q)).max()))


def test_check_state(rrr):
    robot = rrr
    x = np.array([0.1, 0.2, 0.3])
    assert robot.check_state("q", x) is x  # a valid float64 array passes through, no copy
    big = np.array([1e308, 1e308, 0.0])  # finite, though its sum overflows
    assert robot.check_state("q", big) is big
    with pytest.raises(ValueError, match=r"qd must be finite, got \[0\.1 nan 0\.3\]"):
        robot.check_state("qd", [0.1, math.nan, 0.3])
    with pytest.raises(ValueError, match=r"tau must be finite"):
        robot.check_state("tau", np.array([-math.inf, math.inf, 0.0]))
    with pytest.raises(ValueError, match=r"Expected q of shape \(3,\), got \(2,\)"):
        robot.check_state("q", [0.0, 0.0])
    with pytest.raises(ValueError, match=r"q must be an array of numbers"):
        robot.check_state("q", ["a", "b", "c"])
    # V checks its two arrays in one test first; a failure still names the bad one.
    with pytest.raises(ValueError, match=r"qd must be finite, got \[ 0\. inf  0\.\]"):
        robot.V(np.zeros(3), np.array([0.0, math.inf, 0.0]))
    with pytest.raises(ValueError, match=r"q must be finite"):
        robot.V([math.nan, 0.0, 0.0], np.zeros(3))
    assert_array_equal(robot.V(big, np.zeros(3)), robot.V(big, np.zeros(3), check=False))


@pytest.mark.parametrize(("mass", "inertia", "match"), [
    (-1.0, np.eye(3), "mass must be a finite number >= 0"),
    (0.0, np.eye(3), "massless body"),
    (1.0, [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]], "inertia must be symmetric"),
    (1.0, [[1, 0, 0], [0, math.nan, 0], [0, 0, 1]], "inertia must be finite"),
    (1.0, np.diag([-1.0, 1.0, 1.0]), "not positive semi-definite"),
    (1.0, np.diag([1.0, 1.0, 2.0 * (1.0 + 5.0 * INERTIA_RTOL)]), "triangle inequality"),
], ids=["negative-mass", "massless", "asymmetric", "nan", "negative-moment", "triangle"])
def test_check_inertials_refuses_what_check_inertial_refuses(mass, inertia, match):
    # The vectorized check names the first failing body with check_inertial's own message;
    # the bodies around it (valid, one on the triangle bound, one massless) pass.
    good = [(1.0, np.diag([1.0, 2.0, 2.5])), (0.0, np.zeros((3, 3))),
            (1.0, np.diag([1.0, 1.0, 2.0 * (1.0 + 0.2 * INERTIA_RTOL)]))]
    check_inertials([m for m, _ in good], [I for _, I in good], ["a", "b", "c"])
    bodies = [*good, (mass, np.asarray(inertia, dtype=float)), good[0]]
    with pytest.raises(ValueError, match=match) as info:
        check_inertials([m for m, _ in bodies], [I for _, I in bodies],
                        ["a", "b", "c", "bad", "e"])
    assert str(info.value).startswith("bad")

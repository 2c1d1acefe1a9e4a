"""Structural properties of the Pinocchio dynamics (rrr_pin.model.dynamics), and its edge checks.

Each property is checked against a second Pinocchio algorithm or a finite difference, on the
paper's arm and on example-robot-data arms.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from numpy.testing import assert_allclose

from rrr_pin.model.dynamics import load_robot, robot_from_xml
from rrr_pin.model.robots import RobotModelError
from rrr_pin.model.urdf import urdf_from_params

PANDA_LOCK = {"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0}
ROBOTS = {
    "rrr": ("rrr", {}),
    "ur5": ("ur5", {}),
    "panda": ("panda", {"lock": PANDA_LOCK}),
}
N_STATES = 25
QD_MAX = 5.0  # rad/s
QDD_MAX = 10.0  # rad/s^2
EPS = np.finfo(float).eps


@pytest.fixture(scope="module", params=list(ROBOTS), ids=list(ROBOTS))
def robot(request):
    source, kwargs = ROBOTS[request.param]
    return load_robot(source, **kwargs)


def _states(robot, seed: int, n: int = N_STATES):
    """Random states: q within the joint limits (or [-pi, pi] if unbounded), qd, qdd."""
    rng = np.random.default_rng(seed)
    lower = np.where(np.isfinite(robot.lower), robot.lower, -math.pi)
    upper = np.where(np.isfinite(robot.upper), robot.upper, math.pi)
    for _ in range(n):
        yield (rng.uniform(lower, upper), rng.uniform(-QD_MAX, QD_MAX, robot.nq),
               rng.uniform(-QDD_MAX, QDD_MAX, robot.nq))


def test_M_symmetric_positive_definite_and_equal_to_rnea_columns(robot):
    for q, _, _ in _states(robot, 1):
        M = robot.M(q)
        assert_allclose(M, M.T, rtol=0, atol=0)  # Robot.M mirrors CRBA's upper triangle
        assert np.linalg.eigvalsh(M).min() > 0.0
        # Independent algorithm: column j of M is rnea(q, 0, e_j) - G(q). Both are sums of the
        # same link terms in another order; round-off ~ eps * |M| ~ 1e-14.
        cols = np.column_stack([robot.inverse_dynamics(q, np.zeros(robot.nq), e) - robot.G(q)
                                for e in np.eye(robot.nq)])
        assert_allclose(M, cols, rtol=1e-9, atol=1e-12 * np.abs(M).max())


def test_Mdot_minus_2C_skew_symmetric(robot):
    h = 1e-6  # s: dM/dt along qd by central differences, M(q + h qd) - M(q - h qd) / (2 h)
    for q, qd, _ in _states(robot, 2):
        C = pin.computeCoriolisMatrix(robot.model, robot.data, q, qd)
        Mdot = (robot.M(q + h * qd) - robot.M(q - h * qd)) / (2.0 * h)
        N = Mdot - 2.0 * C
        # FD error: truncation h^2/6 |d^3M/dt^3| <~ 1e-12/6 * |qd|^3 * |M| ~ 1e-9 (|qd| <= 5,
        # |M| <~ 30), round-off ~ eps |M| / h ~ 7e-9; atol 1e-7 covers both 10-fold, while the
        # entries of Mdot reach ~100 kg m^2/s.
        assert_allclose(N, -N.T, rtol=0, atol=1e-7)


def test_C_qd_equals_V(robot):
    for q, qd, _ in _states(robot, 3):
        C = pin.computeCoriolisMatrix(robot.model, robot.data, q, qd)
        V = robot.V(q, qd)  # RNEA(q, qd, 0) - G(q), another algorithm
        # Exact identity up to round-off, eps * |V| with |V| up to ~400 N m.
        assert_allclose(C @ qd, V, rtol=1e-9, atol=1e-12 * max(np.abs(V).max(), 1.0))


def test_G_is_gradient_of_potential_energy(robot):
    h = 1e-5  # rad

    def potential(q):
        return pin.computePotentialEnergy(robot.model, robot.data, q)

    for q, _, _ in _states(robot, 4):
        grad = np.array([(potential(q + h * e) - potential(q - h * e)) / (2.0 * h)
                         for e in np.eye(robot.nq)])
        # Central differences: truncation h^2/6 |P'''| <~ 2e-11 * 300 J ~ 5e-9, round-off
        # eps |P| / h ~ 2e-16 * 500 J / 1e-5 ~ 1e-8; atol 1e-7 N m against |G| ~ 200 N m.
        assert_allclose(robot.G(q), grad, rtol=0, atol=1e-7)


def test_forward_dynamics_inverts_inverse_dynamics(robot):
    for q, qd, qdd in _states(robot, 5):
        tau = robot.inverse_dynamics(q, qd, qdd)
        # ABA vs RNEA: error ~ cond(M) eps |qdd| <~ 1e3 * 2e-16 * 10 ~ 2e-12 rad/s^2 (cond(M)
        # of the panda reaches ~600).
        assert_allclose(robot.forward_dynamics(q, qd, tau), qdd, rtol=0, atol=1e-10)


def test_inverse_of_M_equals_computeMinverse(robot):
    for q, _, _ in _states(robot, 6):
        Minv = pin.computeMinverse(robot.model, robot.data, q)
        inv = np.linalg.inv(robot.M(q))
        # Pinocchio documents the upper triangle of Minv; compare that. Both inverses carry
        # ~cond(M) eps relative error, cond(M) <~ 1e3.
        assert_allclose(np.triu(Minv), np.triu(inv), rtol=1e-9,
                        atol=1e-11 * np.abs(inv).max())


def test_M_V_G_consistent_with_inverse_dynamics(robot):
    for q, qd, qdd in _states(robot, 7):
        tau = robot.M(q) @ qdd + robot.V(q, qd) + robot.G(q)  # eq. (1)
        ref = robot.inverse_dynamics(q, qd, qdd)
        assert_allclose(tau, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())


# --- edge checks ------------------------------------------------------------------------------

@pytest.mark.parametrize(
    ("method", "args", "match"),
    [
        ("M", ([0.0, 0.0],), r"Expected q of shape \(3,\), got \(2,\)"),
        ("G", (np.zeros((3, 1)),), r"Expected q of shape \(3,\), got \(3, 1\)"),
        ("V", (np.zeros(3), np.zeros(4)), r"Expected qd of shape \(3,\), got \(4,\)"),
        ("inverse_dynamics", (np.zeros(3), np.zeros(3), np.zeros(2)),
         r"Expected qdd of shape \(3,\), got \(2,\)"),
        ("forward_dynamics", (np.zeros(3), np.zeros(3), np.zeros(5)),
         r"Expected tau of shape \(3,\), got \(5,\)"),
        ("M", ([0.0, np.inf, 0.0],), "q must be finite"),
    ],
    ids=["M-q", "G-q-2d", "V-qd", "rnea-qdd", "aba-tau", "M-inf"],
)
def test_wrong_array_raises(method, args, match, rrr):
    with pytest.raises(ValueError, match=match):
        getattr(rrr, method)(*args)


def test_missing_file_raises(tmp_path):
    with pytest.raises(FileNotFoundError, match="URDF file not found"):
        load_robot(tmp_path / "missing.urdf")


_LINK = ('<link name="{name}"><inertial><mass value="1"/><origin xyz="0 0 0.1"/>'
         '<inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>')
_JOINT = ('<joint name="j1" type="revolute"><parent link="base"/><child link="{child}"/>'
          '<axis xyz="0 1 0"/>{limit}</joint>')
_LIMIT = '<limit lower="-1" upper="1" effort="10" velocity="1"/>'


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("this is not XML <robot", "not well-formed XML"),
        ('<robot name="r"><link name="base"/>' + _LINK.format(name="l1")
         + _JOINT.format(child="l1", limit="") + "</robot>", r"has no <limit>"),
        ('<robot name="r"><link name="base"/>' + _LINK.format(name="l1")
         + _JOINT.format(child="l9", limit=_LIMIT) + "</robot>", "unknown link 'l9'"),
        ('<robot name="r"><link name="base"/><link name="l1"/>'
         + _JOINT.format(child="l1", limit=_LIMIT) + "</robot>",
         r"moves no mass.*\(l1\) have no <inertial>"),
    ],
    ids=["not-xml", "no-limit", "unknown-link", "no-inertial"],
)
def test_malformed_urdf_raises(tmp_path, text, match):
    path = tmp_path / "bad.urdf"
    path.write_text(text)
    with pytest.raises(RobotModelError, match=match) as info:
        load_robot(path)
    assert isinstance(info.value, ValueError)


def test_well_formed_minimal_urdf_loads(tmp_path):
    """The malformed cases above differ from this valid model by one defect each."""
    path = tmp_path / "ok.urdf"
    path.write_text('<robot name="r"><link name="base"/>' + _LINK.format(name="l1")
                    + _JOINT.format(child="l1", limit=_LIMIT) + "</robot>")
    robot = load_robot(path)
    # One pendulum link: M = Iyy + m r^2 = 0.01 + 1 * 0.1^2 about the y axis.
    assert_allclose(robot.M([0.3]), [[0.02]], rtol=1e-12)


def test_trusted_load_still_unbounds_continuous_joints():
    # check=False skips the URDF validator, not the rewrite of continuous joints for urdfdom.
    text = urdf_from_params().replace('<joint name="joint1" type="revolute">',
                                      '<joint name="joint1" type="continuous">', 1)
    checked, trusted = robot_from_xml(text), robot_from_xml(text, check=False)
    assert checked.upper[0] == trusted.upper[0] == np.inf
    assert checked.lower[0] == trusted.lower[0] == -np.inf
    q = np.array([0.3, -0.2, 0.5])
    assert np.array_equal(trusted.M(q), checked.M(q))


def test_gravity_is_a_magnitude():
    with pytest.raises(ValueError, match=r"gravity must be a finite number >= 0 \[m/s\^2\], "
                                         r"got -9\.8"):
        robot_from_xml(urdf_from_params(), gravity=-9.8)


def _scaled_rrr(s_mass, s_length):
    """The paper's arm with masses x s_mass, lengths x s_length (inertias x s_mass s_length^2)."""
    import dataclasses

    from rrr_pin.model.dh import paper_params

    p = paper_params()
    links = tuple(dataclasses.replace(
        link, a=link.a * s_length, d=link.d * s_length, lg=link.lg * s_length,
        mass=link.mass * s_mass, J=tuple(j * s_mass * s_length**2 for j in link.J))
        for link in p.links)
    return dataclasses.replace(p, links=links)


@pytest.mark.parametrize("s_mass, s_length", [(1e-12, 1.0), (1e-6, 1e-3), (1.0, 1e12),
                                              (1e12, 1.0), (1e-9, 1e6)],
                         ids=["1e-12kg", "mm-mg", "1e12m", "1e12kg", "tiny-mass-long"])
def test_a_tiny_or_huge_arm_loads_and_scales_as_m_l2(s_mass, s_length):
    # An absolute floor (eig_min > 1e-12 max(eig_max, 1)) refused the 1e-12 kg arm as
    # "singular". Reference: M is homogeneous of degree 1 in the masses and 2 in the lengths,
    # so M_scaled(q) = s_mass s_length^2 M(q) exactly; rtol 1e-12 covers the round-off of the
    # scaled parameters (~1e-16) through CRBA.
    nominal = load_robot("rrr")
    arm = load_robot(_scaled_rrr(s_mass, s_length))
    q = np.array([0.3, -0.7, 1.1])
    assert_allclose(arm.M(q), s_mass * s_length**2 * nominal.M(q), rtol=1e-12,
                    atol=1e-12 * s_mass * s_length**2 * np.abs(nominal.M(q)).max())


def test_a_joint_that_moves_no_inertia_is_still_refused():
    # A point mass on joint 1's own axis: M = [0], singular whatever the scale.
    text = ('<robot name="axis"><link name="base"/>'
            '<link name="l1"><inertial><mass value="2"/><origin xyz="0 0 0.5"/>'
            '<inertia ixx="0" iyy="0" izz="0" ixy="0" ixz="0" iyz="0"/></inertial></link>'
            '<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>'
            '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="10" velocity="1"/>'
            '</joint></robot>')
    with pytest.raises(RobotModelError, match=r"mass matrix is singular .* some joint moves "
                                              r"no inertia about its axis"):
        robot_from_xml(text)


def test_a_folder_is_refused_as_a_folder(tmp_path):
    # It said "URDF file not found" (the folder exists).
    (tmp_path / "arm.urdf").mkdir()
    with pytest.raises(RobotModelError, match=r"arm.urdf: is a directory; a robot is a URDF "
                                              r"file or a name"):
        load_robot(tmp_path / "arm.urdf")

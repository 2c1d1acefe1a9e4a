r"""Rigid-body dynamics of a fixed-base serial arm from any URDF, through Pinocchio.

The equation of motion is the paper's eq. (1),

.. math:: M(q) \ddot q + V(q, \dot q) + G(q) = \tau,

with ``M`` from the composite rigid body algorithm (CRBA), ``V + G`` from the recursive
Newton-Euler algorithm (RNEA) and ``qdd`` from the articulated body algorithm (ABA).

Conventions: SI units (rad, rad/s, N m); gravity of magnitude ``gravity`` along ``-z`` of the
URDF's root link; ``q`` are joint angles (revolute) or displacements (prismatic), one per degree
of freedom. Continuous (unbounded revolute) joints are loaded as revolute joints with infinite
limits, so ``q`` is always an angle and ``nq == nv``.

References
----------
.. [1] J. Carpentier et al., "The Pinocchio C++ library", SII 2019.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from .dh import ArmParams

__all__ = ["Robot", "RobotModelError", "load_robot", "robot_from_xml", "robot_names",
           "DEFAULT_GRAVITY"]

#: Gravity magnitude [m/s^2] used unless told otherwise: the paper's "standard value" 9.8.
DEFAULT_GRAVITY = 9.8

#: Stand-in limit [rad] for continuous joints in the URDF handed to urdfdom (it cannot parse
#: ``inf``); replaced by ``+-inf`` in the loaded model.
_UNBOUNDED = 1e300

#: example-robot-data names accepted by :func:`load_robot` (fixed-base arms).
_ERD_ARMS = ("ur3", "ur5", "ur10", "panda", "kinova", "z1", "bravo7_no_ee", "so_arm100")


class RobotModelError(ValueError):
    """A URDF or robot model that rrr-pin cannot simulate (with the reason in the message)."""


def robot_names() -> tuple[str, ...]:
    """Names :func:`load_robot` accepts besides paths: ``"rrr"`` and example-robot-data arms."""
    return ("rrr",) + _ERD_ARMS


@dataclass
class Robot:
    """A Pinocchio model of a fixed-base serial arm with its workspace.

    Attributes
    ----------
    model : pinocchio.Model
        The (possibly reduced) kinematic and inertial model.
    data : pinocchio.Data
        Workspace of ``model``; not thread-safe (one ``Robot`` per process or thread).
    name : str
        Robot name.
    source : str
        Where the model came from (a path, a robot name, or ``"<params>"``).
    urdf : str
        The URDF text the model was built from (before joint locking).
    locked : dict
        Joints locked at fixed values [rad or m], by name.
    """

    model: pin.Model = field(repr=False)
    data: pin.Data = field(repr=False)
    name: str
    source: str
    urdf: str = field(repr=False)
    locked: dict = field(default_factory=dict)

    @property
    def nq(self) -> int:
        """Number of joint coordinates (equal to the number of velocities)."""
        return self.model.nq

    @property
    def joint_names(self) -> list[str]:
        """Names of the moving joints, base to tip, shape (nq,)."""
        return list(self.model.names)[1:]

    @property
    def gravity(self) -> float:
        """Gravity magnitude [m/s^2] (along -z of the root link)."""
        return float(-self.model.gravity.linear[2])

    @property
    def lower(self) -> np.ndarray:
        """Lower joint limits, shape (nq,) [rad or m]; ``-inf`` for continuous joints."""
        return np.array(self.model.lowerPositionLimit, dtype=float)

    @property
    def upper(self) -> np.ndarray:
        """Upper joint limits, shape (nq,) [rad or m]; ``+inf`` for continuous joints."""
        return np.array(self.model.upperPositionLimit, dtype=float)

    def neutral(self) -> np.ndarray:
        """Neutral configuration (all zeros for revolute/prismatic joints), shape (nq,)."""
        return np.array(pin.neutral(self.model), dtype=float)

    def _vec(self, name: str, x) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.shape != (self.nq,):
            raise ValueError(f"Expected {name} of shape ({self.nq},), got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError(f"{name} must be finite, got {x}")
        return x

    def M(self, q) -> np.ndarray:
        """Joint-space inertia matrix ``M(q)`` (CRBA), eq. (2).

        Parameters
        ----------
        q : array-like, shape (nq,)
            Joint positions [rad].

        Returns
        -------
        M : ndarray, shape (nq, nq)
            Full symmetric matrix [kg m^2].
        """
        q = self._vec("q", q)
        Mu = pin.crba(self.model, self.data, q)
        return np.triu(Mu) + np.triu(Mu, 1).T

    def V(self, q, qd) -> np.ndarray:
        """Centrifugal and Coriolis torques ``V(q, qd)``, eq. (3), shape (nq,) [N m].

        Computed as ``rnea(q, qd, 0) - G(q)``.
        """
        q, qd = self._vec("q", q), self._vec("qd", qd)
        nle = pin.nonLinearEffects(self.model, self.data, q, qd)
        return nle - pin.computeGeneralizedGravity(self.model, self.data, q)

    def G(self, q) -> np.ndarray:
        """Gravity torques ``G(q)``, eq. (4), shape (nq,) [N m]."""
        q = self._vec("q", q)
        return np.array(pin.computeGeneralizedGravity(self.model, self.data, q))

    def inverse_dynamics(self, q, qd, qdd) -> np.ndarray:
        """Torques ``tau = M qdd + V + G`` (RNEA), shape (nq,) [N m]."""
        q, qd, qdd = self._vec("q", q), self._vec("qd", qd), self._vec("qdd", qdd)
        return np.array(pin.rnea(self.model, self.data, q, qd, qdd))

    def forward_dynamics(self, q, qd, tau) -> np.ndarray:
        """Accelerations ``qdd = M^-1 (tau - V - G)`` (ABA), shape (nq,) [rad/s^2]."""
        q, qd, tau = self._vec("q", q), self._vec("qd", qd), self._vec("tau", tau)
        return np.array(pin.aba(self.model, self.data, q, qd, tau))

    def frame_placement(self, q, frame: str) -> np.ndarray:
        """Placement of a URDF frame (link or joint name) in the root frame, shape (4, 4)."""
        q = self._vec("q", q)
        if not self.model.existFrame(frame):
            raise ValueError(f"no frame named {frame!r} in robot {self.name!r}")
        pin.framesForwardKinematics(self.model, self.data, q)
        return np.array(self.data.oMf[self.model.getFrameId(frame)].homogeneous)

    def joint_placements(self, q) -> list[np.ndarray]:
        """Placements of the joint frames ``joint1..jointn``, each shape (4, 4)."""
        q = self._vec("q", q)
        pin.forwardKinematics(self.model, self.data, q)
        return [np.array(self.data.oMi[j].homogeneous) for j in range(1, self.model.njoints)]


def _read_source(source) -> tuple[str, str, str]:
    """Return (urdf_text, name, source_label) for a path, a known name or an ArmParams."""
    from .urdf import urdf_from_params  # local import: urdf imports dh only

    if isinstance(source, ArmParams):
        return urdf_from_params(source), source.name, "<params>"
    if not isinstance(source, (str, Path)):
        raise TypeError(f"source must be a URDF path, a robot name or ArmParams, got "
                        f"{type(source).__name__}")
    text = str(source)
    if text == "rrr":
        return urdf_from_params(), "rrr", "rrr"
    if text in _ERD_ARMS or (not text.lower().endswith(".urdf") and _erd_has(text)):
        path = _erd_urdf_path(text)
        return path.read_text(), text, text
    path = Path(text)
    if path.suffix.lower() != ".urdf" and not path.exists():
        raise ValueError(f"unknown robot {text!r}: give a URDF path or one of "
                         f"{', '.join(robot_names())}")
    if not path.is_file():
        raise FileNotFoundError(f"URDF file not found: {path}")
    return path.read_text(), path.stem, str(path)


def _erd_has(name: str) -> bool:
    from example_robot_data.robots_loader import ROBOTS

    return name in ROBOTS


def _erd_urdf_path(name: str) -> Path:
    from example_robot_data import robots_loader

    if name not in robots_loader.ROBOTS:
        raise ValueError(f"example-robot-data has no robot {name!r}")
    loader = robots_loader.ROBOTS[name]
    if name == "ur3" and hasattr(robots_loader, "UR3Loader"):
        # example-robot-data 5.0 maps "ur3" to UR5Loader (its ROBOTS table); its UR3Loader
        # names the UR3's own URDF.
        loader = robots_loader.UR3Loader
    root = Path(__import__("example_robot_data").getModelPath(
        f"{loader.path}/{loader.urdf_subpath}/{loader.urdf_filename}"))
    path = root / loader.path / loader.urdf_subpath / loader.urdf_filename
    if not path.is_file():
        raise FileNotFoundError(f"example-robot-data URDF for {name!r} not found at {path}")
    if getattr(loader, "free_flyer", False):
        raise RobotModelError(f"{name!r} is a floating-base robot; rrr-pin handles fixed-base "
                              f"arms only")
    return path


def _prepare_urdf(text: str, locked: set[str]) -> tuple[str, str]:
    """Validate URDF XML and rewrite continuous joints as unbounded revolute joints."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise RobotModelError(f"malformed URDF (not well-formed XML): {exc}") from None
    if root.tag != "robot":
        raise RobotModelError(f"malformed URDF: root element is <{root.tag}>, expected <robot>")
    links = {link.get("name"): link for link in root.findall("link")}
    joints = root.findall("joint")
    if not links:
        raise RobotModelError("malformed URDF: no <link> element")
    children = {}
    for joint in joints:
        name, jtype = joint.get("name"), joint.get("type")
        parent, child = joint.find("parent"), joint.find("child")
        if parent is None or child is None:
            raise RobotModelError(f"malformed URDF: joint {name!r} lacks <parent> or <child>")
        for end in (parent.get("link"), child.get("link")):
            if end not in links:
                raise RobotModelError(f"malformed URDF: joint {name!r} refers to an unknown "
                                      f"link {end!r}")
        if jtype in ("floating", "planar"):
            raise RobotModelError(f"joint {name!r} is {jtype}: rrr-pin handles fixed-base arms "
                                  f"with revolute and prismatic joints only")
        if jtype not in ("revolute", "continuous", "prismatic", "fixed"):
            raise RobotModelError(f"malformed URDF: joint {name!r} has unknown type {jtype!r}")
        if joint.find("mimic") is not None and name not in locked:
            raise RobotModelError(
                f"joint {name!r} mimics {joint.find('mimic').get('joint')!r}: mimic joints are "
                f"not supported; lock it (e.g. lock={{{name!r}: 0.0}})")
        if jtype in ("revolute", "prismatic") and joint.find("limit") is None:
            raise RobotModelError(f"malformed URDF: {jtype} joint {name!r} has no <limit>")
        if jtype == "continuous":
            joint.set("type", "revolute")
            limit = joint.find("limit")
            if limit is None:
                limit = ET.SubElement(joint, "limit", {"effort": "1e6", "velocity": "1e6"})
            limit.set("lower", repr(-_UNBOUNDED))
            limit.set("upper", repr(_UNBOUNDED))
        children.setdefault(parent.get("link"), []).append((joint, child.get("link")))
    roots = set(links) - {j.find("child").get("link") for j in joints}
    if len(roots) != 1:
        raise RobotModelError(f"malformed URDF: expected one root link, found {sorted(roots)}")
    _check_inertials(links, children, locked)
    return ET.tostring(root, encoding="unicode"), root.get("name") or "robot"


def _check_inertials(links, children, locked) -> None:
    """Refuse a moving joint whose subtree carries no mass (M would be singular)."""

    def subtree_mass(link_name):
        link = links[link_name]
        mass_el = link.find("inertial/mass")
        mass = float(mass_el.get("value", "0")) if mass_el is not None else 0.0
        return mass + sum(subtree_mass(child) for _, child in children.get(link_name, []))

    def missing(link_name):
        names = [] if links[link_name].find("inertial") is not None else [link_name]
        for _, child in children.get(link_name, []):
            names += missing(child)
        return names

    for joints in children.values():
        for joint, child in joints:
            if joint.get("type") == "fixed" or joint.get("name") in locked:
                continue
            mass = subtree_mass(child)
            if not (mass > 0.0 and math.isfinite(mass)):
                raise RobotModelError(
                    f"joint {joint.get('name')!r} moves no mass: the links downstream of it "
                    f"({', '.join(missing(child))}) have no <inertial> data; rrr-pin refuses to "
                    f"simulate an arm with zero mass")


def load_robot(source="rrr", *, gravity: float | None = None,
               lock: dict[str, float] | None = None) -> Robot:
    """Load a fixed-base serial arm into Pinocchio.

    Parameters
    ----------
    source : str, path-like or ArmParams, default "rrr"
        A URDF file path; ``"rrr"`` (the paper's arm, generated from :func:`paper_params`);
        an example-robot-data arm name (see :func:`robot_names`); or an :class:`ArmParams`,
        whose URDF is generated on the fly.
    gravity : float, optional
        Gravity magnitude [m/s^2], along ``-z`` of the URDF's root link; default ``source.g``
        for an :class:`ArmParams`, else 9.8 (the paper's value).
    lock : dict of str to float, optional
        Joints to lock, by name, at the given positions [rad or m] (Pinocchio's reduced model);
        e.g. ``{"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0}``.

    Returns
    -------
    Robot

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    RobotModelError (a ValueError)
        Malformed URDF, floating base, unlocked mimic joint, moving joint without mass
        downstream, unknown joint to lock, or a mass matrix that is not positive definite.
    """
    if gravity is None:
        gravity = source.g if isinstance(source, ArmParams) else DEFAULT_GRAVITY
    raw, name, label = _read_source(source)
    return robot_from_xml(raw, name=name, gravity=gravity, lock=lock, label=label)


def robot_from_xml(urdf: str, *, name: str | None = None, gravity: float = DEFAULT_GRAVITY,
                   lock: dict[str, float] | None = None, label: str = "<string>") -> Robot:
    """Like :func:`load_robot`, from URDF text already in memory.

    Parameters
    ----------
    urdf : str
        URDF XML text.
    name : str, optional
        Robot name; default the URDF's ``<robot name>``.
    gravity, lock
        As in :func:`load_robot`.
    label : str
        Where the text came from, for error messages.
    """
    lock = dict(lock or {})
    gravity = float(gravity)
    if not math.isfinite(gravity) or gravity < 0.0:
        raise ValueError(f"gravity must be a finite magnitude >= 0 m/s^2, got {gravity!r}")
    raw = urdf
    urdf, urdf_name = _prepare_urdf(raw, set(lock))
    try:
        model = pin.buildModelFromXML(urdf)
    except (ValueError, RuntimeError) as exc:
        raise RobotModelError(f"Pinocchio could not build a model from {label}: {exc}") from None
    if model.nq != model.nv:
        raise RobotModelError(f"{label}: joints with nq != nv are not supported "
                              f"(nq={model.nq}, nv={model.nv})")
    unbounded = np.abs(model.upperPositionLimit) >= _UNBOUNDED
    model.upperPositionLimit[unbounded] = np.inf
    model.lowerPositionLimit[np.abs(model.lowerPositionLimit) >= _UNBOUNDED] = -np.inf
    if lock:
        unknown = [j for j in lock if not model.existJointName(j)]
        if unknown:
            raise RobotModelError(f"cannot lock unknown joints {unknown}; joints are "
                                  f"{list(model.names)[1:]}")
        q_ref = pin.neutral(model)
        for joint_name, value in lock.items():
            jid = model.getJointId(joint_name)
            q_ref[model.joints[jid].idx_q] = float(value)
        model = pin.buildReducedModel(model, [model.getJointId(j) for j in lock], q_ref)
    if model.nq == 0:
        raise RobotModelError(f"{label}: no moving joint left")
    model.gravity.linear = np.array([0.0, 0.0, -gravity])
    robot = Robot(model=model, data=model.createData(), name=name or urdf_name, source=label,
                  urdf=raw, locked=lock)
    q0 = np.clip(robot.neutral(), robot.lower, robot.upper)
    eig = np.linalg.eigvalsh(robot.M(q0))
    if not eig.min() > 1e-12 * max(eig.max(), 1.0):
        raise RobotModelError(f"{label}: the mass matrix is not positive definite at the "
                              f"neutral configuration (eigenvalues {eig}); check the inertials")
    return robot

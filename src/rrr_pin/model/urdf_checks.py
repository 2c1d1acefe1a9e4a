"""A URDF checked before Pinocchio reads it: its inertials, its joints and its tree.

:func:`check_urdf_inertials` refuses a body that is not physical, naming it;
:func:`prepare_urdf` checks the whole text (tree, joints, limits, masses) and hands urdfdom a
copy it can parse (continuous joints bounded by :data:`UNBOUNDED`);
:func:`rrr_pin.model.dynamics.load_robot` calls them; so do the writers of drawn and
identified arms.
"""

from __future__ import annotations

import logging
import math
import xml.etree.ElementTree as ET

import numpy as np

from .dh import check_inertial
from .robots import RobotModelError

__all__ = ["UNBOUNDED", "check_urdf_inertials", "parse_urdf", "prepare_urdf",
           "unbound_continuous"]

logger = logging.getLogger(__name__)

#: Stand-in limit [rad] for continuous joints in the URDF handed to urdfdom (it cannot parse
#: ``inf``); replaced by ``+-inf`` in the loaded model.
UNBOUNDED = 1e300


def _numbers(element, attribute: str, count: int, default: str, what: str) -> list[float]:
    """Parse ``count`` finite numbers from an attribute, or raise naming ``what``."""
    raw = element.get(attribute, default)
    try:
        values = [float(v) for v in raw.split()]
    except ValueError:
        values = []
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise RobotModelError(f"{what}: <{element.tag} {attribute}=\"{raw}\"> must hold "
                              f"{count} finite number{'s' if count > 1 else ''}")
    return values


def _inertial_of(link: ET.Element) -> tuple[float, np.ndarray] | None:
    """Mass [kg] and inertia tensor [kg m^2] of a URDF ``<link>``, checked; None if absent."""
    what = f"link {link.get('name')!r}"
    inertial = link.find("inertial")
    if inertial is None:
        return None
    origin = inertial.find("origin")
    if origin is not None:
        _numbers(origin, "xyz", 3, "0 0 0", f"{what} <inertial>")
        _numbers(origin, "rpy", 3, "0 0 0", f"{what} <inertial>")
    mass_el = inertial.find("mass")
    if mass_el is None:
        raise RobotModelError(f"{what}: <inertial> has no <mass>")
    (mass,) = _numbers(mass_el, "value", 1, "", what)
    inertia_el = inertial.find("inertia")
    if inertia_el is None:
        raise RobotModelError(f"{what}: <inertial> has no <inertia> (urdfdom would read zero "
                              f"rotational inertia); give ixx, ixy, ixz, iyy, iyz, izz")
    v = {key: _numbers(inertia_el, key, 1, "", what)[0]
         for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
    inertia = np.array([[v["ixx"], v["ixy"], v["ixz"]],
                        [v["ixy"], v["iyy"], v["iyz"]],
                        [v["ixz"], v["iyz"], v["izz"]]])
    try:
        return check_inertial(mass, inertia, name=what)
    except ValueError as exc:
        raise RobotModelError(str(exc)) from None


def check_urdf_inertials(urdf) -> dict[str, tuple[float, np.ndarray]]:
    """Read and check the ``<inertial>`` of every link of a URDF.

    urdfdom (under Pinocchio) reads NaN or inf in ``<inertia>``, or an ``<inertial>`` without
    ``<inertia>``, as zero rotational inertia with only a message on stderr; this validator
    refuses them, and every body that is not physical (:func:`rrr_pin.model.dh.check_inertial`).

    Parameters
    ----------
    urdf : str or xml.etree.ElementTree.Element
        URDF text, or its parsed ``<robot>`` element.

    Returns
    -------
    dict
        Link name -> ``(mass [kg], inertia tensor, shape (3, 3) [kg m^2])``, in the
        ``<inertial>`` frame, for the links that have an ``<inertial>``.

    Raises
    ------
    RobotModelError (a ValueError)
        Naming the link, the field and the value: a non-finite number, a missing ``<mass>`` or
        ``<inertia>`` or attribute, a negative mass, an inertia that is not positive
        semi-definite or breaks the triangle inequality, or a massless link with inertia.
    """
    root = parse_urdf(urdf) if isinstance(urdf, str) else urdf
    out = {}
    for link in root.findall("link"):
        inertial = _inertial_of(link)
        if inertial is not None:
            out[link.get("name")] = inertial
    return out


def parse_urdf(text: str) -> ET.Element:
    """Return the ``<robot>`` root of URDF ``text``, or refuse text that is not one."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise RobotModelError(f"malformed URDF (not well-formed XML): {exc}") from None
    if root.tag != "robot":
        raise RobotModelError(f"malformed URDF: root element is <{root.tag}>, expected <robot>")
    return root


def _check_joint(joint: ET.Element, locked: set[str]) -> None:
    """Check a joint's numbers: origin, axis (nonzero) and limits (lower < upper)."""
    name, jtype = joint.get("name"), joint.get("type")
    what = f"joint {name!r}"
    origin = joint.find("origin")
    if origin is not None:
        _numbers(origin, "xyz", 3, "0 0 0", what)
        _numbers(origin, "rpy", 3, "0 0 0", what)
    if jtype == "fixed":
        return
    axis_el = joint.find("axis")
    if axis_el is not None:
        axis = _numbers(axis_el, "xyz", 3, "1 0 0", what)
        if math.hypot(*axis) == 0.0:
            raise RobotModelError(f"{what}: <axis xyz=\"{axis_el.get('xyz')}\"> is the zero "
                                  f"vector; a joint needs a direction to turn or slide along")
    limit = joint.find("limit")
    if jtype in ("revolute", "prismatic"):
        if limit is None:
            raise RobotModelError(f"malformed URDF: {jtype} {what} has no <limit>")
        (lower,) = _numbers(limit, "lower", 1, "0", what)
        (upper,) = _numbers(limit, "upper", 1, "0", what)
        if lower > upper or (lower == upper and name not in locked):
            raise RobotModelError(
                f"{what}: limits lower={lower!r} and upper={upper!r} leave no range of motion "
                f"(need lower < upper; a missing attribute reads 0); fix the <limit>, make the "
                f"joint fixed, or lock it")


def prepare_urdf(text: str, locked: set[str]) -> tuple[str, str]:
    """Validate URDF XML and rewrite continuous joints as unbounded revolute joints.

    The URDF validator: the tree (one root, one parent per link, every link reached), every
    joint's numbers (:func:`_check_joint`), every link's inertial
    (:func:`check_urdf_inertials`) and some mass behind every moving joint.
    """
    root = parse_urdf(text)
    links = {}
    for link in root.findall("link"):
        if link.get("name") in links:
            raise RobotModelError(f"malformed URDF: two links named {link.get('name')!r}")
        links[link.get("name")] = link
    joints = root.findall("joint")
    if not links:
        raise RobotModelError("malformed URDF: no <link> element")
    masses = {link: mass for link, (mass, _) in check_urdf_inertials(root).items()}
    children, parent_joint = {}, {}
    for joint in joints:
        name, jtype = joint.get("name"), joint.get("type")
        parent, child = joint.find("parent"), joint.find("child")
        if parent is None or child is None:
            raise RobotModelError(f"malformed URDF: joint {name!r} lacks <parent> or <child>")
        for end in (parent.get("link"), child.get("link")):
            if end not in links:
                raise RobotModelError(f"malformed URDF: joint {name!r} refers to an unknown "
                                      f"link {end!r}")
        if child.get("link") in parent_joint:
            raise RobotModelError(
                f"malformed URDF: link {child.get('link')!r} is the child of two joints, "
                f"{parent_joint[child.get('link')]!r} and {name!r}; a URDF must be a tree "
                f"(one parent per link)")
        parent_joint[child.get("link")] = name
        if jtype in ("floating", "planar"):
            raise RobotModelError(f"joint {name!r} is {jtype}: rrr-pin handles fixed-base arms "
                                  f"with revolute and prismatic joints only")
        if jtype not in ("revolute", "continuous", "prismatic", "fixed"):
            raise RobotModelError(f"malformed URDF: joint {name!r} has unknown type {jtype!r}")
        if joint.find("mimic") is not None and name not in locked:
            raise RobotModelError(
                f"joint {name!r} mimics {joint.find('mimic').get('joint')!r}: mimic joints are "
                f"not supported; lock it (Python: lock={{{name!r}: 0.0}}; command line: "
                f"--lock {name}=0)")
        _check_joint(joint, locked)
        children.setdefault(parent.get("link"), []).append((joint, child.get("link")))
    roots = set(links) - set(parent_joint)
    if len(roots) != 1:
        raise RobotModelError(f"malformed URDF: expected one root link, found {sorted(roots)}")
    reached, stack = set(), list(roots)
    while stack:
        name = stack.pop()
        reached.add(name)
        stack += [child for _, child in children.get(name, [])]
    if len(reached) != len(links):
        raise RobotModelError(f"malformed URDF: links {sorted(set(links) - reached)} are not "
                              f"connected to the root link {sorted(roots)[0]!r} (their joints "
                              f"form a loop)")
    _check_subtree_mass(masses, children, locked)
    return unbound_continuous(root)


def unbound_continuous(root: ET.Element, raw: str | None = None) -> tuple[str, str]:
    """Rewrite continuous joints as revolute joints with unbounded limits (no checks).

    Returns the URDF text for urdfdom and the ``<robot name>``: ``raw`` (the text ``root``
    was parsed from, when given) as it is if no joint is continuous, which saves writing the
    same elements and attributes out again (0.3 ms of a campaign's 3-joint plant).
    """
    name = root.get("name") or "robot"
    joints = root.findall("joint")
    if raw is not None and all(j.get("type") != "continuous" for j in joints):
        return raw, name
    for joint in joints:
        if joint.get("type") == "continuous":
            joint.set("type", "revolute")
            limit = joint.find("limit")
            if limit is None:
                limit = ET.SubElement(joint, "limit", {"effort": "1e6", "velocity": "1e6"})
            limit.set("lower", repr(-UNBOUNDED))
            limit.set("upper", repr(UNBOUNDED))
    return ET.tostring(root, encoding="unicode"), name


def _check_subtree_mass(masses, children, locked) -> None:
    """Refuse a moving joint whose subtree carries no mass (M would be singular).

    ``masses`` maps the links that have an ``<inertial>`` to their mass [kg], as read and
    checked (finite, >= 0) by :func:`check_urdf_inertials`; ``children`` maps a link to its
    ``(joint, child link)`` pairs.
    """

    def subtree(link_name):
        names = [link_name]
        for _, child in children.get(link_name, []):
            names += subtree(child)
        return names

    for joints in children.values():
        for joint, child in joints:
            if joint.get("type") == "fixed" or joint.get("name") in locked:
                continue
            below = subtree(child)
            # Masses are >= 0: a zero sum means every link below is massless (all are named).
            if not sum(masses.get(link, 0.0) for link in below) > 0.0:
                raise RobotModelError(
                    f"joint {joint.get('name')!r} moves no mass: the links downstream of it "
                    f"({', '.join(below)}) have no <inertial> data or zero mass; "
                    f"rrr-pin refuses to simulate an arm with zero mass")

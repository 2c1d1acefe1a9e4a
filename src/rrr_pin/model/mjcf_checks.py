r"""Checks of an MJCF closed chain in Python, before Pinocchio's parser reads the file.

Pinocchio 4.1's ``buildModelAndLegacyConstraintsFromMJCF`` segfaults on a ``<connect>`` naming a
site that does not exist, and reports other malformed loops under the wrong cause (a
singularity, an invalid parent joint, an actuator/mobility mismatch, an empty message). Every
check here names the file, the element and the value, with a
:class:`rrr_pin.model.mechanisms.MechanismError`:

* :func:`check_mjcf_tree` on the XML tree (sites, bodies, anchors, inertias, the ``home`` keyframe);
* :func:`check_home_closes` on the parsed model (every loop closes at ``home`` within
  :data:`HOME_GAP_LIMIT`).

:func:`rrr_pin.model.closed_chain.load_closed_chain` runs both. A *serial* MJCF (no
``<connect>``: an arm such as MuJoCo Menagerie's Franka models) is checked by
:func:`check_serial_mjcf` (a :class:`rrr_pin.model.robots.RobotModelError`), and
:func:`has_loop_closure` tells the two apart.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin

from .mechanisms import MechanismError
from .robots import RobotModelError

__all__ = ["HOME_GAP_LIMIT", "check_mjcf_tree", "check_home_closes", "check_serial_mjcf",
           "has_loop_closure", "MOTOR_ACTUATORS", "is_serial_mjcf", "MJCF_GRAVITY",
           "mjcf_gravity"]


#: Largest gap [m] of a ``<connect>`` at the ``home`` keyframe that loading closes by Newton
#: (a keyframe written with rounded digits); a wider gap is an open loop and is refused.
HOME_GAP_LIMIT = 1e-3


def check_mjcf_tree(root, label: str) -> None:
    """Refuse, in Python, an MJCF that Pinocchio's parser would misread or crash on.

    Pinocchio 4.1's ``buildModelAndLegacyConstraintsFromMJCF`` segfaults (measured: 4 to 6 of
    10 runs) on a ``<connect>`` naming a site that does not exist, and otherwise reports it as
    a singularity or an invalid parent joint. Checked here: a ``<worldbody>`` with a body; every
    ``<connect>`` names two existing, different sites (``site1``/``site2``) or bodies
    (``body1``, ``body2`` or the world, with an ``anchor``) inside the first top-level body,
    the only one the parser keeps; every ``<inertial>`` has a finite mass > 0 and finite
    principal moments > 0; the ``home`` keyframe has one number per joint.
    """
    world = root.find("worldbody")
    if root.tag != "mujoco" or world is None:
        raise MechanismError(f"{label}: not an MJCF model (no <mujoco><worldbody>)")
    tops = world.findall("body")
    if not tops:
        raise MechanismError(f"{label}: <worldbody> has no <body>")
    kept = tops[0]
    sites = {s.get("name") for s in world.findall("site")} | \
        {s.get("name") for s in kept.iter("site")}
    bodies = {"world"} | {b.get("name") for b in kept.iter("body")}
    dropped = {}
    for top in tops[1:]:
        for el in top.iter():
            if el.tag in ("site", "body") and el.get("name"):
                dropped[(el.tag, el.get("name"))] = top.get("name") or "(unnamed)"
    names = set()

    def where(kind: str, key: str, value: str) -> str:
        top = dropped.get((kind, value))
        if top is not None:
            return (f"{key}={value!r} is in the top-level body {top!r}, which the parser drops "
                    f"(only the first top-level body of <worldbody>, {kept.get('name')!r}, is "
                    f"read): put every body under one top-level body")
        known = sorted(n for n in (sites if kind == "site" else bodies) if n)
        return f"{key}={value!r}: no such {kind} (the {kind}s are {', '.join(known) or 'none'})"

    for i, c in enumerate(root.iter("connect")):
        tag = f"{label}: <connect {c.get('name') or f'#{i + 1}'}>"
        if c.get("name"):
            if c.get("name") in names:
                raise MechanismError(f"{tag}: the name is used twice")
            names.add(c.get("name"))
        given = {k: c.get(k) for k in ("site1", "site2", "body1", "body2") if c.get(k)}
        if "site1" in given or "site2" in given:
            if set(given) != {"site1", "site2"}:
                raise MechanismError(f"{tag}: a site connection names site1 and site2 (and no "
                                     f"body), got {sorted(given)}")
            a, b = given["site1"], given["site2"]
            for key, value in (("site1", a), ("site2", b)):
                if value not in sites:
                    raise MechanismError(f"{tag}: {where('site', key, value)}")
        elif "body1" in given:
            a, b = given["body1"], given.get("body2", "world")
            for key, value in (("body1", a), ("body2", b)):
                if value not in bodies:
                    raise MechanismError(f"{tag}: {where('body', key, value)}")
            if not c.get("anchor"):
                raise MechanismError(f"{tag}: a body connection needs an anchor (the point in "
                                     f"body1's frame [m])")
            try:
                anchor = [float(v) for v in c.get("anchor").split()]
            except ValueError:
                anchor = []
            if len(anchor) != 3 or not all(map(math.isfinite, anchor)):
                raise MechanismError(f"{tag}: anchor={c.get('anchor')!r}: expected 3 finite "
                                     f"numbers [m]")
        else:
            raise MechanismError(f"{tag}: names no target: give site1 and site2, or body1 (and "
                                 f"body2) with an anchor")
        if a == b:
            raise MechanismError(f"{tag}: connects {a!r} to itself: a loop closure joins two "
                                 f"different points")
    for body in kept.iter("body"):
        inertial = body.find("inertial")
        if inertial is None:
            continue
        where = f"{label}: <body {body.get('name') or '(unnamed)'}> <inertial>"
        try:
            mass = float(inertial.get("mass", "nan"))
        except ValueError:
            mass = math.nan
        if not (math.isfinite(mass) and mass > 0):
            raise MechanismError(f"{where}: mass={inertial.get('mass')!r}: expected a finite "
                                 f"mass > 0 [kg]")
        if inertial.get("diaginertia") is not None:
            try:
                diag = [float(v) for v in inertial.get("diaginertia").split()]
            except ValueError:
                diag = []
            if len(diag) != 3 or not all(math.isfinite(v) and v > 0 for v in diag):
                raise MechanismError(f"{where}: diaginertia={inertial.get('diaginertia')!r}: "
                                     f"expected 3 finite moments > 0 [kg m^2]")
    joints = list(world.iter("joint"))
    for key in root.iter("key"):
        if key.get("name") == "home" and key.get("qpos"):
            try:
                qpos = [float(v) for v in key.get("qpos").split()]
            except ValueError:
                qpos = None
            if qpos is None or len(qpos) != len(joints) or not all(map(math.isfinite, qpos)):
                raise MechanismError(f"{label}: <key name='home'> qpos must be {len(joints)} "
                                     f"finite numbers [rad, m] (one per joint), got "
                                     f"{key.get('qpos')!r}")


def check_home_closes(model, constraints, home: np.ndarray, label: str) -> None:
    """Refuse a ``home`` keyframe at which a loop is open by more than :data:`HOME_GAP_LIMIT`."""
    data = model.createData()
    pin.forwardKinematics(model, data, home)
    for c in constraints:
        p1 = data.oMi[c.joint1_id].act(c.joint1_placement).translation
        p2 = data.oMi[c.joint2_id].act(c.joint2_placement).translation
        gap = float(np.linalg.norm(p1 - p2))
        if not gap <= HOME_GAP_LIMIT:
            raise MechanismError(
                f"{label}: <connect {c.name or '(unnamed)'}> is open by {gap:.4g} m at the home "
                f"keyframe (points at {np.round(p1, 4).tolist()} and {np.round(p2, 4).tolist()} "
                f"m; at most {HOME_GAP_LIMIT:g} m is closed on loading): give a <key "
                f"name='home'> where every loop closes")


#: The MJCF actuator elements that put a torque ``gear * ctrl`` on their joint and nothing
#: else: the only kind a serial arm's law can drive (its torque is the law's output).
MOTOR_ACTUATORS = ("motor",)

#: MJCF actuator elements (``<actuator>`` children) a serial arm refuses on a moving joint.
_ACTUATOR_TAGS = ("motor", "position", "velocity", "intvelocity", "damper", "cylinder",
                  "muscle", "adhesion", "general", "plugin")


def has_loop_closure(root) -> bool:
    """Whether an MJCF tree closes a kinematic loop (an ``<equality><connect>``)."""
    return any(True for _ in root.iter("connect"))


def _defaults(root) -> dict:
    """Return ``{class name: (<default> element, parent class name or None)}`` of an MJCF."""
    out = {}

    def walk(el, parent):
        name = el.get("class", "main")
        out[name] = (el, parent)
        for child in el.findall("default"):
            walk(child, name)

    top = root.find("default")
    if top is not None:
        walk(top, None)
    return out


def _resolved(defaults: dict, el, attr: str, cls: str | None) -> str | None:
    """``el``'s attribute ``attr``, else the nearest default class's for its tag (MJCF rules)."""
    if el.get(attr) is not None:
        return el.get(attr)
    name = el.get("class") or cls or "main"
    while name is not None and name in defaults:
        default, parent = defaults[name]
        found = default.find(el.tag)
        if found is not None and found.get(attr) is not None:
            return found.get(attr)
        name = parent
    return None


def check_serial_mjcf(root, label: str, locked=()) -> list[str]:
    """Refuse, by name, a serial MJCF whose arm rrr-pin cannot simulate as MuJoCo would.

    Checked on the XML (``root``, the ``<mujoco>`` element), for the joints that move (not in
    ``locked``): no free or ball joint; no nonzero joint ``stiffness`` (a passive spring no
    plant here applies) and no ``ref``; no ``<tendon>`` naming a moving joint, no spatial
    tendon; no ``<equality>`` coupling a moving joint (``joint``, ``tendon``) nor a ``weld``;
    no body with ``gravcomp``; and every actuator on a moving joint a ``<motor>`` with gear 1
    (the law's output is the joint torque: a position servo, a velocity servo, a ``general``
    actuator or a gear other than 1 would change what the law commands). Actuators on locked
    joints are ignored (the joint does not move).

    Returns
    -------
    list of str
        The joint names, in document order.

    Raises
    ------
    RobotModelError (a ValueError)
        Naming the file, the element and the value, with the way out.
    """
    world = root.find("worldbody")
    if root.tag != "mujoco" or world is None:
        raise RobotModelError(f"{label}: not an MJCF model (no <mujoco><worldbody>)")
    defaults = _defaults(root)
    locked = set(locked)
    worlds = root.findall("worldbody")  # MJCF merges every <worldbody> section
    free = [el.get("name") or "(unnamed)" for w in worlds for el in w.iter("freejoint")]
    if free:
        raise RobotModelError(f"{label}: <freejoint {free[0]!r}>: a free-floating body; "
                              f"rrr-pin handles fixed-base arms only (remove the free joint to "
                              f"fix the arm's root body to the world)")
    names = []

    def joints(body, cls):
        cls = body.get("childclass") or cls
        for j in body.findall("joint"):
            yield j, cls
        for child in body.findall("body"):
            yield from joints(child, cls)

    for body in (b for w in worlds for b in w.findall("body")):
        for j, cls in joints(body, None):
            name = j.get("name") or f"(unnamed joint {len(names) + 1})"
            names.append(name)
            jtype = _resolved(defaults, j, "type", cls) or "hinge"
            if jtype in ("free", "ball"):
                raise RobotModelError(
                    f"{label}: joint {name!r} is a {jtype} joint; rrr-pin handles fixed-base "
                    f"arms of hinge and slide joints only"
                    + (" (a free joint makes the arm free-floating)" if jtype == "free" else ""))
            if name in locked:
                continue
            for attr in ("stiffness", "ref"):
                value = _resolved(defaults, j, attr, cls)
                if value is not None and any(float(v) != 0.0 for v in value.split()):
                    raise RobotModelError(
                        f"{label}: joint {name!r} has {attr}={value!r}: "
                        + ("a joint spring rrr-pin's plants do not apply" if attr == "stiffness"
                           else "a reference position other than 0 (qpos0)")
                        + "; remove it (or lock the joint)")
    for body in (b for w in worlds for b in w.iter("body")):
        if body.get("gravcomp") not in (None, "0"):
            raise RobotModelError(f"{label}: body {body.get('name')!r} has gravcomp="
                                  f"{body.get('gravcomp')!r}: MuJoCo's gravity compensation is "
                                  f"a force no plant here applies; remove it")
    moving = [n for n in names if n not in locked]
    tendon_joints = {}
    for section in root.findall("tendon"):
        for t in section:
            tname = t.get("name") or "(unnamed)"
            if t.tag == "spatial":
                raise RobotModelError(f"{label}: <spatial tendon {tname!r}>: a spatial tendon "
                                      f"acts on the arm through sites, which rrr-pin's plants "
                                      f"do not model; remove it")
            coupled = [j.get("joint") for j in t.iter("joint")]
            tendon_joints[tname] = coupled
            hit = [j for j in coupled if j in moving]
            if hit:
                raise RobotModelError(f"{label}: <fixed tendon {tname!r}> drives the arm joint "
                                      f"{hit[0]!r}: a tendon couples joints, which rrr-pin's "
                                      f"serial arms do not model; remove it or lock {hit[0]!r}")
    for section in root.findall("equality"):
        for e in section:
            ename = e.get("name") or "(unnamed)"
            if e.tag == "weld":
                raise RobotModelError(f"{label}: <weld {ename!r}>: a weld constraint is not a "
                                      f"serial arm; remove it")
            coupled = [e.get("joint1"), e.get("joint2")] if e.tag == "joint" else \
                sum((tendon_joints.get(e.get(k), []) for k in ("tendon1", "tendon2")), [])
            hit = [j for j in coupled if j in moving]
            if hit:
                raise RobotModelError(f"{label}: <equality {e.tag} {ename!r}> couples the arm "
                                      f"joint {hit[0]!r}: rrr-pin's serial arms have independent "
                                      f"joints; remove it or lock {hit[0]!r}")
    for section in root.findall("actuator"):
        for a in section:
            if a.tag not in _ACTUATOR_TAGS:
                continue
            aname = a.get("name") or "(unnamed)"
            target = a.get("joint") or a.get("jointinparent")
            via = a.get("tendon") or a.get("site") or a.get("body")
            if target is None and via is not None:
                joined = tendon_joints.get(via, [])
                if a.get("tendon") is None or any(j in moving for j in joined):
                    raise RobotModelError(
                        f"{label}: actuator {aname!r} (<{a.tag}>) acts through "
                        f"{via!r}, not on one joint: rrr-pin's laws command joint torques; "
                        f"remove it")
                continue
            if target is None or target not in moving:
                continue
            if a.tag not in MOTOR_ACTUATORS:
                raise RobotModelError(
                    f"{label}: actuator {aname!r} on joint {target!r} is a <{a.tag}>: rrr-pin's "
                    f"laws command the joint torque, which only a <motor> with gear 1 passes "
                    f"through unchanged; remove it (or make it <motor joint={target!r}/>)")
            gear = _resolved(defaults, a, "gear", None)
            if gear is not None and [float(g) for g in gear.split()][:1] != [1.0]:
                raise RobotModelError(f"{label}: <motor {aname!r}> on joint {target!r} has "
                                      f"gear={gear!r}: the law's torque reaches the joint "
                                      f"unchanged only with gear 1; remove the gear")
    return names


def is_serial_mjcf(source) -> bool:
    """Whether ``source`` is an MJCF file (``.xml``) of a serial arm: no loop closure.

    A file that cannot be read or parsed counts as not serial, so that the closed-chain
    loader reports it as it always has.
    """
    if not isinstance(source, (str, Path)) or not str(source).lower().endswith(".xml"):
        return False
    try:
        root = ET.fromstring(Path(source).read_bytes())
    except (OSError, ET.ParseError):
        return False
    return (root.tag == "mujoco" and root.find("worldbody") is not None
            and not has_loop_closure(root))


#: MuJoCo's gravity when the MJCF gives none [m/s^2] (``<option gravity="0 0 -9.81">``).
MJCF_GRAVITY = 9.81


def mjcf_gravity(root, label: str) -> float:
    """Return the magnitude [m/s^2] of an MJCF's ``<option gravity>``, which must point down z."""
    text = next((o.get("gravity") for o in root.findall("option") if o.get("gravity")), None)
    if text is None:
        return MJCF_GRAVITY
    try:
        g = [float(v) for v in text.split()]
    except ValueError:
        g = []
    if len(g) != 3 or g[0] != 0.0 or g[1] != 0.0 or not g[2] <= 0.0:
        raise RobotModelError(f"{label}: <option gravity={text!r}>: rrr-pin's plants have "
                              f"gravity along -z (0 0 -g, g >= 0 [m/s^2])")
    return -g[2]

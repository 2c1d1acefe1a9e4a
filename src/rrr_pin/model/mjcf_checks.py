r"""Checks of an MJCF closed chain in Python, before Pinocchio's parser reads the file.

Pinocchio 4.1's ``buildModelAndLegacyConstraintsFromMJCF`` segfaults on a ``<connect>`` naming a
site that does not exist, and reports other malformed loops under the wrong cause (a
singularity, an invalid parent joint, an actuator/mobility mismatch, an empty message). Every
check here names the file, the element and the value, with a
:class:`rrr_pin.model.mechanisms.MechanismError`:

* :func:`check_mjcf_tree` on the XML tree (sites, bodies, anchors, inertias, the ``home`` keyframe);
* :func:`check_home_closes` on the parsed model (every loop closes at ``home`` within
  :data:`HOME_GAP_LIMIT`).

:func:`rrr_pin.model.closed_chain.load_closed_chain` runs both.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from .mechanisms import MechanismError

__all__ = ["HOME_GAP_LIMIT", "check_mjcf_tree", "check_home_closes"]


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

"""Joints locked at a position: checked, and removed from a Pinocchio model (its reduced model).

:func:`check_lock` checks the joints to lock and their values, :func:`locked_model` builds the
reduced model, :func:`lock_mimics` adds an arm's mimic joints (which rrr-pin cannot simulate)
to the lock. The arm loaders of :mod:`rrr_pin.model.dynamics` (URDF and MJCF) call them.
"""

from __future__ import annotations

import logging

import pinocchio as pin

from ..validation import check_real
from .robots import RobotModelError

__all__ = ["check_lock", "locked_model", "lock_mimics"]

logger = logging.getLogger(__name__)


def locked_model(model, lock, label: str):
    """Return ``(model, lock)``: ``lock``'s joints fixed (Pinocchio's reduced model), checked.

    A model with no moving joint left is refused, naming ``label``.
    """
    if lock:
        try:
            lock = check_lock(model, lock)
        except RobotModelError as exc:
            raise RobotModelError(f"{label}: {exc}") from None
        q_ref = pin.neutral(model)
        for joint_name, value in lock.items():
            q_ref[model.joints[model.getJointId(joint_name)].idx_q] = value
        model = pin.buildReducedModel(model, [model.getJointId(j) for j in lock], q_ref)
    if model.nq == 0:
        raise RobotModelError(f"{label}: no moving joint left")
    return model, lock


def check_lock(model: pin.Model, lock: dict) -> dict[str, float]:
    """Check the joints to lock (the lock validator): known, finite, inside the limits.

    Returns the values as floats. Raises ``RobotModelError`` naming the joint, the value and the
    limits.
    """
    unknown = [j for j in lock if not isinstance(j, str) or not model.existJointName(j)]
    if unknown:
        raise RobotModelError(f"cannot lock unknown joints {unknown}; joints are "
                              f"{list(model.names)[1:]}")
    out = {}
    for joint_name, value in lock.items():
        jid = model.getJointId(joint_name)
        idx = model.joints[jid].idx_q
        lower = float(model.lowerPositionLimit[idx])
        upper = float(model.upperPositionLimit[idx])
        try:
            value = check_real(f"lock value of joint {joint_name!r}", value, "rad or m")
        except ValueError as exc:
            raise RobotModelError(str(exc)) from None
        if not lower <= value <= upper:
            raise RobotModelError(f"cannot lock joint {joint_name!r} at {value!r}: outside its "
                                  f"limits [{lower!r}, {upper!r}]")
        out[joint_name] = value
    return out


def lock_mimics(urdf: str, name: str, lock: dict[str, float] | None) -> dict[str, float]:
    """Lock an example-robot-data arm's mimic joints and the joints they follow (a gripper).

    rrr-pin cannot simulate a mimic joint; a built-in name must still load, so each mimic
    joint and its leader not already in ``lock`` are locked at 0 clipped to their limits
    [rad or m], with a logged warning naming them (the robot's ``locked`` field records them).
    """
    import xml.etree.ElementTree as ET

    lock = dict(lock or {})
    joints = {j.get("name"): j for j in ET.fromstring(urdf).findall("joint")}
    added = {}
    for joint in joints.values():
        mimic = joint.find("mimic")
        if mimic is None:
            continue
        for jname in (joint.get("name"), mimic.get("joint")):
            if jname in lock or jname in added or jname not in joints:
                continue
            limit = joints[jname].find("limit")
            lower = float(limit.get("lower", 0.0)) if limit is not None else 0.0
            upper = float(limit.get("upper", 0.0)) if limit is not None else 0.0
            added[jname] = min(max(0.0, lower), upper) if lower <= upper else 0.0
    if added:
        logger.warning("%s: locked %s (mimic joints and the joints they follow cannot be "
                       "simulated; pass lock= to choose their positions)", name,
                       ", ".join(f"{k}={v:g}" for k, v in added.items()))
    return {**lock, **added}

"""Uncertain arms put together straight into their Pinocchio model: no URDF text on the way.

:meth:`rrr_pin.model.uncertainty.Tolerances.draw_arm` (what
:meth:`rrr_pin.model.dynamics.Robot.perturbed` calls under the built-in tolerances) draws the
numbers a perturbed URDF would carry, call for call as the text route
(:func:`~rrr_pin.model.uncertainty.perturb_params` for a DH arm,
:func:`~rrr_pin.model.uncertainty.perturb_link` and
:func:`~rrr_pin.model.uncertainty.length_factor` per URDF link and joint), and
:meth:`~rrr_pin.model.dynamics.Robot.drawn` hands them to :func:`assemble`, which puts them
together as Pinocchio's URDF reader does (``pinocchio/parsers/urdf``, ``Model::addFrame``):
each joint origin is ``SE3(R, xyz)`` with ``R`` the rotation urdfdom makes of the text's
roll-pitch-yaw through its quaternion (:func:`urdf_rotation`), a fixed joint's child hangs at
``parent * origin``, a moving joint sits at ``parent * origin``, and every link's inertial
``Inertia(m, c, R I R^T)`` (and every frame's zero inertia) is added to its joint's body with
Pinocchio's own ``+=``, in the reader's order. Everything else (limits, armature, friction,
gravity, frame names) is the nominal model's. :func:`arm_map` reads, once per nominal, what a
draw changes.

This route *defines* the uncertain arm. Its URDF is written only when asked for
(:class:`~rrr_pin.model.dynamics.DrawnArm`: a study saving its plants, a fingerprint), by the
text route from the same draws; read back, that text gives the same model bit for bit (the
same numbers added in the same order, locked joints taken out as ``buildReducedModel`` does;
``tests/test_drawn.py`` pins it on the RRR, UR5, Panda with locked fingers and Kinova, whose
roll-pitch-yaw sit at gimbal lock).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from .urdf import urdf_from_params

__all__ = ["ArmMap", "arm_map", "assemble", "urdf_rotation"]


def urdf_rotation(rpy) -> np.ndarray:
    """Rotation matrix of a URDF roll-pitch-yaw as urdfdom and Pinocchio make it.

    urdfdom's ``Rotation::setFromRPY`` (a quaternion of the half angles, normalized), then
    Eigen's ``Quaternion::toRotationMatrix``, operation for operation (hand-written: neither
    library exposes the step to Python).

    Parameters
    ----------
    rpy : sequence of 3 float
        Roll, pitch, yaw [rad] as read from the text.

    Returns
    -------
    ndarray, shape (3, 3)
    """
    phi, the, psi = (float(a) / 2.0 for a in rpy)
    sp, cp = math.sin(phi), math.cos(phi)
    st, ct = math.sin(the), math.cos(the)
    ss, cs = math.sin(psi), math.cos(psi)
    x = sp * ct * cs - cp * st * ss
    y = cp * st * cs + sp * ct * ss
    z = cp * ct * ss - sp * st * cs
    w = cp * ct * cs + sp * st * ss
    s = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = (x / s, y / s, z / s, w / s) if s != 0.0 else (0.0, 0.0, 0.0, 1.0)
    tx, ty, tz = 2.0 * x, 2.0 * y, 2.0 * z
    twx, twy, twz = tx * w, ty * w, tz * w
    txx, txy, txz = tx * x, ty * x, tz * x
    tyy, tyz, tzz = ty * y, tz * y, tz * z
    return np.array([[1.0 - (tyy + tzz), txy - twz, txz + twy],
                     [txy + twz, 1.0 - (txx + tzz), tyz - twx],
                     [txz - twy, tyz + twx, 1.0 - (txx + tyy)]])


@dataclass(frozen=True)
class _Joint:
    name: str
    kind: str
    child: str
    R: np.ndarray = field(repr=False)      # origin rotation, as Pinocchio reads it
    xyz: np.ndarray = field(repr=False)    # nominal origin translation [m]
    has_origin: bool = True
    motion: pin.SE3 | None = field(default=None, repr=False)  # a locked joint's own motion


@dataclass(frozen=True)
class _Inertial:
    mass: float
    com: np.ndarray = field(repr=False)
    R: np.ndarray = field(repr=False)
    I: np.ndarray = field(repr=False)


@dataclass(frozen=True)
class ArmMap:
    """A nominal arm's URDF as the numbers a draw changes, and the tree Pinocchio reads."""

    root: str
    children: dict    # link -> [_Joint], in urdfdom's order (by joint name)
    joints: list      # [_Joint], document order (the draws' order)
    inertials: dict   # link -> _Inertial, document order (the draws' order)
    frames: dict      # frame name -> frame indices (BODY, FIXED_JOINT) of the nominal model


def _numbers(element, key: str, default: str) -> list[float]:
    return [float(v) for v in (element.get(key) or default).split()]


def arm_map(urdf: str, params, locked: dict, model) -> ArmMap:
    """Return the numbers of a nominal arm's URDF a draw changes, and the tree Pinocchio reads.

    Parameters
    ----------
    urdf : str
        The nominal's URDF text (unused when ``params`` is given).
    params : ArmParams or None
        The nominal's DH parameters, when its plants perturb them (their URDF is
        :func:`~rrr_pin.model.urdf.urdf_from_params`).
    locked : dict
        Locked joints and their values [rad or m].
    model : pinocchio.Model
        The nominal model (its frames' indices).
    """
    dh = params is not None
    text = urdf_from_params(params) if dh else urdf
    root = ET.fromstring(text)
    if not dh:
        from yourdfpy.urdf import URDF, tra  # the text route reads and writes through these

    def rotation(origin):
        rpy = _numbers(origin, "rpy", "0 0 0") if origin is not None else [0.0, 0.0, 0.0]
        if not dh and origin is not None:  # what yourdfpy writes back: its matrix -> rpy
            # yourdfpy's own reader (a private static method): the matrix it writes rpy from
            rpy = tra.euler_from_matrix(URDF._parse_origin(origin))
        return urdf_rotation(rpy)

    joints, children, parents = [], {}, set()
    for j in root.findall("joint"):
        origin = j.find("origin")
        motion = None
        if j.get("name") in locked:
            q = locked[j.get("name")]
            axis = np.array(_numbers(j.find("axis"), "xyz", "1 0 0")
                            if j.find("axis") is not None else [1.0, 0.0, 0.0])
            axis = axis / np.linalg.norm(axis)
            motion = (pin.SE3(np.eye(3), axis * q) if j.get("type") == "prismatic"
                      else pin.SE3(pin.exp3(axis * q), np.zeros(3)))
        joint = _Joint(name=j.get("name"), kind=j.get("type"), child=j.find("child").get("link"),
                       R=rotation(origin),
                       xyz=np.array(_numbers(origin, "xyz", "0 0 0") if origin is not None
                                    else [0.0, 0.0, 0.0]),
                       has_origin=origin is not None, motion=motion)
        joints.append(joint)
        children.setdefault(j.find("parent").get("link"), []).append(joint)
        parents.add(joint.child)
    for kids in children.values():
        kids.sort(key=lambda jt: jt.name)
    inertials = {}
    for link in root.findall("link"):
        el = link.find("inertial")
        if el is None or el.find("mass") is None:
            continue
        origin = el.find("origin")
        v = {k: float(el.find("inertia").get(k)) for k in ("ixx", "ixy", "ixz", "iyy", "iyz",
                                                           "izz")}
        inertials[link.get("name")] = _Inertial(
            mass=float(el.find("mass").get("value")),
            com=np.array(_numbers(origin, "xyz", "0 0 0") if origin is not None
                         else [0.0, 0.0, 0.0]),
            R=rotation(origin),
            I=np.array([[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]],
                        [v["ixz"], v["iyz"], v["izz"]]]))
    (top,) = [link.get("name") for link in root.findall("link")
              if link.get("name") not in parents]
    frames: dict = {}
    for fid, f in enumerate(model.frames):
        if f.type in (pin.FrameType.BODY, pin.FrameType.FIXED_JOINT):
            frames.setdefault(f.name, []).append(fid)
    return ArmMap(root=top, children=children, joints=joints, inertials=inertials,
                  frames=frames)


def _inertias(bodies: dict) -> dict:
    """Pinocchio's ``convertFromUrdf`` of inertials: ``Inertia(m, c, R I R^T)`` each.

    ``bodies``: link name -> ``(m, c, I, R)``. ``I`` as a URDF ``<inertia>`` carries it: its
    upper triangle (``ixy, ixz, iyz``), mirrored. ``R I R^T`` with each dot product summed
    left to right, as Eigen's 3 x 3 products do, for all links at once (elementwise).
    """
    if not bodies:
        return {}
    names = list(bodies)
    sym = np.array([bodies[k][2] for k in names], dtype=float)
    for i, j in ((1, 0), (2, 0), (2, 1)):
        sym[:, i, j] = sym[:, j, i]
    R = np.array([bodies[k][3] for k in names], dtype=float)
    RI = (R[:, :, 0, None] * sym[:, None, 0, :] + R[:, :, 1, None] * sym[:, None, 1, :]
          + R[:, :, 2, None] * sym[:, None, 2, :])
    out = (RI[:, :, 0, None] * R[:, None, :, 0] + RI[:, :, 1, None] * R[:, None, :, 1]
           + RI[:, :, 2, None] * R[:, None, :, 2])
    return {k: pin.Inertia(float(bodies[k][0]), np.asarray(bodies[k][1], dtype=float), out[i])
            for i, k in enumerate(names)}


def assemble(nominal_model, amap: ArmMap, origins: dict, inertials: dict):
    """Return the nominal model with the drawn origins and inertials, as Pinocchio reads them.

    ``origins``: joint name -> translation [m] (absent: nominal); ``inertials``: link name ->
    ``(m, c, I, R)``. Walks the tree as Pinocchio's URDF reader (depth first, children by
    joint name): a moving joint at ``parent * origin``, its child's inertia appended at the
    identity; a fixed joint's child at ``parent * origin``, its inertia appended to the joint
    that carries it. Locked joints then go as ``buildReducedModel`` takes them out: each kept
    joint's body re-appended to a zero inertia, a locked joint's body appended to its parent
    at ``liMi = parent * placement * motion``.
    """
    model = nominal_model.copy()
    zero = pin.Inertia.Zero()
    identity = pin.SE3.Identity()
    full: dict = {}     # joint name -> its body in the model read from the URDF (locks moving)
    joints: list = []   # (name, parent joint name or None, placement), in the reader's order
    placed: list = []   # (frame name, its joint's name or None, placement in that joint)

    def add(owner, Y, P) -> None:
        # Model::addFrame and appendBodyToJoint: inertias[owner] += P.act(Y), in place.
        if owner is not None:
            full[owner] += Y.se3Action(P)

    def walk(link: str, P, owner) -> None:
        for joint in amap.children.get(link, ()):
            origin = pin.SE3(joint.R, origins.get(joint.name, joint.xyz))
            inertia = bodies.get(joint.child, zero)
            if joint.kind != "fixed":  # a joint of the model read from the URDF
                joints.append((joint.name, owner, P * origin))
                full[joint.name] = pin.Inertia.Zero()
                add(joint.name, zero, identity)     # its JOINT frame
                if not inertia.isZero(0.0):         # the child link's body
                    add(joint.name, inertia, identity)
                add(joint.name, zero, identity)     # the child's BODY frame
                placed.append((joint.child, joint.name, identity))
                walk(joint.child, identity, joint.name)
                continue
            Pc = P * origin
            placed.extend([(joint.name, owner, Pc), (joint.child, owner, Pc)])
            add(owner, inertia, Pc)                 # the FIXED_JOINT frame, with the child
            add(owner, zero, Pc)                    # the child's BODY frame
            walk(joint.child, Pc, owner)

    bodies = _inertias({**{link: (nom.mass, nom.com, nom.I, nom.R)
                           for link, nom in amap.inertials.items()}, **inertials})
    walk(amap.root, identity, None)
    locked = {j.name: j.motion for j in amap.joints if j.motion is not None}
    frame: dict = {}  # locked joint -> (the kept joint it hangs on or None, liMi)
    for name, parent, placement in joints:
        owner, at = frame[parent] if parent in locked else (parent, identity)
        if name in locked:
            liMi = at * placement * locked[name]
            frame[name] = (owner, liMi)
            if owner is not None:  # addFrame(FIXED_JOINT frame carrying the body)
                full[owner] += full[name].se3Action(liMi)
            placed.append((name, owner, liMi))
            continue
        j = model.getJointId(name)
        model.jointPlacements[j] = at * placement
        if locked:  # buildReducedModel appends each kept body to a new joint's zero inertia
            body = pin.Inertia.Zero()
            body += full[name].se3Action(identity)
            full[name] = body
    for name in full:
        if name not in locked:
            model.inertias[model.getJointId(name)] = full[name]
    frames = model.frames
    for name, owner, P in placed:
        if owner in locked:  # a frame on a locked joint: joint_frame.placement * placement
            owner, liMi = frame[owner]
            P = liMi * P
        for fid in amap.frames.get(name, ()):
            f = frames[fid]
            f.placement = P
            frames[fid] = f
    return model

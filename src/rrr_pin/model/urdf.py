"""URDF text generated from a DH parameter set (paper Tables 1 and 2).

Frame mapping between the DH table and the URDF
-----------------------------------------------
* ``base_link`` is DH frame 0 (z up, gravity along -z).
* The URDF frame of ``link<i>`` (the joint frame Pinocchio reports for ``joint<i>``) is DH frame
  ``i-1`` rotated by the joint: ``T_0^{i-1} Rz(q_i + theta_offset_i)``. Joint ``i`` therefore
  turns about ``z`` of its own frame, exactly the DH joint axis ``z_{i-1}``.
* DH frame ``i`` sits in ``link<i>`` at ``Tz(d_i) Tx(a_i) Rx(alpha_i)``: URDF origin
  ``xyz = (a_i, 0, d_i)``, ``rpy = (alpha_i, 0, 0)``. That is the origin of ``joint<i+1>``
  (with ``theta_offset_{i+1}`` folded into its rotation) and, for the last link, of the fixed
  frame ``ee`` (the tool tip, DH frame ``n``).
* Each ``<inertial>`` is placed at the centre of mass with its axes along DH frame ``i``, so the
  diagonal ``ixx, iyy, izz`` are the paper's ``Jx_i, Jy_i, Jz_i`` (for link 1 of the paper,
  ``y_1`` is the joint-1 axis and ``Jy1`` the moment about it, as ``D11`` shows).

The output is deterministic: numbers are written with Python's shortest round-trip ``repr``,
so ``urdf/rrr.urdf`` can be regenerated and compared byte for byte (``rrr-pin urdf --check``).
"""

from __future__ import annotations

import math
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from .dh import ArmParams, paper_params

__all__ = ["urdf_from_params", "write_urdf", "check_urdf", "dh_link_frame", "LINK_RADIUS_RATIO"]

#: Radius of the link cylinders as a fraction of the longest link length ``max l_i`` (0.05 m
#: for the paper's 1 m links). The visual shapes are all sized from that radius ``r``: link
#: cylinders of radius ``r`` from joint to joint, joint housings (cylinders of radius ``1.5 r``
#: and length ``3 r`` along each joint axis), a ``6r x 6r x 2r`` base box under joint 1 and a
#: ``2r`` cube at the tool tip. Visual only: no shape plays a role in the dynamics.
LINK_RADIUS_RATIO = 0.05

#: Colours (RGBA) of the visual shapes: links, joint housings and tool, base.
_MATERIALS = (("link", "0.95 0.55 0.15 1"), ("joint", "0.2 0.22 0.28 1"),
              ("base", "0.6 0.6 0.65 1"))


def _num(x: float) -> str:
    x = float(x)
    if x == 0.0:
        return "0"  # also folds -0.0
    return repr(x)


def _vec(v) -> str:
    return " ".join(_num(x) for x in v)


def _dim(x: float) -> str:
    """Format a visual dimension [m] to 6 significant digits (no ``0.30000000000000004``)."""
    return _num(float(f"{x:.6g}"))


def _rpy_of(R: np.ndarray) -> tuple[float, float, float]:
    """URDF roll-pitch-yaw of a rotation matrix (``R = Rz(yaw) Ry(pitch) Rx(roll)``)."""
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    if abs(math.cos(pitch)) < 1e-12:  # gimbal lock: put everything in yaw
        return 0.0, pitch, math.atan2(-R[0, 1], R[1, 1])
    return math.atan2(R[2, 1], R[2, 2]), pitch, math.atan2(R[1, 0], R[0, 0])


def _rot_x(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def dh_link_frame(link) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where a DH link's numbers go in its URDF link frame (the joint's frame).

    Returns
    -------
    frame_xyz : ndarray, shape (3,)
        Origin of DH frame ``i`` [m] (``Tz(d) Tx(a)``): the next joint's origin.
    frame_R : ndarray, shape (3, 3)
        Its rotation ``Rx(alpha)``: the next joint's and the inertial's rotation.
    com : ndarray, shape (3,)
        Centre of mass [m], the inertial's origin.
    """
    frame_xyz = np.array([link.a, 0.0, link.d])
    frame_R = _rot_x(link.alpha)
    return frame_xyz, frame_R, frame_xyz + frame_R @ link.com()


def _origin(xyz, rpy) -> str:
    return f'<origin xyz="{_vec(xyz)}" rpy="{_vec(rpy)}"/>'


def urdf_from_params(params: ArmParams | None = None) -> str:
    """URDF text of a DH arm with its inertial data.

    Parameters
    ----------
    params : ArmParams, optional
        The arm; default :func:`rrr_pin.paper_params` (the paper's Tables 1 and 2).

    Returns
    -------
    str
        URDF XML: a fixed ``base_link``, revolute joints ``joint1..jointn`` about their DH axes,
        links ``link1..linkn`` with inertials, cylinders along each link for visual and
        collision, joint limits, and a fixed frame ``ee`` at the tip of the last link.
        Every link also carries visual shapes sized from the DH lengths (see
        :data:`LINK_RADIUS_RATIO`). The frame mapping is in this module's docstring.
    """
    params = paper_params() if params is None else params
    r = LINK_RADIUS_RATIO * max(link.length for link in params.links)
    joint_shape = (f'<geometry><cylinder radius="{_dim(1.5 * r)}" length="{_dim(3.0 * r)}"/>'
                   f'</geometry><material name="joint"/>')
    out = [
        '<?xml version="1.0"?>',
        f"<!-- Generated by rrr_pin.model.urdf.urdf_from_params from a DH parameter set "
        f"({params.n} links). Do not edit: regenerate with `rrr-pin urdf`. -->",
        f"<robot name={quoteattr(params.name)}>",
        *(f'  <material name="{name}"><color rgba="{rgba}"/></material>'
          for name, rgba in _MATERIALS),
        '  <link name="base_link">',
        f'    <visual name="base">{_origin((0.0, 0.0, float(_dim(-2.5 * r))), (0.0, 0.0, 0.0))}'
        f'<geometry><box size="{_dim(6.0 * r)} {_dim(6.0 * r)} {_dim(2.0 * r)}"/></geometry>'
        f'<material name="base"/></visual>',
        "  </link>",
    ]
    parent = "base_link"
    # Placement (in the parent link frame) of the next joint, before its own offset.
    next_xyz, next_R = np.zeros(3), np.eye(3)
    for i, link in enumerate(params.links, start=1):
        joint_R = next_R @ _rot_z(link.theta_offset)
        out += [
            f'  <joint name="joint{i}" type="revolute">',
            f'    <parent link="{parent}"/>',
            f'    <child link="link{i}"/>',
            f"    {_origin(next_xyz, _rpy_of(joint_R))}",
            '    <axis xyz="0 0 1"/>',
            f'    <limit lower="{_num(link.lower)}" upper="{_num(link.upper)}" '
            f'effort="{_num(link.effort)}" velocity="{_num(link.velocity)}"/>',
            "  </joint>",
        ]
        frame_xyz, frame_R, com = dh_link_frame(link)
        Jx, Jy, Jz = link.J
        length = link.length
        # Cylinder from the joint (link-frame origin) to the next frame origin; URDF cylinders
        # lie along their local z, so tilt z by atan2(a, d) about y.
        cyl = (f'{_origin(frame_xyz / 2.0, (0.0, math.atan2(link.a, link.d), 0.0))}'
               f'<geometry><cylinder radius="{_num(r)}" length="{_num(length)}"/>'
               f"</geometry>")
        out += [
            f'  <link name="link{i}">',
            "    <inertial>",
            f"      {_origin(com, (link.alpha, 0.0, 0.0))}",
            f'      <mass value="{_num(link.mass)}"/>',
            f'      <inertia ixx="{_num(Jx)}" ixy="0" ixz="0" iyy="{_num(Jy)}" iyz="0" '
            f'izz="{_num(Jz)}"/>',
            "    </inertial>",
            f'    <visual name="link{i}_joint">{_origin((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))}'
            f"{joint_shape}</visual>",
            f'    <visual name="link{i}_body">{cyl}<material name="link"/></visual>',
            f"    <collision>{cyl}</collision>",
            "  </link>",
        ]
        parent = f"link{i}"
        next_xyz, next_R = frame_xyz, frame_R
    out += [
        '  <joint name="ee_joint" type="fixed">',
        f'    <parent link="{parent}"/>',
        '    <child link="ee"/>',
        f"    {_origin(next_xyz, _rpy_of(next_R))}",
        "  </joint>",
        '  <link name="ee">',
        f'    <visual name="tool">{_origin((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))}'
        f'<geometry><box size="{" ".join([_dim(2.0 * r)] * 3)}"/></geometry>'
        f'<material name="joint"/></visual>',
        "  </link>",
        "</robot>",
        "",
    ]
    return "\n".join(out)


def write_urdf(path: str | Path, params: ArmParams | None = None) -> Path:
    """Write :func:`urdf_from_params` to ``path`` (parent folders created); return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(urdf_from_params(params), encoding="utf-8")
    return path


def check_urdf(path: str | Path, params: ArmParams | None = None) -> bool:
    """Tell whether the file at ``path`` equals the generator's output for ``params``.

    Compares bytes, so any file (missing: ``False``; binary: ``False``) gets an answer.
    """
    path = Path(path)
    return path.is_file() and path.read_bytes() == urdf_from_params(params).encode()

r"""The 3-DOF Delta of Clavel's design: parameters, kinematics, MJCF and task path.

Leg ``i`` (``phi_i = 0, 120, 240`` deg about ``z``): actuated joint at ``R e_r(phi_i)`` with
its axis tangent to the base circle; upper arm of length ``L`` along ``e_r`` at ``qa_i = 0``,
turning downward for ``qa_i > 0``. The parallelogram forearm is modelled as one rod of length
``l`` with a universal joint at the elbow (two hinges, about the leg's tangent ``y`` then the
rod's ``z``; it cannot spin about its own axis, as a parallelogram cannot) and a spherical
joint at the platform (the loop closure). The platform is a body of mass ``m_platform`` that
only translates (three slide joints: what the parallelograms enforce); its joints are at
``P + r e_r(phi_i)``. Coordinates: per leg ``(qa_i, qe_i1, qe_i2)``, then ``(x, y, z)`` of
the platform. The loop closes iff ``|R - r| < L + l``.

Task path (the study's reference): the adept pick-and-place cycle, :data:`ADEPT_MM` (up,
across, down) and back, with quintic segments (:func:`adept_point`).

References
----------
.. [1] R. Clavel, "DELTA, a fast robot with parallel geometry", 18th ISIR, 1988.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .base import (
    DISTAL_RGBA,
    LINK_RGBA,
    Mechanism,
    MechanismError,
    check_params,
    closures,
    cylinder,
    inertial,
    num,
    quintic,
    vec,
)

__all__ = ["DeltaParams", "Delta", "DELTA", "delta_ik", "delta_fk", "delta_elbows",
           "adept_point", "ADEPT_MM"]

#: The adept cycle [mm]: up, across (along x), down.
ADEPT_MM = (25.0, 305.0, 25.0)

#: Base angles of the Delta's legs [rad].
_PHI = tuple(2.0 * math.pi * i / 3.0 for i in range(3))


@dataclass(frozen=True)
class DeltaParams:
    """A 3-DOF Delta robot (module docstring), lengths [m], masses [kg].

    Parameters
    ----------
    R : float
        Base radius: centre to actuated joint axis [m].
    r : float
        Platform radius: centre to forearm joint [m].
    L : float
        Upper arm length [m].
    l : float
        Forearm (parallelogram) length [m].
    m_upper, m_fore, m_platform : float
        Upper arm, forearm and platform (with its payload) masses [kg].
    radius : float
        Link cylinder radius [m].
    home_z : float
        Platform height of the ``home`` keyframe [m] (below the base: negative).
    name : str
        Model name.
    """

    R: float = 0.2
    r: float = 0.05
    L: float = 0.35
    l: float = 0.8
    m_upper: float = 1.0
    m_fore: float = 0.4
    m_platform: float = 0.5
    radius: float = 0.015
    home_z: float = -0.75
    name: str = "delta"

    def __post_init__(self) -> None:
        check_params(self)
        if abs(self.R - self.r) >= self.L + self.l:
            raise MechanismError(
                f"Delta loop cannot close: |R - r| = {abs(self.R - self.r):g} m is at least "
                f"L + l = {self.L + self.l:g} m (triangle inequality)")



def _leg_frame(phi: float) -> np.ndarray:
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def delta_ik(params: DeltaParams, p) -> np.ndarray:
    """Actuated angles ``qa`` [rad], shape (3,), putting the Delta's platform at ``p`` [m].

    Per leg, in its frame: ``a cos(qa) + b sin(qa) = k`` with ``a = -cx``, ``b = cz``,
    ``k = (l^2 - L^2 - |c|^2) / (2 L)``, ``c`` the platform joint relative to the actuated one;
    of the two roots, the one with the elbow outward (larger ``L cos qa``). Raises
    :class:`MechanismError` if a leg cannot reach.
    """
    p = np.asarray(p, dtype=float)
    out = []
    for i, phi in enumerate(_PHI):
        c = _leg_frame(phi).T @ p + np.array([params.r - params.R, 0.0, 0.0])
        a, b = -c[0], c[2]
        k = (params.l ** 2 - params.L ** 2 - c @ c) / (2.0 * params.L)
        rho = math.hypot(a, b)
        if rho == 0.0 or abs(k) > rho:
            raise MechanismError(f"Delta platform {p} m is out of reach of leg {i + 1}")
        base, half = math.atan2(b, a), math.acos(k / rho)
        roots = (base + half, base - half)
        out.append(max(roots, key=math.cos))
    return np.array([math.remainder(v, 2.0 * math.pi) for v in out])


def delta_elbows(params: DeltaParams, qa) -> list[np.ndarray]:
    """Elbow points [m], one shape (3,) array per leg, of actuated angles ``qa`` [rad]."""
    return [_leg_frame(phi) @ np.array([params.R + params.L * math.cos(a), 0.0,
                                        -params.L * math.sin(a)])
            for phi, a in zip(_PHI, qa, strict=True)]


def delta_fk(params: DeltaParams, qa) -> np.ndarray:
    """Platform position [m], shape (3,), of actuated angles ``qa`` [rad] (platform below).

    The intersection of three spheres of radius ``l`` about the elbows shifted by the platform
    joints' offsets ``-r e_r(phi_i)``: trilateration, the lower of the two points.
    """
    centres = [e - _leg_frame(phi) @ np.array([params.r, 0.0, 0.0])
               for e, phi in zip(delta_elbows(params, qa), _PHI, strict=True)]
    p1, p2, p3 = centres
    ex = (p2 - p1) / np.linalg.norm(p2 - p1)
    i = ex @ (p3 - p1)
    ey = p3 - p1 - i * ex
    ey /= np.linalg.norm(ey)
    ez = np.cross(ex, ey)
    d, j = np.linalg.norm(p2 - p1), ey @ (p3 - p1)
    x = d / 2.0
    y = (i * i + j * j) / (2.0 * j) - i * x / j
    z2 = params.l ** 2 - x * x - y * y
    if z2 < 0.0:
        raise MechanismError(f"Delta loop cannot close at qa = {np.asarray(qa)} rad "
                             f"(forearms short by {math.sqrt(-z2):.4g} m)")
    a, b = p1 + x * ex + y * ey + math.sqrt(z2) * ez, p1 + x * ex + y * ey - math.sqrt(z2) * ez
    return a if a[2] < b[2] else b



def adept_point(params: DeltaParams, t, period: float) -> np.ndarray:
    """Platform position [m], shape (len(t), 3), of the adept cycle at times ``t`` [s].

    Start at ``(-0.1525, 0, home_z)``; up 25 mm, across 305 mm along ``x``, down 25 mm in the
    first half period (segment times 0.2, 0.6, 0.2 of it), back the same way in the second.
    """
    up, across, _ = (v / 1000.0 for v in ADEPT_MM)
    corners = np.array([[-across / 2, 0.0, params.home_z],
                        [-across / 2, 0.0, params.home_z + up],
                        [across / 2, 0.0, params.home_z + up],
                        [across / 2, 0.0, params.home_z]])
    corners = np.vstack([corners, corners[-2::-1]])
    half = 0.5 * period
    edges = np.cumsum([0.0] + [0.2 * half, 0.6 * half, 0.2 * half] * 2)
    t = np.atleast_1d(np.asarray(t, dtype=float))
    out = np.empty((t.shape[0], 3))
    for k, tk in enumerate(t):
        i = int(np.clip(np.searchsorted(edges, tk, side="right") - 1, 0, 5))
        s = quintic(np.array((tk - edges[i]) / (edges[i + 1] - edges[i])))
        out[k] = corners[i] + s * (corners[i + 1] - corners[i])
    return out


class Delta(Mechanism):
    """The Delta (module docstring); its one instance is :data:`DELTA`."""

    name = "delta"
    title = "3-DOF Delta"
    params = DeltaParams
    path_label = "adept cycle (platform reference)"
    lengths = ("R", "r", "L", "l")

    def ik(self, params, p) -> np.ndarray:
        """:func:`delta_ik`."""
        return delta_ik(params, p)

    def fk(self, params, qa) -> np.ndarray:
        """:func:`delta_fk`."""
        return delta_fk(params, qa)

    def elbows(self, params, qa) -> list:
        """Return the three elbow points [m] (:func:`delta_elbows`)."""
        return delta_elbows(params, qa)

    def home(self, params) -> np.ndarray:
        """Return the 12 coordinates [rad, m] of the ``home`` platform point (per leg, then xyz)."""
        p = np.array([0.0, 0.0, params.home_z])
        qa = delta_ik(params, p)
        q = []
        for a, e, phi in zip(qa, delta_elbows(params, qa), _PHI, strict=True):
            joint = p + _leg_frame(phi) @ np.array([params.r, 0.0, 0.0])
            w = _leg_frame(phi).T @ (joint - e) / params.l
            # Upper arm frame: Ry(a) in the leg frame; forearm direction Ry(a) Ry(b1) Rz(b2) x.
            c, s = math.cos(a), math.sin(a)
            wl = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]]) @ w  # Ry(a)^T w
            q += [a, math.atan2(-wl[2], wl[0]), math.asin(max(-1.0, min(1.0, wl[1])))]
        return np.array(q + list(p))

    def body(self, params) -> list[str]:
        """Return the MJCF lines: three legs, the translating platform, three base motors."""
        rho = params.radius
        out = ['  <worldbody>',
               '    <!-- one jointless top-level body: the parser keeps only the first -->',
               '    <body name="base" pos="0 0 0">']
        for i, phi in enumerate(_PHI, start=1):
            c, s = math.cos(phi), math.sin(phi)
            quat = (math.cos(phi / 2.0), 0.0, 0.0, math.sin(phi / 2.0))
            out += [
                f'      <body name="upper{i}" pos="{vec((params.R * c, params.R * s, 0.0))}" '
                f'quat="{vec(quat)}">',
                f'        <joint name="qa{i}" type="hinge" axis="0 1 0"/>',
                f'        {inertial(params.m_upper, params.L, rho)}',
                f'        {cylinder(params.L, rho, LINK_RGBA)}',
                f'        <body name="forearm{i}" pos="{num(params.L)} 0 0">',
                '          <!-- universal joint: the parallelogram forearm cannot spin -->',
                f'          <joint name="qe{i}1" type="hinge" axis="0 1 0"/>',
                f'          <joint name="qe{i}2" type="hinge" axis="0 0 1"/>',
                f'          {inertial(params.m_fore, params.l, rho)}',
                f'          {cylinder(params.l, rho, DISTAL_RGBA)}',
                f'          <site name="wrist{i}" pos="{num(params.l)} 0 0"/>',
                '        </body>',
                '      </body>']
        out += ['      <body name="platform" pos="0 0 0">',
                '        <joint name="px" type="slide" axis="1 0 0"/>',
                '        <joint name="py" type="slide" axis="0 1 0"/>',
                '        <joint name="pz" type="slide" axis="0 0 1"/>',
                f'        <inertial pos="0 0 0" mass="{num(params.m_platform)}" diaginertia="'
                f'{vec((params.m_platform * params.r ** 2 / 4.0,) * 2 + (params.m_platform * params.r ** 2 / 2.0,))}"/>',  # noqa: E501
                f'        <geom type="cylinder" size="{num(params.r)} {num(rho)}" '
                f'rgba="{DISTAL_RGBA}" contype="0" conaffinity="0" mass="0"/>']
        for i, phi in enumerate(_PHI, start=1):
            out.append(f'        <site name="joint{i}" '
                       f'pos="{vec((params.r * math.cos(phi), params.r * math.sin(phi), 0.0))}"/>')
        out += ['      </body>', '    </body>', '  </worldbody>']
        return out + closures([(f"loop{i}", f"wrist{i}", f"joint{i}") for i in (1, 2, 3)],
                              ["qa1", "qa2", "qa3"])

    def task_point(self, params, t, period: float) -> np.ndarray:
        """:func:`adept_point`: the platform's adept cycle [m]."""
        return adept_point(params, t, period)

    def path_source(self, params, period: float, step: float) -> str:
        """``adept cycle 25/305/25 mm, period 2 s, IK every 5 ms``."""
        return (f"adept cycle {ADEPT_MM[0]:g}/{ADEPT_MM[1]:g}/{ADEPT_MM[2]:g} mm, period "
                f"{period:g} s, IK every {step * 1000:g} ms")


#: The Delta, as registered in :data:`rrr_pin.model.mechanisms.MECHANISMS`.
DELTA = Delta()

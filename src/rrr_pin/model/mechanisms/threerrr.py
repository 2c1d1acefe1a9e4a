r"""The 3-RRR planar parallel manipulator: parameters, kinematics, MJCF and task path.

Three RRR legs join a fixed base to a triangular platform; each leg is actuated at its base
revolute, its elbow and platform revolutes are passive; the platform has three degrees of
freedom in its plane, ``(x, z, phi)``.

Plane: the vertical ``x-z`` plane, as the 5-bar, points written ``(x, z)``. In a horizontal
plane gravity would lie along the joint axes: the bearings would carry the weight and the
reduced gravity ``G_r`` of eq. (1) would vanish. The paper's study is about gravity-loaded
dynamics (``G(q)`` in eq. (1), cancelled by the linearizing torque (8)), so here the actuators
carry the platform and the links, and an uncertain mass is a torque error to reject.

Frames and signs. Base joints ``A_i = R u(theta_i)``, ``theta_i = pi/2 + 2 pi (i - 1) / 3``
(90, 210, 330 deg: leg 1 at the top), ``u(a) = (cos a, sin a)``; every hinge axis is along
``-y``, so an angle turns ``+x`` towards ``+z`` (counter-clockwise in the ``x-z`` view).
``qa_i`` is the absolute angle of proximal link ``i`` from ``+x``, ``qp_i`` the angle of
distal link ``i`` relative to it: elbow ``E_i = A_i + l1 u(qa_i)``, distal tip
``C_i = E_i + l2 u(qa_i + qp_i)``. The platform pose is its centre ``P = (x, z)`` and its
angle ``phi`` (about ``-y``, zero at home); its joints are ``B_i = P + r u(theta_i + phi)``.
The loops are ``C_i = B_i``. Coordinates, in MJCF order:
``q = (qa1, qp1, qa2, qp2, qa3, qp3, px, pz, phi)`` [rad, m], ``(px, pz) = P``.

Working mode (inverse kinematics, closed form): every leg with its elbow on the
counter-clockwise side of the line ``A_i B_i``,

.. math::

    qa_i = \operatorname{atan2}(B_i - A_i)
           + \arccos\frac{l_1^2 + |B_i - A_i|^2 - l_2^2}{2 l_1 |B_i - A_i|},

so ``qp_i`` in ``(-pi, 0)``; the built-in home (``P = 0``, ``phi = 0``) is symmetric under a
third of a turn, every ``qp_i = -2 pi / 3``.
Assembly mode (forward kinematics, Newton on the three distal-length equations
``|B_i(x, z, phi) - E_i| = l2``): the one reached from the home pose (or a given seed); a
solution on the other side of the type-II locus (``det`` of the Jacobian of those equations
of the other sign) is refused.

Singularities. Type I (serial): a leg stretched or folded (``qp_i`` = 0 or pi,
``|B_i - A_i|`` = ``l1 + l2`` or ``|l1 - l2|``), the boundary of the IK's reach. Type II
(parallel): the three distal lines concurrent or parallel [2]_, where the rows
``(n_i, (B_i - P) x n_i)`` of the direct-kinematics Jacobian (``n_i`` the unit vector along
distal link ``i``) are dependent and the loaded chain's ``J_p`` is singular. For the built-in
dimensions, the distal lines meet at the platform centre when ``phi`` is -0.68 rad (-38.9 deg)
at ``P = 0``.

Task path (the study's reference): the platform centre on a circle of :data:`PATH_RADIUS`
through home, its centre above it, while the platform swings by ``PATH_SWING sin(2 pi s)``,
``s`` the quintic time law over one period (at rest at both ends;
:func:`platform_path`). Along it the loaded chain's ``cond(J_p)`` stays below 20 (13 at
home, against a refusal limit of 1e4) and every ``|sin qp_i|`` above 0.65: far from both
kinds of singularity (``tests/test_closed_chain.py`` checks both).

References
----------
.. [1] C. Gosselin, J. Angeles, "The optimum kinematic design of a planar three-degree-of-
   freedom parallel manipulator", ASME J. Mech. Trans. Autom. Des. 110(1), 1988.
.. [2] I. Bonev, D. Zlatanov, C. Gosselin, "Singularity analysis of 3-DOF planar parallel
   mechanisms via screw theory", ASME J. Mech. Des. 125(3), 2003.
.. [3] J.-P. Merlet, *Parallel Robots*, 2nd ed., Springer, 2006 (planar 3-RRR kinematics).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

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

__all__ = ["ThreeRRRParams", "ThreeRRR", "THREERRR", "threerrr_ik", "threerrr_fk",
           "threerrr_elbows", "platform_path", "PATH_RADIUS", "PATH_SWING"]

#: Radius [m] of the platform centre's task circle.
PATH_RADIUS = 0.03

#: Amplitude [rad] of the platform's rotation along the task path.
PATH_SWING = 0.1

#: Angles [rad] of the base and platform joints, ``theta_i`` (module docstring).
_THETA = tuple(0.5 * math.pi + 2.0 * math.pi * i / 3.0 for i in range(3))


@dataclass(frozen=True)
class ThreeRRRParams:
    """A 3-RRR planar parallel manipulator in the ``x-z`` plane (module docstring).

    Parameters
    ----------
    R : float
        Base radius: centre to actuated joint [m].
    r : float
        Platform radius: platform centre to platform joint [m].
    l1, l2 : float
        Proximal and distal link lengths [m].
    m1, m2 : float
        Proximal and distal link masses [kg] (uniform cylinders).
    m_platform : float
        Platform mass [kg], its centre of mass at the platform centre.
    I_platform : float
        Platform moment of inertia about its centre, axis ``y`` [kg m^2].
    radius : float
        Link cylinder radius [m] (inertia and drawing).
    home_x, home_z : float
        Platform centre of the ``home`` keyframe [m].
    home_phi : float
        Platform angle of the ``home`` keyframe [rad].
    name : str
        Model name.

    Raises
    ------
    MechanismError
        A leg that cannot reach its platform joint at the home pose.
    """

    R: float = 0.3
    r: float = 0.1
    l1: float = 0.2
    l2: float = 0.2
    m1: float = 0.5
    m2: float = 0.3
    m_platform: float = 0.5
    I_platform: float = field(default=2.5e-3, metadata={"unit": "kg m^2"})
    radius: float = 0.01
    home_x: float = 0.0
    home_z: float = 0.0
    home_phi: float = field(default=0.0, metadata={"unit": "rad"})
    name: str = "threerrr"

    def __post_init__(self) -> None:
        check_params(self)
        threerrr_ik(self, (self.home_x, self.home_z, self.home_phi))


def _u(a: float) -> np.ndarray:
    return np.array([math.cos(a), math.sin(a)])


def _platform_joints(params: ThreeRRRParams, pose) -> list[np.ndarray]:
    """Platform joints ``B_i`` (``x, z``) [m] of the pose ``(x, z, phi)`` [m, m, rad]."""
    centre = np.array([pose[0], pose[1]])
    return [centre + params.r * _u(th + pose[2]) for th in _THETA]


def threerrr_ik(params: ThreeRRRParams, pose) -> np.ndarray:
    """Actuated angles ``(qa1, qa2, qa3)`` [rad] of the platform pose ``(x, z, phi)``.

    Closed form, in the working mode of the module docstring:
    ``qa_i = theta_i - pi + delta_i + beta_i``, ``delta_i`` in ``(-pi, pi]`` the angle of
    ``B_i - A_i`` from the inward radial direction ``theta_i + pi``, ``beta_i`` the arccos:
    continuous wherever the platform joint is not straight outward of its base joint (home
    angles ``-pi/6, pi/2, 7 pi/6`` for the built-in).

    Parameters
    ----------
    params : ThreeRRRParams
    pose : array-like, shape (3,)
        Platform centre ``(x, z)`` [m] and angle ``phi`` [rad].

    Returns
    -------
    ndarray, shape (3,)

    Raises
    ------
    MechanismError
        A leg out of reach (``|B_i - A_i|`` outside ``[|l1 - l2|, l1 + l2]``).
    """
    pose = tuple(float(v) for v in pose)
    out = []
    for i, (th, b) in enumerate(zip(_THETA, _platform_joints(params, pose), strict=True)):
        d = b - params.R * _u(th)
        rho = math.hypot(d[0], d[1])
        c = (params.l1 ** 2 + rho ** 2 - params.l2 ** 2) / (2.0 * params.l1 * rho) if rho else 2
        if not -1.0 <= c <= 1.0:
            raise MechanismError(
                f"3-RRR pose (x, z, phi) = ({pose[0]:g} m, {pose[1]:g} m, {pose[2]:g} rad) is "
                f"out of reach of leg {i + 1} ({rho:.4g} m from its base joint, reach "
                f"[{abs(params.l1 - params.l2):g}, {params.l1 + params.l2:g}] m)")
        delta = math.remainder(math.atan2(d[1], d[0]) - th - math.pi, 2.0 * math.pi)
        out.append(th - math.pi + delta + math.acos(c))
    return np.array(out)


def threerrr_elbows(params: ThreeRRRParams, qa) -> list[np.ndarray]:
    """Elbow points ``E_i`` (``x, z``) [m], one shape (2,) array per leg, of ``qa`` [rad]."""
    return [params.R * _u(th) + params.l1 * _u(a) for th, a in zip(_THETA, qa, strict=True)]


def _distal_equations(params: ThreeRRRParams, elbows, pose):
    """Gaps ``|B_i - E_i| - l2`` [m], shape (3,), and their Jacobian in the pose, (3, 3)."""
    g, rows = np.empty(3), np.empty((3, 3))
    for i, (b, e) in enumerate(zip(_platform_joints(params, pose), elbows, strict=True)):
        w = b - e
        n = w / math.hypot(w[0], w[1])
        arm = b - np.array([pose[0], pose[1]])
        g[i] = math.hypot(w[0], w[1]) - params.l2
        rows[i] = (n[0], n[1], arm[0] * n[1] - arm[1] * n[0])
    return g, rows


def threerrr_fk(params: ThreeRRRParams, qa, seed=None, *, tol: float = 1e-14,
                max_iter: int = 50) -> np.ndarray:
    r"""Platform pose ``(x, z, phi)`` [m, m, rad] of the actuated angles ``qa`` [rad].

    Newton on the distal-length equations ``|B_i(x, z, phi) - E_i| = l2`` (the elbows
    ``E_i`` from ``qa``), whose Jacobian rows are ``(n_i, (B_i - P) x n_i)``:

    .. math::

        p \leftarrow p - \left(\frac{\partial g}{\partial p}\right)^{-1} g(p), \quad
        g_i(p) = |B_i(p) - E_i| - l_2.

    Parameters
    ----------
    params : ThreeRRRParams
    qa : array-like, shape (3,)
        Actuated angles [rad].
    seed : array-like, shape (3,), optional
        Starting pose [m, m, rad]; default the home pose (its assembly mode).
    tol : float
        Largest ``|g_i|`` accepted [m].
    max_iter : int
        Newton iterations before :class:`MechanismError`.

    Returns
    -------
    ndarray, shape (3,)

    Raises
    ------
    MechanismError
        No convergence (the loop cannot close at ``qa``), a singular Jacobian on the way
        (type-II), or a solution in another assembly mode than the seed's (``det`` of the
        Jacobian changed sign).
    """
    elbows = threerrr_elbows(params, np.asarray(qa, dtype=float))
    p = np.array([params.home_x, params.home_z, params.home_phi] if seed is None else seed,
                 dtype=float)
    sign = math.copysign(1.0, np.linalg.det(_distal_equations(params, elbows, p)[1]))
    for _ in range(max_iter):
        g, D = _distal_equations(params, elbows, p)
        if float(np.max(np.abs(g))) <= tol:
            if np.linalg.det(D) * sign <= 0.0:
                raise MechanismError(f"3-RRR forward kinematics at qa = {np.asarray(qa)} rad "
                                     f"reached another assembly mode than the seed's (the "
                                     f"distal lines' determinant changed sign)")
            return p
        try:
            p = p - np.linalg.solve(D, g)
        except np.linalg.LinAlgError:
            raise MechanismError(f"3-RRR forward kinematics at qa = {np.asarray(qa)} rad met a "
                                 f"type-II singularity (distal lines concurrent)") from None
    raise MechanismError(f"3-RRR loop cannot close at qa = {np.asarray(qa)} rad (Newton left "
                         f"a distal-length gap of {float(np.max(np.abs(g))):.3g} m after "
                         f"{max_iter} iterations)")


def platform_path(params: ThreeRRRParams, t, period: float, radius: float = PATH_RADIUS,
                  swing: float = PATH_SWING) -> np.ndarray:
    """Platform poses ``(x, z, phi)`` [m, m, rad], shape (len(t), 3), of the task path.

    The centre on a circle of ``radius`` [m] through home, its centre ``radius`` above it, the
    angle ``home_phi + swing sin(a)`` [rad], ``a = 2 pi s``, ``s`` the quintic time law of
    ``t / period`` (``t`` [s]): once around in ``period``, at rest at both ends.
    """
    s = quintic(np.atleast_1d(np.asarray(t, dtype=float)) / period)
    a = 2.0 * math.pi * s
    return np.column_stack([params.home_x + radius * np.sin(a),
                            params.home_z + radius - radius * np.cos(a),
                            params.home_phi + swing * np.sin(a)])


class ThreeRRR(Mechanism):
    """The 3-RRR (module docstring); its one instance is :data:`THREERRR`."""

    name = "threerrr"
    title = "3-RRR planar parallel manipulator"
    params = ThreeRRRParams
    lengths = ("R", "r", "l1", "l2")
    inertias = ("I_platform",)
    path_label = "platform circle (reference)"

    def ik(self, params, p) -> np.ndarray:
        """:func:`threerrr_ik`."""
        return threerrr_ik(params, p)

    def fk(self, params, qa) -> np.ndarray:
        """:func:`threerrr_fk` from the home pose."""
        return threerrr_fk(params, qa)

    def elbows(self, params, qa) -> list:
        """Return the three elbow points ``(x, z)`` [m] (:func:`threerrr_elbows`)."""
        return threerrr_elbows(params, qa)

    def home(self, params) -> np.ndarray:
        """Return ``(qa1, qp1, qa2, qp2, qa3, qp3, x, z, phi)`` [rad, m] of the home pose."""
        pose = (params.home_x, params.home_z, params.home_phi)
        qa = threerrr_ik(params, pose)
        q = []
        for a, e, b in zip(qa, threerrr_elbows(params, qa), _platform_joints(params, pose),
                           strict=True):
            q += [a, math.remainder(math.atan2(b[1] - e[1], b[0] - e[0]) - a, 2.0 * math.pi)]
        return np.array(q + list(pose))

    def body(self, params) -> list[str]:
        """Return the MJCF lines: three legs, the planar platform, three base motors."""
        rho = params.radius
        out = ['  <worldbody>',
               '    <!-- one jointless top-level body: the parser keeps only the first -->',
               '    <body name="base" pos="0 0 0">']
        for i, th in enumerate(_THETA, start=1):
            a = params.R * _u(th)
            out += [
                f'      <body name="proximal{i}" pos="{vec((a[0], 0.0, a[1]))}">',
                f'        <joint name="qa{i}" type="hinge" axis="0 -1 0"/>',
                f'        {inertial(params.m1, params.l1, rho)}',
                f'        {cylinder(params.l1, rho, LINK_RGBA)}',
                f'        <body name="distal{i}" pos="{num(params.l1)} 0 0">',
                f'          <joint name="qp{i}" type="hinge" axis="0 -1 0"/>',
                f'          {inertial(params.m2, params.l2, rho)}',
                f'          {cylinder(params.l2, rho, DISTAL_RGBA)}',
                f'          <site name="tip{i}" pos="{num(params.l2)} 0 0"/>',
                '        </body>',
                '      </body>']
        m, inertia = params.m_platform, params.I_platform
        corners = [params.r * _u(th) for th in _THETA]
        out += ['      <!-- the platform: slides along x and z, then its angle phi -->',
                '      <body name="platform" pos="0 0 0">',
                '        <joint name="px" type="slide" axis="1 0 0"/>',
                '        <joint name="pz" type="slide" axis="0 0 1"/>',
                '        <joint name="phi" type="hinge" axis="0 -1 0"/>',
                '        <!-- a thin plate in the x-z plane: Ixx = Izz = Iyy / 2 -->',
                f'        <inertial pos="0 0 0" mass="{num(m)}" '
                f'diaginertia="{vec((inertia / 2.0, inertia, inertia / 2.0))}"/>']
        for k in range(3):
            p, q = corners[k], corners[(k + 1) % 3]
            out.append(f'        <geom type="cylinder" fromto="{vec((p[0], 0.0, p[1]))} '
                       f'{vec((q[0], 0.0, q[1]))}" size="{num(rho)}" rgba="{DISTAL_RGBA}" '
                       f'contype="0" conaffinity="0" mass="0"/>')
        out += [f'        <site name="joint{i}" pos="{vec((c[0], 0.0, c[1]))}"/>'
                for i, c in enumerate(corners, start=1)]
        out += ['      </body>', '    </body>', '  </worldbody>']
        return out + closures([(f"loop{i}", f"tip{i}", f"joint{i}") for i in (1, 2, 3)],
                              ["qa1", "qa2", "qa3"])

    def task_point(self, params, t, period: float) -> np.ndarray:
        """:func:`platform_path`: the platform poses ``(x, z, phi)`` [m, m, rad]."""
        return platform_path(params, t, period)

    def path_source(self, params, period: float, step: float) -> str:
        """``platform circle of radius 30 mm through home, swing 0.1 rad, period 2 s, ...``."""
        return (f"platform circle of radius {PATH_RADIUS * 1000:g} mm through home, swing "
                f"{PATH_SWING:g} rad, period {period:g} s, IK every {step * 1000:g} ms")

    def world_points(self, params, points) -> np.ndarray:
        """Platform centres of poses ``(x, z, phi)`` as ``(x, 0, z)`` [m], shape (N, 3)."""
        points = np.asarray(points, dtype=float)
        return np.column_stack([points[:, 0], np.zeros(len(points)), points[:, 1]])


#: The 3-RRR, as registered in :data:`rrr_pin.model.mechanisms.MECHANISMS`.
THREERRR = ThreeRRR()

r"""Parallel mechanisms: a planar 5-bar and a 3-DOF Delta, as MJCF generated from parameters.

URDF cannot express a kinematic loop; MJCF can (``<equality><connect site1 site2/>``), and
Pinocchio reads it with ``buildModelAndLegacyConstraintsFromMJCF`` (the loop becomes a
``CONTACT_3D`` :class:`pinocchio.RigidConstraintModel` between the two sites). Each mechanism
is one frozen parameter set (:class:`FiveBarParams`, :class:`DeltaParams`), one generator
(:func:`mjcf_from_params`), and closed-form kinematics written from the geometry alone (no
Pinocchio), which the tests use as the independent reference of the loaded model.

Conventions: SI units, gravity along ``-z``. Every link is a uniform solid cylinder of radius
``radius`` along its local ``x`` (centre of mass at mid-length, ``Ixx = m rho^2 / 2``,
``Iyy = Izz = m (l^2 / 12 + rho^2 / 4)``). The generated file holds a ``home`` keyframe: a
closed configuration (from the closed-form inverse kinematics of ``home``), and one
``<motor>`` per actuated joint, which is how the loader knows the actuated joints.

Five-bar (DexTAR class: two proximal and two distal links, actuated at the base)
--------------------------------------------------------------------------------
In the vertical ``x-z`` plane. Base joints ``A1 = (-d/2, 0)``, ``A2 = (d/2, 0)`` (in ``x, z``),
axes along ``-y``, so an angle turns ``+x`` towards ``+z``. Coordinates
``q = (qa1, qp1, qa2, qp2)``: ``qa_i`` the absolute angle of proximal link ``i`` from ``+x``,
``qp_i`` the angle of distal link ``i`` relative to it. Elbows ``E_i = A_i + l1 u(qa_i)``,
tip ``P = E_i + l2 u(qa_i + qp_i)`` with ``u(a) = (cos a, sin a)``. Working mode: the left
elbow turned outward (``qa1 = atan2(P - A1) + beta_1``), the right one too
(``qa2 = atan2(P - A2) - beta_2``); assembly mode: the tip above the line ``E1 E2``. The loop
closes iff the elbows are at most ``2 l2`` apart; it is a type-II (parallel) singularity when
the distal links are aligned.

Delta (Clavel: three actuated base revolutes, three parallelogram forearms)
---------------------------------------------------------------------------
Leg ``i`` (``phi_i = 0, 120, 240`` deg about ``z``): actuated joint at ``R e_r(phi_i)`` with
its axis tangent to the base circle; upper arm of length ``L`` along ``e_r`` at ``qa_i = 0``,
turning downward for ``qa_i > 0``. The parallelogram forearm is modelled as one rod of length
``l`` with a universal joint at the elbow (two hinges, about the leg's tangent ``y`` then the
rod's ``z``; it cannot spin about its own axis, as a parallelogram cannot) and a spherical
joint at the platform (the loop closure). The platform is a body of mass ``m_platform`` that
only translates (three slide joints: what the parallelograms enforce); its joints are at
``P + r e_r(phi_i)``. Coordinates: per leg ``(qa_i, qe_i1, qe_i2)``, then ``(x, y, z)`` of
the platform. The loop closes iff ``|R - r| < L + l``.

References
----------
.. [1] R. Clavel, "DELTA, a fast robot with parallel geometry", 18th ISIR, 1988.
.. [2] L. Campos, F. Bourbonnais, I. Bonev, P. Bigras, "Development of a five-bar parallel
   robot with large workspace", ASME IDETC 2010 (the DexTAR).
.. [3] MuJoCo XML reference, ``equality/connect`` and ``keyframe``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from ..validation import check_positive, check_real

__all__ = ["FiveBarParams", "DeltaParams", "MechanismError", "mjcf_from_params", "write_mjcf",
           "check_mjcf", "mechanism_params", "MECHANISMS", "fivebar_ik", "fivebar_fk",
           "delta_ik", "delta_fk", "home_configuration", "perturb_mechanism"]


class MechanismError(ValueError):
    """A mechanism that cannot be built or a point it cannot reach (reason in the message)."""


def _rod(m: float, length: float, rho: float) -> tuple[float, float, float]:
    """Principal inertias [kg m^2] of a solid cylinder along x: ``(Ixx, Iyy, Izz)``."""
    axial = 0.5 * m * rho * rho
    side = m * (length * length / 12.0 + rho * rho / 4.0)
    return axial, side, side


def _checked(params) -> None:
    for f in fields(params):
        if f.name == "name":
            continue
        value = getattr(params, f.name)
        if f.name.startswith("home"):
            check_real(f.name, value, unit="m")
        else:
            check_positive(f.name, value, unit="kg" if f.name.startswith("m") else "m")


@dataclass(frozen=True)
class FiveBarParams:
    """A planar 5-bar in the ``x-z`` plane (module docstring), lengths [m], masses [kg].

    Parameters
    ----------
    d : float
        Distance between the two actuated base joints [m].
    l1, l2 : float
        Proximal and distal link lengths [m].
    m1, m2 : float
        Proximal and distal link masses [kg].
    radius : float
        Link cylinder radius [m] (inertia and drawing).
    home_x, home_z : float
        Tip position of the ``home`` keyframe [m].
    name : str
        Model name.
    """

    d: float = 0.12
    l1: float = 0.23
    l2: float = 0.23
    m1: float = 0.5
    m2: float = 0.3
    radius: float = 0.01
    home_x: float = 0.0
    home_z: float = 0.32
    name: str = "fivebar"

    def __post_init__(self) -> None:
        _checked(self)
        if self.d >= 2.0 * (self.l1 + self.l2):
            raise MechanismError(
                f"5-bar loop cannot close: base distance d = {self.d:g} m is at least "
                f"2 (l1 + l2) = {2.0 * (self.l1 + self.l2):g} m (triangle inequality)")


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
        _checked(self)
        if abs(self.R - self.r) >= self.L + self.l:
            raise MechanismError(
                f"Delta loop cannot close: |R - r| = {abs(self.R - self.r):g} m is at least "
                f"L + l = {self.L + self.l:g} m (triangle inequality)")


#: Built-in mechanisms by name, with their default parameter sets.
MECHANISMS = {"fivebar": FiveBarParams, "delta": DeltaParams}

#: Base angles of the Delta's legs [rad].
_PHI = tuple(2.0 * math.pi * i / 3.0 for i in range(3))


def mechanism_params(name):
    """Return the parameter set of a mechanism.

    A built-in's defaults by name (``"fivebar"`` or ``"delta"``), or ``name`` itself when it
    already is a :class:`FiveBarParams` or :class:`DeltaParams` (your own dimensions and masses).
    """
    if isinstance(name, (FiveBarParams, DeltaParams)):
        return name
    if name not in MECHANISMS:
        raise ValueError(f"unknown mechanism {name!r}: one of {', '.join(MECHANISMS)}")
    return MECHANISMS[name]()


# --- closed-form kinematics (independent of Pinocchio) ----------------------------------------

def fivebar_ik(params: FiveBarParams, p) -> np.ndarray:
    """Actuated angles ``(qa1, qa2)`` [rad] putting the 5-bar's tip at ``p = (x, z)`` [m].

    Working mode of the module docstring. Raises :class:`MechanismError` if ``p`` is out of
    reach of a leg (``|P - A_i|`` outside ``[|l1 - l2|, l1 + l2]``).
    """
    x, z = (float(v) for v in p)
    out = []
    for sign, ax in ((1.0, -0.5 * params.d), (-1.0, 0.5 * params.d)):
        cx, cz = x - ax, z
        rho = math.hypot(cx, cz)
        c = (params.l1 ** 2 + rho ** 2 - params.l2 ** 2) / (2.0 * params.l1 * rho) if rho else 2
        if not -1.0 <= c <= 1.0:
            raise MechanismError(f"5-bar tip ({x:g}, {z:g}) m is out of reach of the "
                                 f"{'left' if sign > 0 else 'right'} leg ({rho:.4g} m from "
                                 f"its base joint, reach [{abs(params.l1 - params.l2):g}, "
                                 f"{params.l1 + params.l2:g}] m)")
        out.append(math.atan2(cz, cx) + sign * math.acos(c))
    return np.array(out)


def fivebar_elbows(params: FiveBarParams, qa) -> tuple[np.ndarray, np.ndarray]:
    """Elbow points ``E1, E2`` (``x, z``) [m] of actuated angles ``qa`` [rad]."""
    e1 = np.array([-0.5 * params.d + params.l1 * math.cos(qa[0]), params.l1 * math.sin(qa[0])])
    e2 = np.array([0.5 * params.d + params.l1 * math.cos(qa[1]), params.l1 * math.sin(qa[1])])
    return e1, e2


def fivebar_fk(params: FiveBarParams, qa) -> np.ndarray:
    """Tip ``(x, z)`` [m] of actuated angles ``qa = (qa1, qa2)`` [rad] (assembly mode: up).

    The intersection of the circles of radius ``l2`` about the elbows; :class:`MechanismError`
    if the elbows are more than ``2 l2`` apart (the loop cannot close) or coincide.
    """
    e1, e2 = fivebar_elbows(params, qa)
    w = e2 - e1
    dist = float(np.hypot(*w))
    if not 0.0 < dist <= 2.0 * params.l2:
        raise MechanismError(f"5-bar loop cannot close at qa = {np.asarray(qa)} rad: elbows "
                             f"{dist:.6g} m apart, distal links reach 2 l2 = "
                             f"{2.0 * params.l2:g} m")
    h = math.sqrt(max(params.l2 ** 2 - 0.25 * dist * dist, 0.0))
    return 0.5 * (e1 + e2) + h * np.array([-w[1], w[0]]) / dist


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


def home_configuration(params) -> np.ndarray:
    """Return the closed configuration ``q`` of the ``home`` point (module docstring).

    Shape (4,) for the 5-bar, (12,) for the Delta [rad, m].
    """
    if isinstance(params, FiveBarParams):
        p = np.array([params.home_x, params.home_z])
        qa = fivebar_ik(params, p)
        q = []
        for a, e in zip(qa, fivebar_elbows(params, qa), strict=True):
            q += [a, math.remainder(math.atan2(p[1] - e[1], p[0] - e[0]) - a, 2.0 * math.pi)]
        return np.array(q)
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


# --- MJCF generation --------------------------------------------------------------------------

def _num(x: float) -> str:
    x = float(x)
    return "0" if x == 0.0 else repr(x)


def _vec(v) -> str:
    return " ".join(_num(x) for x in v)


def _inertial(m: float, length: float, rho: float) -> str:
    return (f'<inertial pos="{_num(length / 2.0)} 0 0" mass="{_num(m)}" '
            f'diaginertia="{_vec(_rod(m, length, rho))}"/>')


def _capsule(length: float, rho: float, rgba: str) -> str:
    return (f'<geom type="cylinder" fromto="0 0 0 {_num(length)} 0 0" size="{_num(rho)}" '
            f'rgba="{rgba}" contype="0" conaffinity="0" mass="0"/>')


_LINK, _DIST = "0.95 0.55 0.15 1", "0.2 0.22 0.28 1"


def _fivebar(params: FiveBarParams) -> list[str]:
    rho = params.radius
    out = ['  <worldbody>',
           '    <!-- one jointless top-level body: the parser keeps only the first -->',
           '    <body name="base" pos="0 0 0">']
    for side, sign in (("1", -1.0), ("2", 1.0)):
        out += [
            f'      <body name="proximal{side}" pos="{_num(sign * params.d / 2.0)} 0 0">',
            f'        <joint name="qa{side}" type="hinge" axis="0 -1 0"/>',
            f'        {_inertial(params.m1, params.l1, rho)}',
            f'        {_capsule(params.l1, rho, _LINK)}',
            f'        <body name="distal{side}" pos="{_num(params.l1)} 0 0">',
            f'          <joint name="qp{side}" type="hinge" axis="0 -1 0"/>',
            f'          {_inertial(params.m2, params.l2, rho)}',
            f'          {_capsule(params.l2, rho, _DIST)}',
            f'          <site name="tip{side}" pos="{_num(params.l2)} 0 0"/>',
            '        </body>',
            '      </body>']
    out += ['    </body>', '  </worldbody>', '  <equality>',
            '    <connect name="loop" site1="tip1" site2="tip2"/>', '  </equality>',
            '  <actuator>', '    <motor name="motor1" joint="qa1"/>',
            '    <motor name="motor2" joint="qa2"/>', '  </actuator>']
    return out


def _delta(params: DeltaParams) -> list[str]:
    rho = params.radius
    out = ['  <worldbody>',
           '    <!-- one jointless top-level body: the parser keeps only the first -->',
           '    <body name="base" pos="0 0 0">']
    for i, phi in enumerate(_PHI, start=1):
        c, s = math.cos(phi), math.sin(phi)
        quat = (math.cos(phi / 2.0), 0.0, 0.0, math.sin(phi / 2.0))
        out += [
            f'      <body name="upper{i}" pos="{_vec((params.R * c, params.R * s, 0.0))}" '
            f'quat="{_vec(quat)}">',
            f'        <joint name="qa{i}" type="hinge" axis="0 1 0"/>',
            f'        {_inertial(params.m_upper, params.L, rho)}',
            f'        {_capsule(params.L, rho, _LINK)}',
            f'        <body name="forearm{i}" pos="{_num(params.L)} 0 0">',
            '          <!-- universal joint: the parallelogram forearm cannot spin -->',
            f'          <joint name="qe{i}1" type="hinge" axis="0 1 0"/>',
            f'          <joint name="qe{i}2" type="hinge" axis="0 0 1"/>',
            f'          {_inertial(params.m_fore, params.l, rho)}',
            f'          {_capsule(params.l, rho, _DIST)}',
            f'          <site name="wrist{i}" pos="{_num(params.l)} 0 0"/>',
            '        </body>',
            '      </body>']
    out += ['      <body name="platform" pos="0 0 0">',
            '        <joint name="px" type="slide" axis="1 0 0"/>',
            '        <joint name="py" type="slide" axis="0 1 0"/>',
            '        <joint name="pz" type="slide" axis="0 0 1"/>',
            f'        <inertial pos="0 0 0" mass="{_num(params.m_platform)}" diaginertia="'
            f'{_vec((params.m_platform * params.r ** 2 / 4.0,) * 2 + (params.m_platform * params.r ** 2 / 2.0,))}"/>',  # noqa: E501
            f'        <geom type="cylinder" size="{_num(params.r)} {_num(rho)}" '
            f'rgba="{_DIST}" contype="0" conaffinity="0" mass="0"/>']
    for i, phi in enumerate(_PHI, start=1):
        out.append(f'        <site name="joint{i}" '
                   f'pos="{_vec((params.r * math.cos(phi), params.r * math.sin(phi), 0.0))}"/>')
    out += ['      </body>', '    </body>', '  </worldbody>', '  <equality>']
    out += [f'    <connect name="loop{i}" site1="wrist{i}" site2="joint{i}"/>'
            for i in (1, 2, 3)]
    out += ['  </equality>', '  <actuator>']
    out += [f'    <motor name="motor{i}" joint="qa{i}"/>' for i in (1, 2, 3)]
    out += ['  </actuator>']
    return out


def mjcf_from_params(params) -> str:
    """MJCF text of a 5-bar or a Delta (module docstring for frames and coordinates).

    Parameters
    ----------
    params : FiveBarParams or DeltaParams
        The mechanism.

    Returns
    -------
    str
        Deterministic MJCF (shortest round-trip numbers): the bodies in one jointless top-level
        body, the loop closures as ``<connect site1 site2>``, one ``<motor>`` per actuated
        joint and a ``home`` keyframe holding a closed configuration.
    """
    if isinstance(params, FiveBarParams):
        body, what = _fivebar(params), "planar 5-bar"
    elif isinstance(params, DeltaParams):
        body, what = _delta(params), "3-DOF Delta"
    else:
        raise TypeError(f"params must be FiveBarParams or DeltaParams, got "
                        f"{type(params).__name__}")
    values = {f.name: getattr(params, f.name) for f in fields(params) if f.name != "name"}
    out = ['<?xml version="1.0"?>',
           f"<!-- Generated by rrr_pin.model.mechanisms.mjcf_from_params ({what}). Do not edit: "
           f"regenerate with `rrr-pin mjcf {params.name}`. -->",
           f"<!-- parameters: {', '.join(f'{k}={_num(v)}' for k, v in values.items())} -->",
           f'<mujoco model="{params.name}">',
           '  <compiler angle="radian"/>',
           '  <option gravity="0 0 -9.8"/>',
           *body,
           '  <keyframe>',
           f'    <key name="home" qpos="{_vec(home_configuration(params))}"/>',
           '  </keyframe>',
           '</mujoco>', '']
    return "\n".join(out)


def write_mjcf(path: str | Path, params) -> Path:
    """Write :func:`mjcf_from_params` to ``path`` (parent folders created); return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(mjcf_from_params(params), encoding="utf-8")
    return path


def check_mjcf(path: str | Path, params) -> bool:
    """Tell whether the file at ``path`` equals the generator's output for ``params`` (bytes)."""
    path = Path(path)
    return path.is_file() and path.read_bytes() == mjcf_from_params(params).encode()



#: Length fields of each parameter set (perturbed by the length tolerance); the masses
#: ``m*`` take the inertia tolerance, and the rods' moments follow from mass and length.
_LENGTHS = {FiveBarParams: ("d", "l1", "l2"), DeltaParams: ("R", "r", "L", "l")}


def perturb_mechanism(params, rng: np.random.Generator, inertia: float = 0.2,
                      length: float = 0.05, attempts: int = 100):
    """Draw an uncertain mechanism: masses and lengths scaled by uniform factors.

    As the paper's uncertain RRR (sec. 5): every mass by a factor in ``[1 - inertia,
    1 + inertia]`` and every length in ``[1 - length, 1 + length]``; the rods' moments of
    inertia follow (uniform cylinders). A draw whose loop cannot close, or whose ``home``
    point it cannot reach, is drawn again (at most ``attempts`` times), so the plant is always
    closable.

    Parameters
    ----------
    params : FiveBarParams or DeltaParams
        Nominal parameters.
    rng : numpy.random.Generator
        Seeded generator.
    inertia, length : float
        Relative tolerances, in [0, 1).

    Returns
    -------
    params : FiveBarParams or DeltaParams
        The perturbed, closable set.
    factors : dict
        Field name -> factor drawn.
    """
    names = [f.name for f in fields(params) if f.name.startswith("m")]
    names += list(_LENGTHS[type(params)])
    for _ in range(attempts):
        factors = {n: float(rng.uniform(1.0 - (length if n in _LENGTHS[type(params)]
                                               else inertia),
                                        1.0 + (length if n in _LENGTHS[type(params)]
                                               else inertia)))
                   for n in names}
        try:
            out = replace(params, **{n: getattr(params, n) * f for n, f in factors.items()})
            home_configuration(out)
        except MechanismError:
            continue
        return out, factors
    raise MechanismError(f"no closable draw of {params.name} in {attempts} attempts "
                         f"(tolerances inertia {inertia:g}, length {length:g})")

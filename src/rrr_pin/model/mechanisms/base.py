r"""What every built-in mechanism is: the :class:`Mechanism` base and the MJCF pieces it uses.

A mechanism kind is one module of :mod:`rrr_pin.model.mechanisms` holding a frozen parameter
set (lengths [m], masses [kg], ``home_*`` the home point, ``name``), closed-form kinematics
written from the geometry alone (no Pinocchio: the tests' independent reference), its MJCF body
and its task path, gathered in one :class:`Mechanism` instance registered by name in
:data:`rrr_pin.model.mechanisms.MECHANISMS`. Everything generic lives here, once: the MJCF
file around the body (:meth:`Mechanism.mjcf`), the perturbation of masses and lengths
(:meth:`Mechanism.perturb`) and the task path as actuated-angle waypoints
(:meth:`Mechanism.waypoints`).

Conventions: SI units, gravity along ``-z``. Every link is a uniform solid cylinder of radius
``radius`` along its local ``x`` (centre of mass at mid-length, ``Ixx = m rho^2 / 2``,
``Iyy = Izz = m (l^2 / 12 + rho^2 / 4)``). The generated file holds a ``home`` keyframe: a
closed configuration (from the closed-form inverse kinematics of ``home``), and one
``<motor>`` per actuated joint, which is how the loader knows the actuated joints.
"""

from __future__ import annotations

from dataclasses import fields, replace
from typing import ClassVar

import numpy as np

from ...validation import check_positive, check_real

__all__ = ["Mechanism", "MechanismError", "rod_inertia", "check_params", "quintic", "num",
           "vec", "inertial", "cylinder", "LINK_RGBA", "DISTAL_RGBA"]


class MechanismError(ValueError):
    """A mechanism that cannot be built or a point it cannot reach (reason in the message)."""


def rod_inertia(m: float, length: float, rho: float) -> tuple[float, float, float]:
    """Principal inertias [kg m^2] of a solid cylinder along x: ``(Ixx, Iyy, Izz)``."""
    axial = 0.5 * m * rho * rho
    side = m * (length * length / 12.0 + rho * rho / 4.0)
    return axial, side, side



def check_params(params) -> None:
    """Check every field of a parameter set: ``home*`` real [m], the others > 0 [kg or m].

    A field's ``metadata["unit"]`` (``dataclasses.field``), when given, is the unit its
    message names instead (``"rad"`` for an angle, ``"kg m^2"`` for a moment of inertia).
    """
    for f in fields(params):
        if f.name == "name":
            continue
        value = getattr(params, f.name)
        if f.name.startswith("home"):
            check_real(f.name, value, unit=f.metadata.get("unit", "m"))
        else:
            check_positive(f.name, value, unit=f.metadata.get(
                "unit", "kg" if f.name.startswith("m") else "m"))



def quintic(s: np.ndarray) -> np.ndarray:
    """Return the rest-to-rest quintic time law ``s^3 (10 - 15 s + 6 s^2)``, ``s`` in [0, 1]."""
    s = np.clip(s, 0.0, 1.0)
    return s ** 3 * (10.0 - 15.0 * s + 6.0 * s * s)


#: Decimals of the ``home`` keyframe [rad, m]: the closed form's last bits (1e-17 where it is
#: 0) differ between libm and NumPy builds, and a committed file must equal the generator's
#: output everywhere; the loader closes the loop from there (to ``closed_chain.CLOSURE_TOL``).
HOME_DIGITS = 12


def num(x: float) -> str:
    """Return ``x`` as MJCF writes it: ``0`` or its shortest round-trip repr."""
    x = float(x)
    return "0" if x == 0.0 else repr(x)


def vec(v) -> str:
    """Return a vector as MJCF writes it: numbers (:func:`num`) joined by spaces."""
    return " ".join(num(x) for x in v)


def inertial(m: float, length: float, rho: float) -> str:
    """Return the ``<inertial>`` of a uniform rod along ``x`` (mass [kg], length, radius [m])."""
    return (f'<inertial pos="{num(length / 2.0)} 0 0" mass="{num(m)}" '
            f'diaginertia="{vec(rod_inertia(m, length, rho))}"/>')


def cylinder(length: float, rho: float, rgba: str) -> str:
    """Return a massless, collision-free ``<geom>`` cylinder along ``x`` for drawing."""
    return (f'<geom type="cylinder" fromto="0 0 0 {num(length)} 0 0" size="{num(rho)}" '
            f'rgba="{rgba}" contype="0" conaffinity="0" mass="0"/>')


def closures(loops, motors) -> list[str]:
    """Return the MJCF ``<equality>`` and ``<actuator>`` blocks that follow ``</worldbody>``.

    ``loops`` holds ``(name, site1, site2)`` of each ``<connect>`` loop closure, ``motors`` the
    actuated joints in order (one ``<motor name="motor<i>">`` each, ``i`` from 1).
    """
    return (['  <equality>']
            + [f'    <connect name="{name}" site1="{a}" site2="{b}"/>' for name, a, b in loops]
            + ['  </equality>', '  <actuator>']
            + [f'    <motor name="motor{i}" joint="{joint}"/>'
               for i, joint in enumerate(motors, start=1)]
            + ['  </actuator>'])


#: Colours of the proximal and distal links in the MJCF (and the report's scenes).
LINK_RGBA, DISTAL_RGBA = "0.95 0.55 0.15 1", "0.2 0.22 0.28 1"


class Mechanism:
    """A kind of parallel mechanism: its parameter set, kinematics, MJCF body and task path.

    Subclass it in one module of :mod:`rrr_pin.model.mechanisms` and register one instance in
    :data:`~rrr_pin.model.mechanisms.MECHANISMS`; every layer above reaches a mechanism only
    through this protocol (and the :class:`~rrr_pin.model.closed_chain.ClosedChain` it loads as).

    Attributes
    ----------
    name : str
        Registry key and default model name (``"fivebar"``).
    title : str
        What it is, in a few words (MJCF comment, reports).
    params : type
        Its frozen parameter dataclass (a default instance is the built-in).
    lengths : tuple of str
        Fields perturbed by the length tolerance; the masses (fields ``m*``) take the inertia
        tolerance, and the rods' moments follow from mass and length.
    inertias : tuple of str
        Further fields perturbed by the inertia tolerance: moments of inertia that are
        parameters of their own [kg m^2] (a platform's), not a rod's mass and length.
    path_label : str
        What the task path is, in a legend (``"tip circle (reference)"``).
    """

    name: ClassVar[str] = ""
    path_label: ClassVar[str] = "reference path"
    title: ClassVar[str] = ""
    params: ClassVar[type] = type(None)
    lengths: ClassVar[tuple] = ()
    inertias: ClassVar[tuple] = ()

    # --- what a kind provides ------------------------------------------------------------
    def ik(self, params, p) -> np.ndarray:
        """Actuated angles [rad] putting the task point at ``p`` [m] (:class:`MechanismError`)."""
        raise NotImplementedError

    def fk(self, params, qa) -> np.ndarray:
        """Task point [m] of the actuated angles ``qa`` [rad] (:class:`MechanismError`)."""
        raise NotImplementedError

    def home(self, params) -> np.ndarray:
        """Return the closed configuration of the ``home`` point, every MJCF joint [rad, m]."""
        raise NotImplementedError

    def body(self, params) -> list[str]:
        """Return the MJCF lines from ``<worldbody>`` to ``</actuator>`` (loops, motors)."""
        raise NotImplementedError

    def task_point(self, params, t, period: float) -> np.ndarray:
        """Return the study's task path at times ``t`` [s]: points [m], shape (len(t), d)."""
        raise NotImplementedError

    def path_source(self, params, period: float, step: float) -> str:
        """Return what the task path is, for the reference's ``source``."""
        raise NotImplementedError

    def world_points(self, params, points) -> np.ndarray:
        """Task points as world positions [m], shape (N, 3) (drawing the path)."""
        points = np.asarray(points, dtype=float)
        return points if points.shape[1] == 3 else np.pad(points,
                                                            ((0, 0), (0, 3 - points.shape[1])))

    def elbows(self, params, qa) -> list:
        """Elbow points [m] of actuated angles ``qa`` (figures); none by default."""
        return []

    # --- generic ---------------------------------------------------------------------------
    def mjcf(self, params) -> str:
        """MJCF text of ``params`` (deterministic, shortest round-trip numbers).

        The bodies in one jointless top-level body, the loop closures as
        ``<connect site1 site2>``, one ``<motor>`` per actuated joint and a ``home`` keyframe
        holding a closed configuration.
        """
        values = {f.name: getattr(params, f.name) for f in fields(params) if f.name != "name"}
        out = ['<?xml version="1.0"?>',
               f"<!-- Generated by rrr_pin.model.mechanisms.mjcf_from_params ({self.title}). Do "
               f"not edit: regenerate with `rrr-pin mjcf {params.name}`. -->",
               f"<!-- parameters: {', '.join(f'{k}={num(v)}' for k, v in values.items())} -->",
               f'<mujoco model="{params.name}">',
               '  <compiler angle="radian"/>',
               '  <option gravity="0 0 -9.8"/>',
               *self.body(params),
               '  <keyframe>',
               f'    <key name="home" qpos="{vec(np.round(self.home(params), HOME_DIGITS))}"/>',
               '  </keyframe>',
               '</mujoco>', '']
        return "\n".join(out)

    def perturb(self, params, rng: np.random.Generator, inertia: float = 0.2,
                length: float = 0.05, attempts: int = 100):
        """Draw an uncertain mechanism: masses and lengths scaled by uniform factors.

        As the paper's uncertain RRR (sec. 5): every mass (and :attr:`inertias`) by a factor
        in ``[1 - inertia, 1 + inertia]`` and every length (:attr:`lengths`) in
        ``[1 - length, 1 + length]``; the rods' moments of inertia follow (uniform cylinders).
        A draw whose loop cannot close, or whose ``home`` point it cannot reach, is drawn again
        (at most ``attempts`` times), so the plant is always closable.

        Returns
        -------
        params
            The perturbed, closable set.
        factors : dict
            Field name -> factor drawn.
        """
        names = [f.name for f in fields(params) if f.name.startswith("m")]
        names += list(self.inertias) + list(self.lengths)
        for _ in range(attempts):
            factors = {n: float(rng.uniform(1.0 - (length if n in self.lengths else inertia),
                                            1.0 + (length if n in self.lengths else inertia)))
                       for n in names}
            try:
                out = replace(params, **{n: getattr(params, n) * f for n, f in factors.items()})
                self.home(out)
            except MechanismError:
                continue
            return out, factors
        raise MechanismError(f"no closable draw of {params.name} in {attempts} attempts "
                             f"(tolerances inertia {inertia:g}, length {length:g})")

    def waypoints(self, params, period: float, step: float = 0.005):
        """Return the task path as actuated waypoints: ``(t, W, source)``.

        :meth:`ik` of :meth:`task_point` every ``step`` [s] over ``[0, period]``; a clamped C2
        spline through them (:class:`rrr_pin.control.references.SplineReference`) is the
        study's reference.
        """
        t = np.linspace(0.0, period, int(round(period / step)) + 1)
        W = np.array([self.ik(params, p) for p in self.task_point(params, t, period)])
        return t, W, self.path_source(params, period, step)

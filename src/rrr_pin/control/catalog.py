"""The built-in control laws by name (one registry), importable without any numerical library.

:data:`LAWS` maps each CLI name to a :class:`BuiltinLaw`: what the law is, and the factory that
builds it. The factories import :mod:`rrr_pin.control.laws` (and, for ``"hinf"`` without a
given ``K``, :mod:`rrr_pin.robust.loopshaping`) only when called, so the CLI's help lists the
names and descriptions without importing Pinocchio, NumPy or python-control.
:func:`rrr_pin.campaign.runner.make_laws` builds laws through :func:`make_law`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import NamedTuple

__all__ = ["BuiltinLaw", "LAWS", "BUILTIN_LAWS", "FRICTION_LAWS", "make_law", "paper_K",
           "StressEffect", "EFFECTS", "EFFECT_FIELDS", "effect_name", "DEFAULT_BUDGET",
           "REFERENCES"]


#: The built-in laws that can compensate joint friction (``friction=``).
FRICTION_LAWS = ("fl", "hinf", "hinf_aw")


def _no_friction(name: str, friction) -> None:
    """Refuse friction compensation for a law that does not implement it, by name."""
    if friction is not None:
        raise ValueError(f"controller {name!r} does not compensate friction; friction "
                         f"compensation applies to {', '.join(FRICTION_LAWS)}")


@functools.lru_cache(maxsize=8)
def paper_K(lam: float, n: int):
    """Return the paper's reduced controller ``K`` for ``lam`` [rad/s] and ``n`` joints, cached.

    :func:`rrr_pin.design` is synthesized once per process and inputs (``hinf`` and
    ``hinf_aw`` share it).

    Returns
    -------
    control.StateSpace
        ``design(lam=lam, n=n).K_reduced``; shared: do not modify it.
    """
    from ..robust.loopshaping import design

    return design(lam=lam, n=n).K_reduced


def _fl(nominal, *, K=None, lam_fl: float = 100.0, lam_hinf: float = 45.0,
        torque_limit=None, friction=None):
    """Feedback linearization alone at ``lam_fl`` [rad/s], compensating ``friction`` if given."""
    from .laws import fl_controller

    return fl_controller(nominal, lam_fl, friction=friction)


def _hinf(nominal, *, K=None, lam_fl: float = 100.0, lam_hinf: float = 45.0,
          torque_limit=None, friction=None):
    """H-infinity + FL at ``lam_hinf`` [rad/s]; ``K`` default: the paper's design for ``nq``."""
    from .laws import hinf_fl_controller

    if K is None:
        K = paper_K(lam_hinf, nominal.nq)
    return hinf_fl_controller(nominal, K, lam_hinf, friction=friction)


def _hinf_aw(nominal, *, K=None, lam_fl: float = 100.0, lam_hinf: float = 45.0,
             torque_limit=None, friction=None):
    """``_hinf``'s law told ``torque_limit`` [N m] (None: the URDF's), ``K`` self-conditioned.

    A plant without effort limits in its description (a closed chain's MJCF) needs
    ``torque_limit``: ``"urdf"`` is refused by name there.
    """
    from .laws import hinf_aw_controller

    if K is None:
        K = paper_K(lam_hinf, nominal.nq)
    return hinf_aw_controller(nominal, K, lam_hinf,
                              torque_limit="urdf" if torque_limit is None else torque_limit,
                              friction=friction)


def _pd(nominal, *, K=None, lam_fl: float = 100.0, lam_hinf: float = 45.0,
        torque_limit=None, friction=None):
    """PD + gravity with the default gains (the options are unused)."""
    from .laws import pd_controller

    _no_friction("pd", friction)
    return pd_controller(nominal)


def _hinf2dof(nominal, *, K=None, lam_fl: float = 100.0, lam_hinf: float = 45.0,
              torque_limit=None, friction=None):
    """2-DOF H-infinity + FL at ``lam_hinf`` [rad/s], its own design (other options unused)."""
    from .laws import hinf_2dof_controller

    _no_friction("hinf2dof", friction)
    return hinf_2dof_controller(nominal, lam_hinf)


class BuiltinLaw(NamedTuple):
    """One built-in law of the registry (a named tuple: immutable, and cheap to import).

    Attributes
    ----------
    description : str
        What the law is (the CLI's help).
    factory : callable
        ``factory(nominal, *, K=None, lam_fl=100.0, lam_hinf=45.0, torque_limit=None) -> law``:
        the options of :func:`rrr_pin.campaign.runner.make_laws`, each factory reading those
        that apply to it (``torque_limit`` [N m]: the actuator limits a law that knows them
        clips to; None: the URDF's effort limits).
    """

    description: str
    factory: Callable


#: The registry: built-in laws by CLI name.
LAWS = {
    "fl": BuiltinLaw("feedback linearization alone, eq. (20), lam = 100 rad/s", _fl),
    "hinf": BuiltinLaw("H-infinity + feedback linearization, eq. (8)-(10), (18)-(19), "
                       "lam = 45 rad/s", _hinf),
    "pd": BuiltinLaw("PD + gravity compensation, critically damped at 20 rad/s per joint", _pd),
    "hinf_aw": BuiltinLaw("hinf told the torque limits (default the URDF's), K self-conditioned "
                          "on the saturated torque (Hanus anti-windup)", _hinf_aw),
    "hinf2dof": BuiltinLaw("2-DOF H-infinity (ncfsyn_2dof) + FL, lam = 45 rad/s, reference model "
                           "(90/(s + 90))^2", _hinf2dof),
}

#: Built-in laws by CLI name, with what each is (the descriptions of :data:`LAWS`).
BUILTIN_LAWS = {name: law.description for name, law in LAWS.items()}


def make_law(name: str, nominal, **options):
    """Build the built-in law ``name`` on ``nominal``, any plant (a serial arm, a closed chain).

    Options: ``K``, ``lam_fl``, ``lam_hinf``, ``torque_limit``, ``friction`` (the
    :class:`~rrr_pin.control.friction.JointFriction` compensated; only the laws of
    :data:`FRICTION_LAWS`, the others refuse it by name) (:class:`BuiltinLaw`).

    Raises
    ------
    ValueError
        An unknown name (the message lists the built-in ones with what each is).
    """
    law = LAWS.get(name) if isinstance(name, str) else None
    if law is None:
        raise ValueError(f"unknown controller {name!r}; built-in controllers: "
                         f"{', '.join(f'{k} ({v})' for k, v in BUILTIN_LAWS.items())}")
    return law.factory(nominal, **options)


class StressEffect(NamedTuple):
    """One effect a stress search can vary (a named tuple: immutable, and cheap to import).

    Attributes
    ----------
    unit : str
        Unit of the effect's size.
    direction : {"up", "down"}
        ``"up"``: the search finds the largest tolerated size; ``"down"``: the smallest.
    what : str
        What the size is (the CLI's help).
    fields : callable
        ``fields(size, seed) -> dict``: the :class:`~rrr_pin.control.effects.PlantEffects`
        fields of the effect at ``size``, the only place a searchable effect is spelled out.
    """

    unit: str
    direction: str
    what: str
    fields: Callable


#: Effects a stress search can vary (:mod:`rrr_pin.campaign.stress`), by name.
EFFECTS = {
    "delay": StressEffect("s", "up", "actuator transport delay tau_d",
                          lambda size, seed: {"delay": size}),
    "actuator": StressEffect("rad/s", "down", "first-order actuator bandwidth wa",
                             lambda size, seed: {"actuator_bandwidth": size}),
    "stiffness": StressEffect("N m/rad", "down", "joint stiffness K (motor inertia 0.01 kg m^2)",
                              lambda size, seed: {"stiffness": size, "motor_inertia": 0.01}),
    "torque": StressEffect("N m", "down", "torque limit |tau| <= tau_max, every joint",
                           lambda size, seed: {"torque_limit": size}),
    "noise": StressEffect("rad", "up", "std of the Gaussian noise on q (and 100x on qd, in rad/s)",
                          lambda size, seed: {"noise_q": size, "noise_qd": 100.0 * size,
                                              "seed": seed}),
    "viscous": StressEffect("N m s/rad", "up", "viscous joint friction Fv, every joint",
                            lambda size, seed: {"viscous": size}),
    "coulomb": StressEffect("N m", "up", "Coulomb joint friction Fc tanh(qd / 0.01 rad/s), "
                            "every joint", lambda size, seed: {"coulomb": size}),
}

#: The names of :data:`EFFECTS` by the :class:`~rrr_pin.control.effects.PlantEffects` field
#: each one sizes, for ``stress --effect`` and ``--with`` (one vocabulary with the options
#: ``--actuator-bandwidth``, ``--torque-limit``, ``--noise-q``): either name is accepted.
EFFECT_FIELDS = {"actuator_bandwidth": "actuator", "torque_limit": "torque", "noise_q": "noise"}


def effect_name(name: str) -> str:
    """Return the :data:`EFFECTS` key of ``name``, a key or its field (:data:`EFFECT_FIELDS`)."""
    return EFFECT_FIELDS.get(name, name)


#: RMS tracking error [rad] above which a stress run counts as broken.
DEFAULT_BUDGET = 0.05


#: Built-in reference kinds and what each is (:class:`rrr_pin.control.specs.ReferenceSpec`);
#: here, so the CLI's help lists them without importing NumPy.
REFERENCES = {
    "study": "the plant's own study reference: a mechanism's task path over the run (e.g. the "
             "5-bar's tip circle), else the sinusoid of 'sine'",
    "sine": "a sinusoid per joint about home (amp [rad], freq [Hz])",
    "quintic": "rest-to-rest quintic from home to 'to' [rad] in move_time [s]",
    "spline": "C2 spline through the waypoints of a CSV file (time [s], one column per joint)",
    "line": "straight line of a frame's origin to 'end' [m], by inverse kinematics",
    "circle": "circle of a frame's origin (radius [m], plane normal), by inverse kinematics",
}

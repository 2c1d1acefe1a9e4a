r"""Parallel mechanisms as data: one module per kind, one registry.

URDF cannot express a kinematic loop; MJCF can (``<equality><connect site1 site2/>``), and
Pinocchio reads it with ``buildModelAndLegacyConstraintsFromMJCF`` (the loop becomes a
``CONTACT_3D`` :class:`pinocchio.RigidConstraintModel` between the two sites). Each kind is one
module holding its frozen parameter set, its closed-form kinematics (no Pinocchio: the tests'
independent reference of the loaded model), its MJCF body and its task path, gathered in one
:class:`~rrr_pin.model.mechanisms.base.Mechanism` registered in :data:`MECHANISMS`:

* :mod:`~rrr_pin.model.mechanisms.fivebar`: the planar 5-bar (DexTAR class), ``"fivebar"``;
* :mod:`~rrr_pin.model.mechanisms.delta`: Clavel's 3-DOF Delta, ``"delta"``;
* :mod:`~rrr_pin.model.mechanisms.threerrr`: the 3-RRR planar parallel manipulator,
  ``"threerrr"``.

A new kind is one module (a parameter dataclass and a ``Mechanism`` subclass) plus one line
in :data:`MECHANISMS`. The functions here are generic: they find the kind of a parameter set
(:func:`mechanism_of`) and ask it. :func:`rrr_pin.load_robot` loads any of them (by name or
parameter set) as a :class:`~rrr_pin.model.closed_chain.ClosedChain`.

References
----------
.. [1] MuJoCo XML reference, ``equality/connect`` and ``keyframe``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .base import Mechanism, MechanismError
from .delta import (
    ADEPT_MM,
    DELTA,
    DeltaParams,
    adept_point,
    delta_elbows,
    delta_fk,
    delta_ik,
)
from .fivebar import (
    CIRCLE_RADIUS,
    FIVEBAR,
    FiveBarParams,
    circle_point,
    fivebar_elbows,
    fivebar_fk,
    fivebar_ik,
)
from .threerrr import THREERRR, ThreeRRRParams

__all__ = ["Mechanism", "MechanismError", "MECHANISMS", "mechanism_of", "mechanism_params",
           "is_mechanism_params", "mjcf_from_params", "write_mjcf", "check_mjcf",
           "home_configuration", "perturb_mechanism", "FiveBarParams", "DeltaParams",
           "fivebar_ik", "fivebar_fk", "fivebar_elbows", "delta_ik", "delta_fk",
           "delta_elbows", "circle_point", "adept_point", "CIRCLE_RADIUS", "ADEPT_MM",
           "ThreeRRRParams"]

#: The registry: every built-in mechanism kind by name.
MECHANISMS: dict[str, Mechanism] = {
    "fivebar": FIVEBAR,
    "delta": DELTA,
    "threerrr": THREERRR,
}

_BY_PARAMS = {m.params: m for m in MECHANISMS.values()}


def is_mechanism_params(params) -> bool:
    """Whether ``params`` is the parameter set of a registered mechanism kind."""
    return type(params) in _BY_PARAMS


def mechanism_of(params) -> Mechanism:
    """Return the registered :class:`Mechanism` of a parameter set (``TypeError`` otherwise)."""
    kind = _BY_PARAMS.get(type(params))
    if kind is None:
        raise TypeError(f"params must be the parameter set of a mechanism "
                        f"({', '.join(m.params.__name__ for m in MECHANISMS.values())}), got "
                        f"{type(params).__name__}")
    return kind


def mechanism_params(name):
    """Return the parameter set of a mechanism.

    A built-in's defaults by name (a key of :data:`MECHANISMS`), or ``name`` itself when it
    already is a registered parameter set (your own dimensions and masses).
    """
    if is_mechanism_params(name):
        return name
    if name not in MECHANISMS:
        raise ValueError(f"unknown mechanism {name!r}: one of {', '.join(MECHANISMS)}")
    return MECHANISMS[name].params()


def mjcf_from_params(params) -> str:
    """MJCF text of a mechanism's parameter set (:meth:`Mechanism.mjcf`)."""
    return mechanism_of(params).mjcf(params)


def home_configuration(params) -> np.ndarray:
    """Return the closed configuration ``q`` of the ``home`` point (:meth:`Mechanism.home`).

    Shape (4,) for the 5-bar, (12,) for the Delta [rad, m].
    """
    return mechanism_of(params).home(params)


def perturb_mechanism(params, rng: np.random.Generator, inertia: float = 0.2,
                      length: float = 0.05, attempts: int = 100):
    """Draw an uncertain mechanism: :meth:`Mechanism.perturb` of the kind of ``params``.

    Every mass by a factor in ``[1 - inertia, 1 + inertia]``, every length in
    ``[1 - length, 1 + length]`` (uniform), redrawn until the loop closes at ``home``.

    Returns
    -------
    params
        The perturbed, closable set.
    factors : dict
        Field name -> factor drawn.
    """
    return mechanism_of(params).perturb(params, rng, inertia, length, attempts)


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

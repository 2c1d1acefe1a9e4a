r"""Joint friction as one typed input: what a plant effect applies and what a law compensates.

.. math:: \tau_f(\dot q) = F_v \dot q + F_c \tanh(\dot q / v_\varepsilon)

per joint, with ``Fv`` viscous [N m s/rad], ``Fc`` Coulomb [N m] and ``v_eps`` [rad/s] the
smoothing speed: the friction model of :class:`~rrr_pin.control.effects.PlantEffects` (the
torque the joint loses, sign convention: positive coefficients oppose the motion). A
feedback-linearizing law given a :class:`JointFriction` adds ``tau_f(qd)`` at the measured
``qd`` to its torque (friction compensation, :class:`~rrr_pin.control.laws.TrackingController`),
so a law compensating the plant's own friction cancels it exactly. The identified offset
(``off`` of :func:`rrr_pin.model.identification.friction_regressor`) is a bias of the torque
measurement, not a force on the joint: it is neither simulated nor compensated.

``Fc sign(qd)`` (what the identification fits) and ``Fc tanh(qd / v_eps)`` differ only for
``|qd|`` below a few ``v_eps`` (0.01 rad/s by default).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["JointFriction", "DEFAULT_COULOMB_VELOCITY"]

#: Default smoothing speed ``v_eps`` [rad/s] of the Coulomb friction (as PlantEffects').
DEFAULT_COULOMB_VELOCITY = 0.01


@dataclass(frozen=True)
class JointFriction:
    """Viscous and smooth Coulomb friction per joint (see the module docstring).

    Parameters
    ----------
    viscous : sequence of float, shape (n,)
        ``Fv`` [N m s/rad] >= 0 per joint.
    coulomb : sequence of float, shape (n,)
        ``Fc`` [N m] >= 0 per joint.
    coulomb_velocity : float, default 0.01
        ``v_eps`` [rad/s] > 0.
    source : str, default ""
        Where the values come from (``"urdf <dynamics> of identified.urdf"``), recorded.

    Raises
    ------
    ValueError
        Naming the field, the joint and the value: lengths that differ, a value that is not
        finite or below zero (friction that feeds energy in), ``v_eps <= 0``.
    """

    viscous: tuple
    coulomb: tuple
    coulomb_velocity: float = DEFAULT_COULOMB_VELOCITY
    source: str = ""

    def __post_init__(self) -> None:
        fv = tuple(float(v) for v in np.atleast_1d(np.asarray(self.viscous, dtype=float)))
        fc = tuple(float(v) for v in np.atleast_1d(np.asarray(self.coulomb, dtype=float)))
        if len(fv) != len(fc):
            raise ValueError(f"friction: viscous has {len(fv)} values and coulomb {len(fc)}; "
                             f"give one per joint for both")
        for key, vals, unit in (("viscous", fv, "N m s/rad"), ("coulomb", fc, "N m")):
            for j, v in enumerate(vals):
                if not (math.isfinite(v) and v >= 0.0):
                    raise ValueError(f"friction: {key}[{j}] = {v!r}: expected finite >= 0 "
                                     f"[{unit}] (positive friction opposes the motion)")
        veps = float(self.coulomb_velocity)
        if not (math.isfinite(veps) and veps > 0.0):
            raise ValueError(f"friction: coulomb_velocity = {self.coulomb_velocity!r}: expected "
                             f"finite > 0 [rad/s]")
        object.__setattr__(self, "viscous", fv)
        object.__setattr__(self, "coulomb", fc)
        object.__setattr__(self, "coulomb_velocity", veps)

    @property
    def n(self) -> int:
        """Number of joints."""
        return len(self.viscous)

    @property
    def active(self) -> bool:
        """Whether any coefficient is nonzero."""
        return any(v > 0.0 for v in (*self.viscous, *self.coulomb))

    def torque(self, qd) -> np.ndarray:
        """Return ``Fv qd + Fc tanh(qd / v_eps)`` [N m], shape (n,), at ``qd`` [rad/s] (n,)."""
        Fv, Fc = np.asarray(self.viscous), np.asarray(self.coulomb)
        return Fv * qd + Fc * np.tanh(qd / self.coulomb_velocity)

    def check_joints(self, n: int, who: str = "the plant") -> JointFriction:
        """Return ``self`` with one value per joint of ``n`` (a single value is repeated).

        Raises
        ------
        ValueError
            A count that is neither 1 nor ``n``.
        """
        if self.n == n:
            return self
        if self.n == 1:
            return JointFriction(self.viscous * n, self.coulomb * n, self.coulomb_velocity,
                                 self.source)
        raise ValueError(f"friction: {self.n} values per coefficient, {who} has {n} joints "
                         f"(give one value, or one per joint)")

    def to_dict(self) -> dict:
        """JSON-ready, units in the keys."""
        return {"viscous_Nms_rad": list(self.viscous), "coulomb_Nm": list(self.coulomb),
                "coulomb_velocity_rad_s": self.coulomb_velocity,
                "model": "Fv qd + Fc tanh(qd / v_eps)", "source": self.source}

r"""The paper's laws, and every built-in law, on a parallel mechanism in its actuated coordinates.

Eq. (8)-(11) apply unchanged to the reduced model of
:class:`rrr_pin.model.closed_chain.ClosedChain`:

.. math:: \tau = M_r(q_a)\,\bar\tau + V_r(q_a, \dot q_a) + G_r(q_a),

with ``taubar`` the FL (and H-infinity) outer loop of
:class:`~rrr_pin.control.laws.TrackingController` on ``e = r - q_a``. The built-in laws read
their model through Pinocchio on the serial arm's tree (``crba``, ``nonLinearEffects``,
``computeGeneralizedGravity`` of ``nominal.model``), which for a closed chain is the tree with
every joint, not the mechanism. Each class here is the built-in with that one inner term
replaced by the reduced model, and nothing else: the outer loop, the controller ``K``, its
discretization, the anti-windup conditioning and the linear model are the built-in's.

======== ========================== ======================================================
name     class                      reduced term
======== ========================== ======================================================
fl       :class:`ReducedTracking`   ``M_r taubar + V_r + G_r`` (``K = None``)
hinf     :class:`ReducedTracking`   the same with the loop-shaping ``K`` (eq. 18, or the
                                    full-order one)
hinf_aw  :class:`ReducedAntiWindup` the same, clipped, ``K`` conditioned on
                                    ``M_r^-1 (tau_s - tau)``
pd       :class:`ReducedPD`         ``Kp e + Kd ed + G_r`` (gains from ``diag M_r(home)``)
hinf2dof :class:`ReducedTwoDOF`     ``M_r taubar + V_r + G_r`` with the 2-DOF ``tauhat``
======== ========================== ======================================================

:data:`CHAIN_LAWS` maps every name of :data:`rrr_pin.control.catalog.LAWS` to its factory
here (a test checks that the two sets are equal), and
:func:`rrr_pin.control.catalog.make_law` hands a closed chain to :func:`make_chain_law`,
which refuses any other name by name. The passive coordinates are solved by the law from the
measured actuated angles (Newton seeded from the previous sample), as a controller reading
only its motor encoders would.

Compiled form: ``fl`` and ``hinf`` (the exact class :class:`ReducedTracking`) have
:class:`ChainFLForm` (the law's ``lam`` and ``K``'s matrices, continuous for the law,
discretized as the sampled law runs them), run by the compiled closed-chain engine
(:mod:`rrr_pin.sim.chain_compiled`); the others have none (the Python engine runs them).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..validation import check_rate
from .laws import (
    DEFAULT_RATE,
    PD_BANDWIDTH,
    AntiWindupTracking,
    ControlLaw,
    FLForm,
    FLLinearModel,
    PDGravity,
    SampledLaw,
    TrackingController,
    TwoDOFController,
    TwoDOFLinearModel,
    _hanus_gain,
    _SampledAntiWindup,
    _SampledTracking,
    _SampledTwoDOF,
    hinf_2dof_controller,
    pd_controller,
)

__all__ = ["ReducedTracking", "ChainFLForm", "ReducedAntiWindup", "ReducedPD", "ReducedTwoDOF",
           "reset_closure", "closed_chain_fl", "closed_chain_hinf_fl", "closed_chain_hinf_aw",
           "closed_chain_pd", "closed_chain_hinf_2dof", "CHAIN_LAWS", "make_chain_law"]


@dataclass(frozen=True, eq=False)
class ChainFLForm(FLForm):
    r"""Compiled form of :class:`ReducedTracking`: eq. (8) on a closed chain's reduced model.

    .. math:: \bar\tau = \ddot r + 2\lambda(\dot r - \dot q_a) + \lambda^2 (e + y), \quad
              \tau = M_r(q_a)\,\bar\tau + V_r(q_a, \dot q_a) + G_r(q_a)

    with ``M_r``, ``V_r + G_r`` of :meth:`rrr_pin.model.closed_chain.ClosedChain.reduced`
    (the passive coordinates by Newton on the loop closure, seeded from the previous sample),
    ``y = C x + D e``, ``x+ = A x + B e`` (sampled law, matrices discrete at its rate). The
    fields are :class:`~rrr_pin.control.laws.FLForm`'s; a type of its own, so the serial
    compiled engine (which dispatches on the exact type) never runs it as a serial arm's FL.

    Attributes
    ----------
    nominal : ClosedChain
        The law's mechanism (``n = nominal.nq`` actuated joints).
    lam : float
        Bandwidth ``lambda`` [rad/s], > 0.
    A, B, C, D : ndarray, shapes (m, m), (m, n), (n, m), (n, n)
        The controller ``K`` on ``e = r - q_a`` [rad], negative feedback; ``m = 0`` for FL
        alone.
    """

    kind: ClassVar[str] = "chain_fl"


@dataclass(frozen=True, eq=False)
class ReducedTracking(TrackingController):
    """:class:`TrackingController` whose model is a closed chain's reduced dynamics.

    ``nominal`` is a :class:`rrr_pin.model.closed_chain.ClosedChain`; ``q, qd, r`` are
    actuated coordinates, shape (nominal.nq,) [rad, rad/s]. Compiled form:
    :class:`ChainFLForm` (for this exact class; a subclass gets None).
    """

    def _tau(self, q, qd, r, rd, rdd, y):
        lam = self.lam
        taubar = rdd + 2.0 * lam * (rd - qd) + lam * lam * ((r - q) + y)
        Mr, h = self.nominal.reduced(q, qd)
        return Mr @ taubar + h

    def sampled(self, rate: float = DEFAULT_RATE, method: str = "tustin") -> SampledLaw:
        """Digital version: ``K`` discretized by ``method``, torque held between samples."""
        rate = check_rate("rate", rate)
        # the built-in's sampled law, calling this class's _tau
        return _SampledReduced(self, rate, method, self.discretize(rate, method))

    def compiled_form(self) -> ChainFLForm | None:
        """Return the :class:`ChainFLForm` with ``K``'s continuous matrices (this class only)."""
        if type(self) is not ReducedTracking:
            return None
        return ChainFLForm(self.nominal, self.lam, *self._mats)

    def linear_model(self) -> FLLinearModel:
        """Return the loop of eq. (10) with ``K``, the same as the serial arm's (exact model)."""
        return FLLinearModel(self.n, self.lam, self._mats, self.discretize)


class _SampledReduced(_SampledTracking):
    """Sampled :class:`ReducedTracking` (the built-in's step), with its compiled form."""

    def compiled_form(self):
        """Return the :class:`ChainFLForm` with the discrete matrices (None for a subclass)."""
        if type(self.law) is not ReducedTracking:
            return None
        return ChainFLForm(self.law.nominal, self.law.lam, *self.mats)


@dataclass(frozen=True, eq=False)
class ReducedAntiWindup(AntiWindupTracking):
    r""":class:`AntiWindupTracking` on a closed chain's reduced model.

    ``tau = sat(M_r taubar + V_r + G_r)``; while a joint clips, ``K`` is driven by
    ``y_hat - y = M_r^-1 (tau_s - tau) / lam^2`` (Hanus). ``torque_limit`` is required: an
    MJCF motor carries no effort limit (``"urdf"`` is refused by name). Unsaturated, the law is
    :class:`ReducedTracking`'s exactly.
    """

    def __post_init__(self) -> None:
        if isinstance(self.torque_limit, str):
            raise ValueError(f"law {self.name!r} on the closed chain {self.nominal.name!r}: "
                             f"torque_limit = {self.torque_limit!r} reads a URDF's effort "
                             f"limits, and an MJCF motor has none; give the limits [N m] "
                             f"(a number or one per actuated joint)")
        super().__post_init__()

    def _conditioned(self, q, qd, r, rd, rdd, y):
        lam = self.lam
        taubar = rdd + 2.0 * lam * (rd - qd) + lam * lam * ((r - q) + y)
        Mr, h = self.nominal.reduced(q, qd)
        tau = Mr @ taubar + h
        lim = self._limit
        sat = np.minimum(np.maximum(tau, -lim), lim)
        if np.array_equal(sat, tau):
            return tau, None
        return sat, np.linalg.solve(Mr, sat - tau) / (lam * lam)

    def sampled(self, rate: float = DEFAULT_RATE, method: str = "tustin") -> SampledLaw:
        """Digital version: ``K`` discretized by ``method``, conditioned with ``Bd Dd^-1``."""
        rate = check_rate("rate", rate)
        mats = self.discretize(rate, method)
        gain = _hanus_gain(self.name, f"the discrete Dd ({method}, {rate:g} Hz)", *mats,
                           discrete=True)
        return _SampledAntiWindup(self, rate, method, mats, gain)

    def linear_model(self) -> FLLinearModel:
        """Return the loop while nothing clips: :class:`ReducedTracking`'s."""
        return FLLinearModel(self.n, self.lam, self._mats, self.discretize)


@dataclass(frozen=True, eq=False)
class ReducedPD(PDGravity):
    r""":class:`PDGravity` on a closed chain: ``tau = Kp e + Kd ed + G_r(q_a)``.

    ``G_r = S^T g(q)`` is the reduced gravity (:meth:`ClosedChain.G`). No linear model (the
    serial one reads ``M`` at the home of a URDF): ``rrr-pin stress`` simulates it only.
    """

    def torque(self, t, q, qd, r, rd, rdd, x) -> np.ndarray:
        """``Kp e + Kd ed + G_r(q)``."""
        return self.Kp @ (r - q) + self.Kd @ (rd - qd) + self.nominal.G(q, check=False)

    def linear_model(self):
        """None: no linear prediction on a closed chain."""
        return None


@dataclass(frozen=True, eq=False)
class ReducedTwoDOF(TwoDOFController):
    """:class:`TwoDOFController` on a closed chain: ``tau = M_r taubar + V_r + G_r``."""

    def _tau(self, q, qd, tauhat):
        lam = self.lam
        taubar = lam * lam * (tauhat - q) - 2.0 * lam * qd
        Mr, h = self.nominal.reduced(q, qd)
        return Mr @ taubar + h

    def sampled(self, rate: float = DEFAULT_RATE, method: str = "tustin") -> SampledLaw:
        """Digital version: the implemented form discretized by ``method``, torque held."""
        rate = check_rate("rate", rate)
        return _SampledTwoDOF(self, rate, method, self.discretize(rate, method))

    def linear_model(self) -> TwoDOFLinearModel:
        """Return the built-in's :class:`TwoDOFLinearModel` (``qdd = taubar``, exact model)."""
        import control

        K, n = self.K, self.n
        K2 = control.ss(K.A, K.B[:, n:], -K.C, -K.D[:, n:])
        return TwoDOFLinearModel(n, self.lam, K2, self.discretize)


def reset_closure(law, reference) -> None:
    """Restart a closed-chain law's loop-closure solver on its home branch at ``r(0)``.

    The reduced-model laws seed their Newton solve from the previous sample, so after a run
    (above all a diverged one) the seed is anywhere; a run that starts from here depends on its
    own plant only. No-op for a law whose ``nominal`` is not a closed chain.
    """
    nominal = getattr(law, "nominal", None)
    if hasattr(nominal, "constraints") and hasattr(nominal, "close"):
        nominal.close(reference(0.0)[0], seed=nominal.home)


def closed_chain_fl(chain, lam: float = 100.0, *, name: str = "fl") -> ReducedTracking:
    """Feedback linearization alone on a closed chain's reduced model (eq. (20))."""
    return ReducedTracking(nominal=chain, lam=lam, K=None, name=name, label="FL alone")


def closed_chain_hinf_fl(chain, K, lam: float = 45.0, *, name: str = "hinf") -> ReducedTracking:
    """H-infinity + feedback linearization on a closed chain's reduced model, eq. (8)-(10).

    Parameters
    ----------
    chain : rrr_pin.model.closed_chain.ClosedChain
        The controller's model.
    K : control LTI
        The loop-shaping controller on ``e = r - q_a`` (negative feedback), SISO or n x n,
        continuous time.
    lam : float, default 45
        FL bandwidth the design assumed [rad/s].
    """
    return ReducedTracking(nominal=chain, lam=lam, K=K, name=name, label="H-infinity + FL")


def closed_chain_hinf_aw(chain, K, lam: float = 45.0, *, torque_limit,
                         name: str = "hinf_aw") -> ReducedAntiWindup:
    """H-infinity + FL with Hanus anti-windup on a closed chain (:class:`ReducedAntiWindup`).

    Parameters
    ----------
    chain : rrr_pin.model.closed_chain.ClosedChain
        The controller's model.
    K : control LTI
        As :func:`closed_chain_hinf_fl` (its ``D`` non-singular).
    lam : float, default 45
        FL bandwidth [rad/s].
    torque_limit : float or array-like, shape (nq,)
        Actuator limits [N m] the law clips to (required).
    """
    return ReducedAntiWindup(nominal=chain, lam=lam, K=K, name=name,
                             label="H-infinity + FL, anti-windup", torque_limit=torque_limit)


def closed_chain_pd(chain, wn: float = PD_BANDWIDTH, zeta: float = 1.0, *,
                    name: str = "pd") -> ReducedPD:
    r"""PD + reduced gravity, gains as :func:`rrr_pin.control.laws.pd_controller`.

    ``Kp = wn^2 diag M_r(home)``, ``Kd = 2 zeta wn diag M_r(home)`` [N m/rad, N m s/rad],
    ``home`` the mechanism's home (actuated part).
    """
    law = pd_controller(chain, wn, zeta, q=chain.neutral(), name=name)
    return ReducedPD(chain, Kp=law.Kp, Kd=law.Kd, name=name, label=law.label)


def closed_chain_hinf_2dof(chain, lam: float = 45.0, *, name: str = "hinf2dof") -> ReducedTwoDOF:
    """Build :func:`rrr_pin.control.laws.hinf_2dof_controller`'s law on the reduced model."""
    law = hinf_2dof_controller(chain, lam, name=name)
    return ReducedTwoDOF(nominal=chain, lam=law.lam, K=law.K, name=name, label=law.label)


def _fl(chain, *, K=None, lam_fl: float = 100.0, lam_hinf: float = 45.0, torque_limit=None):
    return closed_chain_fl(chain, lam_fl)


def _design_K(chain, K, lam_hinf):
    if K is not None:
        return K
    from ..robust.loopshaping import design

    return design(lam=lam_hinf, n=chain.nq).K_reduced


def _hinf(chain, *, K=None, lam_fl: float = 100.0, lam_hinf: float = 45.0, torque_limit=None):
    return closed_chain_hinf_fl(chain, _design_K(chain, K, lam_hinf), lam_hinf)


def _hinf_aw(chain, *, K=None, lam_fl: float = 100.0, lam_hinf: float = 45.0,
             torque_limit=None):
    if torque_limit is None:
        raise ValueError(f"controller 'hinf_aw' on the closed chain {chain.name!r} needs "
                         f"torque_limit [N m] (an MJCF motor carries no effort limit to "
                         f"default to)")
    return closed_chain_hinf_aw(chain, _design_K(chain, K, lam_hinf), lam_hinf,
                                torque_limit=torque_limit)


def _pd(chain, *, K=None, lam_fl: float = 100.0, lam_hinf: float = 45.0, torque_limit=None):
    return closed_chain_pd(chain)


def _hinf2dof(chain, *, K=None, lam_fl: float = 100.0, lam_hinf: float = 45.0,
              torque_limit=None):
    return closed_chain_hinf_2dof(chain, lam_hinf)


#: The closed-chain factory of each built-in law, by the registry's name
#: (:data:`rrr_pin.control.catalog.LAWS`); options as
#: :class:`~rrr_pin.control.catalog.BuiltinLaw`.
CHAIN_LAWS = {"fl": _fl, "hinf": _hinf, "hinf_aw": _hinf_aw, "pd": _pd, "hinf2dof": _hinf2dof}


def make_chain_law(name: str, chain, **options) -> ControlLaw:
    """Build the built-in law ``name`` on the closed chain ``chain`` (its reduced model).

    Options: ``K``, ``lam_fl``, ``lam_hinf``, ``torque_limit`` (as
    :func:`rrr_pin.control.catalog.make_law`; ``hinf_aw`` requires ``torque_limit``).

    Raises
    ------
    ValueError
        A name without a closed-chain form (the message lists those with one).
    """
    # (no import of the registry here: catalog.make_law imports this module)
    factory = CHAIN_LAWS.get(name) if isinstance(name, str) else None
    if factory is None:
        raise ValueError(f"unknown controller {name!r}; built-in controllers on a closed "
                         f"chain: {', '.join(CHAIN_LAWS)}")
    return factory(chain, **options)

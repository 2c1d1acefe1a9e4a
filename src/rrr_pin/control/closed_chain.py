r"""The paper's laws on a parallel mechanism, in its actuated coordinates.

Eq. (8)-(11) apply unchanged to the reduced model of
:class:`rrr_pin.model.closed_chain.ClosedChain`:

.. math:: \tau = M_r(q_a)\,\bar\tau + V_r(q_a, \dot q_a) + G_r(q_a),

with ``taubar`` the FL (and H-infinity) outer loop of
:class:`~rrr_pin.control.laws.TrackingController` on ``e = r - q_a``. Only the inner term
changes: :class:`ReducedTracking` overrides ``_tau`` and nothing else, so the outer loop, the
controller ``K``, its discretization and the linear model are the built-in's. The passive
coordinates are solved by the law from the measured actuated angles (Newton seeded from the
previous sample), as a controller reading only its motor encoders would.

Compiled form: :class:`ChainFLForm` (the law's ``lam`` and ``K``'s matrices, continuous for
the law, discretized as the sampled law runs them), which the compiled closed-chain engine
(:mod:`rrr_pin.sim.chain_compiled`) runs for the exact class :class:`ReducedTracking` only.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ..validation import check_rate
from .laws import (
    DEFAULT_RATE,
    FLForm,
    FLLinearModel,
    SampledLaw,
    TrackingController,
    _SampledTracking,
)

__all__ = ["ReducedTracking", "ChainFLForm", "closed_chain_fl", "closed_chain_hinf_fl"]


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
        The loop-shaping controller on ``e = r - q_a`` (negative feedback), SISO or n x n.
    lam : float, default 45
        FL bandwidth the design assumed [rad/s].
    """
    return ReducedTracking(nominal=chain, lam=lam, K=K, name=name, label="H-infinity + FL")

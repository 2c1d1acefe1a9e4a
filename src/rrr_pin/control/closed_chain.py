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
"""

from __future__ import annotations

from ..validation import check_rate
from .laws import DEFAULT_RATE, FLLinearModel, SampledLaw, TrackingController, _SampledTracking

__all__ = ["ReducedTracking", "closed_chain_fl", "closed_chain_hinf_fl"]


class ReducedTracking(TrackingController):
    """:class:`TrackingController` whose model is a closed chain's reduced dynamics.

    ``nominal`` is a :class:`rrr_pin.model.closed_chain.ClosedChain`; ``q, qd, r`` are
    actuated coordinates, shape (nominal.nq,) [rad, rad/s]. No compiled form: the Python
    engine runs it.
    """

    def _tau(self, q, qd, r, rd, rdd, y):
        lam = self.lam
        taubar = rdd + 2.0 * lam * (rd - qd) + lam * lam * ((r - q) + y)
        Mr, h = self.nominal.reduced(q, qd)
        return Mr @ taubar + h

    def sampled(self, rate: float = DEFAULT_RATE, method: str = "tustin") -> SampledLaw:
        """Digital version: ``K`` discretized by ``method``, torque held between samples."""
        rate = check_rate("rate", rate)
        # the built-in's sampled law calls this class's _tau; its compiled_form() is None for a
        # subclass, so the compiled engine refuses it by name
        return _SampledTracking(self, rate, method, self.discretize(rate, method))

    def linear_model(self) -> FLLinearModel:
        """Return the loop of eq. (10) with ``K``, the same as the serial arm's (exact model)."""
        return FLLinearModel(self.n, self.lam, self._mats, self.discretize)


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

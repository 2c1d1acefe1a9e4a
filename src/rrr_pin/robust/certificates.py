"""Frozen-configuration robustness certificates for uncertain arms (nu-gap against b(Gs, Ks)).

The controller of eq. (8)-(10) uses the *nominal* model, ``tau = Mhat(q) taubar + Vhat(q, qd)
+ Ghat(q)`` with ``taubar = -2 lam qd - lam^2 (q - tauhat)``, while the arm obeys its *true*
``M, V, G`` (eq. 1). The map ``tauhat -> q`` is then

    qdd = M(q)^-1 [ Mhat(q) taubar + Vhat(q, qd) + Ghat(q) - V(q, qd) - G(q) ],

which is eq. (11), ``lam^2 / (s + lam)^2 I``, only when the model is exact. At each frozen
configuration ``(q, qd, qdd)`` along the reference, :func:`frozen_certificate` linearizes this
map (``B`` exactly, the ``q`` and ``qd`` derivatives by central differences of Pinocchio's
``M, V, G``), shapes it like the design (``W2 G W1``), and compares its nu-gap to the nominal
shaped plant with the design's margin ``b(Gs, Ks)``: by Vinnicombe's theorem, ``nugap < b``
implies that ``Ks`` stabilizes the frozen plant, with margin at least
``sin(arcsin b - arcsin nugap)``.

Any plant (:mod:`rrr_pin.model.plant`) offers ``M, V, G`` in its actuated coordinates (a
closed chain's reduced model, eq. (1) in ``q_a``), so the same linearization applies to every
kind. :func:`certificate_along` (what :meth:`CertificateSpec.certify` runs) takes both models
along the reference first (:meth:`~rrr_pin.model.plant.Plant.follow`: a closed chain then
closes each frozen configuration on the reference's assembly mode; a serial arm has nothing
to do).

What a frozen-configuration certificate proves, and what it does not
--------------------------------------------------------------------
It proves that, at every configuration checked, the linear time-invariant model obtained by
freezing the arm there and linearizing the feedback-linearized uncertain dynamics is
stabilized by the loop-shaping controller, with a guaranteed NCF margin. It does not prove
that the nonlinear, time-varying closed loop is stable or tracks the reference: frozen-time
stability does not imply stability of the time-varying system unless the configuration
varies slowly enough, the linearization holds only for small deviations around the frozen
point, the configurations between the checked ones are not covered, and the certificate
ignores what the LTI model leaves out (sampling and discretization of the controller, torque
limits, friction, delays, unmodelled flexible dynamics). A certified plant is therefore
*likely* robust and a non-certified one is *not proven* robust - it may still be stable in
simulation; simulation and the certificate are complementary evidence, not substitutes.

References
----------
.. [1] The paper, eq. (8)-(11) and section 4.
.. [2] G. Vinnicombe, *Uncertainty and Feedback*, Imperial College Press, 2001, th. 3.8.
.. [3] C. A. Desoer, "Slowly varying system xdot = A(t) x", IEEE Trans. Automat. Control
   14(6), 780-781, 1969 (frozen-time stability needs slow variation).
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from ..validation import check_count, check_scalar_bandwidth
from .gap import _nugap
from .loopshaping import fl_plant
from .lti import DimensionMismatchError, check_lti, expand_diagonal
from .ncf import _graph_symbols_ct, _series, ncfmargin
from .reduction import _arcsin_bound

__all__ = ["FrozenCertificate", "CertificateSpec", "frozen_linearization", "frozen_certificate",
           "certificate_along", "WALK_STEP"]

_H = 1e-6  # relative central-difference step of frozen_linearization


@dataclass(frozen=True)
class FrozenCertificate:
    """Result of :func:`frozen_certificate`.

    Attributes
    ----------
    nugap : ndarray, shape (N,)
        nu-gap between each frozen shaped plant and the nominal shaped plant ``Gs``.
    b : float
        ``b(Gs, Ks)`` of the nominal shaped loop.
    b_lower : ndarray, shape (N,)
        Guaranteed margin ``sin(arcsin b - arcsin nugap)`` of each frozen loop (0 where
        ``nugap >= b``).
    b_frozen : ndarray, shape (N,)
        Computed ``b(Gs_k, Ks)`` of each frozen loop (0 where unstable), for comparison.
    certified : bool
        ``max(nugap) < b``.
    """

    nugap: np.ndarray
    b: float
    b_lower: np.ndarray
    b_frozen: np.ndarray
    certified: bool

    @property
    def nugap_max(self) -> float:
        """Largest nu-gap over the configurations."""
        return float(self.nugap.max())

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        return {"certified": bool(self.certified), "b": float(self.b),
                "nugap_max": self.nugap_max, "b_lower_min": float(self.b_lower.min()),
                "b_frozen_min": float(self.b_frozen.min())}


def _configs(nq: int, q, qd, qdd):
    q = np.atleast_2d(np.asarray(q, dtype=float))
    qd = np.atleast_2d(np.asarray(qd, dtype=float))
    qdd = np.zeros_like(q) if qdd is None else np.atleast_2d(np.asarray(qdd, dtype=float))
    for name, x in (("q", q), ("qd", qd), ("qdd", qdd)):
        if x.ndim != 2 or x.shape[1] != nq or x.shape[0] == 0:
            raise DimensionMismatchError(f"Expected {name} of shape (N, {nq}), got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError(f"{name} must be finite")
    if not (q.shape == qd.shape == qdd.shape):
        raise DimensionMismatchError(f"q, qd and qdd must have the same shape, got {q.shape}, "
                                     f"{qd.shape} and {qdd.shape}")
    return q, qd, qdd


def frozen_linearization(nominal, plant, q, qd, qdd=None, lam: float = 45.0,
                         h: float = _H) -> control.StateSpace:
    r"""Linearize the feedback-linearized uncertain arm ``tauhat -> q`` at one configuration.

    .. math:: \ddot q = M^{-1}\left[\hat M \bar\tau + \hat V + \hat G - V - G\right],\quad
              \bar\tau = -2\lambda \dot q - \lambda^2 (q - \hat\tau)

    (paper eq. 8-10 with nominal ``Mhat, Vhat, Ghat`` and true ``M, V, G``), linearized at
    ``(q, qd)`` and the input ``tauhat`` for which ``taubar = qdd``.

    Parameters
    ----------
    nominal, plant : rrr_pin.model.dynamics.Robot
        The controller's model and the true arm (same ``nq``).
    q, qd, qdd : array-like, shape (nq,)
        Configuration [rad], velocity [rad/s] and reference acceleration [rad/s^2]
        (``qdd`` default 0).
    lam : float
        Feedback-linearization natural frequency [rad/s].
    h : float
        Relative central-difference step.

    Returns
    -------
    control.StateSpace
        ``nq x nq`` plant, states ``[dq; dqd]``; equal to :func:`fl_plant` (eq. 11) when
        ``plant`` is ``nominal``.
    """
    nq = _check_pair(nominal, plant)
    q, qd, qdd = (x[0] for x in _configs(nq, q, qd, qdd))
    return _linearization(nominal, plant, q, qd, qdd,
                          check_scalar_bandwidth("lam", lam, "the frozen linearization"),
                          h)


def _check_pair(nominal, plant) -> int:
    nq = nominal.nq
    if plant.nq != nq:
        raise DimensionMismatchError(f"nominal has nq={nq} but plant has nq={plant.nq}")
    return nq


def _linearization(nominal, plant, q, qd, qdd, lam: float, h: float) -> control.StateSpace:
    """:func:`frozen_linearization` of checked float64 arrays ``q, qd, qdd`` of shape (nq,)."""
    nq = nominal.nq
    tauhat = q + (qdd + 2.0 * lam * qd) / lam**2

    def f(q, qd):
        # q, qd are finite float64 arrays of shape (nq,): the robots' unchecked fast path.
        taubar = -2.0 * lam * qd - lam**2 * (q - tauhat)
        rhs = (nominal.M(q, check=False) @ taubar + nominal.V(q, qd, check=False)
               + nominal.G(q, check=False) - plant.V(q, qd, check=False)
               - plant.G(q, check=False))
        return np.linalg.solve(plant.M(q, check=False), rhs)

    Jq, Jqd = np.zeros((nq, nq)), np.zeros((nq, nq))
    for i in range(nq):
        e = np.zeros(nq)
        e[i] = h * max(1.0, abs(q[i]))
        Jq[:, i] = (f(q + e, qd) - f(q - e, qd)) / (2 * e[i])
        e[i] = h * max(1.0, abs(qd[i]))
        Jqd[:, i] = (f(q, qd + e) - f(q, qd - e)) / (2 * e[i])
    Bq = lam**2 * np.linalg.solve(plant.M(q, check=False), nominal.M(q, check=False))
    Z, eye = np.zeros((nq, nq)), np.eye(nq)
    return control.ss(np.block([[Z, eye], [Jq, Jqd]]), np.vstack([Z, Bq]),
                      np.hstack([eye, Z]), Z)


def _square(name, W, nq):
    W = check_lti(W, name)
    if (W.noutputs, W.ninputs) == (1, 1) and nq > 1:
        W = expand_diagonal(W, nq)
    if (W.noutputs, W.ninputs) != (nq, nq):
        raise DimensionMismatchError(f"Expected {name} SISO or {nq} x {nq}, got "
                                     f"{W.noutputs} x {W.ninputs}")
    return W


def _shaped_loop(lam: float, W1, W2, Ks, nq: int):
    """Nominal shaped plant ``Gs = W2 G W1`` (eq. 11) and ``Ks``, both ``nq x nq``."""
    W1, W2, Ks = _square("W1", W1, nq), _square("W2", W2, nq), _square("Ks", Ks, nq)
    return _series(W2, fl_plant(lam, nq), W1), W1, W2, Ks


def frozen_certificate(nominal, plant, q, qd, *, lam: float, W1, W2, Ks,
                       qdd=None) -> FrozenCertificate:
    r"""Certify an uncertain arm at frozen configurations: ``max nugap(Gs_k, Gs) < b(Gs, Ks)``.

    For each configuration ``k`` the uncertain arm is linearized
    (:func:`frozen_linearization`), shaped like the design, ``Gs_k = W2 G_k W1``, and
    compared with the nominal shaped plant ``Gs = W2 G W1`` of eq. (11):

    .. math:: \delta_\nu(G_{s,k}, G_s) < b(G_s, K_s) \implies K_s \text{ stabilizes }
              G_{s,k},\quad \arcsin b(G_{s,k}, K_s) \ge \arcsin b(G_s, K_s)
              - \arcsin \delta_\nu(G_{s,k}, G_s)

    See the module docstring for what this proves and what it does not.

    Parameters
    ----------
    nominal, plant : Plant
        The controller's model and the uncertain (true) plant. A closed chain solves its
        passive coordinates from the last solution, in the order of ``q``: use
        :func:`certificate_along`, which takes both along the reference.
    q, qd : array-like, shape (N, nq)
        Frozen configurations [rad] and velocities [rad/s] along the reference.
    lam : float
        Feedback-linearization natural frequency [rad/s] (``Design.lam``).
    W1, W2 : control.LTI
        Loop-shaping weights, SISO or ``nq x nq`` (``Design.W1``, ``Design.W2``).
    Ks : control.LTI
        Negative-feedback controller of the shaped plant, SISO or ``nq x nq``
        (``Design.Ks_reduced`` for the eq. 18 controller, ``Design.ncf.Ks`` for the full one).
    qdd : array-like, shape (N, nq), optional
        Reference accelerations [rad/s^2] (default 0).

    Returns
    -------
    FrozenCertificate
        ``nugap`` per configuration, ``b``, guaranteed and computed frozen margins,
        ``certified``.

    Examples
    --------
    >>> d = design()                                           # doctest: +SKIP
    >>> cert = frozen_certificate(robot, uncertain, q, qd, lam=d.lam, W1=d.W1, W2=d.W2,
    ...                           Ks=d.Ks_reduced)             # doctest: +SKIP
    """
    nq = _check_pair(nominal, plant)
    q, qd, qdd = _configs(nq, q, qd, qdd)
    return _frozen(nominal, plant, q, qd, qdd, nq, lam, W1, W2, Ks)


def _frozen(nominal, plant, q, qd, qdd, nq, lam, W1, W2, Ks, visit=None) -> FrozenCertificate:
    """Return the certificate at the (checked) configurations ``q, qd, qdd``.

    ``visit(k)``, if given, first takes both models to configuration ``k``
    (:func:`certificate_along`).
    """
    lam = check_scalar_bandwidth("lam", lam, "the frozen certificate")
    Gs0, W1, W2, Ks = _shaped_loop(lam, W1, W2, Ks, nq)
    b = ncfmargin(Gs0, Ks)[0]
    G0, Gt0 = _graph_symbols_ct(Gs0)
    nus, bf = np.empty(q.shape[0]), np.empty(q.shape[0])
    for k in range(q.shape[0]):
        if visit is not None:
            visit(k)
        Gk = _linearization(nominal, plant, q[k], qd[k], qdd[k], lam, _H)
        Gsk = _series(W2, Gk, W1)
        Gk_sym, _ = _graph_symbols_ct(Gsk)
        nus[k] = _nugap(Gk_sym, G0, Gt0)
        bf[k] = ncfmargin(Gsk, Ks)[0]
    lower = np.array([_arcsin_bound(b, d) for d in nus])
    return FrozenCertificate(nugap=nus, b=float(b), b_lower=lower, b_frozen=bf,
                             certified=bool(nus.max() < b))


#: Time step [s] of the walk along the reference that takes each model to its frozen
#: configurations (:func:`certificate_along`): the study's task paths are sampled by inverse
#: kinematics every 5 ms too.
WALK_STEP = 0.005


def certificate_along(nominal, plant, reference, t, *, lam: float, W1, W2,
                      Ks) -> FrozenCertificate:
    r""":func:`frozen_certificate` at the reference's times ``t``, each model taken there.

    Both models start where the reference starts (:meth:`~rrr_pin.model.plant.Plant.reset`
    at ``r(0)``) and follow it (:meth:`~rrr_pin.model.plant.Plant.follow`) every
    :data:`WALK_STEP` [s] (at most) up to each frozen configuration before it is linearized,
    so a model that carries a solution from call to call (a closed chain's loop closure)
    stays on the assembly mode of the reference; for a serial arm this is exactly
    :func:`frozen_certificate` at ``reference.sample(t)``.

    Parameters
    ----------
    nominal, plant : Plant
        The controller's model and the uncertain plant (same ``nq``).
    reference : Reference
        ``reference.sample(t) -> (R, RD, RDD)`` [rad, rad/s, rad/s^2].
    t : array-like, shape (N,)
        Increasing times [s] of the frozen configurations, from ``t[0] >= 0``.
    lam, W1, W2, Ks
        As :func:`frozen_certificate`.

    Returns
    -------
    FrozenCertificate
    """
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0) \
            or t[0] < 0:
        raise ValueError(f"t must be a non-empty increasing array of finite times >= 0 [s], "
                         f"got {t!r}")
    nq = _check_pair(nominal, plant)
    R, RD, RDD = reference.sample(t)
    q, qd, qdd = _configs(nq, R, RD, RDD)
    check_scalar_bandwidth("lam", lam, "the certificate along a reference")
    r0 = reference.sample(np.array([0.0]))[0][0]
    for model in (nominal, plant):
        model.reset(r0)
    last = [0.0]

    def walk_to(k):
        walk = np.linspace(last[0], t[k], max(2, int(np.ceil((t[k] - last[0]) / WALK_STEP)) + 1))
        W = reference.sample(walk)[0]
        for model in (nominal, plant):
            model.follow(W, where=lambda i: f"reference at t = {walk[i]:.6g} s")
        last[0] = t[k]

    return _frozen(nominal, plant, q, qd, qdd, nq, lam, W1, W2, Ks, visit=walk_to)


def _matrices(sys) -> tuple:
    s = control.ss(sys)
    return tuple(np.asarray(m, dtype=float).tolist() for m in (s.A, s.B, s.C, s.D))


@dataclass(frozen=True)
class CertificateSpec:
    """What the study and the campaign certify per uncertain plant (picklable, JSON-ready).

    The loop-shaping design travels as state-space matrices (python-control systems do not
    pickle); :meth:`certify` checks a plant at ``points`` frozen configurations of the
    reference, evenly spaced over the run.

    Parameters
    ----------
    lam : float
        Feedback-linearization natural frequency of the design [rad/s].
    W1, W2, Ks : tuple
        ``(A, B, C, D)`` of the weights and of the shaped-plant controller (nested lists).
    points : int, default 8
        Frozen configurations per plant, >= 1.
    """

    lam: float
    W1: tuple
    W2: tuple
    Ks: tuple
    points: int = 8

    def __post_init__(self) -> None:
        object.__setattr__(self, "lam", check_scalar_bandwidth("lam", self.lam,
                                                               "the certificate"))
        object.__setattr__(self, "points", check_count("points", self.points, 1))

    @classmethod
    def from_design(cls, d, points: int = 8, reduced: bool = True) -> CertificateSpec:
        """From a :class:`rrr_pin.robust.loopshaping.Design` (the eq. 18 ``Ks`` by default)."""
        Ks = d.Ks_reduced if reduced else d.ncf.Ks
        return cls(float(d.lam), _matrices(d.W1), _matrices(d.W2), _matrices(Ks), points)

    def certify(self, nominal, plant, reference, duration: float) -> dict:
        """Certify ``plant`` along ``reference`` over ``[0, duration]``.

        Returns
        -------
        dict
            ``certified`` (bool), ``nugap_max`` and ``b`` (the design's ``b(Gs, Ks)``).
        """
        t = np.linspace(0.0, float(duration), self.points)
        cert = certificate_along(nominal, plant, reference, t, lam=self.lam,
                                 W1=control.ss(*self.W1), W2=control.ss(*self.W2),
                                 Ks=control.ss(*self.Ks))
        return {"certified": cert.certified, "nugap_max": float(cert.nugap_max), "b": cert.b}

    def margin(self, nq: int) -> float:
        """Return the design's NCF margin ``b(Gs, Ks)`` [-] for ``nq`` joints."""
        Gs, _, _, Ks = _shaped_loop(self.lam, control.ss(*self.W1), control.ss(*self.W2),
                                    control.ss(*self.Ks), nq)
        return float(ncfmargin(Gs, Ks)[0])

    def to_dict(self) -> dict:
        """JSON-ready description (recorded in results; a resume must match it)."""
        return {"lam_rad_s": self.lam, "points": self.points, "W1": self.W1, "W2": self.W2,
                "Ks": self.Ks}

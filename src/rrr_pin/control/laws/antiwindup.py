r"""H-infinity + FL told the actuator limits: ``K`` self-conditioned on the torque applied.

:class:`AntiWindupTracking` (Hanus, Kinnaert and Henrotte 1987), its sampled form, its
compiled form :class:`~rrr_pin.control.laws.forms.FLAWForm` and the built-in
:func:`hinf_aw_controller`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from ...validation import check_rate, check_scalar_bandwidth
from ..effects import check_torque_limit
from .forms import FLAWForm
from .protocol import DEFAULT_RATE, ControlLaw, SampledForm, SampledLaw
from .tracking import FLLinearModel, TrackingController, rebuild_tracking

__all__ = ["AntiWindupTracking", "SampledAntiWindup", "hanus_gain", "hinf_aw_controller"]


@dataclass(frozen=True, eq=False)
class AntiWindupTracking(TrackingController):
    r"""H-infinity + FL told the actuator limits: ``K`` conditioned on the torque applied.

    The torque of :class:`TrackingController` is clipped to the limits, and the state of ``K``
    is driven by what the clipped torque realises instead of what ``K`` asked for (Hanus's
    self-conditioned controller [4]_). Through the feedback-linearizing law (8), the applied
    ``tau_s`` realises ``taubar_hat = Mhat^-1 (tau_s - Vhat - Ghat)``, hence the output of ``K``

    .. math:: \hat y = \frac{\hat{\bar\tau} - \ddot r - 2\lambda(\dot r - \dot q)}
              {\lambda^2} - e = y + \frac{\hat M(q)^{-1} (\tau_s - \tau)}{\lambda^2},

    (``y_hat = tauhat_hat - Gfl^-1 r - e``, the ``tau-hat`` of eq. (8)-(10) actually realised,
    minus the feed-forward and the error terms). Hanus's form runs ``K`` on the error that
    would have produced ``y_hat``, ``e_r = D^-1 (y_hat - C x)`` (``D`` non-singular):

    .. math:: \dot x = A x + B e_r = (A - B D^{-1} C) x + B D^{-1} \hat y
              = A x + B e + B D^{-1} (\hat y - y), \qquad
              \tau_s = \mathrm{sat}\big(\hat M \bar\tau + \hat V + \hat G\big)

    with ``sat`` the clip to ``[-tau_max, tau_max]`` per joint. When no joint clips,
    ``y_hat = y`` and the law is :class:`TrackingController`'s exactly (the correction is not
    even computed). While saturated, ``x`` follows ``A - B D^-1 C``, whose eigenvalues are the
    zeros of ``K``: they must be stable (the paper's ``K``, eq. 18: -134.75 and -12.17 rad/s),
    so ``K`` cannot wind up. Sampled, the same with ``K``'s discrete matrices (``Dd``
    non-singular too): ``x+ = Ad x + Bd e + Bd Dd^-1 (y_hat - y)``.

    Parameters
    ----------
    nominal, lam, K, name, label
        As :class:`TrackingController`; ``K`` is required (``n x n`` or SISO).
    torque_limit : "urdf", float or array-like, shape (n,), default "urdf"
        Actuator limits ``tau_max`` [N m] > 0 the law clips to; ``"urdf"``: the nominal URDF's
        effort limits (:func:`rrr_pin.control.effects.check_torque_limit`).

    Raises
    ------
    ValueError
        No ``K``, a ``K`` whose ``D`` is singular (Hanus's form needs ``D^-1``), or whose zeros
        (the eigenvalues of ``A - B D^-1 C``) are unstable; bad limits
        (:class:`~rrr_pin.validation.FieldError` naming ``torque_limit``).

    References
    ----------
    .. [4] R. Hanus, M. Kinnaert, J.-L. Henrotte, "Conditioning technique, a general
       anti-windup and bumpless transfer method", *Automatica* 23(6) (1987) 729-739.
    """

    torque_limit: object = "urdf"
    _limit: np.ndarray = field(init=False, repr=False, compare=False)
    _gain: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.K is None:
            raise ValueError(f"law {self.name!r}: the self-conditioned (Hanus) form needs a "
                             f"controller K with a non-singular D; got K = None")
        super().__post_init__()
        limit = check_torque_limit(self.nominal, self.torque_limit)
        object.__setattr__(self, "_limit", limit)
        A, B, C, D = self._mats
        object.__setattr__(self, "_gain", hanus_gain(self.name, "D", A, B, C, D))

    @property
    def limit(self) -> np.ndarray:
        """Torque limits ``tau_max`` [N m], shape (n,)."""
        return self._limit

    def _conditioned(self, q, qd, r, rd, rdd, y):
        """Return ``(tau_s, dy)``: the clipped torque, and ``y_hat - y`` (None: no clip)."""
        lam = self.lam
        taubar = rdd + 2.0 * lam * (rd - qd) + lam * lam * ((r - q) + y)
        M, h = self.nominal.terms(q, qd)
        tau = M @ taubar + h
        if self.friction is not None:  # friction compensation, before the clip
            tau = tau + self.friction.torque(qd)
        lim = self._limit
        sat = np.minimum(np.maximum(tau, -lim), lim)
        if np.array_equal(sat, tau):
            return tau, None
        # per-joint lam: diag(lam)^-2 Mhat^-1 (tau_s - tau), elementwise
        return sat, np.linalg.solve(M, sat - tau) / (lam * lam)

    def torque(self, t, q, qd, r, rd, rdd, x) -> np.ndarray:
        """Eq. (8) clipped to the limits: ``sat(Mhat taubar + Vhat + Ghat)``."""
        _, _, C, D = self._mats
        return self._conditioned(q, qd, r, rd, rdd, C @ x + D @ (r - q))[0]

    def derivative(self, t, q, qd, r, rd, rdd, x) -> np.ndarray:
        """``xdot = A x + B e + B D^-1 (y_hat - y)`` (the last term only while clipped)."""
        A, B, C, D = self._mats
        e = r - q
        dy = self._conditioned(q, qd, r, rd, rdd, C @ x + D @ e)[1]
        xdot = A @ x + B @ e
        return xdot if dy is None else xdot + self._gain @ dy

    def sampled(self, rate: float = DEFAULT_RATE, method: str = "tustin") -> SampledLaw:
        """Digital version: ``K`` discretized by ``method``, conditioned with ``Bd Dd^-1``.

        Raises
        ------
        ValueError
            The discrete ``Dd`` is singular (or its zeros unstable) at this rate and method.
        """
        rate = check_rate("rate", rate)
        if type(self) is not AntiWindupTracking:
            return ControlLaw.sampled(self, rate, method)
        mats = self.discretize(rate, method)
        gain = hanus_gain(self.name, f"the discrete Dd ({method}, {rate:g} Hz)", *mats,
                           discrete=True)
        return SampledAntiWindup(self, rate, method, mats, gain)

    def linear_model(self) -> FLLinearModel | None:
        """Return the loop while nothing clips: :class:`TrackingController`'s."""
        if type(self) is not AntiWindupTracking:
            return None
        return FLLinearModel(self.n, self.lam, self._mats, self.discretize)

    def compiled_form(self) -> FLAWForm | None:
        """Return the :class:`FLAWForm` with ``K``'s continuous matrices (this exact class only)."""
        if type(self) is not AntiWindupTracking or self.friction is not None:
            return None  # with friction compensation: the Python engine only (no C++ form)
        A, B, C, D = self._mats
        return FLAWForm(self.nominal, self.lam, A, B, C, D, self._gain, self._limit)

    def __reduce__(self):
        state = {f.name: getattr(self, f.name) for f in fields(self) if f.init}
        state["K"] = self._mats
        state["torque_limit"] = tuple(self._limit.tolist())
        return (rebuild_tracking, (type(self), state))

    def describe(self) -> dict:
        """As :class:`TrackingController`, with the limits and the conditioning."""
        return {**super().describe(), "torque_limit_Nm": self._limit.tolist(),
                "anti_windup": "Hanus self-conditioned K (B D^-1), on Mhat^-1 (tau_s - tau)"}


def hanus_gain(name: str, what: str, A, B, C, D, *, discrete: bool = False) -> np.ndarray:
    """Return ``B D^-1`` of Hanus's form, or refuse a singular ``D`` or unstable zeros of K."""
    sv = np.linalg.svd(D, compute_uv=False)
    if sv.size == 0 or sv[-1] <= 1e-12 * max(sv[0], 1.0):
        raise ValueError(f"law {name!r}: the self-conditioned (Hanus) form needs K's {what} "
                         f"non-singular (it inverts it); its singular values are "
                         f"{sv.tolist()}")
    gain = np.linalg.solve(D.T, B.T).T  # B D^-1
    if A.shape[0]:
        zeros = np.linalg.eigvals(A - gain @ C)
        worst = np.max(np.abs(zeros)) if discrete else np.max(zeros.real)
        if worst >= (1.0 if discrete else 0.0):
            raise ValueError(f"law {name!r}: K has unstable zeros (eigenvalues of A - B D^-1 C: "
                             f"{np.round(zeros, 6).tolist()}), which the self-conditioned "
                             f"form would follow while the torque saturates")
    gain.setflags(write=False)
    return gain


class SampledAntiWindup(SampledForm):
    """Sampled :class:`AntiWindupTracking`: ``x+ = Ad x + Bd e + Bd Dd^-1 (y_hat - y)``."""

    def __init__(self, law: AntiWindupTracking, rate: float, method: str, mats, gain):
        super().__init__(law, rate)
        self.method, self.mats, self.gain = method, mats, gain

    def step(self, t, q, qd, r, rd, rdd, x):
        """Clipped output with the old state, then the conditioned state update."""
        Ad, Bd, Cd, Dd = self.mats
        e = r - q
        tau, dy = self.law._conditioned(q, qd, r, rd, rdd, Cd @ x + Dd @ e)
        x_next = Ad @ x + Bd @ e
        return tau, (x_next if dy is None else x_next + self.gain @ dy)

    def compiled_form(self):
        """Return the :class:`FLAWForm` with the discrete matrices and ``Bd Dd^-1``."""
        if type(self.law) is not AntiWindupTracking or self.law.friction is not None:
            return None
        Ad, Bd, Cd, Dd = self.mats
        return FLAWForm(self.law.nominal, self.law.lam, Ad, Bd, Cd, Dd, self.gain,
                        self.law.limit)

    def linear_model(self):
        """Return the unsaturated loop of the continuous law."""
        return self.law.linear_model()

    def describe(self):
        """Describe the continuous law, sampled."""
        return {**self.law.describe(), "time": "sampled", "rate_hz": self.rate,
                "discretization": self.method}


def hinf_aw_controller(nominal, K, lam: float = 45.0, *, torque_limit="urdf",
                       name: str = "hinf_aw", friction=None) -> AntiWindupTracking:
    """H-infinity + FL with anti-windup: :class:`AntiWindupTracking` (default ``lam = 45``).

    Parameters
    ----------
    nominal : Robot
        The controller's model.
    K : control LTI
        As :func:`hinf_fl_controller` (its ``D`` must be non-singular).
    lam : float, default 45
        FL bandwidth [rad/s].
    torque_limit : "urdf", float or array-like, shape (n,), default "urdf"
        Actuator limits [N m] the law knows; ``"urdf"``: the nominal URDF's effort limits.
    friction : rrr_pin.control.friction.JointFriction, optional
        Friction compensated (added before the clip); the law then runs on the Python engine
        only (it declares no compiled form).
    """
    lam = check_scalar_bandwidth("lam", lam, "the hinf_aw law (its K is the H-infinity "
                                             "design of one FL plant)")
    return AntiWindupTracking(nominal=nominal, lam=lam, K=K, name=name,
                              label="H-infinity + FL, anti-windup", torque_limit=torque_limit,
                              friction=friction)

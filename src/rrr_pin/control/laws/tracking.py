r"""The feedback-linearizing tracking laws: eq. (8)-(10) with a linear controller on the error.

:class:`TrackingController` (continuous ``K``, or none: FL alone) and
:class:`DiscreteTrackingController` (a discrete ``K`` at its own rate), with the built-ins
:func:`fl_controller` (eq. 20) and :func:`hinf_fl_controller` (eq. 8-10, 18-19), their compiled
form :class:`~rrr_pin.control.laws.forms.FLForm` and their loop :class:`FLLinearModel`. The
torque is

.. math:: \tau = \hat M(q)\,\bar\tau + \hat h(q, \dot q), \qquad
          (\hat M, \hat h) = \mathrm{nominal.terms}(q, \dot q),

whatever the nominal plant is (a serial arm's CRBA and nonlinear effects, a closed chain's
reduced model).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np
import scipy.linalg

from ...validation import check_bandwidth, check_rate, check_scalar_bandwidth
from .forms import FLForm, FLFrictionForm
from .protocol import (
    DEFAULT_RATE,
    ControlLaw,
    LinearModel,
    ModelLaw,
    SampledForm,
    SampledLaw,
    check_law,
)

__all__ = ["TrackingController", "DiscreteTrackingController", "SampledTracking",
           "FLLinearModel", "controller_ss", "fl_controller", "hinf_fl_controller",
           "lam_record"]


def controller_ss(K, n: int, discrete: bool = False):
    """LTI ``K`` as an ``n x n`` StateSpace (a SISO ``K`` is copied on the diagonal).

    ``discrete=False``: ``K`` must be continuous (a discrete one is refused, naming the law that
    takes it); ``discrete=True``: ``K`` must be discrete with a sampling time ``dt > 0`` [s].
    """
    import control
    import scipy.linalg

    from ...robust.lti import check_lti

    # Finite, proper: checked before any conversion (some hang on NaN).
    K = control.ss(check_lti(K, "K"))
    if not discrete and K.isdtime(strict=True):
        raise ValueError(f"K is a discrete-time system (dt = {K.dt!r} s) and "
                         f"TrackingController takes a continuous-time one (it discretizes it "
                         f"itself); a discrete K runs as a sampled law at its own rate: "
                         f"hinf_fl_controller(nominal, K) or DiscreteTrackingController")
    if discrete and (not K.isdtime(strict=True) or K.dt is True or not float(K.dt) > 0.0
                     or not math.isfinite(float(K.dt))):
        raise ValueError(f"K must be a discrete-time system with a sampling time dt > 0 [s] "
                         f"(its rate is 1/dt), got dt = {K.dt!r}")
    if (K.ninputs, K.noutputs) == (1, 1) and n > 1:
        A = scipy.linalg.block_diag(*[K.A] * n)
        B = scipy.linalg.block_diag(*[K.B] * n)
        C = scipy.linalg.block_diag(*[K.C] * n)
        D = scipy.linalg.block_diag(*[K.D] * n)
        K = control.ss(A, B, C, D, K.dt)
    if (K.ninputs, K.noutputs) != (n, n):
        raise ValueError(f"K must be SISO or {n} x {n}, got {K.noutputs} x {K.ninputs}")
    if discrete:
        if K.nstates and np.any(np.abs(np.linalg.eigvals(K.A)) > 1.0 + 1e-9):
            raise ValueError("K has unstable poles (|z| > 1); the tracking law expects a stable "
                             "controller")
    elif K.nstates and np.any(np.linalg.eigvals(K.A).real > 1e-9):
        raise ValueError("K has unstable poles; the tracking law expects a stable controller")
    return K


@dataclass(frozen=True, eq=False)
class FLLinearModel(LinearModel):
    r"""Linear loop of a feedback-linearizing law: per joint, ``qdd = taubar`` (``M`` cancels).

    .. math:: L(s) = \frac{2\lambda s + \lambda^2 (1 + K(s))}{s^2}

    Attributes
    ----------
    n : int
        Number of joints.
    lam : float or ndarray, shape (n,)
        Bandwidth ``lambda`` [rad/s], shared or one per joint (``diag(lam_j)`` in the loop).
    K : tuple of ndarray
        ``(A, B, C, D)`` of the continuous controller (block diagonal for a SISO ``K``; empty
        for FL alone), shapes (m, m), (m, n), (n, m), (n, n).
    discretize : callable
        ``discretize(rate) -> (Ad, Bd, Cd, Dd)``, the law's own Tustin discretization at
        ``rate`` [Hz] (:meth:`TrackingController.discretize`).
    """

    n: int
    lam: float
    K: tuple
    discretize: object

    def digital(self, rate, home):
        """Return ``u = lam^2 (Cd x - (I + Dd) q) - 2 lam qd``, ``x+ = Ad x - Bd q``, and ``I``.

        A per-joint ``lam`` scales row ``j`` by ``lam_j`` (``diag(lam)`` on the left).
        """
        n, lam = self.n, _rows(self.lam)
        Ad, Bd, Cd, Dd = self.discretize(rate)
        eye = np.eye(n)
        Dc = np.hstack([-lam * lam * (eye + Dd), -2.0 * lam * eye])
        Cc = lam * lam * Cd
        Bc = np.hstack([-Bd, np.zeros_like(Bd)])
        return Ad, Bc, Cc, Dc, eye

    def loops(self, home):
        """Return ``[L(s)]``: one loop if every joint has the same, else one per joint.

        The same: ``K`` SISO copied on the diagonal and ``lam`` shared. Any other ``K`` (a
        diagonal one of one ``K_j`` per joint) gives joint ``j`` its channel ``K_jj``, minimal
        (python-control's ``minreal``, SLICOT).
        """
        import control

        A, B, C, D = self.K
        n, nx = self.n, A.shape[0]
        s = control.tf("s")
        shared = np.ndim(self.lam) == 0
        lams = [self.lam] if shared else [float(x) for x in self.lam]
        if not nx:
            Ks = [control.tf([0.0], [1.0])] * len(lams)
        elif _copied(A, B, C, D, n):
            k = nx // n
            Ks = [control.tf(control.ss(A[:k, :k], B[:k, :1], C[:1, :k], D[:1, :1]))] * len(lams)
        else:
            Ks = [control.tf(control.minreal(control.ss(A, B[:, [j]], C[[j], :], D[[j]][:, [j]]),
                                             verbose=False)) for j in range(n)]
            lams = lams * n if shared else lams
        return [(2 * lam * s + lam * lam * (1 + K)) / s ** 2 for lam, K in zip(lams, Ks,
                                                                                strict=True)]

    def bandwidth(self, home):
        """Return ``lam`` [rad/s] (per joint: the smallest, the loop's slowest joint)."""
        return self.lam if np.ndim(self.lam) == 0 else float(np.min(self.lam))


@dataclass(frozen=True, eq=False)
class TrackingController(ModelLaw, ControlLaw):
    r"""Feedback-linearizing tracking law with an optional linear controller on the error.

    .. math:: \bar\tau = \ddot r + 2\lambda(\dot r - \dot q)
              + \lambda^2 \big(e + K(s) e\big), \quad
              \tau = \hat M(q) \bar\tau + \hat V(q, \dot q) + \hat G(q)

    Its state is the state of ``K`` (``xdot = A x + B e``, ``y = C x + D e``).

    Parameters
    ----------
    nominal : Robot
        The model the controller uses (never the simulated plant).
    lam : float or array-like, shape (n,)
        Bandwidth ``lambda`` of the linearized plant ``lam^2/(s + lam)^2`` [rad/s], eq. (10):
        one for every joint, or one per joint (``diag(lam_j)`` in the law; kept as a
        read-only vector, equal entries included), each finite and > 0.
    K : control LTI or None
        Continuous-time ``n x n`` (or SISO, copied on the diagonal) controller on
        ``e = r - q`` (negative feedback, ``y = K e``); ``None`` for feedback linearization
        alone.
    name : str
        Key in results and on the CLI.
    label : str
        Name in figures and tables.
    friction : rrr_pin.control.friction.JointFriction, optional
        Friction compensation: ``tau_f(qd) = Fv qd + Fc tanh(qd / v_eps)`` at the measured
        ``qd`` added to the torque (the nominal's friction, e.g. identified). None: none.
    """

    nominal: object
    lam: float
    K: object = None
    name: str = "fl"
    label: str = ""
    friction: object = None
    _mats: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if np.ndim(self.lam) == 0:
            lam = float(self.lam)
            if not (math.isfinite(lam) and lam > 0.0):
                raise ValueError(f"lam must be a positive finite bandwidth [rad/s], got "
                                 f"{self.lam!r}")
        else:  # one per joint, each checked (naming the joint)
            lam = check_bandwidth("lam", self.lam, self.nominal.joint_names)
        object.__setattr__(self, "lam", lam)
        n = self.nominal.nq
        if self.K is not None:
            K = controller_ss(self.K, n)
            mats = tuple(np.asarray(x, dtype=float) for x in (K.A, K.B, K.C, K.D))
            object.__setattr__(self, "K", K)
        else:
            mats = (np.zeros((0, 0)), np.zeros((0, n)), np.zeros((n, 0)), np.zeros((n, n)))
        object.__setattr__(self, "_mats", mats)
        if self.friction is not None:
            object.__setattr__(self, "friction", self.friction.check_joints(
                n, f"the nominal {self.nominal.name!r}"))
        check_law(self)

    def continuous_matrices(self):
        """Return ``(A, B, C, D)`` of ``K`` as arrays (empty for FL alone)."""
        return self._mats

    def discretize(self, rate: float = DEFAULT_RATE, method: str = "tustin"):
        """Discrete-time ``(Ad, Bd, Cd, Dd)`` of ``K`` for a sampled implementation.

        Parameters
        ----------
        rate : float, default 1000
            Sampling rate [Hz]; period ``Ts = 1/rate``.
        method : {"tustin", "zoh", "matched", ...}, default "tustin"
            Any method of :func:`control.sample_system`. Tustin (bilinear) keeps a stable
            ``K`` stable at any rate and maps ``s = j w`` onto the unit circle; its frequency
            warping at 1 kHz is under 1 % up to 400 rad/s.

        Returns
        -------
        Ad, Bd, Cd, Dd : ndarrays
            Shapes (nx, nx), (nx, n), (n, nx), (n, n).
        """
        rate = check_rate("rate", rate)
        if self.nx == 0:   # a static law: nothing to discretize (python-control not imported)
            return self._mats
        import control

        Kd = control.sample_system(self.K, 1.0 / rate, method=method)
        return tuple(np.asarray(x, dtype=float) for x in (Kd.A, Kd.B, Kd.C, Kd.D))

    def _tau(self, q, qd, r, rd, rdd, y):
        lam = self.lam
        taubar = rdd + 2.0 * lam * (rd - qd) + lam * lam * ((r - q) + y)
        M, h = self.nominal.terms(q, qd)  # the plant protocol: eq. (1)'s M and V + G
        if self.friction is not None:  # friction compensation, after eq. (8)'s terms
            return M @ taubar + h + self.friction.torque(qd)
        return M @ taubar + h

    def torque(self, t, q, qd, r, rd, rdd, x) -> np.ndarray:
        """Eq. (8): ``tau = Mhat taubar + Vhat + Ghat``, with ``y = C x + D e``."""
        _, _, C, D = self._mats
        return self._tau(q, qd, r, rd, rdd, C @ x + D @ (r - q))

    def derivative(self, t, q, qd, r, rd, rdd, x) -> np.ndarray:
        """State of ``K``: ``xdot = A x + B e``."""
        A, B, _, _ = self._mats
        return A @ x + B @ (r - q)

    def sampled(self, rate: float = DEFAULT_RATE, method: str = "tustin") -> SampledLaw:
        """Digital version: ``K`` discretized by ``method``, torque held between samples.

        A subclass that overrides :meth:`torque`, :meth:`derivative` or ``_tau`` changes the
        law, so the discretization of the built-in does not apply to it: a static subclass
        (``nx == 0``) is sampled by evaluating its own :meth:`torque`; one with state must
        override this method (``NotImplementedError`` otherwise).
        """
        rate = check_rate("rate", rate)
        if self._own_law():
            return SampledTracking(self, rate, method, self.discretize(rate, method))
        return ControlLaw.sampled(self, rate, method)

    def _own_law(self) -> bool:
        """Whether the torque is this class's (no subclass overrides the law's methods)."""
        cls = type(self)
        return all(getattr(cls, m) is getattr(TrackingController, m)
                   for m in ("torque", "derivative", "_tau"))

    def linear_model(self) -> FLLinearModel | None:
        """Return the :class:`FLLinearModel` (None if a subclass overrides the law's methods)."""
        if not self._own_law():
            return None
        return FLLinearModel(self.n, self.lam, self._mats, self.discretize)

    def compiled_form(self) -> FLForm | None:
        """Return the :class:`FLForm` with ``K``'s continuous matrices, for this exact class only.

        A subclass may change the law, so it gets None (the Python engine runs it).
        """
        if type(self) is not TrackingController:
            return None
        return _fl_form(self, *self._mats)

    def __reduce__(self):
        # control.StateSpace does not pickle (it holds a lambda): travel as matrices, rebuilt
        # as the same class (a subclass stays itself).
        state = {f.name: getattr(self, f.name) for f in fields(self) if f.init}
        state["K"] = self._mats if self.nx else None
        return (rebuild_tracking, (type(self), state))

    def describe(self) -> dict:
        """Name, class, bandwidth, ``K``'s order and the friction compensated (or None)."""
        return {**super().describe(), "lam_rad_s": lam_record(self.lam), "K_states": self.nx,
                "nominal": self.nominal.name, "friction_compensation":
                None if self.friction is None else self.friction.to_dict()}


def _copied(A, B, C, D, n: int) -> bool:
    """Whether ``(A, B, C, D)`` is one SISO block copied ``n`` times on the diagonal."""
    nx = A.shape[0]
    if nx % n:
        return False
    k = nx // n
    blocks = (A[:k, :k], B[:k, :1], C[:1, :k], D[:1, :1])
    want = [scipy.linalg.block_diag(*[b] * n) for b in blocks]
    return all(np.array_equal(x, w) for x, w in zip((A, B, C, D), want, strict=True))


def _rows(lam):
    """``lam`` as a factor on the rows of an (n, k) matrix: a number, or shape (n, 1)."""
    return lam if np.ndim(lam) == 0 else np.asarray(lam)[:, None]


def lam_record(lam):
    """JSON record of a bandwidth: a number, or a list of one per joint [rad/s]."""
    return float(lam) if np.ndim(lam) == 0 else [float(x) for x in lam]


def _fl_form(law, A, B, C, D):
    """:class:`FLForm` of a tracking law, or :class:`FLFrictionForm` when it compensates."""
    f = law.friction
    if f is None:
        return FLForm(law.nominal, law.lam, A, B, C, D)
    return FLFrictionForm(law.nominal, law.lam, A, B, C, D, np.asarray(f.viscous),
                          np.asarray(f.coulomb), f.coulomb_velocity)


def rebuild_tracking(cls, state):
    import control

    K = state.pop("K")
    return cls(**state, K=control.ss(*K) if K is not None else None)  # (A, B, C, D[, dt])


class SampledTracking(SampledForm):
    """Sampled :class:`TrackingController`: ``y = Cd x + Dd e``, ``x+ = Ad x + Bd e``."""

    def __init__(self, law: TrackingController, rate: float, method: str, mats):
        super().__init__(law, rate)
        self.method, self.mats = method, mats

    def step(self, t, q, qd, r, rd, rdd, x):
        """Output with the old state, then the state update."""
        if not self.nx:
            # FL alone: y = Cd x + Dd e is +0.0 exactly (empty Cd, zero Dd), x stays empty.
            return self.law._tau(q, qd, r, rd, rdd, 0.0), x
        Ad, Bd, Cd, Dd = self.mats
        e = r - q
        tau = self.law._tau(q, qd, r, rd, rdd, Cd @ x + Dd @ e)
        return tau, Ad @ x + Bd @ e

    def compiled_form(self):
        """Return the :class:`FLForm` with the discrete matrices (None for a subclassed law)."""
        if type(self.law) is not TrackingController:
            return None
        return _fl_form(self.law, *self.mats)

    def describe(self):
        """Describe the continuous law, sampled."""
        return {**self.law.describe(), "time": "sampled", "rate_hz": self.rate,
                "discretization": self.method}


@dataclass(frozen=True, eq=False)
class DiscreteTrackingController(ModelLaw, SampledLaw):
    r"""The tracking law of :class:`TrackingController` with a DISCRETE-time ``K``, sampled.

    .. math:: \bar\tau_k = \ddot r_k + 2\lambda(\dot r_k - \dot q_k)
              + \lambda^2 (e_k + y_k), \quad y_k = C x_k + D e_k, \quad
              x_{k+1} = A x_k + B e_k

    and ``tau_k = Mhat(q_k) taubar_k + Vhat(q_k, qd_k) + Ghat(q_k)``, held (zero-order hold)
    for one period. It runs at ``rate = 1 / K.dt`` [Hz], the rate ``K`` was designed for; a
    simulation at another rate is refused by name (:func:`rrr_pin.sim.simulation.simulate`).
    The discrete :func:`rrr_pin.robust.ncf.ncfsyn` result plugs straight in.

    Parameters
    ----------
    nominal : Robot
        The model the controller uses.
    lam : float or array-like, shape (n,)
        Bandwidth ``lambda`` [rad/s], eq. (10), shared or one per joint (as
        :class:`TrackingController`'s).
    K : control LTI
        Discrete-time ``n x n`` (or SISO, copied on the diagonal) stable controller on
        ``e = r - q`` (negative feedback) with sampling time ``K.dt > 0`` [s].
    name, label : str
        Key and display name.
    friction : rrr_pin.control.friction.JointFriction, optional
        Friction compensation, as :class:`TrackingController`'s.
    """

    nominal: object
    lam: float
    K: object
    name: str = "hinf"
    label: str = ""
    friction: object = None
    _mats: tuple = field(init=False, repr=False, compare=False)
    _fl: object = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        fl = TrackingController(self.nominal, self.lam, None, name=self.name,
                                friction=self.friction)
        K = controller_ss(self.K, self.nominal.nq, discrete=True)
        object.__setattr__(self, "lam", fl.lam)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "_fl", fl)
        object.__setattr__(self, "friction", fl.friction)
        object.__setattr__(self, "_mats",
                           tuple(np.asarray(x, dtype=float) for x in (K.A, K.B, K.C, K.D)))
        check_law(self)

    @property
    def rate(self) -> float:
        """Sampling rate ``1 / K.dt`` [Hz]."""
        return 1.0 / float(self.K.dt)

    def discrete_matrices(self):
        """Return ``(A, B, C, D)`` of the discrete ``K`` as arrays."""
        return self._mats

    def step(self, t, q, qd, r, rd, rdd, x):
        """Output with the old state, then the state update."""
        A, B, C, D = self._mats
        e = r - q
        tau = self._fl._tau(q, qd, r, rd, rdd, C @ x + D @ e)
        return tau, A @ x + B @ e

    def compiled_form(self) -> FLForm | None:
        """Return the :class:`FLForm` with the discrete matrices, for this exact class only."""
        if type(self) is not DiscreteTrackingController:
            return None
        return _fl_form(self, *self._mats)

    def __reduce__(self):
        # control.StateSpace does not pickle: travel as matrices and dt.
        state = {f.name: getattr(self, f.name) for f in fields(self) if f.init}
        state["K"] = (*self._mats, float(self.K.dt))
        return (rebuild_tracking, (type(self), state))

    def describe(self) -> dict:
        """Name, class, rate, bandwidth and ``K``'s order."""
        return {**super().describe(), "lam_rad_s": lam_record(self.lam), "K_states": self.nx,
                "K_dt_s": float(self.K.dt), "nominal": self.nominal.name,
                "friction_compensation":
                None if self.friction is None else self.friction.to_dict()}


def fl_controller(nominal, lam: float = 100.0, *, name: str = "fl",
                  friction=None) -> TrackingController:
    r"""Feedback linearization alone, eq. (20) with feed-forward (default ``lam = 100`` rad/s).

    .. math:: \bar\tau = \ddot r + 2\lambda(\dot r - \dot q) + \lambda^2 (r - q)

    ``friction`` (:class:`~rrr_pin.control.friction.JointFriction`): compensated, or None.
    """
    return TrackingController(nominal=nominal, lam=lam, K=None, name=name, label="FL alone",
                              friction=friction)


def hinf_fl_controller(nominal, K, lam: float = 45.0, *, name: str = "hinf",
                       friction=None) -> TrackingController | DiscreteTrackingController:
    """H-infinity + feedback linearization, eq. (8)-(10), (18)-(19) (default ``lam = 45`` rad/s).

    Parameters
    ----------
    nominal : Robot
        The controller's model.
    K : control LTI
        The loop-shaping controller (negative feedback on ``e = r - q``), SISO (copied on the
        diagonal) or ``n x n``; e.g. ``design().K_reduced``, the paper's eq. (18). Continuous
        time gives a :class:`TrackingController`; discrete time (``K.dt > 0`` [s], e.g. the
        discrete ``ncfsyn(...).K``) gives a :class:`DiscreteTrackingController`, a sampled law
        at ``1 / K.dt`` Hz.
    lam : float, default 45
        FL bandwidth the design assumed [rad/s]: one number (a per-joint ``lam`` is refused
        by name: ``K`` is the design of one FL plant, eq. 11).
    friction : rrr_pin.control.friction.JointFriction, optional
        Friction compensated by the law (None: none).
    """
    import control

    lam = check_scalar_bandwidth("lam", lam, "the hinf law (its K is the H-infinity design "
                                             "of one FL plant)")
    if isinstance(K, control.LTI) and K.isdtime(strict=True):
        return DiscreteTrackingController(nominal=nominal, lam=lam, K=K, name=name,
                                          label="H-infinity + FL", friction=friction)
    return TrackingController(nominal=nominal, lam=lam, K=K, name=name,
                              label="H-infinity + FL", friction=friction)

r"""Control laws: the protocol every law follows, and the built-ins.

A **control law** computes the joint torque from the time, the measured state, the reference
and its own state. Two kinds, as in Simulink's continuous and discrete blocks:

* :class:`ControlLaw`, continuous time: ``tau = torque(t, q, qd, r, rd, rdd, x)`` with the law's
  state ``x`` obeying ``xdot = derivative(t, q, qd, r, rd, rdd, x)``; the simulator integrates
  ``x`` with the arm. :meth:`ControlLaw.sampled` gives its digital (sampled) version.
* :class:`SampledLaw`, discrete time at ``rate`` Hz: ``tau, x_next = step(t, q, qd, r, rd,
  rdd, x)``; the torque is held (zero-order hold) until the next sample.

Write your own law by subclassing either one (see the README, "Your own controller"). The
simulator's Python engine runs any law. The compiled engine runs a law only if the law
declares a :class:`CompiledForm` (:meth:`ControlLaw.compiled_form`) that the C++ loop
implements exactly; the built-ins declare one for their exact class only, so a subclass that
overrides a method never runs the built-in's compiled code in its place.

Built in (each uses the NOMINAL model only; the simulated plant may differ):

* :func:`fl_controller`, feedback linearization alone (eq. 20), ``lam = 100`` rad/s;
* :func:`hinf_fl_controller`, H-infinity + feedback linearization (eq. 8-10, 18-19); with a
  discrete-time ``K`` it is a :class:`DiscreteTrackingController`, sampled at ``1 / K.dt`` Hz;
* :func:`hinf_aw_controller`, the same law told the actuator limits, its ``K`` conditioned on
  the torque actually applied (Hanus's self-conditioned form, :class:`AntiWindupTracking`);
* :func:`pd_controller`, the industrial baseline: PD plus gravity compensation,
  ``tau = Kp e + Kd ed + Ghat(q)``.

Block diagram of the two feedback-linearizing laws (one law, ``K = 0`` gives FL alone)::

                 feed-forward  rdd, rd
       r ----+---------------------------------------+
             |                                       v
       r -->(+)-- e --+-----------------> (+) -- lam^2 (e + y) + 2 lam (rd - qd) + rdd = taubar
             ^-       |                    ^                                          |
             |        +--> [ K(s) ] -- y --+                                          v
             |                                          tau = Mhat(q) taubar + Vhat(q, qd) + Ghat(q)
             |                                                                        |
             +-------------------------------------- q, qd <------- [ true arm ] <----+

With ``M = Mhat`` and ``V + G = Vhat + Ghat`` the arm obeys ``qdd = taubar`` and the error
``e = r - q`` obeys

.. math:: \ddot e + 2\lambda \dot e + \lambda^2 (I + K(s))\, e = -\eta,

where ``eta = (M^-1 Mhat - I) taubar + M^-1 (Vhat + Ghat - V - G)`` is zero for an exact model.

Why this feed-forward: it is the paper's eq. (8)-(10), ``taubar = -2 lam qd - lam^2 (q - tauhat)``,
with ``tauhat = Gfl^-1(s) r + K(s) e``, where ``Gfl^-1(s) r = r + 2 rd / lam + rdd / lam^2`` is the
inverse of the linearized plant (11) applied to the reference. That is the standard
two-degree-of-freedom structure: the model-inverse feed-forward makes the nominal reference-to-error
transfer exactly zero for both controllers (so on the exact model both track alike, as the paper
reports for Fig. 5), and the H-infinity controller ``K`` (eq. 18, negative feedback on ``e``) acts
only on the error the model mismatch ``eta`` causes. For FL alone (``K = 0``, ``lam = 100``) the
law reduces to the paper's eq. (20) with feed-forward:
``taubar = rdd + 2 lam (rd - qd) + lam^2 (r - q)``. The paper's open loop (19),
``q/r = K lam^2/(s + lam)^2``, is the loop this law closes around ``e``.

References
----------
.. [1] The paper, eq. (8)-(11), (18)-(20).
.. [2] S. Skogestad, I. Postlethwaite, *Multivariable Feedback Control*, 2nd ed., Wiley 2005,
   sec. 9.4 (two-degrees-of-freedom loop shaping).
.. [3] B. Siciliano et al., *Robotics: Modelling, Planning and Control*, Springer 2009,
   sec. 8.5.2 (PD control with gravity compensation).
.. [4] R. Hanus, M. Kinnaert, J.-L. Henrotte, "Conditioning technique, a general anti-windup
   and bumpless transfer method", *Automatica* 23(6) (1987) 729-739.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, fields
from typing import ClassVar

import numpy as np
import pinocchio as pin

from ..validation import check_matrix, check_positive, check_rate, check_vector, describe_value
from .effects import check_torque_limit

__all__ = [
    "ControlLaw",
    "SampledLaw",
    "CompiledForm",
    "FLForm",
    "FLAWForm",
    "PDForm",
    "LinearModel",
    "FLLinearModel",
    "PDLinearModel",
    "TrackingController",
    "AntiWindupTracking",
    "DiscreteTrackingController",
    "PDGravity",
    "fl_controller",
    "hinf_fl_controller",
    "hinf_aw_controller",
    "pd_controller",
    "TwoDOFController",
    "TwoDOFLinearModel",
    "hinf_2dof_controller",
    "TREF_BANDWIDTH",
    "check_law",
    "check_law_output",
    "check_step_output",
    "DEFAULT_RATE",
    "PD_BANDWIDTH",
]

#: Default sampling rate of the sampled (digital) controllers [Hz].
DEFAULT_RATE = 1000.0

#: Default closed-loop natural frequency of the PD baseline [rad/s] (see :func:`pd_controller`).
PD_BANDWIDTH = 20.0

_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


@dataclass(frozen=True, eq=False)
class CompiledForm:
    """Base of the compiled forms: what the compiled engine must run to reproduce a law exactly.

    A law declares its form with :meth:`ControlLaw.compiled_form`. Each subclass is one law the
    compiled engine may implement (:class:`FLForm`, :class:`PDForm`); the engine dispatches on
    the form's exact type and refuses any other (``ValueError`` naming it), so a form it does
    not know is never run as another.

    Attributes
    ----------
    nominal : Robot
        The law's model.
    kind : str
        Short name of the form (class attribute; messages and
        :func:`rrr_pin.sim.compiled.floor_ms`).
    """

    nominal: object
    kind: ClassVar[str] = ""


@dataclass(frozen=True, eq=False)
class FLForm(CompiledForm):
    r"""Feedback linearization with a linear controller on the error, eq. (8)-(10).

    .. math:: \bar\tau = \ddot r + 2\lambda(\dot r - \dot q) + \lambda^2 (e + y), \quad
              \tau = \hat M(q)\,\bar\tau + \hat V(q, \dot q) + \hat G(q)

    with ``e = r - q``, ``y = C x + D e`` and the controller state ``xdot = A x + B e``
    (continuous law) or ``x+ = A x + B e`` after the output (sampled law, matrices already
    discrete at its rate). FL alone has ``m = 0`` states and ``D = 0``.

    Attributes
    ----------
    nominal : Robot
        The law's model (``n = nominal.nq`` joints).
    lam : float
        Bandwidth ``lambda`` [rad/s], > 0.
    A, B, C, D : ndarray, shapes (m, m), (m, n), (n, m), (n, n)
        The controller ``K`` on ``e`` [rad] (output ``y`` in rad), negative feedback.
    """

    lam: float
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    kind: ClassVar[str] = "fl"

    def __post_init__(self) -> None:
        object.__setattr__(self, "lam", check_positive("lam", self.lam, unit="rad/s"))
        n = self.nominal.nq
        m = np.shape(self.A)[0] if np.ndim(self.A) == 2 else -1
        for key, shape in (("A", (m, m)), ("B", (m, n)), ("C", (n, m)), ("D", (n, n))):
            value = check_matrix(key, getattr(self, key), shape, readonly=True)
            object.__setattr__(self, key, value)


@dataclass(frozen=True, eq=False)
class FLAWForm(CompiledForm):
    r"""Feedback linearization with ``K`` self-conditioned on the saturated torque (Hanus).

    The law of :class:`FLForm`, its torque clipped to the limits, and ``K``'s state driven by
    the output ``y_hat`` the clipped torque realises (:class:`AntiWindupTracking`):

    .. math:: \tau_s = \mathrm{sat}(\tau), \quad
              \hat y - y = \hat M(q)^{-1} (\tau_s - \tau) / \lambda^2, \quad
              x^+ = A x + B e + L (\hat y - y)

    (sampled; continuous: ``xdot`` instead of ``x+``), with ``L = B D^-1``. The correction is
    computed only at samples where a joint clips (it is exactly zero otherwise).

    Attributes
    ----------
    nominal : Robot
        The law's model (``n = nominal.nq`` joints).
    lam : float
        Bandwidth ``lambda`` [rad/s], > 0.
    A, B, C, D : ndarray, shapes (m, m), (m, n), (n, m), (n, n)
        The controller ``K`` on ``e`` [rad], as in :class:`FLForm` (``m >= 1``).
    L : ndarray, shape (m, n)
        Conditioning gain ``B D^-1``.
    limit : ndarray, shape (n,)
        Torque limits ``tau_max`` [N m], > 0.
    """

    lam: float
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    L: np.ndarray
    limit: np.ndarray
    kind: ClassVar[str] = "fl_aw"

    def __post_init__(self) -> None:
        object.__setattr__(self, "lam", check_positive("lam", self.lam, unit="rad/s"))
        n = self.nominal.nq
        m = np.shape(self.A)[0] if np.ndim(self.A) == 2 else -1
        for key, shape in (("A", (m, m)), ("B", (m, n)), ("C", (n, m)), ("D", (n, n)),
                           ("L", (m, n))):
            value = check_matrix(key, getattr(self, key), shape, readonly=True)
            object.__setattr__(self, key, value)
        limit = check_vector("limit", self.limit, n, readonly=True)
        if not np.all(limit > 0):
            raise ValueError(f"limit must be > 0 per joint [N m], got {limit.tolist()}")
        object.__setattr__(self, "limit", limit)


@dataclass(frozen=True, eq=False)
class PDForm(CompiledForm):
    r"""PD control with gravity compensation.

    .. math:: \tau = K_p (r - q) + K_d (\dot r - \dot q) + \hat G(q)

    Attributes
    ----------
    nominal : Robot
        The law's model (``n = nominal.nq`` joints).
    Kp : ndarray, shape (n, n)
        Stiffness [N m/rad].
    Kd : ndarray, shape (n, n)
        Damping [N m s/rad].
    """

    Kp: np.ndarray
    Kd: np.ndarray
    kind: ClassVar[str] = "pd"

    def __post_init__(self) -> None:
        n = self.nominal.nq
        for key in ("Kp", "Kd"):
            value = check_matrix(key, getattr(self, key), (n, n), readonly=True)
            object.__setattr__(self, key, value)


class LinearModel:
    r"""The linear loop a law closes around the arm, for the predictions of ``stress``.

    Regulation (``r = 0``) with the law's model exact; the loop is broken at the torque input.
    :mod:`rrr_pin.campaign.stress` asks a law for it (:meth:`ControlLaw.linear_model`) and
    builds its digital and continuous predictions from these three methods.

    Attributes
    ----------
    n : int
        Number of joints (set by each subclass).
    """

    def digital(self, rate: float, home) -> tuple:
        """Return the law sampled at ``rate`` [Hz] and the plant's ``M^-1`` at ``home`` [rad].

        Returns
        -------
        Ac, Bc, Cc, Dc : ndarray, shapes (m, m), (m, 2n), (n, m), (n, 2n)
            The discrete law ``u = Cc x + Dc [q; qd]``, ``x+ = Ac x + Bc [q; qd]`` [N m].
        Minv : ndarray, shape (n, n)
            The plant ``qdd = Minv u`` [1/(kg m^2)].
        """
        raise NotImplementedError(f"{type(self).__name__} must implement digital()")

    def loops(self, home) -> list:
        """Return the SISO loops ``L(s)`` (``control.TransferFunction``), one per mode or joint."""
        raise NotImplementedError(f"{type(self).__name__} must implement loops()")

    def bandwidth(self, home) -> float:
        """Return the slowest closed-loop natural frequency [rad/s]."""
        raise NotImplementedError(f"{type(self).__name__} must implement bandwidth()")


@dataclass(frozen=True, eq=False)
class FLLinearModel(LinearModel):
    r"""Linear loop of a feedback-linearizing law: per joint, ``qdd = taubar`` (``M`` cancels).

    .. math:: L(s) = \frac{2\lambda s + \lambda^2 (1 + K(s))}{s^2}

    Attributes
    ----------
    n : int
        Number of joints.
    lam : float
        Bandwidth ``lambda`` [rad/s].
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
        """Return ``u = lam^2 (Cd x - (I + Dd) q) - 2 lam qd``, ``x+ = Ad x - Bd q``, and ``I``."""
        n, lam = self.n, self.lam
        Ad, Bd, Cd, Dd = self.discretize(rate)
        eye = np.eye(n)
        Dc = np.hstack([-lam * lam * (eye + Dd), -2.0 * lam * eye])
        Cc = lam * lam * Cd
        Bc = np.hstack([-Bd, np.zeros_like(Bd)])
        return Ad, Bc, Cc, Dc, eye

    def loops(self, home):
        """Return ``[L(s)]``: every joint has the same loop (``K`` SISO, copied on the diagonal)."""
        import control

        lam = self.lam
        A, B, C, D = self.K
        nx = A.shape[0]
        if nx:
            k = nx // self.n
            K = control.tf(control.ss(A[:k, :k], B[:k, :1], C[:1, :k], D[:1, :1]))
        else:
            K = control.tf([0.0], [1.0])
        s = control.tf("s")
        return [(2 * lam * s + lam * lam * (1 + K)) / s ** 2]

    def bandwidth(self, home):
        """Return ``lam`` [rad/s]."""
        return self.lam


@dataclass(frozen=True, eq=False)
class PDLinearModel(LinearModel):
    r"""Linear loop of PD + gravity at ``home``: ``qdd = M(q_h)^{-1} tau``, coupled.

    .. math:: L(s) = M(q_h)^{-1} (K_d s + K_p) / s^2

    Attributes
    ----------
    n : int
        Number of joints.
    nominal : Robot
        The law's model, whose ``M(q_h)`` [kg m^2] is taken at the configuration ``home``.
    Kp, Kd : ndarray, shape (n, n)
        Stiffness [N m/rad] and damping [N m s/rad].
    """

    n: int
    nominal: object
    Kp: np.ndarray
    Kd: np.ndarray

    def digital(self, rate, home):
        """Return the static law ``u = -(Kp q + Kd qd)`` (no state) and ``M(home)^-1``."""
        Minv = np.linalg.inv(self.nominal.M(home))
        Dc = np.hstack([-self.Kp, -self.Kd])
        return (np.zeros((0, 0)), np.zeros((0, 2 * self.n)), np.zeros((self.n, 0)), Dc, Minv)

    def loops(self, home):
        """Return one loop per mode of ``M^-1 Kp``, or per joint with ``M_jj`` if ``Kd`` couples.

        When ``M^-1 Kd`` is diagonal in the modes of ``M^-1 Kp`` (the default gains, both
        proportional to ``diag(M)``), each mode is a SISO loop; otherwise joint by joint with
        ``M_jj`` (coupling neglected).
        """
        import control

        M = self.nominal.M(home)
        s = control.tf("s")
        lp, V = np.linalg.eig(np.linalg.solve(M, self.Kp))
        Dm = np.linalg.solve(V, np.linalg.solve(M, self.Kd) @ V)
        if np.allclose(Dm, np.diag(np.diag(Dm)), atol=1e-9 * np.abs(Dm).max()) and np.allclose(
                lp.imag, 0) and np.allclose(np.diag(Dm).imag, 0):
            return [(float(d.real) * s + float(p.real)) / s ** 2
                    for p, d in zip(lp, np.diag(Dm), strict=True)]
        return [(self.Kd[j, j] * s + self.Kp[j, j]) / (M[j, j] * s ** 2) for j in range(self.n)]

    def bandwidth(self, home):
        """Return the square root of the slowest eigenvalue of ``M(home)^-1 Kp`` [rad/s]."""
        ev = np.linalg.eigvals(np.linalg.solve(self.nominal.M(home), self.Kp))
        return float(np.sqrt(np.min(np.abs(ev))))


class ControlLaw:
    """Base class of a continuous-time control law.

    Subclasses implement :meth:`torque`; a law with its own state also sets :attr:`nx`,
    implements :meth:`derivative` and, to run sampled, :meth:`sampled`.

    Attributes
    ----------
    name : str
        Short key, used in results, CSV columns and the CLI (letters, digits, ``_``).
    label : str
        Human-readable name for figures and tables.
    n : int
        Number of joints.
    nx : int
        Size of the law's state ``x`` (0 for a static law).
    """

    name: str = "law"
    label: str = ""
    n: int = 0
    nx: int = 0

    def initial_state(self) -> np.ndarray:
        """Return the law's state at ``t = 0``, shape (nx,) (zeros by default)."""
        return np.zeros(self.nx)

    def torque(self, t, q, qd, r, rd, rdd, x) -> np.ndarray:
        """Joint torque [N m], shape (n,).

        Parameters
        ----------
        t : float
            Time [s].
        q, qd : ndarray, shape (n,)
            Measured joint positions [rad] and velocities [rad/s].
        r, rd, rdd : ndarray, shape (n,)
            Reference position [rad], velocity [rad/s] and acceleration [rad/s^2].
        x : ndarray, shape (nx,)
            The law's state.
        """
        raise NotImplementedError(f"{type(self).__name__} must implement torque()")

    def derivative(self, t, q, qd, r, rd, rdd, x) -> np.ndarray:
        """Time derivative of the law's state, shape (nx,) (none by default)."""
        return np.zeros(self.nx)

    def sampled(self, rate: float, method: str = "tustin") -> SampledLaw:
        """Return the law run by a digital controller at ``rate`` Hz (zero-order hold).

        A static law (``nx == 0``) is sampled exactly by evaluating :meth:`torque` at the
        sampling instants. A law with state must override this method (it has to say how its
        state is discretized); otherwise ``NotImplementedError``.
        """
        if self.nx:
            raise NotImplementedError(
                f"law {self.name!r} has {self.nx} states and does not say how to discretize "
                f"them: override sampled(rate) or write it as a SampledLaw")
        return _StaticSampled(self, check_rate("rate", rate))

    def compiled_form(self) -> CompiledForm | None:
        """Return the compiled engine's exact equivalent of this law, or None (Python only)."""
        return None

    def linear_model(self) -> LinearModel | None:
        """Return the linear loop this law closes on the arm, or None (no linear prediction)."""
        return None

    def describe(self) -> dict:
        """JSON-ready description of the law (recorded in results)."""
        return {"name": self.name, "label": self.label or self.name,
                "class": f"{type(self).__module__}.{type(self).__qualname__}",
                "time": "continuous"}


class SampledLaw:
    """Base class of a discrete-time (digital) law sampled at :attr:`rate` Hz.

    Subclasses implement :meth:`step`. The simulator calls it at ``t_k = k / rate`` with the
    measured state and holds the returned torque until ``t_{k+1}``.

    Attributes
    ----------
    name, label, n, nx
        As for :class:`ControlLaw`.
    rate : float
        Sampling rate [Hz].
    """

    name: str = "law"
    label: str = ""
    n: int = 0
    nx: int = 0
    rate: float = DEFAULT_RATE

    def initial_state(self) -> np.ndarray:
        """Return the law's state at ``t = 0``, shape (nx,)."""
        return np.zeros(self.nx)

    def step(self, t, q, qd, r, rd, rdd, x) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(tau, x_next)``: the torque held on ``[t, t + 1/rate)`` and the next state.

        Arguments as for :meth:`ControlLaw.torque`.
        """
        raise NotImplementedError(f"{type(self).__name__} must implement step()")

    def compiled_form(self) -> CompiledForm | None:
        """Return the compiled engine's exact equivalent of this law, or None (Python only)."""
        return None

    def linear_model(self) -> LinearModel | None:
        """Return the linear loop this law closes on the arm, or None (no linear prediction)."""
        return None

    def describe(self) -> dict:
        """JSON-ready description of the law."""
        return {"name": self.name, "label": self.label or self.name,
                "class": f"{type(self).__module__}.{type(self).__qualname__}",
                "time": "sampled", "rate_hz": self.rate}


def check_law(law, n: int | None = None) -> None:
    """Check that ``law`` is a :class:`ControlLaw` or :class:`SampledLaw` for ``n`` joints.

    Raises
    ------
    TypeError
        Not a law.
    ValueError
        Bad name, or the wrong number of joints.
    """
    if not isinstance(law, (ControlLaw, SampledLaw)):
        raise TypeError(f"a control law must subclass rrr_pin.ControlLaw or rrr_pin.SampledLaw, "
                        f"got {type(law).__name__}")
    if not isinstance(law.name, str) or not _NAME.match(law.name):
        raise ValueError(f"law name must be letters, digits and '_' starting with a letter, got "
                         f"{law.name!r}")
    if n is not None and law.n != n:
        raise ValueError(f"law {law.name!r} is for {law.n} joints, the plant has {n}")
    if int(law.nx) != law.nx or law.nx < 0:
        raise ValueError(f"law {law.name!r}: nx must be an integer >= 0, got {law.nx!r}")


def _kind(law) -> str:
    """Return the law's class for a message (a continuous law sampled here: its own class)."""
    inner = getattr(law, "law", None)
    if type(law).__name__.startswith("_") and inner is not None:
        return f"{type(inner).__name__}, sampled at {law.rate:g} Hz"
    return type(law).__name__


def check_law_output(law, method: str, value, size: int, t: float) -> np.ndarray:
    """Check one value a law returned: a finite float ndarray of shape ``(size,)``.

    The simulator calls it on a law's first outputs (the edge where a user's law meets the
    engine) and trusts the later ones; a NaN or inf torque later in a run stops the run with
    its own reason (:data:`rrr_pin.sim.trajectory.REASONS`).

    Parameters
    ----------
    law : ControlLaw or SampledLaw
        The law, named in the message.
    method : str
        What returned ``value``, e.g. ``"torque()"``, ``"step() torque"``.
    value : object
        The returned value.
    size : int
        Required length (``n`` for a torque [N m], ``nx`` for a state).
    t : float
        Time of the call [s].

    Returns
    -------
    ndarray, shape (size,)
        ``value`` itself.

    Raises
    ------
    ValueError
        Naming the law, its class, the method, the time and what it returned: not a NumPy
        array (a scalar, None, a list), an array of another shape or of non-numbers, or an
        array with NaN or inf.
    """
    where = (f"law {law.name!r} ({_kind(law)}): {method} returned {{what}} at "
             f"t = {t:.6g} s; expected a finite float64 ndarray of shape ({size},)")
    if not isinstance(value, np.ndarray):
        raise ValueError(where.format(what=describe_value(value)))
    if value.shape != (size,) or value.dtype != np.float64:
        raise ValueError(where.format(what=f"an array of shape {value.shape} and dtype "
                                           f"{value.dtype}"))
    if not np.all(np.isfinite(value)):
        raise ValueError(where.format(what=f"the non-finite {value.tolist()}"))
    return value


def check_step_output(law, out, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Check what :meth:`SampledLaw.step` returned: ``(tau, x_next)`` (:func:`check_law_output`)."""
    if not isinstance(out, tuple) or len(out) != 2:
        raise ValueError(f"law {law.name!r} ({_kind(law)}): step() returned "
                         f"{describe_value(out)} at t = {t:.6g} s; expected a tuple (tau, x_next)")
    return (check_law_output(law, "step() torque", out[0], law.n, t),
            check_law_output(law, "step() next state", out[1], law.nx, t))


class _StaticSampled(SampledLaw):
    """A static continuous law evaluated at the sampling instants (exact for ``nx = 0``)."""

    def __init__(self, law: ControlLaw, rate: float):
        self.law, self.rate = law, rate
        self.name, self.label, self.n, self.nx = law.name, law.label, law.n, 0

    def step(self, t, q, qd, r, rd, rdd, x):
        """Evaluate the continuous law's torque; no state."""
        return self.law.torque(t, q, qd, r, rd, rdd, x), x

    def compiled_form(self):
        """Return the continuous law's compiled form (a static law samples exactly)."""
        return self.law.compiled_form()

    def describe(self):
        """Describe the continuous law, sampled."""
        return {**self.law.describe(), "time": "sampled", "rate_hz": self.rate}


def _as_statespace(K, n: int, discrete: bool = False):
    """LTI ``K`` as an ``n x n`` StateSpace (a SISO ``K`` is copied on the diagonal).

    ``discrete=False``: ``K`` must be continuous (a discrete one is refused, naming the law that
    takes it); ``discrete=True``: ``K`` must be discrete with a sampling time ``dt > 0`` [s].
    """
    import control
    import scipy.linalg

    from ..robust.lti import check_lti

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
class TrackingController(ControlLaw):
    r"""Feedback-linearizing tracking law with an optional linear controller on the error.

    .. math:: \bar\tau = \ddot r + 2\lambda(\dot r - \dot q)
              + \lambda^2 \big(e + K(s) e\big), \quad
              \tau = \hat M(q) \bar\tau + \hat V(q, \dot q) + \hat G(q)

    Its state is the state of ``K`` (``xdot = A x + B e``, ``y = C x + D e``).

    Parameters
    ----------
    nominal : Robot
        The model the controller uses (never the simulated plant).
    lam : float
        Bandwidth ``lambda`` of the linearized plant ``lam^2/(s + lam)^2`` [rad/s], eq. (10).
    K : control LTI or None
        Continuous-time ``n x n`` (or SISO, copied on the diagonal) controller on
        ``e = r - q`` (negative feedback, ``y = K e``); ``None`` for feedback linearization
        alone.
    name : str
        Key in results and on the CLI.
    label : str
        Name in figures and tables.
    """

    nominal: object
    lam: float
    K: object = None
    name: str = "fl"
    label: str = ""
    _mats: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        lam = float(self.lam)
        if not (math.isfinite(lam) and lam > 0.0):
            raise ValueError(f"lam must be a positive finite bandwidth [rad/s], got {self.lam!r}")
        object.__setattr__(self, "lam", lam)
        n = self.nominal.nq
        if self.K is not None:
            K = _as_statespace(self.K, n)
            mats = tuple(np.asarray(x, dtype=float) for x in (K.A, K.B, K.C, K.D))
            object.__setattr__(self, "K", K)
        else:
            mats = (np.zeros((0, 0)), np.zeros((0, n)), np.zeros((n, 0)), np.zeros((n, n)))
        object.__setattr__(self, "_mats", mats)
        check_law(self)

    @property
    def n(self) -> int:
        """Number of joints."""
        return self.nominal.nq

    @property
    def nx(self) -> int:
        """Number of controller states (0 for FL alone)."""
        return self._mats[0].shape[0]

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
        import control

        rate = check_rate("rate", rate)
        if self.nx == 0:
            return self._mats
        Kd = control.sample_system(self.K, 1.0 / rate, method=method)
        return tuple(np.asarray(x, dtype=float) for x in (Kd.A, Kd.B, Kd.C, Kd.D))

    def _tau(self, q, qd, r, rd, rdd, y):
        model, data, lam = self.nominal.model, self.nominal.data, self.lam
        taubar = rdd + 2.0 * lam * (rd - qd) + lam * lam * ((r - q) + y)
        # pin.crba's binding (pin >= 3, pinned to 4.1.0) returns a symmetric copy, its upper
        # triangle mirrored (as Robot.M documents): no NumPy triu to complete it (they cost a
        # third of the Python engine's time per step).
        return pin.crba(model, data, q) @ taubar + pin.nonLinearEffects(model, data, q, qd)

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
            return _SampledTracking(self, rate, method, self.discretize(rate, method))
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
        A, B, C, D = self._mats
        return FLForm(self.nominal, self.lam, A, B, C, D)

    def __reduce__(self):
        # control.StateSpace does not pickle (it holds a lambda): travel as matrices, rebuilt
        # as the same class (a subclass stays itself).
        state = {f.name: getattr(self, f.name) for f in fields(self) if f.init}
        state["K"] = self._mats if self.nx else None
        return (_rebuild_tracking, (type(self), state))

    def describe(self) -> dict:
        """Name, class, bandwidth and ``K``'s order."""
        return {**super().describe(), "lam_rad_s": self.lam, "K_states": self.nx,
                "nominal": self.nominal.name}


def _rebuild_tracking(cls, state):
    import control

    K = state.pop("K")
    return cls(**state, K=control.ss(*K) if K is not None else None)  # (A, B, C, D[, dt])


class _SampledTracking(SampledLaw):
    """Sampled :class:`TrackingController`: ``y = Cd x + Dd e``, ``x+ = Ad x + Bd e``."""

    def __init__(self, law: TrackingController, rate: float, method: str, mats):
        self.law, self.rate, self.method, self.mats = law, rate, method, mats
        self.name, self.label, self.n, self.nx = law.name, law.label, law.n, law.nx

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
        Ad, Bd, Cd, Dd = self.mats
        return FLForm(self.law.nominal, self.law.lam, Ad, Bd, Cd, Dd)

    def describe(self):
        """Describe the continuous law, sampled."""
        return {**self.law.describe(), "time": "sampled", "rate_hz": self.rate,
                "discretization": self.method}


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
        object.__setattr__(self, "_gain", _hanus_gain(self.name, "D", A, B, C, D))

    @property
    def limit(self) -> np.ndarray:
        """Torque limits ``tau_max`` [N m], shape (n,)."""
        return self._limit

    def _conditioned(self, q, qd, r, rd, rdd, y):
        """Return ``(tau_s, dy)``: the clipped torque, and ``y_hat - y`` (None: no clip)."""
        model, data, lam = self.nominal.model, self.nominal.data, self.lam
        taubar = rdd + 2.0 * lam * (rd - qd) + lam * lam * ((r - q) + y)
        M = pin.crba(model, data, q)
        tau = M @ taubar + pin.nonLinearEffects(model, data, q, qd)
        lim = self._limit
        sat = np.minimum(np.maximum(tau, -lim), lim)
        if np.array_equal(sat, tau):
            return tau, None
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
        gain = _hanus_gain(self.name, f"the discrete Dd ({method}, {rate:g} Hz)", *mats,
                           discrete=True)
        return _SampledAntiWindup(self, rate, method, mats, gain)

    def linear_model(self) -> FLLinearModel | None:
        """Return the loop while nothing clips: :class:`TrackingController`'s."""
        if type(self) is not AntiWindupTracking:
            return None
        return FLLinearModel(self.n, self.lam, self._mats, self.discretize)

    def compiled_form(self) -> FLAWForm | None:
        """Return the :class:`FLAWForm` with ``K``'s continuous matrices (this exact class only)."""
        if type(self) is not AntiWindupTracking:
            return None
        A, B, C, D = self._mats
        return FLAWForm(self.nominal, self.lam, A, B, C, D, self._gain, self._limit)

    def __reduce__(self):
        state = {f.name: getattr(self, f.name) for f in fields(self) if f.init}
        state["K"] = self._mats
        state["torque_limit"] = tuple(self._limit.tolist())
        return (_rebuild_tracking, (type(self), state))

    def describe(self) -> dict:
        """As :class:`TrackingController`, with the limits and the conditioning."""
        return {**super().describe(), "torque_limit_Nm": self._limit.tolist(),
                "anti_windup": "Hanus self-conditioned K (B D^-1), on Mhat^-1 (tau_s - tau)"}


def _hanus_gain(name: str, what: str, A, B, C, D, *, discrete: bool = False) -> np.ndarray:
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


class _SampledAntiWindup(SampledLaw):
    """Sampled :class:`AntiWindupTracking`: ``x+ = Ad x + Bd e + Bd Dd^-1 (y_hat - y)``."""

    def __init__(self, law: AntiWindupTracking, rate: float, method: str, mats, gain):
        self.law, self.rate, self.method, self.mats, self.gain = law, rate, method, mats, gain
        self.name, self.label, self.n, self.nx = law.name, law.label, law.n, law.nx

    def step(self, t, q, qd, r, rd, rdd, x):
        """Clipped output with the old state, then the conditioned state update."""
        Ad, Bd, Cd, Dd = self.mats
        e = r - q
        tau, dy = self.law._conditioned(q, qd, r, rd, rdd, Cd @ x + Dd @ e)
        x_next = Ad @ x + Bd @ e
        return tau, (x_next if dy is None else x_next + self.gain @ dy)

    def compiled_form(self):
        """Return the :class:`FLAWForm` with the discrete matrices and ``Bd Dd^-1``."""
        if type(self.law) is not AntiWindupTracking:
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


@dataclass(frozen=True, eq=False)
class DiscreteTrackingController(SampledLaw):
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
    lam : float
        Bandwidth ``lambda`` [rad/s], eq. (10).
    K : control LTI
        Discrete-time ``n x n`` (or SISO, copied on the diagonal) stable controller on
        ``e = r - q`` (negative feedback) with sampling time ``K.dt > 0`` [s].
    name, label : str
        Key and display name.
    """

    nominal: object
    lam: float
    K: object
    name: str = "hinf"
    label: str = ""
    _mats: tuple = field(init=False, repr=False, compare=False)
    _fl: object = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        fl = TrackingController(self.nominal, self.lam, None, name=self.name)
        K = _as_statespace(self.K, self.nominal.nq, discrete=True)
        object.__setattr__(self, "lam", fl.lam)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "_fl", fl)
        object.__setattr__(self, "_mats",
                           tuple(np.asarray(x, dtype=float) for x in (K.A, K.B, K.C, K.D)))
        check_law(self)

    @property
    def n(self) -> int:
        """Number of joints."""
        return self.nominal.nq

    @property
    def nx(self) -> int:
        """Number of controller states."""
        return self._mats[0].shape[0]

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
        return FLForm(self.nominal, self.lam, *self._mats)

    def __reduce__(self):
        # control.StateSpace does not pickle: travel as matrices and dt.
        state = {f.name: getattr(self, f.name) for f in fields(self) if f.init}
        state["K"] = (*self._mats, float(self.K.dt))
        return (_rebuild_tracking, (type(self), state))

    def describe(self) -> dict:
        """Name, class, rate, bandwidth and ``K``'s order."""
        return {**super().describe(), "lam_rad_s": self.lam, "K_states": self.nx,
                "K_dt_s": float(self.K.dt), "nominal": self.nominal.name}


@dataclass(frozen=True, eq=False)
class PDGravity(ControlLaw):
    r"""PD control with gravity compensation, the industrial baseline.

    .. math:: \tau = K_p (r - q) + K_d (\dot r - \dot q) + \hat G(q)

    No inertia or Coriolis feed-forward: it tracks a moving reference with an error that
    grows with the reference's acceleration.

    Parameters
    ----------
    nominal : Robot
        The model whose gravity torque ``Ghat`` is compensated.
    Kp : array-like, shape (n,) or (n, n)
        Stiffness [N m/rad]; a vector is a diagonal.
    Kd : array-like, shape (n,) or (n, n)
        Damping [N m s/rad].
    name, label : str
        Key and display name.
    """

    nominal: object
    Kp: np.ndarray
    Kd: np.ndarray
    name: str = "pd"
    label: str = ""

    def __post_init__(self) -> None:
        n = self.nominal.nq
        for key in ("Kp", "Kd"):
            K = np.asarray(getattr(self, key), dtype=float)
            K = np.diag(K) if K.ndim == 1 else K
            if K.shape != (n, n):
                raise ValueError(f"Expected {key} of shape ({n},) or ({n}, {n}), got {K.shape}")
            if not np.all(np.isfinite(K)):
                raise ValueError(f"{key} must be finite, got {K.tolist()}")
            K.setflags(write=False)
            object.__setattr__(self, key, K)
        check_law(self)

    @property
    def n(self) -> int:
        """Number of joints."""
        return self.nominal.nq

    def torque(self, t, q, qd, r, rd, rdd, x) -> np.ndarray:
        """``Kp e + Kd ed + Ghat(q)``."""
        model, data = self.nominal.model, self.nominal.data
        return (self.Kp @ (r - q) + self.Kd @ (rd - qd)
                + pin.computeGeneralizedGravity(model, data, q))

    def compiled_form(self) -> PDForm | None:
        """Return the :class:`PDForm`, for this exact class only."""
        if type(self) is not PDGravity:
            return None
        return PDForm(self.nominal, self.Kp, self.Kd)

    def linear_model(self) -> PDLinearModel | None:
        """Return the :class:`PDLinearModel` (None if a subclass overrides :meth:`torque`)."""
        if type(self).torque is not PDGravity.torque:
            return None
        return PDLinearModel(self.n, self.nominal, self.Kp, self.Kd)

    def describe(self) -> dict:
        """Name, class and gains."""
        return {**super().describe(), "Kp": self.Kp.tolist(), "Kd": self.Kd.tolist(),
                "nominal": self.nominal.name}


def fl_controller(nominal, lam: float = 100.0, *, name: str = "fl") -> TrackingController:
    r"""Feedback linearization alone, eq. (20) with feed-forward (default ``lam = 100`` rad/s).

    .. math:: \bar\tau = \ddot r + 2\lambda(\dot r - \dot q) + \lambda^2 (r - q)
    """
    return TrackingController(nominal=nominal, lam=lam, K=None, name=name, label="FL alone")


def hinf_fl_controller(nominal, K, lam: float = 45.0, *,
                       name: str = "hinf") -> TrackingController | DiscreteTrackingController:
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
        FL bandwidth the design assumed [rad/s].
    """
    import control

    if isinstance(K, control.LTI) and K.isdtime(strict=True):
        return DiscreteTrackingController(nominal=nominal, lam=lam, K=K, name=name,
                                          label="H-infinity + FL")
    return TrackingController(nominal=nominal, lam=lam, K=K, name=name,
                              label="H-infinity + FL")


def hinf_aw_controller(nominal, K, lam: float = 45.0, *, torque_limit="urdf",
                       name: str = "hinf_aw") -> AntiWindupTracking:
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
    """
    return AntiWindupTracking(nominal=nominal, lam=lam, K=K, name=name,
                              label="H-infinity + FL, anti-windup", torque_limit=torque_limit)


def pd_controller(nominal, wn: float = PD_BANDWIDTH, zeta: float = 1.0, *, q=None,
                  name: str = "pd") -> PDGravity:
    r"""PD + gravity compensation with gains from a per-joint second-order target.

    Default gains, per joint ``j``, from the diagonal of the nominal inertia matrix at ``q``:

    .. math:: K_{p,j} = \omega_n^2 \hat M_{jj}(q), \qquad K_{d,j} = 2 \zeta \omega_n \hat M_{jj}(q),

    so that each joint, seen alone with its own inertia, is a critically damped (``zeta = 1``)
    second-order loop of natural frequency ``wn``.

    Parameters
    ----------
    nominal : Robot
        The controller's model.
    wn : float, default 20
        Natural frequency [rad/s] (:data:`PD_BANDWIDTH`).
    zeta : float, default 1
        Damping ratio.
    q : array-like, shape (n,), optional
        Configuration where ``Mhat`` is evaluated [rad] (default: the neutral configuration,
        clipped into the joint limits).
    name : str, default "pd"
    """
    wn, zeta = float(wn), float(zeta)
    if not (math.isfinite(wn) and wn > 0.0):
        raise ValueError(f"wn must be > 0 rad/s, got {wn!r}")
    if not (math.isfinite(zeta) and zeta >= 0.0):
        raise ValueError(f"zeta must be >= 0, got {zeta!r}")
    if q is None:
        q = np.clip(nominal.neutral(), nominal.lower, nominal.upper)
    m = np.diag(nominal.M(q))
    return PDGravity(nominal, Kp=wn * wn * m, Kd=2.0 * zeta * wn * m, name=name,
                     label="PD + gravity")


# --- two degrees of freedom (issue 20) ----------------------------------------------------------

def _as_2dof_statespace(K, n: int):
    """Continuous LTI ``K`` as ``n x 2n`` on ``[r; q]`` (a ``1 x 2`` one copied per joint)."""
    import control
    import scipy.linalg

    from ..robust.lti import check_lti

    K = control.ss(check_lti(K, "K"))
    if K.isdtime(strict=True):
        raise ValueError("K must be a continuous-time system (dt = 0); it is discretized here")
    if (K.noutputs, K.ninputs) == (1, 2) and n > 1:
        blocks = [control.ss(K.A, K.B[:, i:i + 1], K.C, K.D[:, i:i + 1]) for i in (0, 1)]
        A = scipy.linalg.block_diag(*[K.A] * n)
        Br = scipy.linalg.block_diag(*[blocks[0].B] * n)
        Bq = scipy.linalg.block_diag(*[blocks[1].B] * n)
        C = scipy.linalg.block_diag(*[K.C] * n)
        Dr = np.eye(n) * float(K.D[0, 0])
        Dq = np.eye(n) * float(K.D[0, 1])
        K = control.ss(A, np.hstack([Br, Bq]), C, np.hstack([Dr, Dq]))
    if (K.noutputs, K.ninputs) != (n, 2 * n):
        raise ValueError(f"K must be 1 x 2 or {n} x {2 * n} (inputs [r; q]), got "
                         f"{K.noutputs} x {K.ninputs}")
    if K.nstates and np.any(np.linalg.eigvals(K.A).real > 1e-9):
        raise ValueError("K has unstable poles; the 2-DOF law expects a stable controller")
    return K


@dataclass(frozen=True, eq=False)
class TwoDOFLinearModel(LinearModel):
    r"""Linear loop of :class:`TwoDOFController` (``r = 0``): per joint ``qdd = taubar``.

    .. math:: L(s) = \frac{2\lambda s + \lambda^2 (1 + K_2(s))}{s^2}

    Attributes
    ----------
    n : int
        Number of joints.
    lam : float
        Bandwidth ``lambda`` [rad/s].
    K2 : control.StateSpace
        The feedback block, ``n x n`` (block diagonal, the same SISO block per joint).
    discretize : callable
        ``discretize(rate) -> (Ad, Bd, Cd, Dd)`` of the law's implemented form on
        ``[e; qd]`` (:meth:`TwoDOFController.discretize`).
    """

    n: int
    lam: float
    K2: object
    discretize: object

    def digital(self, rate, home):
        """Return the law's own digital form with ``r = 0`` (``e = -q``), and ``I``."""
        n, lam = self.n, self.lam
        Ad, Bd, Cd, Dd = self.discretize(rate)
        De, Dv = Dd[:, :n], Dd[:, n:]
        Bc = np.hstack([-Bd[:, :n], Bd[:, n:]])
        Dc = np.hstack([-lam * lam * De, lam * lam * Dv - 2.0 * lam * np.eye(n)])
        return Ad, Bc, lam * lam * Cd, Dc, np.eye(n)

    def loops(self, home):
        """Return ``[L(s)]`` (every joint has the same loop)."""
        import control

        K2 = self.K2
        k = K2.nstates // self.n
        k2 = control.tf(control.ss(K2.A[:k, :k], K2.B[:k, :1], K2.C[:1, :k], K2.D[:1, :1]))
        s = control.tf("s")
        lam = self.lam
        return [(2 * lam * s + lam * lam * (1 + k2)) / s ** 2]

    def bandwidth(self, home):
        """Return ``lam`` [rad/s]."""
        return self.lam


@dataclass(frozen=True, eq=False)
class TwoDOFController(ControlLaw):
    r"""Feedback linearization with a two-degrees-of-freedom controller ``K = [K1, -K2]``.

    .. math:: \hat\tau = K_1(s)\, r - K_2(s)\, q, \quad
              \bar\tau = \lambda^2 (\hat\tau - q) - 2 \lambda \dot q, \quad
              \tau = \hat M(q)\,\bar\tau + \hat V(q, \dot q) + \hat G(q)

    The FL inner loop is the paper's eq. (9)-(10) (``q / tauhat = lam^2 / (s + lam)^2``, eq. 11),
    and ``K`` is a :func:`rrr_pin.robust.ncf.ncfsyn_2dof` design on it: the prefilter ``K1``
    makes the nominal closed loop ``q / r`` follow the reference model, the feedback ``K2``
    gives the robustness of the Glover-McFarlane design. It reads only ``r`` (no ``rd``,
    ``rdd`` feed-forward).

    **Implemented form.** ``tauhat = q`` in steady state (``G(0) = 1``), so ``H = K1 - K2 - 1``
    has ``H(0) = 0`` and, with ``K = (A, [Br, Bq], C, [Dr, Dq])``, ``H(s) = s C (sI - A)^{-1}
    A^{-1} (Br + Bq)`` exactly. The law runs

    .. math:: \hat\tau = q + C x + D_r e, \qquad \dot x = A x + B_r e + A^{-1}(B_r + B_q)\,\dot q,
              \qquad e = r - q,

    the same transfer function as ``K1 r - K2 q``, but its state is zero at rest at any
    position: a ``K`` on ``[r; q]`` started from ``x = 0`` at ``q = r != 0`` would swing the
    arm by the whole position (0.43 rad on the RRR). ``|H(0)|`` is checked below 1e-9
    (relative to ``|K(0)|``) at construction; a ``K`` without it is refused.

    Runs on the Python engine: the compiled engine's :class:`FLForm` forwards ``rd`` and
    ``rdd`` and feeds ``K`` the error alone, which this law does not, so :meth:`compiled_form`
    is None (``engine="compiled"`` refuses it naming the law; ``"auto"`` runs it on Python).

    Parameters
    ----------
    nominal : Robot
        The controller's model.
    lam : float
        FL bandwidth [rad/s] the design assumed.
    K : control LTI
        Continuous ``n x 2n`` controller on ``[r; q]`` [rad] giving ``tauhat`` [rad], or a
        ``1 x 2`` one copied per joint (the ``K`` of :class:`rrr_pin.robust.ncf.NCF2DOFResult`),
        stable.
    name, label : str
        Key and display name.
    """

    nominal: object
    lam: float
    K: object
    name: str = "hinf2dof"
    label: str = ""
    _mats: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        import control

        object.__setattr__(self, "lam", check_positive("lam", self.lam, unit="rad/s"))
        n = self.nominal.nq
        K = _as_2dof_statespace(self.K, n)
        object.__setattr__(self, "K", K)
        A, B, C, D = (np.asarray(x, dtype=float) for x in (K.A, K.B, K.C, K.D))
        Br, Bq, Dr, Dq = B[:, :n], B[:, n:], D[:, :n], D[:, n:]
        dc = Dr + Dq - C @ np.linalg.solve(A, Br + Bq) if A.size else Dr + Dq
        scale = max(1.0, float(np.abs(np.asarray(control.dcgain(K))).max()))
        if not np.allclose(dc, np.eye(n), rtol=0.0, atol=1e-9 * scale):
            raise ValueError(f"K: K1(0) - K2(0) must be the identity (steady state tauhat = q "
                             f"of eq. 11, as ncfsyn_2dof's dc matching gives), got "
                             f"{np.round(dc, 12).tolist()}")
        Bv = np.linalg.solve(A, Br + Bq) if A.size else np.zeros((0, n))
        mats = (A, np.hstack([Br, Bv]), C, np.hstack([Dr, np.zeros((n, n))]))
        for m in mats:
            m.setflags(write=False)
        object.__setattr__(self, "_mats", mats)
        check_law(self)

    @property
    def n(self) -> int:
        """Number of joints."""
        return self.nominal.nq

    @property
    def nx(self) -> int:
        """Number of controller states."""
        return self._mats[0].shape[0]

    def _tau(self, q, qd, tauhat):
        model, data, lam = self.nominal.model, self.nominal.data, self.lam
        taubar = lam * lam * (tauhat - q) - 2.0 * lam * qd
        return pin.crba(model, data, q) @ taubar + pin.nonLinearEffects(model, data, q, qd)

    def torque(self, t, q, qd, r, rd, rdd, x) -> np.ndarray:
        """Eq. (8) with ``tauhat = q + C x + Dr (r - q)``."""
        _, _, C, D = self._mats
        return self._tau(q, qd, q + C @ x + D[:, :self.n] @ (r - q))

    def derivative(self, t, q, qd, r, rd, rdd, x) -> np.ndarray:
        """``xdot = A x + Br (r - q) + A^-1 (Br + Bq) qd``."""
        A, B, _, _ = self._mats
        return A @ x + B @ np.concatenate([r - q, qd])

    def discretize(self, rate: float = DEFAULT_RATE, method: str = "tustin"):
        """Return the implemented form at ``rate`` [Hz] on ``[e; qd]``: ``(Ad, Bd, Cd, Dd)``.

        Shapes (nx, nx), (nx, 2n), (n, nx), (n, 2n); ``method`` of
        :func:`control.sample_system` (Tustin by default).
        """
        import control

        rate = check_rate("rate", rate)
        Kd = control.sample_system(control.ss(*self._mats), 1.0 / rate, method=method)
        return tuple(np.asarray(x, dtype=float) for x in (Kd.A, Kd.B, Kd.C, Kd.D))

    def _own_law(self) -> bool:
        cls = type(self)
        return all(getattr(cls, m) is getattr(TwoDOFController, m)
                   for m in ("torque", "derivative", "_tau"))

    def sampled(self, rate: float = DEFAULT_RATE, method: str = "tustin") -> SampledLaw:
        """Digital version: the implemented form discretized by ``method``, torque held."""
        rate = check_rate("rate", rate)
        if self._own_law():
            return _SampledTwoDOF(self, rate, method, self.discretize(rate, method))
        return ControlLaw.sampled(self, rate, method)

    def linear_model(self) -> TwoDOFLinearModel | None:
        """Return the :class:`TwoDOFLinearModel` (None if a subclass overrides the law)."""
        if not self._own_law():
            return None
        import control

        K, n = self.K, self.n
        K2 = control.ss(K.A, K.B[:, n:], -K.C, -K.D[:, n:])
        return TwoDOFLinearModel(n, self.lam, K2, self.discretize)

    def __reduce__(self):
        # control.StateSpace does not pickle: travel as matrices.
        K = self.K
        mats = tuple(np.asarray(x, dtype=float) for x in (K.A, K.B, K.C, K.D))
        return (_rebuild_2dof, (type(self), self.nominal, self.lam, mats, self.name,
                                self.label))

    def describe(self) -> dict:
        """Name, class, bandwidth and ``K``'s order."""
        return {**super().describe(), "lam_rad_s": self.lam, "K_states": self.nx,
                "nominal": self.nominal.name}


def _rebuild_2dof(cls, nominal, lam, mats, name, label):
    import control

    return cls(nominal=nominal, lam=lam, K=control.ss(*mats), name=name, label=label)


class _SampledTwoDOF(SampledLaw):
    """Sampled :class:`TwoDOFController`: ``tauhat = q + Cd x + Dd v``, ``x+ = Ad x + Bd v``.

    ``v = [r - q; qd]``.
    """

    def __init__(self, law: TwoDOFController, rate: float, method: str, mats):
        self.law, self.rate, self.method, self.mats = law, rate, method, mats
        self.name, self.label, self.n, self.nx = law.name, law.label, law.n, law.nx

    def step(self, t, q, qd, r, rd, rdd, x):
        """Output with the old state, then the state update."""
        Ad, Bd, Cd, Dd = self.mats
        v = np.concatenate([r - q, qd])
        return self.law._tau(q, qd, q + Cd @ x + Dd @ v), Ad @ x + Bd @ v

    def linear_model(self):
        """Return the continuous law's linear model."""
        return self.law.linear_model()

    def describe(self):
        """Describe the continuous law, sampled."""
        return {**self.law.describe(), "time": "sampled", "rate_hz": self.rate,
                "discretization": self.method}


#: Reference-model bandwidth of :func:`hinf_2dof_controller`, in units of ``lam``.
TREF_BANDWIDTH = 2.0


def hinf_2dof_controller(nominal, lam: float = 45.0, wr: float | None = None, rho: float = 1.1,
                         *, name: str = "hinf2dof") -> TwoDOFController:
    r"""H-infinity + FL with the 2-DOF Glover-McFarlane design on the paper's loop shape.

    ``K = ncfsyn_2dof(G, Tref, rho, W1)`` per joint, with the FL plant ``G = lam^2 / (s +
    lam)^2`` (eq. 11), the paper's ``W1 = 25 (s + 11.5) / (s + 0.19)`` (eq. 16) and the
    critically damped reference model

    .. math:: T_{ref}(s) = \frac{\omega_r^2}{(s + \omega_r)^2}, \qquad \omega_r = 2 \lambda.

    Why this reference model (reachable under the torque limits): its impulse response
    ``wr^2 t e^{-wr t}`` is non-negative with unit integral, so the model's trajectory
    ``Tref r`` never has a larger peak velocity or acceleration than the reference ``r``
    itself (``sup |h * f| <= ||h||_1 sup |f|``, ``||h||_1 = Tref(0) = 1``), and it turns a step
    of ``r`` into an acceleration bounded by ``wr^2`` times the step. So the model asks for no
    more torque than the reference does, and a reference the arm can follow under its limits
    leaves the model reachable too. ``wr = 2 lam`` keeps its lag small: on the default sine
    (0.5 rad, 0.5 Hz) ``|1 - Tref(j pi)| = 0.07``.

    Parameters
    ----------
    nominal : Robot
        The controller's model.
    lam : float, default 45
        FL bandwidth [rad/s].
    wr : float, optional
        Reference-model bandwidth [rad/s]; default ``TREF_BANDWIDTH * lam``.
    rho : float, default 1.1
        Model-matching weight of :func:`rrr_pin.robust.ncf.ncfsyn_2dof`.
    name : str, default "hinf2dof"
    """
    import control

    from ..robust.loopshaping import fl_plant, lag_weight
    from ..robust.ncf import ncfsyn_2dof

    lam = check_positive("lam", lam, unit="rad/s")
    wr = TREF_BANDWIDTH * lam if wr is None else check_positive("wr", wr, unit="rad/s")
    s = control.tf("s")
    res = ncfsyn_2dof(fl_plant(lam, 1), wr * wr / (s + wr) ** 2, rho, lag_weight())
    return TwoDOFController(nominal=nominal, lam=lam, K=res.K, name=name,
                            label="H-infinity 2-DOF + FL")

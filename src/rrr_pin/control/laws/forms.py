"""Compiled forms: the typed, frozen records of what a compiled engine must run for a law.

A law declares its form with :meth:`~rrr_pin.control.laws.protocol.ControlLaw.compiled_form`;
an engine runs a form only if it implements its exact type (and refuses any other by name),
so a form it does not know is never run as another. A form's ``cpp`` names the C++ law that
implements it (a law of ``RRR_PIN_LAWS`` in ``src/rrr_pin/_ext/law.hpp``, a class of the
extension with the form's fields): the compiled and the batched engines run exactly the forms
whose own ``cpp`` the extension has (:func:`compiled_forms`). The nominal model of a form is a
:class:`~rrr_pin.model.plant.Plant` of any kind: ``M``, ``h`` and ``G`` are its
:meth:`~rrr_pin.model.plant.Plant.terms` and :meth:`~rrr_pin.model.plant.Plant.G`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np

from ...validation import check_bandwidth, check_matrix, check_positive, check_vector

__all__ = ["CompiledForm", "FLForm", "FLFrictionForm", "FLAWForm", "PDForm", "TwoDOFForm",
           "compiled_forms"]


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
    cpp : str or None
        The C++ law that implements this exact type (class attribute, set on the type itself,
        never inherited: a subclass is another law): its name in ``RRR_PIN_LAWS``
        (``src/rrr_pin/_ext/law.hpp``); None for a form no C++ law implements.
    """

    nominal: object
    kind: ClassVar[str] = ""
    cpp: ClassVar[str | None] = None

    def engine_fields(self) -> dict:
        """Return the fields a compiled law is filled with, by name (all but ``nominal``).

        The compiled laws take ``lam`` per joint (a vector of ``nominal.nq``): a shared
        ``lam`` is given as ``nq`` equal entries, the same numbers in every operation.
        """
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "nominal"}
        if "lam" in out:
            out["lam"] = np.broadcast_to(np.asarray(out["lam"], dtype=float),
                                         (self.nominal.nq,)).copy()
        return out


def _check_controller(form, *extra, inputs: int = 1) -> None:
    """Check ``lam`` and ``K``'s matrices ``A, B, C, D`` of ``form``, stored back read-only.

    ``K`` has ``inputs * n`` inputs (``B`` of shape ``(m, inputs n)``, ``D`` of ``(n, inputs
    n)``): 1 for a ``K`` on ``e``, 2 for one on ``[e; qd]``. ``extra`` names further matrices
    of ``B``'s shape (the conditioning gain ``L``).
    """
    object.__setattr__(form, "lam", check_bandwidth("lam", form.lam, form.nominal.joint_names))
    n = form.nominal.nq
    m = np.shape(form.A)[0] if np.ndim(form.A) == 2 else -1
    w = inputs * n
    shapes = [("A", (m, m)), ("B", (m, w)), ("C", (n, m)), ("D", (n, w))]
    shapes += [(key, (m, w)) for key in extra]
    for key, shape in shapes:
        object.__setattr__(form, key, check_matrix(key, getattr(form, key), shape,
                                                   readonly=True))


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
    lam : float or ndarray, shape (n,)
        Bandwidth ``lambda`` [rad/s], > 0: shared, or one per joint.
    A, B, C, D : ndarray, shapes (m, m), (m, n), (n, m), (n, n)
        The controller ``K`` on ``e`` [rad] (output ``y`` in rad), negative feedback.
    """

    lam: float
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    kind: ClassVar[str] = "fl"
    cpp: ClassVar[str | None] = "FLLaw"

    def __post_init__(self) -> None:
        _check_controller(self)


@dataclass(frozen=True, eq=False)
class FLFrictionForm(CompiledForm):
    r"""The law of :class:`FLForm` with friction compensation.

    .. math:: \tau = \hat M(q)\,\bar\tau + \hat V(q, \dot q) + \hat G(q)
              + F_v \dot q + F_c \tanh(\dot q / v_\varepsilon)

    (:class:`~rrr_pin.control.friction.JointFriction`). Its own type, so that an engine that
    implements :class:`FLForm` only refuses it by name instead of running it without the
    compensation; the exported C law implements it (:mod:`rrr_pin.deploy.sources`).

    Attributes
    ----------
    nominal, lam, A, B, C, D
        As :class:`FLForm`.
    viscous : ndarray, shape (n,)
        ``Fv`` [N m s/rad] >= 0.
    coulomb : ndarray, shape (n,)
        ``Fc`` [N m] >= 0.
    coulomb_velocity : float
        ``v_eps`` [rad/s] > 0.
    """

    lam: float
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    viscous: np.ndarray
    coulomb: np.ndarray
    coulomb_velocity: float
    kind: ClassVar[str] = "fl_friction"
    cpp: ClassVar[str | None] = None  # Python engine only

    def __post_init__(self) -> None:
        _check_controller(self)
        n = self.nominal.nq
        for key in ("viscous", "coulomb"):
            value = check_vector(key, getattr(self, key), n, readonly=True)
            if not np.all(value >= 0.0):
                raise ValueError(f"{key} must be >= 0 per joint, got {value.tolist()}")
            object.__setattr__(self, key, value)
        object.__setattr__(self, "coulomb_velocity", check_positive(
            "coulomb_velocity", self.coulomb_velocity, unit="rad/s"))


@dataclass(frozen=True, eq=False)
class FLAWForm(CompiledForm):
    r"""Feedback linearization with ``K`` self-conditioned on the saturated torque (Hanus).

    The law of :class:`FLForm`, its torque clipped to the limits, and ``K``'s state driven by
    the output ``y_hat`` the clipped torque realises (:class:`AntiWindupTracking`):

    .. math:: \tau_s = \mathrm{sat}(\tau), \quad
              \hat y - y = \Lambda^{-2} \hat M(q)^{-1} (\tau_s - \tau), \quad
              x^+ = A x + B e + L (\hat y - y)

    (sampled; continuous: ``xdot`` instead of ``x+``), with ``L = B D^-1``. The correction is
    computed only at samples where a joint clips (it is exactly zero otherwise).

    Attributes
    ----------
    nominal : Robot
        The law's model (``n = nominal.nq`` joints).
    lam : float or ndarray, shape (n,)
        Bandwidth ``lambda`` [rad/s], > 0: shared, or one per joint.
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
    cpp: ClassVar[str | None] = "FLAWLaw"

    def __post_init__(self) -> None:
        _check_controller(self, "L")
        n = self.nominal.nq
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
    cpp: ClassVar[str | None] = "PDLaw"

    def __post_init__(self) -> None:
        n = self.nominal.nq
        for key in ("Kp", "Kd"):
            value = check_matrix(key, getattr(self, key), (n, n), readonly=True)
            object.__setattr__(self, key, value)


@dataclass(frozen=True, eq=False)
class TwoDOFForm(CompiledForm):
    r"""Feedback linearization with a two-degrees-of-freedom controller on ``v = [e; qd]``.

    The implemented form of :class:`~rrr_pin.control.laws.TwoDOFController` (eq. 8-11 with
    ``tauhat`` from the 2-DOF ``K``; no ``rd``, ``rdd`` feed-forward):

    .. math:: \hat\tau = q + C x + D v, \quad v = \begin{bmatrix} r - q \\ \dot q
              \end{bmatrix}, \quad
              \bar\tau = \lambda^2 (\hat\tau - q) - 2\lambda \dot q, \quad
              \tau = \hat M(q)\,\bar\tau + \hat h(q, \dot q)

    and the controller state ``xdot = A x + B v`` (continuous law) or ``x+ = A x + B v`` after
    the output (sampled law, matrices already discrete at its rate). Its own type: an engine
    that implements :class:`FLForm` only refuses it by name (the two laws differ: FL forwards
    ``rd`` and ``rdd`` and feeds its ``K`` the error alone).

    Attributes
    ----------
    nominal : Robot
        The law's model (``n = nominal.nq`` joints).
    lam : float or ndarray, shape (n,)
        Bandwidth ``lambda`` [rad/s], > 0: shared, or one per joint.
    A : ndarray, shape (m, m)
        State matrix (``m >= 0`` controller states).
    B : ndarray, shape (m, 2 n)
        Input matrix on ``v = [e; qd]`` (``e`` [rad], ``qd`` [rad/s]).
    C : ndarray, shape (n, m)
        Output matrix (``tauhat`` [rad]).
    D : ndarray, shape (n, 2 n)
        Feed-through on ``v`` (the continuous law's ``[Dr, 0]``; its discretization's
        ``qd`` block is not zero).
    """

    lam: float
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    kind: ClassVar[str] = "twodof"
    cpp: ClassVar[str | None] = "TwoDOFLaw"

    def __post_init__(self) -> None:
        _check_controller(self, inputs=2)


def compiled_forms() -> list[type]:
    """Return every compiled form type that names its own C++ law (``cpp``), base first.

    The subclasses of :class:`CompiledForm` defined so far (the built-ins and any user's),
    whose ``cpp`` is set on the type itself; which of them the extension has is
    :func:`rrr_pin.sim.extension.law_name`'s test.
    """
    out, todo = [], list(CompiledForm.__subclasses__())
    while todo:
        cls = todo.pop(0)
        todo.extend(cls.__subclasses__())
        if vars(cls).get("cpp"):
            out.append(cls)
    return out

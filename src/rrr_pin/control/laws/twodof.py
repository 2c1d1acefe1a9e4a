r"""Feedback linearization with a two-degrees-of-freedom H-infinity controller (issue 20).

:class:`TwoDOFController` (``K = [K1, -K2]`` on ``[r; q]``, the Glover-McFarlane 2-DOF design),
its sampled form, its loop :class:`TwoDOFLinearModel` and the built-in
:func:`hinf_2dof_controller`, and its compiled form
:class:`~rrr_pin.control.laws.forms.TwoDOFForm` (run by the compiled and the batched engines).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...validation import check_positive, check_rate, check_scalar_bandwidth
from .forms import TwoDOFForm
from .protocol import (
    DEFAULT_RATE,
    ControlLaw,
    LinearModel,
    ModelLaw,
    SampledForm,
    SampledLaw,
    check_law,
)

__all__ = ["TwoDOFController", "TwoDOFLinearModel", "SampledTwoDOF", "hinf_2dof_controller",
           "TREF_BANDWIDTH"]


def _as_2dof_statespace(K, n: int):
    """Continuous LTI ``K`` as ``n x 2n`` on ``[r; q]`` (a ``1 x 2`` one copied per joint)."""
    import control
    import scipy.linalg

    from ...robust.lti import check_lti

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
class TwoDOFController(ModelLaw, ControlLaw):
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

    Its compiled form is its own type, :class:`~rrr_pin.control.laws.forms.TwoDOFForm`
    (``A``, ``B`` on ``[e; qd]``, ``C``, ``D = [Dr, 0]``; not :class:`FLForm`, which forwards
    ``rd`` and ``rdd`` and feeds ``K`` the error alone): the compiled engine runs it on
    Pinocchio and the batched engine on generated dynamics, operation for operation as
    :meth:`torque` and :meth:`derivative` (or :class:`SampledTwoDOF`'s ``step``). A subclass
    gets no compiled form (it may change the law) and runs on the Python engine.

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

        object.__setattr__(self, "lam", check_scalar_bandwidth("lam", self.lam,
                                                               "the 2-DOF law"))
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

    def _tau(self, q, qd, tauhat):
        lam = self.lam
        taubar = lam * lam * (tauhat - q) - 2.0 * lam * qd
        M, h = self.nominal.terms(q, qd)
        return M @ taubar + h

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
        """Whether the torque is this class's (no subclass overrides the law's methods)."""
        cls = type(self)
        return all(getattr(cls, m) is getattr(TwoDOFController, m)
                   for m in ("torque", "derivative", "_tau"))

    def sampled(self, rate: float = DEFAULT_RATE, method: str = "tustin") -> SampledLaw:
        """Digital version: the implemented form discretized by ``method``, torque held."""
        rate = check_rate("rate", rate)
        if self._own_law():
            return SampledTwoDOF(self, rate, method, self.discretize(rate, method))
        return ControlLaw.sampled(self, rate, method)

    def compiled_form(self) -> TwoDOFForm | None:
        """Return the :class:`TwoDOFForm` with the continuous matrices, for this exact class only.

        A subclass may change the law, so it gets None (the Python engine runs it).
        """
        if type(self) is not TwoDOFController:
            return None
        return TwoDOFForm(self.nominal, self.lam, *self._mats)

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


class SampledTwoDOF(SampledForm):
    """Sampled :class:`TwoDOFController`: ``tauhat = q + Cd x + Dd v``, ``x+ = Ad x + Bd v``.

    ``v = [r - q; qd]``.
    """

    def __init__(self, law: TwoDOFController, rate: float, method: str, mats):
        super().__init__(law, rate)
        self.method, self.mats = method, mats

    def step(self, t, q, qd, r, rd, rdd, x):
        """Output with the old state, then the state update."""
        Ad, Bd, Cd, Dd = self.mats
        v = np.concatenate([r - q, qd])
        return self.law._tau(q, qd, q + Cd @ x + Dd @ v), Ad @ x + Bd @ v

    def compiled_form(self):
        """Return the :class:`TwoDOFForm` with the discrete matrices (None for a subclassed law)."""
        if type(self.law) is not TwoDOFController:
            return None
        return TwoDOFForm(self.law.nominal, self.law.lam, *self.mats)

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

    from ...robust.loopshaping import fl_plant, lag_weight
    from ...robust.ncf import ncfsyn_2dof

    lam = check_scalar_bandwidth("lam", lam, "the hinf2dof law's H-infinity design")
    wr = TREF_BANDWIDTH * lam if wr is None else check_positive("wr", wr, unit="rad/s")
    s = control.tf("s")
    res = ncfsyn_2dof(fl_plant(lam, 1), wr * wr / (s + wr) ** 2, rho, lag_weight())
    return TwoDOFController(nominal=nominal, lam=lam, K=res.K, name=name,
                            label="H-infinity 2-DOF + FL")

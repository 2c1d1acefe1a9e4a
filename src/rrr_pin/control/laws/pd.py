r"""PD control with gravity compensation, the industrial baseline.

:class:`PDGravity`, ``tau = Kp e + Kd ed + Ghat(q)`` with ``Ghat`` the nominal plant's
:meth:`~rrr_pin.model.plant.Plant.G` (a closed chain's reduced gravity included), its compiled
form :class:`~rrr_pin.control.laws.forms.PDForm`, its loop :class:`PDLinearModel` and the
built-in :func:`pd_controller`.

References
----------
.. [1] B. Siciliano et al., *Robotics: Modelling, Planning and Control*, Springer 2009,
   sec. 8.5.2 (PD control with gravity compensation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .forms import PDForm
from .protocol import ControlLaw, LinearModel, check_law

__all__ = ["PDGravity", "PDLinearModel", "pd_controller", "PD_BANDWIDTH"]

#: Default closed-loop natural frequency of the PD baseline [rad/s] (see :func:`pd_controller`).
PD_BANDWIDTH = 20.0


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
        return self.Kp @ (r - q) + self.Kd @ (rd - qd) + self.nominal.G(q, check=False)

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

r"""Excitation trajectories for identification: finite Fourier series (Swevers et al. 1997).

Joint ``j`` follows, with base pulsation ``w = 2 pi f`` and ``L`` harmonics,

.. math:: q_j(t) = q_{0j} + \sum_{l=1}^{L} \frac{a_{jl}}{w l} \sin(w l t)
          - \frac{b_{jl}}{w l} \cos(w l t),

so ``qd_j = sum_l a_jl cos(w l t) + b_jl sin(w l t)``. The trajectory is periodic with period
``1 / f``; it starts and ends (after a whole number of periods) at rest, ``qd = qdd = 0``, by the
choice ``a_j1 = -sum_{l>=2} a_jl`` and ``b_j1 = -sum_{l>=2} l b_jl``.

:func:`design_excitation` chooses the free coefficients and the offsets ``q0`` to minimise the
condition number of the base regressor (:mod:`rrr_pin.model.identification`) stacked over
``points`` instants of one period, with SLSQP (``scipy.optimize.minimize``), under the joint,
velocity and acceleration limits imposed at ``2 points`` instants with a 2 % margin (the limits
are linear in the coefficients, their Jacobian exact). It starts from random coefficients
scaled inside the limits, which is also the random trajectory it reports for comparison.

References
----------
.. [1] J. Swevers, C. Ganseman, D. B. Tukel, J. De Schutter and H. Van Brussel, "Optimal robot
   excitation and identification", IEEE Trans. Robotics and Automation 13(5), 1997.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..validation import FieldError, check_count, check_positive

__all__ = ["FourierTrajectory", "design_excitation", "LIMIT_MARGIN", "MAX_HARMONICS"]

#: Upper bound of the harmonics per joint of :func:`design_excitation` (a 6-joint arm at 200:
#: 7,200 SLSQP variables; 2000 ran past 90 s, issue 31).
MAX_HARMONICS = 200

#: Fraction of every limit the optimisation may use (the rest covers the time between the
#: instants where the limits are imposed).
LIMIT_MARGIN = 0.98


@dataclass(frozen=True)
class FourierTrajectory:
    """A finite Fourier series per joint (see the module docstring).

    Parameters
    ----------
    frequency : float
        Base frequency ``f`` [Hz].
    a, b : ndarray, shape (n, L)
        Coefficients [rad/s].
    q0 : ndarray, shape (n,)
        Offsets [rad].
    periods : int
        Periods in :attr:`duration`.
    """

    frequency: float
    a: np.ndarray
    b: np.ndarray
    q0: np.ndarray
    periods: int = 1

    @property
    def duration(self) -> float:
        """``periods / frequency`` [s]."""
        return self.periods / self.frequency

    def sample(self, t):
        """``(q, qd, qdd)`` at times ``t`` (shape (N,)) [s], each shape (N, n)."""
        t = np.asarray(t, dtype=float)
        w = 2.0 * math.pi * self.frequency
        L = self.a.shape[1]
        wl = w * np.arange(1, L + 1)
        s, c = np.sin(np.outer(t, wl)), np.cos(np.outer(t, wl))
        q = self.q0 + s @ (self.a / wl).T - c @ (self.b / wl).T
        qd = c @ self.a.T + s @ self.b.T
        qdd = -s @ (self.a * wl).T + c @ (self.b * wl).T
        return q, qd, qdd

    def write_csv(self, path, rate: float = 100.0, joint_names=None) -> Path:
        """Write waypoints at ``rate`` [Hz] for ``--reference spline --csv``: ``t, q_<joint>``.

        The spline reference (:class:`rrr_pin.control.references.SplineReference`) is clamped
        (at rest) at both ends, as this trajectory is.
        """
        from ..outputs import writing

        rate = check_positive("rate", rate, unit="Hz")
        count = int(round(self.duration * rate))
        t = np.linspace(0.0, self.duration, count + 1)
        q = self.sample(t)[0]
        names = joint_names or [f"joint{j + 1}" for j in range(q.shape[1])]
        path = Path(path)
        lines = [",".join(["t"] + [f"q_{n}" for n in names])]
        rows = np.column_stack([t, q])
        lines += [",".join(repr(float(v)) for v in row) for row in rows]
        with writing(path):
            path.write_text("\n".join(lines) + "\n")
        return path

    def to_dict(self) -> dict:
        """JSON-ready coefficients."""
        return {"kind": "fourier", "frequency_hz": self.frequency, "periods": self.periods,
                "duration_s": self.duration, "a_rad_s": self.a.tolist(),
                "b_rad_s": self.b.tolist(), "q0_rad": self.q0.tolist()}


def _unpack(x, n: int, L: int):
    free = x[: 2 * n * (L - 1)].reshape(2, n, L - 1)
    q0 = x[2 * n * (L - 1):]
    l = np.arange(2, L + 1)
    a = np.concatenate([-free[0].sum(axis=1, keepdims=True), free[0]], axis=1)
    b = np.concatenate([-(free[1] * l).sum(axis=1, keepdims=True), free[1]], axis=1)
    return a, b, q0


def _cond(robot, base, traj, t) -> float:
    from .identification import regressor

    W = base.reduce(regressor(robot, *traj.sample(t)))
    s = np.linalg.svd(W, compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0.0 else math.inf


def design_excitation(robot, *, harmonics: int = 5, frequency: float = 0.2,
                      max_acceleration: float = 10.0, periods: int = 2, points: int = 100,
                      seed: int = 0, maxiter: int = 60, base=None):
    """Optimise a Fourier excitation for the base regressor's condition number.

    Parameters
    ----------
    robot : rrr_pin.model.dynamics.Robot
    harmonics : int, default 5
        ``L >= 2``.
    frequency : float, default 0.2
        Base frequency [Hz]; the period is ``1 / frequency``.
    max_acceleration : float, default 10
        Acceleration limit of every joint [rad/s^2] (URDF has none).
    periods : int, default 2
        Periods of the trajectory returned.
    points : int, default 100
        Instants of one period where the regressor is stacked (the limits: ``2 points``).
    seed, maxiter : int
        Seed of the starting point; SLSQP iterations.
    base : BaseParameters, optional
        Default :func:`rrr_pin.model.identification.base_parameters`.

    Returns
    -------
    trajectory : FourierTrajectory
    info : dict
        ``cond`` (optimised), ``cond_random`` (the random start), the limits used, SLSQP's
        message.

    Raises
    ------
    ValueError
        A bad option, or a joint without a finite velocity limit.
    """
    from scipy.optimize import minimize

    from .identification import base_parameters

    L = check_count("harmonics", harmonics, 2)
    if L > MAX_HARMONICS:  # 6 n L SLSQP variables: bound the work before any
        raise FieldError("harmonics", f"{{name}} must be <= {MAX_HARMONICS} (6 x joints x "
                         f"harmonics SLSQP variables), got {L}")
    frequency = check_positive("frequency", frequency, unit="Hz")
    amax = check_positive("max_acceleration", max_acceleration, unit="rad/s^2")
    periods = check_count("periods", periods, 1)
    points = check_count("points", points, 10)
    maxiter = check_count("maxiter", maxiter, 1)
    base = base_parameters(robot) if base is None else base
    n = robot.nq
    vmax = np.asarray(robot.model.velocityLimit, dtype=float)
    if not np.all(np.isfinite(vmax) & (vmax > 0.0)):
        raise ValueError(f"every joint needs a finite velocity limit > 0 for an excitation; "
                         f"the URDF gives {vmax.tolist()} rad/s")
    mid = np.where(np.isfinite(robot.lower) & np.isfinite(robot.upper),
                   0.5 * (robot.lower + robot.upper), 0.0)
    half = np.where(np.isfinite(robot.lower) & np.isfinite(robot.upper),
                    0.5 * (robot.upper - robot.lower), math.pi)
    lo, hi = mid - LIMIT_MARGIN * half, mid + LIMIT_MARGIN * half
    T = 1.0 / frequency
    t_obj = np.linspace(0.0, T, points, endpoint=False)
    t_con = np.linspace(0.0, T, 2 * points, endpoint=False)
    nx = 2 * n * (L - 1) + n
    # The constraints are linear in x: their matrix by evaluating the unit vectors.
    basis = []
    for e in np.eye(nx):
        a, b, q0 = _unpack(e, n, L)
        basis.append(np.concatenate([m.ravel() for m in FourierTrajectory(
            frequency, a, b, q0).sample(t_con)]))
    G = np.array(basis).T  # shape (3 * 4points * n, nx): rows q, qd, qdd
    nq_rows = len(t_con) * n
    upper = np.concatenate([np.tile(hi, len(t_con)), np.tile(LIMIT_MARGIN * vmax, len(t_con)),
                            np.full(nq_rows, LIMIT_MARGIN * amax)])
    lower = np.concatenate([np.tile(lo, len(t_con)), -np.tile(LIMIT_MARGIN * vmax, len(t_con)),
                            np.full(nq_rows, -LIMIT_MARGIN * amax)])
    Gd = np.vstack([G, -G])
    bd = np.concatenate([upper, -lower])

    def traj(x):
        a, b, q0 = _unpack(x, n, L)
        return FourierTrajectory(frequency, a, b, q0, periods)

    def objective(x):
        c = _cond(robot, base, traj(x), t_obj)
        return math.log(c) if math.isfinite(c) else 1e3

    rng = np.random.default_rng(seed)
    x0 = np.concatenate([rng.standard_normal(2 * n * (L - 1)), mid])
    # Scale the oscillating part inside the limits (q0 = mid is inside): Gd x <= bd.
    xm = np.concatenate([np.zeros(2 * n * (L - 1)), mid])
    slack, push = bd - Gd @ xm, Gd @ (x0 - xm)
    scale = 0.9 * np.min(slack[push > 0] / push[push > 0])
    x0 = xm + scale * (x0 - xm)
    cond_random = _cond(robot, base, traj(x0), t_obj)
    res = minimize(objective, x0, method="SLSQP",
                   constraints=[{"type": "ineq", "fun": lambda x: bd - Gd @ x,
                                 "jac": lambda x: -Gd}],
                   options={"maxiter": maxiter, "ftol": 1e-6})
    x = res.x if np.all(Gd @ res.x <= bd + 1e-9) else x0
    best = traj(x)
    return best, {"cond": _cond(robot, base, best, t_obj), "cond_random": cond_random,
                  "harmonics": L, "frequency_hz": frequency, "periods": periods,
                  "points": points, "limits": {"lower_rad": lo.tolist(), "upper_rad": hi.tolist(),
                                               "velocity_rad_s": (LIMIT_MARGIN * vmax).tolist(),
                                               "acceleration_rad_s2": LIMIT_MARGIN * amax,
                                               "margin": LIMIT_MARGIN},
                  "optimizer": {"method": "SLSQP", "iterations": int(res.nit),
                                "message": str(res.message), "used": bool(x is res.x)}}

"""Closed-loop simulation of the nonlinear arm: reference, integrator, metrics.

The plant is the full rigid-body model of a URDF (Pinocchio's ABA); the controller sees only its
nominal model (:mod:`rrr_pin.controllers`). This Python loop is the readable reference; every
faster path must reproduce it.

Integration method: classical fixed-step Runge-Kutta 4.

* Continuous-time laws (``rate=None``, as in the paper's Simulink study): the state
  ``(q, qd, x_K)`` of arm and controller is integrated together with step ``dt``; the law is
  evaluated at every RK4 stage.
* Sampled laws (``rate`` in Hz): at ``t_k = k Ts`` the controller reads ``(q_k, qd_k)``,
  updates its discrete state and outputs ``tau_k``, held constant (zero-order hold) while the arm
  is integrated over ``[t_k, t_k + Ts]`` by ``substeps`` RK4 steps of ``Ts / substeps``.

Accuracy: RK4's global error is ``O(dt^4)``; ``tests/test_simulate.py`` halves the step and shows
the tracking errors move by orders of magnitude less than the differences the study reports.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from .controllers import TrackingController
from .dynamics import Robot

__all__ = [
    "SineReference",
    "Trajectory",
    "SimulationDiverged",
    "simulate",
    "metrics",
    "DEFAULT_DT",
    "VELOCITY_LIMIT",
]

#: Default RK4 step of the continuous-time simulation [s].
DEFAULT_DT = 1e-3

#: A joint speed above this [rad/s] is taken as a blow-up of the simulation.
VELOCITY_LIMIT = 1e4


class SimulationDiverged(RuntimeError):
    """The simulated closed loop blew up; the message names the time [s] and the joint."""

    def __init__(self, message: str, time: float, joint: str):
        super().__init__(message)
        self.time = time
        self.joint = joint


@dataclass(frozen=True)
class SineReference:
    """Sinusoidal joint reference ``r(t) = home + amp sin(2 pi freq t + phase)``.

    Parameters
    ----------
    home : array-like, shape (n,)
        Centre of the motion [rad].
    amp : array-like, shape (n,) or float
        Amplitude [rad], >= 0.
    freq : array-like, shape (n,) or float
        Frequency [Hz], >= 0.
    phase : array-like, shape (n,) or float
        Phase [rad].
    """

    home: np.ndarray
    amp: np.ndarray
    freq: np.ndarray
    phase: np.ndarray

    def __post_init__(self) -> None:
        home = np.atleast_1d(np.asarray(self.home, dtype=float))
        if home.ndim != 1:
            raise ValueError(f"Expected home of shape (n,), got {home.shape}")
        n = home.shape[0]
        for name in ("home", "amp", "freq", "phase"):
            v = np.asarray(getattr(self, name), dtype=float)
            v = np.full(n, float(v)) if v.ndim == 0 else v
            if v.shape != (n,):
                raise ValueError(f"Expected {name} of shape ({n},), got {v.shape}")
            if not np.all(np.isfinite(v)):
                raise ValueError(f"{name} must be finite, got {v}")
            if name in ("amp", "freq") and np.any(v < 0.0):
                raise ValueError(f"{name} must be >= 0, got {v}")
            v.setflags(write=False)
            object.__setattr__(self, name, v)

    @property
    def n(self) -> int:
        """Number of joints."""
        return self.home.shape[0]

    @property
    def omega(self) -> np.ndarray:
        """Angular frequencies ``2 pi freq`` [rad/s], shape (n,)."""
        return 2.0 * math.pi * self.freq

    def positions(self, t) -> np.ndarray:
        """Evaluate ``r`` [rad] on a time grid ``t`` [s], shape (N,); returns shape (N, n)."""
        return self.home + self.amp * np.sin(np.outer(t, self.omega) + self.phase)

    def __call__(self, t: float):
        """Evaluate ``(r, rd, rdd)`` at time ``t`` [s], each shape (n,) [rad, rad/s, rad/s^2]."""
        w = self.omega
        arg = w * t + self.phase
        s, c = np.sin(arg), np.cos(arg)
        return self.home + self.amp * s, self.amp * w * c, -self.amp * w * w * s

    def check_limits(self, robot: Robot) -> None:
        """Raise ``ValueError`` if ``home +- amp`` leaves the robot's joint limits."""
        if robot.nq != self.n:
            raise ValueError(f"reference has {self.n} joints, robot {robot.name!r} has "
                             f"{robot.nq}")
        lo, hi = self.home - self.amp, self.home + self.amp
        for j, name in enumerate(robot.joint_names):
            if lo[j] < robot.lower[j] or hi[j] > robot.upper[j]:
                raise ValueError(
                    f"reference for joint {name!r} spans [{lo[j]:.4g}, {hi[j]:.4g}] rad, "
                    f"outside its limits [{robot.lower[j]:.4g}, {robot.upper[j]:.4g}]")

    def to_dict(self) -> dict:
        """JSON-ready parameters (units in the key names)."""
        return {"home_rad": self.home.tolist(), "amp_rad": self.amp.tolist(),
                "freq_hz": self.freq.tolist(), "phase_rad": self.phase.tolist()}


@dataclass
class Trajectory:
    """A simulated closed-loop run, sampled on the integration (or control) grid.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Times [s].
    q, qd : ndarray, shape (N, n)
        Joint positions [rad] and velocities [rad/s].
    r : ndarray, shape (N, n)
        Reference positions [rad].
    tau : ndarray, shape (N, n)
        Applied torques [N m] (for sampled laws: the torque held from ``t[k]`` on).
    controller, plant : str
        Labels.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    r: np.ndarray
    tau: np.ndarray
    controller: str = ""
    plant: str = ""
    info: dict = field(default_factory=dict)

    @property
    def error(self) -> np.ndarray:
        """Tracking error ``e = r - q`` [rad], shape (N, n)."""
        return self.r - self.q


def metrics(traj: Trajectory) -> dict:
    """Per-joint figures of a run, each a list of length n.

    Returns
    -------
    dict
        ``rms_error`` and ``max_error`` [rad] of ``e = r - q``; ``rms_torque`` and
        ``peak_torque`` [N m] of ``tau``. RMS over the samples of the run.
    """
    e, tau = traj.error, traj.tau
    return {
        "rms_error": np.sqrt(np.mean(e * e, axis=0)).tolist(),
        "max_error": np.max(np.abs(e), axis=0).tolist(),
        "rms_torque": np.sqrt(np.mean(tau * tau, axis=0)).tolist(),
        "peak_torque": np.max(np.abs(tau), axis=0).tolist(),
    }


def _check_state(q, qd, t, plant: Robot, lower, upper) -> None:
    bad = ~np.isfinite(q) | ~np.isfinite(qd)
    reason = "became NaN or infinite"
    if not bad.any():
        bad = np.abs(qd) > VELOCITY_LIMIT
        reason = f"exceeded {VELOCITY_LIMIT:g} rad/s (blow-up)"
    if not bad.any():
        bad = (q < lower) | (q > upper)
        reason = "left its joint limits"
    if bad.any():
        j = int(np.flatnonzero(bad)[0])
        name = plant.joint_names[j]
        raise SimulationDiverged(
            f"simulation of plant {plant.name!r} diverged at t = {t:.6g} s: joint {name!r} "
            f"{reason} (q = {q[j]:.6g} rad, qd = {qd[j]:.6g} rad/s)", time=t, joint=name)


def simulate(plant: Robot, controller: TrackingController, reference: SineReference,
             duration: float, *, dt: float = DEFAULT_DT, rate: float | None = None,
             method: str = "tustin", limit_margin: float = 0.0,
             engine: str = "python") -> Trajectory:
    """Simulate the closed loop of ``plant`` and ``controller`` tracking ``reference``.

    The run starts on the reference (``q(0) = r(0)``, ``qd(0) = rd(0)``, controller state 0),
    so no artificial transient is excited.

    Parameters
    ----------
    plant : Robot
        The true arm (may differ from ``controller.nominal``).
    controller : TrackingController
        The law (FL alone or H-infinity + FL).
    reference : SineReference
        Joint reference, shape (n,) per parameter.
    duration : float
        Simulated time [s].
    dt : float, default 1e-3
        RK4 step [s] for continuous-time laws; for sampled laws, the largest plant sub-step
        (``substeps = ceil(Ts / dt)``).
    rate : float, optional
        Sampling rate of a digital controller [Hz] (zero-order hold on the torque, ``K``
        discretized with ``method``); ``None`` (default) for the continuous-time laws.
    method : str, default "tustin"
        Discretization of ``K`` for sampled laws (see
        :meth:`TrackingController.discretize`).
    limit_margin : float, default 0
        Slack beyond the plant's joint limits before the run counts as diverged [rad].
    engine : {"python", "compiled", "auto"}, default "python"
        Rollout path for sampled laws: this module's Python loop (the reference), the
        compiled C++ loop of :mod:`rrr_pin.compiled` (same algorithm, equal to 1e-9 rad), or
        "auto" (compiled when ``rate`` is given and the extension is built). Continuous-time
        laws always run in Python.

    Returns
    -------
    Trajectory
        Sampled every ``dt`` (continuous) or every ``1/rate`` (sampled).

    Raises
    ------
    SimulationDiverged
        NaN/inf state, joint speed above :data:`VELOCITY_LIMIT`, or a joint past its limits.
    ValueError
        Inconsistent sizes, non-positive ``duration``/``dt``/``rate``, or a step too large for
        the controller's fastest pole (RK4 would be unstable).
    """
    n = plant.nq
    if controller.n != n or reference.n != n:
        raise ValueError(f"sizes differ: plant has {n} joints, controller {controller.n}, "
                         f"reference {reference.n}")
    duration, dt = float(duration), float(dt)
    if not (math.isfinite(duration) and duration > 0.0):
        raise ValueError(f"duration must be > 0 s, got {duration!r}")
    if not (math.isfinite(dt) and dt > 0.0):
        raise ValueError(f"dt must be > 0 s, got {dt!r}")
    lower = plant.lower - limit_margin
    upper = plant.upper + limit_margin
    if rate is None:
        return _simulate_continuous(plant, controller, reference, duration, dt, lower, upper)
    rate = float(rate)
    if not (math.isfinite(rate) and rate > 0.0):
        raise ValueError(f"rate must be > 0 Hz, got {rate!r}")
    Ts = 1.0 / rate
    substeps = max(1, math.ceil(Ts / dt - 1e-9))
    n_steps = int(round(duration * rate))
    Ad, Bd, Cd, Dd = controller.discretize(rate, method)
    if engine not in ("python", "compiled", "auto"):
        raise ValueError(f"engine must be 'python', 'compiled' or 'auto', got {engine!r}")
    if engine == "auto":
        from .compiled import available

        engine = "compiled" if available() else "python"
    if engine == "compiled":
        return _simulate_compiled(plant, controller, reference, n_steps, Ts, substeps,
                                  (Ad, Bd, Cd, Dd), lower, upper)
    return _simulate_sampled(plant, controller, reference, n_steps, Ts, substeps,
                             (Ad, Bd, Cd, Dd), lower, upper)


def _first_violation(Q, QD, t, plant, lower, upper) -> None:
    """Raise like the Python loop at the first sample whose state is out of bounds."""
    bad = (~np.isfinite(Q) | ~np.isfinite(QD) | (np.abs(QD) > VELOCITY_LIMIT) | (Q < lower) |
           (Q > upper))
    rows = np.flatnonzero(bad.any(axis=1))
    if rows.size:
        k = int(rows[0])
        _check_state(Q[k], QD[k], float(t[k]), plant, lower, upper)


def _simulate_compiled(plant, controller, reference, n_steps, Ts, substeps, mats, lower, upper):
    from .compiled import rollout_compiled

    out = rollout_compiled(plant, controller.nominal, controller.lam, mats, reference.home,
                           reference.amp, reference.omega, reference.phase, Ts, substeps,
                           n_steps, raise_on_divergence=False)
    t_all, Q, QD = out["t"], out["q"], out["qd"]
    _first_violation(Q, QD, t_all, plant, lower, upper)
    TAU = np.zeros_like(Q)
    TAU[:-1] = out["tau"]
    return _sampled_trajectory(t_all, Q, QD, TAU, reference, controller, plant, Ts, substeps,
                               "RK4 plant, zero-order-hold sampled law (compiled)")


def _sampled_trajectory(t_all, Q, QD, TAU, reference, controller, plant, Ts, substeps, method):
    # The torque held on the last interval is also the one "at" the final sample.
    if len(t_all) > 1:
        TAU[-1] = TAU[-2]
    R = reference.positions(t_all)
    return Trajectory(t=t_all, q=Q, qd=QD, r=R, tau=TAU, controller=controller.name,
                      plant=plant.name,
                      info={"method": method, "rate_hz": 1.0 / Ts, "substeps": substeps})


def _simulate_continuous(plant, controller, reference, duration, dt, lower, upper):
    A, B, C, D = controller.continuous_matrices()
    nx = A.shape[0]
    if nx:
        fastest = float(np.max(np.abs(np.linalg.eigvals(A))))
        # RK4's stability interval on the negative real axis ends at -2.785.
        if fastest * dt > 2.5:
            raise ValueError(
                f"dt = {dt:g} s is too large for the controller's fastest pole "
                f"({fastest:.4g} rad/s): RK4 needs dt < {2.5 / fastest:.3g} s")
    model, data = plant.model, plant.data
    aba, law = pin.aba, controller.torque
    n_steps = int(round(duration / dt))

    def rhs(t, q, qd, x):
        r, rd, rdd = reference(t)
        e = r - q
        y = C @ x + D @ e
        tau = law(q, qd, r, rd, rdd, y)
        return qd, aba(model, data, q, qd, tau), A @ x + B @ e, tau

    t_all = dt * np.arange(n_steps + 1)
    Q = np.empty((n_steps + 1, plant.nq))
    QD = np.empty_like(Q)
    TAU = np.empty_like(Q)
    r0, rd0, _ = reference(0.0)
    q, qd, x = r0.copy(), rd0.copy(), np.zeros(nx)
    for k in range(n_steps + 1):
        t = t_all[k]
        k1q, k1v, k1x, tau = rhs(t, q, qd, x)
        Q[k], QD[k], TAU[k] = q, qd, tau
        if k == n_steps:
            break
        h2 = 0.5 * dt
        k2q, k2v, k2x, _ = rhs(t + h2, q + h2 * k1q, qd + h2 * k1v, x + h2 * k1x)
        k3q, k3v, k3x, _ = rhs(t + h2, q + h2 * k2q, qd + h2 * k2v, x + h2 * k2x)
        k4q, k4v, k4x, _ = rhs(t + dt, q + dt * k3q, qd + dt * k3v, x + dt * k3x)
        h6 = dt / 6.0
        q = q + h6 * (k1q + 2.0 * (k2q + k3q) + k4q)
        qd = qd + h6 * (k1v + 2.0 * (k2v + k3v) + k4v)
        x = x + h6 * (k1x + 2.0 * (k2x + k3x) + k4x)
        _check_state(q, qd, t + dt, plant, lower, upper)
    R = reference.positions(t_all)
    return Trajectory(t=t_all, q=Q, qd=QD, r=R, tau=TAU, controller=controller.name,
                      plant=plant.name, info={"method": "RK4 (continuous-time law)", "dt": dt})


def _simulate_sampled(plant, controller, reference, n_steps, Ts, substeps, mats, lower, upper):
    Ad, Bd, Cd, Dd = mats
    model, data = plant.model, plant.data
    aba, law = pin.aba, controller.torque
    h = Ts / substeps
    h2, h6 = 0.5 * h, h / 6.0
    t_all = Ts * np.arange(n_steps + 1)
    Q = np.empty((n_steps + 1, plant.nq))
    QD = np.empty_like(Q)
    TAU = np.zeros_like(Q)
    r0, rd0, _ = reference(0.0)
    q, qd, x = r0.copy(), rd0.copy(), np.zeros(Ad.shape[0])
    Q[0], QD[0] = q, qd
    for k in range(n_steps):
        r, rd, rdd = reference(t_all[k])
        e = r - q
        y = Cd @ x + Dd @ e
        x = Ad @ x + Bd @ e
        tau = law(q, qd, r, rd, rdd, y)
        TAU[k] = tau
        for _ in range(substeps):
            a1 = aba(model, data, q, qd, tau)
            v2 = qd + h2 * a1
            a2 = aba(model, data, q + h2 * qd, v2, tau)
            v3 = qd + h2 * a2
            a3 = aba(model, data, q + h2 * v2, v3, tau)
            v4 = qd + h * a3
            a4 = aba(model, data, q + h * v3, v4, tau)
            q = q + h6 * (qd + 2.0 * (v2 + v3) + v4)
            qd = qd + h6 * (a1 + 2.0 * (a2 + a3) + a4)
        _check_state(q, qd, t_all[k + 1], plant, lower, upper)
        Q[k + 1], QD[k + 1] = q, qd
    return _sampled_trajectory(t_all, Q, QD, TAU, reference, controller, plant, Ts, substeps,
                               "RK4 plant, zero-order-hold sampled law")

"""What a simulation produces and how it fails: the leaf module both engines share.

:class:`Trajectory` (the result), :class:`SimulationDiverged` and the divergence test
(:func:`diverged_joint`, :data:`VELOCITY_LIMIT`: one definition for the Python and the compiled
engines), and :class:`Run`, a validated run that :func:`rrr_pin.sim.simulation.simulate` hands
to an engine. Imports nothing of rrr_pin.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "Trajectory",
    "SimulationDiverged",
    "Run",
    "metrics",
    "diverged_joint",
    "divergence",
    "law_divergence",
    "first_bad_torque",
    "make_trajectory",
    "VELOCITY_LIMIT",
    "REASONS",
]

#: A joint speed above this [rad/s] is taken as a blow-up of the simulation.
VELOCITY_LIMIT = 1e4

#: Why a run diverged, by the code both engines use (0, 1, 2), in :func:`divergence`'s words;
#: code 3: the law returned a NaN or inf torque (:func:`law_divergence`), which stops the run
#: at the step where it happened, whatever it would have done to the state.
REASONS = ("became NaN or infinite", f"exceeded {VELOCITY_LIMIT:g} rad/s (blow-up)",
           "left its joint limits", "got a non-finite torque (NaN or inf) from the law")

class SimulationDiverged(RuntimeError):
    """The simulated closed loop blew up; the message names the time [s] and the joint."""

    def __init__(self, message: str, time: float, joint: str):
        super().__init__(message)
        self.time = time
        self.joint = joint

    def __reduce__(self):
        return (type(self), (str(self), self.time, self.joint))


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
        The law's name and the plant's name.
    info : dict
        ``engine`` ("python", "compiled" or "codegen"), integration settings.
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


def diverged_joint(q, qd, lower, upper) -> tuple[int, str] | None:
    """Apply the divergence test of both engines: ``(joint index, reason)`` or None.

    Parameters
    ----------
    q, qd : ndarray, shape (n,)
        State [rad, rad/s].
    lower, upper : ndarray, shape (n,)
        Joint limits widened by the run's ``limit_margin`` [rad].
    """
    bad = ~np.isfinite(q) | ~np.isfinite(qd)
    if bad.any():
        return int(np.flatnonzero(bad)[0]), REASONS[0]
    bad = np.abs(qd) > VELOCITY_LIMIT
    if bad.any():
        return int(np.flatnonzero(bad)[0]), REASONS[1]
    bad = (q < lower) | (q > upper)
    if bad.any():
        return int(np.flatnonzero(bad)[0]), REASONS[2]
    return None


def divergence(plant, t: float, q, qd, j: int, reason: str) -> SimulationDiverged:
    """Build the :class:`SimulationDiverged` of both engines: plant, time [s], joint, reason."""
    name = plant.joint_names[j]
    return SimulationDiverged(
        f"simulation of plant {plant.name!r} diverged at t = {t:.6g} s: joint {name!r} "
        f"{reason} (q = {q[j]:.6g} rad, qd = {qd[j]:.6g} rad/s)", time=t, joint=name)


def law_divergence(plant, law: str, t: float, j: int) -> SimulationDiverged:
    """Build the :class:`SimulationDiverged` of both engines for a law's NaN or inf torque.

    Parameters
    ----------
    plant : Robot
    law : str
        The law's name.
    t : float
        Start of the control period (sampled) or RK4 step (continuous) in which the law
        returned the torque [s].
    j : int
        First joint whose torque is not finite.
    """
    name = plant.joint_names[j]
    return SimulationDiverged(
        f"simulation of plant {plant.name!r} stopped at t = {t:.6g} s: law {law!r} returned a "
        f"non-finite torque (NaN or inf) for joint {name!r} in the step from t = {t:.6g} s",
        time=t, joint=name)


def first_bad_torque(tau) -> tuple[int, int] | None:
    """``(row, joint)`` of the first non-finite entry of torques ``tau`` (shape (N, n)), or None."""
    bad = ~np.isfinite(tau)
    if not bad.any():
        return None
    k, j = np.argwhere(bad)[0]
    return int(k), int(j)


@dataclass(frozen=True)
class Run:
    """A validated run: everything an engine needs, nothing left to check."""

    plant: object
    law: object          # ControlLaw (continuous) or SampledLaw
    sampled: bool
    t: np.ndarray        # output grid, shape (N+1,)
    R: np.ndarray        # reference on the law-evaluation grid
    RD: np.ndarray
    RDD: np.ndarray
    q0: np.ndarray
    qd0: np.ndarray
    x0: np.ndarray
    h: float             # RK4 step [s]
    substeps: int        # RK4 steps per control period (1 for continuous laws)
    lower: np.ndarray
    upper: np.ndarray
    info: dict
    effects: object = None  # rrr_pin.control.effects.Resolved, or None for the ideal plant


def make_trajectory(run: Run, Q, QD, TAU) -> Trajectory:
    """Build the :class:`Trajectory` of a finished run (states, torques of shape (N+1, n))."""
    R = run.R if run.sampled else run.R[::2]
    return Trajectory(t=run.t, q=Q, qd=QD, r=R, tau=TAU, controller=run.law.name,
                      plant=run.plant.name, info=dict(run.info))

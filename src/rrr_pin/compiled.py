r"""Compiled rollout of the sampled closed loop: the whole run in one C++ call.

The loop of a digital tracking controller around the simulated arm, without returning to Python
per step (the C++ source is ``src/rrr_pin/_ext/rollout.cpp``, built by ``pip install .``):

* plant: the true arm's forward dynamics ``qdd = ABA(q, qd, tau)``, integrated over each control
  period ``[t_k, t_k + Ts]`` with ``tau_k`` held, by ``substeps`` classical RK4 steps of
  ``h = Ts / substeps`` on the state ``(q, qd)``;
* controller, at ``t_k = k Ts`` from ``(q_k, qd_k)``: the error ``e = r - q``, the discrete
  controller ``K`` (output with the old state, then the state update),

  .. math::

      y_k = C_d x_k + D_d e_k, \qquad x_{k+1} = A_d x_k + B_d e_k,

  and the feedback-linearizing torque with the NOMINAL model, eq. (8),

  .. math::

      \bar\tau = \ddot r + 2\lambda(\dot r - \dot q) + \lambda^2 (e + y), \qquad
      \tau = \hat M(q)\,\bar\tau + \hat V(q, \dot q) + \hat G(q),

  with ``Mhat`` from CRBA (symmetrized from its upper triangle) and ``Vhat + Ghat`` from RNEA
  (``nonLinearEffects``);
* reference ``r = home + amp sin(omega t + phase)``, ``rd``, ``rdd`` its derivatives; the run
  starts on it: ``q_0 = r(0)``, ``qd_0 = rd(0)``, ``x_0 = 0``.

This is the same law as :func:`rrr_pin.simulate.simulate` with ``rate`` set; trajectories agree
to round-off (``tests/test_compiled.py``).

Models reach C++ as :meth:`pinocchio.Model.saveToString` text (Boost.Serialization, exact for
doubles, including infinite joint limits), so the extension needs no Boost.Python object.

Build: ``pip install .`` (or ``pip install -e .``) compiles the extension with scikit-build-core
against the Pinocchio C++ library of the ``libpinocchio`` wheel; the exact Pinocchio version is
pinned at build and run time (``pyproject.toml``) and checked at import.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import control
import numpy as np
import pinocchio as pin  # loads libpinocchio_default.so before the extension needs it

from .dynamics import Robot
from .simulate import SimulationDiverged

__all__ = [
    "CompiledRobot",
    "available",
    "compile_robot",
    "rollout_compiled",
    "floor_ms",
    "DIVERGENCE_BOUND",
]

#: A joint position [rad] or speed [rad/s] beyond this (or NaN/inf) ends a run as diverged.
DIVERGENCE_BOUND = 1e6


def _load_extension():
    """Return (module, None) or (None, reason it cannot be used)."""
    try:
        from . import _rollout as ext
    except ImportError as exc:
        return None, (f"rrr_pin's compiled extension (rrr_pin._rollout) is not built or cannot "
                      f"load ({exc}); install the package with `pip install .` or "
                      f"`pip install -e .`, which compiles it")
    if ext.pinocchio_version() != pin.__version__:
        return None, (f"rrr_pin._rollout was compiled against Pinocchio "
                      f"{ext.pinocchio_version()} but Pinocchio {pin.__version__} is installed "
                      f"(its C++ ABI changes between versions); reinstall rrr-pin "
                      f"(`pip install --force-reinstall .`) or install "
                      f"pin=={ext.pinocchio_version()}")
    return ext, None


_rollout, _UNAVAILABLE = _load_extension()


def available() -> bool:
    """Whether the compiled extension is built and matches the installed Pinocchio."""
    return _rollout is not None


def _require() -> None:
    if _rollout is None:
        raise ImportError(_UNAVAILABLE)


@dataclass(frozen=True)
class CompiledRobot:
    """A robot model loaded into the extension, reusable across rollouts and threads.

    Attributes
    ----------
    name : str
        Robot name (for messages).
    joint_names : tuple of str
        Names of the moving joints, shape (nq,).
    """

    name: str
    joint_names: tuple[str, ...]
    _model: object = field(repr=False)

    @property
    def nq(self) -> int:
        """Number of joints."""
        return self._model.nq


def compile_robot(robot: Robot | CompiledRobot) -> CompiledRobot:
    """Load ``robot.model`` into the extension (about 0.5 ms for a 6-joint arm).

    The copy is independent of ``robot``: later changes to ``robot.model`` do not reach it.
    Each rollout builds its own ``pinocchio::Data``, so one :class:`CompiledRobot` may serve
    concurrent rollouts in several threads (the extension releases the GIL).

    Parameters
    ----------
    robot : Robot or CompiledRobot
        The model; a :class:`CompiledRobot` is returned as is.

    Returns
    -------
    CompiledRobot

    Raises
    ------
    ImportError
        The extension is not built or was built for another Pinocchio (see :func:`available`).
    """
    if isinstance(robot, CompiledRobot):
        return robot
    _require()
    if not isinstance(robot, Robot):
        raise TypeError(f"expected a Robot or CompiledRobot, got {type(robot).__name__}")
    model = _rollout.CompiledModel(robot.model.saveToString())
    return CompiledRobot(robot.name, tuple(robot.joint_names), model)


def _vector(name: str, value, n: int) -> np.ndarray:
    v = np.asarray(value, dtype=float)
    v = np.full(n, float(v)) if v.ndim == 0 else v
    if v.shape != (n,):
        raise ValueError(f"Expected {name} of shape ({n},), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite, got {v}")
    return np.ascontiguousarray(v)


def _controller(Kd, n: int, Ts: float):
    """(Ad, Bd, Cd, Dd) as float arrays from a StateSpace, a 4-tuple or None."""
    if Kd is None:
        return np.zeros((0, 0)), np.zeros((0, n)), np.zeros((n, 0)), np.zeros((n, n))
    if isinstance(Kd, control.StateSpace):
        if not Kd.isdtime(strict=True) or Kd.dt is True or not math.isclose(
                float(Kd.dt), Ts, rel_tol=1e-9):
            raise ValueError(f"Kd must be discrete-time with dt = Ts = {Ts:g} s, got "
                             f"dt = {Kd.dt!r}")
        mats = (Kd.A, Kd.B, Kd.C, Kd.D)
    elif isinstance(Kd, (tuple, list)) and len(Kd) == 4:
        mats = tuple(Kd)
    else:
        raise TypeError(f"Kd must be a control.StateSpace, an (Ad, Bd, Cd, Dd) tuple or None, "
                        f"got {type(Kd).__name__}")
    Ad, Bd, Cd, Dd = (np.asarray(x, dtype=float) for x in mats)
    m = Ad.shape[0] if Ad.ndim == 2 else -1
    expected = {"Ad": (m, m), "Bd": (m, n), "Cd": (n, m), "Dd": (n, n)}
    for name, mat in zip(expected, (Ad, Bd, Cd, Dd), strict=True):
        if mat.shape != expected[name]:
            raise ValueError(f"Expected {name} of shape {expected[name]} (K must be {n} x {n} "
                             f"with {m} states), got {mat.shape}")
        if not np.all(np.isfinite(mat)):
            raise ValueError(f"{name} must be finite")
    return Ad, Bd, Cd, Dd


def rollout_compiled(plant: Robot | CompiledRobot, nominal: Robot | CompiledRobot, lam: float,
                     Kd, home, amp, omega, phase, Ts: float, substeps: int, n_steps: int, *,
                     raise_on_divergence: bool = True) -> dict:
    r"""Simulate the sampled closed loop (FL, or H-infinity + FL) in one compiled call.

    The algorithm is the module's (see :mod:`rrr_pin.compiled`): at ``t_k = k Ts``,
    ``e = r - q``, ``y = Cd x + Dd e``, ``x <- Ad x + Bd e``,
    ``taubar = rdd + 2 lam (rd - qd) + lam^2 (e + y)``,
    ``tau = Mhat(q) taubar + (Vhat + Ghat)(q, qd)``; then ``substeps`` RK4 steps of the plant
    with ``tau`` held.

    .. math:: \tau_k = \hat M(q_k)\,\bar\tau_k + \hat V(q_k, \dot q_k) + \hat G(q_k)

    Parameters
    ----------
    plant : Robot or CompiledRobot
        The true arm, integrated with its ABA.
    nominal : Robot or CompiledRobot
        The model the controller believes in (CRBA, RNEA); same number of joints ``n``.
    lam : float
        Feedback-linearization bandwidth ``lambda`` [rad/s].
    Kd : control.StateSpace, tuple (Ad, Bd, Cd, Dd) or None
        Discrete controller ``K``, ``n`` inputs (``e`` [rad]) and ``n`` outputs (``y`` [rad]),
        sample time ``dt = Ts``, python-control's negative-feedback convention (it acts on
        ``e = r - q``); a tuple has shapes (m, m), (m, n), (n, m), (n, n); ``None`` for FL
        alone (``y = 0``).
    home : array-like, shape (n,) or float
        Centre of the reference [rad].
    amp : array-like, shape (n,) or float
        Amplitude of the reference [rad].
    omega : array-like, shape (n,) or float
        Angular frequency of the reference [rad/s].
    phase : array-like, shape (n,) or float
        Phase of the reference [rad].
    Ts : float
        Control period [s], > 0.
    substeps : int
        RK4 steps of the plant per control period, >= 1 (step ``h = Ts / substeps``).
    n_steps : int
        Number of control periods ``N`` >= 0 (duration ``N Ts``).
    raise_on_divergence : bool, default True
        Raise :class:`~rrr_pin.simulate.SimulationDiverged` if the run diverges; if False,
        return the status instead (for Monte Carlo campaigns).

    Returns
    -------
    dict
        ``t`` : ndarray, shape (N+1,)
            Sample times ``k Ts`` [s].
        ``q``, ``qd`` : ndarray, shape (N+1, n)
            Joint positions [rad] and velocities [rad/s] at ``t``.
        ``tau`` : ndarray, shape (N, n)
            Torque [N m] applied on ``[t_k, t_{k+1})``.
        ``e`` : ndarray, shape (N, n)
            Tracking error ``r(t_k) - q_k`` [rad] the controller saw.
        ``status`` : str
            ``"ok"`` or ``"diverged"``.
        ``diverged_step`` : int or None
            Index ``k`` into ``t`` of the first sample whose ``q`` or ``qd`` is NaN/inf or
            beyond :data:`DIVERGENCE_BOUND` (that sample is kept; later ones are NaN).
        ``diverged_time`` : float or None
            ``t`` of that sample [s].
        ``diverged_joint`` : str or None
            Name of the first offending joint.

    Raises
    ------
    SimulationDiverged
        If the run diverges and ``raise_on_divergence`` is true.
    ImportError
        The extension is not built or was built for another Pinocchio (see :func:`available`).
    ValueError
        Inconsistent sizes, non-finite inputs, ``Ts <= 0``, ``substeps < 1``, ``n_steps < 0``,
        or ``Kd.dt != Ts``.

    References
    ----------
    .. [1] The paper, eq. (8)-(10), (18)-(20).
    """
    plant_c, nominal_c = compile_robot(plant), compile_robot(nominal)
    n = plant_c.nq
    if nominal_c.nq != n:
        raise ValueError(f"plant {plant_c.name!r} has {n} joints, nominal {nominal_c.name!r} "
                         f"has {nominal_c.nq}")
    lam, Ts = float(lam), float(Ts)
    if not math.isfinite(lam):
        raise ValueError(f"lam must be finite, got {lam!r}")
    if not (math.isfinite(Ts) and Ts > 0.0):
        raise ValueError(f"Ts must be > 0 s, got {Ts!r}")
    if int(substeps) != substeps or substeps < 1:
        raise ValueError(f"substeps must be an integer >= 1, got {substeps!r}")
    if int(n_steps) != n_steps or n_steps < 0:
        raise ValueError(f"n_steps must be an integer >= 0, got {n_steps!r}")
    ref = [_vector(name, v, n) for name, v in
           (("home", home), ("amp", amp), ("omega", omega), ("phase", phase))]
    Ad, Bd, Cd, Dd = _controller(Kd, n, Ts)

    q, qd, tau, e, status, bad_step, bad_joint = _rollout.rollout(
        plant_c._model, nominal_c._model, lam, Ad, Bd, Cd, Dd, *ref, Ts, int(substeps),
        int(n_steps), DIVERGENCE_BOUND)
    t = Ts * np.arange(int(n_steps) + 1)
    out = {"t": t, "q": q, "qd": qd, "tau": tau, "e": e, "status": "ok",
           "diverged_step": None, "diverged_time": None, "diverged_joint": None}
    if status != 0:
        joint = plant_c.joint_names[bad_joint]
        out.update(status="diverged", diverged_step=int(bad_step),
                   diverged_time=float(t[bad_step]), diverged_joint=joint)
        if raise_on_divergence:
            raise SimulationDiverged(
                f"compiled rollout of plant {plant_c.name!r} diverged at t = {t[bad_step]:.6g} "
                f"s: joint {joint!r} has q = {q[bad_step, bad_joint]:.6g} rad, "
                f"qd = {qd[bad_step, bad_joint]:.6g} rad/s (NaN/inf or beyond "
                f"{DIVERGENCE_BOUND:g})", time=float(t[bad_step]), joint=joint)
    return out


def floor_ms(plant: Robot | CompiledRobot, nominal: Robot | CompiledRobot, n_steps: int,
             substeps: int = 1, repeat: int = 5) -> float:
    """Time the "C++ floor" of a rollout: the wall time [ms] of its bare Pinocchio calls.

    Times, in a plain C++ loop, exactly the Pinocchio calls :func:`rollout_compiled` makes:
    per control step one CRBA and one ``nonLinearEffects`` on ``nominal`` and ``4 substeps``
    ABA on ``plant``, with no controller, reference or integrator arithmetic.

    Parameters
    ----------
    plant, nominal : Robot or CompiledRobot
        As for :func:`rollout_compiled`.
    n_steps : int
        Control steps, >= 0.
    substeps : int, default 1
        RK4 steps per control step, >= 1.
    repeat : int, default 5
        Runs; the fastest is returned (the least disturbed by other processes).

    Returns
    -------
    float
        Wall time [ms] of the fastest run.
    """
    plant_c, nominal_c = compile_robot(plant), compile_robot(nominal)
    if repeat < 1:
        raise ValueError(f"repeat must be >= 1, got {repeat!r}")
    return 1e3 * min(_rollout.floor_timing(plant_c._model, nominal_c._model, int(substeps),
                                           int(n_steps)) for _ in range(repeat))

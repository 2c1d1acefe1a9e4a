r"""The compiled engine: the whole closed-loop run in one C++ call.

It runs the laws that declare a :class:`~rrr_pin.control.laws.CompiledForm`, operation for
operation as the Python reference engine of :mod:`rrr_pin.sim.simulation` does (C++ source:
``src/rrr_pin/_ext/rollout.cpp``, built by ``pip install .``):

* ``"fl"``, the feedback-linearizing laws (FL alone, H-infinity + FL), eq. (8):

  .. math::

      \bar\tau = \ddot r + 2\lambda(\dot r - \dot q) + \lambda^2 (e + y), \qquad
      \tau = \hat M(q)\,\bar\tau + \hat V(q, \dot q) + \hat G(q),

  with ``y = C x + D e`` and ``K``'s state ``xdot = A x + B e`` (continuous) or
  ``x+ = A x + B e`` after the output (sampled, matrices discretized), ``Mhat`` from CRBA
  (symmetrized from its upper triangle) and ``Vhat + Ghat`` from ``nonLinearEffects``;
* ``"pd"``, PD + gravity compensation: ``tau = Kp e + Kd (rd - qd) + Ghat(q)``.

The reference arrives sampled by :func:`rrr_pin.sim.simulation.simulate` on the grid where the law is
evaluated, so every reference runs here. Trajectories equal the Python engine's to round-off
(``tests/test_engines.py``). Call it through ``simulate(..., engine="compiled")`` (or
``"auto"``); :func:`run_compiled` takes a run that ``simulate`` has already validated.

Models reach C++ as :meth:`pinocchio.Model.saveToString` text (Boost.Serialization, exact for
doubles, including infinite joint limits), so the extension needs no Boost.Python object.

Build: ``pip install .`` (or ``pip install -e .``) compiles the extension with scikit-build-core
against the Pinocchio C++ library of the ``libpinocchio`` wheel; the exact Pinocchio version is
pinned at build and run time (``pyproject.toml``) and checked at import.
"""

from __future__ import annotations

import numpy as np

from .codegen import compile_robot_codegen
from .extension import EXTENSION, CompiledRobot, available, cached, require
from .trajectory import REASONS, VELOCITY_LIMIT, divergence, make_trajectory

__all__ = [
    "CompiledRobot",
    "available",
    "require",
    "compile_robot",
    "run_compiled",
    "floor_ms",
    "KINDS",
]

#: Law kinds the C++ loop implements (``CompiledForm.kind``), and their codes there.
KINDS = {"fl": 0, "pd": 1}


# The last few models loaded, by identity of the Robot's pin.Model (a campaign reuses the
# nominal model for every sample and every law).
_CACHE: dict = {}


def compile_robot(robot) -> CompiledRobot:
    """Load ``robot.model`` into the extension (about 0.5 ms for a 6-joint arm).

    The copy is independent of later changes to ``robot.model``. Each rollout builds its own
    ``pinocchio::Data``, so one :class:`CompiledRobot` may serve concurrent rollouts in several
    threads (the extension releases the GIL).

    Parameters
    ----------
    robot : Robot or CompiledRobot
        The model; a :class:`CompiledRobot` is returned as is.

    Raises
    ------
    ImportError
        The extension is not built or was built for another Pinocchio (see :func:`available`).
    """
    if isinstance(robot, CompiledRobot):
        return robot
    require()
    return cached(_CACHE, robot, lambda r: CompiledRobot(
        r.name, tuple(r.joint_names), EXTENSION.CompiledModel(r.model.saveToString())))


def run_compiled(run, form, *, codegen: bool = False):
    """Run a validated simulation (:class:`rrr_pin.sim.trajectory.Run`) of a law's compiled form.

    ``codegen=True`` (``simulate(..., engine="codegen")``) runs the same loop on the generated
    dynamics of :mod:`rrr_pin.sim.codegen`, which refuses (``CodegenModelMismatch``) unless both the
    plant and the nominal model are the generated model; ideal plant only.

    Returns
    -------
    Trajectory
        As the Python engine's.

    Raises
    ------
    SimulationDiverged
        Same test and message as the Python engine.
    ValueError
        A compiled form of an unknown kind.
    """
    require()
    if form.kind not in KINDS:
        raise ValueError(f"compiled form of kind {form.kind!r} is not implemented in C++ "
                         f"(known: {', '.join(KINDS)})")
    plant = run.plant
    n = plant.nq
    p = form.params
    empty = np.zeros((0, 0))
    if form.kind == "fl":
        A, B, C, D = (np.asarray(p[k], dtype=float) for k in "ABCD")
        Kp = Kd = empty
        lam = float(p["lam"])
    else:
        m = 0
        A, B, C, D = np.zeros((m, m)), np.zeros((m, n)), np.zeros((n, m)), np.zeros((n, n))
        Kp, Kd = np.asarray(p["Kp"], dtype=float), np.asarray(p["Kd"], dtype=float)
        lam = 0.0
    N = len(run.t) - 1
    fx = run.effects
    if codegen:
        if fx is not None:
            raise ValueError("engine='codegen' runs the ideal plant only, got effects; use "
                             "engine='compiled' with plant effects")
        plant_m = compile_robot_codegen(plant, "plant")._model
        nominal_m = compile_robot_codegen(form.nominal, "nominal")._model
    else:
        plant_m, nominal_m = compile_robot(plant)._model, compile_robot(form.nominal)._model
    if fx is None:
        Q, QD, TAU, bad_step, bad_joint, reason = EXTENSION.rollout(
            plant_m, nominal_m, KINDS[form.kind],
            run.sampled, lam, A, B, C, D, Kp, Kd, run.R, run.RD, run.RDD, run.q0, run.qd0,
            run.x0, run.lower, run.upper, VELOCITY_LIMIT, run.h, run.substeps, N)
    else:
        # Plant effects (rrr_pin.control.effects): a separate C++ loop, so the ideal one stays as fast.
        none_v, none_m = np.zeros(0), np.zeros((0, n))
        Fv, Fc, veps = fx.friction if fx.friction is not None else (none_v, none_v, 1.0)
        Bm, Kf, Df = fx.flex if fx.flex is not None else (none_v, none_v, none_v)
        Q, QD, TAU, bad_step, bad_joint, reason = EXTENSION.rollout_effects(
            plant_m, nominal_m, KINDS[form.kind], lam, A, B, C, D, Kp, Kd, run.R, run.RD,
            run.RDD, run.q0, run.qd0, run.x0,
            run.lower, run.upper, VELOCITY_LIMIT, run.h, run.substeps, N, fx.delay_steps,
            fx.wa, fx.limit if fx.limit is not None else none_v, Fv, Fc, veps,
            fx.noise_q if fx.noise_q is not None else none_m,
            fx.noise_qd if fx.noise_qd is not None else none_m, fx.quantum, Bm, Kf, Df)
    if bad_step >= 0:
        raise divergence(plant, float(run.t[bad_step]), Q[bad_step], QD[bad_step], bad_joint,
                         REASONS[reason])
    return make_trajectory(run, Q, QD, TAU)


def floor_ms(plant, nominal, n_steps: int, substeps: int = 1, repeat: int = 5, *,
             kind: str = "fl", sampled: bool = True) -> float:
    """Time the "C++ floor" of a rollout: the wall time [ms] of its bare Pinocchio calls.

    Times, in a plain C++ loop, exactly the Pinocchio calls a compiled rollout of a law of
    ``kind`` makes, with no law, reference or integrator arithmetic: sampled, per control step,
    the law's calls on ``nominal`` (``"fl"``: one CRBA and one ``nonLinearEffects``; ``"pd"``:
    one ``computeGeneralizedGravity``) and ``4 substeps`` ABA on ``plant``; continuous, per
    RK4 step, four times the law's calls and one ABA.

    Parameters
    ----------
    plant, nominal : Robot or CompiledRobot
        The true arm and the law's model.
    n_steps : int
        Control (or RK4) steps, >= 0.
    substeps : int, default 1
        RK4 steps per control step, >= 1 (sampled only).
    repeat : int, default 5
        Runs; the fastest is returned (the least disturbed by other processes).
    kind : {"fl", "pd"}
    sampled : bool, default True

    Returns
    -------
    float
        Wall time [ms] of the fastest run.
    """
    plant_c, nominal_c = compile_robot(plant), compile_robot(nominal)
    if repeat < 1:
        raise ValueError(f"repeat must be >= 1, got {repeat!r}")
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    return 1e3 * min(EXTENSION.floor_timing(plant_c._model, nominal_c._model, KINDS[kind],
                                           bool(sampled), int(substeps), int(n_steps))
                     for _ in range(repeat))

r"""The compiled engine: the whole closed-loop run in one C++ call.

It runs the laws whose :class:`~rrr_pin.control.laws.CompiledForm` it implements, operation for
operation as the Python reference engine of :mod:`rrr_pin.sim.simulation` does (C++ sources in
``src/rrr_pin/_ext/``: ``law.hpp``, ``rollout.cpp``, ``rk4.hpp``, ``effects.hpp``; built by
``pip install .``). It dispatches on the form's exact type (:data:`ENGINE_LAWS`), one C++ law
per form, and refuses any other form with a ``ValueError`` naming it:

* :class:`~rrr_pin.control.laws.FLForm`, the feedback-linearizing laws (FL alone, H-infinity +
  FL), eq. (8):

  .. math::

      \bar\tau = \ddot r + 2\lambda(\dot r - \dot q) + \lambda^2 (e + y), \qquad
      \tau = \hat M(q)\,\bar\tau + \hat V(q, \dot q) + \hat G(q),

  with ``y = C x + D e`` and ``K``'s state ``xdot = A x + B e`` (continuous) or
  ``x+ = A x + B e`` after the output (sampled, matrices discretized), ``Mhat`` from CRBA
  (symmetrized from its upper triangle) and ``Vhat + Ghat`` from ``nonLinearEffects``;
* :class:`~rrr_pin.control.laws.FLAWForm`, the same torque clipped to the law's limits, with
  ``K``'s state conditioned on the clipped torque (Hanus; H-infinity + FL with anti-windup);
* :class:`~rrr_pin.control.laws.PDForm`, PD + gravity compensation:
  ``tau = Kp e + Kd (rd - qd) + Ghat(q)``.

The form's fields, the run (:class:`~rrr_pin.sim.trajectory.Run`) and its plant effects
(:class:`~rrr_pin.control.effects.Resolved`) reach C++ as three objects whose fields are set by
name (``FLLaw``/``PDLaw``, ``RolloutInputs``, ``Effects``), so a field added on one side and not
on the other fails loudly (``AttributeError``) instead of being dropped.

The reference arrives sampled by :func:`rrr_pin.sim.simulation.simulate` on the grid where the
law is evaluated, so every reference runs here. Trajectories equal the Python engine's to
round-off (``tests/test_engines.py``). Call it through ``simulate(..., engine="compiled")`` (or
``"auto"``); :func:`run_compiled` takes a run that ``simulate`` has already validated.

Models reach C++ as :meth:`pinocchio.Model.saveToString` text (Boost.Serialization, exact for
doubles, including infinite joint limits), so the extension needs no Boost.Python object.

Build: ``pip install .`` (or ``pip install -e .``) compiles the extension with scikit-build-core
against the Pinocchio C++ library of the ``libpinocchio`` wheel; the exact Pinocchio version is
pinned at build and run time (``pyproject.toml``) and checked at import.
"""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from ..control.effects import Resolved
from ..control.laws import FLAWForm, FLForm, PDForm, check_law_output
from .extension import EXTENSION, CompiledRobot, available, cached, require
from .trajectory import (
    LAW_TORQUE,
    REASONS,
    VELOCITY_LIMIT,
    divergence,
    law_divergence,
    make_trajectory,
)

__all__ = [
    "compile_robot",
    "why_not",
    "run_compiled",
    "floor_ms",
    "implements",
    "ENGINE_LAWS",
]

#: The compiled forms the C++ loop implements, by exact type, and the C++ law (a class of the
#: extension whose fields are the form's, ``nominal`` aside) each one becomes.
ENGINE_LAWS = {FLForm: "FLLaw", PDForm: "PDLaw", FLAWForm: "FLAWLaw"}


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


def implements(form) -> bool:
    """Whether the compiled engine implements ``form`` (its exact type in :data:`ENGINE_LAWS`)."""
    return type(form) in ENGINE_LAWS


def _known() -> str:
    return ", ".join(cls.__name__ for cls in ENGINE_LAWS)


def _fill(obj, **values):
    """Set the fields of an extension object by name; return it."""
    for key, value in values.items():
        setattr(obj, key, value)
    return obj


def _law(form):
    """Return the C++ law of a compiled form: the extension's class for its type, by name."""
    return _fill(getattr(EXTENSION, ENGINE_LAWS[type(form)])(),
                 **{f.name: getattr(form, f.name) for f in fields(form) if f.name != "nominal"})


def _effects(fx: Resolved):
    """Return the C++ ``Effects``: every field of ``fx`` but ``info``, by name (None: off)."""
    return _fill(EXTENSION.Effects(), **{f.name: getattr(fx, f.name) for f in fields(fx)
                                         if f.name != "info" and getattr(fx, f.name) is not None})


def why_not(run, form) -> str | None:
    """Why the compiled engine cannot run ``run`` exactly (None: it can; :mod:`.engines`).

    A plant with loop closures runs on the closed-chain loop of
    :mod:`rrr_pin.sim.chain_compiled`, which says what it implements.
    """
    law = run.law
    if form is None:
        cls = type(getattr(law, "law", law)).__name__  # a sampled wrapper: its law's class
        return (f"law {law.name!r} ({cls}) declares no compiled form, so the compiled engine "
                f"cannot run it")
    if not available():
        try:
            require()
        except ImportError as exc:
            return str(exc)
    if run.plant.loop_closures or form.nominal.loop_closures:
        from .chain_compiled import why_not as chain_why_not

        return chain_why_not(run, form)
    if not implements(form):
        return (f"compiled form {type(form).__qualname__} of law {law.name!r} is not "
                f"implemented in C++ (known: {_known()})")
    return None


def run_compiled(run, form):
    """Run a validated simulation (:class:`rrr_pin.sim.trajectory.Run`) of a law's compiled form.

    Parameters
    ----------
    run : Run
        What :func:`rrr_pin.sim.simulation.simulate` validated.
    form : CompiledForm
        ``run.law.compiled_form()``; an instance of a type in :data:`ENGINE_LAWS`.

    Returns
    -------
    Trajectory
        As the Python engine's.

    Raises
    ------
    SimulationDiverged
        Same test and message as the Python engine.
    ValueError
        A compiled form of a type the C++ loop does not implement (never run as another).
    """
    require()
    why = why_not(run, form)
    if why is not None:
        raise ValueError(f"{why}; use engine='python'")
    plant = run.plant
    if plant.loop_closures:
        from .chain_compiled import run_chain

        return run_chain(run, form)
    fx = run.effects
    run.info.update(plant.check_path(run.grid, run.R))  # a tree's own check: nothing to record
    plant_m, nominal_m = compile_robot(plant)._model, compile_robot(form.nominal)._model
    inputs = _fill(EXTENSION.RolloutInputs(), sampled=run.sampled, R=run.R, RD=run.RD,
                   RDD=run.RDD, q0=run.q0, qd0=run.qd0, x0=run.x0, lower=run.lower,
                   upper=run.upper, vlim=VELOCITY_LIMIT, h=run.h, substeps=run.substeps,
                   n_steps=len(run.t) - 1)
    Q, QD, TAU, bad_step, bad_joint, reason = EXTENSION.rollout(
        plant_m, nominal_m, _law(form), inputs, _effects(fx) if fx is not None else None)
    law_failed = bad_step >= 0 and reason == LAW_TORQUE
    if law_failed and bad_step == 0 and not np.isfinite(TAU[0]).all():
        # The Python engine checks a law's first output at the edge: the same ValueError.
        check_law_output(run.law, "step() torque" if run.sampled else "torque()", TAU[0],
                         plant.nq, float(run.t[0]))
    if law_failed:
        raise law_divergence(plant, run.law.name, float(run.t[bad_step]), bad_joint)
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
    kind : {"fl", "pd", "fl_aw"}
        The ``kind`` of a form in :data:`ENGINE_LAWS` (``FLForm.kind``, ``PDForm.kind``,
        ``FLAWForm.kind``; ``"fl_aw"`` times FL's calls).
    sampled : bool, default True

    Returns
    -------
    float
        Wall time [ms] of the fastest run.
    """
    plant_c, nominal_c = compile_robot(plant), compile_robot(nominal)
    if repeat < 1:
        raise ValueError(f"repeat must be >= 1, got {repeat!r}")
    kinds = {cls.kind: name for cls, name in ENGINE_LAWS.items()}
    if kind not in kinds:
        raise ValueError(f"kind must be one of {', '.join(kinds)}, got {kind!r}")
    law = getattr(EXTENSION, kinds[kind])()  # only its type matters: which calls to time
    return 1e3 * min(EXTENSION.floor_timing(plant_c._model, nominal_c._model, law, bool(sampled),
                                           int(substeps), int(n_steps))
                     for _ in range(repeat))

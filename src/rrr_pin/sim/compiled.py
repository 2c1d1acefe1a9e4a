r"""The compiled engine: the whole closed-loop run in one C++ call, for any plant.

It runs the laws whose :class:`~rrr_pin.control.laws.CompiledForm` it implements, operation for
operation as the Python reference engine of :mod:`rrr_pin.sim.python_engine` does, on any
plant: the plant reaches C++ as its :meth:`~rrr_pin.model.plant.Plant.description` (a
:class:`~rrr_pin.model.plant.TreeDescription`: the tree, its loop closures, the split of its
coordinates), so nothing here asks which kind of plant it has. C++ sources in
``src/rrr_pin/_ext/`` (built by ``pip install .``): one rollout (``rollout.cpp``) templated on
the plant (``plant.hpp``) and on where the law's model comes from (``terms.hpp``), with the laws
of ``law.hpp``, the plant effects of ``effects.hpp`` and the one RK4 of ``rk4.hpp``:

* the plant: a serial tree (no loop) under Pinocchio's ABA; a closed chain under its exact
  constrained dynamics (``tree.cpp``; CRBA, the nonlinear effects, the loop-closure Jacobian
  ``J`` on the independent rows of the description and ``gamma = Jdot qd``), the KKT system
  solved exactly,

  .. math::

      \ddot q = M^{-1}(u - h) - M^{-1} J^T (J M^{-1} J^T)^{-1} (J M^{-1}(u - h) + \gamma),

  which is what Pinocchio's proximal ``constraintDynamics`` of the Python engine converges to
  (to about 6e-11 rad/s^2 at :data:`~rrr_pin.model.closed_chain.PROXIMAL_MU`), and after every
  RK4 step what :class:`~rrr_pin.model.closed_chain.ChainSettler` does: the drift check against
  the description's ``drift_bound``, the projection (Newton on the passive coordinates to
  ``closure_tol``, then ``qd = S qd_a``), the drift records and the type-II checks
  (``cond(J_p)`` above ``cond_limit``, a sign change of ``det J_p``);
* the plant effects (:class:`~rrr_pin.control.effects.Resolved`: delay, actuator lag,
  saturation, friction, sensor noise, encoder, flexible joints) on the actuated coordinates,
  the passive ones of a closed chain ideal, as the Python engine's ``_effects``;
* the law, by the exact type of its compiled form (its ``cpp``, a C++ law of the extension:
  :func:`rrr_pin.sim.extension.law_name`), on its model's
  ``terms`` and ``G`` (a serial tree's CRBA, ``nonLinearEffects`` and gravity; a closed
  chain's reduced model, its passive coordinates by the law's own Newton seeded from its
  previous evaluation, the first from its description's ``home``):

  - :class:`~rrr_pin.control.laws.FLForm`, the feedback-linearizing laws (FL alone,
    H-infinity + FL), eq. (8):

    .. math::

        \bar\tau = \ddot r + 2\lambda(\dot r - \dot q) + \lambda^2 (e + y), \qquad
        \tau = \hat M(q)\,\bar\tau + \hat h(q, \dot q),

    with ``y = C x + D e`` and ``K``'s state ``xdot = A x + B e`` (continuous) or
    ``x+ = A x + B e`` after the output (sampled, matrices discretized);
  - :class:`~rrr_pin.control.laws.FLAWForm`, the same torque clipped to the law's limits, with
    ``K``'s state conditioned on the clipped torque (Hanus; H-infinity + FL with anti-windup);
  - :class:`~rrr_pin.control.laws.PDForm`, PD + gravity compensation:
    ``tau = Kp e + Kd (rd - qd) + Ghat(q)``;
  - :class:`~rrr_pin.control.laws.TwoDOFForm`, feedback linearization with the 2-DOF
    H-infinity controller (``hinf2dof``): ``tauhat = q + C x + D v`` on ``v = [e; qd]``,
    ``taubar = lam^2 (tauhat - q) - 2 lam qd``, ``tau = Mhat(q) taubar + hhat(q, qd)``, state
    ``A x + B v``.

  Any other form is refused with a ``ValueError`` naming it (:func:`why_not`); sampled and
  continuous-time laws run alike (a continuous law at every RK4 stage, the plant settled after
  every step, as in the Python engine).

The form's fields, the run (:class:`~rrr_pin.sim.trajectory.Run`) and its plant effects reach C++
as three objects whose fields are set by name (``FLLaw``/``FLAWLaw``/``PDLaw``/``TwoDOFLaw``,
``RolloutInputs``, ``Effects``), so a field added on one side and not on the other fails loudly
(``AttributeError``) instead of being dropped. Models travel as
:meth:`pinocchio.Model.saveToString` text (Boost.Serialization, exact for doubles, including
infinite joint limits), so the extension needs no Boost.Python object.

The reference arrives sampled by :func:`rrr_pin.sim.simulation.simulate` on the grid where the
law is evaluated; the plant's own check of it (:meth:`~rrr_pin.model.plant.Plant.check_path`,
a closed chain's closures and singularities along it) runs in C++ too
(:func:`check_reference_compiled`). Trajectories equal the Python engine's to round-off
(``tests/test_engines.py``). A run that stops (a divergence, a law's non-finite torque, a drift,
a singularity, a loop that cannot close) raises the Python engine's exception with its message:
C++ returns where it stopped and the state, and the Python model re-derives the error there.
Call it through ``simulate(..., engine="compiled")`` (or ``"auto"``); :func:`run_compiled` takes
a run that ``simulate`` has already validated.

Build: ``pip install .`` (or ``pip install -e .``) compiles the extension with scikit-build-core
against the Pinocchio C++ library of the ``libpinocchio`` wheel; the exact Pinocchio version is
pinned at build and run time (``pyproject.toml``) and checked at import.
"""

from __future__ import annotations

import math

import numpy as np

from ..control.laws import check_law_output
from ..model.closed_chain import ConstraintDrift, LoopClosureError, SingularConfiguration
from .engine_names import COMPILED, PYTHON
from .extension import (
    EXTENSION,
    CompiledRobot,
    cached,
    cannot_start,
    effects_struct,
    law_forms,
    law_kinds,
    law_name,
    law_struct,
    require,
)
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
    "check_reference_compiled",
    "floor_ms",
    "acceleration_ms",
    "implements",
    "ENGINE_LAWS",
]

#: The compiled forms the C++ loop implements, by exact type, and their C++ law: a view derived
#: at import from the one list of laws (``RRR_PIN_LAWS``, through each form's ``cpp``), not a
#: second list; :func:`implements` is the test the engines use.
ENGINE_LAWS = {cls: vars(cls)["cpp"] for cls in law_forms()}

# Why a C++ run stopped (RolloutResult.reason, Reason of terms.hpp): 0 to 3 index
# rrr_pin.sim.trajectory.REASONS (the divergences, LAW_TORQUE: a law's non-finite torque), the
# others are a closed chain's (its plant's settle, its law model's loop closure).
_DRIFT, _PLANT_SINGULAR, _PLANT_NO_CLOSE, _PLANT_CROSSED, _LAW_SINGULAR, _LAW_NO_CLOSE = range(
    4, 10)

# The last few plants loaded, by identity of the plant's pin.Model (a campaign reuses the
# nominal model for every sample and every law).
_CACHE: dict = {}


def compile_robot(plant) -> CompiledRobot:
    """Load a plant's :meth:`~rrr_pin.model.plant.Plant.description` into the extension.

    About 0.5 ms for a 6-joint arm. The copy is independent of later changes to the plant. Each
    rollout builds its own ``pinocchio::Data``, so one :class:`CompiledRobot` may serve
    concurrent rollouts in several threads (the extension releases the GIL).

    Parameters
    ----------
    plant : Plant or CompiledRobot
        A serial arm, a closed chain (any :class:`~rrr_pin.model.plant.Plant`); a
        :class:`CompiledRobot` is returned as is.

    Raises
    ------
    ImportError
        The extension is not built or was built for another Pinocchio (see :func:`available`).
    """
    if isinstance(plant, CompiledRobot):
        return plant
    require()
    return cached(_CACHE, plant, _load)


def _load(plant) -> CompiledRobot:
    d = plant.description()
    tree = EXTENSION.Tree(
        d.model.saveToString(), np.asarray(d.actuated, dtype=np.int32),
        np.asarray(d.passive, dtype=np.int32),
        np.asarray(d.loop_joints, dtype=np.int32).reshape(-1, 2),
        np.asarray(d.loop_anchors, dtype=float).reshape(-1, 3),
        np.asarray(d.rows, dtype=np.int32), np.asarray(d.home, dtype=float),
        float(d.closure_tol), int(d.max_iter), float(d.cond_limit), float(d.drift_bound))
    return CompiledRobot(plant.name, tuple(plant.joint_names), tree, d)


def implements(form) -> bool:
    """Whether the compiled engine implements ``form`` (its exact type's ``cpp`` is a C++ law)."""
    return law_name(form) is not None


def _known() -> str:
    return ", ".join(cls.__name__ for cls in law_forms())


def _fill(obj, **values):
    """Set the fields of an extension object by name; return it."""
    for key, value in values.items():
        setattr(obj, key, value)
    return obj


def why_not(run, form) -> str | None:
    """Why the compiled engine cannot run ``run`` exactly (None: it can; :mod:`.engines`).

    It runs every plant (serial or closed chain), every plant effect, sampled and continuous
    laws; it refuses a law without a compiled form, a form of a type it does not implement, or
    runs nothing when the extension is not built.
    """
    law = run.law
    reason = cannot_start(law, form, COMPILED)
    if reason is not None:
        return reason
    if not implements(form):
        return (f"compiled form {type(form).__qualname__} of law {law.name!r} is not "
                f"implemented in C++ (known: {_known()})")
    return None


def check_reference_compiled(plant, t, R) -> dict | None:
    """:meth:`~rrr_pin.model.plant.Plant.check_path`'s test, in C++; None where it fails.

    For a closed chain, :func:`rrr_pin.model.closed_chain.check_chain_reference`'s test: the
    same Newton closures from the description's ``home`` along ``R``, the same ``cond(J_p)``
    and ``det J_p`` tests, recorded as ``reference_max_cond_Jp`` and
    ``reference_max_cond_at_s`` (``{}`` for a serial tree, which has nothing to check). None
    when a sample fails: the Python check then runs and raises with its message (time, cond).

    Parameters
    ----------
    plant : Plant
    t : ndarray, shape (N,)
        Sample times [s].
    R : ndarray, shape (N, plant.nq)
        Actuated reference [rad].

    Returns
    -------
    dict or None
        What the run records of the path, or None where the check fails.
    """
    compiled = compile_robot(plant)
    status, k, cond = EXTENSION.check_reference(compiled._model,
                                                np.ascontiguousarray(R, dtype=float))
    if status:
        return None
    if not compiled.loops:
        return {}
    return {"reference_max_cond_Jp": float(cond), "reference_max_cond_at_s": float(t[k])}


def run_compiled(run, form):
    """Run a validated simulation (:class:`rrr_pin.sim.trajectory.Run`) of a law's compiled form.

    Parameters
    ----------
    run : Run
        What :func:`rrr_pin.sim.simulation.simulate` validated.
    form : CompiledForm
        ``run.law.compiled_form()``; one :func:`implements`.

    Returns
    -------
    Trajectory
        As the Python engine's, ``info`` with the same keys (a closed chain's records of the
        path and of the run: ``reference_max_cond_Jp``, the drift, its bound, the final full
        state).

    Raises
    ------
    SimulationDiverged
        Same test and message as the Python engine.
    SingularConfiguration, LoopClosureError, ConstraintDrift
        A closed chain's stop (plant or law model), as the Python engine, with its messages.
    ValueError
        A compiled form of a type the C++ loop does not implement (never run as another).
    """
    require()
    why = why_not(run, form)
    if why is not None:
        raise ValueError(f"{why}; use engine={PYTHON!r}")
    plant = run.plant
    compiled = compile_robot(plant)
    path = check_reference_compiled(compiled, run.grid, run.R)
    run.info.update(plant.check_path(run.grid, run.R) if path is None else path)
    fx = run.effects
    x0, v0 = run.state0
    inputs = _fill(EXTENSION.RolloutInputs(), sampled=run.sampled, R=run.R, RD=run.RD,
                   RDD=run.RDD, q0=x0, qd0=v0, x0=run.x0, lower=run.lower, upper=run.upper,
                   vlim=VELOCITY_LIMIT, h=run.h, substeps=run.substeps,
                   n_steps=len(run.t) - 1)
    out = EXTENSION.rollout(compiled._model, compile_robot(form.nominal)._model, law_struct(form),
                            inputs, effects_struct(fx))
    if out.step >= 0:
        _raise(run, form, compiled.description, out)
    traj = make_trajectory(run, out.Q, out.QD, out.TAU)
    if compiled.loops:  # what a closed chain's settler records (ChainSettler.info)
        traj.info.update({"drift_m": float(out.drift), "drift_velocity_m_s": float(out.drift_v),
                          "drift_bound_m": compiled.description.drift_bound,
                          "final_q": out.q.tolist(), "final_qd": out.qd.tolist()})
    return traj


def _raise(run, form, description, out):
    """Raise the Python engine's exception for the stop C++ reported (the model re-derives it)."""
    plant, t, k, reason = run.plant, run.t, int(out.step), int(out.reason)
    law_model = reason in (_LAW_SINGULAR, _LAW_NO_CLOSE)
    if k == 0 and not law_model and not np.isfinite(out.TAU[0]).all():
        # The Python engine checks a law's first output at the edge: the same ValueError.
        check_law_output(run.law, "step() torque" if run.sampled else "torque()", out.TAU[0],
                         plant.nq, float(t[0]))
    if reason == LAW_TORQUE:
        raise law_divergence(plant, run.law.name, float(t[k]), out.joint)
    if reason < LAW_TORQUE:
        raise divergence(plant, float(t[k]), out.Q[k], out.QD[k], out.joint, REASONS[reason])
    q, qd = np.array(out.q), np.array(out.qd)
    if reason == _DRIFT:
        raise ConstraintDrift(
            f"{plant.name}: one RK4 step of {run.h:g} s left a loop gap of {out.value:.3g} m at "
            f"t = {t[k]:.6g} s (bound {description.drift_bound:g} m): take a smaller dt")
    if reason in (_PLANT_SINGULAR, _PLANT_NO_CLOSE):
        try:
            plant.project(q, qd)
        except SingularConfiguration as exc:
            raise SingularConfiguration(f"plant at t = {t[k + 1]:.6g} s: {exc}",
                                        exc.cond) from None
        # LoopClosureError propagates as in the Python engine.
        _fallback(plant.name, "plant", reason == _PLANT_SINGULAR, out.value, t[k + 1],
                  description)
    if reason == _PLANT_CROSSED:
        raise SingularConfiguration(
            f"plant at t = {t[k + 1]:.6g} s: crossed a type-II (parallel) singularity in "
            f"the last step (det J_p changed sign; cond(J_p) = {out.value:.3g} after it): the "
            f"actuated angles no longer determine the mechanism's branch", math.inf)
    # The law model's closure at the actuated q it was evaluated at, from its Newton seed.
    nominal = form.nominal
    nominal.close(np.array(out.law_q), seed=np.array(out.seed))
    _fallback(nominal.name, "law", reason == _LAW_SINGULAR, out.value, t[k],
              compile_robot(nominal).description)


def _fallback(name, who, singular, value, tk, description):
    """Raise from the C++ values a stop the Python model did not reproduce (borderline)."""
    if singular:
        raise SingularConfiguration(
            f"{name} ({who}, compiled engine) at t = {tk:.6g} s: type-II (parallel) "
            f"singularity: cond(J_p) = {value:.3g} > {description.cond_limit:g}", value)
    raise LoopClosureError(f"{name} ({who}, compiled engine) at t = {tk:.6g} s: the loop does "
                        f"not close (Newton did not converge in {description.max_iter} "
                        f"iterations)")


def floor_ms(plant, nominal, n_steps: int, substeps: int = 1, repeat: int = 5, *,
             kind: str = "fl", sampled: bool = True) -> float:
    """Time the "C++ floor" of a rollout: the wall time [ms] of its bare Pinocchio calls.

    Times, in a plain C++ loop, exactly the Pinocchio calls a compiled rollout of a law of
    ``kind`` on serial trees makes, with no law, reference or integrator arithmetic: sampled,
    per control step, the law's calls on ``nominal`` (``"fl"``: one CRBA and one
    ``nonLinearEffects``; ``"pd"``: one ``computeGeneralizedGravity``) and ``4 substeps`` ABA on
    ``plant``; continuous, per RK4 step, four times the law's calls and one ABA. A closed chain
    is refused by the extension (``ValueError``); its plant's calls alone are
    :func:`acceleration_ms`.

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
    kind : {"fl", "pd", "fl_aw", "twodof"}
        The ``kind`` of a form the engine implements (``FLForm.kind``, ``PDForm.kind``,
        ``FLAWForm.kind``, ``TwoDOFForm.kind``; ``"fl_aw"`` and ``"twodof"`` time FL's
        calls).
    sampled : bool, default True

    Returns
    -------
    float
        Wall time [ms] of the fastest run.
    """
    plant_c, nominal_c = compile_robot(plant), compile_robot(nominal)
    if repeat < 1:
        raise ValueError(f"repeat must be >= 1, got {repeat!r}")
    kinds = law_kinds()
    if kind not in kinds:
        raise ValueError(f"kind must be one of {', '.join(kinds)}, got {kind!r}")
    law = getattr(EXTENSION, kinds[kind])()  # only its type matters: which calls to time
    return 1e3 * min(EXTENSION.floor_timing(plant_c._model, nominal_c._model, law, bool(sampled),
                                           int(substeps), int(n_steps))
                     for _ in range(repeat))


def acceleration_ms(plant, x, v, tau, calls: int, repeat: int = 5) -> float:
    """Time ``calls`` plant accelerations in C++, the fastest of ``repeat`` runs [ms].

    The plant's share of a compiled run: ABA for a serial arm, the exact KKT for a closed chain
    (the engine face's ``acceleration``, at one state).

    Parameters
    ----------
    plant : Plant or CompiledRobot
    x, v : ndarray, shape (nv,)
        Full state [rad, rad/s] (every coordinate of the tree).
    tau : ndarray, shape (nq,)
        Actuator torques [N m].
    calls : int
        Accelerations per run, >= 0.
    repeat : int, default 5
        Runs, >= 1.

    Returns
    -------
    float
        Wall time [ms] of the fastest run.
    """
    compiled = compile_robot(plant)
    if repeat < 1:
        raise ValueError(f"repeat must be >= 1, got {repeat!r}")
    args = (np.asarray(x, dtype=float), np.asarray(v, dtype=float),
            np.asarray(tau, dtype=float), int(calls))
    return 1e3 * min(EXTENSION.acceleration_timing(compiled._model, *args)
                     for _ in range(repeat))

r"""The compiled closed-chain engine: a parallel mechanism's whole closed-loop run in one C++ call.

It runs what the Python engine of :mod:`rrr_pin.sim.closed_chain` runs for a sampled law,
operation for operation (C++ in ``src/rrr_pin/_ext/chain.hpp``, ``chain.cpp``):

* the plant: the full constrained dynamics of the tree, ``M(q)`` by CRBA, the nonlinear
  effects, the loop-closure Jacobian ``J`` (its independent rows, those the ``rows`` of
  :class:`~rrr_pin.model.closed_chain.ClosedChain` pick) and ``gamma = Jdot qd``, with
  the KKT system solved exactly,

  .. math::

      \ddot q = M^{-1}(u - h) - M^{-1} J^T (J M^{-1} J^T)^{-1} (J M^{-1}(u - h) + \gamma),

  which is what Pinocchio's proximal ``constraintDynamics`` converges to (the Python engine's
  plant; it reaches it to about 6e-11 rad/s^2 at
  :data:`~rrr_pin.model.closed_chain.PROXIMAL_MU`); RK4 with the torque held over the control
  period and ``substeps`` steps; after every step the drift check against
  :data:`~rrr_pin.model.closed_chain.DRIFT_BOUND`, the projection (Newton on the passive
  coordinates to :data:`~rrr_pin.model.closed_chain.CLOSURE_TOL`, then ``qd = S qd_a``), the
  drift records and the type-II checks (``cond(J_p)`` above
  :data:`~rrr_pin.model.closed_chain.COND_LIMIT`, a sign change of ``det J_p``);
* the law: :class:`~rrr_pin.control.laws.FLForm` with a closed-chain nominal, the sampled
  :class:`~rrr_pin.control.laws.TrackingController` (FL alone, H-infinity + FL with ``K``
  discretized as the sampled law does), its own loop closure by Newton seeded from its previous
  sample (the first from its mechanism's ``home``).

**Dynamics: Pinocchio's C++ algorithms, not generated code.** The extension already links
Pinocchio's C++ library (the serial compiled engine calls its ABA), so the engine calls
``crba``, ``nonLinearEffects``, ``rnea``, ``computeJointJacobians`` and second-order
``forwardKinematics`` on the plant's deserialized ``pinocchio.Model``
(:meth:`pinocchio.Model.saveToString`, exact for doubles). That is the library the Python engine
uses, for every joint type it has: the 5-bar's unaligned revolutes and the Delta's composite
joints run without a generator for them (:mod:`rrr_pin.sim.dyngen` knows RX/RY/RZ only) and
without hand-written RNEA/CRBA, and a perturbed plant's parameters arrive with its model at run
time. A 10 s, 1 kHz run of the 5-bar takes about half the time of the 40 000
``constraintDynamics`` calls alone that the Python engine makes for it (0.49 to 0.67 times,
measured side by side by ``scripts/bench.py``, section 4b: 0.31 s at a load average of 6 on 2
cores, about 0.25 s at the 0.42 s those calls take on a quieter machine, under the issue's
0.3 s), so generated code was not needed for the goal. The loop-closure kinematics
(anchor points, their Jacobian and classical acceleration) are written in ``chain.cpp`` from
Pinocchio's joint placements, velocities and accelerations; a test pins them on
:meth:`~rrr_pin.model.closed_chain.ClosedChain.jacobian` and
:meth:`~rrr_pin.model.closed_chain.ClosedChain.gamma`.

Refusals, each by name (:func:`why_not`): a law without a compiled form, a compiled form
this engine does not implement, a continuous-time law (sampled laws only), plant effects, or
the extension not built. ``engine="auto"`` then runs Python and records why in
``info["engine_note"]``. A run that stops (drift, singularity, a loop that cannot close) raises
the Python engine's exception with its message: C++ returns where it stopped and the state, and
the Python model re-derives the error there.
"""

from __future__ import annotations

import math

import numpy as np

from ..control.laws import FLForm
from ..model.closed_chain import (
    CLOSURE_TOL,
    COND_LIMIT,
    DRIFT_BOUND,
    ConstraintDrift,
    LoopClosureError,
    SingularConfiguration,
)
from .extension import EXTENSION, cached, require
from .trajectory import Trajectory, make_trajectory

__all__ = ["why_not", "compile_chain", "run_chain", "check_reference_compiled", "CHAIN_FORMS"]

#: The compiled forms the closed-chain C++ loop implements, by exact type, and their C++ law.
CHAIN_FORMS = {FLForm: "ChainFLLaw"}

#: Newton iterations of a loop closure (the default of ClosedChain.close).
_MAX_ITER = 30

# Status codes of chain.hpp (ChainStatus).
_OK, _DRIFT, _PLANT_SINGULAR, _PLANT_NO_CLOSE, _PLANT_CROSSED, _LAW_SINGULAR, _LAW_NO_CLOSE = (
    range(7))

_CACHE: dict = {}


def compile_chain(chain):
    """Load a :class:`~rrr_pin.model.closed_chain.ClosedChain` into the extension (cached).

    The tree travels as :meth:`pinocchio.Model.saveToString` text; each loop closure as the
    joints and the local anchor points of its two sides (``joint1_placement`` and
    ``joint2_placement`` translations of its ``RigidConstraintModel``), with the independent
    rows, the coordinate split and ``home``.
    """
    require()

    def load(c):
        cons = c.constraints
        return EXTENSION.ChainModel(
            c.model.saveToString(),
            np.array([k.joint1_id for k in cons], dtype=np.int32),
            np.array([k.joint2_id for k in cons], dtype=np.int32),
            np.array([k.joint1_placement.translation for k in cons], dtype=float).T.copy(),
            np.array([k.joint2_placement.translation for k in cons], dtype=float).T.copy(),
            np.asarray(c.rows, dtype=np.int32), np.asarray(c.actuated, dtype=np.int32),
            np.asarray(c.passive, dtype=np.int32), np.asarray(c.home, dtype=float))

    return cached(_CACHE, chain, load)


def why_not(run, form) -> str | None:
    """Why the closed-chain C++ loop cannot run ``run`` exactly (None: it can).

    Called by :func:`rrr_pin.sim.compiled.why_not` for a plant (or a law's model) with loop
    closures, once the law has a compiled form and the extension is built.
    """
    plant, law = run.plant, run.law
    if run.effects is not None:
        return (f"plant effects are not implemented by the compiled closed-chain engine "
                f"(plant {plant.name!r})")
    if not run.sampled:
        return (f"law {law.name!r} runs in continuous time (no rate): the compiled "
                f"closed-chain engine runs sampled laws only")
    if type(form) not in CHAIN_FORMS:
        return (f"compiled form {type(form).__qualname__} of law {law.name!r} is not "
                f"implemented by the compiled closed-chain engine (known: "
                f"{', '.join(c.__name__ for c in CHAIN_FORMS)})")
    if not form.nominal.loop_closures:
        return f"law {law.name!r}'s model {form.nominal.name!r} is not a closed chain"
    if not plant.loop_closures:
        return f"plant {plant.name!r} is not a closed chain, law {law.name!r}'s model is"
    return None


def check_reference_compiled(chain, t, R) -> dict | None:
    """:func:`rrr_pin.sim.closed_chain.check_chain_reference`'s test, in C++.

    The same Newton closures from ``chain.home`` along ``R``, the same ``cond(J_p)`` and
    ``det J_p`` tests. Returns ``{"max_cond_Jp", "at_s"}`` when every sample passes, and None
    when one fails: the Python check then runs and raises with its message (time, cond).

    Parameters
    ----------
    chain : ClosedChain
    t : ndarray, shape (N,)
        Sample times [s].
    R : ndarray, shape (N, chain.nq)
        Actuated reference [rad].
    """
    status, k, cond = EXTENSION.chain_check_reference(
        compile_chain(chain), np.ascontiguousarray(R, dtype=float), chain.home, CLOSURE_TOL,
        _MAX_ITER, COND_LIMIT)
    if status:
        return None
    return {"max_cond_Jp": float(cond), "at_s": float(t[k])}


def run_chain(run, form) -> Trajectory:
    """Run a validated sampled closed-chain run (:class:`~rrr_pin.sim.trajectory.Run`) in C++.

    The reference is checked along its grid in C++ (:func:`check_reference_compiled`; the
    Python check re-raises a failure with its message), then the whole run is one call. The
    trajectory's ``info`` has the Python engine's keys: the plant's records of the path
    (:meth:`~rrr_pin.model.closed_chain.ClosedChain.check_path`) and of the run (the drift,
    its bound, the final full state).

    Raises
    ------
    SingularConfiguration, LoopClosureError, ConstraintDrift
        As the Python engine, with its messages.
    """
    plant = run.plant
    t, R = run.t, run.R
    c = check_reference_compiled(plant, t, R)
    path = ({"reference_max_cond_Jp": c["max_cond_Jp"], "reference_max_cond_at_s": c["at_s"]}
            if c is not None else plant.check_path(t, R))
    q, qd = run.state0
    claw = EXTENSION.ChainFLLaw()
    claw.lam, claw.A, claw.B, claw.C, claw.D = form.lam, form.A, form.B, form.C, form.D
    inputs = EXTENSION.ChainInputs()
    for key, value in (("R", R), ("RD", run.RD), ("RDD", run.RDD), ("q0", q), ("qd0", qd),
                       ("x0", run.x0), ("h", float(run.h)), ("substeps", int(run.substeps)),
                       ("n_steps", len(t) - 1), ("closure_tol", CLOSURE_TOL),
                       ("max_iter", _MAX_ITER), ("cond_limit", COND_LIMIT),
                       ("drift_bound", float(DRIFT_BOUND))):
        setattr(inputs, key, value)
    out = EXTENSION.chain_rollout(compile_chain(plant), compile_chain(form.nominal), claw,
                                  inputs)
    if out.status != _OK:
        _raise(plant, form.nominal, out, t, run.h, DRIFT_BOUND, ConstraintDrift)
    traj = make_trajectory(run, out.Q, out.QD, out.TAU)
    traj.info.update(path)
    traj.info.update({"drift_m": float(out.drift), "drift_velocity_m_s": float(out.drift_v),
                      "drift_bound_m": DRIFT_BOUND, "final_q": out.q.tolist(),
                      "final_qd": out.qd.tolist()})
    return traj


def _raise(plant, nominal, out, t, h, drift_bound, drift_error):
    """Raise the Python engine's exception for the stop C++ reported (the model re-derives it)."""
    k, status = int(out.step), int(out.status)
    q, qd = np.array(out.q), np.array(out.qd)
    if status == _DRIFT:
        raise drift_error(
            f"{plant.name}: one RK4 step of {h:g} s left a loop gap of {out.value:.3g} m at "
            f"t = {t[k]:.6g} s (bound {drift_bound:g} m): take a smaller dt")
    if status in (_PLANT_SINGULAR, _PLANT_NO_CLOSE):
        try:
            plant.project(q, qd)
        except SingularConfiguration as exc:
            raise SingularConfiguration(f"plant at t = {t[k + 1]:.6g} s: {exc}",
                                        exc.cond) from None
        # LoopClosureError propagates as in the Python engine.
        _fallback(plant.name, "plant", status == _PLANT_SINGULAR, q, out.value, t[k + 1])
    if status == _PLANT_CROSSED:
        raise SingularConfiguration(
            f"plant at t = {t[k + 1]:.6g} s: crossed a type-II (parallel) singularity in "
            f"the last step (det J_p changed sign; cond(J_p) = {out.value:.3g} after it): the "
            f"actuated angles no longer determine the mechanism's branch", math.inf)
    # The law's closure at the measured q_a (the plant's state at step k).
    nominal.close(q[list(plant.actuated)], seed=np.array(out.seed))
    _fallback(nominal.name, "law", status == _LAW_SINGULAR, np.array(out.seed), out.value, t[k])


def _fallback(name, who, singular, q, value, tk):
    """Raise from the C++ values a stop the Python model did not reproduce (borderline)."""
    if singular:
        raise SingularConfiguration(
            f"{name} ({who}, compiled engine) at t = {tk:.6g} s: type-II (parallel) "
            f"singularity: cond(J_p) = {value:.3g} > {COND_LIMIT:g}", value)
    raise LoopClosureError(f"{name} ({who}, compiled engine) at t = {tk:.6g} s: the loop does "
                           f"not close (Newton did not converge in {_MAX_ITER} iterations)")

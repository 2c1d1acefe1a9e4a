r"""Closed-loop simulation of a parallel mechanism on its full constrained dynamics.

The plant is the whole tree with its loop closures, integrated by Pinocchio's
``constraintDynamics`` (not the reduced model the law uses): a sampled law reads the actuated
``(q_a, qd_a)`` at ``t_k = k Ts``, its torque is held over ``[t_k, t_k + Ts]``, and the full
state ``(q, qd)`` is integrated by ``substeps`` classical RK4 steps. After each step the state
is projected back onto the constraint manifold (Newton on the passive coordinates to
:data:`~rrr_pin.model.closed_chain.CLOSURE_TOL`, then ``qd = S qd_a``; the actuated parts are
kept). A step across a type-II singularity (``det J_p`` changes sign, or ``cond(J_p)`` above
the limit) stops the run with :class:`~rrr_pin.model.closed_chain.SingularConfiguration`
naming the time. The drift each step leaves before its projection is recorded: ``info["drift_m"]``
(largest loop gap [m]) and ``info["drift_velocity_m_s"]`` (largest ``|J qd|``), with the bound
they are checked against, ``info["drift_bound_m"]`` (:data:`DRIFT_BOUND`): a run whose
drift exceeds it stops with :class:`ConstraintDrift` (the step is too large for the motion).

Engines: this module is the Python one (the reference). The compiled engine of
:mod:`rrr_pin.sim.chain_compiled` runs a sampled law with a
:class:`~rrr_pin.control.closed_chain.ChainFLForm` on the ideal plant; ``engine="compiled"``
refuses anything else by name, ``"auto"`` picks compiled when it can and Python otherwise, and
records the engine and why in ``info["engine"]`` and ``info["engine_note"]``; ``"codegen"`` is
refused.

Before the run, the reference is checked along its whole grid (:func:`check_chain_reference`):
each sample must close the loop, away from a type-II singularity (``cond(J_p)`` at most
:data:`~rrr_pin.model.closed_chain.COND_LIMIT`, and no sign change of ``det J_p`` between
samples, which a sampled crossing would otherwise hide); a refusal names the time and the
condition number.

Plant effects (``effects``, :class:`~rrr_pin.control.effects.PlantEffects`) act on the actuated
joints exactly as :func:`rrr_pin.sim.simulation.simulate` applies them to a serial arm's joints,
by the same code (the :class:`~rrr_pin.control.effects.Resolved` steps: sensor, saturation,
delay line on the sub-step grid, actuator lag, flexible transmission, friction): the law reads
the measured actuated ``(q_a, qd_a)``, the drive train's joint torque enters
``constraintDynamics`` on the actuated coordinates, and the actuator and motor states are
integrated by the same RK4 steps as the full state (then projected; they are not). Friction and
flexibility are those of the drives (the actuated joints); the passive joints stay ideal. A delay
must be a whole number of plant sub-steps (refused otherwise, never rounded); effects need a
sampled law; ``torque_limit="urdf"`` is refused (a closed chain's MJCF gives no effort limits).
With effects, a run whose actuated ``q`` or ``qd`` becomes non-finite or ``|qd|`` exceeds
:data:`~rrr_pin.sim.trajectory.VELOCITY_LIMIT` stops with
:class:`~rrr_pin.sim.trajectory.SimulationDiverged`, as a serial arm's, and a non-finite
command is refused at the step that returned it. The settings are recorded in
``info["effects"]``.
"""

from __future__ import annotations

import math

import numpy as np

from ..control.effects import check_effects
from ..control.laws import ControlLaw, SampledLaw, check_law, check_step_output
from ..control.references import check_reference, checked_sample
from ..model.closed_chain import COND_LIMIT, LoopClosureError, SingularConfiguration
from ..validation import check_multiple, check_positive, check_rate
from .chain_compiled import chain_engine, check_reference_compiled, run_chain_compiled
from .trajectory import Trajectory, diverged_joint, divergence, law_divergence, saturation

__all__ = ["simulate_closed_chain", "check_chain_reference", "ConstraintDrift", "DRIFT_BOUND",
           "DEFAULT_DT"]

#: Default RK4 step [s], that of :data:`rrr_pin.sim.simulation.DEFAULT_DT` (which dispatches a
#: closed chain here, so cannot be imported by this module).
DEFAULT_DT = 1e-3

#: Largest loop gap [m] one RK4 step may leave before its projection; above it the run stops.
DRIFT_BOUND = 1e-6


class ConstraintDrift(RuntimeError):
    """An RK4 step left a loop gap above :data:`DRIFT_BOUND` (time and gap in the message)."""


def check_chain_reference(chain, t, R) -> dict:
    """Refuse a reference that leaves the workspace or crosses a type-II singularity.

    Parameters
    ----------
    chain : ClosedChain
        The mechanism (its loop closure and ``J_p``).
    t : ndarray, shape (N,)
        Sample times [s].
    R : ndarray, shape (N, chain.nq)
        Actuated reference [rad] at ``t``.

    Returns
    -------
    dict
        ``{"max_cond_Jp": float, "at_s": float}``: the worst conditioning met.

    Raises
    ------
    SingularConfiguration
        ``cond(J_p) > COND_LIMIT`` at a sample, or ``det J_p`` changes sign between two
        samples (naming the time and the largest condition number there).
    LoopClosureError
        A sample where the loop cannot close (out of the workspace), naming the time.
    """
    q = chain.home.copy()
    pas = list(chain.passive)
    worst, at, sign = 0.0, 0.0, 0.0
    for tk, r in zip(t, R, strict=True):
        try:
            q = chain.close(r, seed=q)
        except SingularConfiguration as exc:
            raise SingularConfiguration(f"reference at t = {tk:.6g} s: {exc}", exc.cond) from None
        except LoopClosureError as exc:
            raise LoopClosureError(f"reference at t = {tk:.6g} s: {exc}") from None
        Jp = chain.jacobian(q)[:, pas]
        cond = float(np.linalg.cond(Jp))
        det = float(np.linalg.det(Jp))
        if cond > worst:
            worst, at = cond, float(tk)
        if sign and det * sign < 0.0:
            raise SingularConfiguration(
                f"reference crosses a type-II (parallel) singularity before t = {tk:.6g} s "
                f"(det J_p changes sign; cond(J_p) = {cond:.3g} there, limit {COND_LIMIT:g})",
                cond)
        sign = math.copysign(1.0, det)
    return {"max_cond_Jp": worst, "at_s": at}


def _resolve_effects(plant, law, effects, continuous: bool, substeps: int, h: float,
                     n_steps: int):
    """Return the run's :class:`~rrr_pin.control.effects.Resolved` effects, None, or refuse.

    Raises
    ------
    ValueError
        Effects with a continuous-time law, or ``torque_limit="urdf"`` (no effort limits in a
        closed chain's description); :meth:`PlantEffects.resolve`'s refusals (a delay that is
        not a whole number of sub-steps ``h``, per-joint sizes of the wrong length, an RK4
        sub-step too large for the actuator or the transmission).
    """
    effects = check_effects(effects)
    if effects is None or not effects.active:
        return None
    if continuous:
        raise ValueError(
            f"effects apply to sampled (digital) controllers only: law {law.name!r} is "
            f"continuous-time; give rate= (e.g. rate=1000) to run it sampled with the effects")
    if isinstance(effects.torque_limit, str):
        raise ValueError(f"torque_limit = {effects.torque_limit!r}: the closed chain "
                         f"{plant.name!r} has no URDF effort limits; give the limit [N m] per "
                         f"actuated joint ({', '.join(plant.joint_names)})")
    return effects.resolve(plant, substeps, h, n_steps)


def simulate_closed_chain(plant, law, reference, duration: float, *, rate: float | None = None,
                          dt: float | None = None, method: str = "tustin", q0=None, qd0=None,
                          engine: str = "auto", effects=None) -> Trajectory:
    """Simulate a sampled law on a parallel mechanism's full constrained dynamics.

    Parameters
    ----------
    plant : ClosedChain
        The true mechanism (may differ from the law's model).
    law : ControlLaw or SampledLaw
        A law on the actuated coordinates (e.g.
        :func:`rrr_pin.control.closed_chain.closed_chain_fl`). A continuous law without
        ``rate`` is evaluated at every RK4 stage; with ``rate``, sampled
        (its ``sampled(rate, method)``).
    reference : Reference
        Actuated-joint reference with ``plant.nq`` joints.
    duration : float
        Simulated time [s], a whole number of control periods.
    rate : float, optional
        Control rate [Hz] of a sampled run (a SampledLaw has its own).
    dt : float, optional
        RK4 step [s]: of a continuous run (default 1e-3), or the plant sub-step of a sampled
        one, dividing ``1/rate`` (default the largest such sub-step not above 1e-3 s).
    method : str, default "tustin"
        Discretization of a continuous law's state.
    q0, qd0 : array-like, shape (plant.nq,), optional
        Initial actuated state [rad, rad/s]; default ``r(0)``, ``rd(0)``.
    engine : {"auto", "python", "compiled"}, default "auto"
        ``"compiled"``: :mod:`rrr_pin.sim.chain_compiled` (a sampled law with a compiled form,
        ideal plant; refused by name otherwise, active plant effects included); ``"auto"``:
        compiled when it can, else Python (``info["engine_note"]`` says why).
    effects : PlantEffects, optional
        Unmodeled dynamics of the drives, sampled runs only (module docstring). None: ideal.

    Returns
    -------
    Trajectory
        Actuated ``q, qd, tau``; ``info`` holds the engine, the plant integration, the drift
        and its bound, the reference's worst ``cond(J_p)``, and the plant's full final state
        ``final_q``, ``final_qd`` (every coordinate, actuated and passive).
    """
    if engine not in ("auto", "python", "compiled"):
        chain_engine(plant, law, engine, continuous=False)  # the refusal, by name
    check_law(law, plant.nq)
    check_reference(reference, plant)
    duration = check_positive("duration", duration, unit="s")
    continuous = isinstance(law, ControlLaw) and rate is None
    if isinstance(law, SampledLaw):
        if rate is not None and not math.isclose(rate, law.rate):
            raise ValueError(f"law {law.name!r} is sampled at {law.rate:g} Hz, rate = "
                             f"{rate!r} asks for another rate")
        rate = law.rate
    elif not continuous:
        law = law.sampled(check_rate("rate", rate), method)
    if continuous:
        h = DEFAULT_DT if dt is None else check_positive("dt", dt, unit="s")
        n_steps = check_multiple("duration", duration, h, low=1, unit="s")
        substeps, rate, Ts = 1, None, h
    else:
        rate = check_rate("rate", rate)
        Ts = 1.0 / rate
        n_steps = check_multiple("duration", duration, Ts, low=1, unit="s")
        if dt is None:
            substeps = max(1, math.ceil(Ts / DEFAULT_DT - 1e-9))
        else:
            dt = check_positive("dt", dt, unit="s")
            substeps = check_multiple("dt", Ts, dt, low=1, unit="s")
        h = Ts / substeps
    fx = _resolve_effects(plant, law, effects, continuous, substeps, h, n_steps)
    engine, engine_note = chain_engine(plant, law, engine, continuous=continuous, effects=fx)
    t = Ts * np.arange(n_steps + 1)
    grid = 0.5 * h * np.arange(2 * n_steps + 1) if continuous else t
    R, RD, RDD = checked_sample(reference, grid)
    conditioning = ((check_reference_compiled(plant, grid, R) if engine == "compiled" else None)
                    or check_chain_reference(plant, grid, R))
    qa0 = R[0] if q0 is None else plant.check_state("q0", q0)
    qda0 = RD[0] if qd0 is None else plant.check_state("qd0", qd0)
    q = plant.close(qa0, seed=plant.home)
    qd = plant.velocity(q, qda0)
    act = list(plant.actuated)
    n = plant.nq
    Q, QD, TAU = (np.empty((n_steps + 1, n)) for _ in range(3))
    Q[0], QD[0] = q[act], qd[act]
    x = np.asarray(law.initial_state(), dtype=float)
    if engine == "compiled":
        return _compiled(plant, law, t, R, RD, RDD, q, qd, x, h, substeps, rate, conditioning,
                         engine_note)
    acc, h2, h6 = plant.constrained_acceleration, 0.5 * h, h / 6.0
    drift = drift_v = 0.0
    pas = list(plant.passive)
    sign = [float(np.linalg.det(plant.jacobian(q)[:, pas]))]

    def project(k, q, qd):
        nonlocal drift, drift_v
        gap = float(np.max(np.abs(plant.residual(q))))
        if not gap <= DRIFT_BOUND:
            raise ConstraintDrift(
                f"{plant.name}: one RK4 step of {h:g} s left a loop gap of {gap:.3g} m at "
                f"t = {t[k]:.6g} s (bound {DRIFT_BOUND:g} m): take a smaller dt")
        drift = max(drift, gap)
        try:
            q, qd_new = plant.project(q, qd)
        except SingularConfiguration as exc:
            raise SingularConfiguration(f"plant at t = {t[k + 1]:.6g} s: {exc}",
                                        exc.cond) from None
        # J at the projected q (the projection's own), applied to the unprojected qd.
        J = plant.jacobian(q, kinematics=False)
        drift_v = max(drift_v, float(np.max(np.abs(J @ qd))))
        det = float(np.linalg.det(J[:, pas]))
        if det * sign[0] < 0.0:
            raise SingularConfiguration(
                f"plant at t = {t[k + 1]:.6g} s: crossed a type-II (parallel) singularity in "
                f"the last step (det J_p changed sign; cond(J_p) = "
                f"{np.linalg.cond(J[:, pas]):.3g} after it): the actuated angles no longer "
                f"determine the mechanism's branch", math.inf)
        sign[0] = det
        return q, qd_new

    if continuous:
        torque, deriv, stateful = law.torque, law.derivative, law.nx > 0

        def rhs(i, tk, q, qd, x):
            qa, qda = q[act], qd[act]
            tau = torque(tk, qa, qda, R[i], RD[i], RDD[i], x)
            xd = deriv(tk, qa, qda, R[i], RD[i], RDD[i], x) if stateful else x
            return acc(q, qd, plant.actuation(tau)), xd, tau

        for k in range(n_steps):
            tk = t[k]
            a1, x1, TAU[k] = rhs(2 * k, tk, q, qd, x)
            v2 = qd + h2 * a1
            a2, x2, _ = rhs(2 * k + 1, tk + h2, q + h2 * qd, v2, x + h2 * x1)
            v3 = qd + h2 * a2
            a3, x3, _ = rhs(2 * k + 1, tk + h2, q + h2 * v2, v3, x + h2 * x2)
            v4 = qd + h * a3
            a4, x4, _ = rhs(2 * k + 2, tk + h, q + h * v3, v4, x + h * x3)
            q = q + h6 * (qd + 2.0 * (v2 + v3) + v4)
            qd = qd + h6 * (a1 + 2.0 * (a2 + a3) + a4)
            if stateful:
                x = x + h6 * (x1 + 2.0 * (x2 + x3) + x4)
            q, qd = project(k, q, qd)
            Q[k + 1], QD[k + 1] = q[act], qd[act]
        TAU[n_steps] = rhs(2 * n_steps, t[-1], q, qd, x)[2]
        R = R[::2]
    elif fx is not None:
        U = np.empty((n_steps, n))
        low, up = plant.lower, plant.upper

        def accel(q, qd, tj):
            return acc(q, qd, plant.actuation(tj))

        for k in range(n_steps):
            qm, qdm = fx.measure(k, q[act], qd[act])
            out = law.step(t[k], qm, qdm, R[k], RD[k], RDD[k], x)
            if k:
                tau, x = out
                # Checked at every step: a saturation would clip an inf, a delay hold a NaN.
                if not np.isfinite(tau).all():
                    j = int(np.flatnonzero(~np.isfinite(tau))[0])
                    raise law_divergence(plant, law.name, float(t[k]), j)
            else:
                tau, x = check_step_output(law, out, t[k])
            TAU[k] = U[k] = fx.saturate(tau)
            if not k:
                a, th, thd = fx.start(q[act], qd[act], U[0])
            for s in range(substeps):
                q, qd, a, th, thd = fx.rk4(accel, q, qd, a, th, thd,
                                           fx.applied(U, k, s, substeps), h, act)
                q, qd = project(k, q, qd)
            Q[k + 1], QD[k + 1] = q[act], qd[act]
            bad = diverged_joint(Q[k + 1], QD[k + 1], low, up)
            if bad is not None:
                raise divergence(plant, float(t[k + 1]), Q[k + 1], QD[k + 1], *bad)
        TAU[n_steps] = TAU[n_steps - 1]
    else:
        for k in range(n_steps):
            out = law.step(t[k], q[act], qd[act], R[k], RD[k], RDD[k], x)
            tau, x = check_step_output(law, out, t[k]) if not k else out
            TAU[k] = tau
            u = plant.actuation(tau)
            for _ in range(substeps):
                a1 = acc(q, qd, u)
                v2 = qd + h2 * a1
                a2 = acc(q + h2 * qd, v2, u)
                v3 = qd + h2 * a2
                a3 = acc(q + h2 * v2, v3, u)
                v4 = qd + h * a3
                a4 = acc(q + h * v3, v4, u)
                q = q + h6 * (qd + 2.0 * (v2 + v3) + v4)
                qd = qd + h6 * (a1 + 2.0 * (a2 + a3) + a4)
                q, qd = project(k, q, qd)
            Q[k + 1], QD[k + 1] = q[act], qd[act]
        TAU[n_steps] = TAU[n_steps - 1]
    info = {"engine": "python", "engine_note": engine_note,
            "method": "RK4 on constraintDynamics, projection onto the loop closure "
            "after each step, " + ("continuous-time law" if continuous
                                   else "zero-order-hold sampled law"), "rate_hz": rate,
            "substeps": substeps, "dt": h, "drift_m": drift, "drift_velocity_m_s": drift_v,
            "drift_bound_m": DRIFT_BOUND, "reference_max_cond_Jp": conditioning["max_cond_Jp"],
            "reference_max_cond_at_s": conditioning["at_s"],
            "final_q": q.tolist(), "final_qd": qd.tolist()}
    if fx is not None:
        info["effects"] = fx.info
        if fx.limit is not None:  # as the serial engine records it (Trajectory.info)
            info["saturation"] = saturation(TAU[:-1], fx.limit, float(t[1] - t[0]))
    return Trajectory(t=t, q=Q, qd=QD, r=R, tau=TAU, controller=law.name, plant=plant.name,
                      info=info, joint_names=plant.joint_names, joint_units=["rad"] * n)


def _compiled(plant, law, t, R, RD, RDD, q, qd, x, h, substeps, rate, conditioning, note):
    """Run the validated run on the compiled engine; the Python engine's info keys."""
    out = run_chain_compiled(plant, law, t, R, RD, RDD, q, qd, x, h, substeps, DRIFT_BOUND,
                             ConstraintDrift)
    info = {"engine": "compiled", "engine_note": note, "method": "RK4 on the exact KKT "
            "constrained dynamics (what constraintDynamics converges to), projection onto the "
            "loop closure after each step, zero-order-hold sampled law", "rate_hz": rate,
            "substeps": substeps, "dt": h, "drift_m": out["drift_m"],
            "drift_velocity_m_s": out["drift_velocity_m_s"], "drift_bound_m": DRIFT_BOUND,
            "reference_max_cond_Jp": conditioning["max_cond_Jp"],
            "reference_max_cond_at_s": conditioning["at_s"],
            "final_q": out["final_q"], "final_qd": out["final_qd"]}
    return Trajectory(t=t, q=out["Q"], qd=out["QD"], r=R, tau=out["TAU"], controller=law.name,
                      plant=plant.name, info=info, joint_names=plant.joint_names,
                      joint_units=["rad"] * plant.nq)

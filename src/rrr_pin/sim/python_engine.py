"""The Python engine: the readable reference every other engine is pinned to.

One loop per kind of run (a sampled law on the ideal plant, a continuous-time law, a sampled
law with plant effects), each written once over the plant protocol of
:mod:`rrr_pin.model.plant`, so a serial arm and a closed chain run the same code: the plant's
full state ``(x, v)`` starts at :meth:`~rrr_pin.model.plant.Plant.start`, every RK4 stage
calls :meth:`~rrr_pin.model.plant.Plant.acceleration`, every step ends with the run's
:meth:`~rrr_pin.model.plant.Settler.settle` (a closed chain's projection onto its loop
closure; nothing for an arm), and the law reads :meth:`~rrr_pin.model.plant.Plant.measure`
(the actuated coordinates). The law's own state is ``z``.

Integration: classical fixed-step Runge-Kutta 4 (:mod:`rrr_pin.sim.simulation` has the grid,
the checks and the divergence rule). Runs the law it is given, whatever it is.
"""

from __future__ import annotations

import math

import numpy as np

from ..control.laws import check_law_output, check_step_output
from .trajectory import (
    VELOCITY_LIMIT,
    Run,
    Trajectory,
    diverged_joint,
    divergence,
    first_bad_torque,
    law_divergence,
    make_trajectory,
)

__all__ = ["run_python"]


def _surely_inside(q, qd, low: list, up: list) -> bool:
    """Return True only if :func:`diverged_joint` would return None (per-step fast test).

    On Python floats (``tolist``), which for an arm's few joints costs about a quarter of
    NumPy's reductions. A finite sum means every entry is finite (NaN and inf propagate); False
    (including a finite overflow of the sum) sends the step to :func:`diverged_joint`, the
    definition, which names the joint and the reason.
    """
    ql, vl = q.tolist(), qd.tolist()
    return (math.isfinite(sum(ql) + sum(vl)) and max(map(abs, vl)) <= VELOCITY_LIMIT
            and all(map(float.__le__, low, ql)) and all(map(float.__le__, ql, up)))


def _law_failure(run: Run, tau, k: int | None = None):
    """Return the :func:`law_divergence` of the first NaN or inf torque of ``tau``, or None.

    ``tau`` has one row per control step (its time ``run.t[row]``), or, with ``k``, the
    torques of the stages of RK4 step ``k``. A law's non-finite torque makes the state
    non-finite, so the engine looks for one only when a run diverges (and once at its end).
    """
    hit = first_bad_torque(np.asarray(tau))
    if hit is None:
        return None
    return law_divergence(run.plant, run.law.name, float(run.t[hit[0] if k is None else k]),
                          hit[1])


def run_python(run: Run) -> Trajectory:
    """Run a validated run (:class:`~rrr_pin.sim.trajectory.Run`) in Python; its trajectory.

    The plant first checks the reference on the grid where the law reads it
    (:meth:`~rrr_pin.model.plant.Plant.check_path`: a closed chain's loop closure and
    singularity along it); what it records goes to ``Trajectory.info``.
    """
    run.info.update(run.plant.check_path(run.grid, run.R))
    if run.effects is not None:
        return _effects(run)
    return (_sampled if run.sampled else _continuous)(run)


def _finish(run: Run, settler, x, v, Q, QD, TAU) -> Trajectory:
    """Return the trajectory, with what the plant records of the run (``Settler.info``)."""
    traj = make_trajectory(run, Q, QD, TAU)
    traj.info.update(settler.info(x, v))
    return traj


def _sampled(run: Run) -> Trajectory:
    plant, law = run.plant, run.law
    acc, measure, step = plant.acceleration, plant.measure, law.step
    check, inside = diverged_joint, _surely_inside
    lower, upper = run.lower, run.upper
    low, up = lower.tolist(), upper.tolist()
    h = run.h
    h2, h6 = 0.5 * h, h / 6.0
    t = run.t
    R, RD, RDD = run.R, run.RD, run.RDD
    N = len(t) - 1
    Q = np.empty((N + 1, plant.nq))
    QD = np.empty_like(Q)
    TAU = np.empty_like(Q)
    x, v = run.state0
    settler = plant.settler(t, h, x, v)
    settle = settler.settle
    q, qd = run.q0, run.qd0
    z = run.x0
    Q[0], QD[0] = q, qd
    for k in range(N):
        if k:
            tau, z = step(t[k], q, qd, R[k], RD[k], RDD[k], z)
        else:  # the edge where the law meets the engine: check its first output
            tau, z = check_step_output(law, step(t[0], q, qd, R[0], RD[0], RDD[0], z), t[0])
        TAU[k] = tau
        for _ in range(run.substeps):
            a1 = acc(x, v, tau)
            v2 = v + h2 * a1
            a2 = acc(x + h2 * v, v2, tau)
            v3 = v + h2 * a2
            a3 = acc(x + h2 * v2, v3, tau)
            v4 = v + h * a3
            a4 = acc(x + h * v3, v4, tau)
            x = x + h6 * (v + 2.0 * (v2 + v3) + v4)
            v = v + h6 * (a1 + 2.0 * (a2 + a3) + a4)
            x, v = settle(k, x, v)
        q, qd = measure(x, v)
        Q[k + 1], QD[k + 1] = q, qd
        if not inside(q, qd, low, up):
            bad = check(q, qd, lower, upper)
            if bad is not None:
                raise (_law_failure(run, TAU[:k + 1])
                       or divergence(plant, float(t[k + 1]), q, qd, *bad))
    # The torque held on the last interval is also the one "at" the final sample.
    TAU[N] = TAU[N - 1]
    return _finish(run, settler, x, v, Q, QD, TAU)


def _continuous(run: Run) -> Trajectory:
    plant, law = run.plant, run.law
    acc, measure = plant.acceleration, plant.measure
    torque, deriv, check, inside = law.torque, law.derivative, diverged_joint, _surely_inside
    lower, upper = run.lower, run.upper
    low, up = lower.tolist(), upper.tolist()
    dt = run.h
    h2, h6 = 0.5 * dt, dt / 6.0
    t = run.t
    R, RD, RDD = run.R, run.RD, run.RDD
    N = len(t) - 1
    Q = np.empty((N + 1, plant.nq))
    QD = np.empty_like(Q)
    TAU = np.empty_like(Q)
    stateful = law.nx > 0

    def rhs(i, tk, x, v, z):
        q, qd = measure(x, v)
        r, rd, rdd = R[i], RD[i], RDD[i]
        tau = torque(tk, q, qd, r, rd, rdd, z)
        zd = deriv(tk, q, qd, r, rd, rdd, z) if stateful else z
        if not i:  # the edge where the law meets the engine: check its first outputs
            check_law_output(law, "torque()", tau, law.n, tk)
            check_law_output(law, "derivative()", zd, law.nx, tk)
        return acc(x, v, tau), zd, tau

    x, v = run.state0
    settler = plant.settler(t, dt, x, v)
    settle = settler.settle
    z = run.x0
    for k in range(N + 1):
        tk = t[k]
        a1, z1, tau = rhs(2 * k, tk, x, v, z)
        Q[k], QD[k] = measure(x, v)
        TAU[k] = tau
        if k == N:
            break
        v2 = v + h2 * a1
        a2, z2, tau2 = rhs(2 * k + 1, tk + h2, x + h2 * v, v2, z + h2 * z1)
        v3 = v + h2 * a2
        a3, z3, tau3 = rhs(2 * k + 1, tk + h2, x + h2 * v2, v3, z + h2 * z2)
        v4 = v + dt * a3
        a4, z4, tau4 = rhs(2 * k + 2, tk + dt, x + dt * v3, v4, z + dt * z3)
        x = x + h6 * (v + 2.0 * (v2 + v3) + v4)
        v = v + h6 * (a1 + 2.0 * (a2 + a3) + a4)
        if stateful:
            z = z + h6 * (z1 + 2.0 * (z2 + z3) + z4)
        x, v = settle(k, x, v)
        q, qd = measure(x, v)
        if not inside(q, qd, low, up):
            bad = check(q, qd, lower, upper)
            if bad is not None:
                raise (_law_failure(run, (tau, tau2, tau3, tau4), k)
                       or divergence(plant, float(t[k + 1]), q, qd, *bad))
    stop = _law_failure(run, TAU[N:], N)  # the torque at the last sample drives no step
    if stop is not None:
        raise stop
    return _finish(run, settler, x, v, Q, QD, TAU)


def _effects(run: Run) -> Trajectory:
    """Run a sampled law with plant effects, in the order of :mod:`rrr_pin.control.effects`.

    The effects' steps are the :class:`~rrr_pin.control.effects.Resolved` methods; the drive
    train acts on the actuated coordinates (``plant.actuated_index``), the passive ones of a
    closed chain stay ideal.
    """
    plant, law, fx = run.plant, run.law, run.effects
    acc, measure, step, check = plant.acceleration, plant.measure, law.step, diverged_joint
    act = plant.actuated_index
    lower, upper = run.lower, run.upper
    h, S = run.h, run.substeps
    t = run.t
    R, RD, RDD = run.R, run.RD, run.RDD
    N = len(t) - 1
    n = plant.nq
    Q = np.empty((N + 1, n))
    QD = np.empty_like(Q)
    TAU = np.empty_like(Q)
    U = np.empty((N, n))
    x, v = run.state0
    settler = plant.settler(t, h, x, v)
    settle = settler.settle
    q, qd = run.q0, run.qd0
    z = run.x0
    a = th = thd = None
    Q[0], QD[0] = q, qd
    for k in range(N):
        qm, qdm = fx.measure(k, q, qd)
        if k:
            tau, z = step(t[k], qm, qdm, R[k], RD[k], RDD[k], z)
            # Checked at every step: a saturation would clip an inf, a delay hold a NaN back.
            if not np.isfinite(tau).all():
                raise _law_failure(run, (tau,), k)
        else:  # the edge where the law meets the engine: check its first output
            tau, z = check_step_output(law, step(t[0], qm, qdm, R[0], RD[0], RDD[0], z), t[0])
        tau = fx.saturate(tau)
        U[k] = tau
        TAU[k] = tau
        if k == 0:
            a, th, thd = fx.start(q, qd, U[0])
        for s in range(S):
            x, v, a, th, thd = fx.rk4(acc, x, v, a, th, thd, fx.applied(U, k, s, S), h, act)
            x, v = settle(k, x, v)
        q, qd = measure(x, v)
        Q[k + 1], QD[k + 1] = q, qd
        bad = check(q, qd, lower, upper)
        if bad is not None:
            raise divergence(plant, float(t[k + 1]), q, qd, *bad)
    TAU[N] = TAU[N - 1]
    return _finish(run, settler, x, v, Q, QD, TAU)

r"""A nonlinear second stage: smooth (sigmoid) Coulomb friction, as Gaz et al. 2019.

After :func:`~rrr_pin.model.identification.identify` with ``friction=True`` (stage 1: base
parameters with ``fv qd + fc sign(qd) + off``, linear), each joint's friction is refitted, the
base parameters held at stage 1's, with the model

.. math:: \tau_{f,j} = f_{v,j} \dot q_j + \frac{\phi_{1,j}}{1 + e^{-\phi_{2,j}(\dot q_j +
          \phi_{3,j})}} - \frac{\phi_{1,j}}{1 + e^{-\phi_{2,j} \phi_{3,j}}} + o_j

(``phi1`` [N m] the Coulomb step, ``phi2`` [s/rad] its sharpness, ``phi3`` [rad/s] its shift;
zero at rest by construction) by nonlinear least squares (``scipy.optimize.least_squares``,
trust region, from stage 1's values: ``phi1 = 2 fc``), the friction torque filtered as the
torques are (parallel filtering, as in the fit). Its standard deviations are
``sqrt(diag(s2 (J^T J)^-1))`` at the optimum, which, like stage 1's without the block
sandwich, assume independent residuals: with estimated derivatives they are optimistic.

Not carried further (yet): the simulation, the laws' compensation and the export use
``fv qd + fc tanh(qd / v_eps)`` (:mod:`rrr_pin.control.friction`).

References
----------
.. [1] C. Gaz, M. Cognetti, A. Oliva, P. Robuffo Giordano, A. De Luca, "Dynamic
   Identification of the Franka Emika Panda Robot With Retrieval of Feasible Parameters Using
   Penalty-Based Optimization", IEEE RA-L 4(4), 2019 (the sigmoid model).
"""

from __future__ import annotations

import numpy as np

from .measurements import Measurements, filter_like
from .regressors import regressor

__all__ = ["sigmoid_friction", "refine_sigmoid_friction"]


def sigmoid_friction(qd, phi1, phi2, phi3) -> np.ndarray:
    """Return the sigmoid friction [N m] of Gaz et al. at ``qd`` [rad/s] (any shape).

    ``expit(x) = 1 / (1 + exp(-x))`` (scipy.special), which does not overflow for sharp steps.
    """
    from scipy.special import expit

    return phi1 * expit(phi2 * (qd + phi3)) - phi1 * expit(phi2 * phi3)


def refine_sigmoid_friction(robot, data: Measurements, result) -> dict:
    """Refit each joint's friction as viscous + sigmoid + offset, base parameters held.

    Parameters
    ----------
    robot : rrr_pin.model.dynamics.Robot
        The arm identified.
    data : Measurements
        The run ``result`` was identified on (one run).
    result : rrr_pin.model.identification.Identification
        Stage 1, identified with ``friction=True``.

    Returns
    -------
    dict
        ``{"joints": {joint: {"viscous_Nms_rad", "phi1_Nm", "phi2_s_rad", "phi3_rad_s",
        "offset_Nm", "std": {...}}}, "fit_rms_Nm": {...}, "held_out_rms_Nm": {...} or None,
        "held_out_r2": {...} or None, "model": str}``: the fitted rows and the held-out rows
        of stage 1, the estimate's torque (base parameters) plus the refitted friction.

    Raises
    ------
    ValueError
        ``result`` has no friction, or its samples are not ``data``'s.
    """
    from scipy.optimize import least_squares

    from .estimation import r_squared

    s = result.summary
    if not s.get("friction"):
        raise ValueError("refine_sigmoid_friction needs a stage 1 with friction (identify "
                         "friction=True)")
    if s.get("runs", 1) != 1 or s["samples"] != data.N:
        raise ValueError(f"result was identified on {s['samples']} samples in "
                         f"{s.get('runs', 1)} run(s); data has {data.N} in one run")
    n = robot.nq
    block = int(data.derived.get("window_samples", 1)) if data.derived else 1
    edge = block // 2
    n_fit = data.N - int(round(s["held_out_fraction"] * data.N))
    fit = np.arange(edge, min(n_fit, data.N - edge))
    held = np.arange(n_fit, data.N - edge)
    rows = np.concatenate([fit, held])
    tau_f = filter_like(data, data.tau) if block > 1 else data.tau
    W = result.base.reduce(regressor(robot, data.q[rows], data.qd[rows], data.qdd[rows]))
    rigid = np.full((data.N, n), np.nan)
    rigid[rows] = (W @ result.theta).reshape(-1, n)
    out, fit_rms, held_rms, held_r2 = {}, {}, {}, {}
    for j, name in enumerate(robot.joint_names):
        f1 = s["friction"][name]
        qd = data.qd[:, j]

        def torque(x, qd=qd):
            fv, p1, p2, p3, off = x
            tf = (fv * qd + sigmoid_friction(qd, p1, p2, p3) + off)[:, None]
            return (filter_like(data, tf) if block > 1 else tf)[:, 0]

        def resid(x, j=j, torque=torque):
            return (tau_f[fit, j] - rigid[fit, j]) - torque(x)[fit]

        x0 = [f1["viscous_Nms_rad"], max(2.0 * f1["coulomb_Nm"], 1e-3), 20.0, 0.0,
              f1["offset_Nm"] - f1["coulomb_Nm"]]
        sol = least_squares(resid, x0, method="trf", x_scale="jac",
                            bounds=([-np.inf, 0.0, 1e-2, -1.0, -np.inf],
                                    [np.inf, np.inf, 1e4, 1.0, np.inf]))
        r = sol.fun
        s2 = float(r @ r) / max(len(r) - 5, 1)
        try:
            std = np.sqrt(np.maximum(np.diag(s2 * np.linalg.inv(sol.jac.T @ sol.jac)), 0.0))
        except np.linalg.LinAlgError:
            std = np.full(5, np.nan)
        keys = ("viscous_Nms_rad", "phi1_Nm", "phi2_s_rad", "phi3_rad_s", "offset_Nm")
        out[name] = {**{k: float(v) for k, v in zip(keys, sol.x, strict=True)},
                     "std": {k: float(v) for k, v in zip(keys, std, strict=True)},
                     "status": sol.message}
        fit_rms[name] = float(np.sqrt(np.mean(r * r)))
        if held.size:
            pred = rigid[held, j] + torque(sol.x)[held]
            held_rms[name] = float(np.sqrt(np.mean((tau_f[held, j] - pred) ** 2)))
            held_r2[name] = float(r_squared(tau_f[held, j][:, None], pred[:, None])[0])
    return {"joints": out, "fit_rms_Nm": fit_rms,
            "held_out_rms_Nm": held_rms or None, "held_out_r2": held_r2 or None,
            "model": "fv qd + phi1 / (1 + exp(-phi2 (qd + phi3))) - phi1 / (1 + exp(-phi2 "
                     "phi3)) + off, base parameters of stage 1 (the estimate)"}

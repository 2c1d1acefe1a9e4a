r"""Joint armature (reflected rotor inertia) as regressor columns.

.. math:: \tau_{a,j} = I_{a,j}\, \ddot q_j

A geared joint's rotor turns ``r_j`` times faster than its link; its inertia ``I_rotor`` adds
``I_{a,j} = r_j^2 I_rotor`` to the diagonal of the mass matrix, ``M(q) + diag(I_a)``
(Pinocchio's ``model.armature``, in ``crba``, ``rnea`` and ``aba``). A URDF cannot carry it,
so it is identified with the friction (``identify(..., armature=True)``) and travels in
``identification.json`` (``"armature"``), set on the loaded model
(:func:`with_armature`). Units: ``I_a`` [kg m^2] (revolute) or [kg] (prismatic).

Not every joint's armature is identifiable apart from the links' inertia: the first joint's
axis is fixed in the base, so ``I_{a,1} \ddot q_1`` is the same column as the first body's
inertia about that axis (its base parameter, e.g. ``Izz_R[link1]``, absorbs it).
:func:`armature_columns` finds which columns add rank to the base regressor, on random states
as :func:`~rrr_pin.model.identification.base_parameters` does; the others are reported as
absorbed, naming the base parameters they join.
"""

from __future__ import annotations

import numpy as np

from .regressors import BaseParameters, random_states, regressor

__all__ = ["armature_regressor", "armature_names", "armature_columns", "with_armature"]

#: Relative residual below which an armature column lies in the base regressor's span.
ABSORBED_RTOL = 1e-8


def armature_regressor(qdd) -> np.ndarray:
    r"""Per-joint armature columns stacked over samples (no checks: inner code).

    Parameters
    ----------
    qdd : ndarray, shape (N, nq)
        Accelerations [rad/s^2 or m/s^2].

    Returns
    -------
    ndarray, shape (N nq, nq)
        Row ``k nq + j``, column ``j``: ``qdd[k, j]``; zero elsewhere, so
        ``tau_a[k, j] = Y_a[k nq + j] @ I_a``.
    """
    qdd = np.asarray(qdd, dtype=float)
    N, n = qdd.shape
    out = np.zeros((N, n, n))
    j = np.arange(n)
    out[:, j, j] = qdd
    return out.reshape(N * n, n)


def armature_names(robot) -> list[str]:
    """Name the columns of :func:`armature_regressor`: ``Ia[joint]``, shape (nq,)."""
    return [f"Ia[{j}]" for j in robot.joint_names]


def armature_columns(robot, base: BaseParameters, samples: int = 50, seed: int = 0):
    """Split the joints into those whose armature is identifiable and those absorbed.

    Parameters
    ----------
    robot : rrr_pin.model.dynamics.Robot
    base : BaseParameters
        The arm's base parameters.
    samples, seed
        Random states stacked (as :func:`~rrr_pin.model.identification.base_parameters`).

    Returns
    -------
    kept : ndarray of int
        Joints (0-based) whose armature column adds rank to ``[Y_b, Y_a(kept so far)]``.
    absorbed : dict
        ``{joint name: [base parameter names]}``: the base parameters a joint's armature joins
        (its column is their combination, relative residual below ``1e-8``).
    """
    q, qd, qdd = random_states(robot, samples, seed)
    W = base.reduce(regressor(robot, q, qd, qdd))
    Ya = armature_regressor(qdd)
    kept, absorbed = [], {}
    for j, name in enumerate(robot.joint_names):
        A = np.hstack([W, Ya[:, kept]])
        coef = np.linalg.lstsq(A, Ya[:, j], rcond=None)[0]
        resid = np.linalg.norm(Ya[:, j] - A @ coef) / np.linalg.norm(Ya[:, j])
        if resid > ABSORBED_RTOL:
            kept.append(j)
        else:
            big = np.abs(coef[:base.p]) > 1e-6 * np.abs(coef).max()
            absorbed[name] = [base.names[i] for i in np.flatnonzero(big)]
    return np.asarray(kept, dtype=int), absorbed


def with_armature(robot, armature):
    """Set ``robot.model.armature`` (shape (nq,), [kg m^2] or [kg]) and return ``robot``.

    Pinocchio (>= 3) adds ``diag(armature)`` to ``M(q)`` in ``crba``, ``rnea`` and ``aba``.

    Raises
    ------
    ValueError
        Not ``nq`` finite values >= 0.
    """
    a = np.asarray(armature, dtype=float).reshape(-1)
    if a.shape != (robot.nq,) or not np.all(np.isfinite(a)) or np.any(a < 0.0):
        raise ValueError(f"armature must be {robot.nq} finite values >= 0 [kg m^2], one per "
                         f"joint of {robot.joint_names}, got {a.tolist()}")
    robot.model.armature = a
    robot.data = robot.model.createData()
    robot.__post_init__()  # the zero-gravity copy is remade from this model at its first use
    return robot

r"""Joint friction as regressor columns: viscous, Coulomb and a torque offset per joint.

.. math:: \tau_{f,j} = f_{v,j}\, \dot q_j + f_{c,j} \operatorname{sign}(\dot q_j) + o_j

Linear in the friction parameters, so they are identified together with the base parameters
(:func:`rrr_pin.model.identification.identify` with ``friction=True``). Units: ``fv``
[N m s/rad], ``fc`` and ``o`` [N m]; a positive ``fv`` or ``fc`` opposes the motion (the torque
the motor must add to move the joint at ``qd``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["FRICTION_NAMES", "friction_regressor", "friction_names"]


FRICTION_NAMES = ("fv", "fc", "off")


def friction_regressor(qd) -> np.ndarray:
    r"""Per-joint friction and offset columns stacked over samples (no checks: inner code).

    .. math:: \tau_{f,j} = f_{v,j}\, \dot q_j + f_{c,j} \operatorname{sign}(\dot q_j) + o_j

    Parameters
    ----------
    qd : ndarray, shape (N, nq)
        Velocities [rad/s].

    Returns
    -------
    ndarray, shape (N nq, 3 nq)
        Row ``k nq + j``, columns ``3 j .. 3 j + 2``: ``qd[k, j]``, ``sign(qd[k, j])``, 1; zero
        elsewhere: ``tau_f[k, j] = Y_f[k nq + j] @ [fv_1, fc_1, off_1, ...]`` with ``fv``
        [N m s/rad], ``fc`` [N m] and ``off`` [N m].
    """
    qd = np.asarray(qd, dtype=float)
    N, n = qd.shape
    out = np.zeros((N, n, 3 * n))
    j = np.arange(n)
    out[:, j, 3 * j] = qd
    out[:, j, 3 * j + 1] = np.sign(qd)
    out[:, j, 3 * j + 2] = 1.0
    return out.reshape(N * n, 3 * n)


def friction_names(robot) -> list[str]:
    """Name the columns of :func:`friction_regressor`: ``fv[joint]``, ``fc[joint]``, ``off``."""
    return [f"{k}[{j}]" for j in robot.joint_names for k in FRICTION_NAMES]


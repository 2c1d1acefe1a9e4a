"""Task-space paths placed from where the arm starts.

:func:`circle_from_start` builds the :class:`~rrr_pin.control.references.CirclePath` whose
motion begins at a given point, as ``rrr-pin reproduce --reference circle`` needs: the point
where the frame is at the start configuration. :func:`task_start` chooses that start
configuration when none is given: the neutral one if the frame can move in every direction
there, else the nearest one-joint move away from it that can (the paper's RRR is stretched,
hence singular, at its neutral configuration).
"""

from __future__ import annotations

import numpy as np

from ..validation import check_direction, check_positive, check_vector
from .references import CirclePath

__all__ = ["circle_from_start", "task_start", "position_conditioning"]

#: Largest condition number of the frame's position Jacobian accepted at a default start.
COND_MAX = 10.0


def circle_from_start(p0, radius: float, normal=(0.0, 0.0, 1.0)) -> CirclePath:
    r"""Circle of ``radius`` in the plane normal to ``normal`` whose motion starts at ``p0``.

    The start direction ``u`` is the base axis x projected on the plane (the axis y when
    ``normal`` is within about 26 degrees of x, where the projection would be short), made
    unit; the centre is ``p0 - radius u``, so the motion starts at ``p0`` and turns once,
    counter-clockwise about ``normal``.

    .. math:: c = p_0 - r\,u, \qquad u = \frac{e - n (e^T n)/(n^T n)}{\lVert\cdot\rVert}

    Parameters
    ----------
    p0 : array-like, shape (3,)
        Start point [m].
    radius : float
        Radius [m], > 0.
    normal : array-like, shape (3,), default (0, 0, 1)
        Normal of the circle's plane (any non-zero length; it is made unit).

    Returns
    -------
    CirclePath

    Raises
    ------
    ValueError
        ``p0`` or ``normal`` not a finite 3-vector, ``normal`` zero, ``radius`` not > 0.
    """
    p0 = check_vector("p0", p0, 3)
    radius = check_positive("radius", radius, unit="m")
    normal = check_direction("normal", normal, 3)
    u = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 * np.linalg.norm(normal) else \
        np.array([0.0, 1.0, 0.0])
    u = u - normal * (u @ normal) / (normal @ normal)
    u /= np.linalg.norm(u)
    return CirclePath(p0 - radius * u, radius, normal=normal, start_dir=u)


def position_conditioning(robot, frame: str, q, data=None) -> float:
    r"""Condition number of the position rows of ``frame``'s Jacobian at ``q``.

    .. math:: \kappa = \sigma_1(J_p) / \sigma_m(J_p), \qquad m = \min(3, n)

    with :math:`J_p` the 3 x n translation rows of Pinocchio's frame Jacobian
    (``LOCAL_WORLD_ALIGNED``). Infinite at a singular configuration, where the frame's origin
    cannot move in some direction.

    Parameters
    ----------
    robot : Robot
    frame : str
        A frame of ``robot.model``.
    q : array-like, shape (n,)
        Configuration [rad].
    data : pinocchio.Data, optional
        Workspace of ``robot.model`` to reuse across calls (default: a new one).
    """
    import pinocchio as pin

    fid = robot.model.getFrameId(frame)
    data = robot.model.createData() if data is None else data
    J = pin.computeFrameJacobian(robot.model, data, np.asarray(q, dtype=float), fid,
                                 pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3]
    s = np.linalg.svd(J, compute_uv=False)[: min(3, robot.nq)]
    return float(s[0] / s[-1]) if s[-1] > 1e-12 * max(s[0], 1e-300) else np.inf


def task_start(robot, frame: str, *, cond_max: float = COND_MAX, step: float = 0.05,
               reach: float = 1.0) -> np.ndarray:
    """Default start configuration of a task-space motion of ``frame``.

    The neutral configuration (moved inside the joint limits) if the position Jacobian of
    ``frame`` is conditioned better than ``cond_max`` there (:func:`position_conditioning`);
    otherwise the first configuration, in order of growing offset ``step, 2 step, ...`` up to
    ``reach``, then joint index, then ``+`` before ``-``, that moves one joint by that offset
    and is conditioned better than ``cond_max``. For the paper's RRR (stretched, hence singular,
    at zero) this bends the elbow: ``(0, 0, 0.5)`` rad, condition number 9.8.

    Parameters
    ----------
    robot : Robot
    frame : str
        A frame of ``robot.model``.
    cond_max : float, default 10
        Largest accepted condition number, > 1.
    step, reach : float, default 0.05 and 1.0
        Offset grid [rad] (or [m] for a prismatic joint).

    Returns
    -------
    ndarray, shape (n,)
        The start [rad].

    Raises
    ------
    ValueError
        No configuration of that set is conditioned better than ``cond_max``; the message gives
        the neutral one's condition number and asks for an explicit start (``--home``).
    """
    cond_max = check_positive("cond_max", cond_max)
    if not robot.model.existFrame(frame):
        raise ValueError(f"frame {frame!r} is not in robot {robot.name!r}")
    q0 = np.clip(robot.neutral(), robot.lower, robot.upper)
    data = robot.model.createData()  # one workspace for every candidate
    k0 = position_conditioning(robot, frame, q0, data)
    if k0 <= cond_max:
        return q0
    for m in range(1, int(round(reach / step)) + 1):
        for j in range(robot.nq):
            for sign in (1.0, -1.0):
                q = q0.copy()
                q[j] += sign * m * step
                if robot.lower[j] <= q[j] <= robot.upper[j] and \
                        position_conditioning(robot, frame, q, data) <= cond_max:
                    return q
    raise ValueError(
        f"frame {frame!r} of {robot.name!r} is badly conditioned at the neutral configuration "
        f"(condition number {k0:.3g} > {cond_max:g}) and at every one-joint move of up to "
        f"{reach:g} rad from it: give the start configuration (--home Q1,Q2,...)")

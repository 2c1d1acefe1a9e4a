r"""The joint torque regressor and the base inertial parameters.

.. math:: \tau = Y(q, \dot q, \ddot q)\, \phi = Y_b(q, \dot q, \ddot q)\, \theta_b ,

with ``Y`` Pinocchio's joint torque regressor (``pinocchio.computeJointTorqueRegressor``),
``phi`` the standard parameters and ``theta_b = K phi`` the base parameters: the smallest set of
combinations of ``phi`` that the torques determine.

Standard parameters, Pinocchio's order
--------------------------------------
Ten per moving body (the body of joint ``j``: its child link and every link fixed to it, as
Pinocchio merges them), in the joint's frame, in the order of
``pinocchio.Inertia.toDynamicParameters`` (checked by a test against the formula):

``m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz``

with ``m`` the mass [kg], ``c`` the centre of mass [m] and ``I = I_C + m (c^T c 1 - c c^T)`` the
inertia about the joint frame's origin [kg m^2] (``I_C`` about the centre of mass). They are
named ``m[link]``, ``mx[link]``, ..., ``Izz[link]`` after the body's URDF link.

Base parameters (Gautier 1990)
------------------------------
The regressor ``W`` stacked over random states (within the joint limits, velocities and
accelerations standard normal) is reduced by QR with column pivoting: its rank ``p`` is the
number of base parameters. The independent columns are then chosen in Pinocchio's order
(proximal bodies first, a column kept when it raises the rank: the diagonal of an unpivoted QR),
so distal parameters are regrouped into proximal ones as in Khalil's closed forms, and

.. math:: \theta_b = \phi_1 + \beta \phi_2, \qquad W_2 = W_1 \beta ,

with ``beta`` by least squares (entries below ``1e-10`` of the largest are round-off of
structural zeros and are set to zero). A base parameter is named after its independent standard
parameter, with ``_R`` (regrouped) when others join it; its expression
(``Izz_R[link1] = Izz[link1] + Iyy[link2] + 1 m[link3]``) says which and how.

References
----------
.. [1] M. Gautier, "Numerical calculation of the base inertial parameters of robots", ICRA 1990.
.. [2] W. Khalil and E. Dombre, "Modeling, identification and control of robots", 2002.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ...validation import check_count

__all__ = [
    "STANDARD_NAMES",
    "IdentificationError",
    "body_links",
    "standard_parameters",
    "standard_names",
    "regressor",
    "random_states",
    "BaseParameters",
    "base_parameters",
    "regressor_rank",
    "joint_kinematics",
]

#: The ten standard parameters of a body, in Pinocchio's order (``Inertia.toDynamicParameters``).
STANDARD_NAMES = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")

#: Relative size of ``|R_ii|`` (of the largest) below which a regressor column adds no rank.
RANK_RTOL = 1e-10


class IdentificationError(ValueError):
    """Data or a model that cannot be identified; the message names the cause."""


# --- standard parameters and the regressor ----------------------------------------------------

def body_links(robot) -> list[str]:
    """URDF link of each moving body (the child link of each joint), base to tip, shape (nq,)."""
    out = []
    for j in range(1, robot.model.njoints):
        out.append(next(f.name for f in robot.model.frames
                        if f.type == pin.FrameType.BODY and f.parentJoint == j))
    return out


def standard_parameters(robot) -> np.ndarray:
    """Return every moving body's standard parameters, shape (10 nq,), Pinocchio's order [SI]."""
    return np.concatenate([robot.model.inertias[j].toDynamicParameters()
                           for j in range(1, robot.model.njoints)])


def standard_names(robot) -> list[str]:
    """Names ``m[link]``, ``mx[link]``, ... of :func:`standard_parameters`, shape (10 nq,)."""
    return [f"{p}[{link}]" for link in body_links(robot) for p in STANDARD_NAMES]


def regressor(robot, q, qd, qdd) -> np.ndarray:
    """Joint torque regressor stacked over samples (no checks: inner code).

    Parameters
    ----------
    robot : rrr_pin.model.dynamics.Robot
    q, qd, qdd : ndarray, shape (N, nq)
        Positions [rad], velocities [rad/s], accelerations [rad/s^2].

    Returns
    -------
    ndarray, shape (N nq, 10 nq)
        Row ``k nq + j`` is joint ``j`` at sample ``k``: ``tau[k, j] = Y[k nq + j] @ phi``.
    """
    model, data = robot.model, robot.data
    n = model.nv
    out = np.empty((len(q) * n, 10 * n))
    for k in range(len(q)):
        out[k * n:(k + 1) * n] = pin.computeJointTorqueRegressor(model, data, q[k], qd[k], qdd[k])
    return out



def random_states(robot, samples: int, seed: int):
    """Draw seeded random states ``(q, qd, qdd)``, each shape (samples, nq).

    ``q`` [rad] uniform within the limits (``[-pi, pi]`` where unbounded); ``qd`` [rad/s] and
    ``qdd`` [rad/s^2] standard normal.
    """
    rng = np.random.default_rng(seed)
    lo = np.where(np.isfinite(robot.lower), robot.lower, -np.pi)
    hi = np.where(np.isfinite(robot.upper), robot.upper, np.pi)
    q = rng.uniform(lo, hi, size=(samples, robot.nq))
    return q, rng.standard_normal(q.shape), rng.standard_normal(q.shape)


@dataclass(frozen=True)
class BaseParameters:
    r"""The base parameters of an arm: ``theta_b = K phi``.

    Attributes
    ----------
    names : tuple of str, shape (p,)
        Readable names (``Izz_R[link1]``: regrouped onto ``Izz[link1]``).
    expressions : tuple of str, shape (p,)
        ``name = standard + coefficient standard + ...`` (coefficients in SI units, 6 digits).
    standard : tuple of str, shape (10 nq,)
        Names of the standard parameters (:func:`standard_names`).
    independent : ndarray of int, shape (p,)
        Columns of the regressor kept (Pinocchio's order).
    K : ndarray, shape (p, 10 nq)
        ``theta_b = K phi``: identity on the independent columns, ``beta`` on the others.
    """

    names: tuple
    expressions: tuple
    standard: tuple
    independent: np.ndarray = field(repr=False)
    K: np.ndarray = field(repr=False)

    @property
    def p(self) -> int:
        """Number of base parameters."""
        return len(self.names)

    def __call__(self, phi) -> np.ndarray:
        """Return the base parameters (shape (p,)) of standard ones ``phi`` (shape (10 nq,))."""
        return self.K @ np.asarray(phi, dtype=float)

    def reduce(self, W: np.ndarray) -> np.ndarray:
        """Return the base regressor ``W[:, independent]`` of a standard one ``W``."""
        return W[:, self.independent]

    def to_dict(self) -> dict:
        """JSON-ready: names, expressions, standard names, independent columns, K."""
        return {"names": list(self.names), "expressions": list(self.expressions),
                "standard": list(self.standard), "independent": self.independent.tolist(),
                "K": self.K.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> BaseParameters:
        """Inverse of :meth:`to_dict`."""
        return cls(tuple(d["names"]), tuple(d["expressions"]), tuple(d["standard"]),
                   np.asarray(d["independent"], dtype=int), np.asarray(d["K"], dtype=float))


def base_parameters(robot, samples: int = 50, seed: int = 0) -> BaseParameters:
    """Find the base parameters of an arm by QR of a regressor stacked over random states (Gautier).

    Parameters
    ----------
    robot : rrr_pin.model.dynamics.Robot
    samples : int, default 50
        Random states stacked (``samples * nq`` rows); must exceed ``10 nq / nq = 10``.
    seed : int, default 0
        Seed of the random states.

    Returns
    -------
    BaseParameters
    """
    from scipy.linalg import qr

    samples = check_count("samples", samples, 11)
    W = regressor(robot, *random_states(robot, samples, seed))
    R = qr(W, mode="r", pivoting=True)[0]
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > RANK_RTOL * d[0]))
    # Independent columns in Pinocchio's order: a column is kept when it raises the rank.
    scale = np.linalg.norm(W, axis=0).max()
    R0 = qr(W, mode="r")[0]
    independent = np.flatnonzero(np.abs(np.diag(R0)) > RANK_RTOL * scale)
    if independent.size != rank:  # round-off pushed the two tests apart: keep the pivoted set
        independent = np.sort(qr(W, mode="economic", pivoting=True)[2][:rank])
    dependent = np.setdiff1d(np.arange(W.shape[1]), independent)
    beta = np.linalg.lstsq(W[:, independent], W[:, dependent], rcond=None)[0]
    beta[np.abs(beta) <= 1e-10 * max(1.0, np.abs(beta).max(initial=0.0))] = 0.0
    K = np.zeros((rank, W.shape[1]))
    K[np.arange(rank), independent] = 1.0
    K[:, dependent] = beta
    std = standard_names(robot)
    names, expressions = [], []
    for i, col in enumerate(independent):
        others = [(c, K[i, c]) for c in dependent if K[i, c] != 0.0]
        pname, link = std[col].split("[", 1)
        name = f"{pname}_R[{link}" if others else std[col]
        terms = " ".join(f"{'-' if v < 0 else '+'} {abs(v):.6g} {std[c]}" for c, v in others)
        names.append(name)
        expressions.append(f"{name} = {std[col]}" + (f" {terms}" if terms else ""))
    return BaseParameters(tuple(names), tuple(expressions), tuple(std), independent, K)


def regressor_rank(robot, samples: int = 50, seed: int = 1) -> int:
    """Rank of the regressor stacked over random states, by SVD (numpy's default tolerance).

    An independent count of the base parameters (a check of :func:`base_parameters`).
    """
    samples = check_count("samples", samples, 1)
    return int(np.linalg.matrix_rank(regressor(robot, *random_states(robot, samples, seed))))


# --- measurements -----------------------------------------------------------------------------


def joint_kinematics(robot) -> list:
    """Joint placements (4x4, in the parent joint frame) and types: what the regressor uses."""
    return [{"joint": name, "type": robot.model.joints[j].shortname(),
             "placement": robot.model.jointPlacements[j].homogeneous.tolist()}
            for j, name in enumerate(robot.joint_names, start=1)]

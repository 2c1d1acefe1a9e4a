r"""Dynamic identification: base inertial parameters from measured torques, with confidence.

The joint torques of a rigid arm are linear in the inertial parameters of its bodies,

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

Estimation
----------
From measured ``q, qd, qdd, tau`` (a CSV, :func:`read_measurements`), ordinary least squares
(``ols``), or weighted least squares (``wls``, the default: each joint's rows divided by its noise
standard deviation from the OLS residuals, Gautier & Poignet 2001), with the covariance

.. math:: \operatorname{cov}(\hat\theta_b) = \sigma^2 (W^T W)^{-1}

of the (weighted) base regressor ``W`` over the training samples, ``sigma^2`` the residual sum of
squares over ``rows - p``. A final fraction of the samples (in time) is held out and predicted.
When the log has no velocities or accelerations, they come from a Savitzky-Golay filter
(:func:`estimate_derivatives`), the torques get the same filter (parallel filtering, so both
sides of the equation see one frequency response); every sample enters the fit (none within
half a window of either end of the log), and since the filter colours the residuals the
covariance is then the block sandwich of :func:`least_squares` (blocks of one window) instead of
the formula above, which assumes them independent. Friction (viscous, Coulomb, offset per joint,
:func:`friction_regressor`) is identified with the base parameters on request. The intervals
cover the noise; a model error (unmodelled friction, a torque delayed against the positions)
is not in them.

Physical consistency (Wensing, Kim & Slotine 2017)
--------------------------------------------------
A body's parameters are those of a mass distribution exactly when its pseudo-inertia

.. math:: J = \begin{bmatrix} \tfrac12 \operatorname{tr}(I) 1 - I & m c \\ m c^T & m
          \end{bmatrix} \succeq 0 .

:func:`consistent_parameters` solves two semidefinite programs (cvxpy, Clarabel), with
``J_b >= eps_b 1`` (``eps_b = 1e-6`` of the largest eigenvalue of the nominal body's ``J``, a
margin so that the URDF written passes the strict checks): the base parameters as close to the
estimate as the constraint allows (in the metric of the estimate's covariance; the estimate
itself when it is consistent, up to the margin), then, among those, the standard parameters
closest to the nominal URDF's (each relative to its nominal size), which fixes the directions
that the data cannot see.

References
----------
.. [1] M. Gautier, "Numerical calculation of the base inertial parameters of robots", ICRA 1990.
.. [2] W. Khalil and E. Dombre, "Modeling, identification and control of robots", 2002.
.. [3] M. Gautier and P. Poignet, "Extended Kalman filtering and weighted least squares dynamic
   identification of robot", Control Engineering Practice 9, 2001.
.. [4] P. M. Wensing, S. Kim and J.-J. E. Slotine, "Linear matrix inequalities for physically
   consistent inertial parameter identification: a statistical perspective on the mass
   distribution", IEEE RA-L 3(1), 2017.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..validation import FieldError, check_count, check_probability
from .plant import UncertaintySet

__all__ = [
    "STANDARD_NAMES",
    "IdentificationError",
    "body_links",
    "standard_parameters",
    "standard_names",
    "regressor",
    "FRICTION_NAMES",
    "friction_regressor",
    "friction_names",
    "random_states",
    "BaseParameters",
    "base_parameters",
    "regressor_rank",
    "Measurements",
    "read_measurements",
    "read_split_log",
    "write_measurements",
    "estimate_derivatives",
    "filter_like",
    "check_in_limits",
    "Identification",
    "least_squares",
    "identify",
    "friction_suspects",
    "predict_torques",
    "consistent_parameters",
    "pseudo_inertia",
    "urdf_with_parameters",
    "IdentifiedUncertainty",
    "check_identification_record",
]

#: The ten standard parameters of a body, in Pinocchio's order (``Inertia.toDynamicParameters``).
STANDARD_NAMES = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")

#: Relative size of ``|R_ii|`` (of the largest) below which a regressor column adds no rank.
RANK_RTOL = 1e-10

#: Margin of the pseudo-inertias, relative to the largest eigenvalue of the nominal body's.
PSEUDO_INERTIA_MARGIN = 1e-6

#: Confidence of the region outside which no consistent arm may lie (else: refused).
CONSISTENCY_CONFIDENCE = 0.999


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


#: The friction parameters of a joint, in the order of :func:`friction_regressor`'s columns.
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

@dataclass(frozen=True)
class Measurements:
    """Measured joint trajectories and torques, one row per sample.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Strictly increasing times [s].
    q, qd, qdd, tau : ndarray, shape (N, nq)
        Positions [rad], velocities [rad/s], accelerations [rad/s^2], torques [N m].
    joint_names : tuple of str
    derived : dict
        How the derivatives not in the data were estimated (:func:`estimate_derivatives`), or
        empty.
    source : str
        File name, for messages and records.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    joint_names: tuple
    derived: dict = field(default_factory=dict)
    source: str = ""

    @property
    def N(self) -> int:
        """Number of samples."""
        return len(self.t)


def estimate_derivatives(t, q, window: float | None = None, polyorder: int = 4):
    """Velocities and accelerations by a Savitzky-Golay filter (zero phase).

    Each joint's position is fitted, in a sliding window centred on every sample, by a
    polynomial of degree ``polyorder`` (least squares, ``scipy.signal.savgol_filter``), whose
    first and second derivatives at the centre are ``qd`` and ``qdd``. The window is symmetric,
    so the filter has zero phase (no delay); near the ends the polynomial fitted to the first or
    last window is used (``mode="interp"``).

    Parameters
    ----------
    t : ndarray, shape (N,)
        Strictly increasing times [s]. Uniform steps (relative spread <= 1e-6) are filtered
        as they are; irregular ones are resampled linearly onto the uniform grid of the mean
        step, filtered, and the derivatives interpolated back (``info["uniform"]`` says which).
    q : ndarray, shape (N, nq)
        Positions [rad].
    window : float, optional
        Window length [s]; default ``max(0.2 s, (2 polyorder + 3) dt)`` rounded to an odd
        number of samples: for excitations up to about 1 Hz (the default Fourier series'
        highest harmonic), with encoder noise of 1e-4 rad at 1 kHz, it estimates ``qdd`` to
        about 0.02 rad/s^2 RMS where 0.05 s gives 0.5 (measured on a designed excitation).
    polyorder : int, default 4

    Returns
    -------
    qd, qdd : ndarray, shape (N, nq)
    info : dict
        ``{"filter": "savgol", "window_samples", "window_s", "polyorder", "dt_s"}``.
    """
    from scipy.signal import savgol_filter

    if window is not None and not (math.isfinite(window) and window > 0.0):
        raise FieldError("window", "{name} must be a finite duration > 0 [s] (the "
                         f"derivative filter's length), got {window!r}")
    steps = np.diff(t)
    dt = float(np.mean(steps))
    uniform = np.ptp(steps) <= 1e-6 * dt
    w = max(0.2 if window is None else float(window), (2 * polyorder + 3) * dt)
    n = int(round(w / dt)) | 1
    if n > len(t):
        raise IdentificationError(f"{len(t)} samples are fewer than the derivative filter's "
                                  f"window of {n} samples ({n * dt:.4g} s)")
    grid = t if uniform else t[0] + dt * np.arange(len(t))
    # Irregular time stamps: q resampled (linear interpolation) onto the uniform grid of the
    # mean step, filtered there, and the derivatives interpolated back to the stamps.
    qg = q if uniform else _resample(t, q, grid)
    qd = savgol_filter(qg, n, polyorder, deriv=1, delta=dt, axis=0)
    qdd = savgol_filter(qg, n, polyorder, deriv=2, delta=dt, axis=0)
    if not uniform:
        qd, qdd = _resample(grid, qd, t), _resample(grid, qdd, t)
    return qd, qdd, {"filter": "savgol", "window_samples": n, "window_s": n * dt,
                     "polyorder": polyorder, "dt_s": dt, "uniform": bool(uniform),
                     "max_step_s": float(steps.max()), "min_step_s": float(steps.min())}


def _resample(t, x, grid) -> np.ndarray:
    """Linear interpolation of every column of ``x`` (shape (N, n)) from ``t`` to ``grid``."""
    return np.column_stack([np.interp(grid, t, x[:, j]) for j in range(x.shape[1])])


def filter_like(data: Measurements, x) -> np.ndarray:
    """Filter ``x`` (shape (N, n), at ``data.t``) as :func:`estimate_derivatives` filtered ``q``.

    The zero-derivative Savitzky-Golay filter of the same window and order (on the uniform grid
    of the mean step when the stamps are irregular): parallel filtering of the torques.
    """
    from scipy.signal import savgol_filter

    d = data.derived
    if not d:
        return np.asarray(x, dtype=float)
    n, order = d["window_samples"], d["polyorder"]
    if d.get("uniform", True):
        return savgol_filter(x, n, order, axis=0)
    grid = data.t[0] + d["dt_s"] * np.arange(len(data.t))
    return _resample(grid, savgol_filter(_resample(data.t, x, grid), n, order, axis=0), data.t)


def read_measurements(path, robot, *, window: float | None = None) -> Measurements:
    """Read a CSV of measurements for ``robot``: ``t, q_<joint>..., [qd_, qdd_], tau_<joint>``.

    The header names the columns (any order): ``t`` [s], ``q_<joint>`` [rad], optionally
    ``qd_<joint>`` [rad/s] and ``qdd_<joint>`` [rad/s^2], ``tau_<joint>`` [N m], one of each per
    joint of ``robot``. Missing derivatives are estimated by :func:`estimate_derivatives`.

    Raises
    ------
    IdentificationError (a ValueError)
        Naming the file and the problem: unreadable, no header, missing or extra columns (the
        joints the URDF has and the ones the data has), a cell that is not a number or not
        finite (row, column), times not strictly increasing (row), fewer than 2 rows.
    """
    path = Path(path)
    where = f"measurements {str(path)!r}"
    try:
        # utf-8-sig: a byte-order mark (spreadsheet exports) is not part of the first column.
        rows = list(csv.reader(path.read_text(encoding="utf-8-sig").splitlines()))
    except (OSError, UnicodeDecodeError) as exc:
        raise IdentificationError(f"cannot read {where}: {exc}") from None
    rows = [r for r in rows if r and any(c.strip() for c in r)]
    if not rows:
        raise IdentificationError(f"{where} is empty")
    header = [c.strip() for c in rows[0]]
    joints = robot.joint_names
    has = {kind: [f"{kind}_{j}" in header for j in joints] for kind in ("qd", "qdd")}
    wanted = ["t"] + [f"{kind}_{j}" for kind in ("q", "qd", "qdd", "tau") for j in joints
                      if kind in ("q", "tau") or any(has[kind])]
    missing = [c for c in wanted if c not in header]
    extra = [c for c in header if c not in wanted]
    if missing or extra or len(set(header)) != len(header):
        data_joints = sorted({c.split("_", 1)[1] for c in header if "_" in c})
        raise IdentificationError(
            f"{where}: " + "; ".join(
                ([f"missing columns {missing}"] if missing else [])
                + ([f"unexpected columns {extra}"] if extra else [])
                + (["repeated column names"] if len(set(header)) != len(header) else []))
            + f". The URDF {robot.name!r} has joints {joints}; the data names {data_joints}. "
              f"Expected columns t, q_<joint>, optionally qd_<joint> and qdd_<joint> (all "
              f"joints or none), tau_<joint>")
    if len(rows) < 3:
        raise IdentificationError(f"{where}: {len(rows) - 1} rows of data; need at least 2")
    values = np.empty((len(rows) - 1, len(header)))
    for k, row in enumerate(rows[1:]):
        if len(row) != len(header):
            raise IdentificationError(f"{where} row {k + 2}: {len(row)} cells, the header has "
                                      f"{len(header)}")
        for c, cell in enumerate(row):
            try:
                values[k, c] = float(cell)
            except ValueError:
                raise IdentificationError(f"{where} row {k + 2}, column {header[c]!r}: "
                                          f"{cell!r} is not a number") from None
    bad = ~np.isfinite(values)
    if bad.any():
        k, c = np.argwhere(bad)[0]
        raise IdentificationError(f"{where} row {k + 2}, column {header[c]!r}: "
                                  f"{rows[k + 1][c].strip()!r} is not finite (every cell must "
                                  f"be a finite number; drop or repair the sample)")
    col = {name: values[:, header.index(name)] for name in header}
    t = col["t"]
    steps = np.diff(t)
    if np.any(steps <= 0.0):
        k = int(np.flatnonzero(steps <= 0.0)[0])
        raise IdentificationError(f"{where}: time must be strictly increasing; row {k + 3} has "
                                  f"t = {float(t[k + 1])!r} s after t = {float(t[k])!r} s")
    q, tau = (np.column_stack([col[f"{kind}_{j}"] for j in joints]) for kind in ("q", "tau"))
    check_in_limits(robot, q, where)
    given = {kind: np.column_stack([col[f"{kind}_{j}"] for j in joints])
             for kind in ("qd", "qdd") if all(has[kind])}
    derived = {}
    if len(given) < 2:  # estimate what is missing; keep what the data give
        qd_f, qdd_f, derived = estimate_derivatives(t, q, window)
        derived["estimated"] = [k for k in ("qd", "qdd") if k not in given]
        given = {"qd": qd_f, "qdd": qdd_f, **given}
    qd, qdd = given["qd"], given["qdd"]
    return Measurements(t, q, qd, qdd, tau, tuple(joints), derived, str(path))


def read_split_log(folder, robot, *, time: str = "time.txt", q: str = "positions.txt",
                   qd: str | None = "velocity.txt", tau: str = "torques.txt",
                   window: float | None = None) -> Measurements:
    """Read a log split into one text file per quantity (e.g. the Panda logs of Gaz et al.).

    Every file holds one number per line (blank lines skipped): ``time`` one per sample [s];
    ``q`` [rad], ``qd`` [rad/s] and ``tau`` [N m] ``nq`` per sample, sample after sample, joints
    in ``robot.joint_names`` order. Accelerations (and velocities when ``qd`` is None) are
    derived as in :func:`read_measurements` (:func:`estimate_derivatives`). To hand such a log
    to ``rrr-pin identify``, write it as a CSV with :func:`write_measurements`.

    Parameters
    ----------
    folder : str or Path
    robot : rrr_pin.model.dynamics.Robot
        Its joints, in the files' order (the Panda with its fingers locked: 7).
    time, q, qd, tau : str
        File names inside ``folder``; ``qd=None`` when the log has no velocities.
    window : float, optional
        Savitzky-Golay window [s] (:func:`estimate_derivatives`).

    Raises
    ------
    IdentificationError
        Naming the file: unreadable, not numbers or not finite (line), a length that is not
        ``nq`` times the time file's (files disagree), time not strictly increasing (line),
        positions outside the joint limits (:func:`check_in_limits`).
    """
    folder = Path(folder)
    n = robot.nq
    values = {}
    for kind, name in (("t", time), ("q", q), ("qd", qd), ("tau", tau)):
        if name is None:
            continue
        path = folder / name
        try:
            lines = path.read_text(encoding="utf-8-sig").splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            raise IdentificationError(f"cannot read log file {str(path)!r}: {exc}") from None
        cells = [(k + 1, c.strip()) for k, c in enumerate(lines) if c.strip()]
        try:
            x = np.array([float(c) for _, c in cells])
        except ValueError:
            k, c = next((k, c) for k, c in cells if not _is_float(c))
            raise IdentificationError(f"log file {str(path)!r} line {k}: {c!r} is not a "
                                      f"number") from None
        if not np.all(np.isfinite(x)):
            k = cells[int(np.flatnonzero(~np.isfinite(x))[0])][0]
            raise IdentificationError(f"log file {str(path)!r} line {k}: not finite")
        values[kind] = (x, path)
    t, tpath = values["t"]
    N = len(t)
    for kind in ("q", "qd", "tau"):
        if kind not in values:
            continue
        x, path = values[kind]
        if len(x) != n * N:
            raise IdentificationError(
                f"log files disagree in length: {str(path)!r} has {len(x)} values, "
                f"{str(tpath)!r} {N} samples; {n} joints of {robot.name!r} need {n * N}")
        values[kind] = (x.reshape(N, n), path)
    if N < 3:
        raise IdentificationError(f"log {str(folder)!r}: {N} samples; need at least 3")
    steps = np.diff(t)
    if np.any(steps <= 0.0):
        k = int(np.flatnonzero(steps <= 0.0)[0])
        raise IdentificationError(f"log file {str(tpath)!r}: time must be strictly increasing; "
                                  f"sample {k + 2} has t = {t[k + 1]!r} s after {t[k]!r} s")
    qv = values["q"][0]
    check_in_limits(robot, qv, f"log file {str(values['q'][1])!r}")
    qd_f, qdd_f, derived = estimate_derivatives(t, qv, window)
    derived["estimated"] = ["qdd"] if "qd" in values else ["qd", "qdd"]
    qdv = values["qd"][0] if "qd" in values else qd_f
    return Measurements(t, qv, qdv, qdd_f, values["tau"][0], tuple(robot.joint_names), derived,
                        str(folder))


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def write_measurements(path, data: Measurements, *, derivatives: bool = False) -> Path:
    """Write measurements as the CSV :func:`read_measurements` reads (``t, q_, [qd_], tau_``).

    Parameters
    ----------
    path : str or Path
    data : Measurements
    derivatives : bool, default False
        Write ``qdd_`` columns too; by default velocities are written when the data gave them
        (``"qd"`` not in ``data.derived["estimated"]``) and accelerations never, so that the
        reader derives them again with the filter of its ``window``.
    """
    est = data.derived.get("estimated", []) if data.derived else []
    kinds = ["q"] + (["qd"] if "qd" not in est or derivatives else []) + (
        ["qdd"] if derivatives else []) + ["tau"]
    header = ["t"] + [f"{k}_{j}" for k in kinds for j in data.joint_names]
    table = np.column_stack([data.t] + [getattr(data, k) for k in kinds])
    path = Path(path)
    np.savetxt(path, table, delimiter=",", header=",".join(header), comments="", fmt="%.10g")
    return path


def check_in_limits(robot, q, where: str) -> None:
    """Refuse positions outside a joint's limits by more than 10 % of its range (or 0.1 rad).

    A log in degrees, or of another arm, is refused here rather than identified.

    Raises
    ------
    IdentificationError
        Naming the joint, its range and the extreme value.
    """
    lo, hi = np.asarray(robot.lower, dtype=float), np.asarray(robot.upper, dtype=float)
    slack = np.where(np.isfinite(hi - lo), np.maximum(0.1 * (hi - lo), 0.1), np.inf)
    for j, name in enumerate(robot.joint_names):
        if not np.isfinite(slack[j]):
            continue
        qmin, qmax = float(q[:, j].min()), float(q[:, j].max())
        if qmin < lo[j] - slack[j] or qmax > hi[j] + slack[j]:
            raise IdentificationError(
                f"{where}: q_{name} spans [{qmin:.4g}, {qmax:.4g}], outside the joint's "
                f"limits [{lo[j]:.4g}, {hi[j]:.4g}] rad of {robot.name!r} by more than 10 % of "
                f"the range: positions must be in rad (not degrees) and of this arm")


# --- physical consistency ---------------------------------------------------------------------

def pseudo_inertia(phi_body) -> np.ndarray:
    """Pseudo-inertia ``J`` (shape (4, 4)) of one body's 10 standard parameters (Wensing 2017)."""
    m, hx, hy, hz, ixx, ixy, iyy, ixz, iyz, izz = np.asarray(phi_body, dtype=float)
    I = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    J = np.zeros((4, 4))
    J[:3, :3] = 0.5 * np.trace(I) * np.eye(3) - I
    J[:3, 3] = J[3, :3] = (hx, hy, hz)
    J[3, 3] = m
    return J


def _pseudo_inertia_basis() -> np.ndarray:
    """``A[i]`` (shape (10, 4, 4)): ``J = sum_i phi_i A[i]``."""
    return np.array([pseudo_inertia(e) for e in np.eye(10)])


def _lmi(phi_var, nb: int, margins):
    A = _pseudo_inertia_basis()
    out = []
    for b in range(nb):
        J = sum(phi_var[10 * b + i] * A[i] for i in range(10))
        out.append(0.5 * (J + J.T) >> margins[b] * np.eye(4))
    return out


def _margins(phi0) -> np.ndarray:
    nb = len(phi0) // 10
    return np.array([PSEUDO_INERTIA_MARGIN * max(np.linalg.eigvalsh(
        pseudo_inertia(phi0[10 * b:10 * b + 10]))[-1], 1e-12) for b in range(nb)])


def _weights(phi0) -> np.ndarray:
    """Per-parameter weights 1 / size: the nominal's, floored at 1e-3 of its body's largest."""
    w = np.empty_like(phi0)
    for b in range(len(phi0) // 10):
        x = np.abs(phi0[10 * b:10 * b + 10])
        w[10 * b:10 * b + 10] = 1.0 / np.maximum(x, 1e-3 * max(x.max(), 1e-12))
    return w


def _solve(problem, what: str):
    try:
        problem.solve(solver="CLARABEL")
    except Exception as exc:  # cvxpy.SolverError: say which problem
        raise IdentificationError(f"the consistency SDP ({what}) failed: {exc}") from None
    return problem.status


def consistent_parameters(base: BaseParameters, theta, A, phi0, *, sigma: float | None = None,
                          confidence: float = CONSISTENCY_CONFIDENCE, refuse: bool = True,
                          mass_band: float | None = None):
    r"""Find the standard parameters of a physically consistent arm nearest to estimated base ones.

    Stage 1: ``t* = min ||A (K phi - theta)||`` over ``phi`` with every pseudo-inertia
    ``J_b >= eps_b 1``. Stage 2: ``min ||w (phi - phi0)||`` with ``||A (K phi - theta)|| <=
    t* + 1e-6 ||A theta||`` and the same LMIs (``w``: :func:`_weights`); if the solver fails
    on stage 2, stage 1's arm is kept and ``info["stage2"]`` says so.

    Parameters
    ----------
    base : BaseParameters
    theta : ndarray, shape (p,)
        Estimated base parameters.
    A : ndarray, shape (p, p)
        Metric: ``A^T A = W^T W / rows`` of the (weighted) base regressor, so ``||A d||`` is the
        RMS torque change [N m] that the change ``d`` makes over the data.
    phi0 : ndarray, shape (10 nq,)
        Nominal standard parameters (the URDF's), for the directions the data cannot see.
    sigma : float, optional
        Noise level of ``||A d||`` (``sigma / sqrt(rows)`` of the fit); with it, a nearest
        consistent point outside the ``confidence`` region of the estimate is refused, unless
        its distance is below ``10 PSEUDO_INERTIA_MARGIN ||A theta||`` (what the margin alone
        can cost: an estimate on the boundary, e.g. noise-free data of thin rods).
    refuse : bool, default True
        ``False``: such a point is kept with a warning (``info["outside_confidence"]``), for
        real logs whose model error (friction, flexibility) the noise model does not cover.
    mass_band : float, optional
        Plausibility bound ``f > 1``: every body's mass within ``[m0 / f, f m0]`` of the
        nominal's ``m0`` (both stages). Default: no bound beyond positive definiteness.

    Returns
    -------
    phi : ndarray, shape (10 nq,)
    info : dict
        ``distance_rms_Nm`` (``t*``, stage 1's optimum), ``mahalanobis`` (``t* / sigma``, or
        None), ``distance_returned_rms_Nm`` and ``mahalanobis_returned``: the same for the arm
        returned (stage 2's, within ``1e-6 ||A theta||`` of stage 1's), statuses.

    Raises
    ------
    IdentificationError
        The SDP is infeasible or fails, or (with ``sigma``) no consistent arm lies inside the
        ``confidence`` region of the estimate.
    """
    import cvxpy as cp
    from scipy.stats import chi2

    phi0 = np.asarray(phi0, dtype=float)
    nb = len(phi0) // 10
    margins = _margins(phi0)
    phi = cp.Variable(len(phi0))
    resid = A @ (base.K @ phi) - A @ theta
    lmis = _lmi(phi, nb, margins)
    if mass_band is not None:
        if not (math.isfinite(mass_band) and mass_band > 1.0):
            raise FieldError("mass_band", "{name} must be a finite factor > 1 (masses within "
                             f"[m0 / f, f m0]), got {mass_band!r}")
        m0 = phi0[0::10]
        lmis = lmis + [phi[0::10] >= m0 / mass_band, phi[0::10] <= m0 * mass_band]
    p1 = cp.Problem(cp.Minimize(cp.norm(resid)), lmis)
    status = _solve(p1, "nearest consistent base parameters")
    # An inaccurate end is kept only when its point checks: every pseudo-inertia positive
    # semi-definite (then t* is the measured distance of a consistent arm, an upper bound on
    # the optimum); the status is recorded in info["stage1"].
    if status == "optimal_inaccurate" and phi.value is not None and all(
            np.linalg.eigvalsh(pseudo_inertia(np.asarray(phi.value, float)[10 * b:10 * b + 10]
                                              )).min() >= 0.0 for b in range(nb)):
        status1 = "optimal_inaccurate: kept, every pseudo-inertia checked positive semi-definite"
        p1_value = float(np.linalg.norm(A @ (base.K @ np.asarray(phi.value, float) - theta)))
    elif status == "optimal":
        status1 = "optimal"
        p1_value = float(p1.value)
    else:
        status1 = status
    if not status1.startswith("optimal"):
        raise IdentificationError(f"the consistency SDP (nearest consistent base parameters) "
                                  f"ended {status!r}: no physically consistent arm found")
    t_star = p1_value
    scale = float(np.linalg.norm(A @ theta))
    mahal = None
    if sigma is not None and sigma > 0.0:
        mahal = t_star / sigma
        limit = math.sqrt(chi2.ppf(confidence, base.p))
        outside = bool(mahal > limit and t_star > 10.0 * PSEUDO_INERTIA_MARGIN * scale)
        if outside and not refuse:
            import warnings

            warnings.warn(f"the nearest physically consistent arm lies at Mahalanobis "
                          f"distance {mahal:.4g} from the estimate, outside its "
                          f"{confidence:.1%} confidence region (RMS torque change "
                          f"{t_star:.4g} N m): kept, as asked", stacklevel=3)
        elif outside:
            raise IdentificationError(
                f"infeasible consistency problem: no physically consistent arm (every body's "
                f"pseudo-inertia positive semi-definite) has base parameters inside the "
                f"{confidence:.1%} confidence region of the estimate; the nearest lies at "
                f"Mahalanobis distance {mahal:.4g} > {limit:.4g} (RMS torque change "
                f"{t_star:.4g} N m). The data do not fit a rigid arm with this URDF's "
                f"kinematics: check the joint order, torque signs and units, and unmodelled "
                f"friction or payload")
    phi1 = np.asarray(phi.value, dtype=float)
    p2 = cp.Problem(cp.Minimize(cp.norm(cp.multiply(_weights(phi0), phi - phi0))),
                    [cp.norm(resid) <= t_star + 1e-6 * scale] + lmis)
    try:
        status2 = _solve(p2, "nearest standard parameters")
    except IdentificationError:
        status2 = "solver_error"
    # Stage 2 only chooses among equally good arms: if it fails, stage 1's arm is kept. An
    # inaccurate end (real logs: parameters over 6 decades) is kept when it checks: every
    # pseudo-inertia positive semi-definite and the torque change within 1e-5 ||A theta||.
    if status2 == "optimal_inaccurate" and phi.value is not None:
        cand = np.asarray(phi.value, dtype=float)
        ok = all(np.linalg.eigvalsh(pseudo_inertia(cand[10 * b:10 * b + 10])).min() >= 0.0
                 for b in range(nb))
        if ok and np.linalg.norm(A @ (base.K @ cand - theta)) <= t_star + 1e-5 * scale:
            status2 = "optimal"
            phi.value = cand
    out = np.asarray(phi.value, dtype=float) if status2 == "optimal" else phi1
    # Where the arm returned sits (stage 2 may move up to 1e-6 ||A theta|| beyond stage 1).
    final = float(np.linalg.norm(A @ (base.K @ out - theta)))
    return out, {"stage1": status1, "stage2": status2 if status2 == "optimal" else
                 f"{status2}: kept the stage-1 arm",
        "distance_rms_Nm": t_star, "mahalanobis": mahal,
        "distance_returned_rms_Nm": final, "mass_band": mass_band,
        "bounded": (f"every body's mass in [m0 / {mass_band:g}, {mass_band:g} m0] of the "
                    f"nominal URDF's" if mass_band else "pseudo-inertia only"),
        "outside_confidence": bool(
            sigma is not None and sigma > 0.0 and mahal > math.sqrt(chi2.ppf(confidence, base.p))
            and t_star > 10.0 * PSEUDO_INERTIA_MARGIN * scale),
        "mahalanobis_returned": None if mahal is None else final / sigma,
        "feasible_at_estimate":
        bool(t_star <= 1e-6 * max(scale, 1e-300)), "pseudo_inertia_margins": margins.tolist()}


def urdf_with_parameters(urdf: str, links, phi, *, moving=None, friction=None) -> str:
    """Return the URDF text with each moving body's inertial replaced by standard parameters.

    Parameters
    ----------
    urdf : str
        The nominal URDF text (kinematics kept as is).
    links : sequence of str, shape (nq,)
        The body links (:func:`body_links`), each given the body's whole inertial (in the link
        frame, which is the joint frame); every other link fixed to it loses its
        ``<inertial>`` (Pinocchio had merged it into the body).
    phi : ndarray, shape (10 nq,)
        Standard parameters, Pinocchio's order.
    moving : sequence of str, optional
        The model's joints; any other non-fixed joint of the URDF is locked (Pinocchio merged
        its child into the body) and treated as fixed. Default: every joint.
    friction : dict, optional
        ``{joint: {"viscous_Nms_rad", "coulomb_Nm", ...}}``: written as each joint's
        ``<dynamics damping=... friction=...>`` (URDF's viscous and Coulomb coefficients; the
        offset has no URDF field and stays in ``identification.json``; so does a negative
        coefficient, which URDF readers refuse).

    Returns
    -------
    str
        URDF text; its inertials are checked by
        :func:`rrr_pin.model.dynamics.check_urdf_inertials` (raises ``RobotModelError``).
    """
    from .dynamics import check_urdf_inertials

    root = ET.fromstring(urdf)
    by_name = {link.get("name"): link for link in root.findall("link")}
    children = {}
    for joint in root.findall("joint"):
        children.setdefault(joint.find("parent").get("link"), []).append(joint)
    for b, name in enumerate(links):
        inertia = pin.Inertia.FromDynamicParameters(np.asarray(phi[10 * b:10 * b + 10], float))
        stack = [name]
        while stack:  # links fixed to the body: their inertial is now in the body's
            current = stack.pop()
            for joint in children.get(current, []):
                if joint.get("type") == "fixed" or (
                        moving is not None and joint.get("name") not in moving):
                    child = joint.find("child").get("link")
                    el = by_name[child].find("inertial")
                    if el is not None:
                        by_name[child].remove(el)
                    stack.append(child)
        link = by_name[name]
        old = link.find("inertial")
        index = list(link).index(old) if old is not None else 0
        if old is not None:
            link.remove(old)
        el = ET.Element("inertial")
        c, Ic = inertia.lever, inertia.inertia
        ET.SubElement(el, "origin", xyz=" ".join(repr(float(x)) for x in c), rpy="0 0 0")
        ET.SubElement(el, "mass", value=repr(float(inertia.mass)))
        ET.SubElement(el, "inertia", **{k: repr(float(Ic[i, j])) for k, (i, j) in (
            ("ixx", (0, 0)), ("ixy", (0, 1)), ("ixz", (0, 2)), ("iyy", (1, 1)),
            ("iyz", (1, 2)), ("izz", (2, 2)))})
        link.insert(index, el)
    for joint in root.findall("joint"):
        f = (friction or {}).get(joint.get("name"))
        if f is None:
            continue
        values = {"damping": float(f["viscous_Nms_rad"]), "friction": float(f["coulomb_Nm"])}
        values = {k: v for k, v in values.items() if v >= 0.0}  # URDF: >= 0 (a negative one
        if not values:                                          # stays in the JSON, warned)
            continue
        el = joint.find("dynamics")
        if el is None:
            el = ET.SubElement(joint, "dynamics")
        for k, v in values.items():
            el.set(k, repr(v))
    text = ET.tostring(root, encoding="unicode")
    check_urdf_inertials(text)
    return text


# --- estimation -------------------------------------------------------------------------------

@dataclass
class Identification:
    """The result of :func:`identify` (see :meth:`to_dict` for the JSON written).

    Attributes
    ----------
    base : BaseParameters
    theta : ndarray, shape (p,)
        Estimated base parameters [SI].
    cov : ndarray, shape (p, p)
        Their covariance.
    phi : ndarray, shape (10 nq,)
        Standard parameters of the consistent arm (:func:`consistent_parameters`).
    urdf : str
        The identified URDF (the nominal's kinematics, inertials from ``phi``).
    summary : dict
        Method, noise, condition number, residuals, held-out errors, consistency record,
        identified friction (``summary["friction"]``, per joint, with standard deviations).
    friction : ndarray, shape (3 nq,) or (0,)
        ``fv, fc, off`` per joint (:func:`friction_regressor`), empty without friction.
    cov_all : ndarray, shape (p + 3 nq, p + 3 nq), optional
        Covariance of base and friction parameters together.
    """

    base: BaseParameters
    theta: np.ndarray
    cov: np.ndarray
    phi: np.ndarray
    urdf: str = field(repr=False)
    summary: dict = field(default_factory=dict)
    friction: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cov_all: np.ndarray | None = field(default=None, repr=False)

    @property
    def std(self) -> np.ndarray:
        """Standard deviations of :attr:`theta`, shape (p,)."""
        return np.sqrt(np.diag(self.cov))

    def to_dict(self) -> dict:
        """JSON-ready record: what ``identification.json`` holds."""
        return {"format": "rrr-pin-identification", "version": 1, **self.summary,
                "base": self.base.to_dict(), "estimate": self.theta.tolist(),
                "std": self.std.tolist(), "cov": self.cov.tolist(),
                "base_consistent": self.base(self.phi).tolist(),
                "standard_consistent": self.phi.tolist(),
                "friction_estimate": self.friction.tolist(),
                "cov_all": None if self.cov_all is None else self.cov_all.tolist()}

    def write(self, folder, *, urdf_name: str = "identified.urdf") -> list[Path]:
        """Write ``identified.urdf`` and ``identification.json`` into ``folder``."""
        from ..outputs import writing

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        u, j = folder / urdf_name, folder / "identification.json"
        with writing(u):
            u.write_text(self.urdf)
        record = {**self.to_dict(), "urdf": urdf_name,
                  "urdf_sha256": hashlib.sha256(self.urdf.encode()).hexdigest()}
        with writing(j):
            j.write_text(json.dumps(record, indent=1) + "\n")
        return [u, j]


def _per_joint(robot, values) -> dict:
    """``{joint: value}`` of an array of shape (nq,)."""
    return {name: float(v) for name, v in zip(robot.joint_names, values, strict=True)}


def _kinematics(robot) -> list:
    """Joint placements (4x4, in the parent joint frame) and types: what the regressor uses."""
    return [{"joint": name, "type": robot.model.joints[j].shortname(),
             "placement": robot.model.jointPlacements[j].homogeneous.tolist()}
            for j, name in enumerate(robot.joint_names, start=1)]


def _qr_solve(W: np.ndarray, y: np.ndarray):
    """Least squares by one QR of ``[W y]``: ``theta`` (shape (p,)) and ``R`` (shape (p, p))."""
    from scipy.linalg import qr, solve_triangular

    p = W.shape[1]
    Rf = qr(np.column_stack([W, y]), mode="r", check_finite=False)[0]
    R = np.triu(Rf[:p, :p])
    d = np.abs(np.diag(R))
    if not np.all(d > 1e-300):
        return np.full(p, np.nan), R
    return solve_triangular(R, Rf[:p, p]), R


def _unidentifiable(names, R: np.ndarray) -> list[str]:
    """Names of the base parameters in the numerical null space of a regressor (its ``R``).

    Columns scaled to unit norm; singular values below ``1e-8`` of the largest count as zero,
    and a parameter with a component above 0.1 in such a direction is not identifiable.
    """
    norms = np.linalg.norm(R, axis=0)
    zero = norms <= 1e-12 * max(norms.max(), 1e-300)
    Rn = R / np.where(zero, 1.0, norms)
    _, s, Vt = np.linalg.svd(Rn)
    null = Vt[s <= 1e-8 * s[0]]
    involved = zero | (np.abs(null) > 0.1).any(axis=0) if null.size else zero
    return [names[i] for i in np.flatnonzero(involved)]


def least_squares(base: BaseParameters, W: np.ndarray, y: np.ndarray, n: int,
                  method: str = "wls", *, names=None, block: int = 1):
    r"""Estimate base parameters by ordinary or weighted least squares, with their covariance.

    Parameters
    ----------
    base : BaseParameters
        For the names of parameters that are not identifiable.
    W : ndarray, shape (N n, p)
        Base regressor, row ``k n + j`` = joint ``j`` at sample ``k``.
    y : ndarray, shape (N n,)
        Measured torques [N m], same rows.
    n : int
        Joints.
    method : {"wls", "ols"}
        ``wls``: the rows of joint ``j`` divided by its OLS residual standard deviation
        ``sigma_j`` (``sigma_j^2 = ||r_j||^2 / (N - p / n)``), then solved again.
    names : sequence of str, shape (p,), optional
        Names of ``W``'s columns (default ``base.names``; with friction columns appended).
    block : int, default 1
        Consecutive samples whose residuals may be correlated (a derivative filter's window).
        Above 1, the covariance is the cluster-robust sandwich over blocks of that many
        samples (Newey & West 1987 with a flat kernel of that width; Cameron & Miller 2015),

        .. math:: \operatorname{cov} = (W^T W)^{-1} \Big(\tfrac{B}{B-1} \sum_b W_b^T r_b
                  r_b^T W_b\Big) (W^T W)^{-1},

        so that every sample enters the fit and the correlation that the filter puts between
        neighbours is counted, not assumed away.

    Returns
    -------
    theta : ndarray, shape (p,)
    cov : ndarray, shape (p, p)
        ``s2 (W_w^T W_w)^{-1}`` with ``W_w`` the (weighted) regressor and ``s2`` its residual
        sum of squares over ``N n - p``.
    R : ndarray, shape (p, p)
        Triangular factor of ``W_w`` (``R^T R = W_w^T W_w``).
    sigma_j : ndarray, shape (n,)
        Per-joint noise standard deviations [N m] of the final fit.
    s2 : float
    cond : float
        Condition number of the unweighted ``W`` (2-norm).

    Raises
    ------
    IdentificationError
        ``W`` is rank deficient (names the parameters not identifiable), or a joint's residual
        is exactly zero under ``wls``.
    """
    N = len(y) // n
    p = W.shape[1]
    theta, R = _qr_solve(W, y)
    names = base.names if names is None else names
    lost = _unidentifiable(names, R)
    if lost:
        raise IdentificationError(
            f"the trajectory does not excite every base parameter (the regressor of its "
            f"{N} samples is rank deficient): not identifiable: {', '.join(lost)}. "
            f"Move every joint with varied velocity and acceleration, e.g. the trajectory "
            f"of `rrr-pin identify --design-excitation`")
    cond = float(np.linalg.cond(R))
    r = (y - W @ theta).reshape(N, n)
    dof_j = N - p / n
    sigma_j = np.sqrt(np.sum(r * r, axis=0) / dof_j)
    weights = np.ones(n)
    if method == "wls":
        if not np.all(sigma_j > 0.0):
            raise IdentificationError(f"weighted least squares needs every joint's residual "
                                      f"noise > 0, got {sigma_j.tolist()} N m; use ols")
        weights = 1.0 / sigma_j
        Dw = np.tile(weights, N)
        theta, R = _qr_solve(W * Dw[:, None], y * Dw)
        r = (y - W @ theta).reshape(N, n)
        sigma_j = np.sqrt(np.sum(r * r, axis=0) / dof_j)
    rw = r * weights
    s2 = float(np.sum(rw * rw)) / (N * n - p)
    Rinv = np.linalg.inv(R)
    cov = s2 * (Rinv @ Rinv.T)
    if block > 1:
        Ww = (W * np.tile(weights, N)[:, None]).reshape(N, n, p)
        B = -(-N // block)
        pad = B * block - N
        g = np.einsum("kjp,kj->kp", Ww, rw)
        g = np.concatenate([g, np.zeros((pad, p))]).reshape(B, block, p).sum(axis=1)
        meat = (B / max(B - 1, 1)) * (g.T @ g)
        cov = (Rinv @ Rinv.T) @ meat @ (Rinv @ Rinv.T)
        cov = 0.5 * (cov + cov.T)
    return theta, cov, R, sigma_j, s2, cond


def identify(robot, data: Measurements, *, method: str = "wls", held_out: float = 0.2,
             base: BaseParameters | None = None, friction: bool = False,
             refuse_inconsistent: bool = True,
             mass_band: float | None = None) -> Identification:
    r"""Identify the base parameters of ``robot`` from measurements, and a consistent URDF.

    Every sample enters the fit (none within half a derivative-filter window of either end of
    the log, where the filter extrapolates). When derivatives were estimated, the torques get
    the same zero-phase filter (parallel filtering, :func:`filter_like`) and the covariance is
    the block sandwich of :func:`least_squares` over blocks of one filter window, which counts
    the correlation the filter puts between neighbouring residuals.

    Parameters
    ----------
    robot : rrr_pin.model.dynamics.Robot
        The nominal arm: its kinematics are trusted, its inertials are the prior for the
        directions the data cannot see.
    data : Measurements
        From :func:`read_measurements` (joints in ``robot.joint_names`` order).
    method : {"wls", "ols"}
        Weighted (per-joint noise) or ordinary least squares.
    held_out : float, default 0.2
        Final fraction of the samples, in time, left out of the fit and predicted; in
        ``[0, 0.9]``.
    base : BaseParameters, optional
        Default :func:`base_parameters` of ``robot``.
    friction : bool, default False
        Identify, with the base parameters, each joint's viscous and Coulomb friction and a
        torque offset (:func:`friction_regressor`):
        ``tau = Y_b theta_b + fv qd + fc sign(qd) + off``.
    refuse_inconsistent : bool, default True
        Refuse an estimate with no physically consistent arm inside its 99.9 % region
        (:func:`consistent_parameters`); ``False`` keeps the nearest with a warning.
    mass_band : float, optional
        Bound every body's mass to ``[m0 / f, f m0]`` of the nominal's
        (:func:`consistent_parameters`).

    Returns
    -------
    Identification

    Warns
    -----
    UserWarning
        The residual of a joint correlates with ``qd`` or ``sign(qd)`` (``|r| > 0.3``, named
        joints): a friction term is missing from the model (``friction=False``) or not of the
        form modelled. The intervals then do not cover the model error.

    Raises
    ------
    IdentificationError
        Joints that differ from the URDF's; too few samples for the base parameters; a
        trajectory that does not excite every base parameter (naming them; with ``friction``,
        a joint the data never move in both directions names its ``fc``); an infeasible
        consistency problem (:func:`consistent_parameters`).
    ValueError
        ``method`` or ``held_out`` out of range.
    """
    if method not in ("wls", "ols"):
        raise ValueError(f"method must be 'wls' or 'ols', got {method!r}")
    held_out = check_probability("held_out", held_out)
    if held_out > 0.9:
        raise FieldError("held_out", "{name} must be in [0, 0.9] (the fraction of the samples "
                         f"held out of the fit), got {held_out!r}")
    if tuple(data.joint_names) != tuple(robot.joint_names):
        raise IdentificationError(f"the data's joints {list(data.joint_names)} do not match the "
                                  f"URDF {robot.name!r}'s joints {robot.joint_names}")
    base = base_parameters(robot) if base is None else base
    n, p = robot.nq, base.p
    N = data.N
    n_fit = N - int(round(held_out * N))
    block = int(data.derived.get("window_samples", 1)) if data.derived else 1
    edge = block // 2
    fit = np.arange(edge, min(n_fit, N - edge))
    m = len(fit)
    names = list(base.names) + (friction_names(robot) if friction else [])
    P = len(names)
    if m * n < 2 * P or m * n - P < n:
        raise IdentificationError(
            f"too few samples: {m} samples for the fit give {m * n} equations for "
            f"{P} {'base and friction ' if friction else 'base '}parameters of "
            f"{robot.name!r}; need at least {math.ceil(2 * P / n)} "
            f"samples (twice as many equations as parameters) after the held-out "
            f"{held_out:.0%}" + (f" and half a derivative-filter window ({edge} samples) "
                                 f"at each end" if edge else ""))
    tau_f = filter_like(data, data.tau) if block > 1 else data.tau
    if friction:  # linear in f: filtered exactly as the torques (sign(qd) jumps included)
        Yf = friction_regressor(data.qd).reshape(N, n * 3 * n)
        Yf = (filter_like(data, Yf) if block > 1 else Yf).reshape(N * n, 3 * n)

    def design(sl):
        W = base.reduce(regressor(robot, data.q[sl], data.qd[sl], data.qdd[sl]))
        if not friction:
            return W
        rows_ = np.arange(N)[sl]
        return np.hstack([W, Yf.reshape(N, n, 3 * n)[rows_].reshape(-1, 3 * n)])

    W1 = design(fit)
    y1 = tau_f[fit].reshape(-1)
    x, cov_x, R, sigma_j, s2, cond = least_squares(base, W1, y1, n, method, names=names,
                                                   block=block)
    r = (y1 - W1 @ x).reshape(m, n)
    rows = m * n
    theta, cov = x[:p], cov_x[:p, :p]
    # The consistency metric from the base parameters' marginal covariance: A^T A = s2 cov^-1
    # / rows, which is R^T R / rows of the (weighted) regressor when there are no friction
    # columns and the residuals are independent.
    # A square root of cov^-1 by eigenvalues (cov can be numerically semi-definite on short
    # logs, where Cholesky of its inverse fails): A^T A = cov^-1 on its range
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    w = np.maximum(w, 1e-15 * max(float(w.max()), 1e-300))
    A = (V / np.sqrt(w)).T * math.sqrt(s2 / rows)
    phi0 = standard_parameters(robot)
    phi, consistency = consistent_parameters(base, theta, A, phi0, sigma=math.sqrt(s2 / rows),
                                             refuse=refuse_inconsistent, mass_band=mass_band)
    from .dynamics import robot_from_xml

    fr = None
    if friction:
        f, fs = x[p:].reshape(n, 3), np.sqrt(np.diag(cov_x))[p:].reshape(n, 3)
        fr = {j: {"viscous_Nms_rad": float(f[i, 0]), "coulomb_Nm": float(f[i, 1]),
                  "offset_Nm": float(f[i, 2]), "std": {"viscous_Nms_rad": float(fs[i, 0]),
                                                       "coulomb_Nm": float(fs[i, 1]),
                                                       "offset_Nm": float(fs[i, 2])}}
              for i, j in enumerate(robot.joint_names)}
    urdf = urdf_with_parameters(robot.urdf, body_links(robot), phi,
                                moving=robot.joint_names, friction=fr)
    identified = robot_from_xml(urdf, name=f"{robot.name}_identified",
                                gravity=robot.gravity, label="identified URDF",
                                lock=dict(robot.locked) or None)
    suspect = friction_suspects(robot, data.qd[fit], r, tau_f[fit])
    if fr:  # friction dissipates: a coefficient below zero by 3 standard deviations contradicts
        wrong = [f"{j} {k} {v[k]:.3g} +- {v['std'][k]:.2g}" for j, v in fr.items()
                 for k in ("viscous_Nms_rad", "coulomb_Nm") if v[k] < -3.0 * v["std"][k]]
        if wrong:
            suspect = "; ".join(filter(None, [suspect, (
                "friction of the wrong sign (it would feed energy in): " + ", ".join(wrong)
                + ": check the torque sign convention, or a term the model lacks "
                  "(Stribeck, position-dependent friction, a coupling)")]))
    summary = {
        "robot": robot.name, "source": robot.source, "joints": list(robot.joint_names),
        "links": body_links(robot), "gravity_m_s2": robot.gravity,
        "locked": dict(robot.locked),
        "kinematics": _kinematics(robot), "data": data.source, "samples": N,
        "samples_fit": m, "fit_decimation": 1,
        "covariance": ("block sandwich over blocks of one derivative-filter window "
                       f"({block} samples): the filter correlates neighbouring residuals"
                       if block > 1 else "s2 (W^T W)^-1 (independent residuals)"),
        "torque_filter": "savgol (as q)" if block > 1 else None,
        "held_out_fraction": held_out, "derivatives": data.derived or
        {"filter": None, "estimated": []}, "method": method, "base_count": p,
        "condition_number": cond,
        "noise_std_Nm": _per_joint(robot, sigma_j.tolist()),
        "residual_rms_Nm": _per_joint(robot, np.sqrt(np.mean(r * r, axis=0)).tolist()),
        "residual_r2": _per_joint(robot, r_squared(tau_f[fit], tau_f[fit] - r)),
        "sigma2_weighted": s2, "consistency": consistency,
        "friction_model": "viscous + coulomb + offset" if friction else None,
        "friction": fr, "model_error_warning": suspect or None,
        "intervals_cover": "noise only: a model error (unmodelled friction, delays, "
                           "flexibility) is not in the standard deviations",
    }
    if suspect:
        import warnings

        warnings.warn(suspect, stacklevel=2)
    if n_fit < N - edge:
        sl = slice(n_fit, N - edge)
        tau2 = tau_f[sl]
        e_est = tau2 - (design(sl) @ x).reshape(-1, n)
        pred = predict_torques(identified, data, fr)[sl]
        e_urdf = tau2 - pred
        rms = np.sqrt(np.mean(tau2 ** 2, axis=0))
        summary["held_out"] = {
            "samples": N - edge - n_fit, "first_sample": n_fit, "last_sample": N - edge - 1,
            "rms_error_estimate_Nm": _per_joint(robot, np.sqrt(np.mean(e_est ** 2, axis=0))),
            "rms_error_urdf_Nm": _per_joint(robot, np.sqrt(np.mean(e_urdf ** 2, axis=0))),
            "r2_urdf": _per_joint(robot, r_squared(tau2, pred)),
            "rms_torque_Nm": _per_joint(robot, rms.tolist())}
    else:
        summary["held_out"] = None
    return Identification(base, theta, cov, phi, urdf, summary, x[p:].copy(),
                          cov_x)


def r_squared(tau, pred) -> np.ndarray:
    """Per-column coefficient of determination ``1 - SS_res / SS_tot`` (shape (n,))."""
    tau, pred = np.asarray(tau), np.asarray(pred)
    ss = np.sum((tau - tau.mean(axis=0)) ** 2, axis=0)
    return 1.0 - np.sum((tau - pred) ** 2, axis=0) / np.where(ss > 0.0, ss, np.nan)


def friction_suspects(robot, qd, r, tau=None, threshold: float = 0.3) -> str:
    """Return a warning naming the joints whose residual correlates with ``qd`` or its sign.

    Parameters
    ----------
    qd, r : ndarray, shape (N, nq)
        Velocities [rad/s] and torque residuals [N m] of the fit.
    tau : ndarray, shape (N, nq), optional
        The torques fitted [N m]: a joint whose residual RMS is below ``1e-9`` of their RMS
        (round-off of exact data) is not named.
    threshold : float, default 0.3
        ``|corr|`` above which a joint is named.

    Returns
    -------
    str
        Empty when no joint is suspect.
    """
    bad = []
    for j, name in enumerate(robot.joint_names):
        rj = r[:, j] - r[:, j].mean()
        if tau is not None and np.sqrt(np.mean(rj * rj)) <= 1e-9 * np.sqrt(
                np.mean(tau[:, j] ** 2)):
            continue
        for what, x in (("sign(qd)", np.sign(qd[:, j])), ("qd", qd[:, j])):
            x = x - x.mean()
            den = float(np.linalg.norm(rj) * np.linalg.norm(x))
            c = float(rj @ x) / den if den > 0.0 else 0.0
            if abs(c) > threshold:
                bad.append(f"{name} (corr with {what} {c:+.2f})")
                break
    if not bad:
        return ""
    return ("model error: the torque residual correlates with the joint velocity or its sign "
            "at " + ", ".join(bad) + ": likely missing term: joint friction (viscous/Coulomb; "
            "identify with --friction). The standard deviations cover the noise, not this "
            "model error")


def predict_torques(robot, data: Measurements, friction: dict | None = None) -> np.ndarray:
    """Inverse dynamics of ``robot`` plus identified friction, as :func:`identify` fits them.

    The friction torque gets the torques' filter when the data's derivatives were estimated
    (:func:`filter_like`: parallel filtering, as in the fit), so the prediction is compared
    with ``filter_like(data, data.tau)``.

    Parameters
    ----------
    robot : rrr_pin.model.dynamics.Robot
    data : Measurements
    friction : dict, optional
        ``{joint: {"viscous_Nms_rad", "coulomb_Nm", "offset_Nm"}}``
        (``Identification.summary["friction"]``).

    Returns
    -------
    ndarray, shape (N, nq)
        Torques [N m].
    """
    q, qd, qdd = data.q, data.qd, data.qdd
    tau = np.array([robot.inverse_dynamics(q[k], qd[k], qdd[k], check=False)
                    for k in range(len(q))])
    if friction:
        f = np.array([[friction[j][k] for k in ("viscous_Nms_rad", "coulomb_Nm", "offset_Nm")]
                      for j in robot.joint_names])
        tf = (friction_regressor(qd) @ f.reshape(-1)).reshape(tau.shape)
        tau = tau + filter_like(data, tf)
    return tau


#: Keys of ``identification.json`` that :class:`IdentifiedUncertainty` reads.
RECORD_KEYS = ("joints", "links", "kinematics", "base", "base_count", "estimate", "cov",
               "standard_consistent", "consistency")


def check_identification_record(record: dict, path) -> None:
    """Refuse an ``identification.json`` that :class:`IdentifiedUncertainty` cannot draw from.

    Raises
    ------
    IdentificationError
        Naming the file and the key: missing keys; base names, ``K`` rows, ``estimate`` and
        ``base_count`` of different lengths; a covariance of the wrong shape, not finite, not
        symmetric or not positive definite.
    """
    missing = [k for k in RECORD_KEYS if k not in record]
    if not missing and isinstance(record["base"], dict):
        missing = [f"base.{k}" for k in ("names", "expressions", "standard", "independent",
                                         "K") if k not in record["base"]]
    if not missing and "pseudo_inertia_margins" not in (record["consistency"] or {}):
        missing = ["consistency.pseudo_inertia_margins"]
    if missing:
        raise IdentificationError(f"identification {str(path)!r}: missing keys {missing} (not "
                                  f"written by `rrr-pin identify`, or edited)")
    try:
        p = int(record["base_count"])
        K = np.asarray(record["base"]["K"], dtype=float)
        est = np.asarray(record["estimate"], dtype=float)
        cov = np.asarray(record["cov"], dtype=float)
    except (TypeError, ValueError) as exc:
        raise IdentificationError(f"identification {str(path)!r}: not numbers: {exc}") from None
    sizes = {"base_count": p, "base.names": len(record["base"]["names"]),
             "base.K rows": K.shape[0] if K.ndim == 2 else -1, "estimate": est.size}
    if len(set(sizes.values())) != 1 or est.ndim != 1:
        raise IdentificationError(f"identification {str(path)!r}: the number of base "
                                  f"parameters disagrees: {sizes}")
    if cov.shape != (p, p):
        raise IdentificationError(f"identification {str(path)!r}: 'cov' has shape "
                                  f"{cov.shape}, expected ({p}, {p}) for {p} base parameters")
    if not np.all(np.isfinite(cov)) or not np.all(np.isfinite(est)):
        raise IdentificationError(f"identification {str(path)!r}: 'cov' or 'estimate' holds a "
                                  f"value that is not finite")
    if not np.allclose(cov, cov.T, rtol=1e-9, atol=0.0):
        raise IdentificationError(f"identification {str(path)!r}: 'cov' is not symmetric")
    try:
        np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        raise IdentificationError(f"identification {str(path)!r}: 'cov' is not positive "
                                  f"definite (smallest eigenvalue "
                                  f"{np.linalg.eigvalsh(cov).min():.3g})") from None


# --- the uncertainty set of an identification -------------------------------------------------

@dataclass(frozen=True)
class IdentifiedUncertainty(UncertaintySet):
    r"""Uncertain plants drawn from an identification's distribution (``identification.json``).

    Each plant: base parameters ``theta ~ N(theta_c, cov)`` kept only inside the
    ``confidence`` ellipsoid ``(theta - theta_c)^T cov^{-1} (theta - theta_c) <=
    chi2_p(confidence)`` (a draw outside is redrawn), centred on ``theta_c``, the base
    parameters of the identified URDF (the study's nominal; equal to the estimate when that is
    consistent, else the nearest consistent point, :func:`consistent_parameters`), with the
    estimate's covariance ``cov``, then the standard parameters with exactly
    those base parameters nearest to the identified ones under ``J_b >= eps_b 1`` (an SDP); a
    draw with no consistent arm is rejected and redrawn (at most :attr:`MAX_DRAWS` draws per
    plant). So the plants follow the identified distribution conditioned on physical
    consistency (within the confidence region): where the estimate lies near the boundary of
    the consistent set (thin links), many draws are rejected, none is moved. The kinematics
    stay the nominal's. Each plant records how many draws were rejected.

    Parameters
    ----------
    path : str
        The ``identification.json`` read (recorded with its SHA-256).
    confidence : float, default 0.95
        Of the ellipsoid the plants are drawn in, in (0, 1).
    """

    MAX_DRAWS = 1000

    path: str
    confidence: float = 0.95
    record: dict = field(default=None, repr=False, compare=False)
    sha256: str = field(default="", compare=True)

    def __post_init__(self) -> None:
        c = check_probability("confidence", self.confidence)
        if not 0.0 < c < 1.0:
            raise ValueError(f"confidence must be in (0, 1), got {c!r}")
        object.__setattr__(self, "confidence", c)
        if self.record is None:
            try:
                raw = Path(self.path).read_bytes()
                record = json.loads(raw)
            except (OSError, ValueError) as exc:
                raise IdentificationError(f"cannot read identification {self.path!r}: "
                                          f"{exc}") from None
            if not isinstance(record, dict) or record.get("format") != "rrr-pin-identification":
                raise IdentificationError(f"{self.path!r} is not an identification.json of "
                                          f"`rrr-pin identify` (no format "
                                          f"'rrr-pin-identification')")
            check_identification_record(record, self.path)
            object.__setattr__(self, "record", record)
            object.__setattr__(self, "sha256", hashlib.sha256(raw).hexdigest())

    @property
    def base(self) -> BaseParameters:
        """The base parameters identified."""
        return BaseParameters.from_dict(self.record["base"])

    def check_robot(self, robot) -> None:
        """Refuse a nominal whose joints or kinematics are not the identification's.

        Raises
        ------
        IdentificationError
            Naming the joints or the first joint whose placement differs (beyond 1e-9).
        """
        rec = self.record
        if list(robot.joint_names) != rec["joints"]:
            raise IdentificationError(f"{self.path}: identified joints {rec['joints']} are not "
                                      f"the robot {robot.name!r}'s {robot.joint_names}")
        for mine, theirs in zip(_kinematics(robot), rec["kinematics"], strict=True):
            if mine["type"] != theirs["type"] or not np.allclose(
                    mine["placement"], theirs["placement"], rtol=0.0, atol=1e-9):
                raise IdentificationError(
                    f"{self.path}: joint {mine['joint']!r} of {robot.name!r} is not placed as "
                    f"in the identified arm (kinematics differ); use the URDF identified "
                    f"({rec.get('urdf', 'identified.urdf')}) or the one it was identified on")
        if len(rec["base"]["K"][0]) != 10 * robot.nq:
            raise IdentificationError(f"{self.path}: its base parameters combine "
                                      f"{len(rec['base']['K'][0])} standard parameters; the "
                                      f"robot {robot.name!r} has {10 * robot.nq} (10 per body)")
        if body_links(robot) != rec["links"]:
            raise IdentificationError(f"{self.path}: body links {rec['links']} are not the "
                                      f"robot's {body_links(robot)}")
        own, theirs = list(base_parameters(robot).names), list(rec["base"]["names"])
        if own != theirs:
            raise IdentificationError(f"{self.path}: {len(theirs)} base parameters identified, "
                                      f"the robot {robot.name!r} has {len(own)} (or named "
                                      f"otherwise: {sorted(set(theirs) ^ set(own))[:4]})")

    def describe(self) -> str:
        """One line for reports."""
        return (f"identified distribution ({Path(self.path).name}, {self.record['base_count']} "
                f"base parameters, {self.confidence:.0%} confidence region)")

    def to_dict(self) -> dict:
        """JSON-ready: what the plants are drawn from."""
        return {"kind": "identified", "identification": str(self.path),
                "identification_sha256": self.sha256, "confidence": self.confidence,
                "base_count": self.record["base_count"]}

    def _problem(self):
        cached = getattr(self, "_cache", None)
        if cached is not None:
            return cached
        import cvxpy as cp

        base, phi_id = self.base, np.asarray(self.record["standard_consistent"], float)
        theta = cp.Parameter(base.p)
        phi = cp.Variable(len(phi_id))
        margins = np.asarray(self.record["consistency"]["pseudo_inertia_margins"], float)
        problem = cp.Problem(
            cp.Minimize(cp.sum_squares(cp.multiply(_weights(phi_id), phi - phi_id))),
            [base.K @ phi == theta] + _lmi(phi, len(phi_id) // 10, margins))
        cached = (problem, theta, phi)
        object.__setattr__(self, "_cache", cached)
        return cached

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k != "_cache"}

    def __setstate__(self, state):
        self.__dict__.update(state)

    def as_settings(self) -> dict:
        """Return what the outputs record: ``{"uncertainty": "identified", ...to_dict()}``."""
        return {"uncertainty": "identified", **{k: v for k, v in self.to_dict().items()
                                                if k != "kind"}}

    def arm(self, source, rng: np.random.Generator, *, skip_joints=(), name=None
            ) -> tuple[str, dict]:
        """:meth:`draw` on the arm's URDF (kinematics nominal): ``(URDF, {"identified": ...})``."""
        from .urdf import urdf_from_params

        text = str(source) if isinstance(source, str) else urdf_from_params(source)
        urdf, drawn = self.draw(text, rng)
        return urdf, {"identified": drawn}

    def draw(self, urdf: str, rng: np.random.Generator) -> tuple[str, dict]:
        """One plant: its URDF text and ``{"base", "standard", "rejected": {...}}``.

        Raises
        ------
        IdentificationError
            No consistent plant in :attr:`MAX_DRAWS` draws.
        """
        from scipy.stats import chi2

        rec = self.record
        mean = np.asarray(rec["base_consistent"], float)
        cov = np.asarray(rec["cov"], float)
        L = np.linalg.cholesky(cov)
        limit = chi2.ppf(self.confidence, len(mean))
        problem, theta, phi = self._problem()
        outside = inconsistent = 0
        for _ in range(self.MAX_DRAWS):
            z = rng.standard_normal(len(mean))
            if z @ z > limit:
                outside += 1
                continue
            theta.value = mean + L @ z
            try:
                problem.solve(solver="CLARABEL")
                ok = problem.status == "optimal"
            except Exception:  # cvxpy.SolverError: a rejected draw
                ok = False
            if ok:
                try:
                    text = urdf_with_parameters(urdf, rec["links"], phi.value)
                except ValueError:  # not physical after all (round-off): rejected
                    ok = False
            if not ok:
                inconsistent += 1
                continue
            return text, {"base": theta.value.tolist(), "standard": phi.value.tolist(),
                          "rejected": {"outside_confidence": outside,
                                       "inconsistent": inconsistent}}
        raise IdentificationError(
            f"{self.path}: no physically consistent plant in {self.MAX_DRAWS} draws "
            f"({outside} outside the {self.confidence:.0%} region, {inconsistent} with no "
            f"consistent arm); the identified covariance is too wide for this arm")

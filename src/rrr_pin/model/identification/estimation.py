r"""Least squares for base and friction parameters: covariance, held-out check, warnings.

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

References
----------
.. [1] M. Gautier and P. Poignet, "Extended Kalman filtering and weighted least squares dynamic
   identification of robot", Control Engineering Practice 9, 2001.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...validation import FieldError, check_probability
from .armature import armature_columns, armature_names, armature_regressor, with_armature
from .consistency import consistent_parameters, urdf_with_parameters
from .friction import friction_names, friction_regressor
from .measurements import Measurements, filter_like
from .regressors import (
    BaseParameters,
    IdentificationError,
    base_parameters,
    body_links,
    joint_kinematics,
    regressor,
    standard_parameters,
)

__all__ = [
    "Identification",
    "least_squares",
    "identify",
    "r_squared",
    "friction_suspects",
    "predict_torques",
    "correlation_lag",
    "written_distance",
    "jackknife_scale",
    "JACKKNIFE_BLOCKS",
]



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
    cov_all : ndarray, shape (p + 3 nq + na, p + 3 nq + na), optional
        Covariance of base, friction and armature parameters together.
    armature : ndarray, shape (nq,) or (0,)
        Estimated armature per joint [kg m^2] (0 where it is absorbed into a base parameter,
        :func:`~rrr_pin.model.identification.armature.armature_columns`), empty without.
    cov_all_noise : ndarray, shape like ``cov_all``, optional
        The white-noise (or filter-window block) covariance of the same fit, before
        calibration; equal to ``cov_all`` with ``covariance="noise"``. Not written.
    """

    base: BaseParameters
    theta: np.ndarray
    cov: np.ndarray
    phi: np.ndarray
    urdf: str = field(repr=False)
    summary: dict = field(default_factory=dict)
    friction: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cov_all: np.ndarray | None = field(default=None, repr=False)
    armature: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cov_all_noise: np.ndarray | None = field(default=None, repr=False)

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
                "armature_estimate": self.armature.tolist(),
                "cov_all": None if self.cov_all is None else self.cov_all.tolist()}

    def write(self, folder, *, urdf_name: str = "identified.urdf") -> list[Path]:
        """Write ``identified.urdf`` and ``identification.json`` into ``folder``."""
        from ...outputs import writing

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
                  method: str = "wls", *, names=None, block: int = 1, hac_lag: int = 0):
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
    hac_lag : int, default 0
        Above 0 (and taking precedence over ``block``), the heteroskedasticity and
        autocorrelation consistent covariance of Newey & West (1987), Bartlett kernel of
        bandwidth ``L = hac_lag`` samples, which counts a model error that is correlated
        over ``L`` samples (a friction shape, an armature, a filter the model lacks) as the
        noise it is for the estimate:

        .. math:: \operatorname{cov} = (W^T W)^{-1} \tfrac{m}{m - P} \Big(\sum_{|l| \le L}
                  \big(1 - \tfrac{|l|}{L+1}\big) \sum_k g_k g_{k-l}^T\Big) (W^T W)^{-1},
                  \qquad g_k = W_k^T r_k ,

        computed as ``H^T H / (L + 1)`` with ``H`` the sums of ``g`` over every window of
        ``L + 1`` consecutive samples (the Bartlett weights are the windows' overlaps), so it
        is positive semi-definite and costs ``O(m P^2)``.

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
    if hac_lag > 0:
        g = np.einsum("kjp,kj->kp", (W * np.tile(weights, N)[:, None]).reshape(N, n, p), rw)
        c = np.concatenate([np.zeros((1, p)), np.cumsum(g, axis=0)])
        lo = np.clip(np.arange(-hac_lag, N) , 0, N)
        hi = np.clip(np.arange(-hac_lag, N) + hac_lag + 1, 0, N)
        H = c[hi] - c[lo]
        meat = (N / max(N - p / n, 1.0)) * (H.T @ H) / (hac_lag + 1)
        cov = (Rinv @ Rinv.T) @ meat @ (Rinv @ Rinv.T)
        cov = 0.5 * (cov + cov.T)
    elif block > 1:
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
             armature: bool = False, covariance: str = "noise",
             hac_lag: int | None = None, refuse_inconsistent: bool = True,
             mass_band: float | None = None,
             inertia_band: float | None = None) -> Identification:
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
    data : Measurements or sequence of Measurements
        From :func:`read_measurements` (joints in ``robot.joint_names`` order); several runs
        are concatenated: each filtered on its own (its ends left out), their rows stacked,
        each run's final ``held_out`` fraction held out (the block sandwich's blocks run over
        the stacked samples, so a block may join the end of one run to the next).
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
    armature : bool, default False
        Identify each joint's armature ``I_a`` (``+ I_a qdd``,
        :func:`~rrr_pin.model.identification.armature.armature_regressor`) with them; a joint
        whose armature the base parameters already hold (the first joint's, about an axis
        fixed in the base) is reported as absorbed (``summary["armature"]``), not a column;
        one estimated below 0 is not detected: its column is left out and the rest refitted
        (a torque sensor after the gearbox, as the Panda's, never sees the rotor).
    covariance : {"noise", "calibrated"}, default "noise"
        ``"noise"``: the covariance of white (or filter-window correlated) noise around a
        correct model. ``"calibrated"``: calibrated to include the model error, the Newey-West
        covariance of :func:`least_squares` (``hac_lag``), and the consistency distance,
        the refusal and ``identification.json``'s ``cov`` in its terms.
    hac_lag : int, optional
        Bandwidth [samples] of ``"calibrated"``; default :func:`correlation_lag` of the residuals
        (the lag at which their autocorrelation, averaged over joints, first falls below
        0.1), at least one derivative-filter window.
    refuse_inconsistent : bool, default True
        Refuse an estimate with no physically consistent arm inside its 99.9 % region
        (:func:`consistent_parameters`), or with a friction coefficient below zero by 3
        standard deviations; ``False`` keeps them with a warning.
    mass_band : float, optional
        Bound every body's mass to ``[m0 / f, f m0]`` of the nominal's
        (:func:`consistent_parameters`).
    inertia_band : float, optional
        Bound every body's pseudo-inertia to ``[J0 / f, f J0]`` of the nominal's (Loewner
        order, :func:`~rrr_pin.model.identification.consistency.plausible_set`).

    Returns
    -------
    Identification

    Warns
    -----
    UserWarning
        The residual of a joint correlates with ``qd`` or ``sign(qd)`` (``|r| > 0.3``, named
        joints): a friction term is missing from the model (``friction=False``) or not of the
        form modelled. The intervals then do not cover the model error.
    UserWarning
        A friction coefficient or armature estimated below 0 and written as 0 into the
        identified model ("clipped: joint parameter estimated value +- std unit";
        ``summary["clipped"]``).

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
    if covariance not in ("noise", "calibrated"):
        raise ValueError(f"covariance must be 'noise' or 'calibrated', got {covariance!r}")
    held_out = check_probability("held_out", held_out)
    if held_out > 0.9:
        raise FieldError("held_out", "{name} must be in [0, 0.9] (the fraction of the samples "
                         f"held out of the fit), got {held_out!r}")
    runs = [data] if isinstance(data, Measurements) else list(data)
    if not runs:
        raise IdentificationError("no measurements: give one run or several")
    for d in runs:
        if tuple(d.joint_names) != tuple(robot.joint_names):
            raise IdentificationError(f"the data's joints {list(d.joint_names)} do not match "
                                      f"the URDF {robot.name!r}'s joints {robot.joint_names}")
    base = base_parameters(robot) if base is None else base
    n, p = robot.nq, base.p
    # Per run: its filter window, the samples fitted (none within half a window of its ends)
    # and its held-out tail; the runs' fitted rows are stacked (several runs concatenated).
    parts = []
    for d in runs:
        b_i = int(d.derived.get("window_samples", 1)) if d.derived else 1
        e_i, n_fit_i = b_i // 2, d.N - int(round(held_out * d.N))
        parts.append({"data": d, "block": b_i, "edge": e_i, "n_fit": n_fit_i,
                      "fit": np.arange(e_i, min(n_fit_i, d.N - e_i))})
    block = max(part["block"] for part in parts)
    edge = block // 2
    N = sum(d.N for d in runs)
    m = sum(len(part["fit"]) for part in parts)
    names = list(base.names) + (friction_names(robot) if friction else [])
    kept, absorbed = (armature_columns(robot, base) if armature
                      else (np.zeros(0, dtype=int), {}))
    names += [armature_names(robot)[j] for j in kept]
    P = len(names)
    if m * n < 2 * P or m * n - P < n:
        raise IdentificationError(
            f"too few samples: {m} samples for the fit give {m * n} equations for "
            f"{P} {'base and friction ' if friction else 'base '}parameters of "
            f"{robot.name!r}; need at least {math.ceil(2 * P / n)} "
            f"samples (twice as many equations as parameters) after the held-out "
            f"{held_out:.0%}" + (f" and half a derivative-filter window ({edge} samples) "
                                 f"at each end" if edge else ""))
    for part in parts:
        d, b_i = part["data"], part["block"]
        part["tau_f"] = filter_like(d, d.tau) if b_i > 1 else d.tau
        if friction:  # linear in f: filtered exactly as the torques (sign(qd) jumps included)
            Yf = friction_regressor(d.qd).reshape(d.N, n * 3 * n)
            part["Yf"] = (filter_like(d, Yf) if b_i > 1 else Yf).reshape(d.N, n, 3 * n)

    def design(part, rows_):
        d = part["data"]
        W = base.reduce(regressor(robot, d.q[rows_], d.qd[rows_], d.qdd[rows_]))
        if friction:
            W = np.hstack([W, part["Yf"][rows_].reshape(-1, 3 * n)])
        if kept.size:
            W = np.hstack([W, armature_regressor(d.qdd[rows_])[:, kept]])
        return W

    W1 = np.vstack([design(part, part["fit"]) for part in parts])
    tau_fit = np.vstack([part["tau_f"][part["fit"]] for part in parts])
    qd_fit = np.vstack([part["data"].qd[part["fit"]] for part in parts])
    y1 = tau_fit.reshape(-1)
    x, cov_x, R, sigma_j, s2, cond = least_squares(base, W1, y1, n, method, names=names,
                                                   block=block)
    nf = 3 * n if friction else 0
    dropped = {}
    below = [int(j) for i, j in enumerate(kept) if x[p + nf + i] < 0.0]
    if below:  # an armature below zero is not detected: its column leaves, the rest refitted
        sd = np.sqrt(np.diag(cov_x))
        for i, j in enumerate(kept):
            if j in below:
                dropped[robot.joint_names[j]] = (float(x[p + nf + i]), float(sd[p + nf + i]))
        kept = np.asarray([j for j in kept if j not in below], dtype=int)
        names = names[:p + nf] + [armature_names(robot)[j] for j in kept]
        W1 = np.vstack([design(part, part["fit"]) for part in parts])
        x, cov_x, R, sigma_j, s2, cond = least_squares(base, W1, y1, n, method, names=names,
                                                       block=block)
    r = (y1 - W1 @ x).reshape(m, n)
    summary_extra = {}
    cov_noise = cov_x[:len(base.names), :len(base.names)].copy()
    cov_all_noise = cov_x.copy()
    if covariance == "calibrated":
        lag = max(correlation_lag(r), block) if hac_lag is None else int(hac_lag)
        cov_x = least_squares(base, W1, y1, n, method, names=names, hac_lag=lag)[1]
        weights = 1.0 / sigma_j if method == "wls" else np.ones(n)
        jack, s_cv = jackknife_scale(W1, y1, cov_x, n, weights)
        cov_x = max(jack, 1.0) * cov_x
        summary_extra = {"jackknife_c2": jack, "hac_lag_samples": lag,
                         "prediction_noise_std_Nm": _per_joint(robot, s_cv)}
    rows = m * n
    theta, cov = x[:p], cov_x[:p, :p]
    # The consistency metric from the base parameters' marginal covariance: A^T A = s2 cov^-1
    # / rows, which is R^T R / rows of the (weighted) regressor when there are no friction
    # columns and the residuals are independent. With the calibrated covariance the arm is
    # still chosen in the noise metric (the smallest torque change over the data, what the
    # prediction needs), and judged in the calibrated one (its distance, the refusal).
    # A square root of cov^-1 by eigenvalues (cov can be numerically semi-definite on short
    # logs, where Cholesky of its inverse fails): A^T A = cov^-1 on its range
    metric = cov_noise if covariance == "calibrated" else cov
    w, V = np.linalg.eigh(0.5 * (metric + metric.T))
    w = np.maximum(w, 1e-15 * max(float(w.max()), 1e-300))
    A = (V / np.sqrt(w)).T * math.sqrt(s2 / rows)
    phi0 = standard_parameters(robot)
    phi, consistency = consistent_parameters(
        base, theta, A, phi0, sigma=None if covariance == "calibrated" else math.sqrt(s2 / rows),
        refuse=refuse_inconsistent, mass_band=mass_band, inertia_band=inertia_band)
    consistency["written"] = written_distance(base(phi) - theta, cov, cov_noise,
                                              W1[:, :p], n, robot.joint_names)
    if covariance == "calibrated":
        from scipy.stats import chi2

        from .consistency import CONSISTENCY_CONFIDENCE, PSEUDO_INERTIA_MARGIN

        d_cal = consistency["written"]["mahalanobis"]
        limit = math.sqrt(chi2.ppf(CONSISTENCY_CONFIDENCE, p))
        scale = float(np.linalg.norm(A @ theta))
        outside = bool(d_cal > limit and consistency["distance_rms_Nm"]
                       > 10.0 * PSEUDO_INERTIA_MARGIN * scale)
        consistency.update(mahalanobis=d_cal, outside_confidence=outside,
                           mahalanobis_returned=d_cal)
        said = (f"the nearest physically consistent arm lies {d_cal:.4g} standard deviations "
                f"of the calibrated covariance from the estimate, outside its "
                f"{CONSISTENCY_CONFIDENCE:.1%} region (limit {limit:.4g}; RMS torque change "
                f"{consistency['written']['rms_Nm_all']:.4g} N m)")
        if outside and refuse_inconsistent:
            raise IdentificationError(
                f"infeasible consistency problem: {said}. The data do not fit a rigid arm with "
                f"this URDF's kinematics even allowing for the model error the residuals show: "
                f"check the joint order, torque signs and units, or a payload; to keep the "
                f"nearest consistent arm anyway: refuse_inconsistent=False (command line: "
                f"--keep-inconsistent)")
        if outside:
            import warnings

            warnings.warn(said + ": kept, as asked", stacklevel=2)
    consistency["covariance"] = covariance
    if covariance == "calibrated":
        consistency["hac_lag_samples"] = lag
    from ..dynamics import robot_from_xml

    fr = None
    std_x = np.sqrt(np.diag(cov_x))
    arm = np.zeros(n if armature else 0)
    arm[kept] = x[p + nf:]
    arm_std = np.zeros_like(arm)
    arm_std[kept] = std_x[p + nf:]
    ar = None if not armature else {
        j: ({"value_kg_m2": 0.0, "std": 0.0, "absorbed_into": absorbed[j]} if j in absorbed
            else {"value_kg_m2": 0.0, "std": dropped[j][1], "not_detected": (
                f"estimate {dropped[j][0]:.4g} +- {dropped[j][1]:.2g} kg m^2 below 0: column "
                f"left out and the rest refitted (a torque sensor after the gearbox does not "
                f"see the rotor)")} if j in dropped
            else {"value_kg_m2": float(arm[i]), "std": float(arm_std[i])})
        for i, j in enumerate(robot.joint_names)}
    if friction:
        f, fs = x[p:p + nf].reshape(n, 3), std_x[p:p + nf].reshape(n, 3)
        fr = {j: {"viscous_Nms_rad": float(f[i, 0]), "coulomb_Nm": float(f[i, 1]),
                  "offset_Nm": float(f[i, 2]), "std": {"viscous_Nms_rad": float(fs[i, 0]),
                                                       "coulomb_Nm": float(fs[i, 1]),
                                                       "offset_Nm": float(fs[i, 2])}}
              for i, j in enumerate(robot.joint_names)}
    urdf = urdf_with_parameters(robot.urdf, body_links(robot), phi,
                                moving=robot.joint_names, friction=fr,
                                locked=dict(robot.locked))
    identified = robot_from_xml(urdf, name=f"{robot.name}_identified",
                                gravity=robot.gravity, label="identified URDF")
    if armature:
        with_armature(identified, np.maximum(arm, 0.0))
    suspect = friction_suspects(robot, qd_fit, r, tau_fit)
    if fr:  # friction dissipates: a coefficient below zero by 3 standard deviations contradicts
        wrong = [f"{j} {k} {v[k]:.3g} +- {v['std'][k]:.2g}" for j, v in fr.items()
                 for k in ("viscous_Nms_rad", "coulomb_Nm") if v[k] < -3.0 * v["std"][k]]
        if wrong:
            said = ("friction of the wrong sign (it would feed energy in): " + ", ".join(wrong)
                    + ": check the torque sign convention, or a term the model lacks "
                      "(Stribeck, position-dependent friction, a coupling)")
            if refuse_inconsistent:  # contradicting signs: not a physical arm
                raise IdentificationError(said + "; refused (keep it, warned, with "
                                                 "refuse_inconsistent=False, CLI "
                                                 "--keep-inconsistent)")
            suspect = "; ".join(filter(None, [suspect, said]))
    clipped = _clipped(fr, ar)
    if covariance == "calibrated":
        covariance_said = (f"Newey-West (Bartlett kernel, {lag} samples) scaled by the block "
                           f"jackknife's c2 = {max(jack, 1.0):.4g} (measured {jack:.4g}, never "
                           f"below 1) over {JACKKNIFE_BLOCKS} blocks: calibrated to the model "
                           f"error")
    elif block > 1:
        covariance_said = ("block sandwich over blocks of one derivative-filter window "
                           f"({block} samples): the filter correlates neighbouring residuals")
    else:
        covariance_said = "s2 (W^T W)^-1 (independent residuals)"
    summary = {
        "robot": robot.name, "source": robot.source, "joints": list(robot.joint_names),
        "links": body_links(robot), "gravity_m_s2": robot.gravity,
        "locked": dict(robot.locked),
        "locked_note": "written into the identified URDF as fixed joints at these values"
                       if robot.locked else None,
        "kinematics": joint_kinematics(robot),
        "data": runs[0].source if len(runs) == 1 else [d.source for d in runs], "samples": N,
        "runs": len(runs), "samples_fit": m, "fit_decimation": 1,
        **summary_extra,
        "covariance": covariance_said,
        "torque_filter": "savgol (as q)" if block > 1 else None,
        "held_out_fraction": held_out, "derivatives": (runs[0].derived or {
            "filter": None, "estimated": []}) if len(runs) == 1 else [
            d.derived or {"filter": None, "estimated": []} for d in runs],
        "method": method, "base_count": p,
        "condition_number": cond,
        "noise_std_Nm": _per_joint(robot, sigma_j.tolist()),
        "residual_rms_Nm": _per_joint(robot, np.sqrt(np.mean(r * r, axis=0)).tolist()),
        "residual_r2": _per_joint(robot, r_squared(tau_fit, tau_fit - r)),
        "sigma2_weighted": s2, "consistency": consistency,
        "standard_nominal": phi0.tolist(),
        "friction_model": "viscous + coulomb + offset" if friction else None,
        "friction": fr, "model_error_warning": suspect or None,
        "armature": ar, "armature_columns": kept.tolist() if armature else None,
        "clipped": clipped or None,
        "armature_note": None if not armature else "per joint [kg m^2], added to M(q)'s "
                         "diagonal (Pinocchio's model.armature); not in the URDF: set on the "
                         "loaded model from this record; absorbed_into: the base parameters "
                         "that already hold it (written into those links' inertia)",
        "friction_urdf": None if not fr else {
            j: {"damping": max(v["viscous_Nms_rad"], 0.0), "friction": max(v["coulomb_Nm"], 0.0)}
            for j, v in fr.items()},
        "friction_urdf_note": None if not fr else "each joint's <dynamics damping friction> "
                              "in the identified URDF: the estimate, a negative one written as 0",
        "intervals_cover": "noise and the model error, as far as it varies from one "
                           "stretch of the motion to the next (block jackknife)"
                           if covariance == "calibrated" else
                           "noise only: a model error (unmodelled friction, delays, "
                           "flexibility) is not in the standard deviations",
    }
    if suspect or clipped:
        import warnings

        if suspect:
            warnings.warn(suspect, stacklevel=2)
        for c in clipped:
            warnings.warn(f"clipped: {c['joint']} {c['parameter']} estimated {c['value']:.4g} "
                          f"+- {c['std']:.2g} {c['unit']} (below 0: it would feed energy in), "
                          f"written as 0 into the identified model", stacklevel=2)
    held = [(part, np.arange(part["n_fit"], part["data"].N - part["edge"])) for part in parts]
    held = [(part, rows_) for part, rows_ in held if rows_.size]
    if held:
        tau2 = np.vstack([part["tau_f"][rows_] for part, rows_ in held])
        e_est = tau2 - np.vstack([(design(part, rows_) @ x).reshape(-1, n)
                                  for part, rows_ in held])
        pred = np.vstack([predict_torques(identified, part["data"], fr)[rows_]
                          for part, rows_ in held])
        e_urdf = tau2 - pred
        rms = np.sqrt(np.mean(tau2 ** 2, axis=0))
        last = held[-1][1]  # the (last) run's held-out samples, by index in that run
        summary["held_out"] = {
            "samples": len(tau2), "first_sample": int(last[0]), "last_sample": int(last[-1]),
            "runs": [{"source": part["data"].source, "first_sample": int(rows_[0]),
                      "last_sample": int(rows_[-1])} for part, rows_ in held],
            "rms_error_estimate_Nm": _per_joint(robot, np.sqrt(np.mean(e_est ** 2, axis=0))),
            "rms_error_urdf_Nm": _per_joint(robot, np.sqrt(np.mean(e_urdf ** 2, axis=0))),
            "r2_urdf": _per_joint(robot, r_squared(tau2, pred)),
            "rms_torque_Nm": _per_joint(robot, rms.tolist())}
    else:
        summary["held_out"] = None
    return Identification(base, theta, cov, phi, urdf, summary, x[p:p + nf].copy(),
                          cov_x, arm, cov_all_noise)


#: Contiguous blocks of the block jackknife that calibrates the covariance.
JACKKNIFE_BLOCKS = 10


def jackknife_scale(W, y, cov, n: int, weights, blocks: int = JACKKNIFE_BLOCKS) -> float:
    r"""How much wider the estimate varies, leaving out blocks of time, than ``cov`` says.

    The delete-a-block jackknife (Kunsch 1989) over ``blocks`` contiguous blocks of samples:
    ``theta_(k)`` fitted without block ``k`` (by downdating the weighted normal equations),

    .. math:: C_J = \tfrac{K-1}{K} \sum_k (\theta_{(k)} - \bar\theta)(\theta_{(k)} -
              \bar\theta)^T, \qquad c^2 = \operatorname{tr}(C^{-1} C_J) / P ,

    the mean ratio of the jackknife variance to ``cov``'s in ``cov``'s own metric. A model
    error that depends on the motion (a friction shape, an armature, a payload the regressor
    lacks) moves the estimate from one stretch of motion to the next by more than the noise
    does; ``c^2 > 1`` measures by how much (with ``K = 10`` blocks, ``C_J`` has rank 9: one
    scalar is what it can calibrate).

    Parameters
    ----------
    W : ndarray, shape (m n, P)
        Regressor (unweighted), rows sample-major.
    y : ndarray, shape (m n,)
        Torques [N m].
    cov : ndarray, shape (P, P)
        The covariance to calibrate.
    n : int
        Joints.
    weights : ndarray, shape (n,)
        Per-joint row weights of the fit (``1 / sigma_j`` for ``wls``).
    blocks : int, default 10

    Returns
    -------
    c2 : float
        ``c^2``.
    s_cv : ndarray, shape (n,)
        Per joint, the RMS [N m] of each block's residual predicted by the fit without it
        (the leave-one-block-out prediction error: the residual level on motion the fit has
        not seen, for prediction intervals).

    References
    ----------
    .. [1] H. R. Kunsch, "The jackknife and the bootstrap for general stationary
       observations", Annals of Statistics 17(3), 1989.
    """
    m, P = len(y) // n, W.shape[1]
    Dw = np.tile(weights, m)
    Ww, yw = (W * Dw[:, None]).reshape(m, n, P), (y * Dw).reshape(m, n)
    edges = np.linspace(0, m, blocks + 1).astype(int)
    spans = list(zip(edges[:-1], edges[1:], strict=True))
    A_k = [np.einsum("kjp,kjq->pq", Ww[a:b], Ww[a:b]) for a, b in spans]
    b_k = [np.einsum("kjp,kj->p", Ww[a:b], yw[a:b]) for a, b in spans]
    A, b = sum(A_k), sum(b_k)
    thetas = np.array([np.linalg.solve(A - Ak, b - bk)
                       for Ak, bk in zip(A_k, b_k, strict=True)])
    Wr, yr = W.reshape(m, n, P), y.reshape(m, n)
    e = np.concatenate([yr[a:c] - Wr[a:c] @ th
                        for (a, c), th in zip(spans, thetas, strict=True)])
    d = thetas - thetas.mean(axis=0)
    CJ = (blocks - 1) / blocks * (d.T @ d)
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    w = np.maximum(w, 1e-15 * max(float(w.max()), 1e-300))
    return (float(np.trace((V.T @ CJ @ V) / w[:, None]) / P),
            np.sqrt(np.mean(e * e, axis=0)))


def correlation_lag(r, level: float = 0.1) -> int:
    """Return the lag [samples] where the residuals' autocorrelation first falls below ``level``.

    Parameters
    ----------
    r : ndarray, shape (m, n)
        Residuals [N m] of consecutive samples, per joint.
    level : float, default 0.1
        Of the autocorrelation averaged over joints (each joint's by FFT, zero-padded).

    Returns
    -------
    int
        At least 1, at most ``m // 4``.
    """
    m = len(r)
    x = r - r.mean(axis=0)
    f = np.fft.rfft(x, n=2 * m, axis=0)
    acf = np.fft.irfft(f * np.conj(f), axis=0)[:m]
    acf = (acf / np.where(acf[0] > 0.0, acf[0], 1.0)).mean(axis=1)
    below = np.flatnonzero(acf[1:m // 4 + 1] < level)
    return int(below[0] + 1) if below.size else max(m // 4, 1)


def written_distance(d, cov, cov_noise, W, n: int, joints) -> dict:
    """Measure how far the arm written lies from the estimate.

    In calibrated and noise-only standard deviations, and as the RMS torque change it makes
    over the fitted samples.

    Parameters
    ----------
    d : ndarray, shape (p,)
        Base parameters written minus estimated.
    cov, cov_noise : ndarray, shape (p, p)
        The record's covariance and the white-noise one.
    W : ndarray, shape (m n, p)
        The (unweighted) base regressor of the fitted samples.
    n : int
        Joints.
    joints : sequence of str, shape (n,)

    Returns
    -------
    dict
        ``mahalanobis`` (``sqrt(d^T cov^-1 d)``), ``mahalanobis_noise`` (the same with
        ``cov_noise``), ``rms_Nm`` per joint and ``rms_Nm_all`` [N m].
    """
    def mahal(c):
        w, V = np.linalg.eigh(0.5 * (c + c.T))
        w = np.maximum(w, 1e-15 * max(float(w.max()), 1e-300))
        z = V.T @ d
        return float(np.sqrt(np.sum(z * z / w)))

    t = (W @ d).reshape(-1, n)
    return {"mahalanobis": mahal(cov), "mahalanobis_noise": mahal(cov_noise),
            "rms_Nm": {j: float(v) for j, v in zip(joints, np.sqrt(np.mean(t * t, axis=0)),
                                                   strict=True)},
            "rms_Nm_all": float(np.sqrt(np.mean(t * t)))}


def _clipped(fr, ar) -> list[dict]:
    """Return the negative friction and armature estimates written as 0 (joint, value, std)."""
    out = []
    for j, v in (fr or {}).items():
        for k, unit in (("viscous_Nms_rad", "N m s/rad"), ("coulomb_Nm", "N m")):
            if v[k] < 0.0:
                out.append({"joint": j, "parameter": k.split("_")[0], "value": v[k],
                            "std": v["std"][k], "unit": unit})
    for j, v in (ar or {}).items():
        if v["value_kg_m2"] < 0.0:
            out.append({"joint": j, "parameter": "armature", "value": v["value_kg_m2"],
                        "std": v["std"], "unit": "kg m^2"})
    return out


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



"""Measured logs: a CSV or per-quantity text files, derivatives by a zero-phase filter.

Irregular time stamps are resampled for the filter and the derivatives interpolated back;
velocities given are kept, accelerations (and missing velocities) are derived
(:func:`estimate_derivatives`); the torques get the same filter (:func:`filter_like`).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...validation import FieldError
from .regressors import IdentificationError

__all__ = [
    "Measurements",
    "read_measurements",
    "read_split_log",
    "write_measurements",
    "estimate_derivatives",
    "filter_like",
    "check_in_limits",
]



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



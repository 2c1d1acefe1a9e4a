"""What a simulation produces and how it fails: the leaf module both engines share.

:class:`Trajectory` (the result), :class:`SimulationDiverged` and the divergence test
(:func:`diverged_joint`, :data:`VELOCITY_LIMIT`: one definition for the Python and the compiled
engines), and :class:`Run`, a validated run that :func:`rrr_pin.sim.simulation.simulate` hands
to an engine; :meth:`Trajectory.save` and :meth:`Trajectory.load` write and read a trajectory
as CSV, NPZ, Parquet or MATLAB ``.mat`` (:data:`FORMATS`). Imports nothing of rrr_pin.
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = [
    "Trajectory",
    "RunFigures",
    "tracking_figures",
    "tracking_figures_batch",
    "SimulationDiverged",
    "Run",
    "metrics",
    "diverged_joint",
    "divergence",
    "law_divergence",
    "first_bad_torque",
    "make_trajectory",
    "saturation",
    "VELOCITY_LIMIT",
    "REASONS",
    "FORMATS",
    "TrajectoryFileError",
]

#: A joint speed above this [rad/s] is taken as a blow-up of the simulation.
VELOCITY_LIMIT = 1e4

#: Why a run diverged, by the code both engines use (0, 1, 2), in :func:`divergence`'s words;
#: code 3: the law returned a NaN or inf torque (:func:`law_divergence`), which stops the run
#: at the step where it happened, whatever it would have done to the state.
REASONS = ("became NaN or infinite", f"exceeded {VELOCITY_LIMIT:g} rad/s (blow-up)",
           "left its joint limits", "got a non-finite torque (NaN or inf) from the law")

#: Index in :data:`REASONS` of a law's non-finite torque (``kLawTorque`` of _ext/terms.hpp).
LAW_TORQUE = 3

class SimulationDiverged(RuntimeError):
    """The simulated closed loop blew up; the message names the time [s] and the joint."""

    def __init__(self, message: str, time: float, joint: str):
        super().__init__(message)
        self.time = time
        self.joint = joint

    def __reduce__(self):
        return (type(self), (str(self), self.time, self.joint))


@dataclass
class Trajectory:
    """A simulated closed-loop run, sampled on the integration (or control) grid.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Times [s].
    q, qd : ndarray, shape (N, n)
        Joint positions [rad] and velocities [rad/s].
    r : ndarray, shape (N, n)
        Reference positions [rad].
    tau : ndarray, shape (N, n)
        Applied torques [N m] (for sampled laws: the torque held from ``t[k]`` on).
    controller, plant : str
        The law's name and the plant's name.
    info : dict
        ``engine`` ("python", "compiled" or "codegen"), integration settings.
    joint_names : list of str
        Names of the n joints, base to tip (empty for a trajectory built by hand without them).
    joint_units : list of str
        Unit of each joint's position: ``"rad"`` (revolute) or ``"m"`` (prismatic, whose
        velocity is in m/s and force in N); empty means every joint is revolute.
    """

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    r: np.ndarray
    tau: np.ndarray
    controller: str = ""
    plant: str = ""
    info: dict = field(default_factory=dict)
    joint_names: list = field(default_factory=list)
    joint_units: list = field(default_factory=list)

    def __repr__(self) -> str:
        """One-line summary (the arrays' sizes, not their values), as the HTML repr shows."""
        t, q = np.asarray(self.t), np.asarray(self.q)
        n = q.shape[1] if q.ndim == 2 else 0
        span = f"{t[-1] - t[0]:.6g} s" if t.size else "empty"
        parts = [f"plant={self.plant!r}", f"controller={self.controller!r}",
                 f"{t.size} samples over {span}", f"{n} joints"]
        if self.info.get("engine"):
            parts.append(f"engine={self.info['engine']!r}")
        if t.size and np.shape(self.r) == q.shape:
            e = np.abs(np.asarray(self.r) - q)
            parts.append(f"max |error| {np.max(e):.4g}" if np.isfinite(e).all()
                         else "non-finite values")
        return f"Trajectory({', '.join(parts)})"

    def _repr_html_(self) -> str:
        """Summary table for notebooks: plant, law, duration, rate, engine, RMS error, status."""
        import html

        e, tau = self.error, self.tau
        finite = bool(np.isfinite(self.q).all() and np.isfinite(tau).all())
        rate = self.info.get("rate_hz")
        rows = [("plant", self.plant), ("law", self.controller),
                ("duration [s]", f"{self.t[-1] - self.t[0]:.6g} ({len(self.t)} samples)"),
                ("rate [Hz]", f"{rate:g} (sampled law)" if rate else "continuous-time law"),
                ("engine", self.info.get("engine", "")),
                ("RMS error per joint [rad]", ", ".join(
                    f"{v:.4g}" for v in np.sqrt(np.mean(e * e, axis=0)))),
                ("max |error| [rad]", f"{np.max(np.abs(e)):.4g}"),
                ("peak |torque| [N m]", f"{np.max(np.abs(tau)):.4g}"),
                ("status", "ran" if finite else "non-finite values")]
        body = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(str(v))}</td></tr>"
                       for k, v in rows)
        return f"<table><caption>Trajectory</caption>{body}</table>"

    @property
    def error(self) -> np.ndarray:
        """Tracking error ``e = r - q`` [rad], shape (N, n)."""
        return self.r - self.q

    def figures(self, joint_names=None) -> dict:
        """Scalar figures of the run (:func:`tracking_figures`; default its own joint names)."""
        names = self.joint_names if joint_names is None else joint_names
        return tracking_figures(self.error, self.tau, names, self.info)

    def save(self, path) -> Path:
        """Write the time series and their metadata to ``path``; the suffix picks the format.

        Units are SI and written with the data: ``t`` [s], ``q`` and ``r`` [rad], ``qd``
        [rad/s], ``tau`` [N m] (for a prismatic joint m, m/s and N). Every format holds the
        same metadata, ``{"format": "rrr-pin trajectory", "version": 1, "controller",
        "plant", "joint_names", "joint_units", "units", "info"}`` (``units`` maps each array
        to its unit per joint), and the arrays bit for bit:

        * ``.csv``: a preamble of ``# key: value`` lines, each value JSON (one line per
          metadata key), then one header row ``t [s],q_<joint> [rad],...,qd_<joint> [rad/s],
          ...,r_<joint> [rad],...,tau_<joint> [N m]`` and one row per sample. Floats are
          written with :func:`repr`, the shortest text that reads back to the same float64,
          so the round trip is exact.
        * ``.npz``: arrays ``t, q, qd, r, tau`` and ``metadata``, the JSON text (read with
          ``numpy.load(path)``; no pickle).
        * ``.parquet``: one column per CSV header entry (pyarrow), the JSON text in the
          schema metadata under ``b"rrr_pin"`` and each column's unit in its field metadata
          under ``b"unit"``.
        * ``.mat``: MATLAB variables ``t`` (N x 1), ``q, qd, r, tau`` (N x n) and ``metadata``,
          the JSON text (``jsondecode(metadata)`` in MATLAB), written by
          :func:`scipy.io.savemat` (MAT 5, compressed).

        ``info`` is stored as JSON: tuples come back as lists, NumPy scalars as numbers.

        Parameters
        ----------
        path : str or path-like
            File to write (its folder must exist); suffix one of :data:`FORMATS`.

        Returns
        -------
        Path
            The file written.

        Raises
        ------
        ValueError
            An unknown suffix (the message names the allowed ones).
        """
        path = Path(path)
        fmt = _format_of(path)
        meta = _metadata(self)
        if fmt == ".csv":
            _write_csv(path, self, meta)
        elif fmt == ".npz":
            with open(path, "wb") as f:  # a file object: numpy would append .npz to a name
                np.savez(f, t=self.t, q=self.q, qd=self.qd, r=self.r, tau=self.tau,
                         metadata=np.array(json.dumps(meta)))
        elif fmt == ".mat":
            import scipy.io

            scipy.io.savemat(path, {"t": np.asarray(self.t, dtype=float), **{
                k: np.asarray(getattr(self, k), dtype=float) for k in _ARRAYS},
                "metadata": json.dumps(meta)}, oned_as="column", do_compression=True)
        else:
            _write_parquet(path, self, meta)
        return path

    @classmethod
    def load(cls, path) -> Trajectory:
        """Read a trajectory written by :meth:`save` (format from the suffix).

        Parameters
        ----------
        path : str or path-like
            A ``.csv``, ``.npz``, ``.parquet`` or ``.mat`` file written by :meth:`save`.

        Returns
        -------
        Trajectory
            Arrays of shape ``(N,)`` and ``(N, n)``, metadata as saved.

        Raises
        ------
        ValueError
            An unknown suffix.
        TrajectoryFileError (a ValueError)
            The file is not an rrr-pin trajectory (a folder, a CSV that is not UTF-8 text, an
            NPZ or Parquet file that is truncated or not of that format, no metadata, another
            format or version, columns that do not match the joints, a NaN or inf in ``q``,
            ``qd``, ``r`` or ``tau``), or its times ``t`` are not finite and strictly
            increasing (time running backwards, rows out of order or repeated), naming the file
            and what is wrong.
        FileNotFoundError
            No such file.
        """
        path = Path(path)
        fmt = _format_of(path)
        if path.is_dir():
            raise TrajectoryFileError(f"{path}: is a directory, expected a trajectory file "
                                      f"written by Trajectory.save")
        if not path.is_file():
            raise FileNotFoundError(f"trajectory file not found: {path}")
        if fmt == ".csv":
            meta, columns = _read_csv(path)
        elif fmt in (".npz", ".mat"):
            meta, arrays = (_read_npz if fmt == ".npz" else _read_mat)(path)
            n = len(meta["joint_names"]) or (arrays["q"].shape[1] if "q" in arrays else 0)
            return _trajectory(path, meta, arrays, n)
        else:
            meta, columns = _read_parquet(path)
        n = len(meta["joint_names"]) or (columns.shape[1] - 1) // 4
        if columns.ndim != 2 or columns.shape[1] != 1 + 4 * n:
            raise TrajectoryFileError(f"{path}: {columns.shape[-1]} columns, expected 1 + 4 x "
                                      f"{n} (t, then q, qd, r, tau per joint)")
        arrays = {"t": columns[:, 0]}
        for k, key in enumerate(_ARRAYS):
            arrays[key] = columns[:, 1 + k * n:1 + (k + 1) * n]
        return _trajectory(path, meta, arrays, n)


def metrics(traj: Trajectory) -> dict:
    """Per-joint figures of a run, each a list of length n.

    Returns
    -------
    dict
        ``rms_error`` and ``max_error`` [rad] of ``e = r - q``; ``rms_torque`` and
        ``peak_torque`` [N m] of ``tau``. RMS over the samples of the run. A run with a
        torque limit (``info["saturation"]``, :func:`saturation`) also has
        ``saturated_fraction``, per joint the fraction [-] of its control periods at the limit;
        a plant that records its loop drift (a closed chain) ``drift_m`` [m], the largest loop
        gap a step left.
    """
    e, tau = traj.error, traj.tau
    out = {
        "rms_error": np.sqrt(np.mean(e * e, axis=0)).tolist(),
        "max_error": np.max(np.abs(e), axis=0).tolist(),
        "rms_torque": np.sqrt(np.mean(tau * tau, axis=0)).tolist(),
        "peak_torque": np.max(np.abs(tau), axis=0).tolist(),
    }
    if "saturation" in traj.info:
        out["saturated_fraction"] = list(traj.info["saturation"]["per_joint_fraction"])
    if "drift_m" in traj.info:  # a plant that records its loop drift (a closed chain)
        out["drift_m"] = float(traj.info["drift_m"])
    return out


def tracking_figures(e, tau, joint_names, info=None) -> dict:
    """Return the scalar figures of a run that a campaign's row holds (one definition).

    Parameters
    ----------
    e : ndarray, shape (N, n)
        Tracking error ``r - q`` [rad], C-contiguous.
    tau : ndarray, shape (N, n)
        Applied torques [N m].
    joint_names : sequence of str, length n
    info : dict, optional
        The run's ``info``; its ``drift_m`` (a closed chain's loop drift) gives ``drift`` [m].

    Returns
    -------
    dict
        ``rms_error``, ``max_error`` [rad], ``rms_torque`` [N m] (over all joints and samples),
        ``drift`` [m] when recorded, and ``rms_error_<joint>`` [rad] per joint, in that order.
    """
    e2 = e * e
    out = {"rms_error": float(np.sqrt(np.mean(e2))),
           "max_error": float(np.max(np.abs(e))),
           "rms_torque": float(np.sqrt(np.mean(tau * tau)))}
    if info is not None and "drift_m" in info:
        out["drift"] = float(info["drift_m"])
    for name, v in zip(joint_names, np.sqrt(np.mean(e2, axis=0)), strict=True):
        out[f"rms_error_{name}"] = float(v)
    return out


def tracking_figures_batch(E, TAU, joint_names) -> list[dict]:
    """Return :func:`tracking_figures` of B runs at once: the same numbers, bit for bit.

    Each reduction runs over one run's own block in the same order as for that run alone
    (numpy's pairwise sum over a contiguous row; a sequential sum over the samples per joint),
    so a run's figures do not depend on the batch (``tests/test_batched.py`` compares).

    Parameters
    ----------
    E : ndarray, shape (B, N, n)
        Tracking errors ``r - q`` [rad], C-contiguous.
    TAU : ndarray, shape (B, N, n)
        Applied torques [N m], C-contiguous.
    joint_names : sequence of B sequences of str, each of length n
        Each run's joint names.

    Returns
    -------
    list of dict
        Per run, :func:`tracking_figures` (no ``drift``: a batch holds serial arms).
    """
    B = E.shape[0]
    E2 = E * E
    rms = np.sqrt(np.mean(E2.reshape(B, -1), axis=1))
    peak = np.max(np.abs(E).reshape(B, -1), axis=1)
    torque = np.sqrt(np.mean((TAU * TAU).reshape(B, -1), axis=1))
    per_joint = np.sqrt(np.mean(E2, axis=1))
    out = []
    for b, names in zip(range(B), joint_names, strict=True):
        row = {"rms_error": float(rms[b]), "max_error": float(peak[b]),
               "rms_torque": float(torque[b])}
        row.update(zip((f"rms_error_{name}" for name in names), per_joint[b].tolist(),
                       strict=True))
        out.append(row)
    return out


@dataclass(frozen=True)
class RunFigures:
    """A finished run reduced to its figures, without its time series.

    What a campaign's batched runs return (:func:`rrr_pin.sim.batched.run_batch` with
    ``figures=True``) when no trajectory is asked for: the numbers
    :meth:`Trajectory.figures` gives for the same run, bit for bit (the same arrays reduced
    by :func:`tracking_figures`).

    Attributes
    ----------
    controller, plant : str
        The law's name and the plant's name.
    values : dict
        :func:`tracking_figures` keyed by the plant's joint names.
    info : dict
        As :attr:`Trajectory.info` (``engine``, integration settings).
    """

    controller: str
    plant: str
    values: dict
    info: dict = field(default_factory=dict)

    def figures(self, joint_names=None) -> dict:
        """:func:`tracking_figures` of the run (``joint_names``: rename the per-joint keys)."""
        if joint_names is None:
            return dict(self.values)
        per = [v for k, v in self.values.items() if k.startswith("rms_error_")]
        out = {k: v for k, v in self.values.items() if not k.startswith("rms_error_")}
        out.update({f"rms_error_{j}": v for j, v in zip(joint_names, per, strict=True)})
        return out


def diverged_joint(q, qd, lower, upper) -> tuple[int, str] | None:
    """Apply the divergence test of both engines: ``(joint index, reason)`` or None.

    Parameters
    ----------
    q, qd : ndarray, shape (n,)
        State [rad, rad/s].
    lower, upper : ndarray, shape (n,)
        Joint limits widened by the run's ``limit_margin`` [rad].
    """
    bad = ~np.isfinite(q) | ~np.isfinite(qd)
    if bad.any():
        return int(np.flatnonzero(bad)[0]), REASONS[0]
    bad = np.abs(qd) > VELOCITY_LIMIT
    if bad.any():
        return int(np.flatnonzero(bad)[0]), REASONS[1]
    bad = (q < lower) | (q > upper)
    if bad.any():
        return int(np.flatnonzero(bad)[0]), REASONS[2]
    return None


def divergence(plant, t: float, q, qd, j: int, reason: str) -> SimulationDiverged:
    """Build the :class:`SimulationDiverged` of both engines: plant, time [s], joint, reason."""
    name = plant.joint_names[j]
    return SimulationDiverged(
        f"simulation of plant {plant.name!r} diverged at t = {t:.6g} s: joint {name!r} "
        f"{reason} (q = {q[j]:.6g} rad, qd = {qd[j]:.6g} rad/s)", time=t, joint=name)


def law_divergence(plant, law: str, t: float, j: int) -> SimulationDiverged:
    """Build the :class:`SimulationDiverged` of both engines for a law's NaN or inf torque.

    Parameters
    ----------
    plant : Robot
    law : str
        The law's name.
    t : float
        Start of the control period (sampled) or RK4 step (continuous) in which the law
        returned the torque [s].
    j : int
        First joint whose torque is not finite.
    """
    name = plant.joint_names[j]
    return SimulationDiverged(
        f"simulation of plant {plant.name!r} stopped at t = {t:.6g} s: law {law!r} returned a "
        f"non-finite torque (NaN or inf) for joint {name!r} in the step from t = {t:.6g} s",
        time=t, joint=name)


def first_bad_torque(tau) -> tuple[int, int] | None:
    """``(row, joint)`` of the first non-finite entry of torques ``tau`` (shape (N, n)), or None."""
    bad = ~np.isfinite(tau)
    if not bad.any():
        return None
    k, j = np.argwhere(bad)[0]
    return int(k), int(j)


@dataclass(frozen=True)
class Run:
    """A validated run: everything an engine needs, nothing left to check."""

    plant: object
    law: object          # ControlLaw (continuous) or SampledLaw
    sampled: bool
    t: np.ndarray        # output grid, shape (N+1,)
    R: np.ndarray        # reference on the law-evaluation grid
    RD: np.ndarray
    RDD: np.ndarray
    q0: np.ndarray
    qd0: np.ndarray
    x0: np.ndarray
    h: float             # RK4 step [s]
    substeps: int        # RK4 steps per control period (1 for continuous laws)
    lower: np.ndarray
    upper: np.ndarray
    info: dict
    effects: object = None  # rrr_pin.control.effects.Resolved, or None for the ideal plant
    state0: tuple = None  # the plant's full initial state (plant.start(q0, qd0))

    @property
    def grid(self) -> np.ndarray:
        """Times [s] of the rows of ``R``: ``t`` (sampled) or its half-step grid (continuous)."""
        return self.t if self.sampled else 0.5 * self.h * np.arange(len(self.R))


def make_trajectory(run: Run, Q, QD, TAU) -> Trajectory:
    """Build the :class:`Trajectory` of a finished run (states, torques of shape (N+1, n))."""
    R = run.R if run.sampled else run.R[::2]
    plant = run.plant
    info = dict(run.info)
    fx = run.effects
    if fx is not None and fx.limit is not None:
        info["saturation"] = saturation(TAU[:-1], fx.limit, float(run.t[1] - run.t[0]))
    return Trajectory(t=run.t, q=Q, qd=QD, r=R, tau=TAU, controller=run.law.name,
                      plant=plant.name, info=info,
                      joint_names=list(plant.joint_names), joint_units=plant.joint_units)


def saturation(tau, limit, Ts: float) -> dict:
    """Time a sampled run spent at its torque limit (``Trajectory.info["saturation"]``).

    A control period counts as saturated for joint ``j`` when the torque applied over it is at
    the limit, ``|tau_j| >= tau_max_j`` (after the plant's clip, that is where the clip acted,
    or where the law itself asked for the limit exactly, as a law that knows the limits does).

    Parameters
    ----------
    tau : ndarray, shape (N, n)
        The torque applied over each of the N control periods [N m].
    limit : ndarray, shape (n,)
        ``tau_max`` [N m].
    Ts : float
        Control period [s].

    Returns
    -------
    dict
        ``fraction`` [-]: of the N periods, those where any joint is at its limit;
        ``seconds`` [s]: ``fraction N Ts``; ``per_joint_fraction`` [-], length n.
    """
    at = np.abs(tau) >= limit
    anyj = at.any(axis=1)
    return {"fraction": float(anyj.mean()), "seconds": float(anyj.sum() * Ts),
            "per_joint_fraction": at.mean(axis=0).tolist(),
            "limit_Nm": np.asarray(limit, dtype=float).tolist()}


# --- files: Trajectory.save / Trajectory.load -------------------------------------------------

#: Suffixes :meth:`Trajectory.save` and :meth:`Trajectory.load` accept.
FORMATS = (".csv", ".npz", ".parquet", ".mat")

#: The joint-space arrays, in file order (after ``t``).
_ARRAYS = ("q", "qd", "r", "tau")

_MAGIC, _VERSION = "rrr-pin trajectory", 1


class TrajectoryFileError(ValueError):
    """A file that :meth:`Trajectory.load` cannot read as a trajectory (the reason is given)."""


def _format_of(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(f"{path}: unknown trajectory format {path.suffix or '(no suffix)'!r}; "
                         f"use one of {', '.join(FORMATS)}")
    return suffix


def _units(traj: Trajectory, n: int) -> dict:
    pos = list(traj.joint_units) or ["rad"] * n
    return {"t": "s", "q": pos, "qd": [f"{u}/s" for u in pos], "r": pos,
            "tau": ["N" if u == "m" else "N m" for u in pos]}


def _json_ready(value):
    if isinstance(value, dict):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    if isinstance(value, np.ndarray):
        return _json_ready(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value


def _metadata(traj: Trajectory) -> dict:
    n = np.shape(traj.q)[1] if np.ndim(traj.q) == 2 else 0
    return {"format": _MAGIC, "version": _VERSION, "controller": traj.controller,
            "plant": traj.plant, "joint_names": list(traj.joint_names),
            "joint_units": list(traj.joint_units), "units": _units(traj, n),
            "info": _json_ready(traj.info)}


def _columns(traj: Trajectory, meta: dict) -> tuple[list[str], list[str], np.ndarray]:
    """Column names (with units), units, and the (N, 1 + 4 n) table of a trajectory."""
    q = np.asarray(traj.q, dtype=float)
    n = q.shape[1]
    joints = list(traj.joint_names) or [str(j + 1) for j in range(n)]
    names, units = ["t [s]"], ["s"]
    for key in _ARRAYS:
        for joint, unit in zip(joints, meta["units"][key], strict=True):
            names.append(f"{key}_{joint} [{unit}]")
            units.append(unit)
    table = np.column_stack([np.asarray(traj.t, dtype=float)]
                            + [np.asarray(getattr(traj, k), dtype=float) for k in _ARRAYS])
    return names, units, table


def _write_csv(path: Path, traj: Trajectory, meta: dict) -> None:
    names, _, table = _columns(traj, meta)
    with open(path, "w", newline="") as f:
        for key, value in meta.items():
            f.write(f"# {key}: {json.dumps(value)}\n")
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(names)
        for row in table.tolist():
            f.write(",".join(map(repr, row)) + "\n")


def _read_csv(path: Path) -> tuple[dict, np.ndarray]:
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise TrajectoryFileError(f"{path}: not a UTF-8 text file (byte {exc.start}: "
                                  f"{exc.reason}); a .csv trajectory is the text that "
                                  f"Trajectory.save writes") from None
    lines = text.splitlines()
    meta, k = {}, 0
    while k < len(lines) and lines[k].startswith("#"):
        key, sep, value = lines[k][1:].strip().partition(":")
        if sep:
            try:
                meta[key.strip()] = json.loads(value)
            except json.JSONDecodeError:
                raise TrajectoryFileError(f"{path}, line {k + 1}: metadata {key.strip()!r} is "
                                          f"not JSON: {value.strip()!r}") from None
        k += 1
    meta = _check_metadata(path, meta)
    if k >= len(lines):
        raise TrajectoryFileError(f"{path}: no header row after the metadata")
    header = next(csv.reader([lines[k]]))
    body = lines[k + 1:]
    if not body:
        return meta, np.empty((0, len(header)))
    for i, line in enumerate(body):
        if line.count(",") != len(header) - 1:
            raise TrajectoryFileError(
                f"{path}, line {k + 2 + i}: {line.count(',') + 1} values, the header has "
                f"{len(header)} (a truncated or edited file?)")
    try:
        table = np.loadtxt(io.StringIO("\n".join(body)), delimiter=",", ndmin=2)
    except ValueError as exc:
        raise TrajectoryFileError(f"{path}: the rows after the header are not numbers "
                                  f"({exc})") from None
    if table.shape[1] != len(header):
        raise TrajectoryFileError(f"{path}: {table.shape[1]} values per row, header has "
                                  f"{len(header)}")
    return meta, table


def _read_npz(path: Path) -> tuple[dict, dict]:
    """Metadata and arrays of an ``.npz`` trajectory; a damaged archive named as such."""
    import zipfile
    import zlib

    with open(path, "rb") as f:
        if f.read(4) != b"PK\x03\x04":
            raise TrajectoryFileError(f"{path}: not an .npz archive (no zip signature at its "
                                      f"start); write it with Trajectory.save")
    try:
        with np.load(path, allow_pickle=False) as data:
            if "metadata" not in data.files:
                raise TrajectoryFileError(f"{path}: no 'metadata' entry; not written by "
                                          f"Trajectory.save")
            meta = _check_metadata(path, data["metadata"].item())
            arrays = {k: np.array(data[k]) for k in ("t",) + _ARRAYS if k in data.files}
    except TrajectoryFileError:
        raise
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError, ValueError) as exc:
        # A truncated or damaged archive fails in zipfile (BadZipFile, EOFError, zlib.error),
        # a damaged member in numpy's header parser (ValueError, OSError).
        raise TrajectoryFileError(f"{path}: a truncated or damaged .npz archive "
                                  f"({type(exc).__name__}: {exc})") from None
    return meta, arrays


def _read_mat(path: Path) -> tuple[dict, dict]:
    """Metadata and arrays of a ``.mat`` trajectory (``t`` back to shape (N,))."""
    import zlib

    import scipy.io

    try:
        data = scipy.io.loadmat(path)
    except (ValueError, OSError, EOFError, zlib.error, TypeError) as exc:
        # scipy.io names a foreign file in ValueError ("Unknown mat file type", "Mat 4 mopt
        # wrong format") and a truncated one in OSError ("could not read bytes").
        raise TrajectoryFileError(f"{path}: not a readable MAT file (truncated, damaged or "
                                  f"of another format: {type(exc).__name__}: {exc})") from None
    if "metadata" not in data or np.size(data["metadata"]) != 1:
        raise TrajectoryFileError(f"{path}: no 'metadata' variable; not written by "
                                  f"Trajectory.save")
    meta = _check_metadata(path, str(np.ravel(data["metadata"])[0]))
    arrays = {k: np.array(data[k], dtype=float) for k in ("t",) + _ARRAYS if k in data}
    if "t" in arrays:
        t = arrays["t"]
        arrays["t"] = t.reshape(-1) if t.ndim == 2 and 1 in t.shape else t
    return meta, arrays


def _write_parquet(path: Path, traj: Trajectory, meta: dict) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    names, units, table = _columns(traj, meta)
    fields = [pa.field(name, pa.float64(), metadata={b"unit": unit.encode()})
              for name, unit in zip(names, units, strict=True)]
    schema = pa.schema(fields, metadata={b"rrr_pin": json.dumps(meta).encode()})
    arrays = [pa.array(np.ascontiguousarray(table[:, j])) for j in range(table.shape[1])]
    pq.write_table(pa.Table.from_arrays(arrays, schema=schema), path)


def _read_parquet(path: Path) -> tuple[dict, np.ndarray]:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as exc:
        raise TrajectoryFileError(f"{path}: not a readable Parquet file (truncated, damaged "
                                  f"or of another format: {exc})") from None
    raw = (table.schema.metadata or {}).get(b"rrr_pin")
    if raw is None:
        raise TrajectoryFileError(f"{path}: no b'rrr_pin' schema metadata; not written by "
                                  f"Trajectory.save")
    meta = _check_metadata(path, raw.decode())
    columns = np.column_stack([table.column(j).to_numpy() for j in range(table.num_columns)]
                              ) if table.num_columns else np.empty((0, 0))
    return meta, np.asarray(columns, dtype=float)


def _check_metadata(path: Path, meta) -> dict:
    if isinstance(meta, str):
        try:
            meta = json.loads(meta)
        except json.JSONDecodeError as exc:
            raise TrajectoryFileError(f"{path}: metadata is not JSON ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != _MAGIC:
        raise TrajectoryFileError(f"{path}: not an rrr-pin trajectory (no metadata "
                                  f"'format: \"{_MAGIC}\"'); write it with Trajectory.save")
    if meta.get("version") != _VERSION:
        raise TrajectoryFileError(f"{path}: trajectory file version {meta.get('version')!r}; "
                                  f"this rrr-pin reads version {_VERSION}")
    return meta


def _trajectory(path: Path, meta: dict, arrays: dict, n: int) -> Trajectory:
    missing = [k for k in ("t",) + _ARRAYS if k not in arrays]
    if missing:
        raise TrajectoryFileError(f"{path}: arrays {missing} missing")
    t = arrays["t"]
    if t.ndim != 1:
        raise TrajectoryFileError(f"{path}: t has shape {t.shape}, expected (N,)")
    N = t.shape[0]
    if not np.isfinite(t).all():
        k = int(np.flatnonzero(~np.isfinite(t))[0])
        raise TrajectoryFileError(f"{path}: t[{k}] = {float(t[k])!r} s is not finite")
    step = np.diff(t)
    if (step <= 0).any():
        k = int(np.flatnonzero(step <= 0)[0])
        why = ("repeats" if step[k] == 0 else
               "runs backwards" if (step < 0).all() else
               "decreases (rows out of order?)")
        raise TrajectoryFileError(
            f"{path}: time t {why} at rows {k} and {k + 1} (t = {float(t[k])!r} s then "
            f"{float(t[k + 1])!r} s); a trajectory's t is strictly increasing")
    for key in _ARRAYS:
        if arrays[key].shape != (N, n):
            raise TrajectoryFileError(f"{path}: {key} has shape {arrays[key].shape}, expected "
                                      f"({N}, {n})")
        bad = ~np.isfinite(arrays[key])
        if bad.any():  # a run that diverged raises, so no saved run holds NaN or inf
            k, j = (int(i) for i in np.argwhere(bad)[0])
            raise TrajectoryFileError(f"{path}: {key}[{k}, {j}] = {float(arrays[key][k, j])!r} "
                                      f"is not finite (t = {float(t[k])!r} s); a saved run "
                                      f"holds finite q, qd, r and tau")
    return Trajectory(**arrays, controller=meta.get("controller", ""),
                      plant=meta.get("plant", ""), info=meta.get("info", {}),
                      joint_names=list(meta.get("joint_names", [])),
                      joint_units=list(meta.get("joint_units", [])))

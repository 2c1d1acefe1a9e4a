r"""Joint references: what a tracking law is asked to follow.

A reference gives, at any time ``t`` [s], the joint position ``r`` [rad], velocity ``rd``
[rad/s] and acceleration ``rdd`` [rad/s^2], each shape ``(n,)``. Every reference is a
:class:`Reference`; the built-ins are

* :class:`SineReference`: ``r = home + amp sin(2 pi f t + phase)`` per joint (the study's);
* :class:`QuinticReference`: rest-to-rest point-to-point motion with a quintic time law;
* :class:`SplineReference`: a C2 cubic spline through waypoints, e.g. read from a CSV file
  (:meth:`SplineReference.from_csv`);
* :func:`task_space_reference`: a straight line or a circle of a frame's origin in task space,
  turned into a joint spline by Pinocchio inverse kinematics (damped least squares) and checked by
  forward kinematics.

Write your own by subclassing :class:`Reference` and implementing :meth:`Reference.__call__`
(and, for speed, the vectorized :meth:`Reference.sample`). Both simulation engines evaluate a
reference only through :meth:`Reference.sample` on the grid of times where the law is evaluated,
so any reference runs on both, with equal values.

Before the end of the motion (``t > duration`` where a reference has one), a finite reference
holds its last point at rest.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..validation import FieldError, check_direction, check_positive, check_vector, describe_value

__all__ = [
    "default_reference",
    "study_reference",
    "Reference",
    "SineReference",
    "QuinticReference",
    "SplineReference",
    "LinePath",
    "CirclePath",
    "task_space_reference",
    "TaskSpaceReference",
    "IKError",
    "check_reference",
    "checked_sample",
]


class IKError(ValueError):
    """Inverse kinematics did not converge; the message names the path point and residual."""


class Reference:
    """Base class of a joint reference.

    Subclasses implement :meth:`__call__`; :meth:`sample` (vectorized over a time grid),
    :attr:`duration` and :meth:`to_dict` may be overridden.

    Attributes
    ----------
    n : int
        Number of joints.
    """

    n: int = 0

    #: End of the motion [s] (the reference is at rest after it), or None for an endless one.
    duration: float | None = None

    def __call__(self, t: float):
        """Return ``(r, rd, rdd)`` at time ``t`` [s], each shape (n,) [rad, rad/s, rad/s^2]."""
        raise NotImplementedError

    def sample(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Evaluate on a time grid.

        Parameters
        ----------
        t : array-like, shape (N,)
            Times [s].

        Returns
        -------
        R, RD, RDD : ndarray, shape (N, n)
            Position [rad], velocity [rad/s] and acceleration [rad/s^2].
        """
        t = np.asarray(t, dtype=float)
        out = []
        for tk in t:
            o = self(float(tk))
            if not (isinstance(o, tuple) and len(o) == 3
                    and all(np.shape(v) == (self.n,) for v in o)):
                raise ValueError(f"reference {type(self).__name__}: __call__({float(tk):g}) "
                                 f"returned {describe_value(o)}; expected a tuple (r, rd, rdd) "
                                 f"of 3 arrays of shape ({self.n},)")
            out.append(o)
        return tuple(np.array([o[i] for o in out], dtype=float).reshape(len(t), self.n)
                     for i in range(3))

    def positions(self, t) -> np.ndarray:
        """Positions ``r`` [rad] on a time grid ``t`` [s] of shape (N,); returns (N, n)."""
        return self.sample(t)[0]

    def check_limits(self, robot, duration: float | None = None, step: float = 1e-3) -> None:
        """Raise ``ValueError`` if the reference leaves ``robot``'s joint limits.

        Checked on a grid of ``step`` [s] over ``[0, duration]`` (default: the reference's own
        duration, or 10 s for an endless one); the message names the joint, time and value.
        """
        check_reference(self, robot)
        end = duration if duration is not None else (self.duration or 10.0)
        t = np.linspace(0.0, end, max(2, int(math.ceil(end / step)) + 1))
        R = checked_sample(self, t)[0]
        lower, upper = robot.lower, robot.upper
        bad = (R < lower) | (R > upper)  # finite: checked_sample refused NaN and inf
        if bad.any():
            k, j = np.argwhere(bad)[0]
            raise ValueError(
                f"reference leaves the limits of joint {robot.joint_names[j]!r} at t = "
                f"{t[k]:.4g} s: r = {R[k, j]:.6g} rad, limits [{lower[j]:.4g}, {upper[j]:.4g}]")

    def to_dict(self) -> dict:
        """JSON-ready description (``kind`` plus parameters, units in the key names)."""
        return {"kind": type(self).__name__}


def checked_sample(reference, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``reference.sample(t)`` as float arrays, checked: shape (N, n) each, finite.

    The edge where a reference (a user's own, or a built-in) meets the simulator: both
    engines and :meth:`Reference.check_limits` sample a reference through it.

    Parameters
    ----------
    reference : Reference
    t : ndarray, shape (N,)
        Times [s].

    Returns
    -------
    R, RD, RDD : ndarray, shape (N, n)
        Position [rad], velocity [rad/s] and acceleration [rad/s^2].

    Raises
    ------
    ValueError
        Naming the reference's class: ``sample`` returned something other than three arrays
        of shape (N, n), or a NaN or inf (with the quantity, the time and the joint).
    """
    t = np.asarray(t, dtype=float)
    name = type(reference).__name__
    out = reference.sample(t)
    want = (len(t), reference.n)
    if not (isinstance(out, tuple) and len(out) == 3):
        raise ValueError(f"reference {name}: sample() returned {describe_value(out)}; expected "
                         f"a tuple (R, RD, RDD) of 3 arrays of shape {want}")
    arrays = []
    for what, v in zip(("r", "rd", "rdd"), out, strict=True):
        try:
            v = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"reference {name}: sample() returned {describe_value(v)} for {what}; "
                             f"expected an array of numbers of shape {want}") from None
        if v.shape != want:
            raise ValueError(f"reference {name}: sample() returned {what} of shape {v.shape}, "
                             f"expected {want} (times x joints)")
        bad = ~np.isfinite(v)
        if bad.any():
            k, j = np.argwhere(bad)[0]
            raise ValueError(f"reference {name}: {what} is {float(v[k, j])!r} (not finite) at "
                             f"t = {t[k]:.6g} s for joint {j}")
        arrays.append(np.ascontiguousarray(v))
    return tuple(arrays)


def check_reference(reference, robot) -> None:
    """Check that ``reference`` is a :class:`Reference` with ``robot.nq`` joints."""
    if not isinstance(reference, Reference):
        raise TypeError(f"reference must be a rrr_pin Reference, got {type(reference).__name__}")
    if reference.n != robot.nq:
        raise ValueError(f"reference has {reference.n} joints, robot {robot.name!r} has "
                         f"{robot.nq}")


@dataclass(frozen=True)
class SineReference(Reference):
    """Sinusoidal joint reference ``r(t) = home + amp sin(2 pi freq t + phase)``.

    Parameters
    ----------
    home : array-like, shape (n,)
        Centre of the motion [rad].
    amp : array-like, shape (n,) or float
        Amplitude [rad], >= 0.
    freq : array-like, shape (n,) or float
        Frequency [Hz], >= 0.
    phase : array-like, shape (n,) or float
        Phase [rad].
    """

    home: np.ndarray
    amp: np.ndarray
    freq: np.ndarray
    phase: np.ndarray

    def __post_init__(self) -> None:
        home = check_vector("home", self.home, readonly=True)
        n = home.shape[0]
        object.__setattr__(self, "home", home)
        for name in ("amp", "freq", "phase"):
            v = np.asarray(getattr(self, name), dtype=float)
            v = check_vector(name, np.full(n, float(v)) if v.ndim == 0 else v, n, readonly=True)
            if name in ("amp", "freq") and np.any(v < 0.0):
                raise ValueError(f"{name} must be >= 0, got {v.tolist()}")
            object.__setattr__(self, name, v)

    @property
    def n(self) -> int:
        """Number of joints."""
        return self.home.shape[0]

    @property
    def omega(self) -> np.ndarray:
        """Angular frequencies ``2 pi freq`` [rad/s], shape (n,)."""
        return 2.0 * math.pi * self.freq

    def __call__(self, t: float):
        """Evaluate ``(r, rd, rdd)`` at time ``t`` [s], each shape (n,)."""
        w = self.omega
        arg = w * t + self.phase
        s, c = np.sin(arg), np.cos(arg)
        return self.home + self.amp * s, self.amp * w * c, -self.amp * w * w * s

    def sample(self, t):
        """Vectorized :meth:`Reference.sample`."""
        w = self.omega
        arg = np.outer(np.asarray(t, dtype=float), w) + self.phase
        s, c = np.sin(arg), np.cos(arg)
        return self.home + self.amp * s, self.amp * w * c, -self.amp * w * w * s

    def check_limits(self, robot, duration=None, step=1e-3) -> None:
        """Raise ``ValueError`` if ``home +- amp`` leaves the robot's joint limits."""
        check_reference(self, robot)
        lo, hi = self.home - self.amp, self.home + self.amp
        for j, name in enumerate(robot.joint_names):
            if lo[j] < robot.lower[j] or hi[j] > robot.upper[j]:
                raise ValueError(
                    f"reference for joint {name!r} spans [{lo[j]:.4g}, {hi[j]:.4g}] rad, "
                    f"outside its limits [{robot.lower[j]:.4g}, {robot.upper[j]:.4g}]")

    def to_dict(self) -> dict:
        """JSON-ready parameters (units in the key names)."""
        return {"kind": "sine", "home_rad": self.home.tolist(), "amp_rad": self.amp.tolist(),
                "freq_hz": self.freq.tolist(), "phase_rad": self.phase.tolist()}


def _quintic(s):
    """Quintic time law ``10 s^3 - 15 s^4 + 6 s^5`` and its first two derivatives in ``s``."""
    s = np.clip(s, 0.0, 1.0)
    return (s**3 * (10.0 - 15.0 * s + 6.0 * s * s), 30.0 * s * s * (1.0 - s) ** 2,
            60.0 * s * (1.0 - s) * (1.0 - 2.0 * s))


@dataclass(frozen=True)
class QuinticReference(Reference):
    r"""Rest-to-rest motion from ``start`` to ``goal`` in ``move_time`` seconds.

    .. math:: r(t) = q_0 + (q_1 - q_0)\,(10 s^3 - 15 s^4 + 6 s^5), \quad
              s = \mathrm{clip}(t / T, 0, 1)

    Zero velocity and acceleration at both ends; at rest on ``goal`` after ``move_time``.

    Parameters
    ----------
    start, goal : array-like, shape (n,)
        Initial and final joint positions [rad].
    move_time : float
        Duration ``T`` of the motion [s], > 0.
    """

    start: np.ndarray
    goal: np.ndarray
    move_time: float

    def __post_init__(self) -> None:
        start = check_vector("start", self.start, readonly=True)
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "goal", check_vector("goal", self.goal, start.shape[0],
                                                      readonly=True))
        object.__setattr__(self, "move_time", check_positive("move_time", self.move_time,
                                                             unit="s"))

    @property
    def n(self) -> int:
        """Number of joints."""
        return self.start.shape[0]

    @property
    def duration(self) -> float:
        """End of the motion [s]."""
        return self.move_time

    def __call__(self, t: float):
        """Evaluate ``(r, rd, rdd)`` at time ``t`` [s]."""
        R, RD, RDD = self.sample([t])
        return R[0], RD[0], RDD[0]

    def sample(self, t):
        """Vectorized :meth:`Reference.sample`."""
        T = self.move_time
        p, dp, ddp = _quintic(np.asarray(t, dtype=float) / T)
        d = self.goal - self.start
        return (self.start + np.outer(p, d), np.outer(dp / T, d), np.outer(ddp / (T * T), d))

    def to_dict(self) -> dict:
        """JSON-ready parameters."""
        return {"kind": "quintic", "start_rad": self.start.tolist(),
                "goal_rad": self.goal.tolist(), "move_time_s": self.move_time}


@dataclass(frozen=True, eq=False)
class SplineReference(Reference):
    """C2 cubic spline through joint waypoints, at rest at both ends.

    A clamped cubic spline (:class:`scipy.interpolate.CubicSpline`, ``bc_type="clamped"``):
    twice continuously differentiable, through every waypoint, zero velocity at the first and
    last waypoint; before the first time it holds the first point, after the last the last.

    Parameters
    ----------
    times : array-like, shape (K,)
        Strictly increasing waypoint times [s], ``K >= 2``, ``times[0] >= 0``.
    waypoints : array-like, shape (K, n)
        Joint positions [rad] at those times.
    source : str, optional
        Where the waypoints came from (a file name), for messages and records.
    """

    times: np.ndarray
    waypoints: np.ndarray
    source: str = ""
    _spline: object = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        from scipy.interpolate import CubicSpline

        t = np.asarray(self.times, dtype=float)
        W = np.asarray(self.waypoints, dtype=float)
        where = f" in {self.source}" if self.source else ""
        if t.ndim != 1 or t.shape[0] < 2:
            raise ValueError(f"times{where} must have shape (K,) with K >= 2, got {t.shape}")
        if W.ndim == 1:
            W = W[:, None]
        if W.ndim != 2 or W.shape[0] != t.shape[0]:
            raise ValueError(f"waypoints{where} must have shape ({t.shape[0]}, n), got {W.shape}")
        for name, arr in (("times", t), ("waypoints", W)):
            if not np.all(np.isfinite(arr)):
                k = int(np.argwhere(~np.isfinite(arr))[0][0])
                raise ValueError(f"{name}{where} must be finite: row {k} is {arr[k].tolist()}")
        if t[0] < 0.0:
            raise ValueError(f"times{where} must start at >= 0 s, got {t[0]:g}")
        steps = np.diff(t)
        if np.any(steps <= 0.0):
            k = int(np.flatnonzero(steps <= 0.0)[0])
            raise ValueError(f"times{where} must be strictly increasing: row {k + 1} has "
                             f"t = {t[k + 1]:g} s after t = {t[k]:g} s")
        t.setflags(write=False)
        W.setflags(write=False)
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "waypoints", W)
        object.__setattr__(self, "_spline", CubicSpline(t, W, bc_type="clamped", axis=0))

    @property
    def n(self) -> int:
        """Number of joints."""
        return self.waypoints.shape[1]

    @property
    def duration(self) -> float:
        """Time of the last waypoint [s]."""
        return float(self.times[-1])

    def __call__(self, t: float):
        """Evaluate ``(r, rd, rdd)`` at time ``t`` [s]."""
        R, RD, RDD = self.sample([t])
        return R[0], RD[0], RDD[0]

    def sample(self, t):
        """Vectorized :meth:`Reference.sample`."""
        t = np.asarray(t, dtype=float)
        tc = np.clip(t, self.times[0], self.times[-1])
        inside = ((t >= self.times[0]) & (t <= self.times[-1]))[:, None]
        sp = self._spline
        return sp(tc), np.where(inside, sp(tc, 1), 0.0), np.where(inside, sp(tc, 2), 0.0)

    @classmethod
    def from_csv(cls, path, robot=None) -> SplineReference:
        """Read waypoints from a CSV file: a column of time [s], then one per joint [rad].

        A first row that is not numeric is taken as a header. With ``robot``, the column count
        must be ``1 + robot.nq`` and every waypoint must lie inside the joint limits.

        Raises
        ------
        ValueError
            Unreadable numbers, the wrong column count, NaN, non-increasing times, or (with
            ``robot``) a waypoint outside the limits; the message names the file, row and
            column.
        """
        path = Path(path)
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as exc:
            raise ValueError(f"cannot read reference CSV {str(path)!r}: {exc}") from None
        rows = [r for r in csv.reader(text.splitlines()) if r and any(c.strip() for c in r)]
        if rows and not _numeric(rows[0][0]):
            rows = rows[1:]
        if len(rows) < 2:
            raise ValueError(f"reference CSV {str(path)!r} needs at least 2 rows of numbers")
        width = len(rows[0])
        expected = None if robot is None else 1 + robot.nq
        data = []
        for k, row in enumerate(rows):
            if len(row) != (expected or width):
                raise ValueError(
                    f"reference CSV {str(path)!r} row {k + 1}: {len(row)} columns, expected "
                    f"{expected or width} (time, then one per joint"
                    + (f" of {robot.name!r}" if robot is not None else "") + ")")
            try:
                data.append([float(c) for c in row])
            except ValueError:
                raise ValueError(f"reference CSV {str(path)!r} row {k + 1}: not a number in "
                                 f"{row}") from None
        data = np.array(data)
        if width < 2:
            raise ValueError(f"reference CSV {str(path)!r}: need a time column and at least "
                             f"one joint column")
        ref = cls(data[:, 0], data[:, 1:], source=str(path))
        if robot is not None:
            lower, upper = robot.lower, robot.upper
            bad = (ref.waypoints < lower) | (ref.waypoints > upper)
            if bad.any():
                k, j = np.argwhere(bad)[0]
                raise ValueError(
                    f"reference CSV {str(path)!r} row {k + 1}: joint {robot.joint_names[j]!r} "
                    f"= {ref.waypoints[k, j]:.6g} rad is outside its limits "
                    f"[{lower[j]:.4g}, {upper[j]:.4g}]")
        return ref

    def to_dict(self) -> dict:
        """JSON-ready description."""
        return {"kind": "spline", "source": self.source, "times_s": self.times.tolist(),
                "waypoints_rad": self.waypoints.tolist()}


def _numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


# --- task space -------------------------------------------------------------------------------

@dataclass(frozen=True)
class LinePath:
    """Straight line of a point from ``start`` to ``end`` [m], base frame, quintic time law."""

    start: np.ndarray
    end: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", check_vector("start", self.start, 3, readonly=True))
        object.__setattr__(self, "end", check_vector("end", self.end, 3, readonly=True))

    def point(self, s: np.ndarray) -> np.ndarray:
        """Points at path parameters ``s`` in [0, 1], shape (N,) -> (N, 3) [m]."""
        return self.start + np.outer(s, self.end - self.start)

    def to_dict(self) -> dict:
        """JSON-ready description."""
        return {"kind": "line", "start_m": self.start.tolist(), "end_m": self.end.tolist()}


@dataclass(frozen=True)
class CirclePath:
    """Circle of ``radius`` [m] about ``center`` [m] in the plane normal to ``normal``.

    The motion starts at ``center + radius u`` (``u`` the unit vector of ``start_dir``
    projected on the plane), turns once, counter-clockwise about ``normal``.
    """

    center: np.ndarray
    radius: float
    normal: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    start_dir: np.ndarray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", check_vector("center", self.center, 3, readonly=True))
        object.__setattr__(self, "radius", check_positive("radius", self.radius, unit="m"))
        nz = check_direction("normal", self.normal, 3)
        u = check_vector("start_dir", self.start_dir, 3)
        u = u - nz * (u @ nz)
        if np.linalg.norm(u) < 1e-9:
            raise ValueError("start_dir must not be parallel to normal")
        object.__setattr__(self, "normal", nz)
        object.__setattr__(self, "start_dir", u / np.linalg.norm(u))

    def point(self, s: np.ndarray) -> np.ndarray:
        """Points at path parameters ``s`` in [0, 1] (one turn), shape (N,) -> (N, 3) [m]."""
        a = 2.0 * math.pi * np.asarray(s, dtype=float)
        v = np.cross(self.normal, self.start_dir)
        return self.center + self.radius * (np.outer(np.cos(a), self.start_dir)
                                            + np.outer(np.sin(a), v))

    def to_dict(self) -> dict:
        """JSON-ready description."""
        return {"kind": "circle", "center_m": self.center.tolist(), "radius_m": self.radius,
                "normal": self.normal.tolist(), "start_dir": self.start_dir.tolist()}


def _ik_point(robot, frame_id: int, target: np.ndarray, q: np.ndarray, *, damping: float,
              tol: float, max_iter: int) -> tuple[np.ndarray, float]:
    """Damped least squares on the frame origin's position; returns (q, residual [m])."""
    import pinocchio as pin

    model, data = robot.model, robot.data
    lower, upper = robot.lower, robot.upper
    err = np.inf
    for _ in range(max_iter):
        pin.forwardKinematics(model, data, q)
        pin.updateFramePlacement(model, data, frame_id)
        e = target - data.oMf[frame_id].translation
        err = float(np.linalg.norm(e))
        if err < tol:
            break
        J = pin.computeFrameJacobian(model, data, q, frame_id,
                                     pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3]
        dq = J.T @ np.linalg.solve(J @ J.T + damping**2 * np.eye(3), e)
        q = np.clip(q + dq, lower, upper)
    return q, err


@dataclass(frozen=True)
class TaskSpaceReference(SplineReference):
    """Joint spline that moves a frame's origin along a task-space path.

    Made by :func:`task_space_reference`: a :class:`SplineReference` (the engines see only its
    joint spline) that also keeps what it was made from, so that a run can be judged in task
    space by :meth:`tracking_error`.

    Attributes
    ----------
    frame : str
        The frame whose origin follows the path.
    path : LinePath or CirclePath
        The path [m], base frame.
    move_time : float
        Duration of the motion [s]; the path parameter follows the quintic rest-to-rest law.
    fk_error_m : float
        Largest deviation of the joint spline from the path, measured between knots [m].
    """

    frame: str = ""
    path: object = None
    move_time: float = 0.0
    fk_error_m: float = 0.0

    def target(self, t) -> np.ndarray:
        """Target point of the frame's origin at times ``t`` [s], shape (N,) -> (N, 3) [m].

        Before 0 the path's start, after :attr:`move_time` its end (at rest, as the spline).
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        return self.path.point(_quintic(t / self.move_time)[0])

    def tracking_error(self, robot, t, q) -> np.ndarray:
        r"""Task-space error of a run: where the frame is, minus where the path wants it.

        .. math:: e_x(t_k) = p(q_k) - p^*(t_k)

        with ``p(q)`` the frame origin by ``robot``'s forward kinematics (Pinocchio) and
        ``p^*`` the path (:meth:`target`), not the joint spline's own kinematics: the error
        includes the spline's deviation (:attr:`fk_error_m`) and, for an uncertain plant, the
        plant's kinematics (its link lengths differ from the nominal ones).

        Parameters
        ----------
        robot : Robot
            The arm that moved (the plant), with a frame named :attr:`frame`.
        t : array-like, shape (N,)
            Times [s].
        q : array-like, shape (N, n)
            Joint positions of the run [rad].

        Returns
        -------
        ndarray, shape (N, 3)
            Error [m], base frame.
        """
        import pinocchio as pin

        if not robot.model.existFrame(self.frame):
            raise ValueError(f"frame {self.frame!r} of the task-space reference is not in "
                             f"robot {robot.name!r}")
        fid = robot.model.getFrameId(self.frame)
        t = np.asarray(t, dtype=float)
        q = np.asarray(q, dtype=float)
        if q.ndim != 2 or q.shape != (t.shape[0], robot.nq):
            raise ValueError(f"q must have shape ({t.shape[0]}, {robot.nq}), got {q.shape}")
        model, data = robot.model, robot.model.createData()
        p = np.empty((t.shape[0], 3))
        for k in range(t.shape[0]):
            pin.forwardKinematics(model, data, q[k])
            p[k] = pin.updateFramePlacement(model, data, fid).translation
        return p - self.target(t)

    def to_dict(self) -> dict:
        """JSON-ready description: the spline's, plus ``task_space`` (frame, path, timing)."""
        return {**super().to_dict(),
                "task_space": {"frame": self.frame, "path": self.path.to_dict(),
                               "move_time_s": self.move_time, "fk_error_m": self.fk_error_m}}


def task_space_reference(robot, frame: str, path, move_time: float, *, q_start=None,
                         rate: float = 200.0, tol: float = 1e-6,
                         fk_tol: float = 1e-4) -> TaskSpaceReference:
    r"""Joint reference that moves ``frame``'s origin along a task-space ``path``.

    The path parameter follows the quintic rest-to-rest time law over ``move_time``; the path
    is sampled at ``rate`` Hz and each point solved by damped least squares on the position of
    the frame's origin (3 rows of Pinocchio's frame Jacobian, ``LOCAL_WORLD_ALIGNED``),

    .. math:: \Delta q = J^T (J J^T + \mu^2 I)^{-1} (p^* - p(q)),

    warm-started from the previous point; the joint solutions are joined by a clamped cubic
    spline. The result is checked by forward kinematics halfway between the knots.

    Parameters
    ----------
    robot : Robot
        The arm.
    frame : str
        A frame of ``robot.model`` (a link or joint name).
    path : LinePath or CirclePath
        The path of the frame's origin [m], in the base frame.
    move_time : float
        Duration [s].
    q_start : array-like, shape (n,), optional
        Initial guess for the first point [rad] (default: the neutral configuration, inside
        the limits).
    rate : float, default 200
        Knots per second of the joint spline [Hz].
    tol : float, default 1e-6
        IK tolerance on each knot [m].
    fk_tol : float, default 1e-4
        Largest accepted deviation of the spline from the path between knots [m].

    Returns
    -------
    TaskSpaceReference
        Its ``source`` (also in ``to_dict``) records the frame, the path and ``fk_error_m``, the
        largest deviation measured [m].

    Raises
    ------
    IKError
        A point is out of reach (IK does not converge): the message names the point, its time
        and the residual.
    ValueError
        Unknown frame, bad path or times, or a spline deviating more than ``fk_tol``.
    """
    import pinocchio as pin

    if not robot.model.existFrame(frame):
        names = [f.name for f in robot.model.frames]
        raise ValueError(f"frame {frame!r} is not in robot {robot.name!r}; frames: "
                         f"{', '.join(names)}")
    fid = robot.model.getFrameId(frame)
    T = check_positive("move_time", move_time, unit="s")
    count = max(3, int(math.ceil(T * rate)) + 1)
    t = np.linspace(0.0, T, count)
    s = _quintic(t / T)[0]
    targets = path.point(s)
    if q_start is None:
        q = np.clip(robot.neutral(), robot.lower, robot.upper)
    else:
        q = robot.check_state("q_start", q_start).copy()
    Q = np.empty((count, robot.nq))
    for k, p in enumerate(targets):
        q, err = _ik_point(robot, fid, p, q, damping=1e-3, tol=tol,
                           max_iter=500 if k == 0 else 100)
        if err >= tol:
            raise IKError(
                f"inverse kinematics of frame {frame!r} did not converge at path point {k} "
                f"(t = {t[k]:.4g} s, target {np.round(p, 6).tolist()} m): residual "
                f"{err:.3g} m > {tol:g} m; the point is probably out of reach")
        Q[k] = q
    ref = TaskSpaceReference(t, Q, source=f"task-space {path.to_dict()['kind']} of frame "
                                          f"{frame!r}", frame=frame, path=path, move_time=T)
    tm = 0.5 * (t[1:] + t[:-1])
    Rm = ref.positions(tm)
    sm = _quintic(tm / T)[0]
    want = path.point(sm)
    dev = 0.0
    for k in range(len(tm)):
        pin.forwardKinematics(robot.model, robot.data, Rm[k])
        pin.updateFramePlacement(robot.model, robot.data, fid)
        dev = max(dev, float(np.linalg.norm(robot.data.oMf[fid].translation - want[k])))
    if dev > fk_tol:
        raise ValueError(f"the joint spline deviates {dev:.3g} m from the path of {frame!r} "
                         f"between knots (> fk_tol = {fk_tol:g} m); raise rate (now {rate:g} Hz)")
    object.__setattr__(ref, "source", f"{ref.source}, {path.to_dict()}, fk_error_m={dev:.3g}")
    object.__setattr__(ref, "fk_error_m", dev)
    return ref


def default_reference(robot, amp: float = 0.5, freq: float = 0.5,
                      home=None) -> SineReference:
    """Build a sinusoid per joint about a home configuration, inside the joint limits.

    Parameters
    ----------
    robot : Robot
        The arm (for its neutral configuration and limits).
    amp : float, default 0.5
        Amplitude [rad], finite and >= 0, the same on every joint. Never reduced: an amplitude
        a joint's limits cannot hold is refused (with ``home`` None, at most its range / 2.2,
        keeping 10 % of the amplitude to spare; with ``home`` given, ``home +- amp`` must stay
        inside the limits).
    freq : float, default 0.5
        Frequency [Hz], finite and >= 0.
    home : array-like, shape (n,), optional
        Centre of the motion [rad]; default the URDF's neutral configuration, moved inside the
        limits where it is closer to them than ``1.1 amp`` (the home used is recorded in
        :meth:`SineReference.to_dict`).

    Returns
    -------
    SineReference
        Phases ``2 pi j / n`` for joint ``j``, so the joints do not move in lockstep.

    Raises
    ------
    ValueError
        ``amp`` out of range, or larger than a joint's limits allow: the message names the
        amplitude, the joint, its limits and the largest amplitude they allow (or, with
        ``home`` given, the span ``home +- amp`` that leaves them).
    """
    amp = check_positive("amp", amp, allow_zero=True, unit="rad")
    freq = check_positive("freq", freq, allow_zero=True, unit="Hz")
    n = robot.nq
    lower, upper = robot.lower, robot.upper
    if home is None:
        largest = (upper - lower) / 2.2
        too = np.flatnonzero(amp > largest)
        if too.size:
            j = int(too[0])
            raise FieldError("amp", (
                f"{{name}} = {amp:g} rad is too large for joint {robot.joint_names[j]!r} "
                f"(limits [{lower[j]:.4g}, {upper[j]:.4g}] rad): the largest amplitude they "
                f"allow about the default home (range / 2.2) is {float(largest[j]):.4g} rad"
                + (f" ({too.size} joints refuse it)" if too.size > 1 else "")))
        # 10 % of the amplitude to spare, so tracking errors cannot touch the limits.
        home = np.clip(robot.neutral(), lower + 1.1 * amp, upper - 1.1 * amp)
    else:  # home +- amp outside the limits: refused by SineReference.check_limits below
        home = check_vector("home", home, n)
    ref = SineReference(home=home, amp=amp, freq=freq, phase=2.0 * math.pi * np.arange(n) / n)
    ref.check_limits(robot)
    return ref


def study_reference(plant, duration: float) -> Reference:
    """Return the reference of the paper's study on ``plant`` over ``duration`` [s].

    The plant's own task path when it declares one
    (:meth:`rrr_pin.model.plant.Plant.task_path`: a closed chain's mechanism, e.g. the 5-bar's
    tip circle or the Delta's adept cycle, its period ``duration``), as actuated waypoints
    joined by a clamped C2 :class:`SplineReference` (at rest at both ends); otherwise the
    joint-space sinusoid of :func:`default_reference` (the paper's section 5).
    """
    path = plant.task_path(duration)
    if path is None:
        return default_reference(plant)
    t, W, source = path
    return SplineReference(times=t, waypoints=W, source=source)

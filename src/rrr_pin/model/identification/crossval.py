r"""Cross-validation by period, segment or run, with per-sample prediction intervals.

The samples are split into folds in time (never at random: neighbouring samples share the
derivative filter and the model error); each fold is predicted by the fit on the others.
Per fold and joint: the RMS of the held-out residual, and the fraction of held-out samples
inside their prediction interval at ``level``,

.. math:: \hat\tau_{k,j} \pm z_{(1+\text{level})/2} \sqrt{s_j^2 + y_{k,j}^T C\, y_{k,j}},

``s_j`` the residual level of joint ``j`` on motion the fit has not seen (its leave-one-block-out
prediction error, :func:`~rrr_pin.model.identification.jackknife_scale`: cross-validated
scaling), ``y_{k,j}`` the regressor row of sample ``k``, joint ``j``, and ``C`` the
Newey-West covariance of the estimate (:func:`~rrr_pin.model.identification.least_squares`),
which widens the interval where the sample's regressor is unlike the training's. (The
parameter covariance of the record, ``identify(..., covariance="calibrated")``, is that ``C`` scaled
by the block jackknife's ``c^2``; the prediction interval does not scale it again, since
``s_j`` already holds the parameter error of an average unseen block.)

A fold whose motion the training samples already hold (a periodic excitation: each period
repeats the others) tests reproduction, not generalization: :func:`repeats_training`
measures, for every held-out sample, the distance of its state ``(q, qd)`` to the nearest
training state, each coordinate in units of its standard deviation over the log, and the
fold is flagged (a ``UserWarning``) when the median falls below :data:`REPEAT_DISTANCE`.

References
----------
.. [1] W. K. Newey and K. D. West, "A simple, positive semi-definite, heteroskedasticity and
   autocorrelation consistent covariance matrix", Econometrica 55(3), 1987.
.. [2] S. Arlot and A. Celisse, "A survey of cross-validation procedures for model
   selection", Statistics Surveys 4, 2010 (blocked folds for dependent data).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from ...validation import FieldError
from .armature import armature_columns, armature_names, armature_regressor
from .estimation import correlation_lag, jackknife_scale, least_squares
from .friction import friction_names, friction_regressor
from .measurements import Measurements, filter_like
from .regressors import IdentificationError, base_parameters, regressor

__all__ = ["REPEAT_DISTANCE", "detect_period", "repeats_training", "cross_validate",
           "prediction_interval"]

#: Median nearest-state distance (in standard deviations per coordinate, RMS over the
#: coordinates) below which a held-out fold repeats the training motion.
REPEAT_DISTANCE = 0.05


def detect_period(data: Measurements) -> float | None:
    """Return the period [s] of a periodic excitation, or None.

    The lag ``T`` that minimises the RMS of ``q(t + T) - q(t)`` over lags from 0.5 s to 90 %
    of the log, relative to the RMS of ``q`` about its mean; a period only when that ratio is
    below 0.2 (a repeat). Irregular stamps: ``q`` is first interpolated on a uniform grid.
    """
    t, q = data.t, data.q
    dt = float(np.median(np.diff(t)))
    grid = np.arange(t[0], t[-1], dt)
    x = np.column_stack([np.interp(grid, t, q[:, j]) for j in range(q.shape[1])])
    x = x - x.mean(axis=0)
    scale = float(np.sqrt(np.mean(x * x)))
    if scale == 0.0:
        return None
    best, best_lag = np.inf, None
    for lag in range(max(int(0.5 / dt), 1), int(0.9 * len(x)), max(int(0.01 / dt), 1)):
        e = float(np.sqrt(np.mean((x[lag:] - x[:-lag]) ** 2))) / scale
        if e < best:
            best, best_lag = e, lag
    return None if best_lag is None or best > 0.2 else best_lag * dt


def repeats_training(state_train, state_held, scale) -> float:
    """Median distance of held-out states to their nearest training state.

    Parameters
    ----------
    state_train, state_held : ndarray, shape (m, d), (h, d)
        States ``(q, qd)``.
    scale : ndarray, shape (d,)
        Each coordinate's standard deviation over the log.

    Returns
    -------
    float
        Median over held-out samples of ``min_k ||(x - x_k) / scale|| / sqrt(d)``.
    """
    from scipy.spatial import cKDTree

    s = np.where(scale > 0.0, scale, 1.0)
    d = state_train.shape[1]
    dist = cKDTree(state_train / s).query(state_held / s)[0]
    return float(np.median(dist) / math.sqrt(d))


def prediction_interval(W_rows, x, cov, s_j, n: int, level: float):
    """Per-sample prediction and interval half-width (see the module's formula).

    Parameters
    ----------
    W_rows : ndarray, shape (h n, P)
        Regressor rows (sample-major, joints inner).
    x : ndarray, shape (P,)
    cov : ndarray, shape (P, P)
    s_j : ndarray, shape (n,)
        Residual standard deviations [N m].
    n : int
    level : float
        In (0, 1).

    Returns
    -------
    pred, half : ndarray, shape (h, n)
        Torque [N m] and half-width [N m].
    """
    from scipy.stats import norm

    pred = (W_rows @ x).reshape(-1, n)
    var = np.einsum("ip,pq,iq->i", W_rows, cov, W_rows).reshape(-1, n)
    half = norm.ppf(0.5 + 0.5 * level) * np.sqrt(s_j ** 2 + np.maximum(var, 0.0))
    return pred, half


def _check_level(level) -> float:
    level = float(level)
    if not (math.isfinite(level) and 0.0 < level < 1.0):
        raise FieldError("level", f"{{name}} must be in (0, 1) (the prediction intervals' "
                         f"coverage), got {level!r}")
    return level


def cross_validate(robot, data, folds, *, method: str = "wls", friction: bool = True,
                   armature: bool = True, level: float = 0.95, hac_lag: int | None = None,
                   base=None) -> dict:
    """Cross-validate an identification by period, segment or run.

    Parameters
    ----------
    robot : rrr_pin.model.dynamics.Robot
    data : Measurements or sequence of Measurements
    folds : int or {"period", "runs"}
        ``K >= 2``: ``K`` contiguous segments of equal length (of the runs concatenated);
        ``"period"``: one fold per period of a periodic excitation (:func:`detect_period`,
        of the first run), the last one possibly partial; ``"runs"``: one fold per run.
    method, friction, armature
        As :func:`~rrr_pin.model.identification.identify` (every armature column the base
        parameters do not absorb).
    level : float, default 0.95
        Of the prediction intervals, in (0, 1).
    hac_lag : int, optional
        Bandwidth [samples] of the calibrated covariance (default as ``identify``'s).
    base : BaseParameters, optional

    Returns
    -------
    dict
        ``folds``: per fold ``{"first_sample", "last_sample", "samples", "rms_Nm",
        "coverage", "repeat_distance", "repeats_training"}`` (per joint dicts); ``rms_Nm`` and
        ``coverage`` over every held-out sample; ``level``; ``period_s``; ``kind``.

    Raises
    ------
    rrr_pin.validation.FieldError
        ``level`` outside (0, 1), ``folds`` not an integer >= 2 or a kind.
    IdentificationError
        A log shorter than one period (``"period"``, or no period found), fewer than two runs
        (``"runs"``), or a training set that leaves a parameter unexcited (naming the fold
        and the parameters).

    Warns
    -----
    UserWarning
        A held-out fold that repeats the training motion (:func:`repeats_training`).
    """
    level = _check_level(level)
    runs = [data] if isinstance(data, Measurements) else list(data)
    if isinstance(folds, str):
        if folds not in ("period", "runs"):
            raise FieldError("folds", f"{{name}} must be an integer >= 2, 'period' or 'runs', "
                             f"got {folds!r}")
    elif isinstance(folds, bool) or not isinstance(folds, (int, np.integer)) or folds < 2:
        raise FieldError("folds", f"{{name}} must be an integer >= 2, 'period' or 'runs', got "
                         f"{folds!r}")
    base = base_parameters(robot) if base is None else base
    n = robot.nq
    kept = armature_columns(robot, base)[0] if armature else np.zeros(0, dtype=int)
    W_all, y_all, state, run_of, index = [], [], [], [], []
    block = 1
    for i, d in enumerate(runs):
        b = int(d.derived.get("window_samples", 1)) if d.derived else 1
        block = max(block, b)
        rows = np.arange(b // 2, d.N - b // 2)
        tau = filter_like(d, d.tau) if b > 1 else d.tau
        W = base.reduce(regressor(robot, d.q[rows], d.qd[rows], d.qdd[rows]))
        if friction:
            Yf = friction_regressor(d.qd).reshape(d.N, n * 3 * n)
            Yf = (filter_like(d, Yf) if b > 1 else Yf).reshape(d.N, n, 3 * n)
            W = np.hstack([W, Yf[rows].reshape(-1, 3 * n)])
        if kept.size:
            W = np.hstack([W, armature_regressor(d.qdd[rows])[:, kept]])
        W_all.append(W.reshape(len(rows), n, -1))
        y_all.append(tau[rows])
        state.append(np.hstack([d.q[rows], d.qd[rows]]))
        run_of.append(np.full(len(rows), i))
        index.append(rows)
    W_all, y_all = np.concatenate(W_all), np.concatenate(y_all)
    state, run_of, index = map(np.concatenate, (state, run_of, index))
    M, P = len(y_all), W_all.shape[2]
    names = (list(base.names) + (friction_names(robot) if friction else [])
             + [armature_names(robot)[j] for j in kept])
    period = None
    if folds == "runs":
        if len(runs) < 2:
            raise IdentificationError("folds 'runs' needs at least two runs (--data A B); got "
                                      "one: use folds 'period' or a number of segments")
        fold_of = run_of
    elif folds == "period":
        period = detect_period(runs[0])
        length = runs[0].t[-1] - runs[0].t[0]
        if period is None or period >= length:
            raise IdentificationError(
                f"folds 'period': the log {runs[0].source!r} ({length:.3g} s) holds less than "
                f"one period of a periodic excitation (no lag repeats its motion): use a "
                f"number of segments (--folds 5) or several runs (--folds runs)")
        t = np.concatenate([d.t[r] for d, r in zip(runs, [index[run_of == i]
                                                          for i in range(len(runs))],
                                                     strict=True)])
        fold_of = np.where(run_of == 0, ((t - runs[0].t[0]) // period).astype(int), -1)
        fold_of[fold_of < 0] = fold_of.max() + 1  # other runs: one more fold
    else:
        fold_of = (np.arange(M) * int(folds)) // M
    scale = state.std(axis=0)
    out, every_e, every_in = [], [], []
    for k in np.unique(fold_of):
        held = np.flatnonzero(fold_of == k)
        # Training samples: the others, none within a filter window of the fold's edges
        # (the filter mixes them with the held-out ones).
        near = np.zeros(M, dtype=bool)
        for edge in (held[0], held[-1]):
            near[max(edge - block, 0):edge + block + 1] = True
        train = np.flatnonzero((fold_of != k) & ~near)
        m = len(train)
        if m * n < 2 * P:
            raise IdentificationError(f"fold {k}: {m} training samples for {P} parameters: "
                                      f"use fewer folds")
        Wt = W_all[train].reshape(-1, P)
        try:
            x, _, _, s_j, _, _ = least_squares(base, Wt, y_all[train].reshape(-1), n, method,
                                               names=names)
        except IdentificationError as exc:
            raise IdentificationError(f"fold {k} (samples {held[0]}..{held[-1]} held out) "
                                      f"leaves its training data unable to identify: {exc}"
                                      ) from None
        r = (y_all[train] - (Wt @ x).reshape(-1, n))
        lag = max(correlation_lag(r), block) if hac_lag is None else int(hac_lag)
        cov = least_squares(base, Wt, y_all[train].reshape(-1), n, method,
                            names=names, hac_lag=lag)[1]
        c2, s_cv = jackknife_scale(Wt, y_all[train].reshape(-1), cov, n,
                                   1.0 / s_j if method == "wls" else np.ones(n))
        pred, half = prediction_interval(W_all[held].reshape(-1, P), x, cov, s_cv, n, level)
        e = y_all[held] - pred
        inside = np.abs(e) <= half
        every_e.append(e)
        every_in.append(inside)
        dist = repeats_training(state[train], state[held], scale)
        repeats = dist < REPEAT_DISTANCE
        if repeats:
            warnings.warn(f"fold {k}: the held-out motion repeats the training motion (median "
                          f"distance to the nearest training state {dist:.3g} standard "
                          f"deviations < {REPEAT_DISTANCE}): its residual shows reproduction, "
                          f"not generalization; validate on another run (--folds runs)",
                          stacklevel=2)
        out.append({"fold": int(k), "run": int(run_of[held[0]]),
                    "first_sample": int(index[held[0]]), "last_sample": int(index[held[-1]]),
                    "samples": int(len(held)), "hac_lag_samples": int(lag),
                    "rms_Nm": _per(robot, np.sqrt(np.mean(e * e, axis=0))),
                    "coverage": _per(robot, inside.mean(axis=0)),
                    "repeat_distance": dist, "repeats_training": bool(repeats)})
    e, inside = np.concatenate(every_e), np.concatenate(every_in)
    return {"kind": folds if isinstance(folds, str) else "segments", "level": level,
            "period_s": period, "folds": out,
            "rms_Nm": _per(robot, np.sqrt(np.mean(e * e, axis=0))),
            "coverage": _per(robot, inside.mean(axis=0))}


def _per(robot, v) -> dict:
    return {j: float(x) for j, x in zip(robot.joint_names, v, strict=True)}

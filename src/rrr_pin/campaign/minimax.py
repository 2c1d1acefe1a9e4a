r"""Minimax search over a few parameters: a trust-region sequence of linear programs.

:func:`minimax` minimizes the largest of a few functions of a few parameters,

.. math:: \min_x F(x) = \max_i f_i(x), \quad l \le x \le u,

the form of :func:`rrr_pin.tune`'s objective (the worst normalized requirement). ``F`` is
non-smooth where two ``f_i`` cross, which is where its minimum usually lies (two requirements
binding together). The method keeps the max explicit, as Madsen's minimax method [1]_ does: at
the current point each ``f_i`` is linearized (forward differences, one evaluation per
parameter), the linear program

.. math:: \min_{d, t}\ t \quad\text{s.t.}\quad f_i(x) + \nabla f_i(x)^T d \le t,\
          \|d\|_\infty \le \Delta,\ l \le x + d \le u

(scipy's HiGHS) gives the step, kept when ``F`` drops; the trust radius ``Delta`` grows when
the drop is near the predicted one and shrinks when the step fails.

Hand-written: scipy has no minimax solver with a trust region (its ``minimize`` methods
treat the max as one smooth function); the linear programs are scipy's.

References
----------
.. [1] K. Madsen, "An algorithm for minimax solution of overdetermined systems of non-linear
   equations", J. Inst. Math. Appl. 16(3), 321-328, 1975.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog

__all__ = ["minimax"]


def minimax(fun, x0, bounds, maxfev: int, *, radius: float = 0.5, step: float = 1e-4,
            xtol: float = 1e-6) -> tuple[np.ndarray, float, int]:
    """Minimize ``max(fun(x))`` inside ``bounds`` with at most ``maxfev`` evaluations.

    Parameters
    ----------
    fun : callable
        ``fun(x) -> array, shape (m,)``, the functions whose largest is minimized (every call
        the same ``m``).
    x0 : array-like, shape (n,)
        Start, inside the bounds.
    bounds : array-like, shape (n, 2)
        Lower and upper bounds.
    maxfev : int
        Largest number of calls of ``fun``.
    radius : float
        Initial trust radius (units of ``x``).
    step : float
        Forward-difference step (units of ``x``).
    xtol : float
        Stop when the trust radius falls below it.

    Returns
    -------
    x : ndarray, shape (n,)
        The best point evaluated.
    F : float
        ``max(fun(x))`` there.
    nfev : int
        Calls of ``fun`` made.
    """
    bounds = np.asarray(bounds, dtype=float)
    lo, hi = bounds[:, 0], bounds[:, 1]
    x = np.clip(np.asarray(x0, dtype=float), lo, hi)
    n = x.size
    f = np.asarray(fun(x), dtype=float)
    nfev = 1
    delta = radius
    while nfev + n + 1 <= maxfev and delta >= xtol:
        J = np.empty((f.size, n))
        for j in range(n):
            h = step if x[j] + step <= hi[j] else -step
            xp = x.copy()
            xp[j] += h
            J[:, j] = (np.asarray(fun(xp), dtype=float) - f) / h
        nfev += n
        # variables (d, t): minimize t, f + J d - t <= 0
        c = np.zeros(n + 1)
        c[-1] = 1.0
        A = np.hstack([J, -np.ones((f.size, 1))])
        box = [(max(lo[j] - x[j], -delta), min(hi[j] - x[j], delta)) for j in range(n)]
        lp = linprog(c, A_ub=A, b_ub=-f, bounds=box + [(None, None)], method="highs")
        if lp.status != 0:
            delta /= 4.0
            continue
        d = lp.x[:n]
        predicted = f.max() - lp.x[-1]
        if predicted <= 0.0:     # no linear decrease inside the region: stationary
            delta /= 4.0
            if np.max(np.abs(d)) == 0.0:
                break
            continue
        x_new = np.clip(x + d, lo, hi)
        f_new = np.asarray(fun(x_new), dtype=float)
        nfev += 1
        actual = f.max() - f_new.max()
        if actual > 0.0:
            x, f = x_new, f_new
            if actual >= 0.75 * predicted and np.max(np.abs(d)) >= 0.99 * delta:
                delta *= 2.0
            elif actual < 0.25 * predicted:
                delta /= 2.0
        else:
            delta /= 4.0
    return x, float(f.max()), nfev

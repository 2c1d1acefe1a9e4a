r"""Cheap bounds that let a frequency grid skip LAPACK where they decide the answer.

The tuner (:func:`rrr_pin.tune`) evaluates margins of the loop responses ``L(e^{jwT})`` of
every plant at every grid frequency, thousands of times: eigenvalues (delay and actuator
margins) and largest singular values (disk margin, bandwidth, noise gain) of small stacked
matrices, each a LAPACK call. Most grid points cannot change the answer, and bounds that cost
a few array operations prove it:

* eigenvalues lie in the Gershgorin discs (by rows, and by columns), so an interval of the
  grid whose two ends have every disc strictly inside, or strictly outside, a margin's
  boundary holds no crossing (:func:`crossing_intervals`);
* ``sigma_max`` lies between the largest row or column 2-norm and
  ``min(||A||_F, sqrt(||A||_1 ||A||_inf))`` (:func:`sigma_bounds`), so a point whose upper
  bound is below another point's lower bound holds no peak (:func:`peak_sigma`), and a point
  whose bounds lie on one side of a level is on that side (:func:`level_sigmas`).

LAPACK runs on the other points, so every value is the one the full grid gives (to rounding:
the bounds carry a relative slack of 1e-9 against LAPACK's). Both bounds are tight for a nearly
diagonal matrix, which the FL loop of a plant near the law's model is. Hand-written: no
library offers these screens for stacked matrices.

References
----------
.. [1] R. A. Horn, C. R. Johnson, *Matrix Analysis*, 2nd ed., 2013, thm. 6.1.1.
.. [2] G. H. Golub, C. F. Van Loan, *Matrix Computations*, 4th ed., 2013, sec. 2.3.
"""

from __future__ import annotations

import numpy as np

__all__ = ["gershgorin_discs", "crossing_intervals", "sigma_bounds", "sensitivity_bounds",
           "peak_from_bounds", "level_from_bounds", "peak_sigma", "level_sigmas"]

#: Relative slack of every bound against LAPACK's rounding.
SLACK = 1e-9


def _sum_last(x):
    """``x.sum(axis=-1)`` for a short last axis (numpy reduces short axes slowly)."""
    return np.einsum("...i->...", x)


def _max_last(x):
    """``x.max(axis=-1)`` for a short last axis."""
    out = x[..., 0].copy()
    for i in range(1, x.shape[-1]):
        np.maximum(out, x[..., i], out=out)
    return out


def _min_last(x):
    """``x.min(axis=-1)`` for a short last axis."""
    return -_max_last(-x)


def _sigma_max(A):
    return np.linalg.svd(A, compute_uv=False)[..., 0]


def gershgorin_discs(L: np.ndarray) -> tuple:
    """Centres and radii of the Gershgorin discs of stacked matrices, by rows and by columns.

    Every eigenvalue of ``L[..., :, :]`` lies in the union of the row discs, and in the union
    of the column discs (Horn & Johnson, thm. 6.1.1).

    Parameters
    ----------
    L : ndarray, shape (..., n, n), complex

    Returns
    -------
    d : ndarray, shape (..., n), complex
        Centres ``L_ii``.
    rows, cols : ndarray, shape (..., n)
        Radii ``sum_{j != i} |L_ij|`` and ``sum_{j != i} |L_ji|``.
    """
    d = np.diagonal(L, axis1=-2, axis2=-1)
    A, ad = np.abs(L), np.abs(d)
    return d, np.einsum("...ij->...i", A) - ad, np.einsum("...ij->...j", A) - ad


def crossing_intervals(discs, factor, kind: str, slack: float = SLACK) -> np.ndarray:
    r"""Grid intervals where an eigenvalue of ``f(w) L(w)`` may cross a margin's boundary.

    ``kind="modulus"``: ``|lambda| = 1``
    (:func:`~rrr_pin.control.sampled_loops.delay_margin_from_response`); ``kind="real"``:
    ``-Re lambda = 1``, which is the ``|lambda| cos(phi) = 1`` of
    :func:`~rrr_pin.control.sampled_loops.actuator_margin_from_response`. An interval whose
    two ends have every disc (scaled by ``f``) strictly on one side of the boundary (by
    ``slack``) holds no crossing of the sorted eigenvalues; the others need eigenvalues at
    both ends.

    Parameters
    ----------
    discs : tuple
        :func:`gershgorin_discs` of ``L``, shapes (np, nw, n).
    factor : ndarray, shape (nw,), complex, or None
        ``f(w)`` (a delay's or an actuator's response); None: 1.
    kind : {"modulus", "real"}

    Returns
    -------
    ndarray of bool, shape (np, nw - 1)
    """
    d, rows, cols = discs
    f = np.ones(d.shape[-2], complex) if factor is None else np.asarray(factor)
    af = np.abs(f)[:, None]
    c = np.abs(d) * af if kind == "modulus" else -(d * f[:, None]).real
    hi = np.minimum(_max_last(c + af * rows), _max_last(c + af * cols))
    lo = np.maximum(_min_last(c - af * rows), _min_last(c - af * cols))
    below, above = hi < 1.0 - slack, lo > 1.0 + slack
    return ~((below[:, :-1] & below[:, 1:]) | (above[:, :-1] & above[:, 1:]))


def sigma_bounds(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""Bounds ``lo <= sigma_max(A) <= hi`` of stacked matrices.

    ``lo``: the largest row or column 2-norm; ``hi``: the smaller of the Frobenius norm and
    ``sqrt(||A||_1 ||A||_inf)`` (Golub & Van Loan, sec. 2.3).

    Parameters
    ----------
    A : ndarray, shape (..., n, n)

    Returns
    -------
    lo, hi : ndarray, shape (...)
    """
    a = np.abs(A)
    a2 = a * a
    r2, c2 = np.einsum("...ij->...i", a2), np.einsum("...ij->...j", a2)
    lo = np.sqrt(np.maximum(_max_last(r2), _max_last(c2)))
    prod = _max_last(np.einsum("...ij->...i", a)) * _max_last(np.einsum("...ij->...j", a))
    return lo, np.sqrt(np.minimum(_sum_last(r2), prod))


def sensitivity_bounds(L: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""Diagonal part and error bound of ``S = (I + L)^-1``, without inverting.

    With ``I + L = D + E`` (``D`` its diagonal) and ``F = E D^-1``, if
    ``eta = sqrt(||F||_1 ||F||_inf) < 1`` then ``||S - D^-1||_2 <= ||D^-1||_2 eta / (1 - eta)``
    (a Neumann series), so by Weyl's inequality ``sigma_max(S - c I)`` lies within that bound
    of ``max_i |1 / D_ii - c|``. Looser than :func:`sigma_bounds` of ``S``: a first screen
    that decides where ``S`` need not be inverted at all.

    Parameters
    ----------
    L : ndarray, shape (..., n, n), complex

    Returns
    -------
    inv_d : ndarray, shape (..., n), complex
        ``1 / (1 + L_ii)``.
    delta : ndarray, shape (...)
        The bound on ``||S - diag(inv_d)||_2`` (``inf`` where ``eta >= 1``).
    """
    inv_d = 1.0 / (1.0 + np.diagonal(L, axis1=-2, axis2=-1))
    a = np.abs(L)
    a = a * (1.0 - np.eye(L.shape[-1]))              # |E|
    ainv = np.abs(inv_d)
    f_inf = _max_last(np.einsum("...ij,...j->...i", a, ainv))
    f_1 = _max_last(np.einsum("...ij->...j", a) * ainv)
    eta = np.sqrt(f_1 * f_inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = np.where(eta < 1.0, _max_last(ainv) * eta / (1.0 - eta), np.inf)
    return inv_d, delta


def _slack(lo, hi):
    return lo - SLACK * np.abs(lo), hi + SLACK * np.abs(hi)


def _refined(lo, hi, mask, refine):
    """``lo, hi`` tightened on ``mask`` by ``refine(mask) -> (lo2, hi2)`` (copies)."""
    lo, hi = lo.copy(), hi.copy()
    if mask.any():
        lo2, hi2 = _slack(*refine(mask))
        lo[mask] = np.maximum(lo[mask], lo2)
        hi[mask] = np.minimum(hi[mask], hi2)
    return lo, hi


def peak_from_bounds(lo: np.ndarray, hi: np.ndarray, exact, refine=None) -> np.ndarray:
    r"""``max_w`` of a quantity per plant from bounds ``lo <= x <= hi``, exact where it can peak.

    Parameters
    ----------
    lo, hi : ndarray, shape (np, nw)
    exact : callable
        ``exact(mask)``: the quantity at the points of a boolean mask (np, nw), shape (k,).
    refine : callable, optional
        ``refine(mask) -> (lo, hi)``: tighter bounds at the points of a mask (a second, dearer
        screen before ``exact``), each shape (k,).

    Returns
    -------
    ndarray, shape (np,)
    """
    lo, hi = _slack(lo, hi)
    cand = hi >= lo.max(axis=1, keepdims=True)
    if refine is not None:
        lo, hi = _refined(lo, hi, cand, refine)
        cand &= hi >= lo.max(axis=1, keepdims=True)
    out = np.full(lo.shape[0], -np.inf)
    np.maximum.at(out, np.nonzero(cand)[0], exact(cand))
    return out


def level_from_bounds(lo: np.ndarray, hi: np.ndarray, level: float, exact,
                      refine=None) -> np.ndarray:
    """Return the quantity wherever it decides its first crossing of ``level``, from bounds.

    Exact (``exact(mask)``) where the bounds cannot place a point against ``level``, and at
    each plant's first point at or above it and the point before (the crossing's
    interpolation); elsewhere a bound on the right side of ``level``.

    Parameters
    ----------
    lo, hi : ndarray, shape (np, nw)
    level : float
    exact, refine : callable
        As in :func:`peak_from_bounds`.

    Returns
    -------
    ndarray, shape (np, nw)
    """
    lo, hi = _slack(lo, hi)
    if refine is not None:
        lo, hi = _refined(lo, hi, (hi >= level) & (lo < level), refine)
    sig = np.where(hi < level, hi, lo)
    done = (hi >= level) & (lo < level)
    sig[done] = exact(done)
    first = np.argmax(sig >= level, axis=1)        # the first at or above (0 if none)
    rows = np.arange(sig.shape[0])
    need = np.zeros(sig.shape, bool)
    need[rows, first] = True
    need[rows, np.maximum(first - 1, 0)] = True
    need &= ~done
    sig[need] = exact(need)
    return sig


def peak_sigma(A: np.ndarray, screen: bool = True) -> np.ndarray:
    r"""``max_w sigma_max(A[p, w])`` per plant, by LAPACK only where the peak can be.

    A point whose upper bound (:func:`sigma_bounds`) lies below the plant's largest lower
    bound cannot hold the peak; the others' singular values are computed (LAPACK ``gesdd``).

    Parameters
    ----------
    A : ndarray, shape (np, nw, n, n)
    screen : bool
        False: LAPACK at every point (the reference the screen is tested against).

    Returns
    -------
    ndarray, shape (np,)
    """
    if not screen:
        return _sigma_max(A).max(axis=1)
    return peak_from_bounds(*sigma_bounds(A), lambda m: _sigma_max(A[m]))


def level_sigmas(A: np.ndarray, level: float, screen: bool = True) -> np.ndarray:
    """``sigma_max(A[p, w])`` wherever it decides the first crossing of ``level``.

    Exact (LAPACK) where :func:`sigma_bounds` cannot place the point against ``level``, and at
    each plant's first point at or above it and the point before (the crossing's
    interpolation); elsewhere a bound on the right side of ``level`` (``hi`` below it, ``lo``
    at or above it), so the first crossing and its interpolation are the full grid's.

    Parameters
    ----------
    A : ndarray, shape (np, nw, n, n)
    level : float
    screen : bool
        False: LAPACK at every point.

    Returns
    -------
    ndarray, shape (np, nw)
    """
    if not screen:
        return _sigma_max(A)
    return level_from_bounds(*sigma_bounds(A), level, lambda m: _sigma_max(A[m]))

"""Frequency barriers of the loop-shaping requirements, paper section 4.1, eq. (12)-(15).

A multiplicative model-error bound (eq. 12) gives the robust-stability barrier RSB for the
largest closed-loop singular value (eq. 13); tracking and rejection specs give the
nominal-performance bound (eq. 14) and, with the model error, the robust-performance barrier
RPB for the smallest open-loop singular value (eq. 15). Frequencies in rad/s.

References
----------
.. [1] The paper: "H-infinity control + feedback linearization of a 3-DOF RRR spatial serial
   mechanism", section 4.1, eq. (12)-(15), Fig. 2 (after da Cruz, 1996).
.. [2] B. L. Stevens, F. L. Lewis and E. N. Johnson, *Aircraft Control and Simulation*, 3rd
   ed., Wiley, 2015 (multiplicative model-error bound, eq. 12).
"""

from __future__ import annotations

import control
import numpy as np
from scipy.optimize import brentq

from ..validation import check_positive

__all__ = [
    "PAPER_MODEL_ERROR",
    "PAPER_PERFORMANCE_SPECS",
    "model_error_bound",
    "robust_stability_barrier",
    "performance_bound",
    "robust_performance_barrier",
    "barrier_intersection",
]

#: Paper eq. (12): model accurate within 20 % up to 200 rad/s, +20 dB/decade beyond.
PAPER_MODEL_ERROR = (0.20, 200.0)
#: Paper eq. (14): 10 % tracking error up to 80 rad/s, 15 % rejection error up to 100 rad/s.
PAPER_PERFORMANCE_SPECS = ((0.10, 80.0), (0.15, 100.0))


def model_error_bound(rel_error: float = PAPER_MODEL_ERROR[0],
                      w_error: float = PAPER_MODEL_ERROR[1]) -> control.TransferFunction:
    r"""Multiplicative model-error bound, paper eq. (12).

    The model is accurate within ``rel_error`` up to ``w_error`` and the error grows at
    +20 dB/decade beyond:

    .. math:: e_M(s) = \text{rel\_error} \left(\frac{s}{\omega_e} + 1\right)
              = \frac{s + 200}{1000} \text{ (paper values)}

    Parameters
    ----------
    rel_error : float
        Relative model error at low frequency (0.2 = 20 %).
    w_error : float
        Corner frequency [rad/s] after which the error grows.

    Returns
    -------
    control.TransferFunction
        SISO ``e_M(s)`` (improper: a bound, not a system to simulate).
    """
    rel_error = check_positive("rel_error", rel_error)
    w_error = check_positive("w_error", w_error, unit="rad/s")
    return control.tf([rel_error / w_error, rel_error], [1.0])


def robust_stability_barrier(rel_error: float = PAPER_MODEL_ERROR[0],
                             w_error: float = PAPER_MODEL_ERROR[1]) -> control.TransferFunction:
    r"""Robust-stability barrier (high frequency), paper eq. (13).

    .. math:: RSB(s) = \frac{1}{e_M(s)} = \frac{1000}{s + 200} \text{ (paper values)}

    Parameters
    ----------
    rel_error, w_error : float
        Model-error bound of :func:`model_error_bound` (fraction, rad/s).

    Returns
    -------
    control.TransferFunction
        SISO barrier for the largest closed-loop singular value.
    """
    rel_error = check_positive("rel_error", rel_error)
    w_error = check_positive("w_error", w_error, unit="rad/s")
    return control.tf([w_error / rel_error], [1.0, w_error])


def performance_bound(specs=PAPER_PERFORMANCE_SPECS) -> control.TransferFunction:
    r"""Nominal-performance bound from tracking and rejection specs, paper eq. (14).

    Each spec ``(error, omega)`` asks for a relative error at most ``error`` up to
    ``omega`` rad/s; the strictest combination is ``alpha_p = min(error)``,
    ``omega_p = max(omega)``:

    .. math:: p(s) = \frac{1}{\alpha_p}\,\frac{1}{s/\omega_p + 1}
              = \frac{1000}{s + 100} \text{ (paper values)}

    Parameters
    ----------
    specs : sequence of (float, float), shape (k, 2)
        ``(relative error, frequency [rad/s])`` pairs; default the paper's
        ``((0.10, 80), (0.15, 100))``.

    Returns
    -------
    control.TransferFunction
        SISO ``p(s)``.
    """
    alpha_p, omega_p = _specs(specs)
    return control.tf([omega_p / alpha_p], [1.0, omega_p])


def _specs(specs) -> tuple[float, float]:
    arr = np.asarray(specs, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0:
        raise ValueError(f"Expected specs of shape (k, 2) as (error, omega) pairs, "
                         f"got shape {arr.shape}")
    if not (np.all(np.isfinite(arr)) and np.all(arr > 0.0)):
        raise ValueError(f"specs must be positive finite (error, omega) pairs, got {arr.tolist()}")
    return float(arr[:, 0].min()), float(arr[:, 1].max())


def robust_performance_barrier(specs=PAPER_PERFORMANCE_SPECS,
                               rel_error: float = PAPER_MODEL_ERROR[0],
                               w_error: float = PAPER_MODEL_ERROR[1]) -> control.TransferFunction:
    r"""Robust-performance barrier (low frequency), paper eq. (15).

    .. math:: RPB(s) = \frac{p(s)}{1 - e_M(s)} = \frac{-10^6}{(s - 800)(s + 100)}
              \text{ (paper values)}

    Parameters
    ----------
    specs : sequence of (float, float), shape (k, 2)
        Performance specs of :func:`performance_bound`.
    rel_error, w_error : float
        Model-error bound of :func:`model_error_bound` (fraction, rad/s).

    Returns
    -------
    control.TransferFunction
        SISO barrier for the smallest open-loop singular value; only its magnitude is used
        (the pole at ``s = w_error (1/rel_error - 1)`` lies in the right half-plane).
    """
    alpha_p, omega_p = _specs(specs)
    rel_error = check_positive("rel_error", rel_error)
    w_error = check_positive("w_error", w_error, unit="rad/s")
    if rel_error >= 1.0:
        raise ValueError(f"rel_error must be < 1 for a robust-performance barrier, "
                         f"got {rel_error!r}")
    # p(s) / (1 - e_M(s)) with 1 - e_M(s) = -(rel_error / w_error) s + (1 - rel_error)
    den = np.polymul([1.0, omega_p], [-rel_error / w_error, 1.0 - rel_error])
    return control.tf([omega_p / alpha_p / den[0]], den / den[0])


def barrier_intersection(RPB=None, RSB=None, omega=None) -> np.ndarray:
    """Frequencies where the magnitudes of the two barriers cross.

    Below the first crossing the robust-performance barrier lies *above* the
    robust-stability barrier (paper Fig. 2): the open loop would have to pass above RPB
    while the closed loop stays below RSB, which no controller achieves (paper sec. 4.1) -
    robust performance is impossible on that band.

    Parameters
    ----------
    RPB, RSB : control.LTI, optional
        SISO barriers; default the paper's (:func:`robust_performance_barrier`,
        :func:`robust_stability_barrier`).
    omega : array-like, shape (N,), optional
        Grid [rad/s] bracketing the crossings; default ``logspace(-3, 6, 901)``.

    Returns
    -------
    ndarray, shape (k,)
        Crossing frequencies [rad/s], ascending (654.5 rad/s for the paper's barriers).
    """
    RPB = robust_performance_barrier() if RPB is None else RPB
    RSB = robust_stability_barrier() if RSB is None else RSB
    omega = np.logspace(-3, 6, 901) if omega is None else np.asarray(omega, dtype=float)

    def diff(w):
        w = np.atleast_1d(w)
        return (np.log(np.abs(np.asarray(RPB(1j * w, squeeze=False)).ravel()))
                - np.log(np.abs(np.asarray(RSB(1j * w, squeeze=False)).ravel())))

    d = diff(omega)
    idx = np.nonzero(np.sign(d[:-1]) * np.sign(d[1:]) < 0)[0]
    return np.array([brentq(lambda w: diff(w)[0], omega[i], omega[i + 1], xtol=1e-12,
                            rtol=1e-14) for i in idx])

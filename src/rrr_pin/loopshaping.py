"""H-infinity loop shaping of the feedback-linearized arm (paper section 4).

Barriers from requirements (eq. 12-15), the feedback-linearized plant (eq. 11), loop-shaping
weights (eq. 16-17), McFarlane-Glover normalized-coprime-factor synthesis :func:`ncfsyn`,
controller reduction (eq. 18) and the whole design of the paper, :func:`design`.

Conventions (used everywhere in rrr-pin):

* Every controller is for python-control's **negative** feedback, ``u = K (r - y)``: the loop
  of ``G`` and ``K`` is ``control.feedback(G * K)``. MATLAB's and Octave's ``ncfsyn`` and
  SLICOT's ``SB10ID`` return the positive-feedback controller, which is ``-K``.
* Shaped plant ``Gs = W2 G W1``, loop-shaping controller ``K = W1 Ks W2``.
* Frequencies in rad/s, continuous time only.

References
----------
.. [1] The paper: "H-infinity control + feedback linearization of a 3-DOF RRR spatial serial
   mechanism", section 4, eq. (11)-(18).
.. [2] D. McFarlane and K. Glover, *Robust Controller Design Using Normalized Coprime Factor
   Plant Descriptions*, LNCIS 138, Springer, 1990; and "A loop shaping design procedure
   using H-infinity synthesis", IEEE Trans. Automat. Control 37(6), 759-769, 1992.
.. [3] S. Skogestad and I. Postlethwaite, *Multivariable Feedback Control: Analysis and
   Design*, 2nd ed., Wiley, 2005, sec. 9.4 (eq. 9.66, 9.75-9.79).
.. [4] B. L. Stevens, F. L. Lewis and E. N. Johnson, *Aircraft Control and Simulation*, 3rd
   ed., Wiley, 2015 (multiplicative model-error bound, eq. 12).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import control
import numpy as np
import scipy.linalg as sla
from scipy.optimize import brentq

from .robustness import (
    CheckResult,
    check_robust_performance,
    check_robust_stability,
    ncf_gamma,
)

__all__ = [
    "HiddenModeError",
    "WeightError",
    "SynthesisError",
    "model_error_bound",
    "robust_stability_barrier",
    "performance_bound",
    "robust_performance_barrier",
    "barrier_intersection",
    "fl_plant",
    "lag_weight",
    "shaped_plant",
    "NCFSynResult",
    "ncfsyn",
    "reduce_controller",
    "expand_diagonal",
    "zpk_data",
    "Design",
    "design",
]

#: Paper eq. (12): model accurate within 20 % up to 200 rad/s, +20 dB/decade beyond.
PAPER_MODEL_ERROR = (0.20, 200.0)
#: Paper eq. (14): 10 % tracking error up to 80 rad/s, 15 % rejection error up to 100 rad/s.
PAPER_PERFORMANCE_SPECS = ((0.10, 80.0), (0.15, 100.0))
#: Paper eq. (16): lag compensator W1 = 25 (s + 11.5) / (s + 0.19).
PAPER_W1 = (25.0, 11.5, 0.19)


class HiddenModeError(ValueError):
    """The shaped plant has an unstable mode that is uncontrollable or unobservable."""


class WeightError(ValueError):
    """A loop-shaping weight is not square, has the wrong size or is improper."""


class SynthesisError(RuntimeError):
    """The NCF synthesis failed numerically (Riccati equation, improper or unstable loop)."""


# --- barriers (paper 4.1) ----------------------------------------------------------------------

def _positive(name: str, value) -> float:
    value = float(value)
    if not (np.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return value


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
    rel_error, w_error = _positive("rel_error", rel_error), _positive("w_error", w_error)
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
    rel_error, w_error = _positive("rel_error", rel_error), _positive("w_error", w_error)
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
    rel_error, w_error = _positive("rel_error", rel_error), _positive("w_error", w_error)
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


# --- plant and weights (paper 3 and 4.2) ------------------------------------------------------

def fl_plant(lam: float = 45.0, n: int = 3) -> control.StateSpace:
    r"""Feedback-linearized plant, paper eq. (11).

    .. math:: G(s) = \frac{q(s)}{\hat\tau(s)} = \frac{\lambda^2}{(s + \lambda)^2} I_n

    Parameters
    ----------
    lam : float
        Natural frequency ``lambda`` [rad/s] of the linearizing loop (paper: 45).
    n : int
        Number of joints (size of the diagonal plant).

    Returns
    -------
    control.StateSpace
        ``n x n`` plant with ``2 n`` states.
    """
    lam = _positive("lam", lam)
    n = _size("n", n)
    g = control.ss(control.tf([lam**2], [1.0, 2.0 * lam, lam**2]))
    return expand_diagonal(g, n)


def _size(name: str, n) -> int:
    if isinstance(n, bool) or int(n) != n or int(n) < 1:
        raise ValueError(f"{name} must be a positive integer, got {n!r}")
    return int(n)


def lag_weight(k: float = PAPER_W1[0], z: float = PAPER_W1[1],
               p: float = PAPER_W1[2]) -> control.TransferFunction:
    r"""Lag pre-compensator, paper eq. (16).

    .. math:: W_1(s) = \frac{k (s + z)}{s + p} = \frac{25 (s + 11.5)}{s + 0.19}
              \text{ (paper values)}

    Parameters
    ----------
    k : float
        High-frequency gain.
    z, p : float
        Zero and pole corner frequencies [rad/s], ``z > p`` for a lag (low-frequency gain
        ``k z / p``).

    Returns
    -------
    control.TransferFunction
        SISO weight; the paper's post-compensator is ``W2 = 1`` (eq. 17).
    """
    k, z, p = _positive("k", k), _positive("z", z), _positive("p", p)
    return control.tf([k, k * z], [1.0, p])


def expand_diagonal(K, n: int) -> control.StateSpace:
    """Block-diagonal ``n x n`` copy ``diag(K, ..., K)`` of a SISO system.

    Parameters
    ----------
    K : control.LTI
        SISO system (e.g. the design's controller).
    n : int
        Number of copies (joints).

    Returns
    -------
    control.StateSpace
        ``n x n`` system with ``n`` times the states of ``K``.
    """
    n = _size("n", n)
    K = control.ss(K)
    if (K.noutputs, K.ninputs) != (1, 1):
        raise ValueError(f"Expected a SISO system, got shape ({K.noutputs}, {K.ninputs})")
    A, B, C, D = (np.asarray(M, dtype=float) for M in (K.A, K.B, K.C, K.D))
    eye = np.eye(n)
    return control.ss(np.kron(eye, A), np.kron(eye, B), np.kron(eye, C), np.kron(eye, D))


def _as_ss(name: str, sys, exc=ValueError) -> control.StateSpace:
    """Continuous-time, proper state-space copy of an LTI object or a constant matrix."""
    if isinstance(sys, control.TransferFunction):
        for i in range(sys.noutputs):
            for j in range(sys.ninputs):
                num = np.trim_zeros(np.atleast_1d(sys.num[i][j]), "f")
                den = np.trim_zeros(np.atleast_1d(sys.den[i][j]), "f")
                if num.size > den.size:
                    raise exc(f"{name} must be proper, entry ({i}, {j}) has numerator degree "
                              f"{num.size - 1} > denominator degree {den.size - 1}")
    if isinstance(sys, control.LTI):
        if sys.dt not in (0, None):
            raise ValueError(f"{name} must be continuous-time, got dt={sys.dt!r}")
        out = control.ss(sys)
    else:
        D = np.atleast_2d(np.asarray(sys, dtype=float))
        if D.ndim != 2:
            raise exc(f"Expected {name} as an LTI system or a 2-D gain, got shape {D.shape}")
        out = control.ss(np.zeros((0, 0)), np.zeros((0, D.shape[1])),
                         np.zeros((D.shape[0], 0)), D)
    if not all(np.all(np.isfinite(M)) for M in (out.A, out.B, out.C, out.D)):
        raise ValueError(f"{name} has non-finite matrices")
    return out


def _weight(name: str, W, size: int) -> control.StateSpace:
    """Square ``size x size`` weight; ``None`` -> identity, SISO -> per-channel copy."""
    if W is None:
        return _as_ss(name, np.eye(size))
    W = _as_ss(name, W, exc=WeightError)
    if W.noutputs != W.ninputs:
        raise WeightError(f"{name} must be square, got shape ({W.noutputs}, {W.ninputs})")
    if W.noutputs == 1 and size > 1:
        return expand_diagonal(W, size)
    if W.noutputs != size:
        raise WeightError(f"{name} must be {size} x {size} (or SISO), "
                          f"got {W.noutputs} x {W.ninputs}")
    return W


def shaped_plant(G, W1=None, W2=None) -> control.StateSpace:
    """Shaped plant of the loop-shaping procedure (paper sec. 4, step 2).

    .. math:: G_s = W_2 G W_1

    Parameters
    ----------
    G : control.LTI or array-like
        Plant, ``p`` outputs and ``m`` inputs.
    W1 : control.LTI, optional
        Pre-compensator, ``m x m`` or SISO (applied per channel); default identity.
    W2 : control.LTI, optional
        Post-compensator, ``p x p`` or SISO; default identity.

    Returns
    -------
    control.StateSpace
        ``p x m`` shaped plant (series connection, states of ``W1``, ``G`` and ``W2``).
    """
    G = _as_ss("G", G)
    W1 = _weight("W1", W1, G.ninputs)
    W2 = _weight("W2", W2, G.noutputs)
    return control.ss(W2 * G * W1)


# --- McFarlane-Glover synthesis (paper 4.3) ---------------------------------------------------

@dataclass(frozen=True)
class NCFSynResult:
    """Result of :func:`ncfsyn`; every controller is for negative feedback, ``u = -K y``.

    Attributes
    ----------
    K : control.StateSpace
        Loop-shaping controller ``W1 Ks W2`` for the plant ``G``, shape (m, p); the loop is
        ``control.feedback(G * K)``. (MATLAB/Octave ``ncfsyn`` return ``-K``.)
    Ks : control.StateSpace
        Central controller of the shaped plant, shape (m, p), same convention.
    Gs : control.StateSpace
        Shaped plant ``W2 G W1``, shape (p, m).
    W1, W2 : control.StateSpace
        The weights actually used, ``m x m`` and ``p x p``.
    gamma : float
        Achieved index ``||[I; Ks](I + Gs Ks)^-1 [I Gs]||_inf`` of the loop (Gs, Ks).
    gamma_min : float
        Optimal index ``sqrt(1 + rho(X Z))`` of the shaped plant.
    emax : float
        Achieved stability margin ``1 / gamma`` (robustness to normalized coprime factor
        uncertainty; the loop shape is kept when ``emax >= 0.2``).
    factor : float
        Requested ``gamma / gamma_min`` (``1`` = optimal).
    """

    K: control.StateSpace
    Ks: control.StateSpace
    Gs: control.StateSpace
    W1: control.StateSpace
    W2: control.StateSpace
    gamma: float
    gamma_min: float
    emax: float
    factor: float


def _check_hidden_modes(Gs: control.StateSpace) -> None:
    """Raise :class:`HiddenModeError` for an unstabilizable or undetectable realization."""
    A, B, C = (np.asarray(M, dtype=float) for M in (Gs.A, Gs.B, Gs.C))
    n = A.shape[0]
    scale = max(1.0, np.linalg.norm(A, 1))
    for ev in np.linalg.eigvals(A):
        if ev.real < -1e-9 * scale:
            continue
        M = A - ev * np.eye(n)
        for what, pbh in (("uncontrollable", np.hstack([M, B])),
                          ("unobservable", np.vstack([M, C]))):
            sv = np.linalg.svd(pbh, compute_uv=False)
            if sv[-1] <= 1e-9 * max(scale, sv[0]):
                raise HiddenModeError(
                    f"the shaped plant has an {what} mode at s = {ev:.6g} with Re(s) >= 0: "
                    "no controller stabilizes it (check W1, W2 for pole-zero cancellations "
                    "with G, or pass a minimal realization)")


def _psd_sqrt(P: np.ndarray) -> np.ndarray:
    d, V = np.linalg.eigh(0.5 * (P + P.T))
    return (V * np.sqrt(np.clip(d, 0.0, None))) @ V.T


def ncfsyn(G, W1=None, W2=None, factor: float = 1.0) -> NCFSynResult:
    r"""McFarlane-Glover normalized coprime factor loop-shaping synthesis.

    For the shaped plant ``Gs = W2 G W1 = (A, B, C, D)``, with ``S = I + D^T D`` and
    ``R = I + D D^T``, ``X`` and ``Z`` are the stabilizing solutions of the generalized
    control and filter Riccati equations (Skogestad & Postlethwaite eq. 9.78-9.79)

    .. math::
        A^T X + X A - (X B + C^T D) S^{-1} (B^T X + D^T C) + C^T C = 0

        A Z + Z A^T - (Z C^T + B D^T) R^{-1} (C Z + D B^T) + B B^T = 0

    and ``gamma_min = sqrt(1 + rho(X Z))``. With ``gamma = factor * gamma_min``,
    ``F = -S^{-1}(D^T C + B^T X)`` and ``E = (1 - gamma^2) I + Z X``, the central
    positive-feedback controller (eq. 9.75-9.77) is the descriptor system

    .. math::
        E \dot\xi = \left(E (A + B F) + \gamma^2 Z C^T (C + D F)\right) \xi
                     + \gamma^2 Z C^T y,\qquad u = B^T X \xi - D^T y,

    returned with the opposite sign (negative feedback). For ``factor > 1``, ``E`` is
    invertible and the controller has the order of ``Gs``. At the optimum (``factor == 1``)
    ``E`` is singular; as in SLICOT ``SB10ID`` (behind Octave's ``ncfsyn``) its null space,
    of dimension the multiplicity of ``rho(X Z)``, is eliminated exactly (SVD of ``E`` and a
    Schur complement on the algebraic equations), so the optimal ``Ks`` has that many states
    fewer and no near-singular fast pole. A ``factor`` just above 1 instead gives a real pole
    whose magnitude grows like ``1 / (factor - 1)``; :func:`reduce_controller` removes it.

    Parameters
    ----------
    G : control.LTI or array-like
        Continuous-time plant, ``p`` outputs and ``m`` inputs, strictly proper or biproper.
    W1 : control.LTI, optional
        Proper pre-compensator, ``m x m`` or SISO (per channel); default identity.
    W2 : control.LTI, optional
        Proper post-compensator, ``p x p`` or SISO; default identity.
    factor : float
        ``gamma / gamma_min >= 1``; 1 for the optimal controller.

    Returns
    -------
    NCFSynResult
        ``K = W1 Ks W2``, ``Ks``, ``Gs``, ``gamma``, ``gamma_min``, ``emax = 1 / gamma``;
        controllers for negative feedback, ``control.feedback(G * K)``.

    Raises
    ------
    ValueError
        ``factor < 1`` or not finite, discrete-time or non-finite data.
    WeightError
        Non-square, wrongly sized or improper weight.
    HiddenModeError
        ``Gs`` has an unstable mode that is uncontrollable or unobservable.
    SynthesisError
        A Riccati equation has no stabilizing solution, the optimal controller is improper,
        or the loop is not internally stable (numerical failure).

    References
    ----------
    .. [1] McFarlane and Glover (1990, 1992); Skogestad and Postlethwaite (2005), sec. 9.4.2;
       SLICOT ``SB10ID``/``SB10JD`` (descriptor form at the optimum).

    Examples
    --------
    >>> import control
    >>> from rrr_pin.loopshaping import ncfsyn, fl_plant, lag_weight
    >>> res = ncfsyn(fl_plant(45.0, 1), lag_weight())
    >>> round(res.gamma_min, 4)
    2.1436
    >>> loop = control.feedback(fl_plant(45.0, 1) * res.K)     # negative feedback
    """
    factor = float(factor)
    if not np.isfinite(factor) or factor < 1.0:
        raise ValueError(f"factor must be >= 1 (1 = optimal controller), got {factor!r}")
    G = _as_ss("G", G)
    W1 = _weight("W1", W1, G.ninputs)
    W2 = _weight("W2", W2, G.noutputs)
    Gs = control.ss(W2 * G * W1)
    _check_hidden_modes(Gs)
    A, B, C, D = (np.asarray(M, dtype=float) for M in (Gs.A, Gs.B, Gs.C, Gs.D))
    n, (p, m) = A.shape[0], D.shape
    if n == 0:
        raise SynthesisError("the shaped plant is a static gain; nothing to synthesize")
    S = np.eye(m) + D.T @ D
    R = np.eye(p) + D @ D.T
    try:
        X = sla.solve_continuous_are(A, B, C.T @ C, S, s=C.T @ D)
        Z = sla.solve_continuous_are(A.T, C.T, B @ B.T, R, s=B @ D.T)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise SynthesisError(f"Riccati equation without stabilizing solution: {exc}") from exc
    Zh = _psd_sqrt(Z)
    mu = np.linalg.eigvalsh(Zh @ X @ Zh)            # eigenvalues of X Z, real and >= 0
    rho = max(float(mu[-1]), 0.0)
    gamma_min = float(np.sqrt(1.0 + rho))
    gam2 = (factor * gamma_min) ** 2

    F = -np.linalg.solve(S, D.T @ C + B.T @ X)
    E = (1.0 - gam2) * np.eye(n) + Z @ X
    Ak = E @ (A + B @ F) + gam2 * Z @ C.T @ (C + D @ F)
    Bk = gam2 * Z @ C.T
    Ck = B.T @ X
    Dk = -D.T
    if factor == 1.0:
        # Null space of E: as many directions as copies of rho in the spectrum of X Z.
        k = int(np.sum(mu >= rho - 1e-8 * max(rho, 1.0)))
        scale = abs(1.0 - gam2) + rho
        Ak, Bk, Ck, Dk = _descriptor_to_ss(E, Ak, Bk, Ck, Dk, n - k, scale)
    else:
        Ak, Bk = np.linalg.solve(E, Ak), np.linalg.solve(E, Bk)
    Ks = control.ss(Ak, Bk, -Ck, -Dk)                 # negative-feedback convention
    gamma = ncf_gamma(Gs, Ks)
    if not np.isfinite(gamma):
        raise SynthesisError("the synthesized controller does not stabilize the shaped plant")
    K = control.ss(W1 * Ks * W2)
    return NCFSynResult(K=K, Ks=Ks, Gs=Gs, W1=W1, W2=W2, gamma=float(gamma),
                        gamma_min=gamma_min, emax=1.0 / float(gamma), factor=factor)


def _descriptor_to_ss(E, A, B, C, D, r: int, scale: float):
    """Return a standard realization of ``E xdot = A x + B u, y = C x + D u`` with ``rank E = r``.

    ``E = U diag(s) V^T``; in the coordinates ``V^T x`` the last ``n - r`` equations are
    algebraic and are eliminated by a Schur complement (no impulsive modes allowed).
    ``scale`` is the size of the terms of ``E``, to judge the discarded singular values.
    """
    U, s, Vt = np.linalg.svd(E)
    if r < E.shape[0] and s[r] > 1e-6 * scale:
        warnings.warn(f"optimal NCF controller: discarded singular value {s[r]:.3g} of E is "
                      f"not small relative to {scale:.3g}", RuntimeWarning, stacklevel=3)
    At, Bt, Ct = U.T @ A @ Vt.T, U.T @ B, C @ Vt.T
    A11, A12, A21, A22 = At[:r, :r], At[:r, r:], At[r:, :r], At[r:, r:]
    if A22.size and np.linalg.cond(A22) > 1e12:
        raise SynthesisError("the optimal controller is improper (singular algebraic part); "
                             "use factor > 1")
    if A22.size:
        M = np.linalg.solve(A22, np.hstack([A21, Bt[r:]]))
        A11, Br = A11 - A12 @ M[:, :r], Bt[:r] - A12 @ M[:, r:]
        Cr, Dr = Ct[:, :r] - Ct[:, r:] @ M[:, :r], D - Ct[:, r:] @ M[:, r:]
    else:
        Br, Cr, Dr = Bt, Ct, D
    si = 1.0 / s[:r]
    return si[:, None] * A11, si[:, None] * Br, Cr, Dr


# --- controller reduction (paper eq. 18) ------------------------------------------------------

def _split(A, B, C, select):
    """Block-diagonalize ``A`` (ordered real Schur + Sylvester): ``select`` block first."""
    T, Q, k = sla.schur(A, output="real", sort=lambda re, im: select(complex(re, im)))
    if 0 < k < A.shape[0]:
        Xs = sla.solve_sylvester(T[:k, :k], -T[k:, k:], -T[:k, k:])
        W = np.eye(A.shape[0])
        W[:k, k:] = Xs
        Wi = np.eye(A.shape[0])
        Wi[:k, k:] = -Xs
        T, Q, Qi = Wi @ T @ W, Q @ W, Wi @ Q.T
    else:
        Qi = Q.T
    return T, Qi @ B, C @ Q, k


def _balanced_truncation(A, B, C, D, r: int):
    """Square-root balanced truncation of a stable system to ``r`` states."""
    P = sla.solve_continuous_lyapunov(A, -B @ B.T)
    Qg = sla.solve_continuous_lyapunov(A.T, -C.T @ C)
    Lp, Lq = _psd_sqrt(P), _psd_sqrt(Qg)
    U, hsv, Vt = np.linalg.svd(Lq.T @ Lp)
    r = min(r, int(np.sum(hsv > 1e-14 * hsv[0])) if hsv.size and hsv[0] > 0 else 0)
    sh = 1.0 / np.sqrt(hsv[:r])
    T = Lp @ Vt[:r].T * sh
    Ti = (U[:, :r] * sh).T @ Lq.T
    return Ti @ A @ T, Ti @ B, C @ T, D


def reduce_controller(K, order: int = 2, fast_gap: float = 1e3) -> control.StateSpace:
    """Reduce a controller: fast near-singular modes, then balanced truncation.

    1. Modes separated from the others by a frequency gap larger than ``fast_gap`` (the
       near-singular fast pole of a nearly optimal NCF controller, ``|p| ~ 1/(factor - 1)``)
       are residualized: their states are set to steady state, which keeps the DC gain.
    2. If more than ``order`` states remain, the stable part is balanced and truncated
       (square-root method); states with tiny Hankel singular values, e.g. near pole-zero
       cancellations such as the weight zero at -11.5 of the paper's design, go first.
       Unstable modes are kept as they are.

    Parameters
    ----------
    K : control.LTI
        Continuous-time controller (any shape).
    order : int
        Number of states wanted (paper eq. 18: 2). Never more states than ``K`` has.
    fast_gap : float
        Ratio between consecutive pole magnitudes above which the faster poles count as
        "fast" and are residualized.

    Returns
    -------
    control.StateSpace
        Reduced controller, same shape and feedback convention as ``K``.

    Raises
    ------
    ValueError
        ``order`` negative or smaller than the number of unstable modes of ``K``.
    """
    K = _as_ss("K", K)
    if isinstance(order, bool) or int(order) != order or order < 0:
        raise ValueError(f"order must be a non-negative integer, got {order!r}")
    order = int(order)
    fast_gap = _positive("fast_gap", fast_gap)
    A, B, C, D = (np.asarray(M, dtype=float) for M in (K.A, K.B, K.C, K.D))
    n = A.shape[0]
    if n <= order:
        return K
    # 1. fast modes, found by the largest gap in the sorted pole magnitudes
    mags = np.sort(np.abs(np.linalg.eigvals(A)))
    nz = mags[mags > 0.0]
    if nz.size > 1:
        ratios = nz[1:] / nz[:-1]
        i = int(np.argmax(ratios))
        if ratios[i] > fast_gap:
            thr = np.sqrt(nz[i] * nz[i + 1])
            A, B, C, k = _split(A, B, C, lambda ev: abs(ev) < thr)
            Af, Bf, Cf = A[k:, k:], B[k:], C[:, k:]
            D = D - Cf @ np.linalg.solve(Af, Bf)
            A, B, C = A[:k, :k], B[:k], C[:, :k]
    if A.shape[0] <= order:
        return control.ss(A, B, C, D)
    # 2. balanced truncation of the stable part
    A, B, C, k = _split(A, B, C, lambda ev: ev.real < 0.0)
    nu = A.shape[0] - k
    if nu > order:
        raise ValueError(f"K has {nu} modes with Re(s) >= 0, more than order={order}")
    As, Bs, Cs, _ = _balanced_truncation(A[:k, :k], B[:k], C[:, :k], D, order - nu)
    Ar = sla.block_diag(As, A[k:, k:])
    Br = np.vstack([Bs, B[k:]])
    Cr = np.hstack([Cs, C[:, k:]])
    return control.ss(Ar, Br, Cr, D)


def zpk_data(K) -> tuple[float, np.ndarray, np.ndarray]:
    """Gain, zeros and poles of a SISO system, ``K(s) = k prod(s - z) / prod(s - p)``.

    Parameters
    ----------
    K : control.LTI
        SISO continuous-time system.

    Returns
    -------
    gain : float
        ``k``, the first non-zero Markov parameter (``D`` when biproper).
    zeros : ndarray, shape (nz,), complex
        Invariant zeros [rad/s], sorted by magnitude (decoupling zeros included).
    poles : ndarray, shape (n,), complex
        Eigenvalues of ``A`` [rad/s], sorted by magnitude.
    """
    K = _as_ss("K", K)
    if (K.noutputs, K.ninputs) != (1, 1):
        raise ValueError(f"Expected a SISO system, got shape ({K.noutputs}, {K.ninputs})")
    A, B, C, D = (np.asarray(M, dtype=float) for M in (K.A, K.B, K.C, K.D))
    n = A.shape[0]
    poles = np.linalg.eigvals(A) if n else np.zeros(0, complex)
    if n:
        L = np.block([[A, B], [C, D]])
        M = sla.block_diag(np.eye(n), 0.0)
        alpha, beta = sla.eig(L, M, right=False, homogeneous_eigvals=True)
        finite = np.abs(beta) > 1e-12 * np.abs(alpha)
        zeros = alpha[finite] / beta[finite]
    else:
        zeros = np.zeros(0, complex)
    rel = n - zeros.size
    gain = float(D[0, 0]) if rel == 0 else float(
        (C @ np.linalg.matrix_power(A, rel - 1) @ B)[0, 0])
    return gain, zeros[np.argsort(np.abs(zeros))], poles[np.argsort(np.abs(poles))]


# --- the paper's design (sec. 4) --------------------------------------------------------------

def _inv(sys: control.StateSpace) -> control.StateSpace:
    A, B, C, D = sys.A, sys.B, sys.C, sys.D
    if np.linalg.cond(D) > 1e12:
        raise WeightError("the weights must be biproper (invertible D) to evaluate the "
                          "reduced controller on the shaped plant")
    Di = np.linalg.inv(D)
    return control.ss(A - B @ Di @ C, B @ Di, -Di @ C, Di)


def _siso_weight(name: str, W, n: int, default) -> control.StateSpace:
    """SISO weight from ``None`` (default), a SISO LTI or an ``n x n`` diagonal copy."""
    if W is None:
        return _as_ss(name, default)
    W = _weight(name, W, n)
    if W.noutputs == 1:
        return W
    w = np.array([0.0, 0.1, 1.0, 10.0, 100.0, 1000.0])
    H = np.asarray(W(1j * w, squeeze=False))
    off = H - np.einsum("ijk,ij->ijk", H, np.eye(n))
    same = np.allclose(H[np.arange(n), np.arange(n)], H[0, 0], rtol=1e-10, atol=1e-12)
    if not same or np.abs(off).max() > 1e-12 * max(1.0, np.abs(H).max()):
        raise WeightError(f"design() is SISO per joint: {name} must be SISO or a diagonal "
                          "copy of one SISO weight; use ncfsyn() for general MIMO weights")
    return _as_ss(name, control.ss(W.A, W.B[:, :1], W.C[:1, :], W.D[:1, :1]))


@dataclass(frozen=True)
class Design:
    """The loop-shaping design of paper section 4 (all controllers negative feedback).

    Attributes
    ----------
    lam : float
        Feedback-linearization natural frequency [rad/s].
    n : int
        Number of joints.
    G, W1, W2, Gs : control.StateSpace
        ``n x n`` plant (eq. 11), weights (eq. 16-17) and shaped plant ``W2 G W1``.
    ncf : NCFSynResult
        MIMO ``n x n`` synthesis (``K``, ``Ks``, ``Gs``, ``gamma``, ``gamma_min``, ``emax``).
    K_full : control.StateSpace
        SISO full-order controller ``W1 Ks W2`` of one joint, ``u = K (r - y)``.
    K_reduced : control.StateSpace
        SISO reduced controller (eq. 18), same convention.
    gamma_reduced : float
        NCF index of ``K_reduced`` on the shaped plant, ``ncf_gamma(Gs, W1^-1 K W2^-1)``.
    RSB, RPB : control.TransferFunction
        Robust-stability and robust-performance barriers (eq. 13 and 15).
    w_performance : float
        Upper end [rad/s] of the performance band (``omega_p``, 100 rad/s).
    robust_stability, robust_performance : CheckResult
        Barrier checks of sec. 4.4 on ``G`` with ``K_reduced`` per joint.
    """

    lam: float
    n: int
    factor: float
    G: control.StateSpace
    W1: control.StateSpace
    W2: control.StateSpace
    Gs: control.StateSpace
    ncf: NCFSynResult
    K_full: control.StateSpace
    K_reduced: control.StateSpace
    gamma_reduced: float
    RSB: control.TransferFunction
    RPB: control.TransferFunction
    w_performance: float
    robust_stability: CheckResult
    robust_performance: CheckResult

    @property
    def K(self) -> control.StateSpace:
        """``n x n`` reduced controller ``diag(K_reduced)`` (eq. 18 times ``I_n``)."""
        return expand_diagonal(self.K_reduced, self.n)


def design(lam: float = 45.0, n: int = 3, factor: float = 1.0, W1=None, W2=None,
           order: int = 2, specs=PAPER_PERFORMANCE_SPECS,
           model_error=PAPER_MODEL_ERROR) -> Design:
    """H-infinity loop-shaping design of paper section 4, defaults = the paper.

    Steps: barriers from the requirements (eq. 12-15), shaped plant ``W2 G W1`` (eq. 11,
    16-17), :func:`ncfsyn` (sec. 4.3), reduction to ``order`` states (eq. 18) and the
    robustness checks of sec. 4.4. The plant is decoupled, so the controller is designed
    on one joint and copied on the diagonal; the MIMO ``n x n`` synthesis is also run
    (``Design.ncf``) and gives the same ``gamma``.

    Parameters
    ----------
    lam : float
        Natural frequency [rad/s] of the feedback-linearizing loop (paper: 45).
    n : int
        Number of joints (paper: 3).
    factor : float
        ``gamma / gamma_min`` of :func:`ncfsyn` (1 = optimal, as in the paper).
    W1, W2 : control.LTI, optional
        SISO weights (applied per joint) or ``n x n`` diagonal copies; defaults
        ``25 (s + 11.5) / (s + 0.19)`` and 1 (eq. 16-17).
    order : int
        States of the reduced controller (paper: 2).
    specs : sequence of (float, float), shape (k, 2)
        Performance specs ``(error, omega [rad/s])`` (eq. 14).
    model_error : (float, float)
        Model-error bound ``(relative error, omega [rad/s])`` (eq. 12).

    Returns
    -------
    Design
    """
    lam, n = _positive("lam", lam), _size("n", n)
    rel_error, w_error = model_error
    RSB = robust_stability_barrier(rel_error, w_error)
    RPB = robust_performance_barrier(specs, rel_error, w_error)
    w_performance = _specs(specs)[1]
    w1 = _siso_weight("W1", W1, n, lag_weight())
    w2 = _siso_weight("W2", W2, n, np.eye(1))
    siso = ncfsyn(fl_plant(lam, 1), w1, w2, factor)
    K_reduced = reduce_controller(siso.K, order)
    gamma_reduced = ncf_gamma(siso.Gs, _inv(w1) * K_reduced * _inv(w2))
    if not gamma_reduced <= 1.05 * siso.gamma:
        warnings.warn(f"the {order}-state reduced controller raises gamma from "
                      f"{siso.gamma:.4g} to {gamma_reduced:.4g}; consider a larger order",
                      RuntimeWarning, stacklevel=2)
    G = fl_plant(lam, n)
    W1n, W2n = expand_diagonal(w1, n), expand_diagonal(w2, n)
    ncf = ncfsyn(G, W1n, W2n, factor)
    Kn = expand_diagonal(K_reduced, n)
    return Design(
        lam=lam, n=n, factor=float(factor), G=G, W1=W1n, W2=W2n, Gs=ncf.Gs, ncf=ncf,
        K_full=siso.K, K_reduced=K_reduced, gamma_reduced=float(gamma_reduced),
        RSB=RSB, RPB=RPB, w_performance=w_performance,
        robust_stability=check_robust_stability(G, Kn, RSB),
        robust_performance=check_robust_performance(G, Kn, RPB, w_max=w_performance),
    )

"""Robustness analysis of a loop (paper section 4.4): H-infinity norms, NCF margin, barrier checks.

Conventions (used everywhere in rrr-pin):

* Every controller ``K`` is for python-control's **negative** feedback, ``u = K (r - y)``, so the
  loop of a plant ``G`` and ``K`` is ``control.feedback(G * K)``. MATLAB's and Octave's
  ``ncfsyn`` return the positive-feedback controller ``-K``.
* Frequencies are in rad/s, magnitudes of barriers and singular values in dB (``20 log10``).
* Open loop ``L = G K``, closed loop (complementary sensitivity) ``T = G K (I + G K)^{-1}``.

The barrier checks follow the paper (after da Cruz, 1996): *robust stability* holds when the
largest closed-loop singular value lies below the robust-stability barrier RSB at every
frequency, *robust performance* when the smallest open-loop singular value lies above the
robust-performance barrier RPB over the performance band (low frequencies, ``w <= w_p``).

References
----------
.. [1] The paper: "H-infinity control + feedback linearization of a 3-DOF RRR spatial serial
   mechanism", section 4.4, Fig. 4.
.. [2] N. A. Bruinsma and M. Steinbuch, "A fast algorithm to compute the H-infinity norm of a
   transfer function matrix", *Systems & Control Letters* 14(4), 287-293, 1990.
.. [3] D. McFarlane and K. Glover, *Robust Controller Design Using Normalized Coprime Factor
   Plant Descriptions*, LNCIS 138, Springer, 1990.
.. [4] S. Skogestad and I. Postlethwaite, *Multivariable Feedback Control: Analysis and
   Design*, 2nd ed., Wiley, 2005, sec. 9.4.
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np
from scipy.optimize import minimize_scalar

from ..validation import check_positive

__all__ = [
    "CheckResult",
    "sigma",
    "hinf_norm",
    "ncf_loop",
    "ncf_gamma",
    "is_internally_stable",
    "closed_loop",
    "check_robust_stability",
    "check_robust_performance",
]

#: Default frequency grid of the barrier checks [rad/s]; the worst point is then refined.
DEFAULT_OMEGA = np.logspace(-3, 6, 1801)


@dataclass(frozen=True)
class CheckResult:
    """Outcome of a barrier check.

    Attributes
    ----------
    ok : bool
        True when the barrier is respected at every checked frequency.
    worst_frequency : float
        Frequency [rad/s] where the margin is smallest (``nan`` if the loop is unstable).
    margin_db : float
        Smallest margin [dB]; positive when respected, ``-inf`` for an unstable loop.
    """

    ok: bool
    worst_frequency: float
    margin_db: float

    def as_dict(self) -> dict:
        """JSON-ready ``{ok, worst_frequency, margin_db}``."""
        return {"ok": bool(self.ok), "worst_frequency": float(self.worst_frequency),
                "margin_db": float(self.margin_db)}


def _freqresp(sys, omega) -> np.ndarray:
    """Frequency response, shape (p, m, N), of an LTI system at ``omega`` [rad/s]."""
    omega = np.atleast_1d(np.asarray(omega, dtype=float))
    return np.asarray(sys(1j * omega, squeeze=False)).reshape(sys.noutputs, sys.ninputs, -1)


def sigma(sys, omega) -> np.ndarray:
    """Singular values of a frequency response.

    Parameters
    ----------
    sys : control.LTI
        System with ``p`` outputs and ``m`` inputs.
    omega : array-like, shape (N,)
        Frequencies [rad/s].

    Returns
    -------
    sv : ndarray, shape (min(p, m), N)
        Singular values of ``sys(j omega)``, largest first (absolute, not dB).
    """
    H = np.moveaxis(_freqresp(sys, omega), -1, 0)
    return np.linalg.svd(H, compute_uv=False).T


def _sigma_max_at(A, B, C, D, w: float) -> float:
    n = A.shape[0]
    H = D + C @ np.linalg.solve(1j * w * np.eye(n) - A, B) if n else D
    return float(np.linalg.norm(H, 2))


#: Relative distance of a Hamiltonian eigenvalue from the imaginary axis below which its
#: frequency is tried (``|Re| <= AXIS_RTOL |lambda|``): eigenvalues that belong on the axis
#: move off it by rounding, most where poles and zeros nearly cancel (nu-gaps of nearly
#: identical systems); trying a frequency only ever raises the lower bound to a true value.
AXIS_RTOL = 1e-4

#: Points per decade of the sweep that checks the Hamiltonian search's answer.
SWEEP_PER_DECADE = 40


def _sigma_max_sweep(A, B, C, D, w: np.ndarray) -> np.ndarray:
    """``sigma_max(G(j w_k))`` for many frequencies, by one eigendecomposition of ``A``.

    Falls back to one linear solve per frequency when ``A``'s eigenvectors are
    ill-conditioned (close to defective).
    """
    p, V = np.linalg.eig(A)
    if np.linalg.cond(V) < 1e8:
        CV, VB = C @ V, np.linalg.solve(V, B)
        G = D[None] + np.einsum("ij,kj,jl->kil", CV, 1.0 / (1j * w[:, None] - p[None]), VB)
        return np.linalg.svd(G, compute_uv=False)[:, 0]
    return np.array([_sigma_max_at(A, B, C, D, wk) for wk in w])


def _sweep_grid(poles: np.ndarray) -> np.ndarray:
    """Log grid from a hundredth of the slowest pole to a hundred times the fastest, and 0."""
    mags = np.abs(poles)
    mags = mags[mags > 0]
    lo, hi = (mags.min() / 100.0, mags.max() * 100.0) if mags.size else (1e-3, 1e3)
    count = max(2, int(np.ceil(SWEEP_PER_DECADE * np.log10(hi / lo))))
    return np.concatenate(([0.0], np.logspace(np.log10(lo), np.log10(hi), count)))


def hinf_norm(sys, rtol: float = 1e-10, maxiter: int = 60) -> tuple[float, float]:
    r"""H-infinity norm of a stable continuous-time system (Bruinsma-Steinbuch algorithm).

    .. math:: \|G\|_\infty = \sup_\omega \bar\sigma(G(j\omega))

    The lower bound is raised at the imaginary-axis eigenvalues of the Hamiltonian of the
    level ``(1 + 2 rtol) gamma`` and their midpoints until none lies above it. Eigenvalues
    near the axis count (:data:`AXIS_RTOL`, relative to their modulus), and the answer is then
    checked by a frequency sweep (:data:`SWEEP_PER_DECADE` points per decade over the poles'
    range, widened 100 times); a higher value found there restarts the search from it. Both
    guard against the early stop that nearly cancelling poles and zeros cause: there the axis
    eigenvalues move off the axis by rounding, and the search missed the peak (nu-gaps of
    nearly identical systems came out 1-7 % low).

    Parameters
    ----------
    sys : control.StateSpace or control.TransferFunction
        Continuous-time system.
    rtol : float
        Relative accuracy of the result.
    maxiter : int
        Maximal number of Hamiltonian eigenvalue problems.

    Returns
    -------
    norm : float
        ``||sys||_inf``; ``inf`` when ``sys`` has a pole with ``Re >= 0``.
    omega_peak : float
        Frequency [rad/s] of the peak (``inf`` when reached at infinite frequency, ``nan``
        when unstable).

    References
    ----------
    .. [1] Bruinsma and Steinbuch (1990), see the module references.
    """
    sys = control.ss(sys)
    A, B, C, D = (np.asarray(M, dtype=float) for M in (sys.A, sys.B, sys.C, sys.D))
    n = A.shape[0]
    dnorm = float(np.linalg.norm(D, 2)) if D.size else 0.0
    if n == 0:
        return dnorm, 0.0
    poles = np.linalg.eigvals(A)
    if np.any(poles.real >= 0.0):
        return np.inf, np.nan
    # Initial lower bound: infinity, 0 and the pole frequencies (Bruinsma-Steinbuch, step 1).
    gl, wpeak = dnorm, np.inf
    for w in np.concatenate(([0.0], np.abs(poles))):
        g = _sigma_max_at(A, B, C, D, w)
        if g > gl:
            gl, wpeak = g, w
    if gl == 0.0:
        return 0.0, 0.0
    grid = None
    for _ in range(maxiter):
        gam = (1.0 + 2.0 * rtol) * gl
        R = D.T @ D - gam**2 * np.eye(D.shape[1])
        S = D @ D.T - gam**2 * np.eye(D.shape[0])
        Ri = np.linalg.inv(R)
        H = np.block([
            [A - B @ Ri @ D.T @ C, -gam * B @ Ri @ B.T],
            [gam * C.T @ np.linalg.solve(S, C), -A.T + C.T @ D @ Ri @ B.T],
        ])
        ev = np.linalg.eigvals(H)
        scale = max(1.0, float(np.abs(ev).max()))
        near = (np.abs(ev.real) < 1e-7 * scale) | (np.abs(ev.real) <= AXIS_RTOL * np.abs(ev))
        ws = np.unique(ev.imag[near & (ev.imag >= 0.0)])
        tries = np.concatenate((ws, 0.5 * (ws[:-1] + ws[1:]))) if ws.size else ws
        gains = [_sigma_max_at(A, B, C, D, w) for w in tries]
        k = int(np.argmax(gains)) if gains else -1
        if k >= 0 and gains[k] > gl:
            gl, wpeak = gains[k], float(tries[k])
            continue
        if grid is None:  # the search stopped: check it once by the sweep
            grid = _sweep_grid(poles)
            sweep = _sigma_max_sweep(A, B, C, D, grid)
            j = int(np.argmax(sweep))
            g = _sigma_max_at(A, B, C, D, grid[j])  # the exact value there
            if g > gl * (1.0 + 2.0 * rtol):
                gl, wpeak = g, float(grid[j])
                continue
        break
    return float(gl), float(wpeak)


def ncf_loop(G, K) -> control.StateSpace:
    r"""Build the closed loop ``[w1; w2] -> [y; u]`` of the NCF robust-stabilization problem.

    For the negative-feedback controller ``K`` (``u = -K y`` with disturbances ``w1`` at the
    plant output and ``w2`` at the plant input) the map is, up to the sign of the ``u`` rows,

    .. math:: \begin{bmatrix} I \\ K \end{bmatrix} (I + G K)^{-1}
              \begin{bmatrix} I & G \end{bmatrix},

    i.e. the transfer ``[I; K_+](I - G K_+)^{-1}[I G]`` of Skogestad & Postlethwaite (9.66)
    with the positive-feedback controller ``K_+ = -K``. The realization contains every
    state of ``G`` and ``K``, so its stability is internal stability of the loop.

    Parameters
    ----------
    G : control.LTI
        Plant, ``p`` outputs and ``m`` inputs.
    K : control.LTI
        Negative-feedback controller, ``m`` outputs and ``p`` inputs.

    Returns
    -------
    control.StateSpace
        ``p + m`` outputs ``[y; u]``, ``p + m`` inputs ``[w1; w2]``.
    """
    G, K = control.ss(G), control.ss(K)
    A, B, C, D = G.A, G.B, G.C, G.D
    Ak, Bk, Ck, Dk = K.A, K.B, K.C, K.D
    p, m = D.shape
    if Dk.shape != (m, p):
        raise ValueError(f"Expected K of shape ({m}, {p}) for G of shape ({p}, {m}), "
                         f"got {Dk.shape}")
    # y = C x - D Ck xk - D Dk y + w1 + D w2  ->  y = Q (C x - D Ck xk + w1 + D w2)
    Q = np.linalg.inv(np.eye(p) + D @ Dk)
    Yx, Yk, Yw = Q @ C, -Q @ D @ Ck, np.hstack([Q, Q @ D])
    Ux, Uk, Uw = -Dk @ Yx, -Ck - Dk @ Yk, -Dk @ Yw          # u = -Ck xk - Dk y
    Acl = np.block([[A + B @ Ux, B @ Uk], [Bk @ Yx, Ak + Bk @ Yk]])
    Bcl = np.vstack([B @ Uw + np.hstack([np.zeros((B.shape[0], p)), B]), Bk @ Yw])
    Ccl = np.block([[Yx, Yk], [Ux, Uk]])
    Dcl = np.vstack([Yw, Uw])
    return control.ss(Acl, Bcl, Ccl, Dcl)


def ncf_gamma(G, K) -> float:
    r"""NCF robust-stabilization index of a loop, the inverse of its stability margin.

    .. math:: \gamma = \left\| \begin{bmatrix} I \\ K \end{bmatrix} (I + G K)^{-1}
              \begin{bmatrix} I & G \end{bmatrix} \right\|_\infty = 1 / b(G, K)

    Parameters
    ----------
    G : control.LTI
        Plant (shaped plant ``Gs`` in the loop-shaping procedure).
    K : control.LTI
        Negative-feedback controller (``Ks``).

    Returns
    -------
    float
        ``gamma >= 1``; ``inf`` when the loop is not internally stable.
    """
    return hinf_norm(ncf_loop(G, K))[0]


def is_internally_stable(G, K) -> bool:
    """Whether the negative-feedback loop of ``G`` and ``K`` is internally stable."""
    return bool(np.all(np.linalg.eigvals(ncf_loop(G, K).A).real < 0.0))


def closed_loop(G, K=None) -> control.StateSpace:
    """Complementary sensitivity ``T = G K (I + G K)^{-1}`` (``K = I`` when omitted)."""
    L = control.ss(G) if K is None else control.ss(G) * control.ss(K)
    return control.ss(control.feedback(L, np.eye(L.noutputs)))


def _worst(margin_db, omega: np.ndarray, w_lo: float, w_hi: float) -> tuple[float, float]:
    """Grid minimum of ``margin_db(w)``, refined by a bounded search in ``log10 w``."""
    m = margin_db(omega)
    k = int(np.argmin(m))
    lo = np.log10(omega[max(k - 1, 0)])
    hi = np.log10(omega[min(k + 1, omega.size - 1)])
    lo, hi = max(lo, np.log10(w_lo)), min(hi, np.log10(w_hi))
    best_w, best_m = float(omega[k]), float(m[k])
    if hi > lo:
        res = minimize_scalar(lambda x: float(margin_db(np.array([10.0**x]))[0]),
                              bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-10})
        if res.fun < best_m:
            best_w, best_m = float(10.0**res.x), float(res.fun)
    return best_w, best_m


def _check_omega(omega) -> np.ndarray:
    omega = np.sort(np.atleast_1d(np.asarray(omega, dtype=float)))
    if omega.ndim != 1 or omega.size < 2 or np.any(omega <= 0.0) or not np.all(
            np.isfinite(omega)):
        raise ValueError(f"Expected omega as >= 2 positive finite frequencies [rad/s], "
                         f"got shape {omega.shape}")
    return omega


def check_robust_stability(G, K, RSB, omega=None) -> CheckResult:
    r"""Robust-stability check: ``sigma_max(T(jw)) < |RSB(jw)|`` at all frequencies.

    .. math:: \bar\sigma\left(G K (I + G K)^{-1}(j\omega)\right) < |RSB(j\omega)|
              = 1 / |e_M(j\omega)|

    Parameters
    ----------
    G : control.LTI
        Plant, shape (p, m).
    K : control.LTI
        Negative-feedback controller, shape (m, p).
    RSB : control.LTI
        SISO robust-stability barrier (paper eq. 13).
    omega : array-like, shape (N,), optional
        Frequency grid [rad/s]; default ``logspace(-3, 6, 1801)``. The worst grid point is
        refined by a bounded scalar search between its neighbours.

    Returns
    -------
    CheckResult
        ``margin_db = min_w (|RSB|_dB - sigma_max(T)_dB)``; ``ok`` when positive and the
        nominal loop is internally stable (otherwise ``margin_db = -inf``).
    """
    omega = _check_omega(DEFAULT_OMEGA if omega is None else omega)
    if not is_internally_stable(G, K):
        return CheckResult(False, np.nan, -np.inf)
    T = closed_loop(G, K)

    def margin_db(w):
        return 20 * np.log10(np.abs(_freqresp(RSB, w)[0, 0])) - 20 * np.log10(sigma(T, w)[0])

    w, m = _worst(margin_db, omega, omega[0], omega[-1])
    return CheckResult(bool(m > 0.0), w, m)


def check_robust_performance(G, K, RPB, w_max: float = 100.0, omega=None) -> CheckResult:
    r"""Robust-performance check: ``sigma_min(L(jw)) > |RPB(jw)|`` for ``w <= w_max``.

    .. math:: \underline\sigma\left(G K(j\omega)\right) > |RPB(j\omega)|
              = \frac{|p(j\omega)|}{1 - |e_M(j\omega)|},\quad \omega \le \omega_p

    Parameters
    ----------
    G : control.LTI
        Plant, shape (p, m).
    K : control.LTI
        Negative-feedback controller, shape (m, p).
    RPB : control.LTI
        SISO robust-performance barrier (paper eq. 15).
    w_max : float
        Upper end [rad/s] of the performance band, the paper's ``omega_p = 100 rad/s``.
    omega : array-like, shape (N,), optional
        Frequency grid [rad/s]; default ``logspace(-3, 6, 1801)`` cut at ``w_max``.

    Returns
    -------
    CheckResult
        ``margin_db = min_{w <= w_max} (sigma_min(L)_dB - |RPB|_dB)``; ``ok`` when positive
        and the nominal loop is internally stable (otherwise ``margin_db = -inf``).
    """
    w_max = check_positive("w_max", w_max, unit="rad/s")
    omega = _check_omega(DEFAULT_OMEGA if omega is None else omega)
    omega = np.append(omega[omega < w_max], w_max)
    if not is_internally_stable(G, K):
        return CheckResult(False, np.nan, -np.inf)
    L = control.ss(G) * control.ss(K)

    def margin_db(w):
        return 20 * np.log10(sigma(L, w)[-1]) - 20 * np.log10(np.abs(_freqresp(RPB, w)[0, 0]))

    w, m = _worst(margin_db, omega, omega[0], w_max)
    return CheckResult(bool(m > 0.0), w, m)

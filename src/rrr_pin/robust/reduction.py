"""Controller order reduction (paper eq. 18) and its stability guarantees.

* :func:`reduce_controller` - the reduction behind the paper's eq. (18): residualize fast
  near-singular modes, then balanced truncation of the stable part.
* :func:`ncf_reduce` - balanced truncation of the controller's normalized right coprime
  factors ``K = N M^-1``: with ``eps = ||[N - Nr; M - Mr]||_inf``, the reduced
  ``Kr = Nr Mr^-1`` stabilizes ``P`` whenever ``eps < b(P, K)``.
* :func:`reduction_guarantee` - for *any* reduced controller, the nu-gap ``d`` between ``K``
  and ``Kr`` gives: ``Kr`` stabilizes ``P`` if ``d < b(P, K)``, and
  ``arcsin b(P, Kr) >= arcsin b(P, K) - arcsin d``.

All controllers are for negative feedback (``control.feedback(P * K)``).

References
----------
.. [1] G. Vinnicombe, *Uncertainty and Feedback*, Imperial College Press, 2001, th. 3.8
   (the arcsin inequality, symmetric in plant and controller since ``b(P, K) = b(K, P)``).
.. [2] D. McFarlane and K. Glover, *Robust Controller Design Using Normalized Coprime Factor
   Plant Descriptions*, LNCIS 138, Springer, 1990, ch. 5 (coprime-factor reduction of
   controllers; robust stability to factor perturbations smaller than ``b``).
.. [3] K. Glover, "All optimal Hankel-norm approximations of linear multivariable systems and
   their L-infinity error bounds", Int. J. Control 39(6), 1984 (``eps <= 2 sum sigma_i``).
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np
import scipy.linalg as sla

from ..validation import check_count, check_positive
from .gap import nugap
from .lti import check_lti, common_timebase, to_continuous, to_discrete
from .ncf import _graph_symbols_ct, _is_discrete, _psd_sqrt, ncfmargin
from .robustness import hinf_norm

__all__ = [
    "reduce_controller",
    "NCFReduction",
    "ncf_reduce",
    "ReductionGuarantee",
    "reduction_guarantee",
]


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


def _hankel_svd(A, B, C):
    """Gramian square roots ``Lp``, ``Lq`` of a stable system and the SVD of ``Lq^T Lp``.

    The singular values are the Hankel singular values, in decreasing order.
    """
    P = sla.solve_continuous_lyapunov(A, -B @ B.T)
    Qg = sla.solve_continuous_lyapunov(A.T, -C.T @ C)
    Lp, Lq = _psd_sqrt(P), _psd_sqrt(Qg)
    U, hsv, Vt = np.linalg.svd(Lq.T @ Lp)
    return Lp, Lq, U, hsv, Vt


def _balanced_truncation(A, B, C, D, r: int):
    """Square-root balanced truncation of a stable system to ``r`` states, and its HSVs."""
    Lp, Lq, U, hsv, Vt = _hankel_svd(A, B, C)
    r = min(r, int(np.sum(hsv > 1e-14 * hsv[0])) if hsv.size and hsv[0] > 0 else 0)
    sh = 1.0 / np.sqrt(hsv[:r])
    T = Lp @ Vt[:r].T * sh
    Ti = (U[:, :r] * sh).T @ Lq.T
    return Ti @ A @ T, Ti @ B, C @ T, D, hsv


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
    K = check_lti(K, "K")
    if _is_discrete(K.dt):
        raise ValueError("reduce_controller takes a continuous-time K; use ncf_reduce for "
                         "discrete controllers")
    order = check_count("order", order)
    fast_gap = check_positive("fast_gap", fast_gap)
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
    As, Bs, Cs, _, _ = _balanced_truncation(A[:k, :k], B[:k], C[:, :k], D, order - nu)
    Ar = sla.block_diag(As, A[k:, k:])
    Br = np.vstack([Bs, B[k:]])
    Cr = np.hstack([Cs, C[:, k:]])
    return control.ss(Ar, Br, Cr, D)




def _loop_check(P, K):
    P, K = check_lti(P, "P"), check_lti(K, "K")
    common_timebase(("P", P), ("K", K))
    return P, K


@dataclass(frozen=True)
class NCFReduction:
    """Result of :func:`ncf_reduce` (negative-feedback controllers).

    Attributes
    ----------
    Kr : control.StateSpace
        Reduced controller ``Nr Mr^-1``, shape of ``K``, ``order`` states.
    eps : float
        Approximation error ``||[N - Nr; M - Mr]||_inf`` of the normalized factors.
    hsv : ndarray, shape (nK,)
        Hankel singular values of ``[N; M]`` (``eps <= 2 sum(hsv[order:])``).
    b : float
        ``b(P, K)`` of the full-order loop.
    b_reduced : float
        ``b(P, Kr)``, computed (0 if unstable).
    guaranteed : bool
        ``eps < b``: ``Kr`` stabilizes ``P`` by the coprime-factor robustness theorem.
    b_lower : float
        Guaranteed lower bound ``sin(arcsin b - arcsin eps)`` on ``b_reduced`` (0 if not
        ``guaranteed``); ``eps`` bounds the gap between ``K`` and ``Kr``.
    """

    Kr: control.StateSpace
    eps: float
    hsv: np.ndarray
    b: float
    b_reduced: float
    guaranteed: bool
    b_lower: float

    @property
    def margin_lost(self) -> float:
        """``b - b_reduced``, the stability margin lost by the reduction."""
        return self.b - self.b_reduced

    def as_dict(self) -> dict:
        """JSON-ready summary (no systems)."""
        return {"order": int(self.Kr.nstates), "eps": float(self.eps), "b": float(self.b),
                "b_reduced": float(self.b_reduced), "margin_lost": float(self.margin_lost),
                "guaranteed": bool(self.guaranteed), "b_lower": float(self.b_lower)}


def _arcsin_bound(b: float, d: float) -> float:
    return float(np.sin(np.arcsin(min(b, 1.0)) - np.arcsin(min(d, 1.0)))) if d < b else 0.0


def ncf_reduce(P, K, order: int) -> NCFReduction:
    r"""Reduce ``K`` by balanced truncation of its normalized right coprime factors.

    ``K = N M^{-1}`` with the normalized graph symbol ``[N; M]`` (stable, ``nK`` states;
    :func:`rrr_pin.robust.ncf.graph_symbols`) is balanced and truncated to ``[Nr; Mr]`` with
    ``order`` states, and ``Kr = Nr Mr^{-1}``. Since ``b(P, K) = b(K, P)`` is the radius of
    normalized-coprime-factor perturbations *of K* that the loop tolerates,

    .. math:: \epsilon = \left\|\begin{bmatrix} N - N_r \\ M - M_r \end{bmatrix}
              \right\|_\infty < b(P, K) \implies K_r \text{ stabilizes } P,\qquad
              \arcsin b(P, K_r) \ge \arcsin b(P, K) - \arcsin \epsilon

    (the factors of ``Kr`` need not be normalized: ``eps`` bounds the directed gap, hence
    the gap, from ``K`` to ``Kr``). Unlike plain balanced truncation of ``K``, this works for
    unstable controllers too.

    Parameters
    ----------
    P : control.LTI
        Plant, ``p x m`` (continuous or discrete).
    K : control.LTI
        Negative-feedback controller, ``m x p``, same timebase.
    order : int
        States of ``Kr`` (``0 <= order``; capped at the states of ``K``).

    Returns
    -------
    NCFReduction
        ``Kr``, ``eps`` (exact H-infinity norm), Hankel singular values, ``b(P, K)``,
        ``b(P, Kr)``, the guarantee and its lower bound.

    References
    ----------
    .. [1] McFarlane and Glover (1990) ch. 5; Vinnicombe (2001) th. 3.8.
    """
    P, K = _loop_check(P, K)
    order = check_count("order", order)
    b = ncfmargin(P, K)[0]
    Kc = to_continuous(K) if _is_discrete(K.dt) else K
    G, _ = _graph_symbols_ct(Kc)                          # [N; M], (p + m) x p
    A, B, C, D = (np.asarray(M, dtype=float) for M in (G.A, G.B, G.C, G.D))
    if A.shape[0] > order:
        Ar, Br, Cr, Dr, hsv = _balanced_truncation(A, B, C, D, order)
    else:
        Ar, Br, Cr, Dr = A, B, C, D
        hsv = _hankel_svd(A, B, C)[3] if A.shape[0] else np.empty(0)
    m = K.noutputs
    Cn, Cm, Dn, Dm = Cr[:m], Cr[m:], Dr[:m], Dr[m:]
    Dmi = np.linalg.inv(Dm)
    Krc = control.ss(Ar - Br @ Dmi @ Cm, Br @ Dmi, Cn - Dn @ Dmi @ Cm, Dn @ Dmi)
    err = control.ss(sla.block_diag(A, Ar), np.vstack([B, Br]), np.hstack([C, -Cr]), D - Dr)
    eps = hinf_norm(err)[0] if err.nstates else float(np.linalg.norm(D - Dr, 2))
    Kr = to_discrete(Krc, K.dt) if _is_discrete(K.dt) else Krc
    b_red = ncfmargin(P, Kr)[0]
    ok = bool(eps < b)
    return NCFReduction(Kr=Kr, eps=float(eps), hsv=np.asarray(hsv), b=float(b),
                        b_reduced=float(b_red), guaranteed=ok,
                        b_lower=_arcsin_bound(b, eps))


@dataclass(frozen=True)
class ReductionGuarantee:
    """Guarantee of :func:`reduction_guarantee` for one reduced controller.

    Attributes
    ----------
    b : float
        ``b(P, K)`` of the full-order loop.
    nugap : float
        ``delta_nu(K, Kr)``.
    guaranteed : bool
        ``nugap < b``: ``Kr`` stabilizes ``P`` (Vinnicombe th. 3.8).
    b_lower : float
        ``sin(arcsin b - arcsin nugap)`` (0 if not guaranteed): the margin ``Kr`` keeps.
    b_reduced : float
        ``b(P, Kr)``, computed.
    """

    b: float
    nugap: float
    guaranteed: bool
    b_lower: float
    b_reduced: float

    @property
    def margin_lost(self) -> float:
        """``b - b_reduced``."""
        return self.b - self.b_reduced

    def as_dict(self) -> dict:
        """JSON-ready summary."""
        return {"b": float(self.b), "nugap": float(self.nugap),
                "guaranteed": bool(self.guaranteed), "b_lower": float(self.b_lower),
                "b_reduced": float(self.b_reduced), "margin_lost": float(self.margin_lost)}


def reduction_guarantee(P, K, Kr) -> ReductionGuarantee:
    r"""Stability guarantee of any reduced controller ``Kr`` of ``K`` on the plant ``P``.

    .. math:: \delta_\nu(K, K_r) < b(P, K) \implies K_r \text{ stabilizes } P,\qquad
              \arcsin b(P, K_r) \ge \arcsin b(P, K) - \arcsin \delta_\nu(K, K_r)

    Parameters
    ----------
    P : control.LTI
        Plant, ``p x m``.
    K, Kr : control.LTI
        Full and reduced negative-feedback controllers, ``m x p``, same timebase.

    Returns
    -------
    ReductionGuarantee

    References
    ----------
    .. [1] Vinnicombe (2001), th. 3.8 with ``b(P, K) = b(K, P)``.
    """
    P, K = _loop_check(P, K)
    Kr = check_lti(Kr, "Kr")
    common_timebase(("P", P), ("Kr", Kr))
    b = ncfmargin(P, K)[0]
    d = nugap(K, Kr)
    return ReductionGuarantee(b=float(b), nugap=float(d), guaranteed=bool(d < b),
                              b_lower=_arcsin_bound(b, d), b_reduced=float(ncfmargin(P, Kr)[0]))

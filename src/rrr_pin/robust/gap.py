"""Gap and nu-gap metrics between two plants, :func:`gapmetric`.

The distance between two plants seen through feedback: a controller with margin
``b(P1, C) > delta(P1, P2)`` stabilizes ``P2`` as well (Vinnicombe 2001, th. 3.8; Georgiou
and Smith 1990), and ``arcsin b(P2, C) >= arcsin b(P1, C) - arcsin delta_nu(P1, P2)``.

Conventions: normalized graph symbols ``G = [N; M]`` and ``Gt = [-Mt, Nt]`` of
:func:`rrr_pin.robust.ncf.graph_symbols`; discrete systems through the bilinear map of
:func:`rrr_pin.robust.lti.to_continuous` (both metrics are invariant under it).

References
----------
.. [1] G. Vinnicombe, *Uncertainty and Feedback: H-infinity Loop-Shaping and the nu-Gap
   Metric*, Imperial College Press, 2001, ch. 3 (nu-gap, winding-number condition).
.. [2] T. T. Georgiou, "On the computation of the gap metric", *Systems & Control Letters*
   11(4), 253-257, 1988; T. T. Georgiou and M. C. Smith, "Optimal robustness in the gap
   metric", IEEE Trans. Automat. Control 35(6), 673-686, 1990.
.. [3] K. Zhou, J. C. Doyle and K. Glover, *Robust and Optimal Control*, Prentice Hall,
   1996, ch. 17 (full-information H-infinity problem with ``D11 != 0``).
"""

from __future__ import annotations

import control
import numpy as np
import scipy.linalg as sla

from .lti import DimensionMismatchError, check_lti, common_timebase, to_continuous
from .ncf import _check_hidden_modes, _graph_symbols_ct, _is_discrete
from .robustness import hinf_norm

__all__ = ["gapmetric", "nugap", "directed_gap"]


def _pair(P1, P2):
    P1, P2 = check_lti(P1, "P1"), check_lti(P2, "P2")
    if (P1.noutputs, P1.ninputs) != (P2.noutputs, P2.ninputs):
        raise DimensionMismatchError(
            f"P1 and P2 must have the same shape, got ({P1.noutputs}, {P1.ninputs}) and "
            f"({P2.noutputs}, {P2.ninputs})")
    dt = common_timebase(("P1", P1), ("P2", P2))
    if _is_discrete(dt):
        P1, P2 = to_continuous(P1), to_continuous(P2)
    domain = "bilinear" if _is_discrete(dt) else "s"
    _check_hidden_modes(P1, domain, what="plant P1")
    _check_hidden_modes(P2, domain, what="plant P2")
    return P1, P2


def _parahermitian(G: control.StateSpace) -> control.StateSpace:
    """``G~(s) = G(-s)^T``."""
    return control.ss(-G.A.T, G.C.T, -G.B.T, G.D.T)


def _winding_ok(G1, G2) -> bool:
    """Whether ``det(G2~ G1)`` has no zero on the imaginary axis and winding number 0."""
    F = control.ss(_parahermitian(G2) * G1)             # G2~ G1, m x m
    A, B, C, D = (np.asarray(M, dtype=float) for M in (F.A, F.B, F.C, F.D))
    if np.linalg.cond(D) > 1e10:                         # det(G2~ G1) = 0 at infinity
        return False
    if A.shape[0]:
        scale = max(1.0, np.abs(np.linalg.eigvals(A)).max())
        zeros = np.linalg.eigvals(A - B @ np.linalg.solve(D, C))
        if np.any(np.abs(zeros.real) <= 1e-10 * scale):  # det(G2~ G1)(jw) = 0
            return False
        # winding number of det(G2~ G1) = RHP zeros - RHP poles; the RHP poles are the n2
        # mirrored poles of G2 (stable), counted on the realization like the zeros.
        if int(np.sum(zeros.real > 0)) != int(np.sum(np.linalg.eigvals(A).real > 0)):
            return False
    return True


def _nugap(G1, G2, Gt2) -> float:
    """nu-gap from the graph symbols: ``||Gt2 G1||_inf`` if the winding condition holds."""
    return min(1.0, hinf_norm(control.ss(Gt2 * G1))[0]) if _winding_ok(G1, G2) else 1.0


def _fi_feasible(A, B1, B2, C1, D11, D12, gamma: float) -> bool:
    """Return whether the full-information problem ``z = C1 x + D11 w + D12 u`` reaches gamma.

    ``D12`` has orthonormal columns and ``A`` is stable. Zhou, Doyle and Glover (1996),
    ch. 17: feasible iff ``gamma > sigma_max(D12perp^T D11)`` and the Hamiltonian below has a
    stabilizing solution ``X >= 0``.
    """
    mw = B1.shape[1]
    Dp = sla.null_space(D12.T)
    if Dp.size and gamma <= np.linalg.norm(Dp.T @ D11, 2) * (1 + 1e-12):
        return False
    n = A.shape[0]
    if n == 0:
        return True
    D1 = np.hstack([D11, D12])
    R = D1.T @ D1
    R[:mw, :mw] -= gamma**2 * np.eye(mw)
    B = np.hstack([B1, B2])
    if np.linalg.cond(R) > 1e14:
        return False
    Ri = np.linalg.inv(R)
    H = (np.block([[A, np.zeros((n, n))], [-C1.T @ C1, -A.T]])
         - np.vstack([B, -C1.T @ D1]) @ Ri @ np.hstack([D1.T @ C1, B.T]))
    if _stabilizing_psd(H, n):
        return True
    if gamma > 1e-3:
        return False
    # The Hamiltonian test is fast but loses accuracy when gamma is tiny (Ri ~ 1/gamma^2);
    # there, confirm a negative answer with the balanced generalized-pencil Riccati solver.
    try:      # A'X + XA - (XB + C1'D1) R^-1 (B'X + D1'C1) + C1'C1 = 0
        X = sla.solve_continuous_are(A, B, C1.T @ C1, R, s=C1.T @ D1, balanced=True)
    except (np.linalg.LinAlgError, ValueError):
        return False
    return _psd(X)


def _psd(X) -> bool:
    if not np.all(np.isfinite(X)):
        return False
    X = 0.5 * (X + X.T)
    return bool(np.linalg.eigvalsh(X).min() >= -1e-9 * max(1.0, np.abs(X).max()))


def _stabilizing_psd(H, n: int) -> bool:
    """Whether the Hamiltonian ``H`` has a stabilizing Riccati solution ``X >= 0``."""
    ev = np.linalg.eigvals(H)
    scale = max(1.0, np.abs(ev).max())
    if np.any(np.abs(ev.real) < 1e-9 * scale):
        return False
    try:
        _, U, k = sla.schur(H, output="real", sort="lhp")
    except np.linalg.LinAlgError:
        return False
    X1, X2 = U[:n, :n], U[n:, :n]
    if k != n or np.linalg.cond(X1) > 1e12:
        return False
    return _psd(np.linalg.solve(X1.T, X2.T).T)


def _directed_gap(G1, G2, lo: float, rtol: float) -> float:
    """``inf_Q ||G1 - G2 Q||_inf`` over stable Q by bisection (upper end returned)."""
    A = sla.block_diag(G1.A, G2.A)
    n1 = G1.A.shape[0]
    B1 = np.vstack([G1.B, np.zeros((G2.A.shape[0], G1.B.shape[1]))])
    B2 = np.vstack([np.zeros((n1, G2.B.shape[1])), G2.B])
    C1 = np.hstack([G1.C, -G2.C])
    D11, D12 = np.asarray(G1.D, float), -np.asarray(G2.D, float)
    lo, hi = max(0.0, lo), 1.0
    if not _fi_feasible(A, B1, B2, C1, D11, D12, hi * (1 + 1e-9)):
        return 1.0
    # The directed gap is often its lower bound ||Gt2 G1||_inf: try just above it first.
    first = lo * (1.0 + rtol) + 1e-12
    if first < hi and _fi_feasible(A, B1, B2, C1, D11, D12, first):
        return first
    while hi - lo > max(rtol * hi, 1e-9):
        # geometric steps while the bracket spans decades (gaps near 0), then arithmetic
        mid = np.sqrt(max(lo, 1e-12) * hi) if hi > 4.0 * max(lo, 1e-12) else 0.5 * (lo + hi)
        if _fi_feasible(A, B1, B2, C1, D11, D12, mid):
            hi = mid
        else:
            lo = mid
    return hi


def directed_gap(P1, P2, rtol: float = 1e-6) -> float:
    r"""Directed gap from ``P1`` to ``P2`` (Georgiou 1988).

    .. math:: \vec\delta(P_1, P_2) = \inf_{Q \in H_\infty} \|G_1 - G_2 Q\|_\infty

    with the normalized right graph symbols ``G_i = [N_i; M_i]``. Computed as a
    full-information H-infinity problem (``y = w``, so ``Q`` must be stable), by bisection
    on the existence of its stabilizing Riccati solution; the upper end is returned
    (``rtol`` relative accuracy).

    Parameters
    ----------
    P1, P2 : control.LTI
        Plants of the same shape and timebase.
    rtol : float
        Relative accuracy of the bisection.

    Returns
    -------
    float
        In ``[0, 1]``.
    """
    P1, P2 = _pair(P1, P2)
    G1, Gt1 = _graph_symbols_ct(P1)
    G2, Gt2 = _graph_symbols_ct(P2)
    lo = hinf_norm(control.ss(Gt2 * G1))[0]
    return _directed_gap(G1, G2, lo, rtol)


def nugap(P1, P2) -> float:
    r"""Vinnicombe's nu-gap metric; see :func:`gapmetric`."""
    P1, P2 = _pair(P1, P2)
    G1, _ = _graph_symbols_ct(P1)
    G2, Gt2 = _graph_symbols_ct(P2)
    return _nugap(G1, G2, Gt2)


def gapmetric(P1, P2, rtol: float = 1e-6) -> tuple[float, float]:
    r"""Gap and Vinnicombe nu-gap metrics between two plants.

    .. math::
        \delta(P_1, P_2) = \max\{\vec\delta(P_1, P_2), \vec\delta(P_2, P_1)\},\quad
        \vec\delta(P_1, P_2) = \inf_{Q \in H_\infty} \|G_1 - G_2 Q\|_\infty

        \delta_\nu(P_1, P_2) = \begin{cases}
            \|\tilde G_2 G_1\|_\infty = \sup_\omega \kappa(P_1(j\omega), P_2(j\omega))
            & \text{if } \det(G_2^\sim G_1)(j\omega) \ne 0\ \forall \omega
              \text{ and } \operatorname{wno}\det(G_2^\sim G_1) = 0 \\
            1 & \text{otherwise,} \end{cases}

    with ``kappa(P1, P2) = sigma_max((I + P2 P2^*)^{-1/2} (P1 - P2) (I + P1^* P1)^{-1/2})``,
    the chordal distance. ``0 <= nugap <= gap <= 1``; both are symmetric and 0 only for
    equal plants. The sup is the exact H-infinity norm (Bruinsma-Steinbuch), not a grid;
    the winding number is the count of right-half-plane zeros minus poles of
    ``det(G2~ G1)``, from the eigenvalues of its realization.

    Parameters
    ----------
    P1, P2 : control.LTI
        Plants of the same shape and timebase (continuous or discrete), stabilizable and
        detectable.
    rtol : float
        Relative accuracy of the gap bisection (the returned gap is an upper bound). Near 0
        the Riccati test resolves the gap to about 1e-5 absolute; the nu-gap, an exact
        H-infinity norm, to a few 1e-10.

    Returns
    -------
    gap : float
        Gap metric ``delta(P1, P2)``.
    nugap : float
        nu-gap metric ``delta_nu(P1, P2)``.

    Raises
    ------
    DimensionMismatchError, TimebaseMismatchError, NonFiniteSystemError,
    ImproperSystemError
        See :mod:`rrr_pin.robust.lti`.
    rrr_pin.robust.ncf.HiddenModeError
        A plant with an unstable hidden mode (no coprime factorization).

    References
    ----------
    .. [1] Vinnicombe (2001), def. 3.1 and th. 3.8; Georgiou (1988); MATLAB Robust Control
       Toolbox ``gapmetric`` (same definitions).

    Examples
    --------
    >>> import control
    >>> from rrr_pin.robust.gap import gapmetric
    >>> g, nu = gapmetric(control.tf(1, [1, -0.001]), control.tf(1, [1, 0.001]))
    >>> round(nu, 4)            # MATLAB documentation: 0.0020
    0.002
    """
    P1, P2 = _pair(P1, P2)
    G1, Gt1 = _graph_symbols_ct(P1)
    G2, Gt2 = _graph_symbols_ct(P2)
    lo12 = hinf_norm(control.ss(Gt2 * G1))[0]                # ||Gt2 G1||_inf, also the nu-gap
    nu = min(1.0, lo12) if _winding_ok(G1, G2) else 1.0
    lo21 = hinf_norm(control.ss(Gt1 * G2))[0]
    d12 = _directed_gap(G1, G2, lo12, rtol)
    d21 = _directed_gap(G2, G1, lo21, rtol)
    return float(max(d12, d21)), float(nu)

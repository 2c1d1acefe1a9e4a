"""Normalized coprime factors: McFarlane-Glover :func:`ncfsyn` and the margin :func:`ncfmargin`.

Conventions (used everywhere in rrr-pin):

* Every controller is for python-control's **negative** feedback, ``u = K (r - y)``: the loop
  of ``G`` and ``K`` is ``control.feedback(G * K)``. MATLAB's and Octave's ``ncfsyn`` and
  SLICOT's ``SB10ID``/``SB10KD``/``SB10ZD`` return the positive-feedback controller ``-K``.
* Shaped plant ``Gs = W2 G W1``, loop-shaping controller ``K = W1 Ks W2``.
* Graph symbols with outputs first, ``G = [N; M]`` for ``P = N M^-1`` (normalized:
  ``G~ G = I``) and ``Gt = [-Mt, Nt]`` for ``P = Mt^-1 Nt`` (``Gt Gt~ = I``, ``Gt G = 0``).
* Continuous time natively; the discrete ``ncfsyn`` with ``factor > 1`` in discrete time
  (SLICOT SB10ZD's method), everything else discrete through the exact bilinear map of
  :func:`rrr_pin.robust.lti.to_continuous`, which preserves every quantity computed here.

References
----------
.. [1] D. McFarlane and K. Glover, *Robust Controller Design Using Normalized Coprime Factor
   Plant Descriptions*, LNCIS 138, Springer, 1990; and "A loop shaping design procedure
   using H-infinity synthesis", IEEE Trans. Automat. Control 37(6), 759-769, 1992.
.. [2] S. Skogestad and I. Postlethwaite, *Multivariable Feedback Control: Analysis and
   Design*, 2nd ed., Wiley, 2005, sec. 9.4 (eq. 9.66, 9.75-9.79).
.. [3] G. Vinnicombe, *Uncertainty and Feedback: H-infinity Loop-Shaping and the nu-Gap
   Metric*, Imperial College Press, 2001, ch. 1-3 (b(P, C), graph symbols).
.. [4] K. Zhou, J. C. Doyle and K. Glover, *Robust and Optimal Control*, Prentice Hall,
   1996, sec. 13.8 (normalized coprime factorizations).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import control
import numpy as np
import scipy.linalg as sla

from ..validation import FieldError, check_positive, check_real
from .lti import (
    DimensionMismatchError,
    IllPosedLoopError,
    check_lti,
    common_timebase,
    expand_diagonal,
    static_gain,
    to_continuous,
    to_discrete,
)
from .robustness import hinf_norm, ncf_gamma, ncf_loop

__all__ = [
    "HiddenModeError",
    "WeightError",
    "SynthesisError",
    "NCFSynResult",
    "shaped_plant",
    "ncfsyn",
    "ncfmargin",
    "graph_symbols",
    "NCF2DOFResult",
    "ncfsyn_2dof",
]


class HiddenModeError(ValueError):
    """The shaped plant has an unstable mode that is uncontrollable or unobservable."""


class WeightError(ValueError):
    """A loop-shaping weight is not square or has the wrong size."""


class SynthesisError(RuntimeError):
    """The NCF synthesis failed numerically (Riccati equation, improper or unstable loop)."""


def _is_discrete(dt) -> bool:
    return dt not in (0, None)


def _weight(name: str, W, size: int) -> control.StateSpace:
    """Square ``size x size`` weight; ``None`` -> identity, SISO -> per-channel copy."""
    if W is None:
        return static_gain(np.eye(size))
    W = check_lti(W, name)
    if W.noutputs != W.ninputs:
        raise WeightError(f"{name} must be square, got shape ({W.noutputs}, {W.ninputs})")
    if W.noutputs == 1 and size > 1:
        W = expand_diagonal(W, size)
    if W.noutputs != size:
        raise WeightError(f"{name} must be {size} x {size} (or SISO), "
                          f"got {W.noutputs} x {W.ninputs}")
    return W


def _series(*systems) -> control.StateSpace:
    """Product ``S1 S2 ...`` of checked systems with one timebase."""
    dt = common_timebase(*((f"system {i}", s) for i, s in enumerate(systems)))
    out = None
    for s in systems:
        s = control.ss(s.A, s.B, s.C, s.D, dt if dt is not None else s.dt)
        out = s if out is None else out * s
    return control.ss(out)


def _plant_and_weights(G, W1, W2):
    G = check_lti(G, "G")
    W1 = _weight("W1", W1, G.ninputs)
    W2 = _weight("W2", W2, G.noutputs)
    dt = common_timebase(("G", G), ("W1", W1), ("W2", W2))
    return G, W1, W2, dt


def shaped_plant(G, W1=None, W2=None) -> control.StateSpace:
    """Shaped plant of the loop-shaping procedure (paper sec. 4, step 2).

    .. math:: G_s = W_2 G W_1

    Parameters
    ----------
    G : control.LTI or array-like
        Plant, ``p`` outputs and ``m`` inputs (continuous or discrete time).
    W1 : control.LTI, optional
        Pre-compensator, ``m x m`` or SISO (applied per channel); default identity.
    W2 : control.LTI, optional
        Post-compensator, ``p x p`` or SISO; default identity.

    Returns
    -------
    control.StateSpace
        ``p x m`` shaped plant (series connection, states of ``W1``, ``G`` and ``W2``).
    """
    G, W1, W2, _ = _plant_and_weights(G, W1, W2)
    return _series(W2, G, W1)


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

    Notes
    -----
    Unpacks as MATLAB's ``[K, CL, gamma, info] = ncfsyn(G, W1, W2)``: ``K, CL, gamma, info =
    ncfsyn(G, W1, W2)`` gives :attr:`K` (negative feedback here; MATLAB's is ``-K``),
    :attr:`CL`, :attr:`gamma` and this record as ``info``.
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

    @property
    def CL(self) -> control.StateSpace:
        r"""Closed loop of the shaped plant, whose H-infinity norm is :attr:`gamma`.

        .. math:: CL = \begin{bmatrix} I \\ K_s \end{bmatrix} (I + G_s K_s)^{-1}
                  \begin{bmatrix} I & G_s \end{bmatrix}

        from the disturbances ``[w1; w2]`` at the shaped plant's output and input to
        ``[y; u]`` (:func:`rrr_pin.robust.robustness.ncf_loop`).
        """
        return ncf_loop(self.Gs, self.Ks)

    def __iter__(self):
        """``K, CL, gamma, info`` (see Notes)."""
        return iter((self.K, self.CL, self.gamma, self))


def _check_hidden_modes(Gs: control.StateSpace, domain: str = "s",
                        what: str = "shaped plant") -> None:
    """Raise :class:`HiddenModeError` for an unstabilizable or undetectable realization.

    ``domain``: ``"s"``, ``Gs`` continuous (modes with ``Re(s) >= 0``); ``"bilinear"``, ``Gs``
    the continuous bilinear image of a discrete plant (the mode is reported at
    ``z = (1 + s) / (1 - s)``); ``"z"``, ``Gs`` discrete itself (modes with ``|z| >= 1``).
    """
    A, B, C = (np.asarray(M, dtype=float) for M in (Gs.A, Gs.B, Gs.C))
    n = A.shape[0]
    scale = max(1.0, np.linalg.norm(A, 1))
    for ev in np.linalg.eigvals(A):
        if (abs(ev) < 1.0 - 1e-9) if domain == "z" else (ev.real < -1e-9 * scale):
            continue
        M = A - ev * np.eye(n)
        for kind, pbh in (("uncontrollable", np.hstack([M, B])),
                          ("unobservable", np.vstack([M, C]))):
            sv = np.linalg.svd(pbh, compute_uv=False)
            if sv[-1] <= 1e-9 * max(scale, sv[0]):
                if domain == "s":
                    where = f"s = {ev:.6g} with Re(s) >= 0"
                else:  # only this domain's z: s = 1 has no bilinear image
                    z = (1 + ev) / (1 - ev) if domain == "bilinear" else ev
                    where = f"z = {z:.6g} with |z| >= 1"
                raise HiddenModeError(
                    f"the {what} has an {kind} mode at {where}: no controller stabilizes "
                    "it (check W1, W2 for pole-zero cancellations with G, or pass a "
                    "minimal realization)")


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
    whose magnitude grows like ``1 / (factor - 1)``;
    :func:`rrr_pin.robust.reduction.reduce_controller` removes it.

    **Discrete time**, ``factor > 1``: solved in discrete time, by the method of SLICOT
    ``SB10ZD`` (``SB10KD`` for ``D = 0``, the routines behind Octave's ``ncfsyn``): two
    discrete Riccati equations, ``gamma_min = sqrt(1 + rho(Q P))`` and SB10ZD's central
    controller (:func:`_ncfsyn_dt`), which reproduces SLICOT's published examples and
    Octave's controller. ``factor == 1``: SB10ZD's ``X`` is singular at the optimum, so
    ``Gs`` is mapped to continuous time by the bilinear map ``z = (1 + s) / (1 - s)``
    (:func:`rrr_pin.robust.lti.to_continuous`), which preserves internal stability and the
    H-infinity norm of the NCF loop, synthesized there with the exact elimination above,
    and mapped back (the same ``gamma_min``; a discrete controller of lower order).

    Parameters
    ----------
    G : control.LTI or array-like
        Plant, ``p`` outputs and ``m`` inputs, continuous or discrete time, proper.
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
        ``factor < 1`` or not finite.
    NonFiniteSystemError, ImproperSystemError, TimebaseMismatchError
        NaN/inf coefficients, an improper plant or weight, mixed timebases
        (:mod:`rrr_pin.robust.lti`), checked before any conversion.
    WeightError
        Non-square or wrongly sized weight.
    HiddenModeError
        ``Gs`` has an unstable mode that is uncontrollable or unobservable.
    SynthesisError
        A Riccati equation has no stabilizing solution, the optimal controller is improper,
        or the loop is not internally stable (numerical failure).

    References
    ----------
    .. [1] McFarlane and Glover (1990, 1992); Skogestad and Postlethwaite (2005), sec. 9.4.2;
       SLICOT ``SB10ID``/``SB10JD`` (descriptor form at the optimum), ``SB10KD``/``SB10ZD``
       (discrete time).

    Examples
    --------
    >>> import control
    >>> from rrr_pin.robust.loopshaping import ncfsyn, fl_plant, lag_weight
    >>> res = ncfsyn(fl_plant(45.0, 1), lag_weight())
    >>> round(res.gamma_min, 4)
    2.1436
    >>> loop = control.feedback(fl_plant(45.0, 1) * res.K)     # negative feedback
    """
    factor = check_real("factor", factor)
    if factor < 1.0:
        raise FieldError("factor", f"{{name}} must be >= 1 (1 = optimal controller), got "
                                   f"{factor!r}")
    G, W1, W2, dt = _plant_and_weights(G, W1, W2)
    Gs = _series(W2, G, W1)
    discrete = _is_discrete(Gs.dt)
    if discrete and factor > 1.0:
        Ks, gamma_min, gamma = _ncfsyn_dt(Gs, factor)
        K = _series(W1, Ks, W2)
        return NCFSynResult(K=K, Ks=Ks, Gs=Gs, W1=W1, W2=W2, gamma=gamma,
                            gamma_min=gamma_min, emax=1.0 / gamma, factor=factor)
    try:
        Gc = to_continuous(Gs) if discrete else Gs
    except ValueError as exc:
        raise SynthesisError(f"shaped plant: {exc}; with factor > 1 the synthesis is done in "
                             "discrete time, without this map") from exc
    _check_hidden_modes(Gc, "bilinear" if discrete else "s")
    Ks_c, gamma_min = _ncfsyn_ct(Gc, factor)
    gamma = ncf_gamma(Gc, Ks_c)
    if not np.isfinite(gamma):
        raise SynthesisError("the synthesized controller does not stabilize the shaped plant")
    if discrete:
        try:
            Ks = to_discrete(Ks_c, Gs.dt)
        except ValueError as exc:
            raise SynthesisError(f"discrete controller: {exc}; use factor > 1") from exc
    else:
        Ks = Ks_c
    K = _series(W1, Ks, W2)
    return NCFSynResult(K=K, Ks=Ks, Gs=Gs, W1=W1, W2=W2, gamma=float(gamma),
                        gamma_min=gamma_min, emax=1.0 / float(gamma), factor=factor)


def _ncfsyn_ct(Gs: control.StateSpace, factor: float):
    """Central controller (negative feedback) and ``gamma_min`` of a continuous ``Gs``."""
    A, B, C, D = (np.asarray(M, dtype=float) for M in (Gs.A, Gs.B, Gs.C, Gs.D))
    n, m = A.shape[0], D.shape[1]
    if n == 0:
        raise SynthesisError("the shaped plant is a static gain; nothing to synthesize")
    X, Z = _riccati_xz(A, B, C, D)
    S = np.eye(m) + D.T @ D
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
    return control.ss(Ak, Bk, -Ck, -Dk), gamma_min        # negative-feedback convention


def _sym_power(M: np.ndarray, e: float) -> np.ndarray:
    """``M^e`` of a symmetric positive-definite matrix (eigendecomposition)."""
    d, V = np.linalg.eigh(0.5 * (M + M.T))
    return (V * d**e) @ V.T


def _ncfsyn_dt(Gs: control.StateSpace, factor: float):
    r"""Discrete central controller (negative feedback), gamma_min and gamma; factor > 1.

    The method of SLICOT ``SB10ZD`` (``SB10KD`` when ``D = 0``; McFarlane and Glover 1992),
    written here with numpy/scipy: with ``R1 = I + D D^T``, ``R2 = I + D^T D`` and
    ``Ar = A - B R2^-1 D^T C``, ``P`` and ``Q`` solve the discrete Riccati equations

    .. math::
        A_r^T P (I + B R_2^{-1} B^T P)^{-1} A_r - P + C^T R_1^{-1} C = 0

        A_r Q (I + C^T R_1^{-1} C Q)^{-1} A_r^T - Q + B R_2^{-1} B^T = 0

    ``gamma_min = sqrt(1 + rho(Q P))``, ``X = ((gamma^2 - 1) I - P Q)^-1 gamma^2 P``, and the
    controller follows SB10ZD's formulas step by step (its ``H``, ``Rx``, ``Bx``, ``Sx``,
    ``F``). ``X`` is singular at the optimum: ``factor == 1`` goes through the bilinear map.
    """
    A, B, C, D = (np.asarray(M, dtype=float) for M in (Gs.A, Gs.B, Gs.C, Gs.D))
    n, (p, m) = A.shape[0], D.shape
    if n == 0:
        raise SynthesisError("the shaped plant is a static gain; nothing to synthesize")
    _check_hidden_modes(Gs, "z")
    R1, R2 = np.eye(p) + D @ D.T, np.eye(m) + D.T @ D
    R1h, R2h = _sym_power(R1, -0.5), _sym_power(R2, -0.5)
    Ar = A - B @ np.linalg.solve(R2, D.T @ C)
    Bt, Ct = B @ R2h, R1h @ C
    try:
        P = sla.solve_discrete_are(Ar, Bt, Ct.T @ Ct, np.eye(m))
        Q = sla.solve_discrete_are(Ar.T, Ct.T, Bt @ Bt.T, np.eye(p))
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise SynthesisError(f"discrete Riccati equation without stabilizing solution: "
                             f"{exc}") from exc
    rho = max(float(np.max(np.linalg.eigvals(Q @ P).real)), 0.0)
    gamma_min = float(np.sqrt(1.0 + rho))
    g2 = (factor * gamma_min) ** 2
    W = R1 + C @ Q @ C.T
    Wh = _sym_power(W, 0.5)
    H = -np.linalg.solve(W, (A @ Q @ C.T + B @ D.T).T).T
    R1D = R1h @ D
    Rx = np.block([[R1 - g2 * np.eye(p), Wh @ R1D], [(Wh @ R1D).T, np.eye(m)]])
    Bx = np.hstack([-H @ Wh, Bt])
    Sx = np.hstack([C.T @ Wh, C.T @ R1D])
    X = np.linalg.solve((g2 - 1.0) * np.eye(n) - P @ Q, g2 * P)
    F = -np.linalg.solve(Rx + Bx.T @ X @ Bx, Sx.T + Bx.T @ X @ A)
    F1, F2 = F[:p], F[p:]
    Dk = -np.linalg.solve(R2 + B.T @ X @ B, D.T - B.T @ X @ H)
    Bk = -H + B @ Dk
    Ck = R2h @ F2 - Dk @ (C + Wh @ F1)
    Ak = A + H @ C + B @ Ck
    Mi = np.linalg.inv(np.eye(m) + Dk @ D)
    Ck, Dk_pos = Mi @ Ck, Mi @ Dk
    Ak = Ak - Bk @ D @ Ck
    Bk = Bk @ np.linalg.inv(np.eye(p) + D @ Dk)
    Ks = control.ss(Ak, Bk, -Ck, -Dk_pos, Gs.dt)            # negative-feedback convention
    loop = ncf_loop(Gs, Ks)
    if not np.all(np.abs(np.linalg.eigvals(loop.A)) < 1.0):
        raise SynthesisError("the discrete controller does not stabilize the shaped plant "
                             "(numerical failure; try a larger factor)")
    gamma = hinf_norm(to_continuous(loop))[0]        # the loop is stable: no pole at z = -1
    return Ks, gamma_min, float(gamma)


def _riccati_xz(A, B, C, D):
    """Stabilizing solutions X (control) and Z (filter) of the NCF Riccati equations."""
    p, m = D.shape
    S = np.eye(m) + D.T @ D
    R = np.eye(p) + D @ D.T
    try:
        X = sla.solve_continuous_are(A, B, C.T @ C, S, s=C.T @ D)
        Z = sla.solve_continuous_are(A.T, C.T, B @ B.T, R, s=B @ D.T)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise SynthesisError(f"Riccati equation without stabilizing solution: {exc}") from exc
    return X, Z


def _inv_sqrt(S: np.ndarray) -> np.ndarray:
    d, V = np.linalg.eigh(0.5 * (S + S.T))
    return (V / np.sqrt(d)) @ V.T


def _graph_symbols_ct(P: control.StateSpace):
    """Return the normalized graph symbols ``[N; M]`` and ``[-Mt, Nt]`` of a continuous P."""
    A, B, C, D = (np.asarray(M, dtype=float) for M in (P.A, P.B, P.C, P.D))
    n, (p, m) = A.shape[0], D.shape
    Ri, Rti = _inv_sqrt(np.eye(m) + D.T @ D), _inv_sqrt(np.eye(p) + D @ D.T)
    if n == 0:
        return static_gain(np.vstack([D @ Ri, Ri])), static_gain(Rti @ np.hstack([-np.eye(p), D]))
    X, Z = _riccati_xz(A, B, C, D)
    F = -np.linalg.solve(np.eye(m) + D.T @ D, B.T @ X + D.T @ C)
    L = -np.linalg.solve(np.eye(p) + D @ D.T, C @ Z + D @ B.T).T
    right = control.ss(A + B @ F, B @ Ri, np.vstack([C + D @ F, F]), np.vstack([D @ Ri, Ri]))
    left = control.ss(A + L @ C, np.hstack([-L, B + L @ D]), Rti @ C,
                      Rti @ np.hstack([-np.eye(p), D]))
    return right, left


def graph_symbols(P) -> tuple[control.StateSpace, control.StateSpace]:
    r"""Return the normalized right and left graph symbols of a plant.

    .. math:: P = N M^{-1} = \tilde M^{-1} \tilde N,\quad
              G = \begin{bmatrix} N \\ M \end{bmatrix},\
              \tilde G = \begin{bmatrix} -\tilde M & \tilde N \end{bmatrix},\quad
              G^\sim G = I,\ \tilde G \tilde G^\sim = I,\ \tilde G G = 0

    With ``R = I + D^T D``, ``Rt = I + D D^T``, the stabilizing Riccati solutions ``X``, ``Z``
    of :func:`ncfsyn`, ``F = -R^{-1}(B^T X + D^T C)`` and ``L = -(Z C^T + B D^T) Rt^{-1}``:
    ``G = (A + B F, B R^{-1/2}, [C + D F; F], [D; I] R^{-1/2})`` and
    ``Gt = (A + L C, [-L, B + L D], Rt^{-1/2} C, Rt^{-1/2} [-I, D])`` (Zhou, Doyle and
    Glover, sec. 13.8).

    Parameters
    ----------
    P : control.LTI
        Stabilizable and detectable plant, ``p x m``, continuous time (discrete plants: pass
        :func:`rrr_pin.robust.lti.to_continuous` of it).

    Returns
    -------
    G : control.StateSpace
        Stable ``(p + m) x m`` right graph symbol ``[N; M]``.
    Gt : control.StateSpace
        Stable ``p x (p + m)`` left graph symbol ``[-Mt, Nt]``.
    """
    P = check_lti(P, "P")
    if _is_discrete(P.dt):
        raise ValueError("graph_symbols takes a continuous-time plant; map a discrete one "
                         "with rrr_pin.robust.lti.to_continuous first")
    _check_hidden_modes(P, what="plant")
    return _graph_symbols_ct(P)


def _loop_pair(P, C):
    """Check a negative-feedback loop ``(P, C)``; return continuous images and the timebase."""
    P, C = check_lti(P, "P"), check_lti(C, "C")
    if (C.noutputs, C.ninputs) != (P.ninputs, P.noutputs):
        raise DimensionMismatchError(
            f"Expected C of shape ({P.ninputs}, {P.noutputs}) for P of shape "
            f"({P.noutputs}, {P.ninputs}), got ({C.noutputs}, {C.ninputs})")
    dt = common_timebase(("P", P), ("C", C))
    Q = np.eye(P.noutputs) + np.asarray(P.D, float) @ np.asarray(C.D, float)
    if np.linalg.cond(Q) > 1e12:
        raise IllPosedLoopError(
            f"the loop is ill-posed: I + D_P D_C is singular (cond {np.linalg.cond(Q):.3g}); "
            f"D_P = {np.asarray(P.D).tolist()}, D_C = {np.asarray(C.D).tolist()}")
    if _is_discrete(dt):
        P, C = to_continuous(P), to_continuous(C)
    return P, C, dt


def _to_frequency(wc: float, dt) -> float:
    """Return the frequency of the original system for a continuous-image frequency ``wc``."""
    if not _is_discrete(dt):
        return wc
    return 2.0 * np.arctan(wc) / (1.0 if dt is True else dt)     # arctan(inf) = pi / 2


def ncfmargin(P, C, sign: int = -1) -> tuple[float, float]:
    r"""Return the NCF stability margin ``b(P, C)`` of a feedback loop.

    .. math:: b(P, C) = \left\| \begin{bmatrix} I \\ C \end{bmatrix} (I + P C)^{-1}
              \begin{bmatrix} I & P \end{bmatrix} \right\|_\infty^{-1}
              \text{ if the loop is internally stable, else } 0

    ``b(P, C) = b(C, P)``. Every plant ``P1 = (N + dN)(M + dM)^{-1}`` with
    ``||[dN; dM]||_inf < b`` (normalized factors of ``P``), and every plant with
    ``nugap(P, P1) < b``, is stabilized by ``C`` (Vinnicombe 2001, th. 3.8).

    Parameters
    ----------
    P : control.LTI
        Plant, ``p x m``; continuous or discrete time.
    C : control.LTI or array-like
        Controller, ``m x p``, same timebase.
    sign : {-1, +1}, default -1
        Feedback sign, as MATLAB's ``ncfmargin(P, C, sign)``: ``-1`` for ``u = -C y`` (this
        package's convention), ``+1`` for ``u = +C y`` (the controllers MATLAB's ``ncfsyn``
        returns); ``ncfmargin(P, C, +1) == ncfmargin(P, -C)``.

    Returns
    -------
    b : float
        Margin in ``[0, 1]``; 0 when the loop is not internally stable.
    freq : float
        Frequency where ``1 / b`` peaks [rad/s; rad per sample when ``dt`` is True];
        ``nan`` for an unstable loop.

    Raises
    ------
    DimensionMismatchError, TimebaseMismatchError, IllPosedLoopError,
    NonFiniteSystemError, ImproperSystemError
        See :mod:`rrr_pin.robust.lti`.

    References
    ----------
    .. [1] MATLAB Robust Control Toolbox ``ncfmargin`` (default sign -1, the same loop);
       Vinnicombe (2001) sec. 1.4; McFarlane and Glover (1990).

    Examples
    --------
    >>> import control
    >>> from rrr_pin.robust.ncf import ncfmargin
    >>> round(ncfmargin(control.tf(4, [1, -0.001]), 1.0)[0], 4)     # MATLAB doc: 0.7069
    0.7069
    """
    if isinstance(sign, bool) or sign not in (-1, 1):
        raise FieldError("sign", f"{{name}} must be -1 (u = -C y) or +1 (u = +C y), got "
                                 f"{sign!r}")
    P, C, dt = _loop_pair(P, C)
    gamma, w = hinf_norm(ncf_loop(P, C if sign == -1 else -C))
    if not np.isfinite(gamma):
        return 0.0, float("nan")
    return 1.0 / gamma, float(_to_frequency(w, dt))


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




# --- two degrees of freedom ---------------------------------------------------------------------

@dataclass(frozen=True)
class NCF2DOFResult:
    r"""Result of :func:`ncfsyn_2dof`: the prefilter ``K1`` and the feedback ``K2``.

    The control law is ``u = K1 r - K2 y`` (python-control's negative feedback on ``y``; the
    form of Skogestad & Postlethwaite and RobustAndOptimalControl.jl is ``u = K1 r + K2' y``
    with ``K2' = -K2``), and the closed loop from ``r`` to ``y`` is :attr:`CL`.

    Attributes
    ----------
    K : control.StateSpace
        The whole controller ``u = K [r; y] = W1 Ks [Wi r; W2 y]``, shape (m, mr + p), one
        realization (the weights' states shared by both blocks); :attr:`K1` and :attr:`K2`
        are its blocks, ``K = [K1, -K2]``.
    Ks : control.StateSpace
        The H-infinity controller of the shaped plant, inputs ``[r; ys]`` (positive feedback
        on ``ys = W2 y``), output the shaped plant's input, without ``Wi``.
    Gs, Tref, W1, W2 : control.StateSpace
        Shaped plant ``W2 G W1``, reference model, weights actually used.
    Wi : ndarray, shape (mr, mr)
        Static prefilter that makes the steady-state closed loop equal ``Tref(0)``
        (identity when ``match_dc`` is False).
    rho : float
        Model-matching weight (``rho = 0``: the 1-DOF design; larger: closer to ``Tref``).
    gamma : float
        Achieved H-infinity norm of the generalized closed loop (eq. 9.84 of S&P), checked by
        :func:`control.linfnorm`.
    gamma_opt : float
        Optimal value found by SLICOT ``SB10AD``'s bisection (tolerance 1e-3).
    factor : float
        Requested ``gamma / gamma_opt``.
    G : control.StateSpace
        The plant.
    """

    K: control.StateSpace
    Ks: control.StateSpace
    Gs: control.StateSpace
    Tref: control.StateSpace
    W1: control.StateSpace
    W2: control.StateSpace
    Wi: np.ndarray
    rho: float
    gamma: float
    gamma_opt: float
    factor: float
    G: control.StateSpace

    @property
    def K1(self) -> control.StateSpace:
        """Reference block of :attr:`K`, shape (m, mr): ``u = K1 r - K2 y``."""
        K, mr = self.K, self.Tref.ninputs
        return control.ss(K.A, K.B[:, :mr], K.C, K.D[:, :mr])

    @property
    def K2(self) -> control.StateSpace:
        """Feedback block, shape (m, p), for negative feedback: ``u = K1 r - K2 y``."""
        K, mr = self.K, self.Tref.ninputs
        return control.ss(K.A, K.B[:, mr:], -K.C, -K.D[:, mr:])

    @property
    def CL(self) -> control.StateSpace:
        """Closed loop ``y = (I + G K2)^-1 G K1 r`` [shape (p, mr)], one realization of ``K``."""
        return _close_2dof(self.G, self.K, self.Tref.ninputs)

    def __iter__(self):
        """``K1, K2, gamma, info``."""
        return iter((self.K1, self.K2, self.gamma, self))


def _check_biproper(name: str, W: control.StateSpace) -> None:
    """WeightError unless ``W``'s ``D`` is invertible (``cond(D) <= 1e12``)."""
    D = np.asarray(W.D, dtype=float)
    cond = float(np.linalg.cond(D)) if D.size else np.inf
    if not cond <= 1e12:
        raise WeightError(f"{name} must be biproper (an invertible D), got D = {D.tolist()} "
                          f"(cond {cond:.3g}): ncfsyn_2dof's steady-state prefilter "
                          f"(match_dc) inverts it; give match_dc=False or a biproper {name}")


def _inv_lti(W: control.StateSpace) -> control.StateSpace:
    A, B, C, D = (np.asarray(M, float) for M in (W.A, W.B, W.C, W.D))
    Di = np.linalg.inv(D)
    return control.ss(A - B @ Di @ C, B @ Di, -Di @ C, Di)


def _check_reference_model(Tref, p: int) -> control.StateSpace:
    Tref = check_lti(Tref, "Tref")
    if _is_discrete(Tref.dt):
        raise FieldError("Tref", "{name} must be continuous time (ncfsyn_2dof is continuous "
                                 "only), got dt = " + repr(Tref.dt))
    if Tref.noutputs != p:
        raise FieldError("Tref", f"{{name}} must have {p} outputs (one per plant output), got "
                                 f"{Tref.noutputs} x {Tref.ninputs}")
    poles = np.linalg.eigvals(np.asarray(Tref.A, float)) if Tref.nstates else np.zeros(0)
    bad = poles[poles.real >= 0.0]
    if bad.size:
        raise FieldError("Tref", f"{{name}}, the reference model, must be stable, got poles "
                                 f"{', '.join(f'{z:.4g}' for z in bad)} with Re(s) >= 0")
    return Tref


def ncfsyn_2dof(G, Tref, rho: float = 1.1, W1=None, W2=None, *, factor: float = 1.1,
                match_dc: bool = True) -> NCF2DOFResult:
    r"""Two-degrees-of-freedom Glover-McFarlane loop-shaping design (Hoyle, Hyde & Limebeer).

    For the shaped plant ``Gs = W2 G W1 = (As, Bs, Cs, Ds)`` with normalized left coprime
    factors ``Gs = Ms^-1 Ns``, the controller ``Ks = [K1s  K2s]`` (inputs ``[r; ys]``)
    minimizes the H-infinity norm from ``[r; phi]`` to ``[us; ys; e]`` (S&P eq. 9.84)

    .. math::
        \begin{bmatrix} u_s \\ y_s \\ e \end{bmatrix} =
        \begin{bmatrix} \rho (I - K_{2s} G_s)^{-1} K_{1s} & K_{2s} (I - G_s K_{2s})^{-1} M_s^{-1} \\
        \rho (I - G_s K_{2s})^{-1} G_s K_{1s} & (I - G_s K_{2s})^{-1} M_s^{-1} \\
        \rho^2 [(I - G_s K_{2s})^{-1} G_s K_{1s} - T_{ref}] & \rho (I - G_s K_{2s})^{-1} M_s^{-1}
        \end{bmatrix}
        \begin{bmatrix} r \\ \phi \end{bmatrix}

    with the generalized plant of S&P Table 9.3 (``Zs`` the filter Riccati solution of
    :func:`ncfsyn`, ``Rs = I + Ds Ds^T``), solved by SLICOT ``SB10AD`` (via slycot): first its
    bisection for ``gamma_opt``, then the sub-optimal controller at ``gamma = factor *
    gamma_opt``. With ``match_dc``, a constant prefilter ``Wi`` (S&P eq. 9.89) makes the
    steady-state closed loop equal ``Tref(0)``. ``rho`` trades robustness (``rho -> 0``: the
    1-DOF design of :func:`ncfsyn`) against model matching.

    Parameters
    ----------
    G : control.LTI
        Plant, ``p`` outputs and ``m`` inputs, continuous time, proper.
    Tref : control.LTI
        Reference model, ``p x mr``, continuous time, proper and stable (the desired closed
        loop from ``r`` to ``y``).
    rho : float, default 1.1
        Model-matching weight, > 0 (S&P: usually ``1 < rho < 3``).
    W1 : control.LTI, optional
        Pre-compensator, ``m x m`` or SISO (may be strictly proper, as ``1/s``); default
        identity.
    W2 : control.LTI, optional
        Post-compensator, ``p x p`` or SISO; default identity. With ``match_dc``, biproper
        (an invertible ``D``: the prefilter inverts it).
    factor : float, default 1.1
        ``gamma / gamma_opt``, > 1 (as RobustAndOptimalControl.jl's ``gamma = 1.1``).
    match_dc : bool, default True
        Add the steady-state prefilter ``Wi``.

    Returns
    -------
    NCF2DOFResult
        ``K1`` (reference), ``K2`` (negative feedback), ``gamma``, ``CL``; unpacks as
        ``K1, K2, gamma, info``.

    Raises
    ------
    FieldError
        ``Tref`` improper (an :class:`ImproperSystemError` from the LTI checks), unstable,
        discrete or with the wrong number of outputs; ``rho`` not > 0; ``factor`` not > 1.
    NonFiniteSystemError, ImproperSystemError, TimebaseMismatchError, WeightError
        The checks of :func:`ncfsyn` on ``G``, ``W1``, ``W2``; with ``match_dc``, a ``W2``
        whose ``D`` is singular (``WeightError``).
    SynthesisError
        No stabilizing controller found (SLICOT failure), or the loop is not stable.

    References
    ----------
    .. [1] D. J. Hoyle, R. A. Hyde and D. J. N. Limebeer, "An H-infinity approach to two
       degree of freedom design", Proc. 30th IEEE CDC, 1991, 1581-1585.
    .. [2] Skogestad and Postlethwaite (2005), sec. 9.4.3, Table 9.3.
    .. [3] RobustAndOptimalControl.jl, ``glover_mcfarlane_2dof`` (the same generalized plant).
    """
    rho = check_positive("rho", rho)
    factor = check_real("factor", factor)
    if not factor > 1.0:
        raise FieldError("factor", f"{{name}} must be > 1 (gamma / gamma_opt of the sub-optimal "
                                   f"controller), got {factor!r}")
    G, W1, W2, dt = _plant_and_weights(G, W1, W2)
    if _is_discrete(dt):
        raise FieldError("G", "{name} must be continuous time (ncfsyn_2dof is continuous only)")
    if match_dc:
        _check_biproper("W2", W2)
    Tref = _check_reference_model(Tref, G.noutputs)
    Gs = _series(W2, G, W1)
    _check_hidden_modes(Gs)
    As, Bs, Cs, Ds = (np.asarray(M, dtype=float) for M in (Gs.A, Gs.B, Gs.C, Gs.D))
    Ar, Br, Cr, Dr = (np.asarray(M, dtype=float) for M in (Tref.A, Tref.B, Tref.C, Tref.D))
    ns, nr = As.shape[0], Ar.shape[0]
    ls, ms = Ds.shape
    mr = Dr.shape[1]
    _, Zs = _riccati_xz(As, Bs, Cs, Ds)
    sRs = sla.sqrtm(np.eye(ls) + Ds @ Ds.T).real
    Z = np.zeros
    A = sla.block_diag(As, Ar)
    B1 = np.block([[Z((ns, mr)), (Bs @ Ds.T + Zs @ Cs.T) @ np.linalg.inv(sRs)],
                   [Br, Z((nr, ls))]])
    B2 = np.vstack([Bs, Z((nr, ms))])
    C1 = np.block([[Z((ms, ns + nr))], [Cs, Z((ls, nr))], [rho * Cs, -rho ** 2 * Cr]])
    C2 = np.block([[Z((mr, ns + nr))], [Cs, Z((ls, nr))]])
    D11 = np.block([[Z((ms, mr + ls))], [Z((ls, mr)), sRs], [-rho ** 2 * Dr, rho * sRs]])
    D12 = np.vstack([np.eye(ms), Ds, rho * Ds])
    D21 = np.block([[rho * np.eye(mr), Z((mr, ls))], [Z((ls, mr)), sRs]])
    D22 = np.vstack([Z((mr, ms)), Ds])
    B, C = np.hstack([B1, B2]), np.vstack([C1, C2])
    D = np.block([[D11, D12], [D21, D22]])
    Ks, gamma_opt = _hinf_suboptimal(A, B, C, D, ncon=ms, nmeas=mr + ls, factor=factor)
    P = control.ss(A, B, C, D)
    CLg = P.lft(Ks, nu=ms, ny=mr + ls)            # u = Ks y, SLICOT's positive feedback
    if np.any(np.real(CLg.poles()) >= 0):
        raise SynthesisError("the 2-DOF controller does not stabilize the generalized plant")
    gamma = float(control.linfnorm(CLg)[0])
    Wi = np.eye(mr)
    if match_dc:
        ys = _close_2dof(Gs, Ks, mr)                      # r -> ys with u = Ks [r; ys]
        dc = _dcgain(_series(_inv_lti(W2), ys))
        Wi = np.linalg.lstsq(dc, _dcgain(Tref), rcond=None)[0]
    K = _series(W1, Ks, control.append(static_gain(Wi), W2))
    return NCF2DOFResult(K=K, Ks=Ks, Gs=Gs, Tref=Tref, W1=W1, W2=W2, Wi=Wi, rho=rho,
                         gamma=gamma, gamma_opt=gamma_opt, factor=factor, G=G)


def _close_2dof(G: control.StateSpace, K: control.StateSpace, mr: int) -> control.StateSpace:
    """Return the closed loop ``r -> y`` of ``y = G u``, ``u = K [r; y]`` (``K``'s own sign)."""
    p = G.noutputs
    route = static_gain(np.vstack([np.zeros((mr, p)), -np.eye(p)]))
    loop = control.feedback(control.ss(G * K), route, sign=-1)
    return control.ss(loop.A, loop.B[:, :mr], loop.C, loop.D[:, :mr])


def _dcgain(sys: control.StateSpace) -> np.ndarray:
    """``C (-A)^-1 B + D`` of a stable continuous system."""
    A, B, C, D = (np.asarray(M, dtype=float) for M in (sys.A, sys.B, sys.C, sys.D))
    return D + C @ np.linalg.solve(-A, B) if A.size else D


#: Tolerance of SB10AD's bisection on gamma_opt (its GTOL; the controller is then sub-optimal
#: at ``factor * gamma_opt``, factor > 1, so this accuracy is ample).
_GTOL = 1e-3


def _hinf_suboptimal(A, B, C, D, ncon: int, nmeas: int, factor: float):
    """SLICOT ``SB10AD``: ``gamma_opt`` by bisection, then the controller at ``factor`` times it."""
    from slycot import sb10ad
    from slycot.exceptions import SlycotError

    n, m, np_ = A.shape[0], B.shape[1], C.shape[0]

    def solve(gamma, job):
        return sb10ad(n, m, np_, ncon, nmeas, gamma, A, B, C, D, job=job, gtol=_GTOL)

    # SB10AD bisects from the gamma it is given: from 1e100 that is ~340 steps. Start from the
    # first power of 10 (from 10) that admits a controller, ~15 steps.
    start = 10.0
    try:
        while True:
            try:
                solve(start, 4)
                break
            except SlycotError:
                if start >= 1e12:
                    raise
                start *= 10.0
        gamma_opt = solve(start, 1)[0]
        out = solve(factor * gamma_opt, 4)
    except (SlycotError, ValueError, np.linalg.LinAlgError) as exc:
        raise SynthesisError(f"2-DOF H-infinity synthesis (SLICOT SB10AD) failed: {exc}") from exc
    return control.ss(*out[1:5]), float(gamma_opt)

"""H-infinity loop shaping of the feedback-linearized arm (paper section 4).

The feedback-linearized plant (eq. 11), the loop-shaping weights (eq. 16-17), :func:`loopsyn`
(loop shaping to a target loop shape) and the whole design of the paper, :func:`design`.
The concepts it builds on live in their own modules and are re-exported here for existing
callers: barriers (:mod:`rrr_pin.robust.barriers`, eq. 12-15), McFarlane-Glover synthesis and
the NCF margin (:mod:`rrr_pin.robust.ncf`), gap metrics (:mod:`rrr_pin.robust.gap`), controller
reduction (:mod:`rrr_pin.robust.reduction`, eq. 18) and LTI validation
(:mod:`rrr_pin.robust.lti`).

Conventions (used everywhere in rrr-pin):

* Every controller is for python-control's **negative** feedback, ``u = K (r - y)``: the loop
  of ``G`` and ``K`` is ``control.feedback(G * K)``. MATLAB's and Octave's ``ncfsyn`` and
  SLICOT's ``SB10ID`` return the positive-feedback controller, which is ``-K``.
* Shaped plant ``Gs = W2 G W1``, loop-shaping controller ``K = W1 Ks W2``.
* Frequencies in rad/s.

References
----------
.. [1] The paper: "H-infinity control + feedback linearization of a 3-DOF RRR spatial serial
   mechanism", section 4, eq. (11)-(18).
.. [2] D. McFarlane and K. Glover, "A loop shaping design procedure using H-infinity
   synthesis", IEEE Trans. Automat. Control 37(6), 759-769, 1992.
.. [3] S. Skogestad and I. Postlethwaite, *Multivariable Feedback Control: Analysis and
   Design*, 2nd ed., Wiley, 2005, sec. 9.4.
.. [4] MathWorks, Robust Control Toolbox, ``loopsyn`` (meaning of ``alpha``).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import control
import numpy as np
import scipy.linalg as sla

from ..validation import FieldError, check_count, check_positive, check_real, check_size
from .barriers import (
    PAPER_MODEL_ERROR,
    PAPER_PERFORMANCE_SPECS,
    _specs,
    robust_performance_barrier,
    robust_stability_barrier,
)
from .lti import DimensionMismatchError, ImproperSystemError, check_lti, expand_diagonal
from .ncf import (
    NCFSynResult,
    SynthesisError,
    WeightError,
    _weight,
    ncfmargin,
    ncfsyn,
)
from .reduction import (
    NCFReduction,
    ReductionGuarantee,
    ncf_reduce,
    reduce_controller,
    reduction_guarantee,
)
from .robustness import (
    CheckResult,
    check_robust_performance,
    check_robust_stability,
    ncf_gamma,
)

__all__ = [
    "fl_plant",
    "lag_weight",
    "zpk_data",
    "LoopsynResult",
    "loopsyn",
    "Design",
    "design",
    "LAM_RANGE",
    "MAX_JOINTS",
]

#: Paper eq. (16): lag compensator W1 = 25 (s + 11.5) / (s + 0.19).
PAPER_W1 = (25.0, 11.5, 0.19)

#: Range of ``lam`` [rad/s] that :func:`design` accepts. With the paper's weights the synthesis
#: was measured to succeed from 1e-7 to 5e7 rad/s and to fail at 1e-8 and 1e8 rad/s (the
#: shaped plant's poles, ``-lam`` and ``-0.19`` of W1, then lie so far apart that the Riccati
#: solutions lose all accuracy: "improper controller", a spurious "uncontrollable mode", or
#: no stabilizing solution); the range keeps a decade inside both ends.
LAM_RANGE = (1e-6, 1e7)

#: Largest joint count of :func:`design` (it builds n x n block-diagonal systems: 1000 joints
#: take 1.6 s; 1e5 joints would need 75 GiB per matrix).
MAX_JOINTS = 1000

# Re-exported names that live in other modules (kept importable from here).
_REEXPORTED = (PAPER_MODEL_ERROR, sla, ncf_gamma)


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
    return _fl_plant(check_positive("lam", lam, unit="rad/s"), check_size("n", n))


def _fl_plant(lam: float, n: int) -> control.StateSpace:
    """:func:`fl_plant` of a checked ``lam`` [rad/s] and ``n``."""
    g = control.ss(control.tf([lam**2], [1.0, 2.0 * lam, lam**2]))
    return expand_diagonal(g, n)


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
    k = check_positive("k", k)
    z, p = check_positive("z", z, unit="rad/s"), check_positive("p", p, unit="rad/s")
    return control.tf([k, k * z], [1.0, p])



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
    K = check_lti(K, "K")
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
        return check_lti(default, name)
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
    return control.ss(W.A, W.B[:, :1], W.C[:1, :], W.D[:1, :1], W.dt)


@dataclass(frozen=True)
class LoopsynResult:
    """Result of :func:`loopsyn` (negative-feedback controllers).

    Attributes
    ----------
    K : control.StateSpace
        Controller for ``G``, ``K = W1 Ks`` with ``W1 = G^-1 Gd``.
    Ks : control.StateSpace
        Controller of the shaped plant ``Gs = G W1 = Gd``.
    W1 : control.StateSpace
        Pre-compensator ``G^-1 Gd``.
    Gs : control.StateSpace
        Shaped plant, equal to the target ``Gd``.
    b : float
        Achieved margin ``b(Gs, Ks)``, at least ``alpha * b_max``.
    b_max : float
        Largest achievable margin ``1 / gamma_min`` of ``Gs`` (ncfsyn).
    margin : float
        ``ncfmargin(G, K)`` of the unweighted loop.
    fit : float
        Relative loop-shape error ``sup_w |(G K - Gd) / Gd| = ||Ks - 1||_Linf`` (0 = exact).
    blend : float
        ``t`` in ``Ks = (1 - t) + t Ks_opt`` (0: ``G K = Gd`` exactly, 1: ncfsyn).
    alpha : float
        The requested trade-off.
    """

    K: control.StateSpace
    Ks: control.StateSpace
    W1: control.StateSpace
    Gs: control.StateSpace
    b: float
    b_max: float
    margin: float
    fit: float
    blend: float
    alpha: float


def _linf_grid(sys: control.StateSpace) -> np.ndarray:
    """Dense frequency grid [rad/s] around the poles and zeros of ``sys``."""
    mags = np.abs(np.concatenate([sys.poles(), sys.zeros()]))
    mags = mags[mags > 0]
    lo = np.log10(mags.min()) - 3 if mags.size else -3
    hi = np.log10(mags.max()) + 3 if mags.size else 3
    return np.logspace(lo, hi, 4000)


def loopsyn(G, Gd, alpha: float = 0.5) -> LoopsynResult:
    r"""Loop shaping to a target loop ``Gd``, trading the fit against robustness (SISO).

    MATLAB's meaning of ``alpha``: the margin is kept at least ``alpha`` times the largest
    achievable one, and within that the fit to ``Gd`` is made as good as possible; ``alpha
    = 1`` is the pure ncfsyn (Glover-McFarlane) design, ``alpha = 0`` the best fit.

    Here the pre-compensator ``W1 = G^{-1} G_d`` makes the shaped plant the target,
    ``Gs = G W1 = Gd``, with the optimal ncfsyn controller ``Ks_opt`` (margin
    ``b_max = 1/gamma_min``). Along the segment

    .. math:: K_s(t) = (1 - t) + t K_{s,\mathrm{opt}},\qquad K = W_1 K_s(t),\qquad
              G K = G_d K_s(t),\qquad
              \text{fit}(t) = \left\| \frac{G K - G_d}{G_d} \right\|_{L_\infty}
                         = t\, \| K_{s,\mathrm{opt}} - 1 \|_{L_\infty}

    the smallest ``t`` with ``b(Gs, Ks(tau)) >= alpha b_max`` for every ``tau >= t`` is
    chosen (a 101-point grid in ``t``, refined by bisection). This is a one-parameter
    search, not MATLAB's mixed-sensitivity optimization: the same trade-off, not the same
    controller. The L-infinity norm is taken on a dense frequency grid.

    Parameters
    ----------
    G : control.LTI
        SISO continuous-time plant; stable and minimum phase, since ``W1 = G^-1 Gd``
        cancels its poles and zeros.
    Gd : control.LTI
        SISO target loop shape; must roll off at least as fast as ``G`` (``W1`` proper).
    alpha : float
        Trade-off in ``[0, 1]`` (default 0.5, as MATLAB).

    Returns
    -------
    LoopsynResult
        ``K``, the achieved margin ``b`` (and ``margin`` on ``G``), the ``fit``.

    Raises
    ------
    DimensionMismatchError
        ``G`` or ``Gd`` not SISO.
    ImproperSystemError
        ``Gd`` rolls off slower than ``G``.
    SynthesisError
        The cancellation in ``W1`` leaves the loop of ``G`` and ``K`` internally unstable
        (``G`` unstable or non-minimum phase).

    References
    ----------
    .. [1] MATLAB Robust Control Toolbox ``loopsyn`` (alpha); McFarlane and Glover (1992);
       Skogestad and Postlethwaite (2005), sec. 9.4.
    """
    alpha = check_real("alpha", alpha)
    if not 0.0 <= alpha <= 1.0:
        raise ValueError(f"alpha must be in [0, 1], got {alpha!r}")
    G, Gd = check_lti(G, "G"), check_lti(Gd, "Gd")
    for name, sys in (("G", G), ("Gd", Gd)):
        if (sys.noutputs, sys.ninputs) != (1, 1):
            raise DimensionMismatchError(
                f"loopsyn supports SISO systems; {name} is {sys.noutputs} x {sys.ninputs} "
                "(use ncfsyn with weights for MIMO plants)")
        if sys.dt not in (0, None):
            raise ValueError(f"loopsyn takes continuous-time systems; {name} has dt={sys.dt!r}")
    g, gd = control.tf(G), control.tf(Gd)
    num = np.polymul(np.atleast_1d(gd.num[0][0]), np.atleast_1d(g.den[0][0]))
    den = np.polymul(np.atleast_1d(gd.den[0][0]), np.atleast_1d(g.num[0][0]))
    num, den = np.trim_zeros(num, "f"), np.trim_zeros(den, "f")
    if num.size > den.size:
        raise ImproperSystemError(
            "Gd must roll off at least as fast as G: W1 = G^-1 Gd would be improper "
            f"(relative degree of G {g.den[0][0].size - np.trim_zeros(g.num[0][0], 'f').size}"
            f" > relative degree of Gd)")
    W1 = control.ss(control.minreal(control.tf(num, den), verbose=False))
    Gs = control.ss(Gd)
    opt = ncfsyn(Gs)
    b_max = 1.0 / opt.gamma_min
    one = control.ss([], [], [], [[1.0]])

    def Ks_at(t):
        return control.ss(control.parallel(opt.Ks * t, one * (1.0 - t)))

    def b_at(t):
        return ncfmargin(Gs, Ks_at(t))[0]

    target = alpha * b_max * (1 - 1e-9)
    ts = np.linspace(0.0, 1.0, 101)
    ok = np.array([b_at(t) >= target and b_at(t) > 0 for t in ts])
    bad = np.nonzero(~ok)[0]
    if bad.size == 0:
        t = 0.0
    else:
        lo, hi = ts[bad[-1]], ts[bad[-1] + 1]
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if b_at(mid) >= target and b_at(mid) > 0 else (mid, hi)
        t = hi
    Ks = Ks_at(t)
    K = control.ss(W1 * Ks)
    margin = ncfmargin(G, K)[0]
    if margin <= 0.0:
        raise SynthesisError("W1 = G^-1 Gd cancels an unstable pole or zero of G: the loop of "
                             "G and K is not internally stable (loopsyn needs a stable, "
                             "minimum-phase G)")
    w = _linf_grid(control.ss(opt.Ks))
    dev = np.abs(np.asarray(opt.Ks(1j * w)).ravel() - 1.0).max()
    return LoopsynResult(K=K, Ks=Ks, W1=W1, Gs=Gs, b=float(b_at(t)), b_max=float(b_max),
                         margin=float(margin), fit=float(t * dev), blend=float(t),
                         alpha=alpha)


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
        ``n x n`` synthesis (``K``, ``Ks``, ``Gs``, ``gamma``, ``gamma_min``, ``emax``): the
        diagonal copy of the SISO synthesis, which is the MIMO synthesis of the decoupled
        plant (its Riccati solutions are block diagonal).
    K_full : control.StateSpace
        SISO full-order controller ``W1 Ks W2`` of one joint, ``u = K (r - y)``.
    K_reduced : control.StateSpace
        SISO reduced controller (eq. 18), same convention.
    gamma_reduced : float
        NCF index of ``K_reduced`` on the shaped plant, ``ncf_gamma(Gs, W1^-1 K W2^-1)``
        ``= 1 / reduction_shaped.b_reduced``.
    RSB, RPB : control.TransferFunction
        Robust-stability and robust-performance barriers (eq. 13 and 15).
    w_performance : float
        Upper end [rad/s] of the performance band (``omega_p``, 100 rad/s).
    robust_stability, robust_performance : CheckResult
        Barrier checks of sec. 4.4 on ``G`` with ``K_reduced`` per joint.
    reduction : ReductionGuarantee
        Guarantee of the eq. (18) reduction on the loop of ``G`` (one joint): ``b(G,
        K_full)``, ``nugap(K_full, K_reduced)``, the guaranteed and the achieved
        ``b(G, K_reduced)`` (the NCF margin of the final loop).
    reduction_shaped : ReductionGuarantee
        The same guarantee on the shaped loop: ``b(Gs, Ks) = 1/gamma``,
        ``nugap(Ks, W1^-1 K_reduced W2^-1)`` and ``b(Gs, Ks_reduced) = 1/gamma_reduced``.
    ncf_reduction : NCFReduction
        The alternative reduction of ``K_full`` to ``order`` states by balanced truncation
        of its normalized coprime factors, with its guarantee (on the loop of ``G``).
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
    reduction: ReductionGuarantee
    reduction_shaped: ReductionGuarantee
    ncf_reduction: NCFReduction

    @property
    def K(self) -> control.StateSpace:
        """``n x n`` reduced controller ``diag(K_reduced)`` (eq. 18 times ``I_n``)."""
        return expand_diagonal(self.K_reduced, self.n)

    @property
    def Ks_reduced(self) -> control.StateSpace:
        """SISO reduced controller of the shaped plant, ``W1^-1 K_reduced W2^-1``."""
        return control.ss(_inv(_siso(self.W1)) * self.K_reduced * _inv(_siso(self.W2)))

    @property
    def ncfmargin(self) -> float:
        """NCF margin ``b(G, K)`` of the final loop (plant and reduced controller)."""
        return self.reduction.b_reduced


def _siso(W: control.StateSpace) -> control.StateSpace:
    """First diagonal block of a diagonal copy made by :func:`expand_diagonal`."""
    k = W.nstates // W.noutputs if W.noutputs else 0
    return control.ss(W.A[:k, :k], W.B[:k, :1], W.C[:1, :k], W.D[:1, :1])


def design(lam: float = 45.0, n: int = 3, factor: float = 1.0, W1=None, W2=None,
           order: int = 2, specs=PAPER_PERFORMANCE_SPECS,
           model_error=PAPER_MODEL_ERROR) -> Design:
    """H-infinity loop-shaping design of paper section 4, defaults = the paper.

    Steps: barriers from the requirements (eq. 12-15), shaped plant ``W2 G W1`` (eq. 11,
    16-17), :func:`ncfsyn` (sec. 4.3), reduction to ``order`` states (eq. 18) with its
    guarantee, and the robustness checks of sec. 4.4. The plant is decoupled with identical
    channels, so everything is computed on one joint and copied on the diagonal: the
    ``n x n`` synthesis, singular values and margins equal the SISO ones, and the cost does
    not grow with ``n``.

    Parameters
    ----------
    lam : float
        Natural frequency [rad/s] of the feedback-linearizing loop (paper: 45), in
        :data:`LAM_RANGE`.
    n : int
        Number of joints (paper: 3).
    factor : float
        ``gamma / gamma_min`` of :func:`ncfsyn` (1 = optimal, as in the paper).
    W1, W2 : control.LTI, optional
        SISO weights (applied per joint) or ``n x n`` diagonal copies; defaults
        ``25 (s + 11.5) / (s + 0.19)`` and 1 (eq. 16-17).
    order : int
        States of the reduced controller (paper: 2), at most the full-order controller's
        (3 with the paper's weights; more is refused).
    specs : sequence of (float, float), shape (k, 2)
        Performance specs ``(error, omega [rad/s])`` (eq. 14).
    model_error : (float, float)
        Model-error bound ``(relative error, omega [rad/s])`` (eq. 12).

    Returns
    -------
    Design

    Raises
    ------
    ValueError
        ``lam`` not finite or outside :data:`LAM_RANGE`, ``n`` not an integer in
        ``[1, MAX_JOINTS]`` (:data:`MAX_JOINTS`), ``factor``
        not finite or below 1 (each a ``FieldError`` naming the field).
    """
    lam, n = check_positive("lam", lam, unit="rad/s"), check_count("n", n, 1, high=MAX_JOINTS)
    order = check_count("order", order)
    if not LAM_RANGE[0] <= lam <= LAM_RANGE[1]:
        raise FieldError("lam", f"{{name}} must be in [{LAM_RANGE[0]:g}, {LAM_RANGE[1]:g}] "
                                f"rad/s (LAM_RANGE, where the synthesis is well conditioned), "
                                f"got {lam!r}")
    rel_error, w_error = model_error
    RSB = robust_stability_barrier(rel_error, w_error)
    RPB = robust_performance_barrier(specs, rel_error, w_error)
    w_performance = _specs(specs)[1]
    w1 = _siso_weight("W1", W1, n, lag_weight())
    w2 = _siso_weight("W2", W2, n, np.eye(1))
    g = _fl_plant(lam, 1)
    siso = ncfsyn(g, w1, w2, factor)
    if order > siso.K.nstates:
        raise FieldError("order", f"{{name}} = {order} is more states than the full-order "
                                  f"controller has ({siso.K.nstates}): give at most "
                                  f"{siso.K.nstates}")
    K_reduced = reduce_controller(siso.K, order)
    reduction_shaped = reduction_guarantee(siso.Gs, siso.Ks, _inv(w1) * K_reduced * _inv(w2))
    b_reduced = reduction_shaped.b_reduced                  # b = 1 / gamma, 0 if unstable
    gamma_reduced = 1.0 / b_reduced if b_reduced > 0.0 else float("inf")
    if not gamma_reduced <= 1.05 * siso.gamma:
        warnings.warn(f"the {order}-state reduced controller raises gamma from "
                      f"{siso.gamma:.4g} to {gamma_reduced:.4g}; consider a larger order",
                      RuntimeWarning, stacklevel=2)
    ncf = NCFSynResult(K=expand_diagonal(siso.K, n), Ks=expand_diagonal(siso.Ks, n),
                       Gs=expand_diagonal(siso.Gs, n), W1=expand_diagonal(w1, n),
                       W2=expand_diagonal(w2, n), gamma=siso.gamma, gamma_min=siso.gamma_min,
                       emax=siso.emax, factor=siso.factor)
    return Design(
        lam=lam, n=n, factor=siso.factor, G=_fl_plant(lam, n), W1=ncf.W1, W2=ncf.W2,
        Gs=ncf.Gs, ncf=ncf, K_full=siso.K, K_reduced=K_reduced,
        gamma_reduced=float(gamma_reduced), RSB=RSB, RPB=RPB, w_performance=w_performance,
        robust_stability=check_robust_stability(g, K_reduced, RSB),
        robust_performance=check_robust_performance(g, K_reduced, RPB, w_max=w_performance),
        reduction=reduction_guarantee(g, siso.K, K_reduced),
        reduction_shaped=reduction_shaped,
        ncf_reduction=ncf_reduce(g, siso.K, order),
    )

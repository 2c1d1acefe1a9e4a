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

from ..validation import (
    FieldError,
    check_count,
    check_positive,
    check_real,
    check_scalar_bandwidth,
    check_size,
)
from .barriers import (
    PAPER_MODEL_ERROR,
    PAPER_PERFORMANCE_SPECS,
    _specs,
    robust_performance_barrier,
    robust_stability_barrier,
)
from .lti import (
    DimensionMismatchError,
    ImproperSystemError,
    TimebaseMismatchError,
    check_lti,
    expand_diagonal,
    static_gain,
)
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
_REEXPORTED = (PAPER_MODEL_ERROR, sla, ncf_gamma, ImproperSystemError, SynthesisError)


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
    return _fl_plant(check_scalar_bandwidth("lam", lam, "the FL plant"), check_size("n", n))


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

def _inv(sys: control.StateSpace, name: str) -> control.StateSpace:
    A, B, C, D = sys.A, sys.B, sys.C, sys.D
    if np.linalg.cond(D) > 1e12:
        raise WeightError(f"{name} must be biproper (an invertible D), got D = "
                          f"{np.asarray(D).tolist()}: the reduced controller is evaluated on "
                          f"the shaped plant through {name}^-1")
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
    """Result of :func:`loopsyn` (negative-feedback controllers, ``u = K (r - y)``).

    Unpacks as MATLAB's ``[K, CL, gamma, info] = loopsyn(G, Gd, alpha)``: ``K, CL, gamma,
    info = loopsyn(G, Gd)`` gives :attr:`K`, :attr:`CL`, :attr:`gamma` and this record.

    Attributes
    ----------
    K : control.StateSpace
        Controller for ``G``, shape (m, p), ``K = W1 Ks W2``; the loop is
        ``control.feedback(G * K)``. (MATLAB's ``loopsyn`` is negative feedback too: its
        example analyses ``diskmargin(G, K)``; MATLAB's ``ncfsyn`` is positive feedback.)
    Ks : control.StateSpace
        Controller of the shaped plant, shape (p, p): ``(1 - t) I + t Ks_opt``.
    Gs : control.StateSpace
        Shaped plant ``W2 G W1``, shape (p, p).
    W1 : control.StateSpace
        Pre-compensator, shape (m, p): ``w(s) R`` with the fitted SISO weight ``w`` and a
        constant ``m x p`` matrix ``R`` with orthonormal columns (``I`` for a square plant).
    W2 : control.StateSpace
        Post-compensator, ``p x p`` identity.
    weight : control.StateSpace
        The fitted stable, minimum-phase, biproper SISO weight ``w(s)``, a cascade of
        first-order sections ``(1 + s/z) / (1 + s/p)`` with real corners inside :attr:`band`.
    gamma : float
        Loop-shape performance (MATLAB's meaning), ``sup_w sigma_max([Gd S; Gd^-1 T])`` with
        ``S = (I + G K)^-1``, ``T = I - S``: 1 when ``G K = Gd`` exactly (for a SISO
        ``Gd``), larger the worse ``G K`` follows ``Gd``; ``||Gd S|| <= gamma`` and
        ``||Gd^-1 T|| <= gamma`` over the band. Taken over :attr:`band`.
    b : float
        NCF margin ``b(Gs, Ks)`` of the shaped loop, at least ``alpha * b_max``.
    b_max : float
        Largest achievable margin ``1 / gamma_min`` of ``Gs`` (:func:`ncfsyn`).
    margin : float
        ``ncfmargin(G, K)`` of the unweighted loop.
    weight_fit : float
        Largest error [dB] over :attr:`band` between the log-mean singular value of ``Gs``
        and that of ``Gd`` (how well ``Gs`` matches ``Gd``; the spread of ``G``'s singular
        values around their mean is kept).
    fit : float
        Largest error [dB] over :attr:`band` between the singular values of the loop
        ``G K`` and those of ``Gd``, ``max |20 log10(sigma_i(G K) / sigma_i(Gd))|``.
    band : tuple of float
        Frequency band ``(low, high)`` [rad/s] of the weight fit.
    blend : float
        ``t`` in ``Ks = (1 - t) I + t Ks_opt`` (0: ``G K = Gs``, 1: ncfsyn).
    alpha : float
        The requested trade-off.
    G : control.StateSpace
        The plant, shape (p, m).
    """

    K: control.StateSpace
    Ks: control.StateSpace
    Gs: control.StateSpace
    W1: control.StateSpace
    W2: control.StateSpace
    weight: control.StateSpace
    gamma: float
    b: float
    b_max: float
    margin: float
    weight_fit: float
    fit: float
    band: tuple
    blend: float
    alpha: float
    G: control.StateSpace

    @property
    def CL(self) -> control.StateSpace:
        """Closed loop ``r -> y``, ``T = G K (I + G K)^-1`` (MATLAB's ``CL``), shape (p, p)."""
        return control.feedback(self.G * self.K, np.eye(self.G.noutputs))

    def __iter__(self):
        """``K, CL, gamma, info``."""
        return iter((self.K, self.CL, self.gamma, self))


#: Points per decade of the frequency grids of :func:`loopsyn` (weight fit, gamma, fit).
LOOPSYN_GRID_PER_DECADE = 60

#: Largest number of pole-zero pairs the weight fit of :func:`loopsyn` adds to Bode's
#: asymptotes where its error exceeds 1.5 dB.
LOOPSYN_EXTRA_PAIRS = 3


def _sv(H: np.ndarray) -> np.ndarray:
    """Singular values of a frequency response of shape (p, m, nw), shape (nw, min(p, m))."""
    return np.linalg.svd(np.moveaxis(H, -1, 0), compute_uv=False)


def _corner_model(u, logk, zeros, poles):
    """``log10 |w(j 10^u)|`` of ``w(s) = k prod(1 + s/z) / prod(1 + s/p)`` (log10 corners)."""
    out = np.full_like(u, logk)
    for c in zeros:
        out += 0.5 * np.log10(1.0 + 10.0 ** (2 * (u - c)))
    for c in poles:
        out -= 0.5 * np.log10(1.0 + 10.0 ** (2 * (u - c)))
    return out


def _gain(u, L, zeros, poles) -> tuple[float]:
    """Least-squares log10 gain of the corner model with fixed corners."""
    return (float(np.mean(L - _corner_model(u, 0.0, zeros, poles))),)


def _refine_corners(u, L, zeros, poles):
    """Corners (log10 rad/s) refined by least squares on ``L``, kept inside ``[u0, u-1]``."""
    from scipy.optimize import least_squares

    nz = len(zeros)
    if nz + len(poles) == 0:
        return list(zeros), list(poles)
    x0 = np.concatenate([_gain(u, L, zeros, poles), zeros, poles])

    def jac(x):
        e = 10.0 ** (2.0 * (u[:, None] - x[None, 1:]))
        d = -e / (1.0 + e)
        d[:, nz:] *= -1.0
        return np.hstack([np.ones((u.size, 1)), d])

    x = least_squares(lambda x: _corner_model(u, x[0], x[1:1 + nz], x[1 + nz:]) - L, x0,
                      jac=jac, bounds=(np.r_[-np.inf, np.full(x0.size - 1, u[0])],
                                       np.r_[np.inf, np.full(x0.size - 1, u[-1])])).x
    return list(x[1:1 + nz]), list(x[1 + nz:])


def _fit_magnitude(u: np.ndarray, L: np.ndarray):
    """Stable, minimum-phase, biproper fit of log-magnitude data ``L = log10 |w(j 10^u)|``.

    Bode's asymptotes: the slope of ``L`` (smoothed over a third of a decade) rounded to
    whole multiples of 20 dB/decade; a zero or pole where the rounded slope steps, poles and
    zeros at the band ends so that ``w`` is flat outside the band (biproper, finite DC gain);
    coincident pole-zero pairs dropped. The corners and the gain are then refined by least
    squares on ``L`` (scipy), and up to :data:`LOOPSYN_EXTRA_PAIRS` pole-zero pairs are added
    where the error peaks while it exceeds 1.5 dB. Real corners only: resonances are smoothed
    over, never inverted.
    """
    per = 1.0 / np.mean(np.diff(u))
    slope = np.gradient(L, u)
    k = max(1, int(round(per / 3.0)))
    slope = np.convolve(np.pad(slope, (k, k), mode="edge"), np.ones(2 * k + 1) / (2 * k + 1),
                        mode="valid")
    n = np.round(slope).astype(int)
    zeros, poles = [], []

    def step(at, d):
        (zeros if d > 0 else poles).extend([at] * abs(d))

    step(u[0], n[0])
    for i in np.nonzero(np.diff(n))[0]:
        step(0.5 * (u[i] + u[i + 1]), n[i + 1] - n[i])
    step(u[-1], -n[-1])
    zeros.sort()
    poles.sort()
    # drop pole-zero pairs closer than a sixth of a decade (rounding chatter)
    z_keep, p_keep = list(zeros), list(poles)
    for zc in zeros:
        near = [pc for pc in p_keep if abs(pc - zc) < 1.0 / 6.0]
        if near:
            p_keep.remove(near[0])
            z_keep.remove(zc)
    zeros, poles = z_keep, p_keep
    zeros, poles = _refine_corners(u, L, zeros, poles)
    # greedy: a zero-pole (or pole-zero) pair where the error peaks inside the band (a third
    # of a decade from its ends, where the flat turn of the weight costs up to 3 dB per
    # corner), while that error exceeds 1.5 dB and each pair lowers it by a tenth
    inner = (u > u[0] + 1.0 / 3.0) & (u < u[-1] - 1.0 / 3.0)
    if not np.any(inner):
        inner[:] = True
    for _ in range(LOOPSYN_EXTRA_PAIRS):
        err = np.where(inner, _corner_model(u, *_gain(u, L, zeros, poles), zeros, poles) - L, 0)
        i = int(np.argmax(np.abs(err)))
        if abs(err[i]) <= 0.075:                # 1.5 dB
            break
        lo_c, hi_c = u[i] - 0.25, u[i] + 0.25
        z2, p2 = (zeros + [lo_c], poles + [hi_c]) if err[i] < 0 else \
            (zeros + [hi_c], poles + [lo_c])
        z2, p2 = _refine_corners(u, L, z2, p2)
        new = np.max(np.abs(_corner_model(u, *_gain(u, L, z2, p2), z2, p2) - L)[inner])
        if not new < 0.9 * abs(err[i]):
            break
        zeros, poles = z2, p2
    logk = _gain(u, L, zeros, poles)[0]
    zeros, poles = np.sort(10.0 ** np.asarray(zeros)), np.sort(10.0 ** np.asarray(poles))
    weight = static_gain([[10.0 ** logk]])
    for z, p in zip(zeros, poles, strict=True):  # (1 + s/z) / (1 + s/p), well conditioned
        r = p / z
        weight = control.ss(weight * control.ss([[-p]], [[np.sqrt(p)]],
                                                [[r * (z - p) / np.sqrt(p)]], [[r]]))
    return weight


def _default_band(G: control.StateSpace, Gd: control.StateSpace) -> tuple[float, float]:
    """Band [rad/s] a decade beyond the poles, zeros and crossovers of ``G`` and ``Gd``."""
    mags = [np.abs(np.concatenate([S.poles(), S.zeros()])) for S in (G, Gd)]
    w = np.logspace(-6, 6, 1201)
    sd = _sv(np.asarray(Gd(1j * w, squeeze=False)))
    cross = w[np.nonzero(np.diff(np.sign(sd[:, 0] - 1.0)))[0]]      # |Gd| crosses 1
    mags = np.concatenate(mags + [cross])
    mags = mags[(mags > 1e-6) & (mags < 1e6)]
    if mags.size == 0:
        return 1e-2, 1e2
    return float(mags.min() / 10.0), float(mags.max() * 10.0)


def _squaring_down(G: control.StateSpace, w: np.ndarray) -> np.ndarray:
    """``m x p`` matrix ``R`` with orthonormal columns spanning G's dominant input directions.

    The ``p`` leading eigenvectors of ``sum_w Re(G(jw)^H G(jw))`` over the band grid ``w``.
    """
    H = np.asarray(G(1j * w, squeeze=False))
    M = np.einsum("ikw,ilw->kl", H.conj(), H).real
    d, V = np.linalg.eigh(0.5 * (M + M.T))
    return V[:, ::-1][:, :G.noutputs]


def loopsyn(G, Gd, alpha: float = 0.5, band=None) -> LoopsynResult:
    r"""Loop shaping to a target loop ``Gd``, trading the fit against robustness (MATLAB's).

    As MATLAB's ``loopsyn``, the weights come from the singular values of ``G`` and ``Gd``,
    never by inverting ``G``: a stable, minimum-phase, biproper SISO weight ``w(s)`` is fitted
    (Bode asymptotes refined by least squares, real corners) over ``band`` to

    .. math:: |w(j\omega)| \approx \frac{\operatorname{gm}\sigma(G_d(j\omega))}
              {\operatorname{gm}\sigma(G(j\omega) R)},

    ``gm`` the geometric mean of the singular values, and ``W1 = w R``, ``W2 = I``: the
    shaped plant ``Gs = G W1`` has the log-mean loop gain of ``Gd``, with ``G``'s spread of
    singular values (no plant inversion, no cancelled flexible modes). ``R`` is ``I`` for a
    square plant; with more inputs than outputs (``m > p``) it is the ``m x p`` matrix of
    the dominant input directions of ``G`` over the band. Then ``Ks_opt = ncfsyn(Gs)`` with
    ``b_max = 1/gamma_min``, and on the segment ``Ks(t) = (1 - t) I + t Ks_opt``
    (``G K = Gs Ks(t)``; ``t = 0`` is the loop ``Gs``, ``t = 1`` the ncfsyn design) the
    ``t`` with the smallest

    .. math:: \gamma = \sup_\omega \bar\sigma\begin{bmatrix} G_d S \\ G_d^{-1} T
              \end{bmatrix},\qquad S = (I + G K)^{-1},\ T = I - S

    subject to ``b(Gs, Ks(t)) >= alpha * b_max`` is chosen (a 41-point grid in ``t``, refined
    by bisection at the constraint). ``gamma = 1`` when ``G K = Gd``; MATLAB calls it the
    mixed-sensitivity performance, ``||[W1 S; W3 T]||_inf`` with its own stable weights
    ``W1 ~ Gd``, ``W3 ~ 1/Gd`` (a crossover tolerance included), so its values are of the
    same meaning, not equal. This is a one-parameter search, not MATLAB's tuned fixed-order
    blend (``systune``) or its ``alpha = 0`` mixsyn design: the same trade-off and measures,
    not the same controller. ``CL = feedback(G K)`` as MATLAB's.
    ``gamma``, ``fit`` and ``weight_fit`` are taken on grids of
    :data:`LOOPSYN_GRID_PER_DECADE` points per decade; ``b``, ``b_max`` and ``margin`` are
    exact (Hamiltonian H-infinity norms).

    Parameters
    ----------
    G : control.LTI
        Continuous-time plant, ``p`` outputs and ``m >= p`` inputs; may be unstable or non-
        minimum phase (the fit uses magnitudes only).
    Gd : control.LTI
        Continuous-time target loop shape, SISO (``Gd I``) or ``p x p``; integrators allowed
        (the weight's fit stops at ``band[0]``: below it the weight is flat).
    alpha : float
        Trade-off in ``[0, 1]`` (default 0.5, as MATLAB): ``b(Gs, Ks) >= alpha b_max``.
    band : (float, float), optional
        Band ``(low, high)`` [rad/s] of the weight fit; default a decade beyond the nonzero
        poles and zeros of ``G`` and ``Gd`` and the crossovers of ``Gd``.

    Returns
    -------
    LoopsynResult
        Unpacks as ``K, CL, gamma, info``.

    Raises
    ------
    FieldError
        ``alpha`` not in ``[0, 1]``; ``band`` not two positive increasing frequencies.
    DimensionMismatchError
        ``G`` with more outputs than inputs (``G K`` could not reach the rank of ``Gd``; MATLAB
        refuses it too); ``Gd`` neither SISO nor ``p x p``.
    TimebaseMismatchError
        A discrete-time ``G`` or ``Gd``.
    ValueError
        ``G`` or ``Gd`` loses rank (a zero singular value) on the band.

    References
    ----------
    .. [1] MathWorks, Robust Control Toolbox, ``loopsyn`` (weights from singular values,
       ``alpha``, ``gamma``, the HiMAT example); McFarlane and Glover (1992); Skogestad and
       Postlethwaite (2005), sec. 9.4.

    Examples
    --------
    >>> import control
    >>> from rrr_pin.robust.loopshaping import loopsyn
    >>> G = control.tf(200, [10, 1]) * control.tf(1, [0.05, 1]) ** 2
    >>> K, CL, gamma, info = loopsyn(G, control.tf(10, [1, 0]))
    >>> info.b >= 0.5 * info.b_max
    True
    """
    alpha = check_real("alpha", alpha)
    if not 0.0 <= alpha <= 1.0:
        raise FieldError("alpha", f"{{name}} must be in [0, 1], got {alpha!r}")
    G, Gd = check_lti(G, "G"), check_lti(Gd, "Gd")
    for name, sys in (("G", G), ("Gd", Gd)):
        if sys.dt not in (0, None):
            raise TimebaseMismatchError(
                f"loopsyn takes continuous-time systems; {name} has dt={sys.dt!r}")
    p, m = G.noutputs, G.ninputs
    if p > m:
        raise DimensionMismatchError(
            f"G has more outputs than inputs ({p} x {m}): G K has rank {m} < {p} and cannot "
            "follow the target loop shape (MATLAB's loopsyn refuses it too)")
    if (Gd.noutputs, Gd.ninputs) not in ((1, 1), (p, p)):
        raise DimensionMismatchError(
            f"Gd must be SISO or {p} x {p} (the loop G K), got {Gd.noutputs} x {Gd.ninputs}")
    if band is None:
        band = _default_band(G, Gd)
    else:
        try:
            lo, hi = (float(x) for x in band)
        except (TypeError, ValueError):
            raise FieldError("band", f"{{name}} must be two frequencies (low, high) [rad/s], "
                                     f"got {band!r}") from None
        if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 < lo < hi):
            raise FieldError("band", f"{{name}} must be 0 < low < high finite [rad/s], got "
                                     f"{band!r}")
        band = (lo, hi)
    if Gd.noutputs == 1 and p > 1:
        Gd = expand_diagonal(Gd, p)
    decades = np.log10(band[1] / band[0])
    u = np.linspace(np.log10(band[0]), np.log10(band[1]),
                    max(2, int(np.ceil(decades * LOOPSYN_GRID_PER_DECADE)) + 1))
    w = 10.0 ** u
    R = np.eye(p) if m == p else _squaring_down(G, w)
    GR = control.ss(G * static_gain(R))
    s_g = _sv(np.asarray(GR(1j * w, squeeze=False)))
    s_d = _sv(np.asarray(Gd(1j * w, squeeze=False)))
    for name, sv in (("G", s_g), ("Gd", s_d)):
        bad = np.nonzero(~(sv[:, -1] > 1e-12 * np.maximum(sv[:, 0], 1e-300)))[0]
        if bad.size:
            raise ValueError(f"{name} loses rank at {w[bad[0]]:.4g} rad/s inside the band "
                             f"{band}: a zero singular value has no log-magnitude to fit")
    L = np.mean(np.log10(s_d), axis=1) - np.mean(np.log10(s_g), axis=1)
    weight = _fit_magnitude(u, L)
    W1 = control.ss((expand_diagonal(weight, p) if p > 1 else weight) * static_gain(R))
    W2 = static_gain(np.eye(p))
    Gs = control.ss(G * W1)
    s_s = _sv(np.asarray(Gs(1j * w, squeeze=False)))
    weight_fit = 20.0 * float(np.max(np.abs(np.mean(np.log10(s_s), axis=1)
                                            - np.mean(np.log10(s_d), axis=1))))
    opt = ncfsyn(Gs)
    b_max = 1.0 / opt.gamma_min
    eye = static_gain(np.eye(p))
    Ks_opt = control.ss(opt.Ks)

    hs = np.moveaxis(np.asarray(Gs(1j * w, squeeze=False)), -1, 0)
    hk = np.moveaxis(np.asarray(Ks_opt(1j * w, squeeze=False)), -1, 0)
    hd = np.moveaxis(np.asarray(Gd(1j * w, squeeze=False)), -1, 0)
    hdi = np.linalg.inv(hd)
    I = np.eye(p)

    def Ks_at(t):
        return control.ss(control.parallel(Ks_opt * t, eye * (1.0 - t)))

    # Scan in t on frequency grids: the NCF 4-block norm on a grid two decades wider than the
    # band and internal stability from the closed-loop eigenvalues; the chosen t is then
    # checked with the exact margin (ncfmargin, a Hamiltonian H-infinity norm).
    wide = np.logspace(u[0] - 2.0, u[-1] + 2.0, int(round((decades + 4.0) * 60)) + 1)
    gs_w = np.moveaxis(np.asarray(Gs(1j * wide, squeeze=False)), -1, 0)
    ks_w = np.moveaxis(np.asarray(Ks_opt(1j * wide, squeeze=False)), -1, 0)
    A, B, C, D = (np.asarray(M, float) for M in (Gs.A, Gs.B, Gs.C, Gs.D))
    Ak, Bk, Ck, Dk = (np.asarray(M, float) for M in (Ks_opt.A, Ks_opt.B, Ks_opt.C, Ks_opt.D))
    I = np.eye(p)
    top = np.concatenate([np.broadcast_to(I, gs_w.shape), gs_w], axis=2)

    def b_grid(t):
        Dt, Ct = t * Dk + (1.0 - t) * I, t * Ck             # u = -(Ct xk + Dt y)
        Q = np.linalg.inv(I + Dt @ D)
        Acl = np.block([[A - B @ Q @ Dt @ C, -B @ Q @ Ct],
                        [Bk @ (C - D @ Q @ Dt @ C), Ak - Bk @ D @ Q @ Ct]])
        if np.linalg.eigvals(Acl).real.max(initial=-np.inf) >= 0.0:
            return 0.0
        kt = t * ks_w + (1.0 - t) * I
        S = np.linalg.inv(I + gs_w @ kt)
        blk = np.concatenate([S, kt @ S], axis=1) @ top
        return 1.0 / float(np.max(np.linalg.svd(blk, compute_uv=False)[:, 0]))

    def gamma_at(t):
        L = hs @ ((1.0 - t) * I + t * hk)
        S = np.linalg.inv(I + L)
        stack = np.concatenate([hd @ S, hdi @ (I - S)], axis=1)
        return float(np.max(np.linalg.svd(stack, compute_uv=False)[:, 0]))

    target = alpha * b_max * (1 - 1e-9)

    def feasible(b):                                # stabilizing, and the margin asked
        return b > 0.0 and b >= target

    ts = np.linspace(0.0, 1.0, 41)
    ok = np.array([feasible(b_grid(t)) for t in ts[:-1]] + [True])   # t = 1: b = b_max
    gam = np.array([gamma_at(t) if o else np.inf for t, o in zip(ts, ok, strict=True)])
    i = int(np.argmin(gam))
    t = float(ts[i])
    if i > 0 and not ok[i - 1]:                     # the best lies on the constraint
        lo_t, hi_t = ts[i - 1], ts[i]
        for _ in range(20):
            mid = 0.5 * (lo_t + hi_t)
            lo_t, hi_t = (lo_t, mid) if feasible(b_grid(mid)) else (mid, hi_t)
        if gamma_at(hi_t) < gam[i]:
            t = float(hi_t)
    if t < 1.0 and not feasible(ncfmargin(Gs, Ks_at(t))[0]):  # the grid was optimistic
        lo_t, hi_t = t, 1.0
        for _ in range(20):
            mid = 0.5 * (lo_t + hi_t)
            lo_t, hi_t = (lo_t, mid) if feasible(ncfmargin(Gs, Ks_at(mid))[0]) else (mid, hi_t)
        t = float(hi_t)
    Ks = Ks_at(t) if t < 1.0 else Ks_opt
    K = control.ss(W1 * Ks * W2)
    b = float(ncfmargin(Gs, Ks)[0]) if t < 1.0 else 1.0 / opt.gamma
    margin = ncfmargin(G, K)[0]
    s_l = _sv(np.asarray((G * K)(1j * w, squeeze=False)))
    fit = 20.0 * float(np.max(np.abs(np.log10(s_l) - np.log10(s_d))))
    return LoopsynResult(K=K, Ks=Ks, Gs=Gs, W1=W1, W2=W2, weight=weight,
                         gamma=gamma_at(t), b=b, b_max=float(b_max), margin=float(margin),
                         weight_fit=weight_fit, fit=fit, band=band, blend=t,
                         alpha=alpha, G=G)


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
        return control.ss(_inv(_siso(self.W1), "W1") * self.K_reduced
                          * _inv(_siso(self.W2), "W2"))

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
    lam = check_scalar_bandwidth("lam", lam, "the loop-shaping design")
    n = check_count("n", n, 1, high=MAX_JOINTS)
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
    reduction_shaped = reduction_guarantee(siso.Gs, siso.Ks,
                                           _inv(w1, "W1") * K_reduced * _inv(w2, "W2"))
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

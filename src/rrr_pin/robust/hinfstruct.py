r"""Fixed-structure H-infinity synthesis: :func:`hinfstruct` tunes the blocks of a controller.

Given a continuous-time generalized plant ``P`` (inputs ``[w; u]``, outputs ``[z; y]``) and a
controller ``K = diag(K_1(x_1), ..., K_N(x_N))`` made of tunable blocks, each a small LTI system
of a few real parameters, :func:`hinfstruct` searches the parameters ``x`` that minimize the
H-infinity norm of the closed loop ``w -> z`` with ``u = K y`` (the LFT convention of MATLAB's
``lft(P, K)`` and ``hinfstruct(P, C0)``: *positive* feedback, the plant carries any sign):

.. math:: \min_x \; \|F_\ell(P, K(x))\|_\infty
          = \min_x \max_\omega \bar\sigma\big(P_{11} + P_{12} K (I - P_{22} K)^{-1} P_{21}\big)
          \quad \text{s.t. } \alpha(A_{cl}(x)) \le -\text{min\_decay}.

The objective is non-smooth (a maximum over frequencies of a largest singular value). The
search is an exchange method on its epigraph, in the spirit of Apkarian and Noll's
``hinfstruct`` [1]_: at the current point the exact norm and its peak frequency are found
(SLICOT ``AB13DD``), the local maxima of ``sigma_max`` on a frequency sweep are added to a
working set of frequencies, and scipy's SLSQP solves

.. math:: \min_{x, t}\ t \quad\text{s.t.}\quad \bar\sigma(T(j\omega_k, x)) \le t\ (\omega_k
          \text{ in the set}),\ \alpha(A_{cl}(x)) \le -\text{min\_decay},\ |x - x_c| \le \Delta

inside a trust region ``Delta`` around the current point; the step is kept when the exact norm
drops (the region grows), else the region shrinks and the new peaks join the set. The gradient
of each frequency's largest singular value is exact given the block's frequency response:
``d sigma = Re(u^H dT v)`` with ``u, v`` its singular vectors and
``dT = P12 (I - K P22)^{-1} dK (I - P22 K)^{-1} P21``; ``dK/dx`` is a central difference of
the block's own response (blocks are a few states). Several seeded starts are run (as
``hinfstructOptions('RandomStart', n)``); a start whose closed loop is unstable is first
stabilized by minimizing the spectral abscissa. The best point is verified with SLICOT's
``AB13DD`` (python-control :func:`control.linfnorm`) on the closed loop built once more.

Hand-written because no maintained Python library does fixed-structure H-infinity synthesis
(python-control has ``hinfsyn`` for full-order controllers only); the parts that libraries do
are theirs: the norm (SLICOT ``AB13DD``), the QP steps (scipy SLSQP), realizations
(python-control).

A tunable block is a typed input a user can write: subclass :class:`TunableBlock` (``names``,
``bounds``, ``initial`` and ``realization(x) -> (A, B, C, D)``), or wrap any function of the
parameters with :class:`TunableFunction`. Built in: :class:`TunableGain`, :class:`TunablePID`
(MATLAB's ``tunablePID`` form ``Kp + Ki/s + Kd s/(Tf s + 1)``) and :class:`TunableTF`.
Parameters whose lower bound is positive are searched on a log scale, the others linearly.

:func:`ncf_plant` builds the generalized plant whose closed-loop norm is the loop-shaping
index ``gamma`` of the paper (sec. 4.3-4.4) for a controller ``K = W1 Ks W2``, so that
:func:`hinfstruct` tunes a fixed-order ``K`` against the paper's own objective.

References
----------
.. [1] P. Apkarian and D. Noll, "Nonsmooth H-infinity synthesis", IEEE Trans. Automat. Control
   51(1), 71-86, 2006.
.. [2] J. V. Burke, D. Henrion, A. S. Lewis and M. L. Overton, "HIFOO - a MATLAB package for
   fixed-order controller design and H-infinity optimization", IFAC ROCOND, 2006.
.. [3] MathWorks, Robust Control Toolbox, ``hinfstruct``; Control System Toolbox, ``systune``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import control
import numpy as np
from scipy import optimize, signal
from scipy.linalg import block_diag

from ..validation import FieldError, check_count, check_positive
from .lti import DimensionMismatchError, TimebaseMismatchError, check_lti

__all__ = [
    "TunableBlock",
    "TunableGain",
    "TunablePID",
    "TunableTF",
    "TunableFunction",
    "HinfstructError",
    "HinfstructResult",
    "hinfstruct",
    "lft_loop",
    "ncf_plant",
]


class HinfstructError(ValueError):
    """No start of :func:`hinfstruct` reached a stable closed loop; carries the best point.

    Attributes
    ----------
    values : list of ndarray
        Parameters of each block at the point of smallest spectral abscissa.
    abscissa : float
        Its closed-loop spectral abscissa [1/s] (>= ``-min_decay``).
    """

    def __init__(self, message: str, values=None, abscissa: float = np.nan):
        super().__init__(message)
        self.values, self.abscissa = values, abscissa


# --- tunable blocks --------------------------------------------------------------------------

@dataclass(frozen=True)
class TunableBlock:
    """Base of the tunable blocks: a named LTI system of a few real parameters.

    Subclasses give ``names`` (parameter names), ``bounds()`` (one ``(low, high)`` pair per
    parameter, ``-inf``/``inf`` allowed), ``initial()`` (a start inside the bounds) and
    ``realization(x) -> (A, B, C, D)`` (arrays; ``D`` of shape (outputs, inputs)).
    A parameter whose lower bound is > 0 is searched on a log scale.
    """

    name: str

    @property
    def names(self) -> tuple:
        """Names of the parameters."""
        raise NotImplementedError(f"{type(self).__name__} must define names")

    def bounds(self) -> list:
        """Return ``(low, high)`` per parameter (default: unbounded)."""
        return [(-np.inf, np.inf)] * len(self.names)

    def initial(self) -> np.ndarray:
        """Return a starting point, shape (len(names),)."""
        raise NotImplementedError(f"{type(self).__name__} must define initial()")

    def realization(self, x):
        """Return ``(A, B, C, D)`` of the block at parameters ``x``."""
        raise NotImplementedError(f"{type(self).__name__} must define realization(x)")

    def ss(self, x) -> control.StateSpace:
        """Return the block at ``x`` as a python-control ``StateSpace``."""
        A, B, C, D = self.realization(np.asarray(x, dtype=float))
        return control.ss(A, B, C, D)

    def response(self, x, omega: np.ndarray) -> np.ndarray:
        """Frequency response at ``omega`` [rad/s], shape (N, outputs, inputs)."""
        return _response(_matrices(self.realization(np.asarray(x, dtype=float))), omega)


def _matrices(real):
    """Return ``(A, B, C, D)`` as 2-D float arrays of consistent shapes."""
    A, B, C, D = (np.atleast_2d(np.asarray(M, dtype=float)) for M in real)
    n = A.shape[0] if A.size else 0
    return A.reshape(n, n), B.reshape(n, D.shape[1]), C.reshape(D.shape[0], n), D


def _response(real, omega: np.ndarray) -> np.ndarray:
    """``D + C (j omega I - A)^-1 B``, shape (N, outputs, inputs)."""
    A, B, C, D = real
    H = np.broadcast_to(D, (omega.size, *D.shape)).astype(complex)
    if A.shape[0]:
        s = 1j * omega[:, None, None]
        H = H + C[None] @ np.linalg.solve(s * np.eye(A.shape[0])[None] - A[None], B[None])
    return H


def _empty_ss(D):
    D = np.atleast_2d(np.asarray(D, dtype=float))
    return np.zeros((0, 0)), np.zeros((0, D.shape[1])), np.zeros((D.shape[0], 0)), D


@dataclass(frozen=True)
class TunableGain(TunableBlock):
    """A static gain ``D`` of shape (outputs, inputs), every entry free (MATLAB ``tunableGain``).

    Parameters
    ----------
    name : str
        Block name.
    noutputs, ninputs : int
        Size of the gain.
    value : float or array-like, optional
        Initial gain (default 0).
    gain_bounds : (float, float)
        Bounds of every entry.
    """

    noutputs: int = 1
    ninputs: int = 1
    value: object = None
    gain_bounds: tuple = (-np.inf, np.inf)

    @property
    def names(self):
        """``d{i}{j}`` per entry (``k`` for a SISO gain)."""
        if (self.noutputs, self.ninputs) == (1, 1):
            return ("k",)
        return tuple(f"d{i}{j}" for i in range(self.noutputs) for j in range(self.ninputs))

    def bounds(self):
        """Return ``gain_bounds`` for every entry."""
        return [tuple(self.gain_bounds)] * len(self.names)

    def initial(self):
        """Return ``value`` (or zeros) flattened."""
        v = np.zeros(len(self.names)) if self.value is None else self.value
        return np.broadcast_to(np.asarray(v, dtype=float), (len(self.names),)).copy()

    def realization(self, x):
        """No states, ``D = x`` reshaped."""
        return _empty_ss(np.reshape(x, (self.noutputs, self.ninputs)))


_PID_TERMS = {"p": ("Kp",), "i": ("Ki",), "pi": ("Kp", "Ki"), "pd": ("Kp", "Kd", "Tf"),
              "pid": ("Kp", "Ki", "Kd", "Tf")}


@dataclass(frozen=True)
class TunablePID(TunableBlock):
    r"""SISO PID in MATLAB ``tunablePID`` parallel form.

    .. math:: C(s) = K_p + \frac{K_i}{s} + \frac{K_d s}{T_f s + 1}

    Parameters
    ----------
    name : str
        Block name.
    kind : {"p", "i", "pi", "pd", "pid"}
        Terms present.
    value : dict, optional
        Initial values by name (default: gains 1, ``Tf = 0.01`` s, clipped into the bounds).
    gain_bounds : (float, float)
        Bounds of ``Kp``, ``Ki`` [1/s] and ``Kd`` [s]; a positive lower bound searches them
        on a log scale.
    tf_bounds : (float, float)
        Bounds of the derivative filter's time constant ``Tf`` [s] (positive).
    """

    kind: str = "pid"
    value: dict = field(default_factory=dict)
    gain_bounds: tuple = (-np.inf, np.inf)
    tf_bounds: tuple = (1e-6, 1e3)

    def __post_init__(self):
        if self.kind not in _PID_TERMS:
            raise FieldError("kind", f"{{name}} must be one of {sorted(_PID_TERMS)}, "
                                     f"got {self.kind!r}")
        unknown = set(self.value) - set(self.names)
        if unknown:
            raise FieldError("value", f"{{name}} names {sorted(unknown)}, not parameters of a "
                                      f"{self.kind!r} PID {self.names}")

    @property
    def names(self):
        """Return the terms of ``kind`` (``Kp``, ``Ki``, ``Kd``, ``Tf``)."""
        return _PID_TERMS[self.kind]

    def bounds(self):
        """``gain_bounds`` for the gains, ``tf_bounds`` for ``Tf``."""
        return [tuple(self.tf_bounds) if n == "Tf" else tuple(self.gain_bounds)
                for n in self.names]

    def initial(self):
        """Return ``value`` where given, else a gain of 1 (clipped) and ``Tf = 0.01`` s."""
        out = []
        for n, (lo, hi) in zip(self.names, self.bounds(), strict=True):
            v = self.value.get(n, 0.01 if n == "Tf" else 1.0)
            out.append(float(np.clip(v, lo, hi)))
        return np.array(out)

    def realization(self, x):
        """States: the integrator (when ``Ki``) and the derivative filter (when ``Kd``)."""
        v = dict(zip(self.names, np.asarray(x, dtype=float), strict=True))
        kp, ki, kd, tf = v.get("Kp", 0.0), v.get("Ki"), v.get("Kd"), v.get("Tf")
        A, B, C, D = [], [], [], kp
        if ki is not None:
            A.append(0.0), B.append(1.0), C.append(ki)
        if kd is not None:   # kd s/(tf s + 1) = kd/tf - (kd/tf^2)/(s + 1/tf)
            A.append(-1.0 / tf), B.append(1.0), C.append(-kd / tf**2)
            D += kd / tf
        n = len(A)
        return (np.diag(A).reshape(n, n), np.array(B).reshape(n, 1),
                np.array(C).reshape(1, n), np.array([[D]]))


@dataclass(frozen=True)
class TunableTF(TunableBlock):
    r"""SISO transfer function with free coefficients, monic denominator (MATLAB ``tunableTF``).

    .. math:: K(s) = \frac{b_m s^m + \dots + b_0}{s^n + a_{n-1} s^{n-1} + \dots + a_0},
              \quad m \le n

    Parameters
    ----------
    name : str
        Block name.
    nz, npoles : int
        Numerator and denominator degrees (``nz <= npoles``).
    value : (array-like, array-like), optional
        Initial ``(num, den)`` coefficients, highest power first (den monic).
    """

    nz: int = 0
    npoles: int = 1
    value: tuple = None

    def __post_init__(self):
        check_count("npoles", self.npoles, 0)
        check_count("nz", self.nz, 0, high=self.npoles)

    @property
    def names(self):
        """``b{m}..b0`` then ``a{n-1}..a0``."""
        return (tuple(f"b{i}" for i in range(self.nz, -1, -1))
                + tuple(f"a{i}" for i in range(self.npoles - 1, -1, -1)))

    def initial(self):
        """Return ``value`` or ``1 / (s + 1)^n``-like coefficients."""
        if self.value is not None:
            num, den = (np.atleast_1d(np.asarray(v, dtype=float)) for v in self.value)
            return np.concatenate([num, den[1:] / den[0]])
        den = np.poly(-np.ones(self.npoles)) if self.npoles else np.array([1.0])
        num = np.zeros(self.nz + 1)
        num[-1] = 1.0
        return np.concatenate([num, den[1:]])

    def realization(self, x):
        """Return the controllable canonical form (scipy ``tf2ss``)."""
        x = np.asarray(x, dtype=float)
        num, den = x[:self.nz + 1], np.concatenate([[1.0], x[self.nz + 1:]])
        if self.npoles == 0:
            return _empty_ss(num[-1:].reshape(1, 1))
        with warnings.catch_warnings():   # tf2ss pads num with leading zeros and warns
            warnings.simplefilter("ignore", signal.BadCoefficients)
            return signal.tf2ss(num, den)


@dataclass(frozen=True)
class TunableFunction(TunableBlock):
    """Any block given as a function of its parameters (as MATLAB ``realp`` inside ``tf``).

    Parameters
    ----------
    name : str
        Block name.
    parameters : tuple of str
        Parameter names.
    x0 : array-like
        Starting values.
    fn : callable
        ``fn(x) -> control.LTI`` (or a number), the block at ``x``; its sizes must not change.
    limits : sequence of (float, float), optional
        Bounds per parameter (default unbounded).
    """

    parameters: tuple = ()
    x0: tuple = ()
    fn: object = None
    limits: tuple = None

    def __post_init__(self):
        if not self.parameters:
            raise FieldError("parameters", f"block {self.name!r}: {{name}} is empty; a "
                                           "tunable block needs at least one parameter")
        if len(self.x0) != len(self.parameters):
            raise FieldError("x0", f"block {self.name!r}: {{name}} has {len(self.x0)} values "
                                   f"for {len(self.parameters)} parameters")
        if not callable(self.fn):
            raise FieldError("fn", f"block {self.name!r}: {{name}} must be callable, got "
                                   f"{type(self.fn).__name__}")

    @property
    def names(self):
        """Return ``parameters``."""
        return tuple(self.parameters)

    def bounds(self):
        """Return ``limits`` or unbounded."""
        if self.limits is None:
            return super().bounds()
        return [tuple(b) for b in self.limits]

    def initial(self):
        """Return ``x0``."""
        return np.asarray(self.x0, dtype=float).copy()

    def realization(self, x):
        """Matrices of ``control.ss(fn(x))``."""
        sys = check_lti(self.fn(np.asarray(x, dtype=float)), f"block {self.name!r}")
        return tuple(np.asarray(M, dtype=float) for M in (sys.A, sys.B, sys.C, sys.D))


# --- parameter map ---------------------------------------------------------------------------

class _Map:
    """Blocks' parameters <-> the search variable ``z`` (log where the lower bound is > 0)."""

    def __init__(self, blocks):
        self.blocks = blocks
        self.sizes = [len(b.names) for b in blocks]
        bounds = [bd for b in blocks for bd in b.bounds()]
        self.lo = np.array([b[0] for b in bounds], dtype=float)
        self.hi = np.array([b[1] for b in bounds], dtype=float)
        self.log = self.lo > 0.0
        self.split_at = np.cumsum(self.sizes)[:-1]

    def z_bounds(self):
        lo = np.where(self.log, np.log(np.where(self.log, self.lo, 1.0)), self.lo)
        hi = np.where(self.log, np.log(np.where(self.log, self.hi, 1.0)), self.hi)
        return lo, hi

    def x_of(self, z):
        return np.where(self.log, np.exp(np.where(self.log, z, 0.0)), z)

    def z_of(self, x):
        x = np.clip(x, self.lo, self.hi)
        return np.where(self.log, np.log(np.where(self.log, x, 1.0)), x)

    def values(self, z):
        return np.split(self.x_of(z), self.split_at)


def _block_ss(parts):
    """Block-diagonal realization ``(AK, BK, CK, DK)`` of the blocks' ``(A, B, C, D)``."""
    return tuple(block_diag(*[p[i] for p in parts]) for i in range(4))


class _Plant:
    """Partitioned generalized plant and its frequency responses (cached per frequency)."""

    def __init__(self, P: control.StateSpace, nmeas: int, ncon: int):
        self.A, B, C, D = (np.asarray(M, dtype=float) for M in (P.A, P.B, P.C, P.D))
        nw, nz = B.shape[1] - ncon, C.shape[0] - nmeas
        self.B1, self.B2 = B[:, :nw], B[:, nw:]
        self.C1, self.C2 = C[:nz], C[nz:]
        self.D11, self.D12, self.D21, self.D22 = D[:nz, :nw], D[:nz, nw:], D[nz:, :nw], \
            D[nz:, nw:]
        self.nw, self.nz, self.ny, self.nu = nw, nz, nmeas, ncon
        self.B, self.C, self.D = B, C, D
        self._cache = {}

    def closed_loop(self, AK, BK, CK, DK):
        """``(Acl, Bcl, Ccl, Dcl)`` of ``u = K y``, or None when ill-posed."""
        nu = self.nu
        R = np.eye(nu) - DK @ self.D22
        if np.linalg.cond(R) > 1e12:
            return None
        Ri = np.linalg.inv(R)
        Ux, Uk, Uw = Ri @ DK @ self.C2, Ri @ CK, Ri @ DK @ self.D21
        Yx, Yk, Yw = self.C2 + self.D22 @ Ux, self.D22 @ Uk, self.D21 + self.D22 @ Uw
        Acl = np.block([[self.A + self.B2 @ Ux, self.B2 @ Uk], [BK @ Yx, AK + BK @ Yk]])
        Bcl = np.vstack([self.B1 + self.B2 @ Uw, BK @ Yw])
        Ccl = np.hstack([self.C1 + self.D12 @ Ux, self.D12 @ Uk])
        return Acl, Bcl, Ccl, self.D11 + self.D12 @ Uw

    def response(self, omega: np.ndarray) -> np.ndarray:
        """``P(j omega)``, shape (N, nz + ny, nw + nu)."""
        missing = [w for w in omega if w not in self._cache]
        if missing:
            H = _response((self.A, self.B, self.C, self.D), np.asarray(missing))
            self._cache.update(zip(missing, H, strict=True))
        return np.stack([self._cache[w] for w in omega])


def _abscissa(A) -> float:
    return float(np.linalg.eigvals(A).real.max()) if A.size else -np.inf


# --- the search ------------------------------------------------------------------------------

class _Problem:
    def __init__(self, plant: _Plant, blocks, pmap: _Map, min_decay: float):
        self.plant, self.blocks, self.pmap, self.min_decay = plant, blocks, pmap, min_decay
        self.nfev = 0
        self._real, self._last = {}, (None, None, None)

    def parts(self, z):
        """Each block's ``(A, B, C, D)`` at ``z`` (cached: SLSQP asks for a point twice)."""
        out = []
        for k, (b, v) in enumerate(zip(self.blocks, self.pmap.values(z), strict=True)):
            key = (k, v.tobytes())
            if key not in self._real:
                if len(self._real) > 20000:
                    self._real.clear()
                self._real[key] = _matrices(b.realization(v))
            out.append(self._real[key])
        return out

    def cl(self, z):
        return self.plant.closed_loop(*_block_ss(self.parts(z)))

    def abscissa(self, z) -> float:
        cl = self.cl(z)
        return np.inf if cl is None else _abscissa(cl[0])

    def exact(self, z):
        """``(gamma, omega_peak, local-peak frequencies)``; gamma inf when not stable."""
        self.nfev += 1
        cl = self.cl(z)
        if cl is None or _abscissa(cl[0]) >= -self.min_decay:
            return np.inf, np.nan, np.array([])
        Acl, Bcl, Ccl, Dcl = cl
        g, wpk = control.linfnorm(control.ss(Acl, Bcl, Ccl, Dcl))
        poles = np.abs(np.linalg.eigvals(Acl))
        poles = poles[poles > 0]
        lo, hi = (poles.min() / 100, poles.max() * 100) if poles.size else (1e-3, 1e3)
        grid = np.logspace(np.log10(lo), np.log10(hi), int(30 * np.log10(hi / lo)) + 2)
        sv = self.sigma(z, grid)
        k = np.flatnonzero((sv[1:-1] >= sv[:-2]) & (sv[1:-1] >= sv[2:])) + 1
        k = k[sv[k] >= 0.3 * sv.max()]
        peaks = grid[k]
        if np.isfinite(wpk):   # the exact peak; DC as a frequency far below the poles (a
            # block's integrator has no response at 0, the loop's is its limit)
            peaks = np.append(peaks, wpk if wpk > 0 else lo / 100)
        elif wpk == np.inf:                     # reached at infinite frequency: far out
            peaks = np.append(peaks, 1e3 * hi)
        return float(g), float(wpk), peaks

    def sigma(self, z, omega):
        """Largest singular value of the closed loop at ``omega``, shape (N,)."""
        T = self._T(z, omega)[0]
        return np.linalg.svd(T, compute_uv=False)[:, 0]

    def _K(self, z, omega):
        """Return the controller's response, shape (N, nu, ny)."""
        Ks = [_response(p, omega) for p in self.parts(z)]
        return Ks[0] if len(Ks) == 1 else np.stack([block_diag(*[K[i] for K in Ks])
                                                    for i in range(omega.size)])

    def _T(self, z, omega):
        p = self.plant
        Pw = p.response(omega)
        P11, P12 = Pw[:, :p.nz, :p.nw], Pw[:, :p.nz, p.nw:]
        P21, P22 = Pw[:, p.nz:, :p.nw], Pw[:, p.nz:, p.nw:]
        K = self._K(z, omega)
        M = np.linalg.inv(np.eye(p.ny)[None] - P22 @ K)           # (I - P22 K)^-1
        T = P11 + P12 @ K @ M @ P21
        return T, P12, P21, P22, K, M

    def sigma_and_grad(self, z, omega):
        """``sigma_max`` at ``omega`` (N,) and its gradient in ``z``, shape (N, len(z))."""
        key = (z.tobytes(), omega.tobytes())
        if self._last[0] != key:
            self._last = (key, *self._sigma_and_grad(z, omega))
        return self._last[1], self._last[2]

    def _sigma_and_grad(self, z, omega):
        T, P12, P21, P22, K, M = self._T(z, omega)
        U, S, Vh = np.linalg.svd(T)
        u, v = U[:, :, 0], np.conj(Vh[:, 0, :])
        # d sigma = Re(a^H dK b), a^H = u^H P12 (I - K P22)^-1, b = (I - P22 K)^-1 P21 v
        N = np.linalg.inv(np.eye(self.plant.nu)[None] - K @ P22)
        aH = np.einsum("ni,nij->nj", np.conj(u), P12 @ N)
        b = np.einsum("nij,nj->ni", M @ P21, v)
        grad = np.zeros((omega.size, z.size))
        parts = self.parts(z)
        start, row, col = 0, 0, 0
        for k, size in enumerate(self.pmap.sizes):
            no, ni = parts[k][3].shape
            for j in range(size):
                i = start + j
                h = 1e-6 * max(abs(z[i]), 1.0)
                zp, zm = z.copy(), z.copy()
                zp[i] += h
                zm[i] -= h
                dK = (_response(self.parts(zp)[k], omega)
                      - _response(self.parts(zm)[k], omega)) / (2 * h)
                grad[:, i] = np.einsum("ni,nij,nj->n", aH[:, row:row + no], dK,
                                       b[:, col:col + ni]).real
            start += size
            row += no
            col += ni
        return S[:, 0], grad


def _stabilize(prob: _Problem, z0, lo, hi):
    """Minimize the spectral abscissa from ``z0`` until below ``-min_decay`` (Nelder-Mead)."""
    target = -prob.min_decay

    def fun(z):
        a = prob.abscissa(np.clip(z, lo, hi))
        return max(a, 10 * target - 1e-3) if np.isfinite(a) else 1e6

    simplex = np.vstack([z0, z0 + np.eye(z0.size)])      # unit steps: a factor e in log
    res = optimize.minimize(fun, z0, method="Nelder-Mead",
                            options={"maxfev": 400 * z0.size, "xatol": 1e-8, "fatol": 1e-12,
                                     "initial_simplex": simplex})
    z = np.clip(res.x, lo, hi)
    return z, prob.abscissa(z)


def _local_search(prob: _Problem, z0, lo, hi, maxiter: int, rtol: float):
    """Trust-region exchange method on the epigraph, from a stable ``z0``; returns the best."""
    g, _, peaks = prob.exact(z0)
    best_z, best_g = z0.copy(), g
    poles = np.abs(np.linalg.eigvals(prob.cl(z0)[0]))
    poles = poles[poles > 0]
    base = np.logspace(np.log10(poles.min() / 10), np.log10(poles.max() * 10), 25) \
        if poles.size else np.logspace(-2, 3, 25)
    omega = np.unique(np.concatenate([[base[0] / 1e3], base, peaks]))   # near DC too
    delta, stall, it = 1.0, 0, 0
    nz = z0.size
    for it in range(maxiter):  # noqa: B007 - the count is returned
        zc = best_z
        lo_t, hi_t = np.maximum(lo, zc - delta), np.minimum(hi, zc + delta)

        def obj(v):
            return v[-1]

        def obj_jac(v):
            g = np.zeros(nz + 1)
            g[-1] = 1.0
            return g

        def cons(v, om=omega):
            return v[-1] - prob.sigma_and_grad(v[:-1], om)[0]

        def cons_jac(v, om=omega):
            _, G = prob.sigma_and_grad(v[:-1], om)
            return np.hstack([-G, np.ones((om.size, 1))])

        def stab(v):
            a = prob.abscissa(v[:-1])
            return np.array([-prob.min_decay - a if np.isfinite(a) else -1e6])

        t0 = float(prob.sigma_and_grad(zc, omega)[0].max())
        res = optimize.minimize(
            obj, np.append(zc, t0), jac=obj_jac, method="SLSQP",
            bounds=list(zip(np.append(lo_t, 0.0), np.append(hi_t, np.inf), strict=True)),
            constraints=[{"type": "ineq", "fun": cons, "jac": cons_jac},
                         {"type": "ineq", "fun": stab}],
            options={"maxiter": 60, "ftol": 1e-10})
        z_new = np.clip(res.x[:-1], lo, hi)
        g_new, _, peaks = prob.exact(z_new)
        omega = np.unique(np.concatenate([omega, peaks]))
        if g_new < best_g * (1 - 1e-12):
            gain = (best_g - g_new) / best_g
            best_z, best_g = z_new, g_new
            delta = min(2 * delta, 8.0) if np.max(np.abs(z_new - zc)) > 0.5 * delta else delta
            stall = stall + 1 if gain < rtol else 0
        else:
            delta /= 4.0
            stall += 1
        if stall >= 3 or delta < 1e-8:
            break
    return best_z, best_g, it + 1


@dataclass(frozen=True)
class HinfstructResult:
    """Result of :func:`hinfstruct`.

    Attributes
    ----------
    blocks : tuple of TunableBlock
        The blocks tuned.
    values : dict
        ``{block name: {parameter name: value}}`` at the best point.
    K : tuple of control.StateSpace
        Each tuned block as a system.
    gamma : float
        H-infinity norm of the tuned closed loop, verified by SLICOT ``AB13DD``
        (:func:`control.linfnorm`) on the loop built again from the tuned blocks.
    omega_peak : float
        Frequency of that peak [rad/s].
    CL : control.StateSpace
        Tuned closed loop ``w -> z``.
    runs : tuple of dict
        Per start: ``start`` (its parameters, after the stabilization when it needed one),
        ``gamma`` (found; inf when not stabilized), ``iterations``.
    nfev : int
        Exact-norm evaluations over all starts.
    verified_by : str
        What computed :attr:`gamma`.
    """

    blocks: tuple
    values: dict
    K: tuple
    gamma: float
    omega_peak: float
    CL: control.StateSpace
    runs: tuple
    nfev: int
    verified_by: str = "SLICOT AB13DD (python-control linfnorm)"

    def x(self, name: str) -> np.ndarray:
        """Parameters of block ``name`` in its ``names`` order, shape (n,)."""
        return np.array(list(self.values[name].values()))


def lft_loop(P, blocks, values, nmeas: int | None = None,
             ncon: int | None = None) -> control.StateSpace:
    """Return the closed loop ``w -> z`` of ``P`` with ``u = K y``, ``K = diag(blocks)``.

    Parameters
    ----------
    P : control.StateSpace
        Generalized plant, inputs ``[w; u]`` and outputs ``[z; y]``.
    blocks : sequence of TunableBlock
        The controller's blocks, in the order of ``u`` and ``y``.
    values : sequence of array-like
        Parameters of each block.
    nmeas, ncon : int, optional
        Sizes of ``y`` and ``u`` (default: the blocks' inputs and outputs).

    Returns
    -------
    control.StateSpace
        The closed loop (every state of ``P`` and of the blocks).
    """
    plant, blocks = _check_problem(P, blocks, nmeas, ncon)
    cl = plant.closed_loop(*_block_ss([_matrices(b.realization(np.asarray(v, dtype=float)))
                                       for b, v in zip(blocks, values, strict=True)]))
    if cl is None:
        raise ValueError("the loop is ill-posed: I - DK D22 is singular")
    return control.ss(*cl)


def _check_problem(P, blocks, nmeas, ncon):
    P = check_lti(P, "P")
    if P.dt not in (0, None):
        raise TimebaseMismatchError(f"P must be continuous-time, got dt={P.dt!r}")
    blocks = tuple(blocks)
    if not blocks:
        raise FieldError("blocks", "{name} is empty: give at least one tunable block")
    for b in blocks:
        if not isinstance(b, TunableBlock):
            raise TypeError(f"Expected blocks as TunableBlock instances, got "
                            f"{type(b).__name__}")
        if not b.names:
            raise FieldError("blocks", f"{{name}}: block {b.name!r} has no free parameter")
    sizes = [np.atleast_2d(b.realization(b.initial())[3]).shape for b in blocks]
    nu = sum(s[0] for s in sizes) if ncon is None else check_count("ncon", ncon, 1)
    ny = sum(s[1] for s in sizes) if nmeas is None else check_count("nmeas", nmeas, 1)
    if (nu, ny) != (sum(s[0] for s in sizes), sum(s[1] for s in sizes)):
        raise DimensionMismatchError(
            f"the blocks have {sum(s[0] for s in sizes)} outputs and {sum(s[1] for s in sizes)} "
            f"inputs, but ncon={nu} and nmeas={ny}")
    if P.ninputs <= nu or P.noutputs <= ny:
        raise DimensionMismatchError(
            f"P has {P.ninputs} inputs and {P.noutputs} outputs: too few for ncon={nu} "
            f"controls and nmeas={ny} measurements plus at least one w and one z")
    return _Plant(P, ny, nu), blocks


def hinfstruct(P, blocks, nmeas: int | None = None, ncon: int | None = None, *,
               starts: int = 4, seed: int = 0, spread: float = 1.0, min_decay: float = 1e-7,
               maxiter: int = 40, rtol: float = 1e-6) -> HinfstructResult:
    r"""Tune fixed-structure blocks to minimize the H-infinity norm of ``F_l(P, K)``.

    .. math:: \min_x \|F_\ell(P, \mathrm{diag}(K_1(x_1), \dots, K_N(x_N)))\|_\infty,
              \quad u = K y

    Parameters
    ----------
    P : control.StateSpace or control.TransferFunction
        Continuous-time generalized plant: inputs ``[w; u]``, outputs ``[z; y]``.
    blocks : sequence of TunableBlock
        The controller's blocks; block ``i`` maps its slice of ``y`` to its slice of ``u``.
    nmeas, ncon : int, optional
        Sizes of ``y`` and ``u`` (default: the blocks' inputs and outputs; must agree).
    starts : int
        Number of starts: the blocks' ``initial()`` and ``starts - 1`` seeded random
        perturbations of it (normal, ``spread`` in the search variable: a factor
        ``e**spread`` for log-scaled parameters).
    seed : int
        Seed of the random starts.
    spread : float
        Standard deviation of the random starts in the search variable.
    min_decay : float
        The closed-loop poles must satisfy ``Re(p) <= -min_decay`` [1/s].
    maxiter : int
        Trust-region steps per start.
    rtol : float
        A start stops after 3 steps that lower the norm by less than ``rtol`` (relative).

    Returns
    -------
    HinfstructResult

    Raises
    ------
    HinfstructError
        No start could be stabilized (the best spectral abscissa is reported).
    FieldError, DimensionMismatchError, TimebaseMismatchError
        Bad input, named.
    """
    plant, blocks = _check_problem(P, blocks, nmeas, ncon)
    starts = check_count("starts", starts, 1)
    seed = check_count("seed", seed, 0)
    spread = check_positive("spread", spread, allow_zero=True)
    min_decay = check_positive("min_decay", min_decay, allow_zero=True, unit="1/s")
    maxiter = check_count("maxiter", maxiter, 1)
    pmap = _Map(blocks)
    lo, hi = pmap.z_bounds()
    prob = _Problem(plant, blocks, pmap, min_decay)
    rng = np.random.default_rng(seed)
    z_init = pmap.z_of(np.concatenate([b.initial() for b in blocks]))
    best = (np.inf, None)
    runs, closest = [], (np.inf, z_init)
    for k in range(starts):
        z0 = z_init if k == 0 else np.clip(
            z_init + spread * rng.standard_normal(z_init.size), lo, hi)
        a = prob.abscissa(z0)
        if not a < -prob.min_decay:
            z0, a = _stabilize(prob, z0, lo, hi)
        if not a < -prob.min_decay:
            closest = min(closest, (a, z0), key=lambda t: t[0])
            runs.append({"start": pmap.x_of(z0).tolist(), "gamma": np.inf, "iterations": 0})
            continue
        z, g, its = _local_search(prob, z0, lo, hi, maxiter, rtol)
        runs.append({"start": pmap.x_of(z0).tolist(), "gamma": float(g), "iterations": its})
        if g < best[0]:
            best = (g, z)
    if best[1] is None:
        values = pmap.values(closest[1])
        raise HinfstructError(
            f"no start of {starts} gave a stable closed loop (best spectral abscissa "
            f"{closest[0]:.4g} 1/s at {[v.tolist() for v in values]}): the structure may not "
            f"stabilize P", values=values, abscissa=float(closest[0]))
    values = pmap.values(best[1])
    CL = lft_loop(P, blocks, values)
    if not _abscissa(np.asarray(CL.A)) < 0:
        raise HinfstructError("the tuned loop is not stable on re-check", values=values)
    gamma, wpk = control.linfnorm(CL)
    return HinfstructResult(
        blocks=blocks,
        values={b.name: dict(zip(b.names, map(float, v), strict=True))
                for b, v in zip(blocks, values, strict=True)},
        K=tuple(b.ss(v) for b, v in zip(blocks, values, strict=True)),
        gamma=float(gamma), omega_peak=float(wpk), CL=CL, runs=tuple(runs), nfev=prob.nfev)


def ncf_plant(G, W1=None, W2=None) -> control.StateSpace:
    r"""Generalized plant of the loop-shaping index, for a controller ``K = W1 Ks W2``.

    With ``u = K e`` and ``e = -y`` (the negative feedback of rrr-pin), the closed loop
    ``[w1; w2] -> [z1; z2]`` of this plant is, up to signs of its rows,

    .. math:: \begin{bmatrix} I \\ K_s \end{bmatrix} (I + G_s K_s)^{-1}
              \begin{bmatrix} I & G_s \end{bmatrix},\quad G_s = W_2 G W_1,\
              K_s = W_1^{-1} K W_2^{-1},

    whose H-infinity norm is the NCF index ``gamma`` of the paper (sec. 4.4,
    :func:`rrr_pin.robust.robustness.ncf_gamma`). Inputs ``[w1 (p); w2 (m); u (m)]``, outputs
    ``[z1 (p); z2 (m); e (p)]``.

    Parameters
    ----------
    G : control.LTI
        Plant, ``p`` outputs, ``m`` inputs (continuous time).
    W1, W2 : control.LTI, optional
        Square weights ``m x m`` and ``p x p`` (default identity), biproper with stable
        inverses (minimum phase): ``W1^-1`` and ``W2^-1`` are states of the plant.

    Returns
    -------
    control.StateSpace
        The generalized plant (states of ``W1``, ``G``, ``W2``, ``W1^-1``, ``W2^-1``).
    """
    G = check_lti(G, "G")
    p, m = G.noutputs, G.ninputs
    W1 = check_lti(np.eye(m) if W1 is None else W1, "W1")
    W2 = check_lti(np.eye(p) if W2 is None else W2, "W2")
    if (W1.noutputs, W1.ninputs) != (m, m) or (W2.noutputs, W2.ninputs) != (p, p):
        raise DimensionMismatchError(f"W1 must be {m} x {m} and W2 {p} x {p} for G {p} x {m}")
    inv = {}
    for name, W in (("W1", W1), ("W2", W2)):
        D = np.asarray(W.D, dtype=float)
        if abs(np.linalg.det(D)) < 1e-12:
            raise ValueError(f"{name} must be biproper (invertible D) for the index's plant")
        Di = np.linalg.inv(D)
        A_, B_, C_ = (np.asarray(M, dtype=float) for M in (W.A, W.B, W.C))
        Wi = control.ss(A_ - B_ @ Di @ C_, B_ @ Di, -Di @ C_, Di)
        if Wi.nstates and np.linalg.eigvals(Wi.A).real.max() >= 0:
            raise ValueError(f"{name} must be minimum phase (its inverse is a state of the "
                             "index's plant)")
        inv[name] = Wi
    # z1 = ys = w1 + W2 G (W1 w2 + u); z2 = W1^-1 u; e = -W2^-1 w1 - G (W1 w2 + u)
    Im, Ip = np.eye(m), np.eye(p)
    v = control.append(W1, G, W2, inv["W1"], inv["W2"])
    A, B, C, D = (np.asarray(M, dtype=float) for M in (v.A, v.B, v.C, v.D))
    # outputs of v: y_a (m), y_g (p), y_c (p), y_d (m), y_f (p); inputs: a (m), g (m), c (p),
    # d (m), f (p). Close the internal loop g = y_a + u, c = y_g; external inputs w1, w2, u.
    ia, ig, ic, id_, if_ = np.cumsum([0, m, m, p, m])
    oa, og, oc, od, of = np.cumsum([0, m, p, p, m])
    nin, nout = B.shape[1], C.shape[0]
    # input map: v_in = E_ext [w1; w2; u] + F v_out
    E = np.zeros((nin, p + m + m))
    F = np.zeros((nin, nout))
    E[ia:ia + m, p:p + m] = Im          # a = w2
    E[ig:ig + m, p + m:] = Im           # g = W1 w2 + u
    F[ig:ig + m, oa:oa + m] = Im
    F[ic:ic + p, og:og + p] = Ip        # c = G g
    E[id_:id_ + m, p + m:] = Im         # d = u
    E[if_:if_ + p, :p] = Ip             # f = w1
    X = np.linalg.inv(np.eye(nout) - D @ F)
    Ac = A + B @ F @ X @ C
    Bc = B @ (E + F @ X @ D @ E)
    Cv, Dv = X @ C, X @ D @ E                      # block outputs in terms of [x; w1 w2 u]
    # external outputs: z1 = w1 + y_c, z2 = y_d, e = -y_f - y_g
    S = np.zeros((p + m + p, nout))
    S[:p, oc:oc + p] = Ip
    S[p:p + m, od:od + m] = Im
    S[p + m:, of:of + p] = -Ip
    S[p + m:, og:og + p] = -Ip
    Dext = np.zeros((p + m + p, p + m + m))
    Dext[:p, :p] = Ip
    return control.ss(Ac, Bc, S @ Cv, S @ Dv + Dext)

r"""Structured singular value with real and complex blocks: ``mussv`` and ``robstab``.

For the loop ``det(I - M Delta)`` with ``Delta = diag(Delta_1, ..., Delta_k)`` of a given
structure, the structured singular value is

.. math:: \mu_\Delta(M) = \left(\min\{\bar\sigma(\Delta) : \det(I - M\Delta) = 0\}\right)^{-1}

and the loop stays stable for every ``Delta`` with ``sup_w sigma_max(Delta) < 1/peak mu``
(``M`` stable). Two kinds of blocks, written ``(kind, n)``:

* ``("real", n)``: a repeated real scalar ``delta I_n`` (MATLAB's ``mussv`` block ``[-n 0]``);
* ``("complex", n)``: a full complex ``n x n`` block (MATLAB's ``[n n]``).

The upper bound is the D,G-scaling bound of Fan, Tits and Doyle [1]_, an LMI solved with
Clarabel (assembled here directly: cvxpy's canonicalization of the complex LMI cost seconds
per frequency):

.. math:: \mu_\Delta(M) \le \beta \;\text{ if }\; \exists D \succ 0, G = G^H :
          M^H D M + j (G M - M^H G) - \beta^2 D \prec 0

with ``D`` and ``G`` commuting with the structure (``D`` a full Hermitian block and ``G`` a
Hermitian block on each repeated real scalar, ``D = d I`` and ``G = 0`` on each full complex
block), bisected on ``beta``. ``M`` is balanced first (Osborne's method by groups that commute
with the structure: ``mu`` is unchanged), so a badly scaled matrix costs nothing; one solve
bounds the spread of ``D`` and, where the ``D`` found reaches that bound, the matrix is
re-scaled by it and solved again, so the scaling's spread is not limited. (An ill-conditioned
similarity *inside* a repeated real block, which no diagonal undoes, is resolved only as far as
the solver's accuracy allows: measured, condition 1e2 exact, 1e4 9 % high, 1e6 far off -- still
valid bounds.) Each reported upper bound is verified: the LMI is re-evaluated in
NumPy with the solver's ``D, G`` and must be negative definite, else the next ``beta`` up is
taken. The lower bound is a local search (hand-written, as no Python library offers one): it
minimizes ``max_i |delta_i|`` (and the complex blocks' norms, rank one) subject to
``det(I - M Delta) = 0`` with SciPy's SLSQP from several starts; every bound it reports is
``1/sigma_max(Delta)`` of a ``Delta`` checked to make ``I - M Delta`` singular. Where no such
``Delta`` is found the lower bound is 0 (a purely real problem has ``mu = 0`` at every
frequency where no real ``Delta`` can make the determinant vanish).

Both bounds are values at the frequencies asked for. A purely real ``mu`` can be
discontinuous in frequency (nonzero only where ``M(jw)`` admits a real singular ``Delta``), so
:func:`robstab` also searches the frequency together with the parameters, evaluates the upper
bound at the critical frequencies it finds, and checks the vertices of the parameter box at
the claimed margin on the closed loop's state-space matrices.

References
----------
.. [1] M. K. H. Fan, A. L. Tits and J. C. Doyle, "Robustness in the presence of mixed
   parametric uncertainty and unmodeled dynamics", IEEE Trans. Automatic Control 36(1),
   25-38, 1991.
.. [2] P. M. Young, M. P. Newlin and J. C. Doyle, "Practical computation of the mixed mu
   problem", Proc. American Control Conference, 1992.
.. [3] A. Packard and J. C. Doyle, "The complex structured singular value", Automatica 29(1),
   71-109, 1993.
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass

import control
import numpy as np
import scipy.optimize

from ..validation import FieldError, check_count
from .lti import DimensionMismatchError, check_lti

__all__ = ["BLOCK_KINDS", "mussv", "robstab", "RobstabResult", "closed_loop_matrix"]

#: The block kinds of a structure (see the module docstring).
BLOCK_KINDS = ("real", "complex")

# Relative width of the bisection bracket on beta at which the upper bound stops.
_RTOL = 5e-3
# Bounds on the scalings of one LMI solve, on the balanced M / sigma_max: D in [I, _DMAX I],
# |G| <= _GMAX (the LMI is homogeneous in D, G). They confine one solve only: where the D found
# spreads near _DMAX the matrix is re-scaled by it and solved again (_upper), so the scaling
# that is optimized has no bound.
_DMAX = 1e4
_GMAX = 1e4
# Re-scalings of the upper bound after the first solve, and Osborne sweeps of the balancing.
_ROUNDS = 8
_SWEEPS = 100
# Relative size (to sigma_max(M)) below which the upper bound is not refined further.
_FLOOR = 1e-4
# sigma_min(I - M Delta) / (1 + sigma_max(M Delta)) below which Delta counts as singular.
_SING = 1e-7


def _check_blocks(blocks) -> tuple[tuple[str, int], ...]:
    """Return ``blocks`` as a tuple of ``(kind, n)``; FieldError on anything else."""
    try:
        items = list(blocks)
    except TypeError:
        raise FieldError("blocks", f"{{name}} must be a list of (kind, n) pairs, got "
                                   f"{blocks!r}") from None
    if not items:
        raise FieldError("blocks", "{name} must hold at least one block, got []")
    out = []
    for i, b in enumerate(items):
        if not isinstance(b, (tuple, list)) or len(b) != 2 or b[0] not in BLOCK_KINDS:
            raise FieldError("blocks", f"{{name}}[{i}] must be (kind, n) with kind in "
                                       f"{BLOCK_KINDS}, got {b!r}")
        out.append((b[0], check_count(f"blocks[{i}] size", b[1], 1)))
    return tuple(out)


def _size(blocks) -> int:
    return sum(n for _, n in blocks)


def _response(M, omega, n: int) -> tuple[np.ndarray, np.ndarray | None]:
    """Frequency response of ``M``, shape (nw, n, n), and ``omega`` (None for an array)."""
    if isinstance(M, (control.LTI,)):
        sys = check_lti(M, "M")
        if sys.isdtime(strict=True):
            raise FieldError("M", "{name} must be continuous-time (dt = 0) here")
        if (sys.noutputs, sys.ninputs) != (n, n):
            raise DimensionMismatchError(f"M is {sys.noutputs} x {sys.ninputs} but the blocks "
                                         f"add up to {n} x {n}")
        if omega is None:
            raise FieldError("omega", "{name} is required when M is a system")
        w = _check_omega(omega)
        H = np.stack([_at(sys, wk) for wk in w])
        return H.reshape(len(w), n, n), w
    H = np.asarray(M, dtype=complex)
    if H.ndim == 2:
        H = H[None]
    if H.ndim != 3 or H.shape[1:] != (n, n):
        raise DimensionMismatchError(f"Expected M of shape (nw, {n}, {n}) for blocks adding up "
                                     f"to {n}, got {np.shape(M)}")
    if not np.all(np.isfinite(H)):
        raise FieldError("M", "{name} must be finite")
    w = None if omega is None else _check_omega(omega)
    if w is not None and len(w) != H.shape[0]:
        raise DimensionMismatchError(f"omega has {len(w)} frequencies but M has {H.shape[0]}")
    return H, w


def _at(sys: control.StateSpace, w: float) -> np.ndarray:
    """``M(j w)``, shape (n, n), complex."""
    if not sys.nstates:
        return np.asarray(sys.D, dtype=complex)
    return np.asarray(sys(1j * w, squeeze=False), dtype=complex).reshape(sys.noutputs,
                                                                         sys.ninputs)


def _check_omega(omega) -> np.ndarray:
    w = np.atleast_1d(np.asarray(omega, dtype=float))
    if w.ndim != 1 or w.size == 0 or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise FieldError("omega", f"{{name}} must be finite frequencies >= 0 [rad/s], got "
                                  f"{np.asarray(omega).tolist()!r}")
    return w


# ---------------------------------------------------------------- upper bound (LMI)

def _svec(X: np.ndarray) -> np.ndarray:
    """Return Clarabel's vectorization of a real symmetric matrix.

    The upper triangle by columns, off-diagonal entries times sqrt 2.
    """
    iu = _triu(X.shape[0])
    return X[iu] * np.where(iu[0] == iu[1], 1.0, np.sqrt(2.0))


_TRIU: dict = {}


def _triu(n: int):
    if n not in _TRIU:
        rows, cols = zip(*[(i, j) for j in range(n) for i in range(j + 1)], strict=True)
        _TRIU[n] = (np.array(rows), np.array(cols))
    return _TRIU[n]


def _real(X: np.ndarray) -> np.ndarray:
    """Real symmetric embedding ``[[Re X, -Im X], [Im X, Re X]]`` of a Hermitian ``X``."""
    return np.block([[X.real, -X.imag], [X.imag, X.real]])


def _hermitian_basis(k: int) -> list:
    """Return a real basis of the ``k x k`` Hermitian matrices (``k^2`` of them)."""
    out = []
    for j in range(k):
        for i in range(j + 1):
            E = np.zeros((k, k), dtype=complex)
            E[i, j] = E[j, i] = 1.0
            out.append(E)
            if i != j:
                F = np.zeros((k, k), dtype=complex)
                F[i, j], F[j, i] = 1j, -1j
                out.append(F)
    return out


class _UpperLMI:
    r"""The D,G LMI of one matrix ``M``, assembled for Clarabel.

    Hand-written: cvxpy's canonicalization of the complex problem took about 3.6 s per
    frequency (measured on the 10 x 10 frozen FL loop), against milliseconds for the solve.

    Variables: a real basis of each block's ``D`` and ``G`` (Hermitian ``k x k`` on a repeated
    real scalar, ``d I`` and no ``G`` on a full complex block) and ``t``; minimize ``t`` with

    .. math:: M^H D M + j (G M - M^H G) - \beta^2 D \preceq t I, \quad
              I \preceq D \preceq d_{max} I, \quad -g_{max} I \preceq G \preceq g_{max} I

    (each Hermitian inequality as its real ``2n x 2n`` embedding), for ``M`` scaled to
    ``sigma_max(M) = 1``. ``beta`` is feasible when ``t < 0``.
    """

    def __init__(self, M: np.ndarray, blocks):
        n = M.shape[0]
        self.M, self.n = M, n
        Mh = M.conj().T
        lmiD, lmiDb = [], []  # columns of the main LMI (fixed part, part times beta^2)
        self.dcols, self.gcols = [], []  # (offset, basis) to rebuild D and G
        col, j = 0, 0
        for kind, k in blocks:
            sl = slice(j, j + k)
            basis = _hermitian_basis(k) if kind == "real" else [np.eye(k, dtype=complex)]
            for E in basis:
                F = np.zeros((n, n), dtype=complex)
                F[sl, sl] = E
                lmiD.append(_svec(_real(Mh @ F @ M)))
                lmiDb.append(_svec(_real(F)))
                self.dcols.append((col, sl, E))
                col += 1
            if kind == "real":
                for E in basis:
                    F = np.zeros((n, n), dtype=complex)
                    F[sl, sl] = E
                    lmiD.append(_svec(_real(1j * (F @ M - Mh @ F))))
                    lmiDb.append(np.zeros_like(lmiD[-1]))
                    self.gcols.append((col, sl, E))
                    col += 1
            j += k
        self.nvar = col + 1  # and t
        size = 2 * n
        tcol = _svec(-np.eye(size))
        self.A_fixed = np.column_stack(lmiD + [tcol])
        self.A_beta = np.column_stack(lmiDb + [np.zeros_like(tcol)])
        # Bound cones, one per block and kind: s = b - A x.
        rows_A, rows_b, cones = [], [], []
        self._bound_rows(blocks, rows_A, rows_b, cones)
        self.A_bounds = np.vstack(rows_A) if rows_A else np.zeros((0, self.nvar))
        self.b_bounds = np.concatenate(rows_b) if rows_b else np.zeros(0)
        self.bound_cones = cones

    def _bound_rows(self, blocks, rows_A, rows_b, cones):
        import clarabel

        dcols, gcols = list(self.dcols), list(self.gcols)
        for kind, k in blocks:
            nb = k * k if kind == "real" else 1
            dpart, dcols = dcols[:nb], dcols[nb:]
            if kind == "real":
                gpart, gcols = gcols[:nb], gcols[nb:]
                for part, lo, hi in ((dpart, 1.0, _DMAX), (gpart, -_GMAX, _GMAX)):
                    for sign, level in ((1.0, lo), (-1.0, hi)):
                        # sign (X - level I) >= 0  ->  s = -sign level I_vec + sign X(x)
                        A = np.zeros((len(_svec(np.eye(2 * k))), self.nvar))
                        for c, _, E in part:
                            A[:, c] = -sign * _svec(_real(E))
                        rows_A.append(A)
                        rows_b.append(-sign * level * _svec(np.eye(2 * k)))
                        cones.append(clarabel.PSDTriangleConeT(2 * k))
            else:
                c = dpart[0][0]
                A = np.zeros((2, self.nvar))
                A[0, c], A[1, c] = -1.0, 1.0
                rows_A.append(A)
                rows_b.append(np.array([-1.0, _DMAX]))
                cones.append(clarabel.NonnegativeConeT(2))

    def certificate(self, M: np.ndarray, beta: float):
        """Return ``(D, G)`` proving ``mu(M) <= beta`` (checked in NumPy), or None."""
        import clarabel
        import scipy.sparse as sparse

        # main LMI: -(sum x_i F_i - t I) >= 0  ->  s = 0 - A x with A = F columns
        A_main = self.A_fixed - beta * beta * self.A_beta
        A = sparse.csc_matrix(np.vstack([A_main, self.A_bounds]))
        b = np.concatenate([np.zeros(A_main.shape[0]), self.b_bounds])
        q = np.zeros(self.nvar)
        q[-1] = 1.0
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        cones = [clarabel.PSDTriangleConeT(2 * self.n)] + self.bound_cones
        sol = clarabel.DefaultSolver(sparse.csc_matrix((self.nvar, self.nvar)), q, A, b,
                                     cones, settings).solve()
        x = np.asarray(sol.x)
        if not np.all(np.isfinite(x)) or x[-1] >= 0:
            return None
        D = np.zeros((self.n, self.n), dtype=complex)
        G = np.zeros((self.n, self.n), dtype=complex)
        for c, sl, E in self.dcols:
            D[sl, sl] += x[c] * E
        for c, sl, E in self.gcols:
            G[sl, sl] += x[c] * E
        return (D, G) if _lmi_holds(M, D, G, beta) else None


def _lmi_holds(M, D, G, beta) -> bool:
    """Whether ``M^H D M + j(GM - M^H G) - beta^2 D`` is negative definite, ``D`` positive."""
    D, G = 0.5 * (D + D.conj().T), 0.5 * (G + G.conj().T)
    Mh = M.conj().T
    X = Mh @ D @ M + 1j * (G @ M - Mh @ G) - beta * beta * D
    X = 0.5 * (X + X.conj().T)
    return bool(np.linalg.eigvalsh(D).min() > 0 and np.linalg.eigvalsh(X).max() < 0)


def _balance(M: np.ndarray, blocks) -> np.ndarray:
    r"""Osborne's balancing: ``d``, shape (n,), positive, commuting with the structure.

    ``diag(d)`` commutes with every ``Delta`` of the structure: one scalar on a full complex
    block, any positive diagonal on a repeated real scalar ``delta I`` (each of its rows is a
    group of its own). So ``mu(diag(d) M diag(d)^-1) = mu(M)``. ``d`` minimizes the Frobenius
    norm of that matrix by coordinate descent, one group at a time: scaling group ``k`` by
    ``s`` multiplies its off-diagonal row norm squared ``R_k`` by ``s^2`` and its column norm
    squared ``C_k`` by ``s^-2``, so the exact minimizer is ``s^4 = C_k / R_k`` (E. E. Osborne,
    "On pre-conditioning of matrices", J. ACM 7, 1960; Packard & Doyle [3]_ discuss it as a
    fast D scaling). For a rank-one ``M = a b^H`` it is the upper bound's optimal ``D``.
    Hand-written: SciPy's ``matrix_balance`` balances single entries only, in powers of 2.
    """
    sizes = []  # the groups of rows that share one scalar
    for kind, n in blocks:
        sizes += [n] if kind == "complex" else [1] * n
    edges = np.cumsum([0] + sizes)
    m = len(sizes)
    N2 = np.array([[np.linalg.norm(M[edges[i]:edges[i + 1], edges[j]:edges[j + 1]]) ** 2
                    for j in range(m)] for i in range(m)])
    np.fill_diagonal(N2, 0.0)
    logd = np.zeros(m)
    for _ in range(_SWEEPS):
        largest = 0.0
        for k in range(m):
            w = np.exp(2.0 * (logd - logd[k]))  # (d_j / d_k)^2
            row, col = float(np.sum(N2[k] / w)), float(np.sum(N2[:, k] * w))
            if row > 0.0 and col > 0.0:
                step = 0.25 * np.log(col / row)
                logd[k] += step
                largest = max(largest, abs(step))
        if largest < 1e-4:
            break
    # A reducible M (a row or column of zeros off the diagonal) pushes d apart without end;
    # 300 keeps exp(d_i - d_j) finite, far past where the scaled entries stop mattering.
    logd = np.clip(logd - logd.mean(), -300.0, 300.0)
    return np.repeat(np.exp(logd), sizes)


def _block_sqrt(D: np.ndarray, blocks) -> tuple[np.ndarray, np.ndarray]:
    """``T = D^(1/2)`` and ``T^-1`` block by block (``D`` Hermitian positive, block diagonal)."""
    T, Ti, j = np.zeros_like(D), np.zeros_like(D), 0
    for _, k in blocks:
        lam, V = np.linalg.eigh(D[j:j + k, j:j + k])
        lam = np.maximum(lam, 1e-300)
        T[j:j + k, j:j + k] = (V * np.sqrt(lam)) @ V.conj().T
        Ti[j:j + k, j:j + k] = (V / np.sqrt(lam)) @ V.conj().T
        j += k
    return T, Ti


def _upper(M: np.ndarray, blocks, lo: float) -> float:
    """Return the verified D,G upper bound of ``mu(M)``.

    ``M`` is first balanced (:func:`_balance`), which changes neither ``mu`` nor the bound's
    optimum; ``sigma_max`` of the balanced matrix is a first upper bound. Then the LMI is
    bisected down from it on ``M / sigma_max`` (``mu`` is homogeneous), trying ``lo (1 +
    rtol)`` first (one solve when the lower bound is tight). Where the ``D`` of the best
    certificate spreads near the solve's bound ``_DMAX``, ``M`` is re-scaled by ``D^(1/2)``
    (which commutes with the structure) and the bisection starts again from the bound found,
    up to ``_ROUNDS`` times: the scaling is optimized without a bound on its spread. Each
    certificate is checked on the matrix it was solved for (a congruence of the LMI on ``M``).
    Stops at ``_FLOOR sigma_max`` when the bound keeps falling (a purely real ``mu`` is 0 at
    most frequencies, where the scalings make the bound as small as one likes).
    """
    d = _balance(M, blocks)
    Mb = (d[:, None] * M) / d[None, :]
    smax = float(np.linalg.norm(Mb, 2))
    if smax <= 1e-300:
        return 0.0
    best = smax * (1.0 + 1e-9)  # sigma_max(D M D^-1) bounds mu with no LMI
    for _ in range(_ROUNDS):
        s = float(np.linalg.norm(Mb, 2))
        Mn = Mb / s
        lmi = _UpperLMI(Mn, blocks)
        hi = best / s
        low = min(max(lo / s, 0.0), hi)
        cert = None
        if low > 0 and low * (1.0 + _RTOL) < hi:
            cert = lmi.certificate(Mn, low * (1.0 + _RTOL))
            if cert is not None:
                hi = low * (1.0 + _RTOL)
            else:
                low *= 1.0 + _RTOL
        while hi - low > _RTOL * hi and hi * s > _FLOOR * smax:
            mid = 0.5 * (low + hi) if low > 0.05 * hi else np.sqrt(max(low, 1e-3 * hi) * hi)
            found = lmi.certificate(Mn, mid)
            if found is not None:
                hi, cert = mid, found
            else:
                low = mid
        best = min(best, hi * s)
        if cert is None or best <= lo * (1.0 + _RTOL) * (1.0 + 1e-9):
            break  # no better scaling found, or the bound meets the lower bound
        lam = np.linalg.eigvalsh(cert[0])
        if lam.max() < 0.1 * _DMAX * lam.min():
            break  # the scaling is inside the solve's bound: the optimum is not confined
        T, Ti = _block_sqrt(cert[0], blocks)
        Mb = T @ Mb @ Ti
    return best


# ---------------------------------------------------------------- lower bound (local search)

class _Structure:
    """Map a real vector ``x`` to a structured ``Delta`` (complex blocks of rank one)."""

    def __init__(self, blocks):
        self.blocks = blocks
        self.size = sum(1 if kind == "real" else 4 * n for kind, n in blocks)

    def delta(self, x) -> np.ndarray:
        parts, i = [], 0
        for kind, n in self.blocks:
            if kind == "real":
                parts.append(x[i] * np.eye(n))
                i += 1
            else:
                a = x[i:i + n] + 1j * x[i + n:i + 2 * n]
                b = x[i + 2 * n:i + 3 * n] + 1j * x[i + 3 * n:i + 4 * n]
                parts.append(np.outer(a, b.conj()))
                i += 4 * n
        return _bd(parts)

    def trace_gradient(self, W: np.ndarray, x) -> np.ndarray:
        """``d tr(W Delta(x)) / dx``, shape (size,), complex."""
        out, i, j = [], 0, 0
        for kind, n in self.blocks:
            Ws = W[j:j + n, j:j + n]
            if kind == "real":
                out.append(np.trace(Ws))
                i += 1
            else:
                a = x[i:i + n] + 1j * x[i + n:i + 2 * n]
                b = x[i + 2 * n:i + 3 * n] + 1j * x[i + 3 * n:i + 4 * n]
                bW, Wa = b.conj() @ Ws, Ws @ a
                out += list(bW) + list(1j * bW) + list(Wa) + list(-1j * Wa)
                i += 4 * n
            j += n
        return np.array(out, dtype=complex)

    def norms(self, x) -> np.ndarray:
        out, i = [], 0
        for kind, n in self.blocks:
            if kind == "real":
                out.append(abs(x[i]))
                i += 1
            else:
                out.append(np.linalg.norm(x[i:i + 2 * n]) * np.linalg.norm(x[i + 2 * n:i + 4 * n]))
                i += 4 * n
        return np.array(out)

    def from_matrix(self, E: np.ndarray) -> np.ndarray:
        """Return a structured start near the full matrix ``E`` (diagonal blocks projected)."""
        x, i, j = [], 0, 0
        for kind, n in self.blocks:
            blk = E[j:j + n, j:j + n]
            if kind == "real":
                x.append(float(np.real(np.trace(blk))) / n)
            else:
                U, s, Vh = np.linalg.svd(blk)
                a, b = U[:, 0] * np.sqrt(s[0]), Vh[0].conj() * np.sqrt(s[0])
                x += list(a.real) + list(a.imag) + list(b.real) + list(b.imag)
            i += 1
            j += n
        return np.array(x)


def _bd(parts):
    n = sum(p.shape[0] for p in parts)
    out = np.zeros((n, n), dtype=complex)
    j = 0
    for p in parts:
        k = p.shape[0]
        out[j:j + k, j:j + k] = p
        j += k
    return out


def _singular(M, Delta) -> bool:
    E = np.eye(M.shape[0]) - M @ Delta
    s = np.linalg.svd(E, compute_uv=False)
    return bool(s[-1] <= _SING * (1.0 + np.linalg.norm(M @ Delta, 2)))


def _search(Mfun, st: _Structure, x0, w0=None, wscale: float = 1.0):
    """Minimize ``max norm`` s.t. ``det(I - M(w) Delta(x)) = 0``; return (x, w) or None.

    ``Mfun(w)`` gives ``M`` at frequency ``w``; with ``w0`` None the frequency is fixed.
    """
    free_w = w0 is not None
    m = st.size

    def unpack(z):
        return z[:m], (abs(z[m]) * wscale if free_w else None), z[-1]

    def det(z):
        x, w, _ = unpack(z)
        M = Mfun(w)
        d = np.linalg.det(np.eye(M.shape[0]) - M @ st.delta(x))
        return np.array([d.real, d.imag])

    def det_jac(z):
        # d det(E) = -det(E) tr(E^-1 M dDelta), E = I - M Delta (Jacobi's formula).
        x, w, _ = unpack(z)
        M = Mfun(w)
        E = np.eye(M.shape[0]) - M @ st.delta(x)
        d = np.linalg.det(E)
        try:
            W = np.linalg.solve(E, M)
        except np.linalg.LinAlgError:
            W = np.linalg.pinv(E) @ M
        g = -d * st.trace_gradient(W, x)
        J = np.zeros((2, z.size))
        J[0, :m], J[1, :m] = g.real, g.imag
        if free_w:
            h = 1e-7 * max(1.0, abs(z[m]))
            zp = z.copy()
            zp[m] += h
            J[:, m] = (det(zp) - det(z)) / h
        return J

    def norms(z):
        x, _, s = unpack(z)
        return s - st.norms(x)

    def norms_jac(z):
        x, _, _ = unpack(z)
        J = np.zeros((len(st.blocks), z.size))
        J[:, -1] = 1.0
        i = 0
        for r, (kind, n) in enumerate(st.blocks):
            if kind == "real":
                J[r, i] = -np.sign(x[i])
                i += 1
            else:
                a, b = x[i:i + 2 * n], x[i + 2 * n:i + 4 * n]
                na, nb = np.linalg.norm(a), np.linalg.norm(b)
                J[r, i:i + 2 * n] = -nb * a / max(na, 1e-300)
                J[r, i + 2 * n:i + 4 * n] = -na * b / max(nb, 1e-300)
                i += 4 * n
        return J

    s0 = float(np.max(st.norms(x0))) or 1.0
    z0 = np.concatenate([x0, [w0 / wscale] if free_w else [], [s0]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            res = scipy.optimize.minimize(
                lambda z: z[-1], z0, method="SLSQP",
                constraints=[{"type": "eq", "fun": det, "jac": det_jac},
                             {"type": "ineq", "fun": norms, "jac": norms_jac}],
                jac=lambda z: np.eye(z.size)[-1], options={"maxiter": 60, "ftol": 1e-12})
        except (ValueError, np.linalg.LinAlgError):
            return None
    x, w, _ = unpack(res.x)
    if not np.all(np.isfinite(res.x)):
        return None
    return x, w


def _starts(M, st: _Structure, rng, count: int):
    """Return starting points: the top singular pair of ``M``, then random structured directions."""
    U, s, Vh = np.linalg.svd(M)
    starts = [st.from_matrix(np.outer(Vh[0].conj(), U[:, 0].conj()) / max(s[0], 1e-300))]
    for sign in (1.0, -1.0):  # the vertices where every real parameter moves together
        x = np.where(_real_mask(st), sign, rng.standard_normal(st.size))
        lam = np.linalg.eigvals(M @ st.delta(x))
        if np.any(np.abs(lam) > 0):
            starts.append(_scale_start(st, x, lam[int(np.argmax(np.abs(lam)))]))
    for _ in range(count):
        x = rng.standard_normal(st.size)
        E = M @ st.delta(x)
        lam = np.linalg.eigvals(E)
        k = int(np.argmax(np.abs(lam)))
        if abs(lam[k]) > 0:
            starts.append(_scale_start(st, x, lam[k]))
    return starts


def _real_mask(st: _Structure) -> np.ndarray:
    mask, i = np.zeros(st.size, dtype=bool), 0
    for kind, n in st.blocks:
        if kind == "real":
            mask[i] = True
            i += 1
        else:
            i += 4 * n
    return mask


def _scale_start(st, x, lam):
    """Scale ``x`` so that the eigenvalue ``lam`` of ``M Delta(x)`` would move to 1."""
    y, i = x.copy(), 0
    for kind, n in st.blocks:
        if kind == "real":
            y[i] = x[i] * np.sign(lam.real or 1.0) / abs(lam)
            i += 1
        else:
            a = (x[i:i + n] + 1j * x[i + n:i + 2 * n]) / lam
            y[i:i + n], y[i + n:i + 2 * n] = a.real, a.imag
            i += 4 * n
    return y


def _lower(M, blocks, rng, starts: int = 4, warm=None) -> tuple[float, np.ndarray | None]:
    """Lower bound ``1/max norm`` of a checked singular ``Delta``, and its ``x`` (or 0, None).

    Searches on the balanced matrix (:func:`_balance`: the same ``det(I - M Delta)`` for every
    structured ``Delta``, better conditioned); stops early when the bound reaches its
    ``sigma_max`` (``mu`` cannot exceed it).
    """
    st = _Structure(blocks)
    if len(blocks) == 1 and blocks[0][0] == "real":
        # One repeated real scalar: exact, mu = max |lambda| over the real eigenvalues of M.
        lam = np.linalg.eigvals(M)
        real = lam[np.abs(lam.imag) <= 1e-9 * np.maximum(np.abs(lam), 1e-300)].real
        if not real.size or np.max(np.abs(real)) == 0:
            return 0.0, None
        top = real[int(np.argmax(np.abs(real)))]
        return float(abs(top)), np.array([1.0 / top])
    d = _balance(M, blocks)
    M = (d[:, None] * M) / d[None, :]
    best, xbest = 0.0, None
    cap = (1.0 - 1e-6) * float(np.linalg.norm(M, 2))
    cands = ([warm] if warm is not None else []) + _starts(M, st, rng, starts)
    for x0 in cands:
        if best >= cap:
            break
        out = _search(lambda w: M, st, x0)
        if out is None:
            continue
        x = out[0]
        nrm = float(np.max(st.norms(x)))
        if nrm > 0 and _singular(M, st.delta(x)) and 1.0 / nrm > best:
            best, xbest = 1.0 / nrm, x
    return best, xbest


# ---------------------------------------------------------------- public API

def mussv(M, blocks, omega=None, *, seed: int = 0,
          lower: bool = True) -> tuple[np.ndarray, np.ndarray]:
    r"""Upper and lower bounds of the structured singular value of ``M`` at each frequency.

    Parameters
    ----------
    M : control.LTI or array-like, shape (nw, n, n) or (n, n)
        The loop's ``M`` (continuous time), or its frequency response (complex).
    blocks : list of (str, int)
        The structure ``Delta = diag(...)``, in order: ``("real", n)`` a repeated real scalar
        ``delta I_n``, ``("complex", n)`` a full complex ``n x n`` block. The sizes add up to
        ``n``.
    omega : array-like, shape (nw,)
        Frequencies [rad/s], ``>= 0``; required when ``M`` is a system.
    seed : int
        Seed of the lower bound's random starts (``numpy.random.default_rng``).
    lower : bool
        False skips the lower bound's search (``lower`` is then all 0, and the bisection of
        the upper bound starts from 0).

    Returns
    -------
    upper, lower : ndarray, shape (nw,)
        ``lower <= mu_Delta(M(j omega)) <= upper``. ``upper`` is verified (see the module
        docstring) and within a relative 5e-3 of the LMI's optimum; ``lower`` is 0 where the
        search found no singular ``Delta``.

    Raises
    ------
    ValueError
        A malformed structure, sizes that do not match ``M``, non-finite data or frequencies
        (each a ``FieldError`` or ``DimensionMismatchError`` naming the field).

    References
    ----------
    Fan, Tits and Doyle (1991); Young, Newlin and Doyle (1992) (module docstring).
    """
    blocks = _check_blocks(blocks)
    H, _ = _response(M, omega, _size(blocks))
    rng = np.random.default_rng(check_count("seed", seed))
    search = lower
    upper, lower = np.zeros(len(H)), np.zeros(len(H))
    warm = None
    for k, Mk in enumerate(H):
        if search:
            lower[k], x = _lower(Mk, blocks, rng, warm=warm)
            warm = x if x is not None else warm
        upper[k] = _upper(Mk, blocks, lower[k])
    return upper, lower


@dataclass(frozen=True)
class RobstabResult:
    """Robust stability margin of the loop ``det(I - M Delta)`` (:func:`robstab`).

    Attributes
    ----------
    margin_lower, margin_upper : float
        ``margin_lower <= margin <= margin_upper``: the loop is stable for every ``Delta`` of
        the structure with ``sigma_max(Delta) < margin_lower`` (at the frequencies evaluated)
        and a ``Delta`` of size ``margin_upper`` destabilizes it (``inf`` if none was found).
        ``1/margin`` is the peak ``mu``.
    critical_frequency : float
        Frequency [rad/s] of the destabilizing ``Delta`` (of the peak upper bound if none);
        ``inf`` when it is the high-frequency limit ``det(I - D Delta) = 0`` (the loop loses
        well-posedness: a pole leaves through infinity).
    omega : ndarray, shape (nw,)
        Frequencies evaluated [rad/s], ascending.
    upper, lower : ndarray, shape (nw,)
        The ``mu`` bounds there (:func:`mussv`).
    destabilizing : ndarray or None
        The destabilizing ``Delta`` found, shape (n, n), complex (None if none).
    vertices_checked : int
        Vertices (or samples) of the real parameter box scaled to ``margin_lower``, checked
        stable on the closed-loop matrix (0 when ``M`` is a frequency response or has
        complex blocks).
    """

    margin_lower: float
    margin_upper: float
    critical_frequency: float
    omega: np.ndarray
    upper: np.ndarray
    lower: np.ndarray
    destabilizing: np.ndarray | None
    vertices_checked: int


def closed_loop_matrix(M: control.StateSpace, Delta) -> np.ndarray:
    r"""State matrix of ``M`` closed by a constant ``w = Delta z``.

    .. math:: A_{cl} = A + B \Delta (I - D \Delta)^{-1} C

    Parameters
    ----------
    M : control.StateSpace
        ``z = C x + D w``, ``xdot = A x + B w``, ``n x n``.
    Delta : array-like, shape (n, n)

    Returns
    -------
    ndarray, shape (nx, nx)
        Complex if ``Delta`` is.
    """
    Delta = np.asarray(Delta)
    n = Delta.shape[0]
    return M.A + M.B @ Delta @ np.linalg.solve(np.eye(n) - M.D @ Delta, M.C)


def _default_omega(sys: control.StateSpace) -> np.ndarray:
    p = np.abs(np.linalg.eigvals(sys.A)) if sys.nstates else np.array([1.0])
    p = p[p > 0] if np.any(p > 0) else np.array([1.0])
    lo, hi = np.log10(p.min()) - 2, np.log10(p.max()) + 2
    return np.concatenate([[0.0], np.logspace(lo, hi, 30)])


def robstab(M, blocks, omega=None, *, seed: int = 0, vertices: int = 1024) -> RobstabResult:
    r"""Robust stability margin of ``det(I - M Delta)``, as MATLAB's ``robstab``.

    The margin is the factor by which the uncertainty may grow before the loop loses
    stability: the loop is stable for every structured ``Delta`` with ``sigma_max(Delta) <
    margin``, and ``margin = 1 / sup_w mu_Delta(M(jw))``.

    Parameters
    ----------
    M : control.StateSpace or control.LTI
        Stable, continuous-time, ``n x n``.
    blocks : list of (str, int)
        The structure (:func:`mussv`).
    omega : array-like, optional
        Frequencies [rad/s]; default 0 and 30 points two decades around ``M``'s poles. The
        critical frequencies found by the search are added.
    seed : int
        Seed of the random starts.
    vertices : int
        At most this many vertices of the real box (all of them if ``2^k`` is not more, else
        random vertices) are checked stable at ``0.999 margin_lower`` when all blocks are
        real; a vertex found unstable there raises ``RuntimeError`` (the grid missed a peak).

    Returns
    -------
    RobstabResult

    Raises
    ------
    ValueError
        ``M`` unstable or not a system, or a malformed structure.
    RuntimeError
        The vertex check contradicted ``margin_lower``.
    """
    blocks = _check_blocks(blocks)
    if not isinstance(M, control.LTI):
        raise FieldError("M", f"{{name}} must be a python-control system for robstab, got "
                              f"{type(M).__name__}")
    sys = control.ss(check_lti(M, "M"))
    if sys.nstates and np.max(np.linalg.eigvals(sys.A).real) >= 0:
        raise FieldError("M", "{name} is not stable: robstab measures how much uncertainty a "
                              "stable nominal loop tolerates")
    w = _default_omega(sys) if omega is None else _check_omega(omega)
    rng = np.random.default_rng(check_count("seed", seed))
    check_count("vertices", vertices)
    upper, lower = mussv(sys, blocks, w, seed=seed)
    st = _Structure(blocks)

    def Mfun(x):
        return _at(sys, x)

    # Search the frequency with the parameters, from the best points of the grid.
    best, xbest, wbest = 0.0, None, float(w[int(np.argmax(upper))])
    wscale = max(float(np.max(w)), 1.0)
    for k in _candidates(Mfun, st, w, upper, lower, rng):
        for x0 in _starts(Mfun(w[k]), st, rng, 3):
            out = _search(Mfun, st, x0, w0=max(w[k], 1e-6), wscale=wscale)
            if out is None:
                continue
            x, wx = out
            nrm = float(np.max(st.norms(x)))
            if nrm > 0 and _singular(Mfun(wx), st.delta(x)) and 1.0 / nrm > best:
                best, xbest, wbest = 1.0 / nrm, x, wx
    if best > 0 and not np.any(np.isclose(w, wbest, rtol=1e-9)):
        u, lo = mussv(sys, blocks, [wbest], seed=seed)
        w, upper, lower = (np.append(w, wbest), np.append(upper, u), np.append(lower, lo))
    order = np.argsort(w)
    w, upper, lower = w[order], upper[order], lower[order]
    peak_lower = max(best, float(lower.max()))
    if peak_lower > best:
        k = int(np.argmax(lower))
        _, xbest = _lower(np.asarray(Mfun(w[k])), blocks, np.random.default_rng(seed))
        wbest = float(w[k])
    # The high-frequency limit M(j inf) = D: det(I - D Delta) = 0 is a loss of well-posedness
    # (a pole through infinity), which no finite grid sees.
    u_inf, l_inf = mussv(sys.D[None].astype(complex), blocks, seed=seed)
    if l_inf[0] > peak_lower:
        peak_lower, wbest = float(l_inf[0]), np.inf
        _, xbest = _lower(sys.D.astype(complex), blocks, np.random.default_rng(seed))
    peak_upper = max(float(upper.max()), float(u_inf[0]), peak_lower)
    margin_lower = 1.0 / peak_upper if peak_upper > 0 else np.inf
    checked = 0
    if all(kind == "real" for kind, _ in blocks) and sys.nstates and np.isfinite(margin_lower):
        checked = _check_vertices(sys, blocks, 0.999 * margin_lower, vertices, rng)
    return RobstabResult(
        margin_lower=margin_lower,
        margin_upper=1.0 / peak_lower if peak_lower > 0 else np.inf,
        critical_frequency=float(wbest),
        omega=w, upper=upper, lower=lower,
        destabilizing=None if xbest is None else st.delta(xbest),
        vertices_checked=checked)


def _candidates(Mfun, st: _Structure, w, upper, lower, rng) -> list[int]:
    """Return the grid indices to start the joint search from.

    The 4 highest bounds, and the frequencies where ``M(jw) Delta`` (a random structured
    direction) has an eigenvalue closest to real (local minima of its relative
    imaginary part), largest eigenvalues first.
    """
    picks = list(np.argsort(-np.maximum(upper, lower))[:4])
    x = rng.standard_normal(st.size)
    score, size = np.zeros(len(w)), np.zeros(len(w))
    for k, wk in enumerate(w):
        lam = np.linalg.eigvals(Mfun(wk) @ st.delta(x))
        r = np.abs(lam.imag) / np.maximum(np.abs(lam), 1e-300)
        i = int(np.argmin(r - 1e-3 * np.abs(lam) / max(np.abs(lam).max(), 1e-300)))
        score[k], size[k] = r[i], abs(lam[i])
    minima = [k for k in range(len(w)) if (k == 0 or score[k] <= score[k - 1])
              and (k == len(w) - 1 or score[k] <= score[k + 1])]
    minima.sort(key=lambda k: -size[k])
    return list(dict.fromkeys(picks + minima[:4]))


def _check_vertices(sys, blocks, alpha, limit, rng) -> int:
    k = len(blocks)
    if 2 ** k <= limit:
        signs = np.array(list(itertools.product((-1.0, 1.0), repeat=k)))
    else:
        signs = rng.choice((-1.0, 1.0), size=(limit, k))
    sizes = [n for _, n in blocks]
    for sg in signs:
        Delta = np.diag(np.repeat(alpha * sg, sizes))
        if np.max(np.linalg.eigvals(closed_loop_matrix(sys, Delta)).real) >= 0:
            raise RuntimeError(f"robstab: the vertex {sg.tolist()} of the box scaled to "
                               f"{alpha:.6g} is unstable, below the margin the frequency grid "
                               f"gave; pass a finer omega")
    return len(signs)

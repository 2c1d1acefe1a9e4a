r"""The digital FL loop on a set of plants: exact discrete closed loops and frequency responses.

The law of eq. (8)-(10), sampled at ``rate`` [Hz] (Tustin ``K``, zero-order hold), acting on
each plant of a set linearized at a frozen configuration ``home``; the loop is broken at the
torque input, where delays and actuators act (:mod:`rrr_pin.campaign.stress`). With the law's
nominal model ``(Mhat, hhat)`` and plant ``i``'s ``qdd = A_q q + A_v qd + B tau``
(Pinocchio's ``computeABADerivatives``), regulation about ``home``:

.. math:: \tau = \hat M \bar\tau + H_q q + H_v \dot q, \quad
          \bar\tau = -\lambda^2 (q + y) - 2\lambda \dot q, \quad y = K_d(z) q

with ``H_q, H_v`` the law's own ``dhhat/dq, dhhat/dqd`` (so on the nominal plant the loop is
the double integrator of :class:`~rrr_pin.control.laws.FLLinearModel` exactly).

* :class:`LoopSet` holds the plants' linearizations and their zero-order-hold frequency
  responses, computed once; a law ``(lam, K)`` is then cheap to evaluate on all of them
  (:meth:`LoopSet.loop_response`), which is what the tuner does at every step.
* :meth:`LoopSet.spectral_radius` is the exact discrete closed loop of one plant with a
  fractional transport delay [s] and a first-order actuator [rad/s] (exact discretization,
  Franklin, Powell & Workman sec. 4.3.4, as :func:`rrr_pin.campaign.stress.spectral_radius`,
  generalized here to a plant that is not the double integrator).

References
----------
.. [1] The paper, eq. (8)-(11).
.. [2] G. F. Franklin, J. D. Powell, M. Workman, *Digital Control of Dynamic Systems*, 3rd
   ed., 1998, sec. 4.3.4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ..validation import check_rate, check_vector

__all__ = ["zoh", "split_delay", "delayed_loop_matrix", "LoopSet", "LawResponse",
           "tustin_response", "delay_margin_from_response",
           "actuator_margin_from_response", "siso_coefficients"]


def tustin_response(K, w: np.ndarray, rate: float) -> np.ndarray:
    r"""``K_d(e^{j w T})`` of the Tustin discretization of a SISO ``K(s)``, shape (nw,).

    Tustin maps ``z = e^{j w T}`` to ``s = j (2/T) tan(w T / 2)`` exactly, so the discrete
    response is the continuous one at the warped frequency (no discretization needed).
    """
    if K is None:
        return np.zeros(w.shape, complex)
    T = 1.0 / rate
    s = 1j * (2.0 / T) * np.tan(w * T / 2.0)
    num, den = siso_coefficients(K)
    return np.polyval(num, s) / np.polyval(den, s)


def siso_coefficients(K) -> tuple[np.ndarray, np.ndarray]:
    """Return the numerator and denominator coefficients of a SISO ``K`` (python-control LTI).

    Returns
    -------
    num, den : ndarray, shape (m + 1,), (p + 1,)
        Highest power first.
    """
    import control

    if not isinstance(K, control.TransferFunction):
        K = control.tf(K)
    return tuple(np.asarray(x, dtype=float).ravel() for x in (K.num[0][0], K.den[0][0]))


def _tustin_ss(K, T: float) -> tuple:
    r"""``(A_d, B_d, C_d, D_d)`` of the Tustin discretization of a SISO ``K`` (None: empty).

    The controllable canonical realization of ``K``'s coefficients (the form of scipy's
    ``tf2ss``; not reduced, so an exactly cancelled pole of ``K`` stays as a mode the law does
    not excite) mapped by the bilinear transform (the formulas of scipy's ``cont2discrete``,
    ``method="bilinear"``). Written out because the two scipy calls cost ~1 ms per law on the
    tuner's path; ``tests/test_tuning.py`` checks them against scipy.
    Shapes (m, m), (m, 1), (1, m), float.
    """
    if K is None:
        return np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), 0.0
    num, den = siso_coefficients(K)
    num = np.trim_zeros(num, "f")
    den = np.trim_zeros(den, "f")
    m = den.size - 1
    if num.size > den.size:
        raise ValueError(f"K must be proper, got numerator degree {num.size - 1} over "
                         f"denominator degree {m}")
    num, den = np.concatenate([np.zeros(den.size - num.size), num]) / den[0], den / den[0]
    D = num[0]
    if m == 0:
        return np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), float(D)
    A = np.zeros((m, m))
    A[0] = -den[1:]
    A[1:, :-1] = np.eye(m - 1)
    B = np.zeros((m, 1))
    B[0, 0] = 1.0
    C = (num[1:] - D * den[1:])[None, :]
    # bilinear: I - A T/2 solved against I + A T/2, T B and C^T
    ima = np.eye(m) - 0.5 * T * A
    Ad = np.linalg.solve(ima, np.eye(m) + 0.5 * T * A)
    Bd = np.linalg.solve(ima, T * B)
    Cd = np.linalg.solve(ima.T, C.T).T
    return Ad, Bd, Cd, float(D + 0.5 * (C @ Bd)[0, 0])


@dataclass(frozen=True)
class LawResponse:
    """A law ``(lam, K)`` on a :class:`LoopSet`: its torque response and its discrete matrices.

    Attributes
    ----------
    C : ndarray, shape (nw, n, 2n), complex
        ``tau = C(e^{jwT}) [q; qd]`` [N m per rad, N m per rad/s].
    law : tuple of ndarray
        ``(Ac, Bc, Cc, Dc)``: ``x+ = Ac x + Bc [q; qd]``, ``tau = Cc x + Dc [q; qd]``.
    a : ndarray, shape (nw, n), complex
        ``lam_j^2 (1 + K_j(e^{jwT}))`` per joint [1/s^2]: ``C_q = -Mhat diag(a) + H_q``.
    b : ndarray, shape (n,)
        ``2 lam_j`` per joint [1/s]: ``C_qd = -Mhat diag(b) + H_v``.
    uniform : bool
        The same ``lam`` and ``K`` on every joint.
    """

    C: np.ndarray
    law: tuple
    a: np.ndarray
    b: np.ndarray
    uniform: bool = False


class LoopSet:
    """A set of plants linearized at ``home`` under one nominal model, sampled at ``rate``.

    Parameters
    ----------
    nominal : Plant
        The law's model.
    plants : sequence of Plant
        The plants the loop must work on (the nominal one among them if it must).
    home : array-like, shape (n,)
        Frozen configuration [rad].
    rate : float
        Sampling rate of the law [Hz].
    omega : array-like, optional
        Frequencies [rad/s] of the responses; default 200 points from 0.1 rad/s to 0.999 of
        the Nyquist frequency ``pi rate``.
    """

    def __init__(self, nominal, plants, home, rate: float, omega=None):
        self.rate = check_rate("rate", rate)
        self.T = 1.0 / self.rate
        self.n = n = nominal.nq
        self.home = q0 = check_vector("home", home, n)
        self.plants = list(plants)
        nyq = math.pi * self.rate
        self.omega = (np.geomspace(0.1, 0.999 * nyq, 200) if omega is None
                      else np.asarray(omega, dtype=float))
        Mhat = np.asarray(nominal.M(q0))
        dq0, dv0, _ = nominal.linearization(q0, nominal.G(q0))
        self.Mhat = Mhat
        self.Hq, self.Hv = -Mhat @ dq0, -Mhat @ dv0
        self.A, self.B, self._zohs = [], [], {}
        for p in self.plants:
            dq, dv, dtau = p.linearization(q0, p.G(q0))
            Z, eye = np.zeros((n, n)), np.eye(n)
            self.A.append(np.block([[Z, eye], [dq, dv]]))
            self.B.append(np.vstack([Z, dtau]))
        self.P = self.plant_response(self.omega)
        self._parts = self.parts(self.P)

    def subset(self, plants: slice) -> LoopSet:
        """Return the set restricted to the plants ``plants``, a slice (responses are views).

        The law's nominal, grid and rate are shared; the plants' discretizations are cached
        per subset (:meth:`spectral_radius` of a subset indexes its own plants).
        """
        sub = object.__new__(LoopSet)
        sub.__dict__.update(self.__dict__)
        sub.plants, sub.A, sub.B = self.plants[plants], self.A[plants], self.B[plants]
        sub.P = self.P[plants]
        sub._parts = tuple(x[plants] for x in self._parts)
        sub._zohs = {}
        return sub

    def parts(self, P) -> tuple:
        """Law-independent parts of ``L = Mhat (diag(a) P_q + diag(b) P_qd) + Z`` for ``P``.

        ``Z = -(H_q P_q + H_v P_qd)``; with them :meth:`loop_response` needs one small product
        per law instead of the full ``C P``.

        Returns
        -------
        tuple of ndarray
            ``(P_q, P_qd, Z, Mhat P_q, Mhat P_qd)``, each shape (np, nw, n, n), complex.
        """
        n = self.n
        Pq, Pv = P[..., :n, :], P[..., n:, :]
        return Pq, Pv, -(self.Hq @ Pq + self.Hv @ Pv), self.Mhat @ Pq, self.Mhat @ Pv

    def plant_response(self, omega) -> np.ndarray:
        """Zero-order-hold responses ``[q; qd](e^{jwT}) / tau``, shape (np, nw, 2n, n)."""
        z = np.exp(1j * np.asarray(omega) * self.T)
        out = []
        for A, B in zip(self.A, self.B, strict=True):
            Phi, Gam = zoh(A, B, self.T)
            eye = np.eye(A.shape[0])
            M = z[:, None, None] * eye - Phi
            out.append(np.linalg.solve(M, np.broadcast_to(Gam, (z.size, *Gam.shape))))
        return np.array(out)

    def law(self, lam, K, omega=None, matrices: bool = True) -> LawResponse:
        """Response and discrete matrices of the law ``(lam, K)``.

        Parameters
        ----------
        lam : float or array-like, shape (n,)
            FL bandwidth [rad/s], shared or per joint.
        K : SISO LTI, sequence of n SISO LTI (or None), or None
            The outer controller on ``e``: shared by every joint, one per joint (None: no
            ``K`` on that joint), or None (FL alone).
        omega : array-like, optional
            Frequencies [rad/s] (default the set's grid).
        matrices : bool
            False skips the discrete matrices (``law`` is then None).
        """
        n, Mhat = self.n, self.Mhat
        w = self.omega if omega is None else np.asarray(omega)
        lam = np.broadcast_to(np.asarray(lam, dtype=float), (n,))
        shared = not isinstance(K, list | tuple)
        Ks = [K] * n if shared else list(K)
        kd = tustin_response(Ks[0], w, self.rate)[:, None] if shared else np.stack(
            [tustin_response(k, w, self.rate) for k in Ks], axis=1)
        a = np.broadcast_to(lam * lam * (1.0 + kd), (w.size, n))
        b = 2.0 * lam
        C = np.empty((w.size, n, 2 * n), complex)
        C[:, :, :n] = -Mhat[None] * a[:, None, :] + self.Hq
        C[:, :, n:] = -Mhat * b + self.Hv
        uniform = shared and bool(np.all(lam == lam[0]))
        if not matrices:
            return LawResponse(C, None, a, b, uniform)
        parts = [_tustin_ss(k, self.T) for k in ([Ks[0]] if shared else Ks)]
        if shared:
            parts = parts * n
        Ac = scipy.linalg.block_diag(*[p[0] for p in parts])
        Bk = scipy.linalg.block_diag(*[p[1] for p in parts])
        Ck = scipy.linalg.block_diag(*[p[2] for p in parts])
        Dd = np.array([p[3] for p in parts])
        Bc = np.hstack([-Bk, np.zeros((Ac.shape[0], n))])
        Cc = (Mhat * lam * lam) @ Ck
        Dc = np.hstack([-Mhat * (lam * lam * (1.0 + Dd)) + self.Hq, -Mhat * b + self.Hv])
        return LawResponse(C, (Ac, Bc, Cc, Dc), a, b, uniform)

    def loop_response(self, law: LawResponse, P=None, parts=None) -> np.ndarray:
        """``L = -C P`` at the torque input for every plant, shape (np, nw, n, n).

        Computed as ``Mhat (diag(a) P_q + diag(b) P_qd) + Z`` from :meth:`parts` (of ``P``,
        or the given ``parts``; the grid's own are kept), equal to ``-C P`` to rounding; for
        a law the same on every joint, ``a Mhat P_q + b Mhat P_qd + Z``.
        """
        if parts is None:
            parts = self._parts if P is None else self.parts(P)
        Pq, Pv, Z, X, Y = parts
        if law.uniform:
            return law.a[:, 0, None, None] * X + law.b[0] * Y + Z
        return self.Mhat @ (law.a[:, :, None] * Pq + law.b[:, None] * Pv) + Z

    def _discrete(self, i: int, delay: float, bandwidth):
        """Return plant ``i`` (with the actuator) over one period split by the delay's fraction.

        ``((E0, G0, Phi, G1), ell)``, computed once per plant, fraction and actuator.
        """
        n = self.n
        A0, B0 = self.A[i], self.B[i]
        if bandwidth:
            nz = 3 * n
            A = np.zeros((nz, nz))
            A[:2 * n, :2 * n] = A0
            A[:2 * n, 2 * n:] = B0
            A[2 * n:, 2 * n:] = -bandwidth * np.eye(n)
            B = np.vstack([np.zeros((2 * n, n)), bandwidth * np.eye(n)])
        else:
            nz, A, B = 2 * n, A0, B0
        T = self.T
        ell, frac = split_delay(delay, T)
        key = (i, frac, bandwidth)
        if key not in self._zohs:     # the plant's discretization, shared by every law
            E0, G0 = zoh(A, B, T - frac)
            E1, G1i = zoh(A, B, frac) if frac else (None, np.zeros_like(B))
            if len(self._zohs) > 10000:
                self._zohs.clear()
            self._zohs[key] = (E0, G0, E0 @ E1 if frac else E0, E0 @ G1i)
        return self._zohs[key], ell

    def closed_loop(self, i: int, law: LawResponse, delay: float = 0.0,
                    bandwidth: float | None = None) -> np.ndarray:
        """State matrix of plant ``i``'s exact discrete closed loop with a delay and actuator.

        The plant (with ``a' = wa (u - a)`` when ``bandwidth`` is given) driven by the law's
        zero-order-hold torque delayed by ``delay`` [s] is discretized exactly at ``T``; a
        fractional delay splits the period (Franklin, Powell & Workman sec. 4.3.4).
        """
        (_, G0, Phi, G1), ell = self._discrete(i, delay, bandwidth)
        return delayed_loop_matrix(Phi, G0, G1, ell, law.law, self.n)

    def spectral_radius(self, law: LawResponse, delay: float = 0.0,
                        bandwidth: float | None = None, plants=None) -> np.ndarray:
        """Largest ``|eigenvalue|`` of each plant's exact closed loop, shape (np,) (< 1: stable)."""
        idx = range(len(self.plants)) if plants is None else plants
        parts = [self._discrete(i, delay, bandwidth) for i in idx]
        ell = parts[0][1]
        Phi, G0, G1 = (np.array([p[0][k] for p in parts]) for k in (2, 1, 3))
        mats = delayed_loop_matrix(Phi, G0, G1, ell, law.law, self.n)   # stacked, one size
        return np.abs(np.linalg.eigvals(mats)).max(axis=-1)

    def effect_plant(self, i: int, delay: float = 0.0,
                     bandwidth: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        r"""Plant ``i`` behind a delay and an actuator as one discrete system, exactly.

        The plant of :meth:`closed_loop` (zero-order hold, actuator ``wa/(s + wa)`` as
        states, fractional delay: Franklin, Powell & Workman sec. 4.3.4) with the delayed
        inputs ``w_k = u_{k-k}``, ``k = 1..ell+1``, as states:
        ``x = (z, w_1, ..., w_{ell+1})``, ``x+ = F x + H u``, output ``[q; qd] = x[:2n]``.

        Returns
        -------
        F : ndarray, shape (nx, nx)
        H : ndarray, shape (nx, n)
        """
        n = self.n
        (_, G0, Phi, G1), ell = self._discrete(i, delay, bandwidth)
        nz, L = Phi.shape[0], ell + 1
        F = np.zeros((nz + L * n, nz + L * n))
        H = np.zeros((nz + L * n, n))
        F[:nz, :nz] = Phi
        if ell == 0:
            H[:nz] = G0
        else:
            F[:nz, nz + (ell - 1) * n:nz + ell * n] = G0
        F[:nz, nz + ell * n:] = G1
        H[nz:nz + n] = np.eye(n)
        for k in range(1, L):
            F[nz + k * n:nz + (k + 1) * n, nz + (k - 1) * n:nz + k * n] = np.eye(n)
        return F, H

    def effect_response(self, omega, delay: float = 0.0,
                        bandwidth: float | None = None) -> np.ndarray:
        r"""Exact responses ``[q; qd](e^{jwT}) / u`` of every plant behind a delay and actuator.

        .. math:: P_e(z) = \big[(zI - \Phi)^{-1} (G_0 z^{-\ell} + G_1 z^{-\ell-1})\big]_{2n}

        (:meth:`effect_plant`); without effects, :meth:`plant_response`.

        Returns
        -------
        ndarray, shape (np, nw, 2n, n), complex
        """
        if not delay and not bandwidth:
            return self.plant_response(omega)
        z = np.exp(1j * np.asarray(omega, dtype=float) * self.T)
        out = []
        for i in range(len(self.plants)):
            (_, G0, Phi, G1), ell = self._discrete(i, delay, bandwidth)
            eye = np.eye(Phi.shape[0])
            rhs = (G0[None] * z[:, None, None] ** -ell
                   + G1[None] * z[:, None, None] ** (-ell - 1))
            X = np.linalg.solve(z[:, None, None] * eye - Phi, rhs)
            out.append(X[:, :2 * self.n])
        return np.array(out)


def zoh(A, B, t):
    """Return ``(e^{A t}, int_0^t e^{A s} ds B)``: the zero-order hold over ``t`` [s]."""
    n, m = A.shape[0], B.shape[1]
    blk = np.zeros((n + m, n + m))
    blk[:n, :n], blk[:n, n:] = A, B
    E = scipy.linalg.expm(blk * t)
    return E[:n, :n], E[:n, n:]


def split_delay(delay: float, T: float) -> tuple[int, float]:
    """Return ``(ell, frac)``: ``delay`` [s] as whole periods ``T`` and a fraction [s] (< T)."""
    ell = int(math.floor(delay / T + 1e-12))
    frac = delay - ell * T
    return ell, 0.0 if frac < 1e-15 else frac


def delayed_loop_matrix(Phi, G0, G1, ell: int, K, n: int) -> np.ndarray:
    r"""State matrix of a sampled loop whose zero-order-hold input is delayed.

    The plant ``z+ = Phi z + G0 u_{k-ell} + G1 u_{k-ell-1}`` (a delay of ``ell`` whole periods
    plus a fraction: ``u_{k-ell}`` held over the end of the period, ``u_{k-ell-1}`` over its
    start; Franklin, Powell & Workman sec. 4.3.4), measured as ``y = z[:2n]`` (``q``, ``qd``),
    closed by the discrete law ``K = (A_k, B_k, C_k, D_k)``: ``x+ = A_k x + B_k y``,
    ``u = C_k x + D_k y``. The state is ``(z, x, u_{k-1}, ..., u_{k-ell-1})``.

    Parameters
    ----------
    Phi, G0, G1 : ndarray, shapes (..., nz, nz), (..., nz, n), (..., nz, n)
        The plant over one period (:func:`zoh` of the two parts); stacked plants give
        stacked loops.
    ell : int
        Whole periods of delay (>= 0).
    K : tuple of ndarray
        The law's discrete ``(A_k, B_k, C_k, D_k)``, input ``y`` of size ``2n``.
    n : int
        Number of inputs (joints).

    Returns
    -------
    ndarray, shape (..., nz + nx + (ell + 1) n, same)
    """
    Ak, Bk, Ck, Dk = K
    Phi, G0, G1 = (np.asarray(x) for x in (Phi, G0, G1))
    lead = Phi.shape[:-2]
    nz = Phi.shape[-1]
    L = ell + 1                                 # buffer w_i = u_{k-i}, i = 1..L
    nx = Ak.shape[0]
    N = nz + nx + L * n
    Acl = np.zeros((*lead, N, N))
    Cy = np.zeros((2 * n, nz))
    Cy[:, :2 * n] = np.eye(2 * n)
    Uz, Ux = Dk @ Cy, Ck                        # u_k = C_k x + D_k Cy z
    iz, ix, iw = slice(0, nz), slice(nz, nz + nx), nz + nx

    def wslot(k):
        return slice(iw + (k - 1) * n, iw + k * n)

    Acl[..., iz, iz] = Phi
    if ell == 0:
        Acl[..., iz, iz] += G0 @ Uz
        Acl[..., iz, ix] += G0 @ Ux
    else:
        Acl[..., iz, wslot(ell)] += G0
    Acl[..., iz, wslot(ell + 1)] += G1
    Acl[..., ix, ix] = Ak
    Acl[..., ix, iz] = Bk @ Cy
    Acl[..., wslot(1), iz] = Uz
    Acl[..., wslot(1), ix] = Ux
    for k in range(2, L + 1):
        Acl[..., wslot(k), wslot(k - 1)] = np.eye(n)
    return Acl


def _sorted_eigs(L, eigs):
    lam = np.linalg.eigvals(L) if eigs is None else eigs
    return np.take_along_axis(lam, np.argsort(np.abs(lam), axis=-1), axis=-1)


def delay_margin_from_response(L: np.ndarray, omega: np.ndarray, eigs=None,
                               intervals=None) -> np.ndarray:
    r"""Common-delay margin [s] of loops from their frequency responses, per plant.

    A delay ``tau`` on every input turns ``L`` into ``e^{-j w tau} L``; the loop (stable
    without it) first loses stability where an eigenvalue ``lambda_k(jw)`` of ``L`` with
    ``|lambda_k| = 1`` is rotated onto ``-1``: ``tau = ((arg lambda_k + pi) mod 2 pi) / w``.
    The crossings of ``|lambda| = 1`` are found on the grid (eigenvalues sorted by magnitude,
    crossing and phase interpolated linearly in ``log w``).

    Parameters
    ----------
    L : ndarray, shape (np, nw, n, n)
        Loop responses.
    omega : ndarray, shape (nw,)
        Frequencies [rad/s].
    eigs : ndarray, shape (np, nw, n), complex, optional
        The eigenvalues of ``L`` if known (then ``L`` is not read; NaN where not computed).
    intervals : ndarray of bool, shape (np, nw - 1), optional
        The intervals to search
        (:func:`~rrr_pin.control.grid_bounds.crossing_intervals`); default all.

    Returns
    -------
    ndarray, shape (np,)
        Delay margins [s] (``inf`` without a crossing).
    """
    lam = _sorted_eigs(L, eigs)                                 # (np, nw, n)
    s = np.log(np.maximum(np.abs(lam), 1e-300))
    lw = np.log(omega)
    out = np.full(lam.shape[0], np.inf)
    cross = (s[:, :-1] > 0) != (s[:, 1:] > 0)                   # (np, nw-1, n)
    if intervals is not None:
        cross &= intervals[..., None]
    p, i, k = np.nonzero(cross)
    if p.size:
        f = s[p, i, k] / (s[p, i, k] - s[p, i + 1, k])
        wc = np.exp(lw[i] + f * (lw[i + 1] - lw[i]))
        step = np.angle(lam[p, i + 1, k] / lam[p, i, k])
        phi = np.angle(lam[p, i, k]) + f * step
        tau = np.mod(phi + np.pi, 2.0 * np.pi) / wc
        np.minimum.at(out, p, tau)
    return out


def actuator_margin_from_response(L: np.ndarray, omega: np.ndarray, eigs=None,
                                  intervals=None) -> np.ndarray:
    r"""Slowest first-order actuator ``wa / (s + wa)`` each loop tolerates [rad/s], per plant.

    The actuator turns an eigenvalue ``lambda`` of ``L`` into ``lambda cos(phi) e^{-j phi}``,
    ``phi = atan(w / wa)``; it reaches ``-1`` where ``phi = (arg lambda + pi) mod 2 pi`` lies
    in ``(0, pi/2)`` and ``|lambda| cos(phi) = 1``, i.e. for ``wa = w / tan(phi)``. The loop
    (stable without an actuator) tolerates every ``wa`` above the largest such value. Grid
    crossings of ``|lambda| cos(phi) = 1`` as in :func:`delay_margin_from_response` (a
    continuous-time actuator on the sampled loop's response: an estimate, verified exactly by
    :meth:`LoopSet.spectral_radius`). ``eigs`` and ``intervals`` as in
    :func:`delay_margin_from_response`.

    Returns
    -------
    ndarray, shape (np,)
        ``wa`` [rad/s] (0 without a crossing: any actuator).
    """
    lam = _sorted_eigs(L, eigs)
    phi = np.mod(np.angle(lam) + np.pi, 2.0 * np.pi)
    ok = (phi > 0.0) & (phi < np.pi / 2)
    g = np.where(ok, np.log(np.maximum(np.abs(lam) * np.cos(phi), 1e-300)), np.nan)
    out = np.zeros(lam.shape[0])
    both = ok[:, :-1] & ok[:, 1:]
    cross = both & ((g[:, :-1] > 0) != (g[:, 1:] > 0))
    if intervals is not None:
        cross &= intervals[..., None]
    p, i, k = np.nonzero(cross)
    if p.size:
        f = g[p, i, k] / (g[p, i, k] - g[p, i + 1, k])
        lw = np.log(omega)
        wc = np.exp(lw[i] + f * (lw[i + 1] - lw[i]))
        ph = phi[p, i, k] + f * (phi[p, i + 1, k] - phi[p, i, k])
        np.maximum.at(out, p, wc / np.tan(ph))
    return out

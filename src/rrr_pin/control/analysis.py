r"""Linear analysis of the loop a law closes on the arm at a frozen configuration.

* :func:`loop_at_input` - the loop broken at the torque input, as a python-control system;
* :func:`loop_margins` - its gain, phase, delay and disk margins, loop at a time;
* :func:`parametric_loop` - the feedback-linearized loop with the inertial parameters as real
  uncertainties, an LFT ``M(s)`` for :func:`rrr_pin.robust.mu.robstab`;
* :func:`parametric_margin` - that robust stability margin, in units of the tolerances;
* :func:`sampled_margin` - the same margin found by brute force on perturbed Pinocchio models
  (vertices of the parameter box, scaled), the independent check.

All linearizations are about the regulation equilibrium ``q = r = q0``, ``qd = 0``, with the
law's state at zero; the plant's is Pinocchio's exact ``computeABADerivatives``. On a parallel
mechanism (:class:`rrr_pin.model.closed_chain.ClosedChain`) the plant is the mechanism in its
actuated coordinates, ``qdd_a = M_r^-1 (tau - V_r - G_r)``: its ``q`` and ``qd`` derivatives are
central differences of :meth:`~rrr_pin.model.closed_chain.ClosedChain.forward_dynamics` (each
loop closed by Newton to 1e-12 m), its input matrix is ``M_r^-1`` exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np
import pinocchio as pin

from ..model.plant import central_jacobian
from ..robust.mu import robstab
from ..validation import check_positive, check_vector
from .laws import ControlLaw, FLLinearModel, check_law

__all__ = ["RefinedDiskMargin", "refined_disk_margin", "loop_at_input", "loop_channel",
           "LoopMargins", "loop_margins", "ParametricLoop", "parametric_loop",
           "parametric_margin", "sampled_margin"]

# Relative central-difference step of the law's linearization (the built-in laws are affine
# in qd and x and their q dependence is smooth: the error is O(h^2)).
_H = 1e-6



def loop_at_input(law, robot, q) -> control.StateSpace:
    r"""Return the linearized loop broken at the torque input, ``L = -K_tau P``.

    The plant ``P`` is ``robot`` linearized at ``(q0, 0)`` with the torque that holds it
    (Pinocchio's ``computeABADerivatives``; on a closed chain, central differences of its
    reduced forward dynamics in the actuated coordinates, input matrix ``M_r(q0)^-1``); the law
    is linearized about regulation at ``r = q0`` (central differences of ``law.torque`` and
    ``law.derivative``). Closing ``L`` in negative unit feedback gives the implemented closed loop:

    .. math:: u = \tau_{law} = -y, \quad \ddot q = \partial_q a\, q + \partial_{\dot q} a\,
              \dot q + M(q_0)^{-1} u

    Parameters
    ----------
    law : ControlLaw
        A continuous law for ``robot.nq`` joints.
    robot : rrr_pin.model.dynamics.Robot or rrr_pin.model.closed_chain.ClosedChain
        The arm the law acts on (its own nominal model for the nominal loop).
    q : array-like, shape (nq,)
        Frozen configuration [rad] (actuated coordinates on a closed chain).

    Returns
    -------
    control.StateSpace
        ``nq x nq``, input the torque [N m] injected at the actuators, output minus the law's
        torque [N m]; states ``[dq, dqd, x]``.

    Raises
    ------
    TypeError
        ``law`` is not a continuous :class:`ControlLaw`.
    ValueError
        ``q`` not finite of shape (nq,), or the law for another number of joints; on a closed
        chain, a ``q`` where the loop does not close or that is type-II singular.
    """
    n = robot.nq
    check_law(law, n)
    if not isinstance(law, ControlLaw):
        raise TypeError(f"loop_at_input takes a continuous ControlLaw, got "
                        f"{type(law).__name__}")
    q0 = check_vector("q", q, n)
    z = np.zeros(n)
    nx = int(law.nx)
    tau0 = robot.G(q0)
    dq, dv, dtau = robot.linearization(q0, tau0)
    x0 = np.concatenate([q0, z, law.initial_state()])

    def tau(s):
        return law.torque(0.0, s[:n], s[n:2 * n], q0, z, z, s[2 * n:])

    def xdot(s):
        return law.derivative(0.0, s[:n], s[n:2 * n], q0, z, z, s[2 * n:])

    T = central_jacobian(tau, x0, _H)
    X = central_jacobian(xdot, x0, _H) if nx else np.zeros((0, 2 * n))
    Z, eye = np.zeros((n, n)), np.eye(n)
    A = np.block([[Z, eye, np.zeros((n, nx))],
                  [np.asarray(dq), np.asarray(dv), np.zeros((n, nx))],
                  [X]]) if nx else np.block([[Z, eye], [np.asarray(dq), np.asarray(dv)]])
    B = np.vstack([Z, np.asarray(dtau), np.zeros((nx, n))])
    return control.ss(A, B, -T, np.zeros((n, n)))


@dataclass(frozen=True)
class LoopMargins:
    """Margins of a loop broken at the torque input, one entry per channel (loop at a time).

    Attributes
    ----------
    gain : ndarray, shape (n,)
        Gain margins [-] of python-control's ``margin`` at the phase crossing of -180 deg
        (``inf`` when there is none). Below 1 it is a lower margin: a double-integrator loop
        has phase -180 deg at ``w -> 0``, so FL alone gives about 0 (any gain in ``(0, inf)``
        keeps it stable).
    gain_lower : ndarray, shape (n,)
        Lower gain margins [-]: the loop stays stable when its gain drops to this factor,
        not below (the largest ``1/|L(jw)|`` below 1 over the phase crossings of -180 deg,
        ``w = 0`` included); 0 when no crossing limits it from below (a factor below 1e-9
        is the ``w = 0`` crossing of a double integrator through round-off: 0).
    gain_upper : ndarray, shape (n,)
        Upper gain margins [-]: stable up to this factor (the smallest ``1/|L(jw)|`` above 1
        over the crossings); ``inf`` when none limits it from above.
    phase : ndarray, shape (n,)
        Phase margins [deg].
    crossover : ndarray, shape (n,)
        Gain-crossover frequencies [rad/s].
    delay : ndarray, shape (n,)
        Delay margins [s]: ``phase / crossover`` (in radians).
    disk : float
        Multiloop disk margin ``alpha`` (balanced, ``skew = 0``) of the MIMO loop
        (python-control's ``disk_margins``): stable for simultaneous gain and phase
        changes in every channel inside the disk.
    disk_gain : float
        The gain margin that disk guarantees, as a factor [-]: ``(1 + disk/2) / (1 - disk/2)``
        for the balanced disk (any gain in ``[1/disk_gain, disk_gain]``).
    disk_gain_db : float
        The same in dB, ``20 log10(disk_gain)`` (what python-control's ``disk_margins``
        returns).
    disk_phase : float
        The phase margin [deg] that disk guarantees.
    """

    gain: np.ndarray
    gain_lower: np.ndarray
    gain_upper: np.ndarray
    phase: np.ndarray
    crossover: np.ndarray
    delay: np.ndarray
    disk: float
    disk_gain: float
    disk_gain_db: float
    disk_phase: float


def loop_channel(L: control.StateSpace, i: int) -> control.StateSpace:
    """Return the SISO loop of channel ``i`` with the other channels closed (``D = 0``).

    Parameters
    ----------
    L : control.StateSpace
        Square loop with ``D = 0`` (:func:`loop_at_input`).
    i : int
        The channel (joint), ``0 <= i < L.ninputs``.
    """
    o = [j for j in range(L.ninputs) if j != i]
    A = L.A - L.B[:, o] @ L.C[o, :]
    return control.ss(A, L.B[:, [i]], L.C[[i], :], 0)


#: A lower gain margin below this is 0: the crossing of -180 deg at ``w = 0`` of a loop with
#: two integrators (FL's, ``|L(0)| = inf``), seen through round-off (1e-23 to 1e-14 here).
_GAIN_ZERO = 1e-9


def loop_margins(L, omega=None) -> LoopMargins:
    """Gain, phase, delay and disk margins of a loop ``L`` (negative feedback, ``D = 0``).

    Parameters
    ----------
    L : control.StateSpace
        Square loop (:func:`loop_at_input`).
    omega : array-like, optional
        Frequencies [rad/s] of the disk margin; default 2000 points over 1e-2 to 1e5.

    Returns
    -------
    LoopMargins
    """
    L = control.ss(L)
    w = np.logspace(-2, 5, 2000) if omega is None else np.asarray(omega, dtype=float)
    gm, pm, wc, low, high = [], [], [], [], []
    for i in range(L.ninputs):
        Li = loop_channel(L, i)
        g, p, _, w_c = control.margin(Li)
        gm.append(g)
        pm.append(p)
        wc.append(w_c)
        # every crossing of -180 deg: the gains at which the Nyquist curve passes -1
        every = np.atleast_1d(np.asarray(control.stability_margins(Li, returnall=True)[0],
                                         dtype=float))
        # a factor below _GAIN_ZERO is the w = 0 crossing of a double integrator (|L| -> inf)
        # up to round-off: no lower limit, 0
        lo = float(every[every < 1.0].max()) if np.any(every < 1.0) else 0.0
        low.append(lo if lo >= _GAIN_ZERO else 0.0)
        high.append(float(every[every > 1.0].min()) if np.any(every > 1.0) else np.inf)
    gm, pm, wc, low, high = (np.array(x, dtype=float) for x in (gm, pm, wc, low, high))
    with np.errstate(divide="ignore", invalid="ignore"):
        delay = np.where(wc > 0, np.deg2rad(pm) / wc, np.inf)
    dm, dgm_db, dpm = control.disk_margins(L, w)  # the gain margin in dB
    return LoopMargins(gm, low, high, pm, wc, delay, float(dm),
                       float(10.0 ** (float(dgm_db) / 20.0)),
                       float(dgm_db), float(dpm))


@dataclass(frozen=True)
class RefinedDiskMargin:
    """A balanced multiloop disk margin, refined off its grid, with a certified lower bound.

    Attributes
    ----------
    alpha : float
        ``min_w 1/mu(S(jw) - I/2)`` [-] with python-control's ``disk_margins`` (SLICOT
        ``AB13MD``'s upper bound of ``mu``), its grid's local minima refined by bounded Brent
        searches in ``log w`` to a relative frequency tolerance ``xtol``: never above the
        grid's value.
    lower : float
        ``1 / ||S - I/2||_inf`` [-] (SLICOT ``AB13DD``, the H-infinity norm by Hamiltonian
        bisection, no grid): ``sigma_max >= mu``, so a certified lower bound of ``alpha``;
        equal to it for a SISO or diagonal loop. 0 when the closed loop is unstable.
    grid : float
        The value on the given grid alone (what ``disk_margins`` returns).
    omega : float
        The frequency [rad/s] of ``alpha``.
    """

    alpha: float
    lower: float
    grid: float
    omega: float


def refined_disk_margin(L, omega, *, xtol: float = 1e-6, peaks: int = 4) -> RefinedDiskMargin:
    r"""Balanced disk margin of ``L`` off the grid: its worst points refined, and bounded below.

    .. math:: \alpha = \min_\omega 1/\mu_\Delta(S(j\omega) - I/2),\qquad
              1/\|S - I/2\|_\infty \le \alpha

    A grid's minimum is above the true one when the worst frequency falls between two
    points (issue 50: 0.4753 on the grid, 0.4739 refined). The ``peaks`` lowest local minima
    of the grid are refined; a notch narrower than the grid's spacing that no grid point sees
    can still be missed, which the certified ``lower`` bound covers.

    Parameters
    ----------
    L : control.StateSpace
        Square loop, continuous or discrete (negative feedback).
    omega : array-like
        Increasing frequencies [rad/s] of the grid (below Nyquist for a discrete ``L``).
    xtol : float, default 1e-6
        Relative tolerance of the refined frequency.
    peaks : int, default 4
        How many of the grid's lowest local minima are refined.

    Returns
    -------
    RefinedDiskMargin

    References
    ----------
    .. [1] P. Seiler, A. Packard, P. Gahinet, "An introduction to disk margins", *IEEE
       Control Systems Magazine* 40(5) (2020) 78-95.
    """
    from scipy.optimize import minimize_scalar

    L = control.ss(L)
    w = np.asarray(omega, dtype=float)
    curve = np.asarray(control.disk_margins(L, w, returnall=True)[0], dtype=float)
    k0 = int(np.argmin(curve))
    best, where = float(curve[k0]), float(w[k0])
    grid = best
    inner = [k for k in range(len(w)) if (k == 0 or curve[k] <= curve[k - 1])
             and (k == len(w) - 1 or curve[k] <= curve[k + 1])]
    for k in sorted(inner, key=lambda k: curve[k])[:peaks]:
        lo, hi = np.log(w[max(k - 1, 0)]), np.log(w[min(k + 1, len(w) - 1)])
        if hi <= lo:
            continue
        res = minimize_scalar(
            lambda x: float(control.disk_margins(L, np.exp([x]))[0]), bounds=(lo, hi),
            method="bounded", options={"xatol": xtol})
        if res.fun < best:
            best, where = float(res.fun), float(np.exp(res.x))
    n = L.ninputs
    # minimal first: a loop's realization may carry modes on the boundary that S does not see
    # (a double integrator's z = 1 in a non-minimal discrete product)
    S = control.minreal(control.feedback(control.ss([], [], [], np.eye(n), L.dt), L),
                        verbose=False)
    poles = S.poles()
    stable = (np.all(np.abs(poles) < 1.0) if L.isdtime() else np.all(poles.real < 0.0))
    lower = 0.0
    if stable:
        peak = float(control.norm(S - 0.5 * np.eye(n), p="inf", print_warning=False))
        lower = min(1.0 / peak, best) if peak > 0 else best
    return RefinedDiskMargin(best, lower, grid, where)


# ---------------------------------------------------------------- parametric uncertainty

@dataclass(frozen=True)
class ParametricLoop:
    r"""The frozen feedback-linearized loop with real inertial uncertainties, as an LFT.

    With the true parameters ``p_i = p_i0 (1 + tol delta_i)``, the loop is
    ``det(I - M(s) Delta) = 0`` with ``Delta = diag(delta_i I_{r_i})``.

    Attributes
    ----------
    M : control.StateSpace
        Stable ``m x m`` system (``m = sum r_i``).
    blocks : list of (str, int)
        ``[("real", r_i), ...]`` for :func:`rrr_pin.robust.mu.robstab`.
    names : list of str
        The parameter of each block: ``"<joint>.mass"`` or ``"<joint>.J1"`` .. ``J3`` (the
        principal moments of inertia of the joint's body about its centre of mass, ascending).
    dropped : list of str
        Parameters with no effect on ``M(q)`` and ``dG/dq`` at ``q`` (left out).
    tol : float
        The relative tolerance that ``|delta_i| = 1`` stands for.
    q : ndarray, shape (n,)
        The configuration [rad].
    """

    M: control.StateSpace
    blocks: list
    names: list
    dropped: list
    tol: float
    q: np.ndarray


def _parameters(model: pin.Model):
    """Names and functions ``set(model, f)`` scaling one inertial parameter by ``f``."""
    out = []
    for j in range(1, model.njoints):
        link = model.names[j]
        out.append((f"{link}.mass", j, None))
        for k in range(3):
            out.append((f"{link}.J{k + 1}", j, k))
    return out


def _scaled(model: pin.Model, factors: dict) -> pin.Model:
    """Copy of ``model`` with ``{(joint, k): factor}`` applied (k None: the mass).

    The mass is scaled with the centre of mass and the rotational inertia about it fixed;
    ``k`` scales the ``k``-th principal moment of inertia about the centre of mass (the
    paper's ``Jx, Jy, Jz``), axes fixed. ``M(q)`` and ``dG/dq`` are affine in each factor.

    Every factor must be > 0: Pinocchio composes a subtree's inertia through its total mass
    and centre of mass, so a non-positive mass (a subtree of total mass 0 or below) gives
    meaningless ``M(q)`` (measured: 1e17 to 1e34 at the RRR's ``joint2.mass`` factors -0.5 and
    -1). Below zero, the affine extension (the LFT's, and :func:`sampled_margin`'s) holds.
    """
    bad = {key: f for key, f in factors.items() if not f > 0}
    if bad:
        raise ValueError(f"inertial scale factors must be > 0 for a Pinocchio model, got "
                         f"{bad} (below zero, use the affine extension in the factors)")
    m = model.copy()
    per_joint: dict = {}
    for (j, k), f in factors.items():
        per_joint.setdefault(j, [1.0, np.ones(3)])
        if k is None:
            per_joint[j][0] = f
        else:
            per_joint[j][1][k] = f
    for j, (fm, fJ) in per_joint.items():
        Y = model.inertias[j]
        J, R = np.linalg.eigh(0.5 * (Y.inertia + Y.inertia.T))
        Z = pin.Inertia(Y)  # set field by field: the constructor refuses a non-positive one
        Z.mass, Z.inertia = Y.mass * fm, (R * (J * fJ)) @ R.T
        m.inertias[j] = Z
    return m


#: Step of the central differences in a scale factor (:func:`_derivatives`): factors 0.5 and
#: 1.5, inside the physical range (``M`` and ``dG/dq`` are affine: any step is exact).
_FACTOR_STEP = 0.5


def _derivatives(nominal, model: pin.Model, q: np.ndarray, j: int, k):
    """``(dM/df, d(dG/dq)/df)`` of parameter ``(j, k)``'s scale factor ``f`` at ``q``.

    Exact central differences (both are affine in ``f``) at ``1 +- _FACTOR_STEP``.
    """
    h = _FACTOR_STEP
    Mp, Gp = _mats(nominal, _scaled(model, {(j, k): 1 + h}), q)
    Mm, Gm = _mats(nominal, _scaled(model, {(j, k): 1 - h}), q)
    return (Mp - Mm) / (2 * h), (Gp - Gm) / (2 * h)


def _mats(nominal, model: pin.Model, q: np.ndarray):
    """``M(q)`` and ``dG/dq`` of the law's plant ``nominal`` on the tree ``model``.

    ``model`` is its Pinocchio tree or a scaled copy (``Plant.with_model``); on a closed
    chain ``S`` does not depend on the inertias, so ``M_r = S^T M S`` and ``G_r = S^T g`` stay
    affine in each factor. (Pinocchio's ``crba`` binding returns ``M`` already symmetric.)
    """
    plant = nominal if model is nominal.model else nominal.with_model(model)
    Gq = plant.gravity_jacobian(q)
    return plant.M(q, check=False), Gq


def _fl_parts(law):
    lm = law.linear_model()
    if not isinstance(lm, FLLinearModel):
        raise TypeError(f"law {law.name!r} has no feedback-linearizing linear model "
                        f"(linear_model() gave {type(lm).__name__}); the parametric loop is "
                        f"that of rrr_pin.control.laws.TrackingController (fl, hinf)")
    return lm


def _closed_loop(lam, K, Mhat, Ghat_q, M, G_q) -> np.ndarray:
    """State matrix of ``M qdd + G_q q = Mhat taubar + Ghat_q q`` with the FL law's ``taubar``."""
    n = Mhat.shape[0]
    AK, BK, CK, DK = K
    nk = AK.shape[0]
    # taubar = -lam^2 q - 2 lam qd + lam^2 (CK xK - DK q); a per-joint lam is diag(lam) on
    # the left (row j scaled by lam_j)
    lam = lam if np.ndim(lam) == 0 else np.asarray(lam, dtype=float)[:, None]
    Tq, Tv, Tx = -lam * lam * (np.eye(n) + DK), -2 * lam * np.eye(n), lam * lam * CK
    Minv = np.linalg.inv(M)
    acc_q = Minv @ (Mhat @ Tq + Ghat_q - G_q)
    Z = np.zeros((n, n))
    return np.block([[Z, np.eye(n), np.zeros((n, nk))],
                     [acc_q, Minv @ Mhat @ Tv, Minv @ Mhat @ Tx],
                     [-BK, np.zeros((nk, n)), AK]])


def parametric_loop(law, q, tol: float = 0.2) -> ParametricLoop:
    r"""Build the LFT of the feedback-linearized loop at ``q`` with real inertial errors.

    The law uses its nominal ``Mhat, Ghat``; the arm has ``M = Mhat + sum delta_i M_i`` and
    ``G_q = Ghat_q + sum delta_i G_i`` (``M`` and ``dG/dq`` are affine in each link's mass and
    principal moments of inertia, so ``M_i, G_i`` are exact central differences of Pinocchio's
    ``crba`` and ``computeGeneralizedGravityDerivatives`` at ``+-tol``). At regulation
    (``qd = 0``):

    .. math:: \hat M \ddot q = \hat M \bar\tau - \sum_i \delta_i (M_i \ddot q + G_i q),
              \quad [M_i\; G_i] = L_i R_i

    (rank-revealing SVD), so ``z_i = R_i [qdd; q]``, ``w_i = delta_i z_i``.

    On a closed chain (``law.nominal`` a :class:`~rrr_pin.model.closed_chain.ClosedChain`) the
    parameters are those of every body of its tree, and ``M, G`` are the reduced ``M_r`` and
    ``G_r`` in the actuated coordinates (``S`` does not depend on the inertias, so they stay
    affine in each factor; ``dG_r/dq_a`` is a central difference).

    Parameters
    ----------
    law : TrackingController
        ``fl`` or ``hinf`` (its nominal model, ``lam`` and ``K``).
    q : array-like, shape (n,)
        Frozen configuration [rad].
    tol : float
        Relative tolerance that ``|delta| = 1`` stands for (paper: 0.2).

    Returns
    -------
    ParametricLoop
    """
    lm = _fl_parts(law)
    nominal = law.nominal
    model = nominal.model
    n = nominal.nq
    q0 = check_vector("q", q, n)
    tol = check_positive("tol", tol)
    Mhat, Ghat = _mats(nominal, model, q0)
    Mhat_inv = np.linalg.inv(Mhat)
    Ls, Rs, names, dropped, blocks = [], [], [], [], []
    scale = max(np.abs(Mhat).max(), 1e-12)
    # central-difference derivatives (error ~1e-9 relative): a rank cut above it
    cut = 1e-10 * scale if nominal.exact_derivatives else \
        1e-7 * max(scale, np.abs(Ghat).max())
    for name, j, k in _parameters(model):
        dM, dG = _derivatives(nominal, model, q0, j, k)
        E = tol * np.hstack([dM, dG])
        U, s, Vh = np.linalg.svd(E)
        r = int(np.sum(s > cut))
        if r == 0:
            dropped.append(name)
            continue
        Ls.append(U[:, :r])
        Rs.append(s[:r, None] * Vh[:r])
        names.append(name)
        blocks.append(("real", r))
    L, R = np.hstack(Ls), np.vstack(Rs)
    Ra, Rb = R[:, :n], R[:, n:]
    lam, K = lm.lam, lm.K
    A = _closed_loop(lam, K, Mhat, Ghat, Mhat, Ghat)
    nk = K[0].shape[0]
    Bw = np.vstack([np.zeros((n, L.shape[1])), -Mhat_inv @ L, np.zeros((nk, L.shape[1]))])
    acc = A[n:2 * n]  # qdd as a function of the state, nominal
    Cz = Ra @ acc + Rb @ np.hstack([np.eye(n), np.zeros((n, n + nk))])
    Dz = Ra @ (-Mhat_inv @ L)
    return ParametricLoop(control.ss(A, Bw, Cz, Dz), blocks, names, dropped, tol, q0)


def parametric_margin(law, q, tol: float = 0.2, omega=None, seed: int = 0):
    """Robust stability margin of :func:`parametric_loop`, in units of ``tol``.

    A margin of 2.3 means the loop stays stable for every combination of parameter errors
    up to ``2.3 tol`` (for ``tol = 0.2``: 46 %) at this configuration.

    Returns
    -------
    (ParametricLoop, rrr_pin.robust.mu.RobstabResult)
    """
    loop = parametric_loop(law, q, tol)
    return loop, robstab(loop.M, loop.blocks, omega, seed=seed)


def sampled_margin(law, loop: ParametricLoop, samples: int = 200, seed: int = 0,
                   hi: float = 20.0, rtol: float = 1e-4) -> tuple[float, np.ndarray]:
    """Smallest scaling of sampled parameter directions that makes the frozen loop unstable.

    Independent of the LFT: each direction (the vertices of the box if ``2^k <= samples``,
    else random vertices) scales the link parameters of a copy of the Pinocchio model, and
    the closed loop ``M qdd + G_q q = Mhat taubar + Ghat_q q`` is rebuilt from ``crba`` and
    the gravity derivatives; the scaling is bisected to the first eigenvalue with real part
    ``>= 0``. Where a factor reaches 0 or below (``a tol >= 1``), which no Pinocchio model
    can hold, ``M`` and ``G_q`` are their affine extension in the factors (the LFT's too).

    Returns
    -------
    alpha : float
        The smallest destabilizing scaling found [units of ``tol``] (``inf`` if none up to
        ``hi``); the true margin is at most ``alpha``.
    direction : ndarray, shape (k,)
        Its direction (``+-1`` per parameter of ``loop.names``).
    """
    lm = _fl_parts(law)
    model = law.nominal.model
    Mhat, Ghat = _mats(law.nominal, model, loop.q)
    index = {name: (j, k) for name, j, k in _parameters(model)}
    keys = [index[name] for name in loop.names]
    k = len(keys)
    rng = np.random.default_rng(seed)
    if 2 ** k <= samples:
        dirs = np.array(np.meshgrid(*[[-1.0, 1.0]] * k)).reshape(k, -1).T
    else:
        dirs = rng.choice((-1.0, 1.0), size=(samples, k))

    slopes = {}  # the affine extension, for factors <= 0 (no Pinocchio model has them)

    def mats(f):
        if all(v > 0 for v in f.values()):
            return _mats(law.nominal, _scaled(model, f), loop.q)
        if not slopes:
            slopes.update({key: _derivatives(law.nominal, model, loop.q, *key)
                           for key in keys})
        M, Gq = Mhat.copy(), Ghat.copy()
        for key, v in f.items():
            M += (v - 1.0) * slopes[key][0]
            Gq += (v - 1.0) * slopes[key][1]
        return M, Gq

    def stable(d, a):
        f = {key: 1.0 + loop.tol * a * di for key, di in zip(keys, d, strict=True)}
        try:
            M, Gq = mats(f)
            A = _closed_loop(lm.lam, lm.K, Mhat, Ghat, M, Gq)
        except np.linalg.LinAlgError:  # M singular: the loop is not well posed
            return False
        return bool(np.max(np.linalg.eigvals(A).real) < 0)

    best, dbest = np.inf, None
    for d in dirs:
        top = min(best, hi)
        if stable(d, top):
            continue
        lo, up = 0.0, top
        while up - lo > rtol * up:
            mid = 0.5 * (lo + up)
            lo, up = (mid, up) if stable(d, mid) else (lo, mid)
        best, dbest = up, d
    return best, dbest

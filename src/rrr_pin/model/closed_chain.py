r"""Closed-chain (parallel) mechanisms: loop closure, reduced dynamics in actuated coordinates.

A :class:`ClosedChain` is a Pinocchio tree (all joints, actuated and passive) with loop-closure
constraints, read from MJCF (:mod:`rrr_pin.model.mechanisms` writes the built-ins). Let
``phi(q) = 0`` be the loop closure (the world-frame gap between the two anchor points of each
``<connect>``, its independent rows only) and ``J = d phi / dq = [J_a  J_p]`` its Jacobian,
split into actuated and passive columns. Then ``qd = S qd_a`` and the equation of motion
projected on the actuated coordinates is eq. (1) of the paper in ``q_a``:

.. math::

    S = \begin{bmatrix} I \\ -J_p^{-1} J_a \end{bmatrix}, \quad
    M_r = S^T M S, \quad
    V_r + G_r = S^T \mathrm{rnea}(q, S \dot q_a, s_0), \quad
    s_0 = \begin{bmatrix} 0 \\ -J_p^{-1} \gamma \end{bmatrix},

with ``gamma = Jdot qd`` the constraint's drift term (the classical acceleration of the anchor
gap at ``qdd = 0``), so that ``M_r qdd_a + V_r + G_r = tau`` (``S^T J^T = 0`` removes the
constraint forces). The passive coordinates come from the actuated ones by Newton on
``phi`` seeded from the previous solution (:meth:`ClosedChain.close`). A configuration where
``J_p`` is singular (type-II, or parallel, singularity) is refused by name, with the
condition number (:class:`SingularConfiguration`, above :data:`COND_LIMIT`).

The full constrained dynamics, the plant's, is Pinocchio's ``constraintDynamics``
(:meth:`ClosedChain.constrained_acceleration`).

Pinocchio 4.1.0 traps, each pinned by a test in ``tests/test_closed_chain.py``: a
``RigidConstraintData`` reused after ``lcaba`` corrupts a later ``constraintDynamics`` (fresh
data here, and no ``lcaba``); the MJCF parser keeps only the first top-level body (the built-ins
wrap everything in one jointless ``base``); ``buildModelsFromMJCF(..., constraints=True)``
raises TypeError (``buildModelAndLegacyConstraintsFromMJCF`` is used); a ``CONTACT_3D`` on a
planar loop has an identically zero row, so the proximal ``mu`` sets the accuracy
(:data:`PROXIMAL_MU`).

References
----------
.. [1] J. Carpentier, R. Budhiraja, N. Mansard, "Proximal and sparse resolution of constrained
   dynamic equations", RSS 2021 (Pinocchio's ``constraintDynamics``).
.. [2] C. Gosselin, J. Angeles, "Singularity analysis of closed-loop kinematic chains",
   IEEE T-RA 6(3), 1990 (type-I and type-II singularities).
"""

from __future__ import annotations

import hashlib
import math
import os
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import pinocchio as pin

from .mechanisms import (
    MECHANISMS,
    MechanismError,
    is_mechanism_params,
    mechanism_of,
    mjcf_from_params,
)
from .mjcf_checks import check_home_closes, check_mjcf_tree
from .plant import Plant, Settler, TreeDescription, UncertaintySet, central_jacobian

__all__ = ["ClosedChain", "load_closed_chain", "is_closed_chain_source", "SingularConfiguration",
           "LoopClosureError", "ConstraintDrift", "ChainSettler", "check_chain_reference",
           "COND_LIMIT", "CLOSURE_TOL", "PROXIMAL_MU", "DRIFT_BOUND"]

#: Largest condition number of ``J_p`` accepted; above it the configuration is refused as
#: type-II singular (``S`` and the FL torque scale with ``J_p^-1``). For the built-in 5-bar,
#: ``cond(J_p)`` passes 1e4 about 1e-9 rad from its stretched singularity (27 at 1e-3 rad).
COND_LIMIT = 1e4

#: Loop-closure residual [m] at which Newton stops (:meth:`ClosedChain.close`).
CLOSURE_TOL = 1e-12

#: Proximal parameter of ``constraintDynamics``. With the identically zero row of a planar
#: ``CONTACT_3D``, Pinocchio 4.1.0 reaches 6e-11 rad/s^2 at ``mu = 1e-4`` but only 5e-5 at
#: ``mu = 1e-10`` (a test pins both).
PROXIMAL_MU = 1e-4

#: Largest loop gap [m] one RK4 step may leave before its projection; above it the run stops.
DRIFT_BOUND = 1e-6

#: Relative central-difference step of the linearizations (:meth:`ClosedChain.linearization`):
#: each call closes the loop to :data:`CLOSURE_TOL`, so a smaller step would amplify that error.
LINEARIZATION_STEP = 1e-5


class SingularConfiguration(ValueError):
    """A type-II singular configuration (``J_p`` singular): the message has ``cond(J_p)``.

    Attributes
    ----------
    cond : float
        Condition number of ``J_p`` there.
    """

    def __init__(self, message: str, cond: float):
        super().__init__(message)
        self.cond = cond

    def __reduce__(self):
        # A run's outcome travels back from a worker process: rebuild with both arguments.
        return (type(self), (str(self), self.cond))


class LoopClosureError(ValueError):
    """The loop closure has no solution near the seed (the actuated angles cannot close it)."""


class ConstraintDrift(RuntimeError):
    """An RK4 step left a loop gap above :data:`DRIFT_BOUND` (time and gap in the message)."""


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@dataclass
class ClosedChain(Plant):
    """A parallel mechanism: Pinocchio tree, loop closures, actuated and passive coordinates.

    A :class:`~rrr_pin.model.plant.Plant` in the actuated coordinates ``q_a`` (``nq`` of
    them): the model face is :meth:`terms` (the reduced ``M_r`` and ``V_r + G_r``),
    :meth:`M`, :meth:`V`, :meth:`G`, :meth:`forward_dynamics`, :meth:`inverse_dynamics`; the
    passive coordinates are solved by :meth:`close`, seeded from the last solution (so the
    calls are not thread-safe; :meth:`reset` re-seeds it). The engine face runs the full tree:
    :meth:`start` closes the loop, :meth:`acceleration` is Pinocchio's
    ``constraintDynamics``, :meth:`settler` projects every step back onto the loop closure
    and stops a run at a type-II singularity or a drift above :data:`DRIFT_BOUND`.

    Attributes
    ----------
    model : pinocchio.Model
        The tree with every joint; ``model.nq == model.nv`` (revolute and prismatic joints).
    data : pinocchio.Data
        Workspace of ``model``.
    constraints : list of pinocchio.RigidConstraintModel
        The loop closures as Pinocchio reads them (``CONTACT_3D``), for ``constraintDynamics``.
    name, source, mjcf : str
        Model name, where it came from, its MJCF text.
    actuated, passive : tuple of int
        Velocity indices of the actuated and passive coordinates (``model.nv`` in all).
    dof_names : tuple of str
        Name of every coordinate (the MJCF joint names), shape (model.nv,).
    rows : ndarray of int
        Independent rows of the stacked world-frame anchor gaps (3 per closure), as many as
        passive coordinates.
    home : ndarray, shape (model.nq,)
        A closed configuration [rad, m] (the MJCF ``home`` keyframe).
    params : parameter set or None
        The mechanism's parameter set (:mod:`rrr_pin.model.mechanisms`); None for an MJCF file
        loaded as it is.
    """

    model: pin.Model = field(repr=False)
    data: pin.Data = field(repr=False)
    constraints: list = field(repr=False)
    name: str
    source: str
    mjcf: str = field(repr=False)
    actuated: tuple
    passive: tuple
    dof_names: tuple
    rows: np.ndarray = field(repr=False)
    home: np.ndarray = field(repr=False)
    params: object = None

    capabilities = frozenset()
    exact_derivatives = False
    failures = (SingularConfiguration, LoopClosureError, ConstraintDrift, np.linalg.LinAlgError)

    def __post_init__(self) -> None:
        self._act = np.array(self.actuated, dtype=int)
        self._pas = np.array(self.passive, dtype=int)
        self._frames = []
        for k, c in enumerate(self.constraints):
            ids = []
            for side, joint, place in (("a", c.joint1_id, c.joint1_placement),
                                       ("b", c.joint2_id, c.joint2_placement)):
                name = f"_loop{k}{side}"
                if not self.model.existFrame(name):
                    self.model.addFrame(pin.Frame(name, joint, 0, place, pin.OP_FRAME))
                ids.append(self.model.getFrameId(name))
            self._frames.append(tuple(ids))
        self.data = self.model.createData()
        self._cdatas = [c.createData() for c in self.constraints]
        pin.initConstraintDynamics(self.model, self.data, self.constraints, self._cdatas)
        self._prox = pin.ProximalSettings(1e-14, PROXIMAL_MU, 200)
        self._q = self.home.copy()
        self.actuated_index = self._act
        self.loop_closures = tuple(self.constraint_names)

    def describe_kind(self) -> str:
        """Return ``"the closed chain"``."""
        return "the closed chain"

    def __reduce__(self):
        """Pickle as the MJCF text and gravity it is built from (for worker processes).

        Pinocchio's ``RigidConstraintModel`` does not pickle; the copy is rebuilt by the same
        loader from the same text, so it computes the same numbers. The Newton seed of
        :meth:`close` is not carried: the copy starts from ``home``.
        """
        return (_from_mjcf, (self.mjcf, self.name, self.source, self.params, self.gravity))

    # --- the Robot face in actuated coordinates ----------------------------------------------
    @property
    def nq(self) -> int:
        """Number of actuated coordinates (the mechanism's mobility)."""
        return len(self.actuated)

    @property
    def joint_names(self) -> list[str]:
        """Names of the actuated joints, shape (nq,)."""
        return [self.dof_names[i] for i in self.actuated]

    @property
    def passive_names(self) -> list[str]:
        """Names of the passive coordinates."""
        return [self.dof_names[i] for i in self.passive]

    @property
    def constraint_names(self) -> list[str]:
        """Names of the loop closures (the MJCF ``<connect>`` names)."""
        return [c.name for c in self.constraints]

    @property
    def gravity(self) -> float:
        """Gravity magnitude [m/s^2] (along ``-z``)."""
        return float(-self.model.gravity.linear[2])

    def neutral(self) -> np.ndarray:
        """Actuated coordinates of the ``home`` configuration, shape (nq,) [rad]."""
        return self.home[self._act].copy()

    def check_state(self, name: str, x) -> np.ndarray:
        """Return ``x`` as a finite float64 array of shape ``(nq,)``, or raise ValueError."""
        x = np.asarray(x, dtype=float)
        if x.shape != (self.nq,):
            raise ValueError(f"Expected {name} of shape ({self.nq},), got {x.shape}")
        if not np.isfinite(x).all():
            raise ValueError(f"{name} must be finite, got {x}")
        return x

    # --- loop closure ------------------------------------------------------------------------
    def residual(self, q, *, kinematics: bool = True) -> np.ndarray:
        """Loop-closure gap ``phi(q)`` [m], its independent rows, shape (len(passive),).

        Runs ``framesForwardKinematics`` (``kinematics=False`` trusts that the frames are
        placed at ``q``).
        """
        if kinematics:
            pin.framesForwardKinematics(self.model, self.data, q)
        oMf = self.data.oMf
        gap = np.concatenate([oMf[a].translation - oMf[b].translation for a, b in self._frames])
        return gap[self.rows]

    def jacobian(self, q, *, kinematics: bool = True) -> np.ndarray:
        """Loop-closure Jacobian ``J = d phi / dq``, shape (len(passive), model.nv) [m/rad].

        ``kinematics=False`` trusts that ``computeJointJacobians`` ran at ``q``.
        """
        if kinematics:
            pin.computeJointJacobians(self.model, self.data, q)
            pin.updateFramePlacements(self.model, self.data)
        rows = []
        for a, b in self._frames:
            ja = pin.getFrameJacobian(self.model, self.data, a, pin.LOCAL_WORLD_ALIGNED)[:3]
            jb = pin.getFrameJacobian(self.model, self.data, b, pin.LOCAL_WORLD_ALIGNED)[:3]
            rows.append(ja - jb)
        return np.vstack(rows)[self.rows]

    def passive_jacobian_cond(self, q) -> float:
        """Condition number of ``J_p`` at the full configuration ``q`` (inf if singular)."""
        return float(np.linalg.cond(self.jacobian(q)[:, self._pas]))

    def _refuse_singular(self, q, cond: float) -> None:
        raise SingularConfiguration(
            f"{self.name}: type-II (parallel) singularity at q_a = "
            f"{np.array2string(q[self._act], precision=6)} rad: cond(J_p) = {cond:.3g} > "
            f"{COND_LIMIT:g}; the actuated joints cannot determine the passive ones there",
            cond)

    def close(self, qa, seed=None, *, tol: float = CLOSURE_TOL, max_iter: int = 30,
              remember: bool | None = None) -> np.ndarray:
        """Full configuration ``q`` [rad, m] with actuated part ``qa`` that closes the loop.

        Newton on the passive coordinates, ``q_p <- q_p - J_p^-1 phi``, from ``seed`` (a full
        configuration; default: the last solution remembered). The solution is remembered as
        the next default seed when ``remember`` (default: when no ``seed`` is given, the model
        face's calls; the engine face's calls from an explicit seed leave the model's seed as
        it is, so one object may serve as a law's model and as the plant).

        Parameters
        ----------
        qa : array-like, shape (nq,)
            Actuated coordinates [rad].
        seed : array-like, shape (model.nq,), optional
            Starting configuration.
        tol : float
            Largest residual accepted [m].
        max_iter : int
            Newton iterations before :class:`LoopClosureError`.

        Raises
        ------
        SingularConfiguration
            ``cond(J_p) > COND_LIMIT`` at the solution or on the way.
        LoopClosureError
            No convergence (the loop cannot close at ``qa``, or the seed is too far).
        """
        q = (self._q if seed is None else np.asarray(seed, dtype=float)).copy()
        q[self._act] = qa
        pas = self._pas
        for _ in range(max_iter):
            J = self.jacobian(q)  # also places the frames
            phi = self.residual(q, kinematics=False)
            if float(np.max(np.abs(phi))) <= tol:
                cond = float(np.linalg.cond(J[:, pas]))
                if not cond <= COND_LIMIT:
                    self._refuse_singular(q, cond)
                if remember or (remember is None and seed is None):
                    self._q = q
                self._Jq = (q.copy(), J)
                return q.copy()
            try:
                q[pas] -= np.linalg.solve(J[:, pas], phi)
            except np.linalg.LinAlgError:
                self._refuse_singular(q, math.inf)
        raise LoopClosureError(
            f"{self.name}: the loop does not close at q_a = "
            f"{np.array2string(np.asarray(qa, dtype=float), precision=6)} rad (Newton from the "
            f"last configuration left a gap of {float(np.max(np.abs(self.residual(q)))):.3g} m "
            f"after {max_iter} iterations): out of the workspace")

    def reduced(self, qa, qd_a) -> tuple[np.ndarray, np.ndarray]:
        """``(M_r, V_r + G_r)`` at actuated ``(qa, qd_a)``, unchecked: the law's fast path.

        Closes the loop from the last solution (:meth:`close`), then as
        :meth:`reduced_terms`. Shapes (nq, nq) [kg m^2] and (nq,) [N m].
        """
        q = self.close(qa)
        J = self._Jq[1]  # cond(J_p) checked by close
        Jp = J[:, self._pas]
        Sm = np.zeros((self.model.nv, self.nq))
        Sm[self._act, np.arange(self.nq)] = 1.0
        Sm[self._pas] = -np.linalg.solve(Jp, J[:, self._act])
        qd = Sm @ qd_a
        s0 = np.zeros(self.model.nv)
        s0[self._pas] = -np.linalg.solve(Jp, self.gamma(q, qd))
        M = pin.crba(self.model, self.data, q)
        h = pin.rnea(self.model, self.data, q, qd, s0)
        return Sm.T @ M @ Sm, Sm.T @ h

    def velocity(self, q, qd_a) -> np.ndarray:
        """Full velocity ``S qd_a`` [rad/s, m/s], shape (model.nv,), at a closed ``q``."""
        Sm, _ = self.S(q)
        return Sm @ np.asarray(qd_a, dtype=float)

    def S(self, q) -> tuple[np.ndarray, float]:
        """``S = [I; -J_p^-1 J_a]`` (rows in velocity order), shape (model.nv, nq), and cond(J_p).

        Refuses a type-II singular ``q`` (:class:`SingularConfiguration`).
        """
        J = self.jacobian(q)
        return self._S_of(q, J)

    def _S_of(self, q, J):
        Jp = J[:, self._pas]
        cond = float(np.linalg.cond(Jp))
        if not cond <= COND_LIMIT:
            self._refuse_singular(q, cond)
        Sm = np.zeros((self.model.nv, self.nq))
        Sm[self._act, np.arange(self.nq)] = 1.0
        Sm[self._pas] = -np.linalg.solve(Jp, J[:, self._act])
        return Sm, cond

    def gamma(self, q, qd) -> np.ndarray:
        """Drift term ``gamma = Jdot qd`` [m/s^2], shape (len(passive),)."""
        pin.forwardKinematics(self.model, self.data, q, qd, np.zeros(self.model.nv))
        acc = []
        for a, b in self._frames:
            aa = pin.getFrameClassicalAcceleration(self.model, self.data, a,
                                                   pin.LOCAL_WORLD_ALIGNED).linear
            ab = pin.getFrameClassicalAcceleration(self.model, self.data, b,
                                                   pin.LOCAL_WORLD_ALIGNED).linear
            acc.append(aa - ab)
        return np.concatenate(acc)[self.rows]

    def reduced_terms(self, q, qd) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(M_r, V_r + G_r, S)`` at a closed full state ``(q, qd)`` (module docstring).

        Parameters
        ----------
        q : ndarray, shape (model.nq,)
            Closed configuration [rad, m].
        qd : ndarray, shape (model.nv,)
            Consistent velocity (``J qd = 0``) [rad/s, m/s].

        Returns
        -------
        M_r : ndarray, shape (nq, nq)
            Reduced inertia [kg m^2].
        h_r : ndarray, shape (nq,)
            ``V_r + G_r`` [N m].
        S : ndarray, shape (model.nv, nq)
        """
        J = self.jacobian(q)
        Sm, _ = self._S_of(q, J)
        s0 = np.zeros(self.model.nv)
        s0[self._pas] = -np.linalg.solve(J[:, self._pas], self.gamma(q, qd))
        M = pin.crba(self.model, self.data, q)
        h = pin.rnea(self.model, self.data, q, qd, s0)
        return Sm.T @ M @ Sm, Sm.T @ h, Sm

    def state(self, qa, qd_a) -> tuple[np.ndarray, np.ndarray]:
        """Full ``(q, qd)`` of actuated ``(qa, qd_a)``: :meth:`close`, then ``qd = S qd_a``."""
        q = self.close(qa)
        return q, self.velocity(q, qd_a)

    def M(self, qa, *, check: bool = True) -> np.ndarray:
        """Reduced inertia ``M_r = S^T M S`` at actuated ``qa`` [rad], shape (nq, nq)."""
        if check:
            qa = self.check_state("q", qa)
        q = self.close(qa)
        Sm, _ = self.S(q)
        return Sm.T @ pin.crba(self.model, self.data, q) @ Sm

    def G(self, qa, *, check: bool = True) -> np.ndarray:
        """Reduced gravity ``G_r = S^T g(q)`` [N m], shape (nq,)."""
        if check:
            qa = self.check_state("q", qa)
        q = self.close(qa)
        Sm, _ = self.S(q)
        return Sm.T @ pin.computeGeneralizedGravity(self.model, self.data, q)

    def V(self, qa, qd_a, *, check: bool = True) -> np.ndarray:
        """Reduced centrifugal and Coriolis torques ``V_r`` [N m], shape (nq,)."""
        if check:
            qa, qd_a = self.check_state("q", qa), self.check_state("qd", qd_a)
        q, qd = self.state(qa, qd_a)
        _, h, Sm = self.reduced_terms(q, qd)
        return h - Sm.T @ pin.computeGeneralizedGravity(self.model, self.data, q)

    def inverse_dynamics(self, qa, qd_a, qdd_a, *, check: bool = True) -> np.ndarray:
        """Actuator torques ``M_r qdd_a + V_r + G_r`` [N m], shape (nq,)."""
        if check:
            qa, qd_a = self.check_state("q", qa), self.check_state("qd", qd_a)
            qdd_a = self.check_state("qdd", qdd_a)
        q, qd = self.state(qa, qd_a)
        Mr, h, _ = self.reduced_terms(q, qd)
        return Mr @ qdd_a + h

    def forward_dynamics(self, qa, qd_a, tau, *, check: bool = True) -> np.ndarray:
        """Actuated accelerations ``M_r^-1 (tau - V_r - G_r)`` [rad/s^2], shape (nq,)."""
        if check:
            qa, qd_a = self.check_state("q", qa), self.check_state("qd", qd_a)
            tau = self.check_state("tau", tau)
        q, qd = self.state(qa, qd_a)
        Mr, h, _ = self.reduced_terms(q, qd)
        return np.linalg.solve(Mr, tau - h)

    # --- the plant protocol (model/plant.py) -------------------------------------------------
    def terms(self, q, qd) -> tuple[np.ndarray, np.ndarray]:
        """``(M_r, V_r + G_r)`` at actuated ``(q, qd)``, unchecked: :meth:`reduced`."""
        return self.reduced(q, qd)

    def reset(self, q=None) -> None:
        """Re-seed the loop closure on the home branch, at the actuated ``q`` (default home)."""
        if q is None:
            self._q = self.home.copy()
        else:
            self.close(q, seed=self.home, remember=True)

    def linearization(self, q, tau, h: float = LINEARIZATION_STEP):
        """Central differences of :meth:`forward_dynamics` at ``(q, 0, tau)``; ``M_r^-1`` exactly.

        ``h`` is the relative step: each call closes the loop by Newton to
        :data:`CLOSURE_TOL`, so a smaller step would amplify that closure error
        (``1e-12 / h``). The Newton seed is left at ``q``.
        """
        z = np.zeros(self.nq)
        dq = central_jacobian(lambda qa: self.forward_dynamics(qa, z, tau, check=False), q, h)
        dv = central_jacobian(lambda v: self.forward_dynamics(q, v, tau, check=False), z, h)
        self.close(q)  # leave the Newton seed at q
        return dq, dv, np.linalg.inv(self.M(q, check=False))

    def gravity_jacobian(self, q, h: float = LINEARIZATION_STEP) -> np.ndarray:
        """Return ``dG_r/dq_a`` [N m/rad] by central differences (relative step ``h``)."""
        self.close(q)
        Gq = central_jacobian(lambda qa: self.G(qa, check=False), q, h)
        self.close(q)
        return Gq

    def with_model(self, model) -> ClosedChain:
        """Return this mechanism on another tree of the same joints, its Newton seed kept."""
        out = replace(self, model=model, data=model.createData())
        out._q = self._q.copy()
        return out

    def follow(self, Q, where=None) -> None:
        """Close the loop at each actuated configuration of ``Q`` in turn (the Newton seed).

        ``where(k)`` names row ``k`` in a failure's message (:meth:`Plant.follow`).
        """
        for k, qa in enumerate(Q):
            try:
                self.close(qa)
            except (LoopClosureError, SingularConfiguration) as exc:
                if where is None:
                    raise
                raise _located(exc, where(k)) from None

    def start(self, q, qd) -> tuple[np.ndarray, np.ndarray]:
        """Full closed state at actuated ``(q, qd)``: Newton from ``home``, then ``S qd``."""
        x = self.close(q, seed=self.home)
        return x, self.velocity(x, qd)

    def acceleration(self, x, v, tau) -> np.ndarray:
        """``constraintDynamics`` under actuator torques ``tau`` [N m] (:meth:`actuation`)."""
        return self.constrained_acceleration(x, v, self.actuation(tau))

    def measure(self, x, v) -> tuple[np.ndarray, np.ndarray]:
        """Return the actuated ``(q, qd)`` of a full state."""
        act = self._act
        return x[act], v[act]

    def settler(self, t, h: float, x, v) -> ChainSettler:
        """Return a :class:`ChainSettler` for one run.

        On the grid ``t`` [s] with RK4 step ``h`` [s], from the full state ``(x, v)`` of
        :meth:`start`.
        """
        return ChainSettler(self, t, h, x)

    def task_path(self, period: float):
        """Return the mechanism's task path as actuated waypoints ``(t, W, source)``, or None.

        :meth:`rrr_pin.model.mechanisms.base.Mechanism.waypoints` of its parameter set (the
        5-bar's tip circle, the Delta's adept cycle); None for an MJCF file without one.
        """
        return None if self.params is None else mechanism_of(self.params).waypoints(
            self.params, period)

    def source_text(self) -> tuple[str, str]:
        """Return the MJCF text the mechanism was built from and ``".xml"``."""
        return self.mjcf, ".xml"

    def fingerprint(self) -> dict:
        """Return ``{"mjcf_sha256", "gravity"}``."""
        return {"mjcf_sha256": hashlib.sha256(self.mjcf.encode()).hexdigest(),
                "gravity": self.gravity}

    def description(self) -> TreeDescription:
        """Return the tree, its loop closures and the coordinate split (:class:`TreeDescription`).

        Each loop is the two joints of its ``RigidConstraintModel`` and the translations of
        their ``joint1_placement``, ``joint2_placement`` (the anchor points); the tolerances are
        this module's (:data:`CLOSURE_TOL`, :data:`COND_LIMIT`, :data:`DRIFT_BOUND`, 30
        Newton iterations as :meth:`close`).
        """
        cons = self.constraints
        return TreeDescription(
            model=self.model, actuated=np.asarray(self.actuated, dtype=int),
            passive=np.asarray(self.passive, dtype=int),
            loop_joints=np.array([[c.joint1_id, c.joint2_id] for c in cons], dtype=int),
            loop_anchors=np.array([[c.joint1_placement.translation,
                                    c.joint2_placement.translation] for c in cons], dtype=float),
            rows=np.asarray(self.rows, dtype=int), home=np.asarray(self.home, dtype=float),
            closure_tol=CLOSURE_TOL, max_iter=30, cond_limit=COND_LIMIT,
            drift_bound=DRIFT_BOUND)

    def configurations(self, Q, seed=None, where=None) -> np.ndarray:
        """Close the loop at each row of ``Q`` in turn (:meth:`Plant.configurations`)."""
        Q = np.asarray(Q, dtype=float)
        out = np.empty((Q.shape[0], self.model.nq))
        last = np.asarray(self.home if seed is None else seed, dtype=float)
        for k, qa in enumerate(Q):
            try:
                last = self.close(qa, seed=last)
            except (LoopClosureError, SingularConfiguration) as exc:
                if where is None:
                    raise
                raise _located(exc, where(k)) from None
            out[k] = last
        return out

    def task_points(self, period: float, samples: int = 401):
        """Return the task path as world points [m], shape (samples, 3), and its label."""
        if self.params is None:
            return None
        kind = mechanism_of(self.params)
        t = np.linspace(0.0, period, samples)
        return (kind.world_points(self.params, kind.task_point(self.params, t, period)),
                kind.path_label)

    def task_position(self, Q) -> np.ndarray:
        """Return the mechanism's task point [m] at each actuated row of ``Q``, shape (N, 3)."""
        kind = mechanism_of(self.params)
        return kind.world_points(self.params, np.array([kind.fk(self.params, q) for q in Q]))

    def check_path(self, t, R) -> dict:
        """:func:`check_chain_reference`, recorded as ``reference_max_cond_Jp`` and its time."""
        c = check_chain_reference(self, t, R)
        return {"reference_max_cond_Jp": c["max_cond_Jp"], "reference_max_cond_at_s": c["at_s"]}

    def perturbed(self, rng: np.random.Generator, tolerances, *, name: str | None = None
                  ) -> tuple[ClosedChain, dict]:
        """Draw an uncertain mechanism with ``tolerances.mechanism`` (:meth:`Plant.perturbed`).

        The mechanism's parameter set is perturbed (a built-in's, or your own
        :class:`~rrr_pin.model.mechanisms.FiveBarParams` / ``DeltaParams``); an MJCF file
        without one is refused. Returns the closed chain and ``{"params", "factors",
        "joint_dynamics"}`` (the parameter set drawn, each field's factor, and the chain's
        armature, damping and friction as :meth:`Plant.joint_dynamics` records them).
        """
        if not isinstance(tolerances, UncertaintySet):
            raise TypeError(f"tolerances must be an uncertainty set (e.g. "
                            f"rrr_pin.Tolerances()), got {type(tolerances).__name__}")
        if self.params is None:
            raise ValueError(f"{self.name}: an MJCF file without a parameter set cannot be "
                             f"perturbed (its uncertain plants perturb a FiveBarParams or "
                             f"DeltaParams); load a built-in or your own parameter set")
        params, factors = tolerances.mechanism(self.params, rng)
        record = {"params": asdict(params), "factors": factors}
        if name:
            params = replace(params, name=name)
        plant = load_closed_chain(params, gravity=self.gravity)
        return plant, {**record, "joint_dynamics": plant.joint_dynamics()}

    # --- the plant ---------------------------------------------------------------------------
    def actuation(self, tau) -> np.ndarray:
        """Generalized force of actuator torques ``tau`` [N m], shape (model.nv,).

        ``tau`` on the actuated coordinates, zero on the passive ones.
        """
        out = np.zeros(self.model.nv)
        out[self._act] = tau
        return out

    def constrained_acceleration(self, q, qd, tau_full) -> np.ndarray:
        """Pinocchio's ``constraintDynamics``: full ``qdd`` [rad/s^2, m/s^2], shape (model.nv,).

        The loop forces are in ``self.data.lambda_c`` after the call.
        """
        return pin.constraintDynamics(self.model, self.data, q, qd, tau_full, self.constraints,
                                      self._cdatas, self._prox)

    def energy(self, q, qd) -> float:
        """Kinetic plus potential energy [J] of the full state (Pinocchio)."""
        return float(pin.computeKineticEnergy(self.model, self.data, q, qd)
                     + pin.computePotentialEnergy(self.model, self.data, q))

    def project(self, q, qd) -> tuple[np.ndarray, np.ndarray]:
        """Project a full state onto the constraint manifold.

        Newton on the passive coordinates from ``q``, then ``qd = S qd_a`` (the actuated parts
        are kept).
        """
        q = self.close(q[self._act], seed=q)
        J = self._Jq[1]
        qd = qd.copy()
        qd[self._pas] = -np.linalg.solve(J[:, self._pas], J[:, self._act] @ qd[self._act])
        return q, qd


class ChainSettler(Settler):
    """After every RK4 step of a closed chain: drift check, projection, type-II checks.

    The gap the step left is checked against :data:`DRIFT_BOUND` (:class:`ConstraintDrift`
    above it) and recorded; the state is projected (:meth:`ClosedChain.project`); a sign
    change of ``det J_p`` (a crossing of the type-II singularity between two steps) or a
    refused projection stops the run with :class:`SingularConfiguration` naming the time.
    Records ``drift_m``, ``drift_velocity_m_s`` (largest ``|J qd|`` before projection),
    ``drift_bound_m`` and the final full state (:meth:`info`).
    """

    def __init__(self, chain: ClosedChain, t, h: float, x0):
        self.chain, self.t, self.h = chain, t, h
        self.drift = self.drift_v = 0.0
        self._pas = list(chain.passive)
        # det J_p where the run starts: the branch to stay on
        self._sign = float(np.linalg.det(chain.jacobian(x0)[:, self._pas]))

    def settle(self, k: int, x, v):
        """Project a step of control period ``k`` (ending at ``t[k + 1]``) onto the loop."""
        chain, t, pas = self.chain, self.t, self._pas
        gap = float(np.max(np.abs(chain.residual(x))))
        if not gap <= DRIFT_BOUND:
            raise ConstraintDrift(
                f"{chain.name}: one RK4 step of {self.h:g} s left a loop gap of {gap:.3g} m at "
                f"t = {t[k]:.6g} s (bound {DRIFT_BOUND:g} m): take a smaller dt")
        self.drift = max(self.drift, gap)
        try:
            x, v_new = chain.project(x, v)
        except SingularConfiguration as exc:
            raise SingularConfiguration(f"plant at t = {t[k + 1]:.6g} s: {exc}",
                                        exc.cond) from None
        # J at the projected x (the projection's own), applied to the unprojected v.
        J = chain.jacobian(x, kinematics=False)
        self.drift_v = max(self.drift_v, float(np.max(np.abs(J @ v))))
        det = float(np.linalg.det(J[:, pas]))
        if det * self._sign < 0.0:
            raise SingularConfiguration(
                f"plant at t = {t[k + 1]:.6g} s: crossed a type-II (parallel) singularity in "
                f"the last step (det J_p changed sign; cond(J_p) = "
                f"{np.linalg.cond(J[:, pas]):.3g} after it): the actuated angles no longer "
                f"determine the mechanism's branch", math.inf)
        self._sign = det
        return x, v_new

    def info(self, x, v) -> dict:
        """``drift_m``, ``drift_velocity_m_s``, ``drift_bound_m``, ``final_q``, ``final_qd``."""
        return {"drift_m": self.drift, "drift_velocity_m_s": self.drift_v,
                "drift_bound_m": DRIFT_BOUND, "final_q": x.tolist(), "final_qd": v.tolist()}


def _located(exc, where: str):
    """``exc`` (a loop-closure failure) with ``where`` in front of its message."""
    if isinstance(exc, SingularConfiguration):
        return SingularConfiguration(f"{where}: {exc}", exc.cond)
    return LoopClosureError(f"{where}: {exc}")


def check_chain_reference(chain, t, R) -> dict:
    """Refuse a reference that leaves the workspace or crosses a type-II singularity.

    Parameters
    ----------
    chain : ClosedChain
        The mechanism (its loop closure and ``J_p``).
    t : ndarray, shape (N,)
        Sample times [s].
    R : ndarray, shape (N, chain.nq)
        Actuated reference [rad] at ``t``.

    Returns
    -------
    dict
        ``{"max_cond_Jp": float, "at_s": float}``: the worst conditioning met.

    Raises
    ------
    SingularConfiguration
        ``cond(J_p) > COND_LIMIT`` at a sample, or ``det J_p`` changes sign between two
        samples (naming the time and the largest condition number there).
    LoopClosureError
        A sample where the loop cannot close (out of the workspace), naming the time.
    """
    q = chain.home.copy()
    pas = list(chain.passive)
    worst, at, sign = 0.0, 0.0, 0.0
    for tk, r in zip(t, R, strict=True):
        try:
            q = chain.close(r, seed=q)
        except SingularConfiguration as exc:
            raise SingularConfiguration(f"reference at t = {tk:.6g} s: {exc}", exc.cond) from None
        except LoopClosureError as exc:
            raise LoopClosureError(f"reference at t = {tk:.6g} s: {exc}") from None
        Jp = chain.jacobian(q)[:, pas]
        cond = float(np.linalg.cond(Jp))
        det = float(np.linalg.det(Jp))
        if cond > worst:
            worst, at = cond, float(tk)
        if sign and det * sign < 0.0:
            raise SingularConfiguration(
                f"reference crosses a type-II (parallel) singularity before t = {tk:.6g} s "
                f"(det J_p changes sign; cond(J_p) = {cond:.3g} there, limit {COND_LIMIT:g})",
                cond)
        sign = math.copysign(1.0, det)
    return {"max_cond_Jp": worst, "at_s": at}


def is_closed_chain_source(source) -> bool:
    """Whether :func:`rrr_pin.load_robot` hands ``source`` to :func:`load_closed_chain`."""
    if is_mechanism_params(source):
        return True
    if isinstance(source, (str, Path)):
        text = str(source)
        return text in MECHANISMS or text.lower().endswith(".xml")
    return False


def _mjcf_of(source) -> tuple[str, str, str, object]:
    if is_mechanism_params(source):
        return mjcf_from_params(source), source.name, "<params>", source
    text = str(source)
    if text in MECHANISMS:
        params = MECHANISMS[text].params()
        return mjcf_from_params(params), text, text, params
    path = Path(text)
    if not path.is_file():
        raise FileNotFoundError(f"MJCF file not found: {path}")
    return path.read_text(encoding="utf-8"), path.stem, str(path), None


def load_closed_chain(source, *, gravity: float = 9.8) -> ClosedChain:
    """Load a parallel mechanism from MJCF.

    Parameters
    ----------
    source : str, path-like or parameter set
        A name of :data:`rrr_pin.model.mechanisms.MECHANISMS` (``"fivebar"``, ``"delta"``), a
        parameter set of one, or an MJCF file with ``<equality><connect>`` loop closures and one
        ``<motor joint=...>`` per actuated joint.
    gravity : float, default 9.8
        Gravity magnitude [m/s^2] along ``-z`` (the paper's value).

    Returns
    -------
    ClosedChain

    Raises
    ------
    MechanismError
        No loop closure, no motor, a motor on an unknown joint, a number of actuators that is
        not the mobility (``nv - rank J``), or ``J_p`` singular at ``home``.
    """
    text, name, label, params = _mjcf_of(source)
    return _from_mjcf(text, name, label, params, gravity)


def _from_mjcf(text: str, name: str, label: str, params, gravity: float) -> ClosedChain:
    """Build a ClosedChain from MJCF text (:func:`load_closed_chain`, and unpickling)."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise MechanismError(f"{label}: not well-formed XML: {exc}") from None
    check_mjcf_tree(root, label)
    joints = [j.get("name") for j in root.find("worldbody").iter("joint")]
    motors = [m.get("joint") for m in root.iter("motor")]
    fd, tmp = tempfile.mkstemp(suffix=".xml")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        model, constraints = pin.buildModelAndLegacyConstraintsFromMJCF(tmp)
    finally:
        os.unlink(tmp)
    constraints = list(constraints)
    for c, connect in zip(constraints, root.iter("connect"), strict=False):
        c.name = connect.get("name") or ""
    if model.nq != model.nv or model.nv != len(joints):
        raise MechanismError(f"{label}: rrr-pin handles hinge and slide joints only "
                             f"(nq = {model.nq}, nv = {model.nv}, {len(joints)} joints)")
    if not constraints:
        raise MechanismError(f"{label}: no loop closure (<equality><connect>): a serial arm is "
                             f"a URDF")
    unknown = [m for m in motors if m not in joints]
    if unknown or not motors:
        raise MechanismError(f"{label}: motors must name joints; got {motors}, joints {joints}")
    model.gravity = pin.Motion(np.array([0.0, 0.0, -gravity]), np.zeros(3))
    home = np.zeros(model.nq)
    for key in root.iter("key"):
        if key.get("name") == "home" and key.get("qpos"):
            home = np.array([float(v) for v in key.get("qpos").split()])
    if params is not None:  # the closed form itself: the keyframe holds it to 12 decimals
        home = np.asarray(mechanism_of(params).home(params), dtype=float)
    actuated = tuple(sorted(joints.index(m) for m in motors))
    passive = tuple(i for i in range(model.nv) if i not in actuated)
    check_home_closes(model, constraints, home, label)
    probe = ClosedChain(model=model, data=model.createData(), constraints=constraints,
                        name=name, source=label, mjcf=text, actuated=actuated, passive=passive,
                        dof_names=tuple(joints), rows=np.arange(3 * len(constraints)),
                        home=home, params=params)
    J = probe.jacobian(home)
    sv = np.linalg.svd(J, compute_uv=False)
    rank = int(np.sum(sv > 1e-9 * sv[0]))
    mobility = model.nv - rank
    if len(actuated) != mobility:
        raise MechanismError(
            f"{label}: {len(actuated)} actuator(s) ({', '.join(motors)}) but the mechanism's "
            f"mobility is {mobility} ({model.nv} coordinates, {rank} independent loop-closure "
            f"equations): each degree of freedom needs exactly one actuator")
    # Independent rows: the largest |pivot| first (QR with column pivoting of J^T).
    import scipy.linalg

    _, _, piv = scipy.linalg.qr(J.T, pivoting=True, mode="economic")
    rows = np.sort(piv[:rank])
    chain = ClosedChain(model=model, data=model.createData(), constraints=constraints,
                        name=name, source=label, mjcf=text, actuated=actuated, passive=passive,
                        dof_names=tuple(joints), rows=rows, home=home, params=params)
    gap = float(np.max(np.abs(chain.residual(home))))
    if not math.isfinite(gap) or gap > CLOSURE_TOL:
        chain.home = chain.close(home[list(actuated)], seed=home)
    cond = chain.passive_jacobian_cond(chain.home)
    if not cond <= COND_LIMIT:
        chain._refuse_singular(chain.home, cond)
    return chain

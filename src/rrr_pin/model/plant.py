r"""The plant protocol: what every layer above ``model/`` may ask of a robot, serial or not.

A **plant** is a mechanism in its *actuated* coordinates ``q`` (``nq`` of them): a fixed-base
serial arm (:class:`rrr_pin.model.dynamics.Robot`, every joint actuated) or a closed chain
(:class:`rrr_pin.model.closed_chain.ClosedChain`, passive joints solved from the loop
closure). Laws, engines, studies, campaigns, reports and the command line take a
:class:`Plant` and never ask which kind it is; what a kind lacks is declared in
:attr:`Plant.capabilities` and refused by name (:meth:`Plant.require`), never sniffed.

Two faces, at the grain their users need:

* **the model face**, for control laws and analysis, in actuated coordinates: eq. (1) of the
  paper, :math:`M(q) \ddot q + h(q, \dot q) = \tau` with :math:`h = V + G`, given by
  :meth:`Plant.terms` (one call, ``(M, h)``), :meth:`Plant.G`, and the checked conveniences
  ``M``, ``V``, ``inverse_dynamics``, ``forward_dynamics``;
* **the engine face**, for the simulators, on the plant's *full* state ``(x, v)`` (every
  coordinate: for a serial arm the joints themselves, for a closed chain the passive ones
  too): :meth:`Plant.start` (the full state of an actuated one), :meth:`Plant.acceleration`
  (the forward dynamics under actuator torques), :meth:`Plant.measure` (what the encoders
  read: the actuated coordinates), and a per-run :class:`Settler` from :meth:`Plant.settler`
  whose ``settle`` runs after every integration step (a closed chain projects onto its loop
  closure and checks the singularity there; a serial arm has nothing to do).

One engine loop over this protocol serves every kind (:mod:`rrr_pin.sim.simulation`):

.. code-block:: python

    x, v = plant.start(q0, qd0)
    settler = plant.settler(t, h, x, v)
    for k in ...:
        q, qd = plant.measure(x, v)
        tau = law(...)
        x, v = rk4(plant.acceleration, x, v, tau, h)
        x, v = settler.settle(k, x, v)

Conventions, for every plant: SI units (rad, m, rad/s, N m), gravity of magnitude
:attr:`Plant.gravity` along ``-z`` of the base.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Plant", "Settler", "UncertaintySet", "TreeDescription", "CapabilityError",
           "CAPABILITIES", "URDF", "EFFORT_LIMITS", "JOINT_FRICTION", "JOINT_LIMITS", "FRAMES",
           "CLOSED_FORM", "JOINT_DYNAMICS", "JOINT_DYNAMICS_SOURCES",
           "central_jacobian"]

#: The plant is a serial tree described by a URDF: its regressor can be identified, its
#: dynamics exported as C, its URDF written and perturbed link by link.
URDF = "urdf"
#: Its description carries the actuators' effort limits (``--torque-limit auto``,
#: ``torque_limit="urdf"``).
EFFORT_LIMITS = "effort_limits"
#: Its description carries each joint's viscous and Coulomb friction (URDF ``<dynamics
#: damping friction>``; ``--friction urdf``, ``viscous="urdf"``).
JOINT_FRICTION = "joint_friction"
#: Its actuated joints have position limits a run can leave (``limit_margin``).
JOINT_LIMITS = "joint_limits"
#: Named frames reachable from the actuated coordinates by forward kinematics
#: (task-space references, ``--frame``, ``--home`` chosen by the frame's reach).
FRAMES = "frames"
#: The paper's closed form of eq. (2)-(7) applies (``check-dynamics``).
CLOSED_FORM = "closed_form"

#: Every capability a plant may declare, with what it allows (for messages and docs).
CAPABILITIES = {
    URDF: "a serial tree described by a URDF (identification, C export of its dynamics)",
    EFFORT_LIMITS: "actuator effort limits in its description",
    JOINT_FRICTION: "joint friction in its description (URDF <dynamics damping friction>)",
    JOINT_LIMITS: "position limits on its actuated joints",
    FRAMES: "named frames placed by forward kinematics of the actuated joints",
    CLOSED_FORM: "the paper's closed-form dynamics, eq. (2)-(7)",
}


#: The joint coefficients a plant carries beyond its links, with their units: the reflected
#: rotor inertia added to ``M``'s diagonal (Pinocchio's ``model.armature``), the viscous and
#: the Coulomb friction of its description (``model.damping``, ``model.friction``).
JOINT_DYNAMICS = {"armature": "kg m^2", "damping": "N m s/rad", "friction": "N m"}

#: Where a plant's joint coefficients came from (:attr:`Plant.joint_sources`): its URDF's
#: ``<dynamics>``, the command line or the Python call (``load_robot(armature=...)``), an MJCF
#: ``<joint armature damping frictionloss>``, an identification, or nowhere (all zero).
JOINT_DYNAMICS_SOURCES = ("urdf", "cli", "mjcf", "identification", "none")


def central_jacobian(f, x0: np.ndarray, h: float) -> np.ndarray:
    """Return the central-difference Jacobian of ``f`` at ``x0``, shape (len(f(x0)), len(x0)).

    Coordinate ``i`` steps by ``h * max(1, |x0[i]|)`` (relative, at least ``h``): an
    ``O(h^2)`` truncation error for a smooth ``f``. Used where no analytic derivative exists
    (a closed chain's dynamics, a user's law); ``(f(x0).size, 0)`` zeros for an empty ``x0``.
    """
    cols = []
    for i in range(x0.size):
        e = np.zeros(x0.size)
        e[i] = h * max(1.0, abs(x0[i]))
        cols.append((f(x0 + e) - f(x0 - e)) / (2 * e[i]))
    return np.array(cols).T if cols else np.zeros((f(x0).size, 0))


class CapabilityError(ValueError):
    """A plant asked for something its kind does not declare (:meth:`Plant.require`).

    Attributes
    ----------
    capability : str
        The missing capability (a key of :data:`CAPABILITIES`).
    """

    def __init__(self, message: str, capability: str):
        super().__init__(message)
        self.capability = capability

    def __reduce__(self):
        return (type(self), (str(self), self.capability))


@dataclass(frozen=True, eq=False)
class TreeDescription:
    """A plant as plain data for a compiled engine: the tree, its loops, the coordinate split.

    What :meth:`Plant.description` gives an engine that runs the plant outside Python, so the
    engine never asks which kind of plant it has: a serial arm is a tree with no loop (every
    coordinate actuated), a closed chain the same tree with loop closures.

    Attributes
    ----------
    model : pinocchio.Model
        The kinematic tree with every joint (``model.nq == model.nv``).
    actuated, passive : ndarray of int
        Velocity indices of the actuated and passive coordinates (``model.nv`` in all).
    loop_joints : ndarray of int, shape (L, 2)
        Per loop closure, the two joints its anchor points are fixed to.
    loop_anchors : ndarray, shape (L, 2, 3)
        The anchor points in those joints' frames [m]; a loop is closed when they coincide.
    rows : ndarray of int
        Independent rows of the stacked world-frame anchor gaps (``3 L``), as many as passive
        coordinates.
    home : ndarray, shape (model.nq,)
        A closed configuration [rad, m] (the Newton seed of the loop closure).
    closure_tol : float
        Loop-closure residual [m] at which Newton stops.
    max_iter : int
        Newton iterations before the loop counts as not closing.
    cond_limit : float
        Largest condition number of ``J_p`` accepted (type-II singularity above it).
    drift_bound : float
        Largest loop gap [m] one RK4 step may leave before its projection.
    """

    model: object
    actuated: np.ndarray
    passive: np.ndarray
    loop_joints: np.ndarray
    loop_anchors: np.ndarray
    rows: np.ndarray
    home: np.ndarray
    closure_tol: float = 0.0
    max_iter: int = 0
    cond_limit: float = 0.0
    drift_bound: float = 0.0


class Settler:
    """What a plant does after every integration step of one run (here: nothing).

    Made by :meth:`Plant.settler` at the start of a run. A closed chain's settler projects the
    state back onto the loop closure, checks the type-II singularity and records the drift.
    """

    def settle(self, k: int, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return the full state after a step of control period ``k`` (here: as it is)."""
        return x, v

    def info(self, x: np.ndarray, v: np.ndarray) -> dict:
        """Return what the run records of the plant (``Trajectory.info``), given its final state."""
        return {}


class UncertaintySet:
    """An uncertainty set: how uncertain plants are drawn around a nominal one.

    The typed input of every study and campaign (``Settings.tolerances``); a plant applies it
    in :meth:`Plant.perturbed`, through the one method for its description:

    * :meth:`arm` for a plant described by a URDF (a serial arm);
    * :meth:`mechanism` for a plant described by a parameter set (a closed chain).

    A set implements those that make sense for it, the others refuse it by name. Built in:
    :class:`rrr_pin.model.uncertainty.Tolerances` (both), the identified set
    :class:`rrr_pin.model.identification.IdentifiedUncertainty` (arms) and
    :class:`rrr_pin.model.uncertainty.MechanismUncertainty` (mechanisms; subclass it to
    write your own). A subclass is a frozen dataclass (it crosses process boundaries and is
    recorded whole in the outputs), and uses only the ``rng`` it is given for randomness.
    """

    def arm(self, source, rng: np.random.Generator, *, skip_joints=(), name=None
            ) -> tuple[str, dict]:
        """Return ``(URDF text, parameters)`` of an uncertain arm around ``source``.

        ``source`` is an :class:`~rrr_pin.model.dh.ArmParams` or URDF text; ``skip_joints``
        keep their nominal origins; ``name`` is the drawn arm's name.
        """
        raise TypeError(f"{type(self).__name__} does not perturb a serial arm (a URDF)")

    def draw_arm(self, robot, rng: np.random.Generator, *, name=None):
        """Return ``(arm, parameters)`` drawn straight into the arm's model, or None.

        None (the default): the set has no such route, and the arm is read from the URDF
        text :meth:`arm` writes. A set that has one
        (:class:`rrr_pin.model.uncertainty.Tolerances`) draws the same plant as :meth:`arm`
        without the text.
        """
        return None

    def draw_joint_dynamics(self, values: dict, rng: np.random.Generator
                            ) -> tuple[dict, dict]:
        """Return a drawn arm's joint coefficients around its nominal ones, and the factors.

        ``values`` maps each key of :data:`JOINT_DYNAMICS` to the nominal's values, shape
        (nq,); called by :meth:`Plant.perturbed` after :meth:`arm` (or :meth:`draw_arm`) with
        the same ``rng``. Here: the values unchanged and no factor (a set that does not draw
        them); :class:`rrr_pin.model.uncertainty.Tolerances` draws each with its own relative
        tolerance.
        """
        return values, {}

    def mechanism(self, params, rng: np.random.Generator) -> tuple[object, dict]:
        """Return ``(parameter set, parameters drawn)`` of an uncertain mechanism."""
        raise TypeError(f"{type(self).__name__} does not perturb a parallel mechanism (a "
                        f"parameter set)")

    def to_dict(self) -> dict:
        """JSON-ready settings of the set (recorded; a resume must match them)."""
        raise NotImplementedError(f"{type(self).__name__} must implement to_dict()")

    def as_settings(self) -> dict:
        """Return what the outputs record: ``{"uncertainty": <class name>, **to_dict()}``."""
        return {"uncertainty": type(self).__name__, **self.to_dict()}

    def describe(self) -> str:
        """One line for reports and figure titles."""
        return type(self).__name__


#: The one settler of plants that need none (it holds no state).
NO_SETTLING = Settler()


class Plant:
    """The protocol of a plant (module docstring); :class:`Robot` and ``ClosedChain`` follow it.

    A subclass provides the attributes and methods below; the defaults here are those of a
    plant whose coordinates are all actuated and need no settling.

    Attributes
    ----------
    name : str
        Plant name (results, figures, messages).
    source : str
        Where it came from (a path, a built-in name, ``"<params>"``).
    capabilities : frozenset of str
        Keys of :data:`CAPABILITIES` this plant has; everything else is refused by name.
    failures : tuple of type
        Exceptions (beyond :class:`rrr_pin.sim.trajectory.SimulationDiverged`) that end a run
        of this plant as a recorded outcome, not an error: a closed chain's singularity, a loop
        that will not close, a drift above its bound.
    actuated_index : ndarray of int or None
        Indices of the actuated coordinates in the full state, or None when they are all of
        it (a serial arm).
    loop_closures : tuple of str
        Names of the kinematic loops the engine face closes (empty for a serial tree): an
        engine that integrates trees only refuses a plant with any.
    exact_derivatives : bool
        Whether :meth:`linearization` and :meth:`gravity_jacobian` are analytic (Pinocchio's
        derivatives) rather than central differences (a closed chain's, about 1e-9 relative).
    model : pinocchio.Model
        The kinematic tree with every joint and its inertias (an instance attribute); the
        parametric analysis scales its inertias and rebuilds the plant with
        :meth:`with_model`.
    """

    capabilities: frozenset = frozenset()
    #: Where the plant's armature, damping and friction came from (``{"armature": "mjcf",
    #: ...}``), set where it is loaded; None: not stated (a URDF's or nothing).
    joint_sources: dict | None = None
    failures: tuple = ()
    actuated_index = None
    loop_closures: tuple = ()
    exact_derivatives: bool = True

    # --- identity and workspace --------------------------------------------------------------
    @property
    def nq(self) -> int:
        """Number of actuated coordinates."""
        raise NotImplementedError

    @property
    def joint_names(self) -> list[str]:
        """Names of the actuated joints, shape (nq,)."""
        raise NotImplementedError

    @property
    def joint_units(self) -> list[str]:
        """Unit of each actuated coordinate, ``"rad"`` (revolute) or ``"m"`` (prismatic)."""
        return ["rad"] * self.nq

    @property
    def gravity(self) -> float:
        """Gravity magnitude [m/s^2], along ``-z`` of the base."""
        raise NotImplementedError

    @property
    def lower(self) -> np.ndarray:
        """Lower limits of the actuated coordinates, shape (nq,); ``-inf`` where none."""
        return np.full(self.nq, -np.inf)

    @property
    def upper(self) -> np.ndarray:
        """Upper limits of the actuated coordinates, shape (nq,); ``+inf`` where none."""
        return np.full(self.nq, np.inf)

    def neutral(self) -> np.ndarray:
        """Return a configuration of the actuated coordinates to start from, shape (nq,)."""
        raise NotImplementedError

    def effort_limits(self) -> np.ndarray:
        """Return the actuators' effort limits of the description [N m], shape (nq,).

        Only for a plant with :data:`EFFORT_LIMITS` (:class:`CapabilityError` otherwise).
        """
        self.require(EFFORT_LIMITS, "effort limits")
        raise NotImplementedError

    def joint_friction(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the description's viscous [N m s/rad] and Coulomb [N m] friction, (nq,) each.

        Only for a plant with :data:`JOINT_FRICTION` (:class:`CapabilityError` otherwise).
        """
        self.require(JOINT_FRICTION, "joint friction")
        raise NotImplementedError

    #: Where each coefficient of :data:`JOINT_DYNAMICS` came from (a value of
    #: :data:`JOINT_DYNAMICS_SOURCES` per key), set where the plant is loaded; see
    #: :meth:`joint_dynamics`.
    joint_sources: dict | None = None

    def joint_dynamics(self) -> dict:
        """Return the plant's armature, damping and friction per actuated joint, and their source.

        What results record of every plant (a campaign's rows, a study's ``results.json``):
        ``{"armature_kg_m2": [...], "damping_Nms_rad": [...], "friction_Nm": [...],
        "source": {"armature": "cli", "damping": "urdf", "friction": "none"}}``, lists of
        length nq, sources from :data:`JOINT_DYNAMICS_SOURCES`. Read from :attr:`model` at
        the actuated coordinates (a closed chain's as its MJCF gave them to Pinocchio).
        """
        index = self.description().actuated
        values = {key: np.asarray(getattr(self.model, key), dtype=float)[index]
                  for key in JOINT_DYNAMICS}
        sources = dict(self.joint_sources or {})
        for key, v in values.items():
            sources.setdefault(key, "mjcf" if np.any(v) else "none")
        return {"armature_kg_m2": values["armature"].tolist(),
                "damping_Nms_rad": values["damping"].tolist(),
                "friction_Nm": values["friction"].tolist(), "source": sources}

    def has(self, capability: str) -> bool:
        """Whether the plant declares ``capability`` (a key of :data:`CAPABILITIES`)."""
        if capability not in CAPABILITIES:
            raise KeyError(f"unknown capability {capability!r}; known: "
                           f"{', '.join(CAPABILITIES)}")
        return capability in self.capabilities

    def require(self, capability: str, what: str) -> None:
        """Refuse ``what`` (a command, an option) by name unless the plant has ``capability``.

        Raises
        ------
        CapabilityError
            Naming the plant, ``what`` and what it would need.
        """
        if not self.has(capability):
            raise CapabilityError(
                f"{what} needs {CAPABILITIES[capability]}, which {self.describe_kind()} "
                f"{self.name!r} does not have", capability)

    def describe_kind(self) -> str:
        """Return a few words saying what kind of plant this is, for messages."""
        return "the plant"

    # --- the model face (actuated coordinates) -----------------------------------------------
    def terms(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(M(q), h(q, qd))`` with ``h = V + G``: the two terms of eq. (1), unchecked.

        The grain a feedback-linearizing law needs (eq. 8, ``tau = M taubar + h``), in one
        call. ``q, qd`` must be finite float64 arrays of shape (nq,) [rad, rad/s]; nothing
        verifies it (the fast path of the laws). Returns shapes (nq, nq) [kg m^2] and (nq,)
        [N m].
        """
        raise NotImplementedError

    def G(self, q, *, check: bool = True) -> np.ndarray:
        """Gravity torques ``G(q)`` [N m], shape (nq,)."""
        raise NotImplementedError

    def M(self, q, *, check: bool = True) -> np.ndarray:
        """Inertia matrix ``M(q)`` [kg m^2], shape (nq, nq)."""
        raise NotImplementedError

    def V(self, q, qd, *, check: bool = True) -> np.ndarray:
        """Centrifugal and Coriolis torques ``V(q, qd)`` [N m], shape (nq,)."""
        raise NotImplementedError

    def linearization(self, q, tau) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return the forward dynamics' derivatives at ``(q, 0, tau)``.

        ``(dqdd/dq, dqdd/dqd, M^-1)``, the last the input matrix.

        ``q`` [rad], ``tau`` [N m], shape (nq,) each, in actuated coordinates; returns three
        (nq, nq) arrays.
        """
        raise NotImplementedError

    def gravity_jacobian(self, q) -> np.ndarray:
        """Return ``dG/dq`` [N m/rad] at the actuated ``q`` [rad], shape (nq, nq)."""
        raise NotImplementedError

    def with_model(self, model) -> Plant:
        """Return this plant with another tree ``model`` (the same joints; e.g. scaled inertias)."""
        raise NotImplementedError

    def reset(self, q=None) -> None:
        """Forget what the model carries from one call to the next; here nothing.

        A closed chain solves its passive coordinates by Newton seeded from its previous
        solution; ``reset(q)`` re-seeds it on the branch of its home configuration at the
        actuated ``q`` (default: home), so that a run depends on its own inputs only.
        """

    def follow(self, Q, where=None) -> None:
        """Take the model along the actuated configurations ``Q`` (N, nq) [rad], in order.

        For a model that carries a solution from one call to the next (a closed chain's loop
        closure, seeded from the last one): after ``follow``, a call at a configuration near
        ``Q[-1]`` lands on the branch of the path. Nothing for a serial arm. ``where(k)``, if
        given, names row ``k`` (e.g. its time) in the message of a failure there.
        """

    # --- the engine face (full state) --------------------------------------------------------
    def start(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Full state ``(x, v)`` at the actuated ``(q, qd)`` [rad, rad/s]; here ``(q, qd)``."""
        return q, qd

    def acceleration(self, x: np.ndarray, v: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Full acceleration of the full state ``(x, v)`` under actuator torques ``tau`` [N m]."""
        raise NotImplementedError

    def measure(self, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return the actuated ``(q, qd)`` of a full state (the encoders); here ``(x, v)``."""
        return x, v

    def settler(self, t: np.ndarray, h: float, x: np.ndarray, v: np.ndarray) -> Settler:
        """Return the :class:`Settler` of one run.

        On the output grid ``t`` [s] with RK4 step ``h`` [s], from the full state ``(x, v)``
        of :meth:`start`.
        """
        return NO_SETTLING

    def task_path(self, period: float):
        """Return the plant's own task path as actuated waypoints ``(t, W, source)``, or None.

        A closed chain's mechanism has one (its study reference: the 5-bar's tip circle, the
        Delta's adept cycle) over ``period`` [s]; a serial arm has none (its study runs the
        joint-space default, :func:`rrr_pin.control.references.study_reference`).
        """
        return None

    def source_text(self) -> tuple[str, str]:
        """Return the plant's own description as written, and its file suffix.

        A serial arm's URDF (``".urdf"``), a closed chain's MJCF (``".xml"``): what a study
        writes of each uncertain plant, and what :func:`rrr_pin.load_robot` reads back.
        """
        raise NotImplementedError

    def fingerprint(self) -> dict:
        """Return what identifies the plant's model, JSON-ready (a campaign's resume checks it)."""
        raise NotImplementedError

    def description(self) -> TreeDescription:
        """Return the plant as plain data for a compiled engine (:class:`TreeDescription`)."""
        raise NotImplementedError

    def configurations(self, Q, seed=None, where=None) -> np.ndarray:
        """Full configurations of the actuated rows ``Q`` (N, nq) [rad]: shape (N, model.nq).

        A serial arm's are ``Q`` itself. A closed chain completes each row with its passive
        coordinates, seeded from the previous row's solution (the first from ``seed``,
        default its home); a row where the loop does not close, or closes at a type-II
        singularity, raises that failure, its message prefixed with ``where(k)`` (a
        function of the row ``k``) when given.
        """
        return np.asarray(Q, dtype=float)

    def task_points(self, period: float, samples: int = 401):
        """Return the task path of :meth:`task_path` as world points ``(P, label)``, or None.

        ``P`` shape (samples, 3) [m] over ``[0, period]`` (drawing the reference: the 5-bar's
        tip circle, the Delta's platform cycle); ``label`` what it is. None without a path.
        """
        return None

    def task_position(self, Q) -> np.ndarray:
        """Return the task point of each actuated row of ``Q`` as world positions [m], (N, 3).

        For a plant with a task path (:meth:`task_points` not None): where the path's point
        is at each configuration (a closed chain's forward kinematics in closed form).
        """
        raise NotImplementedError(f"{self.name!r} has no task path")

    def check_path(self, t: np.ndarray, R: np.ndarray) -> dict:
        """Refuse a sampled reference the plant cannot follow; return what the run records.

        ``t`` shape (N,) [s], ``R`` shape (N, nq) [rad]: the reference on the grid where the
        law reads it. Joint limits are the reference's own check
        (:meth:`rrr_pin.control.references.Reference.check_limits`); here nothing more.
        """
        return {}

    # --- uncertainty -------------------------------------------------------------------------
    def perturbed(self, rng: np.random.Generator, tolerances, *, name: str | None = None
                  ) -> tuple[Plant, dict]:
        """Draw an uncertain plant around this one with ``rng``.

        Parameters
        ----------
        rng : numpy.random.Generator
            The only source of randomness (a study's sample ``k`` of seed ``s`` passes
            ``numpy.random.default_rng([s, k])``).
        tolerances : uncertainty set
            :class:`rrr_pin.model.uncertainty.Tolerances`, or another set the kind accepts
            (an identified set for an arm, a :class:`MechanismUncertainty` for a closed chain);
            any other is refused with ``TypeError`` naming it.
        name : str, optional
            The new plant's name.

        Returns
        -------
        plant : Plant
            The uncertain plant, of the same kind, validated.
        parameters : dict
            JSON-ready description of what was drawn.
        """
        raise NotImplementedError

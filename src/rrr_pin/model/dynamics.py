r"""Rigid-body dynamics of a fixed-base serial arm from any URDF, through Pinocchio.

The equation of motion is the paper's eq. (1),

.. math:: M(q) \ddot q + V(q, \dot q) + G(q) = \tau,

with ``M`` from the composite rigid body algorithm (CRBA), ``V + G`` from the recursive
Newton-Euler algorithm (RNEA) and ``qdd`` from the articulated body algorithm (ABA).

Conventions: SI units (rad, rad/s, N m); gravity of magnitude ``gravity`` along ``-z`` of the
URDF's root link; ``q`` are joint angles (revolute) or displacements (prismatic), one per degree
of freedom. Continuous (unbounded revolute) joints are loaded as revolute joints with infinite
limits, so ``q`` is always an angle and ``nq == nv``.

Validation happens at the edges, once. Loading checks the URDF itself (XML, tree, joint
axes and limits, every link's inertial with
:func:`~rrr_pin.model.urdf_checks.check_urdf_inertials`, joints to lock)
before Pinocchio sees it, because urdfdom silently zeroes some bad inertias. The dynamics
methods of :class:`Robot` check their arrays (:meth:`Robot.check_state`) unless called with
``check=False``, the fast path for loops that have validated their state.

References
----------
.. [1] J. Carpentier et al., "The Pinocchio C++ library", SII 2019.
"""

from __future__ import annotations

import hashlib
import logging
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..validation import check_joint_values, check_positive
from .dh import ArmParams
from .drawn import ArmMap, arm_map, assemble
from .locks import lock_mimics, locked_model
from .mjcf_checks import is_serial_mjcf, mjcf_gravity
from .plant import (
    EFFORT_LIMITS,
    FRAMES,
    JOINT_DYNAMICS,
    JOINT_DYNAMICS_SOURCES,
    JOINT_FRICTION,
    JOINT_LIMITS,
    URDF,
    CapabilityError,
    Plant,
    TreeDescription,
    UncertaintySet,
)
from .robots import ERD_ARMS, RobotModelError, nominal_params, read_source
from .urdf_checks import (
    UNBOUNDED,
    parse_urdf,
    prepare_urdf,
    unbound_continuous,
)

__all__ = ["Robot", "DrawnArm", "MjcfArm", "load_robot", "robot_from_xml", "arm_from_mjcf",
           "check_regular", "DEFAULT_GRAVITY"]

logger = logging.getLogger(__name__)

#: Gravity magnitude [m/s^2] used unless told otherwise: the paper's "standard value" 9.8.
DEFAULT_GRAVITY = 9.8

#: The mass matrix at the neutral configuration counts as singular when its smallest
#: eigenvalue is at most this fraction of its largest (a relative test: scale-free).
_SINGULAR_RTOL = 1e-12

#: dtype of the arrays the fast path hands to Pinocchio unconverted.
_F64 = np.dtype(float)


@dataclass
class Robot(Plant):
    """A Pinocchio model of a fixed-base serial arm with its workspace: a :class:`Plant`.

    The dynamics methods (:meth:`M`, :meth:`V`, :meth:`G`, :meth:`inverse_dynamics`,
    :meth:`forward_dynamics`) check their arrays (shape ``(nq,)``, finite) unless called with
    ``check=False``: the fast path for hot loops whose state is already validated, which costs
    no more than the bare Pinocchio call. With ``check=False`` the arrays must be float64
    ndarrays of shape ``(nq,)`` holding finite values; nothing verifies it (a wrong size raises
    Pinocchio's own error; NaN gives NaN). Both paths return the same values, bit for bit.

    ``model`` is fixed at construction (:meth:`V` keeps a zero-gravity copy of it); to change
    the model, build a new ``Robot`` with :func:`load_robot` or :func:`robot_from_xml`.

    Attributes
    ----------
    model : pinocchio.Model
        The (possibly reduced) kinematic and inertial model.
    data : pinocchio.Data
        Workspace of ``model``; not thread-safe (one ``Robot`` per process or thread).
    name : str
        Robot name.
    source : str
        Where the model came from (a path, a robot name, or ``"<params>"``).
    urdf : str
        The URDF text the model was built from (before joint locking).
    locked : dict
        Joints locked at fixed values [rad or m], by name.
    params : ArmParams or None
        The DH parameter set the arm is built from, when its uncertain plants perturb it (the
        paper's RRR, :func:`rrr_pin.model.robots.nominal_params`) instead of its URDF.
    joint_sources : dict
        Where the model's armature, damping and friction came from (a value of
        :data:`~rrr_pin.model.plant.JOINT_DYNAMICS_SOURCES` per key of
        :data:`~rrr_pin.model.plant.JOINT_DYNAMICS`); by default ``"urdf"`` for the damping
        and friction a URDF gives (``"none"`` where all zero) and ``"none"`` for a zero
        armature. Set by the loader that sets the values (:meth:`with_joint_dynamics`).
    """

    model: pin.Model = field(repr=False)
    data: pin.Data = field(repr=False)
    name: str
    source: str
    urdf: str = field(repr=False)
    locked: dict = field(default_factory=dict)
    params: ArmParams | None = field(default=None, repr=False)
    joint_sources: dict | None = field(default=None, repr=False)

    capabilities = frozenset({URDF, EFFORT_LIMITS, JOINT_FRICTION, JOINT_LIMITS, FRAMES})

    def __post_init__(self) -> None:
        self._shape = (self.model.nq,)
        self._joint_names = tuple(self.model.names)[1:]
        self._zero = np.zeros(self.model.nv)
        self.__dict__.pop("_gravity_free", None)  # made at the first V() (_without_gravity)
        sources = dict(self.joint_sources or {})
        for key in JOINT_DYNAMICS:
            if key not in sources:
                nonzero = bool(np.any(np.asarray(getattr(self.model, key))))
                sources[key] = "none" if not nonzero else "urdf" if key != "armature" \
                    else "cli"
        self.joint_sources = sources

    def _without_gravity(self) -> tuple:
        """Return the model without gravity and its data, for ``V(q, qd) = rnea(q, qd, 0)``."""
        made = self.__dict__.get("_gravity_free")
        if made is None:
            model0 = self.model.copy()
            model0.gravity = pin.Motion.Zero()
            made = self.__dict__["_gravity_free"] = (model0, model0.createData())
        return made

    def __getstate__(self) -> dict:
        # Travel as the model and its description only (about 13 kB for the RRR instead of
        # 200 kB): the workspaces and the zero-gravity copy are rebuilt on arrival, as at
        # construction. A campaign sends its laws' nominal Robot with every task.
        return {key: getattr(self, key) for key in ("model", "name", "source", "urdf",
                                                    "locked", "params", "joint_sources")}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self.data = self.model.createData()
        self.__post_init__()

    @property
    def nq(self) -> int:
        """Number of joint coordinates (equal to the number of velocities)."""
        return self.model.nq

    @property
    def joint_names(self) -> list[str]:
        """Names of the moving joints, base to tip, shape (nq,)."""
        return list(self._joint_names)

    @property
    def joint_units(self) -> list[str]:
        """Unit of each joint coordinate: ``"m"`` for a prismatic joint, else ``"rad"``."""
        return ["m" if j.shortname().startswith("JointModelP") else "rad"
                for j in list(self.model.joints)[1:]]

    @property
    def gravity(self) -> float:
        """Gravity magnitude [m/s^2] (along -z of the root link)."""
        return float(-self.model.gravity.linear[2])

    def describe_kind(self) -> str:
        """Return ``"the serial arm"``."""
        return "the serial arm"

    @property
    def lower(self) -> np.ndarray:
        """Lower joint limits, shape (nq,) [rad or m]; ``-inf`` for continuous joints."""
        return np.array(self.model.lowerPositionLimit, dtype=float)

    @property
    def upper(self) -> np.ndarray:
        """Upper joint limits, shape (nq,) [rad or m]; ``+inf`` for continuous joints."""
        return np.array(self.model.upperPositionLimit, dtype=float)

    def neutral(self) -> np.ndarray:
        """Neutral configuration (all zeros for revolute/prismatic joints), shape (nq,)."""
        return np.array(pin.neutral(self.model), dtype=float)

    def effort_limits(self) -> np.ndarray:
        """Return the URDF's ``<limit effort>`` per joint [N m], shape (nq,) (a new array)."""
        return np.asarray(self.model.effortLimit, dtype=float).copy()

    def joint_friction(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the URDF's ``<dynamics damping friction>`` per joint, shape (nq,) each.

        Viscous [N m s/rad] and Coulomb [N m] (Pinocchio's ``model.damping`` and
        ``model.friction``; zero where the URDF gives none). New arrays.
        """
        return (np.asarray(self.model.damping, dtype=float).copy(),
                np.asarray(self.model.friction, dtype=float).copy())

    def joint_dynamics(self) -> dict:
        """Return the arm's armature, damping and friction per joint and their source.

        As :meth:`Plant.joint_dynamics` records them (lists of length nq, the sources of
        :attr:`joint_sources`).
        """
        return {"armature_kg_m2": np.asarray(self.model.armature, dtype=float).tolist(),
                "damping_Nms_rad": np.asarray(self.model.damping, dtype=float).tolist(),
                "friction_Nm": np.asarray(self.model.friction, dtype=float).tolist(),
                "source": dict(self.joint_sources)}

    def with_joint_dynamics(self, *, armature=None, damping=None, friction=None,
                            source: str = "cli") -> Robot:
        r"""Return this arm with other joint coefficients (a new model; this arm unchanged).

        The armature :math:`I_a` is the reflected rotor inertia of each joint's drive (a rotor
        of inertia :math:`J_r` behind a gear ratio :math:`n` reflects :math:`n^2 J_r`), added
        to the mass matrix's diagonal in every algorithm (Pinocchio's CRBA, RNEA and ABA, the
        compiled engines, the generated code):

        .. math:: M_a(q) = M(q) + \operatorname{diag}(I_a).

        Damping and friction are the description's viscous and Coulomb coefficients, which
        the plant effect ``friction="urdf"`` (``--friction urdf``) applies and
        ``--compensate-friction`` compensates (:meth:`joint_friction`).

        Parameters
        ----------
        armature : float or array-like, shape (nq,), optional
            Reflected rotor inertia per joint [kg m^2] (kg for a prismatic joint), >= 0; one
            value for every joint or one per joint, base to tip. None: unchanged.
        damping : float or array-like, shape (nq,), optional
            Viscous friction [N m s/rad], >= 0. None: unchanged.
        friction : float or array-like, shape (nq,), optional
            Coulomb friction [N m], >= 0. None: unchanged.
        source : str, default "cli"
            Where the values given come from, one of
            :data:`~rrr_pin.model.plant.JOINT_DYNAMICS_SOURCES` (recorded in results).

        Raises
        ------
        ValueError
            A value that is negative or not finite, or a count that is neither 1 nor nq,
            naming the field and the joint; an unknown ``source``.
        """
        if source not in JOINT_DYNAMICS_SOURCES:
            raise ValueError(f"source must be one of {', '.join(JOINT_DYNAMICS_SOURCES)}, "
                             f"got {source!r}")
        given = {key: check_joint_values(key, value, self.joint_names, unit=unit)
                 for (key, unit), value in zip(JOINT_DYNAMICS.items(),
                                               (armature, damping, friction), strict=True)
                 if value is not None}
        model = self.model.copy()
        for key, value in given.items():
            getattr(model, key)[:] = value
        sources = {**self.joint_sources, **dict.fromkeys(given, source)}
        return replace(self, model=model, data=model.createData(), joint_sources=sources)

    def check_state(self, name: str, x) -> np.ndarray:
        """Return ``x`` as a finite float64 array of shape ``(nq,)``, or raise ``ValueError``.

        The validator of every joint-space array the methods take (``q``, ``qd``, ``qdd``,
        ``tau``); a hot loop can call it once and then use ``check=False``.

        Parameters
        ----------
        name : str
            The argument's name, for the message.
        x : array-like, shape (nq,)
            Joint-space array [rad, rad/s, rad/s^2 or N m].

        Raises
        ------
        ValueError
            ``Expected q of shape (3,), got (2,)``, or ``q must be finite, got [...]``.
        """
        if type(x) is not np.ndarray or x.dtype is not _F64:
            try:
                x = np.asarray(x, dtype=float)
            except (TypeError, ValueError):
                raise ValueError(f"{name} must be an array of numbers of shape {self._shape}, "
                                 f"got {x!r}") from None
        if x.shape != self._shape:
            raise ValueError(f"Expected {name} of shape {self._shape}, got {x.shape}")
        # The sum is finite only if every entry is (NaN and inf propagate); finite entries can
        # still overflow it, hence the exact test behind. Python's sum of a list is the
        # cheapest reduction for the short arrays of an arm (~0.3 us against ~1 us for NumPy's).
        if not math.isfinite(sum(x.tolist())) and not np.isfinite(x).all():
            raise ValueError(f"{name} must be finite, got {x}")
        return x

    def terms(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(M(q), V(q, qd) + G(q))``, eq. (1), unchecked: CRBA and ``nonLinearEffects``.

        The laws' fast path (:meth:`Plant.terms`): ``q, qd`` finite float64 arrays of shape
        (nq,) [rad, rad/s]. ``M`` is a full symmetric new array [kg m^2] (as :meth:`M`), ``h``
        shape (nq,) [N m].
        """
        model, data = self.model, self.data
        # pin.crba's binding (pin >= 3, pinned to 4.1.0) returns a symmetric copy, its upper
        # triangle mirrored (as M documents): no NumPy triu to complete it.
        return pin.crba(model, data, q), pin.nonLinearEffects(model, data, q, qd)

    def acceleration(self, x: np.ndarray, v: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Forward dynamics ``qdd = M^-1 (tau - V - G)`` (ABA), unchecked: the engines' step.

        ``x, v, tau`` float64 arrays of shape (nq,) [rad, rad/s, N m]; returns [rad/s^2].
        """
        return pin.aba(self.model, self.data, x, v, tau)

    def linearization(self, q, tau) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return Pinocchio's ``computeABADerivatives`` at ``(q, 0, tau)``."""
        dq, dv, dtau = pin.computeABADerivatives(self.model, self.data, q, np.zeros(self.nq),
                                                 tau)
        return np.asarray(dq), np.asarray(dv), np.asarray(dtau)

    def gravity_jacobian(self, q) -> np.ndarray:
        """Return ``computeGeneralizedGravityDerivatives`` at ``q`` [N m/rad], shape (nq, nq)."""
        return np.asarray(pin.computeGeneralizedGravityDerivatives(self.model,
                                                                   self.model.createData(), q))

    def with_model(self, model) -> Robot:
        """Return this arm on another Pinocchio model of the same joints (e.g. scaled inertias)."""
        return replace(self, model=model, data=model.createData())

    def source_text(self) -> tuple[str, str]:
        """Return the URDF text the arm was built from and ``".urdf"``."""
        return self.urdf, ".urdf"

    def fingerprint(self) -> dict:
        """Return ``{"urdf_sha256", "locked", "gravity"}``, and the joint coefficients.

        ``"joint_dynamics"`` (:meth:`joint_dynamics`) when the URDF does not say them all:
        a nonzero armature, or damping or friction from elsewhere than the URDF.
        """
        out = {"urdf_sha256": hashlib.sha256(self.urdf.encode()).hexdigest(),
               "locked": dict(self.locked), "gravity": self.gravity}
        if np.any(np.asarray(self.model.armature)) or any(
                v not in ("urdf", "none") for v in self.joint_sources.values()):
            out["joint_dynamics"] = self.joint_dynamics()
        return out

    def description(self) -> TreeDescription:
        """Return the arm as a tree with no loop, every joint actuated (a TreeDescription)."""
        n = self.nq
        return TreeDescription(model=self.model, actuated=np.arange(n), passive=np.arange(0),
                               loop_joints=np.zeros((0, 2), dtype=int),
                               loop_anchors=np.zeros((0, 2, 3)), rows=np.arange(0),
                               home=self.neutral())

    def perturbed(self, rng: np.random.Generator, tolerances, *, name: str | None = None
                  ) -> tuple[Robot, dict]:
        """Draw an uncertain arm with ``rng`` (:meth:`Plant.perturbed`).

        ``tolerances.arm`` perturbs :attr:`params` when the arm has them (the paper's RRR)
        and the URDF otherwise, the locked joints' origins left nominal
        (:mod:`rrr_pin.model.uncertainty`); the arm drawn keeps this one's gravity and locks.
        """
        if not isinstance(tolerances, UncertaintySet):
            raise TypeError(f"tolerances must be an uncertainty set (e.g. "
                            f"rrr_pin.Tolerances()), got {type(tolerances).__name__}")
        drawn = tolerances.draw_arm(self, rng, name=name)
        if drawn is not None:  # the set draws straight into the model (:meth:`drawn`)
            plant, parameters = drawn
        else:
            source = self.params if self.params is not None else self.urdf
            urdf, parameters = tolerances.arm(source, rng, skip_joints=tuple(self.locked),
                                              name=name)
            # source: the nominal's, so that the drawn arm's mesh references (the nominal's,
            # byte for byte: only inertials and joint origins are perturbed) resolve where the
            # nominal's do (an example-robot-data folder, the URDF's own folder).
            plant = robot_from_xml(urdf, gravity=self.gravity, lock=dict(self.locked),
                                   name=name or self.name, label=self.source, check=False)
        return plant, self._drawn_joint_dynamics(plant, parameters, rng, tolerances)

    def _drawn_joint_dynamics(self, plant: Robot, parameters: dict, rng, tolerances) -> dict:
        """Give a drawn ``plant`` its joint coefficients, drawn around this arm's; in place.

        The nominal values are this arm's, except damping and friction from the URDF, which
        are the drawn plant's own (its URDF's: an identified set draws them there). The set
        then draws each around them (:meth:`UncertaintySet.draw_joint_dynamics`), after the
        arm's own draws, from the same ``rng``: a set that draws none leaves every earlier
        plant of a seed as it was. Returns ``parameters`` with ``"joint_dynamics"`` (the
        values, their source and the factors drawn).
        """
        nominal = {key: np.array(getattr(plant.model if self.joint_sources[key] == "urdf"
                                         else self.model, key), dtype=float)
                   for key in JOINT_DYNAMICS}
        values, factors = tolerances.draw_joint_dynamics(nominal, rng)
        for key in JOINT_DYNAMICS:
            getattr(plant.model, key)[:] = values[key]
        plant.joint_sources = dict(self.joint_sources)
        record = plant.joint_dynamics()
        if factors:
            record["factors"] = factors
        return {**parameters, "joint_dynamics": record}

    def arm_map(self) -> ArmMap:
        """Return the numbers of this arm's URDF a draw changes (:func:`~.drawn.arm_map`).

        Made once and kept (a cache: the arm's URDF, parameters and locks do not change).
        """
        amap = self.__dict__.get("_arm_map")
        if amap is None:
            amap = self.__dict__["_arm_map"] = arm_map(self.urdf, self.params, self.locked,
                                                       self.model)
        return amap

    def drawn(self, origins: dict, inertials: dict, *, write, name: str | None = None
              ) -> DrawnArm:
        """Return this arm with other joint origins and inertials, without URDF text.

        Put together as Pinocchio reads a URDF (:func:`rrr_pin.model.drawn.assemble`).

        Parameters
        ----------
        origins : dict
            URDF joint name -> origin translation, shape (3,) [m] (absent: this arm's).
        inertials : dict
            URDF link name -> ``(m [kg], c shape (3,) [m], I shape (3, 3) [kg m^2], R shape
            (3, 3))``: mass, centre of mass and inertia in the inertial's frame, and that
            frame's rotation (absent: this arm's). Physically valid (checked where drawn).
        write : callable
            ``write() -> str``: the URDF text of the same arm, called at the first use of
            :attr:`DrawnArm.urdf`.
        name : str, optional
            Default this arm's name.

        Raises
        ------
        RobotModelError (a ValueError)
            A mass matrix singular at the neutral configuration (as when a URDF is loaded).
        """
        model = assemble(self.model, self.arm_map(), origins, inertials)
        arm = DrawnArm(model=model, data=model.createData(), name=name or self.name,
                       source=self.source, urdf=None, locked=dict(self.locked))
        arm.__dict__["_write_urdf"] = write
        check_regular(arm, f"the arm drawn around {self.name!r}")
        return arm

    def M(self, q, *, check: bool = True) -> np.ndarray:
        """Joint-space inertia matrix ``M(q)`` (CRBA), eq. (2).

        Parameters
        ----------
        q : array-like, shape (nq,)
            Joint positions [rad or m].
        check : bool, default True
            Validate ``q`` (see the class docstring for ``check=False``).

        Returns
        -------
        M : ndarray, shape (nq, nq)
            Full symmetric matrix [kg m^2], a new array. Pinocchio's CRBA fills the upper
            triangle; its Python binding mirrors it into the lower one and returns a copy
            (``make_symmetric`` in ``bindings/python/algorithm/expose-crba.cpp``).
        """
        # check_state's tests inlined for an already valid q (a method call is ~10 % of a
        # 3-joint CRBA); anything else goes through check_state, which names the fault
        if check and not (type(q) is np.ndarray and q.dtype is _F64 and q.shape == self._shape
                          and math.isfinite(sum(q.tolist()))):
            q = self.check_state("q", q)
        return pin.crba(self.model, self.data, q)

    def V(self, q, qd, *, check: bool = True) -> np.ndarray:
        """Centrifugal and Coriolis torques ``V(q, qd)``, eq. (3), shape (nq,) [N m].

        Computed as ``rnea(q, qd, 0)`` on a zero-gravity copy of the model, which equals
        ``nonLinearEffects(q, qd) - G(q)`` without the cancellation of ``G``.

        Parameters
        ----------
        q : array-like, shape (nq,)
            Joint positions [rad or m].
        qd : array-like, shape (nq,)
            Joint velocities [rad/s or m/s].
        check : bool, default True
            Validate the arrays (see the class docstring for ``check=False``).
        """
        if check and not (type(q) is type(qd) is np.ndarray and q.dtype is qd.dtype is _F64
                          and q.shape == qd.shape == self._shape
                          and math.isfinite(sum(q.tolist()) + sum(qd.tolist()))):
            # One test for the common case (as in check_state); the exact one names the array.
            q, qd = self.check_state("q", q), self.check_state("qd", qd)
        # V(q, qd) = rnea(q, qd, 0) without gravity: one RNEA pass instead of nle - G.
        model0, data0 = self._without_gravity()
        return pin.rnea(model0, data0, q, qd, self._zero)

    def G(self, q, *, check: bool = True) -> np.ndarray:
        """Gravity torques ``G(q)``, eq. (4), shape (nq,) [N m], a new array.

        Parameters
        ----------
        q : array-like, shape (nq,)
            Joint positions [rad or m].
        check : bool, default True
            Validate ``q`` (see the class docstring for ``check=False``).
        """
        if check:
            q = self.check_state("q", q)
        return pin.computeGeneralizedGravity(self.model, self.data, q)

    def inverse_dynamics(self, q, qd, qdd, *, check: bool = True) -> np.ndarray:
        """Torques ``tau = M qdd + V + G`` (RNEA), shape (nq,) [N m].

        Arrays of shape (nq,): ``q`` [rad], ``qd`` [rad/s], ``qdd`` [rad/s^2]; ``check`` as
        in :meth:`M`.
        """
        if check:
            q, qd = self.check_state("q", q), self.check_state("qd", qd)
            qdd = self.check_state("qdd", qdd)
        return pin.rnea(self.model, self.data, q, qd, qdd)

    def forward_dynamics(self, q, qd, tau, *, check: bool = True) -> np.ndarray:
        """Accelerations ``qdd = M^-1 (tau - V - G)`` (ABA), shape (nq,) [rad/s^2].

        Arrays of shape (nq,): ``q`` [rad], ``qd`` [rad/s], ``tau`` [N m]; ``check`` as in
        :meth:`M`.
        """
        if check:
            q, qd = self.check_state("q", q), self.check_state("qd", qd)
            tau = self.check_state("tau", tau)
        return pin.aba(self.model, self.data, q, qd, tau)

    def frame_placement(self, q, frame: str) -> np.ndarray:
        """Placement of a URDF frame (link or joint name) in the root frame, shape (4, 4)."""
        q = self.check_state("q", q)
        if not self.model.existFrame(frame):
            raise ValueError(f"no frame named {frame!r} in robot {self.name!r}")
        pin.framesForwardKinematics(self.model, self.data, q)
        return np.array(self.data.oMf[self.model.getFrameId(frame)].homogeneous)

    def joint_placements(self, q) -> list[np.ndarray]:
        """Placements of the joint frames ``joint1..jointn``, each shape (4, 4)."""
        q = self.check_state("q", q)
        pin.forwardKinematics(self.model, self.data, q)
        return [np.array(self.data.oMi[j].homogeneous) for j in range(1, self.model.njoints)]


class DrawnArm(Robot):
    """An uncertain arm drawn into its Pinocchio model (:meth:`Robot.drawn`); a :class:`Robot`.

    Its URDF text is written at the first use of :attr:`urdf` (saving the plant, a
    fingerprint, pickling), from the same draws.
    """

    @property
    def urdf(self) -> str:
        """The arm's URDF text, written at first use (a model read from it equals this one)."""
        text = self.__dict__.get("_urdf")
        if text is None:
            text = self.__dict__["_urdf"] = self.__dict__.pop("_write_urdf")()
        return text

    @urdf.setter
    def urdf(self, text) -> None:
        self.__dict__["_urdf"] = text

    def __setstate__(self, state: dict) -> None:
        state = dict(state)
        state["_urdf"] = state.pop("urdf")  # written when pickled (Robot.__getstate__)
        super().__setstate__(state)


def load_robot(source="rrr", *, gravity: float | None = None,
               lock: dict[str, float] | None = None, armature=None) -> Robot:
    """Load a fixed-base serial arm into Pinocchio.

    Parameters
    ----------
    source : str, path-like or ArmParams, default "rrr"
        A URDF file path; ``"rrr"`` (the paper's arm, generated from :func:`paper_params`);
        an example-robot-data arm name (see :func:`robot_names`); or an :class:`ArmParams`,
        whose URDF is generated on the fly. An ``.xml`` MJCF path without loop closure is a
        serial arm read by Pinocchio's MJCF parser (:func:`arm_from_mjcf`: a
        :class:`MjcfArm`, with its joints' armature, damping and friction loss).
        A parallel mechanism (``"fivebar"``, ``"delta"``, their parameter sets or an
        ``.xml`` MJCF path with ``<equality><connect>``) gives a
        :class:`rrr_pin.model.closed_chain.ClosedChain` instead.
    gravity : float, optional
        Gravity magnitude [m/s^2], along ``-z`` of the URDF's root link; default ``source.g``
        for an :class:`ArmParams`, an MJCF arm's ``<option gravity>`` (9.81 without one),
        else 9.8 (the paper's value).
    lock : dict of str to float, optional
        Joints to lock, by name, at the given positions [rad or m] (Pinocchio's reduced model);
        e.g. ``{"panda_finger_joint1": 0.0, "panda_finger_joint2": 0.0}``.
    armature : float or array-like, shape (nq,), optional
        Reflected rotor inertia of each moving joint [kg m^2] (after locking), >= 0: one value
        for every joint or one per joint, base to tip; added to ``M(q)``'s diagonal
        (:meth:`Robot.with_joint_dynamics`, source ``"cli"``). Default: none (a URDF carries
        no armature). Not for a closed chain (refused): its armature is its MJCF's.

    Returns
    -------
    Robot
        Or a :class:`~rrr_pin.model.closed_chain.ClosedChain` for a parallel mechanism.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    RobotModelError (a ValueError)
        Naming the link, joint or field: not UTF-8, malformed URDF (not a tree, two parents,
        zero joint axis, limits with ``lower >= upper``, non-finite numbers), an inertial that
        is not physical (:func:`~rrr_pin.model.urdf_checks.check_urdf_inertials`), floating
        base, unlocked mimic joint,
        moving joint without mass downstream, a joint to lock that is unknown or whose value
        is not finite or outside its limits, or a mass matrix that is not positive definite.
    ValueError
        An armature that is negative, not finite, or not one value or one per joint, naming
        the joint.
    """
    from .closed_chain import is_closed_chain_source, load_closed_chain

    if is_serial_mjcf(source):  # an arm described in MJCF (e.g. MuJoCo Menagerie's)
        return arm_from_mjcf(source, gravity=gravity, lock=lock)
    if is_closed_chain_source(source):  # a parallel mechanism (MJCF): "fivebar", "delta"
        if lock:
            raise ValueError(f"lock: joints of a closed chain cannot be locked, got {lock}")
        if armature is not None:
            raise ValueError(f"armature: a closed chain's armature is its MJCF's (<joint "
                             f"armature>); it cannot be set on {source!r}, got {armature!r}")
        return load_closed_chain(source, gravity=DEFAULT_GRAVITY if gravity is None else gravity)
    if gravity is None:
        gravity = source.g if isinstance(source, ArmParams) else DEFAULT_GRAVITY
    raw, name, label = read_source(source)
    if isinstance(source, str) and source in ERD_ARMS:
        lock = lock_mimics(raw, name, lock)
    robot = robot_from_xml(raw, name=name, gravity=gravity, lock=lock, label=label)
    robot.params = nominal_params(robot)
    if armature is not None:
        robot = robot.with_joint_dynamics(armature=armature, source="cli")
    logger.info("loaded %s from %s: %d joints (%s)%s", robot.name, label, robot.nq,
                ", ".join(robot.joint_names),
                f", locked {robot.locked}" if robot.locked else "")
    return robot


def robot_from_xml(urdf: str, *, name: str | None = None, gravity: float = DEFAULT_GRAVITY,
                   lock: dict[str, float] | None = None, label: str = "<string>",
                   check: bool = True) -> Robot:
    """Like :func:`load_robot`, from URDF text already in memory.

    Parameters
    ----------
    urdf : str
        URDF XML text.
    name : str, optional
        Robot name; default the URDF's ``<robot name>``.
    gravity, lock
        As in :func:`load_robot`.
    label : str
        Where the text came from, for error messages.
    check : bool, default True
        Validate the URDF text (the XML tree, every joint, every inertial, some mass behind
        every moving joint). ``False`` trusts a text that rrr-pin made and checked itself,
        so that a plant is validated once, where it is made: the URDF of a loaded
        :class:`Robot` (``robot.urdf``), or an uncertain plant of
        :func:`rrr_pin.model.uncertainty.sample_plant` drawn around such a nominal (its tree,
        joints and limits are the nominal's, and its perturbed inertials were checked when it
        was written). Continuous joints are still rewritten, and ``gravity``, ``lock`` and
        the built model (``nq == nv``, a moving joint left, a positive definite mass matrix)
        are checked either way. A text that rrr-pin did not check must not be passed with
        ``check=False``: urdfdom reads some bad inertias as zero without an error.
    """
    lock = dict(lock or {})
    gravity = check_positive("gravity", gravity, allow_zero=True, unit="m/s^2")
    raw = urdf
    try:
        urdf, urdf_name = (prepare_urdf(raw, set(lock)) if check
                           else unbound_continuous(parse_urdf(raw), raw))
    except RobotModelError as exc:
        raise RobotModelError(f"{label}: {exc}") from None
    try:
        model = pin.buildModelFromXML(urdf)
    except (ValueError, RuntimeError) as exc:
        raise RobotModelError(f"Pinocchio could not build a model from {label}: {exc}") from None
    if model.nq != model.nv:
        raise RobotModelError(f"{label}: joints with nq != nv are not supported "
                              f"(nq={model.nq}, nv={model.nv})")
    unbounded = np.abs(model.upperPositionLimit) >= UNBOUNDED
    model.upperPositionLimit[unbounded] = np.inf
    model.lowerPositionLimit[np.abs(model.lowerPositionLimit) >= UNBOUNDED] = -np.inf
    model, lock = locked_model(model, lock, label)
    model.gravity.linear = np.array([0.0, 0.0, -gravity])
    robot = Robot(model=model, data=model.createData(), name=name or urdf_name, source=label,
                  urdf=raw, locked=lock)
    check_regular(robot, label)
    return robot


def check_regular(robot: Robot, label: str) -> None:
    """Refuse an arm whose mass matrix is singular at the neutral configuration (clipped).

    Raises
    ------
    RobotModelError (a ValueError)
        Naming ``label`` and the eigenvalues.
    """
    q0 = np.clip(robot.neutral(), robot.lower, robot.upper)
    eig = np.linalg.eigvalsh(robot.M(q0))
    if not eig.min() > _SINGULAR_RTOL * eig.max():
        # Every inertial is physical and every moving joint carries mass by now, so a singular
        # M means some joint moves no inertia about its own axis. Relative to the largest
        # eigenvalue: M scales with mass x length^2, and an arm of 1e-12 kg m^2 is as regular
        # as one of 1 kg m^2.
        raise RobotModelError(
            f"{label}: the mass matrix is singular at the neutral configuration (eigenvalues "
            f"{eig}): some joint moves no inertia about its axis (e.g. point masses on the "
            f"axis, or an axis along a massless direction of its subtree)")


#: The joints Pinocchio builds from an MJCF hinge or slide (any axis).
_SERIAL_JOINTS = ("JointModelR", "JointModelP")


@dataclass
class MjcfArm(Robot):
    """A fixed-base serial arm read from an MJCF file by Pinocchio (:func:`arm_from_mjcf`).

    A :class:`Robot` whose description is MJCF instead of URDF: its joints' ``armature``
    [kg m^2] is in :attr:`model` (Pinocchio adds it to ``M``'s diagonal in CRBA, ABA and RNEA,
    as MuJoCo does), and its ``damping`` [N m s/rad] and ``frictionloss`` [N m] are the plant's
    own friction (:meth:`joint_friction`, applied in every run as the friction effect; see
    :func:`rrr_pin.sim.simulation.simulate`). It has no URDF: identification, C export of its
    dynamics and uncertain plants drawn around it are refused by name.

    Attributes
    ----------
    mjcf : str
        The MJCF text the model was built from (before joint locking).
    joint_sources : dict
        Where the armature, damping and friction came from: ``"mjcf"`` for each.
    """

    mjcf: str = field(default="", repr=False)
    joint_sources: dict = field(default_factory=lambda: dict.fromkeys(
        ("armature", "damping", "friction"), "mjcf"))

    capabilities = frozenset({EFFORT_LIMITS, JOINT_FRICTION, JOINT_LIMITS, FRAMES})

    def __getstate__(self) -> dict:
        return {**super().__getstate__(), "mjcf": self.mjcf,
                "joint_sources": self.joint_sources}

    def describe_kind(self) -> str:
        """Return ``"the MJCF arm"``."""
        return "the MJCF arm"

    def source_text(self) -> tuple[str, str]:
        """Return the MJCF text the arm was built from and ``".xml"``."""
        return self.mjcf, ".xml"

    def fingerprint(self) -> dict:
        """Return ``{"mjcf_sha256", "locked", "gravity"}``."""
        return {"mjcf_sha256": hashlib.sha256(self.mjcf.encode()).hexdigest(),
                "locked": dict(self.locked), "gravity": self.gravity}

    def joint_friction(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the MJCF's ``<joint damping frictionloss>`` per joint, shape (nq,) each.

        Viscous [N m s/rad] and Coulomb [N m] (Pinocchio's ``model.damping`` and
        ``model.friction``, as its MJCF parser fills them). New arrays.
        """
        return super().joint_friction()

    def perturbed(self, rng, tolerances, *, name=None):
        """Refused: uncertain plants are drawn around a URDF, and an MJCF arm has none."""
        raise CapabilityError(f"uncertain plants drawn around {self.describe_kind()} "
                              f"{self.name!r} need a URDF, which an MJCF arm does not have; "
                              f"run it as a nominal plant (rrr-pin reproduce --samples 0, "
                              f"rrr-pin stress)", URDF)

    def arm_map(self):
        """Refused: see :meth:`perturbed`."""
        return self.perturbed(None, None)


def arm_from_mjcf(source, *, gravity: float | None = None,
                  lock: dict[str, float] | None = None, name: str | None = None) -> MjcfArm:
    """Load a fixed-base serial arm from an MJCF file with Pinocchio's MJCF parser.

    The joints' ``armature`` [kg m^2], ``damping`` [N m s/rad] and ``frictionloss`` [N m]
    become the plant's (Pinocchio's ``model.armature``, ``model.damping``,
    ``model.friction``); joints that are not the arm's (a gripper's fingers) are locked with
    ``lock`` as for a URDF, e.g. ``{"finger_joint1": 0.0, "finger_joint2": 0.0}`` on MuJoCo
    Menagerie's Panda. Geometry, contacts and sensors are ignored.

    Parameters
    ----------
    source : str or path-like
        An MJCF file (``.xml``) with no ``<equality><connect>`` loop closure.
    gravity : float, optional
        Gravity magnitude [m/s^2] along ``-z``; default the file's ``<option gravity>``
        (MuJoCo's default 9.81 without one; a gravity not along ``-z`` is refused).
    lock : dict of str to float, optional
        Joints to lock, by name, at the given positions [rad or m].
    name : str, optional
        Default: the file's stem.

    Returns
    -------
    MjcfArm

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    RobotModelError (a ValueError)
        A closed chain (``<connect>``: load it with :func:`load_robot`, not as an arm), and
        each refusal of :func:`rrr_pin.model.mjcf_checks.check_serial_mjcf` (a free joint, a
        tendon or an equality on an arm joint, an actuator other than a gear-1 motor on one);
        a joint to lock that is unknown or outside its limits; a singular mass matrix.
    """
    from .mjcf_checks import check_serial_mjcf, has_loop_closure

    path = Path(source)
    label = str(path)
    if not path.is_file():
        raise FileNotFoundError(f"MJCF file not found: {path}")
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8")
        root = ET.fromstring(raw)
    except (UnicodeDecodeError, ET.ParseError) as exc:
        raise RobotModelError(f"{label}: not a well-formed UTF-8 XML file: {exc}") from None
    if has_loop_closure(root):
        raise RobotModelError(f"{label}: has <equality><connect> loop closures: a closed "
                              f"chain, not a serial arm (load it with load_robot, or --robot, "
                              f"as a parallel mechanism)")
    lock = dict(lock or {})
    if gravity is None:
        gravity = mjcf_gravity(root, label)
    gravity = check_positive("gravity", gravity, allow_zero=True, unit="m/s^2")
    check_serial_mjcf(root, label, locked=lock)
    try:
        model = pin.buildModelFromMJCF(str(path))
    except (ValueError, RuntimeError) as exc:
        raise RobotModelError(f"Pinocchio could not build a model from {label}: {exc}") from None
    kinds = [j.shortname() for j in list(model.joints)[1:]]
    odd = [(n, k) for n, k in zip(list(model.names)[1:], kinds, strict=True)
           if not k.startswith(_SERIAL_JOINTS)]
    if odd or model.nq != model.nv:
        raise RobotModelError(f"{label}: joints other than hinge and slide ({odd}); rrr-pin "
                              f"handles fixed-base arms of hinge and slide joints only")
    negative = [(key, float(np.min(getattr(model, key)))) for key in
                ("armature", "damping", "friction") if np.any(getattr(model, key) < 0)]
    if negative:
        raise RobotModelError(f"{label}: negative joint {negative[0][0]} "
                              f"({negative[0][1]:g}); armature, damping and frictionloss "
                              f"must be >= 0")
    model, lock = locked_model(model, lock, label)
    model.gravity.linear = np.array([0.0, 0.0, -gravity])
    robot = MjcfArm(model=model, data=model.createData(), name=name or path.stem,
                    source=label, urdf="", locked=lock, mjcf=text)
    check_regular(robot, label)
    logger.info("loaded %s from %s (MJCF): %d joints (%s), armature %s kg m^2, damping %s "
                "N m s/rad, friction loss %s N m%s", robot.name, label, robot.nq,
                ", ".join(robot.joint_names), np.round(model.armature, 6).tolist(),
                np.round(model.damping, 6).tolist(), np.round(model.friction, 6).tolist(),
                f", locked {robot.locked}" if robot.locked else "")
    return robot

"""Uncertain plants: seeded, physically valid perturbations of an arm, written out as URDF.

Under :class:`Tolerances`, :meth:`rrr_pin.model.dynamics.Robot.perturbed` draws the plant
straight into its Pinocchio model (:mod:`rrr_pin.model.drawn`: the same draws, the numbers this
module writes, read as Pinocchio reads them) and writes the URDF text of this module only when
asked for. A plant is validated once, where it is made: a DH plant by the checks of
:class:`~rrr_pin.model.dh.DHLink`, which hold for its scaled links by construction
(:meth:`~rrr_pin.model.dh.DHLink.scaled`; its URDF is generated from them), a URDF plant by
:func:`~rrr_pin.model.urdf_checks.check_urdf_inertials` on the text written, or by
:func:`~rrr_pin.model.dh.check_inertials` on the inertials drawn into its model (its tree,
joints and limits are the nominal's, which were checked when the nominal was loaded). So
the plant of a loaded nominal may be loaded with
``rrr_pin.model.dynamics.robot_from_xml(plant.urdf, ..., check=False)``.

Perturbation model (paper section 5: "20 % tolerance for the inertia parameters and 5 % for the
link lengths"); every factor is drawn independently and uniformly in ``[1 - tol, 1 + tol]``:

* mass of each link: ``m * f_m``;
* inertia of each link: the principal *second moments* of its mass distribution
  ``S_k = integral of x_k^2 dm`` (principal axes of ``S`` = those of the inertia tensor) are
  scaled, ``S_k * f_k``, and the inertia rebuilt as ``I = tr(S) 1 - S``. Since ``S_k >= 0``
  stays true, every perturbed tensor is positive semi-definite and satisfies the triangle
  inequality by construction, and each principal moment ``J_x = S_y + S_z`` moves by the same
  relative tolerance. (Scaling ``Jx, Jy, Jz`` independently would break the triangle inequality
  of the paper's thin rods, whose moments sit exactly on it.)
* lengths: each link length ``l`` (DH ``a`` and ``d``) by ``f_l`` with the centre-of-mass
  distance ``lg`` scaled by the same factor (for a URDF: each joint origin's translation and the
  link's centre of mass).
* joint coefficients (off by default): each joint's armature (reflected rotor inertia),
  damping and Coulomb friction by its own factor in ``[1 - tol, 1 + tol]``, ``tol`` being
  ``Tolerances.armature``, ``.damping``, ``.friction``. These are *relative to the nominal
  value*: a joint whose nominal armature is zero (any URDF without ``--armature``) stays at
  zero whatever the tolerance. Give the nominal first (``load_robot(..., armature=0.1)``,
  ``--armature 0.1``), then its tolerance. They are drawn after the inertials and lengths,
  from the same generator, and only when nonzero: a zero tolerance draws nothing, so every
  plant drawn without them is the same as before they existed.

Identified uncertainty: with ``tol`` an
:class:`~rrr_pin.model.identification.IdentifiedUncertainty` (an ``identification.json`` of
``rrr-pin identify``) instead of :class:`Tolerances`, the kinematics stay nominal and the
inertials are drawn from the identified distribution of the base parameters, each plant made
physically consistent or rejected and redrawn (counted in its ``parameters["identified"]
["rejected"]``): :meth:`~rrr_pin.model.identification.IdentifiedUncertainty.draw`.

Seeding: sample ``k`` of a study with seed ``s`` uses ``numpy.random.default_rng([s, k])``
(PCG64, identical on every platform), so a single plant can be regenerated alone.

Parallel mechanisms (the 5-bar and the Delta of :mod:`rrr_pin.model.mechanisms`) are not URDF:
their uncertain plants are parameter sets, drawn by a :class:`MechanismUncertainty` (a small
base class a user may subclass: ``draw(params, rng) -> (params, factors)`` and ``to_dict()``).
The built-in is :class:`MechanismTolerances`, :func:`~rrr_pin.model.mechanisms.perturb_mechanism`
with the paper's 20 % on masses and 5 % on lengths (the rods' moments follow), every draw
closable. :func:`sample_mechanism` draws sample ``k`` with the same seed rule.
"""

from __future__ import annotations

import io
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..outputs import writing
from ..validation import check_count, check_real, check_vector
from .dh import ArmParams, check_inertial, check_inertials
from .mechanisms import is_mechanism_params, perturb_mechanism
from .plant import UncertaintySet
from .robots import RobotModelError
from .urdf import dh_link_frame, urdf_from_params

__all__ = [
    "Tolerances",
    "ToleranceVertices",
    "JOINT_TOLERANCES",
    "PlantSample",
    "perturb_params",
    "perturb_urdf",
    "perturb_inertia",
    "perturb_link",
    "perturb_links",
    "length_factor",
    "sample_plant",
    "sample_plants",
    "MechanismUncertainty",
    "MechanismTolerances",
    "sample_mechanism",
]


#: The relative tolerances of an arm's joint coefficients (:class:`Tolerances`), by the key of
#: :data:`rrr_pin.model.plant.JOINT_DYNAMICS` they perturb, in the order they are drawn.
JOINT_TOLERANCES = ("armature", "damping", "friction")


def _check_tolerances(tol) -> None:
    """Check and store the tolerances of ``tol``: real, in ``[0, 1)`` (frozen record)."""
    for name in ("inertia", "length", *(k for k in JOINT_TOLERANCES if hasattr(tol, k))):
        value = check_real(f"{name} tolerance", getattr(tol, name))
        if not 0.0 <= value < 1.0:
            raise ValueError(f"{name} tolerance must be in [0, 1), got {value!r}")
        object.__setattr__(tol, name, value)


@dataclass(frozen=True)
class Tolerances(UncertaintySet):
    """Relative tolerances of the uncertain plants (paper: 20 % inertia, 5 % lengths).

    The uncertainty set of every kind of plant: an arm's URDF (or DH parameters) is perturbed
    as the module docstring says, a mechanism's parameter set by
    :func:`~rrr_pin.model.mechanisms.perturb_mechanism` (masses and lengths; the rods'
    moments follow).

    Parameters
    ----------
    inertia : float, default 0.2
        On masses and moments of inertia, in ``[0, 1)``.
    length : float, default 0.05
        On link lengths, joint offsets and centre-of-mass positions, in ``[0, 1)``.
    armature : float, default 0
        On each joint's armature (reflected rotor inertia), relative to its nominal value, in
        ``[0, 1)``: a zero nominal armature stays zero (module docstring). Arms only.
    damping : float, default 0
        On each joint's viscous friction (the description's, ``model.damping``), relative to
        the nominal, in ``[0, 1)``. Arms only; it acts through ``--friction urdf``.
    friction : float, default 0
        On each joint's Coulomb friction (``model.friction``), relative to the nominal, in
        ``[0, 1)``. Arms only; it acts through ``--friction urdf``.
    """

    inertia: float = 0.2
    length: float = 0.05
    armature: float = 0.0
    damping: float = 0.0
    friction: float = 0.0

    def __post_init__(self) -> None:
        _check_tolerances(self)

    def describe(self) -> str:
        """One line for reports: ``20% on masses and moments, 5% on lengths``."""
        joints = "".join(f", {getattr(self, k):.0%} on {k}" for k in JOINT_TOLERANCES
                         if getattr(self, k))
        return (f"{self.inertia:.0%} on masses and moments, {self.length:.0%} on lengths"
                + joints)

    def to_dict(self) -> dict:
        """``{"tolerance_inertia", "tolerance_length"}``, as the outputs record them.

        With ``"tolerance_armature"``, ``"tolerance_damping"``, ``"tolerance_friction"``
        where nonzero (a set without them records as it always did: a resume matches).
        """
        return {"tolerance_inertia": self.inertia, "tolerance_length": self.length,
                **{f"tolerance_{k}": getattr(self, k) for k in JOINT_TOLERANCES
                   if getattr(self, k)}}

    def _draws(self, rng: np.random.Generator):
        """Return the generator the factors are drawn from (:class:`ToleranceVertices`: corners)."""
        return rng

    def draw_joint_dynamics(self, values: dict, rng: np.random.Generator
                            ) -> tuple[dict, dict]:
        """Scale each joint's armature, damping and friction by a factor in ``[1 - tol, 1 + tol]``.

        One factor per joint for each coefficient whose tolerance is nonzero, drawn in the
        order of :data:`JOINT_TOLERANCES` (nothing drawn for a zero tolerance). Returns the
        values (shape (nq,) each) and ``{key: factors}`` of those drawn.
        """
        out, factors = dict(values), {}
        draws = self._draws(rng)
        for key in JOINT_TOLERANCES:
            tol = getattr(self, key)
            if tol:
                f = np.asarray(_factor(draws, tol, len(values[key])), dtype=float)
                out[key] = np.asarray(values[key], dtype=float) * f
                factors[key] = f.tolist()
        return out, factors

    def _refuse_joint_tolerances(self) -> None:
        """Refuse joint tolerances for a closed chain (its draws are parameter sets)."""
        given = [k for k in JOINT_TOLERANCES if getattr(self, k)]
        if given:
            raise ValueError(f"{', '.join(f'tolerance {k}' for k in given)}: drawn for serial "
                             f"arms only; a closed chain's uncertain plants perturb its "
                             f"parameter set (masses and lengths)")

    def as_settings(self) -> dict:
        """Return what ``Settings.to_dict`` records of the set: :meth:`to_dict`."""
        return self.to_dict()

    def arm(self, source, rng: np.random.Generator, *, skip_joints=(), name=None
            ) -> tuple[str, dict]:
        """Perturb a DH parameter set (renamed ``name``) or a URDF text; see the module."""
        if isinstance(source, ArmParams):
            params, factors = perturb_params(source, rng, self)
            urdf = urdf_from_params(replace(params, name=name) if name else params)
            return urdf, {"params": params.to_dict(), "factors": factors}
        urdf, factors = perturb_urdf(str(source), rng, self, skip_joints=skip_joints)
        return urdf, {"factors": factors}

    def draw_arm(self, robot, rng: np.random.Generator, *, name=None):
        """Return the arm of :meth:`arm` drawn straight into its model, and its parameters.

        The same draws as :meth:`arm` (:func:`perturb_params`, or :func:`perturb_link` and
        :func:`length_factor` per URDF link and joint, in document order), the same factors
        recorded; the numbers the URDF would carry go to
        :meth:`rrr_pin.model.dynamics.Robot.drawn` instead of into text, which is written only
        when asked for (from the same draws, by :meth:`arm`).

        A subclass that overrides :meth:`arm` gets None (its own text route): this route
        draws what :meth:`arm` of this class draws, and nothing else.

        Raises
        ------
        RobotModelError (a ValueError)
            A drawn inertial that is not physical, naming the link, or a singular arm.
        """
        if type(self).arm is not Tolerances.arm:
            return None
        state = rng.bit_generator.state  # to write the URDF from the same draws, if asked
        amap = robot.arm_map()
        origins, inertials = {}, {}
        if robot.params is not None:
            params, factors = perturb_params(robot.params, rng, self)
            parameters = {"params": params.to_dict(), "factors": factors}
            xyz = np.zeros(3)
            for i, link in enumerate(params.links, start=1):
                origins[f"joint{i}"] = xyz  # urdf_from_params: the joints and inertials
                xyz, _, com = dh_link_frame(link)
                inertials[f"link{i}"] = (link.mass, com, np.diag(link.J),
                                         amap.inertials[f"link{i}"].R)
            origins["ee_joint"] = xyz
        else:
            skip, links, joints = set(robot.locked), {}, {}
            names = list(amap.inertials)
            noms = [amap.inertials[link] for link in names]
            drawn = perturb_links([(nom.mass, nom.I, nom.com) for nom in noms], rng, self)
            try:
                check_inertials([d[0] for d in drawn], [d[1] for d in drawn],
                                [f"link {link!r} of the drawn arm" for link in names])
            except ValueError as exc:
                raise RobotModelError(str(exc)) from None
            for link, nom, (m, I, c, links[link]) in zip(names, noms, drawn, strict=True):
                inertials[link] = (m, c, I, nom.R)
            for joint in amap.joints:
                f_l = length_factor(rng, self)
                if joint.name in skip or not joint.has_origin:
                    continue
                origins[joint.name] = joint.xyz * f_l
                joints[joint.name] = f_l
            parameters = {"factors": {"links": links, "joints": joints}}

        def write() -> str:
            bit_generator = type(rng.bit_generator)()
            bit_generator.state = state
            source = robot.params if robot.params is not None else robot.urdf
            return self.arm(source, np.random.Generator(bit_generator),
                            skip_joints=tuple(robot.locked), name=name)[0]

        return robot.drawn(origins, inertials, write=write, name=name), parameters

    def mechanism(self, params, rng: np.random.Generator) -> tuple[object, dict]:
        """``perturb_mechanism(params, rng, inertia, length)``: masses and lengths.

        Raises
        ------
        ValueError
            A nonzero armature, damping or friction tolerance (arms only).
        """
        self._refuse_joint_tolerances()
        return perturb_mechanism(params, rng, self.inertia, self.length)


class _CornerDraws:
    """A generator whose ``uniform(low, high)`` returns ``low`` or ``high`` (even odds).

    Hands :class:`ToleranceVertices` the perturbation code of :class:`Tolerances` unchanged,
    every factor moved from inside its interval to one of its two ends.
    """

    def __init__(self, rng: np.random.Generator):
        self._rng = rng

    def uniform(self, low=0.0, high=1.0, size=None):
        pick = self._rng.random(size) < 0.5
        return np.where(pick, low, high) if size is not None else float(low if pick
                                                                         else high)


@dataclass(frozen=True)
class ToleranceVertices(Tolerances):
    """Corners of the tolerance box: every factor at ``1 - tol`` or ``1 + tol``.

    The same perturbation as :class:`Tolerances` (masses, principal second moments, lengths),
    each factor drawn at one end of its interval with even odds instead of uniformly inside
    it: a seeded sample of the box's ``2^N`` vertices (``N`` factors: 5 per link of a DH arm,
    so 32768 for the RRR, too many to enumerate), where worst cases of a multilinear
    dependence lie.

    Parameters
    ----------
    inertia, length : float
        As :class:`Tolerances`.
    """

    def describe(self) -> str:
        """One line for reports."""
        return f"vertices of {super().describe()}"

    def to_dict(self) -> dict:
        """Return :meth:`Tolerances.to_dict` with ``"draw": "vertices"``."""
        return {**super().to_dict(), "draw": "vertices"}

    def _draws(self, rng: np.random.Generator):
        """Return a generator drawing every joint coefficient's factor at a corner too."""
        return _CornerDraws(rng)

    def arm(self, source, rng: np.random.Generator, *, skip_joints=(), name=None
            ) -> tuple[str, dict]:
        """Perturb as :meth:`Tolerances.arm`, every factor at a corner."""
        return super().arm(source, _CornerDraws(rng), skip_joints=skip_joints, name=name)

    def mechanism(self, params, rng: np.random.Generator) -> tuple[object, dict]:
        """Perturb as :meth:`Tolerances.mechanism`, every factor at a corner."""
        return super().mechanism(params, _CornerDraws(rng))


@dataclass(frozen=True)
class PlantSample:
    """One uncertain plant: where it came from and its URDF text.

    Attributes
    ----------
    index : int
        Sample number ``k``.
    seed : list of int
        ``[s, k]``, the seed of ``numpy.random.default_rng`` that made it.
    urdf : str
        URDF text of the plant.
    parameters : dict
        JSON-ready description of the perturbation (the ``ArmParams`` of the RRR, or the
        factors applied to each link and joint of a URDF).
    """

    index: int
    seed: list
    urdf: str
    parameters: dict

    def write(self, folder: str | Path, stem: str = "plant") -> Path:
        """Write the URDF as ``folder/<stem>_<index:03d>.urdf``; return the path."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{stem}_{self.index:03d}.urdf"
        with writing(path):  # a full disk names the file
            path.write_text(self.urdf)
        return path


def _factor(rng: np.random.Generator, tol: float, size=None):
    return rng.uniform(1.0 - tol, 1.0 + tol, size=size)


def perturb_link(mass: float, I, com, rng: np.random.Generator, tol: Tolerances
                 ) -> tuple[float, np.ndarray | None, np.ndarray, dict]:
    """Draw one URDF link's factors and apply them (:func:`perturb_urdf`, one link).

    The draws, in order: the mass factor, three second-moment factors, the centre-of-mass
    factor. Both routes of an uncertain arm call it (:func:`perturb_urdf` and
    :mod:`rrr_pin.model.drawn`), so they draw the same numbers and mean the same thing.

    Parameters
    ----------
    mass : float
        Nominal mass [kg].
    I : ndarray, shape (3, 3), or None
        Nominal inertia in the inertial's frame [kg m^2], physically valid (checked where it
        was read); None for none.
    com : ndarray, shape (3,)
        Nominal centre of mass (the inertial's origin) [m].
    rng : numpy.random.Generator
    tol : Tolerances

    Returns
    -------
    mass : float
    I : ndarray, shape (3, 3), or None
        :func:`perturb_inertia` of ``I``.
    com : ndarray, shape (3,)
    factors : dict
        ``{"mass", "second_moments", "com"}``, as :func:`perturb_urdf` records them.
    """
    return perturb_links([(mass, I, com)], rng, tol)[0]


def _link_factors(rng: np.random.Generator, tol: Tolerances) -> tuple:
    """One link's draws, in order: the mass factor, three second-moment factors, the com's."""
    return (float(_factor(rng, tol.inertia)), _factor(rng, tol.inertia, 3),
            float(_factor(rng, tol.length)))


def perturb_links(nominals, rng: np.random.Generator, tol: Tolerances) -> list[tuple]:
    """:func:`perturb_link` of several links, in order: the same draws and numbers.

    The draws are made link by link as :func:`perturb_link` makes them; the inertias are then
    scaled together (:func:`_perturb_inertias`, the same operations on a stack).

    Parameters
    ----------
    nominals : sequence of (mass, I, com)
        Per link as :func:`perturb_link` takes them (``I`` a (3, 3) array or None).
    rng : numpy.random.Generator
    tol : Tolerances

    Returns
    -------
    list of (mass, I, com, factors)
        Per link, what :func:`perturb_link` returns.
    """
    draws = [_link_factors(rng, tol) for _ in nominals]
    with_I = [k for k, (_, I, _) in enumerate(nominals) if I is not None]
    inertias = [None] * len(nominals)
    if with_I:
        stack = _perturb_inertias(np.array([nominals[k][1] for k in with_I], dtype=float),
                                  np.array([draws[k][1] for k in with_I]))
        for k, I in zip(with_I, stack, strict=True):
            inertias[k] = I
    return [(mass * f_m, I, np.asarray(com, dtype=float) * f_c,
             {"mass": f_m, "second_moments": f_s.tolist(), "com": f_c})
            for (mass, _, com), (f_m, f_s, f_c), I in zip(nominals, draws, inertias,
                                                          strict=True)]


def length_factor(rng: np.random.Generator, tol: Tolerances) -> float:
    """Draw one joint origin's length factor (:func:`perturb_urdf`, one joint)."""
    return float(_factor(rng, tol.length))


def perturb_inertia(I: np.ndarray, factors) -> np.ndarray:
    """Scale the principal second moments of an inertia tensor.

    Parameters
    ----------
    I : array-like, shape (3, 3)
        Inertia tensor about the centre of mass [kg m^2] (symmetric, physically valid).
    factors : array-like, shape (3,)
        Positive factors on the principal second moments ``S = tr(I)/2 1 - I``.

    Returns
    -------
    ndarray, shape (3, 3)
        ``tr(S') 1 - S'`` with ``S' = R diag(f * s) R^T``: positive semi-definite and
        satisfying the triangle inequality whenever ``I`` does.

    Raises
    ------
    ValueError
        ``I`` is not a physical inertia (:func:`rrr_pin.model.dh.check_inertial`), or a factor is
        not finite and > 0.
    """
    _, I = check_inertial(None, I, name="I")
    factors = check_vector("factors", factors, 3)
    if not np.all(factors > 0.0):
        raise ValueError(f"factors must be 3 finite numbers > 0, got {factors.tolist()}")
    return _perturb_inertia(I, factors)


def _perturb_inertia(I, factors) -> np.ndarray:
    """:func:`perturb_inertia` without the checks, for inertias checked where they were read."""
    return _perturb_inertias(np.asarray(I, dtype=float)[None], np.asarray(factors)[None])[0]


def _perturb_inertias(I: np.ndarray, factors: np.ndarray) -> np.ndarray:
    """:func:`_perturb_inertia` of a stack, shapes (k, 3, 3) and (k, 3): each the same numbers.

    numpy applies every operation to each matrix of the stack as to a single one (LAPACK's
    eigensolver per matrix, the same products and sums), so the result does not depend on
    the stack (``tests/test_uncertainty.py`` checks it bit for bit).
    """
    I = 0.5 * (I + np.swapaxes(I, -1, -2))
    S = 0.5 * np.trace(I, axis1=-2, axis2=-1)[:, None, None] * np.eye(3) - I
    s, R = np.linalg.eigh(S)
    # I is checked: second moments below zero are round-off within INERTIA_RTOL; drop them.
    s = np.clip(s, 0.0, None) * factors
    S_new = (R * s[:, None, :]) @ np.swapaxes(R, -1, -2)
    return np.trace(S_new, axis1=-2, axis2=-1)[:, None, None] * np.eye(3) - S_new


def perturb_params(params: ArmParams, rng: np.random.Generator,
                   tol: Tolerances = Tolerances()) -> tuple[ArmParams, dict]:
    """Perturb a DH parameter set (masses, principal moments, lengths with ``lg``).

    Returns
    -------
    params : ArmParams
        The perturbed, validated parameter set.
    factors : dict
        The factors drawn, per link: ``mass``, ``second_moments`` (3), ``length``.
    """
    # the draws link by link (mass, 3 second moments, length), then the inertias together
    draws = [_link_factors(rng, tol) for _ in params.links]
    # link.J was checked by DHLink; the perturbed link needs no check again (DHLink.scaled).
    Js = _perturb_inertias(np.array([np.diag(link.J) for link in params.links], dtype=float),
                           np.array([f_s for _, f_s, _ in draws]))
    links, factors = [], []
    for link, (f_m, f_s, f_l), J in zip(params.links, draws, Js, strict=True):
        links.append(link.scaled(f_m, np.diag(J).tolist(), f_l))
        factors.append({"mass": f_m, "second_moments": f_s.tolist(), "length": f_l})
    return params.with_links(links), {"links": factors}


@lru_cache(maxsize=8)
def _check_nominal(urdf: str) -> None:
    """Check the inertials of a nominal URDF, once per distinct text.

    A campaign perturbs the same nominal for every sample; the cache remembers the last texts
    that passed (a text that fails raises, so is not cached), and the check of each perturbed
    plant is never skipped.
    """
    from .urdf_checks import check_urdf_inertials

    check_urdf_inertials(urdf)


def perturb_urdf(urdf: str, rng: np.random.Generator, tol: Tolerances = Tolerances(),
                 *, skip_joints=()) -> tuple[str, dict]:
    """Perturb the inertials and geometry of any URDF (read and written with yourdfpy).

    Every link with an ``<inertial>`` gets a mass factor and three second-moment factors
    (:func:`perturb_inertia`, in the inertial's own frame) and its centre of mass scaled by a
    length factor; every joint origin's translation is scaled by a length factor.

    Parameters
    ----------
    urdf : str
        URDF text.
    rng : numpy.random.Generator
        Seeded generator.
    tol : Tolerances
        Relative tolerances.
    skip_joints : iterable of str
        Joints whose origins stay nominal (e.g. locked gripper fingers).

    Returns
    -------
    urdf : str
        The perturbed URDF text.
    factors : dict
        ``links``: name -> ``{mass, second_moments, com}``; ``joints``: name -> length factor.

    Raises
    ------
    RobotModelError (a ValueError)
        An inertial of ``urdf``, or of the plant, that is not physical, naming the link
        (:func:`rrr_pin.model.urdf_checks.check_urdf_inertials`).
    """
    import yourdfpy

    from .urdf_checks import check_urdf_inertials

    _check_nominal(urdf)  # perturb physical bodies only
    robot = yourdfpy.URDF.load(io.BytesIO(urdf.encode()), build_scene_graph=False,
                               load_meshes=False, filename_handler=yourdfpy.filename_handler_null,
                               build_collision_scene_graph=False, load_collision_meshes=False)
    skip = set(skip_joints)
    link_factors, joint_factors = {}, {}
    for link in robot.robot.links:
        inertial = link.inertial
        if inertial is None or inertial.mass is None:
            continue
        origin = np.eye(4) if inertial.origin is None else np.array(inertial.origin, float)
        # the inertia was checked above (_check_nominal)
        inertial.mass, inertial.inertia, origin[:3, 3], link_factors[link.name] = perturb_link(
            float(inertial.mass), inertial.inertia, origin[:3, 3], rng, tol)
        inertial.origin = origin
    for joint in robot.robot.joints:
        f_l = length_factor(rng, tol)
        if joint.name in skip or joint.origin is None:
            continue
        origin = np.array(joint.origin, dtype=float)
        origin[:3, 3] *= f_l
        joint.origin = origin
        joint_factors[joint.name] = f_l
    text = robot.write_xml_string()
    if isinstance(text, bytes):
        text = text.decode()
    check_urdf_inertials(text)  # the plant written is physical too
    return text, {"links": link_factors, "joints": joint_factors}


def sample_plants(nominal, count: int, seed: int = 0, tol: Tolerances = Tolerances(),
                  *, skip_joints=()) -> list[PlantSample]:
    """Draw ``count`` uncertain plants around a nominal arm.

    Parameters
    ----------
    nominal : ArmParams or str
        A DH parameter set (perturbed with :func:`perturb_params`, its URDF generated) or the
        URDF text of any arm (perturbed with :func:`perturb_urdf`).
    count : int
        Number of plants, >= 0.
    seed : int, default 0
        Study seed; sample ``k`` uses ``default_rng([seed, k])``.
    tol : Tolerances or IdentifiedUncertainty
        Relative tolerances (default 20 % inertia, 5 % lengths), or the distribution of an
        identification (see the module docstring).
    skip_joints : iterable of str
        For URDF input: joints whose origins stay nominal.

    Returns
    -------
    list of PlantSample
    """
    count, seed = check_count("count", count), check_count("seed", seed)
    return [sample_plant(nominal, seed, k, tol, skip_joints=skip_joints) for k in range(count)]


def sample_plant(nominal, seed: int, index: int, tol: Tolerances = Tolerances(),
                 *, skip_joints=()) -> PlantSample:
    """Plant number ``index`` of a study with ``seed``, drawn alone (see :func:`sample_plants`).

    ``sample_plant(nominal, s, k)`` equals ``sample_plants(nominal, n, s)[k]`` for any ``n > k``.
    """
    rng = np.random.default_rng([int(seed), int(index)])
    name = f"{nominal.name}_sample{index:03d}" if isinstance(nominal, ArmParams) else None
    urdf, parameters = tol.arm(nominal, rng, skip_joints=skip_joints, name=name)
    return PlantSample(index=int(index), seed=[int(seed), int(index)], urdf=urdf,
                       parameters=parameters)


class MechanismUncertainty(UncertaintySet):
    """How an uncertain parallel mechanism is drawn: subclass it to write your own.

    A subclass is a frozen dataclass (it crosses process boundaries and is recorded whole in
    a campaign's settings) with two methods:

    * ``draw(params, rng) -> (params, factors)``: a perturbed, closable parameter set of the
      same type as ``params`` (:class:`~rrr_pin.model.mechanisms.FiveBarParams` or
      :class:`~rrr_pin.model.mechanisms.DeltaParams`) and a JSON-ready dict of what was drawn;
      it must use only ``rng`` (a seeded :class:`numpy.random.Generator`) for randomness;
    * ``to_dict() -> dict``: JSON-ready settings, recorded in the outputs (a resume must
      match them).
    """

    def draw(self, params, rng: np.random.Generator):
        """Return ``(perturbed params, factors)`` drawn with ``rng``."""
        raise NotImplementedError(f"{type(self).__name__} must implement draw(params, rng)")

    def to_dict(self) -> dict:
        """JSON-ready settings of the uncertainty set."""
        raise NotImplementedError(f"{type(self).__name__} must implement to_dict()")

    def mechanism(self, params, rng: np.random.Generator) -> tuple[object, dict]:
        """:meth:`draw`, checked to return a parameter set of the type of ``params``."""
        out, factors = self.draw(params, rng)
        if type(out) is not type(params):
            raise TypeError(f"{type(self).__name__}.draw returned a {type(out).__name__}, "
                            f"expected a {type(params).__name__}")
        return out, factors


@dataclass(frozen=True)
class MechanismTolerances(MechanismUncertainty):
    """The built-in uncertainty of a mechanism: uniform factors on masses and lengths.

    Every mass by a factor in ``[1 - inertia, 1 + inertia]`` and every length in
    ``[1 - length, 1 + length]`` (:func:`rrr_pin.model.mechanisms.perturb_mechanism`; the
    rods' moments of inertia follow from mass and length), redrawn until the loop closes.

    Parameters
    ----------
    inertia : float, default 0.2
        Relative tolerance on the masses, in ``[0, 1)``.
    length : float, default 0.05
        Relative tolerance on the lengths, in ``[0, 1)``.
    """

    inertia: float = 0.2
    length: float = 0.05

    def __post_init__(self) -> None:
        _check_tolerances(self)

    def draw(self, params, rng: np.random.Generator):
        """Return ``perturb_mechanism(params, rng, inertia, length)``."""
        return perturb_mechanism(params, rng, self.inertia, self.length)

    def to_dict(self) -> dict:
        """``{"uncertainty": "MechanismTolerances", "tolerance_inertia", "tolerance_length"}``."""
        return {"uncertainty": "MechanismTolerances", "tolerance_inertia": self.inertia,
                "tolerance_length": self.length}

    def describe(self) -> str:
        """One line for reports: ``20% on masses, 5% on lengths (rod moments follow)``."""
        return (f"{self.inertia:.0%} on masses, {self.length:.0%} on lengths (rod moments "
                f"follow)")


def sample_mechanism(nominal, seed: int, index: int,
                     tol: MechanismUncertainty = MechanismTolerances()):
    """Uncertain mechanism number ``index`` of a campaign with ``seed``, drawn alone.

    ``tol.draw(nominal, numpy.random.default_rng([seed, index]))``.

    Parameters
    ----------
    nominal : FiveBarParams or DeltaParams
        Nominal parameter set.
    seed, index : int
        Campaign seed and sample number, >= 0.
    tol : MechanismUncertainty, default MechanismTolerances()

    Returns
    -------
    params : FiveBarParams or DeltaParams
        The plant's parameters.
    factors : dict
        What ``tol`` drew (for the built-in: field name -> factor).

    Raises
    ------
    TypeError
        ``nominal`` not a mechanism parameter set, ``tol`` not a MechanismUncertainty, or a
        draw of another type than ``nominal``.
    """
    if not is_mechanism_params(nominal):
        raise TypeError(f"nominal must be a mechanism's parameter set (e.g. FiveBarParams), "
                        f"got {type(nominal).__name__}")
    if not isinstance(tol, MechanismUncertainty):
        raise TypeError(f"tol must be a MechanismUncertainty (e.g. MechanismTolerances()), got "
                        f"{type(tol).__name__}")
    rng = np.random.default_rng([check_count("seed", seed), check_count("index", index)])
    return tol.mechanism(nominal, rng)

"""Denavit-Hartenberg parameter sets with inertial data, and DH forward kinematics.

Conventions (used everywhere in rrr-pin):

* Standard (distal) DH: the transform from frame ``i-1`` to frame ``i`` is
  ``Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)`` with ``theta_i = q_i + theta_offset_i``.
* SI units: metres, radians, kilograms, kg m^2, seconds.
* Gravity of magnitude ``g`` points along ``-z`` of the base frame (frame 0).
* Link ``i`` runs from the origin of frame ``i-1`` (joint ``i``) to the origin of frame ``i``;
  its length is ``l_i = sqrt(a_i**2 + d_i**2)`` and its centre of mass lies on that segment at
  distance ``lg_i`` from its start (the paper's ``lg_i``).
* The principal moments ``(Jx, Jy, Jz)`` of link ``i`` are about its centre of mass, along the
  axes of DH frame ``i``. This is how the paper's Table 2 reads: ``D11`` contains ``Jy1``, the
  moment about the joint-1 axis, and ``y1`` is exactly that axis because ``alpha_1 = pi/2``.

References
----------
.. [1] The paper: "H-infinity control + feedback linearization of a 3-DOF RRR spatial serial
   mechanism", Tables 1 and 2.
.. [2] J. J. Craig, *Introduction to Robotics*, 3rd ed., 2005 (DH conventions).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from ..validation import check_positive, check_real

__all__ = [
    "DHLink",
    "ArmParams",
    "paper_params",
    "dh_transform",
    "forward_kinematics",
    "check_inertial",
    "check_inertials",
    "inertials_ok",
    "check_robot_name",
    "INERTIA_RTOL",
]

#: Relative slack [-] allowed on the physical-validity checks of an inertia tensor (positive
#: semi-definite, triangle inequality of principal moments), relative to the largest principal
#: moment. Bodies that sit exactly on a bound are common (a thin rod has ``Jx = 0``,
#: ``Jy = Jz``, as in the paper's Table 2), and URDF exporters print about 6 significant digits,
#: which moves such a body off the bound by up to ~1e-6 relative; 1e-6 accepts that round-off
#: and nothing a real body could not have.
INERTIA_RTOL = 1e-6


def check_inertial(mass, inertia, *, name: str = "inertial") -> tuple[float, np.ndarray]:
    r"""Check that a mass and an inertia tensor describe a physical rigid body.

    The inertia tensor ``I`` about the centre of mass of a body with mass density ``rho >= 0``
    is ``I = tr(S) 1 - S`` with ``S = integral of x x^T dm`` positive semi-definite, so its
    principal moments ``J_1, J_2, J_3`` (eigenvalues) satisfy

    .. math:: J_k \ge 0, \qquad J_k \le J_i + J_j \quad (\{i, j, k\} = \{1, 2, 3\}),

    and a massless body has ``I = 0``.

    Parameters
    ----------
    mass : float or None
        Mass [kg]; finite and ``>= 0``. ``None`` checks the tensor alone.
    inertia : array-like, shape (3, 3)
        Inertia tensor about the centre of mass [kg m^2], in any frame; finite and symmetric.
    name : str
        What is checked, for the messages (e.g. ``"link 'link2'"``).

    Returns
    -------
    mass : float or None
    inertia : ndarray, shape (3, 3)

    Raises
    ------
    ValueError
        Naming ``name``, the field and the value: non-finite or negative mass, wrong shape,
        non-finite or asymmetric tensor, a negative principal moment or one above the sum of
        the other two (beyond :data:`INERTIA_RTOL` of the largest), or a massless body with
        nonzero inertia.
    """
    if mass is not None:
        mass = check_positive(f"{name}: mass", mass, allow_zero=True, unit="kg")
    try:
        inertia = np.array(inertia, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: inertia must be a 3x3 array of numbers [kg m^2], got "
                         f"{inertia!r}") from None
    if inertia.shape != (3, 3):
        raise ValueError(f"{name}: Expected inertia of shape (3, 3), got {inertia.shape}")
    if not np.isfinite(inertia).all():
        raise ValueError(f"{name}: inertia must be finite [kg m^2], got {inertia.tolist()}")
    scale = float(np.abs(inertia).max())
    if mass == 0.0:
        if scale > 0.0:
            raise ValueError(f"{name}: a massless body (mass 0 kg) must have zero inertia, got "
                             f"{inertia.tolist()} kg m^2")
        return mass, inertia
    if np.abs(inertia - inertia.T).max() > INERTIA_RTOL * scale:
        raise ValueError(f"{name}: inertia must be symmetric, got {inertia.tolist()} kg m^2")
    J = np.linalg.eigvalsh(0.5 * (inertia + inertia.T))
    tol = INERTIA_RTOL * max(float(J.max()), 0.0)
    if J.min() < -tol:
        raise ValueError(f"{name}: inertia is not positive semi-definite: principal moments "
                         f"({_moments(J)}) kg m^2")
    if J.max() > J.sum() - J.max() + tol:
        raise ValueError(f"{name}: inertia violates the triangle inequality: the largest "
                         f"principal moment {J.max():.6g} exceeds the sum of the other two "
                         f"{J.sum() - J.max():.6g} (principal moments ({_moments(J)}) kg m^2); "
                         f"no rigid body has it")
    return mass, inertia


def _moments(J) -> str:
    return ", ".join(f"{v:.6g}" for v in J)


def check_inertials(masses, inertias, names) -> None:
    """:func:`check_inertial` of many bodies at once (the same tests, vectorized).

    The first body that fails a test is checked again alone by :func:`check_inertial`, which
    raises its message.

    Parameters
    ----------
    masses : array-like, shape (k,)
        Masses [kg].
    inertias : array-like, shape (k, 3, 3)
        Inertia tensors about the centres of mass [kg m^2].
    names : sequence of str, length k
        What each body is, for the message.

    Raises
    ------
    ValueError
        As :func:`check_inertial`, for the first body that fails.
    """
    if len(names) != len(masses):
        raise ValueError(f"check_inertials needs one name per body, got {len(names)} names for "
                         f"{len(masses)} bodies")
    for k in np.flatnonzero(~inertials_ok(masses, inertias)):
        check_inertial(masses[k], inertias[k], name=names[k])


def inertials_ok(masses, inertias) -> np.ndarray:
    """Return which bodies pass the tests of :func:`check_inertial`, vectorized.

    Parameters
    ----------
    masses : array-like, shape (k,)
        Masses [kg].
    inertias : array-like, shape (k, 3, 3)
        Inertia tensors about the centres of mass [kg m^2].

    Returns
    -------
    ndarray of bool, shape (k,)
    """
    m = np.asarray(masses, dtype=float)
    inertia = np.asarray(inertias, dtype=float)
    if inertia.shape != (len(m), 3, 3):
        raise ValueError(f"inertials_ok needs k masses and (k, 3, 3) inertias, got {m.shape} "
                         f"and {inertia.shape}")
    finite = np.isfinite(m) & np.isfinite(inertia).all(axis=(-1, -2))
    inertia = np.where(finite[:, None, None], inertia, 0.0)
    T = np.swapaxes(inertia, -1, -2)
    scale = np.abs(inertia).max(axis=(-1, -2), initial=0.0)
    J = np.linalg.eigvalsh(0.5 * (inertia + T))
    top = J.max(axis=-1, initial=-np.inf)
    tol = INERTIA_RTOL * np.maximum(top, 0.0)
    body = ((np.abs(inertia - T).max(axis=(-1, -2), initial=0.0) <= INERTIA_RTOL * scale)
            & (J.min(axis=-1, initial=np.inf) >= -tol) & ~(top > J.sum(axis=-1) - top + tol))
    return finite & (m >= 0.0) & np.where(m == 0.0, scale == 0.0, body)


@dataclass(frozen=True)
class DHLink:
    """One link of a serial arm: its DH row and its inertial data.

    Parameters
    ----------
    a : float
        Link length along ``x_i`` [m].
    alpha : float
        Link twist about ``x_i`` [rad].
    d : float
        Link offset along ``z_{i-1}`` [m].
    mass : float
        Link mass [kg], > 0.
    lg : float
        Distance from the start of the link (joint ``i``) to its centre of mass, measured along
        the segment to the next joint [m], in ``[0, l]`` with ``l = sqrt(a**2 + d**2)``.
    J : tuple of 3 floats
        Principal moments of inertia ``(Jx, Jy, Jz)`` about the centre of mass, along the axes of
        DH frame ``i`` [kg m^2]; non-negative and satisfying the triangle inequality.
    theta_offset : float, default 0
        Constant added to the joint angle: ``theta_i = q_i + theta_offset`` [rad].
    lower, upper : float, default -pi, pi
        Joint limits [rad].
    effort : float, default 1000
        Torque limit written into the URDF [N m] (not enforced by the simulation).
    velocity : float, default 20
        Speed limit written into the URDF [rad/s] (not enforced by the simulation).

    Raises
    ------
    ValueError
        Naming the field and value, for NaN/inf, non-positive mass or length, ``lg`` outside
        ``[0, l]``, negative moments, moments violating the triangle inequality, or
        ``lower >= upper``.
    """

    a: float
    alpha: float
    d: float
    mass: float
    lg: float
    J: tuple[float, float, float]
    theta_offset: float = 0.0
    lower: float = -math.pi
    upper: float = math.pi
    effort: float = 1000.0
    velocity: float = 20.0

    def __post_init__(self) -> None:
        units = {"a": "m", "alpha": "rad", "d": "m", "mass": "kg", "lg": "m",
                 "theta_offset": "rad", "lower": "rad", "upper": "rad", "effort": "N m",
                 "velocity": "rad/s"}
        for name, unit in units.items():
            check = check_positive if name in ("mass", "effort", "velocity") else check_real
            object.__setattr__(self, name, check(name, getattr(self, name), unit=unit))
        if isinstance(self.J, (str, bytes, dict)) or not hasattr(self.J, "__len__"):
            raise ValueError(f"J must be a list of 3 principal moments (Jx, Jy, Jz) [kg m^2], "
                             f"got {self.J!r} ({type(self.J).__name__})")
        if len(self.J) != 3:
            raise ValueError(f"J must hold 3 principal moments (Jx, Jy, Jz), got {len(self.J)}")
        J = tuple(check_positive(f"J{axis}", v, allow_zero=True, unit="kg m^2")
                  for axis, v in zip("xyz", self.J, strict=True))
        object.__setattr__(self, "J", J)
        if self.length <= 0.0:
            raise ValueError(
                f"link length sqrt(a**2 + d**2) must be > 0 m, got a={self.a!r}, d={self.d!r}")
        if not 0.0 <= self.lg <= self.length * (1.0 + 1e-12):
            raise ValueError(f"lg must lie in [0, l] = [0, {self.length!r}] m, got {self.lg!r}")
        scale = max(max(J), 1e-300)
        for k, axis in enumerate("xyz"):
            others = [J[j] for j in range(3) if j != k]
            if J[k] > sum(others) + INERTIA_RTOL * scale:
                raise ValueError(
                    f"J{axis} = {J[k]!r} violates the triangle inequality of principal moments "
                    f"(must be <= the sum of the other two, {sum(others)!r})")
        if self.lower >= self.upper:
            raise ValueError(f"joint limits must satisfy lower < upper, got lower="
                             f"{self.lower!r} rad, upper={self.upper!r} rad")

    def scaled(self, mass_factor: float, J, length_factor: float) -> DHLink:
        """Return this link with its mass and lengths scaled and other principal moments.

        ``mass * mass_factor``, ``a``, ``d`` and ``lg`` times ``length_factor``, ``J`` as given:
        an uncertain arm's draw (:func:`rrr_pin.model.uncertainty.perturb_params`). The checks
        of :class:`DHLink` are not run again, because they hold for the result whenever they
        hold for this link: both factors are > 0 (so the mass stays > 0 and ``lg / l`` is
        unchanged up to round-off, inside the ``lg <= l`` check's 1e-12), and ``J``, the
        principal moments of :func:`~rrr_pin.model.uncertainty.perturb_inertia` of this
        link's, are >= 0 and satisfy the triangle inequality by construction.

        Parameters
        ----------
        mass_factor, length_factor : float
            In ``(0, 2)`` (``1 +- tolerance``).
        J : tuple of 3 float
            Principal moments [kg m^2].
        """
        new = object.__new__(DHLink)
        new.__dict__.update(self.__dict__)
        new.__dict__.update(mass=self.mass * mass_factor, J=tuple(J),
                            a=self.a * length_factor, d=self.d * length_factor,
                            lg=self.lg * length_factor)
        return new

    @property
    def length(self) -> float:
        """Link length ``l = sqrt(a**2 + d**2)`` [m]."""
        return math.hypot(self.a, self.d)

    def com(self) -> np.ndarray:
        """Centre of mass in DH frame ``i``, shape (3,) [m].

        The link's start (origin of frame ``i-1``) seen from frame ``i`` is
        ``-Rx(alpha)^T (a, 0, d)``; the centre of mass lies ``lg / l`` of the way from there to
        the origin of frame ``i``.
        """
        ca, sa = math.cos(self.alpha), math.sin(self.alpha)
        # Origin of frame i-1 expressed in frame i: p = -(Rx(alpha)^T) [a, 0, d]^T.
        start = -np.array([self.a, sa * self.d, ca * self.d])
        return start * (1.0 - self.lg / self.length)


@dataclass(frozen=True)
class ArmParams:
    """A fixed-base serial arm of revolute joints described by a DH table with inertial data.

    Parameters
    ----------
    links : tuple of DHLink
        One entry per joint, base to tip.
    g : float, default 9.8
        Gravity magnitude [m/s^2], along ``-z`` of the base frame (the paper uses 9.8).
    name : str, default "rrr"
        Robot name, used as the URDF ``<robot name>``.
    """

    links: tuple[DHLink, ...]
    g: float = 9.8
    name: str = "rrr"
    notes: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if isinstance(self.links, (str, bytes, dict)) or not hasattr(self.links, "__iter__"):
            raise ValueError(f"links must be a list of links, got {self.links!r} "
                             f"({type(self.links).__name__})")
        links = tuple(self.links)
        if not links:
            raise ValueError("links must hold at least one DHLink")
        for k, link in enumerate(links):
            if not isinstance(link, DHLink):
                raise ValueError(f"links[{k}] must be a DHLink, got {type(link).__name__}")
        object.__setattr__(self, "links", links)
        object.__setattr__(self, "g", check_positive("g", self.g, allow_zero=True, unit="m/s^2"))
        check_robot_name(self.name)
        if not isinstance(self.notes, str):
            raise ValueError(f"notes must be a string, got {self.notes!r} "
                             f"({type(self.notes).__name__})")

    @property
    def n(self) -> int:
        """Number of joints."""
        return len(self.links)

    # The paper's symbols, as arrays of shape (n,).
    @property
    def m(self) -> np.ndarray:
        """Masses ``m_i`` [kg], shape (n,)."""
        return np.array([link.mass for link in self.links])

    @property
    def l(self) -> np.ndarray:  # noqa: E743 - the paper's symbol
        """Link lengths ``l_i`` [m], shape (n,)."""
        return np.array([link.length for link in self.links])

    @property
    def lg(self) -> np.ndarray:
        """Centre-of-mass distances ``lg_i`` [m], shape (n,)."""
        return np.array([link.lg for link in self.links])

    @property
    def J(self) -> np.ndarray:
        """Principal moments, shape (n, 3), columns ``Jx, Jy, Jz`` [kg m^2]."""
        return np.array([link.J for link in self.links])

    def with_links(self, links) -> ArmParams:
        """Return a copy with other links (same ``g`` and ``name``)."""
        return replace(self, links=tuple(links))

    def to_dict(self) -> dict:
        """Plain-JSON dictionary of the parameter set."""
        return {"name": self.name, "g": self.g, "notes": self.notes,
                # the fields are numbers and the tuple J: no deep copy needed (dataclasses.asdict)
                "links": [{f.name: (list(link.J) if f.name == "J" else getattr(link, f.name))
                           for f in fields(link)} for link in self.links]}

    @classmethod
    def from_dict(cls, data: dict) -> ArmParams:
        """Build from :meth:`to_dict` output (the parameter-file validator).

        Raises
        ------
        ValueError
            Naming the field (e.g. ``links[1].mass``) and its value: not a mapping, unknown or
            missing keys, ``links`` not a list, ``null``, booleans or strings where numbers
            belong, and every check of :class:`DHLink` and :class:`ArmParams`.
        """
        if not isinstance(data, dict):
            raise ValueError(f"parameter data must be a JSON object with a 'links' list, got "
                             f"{type(data).__name__}")
        if "links" not in data:
            raise ValueError("parameter data lacks the field 'links' (a list of links)")
        known = {"name", "g", "notes", "links"}
        extra = set(data) - known
        if extra:
            raise ValueError(f"unknown parameter keys: {sorted(extra)}; expected {sorted(known)}")
        rows = data["links"]
        if not isinstance(rows, list):
            raise ValueError(f"links must be a list of link objects, got {rows!r} "
                             f"({type(rows).__name__})")
        fields = [f.name for f in dataclasses.fields(DHLink)]
        required = [f.name for f in dataclasses.fields(DHLink)
                    if f.default is dataclasses.MISSING]
        links = []
        for k, row in enumerate(rows):
            if not isinstance(row, dict):
                raise ValueError(f"links[{k}] must be an object with the fields {fields}, got "
                                 f"{row!r}")
            unknown = sorted(set(row) - set(fields))
            if unknown:
                raise ValueError(f"links[{k}]: unknown fields {unknown}; expected {fields}")
            missing = [key for key in required if key not in row]
            if missing:
                raise ValueError(f"links[{k}] lacks the fields {missing}")
            try:
                links.append(DHLink(**row))
            except ValueError as exc:
                raise ValueError(f"links[{k}]: {exc}") from None
        kwargs = {key: data[key] for key in ("g", "name", "notes") if key in data}
        return cls(links=tuple(links), **kwargs)

    def save(self, path: str | Path) -> None:
        """Write the parameter set to a JSON file."""
        Path(path).write_text(json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> ArmParams:
        """Read a parameter set from a JSON file written by :meth:`save`.

        Raises
        ------
        FileNotFoundError
            No such file.
        ValueError
            Naming the file: a directory, not UTF-8 text, not JSON, or a field refused by
            :meth:`from_dict`.
        """
        path = Path(path)
        if path.is_dir():
            raise ValueError(f"{path}: is a directory; a parameter set is a JSON file")
        if not path.is_file():
            raise FileNotFoundError(f"parameter file not found: {path}")
        try:
            data = json.loads(path.read_bytes().decode("utf-8"))
        except UnicodeDecodeError as exc:
            raise ValueError(f"{path}: not a UTF-8 text file (byte {exc.start}: {exc.reason}); "
                             f"a parameter file is JSON") from None
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: not valid JSON ({exc})") from None
        try:
            return cls.from_dict(data)
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None


def check_robot_name(name) -> str:
    """Check a robot name: a non-empty string of printable characters.

    Any such name is accepted; the URDF generator escapes XML's special characters
    (``& < > "``), so ``"R&D arm"`` gives valid XML. Control characters (newline, tab, NUL...)
    cannot appear in an XML attribute and are refused.

    Raises
    ------
    ValueError
        Naming the value.
    """
    if not isinstance(name, str) or not name:
        raise ValueError(f"name must be a non-empty string, got {name!r}")
    if not name.isprintable():
        raise ValueError(f"name must hold printable characters only (no newline, tab or other "
                         f"control character), got {name!r}")
    return name


def paper_params() -> ArmParams:
    """Return the paper's RRR arm: DH Table 1 with the nominal parameters of Table 2.

    ====  ===  =======  ===  =====  ====  ====  ===================
    i     a    alpha    d    m      l     lg    (Jx, Jy, Jz)
    ====  ===  =======  ===  =====  ====  ====  ===================
    1     0    pi/2     1    20     1     0.75  (1.6667, 1.6667, 0)
    2     1    0        0    20     1     0.75  (0, 1.6667, 1.6667)
    3     1    0        0    5      1     0.5   (0, 0.4167, 0.4167)
    ====  ===  =======  ===  =====  ====  ====  ===================

    Units: m, rad, kg, kg m^2; ``g = 9.8`` m/s^2.
    """
    return ArmParams(
        links=(
            DHLink(a=0.0, alpha=math.pi / 2, d=1.0, mass=20.0, lg=0.75, J=(1.6667, 1.6667, 0.0)),
            DHLink(a=1.0, alpha=0.0, d=0.0, mass=20.0, lg=0.75, J=(0.0, 1.6667, 1.6667)),
            DHLink(a=1.0, alpha=0.0, d=0.0, mass=5.0, lg=0.5, J=(0.0, 0.4167, 0.4167)),
        ),
        g=9.8,
        name="rrr",
        notes="Paper Tables 1 and 2 (standard DH, SI units).",
    )


def dh_transform(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """Homogeneous transform ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``, shape (4, 4)."""
    ct, st = math.cos(theta), math.sin(theta)
    ca, sa = math.cos(alpha), math.sin(alpha)
    return np.array([
        [ct, -st * ca, st * sa, a * ct],
        [st, ct * ca, -ct * sa, a * st],
        [0.0, sa, ca, d],
        [0.0, 0.0, 0.0, 1.0],
    ])


def forward_kinematics(params: ArmParams, q) -> list[np.ndarray]:
    """DH forward kinematics: the placements of frames 0..n in the base frame.

    Parameters
    ----------
    params : ArmParams
        The arm.
    q : array-like, shape (n,)
        Joint angles [rad].

    Returns
    -------
    frames : list of n + 1 arrays, shape (4, 4)
        ``frames[i]`` is ``T_0^i``; ``frames[0]`` is the identity and ``frames[n]`` the tip
        (the URDF frame ``ee``).
    """
    q = np.asarray(q, dtype=float)
    if q.shape != (params.n,):
        raise ValueError(f"Expected q of shape ({params.n},), got {q.shape}")
    frames = [np.eye(4)]
    for link, qi in zip(params.links, q, strict=True):
        frames.append(frames[-1] @ dh_transform(qi + link.theta_offset, link.d, link.a,
                                                link.alpha))
    return frames

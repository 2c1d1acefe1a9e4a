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

import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

__all__ = [
    "DHLink",
    "ArmParams",
    "paper_params",
    "dh_transform",
    "forward_kinematics",
]

#: Relative slack allowed on the triangle inequality of principal moments. The paper's own
#: Table 2 sits exactly on the bound (thin rods, e.g. Jx2 = 0, Jy2 = Jz2), printed to 4 digits.
TRIANGLE_RTOL = 1e-9


def _check_finite(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return value


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
        for name in ("a", "alpha", "d", "mass", "lg", "theta_offset", "lower", "upper",
                     "effort", "velocity"):
            object.__setattr__(self, name, _check_finite(name, getattr(self, name)))
        J = tuple(_check_finite(f"J[{k}]", v) for k, v in enumerate(self.J))
        if len(J) != 3:
            raise ValueError(f"J must hold 3 principal moments (Jx, Jy, Jz), got {len(J)}")
        object.__setattr__(self, "J", J)
        if self.mass <= 0.0:
            raise ValueError(f"mass must be > 0 kg, got {self.mass!r}")
        if self.length <= 0.0:
            raise ValueError(
                f"link length sqrt(a**2 + d**2) must be > 0 m, got a={self.a!r}, d={self.d!r}")
        if not 0.0 <= self.lg <= self.length * (1.0 + 1e-12):
            raise ValueError(f"lg must lie in [0, l] = [0, {self.length!r}] m, got {self.lg!r}")
        for axis, value in zip("xyz", J, strict=True):
            if value < 0.0:
                raise ValueError(f"J{axis} must be >= 0 kg m^2, got {value!r}")
        scale = max(max(J), 1e-300)
        for k, axis in enumerate("xyz"):
            others = [J[j] for j in range(3) if j != k]
            if J[k] > sum(others) + TRIANGLE_RTOL * scale:
                raise ValueError(
                    f"J{axis} = {J[k]!r} violates the triangle inequality of principal moments "
                    f"(must be <= the sum of the other two, {sum(others)!r})")
        if self.lower >= self.upper:
            raise ValueError(f"lower must be < upper, got lower={self.lower!r}, "
                             f"upper={self.upper!r}")
        if self.effort <= 0.0 or self.velocity <= 0.0:
            raise ValueError(f"effort and velocity limits must be > 0, got effort="
                             f"{self.effort!r}, velocity={self.velocity!r}")

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
        links = tuple(self.links)
        if not links:
            raise ValueError("links must hold at least one DHLink")
        for k, link in enumerate(links):
            if not isinstance(link, DHLink):
                raise ValueError(f"links[{k}] must be a DHLink, got {type(link).__name__}")
        object.__setattr__(self, "links", links)
        g = _check_finite("g", self.g)
        if g < 0.0:
            raise ValueError(f"g must be >= 0 m/s^2 (it points along -z), got {g!r}")
        object.__setattr__(self, "g", g)

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
                "links": [{**asdict(link), "J": list(link.J)} for link in self.links]}

    @classmethod
    def from_dict(cls, data: dict) -> ArmParams:
        """Build from :meth:`to_dict` output; unknown keys raise ``ValueError``."""
        if not isinstance(data, dict) or "links" not in data:
            raise ValueError("parameter data must be a mapping with a 'links' list")
        known = {"name", "g", "notes", "links"}
        extra = set(data) - known
        if extra:
            raise ValueError(f"unknown parameter keys: {sorted(extra)}")
        links = []
        for k, row in enumerate(data["links"]):
            try:
                links.append(DHLink(**{**row, "J": tuple(row["J"])}))
            except TypeError as exc:
                raise ValueError(f"links[{k}]: {exc}") from None
            except KeyError as exc:
                raise ValueError(f"links[{k}] lacks the field {exc}") from None
        kwargs = {key: data[key] for key in ("g", "name", "notes") if key in data}
        return cls(links=tuple(links), **kwargs)

    def save(self, path: str | Path) -> None:
        """Write the parameter set to a JSON file."""
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> ArmParams:
        """Read a parameter set from a JSON file written by :meth:`save`."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"parameter file not found: {path}")
        try:
            data = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: not valid JSON ({exc})") from None
        return cls.from_dict(data)


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

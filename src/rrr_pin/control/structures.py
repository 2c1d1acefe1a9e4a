r"""Tunable structures of the feedback-linearizing law: what :func:`rrr_pin.tune` may change.

A structure fixes the SHAPE of the law of eq. (8)-(10) and leaves some numbers free: the FL
bandwidth ``lam`` and the parameters of the outer controller ``K(s)`` on ``e = r - q``
(negative feedback, ``y = K e``). Per joint the law's loop is

.. math:: L(s) = \frac{2\lambda s + \lambda^2 (1 + K(s))}{s^2},

so ``K = 0`` is FL alone (eq. 20) and the paper's order-2 ``K`` (eq. 18) is one
:class:`FixedOrder` point. ``K`` is shared by every joint (copied on the diagonal, as the
paper's); ``lam`` is fixed (a number) or tuned (``lam=None``, inside ``lam_bounds``), shared
by every joint, or tuned per joint by :class:`PerJoint` (``lam="per_joint"``).

Write your own structure by subclassing :class:`Structure`: give ``names``, ``bounds``,
``initial`` and ``K(values)``; :func:`rrr_pin.tune` searches each parameter on a log scale
between its bounds (all parameters are positive).

Built in: :class:`FLOnly` (no ``K``), :class:`Gain`, :class:`PID` (derivative filter),
:class:`LeadLag`, :class:`FixedOrder` (a strictly stable order-``m`` transfer function), and
:class:`LoopShapingWeight` (the paper's synthesis with its weight's ``k, z, p`` free), and
:class:`PerJoint` (any of these once per joint: ``K`` diagonal, each joint its own
parameters; ``lam`` shared, or with ``lam="per_joint"`` one tuned per joint).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..validation import FieldError, check_count, check_positive

__all__ = ["Structure", "FLOnly", "Gain", "PID", "LeadLag", "FixedOrder", "LoopShapingWeight",
           "PerJoint", "PER_JOINT", "STRUCTURES", "make_structure", "LAM_BOUNDS"]

#: Default search range of a tuned ``lam`` [rad/s].
LAM_BOUNDS = (5.0, 500.0)


@dataclass(frozen=True)
class Structure:
    """Base of the tunable structures: ``lam`` (fixed or tuned) and the outer ``K(s)``.

    Parameters
    ----------
    lam : float or None
        FL bandwidth [rad/s]; None: tuned inside ``lam_bounds``.
    lam_bounds : (float, float)
        Search range of a tuned ``lam`` [rad/s].

    Subclasses define ``kind`` (the CLI's name), ``outer_names``, ``outer_bounds``,
    ``outer_initial`` and :meth:`K`.
    """

    lam: float | None = 45.0
    lam_bounds: tuple = LAM_BOUNDS
    kind: ClassVar[str] = ""
    outer_names: ClassVar[tuple] = ()

    def __post_init__(self) -> None:
        if self.lam is not None:
            object.__setattr__(self, "lam", check_positive("lam", self.lam, unit="rad/s"))
        lo, hi = (check_positive("lam_bounds", x, unit="rad/s") for x in self.lam_bounds)
        if not lo <= hi:
            raise FieldError("lam_bounds", f"{{name}} must be (low, high) with low <= high, "
                                           f"got {self.lam_bounds!r}")
        object.__setattr__(self, "lam_bounds", (lo, hi))

    # -- what a subclass gives --------------------------------------------------------------
    def outer_bounds(self) -> list[tuple[float, float]]:
        """Bounds of the outer controller's parameters (positive), one pair per name."""
        return []

    def outer_initial(self) -> list[float]:
        """Return a starting point of the outer controller's parameters."""
        return []

    def K(self, values) -> object:
        """Return ``K(s)`` (``control.TransferFunction``, SISO, continuous) of the values."""
        raise NotImplementedError(f"{type(self).__name__} must implement K(values)")

    def check_joints(self, robot: str, joint_names) -> None:
        """Refuse an arm whose joints the structure does not fit (nothing by default)."""

    # -- derived -------------------------------------------------------------------------------
    @property
    def names(self) -> tuple:
        """Names of the free parameters, ``"lam"`` first when tuned."""
        return (("lam",) if self.lam is None else ()) + tuple(self.outer_names)

    def bounds(self) -> list[tuple[float, float]]:
        """Search bounds of the free parameters (units of each)."""
        return ([self.lam_bounds] if self.lam is None else []) + list(self.outer_bounds())

    def initial(self) -> np.ndarray:
        """Return a starting point inside the bounds, shape (len(names),)."""
        lam0 = [float(np.sqrt(self.lam_bounds[0] * self.lam_bounds[1]))] if self.lam is None \
            else []
        return np.array(lam0 + list(self.outer_initial()), dtype=float)

    def split(self, values) -> tuple[float, object]:
        """Return ``(lam, K)`` of the free parameters ``values``.

        ``K`` None: FL alone; a list: one SISO ``K`` per joint.
        """
        values = list(np.asarray(values, dtype=float))
        lam = values.pop(0) if self.lam is None else self.lam
        return float(lam), self.K(values)

    def to_dict(self, values=None) -> dict:
        """JSON-ready record: kind, fixed ``lam``, bounds and (given ``values``) the parameters."""
        out = {"kind": self.kind, "class": f"{type(self).__module__}.{type(self).__qualname__}",
               "lam_rad_s": self.lam, "lam_bounds_rad_s": list(self.lam_bounds),
               "names": list(self.names), "bounds": [list(b) for b in self.bounds()]}
        if values is not None:
            out["values"] = {k: float(v) for k, v in zip(self.names, values, strict=True)}
        return out


def _tf(num, den):
    import control

    return control.tf(np.asarray(num, dtype=float), np.asarray(den, dtype=float))


@dataclass(frozen=True)
class FLOnly(Structure):
    """Feedback linearization alone, ``K = 0`` (eq. 20): only ``lam`` can be tuned."""

    kind: ClassVar[str] = "fl"

    def K(self, values):
        """No outer controller: None."""
        return None


@dataclass(frozen=True)
class Gain(Structure):
    r"""A static gain, ``K(s) = k``: the law is a PD on ``e`` with stiffness ``lam^2 (1 + k)``.

    Parameters
    ----------
    k_bounds : (float, float)
        Search range of ``k`` [-].
    """

    k_bounds: tuple = (1e-3, 1e3)
    kind: ClassVar[str] = "gain"
    outer_names: ClassVar[tuple] = ("k",)

    def outer_bounds(self):
        """Return the search bounds of the outer parameters."""
        return [tuple(self.k_bounds)]

    def outer_initial(self):
        """Return the starting point of the outer parameters."""
        return [1.0]

    def K(self, values):
        """``k``."""
        return _tf([values[0]], [1.0])


@dataclass(frozen=True)
class PID(Structure):
    r"""PID with a filtered derivative.

    .. math:: K(s) = k_p + \frac{k_i}{s} + \frac{k_d s}{T_f s + 1}

    ``k_p`` [-], ``k_i`` [1/s], ``k_d`` [s], ``T_f`` [s].
    """

    kind: ClassVar[str] = "pid"
    outer_names: ClassVar[tuple] = ("kp", "ki", "kd", "tf")

    def outer_bounds(self):
        """Return the search bounds of the outer parameters."""
        return [(1e-3, 1e3), (1e-3, 1e4), (1e-6, 10.0), (1e-4, 1.0)]

    def outer_initial(self):
        """Return the starting point of the outer parameters."""
        return [1.0, 1.0, 1e-3, 1e-2]

    def K(self, values):
        """``kp + ki/s + kd s/(tf s + 1)`` as one transfer function."""
        kp, ki, kd, tf = values
        # (kp s (tf s + 1) + ki (tf s + 1) + kd s^2) / (s (tf s + 1))
        return _tf([kp * tf + kd, kp + ki * tf, ki], [tf, 1.0, 0.0])


@dataclass(frozen=True)
class LeadLag(Structure):
    r"""A lead or lag compensator with DC gain ``k``.

    .. math:: K(s) = k \frac{s / z + 1}{s / p + 1}

    ``k`` [-], corners ``z`` and ``p`` [rad/s] (``z < p``: lead; ``z > p``: lag, such as the
    paper's weight eq. 16).
    """

    kind: ClassVar[str] = "leadlag"
    outer_names: ClassVar[tuple] = ("k", "z", "p")

    def outer_bounds(self):
        """Return the search bounds of the outer parameters."""
        return [(1e-3, 1e4), (1e-2, 1e4), (1e-2, 1e4)]

    def outer_initial(self):
        """Return the starting point of the outer parameters."""
        return [1.0, 10.0, 100.0]

    def K(self, values):
        """``k (s/z + 1)/(s/p + 1)``."""
        k, z, p = values
        return _tf([k / z, k], [1.0 / p, 1.0])


@dataclass(frozen=True)
class FixedOrder(Structure):
    r"""A biproper, strictly stable transfer function of order ``order`` (paper's eq. 18: 2).

    In second-order sections (one first-order section for an odd order), every coefficient
    positive, so every point of the search is stable and minimum phase:

    .. math:: K(s) = g \prod_i \frac{s^2 + b_{i1} s + b_{i0}}{s^2 + a_{i1} s + a_{i0}}

    Parameters
    ----------
    order : int
        Number of states, >= 1.
    """

    order: int = 2
    kind: ClassVar[str] = "order"

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "order", check_count("order", self.order, 1, high=8))

    @property
    def outer_names(self) -> tuple:
        """Return the outer parameters' names."""
        names = ["g"]
        for i in range(self.order // 2):
            names += [f"b{i}1", f"b{i}0", f"a{i}1", f"a{i}0"]
        if self.order % 2:
            names += ["b0", "a0"]
        return tuple(names)

    def outer_bounds(self):
        """Return the search bounds of the outer parameters."""
        return [(1e-3, 1e4)] + [(1e-3, 1e6)] * (len(self.outer_names) - 1)

    def outer_initial(self):
        """Return the starting point of the outer parameters."""
        # sections (s + 10)^2 / (s + 10)^2: K = g, a static gain to start from
        return [1.0] + [20.0, 100.0, 20.0, 100.0] * (self.order // 2) + \
            [10.0, 10.0] * (self.order % 2)

    def K(self, values):
        """Return the product of the sections times ``g``."""
        g, rest = values[0], list(values[1:])
        num, den = np.array([g]), np.array([1.0])
        for _ in range(self.order // 2):
            b1, b0, a1, a0 = rest[:4]
            rest = rest[4:]
            num, den = np.polymul(num, [1.0, b1, b0]), np.polymul(den, [1.0, a1, a0])
        if self.order % 2:
            b0, a0 = rest
            num, den = np.polymul(num, [1.0, b0]), np.polymul(den, [1.0, a0])
        return _tf(num, den)

    def to_dict(self, values=None) -> dict:
        """Return the JSON-ready record."""
        return {**super().to_dict(values), "order": self.order}


@dataclass(frozen=True)
class LoopShapingWeight(Structure):
    r"""The paper's loop-shaping controller with its weight's parameters free.

    ``K = W1 Ks`` of :func:`~rrr_pin.robust.ncf.ncfsyn` (optimal, ``factor = 1``) on the FL
    plant ``lam^2 / (s + lam)^2`` (eq. 11) shaped by the lag weight (eq. 16)

    .. math:: W_1(s) = \frac{k (s + z)}{s + p},

    full order (the synthesis' own controller, as ``rrr_pin.design(...).K_full``); the paper's
    point is ``k, z, p = 25, 11.5, 0.19`` at ``lam = 45``
    (:data:`rrr_pin.robust.loopshaping.PAPER_W1`). Each evaluation
    runs the synthesis (~30 ms), so a tuning of this structure takes minutes.
    """

    kind: ClassVar[str] = "weight"
    outer_names: ClassVar[tuple] = ("k", "z", "p")

    def outer_bounds(self):
        """Return the search bounds: ``k`` [-], ``z`` and ``p`` [rad/s]."""
        return [(0.1, 1e3), (0.01, 1e3), (1e-3, 100.0)]

    def outer_initial(self):
        """Return the paper's weight, eq. (16)."""
        from ..robust.loopshaping import PAPER_W1

        return list(PAPER_W1)

    def split(self, values):
        """Return ``(lam, K)``: the synthesis needs ``lam`` (its plant is eq. 11's)."""
        values = list(np.asarray(values, dtype=float))
        lam = values.pop(0) if self.lam is None else self.lam
        return float(lam), self._K(float(lam), values)

    def K(self, values):
        """Return ``K`` at the fixed ``lam`` (tuned ``lam``: use :meth:`split`)."""
        if self.lam is None:
            raise ValueError("LoopShapingWeight with a tuned lam: K depends on it, use split")
        return self._K(self.lam, values)

    @staticmethod
    def _K(lam, values):
        import control

        from ..robust.loopshaping import fl_plant, lag_weight
        from ..robust.ncf import ncfsyn

        k, z, p = values
        return control.tf(ncfsyn(fl_plant(lam, 1), lag_weight(k, z, p), np.eye(1), 1.0).K)


#: :class:`PerJoint`'s ``lam`` for one FL bandwidth tuned per joint.
PER_JOINT = "per_joint"


@dataclass(frozen=True)
class PerJoint(Structure):
    r"""One outer controller per joint, each of the shape of ``base``; ``lam`` shared or per joint.

    ``K(s) = diag(K_1(s), ..., K_n(s))``, every ``K_j`` a ``base`` structure with its own
    parameters (named ``<name>@<joint>``). ``lam`` is ``base``'s (shared by every joint, fixed
    or tuned), or with ``lam="per_joint"`` one bandwidth per joint, each tuned inside
    ``base.lam_bounds`` (named ``lam@<joint>``, starting from ``base``'s ``lam`` when fixed):
    the law is then ``taubar = rdd + 2 diag(lam) (rd - qd) + diag(lam)^2 (e + y)``
    (:class:`~rrr_pin.control.laws.TrackingController` with a vector ``lam``).

    Parameters
    ----------
    lam : None or "per_joint"
        None: ``base``'s ``lam`` (shared); ``"per_joint"``: tuned per joint. A shared number
        is given on ``base``.
    base : Structure
        The shape of each joint's controller (its ``lam`` and ``lam_bounds`` are the law's).
        With ``lam="per_joint"``, :class:`FLOnly` too (FL alone, one bandwidth per joint);
        never :class:`LoopShapingWeight` (its synthesis is of one FL plant, eq. 11).
    joints : tuple of str
        The arm's joint names, in order (``robot.joint_names``).
    """

    lam: object = None
    base: Structure = None
    joints: tuple = ()
    kind: ClassVar[str] = "perjoint"

    def __post_init__(self) -> None:
        if not isinstance(self.base, Structure) or isinstance(self.base, PerJoint):
            raise FieldError("structure", f"{{name}}: PerJoint needs a base Structure (gain, "
                                          f"pid, leadlag, orderN), got {self.base!r}")
        if self.lam is not None and self.lam != PER_JOINT:
            raise FieldError("lam", f"{{name}} of PerJoint must be None (the base's, shared) "
                                    f"or {PER_JOINT!r} (tuned per joint); a shared lam is given "
                                    f"on the base structure, got {self.lam!r}")
        per_joint = self.lam == PER_JOINT
        if per_joint and isinstance(self.base, LoopShapingWeight):
            raise FieldError("lam", "{name}: a per-joint lam with the weight structure: its "
                                    "loop-shaping synthesis is of one FL plant (eq. 11), one "
                                    "lam; tune a gain, pid, leadlag or orderN per joint")
        if isinstance(self.base, FLOnly) and not per_joint:
            raise FieldError("structure", "{name}: PerJoint of fl has no outer controller to "
                                          "give each joint (with lam='per_joint' it tunes one "
                                          "lam per joint)")
        joints = tuple(str(j) for j in self.joints)
        if not joints or len(set(joints)) != len(joints):
            raise FieldError("joints", f"{{name}} must be distinct joint names, got "
                                       f"{self.joints!r}")
        object.__setattr__(self, "joints", joints)
        object.__setattr__(self, "lam_bounds", self.base.lam_bounds)
        if per_joint:  # base's lam (each joint's start) and lam_bounds are checked by base
            lo, hi = self.lam_bounds
            if self.base.lam is not None and not lo <= self.base.lam <= hi:
                raise FieldError("lam_start", f"{{name}} = {self.base.lam:g} rad/s, the "
                                              f"start of each joint's lam, is outside the "
                                              f"search range [{lo:g}, {hi:g}] rad/s")
            return
        object.__setattr__(self, "lam", self.base.lam)
        super().__post_init__()

    @property
    def per_joint_lam(self) -> bool:
        """Whether ``lam`` is tuned per joint."""
        return self.lam == PER_JOINT

    @property
    def names(self) -> tuple:
        """Names of the free parameters: ``lam@<joint>`` first when tuned per joint."""
        if not self.per_joint_lam:
            return super().names
        return tuple(f"lam@{j}" for j in self.joints) + tuple(self.outer_names)

    def bounds(self) -> list[tuple[float, float]]:
        """Search bounds of the free parameters (``lam_bounds`` once per joint first)."""
        if not self.per_joint_lam:
            return super().bounds()
        return [self.lam_bounds] * len(self.joints) + list(self.outer_bounds())

    def initial(self) -> np.ndarray:
        """Return a start: per-joint ``lam`` from ``base``'s fixed one (else mid-bounds)."""
        if not self.per_joint_lam:
            return super().initial()
        lo, hi = self.lam_bounds
        lam0 = float(np.clip(self.base.lam, lo, hi)) if self.base.lam is not None \
            else float(np.sqrt(lo * hi))
        return np.array([lam0] * len(self.joints) + list(self.outer_initial()), dtype=float)

    def split(self, values) -> tuple[object, object]:
        """Return ``(lam, K)``: ``lam`` a vector (n,) [rad/s] when tuned per joint."""
        if not self.per_joint_lam:
            return super().split(values)
        values = np.asarray(values, dtype=float)
        n = len(self.joints)
        return values[:n].copy(), self.K(list(values[n:]))

    @property
    def outer_names(self) -> tuple:
        """Return ``<name>@<joint>`` for each joint and each of ``base``'s parameters."""
        return tuple(f"{k}@{j}" for j in self.joints for k in self.base.outer_names)

    def outer_bounds(self):
        """Return ``base``'s bounds, once per joint."""
        return list(self.base.outer_bounds()) * len(self.joints)

    def outer_initial(self):
        """Return ``base``'s starting point, once per joint."""
        return list(self.base.outer_initial()) * len(self.joints)

    def K(self, values):
        """Return the list of the joints' ``K_j`` (SISO, in joint order); None for FL alone."""
        if isinstance(self.base, FLOnly):
            return None
        m = len(self.base.outer_names)
        return [self.base.K(list(values[i * m:(i + 1) * m])) for i in range(len(self.joints))]

    def check_joints(self, robot: str, joint_names) -> None:
        """Refuse an arm with other joints (:class:`FieldError` ``structure``)."""
        if tuple(joint_names) != self.joints:
            raise FieldError("structure", f"{{name}}: per-joint structure on joints "
                                          f"{list(self.joints)}, but {robot} has joints "
                                          f"{list(joint_names)}")

    def to_dict(self, values=None) -> dict:
        """Return the JSON-ready record, with ``base``'s."""
        out = {**super().to_dict(values), "base": self.base.to_dict(),
               "joints": list(self.joints), "lam_per_joint": self.per_joint_lam}
        if self.per_joint_lam:
            out["lam_rad_s"] = None  # tuned, one per joint: the values' lam@<joint>
        return out


#: Built-in structures by CLI name (``order2`` and any ``orderN`` are :class:`FixedOrder`).
STRUCTURES = {"fl": FLOnly, "gain": Gain, "pid": PID, "leadlag": LeadLag, "order": FixedOrder,
              "weight": LoopShapingWeight}


def make_structure(name: str, lam: float | None = 45.0, joints=None,
                   per_joint: bool = False, per_joint_lam: bool = False) -> Structure:
    """Build a built-in structure by name: ``fl``, ``gain``, ``pid``, ``leadlag``, ``orderN``.

    Parameters
    ----------
    name : str
        The structure's name; ``orderN`` is a :class:`FixedOrder` of ``N`` states.
    lam : float or None
        Fixed FL bandwidth [rad/s], or None to tune it.
    joints : sequence of str, optional
        The arm's joint names (needed with ``per_joint``).
    per_joint : bool
        One controller per joint (:class:`PerJoint`) instead of one shared.
    per_joint_lam : bool
        One ``lam`` per joint, tuned (:class:`PerJoint` with ``lam="per_joint"``; implies
        ``per_joint``); ``lam`` is then the start of each.

    Raises
    ------
    FieldError
        ``structure``: an unknown name (the message lists the built-in ones).
    """
    if per_joint or per_joint_lam:
        return PerJoint(base=make_structure(name, lam), joints=tuple(joints or ()),
                        lam=PER_JOINT if per_joint_lam else None)
    if isinstance(name, str) and name.startswith("order") and name[5:].isdigit():
        return FixedOrder(lam=lam, order=int(name[5:]))
    cls = STRUCTURES.get(name) if isinstance(name, str) and name != "order" else None
    if cls is None:
        raise FieldError("structure", f"{{name}}: unknown structure {name!r}; built-in: fl, "
                                      f"gain, pid, leadlag, orderN (e.g. order2), weight")
    return cls(lam=lam)

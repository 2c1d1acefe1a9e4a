r"""Plant-side effects: the unmodeled dynamics of a real arm, composed into one object.

:class:`PlantEffects` lists what a real drive train and its sensors add to the rigid-body model
the laws are designed on. Every effect is off by default; a run with ``effects=None`` (or with
no effect switched on) is the ideal loop of :mod:`rrr_pin.sim.simulation`, bit for bit.

Effects apply to **sampled runs** (digital controllers: ``rate`` given, or a
:class:`~rrr_pin.control.laws.SampledLaw`). A continuous-time law with effects is refused
(``ValueError``): a transport delay or a sensor sampled with noise needs a sampling instant.

Order in the loop, per control period ``[t_k, t_k + Ts)`` (``Ts = 1/rate``)::

    sensor        q_m = Q(q + n_q),  qd_m = qd + n_qd          (noise, encoder quantization)
      -> law      tau_k = law(t_k, q_m, qd_m, r_k, ...)         (zero-order hold)
      -> saturation  tau_k = clip(tau_k, -tau_max, tau_max)
      -> delay    u(t) = tau(t - tau_d)                          (transport delay)
      -> actuator a' = wa (u - a)                                (first order, wa/(s + wa))
      -> [flexible transmission]  motor B th'' = a - s,  s = K (th - q) + D (th' - qd)
      -> arm with friction  M(q) qdd + V + G = s_or_a - (Fv qd + Fc tanh(qd / v_eps))

where ``Q(x) = delta round(x / delta)``, ``delta = 2 pi / counts`` [rad] (round half to even)
and the joint torque is the spring-damper torque ``s`` for a flexible joint, the actuator
output ``a`` otherwise. The law always measures the **link** side.

Discretization (both engines, :mod:`rrr_pin.sim.simulation` and the C++ rollout):

* the arm, the actuator state ``a`` and the motor state ``(th, th')`` are integrated together
  by classical RK4 with the plant sub-step ``h = Ts / substeps`` (``dt``, which must divide
  ``Ts``: :func:`rrr_pin.sim.simulation.time_grid`);
* the delay is realized exactly on that sub-step grid: ``tau_d`` must be a whole number
  ``d`` of sub-steps ``h`` (to a relative 1e-9, :func:`rrr_pin.validation.check_multiple`);
  any other delay is refused, naming ``h`` and the two nearest realizable delays, never
  rounded. The run records ``d`` and ``d h`` (``Trajectory.info["effects"]["delay_substeps"]``,
  ``["delay_s"]``). Choose ``dt`` to divide the delays you need;
* before ``t = 0`` the loop is taken at rest on its first command: the delay line and the
  actuator state hold ``tau_0``; a flexible joint starts with its spring carrying ``tau_0``
  (``th(0) = q(0) + tau_0 / K``, ``th'(0) = qd(0)``);
* noise sequences are drawn in Python from ``numpy.random.default_rng(seed)`` (first ``n_q``,
  shape (N, n), then ``n_qd``), and the same arrays reach both engines, so their runs agree.

Smooth Coulomb friction: ``Fc tanh(qd / v_eps)`` tends to ``Fc sign(qd)`` for
``|qd| >> v_eps`` and is differentiable at rest, so RK4 integrates it without chattering.

References
----------
.. [1] M. W. Spong, "Modeling and control of elastic joint robots", *J. Dyn. Sys. Meas.
   Control* 109 (1987) 310-319 (flexible-joint model: motor and link coupled by a spring).
.. [2] G. F. Franklin, J. D. Powell, M. Workman, *Digital Control of Dynamic Systems*, 3rd ed.,
   1998, sec. 4.3.4 (zero-order hold with a fractional transport delay).
"""

from __future__ import annotations

import inspect
import math
import warnings
from dataclasses import asdict, dataclass, replace

import numpy as np

from ..model.plant import EFFORT_LIMITS, JOINT_FRICTION
from ..validation import FieldError, check_multiple
from .references import checked_sample

__all__ = ["PlantEffects", "Resolved", "EffectsError", "check_effects", "check_torque_limit",
           "peak_torque", "torque_limit_spec", "with_plant_friction"]

class EffectsError(ValueError):
    """Bad plant effects: the message names every bad field, its value and the expected range."""


def _per_joint(value):
    """Return a float, or a tuple of floats (per joint), from a scalar or a sequence."""
    if value is None:
        return None
    if isinstance(value, str):
        return value
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        return float(arr)
    return tuple(float(v) for v in arr.ravel())


@dataclass(frozen=True)
class PlantEffects:
    """Unmodeled dynamics of the simulated arm (all off by default); see the module docstring.

    Parameters
    ----------
    delay : float, default 0
        Transport delay ``tau_d`` [s] >= 0: the torque computed at ``t`` reaches the joints at
        ``t + tau_d``: a whole number of RK4 sub-steps ``h`` of the run (others are refused
        when the run is prepared, :meth:`delay_substeps`).
    actuator_bandwidth : float, optional
        First-order actuator bandwidth ``wa`` [rad/s] > 0: applied = ``wa/(s + wa)`` times the
        commanded torque (``--actuator-bandwidth``). None: ideal actuator. The old keyword
        ``bandwidth=`` and attribute ``bandwidth`` still work, with a ``DeprecationWarning``.
    viscous : "urdf", float or sequence, shape (n,), default 0
        Viscous friction ``Fv`` [N m s/rad] >= 0 per joint; ``"urdf"``: each plant's own
        (its URDF's ``<dynamics damping>``, :meth:`rrr_pin.model.plant.Plant.joint_friction`:
        an identified URDF's, or a plant drawn from an identification's).
    coulomb : "urdf", float or sequence, shape (n,), default 0
        Coulomb friction level ``Fc`` [N m] >= 0 per joint (smooth: ``Fc tanh(qd / v_eps)``);
        ``"urdf"``: each plant's ``<dynamics friction>`` (``viscous`` must be ``"urdf"`` too).
    coulomb_velocity : float, default 0.01
        Smoothing speed ``v_eps`` [rad/s] > 0 of the Coulomb friction.
    torque_limit : "urdf", float or sequence, shape (n,), optional
        Saturation ``|tau| <= tau_max`` [N m] > 0; ``"urdf"``: the URDF effort limits
        (``robot.model.effortLimit``). None: no saturation.
    noise_q : float or sequence, default 0
        Standard deviation [rad] >= 0 of the Gaussian noise on the measured ``q``.
    noise_qd : float or sequence, default 0
        Standard deviation [rad/s] >= 0 of the Gaussian noise on the measured ``qd``.
    encoder_counts : int, optional
        Encoder resolution [counts per revolution] >= 1: ``q`` is measured in steps of
        ``2 pi / counts`` rad. None: exact positions.
    stiffness : float or sequence, optional
        Joint stiffness ``K`` [N m/rad] > 0 of a flexible transmission; None: rigid joints.
    motor_inertia : float or sequence, default 0.01
        Motor-side inertia ``B`` [kg m^2] > 0 (flexible joints only).
    transmission_damping : float or sequence, default 0
        Transmission damping ``D`` [N m s/rad] >= 0 (flexible joints only;
        ``--transmission-damping``, not the joint's own damping of
        :meth:`rrr_pin.model.plant.Plant.joint_friction`). The old keyword and attribute
        ``damping`` still work, with a ``DeprecationWarning``.
    seed : int, default 0
        Seed of the noise sequences, >= 0.
    """

    delay: float = 0.0
    actuator_bandwidth: float | None = None
    viscous: float | tuple = 0.0
    coulomb: float | tuple = 0.0
    coulomb_velocity: float = 0.01
    torque_limit: str | float | tuple | None = None
    noise_q: float | tuple = 0.0
    noise_qd: float | tuple = 0.0
    encoder_counts: int | None = None
    stiffness: float | tuple | None = None
    motor_inertia: float | tuple = 0.01
    transmission_damping: float | tuple = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        errors = []
        for key in ("viscous", "coulomb", "torque_limit", "noise_q", "noise_qd", "stiffness",
                    "motor_inertia", "transmission_damping"):
            try:
                object.__setattr__(self, key, _per_joint(getattr(self, key)))
            except (TypeError, ValueError):
                errors.append(f"{key} = {getattr(self, key)!r}: expected a number or a "
                              f"sequence of numbers")
        specs = {  # field: (lowest, zero allowed, unit)
            "delay": (0.0, True, "s"), "actuator_bandwidth": (0.0, False, "rad/s"),
            "viscous": (0.0, True, "N m s/rad"), "coulomb": (0.0, True, "N m"),
            "coulomb_velocity": (0.0, False, "rad/s"), "torque_limit": (0.0, False, "N m"),
            "noise_q": (0.0, True, "rad"), "noise_qd": (0.0, True, "rad/s"),
            "stiffness": (0.0, False, "N m/rad"), "motor_inertia": (0.0, False, "kg m^2"),
            "transmission_damping": (0.0, True, "N m s/rad"),
        }
        for key, (low, zero_ok, unit) in specs.items():
            v = getattr(self, key)
            if v is None or (key in ("torque_limit", "viscous", "coulomb") and v == "urdf"):
                continue
            if isinstance(v, str) or isinstance(v, bool):
                errors.append(f"{key} = {v!r}: expected a number [{unit}]")
                continue
            vals = v if isinstance(v, tuple) else (v,)
            ok = bool(vals) and all(math.isfinite(x) and (x > low or (zero_ok and x == low))
                                    for x in vals)
            if not ok:
                want = ">= 0" if zero_ok else "> 0"
                errors.append(f"{key} = {v!r}: expected finite {want} [{unit}]")
        if (self.viscous == "urdf") != (self.coulomb == "urdf"):
            errors.append(f"viscous = {self.viscous!r}, coulomb = {self.coulomb!r}: the "
                          f"plant's own friction ('urdf') is both coefficients or neither")
        c = self.encoder_counts
        if c is not None and (isinstance(c, bool) or not isinstance(c, (int, np.integer))
                              or c < 1):
            errors.append(f"encoder_counts = {c!r}: expected an integer >= 1 [counts/rev]")
        s = self.seed
        if isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0:
            errors.append(f"seed = {s!r}: expected an integer >= 0")
        if errors:
            raise EffectsError("bad plant effects: " + "; ".join(errors))

    @property
    def active(self) -> bool:
        """Whether any effect is switched on."""
        return bool(self.delay > 0 or self.actuator_bandwidth is not None or self.friction
                    or self.torque_limit is not None or self.noisy
                    or self.encoder_counts is not None or self.stiffness is not None)

    @property
    def friction(self) -> bool:
        """Whether any friction coefficient is nonzero, or read from each plant (``"urdf"``)."""
        if self.viscous == "urdf":
            return True
        return any(np.any(np.asarray(v) > 0) for v in (self.viscous, self.coulomb))

    @property
    def noisy(self) -> bool:
        """Whether a noise level is nonzero."""
        return any(np.any(np.asarray(v) > 0) for v in (self.noise_q, self.noise_qd))

    def to_dict(self) -> dict:
        """JSON-ready fields (units in the key names)."""
        d = asdict(self)
        units = {"delay": "delay_s", "actuator_bandwidth": "actuator_bandwidth_rad_s",
                 "viscous": "viscous_Nms",
                 "coulomb": "coulomb_Nm", "coulomb_velocity": "coulomb_velocity_rad_s",
                 "torque_limit": "torque_limit_Nm", "noise_q": "noise_q_rad",
                 "noise_qd": "noise_qd_rad_s", "encoder_counts": "encoder_counts",
                 "stiffness": "stiffness_Nm_rad", "motor_inertia": "motor_inertia_kgm2",
                 "transmission_damping": "transmission_damping_Nms", "seed": "seed"}
        return {units[k]: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}

    def delay_substeps(self, h: float) -> int:
        """Return the delay as a whole number of plant sub-steps ``h`` [s], or refuse it.

        Raises
        ------
        rrr_pin.validation.FieldError
            ``delay`` is not a multiple of ``h`` (to a relative 1e-9): the message names the
            delay, ``h`` and the two nearest realizable delays.
        """
        return check_multiple("delay", self.delay, h, unit="s",
                              step_name="plant sub-steps h")

    def resolve(self, plant, substeps: int, h: float, n_steps: int) -> Resolved:
        """Per-joint arrays for a run of ``n_steps`` control periods on ``plant`` (engines' input).

        Raises
        ------
        EffectsError
            A per-joint field of the wrong length, a URDF without effort limits, or a sub-step
            ``h`` too large for the actuator bandwidth or the joint resonance (RK4).
        rrr_pin.validation.FieldError
            A delay that is not a whole number of sub-steps ``h`` (:meth:`delay_substeps`).
        """
        n = plant.nq

        def vec(key, value):
            arr = np.asarray(value, dtype=float)
            if arr.ndim == 0:
                return np.full(n, float(arr))
            if arr.shape != (n,):
                raise EffectsError(f"{key}: expected one value or {n} (one per joint), got "
                                   f"{arr.size}")
            return arr.copy()

        d = self.delay_substeps(h)
        limit = None
        if self.torque_limit == "urdf":
            if not plant.has(EFFORT_LIMITS):
                raise EffectsError(f"torque_limit = 'urdf': {plant.describe_kind()} "
                                   f"{plant.name!r} has no URDF effort limits; give the limit "
                                   f"[N m] per actuated joint ({', '.join(plant.joint_names)})")
            limit = plant.effort_limits()
            if limit.shape != (n,) or not np.all(limit > 0):
                raise EffectsError(f"torque_limit = 'urdf': the URDF of {plant.name!r} has "
                                   f"effort limits {limit.tolist()}, expected > 0 per joint")
        elif self.torque_limit is not None:
            limit = vec("torque_limit", self.torque_limit)
        wa = float(self.actuator_bandwidth) if self.actuator_bandwidth is not None else 0.0
        # RK4's stability interval on the negative real axis ends at -2.785.
        if wa * h > 2.5:
            raise EffectsError(f"actuator_bandwidth = {wa:g} rad/s is too fast for the plant "
                               f"sub-step h = {h:g} s (RK4 needs wa h < 2.5): lower dt")
        Bm = Kf = Df = None
        if self.stiffness is not None:
            Kf = vec("stiffness", self.stiffness)
            Bm = vec("motor_inertia", self.motor_inertia)
            Df = vec("transmission_damping", self.transmission_damping)
            w = float(np.max(np.sqrt(Kf / Bm)))
            if w * h > 2.5:
                raise EffectsError(f"stiffness: the motor resonance sqrt(K/B) = {w:.4g} rad/s "
                                   f"is too fast for the plant sub-step h = {h:g} s (RK4 needs "
                                   f"sqrt(K/B) h < 2.5): lower dt")
        Fv = Fc = None
        veps = 1.0
        if self.viscous == "urdf":
            if not plant.has(JOINT_FRICTION):
                raise EffectsError(f"friction 'urdf': {plant.describe_kind()} {plant.name!r} "
                                   f"has no joint friction in its description; give the "
                                   f"coefficients per joint ({', '.join(plant.joint_names)})")
            Fv, Fc = plant.joint_friction()
            if not (np.any(Fv != 0.0) or np.any(Fc != 0.0)):
                raise EffectsError(f"friction 'urdf': {plant.describe_kind()} {plant.name!r} "
                                   f"has no joint friction in its description (every "
                                   f"damping and friction is 0 or absent), so the run would "
                                   f"have none; give the coefficients per joint "
                                   f"({', '.join(plant.joint_names)}), e.g. "
                                   f"viscous=V,coulomb=C")
            bad = [f"{j}: viscous {v:g}, coulomb {c:g}" for j, v, c in
                   zip(plant.joint_names, Fv, Fc, strict=True) if not (v >= 0.0 and c >= 0.0)]
            if bad:
                raise EffectsError(f"friction 'urdf' of {plant.name!r}: negative coefficients "
                                   f"({'; '.join(bad)}); friction opposes the motion")
            veps = float(self.coulomb_velocity)
        elif self.friction:
            Fv, Fc = vec("viscous", self.viscous), vec("coulomb", self.coulomb)
            veps = float(self.coulomb_velocity)
        if Fv is not None and np.any(Fv > 0):
            # Viscous friction is a damper Fv on the joint's inertia: RK4's stability on the
            # negative real axis needs h times the fastest rate of M(q)^-1 diag(Fv) below 2.5
            # (checked at the neutral configuration). The smooth Coulomb term is as stiff only
            # for |qd| < v_eps and bounded beyond: a chatter of that size, not a blow-up.
            M = plant.terms(np.clip(plant.neutral(), plant.lower, plant.upper),
                            np.zeros(n))[0]
            rate = float(np.max(np.abs(np.linalg.eigvals(np.linalg.solve(M, np.diag(Fv))))))
            if rate * h > 2.5:
                raise EffectsError(
                    f"viscous friction damps {plant.name!r} at {rate:.4g} 1/s (M^-1 Fv at the "
                    f"neutral configuration), too fast for the plant sub-step h = {h:g} s "
                    f"(RK4 needs rate h < 2.5): lower dt below {2.5 / rate:.3g} s")
        rng = np.random.default_rng(self.seed)
        sq, sqd = vec("noise_q", self.noise_q), vec("noise_qd", self.noise_qd)
        nq = rng.standard_normal((n_steps, n)) * sq if np.any(sq > 0) else None
        nqd = rng.standard_normal((n_steps, n)) * sqd if np.any(sqd > 0) else None
        quantum = 2.0 * math.pi / self.encoder_counts if self.encoder_counts else 0.0
        info = {**self.to_dict(), "delay_s": d * h, "delay_substeps": d}
        if self.viscous == "urdf":  # the values this plant's description gave
            where = ("MJCF <joint damping frictionloss>" if _own_friction_source(plant)
                     == "mjcf" else "URDF <dynamics>")
            info.update(viscous_Nms=Fv.tolist(), coulomb_Nm=Fc.tolist(),
                        friction_source=f"{where} of {plant.name!r}")
        return Resolved(delay_steps=d, wa=wa, limit=limit, Fv=Fv, Fc=Fc, veps=veps, noise_q=nq,
                        noise_qd=nqd, quantum=quantum, Bm=Bm, Kf=Kf, Df=Df, info=info)


_UNSET = object()
_plant_effects_init = PlantEffects.__init__
#: Old field names of :class:`PlantEffects` (deprecated) and the names that replaced them, as
#: the command line spells them (``--actuator-bandwidth``, ``--transmission-damping``).
_RENAMED = {"bandwidth": "actuator_bandwidth", "damping": "transmission_damping"}


def _init_with_old_names(self, *args, **kwargs):
    """``PlantEffects(bandwidth=..., damping=...)``: the names before the renames (deprecated)."""
    fields = list(inspect.signature(_plant_effects_init).parameters)[1:]
    for old, new in _RENAMED.items():
        if old not in kwargs:
            continue
        if new in kwargs or fields.index(new) < len(args):
            raise TypeError(f"PlantEffects: give {new} or its old name {old}, not both")
        warnings.warn(f"PlantEffects({old}=...) is deprecated: the field is {new}, as "
                      f"--{new.replace('_', '-')} spells it", DeprecationWarning, stacklevel=2)
        kwargs[new] = kwargs.pop(old)
    _plant_effects_init(self, *args, **kwargs)


def _old_name(old: str, new: str) -> property:
    def get(self):
        warnings.warn(f"PlantEffects.{old} is deprecated: use {new}", DeprecationWarning,
                      stacklevel=2)
        return getattr(self, new)
    get.__doc__ = f"Return ``{new}`` under its old name (deprecated)."
    return property(get)


_init_with_old_names.__signature__ = inspect.signature(_plant_effects_init)
_init_with_old_names.__doc__ = _plant_effects_init.__doc__
PlantEffects.__init__ = _init_with_old_names
for _old, _new in _RENAMED.items():
    setattr(PlantEffects, _old, _old_name(_old, _new))


@dataclass(frozen=True, eq=False)
class Resolved:
    """The effects of one run as both engines take them: validated, per joint, None when off.

    Made by :meth:`PlantEffects.resolve`. Each field but ``info`` has a namesake in the compiled
    engine's ``Effects`` (``src/rrr_pin/_ext/effects.hpp``), which
    :func:`rrr_pin.sim.extension.effects_struct` fills by name for the compiled and batched
    engines; a new effect is a field here, its check in :meth:`PlantEffects.resolve`, its
    step in the Python engine and its step in C++.

    Attributes
    ----------
    delay_steps : int
        Transport delay in plant sub-steps ``h``, >= 0.
    wa : float
        Actuator bandwidth [rad/s]; 0: ideal actuator.
    limit : ndarray, shape (n,), or None
        Saturation ``tau_max`` [N m].
    Fv, Fc : ndarray, shape (n,), or None
        Viscous [N m s/rad] and Coulomb [N m] friction (both or neither).
    veps : float
        Coulomb smoothing speed ``v_eps`` [rad/s] > 0.
    noise_q, noise_qd : ndarray, shape (N, n), or None
        Sensor noise per control step [rad], [rad/s].
    quantum : float
        Encoder step [rad]; 0: exact positions.
    Bm, Kf, Df : ndarray, shape (n,), or None
        Flexible joints: motor inertia [kg m^2], stiffness [N m/rad], damping [N m s/rad] (all
        three or none).
    info : dict
        What the run records (``Trajectory.info["effects"]``): the settings, with the delay as
        realized (``delay_s = delay_substeps h``).
    """

    delay_steps: int
    wa: float
    limit: np.ndarray | None
    Fv: np.ndarray | None
    Fc: np.ndarray | None
    veps: float
    noise_q: np.ndarray | None
    noise_qd: np.ndarray | None
    quantum: float
    Bm: np.ndarray | None
    Kf: np.ndarray | None
    Df: np.ndarray | None
    info: dict

    @property
    def friction(self) -> tuple | None:
        """``(Fv, Fc, v_eps)``, or None without friction."""
        return (self.Fv, self.Fc, self.veps) if self.Fv is not None else None

    @property
    def flex(self) -> tuple | None:
        """``(B, K, D)`` of flexible joints, or None for rigid ones."""
        return (self.Bm, self.Kf, self.Df) if self.Kf is not None else None

    # --- the effects' steps, shared by the Python engines (serial arm and closed chain) ------
    def measure(self, k: int, q, qd) -> tuple[np.ndarray, np.ndarray]:
        """Return what the law reads at control step ``k``: ``(Q(q + n_q), qd + n_qd)``.

        ``q, qd`` shape (n,) [rad, rad/s]: the measured (actuated) joints.
        """
        qm, qdm = q, qd
        if self.noise_q is not None:
            qm = qm + self.noise_q[k]
        if self.quantum:
            qm = self.quantum * np.rint(qm / self.quantum)
        if self.noise_qd is not None:
            qdm = qdm + self.noise_qd[k]
        return qm, qdm

    def saturate(self, tau) -> np.ndarray:
        """``clip(tau, -tau_max, tau_max)`` [N m], shape (n,); ``tau`` itself without a limit."""
        if self.limit is None:
            return tau
        return np.minimum(np.maximum(tau, -self.limit), self.limit)

    def applied(self, U, k: int, s: int, substeps: int) -> np.ndarray:
        """Return the command [N m] reaching the actuator on sub-step ``s`` of period ``k``.

        ``U`` shape (>= k + 1, n): the (saturated) commands so far. The delay line is
        ``delay_steps`` sub-steps long and holds ``U[0]`` before ``t = 0``.
        """
        j = k * substeps + s - self.delay_steps
        return U[j // substeps] if j >= 0 else U[0]

    def start(self, q, qd, u0) -> tuple:
        """Return the actuator and motor states ``(a, th, thd)`` at ``t = 0``, at rest on ``u0``.

        Each is None when its effect is off.
        """
        a = u0.copy() if self.wa else None
        th = thd = None
        if self.Kf is not None:
            th, thd = q + u0 / self.Kf, qd.copy()
        return a, th, thd

    def drive(self, q, qd, a, th, thd, u) -> tuple:
        """Return the joint torque [N m] and the effects' state derivatives, command ``u``.

        Returns ``(tau_joint, a', th'')``: the torque the drive train puts on the joints at
        ``(q, qd)`` (actuator output or spring-damper torque, minus friction), and the
        derivatives of the actuator state and of the motor velocity (None when off).
        """
        tm = a if self.wa else u
        thdd = None
        if self.Kf is not None:
            tj = self.Kf * (th - q) + self.Df * (thd - qd)
            thdd = (tm - tj) / self.Bm
        else:
            tj = tm
        if self.Fv is not None:
            tj = tj - (self.Fv * qd + self.Fc * np.tanh(qd / self.veps))
        ad = self.wa * (u - a) if self.wa else None
        return tj, ad, thdd

    def rk4(self, accel, q, qd, a, th, thd, u, h: float, act=None) -> tuple:
        """Take one classical RK4 step ``h`` [s] of the plant and the effects' states.

        Parameters
        ----------
        accel : callable
            ``accel(q, qd, tau_joint) -> qdd``: the plant's forward dynamics (Pinocchio's ABA
            for an arm, ``constraintDynamics`` for a closed chain, with ``tau_joint`` on the
            actuated joints).
        q, qd : ndarray
            Plant state [rad, rad/s] (every coordinate of a closed chain).
        a, th, thd : ndarray, shape (n,), or None
            Actuator output, motor angle and velocity (:meth:`start`).
        u : ndarray, shape (n,)
            Command held over the step (:meth:`applied`).
        act : sequence of int, optional
            Indices of the actuated (driven, measured) coordinates in ``q``; None: all.

        Returns
        -------
        tuple
            ``(q, qd, a, th, thd)`` at the end of the step.
        """
        wa, h2, h6 = self.wa, 0.5 * h, h / 6.0

        def f(q, qd, a, th, thd):
            tj, ad, thdd = (self.drive(q, qd, a, th, thd, u) if act is None
                            else self.drive(q[act], qd[act], a, th, thd, u))
            return accel(q, qd, tj), ad, thdd

        a1, b1, c1 = f(q, qd, a, th, thd)
        v2 = qd + h2 * a1
        a2s = a + h2 * b1 if wa else None
        th2, w2 = (th + h2 * thd, thd + h2 * c1) if th is not None else (None, None)
        a2, b2, c2 = f(q + h2 * qd, v2, a2s, th2, w2)
        v3 = qd + h2 * a2
        a3s = a + h2 * b2 if wa else None
        th3, w3 = (th + h2 * w2, thd + h2 * c2) if th is not None else (None, None)
        a3, b3, c3 = f(q + h2 * v2, v3, a3s, th3, w3)
        v4 = qd + h * a3
        a4s = a + h * b3 if wa else None
        th4, w4 = (th + h * w3, thd + h * c3) if th is not None else (None, None)
        a4, b4, c4 = f(q + h * v3, v4, a4s, th4, w4)
        q = q + h6 * (qd + 2.0 * (v2 + v3) + v4)
        qd = qd + h6 * (a1 + 2.0 * (a2 + a3) + a4)
        if wa:
            a = a + h6 * (b1 + 2.0 * (b2 + b3) + b4)
        if th is not None:
            th = th + h6 * (thd + 2.0 * (w2 + w3) + w4)
            thd = thd + h6 * (c1 + 2.0 * (c2 + c3) + c4)
        return q, qd, a, th, thd


def _own_friction_source(plant) -> str | None:
    """``"mjcf"`` when the plant's damping or friction came from its MJCF, else None."""
    sources = plant.joint_sources or {}
    return "mjcf" if "mjcf" in (sources.get("damping"), sources.get("friction")) else None


def with_plant_friction(plant, effects: PlantEffects | None, sampled: bool
                        ) -> tuple[PlantEffects | None, dict | None]:
    """Return the effects of a run with the plant's own friction, and what the run records.

    A plant whose description is a simulator's (an MJCF arm: ``plant.joint_sources`` says
    ``"mjcf"``) carries its joints' damping and friction loss as part of the arm, as MuJoCo
    applies them. Every run on it applies them as the friction effect, with the plant's values
    (``viscous="urdf", coulomb="urdf"``: ``Fv qd + Fc tanh(qd / v_eps)``), unless:

    * the effects already name a friction (numbers, or the plant's own): they are kept, and the
      record says they replace the description's;
    * the law is continuous-time (effects need a sampling instant): nothing is applied, and the
      record and a warning (``UserWarning``, once per message) say so.

    A plant without such friction (a URDF's ``<dynamics>`` is applied only when asked, with
    ``--friction urdf``) returns ``effects`` unchanged and no record.

    Parameters
    ----------
    plant : Plant
    effects : PlantEffects or None
        Checked, active effects (or None).
    sampled : bool
        Whether the law is sampled (effects apply).

    Returns
    -------
    effects : PlantEffects or None
    record : dict or None
        ``Trajectory.info["plant_friction"]``: ``applied`` (bool), ``source``, the plant's
        ``damping_Nms_rad`` and ``frictionloss_Nm`` per joint, and ``note`` in words.
    """
    if _own_friction_source(plant) is None:
        return effects, None
    Fv, Fc = plant.joint_friction()
    if not (np.any(Fv > 0) or np.any(Fc > 0)):
        return effects, None
    record = {"source": "mjcf", "damping_Nms_rad": Fv.tolist(), "frictionloss_Nm": Fc.tolist()}
    if not sampled:
        note = (f"not applied: the damping and friction loss of {plant.name!r} act as the "
                f"friction effect, which needs a sampled law (give rate=)")
        warnings.warn(note, UserWarning, stacklevel=2)  # once per message (Python's filter)
        return effects, {**record, "applied": False, "note": note}
    if effects is not None and effects.friction:
        if effects.viscous == "urdf":
            note = "applied: the plant's own (the effects' friction 'urdf')"
        else:
            note = (f"replaced: the run's friction effect (viscous {effects.viscous}, coulomb "
                    f"{effects.coulomb}) instead of the MJCF's damping and friction loss")
        return effects, {**record, "applied": effects.viscous == "urdf", "note": note}
    base = effects if effects is not None else PlantEffects()
    effects = replace(base, viscous="urdf", coulomb="urdf")
    return effects, {**record, "applied": True,
                     "note": f"applied: the MJCF's damping and friction loss as the friction "
                             f"effect Fv qd + Fc tanh(qd / {effects.coulomb_velocity:g})"}


def check_effects(effects) -> PlantEffects | None:
    """Return ``effects`` if it is None or a :class:`PlantEffects`; ``TypeError`` otherwise."""
    if effects is None or isinstance(effects, PlantEffects):
        return effects
    raise TypeError(f"effects must be a rrr_pin.PlantEffects or None, got "
                    f"{type(effects).__name__}")


def check_torque_limit(robot, value="urdf", reference=None, *,
                       name: str = "torque_limit") -> np.ndarray:
    """Return actuator limits ``tau_max`` [N m] per joint, checked: finite, > 0, one per joint.

    With a ``reference``, each limit must also hold the arm still where the reference starts:
    ``tau_max_j >= |G_j(r(0))|`` on ``robot`` (below it the arm cannot even carry its own weight).

    Parameters
    ----------
    robot : Robot
        The arm (``n = robot.nq`` joints); its URDF effort limits for ``"urdf"``, its gravity
        torque ``G(q)`` for the check against the reference.
    value : "urdf", float or array-like, shape (n,)
        The limits; a scalar is every joint's.
    reference : Reference, optional
        Check the limits against the gravity torque at ``r(0)``.
    name : str, default "torque_limit"
        The field, for the message.

    Returns
    -------
    ndarray, shape (n,)
        The limits [N m] (read-only).

    Raises
    ------
    rrr_pin.validation.FieldError
        Naming the field and the value: not numbers, NaN or inf, <= 0, the wrong size, a URDF
        without effort limits, or a limit below the gravity torque at the reference's start
        (naming the joint, the limit and the torque).
    """
    n = robot.nq
    if isinstance(value, str) and value == "urdf":
        if not robot.has(EFFORT_LIMITS):
            raise FieldError(name, f"{{name}} = 'urdf' reads the effort limits of a URDF, and "
                                   f"{robot.describe_kind()} {robot.name!r} carries none (an "
                                   f"MJCF motor has no effort limit); give the limits [N m] "
                                   f"(a number or one per actuated joint: "
                                   f"{', '.join(robot.joint_names)})")
        arr = robot.effort_limits()
        if arr.shape != (n,) or not np.all(np.isfinite(arr) & (arr > 0)):
            raise FieldError(name, f"{{name}} = 'urdf': the URDF of {robot.name!r} has effort "
                                   f"limits {arr.tolist()}, expected finite > 0 per joint [N m]")
    else:
        try:
            if value is None or isinstance(value, (str, bool)):
                raise TypeError
            arr = np.array(value, dtype=float)
        except (TypeError, ValueError):
            raise FieldError(name, f"{{name}} = {value!r}: expected 'urdf', a number or {n} "
                                   f"numbers (one per joint) [N m]") from None
        shown = arr.tolist()
        if arr.ndim == 0 or arr.shape == (1,):  # one value: every joint's
            arr = np.full(n, float(arr.ravel()[0]))
        if arr.shape != (n,):
            raise FieldError(name, f"{{name}} = {shown}: expected one value or {n} (one "
                                   f"per joint), got {arr.size}")
        if not np.all(np.isfinite(arr) & (arr > 0)):
            raise FieldError(name, f"{{name}} = {shown}: expected finite > 0 per joint [N m]")
    if reference is not None:
        r0 = checked_sample(reference, np.zeros(1))[0][0]
        g = np.abs(robot.G(r0))
        below = np.flatnonzero(arr < g)
        if below.size:
            j = below[0]
            raise FieldError(name, (
                f"{{name}} of joint {robot.joint_names[j]!r} is {arr[j]:.6g} N m, below the "
                f"gravity torque {g[j]:.6g} N m at the reference's start r(0) = "
                f"{np.round(r0, 6).tolist()} rad: the arm cannot even hold itself there"))
    arr.setflags(write=False)
    return arr


def peak_torque(robot, reference, t) -> np.ndarray:
    r"""Peak torque [N m] per joint the reference asks of ``robot``: its inverse dynamics.

    .. math:: \tau_{peak, j} = \max_k |(M(r) \ddot r + V(r, \dot r) + G(r))_j|(t_k)

    Parameters
    ----------
    robot : Robot
        The arm (a law's nominal model).
    reference : Reference
    t : array-like, shape (N,)
        Times [s] (e.g. a run's control instants).

    Returns
    -------
    ndarray, shape (n,)
    """
    R, RD, RDD = checked_sample(reference, np.asarray(t, dtype=float))
    tau = np.array([robot.inverse_dynamics(R[k], RD[k], RDD[k], check=False)
                    for k in range(len(R))])
    return np.max(np.abs(tau), axis=0)


def torque_limit_spec(plant, spec: str, reference, rate, duration: float, *,
                      name: str = "torque_limit") -> tuple[np.ndarray, dict]:
    """Return the actuator limits [N m] a text names, and how they were chosen (the rule).

    Parameters
    ----------
    plant : Plant
        The nominal plant (its description's effort limits, its inverse dynamics, its gravity).
    spec : str
        ``"auto"``: the description's effort limits (a URDF's; refused for a plant without
        them, a closed chain's MJCF); ``"P%"``: P percent of the peak torque the reference asks
        of the nominal plant per joint, its inverse dynamics
        ``M(r) rdd + V(r, rd) + G(r)`` in actuated coordinates over the control instants of a
        run of ``duration`` [s] at ``rate`` [Hz] (:func:`peak_torque`); or one number, or one
        per joint, separated by commas [N m].
    reference : Reference
    rate : float or None
        Control rate [Hz]: a limit acts on sampled controllers only (None is refused).
    duration : float
        Length of the run [s].
    name : str
        How the caller spells the option, for messages (``"--torque-limit"``).

    Returns
    -------
    limit : ndarray, shape (nq,)
        Checked by :func:`check_torque_limit` (finite, > 0, at least the gravity torque where
        the reference starts).
    info : dict
        ``spec``, ``rule`` and, for ``P%``, ``percent`` and ``peak_torque_Nm``: what a study
        records (``summary.torque_limit``).

    Raises
    ------
    rrr_pin.validation.FieldError
        Naming ``name``: no rate, a text that is none of the three forms, a percent that is not
        finite and > 0, or limits :func:`check_torque_limit` refuses.
    """
    if rate is None:
        raise FieldError(name, "{name} acts on sampled controllers (the plant clips the torque "
                               "each control period): give the rate too, e.g. 1000 Hz")
    text = spec.strip()
    if text == "auto":
        return (check_torque_limit(plant, "urdf", reference, name=name),
                {"spec": "auto", "rule": "the URDF's effort limits"})
    if text.endswith("%"):
        try:
            percent = float(text[:-1])
        except ValueError:
            raise FieldError(name, f"{{name}} {text!r}: expected auto, P% (a number P > 0, "
                                   f"percent of the peak torque) or one number per joint "
                                   f"[N m]") from None
        if not (math.isfinite(percent) and percent > 0):
            raise FieldError(name, f"{{name}} {text!r}: the percent must be finite and > 0")
        n_steps = round(duration * rate)
        peak = peak_torque(plant, reference, np.arange(n_steps + 1) / rate)
        limit = check_torque_limit(plant, percent / 100.0 * peak, reference, name=name)
        return limit, {"spec": text, "percent": percent, "peak_torque_Nm": peak.tolist(),
                       "rule": f"{percent:g} % of the peak |M(r) rdd + V(r, rd) + G(r)| per "
                               f"joint of the reference on the nominal arm, over the control "
                               f"instants"}
    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        raise FieldError(name, f"{{name}} expects auto, P% or numbers separated by commas, got "
                               f"{text!r}") from None
    return check_torque_limit(plant, values, reference, name=name), {"spec": text,
                                                                     "rule": "given"}

r"""Requirements of a tuned design: typed inputs, each estimated on a frequency grid and verified.

A requirement states a target on the loop actually implemented: the law sampled at its rate,
on every plant of the set (:class:`~rrr_pin.control.sampled_loops.LoopSet`, the plants
linearized at the reference's mean configuration), behind the design's effects
(``ctx.effects``, :func:`rrr_pin.campaign.design_set.design_effects`: the ``--with`` effects and
the delay and actuator a requirement states, ``{"delay": s, "actuator": rad/s}``; the plant
behind them discretized exactly, :meth:`~rrr_pin.control.sampled_loops.LoopSet.effect_plant`).
Each gives

* :meth:`Requirement.estimate`, the fast value the tuner minimizes over (a frequency grid, or
  a linear prediction), worst over the plants;
* :meth:`Requirement.verify`, the exact value (eigenvalues of the exact discrete closed loop,
  python-control's ``disk_margins`` with SLICOT's ``AB13MD``, nonlinear simulation);
* :meth:`Requirement.normalized`, the value over the target (<= 1: met), the tuner's measure;
* :meth:`Requirement.per_plant`, the value of each plant (which one fails).

Built in (:data:`REQUIREMENTS`, the CLI's ``--require NAME=VALUE``): ``delay_margin`` [s],
``disk_margin`` [-], ``lower_gain_margin`` [-], ``actuator_bandwidth`` [rad/s], ``bandwidth``
[rad/s], ``peak_torque`` [N m or ``urdf``], ``error_ratio`` [-], ``noise_gain`` [N m/rad],
``reference_model`` [rad/s]. Write your own by subclassing :class:`Requirement`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import ClassVar

import numpy as np

from ..validation import FieldError, check_positive

__all__ = ["Requirement", "DelayMargin", "DiskMargin", "LowerGainMargin", "ActuatorBandwidth",
           "Bandwidth",
           "PeakTorque", "ErrorRatio", "NoiseGain", "ReferenceModel", "REQUIREMENTS",
           "make_requirement",
           "disk_margin_grid", "bandwidth_grid"]


#: Largest delay [s] a requirement names: :func:`_bisect_up` counts a margin above it as inf.
MAX_DELAY_MARGIN = 1.0

#: Largest delay, in samples of the law, that :meth:`DelayMargin.verify` builds an exact
#: discrete loop for (each sample adds ``n`` states to the eigenvalue problem).
MAX_DELAY_SAMPLES = 200


def _sigma_max(A: np.ndarray) -> np.ndarray:
    """Largest singular value of stacked matrices (LAPACK ``gesdd``), shape ``A.shape[:-2]``."""
    return np.linalg.svd(A, compute_uv=False)[..., 0]


def _sens(L: np.ndarray) -> np.ndarray:
    """Input sensitivity ``S = (I + L)^-1``, same shape as ``L`` (..., n, n)."""
    eye = np.eye(L.shape[-1])
    return np.linalg.inv(eye + L)


def disk_margin_grid(L: np.ndarray, S=None, screen: bool = True) -> np.ndarray:
    r"""Balanced multiloop disk margin on a grid, per plant: ``1 / max_w sigma_max(S - I/2)``.

    The unstructured bound (``sigma_max`` instead of SLICOT's ``mu`` upper bound of
    python-control's ``disk_margins``), so never above it; equal for a SISO loop. LAPACK
    only where the peak can be (:func:`~rrr_pin.control.grid_bounds.peak_sigma`).

    Parameters
    ----------
    L : ndarray, shape (np, nw, n, n)
    S : ndarray, same shape, optional
        ``(I + L)^-1`` if known.
    screen : bool
        False: LAPACK at every point.

    Returns
    -------
    ndarray, shape (np,)
    """
    from ..control.grid_bounds import peak_sigma

    S = (_sens(L) if S is None else S) - 0.5 * np.eye(L.shape[-1])
    return 1.0 / peak_sigma(S, screen)


#: The error bandwidth's level of ``sigma_max(S)`` (-3 dB).
BANDWIDTH_LEVEL = 1.0 / math.sqrt(2.0)


def bandwidth_grid(L: np.ndarray, omega: np.ndarray, S=None,
                   screen: bool = True) -> np.ndarray:
    r"""Error bandwidth per plant: lowest ``w`` with ``sigma_max(S(jw)) >= 1/sqrt(2)`` [rad/s].

    Interpolated linearly in ``log w`` between grid points; ``inf`` if never reached.
    Singular values by LAPACK only where they decide it
    (:func:`~rrr_pin.control.grid_bounds.level_sigmas`): the value is the full grid's.
    """
    from ..control.grid_bounds import level_sigmas

    sig = level_sigmas(_sens(L) if S is None else S, BANDWIDTH_LEVEL, screen)  # (np, nw)
    return _first_crossing(sig, omega, BANDWIDTH_LEVEL)


def _first_crossing(sig, omega, lvl) -> np.ndarray:
    """Lowest ``w`` where ``sig[p]`` reaches ``lvl``, interpolated in ``log w``, per plant."""
    out = np.full(sig.shape[0], np.inf)
    for p in range(sig.shape[0]):
        above = np.nonzero(sig[p] >= lvl)[0]
        if above.size == 0:
            continue
        i = above[0]
        if i == 0:
            out[p] = omega[0]
            continue
        f = (lvl - sig[p, i - 1]) / (sig[p, i] - sig[p, i - 1])
        out[p] = math.exp(math.log(omega[i - 1]) + f * math.log(omega[i] / omega[i - 1]))
    return out


@dataclass(frozen=True)
class Requirement:
    """Base of the requirements.

    Parameters
    ----------
    target : float
        The value to reach, in :attr:`unit`.

    Class attributes: ``name`` (the CLI's), ``unit``, ``sense`` (``"min"``: at least the
    target; ``"max"``: at most).
    """

    target: float
    name: ClassVar[str] = ""
    unit: ClassVar[str] = ""
    sense: ClassVar[str] = "min"
    #: True: the estimate pools the plants (not the worst of per-plant values), so the tuner
    #: estimates it on all plants at once rather than block by block.
    pooled: ClassVar[bool] = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "target", check_positive(self.name, self.target,
                                                          unit=self.unit))

    def normalized(self, achieved: float) -> float:
        """``target / achieved`` (at least) or ``achieved / target`` (at most); <= 1 met."""
        if self.sense == "min":
            return self.target / achieved if achieved > 0 else math.inf
        return achieved / self.target

    def prepare(self, ctx) -> None:
        """Precompute what :meth:`estimate` needs on the context (nothing by default)."""

    def estimate(self, ctx, ev) -> float:
        """Fast value of the evaluated law ``ev`` (worst over the plants)."""
        raise NotImplementedError(f"{type(self).__name__} must implement estimate()")

    def verify(self, ctx, ev) -> tuple[float, str]:
        """Exact value and how it was computed (default: the estimate)."""
        return self.estimate(ctx, ev), "frequency grid"

    def per_plant(self, ctx, ev):
        """Return the value on each plant of the set, shape (np,), or None (none per plant).

        The tuner names the plant that fails with it.
        """
        return None

    def to_dict(self) -> dict:
        """JSON-ready record (with the fields a subclass adds)."""
        extra = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "target"}
        return {"name": self.name, "target": self.target, "unit": self.unit,
                "sense": "at least" if self.sense == "min" else "at most", **extra}


@dataclass(frozen=True)
class DelayMargin(Requirement):
    """Common transport delay on every actuator the loop tolerates [s], worst plant.

    Parameters
    ----------
    actuator : float, optional
        A first-order actuator [rad/s] present while the delay grows (CLI:
        ``delay_margin=0.003,actuator=300``); default the fixed effects' (or none).
    """

    actuator: float | None = None
    name: ClassVar[str] = "delay_margin"
    unit: ClassVar[str] = "s"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.target > MAX_DELAY_MARGIN:
            raise FieldError(self.name, f"{{name}} = {self.target:g} s is beyond what is "
                                        f"verified: at most {MAX_DELAY_MARGIN:g} s (a larger "
                                        f"margin counts as inf)")
        if self.actuator is not None:
            check_positive("actuator", self.actuator, unit="rad/s")

    def _wa(self, ctx):
        return self.actuator or _effects(ctx).get("actuator")

    def per_plant(self, ctx, ev):
        """Grid value of each plant, shape (np,) [s]."""
        from ..control.sampled_loops import delay_margin_from_response

        wa = self._wa(ctx)
        f = None if wa is None else wa / (1j * ctx.loops.omega + wa)
        eigs, iv = ev.scaled_eigs(f, "modulus")
        return delay_margin_from_response(None, ctx.loops.omega, eigs, iv)

    def estimate(self, ctx, ev):
        """Return the grid value, worst over the plants."""
        from ..control.sampled_loops import delay_margin_from_response

        wa = self._wa(ctx)
        f = None if wa is None else wa / (1j * ctx.loops.omega + wa)
        eigs, iv = ev.scaled_eigs(f, "modulus")
        return float(np.min(delay_margin_from_response(None, ctx.loops.omega, eigs, iv)))

    def verify(self, ctx, ev):
        """Return the exact value and how it was computed."""
        wa = self._wa(ctx)
        est = self.estimate(ctx, ev)
        if est * ctx.loops.rate > MAX_DELAY_SAMPLES:
            return est, (f"frequency grid (the exact loop would hold over "
                         f"{MAX_DELAY_SAMPLES} delayed samples)")

        def stable(tau):
            return bool(np.all(ctx.loops.spectral_radius(ev.law, tau, wa) < 1.0))
        start = min(max(self.target, 1e-4), MAX_DELAY_SAMPLES / ctx.loops.rate)
        return _bisect_up(stable, start, 1e-4), \
            "exact discrete eigenvalues (fractional delay), bisection"


@dataclass(frozen=True)
class DiskMargin(Requirement):
    """Balanced multiloop disk margin ``alpha`` [-] at the torque input, worst plant."""

    name: ClassVar[str] = "disk_margin"
    unit: ClassVar[str] = "-"

    def estimate(self, ctx, ev):
        """Return the grid value, worst over the plants."""
        if ctx.screen:   # two screens, then LAPACK where the peak can be
            from ..control.grid_bounds import peak_from_bounds

            lo, hi, exact, refine = ev.sensitivity_screen(0.5)
            return float(np.min(1.0 / peak_from_bounds(lo, hi, exact, refine)))
        return float(np.min(disk_margin_grid(ev.L, ev.S(), screen=False)))

    def verify(self, ctx, ev):
        """Return the exact value and how it was computed."""
        from ..control.analysis import refined_disk_margin

        got = [refined_disk_margin(ev.loop_ss(ctx, i), ctx.loops.omega)
               for i in range(len(ctx.loops.plants))]
        worst = min(got, key=lambda m: m.alpha)
        return worst.alpha, (f"python-control disk_margins (SLICOT AB13MD mu bound), its grid "
                             f"refined at its lowest minima to 1e-6 in frequency (grid "
                             f"{min(m.grid for m in got):.6g}); certified lower bound "
                             f"1/||S - I/2||_inf = {min(m.lower for m in got):.6g} (AB13DD)")

    def per_plant(self, ctx, ev):
        """Grid value of each plant, shape (np,)."""
        return disk_margin_grid(ev.L, ev.S(), screen=False)


@dataclass(frozen=True)
class LowerGainMargin(Requirement):
    r"""Lower gain margin: the smallest common factor ``k`` on the torque the loop tolerates [-].

    The loop stays stable with the law's torque scaled by every ``k`` in ``[k_low, 1]``
    (``k_low`` at most the target; 0.5 is 6 dB), worst plant, with the design's effects: the
    margin a plant heavier than the law's model uses up (a rotor armature the model lacks
    scales the FL loop's gain by ``Mhat M^-1``). An open loop unstable at rest (gravity)
    always has one.

    * :meth:`estimate`: the eigenvalues ``lambda(e^{jwT})`` of ``L`` on the grid where they
      cross the negative real axis outside the unit circle, ``k = 1 / |lambda|``
      (generalized Nyquist: the closed loop of ``k L`` changes only where ``-1/k`` is on an
      eigenlocus), the largest;
    * :meth:`verify`: bisection on ``k`` of the exact discrete closed loop's spectral radius
      (:meth:`~rrr_pin.control.sampled_loops.LoopSet.spectral_radius` with the law's output
      scaled by ``k``, the delay and actuator included), then ``[k_low, 1]`` checked on 20
      points.

    Parameters
    ----------
    target : float
        The factor [-], in (0, 1] (1: off, any reduction may destabilize).
    default : bool
        Added by the tuner because no requirement stated one (recorded).
    """

    default: bool = False
    name: ClassVar[str] = "lower_gain_margin"
    unit: ClassVar[str] = "-"
    sense: ClassVar[str] = "max"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.target > 1.0:
            raise FieldError("lower_gain_margin", f"{{name}} is a factor on the torque in "
                                                  f"(0, 1], got {self.target!r}")

    def normalized(self, achieved) -> float:
        """``achieved / target`` (<= 1 met); a target of 1 is always met."""
        return 0.0 if self.target >= 1.0 else float(achieved) / self.target

    def per_plant(self, ctx, ev):
        """Grid value of each plant, shape (np,)."""
        if ev._eig_e is None:
            ev._eig_e = np.linalg.eigvals(ev.L)
        lam = ev._eig_e                                        # (np, nw, n)
        out = np.zeros(lam.shape[0])
        a, b = lam[:, :-1, :, None], lam[:, 1:, None, :]       # every pair of eigenvalues
        cross = (a.imag * b.imag <= 0) & (a.real < 0) & (b.real < 0)
        f = np.where(cross, a.imag / np.where(a.imag == b.imag, 1.0, a.imag - b.imag), 0.0)
        mag = np.exp((1 - f) * np.log(np.abs(a) + 1e-300) + f * np.log(np.abs(b) + 1e-300))
        k = np.where(cross & (mag > 1.0), 1.0 / mag, 0.0)
        np.maximum(out, k.reshape(k.shape[0], -1).max(axis=1), out=out)
        return out

    def estimate(self, ctx, ev):
        """Return the grid value, worst over the plants."""
        return float(np.max(self.per_plant(ctx, ev)))

    def verify(self, ctx, ev):
        """Return the exact value and how it was computed."""
        from dataclasses import replace

        fx = _effects(ctx)
        Ac, Bc, Cc, Dc = ev.law.law

        def stable(k):
            law = replace(ev.law, law=(Ac, Bc, k * Cc, k * Dc))
            return bool(np.all(ctx.loops.spectral_radius(law, fx.get("delay", 0.0),
                                                         fx.get("actuator")) < 1.0))
        if not stable(1.0):
            return math.inf, "exact discrete eigenvalues: unstable at k = 1"
        lo, hi = 0.0, 1.0           # stable at hi; largest unstable k below it
        for k in np.linspace(1.0, 0.0, 21)[1:]:
            if not stable(max(k, 1e-6)):
                lo = k
                break
            hi = k
        else:
            return 0.0, "exact discrete eigenvalues, stable down to k = 1e-6"
        while hi - lo > 1e-4:
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if stable(mid) else (mid, hi)
        return hi, "exact discrete eigenvalues (delay and actuator as states), bisection"

    def to_dict(self):
        """Return the JSON-ready record."""
        return {**super().to_dict(),
                "note": "stable for the torque scaled by every k in [verified, 1]"
                        + ("; added by default (lower_gain_margin=1 turns it off)"
                           if self.default else "")}


@dataclass(frozen=True)
class ActuatorBandwidth(Requirement):
    """Slowest first-order actuator ``wa/(s + wa)`` the loop tolerates [rad/s], worst plant.

    Parameters
    ----------
    delay : float, optional
        A transport delay [s] present with the actuator (CLI:
        ``actuator_bandwidth=300,delay=0.002``); default the fixed effects' (or none).
    """

    delay: float | None = None
    name: ClassVar[str] = "actuator_bandwidth"
    unit: ClassVar[str] = "rad/s"
    sense: ClassVar[str] = "max"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.delay is not None:
            check_positive("delay", self.delay, allow_zero=True, unit="s")
            if self.delay > MAX_DELAY_MARGIN:
                raise FieldError("delay", f"{{name}} = {self.delay:g} s: at most "
                                          f"{MAX_DELAY_MARGIN:g} s")

    def _delay(self, ctx):
        return self.delay if self.delay is not None else _effects(ctx).get("delay", 0.0)

    def per_plant(self, ctx, ev):
        """Exact smallest actuator of each plant [rad/s] (bisection, 1e-3), shape (np,)."""
        delay = self._delay(ctx)
        return np.array([_bisect_down(
            lambda wa, i=i: bool(ctx.loops.spectral_radius(ev.law, delay, wa,
                                                           plants=[i])[0] < 1.0),
            self.target, 1e-3) for i in range(len(ctx.loops.plants))])

    def _smallest(self, ctx, ev, rtol):
        delay = self._delay(ctx)

        def stable(wa):
            return bool(np.all(ctx.loops.spectral_radius(ev.law, delay, wa) < 1.0))
        return _bisect_down(stable, self.target, rtol)

    def estimate(self, ctx, ev):
        """Return the grid value, worst over the plants."""
        from ..control.sampled_loops import actuator_margin_from_response

        delay = self._delay(ctx)
        f = np.exp(-1j * ctx.loops.omega * delay) if delay else None
        eigs, iv = ev.scaled_eigs(f, "real")
        return float(np.max(actuator_margin_from_response(None, ctx.loops.omega, eigs, iv)))

    def verify(self, ctx, ev):
        """Return the exact value and how it was computed."""
        return self._smallest(ctx, ev, 1e-4), "exact discrete eigenvalues, bisection"


@dataclass(frozen=True)
class Bandwidth(Requirement):
    """Error bandwidth: lowest ``w`` where ``sigma_max(S)`` reaches -3 dB [rad/s], worst plant."""

    name: ClassVar[str] = "bandwidth"
    unit: ClassVar[str] = "rad/s"

    def estimate(self, ctx, ev):
        """Return the grid value, worst over the plants."""
        if ctx.screen:   # two screens, then LAPACK where they cannot decide
            from ..control.grid_bounds import level_from_bounds

            lo, hi, exact, refine = ev.sensitivity_screen(0.0)
            sig = level_from_bounds(lo, hi, BANDWIDTH_LEVEL, exact, refine)
            return float(np.min(_first_crossing(sig, ctx.loops.omega, BANDWIDTH_LEVEL)))
        return float(np.min(bandwidth_grid(ev.L, ctx.loops.omega, ev.S(), screen=False)))

    def verify(self, ctx, ev):
        """Return the exact value and how it was computed."""
        from scipy.optimize import brentq

        lvl = 1.0 / math.sqrt(2.0)
        out = []
        for i in range(len(ctx.loops.plants)):
            def g(logw, i=i):
                w = np.array([math.exp(logw)])
                L = ev.loop_at(ctx, i, w)
                return float(np.linalg.svd(_sens(L), compute_uv=False)[0, 0]) - lvl
            w0 = float(bandwidth_grid(ev.L[i:i + 1], ctx.loops.omega)[0])
            if not math.isfinite(w0):
                out.append(math.inf)
                continue
            lo, hi = math.log(w0) - 0.05, math.log(w0) + 0.05
            while g(lo) > 0 and lo > math.log(ctx.loops.omega[0]):
                lo -= 0.05
            while g(hi) < 0:
                hi += 0.05
            out.append(math.exp(brentq(g, lo, hi, xtol=1e-10)))
        return min(out), "exact frequency response, root of sigma_max(S) = -3 dB"

    def per_plant(self, ctx, ev):
        """Grid value of each plant, shape (np,) [rad/s]."""
        return bandwidth_grid(ev.L, ctx.loops.omega, ev.S(), screen=False)


@dataclass(frozen=True)
class ReferenceModel(Requirement):
    r"""Tracking against a reference model: the error no larger than the model's.

    The tracking error the FL law leaves is driven by the acceleration its model misses
    (``Mhat^-1`` times the torque mismatch, what :class:`ErrorRatio` simulates); per unit of
    it the error is ``E = P_q S Mhat`` (``P_q``: plant torque to ``q``; ``S = (I + L)^-1``),
    on the nominal plant ``1 / (s + lam)^2`` per joint (eq. 10's closed loop). The reference
    model is that closed loop at the target bandwidth ``w_m``, with a high-frequency allowance
    ``M`` (above any inertia mismatch, where no controller acts):

    .. math:: E_m(s) = \frac{1}{(s / \sqrt{M} + w_m)^2}, \qquad
              \psi = \max_\omega \bar\sigma\big(E(e^{j\omega T})\big)
              \Big(\frac{\omega^2}{M} + w_m^2\Big) \le 1,

    the H-infinity norm of ``E / E_m`` (Skogestad & Postlethwaite 2005, eq. 2.105, squared,
    as a weight on the error), worst plant. ``achieved`` and ``verified`` are ``psi`` (<= 1:
    met; a graded value the tuner can descend, as MATLAB's ``TuningGoal`` normalized values);
    FL alone of bandwidth ``lam`` gives ``max(w_m^2 / lam^2, 1/M)`` on the nominal plant.

    Parameters
    ----------
    target : float
        The model's bandwidth ``w_m`` [rad/s].
    peak : float
        ``M`` [-], the allowance at high frequency, > 1 (CLI:
        ``reference_model=30,peak=1.5``; default 2).
    """

    peak: float = 2.0
    name: ClassVar[str] = "reference_model"
    unit: ClassVar[str] = "rad/s"
    sense: ClassVar[str] = "max"

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "peak", check_positive("peak", self.peak))
        if self.peak <= 1.0:
            raise FieldError("peak", f"{{name}} of reference_model must be > 1 (1 is the FL "
                                     f"double integrator's continuous closed loop, which its "
                                     f"sampled loop exceeds near the Nyquist frequency), got "
                                     f"{self.peak!r}")

    def normalized(self, achieved) -> float:
        """Return ``psi`` itself (<= 1 met)."""
        return float(achieved)

    def _weight(self, w):
        """``1 / |E_m(jw)| = w^2 / M + w_m^2``."""
        return w * w / self.peak + self.target ** 2

    @staticmethod
    def _E(loops, S, Pq):
        """``P_q S Mhat``, the error per unit of missed acceleration, shape of ``S``."""
        return Pq @ S @ loops.Mhat

    def estimate(self, ctx, ev):
        """Return the grid value, worst over the plants."""
        from ..control.grid_bounds import peak_from_bounds, sigma_bounds

        w = ctx.loops.omega
        c = self._weight(w)
        E = self._E(ctx.loops, ev.S(), ctx.loops.P[..., :ctx.loops.n, :])
        if not ctx.screen:
            return float((_sigma_max(E) * c).max())
        lo, hi = sigma_bounds(E)
        cw = np.broadcast_to(c, lo.shape)
        return float(peak_from_bounds(lo * c, hi * c,
                                      lambda m: _sigma_max(E[m]) * cw[m]).max())

    def verify(self, ctx, ev):
        """Return the exact value and how it was computed."""
        from scipy.optimize import minimize_scalar

        loops, w, n = ctx.loops, ctx.loops.omega, ctx.loops.n

        def psi(i, x):
            P = loops.plant_response(x)[i:i + 1]
            Pe = ctx.plant_response(x)[i:i + 1] if _effects(ctx) else P
            L = loops.loop_response(loops.law(ev.lam, ev.K, x, matrices=False), Pe)
            return _sigma_max(self._E(loops, _sens(L), P[..., :n, :]))[0] * self._weight(x)

        out = []
        for i in range(len(loops.plants)):
            k = int(np.argmax(psi(i, w)))
            lo, hi = math.log(w[max(k - 1, 0)]), math.log(w[min(k + 1, w.size - 1)])
            best = float(psi(i, w[k:k + 1])[0])
            if hi > lo:
                res = minimize_scalar(
                    lambda lw, i=i: -float(psi(i, np.array([math.exp(lw)]))[0]),
                    bounds=(lo, hi), method="bounded", options={"xatol": 1e-10})
                best = max(best, -float(res.fun))
            out.append(best)
        return max(out), "exact frequency response, peak over w refined (scipy bounded)"

    def per_plant(self, ctx, ev):
        """Grid value of each plant, shape (np,)."""
        E = self._E(ctx.loops, ev.S(), ctx.loops.P[..., :ctx.loops.n, :])
        return (_sigma_max(E) * self._weight(ctx.loops.omega)).max(axis=1)

    def to_dict(self):
        """Return the JSON-ready record."""
        return {**super().to_dict(),
                "note": "achieved and verified are the peak of sigma_max(E) / |E_m| (<= 1 met)"}


@dataclass(frozen=True)
class NoiseGain(Requirement):
    r"""Noise amplification: peak gain from position-sensor noise to torque [N m/rad].

    .. math:: \max_\omega \bar\sigma\big(S(e^{j\omega T})\, C_q(e^{j\omega T})\big)

    with ``S = (I + L)^-1`` at the torque input and ``C_q`` the law's response to ``q``:
    the H-infinity norm of noise on ``q`` to torque, worst plant.
    """

    name: ClassVar[str] = "noise_gain"
    unit: ClassVar[str] = "N m/rad"
    sense: ClassVar[str] = "max"

    def estimate(self, ctx, ev):
        """Return the grid peak, worst over the plants."""
        n = ctx.loops.n
        from ..control.grid_bounds import peak_sigma

        T = ev.S() @ ev.law.C[None, :, :, :n]
        return float(peak_sigma(T, ctx.screen).max())

    def verify(self, ctx, ev):
        """Return the H-infinity norm of each plant's discrete loop (SLICOT AB13DD), worst."""
        import control

        out = []
        for i in range(len(ctx.loops.plants)):
            T = ev.noise_ss(ctx, i)
            out.append(float(control.linfnorm(T)[0]))
        return max(out), "H-infinity norm of the discrete loop (python-control linfnorm, " \
                         "SLICOT AB13DD)"

    def per_plant(self, ctx, ev):
        """Grid peak of each plant, shape (np,) [N m/rad]."""
        from ..control.grid_bounds import peak_sigma

        return peak_sigma(ev.S() @ ev.law.C[None, :, :, :ctx.loops.n], False)


@dataclass(frozen=True)
class PeakTorque(Requirement):
    """Peak ``|tau_j|`` on the reference within the limits [N m] (a number, or the URDF's).

    Parameters
    ----------
    target : float or "urdf"
        The limit of every joint [N m], or ``"urdf"``: each joint's effort limit.
    joint : str, optional
        Only this joint (by name).
    """

    target: object = "urdf"
    joint: str | None = None
    name: ClassVar[str] = "peak_torque"
    unit: ClassVar[str] = "N m"
    sense: ClassVar[str] = "max"

    def __post_init__(self) -> None:
        if self.target != "urdf":
            super().__post_init__()

    def limits(self, ctx) -> np.ndarray:
        """Limit per joint [N m], shape (n,)."""
        if self.target == "urdf":
            return np.asarray(ctx.nominal.effort_limits(), dtype=float)
        return np.full(ctx.loops.n, float(self.target))

    def _joints(self, ctx):
        return [ctx.joint_index(self.joint)] if self.joint else list(range(ctx.loops.n))

    def normalized(self, achieved) -> float:
        """Return the achieved ratio itself (<= 1 met)."""
        return float(achieved)

    def estimate(self, ctx, ev):
        """Peak inverse-dynamics torque of the reference on the worst plant over the limit.

        Independent of the controller (a law that tracks must deliver it): a floor.
        """
        j = self._joints(ctx)
        return float(np.max(ctx.id_peak[:, j] / self.limits(ctx)[j]))

    def verify(self, ctx, ev):
        """Return the exact value and how it was computed."""
        j = self._joints(ctx)
        peak = ctx.simulated(ev)["peak_torque"]
        return float(np.max(peak[:, j] / self.limits(ctx)[j])), \
            "nonlinear simulation on every plant, peak |tau| over the limit"

    def per_plant(self, ctx, ev):
        """Return the simulated peak over the limit of each plant, shape (np,)."""
        j = self._joints(ctx)
        return (ctx.simulated(ev)["peak_torque"][:, j] / self.limits(ctx)[j]).max(axis=1)

    def to_dict(self):
        """Return the JSON-ready record."""
        return {**super().to_dict(),
                "note": "achieved and verified are peak |tau| over the limit (<= 1 met)"}


@dataclass(frozen=True)
class ErrorRatio(Requirement):
    """RMS tracking error of FL alone (lam 100 rad/s) over the law's, pooled over the plants."""

    name: ClassVar[str] = "error_ratio"
    unit: ClassVar[str] = "-"
    pooled: ClassVar[bool] = True

    def estimate(self, ctx, ev):
        """Return the grid value, worst over the plants."""
        return ctx.error_ratio_estimate(ev)

    def verify(self, ctx, ev):
        """Return the exact value and how it was computed (NaN: a run diverged)."""
        return ctx.simulated(ev)["error_ratio"], \
            "nonlinear simulation on every plant with the design's effects, against FL " \
            "alone (lam 100 rad/s) behind the same effects"

    def per_plant(self, ctx, ev):
        """Return the simulated ratio of each plant, shape (np,) (0: the law diverged)."""
        sim = ctx.simulated(ev)
        each = np.array(sim["error_ratio_per_plant"], dtype=float)
        each[list(sim["diverged"])] = 0.0      # a divergence is the worst ratio
        return each


def _effects(ctx) -> dict:
    """Return the effects a requirement is evaluated with (the design's, else the fixed)."""
    return getattr(ctx, "effects", None) or ctx.fixed


def _bisect_up(stable, start, floor, rtol=1e-3):
    """Largest size keeping ``stable`` (0 if even ``floor`` fails)."""
    if not stable(floor):
        return 0.0
    lo, hi = floor, max(start, floor * 2)
    while stable(hi):
        lo, hi = hi, hi * 2
        if hi > 1.0:
            return math.inf
    while hi / lo - 1 > rtol:
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def _bisect_down(stable, start, rtol):
    """Smallest bandwidth keeping ``stable`` [rad/s] (``inf`` if 1e6 already fails)."""
    hi = 1e6
    if not stable(hi):
        return math.inf
    lo = min(start, hi / 2)
    while stable(lo):
        hi, lo = lo, lo / 2
        if lo < 1e-3:
            return 0.0
    while hi / lo - 1 > rtol:
        mid = math.sqrt(lo * hi)
        hi, lo = (mid, lo) if stable(mid) else (hi, mid)
    return hi


#: Built-in requirements by CLI name.
REQUIREMENTS = {cls.name: cls for cls in (DelayMargin, DiskMargin, LowerGainMargin,
                                          ActuatorBandwidth,
                                          Bandwidth, PeakTorque, ErrorRatio, NoiseGain,
                                          ReferenceModel)}


def make_requirement(text: str) -> Requirement:
    """Parse ``NAME=VALUE`` (``peak_torque=urdf``; ``peak_torque@JOINT=VALUE`` for one joint).

    Raises
    ------
    FieldError
        ``require``: not ``NAME=VALUE``, an unknown name (the message lists the built-in
        ones), or a value that is not a positive number.
    """
    name, sep, value = str(text).partition("=")
    name, _, joint = name.strip().partition("@")
    if not sep or name not in REQUIREMENTS:
        raise FieldError("require", f"{{name}}: expected NAME=VALUE with NAME one of "
                                    f"{', '.join(REQUIREMENTS)}, got {text!r}")
    cls = REQUIREMENTS[name]
    value, *rest = value.split(",")
    extras = {}
    allowed = {"delay_margin": "actuator", "actuator_bandwidth": "delay",
               "reference_model": "peak"}.get(name)
    for item in rest:
        key, eq, size = item.partition("=")
        try:
            extras[key.strip()] = float(size) if eq and key.strip() == allowed else None
        except ValueError:
            extras[key.strip()] = None
        if extras[key.strip()] is None:
            raise FieldError("require", f"{{name}}: {name} takes "
                                        f"{f'{allowed}=SIZE' if allowed else 'no option'} "
                                        f"after its value, got {item!r} in {text!r}")
    if joint and cls is not PeakTorque:
        raise FieldError("require", f"{{name}}: a joint (@{joint}) applies to peak_torque "
                                    f"only, got {text!r}")
    if cls is PeakTorque and value.strip() == "urdf":
        return PeakTorque("urdf", joint=joint or None)
    try:
        number = float(value)
    except ValueError:
        raise FieldError("require", f"{{name}}: {name} needs a number [{cls.unit}]"
                                    f"{' or urdf' if cls is PeakTorque else ''}, got "
                                    f"{value!r}") from None
    try:
        return cls(number, joint=joint or None) if cls is PeakTorque else cls(number,
                                                                              **extras)
    except FieldError as exc:
        raise FieldError("require", "{name}: " + str(exc).replace("{", "{{")
                         .replace("}", "}}")) from None


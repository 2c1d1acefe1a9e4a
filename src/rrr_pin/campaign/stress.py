r"""Where each controller breaks: unmodeled dynamics, simulated, predicted and guaranteed.

For one law and one effect of :mod:`rrr_pin.control.effects`, three numbers side by side:

* **simulated** (:func:`breaking_point`): the effect's size at which the nonlinear closed loop
  (sampled law, RK4 plant) stops working, by bisection: the largest delay, the smallest
  actuator bandwidth, the smallest joint stiffness, the lowest torque limit, the largest
  sensor noise for which the run neither diverges nor exceeds the RMS tracking-error
  ``budget`` (default :data:`DEFAULT_BUDGET`);
* **predicted** (:func:`linear_boundary`): the same boundary for the linear loop of the
  design, broken at the torque input, analysed in discrete time at the law's rate (exact
  zero-order-hold discretization with a fractional transport delay, Franklin, Powell &
  Workman sec. 4.3.4), so that it describes the digital loop that is simulated. Per joint,
  with the law's model exact, the FL laws see ``qdd = taubar`` (``M`` cancels):

  .. math:: L(s) = \frac{2\lambda s + \lambda^2 (1 + K(s))}{s^2}

  and PD + gravity at the home configuration ``q_h`` sees ``qdd = M(q_h)^{-1} tau``:
  ``L(s) = M(q_h)^{-1} (K_d s + K_p) / s^2``, analysed with the full (coupled) ``M(q_h)``:
  on the RRR at the sine's start the coupling of joints 2-3 makes one mode 1.7 times faster
  than the per-joint ``K_p / M_jj`` suggests, and its delay margin 2.3 times smaller. The
  continuous-time margins (delay margin
  ``PM / w_c``; the Routh bound on ``wa``) are given too (``predicted_continuous``);
* **guaranteed** (:func:`barrier_guarantee`): what the robust-stability barrier of eq. (12)-(13)
  covers: the multiplicative error ``Delta`` of the effect stays below
  ``|e_M(jw)| = 0.2 |jw / 200 + 1|`` at every frequency, for a delay
  ``|e^{-jw tau} - 1| <= |e_M(jw)|`` and for an actuator ``|jw / (jw + wa)| <= |e_M(jw)|``. It
  holds for a loop whose complementary sensitivity meets the barrier, ``|T| <= 1/|e_M|``
  (``barrier_met``); ``None`` where no such bound applies (stiffness, torque limit, noise).

**Torque limit** (:func:`torque_prediction`): the predicted limit is an estimate, the peak
inverse-dynamics torque of the reference, with a describing-function test of the loop at the
torque input saying on which side of it the law breaks (below for a loop that is never
conditionally stable, above for one that is, like the paper's H-infinity + FL, which winds up);
the guaranteed one is a sufficient condition, the peak torque of the unsaturated run.

**Any plant** (:mod:`rrr_pin.model.plant`): on a closed chain the effects act on the actuated
joints and the laws run on its reduced model, whose loop in actuated coordinates is the serial
one (:class:`~rrr_pin.control.laws.FLLinearModel`), so the same predictions apply. A run that
ends by the plant's own failure (a closed chain leaving its workspace, crossing a type-II
singularity or drifting off its loop closure: the loop has gone unstable,
:attr:`~rrr_pin.model.plant.Plant.failures`) counts as diverged.

**Combined effects** (``fixed``, CLI ``--with NAME=SIZE``): one effect is searched with others
held at a size; the simulation, the digital prediction (delay and actuator together, exactly
discretized), the continuous delay margin (with a fixed actuator) and the barrier's guarantee
(``|e^{-jw tau} wa/(jw + wa) - 1| <= |e_M|``) all include them.

References
----------
.. [1] The paper, eq. (12)-(13).
.. [2] G. F. Franklin, J. D. Powell, M. Workman, *Digital Control of Dynamic Systems*, 3rd ed.,
   1998, sec. 4.3.4.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from ..control.catalog import DEFAULT_BUDGET, EFFECTS, effect_name
from ..control.effects import PlantEffects
from ..control.sampled_loops import delayed_loop_matrix, split_delay, zoh
from ..robust.barriers import model_error_bound, robust_stability_barrier
from ..robust.lti import static_gain
from ..robust.robustness import check_robust_stability
from ..sim.simulation import simulate
from ..sim.trajectory import SimulationDiverged
from ..validation import FieldError, check_count, check_positive
from .runner import RunSettings

__all__ = ["StressSettings", "linear_boundary",
           "continuous_boundary", "barrier_guarantee", "barrier_met", "breaking_point",
           "stress", "effects_of", "check_fixed", "spectral_radius", "loop_bandwidth",
           "torque_prediction", "LINEAR_EFFECTS"]

logger = logging.getLogger(__name__)

# EFFECTS and DEFAULT_BUDGET live in rrr_pin.control.catalog: the CLI's help lists them without
# importing this module's numerical dependencies.


@dataclass(frozen=True)
class StressSettings:
    """How the breaking point is searched.

    Parameters
    ----------
    run : RunSettings
        Simulation of each run (at least; see ``cycles``): default 2 s, sampled at 1 kHz,
        plant sub-step ``1e-4`` s (the grid of the delays tried: a delay is a whole number of
        sub-steps, see :mod:`rrr_pin.control.effects`), compiled engine where possible.
    budget : float, default 0.05
        RMS tracking error [rad] (over all joints and samples) above which the loop counts as
        broken; a diverged run is broken too.
    rtol : float, default 0.01
        Bisection stops when the bracket is this narrow (relative).
    sweep : int, default 6
        Extra runs below the breaking point, for the error-against-size figure.
    cycles : float, default 150
        Each law runs at least ``cycles / w_b`` seconds, ``w_b`` its slowest closed-loop
        natural frequency [rad/s] (``lam`` for the FL laws, the slowest mode of
        ``M(q_h)^-1 K_p`` for PD): near the boundary an unstable mode grows at a rate
        proportional to ``w_b``, so a slow loop needs a longer run to show it (the PD
        baseline, 15.6 rad/s on the RRR, runs 9.6 s).
    offset : float, default 0.01
        Every run starts this far off the reference on every joint [rad] (``q0 = r(0) +
        offset``, unless ``run.q0`` is given; refused if that leaves a joint's limits), so
        that an unstable loop has a mode to grow from: started exactly on the reference, a
        slowly unstable loop (growth of a few 1/s near the boundary) can stay under the budget
        for seconds and the search would report a boundary beyond the true one. A stable loop
        forgets the offset within ~5 / lam.
    """

    run: RunSettings = field(default_factory=lambda: RunSettings(duration=2.0, dt=1e-4,
                                                                 rate=1000.0))
    budget: float = DEFAULT_BUDGET
    rtol: float = 0.01
    sweep: int = 6
    offset: float = 0.01
    cycles: float = 150.0

    def __post_init__(self) -> None:
        if self.run.rate is None:
            raise ValueError("StressSettings.run.rate: effects need sampled laws (give a rate)")
        check_positive("offset", self.offset, allow_zero=True, unit="rad")
        check_positive("budget", self.budget, unit="rad")
        check_positive("rtol", self.rtol)
        object.__setattr__(self, "sweep", check_count("sweep", self.sweep))


def _check_effect(effect: str) -> str:
    effect = effect_name(effect)
    if effect not in EFFECTS:
        raise ValueError(f"unknown effect {effect!r}; known: {', '.join(EFFECTS)}")
    return effect


def check_fixed(fixed, effect: str | None = None) -> dict:
    """Check the effects held fixed during a search: ``{name: size}`` (units of :data:`EFFECTS`).

    Raises
    ------
    FieldError
        ``fixed``: an unknown effect, the searched ``effect`` itself, or a size that is not a
        positive finite number (the message names the effect and the size).
    """
    out = {}
    effect = None if effect is None else effect_name(effect)
    for name, size in dict(fixed or {}).items():
        name = effect_name(name)
        if name not in EFFECTS:
            raise FieldError("fixed", f"{{name}}: unknown effect {name!r}; known: "
                                      f"{', '.join(EFFECTS)}")
        if name == effect:
            raise FieldError("fixed", f"{{name}}: {name!r} is the effect searched; hold only "
                                      f"the others fixed")
        try:
            out[name] = check_positive(name, size, unit=EFFECTS[name].unit)
        except FieldError as exc:
            text = str(exc).replace("{", "{{").replace("}", "}}")
            raise FieldError("fixed", "{name}: " + text) from None
    return out


def effects_of(effect: str, size: float, seed: int = 0, fixed=None) -> PlantEffects:
    """Return the :class:`PlantEffects` of one effect at ``size``, plus the ``fixed`` ones.

    ``fixed`` is ``{name: size}`` of other effects held at their size (:func:`check_fixed`).
    """
    effect = _check_effect(effect)
    fields = {}
    for name, value in {**check_fixed(fixed, effect), effect: size}.items():
        fields.update(EFFECTS[name].fields(value, seed))
    return PlantEffects(**fields)


# --- linear loop -------------------------------------------------------------------------------

def _model_of(law):
    """Return the law's linear model (``law.linear_model()``), or None if it has none."""
    ask = getattr(law, "linear_model", None)
    return ask() if ask is not None else None


def _linear_model(law):
    """Return the law's linear model; ``TypeError`` (:func:`_no_linear_model`) if it has none."""
    model = _model_of(law)
    if model is None:
        raise _no_linear_model(law)
    return model


def _law_matrices(law, rate: float, home):
    """Return the discrete law and the plant's ``M^-1`` (:meth:`LinearModel.digital`).

    Law: ``u = Cc x + Dc [q; qd]``, ``x+ = Ac x + Bc [q; qd]``; ``M^-1`` (identity for the FL
    laws, whose ``Mhat`` cancels ``M``), regulation (r = 0).
    """
    return _linear_model(law).digital(rate, home)


def _no_linear_model(law) -> TypeError:
    """Return the refusal for a law with no linear model (``stress`` then predicts nothing)."""
    return TypeError(f"no linear model of law {law.name!r} ({type(law).__name__}): the linear "
                     f"prediction covers laws whose linear_model() gives one (the built-in "
                     f"TrackingController and PDGravity laws)")


def spectral_radius(law, rate: float, home=None, *, delay: float = 0.0,
                    bandwidth: float | None = None) -> float:
    """Largest ``|eigenvalue|`` of the linear digital loop with a delay [s] and an actuator [rad/s].

    The plant ``qdd = M^-1 a`` (``a = u`` or ``a' = wa (u - a)``), driven by the law's
    zero-order-hold output delayed by ``delay``, is discretized exactly at ``Ts = 1/rate``;
    the loop is stable iff the result is < 1.
    """
    Ad, Bc, Cc, Dc, Minv = _law_matrices(law, rate, home)
    n = Minv.shape[0]
    Ts = 1.0 / rate
    nz = 3 * n if bandwidth else 2 * n
    A = np.zeros((nz, nz))
    B = np.zeros((nz, n))
    A[:n, n:2 * n] = np.eye(n)
    if bandwidth:
        A[n:2 * n, 2 * n:] = Minv
        A[2 * n:, 2 * n:] = -bandwidth * np.eye(n)
        B[2 * n:] = bandwidth * np.eye(n)
    else:
        B[n:2 * n] = Minv
    ell, mfrac = split_delay(delay, Ts)
    E0, G0 = zoh(A, B, Ts - mfrac)
    E1, G1i = zoh(A, B, mfrac) if mfrac else (None, np.zeros_like(B))
    Phi = E0 @ E1 if mfrac else E0
    Acl = delayed_loop_matrix(Phi, G0, E0 @ G1i, ell, (Ad, Bc, Cc, Dc), n)
    return float(np.max(np.abs(np.linalg.eigvals(Acl))))


def _bisect(stable, lo, hi, rtol):
    """Boundary between ``lo`` (stable) and ``hi`` (not), geometric bisection."""
    while hi / lo - 1.0 > rtol if hi > lo else lo / hi - 1.0 > rtol:
        mid = math.sqrt(lo * hi)
        if stable(mid):
            lo = mid
        else:
            hi = mid
    return lo, hi


def _bisect_steps(stable, lo: int, hi: int, h: float, rtol: float) -> tuple[int, int]:
    """:func:`_bisect` on whole numbers of steps ``h``: ``stable(k h)`` at ``lo``, not at ``hi``.

    Stops when the bracket is ``rtol`` narrow or one step wide.
    """
    while hi - lo > 1 and hi / lo - 1.0 > rtol:
        mid = min(max(round(math.sqrt(lo * hi)), lo + 1), hi - 1)
        if stable(mid * h):
            lo = mid
        else:
            hi = mid
    return lo, hi


#: The effects the linear digital loop models (:func:`spectral_radius`): searched or held fixed.
LINEAR_EFFECTS = ("delay", "actuator")


def _linear_fixed(fixed) -> dict | None:
    """``spectral_radius`` keywords of the fixed effects; None if one has no linear model."""
    kw = {}
    for name, size in (fixed or {}).items():
        if name not in LINEAR_EFFECTS:
            return None
        kw["delay" if name == "delay" else "bandwidth"] = size
    return kw


def linear_boundary(law, effect: str, rate: float, home=None, rtol: float = 1e-4, fixed=None):
    """Predicted breaking point of the linear digital loop (see the module docstring).

    Parameters
    ----------
    fixed : dict, optional
        Other effects held at a size, ``{"actuator": 300.0}`` or ``{"delay": 0.002}``: the
        loop includes them (the delay and the actuator lag together, exactly discretized).

    Returns
    -------
    float or None
        Largest delay [s] or smallest bandwidth [rad/s] that keeps the loop stable; None for
        effects without a linear prediction (stiffness, torque, noise), searched or fixed.
    """
    effect = _check_effect(effect)
    kw = _linear_fixed(check_fixed(fixed, effect))
    if kw is None:
        return None
    if effect == "delay":
        def stable(x):
            return spectral_radius(law, rate, home, **{**kw, "delay": x}) < 1.0
        lo = 1e-5
        if not stable(lo):
            return 0.0
        hi = lo * 2
        while stable(hi):
            lo, hi = hi, hi * 2
            if hi > 10.0:
                return math.inf
        return _bisect(stable, lo, hi, rtol)[0]
    if effect == "actuator":
        def stable(x):
            return spectral_radius(law, rate, home, **{**kw, "bandwidth": x}) < 1.0
        hi = 1e6
        if not stable(hi):
            return math.inf
        lo = hi / 2
        while stable(lo):
            hi, lo = lo, lo / 2
            if lo < 1e-6:
                return 0.0
        return _bisect(stable, hi, lo, rtol)[0]
    return None


def _siso_loops(law, home):
    """Per-joint continuous ``L(s)`` (loop broken at the torque; :meth:`LinearModel.loops`)."""
    return _linear_model(law).loops(home)


def continuous_boundary(law, effect: str, home=None, fixed=None):
    """Return the continuous-time (no sampling) prediction.

    The delay margin ``PM / w_c`` [s] (of ``L(s) wa / (s + wa)`` with an actuator held fixed),
    or the smallest ``wa`` [rad/s] keeping ``L(s) wa/(s + wa)`` closed-loop stable; None
    otherwise, and for the actuator with a delay held fixed (a delay has no rational loop).
    """
    import control

    effect = _check_effect(effect)
    fixed = check_fixed(fixed, effect)
    if set(fixed) - {"actuator"} or (effect == "actuator" and fixed):
        return None
    loops = _siso_loops(law, home)
    if "actuator" in fixed:
        wa = fixed["actuator"]
        loops = [L * control.tf([wa], [1.0, wa]) for L in loops]
    if effect == "delay":
        out = []
        for L in loops:
            _, pm, _, wc = control.margin(L)[:4]
            out.append(math.radians(pm) / wc)
        return min(out)
    if effect == "actuator":
        out = []
        for L in loops:
            def stable(wa, L=L):
                cl = control.feedback(L * control.tf([wa], [1.0, wa]), 1)
                return bool(np.all(np.real(cl.poles()) < 0))
            hi = 1e6
            lo = hi / 2
            while stable(lo) and lo > 1e-6:
                hi, lo = lo, lo / 2
            out.append(_bisect(stable, hi, lo, 1e-6)[0])
        return max(out)
    return None


_W = np.logspace(-2, 6, 20001)


def _eM(w):
    """``|e_M(jw)|`` of the paper's model-error bound, eq. (12)."""
    return np.abs(model_error_bound()(1j * w))


def barrier_guarantee(effect: str, fixed=None):
    """Return what eq. (12)-(13) covers.

    The largest delay [s] with ``|e^{-jw tau} - 1| <= |e_M(jw)|``,
    smallest ``wa`` [rad/s] with ``|jw/(jw + wa)| <= |e_M(jw)|`` for all w; None otherwise.
    With ``fixed`` effects the multiplicative error is the product's,
    ``Delta = e^{-jw tau} wa / (jw + wa) - 1``; None if the fixed ones leave no size covered
    (or include an effect without a bound).
    """
    effect = _check_effect(effect)
    fixed = check_fixed(fixed, effect)
    if effect not in LINEAR_EFFECTS or set(fixed) - set(LINEAR_EFFECTS):
        return None
    eM = _eM(_W)

    def covered(delay, wa):
        act = 1.0 if wa is None else wa / (1j * _W + wa)
        return bool(np.all(np.abs(np.exp(-1j * _W * delay) * act - 1.0) <= eM))

    if effect == "delay":
        wa = fixed.get("actuator")
        if not covered(1e-7, wa):
            return None
        return _bisect(lambda tau: covered(tau, wa), 1e-7, 1.0, 1e-6)[0]
    delay = fixed.get("delay", 0.0)
    if not covered(delay, 1e9):
        return None
    return _bisect(lambda wa: covered(delay, wa), 1e9, 1.0, 1e-6)[0]


def barrier_met(law, home=None) -> bool:
    """Whether every joint's ``|T(jw)| = |L/(1 + L)|`` stays below ``RSB = 1/|e_M|``.

    Each loop is checked by :func:`rrr_pin.robust.robustness.check_robust_stability` (nominally
    stable, grid minimum refined) against :func:`rrr_pin.robust.barriers.robust_stability_barrier`.
    """
    RSB = robust_stability_barrier()
    unity = static_gain(np.eye(1))
    return all(check_robust_stability(L, unity, RSB, omega=_W[::10]).ok
               for L in _siso_loops(law, home))


# --- nonlinear search --------------------------------------------------------------------------

def loop_bandwidth(law, home) -> float | None:
    """Slowest closed-loop natural frequency [rad/s] of a law's linear loop (None: no model)."""
    model = _model_of(law)
    return model.bandwidth(home) if model is not None else None


def _duration(law, home, settings: StressSettings) -> float:
    """Length of each run [s]: ``run.duration``, at least ``cycles / w_b`` (see StressSettings)."""
    wb = loop_bandwidth(law, home)
    duration = settings.run.duration
    if wb:
        rate = settings.run.rate
        duration = max(duration, math.ceil(settings.cycles / wb * rate) / rate)
    return duration


def _start(plant, reference, settings: StressSettings):
    """Return the start of every run [rad]: ``run.q0``, or ``r(0) + offset`` (None: on r).

    Raises
    ------
    ValueError
        ``r(0) + offset`` outside a joint's limits (it is not moved inside them).
    """
    if settings.run.q0 is not None or not settings.offset:
        return settings.run.q0
    r0 = np.asarray(reference.sample(np.array([0.0]))[0][0], dtype=float)
    q0 = r0 + settings.offset
    for j, name in enumerate(plant.joint_names):
        if not plant.lower[j] <= q0[j] <= plant.upper[j]:
            raise ValueError(f"offset = {settings.offset:g} rad puts joint {name!r} at "
                             f"{q0[j]:.6g} rad, outside its limits [{plant.lower[j]:.4g}, "
                             f"{plant.upper[j]:.4g}]: choose a smaller offset or give run.q0")
    return q0


def _rms(plant, law, reference, effect, size, settings: StressSettings, duration, fixed=None):
    """RMS tracking error [rad] of one run (from :func:`_start`), ``inf`` if it diverged."""
    kwargs = settings.run.simulate_kwargs()
    kwargs.pop("effects", None)  # the effect under test replaces any in the settings
    kwargs["q0"] = _start(plant, reference, settings)
    failures = (SimulationDiverged, *plant.failures)
    try:
        traj = simulate(plant, law, reference, duration,
                        effects=effects_of(effect, size, fixed=fixed), **kwargs)
    except failures:
        return math.inf
    e = traj.error
    return float(np.sqrt(np.mean(e * e)))


def breaking_point(plant, law, reference, effect: str, settings: StressSettings | None = None,
                   guess: float | None = None, home=None, fixed=None):
    """Bisection on the effect's size for the boundary of the nonlinear closed loop.

    Parameters
    ----------
    plant : Plant
        The simulated arm or mechanism.
    law : ControlLaw or SampledLaw
        Any law (sampled at ``settings.run.rate``).
    reference : Reference
    effect : str
        A key of :data:`EFFECTS`.
    settings : StressSettings, optional
    home : array-like, shape (n,), optional
        Configuration of the linear model that sets the run's length (``cycles``); default
        the reference at ``t = 0``.
    guess : float, optional
        A first estimate of the boundary (e.g. the linear prediction): the bracket starts at
        ``[guess / 2, 2 guess]``.
    fixed : dict, optional
        Other effects held at a size in every run, ``{name: size}`` (:func:`check_fixed`).

    Returns
    -------
    dict
        ``simulated`` (the last size that passed; None when there is no boundary to give),
        ``status`` (``"found"``; ``"not broken"``: even the harshest size tried passed,
        ``bracket[0]``; ``"broken at the mildest size tried"``: even ``bracket[1]`` failed),
        ``bracket`` [pass, fail] (None where that side was not reached), ``samples``: one
        ``{"size", "rms_error", "status"}`` per run, sorted by size (``rms_error`` None and
        ``status`` ``"diverged"`` for a run that diverged, else ``"passed"`` or
        ``"over budget"``), and ``duration`` [s] of each run. A delay is searched on whole
        numbers of plant sub-steps ``h = settings.run.dt`` (the only delays a run realizes):
        ``simulated`` and the bracket are multiples of ``h``, the bracket at least ``h`` wide,
        and the true boundary of the simulated loop lies inside it.
    """
    settings = settings or StressSettings()
    unit, direction, _, _ = EFFECTS[_check_effect(effect)]
    fixed = check_fixed(fixed, effect)
    # A delay is realized only as a whole number of plant sub-steps h (any other is refused,
    # rrr_pin.control.effects): the delays tried are multiples of h, and the bracket is at
    # least h wide.
    h = settings.run.dt if effect == "delay" else None
    samples = []
    if home is None:
        home = np.asarray(reference.sample(np.array([0.0]))[0][0], dtype=float)
    duration = _duration(law, home, settings)

    _start(plant, reference, settings)  # an offset off the limits: refused before any run

    def ok(size):
        rms = _rms(plant, law, reference, effect, size, settings, duration, fixed)
        passed = rms <= settings.budget
        samples.append({"size": size, "rms_error": rms if math.isfinite(rms) else None,
                        "status": "passed" if passed else "over budget" if math.isfinite(rms)
                        else "diverged"})
        logger.debug("%s, %s %.6g %s: RMS error %.4g rad (%s)", law.name, effect, size, unit, rms,
                     "passes" if passed else "broken")
        return passed

    default = {"delay": 5e-3, "actuator": 100.0, "stiffness": 1e3, "torque": 50.0,
               "noise": 1e-3, "viscous": 5.0, "coulomb": 5.0}[effect]
    def snap(x, up):
        """``x``, or for a delay the multiple of ``h`` (>= h) below it (above it if ``up``)."""
        if h is None:
            return x
        k = math.ceil(x / h - 1e-9) if up else math.floor(x / h + 1e-9)
        return max(1, k) * h

    g = guess if guess is not None and math.isfinite(guess) and guess > 0 else default
    # "up": pass below, fail above; "down": pass above, fail below.
    mild, harsh = (snap(g / 2, False), snap(2 * g, True)) if direction == "up" else (2 * g, g / 2)
    for _ in range(12):
        if ok(mild):
            break
        if h is not None and mild <= h * (1 + 1e-9):  # even one sub-step of delay fails
            return {"simulated": None, "status": "broken at the mildest size tried",
                    "bracket": [None, mild], "samples": _sorted(samples), "duration": duration}
        mild, harsh = (snap(mild / 4, False), mild) if direction == "up" else (mild * 4, mild)
    else:
        return {"simulated": None, "status": "broken at the mildest size tried",
                "bracket": [None, harsh], "samples": _sorted(samples), "duration": duration}
    for _ in range(12):
        if not ok(harsh):
            break
        mild, harsh = (harsh, snap(harsh * 4, True)) if direction == "up" else (harsh,
                                                                                harsh / 4)
    else:
        return {"simulated": None, "status": "not broken", "bracket": [mild, None],
                "samples": _sorted(samples), "duration": duration}
    if h is None:
        mild, harsh = _bisect(ok, mild, harsh, settings.rtol)
        sweep = np.geomspace(mild / 4 if direction == "up" else mild * 4, mild,
                             settings.sweep + 1)[:-1]
    else:
        k_lo, k_hi = _bisect_steps(ok, round(mild / h), round(harsh / h), h, settings.rtol)
        mild, harsh = k_lo * h, k_hi * h
        ks = np.unique(np.floor(np.geomspace(max(1.0, k_lo / 4), k_lo, settings.sweep + 1)))
        sweep = [k * h for k in ks if k < k_lo]
    for x in sweep:
        ok(float(x))
    return {"simulated": mild, "status": "found", "bracket": [mild, harsh],
            "samples": _sorted(samples), "duration": duration}


def _sorted(samples):
    return sorted(samples, key=lambda s: s["size"])


# --- torque limit ------------------------------------------------------------------------------

#: Frequencies [rad/s] where the describing-function test looks for phase crossovers of L.
_W_DF = np.logspace(-3, 4, 70001)


def _saturation_df(law, home):
    """``(N*, w_pc)``: the smallest saturation gain the linear loop tolerates, or ``(None, None)``.

    Describing function of ``tau_max``-saturation for a sinusoid of amplitude ``A``: a gain
    ``N(A) in (0, 1]``. The loop ``N L`` (every joint's ``L`` of the linear model) keeps its
    stability for every ``N`` in ``(0, 1]`` unless ``L(jw)`` crosses the negative real axis
    left of ``-1`` (a conditionally stable loop); then it loses it for ``N < N* = 1 / |L(j
    w_pc)|`` at the largest such crossing.
    """
    worst = (None, None)
    for L in _siso_loops(law, home):
        resp = L(1j * _W_DF)
        crossing = np.nonzero(np.diff(np.sign(resp.imag)) != 0)[0]
        for i in crossing:
            # Linear interpolation of the crossing between grid points i and i + 1.
            f = resp[i].imag / (resp[i].imag - resp[i + 1].imag)
            re = float(resp[i].real + f * (resp[i + 1].real - resp[i].real))
            if re < -1.0 and (worst[0] is None or -1.0 / re > worst[0]):
                worst = (-1.0 / re, float(_W_DF[i] + f * (_W_DF[i + 1] - _W_DF[i])))
    return worst


def torque_prediction(plant, law, reference, settings: StressSettings | None = None, home=None,
                      fixed=None) -> dict:
    r"""Return what a torque limit (the same on every joint) does to a law: estimate, guarantee.

    * ``predicted`` (an **estimate**): the peak inverse-dynamics torque of the reference
      itself on the plant, ``max_{t, j} |M(r) rdd + V(r, rd) + G(r)|_j``. Below it no law can
      follow ``r`` exactly; how far below it a law still meets the RMS budget depends on how
      its loop takes saturation, which the describing-function test says:
    * ``df_gain``, the describing-function test of the linear loop at the torque input
      (:func:`_saturation_df`). Saturation acts on a sinusoid as a gain ``N in (0, 1]``. With
      ``df_gain`` None, ``L(jw)`` never crosses the negative real axis left of -1 and the
      loop stays stable for every such gain: it degrades gracefully, the error grows with the
      shortfall, and it is expected to break a little **below** ``predicted`` (FL alone, PD).
      A conditionally stable loop (a near-integral ``K``: the paper's H-infinity + FL crosses
      at ``-21.7`` at 36.7 rad/s, ``df_gain = 1/21.7``) loses stability for ``N < df_gain``:
      a deep saturation, such as the kick of the start's offset, winds it up, and it is
      expected to break **above** ``predicted``. An approximation (the describing function
      assumes a sinusoid at the saturation), so it ranks and brackets, it does not bound.
    * ``guaranteed`` (a **sufficient** condition): the peak ``|tau|`` the law asks for in the
      run without a limit (same start, length, rate and fixed effects as the search). At or
      above it the saturation never acts and the run is the unsaturated one, so the simulated
      breaking limit is at most this. It includes the start's offset kick, so it is loose.

    Returns
    -------
    dict
        ``predicted`` [N m], ``guaranteed`` [N m], ``df_gain`` (or None), ``df_frequency``
        [rad/s] (or None), ``expected`` (``"below"`` or ``"above"`` ``predicted``; None
        without a linear model), ``criterion`` (text).
    """
    settings = settings or StressSettings()
    if home is None:
        home = np.asarray(reference.sample(np.array([0.0]))[0][0], dtype=float)
    duration = _duration(law, home, settings)
    kwargs = settings.run.simulate_kwargs()
    kwargs.pop("effects", None)
    kwargs["q0"] = _start(plant, reference, settings)
    fields = {}
    for name, size in check_fixed(fixed, "torque").items():
        fields.update(EFFECTS[name].fields(size, 0))
    traj = simulate(plant, law, reference, duration,
                    effects=PlantEffects(**fields) if fields else None, **kwargs)
    r, rd, rdd = reference.sample(traj.t)
    need = max(float(np.max(np.abs(plant.inverse_dynamics(q, v, a))))
               for q, v, a in zip(r, rd, rdd, strict=True))
    try:
        gain, wpc = _saturation_df(law, home)
        expected = "below" if gain is None else "above"
    except TypeError:                                     # no linear model
        gain = wpc = expected = None
    return {"predicted": need, "guaranteed": float(np.max(np.abs(traj.tau))),
            "df_gain": gain, "df_frequency": wpc, "expected": expected,
            "criterion": "predicted: peak inverse-dynamics torque of the reference (estimate); "
                         "describing function of the loop at the torque input: breaks below "
                         "it if never conditionally stable, above it if df_gain is set "
                         "(estimate); guaranteed: peak |tau| of the unsaturated run "
                         "(sufficient: nothing saturates at or above it)"}


def stress(plant, laws, reference, effect: str, settings: StressSettings | None = None,
           home=None, progress=None, fixed=None) -> dict:
    """Find the breaking points of every law for one effect: simulated, predicted, guaranteed.

    Parameters
    ----------
    plant : Plant
        The nominal arm or mechanism (the laws' model is the plant: the effect is the only
        mismatch).
    laws : sequence of laws
    reference : Reference
    effect : str
        A key of :data:`EFFECTS`.
    settings : StressSettings, optional
    home : array-like, shape (n,), optional
        Configuration of the PD loop's linear model [rad] (default: the reference at t = 0).
    progress : callable, optional
        Called as ``progress(done, total)`` after each law's search (``total = len(laws)``).
    fixed : dict, optional
        Other effects held at a size in every run, ``{name: size}`` (:func:`check_fixed`),
        e.g. ``{"actuator": 300.0}`` while the delay is searched: the simulation, the digital
        prediction (:func:`linear_boundary`), the continuous one and the barrier's guarantee
        all include them. Recorded as ``"with"``.

    Returns
    -------
    dict
        ``{"effect", "unit", "budget_rad", "settings", "rows": [...]}``; each row has
        ``controller``, ``effect``, ``unit``, ``predicted`` (digital loop),
        ``predicted_continuous``, ``simulated``, ``status``, ``bracket`` and ``samples`` (of
        :func:`breaking_point`), ``resolution`` (the grid a delay is searched on, the plant
        sub-step [s]; None for other effects), ``guaranteed``, ``barrier_met``, ``agreement``
        (simulated / predicted). A prediction is ``inf`` when no size breaks the linear loop;
        the JSON writers (:mod:`rrr_pin.report.jsondata`) write it as ``null`` with a status.
        For the torque limit, ``predicted`` and ``guaranteed`` are :func:`torque_prediction`'s
        estimate and sufficient bound, and each row adds its whole ``torque`` dict.
    """
    settings = settings or StressSettings()
    effect = _check_effect(effect)
    fixed = check_fixed(fixed, effect)
    unit, direction, what, _ = EFFECTS[effect]
    if home is None:
        home = np.asarray(reference.sample(np.array([0.0]))[0][0], dtype=float)
    rate = settings.run.rate
    guarantee = barrier_guarantee(effect, fixed)
    rows = []
    laws = list(laws)
    for k, law in enumerate(laws):
        extra = {}
        try:
            pred = linear_boundary(law, effect, rate, home, fixed=fixed)
            cont = continuous_boundary(law, effect, home, fixed)
            met = barrier_met(law, home)
        except TypeError:
            pred = cont = met = None
        if effect == "torque":
            extra["torque"] = torque_prediction(plant, law, reference, settings, home, fixed)
            pred = extra["torque"]["predicted"]
        found = breaking_point(plant, law, reference, effect, settings, guess=pred, home=home,
                               fixed=fixed)
        sim = found["simulated"]
        rows.append({**extra,
            "controller": law.name, "label": law.label or law.name, "effect": effect,
            "unit": unit, "predicted": pred, "predicted_continuous": cont, "simulated": sim,
            "status": found["status"], "bracket": found["bracket"],
            "duration_s": found["duration"],
            "resolution": settings.run.dt if effect == "delay" else None,
            "guaranteed": (extra["torque"]["guaranteed"] if effect == "torque"
                           else guarantee if (guarantee is not None and met) else None),
            "barrier_met": met,
            "agreement": sim / pred if (sim and pred and math.isfinite(pred)) else None,
            "samples": found["samples"],
        })
        logger.info("%s breaks at %s = %s %s (%d runs; linear prediction %s)", law.name,
                    effect, "none found" if sim is None else f"{sim:.4g}", unit,
                    len(found["samples"]), "none" if pred is None else f"{pred:.4g}")
        if progress:
            progress(k + 1, len(laws))
    return {"effect": effect, "unit": unit, "direction": direction, "what": what,
            "with": fixed, "budget_rad": settings.budget, "settings": {**settings.run.to_dict(),
                                                        "rtol": settings.rtol},
            "rows": rows}

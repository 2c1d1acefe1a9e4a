r"""Design to requirements: tune a structured FL law over a plant set, then verify it exactly.

:func:`tune` minimizes the worst normalized requirement (:mod:`rrr_pin.campaign.requirements`)

.. math:: \min_\theta \max_r \frac{\text{target}_r}{\text{achieved}_r(\theta)}
          \quad (\text{or achieved over target for an upper bound})

over the free parameters ``theta`` of a :class:`~rrr_pin.control.structures.Structure`
(searched on a log scale inside their bounds), every requirement evaluated on the digital loop
of each plant of the set (:class:`~rrr_pin.control.sampled_loops.LoopSet`) on a frequency grid,
behind the design's effects (:func:`design_effects`: ``fixed`` and the delay and actuator the
requirements state; the plant behind them discretized exactly). A point whose exact discrete
closed loop is unstable on any plant (with those effects) is penalized by its spectral radius.
The search is scipy's bounded Nelder-Mead (the objective is a maximum of non-smooth functions)
from several seeded starts. The best point is then verified:
each requirement's exact value (:meth:`Requirement.verify`) and, for the delay and the
actuator, the breaking point that :func:`rrr_pin.campaign.stress.breaking_point` simulates on
the nominal plant beside the exact linear prediction on that plant; every plant of the set is
simulated behind the effects. The status is ``met`` only when every requirement holds with a
finite value and no run diverged; otherwise the failures name the requirement and the plant
(:func:`plant_failures`, :func:`simulated_failures`). ``lower_gain_margin`` is added unless a
requirement states one (:func:`with_default_requirements`).

The result (:class:`TuneResult`) is the tuned law (``name = "tuned"``), the table per
requirement (target, achieved on the grid, verified), and the trade-off when the requirements
cannot all be met (the best point found and which requirements bind there). It is written as
``design.json`` (:meth:`TuneResult.to_dict`) and read back by :func:`tuned_law`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..validation import FieldError, check_count, check_rate
from .design_file import DESIGN_FORMAT, k_record, law_of
from .design_set import (
    check_plant_set,
    design_effects,
    design_tolerances,
    number_text,
    plant_failures,
    simulated_failures,
    with_default_requirements,
)
from .requirements import (
    ActuatorBandwidth,
    DelayMargin,
    ErrorRatio,
    PeakTorque,
    Requirement,
    _bisect_down,
    _bisect_up,
)

__all__ = ["tune", "TuneResult", "TuneError", "check_budget", "peak_rss_mb",
           "MAX_SEARCH_SECONDS"]


#: Objective of a point unstable on some plant: this plus its largest spectral radius.
_UNSTABLE = 1e3


class TuneError(ValueError):
    """Requirements or plants no point of the structure can satisfy; carries the best point.

    Attributes
    ----------
    result : TuneResult or None
        The best point found (None when refused before any search).
    """

    def __init__(self, message: str, result=None):
        super().__init__(message)
        self.result = result


class _Eval:
    """One law ``(lam, K)`` on the context: responses computed once, values cached."""

    def __init__(self, ctx, lam, K, law=None):
        self.ctx, self.lam, self.K = ctx, lam, K
        # the law's response is the same on every block of plants (one grid, one nominal)
        self.law = ctx.loops.law(lam, K) if law is None else law
        self._L0 = self._L = None
        self._sim, self._eig_e = None, None
        self._S, self._discs, self._lam, self._done = None, None, None, None
        self._sb, self._Sp, self._Sdone = None, None, None

    @property
    def L0(self) -> np.ndarray:
        """The loop without effects (margins are searched on top of it), (np, nw, n, n).

        Computed on first use: an evaluation whose requirements need no response builds none.
        """
        if self._L0 is None:
            self._L0 = self.ctx.loops.loop_response(self.law)
        return self._L0

    @property
    def L(self) -> np.ndarray:
        """The loop behind the design's effects, shape (np, nw, n, n), on first use.

        :func:`design_effects`' exact discrete responses; :attr:`L0` without effects.
        """
        if self.ctx.parts_e is None:
            return self.L0
        if self._L is None:
            self._L = self.ctx.loops.loop_response(self.law, parts=self.ctx.parts_e)
        return self._L

    def scaled_eigs(self, factor, kind):
        """Eigenvalues of ``f(w) L`` where a margin may cross, and those intervals.

        Eigenvalues of ``L`` are computed (LAPACK, once per grid point) only at the ends of
        the intervals :func:`~rrr_pin.control.grid_bounds.crossing_intervals` cannot rule
        out, then scaled by ``f`` (a scalar per frequency: ``eig(f L) = f eig(L)``); NaN
        elsewhere. The margins searched on those intervals are the full grid's.

        Parameters
        ----------
        factor : ndarray, shape (nw,), complex, or None
        kind : {"modulus", "real"}

        Returns
        -------
        eigs : ndarray, shape (np, nw, n), complex
        intervals : ndarray of bool, shape (np, nw - 1)
        """
        from ..control.grid_bounds import crossing_intervals, gershgorin_discs

        if self._discs is None:
            self._discs = gershgorin_discs(self.L0)
            self._lam = np.full(self.L0.shape[:-1], np.nan, complex)
            self._done = np.zeros(self.L0.shape[:2], bool)
        iv = crossing_intervals(self._discs, factor, kind)
        if not self.ctx.screen:
            iv = np.ones_like(iv)
        need = np.zeros_like(self._done)
        need[:, :-1] |= iv
        need[:, 1:] |= iv
        need &= ~self._done
        if need.any():
            self._lam[need] = np.linalg.eigvals(self.L0[need])
            self._done |= need
        lam = self._lam if factor is None else self._lam * factor[None, :, None]
        return lam, iv

    def S(self):
        """Input sensitivity ``(I + L)^-1`` of the loop with the design's effects, once."""
        if self._S is None:
            self._S = np.linalg.inv(np.eye(self.L.shape[-1]) + self.L)
        return self._S

    def S_at(self, mask) -> np.ndarray:
        """``(I + L)^-1`` at the points of ``mask`` (np, nw), inverted once each, (k, n, n)."""
        if self._S is not None:
            return self._S[mask]
        if self._Sp is None:
            self._Sp = np.full(self.L.shape, np.nan, complex)
            self._Sdone = np.zeros(self.L.shape[:2], bool)
        todo = mask & ~self._Sdone
        if todo.any():
            self._Sp[todo] = np.linalg.inv(np.eye(self.L.shape[-1]) + self.L[todo])
            self._Sdone |= todo
        return self._Sp[mask]

    def sensitivity_screen(self, c: float) -> tuple:
        """Screens of ``sigma_max(S - c I)`` for :mod:`~rrr_pin.control.grid_bounds`.

        Returns
        -------
        lo, hi : ndarray, shape (np, nw)
            :func:`~rrr_pin.control.grid_bounds.sensitivity_bounds` (no inversion).
        exact, refine : callable
            On a mask: the singular value (LAPACK), and
            :func:`~rrr_pin.control.grid_bounds.sigma_bounds` of ``S - c I`` there.
        """
        from ..control.grid_bounds import sensitivity_bounds, sigma_bounds

        if self._sb is None:
            self._sb = sensitivity_bounds(self.L)
        inv_d, delta = self._sb
        m = np.abs(inv_d - c).max(axis=-1)
        eye = c * np.eye(self.L.shape[-1])

        def exact(mask):
            return np.linalg.svd(self.S_at(mask) - eye, compute_uv=False)[..., 0]

        def refine(mask):
            return sigma_bounds(self.S_at(mask) - eye)
        return np.maximum(m - delta, 0.0), m + delta, exact, refine

    def loop_at(self, ctx, i, w):
        """Plant ``i``'s loop response at frequencies ``w``, shape (nw, n, n)."""
        P = ctx.plant_response(w)[i:i + 1]
        return ctx.loops.loop_response(ctx.loops.law(self.lam, self.K, w, matrices=False),
                                       P)[0]

    def _plant_andlaw_of(self, ctx, i):
        """Plant ``i`` (zero-order hold at ``T``, output its state) and the law, discrete."""
        import control

        from ..control.sampled_loops import zoh

        loops = ctx.loops
        fx = ctx.effects or {}
        if fx:   # the plant behind the design's delay and actuator, exactly discretized
            Phi, Gam = loops.effect_plant(i, fx.get("delay", 0.0), fx.get("actuator"))
            Cy = np.eye(2 * loops.n, Phi.shape[0])
        else:
            Phi, Gam = zoh(loops.A[i], loops.B[i], loops.T)
            Cy = np.eye(Phi.shape[0])
        P = control.ss(Phi, Gam, Cy, 0, loops.T)
        Ac, Bc, Cc, Dc = self.law.law
        C = control.ss(Ac, Bc, Cc, Dc, loops.T) if Ac.size else control.ss([], [], [], Dc,
                                                                             loops.T)
        return P, C

    def loop_ss(self, ctx, i):
        """Plant ``i``'s discrete loop at the torque input as a ``control.StateSpace``."""
        P, C = self._plant_andlaw_of(ctx, i)
        return -C * P

    def noise_ss(self, ctx, i):
        """Plant ``i``'s discrete loop from noise on ``q`` to the law's torque."""
        import control

        loops = ctx.loops
        n = loops.n
        P, C = self._plant_andlaw_of(ctx, i)
        E = np.vstack([np.eye(n), np.zeros((n, n))])
        eye = control.ss([], [], [], np.eye(n), loops.T)
        return control.feedback(eye, C * P, sign=1) * C * control.ss([], [], [], E, loops.T)


@dataclass
class _Context:
    nominal: object
    loops: object
    reference: object
    fixed: dict
    run: object
    plants: list
    id_peak: np.ndarray = None
    harmonics: tuple = None
    fl_energy: float = None
    #: Screen the grid (:mod:`rrr_pin.control.grid_bounds`); False: LAPACK at every point.
    screen: bool = True
    #: The effects every requirement is evaluated with (:func:`design_effects`):
    #: ``{"delay": s, "actuator": rad/s}``; None or empty: the ideal loop.
    effects: dict = None
    #: :meth:`LoopSet.parts` of the plants behind ``effects`` on the grid (None: none).
    parts_e: tuple = None

    def plant_response(self, w) -> np.ndarray:
        """Exact responses of every plant behind the design's effects, (np, nw, 2n, n)."""
        fx = self.effects or {}
        return self.loops.effect_response(w, fx.get("delay", 0.0), fx.get("actuator"))

    def effect_factor(self, w) -> np.ndarray:
        """``e^{-j w tau} wa / (j w + wa)`` of the design's effects at ``w`` [rad/s], (nw,)."""
        fx = self.effects or {}
        f = np.exp(-1j * w * fx.get("delay", 0.0))
        if fx.get("actuator"):
            f = f * fx["actuator"] / (1j * w + fx["actuator"])
        return f
    #: Plants per block of an evaluation (None: all at once); what one evaluation holds is
    #: proportional to it, not to the number of plants.
    block: int | None = None

    def blocks(self) -> list[slice]:
        """Return the plants' blocks, in order, as slices of :attr:`plants`."""
        n = len(self.plants)
        b = n if self.block is None else self.block
        return [slice(i, min(i + b, n)) for i in range(0, max(n, 1), max(b, 1))]

    def subset(self, plants: slice) -> _Context:
        """Return the context on the plants ``plants`` (the loops' arrays are views, not copies)."""
        return replace(self, loops=self.loops.subset(plants), plants=self.plants[plants],
                       id_peak=None if self.id_peak is None else self.id_peak[plants],
                       parts_e=None if self.parts_e is None else
                       tuple(x[plants] for x in self.parts_e))

    def joint_index(self, name):
        return list(self.nominal.joint_names).index(name)

    def prepare_tracking(self, duration: float, fs: float = 25.0, pad: int = 3):
        """Peak inverse dynamics per plant, and the torque mismatch along ``r`` for the estimate.

        The estimate of the tracking error is the linear response, from rest, of each plant's
        loop to its torque mismatch ``w(t) = ID_plant(r) - ID_nominal(r)`` (what the law's
        feed-forward misses): a linear convolution by FFT (the input zero-padded to ``pad``
        times its length, so that the response is the one from rest, transient included).
        With the design's effects the feed-forward reaches the plant through them
        (``W = ID_plant - f ID_nominal``, ``f = e^{-j w tau} wa / (j w + wa)``) and the loop
        is the plant's behind them (:meth:`plant_response`).
        """
        t = np.arange(int(round(duration * fs))) / fs
        r, rd, rdd = (np.asarray(x) for x in self.reference.sample(t))
        ids = np.array([[p.inverse_dynamics(q, v, a) for q, v, a in zip(r, rd, rdd,
                                                                          strict=True)]
                        for p in self.plants])                     # (np, nt, n)
        hat = np.array([self.nominal.inverse_dynamics(q, v, a)
                        for q, v, a in zip(r, rd, rdd, strict=True)])
        self.id_peak = np.abs(ids).max(axis=1)
        nfft = pad * t.size
        w = 2.0 * np.pi * np.fft.rfftfreq(nfft, 1.0 / fs)
        w[0] = 1e-3 * w[1]                                          # DC: the slowest bin
        W = np.fft.rfft(ids, n=nfft, axis=1) - self.effect_factor(w)[None, :, None] * \
            np.fft.rfft(hat, n=nfft, axis=0)[None]                  # (np, nf, n)
        P = self.plant_response(w)                                  # (np, nf, 2n, n)
        self.harmonics = (w, W, t.size, nfft, self.loops.parts(P))
        self.fl_energy = self._energy(100.0, None)

    def _energy(self, lam, K):
        w, W, nt, nfft, parts = self.harmonics
        law = self.loops.law(lam, K, w, matrices=False)
        total = 0.0
        for b in self.blocks():   # summed block by block: one block's responses at a time
            pb = tuple(x[b] for x in parts)
            L = self.loops.loop_response(law, parts=pb)
            n = L.shape[-1]
            # e = P_q S w, S = (I + L)^-1 applied by a solve
            E = (pb[0] @ np.linalg.solve(np.eye(n) + L, W[b][..., None]))[..., 0]
            e = np.fft.irfft(E, n=nfft, axis=1)[:, :nt]
            total += float(np.sum(e * e))
        return total

    def error_ratio_estimate(self, ev) -> float:
        """Linear estimate of FL alone's RMS error over the law's, pooled over the plants."""
        e = self._energy(ev.lam, ev.K)
        return math.sqrt(self.fl_energy / e) if e > 0 else math.inf

    def simulated(self, ev) -> dict:
        """Simulate the law and FL alone on every plant (cached): peak torque, error ratio."""
        if ev._sim is not None:
            return ev._sim
        from ..control.laws import fl_controller
        from .runner import run_laws_batch

        law = law_of(self.nominal, ev.lam, ev.K)
        fl = fl_controller(self.nominal, 100.0)
        runs = run_laws_batch(self.plants, [law, fl], self.reference, self.run)
        peak, errs, errs_fl, diverged, fl_diverged = [], [], [], {}, {}
        for p, row in enumerate(runs):
            t, tf = row[law.name], row[fl.name]
            if isinstance(t, Exception):
                peak.append(np.full(self.loops.n, np.inf))
                errs.append(math.inf)
                diverged[p] = str(t)
            else:
                peak.append(np.abs(t.tau).max(axis=0))
                errs.append(float(np.sum(t.error ** 2)))
            if isinstance(tf, Exception):
                errs_fl.append(math.inf)
                fl_diverged[p] = str(tf)
            else:
                errs_fl.append(float(np.sum(tf.error ** 2)))
        err, err_fl = float(np.sum(errs)), float(np.sum(errs_fl))
        with np.errstate(divide="ignore", invalid="ignore"):
            each = np.sqrt(np.asarray(errs_fl) / np.asarray(errs))
        ev._sim = {"peak_torque": np.array(peak),
                   "error_ratio": (math.sqrt(err_fl / err) if err > 0 and math.isfinite(err)
                                   and math.isfinite(err_fl) else math.nan),
                   "error_ratio_per_plant": each, "diverged": diverged,
                   "baseline_diverged": fl_diverged}
        return ev._sim


def _context(robot, plants, reference, rate, fixed, duration, effects=None) -> _Context:
    """Build the tuner's context: the plants' digital loops and the tracking estimate's inputs.

    The loops are linearized at the reference's mean configuration; ``effects``
    (:func:`design_effects`) are in every requirement's evaluation and in the simulations.
    """
    from ..control.effects import PlantEffects
    from ..control.sampled_loops import LoopSet
    from .runner import RunSettings

    t = np.linspace(0.0, duration, 401)
    home = np.asarray(reference.sample(t)[0], float).mean(axis=0)
    loops = LoopSet(robot, plants, home, rate)
    effects = dict(effects or {})
    run = RunSettings(duration=duration, rate=rate, effects=PlantEffects(
        delay=effects.get("delay", 0.0), actuator_bandwidth=effects.get("actuator"))
        if effects else None)
    ctx = _Context(robot, loops, reference, fixed, run, list(plants), effects=effects)
    if effects:
        ctx.parts_e = loops.parts(ctx.plant_response(loops.omega))
    ctx.prepare_tracking(duration)
    return ctx


def _estimates(ctx, blocks, reqs, lam, K, fixed) -> tuple:
    """Return the tuner's objective and estimates of the law ``(lam, K)``, block by block.

    A point unstable on any plant (with the fixed effects) scores :data:`_UNSTABLE` plus the
    largest spectral radius, with no estimates. Otherwise each requirement's estimate (the
    worst over the plants) is the worst of its blocks' (the smallest for a lower bound, the
    largest for an upper bound), equal to the one on all plants at once; a pooled requirement
    (``pooled``, e.g. the error ratio) is estimated once on the whole context. One block's
    responses are alive at a time.

    Returns
    -------
    objective : float
    estimates : list of float, or None (unstable)
    """
    loops = ctx.loops
    law = loops.law(lam, K)
    rho = 0.0
    for b, _ in blocks:
        idx = range(b.start, b.stop)
        rho = max(rho, float(np.max(loops.spectral_radius(law, plants=idx))))
        if fixed:
            rho = max(rho, float(np.max(loops.spectral_radius(
                law, fixed.get("delay", 0.0), fixed.get("actuator"), plants=idx))))
    if rho >= 1.0:
        return _UNSTABLE + rho, None
    vals = [None] * len(reqs)
    for _, sub in blocks:
        ev = _Eval(sub, lam, K, law)
        for j, r in enumerate(reqs):
            if r.pooled:
                continue
            v = r.estimate(sub, ev)
            vals[j] = v if vals[j] is None else (min if r.sense == "min" else max)(vals[j], v)
        del ev
    whole = _Eval(ctx, lam, K, law)    # its responses are not built unless a requirement asks
    for j, r in enumerate(reqs):
        if r.pooled:
            vals[j] = r.estimate(ctx, whole)
    norm = [r.normalized(v) for r, v in zip(reqs, vals, strict=True)]
    return float(max(norm)), vals


#: Bytes the tuner's context holds per plant and per grid point, over ``n^2`` (the plant's
#: responses ``P`` and their five law-independent parts, complex).
_BYTES_PER_POINT = (2 + 5) * 16
#: Seconds of one plant's evaluation per grid point, over ``n^2`` (measured: UR5, 6 joints,
#: 200 points, ~3 ms per plant and evaluation on the 2-core machine); a floor of the cost.
_SECONDS_PER_POINT = 1e-6
#: Longest search :func:`tune` starts [s]: a day.
MAX_SEARCH_SECONDS = 86400.0


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far [MB] (``getrusage``; Linux reports kB)."""
    import resource
    import sys

    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / (1024.0 * 1024.0) if sys.platform == "darwin" else rss / 1024.0


def check_budget(n: int, plants: int, starts: int, maxfev: int, points: int = 200) -> None:
    """Refuse a search that cannot finish: its memory above what is free, or over a day.

    A floor of the cost (the context's responses; every evaluation on every plant), so what
    is refused could not finish; what passes may still be slow.

    Raises
    ------
    FieldError
        ``plants`` (memory) or ``starts`` (time), naming the estimate.
    """
    from .executors import available_memory

    per_plant = _BYTES_PER_POINT * points * n * n
    need = per_plant * plants
    free = available_memory()
    if need > free:
        raise FieldError("plants", f"{{name}} = {plants - 1} (+ the nominal) needs at least "
                                   f"{need / 1e9:.3g} GB for the plants' frequency responses "
                                   f"({per_plant / 1e6:.3g} MB each), more than the "
                                   f"{free / 1e9:.3g} GB available: give fewer plants")
    secs = _SECONDS_PER_POINT * points * n * n * plants * starts * maxfev
    if secs > MAX_SEARCH_SECONDS:
        raise FieldError("starts", f"{{name}} = {starts} of up to {maxfev} evaluations on "
                                   f"{plants} plants would take at least {secs / 3600:.3g} h "
                                   f"(more than {MAX_SEARCH_SECONDS / 3600:g} h): give fewer "
                                   f"starts or plants")


@dataclass
class TuneResult:
    """What :func:`tune` found and verified.

    Attributes
    ----------
    structure : Structure
    values : ndarray, shape (len(structure.names),)
        The tuned parameters.
    lam : float or ndarray, shape (n,)
        FL bandwidth [rad/s]: shared, or one per joint (``PerJoint(..., lam="per_joint")``).
    K : control.TransferFunction, list of them, or None
        The outer controller (negative feedback on ``e``): SISO, copied on every joint, or
        one per joint (:class:`~rrr_pin.control.structures.PerJoint`).
    rate : float
        Sampling rate [Hz] the law was tuned and verified at (Tustin ``K``).
    table : list of dict
        Per requirement: ``name``, ``unit``, ``sense``, ``target``, ``achieved`` (the grid
        value the tuner saw), ``verified`` (exact), ``method``, ``normalized`` (of the
        verified value, <= 1 met), ``met``; the delay and the actuator add ``simulated`` (the
        nominal plant's breaking point by :func:`~rrr_pin.campaign.stress.breaking_point`) and
        ``predicted_nominal`` (the exact linear prediction on that plant).
    objective : float
        Worst normalized requirement on the grid at the best point.
    status : str
        ``"met"`` or ``"trade-off"`` (some requirement not met).
    tradeoff : dict or None
        At a trade-off: ``binding`` (the requirements whose normalized value is within 2 % of
        the worst) and ``unmet``.
    starts : list of dict
        Per start: its initial point, best objective and evaluations.
    info : dict
        Robot, plant set, home, fixed effects, reference, seconds, and ``peak_rss_mb``: the
        process's peak resident memory [MB] when the design was verified.
    """

    structure: object
    values: np.ndarray
    lam: float
    K: object
    rate: float
    table: list
    objective: float
    status: str
    tradeoff: dict | None
    starts: list
    info: dict = field(default_factory=dict)

    def law(self, nominal, name: str = "tuned"):
        """Return the tuned law on ``nominal`` (continuous; run it sampled at ``rate``)."""
        return law_of(nominal, self.lam, self.K, name)

    def to_dict(self) -> dict:
        """Return the ``design.json`` record (``lam_rad_s`` a list when per joint)."""
        from ..control.laws.tracking import lam_record

        return {"format": DESIGN_FORMAT, "law": "tuned", "lam_rad_s": lam_record(self.lam),
                "K": k_record(self.K),
                "rate_hz": self.rate, "structure": self.structure.to_dict(self.values),
                "requirements": self.table, "objective": self.objective,
                "status": self.status, "tradeoff": self.tradeoff, "starts": self.starts,
                **self.info}

    def lines(self) -> list[str]:
        """Return a printable summary: the law and the requirement table."""
        lam = (f"{self.lam:.4g}" if np.ndim(self.lam) == 0 else
               "[" + ", ".join(f"{x:.4g}" for x in self.lam) + "] (per joint)")
        out = [f"tuned {self.structure.kind} on {self.info.get('robot')}: lam = "
               f"{lam} rad/s, {_k_text(self.K)}, at {self.rate:g} Hz; status "
               f"{self.status} (worst normalized {self.objective:.3g})"]
        out.append(f"{'requirement':<20}{'target':>12}{'achieved':>12}{'verified':>12}"
                   f"{'simulated':>12}  met")
        for row in self.table:
            sim = row.get("simulated")
            out.append(f"{row['name']:<20}{number_text(row['target']):>12}{number_text(row['achieved']):>12}"
                       f"{number_text(row['verified']):>12}{number_text(sim):>12}  "
                       f"{'yes' if row['met'] else 'NO'}")
        if self.tradeoff:
            out.append(f"trade-off: binding {', '.join(self.tradeoff['binding'])}; unmet "
                       f"{', '.join(self.tradeoff['unmet']) or 'none'}")
            out += [f"  not met: {text}" for text in self.tradeoff.get("failures", [])]
        return out


def _k_text(K):
    if K is None:
        return "K = 0"
    if isinstance(K, list | tuple):
        return "; ".join(f"joint {j + 1}: {_k_text(k)}" for j, k in enumerate(K))
    num = np.asarray(K.num[0][0], float).ravel()
    den = np.asarray(K.den[0][0], float).ravel()
    return f"K = [{', '.join(f'{c:.5g}' for c in num)}] / [{', '.join(f'{c:.5g}' for c in den)}]"


def _check_requirements(requirements, nominal, fixed) -> list:
    reqs = list(requirements)
    if not reqs:
        raise FieldError("requirements", "{name}: give at least one requirement")
    seen = set()
    for r in reqs:
        if not isinstance(r, Requirement):
            raise TypeError(f"a requirement must subclass rrr_pin.campaign.requirements."
                            f"Requirement, got {type(r).__name__}")
        key = (r.name, getattr(r, "joint", None))
        if key in seen:
            raise FieldError("requirements", f"{{name}}: {r.name} given twice (two targets "
                                             f"for one value contradict by construction)")
        seen.add(key)
        joint = getattr(r, "joint", None)
        if joint is not None and joint not in nominal.joint_names:
            raise FieldError("requirements", f"{{name}}: {r.name} on joint {joint!r}, which "
                                             f"{nominal.name} does not have (joints: "
                                             f"{', '.join(nominal.joint_names)})")
        if isinstance(r, DelayMargin) and "delay" in fixed:
            raise FieldError("requirements", "{name}: delay_margin with a delay held fixed "
                                             "contradicts by construction")
        if isinstance(r, ActuatorBandwidth) and "actuator" in fixed:
            raise FieldError("requirements", "{name}: actuator_bandwidth with an actuator "
                                             "held fixed contradicts by construction")
    return reqs




def tune(robot, structure, requirements, plants=20, *, seed: int = 0, tolerances=None,
         reference=None, rate: float = 1000.0, fixed=None, starts: int = 4,
         maxfev: int | None = None, verify: bool = True, simulate: bool = True,
         duration: float = 4.0, stress_settings=None,
         search: str = "nelder-mead", block: int | None = 32,
         progress=None) -> TuneResult:
    """Tune ``structure`` on ``robot`` against ``requirements`` over a plant set, and verify.

    Parameters
    ----------
    robot : Plant
        The nominal model (the law's), e.g. ``load_robot("ur5")``.
    structure : Structure
        What may change (:mod:`rrr_pin.control.structures`).
    requirements : sequence of Requirement
        Targets (:mod:`rrr_pin.campaign.requirements`).
    plants : int or sequence of Plant
        The plant set: a count of uncertain plants drawn as the study draws them
        (``robot.perturbed(default_rng([seed, k]), tolerances)``), the nominal added first;
        or the plants themselves.
    seed : int
        Seed of the drawn plants and of the random starts.
    tolerances : UncertaintySet, optional
        Default the paper's 20 % inertia / 5 % length.
    reference : Reference, optional
        The tracking reference (default: the study's sinusoid).
    rate : float
        Sampling rate of the law [Hz].
    fixed : dict, optional
        Effects held in every evaluation, ``{"delay": s, "actuator": rad/s}``.
    starts : int
        Number of starts (the structure's initial point, then log-uniform random points).
    maxfev : int, optional
        Evaluations per start (default ``150 * (number of parameters + 1)``).
    verify, simulate : bool
        Verify exactly; with ``simulate``, also the simulated values (peak torque, error
        ratio, stress breaking points).
    duration : float
        Simulated time of the tracking runs [s].
    search : {"nelder-mead", "minimax"}
        The search per start: scipy's bounded Nelder-Mead on the worst normalized value, or
        :func:`rrr_pin.campaign.minimax.minimax` (trust-region linear programs on the
        requirements' linearizations, the max kept explicit); both get ``maxfev``.
    block : int or None
        Plants evaluated together (None: all at once). What one evaluation holds grows with
        the block, not with the number of plants; the result is the same for every block
        (each estimate is the worst of its blocks'; the pooled error ratio sums its energies
        block by block, equal to rounding).
    progress : callable, optional
        ``progress(done, total, start, best)`` after each evaluation: evaluations done and
        the most there can be (``starts * maxfev``; a start that converges early counts as
        finished), the start (1-based) and the best objective so far.

    Returns
    -------
    TuneResult

    Raises
    ------
    FieldError
        A structure with no free parameter, no requirement, a requirement twice, on a joint
        the arm lacks, or contradicting a fixed effect.
    TuneError
        No point of the structure stabilizes every plant, or a requirement no controller can
        meet (the peak torque the reference itself needs); ``.result`` is the best point.
    """
    from scipy.optimize import minimize

    from ..control.references import default_reference
    from .stress import check_fixed

    t0 = time.perf_counter()
    names = structure.names
    if not names:
        raise FieldError("structure", f"{{name}}: {type(structure).__name__} has no free "
                                      f"parameter (lam fixed at {structure.lam} rad/s): "
                                      f"nothing to tune")
    rate = check_rate("rate", rate)
    starts = check_count("starts", starts, 1)
    if block is not None:
        block = check_count("block", block, 1)
    if search not in ("nelder-mead", "minimax"):
        raise FieldError("search", f"{{name}} must be 'nelder-mead' or 'minimax', got "
                                   f"{search!r}")
    fixed = check_fixed(fixed)
    reqs = with_default_requirements(_check_requirements(requirements, robot, fixed))
    effects = design_effects(reqs, fixed)
    structure.check_joints(robot.name, robot.joint_names)
    maxfev = maxfev or 150 * (len(names) + 1)
    if isinstance(plants, int | np.integer):
        count = check_count("plants", plants)
        check_budget(robot.nq, count + 1, starts, maxfev)
        tol = tolerances or design_tolerances()
        check_plant_set(tol)
        plant_list = [robot] + [robot.perturbed(np.random.default_rng([int(seed), k]), tol)[0]
                                for k in range(count)]
        plant_info = {"samples": count, "seed": int(seed), "tolerances": tol.as_settings(),
                      "nominal_included": True}
    else:
        plant_list = list(plants)
        plant_info = {"given": len(plant_list)}
    reference = reference or default_reference(robot)
    ctx = _context(robot, plant_list, reference, rate, fixed, duration, effects)
    loops, home = ctx.loops, ctx.loops.home
    for r in reqs:
        r.prepare(ctx)
    ctx.block = block
    blocks = [(b, ctx.subset(b)) for b in ctx.blocks()]

    bounds = np.log(np.array(structure.bounds(), dtype=float))
    cache = {}

    def evaluate(x):
        """``(objective, estimates or None)`` at ``x``; only these numbers are cached."""
        key = tuple(np.round(x, 12))
        if key in cache:
            return cache[key]
        values = np.exp(np.clip(x, bounds[:, 0], bounds[:, 1]))
        lam, K = structure.split(values)
        out = _estimates(ctx, blocks, reqs, lam, K, effects)
        cache[key] = out   # the numbers only: no response is kept (memory)
        report(out[0])
        return out

    rng = np.random.default_rng([int(seed), 7919])
    x0s = [np.clip(np.log(structure.initial()), bounds[:, 0], bounds[:, 1])]
    x0s += [rng.uniform(bounds[:, 0], bounds[:, 1]) for _ in range(starts - 1)]
    best, runs = None, []
    done = [0, 1, math.inf]         # evaluations, start, best objective

    def report(f):
        done[0] += 1
        done[2] = min(done[2], f)
        if progress is not None:
            progress(min(done[0], starts * maxfev), starts * maxfev, done[1], done[2])
    def normalized(x):   # the vector whose max is the objective (minimax search)
        f, vals = evaluate(x)
        return np.full(len(reqs), f) if vals is None else \
            np.array([r.normalized(v) for r, v in zip(reqs, vals, strict=True)])

    for x0 in x0s:
        if search == "minimax":
            from .minimax import minimax

            xs, fun, nfev = minimax(normalized, x0, bounds, maxfev)
        else:
            res = minimize(lambda x: evaluate(x)[0], x0, method="Nelder-Mead",
                           bounds=list(map(tuple, bounds)),
                           options={"maxfev": maxfev, "xatol": 1e-4, "fatol": 1e-6,
                                    "adaptive": len(names) > 3})
            xs, fun, nfev = res.x, float(res.fun), int(res.nfev)
        runs.append({"initial": dict(zip(names, np.exp(x0).tolist(), strict=True)),
                     "objective": float(fun), "evaluations": int(nfev)})
        if best is None or fun < best[0]:
            best = (float(fun), xs)
        done[0], done[1] = done[1] * maxfev, done[1] + 1   # an early stop ends its share
    objective, x = best
    values = np.exp(np.clip(x, bounds[:, 0], bounds[:, 1]))
    lam, K = structure.split(values)
    _, estimates = evaluate(x)
    ev = _Eval(ctx, lam, K)   # the best point's, on every plant, for the verification
    info = {"robot": robot.name, "joints": list(robot.joint_names), "plants": plant_info,
            "home_rad": home.tolist(), "fixed": fixed,
            "effects": {**effects, "note": "every requirement is evaluated, and every plant "
                                           "simulated, with these effects (--with and the "
                                           "delay and actuator the requirements state)"},
            "reference": reference.to_dict(),
            "grid_rad_s": [float(loops.omega[0]), float(loops.omega[-1]),
                           int(loops.omega.size)],
            "search": ("minimax: trust-region linear programs (scipy HiGHS), log scale, "
                       "seeded starts" if search == "minimax" else
                       "scipy Nelder-Mead (bounded, log scale), seeded starts"),
            "seconds_search": time.perf_counter() - t0}
    if estimates is None:
        result = TuneResult(structure, values, lam, K, rate, [], objective, "unstable",
                            None, runs, info)
        raise TuneError(f"no point of the {structure.kind} structure found stabilizes every "
                        f"plant of the set (with {effects or 'no effects'}): best point "
                        f"{dict(zip(names, values.round(6).tolist(), strict=True))}, largest "
                        f"closed-loop spectral radius {objective - _UNSTABLE:.4g} (>= 1)",
                        result)
    table = []
    for r, est in zip(reqs, estimates, strict=True):
        row = {**r.to_dict(), "achieved": est, "verified": None, "method": None}
        if verify and (simulate or not isinstance(r, PeakTorque | ErrorRatio)):
            row["verified"], row["method"] = r.verify(ctx, ev)
        else:
            row["method"] = "not verified (" + ("verify" if not verify else "simulate") + \
                "=False): met and normalized are the estimate's"
        value = row["verified"] if row["verified"] is not None else est
        row["normalized"] = r.normalized(value)
        # a non-finite value is never met (inf error ratio of a zero error, NaN of a divergence)
        row["met"] = bool(math.isfinite(value) and row["normalized"] <= 1.0 + 1e-9)
        if verify and simulate and isinstance(r, DelayMargin | ActuatorBandwidth):
            row.update(_stress_row(ctx, ev, r, stress_settings))
        table.append(row)
    failures = plant_failures(ctx, ev, reqs, table) if verify else []
    if verify and simulate:
        failures += simulated_failures(ctx, ev)
    norms = [row["normalized"] for row in table]
    worst = max(norms)
    status = "met" if all(row["met"] for row in table) and not failures else "trade-off"
    info["failures"] = failures
    tradeoff = None if status == "met" else {
        "binding": [row["name"] for row in table if row["normalized"] >= worst / 1.02],
        "unmet": [row["name"] for row in table if not row["met"]],
        "failures": [f["text"] for f in failures],
        "best_point": dict(zip(names, values.tolist(), strict=True))}
    info["seconds"] = time.perf_counter() - t0
    info["peak_rss_mb"] = peak_rss_mb()
    result = TuneResult(structure, values, lam, K, rate, table, objective, status, tradeoff,
                        runs, info)
    floor = [r for r in reqs if isinstance(r, PeakTorque)
             and r.normalized(r.estimate(ctx, ev)) > 1.0]
    if floor:
        raise TuneError(f"peak_torque = {floor[0].target}: the reference itself needs "
                        f"{floor[0].estimate(ctx, ev):.4g} times the limit on the worst plant "
                        f"(inverse dynamics, whatever the controller); best point "
                        f"{dict(zip(names, values.round(6).tolist(), strict=True))}", result)
    return result


def _stress_row(ctx, ev, req, settings) -> dict:
    """Return the simulated breaking point on the nominal plant and its exact prediction."""
    from .stress import StressSettings, breaking_point

    effect = "delay" if isinstance(req, DelayMargin) else "actuator"
    nominal_only = [0]
    # the effects the requirement holds with it (its own, else the fixed ones), in the
    # prediction and in the simulation alike
    wa = req._wa(ctx) if effect == "delay" else None
    delay = req._delay(ctx) if effect == "actuator" else 0.0
    held = {k: v for k, v in (ctx.effects or ctx.fixed).items() if k != effect}
    if wa:
        held["actuator"] = wa
    if delay:
        held["delay"] = delay
    if effect == "delay":
        def stable(tau):
            return ctx.loops.spectral_radius(ev.law, tau, wa, plants=nominal_only)[0] < 1.0
        pred = _bisect_up(stable, req.target, 1e-4)
    else:
        def stable(w):
            return ctx.loops.spectral_radius(ev.law, delay, w, plants=nominal_only)[0] < 1.0
        pred = _bisect_down(stable, req.target, 1e-4)
    settings = settings or StressSettings()
    law = law_of(ctx.nominal, ev.lam, ev.K)
    found = breaking_point(ctx.nominal, law, ctx.reference, effect, settings,
                           guess=pred if math.isfinite(pred) and pred > 0 else None,
                           fixed=held)
    return {"simulated": found["simulated"], "simulated_status": found["status"],
            "simulated_bracket": found["bracket"], "predicted_nominal": pred,
            "simulated_with": held}

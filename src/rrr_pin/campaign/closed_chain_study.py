r"""The paper's section-5 study on a parallel mechanism (the 5-bar or the Delta).

Every law of ``controllers`` (default: FL alone, ``lam = 100`` rad/s, eq. (20), against
H-infinity + FL, ``lam = 45`` rad/s with the paper's reduced loop-shaping controller, eq. (18);
any built-in of :data:`rrr_pin.control.catalog.LAWS`, and the user's own laws), each on the
reduced model of the nominal mechanism (:mod:`rrr_pin.control.closed_chain`), each run on the
nominal plant and on
``samples`` seeded uncertain plants (:func:`rrr_pin.model.mechanisms.perturb_mechanism`: 20 %
masses, 5 % lengths, as the paper's sec. 5), every plant integrated on Pinocchio's constraint
dynamics (:mod:`rrr_pin.sim.closed_chain`).

References (actuated coordinates):

* 5-bar: a circle of the tip, 50 mm radius through ``home``, once per ``duration`` with a
  quintic time law, by the closed-form inverse kinematics every 5 ms and a C2 spline
  (:func:`circle_reference`);
* Delta: the adept cycle, a pick-and-place of the platform 25 mm up, 305 mm across, 25 mm down
  and back, each segment rest-to-rest with a quintic time law, turned into actuated angles by
  the closed-form inverse kinematics every 5 ms and joined by a C2 spline
  (:func:`adept_reference`).

The claims checked are the paper's conclusions (sec. 5-6): equivalent on the nominal model,
better (the paper: about ten times) on uncertain models, with basically the same control
effort (:func:`claims`). They compare ``fl`` with ``hinf``: without both among the laws there
is no verdict (``claims`` is empty and ``claims_note`` says why), never a substitute pair.

Each uncertain plant is also certified (``certify``, default on): the frozen-configuration
nu-gap of the feedback-linearized uncertain mechanism against ``b(Gs, Ks)`` of the
H-infinity design, at ``certificate_points`` configurations of the reference
(:func:`rrr_pin.robust.certificates.chain_certificate`).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from ..control.catalog import make_law
from ..control.closed_chain import CHAIN_LAWS, reset_closure
from ..control.effects import PlantEffects
from ..control.laws import SampledLaw, check_law
from ..control.references import SplineReference
from ..model.closed_chain import LoopClosureError, SingularConfiguration, load_closed_chain
from ..model.mechanisms import (
    MECHANISMS,
    DeltaParams,
    FiveBarParams,
    delta_ik,
    fivebar_ik,
    perturb_mechanism,
)
from ..robust.certificates import CertificateSpec
from ..robust.loopshaping import design
from ..sim.chain_compiled import chain_engine
from ..sim.closed_chain import ConstraintDrift, simulate_closed_chain
from ..sim.trajectory import SimulationDiverged
from ..validation import check_count, check_positive

__all__ = ["ChainStudyConfig", "ChainStudyResult", "run_chain_study", "chain_reference",
           "adept_reference", "adept_point", "circle_reference", "circle_point", "claims",
           "ADEPT_MM", "NOMINAL_FLOOR", "CIRCLE_RADIUS", "FAILURES"]

#: RMS tracking error [rad] below which two laws on the exact model count as equivalent
#: (both sit at the 1 kHz sampling floor, ~1e-6 rad, on motions of about 0.1 rad).
NOMINAL_FLOOR = 1e-4

#: Radius [m] of the 5-bar's task-space circle.
CIRCLE_RADIUS = 0.05

#: The adept cycle's legs [mm]: up, across, down.
ADEPT_MM = (25.0, 305.0, 25.0)

#: What ends a run as "failed" (recorded in its row; the study goes on): a type-II singularity
#: met, a loop that would not close, a drift above its bound, a divergence, a singular matrix.
#: Anything else (a refusal of the settings, a bug) propagates.
FAILURES = (SingularConfiguration, LoopClosureError, ConstraintDrift, SimulationDiverged,
            np.linalg.LinAlgError)


@dataclass(frozen=True)
class ChainStudyConfig:
    """Settings of a closed-chain study, recorded whole in its results.

    Parameters
    ----------
    mechanism : {"fivebar", "delta"} or FiveBarParams or DeltaParams
        A built-in mechanism by name, or your own parameter set (its dimensions and masses;
        the uncertain plants perturb it, and the reference is its own circle or adept cycle).
    samples : int
        Uncertain plants (the paper: 10).
    seed : int
        Seed of the uncertain plants.
    duration : float
        Simulated time [s]; for the Delta, the adept cycle's period (go and back).
    rate : float or None
        Control rate [Hz] (zero-order hold, Tustin ``K``); None: continuous-time laws.
    inertia, length : float
        Relative tolerances of masses and lengths.
    lam_fl, lam_hinf : float
        FL bandwidths [rad/s] of ``fl`` and of the H-infinity laws (the paper's 100 and 45).
    controllers : tuple of str
        Built-in laws by name (:data:`rrr_pin.control.catalog.LAWS`), in order; default the
        paper's ``("fl", "hinf")``.
    full_order : bool
        ``hinf`` (and ``hinf_aw``) with the full-order ``K`` of the design instead of the
        reduced eq. (18); the certificate then uses the full ``Ks``.
    torque_limit : tuple of float or None
        Actuator limits [N m] per actuated joint (a scalar is every joint's): every plant
        saturates there (``PlantEffects(torque_limit=...)``, run by the Python engine, which
        records ``info["saturation"]``), and ``hinf_aw`` is told them (required for it). None:
        ideal actuators.
    certify : bool
        Certify each uncertain plant (module docstring).
    certificate_points : int
        Frozen configurations per plant (>= 1), evenly spaced over the run.
    engine : {"auto", "python", "compiled"}
        Engine of every run (:func:`rrr_pin.sim.closed_chain.simulate_closed_chain`); ``auto``
        runs ``fl`` and ``hinf`` compiled and the other laws in Python (each run records it).
    """

    mechanism: str = "fivebar"
    samples: int = 10
    seed: int = 0
    duration: float = 2.0
    rate: float | None = 1000.0
    inertia: float = 0.2
    length: float = 0.05
    lam_fl: float = 100.0
    lam_hinf: float = 45.0
    controllers: tuple = ("fl", "hinf")
    full_order: bool = False
    torque_limit: tuple | None = None
    certify: bool = True
    certificate_points: int = 8
    engine: str = "auto"

    def __post_init__(self) -> None:
        if not isinstance(self.mechanism, (FiveBarParams, DeltaParams)) and (
                self.mechanism not in MECHANISMS):
            raise ValueError(f"mechanism must be one of {', '.join(MECHANISMS)} or a "
                             f"FiveBarParams / DeltaParams, got {self.mechanism!r}")
        check_count("samples", self.samples)
        check_count("seed", self.seed)
        check_positive("duration", self.duration, unit="s")
        if self.rate is not None:
            check_positive("rate", self.rate, unit="Hz")
        for name in ("inertia", "length"):
            value = check_positive(name, getattr(self, name), allow_zero=True)
            if value >= 1.0:
                raise ValueError(f"{name} must be a relative tolerance in [0, 1), got {value}")
        for name in ("lam_fl", "lam_hinf"):
            check_positive(name, getattr(self, name), unit="rad/s")
        names = self.controllers
        if isinstance(names, str) or not isinstance(names, (tuple, list)) or not all(
                isinstance(x, str) and x for x in names):
            raise ValueError(f"controllers must be a tuple of built-in law names, got "
                             f"{names!r}")
        object.__setattr__(self, "controllers", tuple(names))
        unknown = [x for x in names if x not in CHAIN_LAWS]
        if unknown:
            raise ValueError(f"controllers: {', '.join(map(repr, unknown))} not a built-in "
                             f"law with a closed-chain form ({', '.join(CHAIN_LAWS)}); your own "
                             f"laws go to run_chain_study(config, laws=[...])")
        if "hinf_aw" in names and self.torque_limit is None:
            raise ValueError("controllers: hinf_aw on a closed chain needs torque_limit [N m] "
                             "(an MJCF motor carries no effort limit)")
        if self.torque_limit is not None:
            limit = tuple(float(x) for x in np.atleast_1d(self.torque_limit))
            if not limit or not all(math.isfinite(x) and x > 0.0 for x in limit):
                raise ValueError(f"torque_limit must be finite limits > 0 [N m], got "
                                 f"{self.torque_limit!r}")
            object.__setattr__(self, "torque_limit", limit)
        check_count("certificate_points", self.certificate_points, 1)
        if self.engine not in ("auto", "python", "compiled"):
            raise ValueError(f"engine must be one of auto, python, compiled for a closed chain, "
                             f"got {self.engine!r}")


def _quintic(s: np.ndarray) -> np.ndarray:
    s = np.clip(s, 0.0, 1.0)
    return s ** 3 * (10.0 - 15.0 * s + 6.0 * s * s)


def adept_point(params: DeltaParams, t, period: float) -> np.ndarray:
    """Platform position [m], shape (len(t), 3), of the adept cycle at times ``t`` [s].

    Start at ``(-0.1525, 0, home_z)``; up 25 mm, across 305 mm along ``x``, down 25 mm in the
    first half period (segment times 0.2, 0.6, 0.2 of it), back the same way in the second.
    """
    up, across, _ = (v / 1000.0 for v in ADEPT_MM)
    corners = np.array([[-across / 2, 0.0, params.home_z],
                        [-across / 2, 0.0, params.home_z + up],
                        [across / 2, 0.0, params.home_z + up],
                        [across / 2, 0.0, params.home_z]])
    corners = np.vstack([corners, corners[-2::-1]])
    half = 0.5 * period
    edges = np.cumsum([0.0] + [0.2 * half, 0.6 * half, 0.2 * half] * 2)
    t = np.atleast_1d(np.asarray(t, dtype=float))
    out = np.empty((t.shape[0], 3))
    for k, tk in enumerate(t):
        i = int(np.clip(np.searchsorted(edges, tk, side="right") - 1, 0, 5))
        s = _quintic(np.array((tk - edges[i]) / (edges[i + 1] - edges[i])))
        out[k] = corners[i] + s * (corners[i + 1] - corners[i])
    return out


def adept_reference(params: DeltaParams, period: float = 2.0,
                    step: float = 0.005) -> SplineReference:
    """Return the adept cycle as an actuated-angle reference, by the Delta's inverse kinematics.

    :func:`rrr_pin.model.mechanisms.delta_ik` of :func:`adept_point` every ``step`` [s],
    joined by a clamped C2 spline (at rest at both ends, as the cycle is).
    """
    t = np.linspace(0.0, period, int(round(period / step)) + 1)
    W = np.array([delta_ik(params, p) for p in adept_point(params, t, period)])
    return SplineReference(times=t, waypoints=W,
                           source=f"adept cycle {ADEPT_MM[0]:g}/{ADEPT_MM[1]:g}/"
                                  f"{ADEPT_MM[2]:g} mm, period {period:g} s, IK every "
                                  f"{step * 1000:g} ms")


def circle_point(params: FiveBarParams, t, period: float, radius: float = CIRCLE_RADIUS
                 ) -> np.ndarray:
    """Tip position ``(x, z)`` [m], shape (len(t), 2), of the 5-bar's circle at times ``t``.

    A circle of ``radius`` through ``home``, its centre ``radius`` above it, run once in
    ``period`` with a quintic time law (at rest at both ends).
    """
    s = _quintic(np.atleast_1d(np.asarray(t, dtype=float)) / period)
    a = 2.0 * math.pi * s
    return np.column_stack([params.home_x + radius * np.sin(a),
                            params.home_z + radius - radius * np.cos(a)])


def circle_reference(params: FiveBarParams, period: float = 2.0,
                     step: float = 0.005) -> SplineReference:
    """Return the 5-bar's circle as an actuated-angle reference, by its inverse kinematics.

    :func:`rrr_pin.model.mechanisms.fivebar_ik` of :func:`circle_point` every ``step`` [s],
    joined by a clamped C2 spline.
    """
    t = np.linspace(0.0, period, int(round(period / step)) + 1)
    W = np.array([fivebar_ik(params, p) for p in circle_point(params, t, period)])
    return SplineReference(times=t, waypoints=W,
                           source=f"tip circle of radius {CIRCLE_RADIUS * 1000:g} mm through "
                                  f"home, period {period:g} s, IK every {step * 1000:g} ms")


def chain_reference(chain, duration: float):
    """Return the study's reference for ``chain`` (module docstring)."""
    if isinstance(chain.params, FiveBarParams):
        return circle_reference(chain.params, period=duration)
    return adept_reference(chain.params, period=duration)


def _metrics(traj) -> dict:
    e = traj.q - traj.r
    return {"rms_error_rad": float(np.sqrt(np.mean(e * e))),
            "max_error_rad": float(np.max(np.abs(e))),
            "rms_tau_Nm": float(np.sqrt(np.mean(traj.tau * traj.tau))),
            "drift_m": float(traj.info["drift_m"]), "status": "ok",
            **({"saturated_fraction": traj.info["saturation"]["fraction"]}
               if "saturation" in traj.info else {})}


@dataclass
class ChainStudyResult:
    """Outcome of :func:`run_chain_study`.

    Attributes
    ----------
    config : ChainStudyConfig
    names, labels : list of str
        The laws' keys and display names, in order (the built-ins of ``config.controllers``,
        then the user's laws).
    metrics : list of dict
        Per plant (nominal first): ``{"plant", "factors", law name: metrics}``, metrics with
        ``rms_error_rad``, ``max_error_rad``, ``rms_tau_Nm``, ``drift_m``, ``status``; an
        uncertain plant also has ``"certificate"`` (``certified``, ``nugap_max``, ``b``) when
        ``config.certify``.
    trajectories : list of dict
        Per plant, law name -> Trajectory (None where the run failed).
    reference : str
        What the reference is.
    claims : list of dict
        :func:`claims` (empty without both ``fl`` and ``hinf``).
    claims_note : str
        Why there are no claims, or "".
    laws : list of dict
        Each law's ``describe()`` (what ran).
    certificate : dict or None
        The certificate's design (:meth:`CertificateSpec.to_dict`), None without ``certify``.
    """

    config: ChainStudyConfig
    names: list
    labels: list
    metrics: list
    trajectories: list = field(repr=False)
    reference: str = ""
    claims: list = field(default_factory=list)
    claims_note: str = ""
    laws: list = field(default_factory=list)
    certificate: dict | None = None
    torque_limit: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """Per law and certificates: ``{"laws": {name: {...}}, "certificates": {...}}``.

        Per law: ``nominal_rms_error_rad``, and over the uncertain plants (NaN if a run
        failed, never dropped) ``mean_rms_error_rad``, ``mean_rms_tau_Nm`` and ``failed``
        (how many runs failed). Certificates (when computed): ``certified`` and ``checked``
        counts, ``nugap_max`` (largest over the plants) and ``b``.
        """
        unc = self.metrics[1:]
        laws = {}
        for name in self.names:
            m = [row[name] for row in unc]
            laws[name] = {"nominal_rms_error_rad": self.metrics[0][name]["rms_error_rad"],
                          "mean_rms_error_rad": float(np.mean([x["rms_error_rad"] for x in m]))
                          if m else math.nan,
                          "mean_rms_tau_Nm": float(np.mean([x["rms_tau_Nm"] for x in m]))
                          if m else math.nan,
                          "failed": sum(1 for x in m if x["status"] != "ok")}
            if self.config.torque_limit is not None:  # NaN where a run failed
                laws[name]["nominal_saturated_fraction"] = self.metrics[0][name].get(
                    "saturated_fraction", math.nan)
                laws[name]["mean_saturated_fraction"] = float(np.mean(
                    [x.get("saturated_fraction", math.nan) for x in m])) if m else math.nan
        out = {"laws": laws}
        certs = [row["certificate"] for row in unc if "certificate" in row]
        if certs:
            out["certificates"] = {"certified": sum(1 for c in certs if c["certified"]),
                                   "checked": len(certs),
                                   "nugap_max": max(c["nugap_max"] for c in certs),
                                   "b": certs[0]["b"]}
        return out

    def to_dict(self) -> dict:
        """JSON-ready record (trajectories left out)."""
        return {"config": asdict(self.config), "laws": dict(zip(self.names, self.labels,
                                                                  strict=True)),
                "law_descriptions": self.laws, "reference": self.reference,
                "plants": self.metrics, "claims": self.claims, "claims_note": self.claims_note,
                "certificate": self.certificate, "torque_limit": self.torque_limit,
                "summary": self.summary()}


def _failed(exc) -> dict:
    return {"rms_error_rad": math.nan, "max_error_rad": math.nan, "rms_tau_Nm": math.nan,
            "drift_m": math.nan, "status": f"failed: {exc}"}


def _builtin_laws(config: ChainStudyConfig, d) -> list:
    """Build the laws of ``config.controllers``, each on its own nominal mechanism."""
    K = None if d is None else d.K_full if config.full_order else d.K_reduced
    # Each law gets its own nominal model: its loop-closure seed follows its own runs.
    return [make_law(name, load_closed_chain(config.mechanism), K=K, lam_fl=config.lam_fl,
                     lam_hinf=config.lam_hinf, torque_limit=config.torque_limit)
            for name in config.controllers]


def run_chain_study(config: ChainStudyConfig = ChainStudyConfig(), progress=None,
                    laws=()) -> ChainStudyResult:
    """Run every law on the nominal and uncertain mechanisms, and certify the uncertain ones.

    Parameters
    ----------
    config : ChainStudyConfig
    progress : callable, optional
        ``progress(done, total)`` after each plant.
    laws : sequence of ControlLaw or SampledLaw, optional
        The user's own laws, run after the built-ins of ``config.controllers`` (which may be
        empty), each on the actuated coordinates of the mechanism (``n == nq``); a law with a
        ``nominal`` closed chain has its loop-closure seed reset before each run.

    Returns
    -------
    ChainStudyResult

    Raises
    ------
    ValueError
        An unknown built-in name, one without a closed-chain form, ``hinf_aw`` without
        ``torque_limit``, no law at all, repeated names, or a law for another ``nq``.
    """
    nominal = load_closed_chain(config.mechanism)
    # the loop-shaping design, for the H-infinity laws' K and the certificate only
    needs_design = config.certify or {"hinf", "hinf_aw"} & set(config.controllers)
    d = design(lam=config.lam_hinf, n=nominal.nq) if needs_design else None
    laws = _builtin_laws(config, d) + list(laws)
    if not laws:
        raise ValueError("no control law: give config.controllers or laws")
    for law in laws:
        check_law(law, nominal.nq)
    names = [law.name for law in laws]
    dup = sorted({x for x in names if names.count(x) > 1})
    if dup:
        raise ValueError(f"control law names must be unique, repeated: {', '.join(dup)}")
    effects = None
    if config.torque_limit is not None:
        if len(config.torque_limit) not in (1, nominal.nq):
            raise ValueError(f"torque_limit: expected one value or {nominal.nq} (one per "
                             f"actuated joint of {nominal.name!r}), got "
                             f"{list(config.torque_limit)}")
        limit = config.torque_limit
        effects = PlantEffects(torque_limit=limit[0] if len(limit) == 1 else np.array(limit))
    if effects is not None and config.rate is None:
        raise ValueError("torque_limit acts on sampled laws (the plant clips the torque held "
                         "over each control period): give rate too")
    if config.engine == "compiled":
        # refused here, by name, before any run: a run's ValueError is recorded as "failed"
        for law in laws:
            run = law if config.rate is None else (
                law if isinstance(law, SampledLaw) else law.sampled(config.rate))
            chain_engine(nominal, run, "compiled", continuous=config.rate is None,
                         effects=effects)
    reference = chain_reference(nominal, config.duration)
    spec = CertificateSpec.from_design(d, points=config.certificate_points,
                                       reduced=not config.full_order) if config.certify \
        else None
    rng = np.random.default_rng(config.seed)
    plants = [(nominal, {})]
    for _ in range(config.samples):
        params, factors = perturb_mechanism(nominal.params, rng, config.inertia, config.length)
        plants.append((load_closed_chain(params), factors))
    metrics, trajectories = [], []
    for i, (plant, factors) in enumerate(plants):
        row = {"plant": "nominal" if i == 0 else f"sample{i - 1:03d}", "factors": factors}
        runs = {}
        for law in laws:
            reset_closure(law, reference)
            try:
                traj = simulate_closed_chain(plant, law, reference, config.duration,
                                             rate=config.rate, engine=config.engine,
                                             effects=effects)
            except FAILURES as exc:
                row[law.name] = _failed(exc)
                runs[law.name] = None
                continue
            row[law.name] = _metrics(traj)
            runs[law.name] = traj
        if spec is not None and i > 0:
            # its own nominal copy: the certificate walks the loop closure along the reference
            row["certificate"] = spec.certify(load_closed_chain(config.mechanism), plant,
                                              reference, config.duration)
        metrics.append(row)
        trajectories.append(runs)
        if progress is not None:
            progress(i + 1, len(plants))
    result = ChainStudyResult(config=config, names=names,
                              labels=[law.label or law.name for law in laws], metrics=metrics,
                              trajectories=trajectories, reference=reference.source,
                              laws=[law.describe() for law in laws],
                              certificate=None if spec is None else spec.to_dict())
    if "fl" in names and "hinf" in names:
        result.claims = claims(result)
    else:
        missing = [k for k in ("fl", "hinf") if k not in names]
        result.claims_note = (f"no verdict on the paper's claims: they compare fl with hinf, "
                              f"and {' and '.join(missing)} {'is' if len(missing) == 1 else 'are'}"
                              f" not among the laws ({', '.join(names)})")
    return result


def claims(result: ChainStudyResult) -> list[dict]:
    """Measure the paper's three conclusions: each ``{"claim", "value", "holds"}``.

    They compare the laws named ``fl`` and ``hinf`` (both must be in ``result.names``; the
    others are not part of the claims). ``holds`` is None (undetermined) when a run needed for
    it failed: no verdict from NaN.

    * nominal: the larger RMS error of the two laws on the nominal plant; holds if below
      :data:`NOMINAL_FLOOR` ("equivalent": both track the exact model to within it);
    * uncertain: mean over the uncertain plants of ``rms_fl / rms_hinf``; holds if > 1 (the
      paper measured about 10);
    * effort: mean over the uncertain plants of ``rms_tau_hinf / rms_tau_fl``; holds if in
      [0.9, 1.1] ("basically the same energy").

    Raises
    ------
    ValueError
        ``fl`` or ``hinf`` is not among the laws.
    """
    fl, hinf = "fl", "hinf"
    if fl not in result.names or hinf not in result.names:
        raise ValueError(f"the paper's claims compare fl with hinf; the laws are "
                         f"{', '.join(result.names)}")
    nom = result.metrics[0]
    unc = result.metrics[1:]

    def verdict(value, low, high):
        return None if not math.isfinite(value) else bool(low <= value <= high)

    # np.max, not max(): a NaN (a failed run) stays NaN whichever law it is
    worst = float(np.max([nom[fl]["rms_error_rad"], nom[hinf]["rms_error_rad"]]))
    out = [{"claim": f"nominal model: H-inf + FL and FL alone are equivalent (both RMS "
                     f"errors below {NOMINAL_FLOOR:g} rad)", "value": worst,
            "holds": verdict(worst, 0.0, NOMINAL_FLOOR)}]
    if unc:
        ratio = float(np.mean([m[fl]["rms_error_rad"] / m[hinf]["rms_error_rad"] for m in unc]))
        effort = float(np.mean([m[hinf]["rms_tau_Nm"] / m[fl]["rms_tau_Nm"] for m in unc]))
        out += [{"claim": "uncertain models: H-inf + FL tracks better (mean RMS error ratio "
                          "FL/H-inf > 1; the paper: about 10)", "value": ratio,
                 "holds": verdict(ratio, 1.0, math.inf)},
                {"claim": "uncertain models: with basically the same effort (mean RMS torque "
                          "ratio H-inf/FL in [0.9, 1.1])", "value": effort,
                 "holds": verdict(effort, 0.9, 1.1)}]
    return out

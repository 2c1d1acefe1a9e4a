"""The runner: any set of laws on one plant, the layer under the study and the campaign.

:class:`RunSettings` (frozen, recorded whole in every output) says how a run is simulated;
:func:`run_laws` runs every law of a list on one plant with one reference and returns each
law's trajectory or its divergence; :func:`run_metrics` reduces a trajectory to the figures
both the study and the Monte Carlo campaign report; :func:`error_ratios` compares every law with
a named baseline. :mod:`rrr_pin.campaign.study` and :mod:`rrr_pin.campaign.montecarlo` sit side
by side on this module and import nothing from each other.

The built-in laws are made by name with :func:`make_laws` (``"fl"``, ``"hinf"``, ``"pd"``,
``"hinf_aw"``), so the CLI's ``--controllers fl,hinf,pd`` and Python callers build the same
objects.
"""

from __future__ import annotations

import logging
import math
from dataclasses import asdict, dataclass

from ..control.catalog import BUILTIN_LAWS, make_law
from ..control.effects import PlantEffects, check_effects
from ..control.laws import check_law
from ..sim.engine_names import AUTO
from ..sim.engines import check_engine
from ..sim.simulation import check_run, reuse_preparation, simulate, simulate_batch, time_grid
from ..sim.trajectory import SimulationDiverged, Trajectory
from ..validation import check_positive, check_rate, check_vector

logger = logging.getLogger(__name__)

__all__ = [
    "RunSettings",
    "make_laws",
    "check_laws",
    "check_runs",
    "run_laws",
    "run_laws_batch",
    "run_metrics",
    "failure_text",
    "error_ratios",
    "ratio",
]

@dataclass(frozen=True)
class RunSettings:
    """How each closed-loop run is simulated (see :func:`rrr_pin.sim.simulation.simulate`).

    Parameters
    ----------
    duration : float, default 4
        Simulated time [s], > 0: a whole number of steps (``dt``, or ``1/rate``).
    dt : float, optional
        RK4 step [s] (plant sub-step for sampled laws, which must divide ``1/rate``), > 0.
        None: 1e-3 s, or for sampled laws the largest sub-step not above 1e-3 s that divides
        ``1/rate``; the field then holds the step used. Nothing is rounded: settings off the
        grid are refused (:func:`rrr_pin.sim.simulation.time_grid`).
    rate : float, optional
        Sampling rate of the laws [Hz]; None for continuous-time laws.
    method : str, default "tustin"
        Discretization of continuous laws' states when sampled.
    engine : {"auto", "python", "compiled"}, default "auto"
    limit_margin : float, default 0
        Slack beyond the joint limits before a run counts as diverged [rad].
    q0, qd0 : tuple of float, optional
        Initial state [rad, rad/s]; default on the reference.
    effects : PlantEffects, optional
        Unmodeled plant dynamics (:mod:`rrr_pin.control.effects`); sampled laws only (``rate``).
        A delay must be a whole number of plant sub-steps.
    force : bool, default False
        Accept runs above the work bounds of one run (``rrr_pin.sim.simulation.MAX_SUBSTEPS``
        RK4 steps, ``MAX_SAMPLES`` stored samples), refused otherwise when the settings are
        made. Not recorded by :meth:`to_dict`: it allows a run, it does not change its numbers.

    Raises
    ------
    ValueError
        A field out of range, settings off the time grid or above the work bounds (a
        :class:`~rrr_pin.validation.FieldError` naming the field).
    """

    duration: float = 4.0
    dt: float | None = None
    rate: float | None = None
    method: str = "tustin"
    engine: str = AUTO
    limit_margin: float = 0.0
    q0: tuple | None = None
    qd0: tuple | None = None
    effects: PlantEffects | None = None
    force: bool = False

    def __post_init__(self) -> None:
        check_positive("duration", self.duration, unit="s")
        if self.dt is not None:
            check_positive("dt", self.dt, unit="s")
        if self.rate is not None:
            check_rate("rate", self.rate)
        if not isinstance(self.force, bool):
            raise TypeError(f"force must be a bool, got {type(self.force).__name__}")
        grid = time_grid(self.duration, self.dt, self.rate, force=self.force)
        object.__setattr__(self, "dt", grid.h)
        check_engine(self.engine)
        check_positive("limit_margin", self.limit_margin, allow_zero=True, unit="rad")
        for key in ("q0", "qd0"):
            v = getattr(self, key)
            if v is not None:
                object.__setattr__(self, key, tuple(check_vector(key, v).tolist()))
        check_effects(self.effects)
        if self.effects is not None and self.effects.active and self.rate is None:
            raise ValueError("effects apply to sampled controllers only: give a rate")
        if self.effects is not None:
            self.effects.delay_substeps(grid.h)

    def simulate_kwargs(self) -> dict:
        """Keyword arguments of :func:`rrr_pin.sim.simulation.simulate`."""
        return {"dt": self.dt, "rate": self.rate, "method": self.method, "engine": self.engine,
                "limit_margin": self.limit_margin, "q0": self.q0, "qd0": self.qd0,
                "effects": self.effects, "force": self.force}

    def to_dict(self) -> dict:
        """JSON-ready settings (units in the key names)."""
        d = asdict(self)
        fx = self.effects.to_dict() if self.effects is not None else None
        if fx is not None and self.effects.delay:  # the delay as realized: d sub-steps h
            k = self.effects.delay_substeps(self.dt)
            fx["delay_s"], fx["delay_substeps"] = k * self.dt, k
        return {"duration_s": d["duration"], "dt_s": d["dt"], "rate_hz": d["rate"],
                "method": d["method"], "engine": d["engine"],
                "limit_margin_rad": d["limit_margin"],
                "q0_rad": list(d["q0"]) if d["q0"] is not None else None,
                "qd0_rad_s": list(d["qd0"]) if d["qd0"] is not None else None,
                "effects": fx}


def make_laws(names, nominal, *, K=None, lam_fl: float = 100.0,
              lam_hinf: float = 45.0, torque_limit=None, friction=None) -> list:
    """Build built-in laws by name, in the order given, from the registry ``catalog.LAWS``.

    Each name goes to :func:`rrr_pin.control.catalog.make_law`.

    Parameters
    ----------
    names : str or sequence of str
        Keys of :data:`BUILTIN_LAWS`, e.g. ``"fl,hinf,pd"`` or ``["fl", "hinf"]``.
    nominal : Robot
        The laws' model.
    K : control LTI, optional
        H-infinity controller for ``"hinf"``; default the paper's design for ``nominal.nq``
        joints (``design(lam=lam_hinf).K_reduced``).
    lam_fl, lam_hinf : float
        Bandwidths [rad/s] of ``"fl"`` and ``"hinf"``.
    torque_limit : float or array-like, shape (n,), optional
        Actuator limits [N m] of the laws that know them (``"hinf_aw"``); None: the URDF's.
    friction : rrr_pin.control.friction.JointFriction, optional
        Friction every law compensates (``fl``, ``hinf``, ``hinf_aw``; another law given it
        is refused by name). None: no compensation.

    Raises
    ------
    ValueError
        An unknown or repeated name (the message lists the known ones).
    """
    if isinstance(names, str):
        names = [s.strip() for s in names.split(",")]
    names = list(names)
    if not names or any(not s for s in names):
        raise ValueError(f"controllers: expected comma-separated names from "
                         f"{', '.join(BUILTIN_LAWS)}, got {names!r}")
    laws = [make_law(name, nominal, K=K, lam_fl=lam_fl, lam_hinf=lam_hinf,
                     torque_limit=torque_limit, friction=friction) for name in names]
    check_laws(laws, nominal.nq)
    for law in laws:
        logger.info("law %r built for %s: %s", law.name, nominal.name, law.label or law.name)
    return laws


def check_laws(laws, n: int, baseline: str | None = None) -> list:
    """Check a list of laws for ``n`` joints: each valid, names unique, baseline among them."""
    laws = list(laws)
    if not laws:
        raise ValueError("at least one control law is needed")
    for law in laws:
        check_law(law, n)
    names = [law.name for law in laws]
    dup = sorted({x for x in names if names.count(x) > 1})
    if dup:
        raise ValueError(f"control law names must be unique, repeated: {', '.join(dup)}")
    if baseline is not None and baseline not in names:
        raise ValueError(f"baseline {baseline!r} is not among the controllers "
                         f"({', '.join(names)})")
    return laws


def check_runs(plant, laws, reference, settings: RunSettings) -> dict:
    """Validate every law's run on ``plant`` before any work; return the engine of each.

    :func:`rrr_pin.sim.simulation.check_run` per law: a setting, an effect or an engine that
    cannot run a law on this plant is refused here, once, naming it, instead of failing in a
    worker or being recorded as a failed run.

    Returns
    -------
    dict
        Law name -> the engine that will run it (what ``settings.engine`` resolves to).
    """
    kwargs = settings.simulate_kwargs()
    with reuse_preparation():
        return {law.name: check_run(plant, law, reference, settings.duration, check=False,
                                    **kwargs) for law in laws}


def run_laws(plant, laws, reference, settings: RunSettings) -> dict:
    """Simulate every law on ``plant``.

    Returns
    -------
    dict
        By law name: its :class:`~rrr_pin.sim.trajectory.Trajectory`, or the
        :class:`~rrr_pin.sim.trajectory.SimulationDiverged` (or the plant's own failure,
        :attr:`rrr_pin.model.plant.Plant.failures`) it ended with; other errors propagate.
    """
    out = {}
    kwargs = settings.simulate_kwargs()
    failures = (SimulationDiverged, *plant.failures)
    with reuse_preparation():  # the laws share the sampled reference (bit-identical)
        for law in laws:
            try:
                # check=False: RunSettings validated duration, dt, rate and limit_margin.
                out[law.name] = simulate(plant, law, reference, settings.duration, check=False,
                                         **kwargs)
            except failures as exc:
                out[law.name] = exc
    return out


def failure_text(exc: Exception) -> str:
    """How a run that ended is recorded: its message, with the kind of a plant's own failure.

    A :class:`~rrr_pin.sim.trajectory.SimulationDiverged` is its message; a plant's failure
    (:attr:`rrr_pin.model.plant.Plant.failures`, e.g. ``SingularConfiguration``) is
    ``"<type>: <message>"``.
    """
    return str(exc) if isinstance(exc, SimulationDiverged) else f"{type(exc).__name__}: {exc}"


def run_laws_batch(plants, laws, reference, settings: RunSettings, *, batch: int = 16,
                   threads: int = 1, figures: bool = False) -> list:
    """Simulate every law on every plant, many plants per call where the engine allows.

    Each law runs on all ``plants`` through :func:`rrr_pin.sim.simulation.simulate_batch`:
    under ``engine="auto"`` on the batched generated dynamics when the plants' structure has
    them (:mod:`rrr_pin.sim.batched`), otherwise one plant at a time as :func:`run_laws`.
    ``batch`` and ``threads`` (threads of the batched engine) change no number; with
    ``figures`` a batched run comes back as its figures
    (:class:`~rrr_pin.sim.trajectory.RunFigures`, for :func:`run_metrics`), not its
    trajectory.

    Returns
    -------
    list of dict
        Per plant, in order, as :func:`run_laws`: by law name, its Trajectory (or
        RunFigures) or the SimulationDiverged it ended with.
    """
    plants = list(plants)
    out: list[dict] = [{} for _ in plants]
    kwargs = settings.simulate_kwargs()
    with reuse_preparation():
        for law in laws:
            results = simulate_batch(plants, law, reference, settings.duration, batch=batch,
                                     threads=threads, figures=figures, check=False,
                                     **kwargs)
            for row, result in zip(out, results, strict=True):
                row[law.name] = result
    return out


def run_metrics(traj: Trajectory, joint_names) -> dict:
    """Scalar figures of a run: its ``figures(joint_names)``.

    ``traj`` is a :class:`~rrr_pin.sim.trajectory.Trajectory` or the
    :class:`~rrr_pin.sim.trajectory.RunFigures` of a run reduced without its time series
    (:func:`run_laws_batch` with ``figures=True``); both give
    :func:`rrr_pin.sim.trajectory.tracking_figures`:

    ``rms_error``, ``max_error`` [rad], ``rms_torque`` [N m] (over all joints and samples),
    ``drift`` [m] for a plant that records its loop drift (a closed chain,
    ``info["drift_m"]``) and ``rms_error_<joint>`` [rad] per joint.
    """
    return traj.figures(joint_names)


def ratio(num: float, den: float) -> float | None:
    """``num / den`` of two figures >= 0; ``inf`` for ``x / 0`` (x > 0); None if undefined.

    None for ``0 / 0`` and for a NaN or inf figure: no number states how the two compare.
    """
    if not (math.isfinite(num) and math.isfinite(den)) or num < 0 or den < 0:
        return None
    if den == 0.0:
        return None if num == 0.0 else math.inf
    return num / den


def error_ratios(metrics_by_law: dict, baseline: str) -> dict:
    """Compare each law with the baseline.

    ``error_ratio`` = baseline RMS error / the law's (above 1: the law tracks better),
    ``torque_ratio`` = the law's RMS torque / the baseline's, each by :func:`ratio`: ``inf``
    when only the denominator is 0, and None, with the reason in ``undefined``, when both are
    0 (e.g. a reference at rest that both laws hold exactly) or one is not finite.

    Parameters
    ----------
    metrics_by_law : dict
        ``{name: run_metrics(...)}`` of the laws that ran.
    baseline : str

    Returns
    -------
    dict
        ``{name: {"error_ratio": float or None, "torque_ratio": float or None}}`` for every
        law but the baseline, plus ``"undefined": [sentence, ...]`` when a ratio is None;
        empty if the baseline did not run.
    """
    base = metrics_by_law.get(baseline)
    if base is None:
        return {}
    out = {}
    for name, m in metrics_by_law.items():
        if name == baseline:
            continue
        r = {"error_ratio": ratio(base["rms_error"], m["rms_error"]),
             "torque_ratio": ratio(m["rms_torque"], base["rms_torque"])}
        undefined = [
            f"{key}_{name} undefined: {what} of {name} ({m[metric]!r}) and of the baseline "
            f"{baseline} ({base[metric]!r}) give no ratio"
            for key, metric, what in (("error_ratio", "rms_error", "RMS error"),
                                      ("torque_ratio", "rms_torque", "RMS torque"))
            if r[key] is None]
        if undefined:
            r["undefined"] = undefined
        out[name] = r
    return out


def law_kind(law) -> str:
    """``"continuous"`` or ``"sampled"``, as the law describes itself (``"unknown"`` otherwise)."""
    describe = getattr(law, "describe", None)
    time = describe().get("time") if describe is not None else None
    return time if time in ("continuous", "sampled") else "unknown"

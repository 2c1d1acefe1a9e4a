"""The paper's section-5 study, for any set of control laws on any plant: nominal and uncertain.

One code path for every plant (:mod:`rrr_pin.model.plant`): a serial arm (the paper's RRR, an
example-robot-data arm, a URDF) or a closed chain (the 5-bar, the Delta, any registered
mechanism). Its uncertain plants are drawn by the plant itself
(:meth:`~rrr_pin.model.plant.Plant.perturbed`: plant ``k`` of seed ``s`` with
``numpy.random.default_rng([s, k])``, from ``config.tolerances``), the laws are built-in or
your own (:mod:`rrr_pin.control.laws`), the reference is the plant's study reference by default
(:func:`rrr_pin.control.references.study_reference`: the joint-space sinusoid of an arm, the
task path of a mechanism), and the runner (:mod:`rrr_pin.campaign.runner`) runs them with the
settings of :mod:`rrr_pin.campaign.settings`. Plants run in parallel processes; results do not
depend on the number of processes. Laws are compared with a named baseline (``"fl"`` by
default, the paper's). A run that ends (a divergence, or a plant's own failure such as a closed
chain's type-II singularity, :attr:`~rrr_pin.model.plant.Plant.failures`) is recorded in its
sample's ``status``.

Under a torque limit (``config.run.effects.torque_limit``, the study of the paper under limits)
a law that diverges on the nominal plant is a result, not an error: it is set aside
(:attr:`StudyResult.dropped`, its outcome on every plant kept) and the others are reported as
usual; ``summary["torque_limit"]`` gives, per law, the diverged plants, the RMS error and the
time in saturation. Without a limit, such a divergence stops the study (``SimulationDiverged``).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..control.effects import check_torque_limit
from ..control.references import Reference, TaskSpaceReference, study_reference
from ..outputs import writing
from ..sim.simulation import time_grid
from ..sim.trajectory import SimulationDiverged, metrics
from .coverage import certificate_loop, certify_run
from .executors import check_jobs, default_jobs, run_tasks
from .runner import (
    RunSettings,
    check_laws,
    check_runs,
    failure_text,
    ratio,
    run_laws,
    run_laws_batch,
)
from .settings import Settings

if TYPE_CHECKING:
    from ..robust.certificates import CertificateSpec

__all__ = [
    "StudyConfig",
    "StudyResult",
    "UncertainPlant",
    "draw_plants",
    "REALISTIC_SET",
    "realistic_run",
    "PlantTask",
    "run_plant",
    "run_plants",
    "check_study",
    "run_study",
    "summarize",
    "task_space_errors",
    "refined_run",
    "refined_nominal_errors",
    "MAX_STUDY_BYTES",
    "check_study_size",
]

logger = logging.getLogger(__name__)


#: Most memory [bytes] the trajectories a study keeps (every law on every plant, for its
#: figures) may take unless ``config.run.force``: ``8 (1 + 4 n)`` bytes per sample and joint
#: count ``n`` (t, q, qd, r, tau), 2 GB, 200 times the paper's study (11 plants, 2 laws, 4 s).
MAX_STUDY_BYTES = 2_000_000_000


@dataclass(frozen=True)
class StudyConfig(Settings):
    """Settings of a study: :class:`~rrr_pin.campaign.settings.Settings` with the study's defaults.

    Recorded whole in ``results.json`` (:meth:`~rrr_pin.campaign.settings.Settings.to_dict`);
    ``jobs`` is not recorded, since the results do not depend on it.

    Parameters
    ----------
    samples : int, default 10
        Number of uncertain plants (the paper's count), >= 0.
    seed, run, tolerances, baseline
        As in :class:`~rrr_pin.campaign.settings.Settings` (``run`` by default 4 s,
        continuous-time laws as in the paper's Simulink study).
    jobs : int, optional
        Worker processes, >= 1; default ``min(2, cpu count)``.
    """

    samples: int = 10
    jobs: int | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.jobs is not None:
            check_jobs(self.jobs)


@dataclass(frozen=True)
class UncertainPlant:
    """One uncertain plant of a study: where it came from, and the plant.

    Attributes
    ----------
    index : int
        Sample number ``k``.
    seed : list of int
        ``[s, k]``, the seed of ``numpy.random.default_rng`` that drew it.
    parameters : dict
        JSON-ready description of what was drawn (:meth:`~rrr_pin.model.plant.Plant.perturbed`).
    plant : Plant
        The plant, of the nominal's kind.
    """

    index: int
    seed: list
    parameters: dict
    plant: object

    def write(self, folder: str | Path, stem: str = "plant") -> Path:
        """Write the plant's description (URDF, MJCF) as ``folder/<stem>_<index:03d>.<ext>``."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        text, suffix = self.plant.source_text()
        path = folder / f"{stem}_{self.index:03d}{suffix}"
        with writing(path):  # a full disk names the file
            path.write_text(text)
        return path


#: The realistic set of ``rrr-pin reproduce --realistic``: the laws sampled at 1 kHz behind a
#: 1 ms delay and a 300 rad/s first-order actuator, joint friction (viscous 0.1 N m s/rad,
#: Coulomb 0.2 N m on every joint), the URDF's effort limits and sensor noise (1e-5 rad on q,
#: about a 19-bit encoder's step; 1e-3 rad/s on qd). Rotor armature is the plant's, not an
#: effect: give the arm's --armature (the laws then model it too).
REALISTIC_SET = {"rate_hz": 1000.0, "delay_s": 0.001, "actuator_rad_s": 300.0,
                 "viscous_Nms": 0.1, "coulomb_Nm": 0.2, "torque_limit": "urdf",
                 "noise_q_rad": 1e-5, "noise_qd_rad_s": 1e-3}


def realistic_run(run: RunSettings, nominal) -> RunSettings:
    """Return ``run`` with :data:`REALISTIC_SET`'s rate and effects (its duration kept).

    Parameters
    ----------
    run : RunSettings
    nominal : Plant
        Its effort limits [N m] are the torque limit.
    """
    from dataclasses import replace

    from ..control.effects import PlantEffects

    fx = PlantEffects(delay=REALISTIC_SET["delay_s"],
                      actuator_bandwidth=REALISTIC_SET["actuator_rad_s"],
                      viscous=REALISTIC_SET["viscous_Nms"], coulomb=REALISTIC_SET["coulomb_Nm"],
                      torque_limit=tuple(float(x) for x in nominal.effort_limits()),
                      noise_q=REALISTIC_SET["noise_q_rad"],
                      noise_qd=REALISTIC_SET["noise_qd_rad_s"])
    return replace(run, rate=REALISTIC_SET["rate_hz"], dt=None, effects=fx)


def draw_plants(nominal, count: int, seed: int, tolerances) -> list[UncertainPlant]:
    """Draw the ``count`` uncertain plants of a study around ``nominal``.

    Plant ``k`` is ``nominal.perturbed(numpy.random.default_rng([seed, k]), tolerances)``,
    named ``<nominal>_sample<k:03d>``: a plant can be regenerated alone, whatever the count.
    """
    out = []
    for k in range(int(count)):
        plant, parameters = nominal.perturbed(np.random.default_rng([int(seed), k]), tolerances,
                                              name=f"{nominal.name}_sample{k:03d}")
        out.append(UncertainPlant(index=k, seed=[int(seed), k], parameters=parameters,
                                  plant=plant))
    return out


@dataclass(frozen=True)
class PlantTask:
    """One plant of a study, sent to a worker process (:func:`run_plant`).

    Attributes
    ----------
    laws : tuple of ControlLaw or SampledLaw
    reference : Reference
    run : RunSettings
    nominal : Plant
        The nominal plant: the certificate's model.
    certificate : CertificateSpec or None
    plant : Plant
        The plant to run.
    certify : bool
        Certify this plant (the uncertain ones; not the nominal).
    """

    laws: tuple
    reference: Reference
    run: RunSettings
    nominal: object
    certificate: CertificateSpec | None
    plant: object
    certify: bool


@dataclass
class StudyResult:
    """Trajectories and figures of a study.

    Attributes
    ----------
    robot : str
        Name of the nominal plant.
    joint_names : list of str
    reference : Reference
    config : StudyConfig
    laws : list of dict
        Each law's :meth:`describe`, in the order given (``laws[i]["name"]`` is its key).
    nominal : dict
        ``{name: Trajectory}`` on the nominal plant.
    samples : list of dict
        Per uncertain plant: ``index``, ``seed``, ``parameters``, ``status`` (``"ok"`` when
        every law ran, otherwise ``"diverged: "`` and how each law's run ended),
        ``trajectories`` and ``metrics`` (by law name, for the laws that ran).
    plants : list of UncertainPlant
    task_space : dict
        For a task-space reference (:class:`~rrr_pin.control.references.TaskSpaceReference`),
        the frame's Cartesian error (:func:`task_space_errors`): ``frame``, ``nominal`` and
        ``uncertain`` per law (figures in [m], see :func:`task_space_errors`), and ``errors``
        (not written to ``results.json``): ``errors["nominal"][law]``, the nominal plant's
        error, shape (N, 3) [m], and ``errors["uncertain"][law]``, a list of tracking-error
        norms (nominal kinematics) of shape (N,) [m], one per uncertain plant where the law
        ran. Empty for a joint-space reference.
    dropped : dict
        Under a torque limit, the laws that diverged on the nominal plant, by name:
        ``label``, ``nominal`` (the divergence message) and ``samples`` (per uncertain plant,
        :func:`~rrr_pin.sim.trajectory.metrics` with ``saturated``, the fraction of the run's
        periods at the limit, or the divergence message). They are not in :attr:`laws`.
    torque_limit : dict
        How the torque limit was chosen (e.g. by the CLI: ``spec``, ``rule``,
        ``peak_torque_Nm``), recorded in ``summary["torque_limit"]``.
    joint_match : dict
        When the laws were designed on another model than the plant (``--plant``): the
        :meth:`rrr_pin.model.joint_map.JointMatch.to_dict` of the pairing, recorded in
        ``summary["joint_match"]``.
    plant_friction : dict
        What the runs applied of the plant's own friction (an MJCF arm's damping and friction
        loss, :func:`rrr_pin.control.effects.with_plant_friction`), recorded in
        ``summary["plant_friction"]``.
    refined : dict
        Per law, the nominal run's largest error [rad] with the discretization halved
        (:func:`refined_nominal_errors`; None where not measured), recorded in
        ``summary["nominal_max_error_refined"]``: how much of the nominal error is the
        sampling's or the integrator's.
    joint_dynamics : dict or None
        The nominal plant's armature, damping and friction and their source
        (:meth:`rrr_pin.model.plant.Plant.joint_dynamics`), in ``results.json``; each drawn
        arm's are in its sample's ``parameters["joint_dynamics"]``.
    """

    robot: str
    joint_names: list
    reference: Reference
    config: StudyConfig
    laws: list
    nominal: dict
    samples: list
    plants: list
    design: dict = field(default_factory=dict)
    certificate: dict | None = None
    task_space: dict = field(default_factory=dict)
    dropped: dict = field(default_factory=dict)
    torque_limit: dict = field(default_factory=dict)
    refined: dict = field(default_factory=dict)
    joint_dynamics: dict | None = None
    joint_match: dict = field(default_factory=dict)
    plant_friction: dict = field(default_factory=dict)

    @property
    def names(self) -> list[str]:
        """Law names, in order."""
        return [d["name"] for d in self.laws]

    def label(self, name: str) -> str:
        """Display name of a law."""
        return next(d["label"] for d in self.laws if d["name"] == name)

    def _repr_html_(self) -> str:
        """Summary table for notebooks: per law, nominal and uncertain RMS errors and status."""
        import html

        run = self.config.run
        rate = f"{run.rate:g} Hz (sampled laws)" if run.rate else "continuous-time laws"
        head = (f"<caption>Study on {html.escape(self.robot)}: {run.duration:g} s, {rate}, "
                f"{len(self.samples)} uncertain plants, baseline "
                f"{html.escape(self.config.baseline)}</caption><tr><th>law</th>"
                "<th>nominal RMS error [rad]</th><th>uncertain: mean RMS error [rad]</th>"
                "<th>status</th></tr>")
        rows = []
        for name in self.names:
            e = self.nominal[name].error
            ran = [s["metrics"][name]["rms_error"] for s in self.samples
                   if name in s.get("metrics", {})]
            mean = (f"{np.mean(np.sqrt(np.mean(np.square(ran), axis=1))):.4g}" if ran
                    else "-")
            status = f"ran on {len(ran)} of {len(self.samples)} uncertain plants"
            rows.append(f"<tr><td>{html.escape(self.label(name))} "
                        f"(<code>{html.escape(name)}</code>)</td>"
                        f"<td>{np.sqrt(np.mean(e * e)):.4g}</td><td>{mean}</td>"
                        f"<td>{status}</td></tr>")
        return f"<table>{head}{''.join(rows)}</table>"

    def to_json(self) -> dict:
        """Return the ``results.json`` content (layout in the README)."""
        uncertain = {}
        for name in self.names:
            rows = [s["metrics"][name] for s in self.samples if name in s.get("metrics", {})]
            uncertain[name] = _mean_metrics(rows)
        return {
            "robot": self.robot,
            "joint_names": self.joint_names,
            **({"joint_dynamics": self.joint_dynamics} if self.joint_dynamics else {}),
            "reference": {**self.reference.to_dict(), "duration_s": self.config.run.duration},
            "config": self.config.to_dict(),
            "controllers": self.laws,
            "design": self.design,
            "certificate": self.certificate,
            "nominal": {name: metrics(self.nominal[name]) for name in self.names},
            "uncertain": {
                **uncertain,
                "samples": [{"index": s["index"], "seed": s["seed"], "status": s["status"],
                             **({"certificate": s["certificate"]} if "certificate" in s
                                else {}),
                             "parameters": s["parameters"], **s.get("metrics", {})}
                            for s in self.samples],
            },
            "summary": summarize(self),
            **({"task_space": {k: v for k, v in self.task_space.items() if k != "errors"}}
               if self.task_space else {}),
            **({"dropped": self.dropped} if self.dropped else {}),
        }


def _mean_metrics(rows: list[dict]) -> dict:
    if not rows:
        return {}
    return {k: np.mean([row[k] for row in rows], axis=0).tolist() for k in rows[0]}


def summarize(result: StudyResult) -> dict:
    """Headline figures of a study, each law against the baseline.

    Returns
    -------
    dict
        ``baseline``; ``nominal_max_error`` [rad] per law; ``samples_ok`` (every law ran) and
        ``samples_diverged``; ``diverged`` (per law, number of plants where it diverged); over
        the samples where every law ran, per law other than the baseline:
        ``error_ratio_uncertain`` (RMS error over all joints, samples and time of the baseline
        divided by the law's: above 1, the law tracks better), ``error_ratio_uncertain_per_joint``
        and ``torque_ratio_uncertain`` (RMS torque of the law over the baseline's); each
        ratio by :func:`rrr_pin.campaign.runner.ratio`, None where undefined (0/0). Under a
        torque limit, ``torque_limit`` (:func:`_torque_limit_summary`). For a plant that
        records its loop drift (a closed chain), ``drift_max_m`` [m] over every run. With
        certificates, ``samples_certified``, ``certificate_b`` and ``nugap_max``.
    """
    names, base = result.names, result.config.baseline
    ok = [s for s in result.samples if s["status"] == "ok"]
    out = {
        "baseline": base,
        "nominal_max_error": {k: float(np.max(np.abs(result.nominal[k].error))) for k in names},
        **({"nominal_max_error_refined": {k: result.refined.get(k) for k in names}}
           if result.refined else {}),
        "samples_ok": len(ok),
        "samples_diverged": len(result.samples) - len(ok),
        "diverged": {k: sum(1 for s in result.samples if k not in s.get("metrics", {}))
                     for k in names},
    }
    limit = _torque_limit_summary(result)
    if limit:
        out["torque_limit"] = limit
    if result.joint_match:
        out["joint_match"] = result.joint_match
    if result.plant_friction:
        out["plant_friction"] = result.plant_friction
    drifts = [m["drift_m"] for s in result.samples for m in s["metrics"].values()
              if "drift_m" in m] + [t.info["drift_m"] for t in result.nominal.values()
                                    if "drift_m" in t.info]
    if drifts:  # a plant that records its loop drift (a closed chain): the largest
        out["drift_max_m"] = max(drifts)
    certs = [s["certificate"] for s in result.samples if "certificate" in s]
    if certs:
        out["samples_certified"] = sum(1 for c in certs if c["certified"])
        out["certificate_b"] = certs[0]["b"]
        out["nugap_max"] = max(c["nugap_max"] for c in certs)
        # per law: certified plants on which it ran (a divergence is never certified for it)
        good = [s for s in result.samples if s.get("certificate", {}).get("certified")]
        out["certified_ran"] = {k: sum(1 for s in good if k in s.get("metrics", {}))
                                for k in names}
        if result.certificate is not None:
            out["certificate"] = certificate_loop(result.certificate["lam_rad_s"],
                                                  result.certificate["points"],
                                                  result.config.run)
    if ok:
        def rms(key, what, axis=None):
            sq = np.array([np.asarray(s["metrics"][key][what]) ** 2 for s in ok])
            return np.sqrt(np.mean(sq, axis=axis))

        others = [k for k in names if k != base]
        # ratio(): None where a ratio is undefined (0/0, e.g. a reference at rest held
        # exactly by both laws), never a NaN that a verdict could be read from.
        out["error_ratio_uncertain"] = {
            k: ratio(float(rms(base, "rms_error")), float(rms(k, "rms_error"))) for k in others}
        out["error_ratio_uncertain_per_joint"] = {
            k: [ratio(float(b), float(v)) for b, v in zip(rms(base, "rms_error", axis=0),
                                                           rms(k, "rms_error", axis=0),
                                                           strict=True)]
            for k in others}
        out["torque_ratio_uncertain"] = {
            k: ratio(float(rms(k, "rms_torque")), float(rms(base, "rms_torque")))
            for k in others}
    return out


def _overall_rms(m: dict) -> float:
    """RMS error over every joint of a run [rad], from its per-joint ``rms_error``."""
    return float(np.sqrt(np.mean(np.square(m["rms_error"]))))


def _torque_limit_summary(result: StudyResult) -> dict:
    """Per law under the study's torque limit: diverged plants, RMS error, time in saturation.

    ``limit_Nm`` (the limits the plants clip to) and what :attr:`StudyResult.torque_limit`
    says of their choice; per law (the dropped ones too): ``nominal_diverged`` (bool),
    ``uncertain_diverged`` (count of the ``uncertain`` plants), ``nominal_rms_error`` and
    ``uncertain_rms_error`` [rad] (RMS over joints, time and the plants where it ran; None
    if none), ``nominal_saturated`` and ``uncertain_saturated`` [-] (the fraction of control
    periods with any joint at its limit: on the nominal plant, and the mean over the uncertain
    plants where it ran; None if none). Empty without a torque limit.
    """
    fx = result.config.run.effects
    if fx is None or fx.torque_limit is None:
        return {}
    outcomes = {}  # name: (nominal metrics or None, [metrics or None per sample])
    for name in result.names:
        traj = result.nominal[name]
        per = []
        for s in result.samples:
            t = s["trajectories"].get(name)
            per.append(None if t is None else
                       {**s["metrics"][name], "saturated": t.info["saturation"]["fraction"]})
        outcomes[name] = ({**metrics(traj), "saturated": traj.info["saturation"]["fraction"]},
                          per)
    for name, d in result.dropped.items():
        outcomes[name] = (None, [m if isinstance(m, dict) else None for m in d["samples"]])
    laws = {}
    for name, (nom, per) in outcomes.items():
        ran = [m for m in per if m is not None]
        laws[name] = {
            "nominal_diverged": nom is None,
            "uncertain_diverged": len(per) - len(ran),
            "uncertain": len(per),
            "nominal_rms_error": _overall_rms(nom) if nom is not None else None,
            "uncertain_rms_error": (float(np.sqrt(np.mean([_overall_rms(m) ** 2 for m in ran])))
                                    if ran else None),
            "nominal_saturated": nom["saturated"] if nom is not None else None,
            "uncertain_saturated": float(np.mean([m["saturated"] for m in ran])) if ran else None,
        }
    limit = result.nominal[result.names[0]].info["saturation"]["limit_Nm"]
    return {**result.torque_limit, "limit_Nm": limit,
            "saturated_means": "fraction [-] of the control periods with any joint at its limit",
            "laws": laws}


def refined_run(run: RunSettings) -> RunSettings | None:
    """Return the run with its discretization halved, or None when it cannot be.

    Twice the rate (and half the sub-step), or half the RK4 step of a continuous-time law;
    None when the settings refuse it (a delay off the finer grid).
    """
    import dataclasses

    try:
        if run.rate is not None:
            return dataclasses.replace(run, rate=2.0 * run.rate, dt=0.5 * run.dt)
        return dataclasses.replace(run, dt=0.5 * run.dt)
    except ValueError:
        return None


def refined_nominal_errors(nominal, laws, reference, run: RunSettings) -> dict:
    """Each law's largest nominal error [rad] with the discretization halved (:func:`refined_run`).

    On the nominal plant the law's model is exact, so its tracking error is the sampling's
    (zero-order hold: first order in the period) or the integrator's (RK4: fourth order in the
    step), plus round-off: the error falls when the discretization is refined. A law sampled at
    its own fixed rate (a :class:`~rrr_pin.control.laws.SampledLaw`), a run that cannot be
    refined, or one that ends, gives None.
    """
    from ..control.laws import SampledLaw

    fine = refined_run(run)
    out = {}
    for law in laws:
        out[law.name] = None
        if fine is None or isinstance(law, SampledLaw):
            continue
        try:
            traj = run_laws(nominal, [law], reference, fine)[law.name]
        except ValueError:  # a setting the refined grid cannot realize
            continue
        if not isinstance(traj, Exception):
            out[law.name] = float(np.max(np.abs(traj.error)))
    return out


def task_space_errors(reference: TaskSpaceReference, nominal, runs: dict,
                      samples: list, plants: list) -> dict:
    """Cartesian error of the frame a task-space reference moves, for every run of a study.

    The frame's origin by forward kinematics against the path
    (:meth:`~rrr_pin.control.references.TaskSpaceReference.tracking_error`), two ways for an
    uncertain plant: by the plant's own kinematics (``rms_error_m``, ``max_error_m``: where the
    arm really is, so its perturbed link lengths count) and by the nominal kinematics
    (``rms_tracking_error_m``, ``max_tracking_error_m``: the joint tracking error seen in task
    space, what the controller is responsible for). RMS over time of the error's Euclidean
    norm, over the plants where the law ran; max its largest value [m].

    Parameters
    ----------
    reference : TaskSpaceReference
    nominal : Plant
        With named frames (:data:`rrr_pin.model.plant.FRAMES`).
    runs : dict
        ``{law name: Trajectory}`` on the nominal plant.
    samples : list of dict
        The study's samples (``trajectories`` by law name).
    plants : list of UncertainPlant
        The uncertain plants, in the order of ``samples``.
    """
    def figures(d, prefix=""):
        return {f"rms_{prefix}error_m": float(np.sqrt(np.mean(d * d))),
                f"max_{prefix}error_m": float(d.max())}

    def norm(robot, traj):
        return np.linalg.norm(reference.tracking_error(robot, traj.t, traj.q), axis=1)

    out = {"frame": reference.frame, "nominal": {}, "uncertain": {},
           "errors": {"nominal": {}, "uncertain": {}}}
    for name, traj in runs.items():
        e = reference.tracking_error(nominal, traj.t, traj.q)
        out["errors"]["nominal"][name] = e
        out["nominal"][name] = figures(np.linalg.norm(e, axis=1))
    true: dict = {name: [] for name in runs}
    seen: dict = {name: [] for name in runs}
    for sample, plant in zip(samples, plants, strict=True):
        for name, traj in sample["trajectories"].items():
            true[name].append(norm(plant.plant, traj))
            seen[name].append(norm(nominal, traj))
    out["errors"]["uncertain"] = seen
    for name in runs:
        if true[name]:
            out["uncertain"][name] = {**figures(np.concatenate(true[name])),
                                      **figures(np.concatenate(seen[name]), "tracking_"),
                                      "plants": len(true[name])}
    return out


def run_plants(tasks: tuple) -> list[tuple[dict, dict | None]]:
    """Simulate every law on several plants of one study, batched where the engine allows.

    The plants run together (:func:`rrr_pin.campaign.runner.run_laws_batch`: under
    ``engine="auto"``, many per call on the generated dynamics of :mod:`rrr_pin.sim.batched`
    when the structure has them); each result is the one :func:`run_plant` gives its plant.
    """
    task = tasks[0]
    runs = run_laws_batch([t.plant for t in tasks], task.laws, task.reference, task.run)
    out = []
    for t, r in zip(tasks, runs, strict=True):
        cert = None
        if t.certificate is not None and t.certify:
            cert = certify_run(t.certificate, t.nominal, t.plant, t.reference, t.run)
        out.append((r, cert))
    return out


def run_plant(task: PlantTask) -> tuple[dict, dict | None]:
    """Simulate every law on one plant, and certify it (runs in a worker process)."""
    runs = run_laws(task.plant, task.laws, task.reference, task.run)
    cert = None
    if task.certificate is not None and task.certify:
        cert = certify_run(task.certificate, task.nominal, task.plant, task.reference,
                           task.run)
    return runs, cert


def check_study_size(config: StudyConfig, n_laws: int, n: int) -> int:
    """Return the memory [bytes] of the trajectories a study keeps, refused above the bound.

    ``(samples + 1) x n_laws`` runs (the nominal plant and the uncertain ones) of
    ``n_steps + 1`` samples each, ``8 (1 + 4 n)`` bytes per sample for ``n`` joints.

    Raises
    ------
    ValueError
        The estimate is above :data:`MAX_STUDY_BYTES` and ``config.run.force`` is False.
    """
    run = config.run
    samples = time_grid(run.duration, run.dt, run.rate, force=True).n_steps + 1
    kept = (config.samples + 1) * n_laws * samples * 8 * (1 + 4 * n)
    if kept > MAX_STUDY_BYTES and not run.force:
        raise ValueError(
            f"the study keeps every trajectory: {config.samples + 1} plants x {n_laws} laws "
            f"x {samples} samples of {n} joints take about {kept / 1e9:.3g} GB, above "
            f"rrr_pin.campaign.study.MAX_STUDY_BYTES = {MAX_STUDY_BYTES / 1e9:g} GB; use fewer "
            f"samples (--samples) or a shorter run, a Monte Carlo campaign (which keeps "
            f"metrics only), or force it (RunSettings(force=True), --force)")
    return kept


def check_study(nominal, laws, *, config: StudyConfig = StudyConfig(),
                reference: Reference | None = None) -> tuple[list, Reference]:
    """Every refusal of :func:`run_study` that needs no run, before any work; its inputs.

    A caller that writes files first (``rrr-pin reproduce``'s design figures, a progress bar)
    calls this before them, so that a refused study writes and prints nothing but the refusal.

    Returns
    -------
    (list, Reference)
        The checked laws and the reference (the plant's study reference if ``None``).

    Raises
    ------
    ValueError, rrr_pin.validation.FieldError
        As :func:`run_study` before any run: the laws, the study's size, the reference on the
        plant, each law's run (settings, effects, engine) and a torque limit below gravity.
    """
    laws = check_laws(laws, nominal.nq, config.baseline)
    check_study_size(config, len(laws), nominal.nq)
    reference = (study_reference(nominal, config.run.duration) if reference is None
                 else reference)
    reference.check_limits(nominal, duration=config.run.duration)
    check_runs(nominal, laws, reference, config.run)
    fx = config.run.effects
    if fx is not None and fx.torque_limit is not None:
        # the plant must at least hold itself where the reference starts
        check_torque_limit(nominal, fx.torque_limit, reference)
    return laws, reference


def run_study(nominal, laws, *, config: StudyConfig = StudyConfig(),
              reference: Reference | None = None, progress=None,
              certificate=None) -> StudyResult:
    """Run every law on the nominal plant and on ``config.samples`` uncertain plants.

    Parameters
    ----------
    nominal : Plant
        The nominal plant, a serial arm or a closed chain (the uncertain plants are drawn
        around it: :func:`draw_plants`).
    laws : sequence of ControlLaw or SampledLaw
        Built-in (:func:`rrr_pin.campaign.runner.make_laws`) or your own; unique names; the
        baseline ``config.baseline`` among them.
    config : StudyConfig
        Run settings, sample count, seed, tolerances, baseline, jobs.
    reference : Reference, optional
        Default :func:`rrr_pin.control.references.study_reference` of ``nominal`` over the
        run's duration.
    progress : callable, optional
        Called as ``progress(done, total)`` after each plant.
    certificate : rrr_pin.robust.certificates.CertificateSpec, optional
        Certify every uncertain plant (frozen-configuration nu-gap against ``b(Gs, Ks)``,
        :mod:`rrr_pin.robust.certificates`); recorded per sample beside the simulated outcome.

    Returns
    -------
    StudyResult

    Raises
    ------
    SimulationDiverged
        A law's run ended on the nominal plant (a divergence, or the plant's own failure
        such as a type-II singularity; under a torque limit: only the baseline's; another
        law is then set aside in :attr:`StudyResult.dropped`).
    ValueError
        The trajectories kept would take more than :data:`MAX_STUDY_BYTES`
        (:func:`check_study_size`, before any work; ``config.run.force`` lifts the bound).
    rrr_pin.validation.FieldError
        A torque limit below the gravity torque at the reference's start
        (:func:`~rrr_pin.control.effects.check_torque_limit`), before any run.
    """
    laws, reference = check_study(nominal, laws, config=config, reference=reference)
    fx = config.run.effects
    limited = fx is not None and fx.torque_limit is not None
    start = time.perf_counter()
    logger.info("study on %s: %d laws (%s), nominal + %d uncertain plants (seed %d), %g s runs",
                nominal.name, len(laws), ", ".join(law.name for law in laws), config.samples,
                config.seed, config.run.duration)
    plants = draw_plants(nominal, config.samples, config.seed, config.tolerances)
    for p in plants:
        logger.debug("uncertain plant %d drawn with seed %s", p.index, p.seed)

    def task(plant, certify: bool) -> PlantTask:
        return PlantTask(laws=tuple(laws), reference=reference, run=config.run, nominal=nominal,
                         certificate=certificate, plant=plant, certify=certify)

    tasks = [task(nominal, False)] + [task(p.plant, True) for p in plants]
    jobs = 1 if len(tasks) <= 2 else config.jobs or default_jobs()
    logger.info("simulating %d plants in %s", len(tasks),
                "this process" if jobs <= 1 else f"{jobs} processes")
    # run_tasks: workers that die with this process and stop on Ctrl-C/SIGTERM (see executors).
    # The uncertain plants go in groups of up to 16 (one batched rollout each), the nominal
    # plant alone; about 2 groups per worker at least, so both cores work.
    size = max(1, min(16, math.ceil((len(tasks) - 1) / (2 * max(jobs, 1)))))
    groups = [tuple(tasks[:1])] + [tuple(tasks[k:k + size])
                                   for k in range(1, len(tasks), size)]
    slot = {id(g): k for k, g in enumerate(groups)}
    outputs_by_group = [None] * len(groups)
    done = 0
    for group, out in run_tasks(run_plants, groups, jobs=jobs):
        outputs_by_group[slot[id(group)]] = out
        done += len(out)
        if progress:
            progress(done, len(tasks))
    outputs = [o for group_out in outputs_by_group for o in group_out]
    failed = {k: v for k, v in outputs[0][0].items() if isinstance(v, Exception)}
    if failed and (not limited or config.baseline in failed):
        name, exc = next(iter(failed.items()))
        raise SimulationDiverged(f"law {name!r} diverged on the nominal plant: "
                                 f"{failure_text(exc)}", time=getattr(exc, "time", math.nan),
                                 joint=getattr(exc, "joint", ""))
    dropped = {}
    for name, exc in failed.items():  # under a torque limit: a result, set aside
        logger.warning("law %r diverged on the nominal plant under the torque limit: %s",
                       name, exc)
        dropped[name] = {
            "label": next(law.label or law.name for law in laws if law.name == name),
            "nominal": failure_text(exc),
            "samples": [failure_text(out[name]) if isinstance(out[name], Exception) else
                        {**metrics(out[name]),
                         "saturated": out[name].info["saturation"]["fraction"]}
                        for out, _ in outputs[1:]]}
    laws = [law for law in laws if law.name not in dropped]
    samples = []
    for plant, (out, cert) in zip(plants, outputs[1:], strict=True):
        out = {k: v for k, v in out.items() if k not in dropped}
        runs = {k: v for k, v in out.items() if not isinstance(v, Exception)}
        bad = [f"{k}: {failure_text(v)}" for k, v in out.items() if isinstance(v, Exception)]
        entry = {"index": plant.index, "seed": plant.seed, "parameters": plant.parameters,
                 "status": "ok" if not bad else "diverged: " + "; ".join(bad),
                 "trajectories": runs, "metrics": {k: metrics(t) for k, t in runs.items()}}
        if cert is not None:
            entry["certificate"] = cert
        samples.append(entry)
    nominal_runs = {k: v for k, v in outputs[0][0].items() if k not in dropped}
    refined = refined_nominal_errors(nominal, laws, reference, config.run)
    task_space = (task_space_errors(reference, nominal, nominal_runs, samples, plants)
                  if isinstance(reference, TaskSpaceReference) else {})
    logger.info("study on %s done in %.1f s: %d of %d uncertain plants ran every law",
                nominal.name, time.perf_counter() - start,
                sum(1 for s in samples if s["status"] == "ok"), len(samples))
    return StudyResult(robot=nominal.name, joint_names=nominal.joint_names, reference=reference,
                       config=config, laws=[law.describe() for law in laws],
                       nominal=nominal_runs, samples=samples, plants=plants,
                       certificate=certificate.to_dict() if certificate is not None else None,
                       task_space=task_space, dropped=dropped, refined=refined,
                       joint_dynamics=nominal.joint_dynamics())

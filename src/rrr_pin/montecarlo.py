"""Monte Carlo robustness campaigns: thousands of seeded uncertain plants, any set of laws.

Each sample ``k`` of a campaign with seed ``s`` is the plant
:func:`rrr_pin.uncertainty.sample_plant` draws with ``default_rng([s, k])``; it is generated,
simulated under every law (:func:`rrr_pin.runner.run_laws`) and reduced to figures inside the
worker, so only a row of numbers travels back. Rows are put in sample order, so the results are
identical whatever the number of workers or where they run.

Workers: ``jobs`` local processes (:class:`concurrent.futures.ProcessPoolExecutor`) or a Dask
distributed cluster (``scheduler="tcp://host:8786"``, through ``Client.get_executor()``, which
is a ``concurrent.futures.Executor`` too): one code path, two executors.

A sample where a law diverges is recorded with its status and parameters, with the figures of
the laws that ran; the campaign goes on.
"""

from __future__ import annotations

import csv
import json
import math
import os
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .dh import ArmParams, paper_params
from .dynamics import robot_from_xml
from .references import Reference
from .runner import RunSettings, check_laws, error_ratios, run_laws, run_metrics
from .simulate import SimulationDiverged
from .uncertainty import Tolerances, sample_plant

__all__ = ["Campaign", "CampaignSettings", "run_campaign", "campaign_summary",
           "campaign_columns", "write_campaign"]


@dataclass(frozen=True)
class CampaignSettings:
    """What a campaign computes (recorded whole in ``summary.json``).

    Parameters
    ----------
    samples : int
        Number of plants, >= 1.
    seed : int, default 0
        Campaign seed, >= 0.
    run : RunSettings
        How each run is simulated (default: 10 s, 1 kHz sampled laws).
    tolerances : Tolerances
        20 % inertia, 5 % lengths by default.
    baseline : str, default "fl"
        Law the others are compared with.
    """

    samples: int
    seed: int = 0
    run: RunSettings = field(default_factory=lambda: RunSettings(duration=10.0, rate=1000.0))
    tolerances: Tolerances = field(default_factory=Tolerances)
    baseline: str = "fl"

    def __post_init__(self) -> None:
        for key, low in (("samples", 1), ("seed", 0)):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < low:
                raise ValueError(f"{key} must be an integer >= {low}, got {v!r}")

    def to_dict(self) -> dict:
        """JSON-ready settings."""
        return {**self.run.to_dict(), "samples": int(self.samples), "seed": int(self.seed),
                "tolerance_inertia": self.tolerances.inertia,
                "tolerance_length": self.tolerances.length, "baseline": self.baseline}


@dataclass
class Campaign:
    """Rows of a campaign, one per sample, in sample order.

    Attributes
    ----------
    robot : str
    joint_names : list of str
    laws : list of dict
        Each law's description (``name``, ``label``, ...), in order.
    rows : list of dict
        ``index``, ``seed``, ``status`` (``"ok"``, or which laws diverged and why),
        ``parameters`` and, per law that ran, ``<law>_rms_error``, ``<law>_max_error`` [rad],
        ``<law>_rms_torque`` [N m], ``<law>_rms_error_<joint>`` [rad]; per law other than the
        baseline, ``error_ratio_<law>`` and ``torque_ratio_<law>``
        (:func:`rrr_pin.runner.error_ratios`).
    settings : dict
        :meth:`CampaignSettings.to_dict` plus the reference.
    """

    robot: str
    joint_names: list
    laws: list
    rows: list
    settings: dict = field(default_factory=dict)

    @property
    def names(self) -> list[str]:
        """Law names, in order."""
        return [d["name"] for d in self.laws]

    @property
    def baseline(self) -> str:
        """Name of the baseline law."""
        return self.settings["baseline"]


_SOURCES: dict = {}


def _plant_source(job):
    """Return the nominal arm the plants are drawn around: ArmParams or URDF text."""
    key = id(job)
    if _SOURCES.get("key") != key:
        _SOURCES.clear()
        _SOURCES.update(key=key, source=ArmParams.from_dict(job["params"])
                        if job["params"] is not None else job["nominal_xml"])
    return _SOURCES["source"]


def sample_row(job: dict, k: int) -> dict:
    """Generate sample ``k``, run every law on it and reduce it to one row."""
    settings: CampaignSettings = job["settings"]
    sample = sample_plant(_plant_source(job), settings.seed, k, settings.tolerances,
                          skip_joints=job["skip_joints"])
    row = {"index": k, "seed": sample.seed, "status": "ok", "parameters": sample.parameters}
    plant = robot_from_xml(sample.urdf, gravity=job["gravity"], lock=job["lock"],
                           name=f"sample{k:05d}", label=f"sample {k}")
    runs = run_laws(plant, job["laws"], job["reference"], settings.run)
    bad = [f"{name}: {v}" for name, v in runs.items() if isinstance(v, SimulationDiverged)]
    if bad:
        row["status"] = "diverged: " + "; ".join(bad)
    figures = {name: run_metrics(t, job["joint_names"]) for name, t in runs.items()
               if not isinstance(t, SimulationDiverged)}
    for name, m in figures.items():
        row.update({f"{name}_{key}": v for key, v in m.items()})
    for name, r in error_ratios(figures, settings.baseline).items():
        row[f"error_ratio_{name}"] = r["error_ratio"]
        row[f"torque_ratio_{name}"] = r["torque_ratio"]
    return row


def _run_chunk(task) -> list[dict]:
    """Simulate the samples ``task[1]`` of campaign job ``task[0]`` (runs in a worker)."""
    job, indices = task
    return [sample_row(job, k) for k in indices]


def run_campaign(robot, laws, settings: CampaignSettings, *, reference: Reference | None = None,
                 params: ArmParams | None = None, jobs: int | None = None,
                 scheduler: str | None = None, executor: Executor | None = None,
                 skip_joints=(), chunk: int | None = None, progress=None) -> Campaign:
    """Run every law on ``settings.samples`` seeded uncertain plants.

    Parameters
    ----------
    robot : Robot
        Nominal arm (the plants are drawn around it).
    laws : sequence of ControlLaw or SampledLaw
        Built-in (:func:`rrr_pin.runner.make_laws`) or your own; picklable (a worker process
        receives them); the baseline among them.
    settings : CampaignSettings
    reference : Reference, optional
        Default :func:`rrr_pin.study.default_reference`.
    params : ArmParams, optional
        Perturb this DH parameter set (the paper's RRR); default: perturb the URDF
        (``paper_params()`` when ``robot`` is ``"rrr"``).
    jobs : int, optional
        Local worker processes, >= 1 (default ``min(2, CPUs)``); 1 runs in this process.
    scheduler : str, optional
        Address of a Dask distributed scheduler; the same tasks go there instead.
    executor : concurrent.futures.Executor, optional
        Any executor to use as is (overrides ``jobs`` and ``scheduler``).
    skip_joints : iterable of str
        Joints whose origins are not perturbed.
    chunk : int, optional
        Samples per task (default: about 4 tasks per worker, at most 50 samples).
    progress : callable, optional
        ``progress(done, total)`` after each finished chunk.

    Returns
    -------
    Campaign
    """
    from .study import default_reference

    laws = check_laws(laws, robot.nq, settings.baseline)
    if jobs is not None and (isinstance(jobs, bool) or int(jobs) != jobs or jobs < 1):
        raise ValueError(f"jobs must be an integer >= 1, got {jobs!r}")
    reference = default_reference(robot) if reference is None else reference
    reference.check_limits(robot, duration=settings.run.duration)
    if params is None and robot.source == "rrr":
        params = paper_params()
    job = {
        "settings": settings, "laws": laws, "reference": reference,
        "params": params.to_dict() if params is not None else None,
        "nominal_xml": robot.urdf, "gravity": robot.gravity, "lock": dict(robot.locked),
        "skip_joints": tuple(skip_joints), "joint_names": list(robot.joint_names),
    }
    samples = int(settings.samples)
    jobs = jobs or min(2, os.cpu_count() or 1)
    workers = jobs if executor is None and scheduler is None else 4
    size = chunk or max(1, min(50, math.ceil(samples / (4 * workers))))
    tasks = [(job, list(range(i, min(i + size, samples)))) for i in range(0, samples, size)]
    rows: list[dict] = []
    own, client = None, None
    if executor is None and scheduler is not None:
        from distributed import Client

        client = Client(scheduler)
        executor = client.get_executor()
    elif executor is None and jobs > 1:
        executor = own = ProcessPoolExecutor(max_workers=jobs)
    try:
        results = executor.map(_run_chunk, tasks) if executor is not None else map(
            _run_chunk, tasks)
        for chunk_rows in results:
            rows.extend(chunk_rows)
            if progress:
                progress(len(rows), samples)
    finally:
        if own is not None:
            own.shutdown()
        if client is not None:
            client.close()
    rows.sort(key=lambda r: r["index"])
    return Campaign(robot=robot.name, joint_names=list(robot.joint_names),
                    laws=[law.describe() for law in laws], rows=rows,
                    settings={**settings.to_dict(), "reference": reference.to_dict()})


def _metrics(names, baseline):
    """Per-sample scalar metrics and the direction that is "worst" for each."""
    out = {}
    for name in names:
        out.update({f"{name}_rms_error": "max", f"{name}_max_error": "max",
                    f"{name}_rms_torque": "max"})
    for name in names:
        if name != baseline:
            out[f"error_ratio_{name}"] = "min"
            out[f"torque_ratio_{name}"] = "max"
    return out


def campaign_columns(names, baseline, joint_names) -> list[str]:
    """Columns of ``campaign.csv``, in order."""
    columns = ["index", "seed", "status"] + list(_metrics(names, baseline))
    for name in names:
        columns += [f"{name}_rms_error_{j}" for j in joint_names]
    return columns


def campaign_summary(campaign: Campaign) -> dict:
    """Median, 95th percentile and worst of each metric over the samples where it exists.

    Returns
    -------
    dict
        ``samples``, ``samples_ok`` (every law ran), ``samples_diverged``, ``diverged`` (their
        indices), ``baseline``, ``fraction_better`` (per law other than the baseline: share of
        the samples where both ran in which the law's RMS error is smaller) and, per metric,
        ``{median, p95, worst, count}`` ("worst" is the maximum, except for the error ratios,
        where it is the minimum: the least benefit over the baseline).
    """
    rows, base = campaign.rows, campaign.baseline
    ok = [r for r in rows if r["status"] == "ok"]
    out = {"samples": len(rows), "samples_ok": len(ok), "samples_diverged": len(rows) - len(ok),
           "diverged": [r["index"] for r in rows if r["status"] != "ok"], "baseline": base,
           "fraction_better": {}}
    for name in campaign.names:
        key = f"error_ratio_{name}"
        both = [r for r in rows if key in r]
        if name != base and both:
            out["fraction_better"][name] = float(np.mean([r[key] > 1.0 for r in both]))
    for metric, worst in _metrics(campaign.names, base).items():
        v = np.array([r[metric] for r in rows if metric in r])
        if v.size:
            out[metric] = {"median": float(np.median(v)), "p95": float(np.percentile(v, 95)),
                           "worst": float(v.max() if worst == "max" else v.min()),
                           "count": int(v.size)}
    return out


def write_campaign(campaign: Campaign, out: str | Path) -> dict:
    """Write ``campaign.csv``, ``samples.jsonl`` (parameters), ``summary.json`` and a figure.

    Returns
    -------
    dict
        The summary; ``summary["written"]`` lists the files this call wrote.
    """
    from .plotting import plot_campaign

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    columns = campaign_columns(campaign.names, campaign.baseline, campaign.joint_names)
    written = [out / "campaign.csv", out / "samples.jsonl", out / "summary.json"]
    with open(written[0], "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        for row in campaign.rows:
            writer.writerow({**row, "seed": f"{row['seed'][0]}:{row['seed'][1]}"})
    with open(written[1], "w") as fh:
        for row in campaign.rows:
            fh.write(json.dumps({"index": row["index"], "seed": row["seed"],
                                 "status": row["status"],
                                 "parameters": row["parameters"]}) + "\n")
    summary = campaign_summary(campaign)
    written[2].write_text(json.dumps(
        {"robot": campaign.robot, "controllers": campaign.laws, "settings": campaign.settings,
         "summary": summary}, indent=1) + "\n")
    figure = out / "montecarlo.png"
    if figure.exists():
        figure.unlink()
    if summary["samples_ok"]:
        written.append(plot_campaign(campaign, figure))
    summary["written"] = [str(p) for p in written]
    return summary

"""Monte Carlo robustness campaigns: thousands of seeded uncertain plants, both controllers.

Each sample ``k`` of a campaign with seed ``s`` is the plant
:func:`rrr_pin.uncertainty.sample_plant` draws with ``default_rng([s, k])``; it is generated,
simulated under FL alone and H-infinity + FL and reduced to figures inside the worker, so only
a row of numbers travels back. Rows are put in sample order, so the results are identical
whatever the number of workers or where they run.

Workers: ``jobs`` local processes (:class:`concurrent.futures.ProcessPoolExecutor`) or a Dask
distributed cluster (``scheduler="tcp://host:8786"``, through ``Client.get_executor()``, which
is a ``concurrent.futures.Executor`` too): one code path, two executors.

A sample whose closed loop diverges is recorded with its status and parameters; the campaign
goes on.
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
from .dynamics import Robot, robot_from_xml
from .simulate import SineReference
from .study import (
    CONTROLLERS,
    controller_spec,
    default_reference,
    simulate_both,
    worker_controllers,
)
from .uncertainty import Tolerances, sample_plant

__all__ = ["Campaign", "run_campaign", "campaign_summary", "write_campaign"]

#: Per-sample scalar metrics and the direction that is "worst" for each.
_WORST = {
    "fl_rms_error": "max", "hinf_rms_error": "max", "fl_max_error": "max",
    "hinf_max_error": "max", "fl_rms_torque": "max", "hinf_rms_torque": "max",
    "error_ratio": "min", "torque_ratio": "max",
}


@dataclass
class Campaign:
    """Rows of a campaign, one per sample, in sample order.

    Attributes
    ----------
    robot : str
    joint_names : list of str
    rows : list of dict
        ``index``, ``seed``, ``status`` (``"ok"`` or the divergence message), ``parameters``
        and, for ``"ok"`` rows, the scalar metrics of :data:`_WORST` plus per-joint RMS
        errors ``fl_rms_error_<joint>``, ``hinf_rms_error_<joint>`` [rad].
    settings : dict
        Reference, rate, duration, seed, tolerances, engine.
    """

    robot: str
    joint_names: list
    rows: list
    settings: dict = field(default_factory=dict)


_SOURCES: dict = {}


def _plant_source(cfg: dict):
    """Return the nominal arm the plants are drawn around: ArmParams or URDF text (cached)."""
    key = (cfg["spec"]["key"], json.dumps(cfg["params"], sort_keys=True))
    if _SOURCES.get("key") != key:
        _SOURCES.clear()
        _SOURCES.update(key=key, source=ArmParams.from_dict(cfg["params"])
                        if cfg["params"] is not None else cfg["spec"]["nominal_xml"])
    return _SOURCES["source"]


def _run_chunk(job) -> list[dict]:
    """Simulate the samples ``job[1]`` of campaign ``job[0]`` (runs in a worker)."""
    cfg, indices = job
    spec = cfg["spec"]
    controllers = worker_controllers(spec)
    source = _plant_source(cfg)
    tol = Tolerances(*cfg["tolerances"])
    rows = []
    for k in indices:
        sample = sample_plant(source, cfg["seed"], k, tol, skip_joints=cfg["skip_joints"])
        row = {"index": k, "seed": sample.seed, "status": "ok",
               "parameters": sample.parameters}
        plant = robot_from_xml(sample.urdf, gravity=spec["gravity"], lock=spec["lock"],
                               name=f"sample{k:05d}", label=f"sample {k}")
        runs, row["status"] = simulate_both(plant, controllers, cfg["reference"],
                                            cfg["duration"], dt=cfg["dt"], rate=cfg["rate"],
                                            engine=cfg["engine"])
        if not runs:
            rows.append(row)
            continue
        for key, traj in runs.items():
            e, tau = traj.error, traj.tau
            row[f"{key}_rms_error"] = float(np.sqrt(np.mean(e * e)))
            row[f"{key}_max_error"] = float(np.max(np.abs(e)))
            row[f"{key}_rms_torque"] = float(np.sqrt(np.mean(tau * tau)))
            rms = np.sqrt(np.mean(e * e, axis=0))
            for name, v in zip(cfg["joint_names"], rms, strict=True):
                row[f"{key}_rms_error_{name}"] = float(v)
        row["error_ratio"] = row["fl_rms_error"] / row["hinf_rms_error"]
        row["torque_ratio"] = row["hinf_rms_torque"] / row["fl_rms_torque"]
        rows.append(row)
    return rows


def run_campaign(robot: Robot, K, *, samples: int, seed: int = 0, rate: float | None = 1000.0,
                 duration: float = 10.0, dt: float = 1e-3,
                 reference: SineReference | None = None, params: ArmParams | None = None,
                 tolerances: Tolerances | None = None, lam_fl: float = 100.0,
                 lam_hinf: float = 45.0, jobs: int | None = None, scheduler: str | None = None,
                 executor: Executor | None = None, engine: str = "auto",
                 skip_joints=(), chunk: int | None = None, progress=None) -> Campaign:
    """Run FL alone and H-infinity + FL on ``samples`` seeded uncertain plants.

    Parameters
    ----------
    robot : Robot
        Nominal arm (the controllers' model).
    K : control LTI
        H-infinity controller (SISO, copied on the diagonal, or ``n x n``).
    samples : int
        Number of plants, >= 1.
    seed : int, default 0
        Campaign seed.
    rate : float or None, default 1000
        Controller sampling rate [Hz] (zero-order hold); ``None`` for continuous-time laws.
    duration : float, default 10
        Simulated time per rollout [s].
    dt : float, default 1e-3
        RK4 step (plant sub-step) [s].
    reference : SineReference, optional
        Default :func:`rrr_pin.study.default_reference`.
    params : ArmParams, optional
        Perturb this DH parameter set (the paper's RRR); default: perturb the URDF
        (``paper_params()`` when ``robot`` is ``"rrr"``).
    tolerances : Tolerances, optional
        Default ``Tolerances()``: 20 % inertia, 5 % lengths.
    lam_fl, lam_hinf : float
        Bandwidths [rad/s].
    jobs : int, optional
        Local worker processes (default ``min(2, CPUs)``); 1 runs in this process.
    scheduler : str, optional
        Address of a Dask distributed scheduler; the same tasks go there instead.
    executor : concurrent.futures.Executor, optional
        Any executor to use as is (overrides ``jobs`` and ``scheduler``).
    engine : {"auto", "python", "compiled"}
        Rollout path of :func:`rrr_pin.simulate.simulate`.
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
    if int(samples) != samples or samples < 1:
        raise ValueError(f"samples must be a positive integer, got {samples!r}")
    reference = default_reference(robot) if reference is None else reference
    reference.check_limits(robot)
    tolerances = Tolerances() if tolerances is None else tolerances
    if params is None and robot.source == "rrr":
        params = paper_params()
    cfg = {
        "spec": controller_spec(robot, K, lam_fl, lam_hinf),
        "params": params.to_dict() if params is not None else None,
        "reference": reference, "duration": duration, "dt": dt, "rate": rate,
        "engine": engine, "seed": int(seed),
        "tolerances": (tolerances.inertia, tolerances.length),
        "skip_joints": tuple(skip_joints), "joint_names": robot.joint_names,
    }
    jobs = jobs or min(2, os.cpu_count() or 1)
    workers = jobs if executor is None and scheduler is None else 4
    size = chunk or max(1, min(50, math.ceil(samples / (4 * workers))))
    tasks = [(cfg, list(range(i, min(i + size, samples)))) for i in range(0, samples, size)]
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
    settings = {"reference": reference.to_dict(), "rate_hz": rate, "duration_s": duration,
                "dt_s": dt, "seed": int(seed), "samples": int(samples),
                "tolerance_inertia": tolerances.inertia, "tolerance_length": tolerances.length,
                "lam_fl_rad_s": lam_fl, "lam_hinf_rad_s": lam_hinf, "engine": engine}
    return Campaign(robot=robot.name, joint_names=robot.joint_names, rows=rows,
                    settings=settings)


def campaign_summary(campaign: Campaign) -> dict:
    """Median, 95th percentile and worst of each metric over the samples that ran.

    Returns
    -------
    dict
        ``samples``, ``samples_ok``, ``samples_diverged``, ``diverged`` (their indices),
        ``fraction_hinf_better`` (share of the samples that ran where H-infinity + FL has the
        smaller RMS error) and, per metric, ``{median, p95, worst}`` ("worst" is the maximum,
        except for ``error_ratio``, where it is the minimum: the least benefit of H-infinity).
    """
    ok = [r for r in campaign.rows if r["status"] == "ok"]
    out = {"samples": len(campaign.rows), "samples_ok": len(ok),
           "samples_diverged": len(campaign.rows) - len(ok),
           "diverged": [r["index"] for r in campaign.rows if r["status"] != "ok"]}
    if not ok:
        return out
    out["fraction_hinf_better"] = float(np.mean([r["hinf_rms_error"] < r["fl_rms_error"]
                                                 for r in ok]))
    for name, worst in _WORST.items():
        v = np.array([r[name] for r in ok])
        out[name] = {"median": float(np.median(v)), "p95": float(np.percentile(v, 95)),
                     "worst": float(v.max() if worst == "max" else v.min())}
    return out


def write_campaign(campaign: Campaign, out: str | Path) -> dict:
    """Write ``campaign.csv``, ``samples.jsonl`` (parameters), ``summary.json`` and figures.

    Returns
    -------
    dict
        The summary.
    """
    from .plotting import plot_campaign

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    columns = ["index", "seed", "status"] + list(_WORST)
    for key in CONTROLLERS:
        columns += [f"{key}_rms_error_{name}" for name in campaign.joint_names]
    with open(out / "campaign.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        for row in campaign.rows:
            writer.writerow({**row, "seed": f"{row['seed'][0]}:{row['seed'][1]}"})
    with open(out / "samples.jsonl", "w") as fh:
        for row in campaign.rows:
            fh.write(json.dumps({"index": row["index"], "seed": row["seed"],
                                 "status": row["status"],
                                 "parameters": row["parameters"]}) + "\n")
    summary = campaign_summary(campaign)
    (out / "summary.json").write_text(json.dumps(
        {"robot": campaign.robot, "settings": campaign.settings, "summary": summary},
        indent=1) + "\n")
    if summary["samples_ok"]:
        plot_campaign(campaign, out / "montecarlo.png")
    return summary

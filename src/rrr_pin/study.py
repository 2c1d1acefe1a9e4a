"""The paper's section-5 study: both controllers on the nominal and on uncertain plants.

One code path for any fixed-base arm: the nominal robot (the paper's RRR, an example-robot-data
arm or a URDF), its uncertain plants (:mod:`rrr_pin.uncertainty`, written out as URDF and loaded
back), the two tracking laws (:mod:`rrr_pin.controllers`) and the simulation
(:mod:`rrr_pin.simulate`). Plants run in parallel processes; results do not depend on the
number of processes.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from .controllers import fl_controller, hinf_fl_controller
from .dh import paper_params
from .dynamics import Robot, robot_from_xml
from .simulate import DEFAULT_DT, SimulationDiverged, SineReference, metrics, simulate
from .uncertainty import PlantSample, Tolerances, sample_plants

__all__ = [
    "controller_spec",
    "simulate_both",
    "worker_controllers",
    "StudyConfig",
    "StudyResult",
    "default_reference",
    "run_study",
    "summarize",
    "CONTROLLERS",
]

#: Result keys of the two controllers, and their labels in figures and tables.
CONTROLLERS = {"fl": "FL alone", "hinf": "H-infinity + FL"}


def default_reference(robot: Robot, amp: float = 0.5, freq: float = 0.5,
                      home=None) -> SineReference:
    """Build a sinusoid per joint about a home configuration, inside the joint limits.

    Parameters
    ----------
    robot : Robot
        The arm (for its neutral configuration and limits).
    amp : float, default 0.5
        Amplitude [rad]. Where a joint's range is narrower than ``2.2 amp`` it is reduced to
        45 % of that range.
    freq : float, default 0.5
        Frequency [Hz].
    home : array-like, shape (n,), optional
        Centre of the motion [rad]; default the URDF's neutral configuration, moved inside the
        limits where it is closer to them than ``1.1 amp``.

    Returns
    -------
    SineReference
        Phases ``2 pi j / n`` for joint ``j``, so the joints do not move in lockstep.
    """
    n = robot.nq
    lower, upper = robot.lower, robot.upper
    width = upper - lower
    a = np.where(width >= 2.2 * amp, amp, 0.45 * width)
    if home is None:
        # 10 % of the amplitude to spare, so tracking errors cannot touch the limits.
        home = np.clip(robot.neutral(), lower + 1.1 * a, upper - 1.1 * a)
    home = np.asarray(home, dtype=float)
    ref = SineReference(home=home, amp=a, freq=freq, phase=2.0 * math.pi * np.arange(n) / n)
    ref.check_limits(robot)
    return ref


@dataclass(frozen=True)
class StudyConfig:
    """Settings of a study.

    Parameters
    ----------
    duration : float, default 4
        Simulated time of each run [s].
    dt : float, default 1e-3
        RK4 step [s] (plant sub-step for sampled laws).
    rate : float, optional
        Sampling rate of digital controllers [Hz]; ``None`` for continuous-time laws (default,
        as in the paper's Simulink study).
    lam_fl, lam_hinf : float, default 100, 45
        FL bandwidths [rad/s] of the two controllers (paper sections 5 and 4.2).
    samples : int, default 10
        Number of uncertain plants (the paper's count).
    seed : int, default 0
        Seed of the uncertain plants.
    tolerances : Tolerances
        20 % inertia, 5 % lengths by default.
    jobs : int, optional
        Worker processes; default ``min(2, cpu count)``.
    engine : {"auto", "python", "compiled"}, default "auto"
        Rollout path of sampled laws (:func:`rrr_pin.simulate.simulate`); continuous-time
        laws always run in Python.
    """

    duration: float = 4.0
    dt: float = DEFAULT_DT
    rate: float | None = None
    lam_fl: float = 100.0
    lam_hinf: float = 45.0
    samples: int = 10
    seed: int = 0
    tolerances: Tolerances = field(default_factory=Tolerances)
    jobs: int | None = None
    engine: str = "auto"

    def to_dict(self) -> dict:
        """JSON-ready settings (units in the key names)."""
        return {"duration_s": self.duration, "dt_s": self.dt, "rate_hz": self.rate,
                "lam_fl_rad_s": self.lam_fl, "lam_hinf_rad_s": self.lam_hinf,
                "samples": self.samples, "seed": self.seed,
                "tolerance_inertia": self.tolerances.inertia,
                "tolerance_length": self.tolerances.length}


@dataclass
class StudyResult:
    """Trajectories and figures of a study.

    Attributes
    ----------
    robot : str
        Name of the nominal arm.
    joint_names : list of str
    reference : SineReference
    config : StudyConfig
    nominal : dict
        ``{"fl": Trajectory, "hinf": Trajectory}`` on the nominal plant.
    samples : list of dict
        Per uncertain plant: ``index``, ``seed``, ``parameters``, ``status`` (``"ok"`` or the
        divergence message), ``trajectories`` (as ``nominal``; absent if diverged) and
        ``metrics`` (per controller).
    plants : list of PlantSample
    """

    robot: str
    joint_names: list
    reference: SineReference
    config: StudyConfig
    nominal: dict
    samples: list
    plants: list
    design: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        """Return the ``results.json`` content (layout in the README)."""
        ok = [s for s in self.samples if s["status"] == "ok"]
        uncertain = {key: _mean_metrics([s["metrics"][key] for s in ok]) for key in CONTROLLERS}
        return {
            "robot": self.robot,
            "joint_names": self.joint_names,
            "reference": {**self.reference.to_dict(), "duration_s": self.config.duration},
            "config": self.config.to_dict(),
            "design": self.design,
            "nominal": {key: metrics(self.nominal[key]) for key in CONTROLLERS},
            "uncertain": {
                **uncertain,
                "samples": [{"index": s["index"], "seed": s["seed"], "status": s["status"],
                             "parameters": s["parameters"], **s.get("metrics", {})}
                            for s in self.samples],
            },
            "summary": summarize(self),
        }


def _mean_metrics(rows: list[dict]) -> dict:
    if not rows:
        return {}
    return {k: np.mean([row[k] for row in rows], axis=0).tolist() for k in rows[0]}


def summarize(result: StudyResult) -> dict:
    """Headline figures of a study.

    Returns
    -------
    dict
        ``nominal_max_error`` [rad], per controller (both sit at the integrator's noise level on
        the exact model: a ratio of the two is no claim); ``error_ratio_uncertain``, RMS error
        over all joints, samples and time of FL alone divided by that of H-infinity + FL;
        ``error_ratio_uncertain_per_joint`` the same per joint; ``torque_ratio_uncertain``,
        RMS torque of H-infinity + FL over that of FL alone; ``samples_ok`` and
        ``samples_diverged``.
    """
    ok = [s for s in result.samples if s["status"] == "ok"]
    out = {
        "nominal_max_error": {k: float(np.max(np.abs(result.nominal[k].error)))
                              for k in CONTROLLERS},
        "samples_ok": len(ok),
        "samples_diverged": len(result.samples) - len(ok),
    }
    if ok:
        def rms(key, what, axis=None):
            sq = np.array([np.asarray(s["metrics"][key][what]) ** 2 for s in ok])
            return np.sqrt(np.mean(sq, axis=axis))

        out["error_ratio_uncertain"] = float(rms("fl", "rms_error") / rms("hinf", "rms_error"))
        out["error_ratio_uncertain_per_joint"] = (
            rms("fl", "rms_error", axis=0) / rms("hinf", "rms_error", axis=0)).tolist()
        out["torque_ratio_uncertain"] = float(rms("hinf", "rms_torque") /
                                              rms("fl", "rms_torque"))
    return out


# --- workers ----------------------------------------------------------------------------------

def controller_spec(nominal: Robot, K, lam_fl: float, lam_hinf: float) -> dict:
    """Picklable description of both controllers, rebuilt once per worker process.

    Parameters
    ----------
    nominal : Robot
        The controllers' model.
    K : control LTI
        The H-infinity controller (SISO or ``n x n``).
    lam_fl, lam_hinf : float
        Bandwidths [rad/s] of FL alone and of H-infinity + FL.

    Returns
    -------
    dict
        URDF text, locked joints and gravity of ``nominal``; ``K`` as ``(A, B, C, D)``; the
        bandwidths; and ``key``, which identifies the spec in a worker's cache.
    """
    import control

    Kss = control.ss(K)
    mats = tuple(np.asarray(m, dtype=float) for m in (Kss.A, Kss.B, Kss.C, Kss.D))
    spec = {"nominal_xml": nominal.urdf, "lock": dict(nominal.locked),
            "gravity": nominal.gravity, "K": mats, "lam_fl": float(lam_fl),
            "lam_hinf": float(lam_hinf)}
    spec["key"] = hash((nominal.urdf, tuple(sorted(spec["lock"].items())), spec["gravity"],
                        tuple(m.tobytes() for m in mats), spec["lam_fl"], spec["lam_hinf"]))
    return spec


_CACHE: dict = {}


def worker_controllers(spec: dict) -> dict:
    """Build (once per process) the controllers ``{"fl", "hinf"}`` of a :func:`controller_spec`."""
    if _CACHE.get("key") != spec["key"]:
        import control

        nominal = robot_from_xml(spec["nominal_xml"], gravity=spec["gravity"],
                                 lock=spec["lock"], label="nominal")
        _CACHE.clear()
        _CACHE.update(key=spec["key"], controllers={
            "fl": fl_controller(nominal, spec["lam_fl"]),
            "hinf": hinf_fl_controller(nominal, control.ss(*spec["K"]), spec["lam_hinf"])})
    return _CACHE["controllers"]


def simulate_both(plant: Robot, controllers: dict, reference: SineReference, duration: float,
                  **kwargs) -> tuple[dict, str]:
    """Run every controller on ``plant``; stop at the first divergence.

    Returns
    -------
    runs : dict
        Trajectories by controller key (empty if a run diverged).
    status : str
        ``"ok"``, or the divergence message prefixed with the controller's label.
    """
    runs = {}
    for key, ctrl in controllers.items():
        try:
            runs[key] = simulate(plant, ctrl, reference, duration, **kwargs)
        except SimulationDiverged as exc:
            return {}, f"{CONTROLLERS[key]}: {exc}"
    return runs, "ok"


def _run_plant(task) -> dict:
    """Simulate both controllers on one plant (runs in a worker process)."""
    controllers = worker_controllers(task["spec"])
    plant = robot_from_xml(task["plant_xml"], gravity=task["spec"]["gravity"],
                           lock=task["spec"]["lock"], name=task["plant_name"],
                           label=task["plant_name"])
    runs, status = simulate_both(plant, controllers, task["reference"], task["duration"],
                                 dt=task["dt"], rate=task["rate"], engine=task["engine"])
    return {"trajectories": runs, "status": status}


def run_study(nominal: Robot, K, *, config: StudyConfig = StudyConfig(),
              reference: SineReference | None = None, params=None,
              skip_joints=(), progress=None) -> StudyResult:
    """Run both controllers on the nominal plant and on ``config.samples`` uncertain plants.

    Parameters
    ----------
    nominal : Robot
        The nominal arm; the controllers use only this model.
    K : control LTI
        The H-infinity controller (SISO, copied on the diagonal, or ``n x n``; negative
        feedback on ``e = r - q``), e.g. ``design().K_reduced``.
    config : StudyConfig
        Durations, rates, bandwidths, sample count and seed.
    reference : SineReference, optional
        Default :func:`default_reference` of the nominal arm.
    params : ArmParams, optional
        For the paper's RRR: perturb this DH parameter set (its URDF is generated); by default
        the nominal URDF itself is perturbed (:func:`rrr_pin.uncertainty.perturb_urdf`).
    skip_joints : iterable of str
        Joints whose origins are not perturbed (e.g. locked fingers).
    progress : callable, optional
        Called as ``progress(done, total)`` after each plant.

    Returns
    -------
    StudyResult
    """
    reference = default_reference(nominal) if reference is None else reference
    reference.check_limits(nominal)
    if nominal.source == "rrr" and params is None:
        params = paper_params()
    source = params if params is not None else nominal.urdf
    plants: list[PlantSample] = sample_plants(source, config.samples, config.seed,
                                              config.tolerances, skip_joints=skip_joints)
    base = {
        "spec": controller_spec(nominal, K, config.lam_fl, config.lam_hinf),
        "reference": reference, "duration": config.duration, "dt": config.dt,
        "rate": config.rate, "engine": config.engine,
    }
    tasks = [{**base, "plant_xml": nominal.urdf, "plant_name": f"{nominal.name} (nominal)"}]
    tasks += [{**base, "plant_xml": p.urdf, "plant_name": f"{nominal.name}_sample{p.index:03d}"}
              for p in plants]
    jobs = config.jobs or min(2, os.cpu_count() or 1)
    outputs = []
    if jobs <= 1:
        for k, task in enumerate(tasks):
            outputs.append(_run_plant(task))
            if progress:
                progress(k + 1, len(tasks))
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            for k, out in enumerate(pool.map(_run_plant, tasks)):
                outputs.append(out)
                if progress:
                    progress(k + 1, len(tasks))
    if outputs[0]["status"] != "ok":
        raise SimulationDiverged(f"the nominal closed loop diverged: {outputs[0]['status']}",
                                 time=math.nan, joint="")
    samples = []
    for plant, out in zip(plants, outputs[1:], strict=True):
        entry = {"index": plant.index, "seed": plant.seed, "parameters": plant.parameters,
                 "status": out["status"]}
        if out["status"] == "ok":
            entry["trajectories"] = out["trajectories"]
            entry["metrics"] = {k: metrics(out["trajectories"][k]) for k in CONTROLLERS}
        samples.append(entry)
    return StudyResult(robot=nominal.name, joint_names=nominal.joint_names, reference=reference,
                       config=config, nominal=outputs[0]["trajectories"], samples=samples,
                       plants=plants)

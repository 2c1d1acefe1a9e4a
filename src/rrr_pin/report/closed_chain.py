"""A closed-chain study's outputs: ``results.json``, ``results.md``, figures, ``report.html``.

Figures (matplotlib, Agg, nothing registered with pyplot): ``fig5_nominal.png`` (tracking
errors [rad] of each actuated joint over time [s], one column per law, on the nominal
mechanism), ``fig6_uncertain.png`` (the same on every uncertain plant, the nominal in black)
and, for the Delta, ``adept_cycle.png`` (the platform path in the x-z plane [mm], reference
and the nominal runs).

``report.html`` (:func:`write_chain_report`) is the serial study's page
(:mod:`rrr_pin.report.html`) for a parallel mechanism: the claims and per-plant table, the
figures, the settings (study, mechanism parameters, reference, laws, loop drift) and one 3D
scene per law (:func:`chain_scenes`): the nominal mechanism opaque, each uncertain plant, with
its own perturbed lengths, as a translucent ghost. Every joint moves: the passive ones are
solved from the recorded actuated angles at each frame by the loop closure
(:func:`rrr_pin.report.viewer.full_configurations`).
"""

from __future__ import annotations

from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ..campaign.closed_chain_study import adept_point, circle_point
from ..model.closed_chain import load_closed_chain
from ..model.mechanisms import DeltaParams, FiveBarParams, delta_fk, mechanism_params
from .html import write_report_html
from .jsondata import dumps
from .viewer import Scene, Track

__all__ = ["write_chain_study", "write_chain_report", "chain_scenes", "chain_settings",
           "chain_captions", "plant_params", "claims_table", "CHAIN_UNITS"]

#: Units of the keys of :func:`chain_settings` that carry no unit suffix ("-": dimensionless).
CHAIN_UNITS = {"duration": "s", "rate": "Hz", "lam_fl": "rad/s", "lam_hinf": "rad/s",
               "inertia": "-", "length": "-", "samples": "-", "seed": "-", "d": "m", "l1": "m",
               "l2": "m", "m1": "kg", "m2": "kg", "radius": "m", "home_x": "m", "home_z": "m",
               "R": "m", "r": "m", "L": "m", "l": "m", "m_upper": "kg", "m_fore": "kg",
               "m_platform": "kg", "dt": "s", "substeps": "-", "reference_max_cond_Jp": "-",
               "runs": "-"}


def claims_table(result) -> str:
    """Return the study's claims, certificates and per-plant numbers as Markdown."""
    names = result.names
    lines = [f"# {mechanism_params(result.config.mechanism).name}: "
             f"{', '.join(result.labels)}", "",
             f"Reference: {result.reference}; {result.config.samples} uncertain plants "
             f"(seed {result.config.seed}, masses +-{result.config.inertia:.0%}, lengths "
             f"+-{result.config.length:.0%}); plant: Pinocchio constraintDynamics.", ""]
    if result.claims:
        lines += ["| claim (paper, sec. 5-6) | measured | holds |", "|---|---|---|"]
    for c in result.claims:
        verdict = "undetermined (a run failed)" if c["holds"] is None else (
            "yes" if c["holds"] else "no")
        lines.append(f"| {c['claim']} | {c['value']:.4g} | {verdict} |")
    if result.claims_note:
        lines.append(result.claims_note)
    cert = result.summary().get("certificates")
    if cert:
        lines += ["", f"Frozen-configuration certificates (H-infinity design, nu-gap against "
                      f"b(Gs, Ks) = {cert['b']:.4g}): {cert['certified']} of {cert['checked']} "
                      f"uncertain plants certified, largest nu-gap {cert['nugap_max']:.4g}."]
    lines += ["", "| plant | " + " | ".join(f"RMS error {k} [rad]" for k in names) + " | "
              + " | ".join(f"RMS torque {k} [N m]" for k in names) + " | drift [m] |",
              "|---|" + "---|" * (2 * len(names) + 1)]
    for m in result.metrics:
        runs = [m[k] for k in names]
        lines.append(f"| {m['plant']} | "
                     + " | ".join(f"{a['rms_error_rad']:.3e}" for a in runs) + " | "
                     + " | ".join(f"{a['rms_tau_Nm']:.4g}" for a in runs) + " | "
                     f"{float(np.max([a['drift_m'] for a in runs])):.1e} |")
    failed = [(m["plant"], k, m[k]["status"]) for m in result.metrics for k in result.names
              if m[k]["status"] != "ok"]
    lines += [""] + [f"- {p} {k}: {s}" for p, k, s in failed]
    return "\n".join(lines) + "\n"


def _errors(fig: Figure, result, rows) -> None:
    # The paper's pair shares its axis (hinf's smaller error shows); more laws (PD's error is
    # 100x FL's) each get their own.
    axes = fig.subplots(1, len(result.names), sharey=len(result.names) <= 2,
                        squeeze=False)[0]
    for ax, name, title in zip(axes, result.names, result.labels, strict=True):
        for i in rows:
            traj = result.trajectories[i][name]
            if traj is None:
                continue
            e = traj.q - traj.r
            many = len(rows) > 1
            for j in range(e.shape[1]):
                if many and i == 0:  # the nominal plant, in black over the uncertain ones
                    label = "nominal plant" if j == 0 else None
                else:
                    first = rows[1] if many else rows[0]
                    label = (f"{traj.joint_names[j]}" + (", uncertain" if many else "")
                             if i == first else None)
                ax.plot(traj.t, e[:, j], lw=1.2 if i == 0 else 0.6,
                        color="black" if (i == 0 and many) else f"C{j}",
                        alpha=1.0 if i == 0 else 0.5, zorder=3 if i == 0 else 2, label=label)
        ax.set_title(title)
        ax.set_xlabel("time [s]")
        ax.grid(True, alpha=0.3)
        ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 2))
    axes[0].set_ylabel("tracking error r - q_a [rad]")
    labelled = [ax for ax in axes if ax.get_legend_handles_labels()[0]]
    if labelled:  # none when every run failed (their reasons are in results.md)
        labelled[-1].legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)


def _adept(fig: Figure, result, params: DeltaParams) -> None:
    ax = fig.subplots()
    traj = result.trajectories[0][result.names[0]]
    ref = np.array([delta_fk(params, r) for r in traj.r]) * 1000.0
    ax.plot(ref[:, 0], ref[:, 2], color="0.6", lw=4, label="reference (adept cycle)")
    for k, (name, label) in enumerate(zip(result.names, result.labels, strict=True)):
        traj = result.trajectories[0][name]
        if traj is not None:
            p = np.array([delta_fk(params, q) for q in traj.q]) * 1000.0
            ax.plot(p[:, 0], p[:, 2], f"C{k}", lw=1, ls="-" if k == 0 else "--",
                    label=f"{label}, nominal")
    ax.set_xlabel("platform x [mm]")
    ax.set_ylabel("platform z [mm]")
    ax.set_title("Delta: pick-and-place path (25 / 305 / 25 mm)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)


def write_chain_study(result, out: str | Path, params=None, *, report: bool = True
                      ) -> list[Path]:
    """Write ``results.json``, ``results.md``, the figures and ``report.html``; return the paths.

    Parameters
    ----------
    result : rrr_pin.campaign.closed_chain_study.ChainStudyResult
    out : str or Path
        Folder (created).
    params : FiveBarParams or DeltaParams, optional
        The nominal mechanism's parameters (``adept_cycle.png`` for the Delta, the report's
        scenes); default the built-in set of ``result.config.mechanism``.
    report : bool, default True
        Also write ``report.html`` (:func:`write_chain_report`), last in the list.
    """
    params = mechanism_params(result.config.mechanism) if params is None else params
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "results.json", out / "results.md"]
    paths[0].write_text(dumps(result.to_dict(), indent=2) + "\n")
    paths[1].write_text(claims_table(result))
    wide = (max(10.0, 4.0 * len(result.names) + 2.0), 3.6)  # one column per law
    figures = [("fig5_nominal.png", lambda f: _errors(f, result, [0]), wide)]
    if len(result.metrics) > 1:
        figures.append(("fig6_uncertain.png",
                        lambda f: _errors(f, result, list(range(len(result.metrics)))),
                        wide))
    if isinstance(params, DeltaParams):
        figures.append(("adept_cycle.png", lambda f: _adept(f, result, params), (8, 4)))
    for name, draw, size in figures:
        fig = Figure(figsize=size, layout="constrained")
        draw(fig)
        fig.savefig(out / name, dpi=120)
        paths.append(out / name)
    if report:
        paths.append(write_chain_report(result, out, paths[2:], params=params))
    return paths


def plant_params(nominal, factors: dict):
    """Parameters of an uncertain plant: the nominal set with each field scaled by its factor.

    The same product :func:`rrr_pin.model.mechanisms.perturb_mechanism` forms, so the plant
    is rebuilt exactly from its recorded ``factors`` (field name -> factor).
    """
    return replace(nominal, **{n: getattr(nominal, n) * f for n, f in factors.items()})


def chain_scenes(result, params=None) -> list[Scene]:
    """One 3D scene per law of a closed-chain study: nominal plant opaque, uncertain ghosts.

    Each uncertain plant is loaded once from its parameters (:func:`plant_params` of the
    ``factors`` recorded in ``result.metrics``) and shared by the scenes of every law; a run
    that failed (no trajectory) is left out, and a law with no run at all has no scene.

    Parameters
    ----------
    result : rrr_pin.campaign.closed_chain_study.ChainStudyResult
    params : FiveBarParams or DeltaParams, optional
        The nominal parameters; default the built-in set of ``result.config.mechanism``.

    Returns
    -------
    list of rrr_pin.report.viewer.Scene
        The tracks' ``q`` are the recorded actuated angles [rad]; the viewer closes the loop.
        Each scene draws the reference's task-space path (the 5-bar's tip circle, the
        Delta's adept cycle) as a grey line.
    """
    params = mechanism_params(result.config.mechanism) if params is None else params
    plants = [load_closed_chain(params if i == 0 else plant_params(params, m["factors"]))
              for i, m in enumerate(result.metrics)]
    path, path_label = _task_path(params, result.config.duration)
    scenes = []
    for name, label in zip(result.names, result.labels, strict=True):
        tracks = []
        for i, (runs, plant) in enumerate(zip(result.trajectories, plants, strict=True)):
            traj = runs.get(name)
            if traj is None:
                continue
            tracks.append(Track("nominal plant", traj.t, traj.q, robot=plant) if i == 0 else
                          Track(f"uncertain plant {i - 1}", traj.t, traj.q, opacity=0.35,
                                robot=plant))
        if tracks:
            scenes.append(Scene(f"{label}: nominal and uncertain plants", plants[0],
                                tracks, path=path, path_label=path_label))
    return scenes


def _task_path(params, duration: float) -> tuple[np.ndarray | None, str]:
    """Return the reference's task-space path [m], shape (K, 3), and its legend label."""
    t = np.linspace(0.0, duration, 401)
    if isinstance(params, DeltaParams):
        return adept_point(params, t, duration), "adept cycle (platform reference)"
    if isinstance(params, FiveBarParams):
        xz = circle_point(params, t, duration)
        return (np.column_stack([xz[:, 0], np.zeros(len(t)), xz[:, 1]]),
                "tip circle (reference)")
    return None, "reference path"


def chain_settings(result, params=None) -> dict:
    """Return the report's settings: study, mechanism, reference, laws and the loop drift.

    ``drift`` gives, per law, the largest loop-closure gap [m] the plant left before a
    projection over every run (None where no run succeeded) and the bound it was checked
    against (``Trajectory.info["drift_bound_m"]``); ``certificate``, the certificate's design
    when the study has one (``result.certificate``).
    """
    params = mechanism_params(result.config.mechanism) if params is None else params
    drift = {}
    info = {}
    for name in result.names:
        runs = [runs[name] for runs in result.trajectories if runs.get(name) is not None]
        values = [float(traj.info["drift_m"]) for traj in runs]
        drift[name] = {"max_drift_m": max(values) if values else None,
                       "drift_bound_m": (float(runs[0].info["drift_bound_m"]) if runs
                                         else None),
                       "runs": len(runs)}
        if runs and not info:
            info = {k: v for k, v in runs[0].info.items()
                    if isinstance(v, str | int | float) and not k.startswith("drift")}
    out = {"mechanism": mechanism_params(result.config.mechanism).name,
           "reference": result.reference,
           "laws": dict(zip(result.names, result.labels, strict=True)),
           "study": asdict(result.config), "parameters": asdict(params),
           "plant integration": info, "drift": drift}
    certificate = getattr(result, "certificate", None)  # a study that certified its plants
    if certificate:
        out["certificate"] = certificate
    return out


def chain_captions(result) -> dict:
    """Caption of each figure of a closed-chain study, by file name."""
    n = len(result.metrics) - 1
    return {"fig5_nominal.png": "Tracking errors r - q_a [rad] of the actuated joints of "
                                "every law on the nominal mechanism (the exact model).",
            "fig6_uncertain.png": f"Tracking errors [rad] of every law on {n} uncertain plants "
                                  f"(thin lines); the nominal plant's run in black.",
            "adept_cycle.png": "The platform's path in the x-z plane [mm]: the adept cycle "
                               "(reference) and each law on the nominal mechanism."}


def write_chain_report(result, out: str | Path, figures=(), params=None) -> Path:
    """Write ``out/report.html`` for a closed-chain study (module docstring).

    Parameters
    ----------
    result : rrr_pin.campaign.closed_chain_study.ChainStudyResult
    out : path-like
        The study's folder.
    figures : sequence of path-like
        Image files to inline (captions from :func:`chain_captions`).
    params : FiveBarParams or DeltaParams, optional
        The nominal parameters; default the built-in set of ``result.config.mechanism``.

    Returns
    -------
    Path
        The file written.
    """
    captions = chain_captions(result)
    return write_report_html(
        Path(out) / "report.html",
        title=f"rrr-pin study on the {mechanism_params(result.config.mechanism).name}: "
              f"{' vs '.join(result.labels)}",
        tables=[("Claims and per-plant numbers", claims_table(result))],
        figures=[(f, captions.get(Path(f).name, Path(f).name)) for f in figures],
        design=chain_settings(result, params), scenes=chain_scenes(result, params),
        units=CHAIN_UNITS, design_title="Settings")

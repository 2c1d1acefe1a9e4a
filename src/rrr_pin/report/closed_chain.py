"""A closed-chain study's outputs: ``results.json``, ``results.md`` (the claims) and figures.

Figures (matplotlib, Agg, nothing registered with pyplot): ``fig5_nominal.png`` (tracking
errors [rad] of each actuated joint over time [s], one column per law, on the nominal
mechanism), ``fig6_uncertain.png`` (the same on every uncertain plant, the nominal in black)
and, for the Delta, ``adept_cycle.png`` (the platform path in the x-z plane [mm], reference
and the nominal runs).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ..model.mechanisms import DeltaParams, delta_fk
from .jsondata import dumps

__all__ = ["write_chain_study", "claims_table"]


def claims_table(result) -> str:
    """Return the study's claims, certificates and per-plant numbers as Markdown."""
    names = result.names
    lines = [f"# {result.config.mechanism}: {', '.join(result.labels)}", "",
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


def write_chain_study(result, out: str | Path, params=None) -> list[Path]:
    """Write ``results.json``, ``results.md`` and the figures into ``out``; return the paths.

    Parameters
    ----------
    result : rrr_pin.campaign.closed_chain_study.ChainStudyResult
    out : str or Path
        Folder (created).
    params : DeltaParams, optional
        The nominal Delta's parameters, for ``adept_cycle.png``.
    """
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
    return paths

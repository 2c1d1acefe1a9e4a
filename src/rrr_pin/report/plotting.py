"""Figures of the paper, written as PNG files (matplotlib, Agg backend, no window).

Loop-shaping figures of section 4 (each takes a :class:`rrr_pin.robust.loopshaping.Design` and an
output path): Fig. 2 :func:`plot_barriers`, Fig. 3 :func:`plot_shaped_plant`, Fig. 4a
:func:`plot_robust_stability`, Fig. 4b :func:`plot_robust_performance`; and
:func:`save_design_figures` for all four. Magnitudes in dB over frequency in rad/s (log).

Simulation figures of section 5 (torques [N m] and tracking errors [rad] over time [s], one
colour per joint): Fig. 5 :func:`plot_study_nominal`, Fig. 6 :func:`plot_study_uncertain`, and
:func:`plot_runs` for any set of runs; one column per controller.

References
----------
.. [1] The paper: "H-infinity control + feedback linearization of a 3-DOF RRR spatial serial
   mechanism", Fig. 2-4.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402  (after selecting the backend)
import numpy as np  # noqa: E402

from ..robust.robustness import closed_loop, sigma  # noqa: E402

__all__ = [
    "design_omega",
    "plot_stress",
    "plot_barriers",
    "plot_shaped_plant",
    "plot_robust_stability",
    "plot_robust_performance",
    "save_design_figures",
    "plot_runs",
    "plot_study_nominal",
    "plot_study_uncertain",
    "plot_campaign",
    "plot_certificates",
]


def design_omega(num: int = 600) -> np.ndarray:
    """Frequency grid of the loop-shaping figures, ``logspace(-2, 4)`` [rad/s]."""
    return np.logspace(-2, 4, num)


def _db(x) -> np.ndarray:
    return 20.0 * np.log10(np.abs(np.asarray(x)))


def _barrier_db(B, omega) -> np.ndarray:
    return _db(np.asarray(B(1j * omega, squeeze=False)).ravel())


def _sv_db(sys, omega, which: str) -> np.ndarray:
    sv = sigma(sys, omega)
    return _db(sv[0] if which == "max" else sv[-1])


def _finish(fig, ax, title: str, path) -> Path:
    ax.set_xscale("log")
    ax.set_xlabel("Frequency [rad/s]")
    ax.set_ylabel("Magnitude [dB]")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="best")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _barriers(ax, d, omega, rsb: bool = True, rpb: bool = True) -> None:
    if rsb:
        ax.plot(omega, _barrier_db(d.RSB, omega), "r--", lw=2, label="RSB (robust stability)")
    if rpb:
        ax.plot(omega, _barrier_db(d.RPB, omega), "b--", lw=2,
                label="RPB (robust performance)")


def plot_barriers(d, path, omega=None) -> Path:
    """Fig. 2: robust-stability (eq. 13) and robust-performance (eq. 15) barriers.

    Parameters
    ----------
    d : rrr_pin.robust.loopshaping.Design
        The design (uses ``d.RSB``, ``d.RPB``).
    path : str or Path
        Output PNG file.
    omega : array-like, shape (N,), optional
        Frequencies [rad/s], default :func:`design_omega`.

    Returns
    -------
    Path
        The written file.
    """
    omega = design_omega() if omega is None else np.asarray(omega, dtype=float)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    _barriers(ax, d, omega)
    return _finish(fig, ax, "Frequency barriers (Fig. 2)", path)


def plot_shaped_plant(d, path, omega=None) -> Path:
    """Fig. 3: barriers and the open-loop singular values of the shaped plant ``W2 G W1``.

    Parameters
    ----------
    d : rrr_pin.robust.loopshaping.Design
        The design (uses ``d.RSB``, ``d.RPB``, ``d.Gs``).
    path : str or Path
        Output PNG file.
    omega : array-like, shape (N,), optional
        Frequencies [rad/s], default :func:`design_omega`.

    Returns
    -------
    Path
        The written file.
    """
    omega = design_omega() if omega is None else np.asarray(omega, dtype=float)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    _barriers(ax, d, omega)
    ax.plot(omega, _sv_db(d.Gs, omega, "max"), "k-", lw=1.5,
            label=r"OLS shaped plant $\bar{\sigma}(W_2 G W_1)$")
    return _finish(fig, ax, "Barriers and shaped plant open loop (Fig. 3)", path)


def plot_robust_stability(d, path, omega=None) -> Path:
    """Fig. 4a: RSB and the closed-loop largest singular values of shaped and controlled plants.

    The shaped plant closes the loop with unit feedback, ``Gs (I + Gs)^-1``; the
    controlled plant with the reduced controller, ``G K (I + G K)^-1``.

    Parameters
    ----------
    d : rrr_pin.robust.loopshaping.Design
        The design (uses ``d.RSB``, ``d.Gs``, ``d.G``, ``d.K``).
    path : str or Path
        Output PNG file.
    omega : array-like, shape (N,), optional
        Frequencies [rad/s], default :func:`design_omega`.

    Returns
    -------
    Path
        The written file.
    """
    omega = design_omega() if omega is None else np.asarray(omega, dtype=float)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    _barriers(ax, d, omega, rpb=False)
    ax.plot(omega, _sv_db(closed_loop(d.Gs), omega, "max"), "k-", lw=1.5,
            label=r"CLS shaped plant $\bar{\sigma}(G_s (I+G_s)^{-1})$")
    ax.plot(omega, _sv_db(closed_loop(d.G, d.K), omega, "max"), "g-", lw=1.5,
            label=r"CLS controlled plant $\bar{\sigma}(GK (I+GK)^{-1})$")
    rs = d.robust_stability
    if np.isfinite(rs.worst_frequency):
        w = np.array([rs.worst_frequency])
        ax.plot([w[0], w[0]], [_sv_db(closed_loop(d.G, d.K), w, "max")[0],
                               _barrier_db(d.RSB, w)[0]], "m-", lw=3,
                label=f"smallest margin {rs.margin_db:.2f} dB at {w[0]:.4g} rad/s")
    return _finish(fig, ax, "Robust stability (Fig. 4a)", path)


def plot_robust_performance(d, path, omega=None) -> Path:
    """Fig. 4b: RPB and the open-loop smallest singular values of shaped and controlled plants.

    Parameters
    ----------
    d : rrr_pin.robust.loopshaping.Design
        The design (uses ``d.RPB``, ``d.Gs``, ``d.G``, ``d.K``, ``d.w_performance``).
    path : str or Path
        Output PNG file.
    omega : array-like, shape (N,), optional
        Frequencies [rad/s], default :func:`design_omega`.

    Returns
    -------
    Path
        The written file.
    """
    omega = design_omega() if omega is None else np.asarray(omega, dtype=float)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    _barriers(ax, d, omega, rsb=False)
    ax.plot(omega, _sv_db(d.Gs, omega, "min"), "k-", lw=1.5,
            label=r"OLS shaped plant $\underline{\sigma}(W_2 G W_1)$")
    ax.plot(omega, _sv_db(d.G * d.K, omega, "min"), "g-", lw=1.5,
            label=r"OLS controlled plant $\underline{\sigma}(G K)$")
    ax.axvline(d.w_performance, color="0.5", ls=":",
               label=rf"performance band $\omega_p$ = {d.w_performance:g} rad/s")
    rp = d.robust_performance
    if np.isfinite(rp.worst_frequency):
        w = np.array([rp.worst_frequency])
        ax.plot([w[0], w[0]], [_sv_db(d.G * d.K, w, "min")[0], _barrier_db(d.RPB, w)[0]],
                "m-", lw=3, label=f"smallest margin {rp.margin_db:.2f} dB at {w[0]:.4g} rad/s")
    return _finish(fig, ax, "Robust performance (Fig. 4b)", path)


def save_design_figures(d, out_dir) -> list[Path]:
    """Write ``fig2.png``, ``fig3.png``, ``fig4a.png`` and ``fig4b.png`` into ``out_dir``.

    Parameters
    ----------
    d : rrr_pin.robust.loopshaping.Design
        The design.
    out_dir : str or Path
        Directory, created if missing.

    Returns
    -------
    list of Path
        The four files.
    """
    out = Path(out_dir)
    return [plot_barriers(d, out / "fig2.png"),
            plot_shaped_plant(d, out / "fig3.png"),
            plot_robust_stability(d, out / "fig4a.png"),
            plot_robust_performance(d, out / "fig4b.png")]


# --- simulation figures (paper Fig. 5 and 6) ---------------------------------------------------

_JOINT_COLOURS = plt.rcParams["axes.prop_cycle"].by_key()["color"]


def _study_axes(title: str, labels: list[str]):
    cols = len(labels)
    fig, axes = plt.subplots(2, cols, figsize=(1.0 + 5.0 * cols, 7), sharex=True,
                             constrained_layout=True, squeeze=False)
    fig.suptitle(title)
    for ax in axes.flat:
        ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("Time [s]")
    axes[0, 0].set_ylabel("Joint torque [N m]")
    axes[1, 0].set_ylabel("Tracking error r - q [rad]")
    for col, label in enumerate(labels):
        axes[0, col].set_title(f"({chr(97 + col)}) {label}: control signals")
        axes[1, col].set_title(f"({chr(97 + cols + col)}) {label}: tracking errors")
    return fig, axes


def _plot_runs(axes, runs: dict, names, joint_names, alpha=1.0, labelled=None):
    # Joint names go in a column's legend once: with the first run plotted in it (``labelled``
    # holds the columns already labelled across calls).
    labelled = set() if labelled is None else labelled
    for col, key in enumerate(names):
        traj = runs.get(key)
        if traj is None:
            continue
        label = key not in labelled
        labelled.add(key)
        for j, name in enumerate(joint_names):
            colour = _JOINT_COLOURS[j % len(_JOINT_COLOURS)]
            lab = name if label else None
            axes[0, col].plot(traj.t, traj.tau[:, j], color=colour, lw=1.0, alpha=alpha,
                              label=lab)
            axes[1, col].plot(traj.t, traj.error[:, j], color=colour, lw=1.0, alpha=alpha,
                              label=lab)


def _finish_study(fig, axes, path):
    # Torques of all controllers on one scale, so their sizes compare at a glance.
    lo = min(ax.get_ylim()[0] for ax in axes[0])
    hi = max(ax.get_ylim()[1] for ax in axes[0])
    for ax in axes[0]:
        ax.set_ylim(lo, hi)
    for ax in axes[1]:
        ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 2))
    for ax in axes.flat:
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper right", fontsize="small", ncol=2)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)


def plot_runs(runs: dict, joint_names, path, title: str = "", labels: dict | None = None) -> Path:
    """Torques and tracking errors of any number of controllers on one plant (layout of Fig. 5).

    Parameters
    ----------
    runs : dict
        ``{name: Trajectory}``, one column per controller, in this order.
    joint_names : list of str
        Legend labels, one per joint.
    path : str or Path
        PNG to write.
    title : str
        Figure title.
    labels : dict, optional
        Display name per controller name (default: the names).
    """
    names = list(runs)
    labels = labels or {}
    fig, axes = _study_axes(title, [labels.get(k, k) for k in names])
    _plot_runs(axes, runs, names, joint_names)
    return _finish_study(fig, axes, path)


def plot_study_nominal(result, path):
    """Paper Fig. 5: torques and tracking errors of every controller on the nominal plant.

    Parameters
    ----------
    result : rrr_pin.campaign.study.StudyResult
        A study.
    path : str or Path
        PNG to write.
    """
    return plot_runs({k: result.nominal[k] for k in result.names}, result.joint_names, path,
                     title=f"{result.robot}: nominal plant (exact model)",
                     labels={k: result.label(k) for k in result.names})


def plot_study_uncertain(result, path):
    """Paper Fig. 6: torques and tracking errors of every controller on every uncertain plant.

    Each thin line is one plant (colour = joint); a controller's diverged runs are left out and
    counted in the title.
    """
    names = result.names
    n = len(result.samples)
    title = (f"{result.robot}: {n} uncertain plants "
             f"({result.config.tolerances.inertia:.0%} inertia, "
             f"{result.config.tolerances.length:.0%} length tolerance)")
    lost = {k: sum(1 for s in result.samples if k not in s["trajectories"]) for k in names}
    if any(lost.values()):
        title += ", diverged (not shown): " + ", ".join(
            f"{result.label(k)} {v}" for k, v in lost.items() if v)
    fig, axes = _study_axes(title, [result.label(k) for k in names])
    labelled: set = set()
    for sample in result.samples:
        _plot_runs(axes, sample["trajectories"], names, result.joint_names, alpha=0.6,
                   labelled=labelled)
    return _finish_study(fig, axes, path)


def save_study_figures(result, out_dir) -> list[Path]:
    """Write ``fig5_nominal.png``, ``fig6_uncertain.png`` and, if certified, ``certificates.png``.

    Parameters
    ----------
    result : rrr_pin.campaign.study.StudyResult
        A study; its certified uncertain plants (if any) give :func:`plot_certificates`.
    out_dir : str or Path
        Directory, created if missing.

    Returns
    -------
    list of Path
        The files written, in that order.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figures = [plot_study_nominal(result, out / "fig5_nominal.png"),
               plot_study_uncertain(result, out / "fig6_uncertain.png")]
    certified = [x for x in result.samples if "certificate" in x]
    if certified:
        figures.append(plot_certificates(
            [x["certificate"]["nugap_max"] for x in certified],
            certified[0]["certificate"]["b"], [x["status"] == "ok" for x in certified],
            out / "certificates.png"))
    return figures


# --- Monte Carlo campaign ----------------------------------------------------------------------

def plot_campaign(campaign, path) -> Path:
    """Distribution of the error ratios and per-joint spread of the RMS errors of a campaign.

    Left: for every controller but the baseline, histogram of ``RMS error of the baseline /
    RMS error of the controller`` over the plants (log scale; above 1 the controller tracks
    better). Right: per joint, box plots of the RMS tracking error [rad] of every controller.

    Parameters
    ----------
    campaign : rrr_pin.campaign.montecarlo.Campaign
        A campaign with at least one sample that ran.
    path : str or Path
        PNG to write.
    """
    rows, names, base = campaign.rows, campaign.names, campaign.baseline
    labels = {d["name"]: d["label"] for d in campaign.laws}
    colours = {k: _JOINT_COLOURS[(i + 1) % len(_JOINT_COLOURS)] for i, k in enumerate(names)}
    ok = sum(1 for r in rows if r["status"] == "ok")
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True)
    fig.suptitle(f"{campaign.robot}: Monte Carlo campaign, {len(rows)} plants"
                 + (f" ({len(rows) - ok} with a diverged run)" if ok < len(rows) else ""))
    ratios = {k: np.array([r[f"error_ratio_{k}"] for r in rows if f"error_ratio_{k}" in r])
              for k in names if k != base}
    ratios = {k: v for k, v in ratios.items() if v.size}
    if ratios:
        allv = np.concatenate(list(ratios.values()))
        bins = np.logspace(np.log10(max(allv.min(), 1e-3)) - 0.05,
                           np.log10(max(allv.max(), 1e-3)) + 0.05, 40)
        for k, v in ratios.items():
            ax1.hist(v, bins=bins, color=colours[k], alpha=0.6,
                     label=f"{labels[k]} (median {np.median(v):.3g})")
        ax1.axvline(1.0, color="tab:red", ls=":", label="ratio 1 (no benefit)")
        ax1.set_xscale("log")
        ax1.legend(fontsize="small")
    else:
        text = ("one controller: no ratio" if len(names) < 2 else
                "no ratio: undefined (0/0) or a diverged run on every plant")
        ax1.text(0.5, 0.5, text, ha="center", va="center", transform=ax1.transAxes)
    ax1.set_xlabel(f"RMS error {labels[base]} / RMS error of the controller [-]")
    ax1.set_ylabel("Number of plants [-]")
    ax1.set_title(f"Error ratio against the baseline ({labels[base]})")
    ax1.grid(True, alpha=0.3)
    joints = campaign.joint_names
    pos = np.arange(len(joints))
    width = 0.8 / len(names)
    positive = True  # a log axis, unless some error is 0 (a reference held exactly)
    for i, key in enumerate(names):
        data = [[r[f"{key}_rms_error_{j}"] for r in rows if f"{key}_rms_error_{j}" in r]
                for j in joints]
        if not any(data):
            continue
        positive = positive and min(min(d, default=1.0) for d in data) > 0.0
        offset = (i - (len(names) - 1) / 2) * width
        bp = ax2.boxplot(data, positions=pos + offset, widths=0.9 * width, patch_artist=True,
                         showfliers=True, flierprops={"markersize": 2})
        for box in bp["boxes"]:
            box.set_facecolor(colours[key])
            box.set_alpha(0.6)
        ax2.plot([], [], color=colours[key], lw=6, alpha=0.6, label=labels[key])
    ax2.set_xticks(pos, joints, rotation=30 if len(joints) > 4 else 0)
    ax2.set_yscale("log" if positive else "linear")
    ax2.set_xlabel("Joint")
    ax2.set_ylabel("RMS tracking error [rad]")
    ax2.set_title("Per-joint error spread")
    ax2.legend()
    ax2.grid(True, alpha=0.3, which="both")
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)


def plot_certificates(nugap, b, ran, path, title: str = "") -> Path:
    """Frozen-configuration certificates: each plant's largest nu-gap against ``b(Gs, Ks)``.

    A plant below the line ``nu-gap = b`` is certified (:mod:`rrr_pin.robust.certificates`); the
    marker says whether every controller's simulation ran without diverging.

    Parameters
    ----------
    nugap : array-like, shape (N,)
        Largest nu-gap [-] of each plant over its frozen configurations.
    b : float
        The design's NCF margin ``b(Gs, Ks)`` [-].
    ran : array-like of bool, shape (N,)
        Whether the plant's simulations all ran (no divergence).
    path : str or Path
        PNG to write.
    title : str
    """
    nugap, ran = np.asarray(nugap, dtype=float), np.asarray(ran, dtype=bool)
    idx = np.arange(len(nugap))
    fig, ax = plt.subplots(figsize=(8, 4.5), constrained_layout=True)
    ax.scatter(idx[ran], nugap[ran], color="tab:green", s=14, label="simulation ran")
    if (~ran).any():
        ax.scatter(idx[~ran], nugap[~ran], color="tab:red", marker="x", s=24,
                   label="simulation diverged")
    ax.axhline(b, color="k", ls="--", label=f"b(Gs, Ks) = {b:.4g} (certified below)")
    ax.set_xlabel("Uncertain plant (sample index) [-]")
    ax.set_ylabel("Largest nu-gap to the nominal shaped plant [-]")
    ax.set_ylim(0.0, max(1.05 * b, 1.05 * float(np.max(nugap)) if nugap.size else b))
    ax.set_title(title or f"Frozen-configuration certificates: {int((nugap < b).sum())} of "
                 f"{len(nugap)} plants certified")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)


def plot_stress(result: dict, path):
    """Figure: RMS error against the effect's size per law, predicted boundaries dashed."""
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    budget = result["budget_rad"]
    top = budget * 30
    for i, row in enumerate(result["rows"]):
        color = f"C{i}"
        s = np.array(row["samples"], dtype=float)
        if s.size:
            fin = np.isfinite(s[:, 1])
            y = np.where(fin, s[:, 1], top)
            ax.plot(s[:, 0], np.minimum(y, top), "-", color=color, alpha=0.6)
            ax.plot(s[fin, 0], s[fin, 1], "o", color=color, ms=4,
                    label=f"{row['label']}: simulated")
            ax.plot(s[~fin, 0], y[~fin], "x", color=color, ms=6)
        if row["predicted"] is not None and math.isfinite(row["predicted"]):
            ax.axvline(row["predicted"], color=color, ls="--",
                       label=f"{row['label']}: predicted {row['predicted']:.4g} {row['unit']}")
    g = next((r["guaranteed"] for r in result["rows"] if r["guaranteed"] is not None), None)
    if g is not None:
        ax.axvline(g, color="k", ls=":", label=f"eq. (12)-(13) guarantee {g:.3g}")
    ax.axhline(budget, color="gray", lw=0.8, label=f"budget {budget:g} rad")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(f"{result['what']} [{result['unit']}]")
    ax.set_ylabel("RMS tracking error [rad] (x: diverged)")
    ax.set_title(f"Breaking points: {result['effect']}")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path

"""Figures of the paper, written as PNG files (matplotlib, Agg backend, no window).

Loop-shaping figures of section 4 (each takes a :class:`rrr_pin.loopshaping.Design` and an
output path): Fig. 2 :func:`plot_barriers`, Fig. 3 :func:`plot_shaped_plant`, Fig. 4a
:func:`plot_robust_stability`, Fig. 4b :func:`plot_robust_performance`; and
:func:`save_design_figures` for all four. Magnitudes in dB over frequency in rad/s (log).

Simulation figures of section 5 (torques [N m] and tracking errors [rad] over time [s], one
colour per joint): Fig. 5 :func:`plot_study_nominal`, Fig. 6 :func:`plot_study_uncertain`, and
:func:`plot_runs` for any pair of runs.

References
----------
.. [1] The paper: "H-infinity control + feedback linearization of a 3-DOF RRR spatial serial
   mechanism", Fig. 2-4.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402  (after selecting the backend)
import numpy as np  # noqa: E402

from .robustness import closed_loop, sigma  # noqa: E402

__all__ = [
    "design_omega",
    "plot_barriers",
    "plot_shaped_plant",
    "plot_robust_stability",
    "plot_robust_performance",
    "save_design_figures",
    "plot_runs",
    "plot_study_nominal",
    "plot_study_uncertain",
    "plot_campaign",
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
    d : rrr_pin.loopshaping.Design
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
    d : rrr_pin.loopshaping.Design
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
    d : rrr_pin.loopshaping.Design
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
    d : rrr_pin.loopshaping.Design
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
    d : rrr_pin.loopshaping.Design
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


def _study_axes(title: str, joint_names):
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex=True, constrained_layout=True)
    fig.suptitle(title)
    for ax in axes.flat:
        ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("Time [s]")
    axes[0, 0].set_ylabel("Joint torque [N m]")
    axes[1, 0].set_ylabel("Tracking error r - q [rad]")
    axes[0, 0].set_title("(a) FL alone: control signals")
    axes[0, 1].set_title("(b) H-infinity + FL: control signals")
    axes[1, 0].set_title("(c) FL alone: tracking errors")
    axes[1, 1].set_title("(d) H-infinity + FL: tracking errors")
    return fig, axes


def _plot_runs(axes, runs: dict, joint_names, alpha=1.0, label=True):
    for col, key in enumerate(("fl", "hinf")):
        traj = runs[key]
        for j, name in enumerate(joint_names):
            colour = _JOINT_COLOURS[j % len(_JOINT_COLOURS)]
            lab = name if label else None
            axes[0, col].plot(traj.t, traj.tau[:, j], color=colour, lw=1.0, alpha=alpha,
                              label=lab)
            axes[1, col].plot(traj.t, traj.error[:, j], color=colour, lw=1.0, alpha=alpha,
                              label=lab)


def _finish_study(fig, axes, path):
    # Torques of both controllers on one scale, so their sizes compare at a glance.
    lo = min(axes[0, 0].get_ylim()[0], axes[0, 1].get_ylim()[0])
    hi = max(axes[0, 0].get_ylim()[1], axes[0, 1].get_ylim()[1])
    for ax in axes[0]:
        ax.set_ylim(lo, hi)
    for ax in axes[1]:
        ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 2))
    for ax in axes.flat:
        ax.legend(loc="upper right", fontsize="small", ncol=2)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)


def plot_runs(runs: dict, joint_names, path, title: str = "") -> Path:
    """Torques and tracking errors of both controllers on one plant (layout of Fig. 5).

    Parameters
    ----------
    runs : dict
        ``{"fl": Trajectory, "hinf": Trajectory}``.
    joint_names : list of str
        Legend labels, one per joint.
    path : str or Path
        PNG to write.
    title : str
        Figure title.
    """
    fig, axes = _study_axes(title, joint_names)
    _plot_runs(axes, runs, joint_names)
    return _finish_study(fig, axes, path)


def plot_study_nominal(result, path):
    """Paper Fig. 5: torques and tracking errors of both controllers on the nominal plant.

    Parameters
    ----------
    result : rrr_pin.study.StudyResult
        A study.
    path : str or Path
        PNG to write.
    """
    return plot_runs(result.nominal, result.joint_names, path,
                     title=f"{result.robot}: nominal plant (exact model)")


def plot_study_uncertain(result, path):
    """Paper Fig. 6: torques and tracking errors of both controllers on every uncertain plant.

    Each thin line is one plant (colour = joint); diverged plants are left out and counted in
    the title.
    """
    ok = [s for s in result.samples if s["status"] == "ok"]
    title = (f"{result.robot}: {len(ok)} uncertain plants "
             f"({result.config.tolerances.inertia:.0%} inertia, "
             f"{result.config.tolerances.length:.0%} length tolerance)")
    if len(ok) < len(result.samples):
        title += f", {len(result.samples) - len(ok)} diverged (not shown)"
    fig, axes = _study_axes(title, result.joint_names)
    for k, sample in enumerate(ok):
        _plot_runs(axes, sample["trajectories"], result.joint_names, alpha=0.6, label=(k == 0))
    return _finish_study(fig, axes, path)


# --- Monte Carlo campaign ----------------------------------------------------------------------

def plot_campaign(campaign, path) -> Path:
    """Distribution of the error ratio and per-joint spread of the RMS errors of a campaign.

    Left: histogram of ``RMS error FL alone / RMS error H-infinity + FL`` over the plants
    (log scale; a ratio above 1 means H-infinity + FL tracks better). Right: per joint, box
    plots of the RMS tracking error [rad] of both controllers over the plants.

    Parameters
    ----------
    campaign : rrr_pin.montecarlo.Campaign
        A campaign with at least one sample that ran.
    path : str or Path
        PNG to write.
    """
    ok = [r for r in campaign.rows if r["status"] == "ok"]
    ratios = np.array([r["error_ratio"] for r in ok])
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.8), constrained_layout=True)
    fig.suptitle(f"{campaign.robot}: Monte Carlo campaign, {len(ok)} plants"
                 + (f" ({len(campaign.rows) - len(ok)} diverged)"
                    if len(ok) < len(campaign.rows) else ""))
    bins = np.logspace(np.log10(max(ratios.min(), 1e-3)) - 0.05,
                       np.log10(ratios.max()) + 0.05, 40)
    ax1.hist(ratios, bins=bins, color="tab:blue", alpha=0.8, label="plants")
    ax1.axvline(np.median(ratios), color="k", ls="--",
                label=f"median {np.median(ratios):.3g}")
    ax1.axvline(1.0, color="tab:red", ls=":", label="ratio 1 (no benefit)")
    ax1.set_xscale("log")
    ax1.set_xlabel("RMS error FL alone / RMS error H-infinity + FL [-]")
    ax1.set_ylabel("Number of plants [-]")
    ax1.set_title("Error ratio")
    ax1.legend()
    ax1.grid(True, alpha=0.3)
    names = campaign.joint_names
    pos = np.arange(len(names))
    for offset, key, colour in ((-0.18, "fl", "tab:orange"), (0.18, "hinf", "tab:green")):
        data = [[r[f"{key}_rms_error_{n}"] for r in ok] for n in names]
        bp = ax2.boxplot(data, positions=pos + offset, widths=0.3, patch_artist=True,
                         showfliers=True, flierprops={"markersize": 2})
        for box in bp["boxes"]:
            box.set_facecolor(colour)
            box.set_alpha(0.6)
        ax2.plot([], [], color=colour, lw=6, alpha=0.6,
                 label="FL alone" if key == "fl" else "H-infinity + FL")
    ax2.set_xticks(pos, names, rotation=30 if len(names) > 4 else 0)
    ax2.set_yscale("log")
    ax2.set_xlabel("Joint")
    ax2.set_ylabel("RMS tracking error [rad]")
    ax2.set_title("Per-joint error spread")
    ax2.legend()
    ax2.grid(True, alpha=0.3, which="both")
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)

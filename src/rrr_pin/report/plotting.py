"""Figures of the paper and of the campaigns, as matplotlib figures (notebook-friendly).

Every ``plot_*`` function draws into the axes it is given (``ax=`` for one axes, ``axes=`` for
a figure of several) or, without one, into a new :class:`matplotlib.figure.Figure` that is
not registered with pyplot (no window, no backend switched, nothing to close), and returns
the figure, never closed: in a notebook it shows as the cell's output. The ``save_*``
functions and :func:`save_figure` write PNG files. Legends sit outside the axes, so they
never cover data.

Loop-shaping figures of section 4 (each takes a :class:`rrr_pin.robust.loopshaping.Design`):
Fig. 2 :func:`plot_barriers`, Fig. 3 :func:`plot_shaped_plant`, Fig. 4a
:func:`plot_robust_stability`, Fig. 4b :func:`plot_robust_performance`; and
:func:`save_design_figures` for all four. Magnitudes in dB over frequency in rad/s (log).

Simulation figures of section 5 (torques [N m] and tracking errors [rad] over time [s], one
colour per joint): Fig. 5 :func:`plot_study_nominal`, Fig. 6 :func:`plot_study_uncertain`
(the nominal plant outlined in black among the uncertain ones), and :func:`plot_runs` for any
set of runs; one column per controller. Campaigns: :func:`plot_campaign` (Monte Carlo),
:func:`plot_certificates` (nu-gap certificates) and :func:`plot_stress` (breaking points).

References
----------
.. [1] The paper: "H-infinity control + feedback linearization of a 3-DOF RRR spatial serial
   mechanism", Fig. 2-6.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib as mpl
import matplotlib.ticker as mticker
import numpy as np
from matplotlib import patheffects
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from ..outputs import writing
from ..robust.robustness import closed_loop, sigma

__all__ = [
    "plot_realistic",
    "plant_effects_phrase",
    "plot_task_path",
    "design_omega",
    "save_figure",
    "plot_stress",
    "plot_barriers",
    "plot_shaped_plant",
    "plot_robust_stability",
    "plot_robust_performance",
    "save_design_figures",
    "plot_runs",
    "plot_study_nominal",
    "plot_study_uncertain",
    "save_study_figures",
    "plot_task_space",
    "plot_campaign",
    "plot_certificates",
]

#: Resolution of the written PNG files [dots per inch].
DPI = 120


def design_omega(num: int = 600) -> np.ndarray:
    """Frequency grid of the loop-shaping figures, ``logspace(-2, 4)`` [rad/s]."""
    return np.logspace(-2, 4, num)


def save_figure(fig, path) -> Path:
    """Write ``fig`` to ``path`` (parent folders created) at :data:`DPI`; return the path.

    The figure is left open (a figure made by this module holds no pyplot state).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with writing(path):  # a full disk names the figure
        fig.savefig(path, dpi=DPI)
    return path


def _new(figsize, ax=None):
    """``(figure, axes)``: ``ax`` and its figure, or a new constrained-layout figure."""
    if ax is not None:
        return ax.figure, ax
    fig = Figure(figsize=figsize, layout="constrained")
    return fig, fig.add_subplot()


def plot_realistic(runs: dict, ax=None):
    """Draw the paper's comparison on the ideal loop and behind the realistic set, per robot.

    Parameters
    ----------
    runs : dict
        ``{robot: results.json content}`` of ``rrr-pin reproduce --realistic`` runs.
    ax : matplotlib Axes, optional

    Returns
    -------
    matplotlib.figure.Figure
        Bars of the RMS error ratio baseline / law [-] (log scale; above 1 the law tracks
        better) of each law, ideal and realistic, and the paper's 10.
    """
    fig, ax = _new((7.0, 3.6), ax)
    bars, labels = [], []
    for robot, data in runs.items():
        ideal = data["summary"]["error_ratio_uncertain"]
        real = data["realistic"]["summary"].get("error_ratio_uncertain", {})
        for law in ideal:
            bars.append((ideal[law], real.get(law)))
            labels.append(f"{robot}\n{law}")
    x = np.arange(len(bars))
    w = 0.38
    ideal = [b[0] if b[0] else np.nan for b in bars]
    real = [b[1] if b[1] else np.nan for b in bars]
    # bars from 1 (equal tracking) up to a ratio above 1 or down to one below: on a log scale
    # a bar from the axis' bottom would show a 0.01 as a bar as long as a 1
    ax.bar(x - w / 2, np.asarray(ideal) - 1.0, w, bottom=1.0, label="ideal loop (the paper's)")
    ax.bar(x + w / 2, np.asarray(real) - 1.0, w, bottom=1.0, label="behind the realistic set")
    for xi, (i, r) in zip(x, bars, strict=True):
        for dx, v in ((-w / 2, i), (w / 2, r)):
            if v:
                ax.annotate(f"{v:.3g}", (xi + dx, v), ha="center", va="bottom", fontsize=8)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.axhline(10.0, color="k", lw=0.8, ls="--", label="the paper's 10x")
    ax.set_yscale("log")
    ax.set_xticks(x, labels)
    ax.set_ylabel("RMS error ratio FL / law [-]")
    vals = [v for b in bars for v in b if v]
    if vals:
        ax.set_ylim(min(min(vals), 1.0) / 3.0, max(max(vals), 10.0) * 3.0)
    ax.set_title("RMS tracking error of FL alone over the law's, uncertain plants: "
                 "the ideal loop and the realistic set (above 1: the law tracks better)",
                 fontsize=9, wrap=True)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return fig


def _grid(axes, rows: int, cols: int, figsize, **subplots):
    """``(figure, axes array of shape (rows, cols))`` from ``axes`` (array, Figure or None)."""
    if axes is None or isinstance(axes, Figure):
        fig = Figure(figsize=figsize, layout="constrained") if axes is None else axes
        return fig, fig.subplots(rows, cols, squeeze=False, **subplots)
    grid = np.asarray(axes, dtype=object).reshape(-1)
    if grid.size != rows * cols:
        raise ValueError(f"axes: expected {rows} x {cols} axes, got {grid.size}")
    grid = grid.reshape(rows, cols)
    return grid[0, 0].figure, grid


def _legend_below(ax, ncol: int = 2, **kw):
    """Put the legend under the axes (outside them: it covers no data)."""
    return ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=ncol,
                     fontsize="small", **kw)


def _legend_right(ax, **kw):
    """Put the legend right of the axes (outside them: it covers no data)."""
    return ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize="small",
                     borderaxespad=0.0, **kw)


def _db(x) -> np.ndarray:
    return 20.0 * np.log10(np.abs(np.asarray(x)))


def _barrier_db(B, omega) -> np.ndarray:
    return _db(np.asarray(B(1j * omega, squeeze=False)).ravel())


def _sv_db(sys, omega, which: str) -> np.ndarray:
    sv = sigma(sys, omega)
    return _db(sv[0] if which == "max" else sv[-1])


def _finish(fig, ax, title: str):
    ax.set_xscale("log")
    ax.set_xlabel("Frequency [rad/s]")
    ax.set_ylabel("Magnitude [dB]")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    _legend_below(ax, ncol=1)
    return fig


def _barriers(ax, d, omega, rsb: bool = True, rpb: bool = True) -> None:
    if rsb:
        ax.plot(omega, _barrier_db(d.RSB, omega), "r--", lw=2, label="RSB (robust stability)")
    if rpb:
        ax.plot(omega, _barrier_db(d.RPB, omega), "b--", lw=2,
                label="RPB (robust performance)")


def plot_barriers(d, omega=None, *, ax=None):
    """Fig. 2: robust-stability (eq. 13) and robust-performance (eq. 15) barriers.

    Parameters
    ----------
    d : rrr_pin.robust.loopshaping.Design
        The design (uses ``d.RSB``, ``d.RPB``).
    omega : array-like, shape (N,), optional
        Frequencies [rad/s], default :func:`design_omega`.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into (default: a new figure).

    Returns
    -------
    matplotlib.figure.Figure
        The figure drawn into (not closed).
    """
    omega = design_omega() if omega is None else np.asarray(omega, dtype=float)
    fig, ax = _new((7, 6), ax)
    _barriers(ax, d, omega)
    return _finish(fig, ax, "Frequency barriers (Fig. 2)")



def plot_shaped_plant(d, omega=None, *, ax=None):
    """Fig. 3: barriers and the open-loop largest singular value of the shaped plant ``W2 G W1``.

    Parameters
    ----------
    d : rrr_pin.robust.loopshaping.Design
        The design (uses ``d.RSB``, ``d.RPB``, ``d.Gs``).
    omega : array-like, shape (N,), optional
        Frequencies [rad/s], default :func:`design_omega`.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into (default: a new figure).

    Returns
    -------
    matplotlib.figure.Figure
        The figure drawn into (not closed).
    """
    omega = design_omega() if omega is None else np.asarray(omega, dtype=float)
    fig, ax = _new((7, 6), ax)
    _barriers(ax, d, omega)
    ax.plot(omega, _sv_db(d.Gs, omega, "max"), "k-", lw=1.5,
            label=r"OLS shaped plant $\bar{\sigma}(W_2 G W_1)$")
    return _finish(fig, ax, "Barriers and shaped plant open loop (Fig. 3)")



def plot_robust_stability(d, omega=None, *, ax=None):
    """Fig. 4a: RSB and the closed-loop largest singular values of shaped and controlled plants.

    The shaped plant closes the loop with unit feedback, ``Gs (I + Gs)^-1``; the controlled
    plant with the reduced controller, ``G K (I + G K)^-1``. The magenta bar is the smallest
    margin, RSB minus the controlled plant's closed loop (``d.robust_stability``, in dB).

    Parameters
    ----------
    d : rrr_pin.robust.loopshaping.Design
        The design (uses ``d.RSB``, ``d.Gs``, ``d.G``, ``d.K``).
    omega : array-like, shape (N,), optional
        Frequencies [rad/s], default :func:`design_omega`.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into (default: a new figure).

    Returns
    -------
    matplotlib.figure.Figure
        The figure drawn into (not closed).
    """
    omega = design_omega() if omega is None else np.asarray(omega, dtype=float)
    fig, ax = _new((7, 6), ax)
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
                label=f"smallest margin, RSB minus the controlled plant's CLS: "
                      f"{rs.margin_db:.2f} dB at {w[0]:.4g} rad/s")
    return _finish(fig, ax, "Robust stability (Fig. 4a)")



def plot_robust_performance(d, omega=None, *, ax=None):
    """Fig. 4b: RPB and the open-loop smallest singular values of shaped and controlled plants.

    The magenta bar is the smallest margin, the controlled plant's open loop minus the RPB,
    within the performance band (``d.robust_performance``, in dB; negative: the RPB is not met).

    Parameters
    ----------
    d : rrr_pin.robust.loopshaping.Design
        The design (uses ``d.RPB``, ``d.Gs``, ``d.G``, ``d.K``, ``d.w_performance``).
    omega : array-like, shape (N,), optional
        Frequencies [rad/s], default :func:`design_omega`.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into (default: a new figure).

    Returns
    -------
    matplotlib.figure.Figure
        The figure drawn into (not closed).
    """
    omega = design_omega() if omega is None else np.asarray(omega, dtype=float)
    fig, ax = _new((7, 6), ax)
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
                "m-", lw=3, label=f"smallest margin, the controlled plant's OLS minus the "
                                  f"RPB: {rp.margin_db:.2f} dB at {w[0]:.4g} rad/s")
    return _finish(fig, ax, "Robust performance (Fig. 4b)")



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
    return [save_figure(plot(d), out / name) for plot, name in (
        (plot_barriers, "fig2.png"), (plot_shaped_plant, "fig3.png"),
        (plot_robust_stability, "fig4a.png"), (plot_robust_performance, "fig4b.png"))]


# --- simulation figures (paper Fig. 5 and 6) ---------------------------------------------------

_JOINT_COLOURS = mpl.rcParams["axes.prop_cycle"].by_key()["color"]

#: The nominal plant's run among uncertain ones: a black outline around the joint's colour.
_NOMINAL_OUTLINE = [patheffects.withStroke(linewidth=3.6, foreground="k")]


def plant_effects_phrase(effects, lead: str = "") -> str:
    """Say what a study's plants carry besides the model, for a title; ``""`` without effects.

    Parameters
    ----------
    effects : rrr_pin.control.effects.PlantEffects or None
        The effects the runs applied (``result.config.run.effects``).
    lead : str
        Text put before a non-empty phrase (e.g. ``"; "``).

    Returns
    -------
    str
        E.g. ``"; with viscous friction 0.5 N m s, delay 2 ms"``, or ``""``.
    """
    if effects is None or not effects.active:
        return ""

    def val(v) -> str:
        return "/".join(f"{x:g}" for x in np.atleast_1d(v))

    parts = []
    if effects.delay > 0:
        parts.append(f"delay {effects.delay * 1e3:g} ms")
    if effects.actuator_bandwidth is not None:
        parts.append(f"actuator bandwidth {effects.actuator_bandwidth:g} rad/s")
    if effects.viscous == "urdf":
        parts.append("friction of each plant's URDF")
    else:
        if np.any(np.asarray(effects.viscous) > 0):
            parts.append(f"viscous friction {val(effects.viscous)} N m s")
        if np.any(np.asarray(effects.coulomb) > 0):
            parts.append(f"Coulomb friction {val(effects.coulomb)} N m")
    if effects.torque_limit is not None:
        limit = effects.torque_limit
        parts.append(f"torque limit {limit if isinstance(limit, str) else val(limit) + ' N m'}")
    if np.any(np.asarray(effects.noise_q) > 0):
        parts.append(f"angle noise {val(effects.noise_q)} rad")
    if np.any(np.asarray(effects.noise_qd) > 0):
        parts.append(f"velocity noise {val(effects.noise_qd)} rad/s")
    if effects.encoder_counts is not None:
        parts.append(f"encoder {effects.encoder_counts} counts/rev")
    if effects.stiffness is not None:
        parts.append(f"joint stiffness {val(effects.stiffness)} N m/rad")
    return f"{lead}with {', '.join(parts)}"


def _study_axes(title: str, labels: list[str], axes=None):
    cols = len(labels)
    fig, axes = _grid(axes, 2, cols, (2.5 + 5.0 * cols, 7), sharex=True)
    if title:
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


def _plot_runs(axes, runs: dict, names, joint_names, **style):
    for col, key in enumerate(names):
        traj = runs.get(key)
        if traj is None:
            continue
        for j in range(len(joint_names)):
            colour = _JOINT_COLOURS[j % len(_JOINT_COLOURS)]
            axes[0, col].plot(traj.t, traj.tau[:, j], color=colour, **style)
            axes[1, col].plot(traj.t, traj.error[:, j], color=colour, **style)


def _finish_study(fig, axes, joint_names, extra=()):
    # Torques, and tracking errors, of all controllers on one scale per row, so their sizes
    # compare at a glance (Fig. 6 exists to show one controller's errors 20x another's).
    for row in axes:
        lo = min(ax.get_ylim()[0] for ax in row)
        hi = max(ax.get_ylim()[1] for ax in row)
        for ax in row:
            ax.set_ylim(lo, hi)
    for ax in axes[1]:
        ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 2))
    handles = [Line2D([], [], color=_JOINT_COLOURS[j % len(_JOINT_COLOURS)], lw=1.5,
                      label=name) for j, name in enumerate(joint_names)]
    _legend_right(axes[0, -1], handles=handles + list(extra))
    return fig


def plot_runs(runs: dict, joint_names, *, title: str = "", labels: dict | None = None,
              axes=None):
    """Torques and tracking errors of any number of controllers on one plant (layout of Fig. 5).

    Parameters
    ----------
    runs : dict
        ``{name: Trajectory}``, one column per controller, in this order.
    joint_names : list of str
        Legend labels, one per joint.
    title : str
        Figure title.
    labels : dict, optional
        Display name per controller name (default: the names).
    axes : array of matplotlib.axes.Axes, shape (2, len(runs)), or Figure, optional
        Axes to draw into (row 0 torques, row 1 errors, one column per controller), or a
        figure to add them to (default: a new figure).

    Returns
    -------
    matplotlib.figure.Figure
        The figure drawn into (not closed).
    """
    names = list(runs)
    labels = labels or {}
    fig, axes = _study_axes(title, [labels.get(k, k) for k in names], axes)
    _plot_runs(axes, runs, names, joint_names, lw=1.0)
    return _finish_study(fig, axes, joint_names)


def plot_study_nominal(result, *, axes=None):
    """Paper Fig. 5: torques and tracking errors of every controller on the nominal plant.

    Parameters
    ----------
    result : rrr_pin.campaign.study.StudyResult
        A study.
    axes : array of matplotlib.axes.Axes, shape (2, number of laws), or Figure, optional
        As in :func:`plot_runs`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    return plot_runs({k: result.nominal[k] for k in result.names}, result.joint_names,
                     title=f"{result.robot}: nominal plant ("
                           f"{plant_effects_phrase(result.config.run.effects) or 'exact model'})",
                     labels={k: result.label(k) for k in result.names}, axes=axes)


def plot_study_uncertain(result, *, axes=None):
    """Paper Fig. 6: torques and tracking errors of every controller on every uncertain plant.

    Each thin line is one uncertain plant (colour = joint); the nominal plant's run is drawn
    over them, outlined in black. A controller's diverged runs are left out and counted in the
    title.

    Parameters
    ----------
    result : rrr_pin.campaign.study.StudyResult
        A study.
    axes : array of matplotlib.axes.Axes, shape (2, number of laws), or Figure, optional
        As in :func:`plot_runs`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    names = result.names
    n = len(result.samples)
    title = (f"{result.robot}: {n} uncertain plants ({result.config.tolerances.describe()}"
             f"{plant_effects_phrase(result.config.run.effects, lead='; ')})")
    lost = {k: sum(1 for s in result.samples if k not in s["trajectories"]) for k in names}
    if any(lost.values()):
        title += ", diverged (not shown): " + ", ".join(
            f"{result.label(k)} {v}" for k, v in lost.items() if v)
    fig, axes = _study_axes(title, [result.label(k) for k in names], axes)
    for sample in result.samples:
        _plot_runs(axes, sample["trajectories"], names, result.joint_names, lw=0.8, alpha=0.5)
    _plot_runs(axes, result.nominal, names, result.joint_names, lw=1.6,
               path_effects=_NOMINAL_OUTLINE)
    extra = [Line2D([], [], color="0.4", lw=0.8, alpha=0.5, label="uncertain plants"),
             Line2D([], [], color="0.6", lw=1.6, path_effects=_NOMINAL_OUTLINE,
                    label="nominal plant")]
    return _finish_study(fig, axes, result.joint_names, extra)


def save_study_figures(result, out_dir, plant=None) -> list[Path]:
    """Write the study's figures: Fig. 5, Fig. 6, certificates, task space and task path.

    ``fig5_nominal.png``, ``fig6_uncertain.png``, ``certificates.png`` if certified,
    ``task_space.png`` for a task-space reference (:func:`plot_task_space`) and
    ``task_path.png`` for a plant with its own task path (:func:`plot_task_path`).

    Parameters
    ----------
    result : rrr_pin.campaign.study.StudyResult
        A study; its certified uncertain plants (if any) give :func:`plot_certificates`.
    out_dir : str or Path
        Directory, created if missing.
    plant : Plant, optional
        The nominal plant, for its task path (a closed chain's); None: none drawn.

    Returns
    -------
    list of Path
        The files written, in that order.
    """
    out = Path(out_dir)
    figures = [save_figure(plot_study_nominal(result), out / "fig5_nominal.png"),
               save_figure(plot_study_uncertain(result), out / "fig6_uncertain.png")]
    certified = [x for x in result.samples if "certificate" in x]
    if certified:
        figures.append(save_figure(plot_certificates(
            [x["certificate"]["nugap_max"] for x in certified],
            certified[0]["certificate"]["b"], [x["status"] == "ok" for x in certified]),
            out / "certificates.png"))
    if result.task_space:
        figures.append(save_figure(plot_task_space(result), out / "task_space.png"))
    if plant is not None and plant.task_points(result.config.run.duration) is not None:
        figures.append(save_figure(plot_task_path(result, plant), out / "task_path.png"))
    return figures


def plot_task_path(result, plant, *, ax=None):
    """Draw a plant's task path: the reference's and each law's on the nominal plant [mm].

    The path (a closed chain's tip circle, a Delta's platform cycle; ``plant.task_points``)
    in grey, and the task point of each law's nominal run (``plant.task_position`` of its
    actuated angles), seen in the plane of the two world axes the path spans most.

    Parameters
    ----------
    result : rrr_pin.campaign.study.StudyResult
        A study on ``plant``.
    plant : Plant
        The nominal plant, with a task path.
    ax : matplotlib.axes.Axes, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, ax = _new((8.0, 4.5), ax)
    path, label = plant.task_points(result.config.run.duration)
    keep = np.sort(np.argsort(np.ptp(path, axis=0))[-2:])  # the two axes the path spans most
    axis = "xyz"
    ax.plot(1e3 * path[:, keep[0]], 1e3 * path[:, keep[1]], color="0.6", lw=4, label=label)
    for k, name in enumerate(result.names):
        p = 1e3 * plant.task_position(result.nominal[name].q)
        ax.plot(p[:, keep[0]], p[:, keep[1]], f"C{k}", lw=1, ls="-" if k == 0 else "--",
                label=f"{result.label(name)}, nominal plant")
    ax.set_xlabel(f"{axis[keep[0]]} [mm]")
    ax.set_ylabel(f"{axis[keep[1]]} [mm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    _legend_right(ax)
    ax.set_title(f"{result.robot}: task path, reference and nominal runs")
    return fig


def plot_task_space(result, *, axes=None):
    """Task-space tracking of a study: the frame's path, and its Cartesian error over time.

    Left: the path (dashed) and, for every controller, the frame's path on the nominal plant,
    seen along the base axis over which the path varies least. Right: norm of the Cartesian
    error [mm] (log scale) against time: the nominal plant thick, each uncertain plant thin
    (by the nominal kinematics: the tracking error; see
    :func:`~rrr_pin.campaign.study.task_space_errors`).

    Parameters
    ----------
    result : rrr_pin.campaign.study.StudyResult
        A study with a task-space reference (``result.task_space`` not empty).
    axes : sequence of two matplotlib Axes, or a Figure, optional
        Where to draw (default: a new figure).

    Returns
    -------
    matplotlib.figure.Figure
        The figure drawn into (not closed).
    """
    ts = result.task_space
    if not ts:
        raise ValueError("the study's reference is not a task-space motion (line or circle)")
    fig, grid = _grid(axes, 1, 2, (12, 5.5), width_ratios=[1, 1.4])
    ax, ax2 = grid[0]
    names = result.names
    t = result.nominal[names[0]].t
    target = result.reference.target(t)
    keep = np.sort(np.argsort(np.ptp(target, axis=0))[1:])  # the two axes of largest extent
    ax.plot(target[:, keep[0]], target[:, keep[1]], "k--", lw=2.5, label="path")
    for i, name in enumerate(names):
        p = target + ts["errors"]["nominal"][name]
        ax.plot(p[:, keep[0]], p[:, keep[1]], color=f"C{i}", lw=1.2, label=result.label(name))
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel(f"{'xyz'[keep[0]]} [m]")
    ax.set_ylabel(f"{'xyz'[keep[1]]} [m]")
    ax.set_title(f"frame {ts['frame']!r} on the nominal plant")
    _legend_below(ax, ncol=2)
    floor = 1e-9  # [mm]: a log axis cannot show an exact zero
    for i, name in enumerate(names):
        for k, d in enumerate(ts["errors"]["uncertain"].get(name, [])):
            ax2.semilogy(t[: len(d)], np.maximum(1e3 * d, floor), color=f"C{i}", lw=0.6,
                         alpha=0.4, label=f"{result.label(name)}, uncertain plants (nominal "
                                          "kinematics)" if k == 0 else None)
        d = np.linalg.norm(ts["errors"]["nominal"][name], axis=1)
        ax2.semilogy(t, np.maximum(1e3 * d, floor), color=f"C{i}", lw=2.0,
                     label=f"{result.label(name)}, nominal plant")
    ax2.set_xlabel("time [s]")
    ax2.set_ylabel("Cartesian error |p(q) - p*(t)| [mm]")
    ax2.set_title("task-space tracking error")
    ax2.grid(True, which="both", alpha=0.3)
    _legend_below(ax2, ncol=2)
    return fig


# --- Monte Carlo campaign ----------------------------------------------------------------------

def _log_limits(lo: float, hi: float, pad: float = 0.08) -> tuple[float, float]:
    """Limits of a log axis around ``[lo, hi]`` (> 0), ``pad`` decades of margin each side."""
    a, b = math.log10(lo), math.log10(hi)
    return 10 ** (a - pad), 10 ** (b + pad)


def plot_campaign(campaign, *, axes=None):
    """Distribution of the error ratios and per-joint spread of the RMS errors of a campaign.

    Left: for every controller but the baseline, histogram of ``RMS error of the baseline /
    RMS error of the controller`` over the plants (log scale; above 1 the controller tracks
    better), its median dashed. The axis spans the ratios; the line ratio = 1 is drawn where
    it falls inside, otherwise the legend says on which side of it every plant lies. Right:
    per joint, box plots of the RMS tracking error [rad] of every controller (median black,
    box the quartiles, whiskers 1.5 IQR, dots beyond); the axis spans the data.

    Parameters
    ----------
    campaign : rrr_pin.campaign.montecarlo.Campaign
        A campaign with at least one sample that ran.
    axes : sequence of two matplotlib.axes.Axes, or Figure, optional
        Axes to draw into (histogram, box plots), or a figure to add them to (default: a new
        figure).

    Returns
    -------
    matplotlib.figure.Figure
        The figure drawn into (not closed).
    """
    rows, names, base = campaign.rows, campaign.names, campaign.baseline
    labels = {d["name"]: d["label"] for d in campaign.laws}
    colours = {k: _JOINT_COLOURS[(i + 1) % len(_JOINT_COLOURS)] for i, k in enumerate(names)}
    ok = sum(1 for r in rows if r["status"] == "ok")
    fig, grid = _grid(axes, 1, 2, (12, 5.2))
    ax1, ax2 = grid[0]
    fig.suptitle(f"{campaign.robot}: Monte Carlo campaign, {len(rows)} plants"
                 + (f" ({len(rows) - ok} with a diverged run)" if ok < len(rows) else ""))
    ratios = {k: np.array([r[f"error_ratio_{k}"] for r in rows if f"error_ratio_{k}" in r])
              for k in names if k != base}
    ratios = {k: v for k, v in ratios.items() if v.size}
    if ratios:
        allv = np.concatenate(list(ratios.values()))
        lo, hi = _log_limits(max(allv.min(), 1e-3), max(allv.max(), 1e-3), pad=0.03)
        bins = np.logspace(np.log10(lo), np.log10(hi), 40)
        for k, v in ratios.items():
            ax1.hist(v, bins=bins, color=colours[k], alpha=0.6, label=labels[k])
            ax1.axvline(np.median(v), color=colours[k], ls="--", lw=1.5,
                        label=f"{labels[k]}: median {np.median(v):.3g}")
        if lo <= 1.0 <= hi:
            ax1.axvline(1.0, color="tab:red", ls=":", label="ratio 1 (no benefit)")
        else:
            side = "above" if lo > 1.0 else "below"
            ax1.plot([], [], " ", label=f"every plant {side} ratio 1 "
                                        f"({'better' if lo > 1.0 else 'worse'} than the "
                                        f"baseline)")
        ax1.set_xscale("log")
        ax1.set_xlim(lo, hi)
        span = math.log10(hi / lo)
        if span < 2:  # a short log axis: label more than the powers of 10
            subs = (1.0, 2.0, 5.0) if span >= 1 else (1.0, 1.5, 2.0, 3.0, 5.0, 7.0)
            ax1.xaxis.set_major_locator(mticker.LogLocator(subs=subs))
            ax1.xaxis.set_major_formatter(mticker.FormatStrFormatter("%g"))
            ax1.xaxis.set_minor_formatter(mticker.NullFormatter())
        _legend_below(ax1, ncol=1)
    else:
        text = ("one controller: no ratio" if len(names) < 2 else
                "no ratio: undefined (0/0) or a diverged run on every plant")
        ax1.text(0.5, 0.5, text, ha="center", va="center", transform=ax1.transAxes)
    ax1.set_xlabel(f"RMS error {labels[base]} / RMS error of the controller [-]")
    ax1.set_ylabel("Number of plants [-]")
    ax1.set_title(f"Error ratio against the baseline ({labels[base]})")
    ax1.grid(True, alpha=0.3, which="both")
    joints = campaign.joint_names
    pos = np.arange(len(joints))
    width = 0.8 / len(names)
    values = []
    for i, key in enumerate(names):
        data = [[r[f"{key}_rms_error_{j}"] for r in rows if f"{key}_rms_error_{j}" in r]
                for j in joints]
        if not any(data):
            continue
        values += [v for col in data for v in col]
        offset = (i - (len(names) - 1) / 2) * width
        bp = ax2.boxplot(data, positions=pos + offset, widths=0.9 * width, patch_artist=True,
                         showfliers=True, flierprops={"markersize": 2},
                         medianprops={"color": "k", "lw": 2.0})
        for box in bp["boxes"]:
            box.set_facecolor(colours[key])
            box.set_alpha(0.6)
        ax2.plot([], [], color=colours[key], lw=6, alpha=0.6, label=labels[key])
    ax2.plot([], [], color="k", lw=2.0, label="median")
    ax2.set_xticks(pos, joints, rotation=30 if len(joints) > 4 else 0)
    finite = [v for v in values if math.isfinite(v)]
    if finite and min(finite) > 0.0:
        ax2.set_yscale("log")
        ax2.set_ylim(*_log_limits(min(finite), max(finite)))
    else:  # a log axis cannot show an error of exactly 0 (a reference held exactly)
        ax2.set_yscale("linear")
    ax2.set_xlabel("Joint")
    ax2.set_ylabel("RMS tracking error [rad]")
    ax2.set_title("Per-joint error spread")
    _legend_below(ax2, ncol=len(names) + 1)
    ax2.grid(True, alpha=0.3, which="both")
    return fig


def plot_certificates(nugap, b, ran, *, title: str = "", ax=None):
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
    title : str
        Axes title (default: how many plants are certified).
    ax : matplotlib.axes.Axes, optional
        Axes to draw into (default: a new figure).

    Returns
    -------
    matplotlib.figure.Figure
        The figure drawn into (not closed).
    """
    nugap, ran = np.asarray(nugap, dtype=float), np.asarray(ran, dtype=bool)
    idx = np.arange(len(nugap))
    fig, ax = _new((8, 5), ax)
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
    _legend_below(ax, ncol=3)
    return fig


#: Display unit of an effect's size: delays in ms (the search runs in s).
_DISPLAY_UNITS = {"s": (1e3, "ms")}


def plot_stress(result: dict, *, ax=None):
    """Plot the breaking points: RMS error against the effect's size, simulated and predicted.

    Per law: the simulated runs (dots; ``x`` a diverged run, drawn at 30 budgets), the
    simulated breaking point (solid vertical line) and the linear prediction of the digital
    loop (dashed), both in the legend; the eq. (12)-(13) guarantee dotted (for the torque limit,
    each law's sufficient bound, dotted in its colour). Delays are shown
    in ms.

    Parameters
    ----------
    result : dict
        :func:`rrr_pin.campaign.stress.stress`'s result.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into (default: a new figure).

    Returns
    -------
    matplotlib.figure.Figure
        The figure drawn into (not closed).
    """
    fig, ax = _new((8, 6.5), ax)
    scale, unit = _DISPLAY_UNITS.get(result["unit"], (1.0, result["unit"]))
    budget = result["budget_rad"]
    top = budget * 30
    for i, row in enumerate(result["rows"]):
        color = f"C{i}"
        # [size, rms_error] per run; a diverged run (rms_error None) becomes NaN, drawn as x
        s = np.array([[x["size"], np.nan if x["rms_error"] is None else x["rms_error"]]
                      for x in row["samples"]], dtype=float).reshape(-1, 2)
        if s.size:
            x = s[:, 0] * scale
            fin = np.isfinite(s[:, 1])
            y = np.where(fin, s[:, 1], top)
            ax.plot(x, np.minimum(y, top), "-", color=color, alpha=0.6)
            ax.plot(x[fin], s[fin, 1], "o", color=color, ms=4, label=f"{row['label']}: runs")
            ax.plot(x[~fin], y[~fin], "x", color=color, ms=6)
        sim = row.get("simulated")
        if sim is not None and math.isfinite(sim):
            ax.axvline(sim * scale, color=color, ls="-", lw=1.2,
                       label=f"{row['label']}: simulated limit {sim * scale:.4g} {unit}")
        if row["predicted"] is not None and math.isfinite(row["predicted"]):
            ax.axvline(row["predicted"] * scale, color=color, ls="--",
                       label=f"{row['label']}: predicted limit {row['predicted'] * scale:.4g} "
                             f"{unit}")
        if row.get("torque") and row["guaranteed"] is not None:
            ax.axvline(row["guaranteed"] * scale, color=color, ls=":",
                       label=f"{row['label']}: sufficient "
                             f"{row['guaranteed'] * scale:.4g} {unit}")
    g = next((r["guaranteed"] for r in result["rows"] if r["guaranteed"] is not None), None)
    if g is not None and result["effect"] != "torque":
        ax.axvline(g * scale, color="k", ls=":",
                   label=f"eq. (12)-(13) guarantee {g * scale:.3g} {unit}")
    ax.axhline(budget, color="gray", lw=0.8, label=f"budget {budget:g} rad")
    ax.plot([], [], "x", color="0.3", label=f"diverged run (drawn at {top:g} rad)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(f"{result['what']} [{unit}]")
    ax.set_ylabel("RMS tracking error [rad]")
    from ..control.catalog import EFFECTS

    held = ", ".join(f"{k} = {v:g} {EFFECTS[k].unit}"
                     for k, v in (result.get("with") or {}).items())
    ax.set_title(f"Breaking points: {result['effect']}" + (f" (held: {held})" if held else ""))
    ax.grid(True, alpha=0.3, which="both")
    _legend_below(ax, ncol=2)
    return fig

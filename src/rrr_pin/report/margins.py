"""Figures of the loops broken at the torque input: singular values, Bode and Nyquist.

:func:`margins_figure` draws, for each law's loop ``L`` (:func:`rrr_pin.control.analysis.
loop_at_input`), the singular values of ``L(jw)``, the Bode phase of each joint's loop (the
others closed) and its Nyquist curve near the critical point -1. Matplotlib's object API
(no pyplot): the figure renders with the Agg canvas, whatever the backend.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..control.analysis import loop_channel

__all__ = ["margins_figure", "save_margins_figure", "design_loop_title"]


def margins_figure(loops: dict, omega=None, title: str | None = None) -> Figure:
    """Return a figure of singular values, joint Bode phases and Nyquist curves of ``loops``.

    Parameters
    ----------
    loops : dict of str to control.StateSpace
        Each law's loop at the torque input, by law name.
    omega : array-like, optional
        Frequencies [rad/s]; default 1e-1 to 1e5.
    title : str, optional
        What the loops are (the plant, its configuration, the laws): the figure's title.
    """
    w = np.logspace(-1, 5, 1500) if omega is None else np.asarray(omega, dtype=float)
    fig = Figure(figsize=(13, 4.2), layout="constrained")
    FigureCanvasAgg(fig)
    ax_sv, ax_ph, ax_ny = fig.subplots(1, 3)
    colors = [f"C{i}" for i in range(10)]
    for (name, L), c in zip(loops.items(), colors, strict=False):
        H = np.stack([L(1j * wk, squeeze=False) for wk in w])
        sv = np.linalg.svd(H, compute_uv=False)
        ax_sv.loglog(w, sv[:, 0], color=c, label=f"{name}: max")
        ax_sv.loglog(w, sv[:, -1], color=c, ls="--", label=f"{name}: min")
        for i in range(L.ninputs):
            Li = loop_channel(L, i)
            h = np.array([complex(Li(1j * wk)) for wk in w])
            ph = np.degrees(np.unwrap(np.angle(h)))
            ph -= 360.0 * np.ceil(ph[-1] / 360.0)  # high-frequency end in (-360, 0]
            ax_ph.semilogx(w, ph, color=c,
                           alpha=1.0 if i == 0 else 0.5, label=name if i == 0 else None)
            ax_ny.plot(h.real, h.imag, color=c, alpha=1.0 if i == 0 else 0.5,
                       label=name if i == 0 else None)
    ax_sv.axhline(1.0, color="0.5", lw=0.8)
    ax_sv.set(xlabel="frequency [rad/s]", ylabel="singular values of L(jw) [-]",
              title="singular values of the loop")
    ax_ph.axhline(-180.0, color="0.5", lw=0.8)
    ax_ph.set(xlabel="frequency [rad/s]", ylabel="phase of each joint's loop [deg]",
              title="Bode phase (other joints closed)")
    t = np.linspace(0, 2 * np.pi, 200)
    ax_ny.plot(-1 + np.cos(t), np.sin(t), color="0.7", lw=0.8, label="|1 + L| = 1")
    ax_ny.plot([-1], [0], "k+", ms=10)
    ax_ny.set(xlim=(-3, 1), ylim=(-2.5, 1.5), aspect="equal", xlabel="Re L(jw) [-]",
              ylabel="Im L(jw) [-]", title="Nyquist near -1 (w > 0)")
    for ax in (ax_sv, ax_ph, ax_ny):
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def design_loop_title(d) -> str:
    """Title of the design's own loop ``G K`` (eq. 11 plant, eq. 18 controller)."""
    return (f"design loop G K: the FL plant (eq. 11, lam = {d.lam:g} rad/s, {d.n} joints) "
            f"with the H-inf controller K (eq. 18), no robot configuration")


def save_margins_figure(loops: dict, folder, title: str | None = None) -> Path:
    """Write :func:`margins_figure` (with ``title``) as ``folder/margins.png``; return its path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "margins.png"
    margins_figure(loops, title=title).savefig(path, dpi=110)
    return path

"""The outputs of a stress search: ``stress_<effect>.png``, ``stress_<effect>.json`` and text.

Built from the dict :func:`rrr_pin.campaign.stress.stress` returns (with the caller's
``elapsed_s`` and ``robot`` added): the figure is
:func:`rrr_pin.report.plotting.plot_stress`, the JSON is that dict with the figure's path.
"""

from __future__ import annotations

import json
from pathlib import Path

from .plotting import plot_stress, save_figure

__all__ = ["write_stress", "stress_lines"]


def write_stress(result: dict, out: str | Path) -> Path:
    """Write ``stress_<effect>.png`` and ``stress_<effect>.json`` into ``out``.

    Sets ``result["figure"]`` to the figure's path before writing the JSON.

    Returns
    -------
    Path
        The figure.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig = save_figure(plot_stress(result), out / f"stress_{result['effect']}.png")
    result["figure"] = str(fig)
    (out / f"stress_{result['effect']}.json").write_text(json.dumps(result, indent=1))
    return fig


def _fmt(v) -> str:
    return "-" if v is None else f"{v:.4g}"


def stress_lines(result: dict) -> list[str]:
    """Return a stress search as text lines (no newlines), for a terminal.

    The effect, budget, rate and time taken, then per controller the predicted and simulated
    breaking points, their ratio and what the robust-stability barrier guarantees (``-``: none).
    """
    lines = [f"{result['robot']}: {result['what']} [{result['unit']}], budget "
             f"{result['budget_rad']:g} rad RMS, {result['settings']['rate_hz']:g} Hz, "
             f"{result['elapsed_s']:.1f} s",
             f"{'controller':12}{'predicted':>12}{'simulated':>12}{'sim/pred':>10}"
             f"{'guaranteed':>12}"]
    lines += [f"{row['controller']:12}{_fmt(row['predicted']):>12}"
              f"{_fmt(row['simulated']):>12}{_fmt(row['agreement']):>10}"
              f"{_fmt(row['guaranteed']):>12}" for row in result["rows"]]
    return lines

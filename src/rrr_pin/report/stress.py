"""The outputs of a stress search: ``stress_<effect>.png``, ``stress_<effect>.json`` and text.

Built from the dict :func:`rrr_pin.campaign.stress.stress` returns (with the caller's
``elapsed_s`` and ``robot`` added): the figure is
:func:`rrr_pin.report.plotting.plot_stress`, the JSON is that dict with the figure's path, strict
(:func:`rrr_pin.report.jsondata.dumps`: an infinite prediction is ``null`` with a ``_status``).
"""

from __future__ import annotations

from pathlib import Path

from ..control.catalog import EFFECTS
from ..outputs import writing
from .jsondata import dumps

__all__ = ["write_stress", "stress_lines"]


def write_stress(result: dict, out: str | Path, figure: bool = True) -> Path:
    """Write ``stress_<stem>.png`` and ``stress_<stem>.json`` into ``out``.

    ``stem`` is ``result["stem"]`` if given (the CLI's ``delay_with_actuator300`` for
    ``--with``), else the effect. Sets ``result["figure"]`` to the figure's path (None with
    ``figure=False``: no PNG, matplotlib not imported) before writing the JSON.

    Returns
    -------
    Path
        The figure, or the JSON without one.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    stem = result.get("stem") or result["effect"]
    fig = None
    if figure:
        from .plotting import plot_stress, save_figure

        fig = save_figure(plot_stress(result), out / f"stress_{stem}.png")
    result["figure"] = None if fig is None else str(fig)
    path = out / f"stress_{stem}.json"
    with writing(path):  # a full disk names the file
        path.write_text(dumps(result, indent=1))
    return path if fig is None else fig


def _fmt(v) -> str:
    return "-" if v is None else f"{v:.4g}"


def _simulated(row: dict, result: dict) -> str:
    """Format the simulated boundary: ``>x`` (``<x``) if even the harshest size tried, x, passed."""
    if row.get("status") == "not broken":
        return f"{'>' if result['direction'] == 'up' else '<'}{row['bracket'][0]:.4g}"
    return _fmt(row["simulated"])


def stress_lines(result: dict) -> list[str]:
    """Return a stress search as text lines (no newlines), for a terminal.

    The effect, budget, rate and time taken, then per controller the predicted and simulated
    breaking points, their ratio and what the robust-stability barrier guarantees (``-``: none;
    ``>x`` or ``<x``: not broken by any size tried, the harshest being x).
    """
    lines = [f"{result['robot']}: {result['what']} [{result['unit']}], budget "
             f"{result['budget_rad']:g} rad RMS, {result['settings']['rate_hz']:g} Hz, "
             f"{result['elapsed_s']:.1f} s",
             f"{'controller':12}{'predicted':>12}{'simulated':>12}{'sim/pred':>10}"
             f"{'guaranteed':>12}"]
    lines += [f"{row['controller']:12}{_fmt(row['predicted']):>12}"
              f"{_simulated(row, result):>12}{_fmt(row['agreement']):>10}"
              f"{_fmt(row['guaranteed']):>12}" for row in result["rows"]]
    if result.get("with"):
        lines.insert(1, "held fixed in every run and in the predictions: " + ", ".join(
            f"{k} = {v:g} {EFFECTS[k].unit}" for k, v in result["with"].items()))
    torque = [row for row in result["rows"] if row.get("torque")]
    if torque:
        lines.append("predicted: the reference's peak inverse-dynamics torque (an estimate); "
                     "guaranteed: the unsaturated run's peak |tau| (sufficient: nothing "
                     "saturates at or above it)")
        lines += [f"  {row['controller']}: describing function of the loop at the torque "
                  + ("input: never conditionally stable, expected to break below predicted"
                     if row["torque"]["df_gain"] is None else
                     f"input: conditionally stable (gain {row['torque']['df_gain']:.3g} at "
                     f"{row['torque']['df_frequency']:.3g} rad/s), expected to break above "
                     f"predicted (windup)")
                  for row in torque if row["torque"]["expected"] is not None]
    grid = {row.get("resolution") for row in result["rows"]} - {None}
    if grid:
        lines.append(f"simulated: the largest delay that passed, searched on whole plant "
                     f"sub-steps of {', '.join(f'{h:g}' for h in sorted(grid))} s (the only "
                     f"delays a run realizes)")
    return lines

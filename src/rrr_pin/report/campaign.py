"""The files of a Monte Carlo campaign: ``campaign.csv``, ``samples.jsonl``, ``summary.json``, a figure.

Built from a finished :class:`rrr_pin.campaign.montecarlo.Campaign`; written through its
:class:`~rrr_pin.campaign.store.CampaignStore` when given one (atomically, recorded as the
run's own files).
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

from ..campaign.montecarlo import Campaign, campaign_columns, campaign_summary
from ..campaign.store import CampaignStore
from .plotting import plot_campaign

__all__ = ["write_campaign"]


def write_campaign(campaign: Campaign, out: str | Path,
                   store: CampaignStore | None = None) -> dict:
    """Write ``campaign.csv``, ``samples.jsonl`` (parameters), ``summary.json`` and a figure.

    With a ``store``, the files are written through it (atomically, recorded as this run's).

    Returns
    -------
    dict
        The summary; ``summary["written"]`` lists the files this call wrote.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    columns = campaign_columns(campaign.names, campaign.baseline, campaign.joint_names,
                               any("certified" in r for r in campaign.rows))
    table = io.StringIO(newline="")
    writer = csv.DictWriter(table, fieldnames=columns, extrasaction="ignore",
                            lineterminator="\n")
    writer.writeheader()
    for row in campaign.rows:
        writer.writerow({**row, "seed": f"{row['seed'][0]}:{row['seed'][1]}"})
    params = "".join(json.dumps({"index": row["index"], "seed": list(row["seed"]),
                                 "status": row["status"], "parameters": row["parameters"]})
                     + "\n" for row in campaign.rows)
    summary = campaign_summary(campaign)
    text = json.dumps({"robot": campaign.robot, "controllers": campaign.laws,
                       "settings": campaign.settings, "summary": summary}, indent=1) + "\n"
    written = []
    for name, content in (("campaign.csv", table.getvalue()), ("samples.jsonl", params),
                          ("summary.json", text)):
        if store is not None:
            written.append(store.write_text(name, content))
        else:
            (out / name).write_text(content)
            written.append(out / name)
    figure = out / "montecarlo.png"
    if figure.exists():
        figure.unlink()
    if any(r["status"] == "ok" for r in campaign.rows):
        plot_campaign(campaign, figure)
        written.append(store.wrote("montecarlo.png") if store is not None else figure)
    summary["written"] = [str(p) for p in written]
    return summary

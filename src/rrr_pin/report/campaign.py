"""The files of a Monte Carlo campaign: tables, summary, figures and ``report.html``.

``campaign.csv``, ``samples.jsonl``, ``summary.json``, ``montecarlo.png`` and, for certified
plants, ``certificates.png``.

Built from a finished :class:`rrr_pin.campaign.montecarlo.Campaign`; written through its
:class:`~rrr_pin.campaign.store.CampaignStore` when given one (atomically, recorded as the
run's own files). :func:`write_campaign_report` adds ``report.html``, and
:func:`summary_lines` is the summary as text for a terminal.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

from ..campaign.montecarlo import Campaign, campaign_columns, campaign_summary
from ..campaign.store import CampaignStore
from .html import write_report_html
from .plotting import plot_campaign, plot_certificates

__all__ = ["write_campaign", "write_campaign_report", "summary_lines"]

#: Metrics of the summary tables, per law, in order (``report.html`` also shows the torque).
_TABLE_METRICS = ("error_ratio_{}", "torque_ratio_{}", "{}_rms_error", "{}_max_error")


def write_campaign(campaign: Campaign, out: str | Path, store: CampaignStore | None = None,
                   certificate_b: float | None = None) -> dict:
    """Write ``campaign.csv``, ``samples.jsonl`` (parameters), ``summary.json`` and figures.

    With a ``store``, the files are written through it (atomically, recorded as this run's).
    ``montecarlo.png`` is drawn when a sample ran every law; ``certificates.png``
    (:func:`rrr_pin.report.plotting.plot_certificates`) when the rows are certified and
    ``certificate_b``, the margin ``b(Gs, Ks)`` they were certified against, is given.

    Returns
    -------
    dict
        The summary; ``summary["written"]`` lists the files this call wrote.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    columns = campaign_columns(campaign.names, campaign.baseline, campaign.joint_names,
                               any("certified" in r for r in campaign.rows),
                               any("undefined" in r for r in campaign.rows))
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
    certs = [r for r in campaign.rows if "certified" in r]
    if certs and certificate_b is not None:
        figure = plot_certificates([r["nugap_max"] for r in certs], certificate_b,
                                   [r["status"] == "ok" for r in certs],
                                   out / "certificates.png")
        written.append(store.wrote("certificates.png") if store is not None else figure)
    summary["written"] = [str(p) for p in written]
    return summary


def _metrics(campaign: Campaign, summary: dict, torque: bool) -> list[str]:
    """Metrics of the summary present in ``summary``, per law in order."""
    forms = _TABLE_METRICS + (("{}_rms_torque",) if torque else ())
    return [m for name in campaign.names for m in (f.format(name) for f in forms)
            if m in summary]


def write_campaign_report(campaign: Campaign, summary: dict, out: str | Path,
                          store: CampaignStore | None = None) -> Path:
    """Write ``report.html`` of a campaign: the summary table, the settings and the figure.

    No trajectories are kept by a campaign, so the page has no 3D scene.

    Parameters
    ----------
    campaign : Campaign
    summary : dict
        :func:`write_campaign`'s (or :func:`rrr_pin.campaign.montecarlo.campaign_summary`'s).
    out : path-like
        The campaign's folder; ``montecarlo.png`` there is shown if it exists.
    store : CampaignStore, optional
        Record ``report.html`` as this run's output.

    Returns
    -------
    Path
        The file written.
    """
    out = Path(out)
    lines = ["| metric | median | 95th percentile | worst | samples |", "|---|---|---|---|---|"]
    for metric in _metrics(campaign, summary, torque=True):
        m = summary[metric]
        lines.append(f"| {metric} | {m['median']:.4g} | {m['p95']:.4g} | {m['worst']:.4g} | "
                     f"{m['count']} |")
    figure = out / "montecarlo.png"
    path = write_report_html(
        out / "report.html", title=f"rrr-pin Monte Carlo campaign on {campaign.robot}",
        tables=[(f"{summary['samples']} plants, baseline {summary['baseline']}",
                 "\n".join(lines))],
        figures=[figure] if figure.exists() else [], design=campaign.settings)
    return store.wrote("report.html") if store is not None else path


def summary_lines(campaign: Campaign, summary: dict) -> list[str]:
    """Return the summary of a campaign as text lines (no newlines), for a terminal.

    How many plants every law ran on, the certificates (if any), the share of plants where
    each law beats the baseline, and a fixed-width table of median, 95th percentile and worst
    of each error and torque ratio and error metric.
    """
    s = summary
    lines = [f"every controller ran on {s['samples_ok']}, a run diverged on "
             f"{s['samples_diverged']}"]
    if "certified" in s:
        lines.append(f"certified (frozen nu-gap < b): {s['certified']} plants, of which "
                     f"{s['certified_and_ran']} ran; not certified but ran: "
                     f"{s['not_certified_but_ran']}; largest nu-gap {s['nugap_max']:.4g}")
    lines += [f"{name} better than {s['baseline']} on {100 * frac:.1f} % of the plants"
              for name, frac in s["fraction_better"].items()]
    lines += [f"{key} undefined (no ratio: 0/0 or not finite) on {count} plants, left out; "
              f"see the column 'undefined' of campaign.csv"
              for key, count in s.get("undefined", {}).items()]
    lines.append(f"{'metric':28}{'median':>12}{'p95':>12}{'worst':>12}")
    for metric in _metrics(campaign, s, torque=False):
        m = s[metric]
        lines.append(f"{metric:28}{m['median']:12.4g}{m['p95']:12.4g}{m['worst']:12.4g}")
    return lines

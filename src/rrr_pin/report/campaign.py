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
from pathlib import Path

from ..campaign.montecarlo import Campaign, campaign_columns, campaign_summary
from ..campaign.store import CampaignStore
from ..outputs import writing
from .html import write_report_html
from .jsondata import dumps

__all__ = ["write_campaign", "write_campaign_report", "summary_lines", "SETTINGS_UNITS"]

#: Metrics of the summary tables, per law, in order (``report.html`` also shows the torque).
_TABLE_METRICS = ("error_ratio_{}", "torque_ratio_{}", "{}_rms_error", "{}_max_error",
                  "{}_drift")


def write_campaign(campaign: Campaign, out: str | Path, store: CampaignStore | None = None,
                   certificate_b: float | None = None, figures: bool = True) -> dict:
    """Write ``campaign.csv``, ``samples.jsonl`` (parameters), ``summary.json`` and figures.

    ``campaign.csv`` has one row per sample: ``index`` ``k`` and ``seed`` ``s`` (integers; the
    plant is the one of ``numpy.random.default_rng([s, k])``), ``status``, then the metrics;
    ``samples.jsonl`` records ``"seed": [s, k]``.

    With a ``store``, the files are written through it (atomically, recorded as this run's).
    ``montecarlo.png`` is drawn when a sample ran every law; ``certificates.png``
    (:func:`rrr_pin.report.plotting.plot_certificates`) when the rows are certified and
    ``certificate_b``, the margin ``b(Gs, Ks)`` they were certified against, is given. With
    ``figures=False`` neither is drawn (matplotlib is not imported); the tables are the same.

    Returns
    -------
    dict
        The summary; ``summary["written"]`` lists the files this call wrote.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    columns = campaign_columns(campaign.names, campaign.baseline, campaign.joint_names,
                               any("certified" in r for r in campaign.rows),
                               any("undefined" in r for r in campaign.rows),
                               per_law=campaign.per_law)
    table = io.StringIO(newline="")
    writer = csv.DictWriter(table, fieldnames=columns, extrasaction="ignore",
                            lineterminator="\n")
    writer.writeheader()
    for row in campaign.rows:
        # seed: the campaign's seed s, an integer; row k is the plant of default_rng([s, k])
        writer.writerow({**row, "seed": row["seed"][0]})
    params = "".join(dumps({"index": row["index"], "seed": list(row["seed"]),
                                 "status": row["status"], "parameters": row["parameters"]})
                     + "\n" for row in campaign.rows)
    summary = campaign_summary(campaign)
    record = {"robot": campaign.robot, "controllers": campaign.laws,
              "settings": campaign.settings, "summary": summary}
    if campaign.nominal is not None:  # every campaign runs the nominal plant too (index -1)
        record["nominal"] = campaign.nominal
    if campaign.joint_dynamics is not None:  # the nominal's armature, damping, friction
        record["joint_dynamics"] = campaign.joint_dynamics
    text = dumps(record, indent=1) + "\n"
    written = []
    for name, content in (("campaign.csv", table.getvalue()), ("samples.jsonl", params),
                          ("summary.json", text)):
        if store is not None:
            written.append(store.write_text(name, content))
        else:
            with writing(out / name):  # a full disk names the file
                (out / name).write_text(content)
            written.append(out / name)
    figure = out / "montecarlo.png"
    if figure.exists():
        figure.unlink()
    if not figures:
        summary["written"] = [str(p) for p in written]
        return summary
    from .plotting import plot_campaign, plot_certificates, save_figure

    if any(r["status"] == "ok" for r in campaign.rows):
        save_figure(plot_campaign(campaign), figure)
        written.append(store.wrote("montecarlo.png") if store is not None else figure)
    certs = [r for r in campaign.rows if "certified" in r]
    if certs and certificate_b is not None:
        figure = save_figure(plot_certificates([r["nugap_max"] for r in certs], certificate_b,
                                               [r["status"] == "ok" for r in certs]),
                             out / "certificates.png")
        written.append(store.wrote("certificates.png") if store is not None else figure)
    summary["written"] = [str(p) for p in written]
    return summary


def _metrics(campaign: Campaign, summary: dict, torque: bool) -> list[str]:
    """Metrics of the summary present in ``summary``, per law in order."""
    forms = _TABLE_METRICS + (("{}_rms_torque",) if torque else ())
    return [m for name in campaign.names for m in (f.format(name) for f in forms)
            if m in summary]


#: Units of the campaign settings' keys that carry no unit suffix ("-": dimensionless).
SETTINGS_UNITS = {"samples": "-", "seed": "-", "tolerance_inertia": "-",
                  "tolerance_length": "-", "uncertainty": "-", "identification": "-",
                  "identification_sha256": "-", "confidence": "-", "base_count": "-"}


def _metric_unit(metric: str) -> str:
    if metric.startswith(("error_ratio_", "torque_ratio_")):
        return "-"
    if metric.endswith("_drift"):
        return "m"
    return "N m" if metric.endswith("_rms_torque") else "rad"


def _captions(campaign: Campaign) -> dict:
    """Caption of each figure a campaign may have, by file name."""
    base = next(d["label"] for d in campaign.laws if d["name"] == campaign.baseline)
    return {"montecarlo.png": f"Left: per controller, the ratio RMS error of the baseline "
                              f"({base}) / RMS error of the controller over the plants "
                              f"(above 1: better than the baseline). Right: per joint, the "
                              f"spread of the RMS tracking error [rad] of every controller.",
            "certificates.png": "Frozen-configuration certificates: each plant's largest "
                                "nu-gap to the nominal shaped plant against b(Gs, Ks); below "
                                "the line, certified."}


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
        The campaign's folder; ``montecarlo.png`` and ``certificates.png`` there are shown,
        with captions, if they exist.
    store : CampaignStore, optional
        Record ``report.html`` as this run's output.

    Returns
    -------
    Path
        The file written.
    """
    out = Path(out)
    lines = ["| metric | unit | median | 95th percentile | worst | samples |",
             "|---|---|---|---|---|---|"]
    for metric in _metrics(campaign, summary, torque=True):
        m = summary[metric]
        lines.append(f"| {metric} | {_metric_unit(metric)} | {m['median']:.4g} | "
                     f"{m['p95']:.4g} | {m['worst']:.4g} | {m['count']} |")
    figures = [(out / name, caption) for name, caption in _captions(campaign).items()
               if (out / name).exists()]
    tables = [(f"{summary['samples']} plants, baseline {summary['baseline']}",
               "\n".join(lines))]
    if campaign.nominal is not None:  # every campaign runs the nominal plant too (index -1)
        tables.append(("Nominal plant", _nominal_table(campaign)))
    path = write_report_html(
        out / "report.html", title=f"rrr-pin Monte Carlo campaign on {campaign.robot}",
        tables=tables,
        figures=figures, design=campaign.settings, units=SETTINGS_UNITS,
        design_title="Settings")
    return store.wrote("report.html") if store is not None else path


def _nominal_table(campaign: Campaign) -> str:
    """Markdown table of the nominal plant's row: per law, its figures (``-`` if it failed)."""
    row = campaign.nominal
    keys = (("rms_error", "RMS error [rad]"), ("max_error", "max error [rad]"),
            ("rms_torque", "RMS torque [N m]"), ("drift", "loop drift [m]"))
    lines = ["| controller | " + " | ".join(label for _, label in keys) + " | status |",
             "|---" * (len(keys) + 2) + "|"]
    for d in campaign.laws:
        cells = [f"{row[k]:.4g}" if k in row else "-"
                 for k in (f"{d['name']}_{key}" for key, _ in keys)]
        lines.append(f"| {d['label']} | " + " | ".join(cells) +
                     f" | {row.get(d['name'] + '_status', row['status'])} |")
    return "\n".join(lines)


def summary_lines(campaign: Campaign, summary: dict) -> list[str]:
    """Return the summary of a campaign as text lines (no newlines), for a terminal.

    How many plants every law ran on, the engines that ran them, the certificates (if any),
    the share of plants where each law beats the baseline, and a fixed-width table of median,
    95th percentile and worst of each error and torque ratio and error metric.
    """
    s = summary
    lines = [f"every controller ran on {s['samples_ok']}, a run diverged on "
             f"{s['samples_diverged']}"]
    if "status" in s:
        lines.append(f"per law: {s['status']}")
    if "certified" in s:
        exact = " and exact discrete loop" if (s.get("certificate") or {}).get("rate_hz") \
            else ""
        lines.append(f"certified (frozen nu-gap < b{exact}): {s['certified']} plants, of which "
                     f"{s['certified_and_ran']} ran; not certified but ran: "
                     f"{s['not_certified_but_ran']}; largest nu-gap {s['nugap_max']:.4g}")
        if "certified_ran" in s:
            lines.append("on the certified plants: " + ", ".join(
                f"{n} ran on {c}" + (f" (diverged on {s['certified_diverged'][n]}: not "
                                      f"certified for {n})" if s['certified_diverged'][n]
                                      else "") for n, c in s["certified_ran"].items()))
        cov = s.get("certificate")
        if cov:
            wa = f"{cov['actuator_rad_s']:g} rad/s" if cov["actuator_rad_s"] else "none"
            rate = (f"at {cov['rate_hz']:g} Hz, delay {cov['delay_s']:g} s, actuator {wa}"
                    if cov["rate_hz"] else "continuous, without effects")
            lines.append(f"the certificate covers {cov['law']} on {cov['plant']}, {rate}; "
                         + (f"not covered, present in this run: "
                            f"{', '.join(cov['not_covered'])}" if cov["not_covered"]
                            else "every effect of this run covered"))
    if s.get("engines"):
        lines.append("engines that ran: " + "; ".join(
            f"{name} " + ", ".join(f"{e} {n}" for e, n in counts.items())
            for name, counts in s["engines"].items()))
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

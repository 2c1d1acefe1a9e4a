"""The report of a study: ``results.json``, ``results.md``, the plants' URDFs and ``report.html``.

``results.md`` has, for any set of controllers, a table of every controller against the
baseline, and per-joint figures. Where the study includes the paper's two controllers (the
built-in laws named ``fl`` and ``hinf``, FL alone as the baseline), it also sets the measured
figures beside the paper's claims (section 5) and says plainly where they agree. Nothing here
tunes the study: the verdicts are fixed rules on measured numbers, stated in the file, and no
verdict is computed from a missing or non-finite number.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..campaign.study import StudyResult
from ..model.dynamics import Robot, robot_from_xml
from .html import write_report_html
from .viewer import Scene, Track

__all__ = ["write_results", "results_markdown", "write_study_report", "summary_lines",
           "PAPER_ERROR_RATIO", "PAPER_LAWS"]

#: The paper's claim for the uncertain plants: "almost a ten times better performance".
PAPER_ERROR_RATIO = 10.0

#: Names of the built-in laws the paper compares: (baseline, H-infinity + FL). The paper's
#: claims are checked only when both are the built-in tracking law (not a user's law that
#: happens to carry one of these names).
PAPER_LAWS = ("fl", "hinf")
_TRACKING = "rrr_pin.control.laws.TrackingController"

#: Nominal errors below this fraction of the reference amplitude count as "equivalent": both
#: at the noise level of the integrator (continuous-time laws, ~1e-9 rad) or of the sampling
#: (1 kHz zero-order hold, ~1e-6 rad), far below the uncertain plants' errors.
NOMINAL_NOISE = 1e-5


def _fmt(x, digits=3) -> str:
    if x is None:
        return "undefined (0/0)"
    return f"{x:.{digits}g}"


def _error_ratio_verdict(ratio: float) -> str:
    if ratio is None or not math.isfinite(ratio):
        return "**no verdict**: the ratio is undefined or not a finite number"
    if ratio <= 1.0:
        return "**does not reproduce**: H-infinity + FL is not better"
    if ratio < PAPER_ERROR_RATIO / 2:
        return (f"same direction, **weaker** than the paper: {_fmt(ratio)}x instead of about "
                f"{PAPER_ERROR_RATIO:g}x")
    if ratio <= PAPER_ERROR_RATIO * 2:
        return f"agrees: {_fmt(ratio)}x, the paper's order (about {PAPER_ERROR_RATIO:g}x)"
    return (f"same direction, **stronger** than the paper: {_fmt(ratio)}x instead of about "
            f"{PAPER_ERROR_RATIO:g}x")


def _torque_verdict(ratio: float) -> str:
    if ratio is None or not math.isfinite(ratio):
        return "**no verdict**: the ratio is undefined or not a finite number"
    if abs(ratio - 1.0) <= 0.1:
        side = "slightly smaller" if ratio < 1.0 else "slightly larger" if ratio > 1.0 else "equal"
        agree = "agrees" if ratio <= 1.0 else "agrees on 'about the same'; the paper says smaller"
        return f"{agree}: H-infinity + FL uses {_fmt(ratio, 5)}x the torque ({side})"
    return f"**does not agree**: H-infinity + FL uses {_fmt(ratio)}x the torque of FL alone"


def _paper_rows(result: StudyResult, s: dict) -> list[str]:
    fl, hinf = PAPER_LAWS
    cfg, ref = result.config, result.reference
    lines = ["## The paper's claims (section 5): FL alone against H-infinity + FL", "",
             "| Claim (paper, section 5) | Paper | Measured | Verdict |", "|---|---|---|---|"]
    nom = s["nominal_max_error"]
    amp = getattr(ref, "amp", None)
    if amp is not None:
        scale = float(np.max(amp))
    else:  # half the peak-to-peak range over the run (a sinusoid's amplitude); a closed path
        # returns to its start, so the start-to-end distance would be no scale at all
        R = ref.positions(np.linspace(0.0, cfg.run.duration, 1001))
        scale = 0.5 * float(np.max(np.ptp(R, axis=0)))
    noise = NOMINAL_NOISE * scale
    values = [nom[fl], nom[hinf]]
    if not all(math.isfinite(v) for v in values):
        verdict = "**no verdict**: a nominal error is not finite"
    elif max(values) < noise:
        verdict = (f"agrees: both below {noise:.2g} rad, at the "
                   f"{'sampling' if cfg.run.rate else 'integrator'}'s noise level (a ratio of "
                   f"two noise levels is no claim)")
    else:
        verdict = f"**differs**: an error above {noise:.2g} rad"
    lines.append(f"| Nominal model: both controllers track alike (Fig. 5c) | equivalent | max abs "
                 f"error: FL {_fmt(nom[fl])} rad, H-inf+FL {_fmt(nom[hinf])} rad | {verdict} |")
    if hinf not in s.get("error_ratio_uncertain", {}):
        lines.append("| Uncertain plants | about 10x smaller error | no plant where both ran | "
                     "**no figure** |")
        return lines
    ratio = s["error_ratio_uncertain"][hinf]
    lines.append(f"| Uncertain plants: RMS error FL alone / H-inf+FL (Fig. 6c) | about 10 | "
                 f"{_fmt(ratio)} | {_error_ratio_verdict(ratio)} |")
    per_joint = s["error_ratio_uncertain_per_joint"][hinf]
    better = ("**no verdict**: a ratio is undefined or not a finite number"
              if not all(x is not None and math.isfinite(x) for x in per_joint)
              else "all joints better" if min(per_joint) > 1 else "**not on every joint**")
    lines.append(f"| ... per joint ({', '.join(result.joint_names)}) | - | "
                 f"{', '.join(_fmt(x) for x in per_joint)} | {better} |")
    torque = s["torque_ratio_uncertain"][hinf]
    lines.append(f"| Uncertain plants: RMS torque H-inf+FL / FL alone (Fig. 6a-b) | about 1, "
                 f"slightly smaller | {_fmt(torque, 5)} | {_torque_verdict(torque)} |")
    return lines


def results_markdown(result: StudyResult, data: dict | None = None) -> str:
    """Markdown report of a study.

    Every controller against the baseline, per-joint figures, and, where the paper's two
    controllers are present, the paper's claims.
    """
    data = result.to_json() if data is None else data
    s = data["summary"]
    cfg = result.config
    run = cfg.run
    names, base = result.names, cfg.baseline
    mode = (f"sampled controllers at {run.rate:g} Hz (zero-order hold)" if run.rate
            else "continuous-time control laws (as the paper's Simulink study)")
    start = ("starting on the reference" if run.q0 is None and run.qd0 is None
             else f"starting at q0 = {run.q0}, qd0 = {run.qd0}")
    lines = [
        f"# Closed-loop study on `{result.robot}`",
        "",
        f"Reference: {_describe_reference(result.reference.to_dict())}, {run.duration:g} s, "
        f"{start}. Integration: RK4, step {run.dt:g} s; {mode}; engine {run.engine}. "
        f"Uncertain plants: {len(result.samples)} (seed {cfg.seed}), "
        f"{cfg.tolerances.inertia:.0%} on masses and moments, {cfg.tolerances.length:.0%} on "
        f"lengths; every controller ran on {s['samples_ok']}.",
        "",
        "Controllers: " + "; ".join(f"`{d['name']}` = {d['label']}" for d in result.laws)
        + f". Baseline: `{base}`.",
        "",
        f"## Every controller against the baseline ({result.label(base)})",
        "",
        "| Controller | nominal max error [rad] | uncertain: RMS error baseline / controller | "
        "per joint | uncertain: RMS torque controller / baseline | diverged plants |",
        "|---|---|---|---|---|---|",
    ]
    ratios = s.get("error_ratio_uncertain", {})
    for k in names:
        if k == base:
            cells = ["(baseline)", "-", "(baseline)"]
        elif k in ratios:
            cells = [_fmt(ratios[k]),
                     ", ".join(_fmt(x) for x in s["error_ratio_uncertain_per_joint"][k]),
                     _fmt(s["torque_ratio_uncertain"][k], 5)]
        else:
            cells = ["no plant where both ran", "-", "-"]
        lines.append(f"| {result.label(k)} (`{k}`) | {_fmt(s['nominal_max_error'][k])} | "
                     + " | ".join(cells) + f" | {s['diverged'][k]} |")
    if "samples_certified" in s:
        n_cert = sum(1 for x in result.samples if "certificate" in x)
        lines += ["", f"Frozen-configuration certificates (H-infinity design, nu-gap against "
                  f"b(Gs, Ks) = {s['certificate_b']:.4g}): {s['samples_certified']} of {n_cert} "
                  f"uncertain plants certified, largest nu-gap {s['nugap_max']:.4g}. A "
                  "certificate covers the frozen linearizations only (see the README)."]
    builtin = {d["name"] for d in result.laws if d.get("class") == _TRACKING}
    if all(k in builtin for k in PAPER_LAWS) and base == PAPER_LAWS[0]:
        lines += [""] + _paper_rows(result, s)
    lines += ["", f"## Per-joint figures (each cell: {', '.join(result.joint_names)})", "",
              "| Plant | Controller | RMS error [rad] | max error [rad] | RMS torque [N m] | "
              "peak torque [N m] |",
              "|---|---|---|---|---|---|"]
    for group, label in (("nominal", "nominal"), ("uncertain", "uncertain (mean)")):
        for key in names:
            row = data[group].get(key)
            if not row:
                continue
            cells = [" ".join(_fmt(v) for v in row[m])
                     for m in ("rms_error", "max_error", "rms_torque", "peak_torque")]
            lines.append(f"| {label} | {result.label(key)} | " + " | ".join(cells) + " |")
    lines += ["", f"Verdict rules: nominal errors below {NOMINAL_NOISE:g} of the reference "
              "amplitude (half its peak-to-peak range) count as equivalent; an error ratio "
              "within a factor of 2 of the paper's 10 agrees; a torque ratio within 10 % of 1 "
              "is 'about the same'.", ""]
    return "\n".join(lines)


def _describe_reference(d: dict) -> str:
    kind = d.get("kind")
    if kind == "sine":
        return (f"r(t) = home + amp sin(2 pi f t + phase), home = {_list(d['home_rad'])} rad, "
                f"amp = {_list(d['amp_rad'])} rad, f = {_list(d['freq_hz'])} Hz, phase = "
                f"{_list(d['phase_rad'])} rad")
    if kind == "quintic":
        return (f"quintic rest-to-rest from {_list(d['start_rad'])} to {_list(d['goal_rad'])} "
                f"rad in {d['move_time_s']:g} s")
    if kind == "spline":
        return (f"C2 spline through {len(d['times_s'])} waypoints"
                + (f" ({d['source']})" if d.get("source") else ""))
    return f"{kind} reference"


def _list(v) -> str:
    return "[" + ", ".join(f"{x:.4g}" for x in np.asarray(v)) + "]"


def write_results(result: StudyResult, out: str | Path, design: dict | None = None) -> dict:
    """Write ``results.json``, ``results.md`` and ``plants/*.urdf`` into ``out``.

    Returns
    -------
    dict
        The ``results.json`` content.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if design is not None:
        result.design = design
    data = result.to_json()
    plants = out / "plants"
    plants.mkdir(exist_ok=True)
    for stale in plants.glob("*.urdf"):
        stale.unlink()
    for plant in result.plants:
        plant.write(plants, stem=result.robot)
    (out / "results.json").write_text(json.dumps(data, indent=1) + "\n")
    (out / "results.md").write_text(results_markdown(result, data))
    return data


def write_study_report(result: StudyResult, out: str | Path, figures, design: dict | None,
                       robot: Robot) -> Path:
    """Write ``out/report.html``: results table, figures, design and one 3D scene per law.

    In each scene the nominal plant is opaque and the uncertain plants are translucent ghosts.
    Each uncertain plant's model is built once from its URDF (``result.plants``) and shared by
    the scenes of every law that ran on it.

    Parameters
    ----------
    result : StudyResult
    out : path-like
        The study's folder.
    figures : sequence of path-like
        Image files to inline.
    design : dict, optional
        Design summary shown as nested tables.
    robot : Robot
        The nominal arm (its gravity and locked joints are the plants').

    Returns
    -------
    Path
        The file written.
    """
    models: dict[int, Robot] = {}

    def model(plant) -> Robot:
        if plant.index not in models:
            models[plant.index] = robot_from_xml(plant.urdf, gravity=robot.gravity,
                                                 lock=dict(robot.locked),
                                                 name=f"sample{plant.index}", check=False)
        return models[plant.index]

    scenes = []
    for name in result.names:
        nominal = result.nominal[name]
        tracks = [Track("nominal plant", nominal.t, nominal.q)]
        for sample, plant in zip(result.samples, result.plants, strict=True):
            traj = sample["trajectories"].get(name)
            if traj is not None:
                tracks.append(Track(f"uncertain plant {plant.index}", traj.t, traj.q,
                                    opacity=0.35, robot=model(plant)))
        scenes.append(Scene(f"{result.label(name)}: nominal and uncertain plants", robot,
                            tracks))
    return write_report_html(Path(out) / "report.html", title=f"rrr-pin study on {result.robot}",
                             tables=[("Results", results_markdown(result))],
                             figures=figures, design=design, scenes=scenes)


def summary_lines(result: StudyResult, summary: dict) -> list[str]:
    """Headline figures of a study as text lines (no newlines), for a terminal.

    From ``summary`` (``results.json["summary"]``): the nominal largest errors, per law the
    uncertain-plant error and torque ratios against the baseline, the certificates of the
    uncertain plants of ``result``, and the count of plants with a diverged run (if any).
    """
    s, base = summary, summary["baseline"]
    lines = ["nominal max |e| [rad]: " + ", ".join(f"{k} {v:.3g}"
                                                   for k, v in s["nominal_max_error"].items())]
    for name, ratio in s.get("error_ratio_uncertain", {}).items():
        per_joint = ", ".join(_fmt(x) for x in s["error_ratio_uncertain_per_joint"][name])
        torque = s["torque_ratio_uncertain"][name]
        lines.append(f"uncertain ({s['samples_ok']} plants): RMS error {base} / {name} = "
                     f"{_fmt(ratio)} (per joint {per_joint}); RMS torque {name} / {base} = "
                     + (_fmt(None) if torque is None else f"{torque:.4f}"))
    if "samples_certified" in s:
        checked = sum(1 for x in result.samples if "certificate" in x)
        lines.append(f"certified (frozen nu-gap < b = {s['certificate_b']:.4g}): "
                     f"{s['samples_certified']} of {checked} plants, largest nu-gap "
                     f"{s['nugap_max']:.4g}")
    if s["samples_diverged"]:
        lines.append(f"{s['samples_diverged']} uncertain plant(s) with a diverged run (see "
                     f"results.json)")
    return lines

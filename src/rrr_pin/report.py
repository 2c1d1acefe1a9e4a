"""The report of a study: ``results.json``, ``results.md`` and the uncertain plants' URDFs.

``results.md`` sets the measured figures beside the paper's claims (section 5) and says plainly
where they agree. Nothing here tunes the study: the verdicts are fixed rules on measured numbers,
stated in the table.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .study import CONTROLLERS, StudyResult

__all__ = ["write_results", "results_markdown", "PAPER_ERROR_RATIO"]

#: The paper's claim for the uncertain plants: "almost a ten times better performance".
PAPER_ERROR_RATIO = 10.0

#: Nominal errors below this fraction of the reference amplitude count as "equivalent": both
#: at the noise level of the integrator (continuous-time laws, ~1e-9 rad) or of the sampling
#: (1 kHz zero-order hold, ~1e-6 rad), far below the uncertain plants' errors.
NOMINAL_NOISE = 1e-5


def _fmt(x, digits=3) -> str:
    return f"{x:.{digits}g}"


def _error_ratio_verdict(ratio: float) -> str:
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
    if abs(ratio - 1.0) <= 0.1:
        side = "slightly smaller" if ratio < 1.0 else "slightly larger" if ratio > 1.0 else "equal"
        agree = "agrees" if ratio <= 1.0 else "agrees on 'about the same'; the paper says smaller"
        return f"{agree}: H-infinity + FL uses {_fmt(ratio, 5)}x the torque ({side})"
    return f"**does not agree**: H-infinity + FL uses {_fmt(ratio)}x the torque of FL alone"


def results_markdown(result: StudyResult, data: dict | None = None) -> str:
    """Markdown table of a study's figures beside the paper's claims."""
    data = result.to_json() if data is None else data
    s = data["summary"]
    cfg = result.config
    ref = result.reference
    mode = (f"sampled controllers at {cfg.rate:g} Hz (zero-order hold, Tustin K)" if cfg.rate
            else "continuous-time control laws (as the paper's Simulink study)")
    lines = [
        f"# Reproduction of the paper's section 5 on `{result.robot}`",
        "",
        f"Reference: r(t) = home + amp sin(2 pi f t + phase), home = {_list(ref.home)} rad, "
        f"amp = {_list(ref.amp)} rad, f = {_list(ref.freq)} Hz, phase = {_list(ref.phase)} rad, "
        f"{cfg.duration:g} s, starting on the reference. Integration: RK4, step "
        f"{cfg.dt:g} s; {mode}. FL alone: lam = {cfg.lam_fl:g} rad/s; H-infinity + FL: "
        f"lam = {cfg.lam_hinf:g} rad/s with the loop-shaping K. Uncertain plants: "
        f"{len(result.samples)} (seed {cfg.seed}), {cfg.tolerances.inertia:.0%} on masses and "
        f"moments, {cfg.tolerances.length:.0%} on lengths; {s['samples_ok']} ran, "
        f"{s['samples_diverged']} diverged.",
        "",
        "| Claim (paper, section 5) | Paper | Measured | Verdict |",
        "|---|---|---|---|",
    ]
    nom = s["nominal_max_error"]
    noise = NOMINAL_NOISE * float(np.max(ref.amp))
    equivalent = max(nom.values()) < noise
    lines.append(
        f"| Nominal model: both controllers track alike (Fig. 5c) | equivalent | max abs error: "
        f"FL {_fmt(nom['fl'])} rad, H-inf+FL {_fmt(nom['hinf'])} rad | "
        + (f"agrees: both below {noise:.2g} rad, at the {'sampling' if cfg.rate else 'integrator'}"
           "'s noise level (a ratio of two noise levels is no claim)" if equivalent
           else f"**differs**: an error above {noise:.2g} rad")
        + " |")
    if "error_ratio_uncertain" in s:
        lines.append(
            f"| Uncertain plants: RMS error FL alone / H-inf+FL (Fig. 6c) | about 10 | "
            f"{_fmt(s['error_ratio_uncertain'])} | "
            f"{_error_ratio_verdict(s['error_ratio_uncertain'])} |")
        per_joint = ", ".join(_fmt(x) for x in s["error_ratio_uncertain_per_joint"])
        better = ("all joints better" if min(s["error_ratio_uncertain_per_joint"]) > 1
                  else "**not on every joint**")
        lines.append(f"| ... per joint ({', '.join(result.joint_names)}) | - | {per_joint} | "
                     f"{better} |")
        lines.append(
            f"| Uncertain plants: RMS torque H-inf+FL / FL alone (Fig. 6a-b) | about 1, slightly "
            f"smaller | {_fmt(s['torque_ratio_uncertain'], 5)} | "
            f"{_torque_verdict(s['torque_ratio_uncertain'])} |")
    else:
        lines.append("| Uncertain plants | about 10x smaller error | every plant diverged | "
                     "**no figure** |")
    lines += ["", f"## Per-joint figures (each cell: {', '.join(result.joint_names)})", "",
              "| Plant | Controller | RMS error [rad] | max error [rad] | RMS torque [N m] | "
              "peak torque [N m] |",
              "|---|---|---|---|---|---|"]
    for group, label in (("nominal", "nominal"), ("uncertain", "uncertain (mean)")):
        for key in CONTROLLERS:
            row = data[group].get(key)
            if not row:
                continue
            cells = [" ".join(_fmt(v) for v in row[m])
                     for m in ("rms_error", "max_error", "rms_torque", "peak_torque")]
            lines.append(f"| {label} | {CONTROLLERS[key]} | " + " | ".join(cells) + " |")
    lines += ["", f"Verdict rules: nominal errors below {NOMINAL_NOISE:g} of the reference "
              "amplitude count as equivalent; an error "
              "ratio within a factor of 2 of the paper's 10 agrees; a torque ratio within 10 % of "
              "1 is 'about the same'.", ""]
    return "\n".join(lines)


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

"""The report of a study on any plant: ``results.json``, ``results.md``, plants, ``report.html``.

``results.md`` has, for any set of controllers, a table of every controller against the
baseline, and per-joint figures. Where the study includes the paper's two controllers (the
built-in laws named ``fl`` and ``hinf``, FL alone as the baseline), it also sets the measured
figures beside the paper's claims (section 5) and says plainly where they agree. Nothing here
tunes the study: the verdicts are fixed rules on measured numbers, stated in the file, and no
verdict is computed from a missing or non-finite number.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from ..campaign.study import StudyResult
from ..control.laws import TrackingController
from ..outputs import writing
from .design import DESIGN_UNITS
from .geometry import MissingMeshWarning
from .html import write_report_html
from .jsondata import dumps
from .viewer import Scene, Track, task_path_points

__all__ = ["write_results", "results_markdown", "write_study_report", "study_captions",
           "failed_checks", "summary_lines", "write_trajectories", "torque_limit_table",
           "PAPER_ERROR_RATIO", "PAPER_LAWS", "realistic_lines"]

#: The paper's claim for the uncertain plants: "almost a ten times better performance".
PAPER_ERROR_RATIO = 10.0

#: Names of the built-in laws the paper compares: (baseline, H-infinity + FL). The paper's
#: claims are checked only when both are the built-in tracking law (not a user's law that
#: happens to carry one of these names).
PAPER_LAWS = ("fl", "hinf")
_TRACKING = f"{TrackingController.__module__}.{TrackingController.__qualname__}"

#: Nominal errors below this fraction of the reference amplitude count as "equivalent": both
#: at the noise level of the integrator (continuous-time laws, ~1e-9 rad) or of the sampling
#: (1 kHz zero-order hold, ~1e-6 rad), far below the uncertain plants' errors.
NOMINAL_NOISE = 1e-5

#: A nominal error that falls at least this factor when the discretization halves (twice the
#: rate, half the step) is the discretization's, not the law's: zero-order hold is first
#: order in the period (factor 2), RK4 fourth order in the step (16).
DISCRETIZATION_FALL = 1.5


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
    fine = [s.get("nominal_max_error_refined", {}).get(k) for k in (fl, hinf)]
    where = "sampling" if cfg.run.rate else "integrator"
    if not all(math.isfinite(v) for v in values):
        verdict = "**no verdict**: a nominal error is not finite"
    elif max(values) < noise:
        verdict = (f"agrees: both below {noise:.2g} rad, at the {where}'s noise level (a ratio "
                   f"of two noise levels is no claim)")
    elif all(f is not None and f * DISCRETIZATION_FALL <= v for f, v in zip(fine, values,
                                                                           strict=True)):
        verdict = (f"agrees: both are the {where}'s error (halving the "
                   f"{'period' if cfg.run.rate else 'step'} divides them by "
                   f"{values[0] / fine[0]:.3g} and {values[1] / fine[1]:.3g}; a ratio of two "
                   f"discretization errors is no claim)")
    else:
        verdict = f"**differs**: an error above {noise:.2g} rad that is not the {where}'s"
    lines.append(f"| Nominal model: both controllers track alike (Fig. 5c) | equivalent | max abs "
                 f"error: FL {_fmt(nom[fl])} rad, H-inf+FL {_fmt(nom[hinf])} rad | {verdict} |")
    if hinf not in s.get("error_ratio_uncertain", {}):
        lines.append("| Uncertain plants | about 10x smaller error | no plant where both ran | "
                     "**no figure** |")
        return lines
    ratio = s["error_ratio_uncertain"][hinf]
    lines.append(f"| Uncertain plants: RMS error FL alone / H-inf+FL [-] (Fig. 6c) | about 10 | "
                 f"{_fmt(ratio)} | {_error_ratio_verdict(ratio)} |")
    per_joint = s["error_ratio_uncertain_per_joint"][hinf]
    better = ("**no verdict**: a ratio is undefined or not a finite number"
              if not all(x is not None and math.isfinite(x) for x in per_joint)
              else "all joints better" if min(per_joint) > 1 else "**not on every joint**")
    lines.append(f"| ... per joint ({', '.join(result.joint_names)}) [-] | - | "
                 f"{', '.join(_fmt(x) for x in per_joint)} | {better} |")
    torque = s["torque_ratio_uncertain"][hinf]
    lines.append(f"| Uncertain plants: RMS torque H-inf+FL / FL alone [-] (Fig. 6a-b) | about 1, "
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
        f"{cfg.tolerances.describe()}; every controller ran on {s['samples_ok']}.",
        "",
        "Controllers: " + "; ".join(f"`{d['name']}` = {d['label']}" for d in result.laws)
        + f". Baseline: `{base}`.",
        "",
        f"## Every controller against the baseline ({result.label(base)})",
        "",
        "| Controller | nominal max error [rad] | uncertain: RMS error baseline / controller "
        "[-] | per joint [-] | uncertain: RMS torque controller / baseline [-] | "
        "diverged plants [-] |",
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
                  "certificate covers the frozen linearizations only (see the README)"
                  + _coverage_text(s) + "."]
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
    limited = torque_limit_table(result, s)
    if limited:
        lines += ["", "## Under the torque limit", ""] + limited
    ts = data.get("task_space")
    if ts:
        lines += ["", f"## Task space: error of frame `{ts['frame']}` against the path", "",
                  "Norm of the 3D error of the frame's origin, RMS over time and plants. "
                  "Uncertain plants two ways: by the nominal kinematics (the joint tracking "
                  "error seen in task space) and by each plant's own kinematics (where the "
                  "arm really is: its perturbed link lengths count).", "",
                  "| Controller | nominal RMS [mm] | nominal max [mm] | uncertain, tracking RMS "
                  "[mm] | uncertain, tracking max [mm] | uncertain, true RMS [mm] | "
                  "uncertain, true max [mm] |", "|---|---|---|---|---|---|---|"]
        for key in names:
            nom, unc = ts["nominal"].get(key, {}), ts["uncertain"].get(key, {})
            cells = [_fmt(1e3 * d[m]) if m in d else "-" for d, m in (
                (nom, "rms_error_m"), (nom, "max_error_m"), (unc, "rms_tracking_error_m"),
                (unc, "max_tracking_error_m"), (unc, "rms_error_m"), (unc, "max_error_m"))]
            lines.append(f"| {result.label(key)} | " + " | ".join(cells) + " |")
    lines += ["", f"Verdict rules: nominal errors below {NOMINAL_NOISE:g} of the reference "
              "amplitude (half its peak-to-peak range), or that fall at least "
              f"{DISCRETIZATION_FALL:g}x when the discretization halves (the sampling's or the "
              "integrator's error), count as equivalent; an error ratio within a factor of 2 "
              "of the paper's 10 agrees; a torque ratio within 10 % of 1 is 'about the same'.",
              ""]
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
    if kind == "spline" and "task_space" in d:
        ts = d["task_space"]
        return (f"task-space {ts['path']['kind']} of frame `{ts['frame']}` in "
                f"{ts['move_time_s']:g} s (inverse kinematics into a C2 joint spline through "
                f"{len(d['times_s'])} knots, {1e3 * ts['fk_error_m']:.3g} mm from the path at "
                f"most)")
    if kind == "spline":
        return (f"C2 spline through {len(d['times_s'])} waypoints"
                + (f" ({d['source']})" if d.get("source") else ""))
    return f"{kind} reference"


def _list(v) -> str:
    return "[" + ", ".join(f"{x:.4g}" for x in np.asarray(v)) + "]"


def write_results(result: StudyResult, out: str | Path, design: dict | None = None) -> dict:
    """Write ``results.json``, ``results.md`` and the uncertain plants into ``out``.

    Each plant as its own description (:meth:`rrr_pin.model.plant.Plant.source_text`):
    ``plants/<robot>_<k>.urdf`` for a serial arm, ``.xml`` (MJCF) for a closed chain.

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
    for stale in (*plants.glob("*.urdf"), *plants.glob("*.xml")):
        stale.unlink()
    for plant in result.plants:
        plant.write(plants, stem=result.robot)
    for name, text in (("results.json", dumps(data, indent=1) + "\n"),
                       ("results.md", results_markdown(result, data))):
        with writing(out / name):  # a full disk names the file
            (out / name).write_text(text)
    return data


def write_trajectories(result: StudyResult, out: str | Path, fmt: str | None = "npz"
                       ) -> list[Path]:
    """Write every simulated run of a study as ``out/trajectories/<plant>_<law>.<fmt>``.

    ``<plant>`` is ``nominal`` or ``sample<index:03d>`` (the uncertain plant of
    ``plants/<robot>_<index:03d>.urdf``), ``<law>`` the law's name; a run that diverged has no
    file. Each file is :meth:`rrr_pin.sim.trajectory.Trajectory.save`'s (units and metadata
    in it; read back with :meth:`~rrr_pin.sim.trajectory.Trajectory.load`). Files of an
    earlier study in ``out/trajectories`` are deleted first, also with ``fmt=None``, which
    writes nothing (so no file there outlives the study it came from).

    Parameters
    ----------
    result : StudyResult
    out : path-like
        The study's folder.
    fmt : {"npz", "csv", "parquet"} or None, default "npz"

    Returns
    -------
    list of Path
        The files written: the nominal plant's first, in law order.

    Raises
    ------
    ValueError
        An unknown format, or a law name that is not a safe file name (letters, digits,
        ``_ . -``).
    """
    import re

    from ..sim.trajectory import FORMATS

    suffix = f".{fmt}"
    if fmt is not None and suffix not in FORMATS:
        raise ValueError(f"trajectory format {fmt!r} is unknown; use one of "
                         f"{', '.join(f[1:] for f in FORMATS)}")
    folder = Path(out) / "trajectories"
    for stale in folder.iterdir() if folder.is_dir() else ():
        if stale.suffix in FORMATS:
            stale.unlink()
    if fmt is None:
        return []
    for name in result.names:
        if not re.fullmatch(r"[A-Za-z0-9_.-]+", name) or name.startswith("."):
            raise ValueError(f"law name {name!r} is not a safe file name (letters, digits, "
                             f"'_', '.', '-'); cannot name its trajectory file")
    folder.mkdir(parents=True, exist_ok=True)
    runs = [("nominal", result.nominal)]
    runs += [(f"sample{s['index']:03d}", s["trajectories"]) for s in result.samples]
    written = []
    for plant, trajectories in runs:
        for name in result.names:
            if name in trajectories:
                written.append(trajectories[name].save(folder / f"{plant}_{name}{suffix}"))
    return written


def write_study_report(result: StudyResult, out: str | Path, figures, design: dict | None,
                       nominal, data: dict | None = None) -> Path:
    """Write ``out/report.html``: results table, figures, design and one 3D scene per law.

    In each scene the nominal plant is opaque and the uncertain plants (``result.plants``, each
    with its own perturbed dimensions) are translucent ghosts; a closed chain's passive joints
    move too (:func:`rrr_pin.report.viewer.full_configurations`), and a plant's task path is
    drawn as a grey line. An uncertain arm's mesh files are looked for where the nominal's
    are. Mesh files not found are drawn as simple shapes, with one
    :class:`~rrr_pin.report.geometry.MissingMeshWarning` per distinct set of files.

    Parameters
    ----------
    result : StudyResult
    out : path-like
        The study's folder.
    figures : sequence of path-like
        Image files to inline.
    design : dict, optional
        Design summary shown as nested tables.
    nominal : Plant
        The nominal plant.
    data : dict, optional
        The study's ``results.json`` content if already computed (:func:`write_results`
        returns it); default ``result.to_json()``.

    Returns
    -------
    Path
        The file written.
    """
    path, path_label = task_path_points(nominal, result.config.run.duration)
    scenes = []
    for name in result.names:
        traj = result.nominal[name]
        tracks = [Track("nominal plant", traj.t, traj.q)]
        for sample, plant in zip(result.samples, result.plants, strict=True):
            traj = sample["trajectories"].get(name)
            if traj is not None:
                tracks.append(Track(f"uncertain plant {plant.index}", traj.t, traj.q,
                                    opacity=0.35, robot=plant.plant))
        scenes.append(Scene(f"{result.label(name)}: nominal and uncertain plants", nominal,
                            tracks, path=path, path_label=path_label))
    captions = study_captions(result, design)
    caught: list = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            return write_report_html(Path(out) / "report.html",
                                     title=f"rrr-pin study on {result.robot}",
                                     tables=_failed_table(design) + [
                                         ("Study tables", results_markdown(result, data))],
                                     figures=[(f, captions.get(Path(f).name, Path(f).name))
                                              for f in figures],
                                     design=design, scenes=scenes, units=DESIGN_UNITS)
    finally:
        # Every scene draws the nominal and its plants, which share the nominal's mesh files:
        # each set of missing files is warned about once, not once per plant and law; also
        # when the report could not be written (the warnings may say why).
        seen = set()
        for w in caught:
            if isinstance(w.message, MissingMeshWarning):
                if w.message.missing in seen:
                    continue
                seen.add(w.message.missing)
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno,
                                   source=w.source)


#: The boolean verdict keys of the design's records (``ok`` of a barrier check,
#: ``guaranteed`` of a reduction, ``certified`` of a certificate).
_VERDICT_KEYS = ("ok", "guaranteed", "certified")


def failed_checks(design: dict | None, where: str = "") -> list[str]:
    """Return one line per check of a design record that did not pass, in record order.

    A check is a dict holding a verdict key (``ok``, ``guaranteed`` or ``certified``) that is
    false; the line names its path in the record and its figures (``margin_db`` ...), so a
    reader of a report's headline sees every failed check, not only the nested tables.

    Parameters
    ----------
    design : dict or None
        A design record (:func:`rrr_pin.report.design.study_design`), nested dicts.
    where : str
        The path of ``design`` in the record (for the recursion).
    """
    out: list[str] = []
    if not isinstance(design, dict):
        return out
    for key in _VERDICT_KEYS:
        if key in design and design[key] is False:
            figures = ", ".join(f"{k} = {_fmt(v)}" for k, v in design.items()
                                if isinstance(v, int | float) and not isinstance(v, bool))
            out.append(f"{where or 'design'}: {key} = no" + (f" ({figures})" if figures else ""))
    for key, value in design.items():
        if isinstance(value, dict):
            out += failed_checks(value, f"{where}.{key}" if where else key)
    return out


def _failed_table(design: dict | None) -> list[tuple[str, str]]:
    """Return the report's first section when a design check failed: each one, listed."""
    lines = failed_checks(design)
    if not lines:
        return []
    return [("Design checks not passed", "\n".join(f"- {line}" for line in lines))]


def study_captions(result: StudyResult, design: dict | None = None) -> dict:
    """Caption of each figure of a study, by file name (``fig2.png`` ... ``certificates.png``).

    With ``design`` (:func:`rrr_pin.report.design.study_design`), the Fig. 4 captions give the
    margins and say which curve they belong to.
    """
    def margin(key, what):
        c = (design or {}).get(key)
        if not c:
            return ""
        return (f" The magenta bar is the smallest margin, {what}: {c['margin_db']:.2f} dB at "
                f"{c['worst_frequency']:.4g} rad/s.")

    n = len(result.samples)
    return {
        "fig2.png": "Fig. 2: the robust-stability (RSB, eq. 13) and robust-performance (RPB, "
                    "eq. 15) barriers, magnitude [dB] over frequency [rad/s].",
        "fig3.png": "Fig. 3: the barriers and the largest singular value of the shaped plant "
                    "W2 G W1 (open loop).",
        "fig4a.png": "Fig. 4a, robust stability: the largest singular values of the closed "
                     "loops of the shaped plant Gs (I + Gs)^-1 (black) and of the controlled "
                     "plant G K (I + G K)^-1 (green) under the RSB."
                     + margin("robust_stability", "RSB minus the controlled plant's closed "
                                                  "loop G K (I + G K)^-1"),
        "fig4b.png": "Fig. 4b, robust performance: the smallest singular values of the open "
                     "loops of the shaped plant (black) and of the controlled plant G K "
                     "(green) above the RPB, up to the performance band."
                     + margin("robust_performance", "the controlled plant's open loop G K "
                                                    "minus the RPB (negative: not met)"),
        "margins.png": "The design's loop G K per joint (eq. 11 plant, eq. 18 controller): "
                       "singular values, Bode phase and Nyquist curve near -1 "
                       "(rrr-pin margins gives each law's loop at the torque input).",
        "fig5_nominal.png": "Fig. 5: joint torques [N m] and tracking errors [rad] of every "
                            "controller on the nominal plant (exact model).",
        "fig6_uncertain.png": f"Fig. 6: joint torques [N m] and tracking errors [rad] of every "
                              f"controller on {n} uncertain plants (thin lines); the nominal "
                              f"plant's run is outlined in black.",
        "certificates.png": "Frozen-configuration certificates: each uncertain plant's largest "
                            "nu-gap to the nominal shaped plant against b(Gs, Ks); below the "
                            "line, certified.",
        "task_space.png": "Task space: the frame's path and its Cartesian error [mm] on the "
                          "nominal plant (thick) and the uncertain plants (thin).",
        "task_path.png": "Task path: the plant's task point [mm] along the reference (grey, "
                         "e.g. a mechanism's tip circle or platform cycle) and along each "
                         "controller's run on the nominal plant, in the plane the path spans "
                         "most.",
    }


def realistic_lines(section: dict) -> list[str]:
    """Return the realistic pass of ``reproduce --realistic`` as text lines.

    ``section`` is ``results.json``'s ``realistic``: ``set`` (the effects), ``summary`` (of
    the study run behind them, :func:`rrr_pin.campaign.study.summarize`).
    """
    fx, s = section["set"], section["summary"]
    head = (f"realistic set ({fx['rate_hz']:g} Hz, delay {1e3 * fx['delay_s']:g} ms, actuator "
            f"{fx['actuator_rad_s']:g} rad/s, friction {fx['viscous_Nms']:g} N m s/rad + "
            f"{fx['coulomb_Nm']:g} N m, torque limits {fx['torque_limit']}"
            + (f", noise {fx['noise_q_rad']:g} rad on q and {fx['noise_qd_rad_s']:g} rad/s on qd"
               if "noise_q_rad" in fx else "") + "):")
    base = s["baseline"]
    out = [head]
    for name, r in s.get("error_ratio_uncertain", {}).items():
        t = s.get("torque_ratio_uncertain", {}).get(name)
        out.append(f"  RMS error {base} / {name} = {_fmt(r)}; RMS torque {name} / {base} = "
                   f"{_fmt(t)}")
    laws = (s.get("torque_limit") or {}).get("laws") or {
        k: {"uncertain_diverged": v} for k, v in s["diverged"].items()}
    out.append("  diverged (of the uncertain plants): " + ", ".join(
        f"{k} {v['uncertain_diverged']}" + (" and on the nominal" if v.get("nominal_diverged")
                                           else "") for k, v in laws.items()))
    return out


def _coverage_text(s: dict) -> str:
    """``; covers ...`` of a study summary's certificate: its loop, laws, effects left out."""
    cov = s.get("certificate")
    if not cov:
        return ""
    wa = f"{cov['actuator_rad_s']:g} rad/s" if cov["actuator_rad_s"] else "none"
    loop = (f"at {cov['rate_hz']:g} Hz, delay {cov['delay_s']:g} s, actuator {wa}"
            if cov["rate_hz"] else "continuous, without effects")
    ran = ", ".join(f"{k} ran on {n}" for k, n in s.get("certified_ran", {}).items())
    return (f"; covers {cov['law']}, {loop}"
            + (f"; not covered, present in the runs: {', '.join(cov['not_covered'])}"
               if cov["not_covered"] else "")
            + (f"; on the certified plants {ran}" if ran else ""))


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
                     f"{s['nugap_max']:.4g}" + _coverage_text(s))
    ts = result.task_space
    if ts:
        lines.append(f"task space, frame {ts['frame']!r}, RMS |e_x| [mm] nominal / uncertain "
                     "(tracking; true): " + ", ".join(
                         f"{k} {1e3 * v['rms_error_m']:.3g}"
                         + (f" / {1e3 * ts['uncertain'][k]['rms_tracking_error_m']:.3g}; "
                            f"{1e3 * ts['uncertain'][k]['rms_error_m']:.3g}"
                            if k in ts["uncertain"] else "") for k, v in ts["nominal"].items()))
    if s["samples_diverged"]:
        lines.append(f"{s['samples_diverged']} uncertain plant(s) with a diverged run (see "
                     f"results.json)")
    tl = s.get("torque_limit")
    if tl:
        lines.append(f"torque limit {', '.join(f'{v:.5g}' for v in tl['limit_Nm'])} N m"
                     + (f" ({tl['spec']})" if "spec" in tl else "") + ", per controller "
                     "(diverged nominal, uncertain; RMS error uncertain [rad]; saturated "
                     "fraction uncertain [-]):")
        for name, d in tl["laws"].items():
            rms, sat = d["uncertain_rms_error"], d["uncertain_saturated"]
            lines.append(f"  {name}: {'diverged' if d['nominal_diverged'] else 'ran'}, "
                         f"{d['uncertain_diverged']} of {d['uncertain']} diverged; "
                         f"{'-' if rms is None else f'{rms:.3g}'}; "
                         f"{'-' if sat is None else f'{sat:.3g}'}")
    return lines


def torque_limit_table(result: StudyResult, summary: dict) -> list[str]:
    """Markdown table of a study under a torque limit (``summary["torque_limit"]``), or [].

    Per law (also those that diverged on the nominal plant): diverged plants, RMS error and
    time in saturation, on the nominal plant and over the uncertain ones.
    """
    tl = summary.get("torque_limit")
    if not tl:
        return []
    labels = {**{k: result.label(k) for k in result.names},
              **{k: d["label"] for k, d in result.dropped.items()}}
    how = f" ({tl['spec']}: {tl['rule']})" if "rule" in tl else ""
    lines = [f"Torque limit {', '.join(f'{v:.5g}' for v in tl['limit_Nm'])} N m{how}; "
             f"saturated = {tl['saturated_means']}.", "",
             "| Controller | diverged: nominal | diverged: uncertain plants | RMS error nominal "
             "[rad] | RMS error uncertain [rad] | saturated nominal [-] | saturated uncertain "
             "(mean) [-] |", "|---|---|---|---|---|---|---|"]

    def cell(x):
        return "-" if x is None else f"{x:.3g}"

    for name, d in tl["laws"].items():
        lines.append(f"| {labels[name]} (`{name}`) | {'yes' if d['nominal_diverged'] else 'no'} "
                     f"| {d['uncertain_diverged']} of {d['uncertain']} | "
                     f"{cell(d['nominal_rms_error'])} | {cell(d['uncertain_rms_error'])} | "
                     f"{cell(d['nominal_saturated'])} | {cell(d['uncertain_saturated'])} |")
    return lines

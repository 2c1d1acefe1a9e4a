"""``rrr-pin reproduce``: the paper end to end on any plant (design, study, figures, report)."""

from __future__ import annotations

from .build import (
    design_record,
    laws_from_args,
    load_model_and_plant,
    plant_friction_record,
    reference_from_args,
    rejections_line,
    settings_from_args,
    tolerances_from_args,
    torque_limit_from_args,
    warn_effect_margins,
    with_torque_limit,
)
from .common import check_out_early, claim_out, control_ss
from .options import add_design_argument, add_law_arguments, add_overwrite, add_plant_arguments

__all__ = ["add", "run_reproduce"]


def add(sub) -> None:
    """Declare ``reproduce``."""
    p = sub.add_parser(
        "reproduce", help="the paper end to end: design, nominal and uncertain studies, figures",
        description="Runs the loop-shaping design (section 4) and the closed-loop study "
                    "(section 5): every --controllers law on the nominal plant and on "
                    "uncertain plants, and writes fig2-fig4b, margins, fig5_nominal, "
                    "fig6_uncertain, the plants (plants/*.urdf or *.xml), results.json, "
                    "results.md and report.html into --out. Any plant: a serial arm or a "
                    "closed chain (its own task path is its reference by default).")
    add_plant_arguments(p, plant=True)
    add_law_arguments(p, 4.0, None)
    add_design_argument(p)
    p.add_argument("--samples", type=int, default=10, help="uncertain plants (10, the paper's)")
    p.add_argument("--realistic", action="store_true",
                   help="also run the comparison behind a stated realistic set (1 kHz, 1 ms "
                        "delay, 300 rad/s actuator, friction 0.1 N m s/rad + 0.2 N m, the "
                        "URDF's torque limits with hinf_aw added): results.json 'realistic', "
                        "a section of results.md and the printed lines")
    p.add_argument("--no-certify", action="store_true",
                   help="skip the frozen-configuration nu-gap certificate of each uncertain "
                        "plant (about 0.3 s per plant)")
    p.add_argument("--full-order", action="store_true",
                   help="use the full-order K instead of the reduced eq. (18)")
    p.add_argument("--out", default="results", metavar="DIR", help="output folder (results/)")
    add_overwrite(p)
    p.add_argument("--save-trajectories", nargs="?", const="npz", default=None,
                   choices=("npz", "csv", "parquet", "mat"), metavar="FORMAT",
                   help="also write every run's time series (t, q, qd, r, tau with units) as "
                        "DIR/trajectories/<nominal|sampleNNN>_<controller>.FORMAT; FORMAT npz "
                        "(default), csv, parquet or mat (MATLAB); read with Trajectory.load")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-figures", action="store_true",
                   help="no PNG figures (matplotlib not imported); results.json, results.md "
                        "and report.html are the same but for the figures")
    p.set_defaults(func=run_reproduce)


def run_reproduce(args) -> int:
    """Design, run the study, write its outputs and print its summary."""
    from tqdm import tqdm

    from ..campaign.study import StudyConfig, check_study, run_study
    from ..report.design import study_design
    from ..report.results import (
        summary_lines,
        write_results,
        write_study_report,
        write_trajectories,
    )
    from ..robust.certificates import CertificateSpec
    from ..robust.loopshaping import design
    from ..validation import check_count

    out = check_out_early(args, "reproduce")  # a file, no permission, another tool's run
    check_count("--samples", args.samples)
    model, plant, match = load_model_and_plant(args)
    settings = settings_from_args(args, plant.nq)
    reference = reference_from_args(args, plant)
    limit, limit_info = torque_limit_from_args(args, plant, reference, settings)
    if limit is not None:
        settings = with_torque_limit(settings, limit)
    tolerances = tolerances_from_args(args, plant)
    d = design(lam=45.0, n=plant.nq)
    laws, baseline = laws_from_args(args, model, K=d.K_full if args.full_order else
                                    d.K_reduced, torque_limit=limit,
                                    extra=("hinf_aw",) if limit is not None else ())
    config = StudyConfig(run=settings, samples=args.samples, seed=args.seed, jobs=args.jobs,
                         baseline=baseline, tolerances=tolerances)
    # every refusal before the design figures and the progress bar: a refused study writes
    # and prints nothing but its one line
    laws, reference = check_study(plant, laws, config=config, reference=reference)
    warn_effect_margins(args, laws, settings.rate, settings.effects)
    if out is None:  # --overwrite: the previous run is removed now that the study holds
        out = claim_out(args, "reproduce")
    figures = []
    if not args.no_figures:
        from ..report.margins import design_loop_title, save_margins_figure
        from ..report.plotting import save_design_figures

        figures = save_design_figures(d, out)
        figures.append(save_margins_figure({"G K": control_ss(d.G * d.K)}, out,
                                           title=design_loop_title(d)))
    bar = tqdm(total=args.samples + 1, unit="plant", desc=f"{plant.name}: simulating",
               disable=args.no_progress)
    certificate = None if args.no_certify else CertificateSpec.from_design(
        d, reduced=not args.full_order)
    try:
        result = run_study(plant, laws, config=config, reference=reference,
                           certificate=certificate,
                           progress=lambda done, total: bar.update(done - bar.n))
    finally:  # on Ctrl-C too, so the interrupt message starts on a line of its own
        bar.close()
    result.torque_limit = limit_info
    if match is not None:
        result.joint_match = match.to_dict()
    friction = plant_friction_record(plant, settings)
    if friction is not None:
        result.plant_friction = friction
    design_info = study_design(d, full_order=args.full_order)
    if design_record(args) is not None:
        design_info = {**design_info, "tuned": design_record(args)}
    data = write_results(result, out, design=design_info)
    if args.realistic:
        data = _realistic(args, plant, d, config, reference, certificate, data, out)
    if not args.no_figures:
        from ..report.plotting import save_study_figures

        figures += save_study_figures(result, out, plant)
    report = write_study_report(result, out, figures, design_info, plant, data=data)
    saved = write_trajectories(result, out, args.save_trajectories)  # None: clears old ones
    print(f"{plant.name}: {plant.nq} joints, gamma = {d.ncf.gamma:.4f}, controllers "
          f"{', '.join(result.names)} (baseline {baseline})")
    if match is not None:
        print(f"laws designed on {match.model}, run on {match.plant} (joints paired by "
              f"{match.by})")
    if friction is not None:
        print(f"{plant.name}: its own damping and friction loss ({friction['source']}): "
              f"{friction['note']}")
    print("\n".join(summary_lines(result, data["summary"])))
    if "realistic" in data:
        from ..report.results import realistic_lines

        print("\n".join(realistic_lines(data["realistic"])))
    if rejections_line(result.samples):
        print(rejections_line(result.samples))
    print(f"wrote {out}/results.json, results.md, plants/, {len(figures)} figures and "
          f"{report.name} (open it in a browser)")
    if saved:
        print(f"wrote {len(saved)} trajectories to {out}/trajectories/ "
              f"({args.save_trajectories})")
    return 0


def _realistic(args, plant, d, config, reference, certificate, data, out) -> dict:
    """Run the study again behind ``REALISTIC_SET``; add it to results.json and results.md."""
    import dataclasses

    import numpy as np

    from ..campaign.study import REALISTIC_SET, check_study, realistic_run, run_study, summarize
    from ..outputs import writing
    from ..report.jsondata import dumps
    from ..report.results import realistic_lines

    run = realistic_run(config.run, plant)
    limit = np.asarray(plant.effort_limits(), dtype=float)
    laws, _ = laws_from_args(args, plant, K=d.K_full if args.full_order else d.K_reduced,
                             torque_limit=limit, extra=("hinf_aw",))
    cfg = dataclasses.replace(config, run=run)
    laws, reference = check_study(plant, laws, config=cfg, reference=reference)
    warn_effect_margins(args, laws, run.rate, run.effects)
    result = run_study(plant, laws, config=cfg, reference=reference, certificate=certificate)
    data = {**data, "realistic": {"set": REALISTIC_SET, "run": run.to_dict(),
                                  "summary": summarize(result)}}
    from ..report.plotting import plot_realistic, save_figure

    save_figure(plot_realistic({plant.name: data}), out / "realistic.png")
    lines = realistic_lines(data["realistic"])
    with writing(out / "results.json"):
        (out / "results.json").write_text(dumps(data, indent=1) + "\n")
    with writing(out / "results.md"):
        md = (out / "results.md").read_text()
        (out / "results.md").write_text(md + "\n## The comparison behind a realistic set\n\n"
                                        + "\n".join(f"- {x.strip()}" for x in lines) + "\n")
    return data

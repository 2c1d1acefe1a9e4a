"""``rrr-pin montecarlo``: a Monte Carlo campaign of seeded uncertain plants, on any plant."""

from __future__ import annotations

import sys

from .build import (
    design_record,
    laws_from_args,
    load_model_and_plant,
    reference_from_args,
    rejections_line,
    settings_from_args,
    tolerances_from_args,
    torque_limit_from_args,
    warn_effect_margins,
    with_torque_limit,
)
from .options import add_design_argument, add_law_arguments, add_plant_arguments

__all__ = ["add", "run_montecarlo"]


def add(sub) -> None:
    """Declare ``montecarlo``."""
    p = sub.add_parser(
        "montecarlo", help="Monte Carlo campaign: N seeded uncertain plants, any controllers",
        description="Draws N seeded uncertain plants (20 % inertia, 5 % lengths) around the "
                    "plant, simulates every --controllers law on each and on the nominal plant "
                    "(sampled controllers, 1 kHz by default) and writes campaign.csv, "
                    "samples.jsonl, summary.json, montecarlo.png and report.html into --out. "
                    "Results are identical whatever --jobs. Any plant: a closed chain's rows "
                    "also hold each run's loop drift.")
    add_plant_arguments(p, plant=True)
    add_law_arguments(p, 10.0, 1000.0)
    p.add_argument("--samples", type=int, required=True, help="number of uncertain plants")
    p.add_argument("--threads", type=int, default=1,
                   help="threads of the batched engine in each worker process (default 1): "
                        "--jobs 1 --threads 2 uses two cores in one process; rows are "
                        "identical whatever --threads")
    p.add_argument("--scheduler", metavar="ADDRESS", default=None,
                   help="Dask distributed scheduler address (e.g. tcp://10.0.0.5:8786); the "
                        "same tasks run on that cluster")
    p.add_argument("--out", default="results/montecarlo", metavar="DIR",
                   help="output folder (results/montecarlo); finished samples are appended to "
                        "DIR/parts.jsonl as they finish")
    p.add_argument("--certify", action="store_true",
                   help="certify every plant (frozen-configuration nu-gap < b(Gs, Ks) of the "
                        "H-infinity design): columns certified and nugap_max, certificates.png "
                        "(about 0.3 s per plant)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--resume", action="store_true",
                      help="continue the interrupted campaign in --out (same settings): only "
                           "the missing samples run; the final tables equal an uninterrupted "
                           "run's")
    mode.add_argument("--overwrite", action="store_true",
                      help="start afresh in a non-empty --out (its previous campaign is "
                           "deleted)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-figures", action="store_true",
                   help="no montecarlo.png or certificates.png (matplotlib not imported); "
                        "the tables are the same")
    add_design_argument(p)
    p.set_defaults(func=run_montecarlo)


def run_montecarlo(args) -> int:
    """Run (or resume) the campaign into its store, write its tables and print the summary."""
    import time

    from tqdm import tqdm

    from ..campaign.executors import CampaignInterrupted, WorkersLost, check_jobs, exit_status
    from ..campaign.montecarlo import (
        CampaignSettings,
        check_campaign,
        open_store,
        run_campaign,
    )
    from ..campaign.store import check_room, row_bytes
    from ..outputs import check_writable
    from ..report.campaign import summary_lines, write_campaign, write_campaign_report
    from ..sim.batched import MAX_THREADS
    from ..sim.engine_names import AUTO, CODEGEN
    from ..validation import check_count

    check_count("--samples", args.samples, 1)
    check_count("--threads", args.threads, 1, MAX_THREADS)
    if args.threads > 1 and args.engine not in (AUTO, CODEGEN):
        raise ValueError(f"--threads {args.threads} with --engine {args.engine}: threads are "
                         f"the batched engine's ({CODEGEN}); the {args.engine} engine runs one "
                         f"plant at a time per process: give --jobs instead, or --engine "
                         f"{CODEGEN} or {AUTO}")
    try:
        check_jobs(args.jobs)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"--{exc}") from None
    check_writable(args.out)
    args.write_hint = (f"; the samples finished so far are kept in {args.out}/parts.jsonl: "
                       "free space, then rerun with --resume")
    model, plant, match = load_model_and_plant(args)
    run = settings_from_args(args, plant.nq)
    reference = reference_from_args(args, plant)
    limit, _ = torque_limit_from_args(args, plant, reference, run)
    if limit is not None:
        run = with_torque_limit(run, limit)
    tolerances = tolerances_from_args(args, plant)
    certificate = K = None
    if args.certify:  # one design serves the certificate and the H-infinity law
        from ..robust.certificates import CertificateSpec
        from ..robust.loopshaping import design

        d = design(lam=45.0, n=plant.nq)
        certificate, K = CertificateSpec.from_design(d), d.K_reduced
    laws, baseline = laws_from_args(args, model, K=K)
    settings = CampaignSettings(samples=args.samples, seed=args.seed, run=run,
                                baseline=baseline, tolerances=tolerances)
    # every refusal before the store is opened: a refused campaign leaves no files behind
    laws, reference = check_campaign(plant, laws, settings, reference=reference)
    warn_effect_margins(args, laws, run.rate, run.effects)
    check_room(args.out, args.samples + 1, row_bytes(len(laws), plant.nq))
    store = open_store(args.out, plant, laws, settings, reference, resume=args.resume,
                       overwrite=args.overwrite, certificate=certificate)
    total = args.samples + 1  # the nominal plant too
    with store:
        done = len(store.done())
        if done:
            print(f"resuming: {done} of {total} plants (with the nominal) already done in "
                  f"{args.out}")
        bar = tqdm(total=total, initial=done, unit="plant",
                   desc=f"{plant.name}: Monte Carlo (nominal + {args.samples})",
                   disable=args.no_progress)
        start = time.perf_counter()
        try:
            campaign = run_campaign(plant, laws, settings, reference=reference, jobs=args.jobs,
                                    scheduler=args.scheduler,
                                    progress=lambda d, total: bar.update(d - bar.n),
                                    store=store, certificate=certificate,
                                    threads=args.threads)
        except CampaignInterrupted as exc:
            bar.close()
            print(f"rrr-pin montecarlo: {exc}", file=sys.stderr)
            # 3: workers lost; else 128 + the signal (130 SIGINT, 143 SIGTERM), as a shell does.
            return 3 if isinstance(exc, WorkersLost) else exit_status(exc)
        bar.close()
        elapsed = time.perf_counter() - start
        s = write_campaign(campaign, args.out, store=store, certificate_b=None if
                           certificate is None else certificate.margin(plant.nq),
                           figures=not args.no_figures)
        if design_record(args) is not None:  # which design ran, with its requirement table
            _record_summary(args, "design", design_record(args))
        if match is not None:  # the laws' model and the plant, joint by joint
            _record_summary(args, "joint_match", match.to_dict())
        s["written"].append(str(write_campaign_report(campaign, s, args.out, store)))
    nl, ran = len(laws), total - done
    print(f"{plant.name}: {ran} plants x {nl} controllers x {run.duration:g} s in "
          f"{elapsed:.1f} s ({nl * ran / max(elapsed, 1e-9):.1f} rollouts/s)")
    if match is not None:
        print(f"laws designed on {match.model}, run on plants drawn around {match.plant} "
              f"(joints paired by {match.by})")
    print("\n".join(summary_lines(campaign, s)))
    if rejections_line(campaign.rows):
        print(rejections_line(campaign.rows))
    print("wrote " + ", ".join(s["written"]))
    return 0


def _record_summary(args, key: str, record: dict) -> None:
    """Add ``record`` to ``summary.json`` under ``key`` (``--design``'s, ``--plant``'s)."""
    import json
    from pathlib import Path

    from ..report.jsondata import dumps

    path = Path(args.out) / "summary.json"
    data = json.loads(path.read_text())
    data[key] = record
    path.write_text(dumps(data))

"""``rrr-pin design``: the paper's loop-shaping design (section 4), or a design to requirements."""

from __future__ import annotations

import sys

from .common import claim_out, control_ss, option
from .options import add_armature_argument, add_joint_tolerance_arguments, add_overwrite

__all__ = ["add", "run_design", "run_tuned", "add_tuning_arguments", "DEFAULT_REQUIREMENTS"]


def add(sub) -> None:
    """Declare ``design``."""
    p = sub.add_parser(
        "design", help="the paper's H-infinity loop-shaping design (section 4), or with --robot "
                       "and --require a design tuned to requirements (design.json)",
        description="Without --robot or --require: the paper's H-infinity loop-shaping design "
                    "(section 4: ncfsyn on the feedback-linearized plant, the reduced controller "
                    "of eq. 18). With --robot or --require: design to requirements, a "
                    "structured FL law tuned over the arm's uncertain plants, written to "
                    "--out DIR/design.json.")
    p.add_argument("--lam", type=float, default=None,
                   help="feedback-linearization natural frequency lambda [rad/s] (default 45; "
                        "with --per-joint-lam the start of each joint's; refused with "
                        "--tune-lam, whose search starts mid-range)")
    p.add_argument("--factor", type=float, default=1.0,
                   help="gamma / gamma_min of ncfsyn, 1 = optimal (default 1.0)")
    p.add_argument("--joints", type=int, default=3,
                   help="size n of the diagonal MIMO plant and controller (default 3)")
    p.add_argument("--order", type=int, default=2, metavar="N",
                   help="states of the reduced controller, eq. (18) (2, the paper's)")
    p.add_argument("--out", metavar="DIR", default=None,
                   help="write fig2.png, fig3.png, fig4a.png, fig4b.png and margins.png (the "
                        "loop G K: singular values, Bode phase, Nyquist) into DIR")
    add_overwrite(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    add_tuning_arguments(p)
    p.set_defaults(func=run_design)


def add_tuning_arguments(p) -> None:
    """Declare the options of a design tuned to requirements (``--robot``, ``--require``)."""
    g = p.add_argument_group(
        "design to requirements (with --robot or --require: writes --out DIR/design.json)")
    g.add_argument("--robot", default=None, metavar="NAME|PATH",
                   help="tune a structured FL law for this arm (rrr, ur5, panda, a URDF, ...) "
                        "over its uncertain plants")
    g.add_argument("--lock", action="append", metavar="JOINT=VALUE",
                   help="lock a joint of --robot at a position (repeatable)")
    add_armature_argument(g)
    g.add_argument("--require", action="append", default=[], metavar="NAME=VALUE",
                   help="a requirement (repeatable): delay_margin=S, disk_margin=ALPHA, "
                        "actuator_bandwidth=RAD_S, bandwidth=RAD_S, peak_torque=N_M|urdf "
                        "(peak_torque@JOINT=... for one joint), error_ratio=X (RMS error of "
                        "FL alone over the tuned law's on the uncertain plants), "
                        "noise_gain=N_M_PER_RAD (peak gain from position noise to torque), "
                        "reference_model=RAD_S[,peak=M] (the tracking error no larger than "
                        "the FL closed loop's of that bandwidth, M > 1 allowed at high "
                        "frequency; default 2), lower_gain_margin=K (stable with the torque "
                        "scaled by every factor in [K, 1]; lower_gain_margin=0.5 is added "
                        "unless given, =1 turns it off); default "
                        "delay_margin=0.003 disk_margin=0.5 error_ratio=10. Every requirement "
                        "is evaluated, and every plant simulated, behind the --with effects "
                        "and the delay and actuator of actuator_bandwidth=RAD_S,delay=S; "
                        "status met only when every requirement is verified and every plant "
                        "simulated stable")
    g.add_argument("--structure", default="order2", metavar="NAME",
                   help="the outer controller K: fl (none), gain, pid, leadlag, orderN "
                        "(a stable order-N transfer function; order2 is the paper's shape), "
                        "weight (the paper's loop-shaping synthesis, its weight W1's k, z, p "
                        "tuned; minutes)")
    g.add_argument("--tune-lam", action="store_true",
                   help="tune the FL bandwidth lam too (else fixed at --lam)")
    g.add_argument("--per-joint", action="store_true",
                   help="one outer controller of --structure per joint, each its own "
                        "parameters (K diagonal; lam shared unless --per-joint-lam)")
    g.add_argument("--per-joint-lam", action="store_true",
                   help="tune one FL bandwidth lam per joint, each starting at --lam (implies "
                        "--per-joint; design.json records lam_rad_s as a list)")
    g.add_argument("--samples", type=int, default=20,
                   help="uncertain plants the design must work on, with the nominal (20, "
                        ">= 1), drawn from the design's plant set: the 20 %% inertia / 5 %% "
                        "length box (recorded in design.json under plants); each is "
                        "simulated behind the design's effects before status met")
    g.add_argument("--plants", choices=("samples", "vertices"), default="samples",
                   help="how the --samples plants are drawn: samples (uniform inside the "
                        "20 %% / 5 %% tolerance box, as the studies draw them) or vertices "
                        "(seeded corners of that box, every factor at 1 - tol or 1 + tol)")
    add_joint_tolerance_arguments(g)
    g.add_argument("--uncertainty", metavar="IDENTIFICATION.json", default=None,
                   help="draw the plants from an identification (rrr-pin identify) instead "
                        "of the tolerance box; use --robot DIR/identified.urdf as the nominal")
    g.add_argument("--confidence", type=float, default=None,
                   help="with --uncertainty only: confidence region the plants are drawn in "
                        "(0.95)")
    g.add_argument("--uncertainty-draws", choices=("reject", "project"), default=None,
                   help="with --uncertainty: a draw with no physically consistent arm is "
                        "rejected and redrawn (reject, default), or moved to the nearest "
                        "consistent arm, its distance recorded (project)")
    g.add_argument("--seed", type=int, default=0, help="seed of the plants and starts (0)")
    g.add_argument("--rate", type=float, default=1000.0, metavar="HZ",
                   help="sampling rate of the tuned law [Hz] (1000)")
    g.add_argument("--with", dest="fixed", action="append", default=[], metavar="EFFECT=SIZE",
                   help="an effect present in every evaluation, delay=S or actuator=RAD_S")
    g.add_argument("--starts", type=int, default=4, help="seeded starts of the search (4)")
    g.add_argument("--search", choices=("nelder-mead", "minimax"), default="nelder-mead",
                   help="search per start: bounded Nelder-Mead (default) or minimax "
                        "(trust-region linear programs, the worst requirement explicit)")
    g.add_argument("--no-simulate", action="store_true",
                   help="verify without the simulations (peak torque, error ratio, stress "
                        "breaking points)")
    g.add_argument("--block", type=int, default=32, metavar="N",
                   help="plants evaluated together (32): the memory of one evaluation "
                        "grows with N, not with --samples; the design is the same for any N")
    g.add_argument("--no-progress", action="store_true",
                   help="no progress bar (start, evaluations, best normalized value, time "
                        "left)")
    g.add_argument("--quiet", action="store_true",
                   help="no progress bar and no table: print only the file written")


#: Requirements of ``rrr-pin design --robot ARM`` without ``--require``.
DEFAULT_REQUIREMENTS = ("delay_margin=0.003", "disk_margin=0.5", "error_ratio=10")


def run_tuned(args) -> int:
    """Tune, verify and write ``--out/design.json``; print the requirement table."""
    import json

    from ..campaign.design_set import design_tolerances
    from ..campaign.requirements import make_requirement
    from ..campaign.tuning import TuneError, tune
    from ..control.structures import make_structure
    from ..report.jsondata import dumps
    from ..validation import FieldError
    from .build import load_plant, tolerances_from_args
    from .stress import parse_with

    if args.out is None:
        raise ValueError("design to requirements writes DIR/design.json: give --out DIR")
    if args.samples < 1:
        raise FieldError("--samples", f"{{name}} must be >= 1 (the uncertain plants the design "
                                      f"is verified on, besides the nominal), got "
                                      f"{args.samples}")
    out = claim_out(args, "design")
    reqs = [make_requirement(t) for t in (args.require or DEFAULT_REQUIREMENTS)]
    robot = load_plant(args, robot=args.robot or "rrr")
    if args.tune_lam and args.lam is not None:
        from ..control.structures import LAM_BOUNDS

        lo, hi = LAM_BOUNDS
        raise ValueError(f"--lam {args.lam:g} with --tune-lam: the search of lam starts at "
                         f"{(lo * hi) ** 0.5:g} rad/s inside [{lo:g}, {hi:g}] rad/s and "
                         f"would not read --lam; drop --lam, or drop --tune-lam to fix lam")
    lam = 45.0 if args.lam is None else args.lam
    try:
        structure = make_structure(args.structure, None if args.tune_lam else lam,
                                   joints=robot.joint_names, per_joint=args.per_joint,
                                   per_joint_lam=args.per_joint_lam)
    except FieldError as exc:  # PerJoint's lam is --per-joint-lam here
        raise exc.relabelled(lambda f: "--per-joint-lam" if f == "lam" and args.per_joint_lam
                             else "--lam" if f == "lam_start" else f) from None
    fixed = parse_with(args.fixed, "")
    if args.plants == "vertices":
        if (args.uncertainty is not None or args.confidence is not None
                or args.uncertainty_draws is not None):
            raise ValueError("--plants vertices takes the corners of the tolerance box; an "
                             "identified set (--uncertainty, --confidence) has none: give "
                             "--plants samples")
        tol = tolerances_from_args(args, robot, vertices=True)
    elif (args.uncertainty is None and args.confidence is None
          and not any(getattr(args, f"tolerance_{k}", 0.0) for k in ("armature", "damping",
                                                                     "friction"))):
        tol = design_tolerances()
    else:
        tol = tolerances_from_args(args, robot)
    from tqdm import tqdm

    from ..campaign.executors import exit_status

    # the bar opens at the first evaluation: a refused search prints only its refusal
    bar = tqdm(total=0, unit="eval", desc=f"{robot.name}: design", delay=1e9,
               disable=args.no_progress or args.quiet)

    def progress(done, total, start, best):
        if bar.total != total:
            bar.total, bar.delay = total, 0
        bar.set_postfix_str(f"start {start}/{args.starts}, best normalized {best:.4g}",
                            refresh=False)
        bar.update(done - bar.n)

    try:
        res = tune(robot, structure, reqs, plants=args.samples, seed=args.seed,
                   rate=args.rate, fixed=fixed, starts=args.starts, tolerances=tol,
                   simulate=not args.no_simulate, search=args.search, block=args.block,
                   progress=progress)
    except TuneError as exc:
        bar.close()
        if exc.result is not None:
            _write(out / "design_refused.json", dumps(exc.result.to_dict()))
        raise ValueError(str(exc)) from None
    except FieldError as exc:  # tune's plants, starts, block are --samples, --starts, --block
        bar.close()
        raise exc.relabelled(lambda f: {"plants": "--samples", "starts": "--starts",
                                        "block": "--block"}.get(f, f)) from None
    except KeyboardInterrupt as exc:
        bar.close()
        print(f"rrr-pin design: interrupted ({exc or 'Ctrl-C'}) after {bar.n} evaluations; "
              f"nothing written (design.json is written only once the search and its "
              f"verification finish)", file=sys.stderr)
        return exit_status(exc)
    bar.close()
    path = out / "design.json"
    _write(path, dumps(res.to_dict()))
    if args.json:
        print(json.dumps({"design": str(path), "status": res.status}))
        return 0
    print("\n".join(([] if args.quiet else res.lines()) + [f"wrote {path}"]))
    return 0


def _write(path, text: str) -> None:
    """Write ``text`` to ``path`` whole or not at all (a temporary file renamed over it)."""
    import os

    tmp = path.with_name(path.name + ".part")
    tmp.write_text(text)
    os.replace(tmp, path)


def run_design(args) -> int:
    """Design, print (or ``--json``) and optionally draw the loop-shaping controller."""
    if args.robot is not None or args.require:
        return run_tuned(args)
    for name in ("armature", "tolerance_armature", "tolerance_damping", "tolerance_friction"):
        if getattr(args, name):
            raise ValueError(f"{option(name)} applies to an arm's design to requirements: give "
                             f"--robot ARM too (the paper's loop-shaping design, eq. 11, has "
                             f"no arm)")
    if args.per_joint_lam:
        raise ValueError("--per-joint-lam: the paper's loop-shaping design is of one FL plant "
                         "(eq. 11), one lam; a per-joint lam is tuned to requirements: give "
                         "--robot ARM (and --require NAME=VALUE ...)")
    if args.out is not None:  # before the design and its imports: --out /proc/x refused at once
        claim_out(args, "design")
    from ..report.design import design_lines, design_summary
    from ..report.jsondata import dumps
    from ..robust.loopshaping import design
    from ..validation import FieldError

    try:
        d = design(lam=45.0 if args.lam is None else args.lam, n=args.joints,
                   factor=args.factor, order=args.order)
    except FieldError as exc:  # design's lam, n, factor are --lam, --joints, --factor
        raise exc.relabelled(lambda f: "--joints" if f == "n" else option(f)) from None
    figures = []
    if args.out is not None:
        from ..report.margins import design_loop_title, save_margins_figure
        from ..report.plotting import save_design_figures

        figures = [str(f) for f in save_design_figures(d, args.out)]
        # the design's own loop, G K (eq. 11 plant, eq. 18 controller): margins.png
        figures.append(str(save_margins_figure({"G K": control_ss(d.G * d.K)}, args.out,
                                               title=design_loop_title(d))))
    if args.json:
        print(dumps({**design_summary(d), **({"figures": figures} if figures else {})}))
        return 0
    print("\n".join(design_lines(d) + [f"wrote {f}" for f in figures]))
    return 0

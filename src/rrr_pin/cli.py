"""Command-line interface: ``rrr-pin <command> [options]``.

Each sub-command has an ``_add_<name>(subparsers)`` function that declares its options and a
``_cmd_<name>(args) -> int`` function that runs it and returns the exit status.
"""

from __future__ import annotations

import argparse
import sys
from contextlib import contextmanager

__all__ = ["main"]


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rrr-pin",
        description="H-infinity loop shaping + feedback linearization of serial arms "
                    "(Pinocchio dynamics).")
    from . import __version__

    parser.add_argument("--version", action="version", version=f"rrr-pin {__version__}")
    verbose = {"action": "count", "help": "log on stderr what the library does: -v steps "
               "(INFO), -vv details (DEBUG), e.g. the engine chosen for each run"}
    parser.add_argument("-v", "--verbose", default=0, **verbose)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in (_add_urdf, _add_check_dynamics, _add_design, _add_reproduce,
                _add_montecarlo, _add_stress, _add_export):
        add(sub)
    for command in sub.choices.values():  # also after the command: rrr-pin reproduce -v
        command.add_argument("-v", "--verbose", default=argparse.SUPPRESS, **verbose)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``rrr-pin`` console script.

    SIGINT (Ctrl-C) and SIGTERM stop any command with one line on standard error and the
    exit status 130 or 143 (128 + the signal); its local worker processes are stopped. The
    files a command wrote are recorded in its folder's manifest (:mod:`rrr_pin.outputs`)
    however it ends.
    """
    from .campaign.executors import exit_status, interrupt_on_signals

    args = None
    try:
        with interrupt_on_signals():
            parser = _build_parser()
            args = parser.parse_args(
                _negative_values(sys.argv[1:] if argv is None else list(argv)))
            try:
                with _logging(args.verbose):
                    return int(args.func(args) or 0)
            finally:  # record the files written, also after an error or an interrupt
                if getattr(args, "outputs", None) is not None:
                    args.outputs.close()
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        print(f"rrr-pin {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # stdout closed early (`| head`): stop quietly, as shell tools do
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no error at exit
        return 141  # 128 + SIGPIPE
    except OSError as exc:  # a full disk, a lost mount: while writing the outputs
        import errno

        where = f"cannot write {exc.filename}" if exc.filename else "cannot write the outputs"
        code = f" ({errno.errorcode[exc.errno]})" if exc.errno in errno.errorcode else ""
        print(f"rrr-pin {args.command}: error: {where}: {exc.strerror or exc}{code}"
              f"{getattr(args, 'write_hint', '')}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # before the command ran, or one with no own message
        name = " ".join(["rrr-pin"] + ([args.command] if args is not None else []))
        out = getattr(args, "out", None)
        left = f"; {out} may hold files of this unfinished run" if out not in (None, "-") else ""
        print(f"{name}: interrupted ({exc or 'Ctrl-C'}){left}", file=sys.stderr)
        return exit_status(exc)


def _claim_out(args, tool: str, part: str | None = None):
    """Claim ``args.out`` for this run before any work (rrr_pin.outputs: the folder rule).

    Refuses a file, an unwritable folder, another tool's run, and a non-empty folder without
    ``--overwrite``; :func:`main` records the files written when the command ends.
    """
    from pathlib import Path

    from .outputs import OutputDir

    settings = {k: v for k, v in vars(args).items() if k not in ("func", "outputs")}
    args.outputs = OutputDir.claim(args.out, tool, part=part, overwrite=args.overwrite,
                                   settings=settings)
    args.write_hint = (f"; the files written so far (if any) are listed in "
                       f"{args.outputs.manifest}: free space, then rerun with --overwrite")
    return Path(args.out)


def _check_out_early(args, tool: str, part: str | None = None):
    """Refuse before any work what ``--overwrite`` cannot fix; claim at once without it.

    Without ``--overwrite`` the claim removes nothing, so it is made at once (returns the
    folder). With it, only the checks are made (a file, an unwritable folder, another tool's
    run; returns None), and :func:`_claim_out`, called once the options are checked, removes
    the previous run: a mistyped option never costs that run.
    """
    if not args.overwrite:
        return _claim_out(args, tool, part)
    from .outputs import check_writable, refuse_other_tool

    check_writable(args.out)
    refuse_other_tool(args.out, tool)
    return None


def _add_overwrite(p) -> None:
    p.add_argument("--overwrite", action="store_true",
                   help="replace the previous run of this command in a non-empty --out (only "
                        "the files its manifest rrr-pin-run*.json lists are removed)")


@contextmanager
def _logging(verbose: int):
    """Show the ``rrr_pin`` loggers on stderr: WARNING, INFO (-v) or DEBUG (-vv and more).

    Through tqdm's handler, so that a log line does not break a progress bar.
    """
    import logging

    from tqdm.contrib.logging import logging_redirect_tqdm

    logger = logging.getLogger("rrr_pin")
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    level = logger.level
    logger.setLevel(logging.WARNING if verbose < 1 else logging.INFO if verbose == 1
                    else logging.DEBUG)
    logger.addHandler(handler)
    try:
        with logging_redirect_tqdm(loggers=[logger]):
            yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)


def _negative_values(argv: list[str]) -> list[str]:
    """Join ``--opt -1e-3`` into ``--opt=-1e-3``: argparse reads ``-1e-3`` as an option.

    argparse takes a token for a negative number only in the forms ``-1`` and ``-0.5``; an
    exponent (``-1e-3``) made ``--dt -1e-3`` fail with "expected one argument" instead of
    reaching the option's own check.
    """
    import re

    number = re.compile(r"^-(\d+\.?\d*|\.\d+)[eE][-+]?\d+$")
    out = []
    for token in argv:
        if out and number.match(token) and out[-1].startswith("--") and "=" not in out[-1]:
            out[-1] = f"{out[-1]}={token}"
        else:
            out.append(token)
    return out


# --- urdf -------------------------------------------------------------------------------------

#: The generator's committed output, relative to the repository's root (``urdf --check``).
_COMMITTED_URDF = "urdf/rrr.urdf"


def _add_urdf(sub) -> None:
    p = sub.add_parser("urdf", help="write (or check) the URDF generated from a DH parameter set")
    p.add_argument("--params", metavar="FILE",
                   help="DH parameter set as JSON (ArmParams.save); default: the paper's Tables "
                        "1-2")
    p.add_argument("--out", metavar="PATH", default=None,
                   help="where to write the URDF (default: standard output; with --check, "
                        f"the committed {_COMMITTED_URDF})")
    p.add_argument("--check", action="store_true",
                   help="do not write: exit 1 if PATH (default: the committed "
                        f"{_COMMITTED_URDF}, from the repository's root) differs from what the "
                        "generator writes")
    p.set_defaults(func=_cmd_urdf)


def _cmd_urdf(args) -> int:
    from .model.dh import ArmParams, paper_params
    from .model.urdf import check_urdf, urdf_from_params, write_urdf

    _not_a_folder(params=args.params)
    params = ArmParams.load(args.params) if args.params else paper_params()
    if args.check:
        if args.out == "-":
            raise ValueError("--check compares a file: give --out PATH (default: "
                             f"{_COMMITTED_URDF}), not standard output")
        if args.out is None:
            args.out = _COMMITTED_URDF
        if check_urdf(args.out, params):
            print(f"{args.out}: up to date")
            return 0
        from pathlib import Path

        if Path(args.out).is_file():
            print(f"{args.out}: differs from the generator's output; regenerate with "
                  f"`rrr-pin urdf --out {args.out}`")
        else:
            where = (" (run from the repository's root, or give --out PATH)"
                     if args.out == _COMMITTED_URDF else "")
            print(f"{args.out}: missing{where}; write it with `rrr-pin urdf --out {args.out}`")
        return 1
    if args.out in (None, "-"):
        sys.stdout.write(urdf_from_params(params))
        return 0
    try:
        path = write_urdf(args.out, params)
    except OSError as exc:
        print(f"rrr-pin urdf: error: --out {args.out}: cannot write the URDF there "
              f"({exc.strerror or exc})", file=sys.stderr)
        return 2
    print(f"wrote {path}")
    return 0


# --- check-dynamics ---------------------------------------------------------------------------

def _add_check_dynamics(sub) -> None:
    p = sub.add_parser(
        "check-dynamics", help="compare Pinocchio with the paper's closed form",
        description="Largest differences between Pinocchio's M, V, G and the corrected closed "
                    "form of the paper's eq. (2)-(7) over random states (q uniform in "
                    "[-pi, pi], qd in [-5, 5] rad/s). Exits 1 if a relative difference "
                    "(largest absolute difference / largest Pinocchio entry) exceeds --rtol.")
    p.add_argument("--urdf", metavar="PATH", default=None,
                   help="URDF that Pinocchio loads (default: generated from the parameters)")
    p.add_argument("--params", metavar="FILE", default=None,
                   help="parameter JSON (ArmParams.save) for the closed form and gravity "
                        "(default: the paper's Tables 1-2)")
    p.add_argument("--samples", type=int, default=200, metavar="N",
                   help="number of random states (default: 200)")
    p.add_argument("--seed", type=int, default=0, metavar="S",
                   help="seed of the random states (default: 0)")
    p.add_argument("--rtol", type=float, default=1e-9,
                   help="largest accepted relative difference (default: 1e-9)")
    p.set_defaults(func=_cmd_check_dynamics)


def _cmd_check_dynamics(args) -> int:
    from .model.closed_form import MAX_CHECK_SAMPLES, compare_with_pinocchio
    from .model.dh import ArmParams, paper_params
    from .model.dynamics import load_robot
    from .report.dynamics import comparison_lines
    from .validation import check_count, check_positive

    check_positive("--rtol", args.rtol, allow_zero=True)
    check_count("--samples", args.samples, 1, high=MAX_CHECK_SAMPLES)
    check_count("--seed", args.seed)
    _not_a_folder(urdf=args.urdf, params=args.params)
    params = ArmParams.load(args.params) if args.params else paper_params()
    robot = load_robot(args.urdf if args.urdf else params, gravity=params.g)
    result = compare_with_pinocchio(robot, params, samples=args.samples, seed=args.seed)
    print(f"Pinocchio ({args.urdf or 'URDF generated from the parameters'}) vs closed form "
          f"eq. (2)-(7) ({args.params or 'paper Tables 1-2'}), {args.samples} random states, "
          f"seed {args.seed}")
    lines, failed = comparison_lines(result, args.rtol)
    print("\n".join(lines))
    return 1 if failed else 0


# --- design (H-infinity loop shaping, paper section 4) ----------------------------------------

def _add_design(sub) -> None:
    p = sub.add_parser("design", help="H-infinity loop-shaping design of the paper's section 4")
    p.add_argument("--lam", type=float, default=45.0,
                   help="feedback-linearization natural frequency lambda [rad/s] (default 45)")
    p.add_argument("--factor", type=float, default=1.0,
                   help="gamma / gamma_min of ncfsyn, 1 = optimal (default 1.0)")
    p.add_argument("--joints", type=int, default=3,
                   help="size n of the diagonal MIMO plant and controller (default 3)")
    p.add_argument("--order", type=int, default=2, metavar="N",
                   help="states of the reduced controller, eq. (18) (2, the paper's)")
    p.add_argument("--out", metavar="DIR", default=None,
                   help="write fig2.png, fig3.png, fig4a.png, fig4b.png into DIR")
    _add_overwrite(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_design)


def _cmd_design(args) -> int:
    if args.out is not None:  # before the design and its imports: --out /proc/x refused at once
        _claim_out(args, "design")
    from .report.design import design_lines, design_summary
    from .report.jsondata import dumps
    from .robust.loopshaping import design
    from .validation import FieldError

    try:
        d = design(lam=args.lam, n=args.joints, factor=args.factor, order=args.order)
    except FieldError as exc:  # design's lam, n, factor are --lam, --joints, --factor
        raise exc.relabelled(lambda f: "--joints" if f == "n" else _option(f)) from None
    figures = []
    if args.out is not None:
        from .report.plotting import save_design_figures

        figures = [str(f) for f in save_design_figures(d, args.out)]
    if args.json:
        print(dumps({**design_summary(d), **({"figures": figures} if figures else {})}))
        return 0
    print("\n".join(design_lines(d) + [f"wrote {f}" for f in figures]))
    return 0


# --- reproduce (paper section 5, end to end) --------------------------------------------------

def _parse_lock(items) -> dict:
    lock = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ValueError(f"--lock expects JOINT=VALUE, got {item!r}")
        if name in lock:
            raise ValueError(f"--lock {name} given twice")
        try:
            lock[name] = float(value)
        except ValueError:
            raise ValueError(f"--lock {item!r}: {value!r} is not a number") from None
    return lock


def _not_a_folder(**options) -> None:
    """Refuse a folder given where a file is expected (``--urdf DIR``), naming the option."""
    from pathlib import Path

    for field, path in options.items():
        if path is not None and Path(path).is_dir():
            raise ValueError(f"{_option(field)} {path}: is a directory, expected a file")


def _floats(text: str | None, name: str):
    """Comma-separated numbers of an option, or None (their count is checked where used)."""
    if text is None:
        return None
    try:
        return [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        raise ValueError(f"{name} expects numbers separated by commas, got {text!r}") from None


def _add_robot_arguments(p) -> None:
    p.add_argument("--robot", default="rrr", metavar="NAME|PATH",
                   help="arm: 'rrr' (the paper's, default), an example-robot-data name (ur5, "
                        "ur3, ur10, panda, kinova, ...) or a URDF path")
    p.add_argument("--lock", action="append", metavar="JOINT=VALUE",
                   help="lock a joint at a position [rad or m] (repeatable), e.g. the Panda's "
                        "fingers: --lock panda_finger_joint1=0 --lock panda_finger_joint2=0")
    p.add_argument("--home", metavar="Q1,Q2,...", default=None,
                   help="centre of the sinusoid, start of a quintic or task-space motion [rad] "
                        "(default: the URDF's neutral configuration, moved inside the limits; "
                        "for line/circle, bent one joint away from it if the frame is singular "
                        "there)")


def _add_law_arguments(p, default_duration: float, default_rate) -> None:
    from .control.catalog import BUILTIN_LAWS

    p.add_argument("--controllers", default="fl,hinf", metavar="NAMES",
                   help="comma-separated built-in controllers to compare: "
                        + "; ".join(f"{k} = {v}" for k, v in BUILTIN_LAWS.items())
                        + " (default: fl,hinf, the paper's)")
    p.add_argument("--baseline", default=None, metavar="NAME",
                   help="controller the others are compared with (default: the first)")
    p.add_argument("--duration", type=float, default=default_duration,
                   help=f"simulated time [s] ({default_duration:g})")
    p.add_argument("--dt", type=float, default=None,
                   help="RK4 step [s] (1e-3); with --rate the plant sub-step, which must "
                        "divide 1/rate (default: the largest such step up to 1e-3)")
    p.add_argument("--rate", type=float, default=default_rate, metavar="HZ",
                   help="sampled controllers at this rate [Hz] (zero-order hold, Tustin K)"
                        + (f" ({default_rate:g})" if default_rate else
                           "; default: continuous-time laws as in the paper's Simulink study"))
    p.add_argument("--engine", choices=("auto", "python", "compiled", "codegen"),
                   default="auto",
                   help="simulation engine (auto: compiled where the law has a compiled form; "
                        "codegen: generated dynamics of the nominal RRR only, refused for any "
                        "other model, e.g. the uncertain plants: use it with --samples 0)")
    p.add_argument("--q0", metavar="Q1,Q2,...", default=None,
                   help="initial joint positions [rad] (default: on the reference)")
    p.add_argument("--qd0", metavar="V1,V2,...", default=None,
                   help="initial joint velocities [rad/s] (default: on the reference)")
    p.add_argument("--seed", type=int, default=0, help="seed of the uncertain plants (0)")
    p.add_argument("--delay", type=float, default=None, metavar="S",
                   help="plant effect: actuator transport delay [s] (sampled controllers; "
                        "a whole number of plant sub-steps --dt, others are refused)")
    p.add_argument("--actuator-bandwidth", type=float, default=None, metavar="RAD_S",
                   help="plant effect: first-order actuator wa/(s + wa), wa [rad/s] "
                        "(sampled controllers)")
    p.add_argument("--jobs", type=int, default=None,
                   help="worker processes (default: min(2, CPUs))")
    _add_force_argument(p)
    g = p.add_argument_group("reference")
    g.add_argument("--reference", default="sine",
                   choices=("sine", "quintic", "spline", "line", "circle"),
                   help="sine (default): a sinusoid per joint; quintic: rest-to-rest from "
                        "--home to --to; spline: C2 spline through the waypoints of --csv; "
                        "line/circle: a path of --frame in task space, by inverse kinematics")
    g.add_argument("--amp", type=float, default=0.5, help="sine: amplitude [rad] (0.5)")
    g.add_argument("--freq", type=float, default=0.5, help="sine: frequency [Hz] (0.5)")
    g.add_argument("--to", metavar="Q1,Q2,...", default=None, help="quintic: goal [rad]")
    g.add_argument("--move-time", type=float, default=None,
                   help="quintic, line, circle: duration of the motion [s] (default: "
                        "half of --duration)")
    g.add_argument("--csv", metavar="PATH", default=None,
                   help="spline: waypoints, one row each: time [s], then one column per "
                        "joint [rad]")
    g.add_argument("--frame", default=None,
                   help="line, circle: frame whose origin moves (default: the model's last frame)")
    g.add_argument("--end", metavar="X,Y,Z", default=None,
                   help="line: end point [m] (the line starts where the frame is at --home)")
    g.add_argument("--radius", type=float, default=None,
                   help="circle: radius [m]; the circle starts where the frame is at --home")
    g.add_argument("--normal", metavar="X,Y,Z", default="0,0,1",
                   help="circle: normal of its plane (0,0,1)")


def _add_force_argument(p) -> None:
    # The bounds are named, not imported: --help must not load NumPy (rrr_pin.sim does).
    p.add_argument("--force", action="store_true",
                   help="run even above the work bounds of one run (MAX_SUBSTEPS RK4 steps "
                        "and MAX_SAMPLES stored samples of rrr_pin.sim.simulation, 1e7 and "
                        "1e6), refused otherwise before any work")


def _option(field: str) -> str:
    """How the command line spells a settings field: ``move_time`` -> ``--move-time``."""
    return "--" + field.replace("_", "-")


def _reference_from_args(args, robot):
    from .control.specs import ReferenceSpec

    def values(text, name):
        v = _floats(text, name)
        return None if v is None else tuple(v)

    spec = ReferenceSpec(kind=args.reference, amp=args.amp, freq=args.freq,
                         home=values(args.home, "--home"), to=values(args.to, "--to"),
                         move_time=args.move_time, csv=args.csv, frame=args.frame,
                         end=values(args.end, "--end"), radius=args.radius,
                         normal=values(args.normal, "--normal"))
    return spec.build(robot, args.duration, label=_option)


@contextmanager
def _as_options():
    """Name a settings field as its option (``move_time`` -> ``--move-time``) in an error."""
    from .validation import FieldError

    try:
        yield
    except FieldError as exc:
        raise exc.relabelled(_option) from None


def _settings_from_args(args, n: int):
    from .campaign.runner import RunSettings
    from .control.effects import PlantEffects
    from .validation import check_count, check_positive, check_vector

    if args.jobs is not None:
        check_count("--jobs", args.jobs, 1)
    check_count("--seed", args.seed)
    for name in ("delay", "actuator_bandwidth"):
        if getattr(args, name) is not None:
            check_positive(_option(name), getattr(args, name), allow_zero=name == "delay")
    effects = None
    if args.delay or args.actuator_bandwidth is not None:
        if args.rate is None:
            raise ValueError("--delay and --actuator-bandwidth act on sampled controllers: "
                             "give --rate HZ too")
        with _as_options():
            effects = PlantEffects(delay=args.delay or 0.0, bandwidth=args.actuator_bandwidth)
    q0, qd0 = (None if text is None else tuple(check_vector(name, _floats(text, name), n))
               for text, name in ((args.q0, "--q0"), (args.qd0, "--qd0")))
    with _as_options():
        return RunSettings(duration=args.duration, dt=args.dt, rate=args.rate,
                           engine=args.engine, q0=q0, qd0=qd0, effects=effects,
                           force=args.force)


def _laws_from_args(args, robot, K=None):
    from .campaign.runner import make_laws

    laws = make_laws(args.controllers, robot, K=K)
    baseline = args.baseline or laws[0].name
    if baseline not in [law.name for law in laws]:
        raise ValueError(f"--baseline {baseline!r} is not among --controllers "
                         f"({args.controllers})")
    return laws, baseline


def _add_reproduce(sub) -> None:
    p = sub.add_parser(
        "reproduce", help="the paper end to end: design, nominal and uncertain studies, figures",
        description="Runs the loop-shaping design (section 4) and the closed-loop study "
                    "(section 5): every --controllers law on the nominal arm and on uncertain "
                    "plants, and writes fig2-fig4b, fig5_nominal, fig6_uncertain, "
                    "plants/*.urdf, results.json and results.md into --out.")
    _add_robot_arguments(p)
    _add_law_arguments(p, 4.0, None)
    p.add_argument("--samples", type=int, default=10, help="uncertain plants (10, the paper's)")
    p.add_argument("--no-certify", action="store_true",
                   help="skip the frozen-configuration nu-gap certificate of each uncertain "
                        "plant (about 0.3 s per plant)")
    p.add_argument("--full-order", action="store_true",
                   help="use the full-order K instead of the reduced eq. (18)")
    p.add_argument("--out", default="results", metavar="DIR", help="output folder (results/)")
    _add_overwrite(p)
    p.add_argument("--save-trajectories", nargs="?", const="npz", default=None,
                   choices=("npz", "csv", "parquet"), metavar="FORMAT",
                   help="also write every run's time series (t, q, qd, r, tau with units) as "
                        "DIR/trajectories/<nominal|sampleNNN>_<controller>.FORMAT; FORMAT npz "
                        "(default), csv or parquet; read with Trajectory.load")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_reproduce)


def _cmd_reproduce(args) -> int:
    from tqdm import tqdm

    from .campaign.study import StudyConfig, check_study_size, run_study
    from .model.dynamics import load_robot
    from .report.design import study_design
    from .report.plotting import save_design_figures, save_study_figures
    from .report.results import summary_lines, write_results, write_study_report, write_trajectories
    from .robust.certificates import CertificateSpec
    from .robust.loopshaping import design
    from .validation import check_count

    out = _check_out_early(args, "reproduce")  # a file, no permission, another tool's run
    check_count("--samples", args.samples)
    lock = _parse_lock(args.lock)
    _not_a_folder(robot=args.robot, csv=args.csv)
    robot = load_robot(args.robot, lock=lock)
    settings = _settings_from_args(args, robot.nq)
    reference = _reference_from_args(args, robot)
    if out is None:  # --overwrite: the previous run is removed now that the options hold
        out = _claim_out(args, "reproduce")
    d = design(lam=45.0, n=robot.nq)
    laws, baseline = _laws_from_args(args, robot, K=d.K_full if args.full_order else
                                     d.K_reduced)
    config = StudyConfig(run=settings, samples=args.samples, seed=args.seed, jobs=args.jobs,
                         baseline=baseline)
    check_study_size(config, len(laws), robot.nq)  # before the design figures are written
    figures = save_design_figures(d, out)
    bar = tqdm(total=args.samples + 1, unit="plant", desc=f"{robot.name}: simulating",
               disable=args.no_progress)
    certificate = None if args.no_certify else CertificateSpec.from_design(
        d, reduced=not args.full_order)
    try:
        result = run_study(robot, laws, config=config, reference=reference,
                           skip_joints=tuple(lock), certificate=certificate,
                           progress=lambda done, total: bar.update(done - bar.n))
    finally:  # on Ctrl-C too, so the interrupt message starts on a line of its own
        bar.close()
    design_info = study_design(d, full_order=args.full_order)
    data = write_results(result, out, design=design_info)
    figures += save_study_figures(result, out)
    report = write_study_report(result, out, figures, design_info, robot, data=data)
    saved = write_trajectories(result, out, args.save_trajectories)  # None: clears old ones
    print(f"{robot.name}: {robot.nq} joints, gamma = {d.ncf.gamma:.4f}, controllers "
          f"{', '.join(result.names)} (baseline {baseline})")
    print("\n".join(summary_lines(result, data["summary"])))
    print(f"wrote {out}/results.json, results.md, plants/, {len(figures)} figures and "
          f"{report.name} (open it in a browser)")
    if saved:
        print(f"wrote {len(saved)} trajectories to {out}/trajectories/ "
              f"({args.save_trajectories})")
    return 0


# --- montecarlo (robustness campaign) ---------------------------------------------------------

def _add_montecarlo(sub) -> None:
    p = sub.add_parser(
        "montecarlo", help="Monte Carlo campaign: N seeded uncertain plants, any controllers",
        description="Draws N seeded uncertain plants (20 % inertia, 5 % lengths), simulates "
                    "every --controllers law on each (sampled controllers, 1 kHz by default) "
                    "and writes campaign.csv, samples.jsonl, summary.json and montecarlo.png "
                    "into --out. Results are identical whatever --jobs.")
    _add_robot_arguments(p)
    _add_law_arguments(p, 10.0, 1000.0)
    p.add_argument("--samples", type=int, required=True, help="number of uncertain plants")
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
    p.set_defaults(func=_cmd_montecarlo)


def _cmd_montecarlo(args) -> int:
    import time

    from tqdm import tqdm

    from .campaign.executors import CampaignInterrupted, WorkersLost, exit_status
    from .campaign.montecarlo import CampaignSettings, open_store, run_campaign
    from .model.dynamics import load_robot
    from .outputs import check_writable
    from .report.campaign import summary_lines, write_campaign, write_campaign_report
    from .validation import check_count

    check_count("--samples", args.samples, 1)
    check_writable(args.out)
    args.write_hint = (f"; the samples finished so far are kept in {args.out}/parts.jsonl: "
                       "free space, then rerun with --resume")
    lock = _parse_lock(args.lock)
    _not_a_folder(robot=args.robot, csv=args.csv)
    robot = load_robot(args.robot, lock=lock)
    run = _settings_from_args(args, robot.nq)
    reference = _reference_from_args(args, robot)
    certificate = K = None
    if args.certify:  # one design serves the certificate and the H-infinity law
        from .robust.certificates import CertificateSpec
        from .robust.loopshaping import design

        d = design(lam=45.0, n=robot.nq)
        certificate, K = CertificateSpec.from_design(d), d.K_reduced
    laws, baseline = _laws_from_args(args, robot, K=K)
    settings = CampaignSettings(samples=args.samples, seed=args.seed, run=run,
                                baseline=baseline)
    store = open_store(args.out, robot, laws, settings, reference, resume=args.resume,
                       overwrite=args.overwrite, certificate=certificate)
    with store:
        done = len(store.done())
        if done:
            print(f"resuming: {done} of {args.samples} samples already done in {args.out}")
        bar = tqdm(total=args.samples, initial=done, unit="plant",
                   desc=f"{robot.name}: Monte Carlo", disable=args.no_progress)
        start = time.perf_counter()
        try:
            campaign = run_campaign(robot, laws, settings, reference=reference, jobs=args.jobs,
                                    scheduler=args.scheduler, skip_joints=tuple(lock),
                                    progress=lambda d, total: bar.update(d - bar.n),
                                    store=store, certificate=certificate)
        except CampaignInterrupted as exc:
            bar.close()
            print(f"rrr-pin montecarlo: {exc}", file=sys.stderr)
            # 3: workers lost; else 128 + the signal (130 SIGINT, 143 SIGTERM), as a shell does.
            return 3 if isinstance(exc, WorkersLost) else exit_status(exc)
        bar.close()
        elapsed = time.perf_counter() - start
        s = write_campaign(campaign, args.out, store=store, certificate_b=None if
                           certificate is None else certificate.margin(robot.nq))
        s["written"].append(str(write_campaign_report(campaign, s, args.out, store)))
    nl, ran = len(laws), s["samples"] - done
    print(f"{robot.name}: {ran} plants x {nl} controllers x {run.duration:g} s in "
          f"{elapsed:.1f} s ({nl * ran / max(elapsed, 1e-9):.1f} rollouts/s)")
    print("\n".join(summary_lines(campaign, s)))
    print("wrote " + ", ".join(s["written"]))
    return 0


# --- stress (unmodeled dynamics: breaking points) ---------------------------------------------

def _add_stress(sub) -> None:
    from .control.catalog import DEFAULT_BUDGET, EFFECTS

    p = sub.add_parser(
        "stress", help="where each controller breaks under an unmodeled effect",
        description="For each --controllers law and the --effect, the breaking point of the "
                    "nonlinear closed loop (bisection on the effect's size: the run diverges "
                    "or its RMS tracking error exceeds --budget), the linear prediction of the "
                    "design's digital loop, and what the robust-stability barrier of eq. "
                    "(12)-(13) guarantees. Writes stress_<effect>.png (and .json) into --out.")
    _add_robot_arguments(p)
    p.add_argument("--controllers", default="fl,hinf,pd", metavar="NAMES",
                   help="comma-separated built-in controllers (fl,hinf,pd)")
    p.add_argument("--effect", required=True, metavar="NAME",
                   help="; ".join(f"{k}: {v.what} [{v.unit}]" for k, v in EFFECTS.items()))
    p.add_argument("--budget", type=float, default=DEFAULT_BUDGET,
                   help=f"RMS tracking error [rad] above which a run is broken "
                        f"({DEFAULT_BUDGET:g})")
    p.add_argument("--duration", type=float, default=2.0,
                   help="shortest simulated time per run [s] (2; slow loops run longer)")
    p.add_argument("--rate", type=float, default=1000.0, metavar="HZ",
                   help="sampling rate of the controllers [Hz] (1000)")
    p.add_argument("--dt", type=float, default=None,
                   help="plant RK4 sub-step [s], which must divide 1/rate; also the grid the "
                        "delay is searched on (default: the largest such step up to 1e-4)")
    p.add_argument("--engine", choices=("auto", "python", "compiled"), default="auto",
                   help="simulation engine (auto)")
    _add_force_argument(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--out", default="results/stress", metavar="DIR",
                   help="folder for the figure and the JSON (results/stress)")
    _add_overwrite(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_stress)


def _cmd_stress(args) -> int:
    import time

    from tqdm import tqdm

    from .campaign.runner import RunSettings, make_laws
    from .campaign.stress import StressSettings, stress
    from .control.catalog import EFFECTS
    from .control.specs import ReferenceSpec
    from .model.dynamics import load_robot
    from .report.jsondata import dumps
    from .report.stress import stress_lines, write_stress

    if args.effect not in EFFECTS:
        raise ValueError(f"--effect {args.effect!r} is unknown; known effects: "
                         f"{', '.join(EFFECTS)}")
    from .sim.simulation import largest_substep
    from .validation import check_rate

    rate = check_rate("--rate", args.rate)
    with _as_options():
        dt = args.dt if args.dt is not None else largest_substep(rate, 1e-4)
        settings = StressSettings(run=RunSettings(duration=args.duration, dt=dt,
                                                  rate=rate, engine=args.engine,
                                                  force=args.force),
                                  budget=args.budget)
    _claim_out(args, "stress", part=args.effect)  # one folder holds every effect's run
    _not_a_folder(robot=args.robot)
    robot = load_robot(args.robot, lock=_parse_lock(args.lock))
    home = _floats(args.home, "--home")
    reference = ReferenceSpec(home=None if home is None else tuple(home)).build(
        robot, args.duration, label=_option)
    laws = make_laws(args.controllers, robot)
    start = time.perf_counter()
    bar = tqdm(total=len(laws), unit="law", desc=f"{robot.name}: stress {args.effect}",
               disable=args.no_progress)
    result = stress(robot, laws, reference, args.effect, settings,
                    progress=lambda done, total: bar.update(done - bar.n))
    bar.close()
    result["elapsed_s"] = time.perf_counter() - start
    result["robot"] = robot.name
    fig = write_stress(result, args.out)
    if args.json:
        print(dumps(result))
        return 0
    print("\n".join(stress_lines(result) + [f"wrote {fig}"]))
    return 0


# --- export (the law as C code) ---------------------------------------------------------------

def _add_export(sub) -> None:
    from .control.catalog import BUILTIN_LAWS

    p = sub.add_parser(
        "export", help="write a built-in controller as C code for a real-time loop",
        description="Writes --law on --robot, sampled at --rate, into --out: controller.h/.c "
                    "(C99, ctrl_reset/ctrl_step), the model's dynamics (generated C for the "
                    "nominal RRR, Pinocchio C++ otherwise), CMakeLists.txt, main.c, "
                    "ros2_controller.hpp and controller.json. Build with cmake -S DIR -B "
                    "DIR/build && cmake --build DIR/build.")
    p.add_argument("--robot", default="rrr", metavar="NAME|PATH",
                   help="arm: 'rrr' (default), an example-robot-data name (ur5, ...) or a URDF "
                        "path")
    p.add_argument("--lock", action="append", metavar="JOINT=VALUE",
                   help="lock a joint at a position [rad or m] (repeatable)")
    p.add_argument("--law", default="hinf", metavar="NAME",
                   help="built-in controller: " + "; ".join(
                       f"{k} = {v}" for k, v in BUILTIN_LAWS.items()) + " (default: hinf)")
    p.add_argument("--rate", type=float, default=None, metavar="HZ",
                   help="sampling rate of the exported code [Hz] (required: the built-in "
                        "laws are continuous-time)")
    p.add_argument("--method", default="tustin",
                   help="discretization of the H-infinity K (tustin; any method of "
                        "control.sample_system)")
    p.add_argument("--prewarp", type=float, default=None, metavar="RAD_S",
                   help="Tustin prewarp frequency [rad/s], below pi * rate")
    p.add_argument("--full-order", action="store_true",
                   help="hinf: the full-order K instead of the reduced eq. (18)")
    p.add_argument("--out", default="controller", metavar="DIR",
                   help="output folder (controller/)")
    _add_overwrite(p)
    p.set_defaults(func=_cmd_export)


def _cmd_export(args) -> int:
    from .control.catalog import LAWS, make_law
    from .deploy.writer import prepare_export
    from .model.dynamics import load_robot

    out = _check_out_early(args, "export")  # a file, no permission, another tool's run
    if args.law not in LAWS:
        raise ValueError(f"--law {args.law!r} is not a built-in controller ({', '.join(LAWS)})")
    _not_a_folder(robot=args.robot)
    robot = load_robot(args.robot, lock=_parse_lock(args.lock))
    d, law = None, args.law
    if args.law == "hinf":
        from .robust.loopshaping import design

        d = design(lam=45.0, n=robot.nq)
        law = make_law("hinf", robot, K=d.K_full if args.full_order else d.K_reduced)
    else:
        law = make_law(args.law, robot)
    with _as_options():
        prepared = prepare_export(law, robot, args.rate, method=args.method,
                                  prewarp=args.prewarp, design=d)
    if out is None:  # --overwrite: the previous export is removed now that the options hold
        out = _claim_out(args, "export")
    prepared.write(out)
    print(f"{robot.name}: {prepared.law.name} ({prepared.form.kind}, {prepared.law.nx} states) "
          f"at {prepared.rate:g} Hz, {prepared.dynamics} dynamics")
    print(f"wrote {out}/: {', '.join(prepared.files)}")
    print(f"build: cmake -S {out} -B {out}/build && cmake --build {out}/build && "
          f"{out}/build/ctrl_main")
    return 0


if __name__ == "__main__":
    sys.exit(main())

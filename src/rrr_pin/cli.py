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
    for add in (_add_urdf, _add_mjcf, _add_check_dynamics, _add_design, _add_reproduce,
                _add_montecarlo, _add_stress, _add_identify, _add_margins, _add_robstab,
                _add_export):
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


# --- mjcf ---------------------------------------------------------------------------------

def _add_mjcf(sub) -> None:
    p = sub.add_parser("mjcf", help="write (or check) the MJCF of a parallel mechanism (5-bar, "
                       "Delta) generated from its parameter set")
    p.add_argument("mechanism", choices=("fivebar", "delta"))
    p.add_argument("--out", metavar="PATH", default=None,
                   help="where to write it (default: standard output; with --check, the "
                        "committed mjcf/MECHANISM.xml)")
    p.add_argument("--check", action="store_true",
                   help="do not write: exit 1 if PATH differs from what the generator writes")
    p.set_defaults(func=_cmd_mjcf)


def _cmd_mjcf(args) -> int:
    from .model.mechanisms import check_mjcf, mechanism_params, mjcf_from_params, write_mjcf

    params = mechanism_params(args.mechanism)
    if args.check:
        out = args.out or f"mjcf/{args.mechanism}.xml"
        if check_mjcf(out, params):
            print(f"{out}: up to date")
            return 0
        print(f"{out}: missing or differs from the generator's output; regenerate with "
              f"`rrr-pin mjcf {args.mechanism} --out {out}`")
        return 1
    if args.out in (None, "-"):
        sys.stdout.write(mjcf_from_params(params))
        return 0
    print(f"wrote {write_mjcf(args.out, params)}")
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
    _refuse_closed_chain(args.urdf, "check-dynamics",
                         "it compares a serial arm with the RRR's closed form eq. (2)-(7)",
                         option="--urdf")
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
                   help="write fig2.png, fig3.png, fig4a.png, fig4b.png and margins.png (the "
                        "loop G K: singular values, Bode phase, Nyquist) into DIR")
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
        from .report.margins import save_margins_figure

        # the design's own loop, G K (eq. 11 plant, eq. 18 controller): margins.png
        figures.append(str(save_margins_figure({"G K": _control_ss(d.G * d.K)}, args.out)))
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


def _refuse_closed_chain(source, command: str, reason: str, option: str = "--robot") -> None:
    """Refuse a parallel mechanism (``fivebar``, ``delta``, an MJCF ``.xml``) by name."""
    from .model.closed_chain import is_closed_chain_source

    if source is not None and is_closed_chain_source(source):
        raise ValueError(f"{option} {source}: a closed chain (parallel mechanism); {command} "
                         f"does not implement closed chains: {reason}")


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
                   help="simulation engine (auto: compiled where the law has a compiled form, "
                        "and for many plants the batched generated dynamics where the arm's "
                        "structure has them; codegen: generated dynamics with the plant's "
                        "parameters as inputs (RRR, UR5, Panda structures), refused for any "
                        "other structure)")
    p.add_argument("--q0", metavar="Q1,Q2,...", default=None,
                   help="initial joint positions [rad] (default: on the reference)")
    p.add_argument("--qd0", metavar="V1,V2,...", default=None,
                   help="initial joint velocities [rad/s] (default: on the reference)")
    p.add_argument("--seed", type=int, default=0, help="seed of the uncertain plants (0)")
    p.add_argument("--uncertainty", metavar="IDENTIFICATION.json", default=None,
                   help="draw the uncertain plants from an identification (rrr-pin identify) "
                        "instead of the paper's 20 %% inertia / 5 %% length tolerances; use "
                        "--robot DIR/identified.urdf as the nominal")
    p.add_argument("--confidence", type=float, default=0.95,
                   help="with --uncertainty: confidence region the plants are drawn in (0.95)")
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


def _tolerances_from_args(args, robot):
    """Return the paper's tolerances, or ``--uncertainty``'s identified distribution."""
    from .model.uncertainty import Tolerances

    if args.uncertainty is None:
        return Tolerances()
    from .model.identification import IdentifiedUncertainty

    _not_a_folder(uncertainty=args.uncertainty)
    with _as_options():
        tol = IdentifiedUncertainty(args.uncertainty, confidence=args.confidence)
    tol.check_robot(robot)
    return tol


def _rejections_line(entries) -> str | None:
    """How many draws of an identified distribution were rejected, or None (tolerances)."""
    drawn = [e["parameters"]["identified"]["rejected"] for e in entries
             if "identified" in (e.get("parameters") or {})]
    if not drawn:
        return None
    outside = sum(d["outside_confidence"] for d in drawn)
    inconsistent = sum(d["inconsistent"] for d in drawn)
    return (f"identified uncertainty: {len(drawn)} plants drawn; rejected and redrawn: "
            f"{outside} outside the confidence region, {inconsistent} with no physically "
            f"consistent arm")


def _laws_from_args(args, robot, K=None, torque_limit=None, extra=()):
    from .campaign.runner import make_laws

    names = [s.strip() for s in args.controllers.split(",")]
    names += [name for name in extra if name not in names]
    laws = make_laws(names, robot, K=K, torque_limit=torque_limit)
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
    p.add_argument("--torque-limit", default=None, metavar="auto|P%|T1,T2,...",
                   help="run the study under actuator limits |tau_j| <= T_j [N m] (sampled "
                        "controllers: give --rate too), with hinf_aw added to --controllers "
                        "and told the limits: auto = the URDF's effort limits; P%% = P percent "
                        "of the peak torque the reference asks of the nominal arm, per joint "
                        "(its inverse dynamics over the control instants); or one number per "
                        "joint. results.json records the limits used (summary.torque_limit)")
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
    if args.robot in ("fivebar", "delta"):
        return _reproduce_chain(args, out)
    if args.robot.lower().endswith(".xml"):
        raise ValueError(f"--robot {args.robot}: an MJCF closed chain; the closed-chain study "
                         f"runs the built-in fivebar and delta only (load your MJCF with "
                         f"rrr_pin.load_robot and simulate it from Python)")
    lock = _parse_lock(args.lock)
    _not_a_folder(robot=args.robot, csv=args.csv)
    robot = load_robot(args.robot, lock=lock)
    settings = _settings_from_args(args, robot.nq)
    reference = _reference_from_args(args, robot)
    limit, limit_info = None, {}
    if args.torque_limit is not None:
        limit, limit_info = _torque_limit_from_args(args.torque_limit, robot, reference,
                                                    settings.rate, settings.duration)
        import dataclasses

        from .control.effects import PlantEffects

        effects = dataclasses.replace(settings.effects or PlantEffects(),
                                      torque_limit=tuple(limit.tolist()))
        settings = dataclasses.replace(settings, effects=effects)
    tolerances = _tolerances_from_args(args, robot)
    if out is None:  # --overwrite: the previous run is removed now that the options hold
        out = _claim_out(args, "reproduce")
    d = design(lam=45.0, n=robot.nq)
    laws, baseline = _laws_from_args(args, robot, K=d.K_full if args.full_order else
                                     d.K_reduced, torque_limit=limit,
                                     extra=("hinf_aw",) if limit is not None else ())
    config = StudyConfig(run=settings, samples=args.samples, seed=args.seed, jobs=args.jobs,
                         baseline=baseline, tolerances=tolerances)
    check_study_size(config, len(laws), robot.nq)  # before the design figures are written
    figures = save_design_figures(d, out)
    from .report.margins import save_margins_figure

    figures.append(save_margins_figure({"G K": _control_ss(d.G * d.K)}, out))
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
    result.torque_limit = limit_info
    design_info = study_design(d, full_order=args.full_order)
    data = write_results(result, out, design=design_info)
    figures += save_study_figures(result, out)
    report = write_study_report(result, out, figures, design_info, robot, data=data)
    saved = write_trajectories(result, out, args.save_trajectories)  # None: clears old ones
    print(f"{robot.name}: {robot.nq} joints, gamma = {d.ncf.gamma:.4f}, controllers "
          f"{', '.join(result.names)} (baseline {baseline})")
    print("\n".join(summary_lines(result, data["summary"])))
    if _rejections_line(result.samples):
        print(_rejections_line(result.samples))
    print(f"wrote {out}/results.json, results.md, plants/, {len(figures)} figures and "
          f"{report.name} (open it in a browser)")
    if saved:
        print(f"wrote {len(saved)} trajectories to {out}/trajectories/ "
              f"({args.save_trajectories})")
    return 0


def _torque_limit_from_args(text: str, robot, reference, rate, duration):
    """Return the limits [N m] of ``--torque-limit`` (shape (n,)) and how they were chosen.

    ``auto``: the URDF's effort limits (refused for a closed chain: an MJCF motor carries
    none); ``P%``: P percent of the peak inverse-dynamics torque of the reference on the nominal
    arm (a closed chain: its reduced model) per joint, over the control instants of a run of
    ``duration`` [s] at ``rate`` [Hz]; or numbers. Each is checked (finite, > 0, one per joint,
    not below the gravity torque at the reference's start) as ``--torque-limit``.
    """
    import numpy as np

    from .control.effects import check_torque_limit, peak_torque
    from .validation import FieldError

    name = "--torque-limit"
    chain = hasattr(robot, "constraints")
    if rate is None:
        raise ValueError(f"{name} acts on sampled controllers (the plant clips the torque each "
                         f"control period): give --rate HZ too, e.g. --rate 1000")
    text = text.strip()
    if text == "auto":
        if chain:
            raise FieldError(name, f"{{name}} auto reads a URDF's effort limits, and the MJCF "
                                   f"motors of {robot.name!r} have none: give P% (percent of "
                                   f"the reference's peak torque) or one number per actuated "
                                   f"joint [N m]")
        info = {"spec": "auto", "rule": "the URDF's effort limits"}
        return check_torque_limit(robot, "urdf", reference, name=name), info
    if text.endswith("%"):
        try:
            percent = float(text[:-1])
        except ValueError:
            raise FieldError(name, f"{{name}} {text!r}: expected {'' if chain else 'auto, '}P% "
                                   f"(a number P > 0, percent of the peak torque) or one "
                                   f"number per joint [N m]") from None
        if not (np.isfinite(percent) and percent > 0):
            raise FieldError(name, f"{{name}} {text!r}: the percent must be finite and > 0")
        n_steps = round(duration * rate)
        peak = peak_torque(robot, reference, np.arange(n_steps + 1) / rate)
        limit = check_torque_limit(robot, percent / 100.0 * peak, reference, name=name)
        rule = (f"{percent:g} % of the peak |M_r(r) rdd + V_r(r, rd) + G_r(r)| per actuated "
                f"joint of the reference on the nominal mechanism, over the control instants"
                if chain else
                f"{percent:g} % of the peak |M(r) rdd + V(r, rd) + G(r)| per joint of the "
                f"reference on the nominal arm, over the control instants")
        info = {"spec": text, "percent": percent, "peak_torque_Nm": peak.tolist(),
                **({"limit_Nm": limit.tolist()} if chain else {}), "rule": rule}
        return limit, info
    values = _floats(text, name)
    info = {"spec": text, "rule": "given"}
    return check_torque_limit(robot, values, reference, name=name), info


def _chain_controllers(text: str, limited: bool = False) -> tuple:
    """Return the built-in names of a closed-chain study's ``--controllers``, checked.

    ``limited`` (``--torque-limit`` given): ``hinf_aw`` is allowed, and added if absent (as the
    serial reproduce does).
    """
    from .control.catalog import BUILTIN_LAWS
    from .control.closed_chain import CHAIN_LAWS

    names = tuple(s.strip() for s in text.split(","))
    if not names or any(not s for s in names):
        raise ValueError(f"--controllers: expected comma-separated names from "
                         f"{', '.join(CHAIN_LAWS)}, got {text!r}")
    dup = sorted({x for x in names if names.count(x) > 1})
    if dup:
        raise ValueError(f"--controllers: repeated {', '.join(dup)}")
    for name in names:
        if name == "hinf_aw" and not limited:
            raise ValueError("--controllers hinf_aw: on a closed chain the law must be told "
                             "the torque limits (an MJCF motor has none): give "
                             "--torque-limit P% or T1,T2,... [N m]")
        if name not in CHAIN_LAWS:
            known = ", ".join(f"{k} ({BUILTIN_LAWS[k]})" for k in CHAIN_LAWS if k in
                              BUILTIN_LAWS and k != "hinf_aw")
            raise ValueError(f"--controllers {name!r}: not a built-in controller with a "
                             f"closed-chain form; closed chains run {known}")
    return names + (("hinf_aw",) if limited and "hinf_aw" not in names else ())


def _reproduce_chain(args, out) -> int:
    """``reproduce --robot fivebar|delta``: the study on a parallel mechanism."""
    from .campaign.closed_chain_study import ChainStudyConfig, run_chain_study
    from .report.closed_chain import write_chain_study

    reference_options = (("--amp", args.amp != 0.5), ("--freq", args.freq != 0.5),
                         ("--to", args.to), ("--move-time", args.move_time),
                         ("--frame", args.frame), ("--end", args.end),
                         ("--radius", args.radius), ("--normal", args.normal != "0,0,1"))
    unsupported = [opt for opt, given in (
        ("--lock", args.lock), ("--csv", getattr(args, "csv", None)),
        ("--engine codegen", args.engine == "codegen"),
        ("--delay", args.delay), ("--actuator-bandwidth", args.actuator_bandwidth),
        ("--q0", args.q0), ("--qd0", args.qd0), ("--home", args.home),
        ("--save-trajectories", args.save_trajectories),
        ("--baseline", args.baseline),
        ("--uncertainty", args.uncertainty), ("--confidence", args.confidence != 0.95),
        ("--dt", args.dt),
        ("--reference other than sine", args.reference != "sine"),
        *reference_options) if given]
    if unsupported:
        raise ValueError(f"--robot {args.robot} (a closed chain) does not implement "
                         f"{', '.join(unsupported)}; its study runs --controllers on the "
                         f"mechanism's own reference, engine auto (the compiled chain "
                         f"engine for fl and hinf)")
    limit, limit_info = None, {}
    if args.torque_limit is not None:
        from .campaign.closed_chain_study import chain_reference
        from .model.closed_chain import load_closed_chain

        chain = load_closed_chain(args.robot)
        limit, limit_info = _torque_limit_from_args(args.torque_limit, chain,
                                                    chain_reference(chain, args.duration),
                                                    args.rate, args.duration)
        limit_info.setdefault("limit_Nm", limit.tolist())  # the study records the limit used
    config = ChainStudyConfig(mechanism=args.robot, samples=args.samples, seed=args.seed,
                              duration=args.duration, rate=args.rate,
                              controllers=_chain_controllers(args.controllers,
                                                             limited=limit is not None),
                              full_order=args.full_order, certify=not args.no_certify,
                              engine=args.engine,
                              torque_limit=None if limit is None else tuple(limit))
    if out is None:
        out = _claim_out(args, "reproduce")
    result = run_chain_study(config, progress=None if args.no_progress else
                             lambda done, total: print(f"{args.robot}: plant {done}/{total}",
                                                       file=sys.stderr))
    result.torque_limit = limit_info
    from .model.mechanisms import mechanism_params

    paths = write_chain_study(result, out, params=mechanism_params(args.robot))
    for c in result.claims:
        verdict = "undetermined" if c["holds"] is None else ("holds" if c["holds"] else
                                                              "does not hold")
        print(f"{c['claim']}: {c['value']:.4g} -> {verdict}")
    if result.claims_note:
        print(result.claims_note)
    summary = result.summary()
    for name, s in summary["laws"].items():
        line = f"{name}: nominal RMS error {s['nominal_rms_error_rad']:.3g} rad"
        if config.samples:
            line += (f", uncertain mean RMS error {s['mean_rms_error_rad']:.3g} rad, mean RMS "
                     f"torque {s['mean_rms_tau_Nm']:.4g} N m"
                     + (f", {s['failed']} run(s) failed" if s["failed"] else ""))
        if limit is not None:
            line += (f"; saturated fraction nominal {s['nominal_saturated_fraction']:.3g}"
                     + (f", uncertain mean {s['mean_saturated_fraction']:.3g}"
                        if config.samples else ""))
        status = result.metrics[0][name]["status"]
        if status != "ok":
            line += f"; nominal run {status}"
        print(line)
    if limit is not None:
        print(f"torque limit {limit_info['spec']} ({limit_info['rule']}): "
              f"{', '.join(f'{v:.4g}' for v in limit)} N m")
    cert = summary.get("certificates")
    if cert:
        print(f"certified (frozen nu-gap < b = {cert['b']:.4g}): {cert['certified']}/"
              f"{cert['checked']} uncertain plants, largest nu-gap {cert['nugap_max']:.4g}")
    engines = sorted({tr.info["engine"] for runs in result.trajectories
                      for tr in runs.values() if tr is not None})
    print(f"wrote {', '.join(p.name for p in paths)} into {out} (engine: "
          f"{', '.join(engines) or 'none'})")
    return 0


# --- montecarlo (robustness campaign) ---------------------------------------------------------

def _add_montecarlo(sub) -> None:
    p = sub.add_parser(
        "montecarlo", help="Monte Carlo campaign: N seeded uncertain plants, any controllers",
        description="Draws N seeded uncertain plants (20 % inertia, 5 % lengths), simulates "
                    "every --controllers law on each (sampled controllers, 1 kHz by default) "
                    "and writes campaign.csv, samples.jsonl, summary.json and montecarlo.png "
                    "into --out. Results are identical whatever --jobs. With --robot fivebar "
                    "or delta (parallel mechanisms): the --controllers on the nominal and N "
                    "perturbed mechanisms (masses 20 %, lengths 5 %), on the constraint "
                    "dynamics, along the mechanism's own reference (its period --duration), "
                    "with each run's loop drift and status.")
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
    if args.robot in ("fivebar", "delta") or args.robot.lower().endswith(".xml"):
        return _montecarlo_chain(args)
    lock = _parse_lock(args.lock)
    _not_a_folder(robot=args.robot, csv=args.csv)
    robot = load_robot(args.robot, lock=lock)
    run = _settings_from_args(args, robot.nq)
    reference = _reference_from_args(args, robot)
    tolerances = _tolerances_from_args(args, robot)
    certificate = K = None
    if args.certify:  # one design serves the certificate and the H-infinity law
        from .robust.certificates import CertificateSpec
        from .robust.loopshaping import design

        d = design(lam=45.0, n=robot.nq)
        certificate, K = CertificateSpec.from_design(d), d.K_reduced
    laws, baseline = _laws_from_args(args, robot, K=K)
    settings = CampaignSettings(samples=args.samples, seed=args.seed, run=run,
                                baseline=baseline, tolerances=tolerances)
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
    if _rejections_line(campaign.rows):
        print(_rejections_line(campaign.rows))
    print("wrote " + ", ".join(s["written"]))
    return 0


def _montecarlo_chain(args) -> int:
    """``montecarlo --robot fivebar|delta``: the campaign on a parallel mechanism."""
    import time

    from tqdm import tqdm

    from .campaign.closed_chain_campaign import chain_laws, open_chain_store, run_chain_campaign
    from .campaign.executors import CampaignInterrupted, WorkersLost, exit_status
    from .campaign.montecarlo import CampaignSettings
    from .model.closed_chain import load_closed_chain
    from .model.uncertainty import MechanismTolerances
    from .report.campaign import summary_lines, write_campaign, write_campaign_report

    if args.robot.lower().endswith(".xml"):
        raise ValueError(f"--robot {args.robot}: an MJCF closed chain; the closed-chain "
                         f"campaign runs the built-in fivebar and delta only (it perturbs their "
                         f"parameter sets; from Python, run_chain_campaign takes "
                         f"load_closed_chain(FiveBarParams(...)))")
    defaults = {"amp": 0.5, "freq": 0.5, "normal": "0,0,1"}
    unsupported = [opt for opt, given in (
        ("--lock", args.lock), ("--home", args.home),
        ("--engine codegen", args.engine == "codegen"),
        ("--delay/--actuator-bandwidth with --engine compiled (no plant effects there)",
         args.engine == "compiled" and (args.delay or args.actuator_bandwidth is not None)),
        ("--q0", args.q0), ("--qd0", args.qd0), ("--uncertainty", args.uncertainty),
        ("--certify", args.certify),
        ("--reference other than sine", args.reference != "sine"),
        *((_option(k), getattr(args, k) != defaults.get(k))
          for k in ("amp", "freq", "to", "move_time", "csv", "frame", "end", "radius",
                    "normal"))) if given]
    if unsupported:
        raise ValueError(f"--robot {args.robot} (a closed chain) does not implement "
                         f"{', '.join(unsupported)}; its campaign runs the built-in laws on the "
                         f"mechanism's own reference (that of `rrr-pin reproduce --robot "
                         f"{args.robot}`), Python engine on the constraint dynamics")
    chain = load_closed_chain(args.robot)
    run = _settings_from_args(args, chain.nq)
    with _as_options():
        laws = chain_laws(args.controllers, chain)
    baseline = args.baseline or laws[0].name
    if baseline not in [law.name for law in laws]:
        raise ValueError(f"--baseline {baseline!r} is not among --controllers "
                         f"({args.controllers})")
    settings = CampaignSettings(samples=args.samples, seed=args.seed, run=run,
                                baseline=baseline, tolerances=MechanismTolerances())
    from .campaign.closed_chain_study import chain_reference

    reference = chain_reference(chain, run.duration)
    store = open_chain_store(args.out, chain, laws, settings, reference, resume=args.resume,
                             overwrite=args.overwrite)
    with store:
        done = len(store.done())
        if done:
            print(f"resuming: {done} of {args.samples + 1} plants (with the nominal) already "
                  f"done in {args.out}")
        bar = tqdm(total=args.samples + 1, initial=done, unit="plant",
                   desc=f"{chain.name}: Monte Carlo (nominal + {args.samples})",
                   disable=args.no_progress)
        start = time.perf_counter()
        try:
            campaign = run_chain_campaign(chain, laws, settings, reference=reference,
                                          jobs=args.jobs, scheduler=args.scheduler,
                                          progress=lambda d, total: bar.update(d - bar.n),
                                          store=store)
        except CampaignInterrupted as exc:
            bar.close()
            print(f"rrr-pin montecarlo: {exc}", file=sys.stderr)
            return 3 if isinstance(exc, WorkersLost) else exit_status(exc)
        bar.close()
        elapsed = time.perf_counter() - start
        s = write_campaign(campaign, args.out, store=store)
        s["written"].append(str(write_campaign_report(campaign, s, args.out, store)))
    nl, ran = len(laws), s["samples"] + 1 - done
    print(f"{chain.name}: {ran} plants x {nl} controllers x {run.duration:g} s in "
          f"{elapsed:.1f} s (engine {run.engine} on the constraint dynamics; auto: compiled "
          f"for fl and hinf, Python for the other laws)")
    nominal = campaign.nominal
    print("nominal plant: " + ", ".join(
        f"{law.name} RMS error {nominal[law.name + '_rms_error']:.4g} rad"
        if law.name + "_rms_error" in nominal else f"{law.name} {nominal[law.name + '_status']}"
        for law in laws))
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
    p.add_argument("--controllers", default=None, metavar="NAMES",
                   help="comma-separated built-in controllers (fl,hinf,pd; on --robot "
                        "fivebar|delta: fl,hinf, the reduced-model laws)")
    p.add_argument("--effect", required=True, metavar="NAME",
                   help="; ".join(f"{k}: {v.what} [{v.unit}]" for k, v in EFFECTS.items()))
    p.add_argument("--with", dest="fixed", action="append", default=[], metavar="EFFECT=SIZE",
                   help="hold another effect at a size in every run, e.g. actuator=300 "
                        "(repeatable or comma-separated); predictions include it")
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


def _parse_with(items, effect: str) -> dict:
    """``["actuator=300", "delay=0.001,..."]`` -> ``{"actuator": 300.0, ...}`` (``--with``)."""
    from .campaign.stress import check_fixed
    from .validation import FieldError

    fixed = {}
    for item in (part.strip() for text in items for part in text.split(",")):
        name, sep, size = item.partition("=")
        try:
            value = float(size)
        except ValueError:
            value = None
        if not sep or value is None or name.strip() in fixed:
            raise FieldError("--with", f"{{name}} expects EFFECT=SIZE, each effect once (e.g. "
                                       f"actuator=300), got {item!r}")
        fixed[name.strip()] = value
    try:
        return check_fixed(fixed, effect)
    except FieldError as exc:
        raise exc.relabelled(lambda _: "--with") from None


def _cmd_stress(args) -> int:
    import time

    from tqdm import tqdm

    from .campaign.runner import RunSettings, make_laws
    from .campaign.stress import StressSettings, stress
    from .control.catalog import EFFECTS
    from .control.specs import ReferenceSpec
    from .model.dynamics import load_robot
    from .model.mechanisms import MECHANISMS
    from .report.jsondata import dumps
    from .report.stress import stress_lines, write_stress

    if args.effect not in EFFECTS:
        raise ValueError(f"--effect {args.effect!r} is unknown; known effects: "
                         f"{', '.join(EFFECTS)}")
    from .sim.simulation import largest_substep
    from .validation import check_rate

    rate = check_rate("--rate", args.rate)
    fixed = _parse_with(args.fixed, args.effect)
    with _as_options():
        dt = args.dt if args.dt is not None else largest_substep(rate, 1e-4)
        settings = StressSettings(run=RunSettings(duration=args.duration, dt=dt,
                                                  rate=rate, engine=args.engine,
                                                  force=args.force),
                                  budget=args.budget)
    stem = args.effect + "".join(f"_with_{k}{v:g}" for k, v in fixed.items())
    if args.robot.lower().endswith(".xml"):
        raise ValueError(f"--robot {args.robot}: an MJCF closed chain; stress on a closed chain "
                         f"runs the built-in fivebar and delta only (their laws and reference)")
    if args.robot in MECHANISMS:
        robot, laws, reference = _stress_chain(args)
    _claim_out(args, "stress", part=stem)  # one folder holds every effect's run
    if args.robot not in MECHANISMS:
        _not_a_folder(robot=args.robot)
        robot = load_robot(args.robot, lock=_parse_lock(args.lock))
        home = _floats(args.home, "--home")
        reference = ReferenceSpec(home=None if home is None else tuple(home)).build(
            robot, args.duration, label=_option)
        laws = make_laws(args.controllers or "fl,hinf,pd", robot)
    start = time.perf_counter()
    bar = tqdm(total=len(laws), unit="law", desc=f"{robot.name}: stress {args.effect}",
               disable=args.no_progress)
    result = stress(robot, laws, reference, args.effect, settings, fixed=fixed,
                    progress=lambda done, total: bar.update(done - bar.n))
    bar.close()
    result["elapsed_s"] = time.perf_counter() - start
    result["robot"] = robot.name
    result["stem"] = stem
    fig = write_stress(result, args.out)
    if args.json:
        print(dumps(result))
        return 0
    print("\n".join(stress_lines(result) + [f"wrote {fig}"]))
    return 0


def _stress_chain(args) -> tuple:
    """``stress --robot fivebar|delta``: the nominal mechanism, its laws, the study's reference.

    The laws are the chain study's (:func:`rrr_pin.campaign.closed_chain_campaign.chain_laws`,
    default FL alone at ``lam = 100`` rad/s and H-infinity + FL at ``lam = 45`` rad/s with the
    reduced loop-shaping controller), each on its own nominal model; the reference is
    ``chain_reference`` with period ``--duration``. What does not apply to a closed chain is
    refused by name.
    """
    from .campaign.closed_chain_campaign import chain_laws
    from .campaign.closed_chain_study import chain_reference
    from .model.closed_chain import load_closed_chain

    given = [flag for flag, on in (("--lock", args.lock), ("--home", args.home is not None),
                                   ("--engine compiled", args.engine == "compiled")) if on]
    if given:
        raise ValueError(f"--robot {args.robot} (a closed chain) does not implement "
                         f"{', '.join(given)}: stress runs the chain study's reference from "
                         f"the mechanism's home on the Python engine (the compiled chain "
                         f"engine has no plant effects)")
    chain = load_closed_chain(args.robot)
    with _as_options():
        laws = chain_laws("fl,hinf" if args.controllers is None else args.controllers, chain)
        reference = chain_reference(chain, args.duration)
    return chain, laws, reference


# --- identify (base inertial parameters from measured torques) --------------------------------

def _add_identify(sub) -> None:
    p = sub.add_parser(
        "identify", help="identify the arm's base inertial parameters from measured torques",
        description="Reads --data (CSV: t, q_<joint>, optionally qd_<joint> and qdd_<joint>, "
                    "tau_<joint>, SI units), estimates the base inertial parameters of --robot "
                    "with their covariance, makes them physically consistent (SDP) and writes "
                    "DIR/identified.urdf and DIR/identification.json. With "
                    "--design-excitation, writes instead an optimised Fourier excitation, "
                    "DIR/excitation.csv (for --reference spline --csv) and excitation.json.")
    p.add_argument("--robot", default="rrr", metavar="NAME|PATH",
                   help="arm whose kinematics are trusted and whose inertials are the prior: "
                        "'rrr' (default), an example-robot-data name or a URDF path")
    p.add_argument("--data", metavar="FILE.csv", default=None,
                   help="measurements (required unless --design-excitation)")
    p.add_argument("--method", choices=("wls", "ols"), default="wls",
                   help="weighted (per-joint noise, default) or ordinary least squares")
    p.add_argument("--held-out", type=float, default=0.2, metavar="FRACTION",
                   help="final fraction of the samples left out of the fit and predicted (0.2)")
    p.add_argument("--window", type=float, default=None, metavar="S",
                   help="Savitzky-Golay window [s] for derivatives missing from the data "
                        "(default max(0.2 s, 11 samples))")
    g = p.add_argument_group("excitation")
    g.add_argument("--design-excitation", action="store_true",
                   help="design an excitation trajectory instead of identifying")
    g.add_argument("--harmonics", type=int, default=5, help="Fourier harmonics per joint (5)")
    g.add_argument("--frequency", type=float, default=0.2, metavar="HZ",
                   help="base frequency [Hz] (0.2: a 5 s period)")
    g.add_argument("--periods", type=int, default=2, help="periods in the trajectory (2)")
    g.add_argument("--max-acceleration", type=float, default=10.0, metavar="RAD_S2",
                   help="acceleration limit of every joint [rad/s^2] (10)")
    g.add_argument("--maxiter", type=int, default=60, help="SLSQP iterations (60)")
    g.add_argument("--seed", type=int, default=0, help="seed of the starting point (0)")
    g.add_argument("--csv-rate", type=float, default=100.0, metavar="HZ",
                   help="waypoints per second in excitation.csv (100)")
    p.add_argument("--out", default="results/identify", metavar="DIR",
                   help="output folder (results/identify)")
    _add_overwrite(p)
    p.set_defaults(func=_cmd_identify)


def _cmd_identify(args) -> int:
    import json

    from .model.dynamics import load_robot
    from .outputs import writing

    _not_a_folder(robot=args.robot, data=args.data)
    _refuse_closed_chain(args.robot, "identify",
                         "its base-parameter regressor is that of a serial tree with a torque "
                         "at every joint, while a mechanism is driven at its actuated joints "
                         "only (its passive joints' torques are the loop forces)")
    if args.design_excitation:
        from .model.excitation import design_excitation

        if args.data is not None:
            raise ValueError("--data is not read by --design-excitation (it designs the "
                             "motion to log); give one or the other")

        robot = load_robot(args.robot)
        with _as_options():
            traj, info = design_excitation(
                robot, harmonics=args.harmonics, frequency=args.frequency,
                max_acceleration=args.max_acceleration, periods=args.periods,
                seed=args.seed, maxiter=args.maxiter)
        out = _claim_out(args, "identify")
        csv_path = traj.write_csv(out / "excitation.csv", args.csv_rate, robot.joint_names)
        path = out / "excitation.json"
        with writing(path):
            path.write_text(json.dumps({"robot": robot.name, **info,
                                        "trajectory": traj.to_dict()}, indent=1) + "\n")
        print(f"{robot.name}: Fourier excitation, {info['harmonics']} harmonics at "
              f"{info['frequency_hz']:g} Hz, {traj.duration:g} s; condition number of the "
              f"base regressor {info['cond']:.4g} (random start {info['cond_random']:.4g})")
        print(f"wrote {csv_path} and {path}; run it with --reference spline --csv {csv_path} "
              f"--duration {traj.duration:g}")
        return 0
    if args.data is None:
        raise ValueError("--data FILE.csv is required (or --design-excitation)")
    from .model.identification import identify, read_measurements

    robot = load_robot(args.robot)
    with _as_options():
        data = read_measurements(args.data, robot, window=args.window)
        result = identify(robot, data, method=args.method, held_out=args.held_out)
    out = _claim_out(args, "identify")
    written = result.write(out)
    s = result.summary
    print(f"{robot.name}: {s['base_count']} base parameters from {s['samples_fit']} samples "
          f"({s['method']}), condition number {s['condition_number']:.4g}")
    print("residual RMS [N m]: " + ", ".join(f"{k} {v:.4g}"
                                             for k, v in s["residual_rms_Nm"].items()))
    if s["held_out"] is not None:
        print(f"held-out {s['held_out']['samples']} samples, identified URDF's torque error "
              "RMS [N m]: " + ", ".join(f"{k} {v:.4g}" for k, v in
                                       s["held_out"]["rms_error_urdf_Nm"].items()))
    c = s["consistency"]
    print("physically consistent: " + ("the estimate itself" if c["feasible_at_estimate"]
                                       else f"nearest consistent arm at RMS torque change "
                                            f"{c['distance_rms_Nm']:.3g} N m"))
    print("wrote " + ", ".join(str(p) for p in written))


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
    _refuse_closed_chain(args.robot, "export",
                         "the exported C code holds a serial arm's dynamics (crba/rnea on a "
                         "tree) and no loop closure, and the closed-chain laws have no sampled "
                         "form")
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


# --- margins and robstab (linear analysis at a frozen configuration) --------------------------

def _add_margins(sub) -> None:
    p = sub.add_parser(
        "margins", help="gain, phase, delay and disk margins of each law's loop at the torque "
                        "input, linearized at a frozen configuration")
    _add_robot_arguments(p)
    p.add_argument("--controllers", default="fl,hinf,pd", metavar="NAMES",
                   help="comma-separated built-in controllers (fl,hinf,pd)")
    p.add_argument("--out", metavar="DIR", default=None,
                   help="write margins.png (singular values, Bode phase, Nyquist) into DIR")
    _add_overwrite(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_margins)


def _frozen(args):
    from .model.dynamics import load_robot

    _not_a_folder(robot=args.robot)
    robot = load_robot(args.robot, lock=_parse_lock(args.lock))
    from .validation import check_vector

    home = _floats(args.home, "--home")
    if home is None:
        import numpy as np

        return robot, np.clip(robot.neutral(), robot.lower, robot.upper)
    return robot, check_vector("--home", home, robot.nq)


def _cmd_margins(args) -> int:
    from .campaign.runner import make_laws
    from .control.analysis import loop_at_input, loop_margins
    from .report.jsondata import dumps

    if args.out is not None:
        _claim_out(args, "margins")
    robot, q = _frozen(args)
    out = {"robot": robot.name, "q_rad": [float(v) for v in q], "laws": {}}
    loops = {}
    with _as_options():
        laws = make_laws(args.controllers, robot)
        for law in laws:
            loops[law.name] = loop_at_input(law, robot, q)
            m = loop_margins(loops[law.name])
            out["laws"][law.name] = {
                "gain_margin": m.gain.tolist(), "phase_margin_deg": m.phase.tolist(),
                "crossover_rad_s": m.crossover.tolist(), "delay_margin_s": m.delay.tolist(),
                "disk_margin": m.disk, "disk_gain_margin": m.disk_gain,
                "disk_phase_margin_deg": m.disk_phase}
    if args.out is not None:
        from .report.margins import save_margins_figure

        out["figure"] = str(save_margins_figure(loops, args.out))
    if args.json:
        print(dumps(out))
        return 0
    print(f"{robot.name} at q = {[round(float(v), 4) for v in q]} rad, loop broken at the "
          f"torque input (loop at a time, per joint):")
    for name, m in out["laws"].items():
        print(f"  {name}: phase margin {_join(m['phase_margin_deg'], '.1f')} deg at "
              f"{_join(m['crossover_rad_s'], '.1f')} rad/s; delay margin "
              f"{_join([1e3 * d for d in m['delay_margin_s']], '.2f')} ms; gain margin "
              f"{_join(m['gain_margin'], '.3g')}; disk margin {m['disk_margin']:.3f} "
              f"(gain x{m['disk_gain_margin']:.3g}, phase {m['disk_phase_margin_deg']:.1f} "
              f"deg, all joints at once)")
    if "figure" in out:
        print(f"wrote {out['figure']}")
    return 0


def _control_ss(sys):
    import control

    return control.ss(sys)


def _join(values, fmt: str) -> str:
    return "/".join(format(v, fmt) for v in values)


def _add_robstab(sub) -> None:
    p = sub.add_parser(
        "robstab", help="real-parametric robust stability (mu) of the feedback-linearized "
                        "loop at a frozen configuration, inertial parameters uncertain")
    _add_robot_arguments(p)
    p.add_argument("--controllers", default="fl,hinf", metavar="NAMES",
                   help="comma-separated feedback-linearizing controllers (fl,hinf)")
    p.add_argument("--tol", type=float, default=0.2,
                   help="relative tolerance of the masses and principal second moments that "
                        "the margin is counted in (0.2, the paper's 20 %%)")
    p.add_argument("--samples", type=int, default=0,
                   help="also scale this many vertices of the parameter box on perturbed "
                        "Pinocchio models until the loop is unstable (0: no check)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_robstab)


def _cmd_robstab(args) -> int:
    from .campaign.runner import make_laws
    from .control.analysis import parametric_margin, sampled_margin
    from .report.jsondata import dumps
    from .validation import check_count

    robot, q = _frozen(args)
    out = {"robot": robot.name, "q_rad": [float(v) for v in q], "tol": args.tol, "laws": {}}
    with _as_options():
        samples = check_count("samples", args.samples)
        for law in make_laws(args.controllers, robot):
            try:
                loop, r = parametric_margin(law, q, args.tol)
            except TypeError as exc:  # pd: no feedback-linearizing loop
                raise ValueError(f"--controllers {law.name}: {exc}") from None
            rec = {"margin_lower": r.margin_lower, "margin_upper": r.margin_upper,
                   "critical_frequency_rad_s": r.critical_frequency,
                   "parameters": loop.names, "dropped": loop.dropped}
            if samples:
                rec["sampled_margin"] = sampled_margin(law, loop, samples)[0]
            out["laws"][law.name] = rec
    if args.json:
        print(dumps(out))
        return 0
    print(f"{robot.name} at q = {[round(float(v), 4) for v in q]} rad: inertial parameters "
          f"uncertain, margin in units of +-{100 * args.tol:g} %")
    for name, m in out["laws"].items():
        line = (f"  {name}: stable for all errors up to {m['margin_lower']:.3f} x "
                f"{100 * args.tol:g} %; a {m['margin_upper']:.3f} x error destabilizes it "
                f"(at {m['critical_frequency_rad_s']:.3g} rad/s); {len(m['parameters'])} "
                f"parameters")
        if "sampled_margin" in m:
            line += f"; sampled vertices: unstable from {m['sampled_margin']:.3f} x"
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())

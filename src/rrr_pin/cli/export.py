"""``rrr-pin export``: a built-in controller as C code for a real-time loop."""

from __future__ import annotations

from .build import design_record, load_plant, tuned_from_args
from .common import as_options, check_out_early, claim_out
from .options import add_design_argument, add_overwrite

__all__ = ["add", "run_export"]


def add(sub) -> None:
    """Declare ``export``."""
    from ..control.catalog import BUILTIN_LAWS

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
                       f"{k} = {v}" for k, v in BUILTIN_LAWS.items()) + "; tuned = the law "
                        "of --design (default: hinf)")
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
    add_overwrite(p)
    add_design_argument(p)
    p.set_defaults(func=run_export)


def run_export(args) -> int:
    """Write the exported folder and print how to build it."""
    from ..control.catalog import LAWS, make_law
    from ..deploy.writer import check_exportable, prepare_export

    out = check_out_early(args, "export")  # a file, no permission, another tool's run
    if args.law not in LAWS and args.law != "tuned":
        raise ValueError(f"--law {args.law!r} is not a built-in controller ({', '.join(LAWS)})")
    robot = load_plant(args)
    check_exportable(robot)
    K, d = None, None
    if args.law == "hinf":
        from ..robust.loopshaping import design

        d = design(lam=45.0, n=robot.nq)
        K = d.K_full if args.full_order else d.K_reduced
    with as_options():
        law = tuned_from_args(args, robot, [args.law]) or \
            make_law(args.law, robot, **({"K": K} if K is not None else {}))
        prepared = prepare_export(law, robot, args.rate, method=args.method,
                                  prewarp=args.prewarp, design=d)
    check_sampled_loop(law, robot, prepared.rate)
    if out is None:  # --overwrite: the previous export is removed now that the options hold
        out = claim_out(args, "export")
    prepared.write(out)
    if design_record(args) is not None:  # which design ran, with its requirement table
        import json

        (out / "design.json").write_text(json.dumps(design_record(args), indent=1,
                                                    default=str))
    print(f"{robot.name}: {prepared.law.name} ({prepared.form.kind}, {prepared.law.nx} states) "
          f"at {prepared.rate:g} Hz, {prepared.dynamics} dynamics")
    print(f"wrote {out}/: {', '.join(prepared.files)}")
    print(f"build: cmake -S {out} -B {out}/build && cmake --build {out}/build && "
          f"{out}/build/ctrl_main")
    return 0


def check_sampled_loop(law, robot, rate: float) -> None:
    """Refuse a rate at which the law's linear digital loop is unstable, naming the figure.

    The loop of :func:`rrr_pin.campaign.stress.spectral_radius` (the law's zero-order-hold
    output on its linear plant, at the neutral configuration): before, ``--law fl --rate 1``
    was exported without a word while its Python twin diverged at once.
    """
    from ..campaign.stress import spectral_radius

    home = robot.neutral()
    rho = spectral_radius(law, rate, home)
    if rho < 1.0:
        return
    lo, hi = rate, rate
    while spectral_radius(law, hi, home) >= 1.0 and hi < 1e6:
        lo, hi = hi, 2.0 * hi
    while hi / lo - 1.0 > 1e-3:  # the smallest stable rate, to 0.1 %
        mid = (lo * hi) ** 0.5
        lo, hi = (lo, mid) if spectral_radius(law, mid, home) < 1.0 else (mid, hi)
    raise ValueError(f"--rate {rate:g} Hz: the sampled loop of {law.name!r} is unstable there "
                     f"(spectral radius {rho:.4g} >= 1 of its linear digital loop at the neutral "
                     f"configuration); it is stable from about {hi:.4g} Hz: give a faster rate")


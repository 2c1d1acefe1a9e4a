"""``rrr-pin export``: a built-in controller as C code for a real-time loop."""

from __future__ import annotations

from .build import (
    compensation_from_args,
    design_record,
    load_plant,
    tuned_from_args,
    warn_effect_margins,
)
from .common import as_options, check_out_early, claim_out
from .options import add_armature_argument, add_design_argument, add_overwrite

__all__ = ["add", "run_export"]


def add(sub) -> None:
    """Declare ``export``."""
    from ..control.catalog import BUILTIN_LAWS

    p = sub.add_parser(
        "export", help="write a built-in controller as C code for a real-time loop",
        description="Writes --law on --robot, sampled at --rate, into --out: controller.h/.c "
                    "(C99, ctrl_reset/ctrl_step), the model's dynamics (generated C for the "
                    "nominal RRR, Pinocchio C++ otherwise), CMakeLists.txt, main.c and "
                    "controller.json (with --ros2, a ros2_control package in DIR/ros2). "
                    "Build with cmake -S DIR -B "
                    "DIR/build && cmake --build DIR/build.")
    p.add_argument("--robot", default="rrr", metavar="NAME|PATH",
                   help="arm: 'rrr' (default), an example-robot-data name (ur5, ...) or a URDF "
                        "path")
    p.add_argument("--lock", action="append", metavar="JOINT=VALUE",
                   help="lock a joint at a position [rad or m] (repeatable)")
    add_armature_argument(p)
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
    p.add_argument("--friction", metavar="urdf|viscous=V,coulomb=C[,smooth=S]", default=None,
                   help="with --compensate-friction: the friction compensated (default and "
                        "'urdf': the URDF's <dynamics damping friction>, e.g. an identified "
                        "URDF's), Fv [N m s/rad], Fc [N m], S [rad/s] (0.01), one value or one "
                        "per joint separated by '/'")
    p.add_argument("--compensate-friction", action="store_true",
                   help="fl, hinf: the exported law adds Fv qd + Fc tanh(qd / S) to its torque "
                        "(recorded in controller.json: law.friction_compensation)")
    # dest: "command" is the subcommand's name (rrr-pin's own errors say "rrr-pin export")
    p.add_argument("--command", dest="torque_command", default="full",
                   choices=("full", "no-gravity", "no-gravity-no-friction"),
                   help="the drive's torque convention: full (the law's whole torque, "
                        "default), no-gravity (minus Ghat(q): the drive adds gravity), "
                        "no-gravity-no-friction (minus the friction compensation too, as "
                        "libfranka's franka::Torques); recorded in controller.json")
    p.add_argument("--out", default="controller", metavar="DIR",
                   help="output folder (controller/)")
    p.add_argument("--ros2", action="store_true",
                   help="also write DIR/ros2/, a ros2_control controller package (package.xml, "
                        "plugin, parameters YAML); build it with colcon build --paths DIR/ros2")
    p.add_argument("--ros2-name", default=None, metavar="NAME",
                   help="with --ros2: the package's name and the plugin's namespace (default "
                        "<arm>_<law>_controller; a ROS 2 package name, REP 144)")
    p.add_argument("--maintainer", default=None, metavar="'NAME <EMAIL>'",
                   help="with --ros2: package.xml's maintainer (default a placeholder the "
                        "package's CMake refuses to release)")
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
    if args.friction is not None and not args.compensate_friction:
        raise ValueError("--friction in export says which friction the law compensates: give "
                         "--compensate-friction too (the exported code simulates no plant)")
    friction = compensation_from_args(args, robot)
    with as_options():
        law = tuned_from_args(args, robot, [args.law]) or \
            make_law(args.law, robot, **({"K": K} if K is not None else {}),
                     **({"friction": friction} if friction is not None else {}))
        prepared = prepare_export(law, robot, args.rate, method=args.method,
                                  prewarp=args.prewarp, design=d, command=args.torque_command)
    band = 0.0
    if args.ros2:
        from ..deploy.ros2 import PERIOD_TOLERANCE

        band = PERIOD_TOLERANCE
    check_sampled_loop(law, robot, prepared.rate, method=args.method, prewarp=args.prewarp,
                       band=band)
    warn_effect_margins(args, [law], prepared.rate)   # the effects its design recorded
    if args.ros2:
        from ..deploy.ros2 import ros2_package

        with as_options():  # every check, --ros2-name and --maintainer too, before writing
            package = ros2_package(prepared, robot, name=args.ros2_name,
                                   maintainer=args.maintainer)
    elif args.ros2_name is not None or args.maintainer is not None:
        raise ValueError("--ros2-name and --maintainer name the ros2_control package: give "
                         "--ros2 too")
    if out is None:  # --overwrite: the previous export is removed now that the options hold
        out = claim_out(args, "export")
    prepared.write(out)
    if args.ros2:
        from ..deploy.ros2 import write_ros2_package

        write_ros2_package(prepared, robot, out, name=args.ros2_name,
                           maintainer=args.maintainer)
    if design_record(args) is not None:  # which design ran, with its requirement table
        import json

        (out / "design.json").write_text(json.dumps(design_record(args), indent=1,
                                                    default=str))
    print(f"{robot.name}: {prepared.law.name} ({prepared.form.kind}, {prepared.law.nx} states) "
          f"at {prepared.rate:g} Hz, {prepared.dynamics} dynamics, command "
          f"{prepared.command.name}")
    print(f"wrote {out}/: {', '.join(prepared.files)}")
    print(f"build: cmake -S {out} -B {out}/build && cmake --build {out}/build && "
          f"{out}/build/ctrl_main")
    if args.ros2:
        name = next(k for k in package if k.startswith("ros2/config/")).split("/")[-1][:-5]
        print(f"ros2_control package {name}: {out}/ros2/ (colcon build --paths {out}/ros2; "
              f"parameters in {out}/ros2/config/{name}.yaml)")
    return 0


class _AsExported:
    """``law`` whose linear model discretizes K as the export does (``method``, ``prewarp``)."""

    def __init__(self, law, method: str, prewarp):
        self.law, self.name, self.method, self.prewarp = law, law.name, method, prewarp

    def linear_model(self):
        import dataclasses

        import control
        import numpy as np

        from ..control.laws import FLLinearModel

        model = self.law.linear_model()
        if type(model) is not FLLinearModel or not model.K[0].size:
            return model  # no K: nothing discretized
        kwargs = {} if self.prewarp is None else {"prewarp_frequency": self.prewarp}

        def discretize(rate):
            Kd = control.sample_system(control.ss(*model.K), 1.0 / rate, method=self.method,
                                       **kwargs)
            return tuple(np.asarray(M, dtype=float) for M in (Kd.A, Kd.B, Kd.C, Kd.D))

        return dataclasses.replace(model, discretize=discretize)


def check_sampled_loop(law, robot, rate: float, *, method: str = "tustin", prewarp=None,
                       band: float = 0.0) -> None:
    """Refuse a rate at which the law's linear digital loop is unstable, naming the figure.

    The loop of :func:`rrr_pin.campaign.stress.spectral_radius` (the law's zero-order-hold
    output on its linear plant, at the neutral configuration), with K discretized as the export
    does (``method``, ``prewarp``): before, ``--law fl --rate 1`` was exported without a word
    while its Python twin diverged at once. With ``band`` (``--ros2``: the controller accepts
    update periods within ``(1 +- band) / rate`` and computes with each), the loop must also be
    stable at both edges of the band, each period held (a frozen-period criterion).
    """
    from ..campaign.stress import spectral_radius

    home = robot.neutral()
    model = _AsExported(law, method, prewarp)
    factors = (1.0, 1.0 / (1.0 + band), 1.0 / (1.0 - band)) if band else (1.0,)

    def worst(r):  # (spectral radius, rate [Hz]) of the least stable period checked
        return max((spectral_radius(model, r * f, home), r * f) for f in factors)

    rho, at = worst(rate)
    if rho < 1.0:
        return
    lo, hi = rate, rate
    while worst(hi)[0] >= 1.0 and hi < 1e6:
        lo, hi = hi, 2.0 * hi
    while hi / lo - 1.0 > 1e-3:  # the smallest stable rate, to 0.1 %
        mid = (lo * hi) ** 0.5
        lo, hi = (lo, mid) if worst(mid)[0] < 1.0 else (mid, hi)
    if at == rate:
        raise ValueError(f"--rate {rate:g} Hz: the sampled loop of {law.name!r} is unstable "
                         f"there (spectral radius {rho:.4g} >= 1 of its linear digital loop at "
                         f"the neutral configuration); it is stable from about {hi:.4g} Hz"
                         f"{' over the --ros2 period band' if band else ''}: give a faster rate")
    raise ValueError(f"--rate {rate:g} Hz with --ros2: the controller accepts update periods "
                     f"within +-{100 * band:g} % of 1/rate and computes with each, and the "
                     f"sampled loop of {law.name!r} is unstable at a period of "
                     f"{1e3 / at:.4g} ms ({at:.4g} Hz; spectral radius {rho:.4g} >= 1 of its "
                     f"linear digital loop at the neutral configuration); it is stable over "
                     f"the whole band from about {hi:.4g} Hz: give a faster rate")

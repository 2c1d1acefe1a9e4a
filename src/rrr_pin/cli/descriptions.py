"""``rrr-pin urdf``, ``mjcf`` and ``check-dynamics``: the generated descriptions and their check."""

from __future__ import annotations

import sys
from pathlib import Path

from .common import not_a_folder

__all__ = ["add", "run_urdf", "run_mjcf", "run_check_dynamics", "COMMITTED_URDF"]

#: The generator's committed output, relative to the repository's root (``urdf --check``).
COMMITTED_URDF = "urdf/rrr.urdf"


def add(sub) -> None:
    """Declare ``urdf``, ``mjcf`` and ``check-dynamics``."""
    p = sub.add_parser("urdf", help="write (or check) the URDF generated from a DH parameter set")
    p.add_argument("--params", metavar="FILE",
                   help="DH parameter set as JSON (ArmParams.save); default: the paper's Tables "
                        "1-2")
    p.add_argument("--out", metavar="PATH", default=None,
                   help="where to write the URDF (default: standard output; with --check, "
                        f"the committed {COMMITTED_URDF})")
    p.add_argument("--check", action="store_true",
                   help="do not write: exit 1 if PATH (default: the committed "
                        f"{COMMITTED_URDF}, from the repository's root) differs from what the "
                        "generator writes")
    p.set_defaults(func=run_urdf)

    p = sub.add_parser("mjcf", help="write (or check) the MJCF of a parallel mechanism "
                                    "generated from its parameter set")
    p.add_argument("mechanism", metavar="MECHANISM",
                   help="a registered mechanism (a name of "
                        "rrr_pin.model.mechanisms.MECHANISMS)")
    p.add_argument("--out", metavar="PATH", default=None,
                   help="where to write it (default: standard output; with --check, the "
                        "committed mjcf/MECHANISM.xml)")
    p.add_argument("--check", action="store_true",
                   help="do not write: exit 1 if PATH differs from what the generator writes")
    p.set_defaults(func=run_mjcf)

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
    p.set_defaults(func=run_check_dynamics)


def run_urdf(args) -> int:
    """Write, print or check the URDF of a DH parameter set."""
    from ..model.dh import ArmParams, paper_params
    from ..model.urdf import check_urdf, urdf_from_params, write_urdf

    not_a_folder(params=args.params)
    params = ArmParams.load(args.params) if args.params else paper_params()
    if args.check:
        if args.out == "-":
            raise ValueError("--check compares a file: give --out PATH (default: "
                             f"{COMMITTED_URDF}), not standard output")
        if args.out is None:
            args.out = COMMITTED_URDF
        if check_urdf(args.out, params):
            print(f"{args.out}: up to date")
            return 0
        if Path(args.out).is_file():
            print(f"{args.out}: differs from the generator's output; regenerate with "
                  f"`rrr-pin urdf --out {args.out}`")
        else:
            where = (" (run from the repository's root, or give --out PATH)"
                     if args.out == COMMITTED_URDF else "")
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


def run_mjcf(args) -> int:
    """Write, print or check the MJCF of a registered mechanism."""
    from ..model.mechanisms import check_mjcf, mechanism_params, mjcf_from_params, write_mjcf

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


def run_check_dynamics(args) -> int:
    """Compare Pinocchio's M, V, G of a URDF with the paper's closed form."""
    from ..model.closed_form import MAX_CHECK_SAMPLES, compare_with_pinocchio
    from ..model.dh import ArmParams, paper_params
    from ..model.dynamics import load_robot
    from ..model.plant import URDF
    from ..report.dynamics import comparison_lines
    from ..validation import check_count, check_positive

    check_positive("--rtol", args.rtol, allow_zero=True)
    check_count("--samples", args.samples, 1, high=MAX_CHECK_SAMPLES)
    check_count("--seed", args.seed)
    not_a_folder(urdf=args.urdf, params=args.params)
    params = ArmParams.load(args.params) if args.params else paper_params()
    robot = load_robot(args.urdf if args.urdf else params, gravity=params.g)
    robot.require(URDF, f"check-dynamics --urdf {args.urdf} (it compares a serial arm with the "
                        f"RRR's closed form eq. (2)-(7))")
    result = compare_with_pinocchio(robot, params, samples=args.samples, seed=args.seed)
    print(f"Pinocchio ({args.urdf or 'URDF generated from the parameters'}) vs closed form "
          f"eq. (2)-(7) ({args.params or 'paper Tables 1-2'}), {args.samples} random states, "
          f"seed {args.seed}")
    lines, failed = comparison_lines(result, args.rtol)
    print("\n".join(lines))
    return 1 if failed else 0

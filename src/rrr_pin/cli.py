"""Command-line interface: ``rrr-pin <command> [options]``.

Each sub-command has an ``_add_<name>(subparsers)`` function that declares its options and a
``_cmd_<name>(args) -> int`` function that runs it and returns the exit status.
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["main"]


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rrr-pin",
        description="H-infinity loop shaping + feedback linearization of serial arms "
                    "(Pinocchio dynamics).")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in (_add_urdf, _add_check_dynamics, _add_design):
        add(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``rrr-pin`` console script."""
    parser = _build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        print(f"rrr-pin {args.command}: error: {exc}", file=sys.stderr)
        return 2


# --- urdf -------------------------------------------------------------------------------------

def _add_urdf(sub) -> None:
    p = sub.add_parser("urdf", help="write (or check) the URDF generated from a DH parameter set")
    p.set_defaults(func=_cmd_urdf)


def _cmd_urdf(args) -> int:
    raise NotImplementedError


# --- check-dynamics ---------------------------------------------------------------------------

def _add_check_dynamics(sub) -> None:
    p = sub.add_parser("check-dynamics", help="compare Pinocchio with the paper's closed form")
    p.set_defaults(func=_cmd_check_dynamics)


def _cmd_check_dynamics(args) -> int:
    raise NotImplementedError


# --- design (H-infinity loop shaping, paper section 4) ----------------------------------------

def _add_design(sub) -> None:
    p = sub.add_parser("design", help="H-infinity loop-shaping design of the paper's section 4")
    p.set_defaults(func=_cmd_design)


def _cmd_design(args) -> int:
    raise NotImplementedError


if __name__ == "__main__":
    sys.exit(main())

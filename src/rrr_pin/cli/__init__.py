"""Command-line interface: ``rrr-pin <command> [options]``, a package of thin commands.

Each command module (:data:`COMMANDS`) has ``add(subparsers)``, which declares its options, and
functions ``run_<name>(args) -> int`` that parse, build the typed inputs of the layers below
(:mod:`rrr_pin.cli.build`: the plant, the settings, the reference, the laws), call one public
function and print. No domain rule lives here: the torque-limit rule, the claims and the
capabilities of a plant are their layers'. The options shared by several commands are declared
once (:mod:`rrr_pin.cli.options`).
"""

from __future__ import annotations

import argparse
import sys

from . import analysis, campaign, descriptions, design, export, hil, identify, reproduce, stress
from .common import logging_to_stderr, negative_values, option

__all__ = ["main", "build_parser", "COMMANDS"]

#: The command modules, in the order of ``rrr-pin --help``.
COMMANDS = (descriptions, design, reproduce, campaign, stress, identify, analysis, export, hil)


def build_parser() -> argparse.ArgumentParser:
    """Return the ``rrr-pin`` parser with every command's options."""
    parser = argparse.ArgumentParser(
        prog="rrr-pin",
        description="H-infinity loop shaping + feedback linearization of robot arms and "
                    "closed chains (Pinocchio dynamics).")
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"rrr-pin {__version__}")
    verbose = {"action": "count", "help": "log on stderr what the library does: -v steps "
               "(INFO), -vv details (DEBUG), e.g. the engine chosen for each run"}
    parser.add_argument("-v", "--verbose", default=0, **verbose)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for module in COMMANDS:
        module.add(sub)
    for command in sub.choices.values():  # also after the command: rrr-pin reproduce -v
        command.add_argument("-v", "--verbose", default=argparse.SUPPRESS, **verbose)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``rrr-pin`` console script.

    SIGINT (Ctrl-C) and SIGTERM stop any command with one line on standard error and the
    exit status 130 or 143 (128 + the signal); its local worker processes are stopped. The
    files a command wrote are recorded in its folder's manifest (:mod:`rrr_pin.outputs`)
    however it ends. A refused input is one line on standard error and exit status 2.
    """
    from ..campaign.executors import exit_status, interrupt_on_signals

    args = None
    try:
        with interrupt_on_signals():
            parser = build_parser()
            args = parser.parse_args(
                negative_values(sys.argv[1:] if argv is None else list(argv)))
            status = None
            try:
                with logging_to_stderr(args.verbose):
                    status = int(args.func(args) or 0)
                    return status
            finally:  # record the files written, also after an error or an interrupt
                if getattr(args, "outputs", None) is not None:
                    args.outputs.close(finished=status == 0)
    except (ValueError, FileNotFoundError, RuntimeError) as exc:
        from ..validation import FieldError

        if isinstance(exc, FieldError) and args is not None and exc.field in vars(args):
            exc = exc.relabelled(option)  # a field that is this command's option: --q0
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

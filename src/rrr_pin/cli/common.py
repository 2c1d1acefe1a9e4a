"""What every command shares: the output folder's claim, logging, and option spelling."""

from __future__ import annotations

import sys
from contextlib import contextmanager
from pathlib import Path

__all__ = ["claim_out", "check_out_early", "logging_to_stderr", "negative_values", "option",
           "as_options", "floats", "not_a_folder", "parse_lock", "control_ss", "join"]


def claim_out(args, tool: str, part: str | None = None) -> Path:
    """Claim ``args.out`` for this run before any work (rrr_pin.outputs: the folder rule).

    Refuses a file, an unwritable folder, another tool's run, and a non-empty folder without
    ``--overwrite``; :func:`rrr_pin.cli.main` records the files written when the command ends.
    """
    from ..outputs import OutputDir

    settings = {k: v for k, v in vars(args).items() if k not in ("func", "outputs")}
    args.outputs = OutputDir.claim(args.out, tool, part=part, overwrite=args.overwrite,
                                   settings=settings)
    args.write_hint = (f"; the files written so far (if any) are listed in "
                       f"{args.outputs.manifest}: free space, then rerun with --overwrite")
    return Path(args.out)


def check_out_early(args, tool: str, part: str | None = None) -> Path | None:
    """Refuse before any work what ``--overwrite`` cannot fix; claim at once without it.

    Without ``--overwrite`` the claim removes nothing, so it is made at once (returns the
    folder). With it, only the checks are made (a file, an unwritable folder, another tool's
    run; returns None), and :func:`claim_out`, called once the options are checked, removes
    the previous run: a mistyped option never costs that run.
    """
    if not args.overwrite:
        return claim_out(args, tool, part)
    from ..outputs import check_writable, refuse_other_tool

    check_writable(args.out)
    refuse_other_tool(args.out, tool)
    return None


@contextmanager
def logging_to_stderr(verbose: int):
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


def negative_values(argv: list[str]) -> list[str]:
    """Join ``--opt -1e-3`` into ``--opt=-1e-3``: argparse reads ``-1e-3`` as an option.

    argparse takes a token for a negative number only in the forms ``-1`` and ``-0.5``; an
    exponent (``-1e-3``), a percentage (``--torque-limit -5%``) or a list (``--home
    -0.3,0.6,-0.9``) failed with "expected one argument" instead of reaching the option's own
    check. A token of ``-`` then a digit or a point is never an option.
    """
    import re

    number = re.compile(r"^-[\d.]")
    out = []
    for token in argv:
        if out and number.match(token) and out[-1].startswith("--") and "=" not in out[-1]:
            out[-1] = f"{out[-1]}={token}"
        else:
            out.append(token)
    return out


def option(field: str) -> str:
    """How the command line spells a settings field: ``move_time`` -> ``--move-time``."""
    return "--" + field.replace("_", "-")


@contextmanager
def as_options():
    """Name a settings field as its option (``move_time`` -> ``--move-time``) in an error."""
    from ..validation import FieldError

    try:
        yield
    except FieldError as exc:
        raise exc.relabelled(option) from None


def floats(text: str | None, name: str):
    """Comma-separated numbers of an option, or None (their count is checked where used)."""
    if text is None:
        return None
    try:
        return [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        raise ValueError(f"{name} expects numbers separated by commas, got {text!r}") from None


def not_a_folder(**options) -> None:
    """Refuse a folder given where a file is expected (``--urdf DIR``), naming the option.

    A built-in robot name (``--robot panda``, ``--robot fivebar``) is a name, never a path:
    a folder of that name in the working directory (``--out xarm7``) does not shadow it,
    as :func:`rrr_pin.model.robots.read_source` resolves names before paths.
    """
    from ..model.closed_chain import MECHANISMS
    from ..model.robots import robot_names

    for field, path in options.items():
        if field == "robot" and str(path) in (*robot_names(), *MECHANISMS):
            continue
        if path is not None and Path(path).is_dir():
            raise ValueError(f"{option(field)} {path}: is a directory, expected a file")


def parse_lock(items, option: str = "--lock") -> dict:
    """``["joint=0.1", ...]`` of ``--lock`` -> ``{"joint": 0.1, ...}``, each joint once."""
    lock = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ValueError(f"{option} expects JOINT=VALUE, got {item!r}")
        if name in lock:
            raise ValueError(f"{option} {name} given twice")
        try:
            lock[name] = float(value)
        except ValueError:
            raise ValueError(f"{option} {item!r}: {value!r} is not a number") from None
    return lock


def control_ss(sys):
    """``control.ss(sys)`` (python-control imported on use: ``--help`` stays light)."""
    import control

    return control.ss(sys)


def join(values, fmt: str) -> str:
    """Per-joint values as ``a/b/c`` in format ``fmt``."""
    return "/".join(format(v, fmt) for v in values)

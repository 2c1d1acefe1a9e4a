"""Where an arm comes from: the paper's RRR, an example-robot-data arm, a URDF file or ArmParams.

:func:`read_source` turns any of them into URDF text; :func:`robot_names` lists the names
:func:`rrr_pin.model.dynamics.load_robot` accepts besides paths. A new arm source is one branch
here; :func:`nominal_params` says which sources come with a DH parameter set.
"""

from __future__ import annotations

from pathlib import Path

from .dh import ArmParams, paper_params
from .urdf import urdf_from_params

__all__ = ["ERD_ARMS", "RobotModelError", "robot_names", "read_source", "erd_urdf_path",
           "nominal_params"]

#: example-robot-data names accepted by :func:`load_robot`: every fixed-base serial arm of
#: example-robot-data 5.0 that rrr-pin can simulate (its joint-limited and gripper variants
#: too). Not listed: floating bases, trees (baxter, tiago, hands), and those whose URDF
#: rrr-pin refuses (bravo7_gripper: a finger moves no mass; talos_arm: its mimic joints'
#: leaders are not joints of the file); the 2-joint pendulums and the 3-joint finger_edu load
#: by name too but are not arms.
ERD_ARMS = ("ur3", "ur5", "ur10", "panda", "kinova", "z1", "bravo7_no_ee", "xarm7",
            "ur3_limited", "ur5_limited", "ur10_limited", "ur3_gripper", "ur5_gripper",
            "panda_collision")


class RobotModelError(ValueError):
    """A URDF or robot model that rrr-pin cannot simulate (with the reason in the message)."""


def robot_names() -> tuple[str, ...]:
    """Names :func:`load_robot` accepts besides paths: ``"rrr"`` and example-robot-data arms."""
    return ("rrr",) + ERD_ARMS


def read_source(source) -> tuple[str, str, str]:
    """Return ``(urdf_text, name, source_label)`` for a path, a known name or an ArmParams.

    Raises
    ------
    TypeError, ValueError, FileNotFoundError, RobotModelError
        Not a source, an unknown name, a missing file, a directory, a file that is not UTF-8
        text.
    """
    if isinstance(source, ArmParams):
        return urdf_from_params(source), source.name, "<params>"
    if not isinstance(source, (str, Path)):
        raise TypeError(f"source must be a URDF path, a robot name or ArmParams, got "
                        f"{type(source).__name__}")
    text = str(source)
    if text == "rrr":
        return urdf_from_params(), "rrr", "rrr"
    if text in ERD_ARMS or (not text.lower().endswith(".urdf") and _erd_has(text)):
        path = erd_urdf_path(text)
        return _read_text(path), text, text
    path = Path(text)
    if path.suffix.lower() != ".urdf" and not path.exists():
        raise ValueError(f"unknown robot {text!r}: give a URDF path or one of "
                         f"{', '.join(robot_names())} (the arms of example-robot-data "
                         f"{_erd_version()}, installed)")
    if path.is_dir():
        raise RobotModelError(f"{path}: is a directory; a robot is a URDF file or a name")
    if not path.is_file():
        raise FileNotFoundError(f"URDF file not found: {path}")
    return _read_text(path), path.stem, str(path)


def nominal_params(robot) -> ArmParams | None:
    """Return the DH parameter set an arm is built from, if rrr-pin knows it; else None.

    The one place of the rule "``rrr`` means the paper's parameters": an arm loaded as
    ``"rrr"`` (with or without locked joints) is the paper's Tables 1-2, so its uncertain
    plants perturb :func:`rrr_pin.model.dh.paper_params`; any other arm (an example-robot-data
    name, a URDF file, ``ArmParams``) has its URDF perturbed instead.

    Parameters
    ----------
    robot : rrr_pin.model.dynamics.Robot
        The nominal arm; only its ``source`` label is read.

    Returns
    -------
    ArmParams or None
        ``paper_params()`` for ``robot.source == "rrr"``, otherwise None.
    """
    return paper_params() if robot.source == "rrr" else None


def _read_text(path: Path) -> str:
    """Read a URDF file as text; ``RobotModelError`` naming the file if it is not UTF-8."""
    try:
        return path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise RobotModelError(f"{path}: not a UTF-8 text file (byte {exc.start}: "
                              f"{exc.reason}); a URDF is XML text") from None


def _erd_version() -> str:
    """Return the installed example-robot-data's version (an unknown name's refusal names it)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("example-robot-data")
    except PackageNotFoundError:
        return "(version unknown)"


def _erd_has(name: str) -> bool:
    from example_robot_data.robots_loader import ROBOTS

    return name in ROBOTS


def erd_urdf_path(name: str) -> Path:
    """Path of an example-robot-data arm's URDF file; refuses a floating base."""
    from example_robot_data import robots_loader

    if name not in robots_loader.ROBOTS:
        raise ValueError(f"example-robot-data has no robot {name!r}")
    loader = robots_loader.ROBOTS[name]
    if name == "ur3" and hasattr(robots_loader, "UR3Loader"):
        # example-robot-data 5.0 maps "ur3" to UR5Loader (its ROBOTS table); its UR3Loader
        # names the UR3's own URDF.
        loader = robots_loader.UR3Loader
    root = Path(__import__("example_robot_data").getModelPath(
        f"{loader.path}/{loader.urdf_subpath}/{loader.urdf_filename}"))
    path = root / loader.path / loader.urdf_subpath / loader.urdf_filename
    if not path.is_file():
        raise FileNotFoundError(f"example-robot-data URDF for {name!r} not found at {path}")
    if getattr(loader, "free_flyer", False):
        # example-robot-data adds the floating root itself (its URDF files have no floating
        # joint), so the file can still be read as a fixed-base tree: say both, and the way.
        raise RobotModelError(
            f"example-robot-data loads {name!r} with a floating base ({loader.__name__}."
            f"free_flyer = True) and rrr-pin handles fixed-base arms only; its URDF, {path}, "
            f"has no floating joint: to use it as an arm fixed at its root link, give that "
            f"path (--robot PATH)")
    return path

"""rrr-pin: H-infinity loop shaping + feedback linearization of serial arms, Pinocchio dynamics."""

from importlib.metadata import PackageNotFoundError, version

from .dh import ArmParams, DHLink, forward_kinematics, paper_params

try:
    __version__ = version("rrr-pin")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

__all__ = [
    "__version__",
    "ArmParams",
    "DHLink",
    "forward_kinematics",
    "paper_params",
]

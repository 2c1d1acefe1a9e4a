"""rrr-pin: H-infinity loop shaping + feedback linearization of serial arms, Pinocchio dynamics.

Conventions: SI units (m, rad, kg, s, N m); standard DH ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``;
gravity along ``-z`` of the base; every controller for negative feedback on ``e = r - q``
(python-control's ``feedback(G*K)``).

The names below are imported on first use (PEP 562), so ``import rrr_pin`` and the
``rrr-pin`` command start without loading Pinocchio or python-control until needed.
"""

from __future__ import annotations

import importlib
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("rrr-pin")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

#: Public name -> submodule that defines it.
_EXPORTS = {
    "ArmParams": "dh",
    "check_inertial": "dh",
    "check_lti": "lti",
    "check_urdf_inertials": "dynamics",
    "CirclePath": "references",
    "CompiledForm": "controllers",
    "ControlLaw": "controllers",
    "default_reference": "study",
    "Design": "loopshaping",
    "design": "loopshaping",
    "DHLink": "dh",
    "expand_diagonal": "loopshaping",
    "fl_controller": "controllers",
    "forward_kinematics": "dh",
    "frozen_certificate": "certificates",
    "gapmetric": "gap",
    "hinf_fl_controller": "controllers",
    "IKError": "references",
    "LinePath": "references",
    "load_robot": "dynamics",
    "loopsyn": "loopshaping",
    "make_laws": "runner",
    "metrics": "simulation",
    "ncf_reduce": "reduction",
    "ncfmargin": "ncf",
    "ncfsyn": "loopshaping",
    "NCFSynResult": "loopshaping",
    "paper_params": "dh",
    "pd_controller": "controllers",
    "PDGravity": "controllers",
    "QuinticReference": "references",
    "reduction_guarantee": "reduction",
    "Reference": "references",
    "Robot": "dynamics",
    "robot_names": "dynamics",
    "RobotModelError": "dynamics",
    "run_laws": "runner",
    "run_study": "study",
    "RunSettings": "runner",
    "sample_plants": "uncertainty",
    "SampledLaw": "controllers",
    "simulate": "simulation",
    "SimulationDiverged": "simulation",
    "SineReference": "references",
    "SplineReference": "references",
    "StudyConfig": "study",
    "StudyResult": "study",
    "task_space_reference": "references",
    "Tolerances": "uncertainty",
    "TrackingController": "controllers",
    "Trajectory": "simulation",
}

__all__ = ["__version__", *sorted(_EXPORTS, key=str.lower)]


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'rrr_pin' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_EXPORTS))

"""rrr-pin: H-infinity loop shaping + feedback linearization of serial arms, Pinocchio dynamics.

Conventions: SI units (m, rad, kg, s, N m); standard DH ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``;
gravity along ``-z`` of the base; every controller for negative feedback on ``e = r - q``
(python-control's ``feedback(G*K)``).
"""

from importlib.metadata import PackageNotFoundError, version

from .controllers import (
    CompiledForm,
    ControlLaw,
    PDGravity,
    SampledLaw,
    TrackingController,
    fl_controller,
    hinf_fl_controller,
    pd_controller,
)
from .dh import ArmParams, DHLink, check_inertial, forward_kinematics, paper_params
from .dynamics import Robot, RobotModelError, check_urdf_inertials, load_robot, robot_names
from .gap import gapmetric
from .loopshaping import Design, NCFSynResult, design, expand_diagonal, loopsyn, ncfsyn
from .lti import check_lti
from .ncf import ncfmargin
from .reduction import ncf_reduce, reduction_guarantee
from .references import (
    CirclePath,
    IKError,
    LinePath,
    QuinticReference,
    Reference,
    SineReference,
    SplineReference,
    task_space_reference,
)
from .runner import RunSettings, make_laws, run_laws
from .simulate import SimulationDiverged, Trajectory, metrics, simulate
from .study import StudyConfig, StudyResult, default_reference, run_study
from .uncertainty import Tolerances, sample_plants

try:
    __version__ = version("rrr-pin")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

__all__ = [
    "__version__",
    "ArmParams",
    "CirclePath",
    "CompiledForm",
    "ControlLaw",
    "DHLink",
    "Design",
    "IKError",
    "LinePath",
    "NCFSynResult",
    "PDGravity",
    "QuinticReference",
    "Reference",
    "Robot",
    "RobotModelError",
    "RunSettings",
    "SampledLaw",
    "SimulationDiverged",
    "SineReference",
    "SplineReference",
    "StudyConfig",
    "StudyResult",
    "Tolerances",
    "TrackingController",
    "Trajectory",
    "check_inertial",
    "check_urdf_inertials",
    "default_reference",
    "design",
    "expand_diagonal",
    "fl_controller",
    "forward_kinematics",
    "hinf_fl_controller",
    "load_robot",
    "make_laws",
    "metrics",
    "ncfsyn",
    "gapmetric",
    "loopsyn",
    "check_lti",
    "ncfmargin",
    "ncf_reduce",
    "reduction_guarantee",
    "paper_params",
    "pd_controller",
    "robot_names",
    "run_laws",
    "run_study",
    "sample_plants",
    "simulate",
    "task_space_reference",
]

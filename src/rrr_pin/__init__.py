"""rrr-pin: H-infinity loop shaping + feedback linearization of serial arms, Pinocchio dynamics.

Conventions: SI units (m, rad, kg, s, N m); standard DH ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``;
gravity along ``-z`` of the base; every controller for negative feedback on ``e = r - q``
(python-control's ``feedback(G*K)``).

The names below are imported on first use (PEP 562), so ``import rrr_pin`` and the
``rrr-pin`` command start without loading Pinocchio or python-control until needed.
"""

import importlib.metadata as _metadata
from importlib import import_module as _import_module

try:
    __version__ = _metadata.version("rrr-pin")
except _metadata.PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

#: Public name -> submodule that defines it.
_EXPORTS = {
    "AntiWindupTracking": "control.laws",
    "ArmParams": "model.dh",
    "Campaign": "campaign.montecarlo",
    "CampaignSettings": "campaign.montecarlo",
    "CertificateSpec": "robust.certificates",
    "check_inertial": "model.dh",
    "check_lti": "robust.lti",
    "check_urdf_inertials": "model.urdf_checks",
    "CirclePath": "control.references",
    "CompiledForm": "control.laws",
    "ControlLaw": "control.laws",
    "default_reference": "control.references",
    "Design": "robust.loopshaping",
    "DiscreteTrackingController": "control.laws",
    "design": "robust.loopshaping",
    "DHLink": "model.dh",
    "expand_diagonal": "robust.lti",
    "export": "deploy.writer",
    "exported_law": "deploy.loaded",
    "fl_controller": "control.laws",
    "FLAWForm": "control.laws",
    "FLForm": "control.laws",
    "forward_kinematics": "model.dh",
    "frozen_certificate": "robust.certificates",
    "gapmetric": "robust.gap",
    "hinf_aw_controller": "control.laws",
    "hinf_fl_controller": "control.laws",
    "hinfstruct": "robust.hinfstruct",
    "HinfstructResult": "robust.hinfstruct",
    "IKError": "control.references",
    "LinearModel": "control.laws",
    "LinePath": "control.references",
    "load_design": "campaign.design_file",
    "load_robot": "model.dynamics",
    "loopsyn": "robust.loopshaping",
    "make_law": "control.catalog",
    "make_laws": "campaign.runner",
    "metrics": "sim.trajectory",
    "ncf_reduce": "robust.reduction",
    "ncfmargin": "robust.ncf",
    "ncfsyn": "robust.ncf",
    "NCFSynResult": "robust.ncf",
    "paper_params": "model.dh",
    "pd_controller": "control.laws",
    "PDForm": "control.laws",
    "PDGravity": "control.laws",
    "PlantEffects": "control.effects",
    "QuinticReference": "control.references",
    "reduction_guarantee": "robust.reduction",
    "Reference": "control.references",
    "Robot": "model.dynamics",
    "robot_names": "model.robots",
    "RobotModelError": "model.robots",
    "run_campaign": "campaign.montecarlo",
    "run_laws": "campaign.runner",
    "run_study": "campaign.study",
    "RunSettings": "campaign.runner",
    "sample_plants": "model.uncertainty",
    "SampledLaw": "control.laws",
    "simulate": "sim.simulation",
    "SimulationDiverged": "sim.trajectory",
    "SineReference": "control.references",
    "SplineReference": "control.references",
    "stress": "campaign.stress",
    "StressSettings": "campaign.stress",
    "StudyConfig": "campaign.study",
    "StudyResult": "campaign.study",
    "task_space_reference": "control.references",
    "Tolerances": "model.uncertainty",
    "TrackingController": "control.laws",
    "Trajectory": "sim.trajectory",
    "tune": "campaign.tuning",
    "TuneResult": "campaign.tuning",
    "tuned_law": "campaign.design_file",
}

__all__ = ["__version__", *sorted(_EXPORTS, key=str.lower)]


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'rrr_pin' has no attribute {name!r}")
    value = getattr(_import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    """List the public names only (``__all__``), not this module's own imports."""
    return list(__all__)

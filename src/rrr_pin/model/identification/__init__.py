r"""Dynamic identification: base inertial parameters and friction from measured torques.

The joint torques of a rigid arm are linear in the inertial parameters of its bodies and in
its joints' friction,

.. math:: \tau = Y_b(q, \dot q, \ddot q)\, \theta_b + Y_f(\dot q)\, f ,

so both are estimated by least squares, with their covariance; the standard parameters of a
physically consistent arm are then retrieved from the base ones by two semidefinite programs.
One module per concept:

- :mod:`rrr_pin.model.identification.regressors`: standard parameters, Pinocchio's regressor,
  the base parameters (Gautier 1990), :class:`IdentificationError`;
- :mod:`rrr_pin.model.identification.friction`: viscous, Coulomb and offset columns;
- :mod:`rrr_pin.model.identification.armature`: a reflected rotor inertia column per joint;
- :mod:`rrr_pin.model.identification.measurements`: logs (a CSV, per-quantity text files),
  derivatives by a zero-phase filter, irregular time stamps;
- :mod:`rrr_pin.model.identification.consistency`: the pseudo-inertia SDPs (Wensing, Kim &
  Slotine 2017) and the identified URDF;
- :mod:`rrr_pin.model.identification.estimation`: least squares, the block-sandwich
  covariance, :func:`identify`, the model-error warning, predictions;
- :mod:`rrr_pin.model.identification.crossval`: cross-validation by period, segment or
  run, per-sample prediction intervals, the repeated-motion check;
- :mod:`rrr_pin.model.identification.record`: ``identification.json``'s check and the
  uncertain plants drawn from it (:class:`IdentifiedUncertainty`);
- :mod:`rrr_pin.model.identification.sigmoid`: a nonlinear second stage, each joint's
  friction refitted with a sigmoid Coulomb term (Gaz et al. 2019).

Every public name is re-exported here (``rrr_pin.model.identification.identify``, ...).
"""

from .armature import armature_columns, armature_names, armature_regressor, with_armature
from .consistency import (
    CONSISTENCY_CONFIDENCE,
    PSEUDO_INERTIA_MARGIN,
    consistent_parameters,
    parameter_weights,
    pseudo_inertia,
    pseudo_inertia_lmis,
    urdf_with_parameters,
)
from .crossval import (
    REPEAT_DISTANCE,
    cross_validate,
    detect_period,
    prediction_interval,
    repeats_training,
)
from .estimation import (
    JACKKNIFE_BLOCKS,
    Identification,
    correlation_lag,
    friction_suspects,
    identify,
    jackknife_scale,
    least_squares,
    predict_torques,
    r_squared,
    written_distance,
)
from .friction import FRICTION_NAMES, friction_names, friction_regressor
from .measurements import (
    Measurements,
    check_in_limits,
    estimate_derivatives,
    filter_like,
    read_measurements,
    read_split_log,
    write_measurements,
)
from .record import RECORD_KEYS, IdentifiedUncertainty, check_identification_record
from .regressors import (
    RANK_RTOL,
    STANDARD_NAMES,
    BaseParameters,
    IdentificationError,
    base_parameters,
    body_links,
    joint_kinematics,
    random_states,
    regressor,
    regressor_rank,
    standard_names,
    standard_parameters,
)
from .sigmoid import refine_sigmoid_friction, sigmoid_friction

__all__ = [
    "STANDARD_NAMES",
    "IdentificationError",
    "body_links",
    "standard_parameters",
    "standard_names",
    "regressor",
    "FRICTION_NAMES",
    "friction_regressor",
    "friction_names",
    "armature_regressor",
    "armature_names",
    "armature_columns",
    "with_armature",
    "REPEAT_DISTANCE",
    "cross_validate",
    "detect_period",
    "prediction_interval",
    "repeats_training",
    "correlation_lag",
    "written_distance",
    "jackknife_scale",
    "JACKKNIFE_BLOCKS",
    "random_states",
    "BaseParameters",
    "base_parameters",
    "regressor_rank",
    "Measurements",
    "read_measurements",
    "read_split_log",
    "write_measurements",
    "estimate_derivatives",
    "filter_like",
    "check_in_limits",
    "Identification",
    "least_squares",
    "identify",
    "r_squared",
    "friction_suspects",
    "predict_torques",
    "consistent_parameters",
    "pseudo_inertia",
    "urdf_with_parameters",
    "IdentifiedUncertainty",
    "check_identification_record",
    "RECORD_KEYS",
    "RANK_RTOL",
    "PSEUDO_INERTIA_MARGIN",
    "CONSISTENCY_CONFIDENCE",
    "joint_kinematics",
    "parameter_weights",
    "pseudo_inertia_lmis",
    "sigmoid_friction",
    "refine_sigmoid_friction",
]

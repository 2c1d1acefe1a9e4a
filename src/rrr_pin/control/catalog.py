"""Names of the built-in control laws, importable without loading any numerical library.

:func:`rrr_pin.campaign.runner.make_laws` builds them; the CLI lists them in its help, which must answer
without importing Pinocchio or python-control.
"""

__all__ = ["BUILTIN_LAWS", "EFFECTS", "DEFAULT_BUDGET"]

#: Built-in laws by CLI name, with what each is.
BUILTIN_LAWS = {
    "fl": "feedback linearization alone, eq. (20), lam = 100 rad/s",
    "hinf": "H-infinity + feedback linearization, eq. (8)-(10), (18)-(19), lam = 45 rad/s",
    "pd": "PD + gravity compensation, critically damped at 20 rad/s per joint",
}

#: Effects a stress search can vary (:mod:`rrr_pin.campaign.stress`): (unit, direction: "up" = largest
#: tolerated size, "down" = smallest, what the size is).
EFFECTS = {
    "delay": ("s", "up", "actuator transport delay tau_d"),
    "actuator": ("rad/s", "down", "first-order actuator bandwidth wa"),
    "stiffness": ("N m/rad", "down", "joint stiffness K (motor inertia 0.01 kg m^2)"),
    "torque": ("N m", "down", "torque limit |tau| <= tau_max, every joint"),
    "noise": ("rad", "up", "std of the Gaussian noise on q (and 100x on qd, in rad/s)"),
}

#: RMS tracking error [rad] above which a stress run counts as broken.
DEFAULT_BUDGET = 0.05

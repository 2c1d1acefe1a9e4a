"""Names of the built-in control laws, importable without loading any numerical library.

:func:`rrr_pin.runner.make_laws` builds them; the CLI lists them in its help, which must answer
without importing Pinocchio or python-control.
"""

__all__ = ["BUILTIN_LAWS"]

#: Built-in laws by CLI name, with what each is.
BUILTIN_LAWS = {
    "fl": "feedback linearization alone, eq. (20), lam = 100 rad/s",
    "hinf": "H-infinity + feedback linearization, eq. (8)-(10), (18)-(19), lam = 45 rad/s",
    "pd": "PD + gravity compensation, critically damped at 20 rad/s per joint",
}

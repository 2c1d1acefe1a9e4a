"""One validator per kind of scalar or vector input, shared by every layer.

Each ``check_*`` converts what it accepts and raises ``ValueError`` naming the field, the value
and the expected range, in the same words everywhere:

* :func:`check_real`: a finite number;
* :func:`check_positive`: a finite number > 0 (or >= 0);
* :func:`check_count`: an integer >= a bound (sizes, samples, seeds, jobs);
* :func:`check_size`: a dimension, an integer >= 1;
* :func:`check_rate`: a sampling rate [Hz], finite and > 0;
* :func:`check_multiple`: a whole number of steps (a delay, a duration on a time grid);
* :func:`check_probability`: a number in [0, 1];
* :func:`check_vector`: a finite vector of shape (n,);
* :func:`check_direction`: a finite non-zero vector of shape (n,), returned of unit length;
* :func:`check_joint_values`: one finite value >= 0 per joint (a scalar for every joint);
* :func:`check_matrix`: a finite matrix of a given shape.

:func:`describe_value` words a value that is not what was expected (its repr and type), for
the messages about what a user's law or reference returned.

Public entry points call them once; inner loops trust what they were handed. Booleans, ``None``
and strings are refused as numbers everywhere (``float(True)`` would read a JSON ``true`` as 1).
Each raises :class:`FieldError` (a ``ValueError``) that keeps the field apart from the words,
so a caller that spells the field otherwise (a command line's ``--move-time`` for
``move_time``) can say the same sentence in its own terms (:meth:`FieldError.relabelled`).
This module imports nothing of rrr_pin: it is the bottom layer.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = [
    "FieldError",
    "check_real",
    "check_positive",
    "check_bandwidth",
    "check_scalar_bandwidth",
    "check_count",
    "check_size",
    "check_rate",
    "check_multiple",
    "MULTIPLE_RTOL",
    "check_probability",
    "check_vector",
    "check_direction",
    "check_joint_values",
    "check_matrix",
    "describe_value",
]


class FieldError(ValueError):
    """A field's value is out of its range; ``str()`` is the sentence, naming field and value.

    Attributes
    ----------
    field : str
        The field as named in the sentence.
    template : str
        The sentence with ``{name}`` where the field stands.
    """

    def __init__(self, field: str, template: str):
        super().__init__(template.format(name=field))
        self.field, self.template = field, template

    def relabelled(self, label) -> FieldError:
        """Return the same error with the field named ``label(field)``."""
        return FieldError(label(self.field), self.template)

    def __reduce__(self):
        return (type(self), (self.field, self.template))


def _fail(name: str, sentence: str) -> FieldError:
    """Build a :class:`FieldError` whose sentence starts with the field ``name``."""
    return FieldError(name, "{name}" + sentence.replace("{", "{{").replace("}", "}}"))


def _unit(unit: str) -> str:
    return f" [{unit}]" if unit else ""


def _is_number(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def check_real(name: str, value, unit: str = "") -> float:
    """Return ``value`` as a finite float.

    Parameters
    ----------
    name : str
        The field, for the message.
    value : int or float
        The value; booleans, None, strings and other non-numbers are refused.
    unit : str, optional
        Unit shown in the message (``"kg"`` gives ``"mass must be a number [kg]"``).

    Raises
    ------
    ValueError
        ``"{name} must be a number [unit], got ... (type)"`` or ``"{name} must be finite"``.
    """
    if not _is_number(value):
        raise _fail(name, f" must be a number{_unit(unit)}, got {value!r} "
                         f"({type(value).__name__})")
    value = float(value)
    if not math.isfinite(value):
        raise _fail(name, f" must be finite{_unit(unit)}, got {value!r}")
    return value


def check_positive(name: str, value, *, allow_zero: bool = False, unit: str = "") -> float:
    """Return ``value`` as a finite float > 0 (``allow_zero``: >= 0).

    Raises
    ------
    ValueError
        ``"{name} must be a finite number > 0 [unit], got ..."`` for a non-number, NaN, inf or
        a value out of range.
    """
    want = ">= 0" if allow_zero else "> 0"
    ok = _is_number(value) and math.isfinite(value) and (value >= 0 if allow_zero else value > 0)
    if not ok:
        raise _fail(name, f" must be a finite number {want}{_unit(unit)}, got {value!r}")
    return float(value)


def check_bandwidth(name: str, value, joints, *, unit: str = "rad/s"):
    """Return a bandwidth shared by every joint (a float) or one per joint (read-only vector).

    The FL bandwidth ``lam`` of the tracking laws: one number, or one value per joint of the
    law's model, each finite and > 0. A sequence of one value per joint keeps its shape (equal
    entries included), so the law records exactly what it was given.

    Parameters
    ----------
    name : str
        The field, for the message.
    value : float or array-like, shape (n,)
        The bandwidth [unit].
    joints : sequence of str
        The joint names, in order (``n = len(joints)``; named in the messages).
    unit : str
        Unit shown in the messages.

    Returns
    -------
    float or ndarray, shape (n,)
        The value checked: a float for a number, a read-only vector for a sequence.

    Raises
    ------
    FieldError
        A non-number, a wrong length (naming the joints), or a value that is not finite and
        > 0 (naming the joint).
    """
    if _is_number(value) or (isinstance(value, np.ndarray) and value.ndim == 0):
        return check_positive(name, value.item() if isinstance(value, np.ndarray) else value,
                              unit=unit)
    joints = [str(j) for j in joints]
    try:
        if value is None or isinstance(value, str):
            raise TypeError
        v = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise _fail(name, f" must be one number or one number per joint{_unit(unit)}, got "
                         f"{value!r}") from None
    if v.shape != (len(joints),):
        raise _fail(name, f" must be one number or one per joint ({len(joints)}: "
                         f"{', '.join(joints)}){_unit(unit)}, got shape {v.shape}: "
                         f"{v.tolist()}")
    for i, x in enumerate(v):
        if not (math.isfinite(x) and x > 0.0):
            raise FieldError(f"{name}[{i}]", f"{{name}} (joint {joints[i]!r}) must be a finite "
                                             f"number > 0{_unit(unit)}, got {float(x)!r}")
    v.setflags(write=False)
    return v


def check_scalar_bandwidth(name: str, value, where: str, *, unit: str = "rad/s") -> float:
    """Return ``value`` as one finite float > 0, refusing a per-joint vector by name.

    For the paths built on one FL plant ``lam^2 / (s + lam)^2`` (eq. 11): the loop-shaping
    synthesis, its certificates and the ``hinf`` laws' design. ``where`` names the path.

    Raises
    ------
    FieldError
        A sequence (a per-joint ``lam``), or a number that is not finite and > 0.
    """
    if not _is_number(value) and np.ndim(value) > 0:
        raise _fail(name, f" must be one number{_unit(unit)} for {where} (its FL plant "
                         f"lam^2/(s + lam)^2 of eq. 11 has one bandwidth), got a per-joint "
                         f"value {np.asarray(value).tolist()!r}; a per-joint lam is the tuned "
                         f"law's (rrr-pin design --per-joint-lam) and the tracking laws'")
    if isinstance(value, np.ndarray):
        value = value.item()
    return check_positive(name, value, unit=unit)


def check_count(name: str, value, low: int = 0, high: int | None = None) -> int:
    """Return ``value`` as an int >= ``low`` (an integral float such as 200.0 is accepted).

    With ``high``, also <= ``high``: the documented bound of a count whose work or memory
    grows with it (the caller names the bound in its docstring).

    Raises
    ------
    ValueError
        ``"{name} must be an integer >= {low}, got ..."`` for a bool, a string, NaN, inf, a
        fraction or a value below ``low`` (``int()`` alone would raise an unnamed ``ValueError``
        or an ``OverflowError`` for some of them); ``"... in [low, high]"`` with ``high``.
    """
    where = f">= {low}" if high is None else f"in [{low}, {high}]"
    if (not _is_number(value) or not math.isfinite(value) or value != int(value)
            or value < low or (high is not None and value > high)):
        raise _fail(name, f" must be an integer {where}, got {value!r}")
    return int(value)


def check_size(name: str, n) -> int:
    """Return a dimension ``n`` as an int >= 1 (:func:`check_count` with ``low=1``)."""
    return check_count(name, n, 1)


def check_rate(name: str, rate) -> float:
    """Return a sampling rate [Hz] as a finite float > 0.

    Raises
    ------
    ValueError
        ``"{name} must be a finite number > 0 [Hz], got ..."``.
    """
    return check_positive(name, rate, unit="Hz")


#: Relative tolerance of :func:`check_multiple`: ``value / step`` may miss an integer by this
#: much (times the integer), the round-off of a value written in decimal (``0.3 / 0.1``).
MULTIPLE_RTOL = 1e-9


def check_multiple(name: str, value: float, step: float, *, low: int = 0, unit: str = "",
                   step_name: str = "steps") -> int:
    """Return the integer ``k >= low`` with ``value = k step``, or refuse ``value``.

    A time grid realizes only whole steps: a value in between would be rounded to the grid,
    which is computing something else than what was asked. Accepted when ``value / step``
    is within :data:`MULTIPLE_RTOL` (relative) of an integer.

    Parameters
    ----------
    name : str
        The field, for the message.
    value : float
        Finite, >= 0 (checked by the caller).
    step : float
        The grid's step, > 0.
    low : int, default 0
        Smallest accepted ``k``.
    unit : str
        Unit of ``value`` and ``step``, for the message.
    step_name : str
        What the steps are, for the message (``"plant sub-steps h"``).

    Raises
    ------
    FieldError
        ``"{name} = 0.0004 s is not a whole number of <step_name> = 0.001 s (0.4 of them):
        the nearest realizable values are 0 s and 0.001 s"``, or ``value`` below ``low``
        steps.
    """
    x = value / step
    k = round(x)
    u = f" {unit}" if unit else ""
    if abs(x - k) > MULTIPLE_RTOL * max(1.0, abs(x)):
        near = [f"{j * step:.12g}{u}" for j in (math.floor(x), math.ceil(x)) if j >= low]
        which = (f"values are {near[0]} and {near[1]}" if len(near) == 2 else
                 f"value is {near[0]}")
        raise _fail(name, f" = {value:.12g}{u} is not a whole number of {step_name} = "
                          f"{step:.12g}{u} ({x:.6g} of them): the nearest realizable {which}")
    if k < low:
        raise _fail(name, f" = {value:.12g}{u} is below {low} {step_name} = {step:.12g}{u}")
    return int(k)


def check_probability(name: str, p) -> float:
    """Return ``p`` as a float in [0, 1].

    Raises
    ------
    ValueError
        ``"{name} must be a probability in [0, 1], got ..."``.
    """
    if not (_is_number(p) and 0.0 <= p <= 1.0):
        raise _fail(name, f" must be a probability in [0, 1], got {p!r}")
    return float(p)


def check_vector(name: str, value, n: int | None = None, *, readonly: bool = False) -> np.ndarray:
    """Return ``value`` as a finite float vector of shape ``(n,)`` (a scalar reads as (1,)).

    Parameters
    ----------
    name : str
        The field, for the message.
    value : array-like
        The vector.
    n : int, optional
        Required length; any length if None.
    readonly : bool, default False
        Return a read-only array (for values kept in frozen objects).

    Raises
    ------
    ValueError
        ``"{name} must be an array of numbers"``, ``"Expected {name} of shape (n,), got ..."``
        or ``"{name} must be finite, got [...]"``.
    """
    try:
        if value is None:  # np.array(None, dtype=float) would read it as NaN
            raise TypeError
        v = np.atleast_1d(np.array(value, dtype=float))
    except (TypeError, ValueError):
        raise _fail(name, f" must be an array of numbers, got {value!r}") from None
    if v.ndim != 1 or (n is not None and v.shape != (n,)):
        want = f"({n},)" if n is not None else "(n,)"
        raise FieldError(name, f"Expected {{name}} of shape {want}, got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise _fail(name, f" must be finite, got {v.tolist()}")
    if readonly:
        v.setflags(write=False)
    return v


def check_joint_values(name: str, value, joints, *, unit: str = "") -> np.ndarray:
    """Return one finite value >= 0 per joint, shape ``(len(joints),)`` (a new array).

    A per-joint physical coefficient (armature, damping, Coulomb friction): one number for
    every joint, or one per joint in the order of ``joints``.

    Parameters
    ----------
    name : str
        The field, for the message (``"armature"``).
    value : float or array-like, shape (len(joints),)
        The value(s).
    joints : sequence of str
        The joints' names, base to tip (the message names the joint of a bad value).
    unit : str, optional
        Unit shown in the message.

    Raises
    ------
    ValueError
        ``"armature has 2 values, the arm has 3 joints (j1, j2, j3): give one value, or one
        per joint"`` or ``"armature of joint 'j2' must be a finite number >= 0 [kg m^2], got
        -0.1"``.
    """
    joints = list(joints)
    try:
        if value is None or isinstance(value, (str, bytes)):
            raise TypeError
        v = np.atleast_1d(np.array(value, dtype=float)).copy()
    except (TypeError, ValueError):
        raise _fail(name, f" must be a number or one number per joint{_unit(unit)}, got "
                         f"{value!r}") from None
    if v.ndim != 1 or v.size not in (1, len(joints)):
        raise _fail(name, f" has {v.size} values, the arm has {len(joints)} joints "
                         f"({', '.join(joints)}): give one value, or one per joint")
    if v.size == 1:
        v = np.full(len(joints), v[0])
    for joint, x in zip(joints, v.tolist(), strict=True):
        if not (math.isfinite(x) and x >= 0.0):
            raise FieldError(name, f"{{name}} of joint {joint!r} must be a finite number >= 0"
                                   f"{_unit(unit)}, got {x!r}")
    return v


def check_direction(name: str, value, n: int = 3) -> np.ndarray:
    """Return the unit vector of a direction ``value``: finite, shape ``(n,)``, not zero.

    Any non-zero length is accepted, from 1e-300 to 1e300: the vector is scaled by its
    largest entry before it is normalized, so that neither ``v @ v`` nor the norm under- or
    overflows.

    Raises
    ------
    ValueError
        As :func:`check_vector`, or ``"{name} must be a non-zero vector, got [0.0, ...]"``.
    """
    v = check_vector(name, value, n)
    scale = float(np.abs(v).max()) if v.size else 0.0
    if scale == 0.0:
        raise _fail(name, f" must be a non-zero vector (a direction), got {v.tolist()}")
    v = v / scale
    return v / np.linalg.norm(v)


def check_matrix(name: str, value, shape: tuple[int, int], *,
                 readonly: bool = False) -> np.ndarray:
    """Return ``value`` as a finite float matrix of exactly ``shape``.

    Parameters
    ----------
    name : str
        The field, for the message.
    value : array-like
        The matrix.
    shape : tuple of int
        Required shape ``(rows, columns)``.
    readonly : bool, default False
        Return a read-only array (a copy if ``value`` was writable), for frozen objects.

    Raises
    ------
    ValueError
        ``"{name} must be an array of numbers"``, ``"Expected {name} of shape (r, c), got ..."``
        or ``"{name} must be finite, got [[...]]"``.
    """
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise _fail(name, f" must be an array of numbers, got {value!r}") from None
    if arr.shape != tuple(shape):
        raise FieldError(name, f"Expected {{name}} of shape {tuple(shape)}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise _fail(name, f" must be finite, got {arr.tolist()}")
    if readonly and arr.flags.writeable:
        arr = arr.copy()
        arr.setflags(write=False)
    return arr


def describe_value(value) -> str:
    """Return a value's ``repr`` (cut at 80 characters) and type, for an error message."""
    text = repr(value)
    return f"{text[:80]}{'...' if len(text) > 80 else ''} ({type(value).__name__})"

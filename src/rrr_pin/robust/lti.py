"""LTI inputs at the edge of the analysis API: validation, diagonal copies, bilinear maps.

Every public function of :mod:`rrr_pin.robust.ncf`, :mod:`rrr_pin.robust.gap`,
:mod:`rrr_pin.robust.reduction` and :mod:`rrr_pin.robust.loopshaping` that takes a
python-control system calls :func:`check_lti` first.
It checks the raw coefficients *before* any python-control conversion (python-control 0.10's
``ss(tf)`` never returns on a NaN numerator), so bad input gets a named error:

* :class:`NonFiniteSystemError` - NaN or inf in a coefficient or matrix;
* :class:`ImproperSystemError` - a transfer-function entry with more zeros than poles;
* :class:`DimensionMismatchError` - sizes that do not fit together;
* :class:`TimebaseMismatchError` - continuous and discrete time mixed, or two sampling times;
* :class:`IllPosedLoopError` - ``I + D_P D_C`` singular: the loop has no solution.

Discrete-time systems are handled by the exact bilinear (Cayley) map
``z = (1 + s) / (1 - s)``: it maps the unit disc onto the open left half-plane and the unit
circle onto the imaginary axis, so stability, H-infinity norms, normalized coprime factors,
the NCF margin and the gap metrics of a discrete system are those of its image
(:func:`to_continuous`, :func:`to_discrete`).

References
----------
.. [1] K. Zhou, J. C. Doyle and K. Glover, *Robust and Optimal Control*, Prentice Hall, 1996,
   (discrete-time problems by the bilinear transformation).
"""

from __future__ import annotations

import numbers

import control
import numpy as np

from ..validation import check_size

__all__ = [
    "LTIInputError",
    "NonFiniteSystemError",
    "ImproperSystemError",
    "DimensionMismatchError",
    "TimebaseMismatchError",
    "IllPosedLoopError",
    "check_lti",
    "common_timebase",
    "expand_diagonal",
    "static_gain",
    "to_continuous",
    "to_discrete",
]


class LTIInputError(ValueError):
    """Base class of the LTI input errors of rrr-pin."""


class NonFiniteSystemError(LTIInputError):
    """A system has NaN or inf coefficients."""


class ImproperSystemError(LTIInputError):
    """A transfer function has a numerator of higher degree than its denominator."""


class DimensionMismatchError(LTIInputError):
    """Two systems (or a system and a size) do not fit together."""


class TimebaseMismatchError(LTIInputError):
    """Continuous and discrete time mixed, or two different sampling times."""


class IllPosedLoopError(LTIInputError):
    """The feedback loop is ill-posed: ``I + D_P D_C`` is singular."""


def static_gain(D) -> control.StateSpace:
    """State-space system with no states and feedthrough ``D``, shape (p, m)."""
    D = np.atleast_2d(np.asarray(D, dtype=float))
    return control.ss(np.zeros((0, 0)), np.zeros((0, D.shape[1])),
                      np.zeros((D.shape[0], 0)), D)


def _dt_ok(name: str, dt):
    if dt is None or dt is True or dt == 0:
        return dt
    if isinstance(dt, numbers.Real) and np.isfinite(dt) and dt > 0:
        return dt
    raise TimebaseMismatchError(f"{name} has an invalid sampling time dt={dt!r}; expected 0 "
                                "(continuous), True or a positive finite period [s]")


def check_lti(sys, name: str = "sys") -> control.StateSpace:
    """Validate an LTI system (or a constant gain) and return it as a ``StateSpace``.

    The coefficients are checked before python-control converts anything.

    Parameters
    ----------
    sys : control.StateSpace, control.TransferFunction, float or array-like, shape (p, m)
        System, or a static gain (a scalar or a 2-D array).
    name : str
        Name used in the error messages (e.g. ``"K"``).

    Returns
    -------
    control.StateSpace
        The same system, with the same sampling time (static gains get ``dt = None``,
        compatible with either timebase).

    Raises
    ------
    NonFiniteSystemError
        A NaN or inf coefficient or matrix entry.
    ImproperSystemError
        A transfer-function entry with numerator degree > denominator degree, or a zero
        denominator.
    TimebaseMismatchError
        An invalid sampling time.
    TypeError
        Not an LTI system or a numeric gain (e.g. a frequency-response data object).
    """
    if isinstance(sys, control.TransferFunction):
        _dt_ok(name, sys.dt)
        for i in range(sys.noutputs):
            for j in range(sys.ninputs):
                num = np.atleast_1d(np.asarray(sys.num[i][j], dtype=float))
                den = np.atleast_1d(np.asarray(sys.den[i][j], dtype=float))
                if not (np.all(np.isfinite(num)) and np.all(np.isfinite(den))):
                    raise NonFiniteSystemError(
                        f"{name} has non-finite coefficients in entry ({i}, {j}): "
                        f"num={num.tolist()}, den={den.tolist()}")
                num, den = np.trim_zeros(num, "f"), np.trim_zeros(den, "f")
                if den.size == 0:
                    raise ImproperSystemError(f"{name} entry ({i}, {j}) has a zero denominator")
                if num.size > den.size:
                    raise ImproperSystemError(
                        f"{name} must be proper, entry ({i}, {j}) has numerator degree "
                        f"{num.size - 1} > denominator degree {den.size - 1}")
        return control.ss(sys)
    if isinstance(sys, control.StateSpace):
        _dt_ok(name, sys.dt)
        for key in ("A", "B", "C", "D"):
            M = np.asarray(getattr(sys, key), dtype=float)
            if not np.all(np.isfinite(M)):
                raise NonFiniteSystemError(f"{name} has non-finite entries in its {key} matrix")
        return sys
    if isinstance(sys, control.LTI) or isinstance(sys, (str, bytes, bool)):
        raise TypeError(f"Expected {name} as a StateSpace, a TransferFunction or a numeric "
                        f"gain, got {type(sys).__name__}")
    try:
        D = np.asarray(sys, dtype=float)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"Expected {name} as an LTI system or a numeric gain, got "
                        f"{type(sys).__name__}") from exc
    if D.ndim > 2:
        raise DimensionMismatchError(f"Expected {name} as a 2-D gain, got shape {D.shape}")
    if not np.all(np.isfinite(D)):
        raise NonFiniteSystemError(f"{name} has non-finite gain entries: {D.tolist()}")
    return static_gain(np.atleast_2d(D))


def _is_static(sys: control.StateSpace) -> bool:
    return sys.nstates == 0


def common_timebase(*named) -> float | bool | None:
    """Return the common sampling time of ``(name, StateSpace)`` pairs (static gains fit any).

    Returns
    -------
    0 for continuous time, a period [s] (or ``True``) for discrete time, ``None`` when all
    systems are static gains.

    Raises
    ------
    TimebaseMismatchError
        Continuous and discrete systems mixed, or two different sampling times.
    """
    dt, first = None, None
    for name, sys in named:
        d = sys.dt
        if _is_static(sys) or d is None:
            continue
        if dt is None:
            dt, first = d, name
        elif (d == 0) != (dt == 0) or (d != dt and d is not True and dt is not True):
            what = "continuous" if dt == 0 else f"discrete (dt={dt!r})"
            raise TimebaseMismatchError(
                f"{name} has dt={d!r} but {first} is {what}: do not mix continuous- and "
                "discrete-time systems or sampling times")
    return dt


def expand_diagonal(K, n: int) -> control.StateSpace:
    """Block-diagonal ``n x n`` copy ``diag(K, ..., K)`` of a SISO system.

    Parameters
    ----------
    K : control.LTI
        SISO system (e.g. the design's controller).
    n : int
        Number of copies (joints).

    Returns
    -------
    control.StateSpace
        ``n x n`` system with ``n`` times the states of ``K``, same sampling time.
    """
    n = check_size("n", n)
    K = check_lti(K, "K")
    if (K.noutputs, K.ninputs) != (1, 1):
        raise ValueError(f"Expected a SISO system, got shape ({K.noutputs}, {K.ninputs})")
    A, B, C, D = (np.asarray(M, dtype=float) for M in (K.A, K.B, K.C, K.D))
    eye = np.eye(n)
    return control.ss(np.kron(eye, A), np.kron(eye, B), np.kron(eye, C), np.kron(eye, D),
                      K.dt)


def to_continuous(sys: control.StateSpace) -> control.StateSpace:
    r"""Continuous-time image of a discrete system by the bilinear map ``z = (1 + s)/(1 - s)``.

    .. math:: G_c(s) = G_d\left(\frac{1 + s}{1 - s}\right),\quad
              A_c = (I + A)^{-1}(A - I),\ B_c = \sqrt2 (I + A)^{-1} B,\
              C_c = \sqrt2\, C (I + A)^{-1},\ D_c = D - C (I + A)^{-1} B

    ``G_c(j \tan(\theta/2)) = G_d(e^{j\theta})``: norms, stability and coprime factors are
    preserved. Requires no eigenvalue of ``A`` at ``z = -1`` (the Nyquist frequency).

    Raises
    ------
    ValueError
        ``A`` has an eigenvalue at ``z = -1``.
    """
    A, B, C, D = (np.asarray(M, dtype=float) for M in (sys.A, sys.B, sys.C, sys.D))
    n = A.shape[0]
    if n == 0:
        return static_gain(D)
    IA = np.eye(n) + A
    if np.linalg.cond(IA) > 1e12:
        raise ValueError("the discrete system has a pole at z = -1 (Nyquist frequency); "
                         "the bilinear map to continuous time is not defined")
    Ac = np.linalg.solve(IA, A - np.eye(n))
    Bi = np.linalg.solve(IA, B)
    Ci = np.linalg.solve(IA.T, C.T).T
    return control.ss(Ac, np.sqrt(2.0) * Bi, np.sqrt(2.0) * Ci, D - C @ Bi)


def to_discrete(sys: control.StateSpace, dt) -> control.StateSpace:
    r"""Inverse of :func:`to_continuous`: ``s = (z - 1)/(z + 1)``, sampling time ``dt``.

    .. math:: A = (I + A_c)(I - A_c)^{-1},\ B = \sqrt2 (I - A_c)^{-1} B_c,\
              C = \sqrt2\, C_c (I - A_c)^{-1},\ D = D_c + C_c (I - A_c)^{-1} B_c

    Raises
    ------
    ValueError
        ``A_c`` has an eigenvalue at ``s = 1`` (mapped to ``z = infinity``).
    """
    A, B, C, D = (np.asarray(M, dtype=float) for M in (sys.A, sys.B, sys.C, sys.D))
    n = A.shape[0]
    if n == 0:
        return control.ss(A, B, C, D, dt)
    IA = np.eye(n) - A
    if np.linalg.cond(IA) > 1e12:
        raise ValueError("the continuous system has a pole at s = 1; its bilinear image has "
                         "a pole at infinity")
    Bi = np.linalg.solve(IA, B)
    Ci = np.linalg.solve(IA.T, C.T).T
    Ad = np.linalg.solve(IA.T, (np.eye(n) + A).T).T
    return control.ss(Ad, np.sqrt(2.0) * Bi, np.sqrt(2.0) * Ci, D + C @ Bi, dt)

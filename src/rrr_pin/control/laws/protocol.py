"""The control-law protocol: continuous and sampled laws, and the checks at the engine's edge.

:class:`ControlLaw` (continuous time) and :class:`SampledLaw` (discrete time, zero-order hold)
are the two bases every law subclasses, a user's or a built-in; :class:`LinearModel` is what a
law may tell ``rrr-pin stress`` of the loop it closes. :func:`check_law`,
:func:`check_law_output` and :func:`check_step_output` are the validators of a law where it
meets an engine. A law reads its model through the plant protocol only
(:meth:`rrr_pin.model.plant.Plant.terms` and :meth:`~rrr_pin.model.plant.Plant.G`), so every
law runs on every plant, serial arm or closed chain.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

import numpy as np

from ...model.plant import Plant
from ...validation import check_rate, describe_value

if TYPE_CHECKING:
    from .forms import CompiledForm

__all__ = ["LawBase", "ModelLaw", "ControlLaw", "SampledLaw", "LinearModel", "SampledForm",
           "StaticSampled", "check_law", "check_law_output", "check_step_output", "DEFAULT_RATE"]

#: Default sampling rate of the sampled (digital) controllers [Hz].
DEFAULT_RATE = 1000.0

_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


class LinearModel:
    r"""The linear loop a law closes around the arm, for the predictions of ``stress``.

    Regulation (``r = 0``) with the law's model exact; the loop is broken at the torque input.
    :mod:`rrr_pin.campaign.stress` asks a law for it (:meth:`ControlLaw.linear_model`) and
    builds its digital and continuous predictions from these three methods.

    Attributes
    ----------
    n : int
        Number of joints (set by each subclass).
    """

    def digital(self, rate: float, home) -> tuple:
        """Return the law sampled at ``rate`` [Hz] and the plant's ``M^-1`` at ``home`` [rad].

        Returns
        -------
        Ac, Bc, Cc, Dc : ndarray, shapes (m, m), (m, 2n), (n, m), (n, 2n)
            The discrete law ``u = Cc x + Dc [q; qd]``, ``x+ = Ac x + Bc [q; qd]`` [N m].
        Minv : ndarray, shape (n, n)
            The plant ``qdd = Minv u`` [1/(kg m^2)].
        """
        raise NotImplementedError(f"{type(self).__name__} must implement digital()")

    def loops(self, home) -> list:
        """Return the SISO loops ``L(s)`` (``control.TransferFunction``), one per mode or joint."""
        raise NotImplementedError(f"{type(self).__name__} must implement loops()")

    def bandwidth(self, home) -> float:
        """Return the slowest closed-loop natural frequency [rad/s]."""
        raise NotImplementedError(f"{type(self).__name__} must implement bandwidth()")


class LawBase:
    """What every law has, continuous or sampled: names, sizes, its reset and its forms.

    Subclass :class:`ControlLaw` or :class:`SampledLaw`, never this class itself.

    Attributes
    ----------
    name : str
        Short key, used in results, CSV columns and the CLI (letters, digits, ``_``).
    label : str
        Human-readable name for figures and tables.
    n : int
        Number of joints.
    nx : int
        Size of the law's state ``x`` (0 for a static law).
    """

    name: str = "law"
    label: str = ""
    n: int = 0
    nx: int = 0

    def initial_state(self) -> np.ndarray:
        """Return the law's state at ``t = 0``, shape (nx,) (zeros by default)."""
        return np.zeros(self.nx)

    def reset(self, q) -> None:
        """Forget what the law carries from one run to the next, at the actuated ``q`` [rad].

        The simulator calls it at the start of every run with ``r(0)``, so that a run depends
        on its own inputs only. By default it resets the law's model, ``self.nominal`` when the
        law has one (:meth:`rrr_pin.model.plant.Plant.reset`: a closed chain re-seeds its
        loop-closure solver on its home branch); override it for state of your own.
        """
        nominal = getattr(self, "nominal", None)
        if isinstance(nominal, Plant):
            nominal.reset(q)

    def compiled_form(self) -> CompiledForm | None:
        """Return the compiled engine's exact equivalent of this law, or None (Python only)."""
        return None

    def linear_model(self) -> LinearModel | None:
        """Return the linear loop this law closes on the arm, or None (no linear prediction)."""
        return None


class ModelLaw:
    """Mixin of a built-in law on a model ``nominal`` with its matrices in ``_mats``.

    ``n`` is the model's number of (actuated) joints, ``nx`` the size of the state matrix
    ``_mats[0]`` (0 for FL alone, whose ``A`` is empty).
    """

    @property
    def n(self) -> int:
        """Number of joints."""
        return self.nominal.nq

    @property
    def nx(self) -> int:
        """Number of controller states."""
        return self._mats[0].shape[0]


class ControlLaw(LawBase):
    """Base class of a continuous-time control law.

    Subclasses implement :meth:`torque`; a law with its own state also sets :attr:`nx`,
    implements :meth:`derivative` and, to run sampled, :meth:`sampled`. Names, sizes,
    :meth:`~LawBase.reset` and the forms are :class:`LawBase`'s.
    """

    def torque(self, t, q, qd, r, rd, rdd, x) -> np.ndarray:
        """Joint torque [N m], shape (n,).

        Parameters
        ----------
        t : float
            Time [s].
        q, qd : ndarray, shape (n,)
            Measured joint positions [rad] and velocities [rad/s].
        r, rd, rdd : ndarray, shape (n,)
            Reference position [rad], velocity [rad/s] and acceleration [rad/s^2].
        x : ndarray, shape (nx,)
            The law's state.
        """
        raise NotImplementedError(f"{type(self).__name__} must implement torque()")

    def derivative(self, t, q, qd, r, rd, rdd, x) -> np.ndarray:
        """Time derivative of the law's state, shape (nx,) (none by default)."""
        return np.zeros(self.nx)

    def sampled(self, rate: float, method: str = "tustin") -> SampledLaw:
        """Return the law run by a digital controller at ``rate`` Hz (zero-order hold).

        A static law (``nx == 0``) is sampled exactly by evaluating :meth:`torque` at the
        sampling instants. A law with state must override this method (it has to say how its
        state is discretized); otherwise ``NotImplementedError``.
        """
        if self.nx:
            raise NotImplementedError(
                f"law {self.name!r} has {self.nx} states and does not say how to discretize "
                f"them: override sampled(rate) or write it as a SampledLaw")
        return StaticSampled(self, check_rate("rate", rate))


    def describe(self) -> dict:
        """JSON-ready description of the law (recorded in results)."""
        return {"name": self.name, "label": self.label or self.name,
                "class": f"{type(self).__module__}.{type(self).__qualname__}",
                "time": "continuous"}


class SampledLaw(LawBase):
    """Base class of a discrete-time (digital) law sampled at :attr:`rate` Hz.

    Subclasses implement :meth:`step`. The simulator calls it at ``t_k = k / rate`` with the
    measured state and holds the returned torque until ``t_{k+1}``.

    Attributes
    ----------
    name, label, n, nx
        As for :class:`LawBase`.
    rate : float
        Sampling rate [Hz].
    """

    rate: float = DEFAULT_RATE


    def step(self, t, q, qd, r, rd, rdd, x) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(tau, x_next)``: the torque held on ``[t, t + 1/rate)`` and the next state.

        Arguments as for :meth:`ControlLaw.torque`.
        """
        raise NotImplementedError(f"{type(self).__name__} must implement step()")


    def describe(self) -> dict:
        """JSON-ready description of the law."""
        return {"name": self.name, "label": self.label or self.name,
                "class": f"{type(self).__module__}.{type(self).__qualname__}",
                "time": "sampled", "rate_hz": self.rate}


def check_law(law, n: int | None = None) -> None:
    """Check that ``law`` is a :class:`ControlLaw` or :class:`SampledLaw` for ``n`` joints.

    Raises
    ------
    TypeError
        Not a law.
    ValueError
        Bad name, or the wrong number of joints.
    """
    if not isinstance(law, (ControlLaw, SampledLaw)):
        raise TypeError(f"a control law must subclass rrr_pin.ControlLaw or rrr_pin.SampledLaw, "
                        f"got {type(law).__name__}")
    if not isinstance(law.name, str) or not _NAME.match(law.name):
        raise ValueError(f"law name must be letters, digits and '_' starting with a letter, got "
                         f"{law.name!r}")
    if n is not None and law.n != n:
        raise ValueError(f"law {law.name!r} is for {law.n} joints, the plant has {n}")
    if int(law.nx) != law.nx or law.nx < 0:
        raise ValueError(f"law {law.name!r}: nx must be an integer >= 0, got {law.nx!r}")


def _kind(law) -> str:
    """Return the law's class for a message (a continuous law sampled here: its own class)."""
    inner = getattr(law, "law", None)
    if type(law).__name__.startswith("_") and inner is not None:
        return f"{type(inner).__name__}, sampled at {law.rate:g} Hz"
    return type(law).__name__


def check_law_output(law, method: str, value, size: int, t: float) -> np.ndarray:
    """Check one value a law returned: a finite float ndarray of shape ``(size,)``.

    The simulator calls it on a law's first outputs (the edge where a user's law meets the
    engine) and trusts the later ones; a NaN or inf torque later in a run stops the run with
    its own reason (:data:`rrr_pin.sim.trajectory.REASONS`).

    Parameters
    ----------
    law : ControlLaw or SampledLaw
        The law, named in the message.
    method : str
        What returned ``value``, e.g. ``"torque()"``, ``"step() torque"``.
    value : object
        The returned value.
    size : int
        Required length (``n`` for a torque [N m], ``nx`` for a state).
    t : float
        Time of the call [s].

    Returns
    -------
    ndarray, shape (size,)
        ``value`` itself.

    Raises
    ------
    ValueError
        Naming the law, its class, the method, the time and what it returned: not a NumPy
        array (a scalar, None, a list), an array of another shape or of non-numbers, or an
        array with NaN or inf.
    """
    where = (f"law {law.name!r} ({_kind(law)}): {method} returned {{what}} at "
             f"t = {t:.6g} s; expected a finite float64 ndarray of shape ({size},)")
    if not isinstance(value, np.ndarray):
        raise ValueError(where.format(what=describe_value(value)))
    if value.shape != (size,) or value.dtype != np.float64:
        raise ValueError(where.format(what=f"an array of shape {value.shape} and dtype "
                                           f"{value.dtype}"))
    if not np.all(np.isfinite(value)):
        raise ValueError(where.format(what=f"the non-finite {value.tolist()}"))
    return value


def check_step_output(law, out, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Check what :meth:`SampledLaw.step` returned: ``(tau, x_next)`` (:func:`check_law_output`)."""
    if not isinstance(out, tuple) or len(out) != 2:
        raise ValueError(f"law {law.name!r} ({_kind(law)}): step() returned "
                         f"{describe_value(out)} at t = {t:.6g} s; expected a tuple (tau, x_next)")
    return (check_law_output(law, "step() torque", out[0], law.n, t),
            check_law_output(law, "step() next state", out[1], law.nx, t))


class SampledForm(SampledLaw):
    """The sampled form of a continuous law ``law`` at ``rate`` [Hz]: the base of the wrappers.

    Names, sizes and :meth:`reset` are the continuous law's.
    """

    def __init__(self, law: ControlLaw, rate: float):
        self.law, self.rate = law, rate
        self.name, self.label, self.n, self.nx = law.name, law.label, law.n, law.nx

    def reset(self, q) -> None:
        """Reset the continuous law (:meth:`ControlLaw.reset`)."""
        self.law.reset(q)


class StaticSampled(SampledForm):
    """A static continuous law evaluated at the sampling instants (exact for ``nx = 0``)."""

    def __init__(self, law: ControlLaw, rate: float):
        super().__init__(law, rate)
        self.nx = 0

    def step(self, t, q, qd, r, rd, rdd, x):
        """Evaluate the continuous law's torque; no state."""
        return self.law.torque(t, q, qd, r, rd, rdd, x), x

    def compiled_form(self):
        """Return the continuous law's compiled form (a static law samples exactly)."""
        return self.law.compiled_form()

    def describe(self):
        """Describe the continuous law, sampled."""
        return {**self.law.describe(), "time": "sampled", "rate_hz": self.rate}

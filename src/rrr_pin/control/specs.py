"""A built-in reference named by its kind and options, as a command line or a file gives it.

:class:`ReferenceSpec` is a frozen record of the options (``kind`` one of :data:`KINDS`);
:meth:`ReferenceSpec.build` checks them once, against the arm, and returns the
:class:`~rrr_pin.control.references.Reference` they name. Messages name each option as the
caller spells it (``label``): ``rrr-pin`` passes ``"--move-time"`` for ``move_time``.

A user's own reference needs no spec: any :class:`~rrr_pin.control.references.Reference`
instance is accepted wherever a reference is.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..model.plant import FRAMES
from ..validation import FieldError, check_direction, check_positive, check_vector
from .catalog import REFERENCES
from .paths import circle_from_start, task_start
from .references import (
    LinePath,
    QuinticReference,
    Reference,
    SplineReference,
    default_reference,
    study_reference,
    task_space_reference,
)

__all__ = ["KINDS", "ReferenceSpec"]

#: Built-in reference kinds and what each is (:data:`rrr_pin.control.catalog.REFERENCES`).
KINDS = REFERENCES


#: The options each kind reads ("study" reads the sinusoid's: a plant with a task path refuses
#: them when it is built); any other option given is refused, never ignored.
_OPTIONS_OF_KIND = {
    "sine": ("amp", "freq", "home"),
    "study": ("amp", "freq", "home"),
    "spline": ("csv",),
    "quintic": ("home", "to", "move_time"),
    "line": ("home", "move_time", "frame", "end"),
    "circle": ("home", "move_time", "frame", "radius", "normal"),
    "all": ("amp", "freq", "home", "to", "move_time", "csv", "frame", "end", "radius",
            "normal"),
}


@dataclass(frozen=True)
class ReferenceSpec:
    """Options of a built-in reference (SI units; joint values per joint, in joint order).

    Parameters
    ----------
    kind : str
        One of :data:`KINDS`; ``"study"`` (the plant's own study reference,
        :func:`~rrr_pin.control.references.study_reference`) is the sinusoid of ``"sine"`` for
        a plant without a task path, and that path for one with it (then the sinusoid's
        options are refused).
    amp, freq : float
        ``sine``: amplitude [rad] and frequency [Hz], finite and >= 0.
    home : tuple of float, shape (n,), optional
        Centre of the sinusoid, start of a quintic or task-space motion [rad]; default the
        URDF's neutral configuration (moved inside the limits), and for a task-space motion
        :func:`~rrr_pin.control.paths.task_start` (the neutral one unless the frame is
        singular there).
    to : tuple of float, shape (n,), optional
        ``quintic``: goal [rad].
    move_time : float, optional
        ``quintic``, ``line``, ``circle``: duration of the motion [s], > 0; default half the
        run's duration.
    csv : str, optional
        ``spline``: path of the waypoint file.
    frame : str, optional
        ``line``, ``circle``: frame whose origin moves; default the model's last frame.
    end : tuple of float, shape (3,), optional
        ``line``: end point [m] in the base frame; the line starts where the frame is at home.
    radius : float, optional
        ``circle``: radius [m], > 0; the circle starts where the frame is at home.
    normal : tuple of float, shape (3,), default (0, 0, 1)
        ``circle``: normal of its plane (base frame).
    """

    kind: str = "sine"
    amp: float = 0.5
    freq: float = 0.5
    home: tuple | None = None
    to: tuple | None = None
    move_time: float | None = None
    csv: str | None = None
    frame: str | None = None
    end: tuple | None = None
    radius: float | None = None
    normal: tuple = (0.0, 0.0, 1.0)

    def given(self) -> tuple[str, ...]:
        """Return the options set away from their defaults, in field order (``kind`` aside)."""
        return tuple(key for key in _OPTIONS_OF_KIND["all"]
                     if getattr(self, key) != _DEFAULTS[key])

    def _reads(self) -> tuple[str, ...]:
        """Return the options this spec's kind reads."""
        return _OPTIONS_OF_KIND.get(self.kind, _OPTIONS_OF_KIND["all"])

    def _check_options_of(self, kind: str, label: Callable[[str], str]) -> None:
        """Refuse an option the reference ``kind`` does not read (it would be ignored)."""
        reads = self._reads()
        stray = [key for key in self.given() if key not in reads]
        if stray:
            users = {key: [k for k in KINDS
                           if k != "study" and key in _OPTIONS_OF_KIND.get(k, ())]
                     for key in stray}
            raise ValueError(
                f"{', '.join(label(key) for key in stray)} "
                f"{'is' if len(stray) == 1 else 'are'} not read by {label('reference')} "
                f"{kind}: " + "; ".join(f"{label(key)} belongs to {' or '.join(users[key])}"
                                        for key in stray)
                + f" (give {label('reference')} KIND, or drop the option)")

    def build(self, robot, duration: float, *,
              label: Callable[[str], str] = str) -> Reference:
        """Check the options against ``robot`` and return the reference they name.

        Parameters
        ----------
        robot : Plant
            The plant (joint count, limits, frames, task path).
        duration : float
            Length of the run [s], > 0 (the default ``move_time`` is half of it).
        label : callable, default str
            How the caller spells an option, for messages (``"move_time"`` -> ``"--move-time"``).

        Raises
        ------
        ValueError
            An unknown kind, a missing or out-of-range option (named by ``label``), a reference
            that leaves the joint limits; :class:`~rrr_pin.control.references.IKError` for an
            unreachable task-space point.
        """
        n = robot.nq
        kind = self.kind
        if kind not in KINDS:
            raise ValueError(f"{label('reference')} {kind!r} is unknown; known: "
                             f"{', '.join(KINDS)}")
        self._check_options_of(kind, label)
        home = None if self.home is None else check_vector(label("home"), self.home, n)
        if kind == "study":
            if robot.task_path(duration) is None:
                kind = "sine"
            else:
                given = [label(k) for k, on in (("home", self.home is not None),
                                                ("amp", self.amp != 0.5),
                                                ("freq", self.freq != 0.5)) if on]
                if given:
                    raise ValueError(f"{', '.join(given)} shape(s) a sinusoid; the study "
                                     f"reference of {robot.name!r} is its task path (give "
                                     f"{label('reference')} sine for a sinusoid)")
                return study_reference(robot, duration)
        if kind == "sine":
            amp = check_positive(label("amp"), self.amp, allow_zero=True)
            freq = check_positive(label("freq"), self.freq, allow_zero=True)
            try:
                return default_reference(robot, amp=amp, freq=freq, home=home)
            except FieldError as exc:  # an amplitude the limits cannot hold, as the caller says
                raise exc.relabelled(label) from None
        if kind == "spline":
            if self.csv is None:
                raise ValueError(f"{label('reference')} spline needs {label('csv')} PATH")
            return SplineReference.from_csv(self.csv, robot)
        start = home if home is not None else np.clip(robot.neutral(), robot.lower, robot.upper)
        move = (0.5 * check_positive("duration", duration) if self.move_time is None
                else check_positive(label("move_time"), self.move_time))
        if kind == "quintic":
            if self.to is None:
                raise ValueError(f"{label('reference')} quintic needs {label('to')} Q1,Q2,... "
                                 f"(the goal, one value per joint)")
            return QuinticReference(start, check_vector(label("to"), self.to, n), move)
        robot.require(FRAMES, f"{label('reference')} {kind}")
        frame = self.frame or robot.model.frames[len(robot.model.frames) - 1].name
        if home is None:
            start = task_start(robot, frame)  # neutral, unless singular there (see task_start)
        p0 = robot.frame_placement(start, frame)[:3, 3]
        if kind == "line":
            if self.end is None:
                raise ValueError(f"{label('reference')} line needs {label('end')} X,Y,Z [m]")
            path = LinePath(p0, check_vector(label("end"), self.end, 3))
        else:
            if self.radius is None:
                raise ValueError(f"{label('reference')} circle needs {label('radius')} R [m]")
            path = circle_from_start(p0, check_positive(label("radius"), self.radius),
                                     check_direction(label("normal"), self.normal, 3))
        return task_space_reference(robot, frame, path, move, q_start=start)


#: The defaults of :class:`ReferenceSpec`'s options (an option is "given" when it differs).
_DEFAULTS = {key: getattr(ReferenceSpec, key) for key in _OPTIONS_OF_KIND["all"]}

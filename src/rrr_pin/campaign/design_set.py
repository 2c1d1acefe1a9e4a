"""The loop a design is judged on: its effects, default requirement, plants, and failures.

:func:`design_effects` is the delay and actuator every requirement is evaluated behind;
:func:`design_tolerances` the default plant set; :func:`with_default_requirements` adds the
lower gain margin; :func:`plant_failures` and :func:`simulated_failures` name the requirement
and the plant that failed. :func:`rrr_pin.campaign.tuning.tune` calls them.
"""

from __future__ import annotations

import numpy as np

from ..validation import FieldError
from .requirements import ActuatorBandwidth, DelayMargin

__all__ = ["DEFAULT_LOWER_GAIN_MARGIN", "DESIGN_ARMATURE_TOLERANCE", "with_default_requirements",
           "design_effects", "design_tolerances", "check_plant_set", "plant_failures",
           "simulated_failures", "number_text"]


def number_text(x) -> str:
    """Return a requirement table's number as printed: ``-`` for None, text as is, 4 digits."""
    if x is None:
        return "-"
    if isinstance(x, str):
        return x
    return f"{x:.4g}"


#: Lower gain margin every design must have unless a requirement states its own: the loop
#: stays stable with every torque scaled by any factor in ``[0.5, 1]`` (6 dB), e.g. a real
#: arm whose inertia (rotor armature) is up to twice the model's on the loop's directions.
DEFAULT_LOWER_GAIN_MARGIN = 0.5


def with_default_requirements(reqs) -> list:
    """Add ``lower_gain_margin`` (:data:`DEFAULT_LOWER_GAIN_MARGIN`) unless one is given.

    ``LowerGainMargin(1.0)`` (any gain reduction may destabilize) turns it off.
    """
    from .requirements import LowerGainMargin

    if any(isinstance(r, LowerGainMargin) for r in reqs):
        return list(reqs)
    return [*reqs, LowerGainMargin(DEFAULT_LOWER_GAIN_MARGIN, default=True)]


def design_effects(reqs, fixed) -> dict:
    """Return the effects the design's loop runs with: ``fixed`` and the requirements'.

    ``actuator_bandwidth=WA,delay=TAU`` states an actuator ``WA`` and a delay ``TAU`` the
    loop runs behind; ``delay_margin=...,actuator=WA`` an actuator. Of several, the largest
    delay and the slowest actuator.

    Returns
    -------
    dict
        ``{"delay": s, "actuator": rad/s}`` (keys only for the effects present).

    Raises
    ------
    FieldError
        ``requirements``: a delay present (held or stated) at or above the required delay
        margin, which no loop can then have.
    """
    out = {k: v for k, v in fixed.items() if k in ("delay", "actuator")}

    def put(key, value, pick):
        if value:
            out[key] = pick(out[key], value) if key in out else value
    for r in reqs:
        if isinstance(r, ActuatorBandwidth):
            put("actuator", r.target, min)
            put("delay", r.delay, max)
        elif isinstance(r, DelayMargin):
            put("actuator", r.actuator, min)
    for r in reqs:
        if isinstance(r, DelayMargin) and out.get("delay", 0.0) >= r.target:
            raise FieldError("requirements", f"{{name}}: delay_margin = {r.target:g} s with a "
                                             f"delay of {out['delay']:g} s present "
                                             f"contradicts: the margin counts the whole delay "
                                             f"the loop tolerates, the present one included")
    return out


def design_tolerances():
    """Return the plant set of a design drawn from a count: the paper's box, armature +-50 %.

    :class:`~rrr_pin.model.uncertainty.Tolerances`: 20 % inertias, 5 % lengths, and each
    joint's armature drawn in [0.5, 1.5] times its nominal (a geared arm's reflected rotor
    inertia is known to a factor, and the loop's lower gain margin is what it tests). The range
    is relative: an arm loaded without armature (a URDF, no ``--armature``) keeps none, so give
    the nominal ``--armature`` of your drives. The one place the design's default set is chosen
    (``design.json`` records it under ``plants``).
    """
    from ..model.uncertainty import Tolerances

    return Tolerances(armature=DESIGN_ARMATURE_TOLERANCE)


#: The design's default relative range of each joint's armature (:func:`design_tolerances`).
DESIGN_ARMATURE_TOLERANCE = 0.5


def check_plant_set(tol) -> None:
    """Refuse a tolerance box with no width: its plants would all be the nominal.

    Raises
    ------
    FieldError
        ``tolerances``: every range of a :class:`~rrr_pin.model.uncertainty.Tolerances` is
        empty (zero width).
    """
    from dataclasses import fields as dc_fields

    from ..model.uncertainty import Tolerances

    if not isinstance(tol, Tolerances):
        return
    widths = {f.name: getattr(tol, f.name) for f in dc_fields(tol)
              if isinstance(getattr(tol, f.name), float | int)}
    if widths and all(float(np.max(np.abs(v))) == 0.0 for v in widths.values()):
        raise FieldError("tolerances", f"{{name}}: the plant set has an empty range "
                                       f"({', '.join(f'{k} = {v}' for k, v in widths.items())}"
                                       f"): every plant would be the nominal; give a width, "
                                       f"or plants=[robot] to design on the nominal alone")


def plant_failures(ctx, ev, reqs, table) -> list:
    """Name the plant each unmet requirement fails on (:meth:`Requirement.per_plant`).

    Returns
    -------
    list of dict
        ``requirement``, ``plant`` (index in the set, 0 the nominal when drawn), ``value``
        (that plant's, or None), ``text``.
    """
    out = []
    for r, row in zip(reqs, table, strict=True):
        if row["met"]:
            continue
        each = r.per_plant(ctx, ev)
        if each is None or not len(each):
            k, v = None, None
        else:
            norm = np.array([r.normalized(x) if np.isfinite(x) else np.inf for x in each])
            k = int(np.argmax(norm))
            v = float(each[k])
        where = f"plant {k}" if k is not None else "the plant set"
        value = row["verified"] if row["verified"] is not None else row["achieved"]
        text = (f"{r.name} = {number_text(value)} against {row['sense']} "
                f"{number_text(row['target'])} {r.unit}: worst on {where}"
                + (f" ({number_text(v)})" if v is not None else ""))
        out.append({"requirement": r.name, "plant": k, "value": v, "text": text})
    return out


def simulated_failures(ctx, ev) -> list:
    """Return the plants on which the law diverged, simulated with the design's effects."""
    sim = ctx.simulated(ev)
    fx = ", ".join(f"{k} {v:g}" for k, v in (ctx.effects or {}).items()) or "no effects"
    return [{"requirement": "stable in simulation", "plant": int(k), "value": None,
             "text": f"stable in simulation: the law diverged on plant {k} with {fx} "
                     f"({why})"} for k, why in sorted(sim["diverged"].items())]

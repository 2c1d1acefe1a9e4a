"""Warnings where a law meets effects it cannot take: its delay or actuator margin named.

:func:`check_effect_margins` predicts, for each law with a linear model, its delay margin
with the actuator present and its slowest tolerable actuator with the delay present (the
exact digital loop of :func:`rrr_pin.campaign.stress.linear_boundary`, Franklin, Powell &
Workman sec. 4.3.4) and issues an :class:`EffectMarginWarning` naming the margin when the
effects requested (a run's) or recorded in a law's design (``design.json``'s ``effects``) are
beyond it. The CLI (``export``, ``montecarlo``, ``reproduce``) prints each warning once.
"""

from __future__ import annotations

import math
import warnings

__all__ = ["EffectMarginWarning", "check_effect_margins", "design_effects_record"]


class EffectMarginWarning(UserWarning):
    """A law's delay or actuator margin is below the effects it is asked to run behind."""


def design_effects_record(design) -> dict:
    """Return the delay and actuator a ``design.json`` record was made for (``{}``: none).

    Parameters
    ----------
    design : dict or None
        :meth:`rrr_pin.campaign.tuning.TuneResult.to_dict`.
    """
    if not design:
        return {}
    fx = dict(design.get("effects") or design.get("fixed") or {})
    for row in design.get("requirements") or []:   # a design.json from before "effects"
        if row.get("name") == "actuator_bandwidth":
            fx.setdefault("actuator", row.get("target"))
            if row.get("delay"):
                fx.setdefault("delay", row["delay"])
    return {k: float(fx[k]) for k in ("delay", "actuator") if fx.get(k)}


def check_effect_margins(laws, rate: float, delay: float = 0.0, actuator=None,
                         source: str = "requested") -> list[str]:
    """Warn for each law whose margin is below a delay [s] and an actuator [rad/s].

    Parameters
    ----------
    laws : sequence of ControlLaw
        Laws without a linear model (``linear_model()``) are skipped.
    rate : float
        Sampling rate of the laws [Hz].
    delay : float
        Transport delay [s] the laws run behind.
    actuator : float, optional
        First-order actuator bandwidth [rad/s].
    source : str
        Where the effects come from, for the message ("requested", "recorded in its design").

    Returns
    -------
    list of str
        The messages warned (an :class:`EffectMarginWarning` each).
    """
    from .stress import linear_boundary

    out = []
    if not delay and not actuator:
        return out
    for law in laws:
        try:
            dm = linear_boundary(law, "delay", rate, fixed={"actuator": actuator}
                                 if actuator else None) if delay else math.inf
            am = linear_boundary(law, "actuator", rate, fixed={"delay": delay}
                                 if delay else None) if actuator else 0.0
        except (TypeError, ValueError, NotImplementedError):
            continue          # no linear model to predict with
        if dm is None or am is None:
            continue
        parts = []
        if delay and dm < delay:
            parts.append(f"delay margin {1e3 * dm:.3g} ms"
                         + (f" (with the {actuator:g} rad/s actuator)" if actuator else "")
                         + f" below the {1e3 * delay:.3g} ms delay {source}")
        if actuator and am > actuator:
            parts.append(f"slowest actuator it tolerates {am:.4g} rad/s"
                         + (f" (with the {1e3 * delay:.3g} ms delay)" if delay else "")
                         + f", faster than the {actuator:g} rad/s actuator {source}")
        if parts:
            text = (f"{law.name}: " + "; ".join(parts) + " (exact digital loop at "
                    f"{rate:g} Hz on the nominal model): the loop is predicted unstable")
            warnings.warn(text, EffectMarginWarning, stacklevel=2)
            out.append(text)
    return out

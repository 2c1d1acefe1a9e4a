"""What a study or a Monte Carlo campaign computes: one frozen settings record for both.

:class:`Settings` holds what changes the numbers of many runs over seeded uncertain plants:
the plant count and seed, the tolerances they are drawn with, how each run is simulated
(:class:`~rrr_pin.campaign.runner.RunSettings`) and the baseline law. It is validated once,
when made, crosses process boundaries as is (frozen, picklable) and is recorded whole in
``results.json`` and ``summary.json`` (:meth:`Settings.to_dict`).

:class:`StudyConfig` (:mod:`rrr_pin.campaign.study`) and :class:`CampaignSettings`
(:mod:`rrr_pin.campaign.montecarlo`) are thin specializations: the same fields and validation,
with the defaults of their use (the paper's 10 plants and 4 s continuous-time runs; a campaign
of 10 s runs of 1 kHz sampled laws, at least one plant).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from ..model.identification import IdentifiedUncertainty
from ..model.uncertainty import MechanismUncertainty, Tolerances
from ..validation import check_count
from .runner import RunSettings

__all__ = ["Settings"]


@dataclass(frozen=True)
class Settings:
    """Settings of many runs over seeded uncertain plants (recorded whole in the outputs).

    Parameters
    ----------
    samples : int
        Number of uncertain plants, >= :attr:`MIN_SAMPLES`.
    seed : int, default 0
        Seed of the plants, >= 0: plant ``k`` is drawn with ``default_rng([seed, k])``.
    run : RunSettings
        Duration, step, rate, engine, initial state and plant effects of every run (default
        :class:`~rrr_pin.campaign.runner.RunSettings`: 4 s, continuous-time laws).
    tolerances : Tolerances, IdentifiedUncertainty or MechanismUncertainty
        20 % inertia, 5 % lengths by default; or the distribution identified from data
        (``rrr-pin identify``'s ``identification.json``); for a campaign on a parallel
        mechanism, a :class:`~rrr_pin.model.uncertainty.MechanismUncertainty` (e.g.
        ``MechanismTolerances()``, :attr:`UNCERTAINTIES`).
    baseline : str, default "fl"
        Name of the law the others are compared with.

    Raises
    ------
    ValueError
        ``samples`` or ``seed`` not an integer in range, naming the field and the value.
    TypeError
        ``run`` not a RunSettings, ``tolerances`` not a Tolerances, ``baseline`` not a string.
    """

    #: Smallest accepted ``samples``.
    MIN_SAMPLES: ClassVar[int] = 0

    #: Accepted types of ``tolerances`` (a campaign adds the mechanisms' uncertainty sets).
    UNCERTAINTIES: ClassVar[tuple] = (Tolerances, IdentifiedUncertainty)

    samples: int
    seed: int = 0
    run: RunSettings = field(default_factory=RunSettings)
    tolerances: Tolerances = field(default_factory=Tolerances)
    baseline: str = "fl"

    def __post_init__(self) -> None:
        object.__setattr__(self, "samples", check_count("samples", self.samples,
                                                        self.MIN_SAMPLES))
        object.__setattr__(self, "seed", check_count("seed", self.seed))
        for key, kind in (("run", RunSettings), ("tolerances", self.UNCERTAINTIES),
                          ("baseline", str)):
            value = getattr(self, key)
            if not isinstance(value, kind):
                names = " or ".join(k.__name__ for k in (kind if isinstance(kind, tuple)
                                                          else (kind,)))
                raise TypeError(f"{key} must be a {names}, got {type(value).__name__}")

    def to_dict(self) -> dict:
        """JSON-ready settings (units in the key names), as recorded in the outputs."""
        tol = self.tolerances
        if isinstance(tol, Tolerances):
            drawn = {"tolerance_inertia": tol.inertia, "tolerance_length": tol.length}
        elif isinstance(tol, MechanismUncertainty):
            drawn = {"uncertainty": type(tol).__name__, **tol.to_dict()}
        else:
            drawn = {"uncertainty": "identified", **{k: v for k, v in tol.to_dict().items()
                                                     if k != "kind"}}
        return {**self.run.to_dict(), "samples": self.samples, "seed": self.seed, **drawn,
                "baseline": self.baseline}

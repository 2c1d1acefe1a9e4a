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

from ..model.plant import UncertaintySet
from ..model.uncertainty import Tolerances
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
    tolerances : UncertaintySet
        Any :class:`~rrr_pin.model.plant.UncertaintySet` the plant accepts
        (:meth:`~rrr_pin.model.plant.Plant.perturbed`): by default
        :class:`~rrr_pin.model.uncertainty.Tolerances` (20 % inertia, 5 % lengths, for every
        kind of plant); the distribution identified from data (``rrr-pin identify``'s
        ``identification.json``, arms); a
        :class:`~rrr_pin.model.uncertainty.MechanismUncertainty` of your own (mechanisms).
    baseline : str, default "fl"
        Name of the law the others are compared with.

    Raises
    ------
    ValueError
        ``samples`` or ``seed`` not an integer in range, naming the field and the value.
    TypeError
        ``run`` not a RunSettings, ``tolerances`` not an UncertaintySet, ``baseline`` not a
        string.
    """

    #: Smallest accepted ``samples``.
    MIN_SAMPLES: ClassVar[int] = 0

    samples: int
    seed: int = 0
    run: RunSettings = field(default_factory=RunSettings)
    tolerances: UncertaintySet = field(default_factory=Tolerances)
    baseline: str = "fl"

    def __post_init__(self) -> None:
        object.__setattr__(self, "samples", check_count("samples", self.samples,
                                                        self.MIN_SAMPLES))
        object.__setattr__(self, "seed", check_count("seed", self.seed))
        for key, kind in (("run", RunSettings), ("tolerances", UncertaintySet),
                          ("baseline", str)):
            value = getattr(self, key)
            if not isinstance(value, kind):
                names = " or ".join(k.__name__ for k in (kind if isinstance(kind, tuple)
                                                          else (kind,)))
                article = "an" if names[0] in "AEIOU" else "a"
                raise TypeError(f"{key} must be {article} {names}, got {type(value).__name__}")

    def to_dict(self) -> dict:
        """JSON-ready settings (units in the key names), as recorded in the outputs."""
        return {**self.run.to_dict(), "samples": self.samples, "seed": self.seed,
                **self.tolerances.as_settings(), "baseline": self.baseline}

"""Many runs: the runner, the paper's study, Monte Carlo campaigns, stress searches, storage.

Holds :mod:`~rrr_pin.campaign.settings` (the one frozen settings record of a study or a
campaign), :mod:`~rrr_pin.campaign.runner` (``RunSettings``, ``run_laws``: any laws on one plant),
:mod:`~rrr_pin.campaign.study` (the section-5 study), :mod:`~rrr_pin.campaign.montecarlo`
(campaigns of seeded plants), :mod:`~rrr_pin.campaign.stress` (breaking points of plant
effects), :mod:`~rrr_pin.campaign.store` (append-only storage, resume) and
:mod:`~rrr_pin.campaign.executors` (local processes or Dask), :mod:`~rrr_pin.campaign.requirements`
and :mod:`~rrr_pin.campaign.tuning` (design to requirements: ``tune``, with the search of
:mod:`~rrr_pin.campaign.minimax`; the loop a design is judged on in
:mod:`~rrr_pin.campaign.design_set`, its ``design.json`` in :mod:`~rrr_pin.campaign.design_file`),
:mod:`~rrr_pin.campaign.coverage` (what a certificate
covers: the exact discrete loop behind a run's effects) and
:mod:`~rrr_pin.campaign.effect_margins` (warnings where a law meets effects beyond its
margins). Each takes any plant
(:mod:`rrr_pin.model.plant`): a serial arm and a closed chain run the same code. The study and
the campaign are siblings on the runner: neither imports the other.

Layer: above :mod:`rrr_pin.sim`. May import every layer below it, never :mod:`rrr_pin.report`.
"""

"""What acts in the loop: control laws, references and plant effects, each an open, typed input.

Holds :mod:`~rrr_pin.control.laws` (the ``ControlLaw``/``SampledLaw`` protocol, the built-in
laws and their typed compiled forms), :mod:`~rrr_pin.control.catalog` (built-in law names,
importable without numerical libraries), :mod:`~rrr_pin.control.references` (the ``Reference``
protocol and the built-in references) and :mod:`~rrr_pin.control.effects` (``PlantEffects``).

Layer: above :mod:`rrr_pin.robust`. May import :mod:`rrr_pin.validation`,
:mod:`rrr_pin.model` and :mod:`rrr_pin.robust`.
"""

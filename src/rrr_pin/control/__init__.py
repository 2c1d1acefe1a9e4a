"""What acts in the loop: control laws, references and plant effects, each an open, typed input.

Holds :mod:`~rrr_pin.control.laws` (the ``ControlLaw``/``SampledLaw`` protocol, the built-in
laws, their typed compiled forms and linear models), :mod:`~rrr_pin.control.catalog` (the
registry of built-in laws by name, importable without numerical libraries),
:mod:`~rrr_pin.control.references` (the ``Reference`` protocol and the built-in references),
:mod:`~rrr_pin.control.paths` (task-space paths placed from the start),
:mod:`~rrr_pin.control.specs` (a built-in reference named by kind and options),
:mod:`~rrr_pin.control.effects` (``PlantEffects``),
:mod:`~rrr_pin.control.friction` (``JointFriction``: the friction a plant effect applies and a
law compensates) and :mod:`~rrr_pin.control.analysis`
(``loop_at_input``, its margins, and the real-parametric robust stability of the
feedback-linearized loop at frozen configurations), :mod:`~rrr_pin.control.structures` (the
tunable structures of the FL law), :mod:`~rrr_pin.control.sampled_loops` (the digital FL
loop on a set of plants) and :mod:`~rrr_pin.control.grid_bounds` (the bounds that screen its
frequency grid). Every law reads its model through the
plant protocol only (:meth:`~rrr_pin.model.plant.Plant.terms`), so it runs on any plant.

Layer: above :mod:`rrr_pin.robust`. May import :mod:`rrr_pin.validation`,
:mod:`rrr_pin.model` and :mod:`rrr_pin.robust`.
"""

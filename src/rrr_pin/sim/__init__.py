"""Closed-loop simulation: one entry point, a Python reference engine and compiled engines.

Holds :mod:`~rrr_pin.sim.trajectory` (the leaf: ``Trajectory``, ``SimulationDiverged``, the
divergence test), :mod:`~rrr_pin.sim.simulation` (``simulate``: validation, then an engine),
:mod:`~rrr_pin.sim.engines` (the registry of engines; their names in
:mod:`~rrr_pin.sim.engine_names`), :mod:`~rrr_pin.sim.python_engine` (the
Python reference engine, any plant), :mod:`~rrr_pin.sim.extension` (the C++ extension
``_rollout``), :mod:`~rrr_pin.sim.compiled` (the compiled engine: serial arms and closed chains
in one C++ loop), :mod:`~rrr_pin.sim.codegen` (the fingerprint of the fixed-model generated C),
:mod:`~rrr_pin.sim.dyngen` (the generator of parameter-input dynamics per structure),
:mod:`~rrr_pin.sim.dyncache` (any structure's generated dynamics, built at first use and
cached),
:mod:`~rrr_pin.sim.batched` (engine ``"codegen"``: batched rollouts of many plants on them),
:mod:`~rrr_pin.sim.mujoco_engine` (engine ``"mujoco"``: the plant stepped by MuJoCo, an
optional extra) and :mod:`~rrr_pin.sim.reuse` (the preparation runs of many plants share,
kept once).

Layer: above :mod:`rrr_pin.control`. May import :mod:`rrr_pin.validation`,
:mod:`rrr_pin.model`, :mod:`rrr_pin.robust` and :mod:`rrr_pin.control`.
"""

"""Closed-loop simulation: one entry point, a Python reference engine and compiled engines.

Holds :mod:`~rrr_pin.sim.trajectory` (the leaf: ``Trajectory``, ``SimulationDiverged``, the
divergence test), :mod:`~rrr_pin.sim.engines` (the registry of engines),
:mod:`~rrr_pin.sim.python_engine` (the Python reference engine, one loop over the plant
protocol), :mod:`~rrr_pin.sim.simulation` (``simulate``: validation, then the engine),
:mod:`~rrr_pin.sim.extension` (the C++ extension ``_rollout``),
:mod:`~rrr_pin.sim.compiled` (the compiled engine), :mod:`~rrr_pin.sim.codegen` (the
fixed-model generated C and its fingerprint), :mod:`~rrr_pin.sim.dyngen` (the generator of
parameter-input dynamics per structure), :mod:`~rrr_pin.sim.batched` (engine ``"codegen"``:
batched rollouts of many plants on them) and :mod:`~rrr_pin.sim.chain_compiled` (the
compiled engine's closed-chain loop).

Layer: above :mod:`rrr_pin.control`. May import :mod:`rrr_pin.validation`,
:mod:`rrr_pin.model`, :mod:`rrr_pin.robust` and :mod:`rrr_pin.control`.
"""

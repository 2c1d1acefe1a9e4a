"""The engines' names, the one place they are spelled (:mod:`rrr_pin.sim.engines` registers them).

An engine module that names itself or another engine in a message imports its name from here,
below the registry, so that the registry can import the engines without a cycle.
"""

from __future__ import annotations

__all__ = ["AUTO", "PYTHON", "COMPILED", "CODEGEN", "MUJOCO"]

#: The policy that picks an engine per run (not an engine itself).
AUTO = "auto"
#: The reference engine (:mod:`rrr_pin.sim.python_engine`).
PYTHON = "python"
#: The C++ loop of a law's compiled form (:mod:`rrr_pin.sim.compiled`).
COMPILED = "compiled"
#: The same loop on generated dynamics, many plants at once (:mod:`rrr_pin.sim.batched`).
CODEGEN = "codegen"
MUJOCO = "mujoco"

"""Shared fixtures; matplotlib renders off-screen in every test."""

import matplotlib

matplotlib.use("Agg")

# Load the compiled extension once, before any test captures sys.stdout: in an editable
# development install its import may first rebuild it in a subprocess, which needs real file
# descriptors (a regular install has no such step).
import rrr_pin.sim.compiled  # noqa: E402, F401

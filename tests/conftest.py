"""Shared fixtures; matplotlib renders off-screen in every test."""

import json

import matplotlib
import pytest

matplotlib.use("Agg")

# Load the compiled extension once, before any test captures sys.stdout: in an editable
# development install its import may first rebuild it in a subprocess, which needs real file
# descriptors (a regular install has no such step).
import rrr_pin.sim.compiled  # noqa: E402, F401


def _strict_loads(text: str):
    """``json.loads`` refusing NaN and Infinity, which are not JSON (RFC 8259; jq, JS refuse)."""
    def refuse(name):
        raise ValueError(f"not JSON: {name}")
    return json.loads(text, parse_constant=refuse)


@pytest.fixture
def strict_json():
    """The strict JSON parser: every JSON file or stream the tool writes must pass it."""
    return _strict_loads

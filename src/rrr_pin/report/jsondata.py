"""Strict JSON for every file and stream the tool writes: no ``NaN``, no ``Infinity``.

``json.dumps`` writes ``NaN`` and ``Infinity`` by default, which are not JSON (RFC 8259) and which
strict parsers (``jq``, JavaScript's ``JSON.parse``, ``json.loads(..., parse_constant=...)``)
refuse. :func:`json_ready` replaces each non-finite number by ``null`` and says what it was in a
sibling field ``<key>_status``; :func:`dumps` is ``json.dumps(json_ready(value),
allow_nan=False)``, so a non-finite number that slips through raises instead of being written.

A dict entry ``"x": inf`` becomes ``"x": null, "x_status": "infinite"`` (``"-infinite"``,
``"undefined (NaN)"``). Inside a list, the entry ``"x": [0.02, inf]`` becomes
``"x": [0.02, null], "x_status": "[1]: infinite"`` (one ``path: what`` per replaced number,
``"; "``-separated). A top-level list or number has no key to hold the status: a non-finite
number there is refused (``ValueError``). NumPy scalars and arrays are converted to Python
numbers and lists.
"""

from __future__ import annotations

import json
import math

import numpy as np

__all__ = ["json_ready", "dumps"]


def _what(x: float) -> str:
    if math.isnan(x):
        return "undefined (NaN)"
    return "infinite" if x > 0 else "-infinite"


def _clean(value, path: str, found: list):
    """``value`` with non-finite numbers as None; ``found`` gets ``(path, what)`` of each."""
    if isinstance(value, dict):
        return json_ready(value)
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, (list, tuple)):
        return [_clean(v, f"{path}[{i}]", found) for i, v in enumerate(value)]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        found.append((path, _what(value)))
        return None
    return value


def json_ready(value):
    """Return ``value`` with every non-finite number as ``None`` and a ``<key>_status`` beside it.

    Parameters
    ----------
    value : dict, list, tuple, number, str, bool or None
        Nested freely; dict keys are strings.

    Returns
    -------
    Same kind as ``value``, safe for ``json.dumps(..., allow_nan=False)``.

    Raises
    ------
    ValueError
        A non-finite number with no dict key to name it (a top-level list or number), or a
        ``<key>_status`` that the dict already holds.
    """
    if not isinstance(value, dict):
        found: list = []
        out = _clean(value, "", found)
        if found:
            raise ValueError(f"non-finite number at {found[0][0] or 'the top level'} "
                             f"({found[0][1]}) has no key for its status: wrap it in a dict")
        return out
    out = {}
    for key, v in value.items():
        found = []
        out[key] = _clean(v, "", found)
        if found:
            status = f"{key}_status"
            if status in value:
                raise ValueError(f"{key!r} is not finite and {status!r} is already set")
            out[status] = "; ".join(f"{p}: {w}" if p else w for p, w in found)
    return out


def dumps(value, **kwargs) -> str:
    """Strict ``json.dumps`` of :func:`json_ready` ``(value)`` (``allow_nan=False``)."""
    return json.dumps(json_ready(value), allow_nan=False, **kwargs)

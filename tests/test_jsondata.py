"""rrr_pin.report.jsondata: strict JSON, a non-finite number written as null with a status."""

import json
import math

import numpy as np
import pytest

from rrr_pin.report.jsondata import dumps, json_ready


def test_non_finite_numbers_become_null_with_a_status(strict_json):
    value = {"gamma": math.inf, "margin_db": -math.inf, "rel": math.nan, "b": 0.4665,
             "ncfmargin": (0.0211, math.inf), "nested": {"w": [1.0, [2.0, np.float64("nan")]]},
             "ok": True, "name": "fl", "none": None}
    assert strict_json(dumps(value)) == {
        "gamma": None, "gamma_status": "infinite",
        "margin_db": None, "margin_db_status": "-infinite",
        "rel": None, "rel_status": "undefined (NaN)", "b": 0.4665,
        "ncfmargin": [0.0211, None], "ncfmargin_status": "[1]: infinite",
        "nested": {"w": [1.0, [2.0, None]], "w_status": "[1][1]: undefined (NaN)"},
        "ok": True, "name": "fl", "none": None}


def test_numpy_values_are_plain_json():
    out = json_ready({"a": np.array([[1.0, np.inf]]), "n": np.int64(3), "x": np.float32(0.5)})
    assert out == {"a": [[1.0, None]], "a_status": "[0][1]: infinite", "n": 3, "x": 0.5}
    assert type(out["n"]) is int and json.dumps(out, allow_nan=False)


def test_finite_data_is_unchanged():
    value = {"rows": [{"seed": [0, 1], "rms": 1.5e-4}], "samples": 10, "label": "H-inf + FL"}
    assert json_ready(value) == value
    assert dumps(value, indent=1) == json.dumps(value, indent=1)


@pytest.mark.parametrize("value, match", [
    ([1.0, math.inf], r"non-finite number at \[1\] \(infinite\) has no key"),
    (math.nan, r"non-finite number at the top level \(undefined \(NaN\)\)"),
    ({"x": math.inf, "x_status": "given"}, r"'x' is not finite and 'x_status' is already set"),
], ids=["top-list", "top-number", "status-taken"])
def test_refused_where_no_status_can_be_written(value, match):
    with pytest.raises(ValueError, match=match):
        dumps(value)

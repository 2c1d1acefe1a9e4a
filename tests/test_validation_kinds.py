"""Tests of rrr_pin.validation: each check_* against hand-written cases.

Accepted values must come back converted (float, int, read-only float vector); everything else
(booleans, None, strings, NaN, inf, out of range, wrong shape) must be refused with a
``ValueError`` whose message names the field and the bad value in the shared wording.
"""

import math
import re

import numpy as np
import pytest

from rrr_pin.validation import (
    FieldError,
    check_count,
    check_direction,
    check_positive,
    check_probability,
    check_rate,
    check_real,
    check_size,
    check_vector,
    describe_value,
)

# --- check_real --------------------------------------------------------------------------------

@pytest.mark.parametrize(("value", "expected"), [
    (3, 3.0), (-2.5, -2.5), (0, 0.0), (np.float32(0.5), 0.5), (np.int64(-7), -7.0),
    (1e300, 1e300),
], ids=["int", "negative-float", "zero", "float32", "int64", "huge"])
def test_check_real_accepts_finite_numbers(value, expected):
    got = check_real("x", value)
    assert type(got) is float and got == expected


@pytest.mark.parametrize(("value", "message"), [
    (True, r"mass must be a number \[kg\], got True \(bool\)"),
    (np.bool_(False), r"mass must be a number \[kg\], got (np\.)?False_? \(bool_?\)"),
    (None, r"mass must be a number \[kg\], got None \(NoneType\)"),
    ("5", r"mass must be a number \[kg\], got '5' \(str\)"),
    ([1.0], r"mass must be a number \[kg\], got \[1\.0\] \(list\)"),
    (math.nan, r"mass must be finite \[kg\], got nan"),
    (-math.inf, r"mass must be finite \[kg\], got -inf"),
], ids=["bool", "numpy-bool", "None", "str", "list", "nan", "-inf"])
def test_check_real_refuses(value, message):
    with pytest.raises(ValueError, match=message):
        check_real("mass", value, "kg")


def test_check_real_without_unit_has_no_brackets():
    with pytest.raises(ValueError, match=re.escape("g must be finite, got inf")):
        check_real("g", math.inf)


# --- check_positive ----------------------------------------------------------------------------

@pytest.mark.parametrize(("value", "allow_zero", "expected"), [
    (2, False, 2.0), (1e-300, False, 1e-300), (np.float64(4.5), False, 4.5),
    (0, True, 0.0), (0.0, True, 0.0), (7, True, 7.0),
], ids=["int", "tiny", "float64", "zero-allowed-int", "zero-allowed", "int-allowed"])
def test_check_positive_accepts(value, allow_zero, expected):
    got = check_positive("dt", value, allow_zero=allow_zero)
    assert type(got) is float and got == expected


@pytest.mark.parametrize(("value", "allow_zero", "message"), [
    (0.0, False, r"dt must be a finite number > 0 \[s\], got 0\.0"),
    (-1, False, r"dt must be a finite number > 0 \[s\], got -1"),
    (-1e-12, True, r"dt must be a finite number >= 0 \[s\], got -1e-12"),
    (math.nan, False, r"dt must be a finite number > 0 \[s\], got nan"),
    (math.inf, True, r"dt must be a finite number >= 0 \[s\], got inf"),
    (True, False, r"dt must be a finite number > 0 \[s\], got True"),
    (None, True, r"dt must be a finite number >= 0 \[s\], got None"),
    ("0.1", False, r"dt must be a finite number > 0 \[s\], got '0\.1'"),
], ids=["zero", "negative", "negative-allow-zero", "nan", "inf", "bool", "None", "str"])
def test_check_positive_refuses(value, allow_zero, message):
    with pytest.raises(ValueError, match=message):
        check_positive("dt", value, allow_zero=allow_zero, unit="s")


# --- check_count and check_size ----------------------------------------------------------------

@pytest.mark.parametrize(("value", "low", "expected"), [
    (0, 0, 0), (5, 1, 5), (200.0, 1, 200), (np.int32(3), 0, 3), (-2, -5, -2),
], ids=["zero", "int", "integral-float", "int32", "negative-low"])
def test_check_count_accepts(value, low, expected):
    got = check_count("samples", value, low)
    assert type(got) is int and got == expected


@pytest.mark.parametrize(("value", "low", "message"), [
    (0, 1, "samples must be an integer >= 1, got 0"),
    (-1, 0, "samples must be an integer >= 0, got -1"),
    (2.5, 0, "samples must be an integer >= 0, got 2.5"),
    (math.nan, 0, "samples must be an integer >= 0, got nan"),
    (math.inf, 1, "samples must be an integer >= 1, got inf"),  # int(inf): OverflowError
    (True, 0, "samples must be an integer >= 0, got True"),
    (None, 0, "samples must be an integer >= 0, got None"),
    ("3", 0, "samples must be an integer >= 0, got '3'"),
], ids=["below-low", "negative", "fraction", "nan", "inf", "bool", "None", "str"])
def test_check_count_refuses(value, low, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        check_count("samples", value, low)


def test_check_count_default_low_is_zero():
    assert check_count("seed", 0) == 0
    with pytest.raises(ValueError, match=re.escape("seed must be an integer >= 0, got -3")):
        check_count("seed", -3)


@pytest.mark.parametrize(("value", "expected"), [(1, 1), (3.0, 3), (np.int64(12), 12)],
                         ids=["one", "integral-float", "int64"])
def test_check_size_accepts(value, expected):
    got = check_size("n", value)
    assert type(got) is int and got == expected


@pytest.mark.parametrize("value", [0, -2, 1.5, True, None, "3", math.nan],
                         ids=["zero", "negative", "fraction", "bool", "None", "str", "nan"])
def test_check_size_refuses(value):
    with pytest.raises(ValueError, match=re.escape(f"n must be an integer >= 1, got {value!r}")):
        check_size("n", value)


# --- check_rate ----------------------------------------------------------------------------------

@pytest.mark.parametrize(("value", "expected"), [(1000, 1000.0), (0.5, 0.5)], ids=["int", "float"])
def test_check_rate_accepts(value, expected):
    got = check_rate("rate", value)
    assert type(got) is float and got == expected


@pytest.mark.parametrize("value", [0, -100.0, math.nan, math.inf, True, None, "1000"],
                         ids=["zero", "negative", "nan", "inf", "bool", "None", "str"])
def test_check_rate_refuses(value):
    message = f"rate must be a finite number > 0 [Hz], got {value!r}"
    with pytest.raises(ValueError, match=re.escape(message)):
        check_rate("rate", value)


# --- check_probability ---------------------------------------------------------------------------

@pytest.mark.parametrize(("value", "expected"), [(0, 0.0), (1, 1.0), (0.25, 0.25)],
                         ids=["zero", "one", "quarter"])
def test_check_probability_accepts(value, expected):
    got = check_probability("p", value)
    assert type(got) is float and got == expected


@pytest.mark.parametrize("value", [-0.01, 1.0000001, math.nan, math.inf, True, None, "0.5"],
                         ids=["below", "above", "nan", "inf", "bool", "None", "str"])
def test_check_probability_refuses(value):
    message = f"p must be a probability in [0, 1], got {value!r}"
    with pytest.raises(ValueError, match=re.escape(message)):
        check_probability("p", value)


# --- check_vector --------------------------------------------------------------------------------

@pytest.mark.parametrize(("value", "n", "expected"), [
    ([1, 2, 3], 3, [1.0, 2.0, 3.0]), ((0.5,), None, [0.5]), (2.0, None, [2.0]),
    (np.arange(4), 4, [0.0, 1.0, 2.0, 3.0]), ([], None, []),
], ids=["list", "tuple-any-length", "scalar-reads-as-1", "int-array", "empty-any-length"])
def test_check_vector_accepts(value, n, expected):
    got = check_vector("q", value, n)
    assert got.dtype == np.float64 and got.shape == (len(expected),)
    assert got.tolist() == expected
    assert got.flags.writeable


def test_check_vector_copies_and_can_freeze():
    source = np.array([1.0, 2.0])
    got = check_vector("home", source, 2, readonly=True)
    assert not got.flags.writeable
    assert source.flags.writeable  # the caller's array is neither shared nor frozen
    got_rw = check_vector("home", source, 2)
    got_rw[0] = 9.0
    assert source[0] == 1.0


@pytest.mark.parametrize(("value", "n", "message"), [
    ([0.0, 0.0], 3, r"Expected q of shape (3,), got (2,)"),
    ([[0.0, 0.0, 0.0]], 3, r"Expected q of shape (3,), got (1, 3)"),
    ([[1.0], [2.0]], None, r"Expected q of shape (n,), got (2, 1)"),
    ([0.0, math.nan, 1.0], 3, r"q must be finite, got [0.0, nan, 1.0]"),
    ([math.inf], None, r"q must be finite, got [inf]"),
    (["a", "b"], None, r"q must be an array of numbers, got ['a', 'b']"),
    (None, None, r"q must be an array of numbers, got None"),
], ids=["short", "2-d", "column", "nan", "inf", "strings", "None"])
def test_check_vector_refuses(value, n, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        check_vector("q", value, n)


# --- FieldError: the field kept apart from the sentence -----------------------------------------

def test_field_error_relabels_and_pickles():
    import pickle

    from rrr_pin.validation import FieldError, check_positive

    with pytest.raises(FieldError) as info:
        check_positive("move_time", -1.0, unit="s")
    exc = info.value
    assert isinstance(exc, ValueError) and exc.field == "move_time"
    assert str(exc) == "move_time must be a finite number > 0 [s], got -1.0"
    assert str(exc.relabelled(lambda f: "--" + f.replace("_", "-"))) == (
        "--move-time must be a finite number > 0 [s], got -1.0")
    back = pickle.loads(pickle.dumps(exc))  # crosses a process boundary whole
    assert (type(back), back.field, str(back)) == (FieldError, exc.field, str(exc))


def test_field_error_keeps_braces_of_the_value():
    from rrr_pin.validation import FieldError, check_real

    with pytest.raises(FieldError) as info:
        check_real("x", "{a}")
    assert str(info.value) == "x must be a number, got '{a}' (str)"
    assert str(info.value.relabelled(str.upper)) == "X must be a number, got '{a}' (str)"


@pytest.mark.parametrize("value, shape, message", [
    ([[1.0, 2.0]], (2, 1), r"Expected K of shape \(2, 1\), got \(1, 2\)"),
    ([[1.0, float("inf")]], (1, 2), r"K must be finite, got \[\[1.0, inf\]\]"),
    ([["a", 1.0]], (1, 2), "K must be an array of numbers"),
], ids=["shape", "inf", "strings"])
def test_check_matrix_refuses(value, shape, message):
    from rrr_pin.validation import check_matrix

    with pytest.raises(ValueError, match=message):
        check_matrix("K", value, shape)


def test_check_matrix_readonly_copies_a_writable_input():
    from rrr_pin.validation import check_matrix

    src = np.eye(2)
    out = check_matrix("K", src, (2, 2), readonly=True)
    assert not out.flags.writeable and src.flags.writeable  # the caller's array is untouched
    np.testing.assert_array_equal(out, src)  # same numbers, exactly
    assert check_matrix("K", [[1, 2]], (1, 2)).dtype == float


@pytest.mark.parametrize("value, step, k", [
    (0.3, 0.1, 3),  # 0.3 / 0.1 = 2.9999999999999996 in floats
    (0.0, 1e-3, 0), (10.0, 1e-3, 10000), (2e-3, 1e-4, 20),
], ids=["decimal", "zero", "many", "sub-steps"])
def test_check_multiple_returns_the_whole_count(value, step, k):
    from rrr_pin.validation import check_multiple

    assert check_multiple("x", value, step) == k


def test_check_multiple_refuses_values_between_steps_and_below_low():
    from rrr_pin.validation import FieldError, check_multiple

    with pytest.raises(FieldError, match=r"^delay = 0.25 s is not a whole number of steps = "
                                         r"0.1 s \(2.5 of them\): the nearest realizable values "
                                         r"are 0.2 s and 0.3 s$"):
        check_multiple("delay", 0.25, 0.1, unit="s")
    with pytest.raises(FieldError, match=r"the nearest realizable value is 0.1 s$"):
        check_multiple("x", 0.05, 0.1, low=1, unit="s")  # 0 is below low: one candidate
    with pytest.raises(FieldError, match=r"^x = 0 s is below 1 steps = 0.1 s$"):
        check_multiple("x", 0.0, 0.1, low=1, unit="s")


# --- check_direction ---------------------------------------------------------------------------

@pytest.mark.parametrize("value, expected", [
    ((0, 0, 2.5), (0, 0, 1)), ((3, 4, 0), (0.6, 0.8, 0)),
    ((3e-200, 4e-200, 0), (0.6, 0.8, 0)),  # v @ v underflows to 0 in double precision
    ((3e300, -4e300, 0), (0.6, -0.8, 0)),  # v @ v overflows to inf
    ((5e-324, 0, 0), (1, 0, 0)),  # the smallest subnormal is still a direction
], ids=["z", "3-4-5", "tiny", "huge", "subnormal"])
def test_check_direction_returns_the_unit_vector(value, expected):
    # Hand-computed unit vectors (3-4-5 triangle); 1e-15: a few ulps of values ~1.
    np.testing.assert_allclose(check_direction("normal", value), expected, rtol=0, atol=1e-15)


@pytest.mark.parametrize("value, message", [
    ((0, 0, 0), "normal must be a non-zero vector (a direction), got [0.0, 0.0, 0.0]"),
    ((0, 0, -0.0), "normal must be a non-zero vector (a direction), got [0.0, 0.0, -0.0]"),
    ((np.nan, 0, 1), "normal must be finite, got [nan, 0.0, 1.0]"),
    ((0, 1), "Expected normal of shape (3,), got (2,)"),
], ids=["zero", "minus-zero", "nan", "short"])
def test_check_direction_refuses(value, message):
    with pytest.raises(FieldError, match=re.escape(message)) as info:
        check_direction("normal", value)
    assert info.value.field == "normal"


def test_describe_value_names_the_type_and_cuts_long_values():
    assert describe_value(None) == "None (NoneType)"
    assert describe_value([1.0, 2.0]) == "[1.0, 2.0] (list)"
    long = describe_value(list(range(100)))
    assert long.endswith("... (list)") and len(long) == 80 + len("... (list)")


def test_counts_with_a_work_bound_are_refused_above_it(capsys):
    # design --joints 100000 asked numpy for a 75 GiB matrix (traceback); check-dynamics
    # --samples 1e9 was killed by the kernel's OOM killer (exit 137, no message).
    from rrr_pin import cli
    from rrr_pin.model.closed_form import MAX_CHECK_SAMPLES
    from rrr_pin.robust.loopshaping import MAX_JOINTS
    from rrr_pin.validation import FieldError, check_count

    assert check_count("n", 1000, 1, high=1000) == 1000
    with pytest.raises(FieldError, match=r"^n must be an integer in \[1, 1000\], got 1001$"):
        check_count("n", 1001, 1, high=1000)
    for argv, message in (
            (["design", "--joints", "100000"], f"--joints must be an integer in [1, {MAX_JOINTS}]"),
            (["check-dynamics", "--samples", "1000000000"],
             f"--samples must be an integer in [1, {MAX_CHECK_SAMPLES}]")):
        assert cli.main(argv) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err

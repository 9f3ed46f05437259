"""The one range check (contracts/checks.py): value back as a float, or a message naming the field,
the value and the range with its open or closed ends and its unit."""

from __future__ import annotations

import math

import pytest

from pressor.contracts.checks import allowed_range, check_int_range, check_range


@pytest.mark.parametrize(
    ("kwargs", "text"),
    [
        ({"lo": 0.0, "lo_open": True}, "> 0"),
        ({"lo": 0.0, "unit": "s"}, ">= 0 s"),
        ({"hi": 5.0, "hi_open": True}, "< 5"),
        ({"lo": 0.0, "hi": 1e4, "lo_open": True, "unit": "ml/h"}, "in (0, 10000] ml/h"),
        ({"lo": 1e-4, "hi": 1.0, "hi_open": True}, "in [0.0001, 1)"),
        ({"lo": 0, "hi": 2**32 - 1}, "in [0, 4294967295]"),
        ({}, ""),
    ],
)
def test_allowed_range_reads_the_ends_and_the_unit(kwargs, text):
    assert allowed_range(**kwargs) == text


def test_a_value_in_range_comes_back_as_a_float():
    assert check_range("n", 3, 0, 5) == 3.0 and type(check_range("n", 3, 0, 5)) is float
    assert check_range("x", 0.0, 0.0) == 0.0  # a closed end is allowed


@pytest.mark.parametrize(
    ("value", "shown"),
    [(0.0, "0.0"), (-1.0, "-1.0"), (math.nan, "nan"), (math.inf, "inf"), (True, "True"),
     ("abc", "'abc'"), (None, "None")],
)  # fmt: skip
def test_a_bad_value_is_named_with_the_field_and_the_range(value, shown):
    with pytest.raises(ValueError) as exc:
        check_range("q_b", value, 0.0, lo_open=True, unit="mmHg")
    assert str(exc.value) == f"q_b = {shown}: must be a finite number > 0 mmHg"


def test_the_caller_picks_the_error_and_adds_its_context():
    class FieldError(Exception):
        pass

    with pytest.raises(FieldError, match=r"^a\.toml: field 'x' = 2\.0: must be .* in \[0, 1\]$"):
        check_range("field 'x'", 2.0, 0.0, 1.0, error=lambda m: FieldError(f"a.toml: {m}"))


def test_an_integer_range_is_exact_at_2_63_and_refuses_floats_and_bools():
    top = 2**63 - 1
    assert check_int_range("seed", top, 0, top) == top  # a float check would round it to 2**63
    with pytest.raises(ValueError, match=r"^seed = 9223372036854775808: must be an integer in "):
        check_int_range("seed", top + 1, 0, top)
    for bad in (3.0, True, "3", None):
        with pytest.raises(ValueError, match=r"must be an integer in \[1, 5\]$"):
            check_int_range("--jobs", bad, 1, 5)
    with pytest.raises(
        KeyError, match=r"--patients = 0: must be an integer in \[1, 100\] patients"
    ):
        check_int_range("--patients", 0, 1, 100, unit="patients", error=KeyError)

"""The argument checks of drake_wbc.math.validation that the math and the
stages share: as_float_array's pass-through, unit_interval for every
scalar type, whole_number's errors, and no string or boolean taken for a
number."""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd

from drake_wbc.math.capability import capability, transition
from drake_wbc.math.validation import (
    as_float_array,
    as_matrix,
    as_scalar,
    as_vector,
    unit_interval,
    whole_number,
)


def test_as_float_array_passes_a_right_array_and_checks_the_rest():
    x = np.arange(3.0)
    assert as_float_array("x", x, (3,)) is x
    np.testing.assert_array_equal(as_float_array("x", [1, 2, 3], (3,)),
                                  [1.0, 2.0, 3.0])
    huge = np.full(3, 1e308)  # finite, though its sum would overflow
    assert as_float_array("x", huge, (3,)) is huge
    for bad in (np.array([0.0, np.nan, 1.0]), np.zeros(4), "abc"):
        with pytest.raises(ValueError, match="x"):
            as_float_array("x", bad, (3,))
    with pytest.raises(ValueError, match="shape"):
        as_float_array("M", np.zeros((2, 3)), (3, 2))


def test_unit_interval_keeps_the_scalar_type():
    value = AutoDiffXd(0.25, [1.0, 2.0])
    assert unit_interval("alpha", value) is value
    assert unit_interval("alpha", 1.0) == 1.0
    assert unit_interval("alpha", np.float64(0.0)) == 0.0


@pytest.mark.parametrize("value", [-1e-12, 1.5, np.nan, np.inf,
                                   AutoDiffXd(1.5, [1.0])])
def test_unit_interval_names_the_value_outside(value):
    with pytest.raises(ValueError,
                       match=r"^sigma_xy = .* must lie in \[0, 1\]"):
        unit_interval("sigma_xy", value)


@pytest.mark.parametrize("value, message", [
    (0, "count = 0 is not allowed: must be 1 or greater"),
    (-3.0, "count = -3 is not allowed: must be 1 or greater"),
    (2.5, "count = 2.5 is not allowed: must be a whole number"),
    (True, "count = True is not allowed: must be a whole number"),
    (np.nan, "count = nan is not allowed: must be finite"),
])
def test_whole_number_shows_a_whole_value_as_an_integer(value, message):
    with pytest.raises(ValueError) as error:
        whole_number("count", value, 1)
    assert str(error.value) == message
    assert whole_number("count", 811.0, 1) == 811


def test_whole_number_has_an_upper_bound_of_its_own():
    """The bench's largest repetitions were checked by a copy of the
    bound (bench.commands): whole_number takes it, as positive_duration
    takes its longest, and names the value as a whole number."""
    assert whole_number("count", 1000.0, 1, 1000) == 1000
    with pytest.raises(ValueError) as error:
        whole_number("count", 1001.0, 1, 1000, " (some 20 minutes)")
    assert str(error.value) == ("count = 1001 is not allowed: must be at "
                                "most 1000 (some 20 minutes)")


@pytest.mark.parametrize("bad", ["15000", b"15000", np.str_("1.5"), True,
                                 np.True_, np.array("2.0"), np.array(True)])
def test_a_string_or_boolean_is_not_a_number(bad):
    with pytest.raises(ValueError, match=(
            r"^k_j = .* is not allowed: must be a single number "
            r"\(not a string or a boolean\)$")):
        as_scalar("k_j", bad)
    assert as_scalar("k_j", np.float32(2.5)) == 2.5
    assert as_scalar("k_j", np.array(3)) == 3.0


@pytest.mark.parametrize("bad", [["1", "2"], [1.0, True], (0.0, np.False_),
                                 np.array([1, 0], dtype=bool),
                                 np.array(["1", "2"]),
                                 np.array([1.0, "2"], dtype=object),
                                 [[1.0, 2.0], [3.0, False]]])
def test_an_array_of_strings_or_booleans_is_not_one_of_numbers(bad):
    check = as_vector if np.ndim(bad) == 1 else (
        lambda name, value: as_matrix(name, value, (2, 2)))
    with pytest.raises(ValueError, match=(
            r"^q = .* is not allowed: must be a (vector|matrix) of numbers "
            r"\(not strings or booleans\)$")):
        check("q", bad)
    with pytest.raises(ValueError, match="q = "):
        as_float_array("q", bad, np.shape(bad))
    np.testing.assert_array_equal(as_vector("q", [1, 2.5]), [1.0, 2.5])
    np.testing.assert_array_equal(as_vector("q", np.arange(2)), [0.0, 1.0])


def test_the_checked_math_names_a_string_or_boolean_argument():
    J, q = np.eye(6), np.zeros(6)
    with pytest.raises(ValueError, match="^k_j = '15000' is not allowed"):
        capability(J, q, -np.ones(6), np.ones(6), k_j="15000")
    with pytest.raises(ValueError, match="^value = True is not allowed"):
        transition(True, 0.04, 0.035)

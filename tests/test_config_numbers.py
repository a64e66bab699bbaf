"""is_finite_number: what a number read from a JSON or YAML file must be."""

import math

from latentrl.config import is_finite_number


def test_finite_ints_and_floats_only():
    assert is_finite_number(0) and is_finite_number(-3) and is_finite_number(2.5)
    for bad in (True, False, math.nan, math.inf, -math.inf, "1", None, [1]):
        assert not is_finite_number(bad), bad

"""The scalar helpers against closed forms and plain float math."""

import numpy as np
import pytest
from pydrake.autodiffutils import (
    AutoDiffXd,
    ExtractGradient,
    ExtractValue,
    InitializeAutoDiff,
)

from drake_wbc.math.scalar_support import (
    all_finite,
    is_autodiff,
    solve,
    through_float_function,
    value_of,
)


def test_solve_floats_matches_numpy():
    rng = np.random.default_rng(0)
    M, b = rng.normal(size=(5, 5)) + 5 * np.eye(5), rng.normal(size=5)
    np.testing.assert_allclose(solve(M, b), np.linalg.solve(M, b))


def test_solve_derivative_matches_finite_differences():
    """d/dp of x(p) = M(p)^-1 b(p) for M, b depending on a parameter p."""
    rng = np.random.default_rng(1)
    M0, M1 = rng.normal(size=(2, 4, 4))
    M0 += 4 * np.eye(4)
    b0, b1 = rng.normal(size=(2, 4))

    def x_of(p):
        return np.linalg.solve(M0 + p * M1, b0 + p * b1)

    p = InitializeAutoDiff(np.array([0.3]))[0, 0]
    M = M0 + p * M1
    b = b0 + p * b1
    x = solve(M, b)
    assert is_autodiff(x)
    h = 1e-6
    numeric = (x_of(0.3 + h) - x_of(0.3 - h)) / (2 * h)
    np.testing.assert_allclose(ExtractValue(x).ravel(), x_of(0.3))
    np.testing.assert_allclose(ExtractGradient(x).ravel(), numeric,
                               rtol=1e-7)


def test_solve_with_only_b_autodiff():
    M = np.array([[2.0, 1.0], [1.0, 3.0]])
    b = InitializeAutoDiff(np.array([1.0, 2.0])).ravel()
    x = solve(M, b)
    np.testing.assert_allclose(ExtractGradient(x), np.linalg.inv(M))


def test_through_float_function_chain_rule():
    def f(v):
        return np.array([np.sin(v[0]) * v[1], v[1] ** 2])

    x = InitializeAutoDiff(np.array([0.4, 1.5])).ravel()
    y = through_float_function(f, x)
    exact = np.array([[np.cos(0.4) * 1.5, np.sin(0.4)], [0.0, 3.0]])
    np.testing.assert_allclose(ExtractValue(y).ravel(), f([0.4, 1.5]))
    np.testing.assert_allclose(ExtractGradient(y), exact, atol=1e-8)
    # Floats pass straight through.
    np.testing.assert_allclose(through_float_function(f, [0.4, 1.5]),
                               f([0.4, 1.5]))


def test_value_of():
    x = InitializeAutoDiff(np.array([1.0, 2.0])).ravel()
    np.testing.assert_array_equal(value_of(x), [1.0, 2.0])
    assert value_of([1, 2]).dtype == float
    assert not is_autodiff(np.ones(2))


def test_is_autodiff_looks_at_every_entry():
    assert not is_autodiff(np.array([], dtype=object))
    assert not is_autodiff(np.array([1.0, 2.0], dtype=object))
    assert is_autodiff(np.array([1.0, AutoDiffXd(2.0)], dtype=object))
    assert is_autodiff([0.5, AutoDiffXd(2.0)])
    assert is_autodiff(AutoDiffXd(2.0))
    assert not is_autodiff(2.0)


@pytest.mark.parametrize("shape", [(3,), (2, 3)])
def test_through_float_function_keeps_the_shape(shape):
    x = InitializeAutoDiff(np.array([0.5, 0.25])).ravel()
    y = through_float_function(lambda v: np.full(shape, v.sum()), x)
    assert y.shape == shape


def test_all_finite_agrees_with_numpy_for_every_scalar_type():
    """all_finite against np.isfinite(...).all() on arrays of floats and of
    AutoDiffXd, of several shapes, with NaN, infinities and sums that
    overflow though every term is finite."""
    rng = np.random.default_rng(7)
    specials = [np.nan, np.inf, -np.inf, 1e308, -1e308, 0.0]
    for _ in range(300):
        shape = [(0,), (1,), (3,), (6,), (2, 3)][rng.integers(5)]
        values = rng.normal(size=shape)
        for _ in range(rng.integers(0, 3)):
            if values.size:
                values.flat[rng.integers(values.size)] = rng.choice(specials)
        expected = bool(np.isfinite(values).all())
        assert all_finite(values) is expected, values
        autodiff = InitializeAutoDiff(values.ravel()).reshape(shape)
        assert all_finite(autodiff) is expected, values
        assert all_finite(values.tolist()) is expected, values
    assert all_finite(np.full(4, 1e308))  # an overflowing sum, all finite

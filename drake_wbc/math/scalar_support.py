"""Math that works for every scalar type a stage is converted to.

The stages are `TemplateSystem`s: the same code runs on float arrays and on
numpy object arrays of `AutoDiffXd` (for `Linearize`). Elementwise numpy
works for both; these helpers cover the rest:

- `solve(M, b)`: a linear solve, exact for AutoDiffXd (the derivative of
  x = M^-1 b is M^-1 (db - dM x)), since np.linalg does not take object
  arrays.
- `all_finite(values)`: whether every entry is finite, for any scalar
  type (the stages' guard against a NaN or an infinity in a tick).
- `through_float_function(function, x)`: evaluates a float-only function
  (one that needs a double MultibodyPlant or an SVD) at an AutoDiffXd
  argument and gives its result the chain-rule derivative, with the
  function's Jacobian taken by central differences. The value is exact;
  the derivative carries the truncation error of central differences,
  about 1e-9 relative for smooth functions at the default step.
"""

import math

import numpy as np
from pydrake.autodiffutils import (
    AutoDiffXd,
    ExtractGradient,
    ExtractValue,
    InitializeAutoDiff,
)

CENTRAL_DIFFERENCE_STEP = 1e-6
"""The step of `through_float_function`'s central differences."""


def is_autodiff(array):
    """True if `array` (an array, a sequence or a scalar) holds an
    AutoDiffXd scalar in any entry; False for an empty one."""
    array = np.asarray(array)
    return array.dtype == object and any(
        isinstance(v, AutoDiffXd) for v in array.flat)


def zero_like(value):
    """0 of the scalar type of `value` (a float, or AutoDiffXd 0 with zero
    derivatives; NaN for an infinite or NaN `value`, as `value * 0.0`)."""
    return value * 0.0


def cross(a, b):
    """a x b along the first axis of (3, ...) arrays, for any scalar type
    (np.cross is slow for small arrays and takes no AutoDiffXd)."""
    return np.array([a[1] * b[2] - a[2] * b[1],
                     a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def constant_like(like, constant):
    """`constant` as a scalar of the type of the scalar `like`: a float,
    or an AutoDiffXd with as many derivatives as `like`'s, all zero; for
    any value of `like` (`like * 0 + constant`, the usual way, is NaN for
    an infinite or NaN `like`)."""
    if isinstance(like, AutoDiffXd):
        return AutoDiffXd(constant, np.zeros(like.derivatives().size))
    return constant


def value_of(array):
    """The float value of an array of any scalar type."""
    array = np.asarray(array)
    if array.dtype != object:
        return array.astype(float)
    return ExtractValue(array.ravel()).reshape(array.shape)


def all_finite(values):
    """Whether every entry of `values` (an array of any shape and scalar
    type) is finite."""
    array = np.asarray(values)
    floats = (value_of(array) if array.dtype == object
              else array).ravel().tolist()
    # A sum of floats is finite only if every term is (one that overflows
    # goes on to the entries).
    return math.isfinite(sum(floats)) or all(map(math.isfinite, floats))


def _gradient(array, size):
    """(array.size, size) derivatives of an array (zeros for floats)."""
    flat = np.asarray(array).ravel()
    if flat.dtype != object:
        return np.zeros((flat.size, size))
    gradient = ExtractGradient(flat)
    if gradient.shape[1] == 0:
        return np.zeros((flat.size, size))
    return gradient


def _derivative_count(*arrays):
    counts = [
        ExtractGradient(np.asarray(a).ravel()).shape[1]
        for a in arrays
        if is_autodiff(a)
    ]
    return max(counts, default=0)


def _with_gradient(value, gradient):
    return InitializeAutoDiff(value.ravel(), gradient).reshape(value.shape)


def solve(M, b):
    """Returns x with M x = b, for float or AutoDiffXd M (n, n), b (n,)."""
    if not (is_autodiff(M) or is_autodiff(b)):
        return np.linalg.solve(np.asarray(M, float), np.asarray(b, float))
    k = _derivative_count(M, b)
    M_value, b_value = value_of(M), value_of(b)
    x = np.linalg.solve(M_value, b_value)
    n = x.size
    dM = _gradient(M, k).reshape(n, n, k)
    db = _gradient(b, k)
    dx = np.linalg.solve(M_value, db - np.einsum("ijk,j->ik", dM, x))
    return _with_gradient(x, dx)


def through_float_function(function, x, step=CENTRAL_DIFFERENCE_STEP):
    """Evaluates float-only `function` at `x` of any scalar type.

    For a float `x` this is `function(x)`. For AutoDiffXd `x` the value is
    `function(value(x))` and the derivative is J dx, with J the Jacobian of
    `function` by central differences of size `step`.

    Args:
        function: maps a float vector (n,) to a float array (any shape).
        x: (n,) float or AutoDiffXd vector.

    Returns:
        function's result, as AutoDiffXd when `x` is.
    """
    if not is_autodiff(x):
        return function(np.asarray(x, dtype=float))
    x_value = value_of(x)
    value = np.asarray(function(x_value), dtype=float)
    columns = []
    for i in range(x_value.size):
        dx = np.zeros_like(x_value)
        dx[i] = step
        difference = np.asarray(function(x_value + dx)) - np.asarray(
            function(x_value - dx)
        )
        columns.append(difference.ravel() / (2.0 * step))
    jacobian = np.stack(columns, axis=1)
    k = _derivative_count(x)
    return _with_gradient(value, jacobian @ _gradient(x, k))

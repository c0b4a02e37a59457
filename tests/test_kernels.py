"""Every fast float kernel of the math layer against its reference.

One parametrised test for all of them (drake_wbc.math.kernels): each
kernel is evaluated beside its scalar-generic reference on random inputs
drawn by its own sampler, and must give the same result to 1e-12 relative
to the size of the result's finite entries (its NaNs and infinities
exactly).
"""

import importlib
import pkgutil

import numpy as np
import pytest

import drake_wbc.math
from drake_wbc.math import kernels
from drake_wbc.math.scalar_support import value_of

for _module in pkgutil.iter_modules(drake_wbc.math.__path__):
    importlib.import_module(f"drake_wbc.math.{_module.name}")

SAMPLES = 200
TOLERANCE = 1e-12


def _flat(result):
    """A kernel's or a reference's result as one float vector (results may
    be arrays, tuples of arrays and numbers, or None)."""
    if result is None:
        return np.zeros(0)
    if isinstance(result, tuple | list) and any(
            isinstance(r, tuple | list | np.ndarray) for r in result):
        return np.concatenate([_flat(r) for r in result])
    return np.ravel(value_of(np.asarray(result)).astype(float))


def _name(kernel):
    return f"{kernel.reference.__module__}.{kernel.reference.__qualname__}"


@pytest.mark.parametrize("kernel", kernels.registered_kernels(), ids=_name)
def test_the_kernel_gives_its_references_result(kernel):
    rng = np.random.default_rng(20261201)
    for _ in range(SAMPLES):
        args = kernel.sample(rng)
        expected = _flat(kernel.reference(*args))
        actual = _flat(kernel.fast(*args))
        assert actual.shape == expected.shape
        scale = max(1.0, float(np.max(np.abs(expected), initial=0.0,
                                      where=np.isfinite(expected))))
        np.testing.assert_allclose(actual, expected, rtol=0.0,
                                   atol=TOLERANCE * scale)


def test_an_equation_has_at_most_one_kernel():
    def reference(x):
        return x

    kernels.fast_kernel(reference, sample=lambda rng: (rng.random(),))(
        lambda x: x)
    with pytest.raises(ValueError, match="at most one"):
        kernels.fast_kernel(reference, sample=lambda rng: ())(lambda x: x)
    assert kernels.body_for(reference, float) is not reference
    assert kernels.body_for(reference, object) is reference

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
from drake_wbc.math import compiled, kernels
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
# Samples with entries NaN or infinite make references compute 0 * inf.
@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")
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


def _compiled_functions():
    """Every compiled function (drake_wbc.math.compiled) of the math
    layer's modules."""
    found = []
    for info in pkgutil.iter_modules(drake_wbc.math.__path__):
        module = importlib.import_module(f"drake_wbc.math.{info.name}")
        found += [value for value in vars(module).values()
                  if compiled.is_compiled(value)]
    return found


# Its samples, like the test above's, hold NaN and infinite entries.
@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")
def test_no_tick_compiles_once_the_kernels_are_warm():
    for kernel in kernels.registered_kernels():
        kernels.warm(kernel)
    functions = _compiled_functions()
    signatures = [len(f.signatures) for f in functions]
    rng = np.random.default_rng(7)
    for kernel in kernels.registered_kernels():
        for _ in range(20):
            kernel.fast(*kernel.sample(rng))
    assert [len(f.signatures) for f in functions] == signatures, (
        "a kernel compiled again after warming: its inputs' types differ "
        "between its sample and later calls")


def test_a_compiled_function_computes_as_numpy_does():
    @compiled.compiled
    def ratio(a, b):
        return a / b

    assert compiled.is_compiled(ratio)
    assert ratio(1.0, 0.0) == np.inf
    assert np.isnan(ratio(0.0, 0.0))
    assert not compiled.is_compiled(lambda x: x)


def test_a_sealed_function_refuses_other_arrays_instead_of_compiling():
    """compiled_for compiles its one signature when it is made and never
    again: other arrays raise TypeError (which its wrapper answers with
    float_array copies), numbers convert to its scalars."""
    @compiled.compiled_for("float64(float64[::1], float64)")
    def weighted_sum(x, w):
        return w * x.sum()

    assert compiled.is_compiled(weighted_sum)
    assert len(weighted_sum.signatures) == 1
    x = np.arange(6.0)
    assert weighted_sum(x, 2) == 30.0
    read_only = x.copy()
    read_only.flags.writeable = False
    for other in (x[::2], read_only, list(x), x.astype(np.float32)):
        with pytest.raises(TypeError):
            weighted_sum(other, 1.0)
        assert weighted_sum(compiled.float_array(other), 1.0) == \
            float(np.sum(other, dtype=float))
    assert len(weighted_sum.signatures) == 1


def test_float_array_gives_the_one_array_type_the_compiled_loops_take():
    """A float64 C-contiguous aligned writeable array passes as it is;
    anything else (read-only, strided, unaligned, big-endian, int, a
    list) is copied into one, which a compiled function takes without
    compiling a signature of its own."""
    @compiled.compiled
    def total(x):
        return x.sum()

    right = np.arange(6.0)
    assert compiled.float_array(right) is right
    read_only = np.arange(6.0)
    read_only.flags.writeable = False
    unaligned = np.zeros(6 * 8 + 1, np.uint8)[1:].view(np.float64)
    unaligned[:] = right
    others = [read_only, np.repeat(right, 2)[::2], unaligned,
              right.astype(">f8"), np.arange(6), right.tolist()]
    total(right)
    signatures = list(total.signatures)
    for other in others:
        copy = compiled.float_array(other)
        assert copy is not other
        np.testing.assert_array_equal(copy, np.asarray(other, dtype=float))
        assert total(copy) == total(right)
    assert list(total.signatures) == signatures


CLOSED_LOOP = """
description: a person walking past the base, seen by both LIDARs
duration: 1.5
scene:
  people: [{name: walker, times: [0.0, 4.0],
            waypoints: [[3.0, 1.0], [-3.0, 1.0]]}]
"""


def test_the_closed_loops_ticks_compile_nothing():
    """The simulated station's LIDAR scans (a person walking past, so the
    tracker's and the people's kernels run too) give the compiled loops
    nothing they were not warmed with when the controller was built."""
    from drake_wbc.experiments.runner import build_closed_loop, start_simulator
    from drake_wbc.experiments.scenario import load_scenario

    loop = build_closed_loop(load_scenario(text=CLOSED_LOOP))
    simulator = start_simulator(loop)
    functions = _compiled_functions()
    signatures = [list(f.signatures) for f in functions]
    assert any(signatures)  # warmed when the controller was built
    simulator.AdvanceTo(1.5)
    assert [list(f.signatures) for f in functions] == signatures


def test_no_compiled_function_calls_one_of_another_module():
    """Numba's cache knows a compiled function by its own file only
    (drake_wbc.math.compiled): one that called a compiled function of
    another module would run that one's old machine code after it
    changed."""
    import inspect
    import re

    crossing = []
    for function in _compiled_functions():
        module = function.py_func.__module__
        called = set(re.findall(r"\b([A-Za-z_]\w*)\s*\(",
                                inspect.getsource(function.py_func)))
        for name in called:
            other = function.py_func.__globals__.get(name)
            if (compiled.is_compiled(other)
                    and other.py_func.__module__ != module):
                crossing.append(f"{module}.{function.__name__} -> "
                                f"{other.py_func.__module__}.{name}")
    assert _compiled_functions() and not crossing, crossing

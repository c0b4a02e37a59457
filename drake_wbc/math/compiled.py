"""Machine code for the fast kernels: compiled once, cached on disk.

A fast kernel (drake_wbc.math.kernels) that loops over obstacle points
or joints runs its loops through `compiled`, which is numba's `njit` with
the settings every kernel of the tick shares:

- `cache=True`: the machine code is written beside the module's source
  (or, where that is read-only, to numba's cache directory; set
  NUMBA_CACHE_DIR to choose it) on the first run and loaded from there
  on every later one, so only the very first run of a machine compiles.
- `error_model="numpy"`: a division by zero gives inf or NaN as numpy
  does, never an exception in the middle of a tick; the reference bodies
  do the same.
- no `fastmath`: the kernels keep IEEE rounding, so that they stay equal
  to their references to rounding (tests/test_kernels.py).

A compiled function compiles for the types of its first call; the
kernels give it float64 contiguous arrays and floats only, and
`kernels.body_for` calls each kernel on its own samples when a stage
is built (`kernels.warm`), so that no tick compiles
(tests/test_kernels.py checks that a second call adds no compiled
signature).
"""

import numba


def compiled(function):
    """`function` compiled to machine code (see the module), for the fast
    kernels' inner loops. Numeric code only: numpy arrays and scalars in,
    numpy arrays and scalars out."""
    return numba.njit(cache=True, error_model="numpy")(function)


def is_compiled(function):
    """Whether `function` was made by `compiled` (a numba dispatcher)."""
    return isinstance(function, numba.core.registry.CPUDispatcher)

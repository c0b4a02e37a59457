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
signature). A read-only or strided array is a type of its own to numba:
`float_array` gives the one type they take.

Where those conversions would cost as much as the kernel's own work
(the distribution's closed form runs in under a microsecond),
`compiled_for` compiles a kernel for its one signature when its module
loads (from the cache after the first run) and never again: a call with
any other array type raises TypeError instead of compiling, so that its
wrapper passes the stages' arrays as they are and makes `float_array`
copies only when the call is refused.

Numba's cache knows a compiled function by its own source file only: a
compiled function that calls one of another module would keep that
one's old machine code after the other module changes. So a compiled
function calls compiled functions of its own module only; across
modules, the thin Python wrappers call them one after the other.
"""

import numba
import numpy as np


def compiled(function):
    """`function` compiled to machine code (see the module), for the fast
    kernels' inner loops. Numeric code only: numpy arrays and scalars in,
    numpy arrays and scalars out."""
    return numba.njit(cache=True, error_model="numpy")(function)


def compiled_for(signature):
    """A decorator: `compiled` for exactly `signature` (numba's signature
    string, e.g. "float64[::1](float64[::1], float64)"), compiled when the
    module loads and sealed (see the module): numbers convert to its
    scalars as numba converts them, and any other array type raises
    TypeError."""
    return numba.njit(signature, cache=True, error_model="numpy")


def is_compiled(function):
    """Whether `function` was made by `compiled` (a numba dispatcher)."""
    return isinstance(function, numba.core.registry.CPUDispatcher)


_FLOAT64 = np.dtype(np.float64)


def float_array(values):
    """`values` as a C-contiguous, aligned, writeable float64 numpy array:
    the one array type the compiled loops take (itself when it already is
    one, a copy otherwise), so that no call compiles for a type of its
    own."""
    if (type(values) is np.ndarray and values.flags.carray
            and (values.dtype is _FLOAT64 or values.dtype == _FLOAT64)):
        return values
    return np.array(values, dtype=np.float64, order="C")

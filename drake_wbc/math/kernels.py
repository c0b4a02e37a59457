"""The fast float kernels of the control tick, each beside its reference.

Each equation of the paper has one reference body in this package,
scalar-generic (float and AutoDiffXd), which is what a reader checks
against the paper and what `Linearize` differentiates. Where the control
tick needs speed, an equation may have at most ONE fast kernel beside it:
a float-only function with the reference's arguments and its result (to
rounding), registered with `fast_kernel`:

    def transition(value, upper, lower):            # the reference
        ...

    @fast_kernel(transition, sample=_transition_inputs)
    def transition_float(value, upper, lower):      # the kernel
        ...

A stage chooses once, when it is built, which body it runs
(`body_for(reference, T)`): the kernel in double where there is one, the
reference otherwise (AutoDiffXd, or no kernel). No calculation branches
on the scalar type.

tests/test_kernels.py holds every registered kernel equal to its
reference on random inputs drawn by the kernel's own `sample`.

An equation whose true reference needs a MultibodyPlant (the arm's
kinematics) fits this registry unchanged: its reference body here takes
the plant's data as plain arrays (drake_wbc.math.chain: a serial chain's
fixed poses, axes and kinds), the kernel is held equal to it on random
chains like every other, and the robot layer holds the two equal to the
plant's own kinematics on every robot at hand (tests/test_robot_model.py).

A kernel whose loops are compiled (drake_wbc.math.compiled) compiles on
its first call; `body_for` makes those calls, once per process, on a
few of the kernel's own samples (`warm`), so that a stage's first tick
runs machine code.
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Kernel:
    """A fast float kernel and the reference it stands in for.

    Attributes:
        reference: the scalar-generic reference body of the equation.
        fast: the float kernel; the same arguments, the same result.
        sample: sample(rng) -> a tuple of positional arguments that both
            take, drawn from a numpy Generator (random inputs for the
            test that holds them equal).
    """

    reference: Callable
    fast: Callable
    sample: Callable


_KERNELS: dict[Callable, Kernel] = {}
_WARM: set[Callable] = set()


def fast_kernel(reference, sample):
    """Registers the decorated function as the fast float kernel of
    `reference` (see the module). One equation has at most one kernel:
    registering a second raises ValueError."""

    def register(fast):
        if reference in _KERNELS:
            raise ValueError(
                f"{reference.__module__}.{reference.__qualname__} already "
                f"has a fast kernel ({_KERNELS[reference].fast.__qualname__}"
                f"); an equation has at most one, {fast.__qualname__} is "
                "not allowed")
        _KERNELS[reference] = Kernel(reference, fast, sample)
        return fast

    return register


def body_for(reference, T):
    """The body a stage of scalar type `T` runs for `reference`, chosen
    once when the stage is built: its fast kernel for float, if it has
    one (called on its samples first, see the module); the reference
    otherwise."""
    kernel = _KERNELS.get(reference)
    if T is float and kernel is not None:
        warm(kernel)
        return kernel.fast
    return reference


WARM_SAMPLES = 8
"""Samples `warm` calls a kernel on: a kernel that leaves some cases to
its reference (the distribution's closed form, for a turned mounting)
reaches its compiled path on most samples, not on every one."""


def warm(kernel):
    """Calls `kernel.fast` on its own samples (WARM_SAMPLES of them, from
    one seeded generator), the first time only, so that whatever it
    compiles is compiled before a tick needs it."""
    if kernel.fast not in _WARM:
        rng = np.random.default_rng(0)
        for _ in range(WARM_SAMPLES):
            kernel.fast(*kernel.sample(rng))
        _WARM.add(kernel.fast)


def registered_kernels():
    """Every registered Kernel, in the order of registration (import the
    math modules first: registering happens when they load)."""
    return tuple(_KERNELS.values())

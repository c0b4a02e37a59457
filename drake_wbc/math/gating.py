"""The stop switch of the controller's run-time safety: a signal passed
on, or zeros during a safe stop. The controller holds the inputs of the
DMPs' couplings with it, so that they do not integrate while stopped
(drake_wbc.controller.diagram); the stop is InputGuard's decision, 0 or
1 (drake_wbc.math.safety), and any value >= 0.5 counts as a stop.

One function for double, AutoDiffXd and symbolic Expressions: on
symbolic variables it builds the expressions of the C++
SymbolicVectorSystem of drake_wbc.stages.stop_switch, so that the
stage evaluates this very function without Python.
"""

import numpy as np
import pydrake.symbolic as sym
from pydrake.symbolic import Expression, Variable

STOP_THRESHOLD = 0.5
"""A stop signal at or above this is a stop."""


def _is_symbolic(*values):
    return any(isinstance(v, (Expression, Variable)) for v in values)


def stop_switched(value, stop):
    """`value` (any size) while stop < STOP_THRESHOLD, zeros while
    stop >= STOP_THRESHOLD; per entry `if_then_else(stop >= 0.5, 0, v)`
    when either is symbolic. Returns an array of value's entries (the
    very entries when passed on)."""
    value = np.asarray(value)
    if _is_symbolic(stop, *value.ravel()):
        zero = Expression(0.0)
        return np.array([sym.if_then_else(stop >= STOP_THRESHOLD, zero,
                                          Expression(v)) for v in value])
    if stop >= STOP_THRESHOLD:
        return np.zeros(value.shape)
    return value

"""Joint position ranges where a continuous joint has none.

A revolute joint without position limits (a continuous joint: URDF's
type="continuous", whose limits Drake gives as -inf and inf) is limited
on neither side: the controller keeps no margin from an edge it does not
have, and its factor of the joint-limit penalization is the one of a
joint at mid-range (drake_wbc.math.capability). Its configurations repeat
every turn, so one turn holds all of them: that is the range to draw
configurations from (`configuration_range`).
"""

import math

import numpy as np

ONE_TURN = (-math.pi, math.pi)
"""rad: the range `configuration_range` gives a continuous joint."""


def unlimited(lower, upper):
    """(n,) bool: True for each joint whose position limits are
    (-inf, inf), a continuous joint's."""
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper,
                                                               dtype=float)
    return (lower == -math.inf) & (upper == math.inf)


def configuration_range(lower, upper):
    """(lower, upper), (n,) float arrays: the joint position limits with
    each continuous joint's (-inf, inf) replaced by ONE_TURN, which holds
    every configuration of such a joint; a limited joint keeps its own
    (the very values given)."""
    lower = np.array(lower, dtype=float)
    upper = np.array(upper, dtype=float)
    free = unlimited(lower, upper)
    lower[free], upper[free] = ONE_TURN
    return lower, upper

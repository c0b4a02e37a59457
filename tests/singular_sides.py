"""The two one-sided gradients of C_m at a configuration with one zero
singular value of J_a (drake_wbc.math.capability.
manipulability_joint_gradient): there the gradient has no side, and which
one a body returns depends on the signs its SVD's LAPACK gives."""

import numpy as np

from drake_wbc.math import capability


def one_sided_gradients(J_a, *args, delta=1e-9):
    """grad_x C_m (capability.capability_terms with `args`: q, lower,
    upper, k_j, damping, damping_threshold) at J_a + delta u v^T and
    J_a - delta u v^T, u and v the singular vectors of J_a's smallest
    singular value: the limits from either side, to O(delta)."""
    U, _, Vt = np.linalg.svd(J_a)
    step = delta * np.outer(U[:, -1], Vt[J_a.shape[0] - 1])
    return [capability.capability_terms(J_a + side * step, *args)[1]
            for side in (1.0, -1.0)]


def is_one_of(gradient, sides, rtol=1e-4):
    """Whether `gradient` is one of `sides` to rtol of its size."""
    return min(np.linalg.norm(gradient - side) for side in sides) <= (
        rtol * np.linalg.norm(sides[0]))

"""Capability of movement C_m of the arm and the transition alpha (Sec. III-A).

The capability of movement C_m = m * P_jnt ("Movement Capability
Optimization") multiplies Yoshikawa's manipulability index m (distance to
singularity) by the joint-limit penalization P_jnt (distance to the joint
limits). Its gradient w.r.t. the arm's Cartesian pose, grad_x C_m, drives
the null-space term of eq. (wbccm) and is the direction that the
compensation of eq. (wb_error) must not worsen, a projection faded in by
the transition alpha of eq. (transition) as C_m drops from C_m^u to C_m^l.
Here: m, P_jnt, C_m and alpha with its derivative; the gradients of C_m
are in drake_wbc.math.capability_gradients.

J_a is the 6 x n geometric Jacobian of the tool point in the arm's base frame
T_a, rows [v; w] (linear velocity of the tool point in m/s, angular velocity
in rad/s per joint rate in rad/s), columns the joint rates of an
all-revolute serial chain (n = 6 for the Elfin5).
"""

import math

import numpy as np

from drake_wbc.math.validation import (
    as_matrix,
    as_scalar,
    as_vector,
    ordered_limits,
    positive,
)

DEFAULT_JOINT_LIMIT_GAIN = 1.5e4
"""Default scaling factor k_j of P_jnt (dimensionless).

Scaling: each factor (q_i - l_i)(u_i - q_i) / (u_i - l_i)^2 of P_jnt is at
most 1/4, reached at mid-range, so their product over n joints is at most
4^-n (1/4096 for six joints). k_j must therefore be of order 4^n for P_jnt
to approach 1 at mid-range. For n = 6 and this default:

    every joint mid-range:  P_jnt = 1 - exp(-k_j 4^-6)
                                  = 1 - exp(-3.66) = 0.974,
    one joint 5% of its range from a limit, the others mid-range
    (its factor is 0.05 * 0.95 = 0.19 / 4 instead of 1/4):
                            P_jnt = 1 - exp(-0.19 k_j 4^-6)
                                  = 1 - exp(-0.696) = 0.501.

Why 1.5e4 on our arm: it makes the paper's limitation band
0.035 < C_m < 0.04 mean "close to a constraint" on the Elfin5 with the
wiping tool. At the home pose (drake_wbc.robot.model.HOME_ARM_POSITIONS)
m = 0.071 and P_jnt = 0.91, so C_m = 0.065, well above the band. Moving
one joint from home, C_m enters the band either when that joint comes
within about 8 to 12% of its range from a limit (P_jnt falls to 0.5-0.6
with m unchanged), or when the manipulability itself falls to about 0.04
(the elbow opening towards the stretched singularity, or the wrist
straightening), with P_jnt still above 0.9. A smaller k_j (5e3) would put
home itself inside the band; a larger one (3e4) would let joints come
within about 4% of a limit before the band is reached.
"""


def _as_jacobian(J_a, rows=None, wide=True):
    """Returns J_a as a finite float matrix with `rows` rows (any number if
    None) and, if `wide`, at least as many columns as rows."""
    J = as_matrix("J_a", J_a, (rows, None))
    if J.size == 0 or (wide and J.shape[0] > J.shape[1]):
        raise ValueError(
            f"J_a has shape {J.shape}, which is not allowed: must be "
            "non-empty" + (" with at least as many columns as rows"
                           if wide else "")
        )
    return J


def _as_limits(q, lower, upper, size=None):
    """Returns q, lower, upper, checked float vectors of one size, as lists
    of floats."""
    q = as_vector("q", q, size)
    lower, upper = ordered_limits("lower", lower, "upper", upper, q.size)
    return q.tolist(), lower.tolist(), upper.tolist()


def _products_of_others(values):
    """Returns p (a list) with p_k = prod_{l != k} values_l, computed without
    any division (the product of the values before k times that of the
    values after k), so that it stays exact when some values are 0.

    Args:
        values: a sequence of floats (a few numbers: a list of plain
            floats is the fastest).
    """
    n = len(values)
    products = [1.0] * n
    before = 1.0
    for k in range(1, n):  # first the product of the values before k
        before *= values[k - 1]
        products[k] = before
    after = 1.0
    for k in range(n - 2, -1, -1):  # times that of the values after k
        after *= values[k + 1]
        products[k] *= after
    return products


def _penalty_and_gradient(q, lower, upper, k_j):
    """P_jnt and dP_jnt/dq (a list) for checked inputs (see the public
    functions): q, lower and upper lists of floats, k_j a float. Plain
    floats: a handful of them, for which numpy calls cost more than the
    arithmetic."""
    factors, slopes = [], []
    for q_i, l_i, u_i in zip(q, lower, upper, strict=True):
        if q_i < l_i:
            q_i = l_i
        elif q_i > u_i:
            q_i = u_i
        span2 = (u_i - l_i) * (u_i - l_i)
        factors.append((q_i - l_i) * (u_i - q_i) / span2)
        slopes.append((u_i + l_i - 2.0 * q_i) / span2)
    product = math.prod(factors)
    penalty = -math.expm1(-k_j * product)
    scale = k_j * math.exp(-k_j * product)
    gradient = [scale * slope * others for slope, others
                in zip(slopes, _products_of_others(factors), strict=True)]
    return penalty, gradient


def manipulability(J_a):
    """Yoshikawa's manipulability index m (Sec. III-A, "manipulability
    index"): m = sqrt(det(J_a J_a^T)) = prod_i s_i.

    Computed as the product of the singular values s_i of J_a, which stays
    accurate near a singularity where det(J_a J_a^T) loses all its digits.

    Args:
        J_a: (k, n) matrix with k <= n; for the arm the (6, n) geometric
            Jacobian [v; w] of the tool point in T_a.

    Returns:
        m >= 0 as a float, in metres^3 for the arm's Jacobian (three rows
        in m/rad); 0, to rounding, only at a singularity.
    """
    J = _as_jacobian(J_a)
    return float(np.prod(np.linalg.svd(J, compute_uv=False)))


def joint_limit_penalty(q, lower, upper, k_j=DEFAULT_JOINT_LIMIT_GAIN):
    """Joint-limit penalization P_jnt (Sec. III-A, "penalization"):

        P_jnt = 1 - exp(-k_j prod_i (q_i - l_i)(u_i - q_i) / (u_i - l_i)^2).

    P_jnt is 0 when any joint is at a limit and largest, 1 - exp(-k_j 4^-n),
    when every joint is mid-range (see `DEFAULT_JOINT_LIMIT_GAIN`). A joint
    beyond a limit (a simulated joint can overshoot by a hair) is clamped to
    that limit, so that P_jnt = 0 there rather than a meaningless value.

    Args:
        q: (n,) joint angles q_a, rad.
        lower: (n,) lower joint limits q^l, rad.
        upper: (n,) upper joint limits q^u, rad, each > its lower limit.
        k_j: scaling factor k_j > 0, dimensionless.

    Returns:
        P_jnt in [0, 1), dimensionless, as a float.
    """
    q, lower, upper = _as_limits(q, lower, upper)
    k_j = positive("k_j", k_j)
    return _penalty_and_gradient(q, lower, upper, k_j)[0]


def capability(J_a, q, lower, upper, k_j=DEFAULT_JOINT_LIMIT_GAIN):
    """Capability of movement C_m = m * P_jnt (Sec. III-A, the equation
    before eq. (wbccm)).

    Args:
        J_a: (6, n) geometric Jacobian [v; w] of the tool point in T_a at q.
        q: (n,) joint angles q_a, rad.
        lower, upper: (n,) joint limits, rad (see `joint_limit_penalty`).
        k_j: scaling factor k_j > 0 of P_jnt.

    Returns:
        C_m >= 0 as a float, in the units of m (metres^3 for the arm).
    """
    J = _as_jacobian(J_a, rows=6)
    q, lower, upper = _as_limits(q, lower, upper, J.shape[1])
    k_j = positive("k_j", k_j)
    penalty = _penalty_and_gradient(q, lower, upper, k_j)[0]
    return float(np.prod(np.linalg.svd(J, compute_uv=False)) * penalty)


def _as_values(value):
    """Returns (value as float or float array, whether it was a scalar)."""
    try:
        shape = np.shape(value)
    except ValueError:
        raise ValueError(
            f"value = {value!r} is not allowed: must be a number or an "
            "array of numbers"
        ) from None
    if shape == ():
        return as_scalar("value", value), True
    return as_vector("value", np.ravel(value)).reshape(shape), False


def _transition_band(value, upper, lower):
    """Checked value, the position x of value in the band and its width."""
    value, scalar = _as_values(value)
    lower, upper = ordered_limits("lower", lower, "upper", upper, 1)
    width = upper[0] - lower[0]
    return (value - lower[0]) / width, width, scalar


def transition(value, upper, lower):
    """Transition function alpha(C_m, C_m^u, C_m^l) of eq. (transition):

        alpha = 0                                   for value >= upper,
        alpha = 0.5 (1 + cos(pi x)),
                x = (value - lower) / (upper - lower)  in between,
        alpha = 1                                   for value <= lower.

    alpha is continuous with a continuous derivative (0 at both band edges)
    and non-increasing in `value`.

    Args:
        value: C_m, a number or an array of numbers (elementwise).
        upper: upper threshold C_m^u.
        lower: lower threshold C_m^l, < upper.

    Returns:
        alpha in [0, 1], dimensionless: a float for a scalar `value`, else
        an array of the shape of `value`.
    """
    x, _, scalar = _transition_band(value, upper, lower)
    alpha = 0.5 * (1.0 + np.cos(np.pi * np.clip(x, 0.0, 1.0)))
    return float(alpha) if scalar else alpha


def transition_derivative(value, upper, lower):
    """Derivative d alpha / d value of eq. (transition):

        -0.5 pi / (upper - lower) * sin(pi x)  inside the band, else 0,

    with x as in `transition`. It vanishes at both band edges, so alpha is
    C^1 across them.

    Args:
        value, upper, lower: as for `transition`.

    Returns:
        d alpha / d value <= 0, in 1 / (units of value): a float for a
        scalar `value`, else an array of the shape of `value`.
    """
    x, width, scalar = _transition_band(value, upper, lower)
    inside = (x > 0.0) & (x < 1.0)
    slope = np.where(inside, -0.5 * np.pi / width * np.sin(np.pi * x), 0.0)
    return float(slope) if scalar else slope


def transition_unchecked(value, upper, lower):
    """alpha of eq. (transition) (see `transition`) for a float value and
    thresholds already checked (lower < upper); a float."""
    x = min(max((value - lower) / (upper - lower), 0.0), 1.0)
    return 0.5 * (1.0 + math.cos(math.pi * x))

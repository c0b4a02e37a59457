"""Analytic gradients of the capability of movement C_m (Sec. III-A).

The gradient of C_m = m * P_jnt (drake_wbc.math.capability) w.r.t. the arm's
Cartesian pose, grad_x C_m, drives the null-space term of eq. (wbccm) and is
the direction that the compensation of eq. (wb_error) must not worsen. Here:
the derivative of the geometric Jacobian w.r.t. the joints, the joint-space
gradients dm/dq, dP_jnt/dq and dC_m/dq, and grad_x C_m itself (damped near
a singularity), with the per-tick path that gives C_m and grad_x C_m from one
SVD.

J_a is the 6 x n geometric Jacobian of the tool point in the arm's base frame
T_a, rows [v; w] (linear velocity of the tool point in m/s, angular velocity
in rad/s per joint rate in rad/s), columns the joint rates of an
all-revolute serial chain (n = 6 for the Elfin5). All gradients here are
analytic, computed from J_a and q alone: no AutoDiff, no finite differences.
"""

import math

import numpy as np
from scipy.linalg.lapack import dgesdd

from drake_wbc.math.capability import (
    DEFAULT_JOINT_LIMIT_GAIN,
    _as_jacobian,
    _as_limits,
    _penalty_and_gradient,
    _products_of_others,
)
from drake_wbc.math.validation import non_negative, positive

DEFAULT_DAMPING_THRESHOLD = 0.02
"""Default threshold eps on the smallest singular value s_min of J_a, below
which `capability_gradient` damps its solve. For the Elfin5, s_min is about
0.2 d within d rad of the wrist singularity (q_5 = 0) and about 0.16 d near
the stretched elbow (q_3 = 0): 0.02 damps roughly the last 0.1 rad."""

DEFAULT_MAX_DAMPING = 0.02
"""Default damping lambda_max of `capability_gradient` (at s_min = 0). Equal
to eps, so that below eps s_min^2 + lambda^2 = eps^2: the gain
s_min / eps^2 of the weakest direction falls linearly from 1/eps to 0,
meeting the undamped gain 1/s_min continuously at s_min = eps."""


def _cross(a, b):
    """a x b along the first axis of (3, ...) arrays (np.cross is slow for
    small arrays)."""
    return np.array([a[1] * b[2] - a[2] * b[1],
                     a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def _svd(J):
    """The thin SVD (U, s, Vt) of a checked J (rows <= columns), by LAPACK's
    dgesdd directly (as np.linalg.svd, without its overhead)."""
    U, s, Vt, info = dgesdd(J, compute_uv=1, full_matrices=0)
    if info != 0:
        return np.linalg.svd(J, full_matrices=False)
    return U, s, Vt


def _manipulability_gradient(J, U, s, Vt):
    """dm/dq (a list) from J and its thin SVD J = U diag(s) Vt, s a list
    (see `manipulability_joint_gradient` for the derivation).

    With W = U diag(m / s_k) Vt (6, n), dm/dq_i = sum_j W_j . dJ_j/dq_i
    over the columns j, and by the rules of `jacobian_derivative` and the
    triple product a . (b x c) = b . (c x a) = c . (a x b):

        dm/dq_i = Jw_i . a_i + Jv_i . b_i,
        a_i = sum_{j >= i} (Jv_j x Wv_j + Jw_j x Ww_j),
        b_i = sum_{j < i} (Wv_j x Jw_j),

    O(n) with running sums, without forming the (n, 6, n) derivative; in
    plain floats, which for a few columns beat any sequence of numpy calls.
    """
    W = (U * _products_of_others(s)) @ Vt  # m / s_k, with no division
    J0, J1, J2, J3, J4, J5 = J.tolist()
    W0, W1, W2, W3, W4, W5 = W.tolist()
    n = len(J0)
    gradient = [0.0] * n
    ax = ay = az = 0.0
    for j in range(n - 1, -1, -1):  # a_j, summed from the last column
        vx, vy, vz, wx, wy, wz = J0[j], J1[j], J2[j], J3[j], J4[j], J5[j]
        Vx, Vy, Vz, Wx, Wy, Wz = W0[j], W1[j], W2[j], W3[j], W4[j], W5[j]
        ax += (vy * Vz - vz * Vy) + (wy * Wz - wz * Wy)
        ay += (vz * Vx - vx * Vz) + (wz * Wx - wx * Wz)
        az += (vx * Vy - vy * Vx) + (wx * Wy - wy * Wx)
        gradient[j] = (wx, wy, wz, ax, ay, az)
    bx = by = bz = 0.0
    for i in range(n):  # b_i, summed from the first column
        wx, wy, wz, ax, ay, az = gradient[i]
        vx, vy, vz = J0[i], J1[i], J2[i]
        gradient[i] = ((wx * ax + vx * bx) + (wy * ay + vy * by)
                       + (wz * az + vz * bz))
        Vx, Vy, Vz = W0[i], W1[i], W2[i]
        bx += Vy * wz - Vz * wy
        by += Vz * wx - Vx * wz
        bz += Vx * wy - Vy * wx
    return gradient


def jacobian_derivative(J_a):
    """Partial derivatives dJ_a/dq_i of a revolute chain's geometric
    Jacobian, from J_a alone.

    Column j of J_a is [z_j x (p - p_j); z_j]: z_j the unit axis of joint
    j, p_j a point on it, p the tool point, all in the fixed frame T_a.
    Turning joint i moves the links after it rigidly about axis i: a vector r
    on them changes as dr/dq_i = z_i x r, the tool point as dp/dq_i = Jv_i.
    With J_j = [Jv_j; Jw_j]:

    - i <= j: z_j and p - p_j ride on the moving links, and by the Jacobi
      identity dJv_j/dq_i = z_i x Jv_j = Jw_i x Jv_j, dJw_j/dq_i =
      Jw_i x Jw_j;
    - i > j: z_j and p_j stay, only p moves: dJv_j/dq_i = Jw_j x Jv_i,
      dJw_j/dq_i = 0.

    Args:
        J_a: (6, n) geometric Jacobian [v; w] of the tool point in the fixed
            frame T_a, all joints revolute; m/rad and rad/rad.

    Returns:
        (n, 6, n) array D with D[i] = dJ_a/dq_i, per rad.
    """
    J = _as_jacobian(J_a, rows=6, wide=False)
    Jv, Jw = J[:3].T, J[3:].T  # (n, 3): row j is column j of J_a
    # [:, i, j] = Jw_i x Jv_j and Jw_i x Jw_j (vector first).
    w_x_v = _cross(Jw.T[:, :, None], Jv.T[:, None, :])
    w_x_w = _cross(Jw.T[:, :, None], Jw.T[:, None, :])
    upper = np.triu(np.ones((J.shape[1],) * 2, dtype=bool))
    dJv = np.where(upper, w_x_v, np.swapaxes(w_x_v, 1, 2))
    dJw = np.where(upper, w_x_w, 0.0)
    return np.concatenate([dJv, dJw], axis=0).transpose(1, 0, 2)


def manipulability_joint_gradient(J_a):
    """Gradient dm/dq of the manipulability index, analytic from J_a.

    Derivation: m^2 = det(J J^T), so 2 m dm = m^2 tr((J J^T)^-1 d(J J^T))
    = 2 m^2 tr((J J^T)^-1 J dJ^T), hence dm = m tr(J^+ dJ) with
    J^+ = J^T (J J^T)^-1. With the thin SVD J = U diag(s) V^T,
    m J^+ = V diag(m / s_k) U^T and m / s_k = prod_{l != k} s_l, so

        dm/dq_i = sum_k (prod_{l != k} s_l) u_k^T (dJ/dq_i) v_k,

    with dJ/dq_i from `jacobian_derivative`. This form has no division and
    stays finite as m -> 0. Where m > 0 it is the exact gradient. At an
    exact singularity m has no gradient: with one zero singular value m
    behaves like |linear| and the value returned is one of its two
    one-sided gradients (which one depends on the signs the SVD picks for
    u_k, v_k), either of them an ascent direction out of the singularity;
    with two or more zero singular values m vanishes to second order and
    the exact gradient, 0, is returned.

    Args:
        J_a: (6, n) geometric Jacobian [v; w] of the tool point in T_a,
            n >= 6, all joints revolute.

    Returns:
        (n,) array dm/dq, in units of m (metres^3) per rad.
    """
    J = _as_jacobian(J_a, rows=6)
    U, s, Vt = _svd(J)
    return np.array(_manipulability_gradient(J, U, s.tolist(), Vt))


def joint_limit_penalty_gradient(q, lower, upper,
                                 k_j=DEFAULT_JOINT_LIMIT_GAIN):
    """Gradient dP_jnt/dq of the penalization of `joint_limit_penalty`.

    With f_i = (q_i - l_i)(u_i - q_i) / (u_i - l_i)^2 and F = prod_i f_i:

        dP_jnt/dq_i = k_j exp(-k_j F) (u_i + l_i - 2 q_i) / (u_i - l_i)^2
                      * prod_{j != i} f_j,

    the product of the other factors computed directly (not F / f_i), so
    that it stays right with a joint at a limit (f_i = 0): there the
    component of that joint points back into the range and the others are
    0. A joint beyond a limit is clamped to it as in `joint_limit_penalty`,
    and the gradient is the one at the clamped configuration.

    Args:
        q, lower, upper, k_j: as for `joint_limit_penalty`.

    Returns:
        (n,) array dP_jnt/dq, per rad.
    """
    q, lower, upper = _as_limits(q, lower, upper)
    k_j = positive("k_j", k_j)
    return np.array(_penalty_and_gradient(q, lower, upper, k_j)[1])


def _capability_and_gradient(J, q, lower, upper, k_j):
    """C_m, dC_m/dq (a list) and the SVD (U, s as a list, Vt) of J for
    checked inputs (q, lower, upper: sequences of floats, lists the
    fastest)."""
    U, s, Vt = _svd(J)
    s = s.tolist()
    m = math.prod(s)
    penalty, penalty_gradient = _penalty_and_gradient(q, lower, upper, k_j)
    gradient = [penalty * dm + m * dp for dm, dp in zip(
        _manipulability_gradient(J, U, s, Vt), penalty_gradient,
        strict=True)]
    return m * penalty, gradient, (U, s, Vt)


def capability_joint_gradient(J_a, q, lower, upper,
                              k_j=DEFAULT_JOINT_LIMIT_GAIN):
    """Gradient dC_m/dq = P_jnt dm/dq + m dP_jnt/dq of C_m = m * P_jnt.

    See `manipulability_joint_gradient` for the value at an exact
    singularity and `joint_limit_penalty_gradient` for joints at or beyond
    a limit.

    Args:
        J_a: (6, n) geometric Jacobian [v; w] of the tool point in T_a at q,
            n >= 6, all joints revolute.
        q, lower, upper, k_j: as for `joint_limit_penalty`.

    Returns:
        (n,) array dC_m/dq, in units of C_m per rad.
    """
    J = _as_jacobian(J_a, rows=6)
    q, lower, upper = _as_limits(q, lower, upper, J.shape[1])
    k_j = positive("k_j", k_j)
    return np.array(_capability_and_gradient(J, q, lower, upper, k_j)[1])


def capability_gradient(J_a, q, lower, upper, k_j=DEFAULT_JOINT_LIMIT_GAIN,
                        damping=DEFAULT_MAX_DAMPING,
                        damping_threshold=DEFAULT_DAMPING_THRESHOLD):
    """Gradient grad_x C_m of C_m w.r.t. the arm's Cartesian pose, as used
    in eq. (wbccm) and eq. (wb_error).

    Definition: the covector g such that dC_m/dt = g . V_a for every arm
    twist V_a = [v_a; w_a] = J_a qdot (in T_a, at the tool point), i.e.
    J_a^T g = dC_m/dq, so g = J_a^-T dC_m/dq for a square nonsingular J_a.
    It is analytic, from J_a alone (see `capability_joint_gradient`); no
    AutoDiff.

    It is solved as g = (J_a J_a^T + lambda^2 I)^-1 J_a dC_m/dq, evaluated
    through the SVD of J_a. lambda = 0 (the exact J_a^-T, or the
    least-squares solution if n > 6) unless the smallest singular value
    s_min is below the threshold eps, where
    lambda^2 = lambda_max^2 (1 - (s_min / eps)^2) grows continuously from 0.
    This damping is the only approximation. A zero singular value with
    lambda = 0 gets gain 0 (pseudo-inverse).

    Args:
        J_a: (6, n) geometric Jacobian [v; w] of the tool point in T_a at q,
            n >= 6, all joints revolute.
        q, lower, upper, k_j: as for `joint_limit_penalty`.
        damping: lambda_max >= 0, in the units of the singular values of
            J_a; 0 turns damping off. Default `DEFAULT_MAX_DAMPING`.
        damping_threshold: eps > 0. Default `DEFAULT_DAMPING_THRESHOLD`.

    Returns:
        (6,) array g = [g_v; g_w]: C_m per m along v_a, C_m per rad along
        w_a.
    """
    J = _as_jacobian(J_a, rows=6)
    q, lower, upper = _as_limits(q, lower, upper, J.shape[1])
    k_j = positive("k_j", k_j)
    lambda_max = non_negative("damping", damping)
    eps = positive("damping_threshold", damping_threshold)
    _, joint_gradient, svd = _capability_and_gradient(J, q, lower, upper, k_j)
    return _cartesian_gradient(joint_gradient, svd, lambda_max, eps)


def _cartesian_gradient(joint_gradient, svd, lambda_max, eps):
    """g = (J J^T + lambda^2 I)^-1 J dC_m/dq through the thin SVD
    svd = (U, s, Vt) of J, s a list (see capability_gradient);
    joint_gradient a sequence of n floats. The gains s_k / (s_k^2 +
    lambda^2) in plain floats (0 for a zero denominator)."""
    U, s, Vt = svd
    s_min = s[-1]
    lambda2 = (lambda_max**2 * (1.0 - (s_min / eps) ** 2)
               if s_min < eps else 0.0)
    gains = []
    for s_k in s:
        denominator = s_k * s_k + lambda2
        gains.append(s_k / denominator if denominator > 0.0 else 0.0)
    return U @ (np.array(gains) * (Vt @ np.array(joint_gradient)))


def capability_terms_unchecked(J_a, q, lower, upper, k_j, damping,
                               damping_threshold):
    """C_m and grad_x C_m together, from one SVD of J_a, for arguments
    already checked: the per-tick path of the controller's ArmCapability,
    whose parameters are checked once at construction.

    The same values as `capability` and `capability_gradient` (to
    rounding); nothing is checked here: J_a (6, n) float array with
    n >= 6, q, lower and upper (n,) finite floats (arrays or, the
    fastest, lists) with lower < upper, k_j > 0, damping >= 0 and
    damping_threshold > 0.

    Returns:
        (C_m, g): C_m as a float and g = grad_x C_m (6,).
    """
    C_m, joint_gradient, svd = _capability_and_gradient(J_a, q, lower,
                                                        upper, k_j)
    return float(C_m), _cartesian_gradient(joint_gradient, svd, damping,
                                           damping_threshold)

"""Weighted whole-body motion distribution (paper Sec. III-B and IV-A).

The end-effector twist V_ee (6,) is split into the whole-body input
V_wb = [V_a; V_b] (9,) by the weighted least-norm solution of eq. (wln),

    V_wb = J^+ V_ee + (I - J^+ J) V_n^0,   J^+ = Q J^T (J Q J^T)^-1,

eq. (wbsln) with Q = W^-1 of eq. (weight-factors), and with the null-space
velocity V_n^0 = k_n [grad_x C_m; 0_3] of eq. (wbccm).

The weighting matrix Q, the weighted pseudo-inverse J^+ with its damping
near singularity, and the proof that J Q J^T stays positive definite for
the controller's J_wb = [R_ba, J_b] (so that no damping happens there and
J_wb V_wb = V_ee holds exactly) are in drake_wbc.math.pseudoinverse. The closed
form for ^bR_a = I in plain floats, the controller's per-tick path, is
drake_wbc.math.aligned_distribution.
"""

import math

import numpy as np

from drake_wbc.math.pseudoinverse import (
    DEFAULT_DAMPING,
    certified_solve,
    checked_damping,
    pseudoinverse_by_rule,
    weights_of,
)
from drake_wbc.math.validation import (
    as_float_array,
    in_closed_range,
    non_negative,
)


def _unit_interval(name, value):
    """validation.in_closed_range(name, value, 0, 1), with a fast path for
    a float in [0, 1] (finite, and not NaN, since it compares)."""
    if type(value) is float and 0.0 <= value <= 1.0:
        return value
    return in_closed_range(name, value, 0.0, 1.0)


def distribute_unchecked(J_wb, V_ee, weights, null_velocity=None,
                         damping=DEFAULT_DAMPING):
    """`distribute` for float arguments already checked, Q given by its
    diagonal `weights` (9,) (see pseudoinverse.weights_of): the per-tick
    path of the controller, which checks its parameters once at
    construction.

        V_wb = Q J^T (J Q J^T)^-1 (V_ee - J V_n^0) + V_n^0,

    the same as J^+ V_ee + (I - J^+ J) V_n^0 of eq. (wbccm), with the
    damping of pseudoinverse.weighted_pseudoinverse. Nothing is checked
    here: J_wb (6, 9), V_ee (6,) and null_velocity (9,) or None must be
    finite float arrays, weights non-negative and damping a
    SingularityDamping or None.

    Returns:
        (9,) array V_wb = [V_a (6, T_a); V_b (3, T_b)].
    """
    JQ = J_wb * weights
    if damping is not None:
        rhs = (V_ee if null_velocity is None
               else V_ee - J_wb @ null_velocity)
        x = certified_solve(J_wb, JQ, rhs, damping.threshold)
        if x is not None:
            return JQ.T @ x if null_velocity is None else (
                JQ.T @ x + null_velocity)
    J_pinv = pseudoinverse_by_rule(J_wb, JQ, damping)
    V_wb = J_pinv @ V_ee
    if null_velocity is not None:
        V_wb += null_velocity - J_pinv @ (J_wb @ null_velocity)
    return V_wb


def capability_null_velocity(grad_x_C_m, k_n):
    """Null-space velocity V_n^0 = k_n [grad_x C_m; 0_3] of eq. (wbccm).

    Args:
        grad_x_C_m: (6,) gradient of the movement capability C_m w.r.t.
            the arm's Cartesian pose coordinates, ordered and expressed like
            V_a ([linear; angular], T_a).
        k_n: gain k_n >= 0 of the secondary task (0 switches it off, as
            the paper does when C_m exceeds C_m^u).

    Returns:
        (9,) array V_n^0, ordered like V_wb; its base part is zero.

    Raises:
        ValueError: if grad_x_C_m is not 6 finite numbers or k_n is
            negative or not finite.
    """
    grad = as_float_array("grad_x_C_m", grad_x_C_m, (6,))
    gain = (k_n if type(k_n) is float and 0.0 <= k_n < math.inf
            else non_negative("k_n", k_n))
    V_n = np.zeros(9)
    V_n[:6] = gain * grad
    return V_n


def distribute(
    J_wb,
    V_ee,
    sigma_xy,
    sigma_phi,
    null_velocity=None,
    damping=DEFAULT_DAMPING,
):
    """Whole-body input V_wb for an end-effector twist, eq. (wbsln)/(wbccm).

        V_wb = J^+ V_ee + (I - J^+ J_wb) V_n^0,

    with J^+ the weighted pseudo-inverse for Q(sigma_xy, sigma_phi) of
    eq. (weight-factors). The null-space term does not change the
    end-effector twist: J_wb (I - J^+ J_wb) = 0 whenever no damping is
    needed (always for J_wb = [R_ba, J_b], see drake_wbc.math.pseudoinverse).

    Args:
        J_wb: (6, 9) whole-body Jacobian, normally [R_ba, J_b] (eq. (1),
            bottom line) from kinematics.whole_body_jacobian(None, ...).
        V_ee: (6,) end-effector twist [v; w] in T_b (m/s; rad/s).
        sigma_xy: weighting factor of the x-y translation, in [0, 1].
        sigma_phi: weighting factor of the rotation about z, in [0, 1].
        null_velocity: (9,) V_n^0, ordered like V_wb, e.g. from
            capability_null_velocity; None for no null-space motion.
        damping: see pseudoinverse.weighted_pseudoinverse.

    Returns:
        (9,) array V_wb = [V_a (6, T_a); V_b (3, T_b)].

    Raises:
        ValueError: on a bad argument (wrong shape, non-finite entry, sigma
            outside [0, 1]), naming it.
    """
    J = as_float_array("J_wb", J_wb, (6, 9))
    V_ee = as_float_array("V_ee", V_ee, (6,))
    weights = weights_of(_unit_interval("sigma_xy", sigma_xy),
                         _unit_interval("sigma_phi", sigma_phi))
    V_n = (None if null_velocity is None
           else as_float_array("null_velocity", null_velocity, (9,)))
    return distribute_unchecked(J, V_ee, weights, V_n,
                                checked_damping(damping))

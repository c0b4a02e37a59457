"""Robust compensation of the filtered base motion (paper Sec. IV-A).

The base command V_b from eq. (wbccm) is low-pass filtered, eq.
(filtering), before it is sent to the slow base. The arm, much faster,
compensates the difference so that the end effector keeps its reference
motion, except in the direction that would lower the arm's movement
capability C_m: that part of the compensation is removed in proportion to
alpha of eq. (transition), and it shows up as the end-effector deviation
of eq. (deviation).

    delta_V_b       = V_b^flt - V_b                        (after filtering)
    delta_V_a^req   = -R_ba^T J_b delta_V_b
    delta_V_a^cmp   = (I - alpha P_Cm) delta_V_a^req        eq. (wb_error)
    V_a^ref         = V_a + delta_V_a^cmp                   eq. (compensation)
    delta_V_ee      = delta_V_a^cmp - delta_V_a^req
                    = -alpha P_Cm delta_V_a^req             eq. (deviation)

Twists are [linear; angular] (m/s; rad/s); the arm's are in T_a, the
base's [vx_b, vy_b, wz_b] in T_b.
"""

import math

import numpy as np

from drake_wbc.math.kinematics import twist_rotation
from drake_wbc.math.validation import (
    as_matrix,
    as_vector,
    in_closed_range,
    non_negative,
    rotation_matrix,
)


def base_deviation(V_b_filtered, V_b):
    """Motion deviation of the base, delta_V_b = V_b^flt - V_b.

    The equation after eq. (filtering): what the base will not do of the
    distributed command V_b because it receives the filtered V_b^flt.

    Args:
        V_b_filtered: (3,) filtered base command V_b^flt = [vx_b, vy_b,
            wz_b] in T_b (m/s, m/s, rad/s).
        V_b: (3,) base command V_b from eq. (wbccm) (same frame, units).

    Returns:
        (3,) array delta_V_b.

    Raises:
        ValueError: if either argument is not 3 finite numbers.
    """
    V_b_flt = as_vector("V_b_filtered", V_b_filtered, 3)
    return V_b_flt - as_vector("V_b", V_b, 3)


def gradient_projector(grad, tolerance=1e-12):
    """Projector P_Cm onto the gradient of C_m, eq. (wb_error).

    With the gradient g = grad_x C_m (a row vector in the paper),

        P_Cm = g^T (g g^T)^-1 g,

    here for a column g: P_Cm = g g^T / (g^T g), the orthogonal projector
    onto span(g) (symmetric and idempotent), so I - P_Cm removes the part
    of a twist along g. When ||g|| <= tolerance no direction changes C_m
    to first order (e.g. at a maximum of C_m), there is nothing to remove
    and the result is the zero matrix (then delta_V_a^cmp =
    delta_V_a^req).

    Args:
        grad: (6,) gradient of C_m w.r.t. the arm's Cartesian pose
            coordinates, ordered and expressed like V_a ([linear; angular],
            T_a).
        tolerance: norm below which grad counts as zero (>= 0, same units
            as grad); P_Cm itself does not depend on the scale of g.

    Returns:
        (6, 6) array P_Cm.

    Raises:
        ValueError: if grad is not 6 finite numbers or tolerance is
            negative.
    """
    g = as_vector("grad", grad, 6)
    tolerance = non_negative("tolerance", tolerance)
    norm = np.linalg.norm(g)
    if norm <= tolerance:
        return np.zeros((6, 6))
    u = g / norm
    return np.outer(u, u)


def robust_compensation(delta_V_b, J_b, R_ba, grad_C_m, alpha):
    """Arm compensation of the base deviation, eqs. (wb_error)-(deviation).

    The arm twist that cancels the base deviation at the end effector
    follows from eq. (1) (R_ba delta_V_a + J_b delta_V_b = 0):

        delta_V_a^req = -R_ba^T J_b delta_V_b.

    Its component along grad_x C_m is removed in proportion to alpha,

        delta_V_a^cmp = (I - alpha P_Cm) delta_V_a^req,     eq. (wb_error)

    and the end-effector tracking deviation that this leaves is

        delta_V_ee = delta_V_a^cmp - delta_V_a^req
                   = -alpha P_Cm delta_V_a^req.             eq. (deviation)

    Like the paper, delta_V_ee is in the arm's frame T_a (the frame of
    the compensation); the deviation of the end-effector twist in T_b is
    R_ba delta_V_ee, the same vector when ^bR_a = I. alpha = 0 gives the
    full compensation (delta_V_ee = 0), alpha = 1 none along the gradient.

    Args:
        delta_V_b: (3,) base deviation V_b^flt - V_b in T_b (see
            base_deviation).
        J_b: (6, 3) base Jacobian of eq. (2), from
            kinematics.base_jacobian.
        R_ba: (3, 3) rotation ^bR_a from T_a to T_b, or None for the
            identity.
        grad_C_m: (6,) gradient grad_x C_m, ordered and expressed like V_a
            (see gradient_projector).
        alpha: transition value of eq. (transition), in [0, 1].

    Returns:
        (delta_V_a_cmp, delta_V_ee): two (6,) arrays in T_a; the arm's
        reference twist is V_a + delta_V_a_cmp, eq. (compensation).

    Raises:
        ValueError: on a bad argument (wrong shape, non-finite entry,
            R_ba not a rotation, alpha outside [0, 1]), naming it.
    """
    dV_b = as_vector("delta_V_b", delta_V_b, 3)
    J_b = as_matrix("J_b", J_b, (6, 3))
    R = np.eye(3) if R_ba is None else rotation_matrix("R_ba", R_ba)
    P = gradient_projector(as_vector("grad_C_m", grad_C_m, 6))
    a = in_closed_range("alpha", alpha, 0.0, 1.0)
    R6 = twist_rotation(R)
    dV_a_req = -(R6.T @ (J_b @ dV_b))
    dV_ee = -a * (P @ dV_a_req)
    dV_a_cmp = dV_a_req + dV_ee
    return dV_a_cmp, dV_ee


def compensate_unchecked(V_a, delta_V_b, p_ee_in_base, R_ab, grad_C_m,
                         alpha, tolerance=1e-12):
    """V_a^ref and delta_V_ee of eqs. (compensation) and (deviation) for
    float arguments already checked, in plain floats: the per-tick path
    of the controller's RobustCompensator.

    The same values as `robust_compensation` (to rounding), with
    J_b delta_V_b = [dv_x - y dw_z, dv_y + x dw_z, 0, 0, 0, dw_z] of eq.
    (2) and alpha P_Cm d = alpha g (g . d) / (g . g) written out; a
    gradient of norm at most `tolerance` gives P_Cm = 0, as in
    `gradient_projector`.

    Args:
        V_a: (6,) floats, the arm's distributed twist in T_a.
        delta_V_b: (3,) floats V_b^flt - V_b in T_b.
        p_ee_in_base: (3,) floats, p_ee in T_b (only x and y enter).
        R_ab: ((3,), (3,), (3,)) rows of ^bR_a^T, i.e. ^aR_b, as floats.
        grad_C_m: (6,) floats, grad_x C_m in T_a.
        alpha: float s_c alpha in [0, 1].
        tolerance: float >= 0.

    Returns:
        list of 12 floats: [V_a^ref (6); delta_V_ee (6)], both in T_a.
    """
    dvx, dvy, dwz = delta_V_b
    x, y = p_ee_in_base[0], p_ee_in_base[1]
    # J_b delta_V_b (eq. (2)), then delta_V_a^req = -R_ba^T J_b delta_V_b.
    tx = dvx - y * dwz
    ty = dvy + x * dwz
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R_ab
    required = [-(r00 * tx + r01 * ty), -(r10 * tx + r11 * ty),
                -(r20 * tx + r21 * ty), -(r02 * dwz), -(r12 * dwz),
                -(r22 * dwz)]
    g0, g1, g2, g3, g4, g5 = grad_C_m
    g_squared = g0 * g0 + g1 * g1 + g2 * g2 + g3 * g3 + g4 * g4 + g5 * g5
    if math.sqrt(g_squared) <= tolerance:
        return [v + d for v, d in zip(V_a, required, strict=True)] + [
            0.0] * 6
    q0, q1, q2, q3, q4, q5 = required
    factor = -alpha * (g0 * q0 + g1 * q1 + g2 * q2 + g3 * q3 + g4 * q4
                       + g5 * q5) / g_squared
    deviation = [factor * g0, factor * g1, factor * g2, factor * g3,
                 factor * g4, factor * g5]
    return [v + (d + e) for v, d, e in zip(V_a, required, deviation,
                                           strict=True)] + deviation

"""Weighted whole-body motion distribution for the usual mounting, in plain
floats: the controller's per-tick path (paper Sec. III-B and IV-A).

For J_wb = [I, J_b] (^bR_a = I, eq. (1) bottom line) the weighted solution
of eqs. (wbsln)/(wbccm), V_wb = J^+ V_ee + (I - J^+ J) V_n^0, has a closed
form around a 3x3 Cholesky solve, which `distribute_aligned` evaluates in
plain floats. It gives the values of drake_wbc.math.distribution's
`distribute_unchecked` (to rounding), with the same damping rule, and
hands every case that rule might damp, or any value that is not finite,
to that general path.
"""

import math

import numpy as np

from drake_wbc.math.distribution import distribute_unchecked
from drake_wbc.math.kinematics import whole_body_jacobian_unchecked
from drake_wbc.math.pseudoinverse import DEFAULT_DAMPING, weights_of

_IDENTITY = np.eye(3)
"""^bR_a of the usual mounting (see distribute_aligned)."""


def distribute_aligned(V_ee, p_ee_in_base, sigma_xy, sigma_phi,
                       null_velocity_arm=None, damping=DEFAULT_DAMPING):
    """`distribute_unchecked` for J_wb = [I, J_b] (^bR_a = I, the usual
    mounting), in plain floats: the controller's per-tick path.

    With R_ba = I, M = J Q J^T is the identity on the rows (vz, wx, wy)
    and on (vx, vy, wz) the 3x3 block

        A = diag(s + (1 - s), s + (1 - s), p) + (1 - p) c c^T,
        c = [-y, x, 1],

    (s = sigma_xy, p = sigma_phi, det A = 1 + p (1 - p) r^2 >= 1, see
    drake_wbc.math.pseudoinverse), so that x = M^-1 (V_ee - J V_n^0) is a 3x3
    Cholesky solve and V_wb = Q J^T x + V_n^0 of eq. (wbccm) has the
    closed form

        V_a = w_a x + V_n^0,   V_b = [(1 - s) x_vx, (1 - s) x_vy,
                                      (1 - p)(x_wz - y x_vx + x x_vy)].

    The same values as `distribute_unchecked` to rounding. The damping
    certificate of `pseudoinverse.certified_solve` is taken from this
    factorisation (det M / (tr M / 5)^6 >= 5 threshold); when it does not
    prove lambda = 0, or a value is not finite, the general path runs
    instead.

    Args:
        V_ee: (6,) floats (a sequence or an array), the twist in T_b.
        p_ee_in_base: (3,) floats, p_ee in T_b (only x and y enter).
        sigma_xy, sigma_phi: floats already checked to lie in [0, 1].
        null_velocity_arm: (6,) floats k_n grad_x C_m, the arm part of
            V_n^0 (its base part is zero), or None.
        damping: a SingularityDamping or None, as checked by the caller.

    Returns:
        (9,) array V_wb = [V_a (6, T_a); V_b (3, T_b)].
    """
    x, y = float(p_ee_in_base[0]), float(p_ee_in_base[1])
    s, p = float(sigma_xy), float(sigma_phi)
    v0, v1, v2, v3, v4, v5 = (V_ee.tolist() if type(V_ee) is np.ndarray
                              else map(float, V_ee))
    if null_velocity_arm is not None:
        n0, n1, n2, n3, n4, n5 = (
            null_velocity_arm.tolist()
            if type(null_velocity_arm) is np.ndarray
            else map(float, null_velocity_arm))
        # V_ee - J_wb V_n^0 with J_wb V_n^0 = the arm part of V_n^0.
        v0, v1, v2, v3, v4, v5 = (v0 - n0, v1 - n1, v2 - n2, v3 - n3,
                                  v4 - n4, v5 - n5)
    a, b = 1.0 - s, 1.0 - p
    u = s + a
    ay = -b * y
    ax = b * x
    # The block A on (vx, vy, wz), and its Cholesky factor L.
    a00, a10, a11 = u + ay * -y, ay * x, u + ax * x
    a20, a21, a22 = ay, ax, p + b
    l00 = math.sqrt(a00) if a00 > 0.0 else math.nan
    l10, l20 = a10 / l00, a20 / l00
    d11 = a11 - l10 * l10
    l11 = math.sqrt(d11) if d11 > 0.0 else math.nan
    l21 = (a21 - l20 * l10) / l11
    d22 = a22 - l20 * l20 - l21 * l21
    l22 = math.sqrt(d22) if d22 > 0.0 else math.nan
    if damping is not None:
        # pseudoinverse.certified_solve's product of 5 L_ii^2 / tr M over
        # the six pivots, three of them 1.
        ratio = 5.0 / (3.0 + a00 + a11 + a22)
        certificate = ((l00 * l00 * ratio) * (l11 * l11 * ratio)
                       * (l22 * l22 * ratio) * ratio * ratio * ratio)
        proved = certificate >= 5.0 * damping.threshold
    else:
        proved = l22 == l22  # not NaN: A is positive definite
    if not (proved and math.isfinite(x + y + v0 + v1 + v2 + v3 + v4
                                      + v5)):
        J = whole_body_jacobian_unchecked(None, np.array([x, y, 0.0]),
                                          _IDENTITY)
        V_n = None
        if null_velocity_arm is not None:
            V_n = np.zeros(9)
            V_n[:6] = null_velocity_arm
        return distribute_unchecked(J, np.array(V_ee, dtype=float),
                                    weights_of(s, p), V_n, damping)
    z0 = v0 / l00
    z1 = (v1 - l10 * z0) / l11
    z5 = (v5 - l20 * z0 - l21 * z1) / l22
    x5 = z5 / l22
    x1 = (z1 - l21 * x5) / l11
    x0 = (z0 - l10 * x1 - l20 * x5) / l00
    V_wb = [s * x0, s * x1, v2, v3, v4, p * x5,
            a * x0, a * x1, b * (x5 - y * x0 + x * x1)]
    if null_velocity_arm is not None:
        V_wb[0] += n0
        V_wb[1] += n1
        V_wb[2] += n2
        V_wb[3] += n3
        V_wb[4] += n4
        V_wb[5] += n5
    return np.array(V_wb)

"""The coordination math of Sec. IV-A for any scalar type: the weighted
distribution of eqs. (wbsln)/(wbccm) and the robust compensation of eqs.
(wb_error) and (deviation), for AutoDiffXd arguments (floats also work).

The same formulas as drake_wbc.math.distribution.distribute,
drake_wbc.math.compensation.robust_compensation and
drake_wbc.math.kinematics.base_jacobian (eq. (2)), written elementwise so that
AutoDiffXd passes through, with scalar_support.solve for the linear solve,
so that their derivatives are exact. The AutoDiffXd forms of the Drake
systems MotionDistributor and RobustCompensator
(drake_wbc.stages.coordination) run them.
"""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd

from drake_wbc.math import kinematics, pseudoinverse
from drake_wbc.math.scalar_support import solve, value_of

PROJECTOR_TOLERANCE = 1e-12
"""Norm of grad_x C_m below which P_Cm = 0, as in
compensation.gradient_projector (its default)."""


def _autodiff(array):
    """`array` with every entry an AutoDiffXd (floats get no derivatives)."""
    array = np.asarray(array, dtype=object)
    flat = [e if isinstance(e, AutoDiffXd) else AutoDiffXd(float(e))
            for e in array.ravel()]
    return np.array(flat, dtype=object).reshape(array.shape)


def _unit_interval(name, value):
    """Checks 0 <= value <= 1 for a float or AutoDiffXd scalar."""
    if not 0.0 <= value <= 1.0:
        raise ValueError(
            f"{name} = {float(value_of(value))!r} is not allowed: must lie "
            "in [0, 1]"
        )
    return value


def base_jacobian_any(p_ee_in_base):
    """J_b of eq. (2) (kinematics.base_jacobian) for any scalar type."""
    p = np.asarray(p_ee_in_base)
    zero = p[0] * 0.0
    one = zero + 1.0
    return np.array([[one, zero, -p[1]], [zero, one, p[0]], [zero] * 3,
                     [zero] * 3, [zero] * 3, [zero, zero, one]])


def distribute_any(J_wb, V_ee, sigma_xy, sigma_phi, null_velocity,
                   damping=pseudoinverse.DEFAULT_DAMPING):
    """distribution.distribute for AutoDiffXd arguments (floats also work).

        V_wb = J^+ (V_ee - J V_n^0) + V_n^0,  J^+ = Q J^T (J Q J^T)^-1,

    the same as J^+ V_ee + (I - J^+ J) V_n^0, with the same damping of
    J Q J^T near singularity; there the eigenvalues s_min, s_max are taken
    as v^T (J Q J^T) v with the eigenvectors v of its value, which gives
    them (and lambda^2) their exact first derivatives for simple
    eigenvalues.
    """
    _unit_interval("sigma_xy", sigma_xy)
    _unit_interval("sigma_phi", sigma_phi)
    J = _autodiff(J_wb)
    weights = np.array([sigma_xy, sigma_xy, 1.0, 1.0, 1.0, sigma_phi,
                        1.0 - sigma_xy, 1.0 - sigma_xy, 1.0 - sigma_phi],
                       dtype=object)
    JQ = J * weights[np.newaxis, :]
    M = JQ @ J.T
    M = _autodiff(0.5 * (M + M.T))
    V_n = _autodiff(null_velocity)
    eigenvalues, vectors = np.linalg.eigh(value_of(M))
    if eigenvalues[-1] <= 0.0:
        return V_n  # J^+ = 0: no weighted input moves the end effector
    if damping is not None:
        eps = damping.threshold * eigenvalues[-1]
        if max(eigenvalues[0], 0.0) < eps:
            s_max = vectors[:, -1] @ M @ vectors[:, -1]
            s_min = (vectors[:, 0] @ M @ vectors[:, 0]
                     if eigenvalues[0] > 0.0 else s_max * 0.0)
            ratio = s_min / (damping.threshold * s_max)
            lambda_sq = damping.max_squared * s_max * (1.0 - ratio * ratio)
            M = M + lambda_sq * np.eye(6)
    try:
        x = solve(M, _autodiff(V_ee) - J @ V_n)
    except np.linalg.LinAlgError:
        raise ValueError(
            "J_wb with singular J_wb Q J_wb^T is not allowed with "
            "damping=None: pass a SingularityDamping"
        ) from None
    return JQ.T @ x + V_n


def compensate_any(delta_V_b, p_ee_in_base, R_ba, grad_C_m, alpha):
    """compensation.robust_compensation for AutoDiffXd arguments:
    (delta_V_a^cmp, delta_V_ee), eqs. (wb_error) and (deviation), with
    P_Cm = g g^T / (g^T g) written as g (g . x) / (g . g)."""
    _unit_interval("alpha", alpha)
    R6 = kinematics.twist_rotation(R_ba)
    required = -(R6.T @ (base_jacobian_any(p_ee_in_base) @ delta_V_b))
    g = np.asarray(grad_C_m)
    g_squared = np.dot(g, g)
    if g_squared > PROJECTOR_TOLERANCE**2:
        deviation = -alpha * g * (np.dot(g, required) / g_squared)
    else:
        deviation = required * 0.0
    return required + deviation, deviation

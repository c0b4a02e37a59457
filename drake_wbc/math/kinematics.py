"""Velocity kinematics of the mobile collaborative robot (paper Sec. III-A).

The robot is an omnidirectional base carrying a 6-DoF arm. Frames:
T_w (world), T_b (mobile base), T_a (arm base, fixed on the mobile base)
and T_ee (end effector). Inputs:

- V_b = [vx_b, vy_b, wz_b] (m/s, m/s, rad/s): base velocity command,
  expressed in T_b.
- V_a = [v_a; w_a] (m/s; rad/s): Cartesian twist command of the arm,
  linear part first, expressed in T_a.
- V_wb = [V_a; V_b] (9,): the whole-body input, arm first, eq. (1).

Every twist here is [linear; angular]; the linear part is the velocity of
the end-effector point. V_ee is the end effector's velocity relative to
the world, with its components expressed in T_b, eq. (1) and eq. (3).
"""

import numpy as np

from drake_wbc.math.validation import (
    as_float_array,
    as_scalar,
    as_vector,
)
from drake_wbc.math.validation import rotation_matrix as checked_rotation


class _RotationCheck:
    """validation.rotation_matrix, remembering the last value it passed:
    the same matrix (bytes equal) is not checked again, so that a constant
    R_ba costs one comparison per call."""

    def __init__(self):
        self._last = None

    def __call__(self, name, value):
        if (type(value) is np.ndarray and value.dtype == np.float64
                and value.shape == (3, 3)
                and value.tobytes() == self._last):
            return value
        R = checked_rotation(name, value)
        self._last = R.tobytes()
        return R


_checked_rotation_cached = _RotationCheck()


def base_jacobian(p_ee_in_base):
    """Jacobian J_b of the base input, eq. (2).

    Maps the base command V_b = [vx_b, vy_b, wz_b] (T_b) to the
    end-effector twist it causes, [v; w] in T_b, by the rigid-body rule
    v_ee = v_b + w_b x p_ee with w_b = [0, 0, wz_b]:

        J_b = [[1, 0, -y],
               [0, 1,  x],
               [0, 0,  0],
               [0, 0,  0],
               [0, 0,  0],
               [0, 0,  1]]

    Args:
        p_ee_in_base: (3,) end-effector position ^b p_ee = [x, y, z] in T_b,
            in m. The height z does not enter J_b.

    Returns:
        (6, 3) array J_b; rows [vx, vy, vz, wx, wy, wz], columns
        [vx_b, vy_b, wz_b].

    Raises:
        ValueError: if p_ee_in_base is not 3 finite numbers.
    """
    p = as_float_array("p_ee_in_base", p_ee_in_base, (3,))
    J_b = np.zeros((6, 3))
    J_b[0, 0] = 1.0
    J_b[1, 1] = 1.0
    J_b[0, 2] = -p[1]
    J_b[1, 2] = p[0]
    J_b[5, 2] = 1.0
    return J_b


def twist_rotation(R):
    """The 6x6 twist rotation block-diag(R, R), e.g. R_ba of eq. (1).

    Rotates a twist [v; w] from one frame to another: with R = ^bR_a it
    is the paper's R_ba, which maps a twist expressed in T_a to T_b.

    Args:
        R: (3, 3) rotation matrix (checked: R^T R = I, det R = 1).

    Returns:
        (6, 6) array block-diag(R, R).

    Raises:
        ValueError: if R is not a finite 3x3 rotation matrix.
    """
    R = checked_rotation("R", R)
    R6 = np.zeros((6, 6))
    R6[:3, :3] = R
    R6[3:, 3:] = R
    return R6


def whole_body_jacobian(J_a, p_ee_in_base, R_ba=None):
    """Whole-body Jacobian [R_ba J_a, J_b] of eq. (1).

    Eq. (1) has two lines; this function gives both:

    - Bottom line, the controller's case (J_a = None): the arm input is its
      Cartesian twist V_a in T_a and

          V_ee = [R_ba, J_b] [V_a; V_b] = J_wb V_wb,

      so J_wb = [R_ba, J_b] (6, 9) is the matrix that the weighted
      distribution of eq. (wbsln) works with. J_a = None means exactly
      J_a = I (6x6).
    - Top line (J_a given): J_a is the arm's geometric Jacobian w.r.t. T_a
      (6x6, rows [v; w], linear velocity of the end-effector point) and
      the arm columns map joint rates dq_a (rad/s):

          V_ee = R_ba J_a dq_a + J_b V_b.

      The base columns here take the body-frame command V_b; the paper
      writes J_b ^bR_w dq_b with the world-frame rates dq_b = [dx_b, dy_b,
      dphi_b], which is the same since V_b = ^bR_w dq_b.

    Args:
        J_a: (6, 6) geometric Jacobian of the arm in T_a, or None for the
            identity (arm input = Cartesian twist V_a).
        p_ee_in_base: (3,) end-effector position in T_b, in m (for J_b).
        R_ba: (3, 3) rotation ^bR_a from T_a to T_b, or None for the
            identity (the usual mounting, as the paper notes).

    Returns:
        (6, 9) array; columns [arm input (6), V_b (3)], rows [v; w] of the
        end effector in T_b.

    Raises:
        ValueError: if J_a is not a finite 6x6 matrix, p_ee_in_base not 3
            finite numbers, or R_ba not a rotation matrix.
    """
    R = (np.eye(3) if R_ba is None
         else _checked_rotation_cached("R_ba", R_ba))
    if J_a is not None:
        J_a = as_float_array("J_a", J_a, (6, 6))
    p = as_float_array("p_ee_in_base", p_ee_in_base, (3,))
    return whole_body_jacobian_unchecked(J_a, p, R)


def whole_body_jacobian_unchecked(J_a, p_ee_in_base, R_ba):
    """whole_body_jacobian for float arguments already checked: J_a (6, 6)
    or None, p_ee_in_base (3,) and the rotation matrix R_ba (3, 3), which
    is not optional here. The per-tick path of the controller."""
    J_wb = np.zeros((6, 9))
    if J_a is None:
        J_wb[:3, :3] = R_ba
        J_wb[3:, 3:6] = R_ba
    else:
        J_wb[:3, :6] = R_ba @ J_a[:3]
        J_wb[3:, :6] = R_ba @ J_a[3:]
    # J_b of eq. (2) (base_jacobian).
    J_wb[0, 6] = 1.0
    J_wb[1, 7] = 1.0
    J_wb[0, 8] = -p_ee_in_base[1]
    J_wb[1, 8] = p_ee_in_base[0]
    J_wb[5, 8] = 1.0
    return J_wb


def world_to_base_twist(V_ee_ref_world, base_yaw):
    """End-effector reference twist from T_w to T_b, eq. (3).

    Eq. (3) is the unlabeled equation right after eq. (2):

        V_ee = block-diag(^bR_w, ^bR_w) V_ee^ref,  ^bR_w = Rz(-phi_b).

    Only the orientation changes; the twist is still the end effector's
    motion relative to the world.

    Args:
        V_ee_ref_world: (6,) reference twist V_ee^ref = [v; w] of the end
            effector, components in T_w (m/s; rad/s).
        base_yaw: yaw angle phi_b of the base w.r.t. T_w, in rad.

    Returns:
        (6,) array V_ee, the same twist with components in T_b.

    Raises:
        ValueError: if V_ee_ref_world is not 6 finite numbers or base_yaw
            is not finite.
    """
    V_ref = as_vector("V_ee_ref_world", V_ee_ref_world, 6)
    phi_b = as_scalar("base_yaw", base_yaw)
    c, s = np.cos(phi_b), np.sin(phi_b)
    # ^bR_w = Rz(-phi_b) = [[c, s, 0], [-s, c, 0], [0, 0, 1]].
    R_bw = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    V_ee = np.empty(6)
    V_ee[:3] = R_bw @ V_ref[:3]
    V_ee[3:] = R_bw @ V_ref[3:]
    return V_ee

"""Velocity kinematics of the mobile collaborative robot (paper Sec. III-A).

The robot is an omnidirectional base carrying a 6-DoF arm. Frames:
T_w (world), T_b (mobile base), T_a (arm base, fixed on the mobile base)
and T_ee (end effector). Inputs:

- V_b = [vx_b, vy_b, wz_b] (m/s, m/s, rad/s): base velocity command,
  expressed in T_b.
- V_a = [v_a; w_a] (m/s; rad/s): Cartesian twist command of the arm,
  linear part first, expressed in T_a.
- V_wb = [V_a; V_b] (9,): the whole-body input, arm first, eq. (fk).

Every twist here is [linear; angular]; the linear part is the velocity of
the end-effector point. V_ee is the end effector's velocity relative to
the world, with its components expressed in T_b, eqs. (fk) and (3).

Each equation has one reference body, scalar-generic (float arrays and
numpy object arrays of AutoDiffXd), which checks nothing: what the stages
and the other reference bodies call. The public functions a user calls
by hand check their arguments and call it:

- J_b of eq. (2): `base_jacobian_of`, checked `base_jacobian`;
- J_wb of eq. (fk): `whole_body_jacobian_of`, checked
  `whole_body_jacobian`;
- block-diag(R, R) of eqs. (fk) and (3): `rotate_twist`, checked
  `twist_rotation` (the matrix);
- ^bR_w V_ee^ref of eq. (3), ^bR_w = Rz(-phi_b): `twist_in_base`, checked
  `world_to_base_twist`; its inverse Rz(phi_b), from T_b to the world:
  `twist_in_world`.

The two rotations of eq. (3) have a fast float kernel each (the
whole-body CDMP's tick, drake_wbc.stages.whole_body_cdmp); the others
have none: the tick runs them inside the kernels of the distribution and
of the compensation.
"""

import math

import numpy as np

from drake_wbc.math.kernels import fast_kernel
from drake_wbc.math.validation import (
    as_matrix,
    as_scalar,
    as_vector,
    rotation_matrix,
)

_IDENTITY_6 = np.eye(6)


def base_jacobian_of(p_ee_in_base):
    """J_b of eq. (2) at p_ee = [x, y, z] in T_b, for any scalar type
    (the reference body of `base_jacobian`, which documents it); a (6, 3)
    array of the scalar type of p_ee_in_base."""
    p = np.asarray(p_ee_in_base)
    zero = p[0] * 0.0
    one = zero + 1.0
    return np.array([[one, zero, -p[1]], [zero, one, p[0]], [zero] * 3,
                     [zero] * 3, [zero] * 3, [zero, zero, one]])


def rotate_twist(R, twist):
    """block-diag(R, R) twist: both halves of the twist [v; w] (6,), or of
    each column of a (6, k) array, rotated by R (3, 3), for any scalar
    type. With R = ^bR_a it maps a twist from T_a to T_b (R_ba of eq.
    (fk)), with R = ^bR_w from T_w to T_b (eq. (3))."""
    R, twist = np.asarray(R), np.asarray(twist)
    return np.concatenate([R @ twist[:3], R @ twist[3:]])


def whole_body_jacobian_of(J_a, p_ee_in_base, R_ba):
    """J_wb = [R_ba J_a, J_b] of eq. (fk) for any scalar type (the
    reference body of `whole_body_jacobian`, which documents it); J_a None
    is the identity (the arm input is its Cartesian twist V_a), R_ba a
    rotation matrix (3, 3). A (6, 9) array."""
    arm = rotate_twist(R_ba, _IDENTITY_6 if J_a is None else J_a)
    return np.hstack([arm, base_jacobian_of(p_ee_in_base)])


def twist_in_world(twist, yaw):
    """Rz(yaw) [v; w]: a twist (6,) with components in T_b, in the world,
    for the base's yaw phi_b (the inverse of eq. (3)); float or
    AutoDiffXd. A yaw that is not finite has no heading: the x and y
    components are NaN."""
    c, s = np.cos(yaw), np.sin(yaw)
    vx, vy, vz, wx, wy, wz = twist
    return np.array([c * vx - s * vy, s * vx + c * vy, vz,
                     c * wx - s * wy, s * wx + c * wy, wz])


def twist_in_base(twist, yaw):
    """Rz(-yaw) [v; w] of eq. (3): a twist (6,) with components in the
    world, in T_b; float or AutoDiffXd. A yaw that is not finite has no
    heading: the x and y components are NaN."""
    c, s = np.cos(yaw), np.sin(yaw)
    vx, vy, vz, wx, wy, wz = twist
    return np.array([c * vx + s * vy, c * vy - s * vx, vz,
                     c * wx + s * wy, c * wy - s * wx, wz])


def _twist_inputs(rng):
    """A twist (zero, or of any size) and a yaw (0, a right angle, any
    turn); in one case in ten the yaw, or an entry of the twist, NaN or
    infinite."""
    twist = 10.0 ** rng.uniform(-3, 3) * rng.normal(size=6)
    if rng.random() < 0.1:
        twist = np.zeros(6)
    yaw = float(rng.choice([0.0, np.pi / 2, -np.pi, rng.uniform(-20, 20)]))
    if rng.random() < 0.1:
        value = float(rng.choice([np.nan, np.inf, -np.inf]))
        if rng.random() < 0.5:
            yaw = value
        else:
            twist[rng.integers(6)] = value
    return twist, yaw


@fast_kernel(twist_in_world, sample=_twist_inputs)
def twist_in_world_float(twist, yaw):
    """`twist_in_world` of a float array, in plain floats (math.cos), a
    list."""
    try:
        c, s = math.cos(yaw), math.sin(yaw)
    except ValueError:  # an infinite yaw: NaN, as np.cos gives
        c = s = math.nan
    vx, vy, vz, wx, wy, wz = twist.tolist()
    return [c * vx - s * vy, s * vx + c * vy, vz,
            c * wx - s * wy, s * wx + c * wy, wz]


@fast_kernel(twist_in_base, sample=_twist_inputs)
def twist_in_base_float(twist, yaw):
    """`twist_in_base` of a float array, in plain floats (math.cos), a
    list."""
    try:
        c, s = math.cos(yaw), math.sin(yaw)
    except ValueError:  # an infinite yaw: NaN, as np.cos gives
        c = s = math.nan
    vx, vy, vz, wx, wy, wz = twist.tolist()
    return [c * vx + s * vy, c * vy - s * vx, vz,
            c * wx + s * wy, c * wy - s * wx, wz]


def random_rotation(rng):
    """A random rotation matrix (3, 3) from the numpy Generator `rng`
    (random mountings ^bR_a for the kernels' samplers)."""
    R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return R * np.sign(np.linalg.det(R))


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
    return base_jacobian_of(as_vector("p_ee_in_base", p_ee_in_base, 3))


def twist_rotation(R):
    """The 6x6 twist rotation block-diag(R, R), e.g. R_ba of eq. (fk).

    Rotates a twist [v; w] from one frame to another: with R = ^bR_a it
    is the paper's R_ba, which maps a twist expressed in T_a to T_b.

    Args:
        R: (3, 3) rotation matrix (checked: R^T R = I, det R = 1).

    Returns:
        (6, 6) array block-diag(R, R).

    Raises:
        ValueError: if R is not a finite 3x3 rotation matrix.
    """
    return rotate_twist(rotation_matrix("R", R), _IDENTITY_6)


def whole_body_jacobian(J_a, p_ee_in_base, R_ba=None):
    """Whole-body Jacobian [R_ba J_a, J_b] of eq. (fk).

    Eq. (fk) has two lines; this function gives both:

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
    R = np.eye(3) if R_ba is None else rotation_matrix("R_ba", R_ba)
    if J_a is not None:
        J_a = as_matrix("J_a", J_a, (6, 6))
    p = as_vector("p_ee_in_base", p_ee_in_base, 3)
    return whole_body_jacobian_of(J_a, p, R)


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
    return twist_in_base(
        as_vector("V_ee_ref_world", V_ee_ref_world, 6),
        as_scalar("base_yaw", base_yaw))

"""The forward kinematics and geometric Jacobian of a serial chain (paper,
eq. (fk): J_a, and the end effector's pose in T_a).

A serial chain of n one-dof joints from a frame A (the arm's base T_a) to
a frame E (the end effector) is data (`SerialChain`): each joint's fixed
pose in the previous joint's moving frame, its axis and its kind. With
F_i the frame of joint i on its parent and M_i the one on its child,

    X_AE(q) = X_A,F1 J_1(q_1) X_M1,F2 J_2(q_2) ... J_n(q_n) X_Mn,E,

J_i(q_i) a rotation by q_i about the unit axis a_i (revolute) or a
translation by q_i along it (prismatic), a_i the same in F_i and M_i.
The geometric Jacobian of E's origin in A, expressed in A, rows [v; w]
(the paper's order), has for joint i, with w_i = R_AF_i a_i and o_i the
origin of F_i in A:

    revolute:   [w_i x (p_AE - o_i); w_i],
    prismatic:  [w_i; 0].

The chain is read once from a MultibodyPlant by
drake_wbc.robot.model.ArmKinematics (any described robot; the plant's
own kinematics is what tests/test_robot_model.py holds the kernel equal
to); here it is plain arrays, so that the kinematics of the tick runs in
machine code:

- `chain_kinematics_of`: the reference body, scalar-generic (float, or
  numpy object arrays of AutoDiffXd for q);
- `chain_kinematics_float`: its compiled kernel (drake_wbc.math.compiled),
  registered with drake_wbc.math.kernels.fast_kernel;
- `origin_in`: E's origin in a frame B in which A is fixed, from X_AE,
  compiled (B is the base's T_b for the nominal kinematics).
"""

import math
from typing import NamedTuple

import numpy as np

from drake_wbc.math.compiled import compiled
from drake_wbc.math.kernels import fast_kernel
from drake_wbc.math.scalar_support import value_of

REVOLUTE, PRISMATIC = 1.0, 0.0
"""The kinds of `SerialChain.revolute` (floats: the compiled kernel takes
float64 arrays only)."""


class SerialChain(NamedTuple):
    """A serial chain of n one-dof joints (see the module), as float64
    C-contiguous arrays.

    Attributes:
        fixed: (n + 1, 4, 4) homogeneous transforms: X_A,F1, then
            X_Mi,F(i+1) for i = 1..n-1, then X_Mn,E.
        axes: (n, 3) each joint's unit axis, in F_i (= in M_i).
        revolute: (n,) REVOLUTE (1.0) or PRISMATIC (0.0) per joint.
    """

    fixed: np.ndarray
    axes: np.ndarray
    revolute: np.ndarray

    @property
    def num_joints(self):
        """n."""
        return self.axes.shape[0]


def _joint_transform(axis, revolute, q_i):
    """J_i(q_i) (4, 4): the rotation by q_i about the unit `axis`
    (Rodrigues' formula) or the translation by q_i along it; any scalar
    type for q_i."""
    zero = q_i * 0.0
    one = zero + 1.0
    X = np.array([[one, zero, zero, zero], [zero, one, zero, zero],
                  [zero, zero, one, zero], [zero, zero, zero, one]])
    if revolute == REVOLUTE:
        c, s = np.cos(q_i), np.sin(q_i)
        K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                      [-axis[1], axis[0], 0.0]])
        X[:3, :3] = X[:3, :3] + s * K + (1.0 - c) * (K @ K)
    else:
        X[:3, 3] = q_i * np.asarray(axis)
    return X


def chain_kinematics_of(fixed, axes, revolute, q):
    """J_a and X_AE of a serial chain at q (see the module), for any
    scalar type of q (the reference body of `chain_kinematics_float`).

    Args:
        fixed, axes, revolute: a SerialChain's arrays.
        q: (n,) joint positions (rad for revolute, m for prismatic).

    Returns:
        (J, X_AE): J (6, n) the geometric Jacobian [v; w] of E's origin in
        A, X_AE (4, 4) the pose of E in A; both all NaN if an entry of q
        or of the chain is not finite (E is nowhere known).
    """
    n = len(axes)
    X = np.asarray(fixed[0])
    origins, directions = [], []
    for i in range(n):
        origins.append(X[:3, 3])
        directions.append(X[:3, :3] @ np.asarray(axes[i]))
        X = X @ _joint_transform(axes[i], revolute[i], q[i]) @ fixed[i + 1]
    p = X[:3, 3]
    columns = []
    for i in range(n):
        w = directions[i]
        if revolute[i] == REVOLUTE:
            columns.append(np.concatenate([np.cross(w, p - origins[i]), w]))
        else:
            columns.append(np.concatenate([w, w * 0.0]))
    J = np.array(columns).T
    if not all(np.isfinite(value_of(a)).all()
               for a in (fixed, axes, revolute, q)):
        return J * math.nan, X * math.nan
    return J, X


@compiled
def _chain_kinematics(fixed, axes, revolute, q):
    """The compiled loop of `chain_kinematics_float`: the product of the
    transforms in 3x3 and 3-vector arithmetic, the Jacobian's columns
    beside it; both all NaN if an entry of q or of the chain is not
    finite, as the reference."""
    n = axes.shape[0]
    R = np.empty((3, 3))
    p = np.empty(3)
    for r in range(3):
        p[r] = fixed[0, r, 3]
        for c in range(3):
            R[r, c] = fixed[0, r, c]
    origins = np.empty((n, 3))
    directions = np.empty((n, 3))
    M = np.empty((3, 3))
    S = np.empty((3, 3))
    for i in range(n):
        ax, ay, az = axes[i, 0], axes[i, 1], axes[i, 2]
        for r in range(3):
            origins[i, r] = p[r]
            directions[i, r] = R[r, 0] * ax + R[r, 1] * ay + R[r, 2] * az
        # M = R J_i (rotation), p += R a q (translation).
        if revolute[i] == 1.0:
            c, s = math.cos(q[i]), math.sin(q[i])
            t = 1.0 - c
            # I + s K + (1 - c) K^2, as the reference sums it.
            KK00, KK11, KK22 = -(ay * ay + az * az), -(ax * ax + az * az), \
                -(ax * ax + ay * ay)
            KK01, KK02, KK12 = ax * ay, ax * az, ay * az
            J00 = (1.0 + s * 0.0) + t * KK00
            J01 = (0.0 + s * -az) + t * KK01
            J02 = (0.0 + s * ay) + t * KK02
            J10 = (0.0 + s * az) + t * KK01
            J11 = (1.0 + s * 0.0) + t * KK11
            J12 = (0.0 + s * -ax) + t * KK12
            J20 = (0.0 + s * -ay) + t * KK02
            J21 = (0.0 + s * ax) + t * KK12
            J22 = (1.0 + s * 0.0) + t * KK22
            for r in range(3):
                M[r, 0] = R[r, 0] * J00 + R[r, 1] * J10 + R[r, 2] * J20
                M[r, 1] = R[r, 0] * J01 + R[r, 1] * J11 + R[r, 2] * J21
                M[r, 2] = R[r, 0] * J02 + R[r, 1] * J12 + R[r, 2] * J22
        else:
            tx, ty, tz = q[i] * ax, q[i] * ay, q[i] * az
            for r in range(3):
                p[r] = p[r] + (R[r, 0] * tx + R[r, 1] * ty + R[r, 2] * tz)
                for c in range(3):
                    M[r, c] = R[r, c]
        # Then the fixed transform to the next joint's frame (or to E).
        F = fixed[i + 1]
        for r in range(3):
            p[r] = (M[r, 0] * F[0, 3] + M[r, 1] * F[1, 3]
                    + M[r, 2] * F[2, 3]) + p[r]
            for c in range(3):
                S[r, c] = (M[r, 0] * F[0, c] + M[r, 1] * F[1, c]
                           + M[r, 2] * F[2, c])
        for r in range(3):
            for c in range(3):
                R[r, c] = S[r, c]
    J = np.empty((6, n))
    for i in range(n):
        wx, wy, wz = directions[i, 0], directions[i, 1], directions[i, 2]
        if revolute[i] == 1.0:
            dx, dy, dz = (p[0] - origins[i, 0], p[1] - origins[i, 1],
                          p[2] - origins[i, 2])
            J[0, i] = wy * dz - wz * dy
            J[1, i] = wz * dx - wx * dz
            J[2, i] = wx * dy - wy * dx
            J[3, i], J[4, i], J[5, i] = wx, wy, wz
        else:
            J[0, i], J[1, i], J[2, i] = wx, wy, wz
            J[3, i] = J[4, i] = J[5, i] = 0.0
    X = np.zeros((4, 4))
    for r in range(3):
        X[r, 3] = p[r]
        for c in range(3):
            X[r, c] = R[r, c]
    X[3, 3] = 1.0
    finite = True
    for i in range(n):
        finite = finite and math.isfinite(q[i]) and math.isfinite(
            revolute[i])
        for c in range(3):
            finite = finite and math.isfinite(axes[i, c])
    for i in range(n + 1):
        for r in range(4):
            for c in range(4):
                finite = finite and math.isfinite(fixed[i, r, c])
    if not finite:
        J[:, :] = math.nan
        X[:, :] = math.nan
    return J, X


def _random_pose(rng):
    """A random homogeneous transform (4, 4): a rotation from a QR and an
    offset of up to half a metre."""
    R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    X = np.eye(4)
    X[:3, :3] = R * np.sign(np.linalg.det(R))
    X[:3, 3] = rng.uniform(-0.5, 0.5, 3)
    return X


def _chain_sample(rng):
    """A random chain of 1 to 9 joints (revolute, and prismatic one time
    in four per joint), axes random or along a frame axis, at random q
    (any turn for the revolute joints); in one case in ten an entry of q,
    or one time in four of those of a fixed transform or an axis, NaN or
    infinite."""
    n = int(rng.integers(1, 10))
    fixed = np.array([_random_pose(rng) for _ in range(n + 1)])
    axes = rng.normal(size=(n, 3))
    along = rng.uniform(size=n) < 0.4
    axes[along] = np.eye(3)[rng.integers(3, size=int(along.sum()))]
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    revolute = np.where(rng.uniform(size=n) < 0.75, REVOLUTE, PRISMATIC)
    q = np.where(revolute == REVOLUTE, rng.uniform(-7.0, 7.0, n),
                 rng.uniform(-0.5, 0.5, n))
    if rng.random() < 0.1:
        spoilt = (q if rng.random() < 0.75
                  else fixed if rng.random() < 0.5 else axes)
        spoilt[np.unravel_index(rng.integers(spoilt.size),
                                spoilt.shape)] = rng.choice(
            [np.nan, np.inf, -np.inf])
    return fixed, axes, revolute, q


@compiled
def origin_in(R_BA, p_BA, X_AE):
    """p_BE = R_BA p_AE + p_BA (3,): the origin of E, at X_AE (4, 4), in a
    frame B in which A is fixed at (R_BA (3, 3), p_BA (3,)), each entry
    summed as ((R_0 x + R_1 y) + R_2 z) + p, the order of Python's
    arithmetic on the entries. Float64 C-contiguous arrays."""
    p_BE = np.empty(3)
    for r in range(3):
        p_BE[r] = ((R_BA[r, 0] * X_AE[0, 3] + R_BA[r, 1] * X_AE[1, 3])
                   + R_BA[r, 2] * X_AE[2, 3]) + p_BA[r]
    return p_BE


@fast_kernel(chain_kinematics_of, sample=_chain_sample)
def chain_kinematics_float(fixed, axes, revolute, q):
    """`chain_kinematics_of` in machine code, for float64 C-contiguous
    arrays (a SerialChain's and q (n,)): the arm's kinematics of every
    tick (drake_wbc.robot.model.ArmKinematics)."""
    return _chain_kinematics(fixed, axes, revolute, q)

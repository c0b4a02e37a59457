"""Reference implementations for the tests, independent of drake_wbc.

A small forward kinematics of serial chains given as URDF-style joint
origins (xyz, rpy relative to the previous link frame, revolute about the
local z axis, then a fixed flange offset), the Elfin5 chain as tabulated in
the robot facts, the UR5e's maker's Denavit-Hartenberg table, and random
rotations. The tests compare the library and
the model files with these; the joint-limit penalty of the paper is
written out term by term here too.
"""

import numpy as np

# Joint origins (xyz in m, rpy in rad) of the Elfin5, as in its URDF.
ELFIN5 = (
    (
        ((0.0, 0.0, 0.22), (0.0, 0.0, 0.0)),
        ((0.0, 0.0, 0.0), (1.5708, 0.0, 0.0)),
        ((0.0, 0.38, 0.0), (3.1416, 0.0, 1.5708)),
        ((0.0, 0.0, 0.0), (1.5708, 0.0, 1.5708)),
        ((0.0, 0.0, 0.42), (-1.5708, 0.0, 0.0)),
        ((0.0, 0.0, 0.0), (1.5708, 0.0, 0.0)),
    ),
    ((0.0, 0.0, 0.1565), (0.0, 0.0, 0.0)),
)
ELFIN5_UPPER = np.array([3.14, 2.35, 2.61, 3.14, 2.56, 3.14])
ELFIN5_LOWER = -ELFIN5_UPPER

# The UR5e's published Denavit-Hartenberg parameters (d, a, alpha), theta =
# q, and its dynamic parameters: link masses (kg) and centres of mass in
# the DH link frames (m).
UR5E_DH = (
    (0.1625, 0.0, np.pi / 2),
    (0.0, -0.425, 0.0),
    (0.0, -0.3922, 0.0),
    (0.1333, 0.0, np.pi / 2),
    (0.0997, 0.0, -np.pi / 2),
    (0.0996, 0.0, 0.0),
)
UR5E_MASSES = (3.761, 8.058, 2.846, 1.37, 1.3, 0.365)
UR5E_CENTRES_OF_MASS = (
    (0.0, -0.02561, 0.00193),
    (0.2125, 0.0, 0.11336),
    (0.15, 0.0, 0.0265),
    (0.0, -0.0018, 0.01634),
    (0.0, 0.0018, 0.01634),
    (0.0, 0.0, -0.001159),
)


def random_rotation(rng):
    """A uniformly random rotation matrix from a random unit quaternion."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def rpy_matrix(roll, pitch, yaw):
    """R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    Ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    Rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    return Rz @ Ry @ Rx


def forward_kinematics(chain, q):
    """Tool position, tool rotation, joint axes (n, 3), joint origins (n, 3),
    all in the base frame."""
    joints, (flange_xyz, flange_rpy) = chain
    R, p = np.eye(3), np.zeros(3)
    axes, origins = [], []
    for (xyz, rpy), angle in zip(joints, q, strict=True):
        p = p + R @ np.asarray(xyz)
        R = R @ rpy_matrix(*rpy)
        axes.append(R[:, 2])
        origins.append(p)
        R = R @ rpy_matrix(0.0, 0.0, angle)
    p = p + R @ np.asarray(flange_xyz)
    R = R @ rpy_matrix(*flange_rpy)
    return p, R, np.array(axes), np.array(origins)


def dh_frames(table, q):
    """The (4, 4) poses of the DH link frames 1 to n in frame 0, by the
    classic convention: T_i = T_(i-1) Rz(theta_i) Tz(d_i) Tx(a_i)
    Rx(alpha_i), theta_i = q_i."""
    T, frames = np.eye(4), []
    for (d, a, alpha), theta in zip(table, q, strict=True):
        ct, st = np.cos(theta), np.sin(theta)
        ca, sa = np.cos(alpha), np.sin(alpha)
        T = T @ np.array([[ct, -st * ca, st * sa, a * ct],
                          [st, ct * ca, -ct * sa, a * st],
                          [0.0, sa, ca, d],
                          [0.0, 0.0, 0.0, 1.0]])
        frames.append(T)
    return frames


def jacobian(chain, q):
    """Geometric Jacobian [v; w] of the tool point by the cross products
    z_i x (p - p_i), z_i."""
    p, _, axes, origins = forward_kinematics(chain, q)
    return np.vstack([np.cross(axes, p - origins).T, axes.T])


def jacobian_by_differences(chain, q, h=1e-6):
    """Geometric Jacobian from central differences of the forward
    kinematics: v from the tool position, w from R_dot R^T."""
    columns = []
    for e in np.eye(len(q)):
        p_plus, R_plus, _, _ = forward_kinematics(chain, q + h * e)
        p_minus, R_minus, _, _ = forward_kinematics(chain, q - h * e)
        _, R, _, _ = forward_kinematics(chain, q)
        W = (R_plus - R_minus) / (2.0 * h) @ R.T
        w = np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0],
                      W[1, 0] - W[0, 1]]) / 2.0
        columns.append(np.concatenate([(p_plus - p_minus) / (2.0 * h), w]))
    return np.array(columns).T


def random_chain(rng, n):
    joints = tuple(
        (tuple(rng.uniform(-0.4, 0.4, 3)), tuple(rng.uniform(-np.pi, np.pi, 3)))
        for _ in range(n)
    )
    flange = (tuple(rng.uniform(-0.2, 0.2, 3)), tuple(rng.uniform(-1, 1, 3)))
    return joints, flange


def random_nonsingular_q(rng, chain, lower, upper, s_min=0.05):
    """A random configuration inside the limits, with smallest singular
    value of the Jacobian above s_min."""
    while True:
        q = rng.uniform(lower, upper)
        if np.linalg.svd(jacobian(chain, q), compute_uv=False)[-1] > s_min:
            return q


def central_differences(function, x, h=1e-6):
    return np.array([
        (function(x + h * e) - function(x - h * e)) / (2.0 * h)
        for e in np.eye(len(x))
    ])


def one_sided_difference(function, x, direction, h=1e-6):
    """Second-order one-sided difference of function along direction."""
    return (-3.0 * function(x) + 4.0 * function(x + h * direction)
            - function(x + 2.0 * h * direction)) / (2.0 * h)


def penalty_by_loop(q, lower, upper, k_j):
    """P_jnt written out term by term, from the paper's formula."""
    product = 1.0
    for qi, li, ui in zip(q, lower, upper, strict=True):
        product *= (qi - li) * (ui - qi) / (ui - li) ** 2
    return 1.0 - np.exp(-k_j * product)


def chains_under_test():
    """(name, chain, lower, upper): the Elfin5 and three random chains."""
    rng = np.random.default_rng(7)
    chains = [("elfin5", ELFIN5, ELFIN5_LOWER, ELFIN5_UPPER)]
    for n in (6, 6, 7):
        chains.append((f"random{n}", random_chain(rng, n),
                       -np.full(n, 2.5), np.full(n, 2.5)))
    return chains

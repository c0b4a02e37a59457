"""Weighted whole-body motion distribution (paper Sec. III-B and IV-A).

The end-effector twist V_ee (6,) is split into the whole-body input
V_wb = [V_a; V_b] (9,) by the weighted least-norm solution of eq. (wln),

    V_wb = J^+ V_ee + (I - J^+ J) V_n^0,   J^+ = Q J^T (J Q J^T)^-1,

eq. (wbsln) with Q = W^-1 of eq. (weight-factors), and with the null-space
velocity V_n^0 = k_n [grad_x C_m; 0_3] of eq. (wbccm). J^+ V_ee is the
distribution without null-space term, and J^+ itself the distribution of
the six unit twists: the pseudo-inverse, its damping and V_wb are one
calculation, `weighted_distribution`, which forms neither J^+ nor W.

- the diagonal of Q, eq. (weight-factors): `weight_factors`, checked
  `weighting_matrix` (the matrix);
- V_wb of eqs. (wbsln)/(wbccm), and J^+: `weighted_distribution`, checked
  `distribute` and `weighted_pseudoinverse`;
- V_n^0 of eq. (wbccm): `capability_null_velocity_of`, checked
  `capability_null_velocity`;
- V_wb for J_wb = [R_ba, J_b] of eq. (fk) at p_ee:
  `whole_body_distribution`.

The references are scalar-generic (float, and numpy object arrays of
AutoDiffXd for the stages' derivatives) and check nothing; the checked
functions, for a user's call by hand, check their arguments and call them.
`whole_body_distribution` is what MotionDistributor runs each tick; its
fast float kernel `whole_body_distribution_float` is the closed form for
the usual mounting ^bR_a = I (below).

Singular Q. At sigma_xy or sigma_phi equal to 0 or 1 the matrix Q has
zeros on its diagonal and W = Q^-1 does not exist, but the formula for J^+
only needs J Q J^T to be invertible; Q^-1 is never formed. As Q is
diagonal, J^+ V_ee = Q (...) gives exactly zero to every input whose
weight in Q is zero.

Claim: for the controller's J = J_wb = [R_ba, J_b] (arm input = Cartesian
twist, eq. (fk) bottom line), J Q J^T is positive definite for every
(sigma_xy, sigma_phi) in [0, 1]^2 when ^bR_a = I (the usual mounting);
for a general mounting ^bR_a it is so whenever a_z != 0, a = ^bR_a e_z
being the arm base's z axis in T_b (a_z = 0 only for an arm mounted on
its side, and then only at sigma_xy = 0 or sigma_phi = 0).

Proof. Write s = sigma_xy, p = sigma_phi and R = ^bR_a. J Q J^T is a sum
of positive semidefinite terms, R6 Q_a R6^T + J_b Q_b J_b^T, so it is
singular iff some u = [l; w] != 0 (l linear, w angular, in T_b) makes
both terms vanish, i.e. Q_a R6^T u = 0 and Q_b J_b^T u = 0. With
l' = R^T l, w' = R^T w these read

    s l'_x = s l'_y = l'_z = w'_x = w'_y = p w'_z = 0,
    (1 - s) l_x = (1 - s) l_y = (1 - p)(w_z - y l_x + x l_y) = 0.

So w = w'_z a and l is orthogonal to a. Linear part: if s > 0 then
l' = 0, so l = 0; if s = 0 then l_x = l_y = 0, and l orthogonal to a
gives l_z a_z = 0, so l = 0 when a_z != 0. Angular part, with l = 0: if
p > 0 then w'_z = 0; if p = 0 then w_z = w'_z a_z = 0, so w'_z = 0 when
a_z != 0. Hence u = 0: each of the planar translations and the yaw is
always carried by the arm block or by J_b. For R = I, J Q J^T does not
depend on s; it has the eigenvalue 1 three times (vz, wx, wy), and on
(vx, vy, wz) it equals diag(1, 1, p) + (1 - p) c c^T, c = [-y, x, 1], with
determinant 1 + p (1 - p) r^2 >= 1 and trace 3 + (1 - p) r^2 <= 3 + r^2
(r = horizontal distance of the end effector from the base's z axis). So
its smallest eigenvalue is at least 4 / (3 + r^2)^2 and its condition
number at most (3 + r^2)^3 / 4, below the damping threshold 1e4 (see
below) for every r < 5.5 m, far beyond an arm's reach. So no damping
happens in the controller's case and J_wb V_wb = V_ee holds exactly (to
rounding). For a general mounting the margin shrinks as a_z -> 0 at
sigma = 0.

Damping. For a general J, e.g. a singular geometric Jacobian in the arm
block (eq. (fk) top line), J Q J^T can be singular. The distribution then
uses the damped inverse (J Q J^T + lambda^2 I)^-1 with the usual smooth
rule on its smallest eigenvalue s_min and largest s_max:

    lambda^2 = lambda_max^2 (1 - (s_min / eps)^2)   if s_min < eps,
    lambda^2 = 0                                     otherwise,

with eps and lambda_max^2 relative to s_max (see SingularityDamping), so
that the rule does not depend on units or on the overall size of J. The
defaults take lambda_max^2 = eps = 1e-4 s_max: then s_min + lambda^2 =
s_min + eps - s_min^2 / eps stays within [eps, 1.25 eps] as s_min goes
from eps to 0, so the smallest eigenvalue of the damped matrix neither
jumps nor drops below eps.
With damping J V_wb = V_ee holds only approximately (the motion along the
weak directions is reduced); this is the only deviation from the paper's
formula. For AutoDiffXd the eigenvalues are taken as v^T (J Q J^T) v with
the eigenvectors v of its value, which gives them (and lambda^2) their
exact first derivatives for simple eigenvalues.
"""

import math
from dataclasses import dataclass, field

import numpy as np

from drake_wbc.math.compiled import compiled_for, float_array
from drake_wbc.math.kernels import fast_kernel
from drake_wbc.math.kinematics import (
    random_rotation,
    whole_body_jacobian_of,
)
from drake_wbc.math.scalar_support import solve, value_of
from drake_wbc.math.task_inputs import TASK_INPUTS
from drake_wbc.math.validation import (
    as_matrix,
    as_vector,
    in_closed_range,
    non_negative,
    positive,
)

SINGULAR_TOLERANCE = 1e-12
"""J_wb Q J_wb^T counts as singular (an error without damping) when its
smallest eigenvalue is at most this fraction of its largest: below it the
undamped solve's result is rounding."""


@dataclass
class SingularityDamping:
    """Parameters of the damped inverse of J Q J^T near singularity.

    Both values are relative to s_max, the largest eigenvalue of J Q J^T
    (whose entries mix units of linear and angular motion), so the rule
    is the same whatever the units or the overall size of J. Damping
    starts when the condition number of J Q J^T exceeds 1 / threshold,
    i.e. that of J Q^(1/2) exceeds 1 / sqrt(threshold).

    Attributes:
        threshold: eps / s_max, in (0, 1); default 1e-4, i.e. damping
            starts where the smallest singular value of J Q^(1/2) falls
            below 1 % of the largest. Whole-body Jacobians [R_ba, J_b]
            stay above it (module docstring).
        max_squared: lambda_max^2 / s_max, reached when J Q J^T is exactly
            singular; default 1e-4 (lambda_max = 1 % of the largest
            singular value of J Q^(1/2)). Equal to the threshold, it makes
            the transition gentle: s_min + lambda^2 stays within
            [eps, 1.25 eps]. The motion along a direction of singular
            value sigma_i of J Q^(1/2) is reduced by the relative amount
            lambda^2 / (sigma_i^2 + lambda^2) <= 1e-4 s_max / sigma_i^2,
            negligible in well-conditioned directions, and the gain of J^+
            stays below 1 / sqrt(eps) = 100 / sqrt(s_max) instead of
            growing without bound.
    """

    threshold: float = 1e-4
    max_squared: float = 1e-4

    def __post_init__(self):
        threshold = positive("threshold", self.threshold)
        if threshold >= 1.0:
            raise ValueError(
                f"threshold = {threshold!r} is not allowed: must lie in "
                "(0, 1) (s_min / s_max <= 1 always, so 1 or more would damp "
                "every J Q J^T)")
        non_negative("max_squared", self.max_squared)


DEFAULT_DAMPING = SingularityDamping()
"""The default damping of the distribution (shared: pass a
SingularityDamping of your own rather than changing this one)."""


# --- the reference bodies ---------------------------------------------------

def weight_factors(sigma_xy, sigma_phi):
    """The diagonal of Q = W^-1 of eq. (weight-factors), (9,), for any
    scalar type (the reference body of `weighting_matrix`, which documents
    it)."""
    return np.array([sigma_xy, sigma_xy, 1.0, 1.0, 1.0, sigma_phi,
                     1.0 - sigma_xy, 1.0 - sigma_xy, 1.0 - sigma_phi])


def weighted_distribution(J_wb, V_ee, Q, null_velocity=None,
                          damping=DEFAULT_DAMPING):
    """V_wb of eqs. (wbsln)/(wbccm) for any scalar type, unchecked:

        V_wb = Q J^T (J Q J^T)^-1 (V_ee - J V_n^0) + V_n^0,

    the same as J^+ V_ee + (I - J^+ J) V_n^0, with the damping of J Q J^T
    near singularity (module docstring). The reference body of
    `distribute` and `weighted_pseudoinverse`, which document the
    arguments: J^+ is the distribution of V_ee = I (6, 6).

    Args:
        J_wb: (6, 9) Jacobian.
        V_ee: (6,) twist, or (6, k) twists (then without null_velocity).
        Q: the weights: (9,) the diagonal of a diagonal Q (see
            weight_factors), or a (9, 9) symmetric positive semidefinite
            matrix.
        null_velocity: (9,) V_n^0, or None for none.
        damping: a SingularityDamping, or None for the exact inverse.

    Returns:
        (9,) V_wb (or (9, k)), of the arguments' scalar type; NaN where
        J Q J^T is not finite, and with damping None where it is not
        positive definite (`_not_invertible`; the checked functions
        raise there instead).
    """
    J, Q, V_ee = np.asarray(J_wb), np.asarray(Q), np.asarray(V_ee)
    JQ = J * Q if Q.ndim == 1 else J @ Q
    M = JQ @ J.T
    M = 0.5 * (M + M.T)
    rhs = V_ee if null_velocity is None else V_ee - J @ null_velocity
    M_value = value_of(M)
    if not np.isfinite(M_value).all():  # whose eigh numpy refuses
        x = math.nan * rhs
        V_wb = JQ.T @ x
        return V_wb if null_velocity is None else V_wb + null_velocity
    eigenvalues, vectors = np.linalg.eigh(M_value)
    if damping is None and _not_invertible(eigenvalues):
        x = math.nan * rhs  # no exact inverse
    elif eigenvalues[-1] <= 0.0:
        x = 0.0 * rhs  # J Q^(1/2) = 0: no weighted input moves the end effector
    else:
        if (damping is not None and max(eigenvalues[0], 0.0)
                < damping.threshold * eigenvalues[-1]):
            s_max = vectors[:, -1] @ M @ vectors[:, -1]
            s_min = (vectors[:, 0] @ M @ vectors[:, 0]
                     if eigenvalues[0] > 0.0 else 0.0 * s_max)
            ratio = s_min / (damping.threshold * s_max)
            M = M + (damping.max_squared * s_max * (1.0 - ratio * ratio)
                     * np.eye(6))
        x = (solve(M, rhs) if rhs.ndim == 1 else
             np.stack([solve(M, column) for column in rhs.T], axis=1))
    V_wb = JQ.T @ x
    return V_wb if null_velocity is None else V_wb + null_velocity


def _not_invertible(eigenvalues):
    """Whether J Q J^T of these ascending eigenvalues has no exact inverse:
    zero, or numerically singular, whatever the rounding of the LAPACK at
    hand (a Cholesky factorisation may or may not succeed on an
    eigenvalue of 1e-17)."""
    return bool(eigenvalues[-1] <= 0.0
                or eigenvalues[0] <= SINGULAR_TOLERANCE * eigenvalues[-1])


def _check_invertible(J, Q, damping):
    """With damping None, raises the ValueError of the checked functions
    where `weighted_distribution` has no exact inverse (and gives NaN):
    J Q J^T not positive definite. J, Q (9,) or (9, 9) checked floats."""
    if damping is not None:
        return
    M = (J * Q if Q.ndim == 1 else J @ Q) @ J.T
    eigenvalues = np.linalg.eigvalsh(0.5 * (M + M.T))
    if _not_invertible(eigenvalues):
        raise ValueError(
            "J_wb with J_wb Q J_wb^T of smallest eigenvalue "
            f"{eigenvalues[0]:.6g} (largest {eigenvalues[-1]:.6g}) is not "
            "allowed with damping=None: J_wb Q J_wb^T must be positive "
            "definite (J_wb Q^(1/2) of full row rank); pass a "
            "SingularityDamping")


def capability_null_velocity_of(grad_x_C_m, k_n):
    """V_n^0 = k_n [grad_x C_m; 0_3] of eq. (wbccm) for any scalar type
    (the reference body of `capability_null_velocity`, which documents
    it); a (9,) array."""
    g = np.asarray(grad_x_C_m)
    return np.concatenate([k_n * g, 0.0 * g[:3]])


def whole_body_distribution(V_ee, p_ee_in_base, R_ba, sigma_xy, sigma_phi,
                            capability_gradient, null_space_gain,
                            damping=DEFAULT_DAMPING):
    """V_wb of eq. (wbccm) for J_wb = [R_ba, J_b] of eq. (fk) (bottom
    line) at the end effector's position, for any scalar type, unchecked:
    what MotionDistributor runs each tick (its fast float kernel is
    `whole_body_distribution_float`).

    Args:
        V_ee: (6,) the end-effector twist in T_b.
        p_ee_in_base: (3,) p_ee in T_b (only x and y enter J_b).
        R_ba: (3, 3) ^bR_a, or None for the identity.
        sigma_xy, sigma_phi: the weighting factors, in [0, 1].
        capability_gradient: (6,) grad_x C_m in T_a.
        null_space_gain: k_n >= 0.
        damping: a SingularityDamping, or None.

    Returns:
        (9,) V_wb = [V_a (6, T_a); V_b (3, T_b)].
    """
    J = whole_body_jacobian_of(None, p_ee_in_base,
                               np.eye(3) if R_ba is None else R_ba)
    return weighted_distribution(
        J, V_ee, weight_factors(sigma_xy, sigma_phi),
        capability_null_velocity_of(capability_gradient, null_space_gain),
        damping)


# --- the controller's kernel ------------------------------------------------

def _whole_body_problems(rng):
    """Arguments of whole_body_distribution: the usual mounting mostly,
    sometimes a random one (the general path); reaches up to 3 m, where
    the certificate holds, and up to 30 m, where it fails and the general
    path damps; sigmas at 0 and 1; zero gradients and gains; no damping
    at arm's reach; in one case in twenty an entry of V_ee, p_ee or the
    gradient NaN or infinite."""
    damped = rng.random() < 0.75
    reach = rng.choice([1.0, 2.3, 20.0] if damped else [1.0])
    p = rng.uniform(-1.5, 1.5, 3) * reach
    R = None if rng.random() < 0.8 else random_rotation(rng)
    sigma_xy, sigma_phi = rng.choice([0.0, 1.0, *rng.uniform(size=3)], 2)
    gradient = rng.normal(size=6) * rng.choice([0.0, 1e-3, 1.0])
    gain = rng.choice([0.0, 0.1, rng.uniform(0.0, 3.0)])
    V_ee = rng.normal(size=6) * rng.choice([1e-3, 1.0])
    if rng.random() < 0.05:
        vector = (V_ee, p, gradient)[rng.integers(3)]
        vector[rng.integers(vector.size)] = rng.choice(
            [np.nan, np.inf, -np.inf])
    return (V_ee, p, R, float(sigma_xy), float(sigma_phi), gradient,
            float(gain), DEFAULT_DAMPING if damped else None)


@compiled_for("float64[::1](float64[::1], float64[::1], float64, float64, "
              "float64[::1], float64, boolean, float64)")
def _closed_form(V_ee, p_ee_in_base, s, p, capability_gradient, k, damped,
                 threshold):
    """The compiled closed form of `whole_body_distribution_float`: V_wb
    (9,), or NaN in every entry where it does not hold (the certificate
    not proved, or a value not finite)."""
    x, y = p_ee_in_base[0], p_ee_in_base[1]
    n0, n1, n2 = (k * capability_gradient[0], k * capability_gradient[1],
                  k * capability_gradient[2])
    n3, n4, n5 = (k * capability_gradient[3], k * capability_gradient[4],
                  k * capability_gradient[5])
    # V_ee - J_wb V_n^0 with J_wb V_n^0 = the arm part of V_n^0.
    v0, v1, v2 = V_ee[0] - n0, V_ee[1] - n1, V_ee[2] - n2
    v3, v4, v5 = V_ee[3] - n3, V_ee[4] - n4, V_ee[5] - n5
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
    if damped:
        # The product of 5 L_ii^2 / tr M over the six pivots, three of
        # them 1.
        ratio = 5.0 / (3.0 + a00 + a11 + a22)
        certificate = ((l00 * l00 * ratio) * (l11 * l11 * ratio)
                       * (l22 * l22 * ratio) * ratio * ratio * ratio)
        proved = certificate >= 5.0 * threshold
    else:
        proved = l22 == l22  # not NaN: A is positive definite
    V_wb = np.empty(9)
    if not (proved and math.isfinite(x + y + v0 + v1 + v2 + v3 + v4
                                      + v5)):
        V_wb[:] = math.nan
        return V_wb
    z0 = v0 / l00
    z1 = (v1 - l10 * z0) / l11
    z5 = (v5 - l20 * z0 - l21 * z1) / l22
    x5 = z5 / l22
    x1 = (z1 - l21 * x5) / l11
    x0 = (z0 - l10 * x1 - l20 * x5) / l00
    V_wb[0], V_wb[1], V_wb[2] = s * x0 + n0, s * x1 + n1, v2 + n2
    V_wb[3], V_wb[4], V_wb[5] = v3 + n3, v4 + n4, p * x5 + n5
    V_wb[6], V_wb[7] = a * x0, a * x1
    V_wb[8] = b * (x5 - y * x0 + x * x1)
    return V_wb


@fast_kernel(whole_body_distribution, sample=_whole_body_problems)
def whole_body_distribution_float(V_ee, p_ee_in_base, R_ba, sigma_xy,
                                  sigma_phi, capability_gradient,
                                  null_space_gain, damping=DEFAULT_DAMPING):
    """`whole_body_distribution` in machine code (drake_wbc.math.compiled):
    the closed form for the usual mounting (R_ba None, ^bR_a = I); any
    other mounting, a case the damping might touch or a value that is not
    finite goes to the reference.

    With R_ba = I, M = J Q J^T is the identity on the rows (vz, wx, wy)
    and on (vx, vy, wz) the 3x3 block

        A = diag(s + (1 - s), s + (1 - s), p) + (1 - p) c c^T,
        c = [-y, x, 1],

    (s = sigma_xy, p = sigma_phi, det A = 1 + p (1 - p) r^2 >= 1, module
    docstring), so that x = M^-1 (V_ee - J V_n^0) is a 3x3 Cholesky solve
    and V_wb = Q J^T x + V_n^0 of eq. (wbccm) has the closed form

        V_a = w_a x + V_n^0,   V_b = [(1 - s) x_vx, (1 - s) x_vy,
                                      (1 - p)(x_wz - y x_vx + x x_vy)],

    with J V_n^0 = the arm part k_n grad_x C_m of V_n^0.

    The damping rule leaves M undamped when s_min >= eps =
    threshold s_max; this is proved without eigenvalues. With the Cholesky
    factor L of M and t = tr M: s_max <= t, and the other five eigenvalues
    multiply to at most (t / 5)^5 (arithmetic and geometric means), so
    s_min >= det M (5 / t)^5 with det M = prod L_ii^2. Hence
    prod_i (5 L_ii^2 / t) >= 5 threshold (six factors, three of them
    5 / t here, free of units and scale) proves s_min >= threshold t >=
    eps, i.e. lambda = 0. For R_ba = I it holds for every reach r up to
    about 3.4 m (det M >= 1, t <= 6 + r^2); beyond it, the reference
    applies the rule as written.

    Args:
        as whole_body_distribution; V_ee, p_ee_in_base and
        capability_gradient as float64 C-contiguous writeable arrays, as
        the stages give them, go to the closed form as they are; any
        other (a strided view, a list) is refused by the sealed closed
        form (drake_wbc.math.compiled.compiled_for) and copied by
        `float_array` (a scalar that numba refuses, a 0-d array, by
        float). Their shapes are not checked: the stages' are right by
        construction; a caller by hand has the checked `distribute`.

    Returns:
        (9,) array V_wb.
    """
    if R_ba is None:
        damped = damping is not None
        threshold = damping.threshold if damped else 0.0
        try:
            V_wb = _closed_form(V_ee, p_ee_in_base, sigma_xy, sigma_phi,
                                capability_gradient, null_space_gain,
                                damped, threshold)
        except TypeError:  # not the types it is compiled for: copies
            V_wb = _closed_form(
                float_array(V_ee), float_array(p_ee_in_base),
                float(sigma_xy), float(sigma_phi),
                float_array(capability_gradient), float(null_space_gain),
                damped, threshold)
        if V_wb[0] == V_wb[0]:  # not NaN: the closed form holds
            return V_wb
    return whole_body_distribution(
        V_ee, p_ee_in_base, R_ba, sigma_xy, sigma_phi, capability_gradient,
        null_space_gain, damping)



# --- the checked functions --------------------------------------------------

def weighting_matrix(sigma_xy, sigma_phi):
    """Weighting matrix Q = W^-1 of eq. (weight-factors).

    Q = block-diag(Q_a, Q_b) with

        Q_a = diag(sigma_xy, sigma_xy, 1, 1, 1, sigma_phi),
        Q_b = diag(1 - sigma_xy, 1 - sigma_xy, 1 - sigma_phi),

    ordered like V_wb = [V_a; V_b] = [vx, vy, vz, wx, wy, wz (arm, T_a);
    vx_b, vy_b, wz_b (base, T_b)]. sigma = 1 gives the motion in the plane
    (sigma_xy) or about z (sigma_phi) to the arm only, sigma = 0 to the
    base only, values in between to both.

    Args:
        sigma_xy: weighting factor of the x-y translation, in [0, 1].
        sigma_phi: weighting factor of the rotation about z, in [0, 1].

    Returns:
        (9, 9) diagonal array Q (positive semidefinite; singular when a
        sigma is 0 or 1).

    Raises:
        ValueError: if a sigma is not a finite number in [0, 1].
    """
    return np.diag(weight_factors(
        in_closed_range("sigma_xy", sigma_xy, 0.0, 1.0),
        in_closed_range("sigma_phi", sigma_phi, 0.0, 1.0)))


def _checked_weights(Q):
    """Q as a finite, symmetric, positive semidefinite 9x9 matrix."""
    Q = as_matrix("Q", Q, (9, 9))
    scale = max(np.max(np.abs(Q)), 1.0)
    asymmetry = np.abs(Q - Q.T)
    i, j = np.unravel_index(np.argmax(asymmetry), asymmetry.shape)
    if asymmetry[i, j] > 1e-12 * scale:
        raise ValueError(
            f"Q with Q[{i}, {j}] = {Q[i, j]!r} and Q[{j}, {i}] = "
            f"{Q[j, i]!r} is not allowed: must be symmetric"
        )
    smallest = np.linalg.eigvalsh(Q)[0]
    if smallest < -1e-12 * scale:
        raise ValueError(
            f"Q with smallest eigenvalue {smallest:.6g} is not allowed: "
            "must be positive semidefinite (no negative eigenvalue)"
        )
    return Q


def _checked_damping(damping):
    """damping, after checking that it is a SingularityDamping or None."""
    if damping is not None and not isinstance(damping, SingularityDamping):
        raise ValueError(
            f"damping = {damping!r} is not allowed: must be a "
            "SingularityDamping or None"
        )
    return damping


def weighted_pseudoinverse(J_wb, Q, damping=DEFAULT_DAMPING):
    """Weighted pseudo-inverse J^+ = Q J^T (J Q J^T)^-1 of eq. (wbsln).

    The paper's W^-1 is Q of eq. (weight-factors). Q may be singular
    (sigma at 0 or 1): only J Q J^T is inverted. J^+ V_ee is then the
    weighted least-norm solution of eq. (wln), min V^T W V subject to
    J V = V_ee, and J J^+ = I.

    Near a singularity of J Q J^T (smallest eigenvalue s_min below
    eps = damping.threshold * s_max) the damped inverse
    (J Q J^T + lambda^2 I)^-1 is used, with lambda^2 =
    damping.max_squared * s_max * (1 - (s_min / eps)^2); see the module
    docstring. J J^+ = I then holds only approximately. For the
    controller's J_wb = [R_ba, J_b] this never happens in practice (proof
    in the module docstring).

    Args:
        J_wb: (6, 9) whole-body Jacobian, e.g. from
            kinematics.whole_body_jacobian.
        Q: (9, 9) symmetric positive semidefinite weighting matrix W^-1.
        damping: SingularityDamping parameters, or None for the paper's
            exact formula (an error if J Q J^T is singular).

    Returns:
        (9, 6) array J^+.

    Raises:
        ValueError: if J_wb or Q has the wrong shape or a non-finite entry,
            Q is not symmetric positive semidefinite, damping is not a
            SingularityDamping or None, or (damping=None only) J Q J^T is
            not positive definite.
    """
    J = as_matrix("J_wb", J_wb, (6, 9))
    Q = _checked_weights(Q)
    damping = _checked_damping(damping)
    _check_invertible(J, Q, damping)
    return weighted_distribution(J, np.eye(6), Q, None, damping)


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
    return capability_null_velocity_of(
        as_vector("grad_x_C_m", grad_x_C_m, 6),
        TASK_INPUTS["null_space_gain"].check_number("k_n", k_n))


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
    needed (always for J_wb = [R_ba, J_b], see the module docstring).

    Args:
        J_wb: (6, 9) whole-body Jacobian, normally [R_ba, J_b] (eq. (fk),
            bottom line) from kinematics.whole_body_jacobian(None, ...).
        V_ee: (6,) end-effector twist [v; w] in T_b (m/s; rad/s).
        sigma_xy: weighting factor of the x-y translation, in [0, 1].
        sigma_phi: weighting factor of the rotation about z, in [0, 1].
        null_velocity: (9,) V_n^0, ordered like V_wb, e.g. from
            capability_null_velocity; None for no null-space motion.
        damping: see weighted_pseudoinverse.

    Returns:
        (9,) array V_wb = [V_a (6, T_a); V_b (3, T_b)].

    Raises:
        ValueError: on a bad argument (wrong shape, non-finite entry, sigma
            outside [0, 1]), naming it; with damping=None, if J Q J^T is
            not positive definite.
    """
    J = as_matrix("J_wb", J_wb, (6, 9))
    V_ee = as_vector("V_ee", V_ee, 6)
    weights = weight_factors(in_closed_range("sigma_xy", sigma_xy, 0.0, 1.0),
                             in_closed_range("sigma_phi", sigma_phi, 0.0,
                                             1.0))
    V_n = (None if null_velocity is None
           else as_vector("null_velocity", null_velocity, 9))
    damping = _checked_damping(damping)
    _check_invertible(J, weights, damping)
    return weighted_distribution(J, V_ee, weights, V_n, damping)


@dataclass
class MotionDistributorParameters:
    """Parameters of MotionDistributor.

    Attributes:
        null_space_gain: k_n >= 0 of eq. (wbccm), used when the
            null_space_gain port is not connected; the paper starts with 0
            and switches to 0.1.
        smooth_switch_off: True fades k_n out across the band,
            k_n alpha(C_m, C_m^u, C_m^l); False switches it off in one step
            above C_m^u, the paper's words read literally.
        damping: SingularityDamping (never active for our
            robot's J_wb, see the module), or None for
            none; default the values of DEFAULT_DAMPING.

    The band C_m^l, C_m^u (k_n is off at and above C_m^u with the smooth
    switch-off, above it with the step) is the stage's `band` argument
    (one CapabilityBand for every stage that looks at C_m).
    """

    null_space_gain: float = 0.0
    smooth_switch_off: bool = True
    damping: SingularityDamping | None = field(
        default_factory=SingularityDamping)

    def __post_init__(self):
        TASK_INPUTS["null_space_gain"].check_number(
            "null_space_gain", self.null_space_gain)
        if not isinstance(self.smooth_switch_off, bool):
            raise ValueError(
                f"smooth_switch_off = {self.smooth_switch_off!r} is not "
                "allowed: must be True or False"
            )
        if not (self.damping is None or isinstance(
                self.damping, SingularityDamping)):
            raise ValueError(
                f"damping = {self.damping!r} is not allowed: must be a "
                "SingularityDamping or None"
            )

"""The weighted pseudo-inverse of eq. (wbsln) (paper Sec. III-B and IV-A),

    J^+ = Q J^T (J Q J^T)^-1,

with Q = W^-1 of eq. (weight-factors), the weighting matrix of the
factors sigma_xy, sigma_phi, and its damping near singularity. J^+ V_ee
is the weighted least-norm solution of eq. (wln); drake_wbc.math.distribution
builds V_wb of eqs. (wbsln)/(wbccm) on it.

Singular Q. At sigma_xy or sigma_phi equal to 0 or 1 the matrix Q has
zeros on its diagonal and W = Q^-1 does not exist, but the formula for J^+
only needs J Q J^T to be invertible; Q^-1 is never formed. As Q is
diagonal, J^+ V_ee = Q (...) gives exactly zero to every input whose
weight in Q is zero.

Claim: for the controller's J = J_wb = [R_ba, J_b] (arm input = Cartesian
twist, eq. (1) bottom line), J Q J^T is positive definite for every
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
block (eq. (1) top line), J Q J^T can be singular. weighted_pseudoinverse
then uses the damped inverse (J Q J^T + lambda^2 I)^-1 with the usual
smooth rule on its smallest eigenvalue s_min and largest s_max:

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
formula. The closed form for ^bR_a = I in plain floats, the controller's
per-tick path, is drake_wbc.math.aligned_distribution.
"""

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dpotrf, dpotrs

from drake_wbc.math.validation import (
    as_matrix,
    in_closed_range,
    non_negative,
    positive,
)


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
"""The default damping of weighted_pseudoinverse and
distribution.distribute (shared: pass a SingularityDamping of your own
rather than changing this one)."""


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
    s_xy = in_closed_range("sigma_xy", sigma_xy, 0.0, 1.0)
    s_phi = in_closed_range("sigma_phi", sigma_phi, 0.0, 1.0)
    return np.diag(
        [s_xy, s_xy, 1.0, 1.0, 1.0, s_phi, 1.0 - s_xy, 1.0 - s_xy, 1.0 - s_phi]
    )


def weights_of(sigma_xy, sigma_phi):
    """The diagonal of Q(sigma_xy, sigma_phi) of eq. (weight-factors), (9,),
    for sigmas already checked to lie in [0, 1] (see weighting_matrix)."""
    return np.array([sigma_xy, sigma_xy, 1.0, 1.0, 1.0, sigma_phi,
                     1.0 - sigma_xy, 1.0 - sigma_xy, 1.0 - sigma_phi])


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
    return _pseudoinverse(J, Q, checked_damping(damping))


def checked_damping(damping):
    """damping, after checking that it is a SingularityDamping or None."""
    if damping is not None and not isinstance(damping, SingularityDamping):
        raise ValueError(
            f"damping = {damping!r} is not allowed: must be a "
            "SingularityDamping or None"
        )
    return damping


def _pseudoinverse(J, Q, damping):
    """J^+ for arguments already checked (see weighted_pseudoinverse)."""
    JQ = J @ Q
    if damping is not None:
        solution = certified_solve(J, JQ, JQ, damping.threshold)
        if solution is not None:
            return solution.T
    return pseudoinverse_by_rule(J, JQ, damping)


def certified_solve(J, JQ, rhs, threshold):
    """(J Q J^T)^-1 rhs when the damping rule provably leaves
    J Q J^T undamped, else None (then apply the rule as written). J (6, 9)
    and JQ = J Q checked, rhs (6,) or (6, k).

    This skips the eigen-decomposition that the rule needs. With the
    Cholesky factor L of M = J Q J^T (so M is positive definite) and
    t = tr M: s_max <= t, and the other five eigenvalues multiply to at
    most (t / 5)^5 (arithmetic and geometric means), so
    s_min >= det M (5 / t)^5 with det M = prod L_ii^2. Hence
    prod_i (5 L_ii^2 / t) >= 5 threshold (six factors, free of units and
    scale) proves s_min >= threshold t >= eps, i.e. lambda = 0. For the
    controller's J_wb = [R_ba, J_b] with R_ba = I it holds for every reach
    r up to about 3.4 m (det M >= 1, t <= 6 + r^2; module docstring), so
    one Cholesky factorisation and its solve are the whole cost.
    """
    M = JQ @ J.T
    factor, info = dpotrf(M, lower=1, clean=0)  # reads M's lower half
    if info != 0:
        return None
    diagonal = factor.diagonal()
    certificate = math.prod((diagonal * diagonal * (5.0 / M.trace()))
                            .tolist())
    if not certificate >= 5.0 * threshold:
        return None
    return dpotrs(factor, rhs, lower=1)[0]


def pseudoinverse_by_rule(J, JQ, damping):
    """J^+ = Q J^T (J Q J^T + lambda^2 I)^-1 with the damping rule of the
    module docstring applied as written (eigenvalues of J Q J^T), or the
    exact inverse for damping None, for checked J and JQ = J Q."""
    M = JQ @ J.T
    M = 0.5 * (M + M.T)
    if damping is None:
        try:
            factor = np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            raise ValueError(
                "J_wb with J_wb Q J_wb^T of smallest eigenvalue "
                f"{np.linalg.eigvalsh(M)[0]:.6g} is not allowed with "
                "damping=None: J_wb Q J_wb^T must be positive definite "
                "(J_wb Q^(1/2) of full row rank); pass a SingularityDamping"
            ) from None
        # (L L^T)^-1 J Q by two triangular solves; J^+ is its transpose.
        return np.linalg.solve(factor.T, np.linalg.solve(factor, JQ)).T
    eigenvalues = np.linalg.eigvalsh(M)
    s_min, s_max = max(eigenvalues[0], 0.0), eigenvalues[-1]
    if s_max <= 0.0:
        # J Q^(1/2) = 0: no input with a weight moves the end effector.
        return np.zeros((9, 6))
    eps = damping.threshold * s_max
    if s_min < eps:
        lambda_sq = damping.max_squared * s_max * (1.0 - (s_min / eps) ** 2)
        M[np.diag_indices(6)] += lambda_sq
    return np.linalg.solve(M, JQ).T

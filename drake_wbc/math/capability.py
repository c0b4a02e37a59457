"""The capability of movement C_m, its gradients and the transition alpha
(paper Sec. IV-A, "Movement Capability Optimization" and eq. (transition)).

The capability of movement C_m = m * P_jnt multiplies Yoshikawa's
manipulability index m (distance to singularity) by the joint-limit
penalization P_jnt (distance to the joint limits). Its gradient w.r.t.
the arm's Cartesian pose, grad_x C_m, drives the null-space term of eq.
(wbccm) and is the direction that the compensation of eq. (wb_error) must
not worsen, a projection faded in by the transition alpha of eq.
(transition) as C_m drops from C_m^u to C_m^l (the band, CapabilityBand).

J_a is the 6 x n geometric Jacobian of the tool point in the arm's base
frame T_a, rows [v; w] (linear velocity of the tool point in m/s, angular
velocity in rad/s per joint rate in rad/s), columns the joint rates of an
all-revolute serial chain (n = 6 for the shipped arm). The gradients are
analytic, from J_a and q alone: dJ_a/dq from J_a itself, no finite
differences of the kinematics.

How the module is laid out, for each equation:

- its reference body, scalar-generic (float, or numpy object arrays of
  AutoDiffXd) and unchecked: the formula as written. The tick's bodies are
  public (`capability_terms`, `transition_of`,
  `transition_derivative_of`), the others private. Where a body
  takes an SVD, which numpy has for floats only, AutoDiffXd goes through
  scalar_support.through_float_function (exact values, derivatives by
  central differences);
- its checked public function of the plain name (`capability`,
  `capability_gradient`, `transition`, ...), for calls by hand: one thin
  layer that checks the arguments and calls the reference body;
- at most one float kernel (`*_float`), the controller's per-tick path,
  registered with drake_wbc.math.kernels.fast_kernel: C_m and grad_x C_m
  from one SVD in machine code (drake_wbc.math.compiled), and alpha and
  its derivative in plain floats.
"""

import functools
import math
from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import AutoDiffXd

from drake_wbc.math.compiled import compiled
from drake_wbc.math.joint_range import unlimited
from drake_wbc.math.kernels import fast_kernel
from drake_wbc.math.scalar_support import (
    constant_like,
    cross,
    is_autodiff,
    through_float_function,
    zero_like,
)
from drake_wbc.math.validation import (
    as_matrix,
    as_scalar,
    as_vector,
    non_negative,
    ordered_limits,
    positive,
)

DEFAULT_JOINT_LIMIT_GAIN = 1.5e4
"""Default scaling factor k_j of P_jnt (dimensionless).

Scaling: each factor (q_i - l_i)(u_i - q_i) / (u_i - l_i)^2 of P_jnt is at
most 1/4, reached at mid-range, so their product over n joints is at most
4^-n (1/4096 for six joints). k_j must therefore be of order 4^n for P_jnt
to approach 1 at mid-range. For n = 6 and this default:

    every joint mid-range:  P_jnt = 1 - exp(-k_j 4^-6)
                                  = 1 - exp(-3.66) = 0.974,
    one joint 5% of its range from a limit, the others mid-range
    (its factor is 0.05 * 0.95 = 0.19 / 4 instead of 1/4):
                            P_jnt = 1 - exp(-0.19 k_j 4^-6)
                                  = 1 - exp(-0.696) = 0.501.

Why 1.5e4 on our arm: it makes the paper's limitation band
0.035 < C_m < 0.04 mean "close to a constraint" on the shipped arm with its
tool. At the home pose (drake_wbc.robot.model.HOME_ARM_POSITIONS)
m = 0.071 and P_jnt = 0.91, so C_m = 0.065, well above the band. Moving
one joint from home, C_m enters the band either when that joint comes
within about 8 to 12% of its range from a limit (P_jnt falls to 0.5-0.6
with m unchanged), or when the manipulability itself falls to about 0.04
(the elbow opening towards the stretched singularity, or the wrist
straightening), with P_jnt still above 0.9. A smaller k_j (5e3) would put
home itself inside the band; a larger one (3e4) would let joints come
within about 4% of a limit before the band is reached.
"""

DEFAULT_DAMPING_THRESHOLD = 0.02
"""Default threshold eps on the smallest singular value s_min of J_a, below
which `capability_gradient` damps its solve. For the shipped arm with its tool,
s_min is about 0.31 d within d rad of the wrist singularity (q_5 = 0) and
about 0.16 d near the stretched elbow (q_3 = 0) (as for
drake_wbc.math.arm_control's threshold): 0.02 damps roughly the last
0.065 rad before the first and the last 0.13 rad before the second."""

DEFAULT_MAX_DAMPING = 0.02
"""Default damping lambda_max of `capability_gradient` (at s_min = 0). Equal
to eps, so that below eps s_min^2 + lambda^2 = eps^2: the gain
s_min / eps^2 of the weakest direction falls linearly from 1/eps to 0,
meeting the undamped gain 1/s_min continuously at s_min = eps."""


# ----------------------------------------------------------------------------
# Parameters
# ----------------------------------------------------------------------------

@dataclass
class CapabilityBand:
    """The limitation band C_m^l < C_m < C_m^u of eq. (transition).

    One band serves every stage that looks at C_m: alpha of the robust
    compensation (ArmCapability), the adaptive weighting factors of the
    intuitive pHRI mode (WorkspaceAdapter) and the switch-off of the
    null-space gain (MotionDistributor). It is
    ControllerParameters.capability_band (by default the robot's, its
    description's tuning), which build_controller hands to each of them
    (their `band` argument).

    Attributes:
        lower: C_m^l >= 0 (m^3, like C_m); alpha = 1 at and below it.
        upper: C_m^u > C_m^l; alpha = 0 at and above it.

    The defaults are the paper's 0.035 and 0.04 (fixed-point experiment);
    see DEFAULT_JOINT_LIMIT_GAIN for what they mean on our arm.
    """

    lower: float = 0.035
    upper: float = 0.04

    def __post_init__(self):
        lower = non_negative("lower", self.lower)
        upper = as_scalar("upper", self.upper)
        if not lower < upper:
            raise ValueError(
                f"lower = {lower!r} and upper = {upper!r} are not allowed: "
                "the band's lower threshold C_m^l must be strictly below "
                "its upper threshold C_m^u"
            )


@dataclass
class ArmCapabilityParameters:
    """Parameters of the ArmCapability stage: C_m, grad_x C_m and alpha.

    The limitation band of alpha, eq. (transition), is the stage's `band`
    argument (one CapabilityBand for every stage that looks at C_m).

    Attributes:
        joint_limit_gain: k_j > 0 of the joint-limit penalization P_jnt;
            None (the default): the robot's, its description's tuning
            (drake_wbc.robot.description.RobotTuning; the paper's
            DEFAULT_JOINT_LIMIT_GAIN where it gives none), filled in when
            the stage is built.
        gradient_damping: lambda_max >= 0 of `capability_gradient`.
        gradient_damping_threshold: eps > 0 of the same.
    """

    joint_limit_gain: float | None = None
    gradient_damping: float = DEFAULT_MAX_DAMPING
    gradient_damping_threshold: float = DEFAULT_DAMPING_THRESHOLD

    def __post_init__(self):
        if self.joint_limit_gain is not None:
            positive("joint_limit_gain", self.joint_limit_gain)
        non_negative("gradient_damping", self.gradient_damping)
        positive("gradient_damping_threshold",
                 self.gradient_damping_threshold)


# ----------------------------------------------------------------------------
# Scalar-generic helpers of the reference bodies
# ----------------------------------------------------------------------------

def _expm1(x):
    """e^x - 1, accurate for small |x|, for a float or AutoDiffXd x."""
    if isinstance(x, AutoDiffXd):
        return AutoDiffXd(math.expm1(x.value()),
                          math.exp(x.value()) * x.derivatives())
    return math.expm1(x)


def _through_floats(count):
    """Lets a float-only body (one that takes an SVD) take AutoDiffXd in its
    first `count` arguments: their entries are stacked into one vector for
    scalar_support.through_float_function, so that the value is the float
    body's and the derivative comes from central differences of it."""

    def decorate(body):
        @functools.wraps(body)
        def generic(*args):
            arrays, others = args[:count], args[count:]
            if not any(is_autodiff(a) for a in arrays):
                return body(*args)
            shapes = [np.shape(a) for a in arrays]
            ends = np.cumsum([int(np.prod(s)) for s in shapes])[:-1]

            def on_floats(x):
                parts = [p.reshape(s) for p, s in zip(
                    np.split(x, ends), shapes, strict=True)]
                return np.asarray(body(*parts, *others), dtype=float)

            stacked = np.array([
                v if isinstance(v, AutoDiffXd) else AutoDiffXd(float(v))
                for a in arrays for v in np.ravel(np.asarray(a, object))],
                dtype=object)
            result = through_float_function(on_floats, stacked)
            return result[()] if np.ndim(result) == 0 else result

        return generic

    return decorate


def _others_as_written(values):
    """p_k = prod_{l != k} values_l, from its definition."""
    values = np.asarray(values)
    return np.array([np.prod(np.delete(values, k))
                     for k in range(values.size)])


# ----------------------------------------------------------------------------
# Reference bodies: scalar-generic, arguments not checked
# ----------------------------------------------------------------------------

@_through_floats(1)
def _manipulability(J):
    """m = sqrt(det(J_a J_a^T)) = prod_i s_i (Sec. IV-A): the product of the
    singular values s_i of J_a, which stays accurate near a singularity
    where det(J_a J_a^T) loses all its digits; NaN for a J_a that is not
    finite (see `_finite_jacobian`)."""
    if not _finite_jacobian(J):
        return math.nan
    return np.prod(np.linalg.svd(J, compute_uv=False))


def _finite_jacobian(J):
    """Whether the float J_a is finite: the bodies that take its SVD test
    this first, since numpy refuses the SVD of a NaN and never ends that
    of an infinity; theirs is NaN then."""
    return bool(np.isfinite(J).all())


@compiled
def _zero_singular_value(shape, s_max):
    """The largest singular value of a J_a of `shape` whose largest is
    s_max that counts as zero: max(shape) eps s_max, numpy's rank
    tolerance. A singular value that is zero in exact arithmetic comes
    out of the SVD as rounding, 1e-17 or so, whose inverse the
    pseudo-inverse must not take."""
    return max(shape[0], shape[1]) * 2.220446049250313e-16 * s_max


def _limit_factors(q, lower, upper):
    """The factors f_i = (q_i - l_i)(u_i - q_i) / (u_i - l_i)^2 of P_jnt and
    their slopes df_i/dq_i, with each joint clamped to its limits; a
    continuous joint's (l_i = -inf, u_i = inf) are their limits as the
    range grows about q_i, f_i = 1/4 and 0: it is never nearer a limit
    than at mid-range. A joint with finite limits is limited however
    wide its range: each distance is divided by the span before the two
    are multiplied, so that a range whose square overflows (-1e200,
    1e200) still gives its f_i, 1/4 at mid-range."""
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    q = np.clip(np.asarray(q), lower, upper)
    span = upper - lower
    limited = ~unlimited(lower, upper)
    if limited.all():
        return (((q - lower) / span) * ((upper - q) / span),
                ((upper + lower - 2.0 * q) / span) / span)
    zero = q * 0.0
    finite = np.where(limited, span, 1.0)
    low, high = np.where(limited, lower, -1.0), np.where(limited, upper, 1.0)
    return (np.where(limited, ((q - low) / finite) * ((high - q) / finite),
                     zero + 0.25),
            np.where(limited, ((high + low - 2.0 * q) / finite) / finite,
                     zero))


def _joint_limit_penalty(q, lower, upper, k_j):
    """P_jnt = 1 - exp(-k_j prod_i f_i) (Sec. IV-A, "penalization"), with
    each joint clamped to its limits."""
    factors, _ = _limit_factors(q, lower, upper)
    return -_expm1(-k_j * np.prod(factors))


def _joint_limit_penalty_gradient(q, lower, upper, k_j):
    """dP_jnt/dq_i = k_j exp(-k_j F) f_i' prod_{j != i} f_j, F = prod f_j, at
    the clamped configuration."""
    factors, slopes = _limit_factors(q, lower, upper)
    return (k_j * np.exp(-k_j * np.prod(factors))) * slopes * (
        _others_as_written(factors))


def _capability(J, q, lower, upper, k_j):
    """C_m = m * P_jnt (Sec. IV-A, the equation before eq. (wbccm))."""
    return _manipulability(J) * _joint_limit_penalty(q, lower, upper, k_j)


def _jacobian_derivative(J):
    """(n, 6, n) D with D[i] = dJ_a/dq_i (see `jacobian_derivative`)."""
    Jv, Jw = J[:3].T, J[3:].T  # (n, 3): row j is column j of J_a
    # [:, i, j] = Jw_i x Jv_j and Jw_i x Jw_j (vector first).
    w_x_v = cross(Jw.T[:, :, None], Jv.T[:, None, :])
    w_x_w = cross(Jw.T[:, :, None], Jw.T[:, None, :])
    upper = np.triu(np.ones((J.shape[1],) * 2, dtype=bool))
    dJv = np.where(upper, w_x_v, np.swapaxes(w_x_v, 1, 2))
    dJw = np.where(upper, w_x_w, 0.0)
    return np.concatenate([dJv, dJw], axis=0).transpose(1, 0, 2)


@_through_floats(1)
def _manipulability_joint_gradient(J):
    """dm/dq_i = sum_k (prod_{l != k} s_l) u_k^T (dJ_a/dq_i) v_k (see
    `manipulability_joint_gradient`)."""
    if not _finite_jacobian(J):
        return np.full(J.shape[1], math.nan)
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    W = (U * _others_as_written(s)) @ Vt  # m J_a^+T, without division
    return np.einsum("rc,irc->i", W, _jacobian_derivative(J))


def _capability_joint_gradient(J, q, lower, upper, k_j):
    """dC_m/dq = P_jnt dm/dq + m dP_jnt/dq."""
    return (_joint_limit_penalty(q, lower, upper, k_j)
            * _manipulability_joint_gradient(J)
            + _manipulability(J)
            * _joint_limit_penalty_gradient(q, lower, upper, k_j))


@_through_floats(2)
def _capability_gradient(J, q, lower, upper, k_j, damping,
                         damping_threshold):
    """grad_x C_m = (J_a J_a^T + lambda^2 I)^-1 J_a dC_m/dq through the SVD
    of J_a, lambda^2 = lambda_max^2 (1 - (s_min / eps)^2) below eps, else 0
    (see `capability_gradient`)."""
    if not _finite_jacobian(J):
        return np.full(J.shape[0], math.nan)
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    # damping * damping, not damping**2: a Python float's power raises
    # OverflowError where the product is inf (the kernel's, and gains 0).
    lambda2 = (damping * damping * (1.0 - (s[-1] / damping_threshold) ** 2)
               if s[-1] < damping_threshold else 0.0)
    gains = np.divide(s, s * s + lambda2, out=np.zeros_like(s),
                      where=s > _zero_singular_value(J.shape, s[0]))
    return U @ (gains * (Vt @ _capability_joint_gradient(J, q, lower, upper,
                                                         k_j)))


def capability_terms(J_a, q, lower, upper, k_j, damping,
                               damping_threshold):
    """C_m and grad_x C_m together (Sec. IV-A; eqs. (wbccm), (wb_error)):
    the reference body of what the ArmCapability stage gives each tick.

    The same values as `capability` and `capability_gradient`, for
    arguments already checked (nothing is checked here): J_a (6, n) with
    n >= 6, q, lower and upper (n,) (arrays or sequences) with
    lower < upper, k_j > 0, damping >= 0 and damping_threshold > 0. J_a and
    q may hold AutoDiffXd (see the module: the SVD goes through
    scalar_support.through_float_function). The float kernel
    `capability_terms_float` gives the same from one SVD.

    Returns:
        (C_m, g): C_m and g = grad_x C_m (6,).
    """
    return (_capability(J_a, q, lower, upper, k_j),
            _capability_gradient(J_a, q, lower, upper, k_j, damping,
                                 damping_threshold))


def transition_of(value, upper, lower):
    """alpha(C_m, C_m^u, C_m^l) of eq. (transition), the reference body:

        alpha = 1                                 for value <= lower,
        alpha = 0.5 (1 + cos(pi x)),
                x = (value - lower) / (upper - lower)  in between,
        alpha = 0                                 for value >= upper.

    Args:
        value: a float or AutoDiffXd scalar (C_m, or d and phi for the
            penalties of the local workspace, Sec. IV-C).
        upper, lower: floats, lower < upper (not checked; `transition`
            checks them).

    Returns:
        alpha in [0, 1], of the scalar type of `value`.
    """
    if value <= lower:
        return _constant(value, 1.0)
    if value >= upper:
        return _constant(value, 0.0)
    return 0.5 * (1.0 + np.cos(np.pi * (value - lower) / (upper - lower)))


def _constant(value, constant):
    """`constant` of the scalar type of `value`, without derivative:
    value * 0 + constant (the zero's sign kept) for a finite value, and
    for an infinite one, where value * 0 is NaN, the exact constant
    (scalar_support.constant_like)."""
    zero = zero_like(value)
    if zero != zero:
        return constant_like(value, constant)
    return zero + constant if constant else zero


def transition_derivative_of(value, upper, lower):
    """d alpha / d value of eq. (transition), the reference body:
    -0.5 pi / (upper - lower) sin(pi x) inside the band, 0 outside, with x
    as in `transition_of` (the same arguments)."""
    if value <= lower or value >= upper:
        return _constant(value, 0.0)
    width = upper - lower
    return -0.5 * np.pi / width * np.sin(np.pi * (value - lower) / width)


# ----------------------------------------------------------------------------
# The checked public functions
# ----------------------------------------------------------------------------

def _as_jacobian(J_a, rows=None, wide=True):
    """Returns J_a as a finite float matrix with `rows` rows (any number if
    None) and, if `wide`, at least as many columns as rows."""
    J = as_matrix("J_a", J_a, (rows, None))
    if J.size == 0 or (wide and J.shape[0] > J.shape[1]):
        raise ValueError(
            f"J_a has shape {J.shape}, which is not allowed: must be "
            "non-empty" + (" with at least as many columns as rows"
                           if wide else "")
        )
    return J


def _as_limits(q, lower, upper, size=None):
    """Returns q, lower, upper, checked float vectors of one size."""
    q = as_vector("q", q, size)
    lower, upper = ordered_limits("lower", lower, "upper", upper, q.size,
                                  unlimited=True)
    return q, lower, upper


def manipulability(J_a):
    """Yoshikawa's manipulability index m (Sec. IV-A, "manipulability
    index"): m = sqrt(det(J_a J_a^T)) = prod_i s_i.

    Computed as the product of the singular values s_i of J_a, which stays
    accurate near a singularity where det(J_a J_a^T) loses all its digits.

    Args:
        J_a: (k, n) matrix with k <= n; for the arm the (6, n) geometric
            Jacobian [v; w] of the tool point in T_a.

    Returns:
        m >= 0 as a float, in metres^3 for the arm's Jacobian (three rows
        in m/rad); 0, to rounding, only at a singularity.
    """
    return float(_manipulability(_as_jacobian(J_a)))


def joint_limit_penalty(q, lower, upper, k_j=DEFAULT_JOINT_LIMIT_GAIN):
    """Joint-limit penalization P_jnt (Sec. IV-A, "penalization"):

        P_jnt = 1 - exp(-k_j prod_i (q_i - l_i)(u_i - q_i) / (u_i - l_i)^2).

    P_jnt is 0 when any joint is at a limit and largest, 1 - exp(-k_j 4^-n),
    when every joint is mid-range (see `DEFAULT_JOINT_LIMIT_GAIN`). A joint
    beyond a limit (a simulated joint can overshoot by a hair) is clamped to
    that limit, so that P_jnt = 0 there rather than a meaningless value.
    A continuous joint (q^l = -inf, q^u = inf) is never near a limit: its
    factor is 1/4 at every angle, the limit of the factor as its range
    grows, and it does not turn P_jnt.

    Args:
        q: (n,) joint angles q_a, rad.
        lower: (n,) lower joint limits q^l, rad (-inf: a continuous joint).
        upper: (n,) upper joint limits q^u, rad, each > its lower limit
            (inf where the lower is -inf, and only there).
        k_j: scaling factor k_j > 0, dimensionless.

    Returns:
        P_jnt in [0, 1), dimensionless, as a float.
    """
    q, lower, upper = _as_limits(q, lower, upper)
    return float(_joint_limit_penalty(q, lower, upper, positive("k_j", k_j)))


def capability(J_a, q, lower, upper, k_j=DEFAULT_JOINT_LIMIT_GAIN):
    """Capability of movement C_m = m * P_jnt (Sec. IV-A, the equation
    before eq. (wbccm)).

    Args:
        J_a: (6, n) geometric Jacobian [v; w] of the tool point in T_a at q.
        q: (n,) joint angles q_a, rad.
        lower, upper: (n,) joint limits, rad (see `joint_limit_penalty`).
        k_j: scaling factor k_j > 0 of P_jnt.

    Returns:
        C_m >= 0 as a float, in the units of m (metres^3 for the arm).
    """
    J = _as_jacobian(J_a, rows=6)
    q, lower, upper = _as_limits(q, lower, upper, J.shape[1])
    return float(_capability(J, q, lower, upper, positive("k_j", k_j)))


def jacobian_derivative(J_a):
    """Partial derivatives dJ_a/dq_i of a revolute chain's geometric
    Jacobian, from J_a alone.

    Column j of J_a is [z_j x (p - p_j); z_j]: z_j the unit axis of joint
    j, p_j a point on it, p the tool point, all in the fixed frame T_a.
    Turning joint i moves the links after it rigidly about axis i: a vector r
    on them changes as dr/dq_i = z_i x r, the tool point as dp/dq_i = Jv_i.
    With J_j = [Jv_j; Jw_j]:

    - i <= j: z_j and p - p_j ride on the moving links, and by the Jacobi
      identity dJv_j/dq_i = z_i x Jv_j = Jw_i x Jv_j, dJw_j/dq_i =
      Jw_i x Jw_j;
    - i > j: z_j and p_j stay, only p moves: dJv_j/dq_i = Jw_j x Jv_i,
      dJw_j/dq_i = 0.

    Args:
        J_a: (6, n) geometric Jacobian [v; w] of the tool point in the fixed
            frame T_a, all joints revolute; m/rad and rad/rad.

    Returns:
        (n, 6, n) array D with D[i] = dJ_a/dq_i, per rad.
    """
    return _jacobian_derivative(_as_jacobian(J_a, rows=6, wide=False))


def manipulability_joint_gradient(J_a):
    """Gradient dm/dq of the manipulability index, analytic from J_a.

    Derivation: m^2 = det(J J^T), so 2 m dm = m^2 tr((J J^T)^-1 d(J J^T))
    = 2 m^2 tr((J J^T)^-1 J dJ^T), hence dm = m tr(J^+ dJ) with
    J^+ = J^T (J J^T)^-1. With the thin SVD J = U diag(s) V^T,
    m J^+ = V diag(m / s_k) U^T and m / s_k = prod_{l != k} s_l, so

        dm/dq_i = sum_k (prod_{l != k} s_l) u_k^T (dJ/dq_i) v_k,

    with dJ/dq_i from `jacobian_derivative`. This form has no division and
    stays finite as m -> 0. Where m > 0 it is the exact gradient. At an
    exact singularity m has no gradient: with one zero singular value m
    behaves like |linear| and the value returned is one of its one-sided
    gradients, each an ascent direction out of the singularity (two of
    them for n = 6, a circle of them for n = 7, as many as the unit
    vectors of J_a's null space that the SVD may give as v_k): which one
    depends on the SVD's LAPACK, not on this body (numpy's and the
    compiled kernel's may differ); with two or more zero singular values
    m vanishes to second order and the exact gradient, 0, is returned.

    Args:
        J_a: (6, n) geometric Jacobian [v; w] of the tool point in T_a,
            n >= 6, all joints revolute.

    Returns:
        (n,) array dm/dq, in units of m (metres^3) per rad.
    """
    return _manipulability_joint_gradient(_as_jacobian(J_a, rows=6))


def joint_limit_penalty_gradient(q, lower, upper,
                                 k_j=DEFAULT_JOINT_LIMIT_GAIN):
    """Gradient dP_jnt/dq of the penalization of `joint_limit_penalty`.

    With f_i = (q_i - l_i)(u_i - q_i) / (u_i - l_i)^2 and F = prod_i f_i:

        dP_jnt/dq_i = k_j exp(-k_j F) (u_i + l_i - 2 q_i) / (u_i - l_i)^2
                      * prod_{j != i} f_j,

    the product of the other factors computed directly (not F / f_i), so
    that it stays right with a joint at a limit (f_i = 0): there the
    component of that joint points back into the range and the others are
    0. A joint beyond a limit is clamped to it as in `joint_limit_penalty`,
    and the gradient is the one at the clamped configuration.

    Args:
        q, lower, upper, k_j: as for `joint_limit_penalty`.

    Returns:
        (n,) array dP_jnt/dq, per rad.
    """
    q, lower, upper = _as_limits(q, lower, upper)
    return _joint_limit_penalty_gradient(q, lower, upper,
                                         positive("k_j", k_j))


def capability_joint_gradient(J_a, q, lower, upper,
                              k_j=DEFAULT_JOINT_LIMIT_GAIN):
    """Gradient dC_m/dq = P_jnt dm/dq + m dP_jnt/dq of C_m = m * P_jnt.

    See `manipulability_joint_gradient` for the value at an exact
    singularity and `joint_limit_penalty_gradient` for joints at or beyond
    a limit.

    Args:
        J_a: (6, n) geometric Jacobian [v; w] of the tool point in T_a at q,
            n >= 6, all joints revolute.
        q, lower, upper, k_j: as for `joint_limit_penalty`.

    Returns:
        (n,) array dC_m/dq, in units of C_m per rad.
    """
    J = _as_jacobian(J_a, rows=6)
    q, lower, upper = _as_limits(q, lower, upper, J.shape[1])
    return _capability_joint_gradient(J, q, lower, upper,
                                      positive("k_j", k_j))


def capability_gradient(J_a, q, lower, upper, k_j=DEFAULT_JOINT_LIMIT_GAIN,
                        damping=DEFAULT_MAX_DAMPING,
                        damping_threshold=DEFAULT_DAMPING_THRESHOLD):
    """Gradient grad_x C_m of C_m w.r.t. the arm's Cartesian pose, as used
    in eq. (wbccm) and eq. (wb_error).

    Definition: the covector g such that dC_m/dt = g . V_a for every arm
    twist V_a = [v_a; w_a] = J_a qdot (in T_a, at the tool point), i.e.
    J_a^T g = dC_m/dq, so g = J_a^-T dC_m/dq for a square nonsingular J_a.
    It is analytic, from J_a alone (see `capability_joint_gradient`); no
    AutoDiff.

    It is solved as g = (J_a J_a^T + lambda^2 I)^-1 J_a dC_m/dq, evaluated
    through the SVD of J_a. lambda = 0 (the exact J_a^-T, or the
    least-squares solution if n > 6) unless the smallest singular value
    s_min is below the threshold eps, where
    lambda^2 = lambda_max^2 (1 - (s_min / eps)^2) grows continuously from 0.
    This damping is the only approximation. A zero singular value gets
    gain 0 (the pseudo-inverse), zero to rounding: at most max(6, n) times
    the machine epsilon times the largest (an exact singularity's comes
    out of the SVD as 1e-17 or so, whose inverse gave gradients of 1e12
    with lambda = 0).

    Args:
        J_a: (6, n) geometric Jacobian [v; w] of the tool point in T_a at q,
            n >= 6, all joints revolute.
        q, lower, upper, k_j: as for `joint_limit_penalty`.
        damping: lambda_max >= 0, in the units of the singular values of
            J_a; 0 turns damping off. Default `DEFAULT_MAX_DAMPING`.
        damping_threshold: eps > 0. Default `DEFAULT_DAMPING_THRESHOLD`.

    Returns:
        (6,) array g = [g_v; g_w]: C_m per m along v_a, C_m per rad along
        w_a.
    """
    J = _as_jacobian(J_a, rows=6)
    q, lower, upper = _as_limits(q, lower, upper, J.shape[1])
    return _capability_gradient(
        J, q, lower, upper, positive("k_j", k_j),
        non_negative("damping", damping),
        positive("damping_threshold", damping_threshold))


def _as_values(value):
    """Returns (value as float or float array, whether it was a scalar)."""
    try:
        shape = np.shape(value)
    except ValueError:
        raise ValueError(
            f"value = {value!r} is not allowed: must be a number or an "
            "array of numbers"
        ) from None
    if shape == ():
        return as_scalar("value", value), True
    return as_vector("value", np.ravel(value)).reshape(shape), False


def _elementwise(body, value, upper, lower):
    """body(value, upper, lower) of checked arguments, as a float for a
    scalar `value` and elementwise for an array."""
    values, scalar = _as_values(value)
    lower, upper = ordered_limits("lower", lower, "upper", upper, 1)
    lower, upper = float(lower[0]), float(upper[0])
    if scalar:
        return float(body(values, upper, lower))
    return np.array([body(v, upper, lower) for v in values.ravel()],
                    dtype=float).reshape(values.shape)


def transition(value, upper, lower):
    """Transition function alpha(C_m, C_m^u, C_m^l) of eq. (transition):

        alpha = 0                                   for value >= upper,
        alpha = 0.5 (1 + cos(pi x)),
                x = (value - lower) / (upper - lower)  in between,
        alpha = 1                                   for value <= lower.

    alpha is continuous with a continuous derivative (0 at both band edges)
    and non-increasing in `value`. The checked form of
    `transition_of` (which also takes AutoDiffXd).

    Args:
        value: C_m, a number or an array of numbers (elementwise).
        upper: upper threshold C_m^u.
        lower: lower threshold C_m^l, < upper.

    Returns:
        alpha in [0, 1], dimensionless: a float for a scalar `value`, else
        an array of the shape of `value`.
    """
    return _elementwise(transition_of, value, upper, lower)


def transition_derivative(value, upper, lower):
    """Derivative d alpha / d value of eq. (transition):

        -0.5 pi / (upper - lower) * sin(pi x)  inside the band, else 0,

    with x as in `transition`. It vanishes at both band edges, so alpha is
    C^1 across them. The checked form of `transition_derivative_of`.

    Args:
        value, upper, lower: as for `transition`.

    Returns:
        d alpha / d value <= 0, in 1 / (units of value): a float for a
        scalar `value`, else an array of the shape of `value`.
    """
    return _elementwise(transition_derivative_of, value, upper, lower)


# ----------------------------------------------------------------------------
# The float kernels of the tick
# ----------------------------------------------------------------------------

@compiled
def _products_of_others(values):
    """p with p_k = prod_{l != k} values_l, computed without any division
    (the product of the values before k times that of the values after
    k), so that it stays exact when some values are 0."""
    n = values.size
    products = np.ones(n)
    before = 1.0
    for k in range(1, n):  # first the product of the values before k
        before *= values[k - 1]
        products[k] = before
    after = 1.0
    for k in range(n - 2, -1, -1):  # times that of the values after k
        after *= values[k + 1]
        products[k] *= after
    return products


@compiled
def _penalty_and_gradient(q, lower, upper, k_j):
    """P_jnt and dP_jnt/dq (n,), each joint clamped to its limits."""
    n = q.size
    factors, slopes = np.empty(n), np.empty(n)
    product = 1.0
    for i in range(n):
        q_i, l_i, u_i = q[i], lower[i], upper[i]
        if q_i < l_i:
            q_i = l_i
        elif q_i > u_i:
            q_i = u_i
        span = u_i - l_i
        if math.isinf(l_i):  # a continuous joint (-inf, inf): mid-range
            # (0 q_i: a NaN or infinite angle gives NaN, as the reference)
            factors[i], slopes[i] = 0.25 + 0.0 * q_i, 0.0 * q_i
        else:  # as _limit_factors: no product of two distances
            factors[i] = ((q_i - l_i) / span) * ((u_i - q_i) / span)
            slopes[i] = ((u_i + l_i - 2.0 * q_i) / span) / span
        product *= factors[i]
    penalty = -math.expm1(-k_j * product)
    scale = k_j * math.exp(-k_j * product)
    others = _products_of_others(factors)
    gradient = np.empty(n)
    for i in range(n):
        gradient[i] = scale * slopes[i] * others[i]
    return penalty, gradient


@compiled
def _manipulability_gradient(J, U, s, Vt):
    """dm/dq (n,) from J and its thin SVD J = U diag(s) Vt.

    With W = U diag(m / s_k) Vt (6, n), dm/dq_i = sum_j W_j . dJ_j/dq_i
    over the columns j, and by the rules of `jacobian_derivative` and the
    triple product a . (b x c) = b . (c x a) = c . (a x b):

        dm/dq_i = Jw_i . a_i + Jv_i . b_i,
        a_i = sum_{j >= i} (Jv_j x Wv_j + Jw_j x Ww_j),
        b_i = sum_{j < i} (Wv_j x Jw_j),

    O(n) with running sums, without forming the (n, 6, n) derivative.
    """
    others = _products_of_others(s)  # m / s_k, with no division
    rows, n = J.shape
    k = s.size
    W = np.zeros((rows, n))
    for r in range(rows):
        for c in range(n):
            total = 0.0
            for i in range(k):
                total += (U[r, i] * others[i]) * Vt[i, c]
            W[r, c] = total
    a = np.empty((n, 3))
    ax = ay = az = 0.0
    for j in range(n - 1, -1, -1):  # a_j, summed from the last column
        vx, vy, vz, wx, wy, wz = J[0, j], J[1, j], J[2, j], J[3, j], \
            J[4, j], J[5, j]
        Vx, Vy, Vz, Wx, Wy, Wz = W[0, j], W[1, j], W[2, j], W[3, j], \
            W[4, j], W[5, j]
        ax += (vy * Vz - vz * Vy) + (wy * Wz - wz * Wy)
        ay += (vz * Vx - vx * Vz) + (wz * Wx - wx * Wz)
        az += (vx * Vy - vy * Vx) + (wx * Wy - wy * Wx)
        a[j, 0], a[j, 1], a[j, 2] = ax, ay, az
    gradient = np.empty(n)
    bx = by = bz = 0.0
    for i in range(n):  # b_i, summed from the first column
        wx, wy, wz = J[3, i], J[4, i], J[5, i]
        vx, vy, vz = J[0, i], J[1, i], J[2, i]
        gradient[i] = ((wx * a[i, 0] + vx * bx) + (wy * a[i, 1] + vy * by)
                       + (wz * a[i, 2] + vz * bz))
        Vx, Vy, Vz = W[0, i], W[1, i], W[2, i]
        bx += Vy * wz - Vz * wy
        by += Vz * wx - Vx * wz
        bz += Vx * wy - Vy * wx
    return gradient


@compiled
def _capability_terms(J, q, lower, upper, k_j, damping, damping_threshold):
    """The compiled body of `capability_terms_float`: NaN for a J that is
    not finite (which numba's SVD refuses)."""
    for r in range(J.shape[0]):
        for c in range(J.shape[1]):
            if not math.isfinite(J[r, c]):
                return np.nan, np.full(J.shape[0], np.nan)
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    m = 1.0
    for s_k in s:
        m *= s_k
    penalty, penalty_gradient = _penalty_and_gradient(q, lower, upper, k_j)
    manipulability_gradient = _manipulability_gradient(J, U, s, Vt)
    n = q.size
    joint_gradient = np.empty(n)
    for i in range(n):
        joint_gradient[i] = (penalty * manipulability_gradient[i]
                             + m * penalty_gradient[i])
    # g = U diag(s_k / (s_k^2 + lambda^2)) Vt dC_m/dq (0 for a zero s_k).
    s_min = s[-1]
    lambda2 = (damping**2 * (1.0 - (s_min / damping_threshold) ** 2)
               if s_min < damping_threshold else 0.0)
    k = s.size
    zero = _zero_singular_value(J.shape, s[0])
    projected = np.empty(k)
    for i in range(k):
        gain = s[i] / (s[i] * s[i] + lambda2) if s[i] > zero else 0.0
        total = 0.0
        for c in range(n):
            total += Vt[i, c] * joint_gradient[c]
        projected[i] = gain * total
    g = np.empty(6)
    for r in range(6):
        total = 0.0
        for i in range(k):
            total += U[r, i] * projected[i]
        g[r] = total
    return m * penalty, g


def _capability_terms_sample(rng):
    """Random arguments of `capability_terms`: J_a from chosen
    singular values (well conditioned, near-singular and singular, the
    damping on and off), n = 6 or 7, joints inside their range, at a
    limit, beyond one, two at limits; in one case in twenty an entry of
    J_a NaN or infinite, in one in five some joints continuous (limits
    -inf and inf, at any angle); float64 arrays, as the stage passes
    them."""
    n = 6 if rng.uniform() < 0.75 else 7
    U, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    V, _ = np.linalg.qr(rng.normal(size=(n, n)))
    s = np.sort(rng.uniform(0.05, 1.5, 6))[::-1]
    eps = rng.uniform(0.01, 0.2)
    damping = 0.0 if rng.uniform() < 0.2 else rng.uniform(0.005, 0.05)
    kind = rng.integers(4)
    if damping > 0.0 and kind == 1:
        s[-1] = rng.uniform(0.0, eps)  # near a singularity: damped
    elif damping > 0.0 and kind == 2:
        # At a singularity: two zero singular values, where m vanishes to
        # second order and its gradient is 0, or one 1e-3 from zero (at
        # zero exactly the gradient has no side, and which one an SVD
        # gives depends on its LAPACK: tests/test_capability.py; nearer
        # than about 1e-4, v_k of a seven-joint arm is not defined to
        # 1e-12 either, its null space that near).
        two = rng.uniform() < 0.3
        s[-1] = 0.0 if two else 1e-3
        s[-2] *= 0.0 if two else 1.0
    J = (U * s) @ V[:6]
    lower = rng.uniform(-3.0, -0.5, n)
    upper = rng.uniform(0.5, 3.0, n)
    q = rng.uniform(lower + 0.05, upper - 0.05)
    j, k = rng.choice(n, size=2, replace=False)
    limits = rng.integers(4)
    if limits == 1:
        q[j] = lower[j] if rng.uniform() < 0.5 else upper[j]
    elif limits == 2:
        q[j] = lower[j] - 0.02 if rng.uniform() < 0.5 else upper[j] + 0.02
    elif limits == 3:
        q[j], q[k] = lower[j], upper[k]
    k_j = rng.uniform(5e3, 3e4) * 4.0 ** (n - 6)
    if rng.uniform() < 0.05:
        J[rng.integers(6), rng.integers(n)] = rng.choice(
            [np.nan, np.inf, -np.inf])
    if rng.uniform() < 0.2:  # continuous joints, without position limits
        free = rng.choice(n, size=rng.integers(1, n + 1), replace=False)
        lower[free], upper[free] = -np.inf, np.inf
        q[free] = rng.uniform(-10.0, 10.0, free.size)
    return J, q, lower, upper, k_j, damping, eps


@fast_kernel(capability_terms, sample=_capability_terms_sample)
def capability_terms_float(J_a, q, lower, upper, k_j, damping,
                           damping_threshold):
    """`capability_terms` in machine code (drake_wbc.math.compiled), from
    one SVD of J_a: the per-tick path of the ArmCapability stage. J_a
    (6, n), q, lower and upper (n,) float64 C-contiguous arrays, the
    rest floats.

    Returns:
        (C_m, g): C_m as a float and g = grad_x C_m (6,).
    """
    C_m, g = _capability_terms(J_a, q, lower, upper, float(k_j),
                               float(damping), float(damping_threshold))
    return float(C_m), g


def _transition_sample(rng):
    """(value, upper, lower): a band of any width at any place (C_m's, or a
    workspace's d and phi), the value inside it, on either edge or beyond
    either, or NaN or infinite."""
    lower = rng.uniform(0.0, 1.0) if rng.uniform() < 0.8 else 0.0
    upper = lower + 10.0 ** rng.uniform(-4.0, 0.0)
    kind = rng.integers(6)
    if kind == 0:
        value = lower
    elif kind == 1:
        value = upper
    elif kind == 2:
        value = lower - rng.uniform(0.0, 1.0)
    elif kind == 3:
        value = upper + rng.uniform(0.0, 1.0)
    elif kind == 4:
        value = rng.uniform(lower, upper)
    else:
        value = float(rng.choice([np.nan, np.inf, -np.inf]))
    return value, upper, lower


@fast_kernel(transition_of, sample=_transition_sample)
def transition_float(value, upper, lower):
    """`transition_of` for a float value, in plain floats: the
    per-tick path of the stages that read alpha."""
    if value <= lower:
        return 1.0
    if value >= upper:
        return 0.0
    return 0.5 * (1.0 + math.cos(math.pi * (value - lower) / (upper - lower)))


@fast_kernel(transition_derivative_of, sample=_transition_sample)
def transition_derivative_float(value, upper, lower):
    """`transition_derivative_of` for a float value, in plain
    floats."""
    if value <= lower or value >= upper:
        return 0.0
    width = upper - lower
    return -0.5 * math.pi / width * math.sin(math.pi * (value - lower)
                                              / width)

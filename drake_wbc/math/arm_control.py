"""The arm's Cartesian velocity controller, as plain math (Sec. III-A).

The paper commands the arm with a Cartesian twist V_a = [v_a; w_a] in T_a
and leaves its execution to a Jacobian-based controller with singularity
robustness: V_a -> (inverse kinematics) -> q_dot_a -> (integration) -> q_a,
the joint positions that the arm's stiff position servo follows. One step of
the first arrow is `joint_velocity_for_twist`, in four stages:

1. Damped least squares (singularity robustness):

       q_dot = J_a^T (J_a J_a^T + lambda^2 I)^-1 V_a
             = sum_k s_k / (s_k^2 + lambda^2) v_k u_k^T V_a,

   with J_a = sum_k s_k u_k v_k^T its SVD. lambda is 0 away from
   singularities (the exact J_a^-1 V_a) and grows smoothly as the smallest
   singular value s_min falls below a threshold eps (see
   `singularity_damping`).
2. Joint limits, joint by joint: no joint is commanded past
   [lower + margin, upper - margin] within the next step (q + q_dot h stays
   inside), and with an acceleration limit a joint approaching the band's
   edge is slowed early enough to stop at it without exceeding that limit
   (see `joint_position_velocity_bounds`). A continuous joint (limits
   -inf and inf) has no edge: only its speed and acceleration limits
   hold it, and a redundant arm's self-motion does not centre it.
3. Velocity limits by uniform scaling of the whole q_dot, so that the
   end effector keeps its direction of motion and only slows down.
4. Optionally an acceleration limit: the change from the previous q_dot is
   scaled uniformly so that no joint changes its rate by more than a h.
   Stage 2's bounds are applied once more at the end, so that the position
   limits always hold.

Units: J_a is the (6, n) geometric Jacobian [v; w] of the end effector in
T_a (m/rad and rad/rad per column), V_a is in m/s and rad/s, joint angles
in rad, rates in rad/s, accelerations in rad/s^2, time_step in s. The
singular values of J_a mix both units; for the shipped arm with its tool
they lie between about 0.15 and 2 at the home pose and fall to 0 only at
a singularity (see `DEFAULT_DAMPING_THRESHOLD`).

Here: the parameters and their checks; the limits of one controller,
checked once (`TwistLimits`); the reference body of the controller,
`joint_velocity_command`, for any scalar type (float, and AutoDiffXd for
the stage's linearisation), with its parts (`damping_rule`,
`damped_solve`, `joint_position_bounds`, with the braking rate of
drake_wbc.math.arm_servo.braking_rate); the checked
functions a user calls (`joint_velocity_for_twist` and its parts); and the
float kernel of the control tick, `joint_velocity_command_float`
(drake_wbc.math.kernels), which the Drake system
(drake_wbc.stages.ArmCartesianVelocityController) runs in double.
"""

import functools
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from drake_wbc.math import kernels
from drake_wbc.math.arm_servo import braking_rate
from drake_wbc.math.command_limits import uniform_scale
from drake_wbc.math.compiled import compiled
from drake_wbc.math.safety import beyond_limits
from drake_wbc.math.scalar_support import solve, value_of
from drake_wbc.math.validation import (
    as_matrix,
    as_vector,
    non_negative,
    ordered_limits,
    positive,
    positive_vector,
)

DEFAULT_DAMPING_THRESHOLD = 0.05
"""Default threshold eps on the smallest singular value s_min of J_a below
which `joint_velocity_for_twist` damps its solve.

Why 0.05 on the shipped arm with its tool: at the home pose
s_min = 0.147 and the median over the whole joint space is 0.089, so most
working poses are solved exactly (no damping, no tracking error). s_min
falls as about 0.31 d within d rad of the wrist singularity (q5 = 0) and
as about 0.16 d near the stretched elbow (q3 = 0): damping acts in the last
0.16 rad (9 degrees) before the wrist singularity and the last 0.3 rad
before the stretched elbow. With the default damping (lambda_max = eps) the
largest joint-rate gain of any direction is 1.07 / eps = 21 rad/s per unit
of twist, so a twist of up to 0.07 m/s (or rad/s) towards a singularity
still stays below the shipped arm's 1.57 rad/s, and larger ones are slowed
uniformly by the velocity limit rather than blowing up. A smaller
threshold (0.02) would let the gain reach 53 and the joint rates saturate
on every pass near a singularity; a larger one (0.1) would damp half of the
joint space and make the end effector lag its command there.
"""

DEFAULT_DAMPING = 0.05
"""Default largest damping lambda_max (at s_min = 0), in the units of the
singular values of J_a. Equal to eps: with lambda^2 = lambda_max^2
(1 - (s_min / eps)^2)^2 the gain s / (s^2 + lambda^2) of the weakest
direction rises from 0 at the singularity to at most 1.07 / eps (at
s_min = 0.88 eps) and meets the undamped 1 / s_min at s_min = eps, where
lambda^2 reaches 0 with zero slope."""

DEFAULT_JOINT_LIMIT_MARGIN = 0.05
"""Default margin (rad) kept between the command and each joint limit.

The position command never leaves [lower + margin, upper - margin]. 0.05
rad (2.9 degrees) is 0.8 to 1.1% of each of the shipped arm's ranges (4.7
to 6.28 rad), so it costs practically no workspace, yet it is larger than
what a stiff, well-damped position servo overshoots a command that brakes
to rest (a few percent of the following error, which is itself at most 1.57
rad/s times the arm's 0.02 to 0.05 s lag, 0.03 to 0.08 rad at full speed
and far less once braked), and it covers the tolerance of the arm's own
limit switches and of the published limits. The capability of movement (and
the compensation that gives way by it) keeps the arm much further away in
normal use, from 8 to 12% of a range; this margin is the last line."""

DEFAULT_SELF_MOTION_GAIN = 0.5
"""Default gain k_c of the joint centring in a redundant arm's
self-motion, 1/s: a joint at its limit is driven back at 0.5 rad/s, one
halfway out at 0.25 rad/s, within the null space of J_a (the end effector
does not feel it) and then within every limit like the rest of the
command. Slow against the task (a third of a typical 1.57 rad/s), so that
it uses the redundancy without competing with the tracking."""

@dataclass
class ArmControllerParameters:
    """Parameters of the arm's Cartesian velocity controller.

    Attributes:
        damping: largest damping lambda_max >= 0 of the least-squares
            solve; 0 turns damping off (then only the pseudo-inverse's
            zeroing of exactly zero singular values remains). Default
            `DEFAULT_DAMPING`.
        damping_threshold: eps > 0 on s_min below which damping acts.
            Default `DEFAULT_DAMPING_THRESHOLD`.
        margin: rad >= 0 kept between the command and each joint limit.
            Default `DEFAULT_JOINT_LIMIT_MARGIN`.
        use_acceleration_limit: whether to limit the change of q_dot from
            one step to the next.
        acceleration_limit: rad/s^2 > 0, the same on every joint, or None
            for the arm's own (ArmKinematics.acceleration_limits, joint
            by joint).
        lower, upper: (n,) joint limits in rad, or None for the arm's own
            (ArmKinematics.lower / .upper); -inf and inf for a continuous
            joint, which has none (the arm's own must be unlimited too).
        velocity_limits: (n,) rad/s > 0, or None for the arm's own.
        self_motion_gain: k_c >= 0, 1/s, of the joint centring in the
            self-motion of an arm of more than six joints (see
            `joint_velocity_command`); no effect on six. Default
            `DEFAULT_SELF_MOTION_GAIN`.

    The sizes are checked against the arm when the controller is built
    (drake_wbc.controller.parameters.check_arm_limits), where a limit
    beyond the arm's own is refused too.

    Vectors are given as any sequence (a list in YAML) and stored as
    tuples, so that parameters compare with ==. The control period is not
    a field: it is the controller's one time_step
    (ControllerParameters.time_step), the stage's `time_step` argument.
    """

    damping: float = DEFAULT_DAMPING
    damping_threshold: float = DEFAULT_DAMPING_THRESHOLD
    margin: float = DEFAULT_JOINT_LIMIT_MARGIN
    use_acceleration_limit: bool = True
    acceleration_limit: float | None = None
    self_motion_gain: float = DEFAULT_SELF_MOTION_GAIN
    lower: list[float] | None = None
    upper: list[float] | None = None
    velocity_limits: list[float] | None = None

    def __post_init__(self):
        non_negative("damping", self.damping)
        positive("damping_threshold", self.damping_threshold)
        non_negative("margin", self.margin)
        non_negative("self_motion_gain", self.self_motion_gain)
        if self.acceleration_limit is not None:
            positive("acceleration_limit", self.acceleration_limit)
        if not isinstance(self.use_acceleration_limit, bool):
            raise ValueError(
                f"use_acceleration_limit = {self.use_acceleration_limit!r} "
                "is not allowed: must be True or False"
            )
        if (self.lower is None) != (self.upper is None):
            raise ValueError(
                f"lower = {self.lower!r} and upper = {self.upper!r} are not "
                "allowed: give both limits or neither (None: the model's)"
            )
        if self.lower is not None:
            lower, upper = ordered_limits("lower", self.lower, "upper",
                                          self.upper, unlimited=True)
            check_margin(self.margin, lower, upper)
            self.lower = tuple(lower.tolist())
            self.upper = tuple(upper.tolist())
        if self.velocity_limits is not None:
            limits = positive_vector("velocity_limits",
                                     self.velocity_limits, None)
            self.velocity_limits = tuple(limits.tolist())


def _positive_vector(name, value, size):
    """Returns `value` as a vector of `size` entries, each > 0; a single
    number is repeated."""
    if np.ndim(value) == 0:
        return np.full(size, positive(name, value))
    return positive_vector(name, value, size)


def check_margin(margin, lower, upper):
    """Checks that `margin` leaves each joint a non-empty band
    [lower + margin, upper - margin]; returns it as a float.

    Raises:
        ValueError: naming `margin` when it is negative or at least half of
            a joint's range.
    """
    margin = non_negative("margin", margin)
    half_range = 0.5 * (np.asarray(upper) - np.asarray(lower))
    bad = np.flatnonzero(margin >= half_range)
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"margin = {margin!r} is not allowed: must be below half of "
            f"every joint's range (joint {i}: {half_range[i]!r} rad)"
        )
    return margin


class JointVelocityCommand(NamedTuple):
    """The result of `joint_velocity_command`, with what shaped it.

    Attributes:
        q_dot: (n,) joint velocity command, rad/s.
        scale: the uniform factor in (0, 1] of the velocity limit (1 when
            no joint was too fast).
        acceleration_scale: the uniform factor in [0, 1] applied to the
            change from the previous q_dot (1 when within the acceleration
            limit or without one).
        limited_joints: (n,) bool, True for each joint whose rate was cut
            by its position limits.
        damping: lambda used by the least-squares solve (0 away from
            singularities).
        smallest_singular_value: s_min of J_a.
    """

    q_dot: np.ndarray
    scale: float
    acceleration_scale: float
    limited_joints: np.ndarray
    damping: float
    smallest_singular_value: float

    @property
    def damped(self):
        """True when the solve was damped (near a singularity)."""
        return self.damping > 0.0

    @property
    def limited(self):
        """True when a limit (position, velocity or acceleration) changed
        the damped least-squares solution."""
        return bool(self.scale < 1.0 or self.acceleration_scale < 1.0
                    or self.limited_joints.any())


@dataclass(frozen=True, eq=False)
class TwistLimits:
    """The limits and settings of `joint_velocity_command`, checked once by
    `twist_limits` (a controller builds them when it is built).

    Attributes:
        lower, upper: (n,) joint limits, rad (-inf and inf: a continuous
            joint, without position limits).
        velocity: (n,) joint velocity limits, rad/s > 0.
        time_step: the control period h > 0, s.
        damping: lambda_max >= 0.
        damping_threshold: eps > 0.
        margin: rad >= 0, below half of every joint's range.
        acceleration: None (no acceleration limit), or (n,) rad/s^2 > 0.
        self_motion_gain: k_c >= 0, 1/s, of the joint centring in the
            self-motion of a redundant arm (n > 6).
    """

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    time_step: float
    damping: float
    damping_threshold: float
    margin: float
    acceleration: np.ndarray | None
    self_motion_gain: float = 0.0

    @functools.cached_property
    def _floats(self):
        """The limits as the float kernel reads them (`_FloatLimits`:
        float64 arrays and floats), computed once."""
        return _FloatLimits.of(self)


def twist_limits(lower, upper, velocity_limit, time_step,
                 damping=DEFAULT_DAMPING,
                 damping_threshold=DEFAULT_DAMPING_THRESHOLD,
                 margin=DEFAULT_JOINT_LIMIT_MARGIN, acceleration_limit=None,
                 self_motion_gain=0.0):
    """TwistLimits from the arguments of `joint_velocity_for_twist`,
    checked (see there); a velocity or acceleration limit given as one
    number holds for every joint.

    Raises:
        ValueError: naming the argument, its value and what is allowed.
    """
    lower, upper = ordered_limits("lower", lower, "upper", upper,
                                  unlimited=True)
    n = lower.size
    if acceleration_limit is not None:
        acceleration_limit = _positive_vector("acceleration_limit",
                                              acceleration_limit, n)
    return TwistLimits(
        lower=lower, upper=upper,
        velocity=_positive_vector("velocity_limit", velocity_limit, n),
        time_step=positive("time_step", time_step),
        damping=non_negative("damping", damping),
        damping_threshold=positive("damping_threshold", damping_threshold),
        margin=check_margin(margin, lower, upper),
        acceleration=acceleration_limit,
        self_motion_gain=non_negative("self_motion_gain", self_motion_gain))


# --- the reference: any scalar type ----------------------------------------


def damping_rule(s_min, damping, threshold):
    """The damping lambda of the least-squares solve from s_min (see
    `singularity_damping`), for any scalar type:

        lambda = lambda_max (1 - (s_min / eps)^2)   for s_min < eps,
        lambda = 0                                  otherwise.
    """
    if s_min >= threshold:
        return 0.0
    return damping * (1.0 - (s_min / threshold) ** 2)


def smallest_singular_value(J):
    """s_min of J (m, n), for any scalar type: the value from the SVD of
    J's value, and for AutoDiffXd the derivative u^T dJ v of a simple
    singular value (u, v its singular vectors); NaN for a J that is not
    finite (whose SVD numpy refuses, or, with an infinity, never
    ends)."""
    J_value = value_of(J)
    if not np.isfinite(J_value).all():
        return 0.0 * (J - J_value)[0, 0] + math.nan
    U, s, Vt = np.linalg.svd(J_value, full_matrices=False)
    return float(s[-1]) + U[:, -1] @ (J - J_value) @ Vt[-1]


def damped_solve(J, V, damping):
    """The damped least squares of Sec. III-A for a constant lambda, for
    any scalar type:

        q_dot = J^T (J J^T + lambda^2 I)^-1 V = (J^T J + lambda^2 I)^-1 J^T V,

    solved in the smaller of the two (J^-1 V for a square J without
    damping). Where that system is exactly singular (no damping and J
    rank deficient) it is the pseudo-inverse solution J^+ V, a zero
    singular value getting gain 0 (on the values: J^+ has no derivative
    there).

    Args:
        J: (m, n) Jacobian.
        V: (m,) twist.
        damping: lambda >= 0.

    Returns:
        (n,) joint velocity: all NaN for a J, V or lambda that is not
        finite (whose infinities the solve would mix into some NaNs and
        some numbers, differently for every way of solving).
    """
    rows, n = J.shape
    if not (np.isfinite(value_of(J)).all() and np.isfinite(value_of(V)).all()
            and math.isfinite(float(value_of(damping)))):
        with np.errstate(invalid="ignore"):
            return (J.T @ V) * math.nan
    square = damping * damping
    try:
        if n == rows and square == 0.0:
            return solve(J, V)
        if n <= rows:
            return solve(J.T @ J + np.eye(n) * square, J.T @ V)
        return J.T @ solve(J @ J.T + np.eye(rows) * square, V)
    except np.linalg.LinAlgError:
        U, s, Vt = np.linalg.svd(value_of(J), full_matrices=False)
        gains = np.divide(1.0, s, out=np.zeros_like(s), where=s > 0.0)
        return Vt.T @ (gains * (U.T @ value_of(V)))


def start_within_limits(name, positions, lower, upper, acceleration,
                        period, remedy="move the arm within them first"):
    """`positions` (n,) as a float vector within [lower, upper]: the arm
    positions a command starts from (the robot's measured ones). A
    position beyond a limit by no more than the step its acceleration
    limit allows from rest in one `period` (drake_wbc.math.safety.
    limit_slack: an arm resting on its limit, read with an encoder's
    noise) is taken as on the limit; from one further beyond, the first
    command, held within the limits, would be a jump (a step beyond the
    acceleration limit). A restart after a stop goes by the same rule
    (drake_wbc.math.safety.restart_position).

    Args:
        name: the positions' name in the error.
        positions: (n,) rad.
        lower, upper: (n,) the joint position limits, rad.
        acceleration: (n,) or scalar, the joint acceleration limits,
            rad/s^2.
        period: the command period h, s.
        remedy: what the error proposes.

    Raises:
        ValueError: naming `name`, the first joint beyond, its value and
            its limits.
    """
    lower = np.asarray(lower, dtype=float)
    upper = np.asarray(upper, dtype=float)
    q = as_vector(name, positions, lower.size)
    for i in beyond_limits(q, lower, upper, acceleration, period):
        raise ValueError(
            f"{name}[{i}] = {float(q[i])!r} is not allowed: must be within "
            f"the joint's limits [{float(lower[i])!r}, "
            f"{float(upper[i])!r}] rad (the first command, held within "
            f"them, would jump there); {remedy}")
    return np.clip(q, lower, upper)


def joint_position_bounds(q, lower, upper, time_step, margin,
                          acceleration=None):
    """The bounds (low, high) on q_dot from the joints' position limits
    (see `joint_position_velocity_bounds`), for any scalar type: lists of
    n entries. A joint whose angle is not finite has NaN bounds (it is
    nowhere, so no rate of it is known to be safe), which `_clipped`
    passes on to its rate.

    Args:
        q: (n,) joint angles, rad.
        lower, upper: (n,) joint limits, rad (-inf and inf: a continuous
            joint, without position limits).
        time_step: h > 0, s.
        margin: >= 0, rad.
        acceleration: None, or (n,) rad/s^2 > 0.
    """
    low, high = [], []
    for i in range(len(q)):
        if not math.isfinite(float(value_of(q[i]))):
            low.append(q[i] * math.nan)
            high.append(q[i] * math.nan)
            continue
        step = None if acceleration is None else acceleration[i] * time_step
        for edge, distance, bounds, sign in (
                (upper[i], (upper[i] - margin) - q[i], high, 1.0),
                (lower[i], q[i] - lower[i] - margin, low, -1.0)):
            if math.isinf(edge):  # a continuous joint: no edge to stop at
                bounds.append(sign * math.inf)
                continue
            distance = max(distance, 0.0)
            rate = distance / time_step
            if step is not None:
                rate = min(rate, braking_rate(distance, step,
                                              step * time_step))
            bounds.append(sign * rate)
    return low, high


def _clipped(values, low, high):
    """values clipped to [low, high] entry by entry, and which were cut;
    a NaN bound (`joint_position_bounds` at a joint angle that is not
    finite) makes the value NaN, and cut; a NaN value stays NaN, not cut
    (no bound acted on it)."""
    result, cut = [], []
    for value, lowest, highest in zip(values, low, high, strict=True):
        if math.isnan(float(value_of(lowest))):
            result.append(value * math.nan)
            cut.append(True)
            continue
        clipped = min(max(value, lowest), highest)
        result.append(clipped)
        cut.append(bool(clipped != value)
                   and not math.isnan(float(value_of(value))))
    return result, cut


def centring_velocity(q, lower, upper, gain):
    """The joint centring of a redundant arm's self-motion, any scalar
    type: z_i = -k_c (q_i - m_i) / r_i, m_i the middle of joint i's range
    and r_i its half-width, so that a joint at its limit is driven towards
    the middle at k_c rad/s; z_i = 0 for a continuous joint (no limits:
    the limit of z_i as its range grows about q_i)."""
    return np.array([q_i * 0.0 if math.isinf(lo)
                     else -gain * (q_i - 0.5 * (lo + hi)) / (0.5 * (hi - lo))
                     for q_i, lo, hi in zip(q, lower.tolist(),
                                            upper.tolist(), strict=True)])


def self_motion(J, z, damping):
    """N z, the part of the joint velocity z in the self-motion of J
    (6, n), n > 6, that leaves the end effector still, any scalar type:

        N = I - J^T (J J^T + lambda^2 I)^-1 J,

    the projector onto J's null space at lambda = 0 (and its damped
    counterpart, continuous across singularities, otherwise)."""
    rows = J.shape[0]
    return z - J.T @ solve(J @ J.T + np.eye(rows) * (damping * damping),
                           J @ z)


def joint_velocity_command(J_a, V_a, q, previous, limits):
    """The joint velocity that realises the arm twist V_a within the
    limits: the arm's Cartesian velocity controller of Sec. III-A, the
    reference body (any scalar type; the stages' double path runs
    `joint_velocity_command_float`).

    The module's four stages: the damped least squares
    (`damped_solve`) with lambda from `damping_rule` (for an arm of more
    than six joints plus its self-motion towards the middle of every
    joint's range, `self_motion` of `centring_velocity`: the secondary
    objective, which moves the joints without moving the end effector),
    the joint-limit
    bounds (`joint_position_bounds`) joint by joint, the uniform scaling
    to the velocity limits (drake_wbc.math.command_limits.uniform_scale),
    and with an acceleration limit the uniform scaling of the change from
    `previous` and the joint-limit bounds once more.

    Args:
        J_a: (6, n) geometric Jacobian [v; w] of the end effector in T_a
            at q.
        V_a: (6,) commanded twist [v_a; w_a] in T_a, m/s and rad/s.
        q: (n,) joint angles, rad.
        previous: (n,) the previous command, rad/s (ignored, and may be
            None, without an acceleration limit).
        limits: TwistLimits.

    Returns:
        JointVelocityCommand.
    """
    s_min = smallest_singular_value(J_a)
    lambda_ = damping_rule(s_min, limits.damping, limits.damping_threshold)
    x = damped_solve(J_a, V_a, lambda_)
    if J_a.shape[1] > J_a.shape[0] and limits.self_motion_gain > 0.0:
        x = x + self_motion(J_a, centring_velocity(
            q, limits.lower, limits.upper, limits.self_motion_gain), lambda_)
    low, high = joint_position_bounds(q, limits.lower, limits.upper,
                                      limits.time_step, limits.margin,
                                      limits.acceleration)
    bounded, limited = _clipped(list(x), low, high)
    scale = uniform_scale(bounded, limits.velocity)
    q_dot = [scale * v for v in bounded]
    acceleration_scale = 1.0
    if limits.acceleration is not None:
        change = [v - p for v, p in zip(q_dot, previous, strict=True)]
        acceleration_scale = uniform_scale(
            change, limits.acceleration * limits.time_step)
        q_dot, cut = _clipped(
            [p + acceleration_scale * c
             for p, c in zip(previous, change, strict=True)], low, high)
        limited = [a or b for a, b in zip(limited, cut, strict=True)]
    return JointVelocityCommand(np.array(q_dot), scale, acceleration_scale,
                                np.array(limited), lambda_, s_min)


# --- the checked functions a user calls -------------------------------------


def singularity_damping(smallest_singular_value, damping=DEFAULT_DAMPING,
                        threshold=DEFAULT_DAMPING_THRESHOLD):
    """The damping lambda of the least-squares solve from s_min:

        lambda^2 = lambda_max^2 (1 - (s_min / eps)^2)^2   for s_min < eps,
        lambda   = 0                                      otherwise.

    lambda^2, which is all that the solve uses, is continuous with a
    continuous derivative in s_min (both vanish at eps), so the solve, and
    the controller's linearisation, have no kink where damping sets in;
    lambda = lambda_max at a singularity.

    Args:
        smallest_singular_value: s_min >= 0 of J_a.
        damping: lambda_max >= 0.
        threshold: eps > 0.

    Returns:
        lambda >= 0 as a float.
    """
    return float(damping_rule(
        non_negative("smallest_singular_value", smallest_singular_value),
        non_negative("damping", damping), positive("threshold", threshold)))


def damped_least_squares(J_a, V_a, damping):
    """q_dot = J_a^T (J_a J_a^T + lambda^2 I)^-1 V_a with a constant lambda
    (`damped_solve`); with lambda = 0 it is the pseudo-inverse solution
    J_a^+ V_a (J_a^-1 V_a for a square regular J_a).

    Args:
        J_a: (6, n) Jacobian.
        V_a: (6,) twist.
        damping: lambda >= 0.

    Returns:
        (n,) joint velocity.
    """
    return damped_solve(as_matrix("J_a", J_a, (6, None)),
                        as_vector("V_a", V_a, 6),
                        non_negative("damping", damping))


def joint_position_velocity_bounds(q, lower, upper, time_step,
                                   margin=DEFAULT_JOINT_LIMIT_MARGIN,
                                   acceleration_limit=None):
    """Bounds (low, high) on q_dot from the joints' position limits.

    With d_up = upper - margin - q and d_low = q - lower - margin, the
    distances to the edges of the allowed band:

    - without an acceleration limit, high = d_up / h and low = -d_low / h,
      so that q + q_dot h stays in the band;
    - with one, each is further limited to the rate from which the joint
      can still brake to rest at the edge (`braking_rate`), which also
      keeps q + q_dot h in the band.

    A joint at or beyond an edge (d <= 0) may not move further out (bound
    0) but is not pushed back; so low <= 0 <= high always, and scaling
    q_dot down never breaks these bounds.

    Args:
        q: (n,) joint angles, rad.
        lower, upper: (n,) joint limits, rad (-inf and inf: a continuous
            joint, without position limits).
        time_step: h > 0, s.
        margin: >= 0, rad, below half of every range.
        acceleration_limit: None, or rad/s^2 > 0 (a number or (n,)).

    Returns:
        (low, high), two (n,) arrays in rad/s.
    """
    q = as_vector("q", q)
    lower, upper = ordered_limits("lower", lower, "upper", upper, q.size,
                                  unlimited=True)
    h = positive("time_step", time_step)
    margin = check_margin(margin, lower, upper)
    if acceleration_limit is not None:
        acceleration_limit = _positive_vector(
            "acceleration_limit", acceleration_limit, q.size)
    low, high = joint_position_bounds(q, lower, upper, h, margin,
                                      acceleration_limit)
    return np.array(low), np.array(high)


def joint_velocity_for_twist(J_a, V_a, q, lower, upper, velocity_limit,
                             time_step, damping=DEFAULT_DAMPING,
                             damping_threshold=DEFAULT_DAMPING_THRESHOLD,
                             margin=DEFAULT_JOINT_LIMIT_MARGIN,
                             acceleration_limit=None, previous_q_dot=None):
    """The joint velocity that realises the arm twist V_a, within limits:
    `joint_velocity_command` with its arguments checked.

    See the module's docstring for the four stages: damped least squares
    with lambda from `singularity_damping`, joint-limit bounds from
    `joint_position_velocity_bounds` applied joint by joint, uniform
    scaling to the velocity limits, uniform scaling of the change from
    `previous_q_dot` to the acceleration limit, and the joint-limit bounds
    once more.

    Guarantees: q + q_dot h stays in [lower + margin, upper - margin] for
    every joint that starts there (and a joint outside never moves further
    out); |q_dot_i| <= velocity_limit_i; with an acceleration limit,
    |q_dot_i - previous_q_dot_i| <= a_i h whenever `previous_q_dot` is the
    command of the previous step of this same function (the braking bounds
    are consistent from step to step). Stages 3 and 4 keep the direction of
    the motion (of q_dot, and of its change); only stage 2 and the final
    bounds act on single joints.

    Args:
        J_a: (6, n) geometric Jacobian [v; w] of the end effector in T_a at
            q.
        V_a: (6,) commanded twist [v_a; w_a] in T_a, m/s and rad/s.
        q: (n,) joint angles, rad.
        lower, upper: (n,) joint limits, rad (-inf and inf: a continuous
            joint, without position limits).
        velocity_limit: rad/s > 0, a number or (n,).
        time_step: control period h > 0, s.
        damping: lambda_max >= 0. Default `DEFAULT_DAMPING`.
        damping_threshold: eps > 0. Default `DEFAULT_DAMPING_THRESHOLD`.
        margin: rad >= 0. Default `DEFAULT_JOINT_LIMIT_MARGIN`.
        acceleration_limit: None (no limit), or rad/s^2 > 0, a number or
            (n,).
        previous_q_dot: (n,) the previous command, rad/s; rest (zeros) if
            None. Used only with an acceleration limit.

    Returns:
        JointVelocityCommand: q_dot and what limited it.
    """
    J = as_matrix("J_a", J_a, (6, None))
    n = J.shape[1]
    V = as_vector("V_a", V_a, 6)
    q = as_vector("q", q, n)
    limits = twist_limits(lower, upper, velocity_limit, time_step, damping,
                          damping_threshold, margin, acceleration_limit)
    previous = None
    if acceleration_limit is not None:
        previous = (np.zeros(n) if previous_q_dot is None
                    else as_vector("previous_q_dot", previous_q_dot, n))
    return joint_velocity_command(J, V, q, previous, limits)


# --- the float kernel of the control tick -----------------------------------


class _FloatLimits(NamedTuple):
    """TwistLimits as the compiled kernel reads them: float64 arrays and
    floats, and `clear`, the distance from an edge beyond which a joint's
    bound cannot cut a rate within its velocity limit."""

    lower: np.ndarray
    upper_band: np.ndarray
    velocity: np.ndarray
    h: float
    margin: float
    damping: float
    threshold: float
    accelerating: bool
    step: np.ndarray
    step_h: np.ndarray
    clear: np.ndarray
    middle: np.ndarray
    half: np.ndarray
    gain: float

    @classmethod
    def of(cls, limits):
        h, margin = float(limits.time_step), float(limits.margin)
        velocity = np.array(limits.velocity, dtype=float)
        # Beyond the distance `clear` from an edge a joint's bound is at
        # least its velocity limit c (with a margin for rounding), so a
        # rate of at most c towards it is not cut: d / h >= c for
        # d >= c h and, braking, S(v) <= (v + a h / 2)^2 / (2 a) (the
        # maximum of a h^2 (m + 1)(f + m / 2) over f at a given v) so
        # that braking_rate(d) >= c for d >= (c + a h / 2)^2 / (2 a).
        clear = velocity * h
        step = step_h = np.zeros(velocity.size)
        if limits.acceleration is not None:
            a = np.asarray(limits.acceleration, dtype=float)
            step = a * h
            step_h = step * h
            clear = np.maximum(clear, (velocity + 0.5 * h * a) ** 2
                               / (2.0 * a))
        lower = np.array(limits.lower, dtype=float)
        upper = np.array(limits.upper, dtype=float)
        # A continuous joint's centring is 0: (q - 0) / inf.
        with np.errstate(invalid="ignore"):  # -inf + inf
            middle = np.where(np.isinf(lower), 0.0, 0.5 * (lower + upper))
        return cls(
            lower=lower,
            # The band's upper edges, formed as upper - margin - q is.
            upper_band=upper - margin,
            velocity=velocity, h=h, margin=margin,
            damping=float(limits.damping),
            threshold=float(limits.damping_threshold),
            accelerating=limits.acceleration is not None,
            step=np.ascontiguousarray(step),
            step_h=np.ascontiguousarray(step_h),
            clear=clear * (1.0 + 1e-9) + 1e-300,
            middle=middle, half=0.5 * (upper - lower),
            gain=float(limits.self_motion_gain))


@compiled
def _rate(i, distance, h, accelerating, step, step_h):
    """The bound on |q_dot_i| towards an edge `distance` away:
    min(d / h, braking_rate(d)), d >= 0; inf where there is no edge (a
    continuous joint's)."""
    if distance == math.inf:
        return math.inf
    distance = max(distance, 0.0)
    rate = distance / h
    if accelerating:
        D = distance / step_h[i]
        r = 0.5 * (math.sqrt(1.0 + 8.0 * D) - 1.0)
        m = max(float(math.ceil(r)) - 1.0, 0.0)
        f = min(max(D / (m + 1.0) - 0.5 * m, 0.0), 1.0)
        rate = min(rate, (m + f) * step[i])
    return rate


@compiled
def _bounded(q_dot, q, limited, low, high, lower, upper_band, velocity,
             clear, margin, h, accelerating, step, step_h):
    """q_dot clipped to the position bounds at q, joint by joint; sets
    limited[i] where it cuts. A joint's bound is computed only on the side
    it moves towards and only where it may cut (`clear`); `low` and `high`
    keep those computed (NaN: not yet). A joint whose angle is not finite
    has no bound: its rate is NaN, and cut (as in the reference)."""
    result = np.empty(q_dot.size)
    for i in range(q_dot.size):
        if not math.isfinite(q[i]):
            result[i] = math.nan
            limited[i] = True
            continue
        v = q_dot[i]
        if v > 0.0:
            distance = upper_band[i] - q[i]
            if v > velocity[i] or distance < clear[i]:
                if math.isnan(high[i]):
                    high[i] = _rate(i, distance, h, accelerating, step,
                                    step_h)
                if v > high[i]:
                    v = high[i]
                    limited[i] = True
        elif v < 0.0:
            distance = q[i] - lower[i] - margin
            if -v > velocity[i] or distance < clear[i]:
                if math.isnan(low[i]):
                    low[i] = -_rate(i, distance, h, accelerating, step,
                                    step_h)
                if v < low[i]:
                    v = low[i]
                    limited[i] = True
        result[i] = v
    return result


@compiled
def _scale_to(vector, limits):
    """The largest factor in (0, 1] with |factor * vector_i| <= limits_i."""
    scale = 1.0
    for i in range(vector.size):
        size = abs(vector[i])
        if size > limits[i]:
            scale = min(scale, limits[i] / size)
    return scale


@compiled
def _solved(A, b):
    """x with A x = b (A square, nonsingular) by Gaussian elimination with
    partial pivoting, as LAPACK's dgesv (the same to rounding), on copies:
    written out because numba's np.linalg.solve takes ten seconds and
    more to compile."""
    n = b.size
    M = A.copy()
    x = b.copy()
    for k in range(n):
        pivot = k
        for i in range(k + 1, n):
            if abs(M[i, k]) > abs(M[pivot, k]):
                pivot = i
        if pivot != k:
            for c in range(n):
                M[k, c], M[pivot, c] = M[pivot, c], M[k, c]
            x[k], x[pivot] = x[pivot], x[k]
        for i in range(k + 1, n):
            factor = M[i, k] / M[k, k]
            for c in range(k + 1, n):
                M[i, c] -= factor * M[k, c]
            x[i] -= factor * x[k]
    for k in range(n - 1, -1, -1):
        total = x[k]
        for c in range(k + 1, n):
            total -= M[k, c] * x[c]
        x[k] = total / M[k, k]
    return x


@compiled
def _least_squares(J, V, damping, threshold):
    """(q_dot, lambda, s_min) of the damped least squares: at a regular
    point (J square, s_min >= eps) by an LU solve, otherwise through the
    thin SVD; all NaN for a J that is not finite (which numba's SVD
    refuses), q_dot NaN for a V that is not (as `damped_solve`)."""
    rows, n = J.shape
    for r in range(rows):
        for c in range(n):
            if not math.isfinite(J[r, c]):
                return np.full(n, np.nan), np.nan, np.nan
    finite_twist = True
    for r in range(rows):
        finite_twist = finite_twist and math.isfinite(V[r])
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    s_min = s[-1]
    if not finite_twist:
        return np.full(n, np.nan), (
            0.0 if s_min >= threshold
            else damping * (1.0 - (s_min / threshold) ** 2)), s_min
    if rows == n and s_min >= threshold:
        return _solved(J, V), 0.0, s_min
    lambda_ = (0.0 if s_min >= threshold
               else damping * (1.0 - (s_min / threshold) ** 2))
    k = s.size
    projected = np.empty(k)
    for i in range(k):
        denominator = s[i] ** 2 + lambda_ ** 2
        gain = s[i] / denominator if denominator > 0.0 else 0.0
        total = 0.0
        for r in range(rows):
            total += U[r, i] * V[r]
        projected[i] = gain * total
    x = np.empty(n)
    for c in range(n):
        total = 0.0
        for i in range(k):
            total += Vt[i, c] * projected[i]
        x[c] = total
    return x, lambda_, s_min


@compiled
def _command(J, V, q, previous, lower, upper_band, velocity, clear, margin,
             h, damping, threshold, accelerating, step, step_h, middle, half,
             gain):
    """The compiled body of `joint_velocity_command_float`: (q_dot, scale,
    acceleration_scale, limited, lambda, s_min)."""
    x, lambda_, s_min = _least_squares(J, V, damping, threshold)
    rows, n = J.shape
    if n > rows and gain > 0.0:
        z = np.empty(n)
        for i in range(n):
            z[i] = (-gain) * (q[i] - middle[i]) / half[i]
        # z - J^T (J J^T + lambda^2 I)^-1 J z, the products written out.
        A = np.empty((rows, rows))
        Jz = np.empty(rows)
        for r in range(rows):
            for c in range(rows):
                total = 0.0
                for k in range(n):
                    total += J[r, k] * J[c, k]
                A[r, c] = total + (lambda_ * lambda_ if r == c else 0.0)
            total = 0.0
            for k in range(n):
                total += J[r, k] * z[k]
            Jz[r] = total
        y = _solved(A, Jz)
        for k in range(n):
            total = 0.0
            for r in range(rows):
                total += J[r, k] * y[r]
            x[k] = x[k] + (z[k] - total)
    limited = np.zeros(n, dtype=np.bool_)
    low = np.full(n, np.nan)
    high = np.full(n, np.nan)
    q_dot = _bounded(x, q, limited, low, high, lower, upper_band, velocity,
                     clear, margin, h, accelerating, step, step_h)
    scale = _scale_to(q_dot, velocity)
    if scale != 1.0:
        q_dot = scale * q_dot
    acceleration_scale = 1.0
    if accelerating:
        change = q_dot - previous
        acceleration_scale = _scale_to(change, step)
        if acceleration_scale != 1.0:
            change = acceleration_scale * change
        q_dot = _bounded(previous + change, q, limited, low, high, lower,
                         upper_band, velocity, clear, margin, h,
                         accelerating, step, step_h)
    return q_dot, scale, acceleration_scale, limited, lambda_, s_min


def _twist_samples(rng):
    """Random arguments of joint_velocity_command: Jacobians of 5 to 7
    columns with singular values from regular to exactly zero (damped and
    undamped solves), joints inside, on and beyond the edges of their
    bands (one case in five with continuous joints, limits -inf and inf,
    at any angle; one in ten with a joint angle NaN or infinite, one
    in twenty each with an entry of J_a or V_a NaN or infinite), slow
    and fast twists, previous rates from rest to beyond the
    limits, with and without an acceleration limit; and one case in five
    with a diagonal J_a whose rates lie just below, at and just above the
    velocity limits, at distances from the edges just inside and outside
    the float kernel's `clear` (where it starts computing bounds)."""
    if rng.uniform() < 0.2:
        return _boundary_sample(rng)
    n = int(rng.choice([6, 6, 6, 5, 7]))
    k = min(n, 6)
    U = np.linalg.qr(rng.normal(size=(6, 6)))[0][:, :k]
    W = np.linalg.qr(rng.normal(size=(n, n)))[0][:, :k]
    s = np.sort(rng.uniform(0.1, 2.5, k))[::-1]
    kind = rng.integers(4)
    if kind == 0:
        s[-1] = rng.uniform(0.0, DEFAULT_DAMPING_THRESHOLD)
    elif kind == 1:
        s[-1] = 0.0
    J = U @ np.diag(s) @ W.T
    lower = rng.uniform(-3.0, -1.0, n)
    upper = rng.uniform(1.0, 3.0, n)
    margin = float(rng.choice([0.0, DEFAULT_JOINT_LIMIT_MARGIN, 0.3]))
    q = rng.uniform(lower - 0.02, upper + 0.02)
    for i in rng.choice(n, size=rng.integers(0, 3), replace=False):
        edge = (lower[i] + margin if rng.uniform() < 0.5
                else upper[i] - margin)
        q[i] = edge + rng.choice([-1.0, 0.0, 1.0]) * rng.uniform(0.0, 0.05)
    if rng.uniform() < 0.2:  # continuous joints, without position limits
        free = rng.choice(n, size=rng.integers(1, n + 1), replace=False)
        lower[free], upper[free] = -np.inf, np.inf
        q[free] = rng.uniform(-10.0, 10.0, free.size)
    if rng.uniform() < 0.1:
        q[rng.integers(n)] = rng.choice([np.nan, np.inf, -np.inf])
    if rng.uniform() < 0.05:
        J[rng.integers(6), rng.integers(n)] = rng.choice(
            [np.nan, np.inf, -np.inf])
    V = rng.normal(0.0, rng.choice([1e-3, 0.05, 0.3, 3.0]), 6)
    if rng.uniform() < 0.05:
        V[rng.integers(6)] = rng.choice([np.nan, np.inf, -np.inf])
    h = float(rng.choice([0.01, 0.01, 0.001, 0.1]))
    acceleration = (None if rng.uniform() < 0.3
                    else float(rng.choice([12.56, 1.0])))
    limits = twist_limits(
        lower, upper, rng.choice([1.57, 0.5]) * rng.uniform(0.8, 1.2, n),
        h, damping=float(rng.choice([DEFAULT_DAMPING, 0.2])),
        damping_threshold=float(rng.choice([DEFAULT_DAMPING_THRESHOLD,
                                            DEFAULT_DAMPING_THRESHOLD,
                                            10.0])),
        margin=margin, acceleration_limit=acceleration,
        self_motion_gain=float(rng.choice([0.0, DEFAULT_SELF_MOTION_GAIN,
                                           5.0])))
    previous = (None if acceleration is None else
                rng.normal(0.0, rng.choice([0.0, 0.3, 3.0]), n))
    return J, V, q, previous, limits


def _boundary_sample(rng):
    """A sample of `_twist_samples` at the kernel's boundaries: J_a
    diagonal (regular), so that the rates are V_a / s exactly."""
    s = rng.uniform(0.1, 2.5, 6)
    lower, upper = -np.full(6, 2.0), np.full(6, 2.5)
    h = 0.01
    acceleration = (None if rng.uniform() < 0.3
                    else float(rng.choice([12.56, 0.5])))
    limits = twist_limits(lower, upper, 1.57, h,
                          margin=DEFAULT_JOINT_LIMIT_MARGIN,
                          acceleration_limit=acceleration)
    clear = np.array(limits._floats.clear)
    distance = clear * rng.choice([0.0, 0.5, 1.0 - 1e-9, 1.0, 1.0 + 1e-9,
                                   2.0], 6)
    towards_upper = rng.uniform(size=6) < 0.5
    q = np.where(towards_upper, upper - limits.margin - distance,
                 lower + limits.margin + distance)
    speed = limits.velocity * rng.choice([0.3, 1.0 - 1e-12, 1.0,
                                          1.0 + 1e-12, 3.0], 6)
    V = s * np.where(towards_upper, speed, -speed)
    previous = (None if acceleration is None
                else V / s * rng.choice([0.0, 1.0], 6))
    return np.diag(s), V, q, previous, limits


@kernels.fast_kernel(joint_velocity_command, sample=_twist_samples)
def joint_velocity_command_float(J_a, V_a, q, previous, limits):
    """`joint_velocity_command` in machine code (drake_wbc.math.compiled),
    for the controller's tick (float arrays; the same result to rounding):
    the least squares by an LU solve at a regular point, then the limits
    applied joint by joint, a joint's bound computed only where it may
    cut."""
    f = limits._floats
    q = np.ascontiguousarray(q, dtype=float)
    previous = (np.ascontiguousarray(previous, dtype=float)
                if f.accelerating else np.zeros(q.size))
    q_dot, scale, acceleration_scale, limited, lambda_, s_min = (
        _command(
            np.ascontiguousarray(J_a, dtype=float),
            np.ascontiguousarray(V_a, dtype=float), q, previous, f.lower,
            f.upper_band, f.velocity, f.clear, f.margin, f.h, f.damping,
            f.threshold, f.accelerating, f.step, f.step_h, f.middle, f.half,
            f.gain))
    return JointVelocityCommand(q_dot, float(scale),
                                float(acceleration_scale), limited,
                                float(lambda_), float(s_min))

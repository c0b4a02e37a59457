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
   (see `joint_position_velocity_bounds`).
3. Velocity limits by uniform scaling of the whole q_dot, so that the
   end effector keeps its direction of motion and only slows down.
4. Optionally an acceleration limit: the change from the previous q_dot is
   scaled uniformly so that no joint changes its rate by more than a h.
   Stage 2's bounds are applied once more at the end, so that the position
   limits always hold.

Units: J_a is the (6, n) geometric Jacobian [v; w] of the end effector in
T_a (m/rad and rad/rad per column), V_a is in m/s and rad/s, joint angles
in rad, rates in rad/s, accelerations in rad/s^2, time_step in s. The
singular values of J_a mix both units; for the Elfin5 with its tool they lie
between about 0.15 and 2 at the home pose and fall to 0 only at a
singularity (see `DEFAULT_DAMPING_THRESHOLD`).

Here: the parameters, their checks and the checked functions; the result,
a `JointVelocityCommand`, and the per-tick solver that computes it with its
limits checked once, `TwistSolver`, are in drake_wbc.math.twist_solver.

Numpy only: the Drake system (drake_wbc.stages.ArmCartesianVelocityController)
calls this in double and gives the result its derivatives for AutoDiffXd.
"""

from dataclasses import dataclass

import numpy as np

from drake_wbc.math.twist_solver import (
    TwistSolver,
    _damped_solve,
    _PositionBounds,
)
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

Why 0.05 on the Elfin5 with the wiping tool: at the home pose
s_min = 0.147 and the median over the whole joint space is 0.089, so most
working poses are solved exactly (no damping, no tracking error). s_min
falls as about 0.31 d within d rad of the wrist singularity (q5 = 0) and
as about 0.16 d near the stretched elbow (q3 = 0): damping acts in the last
0.16 rad (9 degrees) before the wrist singularity and the last 0.3 rad
before the stretched elbow. With the default damping (lambda_max = eps) the
largest joint-rate gain of any direction is 1.07 / eps = 21 rad/s per unit
of twist, so a twist of up to 0.07 m/s (or rad/s) towards a singularity
still stays below the Elfin5's 1.57 rad/s, and larger ones are slowed
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

The position command never leaves [lower + margin, upper - margin]. 0.05 rad
(2.9 degrees) is 0.8 to 1.1% of each Elfin5 range (4.7 to 6.28 rad), so it
costs practically no workspace, yet it is larger than what a stiff,
well-damped position servo overshoots a command that brakes to rest (a few
percent of the following error, which is itself at most 1.57 rad/s times
the arm's 0.02 to 0.05 s lag, 0.03 to 0.08 rad at full speed and far less
once braked), and it covers the tolerance of the arm's own limit switches
and of the published limits. The capability of movement (and the
compensation that gives way by it) keeps the arm much further away in
normal use, from 8 to 12% of a range; this margin is the last line."""

ELFIN5_ACCELERATION_LIMIT = 12.56
"""The Elfin5's joint acceleration limit, rad/s^2, the same on every
joint (the robot facts; also in models/elfin5.sdf)."""


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
        acceleration_limit: rad/s^2 > 0, the same on every joint; the
            Elfin5's 12.56 by default.
        lower, upper: (6,) joint limits in rad, or None for the model's
            (drake_wbc.robot.model.ArmKinematics().lower / .upper).
        velocity_limits: (6,) rad/s > 0, or None for the model's (1.57 on
            every Elfin5 joint).

    Vectors are given as any sequence (a list in YAML) and stored as
    tuples, so that parameters compare with ==. The control period is not
    a field: it is the controller's one time_step
    (ControllerParameters.time_step), the stage's `time_step` argument.
    """

    damping: float = DEFAULT_DAMPING
    damping_threshold: float = DEFAULT_DAMPING_THRESHOLD
    margin: float = DEFAULT_JOINT_LIMIT_MARGIN
    use_acceleration_limit: bool = True
    acceleration_limit: float = ELFIN5_ACCELERATION_LIMIT
    lower: list[float] | None = None
    upper: list[float] | None = None
    velocity_limits: list[float] | None = None

    def __post_init__(self):
        non_negative("damping", self.damping)
        positive("damping_threshold", self.damping_threshold)
        non_negative("margin", self.margin)
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
                                          self.upper, 6)
            check_margin(self.margin, lower, upper)
            self.lower = tuple(lower.tolist())
            self.upper = tuple(upper.tolist())
        if self.velocity_limits is not None:
            limits = _positive_vector("velocity_limits",
                                      self.velocity_limits, 6)
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
    s_min = non_negative("smallest_singular_value", smallest_singular_value)
    lambda_max = non_negative("damping", damping)
    eps = positive("threshold", threshold)
    if s_min >= eps:
        return 0.0
    return float(lambda_max * (1.0 - (s_min / eps) ** 2))


def damped_least_squares(J_a, V_a, damping):
    """q_dot = J_a^T (J_a J_a^T + lambda^2 I)^-1 V_a with a constant lambda.

    Evaluated through the SVD of J_a; with lambda = 0 it is the
    pseudo-inverse solution J_a^+ V_a (J_a^-1 V_a for a square regular
    J_a), a zero singular value then getting gain 0.

    Args:
        J_a: (6, n) Jacobian.
        V_a: (6,) twist.
        damping: lambda >= 0.

    Returns:
        (n,) joint velocity.
    """
    J = as_matrix("J_a", J_a, (6, None))
    V = as_vector("V_a", V_a, 6)
    lambda_ = non_negative("damping", damping)
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    return _damped_solve(U, s, Vt, V, lambda_)


def joint_position_velocity_bounds(q, lower, upper, time_step,
                                   margin=DEFAULT_JOINT_LIMIT_MARGIN,
                                   acceleration_limit=None):
    """Bounds (low, high) on q_dot from the joints' position limits.

    With d_up = upper - margin - q and d_low = q - lower - margin, the
    distances to the edges of the allowed band:

    - without an acceleration limit, high = d_up / h and low = -d_low / h,
      so that q + q_dot h stays in the band;
    - with one, each is further limited to the rate from which the joint
      can still brake to rest at the edge (see
      `twist_solver._braking_rate`), which also keeps q + q_dot h in the
      band.

    A joint at or beyond an edge (d <= 0) may not move further out (bound
    0) but is not pushed back; so low <= 0 <= high always, and scaling
    q_dot down never breaks these bounds.

    Args:
        q: (n,) joint angles, rad.
        lower, upper: (n,) joint limits, rad.
        time_step: h > 0, s.
        margin: >= 0, rad, below half of every range.
        acceleration_limit: None, or rad/s^2 > 0 (a number or (n,)).

    Returns:
        (low, high), two (n,) arrays in rad/s.
    """
    q = as_vector("q", q)
    lower, upper = ordered_limits("lower", lower, "upper", upper, q.size)
    h = positive("time_step", time_step)
    margin = check_margin(margin, lower, upper)
    if acceleration_limit is not None:
        acceleration_limit = _positive_vector(
            "acceleration_limit", acceleration_limit, q.size)
    bounds = _PositionBounds(lower, upper, h, margin, acceleration_limit)
    low, high = [], []
    for i, q_i in enumerate(q.tolist()):
        low.append(-bounds.rate(i, q_i - bounds.lower[i] - margin))
        high.append(bounds.rate(i, bounds.upper_band[i] - q_i))
    return np.array(low), np.array(high)


def joint_velocity_for_twist(J_a, V_a, q, lower, upper, velocity_limit,
                             time_step, damping=DEFAULT_DAMPING,
                             damping_threshold=DEFAULT_DAMPING_THRESHOLD,
                             margin=DEFAULT_JOINT_LIMIT_MARGIN,
                             acceleration_limit=None, previous_q_dot=None):
    """The joint velocity that realises the arm twist V_a, within limits.

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
        lower, upper: (n,) joint limits, rad.
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
    lower, upper = ordered_limits("lower", lower, "upper", upper, n)
    velocity_limit = _positive_vector("velocity_limit", velocity_limit, n)
    h = positive("time_step", time_step)
    lambda_max = non_negative("damping", damping)
    eps = positive("damping_threshold", damping_threshold)
    margin = check_margin(margin, lower, upper)
    previous = None
    if acceleration_limit is not None:
        acceleration_limit = _positive_vector("acceleration_limit",
                                              acceleration_limit, n)
        previous = (np.zeros(n) if previous_q_dot is None
                    else as_vector("previous_q_dot", previous_q_dot, n))
    return joint_velocity_for_twist_unchecked(
        J, V, q, lower, upper, velocity_limit, h, lambda_max, eps, margin,
        acceleration_limit, previous)


def joint_velocity_for_twist_unchecked(J, V, q, lower, upper,
                                       velocity_limit, h, lambda_max, eps,
                                       margin, acceleration_limit, previous):
    """`joint_velocity_for_twist` without its argument checks: float
    arrays of the sizes given there, velocity_limit (n,),
    acceleration_limit None or (n,), previous (n,) when it is not None.
    A controller that keeps its limits calls a `TwistSolver` instead."""
    return TwistSolver(lower, upper, velocity_limit, h, lambda_max, eps,
                       margin, acceleration_limit).solve(J, V, q, previous)

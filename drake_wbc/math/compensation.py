"""Robust compensation of the filtered base motion (paper Sec. IV-A).

The base command V_b from eq. (wbccm) is low-pass filtered, eq.
(filtering), before it is sent to the slow base. The arm, much faster,
compensates the difference so that the end effector keeps its reference
motion, except in the direction that would lower the arm's movement
capability C_m: that part of the compensation is removed in proportion to
alpha of eq. (transition), and it shows up as the end-effector deviation
of eq. (deviation).

    delta_V_b       = V_b^flt - V_b                        (after filtering)
    delta_V_a^req   = -R_ba^T J_b delta_V_b
    delta_V_a^cmp   = (I - alpha P_Cm) delta_V_a^req        eq. (wb_error)
    V_a^ref         = V_a + delta_V_a^cmp                   eq. (compensation)
    delta_V_ee      = R_ba (delta_V_a^cmp - delta_V_a^req)
                    = -alpha R_ba P_Cm delta_V_a^req        eq. (deviation)

Twists are [linear; angular] (m/s; rad/s); the arm's are in T_a, the
base's [vx_b, vy_b, wz_b] in T_b, and so is delta_V_ee, the deviation of
the end effector's twist V_ee, which eq. (fk) gives in T_b: with V_a^ref
and V_b^flt the end effector moves at R_ba (V_a + delta_V_a^cmp) + J_b
V_b^flt = V_ee + R_ba (delta_V_a^cmp - delta_V_a^req). The paper prints
eq. (deviation) without R_ba, its robot's ^bR_a = I; the tracking-error
term of eq. (cdmp-wb-error) integrates delta_V_ee where V_ee lives, in
T_b (an arm mounted turned or tilted on the base otherwise has its
deviation commanded back along the wrong axes).

- delta_V_b: `base_deviation_of`, checked `base_deviation`;
- P_Cm of eq. (wb_error): `project_on_gradient` (P_Cm applied), checked
  `gradient_projector` (the matrix);
- delta_V_a^req: `required_compensation`, eq. (wb_error):
  `projected_compensation`, eq. (deviation) in T_b: `deviation_in_base`,
  all three checked `robust_compensation`;
- eq. (compensation) with J_b of eq. (2) at p_ee: `arm_compensation`;
- eq. (base_lag): `base_velocity_prediction` with g = `lag_gain`; T_b
  from a logged response: `identify_lag`.

The base's motion (beyond the paper; RobustCompensatorParameters.
base_source). The paper's V_b^flt is the command sent; the base follows it
through its own velocity loop (0.2 s on the shipped base), so the arm
compensates motion the base has not made yet and the tool moves although
delta_V_ee = 0. Two other sources stand for what the base really does:

- "measured": the odometry's twist (base.state_estimated[3:6]). Costs:
  its noise reaches the arm's reference one to one (through J_b: the yaw
  rate's noise times the tool's lever, about 0.9 m), at every frequency
  up to the control rate, and integrates into a random walk of the tool
  that nothing brings back while alpha = 0 (white noise of sigma m/s
  each tick: sigma sqrt(h t) after t s, 0.1 mm after 1 s at 1 mm/s); a
  bias or scale error of the odometry moves the tool at that error. A
  delay d of the odometry leaves about d times the base's velocity
  change as the tool's error: the command source is this with d = the
  loop's lag (0.2 s), so d = 20 ms costs about a tenth of its deviation.
  The station's odometry is exact and has no delay; what is left there
  comes from the arm's own delay (its command acts a period or two
  after the tick). Measured on line_tracking with the compensator's
  odometry delayed or made noisy (README, fixed point): 0.75 mm RMS
  lateral, 1.38 and 2.35 mm delayed 20 and 50 ms, 0.81 and 1.30 mm
  with 1 and 5 mm/s of white noise, which raises the arm command's
  share above 5 Hz from 0.5 to 3.5 and 17 %.
- "predicted": the command through a first-order lag of time constant
  base_lag, eq. (base_lag):

      V_b^pred+ = V_b^pred + g (V_b^flt - V_b^pred),
      g = 1 - e^(-h / T_b),                                 eq. (base_lag)

  (a label of this project: the paper models no base loop), the exact
  step for a command held over the period h; the compensator takes
  V_b^pred+, the base's velocity one period after this tick's command.
  No sensor noise or delay; the cost is the model's
  error: a lag off by Delta T leaves about Delta T / T_b of the command's
  deviation, and a base that is not a first-order lag (one that rings) is
  compensated wrongly; `identify_lag` fits T_b to a logged response. The
  model has no saturation: it is exact while the command's acceleration
  stays within the base's limits (the BaseCommandLimiter sees to that),
  not after a safe stop's step to zero (the arm is then held anyway).

Stability: with alpha = 0 every source is a feedforward into the arm (the
measured one reads the robot, but the arm does not drive the base's
velocity loop), so no loop changes. With alpha > 0 the deviation closes
the loop of the tracking-error elimination, delta_V_ee -> WholeBodyCdmp
-> V_b -> base -> delta_V_ee; with "measured" and "predicted" the base's
lag is inside it, which costs phase: at alpha = 1 its gain margin falls
from 29.5 to 25.5 dB in fixed_point and from 4.4 to 2.4 dB with the
controller's whole-body DMP (drake_wbc.analysis.chains.deviation_loop).

The references are scalar-generic (float, and numpy object arrays of
AutoDiffXd for the stage's derivatives) and check nothing; the checked
functions, for a user's call by hand, check their arguments and call them.
`arm_compensation` is what RobustCompensator runs each tick; its fast
float kernel is `arm_compensation_float`.
"""

import math
from dataclasses import dataclass

import numpy as np

from drake_wbc.math.compiled import compiled, float_array
from drake_wbc.math.kernels import fast_kernel
from drake_wbc.math.kinematics import (
    base_jacobian_of,
    random_rotation,
    rotate_twist,
)
from drake_wbc.math.scalar_support import value_of
from drake_wbc.math.task_inputs import TASK_INPUTS
from drake_wbc.math.validation import (
    as_matrix,
    as_vector,
    in_closed_range,
    non_negative,
    positive,
    rotation_matrix,
)

PROJECTOR_TOLERANCE = 1e-12
"""Norm of grad_x C_m at and below which P_Cm = 0 (gradient_projector's
default and the compensator's)."""


BASE_SOURCES = ("command", "measured", "predicted")
"""What the compensator takes for the base's motion V_b^flt of eq.
(wb_error) (RobustCompensatorParameters.base_source)."""


@dataclass
class RobustCompensatorParameters:
    """Parameters of RobustCompensator (drake_wbc.stages.coordination).

    Attributes:
        compensation_switch: s_c in [0, 1], used when the
            compensation_switch port is not connected. The paper's s_c is
            1 (robust compensation, alpha as computed) or 0 (alpha = 0:
            exact compensation whatever C_m); values in between scale
            alpha.
        base_source: what stands for the base's motion V_b^flt in
            delta_V_b = V_b^flt - V_b (one of BASE_SOURCES):
            "command" (the paper's and the default): the command sent,
            the filter's output after the limiter; "measured": the base's
            twist from its odometry (base.state_estimated); "predicted":
            the command through a model of the base's velocity loop, a
            first-order lag of time constant `base_lag` (eq.
            (base_lag); `base_velocity_prediction`). What each costs:
            module docstring, "The base's motion".
        base_lag: the time constant of the "predicted" source's lag, s,
            > 0 (0.2, the shipped base's loop; `identify_lag` estimates it
            from a logged response). Read only by that source. An
            estimate; the separation's stop allows for a bound instead
            (the robot's base.velocity_lag, SafetyParameters.base_lag).
    """

    compensation_switch: float = 1.0
    base_source: str = "command"
    base_lag: float = 0.2

    def __post_init__(self):
        TASK_INPUTS["compensation_switch"].check_number(
            "compensation_switch", self.compensation_switch)
        if self.base_source not in BASE_SOURCES:
            allowed = ", ".join(repr(name) for name in BASE_SOURCES)
            raise ValueError(
                f"base_source = {self.base_source!r} is not allowed: must "
                f"be one of {allowed}")
        positive("base_lag", self.base_lag)


# --- the reference bodies ---------------------------------------------------

def base_deviation_of(V_b_filtered, V_b):
    """delta_V_b = V_b^flt - V_b for any scalar type (the reference body
    of `base_deviation`, which documents it)."""
    return np.asarray(V_b_filtered) - np.asarray(V_b)


def lag_gain(time_step, lag):
    """g = 1 - e^(-h / T_b) of eq. (base_lag): the fraction of the way to
    a command held over one period h that a first-order lag of time
    constant T_b goes (float)."""
    return -math.expm1(-time_step / lag)


def base_velocity_prediction(predicted, command, gain):
    """V_b^pred+ = V_b^pred + g (V_b^cmd - V_b^pred), eq. (base_lag), for
    any scalar type: one control period of the base's velocity loop
    modelled as a first-order lag, the exact step for a command held over
    the period (zero-order hold), g = `lag_gain(h, T_b)`. From rest, a
    step to u gives u (1 - e^(-k h / T_b)) after k periods."""
    predicted = np.asarray(predicted)
    return predicted + gain * (np.asarray(command) - predicted)


def project_on_gradient(twist, grad, tolerance=PROJECTOR_TOLERANCE):
    """P_Cm twist = g (g . twist) / (g . g) of eq. (wb_error) for any
    scalar type, twist (6,) or (6, k); zero when ||g|| <= tolerance (the
    reference body of `gradient_projector`, which documents P_Cm)."""
    g, twist = np.asarray(grad), np.asarray(twist)
    g_squared = g @ g
    if math.sqrt(value_of(g_squared)) <= tolerance:
        return 0.0 * twist
    along = g @ twist
    return (g * along if twist.ndim == 1 else np.outer(g, along)) / g_squared


def required_compensation(delta_V_b, J_b, R_ba):
    """delta_V_a^req = -R_ba^T J_b delta_V_b for any scalar type: the arm
    twist in T_a that cancels the base deviation at the end effector,
    from eq. (fk) (R_ba delta_V_a + J_b delta_V_b = 0); R_ba a rotation
    matrix (3, 3)."""
    return -rotate_twist(np.asarray(R_ba).T,
                         np.asarray(J_b) @ np.asarray(delta_V_b))


def projected_compensation(required, grad, alpha,
                           tolerance=PROJECTOR_TOLERANCE):
    """(delta_V_a^cmp, delta_V_a^cmp - delta_V_a^req) of eq. (wb_error)
    for any scalar type, both in T_a: the difference -alpha P_Cm
    delta_V_a^req is the deviation of eq. (deviation) before it is
    turned into T_b (`deviation_in_base`)."""
    deviation = -alpha * project_on_gradient(required, grad, tolerance)
    return np.asarray(required) + deviation, deviation


def deviation_in_base(deviation_in_arm, R_ba):
    """delta_V_ee = R_ba (delta_V_a^cmp - delta_V_a^req) of eq.
    (deviation) for any scalar type: the end effector's twist deviation
    in T_b from the compensation's shortfall in T_a (module docstring);
    R_ba a rotation matrix (3, 3)."""
    return rotate_twist(R_ba, deviation_in_arm)


def arm_compensation(V_a, V_b, V_b_filtered, p_ee_in_base, R_ba, grad_C_m,
                     alpha, tolerance=PROJECTOR_TOLERANCE):
    """[V_a^ref; delta_V_ee] of eqs. (compensation) and (deviation), with
    J_b of eq. (2) at the end effector's position, for any scalar type,
    unchecked: what RobustCompensator runs each tick (its fast float
    kernel is `arm_compensation_float`).

    Args:
        V_a: (6,) the arm's distributed twist in T_a.
        V_b, V_b_filtered: (3,) the base's distributed and filtered
            commands in T_b.
        p_ee_in_base: (3,) p_ee in T_b (only x and y enter J_b).
        R_ba: (3, 3) ^bR_a (an array or rows), or None for the identity.
        grad_C_m: (6,) grad_x C_m in T_a.
        alpha: the transition value (times s_c), in [0, 1].
        tolerance: the norm of grad_C_m at and below which P_Cm = 0.

    Returns:
        (12,) array [V_a^ref (6) in T_a; delta_V_ee (6) in T_b].
    """
    R = np.eye(3) if R_ba is None else R_ba
    required = required_compensation(
        base_deviation_of(V_b_filtered, V_b), base_jacobian_of(p_ee_in_base),
        R)
    cmp, deviation = projected_compensation(required, grad_C_m, alpha,
                                            tolerance)
    return np.concatenate([np.asarray(V_a) + cmp,
                           deviation_in_base(deviation, R)])


# --- the controller's kernel ------------------------------------------------

_IDENTITY_ROWS = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def _compensation_problems(rng):
    """Arguments of arm_compensation: mountings the identity (as None and
    as rows) and random; gradients zero, below, just above and far above
    the tolerance; alpha at 0, 1 and between; in one case in ten an entry
    of a vector, or alpha, NaN or infinite."""
    mounting = rng.choice(3)
    R = (None, _IDENTITY_ROWS, random_rotation(rng))[mounting]
    gradient = rng.normal(size=6) * rng.choice([0.0, 1e-13, 1e-11, 1.0,
                                                 1e3])
    alpha = float(rng.choice([0.0, 1.0, rng.uniform()]))
    vectors = [rng.normal(size=6), rng.normal(size=3), rng.normal(size=3),
               rng.uniform(-1.5, 1.5, 3), gradient]
    if rng.uniform() < 0.1:
        bad = float(rng.choice([np.nan, np.inf, -np.inf]))
        which = rng.integers(len(vectors) + 1)
        if which == len(vectors):
            alpha = bad
        else:
            vectors[which][rng.integers(vectors[which].size)] = bad
    V_a, V_b, V_b_filtered, p_ee, gradient = vectors
    return (V_a, V_b, V_b_filtered, p_ee, R, gradient, alpha,
            PROJECTOR_TOLERANCE)


@compiled
def _compensation(V_a, V_b, V_b_filtered, p_ee_in_base, R, rotate, g, alpha,
                  tolerance):
    """The compiled body of `arm_compensation_float`; R the (3, 3) ^bR_a,
    `rotate` False for the identity (the deviation stays as it is). An
    empty result where an input is not finite: the caller takes the
    reference, whose NaNs this arithmetic, written out, would not give
    (its early return for a small gradient reads neither alpha nor the
    zeros of J_b, where 0 * NaN is NaN)."""
    if not (math.isfinite(alpha) and _finite(V_a) and _finite(V_b)
            and _finite(V_b_filtered) and _finite(p_ee_in_base)
            and _finite(R.ravel()) and _finite(g)):
        return np.empty(0)
    dvx = V_b_filtered[0] - V_b[0]
    dvy = V_b_filtered[1] - V_b[1]
    dwz = V_b_filtered[2] - V_b[2]
    x, y = p_ee_in_base[0], p_ee_in_base[1]
    # J_b delta_V_b (eq. (2)), then delta_V_a^req = -R_ba^T J_b delta_V_b.
    tx = dvx - y * dwz
    ty = dvy + x * dwz
    required = np.empty(6)
    for c in range(3):
        required[c] = -(R[0, c] * tx + R[1, c] * ty)
        required[3 + c] = -(R[2, c] * dwz)
    result = np.zeros(12)
    g_squared = 0.0
    for i in range(6):
        g_squared += g[i] * g[i]
    if math.sqrt(g_squared) <= tolerance:
        for i in range(6):
            result[i] = V_a[i] + required[i]
        return result
    along = 0.0
    for i in range(6):
        along += g[i] * required[i]
    factor = -alpha * along / g_squared
    deviation = np.empty(6)
    for i in range(6):
        deviation[i] = factor * g[i]
        result[i] = V_a[i] + (required[i] + deviation[i])
    if not rotate:
        for i in range(6):
            result[6 + i] = deviation[i]
        return result
    # delta_V_ee = R_ba (delta_V_a^cmp - delta_V_a^req), in T_b.
    for r in range(3):
        result[6 + r] = (R[r, 0] * deviation[0] + R[r, 1] * deviation[1]
                         + R[r, 2] * deviation[2])
        result[9 + r] = (R[r, 0] * deviation[3] + R[r, 1] * deviation[4]
                         + R[r, 2] * deviation[5])
    return result


@compiled
def _finite(values):
    """Whether every entry of the float vector `values` is finite."""
    for value in values:
        if not math.isfinite(value):
            return False
    return True


_IDENTITY = np.eye(3)



@fast_kernel(arm_compensation, sample=_compensation_problems)
def arm_compensation_float(V_a, V_b, V_b_filtered, p_ee_in_base, R_ba,
                           grad_C_m, alpha, tolerance=PROJECTOR_TOLERANCE):
    """`arm_compensation` in machine code (drake_wbc.math.compiled): J_b
    delta_V_b = [dv_x - y dw_z, dv_y + x dw_z, 0, 0, 0, dw_z] of eq. (2)
    and alpha P_Cm d = alpha g (g . d) / (g . g) written out (the same
    values to rounding).

    An input that is not finite takes the reference (whose result it
    is: NaN where the equations give NaN).

    Args:
        as arm_compensation; the vectors float arrays, R_ba None or a
        (3, 3) array (or its rows).
    """
    result = _compensation(
        float_array(V_a), float_array(V_b), float_array(V_b_filtered),
        float_array(p_ee_in_base),
        _IDENTITY if R_ba is None else float_array(R_ba), R_ba is not None,
        float_array(grad_C_m), float(alpha), float(tolerance))
    if result.size == 0:
        with np.errstate(invalid="ignore"):  # 0 * inf, as it should be
            return arm_compensation(V_a, V_b, V_b_filtered, p_ee_in_base,
                                    R_ba, grad_C_m, alpha, tolerance)
    return result


# --- the checked functions --------------------------------------------------

def base_deviation(V_b_filtered, V_b):
    """Motion deviation of the base, delta_V_b = V_b^flt - V_b.

    The equation after eq. (filtering): what the base will not do of the
    distributed command V_b because it receives the filtered V_b^flt.

    Args:
        V_b_filtered: (3,) filtered base command V_b^flt = [vx_b, vy_b,
            wz_b] in T_b (m/s, m/s, rad/s).
        V_b: (3,) base command V_b from eq. (wbccm) (same frame, units).

    Returns:
        (3,) array delta_V_b.

    Raises:
        ValueError: if either argument is not 3 finite numbers.
    """
    return base_deviation_of(as_vector("V_b_filtered", V_b_filtered, 3),
                             as_vector("V_b", V_b, 3))


def identify_lag(commands, velocities, time_step):
    """The time constant T_b of eq. (base_lag) that fits a logged response
    of the base's velocity loop best.

    With u_k the command held over [t_k, t_k + h) and v_k the base's
    velocity at t_k, the gain g of v_{k+1} - v_k = g (u_k - v_k) is fitted
    by least squares over every sample and axis, and T_b = -h / ln(1 - g).

    Args:
        commands: (N,) or (N, k) commands u_k, one row a period.
        velocities: the base's velocities v_k at the same instants, the
            same shape.
        time_step: h, the period of the samples (s, > 0).

    Returns:
        T_b in s.

    Raises:
        ValueError: naming the argument, on a bad shape or non-finite
            entry, fewer than two samples, no command that differs from
            the velocity (nothing to fit), or a fitted g outside (0, 1)
            (the response is no lag).
    """
    h = positive("time_step", time_step)
    u = np.atleast_2d(np.asarray(commands, dtype=float).T).T
    v = np.atleast_2d(np.asarray(velocities, dtype=float).T).T
    if u.shape != v.shape or u.shape[0] < 2:
        raise ValueError(
            f"commands and velocities of shapes {u.shape} and {v.shape} are "
            "not allowed: must have the same shape, two samples or more")
    as_vector("commands", u.ravel())
    as_vector("velocities", v.ravel())
    error, step = (u - v)[:-1].ravel(), np.diff(v, axis=0).ravel()
    energy = float(error @ error)
    if energy == 0.0:
        raise ValueError("commands = velocities throughout is not allowed: "
                         "must differ somewhere (a step) to show the lag")
    gain = float(error @ step) / energy
    if not 0.0 < gain < 1.0:
        raise ValueError(
            f"the fitted gain {gain!r} is not allowed: must be in (0, 1), "
            "a first-order lag's (the response is not one)")
    return -h / math.log1p(-gain)


def gradient_projector(grad, tolerance=PROJECTOR_TOLERANCE):
    """Projector P_Cm onto the gradient of C_m, eq. (wb_error).

    With the gradient g = grad_x C_m (a row vector in the paper),

        P_Cm = g^T (g g^T)^-1 g,

    here for a column g: P_Cm = g g^T / (g^T g), the orthogonal projector
    onto span(g) (symmetric and idempotent), so I - P_Cm removes the part
    of a twist along g. When ||g|| <= tolerance no direction changes C_m
    to first order (e.g. at a maximum of C_m), there is nothing to remove
    and the result is the zero matrix (then delta_V_a^cmp =
    delta_V_a^req).

    Args:
        grad: (6,) gradient of C_m w.r.t. the arm's Cartesian pose
            coordinates, ordered and expressed like V_a ([linear; angular],
            T_a).
        tolerance: norm below which grad counts as zero (>= 0, same units
            as grad); P_Cm itself does not depend on the scale of g.

    Returns:
        (6, 6) array P_Cm.

    Raises:
        ValueError: if grad is not 6 finite numbers or tolerance is
            negative.
    """
    return project_on_gradient(np.eye(6), as_vector("grad", grad, 6),
                               non_negative("tolerance", tolerance))


def robust_compensation(delta_V_b, J_b, R_ba, grad_C_m, alpha):
    """Arm compensation of the base deviation, eqs. (wb_error)-(deviation).

    The arm twist that cancels the base deviation at the end effector
    follows from eq. (fk) (R_ba delta_V_a + J_b delta_V_b = 0):

        delta_V_a^req = -R_ba^T J_b delta_V_b.

    Its component along grad_x C_m is removed in proportion to alpha,

        delta_V_a^cmp = (I - alpha P_Cm) delta_V_a^req,     eq. (wb_error)

    and the end-effector tracking deviation that this leaves, in T_b
    where eq. (fk) gives V_ee (module docstring), is

        delta_V_ee = R_ba (delta_V_a^cmp - delta_V_a^req)
                   = -alpha R_ba P_Cm delta_V_a^req.        eq. (deviation)

    The paper prints it without R_ba (its ^bR_a = I). alpha = 0 gives the
    full compensation (delta_V_ee = 0), alpha = 1 none along the gradient.

    Args:
        delta_V_b: (3,) base deviation V_b^flt - V_b in T_b (see
            base_deviation).
        J_b: (6, 3) base Jacobian of eq. (2), from
            kinematics.base_jacobian.
        R_ba: (3, 3) rotation ^bR_a from T_a to T_b, or None for the
            identity.
        grad_C_m: (6,) gradient grad_x C_m, ordered and expressed like V_a
            (see gradient_projector).
        alpha: transition value of eq. (transition), in [0, 1].

    Returns:
        (delta_V_a_cmp, delta_V_ee): two (6,) arrays, in T_a and in T_b;
        the arm's reference twist is V_a + delta_V_a_cmp, eq.
        (compensation).

    Raises:
        ValueError: on a bad argument (wrong shape, non-finite entry,
            R_ba not a rotation, alpha outside [0, 1]), naming it.
    """
    dV_b = as_vector("delta_V_b", delta_V_b, 3)
    J_b = as_matrix("J_b", J_b, (6, 3))
    R = np.eye(3) if R_ba is None else rotation_matrix("R_ba", R_ba)
    g = as_vector("grad_C_m", grad_C_m, 6)
    a = in_closed_range("alpha", alpha, 0.0, 1.0)
    cmp, deviation = projected_compensation(
        required_compensation(dV_b, J_b, R), g, a)
    return cmp, deviation_in_base(deviation, R)

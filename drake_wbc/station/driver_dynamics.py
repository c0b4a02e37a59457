"""The drivers' step math as plain functions, for double, AutoDiffXd and
symbolic Expressions: one period of the base's velocity loop (a lag with
saturation at the velocity and acceleration limits, first or second
order), the arm driver's linear interpolation between position commands,
and the base's velocity in T_b as its joints' rates (eq. (3)).

BaseVelocityDriver and ArmPositionDriver (drake_wbc.station.drivers) run
these functions on double and AutoDiffXd, and the station's C++
SymbolicVectorSystems (drake_wbc.station.symbolic_drivers) on symbolic
variables, so that both follow the same math.
"""

import numpy as np
import pydrake.symbolic as sym
from pydrake.symbolic import Expression, Variable


def _is_symbolic(*values):
    return any(isinstance(v, (Expression, Variable)) for v in values)


def clip(value, low, high):
    """min(max(value, low), high) for double, AutoDiffXd or a symbolic
    Expression (then Drake's symbolic min and max, so that the same math
    builds a SymbolicVectorSystem)."""
    if _is_symbolic(value, low, high):
        return sym.min(sym.max(value, low), high)
    return min(max(value, low), high)


def beyond(value, limit, outside, inside):
    """`outside` where |value| > limit, else `inside`, for double,
    AutoDiffXd or a symbolic Expression (if_then_else)."""
    if _is_symbolic(value, outside, inside):
        return sym.if_then_else(abs(value) > limit, outside, inside)
    return outside if value > limit or value < -limit else inside


def interpolated_command(state, time, period):
    """The arm driver's interpolation (ArmPositionDriver): from the state
    [q_from (n), q_to (n), t_k] at `time`, (q_d, v_d): q_d moves linearly
    from q_from at t_k to q_to at t_k + period, then holds; v_d is the
    constant rate (q_to - q_from) / period. For double, AutoDiffXd or
    symbolic Expressions."""
    n = (len(state) - 1) // 2
    q_from, q_to, t_k = state[:n], state[n:2 * n], state[2 * n]
    rate = (q_to - q_from) / period
    fraction = clip((time - t_k) / period, 0.0, 1.0)
    return q_from + fraction * (q_to - q_from), rate


def base_loop_step(x, command, params, time_step):
    """One period of the base's velocity loop, per axis.

    First order (params.damping_ratio None): x = v, and
    v+ = v + clip((1 - e^(-h / lag)) (sat(command) - v), +-a_max h), the
    exact step of the lag towards the saturated command, limited to the
    acceleration limits.

    Second order: x = [v, a] (6,), w = 1 / lag, zeta = damping_ratio;
    a+ = clip(a + h (w^2 (sat(command) - v) - 2 zeta w a), +-a_max),
    v+ = v + h a+ (semi-implicit Euler, exact enough for w h << 1); an
    overshoot is stopped at the velocity limits.

    Works for double, AutoDiffXd and symbolic Expressions (see `clip`).

    Args:
        x: the loop's state: its velocity [vx, vy, wz] in T_b, followed
            by its acceleration in the second-order loop.
        command: (3,) the commanded velocity, T_b.
        params: BaseDriverParameters.
        time_step: the loop's step h in s (the plant's in the station,
            StationOptions.time_step; checked by the caller,
            drivers.check_base_time_step).
    """
    h, zeta = time_step, params.damping_ratio
    w = 1.0 / params.lag
    gain = 1.0 - np.exp(-h / params.lag)
    velocity, acceleration = [], []
    for i in range(3):
        limit = params.velocity_limits[i]
        target = clip(command[i], -limit, limit)
        a_max = params.acceleration_limits[i]
        if zeta is None:
            step = a_max * h
            velocity.append(x[i] + clip(gain * (target - x[i]), -step, step))
            continue
        a = x[3 + i] + h * (w * w * (target - x[i]) - 2.0 * zeta * w
                            * x[3 + i])
        a = clip(a, -a_max, a_max)
        v = x[i] + h * a
        # At the velocity limit: stop there.
        v, a = beyond(v, limit, clip(v, -limit, limit), v), beyond(
            v, limit, 0.0 * a, a)
        acceleration.append(a)
        velocity.append(v)
    return np.array(velocity + acceleration)


def base_loop_size(params):
    """The size of the base loop's state (see base_loop_step)."""
    return 3 if params.damping_ratio is None else 6


def body_to_world_rates(yaw, v):
    """The base joints' rates [x_dot, y_dot, yaw_dot] for a velocity v =
    [vx, vy, wz] in T_b at heading `yaw` (eq. (3))."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]])

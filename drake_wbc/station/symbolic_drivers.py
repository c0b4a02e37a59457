"""The drivers' math as Drake SymbolicVectorSystems, evaluated in C++.

The station steps its plant at 1 / time_step, and its drivers with it; a
Python system there costs far more than the math. These systems build the
very functions of drake_wbc.station.driver_dynamics (`base_loop_step`,
`body_to_world_rates`, `interpolated_command`) on symbolic variables, so
the numbers are those of BaseVelocityDriver and ArmPositionDriver (the
reference implementations, which tests compare against), and the
SymbolicVectorSystem evaluates them without Python. Like any
SymbolicVectorSystem they convert to AutoDiffXd.

- `base_loop_system(params, time_step)`: the base's velocity loop at
  the plant's step (state: the loop's velocity in T_b, and its
  acceleration in the second-order loop); input the velocity command
  (3), output the loop's velocity (3), from the state alone.
- `joint_rates_system()`: input [v (3); base pose [x, y, yaw] (3)],
  output the base's desired state [0 (3); R(yaw) v] (6), for the plant.
- `arm_interpolator_system(params, initial_positions)`: state [q_from,
  q_to, t_k] (2 n + 1, positions relative to the initial ones of the
  arm's n joints), input q_cmd (n), output [q_d; v_d] (2 n) at the
  context's time.
"""

import numpy as np
from pydrake.symbolic import MakeVectorVariable, Variable
from pydrake.systems.primitives import SymbolicVectorSystem

from drake_wbc.math.validation import (
    as_vector,
    checked_instance,
)
from drake_wbc.station.driver_dynamics import (
    base_loop_size,
    base_loop_step,
    body_to_world_rates,
    interpolated_command,
)
from drake_wbc.station.drivers import (
    ArmDriverParameters,
    BaseDriverParameters,
    arm_start,
    check_base_time_step,
)


def _symbolic_numpy():
    """numpy over arrays of symbolic variables: its floating-point checks
    after an object loop report flags the symbolic operations leave, not
    errors of the math."""
    return np.errstate(all="ignore")


def base_loop_system(params=None, time_step=None):
    """The base's velocity loop (`base_loop_step` of BaseDriverParameters
    `params`, the defaults if None, at the step `time_step` in s, required:
    the station's plant's, at most params.lag / 10) as a discrete
    SymbolicVectorSystem. Start it with `base_loop_state`."""
    params = checked_instance("params", params, BaseDriverParameters,
                              BaseDriverParameters)
    h = check_base_time_step(params, "time_step", time_step)
    x = MakeVectorVariable(base_loop_size(params), "x")
    u = MakeVectorVariable(3, "u")
    with _symbolic_numpy():
        dynamics = base_loop_step(x, u, params, h)
    return SymbolicVectorSystem(state=x, input=u, dynamics=dynamics,
                                output=x[:3], time_period=h)


def base_loop_state(params, velocity):
    """The state of `base_loop_system(params, time_step)` at rest at
    `velocity` (3,) in T_b (zero acceleration)."""
    state = np.zeros(base_loop_size(params))
    state[:3] = velocity
    return state


def joint_rates_system():
    """[v; pose] (6) -> the base's desired state [0, 0, 0, R(yaw) v] (6),
    stateless (eq. (3), `body_to_world_rates`)."""
    v = MakeVectorVariable(3, "v")
    pose = MakeVectorVariable(3, "pose")
    with _symbolic_numpy():
        rates = body_to_world_rates(pose[2], v)
    return SymbolicVectorSystem(
        input=np.concatenate([v, pose]),
        output=np.concatenate([np.zeros(3), rates]))


def arm_interpolator_system(params=None, initial_positions=None):
    """The arm's position servo (ArmPositionDriver's math) as a discrete
    SymbolicVectorSystem updated every params.command_period: at each
    sample it stores where the interpolation got to, the new command and
    the time; its output [q_d; v_d] follows `interpolated_command` at the
    context's time.

    The positions in its state are relative to `initial_positions` (n,)
    (required), so that its default state, zero, holds
    the arm there from t = 0, like ArmPositionDriver's; set another start
    with `arm_interpolator_state`.
    """
    params = checked_instance("params", params, ArmDriverParameters,
                              ArmDriverParameters)
    q0 = arm_start(initial_positions)
    n = q0.size
    t = Variable("t")
    state = MakeVectorVariable(2 * n + 1, "s")
    command = MakeVectorVariable(n, "q_cmd")
    with _symbolic_numpy():
        absolute = np.concatenate([q0 + state[:n], q0 + state[n:2 * n],
                                   [state[2 * n]]])
        q_d, v_d = interpolated_command(absolute, t, params.command_period)
        # At a sample, q_d is where the interpolation got to.
        dynamics = np.concatenate([q_d - q0, command - q0, [t]])
    return SymbolicVectorSystem(
        time=t, state=state, input=command, dynamics=dynamics,
        output=np.concatenate([q_d, v_d]),
        time_period=params.command_period)


def arm_interpolator_state(positions, time, initial_positions=None):
    """The state of `arm_interpolator_system(params, initial_positions)`
    holding the arm at `positions` (n,) from `time` on."""
    q0 = arm_start(initial_positions)
    q = as_vector("positions", positions, q0.size) - q0
    return np.concatenate([q, q, [time]])

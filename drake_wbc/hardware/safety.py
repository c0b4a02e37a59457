"""The controller side's safety: a watchdog on the robot's status and the
saturation of every command before it is sent.

Pure functions first (`saturate_base_velocity`, `saturate_arm_command`,
`guarded_commands`), then `CommandGuard`, the Drake system thin over them
that sits between the controller's command outputs and the LCM
publishers inside the hardware interface (drake_wbc.hardware.interface).
"""

import logging
from typing import NamedTuple

import numpy as np
from pydrake.systems.framework import LeafSystem

from drake_wbc.hardware.options import HardwareOptions
from drake_wbc.math.validation import (
    as_vector,
    checked_instance,
    ordered_limits,
    positive,
)
from drake_wbc.robot.model import HOME_ARM_POSITIONS, ArmKinematics

LOG = logging.getLogger("drake_wbc.hardware")

AGE_TOLERANCE = 1e-9
"""s: an age equal to the watchdog limit up to rounding is not over it."""

GUARD_STATUS = ("watchdog_tripped", "watchdog_trips",
                "base_command_saturated", "arm_command_saturated",
                "invalid_commands")
"""The entries of CommandGuard's `status` output."""


class Limits(NamedTuple):
    """What the robot may be sent.

    Attributes:
        base_speed: the largest planar speed, m/s.
        base_yaw_rate: the largest yaw rate, rad/s.
        joint_speed: (6,) the largest joint speeds, rad/s.
        lower, upper: (6,) the joints' position limits, rad.
    """

    base_speed: float
    base_yaw_rate: float
    joint_speed: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def of_robot(cls, options=None, arm=None):
        """The limits of `options` (HardwareOptions, its defaults if None)
        and the joint position limits of the robot model (drake_wbc.
        robot_model; `arm` an ArmKinematics, a new one if None)."""
        options = checked_instance("options", options, HardwareOptions,
                                   HardwareOptions)
        arm = checked_instance("arm", arm, ArmKinematics, ArmKinematics)
        return cls(options.base_speed_limit, options.base_yaw_rate_limit,
                   np.full(6, options.joint_speed_limit), arm.lower.copy(),
                   arm.upper.copy())


def saturate_base_velocity(velocity, speed_limit, yaw_rate_limit):
    """[vx, vy, wz] with the planar speed scaled down to `speed_limit`
    (its direction kept) and wz clipped to +-`yaw_rate_limit`.

    Returns:
        (velocity (3,), True if anything was changed).
    """
    velocity = as_vector("velocity", velocity, 3).copy()
    speed_limit = positive("speed_limit", speed_limit)
    yaw_rate_limit = positive("yaw_rate_limit", yaw_rate_limit)
    speed = np.hypot(velocity[0], velocity[1])
    changed = False
    if speed > speed_limit:
        velocity[:2] *= speed_limit / speed
        changed = True
    if abs(velocity[2]) > yaw_rate_limit:
        velocity[2] = np.clip(velocity[2], -yaw_rate_limit, yaw_rate_limit)
        changed = True
    return velocity, changed


def saturate_arm_command(command, last, period, limits):
    """A joint position command moved no faster than the joint speed
    limits from the `last` command sent, `period` s before, and kept
    within the joint position limits.

    Args:
        command: (6,) the controller's command, rad.
        last: (6,) the last command sent, rad.
        period: s between the two, > 0.
        limits: Limits.

    Returns:
        (command (6,), True if anything was changed).
    """
    command = as_vector("command", command, 6)
    last = as_vector("last", last, 6)
    period = positive("period", period)
    lower, upper = ordered_limits("limits.lower", limits.lower,
                                  "limits.upper", limits.upper, 6)
    step = period * as_vector("limits.joint_speed", limits.joint_speed, 6)
    result = np.clip(np.clip(command, last - step, last + step), lower, upper)
    return result, bool(np.any(result != command))


class GuardedCommands(NamedTuple):
    """What CommandGuard sends for one control period.

    Attributes:
        base: (3,) base velocity command.
        arm: (6,) arm position command.
        tripped: the watchdog stopped the commands.
        base_saturated, arm_saturated: a command was limited.
        invalid: the controller's command was not finite (so not sent).
    """

    base: np.ndarray
    arm: np.ndarray
    tripped: bool
    base_saturated: bool
    arm_saturated: bool
    invalid: bool


def guarded_commands(base, arm, last_arm, ages, watchdog_limit, period,
                     limits):
    """The commands to send, given the controller's and the status ages.

    When a status age exceeds `watchdog_limit`, or a command of the
    controller is not finite, the base gets zero velocity and the arm
    keeps `last_arm` (it holds where it was sent last); otherwise both
    commands are saturated (saturate_base_velocity, saturate_arm_command).

    Args:
        base: (3,) the controller's base velocity command.
        arm: (6,) the controller's arm position command.
        last_arm: (6,) the last arm command sent.
        ages: the ages of the statuses watched, s (inf: never received).
        watchdog_limit: s, > 0.
        period: s between commands.
        limits: Limits.

    Returns:
        GuardedCommands.
    """
    base = np.asarray(base, dtype=float)
    arm = np.asarray(arm, dtype=float)
    last_arm = as_vector("last_arm", last_arm, 6)
    stale = bool(np.any(np.asarray(ages, dtype=float)
                        > watchdog_limit + AGE_TOLERANCE))
    invalid = not (np.all(np.isfinite(base)) and np.all(np.isfinite(arm)))
    if stale or invalid:
        return GuardedCommands(np.zeros(3), last_arm.copy(), stale, False,
                               False, invalid)
    base, base_saturated = saturate_base_velocity(
        base, limits.base_speed, limits.base_yaw_rate)
    arm, arm_saturated = saturate_arm_command(arm, last_arm, period, limits)
    return GuardedCommands(base, arm, False, base_saturated, arm_saturated,
                           False)


class CommandGuard(LeafSystem):
    """The watchdog and the saturation of the commands to the robot.

    ::

                                   ┌──────────────┐
          base_velocity_command ──►│              ├──► base_velocity_command
          arm_position_command ───►│ CommandGuard ├──► arm_position_command
          status_ages ────────────►│              ├──► status
                                   └──────────────┘

    - base_velocity_command: (3) the controller's [vx, vy, wz] in T_b.
    - arm_position_command: (6) the controller's joint positions.
    - status_ages: (n) the ages of the statuses watched (the base's and
      the arm's), s.
    - base_velocity_command, arm_position_command (outputs): what is
      sent, from state: zero and the last arm command sent while the
      watchdog is tripped, the saturated commands otherwise
      (`guarded_commands`).
    - status: (5) GUARD_STATUS: watchdog tripped (0/1), how many times it
      tripped, base and arm command saturated (0/1, this period), how
      many controller commands were not finite.

    A periodic discrete update every `options.publish_period` s, at
    `options.guard_offset` after each control tick (so the controller's
    commands of that tick are taken), stores what is sent; the LCM
    publishers send it at `options.publish_offset`. The watchdog says so
    once on the `drake_wbc.hardware` logger when it trips, and once when
    the commands resume. A plain double LeafSystem (it branches on ages
    and limits and is never linearised).

    Args:
        options: HardwareOptions (periods, watchdog limit, base and joint
            speed limits).
        initial_arm_positions: (6,) the arm command held before the first
            command (the robot's measured positions; `set_arm_command`
            sets it in a context).
        num_statuses: how many status ages are watched.
        limits: Limits (Limits.of_robot(options) if None).
    """

    def __init__(self, options=None, initial_arm_positions=HOME_ARM_POSITIONS,
                 num_statuses=2, limits=None):
        super().__init__()
        self.options = checked_instance("options", options, HardwareOptions,
                                        HardwareOptions)
        self.limits = limits or Limits.of_robot(self.options)
        initial = as_vector("initial_arm_positions", initial_arm_positions, 6)
        self._base_in = self.DeclareVectorInputPort("base_velocity_command", 3)
        self._arm_in = self.DeclareVectorInputPort("arm_position_command", 6)
        self._ages = self.DeclareVectorInputPort("status_ages", num_statuses)
        # [base (3), arm (6), tripped, trips, base sat., arm sat., invalid]
        self._state = self.DeclareDiscreteState(
            np.concatenate([np.zeros(3), initial, np.zeros(5)]))
        self.DeclarePeriodicDiscreteUpdateEvent(
            self.options.publish_period, self.options.guard_offset,
            self._update)
        ticket = {self.discrete_state_ticket(self._state)}
        self.DeclareVectorOutputPort(
            "base_velocity_command", 3, lambda c, o: o.SetFromVector(
                self._stored(c)[:3]), prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort(
            "arm_position_command", 6, lambda c, o: o.SetFromVector(
                self._stored(c)[3:9]), prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort(
            "status", len(GUARD_STATUS), lambda c, o: o.SetFromVector(
                self._stored(c)[9:]), prerequisites_of_calc=ticket)

    def _stored(self, context):
        return context.get_discrete_state(self._state).CopyToVector()

    def set_arm_command(self, context, positions):
        """Sets the arm command held (and the base command to zero) in
        `context` (this system's or a root context holding it)."""
        context = self.GetMyMutableContextFromRoot(context)
        x = self._stored(context)
        x[:3] = 0.0
        x[3:9] = as_vector("positions", positions, 6)
        context.SetDiscreteState(self._state, x)

    def _update(self, context, discrete_state):
        x = self._stored(context)
        ages = self._ages.Eval(context)
        result = guarded_commands(
            self._base_in.Eval(context), self._arm_in.Eval(context), x[3:9],
            ages, self.options.watchdog_limit, self.options.publish_period,
            self.limits)
        was_tripped = x[9] > 0.5
        if result.tripped and not was_tripped:
            LOG.warning(
                "watchdog tripped at t = %.3f s: status ages %s s (limit "
                "%.3f s); sending zero base velocity and holding the arm",
                context.get_time(), np.array2string(ages, precision=3),
                self.options.watchdog_limit)
        elif was_tripped and not result.tripped:
            LOG.warning("watchdog cleared at t = %.3f s: fresh status, the "
                        "commands resume", context.get_time())
        if result.invalid:
            LOG.warning("the controller's command at t = %.3f s is not "
                        "finite; not sent", context.get_time())
        trips = x[10] + (1.0 if result.tripped and not was_tripped else 0.0)
        discrete_state.set_value(self._state, np.concatenate([
            result.base, result.arm,
            [float(result.tripped), trips, float(result.base_saturated),
             float(result.arm_saturated), x[13] + float(result.invalid)]]))

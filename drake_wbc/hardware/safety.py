"""What the commands on the wire may be, on both sides of the protocol: the
controller side's watchdog and command limits, and the robot side's own
limit on the arm's commands.

Pure functions first: the limits of the robot (`Limits`), the base's
command within its speed and acceleration limits
(`saturate_base_velocity`, `limit_base_command`), the arm's position
command within its rate and acceleration limits (`follow_arm_command`,
`stop_arm`), and one check of the command guard (`guard_step`). Then
the Drake systems thin over them: `CommandGuard`, between the
controller's command outputs and the LCM publishers inside the hardware
interface (drake_wbc.hardware.interface), and `ArmCommandLimiter`,
between the robot side's command receiver and its arm
(drake_wbc.deployment.robot_side).

The promises (drake_wbc/hardware/README.md): every arm command sent is
within the joint position limits and within the joint speed and
acceleration limits of the one before, after a stop too, but where the
arm is not where the one before sent it: after a stop, and when the
controller restarts its arm command from where the arm is, an arm found
farther than the tolerance from the last command sent is commanded
from where it is instead, at rest, and within the limits as it sees
them (`resync_arm`; not from a measurement beyond the limits, from
which the command, held within them, would jump); every base
command is within the base's speed limits, and within its acceleration
limits of the one before except a stop, which is zero at once (the
base's own velocity loop brakes within its limits); a stale stream stops
what depends on it within its watchdog limit and one watchdog period
(the stop goes out at the next period, not the next control tick); a
sender's clock that jumps, and a stall of the controller's own process
long enough for the robot to stop on its command timeout (WallClock),
are stale streams; and the commands resume only after every stream
behind the stop has been fresh for the recovery time.
"""

import logging
import math
import time
from typing import NamedTuple

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from drake_wbc.hardware.options import (
    STATUS_CHANNELS,
    HardwareOptions,
    command_timeout_of,
)
from drake_wbc.math.arm_control import start_within_limits
from drake_wbc.math.arm_servo import brake_arm, brake_speed, catch_up_arm
from drake_wbc.math.command_limits import ROUNDING, limit_base_velocity
from drake_wbc.math.safety import (
    DEFAULT_ARM_FOLLOW_TOLERANCE,
    VALID,
    Restart,
    check_following,
    check_vector,
    limit_slack,
    restart_position,
)
from drake_wbc.math.validation import (
    as_vector,
    checked_instance,
    positive,
)
from drake_wbc.robot.model import HOME_ARM_POSITIONS, ArmKinematics

LOG = logging.getLogger("drake_wbc.hardware")

AGE_TOLERANCE = 1e-9
"""s: an age equal to the watchdog limit up to rounding is not over it."""

FULL_STOP_STREAMS = ("base_state", "arm_status", "wrist_wrench")
"""The streams whose staleness stops everything: no base motion without
odometry, no arm motion without the arm's state, and no force control,
pHRI or compliance (the arm's DMP reads the wrench in every mode, eq.
(cdmp-arm)) without a fresh wrench. A stale obstacle_points stream stops
the base alone."""

GUARD_STATUS = ("watchdog_tripped", "watchdog_trips", "base_stopped",
                "base_stops", "base_command_saturated",
                "arm_command_saturated", "invalid_commands",
                "check_interval")
"""The entries of CommandGuard's `status` output: the full stop (0/1; 1
also at the start until the streams' first messages) and how many began
while the commands ran, the base's stop for want of fresh obstacle
points (0/1, likewise) and how many, a command limited this period (0/1
each), how many controller commands were not finite, and the wall
clock's time between the last two checks, in controller seconds
(WallClock; 0 on simulated time; the checks' period while the controller
keeps pace)."""


class Limits(NamedTuple):
    """What the robot may be sent.

    Attributes:
        base_speed: the largest planar speed, m/s.
        base_yaw_rate: the largest yaw rate, rad/s.
        base_acceleration: (3,) the largest change of [vx, vy, wz], m/s^2,
            m/s^2, rad/s^2.
        joint_speed: (n,) the largest joint speeds, rad/s.
        joint_acceleration: (n,) the largest joint accelerations, rad/s^2.
        lower, upper: (n,) the joints' position limits, rad (n the arm's
            joints).
        command_timeout: the robot side stops its base when no command
            came for this long, s (`command_timeout_of`; inf: never).
    """

    base_speed: float
    base_yaw_rate: float
    base_acceleration: np.ndarray
    joint_speed: np.ndarray
    joint_acceleration: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    command_timeout: float = math.inf

    @classmethod
    def of_robot(cls, options=None, arm=None):
        """The limits of `options` (HardwareOptions, its defaults if None)
        and the joint position limits of the arm (`arm` an ArmKinematics
        of the robot, the shipped robot's if None): the arm's own limits,
        whatever arm it is.

        Raises:
            ValueError: when one of the options' base or joint speed or
                acceleration limits, the robot side's command timeout or a
                watchdog limit is beyond the robot's own (a limit may
                tighten the robot's, never widen it; `command_timeout_of`).
        """
        options = checked_instance("options", options, HardwareOptions,
                                   HardwareOptions)
        arm = checked_instance("arm", arm, ArmKinematics, ArmKinematics)
        base = arm.model.description.base
        timeout = command_timeout_of(options, base)
        speed, acceleration = arm_own_limits(arm)
        own = {"base_speed_limit": (min(base.velocity_limits[:2]), "m/s"),
               "base_yaw_rate_limit": (base.velocity_limits[2], "rad/s"),
               "base_acceleration_limit": (min(base.acceleration_limits[:2]),
                                           "m/s^2"),
               "base_yaw_acceleration_limit": (base.acceleration_limits[2],
                                               "rad/s^2"),
               "joint_speed_limit": (speed, "rad/s"),
               "joint_acceleration_limit": (acceleration, "rad/s^2")}
        value = {}
        for name, (robots, unit) in own.items():
            given = getattr(options, name)
            if given is None:
                value[name] = robots
                continue
            if given > np.min(robots):
                raise ValueError(
                    f"hardware.{name} = {given!r} is not allowed: must be at "
                    f"most the robot's own {float(np.min(robots))!r} {unit}")
            value[name] = (np.full(arm.num_joints, float(given))
                           if np.ndim(robots) else float(given))
        return cls(value["base_speed_limit"], value["base_yaw_rate_limit"],
                   np.array([value["base_acceleration_limit"],
                             value["base_acceleration_limit"],
                             value["base_yaw_acceleration_limit"]]),
                   np.array(value["joint_speed_limit"], dtype=float),
                   np.array(value["joint_acceleration_limit"], dtype=float),
                   arm.lower.copy(), arm.upper.copy(), float(timeout))


def arm_own_limits(arm):
    """(joint speed limits (n,), joint acceleration limits (n,)) of the
    arm (`arm` an ArmKinematics): the robot's own, from its model and
    description (drake_wbc.robot.model.RobotModel.limits)."""
    return (np.asarray(arm.velocity_limits, dtype=float),
            np.asarray(arm.acceleration_limits, dtype=float))


def saturate_base_velocity(velocity, speed_limit, yaw_rate_limit):
    """[vx, vy, wz] with the planar speed scaled down to `speed_limit`
    (its direction kept) and wz clipped to +-`yaw_rate_limit`.

    Returns:
        (velocity (3,), True if anything was changed).
    """
    return _saturate_base(as_vector("velocity", velocity, 3),
                          positive("speed_limit", speed_limit),
                          positive("yaw_rate_limit", yaw_rate_limit))


def _saturate_base(velocity, speed_limit, yaw_rate_limit):
    velocity = np.array(velocity, dtype=float)
    speed = math.hypot(velocity[0], velocity[1])
    changed = False
    if speed > speed_limit * (1.0 + ROUNDING):
        velocity[:2] *= speed_limit / speed
        changed = True
    if abs(velocity[2]) > yaw_rate_limit * (1.0 + ROUNDING):
        velocity[2] = math.copysign(yaw_rate_limit, velocity[2])
        changed = True
    return velocity, changed


def limit_base_command(command, last, period, limits):
    """The base command to send: `command` [vx, vy, wz] within the speed
    limits (`_saturate_base`), then its change from `last` (the last one
    sent, `period` s before) scaled as a whole into the acceleration
    limits (drake_wbc.math.command_limits.limit_base_velocity), so that it
    keeps its direction. A command within both is sent unchanged.

    Returns:
        (command (3,), True if a limit changed it).
    """
    velocity, changed = _saturate_base(command, limits.base_speed,
                                       limits.base_yaw_rate)
    limited = limit_base_velocity(
        velocity, last, (math.inf,) * 3,
        limits.base_acceleration * (1.0 + ROUNDING), period)
    return np.asarray(limited.command, dtype=float), (
        changed or limited.acceleration_scale < 1.0)


TARGET_RATE_BOUND = 1e150
"""rad/s: the largest target rate `follow_arm_command` takes as it is.
Any rate beyond it is far beyond every joint's limits (so the joint
follows it at its limits, as it would the rate itself), and the target's
distance and `brake_speed` computed from it stay finite: a finite target
near the largest float (1e306 rad) once turned the commands into NaN."""


def follow_arm_command(target, target_velocity, last, velocity, period,
                       limits):
    """The next arm position command towards `target` within the limits.

    A target within the joint position limits whose step from `last`
    (the last command sent, moving at `velocity`) is within the joint
    speed limits, differs from `velocity` and from `target_velocity` by
    no more than the acceleration limits allow in one period (so that the
    joint can go on with the target, or stop with it), and towards each
    position limit at no more than the `brake_speed` of the distance to
    it (so that the joint can still stop there), is sent as it is, bit
    for bit. Otherwise each joint follows the target (held within the
    position limits), which moves at `target_velocity`, as fast as the
    limits allow without overshooting it: relative to the target it
    moves at `brake_speed` of the distance between them, its speed is at
    most the speed limit and the `brake_speed` towards each position
    limit, and its change of speed at most the acceleration limit.

    Args:
        target: (n,) the command asked for, rad.
        target_velocity: (n,) the rate at which the target moves, rad/s
            (the change of the commands asked for over one period).
        last: (n,) the last command sent, rad.
        velocity: (n,) its rate, rad/s.
        period: h, s between commands.
        limits: Limits.

    Returns:
        (command (n,), its rate (n,), True if the limits changed it).
    """
    speed, accel = limits.joint_speed, limits.joint_acceleration
    change = accel * period * (1.0 + ROUNDING)
    step = target_rate(target, last, period)
    # The speeds towards the position limits from which the joint can
    # still stop at them (a target running into a limit at full speed
    # was followed there, and stopped at it within a period).
    up = brake_speed(np.maximum(limits.upper - last, 0.0), accel, period)
    down = brake_speed(np.maximum(last - limits.lower, 0.0), accel, period)
    if (np.all(np.abs(step) <= speed * (1.0 + ROUNDING))
            and np.all(step <= up * (1.0 + ROUNDING))
            and np.all(-step <= down * (1.0 + ROUNDING))
            and np.all(np.abs(step - velocity) <= change)
            and np.all(np.abs(step - target_velocity) <= change)
            and np.all(target >= limits.lower)
            and np.all(target <= limits.upper)):
        return np.array(target, dtype=float), step, False
    held = np.clip(target, limits.lower, limits.upper)
    # A rate beyond TARGET_RATE_BOUND (a target that jumped from near the
    # largest float) is bounded, so that nothing below overflows to NaN;
    # the joint follows it at its limits all the same.
    moving = np.clip(np.where(held == target, target_velocity, 0.0),
                     -TARGET_RATE_BOUND, TARGET_RATE_BOUND)
    command, _ = catch_up_arm(last, velocity, held, period, speed, accel,
                              target_velocity=moving, bounds=(down, up))
    command = np.clip(command, limits.lower, limits.upper)
    return command, (command - last) / period, True


def target_rate(target, before, period):
    """(target - before) / period, the rate of an arm target between two
    commands: +-inf where it overflows (a finite target near the largest
    float, forged or not), without numpy's warning; follow_arm_command
    bounds it (TARGET_RATE_BOUND)."""
    with np.errstate(over="ignore"):
        return (target - before) / period


def stop_arm(last, velocity, period, limits):
    """The next arm position command of a stop: each joint slows down from
    `velocity` at its acceleration limit and holds where it comes to rest
    (within the position limits), as the arm's own servo stops on a fault
    (drake_wbc.math.arm_servo.brake_arm, with `limits`, a Limits).

    Returns:
        (command (n,), its rate (n,)).
    """
    return brake_arm(last, velocity, period, limits.joint_acceleration,
                     limits.lower, limits.upper)


class GuardState(NamedTuple):
    """What the command guard keeps between two checks.

    Attributes:
        base: (3,) the base command to send.
        arm: (n,) the arm command to send, and arm_velocity (n,) its rate.
        target: (n,) the controller's arm command at the last command
            time (the rate at which the target moves follows from it).
        full_stop: the watchdog stops everything (base zero, the arm
            stopping within its limits); also at the start, until every
            stream of FULL_STOP_STREAMS has its first message.
        base_stop: the base is stopped for want of fresh obstacle points
            (also until the first ones).
        started: the commands have run (they wait for every stream's
            first message at the start; that is no trip).
        trips, base_stops: how many full stops and base stops began.
        base_saturated, arm_saturated: a limit changed the command of the
            last command time.
        invalid: how many controller commands were not finite.
        not_finite: the controller's command at the last command time was
            not finite.
        fresh_since: (4,) per stream of STATUS_CHANNELS, since when it has been
            fresh (nan: stale now).
        recovering: (4,) per stream, it went stale after being fresh, so
            it must be fresh for the recovery time before it counts.
        urgent: a stop began at this check, between two command times:
            the base's zero goes out at the next check (CommandGuard's
            `urgent` output).
        clock_jumps: (4,) per stream, how many times its sender's clock
            had jumped at the last check (the decoders' counts).
        wall_time: the wall clock at the last check, in controller
            seconds (WallClock.now; nan: none, on simulated time).
        check_interval: the wall clock's time between the last two
            checks, in controller seconds (0 on simulated time).
        command_wall_time: the wall clock at the last command time, in
            controller seconds (nan: none, on simulated time).
        arm_resync: the arm was found away from `arm` (`resync_arm`):
            the arm command restarted from its measured position, at
            rest, and holds there until the controller's command is
            within the tolerance of it.
    """

    base: np.ndarray
    arm: np.ndarray
    arm_velocity: np.ndarray
    target: np.ndarray
    full_stop: bool = True
    base_stop: bool = True
    started: bool = False
    trips: int = 0
    base_stops: int = 0
    base_saturated: bool = False
    arm_saturated: bool = False
    invalid: int = 0
    not_finite: bool = False
    fresh_since: tuple = (math.nan,) * len(STATUS_CHANNELS)
    recovering: tuple = (False,) * len(STATUS_CHANNELS)
    urgent: bool = False
    clock_jumps: tuple = (0,) * len(STATUS_CHANNELS)
    wall_time: float = math.nan
    check_interval: float = 0.0
    command_wall_time: float = math.nan
    arm_resync: bool = False

    def __deepcopy__(self, memo):
        # Never changed in place (only replaced), so the copies that Drake
        # makes of an abstract state at each update may share it.
        return self

    @classmethod
    def holding(cls, arm_positions):
        """The state at the start: the arm held at `arm_positions`, the
        base at rest, waiting for every stream."""
        arm = np.array(arm_positions, dtype=float)
        return cls(np.zeros(3), arm, np.zeros_like(arm), arm.copy())


class GuardConfig(NamedTuple):
    """The command guard's fixed settings.

    Attributes:
        watchdog_limits: (4,) per stream of STATUS_CHANNELS, s.
        recovery_time: s.
        period: the command period, s.
        limits: Limits.
        arm_follow_tolerance: rad, how far the measured arm may be from
            the last command sent before it counts as elsewhere
            (`resync_arm`).
    """

    watchdog_limits: tuple
    recovery_time: float
    period: float
    limits: Limits
    arm_follow_tolerance: float = DEFAULT_ARM_FOLLOW_TOLERANCE

    @classmethod
    def of(cls, options, limits=None,
           arm_follow_tolerance=DEFAULT_ARM_FOLLOW_TOLERANCE):
        """The settings of a HardwareOptions (Limits.of_robot(options) if
        `limits` is None) and the controller's arm tolerance (its
        SafetyParameters.arm_follow_tolerance).

        Raises:
            ValueError: naming arm_follow_tolerance when it is not finite
                and > 0.
        """
        return cls(options.watchdog_limits.as_tuple(),
                   options.watchdog_recovery_time, options.publish_period,
                   limits or Limits.of_robot(options),
                   positive("arm_follow_tolerance", arm_follow_tolerance))


def stall_limit(config):
    """The longest time on the wall clock between two checks of the
    guard, s: the robot's command timeout less one command period (the
    last command before a stall went out up to a period before it),
    beyond which the robot has stopped its base on its own (GuardConfig
    `config`)."""
    return config.limits.command_timeout - config.period


def resync_arm(state, measured, config):
    """The GuardState `state` with its arm command restarted from where
    the arm is, when it is elsewhere.

    The guard sends what it limited from what it sent last
    (`follow_arm_command`). An arm that is farther than
    `config.arm_follow_tolerance` from that (moved by hand, or stopped
    on its own, during a stop) would be asked to jump back to it. So its
    command restarts from its measured position (within the joint
    limits: drake_wbc.math.safety.restart_position, the controller's
    rule), at rest, and holds there (`arm_resync`) until the
    controller's command is within the tolerance of it (the controller
    resumes from where the arm is too, drake_wbc.controller.diagram).
    An arm where the last command was, or no measurement (None), leaves
    `state` as it is; so does an arm measured farther beyond a joint's
    limits than one period's step at its acceleration limit from rest
    (`Restart.beyond`: no position to start from either,
    `start_within_limits`): the command, held within the limits, would
    jump away from it. The command goes on from the last one sent,
    within the limits.

    Returns:
        (GuardState, the Restart of restart_position; its check VALID
        with no measurement).
    """
    if measured is None:
        return state, Restart(VALID, None)
    restart = restart_position(
        np.asarray(measured, dtype=float), state.arm,
        config.arm_follow_tolerance, config.limits.lower,
        config.limits.upper, config.limits.joint_acceleration,
        config.period)
    if restart.start is None:
        return state, restart
    start = restart.start
    return state._replace(arm=start, arm_velocity=np.zeros_like(start),
                          arm_resync=True), restart


def guard_step(state, now, ages, base, arm, command_time, config,
               clock_jumps=None, wall_time=None, arm_measured=None,
               until_command=0.0):
    """One check of the command guard.

    Each stream is fresh while its age is within its watchdog limit; it
    counts once fresh, or, after it went stale, once fresh for
    `config.recovery_time`. A stream whose sender's clock jumped since
    the last check (a restart or a clock step of the robot, or another
    sender on its channel) is stale at this check: its freshness is not
    to be judged across the jump. When the wall clock ran longer since
    the last check than the robot's command timeout less a command
    period (`stall_limit`: the controller's process missed the processor
    so long, its own clock standing still), the robot has stopped its
    base on its own timeout meanwhile: every stream is stale at this
    check, so that the commands resume from rest after the recovery time
    (a shorter stall is as a late message: the robot still runs the last
    command, and the commands go on from it). So, too, when the wall
    clock since the last command time and the controller's time to the
    next one (`until_command`) are longer than the robot's command
    timeout together, however short each check: a controller so slow
    that its commands come further apart than the robot waits for one
    (each goes out at the same offset after its command time, so the
    robot waits at least that long for the next). A stream of
    FULL_STOP_STREAMS that does not count stops everything;
    obstacle_points stop the base. A stop that begins
    between command times zeroes the base at once (`urgent`). At a
    command time the commands to send are computed: in a full stop (or
    for a controller command that is not finite) zero base velocity and
    the arm stopping (`stop_arm`); otherwise the arm following the
    controller's (`follow_arm_command`) and the base zero in a base stop,
    else the controller's within the limits (`limit_base_command`), from
    what was sent last, so nothing jumps when the commands resume. The
    arm's from where it is (`resync_arm`) when it is elsewhere at the
    check at which a full stop ends (the commands start, or resume), or
    at a command time at which the controller's command moved farther
    than the tolerance since the last one (no joint moves that fast:
    the controller restarted from where the arm is).

    Args:
        state: GuardState.
        now: the check's time, s.
        ages: (4,) the streams' ages, s (inf: never received).
        base: (3,) the controller's base command.
        arm: (n,) the controller's arm command.
        command_time: whether this check computes the commands to send.
        config: GuardConfig.
        clock_jumps: (4,) per stream, how many times its sender's clock
            has jumped (the decoders' Reception.clock_jumps); None: none.
        wall_time: the wall clock now, in controller seconds
            (WallClock.now); None on simulated time.
        arm_measured: (n,) the arm's measured positions (the arm_status
            stream's), rad; None: not known (no `resync_arm`).
        until_command: the controller's time from this check to the next
            command time, s (0 at one).

    Returns:
        (GuardState, list of (event, detail) for the log: "tripped",
        "cleared", "base stopped", "base cleared", "started", "arm
        elsewhere", "arm beyond its limits", and "not finite" and
        "finite" when the controller's command becomes not finite, and
        finite again, at a command time).
    """
    jumps = state.clock_jumps if clock_jumps is None else tuple(
        int(count) for count in clock_jumps)
    interval = (0.0 if wall_time is None or math.isnan(state.wall_time)
                else wall_time - state.wall_time)
    since_command = (
        0.0 if wall_time is None or math.isnan(state.command_wall_time)
        else wall_time - state.command_wall_time)
    stalled = interval > stall_limit(config) + AGE_TOLERANCE
    waits = since_command + (0.0 if command_time else until_command)
    lagging = stalled or (
        wall_time is not None
        and waits > config.limits.command_timeout + AGE_TOLERANCE)
    fresh_since, recovering, counts, why = [], [], [], []
    for i, age in enumerate(ages):
        since, again = state.fresh_since[i], state.recovering[i]
        jumped = jumps[i] > state.clock_jumps[i]
        if age <= config.watchdog_limits[i] + AGE_TOLERANCE and not (
                lagging or jumped):
            since = now - age if math.isnan(since) else since
            counts.append(not again or now - since
                          >= config.recovery_time - AGE_TOLERANCE)
        else:
            again = again or not math.isnan(since)
            since = math.nan
            counts.append(False)
        fresh_since.append(since)
        recovering.append(again)
        if not counts[-1] and not lagging:
            why.append(f"{STATUS_CHANNELS[i]} (its sender's clock jumped)"
                       if jumped else
                       f"{STATUS_CHANNELS[i]} (age {age:.3f} s, limit "
                       f"{config.watchdog_limits[i]:.3f} s)")
    full = not all(counts[STATUS_CHANNELS.index(n)] for n in FULL_STOP_STREAMS)
    lidar = STATUS_CHANNELS.index("obstacle_points")
    base_stop = not counts[lidar]
    stale = ", ".join(why) if not lagging else (
        f"every stream: {interval:.3f} s of wall clock passed since the "
        f"last check (limit {stall_limit(config):.3f} s): the controller's "
        "process missed the processor for longer than the robot waits for "
        "a command") if stalled else (
        f"every stream: {since_command:.3f} s of wall clock passed since "
        f"the last command time, the next {waits - since_command:.3f} s "
        f"away at the least (limit {config.limits.command_timeout:.3f} s "
        "together): the controller runs too slowly for the robot, which "
        "stops its base when no command comes for that long")
    events = []
    tripped = full and not state.full_stop and state.started
    if tripped:
        events.append(("tripped", stale))
    elif state.full_stop and not full:
        events.append(("cleared" if state.started else "started", ""))
    base_stopped = base_stop and not state.base_stop and state.started
    # The base's own stop and recovery are said while the rest runs (a
    # full stop's words cover the base).
    if base_stopped and not full:
        events.append(("base stopped", stale))
    elif (state.base_stop and not base_stop and recovering[lidar]
          and not full):
        events.append(("base cleared", ""))
    new = state._replace(
        full_stop=full, base_stop=base_stop,
        started=state.started or not full,
        trips=state.trips + tripped,
        base_stops=state.base_stops + base_stopped,
        fresh_since=tuple(fresh_since), recovering=tuple(recovering),
        urgent=False, clock_jumps=jumps,
        wall_time=math.nan if wall_time is None else float(wall_time),
        check_interval=float(interval),
        command_wall_time=(
            (math.nan if wall_time is None else float(wall_time))
            if command_time else state.command_wall_time))
    if state.full_stop and not full:
        new = _resync(new, arm_measured, config, events)
    if not command_time:
        if (tripped or base_stopped) and np.any(state.base != 0.0):
            new = new._replace(base=np.zeros(3), urgent=True)
        return new, events
    h, limits = config.period, config.limits
    bad = _not_finite(base, arm)
    invalid = bad is not None
    if invalid and not state.not_finite:
        events.append(("not finite", bad))
    elif state.not_finite and not invalid:
        events.append(("finite", ""))
    new = new._replace(not_finite=invalid)
    if full or invalid:
        q, v = stop_arm(new.arm, new.arm_velocity, h, limits)
        return new._replace(
            base=np.zeros(3), arm=q, arm_velocity=v,
            target=state.target if invalid else np.array(arm, dtype=float),
            base_saturated=False, arm_saturated=False,
            invalid=state.invalid + invalid,
            arm_resync=new.arm_resync and not full), events
    arm = np.array(arm, dtype=float)
    tolerance = config.arm_follow_tolerance
    if not check_following(arm, state.target, tolerance).valid:
        new = _resync(new, arm_measured, config, events)
    if new.arm_resync and not check_following(
            arm, new.arm, tolerance).valid:
        # Held where the arm is until the controller's command is near.
        q, v, arm_saturated = new.arm, np.zeros_like(new.arm), True
    else:
        # After a restart the target moves from where the arm is (the
        # controller resumed there, at rest), not from its old command.
        q, v, arm_saturated = follow_arm_command(
            arm, target_rate(arm, new.arm if new.arm_resync
                             else state.target, h), new.arm,
            new.arm_velocity, h, limits)
        new = new._replace(arm_resync=False)
    if base_stop:
        sent, base_saturated = np.zeros(3), False
    else:
        sent, base_saturated = limit_base_command(base, state.base, h,
                                                  limits)
    return new._replace(base=sent, arm=q, arm_velocity=v, target=arm,
                        base_saturated=base_saturated,
                        arm_saturated=arm_saturated), events


def _not_finite(base, arm):
    """The first entry of the controller's commands that is not finite,
    as "port[i] = value" (the base's velocity command first, then the
    arm's position command: CommandGuard's input ports), or None."""
    for port, values in (("base_velocity_command", base),
                         ("arm_position_command", arm)):
        check = check_vector(values)
        if not check.valid:
            return f"{port}[{check.entry}] = {check.value!r}"
    return None


def _resync(state, measured, config, events):
    """`resync_arm` of `state`, its event added to `events` when the
    arm was elsewhere, or beyond its limits."""
    state, restart = resync_arm(state, measured, config)
    check, j = restart.check, restart.beyond
    if j >= 0:
        limits = config.limits
        slack = limit_slack(limits.joint_acceleration[j], config.period)
        events.append(("arm beyond its limits", (
            f"joint {j} reads {measured[j]:.6g} rad, beyond its limits "
            f"[{limits.lower[j]:.6g}, {limits.upper[j]:.6g}] rad by more "
            f"than {slack:.3g} rad, and is {abs(check.value):.3g} "
            f"rad from the last command sent (tolerance "
            f"{config.arm_follow_tolerance:g} rad)")))
    elif not check.valid:
        events.append(("arm elsewhere", (
            f"joint {check.entry} is {abs(check.value):.3g} rad from the "
            f"last command sent (tolerance "
            f"{config.arm_follow_tolerance:g} rad)")))
    return state


class WallClock:
    """The wall clock of a controller running in real time.

    A deployed controller measures its streams' ages on its own clock,
    the Simulator's, which stands still while its process misses the
    processor (the scheduler, a swap, a stop signal) and then runs fast
    to catch up. Meanwhile the robot's own command timeout runs on the
    wall clock: its base stops, and the commands computed in the catch-up
    would start it again with a step. The CommandGuard reads `now` at
    each of its checks: a check that finds more of the wall clock passed
    since the one before than the robot's command timeout less a period
    (`stall_limit`) stops everything, and the commands resume from rest
    after the recovery time.

    Args:
        rate: the Simulator's target real-time rate (controller seconds
            a wall-clock second), > 0.
        clock: the wall clock, s (time.monotonic; a test may give its
            own).
    """

    def __init__(self, rate=1.0, clock=time.monotonic):
        self.rate = positive("rate", rate)
        self._clock = clock

    def now(self):
        """The wall clock, in controller seconds (its differences are
        what counts)."""
        return self.rate * self._clock()


class CommandGuard(LeafSystem):
    """The watchdog and the limits of the commands to the robot.

    ::

                                   ┌──────────────┐
          base_velocity_command ──►│              ├──► base_velocity_command
          arm_position_command ───►│ CommandGuard ├──► arm_position_command
          status_ages ────────────►│              ├──► status
                                   │              ├──► urgent
                                   │              ├──► tripped
                                   └──────────────┘

    - base_velocity_command: (3) the controller's [vx, vy, wz] in T_b.
    - arm_position_command: (n) the controller's joint positions (n the
      size of the limits).
    - status_ages: (4) the ages of the streams of STATUS_CHANNELS, s.
    - clock_jumps: optional (none when unconnected), (4) per stream, how
      many times its sender's clock has jumped (the decoders'
      `clock_jumps`): a jump is a stale stream at that check.
    - arm_position_measured: optional (never used when unconnected), (n)
      the arm's measured positions (the arm_status decoder's): after a
      full stop, or when the controller restarts from where the arm is,
      an arm farther than `arm_follow_tolerance` from the last command
      sent is commanded from where it is, at rest (`resync_arm`), never back to
      that command at once.
    - base_velocity_command, arm_position_command (outputs): what is
      sent, from state (`guard_step`).
    - status: (8) GUARD_STATUS.
    - urgent: (1) 1 when a stop began at the last check between two
      command times: a FlaggedPublisher sends the base's zero at once.
    - tripped: (1) 1 during a full stop of the watchdog (not while it
      waits for the streams' first messages): the controller's input
      `hardware.watchdog_tripped`, so that it stops too and resumes from
      rest, not from what it integrated while the robot was stopped.

    A periodic update every `options.watchdog_period` (1 ms) from
    `options.guard_offset` checks the ages; the one at `guard_offset`
    after each control tick also takes the controller's commands of that
    tick and computes what is sent; the LCM publishers send it at
    `options.publish_offset`. Each stop and each recovery, and the
    controller's command becoming not finite and finite again, is said
    once on the `drake_wbc.hardware` logger. A plain double LeafSystem
    (it branches on ages and limits and is never linearised).

    Args:
        options: HardwareOptions (periods, watchdog, limits).
        initial_arm_positions: (n,) the arm command held before the first
            command (the robot's measured positions; `set_arm_command`
            sets it in a context), within the joint limits
            (`start_within_limits`); the shipped robot's home if None,
            which only goes with limits None.
        limits: Limits (Limits.of_robot(options), of the shipped robot,
            if None).
        wall_clock: the WallClock of a controller running in real time
            (drake_wbc.deployment.deploy), which every check reads; None
            on simulated time.
        arm_follow_tolerance: rad > 0, the controller's
            SafetyParameters.arm_follow_tolerance (its default if not
            given).
    """

    def __init__(self, options=None, initial_arm_positions=None,
                 limits=None, wall_clock=None,
                 arm_follow_tolerance=DEFAULT_ARM_FOLLOW_TOLERANCE):
        super().__init__()
        self.wall_clock = checked_instance("wall_clock", wall_clock,
                                           WallClock, lambda: None)
        self.options = options = checked_instance(
            "options", options, HardwareOptions, HardwareOptions)
        self.config = GuardConfig.of(options, limits, arm_follow_tolerance)
        self.limits = self.config.limits
        self.num_joints = n = self.limits.lower.size
        if initial_arm_positions is None and limits is not None:
            # The shipped robot's home is a configuration of its arm only.
            raise ValueError(
                "initial_arm_positions = None is not allowed with limits "
                "given: pass the positions of the limits' arm to hold (its "
                "measured positions, or its home)")
        initial = start_within_limits(
            "initial_arm_positions", HOME_ARM_POSITIONS
            if initial_arm_positions is None else initial_arm_positions,
            self.limits.lower, self.limits.upper,
            self.limits.joint_acceleration, options.publish_period)
        self._checks_per_command = round(options.publish_period
                                         / options.watchdog_period)
        self._base_in = self.DeclareVectorInputPort("base_velocity_command", 3)
        self._arm_in = self.DeclareVectorInputPort("arm_position_command", n)
        self._ages = self.DeclareVectorInputPort("status_ages",
                                                 len(STATUS_CHANNELS))
        self._jumps = self.DeclareVectorInputPort("clock_jumps",
                                                  len(STATUS_CHANNELS))
        self._measured = self.DeclareVectorInputPort(
            "arm_position_measured", n)
        self._state = self.DeclareAbstractState(AbstractValue.Make(
            GuardState.holding(initial)))
        self.DeclarePeriodicUnrestrictedUpdateEvent(
            options.watchdog_period, options.guard_offset, self._update)
        ticket = {self.abstract_state_ticket(self._state)}
        # With a wall clock the base's command is read afresh at every
        # send (time among its prerequisites): see `_base_command`.
        self.DeclareVectorOutputPort(
            "base_velocity_command", 3, self._base_command,
            prerequisites_of_calc=ticket if self.wall_clock is None
            else {*ticket, self.time_ticket()})
        self.DeclareVectorOutputPort(
            "arm_position_command", n, lambda c, o: o.SetFromVector(
                self.stored(c).arm), prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort(
            "status", len(GUARD_STATUS), self._status,
            prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort(
            "urgent", 1, lambda c, o: o.SetAtIndex(
                0, float(self.stored(c).urgent)),
            prerequisites_of_calc=ticket)
        self.DeclareVectorOutputPort(
            "tripped", 1, lambda c, o: o.SetAtIndex(0, float(
                self.stored(c).full_stop and self.stored(c).started)),
            prerequisites_of_calc=ticket)

    def stored(self, context):
        """The GuardState at `context`."""
        return context.get_abstract_state(self._state).get_value()

    def _base_command(self, context, output):
        """The base command to send: the stored one, or zero when more of
        the wall clock passed since the last check than `stall_limit`.
        A stall can end just before a send (the send at a time comes
        before the check at that time), which must then not go out with
        the command of before the stall; the check that follows trips."""
        state = self.stored(context)
        if self.wall_clock is not None and (
                self.wall_clock.now() - state.wall_time
                > stall_limit(self.config) + AGE_TOLERANCE):
            output.SetFromVector(np.zeros(3))
        else:
            output.SetFromVector(state.base)

    def _status(self, context, output):
        s = self.stored(context)
        output.SetFromVector([
            float(s.full_stop), s.trips, float(s.base_stop), s.base_stops,
            float(s.base_saturated), float(s.arm_saturated), s.invalid,
            s.check_interval])

    def set_arm_command(self, context, positions):
        """Holds the arm at `positions` (and the base at rest) in `context`
        (this system's or a root context holding it); `positions` within
        the joint limits (`start_within_limits`)."""
        context = self.GetMyMutableContextFromRoot(context)
        context.SetAbstractState(self._state, GuardState.holding(
            start_within_limits(
                "positions", positions, self.limits.lower,
                self.limits.upper, self.limits.joint_acceleration,
                self.config.period)))

    def _update(self, context, state):
        now = context.get_time()
        check = round((now - self.options.guard_offset)
                      / self.options.watchdog_period)
        command_time = check % self._checks_per_command == 0
        ages = self._ages.Eval(context)
        jumps = (self._jumps.Eval(context) if self._jumps.HasValue(context)
                 else None)
        measured = (self._measured.Eval(context)
                    if self._measured.HasValue(context) else None)
        wall_time = (None if self.wall_clock is None
                     else self.wall_clock.now())
        result, events = guard_step(
            self.stored(context), now, ages, self._base_in.Eval(context),
            self._arm_in.Eval(context), command_time, self.config,
            clock_jumps=jumps, wall_time=wall_time, arm_measured=measured,
            until_command=(-check % self._checks_per_command)
            * self.options.watchdog_period)
        for event, detail in events:
            _say(event, detail, now, self.options)
        state.get_mutable_abstract_state(self._state).set_value(result)


def _say(event, detail, now, options):
    """Logs one of guard_step's events."""
    recovery = options.watchdog_recovery_time
    if event == "tripped":
        LOG.warning("watchdog tripped at t = %.3f s: stale %s; sending zero "
                    "base velocity and stopping the arm within its limits",
                    now, detail)
    elif event == "cleared":
        LOG.warning("watchdog cleared at t = %.3f s: every stream fresh for "
                    "%.3g s; the commands resume within the limits", now,
                    recovery)
    elif event == "base stopped":
        LOG.warning("base stopped at t = %.3f s: stale %s; the arm goes on",
                    now, detail)
    elif event == "base cleared":
        LOG.warning("base cleared at t = %.3f s: obstacle points fresh for "
                    "%.3g s; the base resumes within its limits", now,
                    recovery)
    elif event == "not finite":
        LOG.warning("the controller's command at t = %.3f s is not finite "
                    "(%s); not sent (the base stops, the arm slows down and "
                    "holds) until it is finite again", now, detail)
    elif event == "finite":
        LOG.warning("the controller's command at t = %.3f s is finite "
                    "again; sent within the limits", now)
    elif event == "arm elsewhere":
        LOG.warning("arm elsewhere at t = %.3f s: %s; its commands restart "
                    "from where it is, at rest", now, detail)
    elif event == "arm beyond its limits":
        LOG.warning("arm beyond its limits at t = %.3f s: %s; its commands "
                    "do not restart from there (held within the limits, "
                    "they would jump away from it): they go on from the "
                    "last command sent, within the limits", now, detail)
    else:
        LOG.info("every stream fresh at t = %.3f s: the commands start", now)


class LimiterState(NamedTuple):
    """What an ArmCommandLimiter keeps: the command the arm gets, its rate,
    the command received it was taken from, and whether it was limited."""

    command: np.ndarray
    velocity: np.ndarray
    taken: np.ndarray
    limited: bool

    def __deepcopy__(self, memo):
        # Never changed in place (only replaced), so the copies that Drake
        # makes of an abstract state at each update may share it.
        return self


class ArmCommandLimiter(LeafSystem):
    """The robot side's own limit on the arm's commands: whatever arrives,
    the arm is commanded within its rate and acceleration limits
    (`follow_arm_command`), so that no packet, forged or not, moves it at
    once (drake_wbc/hardware/README.md, "What the robot does itself").

    ::

                          ┌───────────────────┐
          positions ─────►│ ArmCommandLimiter ├──► positions
                          │                   ├──► limited
                          └───────────────────┘

    - positions: (n) the arm command received (CommandReceiver's), n
      the size of the limits.
    - positions (output): the command the arm gets: one step of
      `follow_arm_command` a period, from the last stored command towards
      the newest one received, stored by a periodic update in the middle
      of the command period (after the commands sent on time have
      arrived, before the arm's servo samples); the arm goes on towards
      the last command, period by period, when no new one comes. So the
      arm's servo, sampling once a period, sees one step within the
      limits between two samples, however the commands arrive: taken at
      once on arrival, two commands of a stalled controller arriving
      together on both sides of an update were two steps within one of
      the servo's periods, twice the rate (37 rad/s^2 against 12.56).
    - limited: (1) the limits changed the last stored step (0/1).

    Args:
        period: the command period h, s (HardwareOptions.publish_period).
        offset: when the step is stored, s (publish_offset + h / 2).
        initial_positions: (n,) the arm's command at the start, within
            the joint limits (`start_within_limits`).
        limits: Limits (the arm's own).
    """

    def __init__(self, period, offset, initial_positions, limits):
        super().__init__()
        self.period = positive("period", period)
        self.limits = limits
        self.num_joints = n = limits.lower.size
        initial = start_within_limits(
            "initial_positions", initial_positions, limits.lower,
            limits.upper, limits.joint_acceleration, period)
        self._in = self.DeclareVectorInputPort("positions", n)
        self._state = self.DeclareAbstractState(AbstractValue.Make(
            LimiterState(initial.copy(), np.zeros(n), initial.copy(), False)))
        self.DeclarePeriodicUnrestrictedUpdateEvent(self.period, offset,
                                                    self._update)
        stored = {self.abstract_state_ticket(self._state)}
        self.DeclareVectorOutputPort("positions", n, self._positions,
                                     prerequisites_of_calc=stored)
        self.DeclareVectorOutputPort(
            "limited", 1, lambda c, o: o.SetAtIndex(
                0, float(self._stored(c)[3])),
            prerequisites_of_calc=stored)

    def _stored(self, context):
        return context.get_abstract_state(self._state).get_value()

    def set_positions(self, context, positions):
        """Starts the limiter at rest at `positions` (within the joint
        limits) in `context`."""
        context = self.GetMyMutableContextFromRoot(context)
        q = start_within_limits(
            "positions", positions, self.limits.lower, self.limits.upper,
            self.limits.joint_acceleration, self.period)
        context.SetAbstractState(self._state, LimiterState(
            q.copy(), np.zeros(self.num_joints), q.copy(), False))

    def _positions(self, context, output):
        output.SetFromVector(self._stored(context).command)

    def _update(self, context, state):
        command, velocity, taken, _ = self._stored(context)
        received = np.array(self._in.Eval(context))
        command, velocity, limited = follow_arm_command(
            received, target_rate(received, taken, self.period), command,
            velocity, self.period, self.limits)
        state.get_mutable_abstract_state(self._state).set_value(
            LimiterState(command, velocity, received, limited))

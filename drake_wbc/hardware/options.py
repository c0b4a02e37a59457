"""How the controller talks to the robot over LCM: a scenario's `hardware:`.

    hardware:
      lcm_url: udpm://239.255.76.67:7667?ttl=0
      channels: {base_command: WBC_BASE_COMMAND, arm_status: WBC_ARM_STATUS}
      watchdog_limits: {obstacle_points: 0.2}

Every field has a default (the channel names and rules of drake_wbc/
hardware/README.md, the protocol), so `hardware: {}` chooses LCM with the
defaults. The checks run in `__post_init__`, as for every parameters
dataclass of the library (drake_wbc.math.validation). Limits may only
tighten the robot's own: the base's and the joints' speed and
acceleration limits and the robot side's command timeout (None: the
robot's own) and the watchdog limits are checked against the robot's
description and arm model when the command guard is built
(drake_wbc.hardware.safety.Limits.of_robot, `command_timeout_of`).
"""

import re
from dataclasses import dataclass, field, fields

from drake_wbc.math.validation import (
    positive,
    whole_multiple,
    whole_number,
)

ROBOT_OWN = ("base_speed_limit", "base_yaw_rate_limit",
             "base_acceleration_limit", "base_yaw_acceleration_limit",
             "joint_speed_limit", "joint_acceleration_limit",
             "robot_command_timeout")
"""The limits that default to the robot's own (None)."""

CHANNEL_PATTERN = re.compile(r"^[A-Za-z0-9_.\-/]+$")
"""What a channel name may hold: letters, digits and _ . - /."""

URL_SCHEMES = ("udpm://", "memq://", "file://")
"""The LCM providers a URL may name."""

STATUS_CHANNELS = ("base_state", "arm_status", "wrist_wrench",
                   "obstacle_points")
"""The channels the robot sends and the controller depends on (fields of
ChannelNames and of WatchdogLimits), in the order of the command guard's
`status_ages`."""

ROBOT_STATUS_PERIOD = 0.01
"""s: the robot's base odometry, arm status and FT-300 wrench come at
100 Hz (the robot facts)."""

ROBOT_LIDAR_PERIOD = 1.0 / 15.0
"""s: the TiM571 LIDARs scan at 15 Hz (the robot facts)."""

def at_most(name, value, own, unit, what="the robot's own"):
    """`value` after checking that it is at most `own` (a limit may
    tighten the robot's, never widen it).

    Raises:
        ValueError: naming `name`, its value and the robot's value.
    """
    if value > own:
        raise ValueError(f"{name} = {value!r} is not allowed: must be at "
                         f"most {what} {own!r} {unit}")
    return value


@dataclass
class ChannelNames:
    """The LCM channels, one per message (see drake_wbc/hardware/
    README.md for their types).

    Attributes:
        base_command: controller -> robot, base_velocity_command_t.
        arm_command: controller -> robot, arm_command_t.
        base_state: robot -> controller, base_state_t.
        arm_status: robot -> controller, arm_status_t.
        wrist_wrench: robot -> controller, Drake's lcmt_force_torque.
        obstacle_points: robot -> controller, obstacle_points_t.
        truth: robot (simulated) -> logs, signal_bundle_t of the ground
            truth.
        controller: controller -> logs, signal_bundle_t of the
            controller's diagnostics, the task's reference and the
            hardware interface's diagnostics.
    """

    base_command: str = "WBC_BASE_COMMAND"
    arm_command: str = "WBC_ARM_COMMAND"
    base_state: str = "WBC_BASE_STATE"
    arm_status: str = "WBC_ARM_STATUS"
    wrist_wrench: str = "WBC_WRIST_WRENCH"
    obstacle_points: str = "WBC_OBSTACLE_POINTS"
    truth: str = "WBC_TRUTH"
    controller: str = "WBC_CONTROLLER"

    def __post_init__(self):
        names = {}
        for item in fields(self):
            value = getattr(self, item.name)
            if not isinstance(value, str) or not CHANNEL_PATTERN.match(value):
                raise ValueError(
                    f"{item.name} = {value!r} is not allowed: must be a "
                    "channel name of letters, digits and _ . - / only, "
                    "not empty")
            if value in names:
                raise ValueError(
                    f"{item.name} = {value!r} is not allowed: "
                    f"{names[value]} uses that channel already; each "
                    "message needs its own")
            names[value] = item.name


@dataclass
class WatchdogLimits:
    """The oldest each stream's last good message may be, s, on the
    receiver's clock, before the command guard stops what depends on it
    (drake_wbc.hardware.safety.CommandGuard).

    Attributes:
        base_state: the base's odometry (100 Hz); stale: full stop.
        arm_status: the arm's joint state (100 Hz); stale: full stop.
        wrist_wrench: the FT-300's wrench (100 Hz): it feeds force
            control, the pHRI term and the compliance of the arm's DMP in
            every mode; stale: full stop.
        obstacle_points: the LIDARs' points (15 Hz); stale: the base
            stops (no base motion without fresh obstacle points), the arm
            goes on.

    Each is 3 periods of its stream by default; each must be at least one
    period (ROBOT_STATUS_PERIOD, ROBOT_LIDAR_PERIOD) and at most the
    robot's own command timeout (its description's base.command_timeout:
    the robot would stop first, and uninformed; `command_timeout_of`).
    """

    base_state: float = 0.03
    arm_status: float = 0.03
    wrist_wrench: float = 0.03
    obstacle_points: float = 0.2

    def __post_init__(self):
        for item in fields(self):
            value = positive(item.name, getattr(self, item.name))
            period = (ROBOT_LIDAR_PERIOD if item.name == "obstacle_points"
                      else ROBOT_STATUS_PERIOD)
            if value < period:
                raise ValueError(
                    f"{item.name} = {value!r} s is not allowed: must be at "
                    f"least one period of its stream ({period:.4g} s), or "
                    "every message is late")

    def as_tuple(self):
        """The limits in the order of STATUS_CHANNELS."""
        return tuple(getattr(self, name) for name in STATUS_CHANNELS)


@dataclass
class HardwareOptions:
    """The LCM hardware interface (drake_wbc.hardware.interface) and the
    robot-side program that speaks the same protocol (drake_wbc/hardware/
    README.md).

    Attributes:
        lcm_url: the LCM provider. The default is Drake's: UDP multicast
            with ttl=0, which leaves no host. `memq://` is in process.
        channels: the channel names.
        publish_period: how often the controller sends its commands, s
            (the control period, 0.01 s).
        publish_offset: when, after each control tick, the commands go
            out, s, in (0, publish_period): the command guard checks and
            limits the controller's new commands at half this offset,
            and the publishers send them at it (2 ms).
        watchdog_limits: WatchdogLimits, the oldest each stream may be.
        watchdog_period: how often the command guard checks the streams'
            ages, s (1 ms); a stop found between two command periods goes
            out at the next check. publish_period must be a whole multiple
            of it.
        watchdog_recovery_time: how long every stream behind a stop must
            have been fresh before the commands resume, s (0.5 s, the
            controller's safety.hold_time), so that a stream that comes and
            goes (a flood, a flaky link) does not start and stop the robot
            at every good message. A stream's first message needs no wait.
        base_speed_limit: the largest planar speed sent to the base, m/s;
            None for the robot's own (its description's base
            velocity_limits: the smaller of vx and vy, 1.0 m/s on the
            shipped base).
        base_yaw_rate_limit: the largest yaw rate sent, rad/s; None for
            the robot's own.
        base_acceleration_limit: the largest change of vx and of vy sent,
            m/s^2, scaled as one vector with the yaw's; None for the
            robot's own.
        base_yaw_acceleration_limit: of wz, rad/s^2; None for the
            robot's own. Each may tighten the robot's own, never widen it
            (checked against the robot's description, Limits.of_robot).
        joint_speed_limit: the largest joint speed the arm commands may
            ask for from one command to the next, rad/s, the same on every
            joint; None for the arm's own, joint by joint (from the
            robot's model and description).
        joint_acceleration_limit: the largest change of that speed,
            rad/s^2; None for the arm's own, joint by joint. Both may
            tighten the arm's own, never widen them
            (checked against the robot, Limits.of_robot).
        clock_tolerance: how far a sender's time stamp may run ahead of
            the receiver's clock since the last good message, s (0.1 s);
            a stamp further ahead, or one that goes backwards, is out of
            sequence (see clock_resync_messages).
        clock_resync_messages: how many consecutive messages, each in
            sequence with the one before, establish a sender's clock that
            jumped (forward or back): the last of them is accepted (3).
        status_period: how often the robot side sends the base's and the
            arm's status and the wrist's wrench, s (100 Hz).
        truth_period: how often the simulated robot sends its ground
            truth, and the controller its diagnostics, s.
        robot_command_timeout: the robot side stops the base when no base
            command came for this long, s; None (the default): the
            robot's own (its description's base.command_timeout, 0.25 s
            for the shipped base), which a given one may only shorten;
            at least publish_period + watchdog_period (`command_timeout_of`).
        sender_release_time: the robot side hands its command channels
            to another sender only after the one it obeys has been quiet
            for this long, s (1.0 s): a controller that misses the
            processor for a moment is stopped by the command timeout but
            does not lose the robot to a stray sender meanwhile.
        startup_timeout: how long `drake-wbc deploy` waits for the
            robot's first status before giving up, s.
        max_obstacle_points: the most points an obstacle points message
            may hold (4096); one with more is rejected as malformed, since
            the controller's tick grows with the points and a flood of
            them would slow it below real time. A robot's LIDARs together
            give fewer (the shipped robot's two TiM571 give 1622 a scan
            pair); raise it for a robot whose scans hold more.
    """

    lcm_url: str = "udpm://239.255.76.67:7667?ttl=0"
    channels: ChannelNames = field(default_factory=ChannelNames)
    publish_period: float = 0.01
    publish_offset: float = 0.002
    watchdog_limits: WatchdogLimits = field(default_factory=WatchdogLimits)
    watchdog_period: float = 0.001
    watchdog_recovery_time: float = 0.5
    base_speed_limit: float | None = None
    base_yaw_rate_limit: float | None = None
    base_acceleration_limit: float | None = None
    base_yaw_acceleration_limit: float | None = None
    joint_speed_limit: float | None = None
    joint_acceleration_limit: float | None = None
    clock_tolerance: float = 0.1
    clock_resync_messages: int = 3
    status_period: float = 0.01
    truth_period: float = 0.01
    robot_command_timeout: float | None = None
    sender_release_time: float = 1.0
    startup_timeout: float = 10.0
    max_obstacle_points: int = 4096

    def __post_init__(self):
        if not isinstance(self.lcm_url, str) or not self.lcm_url.startswith(
                URL_SCHEMES):
            raise ValueError(
                f"lcm_url = {self.lcm_url!r} is not allowed: must start "
                f"with one of {', '.join(URL_SCHEMES)}")
        for name, kind in (("channels", ChannelNames),
                           ("watchdog_limits", WatchdogLimits)):
            if not isinstance(getattr(self, name), kind):
                raise ValueError(f"{name} = {getattr(self, name)!r} is not "
                                 f"allowed: must be a {kind.__name__}")
        for item in fields(self):
            if item.name in ROBOT_OWN and getattr(self, item.name) is None:
                continue
            if item.name not in ("lcm_url", "channels", "watchdog_limits",
                                 "clock_resync_messages",
                                 "max_obstacle_points"):
                positive(item.name, getattr(self, item.name))
        self.clock_resync_messages = whole_number(
            "clock_resync_messages", self.clock_resync_messages, 2)
        self.max_obstacle_points = whole_number(
            "max_obstacle_points", self.max_obstacle_points, 1)
        if self.publish_offset >= self.publish_period:
            raise ValueError(
                f"publish_offset = {self.publish_offset!r} s is not allowed "
                f"with publish_period = {self.publish_period!r} s: must be "
                "below it")
        if self.watchdog_period > self.publish_period:
            raise ValueError(
                f"watchdog_period = {self.watchdog_period!r} s is not "
                f"allowed with publish_period = {self.publish_period!r} s: "
                "must be at most it")
        whole_multiple("publish_period", self.publish_period,
                       "watchdog_period", self.watchdog_period)
        limits = self.watchdog_limits
        for name in ("base_state", "arm_status", "wrist_wrench"):
            if getattr(limits, name) < self.status_period:
                raise ValueError(
                    f"watchdog_limits.{name} = {getattr(limits, name)!r} s "
                    f"is not allowed with status_period = "
                    f"{self.status_period!r} s: must be at least one status "
                    "period, or every status is late")

    @property
    def guard_offset(self):
        """When the command guard samples the controller's commands after
        each control tick, s (half of publish_offset)."""
        return 0.5 * self.publish_offset


def command_timeout_of(options, base):
    """The robot side's command timeout for `options` on a robot, checked:
    options.robot_command_timeout, or the base's own where None.

    A limit may only tighten the robot's own: the timeout and each
    watchdog limit (options.watchdog_limits) at most the base's own
    command timeout (a watchdog slower than the robot's would let the
    robot stop first, and uninformed), and options.sender_release_time
    at least the timeout (the base has stopped before another sender may
    drive it), and the timeout at least options.publish_period plus
    options.watchdog_period: no longer than a period, the base stops
    between two commands, and shorter than that sum, the command guard,
    which takes a gap between two of its checks longer than the timeout
    less a period for a stall of the controller
    (drake_wbc.hardware.safety.stall_limit), stops at every check.

    Args:
        options: HardwareOptions.
        base: the robot's BaseDescription (its command_timeout).

    Returns:
        The timeout, s.

    Raises:
        ValueError: naming the option, its value and the robot's own.
    """
    own = float(base.command_timeout)
    for item in fields(options.watchdog_limits):
        at_most(f"watchdog_limits.{item.name}",
                getattr(options.watchdog_limits, item.name), own, "s",
                "the robot's own command timeout")
    timeout = options.robot_command_timeout
    if timeout is None:
        timeout = own
    at_most("robot_command_timeout", timeout, own, "s")
    least = options.publish_period + options.watchdog_period
    if timeout < least * (1.0 - 1e-12):
        whose = (" (the robot's own)" if options.robot_command_timeout is None
                 else "")
        raise ValueError(
            f"robot_command_timeout = {timeout!r} s{whose} is not allowed "
            f"with publish_period = {options.publish_period!r} s and "
            f"watchdog_period = {options.watchdog_period!r} s: must be at "
            f"least their sum, {least:.6g} s: the robot stops its base "
            "when no command came for that long, and the command guard "
            "when more than the timeout less a period passed between two "
            "of its checks")
    if options.sender_release_time < timeout:
        raise ValueError(
            f"sender_release_time = {options.sender_release_time!r} s is "
            f"not allowed with robot_command_timeout = {timeout!r} s: must "
            "be at least it, so that the base has stopped before another "
            "sender may drive it")
    return timeout

"""How the controller talks to the robot over LCM: a scenario's `hardware:`.

    hardware:
      lcm_url: udpm://239.255.76.67:7667?ttl=0
      channels: {base_command: WBC_BASE_COMMAND, arm_status: WBC_ARM_STATUS}
      watchdog_limit: 0.03

Every field has a default (the channel names of drake_wbc/hardware/
README.md), so `hardware: {}` chooses LCM with the defaults. The checks
run in `__post_init__`, as for every parameters dataclass of the library
(drake_wbc.math.validation).
"""

import re
from dataclasses import dataclass, field, fields

from drake_wbc.math.validation import positive

CHANNEL_PATTERN = re.compile(r"^[A-Za-z0-9_.\-/]+$")
"""What a channel name may hold: letters, digits and _ . - /."""

URL_SCHEMES = ("udpm://", "memq://", "file://")
"""The LCM providers a URL may name."""


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
class HardwareOptions:
    """The LCM hardware interface (drake_wbc.hardware.interface) and the
    robot-side program that speaks the same protocol.

    Attributes:
        lcm_url: the LCM provider. The default is Drake's: UDP multicast
            with ttl=0, which leaves no host. `memq://` is in process.
        channels: the channel names.
        publish_period: how often the controller sends its commands, s
            (the control period, 0.01 s).
        publish_offset: when, after each control tick, the commands go
            out, s, in (0, publish_period): the command guard checks and
            saturates the controller's new commands at half this offset,
            and the publishers send them at it (2 ms).
        watchdog_limit: the oldest the base's and the arm's status may
            be, s, before the commands stop (zero base velocity, arm
            held); 3 control periods by default.
        base_speed_limit: the largest planar speed sent to the base, m/s
            (the base's 1.0 m/s).
        base_yaw_rate_limit: the largest yaw rate sent, rad/s (1.0).
        joint_speed_limit: the largest joint speed the arm commands may
            ask for from one command to the next, rad/s (the Elfin5's
            1.57 rad/s).
        status_period: how often the robot side sends the base's and the
            arm's status and the wrist's wrench, s (100 Hz).
        truth_period: how often the simulated robot sends its ground
            truth, and the controller its diagnostics, s.
        robot_command_timeout: the robot side stops the base when no base
            command came for this long, s (0.25 s, as such bases do).
        startup_timeout: how long `drake-wbc deploy` waits for the
            robot's first status before giving up, s.
    """

    lcm_url: str = "udpm://239.255.76.67:7667?ttl=0"
    channels: ChannelNames = field(default_factory=ChannelNames)
    publish_period: float = 0.01
    publish_offset: float = 0.002
    watchdog_limit: float = 0.03
    base_speed_limit: float = 1.0
    base_yaw_rate_limit: float = 1.0
    joint_speed_limit: float = 1.57
    status_period: float = 0.01
    truth_period: float = 0.01
    robot_command_timeout: float = 0.25
    startup_timeout: float = 10.0

    def __post_init__(self):
        if not isinstance(self.lcm_url, str) or not self.lcm_url.startswith(
                URL_SCHEMES):
            raise ValueError(
                f"lcm_url = {self.lcm_url!r} is not allowed: must start "
                f"with one of {', '.join(URL_SCHEMES)}")
        if not isinstance(self.channels, ChannelNames):
            raise ValueError(f"channels = {self.channels!r} is not allowed: "
                             "must be a ChannelNames")
        for item in fields(self):
            if item.name not in ("lcm_url", "channels"):
                positive(item.name, getattr(self, item.name))
        if self.publish_offset >= self.publish_period:
            raise ValueError(
                f"publish_offset = {self.publish_offset!r} s is not allowed "
                f"with publish_period = {self.publish_period!r} s: must be "
                "below it")
        if self.watchdog_limit < self.status_period:
            raise ValueError(
                f"watchdog_limit = {self.watchdog_limit!r} s is not allowed "
                f"with status_period = {self.status_period!r} s: must be at "
                "least one status period, or every status is late")

    @property
    def guard_offset(self):
        """When the command guard samples the controller's commands after
        each control tick, s (half of publish_offset)."""
        return 0.5 * self.publish_offset

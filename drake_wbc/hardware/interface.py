"""The LCM hardware interface: the station's ports, over LCM.

::

                              ┌───────────────────┐
    base.velocity_command ───►│                   ├──► base.state_estimated
    arm.position_command ────►│                   ├──► arm.position_measured
                              │ HardwareInterface ├──► arm.velocity_estimated
                              │                   ├──► wrist.wrench_measured
                              │                   ├──► lidar.obstacle_points
                              │                   ├──► hardware.diagnostics
                              │                   ├──► hardware.<command>
                              │                   ├──► hardware.watchdog_tripped
                              └───────────────────┘

It offers the ports of the simulated station (drake_wbc.station.
simulation) that the controller reads (drake_wbc.controller.diagram.
STATION_INPUTS), with the same names, sizes and types, so the controller
Diagram built for a simulation drives the robot unchanged. Inside, a
MessageDecoder (drake_wbc.hardware.codecs) subscribes to each status
channel and keeps its last good message, judging time stamps by the
protocol's rules; the controller's commands go through the CommandGuard
(drake_wbc.hardware.safety: the watchdog of every stream, the limits,
and, with the arm's measured positions, the arm's restart from where it
is after a stop) to MessageEncoders, which stamp them with the
interface's sender identity, and LcmPublisherSystems; a
FlaggedPublisher sends the base's stop at once when the guard finds a
stale stream between two ticks; an LcmPump delivers the messages to
the decoders at the start of every simulator step.

`hardware.diagnostics` holds DIAGNOSTICS: the guard's status, the age of
each status channel's last good message and its count of rejected
messages. `hardware.base_velocity_command` and `hardware.arm_position_
command` are the commands as sent (after the watchdog and the limits).
`hardware.watchdog_tripped` (1) is 1 during a full stop of the watchdog:
the controller's input of that name (drake_wbc.controller.diagram), so
that the controller stops with the robot.

Timing, with the controller ticking at offset 0 every publish_period h:
the statuses the robot sent up to a tick are read at that tick (the
last good message of each channel); the commands computed at tick k are
checked at k h + publish_offset / 2 and sent at k h + publish_offset;
the guard checks the streams' ages every watchdog_period (1 ms) from
there, and a base stop found between two ticks goes out one check later.
"""

import secrets

from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.lcm import LcmPublisherSystem
from pydrake.systems.primitives import Multiplexer

from drake_wbc.hardware.codecs import (
    ClockRules,
    FlaggedPublisher,
    LcmPump,
    MessageDecoder,
    MessageEncoder,
    receiving_bus,
)
from drake_wbc.hardware.messages import RawBytesSerializer
from drake_wbc.hardware.options import STATUS_CHANNELS, HardwareOptions
from drake_wbc.hardware.safety import GUARD_STATUS, CommandGuard, Limits
from drake_wbc.math.safety import arm_follow_tolerance_of
from drake_wbc.math.validation import checked_instance
from drake_wbc.robot.model import arm_kinematics

DIAGNOSTICS = (GUARD_STATUS
               + tuple(f"{name}_age" for name in STATUS_CHANNELS)
               + tuple(f"{name}_rejected" for name in STATUS_CHANNELS))
"""The entries of the `hardware.diagnostics` port."""

OUTPUTS = (
    ("base_state", "state", "base.state_estimated"),
    ("arm_status", "positions", "arm.position_measured"),
    ("arm_status", "velocities", "arm.velocity_estimated"),
    ("wrist_wrench", "wrench", "wrist.wrench_measured"),
    ("obstacle_points", "points", "lidar.obstacle_points"),
)
"""(decoder, its port, the station's port name) of each output."""


def new_sender():
    """A sender identity for the commands: 63 random bits (an int64 > 0),
    drawn afresh by each controller, so that two never share one."""
    return secrets.randbits(63)


def add_publisher(builder, channel, lcm, name, period, offset=0.0):
    """An LcmPublisherSystem sending bytes on `channel` every `period` s
    at `offset`, added as `name`."""
    return builder.AddNamedSystem(name, LcmPublisherSystem(
        channel, RawBytesSerializer(), lcm, publish_period=period,
        publish_offset=offset))


class HardwareInterface:
    """The built interface: its Diagram and the parts inside it.

    Attributes:
        diagram: the Diagram (ports in the module's docstring).
        systems: dict of its systems by name (`guard`, `decoder.<channel>`,
            `encoder.<channel>`, ...).
        options: the HardwareOptions it was built from.
        sender: the identity its commands carry.

    Args:
        options: HardwareOptions (its defaults if None).
        lcm: the DrakeLcmInterface to talk over (e.g. DrakeLcm(options.
            lcm_url)); it must outlive the diagram.
        initial_arm_positions: the arm command held until the controller
            sends one (set the robot's measured positions with
            `set_arm_command` before running); the robot's home if None.
        sender: the commands' sender identity (`new_sender()` if None).
        robot: the robot on the other end: a RobotDescription (the
            shipped robot if None) or the ArmKinematics of one. Its arm
            sizes the arm's messages and ports, and its own limits bound
            the commands (Limits.of_robot).
        wall_clock: the WallClock (drake_wbc.hardware.safety) of a run in
            real time, which the guard reads at every check; None on
            simulated time.
        arm_follow_tolerance: rad, the controller's
            SafetyParameters.arm_follow_tolerance, for the guard's
            restart of the arm's commands from where it is after a stop
            (CommandGuard); None: the robot's arm's own, as the
            controller's (drake_wbc.math.safety.arm_follow_tolerance_of
            its joint speed limits).
    """

    def __init__(self, options=None, lcm=None, initial_arm_positions=None,
                 sender=None, robot=None, wall_clock=None,
                 arm_follow_tolerance=None):
        self.options = options = checked_instance(
            "options", options, HardwareOptions, HardwareOptions)
        if lcm is None:
            raise ValueError("lcm = None is not allowed: pass the "
                             "DrakeLcmInterface to talk over, e.g. "
                             "DrakeLcm(options.lcm_url)")
        self.sender = new_sender() if sender is None else int(sender)
        self.arm = arm = arm_kinematics(robot)
        n = arm.num_joints
        if arm_follow_tolerance is None:
            arm_follow_tolerance = arm_follow_tolerance_of(
                arm.velocity_limits)
        if initial_arm_positions is None:
            initial_arm_positions = arm.home
        channels = options.channels
        rules = ClockRules.of(options)
        builder = DiagramBuilder()
        s = self.systems = {}
        self.receiving = bus = receiving_bus(lcm)
        s["pump"] = builder.AddNamedSystem("pump", LcmPump(bus))
        for name in STATUS_CHANNELS:
            s[f"decoder.{name}"] = builder.AddNamedSystem(
                f"decoder.{name}", MessageDecoder(
                    name, bus, getattr(channels, name), rules=rules,
                    num_joints=n, max_points=options.max_obstacle_points))
        s["guard"] = guard = builder.AddNamedSystem("guard", CommandGuard(
            options, initial_arm_positions, Limits.of_robot(options, arm),
            wall_clock=wall_clock,
            arm_follow_tolerance=arm_follow_tolerance))
        # Where the arm is, so that the commands never send it back to
        # an old command at once after a stop.
        builder.Connect(s["decoder.arm_status"].GetOutputPort("positions"),
                        guard.GetInputPort("arm_position_measured"))
        for port, name in (("age", "status_ages"),
                           ("clock_jumps", "clock_jumps")):
            mux = builder.AddNamedSystem(
                name, Multiplexer([1] * len(STATUS_CHANNELS)))
            for i, channel in enumerate(STATUS_CHANNELS):
                builder.Connect(s[f"decoder.{channel}"].GetOutputPort(port),
                                mux.get_input_port(i))
            builder.Connect(mux.get_output_port(), guard.GetInputPort(name))
        for name, port in (("base_command", "base_velocity_command"),
                           ("arm_command", "arm_position_command")):
            s[f"encoder.{name}"] = encoder = builder.AddNamedSystem(
                f"encoder.{name}", MessageEncoder(name, self.sender,
                                                  num_joints=n))
            builder.Connect(guard.GetOutputPort(port),
                            encoder.get_input_port(0))
            publisher = add_publisher(
                builder, getattr(channels, name), lcm, f"publisher.{name}",
                options.publish_period, options.publish_offset)
            builder.Connect(encoder.GetOutputPort("message"),
                            publisher.get_input_port())
        # A stop found between two control ticks goes out at the next
        # check (the base's zero; the arm's stop starts at the next tick).
        s["publisher.stop"] = stop = builder.AddNamedSystem(
            "publisher.stop", FlaggedPublisher(
                lcm, channels.base_command, options.watchdog_period,
                options.guard_offset))
        builder.Connect(s["encoder.base_command"].GetOutputPort("message"),
                        stop.GetInputPort("message"))
        builder.Connect(guard.GetOutputPort("urgent"),
                        stop.GetInputPort("flag"))
        diagnostics = builder.AddNamedSystem("diagnostics", Multiplexer(
            [len(GUARD_STATUS)] + [1] * (2 * len(STATUS_CHANNELS))))
        builder.Connect(guard.GetOutputPort("status"),
                        diagnostics.get_input_port(0))
        for i, name in enumerate(STATUS_CHANNELS):
            for j, port in enumerate(("age", "rejected")):
                builder.Connect(
                    s[f"decoder.{name}"].GetOutputPort(port),
                    diagnostics.get_input_port(
                        1 + i + j * len(STATUS_CHANNELS)))

        builder.ExportInput(guard.GetInputPort("base_velocity_command"),
                            "base.velocity_command")
        builder.ExportInput(guard.GetInputPort("arm_position_command"),
                            "arm.position_command")
        for decoder, port, name in OUTPUTS:
            builder.ExportOutput(
                s[f"decoder.{decoder}"].GetOutputPort(port), name)
        builder.ExportOutput(diagnostics.get_output_port(),
                             "hardware.diagnostics")
        for port in ("base_velocity_command", "arm_position_command"):
            builder.ExportOutput(guard.GetOutputPort(port), f"hardware.{port}")
        builder.ExportOutput(guard.GetOutputPort("tripped"),
                             "hardware.watchdog_tripped")
        self.diagram = builder.Build()
        self.diagram.set_name("hardware_interface")

    def set_arm_command(self, root_context, positions):
        """Holds the arm at `positions` (the measured ones at the start)
        until the controller's first command; see CommandGuard."""
        self.systems["guard"].set_arm_command(root_context, positions)

    def discard_pending(self):
        """Forgets what each status channel delivered before the run but
        its newest message (MessageDecoder.discard_pending): call it just
        before the Simulator starts."""
        for name in STATUS_CHANNELS:
            self.systems[f"decoder.{name}"].discard_pending()

    def command_utime(self, root_context):
        """The stamp the commands carry at `root_context`'s time,
        microseconds: a message sent by hand after the run (its final
        stop) is stamped from it, on the same time base as the run's, so
        that the robot takes it in sequence however far the controller's
        clock is behind the wall clock."""
        return self.systems["encoder.base_command"].utime(root_context)

    def set_time_offset(self, root_context, offset):
        """Stamps the commands with 1e6 (t + offset) microseconds, t the
        diagram's time (e.g. offset = time.time() at the start)."""
        for name in ("base_command", "arm_command"):
            self.systems[f"encoder.{name}"].set_time_offset(
                root_context, offset)

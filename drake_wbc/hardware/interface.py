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
                              └───────────────────┘

It offers the ports of the simulated station (drake_wbc.station.
simulation) that the controller reads (drake_wbc.controller.diagram.
STATION_INPUTS), with the same names, sizes and types, so the controller
Diagram built for a simulation drives the robot unchanged. Inside, for
each status channel an LcmSubscriberSystem carries the bytes to a
MessageDecoder (drake_wbc.hardware.codecs), which keeps the last good
message; the controller's commands go through the CommandGuard
(drake_wbc.hardware.safety: watchdog and saturation) to MessageEncoders
and LcmPublisherSystems; an LcmInterfaceSystem pumps the messages in.

`hardware.diagnostics` holds DIAGNOSTICS: the guard's status, the age of
each status channel's last good message and its count of rejected
messages. `hardware.base_velocity_command` and `hardware.arm_position_
command` are the commands as sent (after the watchdog and saturation).

Timing, with the controller ticking at offset 0 every publish_period h:
the statuses the robot sent up to a tick are read at that tick (the
last good message of each channel); the commands computed at tick k are
checked at k h + publish_offset / 2 and sent at k h + publish_offset.
"""

from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.lcm import (
    LcmInterfaceSystem,
    LcmPublisherSystem,
    LcmSubscriberSystem,
)
from pydrake.systems.primitives import Multiplexer

from drake_wbc.hardware.codecs import MessageDecoder, MessageEncoder
from drake_wbc.hardware.messages import RawBytesSerializer
from drake_wbc.hardware.options import HardwareOptions
from drake_wbc.hardware.safety import GUARD_STATUS, CommandGuard
from drake_wbc.math.validation import checked_instance
from drake_wbc.robot.model import HOME_ARM_POSITIONS

STATUS_CHANNELS = ("base_state", "arm_status", "wrist_wrench",
                   "obstacle_points")
"""The channels the interface reads (fields of ChannelNames)."""

WATCHED = ("base_state", "arm_status")
"""The statuses whose age the watchdog checks."""

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


def add_subscriber(builder, channel, lcm, name):
    """An LcmSubscriberSystem of `channel`'s bytes, added as `name`."""
    return builder.AddNamedSystem(name, LcmSubscriberSystem(
        channel, RawBytesSerializer(), lcm))


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

    Args:
        options: HardwareOptions (its defaults if None).
        lcm: the DrakeLcmInterface to talk over (e.g. DrakeLcm(options.
            lcm_url)); it must outlive the diagram.
        initial_arm_positions: the arm command held until the controller
            sends one (set the robot's measured positions with
            `set_arm_command` before running).
    """

    def __init__(self, options=None, lcm=None,
                 initial_arm_positions=HOME_ARM_POSITIONS):
        self.options = options = checked_instance(
            "options", options, HardwareOptions, HardwareOptions)
        if lcm is None:
            raise ValueError("lcm = None is not allowed: pass the "
                             "DrakeLcmInterface to talk over, e.g. "
                             "DrakeLcm(options.lcm_url)")
        channels = options.channels
        builder = DiagramBuilder()
        s = self.systems = {}
        # The pump first, so that subscribers see its messages at once.
        s["lcm"] = builder.AddNamedSystem("lcm", LcmInterfaceSystem(lcm))
        for name in STATUS_CHANNELS:
            subscriber = add_subscriber(builder, getattr(channels, name),
                                        lcm, f"subscriber.{name}")
            s[f"decoder.{name}"] = decoder = builder.AddNamedSystem(
                f"decoder.{name}", MessageDecoder(name))
            builder.Connect(subscriber.get_output_port(),
                            decoder.GetInputPort("message"))
        s["guard"] = guard = builder.AddNamedSystem("guard", CommandGuard(
            options, initial_arm_positions, num_statuses=len(WATCHED)))
        ages = builder.AddNamedSystem("status_ages",
                                      Multiplexer([1] * len(WATCHED)))
        for i, name in enumerate(WATCHED):
            builder.Connect(s[f"decoder.{name}"].GetOutputPort("age"),
                            ages.get_input_port(i))
        builder.Connect(ages.get_output_port(),
                        guard.GetInputPort("status_ages"))
        for name, port in (("base_command", "base_velocity_command"),
                           ("arm_command", "arm_position_command")):
            s[f"encoder.{name}"] = encoder = builder.AddNamedSystem(
                f"encoder.{name}", MessageEncoder(name))
            builder.Connect(guard.GetOutputPort(port),
                            encoder.get_input_port(0))
            publisher = add_publisher(
                builder, getattr(channels, name), lcm, f"publisher.{name}",
                options.publish_period, options.publish_offset)
            builder.Connect(encoder.GetOutputPort("message"),
                            publisher.get_input_port())
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
        self.diagram = builder.Build()
        self.diagram.set_name("hardware_interface")

    def set_arm_command(self, root_context, positions):
        """Holds the arm at `positions` (the measured ones at the start)
        until the controller's first command; see CommandGuard."""
        self.systems["guard"].set_arm_command(root_context, positions)

    def set_time_offset(self, root_context, offset):
        """Stamps the commands with 1e6 (t + offset) microseconds, t the
        diagram's time (e.g. offset = time.time() at the start)."""
        for name in ("base_command", "arm_command"):
            self.systems[f"encoder.{name}"].set_time_offset(
                root_context, offset)


def build_hardware_interface(options=None, lcm=None,
                             initial_arm_positions=HOME_ARM_POSITIONS):
    """The HardwareInterface of `options` over `lcm` (see the class)."""
    return HardwareInterface(options, lcm, initial_arm_positions)

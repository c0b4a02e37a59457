"""The simulated robot speaking the robot's side of the LCM protocol.

::

      WBC_BASE_COMMAND ──►┌───────────────────────────┐──► WBC_BASE_STATE
      WBC_ARM_COMMAND ───►│ SimulatedStation + LCM    │──► WBC_ARM_STATUS
                          │ (RobotSide)               │──► WBC_WRIST_WRENCH
                          │                           │──► WBC_OBSTACLE_POINTS
                          └───────────────────────────┘──► WBC_TRUTH

What `drake-wbc robot-sim` runs, and what the in-process tests put in the
same Diagram as the controller: the simulated station (drake_wbc.station.
simulation) with decoders of the commands on its inputs and encoders of
its outputs to LCM publishers, each at its rate:

- base state and arm status every `status_period` (100 Hz), at offset 0:
  the robot's odometry and joint state of that instant;
- the wrist's wrench every `status_period` and the LIDARs' obstacle
  points at the scanners' rate, each one station step after the sensor
  samples (a sensor driver sends its reading as soon as it has it);
- the ground truth (`truth.*` of the station, as a signal_bundle_t) every
  `truth_period`, for metrics and plots from a log.

The commands arrive through a CommandReceiver (drake_wbc.hardware.
codecs), which obeys one sender at a time and judges the time stamps as
the controller side does, and the arm's through an ArmCommandLimiter
(drake_wbc.hardware.safety) with the arm model's own joint speed and
acceleration limits: what drake_wbc/hardware/README.md asks of a real
robot's driver ("What the robot does itself"). Behind it the station's
arm, which faults on a command beyond those limits as a real arm's servo
does (drake_wbc.station.arm_supervisor), never faults. The base's own velocity
loop (the station's base driver) keeps its speed and acceleration within
the base's limits. Like the real base, the robot side stops the base
when no base command came for `robot_command_timeout` (the robot's own
by default, 0.25 s for the shipped base); the arm
holds its last command. Before the first command the base is at rest
and the arm holds the scenario's initial positions.
"""

from dataclasses import replace

from pydrake.systems.framework import DiagramBuilder

from drake_wbc.experiments.scenario import Scenario, scenario_station
from drake_wbc.hardware.codecs import (
    ClockRules,
    CommandReceiver,
    LcmPump,
    MessageEncoder,
    SignalBundleEncoder,
    receiving_bus,
)
from drake_wbc.hardware.interface import add_publisher
from drake_wbc.hardware.options import HardwareOptions, command_timeout_of
from drake_wbc.hardware.safety import (
    ArmCommandLimiter,
    Limits,
)
from drake_wbc.math.validation import checked_instance
from drake_wbc.robot.model import ArmKinematics

TRUTH_SIGNALS = ("truth.end_effector_pose", "truth.end_effector_velocity",
                 "truth.base_pose", "truth.base_loop_velocity",
                 "truth.mount_angles", "truth.wrist_wrench",
                 "truth.hand_force", "truth.people_positions")
"""The station's ground-truth ports sent on the truth channel (those of
size 0, e.g. no people, are left out)."""


class RobotSide:
    """The simulated station behind LCM.

    Attributes:
        diagram: the Diagram: no inputs (the commands come over LCM);
            the station's outputs, for logs and visualisation in process
            (the controller must read them over LCM).
        station: the SimulatedStation inside.
        systems: dict of its LCM systems by name.
        options, scenario: what it was built from.

    Args:
        scenario: the Scenario (its station and scene are simulated).
        options: HardwareOptions (the scenario's, or the defaults, if
            None).
        lcm: the DrakeLcmInterface to talk over; it must outlive the
            diagram.
        add_pump: pump `lcm` with an LcmPump of its own (False when
            another one in the same Diagram pumps `lcm`; a UDP
            connection's queue of its own is always pumped here).
    """

    def __init__(self, scenario, options=None, lcm=None,
                 add_pump=True):
        self.scenario = checked_instance("scenario", scenario, Scenario,
                                         Scenario)
        options = options or scenario.hardware
        self.options = options = checked_instance(
            "options", options, HardwareOptions, HardwareOptions)
        if lcm is None:
            raise ValueError("lcm = None is not allowed: pass the "
                             "DrakeLcmInterface to talk over")
        channels = options.channels
        builder = DiagramBuilder()
        s = self.systems = {}
        self.station = scenario_station(scenario)
        station = builder.AddNamedSystem("station", self.station.diagram)

        bus = receiving_bus(lcm)
        if add_pump or bus is not lcm:
            s["pump"] = builder.AddNamedSystem("pump", LcmPump(bus))
        s["commands"] = receiver = builder.AddNamedSystem(
            "commands", CommandReceiver(
                bus, (channels.base_command, channels.arm_command),
                self.station.options.initial_arm_positions,
                command_timeout_of(options, self.station.model.description
                                   .base),
                options.sender_release_time,
                ClockRules.of(options)))
        builder.Connect(receiver.GetOutputPort("velocity"),
                        station.GetInputPort("base.velocity_command"))
        # The station's robot: its arm's own limits bound the commands.
        arm = ArmKinematics(self.station.plant, self.station.model)
        s["arm_limiter"] = limiter = builder.AddNamedSystem(
            "arm_limiter", ArmCommandLimiter(
                options.publish_period,
                options.publish_offset + 0.5 * options.publish_period,
                self.station.options.initial_arm_positions,
                # The arm's own limits, joint by joint (the robot's
                # driver does not take the controller side's tighter ones).
                Limits.of_robot(replace(
                    options, joint_speed_limit=None,
                    joint_acceleration_limit=None), arm)))
        builder.Connect(receiver.GetOutputPort("positions"),
                        limiter.GetInputPort("positions"))
        builder.Connect(limiter.GetOutputPort("positions"),
                        station.GetInputPort("arm.position_command"))

        sensor_delay = scenario.station.time_step
        statuses = (
            ("base_state", ("base.state_estimated",),
             options.status_period, 0.0),
            ("arm_status", ("arm.position_measured",
                            "arm.velocity_estimated"),
             options.status_period, 0.0),
            ("wrist_wrench", ("wrist.wrench_measured",),
             options.status_period, sensor_delay),
            ("obstacle_points", ("lidar.obstacle_points",),
             1.0 / scenario.station.lidar.rate, sensor_delay),
        )
        for name, ports, period, offset in statuses:
            s[f"encoder.{name}"] = encoder = builder.AddNamedSystem(
                f"encoder.{name}", MessageEncoder(
                    name, num_joints=arm.num_joints))
            for i, port in enumerate(ports):
                builder.Connect(station.GetOutputPort(port),
                                encoder.get_input_port(i))
            publisher = add_publisher(builder, getattr(channels, name), lcm,
                                      f"publisher.{name}", period, offset)
            builder.Connect(encoder.GetOutputPort("message"),
                            publisher.get_input_port())

        sizes = {name: station.GetOutputPort(name).size()
                 for name in TRUTH_SIGNALS}
        sizes = {name: size for name, size in sizes.items() if size > 0}
        s["encoder.truth"] = truth = builder.AddNamedSystem(
            "encoder.truth", SignalBundleEncoder(sizes))
        for name in sizes:
            builder.Connect(station.GetOutputPort(name),
                            truth.GetInputPort(name))
        publisher = add_publisher(builder, channels.truth, lcm,
                                  "publisher.truth", options.truth_period)
        builder.Connect(truth.GetOutputPort("message"),
                        publisher.get_input_port())
        for i in range(station.num_output_ports()):
            port = station.get_output_port(i)
            builder.ExportOutput(port, port.get_name())
        self.diagram = builder.Build()
        self.diagram.set_name("robot_side")

    def set_initial_state(self, root_context):
        """The station's initial state (SimulatedStation.
        set_initial_state), the arm's command limiter at rest there."""
        self.station.set_initial_state(root_context)
        self.systems["arm_limiter"].set_positions(
            root_context, self.station.options.initial_arm_positions)

    def set_time_offset(self, root_context, offset):
        """Stamps every message with 1e6 (t + offset) microseconds."""
        for name, system in self.systems.items():
            if name.startswith("encoder."):
                system.set_time_offset(root_context, offset)

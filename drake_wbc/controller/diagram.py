"""The CDMP-WBC controller as one Drake Diagram (paper Fig. "cdmp_wbc").

One control tick, as wired here (design notes, "data flow of one tick")::

    every input ─► InputGuard ─► (the stages below; stop, safety_status)
    reference_velocity ─► WholeBodyCdmp ◄─ F_ext, S_hri, delta_V_ee
                              │ V_ee (T_b)
    ArmCapability ─► WorkspaceAdapter ─► sigma_xy, sigma_phi
       │ p_ee, C_m, grad C_m, alpha   │
       └──────────────► MotionDistributor ◄─ k_n
                          │ V_a      │ V_b
                          │          ▼
                          │      BaseCdmp ◄─ obstacle points
                          │          │ V_b'
                          │          ▼
                          │   StopGate ◄─ stop (and the velocity limits)
                          │          ▼
                          │   BaseVelocityFilter ──► filtered_base_velocity
                          │          ▼ V_b^flt
                          │   BaseCommandLimiter ◄─ stopped
                          │          │ ──► base.velocity_command
                          ▼          ▼ (the command, limited)
                   RobustCompensator ◄─ s_c ──► delta_V_ee (to WholeBodyCdmp)
                          │ V_a^ref    ◄─ base.state_estimated (its
                          │               "measured" source of the base)
                          ▼
                       ArmCdmp ◄─ F_ext, F_d, S_hri
                          ▼
             ArmCartesianVelocityController ◄─ stop or protective stop
                          │                     (hold), resume, measured
                          ▼
                 arm.position_command (and, its state, to InputGuard)

The station-facing ports carry the names of the simulated station and of
the LCM hardware interface, so the same diagram drives either. The
feedback edges inside, delta_V_ee, which enters WholeBodyCdmp's state
alone, and the arm's position command, the arm controller's state, into
the InputGuard, leave from state, and so do the commands (filter,
limiter's inputs, arm controller): no algebraic loop, and no direct
feedthrough from any input to a command.

Run-time safety (drake_wbc.math.safety, drake_wbc.stages.safety):
- Every input enters through the InputGuard: a NaN, an infinite value, a
  value out of range (k_n < 0, s_c outside [0, 1], an odometry beyond
  MAX_ODOMETRY or a base twist beyond MEASURED_TWIST_FACTOR times the
  robot's velocity limits, an arm position
  beyond its joint's limits by more than MEASURED_POSITION_MARGIN, a
  wrist wrench beyond the sensor's range, tool.ft_sensor_range of the
  robot's description) or a pHRI switch other
  than 0 or 1 never reaches a stage (the guard passes the last valid
  sample on) and triggers a safe stop. So does an arm that does not
  follow: a joint measured farther than safety.arm_follow_tolerance
  from the arm controller's last position command (its state, the
  guard's input `arm.position_command`; checked from the second tick on
  and not during a stop), which says that the arm stopped on its own
  (its protective stop, an e-stop, a servo off) or is held. From that
  tick on the base command is zero (at once: the base's own drive brakes
  it within its limits, the shortest stop it can make) and the arm
  command brakes to rest within
  the joint acceleration limit (the arm controller's hold: a position
  command held at once would ask the servo for an unbounded
  deceleration). Nothing integrates meanwhile: the DMPs' couplings are
  held (the reference is zero, the phri switches turn the whole body's
  admittance term and the arm's force term off, StopSwitches zero the
  base's and the arm's DMP inputs and the tracking error into
  WholeBodyCdmp), because they are the task's progress, which a reset
  would lose; the transformation systems and the base filter (its input
  gated to zero) are stable and come to rest on them. The stop clears
  once every input has been valid for safety.hold_time; the base command
  then restarts from zero within the acceleration limits and the arm from
  rest at its last command, or, when the arm is farther than
  safety.arm_follow_tolerance from it (moved, or stopped on its own,
  during the stop), from rest where the arm is (the guard's `resume` and
  the measured position into the arm controller), so no command jumps
  and none makes up for the stop. The `safety_status`
  output (drake_wbc.math.safety.STATUS_FIELDS) and `safety_reason` (a sentence;
  also Controller.safety_reason) say why; the stop is logged when it trips
  and when it clears. Obstacle points with a NaN or infinite coordinate
  are dropped (counted in the status), not a fault.
- Over LCM, the hardware interface's watchdog enters the same way, as
  `hardware.watchdog_tripped` (HARDWARE_INPUTS): while it stops the
  robot for a stale stream, the controller is in a safe stop too.
- The base command is limited to the robot's velocity limits by uniform
  scaling (its direction kept) before the base filter, by the StopGate,
  so that the filter cannot wind up (its state never asks for more than
  the base can do), and again, with the acceleration limits, after it by
  BaseCommandLimiter, reported on `base_saturation`, which also slows it
  as a whole so that the footprint never approaches an obstacle point
  faster than it can stop short of it (drake_wbc.math.separation: the
  repulsive field alone is a coupling that a steady push overcomes),
  keeps ISO/TS 15066's protective separation from the obstacle points
  that move (people, tracked between scans in the odometry's world: the
  limiter reads base.state_estimated too), and brakes the base to rest
  within its acceleration limits while a point is on or inside the
  footprint (a protective stop, on `base_protective_stop` and in
  Controller.safety_reason). A protective stop stops the arm too, as a
  safe stop does: it brakes to rest within its acceleration limits and
  holds, and the DMPs' couplings are held (their inputs gated). What is
  inside the footprint is a person, or what the base has struck, within
  the arm's reach; the compensation would otherwise make up with the
  arm for the base's braking, moving the tool on towards it (0.3 m/s
  of a 0.3 m/s reference, all of it the arm's once the base stood).
  The compensator sees
  the command actually sent, so the arm makes up for what the limits take
  from the base (eq. (compensation)), or, by its `base_source`, the
  base's measured twist or that command through a model of the base's
  velocity loop. The arm's joint rates are scaled
  uniformly to their limits by the arm controller (reported on
  `arm_limited`), and its position command never leaves the joint
  limits.
"""

import dataclasses
import warnings

import numpy as np
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import Adder, MatrixGain

from drake_wbc.controller.parameters import (
    ControllerParameters,
    check_arm_limits,
    for_robot,
)
from drake_wbc.math.base_state import BASE_STATE_SIZE, BASE_YAW
from drake_wbc.math.motion_mode import MotionMode
from drake_wbc.math.safety import (
    MAX_ODOMETRY,
    MEASURED_POSITION_MARGIN,
    MEASURED_TWIST_FACTOR,
    Following,
    arm_follow_tolerance_of,
)
from drake_wbc.math.task_inputs import TASK_INPUTS
from drake_wbc.math.validation import checked_instance, validated_copy
from drake_wbc.robot.model import arm_kinematics
from drake_wbc.robot.tuning import RobotTuningWarning, check_tuning
from drake_wbc.stages import (
    AdmittanceFilter,
    ArmCapability,
    ArmCartesianVelocityController,
    ArmCdmp,
    BaseCdmp,
    BaseVelocityFilter,
    MotionDistributor,
    RobustCompensator,
    WholeBodyCdmp,
    WorkspaceAdapter,
)
from drake_wbc.stages.base_command import BaseCommandLimiter
from drake_wbc.stages.safety import GuardedInput, InputGuard, StopGate
from drake_wbc.stages.stop_switch import StopSwitch
from drake_wbc.stages.wrench import ExternalWrenchEstimator

STATION_INPUTS = (
    "base.state_estimated",
    "arm.position_measured",
    "wrist.wrench_measured",
    "lidar.obstacle_points",
)
"""The controller's inputs from the station (simulated or LCM)."""

HARDWARE_INPUTS = ("hardware.watchdog_tripped",)
"""Optional inputs from the LCM hardware interface (drake_wbc.hardware):
`hardware.watchdog_tripped` is 1 while its watchdog stops the robot (a
stale stream), and the controller then stops too (a safe stop: its
integrators do not run on while the robot stands, so it resumes from
rest). Unconnected (a simulation), it is 0."""


class Controller:
    """The built controller: its Diagram and its stages by name.

    Attributes:
        diagram: the Diagram; add it to a builder and connect its ports.
        stages: dict of the stages (LeafSystems) by name, for logging
            and inspection.
        params: the (validated copy of the) ControllerParameters it was
            built from.
    """

    def __init__(self, diagram, stages, params, arm):
        self.diagram, self.stages, self.params = diagram, stages, params
        self.arm = arm

    def initialize(self, root_context, arm_position=None,
                   base_velocity=(0.0, 0.0, 0.0)):
        """Starts the controller's state from the robot's measured state:
        the arm command at `arm_position` (the robot's home if None), the
        base filter at rest at
        `base_velocity` (T_b), and the base command's limiter and the
        compensator's prediction of the base (if any) from it. The
        DMPs start at rest; the input guard takes `arm_position` as the
        last valid arm measurement, and from the second tick on expects
        the measured arm within safety.arm_follow_tolerance of the
        command that starts there (an arm elsewhere is a safe stop, after
        which the command restarts from where the arm is)."""
        def context_of(name):
            return self.stages[name].GetMyMutableContextFromRoot(
                root_context)

        base_velocity = np.asarray(base_velocity, dtype=float)
        if arm_position is None:
            arm_position = self.arm.home
        self.stages["arm_controller"].set_arm_position(
            context_of("arm_controller"), arm_position)
        self.stages["base_filter"].set_velocity(context_of("base_filter"),
                                                base_velocity)
        self.stages["base_limiter"].set_previous(context_of("base_limiter"),
                                                 base_velocity)
        self.stages["compensator"].set_prediction(context_of("compensator"),
                                                  base_velocity)
        self.stages["guard"].set_last_valid(
            context_of("guard"), "arm.position_measured", arm_position)
        self.stages["wrench"].set_arm_position(context_of("wrench"),
                                               arm_position)

    def safety_reason(self, root_context):
        """Why the controller is in a safe stop, or the base in a
        protective stop (an obstacle point inside its footprint), as a
        sentence ("" when neither)."""
        reasons = [stage.reason(stage.GetMyContextFromRoot(root_context))
                   for stage in (self.stages["guard"],
                                 self.stages["base_limiter"])]
        return "; ".join(reason for reason in reasons if reason)


def tuning_problems(params, arm, start=None):
    """What is wrong with the tuning of `params` (ControllerParameters on
    its robot, for_robot) on `arm` (ArmKinematics), as sentences
    (drake_wbc.robot.tuning.check_tuning): its capability band and
    joint-limit gain, and its local workspace in the intuitive pHRI
    mode, at the arm's home or at `start` (joint positions)."""
    phri = params.workspace.mode is MotionMode.INTUITIVE_PHRI
    return check_tuning(arm, params.capability_band,
                        params.capability.joint_limit_gain,
                        params.workspace.workspace if phri else None,
                        start=start,
                        damping_threshold=(
                            params.arm_controller.damping_threshold))


def build_controller(params=None, robot=None):
    """Builds the CDMP-WBC controller Diagram.

    Args:
        params: ControllerParameters (the paper's values if None),
            checked here (on a copy, which the controller keeps); each
            stage reads its part when it is built, and the values held
            once (time_step, capability_band, phri_switch) are handed to
            every stage that needs them.
        robot: the robot: a RobotDescription (drake_wbc.robot.description;
            the shipped robot if None), or the ArmKinematics of one, to
            share its plant. Every stage's ports are sized by its arm, and
            the limits are checked against its own; a capability band,
            joint-limit gain or (intuitive pHRI) local workspace that
            does not suit the arm is warned of (RobotTuningWarning,
            drake_wbc.robot.tuning.check_tuning).

    Returns:
        Controller: the diagram with named ports (STATION_INPUTS,
        drake_wbc.math.task_inputs.TASK_INPUTS, HARDWARE_INPUTS; outputs
        base.velocity_command, arm.position_command and the diagnostics
        capability, alpha, sigma_xy, sigma_phi, end_effector_deviation,
        base_velocity, filtered_base_velocity, arm_velocity_command,
        arm_limited, base_saturation, base_protective_stop,
        safety_status, safety_reason).
    """
    params = validated_copy(checked_instance(
        "params", params, ControllerParameters, ControllerParameters))
    arm = arm_kinematics(robot)
    params = for_robot(params, arm.model.description)
    if params.safety.arm_follow_tolerance is None:
        # The arm's own: its fastest joint's lag at full speed.
        params = dataclasses.replace(params, safety=dataclasses.replace(
            params.safety, arm_follow_tolerance=arm_follow_tolerance_of(
                arm.velocity_limits)))
    h, band, switch = (params.time_step, params.capability_band,
                       params.phri_switch)
    check_arm_limits(params.arm_controller, arm)
    for problem in tuning_problems(params, arm):
        warnings.warn(problem, RobotTuningWarning, stacklevel=2)
    builder = DiagramBuilder()
    add = builder.AddNamedSystem
    stages = dict(
        guard=add("guard", _input_guard(params, arm)),
        capability=add("capability", ArmCapability(
            params.capability, arm, band=band)),
        wrench=add("wrench", ExternalWrenchEstimator(
            arm, params.wrench, time_step=h)),
        base_yaw=add("base_yaw", MatrixGain(
            np.eye(BASE_STATE_SIZE)[[BASE_YAW]])),
        whole_body_cdmp=add("whole_body_cdmp", WholeBodyCdmp(
            params.whole_body_cdmp, time_step=h, phri_switch=switch)),
        workspace=add("workspace", WorkspaceAdapter(
            params.workspace, arm, band=band, time_step=h)),
        distributor=add("distributor", MotionDistributor(
            params.distributor, arm, band=band)),
        base_cdmp=add("base_cdmp", BaseCdmp(params.base_cdmp, time_step=h)),
        base_gate=add("base_gate", StopGate(
            3, limits=params.safety.base_velocity_limits)),
        # A safe stop or a protective stop (either >= 0.5): the arm's
        # hold and the couplings' gates.
        any_stop=add("any_stop", Adder(2, 1)),
        # The couplings' inputs held at zero while stopped.
        base_cdmp_gate=add("base_cdmp_gate", StopSwitch(3)),
        arm_cdmp_gate=add("arm_cdmp_gate", StopSwitch(6)),
        deviation_gate=add("deviation_gate", StopSwitch(6)),
        base_filter=add("base_filter", BaseVelocityFilter(
            params.base_filter, time_step=h)),
        base_limiter=add("base_limiter", BaseCommandLimiter(
            params.safety, time_step=h,
            half_sizes=params.base_cdmp.repulsion.half_sizes)),
        compensator=add("compensator", RobustCompensator(
            params.compensator, arm, time_step=h)),
        arm_cdmp=add("arm_cdmp", ArmCdmp(
            params.arm_cdmp, time_step=h, phri_switch=switch)),
        arm_controller=add("arm_controller", ArmCartesianVelocityController(
            params.arm_controller, arm, time_step=h,
            resume_tolerance=params.safety.arm_follow_tolerance)),
    )
    if params.whole_body_cdmp.hri_time_constant > 0.0:
        # The admittance's virtual mass on the whole body's F_ext (eq.
        # (cdmp-wb); math.cdmp.admittance_filter_model).
        stages["admittance_filter"] = add("admittance_filter",
                                          AdmittanceFilter(
            params.whole_body_cdmp.hri_time_constant, time_step=h))
    s = stages

    def connect(source, output, destination, input_name):
        builder.Connect(s[source].GetOutputPort(output),
                        s[destination].GetInputPort(input_name))

    # Every input enters through the guard, and only its outputs (the
    # inputs' last valid samples) reach the stages.
    for name in STATION_INPUTS + tuple(TASK_INPUTS) + HARDWARE_INPUTS:
        builder.ExportInput(s["guard"].GetInputPort(name), name)
    # Station measurements.
    connect("guard", "base.state_estimated", "base_yaw", "u0")
    for stage in ("capability", "wrench", "arm_controller"):
        connect("guard", "arm.position_measured", stage, "arm_position")
    # The arm's last position command (the arm controller's state: no
    # algebraic loop), which its measured position must follow.
    connect("arm_controller", "arm_position_command", "guard",
            "arm.position_command")
    connect("guard", "wrist.wrench_measured", "wrench", "wrist_wrench")
    connect("guard", "lidar.obstacle_points", "base_cdmp", "obstacle_points")
    # Task inputs.
    connect("guard", "reference_velocity", "whole_body_cdmp",
            "reference_velocity")
    connect("guard", "desired_wrench", "arm_cdmp", "desired_wrench")
    connect("guard", "phri_switch.whole_body", "whole_body_cdmp",
            "phri_switch")
    connect("guard", "phri_switch.arm", "arm_cdmp", "phri_switch")
    connect("guard", "null_space_gain", "distributor", "null_space_gain")
    connect("guard", "compensation_switch", "compensator",
            "compensation_switch")
    # The safe stop; the protective stop (a point on or inside the
    # footprint) holds the arm and the couplings as it does.
    connect("guard", "stop", "base_gate", "stop")
    connect("guard", "stopped", "base_limiter", "stopped")
    connect("guard", "stop", "any_stop", "u0")
    connect("base_limiter", "protective_stop", "any_stop", "u1")
    connect("any_stop", "sum", "arm_controller", "hold")
    connect("guard", "resume", "arm_controller", "resume")
    for gate in ("base_cdmp_gate", "arm_cdmp_gate", "deviation_gate"):
        connect("any_stop", "sum", gate, "stop")

    connect("base_yaw", "y0", "whole_body_cdmp", "base_yaw")
    # F_ext in the frame of each DMP's velocity: T_b for the whole body's
    # (with V_ee), T_a for the arm's (with V_a).
    if "admittance_filter" in s:
        connect("wrench", "external_wrench_in_base", "admittance_filter",
                "wrench")
        connect("admittance_filter", "filtered_wrench", "whole_body_cdmp",
                "wrench")
    else:
        connect("wrench", "external_wrench_in_base", "whole_body_cdmp",
                "wrench")
    connect("wrench", "external_wrench", "arm_cdmp", "wrench")
    for destination in ("workspace", "distributor"):
        connect("whole_body_cdmp", "end_effector_velocity", destination,
                "end_effector_velocity")
        for name in ("end_effector_position", "capability",
                     "capability_gradient"):
            connect("capability", name, destination, name)
    for name in ("sigma_xy", "sigma_phi"):
        connect("workspace", name, "distributor", name)
    connect("distributor", "base_velocity", "base_cdmp_gate", "value")
    connect("base_cdmp_gate", "gated", "base_cdmp", "base_velocity")
    connect("base_cdmp", "avoiding_base_velocity", "base_gate", "value")
    connect("base_gate", "gated", "base_filter", "velocity")
    connect("base_filter", "filtered_velocity", "base_limiter", "velocity")
    connect("base_gate", "scale", "base_limiter", "envelope_scale")
    connect("guard", "lidar.obstacle_points", "base_limiter",
            "obstacle_points")
    connect("guard", "base.state_estimated", "base_limiter", "base_state")
    # The base's motion of the "measured" source (params.compensator).
    connect("guard", "base.state_estimated", "compensator", "base_state")
    connect("distributor", "arm_velocity", "compensator", "arm_velocity")
    connect("distributor", "base_velocity", "compensator", "base_velocity")
    connect("base_limiter", "velocity_command", "compensator",
            "filtered_base_velocity")
    for name in ("end_effector_position", "capability_gradient", "alpha"):
        connect("capability", name, "compensator", name)
    connect("compensator", "end_effector_deviation", "deviation_gate",
            "value")
    connect("deviation_gate", "gated", "whole_body_cdmp",
            "end_effector_deviation")
    connect("compensator", "arm_reference_velocity", "arm_cdmp_gate",
            "value")
    connect("arm_cdmp_gate", "gated", "arm_cdmp", "arm_velocity")
    connect("arm_cdmp", "arm_velocity_command", "arm_controller",
            "arm_velocity")

    outputs = (
        ("base_limiter", "velocity_command", "base.velocity_command"),
        ("arm_controller", "arm_position_command", "arm.position_command"),
        ("capability", "capability", "capability"),
        ("capability", "alpha", "alpha"),
        ("workspace", "sigma_xy", "sigma_xy"),
        ("workspace", "sigma_phi", "sigma_phi"),
        ("compensator", "end_effector_deviation", "end_effector_deviation"),
        ("distributor", "base_velocity", "base_velocity"),
        ("base_filter", "filtered_velocity", "filtered_base_velocity"),
        ("arm_cdmp", "arm_velocity_command", "arm_velocity_command"),
        ("arm_controller", "limited", "arm_limited"),
        ("base_limiter", "saturation", "base_saturation"),
        ("base_limiter", "protective_stop", "base_protective_stop"),
        ("guard", "safety_status", "safety_status"),
        ("guard", "safety_reason", "safety_reason"),
    )
    for stage, port, name in outputs:
        builder.ExportOutput(s[stage].GetOutputPort(port), name)
    diagram = builder.Build()
    diagram.set_name("cdmp_wbc_controller")
    return Controller(diagram, stages, params, arm)


def _input_guard(params, arm):
    """The InputGuard of every controller input: the task inputs' defaults
    are the stages' parameters (what the stages used while their port was
    not connected), and their sizes and ranges those of
    drake_wbc.math.task_inputs.TASK_INPUTS; the base's odometry pose
    within +-MAX_ODOMETRY and its twist within MEASURED_TWIST_FACTOR
    times the robot's own velocity limits; the arm's
    measured positions each within its joint's limits, give or take
    MEASURED_POSITION_MARGIN, and within safety.arm_follow_tolerance of
    the arm controller's last position command (its input
    `arm.position_command`; drake_wbc.math.safety.check_following); the
    wrist's wrench each component within
    the sensor's range (the robot's description's tool.ft_sensor_range:
    a reading beyond what the sensor can measure is a broken or forged
    message, not a force)."""
    vector = GuardedInput
    description = arm.model.description
    sensor_range = np.asarray(description.tool.ft_sensor_range)
    odometry = np.concatenate([
        np.full(3, MAX_ODOMETRY),
        MEASURED_TWIST_FACTOR * np.asarray(description.base.velocity_limits)])

    def task(name, outputs=(), **options):
        spec = TASK_INPUTS[name]
        return vector(name, spec.size, outputs, lower=spec.lower,
                      upper=spec.upper, switch=spec.switch, **options)

    inputs = (
        vector("base.state_estimated", BASE_STATE_SIZE,
               lower=tuple(-odometry), upper=tuple(odometry)),
        vector("arm.position_measured", arm.num_joints, initial=arm.home,
               lower=tuple(arm.lower - MEASURED_POSITION_MARGIN),
               upper=tuple(arm.upper + MEASURED_POSITION_MARGIN),
               follows=Following(
                   "arm.position_command",
                   params.safety.arm_follow_tolerance, "rad",
                   "the arm does not follow (its own stop, or held)")),
        vector("wrist.wrench_measured", 6, lower=tuple(-sensor_range),
               upper=tuple(sensor_range)),
        task("reference_velocity", zero_when_stopped=True),
        task("desired_wrench", (("desired_wrench", params.arm_cdmp.F_d),)),
        # While stopped: the admittance term of eq. (cdmp-wb) off (0),
        # and so is the arm's force term of eq. (cdmp-arm) (1), so that
        # neither DMP integrates a wrench.
        task("phri_switch", (
            ("phri_switch.whole_body", [params.phri_switch], [0.0]),
            ("phri_switch.arm", [params.phri_switch], [1.0]))),
        task("null_space_gain", (
            ("null_space_gain", [params.distributor.null_space_gain]),)),
        task("compensation_switch", (
            ("compensation_switch",
             [params.compensator.compensation_switch]),)),
        # The hardware's watchdog: any value but 0 is a stop (HARDWARE_INPUTS).
        vector("hardware.watchdog_tripped", 1, (
            ("hardware.watchdog_tripped", [0.0]),), lower=0.0, upper=0.0),
    )
    return InputGuard(inputs, points_name="lidar.obstacle_points",
                      time_step=params.time_step, params=params.safety)

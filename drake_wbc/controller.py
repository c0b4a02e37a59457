"""The CDMP-WBC controller as one Drake Diagram (paper Fig. "cdmp_wbc").

One control tick, as wired here (design notes, "data flow of one tick")::

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
                          │   BaseVelocityFilter ──► base.velocity_command
                          ▼          │ V_b^flt
                   RobustCompensator ◄─ s_c ──► delta_V_ee (to WholeBodyCdmp)
                          │ V_a^ref
                          ▼
                       ArmCdmp ◄─ F_ext, F_d, S_hri
                          ▼
             ArmCartesianVelocityController ──► arm.position_command

The station-facing ports carry the names of the simulated station and of
the LCM hardware interface, so the same diagram drives either. The only
feedback edge inside, delta_V_ee, enters WholeBodyCdmp's state alone, and
the commands leave from state (filter, arm controller): no algebraic loop.
"""

from dataclasses import dataclass, field, fields, replace

import numpy as np
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import MatrixGain

from drake_wbc import cdmp
from drake_wbc.arm_control import ArmControllerParameters
from drake_wbc.filtering import BaseFilterParameters
from drake_wbc.robot_model import HOME_ARM_POSITIONS, ArmKinematics
from drake_wbc.systems import (
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
from drake_wbc.systems.capability_stage import (
    ArmCapabilityParameters,
    WorkspaceAdapterParameters,
)
from drake_wbc.systems.coordination import (
    MotionDistributorParameters,
    RobustCompensatorParameters,
)
from drake_wbc.systems.wrench import ExternalWrenchEstimator
from drake_wbc.validation import checked_instance, positive, validated_copy

STATION_INPUTS = (
    "base.state_estimated",
    "arm.position_measured",
    "wrist.wrench_measured",
    "lidar.obstacle_points",
)
"""The controller's inputs from the station (simulated or LCM)."""

TASK_INPUTS = (
    "reference_velocity",
    "desired_wrench",
    "phri_switch",
    "null_space_gain",
    "compensation_switch",
)
"""The task's inputs; all but reference_velocity are optional (the stage's
parameter is used while the port is not connected)."""


@dataclass
class ControllerParameters:
    """Every stage's parameters, with the paper's values as defaults.

    Attributes:
        time_step: the control period h in s (the paper runs at 100 Hz);
            it overrides the time steps inside the stage parameters, and
            base_filter.omega_f must stay below its Nyquist rate
            pi / time_step.
        arm_cdmp: stiffness on every axis by default (S_m = I): force
            control drives the tool towards a surface it has not yet
            touched, so it is the task's choice (the wiping scenario sets
            the paper's S_m = diag(0, 1, 1, 1, 1, 1)), not a default.

    Read from YAML by drake_wbc.config.load_controller_parameters
    (diagrams/controller.yaml lists every field). The parameters are
    read when the controller is built: each stage keeps a validated copy,
    so changing them afterwards has no effect on a built controller; after
    assigning fields, drake_wbc.validation.validate checks the whole tree.
    """

    time_step: float = 0.01
    capability: ArmCapabilityParameters = field(
        default_factory=ArmCapabilityParameters)
    workspace: WorkspaceAdapterParameters = field(
        default_factory=WorkspaceAdapterParameters)
    distributor: MotionDistributorParameters = field(
        default_factory=MotionDistributorParameters)
    base_cdmp: cdmp.BaseCdmpParameters = field(
        default_factory=cdmp.BaseCdmpParameters)
    base_filter: BaseFilterParameters = field(
        default_factory=BaseFilterParameters)
    compensator: RobustCompensatorParameters = field(
        default_factory=RobustCompensatorParameters)
    whole_body_cdmp: cdmp.WholeBodyCdmpParameters = field(
        default_factory=cdmp.WholeBodyCdmpParameters)
    arm_cdmp: cdmp.ArmCdmpParameters = field(
        default_factory=lambda: cdmp.ArmCdmpParameters(S_m=np.ones(6)))
    arm_controller: ArmControllerParameters = field(
        default_factory=ArmControllerParameters)

    def __post_init__(self):
        h = positive("time_step", self.time_step)
        for item in fields(self):
            if item.name != "time_step" and not isinstance(
                    getattr(self, item.name), item.type):
                raise ValueError(
                    f"{item.name} = {getattr(self, item.name)!r} is not "
                    f"allowed: must be a {item.type.__name__}")
        omega_f = self.base_filter.omega_f
        if omega_f >= np.pi / h:
            raise ValueError(
                f"time_step = {h!r} s is not allowed with base_filter."
                f"omega_f = {omega_f!r} rad/s: the filter's cut-off must be "
                f"below the Nyquist rate pi / time_step = {np.pi / h:.6g} "
                "rad/s")


class Controller:
    """The built controller: its Diagram and its stages by name.

    Attributes:
        diagram: the Diagram; add it to a builder and connect its ports.
        stages: dict of the stages (LeafSystems) by name, for logging
            and inspection.
        params: the (validated copy of the) ControllerParameters it was
            built from.
    """

    def __init__(self, diagram, stages, params):
        self.diagram, self.stages, self.params = diagram, stages, params

    def initialize(self, root_context, arm_position=HOME_ARM_POSITIONS,
                   base_velocity=(0.0, 0.0, 0.0)):
        """Starts the controller's state from the robot's measured state:
        the arm command at `arm_position`, the base filter at rest at
        `base_velocity` (T_b). The DMPs start at rest."""
        arm = self.stages["arm_controller"]
        arm.set_arm_position(
            arm.GetMyMutableContextFromRoot(root_context), arm_position)
        base_filter = self.stages["base_filter"]
        base_filter.set_velocity(
            base_filter.GetMyMutableContextFromRoot(root_context),
            np.asarray(base_velocity, dtype=float))


def build_controller(params=None, arm=None):
    """Builds the CDMP-WBC controller Diagram.

    Args:
        params: ControllerParameters (the paper's values if None); the
            controller keeps a validated copy.
        arm: a shared ArmKinematics (a new one if None).

    Returns:
        Controller: the diagram with named ports (STATION_INPUTS,
        TASK_INPUTS; outputs base.velocity_command, arm.position_command
        and the diagnostics capability, alpha, sigma_xy, sigma_phi,
        end_effector_deviation, base_velocity, filtered_base_velocity,
        arm_velocity_command, arm_limited).
    """
    params = validated_copy(checked_instance(
        "params", params, ControllerParameters, ControllerParameters))
    h = params.time_step
    arm = checked_instance("arm", arm, ArmKinematics, ArmKinematics)
    builder = DiagramBuilder()
    add = builder.AddNamedSystem
    stages = dict(
        capability=add("capability", ArmCapability(params.capability, arm)),
        wrench=add("wrench", ExternalWrenchEstimator(arm)),
        base_yaw=add("base_yaw", MatrixGain(
            np.array([[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]]))),
        whole_body_cdmp=add("whole_body_cdmp", WholeBodyCdmp(
            params.whole_body_cdmp, time_step=h)),
        workspace=add("workspace", WorkspaceAdapter(params.workspace, arm)),
        distributor=add("distributor", MotionDistributor(
            params.distributor, arm)),
        base_cdmp=add("base_cdmp", BaseCdmp(params.base_cdmp, time_step=h)),
        base_filter=add("base_filter", BaseVelocityFilter(
            replace(params.base_filter, time_step=h))),
        compensator=add("compensator", RobustCompensator(
            params.compensator, arm)),
        arm_cdmp=add("arm_cdmp", ArmCdmp(params.arm_cdmp, time_step=h)),
        arm_controller=add("arm_controller", ArmCartesianVelocityController(
            replace(params.arm_controller, time_step=h), arm)),
    )
    s = stages

    def connect(source, output, destination, input_name):
        builder.Connect(s[source].GetOutputPort(output),
                        s[destination].GetInputPort(input_name))

    def export(name, *targets):
        index = builder.ExportInput(
            s[targets[0][0]].GetInputPort(targets[0][1]), name)
        for stage, port in targets[1:]:
            builder.ConnectInput(index, s[stage].GetInputPort(port))

    # Station measurements.
    export("base.state_estimated", ("base_yaw", "u0"))
    export("arm.position_measured", ("capability", "arm_position"),
           ("wrench", "arm_position"))
    export("wrist.wrench_measured", ("wrench", "wrist_wrench"))
    export("lidar.obstacle_points", ("base_cdmp", "obstacle_points"))
    # Task inputs.
    export("reference_velocity", ("whole_body_cdmp", "reference_velocity"))
    export("desired_wrench", ("arm_cdmp", "desired_wrench"))
    export("phri_switch", ("whole_body_cdmp", "phri_switch"),
           ("arm_cdmp", "phri_switch"))
    export("null_space_gain", ("distributor", "null_space_gain"))
    export("compensation_switch", ("compensator", "compensation_switch"))

    connect("base_yaw", "y0", "whole_body_cdmp", "base_yaw")
    connect("wrench", "external_wrench", "whole_body_cdmp", "wrench")
    connect("wrench", "external_wrench", "arm_cdmp", "wrench")
    for destination in ("workspace", "distributor"):
        connect("whole_body_cdmp", "end_effector_velocity", destination,
                "end_effector_velocity")
        for name in ("end_effector_position", "capability",
                     "capability_gradient"):
            connect("capability", name, destination, name)
    for name in ("sigma_xy", "sigma_phi"):
        connect("workspace", name, "distributor", name)
    connect("distributor", "base_velocity", "base_cdmp", "base_velocity")
    connect("base_cdmp", "avoiding_base_velocity", "base_filter", "velocity")
    connect("distributor", "arm_velocity", "compensator", "arm_velocity")
    connect("distributor", "base_velocity", "compensator", "base_velocity")
    connect("base_filter", "filtered_velocity", "compensator",
            "filtered_base_velocity")
    for name in ("end_effector_position", "capability_gradient", "alpha"):
        connect("capability", name, "compensator", name)
    connect("compensator", "end_effector_deviation", "whole_body_cdmp",
            "end_effector_deviation")
    connect("compensator", "arm_reference_velocity", "arm_cdmp",
            "arm_velocity")
    connect("arm_cdmp", "arm_velocity_command", "arm_controller",
            "arm_velocity")

    outputs = (
        ("base_filter", "filtered_velocity", "base.velocity_command"),
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
    )
    for stage, port, name in outputs:
        builder.ExportOutput(s[stage].GetOutputPort(port), name)
    diagram = builder.Build()
    diagram.set_name("cdmp_wbc_controller")
    return Controller(diagram, stages, params)

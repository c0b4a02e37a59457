"""The controller Diagram: it builds without algebraic loops, runs against
fixed measurements without NaN, and reads the wrist sensor right."""

import numpy as np
import pytest
from locked_robot import sensor_reading, settle_locked_robot
from pydrake.common.value import AbstractValue
from pydrake.multibody.math import SpatialForce
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource, VectorLogSink

from drake_wbc.controller import ControllerParameters, build_controller
from drake_wbc.controller.diagram import HARDWARE_INPUTS, STATION_INPUTS
from drake_wbc.math.task_inputs import TASK_INPUTS
from drake_wbc.robot.model import (
    HOME_ARM_POSITIONS,
    ArmKinematics,
    ArmMount,
)
from drake_wbc.stages.wrench import (
    ExternalWrenchEstimator,
    tool_weight_reading,
)


@pytest.fixture(scope="module")
def arm():
    return ArmKinematics()


def test_ports(arm):
    controller = build_controller(robot=arm)
    diagram = controller.diagram
    inputs = {diagram.get_input_port(i).get_name()
              for i in range(diagram.num_input_ports())}
    assert inputs == set(STATION_INPUTS + tuple(TASK_INPUTS) + HARDWARE_INPUTS)
    for name in ("base.velocity_command", "arm.position_command",
                 "capability", "alpha", "sigma_xy", "sigma_phi",
                 "end_effector_deviation", "base_velocity",
                 "filtered_base_velocity"):
        assert diagram.HasOutputPort(name)


def test_runs_ten_seconds_against_fixed_measurements(arm):
    controller = build_controller(robot=arm)
    builder = DiagramBuilder()
    diagram = builder.AddSystem(controller.diagram)
    names = ("base.velocity_command", "arm.position_command", "capability",
             "alpha", "end_effector_deviation", "filtered_base_velocity")
    logs = {}
    for name in names:
        port = diagram.GetOutputPort(name)
        logs[name] = builder.AddSystem(
            VectorLogSink(port.size(), publish_period=0.01))
        builder.Connect(port, logs[name].get_input_port())
    points = builder.AddSystem(ConstantValueSource(AbstractValue.Make(
        np.array([[0.7, 0.1], [-0.6, -0.45], [2.0, 0.0]]))))
    builder.Connect(points.get_output_port(),
                    diagram.GetInputPort("lidar.obstacle_points"))
    # An arm whose servo follows at once (a measurement far from the
    # command is a fault: the arm does not follow).
    builder.Connect(diagram.GetOutputPort("arm.position_command"),
                    diagram.GetInputPort("arm.position_measured"))
    root = builder.Build()
    context = root.CreateDefaultContext()
    inner = diagram.GetMyMutableContextFromRoot(context)
    diagram.GetInputPort("base.state_estimated").FixValue(
        inner, [0.0, 0.0, 0.3, 0.0, 0.0, 0.0])
    diagram.GetInputPort("wrist.wrench_measured").FixValue(
        inner, tool_weight_reading(arm, HOME_ARM_POSITIONS))
    diagram.GetInputPort("reference_velocity").FixValue(
        inner, [0.1, 0.05, 0.0, 0.0, 0.0, 0.05])
    controller.initialize(context)
    simulator = Simulator(root, context)
    simulator.AdvanceTo(10.0)
    for name, log in logs.items():
        data = log.FindLog(context).data()
        assert data.shape[1] >= 1000, name
        assert np.all(np.isfinite(data)), name
    q_cmd = logs["arm.position_command"].FindLog(context).data()
    assert np.all(q_cmd <= arm.upper[:, None] + 1e-9)
    assert np.all(q_cmd >= arm.lower[:, None] - 1e-9)
    # sigma = 0.5: half of the planar motion is the base's.
    base = logs["base.velocity_command"].FindLog(context).data()
    assert np.max(np.abs(base[:2, -1])) > 0.01


def test_weight_alone_reads_as_no_external_wrench(arm):
    estimator = ExternalWrenchEstimator(arm)
    context = estimator.CreateDefaultContext()
    rng = np.random.default_rng(3)
    for _ in range(3):
        q = rng.uniform(0.7 * arm.lower, 0.7 * arm.upper)
        estimator.GetInputPort("arm_position").FixValue(context, q)
        estimator.GetInputPort("wrist_wrench").FixValue(
            context, tool_weight_reading(arm, q))
        np.testing.assert_allclose(
            estimator.GetOutputPort("external_wrench").Eval(context), 0.0,
            atol=1e-12)


def test_estimator_recovers_a_push_on_the_simulated_tool(arm):
    """A known wrench applied at the tool centre point of the simulated
    robot: the sensing weld's reaction, read as the sensor reads it, gives
    that wrench back (in T_a, at the tool centre point)."""
    push_W = SpatialForce(tau=[0.3, -0.2, 0.1], f=[4.0, -6.0, 9.0])
    q_a = HOME_ARM_POSITIONS + np.array([0.3, 0.2, -0.1, 0.4, 0.2, 0.5])
    reading = sensor_reading(*settle_locked_robot(q_a, push_W))
    estimator = ExternalWrenchEstimator(arm)
    estimator_context = estimator.CreateDefaultContext()
    estimator.GetInputPort("arm_position").FixValue(estimator_context, q_a)
    estimator.GetInputPort("wrist_wrench").FixValue(estimator_context,
                                                    reading)
    estimate = estimator.GetOutputPort("external_wrench").Eval(
        estimator_context)
    # Base at the origin and the mount locked at rest: T_a is parallel to
    # the world frame, so the push in T_a is the push in W.
    np.testing.assert_allclose(estimate[:3], push_W.translational(),
                               atol=1e-6)
    np.testing.assert_allclose(estimate[3:], push_W.rotational(), atol=1e-6)


@pytest.mark.parametrize("mount", [ArmMount(yaw=0.5 * np.pi),
                                   ArmMount(yaw=0.3, tilt=-0.4)],
                         ids=["turned", "tilted"])
def test_a_mounted_arm_gives_the_push_in_each_dmps_frame(mount):
    """The push on the simulated tool of an arm mounted turned or tilted
    on the base: the estimate gives it back in T_b (the world here) for
    the whole-body CDMP, and in T_a (R_ba^T of it) for the arm's, the
    tool's weight removed along the real vertical."""
    push_W = SpatialForce(tau=[0.3, -0.2, 0.1], f=[4.0, -6.0, 9.0])
    q_a = HOME_ARM_POSITIONS + np.array([0.3, 0.2, -0.1, 0.4, 0.2, 0.5])
    reading = sensor_reading(*settle_locked_robot(q_a, push_W, mount=mount))
    arm = ArmKinematics(mount=mount)
    estimator = ExternalWrenchEstimator(arm)
    context = estimator.CreateDefaultContext()
    estimator.GetInputPort("arm_position").FixValue(context, q_a)
    estimator.GetInputPort("wrist_wrench").FixValue(context, reading)
    push = np.r_[push_W.translational(), push_W.rotational()]
    np.testing.assert_allclose(
        estimator.GetOutputPort("external_wrench_in_base").Eval(context),
        push, atol=1e-6)
    R_ab = arm.R_ba.T
    np.testing.assert_allclose(
        estimator.GetOutputPort("external_wrench").Eval(context),
        np.r_[R_ab @ push[:3], R_ab @ push[3:]], atol=1e-6)


def test_parameters_are_validated():
    with pytest.raises(ValueError, match="time_step"):
        ControllerParameters(time_step=0.0)
    with pytest.raises(ValueError, match="params"):
        build_controller(params="fast")

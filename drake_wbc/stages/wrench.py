"""ExternalWrenchEstimator: the wrist sensor's reading as the external
wrench F_ext that the coupled DMPs take (drake_wbc.math.wrench)."""

import numpy as np
from pydrake.systems.framework import LeafSystem_

from drake_wbc.math.kernels import body_for
from drake_wbc.math.scalar_support import through_float_function
from drake_wbc.math.wrench import ToolPayload, external_wrench
from drake_wbc.robot.model import ArmKinematics, bodies_outboard
from drake_wbc.stages.support import define_stage


def _tool(arm):
    """(mass, p_M_com): the mass of what the sensor carries (the bodies
    outboard of its measuring weld, model.ft_sensor_joint) and their
    centre of mass in the measurement frame M, from the plant's mass
    properties."""
    plant, model = arm.plant, arm.model
    context = plant.CreateDefaultContext()
    M = model.ft_measurement_frame
    bodies = bodies_outboard(plant, model.ft_sensor_joint.child_body())
    if len(bodies) == 1:
        tool, = bodies
        X_MB = tool.body_frame().CalcPose(context, M)
        return tool.get_mass(context), X_MB.multiply(
            tool.CalcCenterOfMassInBodyFrame(context))
    masses = np.array([body.get_mass(context) for body in bodies])
    centres = np.array([body.body_frame().CalcPose(context, M).multiply(
        body.CalcCenterOfMassInBodyFrame(context)) for body in bodies])
    return float(masses.sum()), masses @ centres / masses.sum()


def tool_weight_reading(arm, q_a):
    """What the wrist sensor reads with nothing touching the tool: the
    tool's weight as [f; tau] at and in the measurement frame M, from the
    plant's mass properties (base level, mount at rest). The reading for
    which `external_wrench` is zero; for tests, benchmarks and tools that
    feed the controller fixed measurements.

    Args:
        arm: ArmKinematics.
        q_a: (n,) the arm's joint positions, rad.
    """
    mass, p_M_com = _tool(arm)
    R_AM = arm.frame_pose(
        q_a, arm.model.ft_measurement_frame).GetAsMatrix34()[:, :3]
    # [w; p_com x w], w = R_AM^T [0, 0, -m g] (drake_wbc.math.wrench).
    return ToolPayload(mass, p_M_com, np.zeros(3)).weight_map.dot(R_AM[2])


@define_stage("ExternalWrenchEstimator_")
def ExternalWrenchEstimator_(T):
    class Impl(LeafSystem_[T]):
        """The external wrench on the tool from the wrist sensor's reading.

        ::

                           ┌─────────────────────────┐
            wrist_wrench ─►│                         │
            arm_position ─►│ ExternalWrenchEstimator ├──► external_wrench
                           └─────────────────────────┘

        - wrist_wrench: (6) the reading [f; tau], the wrench the tool
          exerts on the sensor at its measurement frame, in that frame.
        - arm_position: (n) the measured arm configuration q_a.
        - external_wrench: F_ext (6), the wrench the environment exerts on
          the tool, at the tool centre point, in T_a, with the tool's
          weight removed (drake_wbc.math.wrench.external_wrench).

        The tool's mass and centre of mass are read from the robot model
        when the stage is built, and so is the tool centre point's
        position from the sensor when the tool is welded to it: then the
        sensor's rotation R_AM is the one function of q_a, from the double
        plant (in AutoDiffXd with its derivative by central differences,
        scalar_support.through_float_function), and F_ext is
        math.wrench.external_wrench of the reading and R_AM (its float
        kernel in double). A tool that is not welded to the sensor has its
        lever from the plant too, and the whole estimate goes through
        through_float_function.

        Args:
            arm: an ArmKinematics of the robot (a new one if None).
        """

        def _construct(self, arm=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._arm = ArmKinematics() if arm is None else arm
            plant, model = self._arm.plant, self._arm.model
            self._tool_mass, self._p_M_com = _tool(self._arm)
            sensor, tcp = model.ft_measurement_frame, model.tcp_frame
            welded = tcp.body().index() in [
                body.index() for body in plant.GetBodiesWeldedTo(
                    sensor.body())]
            self._payload = None
            if welded:
                p_TM = -tcp.CalcPose(plant.CreateDefaultContext(),
                                     sensor).translation()
                self._payload = ToolPayload(self._tool_mass,
                                            self._p_M_com, p_TM)
            self._wrench = body_for(external_wrench, T)
            self._reading = self.DeclareVectorInputPort("wrist_wrench", 6)
            self._joints = self._arm.num_joints
            self._position = self.DeclareVectorInputPort("arm_position",
                                                         self._joints)
            self.DeclareVectorOutputPort(
                "external_wrench", 6,
                self._output if welded else self._output_with_lever)

        def _rotation(self, q_a):
            """R_AM (3, 3) at the arm's joints (float)."""
            return self._arm.frame_pose(
                q_a, self._arm.model.ft_measurement_frame).GetAsMatrix34()[
                    :, :3]

        def _estimate(self, inputs):
            """F_ext from the values [q_a; reading] (n + 6,), the lever
            from the plant (a tool not welded to the sensor)."""
            n, model = self._joints, self._arm.model
            q_a = inputs[:n]
            R_AM = self._rotation(q_a)
            r_TM = (self._arm.frame_pose(q_a, model.ft_measurement_frame)
                    .translation()
                    - self._arm.frame_pose(q_a, model.tcp_frame)
                    .translation())
            return self._wrench(inputs[n:], R_AM, ToolPayload(
                self._tool_mass, self._p_M_com, R_AM.T @ r_TM))

        def _output(self, context, output):
            output.set_value(self._wrench(
                self._reading.Eval(context),
                through_float_function(self._rotation,
                                       self._position.Eval(context)),
                self._payload))

        def _output_with_lever(self, context, output):
            output.SetFromVector(through_float_function(
                self._estimate, np.concatenate(
                    [self._position.Eval(context),
                     self._reading.Eval(context)])))

    return Impl


ExternalWrenchEstimator = ExternalWrenchEstimator_[None]

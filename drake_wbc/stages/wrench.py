"""ExternalWrenchEstimator: the wrist sensor's reading as the external
wrench F_ext that the coupled DMPs take."""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_wbc.math.scalar_support import through_float_function
from drake_wbc.robot.model import ArmKinematics

STANDARD_GRAVITY = 9.81
"""m/s^2, along -z of T_a when the base stands level."""

SCALARS = [float, AutoDiffXd]
"""Double, and AutoDiffXd for Linearize; not symbolic (the stage branches
on values)."""


def external_wrench(reading, X_AM, X_AT, tool_mass, p_M_com):
    """The wrench that the environment exerts on the tool, from a reading.

    The sensor reads the wrench [f; tau] that the tool exerts on it, at and
    in its measurement frame M: the tool's weight plus every external
    wrench on the tool. Removing the weight (payload compensation) and
    moving the result to the tool centre point T, expressed in T_a:

        f_ext = f - m R_MA g,   tau_ext = tau - p_com x (m R_MA g)   (in M),
        F_ext = [R_AM f_ext;  R_AM tau_ext + (p_M - p_T) x R_AM f_ext].

    Args:
        reading: (6,) [f; tau] in M, N and N m.
        X_AM, X_AT: poses of M and of the tool centre point in T_a.
        tool_mass: the mass beyond the measuring plane, kg.
        p_M_com: (3,) its centre of mass in M, m.

    Returns:
        (6,) F_ext = [force; torque] on the tool, at T, in T_a: the force
        convention of drake_wbc.math.cdmp.
    """
    R_AM = X_AM.rotation().matrix()
    weight_M = R_AM.T @ np.array([0.0, 0.0, -tool_mass * STANDARD_GRAVITY])
    f_M = reading[:3] - weight_M
    tau_M = reading[3:] - _cross(p_M_com, weight_M)
    f_A = R_AM @ f_M
    r_TM = X_AM.translation() - X_AT.translation()
    return np.concatenate([f_A, R_AM @ tau_M + _cross(r_TM, f_A)])


def tool_weight_reading(arm, q_a):
    """What the wrist sensor reads with nothing touching the tool: the
    tool's weight as [f; tau] at and in the measurement frame M, from the
    plant's mass properties (base level, mount at rest). The reading for
    which `external_wrench` is zero; for tests, benchmarks and tools that
    feed the controller fixed measurements.

    Args:
        arm: ArmKinematics.
        q_a: (6,) the arm's joint positions, rad.
    """
    plant, model = arm.plant, arm.model
    tool = plant.GetBodyByName("wiping_tool", model.tool)
    context = plant.CreateDefaultContext()
    X_MB = tool.body_frame().CalcPose(context, model.ft_measurement_frame)
    p_M_com = X_MB.multiply(tool.CalcCenterOfMassInBodyFrame(context))
    R_AM = arm.frame_pose(q_a, model.ft_measurement_frame).rotation()
    weight_M = R_AM.inverse().multiply(np.array(
        [0.0, 0.0, -STANDARD_GRAVITY * tool.get_mass(context)]))
    return np.concatenate([weight_M, _cross(p_M_com, weight_M)])


def _skew(p):
    """S(p) with S(p) v = p x v."""
    return np.array([[0.0, -p[2], p[1]], [p[2], 0.0, -p[0]],
                     [-p[1], p[0], 0.0]])


def _cross(a, b):
    """a x b of 3-vectors (np.cross is slow for one pair)."""
    return np.array([a[1] * b[2] - a[2] * b[1],
                     a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


@TemplateSystem.define("ExternalWrenchEstimator_", T_list=SCALARS)
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
        - arm_position: (6) the measured arm configuration q_a.
        - external_wrench: F_ext (6), the wrench the environment exerts on
          the tool, at the tool centre point, in T_a, with the tool's
          weight removed (see `external_wrench`).

        The tool's mass and centre of mass are read from the robot model.
        In AutoDiffXd the derivative comes from central differences of the
        double computation (scalar_support.through_float_function).

        In double, when the tool centre point is fixed to the sensor (the
        tool welded to it), the pose of T in M is taken once and
        `external_wrench` runs as two constant linear maps and a rotation:
        with w = R_AM^T [0, 0, -m g] = -m g R_AM[2, :],

            [f_M; tau_M] = reading - [w; p_com x w],
            F_ext = diag(R_AM, R_AM) [f_M; tau_M + p_TM x f_M],

        p_TM the position of M from T, in M (r_TM = R_AM p_TM): one pose
        from the plant a tick, the same wrench up to round-off.

        Args:
            arm: an ArmKinematics of the robot (a new one if None).
        """

        def _construct(self, arm=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._arm = ArmKinematics() if arm is None else arm
            plant, model = self._arm.plant, self._arm.model
            tool = plant.GetBodyByName("wiping_tool", model.tool)
            context = plant.CreateDefaultContext()
            self._tool_mass = tool.get_mass(context)
            X_MB = tool.body_frame().CalcPose(
                context, model.ft_measurement_frame)
            self._p_M_com = X_MB.multiply(
                tool.CalcCenterOfMassInBodyFrame(context))
            self._reading = self.DeclareVectorInputPort("wrist_wrench", 6)
            self._position = self.DeclareVectorInputPort("arm_position", 6)
            self._prepare_fast_path(plant, context, model)
            self.DeclareVectorOutputPort(
                "external_wrench", 6,
                self._fast_output if self._fast else self._output)

        def _prepare_fast_path(self, plant, context, model):
            """The constant maps of the fast path (class docstring), in
            double when the tool centre point is welded to the sensor."""
            sensor, tcp = model.ft_measurement_frame, model.tcp_frame
            welded = plant.GetBodiesWeldedTo(sensor.body())
            self._fast = T is float and tcp.body().index() in [
                body.index() for body in welded]
            if not self._fast:
                return
            p_TM = -tcp.CalcPose(context, sensor).translation()
            identity = np.eye(3)
            self._weight_map = (-self._tool_mass * STANDARD_GRAVITY) * (
                np.vstack([identity, _skew(self._p_M_com)]))
            self._lever_map = np.block([[identity, np.zeros((3, 3))],
                                        [_skew(p_TM), identity]])

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other._arm, converter=converter)

        def _estimate(self, inputs):
            q_a, reading = inputs[:6], inputs[6:]
            model = self._arm.model
            return external_wrench(
                reading,
                self._arm.frame_pose(q_a, model.ft_measurement_frame),
                self._arm.frame_pose(q_a, model.tcp_frame),
                self._tool_mass,
                self._p_M_com,
            )

        def _output(self, context, output):
            inputs = np.concatenate([self._position.Eval(context),
                                     self._reading.Eval(context)])
            output.SetFromVector(through_float_function(self._estimate,
                                                        inputs))

        def _fast_output(self, context, output):
            X_AM = self._arm.frame_pose(self._position.Eval(context),
                                        self._arm.model.ft_measurement_frame)
            R_AM = X_AM.GetAsMatrix34()[:, :3]
            in_M = self._lever_map.dot(self._reading.Eval(context)
                                       - self._weight_map.dot(R_AM[2]))
            output.set_value(in_M.reshape(2, 3).dot(R_AM.T).ravel())

    return Impl


ExternalWrenchEstimator = ExternalWrenchEstimator_[None]

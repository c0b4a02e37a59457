"""ExternalWrenchEstimator: the wrist sensor's reading as the external
wrench F_ext that the coupled DMPs take (drake_wbc.math.wrench), in T_b
for the whole body's and in T_a for the arm's."""

import math

import numpy as np
from pydrake.systems.framework import LeafSystem_

from drake_wbc.math.kernels import body_for
from drake_wbc.math.kinematics import rotate_twist
from drake_wbc.math.scalar_support import all_finite, through_float_function
from drake_wbc.math.validation import checked_instance, positive
from drake_wbc.math.wrench import (
    ToolPayload,
    WrenchEstimatorParameters,
    external_wrench,
    tool_motion,
)
from drake_wbc.robot.model import ArmKinematics, bodies_outboard
from drake_wbc.stages.support import define_stage, tickets


def _payload_inertia(arm):
    """M_PMo_M: the spatial inertia of what the sensor carries (the bodies
    outboard of its measuring weld, model.ft_sensor_joint) about the
    measurement frame M's origin, in M, from the plant's mass
    properties."""
    plant, model = arm.plant, arm.model
    context = plant.CreateDefaultContext()
    M = model.ft_measurement_frame
    total = None
    for body in bodies_outboard(plant, model.ft_sensor_joint.child_body()):
        X_MB = body.body_frame().CalcPose(context, M)
        # About Bo in B, re-expressed in M, then shifted to Mo.
        M_BMo_M = body.CalcSpatialInertiaInBodyFrame(context).ReExpress(
            X_MB.rotation()).Shift(-X_MB.translation())
        if total is None:
            total = M_BMo_M
        else:
            total += M_BMo_M
    return total


def _tool(arm):
    """(mass, p_M_com): the mass of what the sensor carries and its
    centre of mass in the measurement frame M (_payload_inertia)."""
    inertia = _payload_inertia(arm)
    return inertia.get_mass(), inertia.get_com()


def _tool_inertia(arm):
    """(3, 3) the rotational inertia of what the sensor carries about its
    centre of mass, in M's axes, kg m^2."""
    inertia = _payload_inertia(arm)
    return inertia.Shift(inertia.get_com()).CalcRotationalInertia(
    ).CopyToFullMatrix3()


def _turned(arm):
    """Whether T_a is turned in T_b (^bR_a is not the identity), by an
    ArmMount or by the robot's own model."""
    return not np.array_equal(arm.R_ba, np.eye(3))


def sensor_rotation_in_base(arm, q_a):
    """R_BM (3, 3), the rotation of the sensor's measurement frame M in
    T_b at the arm's joints q_a (float): ^bR_a R_AM, nominal kinematics
    (base level, mount at rest)."""
    R_AM = arm.frame_matrix(q_a, arm.model.ft_measurement_frame)[:3, :3]
    return arm.R_ba @ R_AM if _turned(arm) else R_AM


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
    R_BM = sensor_rotation_in_base(arm, q_a)
    # [w; p_com x w], w = R_BM^T [0, 0, -m g] (drake_wbc.math.wrench).
    return ToolPayload(mass, p_M_com, np.zeros(3)).weight_map.dot(R_BM[2])


@define_stage("ExternalWrenchEstimator_")
def ExternalWrenchEstimator_(T):
    class Impl(LeafSystem_[T]):
        """The external wrench on the tool from the wrist sensor's reading.

        ::

                           ┌─────────────────────────┐
            wrist_wrench ─►│                         ├──► external_wrench_
                           │ ExternalWrenchEstimator │    in_base
            arm_position ─►│                         ├──► external_wrench
                           └─────────────────────────┘

        - wrist_wrench: (6) the reading [f; tau], the wrench the tool
          exerts on the sensor at its measurement frame, in that frame.
        - arm_position: (n) the measured arm configuration q_a.
        - external_wrench_in_base: F_ext (6), the wrench the environment
          exerts on the tool, at the tool centre point, in T_b, with the
          tool's weight removed (drake_wbc.math.wrench.external_wrench
          with L = T_b): the whole-body CDMP's (eq. (cdmp-wb)).
        - external_wrench: the same F_ext in T_a, R_ba^T times the above:
          the arm CDMP's (eq. (cdmp-arm)). The same vector for the
          shipped robot (R_ba = I).

        With params.inertia_compensation the tool's inertial reaction is
        removed too (math.wrench, module docstring): the stage keeps the
        last three arm positions (state, updated every time_step), and
        the reading, params.sensor_delay ticks older than arm_position,
        is taken with the sensor's pose at its own time and the tool's
        motion of the central differences centred there
        (math.wrench.tool_motion), so that the acceleration and the
        reaction it explains are in phase. F_ext is then that reading's,
        sensor_delay ticks old. The motion is the nominal kinematics'
        (the base standing, the mount at rest): the mount's rocking and
        the base's acceleration are not measured and stay in F_ext.

        The tool's mass and centre of mass are read from the robot model
        when the stage is built, and so is the tool centre point's
        position from the sensor when the tool is welded to it: then the
        sensor's rotation R_BM = ^bR_a R_AM is the one function of q_a,
        from the double plant (in AutoDiffXd with its derivative by
        central differences, scalar_support.through_float_function), and
        F_ext is math.wrench.external_wrench of the reading and R_BM (its
        float kernel in double). A tool that is not welded to the sensor
        has its lever from the plant too, and the whole estimate goes
        through through_float_function. A reading or a joint angle that
        is not finite makes F_ext non-finite (NaN in every entry for a
        joint angle), for the checks downstream; nothing raises in a tick.

        Args:
            arm: an ArmKinematics of the robot (a new one of the shipped
                robot if None); anything else is refused (ValueError).
            params: WrenchEstimatorParameters (the weight alone if None).
            time_step: the control period h, s (the arm positions'
                sample period, with inertia compensation).
        """

        def _construct(self, arm=None, params=None, time_step=0.01,
                       converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._arm = checked_instance("arm", arm, ArmKinematics,
                                         ArmKinematics)
            self.params = checked_instance(
                "params", params, WrenchEstimatorParameters,
                WrenchEstimatorParameters)
            self._h = positive("time_step", time_step)
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
            # R_ab = R_ba^T, None for an arm parallel to the base (R_ba =
            # I, as the shipped robot's).
            self._R_ab = (self._arm.R_ba.T.copy() if _turned(self._arm)
                          else None)
            self._reading = self.DeclareVectorInputPort("wrist_wrench", 6)
            self._joints = n = self._arm.num_joints
            self._position = self.DeclareVectorInputPort("arm_position", n)
            moving = self.params.inertia_compensation
            if moving and not welded:
                raise ValueError(
                    "params.inertia_compensation = True is not allowed for "
                    "a tool not welded to the sensor")
            # What F_ext depends on: the two inputs and, with inertia
            # compensation, the remembered arm positions.
            depends = tickets((self._reading, self._position))
            if moving:
                self._payload = ToolPayload(
                    self._tool_mass, self._p_M_com, p_TM,
                    inertia=_tool_inertia(self._arm))
                self._past = self.DeclareDiscreteState(
                    np.tile(self._arm.home, 3))
                self.DeclarePeriodicDiscreteUpdateEvent(
                    self._h, 0.0, self._remember)
                depends.add(self.discrete_state_ticket(self._past))
            calc = (self._output_moving if moving else
                    self._output if welded else self._output_with_lever)
            self._in_base = self.DeclareVectorOutputPort(
                "external_wrench_in_base", 6, calc, depends)
            self.DeclareVectorOutputPort(
                "external_wrench", 6, self._output_in_arm, depends)

        def _rotation(self, q_a):
            """R_BM (3, 3) at the arm's joints (float); NaN in every entry
            for a joint angle that is not finite."""
            if not all_finite(q_a):
                return np.full((3, 3), math.nan)
            return sensor_rotation_in_base(self._arm, q_a)

        def _estimate(self, inputs):
            """F_ext in T_b from the values [q_a; reading] (n + 6,), the
            lever from the plant (a tool not welded to the sensor)."""
            n, model = self._joints, self._arm.model
            q_a = inputs[:n]
            if not all_finite(q_a):
                return np.full(6, math.nan)
            R_BM = self._rotation(q_a)
            X_AM = self._arm.frame_pose(q_a, model.ft_measurement_frame)
            r_TM = (X_AM.translation()
                    - self._arm.frame_pose(q_a, model.tcp_frame)
                    .translation())
            R_AM = X_AM.GetAsMatrix34()[:, :3]
            return self._wrench(inputs[n:], R_BM, ToolPayload(
                self._tool_mass, self._p_M_com, R_AM.T @ r_TM))

        def set_arm_position(self, context, q_a):
            """Starts the remembered arm positions at q_a (n,), the arm
            at rest (with inertia compensation; else nothing to do)."""
            if self.params.inertia_compensation:
                context.SetDiscreteState(np.tile(
                    np.asarray(q_a, dtype=float), 3))

        def _remember(self, context, discrete_state):
            """[q(k); q(k-1); q(k-2)] from q(k) and the state [q(k-1);
            q(k-2); q(k-3)]."""
            past = context.get_discrete_state(self._past).CopyToVector()
            discrete_state.get_mutable_vector(self._past).SetFromVector(
                np.concatenate([self._position.Eval(context),
                                past[:2 * self._joints]]))

        def _pose_and_motion(self, positions):
            """[R_BM (9) at the reading's time; motion (6)] from [q(k);
            q(k-1); q(k-2); q(k-3)] (4 n,), float; NaN in every entry
            for a joint angle that is not finite."""
            if not all_finite(positions):
                return np.full(15, math.nan)
            q = positions.reshape(4, self._joints)
            d = self.params.sensor_delay
            # The three samples around the reading's time k - d, oldest
            # first.
            window = q[d - 1:d + 2][::-1]
            rotations, centres = [], []
            R_ba = self._arm.R_ba
            for q_a in window:
                X_AM = self._arm.frame_pose(
                    q_a, self._arm.model.ft_measurement_frame)
                rotations.append(sensor_rotation_in_base(self._arm, q_a))
                centres.append(R_ba @ X_AM.multiply(self._p_M_com))
            motion = tool_motion(np.array(rotations), np.array(centres),
                                 self._payload, self._h)
            return np.concatenate([rotations[1].ravel(), motion])

        def _output_moving(self, context, output):
            pose = through_float_function(self._pose_and_motion, np.concatenate(
                [self._position.Eval(context),
                 context.get_discrete_state(self._past).CopyToVector()]))
            output.set_value(self._wrench(
                self._reading.Eval(context), pose[:9].reshape(3, 3),
                self._payload, pose[9:]))

        def _output_in_arm(self, context, output):
            in_base = self._in_base.Eval(context)
            output.SetFromVector(in_base if self._R_ab is None
                                 else rotate_twist(self._R_ab, in_base))

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

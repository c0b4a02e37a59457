"""The CDMP of the whole body as a Drake system, eqs. (cdmp-wb) and
(cdmp-wb-error), optionally playing a learned movement (eq. (6) with a
learned forcing term; drake_wbc.math.movement).

Like the other stages (drake_wbc.stages.cdmp_base.CdmpStage), it runs the
affine model x_dot = A x + B u + c of the math layer's derivative
(cdmp.whole_body_cdmp_derivative), in continuous time or exactly
discretised with a zero-order hold at the control period.

A learned movement (WholeBodyCdmpParameters.movement, a
cdmp.MovementReplay) adds two inputs to that model, computed from the
context's time alone (no extra state, so Linearize still runs): the goal
g and the forcing term f(s) (movement.MovementPlayer). Before the
movement's start_time both are zero and the DMP is the paper's; from it,
g = goal - start on x, y, z and yaw and f(s) with s the closed-form phase
of t - start_time (eq. (7)), and the transformation system runs with the
movement's alpha_z, beta_z and tau. The couplings of eq. (cdmp-wb) (the
reference velocity, the wrench k_hri F_ext S_hri) and the tracking-error
term still act, so a worker can still push during a replay. In discrete
time g and f are taken at the middle of each period and held over it (a
second-order accurate hold of the smooth f).

In double the stage takes the fast path of the other CDMP stages (one
matrix [A | B | c] per model on [x; u; 1]), with the yaw rotations of
eq. (3) on plain floats.
"""

import math

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_wbc.math import cdmp
from drake_wbc.math.validation import validated_copy
from drake_wbc.stages.cdmp_base import (
    SCALARS,
    AffineDynamics,
    CdmpStage,
)
from drake_wbc.stages.support import shared_arm_kinematics


def _rotation_z(angle):
    """Rz(angle) for any scalar type."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0 * c], [s, c, 0.0 * c],
                     [0.0 * c, 0.0 * c, 1.0 + 0.0 * c]])


def _rotate_twist(R, twist):
    return np.concatenate([R @ twist[:3], R @ twist[3:]])


def _rotated(c, s, twist):
    """Rz twist, each half of the float twist (a list of 6) rotated by
    Rz with cos c and sin s; a list."""
    vx, vy, vz, wx, wy, wz = twist
    return [c * vx - s * vy, s * vx + c * vy, vz,
            c * wx - s * wy, s * wx + c * wy, wz]


def movement_player(params):
    """The movement.MovementPlayer of params.movement (None without one),
    its file read and checked.

    Raises:
        ValueError: naming movement.file when the file is missing or not
            a learned movement.
    """
    if params.movement is None:
        return None
    from drake_wbc.math.movement import (
        LearnedMovement,
        MovementPlayer,
        resolve_movement_file,
    )

    try:
        movement = LearnedMovement.load(resolve_movement_file(
            params.movement.file))
    except ValueError as error:
        raise ValueError(f"movement.{error}") from None
    return MovementPlayer(movement, params.movement)


def _time(context):
    t = context.get_time()
    return t.value() if isinstance(t, AutoDiffXd) else float(t)


@TemplateSystem.define("WholeBodyCdmp_", T_list=SCALARS)
def WholeBodyCdmp_(T):
    class Impl(CdmpStage, LeafSystem_[T]):
        """CDMP of the whole body, eqs. (cdmp-wb) and (cdmp-wb-error).

        ::

                                    ┌───────────────┐
            reference_velocity ────►│               │
            wrench ────────────────►│               │
            end_effector_deviation ►│ WholeBodyCdmp ├──► end_effector_velocity
            base_yaw ──────────────►│               │
            phri_switch ───────────►│               │
                                    └───────────────┘

        - reference_velocity: V_ee^ref (6), world frame, [v; w].
        - wrench: F_ext (6), the wrench on the end effector, T_b.
        - end_effector_deviation: delta_V_ee (6) of eq. (deviation), T_b;
          it is integrated (E = int delta_V_ee dt) and enters only the
          state, so this edge closes no algebraic loop.
        - base_yaw: phi_b (1), optional (0 when unconnected).
        - phri_switch: S_hri (1), optional (the parameter when
          unconnected; >= 0.5 counts as 1).
        - end_effector_velocity: V_ee (6), y_dot rotated into T_b by
          eq. (3), for the distributor.

        State [y, z, C, E] (24), world frame, displacements from the start
        (goal g = 0, or the learned movement's from its start_time).
        Orientation is carried as integrated angular velocity, which is
        exact for the velocity interface; a learned yaw is its z entry.

        Args:
            params: cdmp.WholeBodyCdmpParameters (paper values if None);
                its `movement`, if any, is read here.
            time_step: control period h (0: continuous), default 0.01 s.
        """

        def _construct(self, params=None, time_step=0.01, converter=None,
                       player=None):
            LeafSystem_[T].__init__(self, converter)
            params = validated_copy(cdmp.WholeBodyCdmpParameters()
                                    if params is None else params)
            self.params, self._dimension = params, 6
            self._default_switch = params.S_hri
            self.player = player or movement_player(params)
            num_inputs = 18 if self.player is None else 30

            def derivative(switch, playing):
                dmp = (self.player.transformation_parameters(params.dmp)
                       if playing else params.dmp)

                def f(x, u):
                    y, z, C, E = np.split(x, 4)
                    g, forcing = ((u[18:24], u[24:30]) if num_inputs == 30
                                  else (np.zeros(6), 0.0))
                    return np.concatenate(cdmp.whole_body_cdmp_derivative(
                        y, z, C, E, g, u[:6], u[6:12], u[12:18], params,
                        S_hri=switch, forcing=forcing, dmp=dmp))
                return f

            if self.player is None:
                self._models = {
                    s: AffineDynamics(derivative(s, False), 24, 18,
                                      time_step)
                    for s in (0, 1)
                }
            else:
                self._models = {
                    (s, playing): AffineDynamics(
                        derivative(s, playing), 24, 30, time_step)
                    for s in (0, 1) for playing in (False, True)
                }
            self._check_state_only(slice(12, 18))
            self._fast = T is float
            self._reference = self.DeclareVectorInputPort(
                "reference_velocity", 6)
            self._wrench = self.DeclareVectorInputPort("wrench", 6)
            self._deviation = self.DeclareVectorInputPort(
                "end_effector_deviation", 6)
            self._yaw = self.DeclareVectorInputPort("base_yaw", 1)
            self._phri_port = self.DeclareVectorInputPort("phri_switch", 1)
            state = self._declare_state(24, time_step)
            prerequisites = {
                state,
                *(self.input_port_ticket(p.get_index())
                  for p in (self._reference, self._wrench, self._yaw,
                            self._phri_port)),
            }
            if self.player is not None:
                prerequisites.add(self.time_ticket())
            # The fast path's shared result leaves out the deviation (state
            # only), which the update adds: B_d's columns of it.
            self._declare_output("end_effector_velocity", prerequisites, [
                i for i in range(num_inputs) if not 12 <= i < 18])
            if self._fast and time_step > 0.0:
                self._fast_deviation = {
                    key: np.ascontiguousarray(model.B_d[:, 12:18])
                    for key, model in self._models.items()}

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.params, other._time_step,
                            converter=converter, player=other.player)
            self.params = other.params

        def _movement_time(self, context, for_update):
            """The time at which the movement's g and f are taken: the
            middle of the period for a discrete update."""
            t = _time(context)
            if for_update and self._time_step > 0.0:
                t += 0.5 * self._time_step
            return t

        def _model(self, context, for_update=False):
            switch = self._switch(context)
            if self.player is None:
                return self._models[switch]
            playing = self.player.active(self._movement_time(context,
                                                             for_update))
            return self._models[(switch, playing)]

        def _yaw_rotation(self, context):
            yaw = self._optional(self._yaw, context, np.zeros(1))[0]
            return _rotation_z(yaw)

        def _drive(self, context, for_output=False, for_update=False):
            R_wb = self._yaw_rotation(context)
            wrench = _rotate_twist(R_wb, self._wrench.Eval(context))
            deviation = (0.0 * wrench if for_output else
                         _rotate_twist(R_wb, self._deviation.Eval(context)))
            parts = [self._reference.Eval(context), wrench, deviation]
            if self.player is not None:
                parts += self.player.goal_and_forcing(
                    self._movement_time(context, for_update))
            return np.concatenate(parts)

        def _output(self, context, output):
            R_bw = self._yaw_rotation(context).T
            output.SetFromVector(_rotate_twist(R_bw, self._velocity(context)))

        def _calc_fast_result(self, context, value):
            """In double: (V_ee in T_b, the next state without the
            deviation's part, the model of the update, cos and sin of
            the yaw); a list."""
            yaw = self._yaw
            if yaw.HasValue(context):
                angle = float(yaw.Eval(context)[0])
                c, s = math.cos(angle), math.sin(angle)
            else:
                c, s = 1.0, 0.0
            phri = self._phri_port
            if phri.HasValue(context):
                switch = 1 if phri.Eval(context)[0] >= 0.5 else 0
            else:
                switch = int(self._default_switch)
            known = (self._state(context).tolist()
                     + self._reference.Eval(context).tolist()
                     + _rotated(c, s, self._wrench.Eval(context).tolist()))
            player, d = self.player, self._dimension
            if player is None:
                key = switch
                result = self._fast_models[key].dot(np.array(known + [1.0]))
                velocity, rest = result[:d].tolist(), result[d:]
            else:
                t = context.get_time()
                key = (switch, player.active(t))
                velocity = self._fast_models[key][:d].dot(np.array(
                    known + player.drive_terms(t) + [1.0])).tolist()
                rest = None
                if self._time_step > 0.0:
                    t += 0.5 * self._time_step
                    key = (switch, player.active(t))
                    rest = self._fast_models[key][d:].dot(np.array(
                        known + player.drive_terms(t) + [1.0]))
            vx, vy, vz, wx, wy, wz = velocity
            # Back into T_b: Rz^T.
            value.set_value([[c * vx + s * vy, c * vy - s * vx, vz,
                              c * wx + s * wy, c * wy - s * wx, wz],
                             rest, key, c, s])

        def _fast_output(self, context, output):
            output.set_value(self._fast_result.Eval(context)[0])

        def _fast_update(self, context, discrete_state):
            _, rest, key, c, s = self._fast_result.Eval(context)
            deviation = _rotated(c, s, self._deviation.Eval(context).tolist())
            discrete_state.set_value(
                rest + self._fast_deviation[key].dot(deviation))

    return Impl


WholeBodyCdmp = WholeBodyCdmp_[None]


@TemplateSystem.define("MovementTracking_", T_list=SCALARS)
def MovementTracking_(T):
    class Impl(LeafSystem_[T]):
        """The task's feedback of a learned movement's replay: the TCP's
        measured pose against the pose the DMP plays.

        ::

                                   ┌──────────────────┐
            base.state_estimated ─►│                  │
            arm.position_measured ►│ MovementTracking ├──► reference_velocity
                                   └──────────────────┘

        - base.state_estimated: [x, y, yaw, vx, vy, wz] (6), odometry.
        - arm.position_measured: the arm's joints (6).
        - reference_velocity: V_ee^ref (6) in the world, [v; w]:
          K (p*(t) - p) on x, y, z and yaw (0 on roll and pitch, and
          before the movement's start_time), p* = player.reference(t), p
          the TCP's pose through the nominal kinematics
          (demonstration.TcpPose, here in plain floats: `tcp_pose`), the
          yaw error wrapped into (-pi, pi].

        It enters the whole-body CDMP as the coupling C of eq. (cdmp-wb)
        (C_dot = V_ee^ref), an integral action of gain K on the TCP's
        error: the TCP follows the played pose with no steady error on a
        ramp and ends on the goal. Evaluated on values (no gradient
        through the kinematics in AutoDiffXd).

        Args:
            player: the movement.MovementPlayer of the WholeBodyCdmp.
            arm: an ArmKinematics (our robot's if None).
        """

        def _construct(self, player, arm=None, converter=None):
            from drake_wbc.math.demonstration import TcpPose

            LeafSystem_[T].__init__(self, converter)
            self.player = player
            self._pose = TcpPose(arm or shared_arm_kinematics())
            arm = self._pose.arm
            model = arm.model
            X_BA = model.arm_base_frame.CalcPose(
                arm.plant.CreateDefaultContext(),
                model.base_frame).GetAsMatrix34()
            self._R_BA, self._p_BA = X_BA[:, :3].copy(), X_BA[:, 3].tolist()
            self._base = self.DeclareVectorInputPort(
                "base.state_estimated", 6)
            self._arm = self.DeclareVectorInputPort("arm.position_measured",
                                                    6)
            self.DeclareVectorOutputPort("reference_velocity", 6,
                                         self._output)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.player, other._pose.arm,
                            converter=converter)

        def tcp_pose(self, base_pose, arm_positions):
            """demonstration.TcpPose in plain floats: the TCP's [x, y, z,
            yaw] (a list) in the world from the base's [x, y, yaw] and the
            arm's joints, X_WE = X_WB X_BA X_AE, yaw = atan2(R_WE[1, 0],
            R_WE[0, 0])."""
            arm = self._pose.arm
            X_AE = arm.frame_pose(arm_positions,
                                  arm.model.tcp_frame).GetAsMatrix34()
            # [R_BE | R_BA p_AE]: its first column and its last one.
            (r00, _, _, px), (r10, _, _, py), (_, _, _, pz) = (
                self._R_BA.dot(X_AE).tolist())
            px, py, pz = (px + self._p_BA[0], py + self._p_BA[1],
                          pz + self._p_BA[2])
            x, y, yaw = base_pose
            c, s = math.cos(yaw), math.sin(yaw)
            return [c * px - s * py + x, s * px + c * py + y, pz,
                    math.atan2(s * r00 + c * r10, c * r00 - s * r10)]

        def _output(self, context, output):
            t, player = _time(context), self.player
            K = player.tracking_gain
            if not (player.active(t) and K > 0.0):
                output.SetFromVector(np.zeros(6))
                return
            x, y, yaw = _values(self._base.Eval(context))[:3].tolist()
            pose = self.tcp_pose((x, y, yaw),
                                 _values(self._arm.Eval(context)))
            x, y, z, yaw = [p - q for p, q in zip(
                player.reference(t).tolist(), pose, strict=True)]
            yaw = (yaw + math.pi) % (2.0 * math.pi) - math.pi
            output.SetFromVector([K * x, K * y, K * z, 0.0, 0.0, K * yaw])

    return Impl


def _values(vector):
    """Float values of a float or AutoDiffXd vector."""
    vector = np.asarray(vector)
    if vector.dtype == object:
        return np.array([v.value() for v in vector])
    return vector


MovementTracking = MovementTracking_[None]

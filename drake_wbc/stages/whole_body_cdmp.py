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

Like the other CDMP stages, one matrix [A | B | c] per model acts on
[x; u; 1] each tick; the yaw rotations of eq. (3) are kinematics.twist_in_world
and kinematics.twist_in_base (their float kernels in double).
"""

import math

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_

from drake_wbc.math import cdmp
from drake_wbc.math.base_state import BASE_POSE, BASE_STATE_SIZE
from drake_wbc.math.demonstration import TcpPose, tcp_pose_in_world
from drake_wbc.math.dmp import check_sampled
from drake_wbc.math.kernels import body_for
from drake_wbc.math.kinematics import twist_in_base, twist_in_world
from drake_wbc.math.movement import (
    LearnedMovement,
    MovementPlayer,
    resolve_movement_file,
)
from drake_wbc.math.scalar_support import through_float_function
from drake_wbc.math.task_inputs import TASK_INPUTS
from drake_wbc.math.validation import checked_instance, non_negative
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages.cdmp_base import ONE, AffineDynamics, CdmpStage
from drake_wbc.stages.support import (
    define_stage,
    optional_scalar,
    shared_arm_kinematics,
)

# The input u of the affine models: V_ee^ref, then F_ext and delta_V_ee
# rotated into the world (18 entries), and with a learned movement its goal
# g and forcing term f (30 entries).
_REFERENCE = slice(0, 6)
_WRENCH = slice(6, 12)
_DEVIATION = slice(12, 18)
_GOAL = slice(18, 24)
_FORCING = slice(24, 30)


def movement_player(params):
    """The movement.MovementPlayer of params.movement (None without one),
    its file read and checked.

    Raises:
        ValueError: naming movement.file when the file is missing or not
            a learned movement.
    """
    if params.movement is None:
        return None
    try:
        movement = LearnedMovement.load(resolve_movement_file(
            params.movement.file))
    except ValueError as error:
        raise ValueError(f"movement.{error}") from None
    return MovementPlayer(movement, params.movement)


def _time(context):
    t = context.get_time()
    return t.value() if isinstance(t, AutoDiffXd) else float(t)


@define_stage("WholeBodyCdmp_")
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
        - phri_switch: S_hri (1), optional (the constructor's
          phri_switch when unconnected; >= 0.5 counts as 1).
        - end_effector_velocity: V_ee (6), y_dot rotated into T_b by
          eq. (3), for the distributor.

        State [y, z, C, E] (24), world frame, displacements from the start
        (goal g = 0, or the learned movement's from its start_time).
        Orientation is carried as integrated angular velocity, which is
        exact for the velocity interface; a learned yaw is its z entry.

        Args:
            params: cdmp.WholeBodyCdmpParameters (checked where they were
                made; paper values if None), read here; its `movement`,
                if any, is read here too.
            time_step: control period h (0: continuous), default 0.01 s.
            phri_switch: the default S_hri, 0 or 1, while the phri_switch
                port is not connected; default 0 (the paper sets 1 for
                pHRI).
            player: the movement.MovementPlayer to run, or None for that
                of params.movement.
        """

        def _construct(self, params=None, time_step=0.01, phri_switch=0.0,
                       converter=None, player=None):
            LeafSystem_[T].__init__(self, converter)
            self.params = params = checked_instance(
                "params", params, cdmp.WholeBodyCdmpParameters,
                cdmp.WholeBodyCdmpParameters)
            check_sampled(params.dmp, non_negative("time_step", time_step),
                          "params.dmp")
            self._dimension = 6
            self._default_switch = TASK_INPUTS["phri_switch"].check_number(
                "phri_switch", phri_switch)
            self.player = player or movement_player(params)
            if self.player is not None:  # the DMP it plays, at its tau
                check_sampled(
                    self.player.transformation_parameters(params.dmp),
                    time_step, "movement.dmp",
                    "; play the movement slower (a larger movement.tau)")
            num_inputs = (_DEVIATION.stop if self.player is None
                          else _FORCING.stop)
            self._in_world = body_for(twist_in_world, T)
            self._in_base = body_for(twist_in_base, T)

            def derivative(s_hri, playing):
                dmp = (self.player.transformation_parameters(params.dmp)
                       if playing else params.dmp)

                def f(x, u):
                    y, z, C, E = np.split(x, 4)
                    g, forcing = ((u[_GOAL], u[_FORCING])
                                  if num_inputs == _FORCING.stop
                                  else (np.zeros(6), 0.0))
                    return np.concatenate(cdmp.whole_body_cdmp_derivative(
                        y, z, C, E, g, u[_REFERENCE], u[_WRENCH],
                        u[_DEVIATION], params, S_hri=s_hri, forcing=forcing,
                        dmp=dmp))
                return f

            if self.player is None:
                self._models = {
                    s: AffineDynamics(derivative(s, False), 24,
                                      num_inputs, time_step)
                    for s in (0, 1)
                }
            else:
                self._models = {
                    (s, playing): AffineDynamics(
                        derivative(s, playing), 24, num_inputs, time_step)
                    for s in (0, 1) for playing in (False, True)
                }
            self._check_state_only(_DEVIATION)
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
            # The shared result leaves out the deviation (state only),
            # which the update adds: B_d's columns of it.
            self._declare_output("end_effector_velocity", prerequisites, [
                i for i in range(num_inputs)
                if not _DEVIATION.start <= i < _DEVIATION.stop])
            if time_step > 0.0:
                self._deviation_columns = {
                    key: np.ascontiguousarray(model.B_d[:, _DEVIATION])
                    for key, model in self._models.items()}

        def _construct_copy(self, other, converter=None):
            # The copy shares the original's parameters and its player
            # (which read the movement's file once).
            Impl._construct(self, other.params, other._time_step,
                            other._default_switch, converter=converter,
                            player=other.player)

        def _model_key(self, context, t=None):
            """The model in force at time t (the context's if None)."""
            s_hri = self._switch(context)
            if self.player is None:
                return s_hri
            return (s_hri, self.player.active(
                _time(context) if t is None else t))

        def _inputs(self, context):
            """u (continuous time): the reference, the wrench and the
            deviation in the world, and the movement's g and f at t."""
            yaw = optional_scalar(self._yaw, context, 0.0)
            parts = [self._reference.Eval(context),
                     self._in_world(self._wrench.Eval(context), yaw),
                     self._in_world(self._deviation.Eval(context), yaw)]
            if self.player is not None:
                parts.append(self.player.drive_terms(_time(context)))
            return np.concatenate(parts)

        def _calc_result(self, context, value):
            """(V_ee in T_b, the next state without the deviation's part,
            the model of the update, the yaw)."""
            yaw = optional_scalar(self._yaw, context, 0.0)
            known = (self._state(context), self._reference.Eval(context),
                     self._in_world(self._wrench.Eval(context), yaw))
            player, d = self.player, self._dimension
            if player is None:
                key = self._model_key(context)
                result = self._stacked[key].dot(np.concatenate(
                    (*known, ONE)))
                velocity, rest = result[:d], result[d:]
            else:
                t = _time(context)
                velocity = self._stacked[self._model_key(context, t)][
                    :d].dot(np.concatenate(
                        (*known, player.drive_terms(t), ONE)))
                key, rest = None, None
                if self._time_step > 0.0:
                    # g and f at the middle of the period (module
                    # docstring).
                    t += 0.5 * self._time_step
                    key = self._model_key(context, t)
                    rest = self._stacked[key][d:].dot(np.concatenate(
                        (*known, player.drive_terms(t), ONE)))
            value.set_value([self._in_base(velocity, yaw), rest, key, yaw])

        def _output(self, context, output):
            output.set_value(self._result.Eval(context)[0])

        def _update(self, context, discrete_state):
            _, rest, key, yaw = self._result.Eval(context)
            discrete_state.set_value(
                rest + self._deviation_columns[key].dot(
                    self._in_world(self._deviation.Eval(context), yaw)))

    return Impl


WholeBodyCdmp = WholeBodyCdmp_[None]


@define_stage("MovementTracking_")
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
        - arm.position_measured: the arm's joints (n).
        - reference_velocity: V_ee^ref (6) in the world, [v; w]:
          K (p*(t) - p) on x, y, z and yaw (0 on roll and pitch, and
          before the movement's start_time), p* = player.reference(t), p
          the TCP's pose through the nominal kinematics
          (demonstration.TcpPose), the yaw error wrapped into [-pi, pi).

        It enters the whole-body CDMP as the coupling C of eq. (cdmp-wb)
        (C_dot = V_ee^ref), an integral action of gain K on the TCP's
        error: the TCP follows the played pose with no steady error on a
        ramp and ends on the goal. The error is evaluated in floats (the
        nominal kinematics need a double plant; the float kernel of
        demonstration.tcp_pose_in_world), in AutoDiffXd through
        scalar_support.through_float_function: the values are exact and
        the derivatives w.r.t. the base's pose and the arm's joints come
        from central differences, so that `Linearize` of a replay sees
        the tracking's feedback.

        Args:
            player: the movement.MovementPlayer of the WholeBodyCdmp.
            arm: an ArmKinematics (the shipped robot's if None);
                anything else is refused (ValueError).
        """

        def _construct(self, player, arm=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.player = player
            arm = checked_instance("arm", arm, ArmKinematics,
                                   shared_arm_kinematics)
            self._pose = TcpPose(arm)
            self._tcp_pose_in_world = body_for(tcp_pose_in_world, float)
            self._base = self.DeclareVectorInputPort(
                "base.state_estimated", BASE_STATE_SIZE)
            self._arm = self.DeclareVectorInputPort("arm.position_measured",
                                                    arm.num_joints)
            self.DeclareVectorOutputPort("reference_velocity", 6,
                                         self._output)

        def _output(self, context, output):
            t, player = _time(context), self.player
            K = player.tracking_gain
            if not (player.active(t) and K > 0.0):
                output.SetFromVector(np.zeros(6))
                return
            reference = player.reference(t).tolist()

            def error(measured):
                """p* - p [x, y, z, yaw], the yaw wrapped into [-pi, pi),
                from the float [base pose (3), arm joints (n)]."""
                pose = self._tcp_pose_in_world(
                    measured[:3].tolist(), self._pose.in_base(measured[3:]))
                x, y, z, yaw = [p - q for p, q in zip(reference, pose,
                                                      strict=True)]
                return np.array(
                    [x, y, z, (yaw + math.pi) % (2.0 * math.pi) - math.pi])

            x, y, z, yaw = through_float_function(error, np.concatenate((
                self._base.Eval(context)[BASE_POSE],
                self._arm.Eval(context))))
            output.SetFromVector([K * x, K * y, K * z, 0.0, 0.0, K * yaw])

    return Impl


MovementTracking = MovementTracking_[None]

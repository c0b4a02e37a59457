"""ArmCartesianVelocityController: the arm's twist to joint position
commands as a Drake system."""

from dataclasses import replace

import numpy as np
from pydrake.systems.framework import BasicVector_, LeafSystem_

from drake_wbc.math.arm_control import (
    ArmControllerParameters,
    joint_velocity_command,
    start_within_limits,
    twist_limits,
)
from drake_wbc.math.arm_servo import catch_up_arm, catching_up
from drake_wbc.math.kernels import body_for
from drake_wbc.math.safety import (
    DEFAULT_ARM_FOLLOW_TOLERANCE,
    check_following,
    restart_position,
)
from drake_wbc.math.scalar_support import (
    all_finite,
    through_float_function,
    value_of,
    zero_like,
)
from drake_wbc.math.validation import checked_instance, positive
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages.support import define_stage, optional_scalar

CAUGHT_UP = 0.25
"""A held joint that goes to where the arm is
(`ArmCartesianVelocityController`'s catch-up) has caught up with it
within this fraction of the resume tolerance (0.025 rad for 0.1): far
above any position servo's steady error (a fraction of a mrad on the
shipped arm), which a command that went on following the arm would
chase for ever (an arm sagging 2 mrad below its command took it to the
joint limit), and near enough that the braking from there ends within a
few mrad of the arm."""

TWIST_SIZE = 6
"""V_a = [v_a; w_a] in T_a."""


def own_or(given, own):
    """A limit of ArmControllerParameters, `given`, or the arm's `own`
    where it is None."""
    return own if given is None else given


@define_stage("ArmCartesianVelocityController_")
def ArmCartesianVelocityController_(T):
    class Impl(LeafSystem_[T]):
        """The arm's Cartesian velocity controller of Sec. III-A, for a
        position-controlled arm: V_a -> q_dot_a -> q_a by damped least
        squares, joint-limit, velocity and acceleration limits
        (drake_wbc.math.arm_control.joint_velocity_command), integrated
        once a control period.

        ::

                           ┌──────────────────────┐
            arm_velocity ─►│ ArmCartesianVelocity ├─► arm_position_command
            hold ─────────►│ Controller           ├─► arm_velocity_command
            arm_position ─►│                      ├─► limited
            resume ───────►│                      │
                           └──────────────────────┘

        - arm_velocity: V_a (6), the arm's Cartesian twist command
          [v_a; w_a] in T_a (m/s, rad/s), at the end effector.
        - hold (1): optional (no hold while unconnected); >= 0.5 brings
          the command to rest and holds it there (a safe stop, see
          drake_wbc.stages.safety.InputGuard's `stop`): the update runs
          as for a zero twist and without the self-motion of an arm of
          more than six joints, so q_dot falls to 0 within the
          acceleration limit, along its direction, and within the joint
          limits' braking bounds (at 12.56 rad/s^2, at most 0.125 s and
          0.1 rad from 1.57 rad/s), then q_cmd stays. A position command
          held at once would ask the arm's servo for an unbounded
          deceleration; braking never asks for more than the arm can do.
          When the hold ends the arm restarts from the command it was
          last sent, from rest, within the acceleration limit: no jump
          either way. Held, the command goes to where the arm is when
          the arm is elsewhere (see arm_position). Without an
          acceleration limit (`use_acceleration_limit` false) the
          command stops at once. A twist that is not finite is treated
          the same way (with `limited` 1.0), never integrated.
        - arm_position: optional, q_meas (n, rad), the arm's measured
          joint positions, read with `hold` and with `resume`. Held,
          once a joint of q_meas is farther than `resume_tolerance` from
          q_cmd (the arm was moved, pushed off its command against
          something, or stopped on its own, during the stop), the
          command goes to q_meas (within the band [lower + margin,
          upper - margin] it keeps to when running) at the joint speed
          and acceleration limits instead of braking on the spot
          (drake_wbc.math.arm_servo.catch_up_arm; every joint while one
          is beyond the tolerance, then each joint on its way there
          until within CAUGHT_UP of the tolerance, whence it brakes on
          the profile that stops on the arm), so that it resumes from
          where the
          arm is: its servo, holding the arm there, must not be asked
          to jump back to where the command was, and the servo of an
          arm pushed off its command refuses a command moved there in
          one tick.
        - resume (1): optional (never while unconnected); >= 0.5 at the
          update at which a safe stop clears (InputGuard's `resume`).
          Should a joint of q_meas still be farther than
          `resume_tolerance` from q_cmd (a stop too short to catch up),
          the command restarts from q_meas (within the joint limits;
          drake_wbc.math.safety.restart_position), at rest, before the
          step; not from a q_meas farther beyond a joint's limits than
          one period's step at the acceleration limit from rest (no
          position to start from either, `set_arm_position`): the
          command, held within the limits, would jump away from the arm.
          Then, as within the tolerance, nothing changes: the command
          resumes from where it was.
        - arm_position_command: q_cmd (n, rad), the joint positions for the
          arm's position servo. It is the state: no direct feedthrough.
        - arm_velocity_command: q_dot (n, rad/s) of the last update, the
          rate at which q_cmd moves now (diagnostics, or feed-forward for a
          servo that takes one).
        - limited: 1.0 when the last update was cut by a joint's position
          limit, scaled by the velocity limits or by the acceleration limit,
          else 0.0 (damping near a singularity alone does not count).

        q_cmd never leaves the joint limits [lower, upper]: the update keeps
        it in the band [lower + margin, upper - margin] (a joint outside the
        band only moves back in), and `set_arm_position` clamps a start
        just outside the limits onto them (and refuses one further out).

        One periodic discrete update at the control period h:

            q_dot  = joint_velocity_command(J_a(q_cmd), V_a, q_cmd,
                                            previous q_dot, limits),
            q_cmd <- q_cmd + h q_dot.

        J_a is taken at the commanded configuration q_cmd, not at a
        measured one: the command is what the stiff position servo follows
        (the measurement differs from it only by the servo's small lag),
        and it keeps the controller's own kinematics consistent: q_cmd is
        the integral of exactly the rates computed from it, so a constant
        twist moves the commanded end effector along the commanded line up
        to the O(h) error of the explicit integration, with no feedback of
        the servo's tracking error or of sensor noise into the IK.

        State: [q_cmd (n), q_dot (n), limited (1)], one discrete group, n
        the arm's joints. It starts at the robot's home at rest; use
        `set_arm_position` to start from the measured arm position.

        Scalar types: double and AutoDiffXd. The update runs
        drake_wbc.math.arm_control.joint_velocity_command, the reference
        body, in AutoDiffXd and its float kernel in double (chosen once,
        drake_wbc.math.kernels.body_for). J_a comes from a double
        MultibodyPlant, so in AutoDiffXd it gets its derivatives by central
        differences (scalar_support.through_float_function); the rest of
        the update is differentiated exactly. `Linearize` at a point away
        from singularities and limits (where the map is smooth) is
        therefore accurate to about 1e-9 relative; where a limit is just
        switching, the derivative is that of the side taken. The system
        is at equilibrium only with V_a = 0 and at rest, where `Linearize`
        applies (an arm of more than six joints also needs its
        self-motion to have come to rest: it moves on by itself until
        the joints' centring is satisfied); while it moves, use Drake's
        `FirstOrderTaylorApproximation` (same A and B).

        Args:
            params: ArmControllerParameters; 100 Hz with the defaults of
                drake_wbc.math.arm_control and the model's limits if None.
            kinematics: the ArmKinematics for J_a (e.g. one built on the
                user's plant); one of the robot alone if None. Scalar
                conversion shares it with the converted copy (its
                `evaluate` sets its own context, so the copies must not
                run their updates concurrently from several threads).
            time_step: the control period h > 0 in s, default 0.01 (the
                paper's 100 Hz).
            resume_tolerance: rad > 0, how far the measured position
                (arm_position) may be from q_cmd before the command
                restarts from it (the controller's
                SafetyParameters.arm_follow_tolerance); the default
                DEFAULT_ARM_FOLLOW_TOLERANCE.
        """

        def _construct(self, params=None, kinematics=None, time_step=0.01,
                       resume_tolerance=DEFAULT_ARM_FOLLOW_TOLERANCE,
                       converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.params = params = checked_instance(
                "params", params, ArmControllerParameters,
                ArmControllerParameters)
            self.kinematics = kinematics = checked_instance(
                "kinematics", kinematics, ArmKinematics, ArmKinematics)
            self.lower = np.array(own_or(params.lower, kinematics.lower),
                                  float)
            self.upper = np.array(own_or(params.upper, kinematics.upper),
                                  float)
            self.velocity_limits = np.array(
                own_or(params.velocity_limits, kinematics.velocity_limits),
                float)
            n = self.num_joints = kinematics.num_joints
            # The state [q_cmd (n), q_dot (n), limited (1)].
            self._q, self._q_dot = slice(0, n), slice(n, 2 * n)
            self._limited_entry, self._state_size = 2 * n, 2 * n + 1
            self._time_step = positive("time_step", time_step)
            self.resume_tolerance = positive("resume_tolerance",
                                             resume_tolerance)
            self._lower, self._upper = self.lower.tolist(), self.upper.tolist()
            self._limits = twist_limits(
                self.lower, self.upper, self.velocity_limits,
                self._time_step, params.damping, params.damping_threshold,
                params.margin,
                own_or(params.acceleration_limit,
                       kinematics.acceleration_limits)
                if params.use_acceleration_limit else None,
                params.self_motion_gain)
            # A start beyond a limit by one period's step at this
            # acceleration is an encoder's reading on the limit.
            self._start_acceleration = np.asarray(own_or(
                params.acceleration_limit, kinematics.acceleration_limits),
                dtype=float)
            # A hold brakes to rest and stays: without the self-motion of
            # an arm of more than six joints, which would go on moving it.
            self._hold_limits = replace(self._limits, self_motion_gain=0.0)
            # Where a held command may go to catch up with the arm: the
            # band the running command keeps to, so that it resumes inside.
            self._band = (self.lower + params.margin,
                          self.upper - params.margin)
            self._command = body_for(joint_velocity_command, T)
            self._no_twist = np.zeros(TWIST_SIZE)
            self._input = self.DeclareVectorInputPort("arm_velocity",
                                                      TWIST_SIZE)
            self._hold = self.DeclareVectorInputPort("hold", 1)
            self._measured = self.DeclareVectorInputPort("arm_position", n)
            self._resume = self.DeclareVectorInputPort("resume", 1)
            initial = np.zeros(self._state_size)
            initial[self._q] = kinematics.home
            state = self.DeclareDiscreteState(BasicVector_[T](initial))
            self.DeclarePeriodicDiscreteUpdateEvent(
                self._time_step, 0.0, self._update
            )
            prerequisites = {self.discrete_state_ticket(state)}
            for name, size, calc in (
                ("arm_position_command", n, self._position),
                ("arm_velocity_command", n, self._velocity),
                ("limited", 1, self._limited),
            ):
                self.DeclareVectorOutputPort(
                    name, size, calc, prerequisites_of_calc=prerequisites
                )

        def _construct_copy(self, other, converter=None):
            # The original's parameters and kinematics, not its arguments:
            # a default (None) would build a second plant.
            Impl._construct(self, other.params, other.kinematics,
                            other._time_step, other.resume_tolerance,
                            converter=converter)

        @staticmethod
        def _state(context):
            return context.get_discrete_state_vector().CopyToVector()

        def _jacobian(self, q):
            """J_a at q (float): the kinematics run in double."""
            return self.kinematics.evaluate(q).J_a

        def _next_state(self, q, previous, V_a, hold):
            """The next state [q_cmd, q_dot, limited] from the state's
            parts and V_a (arrays of T); with `hold` (or a V_a that is not
            finite) the command brakes to rest as for a zero twist."""
            finite = all_finite(V_a)
            limits = self._limits
            if hold or not finite:
                V_a, limits = self._no_twist, self._hold_limits
            J_a = through_float_function(self._jacobian, q)
            command = self._command(J_a, V_a, q, previous, limits)
            if not all_finite(command.q_dot):
                # A finite twist so large that the rates overflow (1e308
                # m/s): braked as one that is not finite.
                finite = False
                command = self._command(J_a, self._no_twist, q, previous,
                                        self._hold_limits)
            h = self._time_step
            # The bounds keep q in the band up to rounding; the clip makes
            # the joint limits exact.
            q_dot = command.q_dot.tolist()
            state = [min(max(q_i + h * v, lower), upper)
                     for q_i, v, lower, upper in zip(
                         q.tolist(), q_dot, self._lower, self._upper,
                         strict=True)]
            state += q_dot
            state.append(1.0 if command.limited or not finite else 0.0)
            return np.array(state)

        def _update(self, context, discrete_state):
            hold = optional_scalar(self._hold, context, 0.0) >= 0.5
            x = self._state(context)
            q, previous = x[self._q], x[self._q_dot]
            resume = optional_scalar(self._resume, context, 0.0) >= 0.5
            # The measurement matters only at a hold and at a resume.
            measured = (self._measured.Eval(context)
                        if (hold or resume) and self._measured.HasValue(
                            context) else None)
            if measured is not None and resume:
                q, previous = self._resumed(q, previous, measured)
            state = self._next_state(q, previous, self._input.Eval(context),
                                     hold)
            if hold and measured is not None:
                self._catch_up(state, q, previous, measured)
            discrete_state.set_value(state)

        def _catch_up(self, state, q, previous, measured):
            """Makes the held command in `state` go to where the arm is
            (within the band the running command keeps to) instead of
            braking on the spot: every joint once a joint is farther than
            resume_tolerance from the command (the arm stopped against
            something, or was moved, during the stop), and a joint
            already on its way there until it is within CAUGHT_UP of the
            tolerance (catching_up); within the
            joint speed and acceleration limits (catch_up_arm). So the
            command is where the arm is when the stop clears, and resumes
            from there without a jump: in one tick, the step from the
            command to the arm is one the servo of an arm pushed off its
            command refuses. In floats: during a stop the command is
            bookkeeping, not a signal to differentiate. A measurement
            that is not finite is none."""
            if not all_finite(measured):
                return
            far = not check_following(measured, q,
                                      self.resume_tolerance).valid
            last = np.array(value_of(q), dtype=float)
            velocity = np.array(value_of(previous), dtype=float)
            arm = np.clip(np.array(value_of(measured), dtype=float),
                          *self._band)
            catching = catching_up(last, velocity, arm,
                                   CAUGHT_UP * self.resume_tolerance) | far
            if not catching.any():
                return
            command, _ = catch_up_arm(last, velocity, arm, self._time_step,
                                      self.velocity_limits,
                                      self._start_acceleration)
            command = np.clip(command, self.lower, self.upper)
            rate = (command - last) / self._time_step
            n = self.num_joints
            for j in np.flatnonzero(catching):
                state[j] = zero_like(state[j]) + command[j]
                state[n + j] = zero_like(state[n + j]) + rate[j]

        def _resumed(self, q, previous, measured):
            """(q_cmd, previous q_dot) to step from: the state's, or
            `measured` (within the joint limits) at rest when a joint is
            farther than resume_tolerance from q_cmd (a measurement
            that is not finite is none, and one farther beyond a joint's
            limits than limit_slack no position to restart from:
            drake_wbc.math.safety.restart_position)."""
            start = restart_position(
                measured, q, self.resume_tolerance, self._lower,
                self._upper, self._start_acceleration, self._time_step).start
            if start is None:
                return q, previous
            return start, previous * 0.0

        def _position(self, context, output):
            output.SetFromVector(self._state(context)[self._q])

        def _velocity(self, context, output):
            output.SetFromVector(self._state(context)[self._q_dot])

        def _limited(self, context, output):
            output.SetFromVector(
                self._state(context)[self._limited_entry:])

        def set_arm_position(self, context, q):
            """Starts the command at `q` (n, rad), at rest: e.g. the
            measured arm position when the controller takes over, so that
            the servo sees no jump. A joint outside the band
            [lower + margin, upper - margin] is kept where it is and is
            only prevented from moving further out; one outside the joint
            limits [lower, upper] by no more than one period's step at
            the acceleration limit from rest (an encoder reading past a
            limit) starts on the limit, so that the command never leaves
            them (`start_within_limits`, the rule of the hardware's
            guard too).

            Raises:
                ValueError: naming the first joint further outside its
                    limits (e.g. limits tightened to exclude the arm's
                    position: its command would jump onto them).
            """
            q = start_within_limits(
                "q", q, self.lower, self.upper, self._start_acceleration,
                self._time_step, remedy="move the arm within them or "
                "widen arm_controller.lower and upper")
            state = np.zeros(self._state_size)
            state[self._q] = q
            context.SetDiscreteState(state)

    return Impl


ArmCartesianVelocityController = ArmCartesianVelocityController_[None]
"""ArmCartesianVelocityController_ for double; `ToAutoDiffXd()` gives the
AutoDiff one."""

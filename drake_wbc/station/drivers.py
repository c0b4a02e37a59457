"""The robot's own low-level loops, as the simulated station runs them.

The controller commands a base velocity and arm joint positions; on the
real robot the base's and the arm's drivers turn those into motion, each
with its own bandwidth. Their gap is the paper's reason for the base
filter (Sec. IV-A), so the station models both honestly:

- `BaseVelocityDriver`: the base's velocity loop, a first-order lag of
  0.1 to 0.3 s (facts sheet, EST) with saturation at the base's velocity
  and acceleration limits, ahead of a stiff wheel servo (the plant's own
  PD controller with p = 0, a velocity servo).
- `ArmPositionDriver`: the arm's position servo. It samples the position
  command at the control period and interpolates linearly towards it over
  the next period, as industrial arm drivers do, feeding the plant's PD
  controller with a consistent position and velocity. In the station it
  takes what the arm's servo interface passes on
  (drake_wbc.station.arm_supervisor), which faults the arm on a command
  beyond its limits.

Both are TemplateSystems (double and AutoDiffXd, for linearisation)
over the step math of drake_wbc.station.driver_dynamics; the station runs
the same math as C++ SymbolicVectorSystems
(drake_wbc.station.symbolic_drivers). The plant's PD gains:
drake_wbc.station.servo_gains.
"""

import copy
from dataclasses import dataclass, field, fields

import numpy as np
from pydrake.systems.framework import LeafSystem_

from drake_wbc.math.validation import (
    as_vector,
    checked_instance,
    in_closed_range,
    non_negative,
    positive,
    whole_multiple,
)
from drake_wbc.stages.support import define_stage
from drake_wbc.station.driver_dynamics import (
    base_loop_size,
    base_loop_step,
    body_to_world_rates,
    interpolated_command,
)

BASE_LOOPS = {
    # Today's model: a heavy base whose velocity loop is a first-order lag
    # of 0.1 to 0.3 s (facts sheet, EST; 0.2 s), held to 1 m/s^2.
    "smooth": {"lag": 0.2, "damping_ratio": None,
               "acceleration_limits": [1.0, 1.0, 1.0],
               "servo_time_constant": 0.01},
    # A stiffly tuned wheel loop (EST): 20 ms lag, as a current-limited
    # hub motor's speed loop with little filtering reaches, and the
    # drives' own 5 m/s^2 (the effort limits allow about 6 m/s^2 for the
    # loaded base, models/mcr_base.sdf), with a 5 ms wheel servo under it.
    # The plant's step must be at most lag / 10 = 2 ms for it.
    "jerky": {"lag": 0.02, "damping_ratio": None,
              "acceleration_limits": [5.0, 5.0, 5.0],
              "servo_time_constant": 0.005},
    # A velocity loop with an integrator against the base's inertia and a
    # little filtering rings (EST): natural frequency 3 Hz (lag = 1 / (2 pi
    # 3 Hz) = 0.053 s), damping ratio 0.15, the 5 m/s^2 of the drives: the
    # overshoot of 62 % and the 3 Hz ringing are those of bases that
    # "shake or even slip" under a rapid command (paper Sec. IV-A); issue
    # 21's sweep measured the filter helping most there.
    "ringing": {"lag": 1.0 / (2.0 * np.pi * 3.0), "damping_ratio": 0.15,
                "acceleration_limits": [5.0, 5.0, 5.0],
                "servo_time_constant": 0.01},
}
"""The named base velocity loops (BaseDriverParameters.loop): the values
of lag, damping_ratio, acceleration_limits and servo_time_constant each
gives (EST, see the comments)."""


@dataclass
class BaseDriverParameters:
    """The base's velocity loop (facts sheet: EST from comparable bases).

    Attributes:
        loop: None (the default: the fields below as given) or a named
            loop of BASE_LOOPS, "smooth", "jerky" or "ringing", which
            sets lag, damping_ratio, acceleration_limits and
            servo_time_constant to its EST values; a field given another
            value than both the loop's and its own default is an error
            (leave `loop` out to tune them).
        lag: time constant of the velocity loop in s (0.1 to 0.3 s on
            such bases); 0.2 s by default.
        velocity_limits: [vx, vy, wz] limits, m/s and rad/s (1.0 each).
        acceleration_limits: [ax, ay, alpha_z] limits, m/s^2 and rad/s^2
            (1.0 each).
        damping_ratio: None (the default) for the first-order lag; a
            number in [0.001, 1] makes the loop second order, with natural
            frequency 1 / lag and this damping ratio: a base whose
            velocity overshoots and rings after a rapid command, the
            shaking the paper reports ("the base can shake or even
            slip", Sec. IV-A).
        servo_time_constant: time constant of the wheel servo that tracks
            the loop's output, s; it sizes the plant's velocity gain and
            must be below lag / 2.

    The loop runs at a step given apart, the plant's in the station
    (StationOptions.time_step), at most lag / 10 (`check_base_time_step`).
    """

    loop: str | None = None
    lag: float = 0.2
    damping_ratio: float | None = None
    velocity_limits: list[float] = field(
        default_factory=lambda: [1.0, 1.0, 1.0])
    acceleration_limits: list[float] = field(
        default_factory=lambda: [1.0, 1.0, 1.0])
    servo_time_constant: float = 0.01

    def __post_init__(self):
        self._fill_from_loop()
        positive("lag", self.lag)
        if self.damping_ratio is not None:
            in_closed_range("damping_ratio", self.damping_ratio, 1e-3, 1.0)
        for name in ("velocity_limits", "acceleration_limits"):
            limits = as_vector(name, getattr(self, name), 3)
            if np.any(limits <= 0.0):
                raise ValueError(f"{name} = {limits.tolist()} is not allowed: "
                                 "every limit must be > 0")
        servo = positive("servo_time_constant", self.servo_time_constant)
        if servo >= 0.5 * self.lag:
            raise ValueError(
                f"servo_time_constant = {servo!r} s is not allowed with "
                f"lag = {self.lag!r} s: must be below lag / 2, or the "
                "servo, not the loop, sets the base's bandwidth")

    def _fill_from_loop(self):
        """Sets the named loop's values (see `loop`)."""
        if self.loop is None:
            return
        if self.loop not in BASE_LOOPS:
            raise ValueError(
                f"loop = {self.loop!r} is not allowed: must be None or one "
                f"of {sorted(BASE_LOOPS)}")
        for name, value in BASE_LOOPS[self.loop].items():
            given = getattr(self, name)
            if not (_same(given, value) or _same(given, BASE_LOOPS[
                    "smooth"][name])):
                raise ValueError(
                    f"{name} = {given!r} is not allowed with loop = "
                    f"{self.loop!r}: the loop sets it to {value!r}; leave "
                    "loop out to set it")
            setattr(self, name, copy.copy(value))


def own_base_loop(base, given=None, prefix=""):
    """The velocity loop of a robot's base as its description gives it
    (`base`, a BaseDescription, drake_wbc.robot.description): first
    order, held to its velocity and acceleration limits, with the lag of
    BaseDriverParameters (0.2 s, a typical such base) or the robot's
    velocity_lag where that bound is shorter; the simulated station's
    loop where its options give none. The wheel servo under it is
    BaseDriverParameters' (10 ms) or, under a loop faster than 40 ms,
    a quarter of the lag (the "jerky" loop's 5 ms under 20 ms), so that
    the loop, not the servo, sets the base's bandwidth.

    Args:
        base: the robot's BaseDescription.
        given: None, or a dict of fields of BaseDriverParameters that
            replace the robot's (a scenario's station.base, given in
            part): a named `loop` sets its own fields (BASE_LOOPS), a
            `lag` its servo as above unless servo_time_constant is given
            too; every field left out is the robot's.
        prefix: what the messages put before a given field's name (e.g.
            "station.base.").

    Raises:
        ValueError: naming the given field (after `prefix`) whose value
            the loop cannot take, or the robot's field where nothing but
            a loop's name is given (a velocity_lag of 0, or under 10
            plant steps).
    """
    given = given or {}
    named = BASE_LOOPS.get(given.get("loop"), {})
    own_lag = min(BaseDriverParameters.lag, base.velocity_lag)
    lag = given.get("lag", named.get("lag", own_lag))
    own = {"lag": own_lag,
           "servo_time_constant": min(
               BaseDriverParameters.servo_time_constant, 0.25 * lag),
           "velocity_limits": [float(v) for v in base.velocity_limits],
           "acceleration_limits": [
               float(a) for a in base.acceleration_limits]}
    values = {name: value for name, value in own.items()
              if name not in named}
    values.update(given)
    try:
        return BaseDriverParameters(**values)
    except ValueError as error:
        if named or set(given) - {"loop"}:  # a given value's error
            raise ValueError(f"{prefix}{error}") from None
        raise ValueError(
            f"the robot's base.velocity_lag = {base.velocity_lag!r} s "
            f"cannot be simulated ({error}); give the station's base loop "
            "(station.base) instead") from None


def moved_base_loop(loop, base, other, prefix=""):
    """The velocity loop `loop` of the robot with BaseDescription `base`
    moved to the robot with BaseDescription `other` (a scenario run on
    another robot): the fields where `loop` differs from `base`'s own
    loop (own_base_loop, with `loop`'s named loop) are kept, every other
    field is `other`'s own (a field set to `base`'s own value too: the
    loop keeps no record of what was written). Errors as own_base_loop's,
    `prefix` before a field's name."""
    own = own_base_loop(base, {"loop": loop.loop})
    given = {f.name: getattr(loop, f.name) for f in fields(loop)
             if f.name == "loop" or not _same(getattr(loop, f.name),
                                                getattr(own, f.name))}
    return own_base_loop(other, given, prefix)


def _same(a, b):
    """Whether two field values (None, numbers or lists) are equal."""
    if a is None or b is None:
        return a is None and b is None
    return bool(np.array_equal(np.asarray(a, dtype=float),
                               np.asarray(b, dtype=float)))


MIN_SERVO_FREQUENCY = 1.0
"""The slowest arm servo allowed, Hz (the real arm's is 25 Hz): the servo's
stiffness grows with the square of its frequency, and below about 0.15 Hz
it is weaker than gravity on the arm."""


@dataclass
class ArmDriverParameters:
    """The arm's position servo.

    Attributes:
        command_period: how often the driver samples the position
            command, s (the control period, 0.01 s).
        servo_frequency: bandwidth of each joint's PD loop in Hz; with
            the joint's inertia from the mass matrix it sets the gains
            (25 Hz: a stiff servo, 0.02 to 0.05 s as on the real arm);
            at least MIN_SERVO_FREQUENCY.
        damping_ratio: of each joint's PD loop (1: critically damped).
        min_inertia: the least joint inertia used to size the gains,
            kg m^2. It stands for the geared drives' reflected inertia,
            which the model leaves out (EST, 0.2 kg m^2): without it the
            wrist joints, whose links weigh little, would get almost no
            stiffness. The station puts it into its plant, as the
            joints' rotor inertia (servo_gains.drive_inertias), so that
            each servo really has servo_frequency.

    The plant's step (StationOptions.time_step), at which the servo's PD
    loop runs, is given apart: command_period a whole multiple of it and
    servo_frequency below its Nyquist frequency (`check_arm_time_step`).
    """

    command_period: float = 0.01
    servo_frequency: float = 25.0
    damping_ratio: float = 1.0
    min_inertia: float = 0.2

    def __post_init__(self):
        positive("command_period", self.command_period)
        if positive("servo_frequency",
                    self.servo_frequency) < MIN_SERVO_FREQUENCY:
            raise ValueError(
                f"servo_frequency = {self.servo_frequency!r} Hz is not "
                f"allowed: must be at least {MIN_SERVO_FREQUENCY!r} Hz (a "
                "position servo; below about 0.15 Hz the joints no longer "
                "hold the arm against gravity and the plant fails)")
        positive("damping_ratio", self.damping_ratio)
        non_negative("min_inertia", self.min_inertia)


def check_base_time_step(params, name, time_step, prefix=""):
    """Checks the step `time_step` (called `name`) of the base's loop
    against BaseDriverParameters `params` (called `prefix` in messages):
    > 0 and at most `lag` / 10 (the second-order loop's semi-implicit
    Euler step needs h / lag << 1)."""
    h = positive(name, time_step)
    if h > 0.1 * params.lag:
        raise ValueError(
            f"{name} = {h!r} s is not allowed with {prefix}lag = "
            f"{params.lag!r} s: "
            "must be at most lag / 10, or the loop's discrete step, not its "
            "time constant, sets its response")
    return h


def check_arm_time_step(params, name, time_step, prefix=""):
    """Checks the step `time_step` (called `name`) of the arm's servo
    against ArmDriverParameters `params` (called `prefix` in messages):
    > 0, the command period a whole multiple of it, and the servo's
    bandwidth below its Nyquist frequency 1 / (2 time_step)."""
    h = positive(name, time_step)
    whole_multiple(f"{prefix}command_period", params.command_period, name,
                   h)
    if params.servo_frequency >= 0.5 / h:
        raise ValueError(
            f"{prefix}servo_frequency = {params.servo_frequency!r} Hz is not "
            f"allowed with {name} = {h!r} s: must be below the Nyquist "
            f"frequency 1 / (2 {name}) = {0.5 / h:.6g} Hz")
    return h


@define_stage("BaseVelocityDriver_")
def BaseVelocityDriver_(T):
    class Impl(LeafSystem_[T]):
        """The base's velocity loop: lag and saturation.

        ::

                               ┌────────────────────┐
            velocity_command ─►│                    ├──► desired_state
            base_pose ────────►│ BaseVelocityDriver ├──► velocity
                               └────────────────────┘

        - velocity_command: [vx, vy, wz] (3) in T_b, as the controller
          sends it.
        - base_pose: [x, y, yaw] (3) of T_b in the world (odometry).
        - desired_state: (6) [q_d; v_d] for the plant's desired-state
          port of the base: v_d is the loop's velocity as joint rates
          (world x, y and yaw); q_d is zero, unused by the velocity servo
          (p = 0).
        - velocity: the loop's velocity (3) in T_b, from its state
          (base_loop_step).

        Args:
            params: BaseDriverParameters (the defaults if None).
            time_step: the loop's step h in s (required; the station's
                plant's, StationOptions.time_step), at most params.lag / 10
                (`check_base_time_step`).
        """

        def _construct(self, params=None, time_step=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.params = params = checked_instance(
                "params", params, BaseDriverParameters, BaseDriverParameters)
            self.time_step = check_base_time_step(params, "time_step",
                                                  time_step)
            self._command = self.DeclareVectorInputPort(
                "velocity_command", 3)
            self._pose = self.DeclareVectorInputPort("base_pose", 3)
            state = self.DeclareDiscreteState(base_loop_size(self.params))
            self.DeclarePeriodicDiscreteUpdateEvent(
                self.time_step, 0.0, self._update)
            ticket = {self.discrete_state_ticket(state)}
            self.DeclareVectorOutputPort(
                "desired_state", 6, self._desired_state,
                prerequisites_of_calc=ticket | {
                    self.input_port_ticket(self._pose.get_index())})
            self.DeclareVectorOutputPort(
                "velocity", 3, self._velocity, prerequisites_of_calc=ticket)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.params, other.time_step,
                            converter=converter)

        def _update(self, context, discrete_state):
            v = context.get_discrete_state_vector().CopyToVector()
            discrete_state.set_value(base_loop_step(
                v, self._command.Eval(context), self.params, self.time_step))

        def _desired_state(self, context, output):
            v = context.get_discrete_state_vector().CopyToVector()[:3]
            yaw = self._pose.Eval(context)[2]
            output.SetFromVector(np.concatenate(
                [np.zeros(3), body_to_world_rates(yaw, v)]))

        def _velocity(self, context, output):
            output.SetFromVector(
                context.get_discrete_state_vector().CopyToVector()[:3])

        def set_velocity(self, context, velocity):
            """Starts the loop at rest at `velocity` (3,) in T_b."""
            state = np.zeros(base_loop_size(self.params))
            state[:3] = as_vector("velocity", velocity, 3)
            context.SetDiscreteState(state)

    return Impl


def arm_start(initial_positions):
    """The arm drivers' start, (n,) rad: `initial_positions`, which a
    driver must be given (its ports are sized by it, and a start is a
    configuration of one arm)."""
    if initial_positions is None:
        raise ValueError(
            "initial_positions = None is not allowed: give the arm's start, "
            "one angle a joint (e.g. its robot's home, RobotModel.home, its "
            "description's arm.home)")
    return as_vector("initial_positions", initial_positions)


@define_stage("ArmPositionDriver_")
def ArmPositionDriver_(T):
    class Impl(LeafSystem_[T]):
        """The arm's position servo: sample, then interpolate.

        ::

                               ┌───────────────────┐
            position_command ─►│ ArmPositionDriver ├──► desired_state
                               └───────────────────┘

        - position_command: q_cmd (n), rad (n: the size of
          initial_positions).
        - desired_state: (2 n) [q_d; v_d] for the plant's desired-state
          port of the arm. At each sample t_k (every command_period) the
          driver takes the command; until the next sample q_d moves
          linearly from the previous command to it, with v_d the constant
          rate between them. The command is reached one period after it
          was sampled.

        State [q_from (n), q_to (n), t_k (1)].

        Args:
            params: ArmDriverParameters (the defaults if None).
            initial_positions: the arm's configuration at the start
                (required).
        """

        def _construct(self, params=None, initial_positions=None,
                       converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.params = params = checked_instance(
                "params", params, ArmDriverParameters, ArmDriverParameters)
            self._initial = arm_start(initial_positions)
            n = self._initial.size
            self._command = self.DeclareVectorInputPort(
                "position_command", n)
            self.DeclareDiscreteState(
                np.concatenate([self._initial, self._initial, [0.0]]))
            self.DeclarePeriodicDiscreteUpdateEvent(
                self.params.command_period, 0.0, self._update)
            self.DeclareVectorOutputPort(
                "desired_state", 2 * n, self._desired_state,
                prerequisites_of_calc={self.time_ticket(),
                                       self.xd_ticket()})

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.params, other._initial,
                            converter=converter)

        def _update(self, context, discrete_state):
            state = context.get_discrete_state_vector().CopyToVector()
            reached = self._interpolated(state, context.get_time())[0]
            discrete_state.set_value(np.concatenate([
                reached, self._command.Eval(context), [context.get_time()]]))

        def _interpolated(self, state, time):
            return interpolated_command(state, time,
                                        self.params.command_period)

        def _desired_state(self, context, output):
            state = context.get_discrete_state_vector().CopyToVector()
            q_d, v_d = self._interpolated(state, context.get_time())
            output.SetFromVector(np.concatenate([q_d, v_d]))

        def set_positions(self, context, positions):
            """Holds the arm at `positions` (n,) from the context's time."""
            q = as_vector("positions", positions, self._initial.size)
            context.SetDiscreteState(
                np.concatenate([q, q, [context.get_time()]]))

    return Impl


BaseVelocityDriver = BaseVelocityDriver_[None]
ArmPositionDriver = ArmPositionDriver_[None]

"""The base's command at a safe stop and at the robot's limits, as a Drake
system thin over drake_wbc.math.safety, drake_wbc.math.separation and
drake_wbc.math.people: BaseCommandLimiter (the base command within the
robot's velocity and acceleration limits, its direction kept, the
separation from obstacles and moving people, the protective stop).
InputGuard, which decides the stop, and StopGate are in
drake_wbc.stages.safety."""

import logging
import zlib
from typing import NamedTuple

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem_, ValueProducer

from drake_wbc.math.base_state import BASE_AXES, BASE_STATE_SIZE
from drake_wbc.math.command_limits import (
    limit_base_velocity,
    uniform_scale,
)
from drake_wbc.math.kernels import body_for
from drake_wbc.math.people import (
    MAX_TRACKS,
    NEVER,
    TRACKER_SIZE,
    initial_tracker,
    people_scan,
)
from drake_wbc.math.repulsion import LastPoints
from drake_wbc.math.safety import SafetyParameters
from drake_wbc.math.scalar_support import all_finite, value_of
from drake_wbc.math.separation import (
    FAR,
    NEAREST_POINTS,
    people_rows,
    protective_timing,
    scale_for_rows,
    separation_state,
)
from drake_wbc.math.validation import (
    as_vector,
    checked_instance,
    non_negative,
    positive,
    robots_own,
)
from drake_wbc.stages.support import define_stage

_ALLOWED = BASE_AXES + 3 * NEAREST_POINTS
"""Where the allowed speeds start in BaseCommandLimiter's state."""

_PEOPLE = _ALLOWED + NEAREST_POINTS
"""Where the moving people's approach rows (3 MAX_TRACKS) start."""

_PEOPLE_ALLOWED = _PEOPLE + 3 * MAX_TRACKS
"""Where their allowed approach speeds (MAX_TRACKS) start."""

_PROTECTIVE = _PEOPLE_ALLOWED + MAX_TRACKS
"""The protective stop's state: [stopped, the last tick's time with a
point on or inside the footprint, whether the last scan had one]."""

_SCAN = _PROTECTIVE + 3
"""The last scan's signature (`_signature_of`)."""

_SIGNATURE_SIZE = 8
"""The size of a scan's signature (`_signature_of`)."""

_TRACKER = _SCAN + _SIGNATURE_SIZE
"""Where the people tracker's state (TRACKER_SIZE) starts."""

_SIZE = _TRACKER + TRACKER_SIZE

class LimiterState(NamedTuple):
    """BaseCommandLimiter's state vector in its parts (views of it, in
    its order; `limiter_state`).

    Attributes:
        previous: the previous command (3).
        separation: the static rule's approach rows (3 NEAREST_POINTS,
            row by row) and allowed speeds (NEAREST_POINTS).
        person_rows: the moving people's approach rows (MAX_TRACKS, 3).
        person_allowed: their allowed speeds (MAX_TRACKS; FAR where
            none).
        protective: [stopped, the last tick's time with a point on or
            inside the footprint, whether the last scan had one].
        scan: the last scan's signature (_SIGNATURE_SIZE).
        tracker: the people tracker's state (TRACKER_SIZE).
    """

    previous: np.ndarray
    separation: np.ndarray
    person_rows: np.ndarray
    person_allowed: np.ndarray
    protective: np.ndarray
    scan: np.ndarray
    tracker: np.ndarray


def limiter_state(state):
    """The LimiterState of a BaseCommandLimiter's state vector (_SIZE,)."""
    return LimiterState(
        state[:BASE_AXES], state[BASE_AXES:_PEOPLE],
        state[_PEOPLE:_PEOPLE_ALLOWED].reshape(-1, 3),
        state[_PEOPLE_ALLOWED:_PROTECTIVE], state[_PROTECTIVE:_SCAN],
        state[_SCAN:_TRACKER], state[_TRACKER:])


def _rows_and_allowed(separation):
    """The approach rows (NEAREST_POINTS, 3) and allowed speeds
    (NEAREST_POINTS,) of LimiterState.separation, views of it."""
    return (separation[:3 * NEAREST_POINTS].reshape(-1, 3),
            separation[3 * NEAREST_POINTS:])


def _signature_of(points):
    """A scan's signature: [points, the CRC-32 of all their coordinates,
    its first, middle and last point] (0 for none): a new scan of a base
    or a scene that moves changes it, wherever the change is (a person
    stepping into a beam of a scanner at rest, its other beams the
    same); a scan of a static scene from a base at rest is the same
    scan. The points are a float (M, 2) array."""
    count = len(points)
    if not count:
        return np.zeros(_SIGNATURE_SIZE)
    crc = zlib.crc32(np.ascontiguousarray(points, dtype=float).data)
    return np.concatenate(((float(count), float(crc)), points[0],
                           points[count // 2], points[count - 1]))


LOGGER = logging.getLogger("drake_wbc.math.safety")
"""The safety stages' logger: a protective stop is logged when it trips
and when it clears."""


@define_stage("BaseCommandLimiter_")
def BaseCommandLimiter_(T):
    class Impl(LeafSystem_[T]):
        """The base velocity command within the robot's limits, or zero in
        a safe stop.

        ::

                              ┌────────────────────┐
            velocity ────────►│                    ├──► velocity_command
            stopped ─────────►│ BaseCommandLimiter ├──► saturation
            envelope_scale ──►│                    ├──► protective_stop
            obstacle_points ─►│                    │
            base_state ──────►│                    │
                              └────────────────────┘

        - velocity: (3) the desired command [vx, vy, wz] in T_b (the base
          filter's V_b^flt of eq. (filtering)).
        - stopped (1): >= 0.5 in a safe stop (InputGuard's `stopped`).
        - envelope_scale (1): optional (1 when unconnected), the factor
          by which the StopGate before the filter scaled V_b' into the
          velocity limits; it enters the report only.
        - obstacle_points: optional (none when unconnected), an (M, 2)
          float array of obstacle points in T_b; the update keeps the
          NEAREST_POINTS nearest the footprint, which limit the next
          tick's command (drake_wbc.math.separation: the footprint
          approaches no point faster than max(d - stop_distance, 0) /
          stop_time, nor faster than the base can brake from to stop
          stop_distance short, eqs. (approach), (allowed)).
          Read only by the update, so the outputs do not depend on it
          directly. The points are also tracked between scans
          (drake_wbc.math.people, in the odometry's world): the approach
          to each cluster that moves (a person) is bounded so that the
          separation stays at least ISO/TS 15066's protective separation
          distance S_p (drake_wbc.math.separation, eq. (protective); the
          command scaled as a whole by the smaller of the two scales),
          and a point on or inside the footprint is a protective stop.
        - base_state: optional, [x, y, yaw, vx, vy, wz] (6), the base's
          odometry (the pose in its world, the twist in T_b), for the
          tracking; read only by the update. Unconnected: at rest at the
          origin.
        - protective_stop (1): 1.0 while the base is in a protective
          stop: a point of the last scan on or inside the footprint, or
          one there within the last hold_time s (SafetyParameters). The
          command then brakes to zero within the acceleration limits
          (scale 0, reported on `saturation` as a separation limit), and
          the stop is logged when it trips and clears (LOGGER, as the
          InputGuard's); `reason` says why.
        - velocity_command: (3)
          drake_wbc.math.command_limits.limit_base_velocity of the desired
          command from the previous tick's command: scaled as a
          whole to the separation from the obstacles and to the velocity
          limits, its change scaled as a whole to the acceleration
          limits, so that its direction is kept. Zero in
          a safe stop, at once: zero is the safe stop of a velocity
          controlled base, whose own drive decelerates within its limits
          (the robot's 1.0 m/s^2), and a ramp would keep trusting the
          controller while its inputs are not valid. After the stop the
          command restarts from zero within the acceleration limits.
          Exactly the desired command when no limit acts.
        - saturation: (3) [limited, velocity scale, acceleration scale]:
          limited is 1.0 when a limit changed the command or the envelope
          before the filter scaled V_b'; the velocity scale is the
          product of envelope_scale and
          drake_wbc.math.command_limits.LimitedCommand's, the acceleration
          scale LimitedCommand's (1.0 when not limited).
          A desired command that is not finite (which the input guard
          leaves no way to reach) gives a zero command, limited 1.0 and
          both scales 0.0.

        Both outputs are direct feedthrough of `velocity` and `stopped`
        (the base filter's and the guard's state), so they add no delay.
        State, updated once a tick h: the previous command (3), and of
        the NEAREST_POINTS obstacle points nearest the footprint their
        approach rows G (3 NEAREST_POINTS, row by row) and allowed speeds
        (NEAREST_POINTS), drake_wbc.math.separation.separation_state, so
        that the outputs bound G s v <= allowed with a product and a
        minimum (drake_wbc.math.separation.scale_for_rows); then the
        moving people's rows (3 MAX_TRACKS) and allowed speeds
        (MAX_TRACKS, FAR where none), the protective stop [stopped, the
        last time a point was inside, whether the last scan had one], the
        last scan's signature (_SIGNATURE_SIZE: its size, the CRC-32 of
        its coordinates, its first, middle and last point) and the
        tracker's state (drake_wbc.math.people.TRACKER_SIZE). The
        tracking is float-only and runs once a scan (when the signature
        changes: at 15 Hz, not every tick); without a moving person or a
        point inside, the command is exactly that of the static rule.

        Scalar types: double and AutoDiffXd, the same calculation; the
        double one runs the float kernels of separation_state,
        scale_for_rows, people_scan and limit_base_velocity
        (drake_wbc.math.kernels), the AutoDiffXd one their references
        (limit_base_velocity's is scalar-generic, so the derivatives are
        exact). The obstacle points are float data in both.

        Args:
            params: SafetyParameters (the limits); the robot's if None.
                Read when the stage is built.
            time_step: the control period h > 0, s.
            half_sizes: the footprint's half-sizes (a, b) in m, those of
                the repulsive field (the robot's own, which
                build_controller gives).
        """

        def _construct(self, params=None, time_step=0.01,
                       half_sizes=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            params = checked_instance("params", params, SafetyParameters,
                                      SafetyParameters)
            self.time_step = positive("time_step", time_step)
            self.half_sizes = tuple(
                non_negative("half_sizes", a)
                for a in as_vector("half_sizes",
                                   robots_own("half_sizes", half_sizes), 2))
            # Float arrays: what the float kernel takes without a copy.
            self._velocity_limits = np.array(robots_own(
                "params.base_velocity_limits", params.base_velocity_limits),
                dtype=float)
            self._acceleration_limits = np.array(robots_own(
                "params.base_acceleration_limits",
                params.base_acceleration_limits), dtype=float)
            self._limit = body_for(limit_base_velocity, T)
            state_of_points = body_for(separation_state, T)
            stop_distance = params.stop_distance
            stop_time = params.stop_time
            # The base's reaction, lag and braking (a ProtectiveTiming), for
            # the static rule's stop (eq. (allowed)) and the people's S_p
            # (eq. (protective)).
            self.timing = protective_timing(
                params.people, self.time_step, self._acceleration_limits,
                robots_own("params.base_lag", params.base_lag))
            self._separation = LastPoints(
                lambda points: state_of_points(points, self.half_sizes,
                                               stop_distance, stop_time,
                                               self.timing))
            self._scale = body_for(scale_for_rows, T)
            self._people_scan = body_for(people_scan, T)
            self._velocity = self.DeclareVectorInputPort(
                "velocity", BASE_AXES)
            self._stopped = self.DeclareVectorInputPort("stopped", 1)
            self._envelope = self.DeclareVectorInputPort("envelope_scale", 1)
            self._points = self.DeclareAbstractInputPort(
                "obstacle_points", AbstractValue.Make(np.zeros((0, 2))))
            self._base_state = self.DeclareVectorInputPort(
                "base_state", BASE_STATE_SIZE)
            self._people = params.people
            self._hold_time = params.hold_time
            # The signature of the points last summed (`_track`).
            self._signature = None
            state = self.DeclareDiscreteState(self._initial_state())
            self.DeclarePeriodicDiscreteUpdateEvent(time_step, 0.0,
                                                    self._update)
            # Not time: the result changes only with the inputs and state.
            self._result = self.DeclareCacheEntry(
                "the limited command",
                ValueProducer(allocate=lambda: AbstractValue.Make(object()),
                              calc=self._calc_result),
                {self.discrete_state_ticket(state),
                 self._velocity.ticket(), self._stopped.ticket()})
            depends = {self._result.ticket()}
            self.DeclareVectorOutputPort(
                "velocity_command", BASE_AXES, self._command_output,
                prerequisites_of_calc=depends)
            self.DeclareVectorOutputPort(
                "saturation", 3, self._saturation_output,
                prerequisites_of_calc={*depends, self._envelope.ticket()})
            self.DeclareVectorOutputPort(
                "protective_stop", 1, self._protective_output,
                prerequisites_of_calc={self.discrete_state_ticket(state)})

        def _initial_state(self):
            """No command, no points, no people, no stop."""
            people = np.concatenate([np.zeros(3 * MAX_TRACKS),
                                     np.full(MAX_TRACKS, FAR)])
            return np.concatenate([
                np.zeros(BASE_AXES),
                self._separation(np.zeros((0, 2))), people,
                [0.0, NEVER, 0.0], np.zeros(_SIGNATURE_SIZE),
                initial_tracker()])

        def _limited(self, desired, previous, stopped, rows, allowed,
                     people=None):
            """[command (3), limited, velocity scale, acceleration scale]
            (without the envelope's scale) from the desired command (3,),
            the previous one (3,), stopped, the approach rows
            (NEAREST_POINTS, 3) and the allowed speeds (NEAREST_POINTS,),
            and `people`: None, or the people's rows (MAX_TRACKS, 3),
            their allowed speeds (MAX_TRACKS,) and the protective stop."""
            if stopped >= 0.5:
                return np.array([0.0, 0.0, 0.0, 0.0, 1.0, 1.0])
            if not all_finite(desired):
                return np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0])
            scale = self._scale(desired, rows, allowed)
            if people is not None:
                person_rows, person_allowed, protective = people
                if protective >= 0.5:
                    # A protective stop: to zero within the acceleration
                    # limits.
                    scale = 0.0
                elif person_allowed[0] != FAR:
                    person_scale = self._scale(desired, person_rows,
                                               person_allowed)
                    if person_scale < scale:
                        scale = person_scale
            result = self._limit(
                desired, previous, self._velocity_limits,
                self._acceleration_limits, self.time_step, scale=scale)
            return np.array(result.command.tolist() + [
                1.0 if result.limited else 0.0, result.velocity_scale,
                result.acceleration_scale])

        def _calc_result(self, context, value):
            state = limiter_state(
                context.get_discrete_state_vector().CopyToVector())
            stop = state.protective[0]
            people = None
            if stop >= 0.5 or state.person_allowed[0] != FAR:
                people = (state.person_rows, state.person_allowed, stop)
            value.set_value(self._limited(
                self._velocity.Eval(context), state.previous,
                self._stopped.Eval(context)[0],
                *_rows_and_allowed(state.separation), people))

        def _command_output(self, context, output):
            output.SetFromVector(self._result.Eval(context)[:3])

        def _saturation_output(self, context, output):
            limited, velocity_scale, acceleration_scale = (
                self._result.Eval(context)[3:])
            if self._envelope.HasValue(context):
                envelope = self._envelope.Eval(context)[0]
                if envelope < 1.0:
                    limited = 1.0
                velocity_scale = envelope * velocity_scale
            output.SetFromVector(np.array(
                [limited, velocity_scale, acceleration_scale]))

        def _protective_output(self, context, output):
            output.SetAtIndex(0, context.get_discrete_state_vector()
                              .GetAtIndex(_PROTECTIVE))

        def _update(self, context, discrete_state):
            points = (self._points.Eval(context)
                      if self._points.HasValue(context)
                      else np.zeros((0, 2)))
            vector = context.get_discrete_state_vector().CopyToVector()
            state = limiter_state(vector)
            state.previous[:] = self._result.Eval(context)[:3]
            state.separation[:] = self._separation(points)
            self._track(context, points, state, self._separation.changed)
            discrete_state.set_value(vector)

        def _track(self, context, points, state, changed):
            """The people's part of `state` (a LimiterState, in place):
            from a scan when the points changed, and the protective stop
            at every tick.

            A scan is new when its signature (`_signature_of`) differs
            from the one in the state (a scan equal to the last one
            leaves the tracks as they are). It is taken only when the
            separation's LastPoints saw new points or the state's is not
            the one taken last (another context)."""
            signature = self._signature
            if changed or signature is None or (
                    state.scan != signature).any():
                points = np.asarray(points, dtype=float).reshape(-1, 2)
                signature = _signature_of(points)
                self._signature = signature
                if (value_of(state.scan) != signature).any():
                    self._scan(context, points, state, signature)
            time = context.get_time()
            time = time if isinstance(time, float) else time.value()
            flags = state.protective
            if flags.dtype == object:
                flags = value_of(flags)
            was, last_inside, inside = flags[0] >= 0.5, flags[1], flags[2]
            if inside >= 0.5 or (time < last_inside and was):
                # (Time set back during a stop: its hold restarts now.)
                last_inside = time
                state.protective[1] = time
            elif time < last_inside:
                # Time set back after the stop cleared: it stays clear.
                last_inside = NEVER
                state.protective[1] = NEVER
            # A point inside now is a stop whatever the hold time (one of
            # 1e-9 s or less would not count the tick itself); none ever
            # inside (NEVER) is none, whatever the hold time (one longer
            # than NEVER is long would otherwise stop the base from the
            # start, saying a point is inside).
            stopped = inside >= 0.5 or (
                last_inside > NEVER
                and time - last_inside < self._hold_time - 1e-9)
            if stopped == was:
                return
            state.protective[0] = 1.0 if stopped else 0.0
            if stopped:
                LOGGER.warning("protective stop at t = %.3f s: %s", time,
                               self._reason(True))
            else:
                LOGGER.warning(
                    "protective stop cleared at t = %.3f s: no obstacle "
                    "point on or inside the base's footprint for %g s, "
                    "resuming", time, self._hold_time)

        def _scan(self, context, points, state, signature):
            """The tracking of a new scan (float, drake_wbc.math.people)
            and the people's rows and allowed speeds of eq.
            (protective), into `state` (a LimiterState, in place)."""
            base = (value_of(self._base_state.Eval(context))
                    if self._base_state.HasValue(context)
                    else np.zeros(BASE_STATE_SIZE))
            tracker, people, inside = self._people_scan(
                value_of(state.tracker), points, base,
                float(value_of(context.get_time())), self.half_sizes,
                self._people)
            rows, allowed = people_rows(
                [p[1] for p in people], [p[2] for p in people],
                self.half_sizes, self._people, self.timing, MAX_TRACKS)
            state.person_rows[:] = rows
            state.person_allowed[:] = allowed
            state.protective[2] = 1.0 if inside else 0.0
            state.scan[:] = signature
            state.tracker[:] = tracker

        def _reason(self, stopped):
            if not stopped:
                return ""
            return ("protective stop: an obstacle point is on or inside "
                    "the base's footprint; the base brakes to rest within "
                    "its acceleration limits and resumes "
                    f"{self._hold_time:g} s after the point has gone")

        def reason(self, context):
            """Why the base is in a protective stop, as a sentence (""
            when it is not)."""
            return self._reason(context.get_discrete_state_vector()
                                .GetAtIndex(_PROTECTIVE) >= 0.5)

        def set_previous(self, context, velocity):
            """Sets the previous command (3,), e.g. the base's measured
            velocity when the controller takes over; one beyond the
            velocity limits is scaled as a whole into them (its direction
            kept), since the command ramps from it: a base moving faster
            than the limits when the controller takes over would
            otherwise be sent commands beyond them until they had
            ramped down."""
            velocity = as_vector("velocity", velocity, BASE_AXES)
            scale = uniform_scale(velocity, self._velocity_limits)
            if scale < 1.0:
                velocity = scale * velocity
            vector = context.get_mutable_discrete_state_vector()
            state = vector.CopyToVector()
            limiter_state(state).previous[:] = velocity
            vector.SetFromVector(state)

    return Impl


BaseCommandLimiter = BaseCommandLimiter_[None]
"""BaseCommandLimiter_ for double; `ToAutoDiffXd()` gives the AutoDiff
one."""

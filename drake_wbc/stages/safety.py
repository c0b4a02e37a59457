"""The controller's run-time safety as Drake systems, thin over
drake_wbc.math.safety: InputGuard, every input checked where it enters,
and the safe stop it decides; StopGate, a signal zeroed during a stop (and
kept within an envelope). The base command's limits are in
drake_wbc.stages.base_command."""

import logging
import math
from typing import NamedTuple

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem_, ValueProducer

from drake_wbc.math.command_limits import uniform_scale
from drake_wbc.math.kernels import body_for
from drake_wbc.math.safety import (
    STATUS_FIELDS,
    VALID,
    Following,
    InputCheck,
    SafetyParameters,
    check_following,
    check_inputs,
    check_points,
    initial_status,
    next_status,
    next_stop_state,
    status_reason,
    stop_state_of,
)
from drake_wbc.math.scalar_support import value_of
from drake_wbc.math.validation import (
    as_vector,
    checked_instance,
    positive,
    positive_vector,
    whole_number,
)
from drake_wbc.stages.support import define_stage

LOGGER = logging.getLogger("drake_wbc.math.safety")
"""Where a safe stop is reported, once when it trips and once when it
clears (at WARNING, so that Python's default handler prints it on
stderr)."""

_STATUS = {name: i for i, name in enumerate(STATUS_FIELDS)}


class GuardedInput(NamedTuple):
    """One vector input of an InputGuard.

    Attributes:
        name: the input port's name.
        size: its size.
        outputs: ((output name, default[, while stopped]), ...), the
            guarded copies of the input; a default (a vector of `size`) is
            what the output carries while the input is not connected, None
            to require a connection; a third entry (a vector of `size`),
            what it carries during a safe stop instead of the input (e.g.
            a switch that turns an integrating term off). () means one
            output named like the input, required.
        lower, upper: the range allowed for every entry (numbers), or
            for each entry (sequences of `size` numbers; e.g. the wrist
            wrench's forces and torques, each within the sensor's own
            range).
        zero_when_stopped: every output carries zeros during a safe stop
            (a reference that must not drive anything while stopped).
        initial: the value passed on if the very first sample is invalid
            (zeros if None).
        switch: every entry must be exactly 0 or 1 (a switch; anything
            else is a fault, drake_wbc.math.safety.check_vector).
        follows: a drake_wbc.math.safety.Following: the input measures
            what a command of the controller drives, and an entry
            farther than its tolerance from the command is a fault
            (check_following); the guard has an input port of the
            command's name and size. None: no such check.
    """

    name: str
    size: int
    outputs: tuple = ()
    lower: float | tuple = -math.inf
    upper: float | tuple = math.inf
    zero_when_stopped: bool = False
    initial: tuple | None = None
    switch: bool = False
    follows: Following | None = None


def _range_of(spec):
    """The range of the GuardedInput `spec` as check_inputs takes it: None
    for any finite value, else (lower, upper, switch), lower and upper
    floats when one range holds for every entry, tuples of `spec.size`
    floats when each entry has its own.

    Raises:
        ValueError: naming the input, when a range is not a number or
            `spec.size` of them, or an entry's lower bound is above its
            upper one.
    """
    bounds = []
    for side in ("lower", "upper"):
        value = np.asarray(getattr(spec, side), dtype=float)
        if np.isnan(value).any() or value.shape not in ((), (spec.size,)):
            raise ValueError(
                f"{spec.name}: {side} = {getattr(spec, side)!r} is not "
                f"allowed: must be a number or {spec.size} numbers")
        bounds.append(float(value) if value.ndim == 0
                      else tuple(value.tolist()))
    lower, upper = bounds
    if np.any(np.asarray(lower) > np.asarray(upper)):
        raise ValueError(f"{spec.name}: lower = {spec.lower!r} is not "
                         f"allowed: must be at most upper = {spec.upper!r}")
    if not (np.any(np.asarray(lower) > -math.inf)
            or np.any(np.asarray(upper) < math.inf) or spec.switch):
        return None
    if isinstance(lower, tuple) or isinstance(upper, tuple):
        lower, upper = (tuple(np.broadcast_to(bound, spec.size).tolist())
                        for bound in (lower, upper))
    return lower, upper, bool(spec.switch)


class _Assessment(NamedTuple):
    values: list        # the current value of each input, None if unset
    checks: tuple       # the InputCheck of each input
    all_valid: bool     # every check valid
    points: np.ndarray  # the usable obstacle points
    dropped: int
    points_check: InputCheck
    following: object   # (input index, InputCheck) of a deviation, or None
    after: object       # the StopState after this tick: the decision
    resumes: bool       # stopped before this tick, not after it


@define_stage("InputGuard_")
def InputGuard_(T):
    class Impl(LeafSystem_[T]):
        """Checks every input of the controller where it enters, passes on
        only valid values, and decides the safe stop.

        ::

                               ┌────────────┐
            <each input> ─────►│            ├──► <its guarded outputs>
            obstacle_points ──►│ InputGuard ├──► obstacle_points (abstract)
            <each command> ───►│            ├──► stop, stopped
                               │            ├──► resume
                               │            ├──► safety_status
                               └────────────┘──► safety_reason (abstract)

        - Each GuardedInput's outputs carry the input while it is valid
          (NaN, infinite, out of range or, for a switch, neither 0 nor 1
          is not), and the last valid
          sample of the whole vector while it is not, so that no stage
          behind it ever integrates an invalid value; with
          zero_when_stopped they carry zeros during a stop, and an output
          given a value while stopped carries that. While an optional
          input is not connected, its outputs carry their defaults.
        - obstacle_points: the (M, 2) points in T_b less the rows with a NaN
          or infinite coordinate, which are dropped and counted
          (drake_wbc.math.safety.check_points); a malformed array is a fault,
          and no points are passed on while it lasts.
        - <each command> (input): for a GuardedInput that `follows` one,
          the command it follows, under the Following's `command` name
          (the arm controller's `arm_position_command`: its state, the
          command of the last tick, so no algebraic loop). At a tick
          that follows one not stopped, an entry of the input farther
          than the tolerance from it is a fault (check_following; the
          input itself is valid and passed on, it is a true
          measurement). During a stop it is not checked: an arm that
          stopped on its own stays where it is, the stop clears after
          hold_time all the same, and the arm controller resumes from
          where the arm is (`resume`). Nor at the very first tick: no
          command has been sent yet (the arm controller's initial state,
          which Controller.initialize sets to the measured position;
          over LCM the measurement may not have arrived yet).
        - stop (1): 1.0 when the controller stops at this tick: the
          decision, from this tick's inputs, that the next update will
          store. For stages that act in their update (the arm
          controller's hold, the gate before the base filter).
        - stopped (1): 1.0 when the last tick decided to stop (state: no
          direct feedthrough), for the command outputs; it equals `stop`
          as it was at that tick.
        - resume (1): 1.0 when a stop clears at this tick (the last tick
          stopped, this one not): for the arm controller's restart from
          where the arm is.
        - safety_status: see STATUS_FIELDS (state).
        - safety_reason: the reason as a sentence, "" when not stopped
          (state); also `reason(context)`.

        Once a tick h (one periodic discrete update): the checks, the stop
        decision by drake_wbc.math.safety.next_stop_state (a stop clears after
        hold_time of valid inputs), the last valid samples kept, and the
        status; a stop is logged (LOGGER) when it trips and when it
        clears.

        State: [the last valid sample of each input, in order; the
        status], one discrete group.

        Args:
            inputs: a sequence of GuardedInput.
            points_name: the obstacle points' input and output port, or
                None for none. Optional: no points while unconnected.
            time_step: the control period h > 0, s.
            params: SafetyParameters (hold_time); defaults if None.
        """

        def _construct(self, inputs, points_name=None, time_step=0.01,
                       params=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.params = checked_instance("params", params,
                                           SafetyParameters,
                                           SafetyParameters)
            self.time_step = positive("time_step", time_step)
            self.inputs = tuple(GuardedInput(*spec) for spec in inputs)
            self.points_name = points_name
            self.input_names = tuple(spec.name for spec in self.inputs) + (
                (points_name,) if points_name else ())
            self._sizes = [spec.size for spec in self.inputs] + [None]
            self._ports, self._slices, start = [], [], 0
            initial = []
            for spec in self.inputs:
                self._ports.append(
                    self.DeclareVectorInputPort(spec.name, spec.size))
                self._slices.append(slice(start, start + spec.size))
                start += spec.size
                initial.append(np.zeros(spec.size) if spec.initial is None
                               else as_vector(spec.name, spec.initial,
                                              spec.size))
            self._status_start = start
            self._status_part = slice(start, None)
            self._stopped = slice(_STATUS["stopped"], _STATUS["stopped"] + 1)
            # Built once: which inputs may be left unconnected, their
            # ranges, and which body checks them.
            self._port_optional = tuple(
                (port, any(entry[1] is not None for entry in spec.outputs))
                for port, spec in zip(self._ports, self.inputs, strict=True))
            self._ranges = tuple(_range_of(spec) for spec in self.inputs)
            # Each input's Following (None for the points), as input_names.
            self.followings = tuple(spec.follows for spec in self.inputs) + (
                (None,) if points_name else ())
            self._commands = []
            for i, spec in enumerate(self.inputs):
                if spec.follows is not None:
                    positive(f"{spec.name} follows.tolerance",
                             spec.follows.tolerance)
                    self._commands.append((i, spec.follows, (
                        self.DeclareVectorInputPort(spec.follows.command,
                                                    spec.size))))
            self._check_inputs = body_for(check_inputs, T)
            self._check_points = body_for(check_points, T)
            self._points = None
            if points_name:
                self._points = self.DeclareAbstractInputPort(
                    points_name, AbstractValue.Make(np.zeros((0, 2))))
            state = self.DeclareDiscreteState(
                np.concatenate(initial + [initial_status()]))
            self.DeclarePeriodicDiscreteUpdateEvent(time_step, 0.0,
                                                    self._update)
            from_state = {self.discrete_state_ticket(state)}
            self._status_entry = self.DeclareCacheEntry(
                "the status, in floats",
                ValueProducer(
                    allocate=lambda: AbstractValue.Make(np.zeros(0)),
                    calc=lambda context, value: value.set_value(value_of(
                        self._state(context)[self._status_part]))),
                from_state)
            self._assessment = self.DeclareCacheEntry(
                "the inputs' checks and the stop decision",
                ValueProducer(allocate=lambda: AbstractValue.Make(object()),
                              calc=self._calc_assessment),
                {self.all_sources_ticket()})
            for i, spec in enumerate(self.inputs):
                outputs = spec.outputs or ((spec.name, None),)
                for name, default, *while_stopped in outputs:
                    if default is not None:
                        default = as_vector(f"{name} default", default,
                                            spec.size)
                    stopped = (np.zeros(spec.size) if spec.zero_when_stopped
                               else None)
                    if while_stopped and while_stopped[0] is not None:
                        stopped = as_vector(f"{name} while stopped",
                                            while_stopped[0], spec.size)
                    self.DeclareVectorOutputPort(
                        name, spec.size,
                        self._guarded_calc(i, default, stopped))
            if points_name:
                self.DeclareAbstractOutputPort(
                    points_name, lambda: AbstractValue.Make(np.zeros((0, 2))),
                    self._points_output)
            self._stop_values = (np.zeros(1), np.ones(1))
            self.DeclareVectorOutputPort("stop", 1, self._stop_output)
            self.DeclareVectorOutputPort("resume", 1, self._resume_output)
            self.DeclareVectorOutputPort(
                "stopped", 1, self._stopped_output,
                prerequisites_of_calc=from_state)
            self.DeclareVectorOutputPort(
                "safety_status", len(STATUS_FIELDS), self._status_output,
                prerequisites_of_calc=from_state)
            self.DeclareAbstractOutputPort(
                "safety_reason", lambda: AbstractValue.Make(""),
                self._reason_output, prerequisites_of_calc=from_state)

        # --- evaluation ---------------------------------------------------

        def _state(self, context):
            """The state as a new array of T."""
            return context.get_discrete_state_vector().CopyToVector()

        def _status(self, context):
            """The status as floats (computed once per state)."""
            return self._status_entry.Eval(context)

        def _calc_assessment(self, context, value):
            value.set_value(self._assessment_of(context))

        def _assessment_of(self, context):
            values = [None if optional and not port.HasValue(context)
                      else port.Eval(context)
                      for port, optional in self._port_optional]
            checks = self._check_inputs(values, self._ranges)
            # Valid checks are VALID itself: counted by identity first.
            all_valid = (checks.count(VALID) == len(checks)
                         or all(check.valid for check in checks))
            if self._points is not None and self._points.HasValue(context):
                points, dropped, points_check = self._check_points(
                    self._points.Eval(context))
            else:
                points, dropped, points_check = np.zeros((0, 2)), 0, VALID
            before = stop_state_of(self._status(context))
            following = None
            # Checked at a tick that follows one not stopped, but for the
            # first (valid for 0 s and not stopped: no tick yet).
            if not before.stopped and before.valid_time > 0.0:
                for i, follows, port in self._commands:
                    if values[i] is None or not checks[i].valid:
                        continue
                    check = check_following(values[i], port.Eval(context),
                                            follows.tolerance)
                    if not check.valid:
                        following = i, check
                        break
            invalid = not (points_check.valid and all_valid) or (
                following is not None)
            after = next_stop_state(before, invalid, self.time_step,
                                    self.params.hold_time)
            return _Assessment(values, checks, all_valid, points, dropped,
                               points_check, following, after,
                               before.stopped and not after.stopped)

        def _first_fault(self, assessment):
            """(input index, InputCheck) of the first invalid input, or
            None."""
            if not assessment.all_valid:
                for i, check in enumerate(assessment.checks):
                    if not check.valid:
                        return i, check
            if not assessment.points_check.valid:
                return len(self.inputs), assessment.points_check
            return assessment.following

        # --- outputs ------------------------------------------------------

        def _guarded_calc(self, i, default, while_stopped):
            part, port = self._slices[i], self._ports[i]
            # An output with a default is its default while its input is
            # not connected: no need of the assessment then (unless a stop
            # changes it).
            shortcut = default is not None and while_stopped is None
            assessment = self._assessment

            def calc(context, output):
                if shortcut and not port.HasValue(context):
                    output.SetFromVector(default)
                    return
                a = assessment.Eval(context)
                value = a.values[i]
                if while_stopped is not None and a.after.stopped:
                    value = while_stopped
                elif value is None:
                    value = default
                elif not (a.all_valid or a.checks[i].valid):
                    value = self._state(context)[part]
                output.SetFromVector(value)

            return calc

        def _points_output(self, context, output):
            output.set_value(self._assessment.Eval(context).points)

        def _resume_output(self, context, output):
            resumes = self._assessment.Eval(context).resumes
            output.SetFromVector(self._stop_values[resumes])

        def _stop_output(self, context, output):
            stop = self._assessment.Eval(context).after.stopped
            output.SetFromVector(self._stop_values[stop])

        def _stopped_output(self, context, output):
            output.SetFromVector(self._status(context)[self._stopped])

        def _status_output(self, context, output):
            output.SetFromVector(self._status(context))

        def _reason_output(self, context, output):
            output.set_value(self.reason(context))

        def reason(self, context):
            """What stopped the controller, as a sentence ("" when it is
            not stopped)."""
            return self._reason_of(self._status(context))

        def _reason_of(self, status):
            return status_reason(status, self.input_names, self._sizes,
                                 self.params.hold_time, self.followings)

        # --- update -------------------------------------------------------

        def _update(self, context, discrete_state):
            a = self._assessment.Eval(context)
            start = self._status_start
            state = self._state(context)
            old = self._status(context)
            was_stopped = old[_STATUS["stopped"]] >= 0.5
            for value, part, check in zip(a.values, self._slices, a.checks,
                                          strict=True):
                if value is not None and (a.all_valid or check.valid):
                    state[part] = value
            new = next_status(old, self._first_fault(a), a.after, a.dropped)
            state[start:] = new
            discrete_state.set_value(state)
            if a.after.stopped != was_stopped:
                self._log(float(value_of(context.get_time())), new)

        def _log(self, t, status):
            if status[_STATUS["stopped"]] >= 0.5:
                LOGGER.warning("safe stop at t = %.3f s: %s", t,
                               self._reason_of(status))
            else:
                LOGGER.warning(
                    "safe stop cleared at t = %.3f s: every input valid for "
                    "%g s, resuming", t, self.params.hold_time)

        def set_last_valid(self, context, name, value):
            """Sets the sample passed on for input `name` if the first one
            is invalid (e.g. the measured arm position at the start)."""
            index = [spec.name for spec in self.inputs].index(name)
            state = self._state(context)
            state[self._slices[index]] = as_vector(
                name, value, self.inputs[index].size)
            context.SetDiscreteState(state)

    return Impl


InputGuard = InputGuard_[None]
"""InputGuard_ for double; `ToAutoDiffXd()` gives the AutoDiff one."""


@define_stage("StopGate_")
def StopGate_(T):
    class Impl(LeafSystem_[T]):
        """Passes a vector on, within an envelope, or zeros during a safe
        stop.

        ::

                     ┌──────────┐
            value ──►│          ├──► gated
            stop ───►│ StopGate ├──► scale
                     └──────────┘

        - value: (size) the signal.
        - stop (1): >= 0.5 during a stop (InputGuard's `stop`).
        - gated: (size) zeros while stop; otherwise value, scaled as a
          whole into `limits` when given and exceeded (|gated_i| <=
          limits_i, direction kept,
          drake_wbc.math.command_limits.uniform_scale); the
          very same values when within them.
        - scale (1): that factor in [0, 1] (1 when within the limits or
          stopped), for the BaseCommandLimiter's report.
        Both outputs are direct feedthrough of both inputs.

        Before the base filter of eq. (filtering) it lets the filter's
        state settle towards rest during a stop (to (1 + omega_f t)
        exp(-omega_f t) of its value, 18% after the shortest stop of 0.5 s
        with the paper's omega_f = 2 pi rad/s and zeta = 1), so that the
        filter restarts from near zero velocity when the stop clears; the
        BaseCommandLimiter ramps the command from zero from there. With
        the base's velocity limits as the envelope it is the filter's
        anti-windup: a critically or over-damped filter (zeta >= 1) has a
        non-negative impulse response of unit area, continuous or sampled
        (its step response is monotone), so its state never asks for more
        than the base can do, however large V_b' grows (e.g. a person
        walking into the footprint, whose repulsion eq. (cdmp-base) bounds
        only by RepulsiveFieldParameters.max_force); the arm compensates
        the part taken away (eq. (compensation)).

        Without limits it is a stop switch; the controller holds the
        DMPs' couplings with StopSwitch (drake_wbc.stages.stop_switch),
        the same in Drake's C++ systems.

        In AutoDiffXd the scale is computed on the AutoDiffXd value
        (uniform_scale takes any scalar type), so the gate's derivatives
        are those of what it sends: the identity where no limit acts,
        and where the k-th entry binds, gated = s value with
        s = limit_k / |value_k|, the Jacobian s (I - value e_k^T /
        value_k), for `Linearize` of a saturated base command.

        Args:
            size: the signal's size, a whole number >= 1.
            limits: None (no envelope), or (size,) limits > 0.
        """

        def _construct(self, size=3, limits=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.size = whole_number("size", size, minimum=1)
            self.limits = None if limits is None else tuple(
                positive_vector("limits", limits, self.size).tolist())
            self._zeros = np.zeros(self.size)
            self._value = self.DeclareVectorInputPort("value", self.size)
            self._stop = self.DeclareVectorInputPort("stop", 1)
            self.DeclareVectorOutputPort("gated", self.size, self._output)
            self.DeclareVectorOutputPort("scale", 1, self._scale_output)

        def _stopped(self, context):
            return self._stop.Eval(context)[0] >= 0.5

        def _scale(self, value):
            if self.limits is None:
                return 1.0
            return uniform_scale(value, self.limits)

        def _output(self, context, output):
            if self._stopped(context):
                output.SetFromVector(self._zeros)
                return
            value = self._value.Eval(context)
            scale = self._scale(value)
            output.SetFromVector(value if scale == 1.0 else scale * value)

        def _scale_output(self, context, output):
            scale = 1.0 if self._stopped(context) else self._scale(
                self._value.Eval(context))
            output.SetFromVector(np.array([scale]))

    return Impl


StopGate = StopGate_[None]
"""StopGate_ for double; `ToAutoDiffXd()` gives the AutoDiff one."""

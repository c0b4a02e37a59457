"""The controller's run-time safety as a Drake system, thin over
drake_wbc.math.safety: InputGuard, every input checked where it enters, and
the safe stop. The systems that act on the base's command during a stop
and at the limits are in drake_wbc.stages.base_command."""

import logging
import math
from typing import NamedTuple

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem_, ValueProducer
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_wbc.math.safety import (
    STATUS_FIELDS,
    VALID,
    InputCheck,
    SafetyParameters,
    check_points,
    check_vector,
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
    validated_copy,
)

SCALARS = [float, AutoDiffXd]
"""Double, and AutoDiffXd (ToAutoDiffXd of the whole controller)."""

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
        outputs: ((output name, default), ...), the guarded copies of the
            input; a default (a vector of `size`) is what the output
            carries while the input is not connected, None to require a
            connection. () means one output named like the input, required.
        lower, upper: the range allowed for every entry.
        zero_when_stopped: the outputs carry zeros during a safe stop (a
            reference that must not drive anything while stopped).
        initial: the value passed on if the very first sample is invalid
            (zeros if None).
    """

    name: str
    size: int
    outputs: tuple = ()
    lower: float = -math.inf
    upper: float = math.inf
    zero_when_stopped: bool = False
    initial: tuple | None = None


def as_scalar_type(T, values):
    """`values` as a float array, or as AutoDiffXd when T is."""
    array = np.asarray(values)
    if T is float:
        return array.astype(float)
    flat = [v if isinstance(v, AutoDiffXd) else AutoDiffXd(float(v))
            for v in array.ravel()]
    return np.array(flat, dtype=object).reshape(array.shape)


class _Assessment(NamedTuple):
    values: list        # the current value of each input, None if unset
    checks: list        # the InputCheck of each input
    points: np.ndarray  # the usable obstacle points
    dropped: int
    points_check: InputCheck
    after: object       # the StopState after this tick: the decision


@TemplateSystem.define("InputGuard_", T_list=SCALARS)
def InputGuard_(T):
    class Impl(LeafSystem_[T]):
        """Checks every input of the controller where it enters, passes on
        only valid values, and decides the safe stop.

        ::

                               ┌────────────┐
            <each input> ─────►│            ├──► <its guarded outputs>
            obstacle_points ──►│ InputGuard ├──► obstacle_points (abstract)
                               │            ├──► stop, stopped
                               │            ├──► safety_status
                               └────────────┘──► safety_reason (abstract)

        - Each GuardedInput's outputs carry the input while it is valid
          (NaN, infinite or out of range is not), and the last valid
          sample of the whole vector while it is not, so that no stage
          behind it ever integrates an invalid value; with
          zero_when_stopped they carry zeros during a stop. While an
          optional input is not connected, its outputs carry their
          defaults.
        - obstacle_points: the (M, 2) points in T_b less the rows with a NaN
          or infinite coordinate, which are dropped and counted
          (drake_wbc.math.safety.check_points); a malformed array is a fault,
          and no points are passed on while it lasts.
        - stop (1): 1.0 when the controller stops at this tick: the
          decision, from this tick's inputs, that the next update will
          store. For stages that act in their update (the arm
          controller's hold, the gate before the base filter).
        - stopped (1): 1.0 when the last tick decided to stop (state: no
          direct feedthrough), for the command outputs; it equals `stop`
          as it was at that tick.
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
            self.params = validated_copy(checked_instance(
                "params", params, SafetyParameters, SafetyParameters))
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
            self._stopped_part = slice(start + _STATUS["stopped"],
                                       start + _STATUS["stopped"] + 1)
            # Built once: which inputs may be left unconnected, which have
            # a range to check, and the checks when every input is valid.
            self._port_optional = tuple(
                (port, any(default is not None for _, default in spec.outputs))
                for port, spec in zip(self._ports, self.inputs, strict=True))
            self._bounded = tuple(
                (i, float(spec.lower), float(spec.upper))
                for i, spec in enumerate(self.inputs)
                if spec.lower > -math.inf or spec.upper < math.inf)
            self._all_valid = (VALID,) * len(self.inputs)
            self._points = None
            if points_name:
                self._points = self.DeclareAbstractInputPort(
                    points_name, AbstractValue.Make(np.zeros((0, 2))))
            state = self.DeclareDiscreteState(
                np.concatenate(initial + [initial_status()]))
            self.DeclarePeriodicDiscreteUpdateEvent(time_step, 0.0,
                                                    self._update)
            from_state = {self.discrete_state_ticket(state)}
            self._assessment = self.DeclareCacheEntry(
                "the inputs' checks and the stop decision",
                ValueProducer(allocate=lambda: AbstractValue.Make(object()),
                              calc=self._calc_assessment),
                {self.all_sources_ticket()})
            for i, spec in enumerate(self.inputs):
                outputs = spec.outputs or ((spec.name, None),)
                for name, default in outputs:
                    if default is not None:
                        default = as_scalar_type(T, as_vector(
                            f"{name} default", default, spec.size))
                    self.DeclareVectorOutputPort(
                        name, spec.size, self._guarded_calc(i, default))
            if points_name:
                self.DeclareAbstractOutputPort(
                    points_name, lambda: AbstractValue.Make(np.zeros((0, 2))),
                    self._points_output)
            self._stop_values = tuple(as_scalar_type(T, [value])
                                      for value in (0.0, 1.0))
            self.DeclareVectorOutputPort("stop", 1, self._stop_output)
            self.DeclareVectorOutputPort(
                "stopped", 1, self._stopped_output,
                prerequisites_of_calc=from_state)
            self.DeclareVectorOutputPort(
                "safety_status", len(STATUS_FIELDS), self._status_output,
                prerequisites_of_calc=from_state)
            self.DeclareAbstractOutputPort(
                "safety_reason", lambda: AbstractValue.Make(""),
                self._reason_output, prerequisites_of_calc=from_state)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.inputs, other.points_name,
                            other.time_step, other.params,
                            converter=converter)
            self.params = other.params

        # --- evaluation ---------------------------------------------------

        def _state(self, context):
            """The state as a new array of T."""
            return context.get_discrete_state_vector().CopyToVector()

        def _status(self, context, part=None):
            """The status, or `part` of the state, as floats (for double,
            a view of the state)."""
            part = part or self._status_part
            if T is float:
                return context.get_discrete_state_vector().get_value()[part]
            return value_of(self._state(context)[part])

        def _calc_assessment(self, context, value):
            value.set_value(self._assessment_of(context))

        def _assessment_of(self, context):
            values = [None if optional and not port.HasValue(context)
                      else port.Eval(context)
                      for port, optional in self._port_optional]
            checks = self._checks(values)
            if self._points is not None and self._points.HasValue(context):
                points, dropped, points_check = check_points(
                    self._points.Eval(context))
            else:
                points, dropped, points_check = np.zeros((0, 2)), 0, VALID
            invalid = not (points_check.valid and (
                checks is self._all_valid or all(c.valid for c in checks)))
            after = next_stop_state(stop_state_of(self._status(context)),
                                    invalid, self.time_step,
                                    self.params.hold_time)
            return _Assessment(values, checks, points, dropped,
                               points_check, after)

        def _checks(self, values):
            """The InputCheck of each value (VALID for None): one test of
            every entry present and of the ranges, the per-input detail
            only when one fails."""
            floats = values if T is float else [
                None if value is None else value_of(value)
                for value in values]
            # A sum of floats is finite only if every term is (a sum that
            # overflows only sends the values to the detailed checks).
            total = 0.0
            for value in floats:
                if value is not None:
                    total += sum(value.tolist())
            valid = math.isfinite(total)
            for i, lower, upper in self._bounded if valid else ():
                value = floats[i]
                if value is not None and not (
                        lower <= value.min() and value.max() <= upper):
                    valid = False
                    break
            if valid:
                return self._all_valid
            return [VALID if value is None else check_vector(
                value, spec.lower, spec.upper)
                for spec, value in zip(self.inputs, floats, strict=True)]

        def _first_fault(self, assessment):
            """(input index, InputCheck) of the first invalid input, or
            None."""
            if assessment.checks is not self._all_valid:
                for i, check in enumerate(assessment.checks):
                    if not check.valid:
                        return i, check
            if not assessment.points_check.valid:
                return len(self.inputs), assessment.points_check
            return None

        # --- outputs ------------------------------------------------------

        def _guarded_calc(self, i, default):
            spec, part, port = self.inputs[i], self._slices[i], self._ports[i]
            zeros = as_scalar_type(T, np.zeros(spec.size))
            # An output with a default is its default while its input is
            # not connected: no need of the assessment then.
            zero_when_stopped = spec.zero_when_stopped
            shortcut = default is not None and not zero_when_stopped
            assessment, all_valid = self._assessment, self._all_valid

            def calc(context, output):
                if shortcut and not port.HasValue(context):
                    output.SetFromVector(default)
                    return
                a = assessment.Eval(context)
                value = a.values[i]
                if zero_when_stopped and a.after.stopped:
                    value = zeros
                elif value is None:
                    value = default
                elif not (a.checks is all_valid or a.checks[i].valid):
                    value = self._state(context)[part]
                output.SetFromVector(value)

            return calc

        def _points_output(self, context, output):
            output.set_value(self._assessment.Eval(context).points)

        def _stop_output(self, context, output):
            stop = self._assessment.Eval(context).after.stopped
            output.SetFromVector(self._stop_values[stop])

        def _stopped_output(self, context, output):
            stopped = self._status(context, self._stopped_part)
            output.SetFromVector(
                stopped if T is float else as_scalar_type(T, stopped))

        def _status_output(self, context, output):
            status = self._status(context)
            output.SetFromVector(
                status if T is float else as_scalar_type(T, status))

        def _reason_output(self, context, output):
            output.set_value(self.reason(context))

        def reason(self, context):
            """What stopped the controller, as a sentence ("" when it is
            not stopped)."""
            return self._reason_of(self._status(context))

        def _reason_of(self, status):
            return status_reason(status, self.input_names, self._sizes,
                                 self.params.hold_time)

        # --- update -------------------------------------------------------

        def _update(self, context, discrete_state):
            a = self._assessment.Eval(context)
            start = self._status_start
            if T is float:
                # Drake fills `discrete_state` with the state before the
                # update: only what changes is written, in place.
                state = discrete_state.get_mutable_value()
            else:
                state = self._state(context)
            old = state[start:] if T is float else value_of(state[start:])
            was_stopped = old[_STATUS["stopped"]] >= 0.5
            valid = a.checks is self._all_valid
            for value, part, check in zip(a.values, self._slices, a.checks,
                                          strict=True):
                if value is not None and (valid or check.valid):
                    state[part] = value
            new = next_status(old, self._first_fault(a), a.after, a.dropped)
            state[start:] = new
            if T is not float:
                discrete_state.set_value(as_scalar_type(T, state))
            elif a.after.stopped != was_stopped:
                self._log(context.get_time(), new)

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
            context.SetDiscreteState(as_scalar_type(T, state))

    return Impl


InputGuard = InputGuard_[None]
"""InputGuard_ for double; `ToAutoDiffXd()` gives the AutoDiff one."""

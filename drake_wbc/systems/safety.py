"""The controller's run-time safety as a Drake system, thin over
drake_wbc.safety: InputGuard, every input checked where it enters, and
the safe stop. The systems that act on the base's command during a stop
and at the limits are in drake_wbc.systems.base_command."""

import logging
import math
from typing import NamedTuple

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem_, ValueProducer
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_wbc.safety import (
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
from drake_wbc.scalar_support import value_of
from drake_wbc.validation import (
    as_vector,
    checked_instance,
    positive,
    validated_copy,
)

SCALARS = [float, AutoDiffXd]
"""Double, and AutoDiffXd (ToAutoDiffXd of the whole controller)."""

LOGGER = logging.getLogger("drake_wbc.safety")
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
    after: object       # the StopState after this tick

    @property
    def stop(self):
        """The decision of this tick."""
        return self.after.stopped


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
          (drake_wbc.safety.check_points); a malformed array is a fault,
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
        decision by drake_wbc.safety.next_stop_state (a stop clears after
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
            # The ranges of the entries of the inputs present, by which
            # are present, for one vectorised check a tick.
            self._ranges = {}
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
                        default = as_vector(f"{name} default", default,
                                            spec.size)
                    self.DeclareVectorOutputPort(
                        name, spec.size, self._guarded_calc(i, default))
            if points_name:
                self.DeclareAbstractOutputPort(
                    points_name, lambda: AbstractValue.Make(np.zeros((0, 2))),
                    self._points_output)
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
            return context.get_discrete_state_vector().CopyToVector()

        def _status(self, context):
            return value_of(self._state(context)[self._status_start:])

        def _assess(self, context):
            """The _Assessment of the inputs at `context` (cached)."""
            return self._assessment.Eval(context)

        def _calc_assessment(self, context, value):
            value.set_value(self._assessment_of(context))

        def _assessment_of(self, context):
            values = [port.Eval(context) if port.HasValue(context) or (
                not self._has_default(spec)) else None
                for spec, port in zip(self.inputs, self._ports, strict=True)]
            checks = self._checks(values)
            points, dropped, points_check = np.zeros((0, 2)), 0, VALID
            if self._points is not None and self._points.HasValue(context):
                points, dropped, points_check = check_points(
                    self._points.Eval(context))
            invalid = not (points_check.valid
                           and all(c.valid for c in checks))
            after = next_stop_state(stop_state_of(self._status(context)),
                                    invalid, self.time_step,
                                    self.params.hold_time)
            return _Assessment(values, checks, points, dropped,
                               points_check, after)

        def _checks(self, values):
            """The InputCheck of each value (VALID for None): one
            vectorised test of every entry present, the per-input detail
            only when an entry fails it."""
            present = tuple(value is not None for value in values)
            ranges = self._ranges.get(present)
            if ranges is None:
                specs = [spec for spec, here in zip(
                    self.inputs, present, strict=True) if here]
                ranges = self._ranges[present] = tuple(
                    np.concatenate([np.full(spec.size, float(getattr(
                        spec, bound))) for spec in specs] or [np.zeros(0)])
                    for bound in ("lower", "upper"))
            flat = value_of(np.concatenate(
                [value for value in values if value is not None]
                or [np.zeros(0)]))
            if np.all(np.isfinite(flat)) and np.all(
                    (flat >= ranges[0]) & (flat <= ranges[1])):
                return [VALID] * len(values)
            return [VALID if value is None else check_vector(
                value_of(value), spec.lower, spec.upper)
                for spec, value in zip(self.inputs, values, strict=True)]

        @staticmethod
        def _has_default(spec):
            return any(default is not None
                       for _, default in (spec.outputs or ()))

        def _first_fault(self, assessment):
            """(input index, InputCheck) of the first invalid input, or
            None."""
            for i, check in enumerate(assessment.checks):
                if not check.valid:
                    return i, check
            if not assessment.points_check.valid:
                return len(self.inputs), assessment.points_check
            return None

        # --- outputs ------------------------------------------------------

        def _guarded_calc(self, i, default):
            spec, part = self.inputs[i], self._slices[i]

            def calc(context, output):
                a = self._assess(context)
                value = a.values[i]
                if spec.zero_when_stopped and a.stop:
                    result = np.zeros(spec.size)
                elif value is None:
                    result = default
                elif a.checks[i].valid:
                    result = value
                else:
                    result = self._state(context)[part]
                output.SetFromVector(as_scalar_type(T, result))

            return calc

        def _points_output(self, context, output):
            output.set_value(self._assess(context).points)

        def _stop_output(self, context, output):
            stop = 1.0 if self._assess(context).stop else 0.0
            output.SetFromVector(as_scalar_type(T, [stop]))

        def _stopped_output(self, context, output):
            output.SetFromVector(as_scalar_type(
                T, self._status(context)[_STATUS["stopped"]:][:1]))

        def _status_output(self, context, output):
            output.SetFromVector(as_scalar_type(T, self._status(context)))

        def _reason_output(self, context, output):
            output.set_value(self.reason(context))

        def reason(self, context):
            """What stopped the controller, as a sentence ("" when it is
            not stopped)."""
            return self._reason_of(self._status(context))

        def _reason_of(self, status):
            sizes = [spec.size for spec in self.inputs] + [None]
            return status_reason(status, self.input_names, sizes,
                                 self.params.hold_time)

        # --- update -------------------------------------------------------

        def _update(self, context, discrete_state):
            a = self._assess(context)
            state = self._state(context)
            old = self._status(context)
            for i, part in enumerate(self._slices):
                if a.values[i] is not None and a.checks[i].valid:
                    state[part] = a.values[i]
            new = next_status(old, self._first_fault(a), a.after, a.dropped)
            was_stopped = stop_state_of(old).stopped
            state[self._status_start:] = new
            discrete_state.set_value(as_scalar_type(T, state))
            if T is float and a.stop != was_stopped:
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

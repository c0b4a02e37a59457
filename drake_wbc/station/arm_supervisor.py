"""The arm's servo interface: the commands it refuses, and its fault stop.

A cobot's servo does not follow any position command stream: a command
beyond a joint's position limits, or moving faster or changing its rate
faster than the joint's speed and acceleration limits allow, makes the
arm fault (drake_wbc.math.arm_servo.arm_command_violation). The
simulated station's arm does the same, so that a controller that would
fault on the robot faults in simulation too: `ArmCommandSupervisor`
stands between the station's `arm.position_command` and the arm's
position servo (its interpolator, drake_wbc.station.symbolic_drivers).

On the first command beyond a limit the arm brakes to rest within its
acceleration limits (drake_wbc.math.arm_servo.brake_arm) and stays there
for the rest of the run, whatever it is sent: the controlled stop of a
cobot's protective stop (IEC 60204-1 stop category 1 or 2, ISO 10218-1),
not a hold on the spot, which would ask the servo for an unbounded
deceleration (from 1.57 rad/s at 12.56 rad/s^2 the shipped arm stops in
0.125 s, within 0.1 rad). Only a new start (`set_positions`, as the
station's `set_initial_state`) clears the fault, as the robot's reset.
"""

import logging
import math
from typing import NamedTuple

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem, ValueProducer

from drake_wbc.math.arm_control import start_within_limits
from drake_wbc.math.arm_servo import (
    LIMIT_KINDS,
    ArmLimitViolation,
    arm_command_violation,
    brake_arm,
)
from drake_wbc.math.validation import positive

FAULT_SIZE = 6
"""The fault's entries in the state: 1 or 0, time, joint, kind, value,
limit."""

LOG = logging.getLogger("drake_wbc.station")
"""Where the station reports an arm fault, once (at WARNING, so that
Python's default handler prints it on stderr)."""


class ArmFault(NamedTuple):
    """A fault of the arm: when, and the limit the command broke.

    Attributes:
        time: the command's sample time, s.
        violation: the ArmLimitViolation (drake_wbc.math.arm_servo).
        joint_name: the joint's name (its robot description's).
    """

    time: float
    violation: ArmLimitViolation
    joint_name: str

    def message(self):
        """The fault in one sentence, as the station's log says it."""
        v = self.violation
        joint = f"joint {v.joint + 1} ({self.joint_name})"
        if v.kind == "position" and np.isnan(v.value):
            what = f"{joint}'s command is not a number"
        elif v.kind == "position":
            side = "lower" if v.value < v.limit else "upper"
            what = (f"{joint}'s command {v.value:.6g} rad is beyond its "
                    f"{side} limit {v.limit:.6g} rad")
        elif v.kind == "speed":
            what = (f"{joint}'s command moves at {v.value:.6g} rad/s, "
                    f"beyond its {v.limit:.6g} rad/s limit")
        else:
            what = (f"{joint}'s command changes its rate at {v.value:.6g} "
                    f"rad/s^2, beyond its {v.limit:.6g} rad/s^2 limit")
        return (f"arm fault at t = {self.time:.3f} s: {what}; the arm "
                "brakes to rest within its acceleration limits and stays "
                "stopped")


class ArmCommandSupervisor(LeafSystem):
    """The arm's servo interface: commands within the limits pass, the
    first one beyond faults the arm.

    ::

                               ┌──────────────────────┐
            position_command ─►│ ArmCommandSupervisor ├──► position_command
                               │                      ├──► fault
                               └──────────────────────┘

    - position_command: (n) the command received, rad.
    - position_command (output): what the arm's servo takes at each
      sample (every `period` from t = 0, when the servo samples too):
      the command received while it and every one before it were within
      the limits (`arm_command_violation` against the last one taken, at
      rest from the start), else the next step of the stop
      (`brake_arm`).
    - fault: (1) 1 from the sample of the first command beyond a limit
      on, else 0.

    A periodic discrete update at each sample stores what was taken (a
    discrete one, so that the servo's own update at the same instant
    reads the output of before it); the fault is said once on the
    `drake_wbc.station` logger (`ArmFault.message`). State: [the last
    command taken (n), its rate (n), the fault: 1 or 0, its time, joint,
    kind (index into LIMIT_KINDS), value and limit]. A plain double
    LeafSystem: it branches on the limits and is never linearised (the
    station's analyses build the servo without it, drake_wbc.analysis).

    Args:
        period: the servo's command period, s.
        initial_positions: (n,) what the arm holds at the start, within
            the joint limits (`start_within_limits`).
        limits: the arm's own ArmLimits (drake_wbc.robot.model:
            lower, upper, velocity, acceleration, (n,) each).
        joint_names: the arm's n joints' names, for the fault's message.
    """

    def __init__(self, period, initial_positions, limits, joint_names):
        super().__init__()
        self.period = positive("period", period)
        self.limits = limits
        self.joint_names = tuple(joint_names)
        n = len(limits.lower)
        if len(self.joint_names) != n:
            raise ValueError(
                f"joint_names = {list(self.joint_names)!r} is not allowed: "
                f"must name the limits' {n} joints")
        self._in = self.DeclareVectorInputPort("position_command", n)
        self.DeclareDiscreteState(self._holding(
            "initial_positions", initial_positions))
        self.DeclarePeriodicDiscreteUpdateEvent(self.period, 0.0,
                                                self._update)
        # What is taken at a sample, once for the output and the update;
        # not on time, since the command taken changes only with the
        # command received and the state (the station's plant steps
        # several times a command period).
        self._taken_entry = self.DeclareCacheEntry(
            "the command taken", ValueProducer(
                allocate=lambda: AbstractValue.Make(np.zeros(0)),
                calc=lambda c, value: value.set_value(self._taken(c))),
            {self._in.ticket(), self.xd_ticket()})
        self.DeclareVectorOutputPort(
            "position_command", n, lambda c, o: o.SetFromVector(
                self._taken_entry.Eval(c)[:n]),
            prerequisites_of_calc={self._taken_entry.ticket()})
        self.DeclareVectorOutputPort(
            "fault", 1, lambda c, o: o.SetAtIndex(
                0, self._state(c)[2 * n]),
            prerequisites_of_calc={self.xd_ticket()})

    def _holding(self, name, positions):
        """The state holding `positions` at rest, without a fault."""
        limits = self.limits
        q = start_within_limits(name, positions, limits.lower, limits.upper,
                                limits.acceleration, self.period)
        return np.concatenate([q, np.zeros(q.size + FAULT_SIZE)])

    @staticmethod
    def _state(context):
        return context.get_discrete_state_vector().CopyToVector()

    def fault(self, context):
        """The ArmFault in this system's `context`, or None."""
        return self._fault_in(self._state(context))

    def _fault_in(self, state):
        """The ArmFault a state vector holds, or None."""
        n = len(self.joint_names)
        faulted, time, joint, kind, value, limit = state[2 * n:]
        if not faulted:
            return None
        joint = int(joint)
        return ArmFault(time, ArmLimitViolation(
            joint, LIMIT_KINDS[int(kind)], value, limit),
            self.joint_names[joint])

    def set_positions(self, context, positions):
        """Holds the arm at `positions` at rest, without a fault, in this
        system's `context` (a reset of the arm)."""
        context.SetDiscreteState(self._holding("positions", positions))

    def _taken(self, context):
        """The state after a sample at the context's input and state (a
        new fault's time NaN: `_update` writes the sample's)."""
        state = self._state(context)
        n, limits = len(self.joint_names), self.limits
        last, velocity = state[:n], state[n:2 * n]
        fault = state[2 * n:]
        if not fault[0]:
            received = self._in.Eval(context)
            violation = arm_command_violation(
                received, last, velocity, self.period, limits.lower,
                limits.upper, limits.velocity, limits.acceleration)
            if violation is None:
                q = np.array(received, dtype=float)
                return np.concatenate([q, (q - last) / self.period, fault])
            # The time is the update's (`_update`).
            fault = [1.0, math.nan, violation.joint,
                     LIMIT_KINDS.index(violation.kind), violation.value,
                     violation.limit]
        command, velocity = brake_arm(
            last, velocity, self.period, limits.acceleration, limits.lower,
            limits.upper)
        return np.concatenate([command, velocity, fault])

    def _update(self, context, discrete_state):
        n = len(self.joint_names)
        taken = self._taken_entry.Eval(context)
        if taken[2 * n] and not self._state(context)[2 * n]:
            taken = taken.copy()
            taken[2 * n + 1] = context.get_time()
            LOG.warning(self._fault_in(taken).message())
        discrete_state.set_value(taken)

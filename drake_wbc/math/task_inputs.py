"""The controller's task inputs: the size of each and the values its
entries may take, in one table, TASK_INPUTS.

- reference_velocity: V_ee^ref (6), the world-frame twist [v; w] of eq.
  (cdmp-wb); every entry within +-MAX_REFERENCE.
- desired_wrench: F_d (6) of eq. (cdmp-arm); any finite values.
- phri_switch: S_hri (1), 0 or 1 (eqs. (cdmp-wb), (cdmp-arm): "a pHRI
  mode switching variable with value of 0 or 1").
- null_space_gain: k_n (1) >= 0 of eq. (wbccm).
- compensation_switch: s_c (1) in [0, 1] of eq. (compensation).

Every check of a task input reads its range here: the task's schedules
(drake_wbc.controller.task), the controller's InputGuard
(drake_wbc.controller.diagram), the parameters that give an input's
default while it is not connected (ControllerParameters.phri_switch,
MotionDistributorParameters.null_space_gain,
RobustCompensatorParameters.compensation_switch) and the stages that read
k_n and s_c from their ports, which check them on every tick so that a
stage used alone raises on a bad value (in the controller the InputGuard
never passes one on).
"""

import math
from typing import NamedTuple

from drake_wbc.math.scalar_support import value_of
from drake_wbc.math.validation import as_scalar


class TaskInput(NamedTuple):
    """One task input: its size and the values every entry may take.

    Attributes:
        size: the number of entries.
        lower, upper: the range of every entry (a NaN is never in it).
        switch: every entry must be exactly 0 or 1 (a switch; the range
            then stays unbounded, so that a value that is neither is
            told apart from one out of range: math.safety.check_vector).
    """

    size: int
    lower: float = -math.inf
    upper: float = math.inf
    switch: bool = False

    @property
    def allowed(self):
        """What an entry must do, as the end of a sentence ("must ...")."""
        if self.switch:
            return "be 0 or 1"
        if self.upper == math.inf:
            return f"be {self.lower:g} or greater"
        return f"lie in [{self.lower:g}, {self.upper:g}]"

    def check(self, name, value):
        """Returns the entry `value` (a float or an AutoDiffXd, as a port
        gives it) as it is after checking it.

        Raises:
            ValueError: naming `name`, the value and what is allowed.
        """
        if not (self.lower <= value <= self.upper
                and (not self.switch or value == 0.0 or value == 1.0)):
            raise ValueError(
                f"{name} = {float(value_of(value))!r} is not allowed: must "
                f"{self.allowed}")
        return value

    def check_number(self, name, value):
        """Returns the entry `value` (a parameter: one number) as a float
        after checking it.

        Raises:
            ValueError: naming `name`, the value and what is allowed.
        """
        return self.check(name, as_scalar(name, value))


MAX_REFERENCE = 1e3
"""m/s and rad/s: the largest magnitude of an entry of reference_velocity,
a thousand times what any mobile manipulator's end effector is meant to
do (the commands saturate far below it). The DMPs integrate the
reference in double precision, in which a value some 1e13 times their
working values absorbs them: a reference of 1e16 m/s for 50 ms left the
base driving at its full speed against a reference of 0.1 m/s seven
seconds later, with no input invalid. A larger entry is a fault of the
input (the InputGuard's safe stop)."""

TASK_INPUTS = {
    "reference_velocity": TaskInput(6, lower=-MAX_REFERENCE,
                                    upper=MAX_REFERENCE),
    "desired_wrench": TaskInput(6),
    "phri_switch": TaskInput(1, switch=True),
    "null_space_gain": TaskInput(1, lower=0.0),
    "compensation_switch": TaskInput(1, lower=0.0, upper=1.0),
}
"""The controller's task inputs by name, in the order of its input ports;
all but reference_velocity are optional (the stage's parameter is used
while the port is not connected)."""

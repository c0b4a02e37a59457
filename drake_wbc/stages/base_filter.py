"""BaseVelocityFilter: the base's low-pass filter, eq. (filtering), as a
Drake system (its math: drake_wbc.math.filtering)."""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.symbolic import Expression
from pydrake.systems.framework import Diagram_
from pydrake.systems.primitives import LinearSystem_

from drake_wbc.math.base_state import BASE_AXES
from drake_wbc.math.filtering import BaseFilterParameters, base_filter_model
from drake_wbc.math.validation import checked_instance
from drake_wbc.stages.support import build_composite, define_composite_stage

MODEL_NAME = "eq_filtering"
"""The name of the stage's LinearSystem inside it."""


@define_composite_stage("BaseVelocityFilter_",
                        scalars=(float, AutoDiffXd, Expression))
def BaseVelocityFilter_(T):
    class Impl(Diagram_[T]):
        """Second-order low-pass of eq. (filtering) on each base axis.

        ::

                            ┌────────────────────┐
            velocity ──────►│ BaseVelocityFilter ├──► filtered_velocity
                            └────────────────────┘

        - velocity: V_b' (3), the base's share after obstacle avoidance,
          [vx, vy, wz] in T_b.
        - filtered_velocity: V_b^flt (3), the base velocity command; it is
          C x of the filter's state (no direct feedthrough).

        With params.enabled False it is bypassed: the output is the input
        sampled at the last tick and held (x+ = [u, 0] per axis).

        Continuous (time_step = 0) or exactly discretised with a zero-order
        hold at the control period (time_step > 0, one periodic discrete
        update), so that Drake's `Linearize` applies either way. The state
        is [y, y_dot] per axis, axes stacked: [vx, vx_dot, vy, vy_dot, wz,
        wz_dot]; it starts at rest.

        The filter is linear, so the stage is Drake's C++ `LinearSystem`
        (named MODEL_NAME, in a Diagram that gives its ports the names
        above) of the matrices that drake_wbc.math.filtering's
        base_filter_model computes from eq. (filtering): no Python runs in
        its tick. The two are held equal by tests/test_base_filter.py (the
        update and output on random states and inputs against those
        matrices, in double, AutoDiffXd and symbolic) beside the closed
        forms of eq. (filtering) that its linearisation meets. Its
        scalar-converted copies are Drake's (stages.support.
        define_composite_stage): the same ports, period and matrices;
        `params` and `set_velocity` are this stage's.

        Args:
            params: BaseFilterParameters (checked where they were made);
                the paper's omega_f = 2 pi rad/s, zeta = 1 if None. Read
                here: changing them afterwards does not reach the stage.
            time_step: the control period h in s, default 0.01 (the
                paper's 100 Hz); 0 for the continuous filter. omega_f
                must stay below the Nyquist rate pi / h, and a bypassed
                filter needs h > 0 (filtering.check_filter_period).
        """

        def __init__(self, params=None, time_step=0.01):
            Diagram_[T].__init__(self)
            self.params = params = checked_instance(
                "params", params, BaseFilterParameters, BaseFilterParameters)
            A, B, C = base_filter_model(params, time_step, BASE_AXES)
            self._time_step = h = float(time_step)

            def build(builder):
                model = builder.AddNamedSystem(MODEL_NAME, LinearSystem_[T](
                    A, B, C, np.zeros((BASE_AXES, BASE_AXES)), h))
                builder.ExportInput(model.get_input_port(), "velocity")
                builder.ExportOutput(model.get_output_port(),
                                     "filtered_velocity")

            build_composite(self, T, build)

        def set_velocity(self, context, velocity):
            """Sets the filter at rest at `velocity` (3,): output equal to
            it and zero rate, e.g. to start from the base's measured
            velocity."""
            x = np.repeat(np.asarray(velocity), 2) * np.tile([1.0, 0.0],
                                                             BASE_AXES)
            if self._time_step > 0.0:
                context.SetDiscreteState(x)
            else:
                context.SetContinuousState(x)

    return Impl


BaseVelocityFilter = BaseVelocityFilter_[None]
"""BaseVelocityFilter_ for double; `ToAutoDiffXd()` gives Drake's
AutoDiffXd copy of it."""

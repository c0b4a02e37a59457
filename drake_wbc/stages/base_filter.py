"""BaseVelocityFilter: the base's low-pass filter, eq. (filtering), as a
Drake system (its math: drake_wbc.math.filtering)."""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.symbolic import Expression
from pydrake.systems.framework import LeafSystem_

from drake_wbc.math.filtering import (
    BaseFilterParameters,
    check_filter_period,
    lowpass_state_space,
    zero_order_hold,
)
from drake_wbc.math.validation import checked_instance
from drake_wbc.stages.support import define_stage

BASE_AXES = 3
"""The base's velocity components [vx, vy, wz] (T_b)."""


@define_stage("BaseVelocityFilter_",
              scalars=(float, AutoDiffXd, Expression))
def BaseVelocityFilter_(T):
    class Impl(LeafSystem_[T]):
        """Second-order low-pass of eq. (filtering) on each base axis.

        ::

                            ┌────────────────────┐
            velocity ──────►│ BaseVelocityFilter ├──► filtered_velocity
                            └────────────────────┘

        - velocity: V_b' (3), the base's share after obstacle avoidance,
          [vx, vy, wz] in T_b.
        - filtered_velocity: V_b^flt (3), the base velocity command; it is
          the filter's state (no direct feedthrough).

        With params.enabled False it is bypassed: the output is the input
        sampled at the last tick and held (x+ = [u, 0] per axis).

        Continuous (time_step = 0) or exactly discretised with a zero-order
        hold at the control period (time_step > 0, one periodic discrete
        update), so that Drake's `Linearize` applies either way. The state
        is [y, y_dot] per axis, axes stacked: [vx, vx_dot, vy, vy_dot, wz,
        wz_dot]; it starts at rest. Linear, with no branch on values: also
        symbolic (`ToSymbolic`).

        Args:
            params: BaseFilterParameters (checked where they were made);
                the paper's omega_f = 2 pi rad/s, zeta = 1 if None. Read
                here: changing them afterwards does not reach the stage.
            time_step: the control period h in s, default 0.01 (the
                paper's 100 Hz); 0 for the continuous filter. omega_f
                must stay below the Nyquist rate pi / h, and a bypassed
                filter needs h > 0 (filtering.check_filter_period).
        """

        def _construct(self, params=None, time_step=0.01, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.params = params = checked_instance(
                "params", params, BaseFilterParameters, BaseFilterParameters)
            self._time_step = h = check_filter_period(params, time_step)
            A, B, C, _ = lowpass_state_space(params.omega_f, params.zeta)
            eye = np.eye(BASE_AXES)
            self._A = np.kron(eye, A)
            self._B = np.kron(eye, B)
            self._C = np.kron(eye, C)
            self._input = self.DeclareVectorInputPort("velocity", BASE_AXES)
            n = 2 * BASE_AXES
            if not params.enabled:
                # Bypassed: x+ = [u, 0] per axis, y = u sampled and held.
                self._A = np.zeros_like(self._A)
                self._B = np.kron(eye, [[1.0], [0.0]])
            elif h > 0.0:
                self._A, self._B = zero_order_hold(self._A, self._B, h)
            if h > 0.0:
                state = self.discrete_state_ticket(
                    self.DeclareDiscreteState(n))
                self.DeclarePeriodicDiscreteUpdateEvent(h, 0.0,
                                                        self._update)
                self._get_state = self._discrete_state
            else:
                self.DeclareContinuousState(n)
                state = self.xc_ticket()
                self._get_state = self._continuous_state
            self.DeclareVectorOutputPort(
                "filtered_velocity", BASE_AXES, self._output,
                prerequisites_of_calc={state})

        @staticmethod
        def _discrete_state(context):
            return context.get_discrete_state_vector().CopyToVector()

        @staticmethod
        def _continuous_state(context):
            return context.get_continuous_state_vector().CopyToVector()

        def _update(self, context, discrete_state):
            x = self._discrete_state(context)
            u = self._input.Eval(context)
            discrete_state.set_value(self._A @ x + self._B @ u)

        def DoCalcTimeDerivatives(self, context, derivatives):
            x = self._continuous_state(context)
            u = self._input.Eval(context)
            derivatives.get_mutable_vector().SetFromVector(
                self._A @ x + self._B @ u
            )

        def _output(self, context, output):
            output.SetFromVector(self._C @ self._get_state(context))

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
"""BaseVelocityFilter_ for double; `ToAutoDiffXd()` gives the AutoDiff one."""

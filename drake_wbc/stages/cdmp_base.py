"""What the coupled DMP stages share (BaseCdmp and ArmCdmp in
drake_wbc.stages.cdmp_stages, WholeBodyCdmp in
drake_wbc.stages.whole_body_cdmp): the affine model of a stage and the
base class that runs it.

For a fixed pHRI switch S_hri, eqs. (cdmp-wb), (cdmp-wb-error),
(cdmp-base) and (cdmp-arm) are affine in their state and inputs (the
forcing term f(s) is zero, as in all of the paper's experiments, or a
learned one entering as an input computed from time, and the repulsive
force of the base enters as an input computed from the obstacle
points). Each stage therefore evaluates the math layer's derivative
function (drake_wbc.math.cdmp) once at construction to obtain

    x_dot = A x + B u + c,

checks that the function is indeed affine (AffineDynamics), and then
runs that model (CdmpStage): in continuous time (time_step = 0) or
exactly discretised with a zero-order hold at the control period
(time_step > 0; inputs held over each period). The update is then a few
small float matrix products per tick, and it is exact for double and
AutoDiffXd alike, so `Linearize` gives the paper's transfer functions.
The velocity output y_dot is the first block of x_dot; its direct
feedthrough is declared explicitly, so that feedback edges such as
delta_V_ee, which enters only the state, close no algebraic loop.

Each tick, for double and AutoDiffXd alike, a stage takes the rows of
y_dot over those of the update as one float matrix acting on [x; u; 1]
(`AffineDynamics.stacked`), and one cache entry holds their product,
which the output and the update share (the inputs are read once a tick).
"""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import ValueProducer

from drake_wbc.math.filtering import zero_order_hold
from drake_wbc.math.validation import non_negative
from drake_wbc.stages.support import optional_scalar

ONE = np.ones(1)
ONE.flags.writeable = False
"""The constant 1 that ends the [x; u; 1] of AffineDynamics.stacked."""


class AffineDynamics:
    """x_dot = A x + B u + c of an affine float function, and its exact
    zero-order-hold discretisation x+ = A_d x + B_d u + c_d.

    Args:
        derivative: f(x, u) -> x_dot, affine in (x, u).
        num_states, num_inputs: sizes of x and u.
        time_step: 0 for continuous time, else the hold period h.

    Raises:
        ValueError: if `derivative` is not affine (checked at a random
            point to 1e-9 relative).
    """

    def __init__(self, derivative, num_states, num_inputs, time_step):
        zero_x, zero_u = np.zeros(num_states), np.zeros(num_inputs)
        self.c = np.asarray(derivative(zero_x, zero_u), dtype=float)
        self.A = np.column_stack(
            [derivative(e, zero_u) - self.c for e in np.eye(num_states)]
        )
        self.B = np.column_stack(
            [derivative(zero_x, e) - self.c for e in np.eye(num_inputs)]
        )
        rng = np.random.default_rng(0)
        x, u = rng.normal(size=num_states), rng.normal(size=num_inputs)
        exact = derivative(x, u)
        model = self.A @ x + self.B @ u + self.c
        if not np.allclose(model, exact, rtol=1e-9, atol=1e-12):
            raise ValueError(
                "derivative is not affine in its state and inputs, which is "
                "not allowed for an AffineDynamics"
            )
        self.time_step = non_negative("time_step", time_step)
        if self.time_step > 0.0:
            augmented = np.column_stack([self.B, self.c])
            self.A_d, B_aug = zero_order_hold(self.A, augmented, time_step)
            self.B_d, self.c_d = B_aug[:, :-1], B_aug[:, -1]

    def derivative(self, x, u):
        """x_dot for state x and input u (any scalar type)."""
        return self.A @ x + self.B @ u + self.c

    def next_state(self, x, u):
        """The state one hold period later, u held constant."""
        return self.A_d @ x + self.B_d @ u + self.c_d

    def stacked(self, num_outputs, columns=None):
        """One float matrix acting on [x; u[columns]; 1] (the inputs left
        out count as 0; None: all): the first `num_outputs` rows of
        [A | B | c] (x_dot), over [A_d | B_d | c_d] when discrete."""
        columns = slice(None) if columns is None else columns
        rows = slice(0, num_outputs)
        blocks = [(self.A[rows], self.B[rows][:, columns], self.c[rows])]
        if self.time_step > 0.0:
            blocks.append((self.A_d, self.B_d[:, columns], self.c_d))
        return np.vstack([np.column_stack(block) for block in blocks])


class CdmpStage:
    """Shared mechanics of the three stages (a mixin of LeafSystem_[T]).

    A stage sets `_models` (AffineDynamics by key) and `_dimension`, and
    defines `_inputs(context)`, its whole input u (for the continuous
    derivatives), and `_stacked_vector(context)`, the [x; u[columns]; 1]
    of its models' `stacked` matrices (`_declare_output`); it may replace
    `_calc_result`, `_output` and `_update` (WholeBodyCdmp does).
    """

    def _declare_state(self, num_states, time_step):
        self._time_step = non_negative("time_step", time_step)
        if self._time_step > 0.0:
            index = self.DeclareDiscreteState(num_states)
            self.DeclarePeriodicDiscreteUpdateEvent(
                self._time_step, 0.0, self._update)
            return self.discrete_state_ticket(index)
        self.DeclareContinuousState(num_states)
        return self.xc_ticket()

    def _state(self, context):
        """The state x."""
        if self._time_step <= 0.0:
            return context.get_continuous_state_vector().CopyToVector()
        return context.get_discrete_state_vector().CopyToVector()

    def _switch(self, context):
        """S_hri from its input port (a value >= 0.5 means 1) or the
        stage's default (its constructor's phri_switch)."""
        value = optional_scalar(self._phri_port, context, None)
        if value is None:
            return int(self._default_switch)
        return 1 if value >= 0.5 else 0

    def _model_key(self, context):
        """The key of the affine model in force (by S_hri)."""
        return self._switch(context)

    def DoCalcTimeDerivatives(self, context, derivatives):
        model = self._models[self._model_key(context)]
        derivatives.get_mutable_vector().SetFromVector(
            model.derivative(self._state(context), self._inputs(context)))

    def _declare_output(self, name, prerequisites, output_columns=None):
        """The output y_dot, computed from `prerequisites` alone: per
        model, the rows of y_dot over those of the discrete update (if
        any), on [x; u[output_columns]; 1], and the cache entry of their
        product, which the output and the update share."""
        self._stacked = {
            key: model.stacked(self._dimension, output_columns)
            for key, model in self._models.items()
        }
        self._result = self.DeclareCacheEntry(
            "y_dot and the next state", ValueProducer(
                allocate=lambda: AbstractValue.Make(np.zeros(0)),
                calc=self._calc_result),
            prerequisites)
        self.DeclareVectorOutputPort(name, self._dimension, self._output,
                                     prerequisites_of_calc=prerequisites)

    def _calc_result(self, context, value):
        value.set_value(self._stacked[self._model_key(context)].dot(
            self._stacked_vector(context)))

    def _output(self, context, output):
        output.set_value(self._result.Eval(context)[:self._dimension])

    def _update(self, context, discrete_state):
        discrete_state.set_value(
            self._result.Eval(context)[self._dimension:])

    def _check_state_only(self, columns):
        """Checks that the inputs u[columns] do not reach y_dot."""
        for model in self._models.values():
            if np.any(model.B[: self._dimension, columns] != 0.0):
                raise RuntimeError(
                    "an input declared state-only reaches the output")

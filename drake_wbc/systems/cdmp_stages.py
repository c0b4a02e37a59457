"""The coupled DMPs of the base and the arm as Drake systems, and the
mechanics they share with the whole body's (WholeBodyCdmp, in
drake_wbc.systems.whole_body_cdmp, also importable from here).

For a fixed pHRI switch S_hri, eqs. (cdmp-wb), (cdmp-wb-error),
(cdmp-base) and (cdmp-arm) are affine in their state and inputs (the
forcing term f(s) is zero, as in all of the paper's experiments, or a
learned one entering as an input computed from time, and the repulsive
force of the base enters as an input computed from the obstacle
points). Each stage therefore evaluates the math layer's derivative
function (drake_wbc.cdmp) once at construction to obtain

    x_dot = A x + B u + c,

checks that the function is indeed affine, and then runs that model: in
continuous time (time_step = 0) or exactly discretised with a zero-order
hold at the control period (time_step > 0; inputs held over each period).
The update is then a few small float matrix products per tick, and it is
exact for double and AutoDiffXd alike, so `Linearize` gives the paper's
transfer functions. The velocity output y_dot is the first block of
x_dot; its direct feedthrough is declared explicitly, so that feedback
edges such as delta_V_ee, which enters only the state, close no algebraic
loop.

In double the stages take a fast path, chosen at construction: the rows
of y_dot over those of the update as one matrix acting on [x; u; 1]
(`AffineDynamics.stacked`), and one cache entry of their product that
the output and the update share (the inputs are read once a tick): the
same model, to round-off. AutoDiffXd and the continuous derivatives keep
the general path, which the fast one is tested against.
"""

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem_, ValueProducer
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_wbc import cdmp, repulsion
from drake_wbc.filtering import zero_order_hold
from drake_wbc.validation import non_negative, validated_copy

SCALARS = [float, AutoDiffXd]
"""Double, and AutoDiffXd for Linearize; not symbolic (the stage branches
on values)."""


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


_ONE = np.ones(1)
_ONE.flags.writeable = False


class _CdmpStage:
    """Shared mechanics of the three stages (a mixin of LeafSystem_[T]).

    A stage sets `_fast` (True in double) before `_declare_state`, and
    with it defines `_fast_vector(context)`, the float [x; u; 1] of its
    models' `stacked` matrices (`_declare_output`).
    """

    def _declare_state(self, num_states, time_step):
        self._time_step = non_negative("time_step", time_step)
        if self._time_step > 0.0:
            index = self.DeclareDiscreteState(num_states)
            self.DeclarePeriodicDiscreteUpdateEvent(
                self._time_step, 0.0,
                self._fast_update if self._fast else self._update
            )
            return self.discrete_state_ticket(index)
        self.DeclareContinuousState(num_states)
        return self.xc_ticket()

    def _state(self, context):
        """The state x; in double a read-only view when discrete."""
        if self._time_step <= 0.0:
            return context.get_continuous_state_vector().CopyToVector()
        vector = context.get_discrete_state_vector()
        return vector.value() if self._fast else vector.CopyToVector()

    def _optional(self, port, context, default):
        if port.HasValue(context):
            return port.Eval(context)
        return default

    def _switch(self, context):
        """S_hri from its input port (a value >= 0.5 means 1) or the
        parameter."""
        value = self._optional(self._phri_port, context, None)
        if value is None:
            return int(self._default_switch)
        return 1 if value[0] >= 0.5 else 0

    def _model(self, context, for_update=False):
        """The affine model in force (by S_hri); `for_update`: for the
        discrete update over the period that starts at the context's
        time."""
        return self._models[self._switch(context)]

    def _update(self, context, discrete_state):
        model = self._model(context, for_update=True)
        discrete_state.set_value(
            model.next_state(self._state(context),
                             self._drive(context, for_update=True))
        )

    def DoCalcTimeDerivatives(self, context, derivatives):
        model = self._model(context)
        derivatives.get_mutable_vector().SetFromVector(
            model.derivative(self._state(context), self._drive(context))
        )

    def _velocity(self, context):
        """y_dot: the first block of x_dot. Inputs that enter the state
        alone (see `_check_state_only`) are not evaluated, so that a
        feedback edge into them closes no loop."""
        model = self._model(context)
        x_dot = model.derivative(self._state(context),
                                 self._drive(context, for_output=True))
        return x_dot[: self._dimension]

    def _output(self, context, output):
        output.SetFromVector(self._velocity(context))

    def _declare_output(self, name, prerequisites, output_columns=None):
        """The output y_dot, computed from `prerequisites` alone. In
        double also, per model, the rows of y_dot over those of the
        discrete update (if any), on [x; u[output_columns]; 1], and the
        cache entry of their product, which the output and the update
        share (the inputs are read once a tick)."""
        if self._fast:
            self._fast_models = {
                key: model.stacked(self._dimension, output_columns)
                for key, model in self._models.items()
            }
            self._fast_result = self.DeclareCacheEntry(
                "y_dot and the next state", ValueProducer(
                    allocate=lambda: AbstractValue.Make(np.zeros(0)),
                    calc=self._calc_fast_result),
                prerequisites)
        self.DeclareVectorOutputPort(
            name, self._dimension,
            self._fast_output if self._fast else self._output,
            prerequisites_of_calc=prerequisites)

    def _calc_fast_result(self, context, value):
        value.set_value(self._fast_models[self._switch(context)].dot(
            self._fast_vector(context)))

    def _fast_output(self, context, output):
        output.set_value(self._fast_result.Eval(context)[:self._dimension])

    def _fast_update(self, context, discrete_state):
        discrete_state.set_value(
            self._fast_result.Eval(context)[self._dimension:])

    def _check_state_only(self, columns):
        """Checks that the inputs u[columns] do not reach y_dot."""
        for model in self._models.values():
            if np.any(model.B[: self._dimension, columns] != 0.0):
                raise RuntimeError(
                    "an input declared state-only reaches the output")


@TemplateSystem.define("BaseCdmp_", T_list=SCALARS)
def BaseCdmp_(T):
    class Impl(_CdmpStage, LeafSystem_[T]):
        """CDMP of the base with obstacle avoidance, eq. (cdmp-base).

        ::

                             ┌──────────┐
            base_velocity ──►│          │
            obstacle_points ►│ BaseCdmp ├──► avoiding_base_velocity
                             └──────────┘

        - base_velocity: V_b (3) from the distributor, [vx, vy, wz], T_b.
        - obstacle_points: an (M, 2) float array of obstacle points in T_b
          (abstract-valued; optional, none when unconnected). The
          repulsive force f_avoid, the gradient of U_rep around the
          footprint (repulsion.repulsive_force), is computed once per new set
          of points (a cache entry that the output and the update share)
          and held over the period.
        - avoiding_base_velocity: V_b' (3), y_dot, for the base filter.

        State [y, z, C] (9) in T_b coordinates, goal g = 0: once the
        obstacle is gone the base returns onto its commanded path.

        Args:
            params: cdmp.BaseCdmpParameters (paper values if None).
            time_step: control period h (0: continuous), default 0.01 s.
        """

        def _construct(self, params=None, time_step=0.01, converter=None):
            LeafSystem_[T].__init__(self, converter)
            params = validated_copy(cdmp.BaseCdmpParameters()
                                    if params is None else params)
            self.params, self._dimension = params, 3
            self._default_switch = 0
            no_points = np.zeros((0, 2))

            def derivative(x, u):
                # f_avoid enters tau z_dot exactly as the forcing term does.
                y, z, C = np.split(x, 3)
                return np.concatenate(cdmp.base_cdmp_derivative(
                    y, z, C, np.zeros(3), u[:3], no_points, params,
                    forcing=u[3:]))

            model = AffineDynamics(derivative, 9, 6, time_step)
            self._models = {0: model, 1: model}
            self._fast = T is float
            self._float_force = repulsion.LastPoints(
                lambda points: np.append(repulsion.repulsive_force(
                    points, params.repulsion), 0.0))
            self._velocity_in = self.DeclareVectorInputPort(
                "base_velocity", 3)
            self._points = self.DeclareAbstractInputPort(
                "obstacle_points", AbstractValue.Make(no_points))
            self._phri_port = None
            self._force = self.DeclareCacheEntry(
                "repulsive force f_avoid",
                ValueProducer(
                    allocate=lambda: AbstractValue.Make(np.zeros(3)),
                    calc=lambda context, value: value.set_value(
                        self._calc_repulsive_force(context))),
                {self.input_port_ticket(self._points.get_index())})
            state = self._declare_state(9, time_step)
            prerequisites = {
                state,
                self.input_port_ticket(self._velocity_in.get_index()),
                self.input_port_ticket(self._points.get_index()),
            }
            self._declare_output("avoiding_base_velocity", prerequisites)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.params, other._time_step,
                            converter=converter)
            self.params = other.params

        def _switch(self, context):
            return 0

        def repulsive_force(self, context):
            """f_avoid (3,) from the obstacle points (no yaw part), from a
            cache entry that depends on the points alone: computed once
            per new set of points, shared by the output and the update."""
            return np.array(self._force.Eval(context))

        def _calc_repulsive_force(self, context):
            points = (self._points.Eval(context)
                      if self._points.HasValue(context)
                      else np.zeros((0, 2)))
            if T is float and points.dtype == np.float64:
                return self._float_force(points)
            force = repulsion.repulsive_force(points, self.params.repulsion)
            return np.array([force[0], force[1], 0.0])

        def _drive(self, context, for_output=False, for_update=False):
            return np.concatenate([self._velocity_in.Eval(context),
                                   self.repulsive_force(context)])

        def _fast_vector(self, context):
            # The cached force is only read here: no copy.
            return np.concatenate((
                self._state(context), self._velocity_in.Eval(context),
                self._force.Eval(context), _ONE))

    return Impl


@TemplateSystem.define("ArmCdmp_", T_list=SCALARS)
def ArmCdmp_(T):
    class Impl(_CdmpStage, LeafSystem_[T]):
        """CDMP of the arm: hybrid stiffness/force control, eq. (cdmp-arm).

        ::

                            ┌─────────┐
            arm_velocity ──►│         │
            wrench ────────►│         │
            desired_wrench ►│ ArmCdmp ├──► arm_velocity_command
            phri_switch ───►│         │
                            └─────────┘

        - arm_velocity: V_a^ref (6) from the compensator, T_a, [v; w].
        - wrench: F_ext (6), the wrench on the tool, T_a.
        - desired_wrench: F_d (6), optional (the parameter when
          unconnected).
        - phri_switch: S_hri (1), optional; 1 turns the force control off.
        - arm_velocity_command: y_dot (6), the arm's Cartesian velocity.

        Along axes with S_m = 1 the arm yields to F_ext like a spring
        (stiffness-coupled, eq. (lp-admit)); along S_m = 0 it drives
        F_ext to F_d (admittance-coupled, eq. (tf-admit)); see drake_wbc.cdmp
        for the force convention and the sign of the force term. State
        [y, z~, C_a] (18), T_a, goal g = 0.

        Args:
            params: cdmp.ArmCdmpParameters (the paper's wiping values if
                None).
            time_step: control period h (0: continuous), default 0.01 s.
        """

        def _construct(self, params=None, time_step=0.01, converter=None):
            LeafSystem_[T].__init__(self, converter)
            params = validated_copy(cdmp.ArmCdmpParameters()
                                    if params is None else params)
            self.params, self._dimension = params, 6
            self._default_switch = params.S_hri
            base = dict(k_p=params.k_p, k_d=params.k_d, k_f=params.k_f,
                        S_m=params.S_m, dmp=params.dmp)

            def derivative(switch):
                def f(x, u):
                    y, z, C_a = np.split(x, 3)
                    with_goal_force = cdmp.ArmCdmpParameters(
                        **base, F_d=u[12:], S_hri=switch)
                    return np.concatenate(cdmp.arm_cdmp_derivative(
                        y, z, C_a, np.zeros(6), u[:6], u[6:12],
                        with_goal_force))
                return f

            self._models = {
                s: AffineDynamics(derivative(s), 18, 18, time_step)
                for s in (0, 1)
            }
            self._fast = T is float
            self._velocity_in = self.DeclareVectorInputPort(
                "arm_velocity", 6)
            self._wrench = self.DeclareVectorInputPort("wrench", 6)
            self._desired = self.DeclareVectorInputPort("desired_wrench", 6)
            self._phri_port = self.DeclareVectorInputPort("phri_switch", 1)
            state = self._declare_state(18, time_step)
            prerequisites = {
                state,
                *(self.input_port_ticket(p.get_index())
                  for p in (self._velocity_in, self._wrench,
                            self._desired, self._phri_port)),
            }
            self._declare_output("arm_velocity_command", prerequisites)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.params, other._time_step,
                            converter=converter)
            self.params = other.params

        def _drive(self, context, for_output=False, for_update=False):
            return np.concatenate([
                self._velocity_in.Eval(context),
                self._wrench.Eval(context),
                self._optional(self._desired, context, self.params.F_d),
            ])

        def _fast_vector(self, context):
            desired = self._desired
            return np.concatenate((
                self._state(context), self._velocity_in.Eval(context),
                self._wrench.Eval(context),
                desired.Eval(context) if desired.HasValue(context)
                else self.params.F_d, _ONE))

    return Impl


BaseCdmp = BaseCdmp_[None]
ArmCdmp = ArmCdmp_[None]


def __getattr__(name):
    """WholeBodyCdmp and WholeBodyCdmp_ live in
    drake_wbc.systems.whole_body_cdmp; they are found here too."""
    if name in ("WholeBodyCdmp", "WholeBodyCdmp_"):
        from drake_wbc.systems import whole_body_cdmp

        return getattr(whole_body_cdmp, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

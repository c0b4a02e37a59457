"""The coupled DMPs of the base and the arm as Drake systems: BaseCdmp,
eq. (cdmp-base), with the repulsive field's obstacle avoidance, and
ArmCdmp, eq. (cdmp-arm), with hybrid stiffness/force control. Both
take their affine model from drake_wbc.stages.cdmp_base.AffineDynamics:
BaseCdmp runs it in Python (CdmpStage), ArmCdmp as Drake's C++
AffineSystem (its one switch, S_hri, moved onto an input); the
whole body's WholeBodyCdmp, eqs. (cdmp-wb) and (cdmp-wb-error), is in
drake_wbc.stages.whole_body_cdmp.
"""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import Diagram_, LeafSystem_, ValueProducer
from pydrake.systems.primitives import AffineSystem_, Multiplexer_

from drake_wbc.math import cdmp, repulsion
from drake_wbc.math.gating import stop_switched
from drake_wbc.math.kernels import body_for
from drake_wbc.math.validation import checked_instance, switch
from drake_wbc.stages.cdmp_base import ONE, AffineDynamics, CdmpStage
from drake_wbc.stages.support import (
    build_composite,
    define_composite_stage,
    define_stage,
)

MODEL_NAME = "eq_cdmp_arm"
"""The name of ArmCdmp's AffineSystem inside it."""


@define_stage("BaseCdmp_")
def BaseCdmp_(T):
    class Impl(CdmpStage, LeafSystem_[T]):
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
          footprint (repulsion.repulsive_force, its float kernel in
          double), is computed once per new set of points (a cache entry
          that the output and the update share, and
          repulsion.LastPoints) and held over the period.
        - avoiding_base_velocity: V_b' (3), y_dot, for the base filter.

        State [y, z, C] (9) in T_b coordinates, goal g = 0: once the
        obstacle is gone the base returns onto its commanded path.

        Args:
            params: cdmp.BaseCdmpParameters (checked where they were
                made; paper values if None), read here.
            time_step: control period h (0: continuous), default 0.01 s.
        """

        def _construct(self, params=None, time_step=0.01, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.params = params = checked_instance(
                "params", params, cdmp.BaseCdmpParameters,
                cdmp.BaseCdmpParameters)
            self._dimension = 3
            no_points = np.zeros((0, 2))

            def derivative(x, u):
                # f_avoid enters tau z_dot exactly as the forcing term does.
                y, z, C = np.split(x, 3)
                return np.concatenate(cdmp.base_cdmp_derivative(
                    y, z, C, np.zeros(3), u[:3], no_points, params,
                    forcing=u[3:]))

            model = AffineDynamics(derivative, 9, 6, time_step)
            self._models = {0: model}
            force = body_for(repulsion.repulsive_force, T)
            field = params.repulsion

            def force_with_no_yaw(points):
                f_x, f_y = force(points, field)
                return np.array((f_x, f_y, 0.0))

            self._force_of = repulsion.LastPoints(force_with_no_yaw)
            self._velocity_in = self.DeclareVectorInputPort(
                "base_velocity", 3)
            self._points = self.DeclareAbstractInputPort(
                "obstacle_points", AbstractValue.Make(no_points))
            self._force = self.DeclareCacheEntry(
                "repulsive force f_avoid",
                ValueProducer(
                    allocate=lambda: AbstractValue.Make(np.zeros(3)),
                    calc=lambda context, value: value.set_value(
                        self._force_of(self._optional(
                            self._points, context, no_points)))),
                {self.input_port_ticket(self._points.get_index())})
            state = self._declare_state(9, time_step)
            prerequisites = {
                state,
                self.input_port_ticket(self._velocity_in.get_index()),
                self.input_port_ticket(self._points.get_index()),
            }
            self._declare_output("avoiding_base_velocity", prerequisites)

        def _model_key(self, context):
            return 0

        def repulsive_force(self, context):
            """f_avoid (3,) from the obstacle points (no yaw part), from a
            cache entry that depends on the points alone: computed once
            per new set of points, shared by the output and the update."""
            return np.array(self._force.Eval(context))

        def _inputs(self, context):
            return np.concatenate([self._velocity_in.Eval(context),
                                   self._force.Eval(context)])

        def _stacked_vector(self, context):
            # The cached force is only read here: no copy.
            return np.concatenate((
                self._state(context), self._velocity_in.Eval(context),
                self._force.Eval(context), ONE))

    return Impl


@define_stage("ForceErrorSwitch_")
def ForceErrorSwitch_(T):
    class Impl(LeafSystem_[T]):
        """The force error of eq. (cdmp-arm)'s force term, switched by
        S_hri: e = (1 - S_hri)(F_ext - F_d) for S_hri 0 or 1
        (math.gating.stop_switched(F_ext - F_d, S_hri): S_hri >= 0.5
        counts as 1), the one part of ArmCdmp that is not affine, with
        its optional inputs.

        ::

                            ┌──────────────────┐
            wrench ────────►│                  │
            desired_wrench ►│ ForceErrorSwitch ├──► force_error
            phri_switch ───►│                  │
                            └──────────────────┘

        - wrench: F_ext (6); desired_wrench: F_d (6), optional (the
          parameter when unconnected); phri_switch: S_hri (1), optional
          (the default when unconnected).

        Args:
            desired_wrench: F_d (6,) while the port is unconnected.
            phri_switch: S_hri, 0 or 1, while the port is unconnected.
        """

        def _construct(self, desired_wrench, phri_switch, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._default_desired = np.asarray(desired_wrench, float)
            self._default_switch = np.array([float(phri_switch)])
            self._switched = body_for(stop_switched, T)
            self._wrench = self.DeclareVectorInputPort("wrench", 6)
            self._desired = self.DeclareVectorInputPort("desired_wrench", 6)
            self._phri_port = self.DeclareVectorInputPort("phri_switch", 1)
            self.DeclareVectorOutputPort("force_error", 6, self._output)

        @staticmethod
        def _optional(port, context, default):
            # Connected in the controller: one Eval (HasValue would
            # evaluate the source as well), the default when it fails
            # for want of a value.
            try:
                return port.Eval(context)
            except RuntimeError:
                if port.HasValue(context):
                    raise
                return default

        def _output(self, context, output):
            error = self._wrench.Eval(context) - self._optional(
                self._desired, context, self._default_desired)
            switch = self._optional(self._phri_port, context,
                                    self._default_switch)[0]
            output.SetFromVector(self._switched(error, switch))

    return Impl


def arm_cdmp_model(params, time_step):
    """Eq. (cdmp-arm) as one affine model, from its reference body
    (math.cdmp.arm_cdmp_derivative): state x = [y, z~, C_a] (18), input
    u = [V_a; F_ext; e] (18) with e = (1 - S_hri)(F_ext - F_d) the force
    error of the force term (ForceErrorSwitch), which is then the
    derivative at S_hri = 0 with F_d = F_ext - e. Affine in (x, u) for
    every S_hri (AffineDynamics checks it); exactly discretised at
    `time_step` > 0."""
    base = dict(k_p=params.k_p, k_d=params.k_d, k_f=params.k_f,
                S_m=params.S_m, dmp=params.dmp)

    def derivative(x, u):
        y, z, C_a = np.split(x, 3)
        V_a, F_ext, error = np.split(u, 3)
        with_error = cdmp.ArmCdmpParameters(**base, F_d=F_ext - error)
        return np.concatenate(cdmp.arm_cdmp_derivative(
            y, z, C_a, np.zeros(6), V_a, F_ext, with_error, S_hri=0.0))

    return AffineDynamics(derivative, 18, 18, time_step)


@define_composite_stage("ArmCdmp_")
def ArmCdmp_(T):
    class Impl(Diagram_[T]):
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
        - phri_switch: S_hri (1), optional (the constructor's
          phri_switch when unconnected; >= 0.5 counts as 1); 1 turns the
          force control off.
        - arm_velocity_command: y_dot (6), the arm's Cartesian velocity.

        Along axes with S_m = 1 the arm yields to F_ext like a spring
        (stiffness-coupled, eq. (lp-admit)); along S_m = 0 it drives
        F_ext to F_d (admittance-coupled, eq. (tf-admit)); see
        drake_wbc.math.cdmp
        for the force convention and the sign of the force term. State
        [y, z~, C_a] (18), T_a, goal g = 0.

        Eq. (cdmp-arm) is affine but for S_hri, which only switches the
        force error e = (1 - S_hri)(F_ext - F_d) of its force term; so
        the stage is Drake's C++ AffineSystem (named MODEL_NAME) of
        arm_cdmp_model, the equation's matrices computed from its
        reference body, on [V_a; F_ext; e] (a Multiplexer), with e from
        a small ForceErrorSwitch, which also holds the optional inputs'
        defaults. The output y_dot is the first block of the model's
        x_dot (C, D, y0 of the AffineSystem); the update its exact
        zero-order hold. tests/test_cdmp_stages.py holds the stage to
        arm_cdmp_derivative itself, for both S_hri, in double and
        AutoDiffXd. Its scalar-converted copies are Drake's
        (stages.support.define_composite_stage): the same ports, period
        and matrices.

        Args:
            params: cdmp.ArmCdmpParameters (checked where they were made;
                the paper's wiping values if None), read here.
            time_step: control period h (0: continuous), default 0.01 s.
            phri_switch: the default S_hri, 0 or 1, while the phri_switch
                port is not connected; default 0.
        """

        def __init__(self, params=None, time_step=0.01, phri_switch=0.0):
            Diagram_[T].__init__(self)
            self.params = params = checked_instance(
                "params", params, cdmp.ArmCdmpParameters,
                cdmp.ArmCdmpParameters)
            self._default_switch = switch("phri_switch", phri_switch)
            self.model = model = arm_cdmp_model(params, time_step)
            self._time_step = h = model.time_step
            A, B, c = ((model.A_d, model.B_d, model.c_d) if h > 0.0
                       else (model.A, model.B, model.c))

            def build(builder):
                error = builder.AddNamedSystem(
                    "force_error", ForceErrorSwitch_[T](
                        params.F_d, self._default_switch))
                join = builder.AddNamedSystem(
                    "inputs", Multiplexer_[T]([6, 6, 6]))
                affine = builder.AddNamedSystem(MODEL_NAME, AffineSystem_[T](
                    A, B, c, model.A[:6], model.B[:6], model.c[:6], h))
                builder.ExportInput(join.get_input_port(0), "arm_velocity")
                wrench = builder.ExportInput(join.get_input_port(1),
                                             "wrench")
                builder.ConnectInput(wrench, error.GetInputPort("wrench"))
                for name in ("desired_wrench", "phri_switch"):
                    builder.ExportInput(error.GetInputPort(name), name)
                builder.Connect(error.get_output_port(),
                                join.get_input_port(2))
                builder.Connect(join.get_output_port(),
                                affine.get_input_port())
                builder.ExportOutput(affine.get_output_port(),
                                     "arm_velocity_command")

            build_composite(self, T, build)

    return Impl


BaseCdmp = BaseCdmp_[None]
ArmCdmp = ArmCdmp_[None]

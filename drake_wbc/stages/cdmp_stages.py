"""The coupled DMPs of the base and the arm as Drake systems: BaseCdmp,
eq. (cdmp-base), with the repulsive field's obstacle avoidance, and
ArmCdmp, eq. (cdmp-arm), with hybrid stiffness/force control. Both run
their affine model through drake_wbc.stages.cdmp_base.CdmpStage; the
whole body's WholeBodyCdmp, eqs. (cdmp-wb) and (cdmp-wb-error), is in
drake_wbc.stages.whole_body_cdmp.
"""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem_, ValueProducer

from drake_wbc.math import cdmp, repulsion
from drake_wbc.math.dmp import check_sampled
from drake_wbc.math.kernels import body_for
from drake_wbc.math.task_inputs import TASK_INPUTS
from drake_wbc.math.validation import (
    checked_instance,
    non_negative,
    robots_own,
)
from drake_wbc.stages.cdmp_base import ONE, AffineDynamics, CdmpStage
from drake_wbc.stages.support import define_stage, optional_input


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
                made), read here, with repulsion.half_sizes (the
                footprint) given: its default None stands for the
                robot's own, which build_controller fills in, and is
                refused here (ValueError), as is params None (the
                defaults).
            time_step: control period h (0: continuous), default 0.01 s.
        """

        def _construct(self, params=None, time_step=0.01, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.params = params = checked_instance(
                "params", params, cdmp.BaseCdmpParameters,
                cdmp.BaseCdmpParameters)
            robots_own("params.repulsion.half_sizes",
                       params.repulsion.half_sizes)
            check_sampled(params.dmp, non_negative("time_step", time_step),
                          "params.dmp")
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
                        self._force_of(optional_input(
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


@define_stage("ArmCdmp_")
def ArmCdmp_(T):
    class Impl(CdmpStage, LeafSystem_[T]):
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

        Args:
            params: cdmp.ArmCdmpParameters (checked where they were made;
                the paper's wiping values if None), read here.
            time_step: control period h (0: continuous), default 0.01 s.
            phri_switch: the default S_hri, 0 or 1, while the phri_switch
                port is not connected; default 0.
        """

        def _construct(self, params=None, time_step=0.01, phri_switch=0.0,
                       converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.params = params = checked_instance(
                "params", params, cdmp.ArmCdmpParameters,
                cdmp.ArmCdmpParameters)
            check_sampled(params.dmp, non_negative("time_step", time_step),
                          "params.dmp")
            self._dimension = 6
            self._default_switch = TASK_INPUTS["phri_switch"].check_number(
                "phri_switch", phri_switch)
            self._default_desired = params.F_d
            base = dict(k_p=params.k_p, k_d=params.k_d, k_f=params.k_f,
                        S_m=params.S_m, dmp=params.dmp)

            def derivative(s):
                def f(x, u):
                    y, z, C_a = np.split(x, 3)
                    with_goal_force = cdmp.ArmCdmpParameters(
                        **base, F_d=u[12:])
                    return np.concatenate(cdmp.arm_cdmp_derivative(
                        y, z, C_a, np.zeros(6), u[:6], u[6:12],
                        with_goal_force, S_hri=s))
                return f

            self._models = {
                s: AffineDynamics(derivative(s), 18, 18, time_step)
                for s in (0, 1)
            }
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

        def _inputs(self, context):
            return np.concatenate([
                self._velocity_in.Eval(context),
                self._wrench.Eval(context),
                optional_input(self._desired, context,
                               self._default_desired),
            ])

        def _stacked_vector(self, context):
            return np.concatenate((
                self._state(context), self._velocity_in.Eval(context),
                self._wrench.Eval(context),
                optional_input(self._desired, context,
                               self._default_desired), ONE))

    return Impl


BaseCdmp = BaseCdmp_[None]
ArmCdmp = ArmCdmp_[None]

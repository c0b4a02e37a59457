"""ArmCapability and WorkspaceAdapter: what the arm's configuration tells
the coordination stages (stages/coordination.py) once a tick, C_m, its
gradient and alpha (Sec. IV-A), and the weighting factors of the motion
modes (Sec. IV-C). Their parameters and math are in
drake_wbc.math.capability and drake_wbc.math.workspace; how the stages
declare their ports and cache: stages/support.py."""

import math

import numpy as np
from pydrake.systems.framework import LeafSystem_

from drake_wbc.math import capability, motion_mode, workspace
from drake_wbc.math.capability import (
    ArmCapabilityParameters,
)
from drake_wbc.math.kernels import body_for
from drake_wbc.math.motion_mode import MotionMode
from drake_wbc.math.scalar_support import all_finite, through_float_function
from drake_wbc.math.validation import checked_instance, positive
from drake_wbc.math.workspace import WorkspaceAdapterParameters
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages.support import (
    arm_mounting,
    band_of,
    declare_cached_vector,
    declare_inputs,
    declare_slices,
    define_stage,
    shared_arm_kinematics,
    tickets,
)

_CAPABILITY_OUTPUTS = (
    ("end_effector_position", slice(0, 3)),
    ("capability", slice(3, 4)),
    ("capability_gradient", slice(4, 10)),
    ("alpha", slice(10, 11)),
)


@define_stage("ArmCapability_")
def ArmCapability_(T):
    class Impl(LeafSystem_[T]):
        """What several stages need from the arm's configuration, once a
        tick: the end effector's position, C_m (Sec. IV-A), its Cartesian
        gradient and alpha of eq. (transition).

        ::

                           ┌───────────────┐
                           │               ├──► end_effector_position
            arm_position ─►│ ArmCapability ├──► capability
                           │               ├──► capability_gradient
                           │               ├──► alpha
                           └───────────────┘

        - arm_position: q_a (n), the measured joint angles (rad).
        - end_effector_position: p_ee (3) in T_b (m), for J_b of eq. (2).
        - capability: C_m = m P_jnt (1), the capability of movement.
        - capability_gradient: grad_x C_m (6) w.r.t. the arm's Cartesian
          pose, ordered and expressed like V_a ([linear; angular], T_a),
          as eqs. (wbccm) and (wb_error) use it.
        - alpha: alpha(C_m, C_m^u, C_m^l) (1) of eq. (transition).

        The arm's kinematics (J_a, p_ee) and C_m are evaluated once per
        context, in a cache entry that every output reads; all outputs
        depend on arm_position only (direct feedthrough, stateless). A
        joint angle that is not finite makes every output NaN (the arm is
        nowhere known: what the chain kinematics and the kernels give
        there), for both scalar types; nothing raises.

        The kinematics need a double MultibodyPlant, so the evaluation
        (`evaluate`) is in floats, with the float kernels of
        capability.capability_terms and
        capability.transition_of; for AutoDiffXd it goes through
        scalar_support.through_float_function: the values are exact and
        the derivatives w.r.t. q_a come from central differences (about
        1e-9 relative).

        Args:
            params: ArmCapabilityParameters (read here, when the stage is
                built); the defaults of drake_wbc.math.capability if None.
            arm: the ArmKinematics to use; a new ArmKinematics() of our
                robot if None.
            band: the CapabilityBand C_m^l, C_m^u of alpha (read here);
                the arm's robot's (its description's tuning) if None.
        """

        def _construct(self, params=None, arm=None, band=None,
                       converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.params = checked_instance(
                "params", params, ArmCapabilityParameters,
                ArmCapabilityParameters)
            self.arm = checked_instance("arm", arm, ArmKinematics,
                                        ArmKinematics)
            self.band = band_of(band, self.arm)
            # What the tick needs, as plain floats (see evaluate).
            p = self.params
            self._limits = (np.ascontiguousarray(self.arm.lower, float),
                            np.ascontiguousarray(self.arm.upper, float))
            k_j = (self.arm.model.description.tuning.joint_limit_gain
                   if p.joint_limit_gain is None else p.joint_limit_gain)
            self._constants = (k_j, p.gradient_damping,
                               p.gradient_damping_threshold)
            self._band = (self.band.upper, self.band.lower)
            self._terms = body_for(capability.capability_terms,
                                   float)
            self._alpha = body_for(capability.transition_of, float)
            self._input = self.DeclareVectorInputPort(
                "arm_position", self.arm.num_joints)
            entry = declare_cached_vector(
                self, "arm kinematics and capability", self._calc,
                {self._input.ticket()})
            declare_slices(self, entry, _CAPABILITY_OUTPUTS)

        def evaluate(self, q_a):
            """[p_ee (3), C_m, grad_x C_m (6), alpha] at float q_a (n,);
            all NaN if an entry of q_a is not finite.

            One evaluation of the kinematics and one SVD of J_a; q_a's
            shape is checked by ArmKinematics.evaluate.
            """
            q = np.ascontiguousarray(q_a, dtype=float)
            if not all_finite(q):
                return np.full(11, math.nan)
            values = self.arm.evaluate(q_a)
            C_m, gradient = self._terms(values.J_a, q, *self._limits,
                                        *self._constants)
            result = np.empty(11)
            result[:3] = values.p_ee_in_base
            result[3] = C_m
            result[4:10] = gradient
            result[10] = self._alpha(C_m, *self._band)
            return result

        def _calc(self, context):
            return through_float_function(self.evaluate,
                                          self._input.Eval(context))

    return Impl


ArmCapability = ArmCapability_[None]
"""ArmCapability_ for double; `ToAutoDiffXd()` gives the AutoDiff one."""


@define_stage("WorkspaceAdapter_")
def WorkspaceAdapter_(T):
    class Impl(LeafSystem_[T]):
        """The weighting factors of eq. (weight-factors) for a motion mode,
        Table (T:motion-mode), with the local workspace and the
        deactivation strategy of Sec. IV-C in the intuitive pHRI mode.

        ::

                                   ┌──────────────────┐
            end_effector_position ►│                  ├──► sigma_xy
            end_effector_velocity ►│ WorkspaceAdapter │
            capability ───────────►│                  ├──► sigma_phi
            capability_gradient ──►│                  │
                                   └──────────────────┘

        - end_effector_position: p_ee (3) in T_b (m).
        - end_effector_velocity: V_ee (6), the commanded twist in T_b.
        - capability: C_m (1); capability_gradient: grad_x C_m (6, T_a).
        - sigma_xy, sigma_phi (1 each), in [0, 1].

        Locomotion gives (0, 0), manipulation (1, 1), loco-manipulation
        the fixed parameters; these modes read no input (no direct
        feedthrough) and have no state. The intuitive pHRI mode computes
        workspace.adaptive_weighting_factors (its float kernel
        in double, chosen when the stage is built): f_xy, f_phi from C_m
        penalized by the extent d and deflection phi of the end effector
        w.r.t. the arm's base (defined in drake_wbc.math.workspace), then
        the deactivation strategy: sigma's target is 1 if the commanded
        twist, carried by the arm alone, would raise C_m^(d,phi) or lead
        back (d_dot, phi_dot < 0), else f, with hysteresis (the
        deactivation sets in above params.deactivation_speed and ends
        when every test leads out), and sigma follows its target at no
        more than params.max_rate per second. Its discrete state is the
        last tick's (sigma_xy, sigma_phi, deactivated_xy,
        deactivated_phi), from workspace.WEIGHTING_START, updated once a
        period (time_step, offset 0, the controller's one periodic
        group, so that `Linearize` applies) with the very vector the
        outputs give: the outputs are this tick's factors from the state
        and the inputs (direct feedthrough, as the paper's rule), so the
        stages that read them at a tick see the factors of that tick.
        sigma changes by at most params.max_rate * time_step per tick.

        Args:
            params: WorkspaceAdapterParameters (read here, when the stage
                is built); loco-manipulation with sigma_xy = sigma_phi =
                0.5 if None. Its local workspace, where None, the arm's
                robot's (its description's tuning).
            arm: ArmKinematics whose R_ba and arm-base position define
                T_a; our robot's if None.
            band: the CapabilityBand C_m^l, C_m^u of f_xy and f_phi
                (intuitive pHRI; read here); the arm's robot's (its
                description's tuning) if None.
            time_step: the control period h in s (> 0), the period of
                the intuitive pHRI mode's update and the time of
                params.max_rate; 0.01 (the paper's 100 Hz) by default.
                Not read in the fixed modes.
        """

        def _construct(self, params=None, arm=None, band=None,
                       time_step=0.01, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.params = checked_instance(
                "params", params, WorkspaceAdapterParameters,
                WorkspaceAdapterParameters)
            self.arm = checked_instance("arm", arm, ArmKinematics,
                                        shared_arm_kinematics)
            self.band = band_of(band, self.arm)
            self.R_ba, self.arm_base_position = arm_mounting(self.arm)
            self._inputs = declare_inputs(self, (
                ("end_effector_position", 3), ("end_effector_velocity", 6),
                ("capability", 1), ("capability_gradient", 6)))
            p = self.params
            if p.mode is MotionMode.INTUITIVE_PHRI:
                h = positive("time_step", time_step)
                local = (p.workspace or self.arm.model.description.tuning
                         .local_workspace)
                self._constants = workspace.AdaptiveWorkspace.of(
                    self.band.upper, self.band.lower, local, self.R_ba,
                    self.arm_base_position, p.deactivation_speed,
                    p.max_rate * h)
                self._factors = body_for(
                    workspace.adaptive_weighting_factors, T)
                state = self.DeclareDiscreteState(
                    np.array(workspace.WEIGHTING_START))
                self.DeclarePeriodicDiscreteUpdateEvent(h, 0.0, self._update)
                calc, prerequisites = (
                    self._calc_adaptive,
                    tickets(self._inputs.values())
                    | {self.discrete_state_ticket(state)})
            else:
                self._fixed = np.array(motion_mode.fixed_weighting_factors(
                    p.mode, p.sigma_xy, p.sigma_phi))
                calc, prerequisites = (self._calc_fixed,
                                       {self.nothing_ticket()})
            self._entry = entry = declare_cached_vector(
                self, "weighting factors", calc, prerequisites)
            declare_slices(self, entry, (("sigma_xy", slice(0, 1)),
                                         ("sigma_phi", slice(1, 2))))

        def _calc_fixed(self, context):
            return self._fixed

        def _calc_adaptive(self, context):
            position, velocity, C_m, gradient = (
                port.Eval(context) for port in self._inputs.values())
            previous = context.get_discrete_state_vector().CopyToVector()
            return np.array(self._factors(previous, position, velocity,
                                          C_m[0], gradient, self._constants))

        def _update(self, context, discrete_state):
            discrete_state.set_value(self._entry.Eval(context))

    return Impl


WorkspaceAdapter = WorkspaceAdapter_[None]
"""WorkspaceAdapter_ for double; `ToAutoDiffXd()` gives the AutoDiff one."""

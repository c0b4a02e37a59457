"""The coordination stages of Sec. IV-A as Drake systems:
MotionDistributor (eq. (wbccm)) and RobustCompensator (eqs.
(wb_error)-(compensation)); their inputs C_m, grad_x C_m, alpha and the
weighting factors come from ArmCapability and WorkspaceAdapter
(stages/capability_stage.py).

Both are stateless, but for RobustCompensator's "predicted" source of the
base's motion (one discrete state, the predicted base velocity): their
outputs follow directly from their inputs (direct feedthrough), neither
sits on a feedback edge. Each runs one
equation of the math layer, chosen once when it is built
(drake_wbc.math.kernels.body_for): distribution.whole_body_distribution
and compensation.arm_compensation, scalar-generic, in AutoDiffXd; their
fast float kernels in double. Their parameters were checked where they
entered (the dataclasses' checks, at load and build time); each tick
checks only the input values that the ports' sizes cannot constrain
(sigma, alpha, and the task inputs s_c and k_n against their ranges in
drake_wbc.math.task_inputs), so that a stage used alone raises on a bad
one.
"""


import numpy as np
from pydrake.systems.framework import LeafSystem_

from drake_wbc.math import (
    capability,
    compensation,
    distribution,
    kernels,
)
from drake_wbc.math.base_state import BASE_STATE_SIZE, BASE_TWIST
from drake_wbc.math.compensation import (
    PROJECTOR_TOLERANCE,
    RobustCompensatorParameters,
)
from drake_wbc.math.distribution import MotionDistributorParameters
from drake_wbc.math.task_inputs import TASK_INPUTS
from drake_wbc.math.validation import (
    checked_instance,
    positive,
    rotation_matrix,
    unit_interval,
)
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages.support import (
    band_of,
    declare_cached_vector,
    declare_inputs,
    declare_slices,
    define_stage,
    optional_scalar,
    shared_arm_kinematics,
    tickets,
)


@define_stage("MotionDistributor_")
def MotionDistributor_(T):
    class Impl(LeafSystem_[T]):
        """Weighted whole-body motion distribution with null-space
        optimisation of C_m, eq. (wbccm):

            V_wb = J^+ V_ee + (I - J^+ J_wb) k_n [grad_x C_m; 0_3],

        J_wb = [R_ba, J_b] (eq. (fk) bottom line, J_b of eq. (2) at p_ee)
        and J^+ weighted by Q(sigma_xy, sigma_phi) of eq.
        (weight-factors) (distribution.whole_body_distribution).

        ::

                                   ┌───────────────────┐
            end_effector_velocity ►│                   │
            sigma_xy ─────────────►│                   ├──► arm_velocity
            sigma_phi ────────────►│                   │
            end_effector_position ►│ MotionDistributor │
            capability ───────────►│                   ├──► base_velocity
            capability_gradient ──►│                   │
            null_space_gain ──────►│ (optional)        │
                                   └───────────────────┘

        - end_effector_velocity: V_ee (6), the commanded twist in T_b.
        - sigma_xy, sigma_phi: weighting factors (1 each) in [0, 1].
        - end_effector_position: p_ee (3) in T_b (m), for J_b.
        - capability: C_m (1); capability_gradient: grad_x C_m (6, T_a).
        - null_space_gain: k_n (1) >= 0, optional: the parameter's
          value when not connected (nor fixed).
        - arm_velocity: V_a (6) in T_a; base_velocity: V_b (3) in T_b.

        Switch-off of k_n: the paper sets k_n = 0 when C_m > C_m^u. A step
        there would put a velocity step k_n grad_x C_m on the arm (the
        kind of step the base filter exists to avoid). By default the
        gain used is k_n alpha(C_m, C_m^u, C_m^l): exactly 0 above C_m^u
        as in the paper, k_n at and below C_m^l, and C^1 in between, so
        V_wb stays continuous. The optimisation then drives C_m up to
        C_m^u, approached from below, instead of across it. The
        null-space term never changes the end-effector twist:
        J_wb V_wb = V_ee.

        Args:
            params: MotionDistributorParameters; k_n = 0 if None.
            arm: ArmKinematics whose R_ba is used; our robot's if None.
            band: the CapabilityBand C_m^l, C_m^u of the switch-off of
                k_n (read here); the arm's robot's (its description's
                tuning) if None.
        """

        def _construct(self, params=None, arm=None, band=None,
                       converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.params = checked_instance(
                "params", params, MotionDistributorParameters,
                MotionDistributorParameters)
            self.arm = checked_instance("arm", arm, ArmKinematics,
                                        shared_arm_kinematics)
            self.band = band_of(band, self.arm)
            self.R_ba = rotation_matrix("R_ba", self.arm.R_ba)
            # None for the usual mounting ^bR_a = I, the closed form of
            # the float kernel.
            self._R_ba = (None if np.array_equal(self.R_ba, np.eye(3))
                          else self.R_ba)
            self._gain = self.params.null_space_gain
            self._gain_range = TASK_INPUTS["null_space_gain"]
            self._band = (self.band.upper, self.band.lower)
            self._smooth = self.params.smooth_switch_off
            self._damping = self.params.damping
            self._distribute = kernels.body_for(
                distribution.whole_body_distribution, T)
            # eq. (transition): its float kernel in double, chosen once.
            self._transition = kernels.body_for(
                capability.transition_of, T)
            self._inputs = declare_inputs(self, (
                ("end_effector_velocity", 6), ("sigma_xy", 1),
                ("sigma_phi", 1), ("end_effector_position", 3),
                ("capability", 1), ("capability_gradient", 6),
                ("null_space_gain", 1)))
            (self._V_ee_port, self._sigma_xy_port, self._sigma_phi_port,
             self._p_ee_port, self._capability_port, self._gradient_port,
             self._gain_port) = self._inputs.values()
            entry = declare_cached_vector(
                self, "whole-body input V_wb", self._calc,
                tickets(self._inputs.values()))
            declare_slices(self, entry, (("arm_velocity", slice(0, 6)),
                                         ("base_velocity", slice(6, 9))))

        def null_space_gain(self, context):
            """The gain of eq. (wbccm) used in `context`: k_n (port, else
            parameter) times the switch-off at C_m (see the class)."""
            k_n = self._gain_range.check("null_space_gain", optional_scalar(
                self._gain_port, context, self._gain))
            C_m = self._capability_port.Eval(context)[0]
            upper, lower = self._band
            if self._smooth:
                return k_n * self._transition(C_m, upper, lower)
            return k_n * (1.0 if C_m <= upper else 0.0)

        def _calc(self, context):
            sigma_xy = self._sigma_xy_port.Eval(context)[0]
            sigma_phi = self._sigma_phi_port.Eval(context)[0]
            if not (0.0 <= sigma_xy <= 1.0 and 0.0 <= sigma_phi <= 1.0):
                unit_interval("sigma_xy", sigma_xy)
                unit_interval("sigma_phi", sigma_phi)
            return self._distribute(
                self._V_ee_port.Eval(context), self._p_ee_port.Eval(context),
                self._R_ba, sigma_xy, sigma_phi,
                self._gradient_port.Eval(context),
                self.null_space_gain(context), self._damping)

    return Impl


MotionDistributor = MotionDistributor_[None]
"""MotionDistributor_ for double; `ToAutoDiffXd()` gives the AutoDiff one."""


@define_stage("RobustCompensator_")
def RobustCompensator_(T):
    class Impl(LeafSystem_[T]):
        """Arm compensation of the filtered base motion, eqs. (wb_error),
        (compensation) and (deviation) (compensation.arm_compensation):

            delta_V_b     = V_b^flt - V_b,   (V_b^flt: params.base_source)
            delta_V_a^req = -R_ba^T J_b delta_V_b,
            delta_V_a^cmp = (I - s_c alpha P_Cm) delta_V_a^req,
            V_a^ref       = V_a + delta_V_a^cmp,
            delta_V_ee    = -s_c alpha R_ba P_Cm delta_V_a^req,

        P_Cm the projector onto grad_x C_m; delta_V_ee turned into T_b
        by R_ba (compensation.deviation_in_base), the frame of V_ee that
        WholeBodyCdmp integrates it in.

        ::

                                    ┌───────────────────┐
            arm_velocity ──────────►│                   │
            base_velocity ─────────►│                   ├─► arm_reference_
            filtered_base_velocity ►│                   │   velocity
            end_effector_position ─►│ RobustCompensator │
            capability_gradient ───►│                   ├─► end_effector_
            alpha ─────────────────►│                   │   deviation
            compensation_switch ───►│ (optional)        │
            base_state ────────────►│ ("measured" only) │
                                    └───────────────────┘

        - arm_velocity: V_a (6, T_a) and base_velocity: V_b (3, T_b), from
          the MotionDistributor.
        - filtered_base_velocity: V_b^flt (3, T_b), from the
          BaseVelocityFilter (what the base is commanded).
        - base_state: the odometry [x, y, yaw; vx, vy, wz] (6), whose
          twist (T_b) the "measured" source takes for V_b^flt; read by no
          other source (it may stay unconnected).
        - end_effector_position: p_ee (3) in T_b (m), for J_b.
        - capability_gradient: grad_x C_m (6, T_a); alpha (1) of eq.
          (transition), in [0, 1].
        - compensation_switch: s_c (1) in [0, 1], optional: the
          parameter's value when not connected (nor fixed). s_c = 0 means
          alpha = 0, the exact compensation.
        - arm_reference_velocity: V_a^ref (6, T_a).
        - end_effector_deviation: delta_V_ee (6), the end effector's
          twist deviation of eq. (deviation), in T_b (the paper's T_a
          value turned by R_ba; the same for the shipped robot, R_ba =
          I).

        With s_c alpha = 0 the arm reference and the filtered base give the
        commanded twist exactly: J_wb [V_a^ref; V_b^flt] = J_wb [V_a; V_b].

        The base's motion (params.base_source; what each costs:
        drake_wbc.math.compensation, "The base's motion"):
        - "command" (the paper's): V_b^flt is filtered_base_velocity, the
          command sent. Stateless.
        - "measured": the odometry's twist, base_state's [vx, vy, wz]
          (drake_wbc.math.base_state.BASE_TWIST). Stateless; the output
          then feeds through from base_state.
        - "predicted": the command through eq. (base_lag), a first-order
          lag of time constant params.base_lag at the control period:
          one discrete state (3, the predicted base velocity V_b^pred in
          T_b, updated every `time_step`), and V_b^flt = V_b^pred+ =
          V_b^pred + g (V_b^flt,cmd - V_b^pred), the base's velocity one
          period after this tick's command
          (compensation.base_velocity_prediction); `set_prediction`
          starts it from the base's measured velocity.

        Args:
            params: RobustCompensatorParameters (drake_wbc.math.compensation);
                s_c = 1 and the command source if None.
            arm: ArmKinematics whose R_ba is used; our robot's if None.
            time_step: the control period h in s, > 0 (0.01, the
                paper's), the period of the "predicted" source's update.
        """

        def _construct(self, params=None, arm=None, time_step=0.01,
                       converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.params = checked_instance(
                "params", params, RobustCompensatorParameters,
                RobustCompensatorParameters)
            self._time_step = h = positive("time_step", time_step)
            self.source = self.params.base_source
            self.arm = checked_instance("arm", arm, ArmKinematics,
                                        shared_arm_kinematics)
            self.R_ba = rotation_matrix("R_ba", self.arm.R_ba)
            # None for the usual mounting ^bR_a = I (no rotation to do),
            # else the matrix, as the compiled kernel takes it.
            self._R_ba = (None if np.array_equal(self.R_ba, np.eye(3))
                          else np.ascontiguousarray(self.R_ba, float))
            self._switch = self.params.compensation_switch
            self._switch_range = TASK_INPUTS["compensation_switch"]
            self._compensate = kernels.body_for(
                compensation.arm_compensation, T)
            self._inputs = declare_inputs(self, (
                ("arm_velocity", 6), ("base_velocity", 3),
                ("filtered_base_velocity", 3), ("end_effector_position", 3),
                ("capability_gradient", 6), ("alpha", 1),
                ("compensation_switch", 1),
                ("base_state", BASE_STATE_SIZE)))
            (self._V_a_port, self._V_b_port, self._V_b_flt_port,
             self._p_ee_port, self._gradient_port, self._alpha_port,
             self._switch_port, self._base_state_port) = (
                 self._inputs.values())
            # The base's motion: base_state's twist for "measured", else
            # the command on filtered_base_velocity.
            unused = ("filtered_base_velocity" if self.source == "measured"
                      else "base_state")
            used = [port for name, port in self._inputs.items()
                    if name != unused]
            prerequisites = tickets(used)
            self._base_motion = self._commanded
            if self.source == "measured":
                self._base_motion = self._measured
            elif self.source == "predicted":
                self._gain = compensation.lag_gain(h, self.params.base_lag)
                prerequisites.add(self.discrete_state_ticket(
                    self.DeclareDiscreteState(3)))
                self.DeclarePeriodicDiscreteUpdateEvent(h, 0.0,
                                                        self._update)
                self._base_motion = self._predicted
                self._predict = kernels.body_for(
                    compensation.base_velocity_prediction, T)
            entry = declare_cached_vector(
                self, "compensated arm twist and deviation", self._calc,
                prerequisites)
            declare_slices(self, entry, (
                ("arm_reference_velocity", slice(0, 6)),
                ("end_effector_deviation", slice(6, 12))))

        def _commanded(self, context):
            return self._V_b_flt_port.Eval(context)

        def _measured(self, context):
            return self._base_state_port.Eval(context)[BASE_TWIST]

        def _predicted(self, context):
            return self._predict(
                context.get_discrete_state_vector().CopyToVector(),
                self._V_b_flt_port.Eval(context), self._gain)

        def _update(self, context, discrete_state):
            discrete_state.set_value(self._predicted(context))

        def set_prediction(self, context, velocity):
            """Starts the "predicted" source's state at the base velocity
            `velocity` (3, T_b), e.g. the base's measured one; nothing to
            do for the other sources."""
            if self.source == "predicted":
                context.SetDiscreteState(np.asarray(velocity))

        def _calc(self, context):
            s_c = self._switch_range.check(
                "compensation_switch",
                optional_scalar(self._switch_port, context, self._switch))
            alpha = self._alpha_port.Eval(context)[0]
            if not 0.0 <= alpha <= 1.0:
                unit_interval("alpha", alpha)
            return self._compensate(
                self._V_a_port.Eval(context), self._V_b_port.Eval(context),
                self._base_motion(context),
                self._p_ee_port.Eval(context), self._R_ba,
                self._gradient_port.Eval(context), s_c * alpha,
                PROJECTOR_TOLERANCE)

    return Impl


RobustCompensator = RobustCompensator_[None]
"""RobustCompensator_ for double; `ToAutoDiffXd()` gives the AutoDiff one."""

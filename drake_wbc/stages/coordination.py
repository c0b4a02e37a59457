"""The coordination stages of Sec. IV-A as Drake systems:
MotionDistributor (eq. (wbccm)) and RobustCompensator (eqs.
(wb_error)-(compensation)); their inputs C_m, grad_x C_m, alpha and the
weighting factors come from ArmCapability and WorkspaceAdapter
(systems/capability_stage.py).

Both are stateless: their outputs follow directly from their inputs
(direct feedthrough), neither sits on a feedback edge. The double systems
run the math layer's unchecked paths in plain floats
(aligned_distribution.distribute_aligned for the usual mounting R_ba = I,
else distribution.distribute_unchecked; compensation.compensate_unchecked):
their parameters and R_ba are checked once at construction, their inputs
have the ports' sizes, and only the values that the ports cannot
constrain (sigma, alpha, s_c, k_n) are checked each tick. The AutoDiffXd
ones run the same formulas elementwise (drake_wbc.math.any_scalar_coordination),
with scalar_support.solve for the linear solve, so that their derivatives
are exact.
"""

from dataclasses import dataclass, field

import numpy as np
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_wbc.math import (
    aligned_distribution,
    capability,
    compensation,
    distribution,
    kinematics,
    pseudoinverse,
)
from drake_wbc.math.any_scalar_coordination import (
    PROJECTOR_TOLERANCE,
    _unit_interval,
    base_jacobian_any,
    compensate_any,
    distribute_any,
)
from drake_wbc.math.capability import CapabilityBand, set_band
from drake_wbc.math.scalar_support import value_of
from drake_wbc.math.validation import (
    checked_instance,
    in_closed_range,
    non_negative,
    validated_copy,
)
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.stages.support import (
    SCALARS,
    declare_cached_vector,
    declare_inputs,
    declare_slices,
    optional_scalar,
    shared_arm_kinematics,
    tickets,
)


@dataclass
class MotionDistributorParameters:
    """Parameters of MotionDistributor.

    Attributes:
        null_space_gain: k_n >= 0 of eq. (wbccm), used when the
            null_space_gain port is not connected; the paper starts with 0
            and switches to 0.1.
        band: C_m^l, C_m^u; k_n is off at and above C_m^u.
        smooth_switch_off: True fades k_n out across the band,
            k_n alpha(C_m, C_m^u, C_m^l); False switches it off in one step
            above C_m^u, the paper's words read literally.
        damping: pseudoinverse.SingularityDamping (never active for our
            robot's J_wb, see pseudoinverse), or None for none; default
            the values of pseudoinverse.DEFAULT_DAMPING.
    """

    null_space_gain: float = 0.0
    band: CapabilityBand = field(default_factory=CapabilityBand)
    smooth_switch_off: bool = True
    damping: pseudoinverse.SingularityDamping | None = field(
        default_factory=pseudoinverse.SingularityDamping)

    def __post_init__(self):
        non_negative("null_space_gain", self.null_space_gain)
        set_band(self)
        if not isinstance(self.smooth_switch_off, bool):
            raise ValueError(
                f"smooth_switch_off = {self.smooth_switch_off!r} is not "
                "allowed: must be True or False"
            )
        if not (self.damping is None or isinstance(
                self.damping, pseudoinverse.SingularityDamping)):
            raise ValueError(
                f"damping = {self.damping!r} is not allowed: must be a "
                "SingularityDamping or None"
            )


@TemplateSystem.define("MotionDistributor_", T_list=SCALARS)
def MotionDistributor_(T):
    class Impl(LeafSystem_[T]):
        """Weighted whole-body motion distribution with null-space
        optimisation of C_m, eq. (wbccm):

            V_wb = J^+ V_ee + (I - J^+ J_wb) k_n [grad_x C_m; 0_3],

        J_wb = [R_ba, J_b] (eq. (1) bottom line, J_b of eq. (2) at p_ee)
        and J^+ weighted by Q(sigma_xy, sigma_phi) of eq.
        (weight-factors).

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
        """

        def _construct(self, params=None, arm=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.params = validated_copy(checked_instance(
                "params", params, MotionDistributorParameters,
                MotionDistributorParameters))
            self.arm = checked_instance("arm", arm, ArmKinematics,
                                        shared_arm_kinematics)
            self.R_ba = np.array(self.arm.R_ba, dtype=float)
            self._inputs = declare_inputs(self, (
                ("end_effector_velocity", 6), ("sigma_xy", 1),
                ("sigma_phi", 1), ("end_effector_position", 3),
                ("capability", 1), ("capability_gradient", 6),
                ("null_space_gain", 1)))
            (self._V_ee_port, self._sigma_xy_port, self._sigma_phi_port,
             self._p_ee_port, _, self._gradient_port, _) = (
                self._inputs.values())
            # Float path in plain floats for the usual mounting, checked
            # here once.
            self._aligned = T is float and np.array_equal(self.R_ba,
                                                          np.eye(3))
            entry = declare_cached_vector(
                self, "whole-body input V_wb", self._calc,
                tickets(self._inputs.values()))
            declare_slices(self, entry, (("arm_velocity", slice(0, 6)),
                                         ("base_velocity", slice(6, 9))))

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.params, other.arm,
                            converter=converter)
            self.params = other.params

        def null_space_gain(self, context):
            """The gain of eq. (wbccm) used in `context`: k_n (port, else
            parameter) times the switch-off at C_m (see the class)."""
            k_n = optional_scalar(self._inputs["null_space_gain"], context,
                                  self.params.null_space_gain)
            if k_n < 0.0:
                raise ValueError(
                    f"null_space_gain = {float(value_of(k_n))!r} is not "
                    "allowed: must be 0 or greater"
                )
            C_m = self._inputs["capability"].Eval(context)[0]
            band = self.params.band
            if self.params.smooth_switch_off:
                if T is float:  # the band was checked at construction
                    return k_n * capability.transition_float(
                        C_m, band.upper, band.lower)
                return k_n * capability.transition_unchecked(
                    C_m, band.upper, band.lower)
            return k_n * (1.0 if C_m <= band.upper else 0.0)

        def _calc(self, context):
            if self._aligned:
                return self._calc_aligned(context)
            value = {name: port.Eval(context)
                     for name, port in self._inputs.items()
                     if name != "null_space_gain"}
            V_ee = value["end_effector_velocity"]
            sigma_xy = value["sigma_xy"][0]
            sigma_phi = value["sigma_phi"][0]
            p = value["end_effector_position"]
            g = value["capability_gradient"]
            k = self.null_space_gain(context)
            if T is float:
                # The checked path of distribution.distribute, unchecked:
                # R_ba and the damping were checked at construction, the
                # ports have their sizes, sigma and k_n are checked here.
                J = kinematics.whole_body_jacobian_unchecked(None, p,
                                                             self.R_ba)
                weights = pseudoinverse.weights_of(
                    _unit_interval("sigma_xy", sigma_xy),
                    _unit_interval("sigma_phi", sigma_phi))
                V_n = np.zeros(9)
                V_n[:6] = k * g
                return distribution.distribute_unchecked(
                    J, V_ee, weights, V_n, self.params.damping)
            J = np.hstack([kinematics.twist_rotation(self.R_ba),
                           base_jacobian_any(p)])
            V_n = np.concatenate([k * g, g[:3] * 0.0])
            return distribute_any(J, V_ee, sigma_xy, sigma_phi, V_n,
                                  self.params.damping)

        def _calc_aligned(self, context):
            """_calc in double for R_ba = I (our robot): the same V_wb,
            in plain floats (aligned_distribution.distribute_aligned)."""
            sigma_xy = float(self._sigma_xy_port.Eval(context)[0])
            sigma_phi = float(self._sigma_phi_port.Eval(context)[0])
            if not (0.0 <= sigma_xy <= 1.0 and 0.0 <= sigma_phi <= 1.0):
                _unit_interval("sigma_xy", sigma_xy)
                _unit_interval("sigma_phi", sigma_phi)
            k = float(self.null_space_gain(context))
            g = self._gradient_port.Eval(context).tolist()
            return aligned_distribution.distribute_aligned(
                self._V_ee_port.Eval(context),
                self._p_ee_port.Eval(context), sigma_xy, sigma_phi,
                [k * e for e in g], self.params.damping)

    return Impl


MotionDistributor = MotionDistributor_[None]
"""MotionDistributor_ for double; `ToAutoDiffXd()` gives the AutoDiff one."""


@dataclass
class RobustCompensatorParameters:
    """Parameters of RobustCompensator.

    Attributes:
        compensation_switch: s_c in [0, 1], used when the
            compensation_switch port is not connected. The paper's s_c is
            1 (robust compensation, alpha as computed) or 0 (alpha = 0:
            exact compensation whatever C_m); values in between scale
            alpha.
    """

    compensation_switch: float = 1.0

    def __post_init__(self):
        in_closed_range("compensation_switch", self.compensation_switch,
                        0.0, 1.0)


@TemplateSystem.define("RobustCompensator_", T_list=SCALARS)
def RobustCompensator_(T):
    class Impl(LeafSystem_[T]):
        """Arm compensation of the filtered base motion, eqs. (wb_error),
        (compensation) and (deviation):

            delta_V_b     = V_b^flt - V_b,
            delta_V_a^req = -R_ba^T J_b delta_V_b,
            delta_V_a^cmp = (I - s_c alpha P_Cm) delta_V_a^req,
            V_a^ref       = V_a + delta_V_a^cmp,
            delta_V_ee    = -s_c alpha P_Cm delta_V_a^req,

        P_Cm the projector onto grad_x C_m.

        ::

                                    ┌───────────────────┐
            arm_velocity ──────────►│                   │
            base_velocity ─────────►│                   ├─► arm_reference_
            filtered_base_velocity ►│                   │   velocity
            end_effector_position ─►│ RobustCompensator │
            capability_gradient ───►│                   ├─► end_effector_
            alpha ─────────────────►│                   │   deviation
            compensation_switch ───►│ (optional)        │
                                    └───────────────────┘

        - arm_velocity: V_a (6, T_a) and base_velocity: V_b (3, T_b), from
          the MotionDistributor.
        - filtered_base_velocity: V_b^flt (3, T_b), from the
          BaseVelocityFilter (what the base is commanded).
        - end_effector_position: p_ee (3) in T_b (m), for J_b.
        - capability_gradient: grad_x C_m (6, T_a); alpha (1) of eq.
          (transition), in [0, 1].
        - compensation_switch: s_c (1) in [0, 1], optional: the
          parameter's value when not connected (nor fixed). s_c = 0 means
          alpha = 0, the exact compensation.
        - arm_reference_velocity: V_a^ref (6, T_a).
        - end_effector_deviation: delta_V_ee (6), in T_a like the paper
          (the same in T_b for our robot, R_ba = I).

        With s_c alpha = 0 the arm reference and the filtered base give the
        commanded twist exactly: J_wb [V_a^ref; V_b^flt] = J_wb [V_a; V_b].

        Args:
            params: RobustCompensatorParameters; s_c = 1 if None.
            arm: ArmKinematics whose R_ba is used; our robot's if None.
        """

        def _construct(self, params=None, arm=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.params = validated_copy(checked_instance(
                "params", params, RobustCompensatorParameters,
                RobustCompensatorParameters))
            self.arm = checked_instance("arm", arm, ArmKinematics,
                                        shared_arm_kinematics)
            self.R_ba = np.array(self.arm.R_ba, dtype=float)
            kinematics.twist_rotation(self.R_ba)  # checks R_ba
            self._R_ab = tuple(tuple(row) for row in self.R_ba.T.tolist())
            self._inputs = declare_inputs(self, (
                ("arm_velocity", 6), ("base_velocity", 3),
                ("filtered_base_velocity", 3), ("end_effector_position", 3),
                ("capability_gradient", 6), ("alpha", 1),
                ("compensation_switch", 1)))
            (self._V_a_port, self._V_b_port, self._V_b_flt_port,
             self._p_ee_port, self._gradient_port, self._alpha_port,
             self._switch_port) = self._inputs.values()
            entry = declare_cached_vector(
                self, "compensated arm twist and deviation", self._calc,
                tickets(self._inputs.values()))
            declare_slices(self, entry, (
                ("arm_reference_velocity", slice(0, 6)),
                ("end_effector_deviation", slice(6, 12))))

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.params, other.arm,
                            converter=converter)
            self.params = other.params

        def _calc(self, context):
            if T is float:
                return self._calc_float(context)
            value = {name: port.Eval(context)
                     for name, port in self._inputs.items()
                     if name != "compensation_switch"}
            s_c = _unit_interval("compensation_switch", optional_scalar(
                self._inputs["compensation_switch"], context,
                self.params.compensation_switch))
            alpha = s_c * _unit_interval("alpha", value["alpha"][0])
            V_b, V_b_flt = (value["base_velocity"],
                            value["filtered_base_velocity"])
            p = value["end_effector_position"]
            g = value["capability_gradient"]
            cmp, deviation = compensate_any(V_b_flt - V_b, p, self.R_ba, g,
                                            alpha)
            return np.concatenate([value["arm_velocity"] + cmp, deviation])

        def _calc_float(self, context):
            """_calc in double, in plain floats
            (compensation.compensate_unchecked): the same values."""
            s_c = optional_scalar(self._switch_port, context,
                                  self.params.compensation_switch)
            alpha = float(self._alpha_port.Eval(context)[0])
            if not (0.0 <= s_c <= 1.0 and 0.0 <= alpha <= 1.0):
                _unit_interval("compensation_switch", s_c)
                _unit_interval("alpha", alpha)
            delta_V_b = (self._V_b_flt_port.Eval(context)
                         - self._V_b_port.Eval(context))
            return np.array(compensation.compensate_unchecked(
                self._V_a_port.Eval(context).tolist(), delta_V_b.tolist(),
                self._p_ee_port.Eval(context).tolist(), self._R_ab,
                self._gradient_port.Eval(context).tolist(),
                float(s_c) * alpha, PROJECTOR_TOLERANCE))

    return Impl


RobustCompensator = RobustCompensator_[None]
"""RobustCompensator_ for double; `ToAutoDiffXd()` gives the AutoDiff one."""

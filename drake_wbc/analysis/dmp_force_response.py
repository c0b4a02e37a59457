"""The force responses of the coupled DMPs, linearised with Drake.

`linearize_dmp_force` builds one of the controller's coupled DMPs from
the project's own scalar-convertible systems and linearises it from the
wrench on the tool to its position y: the arm's CDMP, eq. (cdmp-arm), on a
stiffness axis (eq. (lp-admit)) and on a force axis (eq. (tf-admit),
D_a = k_f), and the whole body's CDMP, eq. (cdmp-wb), with S_hri = 1
(eq. (tf-admit), D_a = k_hri). The filter chain is in
drake_wbc.analysis.chains.
"""

from dataclasses import dataclass

import numpy as np
from pydrake.systems.primitives import Linearize, LinearSystem

from drake_wbc.controller import ControllerParameters
from drake_wbc.math import cdmp
from drake_wbc.math.validation import checked_instance, whole_number
from drake_wbc.stages import ArmCdmp, WholeBodyCdmp


@dataclass
class DmpForceResponse:
    """A coupled DMP linearised from the force to its position.

    Attributes:
        system: the LinearSystem from the wrench (6) to y_dot (6).
        position: the (6, n) selection of the position y from the state.
        axis: the axis (0 to 5) whose force-to-position response is meant.
    """

    system: LinearSystem
    position: np.ndarray
    axis: int

    def response(self, omega):
        """The axis' force-to-position response at `omega` (rad/s)."""
        from drake_wbc.analysis.frequency import linear_system_response

        H = linear_system_response(self.system, omega, self.position)
        return H[:, self.axis, self.axis]


def linearize_dmp_force(kind, params=None, time_step=None, axis=None):
    """Linearises a coupled DMP of the controller from the wrench on the
    tool to its position y.

    Args:
        kind: 'stiffness' (ArmCdmp on an axis with S_m = 1, eq.
            (lp-admit) with its C_s entering without the factor tau),
            'admittance' (ArmCdmp on an axis with S_m = 0, S_hri = 0: eq.
            (tf-admit) with D_a = k_f) or 'phri' (WholeBodyCdmp with
            S_hri = 1: eq. (tf-admit) with D_a = k_hri).
        params: ControllerParameters (the paper's if None): its arm_cdmp's
            k_p, k_d, k_f and DMP, or its whole_body_cdmp. S_m is set on
            `axis` as `kind` needs.
        time_step: 0 for continuous time; params.time_step if None.
        axis: the axis, 0 to 5; 0 (x) if None.

    Returns:
        DmpForceResponse.
    """
    params = checked_instance("params", params, ControllerParameters,
                              ControllerParameters)
    h = params.time_step if time_step is None else time_step
    axis = 0 if axis is None else whole_number("axis", axis)
    if axis > 5:
        raise ValueError(f"axis = {axis!r} is not allowed: must be 0 to 5")
    if kind == "phri":
        system = WholeBodyCdmp(params.whole_body_cdmp, time_step=h)
        switch, others = 1.0, ("reference_velocity", "end_effector_deviation")
    elif kind in ("stiffness", "admittance"):
        arm = params.arm_cdmp
        S_m = np.array(arm.S_m)
        S_m[axis] = 1.0 if kind == "stiffness" else 0.0
        system = ArmCdmp(cdmp.ArmCdmpParameters(
            k_p=arm.k_p, k_d=arm.k_d, k_f=arm.k_f, S_m=S_m, F_d=np.zeros(6),
            dmp=arm.dmp), time_step=h)
        switch, others = 0.0, ("arm_velocity", "desired_wrench")
    else:
        raise ValueError(f"kind = {kind!r} is not allowed: must be "
                         "'stiffness', 'admittance' or 'phri'")
    context = system.CreateDefaultContext()
    for name in others:
        system.GetInputPort(name).FixValue(context, np.zeros(6))
    system.GetInputPort("phri_switch").FixValue(context, [switch])
    if kind == "phri":
        system.GetInputPort("base_yaw").FixValue(context, [0.0])
    wrench = system.GetInputPort("wrench")
    wrench.FixValue(context, np.zeros(6))
    linear = Linearize(system, context, wrench.get_index(),
                       system.get_output_port(0).get_index())
    n = linear.A().shape[0]
    position = np.zeros((6, n))
    position[:, :6] = np.eye(6)
    return DmpForceResponse(linear, position, axis)

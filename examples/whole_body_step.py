"""One step of the whole-body coordination of the paper, by hand.

At the home pose, an end-effector twist of 0.1 m/s along the base's x axis
is split between arm and base with sigma_xy = 0.5 (eq. (wbccm)), the base's
share is then cut by a stand-in for its low-pass filter, and the arm takes
over what the base does not do (eqs. (wb_error)-(deviation)), fully while
C_m is above the band (alpha = 0) and only partly inside it.

Run:  .venv/bin/python examples/whole_body_step.py
"""

import numpy as np

from drake_wbc.math import (
    capability,
    compensation,
    distribution,
    kinematics,
)
from drake_wbc.robot.model import HOME_ARM_POSITIONS, ArmKinematics


def main():
    arm = ArmKinematics()
    q_a = HOME_ARM_POSITIONS
    values = arm.evaluate(q_a)

    # Capability of movement and its gradient w.r.t. the arm's Cartesian pose.
    C_m = capability.capability(values.J_a, q_a, arm.lower, arm.upper)
    grad = capability.capability_gradient(values.J_a, q_a, arm.lower,
                                          arm.upper)
    print(f"C_m at home = {C_m:.4f}")

    # Distribute V_ee between the arm's twist V_a and the base's V_b.
    J_wb = kinematics.whole_body_jacobian(None, values.p_ee_in_base, arm.R_ba)
    V_ee = np.array([0.1, 0, 0, 0, 0, 0])
    V_wb = distribution.distribute(
        J_wb, V_ee, sigma_xy=0.5, sigma_phi=0.5,
        null_velocity=distribution.capability_null_velocity(grad, k_n=0.0),
    )
    V_a, V_b = V_wb[:6], V_wb[6:]
    print("V_a =", np.round(V_a, 4), " V_b =", np.round(V_b, 4))

    # The filtered base lags: suppose it delivers 30% of V_b at this instant.
    delta_V_b = compensation.base_deviation(0.3 * V_b, V_b)
    J_b = kinematics.base_jacobian(values.p_ee_in_base)
    for C_m_now in (C_m, 0.0375):
        alpha = capability.transition(C_m_now, upper=0.04, lower=0.035)
        delta_V_a, delta_V_ee = compensation.robust_compensation(
            delta_V_b, J_b, arm.R_ba, grad, alpha
        )
        achieved = J_wb @ np.concatenate([V_a + delta_V_a, V_b + delta_V_b])
        print(
            f"C_m = {C_m_now:.4f}: alpha = {alpha:.2f}, end effector moves at "
            f"{np.round(achieved[:3], 4)} m/s, deviation "
            f"{np.round(delta_V_ee[:3], 4)} m/s"
        )


if __name__ == "__main__":
    main()

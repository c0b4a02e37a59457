"""The paper's transfer functions in closed form, continuous and as their
exact zero-order-hold equivalents, to check the linearisations against.

- eq. (filtering): drake_wbc.math.filtering.lowpass_response and
  lowpass_zoh_response (the base filter);
- eq. (lp-admit): the stiffness-coupled DMP, eq. (stiff-dmp), from the
  force F to the position y,

      L(y)/L(F) = (k_p (tau^2 + k_d) s + k_p tau alpha_z)
                  / (tau^2 s^2 + tau alpha_z s + alpha_z beta_z);

- eq. (tf-admit): the admittance-coupled DMP, eq. (admit-dmp),
  L(y) = D_a L(F_e) / s.

The discrete forms are derived here from partial fractions of H(s)/s
(H_d(z) = (1 - z^-1) Z{H(s)/s}), independently of the matrix exponential
that discretises the systems, so that the two check each other.
"""

import math

import numpy as np

from drake_wbc.math.filtering import MERGED_POLES
from drake_wbc.math.validation import as_scalar, non_negative, positive


def stiffness_coupled_coefficients(k_p, k_d, tau, alpha_z, beta_z,
                                   velocity_scale=None):
    """(b1, b0, a2, a1, a0) of the stiffness-coupled DMP's force-to-
    position transfer function (b1 s + b0) / (a2 s^2 + a1 s + a0).

    With the coupling C_f = k_p F entering tau y_dot = z + c C_f, the
    Laplace transform of eq. (stiff-dmp) gives

        Y (tau^2 s^2 + tau alpha_z s + alpha_z beta_z)
            = k_p ((c tau + k_d) s + c alpha_z) F.

    c = tau (`velocity_scale` None) is the paper's eq. (stiff-dmp) and
    gives eq. (lp-admit); the arm's CDMP, eq. (cdmp-arm), adds C_s
    without the factor tau (c = 1, drake_wbc.math.cdmp.arm_cdmp_derivative),
    the same for the paper's tau = 1.
    """
    k_p = non_negative("k_p", k_p)
    k_d = non_negative("k_d", k_d)
    tau = positive("tau", tau)
    alpha_z = positive("alpha_z", alpha_z)
    beta_z = positive("beta_z", beta_z)
    c = tau if velocity_scale is None else positive("velocity_scale",
                                                    velocity_scale)
    return (k_p * (c * tau + k_d), k_p * c * alpha_z, tau * tau,
            tau * alpha_z, alpha_z * beta_z)


def lp_admit_response(k_p, k_d, tau, alpha_z, beta_z, omega,
                      velocity_scale=None):
    """Eq. (lp-admit) at angular frequencies `omega` (rad/s): the
    stiffness-coupled DMP's position response to the force
    (`stiffness_coupled_coefficients` for `velocity_scale`)."""
    b1, b0, a2, a1, a0 = stiffness_coupled_coefficients(
        k_p, k_d, tau, alpha_z, beta_z, velocity_scale)
    s = 1j * np.asarray(omega, dtype=float)
    return (b1 * s + b0) / (a2 * s * s + a1 * s + a0)


def tf_admit_response(D_a, omega):
    """Eq. (tf-admit) at angular frequencies `omega` (rad/s): D_a / s,
    the admittance-coupled DMP's position response to the force (one axis,
    D_a > 0)."""
    D_a = positive("D_a", D_a)
    return D_a / (1j * np.asarray(omega, dtype=float))


def tf_admit_zoh_response(D_a, time_step, omega):
    """The exact zero-order-hold equivalent of eq. (tf-admit):
    Z{D_a / s^2} = D_a h z / (z - 1)^2, so H_d(z) = D_a h / (z - 1)."""
    D_a = positive("D_a", D_a)
    h = positive("time_step", time_step)
    z = np.exp(1j * np.asarray(omega, dtype=float) * h)
    return D_a * h / (z - 1.0)


def second_order_zoh_response(b1, b0, a2, a1, a0, time_step, omega):
    """The exact zero-order-hold equivalent of (b1 s + b0) /
    (a2 s^2 + a1 s + a0) (poles p_1, p_2 in the open left half-plane or
    anywhere but 0) at angular frequencies `omega`, z = e^(j omega h).

    Partial fractions of G(s) = H(s)/s, q_i = e^(p_i h):
    - p_1 != p_2: G = r_0/s + sum_i r_i/(s - p_i), r_0 = b0 / a0,
      r_i = (b1 p_i + b0) / (a2 p_i (p_i - p_j)), and
      H_d = r_0 + sum_i r_i (z - 1)/(z - q_i);
    - a double pole p (discriminant a1^2 - 4 a2 a0 = 0, or within
      drake_wbc.math.filtering.MERGED_POLES a1^2 of it, where the first
      form loses the digits that this one keeps; p^2 = a0 / a2):
      G = r_0/s + c_1/(s - p) + c_2/(s - p)^2, c_1 = -r_0,
      c_2 = (b1 p + b0)/(a2 p), and, since Z{t e^(pt)} = h q z/(z - q)^2,
      H_d = r_0 + c_1 (z - 1)/(z - q) + c_2 h q (z - 1)/(z - q)^2.
    For b1 = 0, b0 = a0 = omega_f^2 this is eq. (filtering)'s
    drake_wbc.math.filtering.lowpass_zoh_response. The first form loses
    digits as the poles merge (residues ~ 1 / (p_1 - p_2)), the second
    is exact to O(a1^2 - 4 a2 a0) (relative): each is taken where it is
    the better, exact to about 1e-10 of the response's peak.
    """
    h = positive("time_step", time_step)
    b1, b0, a1, a0 = (as_scalar(name, value) for name, value in (
        ("b1", b1), ("b0", b0), ("a1", a1), ("a0", a0)))
    a2 = positive("a2", a2)
    if a0 == 0.0:
        raise ValueError("a0 = 0.0 is not allowed: a pole at s = 0 needs "
                         "another form (e.g. tf_admit_zoh_response)")
    z = np.exp(1j * np.asarray(omega, dtype=float) * h)
    r_0 = b0 / a0
    discriminant = a1 * a1 - 4.0 * a2 * a0
    if abs(discriminant) <= MERGED_POLES * a1 * a1:
        # The double pole of the same a0 / a2 = p^2 (so that H(0), r_0,
        # stays exact), on the side of -a1 / (2 a2).
        p = -math.copysign(math.sqrt(a0 / a2), a1)
        q = np.exp(p * h)
        c_2 = (b1 * p + b0) / (a2 * p)
        return (r_0 - r_0 * (z - 1.0) / (z - q)
                + c_2 * h * q * (z - 1.0) / (z - q) ** 2)
    root = np.sqrt(complex(discriminant))
    poles = ((-a1 + root) / (2.0 * a2), (-a1 - root) / (2.0 * a2))
    response = np.full(z.shape, r_0, dtype=complex)
    for p_i, p_j in (poles, poles[::-1]):
        residue = (b1 * p_i + b0) / (a2 * p_i * (p_i - p_j))
        response = response + residue * (z - 1.0) / (z - np.exp(p_i * h))
    return response


def lp_admit_zoh_response(k_p, k_d, tau, alpha_z, beta_z, time_step, omega,
                          velocity_scale=None):
    """The exact zero-order-hold equivalent of eq. (lp-admit) (see
    `second_order_zoh_response`)."""
    return second_order_zoh_response(
        *stiffness_coupled_coefficients(k_p, k_d, tau, alpha_z, beta_z,
                                        velocity_scale), time_step, omega)

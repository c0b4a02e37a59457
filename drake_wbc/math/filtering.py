"""The base's second-order low-pass filter, eq. (filtering), as plain math.

    V_b^flt(s) = omega_f^2 / (s^2 + 2 zeta omega_f s + omega_f^2) V_b'(s)

The base is much slower than the arm, so the paper filters the base's share
of the motion and lets the arm make up the difference (Sec. IV-A,
"Trajectory Filtering"). Per axis the filter is the state-space system

    x = [y, y_dot],  x_dot = A x + B u,  y = C x,
    A = [[0, 1], [-omega_f^2, -2 zeta omega_f]],  B = [0, omega_f^2]^T,
    C = [1, 0],  D = 0,

with no direct feedthrough, so its output can close feedback loops in a
Drake diagram. At a control period h it is discretised exactly for a
piecewise-constant input (zero-order hold): A_d = e^(A h) and
B_d = int_0^h e^(A t) dt B. The closed-form responses below are derived
independently of these matrices, from partial fractions of H(s)/s, so that
the two can check each other.
"""

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

from drake_wbc.math.validation import (
    as_matrix,
    non_negative,
    positive,
    square_matrix,
)


@dataclass
class BaseFilterParameters:
    """Parameters of the base velocity filter, eq. (filtering).

    Attributes:
        omega_f: cut-off (natural) frequency omega_f in rad/s, > 0; the
            paper's experiments use 2 pi (1 Hz).
        zeta: damping ratio, > 0; the paper uses 1.0 (critically damped:
            the filtered velocity never overshoots a step).
        enabled: False bypasses the filter (the paper's comparison run
            "without trajectory filtering"): the command is then V_b'
            itself, sampled at each tick and held like every discrete
            command, so the output still leaves from state.

    The control period h is not a field: it is the controller's one
    time_step (ControllerParameters.time_step), the stage's `time_step`
    argument, checked against these fields by `check_filter_period`.
    """

    omega_f: float = 2.0 * np.pi
    zeta: float = 1.0
    enabled: bool = True

    def __post_init__(self):
        positive("omega_f", self.omega_f)
        positive("zeta", self.zeta)
        if not isinstance(self.enabled, (bool, np.bool_)):
            raise ValueError(f"enabled = {self.enabled!r} is not allowed: "
                             "must be true or false")


def check_filter_period(params, time_step, prefix=""):
    """Checks that the base filter `params` can run at the control period
    `time_step`: omega_f below the Nyquist rate pi / h, and h > 0 when the
    filter is bypassed (a one-period hold).

    Args:
        params: BaseFilterParameters.
        time_step: the control period h in s, >= 0; 0 gives the
            continuous filter, > 0 its exact zero-order-hold
            discretisation.
        prefix: how the message names the fields of `params` (e.g.
            "base_filter." for ControllerParameters.base_filter).

    Returns:
        time_step, as a float.

    Raises:
        ValueError: naming time_step, its value, the field it conflicts
            with and what is allowed.
    """
    h = non_negative("time_step", time_step)
    if not params.enabled and h == 0.0:
        raise ValueError(
            f"time_step = 0 is not allowed with {prefix}enabled = False: "
            "the bypassed filter is a one-period hold, which needs a "
            "control period > 0")
    if h > 0.0 and params.omega_f >= np.pi / h:
        raise ValueError(
            f"time_step = {h!r} s is not allowed with {prefix}omega_f = "
            f"{params.omega_f!r} rad/s: the filter's cut-off must be below "
            f"the Nyquist rate pi / time_step = {np.pi / h:.6g} rad/s")
    return h


def lowpass_state_space(omega_f, zeta):
    """Returns (A, B, C, D) of one axis of eq. (filtering), continuous."""
    w = positive("omega_f", omega_f)
    z = positive("zeta", zeta)
    A = np.array([[0.0, 1.0], [-w * w, -2.0 * z * w]])
    B = np.array([[0.0], [w * w]])
    C = np.array([[1.0, 0.0]])
    D = np.zeros((1, 1))
    return A, B, C, D


def zero_order_hold(A, B, time_step):
    """Returns (A_d, B_d): the exact discretisation of x_dot = A x + B u for
    an input held constant over each period `time_step`.

    Both come from one matrix exponential of [[A, B], [0, 0]] h.

    Args:
        A: (n, n) finite.
        B: (n, m) finite.
        time_step: h > 0, s.

    Raises:
        ValueError: naming the argument whose shape or value is not
            allowed.
    """
    h = positive("time_step", time_step)
    A = square_matrix("A", A)
    n = A.shape[0]
    B = as_matrix("B", B, (n, None))
    m = B.shape[1]
    augmented = np.zeros((n + m, n + m))
    augmented[:n, :n] = A
    augmented[:n, n:] = B
    transition = expm(augmented * h)
    return transition[:n, :n], transition[:n, n:]


def base_filter_model(params, time_step, axes=3):
    """(A, B, C) of the base filter of eq. (filtering) on `axes` axes, as
    its stage runs it: the state [y, y_dot] per axis, axes stacked (for
    the base's [vx, vx_dot, vy, vy_dot, wz, wz_dot]), no direct
    feedthrough (D = 0).

    - time_step = 0: the continuous filter, x_dot = A x + B u
      (lowpass_state_space on each axis);
    - time_step = h > 0: its exact zero-order hold, x+ = A x + B u
      (zero_order_hold);
    - params.enabled False (h > 0): the bypass, x+ = [u, 0] per axis,
      y = u sampled and held.

    Args:
        params: BaseFilterParameters; `time_step` checked against them
            (check_filter_period).
        time_step: the control period h in s, >= 0.
        axes: how many axes, each filtered alike.

    Returns:
        (A, B, C): float arrays (2 axes, 2 axes), (2 axes, axes),
        (axes, 2 axes).
    """
    h = check_filter_period(params, time_step)
    A, B, C, _ = lowpass_state_space(params.omega_f, params.zeta)
    eye = np.eye(axes)
    A, B, C = np.kron(eye, A), np.kron(eye, B), np.kron(eye, C)
    if not params.enabled:
        return np.zeros_like(A), np.kron(eye, [[1.0], [0.0]]), C
    if h > 0.0:
        A, B = zero_order_hold(A, B, h)
    return A, B, C


def lowpass_response(omega_f, zeta, omega):
    """Frequency response of eq. (filtering) at angular frequencies `omega`
    (rad/s): omega_f^2 / (omega_f^2 - omega^2 + 2j zeta omega_f omega)."""
    w = positive("omega_f", omega_f)
    z = positive("zeta", zeta)
    s = 1j * np.asarray(omega, dtype=float)
    return w * w / (s * s + 2.0 * z * w * s + w * w)


MERGED_POLES = 1e-10
"""|a1^2 - 4 a2 a0| / a1^2 at or below which the held second order's
closed forms take its poles for a double pole: there the partial
fractions of two poles p_1, p_2 lose digits as 1 / (p_1 - p_2) (half
of them when the discriminant is a rounding away from 0, as a
critically damped DMP's is at most tau), and the double pole's form
(of the same a0 / a2) is exact to O(a1^2 - 4 a2 a0) (relative). Each is
taken on its own side: either way the response is exact to about 1e-10
of its peak (zeta swept through 1 +- 1e-14 to 1e-2; where the gain is
small, towards the Nyquist frequency, the error relative to the gain
there is larger)."""


def lowpass_zoh_response(omega_f, zeta, time_step, omega):
    """Frequency response of the exact zero-order-hold equivalent of
    eq. (filtering) at angular frequencies `omega` (rad/s), z = e^(j omega h).

    From H_d(z) = (1 - z^-1) Z{H(s)/s}, in closed form:
    - zeta = 1 (double pole at -omega_f, q = e^(-omega_f h)):
      H_d = 1 - (z - 1)/(z - q) - omega_f h q (z - 1)/(z - q)^2;
    - zeta != 1 (poles p_1 != p_2, residues r_i = omega_f^2 /
      (p_i (p_i - p_j)) of H(s)/s): H_d = 1 + sum_i r_i (z - 1)/(z - e^(p_i h)).
    The second form loses digits as zeta approaches 1 (the residues grow
    as 1 / (p_1 - p_2)), so the first is taken for |zeta^2 - 1| <=
    MERGED_POLES zeta^2 too, where it is the better of the two: exact to
    about 1e-10 of the response's peak for every zeta.
    """
    w = positive("omega_f", omega_f)
    z_ratio = positive("zeta", zeta)
    h = positive("time_step", time_step)
    z = np.exp(1j * np.asarray(omega, dtype=float) * h)
    if abs(z_ratio * z_ratio - 1.0) <= MERGED_POLES * z_ratio * z_ratio:
        q = np.exp(-w * h)
        return 1.0 - (z - 1.0) / (z - q) - w * h * q * (z - 1.0) / (z - q) ** 2
    root = np.sqrt(complex(z_ratio * z_ratio - 1.0))
    poles = (-z_ratio * w + w * root, -z_ratio * w - w * root)
    response = np.ones_like(z)
    for p_i, p_j in (poles, poles[::-1]):
        residue = w * w / (p_i * (p_i - p_j))
        response = response + residue * (z - 1.0) / (z - np.exp(p_i * h))
    return response

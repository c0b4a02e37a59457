"""The local workspace of intuitive pHRI and its penalties (paper Sec. IV-C,
"Local Workspace").

In the intuitive pHRI mode the arm alone follows the person's guidance while
the end effector stays in a local workspace in front of the arm, and the
base takes over as it leaves it. The workspace is bounded by the extent d
and the deflection angle phi of the end effector w.r.t. the arm's base.
The capability of movement C_m is penalized as d crosses [d^l, d^u] and phi
crosses [phi^l, phi^u], with the transition alpha of eq. (transition):

    P_d = alpha(d, d^u, d^l),  P_phi = alpha(phi, phi^u, phi^l),
    C_m^d = C_m P_d P_phi,     C_m^phi = C_m P_phi,

from which the weighting factors of the intuitive pHRI mode follow
(drake_wbc.math.adaptive_weighting).

Definitions used here (the paper names d and phi but does not define them;
p = [x, y, z] is the end effector's position in the arm's base frame T_a):

- d = sqrt(x^2 + y^2), the horizontal distance of the end effector from the
  arm base's z axis. Horizontal because the base moves in the plane only:
  its motion changes the planar offset between arm base and end effector,
  not the height, so a distance that counted the height would hand the
  planar motion to the base for a reach it cannot relieve (a raised or
  lowered tool). Seen from above, the workspace is the sector of radius
  d_th and half-angle phi_th around the arm's forward axis, the cone of
  Fig. (local_ws).
- phi = |atan2(y, x)| in [0, pi], the magnitude of the end effector's
  azimuth about the arm base's z axis, from its x axis (the arm's forward
  direction, where the arm of our robot points at home). The magnitude,
  because the workspace is symmetric to the left and the right.
- Gradients are w.r.t. the arm's Cartesian pose, ordered and expressed
  like V_a ([linear; angular], T_a), like grad_x C_m: grad_x d =
  [x/d, y/d, 0, 0_3], grad_x phi = s [-y, x, 0, 0_3] / d^2 with s the sign
  of y (phi = |azimuth|).
- On the axis itself (d below `AXIS_TOLERANCE`) phi is 0 and neither d nor
  phi has a gradient; 0 is used for both. phi has a kink at y = 0, where
  P_phi is flat (phi = 0 < phi^l for x > 0) or 0 (phi = pi), so C_m^d and
  C_m^phi stay differentiable there.

For our robot, home puts the tool centre point at d = 0.736 m and phi = 0
(the arm base is 0.2 m ahead of the base's centre), just inside the paper's
d^l = 0.75 m: the paper's limits on our tool make the local workspace about
as deep as the home reach.

Every function here takes float values or AutoDiffXd scalars (numpy object
arrays) alike: only elementwise numpy, comparisons and Python branches, no
conversion to float, so the Drake systems over them can be converted to
AutoDiffXd. Parameters are plain floats, checked.
"""

import numbers
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from drake_wbc.math.validation import (
    as_scalar,
    as_vector,
    checked_instance,
    in_closed_range,
    non_negative,
    rotation_matrix,
)

AXIS_TOLERANCE = 1e-9
"""Horizontal distance (m) from the arm base's z axis below which the end
effector counts as on the axis: phi = 0 and no gradient of d or phi."""


def _ordered(lower_name, lower, upper_name, upper):
    """Checks that lower < upper (both finite) and returns them."""
    lower = as_scalar(lower_name, lower)
    upper = as_scalar(upper_name, upper)
    if not lower < upper:
        raise ValueError(
            f"{lower_name} = {lower!r} and {upper_name} = {upper!r} are not "
            f"allowed: {lower_name} must be strictly below {upper_name}"
        )
    return lower, upper


@dataclass
class LocalWorkspace:
    """The boundaries of the local workspace (Sec. IV-C, "Local Workspace").

    Attributes:
        extent_lower: d^l in m, >= 0: the penalty P_d starts below 1 here.
        extent_upper: d^u in m, > d^l: P_d is 0 from here on.
        deflection_lower: phi^l in rad, >= 0.
        deflection_upper: phi^u in rad, > phi^l and <= pi.

    The defaults are the paper's pHRI experiment: d^l = 0.75 m,
    d^u = 0.8 m, phi^l = 30 deg, phi^u = 35 deg.
    """

    extent_lower: float = 0.75
    extent_upper: float = 0.8
    deflection_lower: float = np.radians(30.0)
    deflection_upper: float = np.radians(35.0)

    def __post_init__(self):
        non_negative("extent_lower", self.extent_lower)
        _ordered("extent_lower", self.extent_lower,
                 "extent_upper", self.extent_upper)
        non_negative("deflection_lower", self.deflection_lower)
        _ordered("deflection_lower", self.deflection_lower,
                 "deflection_upper", self.deflection_upper)
        in_closed_range("deflection_upper", self.deflection_upper,
                        0.0, np.pi)


def _vector(name, value, size):
    """`value` as a vector of `size`: checked floats, or an object array
    (AutoDiffXd) of the right shape."""
    array = np.asarray(value)
    if array.dtype == object:
        if array.shape != (size,):
            raise ValueError(
                f"{name} has shape {array.shape}, which is not allowed: "
                f"must have shape ({size},)"
            )
        return array
    return as_vector(name, array, size)


def _scalar(name, value):
    """`value` as a scalar (float checked; AutoDiffXd passed through)."""
    if np.ndim(value) != 0:
        raise ValueError(
            f"{name} has shape {np.shape(value)}, which is not allowed: "
            "must be a single number"
        )
    if isinstance(value, np.ndarray):
        value = value[()]
    if isinstance(value, numbers.Real):
        return as_scalar(name, value)
    return value


def _zero_like(value):
    """0 of the scalar type of `value` (a float, or AutoDiffXd 0 with zero
    derivatives)."""
    return value * 0.0


def smooth_transition(value, upper, lower):
    """alpha(value, upper, lower) of eq. (transition), for any scalar type.

        1 for value <= lower, 0 for value >= upper,
        0.5 (1 + cos(pi (value - lower) / (upper - lower))) in between.

    The same function as `capability.transition` (which takes floats only),
    written so that AutoDiffXd passes through.

    Args:
        value: a float or AutoDiffXd scalar.
        upper, lower: floats, lower < upper.

    Returns:
        alpha in [0, 1], of the scalar type of `value`.
    """
    value = _scalar("value", value)
    lower, upper = _ordered("lower", lower, "upper", upper)
    if value <= lower:
        return _zero_like(value) + 1.0
    if value >= upper:
        return _zero_like(value)
    return 0.5 * (1.0 + np.cos(np.pi * (value - lower) / (upper - lower)))


def smooth_transition_derivative(value, upper, lower):
    """d alpha / d value of eq. (transition), for any scalar type: -0.5 pi /
    (upper - lower) sin(pi x) inside the band, 0 outside (as
    `capability.transition_derivative`, which takes floats only)."""
    value = _scalar("value", value)
    lower, upper = _ordered("lower", lower, "upper", upper)
    if value <= lower or value >= upper:
        return _zero_like(value)
    width = upper - lower
    return -0.5 * np.pi / width * np.sin(np.pi * (value - lower) / width)


def in_arm_base(p_ee_in_base, R_ba=None, arm_base_in_base=None):
    """The end-effector position in T_a: ^aR_b (p_ee - p_a), with p_a the
    arm base's origin in T_b.

    Args:
        p_ee_in_base: (3,) end-effector position in T_b (m).
        R_ba: (3, 3) rotation ^bR_a, or None for the identity.
        arm_base_in_base: (3,) origin of T_a in T_b (m), or None for 0.

    Returns:
        (3,) position in T_a, of the scalar type of p_ee_in_base.
    """
    p = _vector("p_ee_in_base", p_ee_in_base, 3)
    R = np.eye(3) if R_ba is None else rotation_matrix("R_ba", R_ba)
    origin = (np.zeros(3) if arm_base_in_base is None
              else as_vector("arm_base_in_base", arm_base_in_base, 3))
    return R.T @ (p - origin)


def _horizontal(p_in_arm_base):
    p = _vector("p_in_arm_base", p_in_arm_base, 3)
    x, y = p[0], p[1]
    return x, y, x * x + y * y


def _on_axis(d_squared):
    return d_squared <= AXIS_TOLERANCE**2


def extent(p_in_arm_base):
    """d: the horizontal distance of the end effector from the arm base's
    z axis, sqrt(x^2 + y^2) (m); see the module docstring."""
    _, _, d_squared = _horizontal(p_in_arm_base)
    if d_squared == 0.0:
        return d_squared  # sqrt has no derivative at 0; d^2 has 0 there
    return np.sqrt(d_squared)


def deflection(p_in_arm_base):
    """phi: |azimuth| of the end effector about the arm base's z axis from
    its x axis, |atan2(y, x)| in [0, pi] (rad); 0 on the axis."""
    x, y, d_squared = _horizontal(p_in_arm_base)
    if _on_axis(d_squared):
        return _zero_like(x)
    azimuth = np.arctan2(y, x)
    return -azimuth if azimuth < 0.0 else azimuth


def extent_gradient(p_in_arm_base):
    """grad_x d (6,), ordered like V_a: [x/d, y/d, 0, 0, 0, 0]; 0 on the
    axis."""
    x, y, d_squared = _horizontal(p_in_arm_base)
    zero = _zero_like(x)
    if _on_axis(d_squared):
        return np.array([zero] * 6)
    d = np.sqrt(d_squared)
    return np.array([x / d, y / d] + [zero] * 4)


def deflection_gradient(p_in_arm_base):
    """grad_x phi (6,), ordered like V_a: sign(y) [-y, x, 0, 0_3] / d^2
    (phi = |azimuth|); 0 on the axis and at y = 0."""
    x, y, d_squared = _horizontal(p_in_arm_base)
    zero = _zero_like(x)
    if _on_axis(d_squared) or y == 0.0:
        return np.array([zero] * 6)
    sign = 1.0 if y > 0.0 else -1.0
    return np.array([-sign * y / d_squared, sign * x / d_squared]
                    + [zero] * 4)


def workspace_penalties(p_in_arm_base, workspace=None):
    """(P_d, P_phi) = (alpha(d, d^u, d^l), alpha(phi, phi^u, phi^l)).

    Args:
        p_in_arm_base: (3,) end-effector position in T_a.
        workspace: LocalWorkspace; the paper's if None.
    """
    ws = checked_instance("workspace", workspace, LocalWorkspace,
                          LocalWorkspace)
    P_d = smooth_transition(extent(p_in_arm_base), ws.extent_upper,
                            ws.extent_lower)
    P_phi = smooth_transition(deflection(p_in_arm_base),
                              ws.deflection_upper, ws.deflection_lower)
    return P_d, P_phi


class PenalizedCapability(NamedTuple):
    """C_m penalized by the local workspace, and its Cartesian gradients
    (6,) in T_a, ordered like V_a (see penalized_capability)."""

    C_m_d: object
    C_m_phi: object
    gradient_d: np.ndarray
    gradient_phi: np.ndarray


def penalized_capability(C_m, grad_C_m, p_in_arm_base, workspace=None):
    """C_m^d = C_m P_d P_phi and C_m^phi = C_m P_phi with their gradients.

        grad C_m^d   = P_d P_phi grad C_m
                       + C_m (P_d' P_phi grad d + P_d P_phi' grad phi),
        grad C_m^phi = P_phi grad C_m + C_m P_phi' grad phi,

    with P' the derivative of the transition w.r.t. its argument (d or
    phi) and grad d, grad phi from `extent_gradient`, `deflection_gradient`.

    Args:
        C_m: capability of movement (scalar).
        grad_C_m: (6,) grad_x C_m, ordered and expressed like V_a (T_a).
        p_in_arm_base: (3,) end-effector position in T_a.
        workspace: LocalWorkspace; the paper's if None.

    Returns:
        PenalizedCapability.
    """
    ws = checked_instance("workspace", workspace, LocalWorkspace,
                          LocalWorkspace)
    C_m = _scalar("C_m", C_m)
    g = _vector("grad_C_m", grad_C_m, 6)
    d = extent(p_in_arm_base)
    phi = deflection(p_in_arm_base)
    P_d = smooth_transition(d, ws.extent_upper, ws.extent_lower)
    P_phi = smooth_transition(phi, ws.deflection_upper, ws.deflection_lower)
    dP_d = smooth_transition_derivative(d, ws.extent_upper, ws.extent_lower)
    dP_phi = smooth_transition_derivative(phi, ws.deflection_upper,
                                          ws.deflection_lower)
    grad_d = extent_gradient(p_in_arm_base)
    grad_phi = deflection_gradient(p_in_arm_base)
    gradient_phi = P_phi * g + (C_m * dP_phi) * grad_phi
    gradient_d = P_d * gradient_phi + (C_m * P_phi * dP_d) * grad_d
    return PenalizedCapability(C_m * P_d * P_phi, C_m * P_phi,
                               gradient_d, gradient_phi)

"""Motion modes and the local workspace of intuitive pHRI (paper Sec. IV-C).

The weighting factors sigma_xy, sigma_phi of eq. (weight-factors) select a
motion mode, Table (T:motion-mode):

    locomotion         sigma_xy = sigma_phi = 0        (base only)
    manipulation       sigma_xy = sigma_phi = 1        (arm only)
    loco-manipulation  0 < sigma_xy, sigma_phi < 1     (fixed, both)
    intuitive pHRI     sigma_xy,phi = f_xy,phi(q_a)    (adaptive)

In the intuitive pHRI mode the arm alone follows the person's guidance while
the end effector stays in a local workspace in front of the arm, and the
base takes over as it leaves it. The workspace is bounded by the extent d
and the deflection angle phi of the end effector w.r.t. the arm's base.
The capability of movement C_m is penalized as d crosses [d^l, d^u] and phi
crosses [phi^l, phi^u], with the transition alpha of eq. (transition):

    P_d = alpha(d, d^u, d^l),  P_phi = alpha(phi, phi^u, phi^l),
    C_m^d = C_m P_d P_phi,     C_m^phi = C_m P_phi,
    f_xy = 1 - alpha(C_m^d, C_m^u, C_m^l),
    f_phi = 1 - alpha(C_m^phi, C_m^u, C_m^l),

so f = 1 inside the workspace (with C_m above C_m^u), 0 outside it (or with
C_m below C_m^l), and in between across the boundaries. f falls from 1 to 0
where C_m P_d (or C_m P_phi) crosses [C_m^l, C_m^u], a slice of
[d^l, d^u] (or [phi^l, phi^u]) that is the narrower the larger C_m is: at
C_m = 0.06, d from 0.7696 to 0.7723 m and phi from 31.96 to 32.23 deg with
the paper's values, a steep ramp (still C^1). The deactivation
strategy then gives the motion back to the arm when it leads back:

    sigma = 1    if grad_x C_m^(d,phi) . V_ee > 0  or  d_dot (phi_dot) < 0,
    sigma = f    otherwise

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
- d_dot and phi_dot are the rates that d and phi would have if the arm alone
  carried out the commanded twist V_ee: d_dot = grad d . v, phi_dot =
  grad phi . v with v the linear part of R_ba^T V_ee. phi_dot < 0 means
  moving back towards the forward axis (the magnitude decreasing), from
  either side. The same twist enters the test grad_x C_m^(d,phi) . V_ee.
- Gradients are w.r.t. the arm's Cartesian pose, ordered and expressed
  like V_a ([linear; angular], T_a), like grad_x C_m: grad_x d =
  [x/d, y/d, 0, 0_3], grad_x phi = s [-y, x, 0, 0_3] / d^2 with s the sign
  of y (phi = |azimuth|).
- On the axis itself (d below `AXIS_TOLERANCE`) phi is 0 and neither d nor
  phi has a gradient; 0 is used for both (and d_dot = phi_dot = 0). phi
  has a kink at y = 0, where P_phi is flat (phi = 0 < phi^l for x > 0) or
  0 (phi = pi), so C_m^d and C_m^phi stay differentiable there.

For our robot, home puts the tool centre point at d = 0.736 m and phi = 0
(the arm base is 0.2 m ahead of the base's centre), just inside the paper's
d^l = 0.75 m: the paper's limits on our tool make the local workspace about
as deep as the home reach.

Every function here takes float values or AutoDiffXd scalars (numpy object
arrays) alike: only elementwise numpy, comparisons and Python branches, no
conversion to float, so the Drake systems over them can be converted to
AutoDiffXd. Parameters are plain floats, checked. The one exception is
the per-tick path of the controller in double, `adaptive_weighting_factors`
(with its constants from `adaptive_workspace`): the same formulas as
`local_workspace_state`, in plain Python floats.
"""

import enum
import math
import numbers
import operator
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from drake_wbc.validation import (
    as_scalar,
    as_vector,
    checked_instance,
    in_closed_range,
    non_negative,
    rotation_matrix,
)

DEACTIVATION_TOLERANCE = 1e-9
"""The deactivation's tests count only beyond this cosine between the
commanded motion and the gradient (or the direction of growing d or phi):
a guard against rounding, not a dead band one could feel."""

AXIS_TOLERANCE = 1e-9
"""Horizontal distance (m) from the arm base's z axis below which the end
effector counts as on the axis: phi = 0 and no gradient of d or phi."""


class MotionMode(enum.StrEnum):
    """The motion modes of Table (T:motion-mode).

    A str enum: each member is also its name as a string (e.g.
    MotionMode.INTUITIVE_PHRI == "intuitive-phri"), which is how YAML
    files and WorkspaceAdapterParameters.mode carry it.
    """

    LOCOMOTION = "locomotion"
    MANIPULATION = "manipulation"
    LOCO_MANIPULATION = "loco-manipulation"
    INTUITIVE_PHRI = "intuitive-phri"

    @classmethod
    def parse(cls, mode):
        """Returns `mode` (a MotionMode or one of its names) as MotionMode.

        Raises:
            ValueError: naming `mode` and the allowed names.
        """
        if isinstance(mode, cls):
            return mode
        for member in cls:
            if mode == member.value:
                return member
        names = ", ".join(repr(m.value) for m in cls)
        raise ValueError(
            f"mode = {mode!r} is not allowed: must be a MotionMode or one "
            f"of {names}"
        )


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


def adaptive_factor(C_m_penalized, capability_upper, capability_lower):
    """f = 1 - alpha(C_m^(d,phi), C_m^u, C_m^l) (Sec. IV-C): f_xy from
    C_m^d, f_phi from C_m^phi."""
    return 1.0 - smooth_transition(C_m_penalized, capability_upper,
                                   capability_lower)


def _leads(covector, V, sign):
    """True if covector . V has the given sign, beyond the roundoff guard:
    (c . V)^2 > tol^2 |c|^2 |V|^2 (a cosine above DEACTIVATION_TOLERANCE),
    squared so that no square root of an AutoDiffXd 0 is taken."""
    product = np.dot(covector, V)
    if not sign * product > 0.0:
        return False
    scale = np.dot(covector, covector) * np.dot(V, V)
    return product * product > DEACTIVATION_TOLERANCE**2 * scale


def deactivated(factor, gradient, V_a, direction):
    """The deactivation strategy (Sec. IV-C, "Deactivation Strategy"):
    1 if gradient . V_a > 0 or the rate direction . v_a < 0 (d_dot or
    phi_dot), else `factor`.

    Both tests are strict up to a roundoff guard: the cosine between the
    two vectors must exceed DEACTIVATION_TOLERANCE in magnitude, so that a
    motion along the boundary (a purely tangential or vertical one) or
    none at all keeps sigma = f, whatever the rounding.

    Args:
        factor: f_xy or f_phi.
        gradient: (6,) grad_x C_m^d or grad_x C_m^phi (T_a).
        V_a: (6,) the commanded twist in T_a, R_ba^T V_ee.
        direction: (6,) grad_x d or grad_x phi (its angular part 0), whose
            product with V_a is d_dot or phi_dot.
    """
    g = _vector("gradient", gradient, 6)
    V = _vector("V_a", V_a, 6)
    n = _vector("direction", direction, 6)
    if _leads(g, V, 1.0) or _leads(n[:3], V[:3], -1.0):
        return _zero_like(factor) + 1.0
    return factor


class LocalWorkspaceState(NamedTuple):
    """Every quantity of the intuitive pHRI mode at one instant (see
    local_workspace_state); twists and gradients (6,) in T_a."""

    d: object
    phi: object
    d_rate: object
    phi_rate: object
    P_d: object
    P_phi: object
    capability: PenalizedCapability
    f_xy: object
    f_phi: object
    sigma_xy: object
    sigma_phi: object


def local_workspace_state(p_ee_in_base, V_ee, C_m, grad_C_m,
                          capability_upper, capability_lower,
                          workspace=None, R_ba=None, arm_base_in_base=None):
    """The weighting factors of the intuitive pHRI mode (Sec. IV-C).

    Args:
        p_ee_in_base: (3,) end-effector position in T_b (m).
        V_ee: (6,) commanded end-effector twist [v; w] in T_b.
        C_m: capability of movement.
        grad_C_m: (6,) grad_x C_m (T_a, ordered like V_a).
        capability_upper, capability_lower: C_m^u > C_m^l of eq.
            (transition).
        workspace: LocalWorkspace; the paper's if None.
        R_ba: (3, 3) ^bR_a, or None for the identity.
        arm_base_in_base: (3,) origin of T_a in T_b (m), or None for 0.

    Returns:
        LocalWorkspaceState; sigma_xy and sigma_phi are the weighting
        factors, after the deactivation strategy.
    """
    ws = checked_instance("workspace", workspace, LocalWorkspace,
                          LocalWorkspace)
    p = in_arm_base(p_ee_in_base, R_ba, arm_base_in_base)
    V = _vector("V_ee", V_ee, 6)
    R = np.eye(3) if R_ba is None else rotation_matrix("R_ba", R_ba)
    V_a = np.concatenate([R.T @ V[:3], R.T @ V[3:]])
    grad_d = extent_gradient(p)
    grad_phi = deflection_gradient(p)
    P_d, P_phi = workspace_penalties(p, ws)
    penalized = penalized_capability(C_m, grad_C_m, p, ws)
    f_xy = adaptive_factor(penalized.C_m_d, capability_upper,
                           capability_lower)
    f_phi = adaptive_factor(penalized.C_m_phi, capability_upper,
                            capability_lower)
    return LocalWorkspaceState(
        d=extent(p),
        phi=deflection(p),
        d_rate=np.dot(grad_d, V_a),
        phi_rate=np.dot(grad_phi, V_a),
        P_d=P_d,
        P_phi=P_phi,
        capability=penalized,
        f_xy=f_xy,
        f_phi=f_phi,
        sigma_xy=deactivated(f_xy, penalized.gradient_d, V_a, grad_d),
        sigma_phi=deactivated(f_phi, penalized.gradient_phi, V_a, grad_phi),
    )


def fixed_weighting_factors(mode, sigma_xy=0.5, sigma_phi=0.5):
    """(sigma_xy, sigma_phi) of the three fixed modes of Table
    (T:motion-mode): (0, 0) locomotion, (1, 1) manipulation, the given
    values (each in (0, 1)) loco-manipulation.

    Raises:
        ValueError: for the intuitive pHRI mode (see
            local_workspace_state), an unknown mode, or sigma outside
            (0, 1) in loco-manipulation.
    """
    mode = MotionMode.parse(mode)
    if mode is MotionMode.LOCOMOTION:
        return 0.0, 0.0
    if mode is MotionMode.MANIPULATION:
        return 1.0, 1.0
    if mode is MotionMode.LOCO_MANIPULATION:
        return (_open_unit("sigma_xy", sigma_xy),
                _open_unit("sigma_phi", sigma_phi))
    raise ValueError(
        f"mode = {mode.value!r} is not allowed here: its weighting factors "
        "are adaptive (local_workspace_state)"
    )


def _open_unit(name, value):
    number = in_closed_range(name, value, 0.0, 1.0)
    if number in (0.0, 1.0):
        raise ValueError(
            f"{name} = {number!r} is not allowed in loco-manipulation: must "
            "lie in (0, 1) (0 is locomotion, 1 manipulation)"
        )
    return number


# ----------------------------------------------------------------------------
# The per-tick path of the intuitive pHRI mode, in plain floats
# ----------------------------------------------------------------------------

class AdaptiveWorkspace(NamedTuple):
    """The constants of the intuitive pHRI mode, checked once (see
    `adaptive_workspace`), as plain floats for
    `adaptive_weighting_factors`.

    Attributes:
        capability_upper, capability_lower: C_m^u > C_m^l.
        extent: (d^l, d^u) in m.
        deflection: (phi^l, phi^u) in rad.
        R_ab_rows: ^aR_b = R_ba^T as three rows of three floats.
        R_ba: (3, 3) ^bR_a, checked.
        origin: (3,) origin of T_a in T_b (m), checked.
        workspace: the checked LocalWorkspace.
    """

    capability_upper: float
    capability_lower: float
    extent: tuple
    deflection: tuple
    R_ab_rows: tuple
    R_ba: np.ndarray
    origin: np.ndarray
    workspace: LocalWorkspace


def adaptive_workspace(capability_upper, capability_lower, workspace=None,
                       R_ba=None, arm_base_in_base=None):
    """Checks the parameters of `local_workspace_state` once, for
    `adaptive_weighting_factors`.

    Args:
        capability_upper, capability_lower: C_m^u > C_m^l of eq.
            (transition).
        workspace: LocalWorkspace; the paper's if None.
        R_ba: (3, 3) ^bR_a, or None for the identity.
        arm_base_in_base: (3,) origin of T_a in T_b (m), or None for 0.

    Returns:
        AdaptiveWorkspace.
    """
    lower, upper = _ordered("capability_lower", capability_lower,
                            "capability_upper", capability_upper)
    ws = checked_instance("workspace", workspace, LocalWorkspace,
                          LocalWorkspace)
    R = np.eye(3) if R_ba is None else rotation_matrix("R_ba", R_ba)
    origin = (np.zeros(3) if arm_base_in_base is None
              else as_vector("arm_base_in_base", arm_base_in_base, 3))
    return AdaptiveWorkspace(
        capability_upper=upper,
        capability_lower=lower,
        extent=(float(ws.extent_lower), float(ws.extent_upper)),
        deflection=(float(ws.deflection_lower), float(ws.deflection_upper)),
        R_ab_rows=tuple(tuple(row) for row in R.T.tolist()),
        R_ba=R,
        origin=origin,
        workspace=ws,
    )


def _alpha(value, upper, lower):
    """alpha of eq. (transition) and its derivative at a float value, as
    `smooth_transition` and `smooth_transition_derivative`."""
    if value <= lower:
        return 1.0, 0.0
    if value >= upper:
        return 0.0, 0.0
    width = upper - lower
    return (0.5 * (1.0 + math.cos(math.pi * (value - lower) / width)),
            -0.5 * math.pi / width * math.sin(math.pi * (value - lower)
                                               / width))


def _float_leads(covector, V, sign):
    """`_leads` for sequences of floats of one length."""
    product = sum(map(operator.mul, covector, V))
    if not sign * product > 0.0:
        return False
    scale = (sum(map(operator.mul, covector, covector))
             * sum(map(operator.mul, V, V)))
    return product * product > DEACTIVATION_TOLERANCE**2 * scale


def adaptive_weighting_factors(p_ee_in_base, V_ee, C_m, grad_C_m,
                               constants):
    """(sigma_xy, sigma_phi) of `local_workspace_state` for float inputs,
    in plain floats: the per-tick path of the controller's
    WorkspaceAdapter in the intuitive pHRI mode (Sec. IV-C).

    The same values as `local_workspace_state`, from the same formulas
    (see its docstring and the module's) and the same elementary
    functions, to the last bit but for the commanded twist in T_a and the
    dot products of the deactivation tests (summed in another order,
    which can only matter within the tests' roundoff guard). The
    position in T_a comes from the same numpy product as there: the sign
    of its y coordinate decides, at phi = pi, which way phi grows, which
    the deactivation's rate test reads. The constants were
    checked by `adaptive_workspace`; the inputs are not checked entry by
    entry, but inputs that are not all finite are handed to
    `local_workspace_state`, which names the bad one in its ValueError.

    Args:
        p_ee_in_base: (3,) float array, the end-effector position in T_b
            (m).
        V_ee: six floats, the commanded twist [v; w] in T_b.
        C_m: the capability of movement, a float.
        grad_C_m: six floats, grad_x C_m (T_a, ordered like V_a).
        constants: AdaptiveWorkspace.

    Returns:
        (sigma_xy, sigma_phi), floats in [0, 1].
    """
    c = constants
    p = np.asarray(p_ee_in_base, dtype=float)
    if not math.isfinite(C_m + sum(p.tolist()) + sum(V_ee) + sum(grad_C_m)):
        state = local_workspace_state(
            p_ee_in_base, V_ee, C_m, grad_C_m, c.capability_upper,
            c.capability_lower, c.workspace, c.R_ba, c.origin)
        return float(state.sigma_xy), float(state.sigma_phi)
    x, y, _ = (c.R_ba.T @ (p - c.origin)).tolist()
    rows = c.R_ab_rows
    V_a = [r[0] * V_ee[k] + r[1] * V_ee[k + 1] + r[2] * V_ee[k + 2]
           for k in (0, 3) for r in rows]
    d_squared = x * x + y * y
    if d_squared <= AXIS_TOLERANCE**2:  # on the axis: no gradients
        d = 0.0 if d_squared == 0.0 else math.sqrt(d_squared)
        phi = grad_d_x = grad_d_y = grad_phi_x = grad_phi_y = 0.0
    else:
        d = math.sqrt(d_squared)
        # numpy's arctan2, as deflection: math.atan2 differs in the last
        # bit for some arguments, which the steep ramps of f would show.
        phi = abs(float(np.arctan2(y, x)))
        grad_d_x, grad_d_y = x / d, y / d
        sign = 0.0 if y == 0.0 else (1.0 if y > 0.0 else -1.0)
        grad_phi_x = -sign * y / d_squared
        grad_phi_y = sign * x / d_squared
    P_d, dP_d = _alpha(d, c.extent[1], c.extent[0])
    P_phi, dP_phi = _alpha(phi, c.deflection[1], c.deflection[0])
    # The penalized capabilities and their gradients (penalized_capability).
    scale_phi = C_m * dP_phi
    scale_d = C_m * P_phi * dP_d
    gradient_phi = [P_phi * g for g in grad_C_m]
    gradient_phi[0] += scale_phi * grad_phi_x
    gradient_phi[1] += scale_phi * grad_phi_y
    gradient_d = [P_d * g for g in gradient_phi]
    gradient_d[0] += scale_d * grad_d_x
    gradient_d[1] += scale_d * grad_d_y
    upper, lower = c.capability_upper, c.capability_lower
    f_xy = 1.0 - _alpha(C_m * P_d * P_phi, upper, lower)[0]
    f_phi = 1.0 - _alpha(C_m * P_phi, upper, lower)[0]
    # The deactivation strategy (deactivated).
    linear = V_a[:3]
    sigma_xy = (1.0 if _float_leads(gradient_d, V_a, 1.0)
                or _float_leads((grad_d_x, grad_d_y, 0.0), linear, -1.0)
                else f_xy)
    sigma_phi = (1.0 if _float_leads(gradient_phi, V_a, 1.0)
                 or _float_leads((grad_phi_x, grad_phi_y, 0.0), linear, -1.0)
                 else f_phi)
    return sigma_xy, sigma_phi

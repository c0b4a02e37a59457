"""The local workspace of intuitive pHRI, its penalties, the adaptive
weighting factors and the deactivation strategy (paper Sec. IV-C).

In the intuitive pHRI mode the arm alone follows the person's guidance while
the end effector stays in a local workspace in front of the arm, and the
base takes over as it leaves it: the weighting factors of eq.
(weight-factors) follow the arm's configuration, sigma_xy,phi =
f_xy,phi(q_a) (Table (T:motion-mode)). The workspace is bounded by the
extent d and the deflection angle phi of the end effector w.r.t. the arm's
base ("Local Workspace"). The capability of movement C_m is penalized as d
crosses [d^l, d^u] and phi crosses [phi^l, phi^u], with the transition
alpha of eq. (transition) (drake_wbc.math.capability):

    P_d = alpha(d, d^u, d^l),  P_phi = alpha(phi, phi^u, phi^l),
    C_m^d = C_m P_d P_phi,     C_m^phi = C_m P_phi,
    f_xy = 1 - alpha(C_m^d, C_m^u, C_m^l),
    f_phi = 1 - alpha(C_m^phi, C_m^u, C_m^l),

so f = 1 inside the workspace (with C_m above C_m^u), 0 outside it (or with
C_m below C_m^l), and in between across the boundaries. f falls from 1 to 0
where C_m P_d (or C_m P_phi) crosses [C_m^l, C_m^u], a slice of
[d^l, d^u] (or [phi^l, phi^u]) that is the narrower the larger C_m is: at
C_m = 0.06, d from 0.7696 to 0.7723 m and phi from 31.96 to 32.23 deg with
the paper's values, a steep ramp (still C^1). The deactivation strategy
("Deactivation Strategy") then gives the motion back to the arm when it
leads back:

    sigma = 1    if grad_x C_m^(d,phi) . V_ee > 0  or  d_dot (phi_dot) < 0,
    sigma = f    otherwise

Applied tick by tick, that rule is discontinuous: where f = 0 (outside the
workspace) a twist that turns from leading out to leading back, by a hair,
throws sigma from 0 to 1 and back, and the sensor's noise at rest (the hand
has let go at the boundary) does so at the control rate (417 jumps of
sigma_xy in the 53 s `phri` run). The paper speaks of a smooth transition.
The weighting factors of the stage are therefore the rule above with
hysteresis and a rate limit (`adaptive_weighting_factors`, a function of
the previous tick's factors and sides and of this tick's inputs):

- Hysteresis on which side of the rule one is ("deactivated", sigma's
  target 1, or not, target f), per factor. Each test of the rule is read
  as a speed: s = c . V / |c|, the commanded twist's component along the
  test's covector c (grad_x C_m^(d,phi), or -grad d and -grad phi, whose
  products with the linear part of V_a are -d_dot and -phi_dot; for phi
  the tangential speed d phi_dot). The deactivation sets in when a test
  leads back faster than `deactivation_speed` v_h (s > v_h), and ends only
  when every test leads out (s < 0); in between (0 <= s <= v_h for some
  test, a motion at rest or along the boundary among them) the side of
  the last tick is kept. The band is one-sided on purpose: leaving needs
  no speed, so that a slow push outwards never keeps the arm alone in
  charge beyond the boundary (the base takes over outside the workspace
  as soon as the motion leads out); entering needs v_h, so that noise
  smaller than v_h cannot give the motion back to the arm. A test with a
  zero covector (on the axis, or phi at y = 0) cannot lead back and counts
  as leading out. With v_h = 0 the side is the paper's rule but where no
  test leads back and one lies within the roundoff guard (a twist at rest,
  or exactly along the boundary), where the side is kept; from the side
  "not deactivated" it is the paper's rule exactly.
- A rate limit on sigma: sigma_k = sigma_{k-1} + clip(target_k -
  sigma_{k-1}, -Delta, Delta) with Delta = `max_rate` h, so sigma changes
  by at most max_rate h per tick (0.1 with the defaults at 100 Hz, 0 to 1
  in 0.1 s, half the base's own 0.2 s lag). The arm then carries its
  share for at most 1 / max_rate after the boundary is crossed: at a
  hand's 0.2 m/s at most 0.2 / (2 max_rate) = 1 cm further out than the
  paper's rule would let it (5 /s let the tool of `phri` reach 13 mm
  further in stage B and C_m the band, 0.037); and when the motion leads
  back the arm takes it over within 1 / max_rate, so the robot never
  locks at the boundary.

With v_h = 0 and max_rate h >= 1 the factors are those of the paper's
rule but for the side kept at rest (one tick from the start state,
WEIGHTING_START, exactly those); the paper's experiment with the
defaults (v_h = 0.02 m/s, max_rate = 10 /s) is in the README.

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
- d_dot and phi_dot are the rates that d and phi would have if the arm
  alone carried out the commanded twist V_ee: d_dot = grad d . v, phi_dot
  = grad phi . v with v the linear part of R_ba^T V_ee. phi_dot < 0 means
  moving back towards the forward axis (the magnitude decreasing), from
  either side. The same twist enters the test grad_x C_m^(d,phi) . V_ee.

For our robot, home puts the tool centre point at d = 0.736 m and phi = 0
(the arm base is 0.2 m ahead of the base's centre), just inside the paper's
d^l = 0.75 m: the paper's limits on our tool make the local workspace about
as deep as the home reach.

As in drake_wbc.math.capability: the reference bodies are scalar-generic
(float values or AutoDiffXd scalars in numpy object arrays: only
elementwise numpy, comparisons and Python branches) and unchecked, private
but for the tick's `adaptive_weighting_factors`; the public
functions of plain names check their arguments and call them;
`adaptive_weighting_factors_float` is the float kernel of the tick.
"""

import math
import numbers
import operator
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from drake_wbc.math.capability import (
    transition_derivative_float,
    transition_derivative_of,
    transition_float,
    transition_of,
)
from drake_wbc.math.kernels import fast_kernel
from drake_wbc.math.kinematics import random_rotation
from drake_wbc.math.motion_mode import MotionMode, fixed_weighting_factors
from drake_wbc.math.scalar_support import (
    constant_like,
    value_of,
    zero_like,
)
from drake_wbc.math.validation import (
    as_scalar,
    as_vector,
    checked_instance,
    in_closed_range,
    non_negative,
    positive,
    rotation_matrix,
)

AXIS_TOLERANCE = 1e-9
"""Horizontal distance (m) from the arm base's z axis below which the end
effector counts as on the axis: phi = 0 and no gradient of d or phi."""

DEACTIVATION_TOLERANCE = 1e-9
"""The deactivation's tests count only beyond this cosine between the
commanded motion and the gradient (or the direction of growing d or phi):
a guard against rounding, not a dead band one could feel."""

WEIGHTING_START = (1.0, 1.0, 0.0, 0.0)
"""The state of the weighting factors before the first tick:
(sigma_xy, sigma_phi, deactivated_xy, deactivated_phi) = the arm's
factors (the robot starts with its tool in the workspace, as at home) and
no deactivation; from a tool outside it sigma falls to f within
1 / max_rate at the start."""


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


# ----------------------------------------------------------------------------
# Parameters
# ----------------------------------------------------------------------------

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


@dataclass
class WorkspaceAdapterParameters:
    """Parameters of the WorkspaceAdapter stage: the weighting factors of a
    motion mode (Table (T:motion-mode)).

    Attributes:
        mode: a MotionMode or its name, 'locomotion', 'manipulation',
            'loco-manipulation' or 'intuitive-phri' (Table T:motion-mode);
            stored as the MotionMode (a str enum, so that YAML gives the
            name).
        sigma_xy, sigma_phi: the fixed weighting factors of the
            loco-manipulation mode, in (0, 1) there (checked in [0, 1] in
            the other modes, which do not use them). The default 0.5 is the
            paper's trajectory-tracking experiment.
        workspace: the LocalWorkspace of the intuitive pHRI mode; None
            (the default): the robot's own (its description's tuning,
            drake_wbc.robot.description.RobotTuning), for the shipped
            robot the paper's d^l = 0.75, d^u = 0.8 m, phi^l = 30,
            phi^u = 35 deg.
        deactivation_speed: v_h in m/s (rad/s where the gradient's test
            reads an angular part of V_ee), >= 0, finite: the hysteresis
            of the deactivation strategy (intuitive pHRI; see the
            module): the motion must lead back faster than this for
            sigma's target to become 1, and the side is kept until every
            test leads out. Ours, 0.02 m/s (a hand's 0.4 N at k_hri =
            0.05): in the 53 s `phri` run, with the tool outside
            (f_xy = 0) and no push, the commanded twist's speed back
            stays within it but for one tick (0.021 m/s), and each
            deliberate pull back exceeds it within 0.1 s of its start;
            0 for the paper's rule (but at rest, where the side is
            kept).
        max_rate: the largest change of sigma_xy and sigma_phi per
            second, 1/s, > 0, finite (intuitive pHRI): sigma changes by
            at most max_rate * time_step per tick. Ours, 10 /s (0.1 a
            tick at 100 Hz, 0 to 1 in 0.1 s, half the base's own lag); at
            1 / time_step or more the paper's unlimited rule.

    The band C_m^l, C_m^u of f_xy and f_phi (intuitive pHRI) is the
    stage's `band` argument (one CapabilityBand for every stage that
    looks at C_m).
    """

    mode: str = MotionMode.LOCO_MANIPULATION
    sigma_xy: float = 0.5
    sigma_phi: float = 0.5
    workspace: LocalWorkspace | None = None
    deactivation_speed: float = 0.02
    max_rate: float = 10.0

    def __post_init__(self):
        self.mode = MotionMode.parse(self.mode)
        in_closed_range("sigma_xy", self.sigma_xy, 0.0, 1.0)
        in_closed_range("sigma_phi", self.sigma_phi, 0.0, 1.0)
        self.workspace = checked_instance(
            "workspace", self.workspace, LocalWorkspace, lambda: None)
        self.deactivation_speed = non_negative("deactivation_speed",
                                               self.deactivation_speed)
        self.max_rate = positive("max_rate", self.max_rate)
        if self.mode is MotionMode.LOCO_MANIPULATION:
            fixed_weighting_factors(self.mode, self.sigma_xy, self.sigma_phi)


class AdaptiveWorkspace(NamedTuple):
    """The constants of the intuitive pHRI mode, as plain floats (see
    `AdaptiveWorkspace.of`).

    Attributes:
        capability_upper, capability_lower: C_m^u > C_m^l.
        extent: (d^l, d^u) in m.
        deflection: (phi^l, phi^u) in rad.
        R_ab_rows: ^aR_b = R_ba^T as three rows of three floats.
        R_ba: (3, 3) ^bR_a.
        origin: (3,) origin of T_a in T_b (m).
        deactivation_speed: v_h >= 0, the hysteresis of the deactivation.
        max_step: the largest change of sigma in one tick, max_rate h
            (inf: no limit).
    """

    capability_upper: float
    capability_lower: float
    extent: tuple
    deflection: tuple
    R_ab_rows: tuple
    R_ba: np.ndarray
    origin: np.ndarray
    deactivation_speed: float = 0.0
    max_step: float = math.inf

    @classmethod
    def of(cls, capability_upper, capability_lower, workspace, R_ba,
           arm_base_in_base, deactivation_speed=0.0, max_step=math.inf):
        """The constants from parameters that were checked where they
        entered, nothing checked again: the band C_m^u > C_m^l (a
        CapabilityBand's), a LocalWorkspace, the rotation ^bR_a (3, 3) and
        the origin of T_a in T_b (3,) (the arm's mounting); the
        hysteresis v_h and the largest step of sigma a tick (the paper's
        rule by default: none and no limit)."""
        R = np.asarray(R_ba, dtype=float)
        return cls(
            capability_upper=float(capability_upper),
            capability_lower=float(capability_lower),
            extent=(float(workspace.extent_lower),
                    float(workspace.extent_upper)),
            deflection=(float(workspace.deflection_lower),
                        float(workspace.deflection_upper)),
            R_ab_rows=tuple(tuple(row) for row in R.T.tolist()),
            R_ba=R,
            origin=np.asarray(arm_base_in_base, dtype=float),
            deactivation_speed=float(deactivation_speed),
            max_step=float(max_step),
        )


# ----------------------------------------------------------------------------
# Reference bodies: scalar-generic, arguments not checked
# ----------------------------------------------------------------------------

def _horizontal(p):
    x, y = p[0], p[1]
    return x, y, x * x + y * y


def _on_axis(d_squared):
    return d_squared <= AXIS_TOLERANCE**2


def _extent(p):
    _, _, d_squared = _horizontal(p)
    if d_squared == 0.0:
        return d_squared  # sqrt has no derivative at 0; d^2 has 0 there
    return np.sqrt(d_squared)


def _deflection(p):
    x, y, d_squared = _horizontal(p)
    if _on_axis(d_squared):
        return zero_like(x)
    azimuth = np.arctan2(y, x)
    return -azimuth if azimuth < 0.0 else azimuth


def _extent_gradient(p):
    x, y, d_squared = _horizontal(p)
    zero = zero_like(x)
    if _on_axis(d_squared):
        return np.array([zero] * 6)
    d = np.sqrt(d_squared)
    return np.array([x / d, y / d] + [zero] * 4)


def _deflection_gradient(p):
    x, y, d_squared = _horizontal(p)
    zero = zero_like(x)
    if _on_axis(d_squared) or y == 0.0:
        return np.array([zero] * 6)
    sign = 1.0 if y > 0.0 else -1.0
    return np.array([-sign * y / d_squared, sign * x / d_squared]
                    + [zero] * 4)


def _penalties(p, extent, deflection):
    """(P_d, P_phi) = (alpha(d, d^u, d^l), alpha(phi, phi^u, phi^l)), the
    bands (d^l, d^u) and (phi^l, phi^u)."""
    return (transition_of(_extent(p), extent[1], extent[0]),
            transition_of(_deflection(p), deflection[1],
                                 deflection[0]))


def _penalized(C_m, g, p, extent, deflection):
    """PenalizedCapability (see `penalized_capability`)."""
    d, phi = _extent(p), _deflection(p)
    P_d = transition_of(d, extent[1], extent[0])
    P_phi = transition_of(phi, deflection[1], deflection[0])
    dP_d = transition_derivative_of(d, extent[1], extent[0])
    dP_phi = transition_derivative_of(phi, deflection[1],
                                             deflection[0])
    gradient_phi = P_phi * g + (C_m * dP_phi) * _deflection_gradient(p)
    gradient_d = P_d * gradient_phi + (C_m * P_phi * dP_d) * (
        _extent_gradient(p))
    return PenalizedCapability(C_m * P_d * P_phi, C_m * P_phi,
                               gradient_d, gradient_phi)


def _adaptive_factor(C_m_penalized, upper, lower):
    """f = 1 - alpha(C_m^(d,phi), C_m^u, C_m^l) (Sec. IV-C): f_xy from
    C_m^d, f_phi from C_m^phi."""
    return 1.0 - transition_of(C_m_penalized, upper, lower)


def _lead(covector, V, speed):
    """1 if the motion V leads back by the test of covector c faster than
    `speed` (c . V > speed |c|), -1 if it leads out (c . V < 0), 0 in
    between; both beyond the roundoff guard (c . V)^2 > tol^2 |c|^2 |V|^2
    (a cosine above DEACTIVATION_TOLERANCE), and all squared so that no
    square root of an AutoDiffXd 0 is taken. A zero covector cannot lead
    back: -1."""
    norm_squared = np.dot(covector, covector)
    if norm_squared == 0.0:
        return -1
    product = np.dot(covector, V)
    square = product * product
    guard = DEACTIVATION_TOLERANCE**2 * norm_squared * np.dot(V, V)
    if product > 0.0 and square > guard + speed * speed * norm_squared:
        return 1
    if product < 0.0 and square > guard:
        return -1
    return 0


def _side(previous, gradient, V_a, direction, speed):
    """The side of the deactivation strategy with hysteresis (see the
    module): 1 (deactivated) if a test leads back faster than `speed`, 0
    if both lead out, else `previous`; of the scalar type of `previous`
    (1 and 0 without derivatives, and exact even where `previous` is NaN:
    the tests decide the side whatever it was)."""
    leads = (_lead(gradient, V_a, speed),
             _lead(-direction[:3], V_a[:3], speed))
    if 1 in leads:
        return constant_like(previous, 1.0)
    if leads == (-1, -1):
        return constant_like(previous, 0.0)
    return previous


def _limited(previous, target, max_step):
    """previous + clip(target - previous, -max_step, max_step)."""
    change = target - previous
    if change > max_step:
        return previous + max_step
    if change < -max_step:
        return previous - max_step
    return target


def _deactivated(factor, gradient, V_a, direction):
    """The deactivation strategy (see `deactivated`)."""
    if _side(0.0, gradient, V_a, direction, 0.0) == 1.0:
        return zero_like(factor) + 1.0
    return factor


class PenalizedCapability(NamedTuple):
    """C_m penalized by the local workspace, and its Cartesian gradients
    (6,) in T_a, ordered like V_a (see penalized_capability)."""

    C_m_d: object
    C_m_phi: object
    gradient_d: np.ndarray
    gradient_phi: np.ndarray


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
    deactivated_xy: object
    deactivated_phi: object


def _state(previous, p_ee_in_base, V_ee, C_m, grad_C_m, constants):
    """LocalWorkspaceState (see `local_workspace_state`); `previous` the
    last tick's (sigma_xy, sigma_phi, deactivated_xy, deactivated_phi)."""
    c = constants
    R = c.R_ba
    p = R.T @ (p_ee_in_base - c.origin)
    V = np.asarray(V_ee)
    V_a = np.concatenate([R.T @ V[:3], R.T @ V[3:]])
    grad_d = _extent_gradient(p)
    grad_phi = _deflection_gradient(p)
    P_d, P_phi = _penalties(p, c.extent, c.deflection)
    penalized = _penalized(C_m, np.asarray(grad_C_m), p, c.extent,
                           c.deflection)
    upper, lower = c.capability_upper, c.capability_lower
    f_xy = _adaptive_factor(penalized.C_m_d, upper, lower)
    f_phi = _adaptive_factor(penalized.C_m_phi, upper, lower)
    speed = c.deactivation_speed
    side_xy = _side(previous[2], penalized.gradient_d, V_a, grad_d, speed)
    side_phi = _side(previous[3], penalized.gradient_phi, V_a, grad_phi,
                     speed)
    target_xy = zero_like(f_xy) + 1.0 if side_xy == 1.0 else f_xy
    target_phi = zero_like(f_phi) + 1.0 if side_phi == 1.0 else f_phi
    return LocalWorkspaceState(
        d=_extent(p),
        phi=_deflection(p),
        d_rate=np.dot(grad_d, V_a),
        phi_rate=np.dot(grad_phi, V_a),
        P_d=P_d,
        P_phi=P_phi,
        capability=penalized,
        f_xy=f_xy,
        f_phi=f_phi,
        sigma_xy=_limited(previous[0], target_xy, c.max_step),
        sigma_phi=_limited(previous[1], target_phi, c.max_step),
        deactivated_xy=side_xy,
        deactivated_phi=side_phi,
    )


def adaptive_weighting_factors(previous, p_ee_in_base, V_ee, C_m, grad_C_m,
                               constants):
    """One tick of the weighting factors of the intuitive pHRI mode (Sec.
    IV-C, "Local Workspace" and "Deactivation Strategy": f_xy, f_phi after
    the deactivation strategy, with its hysteresis and sigma's rate limit,
    see the module), the reference body of the WorkspaceAdapter stage's
    discrete update and outputs: `local_workspace_state`'s factors and
    sides, for any scalar type, with nothing checked: an input (other
    than `previous`) that is not finite makes all four NaN, since the
    deactivation's tests, comparisons, would otherwise read a NaN twist
    or gradient as "no lead" and give a confident state.

    Args:
        previous: (4,) the last tick's (sigma_xy, sigma_phi,
            deactivated_xy, deactivated_phi), the sides 0 or 1
            (WEIGHTING_START before the first).
        p_ee_in_base: (3,) end-effector position in T_b (m).
        V_ee: (6,) commanded end-effector twist [v; w] in T_b.
        C_m: capability of movement, a scalar.
        grad_C_m: (6,) grad_x C_m (T_a, ordered like V_a).
        constants: AdaptiveWorkspace.

    Returns:
        (sigma_xy, sigma_phi, deactivated_xy, deactivated_phi), this
        tick's state, of the scalar type of the inputs.
    """
    if not np.isfinite(np.concatenate([
            np.ravel(value_of(part))
            for part in (p_ee_in_base, V_ee, C_m, grad_C_m)])).all():
        nowhere = zero_like(C_m) + math.nan
        return nowhere, nowhere, nowhere, nowhere
    state = _state(previous, p_ee_in_base, V_ee, C_m, grad_C_m, constants)
    return (state.sigma_xy, state.sigma_phi, state.deactivated_xy,
            state.deactivated_phi)


# ----------------------------------------------------------------------------
# The checked public functions
# ----------------------------------------------------------------------------

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


def _bands(workspace):
    """((d^l, d^u), (phi^l, phi^u)) of a LocalWorkspace or None (the
    paper's), checked to be one."""
    ws = checked_instance("workspace", workspace, LocalWorkspace,
                          LocalWorkspace)
    return ((ws.extent_lower, ws.extent_upper),
            (ws.deflection_lower, ws.deflection_upper))


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


def extent(p_in_arm_base):
    """d: the horizontal distance of the end effector from the arm base's
    z axis, sqrt(x^2 + y^2) (m); see the module docstring."""
    return _extent(_vector("p_in_arm_base", p_in_arm_base, 3))


def deflection(p_in_arm_base):
    """phi: |azimuth| of the end effector about the arm base's z axis from
    its x axis, |atan2(y, x)| in [0, pi] (rad); 0 on the axis."""
    return _deflection(_vector("p_in_arm_base", p_in_arm_base, 3))


def extent_gradient(p_in_arm_base):
    """grad_x d (6,), ordered like V_a: [x/d, y/d, 0, 0, 0, 0]; 0 on the
    axis."""
    return _extent_gradient(_vector("p_in_arm_base", p_in_arm_base, 3))


def deflection_gradient(p_in_arm_base):
    """grad_x phi (6,), ordered like V_a: sign(y) [-y, x, 0, 0_3] / d^2
    (phi = |azimuth|); 0 on the axis and at y = 0."""
    return _deflection_gradient(_vector("p_in_arm_base", p_in_arm_base, 3))


def workspace_penalties(p_in_arm_base, workspace=None):
    """(P_d, P_phi) = (alpha(d, d^u, d^l), alpha(phi, phi^u, phi^l))
    (Sec. IV-C, "Local Workspace").

    Args:
        p_in_arm_base: (3,) end-effector position in T_a.
        workspace: LocalWorkspace; the paper's if None.
    """
    extent_band, deflection_band = _bands(workspace)
    return _penalties(_vector("p_in_arm_base", p_in_arm_base, 3),
                      extent_band, deflection_band)


def penalized_capability(C_m, grad_C_m, p_in_arm_base, workspace=None):
    """C_m^d = C_m P_d P_phi and C_m^phi = C_m P_phi with their gradients
    (Sec. IV-C, "Local Workspace"):

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
    extent_band, deflection_band = _bands(workspace)
    return _penalized(_scalar("C_m", C_m), _vector("grad_C_m", grad_C_m, 6),
                      _vector("p_in_arm_base", p_in_arm_base, 3),
                      extent_band, deflection_band)


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
    return _deactivated(factor, _vector("gradient", gradient, 6),
                        _vector("V_a", V_a, 6),
                        _vector("direction", direction, 6))


def local_workspace_state(p_ee_in_base, V_ee, C_m, grad_C_m,
                          capability_upper, capability_lower,
                          workspace=None, R_ba=None, arm_base_in_base=None,
                          previous=None, deactivation_speed=0.0,
                          max_step=math.inf):
    """The weighting factors of the intuitive pHRI mode (Sec. IV-C), with
    every quantity on the way; one tick from `previous`. With the defaults
    (from WEIGHTING_START, no hysteresis, no rate limit) sigma is the
    paper's deactivation strategy applied at this instant alone.

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
        previous: (4,) the last tick's (sigma_xy, sigma_phi,
            deactivated_xy, deactivated_phi), sigmas in [0, 1] and sides
            0 or 1; WEIGHTING_START if None.
        deactivation_speed: v_h >= 0 (m/s), the hysteresis (module).
        max_step: > 0, the largest change of sigma in this tick (inf:
            none).

    Returns:
        LocalWorkspaceState; sigma_xy and sigma_phi are the weighting
        factors, after the deactivation strategy, and deactivated_xy,
        deactivated_phi its sides (1.0 or 0.0).
    """
    lower, upper = _ordered("capability_lower", capability_lower,
                            "capability_upper", capability_upper)
    ws = checked_instance("workspace", workspace, LocalWorkspace,
                          LocalWorkspace)
    R = np.eye(3) if R_ba is None else rotation_matrix("R_ba", R_ba)
    origin = (np.zeros(3) if arm_base_in_base is None
              else as_vector("arm_base_in_base", arm_base_in_base, 3))
    return _state(_previous(previous),
                  _vector("p_ee_in_base", p_ee_in_base, 3),
                  _vector("V_ee", V_ee, 6), _scalar("C_m", C_m),
                  _vector("grad_C_m", grad_C_m, 6),
                  AdaptiveWorkspace.of(
                      upper, lower, ws, R, origin,
                      non_negative("deactivation_speed", deactivation_speed),
                      _max_step(max_step)))


def _previous(previous):
    """`previous` (4,) checked: sigmas in [0, 1], sides 0 or 1."""
    if previous is None:
        return np.array(WEIGHTING_START)
    state = _vector("previous", previous, 4)
    if state.dtype != object:
        for i in (0, 1):
            in_closed_range(f"previous[{i}]", state[i], 0.0, 1.0)
        for i in (2, 3):
            if state[i] not in (0.0, 1.0):
                raise ValueError(
                    f"previous[{i}] = {float(state[i])!r} is not allowed: "
                    "a side of the deactivation must be 0 or 1")
    return state


def _max_step(max_step):
    """`max_step` checked: > 0, inf allowed (no limit)."""
    if max_step == math.inf:
        return max_step
    return positive("max_step", max_step)


# ----------------------------------------------------------------------------
# The float kernel of the tick
# ----------------------------------------------------------------------------

def _weighting_sample(rng):
    """Random arguments of `adaptive_weighting_factors`: the end
    effector on the arm base's axis, straight ahead, straight behind
    (phi = pi), in the extent band, in the deflection band, or anywhere;
    the twist zero, vertical or any; C_m anywhere or with C_m^d in the
    band of the factors (the ramp); the mounting the identity or any; the
    previous state any (the sides 0 or 1), the hysteresis none or up to
    0.1 m/s, the rate limit none or 0.001 to 0.5 a tick, and the twist's
    size from 1e-3 to 1, so that its speeds fall on both sides of v_h;
    in one case in ten an entry of p_ee, V_ee, C_m, grad C_m or the
    previous state NaN or infinite."""
    upper = rng.uniform(0.03, 0.07)
    lower = upper - rng.uniform(0.002, 0.02)
    ws = LocalWorkspace(extent_lower=rng.uniform(0.5, 0.75),
                        extent_upper=rng.uniform(0.76, 0.9),
                        deflection_lower=np.radians(rng.uniform(5, 30)),
                        deflection_upper=np.radians(rng.uniform(31, 60)))
    R = np.eye(3) if rng.uniform() < 0.5 else random_rotation(rng)
    origin = rng.normal(size=3) * 0.3
    constants = AdaptiveWorkspace.of(
        upper, lower, ws, R, origin,
        0.0 if rng.uniform() < 0.3 else rng.uniform(0.0, 0.1),
        math.inf if rng.uniform() < 0.3 else rng.uniform(0.001, 0.5))
    previous = np.array([rng.uniform(), rng.uniform(),
                         float(rng.integers(2)), float(rng.integers(2))])
    radius, azimuth = rng.uniform(0.0, 1.0), rng.uniform(-np.pi, np.pi)
    shape = rng.integers(6)
    if shape == 1:
        radius = 0.0
    elif shape == 2:
        azimuth = 0.0
    elif shape == 3:
        azimuth = np.pi
    elif shape == 4:
        radius = rng.uniform(ws.extent_lower, ws.extent_upper)
    elif shape == 5:
        azimuth = rng.choice([-1, 1]) * rng.uniform(ws.deflection_lower,
                                                    ws.deflection_upper)
    p_a = np.array([radius * np.cos(azimuth), radius * np.sin(azimuth),
                    rng.normal() * 0.3])
    V = rng.normal(size=6) * 10.0 ** rng.uniform(-3.0, 0.0)
    twist = rng.integers(3)
    if twist == 1:
        V[:] = 0.0
    elif twist == 2:
        V[:] = 0.0
        V[:3] = R[:, 2] * rng.normal()  # along the arm base's z axis
    p = R @ p_a + origin
    C_m = rng.uniform(0.0, 0.1)
    if rng.uniform() < 0.4:  # C_m^d in the band of the factors
        P_d, P_phi = _penalties(R.T @ (p - origin), constants.extent,
                                constants.deflection)
        if P_d * P_phi > 0.0:
            C_m = rng.uniform(lower, upper) / (P_d * P_phi)
    grad_C_m = rng.normal(size=6) * 0.1
    if rng.uniform() < 0.1:
        bad = float(rng.choice([np.nan, np.inf, -np.inf]))
        which = rng.integers(5)
        if which == 2:
            C_m = bad
        else:
            vector = (p, V, None, grad_C_m, previous)[which]
            vector[rng.integers(vector.size)] = bad
    return previous, p, V, C_m, grad_C_m, constants


def _float_lead(covector, V, speed):
    """`_lead` for sequences of floats of one length."""
    norm_squared = sum(map(operator.mul, covector, covector))
    if norm_squared == 0.0:
        return -1
    product = sum(map(operator.mul, covector, V))
    square = product * product
    guard = (DEACTIVATION_TOLERANCE**2 * norm_squared
             * sum(map(operator.mul, V, V)))
    if product > 0.0 and square > guard + speed * speed * norm_squared:
        return 1
    if product < 0.0 and square > guard:
        return -1
    return 0


def _float_factor(previous_sigma, previous_side, factor, leads, max_step):
    """(sigma, side) of one factor from its tests' leads (`_side`,
    `_limited`), in floats."""
    if 1 in leads:
        side = 1.0
    elif leads == (-1, -1):
        side = 0.0
    else:
        side = previous_side
    target = 1.0 if side == 1.0 else factor
    change = target - previous_sigma
    if change > max_step:
        return previous_sigma + max_step, side
    if change < -max_step:
        return previous_sigma - max_step, side
    return target, side


@fast_kernel(adaptive_weighting_factors, sample=_weighting_sample)
def adaptive_weighting_factors_float(previous, p_ee_in_base, V_ee, C_m,
                                     grad_C_m, constants):
    """`adaptive_weighting_factors` for float inputs, in plain
    floats: the per-tick path of the WorkspaceAdapter stage in the
    intuitive pHRI mode.

    The same formulas (see the module) and the same elementary functions
    (the float kernels of eq. (transition) and its derivative), to
    rounding; the dot products of the deactivation tests are summed in
    another order, which can only matter within the tests' roundoff
    guard (or at the hysteresis' threshold v_h, to rounding). The position
    in T_a comes from the same numpy product as in the reference: the
    sign of its y coordinate decides, at phi = pi, which way phi grows,
    which the deactivation's rate test reads.

    An input that is not finite makes all four NaN (the reference's
    rule; the stage's tick does not raise for a value).

    Returns:
        (sigma_xy, sigma_phi, deactivated_xy, deactivated_phi), floats,
        the sigmas in [0, 1] and the sides 0 or 1.
    """
    c = constants
    previous = np.asarray(previous, dtype=float).tolist()
    p = np.asarray(p_ee_in_base, dtype=float)
    V_ee = np.asarray(V_ee, dtype=float).tolist()
    grad_C_m = np.asarray(grad_C_m, dtype=float).tolist()
    C_m = float(C_m)
    if not math.isfinite(C_m + sum(p.tolist()) + sum(V_ee) + sum(grad_C_m)):
        # An input that is not finite (all four NaN), or finite ones whose
        # sum overflowed: the reference.
        return tuple(float(sigma) for sigma in
                     adaptive_weighting_factors(
                         previous, p, V_ee, C_m, grad_C_m, constants))
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
        # numpy's arctan2, as the reference: math.atan2 differs in the
        # last bit for some arguments, which the steep ramps of f would
        # show.
        phi = abs(float(np.arctan2(y, x)))
        grad_d_x, grad_d_y = x / d, y / d
        sign = 0.0 if y == 0.0 else (1.0 if y > 0.0 else -1.0)
        grad_phi_x = -sign * y / d_squared
        grad_phi_y = sign * x / d_squared
    (d_lower, d_upper), (phi_lower, phi_upper) = c.extent, c.deflection
    P_d = transition_float(d, d_upper, d_lower)
    dP_d = transition_derivative_float(d, d_upper, d_lower)
    P_phi = transition_float(phi, phi_upper, phi_lower)
    dP_phi = transition_derivative_float(phi, phi_upper, phi_lower)
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
    f_xy = 1.0 - transition_float(C_m * P_d * P_phi, upper, lower)
    f_phi = 1.0 - transition_float(C_m * P_phi, upper, lower)
    # The deactivation strategy with hysteresis, and the rate limit.
    linear, speed = V_a[:3], c.deactivation_speed
    sigma_xy, side_xy = _float_factor(
        previous[0], previous[2], f_xy,
        (_float_lead(gradient_d, V_a, speed),
         _float_lead((-grad_d_x, -grad_d_y, -0.0), linear, speed)),
        c.max_step)
    sigma_phi, side_phi = _float_factor(
        previous[1], previous[3], f_phi,
        (_float_lead(gradient_phi, V_a, speed),
         _float_lead((-grad_phi_x, -grad_phi_y, -0.0), linear, speed)),
        c.max_step)
    return sigma_xy, sigma_phi, side_xy, side_phi

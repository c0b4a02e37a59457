"""The adaptive weighting factors of the intuitive pHRI mode (paper
Sec. IV-C).

In the intuitive pHRI mode the weighting factors of eq. (weight-factors)
follow the arm's configuration, sigma_xy,phi = f_xy,phi(q_a) (Table
(T:motion-mode)), through C_m penalized by the local workspace,
C_m^d = C_m P_d P_phi and C_m^phi = C_m P_phi (drake_wbc.math.workspace, which
also defines d, phi and their gradients), with the transition alpha of
eq. (transition):

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

d_dot and phi_dot are the rates that d and phi would have if the arm alone
carried out the commanded twist V_ee: d_dot = grad d . v, phi_dot =
grad phi . v with v the linear part of R_ba^T V_ee. phi_dot < 0 means
moving back towards the forward axis (the magnitude decreasing), from
either side. The same twist enters the test grad_x C_m^(d,phi) . V_ee.
On the arm base's z axis d_dot = phi_dot = 0 (no gradient of d or phi).

`local_workspace_state` takes float values or AutoDiffXd scalars (numpy
object arrays) alike, as drake_wbc.math.workspace does, so that the Drake
systems over it can be converted to AutoDiffXd. The one exception is
the per-tick path of the controller in double, `adaptive_weighting_factors`
(with its constants from `adaptive_workspace`): the same formulas as
`local_workspace_state`, in plain Python floats.
"""

import math
import operator
from typing import NamedTuple

import numpy as np

from drake_wbc.math.validation import (
    as_vector,
    checked_instance,
    rotation_matrix,
)
from drake_wbc.math.workspace import (
    AXIS_TOLERANCE,
    LocalWorkspace,
    PenalizedCapability,
    _ordered,
    _vector,
    _zero_like,
    deflection,
    deflection_gradient,
    extent,
    extent_gradient,
    in_arm_base,
    penalized_capability,
    smooth_transition,
    workspace_penalties,
)

DEACTIVATION_TOLERANCE = 1e-9
"""The deactivation's tests count only beyond this cosine between the
commanded motion and the gradient (or the direction of growing d or phi):
a guard against rounding, not a dead band one could feel."""


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

    Args: the parameters of the same names of `local_workspace_state`.

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

"""Discrete Dynamic Movement Primitives (paper Sec. II-C, eqs. (6), (7)).

The transformation system of eq. (6), with the generic coupling terms of
Sec. II-C (C_acc at acceleration level, C_vel at velocity level),

    tau z_dot = alpha_z (beta_z (g - y) - z) + f(s) + C_acc,
    tau y_dot = z + C_vel,

is driven by the canonical system of eq. (7), tau s_dot = -alpha_s s,
s(0) = 1. tau (s) scales time; z = tau y_dot is in units of y. With
beta_z = alpha_z / 4 the attractor is critically damped, of natural
frequency sqrt(alpha_z beta_z) / tau (12.5 rad/s by default).

Forcing term. f(s) = s sum_i psi_i(s) w_i / sum_i psi_i(s), psi_i(s) =
exp(-h_i (s - c_i)^2), is kept in absolute units (those of z): it is NOT
multiplied by the classic amplitude (g - y0). That factor vanishes when
the start equals the goal (learning divides by zero, the shape is lost),
mirrors the shape when the goal crosses the start, and rescales it
continually when the goal moves. In absolute units the learned shape is
superposed unchanged on the motion towards any goal, fixed or moving, and
stays finite; `forcing_term`'s `scale` is a fixed factor the user may
choose (e.g. new / demonstrated amplitude, once), never recomputed from
the live goal. Temporal scaling needs no correction: with tau' = k tau
(alpha_s fixed, `DmpParameters.with_tau`) the solution is exactly
y'(t) = y(t / k), the same path k times slower, since z = tau y_dot and f
depends on s only. The paper uses f = 0: weights None, the default
everywhere, gives f = 0 without evaluating any basis function.

The derivative functions (`canonical_derivative`, `basis_functions`,
`forcing_term`, `transformation_derivative`) use elementwise arithmetic
and np.exp only, so they accept numpy object arrays of Drake's AutoDiffXd
as well as floats; parameters are checked once, in `DmpParameters`.
Learning the forcing term from a demonstration is in
drake_wbc.math.dmp_learning.
"""

from dataclasses import dataclass, replace
from functools import lru_cache
from numbers import Integral

import numpy as np

from drake_wbc.math.validation import as_matrix, as_vector, positive

FINAL_PHASE = 0.01
"""Phase s reached at t = duration with the default alpha_s."""


MAX_BASIS = 1000
"""The most basis functions a DMP may have (20 to 100 are usual)."""


@dataclass
class DmpParameters:
    """Gains, timing and basis of a DMP (eqs. (6), (7)).

    Attributes:
        alpha_z: attractor gain alpha_z > 0 (default 25).
        beta_z: attractor gain beta_z > 0, or None for alpha_z / 4
            (critical damping).
        alpha_s: canonical gain alpha_s > 0 of tau s_dot = -alpha_s s, or
            None for -ln(0.01) tau / duration = 4.61 tau / duration, so that
            s(duration) = 0.01.
        tau: temporal scaling factor tau > 0, s (default 1).
        duration: movement duration T > 0 at this tau, s (default 1); sets
            the default alpha_s and the span of the basis centres.
        num_basis: number N of basis functions, 1 to MAX_BASIS (default
            20).

    Basis (the usual heuristic): centres c_i = exp(-alpha_s t_i / tau) at
    times t_i = i T / (N - 1) spaced evenly over [0, T], i.e. geometrically
    in phase from 1 to s(T); widths h_i = 1 / (c_{i+1} - c_i)^2 (the last
    one repeats its neighbour's), so that neighbours cross at
    exp(-1/4) = 0.78 of their peak. For N = 1 the one normalised basis
    function is 1.
    """

    alpha_z: float = 25.0
    beta_z: float | None = None
    alpha_s: float | None = None
    tau: float = 1.0
    duration: float = 1.0
    num_basis: int = 20

    def __post_init__(self):
        for name in ("alpha_z", "beta_z", "alpha_s", "tau", "duration"):
            if getattr(self, name) is not None or name not in (
                    "beta_z", "alpha_s"):
                positive(name, getattr(self, name))
        n = self.num_basis
        if isinstance(n, bool) or not isinstance(n, Integral) or n < 1:
            raise ValueError(f"num_basis = {n!r} is not allowed: must be "
                             "an integer, 1 or greater")
        if n > MAX_BASIS:
            raise ValueError(
                f"num_basis = {n!r} is not allowed: must be at most "
                f"{MAX_BASIS} (the basis is evaluated every tick; 1000 "
                "functions already resolve a 10 s movement to 10 ms)")

    @property
    def resolved_beta_z(self):
        """beta_z, alpha_z / 4 when left as None."""
        return self.alpha_z / 4.0 if self.beta_z is None else self.beta_z

    @property
    def resolved_alpha_s(self):
        """alpha_s, -ln(0.01) tau / duration when left as None."""
        if self.alpha_s is not None:
            return self.alpha_s
        return -np.log(FINAL_PHASE) * self.tau / self.duration

    @property
    def centres(self):
        """(num_basis,) basis centres c_i in phase, from 1 down."""
        return self._basis()[0]

    @property
    def widths(self):
        """(num_basis,) basis widths h_i = 1 / (c_{i+1} - c_i)^2."""
        return self._basis()[1]

    def _basis(self):
        return _basis(self.resolved_alpha_s, self.tau, self.duration,
                      self.num_basis)

    def with_tau(self, tau):
        """The same movement executed with temporal scaling `tau`.

        alpha_s is fixed at its resolved value and the duration scaled by
        tau / self.tau, so the phase s(t) runs tau / self.tau times slower
        while the basis (centres, widths), hence any learned weights, stay
        the same.
        """
        tau = positive("tau", tau)
        return replace(self, tau=tau, alpha_s=self.resolved_alpha_s,
                       duration=self.duration * tau / self.tau)


@lru_cache(maxsize=64)
def _basis(alpha_s, tau, duration, num_basis):
    """(centres, widths) of the basis (DmpParameters), read-only; computed
    once per set of values, so they always follow the current fields."""
    t_i = np.linspace(0.0, duration, num_basis)
    c = np.exp(-alpha_s * t_i / tau)
    if num_basis == 1:
        h = np.ones(1)
    else:
        h = 1.0 / np.diff(c) ** 2
        h = np.append(h, h[-1])
    c.flags.writeable = False
    h.flags.writeable = False
    return c, h


def _checked_parameters(params):
    if not isinstance(params, DmpParameters):
        raise ValueError(f"params = {params!r} is not allowed: must be a "
                         "DmpParameters")
    return params


def canonical_phase(t, params):
    """Closed form s(t) = exp(-alpha_s t / tau) of eq. (7), s(0) = 1, for
    t (s since the start; a number or an array) and DmpParameters."""
    return np.exp(-params.resolved_alpha_s * np.asarray(t) / params.tau)


def canonical_derivative(s, params):
    """s_dot = -alpha_s s / tau of eq. (7) (float or AutoDiffXd)."""
    return -params.resolved_alpha_s * s / params.tau


def basis_functions(s, params):
    """Normalised Gaussian basis psi_i(s) / sum_j psi_j(s), (num_basis,).

    psi_i(s) = exp(-h_i (s - c_i)^2) with the centres and widths of
    `params`, s a number (float or AutoDiffXd). The exponents are shifted
    by their maximum before np.exp (the ratio, and its gradient, are
    unchanged), so the sum never underflows.
    """
    a = -params.widths * (s - params.centres) ** 2
    e = np.exp(a - np.max(a))
    return e / np.sum(e)


def forcing_term(s, weights, params, scale=1.0):
    """f(s) = scale * s * sum_i psi_i(s) w_i / sum_i psi_i(s) of eq. (6).

    In absolute units, with no (g - y0) factor (module docstring);
    `scale` is a fixed number chosen by the caller (f is linear in the
    weights, so it is the same as scaled weights).

    Args:
        s: phase, a number (float or AutoDiffXd).
        weights: (num_basis, d) weights w_i (units of z), or None for
            f = 0 (returned as the number 0.0 at no cost).
        params: DmpParameters (its basis).
        scale: fixed factor applied to f (default 1).

    Returns:
        (d,) array f(s), or 0.0 when weights is None.
    """
    if weights is None:
        return 0.0
    return (basis_functions(s, params) @ weights) * (s * scale)


def transformation_derivative(y, z, g, s, params, forcing=0.0,
                              coupling_acceleration=0.0,
                              coupling_velocity=0.0):
    """Derivatives of the transformation system of eq. (6) with coupling:

        tau z_dot = alpha_z (beta_z (g - y) - z) + f(s) + C_acc,
        tau y_dot = z + C_vel.

    C_vel is added to z as given: it carries whatever tau factor its
    coupling has (e.g. pass tau C_dot for eq. (admit-dmp)). Float or
    AutoDiffXd arrays; no checks (see DmpParameters).

    Args:
        y, z, g: (d,) position, scaled velocity z = tau y_dot - C_vel,
            goal.
        s: phase; only used when `forcing` is callable (else may be None).
        params: DmpParameters (alpha_z, beta_z, tau).
        forcing: f(s) as a number or (d,) array, or a callable of s
            (e.g. a dmp_learning.LearnedForcingTerm); default 0.
        coupling_acceleration, coupling_velocity: C_acc, C_vel, numbers
            or (d,); default 0.

    Returns:
        (y_dot, z_dot), each (d,).
    """
    if callable(forcing):
        forcing = forcing(s)
    tau = params.tau
    z_dot = (params.alpha_z * (params.resolved_beta_z * (g - y) - z)
             + forcing + coupling_acceleration) / tau
    y_dot = (z + coupling_velocity) / tau
    return y_dot, z_dot


def rollout(params, y0, goal, duration, dt, weights=None,
            goal_trajectory=None, tau=None):
    """Integrates eqs. (6) and (7) from rest at y0 (z = 0, s = 1).

    Classic fourth-order Runge-Kutta on the state (y, z, s) with a fixed
    step: the phase is integrated alongside (not taken from the closed
    form), and the goal is evaluated at every stage time.

    Args:
        params: DmpParameters.
        y0, goal: (d,) start and goal (numbers for d = 1); goal is
            ignored (may be None) with goal_trajectory.
        duration: length > 0 of the rollout, s (may exceed
            params.duration); dt: step > 0, s (round(duration / dt) steps).
        weights: (num_basis, d) forcing weights, or None for f = 0.
        goal_trajectory: optional callable t -> (d,) moving goal g(t).
        tau: optional temporal scaling, None for params.tau; runs
            params.with_tau(tau), the same path tau / params.tau times
            slower.

    Returns:
        (t, y, yd): times (n + 1,), positions and velocities y_dot
        (n + 1, d).
    """
    params = _checked_parameters(params)
    if tau is not None:
        params = params.with_tau(tau)
    y0 = as_vector("y0", np.atleast_1d(y0))
    d = y0.size
    duration = positive("duration", duration)
    dt = positive("dt", dt)
    if weights is not None:
        weights = as_matrix("weights", weights, (params.num_basis, d))
    if goal_trajectory is None:
        goal = as_vector("goal", np.atleast_1d(goal), d)

        def goal_at(_t):
            return goal
    elif callable(goal_trajectory):
        def goal_at(t):
            return np.reshape(goal_trajectory(t), d)
    else:
        raise ValueError(f"goal_trajectory = {goal_trajectory!r} is not "
                         "allowed: must be None or a callable of t")

    def derivative(t, x):
        y, z, s = x[:d], x[d:2 * d], x[2 * d]
        f = forcing_term(s, weights, params)
        y_dot, z_dot = transformation_derivative(y, z, goal_at(t), s,
                                                 params, f)
        return np.concatenate([y_dot, z_dot,
                               [canonical_derivative(s, params)]])

    n = max(int(round(duration / dt)), 1)
    times = np.arange(n + 1) * dt
    x = np.concatenate([y0, np.zeros(d), [1.0]])
    ys, yds = np.empty((n + 1, d)), np.empty((n + 1, d))
    for k, t in enumerate(times):
        k1 = derivative(t, x)
        ys[k], yds[k] = x[:d], k1[:d]
        if k == n:
            break
        k2 = derivative(t + dt / 2, x + dt / 2 * k1)
        k3 = derivative(t + dt / 2, x + dt / 2 * k2)
        k4 = derivative(t + dt, x + dt * k3)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return times, ys, yds

"""Discrete Dynamic Movement Primitives (paper Sec. III-C, eqs. (6), (7)).

The transformation system of eq. (6), with the generic coupling terms of
Sec. III-C (C_acc at acceleration level, C_vel at velocity level),

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
as well as floats; parameters are checked once, in `DmpParameters`. The
closed-form phase and the forcing term have each one float kernel
(drake_wbc.math.kernels), the arithmetic a learned movement's replay
runs every control tick (drake_wbc.math.movement.MovementPlayer).

Learning the forcing term. The paper leaves f = 0 and names learning it
as future work. A demonstration's velocities and accelerations are
estimated by `demonstration_derivatives`; eq. (6) solved for f at each
sample gives the targets (`forcing_targets`, with the demonstration's own
goal and the canonical phase of eq. (7)); the gated normalised basis
values at those phases form the design matrix (`design_matrix`); and the
weights are one ridge least-squares fit (`fit_weights`).
`learn_forcing_term` does all of it for one demonstration;
drake_wbc.math.movement stacks several. Learning is float only.
"""

import math
from dataclasses import dataclass, replace
from functools import lru_cache
from numbers import Integral

import numpy as np

from drake_wbc.math.kernels import fast_kernel
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


def _phase_inputs(rng):
    """A time (inside, at the start of and far beyond the movement) and
    random DmpParameters, for canonical_phase_float."""
    params = _random_parameters(rng)
    t = float(rng.choice([0.0, rng.uniform(0.0, params.duration),
                          rng.uniform(0.0, 50.0 * params.duration)]))
    return t, params


def _random_parameters(rng):
    """DmpParameters with random gains, timing and basis, the default
    alpha_s or a given one."""
    return DmpParameters(
        alpha_z=rng.uniform(1.0, 60.0), tau=rng.uniform(0.2, 3.0),
        alpha_s=None if rng.random() < 0.5 else rng.uniform(0.5, 10.0),
        duration=rng.uniform(0.1, 10.0),
        num_basis=int(rng.choice([1, 2, int(rng.integers(3, 60))])))


@fast_kernel(canonical_phase, sample=_phase_inputs)
def canonical_phase_float(t, params):
    """`canonical_phase` of one float t, in plain floats (math.exp): a
    learned movement's replay, each control tick."""
    return math.exp(-params.resolved_alpha_s * t / params.tau)


def fastest_rate(params):
    """A bound, 1/s, on the rates of the linear dynamics of eqs. (6) and
    (7) at DmpParameters `params`: max(alpha_z, sqrt(alpha_z beta_z),
    alpha_s) / tau, at least the largest modulus of the roots of
    tau^2 s^2 + tau alpha_z s + alpha_z beta_z (alpha_z / tau bounds
    them while they are real, sqrt(alpha_z beta_z) / tau is their modulus
    when complex; twice `fastest_pole` at the critically damped default)
    and of the canonical system's -alpha_s / tau. A fixed-step
    integration of the DMP resolves it with steps well below its
    inverse."""
    params = _checked_parameters(params)
    return max(params.alpha_z,
               math.sqrt(params.alpha_z * params.resolved_beta_z),
               params.resolved_alpha_s) / params.tau


def fastest_pole(params):
    """The largest modulus, rad/s, of the poles of eq. (6)'s
    transformation system at DmpParameters `params`, the roots of
    tau^2 lambda^2 + alpha_z tau lambda + alpha_z beta_z = 0:
    (alpha_z + sqrt(alpha_z^2 - 4 alpha_z beta_z)) / (2 tau) while they
    are real, sqrt(alpha_z beta_z) / tau when critically damped or
    under-damped (12.5 rad/s at the defaults); inf where it overflows."""
    alpha, beta, tau = params.alpha_z, params.resolved_beta_z, params.tau
    with np.errstate(over="ignore", invalid="ignore"):
        discriminant = alpha * alpha - 4.0 * alpha * beta
        if discriminant > 0.0:
            return float((alpha + np.sqrt(discriminant)) / (2.0 * tau))
        return float(np.sqrt(alpha * beta) / tau)


def check_sampled(params, time_step, name="dmp", hint=""):
    """Checks that a control period samples the DMP `params`.

    The transformation system's fastest pole (`fastest_pole`) must lie
    below the Nyquist rate pi / time_step, as the base filter's cut-off
    does (a DMP faster than the control period cannot be sampled by it,
    and its discretisation overflows long before 1e300). time_step 0
    (continuous) samples every DMP.

    Args:
        params: DmpParameters.
        time_step: the control period h, s (>= 0, checked by the caller).
        name: what the caller calls `params`, for the message.
        hint: what to change, appended to the message.

    Raises:
        ValueError: naming alpha_z, beta_z, tau, time_step and both
            rates.
    """
    if time_step == 0.0:
        return
    rate, nyquist = fastest_pole(params), math.pi / time_step
    if not rate < nyquist:
        raise ValueError(
            f"{name}.alpha_z = {params.alpha_z!r}, beta_z = "
            f"{params.resolved_beta_z!r} and tau = {params.tau!r} s are not "
            f"allowed with time_step = {time_step!r} s: the transformation "
            f"system's fastest pole ({rate:.6g} rad/s) must lie below "
            f"the Nyquist rate pi / time_step = {nyquist:.6g} "
            "rad/s, as the filter's cut-off (a DMP faster than the "
            "control period cannot be sampled by it, and its "
            f"discretisation overflows long before 1e300){hint}")


def canonical_derivative(s, params):
    """s_dot = -alpha_s s / tau of eq. (7) (float or AutoDiffXd)."""
    return -params.resolved_alpha_s * s / params.tau


def basis_functions(s, params):
    """Normalised Gaussian basis psi_i(s) / sum_j psi_j(s) of eq. (6).

    psi_i(s) = exp(-h_i (s - c_i)^2) with the centres and widths of
    `params`. The exponents are shifted by their maximum before np.exp
    (the ratio, and its gradient, are unchanged), so the sum never
    underflows.

    Args:
        s: the phase, a number (float or AutoDiffXd), or an (N,) array of
            phases.
        params: DmpParameters (its basis).

    Returns:
        (num_basis,) for a number s, (N, num_basis) for N phases.
    """
    s = np.asarray(s)
    a = -params.widths * (s[..., None] - params.centres) ** 2
    e = np.exp(a - np.max(a, axis=-1, keepdims=True))
    return e / np.sum(e, axis=-1, keepdims=True)


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


def _forcing_inputs(rng):
    """A phase (the start, inside, near 0 and past the movement's end),
    weights (None, zeros or random, in one or several columns), random
    DmpParameters and a scale, for forcing_term_float."""
    params = _random_parameters(rng)
    s = float(rng.choice([1.0, rng.uniform(0.0, 1.0), 1e-6 * rng.random(),
                          params.centres[-1] * rng.random(), 0.0]))
    d = int(rng.integers(1, 7))
    kind = rng.integers(0, 4)
    weights = (None if kind == 0 else np.zeros((params.num_basis, d))
               if kind == 1 else 10.0 ** rng.uniform(-3, 3) * rng.normal(
                   size=(params.num_basis, d)))
    return s, weights, params, float(rng.choice([1.0, rng.normal()]))


@fast_kernel(forcing_term, sample=_forcing_inputs)
def forcing_term_float(s, weights, params, scale=1.0):
    """`forcing_term` of a float phase s, in few array operations: the
    basis' exponents shifted by their maximum, the normalisation folded
    into the gate, f(s) = (e . W) (s scale / sum e) (a learned movement's
    replay, each control tick)."""
    if weights is None:
        return 0.0
    offset = params.centres - s
    a = offset * offset
    a *= -params.widths
    e = np.exp(a - a.max())
    return e.dot(weights) * (s * scale / e.sum())


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
            (e.g. a LearnedForcingTerm); default 0.
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


# Learning the forcing term (module docstring).


def _demonstration(t, y):
    """Checked (t, y): t strictly increasing (N >= 3,), y (N, d)."""
    t = as_vector("t", t)
    if t.size < 3 or np.any(np.diff(t) <= 0.0):
        raise ValueError(
            f"t = {t!r} is not allowed: must hold 3 or more strictly "
            "increasing times")
    if np.ndim(y) == 1:
        y = np.reshape(y, (-1, 1))
    return t, as_matrix("y", y, (t.size, None))


def demonstration_derivatives(t, y):
    """Velocities and accelerations of a demonstration by finite
    differences.

    np.gradient (second-order central differences inside, second-order
    one-sided at both ends, valid for uneven sample times) applied once
    for yd and again to yd for ydd; exact for quadratics. Sample densely
    (hundreds of samples per movement): the error is of order dt^2 times
    the third and fourth derivatives.

    Args:
        t: (N,) strictly increasing sample times, N >= 3, s.
        y: (N, d) positions, or (N,) for d = 1.

    Returns:
        (yd, ydd), each (N, d).
    """
    t, y = _demonstration(t, y)
    yd = np.gradient(y, t, axis=0, edge_order=2)
    return yd, np.gradient(yd, t, axis=0, edge_order=2)


def forcing_targets(t, y, yd, ydd, g, params):
    """Forcing term that reproduces a demonstration exactly (eq. (6)),

        f_target = tau^2 ydd - alpha_z (beta_z (g - y) - tau yd),

    in absolute units (no amplitude scaling), (N, d), from the sample
    times t (N,), the (N, d) positions, velocities and accelerations, the
    goal g (d,) (usually y[-1]) and DmpParameters (alpha_z, beta_z, tau).
    """
    params = _checked_parameters(params)
    t, y = _demonstration(t, y)
    yd = as_matrix("yd", yd, y.shape)
    ydd = as_matrix("ydd", ydd, y.shape)
    g = as_vector("g", np.atleast_1d(g), y.shape[1])
    tau = params.tau
    return tau**2 * ydd - params.alpha_z * (
        params.resolved_beta_z * (g - y) - tau * yd)


def design_matrix(s, params):
    """Gated normalised basis values X[k, i] = s_k psi_i(s_k) / sum psi
    (`basis_functions`) for (N,) phases s: (N, num_basis), so that
    f(s_k) = X[k] @ weights."""
    params = _checked_parameters(params)
    s = as_vector("s", np.atleast_1d(s))
    return s[:, None] * basis_functions(s, params)


def fit_weights(design, targets, regularisation=1e-6):
    """Ridge least squares weights W = (X^T X + lambda I)^-1 X^T F.

    X is the (N, num_basis) design matrix, F the (N, d) (or (N,))
    targets; lambda = regularisation * trace(X^T X) / num_basis (relative
    to the mean diagonal, so one value suits any number of samples;
    absolute if X = 0), regularisation > 0. Returns (num_basis, d) (or
    (num_basis,)) weights.
    """
    X = as_matrix("design", design, (None, None))
    if np.ndim(targets) == 1:
        F = as_vector("targets", targets, X.shape[0])
    else:
        F = as_matrix("targets", targets, (X.shape[0], None))
    regularisation = positive("regularisation", regularisation)
    M = X.T @ X
    mean_diagonal = np.trace(M) / M.shape[0]
    M[np.diag_indices_from(M)] += regularisation * (
        mean_diagonal if mean_diagonal > 0.0 else 1.0)
    return np.linalg.solve(M, X.T @ F)


@dataclass(frozen=True, eq=False)
class LearnedForcingTerm:
    """A forcing term learned from a demonstration; call it with s.

    Attributes: weights (num_basis, d) in absolute units (those of z),
    the DmpParameters `params` it was learned with, the demonstration's
    start y0 (d,) and end `goal` (d,). Nothing else is needed: there is
    no amplitude scaling.
    """

    weights: np.ndarray
    params: DmpParameters
    y0: np.ndarray
    goal: np.ndarray

    def __call__(self, s, scale=1.0):
        """f(s), (d,) (float or AutoDiffXd s); see `forcing_term`."""
        return forcing_term(s, self.weights, self.params, scale)


def learn_forcing_term(t, y, params=None, regularisation=1e-6):
    """Learns f from one demonstration (positions y at times t).

    Derivatives by `demonstration_derivatives`, targets by
    `forcing_targets` with g = y[-1], phase by `canonical_phase` of
    t - t[0], weights by `fit_weights`. The demonstration should end at
    rest (zero velocity and acceleration): otherwise f stays non-zero at
    its end and keeps pushing, decaying with s, after t = duration.

    Args:
        t: (N,) strictly increasing times, s.
        y: (N, d) positions, or (N,) for d = 1.
        params: DmpParameters, or None for the defaults with duration =
            t[-1] - t[0].
        regularisation: relative ridge factor of `fit_weights`.

    Returns:
        LearnedForcingTerm.
    """
    t, y = _demonstration(t, y)
    if params is None:
        params = DmpParameters(duration=t[-1] - t[0])
    params = _checked_parameters(params)
    yd, ydd = demonstration_derivatives(t, y)
    targets = forcing_targets(t, y, yd, ydd, y[-1], params)
    design = design_matrix(canonical_phase(t - t[0], params), params)
    weights = fit_weights(design, targets, regularisation)
    y0, goal = y[0].copy(), y[-1].copy()
    for array in (weights, y0, goal):
        array.flags.writeable = False
    return LearnedForcingTerm(weights, params, y0, goal)

"""Learning the forcing term f(s) of a discrete DMP (drake_wbc.math.dmp, eqs.
(6), (7)) from demonstrations.

The paper leaves f = 0 and names learning it as future work. A
demonstration's velocities and accelerations are estimated by
`demonstration_derivatives`; eq. (6) solved for f at each sample gives
the targets (`forcing_targets`, with the demonstration's own goal and
the canonical phase of eq. (7)); the gated normalised basis values at
those phases form the design matrix (`design_matrix`); and the weights
are one ridge least-squares fit (`fit_weights`). `learn_forcing_term`
does all of it for one demonstration; drake_wbc.math.movement stacks several.
The forcing term stays in absolute units (drake_wbc.math.dmp). Float only.
"""

from dataclasses import dataclass

import numpy as np

from drake_wbc.math.dmp import (
    DmpParameters,
    _checked_parameters,
    canonical_phase,
    forcing_term,
)
from drake_wbc.math.validation import as_matrix, as_vector, positive


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
    for (N,) phases s: (N, num_basis), so that f(s_k) = X[k] @ weights."""
    params = _checked_parameters(params)
    s = as_vector("s", np.atleast_1d(s))
    a = -params.widths * (s[:, None] - params.centres) ** 2
    e = np.exp(a - np.max(a, axis=1, keepdims=True))
    return s[:, None] * e / np.sum(e, axis=1, keepdims=True)


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

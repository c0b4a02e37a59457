"""Tests of drake_wbc.math.dmp against closed forms (eqs. (6), (7)), learned
reproductions of demonstrations, and AutoDiff gradients."""

import numpy as np
import pytest
from pydrake.autodiffutils import (
    AutoDiffXd,
    ExtractGradient,
    ExtractValue,
    InitializeAutoDiff,
)
from reference_kinematics import central_differences

from drake_wbc.math.dmp import (
    DmpParameters,
    basis_functions,
    canonical_derivative,
    canonical_phase,
    demonstration_derivatives,
    design_matrix,
    fit_weights,
    forcing_targets,
    forcing_term,
    learn_forcing_term,
    rollout,
    transformation_derivative,
)

DT = 1e-3


def check_autodiff(function, pieces, rtol=1e-6, atol=1e-8):
    """Evaluates function(*pieces) on AutoDiffXd copies of the float
    arrays `pieces` and compares the gradient of the concatenated outputs
    with central differences of the float evaluation."""
    sizes = [np.size(p) for p in pieces]
    splits = np.cumsum(sizes)[:-1]
    shapes = [np.shape(p) for p in pieces]

    def flat(outputs):
        return np.concatenate([np.ravel(o) for o in outputs])

    def call(x):
        parts = [np.reshape(p, s) for p, s in
                 zip(np.split(x, splits), shapes, strict=True)]
        return function(*parts)

    x0 = np.concatenate([np.ravel(p) for p in pieces]).astype(float)
    values = flat(call(x0))
    x_ad = InitializeAutoDiff(x0).ravel()
    outputs = flat(call(x_ad))
    outputs = np.array([
        v if isinstance(v, AutoDiffXd) else AutoDiffXd(v, np.zeros(x0.size))
        for v in outputs], dtype=object)
    np.testing.assert_allclose(ExtractValue(outputs).ravel(), values,
                               rtol=1e-13, atol=1e-13)
    numeric = central_differences(lambda x: flat(call(x)), x0).T
    np.testing.assert_allclose(ExtractGradient(outputs), numeric,
                               rtol=rtol, atol=atol)


def minimum_jerk(x):
    return 10 * x**3 - 15 * x**4 + 6 * x**5


def demonstration(T=1.0, samples=1001):
    """A smooth 3-D demonstration from rest to rest: minimum jerk plus a
    bump, plus a detour out and back."""
    t = np.linspace(0.0, T, samples)
    x = t / T
    bump = np.exp(-(((x - 0.5) / 0.12) ** 2))
    y = np.stack([0.4 * minimum_jerk(x) + 0.12 * bump,
                  -0.2 * minimum_jerk(x) + 0.1 * np.sin(np.pi * x) ** 4,
                  0.05 * bump], axis=1)
    return t, y


# ----------------------------------------------------------------------------
# Parameters, canonical system, basis
# ----------------------------------------------------------------------------

@pytest.mark.parametrize(("tau", "duration"), [(1.0, 1.0), (0.5, 3.0),
                                               (2.0, 0.7)])
def test_default_alpha_s_reaches_final_phase(tau, duration):
    params = DmpParameters(tau=tau, duration=duration)
    np.testing.assert_allclose(canonical_phase(duration, params), 0.01,
                               rtol=1e-14)
    np.testing.assert_allclose(params.resolved_alpha_s,
                               np.log(100.0) * tau / duration, rtol=1e-15)
    assert params.resolved_beta_z == 25.0 / 4.0


def test_canonical_closed_form_matches_integration():
    params = DmpParameters(tau=1.3, alpha_s=3.0)
    s, h = 1.0, 1e-3
    for _ in range(2000):
        k1 = canonical_derivative(s, params)
        k2 = canonical_derivative(s + h / 2 * k1, params)
        k3 = canonical_derivative(s + h / 2 * k2, params)
        k4 = canonical_derivative(s + h * k3, params)
        s += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    np.testing.assert_allclose(s, np.exp(-3.0 * 2.0 / 1.3), rtol=1e-10)
    np.testing.assert_allclose(canonical_phase(2.0, params), s, rtol=1e-10)


def test_basis_centres_even_in_time_and_normalised():
    params = DmpParameters(tau=1.5, duration=2.0, num_basis=12)
    times = -np.log(params.centres) * params.tau / params.resolved_alpha_s
    np.testing.assert_allclose(times, np.linspace(0.0, 2.0, 12), atol=1e-12)
    np.testing.assert_allclose(params.widths[:-1],
                               1.0 / np.diff(params.centres) ** 2)
    for s in np.linspace(0.0, 1.0, 50):
        psi = basis_functions(s, params)
        assert psi.shape == (12,)
        np.testing.assert_allclose(psi.sum(), 1.0, rtol=1e-14)
    # The most active function is the one whose centre is nearest.
    assert np.argmax(basis_functions(params.centres[4], params)) == 4
    np.testing.assert_allclose(
        design_matrix([0.3, 0.7], params),
        [0.3 * basis_functions(0.3, params),
         0.7 * basis_functions(0.7, params)], rtol=1e-14)


def test_f_is_zero_without_weights():
    params = DmpParameters()
    assert forcing_term(0.5, None, params) == 0.0
    np.testing.assert_array_equal(
        forcing_term(0.5, np.zeros((20, 3)), params), np.zeros(3))


def test_transformation_derivative_formula():
    rng = np.random.default_rng(1)
    params = DmpParameters(alpha_z=10.0, beta_z=3.0, tau=0.8)
    y, z, g, f, c_a, c_v = rng.normal(size=(6, 4))
    y_dot, z_dot = transformation_derivative(y, z, g, 0.3, params, f, c_a,
                                             c_v)
    np.testing.assert_allclose(0.8 * z_dot, 10 * (3 * (g - y) - z) + f + c_a)
    np.testing.assert_allclose(0.8 * y_dot, z + c_v)


# ----------------------------------------------------------------------------
# Point-to-point motion (f = 0)
# ----------------------------------------------------------------------------

@pytest.mark.parametrize("tau", [1.0, 0.6])
def test_point_to_point_is_critically_damped(tau):
    """With f = 0, y(t) = g + (y0 - g)(1 + w t) exp(-w t),
    w = sqrt(alpha_z beta_z) / tau: monotone, no overshoot."""
    rng = np.random.default_rng(2)
    params = DmpParameters(tau=tau)
    y0, g = rng.normal(size=(2, 3))
    t, y, yd = rollout(params, y0, g, 2.0, DT)
    w = np.sqrt(25.0 * 6.25) / tau
    exact = g + np.outer((1 + w * t) * np.exp(-w * t), y0 - g)
    np.testing.assert_allclose(y, exact, atol=1e-7)
    progress = (y - y0) / (g - y0)
    assert np.all(np.diff(progress, axis=0) >= -1e-12)
    assert np.all(progress <= 1.0 + 1e-12)
    np.testing.assert_allclose(y[-1], g, atol=1e-6)
    np.testing.assert_allclose(
        yd, np.outer(-w**2 * t * np.exp(-w * t), y0 - g), atol=1e-6)


def test_start_at_goal_stays_put():
    params = DmpParameters()
    t, y, yd = rollout(params, [0.3, -0.2], [0.3, -0.2], 1.5, DT)
    assert np.all(np.isfinite(y))
    np.testing.assert_array_equal(y, np.tile([0.3, -0.2], (len(t), 1)))
    np.testing.assert_array_equal(yd, 0.0)


def test_learned_from_standing_still_stays_put():
    """A demonstration that never moves (start = goal) learns zero weights,
    without dividing by its zero amplitude."""
    t = np.linspace(0.0, 1.0, 201)
    learned = learn_forcing_term(t, np.tile([0.5, 0.1], (201, 1)))
    assert np.all(np.isfinite(learned.weights))
    np.testing.assert_allclose(learned.weights, 0.0, atol=1e-9)
    _, y, _ = rollout(learned.params, [0.5, 0.1], [0.5, 0.1], 1.5, DT,
                      learned.weights)
    np.testing.assert_allclose(y, np.tile([0.5, 0.1], (len(y), 1)),
                               atol=1e-9)


def test_loop_with_start_at_goal_is_reproduced():
    """Out and back (start = goal, amplitude 0.2): the classic (g - y0)
    scaling would lose it; absolute units keep it."""
    t = np.linspace(0.0, 1.0, 1001)
    y = 0.2 * np.sin(np.pi * t) ** 4
    learned = learn_forcing_term(t, y)
    _, y_rep, _ = rollout(learned.params, 0.0, 0.0, 1.0, DT, learned.weights)
    assert np.max(np.abs(y_rep[:, 0] - y)) < 0.01 * 0.2


# ----------------------------------------------------------------------------
# Learning
# ----------------------------------------------------------------------------

def test_demonstration_derivatives_exact_for_quadratics():
    t = np.sort(np.random.default_rng(3).uniform(0.0, 2.0, 40))
    yd, ydd = demonstration_derivatives(t, 3.0 * t**2 - t)
    np.testing.assert_allclose(yd[:, 0], 6.0 * t - 1.0, atol=1e-9)
    np.testing.assert_allclose(ydd[:, 0], 6.0, rtol=1e-8)


def test_forcing_targets_formula():
    rng = np.random.default_rng(4)
    params = DmpParameters(alpha_z=12.0, beta_z=2.0, tau=1.7)
    y, yd, ydd = rng.normal(size=(3, 5, 2))
    g = rng.normal(size=2)
    targets = forcing_targets(np.arange(5.0), y, yd, ydd, g, params)
    np.testing.assert_allclose(
        targets, 1.7**2 * ydd - 12.0 * (2.0 * (g - y) - 1.7 * yd))


def test_fit_weights_recovers_exact_weights():
    rng = np.random.default_rng(5)
    params = DmpParameters(num_basis=8)
    X = design_matrix(canonical_phase(np.linspace(0, 1, 300), params), params)
    W = rng.normal(size=(8, 2))
    np.testing.assert_allclose(fit_weights(X, X @ W, 1e-14), W, rtol=1e-6)
    assert fit_weights(X, (X @ W)[:, 0]).shape == (8,)


def test_learning_recovers_a_rollout():
    """Round trip: a rollout with known weights and goal, learned back
    through the pipeline's steps, gives back the weights."""
    rng = np.random.default_rng(6)
    params = DmpParameters(num_basis=10)
    W = 50.0 * rng.normal(size=(10, 2))
    goal = np.array([0.3, -0.2])
    t, y, _ = rollout(params, [0.0, 0.1], goal, 1.0, 1e-4, W)
    yd, ydd = demonstration_derivatives(t, y)
    targets = forcing_targets(t, y, yd, ydd, goal, params)
    design = design_matrix(canonical_phase(t, params), params)
    np.testing.assert_allclose(targets[5:-5], design[5:-5] @ W, atol=2e-3)
    np.testing.assert_allclose(fit_weights(design, targets, 1e-12), W,
                               rtol=1e-3, atol=2e-2)


@pytest.mark.parametrize("dims", [[0], [0, 1, 2]])
def test_learned_term_reproduces_the_demonstration(dims):
    t, y = demonstration()
    y = y[:, dims]
    learned = learn_forcing_term(t, y)
    _, y_rep, _ = rollout(learned.params, y[0], y[-1], 1.0, DT,
                          learned.weights)
    amplitude = np.ptp(y, axis=0)
    assert np.all(np.max(np.abs(y_rep - y), axis=0) < 0.01 * amplitude)


def test_learned_term_converges_to_a_new_goal():
    t, y = demonstration()
    learned = learn_forcing_term(t, y)
    amplitude = np.ptp(y, axis=0)
    for shift in ([0.3, 0.2, -0.1], [-0.4, 0.2, 0.0], [0.0, 0.0, 0.0]):
        goal = y[-1] + np.array(shift)
        _, y_new, _ = rollout(learned.params, y[0], goal, 1.5, DT,
                              learned.weights)
        assert np.all(np.abs(y_new[-1] - goal) < 1e-3 * amplitude)


def test_moving_goal_is_followed_without_blow_up():
    """The goal moves by 0.3 along a smooth path during [0.2, 0.8] s and
    stays; y stays near it and settles on it."""
    t, y = demonstration()
    learned = learn_forcing_term(t, y)
    g0, g1 = y[-1], y[-1] + np.array([0.3, -0.3, 0.3])

    def goal(time):
        x = np.clip((time - 0.2) / 0.6, 0.0, 1.0)
        return g0 + minimum_jerk(x) * (g1 - g0)

    _, y_run, yd_run = rollout(learned.params, y[0], None, 2.0, DT,
                               learned.weights, goal_trajectory=goal)
    assert np.all(np.isfinite(y_run)) and np.all(np.isfinite(yd_run))
    # Fixed-goal path plus at most the goal's own displacement, no more.
    _, y_fixed, _ = rollout(learned.params, y[0], g0, 2.0, DT,
                            learned.weights)
    deviation = np.max(np.abs(y_run - y_fixed), axis=0)
    assert np.all(deviation <= 1.001 * np.abs(g1 - g0))
    np.testing.assert_allclose(y_run[-1], g1, atol=1e-4)


def test_temporal_scaling_same_path_twice_as_slow():
    t, y = demonstration()
    learned = learn_forcing_term(t, y)
    _, y1, yd1 = rollout(learned.params, y[0], y[-1], 1.0, DT,
                         learned.weights)
    _, y2, yd2 = rollout(learned.params, y[0], y[-1], 2.0, DT,
                         learned.weights, tau=2.0)
    np.testing.assert_allclose(y2[::2], y1, atol=1e-8)
    np.testing.assert_allclose(2.0 * yd2[::2], yd1, atol=1e-6)
    scaled = learned.params.with_tau(2.0)
    np.testing.assert_allclose(scaled.centres, learned.params.centres)
    np.testing.assert_allclose(canonical_phase(2.0, scaled), 0.01)


# ----------------------------------------------------------------------------
# AutoDiff and bad input
# ----------------------------------------------------------------------------

def test_derivative_functions_autodiff_gradients():
    t, y = demonstration()
    learned = learn_forcing_term(t, y)
    params = learned.params
    rng = np.random.default_rng(7)
    y, z, g, c_a, c_v = 0.1 * rng.normal(size=(5, 3))

    def transformation(y, z, g, s, c_a, c_v):
        return transformation_derivative(y, z, g, s[0], params, learned,
                                         c_a, c_v)

    for s in (0.9, 0.35, 0.02):
        check_autodiff(transformation, [y, z, g, np.array([s]), c_a, c_v],
                       rtol=1e-6, atol=1e-6)
        check_autodiff(lambda s: [canonical_derivative(s, params)],
                       [np.array([s])])
        check_autodiff(lambda s: [basis_functions(s[0], params)],
                       [np.array([s])], atol=1e-6)


@pytest.mark.parametrize(("name", "kwargs"), [
    ("alpha_z", {"alpha_z": 0.0}),
    ("alpha_z", {"alpha_z": -1.0}),
    ("beta_z", {"beta_z": -2.0}),
    ("alpha_s", {"alpha_s": 0.0}),
    ("tau", {"tau": -1.0}),
    ("duration", {"duration": 0.0}),
    ("num_basis", {"num_basis": 0}),
    ("num_basis", {"num_basis": 2.5}),
    ("num_basis", {"num_basis": True}),
])
def test_bad_parameters_name_the_argument(name, kwargs):
    with pytest.raises(ValueError, match=name):
        DmpParameters(**kwargs)


def test_bad_learning_input():
    params = DmpParameters()
    with pytest.raises(ValueError, match="t = "):
        learn_forcing_term([0.0, 0.5, 0.4], [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="y = .* has shape"):
        learn_forcing_term([0.0, 0.5, 1.0], np.zeros((4, 2)))
    with pytest.raises(ValueError, match="regularisation"):
        fit_weights(np.ones((3, 2)), np.ones(3), 0.0)
    with pytest.raises(ValueError, match="weights = .* has shape"):
        rollout(params, [0.0], [1.0], 1.0, DT, np.zeros((3, 1)))
    with pytest.raises(ValueError, match="params"):
        rollout("params", [0.0], [1.0], 1.0, DT)
    with pytest.raises(ValueError, match="goal_trajectory"):
        rollout(params, [0.0], [1.0], 1.0, DT, goal_trajectory=3.0)

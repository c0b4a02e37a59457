"""Property-based tests of the math layer (hypothesis): the invariants that
the modules' docstrings state, over generated inputs, badly conditioned
ones included (near-singular arm configurations, sigma at exactly 0 and 1,
joints at their limits, obstacle points inside the footprint, huge and
tiny values).

The examples are derandomized (the same ones on every run) and the
example database is off, so a run is reproducible.
"""

import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from reference_kinematics import ELFIN5, ELFIN5_LOWER, ELFIN5_UPPER, jacobian

from drake_wbc.math import capability as cap
from drake_wbc.math import dmp, filtering, repulsion
from drake_wbc.math.arm_control import joint_velocity_for_twist
from drake_wbc.math.compensation import robust_compensation
from drake_wbc.math.distribution import (
    capability_null_velocity,
    distribute,
    weighting_matrix,
)
from drake_wbc.math.kinematics import (
    base_jacobian,
    twist_rotation,
    whole_body_jacobian,
)


def checked(max_examples):
    """Hypothesis settings: derandomized, no deadline, no database."""
    return settings(max_examples=max_examples, deadline=None,
                    derandomize=True, database=None)


def reals(low, high):
    return st.floats(low, high, allow_nan=False, allow_infinity=False)


def magnitudes():
    """Positive scales from tiny to huge, 1e-9 to 1e6."""
    return st.integers(-9, 6).map(lambda k: 10.0**k)


def vectors(size, bound=1.0):
    return st.lists(reals(-bound, bound), min_size=size, max_size=size).map(
        np.array)


def scaled_vectors(size):
    """Vectors of entries in [-1, 1] times a scale from 1e-9 to 1e6."""
    return st.tuples(vectors(size), magnitudes()).map(lambda a: a[0] * a[1])


# sigma in [0, 1], with its ends (the singular Q) drawn often.
sigmas = st.one_of(st.sampled_from([0.0, 1.0]), reals(0.0, 1.0))


@st.composite
def rotations(draw):
    """A rotation matrix from a unit quaternion."""
    q = draw(vectors(4))
    assume(np.linalg.norm(q) > 1e-3)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


@st.composite
def arm_configurations(draw):
    """Elfin5 joint angles within the limits: uniform, with some joints
    put exactly at a limit, or next to the wrist (q5 = 0) and elbow
    (q3 = 0) singularities."""
    fractions = draw(st.lists(reals(0.0, 1.0), min_size=6, max_size=6))
    q = ELFIN5_LOWER + np.array(fractions) * (ELFIN5_UPPER - ELFIN5_LOWER)
    kind = draw(st.sampled_from(["free", "limit", "wrist", "elbow"]))
    if kind == "limit":
        for i in draw(st.lists(st.integers(0, 5), min_size=1, max_size=3)):
            q[i] = draw(st.sampled_from([ELFIN5_LOWER[i], ELFIN5_UPPER[i]]))
    elif kind in ("wrist", "elbow"):
        q[4 if kind == "wrist" else 2] = draw(st.sampled_from(
            [0.0, 1e-12, -1e-8, 1e-5, 1e-3]))
    return q


# ---------------------------------------------------------------- Q, J^+

@given(sigma_xy=sigmas, sigma_phi=sigmas)
@checked(60)
def test_weighting_matrix_structure(sigma_xy, sigma_phi):
    """Q of eq. (weight-factors): diagonal, entries in [0, 1], each planar
    input shared between arm and base with weights summing to 1, the
    others on the arm alone."""
    Q = weighting_matrix(sigma_xy, sigma_phi)
    assert np.array_equal(Q, np.diag(np.diag(Q)))
    q = np.diag(Q)
    assert np.all((q >= 0.0) & (q <= 1.0))
    np.testing.assert_array_equal(q[[2, 3, 4]], 1.0)
    np.testing.assert_array_equal(q[[0, 1]] + q[[6, 7]], 1.0)
    assert q[5] + q[8] == 1.0
    assert q[0] == q[1] == sigma_xy and q[5] == sigma_phi


@st.composite
def whole_body_problems(draw):
    """J_wb = [R_ba, J_b] at an end-effector position from 1 mm to 100 m
    away, an arm mounting R_ba, sigmas (0 and 1 included) and V_ee from
    1e-9 to 1e6."""
    p = draw(vectors(3)) * draw(st.sampled_from([1e-3, 0.5, 2.0, 100.0]))
    R_ba = draw(st.one_of(st.just(np.eye(3)), rotations()))
    J = whole_body_jacobian(None, p, R_ba)
    return J, draw(scaled_vectors(6)), draw(sigmas), draw(sigmas)


def well_conditioned(J, sigma_xy, sigma_phi, ratio=2e-4):
    """True when J Q J^T is far enough from singular that the default
    damping (threshold 1e-4 of s_max) is off: J has full row rank in the
    weighted sense and J^+ is the exact weighted pseudo-inverse."""
    Q = weighting_matrix(sigma_xy, sigma_phi)
    eigenvalues = np.linalg.eigvalsh(J @ Q @ J.T)
    return eigenvalues[0] > ratio * eigenvalues[-1]


@given(problem=whole_body_problems())
@checked(150)
def test_distribution_reproduces_the_end_effector_twist(problem):
    """J_wb V_wb = V_ee whenever J_wb Q^(1/2) has full row rank (eq.
    (wbsln)); inputs of zero weight get exactly zero."""
    J, V_ee, sigma_xy, sigma_phi = problem
    assume(well_conditioned(J, sigma_xy, sigma_phi))
    V_wb = distribute(J, V_ee, sigma_xy, sigma_phi)
    scale = np.linalg.norm(V_ee) * max(1.0, np.linalg.norm(J, 2))
    np.testing.assert_allclose(J @ V_wb, V_ee, rtol=0, atol=1e-9 * scale)
    weights = np.diag(weighting_matrix(sigma_xy, sigma_phi))
    assert np.all(V_wb[weights == 0.0] == 0.0)


def test_the_controllers_jacobian_is_always_well_conditioned():
    """The module docstring's claim for R_ba = I: J Q J^T is positive
    definite for every sigma in [0, 1]^2 and r < 5.5 m, so the property
    above is not vacuous for the controller's case."""
    for sigma in ((0.0, 0.0), (1.0, 1.0), (0.0, 1.0), (0.5, 0.3)):
        for r in (0.0, 0.5, 1.0, 5.0):
            J = whole_body_jacobian(None, [r, 0.0, 0.4])
            assert well_conditioned(J, *sigma, ratio=1e-4)


@given(problem=whole_body_problems(), gradient=scaled_vectors(6),
       k_n=st.sampled_from([0.0, 0.1, 1.0, 1e3]))
@checked(120)
def test_the_null_space_term_leaves_the_end_effector_twist(problem,
                                                           gradient, k_n):
    """J_wb (I - J^+ J_wb) V_n^0 = 0 (eq. (wbccm))."""
    J, V_ee, sigma_xy, sigma_phi = problem
    assume(well_conditioned(J, sigma_xy, sigma_phi))
    V_n = capability_null_velocity(gradient, k_n)
    with_null = distribute(J, V_ee, sigma_xy, sigma_phi, null_velocity=V_n)
    without = distribute(J, V_ee, sigma_xy, sigma_phi)
    scale = (np.linalg.norm(V_n) + np.linalg.norm(V_ee)) * max(
        1.0, np.linalg.norm(J, 2)) ** 2
    np.testing.assert_allclose(J @ (with_null - without), 0.0, rtol=0,
                               atol=1e-9 * scale)


# ------------------------------------------------------ C_m and alpha

@given(q=arm_configurations(),
       k_j=st.sampled_from([1.0, 1e3, cap.DEFAULT_JOINT_LIMIT_GAIN, 1e8]))
@checked(150)
def test_capability_lies_between_zero_and_its_bound(q, k_j):
    """0 <= C_m <= m (1 - exp(-k_j 4^-n)) (Sec. III-A), and C_m = 0 with a
    joint at a limit."""
    J = jacobian(ELFIN5, q)
    C_m = cap.capability(J, q, ELFIN5_LOWER, ELFIN5_UPPER, k_j)
    m = cap.manipulability(J)
    assert 0.0 <= C_m <= m * -np.expm1(-k_j * 4.0**-6) * (1 + 1e-12)
    if np.any(q == ELFIN5_LOWER) or np.any(q == ELFIN5_UPPER):
        assert C_m == 0.0


def interior_configurations():
    """Elfin5 joint angles 2 % of the range or more from every limit."""
    return st.lists(reals(0.02, 0.98), min_size=6, max_size=6).map(
        lambda f: ELFIN5_LOWER + np.array(f) * (ELFIN5_UPPER - ELFIN5_LOWER))


@given(q=interior_configurations())
@checked(80)
def test_the_capability_gradient_matches_central_differences(q):
    """dC_m/dq (analytic) against central differences of C_m(J_a(q), q),
    away from the kinks: the joint limits (P_jnt clamps there) and the
    singularities (m = prod s_i is not smooth where s_i = 0)."""
    h = 1e-6
    J = jacobian(ELFIN5, q)
    s = np.linalg.svd(J, compute_uv=False)
    assume(s[-1] > 1e-2 and np.min(np.diff(-s)) > 1e-6)

    def C_m(x):
        return cap.capability(jacobian(ELFIN5, x), x, ELFIN5_LOWER,
                              ELFIN5_UPPER)

    numeric = np.array([(C_m(q + h * e) - C_m(q - h * e)) / (2 * h)
                        for e in np.eye(6)])
    analytic = cap.capability_joint_gradient(J, q, ELFIN5_LOWER,
                                                  ELFIN5_UPPER)
    np.testing.assert_allclose(analytic, numeric, rtol=1e-4,
                               atol=1e-7 * max(1.0, np.abs(numeric).max()))
    # The Cartesian gradient maps back to it: J_a^T g = dC_m/dq where the
    # solve is not damped (s_min above the threshold).
    if s[-1] > cap.DEFAULT_DAMPING_THRESHOLD:
        g = cap.capability_gradient(J, q, ELFIN5_LOWER, ELFIN5_UPPER)
        np.testing.assert_allclose(J.T @ g, analytic, rtol=1e-7,
                                   atol=1e-12)


@st.composite
def bands(draw):
    lower = draw(reals(-1e3, 1e3))
    width = draw(magnitudes())
    assume(lower + width > lower)
    return lower, lower + width


@given(band=bands(), fractions=st.lists(reals(-2.0, 3.0), min_size=2,
                                         max_size=30))
@checked(120)
def test_alpha_is_monotone_and_in_the_unit_interval(band, fractions):
    """alpha of eq. (transition): in [0, 1], non-increasing, 1 at and
    below C_m^l, 0 at and above C_m^u, derivative <= 0."""
    lower, upper = band
    values = np.sort(lower + np.array(fractions) * (upper - lower))
    alpha = cap.transition(values, upper, lower)
    assert np.all((alpha >= 0.0) & (alpha <= 1.0))
    assert np.all(np.diff(alpha) <= 0.0)
    assert cap.transition(lower, upper, lower) == 1.0
    assert cap.transition(upper, upper, lower) == 0.0
    assert np.all(cap.transition_derivative(values, upper, lower) <= 0.0)


# -------------------------------------------------------- compensation

@st.composite
def compensation_problems(draw):
    p = draw(vectors(3)) * draw(st.sampled_from([1e-3, 1.0, 1e3]))
    R_ba = draw(st.one_of(st.just(np.eye(3)), rotations()))
    gradient = draw(st.one_of(st.just(np.zeros(6)), scaled_vectors(6)))
    return base_jacobian(p), R_ba, draw(scaled_vectors(3)), gradient


@given(problem=compensation_problems())
@checked(120)
def test_exact_compensation_cancels_the_filtered_deviation(problem):
    """alpha = 0: the arm's compensation undoes the base deviation at the
    end effector, R_ba dV_a^cmp + J_b dV_b = 0 (eqs. (wb_error) and
    (compensation)), and dV_ee = 0 (eq. (deviation))."""
    J_b, R_ba, delta_V_b, gradient = problem
    cmp, deviation = robust_compensation(delta_V_b, J_b, R_ba, gradient,
                                         0.0)
    scale = np.linalg.norm(J_b, 2) * np.linalg.norm(delta_V_b)
    np.testing.assert_allclose(twist_rotation(R_ba) @ cmp + J_b @ delta_V_b,
                               0.0, rtol=0, atol=1e-12 * scale)
    assert np.all(deviation == 0.0)


@given(problem=compensation_problems(), alpha=st.one_of(
    st.sampled_from([0.0, 1.0]), reals(0.0, 1.0)))
@checked(150)
def test_robust_compensation_never_exceeds_what_wb_error_allows(problem,
                                                                alpha):
    """dV_a^cmp = (I - alpha P_Cm) dV_a^req, eq. (wb_error): never larger
    than the exact compensation; along grad C_m exactly (1 - alpha) of it,
    across it all of it; and dV_ee = dV_a^cmp - dV_a^req (eq.
    (deviation), turned into T_b by R_ba) of size alpha |P dV_a^req| at
    most."""
    J_b, R_ba, delta_V_b, gradient = problem
    required, _ = robust_compensation(delta_V_b, J_b, R_ba, gradient, 0.0)
    cmp, deviation = robust_compensation(delta_V_b, J_b, R_ba, gradient,
                                         alpha)
    size = np.linalg.norm(required)
    assert np.linalg.norm(cmp) <= size * (1 + 1e-12) + 1e-300
    # dV_ee in T_b: R_ba (dV_a^cmp - dV_a^req).
    np.testing.assert_allclose(deviation, twist_rotation(R_ba) @ (
        cmp - required), rtol=0, atol=1e-12 * size)
    assert np.linalg.norm(deviation) <= alpha * size * (1 + 1e-12) + 1e-300
    norm = np.linalg.norm(gradient)
    if norm > 1e-12:
        u = gradient / norm
        np.testing.assert_allclose(u @ cmp, (1 - alpha) * (u @ required),
                                   rtol=0, atol=1e-12 * size)
        np.testing.assert_allclose(cmp - (u @ cmp) * u,
                                   required - (u @ required) * u, rtol=0,
                                   atol=1e-12 * size)


# ----------------------------------------------------------------- DMP

@given(alpha_z=reals(2.0, 50.0), tau=reals(0.5, 2.0),
       y0=scaled_vectors(2), goal=scaled_vectors(2))
@checked(15)
def test_a_dmp_without_forcing_converges_to_its_goal(alpha_z, tau, y0,
                                                     goal):
    """Eqs. (6), (7) with f = 0 and beta_z = alpha_z / 4 (critically
    damped): from rest, y reaches g without overshoot."""
    params = dmp.DmpParameters(alpha_z=alpha_z, tau=tau)
    duration = 30.0 * tau / alpha_z + 0.5
    _, y, yd = dmp.rollout(params, y0, goal, duration, dt=0.005)
    start = np.abs(y0 - goal)
    scale = max(float(np.max(start)), 1e-300)
    np.testing.assert_allclose(y[-1], goal, rtol=0, atol=1e-5 * scale)
    # No overshoot: y - g keeps its sign (to rounding).
    assert np.all((y - goal) * (y0 - goal) >= -1e-9 * scale**2)
    assert np.all(np.isfinite(yd))


# ----------------------------------------------------- repulsive field

@st.composite
def obstacle_points(draw):
    """Points around a footprint: inside it, on its edges and corners, at
    tiny and large distances."""
    a, b = draw(st.sampled_from([(0.4, 0.3), (0.0, 0.0), (1.0, 0.05)]))
    kind = draw(st.sampled_from(["any", "inside", "edge", "near", "corner"]))
    u = draw(vectors(2))
    if kind == "any":
        point = u * 3.0
    elif kind == "inside":
        point = u * [a, b]
    elif kind == "edge":
        point = np.array([a * np.sign(u[0] or 1.0), b * u[1]])
    elif kind == "near":
        point = np.array([(a + draw(magnitudes()) * 1e-6)
                          * np.sign(u[0] or 1.0), b * u[1]])
    else:
        point = np.array([a, b]) * np.sign(u + 1e-300)
    return (a, b), point


@given(case=obstacle_points(), k_obs=st.sampled_from([0.0, 0.01, 1.0, 1e4]),
       d_min=st.sampled_from([1e-6, 0.05, 0.3]))
@checked(200)
def test_the_repulsive_force_is_finite_and_points_away(case, k_obs, d_min):
    """f_avoid of eq. (cdmp-base): finite even at d_obs -> 0 and inside
    the footprint (d clamped to d_min), bounded by the slope at d_min, and
    pushing the base away from the obstacle: f . p <= 0 for the point p
    in T_b (the base's centre at the origin)."""
    half_sizes, point = case
    # Distances whose square underflows are the known failure below.
    assume(not 0.0 < independent_gap(point, half_sizes) < 1e-150)
    params = repulsion.RepulsiveFieldParameters(k_obs=k_obs, d_th=0.5,
                                           half_sizes=half_sizes,
                                           d_min=d_min)
    force = repulsion.repulsive_force(point[None, :], params)
    assert np.all(np.isfinite(force))
    bound = k_obs * (1.0 / d_min - 1.0 / params.d_th) / d_min**2
    assert np.linalg.norm(force) <= bound * (1 + 1e-12)
    assert force @ point <= 1e-12 * bound * np.linalg.norm(point)
    distance, _ = repulsion.footprint_distance(point[None, :], params)
    if distance[0] > params.d_th:
        assert np.all(force == 0.0)


def independent_gap(point, half_sizes):
    """The distance from `point` to the rectangle, by np.hypot."""
    return float(np.hypot(*np.maximum(np.abs(point) - half_sizes, 0.0)))


def test_the_repulsive_force_is_finite_at_an_underflowing_distance():
    """A point 3.5e-164 m outside the footprint: |(ox, oy)| computed as
    sqrt(ox^2 + oy^2) would underflow to 0 and the direction to 0 / 0."""
    params = repulsion.RepulsiveFieldParameters(half_sizes=(0.0, 0.0))
    point = np.array([[0.0, 3.5e-164]])
    assert np.all(np.isfinite(repulsion.repulsive_force(point, params)))


# ------------------------------------------------------- base filter

@given(ratio=reals(1e-3, 0.99), zeta=st.one_of(st.just(1.0),
                                               reals(0.05, 5.0)),
       time_step=st.sampled_from([1e-4, 1e-3, 0.01, 0.1]))
@checked(100)
def test_the_zoh_base_filter_has_unit_dc_gain(ratio, zeta, time_step):
    """Eq. (filtering) discretised exactly with a zero-order hold: stable,
    and a constant input passes unchanged in the steady state,
    C (I - A_d)^-1 B_d + D = 1, for any omega_f below the Nyquist rate."""
    omega_f = ratio * np.pi / time_step
    A, B, C, D = filtering.lowpass_state_space(omega_f, zeta)
    A_d, B_d = filtering.zero_order_hold(A, B, time_step)
    assert np.max(np.abs(np.linalg.eigvals(A_d))) < 1.0
    gain = C @ np.linalg.solve(np.eye(2) - A_d, B_d) + D
    np.testing.assert_allclose(gain, 1.0, rtol=1e-7)
    response = filtering.lowpass_zoh_response(omega_f, zeta, time_step,
                                              [0.0])
    np.testing.assert_allclose(response, 1.0, rtol=1e-9)


# ----------------------------------------------------- arm controller

@given(q=arm_configurations(), V_a=scaled_vectors(6),
       previous=st.one_of(st.none(), vectors(6, 1.57)),
       time_step=st.sampled_from([0.001, 0.01, 0.1]),
       limited=st.booleans())
@checked(200)
def test_the_arm_controller_keeps_every_limit(q, V_a, previous, time_step,
                                              limited):
    """joint_velocity_for_twist (drake_wbc.math.arm_control): |q_dot| within
    the velocity limits and q + q_dot h within the joint limits less the
    margin, for any twist, at singularities and at the limits; two steps
    in a row change q_dot by at most a h with an acceleration limit."""
    limit, margin, a = 1.57, 0.05, 12.56
    acceleration = a if limited else None
    J = jacobian(ELFIN5, q)
    first = joint_velocity_for_twist(
        J, V_a, q, ELFIN5_LOWER, ELFIN5_UPPER, limit, time_step,
        margin=margin, acceleration_limit=acceleration,
        previous_q_dot=previous).q_dot
    q_next = q + first * time_step
    second = joint_velocity_for_twist(
        jacobian(ELFIN5, q_next), V_a, q_next, ELFIN5_LOWER, ELFIN5_UPPER,
        limit, time_step, margin=margin, acceleration_limit=acceleration,
        previous_q_dot=first).q_dot
    for q_now, q_dot in ((q, first), (q_next, second)):
        assert np.all(np.isfinite(q_dot))
        assert np.all(np.abs(q_dot) <= limit * (1 + 1e-12))
        after = q_now + q_dot * time_step
        low, high = ELFIN5_LOWER + margin, ELFIN5_UPPER - margin
        inside = (q_now >= low) & (q_now <= high)
        tolerance = 1e-12
        assert np.all(after[inside] >= low[inside] - tolerance)
        assert np.all(after[inside] <= high[inside] + tolerance)
        # A joint outside the band never moves further out.
        assert np.all(q_dot[q_now < low] >= 0.0)
        assert np.all(q_dot[q_now > high] <= 0.0)
    if limited:
        assert np.all(np.abs(second - first) <= a * time_step * (1 + 1e-9))

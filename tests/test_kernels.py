"""Every fast float kernel of the math layer against its reference.

One parametrised test for all of them (drake_wbc.math.kernels): each
kernel is evaluated beside its scalar-generic reference on random inputs
drawn by its own sampler, and on the edge inputs of EDGES (the points
where a piecewise body switches branch, which random draws reach only by
chance: a value on a band's edge and one float either side of it, a norm
at its tolerance, a distance at its threshold, a command at its limit, a
force at its bound), and must give the same result to 1e-12 relative to
the size of the result's finite entries (its NaNs and infinities
exactly).
"""

import importlib
import pkgutil

import numpy as np
import pytest

import drake_wbc.math
from drake_wbc.math import compiled, kernels
from drake_wbc.math.scalar_support import value_of

for _module in pkgutil.iter_modules(drake_wbc.math.__path__):
    importlib.import_module(f"drake_wbc.math.{_module.name}")

SAMPLES = 200
TOLERANCE = 1e-12


def _flat(result):
    """A kernel's or a reference's result as one float vector (results may
    be arrays, tuples of arrays and numbers, or None)."""
    if result is None:
        return np.zeros(0)
    if isinstance(result, tuple | list) and any(
            isinstance(r, tuple | list | np.ndarray) for r in result):
        return np.concatenate([_flat(r) for r in result])
    return np.ravel(value_of(np.asarray(result)).astype(float))


def _name(kernel):
    return f"{kernel.reference.__module__}.{kernel.reference.__qualname__}"


def _either_side(value):
    """value and the floats just below and above it."""
    return [np.nextafter(value, -np.inf), value, np.nextafter(value, np.inf)]


def _transition_edges():
    """alpha and its derivative on both edges of the band and a float
    either side, at zero (of either sign) and at both infinities."""
    bands = [(0.04, 0.035), (1.0, 0.0), (0.8, 0.75)]
    return [(value, upper, lower) for upper, lower in bands
            for value in (*_either_side(lower), *_either_side(upper), 0.0,
                          -0.0, np.inf, -np.inf)]


def _capability_edges():
    """C_m and grad_x C_m with s_min on the damping threshold and a float
    either side (where the damping sets in), at an exact singularity with
    and without damping, J_a zero, joints at both limits (P_jnt = 0) or
    beyond them, a damping of 1e200 and a continuous joint at a NaN or
    infinite angle, for six and seven joints."""
    rng = np.random.default_rng(3)
    cases = []
    for n in (6, 7):
        U = np.linalg.qr(rng.normal(size=(6, 6)))[0]
        V = np.linalg.qr(rng.normal(size=(n, n)))[0][:6]
        lower, upper = -np.ones(n), np.full(n, 1.5)
        configurations = [np.zeros(n), lower.copy(), upper.copy(),
                          np.r_[lower[:1], upper[1:]], upper + 0.1]
        for s_min in (0.02, 0.0):
            J = np.ascontiguousarray(
                (U * [1.5, 1.2, 1.0, 0.8, 0.5, s_min]) @ V)
            s_true = np.linalg.svd(J, compute_uv=False)[-1]
            for threshold in _either_side(max(s_true, 1e-3)):
                for damping in (0.0, 0.02):
                    cases += [(J, q, lower, upper, 1.5e4 * 4.0 ** (n - 6),
                               damping, threshold)
                              for q in configurations]
        cases.append((np.zeros((6, n)), np.zeros(n), lower, upper, 1.5e4,
                      0.02, 0.02))
        # A damping whose square overflows (the reference's power of a
        # float raised OverflowError), and a continuous joint at an angle
        # NaN or infinite (the kernel gave a finite C_m).
        cases.append((J, np.zeros(n), lower, upper, 1.5e4, 1e200, 1.0))
        free_lower, free_upper = lower.copy(), upper.copy()
        free_lower[0], free_upper[0] = -np.inf, np.inf
        for angle in (np.nan, np.inf, -np.inf):
            q = np.zeros(n)
            q[0] = angle
            cases.append((J, q, free_lower, free_upper, 1.5e4, 0.02, 0.02))
    return cases


def _compensation_edges():
    """The compensation with |grad_x C_m| on the projector's tolerance and
    a float either side (where P_Cm switches to 0), a gradient of one
    entry, alpha 0, 1 and between, no base deviation, both mountings."""
    from drake_wbc.math.compensation import PROJECTOR_TOLERANCE
    cases = []
    for norm in _either_side(PROJECTOR_TOLERANCE):
        for gradient in (np.full(6, norm / np.sqrt(6.0)),
                         np.r_[norm, np.zeros(5)]):
            for alpha in (0.0, 0.5, 1.0):
                for R in (None, np.eye(3)):
                    for V_b_filtered in ([0.1, 0.2, 0.3], [0.0, 0.0, 0.0]):
                        cases.append((
                            np.ones(6), np.zeros(3),
                            np.array(V_b_filtered), np.array([0.5, 0.1, 0.3]),
                            R, gradient.copy(), alpha,
                            PROJECTOR_TOLERANCE))
    return cases


def _distribution_edges():
    """The distribution at the corners of the weighting factors, with the
    end effector on the base's axis and at reaches from 3 to 4 m (where
    the closed form's certificate of no damping stops holding and the
    reference takes over), the null-space term off and on."""
    from drake_wbc.math.distribution import DEFAULT_DAMPING
    V_ee = np.array([0.1, -0.2, 0.05, 0.1, 0.0, 0.2])
    cases = []
    for reach in (0.0, *np.linspace(3.0, 4.0, 11)):
        for sigmas in ((0.0, 0.0), (1.0, 1.0), (0.0, 1.0), (1.0, 0.0),
                       (0.5, 0.5)):
            for gain in (0.0, 0.1):
                for damping in (DEFAULT_DAMPING, None):
                    cases.append((V_ee.copy(),
                                  np.array([0.6 * reach, 0.8 * reach, 0.3]),
                                  None, *sigmas, np.full(6, 0.01), gain,
                                  damping))
    return cases


def _repulsion_points():
    """Points on the edges of the field's branches around a 0.8 x 0.6 m
    footprint with d_th = 0.5 m and d_min = 0.05 m (each distance a float
    either side too): at d_th and d_min along a side and off a corner, on
    a side, a corner, inside on the diagonal's tie |x| - a = |y| - b, at
    the centre (of either sign), and none."""
    a, b = 0.4, 0.3
    points = [np.zeros((0, 2)), np.array([[0.0, 0.0]]),
              np.array([[-0.0, -0.0]]), np.array([[0.1, 0.0]]),
              np.array([[-0.2, -0.1]]), np.array([[a, b]]),
              np.array([[-a, b]]), np.array([[a, 0.0]]),
              np.array([[0.0, -b]])]
    for distance in (0.5, 0.05):
        for d in _either_side(distance):
            points += [np.array([[a + d, 0.1]]), np.array([[-0.2, -b - d]]),
                       np.array([[a + d / np.sqrt(2.0), b + d / np.sqrt(2.0)]])]
    return points


def _field(**changes):
    from drake_wbc.math.repulsion import RepulsiveFieldParameters
    values = dict(k_obs=0.01, d_th=0.5, half_sizes=(0.4, 0.3), d_min=0.05,
                  max_force=80.0)
    values.update(changes)
    return RepulsiveFieldParameters(**values)


def _footprint_edges():
    return [(points, _field()) for points in _repulsion_points()]


def _repulsion_edges():
    """The force at the points of `_repulsion_points`, and one point's
    force at the bound max_force exactly and a float either side (where
    the force is scaled down), and under a bound whose square overflows
    (1e200: no bound; the reference's power of a float raised
    OverflowError)."""
    from drake_wbc.math.repulsion import repulsive_force
    point = np.array([[0.45, 0.0]])
    push = float(np.hypot(*repulsive_force(point, _field(max_force=1e9))))
    return [(points, _field()) for points in _repulsion_points()] + [
        (point, _field(max_force=bound)) for bound in _either_side(push)] + [
        (point, _field(max_force=1e200))]


def _limit_edges():
    """The base command at its velocity limit exactly and a float beyond,
    its change at the acceleration limit exactly (a h = 0.01), from rest
    and from itself, and with the separation's scale 0."""
    limits, accelerations, h = (1.0, 0.5, 2.0), (1.0, 1.0, 1.0), 0.01
    cases = []
    for desired in ([1.0, 0.0, 0.0], [1.0, 0.5, 2.0],
                    [np.nextafter(1.0, 2.0), 0.0, 0.0], [0.0, 0.0, 0.0]):
        desired = np.array(desired)
        for previous in (np.zeros(3), desired.copy(), desired - 0.01,
                         desired - [0.01, 0.0, 0.0]):
            for scale in (1.0, 0.0):
                cases.append((desired.copy(), previous, limits,
                              accelerations, h, scale))
    return cases


def _weighting_edges():
    """The weighting factors of intuitive pHRI with the end effector on
    the edges of the extent and deflection bands, on the arm base's axis,
    straight behind it (phi = pi, from either side), C_m on the edges of
    the capability band, the twist at rest, leading out and leading back
    at the hysteresis' speed, from either side of the deactivation."""
    from drake_wbc.math.workspace import AdaptiveWorkspace, LocalWorkspace
    workspace = LocalWorkspace()
    constants = AdaptiveWorkspace.of(0.04, 0.035, workspace, np.eye(3),
                                     np.zeros(3), 0.02, 0.1)
    positions = [np.array([0.0, 0.0, 0.3]), np.array([-0.7, 0.0, 0.3]),
                 np.array([-0.7, -0.0, 0.3])]
    for d in (0.75, 0.8):
        for phi in (0.0, np.radians(30.0), np.radians(35.0)):
            positions.append(np.array([d * np.cos(phi), d * np.sin(phi),
                                       0.3]))
    cases = []
    for p in positions:
        for C_m in (0.04, 0.035, 0.1):
            for speed in (0.0, 0.02, -0.02):
                for previous in ([1.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 1.0]):
                    cases.append((np.array(previous), p.copy(),
                                  np.r_[speed, np.zeros(5)], C_m,
                                  np.array([0.01, 0.0, 0.0, 0.0, 0.0, 0.0]),
                                  constants))
    return cases


def _twist_edges():
    twist = np.arange(1.0, 7.0)
    return [(twist, yaw) for yaw in (0.0, -0.0, np.pi, -np.pi, np.pi / 2)]


def _forcing_edges():
    """f(s) at the start and end of the phase, beyond both, at 0 of
    either sign and at one basis function."""
    from drake_wbc.math.dmp import DmpParameters
    cases = []
    for num_basis in (1, 10):
        params = DmpParameters(num_basis=num_basis)
        weights = np.linspace(-1.0, 1.0, 2 * num_basis).reshape(-1, 2)
        for s in (1.0, 0.0, -0.0, 1e-300, 2.0, -1.0):
            cases += [(s, weights, params, 1.0), (s, None, params, 1.0)]
    return cases


def _one_exact_singularity(J_a, *_):
    """Whether J_a (finite) has exactly one singular value that is zero
    to rounding: there grad_x C_m has no side, and which one a body
    gives depends on its SVD's LAPACK (numpy's and the compiled kernel's
    agree with numpy 2.4, not with 2.5); tests/test_capability.py checks
    that each gives one, and only C_m is compared here."""
    if not np.isfinite(J_a).all():
        return False
    s = np.linalg.svd(J_a, compute_uv=False)
    return np.sum(s <= max(J_a.shape) * np.finfo(float).eps * s[0]) == 1


AMBIGUOUS = {
    "drake_wbc.math.capability.capability_terms": (_one_exact_singularity,
                                                   slice(0, 1)),
}
"""Inputs where a reference's result is not unique, by the reference's
name: (whether the arguments are such, the part of the flat result that
is unique there)."""


EDGES = {
    "drake_wbc.math.capability.transition_of": _transition_edges,
    "drake_wbc.math.capability.transition_derivative_of": _transition_edges,
    "drake_wbc.math.capability.capability_terms": _capability_edges,
    "drake_wbc.math.compensation.arm_compensation": _compensation_edges,
    "drake_wbc.math.distribution.whole_body_distribution":
        _distribution_edges,
    "drake_wbc.math.repulsion.footprint_distance": _footprint_edges,
    "drake_wbc.math.repulsion.repulsive_force": _repulsion_edges,
    "drake_wbc.math.command_limits.limit_base_velocity": _limit_edges,
    "drake_wbc.math.workspace.adaptive_weighting_factors": _weighting_edges,
    "drake_wbc.math.kinematics.twist_in_base": _twist_edges,
    "drake_wbc.math.kinematics.twist_in_world": _twist_edges,
    "drake_wbc.math.dmp.forcing_term": _forcing_edges,
}
"""Edge inputs of the kernels (see the module), by the reference's
name: each a function that returns a list of argument tuples."""


@pytest.mark.parametrize("kernel", kernels.registered_kernels(), ids=_name)
# Samples with entries NaN or infinite make references compute 0 * inf.
@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")
def test_the_kernel_gives_its_references_result(kernel):
    rng = np.random.default_rng(20261201)
    edges = EDGES.get(_name(kernel), lambda: [])()
    ambiguous, unique = AMBIGUOUS.get(_name(kernel), (None, slice(None)))
    for args in [kernel.sample(rng) for _ in range(SAMPLES)] + edges:
        expected = _flat(kernel.reference(*args))
        actual = _flat(kernel.fast(*args))
        assert actual.shape == expected.shape, args
        if ambiguous is not None and ambiguous(*args):
            expected, actual = expected[unique], actual[unique]
        scale = max(1.0, float(np.max(np.abs(expected), initial=0.0,
                                      where=np.isfinite(expected))))
        np.testing.assert_allclose(actual, expected, rtol=0.0,
                                   atol=TOLERANCE * scale, err_msg=args)


def test_the_edge_inputs_name_registered_kernels():
    names = {_name(kernel) for kernel in kernels.registered_kernels()}
    assert set(EDGES) <= names, set(EDGES) - names


def test_an_equation_has_at_most_one_kernel():
    def reference(x):
        return x

    kernels.fast_kernel(reference, sample=lambda rng: (rng.random(),))(
        lambda x: x)
    with pytest.raises(ValueError, match="at most one"):
        kernels.fast_kernel(reference, sample=lambda rng: ())(lambda x: x)
    assert kernels.body_for(reference, float) is not reference
    assert kernels.body_for(reference, object) is reference


def _compiled_functions():
    """Every compiled function (drake_wbc.math.compiled) of the math
    layer's modules."""
    found = []
    for info in pkgutil.iter_modules(drake_wbc.math.__path__):
        module = importlib.import_module(f"drake_wbc.math.{info.name}")
        found += [value for value in vars(module).values()
                  if compiled.is_compiled(value)]
    return found


# Its samples, like the test above's, hold NaN and infinite entries.
@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")
def test_no_tick_compiles_once_the_kernels_are_warm():
    for kernel in kernels.registered_kernels():
        kernels.warm(kernel)
    functions = _compiled_functions()
    signatures = [len(f.signatures) for f in functions]
    rng = np.random.default_rng(7)
    for kernel in kernels.registered_kernels():
        for _ in range(20):
            kernel.fast(*kernel.sample(rng))
    assert [len(f.signatures) for f in functions] == signatures, (
        "a kernel compiled again after warming: its inputs' types differ "
        "between its sample and later calls")


def test_a_compiled_function_computes_as_numpy_does():
    @compiled.compiled
    def ratio(a, b):
        return a / b

    assert compiled.is_compiled(ratio)
    assert ratio(1.0, 0.0) == np.inf
    assert np.isnan(ratio(0.0, 0.0))
    assert not compiled.is_compiled(lambda x: x)


def test_a_sealed_function_refuses_other_arrays_instead_of_compiling():
    """compiled_for compiles its one signature when it is made and never
    again: other arrays raise TypeError (which its wrapper answers with
    float_array copies), numbers convert to its scalars."""
    @compiled.compiled_for("float64(float64[::1], float64)")
    def weighted_sum(x, w):
        return w * x.sum()

    assert compiled.is_compiled(weighted_sum)
    assert len(weighted_sum.signatures) == 1
    x = np.arange(6.0)
    assert weighted_sum(x, 2) == 30.0
    read_only = x.copy()
    read_only.flags.writeable = False
    for other in (x[::2], read_only, list(x), x.astype(np.float32)):
        with pytest.raises(TypeError):
            weighted_sum(other, 1.0)
        assert weighted_sum(compiled.float_array(other), 1.0) == \
            float(np.sum(other, dtype=float))
    assert len(weighted_sum.signatures) == 1


def test_float_array_gives_the_one_array_type_the_compiled_loops_take():
    """A float64 C-contiguous aligned writeable array passes as it is;
    anything else (read-only, strided, unaligned, big-endian, int, a
    list) is copied into one, which a compiled function takes without
    compiling a signature of its own."""
    @compiled.compiled
    def total(x):
        return x.sum()

    right = np.arange(6.0)
    assert compiled.float_array(right) is right
    read_only = np.arange(6.0)
    read_only.flags.writeable = False
    unaligned = np.zeros(6 * 8 + 1, np.uint8)[1:].view(np.float64)
    unaligned[:] = right
    others = [read_only, np.repeat(right, 2)[::2], unaligned,
              right.astype(">f8"), np.arange(6), right.tolist()]
    total(right)
    signatures = list(total.signatures)
    for other in others:
        copy = compiled.float_array(other)
        assert copy is not other
        np.testing.assert_array_equal(copy, np.asarray(other, dtype=float))
        assert total(copy) == total(right)
    assert list(total.signatures) == signatures


CLOSED_LOOP = """
description: a person walking past the base, seen by both LIDARs
duration: 1.5
scene:
  people: [{name: walker, times: [0.0, 4.0],
            waypoints: [[3.0, 1.0], [-3.0, 1.0]]}]
"""


def test_the_closed_loops_ticks_compile_nothing():
    """The simulated station's LIDAR scans (a person walking past, so the
    tracker's and the people's kernels run too) give the compiled loops
    nothing they were not warmed with when the controller was built."""
    from drake_wbc.experiments.runner import build_closed_loop, start_simulator
    from drake_wbc.experiments.scenario import load_scenario

    loop = build_closed_loop(load_scenario(text=CLOSED_LOOP))
    simulator = start_simulator(loop)
    functions = _compiled_functions()
    signatures = [list(f.signatures) for f in functions]
    assert any(signatures)  # warmed when the controller was built
    simulator.AdvanceTo(1.5)
    assert [list(f.signatures) for f in functions] == signatures


def test_no_compiled_function_calls_one_of_another_module():
    """Numba's cache knows a compiled function by its own file only
    (drake_wbc.math.compiled): one that called a compiled function of
    another module would run that one's old machine code after it
    changed."""
    import inspect
    import re

    crossing = []
    for function in _compiled_functions():
        module = function.py_func.__module__
        called = set(re.findall(r"\b([A-Za-z_]\w*)\s*\(",
                                inspect.getsource(function.py_func)))
        for name in called:
            other = function.py_func.__globals__.get(name)
            if (compiled.is_compiled(other)
                    and other.py_func.__module__ != module):
                crossing.append(f"{module}.{function.__name__} -> "
                                f"{other.py_func.__module__}.{name}")
    assert _compiled_functions() and not crossing, crossing

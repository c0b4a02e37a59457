"""BaseVelocityFilter against eq. (filtering): Drake's linearisation of the
very system the controller uses, compared with closed forms."""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd
from pydrake.symbolic import Expression
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (
    ConstantVectorSource,
    Linearize,
    VectorLogSink,
)

from drake_wbc.analysis.frequency import linear_system_response
from drake_wbc.math.filtering import (
    BaseFilterParameters,
    check_filter_period,
    lowpass_response,
    lowpass_state_space,
    lowpass_zoh_response,
    zero_order_hold,
)
from drake_wbc.stages import BaseVelocityFilter
from drake_wbc.stages.base_filter import MODEL_NAME

FREQUENCIES_HZ = np.logspace(-2, 2, 200)
OMEGA = 2 * np.pi * FREQUENCIES_HZ


def linearize(params, time_step):
    system = BaseVelocityFilter(params, time_step=time_step)
    context = system.CreateDefaultContext()
    system.get_input_port().FixValue(context, np.zeros(3))
    return Linearize(system, context)


def assert_diagonal_response(response, expected):
    for axis in range(3):
        relative = np.abs(response[:, axis, axis] - expected) / np.abs(
            expected)
        assert relative.max() < 1e-6
        off = np.delete(response[:, axis, :], axis, axis=1)
        assert np.abs(off).max() == 0.0


@pytest.mark.parametrize("zeta", [0.5, 1.0, 2.0])
def test_continuous_linearization_matches_eq_filtering(zeta):
    params = BaseFilterParameters(omega_f=2 * np.pi, zeta=zeta)
    linear = linearize(params, 0.0)
    assert linear.time_period() == 0.0
    assert_diagonal_response(linear_system_response(linear, OMEGA),
                             lowpass_response(params.omega_f, zeta, OMEGA))


@pytest.mark.parametrize("zeta", [0.5, 1.0, 2.0])
@pytest.mark.parametrize("time_step", [0.01, 0.002])
def test_discrete_linearization_matches_exact_zoh_equivalent(zeta,
                                                             time_step):
    params = BaseFilterParameters(omega_f=2 * np.pi, zeta=zeta)
    linear = linearize(params, time_step)
    assert linear.time_period() == time_step
    expected = lowpass_zoh_response(params.omega_f, zeta, time_step, OMEGA)
    assert_diagonal_response(linear_system_response(linear, OMEGA), expected)


def test_zoh_equivalent_tends_to_the_continuous_filter():
    """Below a tenth of the sampling rate the discrete filter is the
    continuous one up to the hold's half-period delay."""
    omega = OMEGA[FREQUENCIES_HZ < 5]
    h = 0.001
    delayed = lowpass_response(2 * np.pi, 1.0, omega) * np.exp(
        -1j * omega * h / 2)
    discrete = lowpass_zoh_response(2 * np.pi, 1.0, h, omega)
    assert np.abs(discrete - delayed).max() < 1e-3


def test_step_response_is_exact_at_the_samples():
    """With zeta = 1 the step response is 1 - (1 + w t) e^(-w t); the
    zero-order-hold discretisation reproduces it exactly at each sample."""
    params, h = BaseFilterParameters(), 0.01
    builder = DiagramBuilder()
    system = builder.AddSystem(BaseVelocityFilter(params, time_step=h))
    step = np.array([0.1, -0.05, 0.2])
    source = builder.AddSystem(ConstantVectorSource(step))
    builder.Connect(source.get_output_port(), system.get_input_port())
    log = builder.AddSystem(VectorLogSink(3, publish_period=h))
    builder.Connect(system.get_output_port(), log.get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(2.0)
    data = log.FindLog(simulator.get_context())
    t = data.sample_times()
    w = params.omega_f
    expected = np.outer(step, 1 - (1 + w * t) * np.exp(-w * t))
    np.testing.assert_allclose(data.data(), expected, atol=1e-12)


def test_scalar_conversion_keeps_the_model():
    """The converted copies (Drake's) keep the ports, the period and the
    matrices of the parameters the stage was built with."""
    params = BaseFilterParameters(omega_f=3.0, zeta=0.7)
    system = BaseVelocityFilter(params, time_step=0.005)
    A, B = zero_order_hold(*lowpass_state_space(3.0, 0.7)[:2], 0.005)
    for converted in (system.ToAutoDiffXd(), system.ToSymbolic()):
        assert converted.GetUniquePeriodicDiscreteUpdateAttribute(
            ).period_sec() == 0.005
        assert converted.get_input_port().get_name() == "velocity"
        assert converted.get_output_port().get_name() == "filtered_velocity"
        model = converted.GetSubsystemByName(MODEL_NAME)
        np.testing.assert_array_equal(_floats(model.A())[2:4, 2:4], A)
        np.testing.assert_array_equal(_floats(model.B())[4:6, 2:3], B)


def _float(value):
    if isinstance(value, AutoDiffXd):
        return value.value()
    if isinstance(value, Expression):
        return value.Evaluate()
    return float(value)


def _floats(values):
    """An array of floats, AutoDiffXd or constant Expressions as floats."""
    return np.vectorize(_float, otypes=[float])(
        np.asarray(values, dtype=object))


@pytest.mark.parametrize("enabled", [True, False])
@pytest.mark.parametrize("time_step", [0.01, 0.0])
def test_the_linear_system_is_eq_filtering_on_each_axis(enabled, time_step):
    """The stage's C++ LinearSystem against eq. (filtering) axis by axis
    (lowpass_state_space and zero_order_hold of one axis; the bypass
    x+ = [u, 0]), on random states and inputs, in double, AutoDiffXd
    and symbolic: the update (or derivatives) and the output."""
    if not enabled and time_step == 0.0:
        return  # not allowed (test_a_bad_time_step_for_the_filter...)
    params = BaseFilterParameters(omega_f=4.0, zeta=0.8, enabled=enabled)
    A, B, C, _ = lowpass_state_space(4.0, 0.8)
    if not enabled:
        A, B = np.zeros((2, 2)), np.array([[1.0], [0.0]])
    elif time_step > 0.0:
        A, B = zero_order_hold(A, B, time_step)
    double = BaseVelocityFilter(params, time_step=time_step)
    rng = np.random.default_rng(22)
    for system in (double, double.ToAutoDiffXd(), double.ToSymbolic()):
        context = system.CreateDefaultContext()
        for _ in range(20):
            x, u = rng.normal(size=6), rng.normal(size=3)
            system.get_input_port().FixValue(context, u)
            if time_step > 0.0:
                context.SetDiscreteState(x)
                new = system.EvalUniquePeriodicDiscreteUpdate(
                    context).get_vector().CopyToVector()
            else:
                context.SetContinuousState(x)
                new = system.EvalTimeDerivatives(context).CopyToVector()
            output = system.get_output_port().Eval(context)
            for axis in range(3):
                part = slice(2 * axis, 2 * axis + 2)
                np.testing.assert_allclose(
                    _floats(new[part]), A @ x[part] + B[:, 0] * u[axis],
                    rtol=0, atol=1e-14)
                assert _float(output[axis]) == (C @ x[part])[0]


def test_set_velocity_starts_at_rest():
    system = BaseVelocityFilter()
    context = system.CreateDefaultContext()
    system.get_input_port().FixValue(context, [0.3, 0.0, 0.1])
    system.set_velocity(context, [0.3, 0.0, 0.1])
    np.testing.assert_allclose(system.get_output_port().Eval(context),
                               [0.3, 0.0, 0.1])
    state = context.get_discrete_state_vector().CopyToVector()
    update = system.EvalUniquePeriodicDiscreteUpdate(context)
    np.testing.assert_allclose(update.get_vector().CopyToVector(), state,
                               atol=1e-12)


def test_zero_order_hold_of_a_scalar_lag():
    """e^(-h/T) and 1 - e^(-h/T) for x_dot = (u - x) / T."""
    A_d, B_d = zero_order_hold(np.array([[-2.0]]), np.array([[2.0]]), 0.1)
    assert A_d[0, 0] == pytest.approx(np.exp(-0.2), rel=1e-14)
    assert B_d[0, 0] == pytest.approx(1 - np.exp(-0.2), rel=1e-14)


@pytest.mark.parametrize("kwargs, name", [
    (dict(omega_f=0.0), "omega_f"),
    (dict(omega_f=-1.0), "omega_f"),
    (dict(zeta=0.0), "zeta"),
    (dict(zeta=float("nan")), "zeta"),
])
def test_bad_parameters_are_rejected(kwargs, name):
    with pytest.raises(ValueError, match=name):
        BaseFilterParameters(**kwargs)


@pytest.mark.parametrize("params, time_step, fragment", [
    (BaseFilterParameters(), -0.01, "time_step = -0.01"),
    (BaseFilterParameters(omega_f=400.0), 0.01,
     "time_step = 0.01 s is not allowed with omega_f = 400.0 rad/s"),
    (BaseFilterParameters(omega_f=20.0), 0.2, "Nyquist"),
    (BaseFilterParameters(enabled=False), 0.0,
     "time_step = 0 is not allowed with enabled = False"),
])
def test_a_bad_time_step_for_the_filter_is_rejected(params, time_step,
                                                   fragment):
    """The stage checks its time step against its parameters when it is
    built (filtering.check_filter_period), with what is allowed."""
    with pytest.raises(ValueError) as error:
        BaseVelocityFilter(params, time_step=time_step)
    assert fragment in str(error.value)
    assert "not allowed" in str(error.value)
    with pytest.raises(ValueError, match="base_filter.omega_f|base_filter."
                       "enabled|time_step = -0.01"):
        check_filter_period(params, time_step, prefix="base_filter.")
    # Just below the Nyquist rate is allowed.
    assert check_filter_period(BaseFilterParameters(omega_f=314.0),
                               0.01) == 0.01


def test_bad_filter_math_arguments_are_rejected():
    with pytest.raises(ValueError, match="omega_f"):
        lowpass_state_space(0.0, 1.0)
    with pytest.raises(ValueError, match="zeta"):
        lowpass_state_space(1.0, -1.0)
    with pytest.raises(ValueError, match="time_step"):
        zero_order_hold(np.eye(2), np.ones((2, 1)), 0.0)


def test_bypassed_filter_holds_the_input_for_one_period():
    params = BaseFilterParameters(enabled=False)
    filt = BaseVelocityFilter(params, time_step=0.01)
    context = filt.CreateDefaultContext()
    first, second = np.array([0.1, -0.2, 0.3]), np.array([-0.4, 0.5, 0.6])
    filt.get_input_port().FixValue(context, first)
    simulator = Simulator(filt, context)
    simulator.AdvanceTo(0.005)  # sampled at t = 0
    np.testing.assert_array_equal(filt.get_output_port().Eval(context), first)
    filt.get_input_port().FixValue(context, second)
    simulator.AdvanceTo(0.0099)
    np.testing.assert_array_equal(filt.get_output_port().Eval(context), first)
    simulator.AdvanceTo(0.015)  # sampled at t = 0.01
    np.testing.assert_array_equal(filt.get_output_port().Eval(context),
                                  second)


def test_bypass_needs_a_control_period():
    with pytest.raises(ValueError, match="enabled = False"):
        BaseVelocityFilter(BaseFilterParameters(enabled=False),
                           time_step=0.0)

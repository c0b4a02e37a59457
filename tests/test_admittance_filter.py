"""The admittance's lag on F_ext (drake_wbc.math.cdmp.admittance_filter_model,
stages.admittance_filter): its step response against the first-order lag's
closed form, the whole body's admittance it makes (M V_dot + D V = F,
M = T_hri / k_hri) through the whole-body CDMP, its scalar conversion and
linearisation, its parameter's checks, and where the controller puts it."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (
    ConstantVectorSource,
    Linearize,
    VectorLogSink,
)

from drake_wbc.analysis.frequency import linear_system_response
from drake_wbc.controller.diagram import build_controller
from drake_wbc.controller.parameters import ControllerParameters
from drake_wbc.math import cdmp
from drake_wbc.stages.admittance_filter import AdmittanceFilter
from drake_wbc.stages.whole_body_cdmp import WholeBodyCdmp

H = 0.01
WRENCH = np.array([2.0, -1.0, 0.5, 0.1, 0.0, -0.2])
"""A step of F_ext, N and N m, in every component."""


def simulate(filter_stage, wrench=WRENCH, ticks=50):
    """The stage's output at the ticks 0 .. ticks - 1 (discrete) or at
    t = 0, h, ..., (continuous), for a constant input from t = 0."""
    builder = DiagramBuilder()
    stage = builder.AddSystem(filter_stage)
    source = builder.AddSystem(ConstantVectorSource(wrench))
    builder.Connect(source.get_output_port(), stage.get_input_port(0))
    log = builder.AddSystem(VectorLogSink(6, H))
    builder.Connect(stage.get_output_port(0), log.get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.get_mutable_integrator().set_target_accuracy(1e-10)
    simulator.AdvanceTo((ticks - 0.5) * H)
    return log.FindLog(simulator.get_context()).data().T


@pytest.mark.parametrize("T", [0.03, 0.1, 1.0])
def test_discrete_step_response_is_the_lag_sampled_at_each_periods_end(T):
    """F_bar_k = (1 - exp(-(k + 1) h / T)) F: the continuous lag's step
    response at the end of the k-th period (no tick of delay)."""
    out = simulate(AdmittanceFilter(T, time_step=H))
    k = np.arange(len(out))[:, None]
    expected = (1.0 - np.exp(-(k + 1) * H / T)) * WRENCH
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-13)


def test_continuous_step_response_is_the_lag():
    out = simulate(AdmittanceFilter(0.1, time_step=0.0))
    t = H * np.arange(len(out))[:, None]
    np.testing.assert_allclose(out, (1.0 - np.exp(-t / 0.1)) * WRENCH,
                               rtol=0, atol=1e-8)


@pytest.mark.parametrize("T", [0.0, 0.1])
def test_the_whole_body_follows_the_push_as_an_admittance_of_mass_T_over_k(T):
    """With S_hri = 1 and no reference the whole-body CDMP passes
    k_hri F_bar through as its velocity (eq. (tf-admit)), so the
    end effector's commanded velocity obeys M V_dot + V / k_hri = F with
    M = T / k_hri: V = k_hri F (1 - exp(-t / T)), sampled as above; T = 0
    is the paper's V = k_hri F from the first tick."""
    params = cdmp.WholeBodyCdmpParameters(k_hri=0.05, hri_time_constant=T)
    builder = DiagramBuilder()
    whole_body = builder.AddSystem(WholeBodyCdmp(params, time_step=H,
                                                 phri_switch=1.0))
    source = builder.AddSystem(ConstantVectorSource(WRENCH))
    if T > 0:
        lag = builder.AddSystem(AdmittanceFilter(T, time_step=H))
        builder.Connect(source.get_output_port(), lag.get_input_port(0))
        builder.Connect(lag.get_output_port(0),
                        whole_body.GetInputPort("wrench"))
    else:
        builder.Connect(source.get_output_port(),
                        whole_body.GetInputPort("wrench"))
    for name, size in (("reference_velocity", 6),
                       ("end_effector_deviation", 6), ("base_yaw", 1)):
        zero = builder.AddSystem(ConstantVectorSource(np.zeros(size)))
        builder.Connect(zero.get_output_port(), whole_body.GetInputPort(name))
    log = builder.AddSystem(VectorLogSink(6, H))
    builder.Connect(whole_body.GetOutputPort("end_effector_velocity"),
                    log.get_input_port())
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(40.5 * H)
    velocity = log.FindLog(simulator.get_context()).data().T
    k = np.arange(len(velocity))[:, None]
    rise = np.ones_like(k) if T == 0 else 1.0 - np.exp(-(k + 1) * H / T)
    np.testing.assert_allclose(velocity, 0.05 * WRENCH * rise, rtol=0,
                               atol=1e-12)


def test_linearisation_is_the_exponential_smoothing():
    """Drake's Linearize (through the stage's AutoDiffXd copy): per
    component
    (1 - a) z / (z - a), a = exp(-h / T)."""
    T = 0.1
    stage = AdmittanceFilter(T, time_step=H)
    context = stage.CreateDefaultContext()
    stage.get_input_port(0).FixValue(context, np.zeros(6))
    linear = Linearize(stage, context)
    omega = 2 * np.pi * np.logspace(-2, np.log10(49.0), 50)
    response = linear_system_response(linear, omega)
    a = np.exp(-H / T)
    z = np.exp(1j * omega * H)
    expected = (1 - a) * z / (z - a)
    for i in range(6):
        np.testing.assert_allclose(response[:, i, i], expected, rtol=1e-12)
    off = response.copy()
    for i in range(6):
        off[:, i, i] = 0
    assert np.abs(off).max() == 0


@pytest.mark.parametrize("value, message", [
    (-0.1, "hri_time_constant = -0.1 .* not allowed"),
    (float("nan"), "hri_time_constant = nan .* not allowed"),
    (11.0, "hri_time_constant = 11.0 s is not allowed: must be at most 10"),
])
def test_a_bad_time_constant_is_named(value, message):
    with pytest.raises(ValueError, match=message):
        cdmp.WholeBodyCdmpParameters(hri_time_constant=value)


@pytest.mark.parametrize("T, present", [(0.0, False), (0.1, True)])
def test_the_controller_puts_the_lag_before_the_whole_body_cdmp(T, present):
    params = ControllerParameters(
        whole_body_cdmp=cdmp.WholeBodyCdmpParameters(hri_time_constant=T))
    controller = build_controller(params).diagram
    names = {system.get_name() for system in controller.GetSystems()}
    assert ("admittance_filter" in names) == present
    whole_body = controller.GetSubsystemByName("whole_body_cdmp")
    source = controller.connection_map()[
        (whole_body, whole_body.GetInputPort("wrench").get_index())]
    assert source[0].get_name() == ("admittance_filter" if present
                                    else "wrench")

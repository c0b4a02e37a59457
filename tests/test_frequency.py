"""Frequency responses of the filter chain and the coupled DMPs
(drake_wbc.analysis): Drake's linearisations against the paper's closed
forms, against independent formulations, and against simulation."""

from dataclasses import replace

import numpy as np
import pytest
from omni_arm import write_omni_arm
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (
    ConstantVectorSource,
    Linearize,
    LinearSystem,
    LogVectorOutput,
    MatrixGain,
    Sine,
)

from drake_wbc.analysis import (
    admittance_loop,
    bode,
    chains,
    closed_forms,
    plant_chain,
)
from drake_wbc.analysis.dmp_force_response import linearize_dmp_force
from drake_wbc.analysis.frequency import (
    StabilityMargins,
    bandwidth,
    coupled_states,
    frequency_grid,
    frequency_response,
    linear_system_response,
    peak_gain,
    response_function,
    stability_margins,
)
from drake_wbc.analysis.period_map import linearize_period_map
from drake_wbc.analysis.report import base_share_gain, compute_bode_report
from drake_wbc.experiments.scenario import (
    find_scenario,
    load_scenario,
    scenario_station,
    station_base,
)
from drake_wbc.math import cdmp
from drake_wbc.math.compensation import RobustCompensatorParameters
from drake_wbc.math.dmp import DmpParameters
from drake_wbc.math.filtering import (
    BaseFilterParameters,
    lowpass_response,
    lowpass_zoh_response,
    zero_order_hold,
)
from drake_wbc.math.repulsion import RepulsiveFieldParameters
from drake_wbc.robot.description import load_robot_description
from drake_wbc.robot.model import ArmKinematics, ArmMount
from drake_wbc.stages import BaseCdmp
from drake_wbc.stages.cdmp_stages import AffineDynamics
from drake_wbc.station.drivers import BaseVelocityDriver
from drake_wbc.station.simulation import SimulatedStation, StationOptions

HERTZ, OMEGA = frequency_grid(0.01, 100.0, 40)
"""The log grid of the checks, 0.01 to 100 Hz."""

H = 0.01


def off_sampling_rate(time_step):
    """The grid without the frequencies that alias onto DC at `time_step`
    (100 Hz at 100 Hz), where a discrete integrator's pole z = 1 lies."""
    if time_step == 0.0:
        return OMEGA
    cycles = OMEGA * time_step / (2 * np.pi)
    return OMEGA[np.abs(cycles - np.round(cycles)) > 1e-6]


def relative_error(actual, expected):
    return np.max(np.abs(actual - expected) / np.abs(expected))


@pytest.fixture(scope="module")
def scenario():
    return load_scenario(find_scenario("trajectory_tracking"))


@pytest.fixture(scope="module")
def point(scenario):
    return chains.operating_point(scenario.controller,
                                  scenario.station.initial_arm_positions)


@pytest.fixture(scope="module")
def driver(scenario):
    return station_base(scenario)


@pytest.fixture(scope="module")
def step(scenario):
    """The base driver's step: the station's."""
    return scenario.station.time_step


# The base filter, eq. (filtering).

@pytest.mark.parametrize("zeta", [1.0, 0.7, 1.6])
@pytest.mark.parametrize("time_step", [0.0, H])
def test_base_filter_matches_eq_filtering(zeta, time_step):
    params = BaseFilterParameters(omega_f=2 * np.pi, zeta=zeta)
    response = linear_system_response(
        chains.linearize_base_filter(params, time_step), OMEGA)
    expected = (lowpass_response(params.omega_f, zeta, OMEGA)
                if time_step == 0.0 else
                lowpass_zoh_response(params.omega_f, zeta, time_step, OMEGA))
    for axis in range(3):
        assert relative_error(response[:, axis, axis], expected) < 1e-6
    off_axis = response[:, 0, 1:]
    assert np.abs(off_axis).max() < 1e-12


def state_space_zoh_response(b1, b0, a2, a1, a0, time_step, omega):
    """(b1 s + b0) / (a2 s^2 + a1 s + a0) held over `time_step`, from the
    matrix exponential of its companion form (filtering.zero_order_hold),
    independently of the partial fractions of the closed forms."""
    A = np.array([[0.0, 1.0], [-a0 / a2, -a1 / a2]])
    A_d, B_d = zero_order_hold(A, np.array([[0.0], [1.0]]), time_step)
    return frequency_response(A_d, B_d, [[b0 / a2, b1 / a2]], [[0.0]],
                              omega, time_step)[:, 0, 0]


FILTER_ZETAS = (1.0, 0.7, 1.6, 1.0 + 1e-6, 1.0 + 1e-13, 1.0 - 4e-12)
"""Damping ratios of eq. (filtering) (w = 3 rad/s): the paper's double
pole, two pairs apart, and pairs a rounding apart."""

DMP_TAUS = (1.0, 1.1, 1.3, 1.5, 2.3, 3.1)
"""tau of the critically damped DMPs (beta_z = alpha_z / 4, the
default) of eq. (lp-admit): for most tau a1^2 - 4 a2 a0 rounds to
+-1e-13 rather than 0."""


@pytest.mark.parametrize("kind, value", [
    *(("filter", zeta) for zeta in FILTER_ZETAS),
    *(("dmp", tau) for tau in DMP_TAUS)])
def test_second_order_zoh_form_agrees_with_the_filters(kind, value):
    """The closed forms of a held second order, eq. (filtering)'s and
    the general one (eq. (lp-admit)'s), against the hold of its state
    space to 1e-10 of the response's peak (the gain near the Nyquist
    frequency is 1e-4 of it), also with poles a rounding apart, where
    the partial fractions' residues 1 / (p_1 - p_2) lost half the digits
    (1e-6 off for the DMP at tau = 3.1, alpha_z = 10)."""
    if kind == "filter":
        w = 3.0
        cases = [(0.0, w * w, 1.0, 2 * value * w, w * w)]
    else:
        cases = [closed_forms.stiffness_coupled_coefficients(
            5e-4, 0.2, value, alpha_z, alpha_z / 4.0, velocity_scale=1.0)
            for alpha_z in (25.0, 10.0, 7.3)]

    def error(actual, expected):
        return np.abs(actual - expected).max() / np.abs(expected).max()

    for coefficients in cases:
        exact = state_space_zoh_response(*coefficients, H, OMEGA)
        assert error(closed_forms.second_order_zoh_response(
            *coefficients, H, OMEGA), exact) < 1e-10
    if kind == "filter":
        assert error(lowpass_zoh_response(3.0, value, H, OMEGA),
                     exact) < 1e-10


# The coupled DMPs, eqs. (lp-admit) and (tf-admit).

@pytest.mark.parametrize("time_step", [0.0, H])
@pytest.mark.parametrize("dmp", [DmpParameters(),
                                 DmpParameters(alpha_z=20.0, beta_z=8.0),
                                 DmpParameters(tau=0.6, alpha_z=30.0,
                                               beta_z=5.0)])
@pytest.mark.parametrize("k_d", [0.0, 0.4])
def test_arm_stiffness_axis_matches_eq_lp_admit(scenario, time_step, dmp,
                                                k_d):
    """The arm's stiffness axis against eq. (lp-admit) with C_s entering
    tau y_dot without the factor tau, as eq. (cdmp-arm) prints it
    (velocity_scale 1): at tau = 0.6 it is not eq. (stiff-dmp)'s tau C_f
    (with tau = 1 alone the two could not be told apart)."""
    arm = replace(scenario.controller.arm_cdmp, k_d=k_d, dmp=dmp)
    params = replace(scenario.controller, arm_cdmp=arm)
    # Off the alias of DC, where the force axes' integrators C_a make
    # zI - A singular.
    omega = off_sampling_rate(time_step)
    response = linearize_dmp_force("stiffness", params, time_step,
                                   axis=1).response(omega)
    args = (arm.k_p, k_d, dmp.tau, dmp.alpha_z, dmp.resolved_beta_z)
    expected = (closed_forms.lp_admit_response(*args, omega,
                                               velocity_scale=1.0)
                if time_step == 0.0 else
                closed_forms.lp_admit_zoh_response(*args, time_step, omega,
                                                   velocity_scale=1.0))
    assert relative_error(response, expected) < 1e-6
    if dmp.tau != 1.0:
        paper = closed_forms.lp_admit_response(*args, omega)
        assert relative_error(closed_forms.lp_admit_response(
            *args, omega, velocity_scale=1.0), paper) > 0.1


@pytest.mark.parametrize("time_step", [0.0, H])
@pytest.mark.parametrize("kind", ["admittance", "phri"])
def test_admittance_couplings_match_eq_tf_admit(scenario, time_step, kind):
    params = scenario.controller
    gain = (params.arm_cdmp.k_f if kind == "admittance"
            else params.whole_body_cdmp.k_hri)
    omega = off_sampling_rate(time_step)
    response = linearize_dmp_force(kind, params, time_step,
                                   axis=2).response(omega)
    expected = (closed_forms.tf_admit_response(gain, omega)
                if time_step == 0.0 else
                closed_forms.tf_admit_zoh_response(gain, time_step, omega))
    assert relative_error(response, expected) < 1e-6


def test_the_closed_forms_are_the_papers_printed_ones():
    """Eqs. (lp-admit) and (tf-admit) as printed, term by term, at
    tau != 1, and their ZOH forms against scipy's discretisation: the
    other checks compare the closed forms with stages built on the same
    reading of eq. (stiff-dmp), which a shared slip would pass."""
    from scipy.signal import cont2discrete, freqz

    k_p, k_d, tau, alpha_z, beta_z = 0.002, 0.3, 0.6, 30.0, 5.0
    s = 1j * OMEGA
    printed = ((k_p * (tau**2 + k_d) * s + k_p * tau * alpha_z)
               / (tau**2 * s**2 + tau * alpha_z * s + alpha_z * beta_z))
    args = (k_p, k_d, tau, alpha_z, beta_z)
    assert relative_error(closed_forms.lp_admit_response(*args, OMEGA),
                          printed) < 1e-12
    assert relative_error(closed_forms.tf_admit_response(0.02, OMEGA),
                          0.02 / s) < 1e-12
    omega = off_sampling_rate(H)
    for velocity_scale in (None, 1.0):
        b1, b0, a2, a1, a0 = closed_forms.stiffness_coupled_coefficients(
            *args, velocity_scale)
        numerator, denominator, _ = cont2discrete(
            ([b1, b0], [a2, a1, a0]), H, method="zoh")
        _, expected = freqz(numerator.ravel(), denominator, worN=omega * H)
        assert relative_error(closed_forms.lp_admit_zoh_response(
            *args, H, omega, velocity_scale), expected) < 1e-8
    numerator, denominator, _ = cont2discrete(([0.02], [1.0, 0.0]), H,
                                              method="zoh")
    _, expected = freqz(numerator.ravel(), denominator, worN=omega * H)
    assert relative_error(closed_forms.tf_admit_zoh_response(0.02, H, omega),
                          expected) < 1e-8


def _math_layer_model(derivative, num_states, time_step):
    """(A, B) of a one-axis DMP of drake_wbc.math.cdmp from its derivative
    function (no Drake system)."""
    model = AffineDynamics(derivative, num_states, 1, time_step)
    if time_step > 0.0:
        return model.A_d, model.B_d
    return model.A, model.B


@pytest.mark.parametrize("time_step", [0.0, H])
def test_math_layer_dmps_match_the_paper_for_any_tau(time_step):
    dmp = DmpParameters(tau=0.6, alpha_z=30.0, beta_z=5.0)
    stiff = cdmp.StiffnessCouplingParameters(k_p=0.002, k_d=0.3, dmp=dmp)

    def stiffness(x, u):
        return np.concatenate(cdmp.stiffness_coupled_derivative(
            x[:1], x[1:], np.zeros(1), u, stiff))

    A, B = _math_layer_model(stiffness, 2, time_step)
    response = frequency_response(A, B, [[1.0, 0.0]], [[0.0]], OMEGA,
                                  time_step)[:, 0, 0]
    args = (stiff.k_p, stiff.k_d, dmp.tau, dmp.alpha_z, dmp.beta_z)
    expected = (closed_forms.lp_admit_response(*args, OMEGA)
                if time_step == 0.0 else
                closed_forms.lp_admit_zoh_response(*args, time_step, OMEGA))
    assert relative_error(response, expected) < 1e-6

    admit = cdmp.AdmittanceCouplingParameters(D_a=0.02, dmp=dmp)

    def admittance(x, u):
        return np.concatenate(cdmp.admittance_coupled_derivative(
            x[:1], x[1:2], x[2:], np.zeros(1), u, admit))

    A, B = _math_layer_model(admittance, 3, time_step)
    omega = off_sampling_rate(time_step)
    response = frequency_response(A, B, [[1.0, 0.0, 0.0]], [[0.0]], omega,
                                  time_step)[:, 0, 0]
    expected = (closed_forms.tf_admit_response(0.02, omega)
                if time_step == 0.0 else
                closed_forms.tf_admit_zoh_response(0.02, time_step, omega))
    assert relative_error(response, expected) < 1e-6


# The split of the end-effector command.

@pytest.mark.parametrize("mount", [None, ArmMount(yaw=0.6, tilt=0.3)],
                         ids=["shipped", "turned-and-tilted"])
def test_ideal_split_sums_to_unity(scenario, point, mount):
    """The split with ideal actuators reproduces V_ee on every axis, the
    base's share k_b (report.base_share_gain) times the discrete filter,
    also on an arm turned and tilted on its base (k_b once took ^bR_a for
    the identity: 0.521 for the split's 0.514)."""
    if mount is not None:
        point = chains.operating_point(scenario.controller, None,
                                       ArmKinematics(mount=mount))
    assert point.alpha == 0.0
    response = linear_system_response(
        chains.linearize_split(scenario.controller, point), OMEGA)
    total = response[:, 12:18, :]
    for axis in range(6):
        sum_axis = total[:, axis, axis]
        assert np.abs(np.abs(sum_axis) - 1.0).max() < 1e-9
        assert np.abs(np.angle(sum_axis)).max() < 1e-9
    assert np.abs(total - np.eye(6)).max() < 1e-9
    # The base's share is k_b times the discrete filter, the arm's the
    # rest.
    f = scenario.controller.base_filter
    k_b = base_share_gain(point)
    if mount is None:
        assert k_b == pytest.approx(0.5, abs=1e-3)  # sigma_xy = 0.5
    base = k_b * lowpass_zoh_response(f.omega_f, f.zeta, H, OMEGA)
    assert relative_error(response[:, 0, 0], base) < 1e-6
    assert relative_error(response[:, 6, 0], 1.0 - base) < 1e-6


def test_split_with_alpha_gives_way(scenario, point):
    # With robust compensation active (alpha = 1, s_c = 1) the arm leaves
    # out the compensation along grad_x C_m: the sum is no longer one.
    params = replace(scenario.controller,
                     compensator=RobustCompensatorParameters(1.0))
    response = linear_system_response(
        chains.linearize_split(params, point, alpha=1.0), OMEGA)
    assert np.abs(response[:, 12, 0] - 1.0).max() > 0.05


@pytest.mark.parametrize("rate", [0.0, 1e-3])
def test_period_map_refuses_a_point_that_moves_beside_a_large_state(rate):
    """An integrator fed `rate` beside a state that holds -1e9 (as a
    time that never was does): at rest it is an equilibrium; moving by
    1e-5 a period it is not, however large the other entry (the
    tolerance once scaled with the largest entry, and took it)."""
    h = 0.01
    system = LinearSystem(np.eye(2), np.array([[0.0], [h]]), np.eye(2),
                          np.zeros((2, 1)), h)
    context = system.CreateDefaultContext()
    context.SetDiscreteState(np.array([-1e9, 0.5]))
    system.get_input_port().FixValue(context, [rate])

    def linearize():
        return linearize_period_map(system, context, h,
                                    system.get_input_port(),
                                    system.get_output_port())

    if rate == 0.0:
        np.testing.assert_array_equal(linearize().A(), np.eye(2))
    else:
        with pytest.raises(ValueError, match="not an equilibrium"):
            linearize()


@pytest.mark.parametrize("system", ["split", "obstacles"])
def test_period_map_equals_linearize_at_one_rate(scenario, point, system):
    """The period map of a system of one rate is Drake's Linearize: the
    split, and BaseCdmp pushed aside by two obstacle points 0.3 m from
    its footprint, at its equilibrium (its abstract input, which the
    map once tried to convert entry by entry into AutoDiffXd, a
    TypeError)."""
    if system == "split":
        diagram = chains.build_split_diagram(scenario.controller, point)
        context = diagram.CreateDefaultContext()
        source = diagram.GetInputPort("end_effector_velocity")
        output = diagram.GetOutputPort("shares")
        source.FixValue(context, np.zeros(6))
        direct = chains.linearize_split(scenario.controller, point)
    else:
        diagram = BaseCdmp(cdmp.BaseCdmpParameters(
            repulsion=RepulsiveFieldParameters(half_sizes=(0.4, 0.3))),
            time_step=H)
        context = diagram.CreateDefaultContext()
        source = diagram.GetInputPort("base_velocity")
        output = diagram.GetOutputPort("avoiding_base_velocity")
        source.FixValue(context, np.zeros(3))
        diagram.GetInputPort("obstacle_points").FixValue(
            context, AbstractValue.Make(np.array([[0.7, 0.1], [0.7, -0.2]])))
        Simulator(diagram, context).AdvanceTo(20.0)
        context.SetTime(0.0)
        force = diagram.repulsive_force(context)
        assert np.abs(force).max() > 1e-3
        direct = Linearize(diagram, context, source.get_index(),
                           output.get_index())
    lifted = chains.linearize_period_map(diagram, context, H, source, output)
    for name in ("A", "B", "C", "D"):
        assert np.allclose(getattr(lifted, name)(), getattr(direct, name)(),
                           rtol=0.0, atol=1e-12)


def test_base_loop_sum_departs_from_unity(scenario, point, driver, step):
    response = linear_system_response(chains.linearize_split(
        scenario.controller, point, base_driver=driver, base_step=step),
        OMEGA)
    total = response[:, 12, 0]
    assert abs(total[0] - 1.0) < 0.01  # DC: reproduced
    assert np.abs(total - 1.0).max() > 0.1  # the base's lag shows
    # The driver alone: the first-order lag, exactly discretised.
    loop = linear_system_response(chains.linearize_base_driver(
        driver, step), OMEGA)[:, 0, 0]
    q = np.exp(-step / driver.lag)
    z = np.exp(1j * OMEGA * step)
    assert relative_error(loop, (1.0 - q) / (z - q)) < 1e-6


# Linearisation against the simulated nonlinear diagram.

SIM_HZ = (0.5, 1.5, 4.0)
SETTLE, WINDOW, AMPLITUDE = 3.0, 4.0, 0.01


def _measured_response(system, input_size, output_port, axis):
    """Drives input `axis` of `system` with three small sinusoids, logs
    `output_port` every control period and fits the steady-state
    sinusoids by least squares: the complex gain at each of SIM_HZ."""
    builder = DiagramBuilder()
    plant = builder.AddSystem(system)
    omegas = 2 * np.pi * np.array(SIM_HZ)
    sines = builder.AddSystem(Sine(np.full(3, AMPLITUDE), omegas,
                                   np.zeros(3), 3))
    spread = np.zeros((input_size, 3))
    spread[axis] = 1.0
    gain = builder.AddSystem(MatrixGain(spread))
    builder.Connect(sines.get_output_port(0), gain.get_input_port())
    builder.Connect(gain.get_output_port(), plant.get_input_port(0))
    logger = LogVectorOutput(plant.GetOutputPort(output_port), builder, H)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(SETTLE + WINDOW + 1e-9)
    log = logger.FindLog(simulator.get_context())
    t, y = log.sample_times(), log.data()[axis]
    keep = t >= SETTLE - 1e-9
    t, y = t[keep], y[keep]
    design = np.column_stack([f(w * t) for w in omegas
                              for f in (np.sin, np.cos)] + [np.ones_like(t)])
    c = np.linalg.lstsq(design, y, rcond=None)[0]
    # y = a sin + b cos = Im((a + j b) e^(j w t)) for input Im(A e^(jwt)).
    return (c[0:6:2] + 1j * c[1:6:2]) / AMPLITUDE, omegas


def _check(measured, predicted):
    ratio = np.abs(measured) / np.abs(predicted)
    assert np.abs(ratio - 1.0).max() < 0.02
    phase = np.degrees(np.angle(measured / predicted))
    assert np.abs(phase).max() < 2.0


def test_base_filter_linearisation_matches_simulation():
    from drake_wbc.stages import BaseVelocityFilter

    params = BaseFilterParameters()
    measured, omegas = _measured_response(
        BaseVelocityFilter(params, time_step=H), 3, "filtered_velocity", 0)
    predicted = linear_system_response(
        chains.linearize_base_filter(params, H), omegas)[:, 0, 0]
    _check(measured, predicted)


def test_base_loop_chain_linearisation_matches_simulation(scenario, point,
                                                          driver, step):
    diagram = chains.build_split_diagram(scenario.controller, point, driver,
                                         base_step=step)
    measured, omegas = _measured_response(diagram, 6, "end_effector_velocity",
                                          0)
    predicted = linear_system_response(chains.linearize_split(
        scenario.controller, point, driver, base_step=step), omegas)[:, 12, 0]
    _check(measured, predicted)
    base, _ = _measured_response(
        chains.build_split_diagram(scenario.controller, point, driver,
                                   base_step=step), 6,
        "base_share", 0)
    _check(base, linear_system_response(chains.linearize_split(
        scenario.controller, point, driver, base_step=step),
        omegas)[:, 0, 0])


# The base's loop through the station's plant.

@pytest.fixture(scope="module")
def station(scenario):
    return scenario_station(scenario)


@pytest.fixture(scope="module")
def base_plant(station):
    """The driver and plant linearised at the plant's step."""
    return plant_chain.linearize_base_plant(station)


def test_base_plant_agrees_with_the_driver_at_low_frequency(
        station, base_plant, driver, step):
    low = OMEGA[HERTZ <= 0.1]
    plant = linear_system_response(base_plant, low)
    alone = linear_system_response(chains.linearize_base_driver(driver, step),
                                   low)
    for axis in range(3):  # the base's actual velocity: the loop's
        assert relative_error(plant[:, axis, axis],
                              alone[:, axis, axis]) < 0.01
    # A slow base translation carries the end effector along (no yaw:
    # its twist is the base's).
    assert relative_error(plant[:, 3, 0], alone[:, 0, 0]) < 0.01
    # The mount's rocking mode (5 Hz) shows in the end effector's
    # response, not in the base's.
    hertz, omega = frequency_grid(3.0, 8.0, 200)
    response = linear_system_response(base_plant, omega)
    peak, at = peak_gain(omega, response[:, 3, 0] / response[:, 0, 0])
    assert peak > 2.0 and 4.0 < at / (2 * np.pi) < 6.0


def test_split_through_the_plant(scenario, point, station, driver, step):
    with_plant = linear_system_response(chains.linearize_split(
        scenario.controller, point, station=station), OMEGA)
    with_driver = linear_system_response(chains.linearize_split(
        scenario.controller, point, base_driver=driver, base_step=step),
        OMEGA)
    assert with_plant.shape[1] == 18 + 9
    # The shares are those of the driver's loop, exactly.
    assert np.abs(with_plant[:, :18] - with_driver).max() < 1e-9
    low = HERTZ <= 0.1
    # The base's actual velocity is its share's at low frequency, and
    # the end effector reproduces the command there.
    for plant_row, driver_row in ((18, 0), (21, 12)):
        assert relative_error(with_plant[low, plant_row, 0],
                              with_driver[low, driver_row, 0]) < 0.01
    assert abs(with_plant[0, 21, 0] - 1.0) < 0.01
    with pytest.raises(ValueError, match="base_driver"):
        chains.build_split_diagram(scenario.controller, point, driver,
                                   station=station, base_step=step)


def _station_response(station, axis, outputs):
    """Drives the nonlinear station's base.velocity_command `axis` with
    three small sinusoids from its static equilibrium (the arm's command
    held), logs the (port, index) `outputs` every plant step and fits
    the steady-state sinusoids: the complex gains at SIM_HZ."""
    builder = DiagramBuilder()
    system = builder.AddSystem(station.diagram)
    omegas = 2 * np.pi * np.array(SIM_HZ)
    sines = builder.AddSystem(Sine(np.full(3, AMPLITUDE), omegas,
                                   np.zeros(3), 3))
    spread = np.zeros((3, 3))
    spread[axis] = 1.0
    gain = builder.AddSystem(MatrixGain(spread))
    builder.Connect(sines.get_output_port(0), gain.get_input_port())
    builder.Connect(gain.get_output_port(),
                    system.GetInputPort("base.velocity_command"))
    hold = builder.AddSystem(ConstantVectorSource(
        station.options.initial_arm_positions))
    builder.Connect(hold.get_output_port(),
                    system.GetInputPort("arm.position_command"))
    h = station.options.time_step
    loggers = [LogVectorOutput(system.GetOutputPort(port), builder, h)
               for port, _ in outputs]
    simulator = Simulator(builder.Build())
    station.set_initial_state(simulator.get_mutable_context())
    simulator.AdvanceTo(SETTLE + WINDOW + 1e-9)
    gains = []
    for logger, (_, index) in zip(loggers, outputs, strict=True):
        log = logger.FindLog(simulator.get_context())
        t, y = log.sample_times(), log.data()[index]
        keep = t >= SETTLE - 1e-9
        t, y = t[keep], y[keep]
        design = np.column_stack([f(w * t) for w in omegas
                                  for f in (np.sin, np.cos)]
                                 + [np.ones_like(t)])
        c = np.linalg.lstsq(design, y, rcond=None)[0]
        gains.append((c[0:6:2] + 1j * c[1:6:2]) / AMPLITUDE)
    return gains, omegas


def _base_plant_against_station(station, base_plant=None):
    """(base, tool, predicted): the station's base and tool velocity
    along x at SIM_HZ for a command along x (_station_response), and the
    base plant's linearisation there."""
    if base_plant is None:
        base_plant = plant_chain.linearize_base_plant(station)
    (base, end_effector), omegas = _station_response(
        station, 0, [("base.state_estimated", 3),
                     ("truth.end_effector_velocity", 0)])
    return base, end_effector, linear_system_response(base_plant, omegas)


def test_base_plant_linearisation_matches_the_station(station, base_plant):
    base, end_effector, predicted = _base_plant_against_station(
        station, base_plant)
    _check(base, predicted[:, 0, 0])
    _check(end_effector, predicted[:, 3, 0])


def test_a_station_in_a_closed_loop_can_still_be_analysed(scenario,
                                                          base_plant):
    """Once the station is part of another diagram (a closed loop), its
    linearisation is the same, from the same equilibrium: the analysis
    puts the station's own context at rest, which set_initial_state
    takes as it takes a root context (it failed on the context's
    owner before)."""
    station = scenario_station(scenario)
    builder = DiagramBuilder()
    builder.AddSystem(station.diagram)
    loop = builder.Build()
    root = loop.CreateDefaultContext()
    station.set_initial_state(root)
    _, alone = plant_chain.station_at_rest(station)
    np.testing.assert_array_equal(
        station.plant.GetPositions(alone),
        station.plant.GetPositions(station.plant.GetMyContextFromRoot(root)))
    again = plant_chain.linearize_base_plant(station)
    for matrix in ("A", "B", "C", "D"):
        np.testing.assert_array_equal(getattr(again, matrix)(),
                                      getattr(base_plant, matrix)())


def test_base_plant_of_a_one_urdf_robot_matches_its_station(tmp_path):
    """A robot whose base and arm are one model instance (one URDF): the
    analysis' copy of the station's plant feeds its servos in the order
    of that instance's actuators, as the station does, and its
    linearisation matches the station's response."""
    robot = load_robot_description(write_omni_arm(tmp_path, 7))
    station = SimulatedStation(StationOptions(
        initial_arm_positions=list(robot.arm.home)), robot=robot)
    assert station.model.base == station.model.arm
    base, end_effector, predicted = _base_plant_against_station(station)
    _check(base, predicted[:, 0, 0])
    _check(end_effector, predicted[:, 3, 0])


def test_base_plant_of_a_shaking_base_matches_its_station():
    """The base on its suspension (trajectory_tracking_shaking: the
    ringing loop, roll and pitch springs under the chassis at 4 Hz): the
    analysis' copy of the station's plant carries the suspension too
    (it failed on the suspension's two positions before), and its
    linearisation matches the station's response below the suspension's
    modes, and the tool's at them to 3% (2.0% measured; a copy without
    the suspension puts the tool's 12% off at 1.5 Hz and 43% at 4 Hz).
    The base's is not compared at the modes: the analysis reports T_b,
    the rocking chassis, where the station's odometry reads the wheels'
    planar joints (12% apart at 4 Hz; with the joints' velocity as the
    analysis' output they agree to 1e-4 there too)."""
    station = scenario_station(load_scenario(find_scenario(
        "trajectory_tracking_shaking")))
    assert station.model.suspension_joints
    base, end_effector, predicted = _base_plant_against_station(station)
    below = np.array(SIM_HZ) < 2.0
    _check(base[below], predicted[below, 0, 0])
    _check(end_effector[below], predicted[below, 3, 0])
    ratio = np.abs(end_effector / predicted[:, 3, 0])
    assert np.abs(ratio - 1.0).max() < 0.03


# Margins, bandwidth and peak against textbook loops.

def test_only_the_coupled_states_enter_the_response():
    """coupled_states on a chain: u drives x0 -> x1 -> y; x2 is driven
    but not seen, x3 seen but not driven, x4 neither."""
    A = np.zeros((5, 5))
    A[1, 0] = A[2, 1] = A[1, 3] = A[4, 4] = 1.0
    B = np.array([[1.0], [0.0], [0.0], [0.0], [0.0]])
    C = np.array([[0.0, 1.0, 0.0, 1.0, 0.0]])
    np.testing.assert_array_equal(coupled_states(A, B, C), [0, 1])


@pytest.mark.parametrize("time_step", [0.0, 0.01])
def test_the_response_of_the_coupled_states_is_the_whole_systems(
        time_step):
    """response_function (the coupled states only) against
    C (pI - A)^-1 B + D by a dense solve of the whole system, on random
    systems with parts that no input reaches or no output sees (with
    integrators among them, as a controller's held states are) and
    lightly damped modes near the band."""
    rng = np.random.default_rng(3)
    for n, m, p in ((1, 1, 1), (7, 2, 3), (60, 6, 6)):
        A = rng.normal(size=(n, n)) / np.sqrt(n)
        B, C = rng.normal(size=(n, m)), rng.normal(size=(p, n))
        if n > 2:
            third = n // 3
            A[:third, third:] = 0.0  # the first third: not driven ...
            B[:third] = 0.0
            A[:, third:2 * third] = 0.0  # the second: seen by none
            A[third:2 * third, third:2 * third] = 0.0  # integrators
            C[:, third:2 * third] = 0.0
        if time_step:
            A = np.eye(n) + time_step * A
        D = rng.normal(size=(p, m))
        omega = np.geomspace(0.05, 300.0, 40)
        points = (np.exp(1j * omega * time_step) if time_step
                  else 1j * omega)
        dense = np.array([C @ np.linalg.solve(z * np.eye(n) - A, B) + D
                          for z in points])
        fast = response_function(A, B, C, D, time_step)(omega)
        np.testing.assert_allclose(fast, dense, rtol=1e-9,
                                   atol=1e-12 * np.abs(dense).max())
        if n > 2:
            assert len(coupled_states(A, B, C)) <= n - 2 * (n // 3)


def test_gain_margin_of_a_third_order_loop():
    # L = K / (s (s + 1) (s + 2)): phase crossover at sqrt(2) rad/s, where
    # |L| = K / 6, so the gain margin is 6 / K.
    K = 1.5

    def loop(w):
        s = 1j * w
        return K / (s * (s + 1) * (s + 2))

    margins = stability_margins(loop, np.logspace(-2, 2, 50))
    assert margins.gain_margin == pytest.approx(6.0 / K, rel=1e-9)
    assert margins.phase_crossover == pytest.approx(np.sqrt(2.0), rel=1e-9)
    # Its phase margin from the crossover root of w^2 (w^2 + 1)(w^2 + 4) =
    # K^2, a cubic in w^2.
    roots = np.roots([1.0, 5.0, 4.0, -K * K])
    w_c = np.sqrt(roots[np.isreal(roots) & (roots.real > 0)].real[0])
    expected = 90.0 - np.degrees(np.arctan(w_c) + np.arctan(w_c / 2.0))
    assert margins.gain_crossover == pytest.approx(w_c, rel=1e-9)
    assert margins.phase_margin == pytest.approx(expected, abs=1e-7)


def test_phase_margin_of_a_second_order_loop():
    # L = K / (s (s + a)): |L| = 1 at w_c^2 = (-a^2 + sqrt(a^4 + 4 K^2)) / 2
    # and the phase margin is 90 - atan(w_c / a); no phase crossover.
    K, a = 25.0, 2.0
    margins = stability_margins(lambda w: K / (1j * w * (1j * w + a)),
                                np.logspace(-2, 3, 40))
    w_c = np.sqrt((-a**2 + np.sqrt(a**4 + 4 * K * K)) / 2)
    assert margins.phase_margin == pytest.approx(
        90.0 - np.degrees(np.arctan(w_c / a)), abs=1e-7)
    assert np.isinf(margins.gain_margin)


def test_gain_margin_of_a_discrete_integrator_loop():
    # L = g / (z - 1) crosses -180 degrees at the Nyquist frequency with
    # |L| = g / 2: the arm's force axis against a spring, g = K k_f h.
    g = 0.3
    _, omega = frequency_grid(0.01, 0.5 / H, 30)
    margins = stability_margins(
        lambda w: g / (np.exp(1j * w * H) - 1.0), omega)
    assert margins.gain_margin == pytest.approx(2.0 / g, rel=1e-9)


def test_a_discrete_loops_margins_are_read_below_its_nyquist_frequency():
    # On the analysis' default band (to 100 Hz) a loop sampled at 100 Hz
    # repeats itself mirrored above 50 Hz, L(2 pi / h - w) = conj L(w):
    # its gain crossover's alias at 95.2 Hz gave the phase margin -81.4
    # degrees of a loop whose margin is +81.4.
    g = 0.3
    _, omega = frequency_grid()
    w_c = 2.0 / H * np.arcsin(g / 2.0)  # |e^(j w h) - 1| = g
    margins = stability_margins(
        lambda w: g / (np.exp(1j * w * H) - 1.0), omega, time_step=H)
    assert margins.gain_crossover == pytest.approx(w_c, rel=1e-12)
    assert margins.phase_margin == pytest.approx(
        90.0 - np.degrees(w_c * H / 2.0), rel=1e-12)
    assert margins.phase_crossover == pytest.approx(np.pi / H, rel=1e-12)
    assert margins.gain_margin == pytest.approx(2.0 / g, rel=1e-12)
    # The same loop on every axis of an admittance loop's result (L_i =
    # -(R P C R^T)_ii of a 6 by 6 loop C (zI - A)^-1 B, here -g / (z - 1)
    # each): its margins too are read below the Nyquist frequency (they
    # were the alias's, -81.4 degrees, on this grid).
    result = admittance_loop.LoopResult(
        label="integrators", hand=None, inertia_compensation=False,
        time_constant=0.0, k_hri=0.05, loop=LinearSystem(
            np.eye(6), np.eye(6), -g * np.eye(6), np.zeros((6, 6)), H),
        rotation=np.eye(6), spectral_radius=1.0, limit=np.nan,
        limit_frequency=np.nan, open_loop_pole=0j, margins={})
    for axis in admittance_loop.AXES:
        assert result.axis_margins(axis, omega) == margins


def test_bandwidth_and_peak_of_textbook_responses():
    hertz, omega = frequency_grid(0.01, 100.0, 400)
    w_c = 5.0
    first = 1.0 / (1j * omega / w_c + 1.0)
    assert bandwidth(omega, first) == pytest.approx(
        w_c * np.sqrt(10**0.3 - 1.0), rel=1e-3)
    zeta, w_n = 0.2, 10.0
    second = lowpass_response(w_n, zeta, omega)
    peak, at = peak_gain(omega, second)
    assert peak == pytest.approx(1 / (2 * zeta * np.sqrt(1 - zeta**2)),
                                 rel=1e-3)
    assert at == pytest.approx(w_n * np.sqrt(1 - 2 * zeta**2), rel=1e-2)
    assert np.isnan(bandwidth(omega, np.ones_like(omega)))


@pytest.mark.parametrize("time_step", [0.0, H])
def test_an_integrators_row_has_no_dc_gain_nor_bandwidth(time_step):
    """Eq. (tf-admit), D_a / s (and its ZOH, D_a h / (z - 1)): its DC
    gain and its peak are infinite, and it has no -3 dB bandwidth from
    DC, whatever the grid's lowest frequency (the table once gave the
    gain at 0.01 Hz as the DC gain, -15.96 dB for D_a = 0.01, and a
    bandwidth of 0.014 Hz: sqrt(2) times the grid's start)."""
    from drake_wbc.analysis.bode import summarize

    for low in (0.01, 0.001):
        hertz, omega = frequency_grid(low, 40.0, 60)
        response = (closed_forms.tf_admit_response(0.01, omega)
                    if time_step == 0.0 else
                    closed_forms.tf_admit_zoh_response(0.01, time_step,
                                                       omega))
        row = summarize("integrator", hertz, response)
        assert row.dc_gain_db == np.inf and row.peak_db == np.inf
        assert row.peak_hz == 0.0
        assert np.isnan(row.bandwidth_hz)


def test_a_low_pass_rows_do_not_depend_on_the_grids_start():
    """The base filter, eq. (filtering), on grids from 0.01 and 0.001 Hz:
    the same DC gain (0 dB) and -3 dB bandwidth (sqrt(10^0.15 - 1) f_f
    for zeta = 1); a high-pass s / (s + 1) has a zero at DC."""
    from drake_wbc.analysis.bode import summarize

    rows = []
    for low in (0.01, 0.001):
        hertz, omega = frequency_grid(low, 40.0, 400)
        rows.append(summarize("filter", hertz,
                              lowpass_response(2 * np.pi, 1.0, omega)))
        high = summarize("high-pass", hertz,
                         1j * omega / (1j * omega + 1.0))
        assert high.dc_gain_db == -np.inf and np.isnan(high.bandwidth_hz)
    for row in rows:
        assert abs(row.dc_gain_db) < 1e-3
        assert row.bandwidth_hz == pytest.approx(
            np.sqrt(10**0.15 - 1.0), rel=1e-3)


def test_a_pole_near_the_grids_start_hides_the_dc_gain():
    """A low-pass whose corner is at the grid's lowest frequency (as the
    stiff hand's admittance loop, whose gain still rises at 0.01 Hz):
    its DC gain, bandwidth and peak lie below the band and are not
    reported (the table gave its gain at 0.01 Hz, 3 dB below its DC
    gain, as the DC gain and the peak); with the corner a decade lower it
    integrates as far as the band shows, a decade higher it is flat
    enough to read."""
    from drake_wbc.analysis.bode import summarize

    hertz, omega = frequency_grid(0.01, 40.0, 60)
    corner = 2 * np.pi * 0.01
    row = summarize("hidden", hertz, 1.0 / (1j * omega / corner + 1.0))
    assert np.isnan(row.dc_gain_db) and np.isnan(row.bandwidth_hz)
    assert np.isnan(row.peak_db) and np.isnan(row.peak_hz)
    below = summarize("below", hertz, 1.0 / (1j * omega / (0.1 * corner)
                                            + 1.0))
    assert below.dc_gain_db == np.inf and np.isnan(below.bandwidth_hz)
    above = summarize("above", hertz, 1.0 / (1j * omega / (10 * corner)
                                             + 1.0))
    assert above.dc_gain_db == pytest.approx(0.0, abs=0.05)
    assert above.bandwidth_hz == pytest.approx(0.1, rel=0.01)


def driver_period_map(period):
    """The period map of the station's base driver (its 1 ms step) at
    rest over `period`."""
    driver = BaseVelocityDriver(time_step=0.001)
    driver.set_name("driver")
    context = driver.CreateDefaultContext()
    driver.GetInputPort("base_pose").FixValue(context, np.zeros(3))
    command = driver.GetInputPort("velocity_command")
    command.FixValue(context, np.zeros(3))
    return linearize_period_map(driver, context, period, command,
                                driver.GetOutputPort("velocity"))


@pytest.mark.parametrize("call, message", [
    (lambda: frequency_grid(10.0, 1.0), "high_hz"),
    (lambda: frequency_grid(1.0, 10.0, 0.3),
     r"points_per_decade = 0.3 is not allowed: must be at least 1"),
    (lambda: linearize_dmp_force("spring"), "kind = 'spring'"),
    (lambda: stability_margins(3.0, OMEGA), "loop"),
    # A loop's margins and a reason why it has none.
    (lambda: bode.summarize(
        "loop", OMEGA / (2 * np.pi), 1.0 / (1j * OMEGA),
        StabilityMargins(2.0, 1.0, 60.0, 0.5),
        margins_unavailable="open loop unstable"),
     r"margins_unavailable = 'open loop unstable' is not allowed with "
     r"margins: must be '' where the loop has them"),
    (lambda: linearize_dmp_force("stiffness", axis=7), "axis = 7"),
    (lambda: plant_chain.linearize_base_plant(None), "station = None"),
    # A, B, C, D of inconsistent shapes (an IndexError, or with D a
    # response of the wrong size).
    (lambda: frequency_response(np.eye(2), np.ones((3, 1)), np.ones((1, 2)),
                                np.zeros((1, 1)), OMEGA),
     r"B = .* has shape \(3, 1\), which is not allowed: must have shape "
     r"\(2, any\)"),
    (lambda: frequency_response(np.eye(2), np.ones((2, 1)), np.ones((1, 3)),
                                np.zeros((1, 1)), OMEGA),
     r"C = .* has shape \(1, 3\), which is not allowed: must have shape "
     r"\(any, 2\)"),
    (lambda: frequency_response(np.eye(2), np.ones((2, 1)), np.ones((1, 2)),
                                np.zeros((2, 2)), OMEGA),
     r"D = .* has shape \(2, 2\), which is not allowed: must have shape "
     r"\(1, 1\)"),
    (lambda: frequency_response(np.ones((1, 2)), np.ones((1, 1)),
                                np.ones((1, 2)), np.zeros((1, 1)), OMEGA),
     r"A has shape \(1, 2\), which is not allowed: must be square"),
    # A response that is not one value a frequency of its grid (a
    # bandwidth of nan, or an IndexError).
    (lambda: bandwidth(OMEGA, np.ones(3)),
     r"response has shape \(3,\), which is not allowed: must have one "
     r"value for each of the \d+ frequencies of omega"),
    (lambda: peak_gain(OMEGA[:2], np.ones(3)), r"response has shape \(3,\)"),
    # A grid that is not increasing frequencies > 0 (margins read off an
    # unsorted grid, a ZeroDivisionError at -1 rad/s, inf from none).
    (lambda: stability_margins(lambda w: 2.0 / (1j * w),
                               np.array([3.0, 1.0, 2.0])),
     r"omega = .* is not allowed: must hold 2 or more increasing "
     r"frequencies > 0"),
    (lambda: stability_margins(lambda w: 2.0 / (1j * w),
                               np.array([-1.0, 3.0])), "omega = "),
    (lambda: stability_margins(lambda w: 2.0 / (1j * w), np.zeros(0)),
     "omega = "),
    # The closed forms' coefficients and the hold's matrices (a NaN
    # response; with B taller than A a wrong one, A broadcast).
    (lambda: closed_forms.second_order_zoh_response(
        1.0, float("nan"), 1.0, 1.0, 1.0, H, OMEGA),
     r"b0 = nan is not allowed: must be finite"),
    (lambda: closed_forms.second_order_zoh_response(
        "1", 1.0, 1.0, 1.0, 1.0, H, OMEGA), r"b1 = '1' is not allowed"),
    (lambda: zero_order_hold(np.eye(1), np.ones((2, 1)), H),
     r"B = .* has shape \(2, 1\), which is not allowed: must have shape "
     r"\(1, any\)"),
    # An operating point beyond the arm's limits (the input guard passed
    # the home's C_m on under q_a = 3.3 rad).
    (lambda: chains.operating_point(None, [3.3, -0.45, 1.0, 0.0, 1.15,
                                           0.0]),
     r"arm_positions\[0\] = 3.3 is not allowed: must lie within the "
     r"joint's limits \[-3.14, 3.14\] rad"),
    (lambda: base_share_gain(chains.operating_point(), 9),
     r"axis = 9 is not allowed: must be 0 to 5"),
    (lambda: compute_bode_report(load_scenario(find_scenario(
        "trajectory_tracking")), contact_stiffness=-3e3),
     r"contact_stiffness = -3000.0 is not allowed: must be greater than 0"),
    # A period map over a span that is not a whole number of the
    # updates' periods (its A, 1 update of the driver's 1 ms, was
    # labelled 0.5 ms; 2 of them 1.5 ms).
    (lambda: driver_period_map(0.0005),
     r"period = 0.0005 s is not allowed with the update period of "
     r"'driver' = 0.001 s: must be a whole multiple \(1, 2, ...\) of it"),
    (lambda: driver_period_map(0.0015), r"period = 0.0015 s"),
], ids=["grid-order", "grid-density", "dmp-kind", "loop",
        "margins-and-reason", "dmp-axis",
        "station", "B", "C", "D", "A", "bandwidth-response",
        "peak-response", "unsorted-grid", "negative-grid", "empty-grid",
        "zoh-coefficient", "zoh-coefficient-type", "hold-shapes",
        "operating-point", "share-axis", "contact-stiffness",
        "map-period-short", "map-period-between"])
def test_bad_inputs_are_named(call, message):
    """Each bad argument is refused with a ValueError naming it, its value
    (or shape) and what is allowed."""
    with pytest.raises(ValueError, match=message):
        call()

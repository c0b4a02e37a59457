"""The station's drivers against closed forms: the base's velocity loop
(first- and second-order step responses, saturation), the arm's
interpolating position servo, and the servo gains from the mass matrix."""

import numpy as np
import pytest
from pydrake.autodiffutils import (
    ExtractGradient,
    ExtractValue,
    InitializeAutoDiff,
)
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource
from shipped_names import ARM_JOINTS, BASE_JOINTS, SCOPED

from drake_wbc.robot.model import HOME_ARM_POSITIONS, make_robot_plant
from drake_wbc.station.driver_dynamics import base_loop_size, base_loop_step
from drake_wbc.station.drivers import (
    ArmDriverParameters,
    ArmPositionDriver,
    BaseDriverParameters,
    BaseVelocityDriver,
)
from drake_wbc.station.servo_gains import servo_gains
from drake_wbc.station.symbolic_drivers import (
    arm_interpolator_state,
    arm_interpolator_system,
    base_loop_state,
    base_loop_system,
    joint_rates_system,
)

H = 0.001
"""A plant step, s (the station's default)."""


def run_loop(params, h, command, steps, x0=None):
    """The loop's state after 0, 1, ..., steps periods of h s,
    (steps + 1, n)."""
    size = 3 if params.damping_ratio is None else 6
    x = np.zeros(size) if x0 is None else np.asarray(x0, dtype=float)
    states = [x]
    for _ in range(steps):
        x = base_loop_step(x, command, params, h)
        states.append(x)
    return np.array(states)


def second_order_step(u, w, zeta, t):
    """The continuous response of v'' + 2 zeta w v' + w^2 v = w^2 u from
    rest (v = v' = 0 at t = 0)."""
    if zeta < 1.0:
        wd = w * np.sqrt(1.0 - zeta**2)
        return u * (1.0 - np.exp(-zeta * w * t) * (
            np.cos(wd * t) + zeta / np.sqrt(1.0 - zeta**2) * np.sin(wd * t)))
    return u * (1.0 - np.exp(-w * t) * (1.0 + w * t))


def rotation_z(yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize("lag, h, u", [
    (0.2, 0.001, [0.15, -0.1, 0.05]),
    (0.1, 0.002, [0.05, 0.02, -0.08]),
])
def test_first_order_loop_from_rest_is_the_sampled_exponential(lag, h, u):
    params = BaseDriverParameters(lag=lag)
    u = np.array(u)
    gain = 1.0 - np.exp(-h / lag)
    # Below the limits: the first (largest) step stays under a_max h, so
    # the acceleration limit never acts.
    assert np.all(gain * np.abs(u) < np.array(params.acceleration_limits) * h)
    steps = 600
    v = run_loop(params, h, u, steps)
    n = np.arange(steps + 1)[:, None]
    expected = u * (1.0 - np.exp(-n * h / lag))
    np.testing.assert_allclose(v, expected, rtol=0.0, atol=1e-13)


def test_large_command_saturates_at_the_velocity_and_acceleration_limits():
    limits = np.array([1.0, 0.5, 0.8])
    a_max = np.array([1.0, 2.0, 0.5])
    params = BaseDriverParameters(velocity_limits=list(limits),
                                  acceleration_limits=list(a_max))
    h, lag = H, params.lag
    command = np.array([5.0, -3.0, 2.0])
    steps = 6000
    v = run_loop(params, h, command, steps)
    assert np.all(np.abs(v) <= limits + 1e-15)
    change = np.abs(np.diff(v, axis=0))
    assert np.all(change <= a_max * h * (1.0 + 1e-12))
    # Closed form, per axis: a ramp at the acceleration limit while the
    # lag's step g (L - v) would exceed a_max h, then the exponential
    # approach to the saturated command L = sign(u) limit.
    gain = 1.0 - np.exp(-h / lag)
    n = np.arange(steps + 1)
    for i in range(3):
        L, ramp = np.sign(command[i]) * limits[i], a_max[i] * h
        n_switch = int(np.ceil((limits[i] - ramp / gain) / ramp))
        expected = np.where(
            n <= n_switch, np.sign(command[i]) * n * ramp,
            L - (L - np.sign(command[i]) * n_switch * ramp)
            * (1.0 - gain) ** np.maximum(n - n_switch, 0))
        np.testing.assert_allclose(v[:, i], expected, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(v[-1], np.sign(command) * limits, atol=1e-9)


@pytest.mark.parametrize("zeta", [0.3, 0.7, 1.0])
def test_second_order_loop_approaches_the_continuous_step_response(zeta):
    # A small step keeps both limits inactive. Semi-implicit Euler is a
    # first-order method: the discrete response trails the continuous one
    # by about half a step and drifts in phase by O(w h), so over a few
    # periods its error stays below u w h (0.3 to 0.45 u w h for these
    # ratios) and halves when h halves.
    lag, u, duration = 0.2, np.array([0.05, -0.03, 0.04]), 3.0
    w = 1.0 / lag
    errors = []
    for h in (0.001, 0.0005):
        params = BaseDriverParameters(lag=lag, damping_ratio=zeta)
        x = run_loop(params, h, u, int(round(duration / h)))
        assert np.all(np.abs(x[:, 3:]) < params.acceleration_limits)
        t = np.arange(x.shape[0])[:, None] * h
        expected = second_order_step(u, w, zeta, t)
        error = np.max(np.abs(x[:, :3] - expected), axis=0)
        np.testing.assert_array_less(error, np.abs(u) * w * h)
        errors.append(error)
        peak = np.max(x[:, :3] / u, axis=0)
        if zeta < 1.0:
            overshoot = np.exp(-zeta * np.pi / np.sqrt(1.0 - zeta**2))
            np.testing.assert_allclose(peak, 1.0 + overshoot, atol=w * h)
            assert np.all(peak > 1.0 + 0.5 * overshoot)
        else:
            np.testing.assert_array_less(peak, 1.0 + w * h)
    np.testing.assert_allclose(errors[0] / errors[1], 2.0, rtol=0.1)


@pytest.mark.parametrize("h", [0.002, 0.001])
def test_jerky_loop_is_the_short_lags_sampled_exponential(h):
    params = BaseDriverParameters(loop="jerky")
    assert params.lag == 0.02 and params.damping_ratio is None
    np.testing.assert_array_equal(params.acceleration_limits, [5.0] * 3)
    u = np.array([0.05, -0.03, 0.04])
    gain = 1.0 - np.exp(-h / params.lag)
    # Its first (largest) step stays under a_max h: no acceleration limit.
    assert np.all(gain * np.abs(u) < np.array(params.acceleration_limits) * h)
    steps = int(round(0.2 / h))
    v = run_loop(params, h, u, steps)
    n = np.arange(steps + 1)[:, None]
    np.testing.assert_allclose(v, u * (1.0 - np.exp(-n * h / params.lag)),
                               rtol=0.0, atol=1e-13)
    # Ten times faster than the smooth loop: 95 % of the step in 3 lags.
    assert np.all(np.abs(v[int(round(0.06 / h))] - 0.95 * u)
                  < 0.01 * np.abs(u))


def test_ringing_loop_is_the_underdamped_second_order_step():
    h = 0.0005
    params = BaseDriverParameters(loop="ringing")
    w, zeta = 1.0 / params.lag, params.damping_ratio
    assert w / (2 * np.pi) == pytest.approx(3.0) and zeta == 0.15
    u, duration = np.array([0.05, -0.03, 0.04]), 2.0
    x = run_loop(params, h, u, int(round(duration / h)))
    assert np.all(np.abs(x[:, 3:]) < params.acceleration_limits)
    t = np.arange(x.shape[0])[:, None] * h
    error = np.max(np.abs(x[:, :3] - second_order_step(u, w, zeta, t)),
                   axis=0)
    np.testing.assert_array_less(error, np.abs(u) * w * h)
    # Its overshoot (62 %) and its ringing period, 1 / (3 Hz sqrt(1 -
    # zeta^2)), from the upward crossings of the command.
    overshoot = np.exp(-zeta * np.pi / np.sqrt(1.0 - zeta**2))
    np.testing.assert_allclose(np.max(x[:, :3] / u, axis=0), 1.0 + overshoot,
                               atol=w * h)
    above = x[:, 0] > u[0]
    ups = np.flatnonzero(above[1:] & ~above[:-1]) * h
    np.testing.assert_allclose(np.diff(ups), 2 * np.pi / (
        w * np.sqrt(1.0 - zeta**2)), rtol=0.01)


def test_a_named_loop_sets_its_values_and_refuses_others():
    smooth = BaseDriverParameters(loop="smooth")
    assert smooth == BaseDriverParameters(loop="smooth", lag=0.2)
    assert (smooth.lag, smooth.damping_ratio) == (0.2, None)
    # A field at its default takes the loop's value, even when written.
    assert BaseDriverParameters(loop="ringing", lag=0.2).lag == (
        pytest.approx(1.0 / (6.0 * np.pi)))
    for fields, name in ((dict(lag=0.1), "lag"),
                         (dict(damping_ratio=0.3), "damping_ratio"),
                         (dict(acceleration_limits=[2.0] * 3),
                          "acceleration_limits")):
        with pytest.raises(ValueError, match=f"^{name} = .*loop = 'ringing'"):
            BaseDriverParameters(loop="ringing", **fields)
    with pytest.raises(ValueError, match="^damping_ratio = 0.3 .*'jerky'"):
        BaseDriverParameters(loop="jerky", damping_ratio=0.3)


def test_a_named_loop_loads_from_a_scenario_file():
    # The loader fills a default instance field by field: the loop's
    # values, not the smooth defaults it met first, must come out.
    from drake_wbc.experiments.scenario import load_scenario

    scenario = load_scenario(text="station: {base: {loop: ringing}}")
    base = scenario.station.base
    assert base.lag == pytest.approx(1.0 / (6.0 * np.pi))
    assert base.damping_ratio == 0.15
    np.testing.assert_array_equal(base.acceleration_limits, [5.0] * 3)


def autodiff_context(system, state, command, pose):
    """A context of the AutoDiffXd `system` whose derivatives are taken
    with respect to [state, command, pose]."""
    sizes = [len(state), len(command), len(pose)]
    total = sum(sizes)
    context = system.CreateDefaultContext()
    starts = np.cumsum([0] + sizes[:-1])
    values = [InitializeAutoDiff(np.asarray(v, dtype=float),
                                 num_derivatives=total,
                                 deriv_num_start=int(s))[:, 0]
              for v, s in zip((state, command, pose), starts, strict=True)]
    context.SetDiscreteState(values[0])
    system.GetInputPort("velocity_command").FixValue(context, values[1])
    system.GetInputPort("base_pose").FixValue(context, values[2])
    return context


def test_first_order_update_in_autodiff_has_the_lags_derivatives():
    params = BaseDriverParameters()
    system = BaseVelocityDriver(params, H).ToAutoDiffXd()
    v, u, pose = [0.05, -0.02, 0.01], [0.1, 0.1, 0.0], [0.3, -1.0, 0.5]
    context = autodiff_context(system, v, u, pose)
    update = system.EvalUniquePeriodicDiscreteUpdate(context)
    result = update.get_vector().CopyToVector()
    np.testing.assert_allclose(ExtractValue(result).ravel(),
                               base_loop_step(np.array(v), u, params, H),
                               atol=1e-15)
    g = 1.0 - np.exp(-H / params.lag)
    expected = np.hstack([(1.0 - g) * np.eye(3), g * np.eye(3),
                          np.zeros((3, 3))])
    np.testing.assert_allclose(ExtractGradient(result), expected,
                               atol=1e-15)
    # desired_state: rates R(yaw) v, whose yaw derivative is R'(yaw) v.
    desired = system.GetOutputPort("desired_state").Eval(context)
    yaw = pose[2]
    c, s = np.cos(yaw), np.sin(yaw)
    gradient = ExtractGradient(desired)
    np.testing.assert_array_equal(gradient[:3], 0.0)
    np.testing.assert_allclose(gradient[3:, :3], rotation_z(yaw),
                               atol=1e-15)
    np.testing.assert_allclose(
        gradient[3:, 8], [-s * v[0] - c * v[1], c * v[0] - s * v[1], 0.0],
        atol=1e-15)


def test_second_order_update_in_autodiff_has_the_euler_steps_derivatives():
    params = BaseDriverParameters(damping_ratio=0.4)
    h, w, zeta = H, 1.0 / params.lag, 0.4
    system = BaseVelocityDriver(params, h).ToAutoDiffXd()
    x = [0.05, -0.02, 0.01, 0.1, 0.0, -0.2]
    context = autodiff_context(system, x, [0.3, 0.1, -0.2], [0.0, 0.0, 0.0])
    result = system.EvalUniquePeriodicDiscreteUpdate(context).get_vector(
    ).CopyToVector()
    # a+ = a + h (w^2 (u - v) - 2 zeta w a), v+ = v + h a+.
    da_dv, da_da, da_du = -h * w**2, 1.0 - 2.0 * zeta * w * h, h * w**2
    eye = np.eye(3)
    expected = np.block([
        [(1.0 + h * da_dv) * eye, h * da_da * eye, h * da_du * eye,
         np.zeros((3, 3))],
        [da_dv * eye, da_da * eye, da_du * eye, np.zeros((3, 3))]])
    np.testing.assert_allclose(ExtractGradient(result), expected,
                               atol=1e-15)
    np.testing.assert_allclose(
        ExtractValue(result).ravel(),
        base_loop_step(np.array(x), [0.3, 0.1, -0.2], params, h),
        atol=1e-15)


def base_driver_simulator(params, command, pose):
    builder = DiagramBuilder()
    driver = builder.AddSystem(BaseVelocityDriver(params, H))
    for name, value in (("velocity_command", command), ("base_pose", pose)):
        source = builder.AddSystem(ConstantVectorSource(value))
        builder.Connect(source.get_output_port(), driver.GetInputPort(name))
    simulator = Simulator(builder.Build())
    context = driver.GetMyMutableContextFromRoot(
        simulator.get_mutable_context())
    return driver, simulator, context


@pytest.mark.parametrize("yaw", [0.0, 0.5, -2.0])
def test_base_driver_rotates_the_loops_velocity_into_joint_rates(yaw):
    params = BaseDriverParameters()
    h, lag = H, params.lag
    u = np.array([0.12, -0.08, 0.15])
    driver, simulator, context = base_driver_simulator(
        params, u, [0.4, -1.0, yaw])
    for n in (1, 10, 250):
        # Updates at 0, h, ..., n h have run by (n + 1/2) h.
        simulator.AdvanceTo((n + 0.5) * h)
        expected = u * (1.0 - np.exp(-(n + 1) * h / lag))
        velocity = driver.GetOutputPort("velocity").Eval(context)
        np.testing.assert_allclose(velocity, expected, atol=1e-14)
        np.testing.assert_array_equal(
            velocity, context.get_discrete_state_vector().CopyToVector())
        desired = driver.GetOutputPort("desired_state").Eval(context)
        np.testing.assert_array_equal(desired[:3], 0.0)
        np.testing.assert_allclose(desired[3:], rotation_z(yaw) @ velocity,
                                   atol=1e-15)


def test_the_base_drivers_run_at_the_step_they_are_given():
    """The loop's step is an argument of the drivers, not a field of its
    parameters (whose default of 1 ms refused a 5 ms loop even at a
    0.2 ms step); it is checked against the loop's lag."""
    params = BaseDriverParameters(lag=0.005, servo_time_constant=0.001)
    for make in (BaseVelocityDriver, base_loop_system):
        assert make(params, 0.0002).GetUniquePeriodicDiscreteUpdateAttribute(
            ).period_sec() == 0.0002
        with pytest.raises(ValueError, match=r"^time_step = 0\.001 s is not "
                           r"allowed with lag = 0\.005 s: must be at most "
                           r"lag / 10"):
            make(params, 0.001)
        with pytest.raises(ValueError, match="^time_step = None is not "
                           "allowed"):
            make(params)


def test_set_velocity_starts_the_loop_in_steady_motion():
    params = BaseDriverParameters(damping_ratio=0.5)
    v0 = np.array([0.3, -0.2, 0.4])
    driver, simulator, context = base_driver_simulator(params, v0,
                                                       [0.0, 0.0, 0.0])
    driver.set_velocity(context, v0)
    np.testing.assert_array_equal(
        context.get_discrete_state_vector().CopyToVector(),
        np.concatenate([v0, np.zeros(3)]))
    simulator.AdvanceTo(0.2)
    np.testing.assert_allclose(driver.GetOutputPort("velocity").Eval(context),
                               v0, atol=1e-15)


def test_arm_driver_interpolates_from_the_previous_command_to_the_new_one():
    params = ArmDriverParameters(command_period=0.01)
    q0 = np.array(HOME_ARM_POSITIONS)
    q1 = q0 + [0.1, -0.05, 0.2, 0.0, 0.3, -0.1]
    q2 = q1 + [-0.02, 0.04, 0.0, 0.1, 0.0, 0.05]
    driver = ArmPositionDriver(params, q0)
    simulator = Simulator(driver)
    context = simulator.get_mutable_context()
    port = driver.get_input_port()
    desired = driver.GetOutputPort("desired_state")

    def expect(q, v):
        np.testing.assert_allclose(desired.Eval(context),
                                   np.concatenate([q, v]), atol=1e-9)

    port.FixValue(context, q0)
    simulator.AdvanceTo(0.045)
    expect(q0, np.zeros(6))
    # A command that arrives between samples waits for the next one.
    port.FixValue(context, q1)
    simulator.AdvanceTo(0.0475)
    expect(q0, np.zeros(6))
    # Sampled at t_k = 0.05, reached at t_k + period at a constant rate.
    rate = (q1 - q0) / params.command_period
    for fraction in (0.1, 0.25, 0.5, 0.9, 0.99):
        simulator.AdvanceTo(0.05 + fraction * params.command_period)
        expect(q0 + fraction * (q1 - q0), rate)
    simulator.AdvanceTo(0.065)
    expect(q1, np.zeros(6))
    port.FixValue(context, q2)
    simulator.AdvanceTo(0.074)
    expect(q1 + 0.4 * (q2 - q1), (q2 - q1) / params.command_period)
    simulator.AdvanceTo(0.1)
    expect(q2, np.zeros(6))


def test_arm_driver_set_positions_holds_the_arm_there():
    driver = ArmPositionDriver(initial_positions=HOME_ARM_POSITIONS)
    simulator = Simulator(driver)
    context = simulator.get_mutable_context()
    driver.get_input_port().FixValue(context, HOME_ARM_POSITIONS)
    simulator.AdvanceTo(0.033)
    q = np.array([0.2, -0.6, 1.2, 0.1, 0.9, -0.3])
    driver.set_positions(context, q)
    desired = driver.GetOutputPort("desired_state")
    np.testing.assert_array_equal(desired.Eval(context),
                                  np.concatenate([q, np.zeros(6)]))
    driver.get_input_port().FixValue(context, q)
    for t in (0.035, 0.04, 0.077, 0.1):
        simulator.AdvanceTo(t)
        np.testing.assert_allclose(desired.Eval(context),
                                   np.concatenate([q, np.zeros(6)]),
                                   atol=1e-15)


def test_the_arm_drivers_ask_for_the_arms_start():
    """A start is a configuration of one arm: the drivers held the shipped
    Elfin5's home when given none, so another six-joint arm's driver
    started by pulling it there (and a seven-joint arm's had six
    inputs); now they ask for it by name."""
    message = r"initial_positions = None is not allowed: give the arm's start"
    for make in (lambda: ArmPositionDriver(),
                 lambda: ArmPositionDriver(ArmDriverParameters()),
                 lambda: arm_interpolator_system(),
                 lambda: arm_interpolator_state(np.zeros(6), 0.0)):
        with pytest.raises(ValueError, match=message):
            make()
    q0 = np.full(7, 0.3)
    driver = ArmPositionDriver(initial_positions=q0)
    assert driver.get_input_port().size() == 7
    np.testing.assert_array_equal(
        driver.GetOutputPort("desired_state").Eval(
            driver.CreateDefaultContext()), np.concatenate([q0, np.zeros(7)]))


def test_arm_driver_in_autodiff_gives_the_same_desired_state():
    q0 = np.array(HOME_ARM_POSITIONS)
    q1 = q0 + 0.01 * np.arange(1, 7)
    values = []
    double = ArmPositionDriver(initial_positions=q0)
    for driver in (double, double.ToAutoDiffXd()):
        context = driver.CreateDefaultContext()
        driver.get_input_port().FixValue(context, q1)
        state = driver.EvalUniquePeriodicDiscreteUpdate(context)
        context.SetDiscreteState(state.get_vector().CopyToVector())
        context.SetTime(0.004)
        values.append(ExtractValue(
            driver.GetOutputPort("desired_state").Eval(context)).ravel())
    np.testing.assert_allclose(values[1], values[0], atol=1e-15)
    np.testing.assert_allclose(
        values[0], np.concatenate([q0 + 0.4 * (q1 - q0), (q1 - q0) / 0.01]),
        atol=1e-12)


@pytest.mark.parametrize("q_a", [
    HOME_ARM_POSITIONS, [0.3, -0.8, 1.4, 0.5, -0.7, 0.2]])
@pytest.mark.parametrize("arm", [
    ArmDriverParameters(),
    ArmDriverParameters(servo_frequency=10.0, damping_ratio=0.7,
                        min_inertia=0.5),
])
def test_servo_gains_from_the_mass_matrix(q_a, arm):
    base = BaseDriverParameters(servo_time_constant=0.02)
    plant, model = make_robot_plant()
    context = plant.CreateDefaultContext()
    for name, angle in zip(ARM_JOINTS, q_a, strict=True):
        plant.GetJointByName(name, model.arm).set_angle(context, angle)
    M = plant.CalcMassMatrix(context)
    gains = servo_gains(q_a, base, arm)
    assert set(gains) == {SCOPED[n] for n in BASE_JOINTS + ARM_JOINTS}
    for name in BASE_JOINTS:
        i = plant.GetJointByName(name, model.base).velocity_start()
        assert gains[SCOPED[name]].p == 0.0
        assert gains[SCOPED[name]].d == pytest.approx(M[i, i] / 0.02,
                                                      rel=1e-12)
    w = 2.0 * np.pi * arm.servo_frequency
    floored = []
    for name in ARM_JOINTS:
        i = plant.GetJointByName(name, model.arm).velocity_start()
        inertia = max(M[i, i], arm.min_inertia)
        floored.append(M[i, i] < arm.min_inertia)
        assert gains[SCOPED[name]].p == pytest.approx(inertia * w**2,
                                                      rel=1e-12)
        assert gains[SCOPED[name]].d == pytest.approx(
            2.0 * arm.damping_ratio * inertia * w, rel=1e-12)
    # Both branches of max(M_ii, min_inertia) are exercised.
    assert any(floored) and not all(floored)


@pytest.mark.parametrize("kind, fields, name", [
    ("base", dict(lag=0.0), "lag"),
    ("base", dict(lag=-0.2), "lag"),
    ("base", dict(lag=0.02), "servo_time_constant"),
    ("base", dict(servo_time_constant=0.1), "servo_time_constant"),
    ("base", dict(servo_time_constant=0.0), "servo_time_constant"),
    ("base", dict(damping_ratio=0.0), "damping_ratio"),
    ("base", dict(damping_ratio=-0.5), "damping_ratio"),
    ("base", dict(damping_ratio=1.5), "damping_ratio"),
    ("base", dict(velocity_limits=[1.0, 1.0]), "velocity_limits"),
    ("base", dict(velocity_limits=[1.0, 0.0, 1.0]), "velocity_limits"),
    ("base", dict(acceleration_limits=[1.0, 1.0, 1.0, 1.0]),
     "acceleration_limits"),
    ("base", dict(acceleration_limits=[1.0, -1.0, 1.0]),
     "acceleration_limits"),
    ("arm", dict(min_inertia=-0.1), "min_inertia"),
    ("arm", dict(command_period=0.0), "command_period"),
    ("arm", dict(servo_frequency=-25.0), "servo_frequency"),
])
def test_parameter_errors_name_the_field(kind, fields, name):
    cls = BaseDriverParameters if kind == "base" else ArmDriverParameters
    with pytest.raises(ValueError, match=rf"^{name}\b"):
        cls(**fields)


def test_values_at_the_edges_of_the_allowed_ranges_are_accepted():
    assert BaseDriverParameters(damping_ratio=1.0).damping_ratio == 1.0
    assert BaseDriverParameters(
        lag=0.2, servo_time_constant=0.0999).servo_time_constant == 0.0999
    assert ArmDriverParameters(min_inertia=0.0).min_inertia == 0.0


def test_second_order_overshoot_stops_at_the_velocity_limit():
    from drake_wbc.station.driver_dynamics import base_loop_step
    from drake_wbc.station.drivers import BaseDriverParameters

    params = BaseDriverParameters(damping_ratio=0.2, lag=0.1,
                                  acceleration_limits=[50.0, 50.0, 50.0])
    x = np.zeros(6)
    peak = 0.0
    for _ in range(2000):
        x = base_loop_step(x, np.array([0.99, 0.0, 0.0]), params, H)
        peak = max(peak, x[0])
    assert peak <= params.velocity_limits[0]
    assert peak == pytest.approx(params.velocity_limits[0])


# The drivers as the station runs them: SymbolicVectorSystems built from
# the same functions, checked against the reference LeafSystems above.

@pytest.mark.parametrize("params, h", [
    (BaseDriverParameters(), 0.005),
    (BaseDriverParameters(damping_ratio=0.3, lag=0.1,
                          acceleration_limits=[2.0, 0.5, 1.0]), 0.002)])
def test_symbolic_base_loop_steps_like_base_loop_step(params, h):
    system = base_loop_system(params, h)
    assert system.GetUniquePeriodicDiscreteUpdateAttribute().period_sec() \
        == h
    context = system.CreateDefaultContext()
    rng = np.random.default_rng(7)
    for _ in range(200):  # within and beyond every limit
        x = rng.uniform(-1.3, 1.3, base_loop_size(params))
        u = rng.uniform(-2.0, 2.0, 3)
        context.SetDiscreteState(x)
        system.get_input_port().FixValue(context, u)
        np.testing.assert_allclose(
            system.EvalUniquePeriodicDiscreteUpdate(context).get_vector()
            .CopyToVector(), base_loop_step(x, u, params, h), atol=1e-15)
        np.testing.assert_array_equal(
            system.get_output_port().Eval(context), x[:3])
    context.SetDiscreteState(base_loop_state(params, [0.2, 0.0, -0.1]))
    np.testing.assert_array_equal(system.get_output_port().Eval(context),
                                  [0.2, 0.0, -0.1])


def test_symbolic_base_loop_in_autodiff_has_the_lags_derivatives():
    params = BaseDriverParameters()
    system = base_loop_system(params, H).ToAutoDiffXd()
    context = system.CreateDefaultContext()
    context.SetDiscreteState(InitializeAutoDiff(
        np.array([0.1, -0.05, 0.02]), 6, 0).ravel())
    system.get_input_port().FixValue(context, InitializeAutoDiff(
        np.array([0.1005, -0.05, 0.021]), 6, 3).ravel())
    result = system.EvalUniquePeriodicDiscreteUpdate(context).get_vector(
    ).CopyToVector()
    g = 1.0 - np.exp(-H / params.lag)
    np.testing.assert_allclose(ExtractGradient(result), np.hstack(
        [(1.0 - g) * np.eye(3), g * np.eye(3)]), atol=1e-15)


@pytest.mark.parametrize("yaw", [0.0, 0.5, -2.0])
def test_symbolic_joint_rates_are_body_to_world_rates(yaw):
    system = joint_rates_system()
    context = system.CreateDefaultContext()
    v = np.array([0.3, -0.2, 0.1])
    system.get_input_port().FixValue(context, [*v, 1.0, 2.0, yaw])
    np.testing.assert_allclose(
        system.get_output_port().Eval(context),
        [0.0, 0.0, 0.0, *(rotation_z(yaw) @ v)], atol=1e-15)


@pytest.mark.parametrize("n", [6, 7])
def test_symbolic_arm_interpolator_follows_the_arm_driver(n):
    """Both fed the same commands, changing between samples: the same
    desired state at every plant step and in between (a 6- and a 7-joint
    arm)."""
    params = ArmDriverParameters()
    q0 = np.resize(np.array(HOME_ARM_POSITIONS), n)
    reference, symbolic = ArmPositionDriver(params, q0), \
        arm_interpolator_system(params, q0)
    simulators = [Simulator(s) for s in (reference, symbolic)]
    contexts = [s.get_mutable_context() for s in simulators]
    # The default state holds the initial positions, as the reference's.
    np.testing.assert_array_equal(
        symbolic.get_output_port().Eval(contexts[1]),
        np.concatenate([q0, np.zeros(n)]))
    rng = np.random.default_rng(3)
    for t in np.arange(1, 80) * 0.0025:
        if rng.uniform() < 0.3:
            q = q0 + rng.uniform(-0.2, 0.2, n)
            for system, context in zip((reference, symbolic), contexts,
                                       strict=True):
                system.get_input_port().FixValue(context, q)
        for simulator in simulators:
            simulator.AdvanceTo(t)
        np.testing.assert_allclose(
            symbolic.get_output_port().Eval(contexts[1]),
            reference.GetOutputPort("desired_state").Eval(contexts[0]),
            atol=1e-12)


def test_symbolic_arm_interpolator_set_positions_holds_the_arm_there():
    q0 = np.array(HOME_ARM_POSITIONS) + 0.1
    system = arm_interpolator_system(ArmDriverParameters(), q0)
    simulator = Simulator(system)
    context = simulator.get_mutable_context()
    q = np.array([0.2, -0.6, 1.2, 0.1, 0.9, -0.3])
    system.get_input_port().FixValue(context, q)
    simulator.AdvanceTo(0.033)
    context.SetDiscreteState(arm_interpolator_state(q, 0.033, q0))
    for t in (0.033, 0.035, 0.04, 0.077):
        simulator.AdvanceTo(t)
        np.testing.assert_allclose(system.get_output_port().Eval(context),
                                   np.concatenate([q, np.zeros(6)]),
                                   atol=1e-15)

"""The simulated wrist F/T sensor: its reading model against closed forms,
its sampling in a simulation, and the true wrench from the sensing weld of
the robot model."""

import numpy as np
import pytest
from locked_robot import sensor_reading, settle_locked_robot
from omni_arm import write_omni_arm
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from drake_wbc.math.validation import validate
from drake_wbc.robot.description import load_robot_description
from drake_wbc.robot.model import (
    HOME_ARM_POSITIONS,
    ArmKinematics,
    add_robot,
    make_robot_plant,
)
from drake_wbc.stages.wrench import tool_weight_reading
from drake_wbc.station.force_torque import (
    ForceTorqueSensorParameters,
    WeldWrench,
    WristForceTorqueSensor,
    measure,
)
from drake_wbc.station.simulation import SimulatedStation, StationOptions

NOISELESS = dict(force_noise_std=0.0, torque_noise_std=0.0)


def test_readings_are_rounded_to_the_resolution():
    params = ForceTorqueSensorParameters(**NOISELESS)
    wrench = [1.234567, -2.345678, 0.004999, 0.0123456, -0.0004, 3.14159]
    np.testing.assert_allclose(measure(wrench, params, 0),
                               [1.23, -2.35, 0.0, 0.012, 0.0, 3.142],
                               atol=1e-12)
    rng = np.random.default_rng(1)
    resolution = np.repeat([0.01, 0.001], 3)
    for tick in range(20):
        wrench = rng.uniform(-25.0, 25.0, 6)
        reading = measure(wrench, params, tick)
        steps = reading / resolution
        np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)
        assert np.all(np.abs(reading - wrench) <= resolution / 2 + 1e-12)


def test_readings_saturate_at_the_range():
    wrench = [450.0, -301.0, 299.5, 31.0, -100.0, 29.9]
    expected = [300.0, -300.0, 299.5, 30.0, -30.0, 29.9]
    ideal = ForceTorqueSensorParameters.ideal()
    np.testing.assert_array_equal(measure(wrench, ideal, 0), expected)
    quantised = ForceTorqueSensorParameters(**NOISELESS)
    np.testing.assert_allclose(measure(wrench, quantised, 0), expected,
                               atol=1e-12)
    small = ForceTorqueSensorParameters.ideal(force_range=10.0,
                                              torque_range=1.0)
    np.testing.assert_array_equal(measure(wrench, small, 0),
                                  [10, -10, 10, 1, -1, 1])


def test_the_range_is_the_robots_own_sensors(tmp_path):
    """The simulated sensor saturates where the robot's description says
    its sensor does (tool.ft_sensor_range, which the controller's input
    guard reads too), not at the FT-300's range: a 200 N / 20 N m sensor
    read 250 N, which its controller refuses as beyond the range, and
    the simulation then stopped where the robot would not. A range the
    parameters give still wins, and a resolution not below the range it
    meets is refused."""
    path = write_omni_arm(tmp_path, 6)
    path.write_text(path.read_text().replace(
        "[300.0, 300.0, 300.0, 30.0, 30.0, 30.0]",
        "[200.0, 200.0, 250.0, 20.0, 20.0, 25.0]"))
    robot = load_robot_description(path)
    station = SimulatedStation(StationOptions(
        wrist=ForceTorqueSensorParameters.ideal()), robot=robot)
    np.testing.assert_array_equal(station.systems["wrist"].limits,
                                  robot.tool.ft_sensor_range)
    wrench = [450.0, -201.0, 240.0, 31.0, -100.0, 24.0]
    np.testing.assert_array_equal(
        measure(wrench, ForceTorqueSensorParameters.ideal(), 0,
                robot.tool.ft_sensor_range),
        [200.0, -200.0, 240.0, 20.0, -20.0, 24.0])
    np.testing.assert_array_equal(
        measure(wrench, ForceTorqueSensorParameters.ideal(force_range=100.0),
                0, robot.tool.ft_sensor_range),
        [100.0, -100.0, 100.0, 20.0, -20.0, 24.0])
    with pytest.raises(ValueError, match=(
            r"torque_resolution = 20.0 is not allowed with the sensor's "
            r"torque range 20.0: must be below it")):
        WristForceTorqueSensor(ForceTorqueSensorParameters(
            torque_resolution=20.0), robot.tool.ft_sensor_range)
    with pytest.raises(ValueError, match=r"sensor_range\[4\] = -20.0"):
        WristForceTorqueSensor(None, [200.0, 200.0, 250.0, 20.0, -20.0, 25.0])


def test_ideal_sensor_passes_the_wrench_through_exactly():
    ideal = ForceTorqueSensorParameters.ideal()
    assert ideal.force_resolution == 0.0 and ideal.torque_noise_std == 0.0
    rng = np.random.default_rng(2)
    for tick in range(10):
        wrench = np.concatenate([rng.uniform(-299, 299, 3),
                                 rng.uniform(-29, 29, 3)])
        np.testing.assert_array_equal(measure(wrench, ideal, tick), wrench)


def test_noise_has_the_set_rms():
    """4000 readings of a constant wrench with the FT-300's defaults.

    Per quantity (force or torque) that is n = 12000 errors. Quantisation
    adds q^2 / 12 to the variance (0.04% of sigma^2 for forces, 0.3% for
    torques), so the RMS should be sqrt(sigma^2 + q^2 / 12). The sample
    RMS of n Gaussian errors has a relative standard deviation of
    1 / sqrt(2 n) = 0.65%; 3.5% is over five of them. The mean of the
    errors has a standard deviation of sigma / sqrt(n); 5 of them bound it.
    """
    params = ForceTorqueSensorParameters(seed=11)
    wrench = np.array([5.0, -3.0, 20.0, 0.1, 0.2, -0.3])
    errors = np.array([measure(wrench, params, k) - wrench
                       for k in range(4000)])
    for part, sigma, q in ((slice(0, 3), 0.1, 0.01),
                           (slice(3, 6), 0.005, 0.001)):
        e = errors[:, part].ravel()
        expected = np.sqrt(sigma**2 + q**2 / 12.0)
        assert np.sqrt(np.mean(e**2)) == pytest.approx(expected, rel=0.035)
        assert abs(np.mean(e)) < 5.0 * sigma / np.sqrt(e.size)
    # The six components are independent draws: each sample correlation
    # has a standard deviation of 1 / sqrt(4000) = 0.016; 0.08 is five.
    correlation = np.corrcoef(errors.T)
    assert np.max(np.abs(correlation - np.eye(6))) < 0.08


def test_noise_is_a_function_of_seed_and_tick_only():
    params = ForceTorqueSensorParameters(seed=4)
    wrench = np.array([1.0, 2.0, 3.0, 0.1, 0.2, 0.3])
    first = measure(wrench, params, 7)
    for tick in (0, 100, 6):
        measure(wrench, params, tick)
    np.testing.assert_array_equal(measure(wrench, params, 7), first)
    assert not np.array_equal(measure(wrench, params, 8), first)
    other = ForceTorqueSensorParameters(seed=5)
    assert not np.array_equal(measure(wrench, other, 7), first)


def test_readings_are_sampled_at_100_hz_and_held():
    params = ForceTorqueSensorParameters(force_resolution=0.0,
                                         torque_resolution=0.0, seed=2)
    times = [0.0, 0.2]
    path = PiecewisePolynomial.FirstOrderHold(
        times, np.array([[0.0, 10.0], [1.0, -5.0], [2.0, 2.0],
                         [0.0, 1.0], [0.1, 0.0], [-0.2, 0.3]]))
    builder = DiagramBuilder()
    source = builder.AddSystem(TrajectorySource(path))
    sensor = builder.AddSystem(WristForceTorqueSensor(params))
    builder.Connect(source.get_output_port(), sensor.GetInputPort("wrench"))
    simulator = Simulator(builder.Build())
    context = sensor.GetMyContextFromRoot(simulator.get_context())
    output = sensor.GetOutputPort("wrench_measured")
    np.testing.assert_array_equal(output.Eval(context), np.zeros(6))

    def expected(k):
        return measure(path.value(k / params.rate).ravel(), params, k)

    simulator.Initialize()
    np.testing.assert_allclose(output.Eval(context), expected(0),
                               atol=1e-12)
    # Odd multiples of 1/400 s never fall on a multiple of 1/100 s.
    previous, changes = None, 0
    for j in range(40):
        t = (2 * j + 1) / 400.0
        simulator.AdvanceTo(t)
        reading = output.Eval(context)
        np.testing.assert_allclose(reading, expected(int(t * params.rate)),
                                   atol=1e-12)
        if previous is not None and not np.array_equal(reading, previous):
            changes += 1
        previous = reading
    assert changes == 19
    assert not sensor.HasAnyDirectFeedthrough()


def test_initialize_reading_keeps_the_tick():
    sensor = WristForceTorqueSensor()
    context = sensor.CreateDefaultContext()
    wrench = np.array([1.0, -2.0, 3.0, 0.1, -0.2, 0.3])
    sensor.GetInputPort("wrench").FixValue(context, wrench)
    for _ in range(2):
        sensor.initialize_reading(context)
        np.testing.assert_array_equal(
            sensor.GetOutputPort("wrench_measured").Eval(context),
            measure(wrench, ForceTorqueSensorParameters(), 0))


@pytest.fixture(scope="module")
def settled():
    """The locked robot at home, without and with a push on the tool."""
    push_W = SpatialForce(tau=[0.3, -0.2, 0.1], f=[4.0, -6.0, 9.0])
    return {
        "rest": settle_locked_robot(HOME_ARM_POSITIONS),
        "push": settle_locked_robot(HOME_ARM_POSITIONS, push_W),
        "push_W": push_W,
    }


def weld_wrench(plant, model, plant_context):
    weld = WeldWrench(plant, plant.GetJointByName("ft300_sensing",
                                                  model.tool))
    context = weld.CreateDefaultContext()
    weld.GetInputPort("reaction_forces").FixValue(
        context, plant.get_reaction_forces_output_port().Eval(plant_context))
    return weld.GetOutputPort("wrench").Eval(context)


@pytest.mark.parametrize("case", ["rest", "push"])
def test_weld_wrench_is_the_sensor_reading(settled, case):
    state = settled[case]
    np.testing.assert_array_equal(weld_wrench(*state), sensor_reading(*state))


def test_a_push_on_the_tool_reaches_the_sensor(settled):
    """The push at the tool centre point T, moved to the measurement frame
    M: the force itself and the torque tau + (p_T - p_M) x f, in M."""
    plant, model, context = settled["push"]
    push = settled["push_W"]
    X_WM = model.ft_measurement_frame.CalcPoseInWorld(context)
    p_WT = model.tcp_frame.CalcPoseInWorld(context).translation()
    R_MW = X_WM.rotation().inverse().matrix()
    f_W = push.translational()
    tau_W = push.rotational() + np.cross(p_WT - X_WM.translation(), f_W)
    change = weld_wrench(*settled["push"]) - weld_wrench(*settled["rest"])
    np.testing.assert_allclose(change[:3], R_MW @ f_W, atol=1e-6)
    np.testing.assert_allclose(change[3:], R_MW @ tau_W, atol=1e-6)


def test_weld_wrench_connects_to_the_plant():
    """In a diagram with the robot, joints locked. The discrete plant's
    reaction forces are sampled outputs, zero until its first step: the
    reading stored at initialisation is zero. The plant steps in an
    unrestricted update, which Drake runs before the discrete updates due
    at the same time, so the reading of t = 0 already sees the forces of
    the initial state: the tool's weight."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    model = add_robot(plant)
    plant.Finalize()
    weld = builder.AddSystem(WeldWrench(
        plant, plant.GetJointByName("ft300_sensing", model.tool)))
    sensor = builder.AddSystem(WristForceTorqueSensor(
        ForceTorqueSensorParameters.ideal()))
    builder.Connect(plant.get_reaction_forces_output_port(),
                    weld.GetInputPort("reaction_forces"))
    builder.Connect(weld.GetOutputPort("wrench"),
                    sensor.GetInputPort("wrench"))
    simulator = Simulator(builder.Build())
    root = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(root)
    for i in plant.GetJointIndices():
        if plant.get_joint(i).num_velocities() == 1:
            plant.get_joint(i).Lock(plant_context)
    output = sensor.GetOutputPort("wrench_measured")
    sensor_context = sensor.GetMyContextFromRoot(root)
    simulator.Initialize()
    np.testing.assert_array_equal(output.Eval(sensor_context), 0.0)
    simulator.AdvanceTo(0.0)
    weight = plant.GetBodyByName("wiping_tool", model.tool).get_mass(
        plant_context) * 9.81
    assert np.linalg.norm(output.Eval(sensor_context)[:3]) == pytest.approx(
        weight, rel=1e-3)


def test_the_station_reads_the_wrench_in_the_described_sensor_frame(
        tmp_path):
    """A sensor whose measurement frame (tool.ft_sensor_frame) is turned
    and offset from the child frame of its measuring weld
    (tool.ft_sensor_joint), as a URDF's sensor frame often is: the
    simulated station reads the wrench at and in the described frame,
    the tool's weight as the controller expects it
    (tool_weight_reading)."""
    path = write_omni_arm(tmp_path, 6)
    urdf = tmp_path / "omni_arm.urdf"
    urdf.write_text(urdf.read_text().replace("</robot>", (
        "<link name='ft_frame'/><joint name='ft_frame' type='fixed'>"
        "<parent link='sensor'/><child link='ft_frame'/>"
        "<origin xyz='0 0 0.03' rpy='0 0 1.5707963267948966'/></joint>"
        "\n</robot>")))
    path.write_text(path.read_text().replace(
        "ft_sensor_frame: omni_arm::sensor",
        "ft_sensor_frame: omni_arm::ft_frame").replace(
        "ft_sensor_joint: omni_arm::sensor",
        "ft_sensor_joint: omni_arm::tool"))
    description = load_robot_description(path)
    station = SimulatedStation(StationOptions(time_step=0.005),
                               robot=description)
    diagram = station.diagram
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    station.set_initial_state(context)
    diagram.GetInputPort("base.velocity_command").FixValue(
        context, np.zeros(3))
    diagram.GetInputPort("arm.position_command").FixValue(
        context, description.arm.home)
    simulator.AdvanceTo(0.05)
    q = diagram.GetOutputPort("arm.position_measured").Eval(context)
    expected = tool_weight_reading(
        ArmKinematics(*make_robot_plant(description)), q)
    np.testing.assert_allclose(
        diagram.GetOutputPort("truth.wrist_wrench").Eval(context), expected,
        atol=1e-3 * np.abs(expected).max())
    with pytest.raises(ValueError, match="frame = omni_arm::link1"):
        WeldWrench(station.plant, station.model.ft_sensor_joint,
                   station.plant.GetFrameByName("link1"))


def test_parameters_and_arguments_are_checked():
    with pytest.raises(ValueError, match="force_resolution = -0.01"):
        ForceTorqueSensorParameters(force_resolution=-0.01)
    for name in ("torque_resolution", "force_noise_std", "torque_noise_std",
                 "force_range", "rate", "seed"):
        with pytest.raises(ValueError, match=name):
            ForceTorqueSensorParameters(**{name: -1.0})
    loaded = ForceTorqueSensorParameters()
    loaded.torque_range = 0.0
    with pytest.raises(ValueError, match="torque_range"):
        validate(loaded)
    with pytest.raises(ValueError, match="wrench"):
        measure(np.zeros(5), None, 0)
    with pytest.raises(ValueError, match="tick"):
        measure(np.zeros(6), None, 1.5)
    plant, model = make_robot_plant()
    revolute = plant.GetJointByName("joint1", model.arm)
    with pytest.raises(ValueError, match="weld_joint"):
        WeldWrench(plant, revolute)
    other, other_model = make_robot_plant()
    with pytest.raises(ValueError, match="weld_joint"):
        WeldWrench(plant, other.GetJointByName("ft300_sensing",
                                               other_model.tool))

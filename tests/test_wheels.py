"""The base's wheels on the floor: the horizontal compliance's joints in
the plant and its modes against sqrt(k / m) and a free response, the
wheels' slip (the drive's force saturated at mu m g) in the station, and
the defaults that leave the plant as it was."""

import numpy as np
import pytest
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, VectorLogSink
from shipped_names import ARM_JOINTS, BASE_JOINTS, MOUNT_JOINTS

from drake_wbc.robot.description import (
    load_robot_description,
    models_dir,
    shipped_robot,
)
from drake_wbc.robot.model import (
    HOME_ARM_POSITIONS,
    add_robot,
    horizontal_modes,
    joint_position_indices,
    joint_velocity_indices,
    make_robot_plant,
    spring_stiffnesses,
    suspension_gains,
)
from drake_wbc.robot.suspension import (
    HORIZONTAL_JOINTS,
    SUSPENSION_JOINTS,
    HorizontalCompliance,
    SuspensionParameters,
)
from drake_wbc.station.drivers import BaseDriverParameters
from drake_wbc.station.simulation import SimulatedStation, StationOptions
from drake_wbc.station.traction import TractionParameters, traction_limits

HORIZONTAL = HorizontalCompliance(frequency=7.0, yaw_frequency=9.0,
                                  damping_ratio=0.05)
PARAMS = SuspensionParameters(horizontal=HORIZONTAL)


@pytest.fixture(scope="module")
def compliant():
    gains = suspension_gains(PARAMS, HOME_ARM_POSITIONS)
    plant, model = make_robot_plant(suspension=gains)
    return gains, plant, model


def test_the_defaults_leave_the_plant_and_its_drives_as_they_were():
    assert StationOptions().traction is None
    assert SuspensionParameters().horizontal is None
    rigid, rigid_model = make_robot_plant()
    gains = suspension_gains(SuspensionParameters(), HOME_ARM_POSITIONS)
    assert gains.horizontal_stiffness is None and gains.drive_inertia is None
    suspended, model = make_robot_plant(suspension=gains)
    assert model.horizontal_joints == ()
    # The suspension alone: its two joints, no more.
    assert suspended.num_joints() == rigid.num_joints() + 2
    assert suspended.num_multibody_states() == (
        rigid.num_multibody_states() + 4)
    station = SimulatedStation(StationOptions(time_step=0.005))
    assert station.plant.num_joints() == rigid.num_joints()
    assert station.plant.num_multibody_states() == (
        rigid.num_multibody_states())
    # The base's drives: the model's effort limits, no rotor inertia.
    for plant, robot in ((station.plant, station.model),
                         (suspended, model)):
        context = plant.CreateDefaultContext()
        for name in BASE_JOINTS:
            actuator = plant.GetJointActuatorByName(name, robot.base)
            reference = rigid.GetJointActuatorByName(name, rigid_model.base)
            assert actuator.effort_limit() == reference.effort_limit()
            assert actuator.rotor_inertia(context) == 0.0


def test_the_horizontal_compliance_adds_three_joints_and_moves_nothing(
        compliant):
    gains, plant, model = compliant
    rigid, rigid_model = make_robot_plant()
    assert plant.num_joints() == rigid.num_joints() + 5
    assert [j.name() for j in model.horizontal_joints] == list(
        HORIZONTAL_JOINTS)
    assert [j.name() for j in model.suspension_joints] == list(
        SUSPENSION_JOINTS)
    springs = spring_stiffnesses(plant)
    for joint, k, c in zip(model.horizontal_joints,
                           gains.horizontal_stiffness,
                           gains.horizontal_damping, strict=True):
        assert springs[joint.index()] == pytest.approx(k)
        assert joint.default_damping() == pytest.approx(c)
    context, rigid_context = (plant.CreateDefaultContext(),
                              rigid.CreateDefaultContext())
    for name, inertia in zip(BASE_JOINTS, gains.drive_inertia, strict=True):
        actuator = plant.GetJointActuatorByName(name, model.base)
        assert actuator.rotor_inertia(context) == inertia
    for frame, rigid_frame in ((model.tcp_frame, rigid_model.tcp_frame),
                               (model.base_frame, rigid_model.base_frame)):
        np.testing.assert_allclose(
            frame.CalcPoseInWorld(context).GetAsMatrix4(),
            rigid_frame.CalcPoseInWorld(rigid_context).GetAsMatrix4(),
            atol=1e-12)


def test_each_horizontal_axis_has_sqrt_k_over_m(compliant):
    gains, plant, model = compliant
    context = plant.CreateDefaultContext()
    q = plant.GetPositions(context)
    q[joint_position_indices(model.arm_joints)] = HOME_ARM_POSITIONS
    plant.SetPositions(context, q)
    iv = joint_velocity_indices(model.horizontal_joints)
    inertia = np.diag(plant.CalcMassMatrix(context))[iv]
    # x and y carry the whole robot (the mass on its wheels), yaw its
    # inertia about the footprint's centre.
    mass = plant.CalcTotalMass(context)
    np.testing.assert_allclose(inertia[:2], mass, rtol=1e-12)
    frequency = np.sqrt(gains.horizontal_stiffness / inertia) / (2 * np.pi)
    np.testing.assert_allclose(frequency, [7.0, 7.0, 9.0], rtol=1e-9)
    np.testing.assert_allclose(
        gains.horizontal_damping / (2 * inertia * 2 * np.pi * frequency),
        0.05, rtol=1e-9)
    # The x mode alone (the arm's centre of mass ahead of the yaw axis
    # couples y and yaw, not x).
    modes = horizontal_modes(plant, model)
    x_mode = max(modes, key=lambda m: m.shape[0])
    assert x_mode.frequency_hz == pytest.approx(7.0, rel=1e-6)


def test_the_chassis_shakes_at_sqrt_k_over_m_in_simulation(compliant):
    gains, _, _ = compliant
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    model = add_robot(plant, suspension=gains)
    plant.Finalize()
    source = builder.AddSystem(ConstantVectorSource(np.zeros(6)))
    builder.Connect(source.get_output_port(),
                    plant.get_desired_state_input_port(model.base))
    log = builder.AddSystem(VectorLogSink(plant.num_multibody_states()))
    builder.Connect(plant.get_state_output_port(), log.get_input_port())
    simulator = Simulator(builder.Build())
    root = simulator.get_mutable_context()
    context = plant.GetMyMutableContextFromRoot(root)
    q = plant.GetPositions(context)
    q[joint_position_indices(model.arm_joints)] = HOME_ARM_POSITIONS
    x = joint_position_indices(model.horizontal_joints[:1])[0]
    q[x] = 1e-3
    plant.SetPositions(context, q)
    # The wheels held on the floor, the rest of the robot rigid on them.
    for name in (*BASE_JOINTS, *MOUNT_JOINTS, *SUSPENSION_JOINTS):
        plant.GetJointByName(name, model.base).Lock(context)
    for name in ARM_JOINTS:
        plant.GetJointByName(name, model.arm).Lock(context)
    simulator.AdvanceTo(2.0)
    data = log.FindLog(root)
    times, shear = data.sample_times(), data.data()[x]
    spectrum = np.abs(np.fft.rfft((shear - shear.mean())
                                  * np.hanning(len(shear)), n=2**16))
    frequency = np.fft.rfftfreq(2**16, d=times[1] - times[0])[
        np.argmax(spectrum)]
    mass = plant.CalcTotalMass(context)
    closed_form = np.sqrt(gains.horizontal_stiffness[0] / mass) / (2 * np.pi)
    damped = closed_form * np.sqrt(1 - HORIZONTAL.damping_ratio**2)
    assert frequency == pytest.approx(damped, rel=0.02)
    # Its decay: zeta from the logarithmic decrement of the peaks.
    peaks = [i for i in range(1, len(shear) - 1)
             if shear[i] > shear[i - 1] and shear[i] >= shear[i + 1]
             and shear[i] > 0]
    decrement = np.log(shear[peaks[0]] / shear[peaks[4]]) / 4
    zeta = decrement / np.sqrt(4 * np.pi**2 + decrement**2)
    assert zeta == pytest.approx(HORIZONTAL.damping_ratio, rel=0.1)


def _base_step(options, speed, duration):
    """The station's robot from rest under a step of the base's velocity
    command to `speed` along x: (times, the robot's centre-of-mass
    velocity along x, the base's odometry velocity along x)."""
    station = SimulatedStation(options)
    simulator = Simulator(station.diagram)
    root = simulator.get_mutable_context()
    station.set_initial_state(root)
    diagram = station.diagram
    diagram.GetInputPort("arm.position_command").FixValue(
        root, np.array(station.options.initial_arm_positions))
    diagram.GetInputPort("base.velocity_command").FixValue(
        root, np.array([speed, 0.0, 0.0]))
    simulator.Initialize()
    plant = station.plant
    context = plant.GetMyContextFromRoot(root)
    h = options.time_step
    times, com, odometry = [], [], []
    for n in range(1, int(round(duration / h)) + 1):
        simulator.AdvanceTo(n * h)
        times.append(n * h)
        com.append(plant.CalcCenterOfMassTranslationalVelocityInWorld(
            context)[0])
        odometry.append(diagram.GetOutputPort(
            "base.state_estimated").Eval(root)[3])
    return np.array(times), np.array(com), np.array(odometry)


def test_a_rapid_step_slips_the_wheels_at_mu_g():
    mu, h, speed = 0.3, 0.002, 0.8
    # The jerky loop asks for 5 m/s^2, beyond mu g = 2.94 m/s^2.
    base = BaseDriverParameters(loop="jerky")
    options = StationOptions(time_step=h, base=base)
    slipping = StationOptions(time_step=h, base=base,
                              traction=TractionParameters(
                                  friction_coefficient=mu))
    g = 9.81
    station = SimulatedStation(slipping)
    mass = station.plant.CalcTotalMass(
        station.plant.CreateDefaultContext())
    np.testing.assert_allclose(
        [station.plant.GetJointActuatorByName(n, station.model.base)
         .effort_limit() for n in BASE_JOINTS],
        traction_limits(station.options.traction, mass, g), rtol=1e-9)
    times, com, odometry = _base_step(slipping, speed, 0.6)
    _, free_com, free_odometry = _base_step(options, speed, 0.6)
    # The floor's force on the robot is its momentum's rate: with the
    # wheels slipping, m a_com = mu m g, however the arm swings (to 1e-4:
    # SAP's convergence on the saturated servo).
    accel, free_accel = np.diff(com) / h, np.diff(free_com) / h
    assert np.max(np.abs(accel)) <= mu * g * (1 + 1e-4)
    saturated = accel > mu * g * (1 - 1e-4)
    assert saturated.sum() * h > 0.2
    # Without the limit the robot follows the loop's 5 m/s^2.
    assert np.max(free_accel) > 4.5
    # The base gets to the speed later: at least speed / (mu g), not
    # speed / 5 m/s^2 (the loop's ramp).
    reached = times[np.argmax(odometry > 0.99 * speed)]
    free_reached = times[np.argmax(free_odometry > 0.99 * speed)]
    assert reached >= 0.99 * speed / (mu * g)
    assert free_reached < 0.75 * speed / (mu * g)
    # And then it runs at the command's speed: slip is only while the
    # servo's demand exceeds the grip.
    assert odometry[-1] == pytest.approx(speed, abs=5e-3)


def test_the_wheels_grip_about_z_with_the_robots_own_lever():
    """The yaw torque the wheels can take is mu m g rho with rho the
    robot's own wheel distance (its description's base.wheel_distance:
    0.36 m on the shipped base), not the shipped base's on another robot;
    a robot whose description gives none asks for it, naming the field."""
    robot = load_robot_description(models_dir() / "lbr_omni.robot.yaml")
    assert robot.base.wheel_distance is None
    with pytest.raises(ValueError, match=(
            r"traction.wheel_distance is missing, which is not allowed: "
            r"the robot's description gives no base.wheel_distance")):
        SimulatedStation(StationOptions(time_step=0.002,
                                        traction=TractionParameters()),
                         robot=robot)
    robot.base.wheel_distance = 0.25
    station = SimulatedStation(StationOptions(
        time_step=0.002, traction=TractionParameters()), robot=robot)
    plant, model = station.plant, station.model
    mass = plant.CalcTotalMass(plant.CreateDefaultContext())
    yaw = plant.get_joint_actuator(next(
        i for i in plant.GetJointActuatorIndices()
        if plant.get_joint_actuator(i).joint().index()
        == model.base_joints[2].index()))
    assert yaw.effort_limit() == pytest.approx(0.45 * mass * 9.81 * 0.25,
                                               rel=1e-9)
    assert shipped_robot().base.wheel_distance == 0.36


@pytest.mark.parametrize("kind, fields, name", [
    (HorizontalCompliance, dict(frequency=0.1), "frequency"),
    (HorizontalCompliance, dict(yaw_frequency=30.0), "yaw_frequency"),
    (HorizontalCompliance, dict(damping_ratio=0.0), "damping_ratio"),
    (HorizontalCompliance, dict(drive_inertia=0.5), "drive_inertia"),
    (HorizontalCompliance, dict(drive_yaw_inertia=0.0),
     "drive_yaw_inertia"),
    (TractionParameters, dict(friction_coefficient=2.0),
     "friction_coefficient"),
    (TractionParameters, dict(wheel_distance=-1.0), "wheel_distance"),
    (SuspensionParameters, dict(horizontal=3.0), "horizontal"),
    (StationOptions, dict(traction=0.4), "traction"),
])
def test_parameter_errors_name_the_field(kind, fields, name):
    with pytest.raises(ValueError, match=f"^{name} = "):
        kind(**fields)


def test_the_station_on_compliant_wheels_starts_at_rest():
    options = StationOptions(
        time_step=0.005, suspension=PARAMS,
        traction=TractionParameters())
    times, com, odometry = _base_step(options, 0.0, 0.5)
    station = SimulatedStation(options)
    assert len(station.model.horizontal_joints) == 3
    # The base's servo sized for the robot and the drive's own inertia.
    rigid = SimulatedStation(StationOptions(time_step=0.005))
    for name, inertia in zip(station.model.description.base.joints,
                             PARAMS_DRIVE, strict=True):
        mass = rigid._gains[name].d * rigid.options.base.servo_time_constant
        assert station._gains[name].d == pytest.approx(
            (mass + inertia) / station.options.base.servo_time_constant,
            rel=1e-12)
    assert np.max(np.abs(com)) < 1e-6
    assert np.max(np.abs(odometry)) < 1e-6


PARAMS_DRIVE = (HORIZONTAL.drive_inertia, HORIZONTAL.drive_inertia,
                HORIZONTAL.drive_yaw_inertia)


def test_on_compliant_wheels_the_filter_still_reduces_the_shaking():
    from drake_wbc.experiments import trajectory_tracking
    from drake_wbc.experiments.runner import build_closed_loop, simulate
    from drake_wbc.experiments.scenario import find_scenario, load_scenario

    scenario = load_scenario(find_scenario("trajectory_tracking_wheels"))
    assert scenario.station.suspension.horizontal is not None
    assert scenario.station.traction is not None
    logs = {v.name: simulate(build_closed_loop(scenario, v), duration=2.0)
            for v in scenario.variants}
    for log in logs.values():
        before = log.time < 0.9
        assert np.max(np.abs(log["truth.end_effector_velocity"][before,
                                                                 :3])) < 1e-3
    scenario.duration = 2.0
    metrics = trajectory_tracking.compute_metrics(scenario, logs)
    ratio = "ratio_unfiltered_to_filtered."
    assert metrics[ratio + "oscillation_rms_shaking_band_m_s"] > 1.5
    assert metrics[ratio + "measured.oscillation_rms_shaking_band_m_s"] > 1.5

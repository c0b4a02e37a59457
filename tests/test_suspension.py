"""The base's suspension: its joints in the plant, its modes against
sqrt((k - G) / I) read from the plant and against a simulation, and the
shaking base in closed loop with the controller."""

import numpy as np
import pytest
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import PdControllerGains, RevoluteSpring
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, VectorLogSink
from shipped_names import ARM_JOINTS, BASE_JOINTS, MOUNT_JOINTS

from drake_wbc.robot.description import load_robot_description, models_dir
from drake_wbc.robot.model import (
    HOME_ARM_POSITIONS,
    ArmMount,
    add_robot,
    joint_position_indices,
    joint_velocity_indices,
    make_robot_plant,
    suspension_gains,
    suspension_modes,
)
from drake_wbc.robot.suspension import SUSPENSION_JOINTS, SuspensionParameters

PARAMS = SuspensionParameters(roll_frequency=5.0, pitch_frequency=3.0,
                              damping_ratio=0.08)


@pytest.fixture(scope="module")
def suspended():
    gains = suspension_gains(PARAMS, HOME_ARM_POSITIONS)
    plant, model = make_robot_plant(suspension=gains)
    return gains, plant, model


def test_the_suspension_adds_two_spring_damper_joints_and_moves_nothing(
        suspended):
    gains, plant, model = suspended
    rigid, rigid_model = make_robot_plant()
    assert plant.num_positions() == rigid.num_positions() + 2
    springs = {e.joint().name(): e.default_stiffness()
               for e in (plant.get_force_element(i)
                         for i in _force_element_indices(plant))
               if isinstance(e, RevoluteSpring)}
    for name, k, c in zip(SUSPENSION_JOINTS, gains.stiffness, gains.damping,
                          strict=True):
        joint = plant.GetJointByName(name, model.base)
        assert springs[name] == pytest.approx(k)
        assert joint.default_damping() == pytest.approx(c)
    # The base's actuators are still x, y, yaw, in that order; the mass and
    # every frame at rest are the rigid robot's.
    assert [plant.get_joint_actuator(i).joint().name()
            for i in plant.GetJointActuatorIndices(model.base)] == list(
        BASE_JOINTS)
    context, rigid_context = (plant.CreateDefaultContext(),
                              rigid.CreateDefaultContext())
    assert plant.CalcTotalMass(context) == pytest.approx(
        rigid.CalcTotalMass(rigid_context), abs=1e-12)
    for frame, rigid_frame in ((model.tcp_frame, rigid_model.tcp_frame),
                               (model.arm_base_frame,
                                rigid_model.arm_base_frame),
                               (model.lidar_frames[0],
                                rigid_model.lidar_frames[0])):
        np.testing.assert_allclose(
            frame.CalcPoseInWorld(context).GetAsMatrix4(),
            rigid_frame.CalcPoseInWorld(rigid_context).GetAsMatrix4(),
            atol=1e-12)


def _inertia_and_gravity(plant, model, q_a):
    """Read from the plant at the arm's q_a: the diagonal of the mass
    matrix I of the suspension's joints (mount held) and gravity's
    stiffness G by central differences."""
    context = plant.CreateDefaultContext()
    q = plant.GetPositions(context)
    q[joint_position_indices(model.arm_joints)] = q_a
    plant.SetPositions(context, q)
    iq = joint_position_indices(model.suspension_joints)
    iv = joint_velocity_indices(model.suspension_joints)
    inertia = np.diag(plant.CalcMassMatrix(context))[iv]
    gravity = []
    for i, j in zip(iq, iv, strict=True):
        tau = []
        for step in (1e-5, -1e-5):
            shifted = q.copy()
            shifted[i] += step
            plant.SetPositions(context, shifted)
            tau.append(plant.CalcGravityGeneralizedForces(context)[j])
        gravity.append((tau[0] - tau[1]) / 2e-5)
    return inertia, np.array(gravity)


def test_each_axis_has_the_frequency_asked_for_from_the_plant(suspended):
    gains, plant, model = suspended
    inertia, gravity = _inertia_and_gravity(plant, model, HOME_ARM_POSITIONS)
    frequency = np.sqrt((gains.stiffness - gravity) / inertia) / (2 * np.pi)
    np.testing.assert_allclose(frequency, [PARAMS.roll_frequency,
                                           PARAMS.pitch_frequency],
                               rtol=1e-6)
    np.testing.assert_allclose(gains.damping / (2 * inertia * 2 * np.pi
                                                * frequency),
                               PARAMS.damping_ratio, rtol=1e-6)
    # The heavy chassis: both far stiffer than the mount's springs.
    assert np.all(inertia > 10.0)
    modes = suspension_modes(plant, model)
    np.testing.assert_allclose([m.frequency_hz for m in modes], [3.0, 5.0],
                               rtol=1e-3)


def test_the_suspension_is_sized_on_the_robot_it_carries():
    """On the second shipped robot (seven joints, its own base), its arm
    turned and tilted on the mount: the gains give the modes asked for on
    that robot (the sizing used the shipped six-joint robot's plant,
    which refused the seven positions)."""
    robot = load_robot_description(models_dir() / "lbr_omni.robot.yaml")
    mount = ArmMount(yaw=0.5, tilt=0.2)
    home = np.asarray(robot.arm.home, dtype=float)
    gains = suspension_gains(PARAMS, home, robot, mount)
    plant, model = make_robot_plant(robot, suspension=gains, mount=mount)
    assert model.num_arm_joints == 7
    inertia, gravity = _inertia_and_gravity(plant, model, home)
    np.testing.assert_allclose(
        np.sqrt((gains.stiffness - gravity) / inertia) / (2 * np.pi),
        [PARAMS.roll_frequency, PARAMS.pitch_frequency], rtol=1e-6)
    # The turned arm couples roll and pitch a little: the modes move by
    # half a percent from the axes' frequencies.
    modes = suspension_modes(plant, model, home)
    np.testing.assert_allclose(sorted(m.frequency_hz for m in modes),
                               [PARAMS.pitch_frequency, PARAMS.roll_frequency],
                               rtol=0.01)


def test_the_pivot_may_go_up_to_the_robots_own_deck():
    """The suspension's pivot lies at most at the deck of the robot it is
    sized on (its base.height), not the shipped base's 0.3 m: 0.33 m
    under the second robot's 0.35 m deck is taken, 0.25 m above a 0.2 m
    deck is refused naming both."""
    robot = load_robot_description(models_dir() / "lbr_omni.robot.yaml")
    home = np.asarray(robot.arm.home, dtype=float)
    high = SuspensionParameters(pivot_height=0.33)
    gains = suspension_gains(high, home, robot)
    plant, model = make_robot_plant(robot, suspension=gains)
    inertia, gravity = _inertia_and_gravity(plant, model, home)
    np.testing.assert_allclose(
        np.sqrt((gains.stiffness - gravity) / inertia) / (2 * np.pi),
        [high.roll_frequency, high.pitch_frequency], rtol=1e-6)
    robot.base.height = 0.2
    with pytest.raises(ValueError, match=(
            r"pivot_height = 0.25 m is not allowed: must be at most the "
            r"robot's deck, base.height = 0.2 m")):
        suspension_gains(SuspensionParameters(pivot_height=0.25), home,
                         robot)


def test_the_suspension_goes_under_a_base_of_the_users_own_names(tmp_path):
    """A base of the user's model, its yaw joint named otherwise than the
    shipped base's (base.joints[2] = 'my_base::base_theta', the base not
    the directives' first model): the suspension goes between that joint
    and the chassis, with the modes asked for."""
    (tmp_path / "package.xml").write_text(
        "<?xml version='1.0'?><package format='2'><name>mine</name>"
        "</package>")
    (tmp_path / "my_base.sdf").write_text(
        (models_dir() / "mcr_base.sdf").read_text().replace(
            '"base_yaw"', '"base_theta"'))
    directives = (models_dir() / "mcr.dmd.yaml").read_text().replace(
        "mcr_base", "my_base").replace(
        "package://drake_wbc/my_base.sdf", "package://mine/my_base.sdf")
    arm = "- add_model:\n    name: elfin5\n    file: package://drake_wbc/elfin5.sdf\n"
    directives = directives.replace(arm, "").replace(
        "directives:\n", "directives:\n" + arm)
    (tmp_path / "my.dmd.yaml").write_text(directives)
    text = (models_dir() / "mcr.robot.yaml").read_text().replace(
        "mcr_base::", "my_base::").replace(
        "my_base::base_yaw", "my_base::base_theta").replace(
        "package://drake_wbc/mcr.dmd.yaml", "my.dmd.yaml").replace(
        "drake_wbc: .", "mine: .")
    (tmp_path / "my.robot.yaml").write_text(text)
    robot = load_robot_description(tmp_path / "my.robot.yaml")
    home = np.asarray(robot.arm.home, dtype=float)
    gains = suspension_gains(PARAMS, home, robot)
    plant, model = make_robot_plant(robot, suspension=gains)
    assert [j.name() for j in model.suspension_joints] == list(
        SUSPENSION_JOINTS)
    inertia, gravity = _inertia_and_gravity(plant, model, home)
    np.testing.assert_allclose(
        np.sqrt((gains.stiffness - gravity) / inertia) / (2 * np.pi),
        [PARAMS.roll_frequency, PARAMS.pitch_frequency], rtol=1e-6)


def test_the_chassis_rocks_at_the_suspensions_frequency_in_simulation(
        suspended):
    gains, _, _ = suspended
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    model = add_robot(plant, suspension=gains)
    for name in BASE_JOINTS:
        plant.GetJointActuatorByName(name, model.base).set_controller_gains(
            PdControllerGains(p=0.0, d=3e4))
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
    q[joint_position_indices(model.arm_joints)] = (
        HOME_ARM_POSITIONS)
    pitch = joint_position_indices(model.suspension_joints[1:])[0]
    q[pitch] = 0.004
    plant.SetPositions(context, q)
    for name in ARM_JOINTS:
        plant.GetJointByName(name, model.arm).Lock(context)
    for name in MOUNT_JOINTS:
        plant.GetJointByName(name, model.base).Lock(context)
    simulator.AdvanceTo(2.0)
    data = log.FindLog(root)
    times, angle = data.sample_times(), data.data()[pitch]
    angle = angle - angle.mean()
    spectrum = np.abs(np.fft.rfft(angle * np.hanning(len(angle)), n=2**16))
    frequency = np.fft.rfftfreq(2**16, d=times[1] - times[0])[
        np.argmax(spectrum)]
    damped = PARAMS.pitch_frequency * np.sqrt(1 - PARAMS.damping_ratio**2)
    assert frequency == pytest.approx(damped, rel=0.03)


@pytest.mark.parametrize("fields, name", [
    (dict(roll_frequency=0.1), "roll_frequency"),
    (dict(pitch_frequency=25.0), "pitch_frequency"),
    (dict(damping_ratio=1.5), "damping_ratio"),
    (dict(pivot_height=-0.1), "pivot_height"),
])
def test_parameter_errors_name_the_field(fields, name):
    with pytest.raises(ValueError, match=f"^{name} = "):
        SuspensionParameters(**fields)


def test_the_shaking_base_in_closed_loop_the_filter_reduces_the_shaking():
    from drake_wbc.experiments import trajectory_tracking
    from drake_wbc.experiments.runner import build_closed_loop, simulate
    from drake_wbc.experiments.scenario import find_scenario, load_scenario

    scenario = load_scenario(find_scenario("trajectory_tracking_shaking"))
    assert scenario.station.suspension is not None
    assert scenario.station.base.loop == "ringing"
    logs = {v.name: simulate(build_closed_loop(scenario, v), duration=2.0)
            for v in scenario.variants}
    for log in logs.values():
        # At rest before the step: the station starts in equilibrium.
        before = log.time < 0.9
        assert np.max(np.abs(log["truth.end_effector_velocity"][before,
                                                                 :3])) < 1e-3
    scenario.duration = 2.0
    metrics = trajectory_tracking.compute_metrics(scenario, logs)
    ratio = "ratio_unfiltered_to_filtered."
    assert metrics[ratio + "oscillation_rms_shaking_band_m_s"] > 1.5
    assert metrics[ratio + "measured.oscillation_rms_shaking_band_m_s"] > 1.5
    assert metrics[ratio + "error_rms_total_m_s"] > 1.2


def _force_element_indices(plant):
    from pydrake.multibody.tree import ForceElementIndex

    return [ForceElementIndex(i) for i in range(plant.num_force_elements())]

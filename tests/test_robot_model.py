"""The robot model: what it contains, its kinematics against the facts table,
and its flexible mount against a simulation of the loaded plant."""

import numpy as np
import pytest
from locked_robot import sensing_weld_reaction, settle_locked_robot
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import PdControllerGains
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, VectorLogSink
from reference_kinematics import (
    ELFIN5,
    ELFIN5_LOWER,
    ELFIN5_UPPER,
    UR5E_CENTRES_OF_MASS,
    UR5E_DH,
    UR5E_MASSES,
    dh_frames,
    forward_kinematics,
)
from shipped_names import ARM_JOINTS, BASE_JOINTS, MOUNT_JOINTS

from drake_wbc.robot.description import (
    load_robot_description,
    models_dir,
    shipped_robot,
)
from drake_wbc.robot.model import (
    HOME_ARM_POSITIONS,
    ArmKinematics,
    ArmMount,
    add_robot,
    joint_position_indices,
    make_robot_plant,
    mount_rocking_modes,
    shared_robot_plant,
)

# Efforts (N m) and link masses (kg, base to L6) of the Elfin5 facts table;
# its joint origins and limits are in reference_kinematics.
ELFIN5_EFFORTS = [200, 200, 200, 104, 34, 34]
LINK_MASSES = [2.13, 7.96, 3.73, 4.72, 1.47, 2.50, 0.455]


@pytest.fixture(scope="module")
def robot():
    return make_robot_plant()


def _arm_context(plant, model, q_a):
    context = plant.CreateDefaultContext()
    q = plant.GetPositions(context)
    q[joint_position_indices(model.arm_joints)] = q_a
    plant.SetPositions(context, q)
    return context


def test_joints_names_and_limits(robot):
    plant, model = robot
    assert plant.num_positions() == plant.num_velocities() == 11
    names = {
        plant.get_joint(i).name()
        for i in plant.GetJointIndices()
        if plant.get_joint(i).num_velocities() == 1
    }
    assert names == set(BASE_JOINTS + MOUNT_JOINTS + ARM_JOINTS)
    actuated = [
        plant.get_joint_actuator(i).joint().name()
        for i in plant.GetJointActuatorIndices()
    ]
    assert sorted(actuated) == sorted(BASE_JOINTS + ARM_JOINTS)
    for name, limit, effort in zip(ARM_JOINTS, ELFIN5_UPPER, ELFIN5_EFFORTS,
                                   strict=True):
        joint = plant.GetJointByName(name, model.arm)
        assert joint.position_lower_limits()[0] == -limit
        assert joint.position_upper_limits()[0] == limit
        assert joint.velocity_upper_limits()[0] == 1.57
        assert joint.acceleration_upper_limits()[0] == 12.56
        actuator = plant.GetJointActuatorByName(name, model.arm)
        assert actuator.effort_limit() == effort
    for name, limit in zip(BASE_JOINTS, (1.0, 1.0, 1.0), strict=True):
        joint = plant.GetJointByName(name, model.base)
        assert joint.velocity_upper_limits()[0] == limit
    for name in MOUNT_JOINTS:
        assert plant.GetJointByName(name, model.base).type_name() == (
            "revolute"
        )


def test_masses(robot):
    plant, model = robot
    context = plant.CreateDefaultContext()

    def mass(instance):
        return sum(
            plant.get_body(b).get_mass(context)
            for b in plant.GetBodyIndices(instance)
        )

    assert mass(model.arm) == pytest.approx(sum(LINK_MASSES), abs=1e-9)
    assert mass(model.tool) == pytest.approx(0.30 + 0.40, abs=1e-9)
    # Chassis 120 kg and mount plate 1 kg (EST) within the facts' 100-150.
    assert 100 <= mass(model.base) <= 150
    total = mass(model.base) + mass(model.arm) + mass(model.tool)
    assert total == pytest.approx(121.0 + 22.965 + 0.7, abs=1e-9)


@pytest.mark.parametrize(
    "q, position",
    [
        # Straight up: the offsets add along z.
        ((0, 0, 0, 0, 0, 0), (0, 0, 0.22 + 0.38 + 0.42 + 0.1565)),
        # Turning the base joint of a vertical arm moves nothing.
        ((np.pi / 2, 0, 0, 0, 0, 0), (0, 0, 1.1765)),
        # J2 (axis -y) at -90 degrees tips the whole arm forward.
        ((0, -np.pi / 2, 0, 0, 0, 0), (0.38 + 0.42 + 0.1565, 0, 0.22)),
        # J3 (axis +y) at +90 degrees: the forearm points forward.
        ((0, 0, np.pi / 2, 0, 0, 0), (0.42 + 0.1565, 0, 0.60)),
        # J5 (axis +y) at +90 degrees: the flange juts forward.
        ((0, 0, 0, 0, np.pi / 2, 0), (0.1565, 0, 1.02)),
        # Both elbow and wrist at 90 degrees: the flange points down.
        ((0, 0, np.pi / 2, 0, np.pi / 2, 0), (0.42, 0, 0.60 - 0.1565)),
    ],
)
def test_flange_matches_hand_computation(robot, q, position):
    plant, model = robot
    context = _arm_context(plant, model, q)
    X = model.flange_frame.CalcPose(context, model.arm_base_frame)
    # The table rounds pi/2 to 1.5708, which moves the flange by ~1e-5 m
    # from these exact-angle hand results.
    np.testing.assert_allclose(X.translation(), position, atol=1e-4)


def test_forward_kinematics_matches_table(robot):
    plant, model = robot
    """The flange pose equals the chain written by hand from the facts
    table, independent of the model files and of Drake."""
    rng = np.random.default_rng(2)
    for _ in range(20):
        q = rng.uniform(ELFIN5_LOWER, ELFIN5_UPPER)
        context = _arm_context(plant, model, q)
        X = model.flange_frame.CalcPose(context, model.arm_base_frame)
        p, R, _, _ = forward_kinematics(ELFIN5, q)
        np.testing.assert_allclose(X.translation(), p, atol=1e-12)
        np.testing.assert_allclose(X.rotation().matrix(), R, atol=1e-12)


def test_sensor_tool_and_lidar_frames(robot):
    plant, model = robot
    context = _arm_context(plant, model, HOME_ARM_POSITIONS)
    X_FM = model.ft_measurement_frame.CalcPose(context, model.flange_frame)
    np.testing.assert_allclose(X_FM.translation(), [0, 0, 0.01625],
                               atol=1e-12)
    X_FT = model.tcp_frame.CalcPose(context, model.flange_frame)
    np.testing.assert_allclose(X_FT.translation(), [0, 0, 0.0415 + 0.10],
                               atol=1e-12)
    # The two LIDARs sit at diagonally opposite corners of the 0.8 x 0.6 m
    # footprint and face outwards, yawed +45 and -135 degrees.
    front, rear = (
        frame.CalcPose(context, model.base_frame)
        for frame in model.lidar_frames
    )
    for X in (front, rear):
        p = X.translation()
        assert 0.3 < abs(p[0]) <= 0.4 and 0.2 < abs(p[1]) <= 0.3
        facing = X.rotation().matrix()[:, 0]
        outward = np.array([np.sign(p[0]), np.sign(p[1]), 0]) / np.sqrt(2)
        np.testing.assert_allclose(facing, outward, atol=1e-5)
    np.testing.assert_allclose(front.translation()[:2],
                               -rear.translation()[:2])


def test_arm_kinematics_jacobian_against_finite_differences(robot):
    plant, model = robot
    kinematics = ArmKinematics(plant, model)
    np.testing.assert_allclose(kinematics.R_ba, np.eye(3), atol=1e-12)
    rng = np.random.default_rng(3)
    step = 1e-6
    for _ in range(5):
        q = rng.uniform(0.8 * kinematics.lower, 0.8 * kinematics.upper)
        values = kinematics.evaluate(q)
        context = _arm_context(plant, model, q)
        p_base = model.tcp_frame.CalcPose(context, model.base_frame)
        np.testing.assert_allclose(values.p_ee_in_base,
                                   p_base.translation(), atol=1e-12)
        for i in range(6):
            dq = np.zeros(6)
            dq[i] = step
            plus = kinematics.evaluate(q + dq).X_AE
            minus = kinematics.evaluate(q - dq).X_AE
            velocity = (plus.translation() - minus.translation()) / (2 * step)
            R_dot = (plus.rotation().matrix() - minus.rotation().matrix()) / (
                2 * step
            )
            W = R_dot @ values.X_AE.rotation().matrix().T
            omega = np.array([W[2, 1], W[0, 2], W[1, 0]])
            np.testing.assert_allclose(values.J_a[:3, i], velocity, atol=1e-8)
            np.testing.assert_allclose(values.J_a[3:, i], omega, atol=1e-8)


def test_home_pose_is_comfortable(robot):
    plant, model = robot
    kinematics = ArmKinematics(plant, model)
    span = kinematics.upper - kinematics.lower
    margin = np.minimum(HOME_ARM_POSITIONS - kinematics.lower,
                        kinematics.upper - HOME_ARM_POSITIONS) / span
    assert np.all(margin > 0.25)
    # Its manipulability is among the best tenth of the joint space.
    def manipulability(q):
        J_a = kinematics.evaluate(q).J_a
        return np.prod(np.linalg.svd(J_a, compute_uv=False))

    rng = np.random.default_rng(4)
    samples = [
        manipulability(rng.uniform(kinematics.lower, kinematics.upper))
        for _ in range(400)
    ]
    assert manipulability(HOME_ARM_POSITIONS) > np.percentile(samples, 90)


def test_mount_rocking_mode(robot):
    plant, model = robot
    modes = mount_rocking_modes(plant, model)
    assert len(modes) == 2
    for mode in modes:
        assert mode.frequency_hz == pytest.approx(5.0, abs=0.1)
        assert mode.damping_ratio == pytest.approx(0.05, abs=0.005)


def _simulate_locked(q_a, initial_mount, base_velocity=0.0, duration=1.5):
    """Simulates the discrete robot with its arm locked at q_a and the base
    held by a stiff velocity servo on base_x; returns (times, positions,
    velocities, plant, model, context)."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, time_step=1e-3)
    plant.set_discrete_contact_approximation(
        plant.get_discrete_contact_approximation().kSap
    )
    model = add_robot(plant)
    for name in BASE_JOINTS:
        actuator = plant.GetJointActuatorByName(name, model.base)
        actuator.set_controller_gains(PdControllerGains(p=0.0, d=3e4))
    plant.Finalize()
    desired = np.zeros(6)
    desired[3] = base_velocity
    source = builder.AddSystem(ConstantVectorSource(desired))
    builder.Connect(source.get_output_port(),
                    plant.get_desired_state_input_port(model.base))
    log = builder.AddSystem(VectorLogSink(plant.num_multibody_states()))
    builder.Connect(plant.get_state_output_port(), log.get_input_port())
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    q = plant.GetPositions(plant_context)
    q[joint_position_indices(model.arm_joints)] = q_a
    q[joint_position_indices(model.passive_joints)] = initial_mount
    plant.SetPositions(plant_context, q)
    for name in ARM_JOINTS:
        plant.GetJointByName(name, model.arm).Lock(plant_context)
    simulator.AdvanceTo(duration)
    data = log.FindLog(context).data()
    nq = plant.num_positions()
    return (log.FindLog(context).sample_times(), data[:nq], data[nq:],
            plant, model)


def _dominant_frequency(times, signal):
    signal = signal - signal.mean()
    spectrum = np.abs(np.fft.rfft(signal * np.hanning(len(signal)), n=2**16))
    frequencies = np.fft.rfftfreq(2**16, d=times[1] - times[0])
    return frequencies[np.argmax(spectrum)]


def test_mount_oscillates_at_modal_frequency_in_simulation(robot):
    plant, model = robot
    expected = mount_rocking_modes(plant, model)
    times, q, _, sim_plant, sim_model = _simulate_locked(
        HOME_ARM_POSITIONS, initial_mount=[0.0, 0.005]
    )
    pitch = q[joint_position_indices(
        [sim_plant.GetJointByName("mount_pitch", sim_model.base)])[0]]
    frequency = _dominant_frequency(times, pitch)
    pitch_mode = max(expected, key=lambda mode: mode.shape[1])
    assert frequency == pytest.approx(pitch_mode.frequency_hz, rel=0.03)
    # Logarithmic decrement of the peak-to-trough swings: independent of
    # the static sag about which the mount rings (the arm's centre of mass
    # is ahead of the mount).
    extrema = [i for i in range(1, len(pitch) - 1)
               if (pitch[i] - pitch[i - 1]) * (pitch[i + 1] - pitch[i]) < 0]
    swings = np.abs(np.diff(pitch[extrema]))
    cycles = (len(swings) - 1) / 2
    decrement = np.log(swings[0] / swings[-1]) / cycles
    zeta = decrement / np.sqrt(4 * np.pi**2 + decrement**2)
    assert zeta == pytest.approx(pitch_mode.damping_ratio, rel=0.15)


def test_base_velocity_step_shakes_end_effector():
    step = 0.1
    times, q, v, plant, model = _simulate_locked(
        HOME_ARM_POSITIONS, initial_mount=[0.0, 0.0], base_velocity=step,
        duration=2.0,
    )
    context = plant.CreateDefaultContext()
    tcp_velocity = []
    for qi, vi in zip(q.T, v.T, strict=True):
        plant.SetPositionsAndVelocities(context, np.concatenate([qi, vi]))
        V = model.tcp_frame.CalcSpatialVelocityInWorld(context)
        tcp_velocity.append(V.translational()[0])
    tcp_velocity = np.array(tcp_velocity)
    settled = times > 0.1
    # The base reaches the commanded speed; the end effector overshoots it
    # and rings at the mount's mode: a visible shake, as on the real robot.
    base_velocity = v[joint_position_indices(
        [plant.GetJointByName("base_x", model.base)])[0]]
    assert base_velocity[-1] == pytest.approx(step, rel=1e-3)
    swing = tcp_velocity[settled].max() - tcp_velocity[settled].min()
    assert swing > 0.3 * step
    frequency = _dominant_frequency(times[settled], tcp_velocity[settled])
    assert frequency == pytest.approx(5.0, abs=0.3)
    # and the ringing decays (damping ratio 0.05: to ~e^-3 in 2 s).
    late = times > 1.6
    assert np.ptp(tcp_velocity[late]) < 0.3 * swing


def test_sensing_weld_reads_the_tool_weight():
    """At rest the weld `ft300_sensing` carries the tool: its reaction
    wrench (on the tool, at the measurement frame) is the tool's weight
    and its moment about the measurement point, as an F/T sensor reads."""
    plant, model, context = settle_locked_robot(HOME_ARM_POSITIONS)
    wrench = sensing_weld_reaction(plant, model, context)
    tool = plant.GetBodyByName("wiping_tool", model.tool)
    mass = tool.get_mass(context)
    g = plant.gravity_field().gravity_vector()
    X_WM = model.ft_measurement_frame.CalcPoseInWorld(context)
    R_MW = X_WM.rotation().inverse()
    # Equilibrium of the tool: weld force + weight = 0, and the weld's
    # moment about the measurement point cancels that of the weight.
    force_W = -mass * g
    p_WCom = tool.EvalPoseInWorld(context).multiply(
        tool.CalcCenterOfMassInBodyFrame(context))
    moment_W = np.cross(p_WCom - X_WM.translation(), force_W)
    np.testing.assert_allclose(wrench.translational(), R_MW @ force_W,
                               atol=1e-6)
    np.testing.assert_allclose(wrench.rotational(), R_MW @ moment_W,
                               atol=1e-6)
    assert np.linalg.norm(wrench.translational()) == pytest.approx(
        0.40 * 9.81, rel=1e-3)


@pytest.fixture(scope="module")
def ur():
    """The third shipped robot's plant: the UR5e-class arm."""
    return make_robot_plant(load_robot_description(
        models_dir() / "ur_omni.robot.yaml"))


# The maker's base frame (DH frame 0) in the UR arm's T_a: turned by pi
# about z (ur5e.sdf).
X_A0 = np.diag([-1.0, -1.0, 1.0, 1.0])


def test_the_ur_arm_is_its_makers_dh_table(ur):
    """The UR5e-class arm's model (frames placed by hand in ur5e.sdf) is
    the maker's published DH table: the flange is DH frame 6 at random
    configurations over the joints' +-2 pi, and each link's mass and
    centre of mass are the published ones in its DH frame (link 6 with
    the flange's plate beyond the wrist's sensor)."""
    plant, model = ur
    arm = model.arm_joints
    bodies = [[j.child_body()] for j in arm]
    bodies[-1].append(model.ft_sensor_joint.child_body())
    rng = np.random.default_rng(5)
    for _ in range(20):
        q = rng.uniform(-2.0 * np.pi, 2.0 * np.pi, 6)
        context = _arm_context(plant, model, q)
        X_A6 = model.flange_frame.CalcPose(context, model.arm_base_frame)
        frames = [X_A0 @ T for T in dh_frames(UR5E_DH, q)]
        np.testing.assert_allclose(X_A6.GetAsMatrix4(), frames[-1],
                                   atol=1e-12)
        X_AW = model.arm_base_frame.CalcPoseInWorld(context).inverse()
        for link, mass, centre, T in zip(bodies, UR5E_MASSES,
                                         UR5E_CENTRES_OF_MASS, frames,
                                         strict=True):
            masses = [b.get_mass(context) for b in link]
            weighted = sum(m * (X_AW @ b.EvalPoseInWorld(context)).multiply(
                b.CalcCenterOfMassInBodyFrame(context))
                for m, b in zip(masses, link, strict=True))
            assert sum(masses) == pytest.approx(mass, abs=1e-12)
            np.testing.assert_allclose(weighted / sum(masses),
                                       T[:3, :3] @ centre + T[:3, 3],
                                       atol=1e-6)


def test_the_ur_arm_has_its_makers_limits(ur):
    """+-2 pi (the model's, as published; the description holds the
    elbow to +-pi, where the upper arm stops it) and 180 degrees/s on
    every joint, the maker's maximum joint torques (150 N m on the three
    large joints, 28 N m on the wrist's) and the 10 rad/s^2 estimate;
    the arm weighs the published 20.6 kg."""
    plant, model = ur
    arm = ArmKinematics(plant, model)
    for joint in model.arm_joints:
        assert joint.position_upper_limits()[0] == 2.0 * np.pi
        assert joint.position_lower_limits()[0] == -2.0 * np.pi
    np.testing.assert_array_equal(
        arm.upper, [2.0 * np.pi, 2.0 * np.pi, np.pi] + [2.0 * np.pi] * 3)
    np.testing.assert_array_equal(arm.lower, -arm.upper)
    np.testing.assert_array_equal(arm.velocity_limits, np.full(6, np.pi))
    np.testing.assert_array_equal(arm.acceleration_limits, np.full(6, 10.0))
    efforts = [plant.get_joint_actuator(i).effort_limit()
               for i in plant.GetJointActuatorIndices()
               if plant.get_joint_actuator(i).joint() in model.arm_joints]
    assert efforts == [150.0, 150.0, 150.0, 28.0, 28.0, 28.0]
    context = plant.CreateDefaultContext()
    instance = model.arm_joints[0].model_instance()
    assert sum(plant.get_body(i).get_mass(context)
               for i in plant.GetBodyIndices(instance)) == pytest.approx(20.6)


@pytest.fixture(scope="module")
def shipped_arm():
    return ArmKinematics()


def random_configurations(arm, count, seed):
    rng = np.random.default_rng(seed)
    middle, half = 0.5 * (arm.lower + arm.upper), 0.45 * (arm.upper - arm.lower)
    return [rng.uniform(middle - half, middle + half) for _ in range(count)]


def test_kinematics_values_are_the_callers_own(shipped_arm):
    """Each evaluate gives arrays of the caller's own: writing into one
    changes no later answer."""
    arm = shipped_arm
    for q in random_configurations(arm, 3, 9) * 2:
        a = arm.evaluate(q)
        b = arm.evaluate(q)
        np.testing.assert_array_equal(a.J_a, b.J_a)
        np.testing.assert_array_equal(a.p_ee_in_base, b.p_ee_in_base)
        np.testing.assert_array_equal(a.pose, b.pose)
        for array in (a.J_a, a.p_ee_in_base, a.pose):
            array[...] = np.nan
        assert np.isfinite(arm.evaluate(q).J_a).all()


def _context_at(shipped_arm, q_a):
    context = shipped_arm.plant.CreateDefaultContext()
    q = shipped_arm.plant.GetPositions(context)
    q[shipped_arm._q_indices] = q_a
    shipped_arm.plant.SetPositions(context, q)
    return context


def test_p_ee_from_the_pose_matches_the_plant(shipped_arm):
    for q in random_configurations(shipped_arm, 10, 10):
        context = _context_at(shipped_arm, q)
        expected = shipped_arm.plant.CalcPointsPositions(
            context, shipped_arm.model.tcp_frame, np.zeros(3),
            shipped_arm.model.base_frame).ravel()
        p_ee = shipped_arm.evaluate(q).p_ee_in_base
        assert np.max(np.abs(p_ee - expected)) < 1e-15



def test_origin_in_sums_each_entry_in_pythons_order():
    """drake_wbc.math.chain.origin_in: R_BA p_AE + p_BA, each entry summed
    as Python sums it (bit for bit), and R_BA @ p_AE + p_BA to
    rounding."""
    from drake_wbc.math.chain import origin_in

    rng = np.random.default_rng(7)
    for _ in range(200):
        R_BA, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        p_BA = rng.uniform(-1.0, 1.0, 3)
        X_AE = np.eye(4)
        X_AE[:3, 3] = rng.uniform(-1.0, 1.0, 3)
        x, y, z = X_AE[:3, 3].tolist()
        by_hand = [((R[0] * x + R[1] * y) + R[2] * z) + p
                   for R, p in zip(R_BA.tolist(), p_BA.tolist(), strict=True)]
        p_BE = origin_in(R_BA, p_BA, X_AE)
        assert p_BE.tolist() == by_hand
        np.testing.assert_allclose(p_BE, R_BA @ X_AE[:3, 3] + p_BA,
                                   rtol=0.0, atol=1e-15)

def _rz(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


@pytest.mark.parametrize("yaw, tilt", [(0.5 * np.pi, 0.0), (-0.4, 0.35),
                                       (np.pi, -0.5 * np.pi)])
def test_an_arm_mount_turns_the_arm_about_the_mount_point(robot, yaw, tilt):
    """ArmMount(yaw, tilt): ^bR_a = Rz(yaw) Ry(tilt), read back from the
    plant by ArmKinematics (R_ba), and every point of the arm turned by it
    about the arm base's origin, which stays where it was; the arm's own
    kinematics in T_a are unchanged."""
    mount = ArmMount(yaw=yaw, tilt=tilt)
    arm = ArmKinematics(mount=mount)
    shipped = ArmKinematics(*robot)
    R = _rz(yaw) @ _ry(tilt)
    np.testing.assert_allclose(arm.R_ba, R, rtol=0, atol=1e-15)
    np.testing.assert_allclose(mount.rotation(), R, rtol=0, atol=1e-15)
    assert arm.mount == mount and arm.model.mount == mount
    rng = np.random.default_rng(40)
    origin = shipped.evaluate(np.zeros(6)).p_ee_in_base - (
        shipped.evaluate(np.zeros(6)).X_AE.translation())
    for q in rng.uniform(arm.lower, arm.upper, (5, 6)):
        mounted, plain = arm.evaluate(q), shipped.evaluate(q)
        np.testing.assert_allclose(mounted.J_a, plain.J_a, atol=1e-12)
        np.testing.assert_allclose(mounted.p_ee_in_base,
                                   origin + R @ plain.X_AE.translation(),
                                   atol=1e-12)


def test_an_arm_mount_keeps_the_offset_the_model_welds_the_arm_at(tmp_path):
    """A robot whose model directives weld the arm at an offset from the
    weld's parent frame (X_PC's translation): an ArmMount turns the arm
    about that point, which stays where the model has it, rather than
    moving the arm to the parent frame's origin."""
    from drake_wbc.robot.description import (
        load_robot_description,
        models_dir,
    )
    from drake_wbc.stages.support import arm_mounting

    offset = [0.1, 0.05, 0.02]
    (tmp_path / "offset.dmd.yaml").write_text(
        (models_dir() / "mcr.dmd.yaml").read_text().replace(
            "child: elfin5::base_link\n",
            "child: elfin5::base_link\n    X_PC:\n"
            f"      translation: {offset}\n", 1))
    (tmp_path / "offset.robot.yaml").write_text(
        (models_dir() / "mcr.robot.yaml").read_text().replace(
            "package://drake_wbc/mcr.dmd.yaml", "offset.dmd.yaml").replace(
            "  packages:\n    drake_wbc: .\n", ""))
    robot = load_robot_description(tmp_path / "offset.robot.yaml")
    plain = ArmKinematics(*make_robot_plant(robot))
    mount = ArmMount(yaw=0.5, tilt=0.2)
    turned = ArmKinematics(*make_robot_plant(robot, mount=mount))
    shipped = ArmKinematics(*make_robot_plant())
    origin = {name: arm_mounting(arm)[1] for name, arm in (
        ("plain", plain), ("turned", turned), ("shipped", shipped))}
    np.testing.assert_allclose(origin["plain"], origin["shipped"] + offset,
                               atol=1e-12)
    np.testing.assert_allclose(origin["turned"], origin["plain"], atol=1e-12)
    np.testing.assert_allclose(turned.R_ba, mount.rotation(), atol=1e-12)


def test_the_shipped_mount_is_the_identity(robot):
    plant, model = robot
    assert model.mount == ArmMount() and model.mount.is_identity
    np.testing.assert_array_equal(ArmKinematics(*robot).R_ba, np.eye(3))


@pytest.mark.parametrize("field, value", [("yaw", 3.2), ("tilt", -1.6),
                                          ("yaw", np.nan)])
def test_a_bad_arm_mount_is_refused_naming_its_field(field, value):
    with pytest.raises(ValueError, match=field):
        ArmMount(**{field: value})


def test_a_given_plant_carries_its_own_mount(robot):
    with pytest.raises(ValueError, match="mount"):
        ArmKinematics(*robot, mount=ArmMount(yaw=1.0))


def _omni_arm_plant(folder, n):
    from omni_arm import write_omni_arm

    from drake_wbc.robot.description import load_robot_description
    return make_robot_plant(load_robot_description(write_omni_arm(folder,
                                                                  n)))


def _chain_robots(folder):
    """(name, plant, model) of the three shipped robots and the 6- and
    7-joint omni arm of tests/omni_arm.py."""
    from drake_wbc.robot.description import (
        load_robot_description,
        models_dir,
    )
    robots = [(name, *make_robot_plant(load_robot_description(
        models_dir() / f"{name}.robot.yaml")))
        for name in ("mcr", "lbr_omni", "ur_omni")]
    for n in (6, 7):
        (folder / str(n)).mkdir()
        robots.append((f"omni_arm_{n}", *_omni_arm_plant(folder / str(n),
                                                          n)))
    return robots


def test_the_compiled_chain_gives_the_plants_kinematics(tmp_path):
    """J_a, p_ee and X_AE by the compiled chain (drake_wbc.math.chain)
    equal the plant's own at random configurations, over and beyond the
    joints' ranges, for every robot at hand."""
    rng = np.random.default_rng(20261202)
    for name, plant, model in _chain_robots(tmp_path):
        arm = ArmKinematics(plant, model)
        assert arm.chain is not None, name
        for _ in range(100):
            q = rng.uniform(arm.lower - 1.0, arm.upper + 1.0)
            chain, reference = arm.evaluate(q), arm.plant_values(q)
            for a, b in ((chain.J_a, reference.J_a),
                         (chain.p_ee_in_base, reference.p_ee_in_base),
                         (chain.pose, reference.pose)):
                np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12,
                                           err_msg=name)


def test_a_chain_with_prismatic_joints_gives_the_plants_kinematics(
        tmp_path):
    """The omni arm's base (two prismatic joints and a revolute one) and
    its arm, world to TCP, as one chain of n + 3 joints: its Jacobian and
    pose equal the plant's."""
    from pydrake.multibody.tree import JacobianWrtVariable

    from drake_wbc.math.chain import chain_kinematics_float
    from drake_wbc.robot.model import serial_chain
    plant, model = _omni_arm_plant(tmp_path, 7)
    joints = model.base_joints + model.arm_joints
    context = plant.CreateDefaultContext()
    world, tcp = plant.world_frame(), model.tcp_frame
    chain = serial_chain(plant, context, world, tcp, joints)
    assert chain is not None and list(chain.revolute) == [0, 0] + [1] * 8
    columns = joint_position_indices(joints)
    rng = np.random.default_rng(3)
    for _ in range(50):
        q = rng.uniform(-3.0, 3.0, len(joints))
        positions = plant.GetPositions(context)
        positions[columns] = q
        plant.SetPositions(context, positions)
        J = plant.CalcJacobianSpatialVelocity(
            context, JacobianWrtVariable.kV, tcp, np.zeros(3), world, world)
        J_chain, X = chain_kinematics_float(*chain, q)
        np.testing.assert_allclose(J_chain, J[[3, 4, 5, 0, 1, 2]][:, columns],
                                   rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(
            X, tcp.CalcPoseInWorld(context).GetAsMatrix4(), rtol=0.0,
            atol=1e-12)


def test_an_end_effector_inboard_of_the_wrist_is_left_to_the_plant(robot):
    plant, model = robot
    frame = model.arm_joints[3].child_body().body_frame()
    arm = ArmKinematics(plant, model, end_effector_frame=frame)
    assert arm.chain is None
    q = HOME_ARM_POSITIONS + 0.2
    values = arm.evaluate(q)
    np.testing.assert_array_equal(values.J_a[:, 4:], 0.0)
    np.testing.assert_array_equal(values.pose, arm.plant_values(q).pose)


def test_frame_matrix_gives_the_plants_pose_of_any_frame(robot):
    """The compiled chain to the wrist sensor's frame and to the flange,
    and the plant for a frame inboard of the wrist, all equal to
    frame_pose."""
    plant, model = robot
    arm = ArmKinematics(plant, model)
    rng = np.random.default_rng(11)
    frames = (model.ft_measurement_frame, model.flange_frame,
              model.arm_joints[2].child_body().body_frame())
    for _ in range(50):
        q = rng.uniform(arm.lower, arm.upper)
        for frame in frames:
            np.testing.assert_allclose(
                arm.frame_matrix(q, frame),
                arm.frame_pose(q, frame).GetAsMatrix4(), rtol=0.0,
                atol=1e-12)
    assert arm._frame_chains[frames[0].index()]
    assert arm._frame_chains[frames[2].index()] == ()


def test_the_shared_plant_is_made_once_per_description_and_mount():
    """shared_robot_plant parses a robot once per description (by its
    contents) and mount; make_robot_plant makes a plant of one's own."""
    plant, model = shared_robot_plant()
    assert shared_robot_plant(shipped_robot())[0] is plant
    assert ArmKinematics().plant is plant
    assert make_robot_plant()[0] is not plant
    turned = ArmMount(yaw=0.3)
    assert shared_robot_plant(mount=turned)[0] is not plant
    assert shared_robot_plant(mount=ArmMount(yaw=0.3))[0] is (
        shared_robot_plant(mount=turned)[0])
    other = shipped_robot()
    other.base.velocity_lag = 0.25
    assert shared_robot_plant(other)[0] is not plant
    # The same kinematics as a plant of one's own.
    q = HOME_ARM_POSITIONS + 0.1
    ours, theirs = ArmKinematics(), ArmKinematics(*make_robot_plant())
    np.testing.assert_array_equal(ours.evaluate(q).J_a,
                                  theirs.evaluate(q).J_a)


BUILT_UNDER_TRACEMALLOC = """
import tracemalloc
tracemalloc.start(10)
from pydrake.lcm import DrakeLcm
from drake_wbc.deployment.deploy import deploy
from drake_wbc.experiments.scenario import find_scenario, load_scenario
print(deploy(load_scenario(find_scenario("hardware")), lcm=DrakeLcm("memq://"),
             stop=lambda: True))
"""
"""A deployment built with Python's allocations traced (another heap):
it stops at once, before the robot answers (None)."""


def test_the_lidar_check_reads_no_freed_memory():
    """The LIDARs' level check read each frame's z axis through
    RotationMatrix.col of a pose already freed: built under tracemalloc,
    whose heap reuses that memory at once, the shipped robot was refused
    with an axis of [0, 1.7e178, 0]."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", BUILT_UNDER_TRACEMALLOC],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "None"

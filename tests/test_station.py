"""The simulated station as the controller sees it: its ports, a start
in static equilibrium, the base's and the arm's responses to commands,
and what the ground truth, the LIDARs and the wrist sensor report."""

import numpy as np
import pytest
from locked_robot import sensor_reading, settle_locked_robot
from omni_arm import write_omni_arm
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.tree import ForceElementIndex, RevoluteSpring
from pydrake.systems.analysis import Simulator
from pydrake.systems.primitives import MatrixGain
from shipped_names import ARM_JOINTS, BASE_JOINTS, MOUNT_JOINTS, SCOPED

from drake_wbc.hardware.options import HardwareOptions
from drake_wbc.hardware.safety import Limits, follow_arm_command
from drake_wbc.robot.description import load_robot_description
from drake_wbc.robot.model import ArmKinematics
from drake_wbc.station.force_torque import ForceTorqueSensorParameters
from drake_wbc.station.scene import (
    BoxObstacle,
    CylinderObstacle,
    Scene,
    WalkingPerson,
    person_positions,
)
from drake_wbc.station.simulation import SimulatedStation, StationOptions
from drake_wbc.station.state_sensors import (
    BaseOdometry,
    base_state_selection,
    odometry_system,
)

PILLAR = CylinderObstacle(name="pillar", position=[1.5, -1.2], radius=0.2,
                          height=2.0)
WALL = BoxObstacle(name="wall", center=[0.0, -3.0, 1.0],
                   size=[6.0, 0.1, 2.0])
PERSON = WalkingPerson(name="alice", radius=0.25, times=[0.0, 20.0],
                       waypoints=[[-1.5, 1.0], [-1.5, 3.0]])
SCENE = Scene(cylinders=[PILLAR], boxes=[WALL], people=[PERSON])
"""Away from every path the base takes below; all seen by the LIDARs."""

FOOTPRINT_HALF = np.array([0.4, 0.3])  # the base's 0.8 x 0.6 m, in T_b

VECTOR_INPUTS = {"base.velocity_command": 3, "arm.position_command": 6}
VECTOR_OUTPUTS = {
    "base.state_estimated": 6,
    "arm.position_measured": 6,
    "arm.velocity_estimated": 6,
    "arm.fault": 1,
    "wrist.wrench_measured": 6,
    "lidar.front_left.ranges": 811,
    "lidar.rear_right.ranges": 811,
    "truth.end_effector_pose": 6,
    "truth.end_effector_velocity": 6,
    "truth.base_pose": 3,
    "truth.base_loop_velocity": 3,
    "truth.mount_angles": 2,
    "truth.wrist_wrench": 6,
    "truth.hand_force": 6,
    "truth.people_positions": 2,
}
ABSTRACT_OUTPUTS = {"lidar.obstacle_points", "query_object"}

REVOLUTE_JOINTS = ("base_yaw", *MOUNT_JOINTS, *ARM_JOINTS)


@pytest.fixture(scope="module", params=[0.001, 0.005],
                ids=["1ms", "5ms"])
def station(request):
    """The station at the default plant step and at the scenarios'."""
    return SimulatedStation(
        StationOptions(time_step=request.param,
                       wrist=ForceTorqueSensorParameters.ideal()), SCENE)


class Run:
    """A simulation of the station from its initial state, the base at
    `base_pose`, holding the arm at its initial command and the base at
    rest until told otherwise."""

    def __init__(self, station, base_pose=(0.0, 0.0, 0.0)):
        self.station = station
        self.diagram = station.diagram
        self.simulator = Simulator(self.diagram)
        self.context = self.simulator.get_mutable_context()
        station.set_initial_state(self.context)
        plant = station.plant
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)
        x, y, yaw = base_pose
        base = [plant.GetJointByName(n, station.model.base)
                for n in BASE_JOINTS]
        base[0].set_translation(self.plant_context, x)
        base[1].set_translation(self.plant_context, y)
        base[2].set_angle(self.plant_context, yaw)
        self.q_cmd = np.array(station.options.initial_arm_positions)
        self.command(arm=self.q_cmd, base=np.zeros(3))
        self.simulator.Initialize()
        self.sent = (self.q_cmd, np.zeros(self.q_cmd.size))
        self.next_sample = 0  # of the arm's servo (move_arm)

    def move_arm(self, target, until):
        """Sends the arm towards `target` until `until` s, a command at
        each of its servo's samples, each within the arm's own limits
        (the robot side's limiter, follow_arm_command), which its servo
        takes without a fault."""
        h = self.station.options.arm.command_period
        limits = Limits.of_robot(HardwareOptions(), ArmKinematics(
            self.station.plant, self.station.model))
        target = np.asarray(target, dtype=float)
        k = self.next_sample
        while k * h <= until + 1e-12:
            # The Simulator takes the sample at k h at the start of its
            # next AdvanceTo from k h: the command fixed at k h is the one
            # it reads.
            if k * h > self.context.get_time():
                self.advance(k * h)
            q, v, _ = follow_arm_command(target, np.zeros(target.size),
                                         *self.sent, h, limits)
            self.command(arm=q)
            self.sent = (q, v)
            k += 1
        self.next_sample = k
        self.advance(until)

    def command(self, arm=None, base=None):
        if arm is not None:
            self.diagram.GetInputPort("arm.position_command").FixValue(
                self.context, np.asarray(arm, dtype=float))
        if base is not None:
            self.diagram.GetInputPort("base.velocity_command").FixValue(
                self.context, np.asarray(base, dtype=float))

    def __getitem__(self, name):
        value = self.diagram.GetOutputPort(name).Eval(self.context)
        return value.copy() if isinstance(value, np.ndarray) else value

    def advance(self, t):
        self.simulator.AdvanceTo(t)

    def velocities(self, names):
        v = self.station.plant.GetVelocities(self.plant_context)
        return np.array([v[self.station.plant.GetJointByName(n)
                           .velocity_start()] for n in names])

    def distances_to_joints(self, point_W, names):
        """|point - o_j| for the child frame origins o_j (on the axes) of
        the joints `names`."""
        plant = self.station.plant
        return np.array([np.linalg.norm(point_W - plant.GetJointByName(n)
                                        .frame_on_child().CalcPoseInWorld(
                                            self.plant_context).translation())
                         for n in names])


REST_POSE = (0.3, -0.2, 0.4)
REST_DURATION = 0.5


@pytest.fixture(scope="module")
def rest(station):
    """0.5 s with the commands equal to the initial state, the base at
    REST_POSE; the extremes of the mount's and the arm's motion."""
    run = Run(station, REST_POSE)
    run.start = {name: run[name] for name in (
        "truth.mount_angles", "arm.position_measured",
        "truth.end_effector_pose", "truth.base_pose")}
    run.start["plant_positions"] = station.plant.GetPositions(
        run.plant_context).copy()
    run.mount_motion = run.arm_motion = 0.0
    for t in np.arange(1, 51) * REST_DURATION / 50:
        run.advance(t)
        run.mount_motion = max(run.mount_motion, np.max(np.abs(
            run["truth.mount_angles"] - run.start["truth.mount_angles"])))
        run.arm_motion = max(run.arm_motion, np.max(np.abs(
            run["arm.position_measured"]
            - run.start["arm.position_measured"])))
    return run


def test_ports_are_the_documented_ones(station):
    diagram = station.diagram
    inputs = {diagram.get_input_port(i).get_name(): diagram.get_input_port(i)
              for i in range(diagram.num_input_ports())}
    outputs = {diagram.get_output_port(i).get_name():
               diagram.get_output_port(i)
               for i in range(diagram.num_output_ports())}
    assert set(inputs) == set(VECTOR_INPUTS)
    assert set(outputs) == set(VECTOR_OUTPUTS) | ABSTRACT_OUTPUTS
    for ports, sizes in ((inputs, VECTOR_INPUTS), (outputs, VECTOR_OUTPUTS)):
        for name, size in sizes.items():
            assert ports[name].size() == size, name
    for name in ABSTRACT_OUTPUTS:
        assert outputs[name].get_data_type().name == "kAbstractValued"
    # The controller closes the loop through the station: no input may
    # reach an output in the same instant.
    assert not diagram.HasAnyDirectFeedthrough()


def test_initial_state_is_a_static_equilibrium(station, rest):
    plant = station.plant
    # The start is not the nominal pose: the mount sags and the arm
    # droops under gravity, by far more than the bound below, so a start
    # out of equilibrium would swing by about that much.
    sag = rest.start["truth.mount_angles"]
    droop = rest.start["arm.position_measured"] - rest.q_cmd
    assert np.max(np.abs(sag)) > 1e-3
    assert np.max(np.abs(droop)) > 1e-4
    # 1e-6 rad: a thousandth of the sag, two orders above the SAP
    # solver's resolution at rest (a 1e-8 rad offset is left alone).
    assert rest.mount_motion < 1e-6
    assert rest.arm_motion < 1e-6
    # And the balance itself: gravity, the mount's springs and the arm's
    # servo (p (q_cmd - q), at rest) sum to zero on every joint.
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, rest.start["plant_positions"])
    tau_g = plant.CalcGravityGeneralizedForces(context)
    springs = {}
    for i in range(plant.num_force_elements()):
        element = plant.get_force_element(ForceElementIndex(i))
        if isinstance(element, RevoluteSpring):
            springs[element.joint().name()] = element.default_stiffness()
    gains = station._gains
    for name in (*MOUNT_JOINTS, *ARM_JOINTS):
        joint = plant.GetJointByName(name)
        q = joint.get_angle(context)
        if name in MOUNT_JOINTS:
            restoring = -springs[name] * q
        else:
            q_cmd = rest.q_cmd[ARM_JOINTS.index(name)]
            restoring = gains[SCOPED[name]].p * (q_cmd - q)
        residual = tau_g[joint.velocity_start()] + restoring
        assert abs(residual) < 1e-6, name


def test_every_arm_servo_has_the_servo_frequency(station):
    """The drives' reflected inertia tops each arm joint's inertia up to
    the one its gains were sized for: p / M_ii = (2 pi f)^2 on every
    joint, the light wrist joints included (M_ii of the plant without
    the drives: down to 1e-3 kg m^2)."""
    plant, arm = station.plant, station.options.arm
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, station.model.arm,
                       station.options.initial_arm_positions)
    M = plant.CalcMassMatrix(context)
    w = 2.0 * np.pi * arm.servo_frequency
    for name in ARM_JOINTS:
        i = plant.GetJointByName(name).velocity_start()
        assert M[i, i] >= arm.min_inertia - 1e-12, name
        assert station._gains[SCOPED[name]].p / M[i, i] == pytest.approx(
            w * w, rel=1e-9), name


def test_base_moves_along_its_heading_with_the_first_order_lag(station):
    yaw, u, h = 0.5, 0.2, station.options.time_step
    lag = station.options.base.lag
    run = Run(station, (0.0, 0.0, yaw))
    run.command(base=[u, 0.0, 0.0])
    start = run["truth.base_pose"]
    loop, state = [], []
    steps = 1500
    for n in range(1, steps + 1):
        run.advance(n * h)
        loop.append(run["truth.base_loop_velocity"])
        state.append(run["base.state_estimated"])
    loop, state = np.array(loop), np.array(state)
    # The loop's velocity is the sampled lag (u below the acceleration
    # limit: the first step (1 - e^(-h/lag)) u < a_max h).
    assert (1.0 - np.exp(-h / lag)) * u < 1.0 * h
    n = np.arange(1, steps + 1)
    np.testing.assert_allclose(loop[:, 0], u * (1.0 - np.exp(-n * h / lag)),
                               atol=1e-14)
    np.testing.assert_array_equal(loop[:, 1:], 0.0)
    # The base goes where T_b's x axis points, and does not turn.
    end = run["truth.base_pose"]
    np.testing.assert_allclose(state[-1, :3], end, atol=1e-15)
    displacement = end[:2] - start[:2]
    assert np.arctan2(displacement[1], displacement[0]) == pytest.approx(
        yaw, abs=1e-6)
    assert end[2] == pytest.approx(yaw, abs=1e-6)
    # Distance: the lag's integral, less the wheel servo's delay of
    # tau_s u and half a step of the sampled loop (h u / 2); 0.1 mm
    # allows for the servo's transient.
    T, tau_s = steps * h, station.options.base.servo_time_constant
    travelled = u * (T - lag * (1.0 - np.exp(-T / lag))) - u * (
        tau_s + h / 2)
    assert np.linalg.norm(displacement) == pytest.approx(travelled,
                                                         abs=1e-4)
    # After 7.5 lags the measured body-frame twist is the command, less
    # the lag's remainder u e^(-T/lag) (5e-5 for the servo's delay and
    # the mount's rocking).
    np.testing.assert_allclose(state[-1, 3:], [u, 0.0, 0.0],
                               atol=u * np.exp(-T / lag) + 5e-5)
    # Early on (0.3 s) the wheels follow the loop within the servo's
    # delay and the plant's step (the plant reads the loop's last
    # output), tau_s + h, times the loop's largest acceleration u / lag.
    early = n * h <= 0.3 + 1e-9
    np.testing.assert_allclose(state[early, 3], loop[early, 0],
                               atol=(tau_s + h) * u / lag)


def test_a_large_command_saturates_at_the_velocity_limit(station):
    run = Run(station)
    run.command(base=[3.0, 0.0, 0.0])
    h, lag = station.options.time_step, station.options.base.lag
    limit = station.options.base.velocity_limits[0]
    a_max = station.options.base.acceleration_limits[0]
    gain, ramp = 1.0 - np.exp(-h / lag), a_max * h
    n_switch = int(np.ceil((limit - ramp / gain) / ramp))
    measured = []
    for k in range(1, 201):
        n = 10 * k
        run.advance(n * h)
        measured.append(run["base.state_estimated"][3])
        # Closed form of the saturated loop: a ramp at a_max, then the
        # lag towards the limit (not towards the 3 m/s command).
        expected = (n * ramp if n <= n_switch else limit - (
            limit - n_switch * ramp) * (1.0 - gain) ** (n - n_switch))
        assert run["truth.base_loop_velocity"][0] == pytest.approx(
            expected, abs=1e-12)
    measured = np.array(measured)
    # The wheel servo, coupled to the mount's rocking, may pass the limit
    # by a few 1e-7 m/s at the coarser step.
    assert np.all(measured <= limit + 1e-6)
    assert measured[-1] == pytest.approx(limit, abs=1e-3)


def test_the_base_loop_is_the_robots_own_where_the_options_give_none():
    """The second shipped robot's simulated base is held to that base's
    own limits (0.8 m/s, 0.5 m/s^2; the shipped base's are 1 and 1): a
    3 m/s command ramps at 0.5 m/s^2 and levels off at 0.8 m/s. A robot
    whose velocity_lag bound is below the typical 0.2 s gets that lag,
    one the loop cannot take (0 s) is refused naming the field, and a loop the
    options give is kept."""
    from dataclasses import replace

    from drake_wbc.robot.description import (
        load_robot_description,
        models_dir,
    )
    from drake_wbc.station.drivers import BaseDriverParameters, own_base_loop

    lbr = load_robot_description(models_dir() / "lbr_omni.robot.yaml")
    station = SimulatedStation(StationOptions(time_step=0.005), robot=lbr)
    base = station.options.base
    assert base.velocity_limits == list(lbr.base.velocity_limits)
    assert base.acceleration_limits == list(lbr.base.acceleration_limits)
    assert base.lag == 0.2 and base.damping_ratio is None
    run = Run(station)
    run.command(base=[3.0, 0.0, 0.0])
    run.advance(0.5)
    assert run["truth.base_loop_velocity"][0] == pytest.approx(0.25,
                                                               abs=1e-9)
    run.advance(6.0)
    assert run["truth.base_loop_velocity"][0] == pytest.approx(0.8,
                                                               abs=1e-6)
    assert own_base_loop(replace(lbr.base, velocity_lag=0.1)).lag == 0.1
    with pytest.raises(ValueError, match="base.velocity_lag = 0.0 s"):
        own_base_loop(replace(lbr.base, velocity_lag=0.0))
    given = BaseDriverParameters(loop="ringing")
    kept = SimulatedStation(StationOptions(time_step=0.001, base=given),
                            robot=lbr).options.base
    assert kept == given


def test_a_robot_with_a_fast_base_loop_is_simulated_at_its_own_lag():
    """A described velocity_lag of 15 ms (a stiff hub-motor loop, as the
    "jerky" loop's 20 ms) is the simulated loop's own, its wheel servo
    under it faster still: the loop's first-order response to a small
    step (within the acceleration limit) reaches 1 - exp(-1) of it after
    one lag, as the continuous loop does (h / lag = 1 / 15)."""
    from dataclasses import replace

    from drake_wbc.robot.description import (
        load_robot_description,
        models_dir,
    )

    lbr = load_robot_description(models_dir() / "lbr_omni.robot.yaml")
    fast = replace(lbr, base=replace(lbr.base, velocity_lag=0.015))
    station = SimulatedStation(StationOptions(time_step=0.001), robot=fast)
    loop = station.options.base
    assert loop.lag == 0.015
    assert loop.servo_time_constant < 0.5 * loop.lag
    step = 0.005  # m/s: step / lag = 0.33 m/s^2, below the 0.5 allowed.
    run = Run(station)
    run.command(base=[step, 0.0, 0.0])
    run.advance(loop.lag)
    assert run["truth.base_loop_velocity"][0] == pytest.approx(
        step * (1.0 - np.exp(-1.0)), rel=0.05)


def test_an_arm_move_is_tracked_within_a_milliradian(station):
    """A move of 0.05 rad, sent within the arm's limits (its servo
    refuses a step: tests/test_arm_fault.py), takes 0.13 s."""
    run = Run(station)
    start = run["arm.position_measured"]
    step = np.array([0.05, 0.0, 0.0, 0.0, 0.0, 0.0])
    run.move_arm(run.q_cmd + step, 0.3)
    assert run["arm.fault"][0] == 0.0
    measured = run["arm.position_measured"]
    assert abs(measured[0] - (run.q_cmd[0] + step[0])) < 1e-3
    # The other joints stay where gravity left them.
    np.testing.assert_allclose(measured[1:], start[1:], atol=1e-3)


def test_end_effector_starts_at_the_nominal_tcp_within_the_sag(rest):
    q_cmd = rest.q_cmd
    values = ArmKinematics().evaluate(q_cmd)
    x, y, yaw = REST_POSE
    X_WB = RigidTransform(RotationMatrix.MakeZRotation(yaw), [x, y, 0.0])
    p_nominal = X_WB @ values.p_ee_in_base
    R_nominal = X_WB.rotation() @ RotationMatrix(
        ArmKinematics().R_ba) @ values.X_AE.rotation()
    pose = rest.start["truth.end_effector_pose"]
    R_truth = RotationMatrix(RollPitchYaw(pose[3:]))
    # Small rotations theta_j about the mount's and the arm's axes move
    # the tool centre point by at most sum |theta_j| r_j, r_j its distance
    # from axis j (below r_max, the farthest joint origin, plus 1 cm for
    # the moved configuration), and turn it by at most sum |theta_j|.
    angles = np.concatenate([
        rest.start["truth.mount_angles"],
        rest.start["arm.position_measured"] - q_cmd])
    r_max = np.max(rest.distances_to_joints(
        pose[:3], (*MOUNT_JOINTS, *ARM_JOINTS))) + 0.01
    offset = np.linalg.norm(pose[:3] - p_nominal)
    assert offset < np.sum(np.abs(angles)) * r_max
    assert offset > 1e-4  # the sag shows
    turn = (R_nominal.inverse() @ R_truth).ToAngleAxis().angle()
    assert turn < np.sum(np.abs(angles)) + 1e-12


def test_end_effector_velocity_is_the_derivative_of_its_position(station):
    h = station.options.time_step
    run = Run(station, (0.0, 0.0, -0.7))
    run.command(base=[0.2, -0.1, 0.3])
    r_max = np.max(run.distances_to_joints(
        run["truth.end_effector_pose"][:3], REVOLUTE_JOINTS)) + 0.1
    positions, velocities, bounds = [], [], []
    for n in range(1, 401):
        run.advance(n * h)
        positions.append(run["truth.end_effector_pose"][:3])
        velocities.append(run["truth.end_effector_velocity"][:3])
        rate = np.sum(np.abs(run.velocities(REVOLUTE_JOINTS)))
        bounds.append(0.5 * h * rate**2 * r_max)
    positions, velocities = np.array(positions), np.array(velocities)
    # The plant steps q+ = q + h v+, so the backward difference of the
    # position over a step is the velocity at its end, V = J(q+) v+, less
    # (h / 2) Jdot v+, the point's acceleration at constant joint rates:
    # at most (sum of the revolute joints' rates)^2 r_max (the base's
    # prismatic joints have fixed axes and add nothing).
    difference = np.diff(positions, axis=0) / h
    errors = np.linalg.norm(difference - velocities[1:], axis=1)
    assert np.all(errors <= np.array(bounds[1:]) + 1e-9)
    assert np.max(np.linalg.norm(velocities, axis=1)) > 0.1


def test_the_ground_truth_is_the_plants_own_tool_motion(station):
    """truth.end_effector_* equal the tool body's pose and velocity from
    the plant's own output ports (in the station's context), shifted to
    the tool centre point, while the robot moves."""
    run = Run(station, (0.4, -0.3, 0.9))
    run.command(base=[0.3, 0.2, -0.4])
    plant, model = station.plant, station.model
    tool = model.tcp_frame.body()
    X_tool_tcp = model.tcp_frame.GetFixedPoseInBodyFrame()
    for t in (0.05, 0.2):
        run.move_arm(run.q_cmd + 0.2, t)
        assert np.all(np.abs(run["arm.velocity_estimated"]) > 0.1)
        X_W_tool = plant.get_body_poses_output_port().Eval(
            run.plant_context)[int(tool.index())]
        V_W_tool = plant.get_body_spatial_velocities_output_port().Eval(
            run.plant_context)[int(tool.index())]
        X_W_tcp = X_W_tool @ X_tool_tcp
        V_W_tcp = V_W_tool.Shift(
            X_W_tool.rotation() @ X_tool_tcp.translation())
        pose, velocity = (run["truth.end_effector_pose"],
                          run["truth.end_effector_velocity"])
        np.testing.assert_allclose(pose[:3], X_W_tcp.translation(),
                                   atol=1e-12)
        np.testing.assert_allclose(
            RotationMatrix(RollPitchYaw(pose[3:])).matrix(),
            X_W_tcp.rotation().matrix(), atol=1e-12)
        np.testing.assert_allclose(velocity, np.concatenate(
            [V_W_tcp.translational(), V_W_tcp.rotational()]), atol=1e-12)
        assert np.linalg.norm(velocity[:3]) > 0.05


def on_box_boundary(points_W, box, tolerance):
    c, s = np.cos(box.yaw), np.sin(box.yaw)
    local = (points_W - box.center[:2]) @ np.array([[c, -s], [s, c]])
    half = np.array(box.size[:2]) / 2
    return np.abs(np.max(np.abs(local) / half, axis=1) - 1.0) * np.min(
        half) < tolerance


def test_lidar_points_lie_on_the_obstacles_and_the_walking_person(rest):
    points = rest["lidar.obstacle_points"]
    x, y, yaw = rest["truth.base_pose"]
    np.testing.assert_allclose([x, y, yaw], REST_POSE, atol=1e-9)
    c, s = np.cos(yaw), np.sin(yaw)
    points_W = np.array([x, y]) + points @ np.array([[c, -s], [s, c]]).T
    # The last scan before the end, at a multiple of 1/15 s, saw the
    # person where the schedule had them then.
    rate = 15.0
    t_scan = np.floor(REST_DURATION * rate) / rate
    person = person_positions(SCENE.people, t_scan)[0]
    now = rest["truth.people_positions"]
    np.testing.assert_allclose(now, person_positions(SCENE.people,
                                                     REST_DURATION)[0])
    on_pillar = np.abs(np.linalg.norm(points_W - PILLAR.position, axis=1)
                       - PILLAR.radius) < 1e-9
    on_person = np.abs(np.linalg.norm(points_W - person, axis=1)
                       - PERSON.radius) < 1e-9
    on_wall = on_box_boundary(points_W, WALL, 1e-9)
    assert on_pillar.sum() >= 10 and on_person.sum() >= 10
    assert on_wall.sum() >= 10
    assert np.all(on_pillar | on_person | on_wall)
    # The person had moved on since that scan; the points are not where
    # the person is now.
    assert not np.any(np.abs(np.linalg.norm(points_W - now, axis=1)
                             - PERSON.radius) < 1e-9)
    inside = np.all(np.abs(points) <= FOOTPRINT_HALF, axis=1)
    assert not np.any(inside)


def test_a_scanner_sees_only_the_people_as_tall_as_its_scan_plane():
    # The scanners scan 0.2 m above the floor. A person 0.15 m high (a
    # child crawling) in front of each is below both planes; one 1.75 m
    # high in front of the rear scanner is a circle of its radius there.
    low = [WalkingPerson(name=f"low_{i}", radius=0.2, height=0.15,
                         waypoints=[xy]) for i, xy in enumerate(
                             [[1.5, 1.4], [-1.5, -1.4]])]
    tall = WalkingPerson(name="tall", radius=0.25, waypoints=[[-1.2, -2.0]])
    station = SimulatedStation(StationOptions(time_step=0.005),
                               Scene(people=[low[0], tall, low[1]]))
    run = Run(station)
    run.advance(0.1)
    assert np.all(np.isinf(run["lidar.front_left.ranges"]))
    ranges = run["lidar.rear_right.ranges"]
    # The scanner at (-0.36, -0.26), facing -135 degrees: the nearest
    # return is the person's distance less the radius.
    origin = np.array([-0.36, -0.26])
    nearest = np.linalg.norm(np.array([-1.2, -2.0]) - origin) - 0.25
    assert np.min(ranges) == pytest.approx(nearest, abs=2e-3)
    points = run["lidar.obstacle_points"]
    np.testing.assert_allclose(
        np.linalg.norm(points - [-1.2, -2.0], axis=1), 0.25, atol=1e-9)


def test_wrist_at_rest_reads_the_tools_weight(station, rest):
    plant, model = station.plant, station.model
    reading = rest["wrist.wrench_measured"]
    tool = plant.GetBodyByName("wiping_tool", model.tool)
    mass = tool.default_mass()
    weight_W = mass * plant.gravity_field().gravity_vector()
    X_WS = model.ft_measurement_frame.CalcPoseInWorld(rest.plant_context)
    f_S = X_WS.rotation().inverse() @ weight_W
    p_WCm = tool.EvalPoseInWorld(rest.plant_context) @ tool.default_com()
    p_S = X_WS.inverse() @ p_WCm
    np.testing.assert_allclose(reading, np.concatenate(
        [f_S, np.cross(p_S, f_S)]), atol=1e-9)
    assert np.linalg.norm(reading[:3]) == pytest.approx(
        mass * 9.81, rel=1e-3)
    # The robot locked at the same arm configuration, mount at rest, base
    # at the origin: the same force, turned by the sag's tilt.
    locked_plant, locked_model, context = settle_locked_robot(rest.q_cmd)
    locked = sensor_reading(locked_plant, locked_model, context)
    R_W_locked = locked_model.ft_measurement_frame.CalcPoseInWorld(
        context).rotation()
    np.testing.assert_allclose(
        reading[:3], (X_WS.rotation().inverse() @ R_W_locked) @ locked[:3],
        atol=1e-9)
    tilt = (X_WS.rotation().inverse() @ R_W_locked).ToAngleAxis().angle()
    assert tilt > 1e-3


@pytest.mark.parametrize("frames, message", [
    (("scanner", "lidar_scanner"),
     r"lidar_frames\[1\] = 'omni_arm::lidar_scanner' is not allowed: its "
     r"scanner's name 'scanner' .* is that of lidar_frames\[0\] = "
     r"'omni_arm::scanner'"),
    (("lidar_points",),
     r"lidar_frames\[0\] = 'omni_arm::lidar_points' is not allowed: its "
     r"scanner's name would be 'points'")])
def test_scanners_of_one_name_are_refused_naming_their_frames(
        tmp_path, frames, message):
    """A scanner's systems and ports are named by its frame's name without
    a leading lidar_: two frames of one such name ended the process when
    the station was built (Drake's failed condition on unique subsystem
    names, a SystemExit), and a frame named lidar_points failed on an
    input port of the scanners' merger that it took for its own."""
    path = write_omni_arm(tmp_path, 6)
    urdf = tmp_path / "omni_arm.urdf"
    urdf.write_text(urdf.read_text().replace("</robot>", "".join(
        f"<link name='{name}'/><joint name='{name}' type='fixed'><parent "
        f"link='chassis'/><child link='{name}'/><origin xyz='0.4 {y} "
        "0.2'/></joint>" for name, y in zip(frames, (0.3, -0.3)[:len(frames)],
                                           strict=True))
        + "\n</robot>"))
    path.write_text(path.read_text() + "lidar_frames: ["
                    + ", ".join(f"omni_arm::{name}" for name in frames)
                    + "]\n")
    with pytest.raises(ValueError, match=message):
        SimulatedStation(StationOptions(time_step=0.005),
                         robot=load_robot_description(path))


WHEEL = (
    "<link name='wheel'><inertial><mass value='1'/><inertia ixx='0.01' "
    "iyy='0.01' izz='0.01' ixy='0' ixz='0' iyz='0'/></inertial></link>"
    "<joint name='wheel' type='continuous'><parent link='chassis'/><child "
    "link='wheel'/><origin xyz='0.2 0.2 0.1'/><axis xyz='0 1 0'/></joint>"
    "<transmission name='wheel_drive'><type>transmission_interface/"
    "SimpleTransmission</type><joint name='wheel'><hardwareInterface>"
    "EffortJointInterface</hardwareInterface></joint><actuator "
    "name='wheel_motor'><mechanicalReduction>1</mechanicalReduction>"
    "</actuator></transmission>")
"""An actuated joint that is neither the base's nor the arm's."""


@pytest.mark.parametrize("change, message", [
    ("no actuator",
     r"arm.joints\[2\] = 'omni_arm::j3' is not allowed in the simulated "
     r"station: the model gives it no actuator"),
    ("another actuator",
     r"the actuator of 'omni_arm::wheel' is not allowed in the simulated "
     r"station: it drives only base.joints and arm.joints")])
def test_the_station_names_the_joints_its_drives_cannot_drive(
        tmp_path, change, message):
    """The station drives the base's and the arm's joints through the
    model's actuators (a URDF's transmissions): an arm joint without one
    failed with a bare KeyError of a joint index, and an actuator on
    another joint (a wheel) with an error naming no joint."""
    path = write_omni_arm(tmp_path, 6)
    urdf = tmp_path / "omni_arm.urdf"
    text = urdf.read_text()
    if change == "no actuator":
        start = text.index("<transmission name='j3_drive'>")
        end = text.index("</transmission>", start) + len("</transmission>")
        text = text[:start] + text[end:]
    else:
        text = text.replace("</robot>", WHEEL + "\n</robot>")
    urdf.write_text(text)
    with pytest.raises(ValueError, match=message):
        SimulatedStation(StationOptions(time_step=0.005),
                         robot=load_robot_description(path))


def test_a_urdf_bases_joint_limits_are_no_wall(tmp_path):
    """A URDF's prismatic joint carries position limits (its schema asks
    for them; tests/omni_arm.py's and examples/own_robot's base joints
    have +-2.5 m): the base's planar joints are its pose on the floor, so
    the station's base drives on past them, where it stopped at 2.5 m as
    at a wall that is not there."""
    description = load_robot_description(write_omni_arm(tmp_path, 6))
    station = SimulatedStation(StationOptions(
        time_step=0.005, initial_base_pose=[2.3, 0.0, 0.0]),
        robot=description)
    context = station.diagram.CreateDefaultContext()
    station.set_initial_state(context)
    station.diagram.GetInputPort("arm.position_command").FixValue(
        context, description.arm.home)
    station.diagram.GetInputPort("base.velocity_command").FixValue(
        context, [0.5, 0.0, 0.0])
    Simulator(station.diagram, context).AdvanceTo(1.5)
    x = station.diagram.GetOutputPort("truth.base_pose").Eval(context)[0]
    assert x > 2.7


def test_the_plant_step_and_the_scene_period_are_checked():
    StationOptions(time_step=0.005, scene_period=0.02)  # allowed
    with pytest.raises(ValueError, match=r"time_step = 0\.006 s .* at most "
                       r"0\.005 s \(5 ms\)"):
        StationOptions(time_step=0.006)
    with pytest.raises(ValueError, match=r"scene_period = 0\.012 s .* "
                       r"time_step = 0\.005 s: must be a whole multiple"):
        StationOptions(time_step=0.005, scene_period=0.012)


def test_the_drivers_run_at_the_plant_step_alone():
    """The drivers' one step is the plant's: a 5 ms base loop at a
    0.2 ms step (a default 1 ms step of the loop's own refused it) runs
    at 0.2 ms, its velocity the lag sampled at that step; a step coarser
    than lag / 10 is refused naming time_step and base.lag."""
    from drake_wbc.station.drivers import BaseDriverParameters

    h, lag, u = 0.0002, 0.005, np.array([0.004, -0.003, 0.002])
    station = SimulatedStation(StationOptions(
        time_step=h, base=BaseDriverParameters(lag=lag,
                                               servo_time_constant=0.001)))
    assert station.plant.time_step() == h
    driver = station.systems["base_driver"]
    assert driver.GetUniquePeriodicDiscreteUpdateAttribute().period_sec() \
        == h
    context = station.diagram.CreateDefaultContext()
    station.set_initial_state(context)
    station.diagram.GetInputPort("arm.position_command").FixValue(
        context, station.options.initial_arm_positions)
    station.diagram.GetInputPort("base.velocity_command").FixValue(context,
                                                                   u)
    simulator = Simulator(station.diagram, context)
    n = 25  # updates at 0, h, ..., n h have run by (n + 1/2) h
    simulator.AdvanceTo((n + 0.5) * h)
    np.testing.assert_allclose(
        station.diagram.GetOutputPort("truth.base_loop_velocity").Eval(
            context), u * (1.0 - np.exp(-(n + 1) * h / lag)), atol=1e-12)
    with pytest.raises(ValueError, match=r"^time_step = 0\.001 s is not "
                       r"allowed with base\.lag = 0\.005 s: must be at most "
                       r"lag / 10"):
        StationOptions(time_step=0.001, base=BaseDriverParameters(
            lag=lag, servo_time_constant=0.001))


def test_odometry_system_reports_what_base_odometry_does(station):
    """The station's C++ odometry against the reference BaseOdometry, at
    random states of the plant."""
    plant, model = station.plant, station.model
    reference = BaseOdometry(plant, model)
    selection = MatrixGain(base_state_selection(plant, model))
    odometry = odometry_system()
    contexts = [system.CreateDefaultContext()
                for system in (reference, selection, odometry)]
    rng = np.random.default_rng(5)
    for _ in range(20):
        x = rng.uniform(-3.0, 3.0, plant.num_multibody_states())
        reference.GetInputPort("plant_state").FixValue(contexts[0], x)
        selection.get_input_port().FixValue(contexts[1], x)
        odometry.get_input_port().FixValue(
            contexts[2], selection.get_output_port().Eval(contexts[1]))
        np.testing.assert_allclose(
            odometry.get_output_port().Eval(contexts[2]),
            reference.GetOutputPort("state_estimated").Eval(contexts[0]),
            atol=1e-14)

"""A robot the project did not model, closed through the controller: an
omni base carrying a 6- or 7-joint arm (tests/omni_arm.py), the
controller built from its description alone, and an ideal robot (the
joints follow their position command, the base its velocity command) that
must carry the TCP along the commanded world twist."""

import copy
import re
import threading
import time
import warnings

import numpy as np
import pytest
from omni_arm import (
    HOMES,
    SELF_FILTER,
    add_collision_spheres,
    use_directives,
    write_omni_arm,
    write_scenario,
)
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource

from drake_wbc.analysis.plant_chain import linearize_base_plant
from drake_wbc.controller import ControllerParameters, build_controller
from drake_wbc.controller.parameters import for_robot
from drake_wbc.deployment.deploy import add_controller_side, wait_for_status
from drake_wbc.experiments.runner import (
    build_closed_loop,
    simulate,
    start_simulator,
)
from drake_wbc.experiments.scenario import (
    controller_arm,
    controller_for,
    find_scenario,
    load_scenario,
    robot_file_of,
    scenario_robot,
    with_robot,
)
from drake_wbc.hardware import messages
from drake_wbc.hardware.options import HardwareOptions
from drake_wbc.hardware.safety import CommandGuard, Limits, follow_arm_command
from drake_wbc.robot.description import load_robot_description, shipped_robot
from drake_wbc.robot.footprint import check_start_is_free
from drake_wbc.robot.model import ArmKinematics, ArmMount, make_robot_plant
from drake_wbc.robot.suspension import SuspensionParameters
from drake_wbc.robot.tuning import (
    RobotTuningWarning,
    check_tuning,
    survey_capability,
)
from drake_wbc.stages.wrench import tool_weight_reading
from drake_wbc.station.scene import BoxObstacle, CylinderObstacle, Scene
from drake_wbc.station.simulation import SimulatedStation, StationOptions

H = 0.01


class IdealBase(LeafSystem):
    """The base's pose integrated from its velocity command (in T_b), and
    its state [x, y, yaw, vx, vy, wz] as odometry gives it."""

    def __init__(self):
        super().__init__()
        self.command = self.DeclareVectorInputPort("velocity_command", 3)
        state = self.DeclareDiscreteState(6)
        self.DeclarePeriodicDiscreteUpdateEvent(H, 0.0, self._update)
        self.DeclareStateOutputPort("state_estimated", state)

    def _update(self, context, discrete_state):
        x = context.get_discrete_state_vector().CopyToVector()
        v = self.command.Eval(context)
        c, s = np.cos(x[2]), np.sin(x[2])
        x[:3] += H * np.array([c * v[0] - s * v[1], s * v[0] + c * v[1],
                               v[2]])
        x[3:] = v
        discrete_state.set_value(x)


class IdealWrist(LeafSystem):
    """What the wrist sensor reads with nothing touching the tool, at the
    arm's measured joints (the tool's weight only)."""

    def __init__(self, arm):
        super().__init__()
        self.arm = arm
        self.q = self.DeclareVectorInputPort("q", arm.num_joints)
        self.DeclareVectorOutputPort("wrench", BasicVector(6), self._calc)

    def _calc(self, context, output):
        output.SetFromVector(tool_weight_reading(self.arm,
                                                 self.q.Eval(context)))


@pytest.mark.parametrize("n", [6, 7])
def test_the_controller_of_a_urdf_robot_tracks_a_world_twist(tmp_path, n):
    path = write_omni_arm(tmp_path, n)
    arm = ArmKinematics(*make_robot_plant(load_robot_description(path)))
    # The tuning proposed for this arm (drake_wbc.robot.tuning).
    survey = survey_capability(arm, count=100)
    params = ControllerParameters()
    params.capability.joint_limit_gain = survey.k_j
    params.capability_band = survey.proposed_band()
    with warnings.catch_warnings():
        warnings.simplefilter("error", RobotTuningWarning)
        controller = build_controller(params, robot=arm)
    # Its base's own lag (0.2 s, not the shipped 0.3) in the separation.
    assert controller.stages["base_limiter"].timing.lag == 0.2
    builder = DiagramBuilder()
    c = builder.AddSystem(controller.diagram)
    base = builder.AddSystem(IdealBase())
    wrist = builder.AddSystem(IdealWrist(arm))
    twist = np.array([0.05, -0.03, 0.02, 0.0, 0.0, 0.0])
    reference = builder.AddSystem(ConstantVectorSource(twist))
    points = builder.AddSystem(ConstantValueSource(
        AbstractValue.Make(np.zeros((0, 2)))))
    connect = builder.Connect
    connect(c.GetOutputPort("base.velocity_command"),
            base.get_input_port())
    connect(base.get_output_port(), c.GetInputPort("base.state_estimated"))
    # The ideal arm: the joints are where they were commanded.
    connect(c.GetOutputPort("arm.position_command"),
            c.GetInputPort("arm.position_measured"))
    connect(c.GetOutputPort("arm.position_command"), wrist.get_input_port())
    connect(wrist.get_output_port(), c.GetInputPort("wrist.wrench_measured"))
    connect(reference.get_output_port(),
            c.GetInputPort("reference_velocity"))
    connect(points.get_output_port(), c.GetInputPort("lidar.obstacle_points"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    controller.initialize(context)

    def tcp(context):
        q = c.GetOutputPort("arm.position_command").Eval(
            c.GetMyContextFromRoot(context))
        pose = base.get_output_port().Eval(base.GetMyContextFromRoot(context))
        p_b = arm.evaluate(q).p_ee_in_base
        cy, sy = np.cos(pose[2]), np.sin(pose[2])
        return np.array([pose[0] + cy * p_b[0] - sy * p_b[1],
                         pose[1] + sy * p_b[0] + cy * p_b[1], p_b[2]])

    start = tcp(context)
    simulator.AdvanceTo(3.0)
    q = c.GetOutputPort("arm.position_command").Eval(
        c.GetMyContextFromRoot(context))
    assert q.shape == (n,)
    assert np.all(np.isfinite(q))
    moved = tcp(context) - start
    # The DMP follows the reference with a lag of about tau; over 3 s the
    # TCP has moved most of 3 s of the twist, along its direction.
    expected = 3.0 * twist[:3]
    direction = expected / np.linalg.norm(expected)
    assert moved @ direction > 0.8 * np.linalg.norm(expected)
    assert np.linalg.norm(moved - (moved @ direction) * direction) < (
        0.05 * np.linalg.norm(expected))
    reason = controller.safety_reason(context)
    assert reason == ""


def test_the_hardware_guard_holds_the_commands_to_that_arms_own_limits(
        tmp_path):
    """The LCM side of the same robot: its arm's 7 joints in the messages
    and ports, and its own limits, tighter than the shipped Elfin5's, in
    the command guard: a command the Elfin5 would take is limited, and one
    within this arm's limits passes bit for bit."""
    n = 7
    path = write_omni_arm(
        tmp_path, n, extra=f"  velocity_limits: [{', '.join(['0.5'] * n)}]")
    arm = ArmKinematics(*make_robot_plant(load_robot_description(path)))
    limits = Limits.of_robot(HardwareOptions(), arm)
    np.testing.assert_array_equal(limits.joint_speed, np.full(n, 0.5))
    np.testing.assert_array_equal(limits.joint_acceleration, np.full(n, 9.0))
    np.testing.assert_array_equal(limits.upper, np.full(n, 2.5))
    # Its base's own limits too (0.8 m/s, 1.0 rad/s, 0.5 m/s^2 and rad/s^2),
    # and a hardware option wider than them is refused.
    assert (limits.base_speed, limits.base_yaw_rate) == (0.8, 1.0)
    np.testing.assert_array_equal(limits.base_acceleration, np.full(3, 0.5))
    with pytest.raises(ValueError, match="base_speed_limit = 0.9 .* 0.8 m/s"):
        Limits.of_robot(HardwareOptions(base_speed_limit=0.9), arm)
    guard = CommandGuard(HardwareOptions(), arm.home, limits)
    assert guard.GetInputPort("arm_position_command").size() == n
    period = HardwareOptions().publish_period
    last, velocity = arm.home.copy(), np.zeros(n)
    # 1 rad/s on the first joint: within the Elfin5's 1.57, beyond 0.5.
    fast = last.copy()
    fast[0] += 1.0 * period
    command, rate, changed = follow_arm_command(
        fast, np.zeros(n), last, velocity, period, limits)
    assert changed and abs(rate[0]) <= 0.5 * (1 + 1e-9)
    # Beyond this arm's 2.5 rad (within the Elfin5's 3.14): held at 2.5.
    far = last.copy()
    far[1] = 2.9
    for _ in range(2000):
        last, velocity, _ = follow_arm_command(far, np.zeros(n), last,
                                               velocity, period, limits)
    assert last[1] == pytest.approx(2.5) and last[1] <= 2.5
    # Within every limit of this arm: sent as it is.
    slow = arm.home.copy()
    slow[2] += 0.05 * period  # 5 rad/s^2 from rest, within 9
    command, _, changed = follow_arm_command(
        slow, np.zeros(n), arm.home, np.zeros(n), period, limits)
    assert not changed
    np.testing.assert_array_equal(command, slow)


@pytest.mark.parametrize("n", [6, 7])
def test_a_guard_of_that_robots_limits_asks_for_its_arms_start(tmp_path, n):
    """A command guard given another robot's limits but no arm positions
    to hold would hold the shipped Elfin5's home (a configuration of
    another arm) on a six-joint arm, and fail on its size on seven: it
    asks for the positions instead, naming the argument."""
    path = write_omni_arm(tmp_path, n)
    arm = ArmKinematics(*make_robot_plant(load_robot_description(path)))
    limits = Limits.of_robot(HardwareOptions(), arm)
    with pytest.raises(ValueError, match=(
            r"initial_arm_positions = None is not allowed with limits")):
        CommandGuard(HardwareOptions(), None, limits)


@pytest.mark.parametrize("continuous", [(), (0, 2, 4, 6)])
def test_the_same_controller_deploys_over_lcm_to_that_robot(tmp_path,
                                                            continuous):
    """The controller side of `drake-wbc deploy` for a scenario that names
    the 7-joint robot (`robot:`), over real LCM messages (memq://), with
    the test in the robot's place: it sends 7-joint statuses (the arm
    where it was last commanded, the base at its command) and the
    controller answers with 7-joint commands, within that arm's own
    limits, that move the tool along the task's world twist; also with
    the arm's joints 1, 3, 5 and 7 continuous (no position limits, only
    their speed and acceleration limits)."""
    n = 7
    robot = write_omni_arm(tmp_path, n, continuous=continuous)
    scenario_file = write_scenario(tmp_path, robot, 2.0,
                                   extra="hardware:\n  lcm_url: memq://\n")
    scenario = load_scenario(scenario_file)
    assert scenario.robot == str(robot.resolve())
    lcm = DrakeLcm("memq://")
    builder = DiagramBuilder()
    side = add_controller_side(builder, scenario, lcm=lcm)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    root = simulator.get_mutable_context()
    arm = side.hardware.arm
    assert arm.num_joints == n
    channels = side.options.channels
    sent = {"arm": [], "base": []}
    lcm.Subscribe(channels.arm_command, lambda data: sent["arm"].append(
        messages.decode_arm_command(data).values[0]))
    lcm.Subscribe(channels.base_command, lambda data: sent["base"].append(
        messages.decode_base_command(data).values[0]))
    q, base = arm.home.copy(), np.zeros(6)
    side.initialize(root, q)
    simulator.Initialize()
    h = scenario.controller.time_step
    start = None
    for k in range(150):
        utime = int(round(k * h * 1e6))
        lcm.Publish(channels.base_state,
                    messages.encode_base_state(utime, base))
        lcm.Publish(channels.arm_status,
                    messages.encode_arm_status(utime, q, np.zeros(n)))
        lcm.Publish(channels.wrist_wrench, messages.encode_wrench(
            utime, tool_weight_reading(arm, q)))
        if k % 6 == 0:
            lcm.Publish(channels.obstacle_points,
                        messages.encode_obstacle_points(utime,
                                                        np.zeros((0, 2))))
        simulator.AdvanceTo((k + 1) * h)
        if sent["arm"]:
            q = sent["arm"][-1]
            assert q.shape == (n,)
        if sent["base"]:
            v = sent["base"][-1]
            c, s = np.cos(base[2]), np.sin(base[2])
            base = base + h * np.array([c * v[0] - s * v[1],
                                        s * v[0] + c * v[1], v[2], 0, 0, 0])
            base[3:] = v
        if start is None and k == 20:
            start = (q.copy(), base.copy())
    commands = np.array(sent["arm"])
    assert len(commands) > 100
    assert np.all(commands >= arm.lower) and np.all(commands <= arm.upper)
    rates = np.abs(np.diff(commands, axis=0)) / h
    assert np.all(rates <= arm.velocity_limits * (1 + 1e-9))
    # The tool moved along the world twist (x and z) over the run.
    def tool(q_a, pose):
        p = arm.evaluate(q_a).p_ee_in_base
        c, s = np.cos(pose[2]), np.sin(pose[2])
        return np.array([pose[0] + c * p[0] - s * p[1],
                         pose[1] + s * p[0] + c * p[1], p[2]])
    moved = tool(q, base) - tool(*start)
    assert moved[0] > 0.02 and moved[2] > 0.008
    assert abs(moved[1]) < 0.3 * moved[0]



def test_the_wait_for_the_robot_says_why_its_status_is_refused(tmp_path):
    """`drake-wbc deploy` for the 7-joint robot, the arm answering with
    6-joint statuses at 100 Hz (real LCM messages, memq://): the wait for
    the robot's status ends with what was refused and why (the messages'
    count and the last refusal), not with "is the robot running"."""
    n = 7
    robot = write_omni_arm(tmp_path, n)
    num_joints = len(load_robot_description(robot).arm.joints)
    assert num_joints == n
    options = HardwareOptions(lcm_url="memq://")
    channels = options.channels
    lcm = DrakeLcm("memq://")
    waiting, sent = threading.Event(), [0]

    def robot_side():
        utime = 0
        while not waiting.is_set():
            utime += 10_000
            sent[0] += 1
            for channel, data in (
                    (channels.base_state,
                     messages.encode_base_state(utime, np.zeros(6))),
                    (channels.arm_status, messages.encode_arm_status(
                        utime, np.zeros(n - 1), np.zeros(n - 1))),
                    (channels.wrist_wrench,
                     messages.encode_wrench(utime, np.zeros(6))),
                    (channels.obstacle_points,
                     messages.encode_obstacle_points(utime,
                                                     np.zeros((0, 2))))):
                lcm.Publish(channel, data)
            time.sleep(0.01)

    sender = threading.Thread(target=robot_side)
    sender.start()
    try:
        with pytest.raises(TimeoutError) as raised:
            wait_for_status(lcm, options, num_joints, timeout=0.5)
    finally:
        waiting.set()
        sender.join()
    text = str(raised.value)
    print(text)
    match = re.search(rf"{channels.arm_status}: (\d+) messages rejected: "
                      rf"position has {n - 1} entries, which is not "
                      rf"allowed: must have {n}$", text)
    assert match and 1 <= int(match.group(1)) <= sent[0]
    assert f"no status on {channels.arm_status} within" in text
    assert "is the robot" not in text


def test_the_simulated_station_runs_that_robot(tmp_path):
    """The same scenario in the simulated station (a MultibodyPlant of the
    URDF robot, its drivers and the wrist sensor on its weld): the closed
    loop runs, and the true tool follows the world twist."""
    n = 7
    robot = write_omni_arm(tmp_path, n)
    scenario_file = write_scenario(tmp_path, robot, 1.5)
    scenario = load_scenario(scenario_file)
    loop = build_closed_loop(scenario)
    assert loop.station.model.num_arm_joints == n
    simulator = start_simulator(loop)
    root = simulator.get_mutable_context()
    pose = loop.station.diagram.GetOutputPort("truth.end_effector_pose")
    station_context = loop.station.diagram.GetMyContextFromRoot(root)
    simulator.AdvanceTo(0.5)
    start = pose.Eval(station_context)[:3].copy()
    simulator.AdvanceTo(1.5)
    moved = pose.Eval(station_context)[:3] - start
    assert np.all(np.isfinite(moved))
    # 1 s of the twist: 0.05 m along x, 0.02 m up, nothing sideways.
    assert 0.8 * 0.05 < moved[0] < 1.2 * 0.05
    assert 0.6 * 0.02 < moved[2] < 1.4 * 0.02
    assert abs(moved[1]) < 0.01
    assert loop.controller.safety_reason(root) == ""


def _add_finger(folder):
    """Adds a finger to the omni arm's tool (a revolute joint whose link's
    mass sits 5 cm off its axis, so that gravity swings it unless it is
    held); returns the finger's joint name."""
    urdf = folder / "omni_arm.urdf"
    finger = (
        "<link name='finger'><inertial><origin xyz='0.05 0 0'/>"
        "<mass value='0.5'/><inertia ixx='0.001' iyy='0.001' izz='0.001' "
        "ixy='0' ixz='0' iyz='0'/></inertial></link>"
        "<joint name='finger' type='revolute'><parent link='tool'/>"
        "<child link='finger'/><origin xyz='0 0.02 0.03'/>"
        "<axis xyz='0 1 0'/><limit lower='-1.5' upper='1.5' effort='10' "
        "velocity='1'/></joint>")
    urdf.write_text(urdf.read_text().replace("</robot>",
                                             finger + "</robot>"))
    return "omni_arm::finger"


def test_a_gripper_locked_in_the_station_is_carried_rigidly(tmp_path):
    """A joint in what the wrist sensor carries (a gripper's finger) is
    refused unless the description lists it in tool.locked_joints; then
    the station holds it at its default position, so the sensor reads the
    rigid tool the controller compensates: while the robot follows a world
    twist, the true wrist wrench is the weight of the tool with its
    finger as the controller's model computes it (tool_weight_reading),
    and the controller runs without a stop. Unlocked, the finger swings
    down."""
    n = 7
    robot = write_omni_arm(tmp_path, n)
    finger = _add_finger(tmp_path)
    with pytest.raises(ValueError, match="list it in tool.locked_joints"):
        load_scenario(write_scenario(tmp_path, robot, 1.0))
    robot.write_text(robot.read_text().replace(
        "ft_sensor_joint: omni_arm::sensor",
        f"ft_sensor_joint: omni_arm::sensor\n  locked_joints: [{finger}]"))
    loop = build_closed_loop(load_scenario(write_scenario(tmp_path, robot,
                                                          1.0)))
    station = loop.station
    plant = station.plant
    joint = plant.GetJointByName("finger")
    simulator = start_simulator(loop)
    root = simulator.get_mutable_context()
    plant_context = plant.GetMyContextFromRoot(root)
    station_context = station.diagram.GetMyContextFromRoot(root)
    simulator.AdvanceTo(1.0)
    assert joint.is_locked(plant_context)
    assert plant.GetPositions(plant_context)[joint.position_start()] == 0.0
    arm = ArmKinematics(plant, station.model)
    q_a = station.diagram.GetOutputPort("arm.position_measured").Eval(
        station_context)
    weight = tool_weight_reading(arm, q_a)
    wrench = station.diagram.GetOutputPort("truth.wrist_wrench").Eval(
        station_context)
    # The weight of the sensor's far side, the tool and the finger.
    assert np.linalg.norm(weight[:3]) == pytest.approx(1.1 * 9.81, rel=1e-3)
    np.testing.assert_allclose(wrench, weight, atol=0.02 * 1.1 * 9.81)
    assert loop.controller.safety_reason(root) == ""
    # What held it: unlocked, gravity swings the finger away.
    joint.Unlock(plant_context)
    simulator.AdvanceTo(1.2)
    assert abs(plant.GetPositions(plant_context)[joint.position_start()]) \
        > 0.01
    # The plant chain's linearisation cannot hold it: refused, by name.
    with pytest.raises(ValueError, match=(
            r"tool.locked_joints = \['omni_arm::finger'\] cannot be held")):
        linearize_base_plant(station)


def test_a_six_joint_robot_starts_at_its_own_home(tmp_path):
    """A start is a configuration of one arm: the shipped Elfin5's home
    (or a scenario's start written for it) puts another 6-joint arm
    elsewhere. On a 6-joint URDF robot the arm starts at that robot's
    home: a shipped scenario run with --robot (with_robot), a scenario
    naming the robot without a start, and a station built with no start;
    on the scenario's own robot the scenario's start stays."""
    robot = write_omni_arm(tmp_path, 6)
    home = load_robot_description(robot).arm.home
    shipped_home = shipped_robot().arm.home
    assert not np.allclose(home, shipped_home)
    for name in ("trajectory_tracking", "wiping"):
        on_six = with_robot(load_scenario(find_scenario(name)), robot,
                            echo=None)
        assert on_six.station.initial_arm_positions == list(home)
    wiping = load_scenario(find_scenario("wiping"))
    same = with_robot(wiping, find_scenario("trajectory_tracking_lbr")
                      .parent.parent / "models" / "mcr.robot.yaml",
                      echo=None)
    assert (same.station.initial_arm_positions
            == wiping.station.initial_arm_positions)
    scenario_file = tmp_path / "no_start.yaml"
    scenario_file.write_text(f"robot: {robot.name}\n")
    assert load_scenario(scenario_file).station.initial_arm_positions == (
        list(home))
    assert load_scenario(text="duration: 1.0").station.initial_arm_positions \
        == list(shipped_home)
    station = SimulatedStation(StationOptions(time_step=0.005),
                               robot=load_robot_description(robot))
    assert station.options.initial_arm_positions == list(home)


@pytest.mark.parametrize("part, suspension, mount", [
    ("suspension", SuspensionParameters(), ArmMount()),
    ("mount", None, ArmMount(yaw=0.3))])
def test_a_one_file_robot_says_what_cannot_be_added_to_it(
        tmp_path, part, suspension, mount):
    """A robot described by one URDF file: a suspension or a turned arm,
    which only model directives can take, is refused naming the part, the
    robot and its file, and what to do."""
    description = load_robot_description(write_omni_arm(tmp_path, 7))
    options = StationOptions(
        initial_arm_positions=list(description.arm.home),
        suspension=suspension)
    with pytest.raises(ValueError, match=(
            rf"^{part} is not allowed on {description.name}: its model is "
            r"one file .*omni_arm.*\.urdf.* model\.directives")):
        SimulatedStation(options, mount=mount, robot=description)


def test_a_suspension_under_a_urdf_base_is_refused_naming_its_file(
        tmp_path):
    """The suspension's joints go into the base's SDFormat file: under a
    base whose model directives add a URDF, the station failed naming the
    internal argument yaw_joint and "the base's SDFormat", which it was
    not."""
    path = write_omni_arm(tmp_path, 7)
    use_directives(tmp_path, path)
    description = load_robot_description(path)
    options = StationOptions(
        initial_arm_positions=list(description.arm.home),
        suspension=SuspensionParameters())
    with pytest.raises(ValueError, match=(
            r"^suspension is not allowed on omni_arm: the model of "
            r"base.joints\[2\] = 'omni_arm::base_yaw' is "
            r"'package://mine/omni_arm.urdf', not an SDFormat file")):
        SimulatedStation(options, robot=description)



def _link_origins(description, q_arm):
    """Where the omni arm's link1 and link3 are in the world with the
    arm at q_arm and the base at the origin, from a plant of the robot
    alone."""
    plant, model = make_robot_plant(description)
    context = plant.CreateDefaultContext()
    q = plant.GetPositions(context)
    q[[j.position_start() for j in model.arm_joints]] = q_arm
    plant.SetPositions(context, q)
    return [plant.GetBodyByName(link).EvalPoseInWorld(context).translation()
            for link in ("link1", "link3")]


def _sphere_overlap(description, radius, q_arm):
    """How deep the omni arm's spheres of `radius` on link1 and link3
    overlap with the arm at q_arm (m; negative: apart)."""
    p1, p3 = _link_origins(description, q_arm)
    return 2.0 * radius - np.linalg.norm(p3 - p1)


def test_links_that_overlap_at_home_are_refused_unless_filtered(tmp_path):
    """Drake filters a body's contacts with its parent only: link1 and
    link3 (two joints apart), their spheres overlapping at home, pushed
    each other from the first step, and nothing said so. The station
    refuses them naming the pair and the depth (the spheres' closed
    form); with the collision filter group the README gives, it is
    built."""
    path = write_omni_arm(tmp_path, 7)
    add_collision_spheres(tmp_path, {"link1": 0.32, "link3": 0.32})
    use_directives(tmp_path, path)
    description = load_robot_description(path)
    depth = _sphere_overlap(description, 0.32, HOMES[7])
    assert 0.05 < depth < 0.07
    with pytest.raises(ValueError, match=(
            r"(?s)^arm\.home = \[0\.0, 0\.5, .*\] is not allowed: there the "
            r"robot's own bodies overlap \('omni_arm::link1' and "
            rf"'omni_arm::link3' by {1e3 * depth:.1f} mm\).*"
            r"add_collision_filter_group:\n    name: robot\n    members: "
            r"\[omni_arm::link1, omni_arm::link3\]\n")):
        SimulatedStation(robot=description)
    use_directives(tmp_path, path, SELF_FILTER)
    station = SimulatedStation(robot=load_robot_description(path))
    assert station.model.num_arm_joints == 7


def test_links_that_overlap_at_the_start_are_refused(tmp_path):
    """Apart at home, link1's and link3's spheres overlap where a
    scenario starts the arm (joint 2 bent to 1.2 rad): refused naming
    the start; contact with the scene (a box around the arm) is not the
    robot's own."""
    path = write_omni_arm(tmp_path, 7)
    add_collision_spheres(tmp_path, {"link1": 0.27, "link3": 0.27})
    description = load_robot_description(path)
    assert _sphere_overlap(description, 0.27, HOMES[7]) < -0.03
    start = [0.0, 1.2, 0.3, -0.2, 1.3, 0.2, 0.0]
    depth = _sphere_overlap(description, 0.27, start)
    assert depth > 0.04
    with pytest.raises(ValueError, match=(
            r"^station\.initial_arm_positions = \[0\.0, 1\.2, .*\] is not "
            r"allowed: .*\('omni_arm::link1' and 'omni_arm::link3' by "
            rf"{1e3 * depth:.1f} mm\)")):
        SimulatedStation(StationOptions(initial_arm_positions=start),
                         robot=description)
    # A crate the sphere on link3 reaches into at home.
    crate = BoxObstacle("crate", _link_origins(description, HOMES[7])[1],
                        [0.2, 0.2, 0.2])
    SimulatedStation(scene=Scene(boxes=[crate]), robot=description)


@pytest.mark.parametrize("name, robot_name, joints", [
    ("trajectory_tracking_lbr", "lbr_omni", 7),
    ("trajectory_tracking_ur", "ur_omni", 6)])
def test_the_other_shipped_robots_track_the_papers_step(name, robot_name,
                                                         joints):
    """The second and third shipped robots (models/lbr_omni.robot.yaml: a
    7-joint LBR-class arm; models/ur_omni.robot.yaml: a UR5e-class arm
    with shoulder and wrist offsets and its built-in wrist sensor; both on
    the larger omni base) in their trajectory-tracking scenarios, 2.2 s
    of each: the tool takes up the 0.1 m/s step (in the ground truth,
    once settled) with every command within that robot's limits, and the
    tuning its demo proposes (in its description, which the scenario
    leaves to it)."""
    scenario = load_scenario(find_scenario(name))
    scenario.duration = 2.2
    robot = scenario_robot(scenario)
    assert robot.name == robot_name and len(robot.arm.joints) == joints
    arm = controller_arm(scenario)
    assert scenario.controller.capability_band is None
    params = controller_for(scenario)
    assert params.capability_band == robot.tuning.capability_band
    assert check_tuning(arm, params.capability_band,
                        params.capability.joint_limit_gain) == []
    loop = build_closed_loop(scenario, scenario.variants[0])
    log = simulate(loop, scenario.duration)
    v = log["truth.end_effector_velocity"]
    settled = (log.time > 1.8) & (log.time < 2.2)
    assert np.mean(v[settled, 0]) == pytest.approx(0.1, abs=0.01)
    assert np.max(np.abs(v[settled, 1])) < 0.01
    q = log["arm.position_command"]
    assert q.shape[1] == joints
    assert np.all(q >= arm.lower) and np.all(q <= arm.upper)
    speed = np.linalg.norm(log["base.velocity_command"][:, :2], axis=1)
    assert np.max(speed) <= 0.8 + 1e-9


def test_the_controllers_base_defaults_are_that_robots_own():
    """On the second shipped robot (0.8 m/s, 0.5 m/s^2, a 0.9 x 0.7 m
    footprint), a scenario for the shipped robot gets that robot's base
    limits, footprint and braking (its separation rule stops it from
    what its 0.5 m/s^2 can stop from) when the controller is built, not
    the shipped base's; a limit wider than its own or a footprint
    smaller than its own is refused,
    naming the field and that robot's own value."""
    scenario = load_scenario(find_scenario("trajectory_tracking"))
    lbr_file = (find_scenario("trajectory_tracking_lbr").parent.parent
                / "models" / "lbr_omni.robot.yaml")
    on_lbr = with_robot(scenario, lbr_file, echo=None)
    base = load_robot_description(lbr_file).base
    assert len(on_lbr.station.initial_arm_positions) == 7
    params = for_robot(on_lbr.controller, load_robot_description(lbr_file))
    assert params.safety.base_velocity_limits == tuple(base.velocity_limits)
    assert params.safety.base_acceleration_limits == tuple(
        base.acceleration_limits)
    assert params.base_cdmp.repulsion.half_sizes == tuple(
        base.footprint_half_sizes)
    controller = build_controller(on_lbr.controller,
                                  robot=controller_arm(on_lbr))
    limiter = controller.stages["base_limiter"]
    assert limiter.half_sizes == tuple(base.footprint_half_sizes)
    assert limiter.timing.deceleration == min(base.acceleration_limits[:2])
    wider = copy.deepcopy(on_lbr.controller)
    wider.safety.base_velocity_limits = (1.0, 1.0, 1.0)
    with pytest.raises(ValueError, match=re.escape(
            "safety.base_velocity_limits[0] = 1.0 is not allowed: must be "
            "at most the robot's own 0.8 m/s")):
        build_controller(wider, robot=controller_arm(on_lbr))
    smaller = copy.deepcopy(on_lbr.controller)
    smaller.base_cdmp.repulsion.half_sizes = (0.4, 0.3)
    a = base.footprint_half_sizes[0]
    with pytest.raises(ValueError, match=re.escape(
            f"base_cdmp.repulsion.half_sizes[0] = 0.4 is not allowed: must "
            f"be at least the robot's own {a!r} m")):
        build_controller(smaller, robot=controller_arm(on_lbr))


def test_a_base_loop_given_in_part_is_that_robots_own_elsewhere():
    """A scenario's station.base given in part ({loop: ringing}, or a lag
    alone) on the second shipped robot: the fields it leaves out are that
    robot's (0.8 m/s; 0.5 m/s^2 where no named loop sets them), not the
    shipped base's 1 m/s and 1 m/s^2; a lag alone brings a servo under
    it; and moved to that robot by --robot, the shaking scenario keeps
    its ringing loop with that robot's velocity limits."""
    from drake_wbc.station.drivers import BASE_LOOPS, own_base_loop

    lbr_file = (find_scenario("trajectory_tracking_lbr").parent.parent
                / "models" / "lbr_omni.robot.yaml")
    lbr = load_robot_description(lbr_file).base
    text = find_scenario("trajectory_tracking_lbr").read_text()
    assert "\n  base:" not in text
    station_line = "\nstation:\n"
    assert station_line in text

    def with_base(base, time_step=0.005):
        return load_scenario(text=text.replace(
            station_line, f"{station_line}  base: {base}\n").replace(
            "time_step: 0.005", f"time_step: {time_step}").replace(
            "robot: ../models", f"robot: {lbr_file.parent}"))

    ringing = with_base("{loop: ringing}").station.base
    assert ringing.velocity_limits == list(lbr.velocity_limits)
    assert ringing == own_base_loop(lbr, {"loop": "ringing"})
    assert ringing.acceleration_limits == BASE_LOOPS["ringing"][
        "acceleration_limits"]
    assert ringing.damping_ratio == 0.15
    lagging = with_base("{lag: 0.08}").station.base
    assert lagging.lag == 0.08 and lagging.servo_time_constant == 0.01
    assert lagging.velocity_limits == list(lbr.velocity_limits)
    assert lagging.acceleration_limits == list(lbr.acceleration_limits)
    quick = with_base("{lag: 0.03, velocity_limits: [0.5, 0.5, 0.5]}",
                      time_step=0.002).station.base
    assert quick.servo_time_constant == 0.25 * 0.03
    assert quick.velocity_limits == [0.5, 0.5, 0.5]
    assert quick.acceleration_limits == list(lbr.acceleration_limits)
    shaking = load_scenario(find_scenario("trajectory_tracking_shaking"))
    assert shaking.station.base.velocity_limits == [1.0, 1.0, 1.0]
    moved = with_robot(shaking, lbr_file, echo=None).station.base
    assert moved == ringing
    back = with_robot(with_robot(shaking, lbr_file, echo=None),
                      robot_file_of(shaking), echo=None).station.base
    assert back == shaking.station.base


def test_a_base_loop_filled_from_a_fast_robot_is_checked_at_load(tmp_path):
    """On a robot whose base loop lags 30 ms (a copy of the shipped one),
    a station.base given in part takes that lag, and is then checked
    against the station's step at load, as one given in full is: 5 ms
    is refused naming station.time_step and station.base.lag; a given
    field that the robot's lag cannot take is named as given (it was
    blamed on the robot's velocity_lag); and moved there by --robot, a
    loop is checked the same way."""
    shipped_file = robot_file_of(load_scenario(find_scenario(
        "trajectory_tracking")))
    fast = tmp_path / "fast.robot.yaml"
    fast.write_text(shipped_file.read_text().replace(
        "velocity_lag: 0.3", "velocity_lag: 0.03").replace(
        "drake_wbc: .", f"drake_wbc: {shipped_file.parent}"))
    text = find_scenario("trajectory_tracking").read_text()
    station_line = "\nstation:\n"
    assert station_line in text

    def with_base(base, time_step):
        return load_scenario(text=text.replace(
            station_line, f"{station_line}  base: {base}\n").replace(
            "time_step: 0.005", f"time_step: {time_step}")
            + f"robot: {fast}\n")

    assert with_base("{velocity_limits: [0.5, 0.5, 0.5]}", 0.002
                     ).station.base.lag == 0.03
    with pytest.raises(ValueError, match=re.escape(
            "text: station.time_step = 0.005 s is not allowed with "
            "station.base.lag = 0.03 s")):
        with_base("{velocity_limits: [0.5, 0.5, 0.5]}", 0.005)
    with pytest.raises(ValueError, match=re.escape(
            "text: station.base.servo_time_constant = 0.02 s is not "
            "allowed with lag = 0.03 s")):
        with_base("{servo_time_constant: 0.02}", 0.002)
    # Loops that suit the shipped robot's 0.2 s lag (a servo of 20 ms
    # under it, a 5 ms step), moved to the fast robot's 30 ms.
    for base, expected in (
            ("{servo_time_constant: 0.02}", "station.base."
             "servo_time_constant = 0.02 s is not allowed with lag = 0.03 s"),
            ("{velocity_limits: [0.5, 0.5, 0.5]}", "station.time_step = "
             "0.005 s is not allowed with station.base.lag = 0.03 s")):
        shipped = load_scenario(text=text.replace(
            station_line, f"{station_line}  base: {base}\n"))
        with pytest.raises(ValueError, match=re.escape(
                f"--robot = {str(fast)!r}: {expected}")):
            with_robot(shipped, fast, echo=None)


def test_the_start_is_checked_against_the_robots_footprint():
    """A post of radius 0.25 m whose axis stands 0.7 m ahead of the
    base's centre is clear of the shipped 0.8 m long base (0.3 m from its
    front) and overlaps a 1.0 m long one (0.2 m): the start check uses
    the robot's footprint."""

    shipped = shipped_robot().base
    longer = copy.deepcopy(shipped)
    longer.footprint_half_sizes = (0.5, 0.3)
    scene = Scene(cylinders=[CylinderObstacle(
        name="post", position=[0.7, 0.0], radius=0.25, height=1.0)])
    check_start_is_free(scene, [0.0, 0.0, 0.0], shipped)
    with pytest.raises(ValueError, match=re.escape(
            "scene.cylinders[0] ('post') is not allowed with "
            "station.initial_base_pose = [0.0, 0.0, 0.0]: it overlaps the "
            "base's 1.0 x 0.6 m footprint")):
        check_start_is_free(scene, [0.0, 0.0, 0.0], longer)

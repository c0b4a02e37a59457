"""The simulated station: the robot in its scene, as one Drake Diagram.

::

                              ┌───────────────────┐
    base.velocity_command ───►│                   ├──► base.state_estimated
    arm.position_command ────►│                   ├──► arm.position_measured
                              │                   ├──► arm.velocity_estimated
                              │                   ├──► arm.fault
                              │ SimulatedStation  ├──► wrist.wrench_measured
                              │                   ├──► lidar.obstacle_points
                              │                   ├──► lidar.<scanner>.ranges
                              │                   ├──► truth.* (metrics)
                              │                   ├──► query_object
                              └───────────────────┘

Inside: a discrete MultibodyPlant (SAP, StationOptions.time_step: 1 ms
by default, 5 ms in the scenarios) of the robot of models/ and the
scene's static obstacles; the base's velocity loop and the arm's position
servo (the math of drake_wbc.station.driver_dynamics, run as C++
SymbolicVectorSystems, drake_wbc.station.symbolic_drivers), behind the
arm's servo interface, which faults the arm on a command beyond its own
joint limits as the real arm's does (drake_wbc.station.arm_supervisor:
it brakes to rest and stays; `arm.fault` 1, `SimulatedStation.arm_fault`
says why); the FT-300 on
the weld `ft300_sensing`; two TiM571 LIDARs that see the static obstacles
and the walking people at their scan plane; the person's hand on the
tool. The ports named like the LCM hardware interface's are all the
controller may read; `arm.fault` and `truth.*` are for metrics and
plots, `query_object` for visualisation.

What runs at every plant step is C++ (the plant, the drivers, the base
pose's selection); the Python systems run at their sensors' rates (the
FT-300 at 100 Hz, the LIDARs at 15 Hz), the arm's servo interface at its
command period (100 Hz), the scripted scene every
`scene_period`, and the ground truth only when read.

    station = SimulatedStation(StationOptions(), scene)
    builder.AddSystem(station.diagram)
    ...
    station.set_initial_state(root_context)

`set_initial_state` also takes the station's own context, so a station
that is part of a closed loop can still be analysed alone
(drake_wbc.analysis.plant_chain).
"""

from dataclasses import dataclass, field

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import ModelInstanceIndex, MultibodyForces
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import (
    ConstantValueSource,
    ConstantVectorSource,
    Demultiplexer,
    MatrixGain,
    Multiplexer,
)

from drake_wbc.math.validation import (
    as_vector,
    checked_instance,
    positive,
    validated_copy,
    whole_multiple,
    within_site,
)
from drake_wbc.robot.description import RobotDescription, shipped_robot
from drake_wbc.robot.model import (
    ArmMount,
    add_robot,
    check_self_contacts,
    joint_position_indices,
    joint_velocity_indices,
    scoped_joint_name,
    shared_robot_plant,
    spring_stiffnesses,
    suspension_gains,
)
from drake_wbc.robot.suspension import SuspensionParameters
from drake_wbc.station.arm_supervisor import ArmCommandSupervisor
from drake_wbc.station.drivers import (
    ArmDriverParameters,
    BaseDriverParameters,
    check_arm_time_step,
    check_base_time_step,
    own_base_loop,
)
from drake_wbc.station.force_torque import (
    ForceTorqueSensorParameters,
    WeldWrench,
    WristForceTorqueSensor,
)
from drake_wbc.station.hand import (
    add_hand_body,
    add_hand_intention,
    torque_only,
)
from drake_wbc.station.lidar import (
    LidarParameters,
    ObstaclePointMerger,
    PlanarLidar,
)
from drake_wbc.station.scene import (
    Scene,
    add_static_obstacles,
    people_at_height,
    planar_shapes,
)
from drake_wbc.station.scene_sources import add_hand, add_people
from drake_wbc.station.servo_gains import (
    drive_inertias,
    mass_on_wheels,
    servo_gains,
    set_drive_inertias,
    set_servo_gains,
)
from drake_wbc.station.state_sensors import (
    GroundTruth,
    base_state_selection,
    odometry_system,
    selection_matrix,
)
from drake_wbc.station.symbolic_drivers import (
    arm_interpolator_state,
    arm_interpolator_system,
    base_loop_state,
    base_loop_system,
    joint_rates_system,
)
from drake_wbc.station.traction import (
    TractionParameters,
    own_traction,
    set_traction_limits,
    traction_limits,
)

MAX_TIME_STEP = 0.005
"""s, the coarsest plant step allowed: eight steps a period of the arm
servo's 25 Hz and 25 of the mount's rocking mode (at most 8 Hz), and the
control period (0.01 s) a whole multiple of it."""

MIN_TIME_STEP = 1e-5
"""s, the finest plant step allowed (the default is 1 ms): at 10 us a
simulated second takes 100,000 steps of the plant and its Python systems,
hours of wall time; a finer step only stalls the run."""

def lidar_name(frame):
    """A scanner's name in port names: its frame's name without a leading
    `lidar_` (`lidar_front_left` -> `front_left`)."""
    name = frame.name()
    return name[len("lidar_"):] if name.startswith("lidar_") else name


def lidar_names(model):
    """The `lidar_name`s of the scanners of RobotModel `model`, in its
    description's order.

    Raises:
        ValueError: naming lidar_frames[i] when two frames give one name
            (their ports and systems would be one), or a frame gives
            `points` (the name of the scanners' merged points).
    """
    frames = model.description.lidar_frames
    names = []
    for i, frame in enumerate(model.lidar_frames):
        name = lidar_name(frame)
        if name == "points":
            raise ValueError(
                f"lidar_frames[{i}] = {frames[i]!r} is not allowed: its "
                "scanner's name would be 'points', the name of the "
                "scanners' merged points (lidar.obstacle_points); name the "
                "frame otherwise")
        if name in names:
            j = names.index(name)
            raise ValueError(
                f"lidar_frames[{i}] = {frames[i]!r} is not allowed: its "
                f"scanner's name {name!r} (the frame's name without a "
                f"leading lidar_, as in lidar.{name}.ranges) is that of "
                f"lidar_frames[{j}] = {frames[j]!r}; name the frames apart")
        names.append(name)
    return tuple(names)


@dataclass
class StationOptions:
    """How the simulated station is built (a scenario's `station:`).

    Attributes:
        time_step: the plant's discrete step in s (MIN_TIME_STEP, 10 us,
            to MAX_TIME_STEP, 5 ms); the drivers run at it too.
        scene_period: s, how often the scripted scene's hand wrench and
            the people's drawn poses are sampled (held in between); a
            whole multiple of time_step (0.01 s, the control period).
        base: the base's velocity loop (BaseDriverParameters: a named
            loop, smooth, jerky or ringing, or its own values); None (the
            default): the robot's own, a first-order loop of its
            description's velocity_lag and limits (`own_base_loop`), which
            the station's `options` then hold.
        suspension: None (the default: the chassis rigid on its wheels) or
            the suspension's modes between the wheels and the chassis
            (drake_wbc.robot.suspension: spring-damper joints in roll and
            pitch, sized to the modes with the arm at
            initial_arm_positions; with `horizontal`, the wheels' shear on
            the floor in x, y and yaw too, which the odometry and
            truth.base_pose, read from the driven joints like wheel
            odometry, do not see).
        traction: None (the default: the wheels never slip) or the
            TractionParameters of the wheels' grip on the floor
            (drake_wbc.station.traction: the base's drive force saturated
            at mu m g, a slip law).
        arm: the arm's position servo.
        wrist: the FT-300 model (noise and quantisation of the real
            sensor by default; ForceTorqueSensorParameters.ideal() for
            none).
        lidar: the TiM571 model of both scanners.
        initial_base_pose: [x, y, yaw] of T_b in the world at the start,
            yaw within +-2 pi rad.
        initial_arm_positions: the arm's configuration at the start (rad),
            one a joint, within the joints' limits (checked against the
            robot when the station is built: `check_arm_start`); None (the
            default): the home of the robot the station builds (its
            description's arm.home), which the station's `options` then
            hold.

    The drivers run at `time_step`: base.lag must be at least 10
    time_step, arm.command_period a whole multiple of it and
    arm.servo_frequency below 1 / (2 time_step); the sensors sample at
    most once a step (wrist.rate and lidar.rate at most 1 / time_step),
    and the base starts within the scene's site
    (drake_wbc.math.validation.SITE_EXTENT).
    """

    time_step: float = 0.001
    scene_period: float = 0.01
    base: BaseDriverParameters | None = None
    suspension: SuspensionParameters | None = None
    traction: TractionParameters | None = None
    arm: ArmDriverParameters = field(default_factory=ArmDriverParameters)
    wrist: ForceTorqueSensorParameters = field(
        default_factory=ForceTorqueSensorParameters)
    lidar: LidarParameters = field(default_factory=LidarParameters)
    initial_base_pose: list[float] = field(
        default_factory=lambda: [0.0, 0.0, 0.0])
    initial_arm_positions: list[float] | None = None

    def __post_init__(self):
        h = positive("time_step", self.time_step)
        if not MIN_TIME_STEP <= h <= MAX_TIME_STEP:
            raise ValueError(f"time_step = {h!r} s is not allowed: must be "
                             f"at least {MIN_TIME_STEP!r} s (10 us) and at "
                             f"most {MAX_TIME_STEP!r} s (5 ms)")
        self.base = checked_instance("base", self.base,
                                     BaseDriverParameters, lambda: None)
        for name, kind in (("arm", ArmDriverParameters),
                           ("wrist", ForceTorqueSensorParameters),
                           ("lidar", LidarParameters)):
            setattr(self, name, checked_instance(name, getattr(self, name),
                                                 kind, kind))
        self.suspension = checked_instance(
            "suspension", self.suspension, SuspensionParameters,
            lambda: None)
        self.traction = checked_instance(
            "traction", self.traction, TractionParameters, lambda: None)
        # The drivers run at the plant's step, which only this field
        # gives (the robot's own base loop is checked when the station
        # builds it).
        if self.base is not None:
            check_base_time_step(self.base, "time_step", h, prefix="base.")
        check_arm_time_step(self.arm, "time_step", h, prefix="arm.")
        whole_multiple("scene_period", self.scene_period, "time_step", h)
        for name in ("wrist", "lidar"):
            rate = getattr(self, name).rate
            if rate > 1.0 / h:
                raise ValueError(
                    f"{name}.rate = {rate!r} Hz is not allowed with "
                    f"time_step = {h!r} s: must be at most 1 / time_step = "
                    f"{1.0 / h:.6g} Hz (the simulated world changes once a "
                    "plant step; a faster sensor reads nothing new and "
                    "stalls the simulation)")
        pose = as_vector("initial_base_pose", self.initial_base_pose, 3)
        within_site("initial_base_pose", self.initial_base_pose, pose[:2])
        if abs(pose[2]) > 2.0 * np.pi:
            raise ValueError(
                f"initial_base_pose[2] = {float(pose[2])!r} rad is not "
                "allowed: the heading must lie within +-2 pi rad (one turn "
                "either way); far beyond, a step of the yaw rate is lost "
                "in the rounding of the angle and the base cannot turn")
        if self.initial_arm_positions is not None:
            as_vector("initial_arm_positions", self.initial_arm_positions)


def check_arm_start(positions, lower, upper, path="initial_arm_positions"):
    """Checks the arm's start `positions` against the robot's joints:
    one value a joint, each within [lower, upper] (rad); a ValueError
    naming `path` otherwise."""
    q = as_vector(path, positions)
    if q.size != len(lower):
        raise ValueError(
            f"{path} = {q.tolist()} is not allowed: the robot's arm has "
            f"{len(lower)} joints, give one value for each")
    bad = np.flatnonzero((q < lower) | (q > upper))
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"{path}[{i}] = {float(q[i])!r} rad is not allowed: must lie "
            f"within the joint's limits [{float(lower[i])!r}, "
            f"{float(upper[i])!r}] rad")


def add_desired_states(builder, plant, model, base_desired, arm_desired):
    """Feeds the plant's servos: `base_desired` (an output port, the base's
    planar joints' [q (3); v (3)]) and `arm_desired` (the arm's [q (n);
    v (n)]) each to its model instance's desired state, or, for a robot
    whose base and arm are one model instance (one URDF), both through a
    Multiplexer ("drives") and a MatrixGain ("desired_state") that
    permutes them into the order of the instance's actuators. Returns
    the systems it added, by name.

    Raises:
        ValueError: naming the joint of an actuator in the base's or the
            arm's model instance that is not one of their joints (the
            desired states drive those alone), or a shared instance
            whose actuated joints are not exactly the base's and the
            arm's.
    """
    driven = {j.index() for j in model.base_joints + model.arm_joints}
    for instance in dict.fromkeys((model.base, model.arm)):
        for index in plant.GetJointActuatorIndices(instance):
            joint = plant.get_joint_actuator(index).joint()
            if joint.index() not in driven:
                raise ValueError(
                    f"the actuator of {scoped_joint_name(plant, joint)!r} "
                    "is not allowed in the "
                    "simulated station: it drives "
                    "only base.joints and arm.joints, through their model "
                    "instances' desired states; leave that joint without an "
                    "actuator in the model (in a URDF, without a "
                    "<transmission>)")
    if model.base != model.arm:
        builder.Connect(base_desired,
                        plant.get_desired_state_input_port(model.base))
        builder.Connect(arm_desired,
                        plant.get_desired_state_input_port(model.arm))
        return {}
    n = model.num_arm_joints
    drives = {j.index(): i for i, j in enumerate(model.base_joints)}
    drives.update({j.index(): 6 + i for i, j in enumerate(model.arm_joints)})
    order = [plant.get_joint_actuator(a).joint().index()
             for a in plant.GetJointActuatorIndices(model.base)]
    if sorted(order) != sorted(drives):
        raise ValueError(
            "robot is not allowed: its base and arm share a model instance "
            "whose actuated joints are not exactly the base's and the arm's "
            "joints")
    permutation = np.zeros((2 * len(order), 6 + 2 * n))
    for row, joint in enumerate(order):
        q_column = drives[joint]
        v_column = q_column + (3 if q_column < 6 else n)
        permutation[row, q_column] = 1.0
        permutation[len(order) + row, v_column] = 1.0
    added = {
        "drives": builder.AddNamedSystem("drives", Multiplexer([6, 2 * n])),
        "desired_state": builder.AddNamedSystem("desired_state",
                                                MatrixGain(permutation)),
    }
    builder.Connect(base_desired, added["drives"].get_input_port(0))
    builder.Connect(arm_desired, added["drives"].get_input_port(1))
    builder.Connect(added["drives"].get_output_port(),
                    added["desired_state"].get_input_port())
    builder.Connect(added["desired_state"].get_output_port(),
                    plant.get_desired_state_input_port(model.base))
    return added


def arm_state_output(builder, plant, model):
    """(port, added): an output port of the arm's [q (n); v (n)]: its model
    instance's state, or, where the base and the arm are one instance,
    a selection of the plant's state (a MatrixGain "arm_joints", in
    `added`, by name)."""
    if model.base != model.arm:
        return plant.get_state_output_port(model.arm), {}
    nq = plant.num_positions()
    selection = builder.AddNamedSystem("arm_joints", MatrixGain(
        selection_matrix(np.concatenate([
            joint_position_indices(model.arm_joints),
            nq + joint_velocity_indices(model.arm_joints)]),
            plant.num_multibody_states())))
    builder.Connect(plant.get_state_output_port(),
                    selection.get_input_port())
    return selection.get_output_port(), {"arm_joints": selection}


class SimulatedStation:
    """The built station: its Diagram and the parts inside it.

    Attributes:
        diagram: the station Diagram (ports in the module's docstring).
        plant, scene_graph, model: the plant, its SceneGraph and the
            robot's RobotModel.
        systems: dict of the station's other systems by name.
        options, scene: what it was built from.

    Args:
        options: StationOptions (defaults if None).
        scene: the Scene (an empty one if None).
        mount: the robot's ArmMount (drake_wbc.robot.model), the arm's
            rotation on the base: the shipped robot's (none) if None. The
            controller's ArmKinematics must be made with the same one.
        robot: the RobotDescription (the shipped robot's if None).

    Raises:
        ValueError: naming the field, where the options do not fit the
            robot or its description its model (add_robot), or where the
            robot's own bodies overlap at its arm.home or at
            initial_arm_positions (check_self_contacts: the simulation
            is the one place where they would touch).
    """

    def __init__(self, options=None, scene=None, mount=None, robot=None):
        # Checked once, here, for every part below (which keep them).
        self.options = options = validated_copy(checked_instance(
            "options", options, StationOptions, StationOptions))
        self.scene = scene = validated_copy(
            checked_instance("scene", scene, Scene, Scene))
        mount = checked_instance("mount", mount, ArmMount, ArmMount)
        robot = checked_instance("robot", robot, RobotDescription,
                                 shipped_robot)
        h = options.time_step
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(
            time_step=h, discrete_contact_approximation="sap",
            contact_model="hydroelastic_with_fallback",
            use_sampled_output_ports=False), builder)
        # The start first: the gains below are sized at it. A start left
        # out is this robot's home (a configuration belongs to one arm).
        starts = [("arm.home", robot.arm.home)]
        if options.initial_arm_positions is None:
            options.initial_arm_positions = list(robot.arm.home)
        elif list(options.initial_arm_positions) != list(robot.arm.home):
            starts.append(("station.initial_arm_positions",
                           options.initial_arm_positions))
        # The base's velocity loop: the robot's own where the options
        # give none.
        if options.base is None:
            options.base = own_base_loop(robot.base)
            check_base_time_step(options.base, "time_step", h,
                                 prefix="the robot's own base loop's ")
        # The wheels' lever where they slip: the robot's own where the
        # options give none.
        if options.traction is not None:
            options.traction = own_traction(options.traction, robot.base,
                                            prefix="traction.")
        self._arm_limits = limits = shared_robot_plant(
            robot, mount=mount)[1].limits
        check_arm_start(options.initial_arm_positions, limits.lower,
                        limits.upper, "station.initial_arm_positions")
        self._robot, self._mount = robot, mount
        self._suspension = suspension = (
            None if options.suspension is None else suspension_gains(
                options.suspension, options.initial_arm_positions, robot,
                mount))
        self._gains = servo_gains(
            options.initial_arm_positions, options.base, options.arm, robot,
            mount=mount, base_drive_inertia=None if suspension is None
            else suspension.drive_inertia)
        self._traction = None if options.traction is None else (
            traction_limits(options.traction, mass_on_wheels(
                options.initial_arm_positions, robot, mount=mount),
                np.linalg.norm(plant.gravity_field().gravity_vector())))
        self._drive_inertias = drive_inertias(
            options.initial_arm_positions, options.arm, robot, mount=mount)
        first = plant.num_model_instances()
        model = self.add_robot_to(plant)
        self._instances = tuple(ModelInstanceIndex(i) for i in range(
            first, plant.num_model_instances()))
        add_static_obstacles(plant, scene)
        self.hand_body = None if scene.hand.impedance is None else (
            add_hand_body(plant, model, scene.hand.impedance))
        plant.Finalize()
        self.plant, self.scene_graph, self.model = plant, scene_graph, model
        self.lidar_names = lidar_names(model)
        add = builder.AddNamedSystem
        s = self.systems = {}
        # The odometry and the parts of the state read at every plant step
        # or control tick, in C++.
        s["base_state"] = add("base_state", MatrixGain(
            base_state_selection(plant, model)))
        s["odometry"] = add("odometry", odometry_system())
        s["base_pose"] = add("base_pose", MatrixGain(selection_matrix(
            joint_position_indices(model.base_joints),
            plant.num_multibody_states())))
        # The passive joints' angles (the mount's); none: an empty signal.
        s["mount_angles"] = add("mount_angles", MatrixGain(selection_matrix(
            joint_position_indices(model.passive_joints),
            plant.num_multibody_states())) if model.passive_joints
            else ConstantVectorSource(np.zeros(0)))
        s["truth"] = add("truth", GroundTruth(plant, model))
        # The drivers, in C++ (drake_wbc.station.symbolic_drivers): they
        # run at every plant step.
        s["base_driver"] = add("base_driver", base_loop_system(
            options.base, h))
        s["base_rates_input"] = add("base_rates_input", Multiplexer([3, 3]))
        s["base_rates"] = add("base_rates", joint_rates_system())
        s["arm_driver"] = add("arm_driver", arm_interpolator_system(
            options.arm, options.initial_arm_positions))
        # The arm's servo interface before it: a command beyond the
        # arm's own limits faults it (in Python, once a command period).
        s["arm_supervisor"] = add("arm_supervisor", ArmCommandSupervisor(
            options.arm.command_period, options.initial_arm_positions,
            self._arm_limits, robot.arm.joints))
        n = model.num_arm_joints
        s["arm_state"] = add("arm_state", Demultiplexer([n, n]))
        s["weld_wrench"] = add("weld_wrench", WeldWrench(
            plant, model.ft_sensor_joint, model.ft_measurement_frame))
        s["wrist"] = add("wrist", WristForceTorqueSensor(
            options.wrist, robot.tool.ft_sensor_range))
        s["people"] = add_people(builder, scene_graph, scene.people,
                                 options.scene_period)
        if self.hand_body is None:
            s["hand"] = add_hand(builder, plant, model, scene.hand,
                                 options.scene_period)
            hand_force = s["hand"].GetOutputPort("force")
        else:
            # A hand with impedance: the push through its spring and
            # damper in the plant, its twist a scripted torque.
            s["hand"] = add_hand(builder, plant, model,
                                 torque_only(scene.hand),
                                 options.scene_period)
            s["hand_intention"] = add_hand_intention(
                builder, plant, self.hand_body, scene.hand,
                options.scene_period)
            hand_force = s["hand_intention"].GetOutputPort("force")
        connect = builder.Connect
        state = plant.get_state_output_port()
        connect(state, s["base_state"].get_input_port())
        connect(s["base_state"].get_output_port(),
                s["odometry"].get_input_port())
        connect(state, s["truth"].GetInputPort("plant_state"))
        connect(state, s["base_pose"].get_input_port())
        if model.passive_joints:
            connect(state, s["mount_angles"].get_input_port())
        connect(s["arm_supervisor"].GetOutputPort("position_command"),
                s["arm_driver"].get_input_port())
        connect(s["base_driver"].get_output_port(),
                s["base_rates_input"].get_input_port(0))
        connect(s["base_pose"].get_output_port(),
                s["base_rates_input"].get_input_port(1))
        connect(s["base_rates_input"].get_output_port(),
                s["base_rates"].get_input_port())
        s.update(add_desired_states(
            builder, plant, model, s["base_rates"].get_output_port(),
            s["arm_driver"].get_output_port()))
        arm_state, selection = arm_state_output(builder, plant, model)
        s.update(selection)
        connect(arm_state, s["arm_state"].get_input_port())
        connect(plant.get_reaction_forces_output_port(),
                s["weld_wrench"].GetInputPort("reaction_forces"))
        connect(s["weld_wrench"].GetOutputPort("wrench"),
                s["wrist"].GetInputPort("wrench"))
        self._add_lidars(builder, scene)

        export_in, export_out = builder.ExportInput, builder.ExportOutput
        export_in(s["base_driver"].get_input_port(),
                  "base.velocity_command")
        export_in(s["arm_supervisor"].GetInputPort("position_command"),
                  "arm.position_command")
        outputs = (
            (s["odometry"].get_output_port(),
             "base.state_estimated"),
            (s["arm_state"].get_output_port(0), "arm.position_measured"),
            (s["arm_state"].get_output_port(1), "arm.velocity_estimated"),
            (s["wrist"].GetOutputPort("wrench_measured"),
             "wrist.wrench_measured"),
            (self._points,
             "lidar.obstacle_points"),
            *((s[f"lidar_{n}"].GetOutputPort("ranges"),
               f"lidar.{n}.ranges") for n in self.lidar_names),
            *((s["truth"].GetOutputPort(n), f"truth.{n}") for n in (
                "end_effector_pose", "end_effector_velocity")),
            (s["base_pose"].get_output_port(), "truth.base_pose"),
            (s["mount_angles"].get_output_port(), "truth.mount_angles"),
            (s["base_driver"].get_output_port(),
             "truth.base_loop_velocity"),
            (s["weld_wrench"].GetOutputPort("wrench"), "truth.wrist_wrench"),
            (hand_force, "truth.hand_force"),
            (s["people"].GetOutputPort("positions"), "truth.people_positions"),
            (scene_graph.get_query_output_port(), "query_object"),
            (s["arm_supervisor"].GetOutputPort("fault"), "arm.fault"),
        )
        for port, name in outputs:
            export_out(port, name)
        self.diagram = builder.Build()
        self.diagram.set_name("simulated_station")
        # Where the simulation starts, and the home (every station's
        # robot goes there), the robot's own bodies must not overlap.
        context = self.diagram.CreateDefaultContext()
        plant_context = plant.GetMyMutableContextFromRoot(context)
        for path, positions in starts:
            self._set_start_positions(plant_context, positions)
            check_self_contacts(plant, plant_context, self._instances, path,
                                positions)

    def _add_lidars(self, builder, scene):
        """The robot's scanners (its description's lidar_frames), each
        seeing the static obstacles and the people at its height, and the
        merger of their points."""
        plant, model, s = self.plant, self.model, self.systems
        context = plant.CreateDefaultContext()
        if not self.lidar_names:  # a robot without scanners sees nothing
            s["lidar_points"] = builder.AddNamedSystem(
                "lidar_points", ConstantValueSource(
                    AbstractValue.Make(np.zeros((0, 2)))))
            self._points = s["lidar_points"].get_output_port()
            return
        s["lidar_points"] = builder.AddNamedSystem(
            "lidar_points", ObstaclePointMerger(len(self.lidar_names)))
        self._points = s["lidar_points"].GetOutputPort("points")
        for i, (name, frame) in enumerate(zip(self.lidar_names,
                                              model.lidar_frames,
                                              strict=True)):
            X_BL = frame.CalcPose(context, model.base_frame)
            yaw = np.arctan2(X_BL.rotation().matrix()[1, 0],
                             X_BL.rotation().matrix()[0, 0])
            height = X_BL.translation()[2]
            circles, boxes = planar_shapes(scene, height)
            # The people it sees: those as tall as its scan plane.
            seen = people_at_height(scene, height)
            lidar = s[f"lidar_{name}"] = builder.AddNamedSystem(
                f"lidar_{name}", PlanarLidar(
                    self.options.lidar,
                    mount=(*X_BL.translation()[:2], yaw),
                    circles=circles, boxes=boxes,
                    moving_radii=[scene.people[j].radius for j in seen]))
            builder.Connect(s["base_pose"].get_output_port(),
                            lidar.GetInputPort("base_pose"))
            positions = s["people"].GetOutputPort("positions")
            if seen and len(seen) < len(scene.people):
                select = s[f"lidar_{name}_people"] = builder.AddNamedSystem(
                    f"lidar_{name}_people", MatrixGain(selection_matrix(
                        [k for j in seen for k in (2 * j, 2 * j + 1)],
                        2 * len(scene.people))))
                builder.Connect(positions, select.get_input_port())
                positions = select.get_output_port()
            if seen:
                builder.Connect(positions,
                                lidar.GetInputPort("moving_positions"))
            builder.Connect(lidar.GetOutputPort("points"),
                            s["lidar_points"].GetInputPort(f"points_{i}"))

    def add_robot_to(self, plant):
        """Adds the station's robot to `plant` (not finalised) as the
        station's own plant has it: its suspension and its arm's mount,
        its servo gains, traction limits and drive inertias. Returns its
        RobotModel. The station's plant is made with it, and so are the
        analyses' copies of it (drake_wbc.analysis.plant_chain): the
        values, sized once when the station was made, are the same."""
        model = add_robot(plant, self._robot, suspension=self._suspension,
                          mount=self._mount)
        set_servo_gains(plant, model, self._gains)
        if self._traction is not None:
            set_traction_limits(plant, model, self._traction)
        set_drive_inertias(plant, model, self._drive_inertias)
        return model

    def set_initial_state(self, context):
        """Puts the robot at the options' initial pose, at rest and in
        static equilibrium (the mount's sag and the arm servo's droop
        under gravity), with the drivers holding it there. (The sensors
        take their first reading when the Simulator initializes.)

        Args:
            context: the root context of a diagram that holds the
                station, or the station diagram's own context (its
                `CreateDefaultContext()`, also once the station is part
                of another diagram).
        """
        options, plant, model = self.options, self.plant, self.model
        own = self._own_context(context)

        def of(system):
            return self.diagram.GetMutableSubsystemContext(system, own)

        plant_context = of(plant)
        q_cmd = np.asarray(options.initial_arm_positions, dtype=float)
        self._set_start_positions(plant_context, q_cmd)
        plant.SetVelocities(plant_context, np.zeros(plant.num_velocities()))
        self._settle_under_gravity(plant_context, q_cmd)
        # What the wrist sensor carries is rigid: its joints (a gripper's)
        # held where the model puts them at rest.
        for joint in model.locked_joints:
            joint.Lock(plant_context)
        if self.hand_body is not None:
            # The hand at rest on the tool centre point.
            p_tcp = model.tcp_frame.CalcPoseInWorld(
                plant_context).translation()
            q = plant.GetPositions(plant_context)
            q[self.hand_body.position_indices()] = p_tcp
            plant.SetPositions(plant_context, q)
            intention = self.systems["hand_intention"]
            of(intention).SetDiscreteState(
                intention.initial_state(p_tcp, own.get_time()))
        of(self.systems["base_driver"]).SetDiscreteState(
            base_loop_state(options.base, np.zeros(3)))
        of(self.systems["arm_driver"]).SetDiscreteState(
            arm_interpolator_state(q_cmd, own.get_time(),
                                   options.initial_arm_positions))
        self.systems["arm_supervisor"].set_positions(of(
            self.systems["arm_supervisor"]), q_cmd)

    def arm_fault(self, context):
        """The arm's fault (an ArmFault, drake_wbc.station.arm_supervisor:
        when, which joint, which limit; its `message()`) in `context` (a
        root context holding the station, or the station's own), or None
        while the arm has not faulted."""
        supervisor = self.systems["arm_supervisor"]
        return supervisor.fault(self.diagram.GetSubsystemContext(
            supervisor, self._own_context(context)))

    def _own_context(self, context):
        """The station diagram's own context in `context`: the root
        context of a diagram that holds the station, or the station's own
        context itself."""
        try:
            self.diagram.ValidateContext(context)
        except RuntimeError:
            return self.diagram.GetMyMutableContextFromRoot(context)
        return context

    def _compliant_joints(self):
        """The base's spring-damper joints: the passive ones of the robot
        (the mount's), then the suspension's if the station has one (and
        its horizontal compliance's)."""
        model = self.model
        return (model.passive_joints + model.suspension_joints
                + model.horizontal_joints)

    def _set_start_positions(self, plant_context, arm_positions):
        """Puts the robot in `plant_context` at the options' base pose
        with the arm at `arm_positions`, the base's spring-damper joints
        at rest and what the wrist sensor carries as its model has it."""
        options, plant, model = self.options, self.plant, self.model
        q = plant.GetPositions(plant_context)
        q[joint_position_indices(model.base_joints)] = (
            options.initial_base_pose)
        q[joint_position_indices(model.arm_joints)] = arm_positions
        q[joint_position_indices(self._compliant_joints())] = 0.0
        for joint in model.locked_joints:
            start = joint.position_start()
            q[start:start + joint.num_positions()] = (
                joint.default_positions())
        plant.SetPositions(plant_context, q)

    def _settle_under_gravity(self, context, q_cmd, iterations=30):
        """Moves the mount's (and the suspension's) and the arm's joints to
        where the springs and the arm's servo balance gravity (fixed-point
        iteration with each joint's own stiffness; gravity's stiffness is
        far smaller)."""
        plant, model = self.plant, self.model
        springs = spring_stiffnesses(plant)
        compliant = self._compliant_joints()
        n = len(compliant)
        iq = np.concatenate([
            joint_position_indices(compliant),
            joint_position_indices(model.arm_joints)])
        iv = np.concatenate([
            joint_velocity_indices(compliant),
            joint_velocity_indices(model.arm_joints)])
        stiffness = np.array(
            [springs[j.index()] for j in compliant]
            + [self._gains[name].p for name in model.description.arm.joints])
        target = np.concatenate([np.zeros(n), q_cmd])
        forces = MultibodyForces(plant)
        for _ in range(iterations):
            plant.CalcForceElementsContribution(context, forces)
            tau = plant.CalcGeneralizedForces(context, forces)[iv]
            q = plant.GetPositions(context)
            servo = np.concatenate([np.zeros(n), -stiffness[n:] * (
                q[iq[n:]] - target[n:])])
            q[iq] += (tau + servo) / stiffness
            plant.SetPositions(context, q)

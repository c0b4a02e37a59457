"""The robot's model in Drake, from its description.

Loads a robot described by a `RobotDescription` (drake_wbc.robot.description;
the shipped one by default: models/mcr.robot.yaml, the paper's 6-joint
cobot on an omnidirectional base) into a `MultibodyPlant`, finds its
parts, checks the description against the model, and computes the two kinematic
quantities that the controller needs from the arm's configuration: the
arm Jacobian J_a and the end-effector position in the base frame (paper,
Sec. III-A)::

    plant = MultibodyPlant(time_step=0.001)
    model = add_robot(plant)                 # or add_robot(plant, mine)
    plant.Finalize()
    arm = ArmKinematics(plant, model)

The shipped model files are found through Drake's package map under the
package name `drake_wbc`, so they load with no network.
"""

import math
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np
from pydrake.common.schema import Transform
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.parsing import (
    LoadModelDirectives,
    Parser,
    ProcessModelDirectives,
)
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    BodyIndex,
    ForceElementIndex,
    Frame,
    JacobianWrtVariable,
    Joint,
    JointIndex,
    ModelInstanceIndex,
    PrismaticSpring,
    RevoluteSpring,
    ScopedName,
)

from drake_wbc.math.chain import (
    PRISMATIC,
    REVOLUTE,
    SerialChain,
    chain_kinematics_of,
    origin_in,
)
from drake_wbc.math.kernels import body_for
from drake_wbc.math.validation import (
    as_float_array,
    as_scalar,
    as_vector,
    checked_instance,
)
from drake_wbc.robot.description import (
    RobotDescription,
    check_model_files,
    file_prefix,
    models_dir,
    shipped_robot,
)
from drake_wbc.robot.suspension import (
    HORIZONTAL_JOINTS,
    SUSPENSION_JOINTS,
    SuspensionGains,
    suspended_base_sdf,
)

LIBRARY_PACKAGE = "drake_wbc"
"""The package name of the library's models folder (models/: the bases,
tools and arms it ships), which every robot's parser knows."""

HOME_ARM_POSITIONS = np.array(shipped_robot().arm.home)
"""The shipped robot's home configuration (rad), from its description:
the default start of the simulated station and of the controller."""


@dataclass
class ArmMount:
    """How the arm is mounted on the base: the rotation ^bR_a of T_a in
    T_b (paper, eq. (fk)), about the mount point.

    ^bR_a = Rz(yaw) Ry(tilt): the arm turned by `yaw` about the base's
    vertical, then its column tilted by `tilt` about its own y axis (a
    positive tilt leans the arm's z axis towards its own +x). The
    default, no rotation, is the robot as its model has it. It sets the
    rotation of the weld that mounts the arm in the model directives (the
    one whose child is the description's arm.base_frame; its translation,
    the mount point, stays as the model has it), given to
    `add_robot` (and so to the station and to `ArmKinematics`): a scenario
    turns or tilts the arm of a described robot without another model.

    Attributes:
        yaw: rad, in [-pi, pi].
        tilt: rad, in [-pi/2, pi/2] (pi/2: the arm on a wall of the base).
    """

    yaw: float = 0.0
    tilt: float = 0.0

    def __post_init__(self):
        for name, bound in (("yaw", math.pi), ("tilt", 0.5 * math.pi)):
            value = as_scalar(name, getattr(self, name))
            if not -bound <= value <= bound:
                raise ValueError(
                    f"{name} = {value!r} rad is not allowed: must lie in "
                    f"[{-bound!r}, {bound!r}] rad")
            setattr(self, name, float(value))

    @property
    def is_identity(self):
        """True for the shipped robot's mount (^bR_a = I)."""
        return self.yaw == 0.0 and self.tilt == 0.0

    def rotation(self):
        """^bR_a (3, 3), the rotation of T_a in T_b."""
        return (RotationMatrix.MakeZRotation(self.yaw)
                @ RotationMatrix.MakeYRotation(self.tilt)).matrix()


class ArmLimits(NamedTuple):
    """The arm's own limits, (n,) each: the model's, or the description's
    where tighter.

    Attributes:
        lower, upper: joint position limits, rad; -inf and inf for a
            continuous joint, which has none.
        velocity: joint speed limits, rad/s.
        acceleration: joint acceleration limits, rad/s^2.
    """

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray


@dataclass(frozen=True)
class RobotModel:
    """The parts of a robot inside a plant, as `add_robot` returns them.

    Attributes:
        description: the RobotDescription it was added from.
        base, arm, tool: the model instances of the base's joints, of the
            arm's joints and of the TCP.
        base_frame: T_b, on the floor at the centre of the footprint.
        arm_base_frame: T_a, the arm's base.
        flange_frame: the arm's tool flange.
        ft_measurement_frame: the wrist sensor's measurement frame.
        tcp_frame: the tool centre point, the end effector of the
            controller.
        lidar_frames: the LIDARs' scan frames, in the description's order.
        base_joints: the base's planar joints (x, y, yaw).
        passive_joints: the base's unactuated joints (e.g. a flexible
            mount).
        arm_joints: the arm's joints, base to wrist.
        ft_sensor_joint: the weld on the sensor's measuring surface.
        home: (n,) the arm's home configuration, rad.
        limits: the arm's own ArmLimits.
        suspension_joints: the suspension's joints under the chassis
            (roll, pitch) when the robot was added with one, else empty
            (drake_wbc.robot.suspension).
        mount: the ArmMount the arm was welded with.
        horizontal_joints: the horizontal compliance's joints of the
            wheels on the floor (x, y, yaw) when the suspension has one,
            else empty.
        locked_joints: the joints of what the wrist sensor carries that
            the station locks at their default positions (the
            description's tool.locked_joints).
    """

    description: RobotDescription
    base: ModelInstanceIndex
    arm: ModelInstanceIndex
    tool: ModelInstanceIndex
    base_frame: Frame
    arm_base_frame: Frame
    flange_frame: Frame
    ft_measurement_frame: Frame
    tcp_frame: Frame
    lidar_frames: tuple
    base_joints: tuple
    passive_joints: tuple
    arm_joints: tuple
    ft_sensor_joint: Joint
    home: np.ndarray
    limits: ArmLimits
    suspension_joints: tuple = ()
    mount: ArmMount = field(default_factory=ArmMount)
    horizontal_joints: tuple = ()
    locked_joints: tuple = ()

    @property
    def num_arm_joints(self):
        """n, the number of the arm's joints."""
        return len(self.arm_joints)


def add_robot(plant: MultibodyPlant, description=None, parser: Parser = None,
              suspension=None, mount=None):
    """Adds the robot of `description` to `plant` (not yet finalized) and
    checks the description against it.

    Args:
        plant: the plant to add to; its scene graph, if registered,
            receives the geometry.
        description: a RobotDescription; the shipped robot's if None.
        parser: an existing parser of `plant` whose package map is to be
            used (a new one is made if None).
        suspension: None (the chassis rigid on its planar joints, as the
            model has it) or the SuspensionGains of a suspension under the
            chassis (drake_wbc.robot.suspension), inserted into the
            base's model (the one of base.joints[2], its yaw joint; model
            directives only);
            with a horizontal compliance, the base's actuators get the
            drive's reflected inertia (gains.drive_inertia).
        mount: the ArmMount of the arm on the base (None: as the model
            has it): the pose of the directives' weld whose child is
            arm.base_frame (model directives only).

    Returns:
        RobotModel: the model instances, frames and joints.

    Raises:
        ValueError: naming the description's field when a joint or frame
            it names is not in the model, a joint is of the wrong kind
            (or a passive one without a spring),
            T_a (arm.base_frame) is moved by the arm's joints, the
            TCP is not outboard of the arm, the sensor not between the
            flange and the TCP (or its frame not welded to its weld), a
            joint between T_a and the TCP is not one of arm.joints or one
            outboard of the sensor's weld not a weld, a LIDAR's frame is
            not on the base, the arm's limits are missing or wider than
            the model's, a joint of the arm limited on one side only,
            a model file (model.file, model.directives, a
            file the directives add) is not there, or a suspension is
            asked of a base whose model is not SDFormat.
    """
    if plant.is_finalized():
        raise ValueError(
            "plant is finalized, which is not allowed: add the robot before "
            "plant.Finalize()"
        )
    description = checked_instance("description", description,
                                   RobotDescription, shipped_robot)
    # What is wrong with the description is said of its file.
    where = file_prefix(description)
    check_model_files(description, where)
    parser = parser or Parser(plant)
    package_map = parser.package_map()
    # The library's models (bases, tools) as package://drake_wbc/..., so a
    # description may put its own arm on one of them without a path.
    if not package_map.Contains(LIBRARY_PACKAGE):
        package_map.Add(LIBRARY_PACKAGE, str(models_dir()))
    for name, folder in description.model.packages.items():
        # The description's folder wins over a package Drake knows by the
        # same name (e.g. its remote drake_models, which it would try to
        # download).
        if package_map.Contains(name):
            package_map.Remove(name)
        package_map.Add(name, description.resolve(folder))
    source = description.model
    if suspension is not None and not isinstance(suspension,
                                                 SuspensionGains):
        raise ValueError(
            f"suspension = {suspension!r} is not allowed: must be None or "
            "SuspensionGains (drake_wbc.robot.suspension)")
    mount = replace(checked_instance("mount", mount, ArmMount, ArmMount))
    if source.directives:
        url = description.resolve(source.directives)
        path = package_map.ResolveUrl(url) if "://" in url else url
        try:
            directives = LoadModelDirectives(path)
        except RuntimeError as error:  # Drake's loader: one line of why
            raise ValueError(f"{where}model.directives = "
                             f"{source.directives!r} is not allowed: "
                             f"{error}") from None
        for add in (d.add_model for d in directives.directives
                    if d.add_model is not None):
            try:
                package_map.ResolveUrl(add.file)
            except RuntimeError as error:
                raise ValueError(
                    f"{where}model.directives = {source.directives!r} is "
                    f"not allowed: its add_model {add.name!r} gives file = "
                    f"{add.file!r}, which does not resolve "
                    f"({str(error).removeprefix('error: ')}); directives "
                    "name files by package:// URLs (of model.packages, or "
                    "drake_wbc for the library's models) or file:// URLs"
                ) from None
        if not mount.is_identity:
            # Turned about the point the model welds the arm at.
            weld = _mount_weld(directives, description)
            at = (np.zeros(3) if weld.X_PC is None
                  else weld.X_PC.GetDeterministicValue().translation())
            weld.X_PC = Transform(RigidTransform(RollPitchYaw(
                RotationMatrix(mount.rotation())), at))
        if suspension is None:
            try:
                ProcessModelDirectives(directives, plant, parser)
            except RuntimeError as error:  # e.g. a model file not there
                raise ValueError(
                    f"{where}model.directives = {source.directives!r} is "
                    f"not allowed: {error}") from None
        else:
            # The base's file with the suspension's joints added, parsed
            # in its place (the other directives weld to it).
            yaw = ScopedName.Parse(description.base.joints[2])
            adds = [d.add_model for d in directives.directives
                    if d.add_model is not None
                    and d.add_model.name == yaw.get_namespace()]
            if len(adds) != 1:
                raise ValueError(
                    f"suspension is not allowed on {description.name}: its "
                    "model directives must add the model of base.joints[2] "
                    f"= {description.base.joints[2]!r} exactly once "
                    f"(found {len(adds)})")
            first = adds[0]
            if not first.file.lower().endswith(".sdf"):
                raise ValueError(
                    f"suspension is not allowed on {description.name}: the "
                    "model of base.joints[2] = "
                    f"{description.base.joints[2]!r} is {first.file!r}, "
                    "not an SDFormat file (.sdf), which the suspension's "
                    "joints are written into; give the base's model in "
                    "SDFormat")
            text = Path(package_map.ResolveUrl(first.file)).read_text()
            with tempfile.TemporaryDirectory() as folder:
                suspended = Path(folder) / "base_suspended.sdf"
                suspended.write_text(suspended_base_sdf(
                    text, suspension, yaw.get_element()))
                first.file = f"file://{suspended}"
                ProcessModelDirectives(directives, plant, parser)
    else:
        for name, value, what in (
                ("suspension", suspension, "the suspension's joints"),
                ("mount", None if mount.is_identity else mount,
                 "the arm's mount")):
            if value is not None:
                raise ValueError(
                    f"{name} is not allowed on {description.name}: its model "
                    f"is one file (model.file = {source.file!r}), and "
                    f"{what} can only be added to model directives; "
                    "describe the robot by model.directives, or model "
                    f"{what} in its file")
        url = description.resolve(source.file)
        try:
            if "://" in url:
                parser.AddModelsFromUrl(url)
            else:
                parser.AddModels(url)
        except RuntimeError as error:  # Drake's parser: one line of why
            raise ValueError(f"{where}model.file = {source.file!r} is not "
                             f"allowed: {error}") from None
    try:
        model = replace(_robot_model(plant, description), mount=mount)
    except ValueError as error:  # joints, frames, limits, home
        raise ValueError(f"{where}{error}") from None
    if suspension is None:
        return model
    model = replace(model, suspension_joints=tuple(
        plant.GetJointByName(name, model.base) for name in SUSPENSION_JOINTS))
    if not suspension.has_horizontal:
        return model
    inertia = as_vector("drive_inertia", suspension.drive_inertia, 3)
    by_joint = {plant.get_joint_actuator(i).joint().index(): i
                for i in plant.GetJointActuatorIndices()}
    for joint, value in zip(model.base_joints, inertia, strict=True):
        actuator = plant.get_joint_actuator(by_joint[joint.index()])
        actuator.set_default_gear_ratio(1.0)
        actuator.set_default_rotor_inertia(float(value))
    return replace(model, horizontal_joints=tuple(
        plant.GetJointByName(name, model.base) for name in HORIZONTAL_JOINTS))


def _mount_weld(directives, description):
    """The add_weld of `directives` whose child is the description's
    arm.base_frame (the weld an ArmMount poses)."""
    welds = [d.add_weld for d in directives.directives
             if d.add_weld is not None
             and d.add_weld.child == description.arm.base_frame]
    if len(welds) != 1:
        raise ValueError(
            f"mount is not allowed: the model directives must weld "
            f"arm.base_frame = {description.arm.base_frame!r} exactly once "
            f"(found {len(welds)})")
    return welds[0]


def _scoped(plant, field, name, find, kind):
    """The element `name` ("instance::element") of the plant, by
    find(element, instance); a ValueError naming `field` if absent."""
    scoped = ScopedName.Parse(name)
    instance_name, element = scoped.get_namespace(), scoped.get_element()
    if not instance_name or not plant.HasModelInstanceNamed(instance_name):
        instances = [plant.GetModelInstanceName(ModelInstanceIndex(i))
                     for i in range(plant.num_model_instances())]
        raise ValueError(
            f"{field} = {name!r} is not allowed: must be scoped by one of "
            f"the model's instances {instances}, as instance::{kind}")
    instance = plant.GetModelInstanceByName(instance_name)
    try:
        return find(element, instance)
    except RuntimeError:
        raise ValueError(
            f"{field} = {name!r} is not allowed: the model has no {kind} "
            f"{element!r} in {instance_name!r}") from None


def scoped_joint_name(plant, joint):
    """`joint`'s name scoped by its model instance in `plant`, as a
    description gives it ("model::joint")."""
    return (f"{plant.GetModelInstanceName(joint.model_instance())}::"
            f"{joint.name()}")


def _joined(plant, body, joints):
    """The indices of `body` and of the bodies joined to it by welds and
    `joints` alone, through either side of each."""
    allowed = {j.index() for j in joints}
    links = [plant.get_joint(JointIndex(i)) for i in range(plant.num_joints())]
    links = [j for j in links
             if j.type_name() == "weld" or j.index() in allowed]
    joined, grown = {body.index()}, True
    while grown:
        grown = False
        for joint in links:
            ends = {joint.parent_body().index(), joint.child_body().index()}
            if ends & joined and not ends <= joined:
                joined |= ends
                grown = True
    return joined


def _parents(plant):
    """child body index -> (joint, parent body) over every joint."""
    parents = {}
    for i in range(plant.num_joints()):
        joint = plant.get_joint(JointIndex(i))
        parents[joint.child_body().index()] = joint
    return parents


def _outboard(parents, body, ancestor):
    """Whether `body` is `ancestor` or lies outboard of it."""
    index = body.index()
    while True:
        if index == ancestor.index():
            return True
        joint = parents.get(index)
        if joint is None:
            return False
        index = joint.parent_body().index()


def bodies_outboard(plant, body):
    """`body` and every body outboard of it in `plant` (through any joint,
    welds included), in the plant's order: e.g. what a wrist sensor
    carries, outboard of the child body of its measuring weld."""
    parents = _parents(plant)
    return [b for b in (plant.get_body(BodyIndex(i))
                        for i in range(plant.num_bodies()))
            if _outboard(parents, b, body)]


def _robot_model(plant, description):
    """The RobotModel of `description` in `plant`, checked."""
    def frame(field, name):
        return _scoped(plant, field, name, plant.GetFrameByName, "frame")

    def joint(field, name, kinds):
        found = _scoped(plant, field, name, plant.GetJointByName, "joint")
        if found.type_name() not in kinds:
            raise ValueError(
                f"{field} = {name!r} is not allowed: it is a "
                f"{found.type_name()} joint, must be {' or '.join(kinds)}")
        return found

    base, arm, tool = (description.base, description.arm, description.tool)
    base_joints = tuple(
        joint(f"base.joints[{i}]", name, (kind,)) for i, (name, kind) in
        enumerate(zip(base.joints, ("prismatic", "prismatic", "revolute"),
                      strict=True)))
    # They are the base's pose on the floor, which has no limits (a
    # URDF's prismatic joint has some, by its schema: a wall in the plant).
    for found in base_joints:
        found.set_position_limits([-math.inf], [math.inf])
    passive_joints = tuple(
        joint(f"base.passive_joints[{i}]", name,
              ("revolute", "prismatic"))
        for i, name in enumerate(base.passive_joints))
    # A passive joint is held at rest by its spring (the nominal
    # kinematics, the station's static equilibrium); without one it is a
    # free mechanism.
    springs = spring_stiffnesses(plant)
    for i, (name, found) in enumerate(zip(base.passive_joints,
                                          passive_joints, strict=True)):
        if not springs.get(found.index(), 0.0) > 0.0:
            raise ValueError(
                f"base.passive_joints[{i}] = {name!r} is not allowed: it "
                "has no spring (a RevoluteSpring or PrismaticSpring of "
                "stiffness > 0, e.g. SDFormat's <spring_stiffness>; URDF "
                "has none) to hold it at rest")
    arm_joints = tuple(joint(f"arm.joints[{i}]", name, ("revolute",))
                       for i, name in enumerate(arm.joints))
    sensor_joint = joint("tool.ft_sensor_joint", tool.ft_sensor_joint,
                         ("weld",))
    locked_joints = tuple(
        _scoped(plant, f"tool.locked_joints[{i}]", name,
                plant.GetJointByName, "joint")
        for i, name in enumerate(tool.locked_joints))
    frames = dict(
        base_frame=frame("base.frame", base.frame),
        arm_base_frame=frame("arm.base_frame", arm.base_frame),
        flange_frame=frame("arm.flange_frame", arm.flange_frame),
        ft_measurement_frame=frame("tool.ft_sensor_frame",
                                   tool.ft_sensor_frame),
        tcp_frame=frame("tool.tcp_frame", tool.tcp_frame))
    lidar_frames = tuple(frame(f"lidar_frames[{i}]", name)
                         for i, name in enumerate(description.lidar_frames))
    parents = _parents(plant)
    last = arm_joints[-1].child_body()
    for i, (a, b) in enumerate(zip(arm_joints[:-1], arm_joints[1:],
                                   strict=True)):
        if not _outboard(parents, b.parent_body(), a.child_body()):
            raise ValueError(
                f"arm.joints[{i + 1}] = {arm.joints[i + 1]!r} is not allowed:"
                f" it is not outboard of arm.joints[{i}] = {arm.joints[i]!r}"
                " (list the joints base to wrist)")
    # T_a carries the arm's Jacobian (eq. (fk)): a frame moved by the
    # arm's own joints would turn with them.
    if _outboard(parents, frames["arm_base_frame"].body(),
                 arm_joints[0].child_body()):
        raise ValueError(
            f"arm.base_frame = {arm.base_frame!r} is not allowed: must not "
            f"be outboard of arm.joints[0] = {arm.joints[0]!r} (T_a stays "
            "with the base; give the frame the arm is mounted on)")
    flange = frames["flange_frame"].body()
    sensor = sensor_joint.child_body()
    tcp = frames["tcp_frame"].body()
    for where, name, body, ancestor, what in (
            ("arm.flange_frame", arm.flange_frame, flange, last,
             "the arm's last joint"),
            ("tool.ft_sensor_joint", tool.ft_sensor_joint, sensor, flange,
             "the flange"),
            ("tool.ft_sensor_frame", tool.ft_sensor_frame,
             frames["ft_measurement_frame"].body(), flange, "the flange"),
            ("tool.tcp_frame", tool.tcp_frame, tcp, sensor,
             "the sensor's measuring side")):
        if not _outboard(parents, body, ancestor):
            raise ValueError(f"{where} = {name!r} is not allowed: must be "
                             f"outboard of {what}")
    # The sensor reads its weld's reaction at its measurement frame: a
    # joint between them would turn the reading against the frame.
    if frames["ft_measurement_frame"].body().index() not in [
            b.index() for b in plant.GetBodiesWeldedTo(sensor)]:
        raise ValueError(
            f"tool.ft_sensor_frame = {tool.ft_sensor_frame!r} is not "
            "allowed: must be on a body welded to the child of "
            f"tool.ft_sensor_joint = {tool.ft_sensor_joint!r} (no joint "
            "between them)")
    # What the sensor carries is compensated as one rigid body at the
    # model's rest (drake_wbc.stages.wrench), and is the TCP's: a joint
    # there is a weld, or one the station locks at its default position.
    for i, (name, found) in enumerate(zip(tool.locked_joints, locked_joints,
                                          strict=True)):
        if (found.type_name() == "weld"
                or not _outboard(parents, found.child_body(), sensor)):
            raise ValueError(
                f"tool.locked_joints[{i}] = {name!r} is not allowed: must "
                "be a joint that moves (not a weld) outboard of "
                f"tool.ft_sensor_joint = {tool.ft_sensor_joint!r}, in what "
                "the wrist sensor carries")
    locked = {found.index() for found in locked_joints}
    for found in (plant.get_joint(JointIndex(i))
                  for i in range(plant.num_joints())):
        if (found.type_name() != "weld" and found.index() not in locked
                and _outboard(parents, found.child_body(), sensor)):
            raise ValueError(
                f"tool.ft_sensor_joint = {tool.ft_sensor_joint!r} is not "
                f"allowed with the {found.type_name()} joint "
                f"{scoped_joint_name(plant, found)!r} outboard of it: what the "
                "wrist sensor carries must be rigid (its weight is taken at "
                "the model's rest, the TCP on it); weld that joint in the "
                "model, or list it in tool.locked_joints (a gripper's "
                "fingers: the station holds them at their default "
                "positions)")
    # The controller's kinematics move the TCP by the arm's joints alone.
    arm_base = frames["arm_base_frame"].body()
    stop = (arm_base if _outboard(parents, tcp, arm_base)
            else arm_joints[0].parent_body()).index()
    listed = [j.index() for j in arm_joints]
    index = tcp.index()
    while index != stop and index in parents:
        found = parents[index]
        if found.type_name() != "weld" and found.index() not in listed:
            raise ValueError(
                f"arm.joints = {list(arm.joints)} is not allowed: the "
                f"{found.type_name()} joint "
                f"{scoped_joint_name(plant, found)!r} "
                "between arm.base_frame and tool.tcp_frame is not one of "
                "them; list every joint of the arm, base to wrist (or weld "
                "that joint in the model)")
        index = found.parent_body().index()
    # The station's scanners are mounted at their pose in T_b with the
    # model at rest: one that a joint moves would scan from elsewhere (a
    # passive joint's spring holds it at rest).
    on_base = _joined(plant, frames["base_frame"].body(), passive_joints)
    for i, (name, found) in enumerate(zip(description.lidar_frames,
                                          lidar_frames, strict=True)):
        if found.body().index() not in on_base:
            raise ValueError(
                f"lidar_frames[{i}] = {name!r} is not allowed: must be on "
                f"the body of base.frame = {base.frame!r} or one joined to "
                "it by welds and base.passive_joints alone (a scanner on "
                "the base)")
    return RobotModel(
        description=description,
        base=base_joints[0].model_instance(),
        arm=arm_joints[0].model_instance(),
        tool=tcp.model_instance(),
        lidar_frames=lidar_frames,
        base_joints=base_joints,
        passive_joints=passive_joints,
        arm_joints=arm_joints,
        ft_sensor_joint=sensor_joint,
        home=np.array(arm.home),
        limits=_arm_limits(arm, arm_joints),
        locked_joints=locked_joints,
        **frames)


def _arm_limits(arm, joints):
    """The arm's own ArmLimits: the model's, tightened where the
    description gives tighter ones; a ValueError naming the field for a
    limit that is missing or wider than the model's, a joint limited on
    one side only, or a home outside. A joint whose model gives no
    position range (lower = upper = 0) gets the description's in the
    plant. A continuous joint (the model's limits -inf and inf) has no
    position limits, unless the description gives finite ones."""
    n = len(joints)
    model = dict(
        position_lower=[float(j.position_lower_limits()[0]) for j in joints],
        position_upper=[float(j.position_upper_limits()[0]) for j in joints],
        velocity_limits=[float(j.velocity_upper_limits()[0]) for j in joints],
        acceleration_limits=[float(j.acceleration_upper_limits()[0])
                             for j in joints])
    # A speed or acceleration limit of 0 in the model is none (a URDF's
    # velocity='0', as exporters write it where nothing was set): the
    # description gives it.
    shown = {name: list(values) for name, values in model.items()}
    for name in ("velocity_limits", "acceleration_limits"):
        model[name] = [v if v > 0.0 else math.inf for v in model[name]]
    # So is a position range of lower = upper = 0 (a URDF's lower='0'
    # upper='0', likewise); the description's then go into the plant,
    # whose joint would otherwise be held at 0.
    unset = [i for i in range(n) if model["position_lower"][i]
             == model["position_upper"][i] == 0.0]
    for i in unset:
        model["position_lower"][i] = -math.inf
        model["position_upper"][i] = math.inf
    limits = {}
    for name, own in model.items():
        given = getattr(arm, name)
        upper_side = name != "position_lower"
        values = []
        for i in range(n):
            value = own[i] if given is None else given[i]
            wider = (value > own[i]) if upper_side else (value < own[i])
            if given is not None and wider:
                raise ValueError(
                    f"arm.{name}[{i}] = {value!r} is not allowed: must be "
                    f"within the model's own {own[i]!r} for "
                    f"{arm.joints[i]!r} (a limit may only tighten)")
            # An infinite position limit is none, a continuous joint's
            # (the model's, or the description's -.inf and .inf); one
            # the model left unset must be given.
            missing = not np.isfinite(value) and (
                not name.startswith("position")
                or (given is None and i in unset))
            if missing:
                raise ValueError(
                    f"arm.{name}[{i}] is missing, which is not allowed: the "
                    f"model gives {arm.joints[i]!r} none "
                    f"({shown[name][i]!r}); give arm.{name} in the "
                    "description")
            values.append(float(value))
        limits[name] = np.array(values)
    for i, (lo, hi) in enumerate(zip(limits["position_lower"].tolist(),
                                     limits["position_upper"].tolist(),
                                     strict=True)):
        if math.isinf(lo) != math.isinf(hi):
            raise ValueError(
                f"arm.position_lower[{i}] = {lo!r} and arm.position_upper"
                f"[{i}] = {hi!r} (the model gives "
                f"{shown['position_lower'][i]!r} and "
                f"{shown['position_upper'][i]!r}) are not allowed for "
                f"{arm.joints[i]!r}: a joint is limited on both sides, or "
                "on neither (a continuous joint, -inf and inf)")
    for i, (q, lo, hi) in enumerate(zip(
            arm.home, limits["position_lower"].tolist(),
            limits["position_upper"].tolist(), strict=True)):
        if not lo < q < hi:
            raise ValueError(
                f"arm.home[{i}] = {q!r} is not allowed: must be inside "
                f"{arm.joints[i]!r}'s limits ({lo!r}, {hi!r})")
    for i in unset:
        joints[i].set_position_limits(limits["position_lower"][i:i + 1],
                                      limits["position_upper"][i:i + 1])
    return ArmLimits(limits["position_lower"], limits["position_upper"],
                     limits["velocity_limits"],
                     limits["acceleration_limits"])


def make_robot_plant(description=None, time_step=0.0, suspension=None,
                     mount=None):
    """Returns (plant, model): a finalized plant of the robot alone (with
    the suspension of SuspensionGains `suspension` and the arm mounted by
    the ArmMount `mount`, if any)."""
    plant = MultibodyPlant(time_step=time_step)
    model = add_robot(plant, description, suspension=suspension,
                      mount=mount)
    plant.Finalize()
    check_planar_base(plant, model)
    check_lidar_frames(plant, model)
    return plant, model


def self_contacts(plant, context, instances):
    """The robot's own bodies that overlap at the pose of `context`.

    MultibodyPlant filters the contacts of a body with its parent (and
    within bodies welded together) only: two links of an arm whose
    collision shapes overlap elsewhere (a wrist's cylinders at its
    joints) press on each other from the first step of a simulation,
    unless the model filters them (a collision filter group). Contacts
    with what is not the robot's (the world, the scene) are left out.
    One query of SceneGraph (QueryObject.ComputePointPairPenetration).

    Args:
        plant: a finalized plant registered with a SceneGraph, in a
            Diagram.
        context: the plant's context, in its Diagram's.
        instances: the robot's model instances.

    Returns:
        list of (body_a, body_b, depth): the bodies' scoped names (in
        the order of their indices) and how deep their shapes overlap
        (m), the deepest of each pair of bodies, deepest first.
    """
    query = plant.get_geometry_query_input_port().Eval(context)
    inspector = query.inspector()
    robot = set(instances)
    deepest = {}
    for pair in query.ComputePointPairPenetration():
        a, b = (plant.GetBodyFromFrameId(inspector.GetFrameId(i))
                for i in (pair.id_A, pair.id_B))
        if (a is None or b is None or a.index() == b.index()
                or a.model_instance() not in robot
                or b.model_instance() not in robot):
            continue
        if b.index() < a.index():
            a, b = b, a
        key = (a.scoped_name().get_full(), b.scoped_name().get_full())
        deepest[key] = max(deepest.get(key, 0.0), pair.depth)
    return sorted(((a, b, depth) for (a, b), depth in deepest.items()),
                  key=lambda contact: -contact[2])


def check_self_contacts(plant, context, instances, path, positions):
    """Refuses a robot whose own bodies overlap at the arm's
    configuration `positions`, set in `context` (`self_contacts`).

    Args:
        plant, context, instances: as self_contacts takes them.
        path: the name of the configuration's field (e.g. arm.home).
        positions: its value, rad.

    Raises:
        ValueError: naming `path` and its value, each pair of bodies
            that overlap (scoped names) and the depth in mm, and the
            model directive that filters their contacts.
    """
    contacts = self_contacts(plant, context, instances)
    if not contacts:
        return
    pairs = ", ".join(f"{a!r} and {b!r} by {1e3 * depth:.1f} mm"
                      for a, b, depth in contacts)
    members = ", ".join(dict.fromkeys(
        name for a, b, _ in contacts for name in (a, b)))
    raise ValueError(
        f"{path} = {[float(q) for q in positions]} is not allowed: there "
        f"the robot's own bodies overlap ({pairs}), and would push each "
        "other from the first step (Drake filters the contacts of a body "
        "with its parent only); shapes that overlap in the model, not on "
        "the robot, are filtered in its model directives (model.directives;"
        " in a model of one file, its drake:collision_filter_group):\n"
        "- add_collision_filter_group:\n    name: robot\n    members: "
        f"[{members}]\n    ignored_collision_filter_groups: [robot]\n"
        f"and a pair that collides on the robot too needs another {path}")


PLANAR_TEST_POSE = (0.3, -0.2, 0.5)
"""(x, y, yaw), m, m, rad: where check_planar_base puts the base."""


def check_planar_base(plant, model):
    """Checks that the base's planar joints (x, y, yaw) are T_b's pose in
    the world, as the simulated station's odometry and drivers read and
    drive them: with the joints at zero and at PLANAR_TEST_POSE (the
    other joints at their defaults), T_b's origin lies at (x, y) on the
    floor (z = 0, where the scene stands) and its axes are the world's
    turned by yaw about z.

    Args:
        plant: a finalized plant holding the robot.
        model: its RobotModel.

    Raises:
        ValueError: naming base.joints and base.frame, where T_b lies
            elsewhere (the joints listed in another order, an axis of
            another direction or sign, or a base frame turned, offset
            from the yaw joint's axis or above the floor).
    """
    context = plant.CreateDefaultContext()
    q = plant.GetPositions(context)
    indices = joint_position_indices(model.base_joints)
    for pose in ((0.0, 0.0, 0.0), PLANAR_TEST_POSE):
        q[indices] = pose
        plant.SetPositions(context, q)
        X_WB = model.base_frame.CalcPoseInWorld(context)
        expected = RotationMatrix.MakeZRotation(pose[2]).matrix()
        if (np.allclose(X_WB.translation(), (*pose[:2], 0.0), rtol=0,
                        atol=1e-9)
                and np.allclose(X_WB.rotation().matrix(), expected, rtol=0,
                                atol=1e-9)):
            continue
        base = model.description.base
        rpy = RollPitchYaw(X_WB.rotation()).vector()
        raise ValueError(
            f"base.joints = {list(base.joints)} with base.frame = "
            f"{base.frame!r} are not allowed: with the joints at (x, y, "
            f"yaw) = {pose}, T_b lies at (x, y, z) = "
            f"{np.round(X_WB.translation(), 6).tolist()} with (roll, "
            f"pitch, yaw) = {np.round(rpy, 6).tolist()} in the world; the "
            "joints must be T_b's pose: prismatic along the world's x, "
            "then y, then revolute about z, in that order, and T_b on the "
            "yaw axis, on the floor, x forward and z up")


LIDAR_TILT_TOLERANCE = 1e-3
"""rad, the largest tilt of a LIDAR's z axis from T_b's that
check_lidar_frames takes for level (a CAD export's rounding)."""


def check_lidar_frames(plant, model):
    """Checks that each LIDAR frame's z axis is T_b's z (up), as the
    simulated station mounts the scanners: level, at their height and
    heading in T_b, the scan in their x-y plane.

    Args:
        plant: a finalized plant holding the robot.
        model: its RobotModel.

    Raises:
        ValueError: naming lidar_frames[i], where the frame's z axis is
            tilted from T_b's by more than LIDAR_TILT_TOLERANCE (an
            optical frame's z forward, or a frame upside down).
    """
    context = plant.CreateDefaultContext()
    for i, (name, frame) in enumerate(zip(model.description.lidar_frames,
                                          model.lidar_frames, strict=True)):
        # A copy of the rotation, held: RotationMatrix.col's array would
        # read the memory of a pose already freed (a LIDAR of a valid
        # robot was refused with a garbage axis).
        z = frame.CalcPose(context, model.base_frame).rotation().matrix()[:, 2]
        if not z[2] >= math.cos(LIDAR_TILT_TOLERANCE):
            raise ValueError(
                f"lidar_frames[{i}] = {name!r} is not allowed: its z axis "
                f"is {np.round(z, 6).tolist()} in T_b (base.frame), must "
                "be up, [0, 0, 1], within LIDAR_TILT_TOLERANCE = "
                f"{LIDAR_TILT_TOLERANCE!r} rad (a planar scanner scanning "
                "level in its frame's x-y plane)")


_SHARED_PLANTS = {}
"""shared_robot_plant's plants, by the reprs of their description and
mount."""


def shared_robot_plant(description=None, mount=None):
    """(plant, model) as make_robot_plant(description, mount=mount) makes
    them (continuous, without a suspension), made once per description
    and mount in a process and shared by every caller. Parsing the
    robot's model costs about 80 ms, and one run used to parse it nine
    times for its kinematics and servo gains.

    For reading only: its callers make their own contexts (kinematics,
    mass matrices) and never add to it, change it or put it into a
    Diagram (make_robot_plant makes a plant of one's own). A description
    is known by its contents: a copy that differs in any field gets a
    plant of its own."""
    key = (repr(shipped_robot() if description is None else description),
           repr(mount))
    if key not in _SHARED_PLANTS:
        _SHARED_PLANTS[key] = make_robot_plant(description, mount=mount)
    return _SHARED_PLANTS[key]


def joint_position_indices(joints):
    """Returns the indices in q of the one-dof `joints`."""
    return np.array([j.position_start() for j in joints], dtype=int)


def joint_velocity_indices(joints):
    """Returns the indices in v of the one-dof `joints`."""
    return np.array([j.velocity_start() for j in joints], dtype=int)


class ArmKinematicsValues:
    """The arm's kinematics at one configuration (see ArmKinematics),
    unpacked as (J_a, p_ee_in_base, X_AE).

    Attributes:
        J_a: (6, n) geometric Jacobian of the end effector in T_a, rows
            [v; w] (the paper's order), columns the arm's n joint rates.
        p_ee_in_base: (3,) end-effector position in T_b (m).
        X_AE: the end-effector pose in T_a, a RigidTransform made when it
            is read (making one costs more than the whole kinematics, and
            the tick reads only J_a and p_ee).
        pose: X_AE as a (4, 4) homogeneous matrix.
    """

    __slots__ = ("J_a", "p_ee_in_base", "pose")

    def __init__(self, J_a, p_ee_in_base, pose):
        self.J_a, self.p_ee_in_base, self.pose = J_a, p_ee_in_base, pose

    @property
    def X_AE(self):
        return RigidTransform(self.pose)

    def __iter__(self):
        return iter((self.J_a, self.p_ee_in_base, self.X_AE))


class ArmKinematics:
    """J_a and the end-effector position from the robot model.

    The one place where the controller's stages get the arm's kinematics
    (paper, eq. (fk) and eq. (2)), for an arm of n >= 6 joints. The base's
    passive joints (a flexible mount) are not measured on a real robot, so
    these are the nominal kinematics: passive joints at rest, base at the
    origin. T_a is then fixed in T_b and R_ba, the rotation from T_a to
    T_b, is a constant (the identity for the shipped robot).

    `evaluate` runs the compiled kinematics of the arm's serial chain
    (drake_wbc.math.chain), read from the plant once here
    (`serial_chain`): the same values as the plant's to rounding
    (tests/test_robot_model.py holds them equal to 1e-12), at a few
    microseconds instead of the plant's twenty. Where the end effector is
    not outboard of the arm's last joint, or T_a not inboard of its first
    (a frame of the user's choosing), it asks the plant instead.

    Attributes (besides the methods): num_joints n; lower, upper,
    velocity_limits, acceleration_limits (n,), the arm's own limits
    (RobotModel.limits); home (n,); R_ba.

    Args:
        plant: a finalized plant that contains the robot; a private plant of
            the shipped robot alone is made if None.
        model: the RobotModel of `plant` (required when `plant` is
            given).
        end_effector_frame: the frame whose origin is the end effector;
            the tool centre point if None.
        mount: the ArmMount of the private plant (only when `plant` is
            None; a given plant carries its own, model.mount).
    """

    def __init__(self, plant=None, model=None, end_effector_frame=None,
                 mount=None):
        if plant is None:
            plant, model = shared_robot_plant(mount=mount)
        elif model is None:
            raise ValueError(
                "model = None is not allowed when plant is given: pass the "
                "RobotModel that add_robot returned for that plant"
            )
        elif mount is not None:
            raise ValueError(
                f"mount = {mount!r} is not allowed when plant is given: the "
                "plant's arm is mounted already (model.mount)"
            )
        self._plant = plant
        self.plant, self.model = plant, model
        self._context = plant.CreateDefaultContext()
        self._arm_base = model.arm_base_frame
        self._base = model.base_frame
        self._end_effector = end_effector_frame or model.tcp_frame
        self.num_joints = model.num_arm_joints
        self._q_indices = joint_position_indices(model.arm_joints)
        self._v_indices = joint_velocity_indices(model.arm_joints)
        limits = model.limits
        self.lower, self.upper = limits.lower.copy(), limits.upper.copy()
        self.velocity_limits = limits.velocity.copy()
        self.acceleration_limits = limits.acceleration.copy()
        self.home = model.home.copy()
        X_BA = self._arm_base.CalcPose(self._context, self._base)
        self.R_ba = X_BA.rotation().matrix()
        self.mount = model.mount
        # T_a is fixed in T_b (nominal kinematics): p_ee in T_b follows
        # from X_AE, with no third query of the plant.
        self._R_BA, self._p_BA = self.R_ba.copy(), X_BA.translation().copy()
        origin_in(self._R_BA, self._p_BA, np.eye(4))  # compiled now
        self._q = self._plant.GetPositions(self._context)
        # Flat indices of J_a's entries in Drake's (6, nv) Jacobian [w; v].
        self._J_a_entries = (
            np.array([3, 4, 5, 0, 1, 2])[:, None] * plant.num_velocities()
            + np.asarray(self._v_indices)[None, :]).ravel()
        self._q_a_key = None
        self._frame_chains = {}
        self.chain = serial_chain(plant, self._context, self._arm_base,
                                  self._end_effector, model.arm_joints)
        self._chain_kinematics = body_for(chain_kinematics_of, float)
        if self.chain is not None:
            self._chain_arrays = tuple(self.chain)

    def _set_arm_positions(self, q_a):
        """Puts q_a (n,) into the private context; a no-op when it is
        already there, which keeps the plant's kinematics cache valid."""
        q_a = as_float_array("q_a", q_a, (self.num_joints,))
        key = q_a.tobytes()
        if key != self._q_a_key:
            self._q[self._q_indices] = q_a
            self._plant.SetPositions(self._context, self._q)
            self._q_a_key = key

    def frame_pose(self, q_a, frame):
        """Returns the pose X_AF of `frame` (of this plant) in T_a at arm
        configuration `q_a` (n,)."""
        self._set_arm_positions(q_a)
        return frame.CalcPose(self._context, self._arm_base)

    def frame_matrix(self, q_a, frame):
        """X_AF of `frame_pose` as a (4, 4) homogeneous matrix, by the
        compiled chain to `frame` (read from the plant the first time a
        frame is asked for) where one applies, else from the plant: for
        the ticks that need a frame other than the end effector (the
        wrist sensor's)."""
        chain = self._frame_chains.get(frame.index())
        if chain is None:
            chain = self._frame_chains[frame.index()] = serial_chain(
                self._plant, self._context, self._arm_base, frame,
                self.model.arm_joints) or ()
        if not chain:
            return self.frame_pose(q_a, frame).GetAsMatrix4()
        q_a = as_float_array("q_a", q_a, (self.num_joints,))
        return self._chain_kinematics(*chain, q_a)[1]

    def evaluate(self, q_a):
        """Returns the ArmKinematicsValues at arm configuration `q_a` (n,),
        arrays of the caller's own.

        Nothing is remembered between calls: the stages of a control tick
        ask at different configurations (the capability at the measured
        one, the arm's controller at its command), each once a tick, and
        a memo's key and copies cost more than they saved."""
        if self.chain is None:
            return self.plant_values(q_a)
        q_a = as_float_array("q_a", q_a, (self.num_joints,))
        J_a, X_AE = self._chain_kinematics(*self._chain_arrays, q_a)
        return ArmKinematicsValues(J_a, origin_in(self._R_BA, self._p_BA,
                                                  X_AE), X_AE)

    def plant_values(self, q_a):
        """The ArmKinematicsValues at q_a (n,) from the plant itself, as
        `evaluate` gives them when the chain does not apply (X_AE as a
        (4, 4) matrix): the reference of the compiled chain."""
        self._set_arm_positions(q_a)
        return self._evaluate_here()

    def _evaluate_here(self):
        """J_a, p_ee (T_b) and X_AE (4, 4) at the configuration of the
        context, from the plant."""
        J = self._plant.CalcJacobianSpatialVelocity(
            self._context,
            JacobianWrtVariable.kV,
            self._end_effector,
            np.zeros(3),
            self._arm_base,
            self._arm_base,
        )
        # Drake orders spatial velocities [w; v]; the paper orders [v; w].
        J_a = J.take(self._J_a_entries).reshape(6, self.num_joints)
        X_AE = self._end_effector.CalcPose(self._context,
                                           self._arm_base).GetAsMatrix4()
        return ArmKinematicsValues(J_a, origin_in(self._R_BA, self._p_BA,
                                                  X_AE), X_AE)


def serial_chain(plant, context, base_frame, end_frame, joints):
    """The SerialChain (drake_wbc.math.chain) of `joints` (one-dof
    revolute or prismatic joints of `plant`, base to wrist) from
    `base_frame` to `end_frame`, its fixed transforms taken at
    `context` (any other joint between them is held as there); None
    when it does not describe the plant's kinematics: a joint of another
    kind, `end_frame` not outboard of the last joint's child, or
    `base_frame` not inboard of the first joint's parent, or consecutive
    joints not outboard of each other."""
    parents = _parents(plant)
    kinds = {"revolute": REVOLUTE, "prismatic": PRISMATIC}
    if (not joints or any(j.type_name() not in kinds for j in joints)
            or not _outboard(parents, end_frame.body(),
                             joints[-1].child_body())
            or not _outboard(parents, joints[0].parent_body(),
                             base_frame.body())
            or _outboard(parents, base_frame.body(),
                         joints[0].child_body())):
        return None
    for a, b in zip(joints[:-1], joints[1:], strict=True):
        if not _outboard(parents, b.parent_body(), a.child_body()):
            return None
    frames = ([base_frame]
              + [f for j in joints for f in (j.frame_on_parent(),
                                              j.frame_on_child())]
              + [end_frame])
    fixed = np.array([
        plant.CalcRelativeTransform(context, frames[2 * i],
                                    frames[2 * i + 1]).GetAsMatrix4()
        for i in range(len(joints) + 1)])
    axes = np.array([
        j.revolute_axis() if j.type_name() == "revolute"
        else j.translation_axis() for j in joints], dtype=float)
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    revolute = np.array([kinds[j.type_name()] for j in joints])
    return SerialChain(np.ascontiguousarray(fixed),
                       np.ascontiguousarray(axes), revolute)


def arm_kinematics(robot=None):
    """The ArmKinematics of `robot`: a RobotDescription (the shipped
    robot's if None), or an ArmKinematics, returned as it is (to share
    its plant)."""
    if isinstance(robot, ArmKinematics):
        return robot
    return ArmKinematics(*shared_robot_plant(checked_instance(
        "robot", robot, RobotDescription, shipped_robot)))


class MountMode(NamedTuple):
    """One rocking mode of the flexible mount (see mount_rocking_modes)."""

    frequency_hz: float
    damping_ratio: float
    shape: np.ndarray


def mount_rocking_modes(plant, model, q_a=None):
    """Returns the mount's rocking modes with the arm held at `q_a`.

    The base and the arm are held still, so the mount's two joints theta
    (the robot description's passive joints, roll and pitch) obey
    M theta'' + C theta' + K theta = 0 about rest, with M the mount block
    of the plant's mass matrix, C the joint damping, and
    K = k I - d tau_g / d theta: the springs less the destabilising gravity
    of the upright mass (an inverted pendulum), the latter by central
    differences of the plant's gravity forces.

    Args:
        plant: a finalized plant of the robot (see make_robot_plant).
        model: its RobotModel, with two passive joints (the mount's roll
            and pitch).
        q_a: the arm configuration (n,), the robot's home if None.

    Returns:
        list[MountMode]: the modes, lowest frequency first; `shape` is the
        mode's direction in (roll, pitch).
    """
    if len(model.passive_joints) != 2:
        raise ValueError(
            f"model.passive_joints = {model.description.base.passive_joints}"
            " is not allowed: the mount's rocking modes need its two joints"
            " (roll, pitch)")
    return rocking_modes(plant, model, model.passive_joints, q_a)


def suspension_modes(plant, model, q_a=None):
    """The suspension's rocking modes (as mount_rocking_modes, with the
    mount, the base's planar joints and the arm held) of a plant made
    with a suspension; `shape` is in (roll, pitch)."""
    return rocking_modes(plant, model, model.suspension_joints, q_a)


def horizontal_modes(plant, model, q_a=None):
    """The modes of the wheels' horizontal compliance on the floor (as
    mount_rocking_modes, with the mount, the suspension's roll and pitch,
    the base's driven planar joints and the arm held) of a plant made with
    one; `shape` is in (x, y, yaw)."""
    return rocking_modes(plant, model, model.horizontal_joints, q_a)


def suspension_block(gains, q_a=None, horizontal=False, description=None,
                     mount=None):
    """(I, G): the diagonals of the mass matrix's block and of the gravity
    stiffness d tau_g / d theta (> 0: gravity topples the raised mass) of
    the suspension's joints (roll, pitch; or, if `horizontal`, the
    horizontal compliance's x, y, yaw), with the arm at `q_a` (the home if
    None) and the suspension of SuspensionGains `gains`, at rest, on the
    robot of RobotDescription `description` (the shipped one if None)
    with its arm mounted by ArmMount `mount` (as described if None)."""
    plant, model = make_robot_plant(description, suspension=gains,
                                    mount=mount)
    joints = (model.horizontal_joints if horizontal
              else model.suspension_joints)
    M, _, _, gravity = _compliant_block(plant, model, joints, q_a)
    return np.diag(M).copy(), np.diag(gravity).copy()


def suspension_gains(params, arm_positions, description=None, mount=None):
    """The SuspensionGains that give SuspensionParameters `params`' modes
    with the arm at `arm_positions` (n,): k = I w^2 + G and c = 2 zeta w
    I per axis (the module's docstring), I and G from a plant of the robot
    with the suspension (and k = I w^2, c = 2 zeta w I for the horizontal
    compliance's axes, from a plant with it): the robot of
    RobotDescription `description` (the shipped one if None), its arm
    mounted by ArmMount `mount`.

    Raises:
        ValueError: naming pivot_height when it is above the robot's deck
            (its description's base.height).
    """
    deck = checked_instance("description", description, RobotDescription,
                            shipped_robot).base.height
    if params.pivot_height > deck:
        raise ValueError(
            f"pivot_height = {params.pivot_height!r} m is not allowed: must "
            f"be at most the robot's deck, base.height = {deck!r} m")
    unsprung = SuspensionGains(np.zeros(2), np.zeros(2), params.pivot_height)
    inertia, gravity = suspension_block(unsprung, arm_positions,
                                        description=description, mount=mount)
    w = 2.0 * np.pi * np.array([params.roll_frequency,
                                params.pitch_frequency])
    gains = SuspensionGains(
        stiffness=inertia * w * w + gravity,
        damping=2.0 * params.damping_ratio * w * inertia,
        pivot_height=params.pivot_height)
    horizontal = params.horizontal
    if horizontal is None:
        return gains
    drive = np.array([horizontal.drive_inertia, horizontal.drive_inertia,
                      horizontal.drive_yaw_inertia])
    inertia = suspension_block(gains._replace(
        horizontal_stiffness=np.zeros(3), horizontal_damping=np.zeros(3),
        drive_inertia=drive), arm_positions, horizontal=True,
        description=description, mount=mount)[0]
    w = 2.0 * np.pi * horizontal.frequencies()
    return gains._replace(
        horizontal_stiffness=inertia * w * w,
        horizontal_damping=2.0 * horizontal.damping_ratio * w * inertia,
        drive_inertia=drive)


def rocking_modes(plant, model, joints, q_a=None):
    """The modes of the spring-damper `joints` of the base (all else held
    still, the arm at `q_a`, its home if None), lowest frequency first
    (see mount_rocking_modes)."""
    M, k, C, gravity_gradient = _compliant_block(plant, model, joints, q_a)
    n = len(joints)
    K = np.diag(k) - gravity_gradient
    A = np.block(
        [
            [np.zeros((n, n)), np.eye(n)],
            [-np.linalg.solve(M, K), -np.linalg.solve(M, C)],
        ]
    )
    eigenvalues, eigenvectors = np.linalg.eig(A)
    modes = []
    for value, vector in zip(eigenvalues, eigenvectors.T, strict=True):
        if value.imag <= 0:
            continue
        shape = np.abs(vector[:n])
        modes.append(
            MountMode(
                frequency_hz=abs(value) / (2 * np.pi),
                damping_ratio=-value.real / abs(value),
                shape=shape / np.linalg.norm(shape),
            )
        )
    return sorted(modes, key=lambda mode: mode.frequency_hz)


def _compliant_block(plant, model, joints, q_a):
    """M (mass matrix block), k (springs), C (joint damping) and the
    gravity gradient d tau_g / d theta of the base's `joints`, at rest
    with the arm at q_a (its home if None)."""
    q_a = as_vector("q_a", model.home if q_a is None else q_a,
                    model.num_arm_joints)
    context = plant.CreateDefaultContext()
    q = plant.GetPositions(context)
    q[joint_position_indices(model.arm_joints)] = q_a
    plant.SetPositions(context, q)
    iq = joint_position_indices(joints)
    iv = joint_velocity_indices(joints)
    M = plant.CalcMassMatrix(context)[np.ix_(iv, iv)]
    springs = spring_stiffnesses(plant, context)
    k = np.array([springs.get(j.index(), 0.0) for j in joints])
    C = np.diag([j.default_damping() for j in joints])
    step = 1e-6
    gravity_gradient = np.zeros((len(joints), len(joints)))
    for col, i in enumerate(iq):
        tau = []
        for sign in (1.0, -1.0):
            shifted = q.copy()
            shifted[i] += sign * step
            plant.SetPositions(context, shifted)
            tau.append(plant.CalcGravityGeneralizedForces(context)[iv])
        gravity_gradient[:, col] = (tau[0] - tau[1]) / (2 * step)
    return M, k, C, gravity_gradient


def spring_stiffnesses(plant, context=None):
    """joint index -> the stiffness of its RevoluteSpring or
    PrismaticSpring in `plant` (its default if `context` is None)."""
    springs = {}
    for element in _force_elements(plant):
        if isinstance(element, RevoluteSpring):
            springs[element.joint().index()] = (
                element.default_stiffness() if context is None
                else element.GetStiffness(context))
        elif isinstance(element, PrismaticSpring):
            springs[element.joint().index()] = element.stiffness()
    return springs


def _force_elements(plant):
    return [
        plant.get_force_element(ForceElementIndex(i))
        for i in range(plant.num_force_elements())
    ]

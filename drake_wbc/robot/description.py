"""The robot as data: what the controller and the station need to know of a
mobile collaborative robot, in one YAML file a user writes for their own.

A `RobotDescription` names the robot's model (Drake model directives, or
one URDF/SDFormat file, with the packages it refers to), the base's planar
joints and frame, the arm's joints in order (six or more) and frames, the
tool centre point and the wrist force/torque sensor, the LIDARs' frames,
the home configuration and the limits. It is loaded with
`load_robot_description` (Drake's `yaml_load_typed` behind the project's
screened loader, drake_wbc.math.loading), so a wrong key or value is an
error naming its dotted path:

    description = load_robot_description("my_robot.yaml")
    plant = MultibodyPlant(time_step=0.001)
    model = add_robot(plant, description)     # drake_wbc.robot.model

What can be checked without the model is checked here, when the
description is made; what needs the model (every joint and frame exists,
the TCP is outboard of the arm, the sensor between flange and TCP, the
limits within the model's) is checked by `add_robot`.

Names of joints and frames are scoped by their model instance, as Drake
prints them: `<model instance>::<name>`, e.g. `mcr_base::base_link`.
Relative paths are relative to the description file's folder.

The shipped robot, the paper's 6-joint cobot on an omnidirectional base
with a wrist force/torque sensor and a tool, is `models/mcr.robot.yaml`
(`shipped_robot()`).
"""

import copy
import dataclasses
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

from drake_wbc.math.capability import DEFAULT_JOINT_LIMIT_GAIN, CapabilityBand
from drake_wbc.math.loading import load_typed
from drake_wbc.math.validation import (
    as_vector,
    limit_vector,
    non_negative,
    positive,
    text,
)
from drake_wbc.math.workspace import LocalWorkspace

MIN_ARM_JOINTS = 6
"""The controller needs a 6-D task space from the arm alone (pHRI moves
the tool with the arm only), so the arm has at least six joints."""

SHIPPED_ROBOT_FILE = "mcr.robot.yaml"
"""The shipped robot's description, in models/."""


def models_dir():
    """Returns the folder that holds the shipped models (models/).

    A wheel carries models/ inside the package; a source checkout (or an
    editable install) has it at the repository's top level.
    """
    here = Path(__file__).resolve().parents[1]  # the package
    for candidate in (here / "models", here.parent / "models"):
        if (candidate / "package.xml").is_file():
            return candidate
    raise FileNotFoundError(
        f"the robot model folder was not found next to {here}: expected "
        "models/package.xml in the package or in the repository"
    )


def _blank(part):
    """True when every field of the dataclass `part` is at its default:
    the empty part that Drake's loader starts from before it reads the
    file (a description has no meaningful defaults, so a blank part is
    not checked; `RobotDescription` refuses blank parts)."""
    for f in dataclasses.fields(part):
        default = (f.default_factory() if f.default_factory
                   is not dataclasses.MISSING else f.default)
        value = getattr(part, f.name)
        if isinstance(default, float) and math.isnan(default):
            if not (isinstance(value, float) and math.isnan(value)):
                return False
        elif dataclasses.is_dataclass(default):
            # Field by field: a part with a NaN default is never == a
            # blank one from Python 3.13 on (dataclasses compare field by
            # field there, not as tuples, which took NaN is NaN as equal).
            if type(value) is not type(default) or not _blank(value):
                return False
        elif value != default:
            return False
    return True


def _check_given(part, optional=()):
    """Raises naming the first field of the dataclass `part` that its file
    left out: a field still at a blank default (NaN, "" or an empty list)
    that is not one of the `optional` field names."""
    for f in dataclasses.fields(part):
        if f.name in optional:
            continue
        value = getattr(part, f.name)
        left_out = (isinstance(f.default, float) and math.isnan(f.default)
                    and isinstance(value, float) and math.isnan(value))
        if f.default == "" or f.default_factory is list:
            left_out = len(value) == 0
        if left_out:
            raise ValueError(f"{f.name} is missing: a robot description "
                             "must give it (see the README, 'Use your own "
                             "robot')")


def _names(name, values, count=None, minimum=0):
    """`values` as a tuple of non-empty, distinct strings, `count` of them
    (or at least `minimum`)."""
    if not isinstance(values, (list, tuple)):
        raise ValueError(f"{name} = {values!r} is not allowed: must be a "
                         "list of names")
    names = tuple(text(f"{name}[{i}]", v) for i, v in enumerate(values))
    if count is not None and len(names) != count:
        raise ValueError(f"{name} = {list(names)} is not allowed: must name "
                         f"exactly {count}")
    if len(names) < minimum:
        raise ValueError(f"{name} = {list(names)} is not allowed: must name "
                         f"at least {minimum}, got {len(names)}")
    for i, n in enumerate(names):
        if not n.strip():
            raise ValueError(f"{name}[{i}] = {n!r} is not allowed: must be "
                             "a name")
        if n in names[:i]:
            raise ValueError(f"{name}[{i}] = {n!r} is not allowed: named "
                             "twice")
    return names


def _limits(name, values, size, optional=False):
    """`values` as (size,) finite numbers, each > 0; None stays None where
    `optional`."""
    if values is None and optional:
        return None
    vector = as_vector(name, values, size)
    for i, v in enumerate(vector):
        positive(f"{name}[{i}]", v)
    return tuple(float(v) for v in vector)


@dataclass
class ModelSource:
    """Where the robot's model comes from: exactly one of `directives`
    (Drake model directives, a .dmd.yaml) and `file` (one URDF or
    SDFormat file of the whole robot).

    Attributes:
        directives: a `package://` URL or a path (relative to the
            description's folder) of model directives.
        file: a `package://` URL or a path of a URDF or SDFormat file.
        packages: package name -> folder holding its package.xml
            (relative paths from the description's folder), for the
            `package://` URLs of the model.
    """

    directives: str = ""
    file: str = ""
    packages: dict[str, str] = field(default_factory=dict)

    def __post_init__(self):
        if _blank(self):
            return
        text("directives", self.directives)
        text("file", self.file)
        if bool(self.directives) == bool(self.file):
            raise ValueError(
                f"directives = {self.directives!r} and file = {self.file!r} "
                "are not allowed: give exactly one of them")
        if not isinstance(self.packages, dict):
            raise ValueError(f"packages = {self.packages!r} is not allowed: "
                             "must map package names to folders")
        for name, folder in self.packages.items():
            text(f"packages[{name!r}]", folder)


@dataclass
class BaseDescription:
    """The omnidirectional base.

    Attributes:
        frame: T_b, the base frame (on the floor at the centre of the
            footprint, x forward, z up).
        joints: its three planar joints, in the order x, y, yaw (two
            prismatic joints along the world's x and y, one revolute
            about z), actuated by velocity commands [vx, vy, wz] in T_b.
        passive_joints: unactuated joints of the base (springs of a
            suspension or a flexible arm mount), held at rest by the
            controller's nominal kinematics; none by default.
        velocity_limits: (3,) > 0, the base's own limits on [vx, vy, wz],
            m/s, m/s, rad/s; the controller's may only tighten them.
        acceleration_limits: (3,) > 0, its own limits on their rate of
            change, m/s^2, m/s^2, rad/s^2.
        footprint_half_sizes: (2,) > 0, half length and half width of the
            footprint in T_b, m.
        height: > 0, the height of the deck, m (a box higher than this may
            overhang the base).
        command_timeout: > 0, s, after which the base stops by itself when
            no command arrives (its own watchdog).
        velocity_lag: >= 0, s, the longest time constant of its
            velocity loop, from a command to the base's velocity (the
            slowest of its axes; where it is not known exactly, an upper
            bound): the separation rules brake allowing for it
            (drake_wbc.math.separation, eqs. (allowed), (protective)).
        wheel_distance: optional, > 0, m: the wheels' distance from the
            footprint's centre, the lever of their grip about z where the
            simulated station's wheels slip (drake_wbc.station.traction);
            None where not known.
    """

    frame: str = ""
    joints: list[str] = field(default_factory=list)
    passive_joints: list[str] = field(default_factory=list)
    velocity_limits: list[float] = field(default_factory=list)
    acceleration_limits: list[float] = field(default_factory=list)
    footprint_half_sizes: list[float] = field(default_factory=list)
    height: float = math.nan
    command_timeout: float = math.nan
    velocity_lag: float = math.nan
    wheel_distance: float | None = None

    def __post_init__(self):
        if _blank(self):
            return
        _check_given(self, optional=("passive_joints",))
        self.frame = _names("frame", [self.frame])[0]
        self.joints = _names("joints", self.joints, count=3)
        self.passive_joints = _names("passive_joints", self.passive_joints)
        for i, name in enumerate(self.passive_joints):
            if name in self.joints:
                raise ValueError(f"passive_joints[{i}] = {name!r} is not "
                                 "allowed: it is one of the planar joints")
        self.velocity_limits = _limits(
            "velocity_limits", self.velocity_limits, 3)
        self.acceleration_limits = _limits(
            "acceleration_limits", self.acceleration_limits, 3)
        self.footprint_half_sizes = _limits(
            "footprint_half_sizes", self.footprint_half_sizes, 2)
        self.height = positive("height", self.height)
        self.command_timeout = positive("command_timeout",
                                        self.command_timeout)
        self.velocity_lag = non_negative("velocity_lag", self.velocity_lag)
        if self.wheel_distance is not None:
            self.wheel_distance = positive("wheel_distance",
                                           self.wheel_distance)


@dataclass
class ArmDescription:
    """The arm: its joints from base to wrist and its frames.

    Attributes:
        joints: the arm's revolute joints in order, base to wrist, at
            least MIN_ARM_JOINTS (the controller's joint order: the
            commands, the status and the logs follow it).
        base_frame: T_a, the arm's base frame, fixed on the base.
        flange_frame: the arm's tool flange, outboard of the last joint.
        home: the home configuration, one angle per joint, rad: where the
            arm starts and what the capability band is tuned at.
        position_lower, position_upper: optional tighter joint position
            limits, rad (the model's by default). A continuous joint (no
            position limits in its model: URDF's type="continuous") keeps
            none with -.inf and .inf, or gets these if finite.
        velocity_limits: optional tighter joint speed limits, rad/s.
        acceleration_limits: optional tighter joint acceleration limits,
            rad/s^2 (the model must have them, or they are given here).
    """

    joints: list[str] = field(default_factory=list)
    base_frame: str = ""
    flange_frame: str = ""
    home: list[float] = field(default_factory=list)
    position_lower: list[float] | None = None
    position_upper: list[float] | None = None
    velocity_limits: list[float] | None = None
    acceleration_limits: list[float] | None = None

    def __post_init__(self):
        if _blank(self):
            return
        _check_given(self)
        self.joints = _names("joints", self.joints, minimum=MIN_ARM_JOINTS)
        n = len(self.joints)
        self.base_frame = _names("base_frame", [self.base_frame])[0]
        self.flange_frame = _names("flange_frame", [self.flange_frame])[0]
        self.home = tuple(float(v) for v in as_vector("home", self.home, n))
        for name, infinity in (("position_lower", -math.inf),
                               ("position_upper", math.inf)):
            if getattr(self, name) is not None:
                setattr(self, name, tuple(float(v) for v in limit_vector(
                    name, getattr(self, name), n, infinity)))
        if self.position_lower is not None and self.position_upper is not None:
            for i, (lo, hi) in enumerate(zip(self.position_lower,
                                             self.position_upper,
                                             strict=True)):
                if not lo < hi:
                    raise ValueError(
                        f"position_lower[{i}] = {lo!r} is not allowed: must "
                        f"be below position_upper[{i}] = {hi!r}")
        for name in ("velocity_limits", "acceleration_limits"):
            setattr(self, name, _limits(name, getattr(self, name), n,
                                        optional=True))


@dataclass
class ToolDescription:
    """What the arm carries: the end effector and the wrist sensor.

    Attributes:
        tcp_frame: T_ee, the tool centre point, outboard of the flange:
            the end effector of the controller.
        ft_sensor_frame: the force/torque sensor's measurement frame,
            between the flange and the TCP.
        ft_sensor_joint: the weld joint on the sensor's measuring
            surface, whose reaction the simulated sensor reads: the wrench
            of everything outboard of it.
        ft_sensor_range: (6,) > 0, the largest magnitude of each
            component of the sensor's reading [fx, fy, fz, tx, ty, tz],
            N and N m: its measuring range (the FT-300's +-300 N and
            +-30 N m), at which its output saturates. A reading beyond
            it is not a force the sensor measured (a broken or forged
            message): the controller's input guard takes it for a fault
            of the wrist's stream and stops (drake_wbc.controller.diagram).
        locked_joints: joints outboard of the sensor's weld that the
            simulated station holds locked at their default positions
            (a gripper's fingers, say): what the sensor carries is then
            rigid, as the controller takes it (its weight at the model's
            rest). Every other joint there is refused. Optional; on the
            robot they are the tool's own business.
    """

    tcp_frame: str = ""
    ft_sensor_frame: str = ""
    ft_sensor_joint: str = ""
    ft_sensor_range: list[float] = field(default_factory=list)
    locked_joints: list[str] = field(default_factory=list)

    def __post_init__(self):
        if _blank(self):
            return
        _check_given(self, optional=("locked_joints",))
        for name in ("tcp_frame", "ft_sensor_frame", "ft_sensor_joint"):
            setattr(self, name, _names(name, [getattr(self, name)])[0])
        self.ft_sensor_range = _limits("ft_sensor_range",
                                       self.ft_sensor_range, 6)
        self.locked_joints = list(_names("locked_joints",
                                         self.locked_joints))


@dataclass
class RobotTuning:
    """The controller's tuning that depends on the arm: what the
    controller uses where its parameters give none (None there).

    Attributes:
        joint_limit_gain: k_j > 0 of the joint-limit penalization P_jnt
            (drake_wbc.math.capability); it scales with 4^n on n joints.
            Default the paper's DEFAULT_JOINT_LIMIT_GAIN (1.5e4, six
            joints).
        capability_band: the limitation band C_m^l < C_m < C_m^u of eq.
            (transition) (drake_wbc.math.capability.CapabilityBand);
            C_m carries the units of the arm's manipulability, so the
            band is the arm's. Default the paper's 0.035 and 0.04.
        local_workspace: the local workspace of the intuitive pHRI mode
            (drake_wbc.math.workspace.LocalWorkspace: d^l, d^u of the
            tool's horizontal extent from the arm base's axis, and
            phi^l, phi^u of its deflection); d^l sits just outside the
            tool's extent at home, so the extents are the arm's. Default
            the paper's 0.75 and 0.8 m, 30 and 35 deg.

    `drake-wbc demo --robot FILE` surveys the arm and proposes the three
    (drake_wbc.robot.tuning).
    """

    joint_limit_gain: float = DEFAULT_JOINT_LIMIT_GAIN
    capability_band: CapabilityBand = field(default_factory=CapabilityBand)
    local_workspace: LocalWorkspace = field(default_factory=LocalWorkspace)

    def __post_init__(self):
        positive("joint_limit_gain", self.joint_limit_gain)
        for name, kind, what in (
                ("capability_band", CapabilityBand, "(lower, upper)"),
                ("local_workspace", LocalWorkspace,
                 "(extent_lower, extent_upper, deflection_lower, "
                 "deflection_upper)")):
            if not isinstance(getattr(self, name), kind):
                raise ValueError(
                    f"{name} = {getattr(self, name)!r} is not allowed: "
                    f"must be a {kind.__name__} {what}")


@dataclass
class RobotDescription:
    """A mobile collaborative robot as data (see the module).

    Attributes:
        name: a short name, for reports.
        model: where its model comes from.
        base, arm, tool: the parts.
        tuning: the controller's tuning for this arm (RobotTuning; the
            paper's where the file gives none).
        lidar_frames: the scan frames of its planar LIDARs (z up, the scan
            in their x-y plane), on the base.
        root: the folder that relative paths are relative to; the
            description file's folder when loaded from a file.
        source_file: the description file, as load_robot_description
            was given it ("" for a description from text or code; not a
            field of the file): the errors of checking the description
            against its model (drake_wbc.robot.model.add_robot) start
            with it, as the loader's do.
    """

    source_file: ClassVar[str] = ""
    name: str = ""
    model: ModelSource = field(default_factory=ModelSource)
    base: BaseDescription = field(default_factory=BaseDescription)
    arm: ArmDescription = field(default_factory=ArmDescription)
    tool: ToolDescription = field(default_factory=ToolDescription)
    tuning: RobotTuning = field(default_factory=RobotTuning)
    lidar_frames: list[str] = field(default_factory=list)
    root: str = ""

    def __post_init__(self):
        if _blank(self):
            return
        for part in ("model", "base", "arm", "tool"):
            if _blank(getattr(self, part)):
                raise ValueError(f"{part} is missing, which is not allowed: "
                                 f"a robot description gives its {part}")
        self.name = _names("name", [self.name])[0]
        self.lidar_frames = _names("lidar_frames", self.lidar_frames)
        text("root", self.root)

    @property
    def num_arm_joints(self):
        """The number of the arm's joints."""
        return len(self.arm.joints)

    def resolve(self, path):
        """`path` of the description (a `package://` URL is kept as it is)
        as an absolute path: relative to `root`."""
        if "://" in path:
            return path
        return str((Path(self.root or ".") / path).resolve())


def load_robot_description(path=None, text=None, root=None):
    """A RobotDescription from a YAML file (or text), every field checked.

    Args:
        path: the description file; or
        text: its YAML text (then `root` is the folder that its relative
            paths are relative to, the working folder if None).
        root: overrides the folder of relative paths.

    Raises:
        ValueError: naming the file, the field's dotted path (e.g.
            `arm.joints = [...] is not allowed: must name at least 6`),
            its value and what is allowed; also for a model file or a
            package folder that is not there.
    """
    description = load_typed(RobotDescription, path=path, text=text)
    if _blank(description):
        raise ValueError(f"{path or 'text'}: an empty robot description is "
                         "not allowed: give its name, model, base, arm and "
                         "tool")
    if root is not None:
        description.root = str(Path(root).resolve())
    elif not description.root:
        description.root = str(Path(path).resolve().parent if path is not None
                               else Path.cwd())
    elif path is not None:
        description.root = str((Path(path).resolve().parent
                                / description.root).resolve())
    if path is not None:
        description.source_file = str(path)
    check_model_files(description, file_prefix(description))
    return description


def file_prefix(description):
    """`<the description's file>: `, the start of an error found in
    `description` (RobotDescription), or "" where it came from no file."""
    return f"{description.source_file}: " if description.source_file else ""


def check_model_files(description, source=""):
    """Raises a ValueError naming the field (after `source`, the
    description file's path and a colon, or nothing) when a package
    folder or the model file of `description` is not there: a path, or a
    `package://` URL of one of its own packages (others are Drake's to
    find)."""
    model = description.model
    where = (" (a relative path is relative to the description's folder "
             f"{description.root!r})")
    folders = {}
    for name, folder in model.packages.items():
        folders[name] = Path(description.resolve(folder))
        if not folders[name].is_dir():
            raise ValueError(
                f"{source}model.packages[{name!r}] = {folder!r} is not "
                f"allowed: no such folder {str(folders[name])!r}{where}")
    field = "directives" if model.directives else "file"
    url = getattr(model, field)
    file = description.resolve(url)
    if url.startswith("package://"):
        name, _, rest = url[len("package://"):].partition("/")
        if name not in folders:
            return
        file = str(folders[name] / rest)
    elif "://" in url:
        return
    if not Path(file).is_file():
        raise ValueError(
            f"{source}model.{field} = {url!r} is not allowed: no such file "
            f"{file!r}{where}")


@functools.cache
def _shipped():
    return load_robot_description(models_dir() / SHIPPED_ROBOT_FILE)


def shipped_robot():
    """The description of the shipped robot (models/mcr.robot.yaml), a
    fresh copy each call (a caller may change it)."""
    return copy.deepcopy(_shipped())

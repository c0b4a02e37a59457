"""The mobile collaborative robot's model in Drake.

Loads the robot of models/ (omnidirectional base with a flexible arm mount,
Elfin5 arm, FT-300 wrist sensor, wiping tool, two LIDAR frames) into a
`MultibodyPlant`, names its parts, and computes the two kinematic quantities
that the controller needs from the arm's configuration: the arm Jacobian
J_a and the end-effector position in the base frame (paper, Sec. III-A).

The model files are found through Drake's package map under the package
name `drake_wbc`, so they load with no network and no other model package::

    plant = MultibodyPlant(time_step=0.001)
    model = add_mcr(plant)
    plant.Finalize()
"""

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np
from pydrake.common.schema import Transform
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.parsing import (
    LoadModelDirectives,
    PackageMap,
    Parser,
    ProcessModelDirectives,
)
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import (
    ForceElementIndex,
    Frame,
    JacobianWrtVariable,
    ModelInstanceIndex,
    RevoluteSpring,
)

from drake_wbc.math.validation import (
    as_float_array,
    as_scalar,
    as_vector,
    checked_instance,
)

PACKAGE_NAME = "drake_wbc"
"""The package name under which models/ is registered."""

MCR_DIRECTIVES_URL = f"package://{PACKAGE_NAME}/mcr.dmd.yaml"
"""The model directives that assemble the whole robot."""

BASE_JOINTS = ("base_x", "base_y", "base_yaw")
"""The base's planar joints: world-fixed x and y, then yaw (actuated)."""

MOUNT_JOINTS = ("mount_roll", "mount_pitch")
"""The flexible mount's spring-damper joints (unactuated)."""

ARM_JOINTS = tuple(f"joint{i}" for i in range(1, 7))
"""The Elfin5's joints, base to wrist."""

HOME_ARM_POSITIONS = np.array([0.0, -0.45, 1.0, 0.0, 1.15, 0.0])
"""The arm's home configuration (rad): elbow up, the tool centre point
0.54 m ahead of the base's front and 0.66 m above the floor, pointing
forward and 59 degrees down. Among such poses it has about the largest
manipulability (0.071; the 99th percentile over the whole joint space is
0.090) while every joint stays well inside its range."""

LIDAR_FRAMES = ("lidar_front_left", "lidar_rear_right")
"""The scan frames of the two 2-D LIDARs, at diagonally opposite corners."""


def models_dir():
    """Returns the folder that holds the robot's model files.

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


def register_models(package_map: PackageMap):
    """Adds models/ to `package_map` as the package `drake_wbc` (once)."""
    if not package_map.Contains(PACKAGE_NAME):
        package_map.AddPackageXml(str(models_dir() / "package.xml"))


ARM_MOUNT_WELD = ("mcr_base::arm_mount", "elfin5::base_link")
"""The weld (parent, child) of the model directives that mounts the arm
on the base; `ArmMount` sets its pose."""


@dataclass
class ArmMount:
    """How the arm is mounted on the base: the rotation ^bR_a of T_a in
    T_b (paper, eq. (fk)), about the mount point.

    ^bR_a = Rz(yaw) Ry(tilt): the arm turned by `yaw` about the base's
    vertical, then its column tilted by `tilt` about its own y axis (a
    positive tilt leans the arm's z axis towards its own +x). The
    default, no rotation, is the shipped robot (^bR_a = I). The robot
    description (issue 19) will own this datum; until then it is the one
    parameter of the mount, given to `add_mcr` (and so to the station and
    to `ArmKinematics`).

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


@dataclass(frozen=True)
class McrModel:
    """The parts of the robot inside a plant, as `add_mcr` returns them.

    Attributes:
        base: the base's model instance (planar joints, chassis, mount).
        arm: the Elfin5's model instance.
        tool: the FT-300 and wiping tool's model instance.
        base_frame: T_b, on the floor at the centre of the footprint.
        arm_base_frame: T_a, the arm's base (on the flexible mount).
        flange_frame: the arm's tool flange.
        ft_measurement_frame: the FT-300's measurement frame.
        tcp_frame: the tool centre point at the face of the wiping pad,
            the end effector of the controller.
        lidar_frames: the two scan frames, front-left then rear-right.
        mount: the ArmMount the arm was welded with.
    """

    base: ModelInstanceIndex
    arm: ModelInstanceIndex
    tool: ModelInstanceIndex
    base_frame: Frame
    arm_base_frame: Frame
    flange_frame: Frame
    ft_measurement_frame: Frame
    tcp_frame: Frame
    lidar_frames: tuple
    mount: ArmMount = field(default_factory=ArmMount)


def add_mcr(plant: MultibodyPlant, parser: Parser = None, mount=None):
    """Adds the whole robot to `plant` (not yet finalized).

    Args:
        plant: the plant to add to; its scene graph, if registered, receives
            the geometry.
        parser: an existing parser of `plant` whose package map is to be used
            (a new one is made if None).
        mount: the ArmMount of the arm on the base (the shipped robot's,
            no rotation, if None): the pose of the weld ARM_MOUNT_WELD.

    Returns:
        McrModel: the model instances and the frames the controller uses.
    """
    if plant.is_finalized():
        raise ValueError(
            "plant is finalized, which is not allowed: add the robot before "
            "plant.Finalize()"
        )
    parser = parser or Parser(plant)
    register_models(parser.package_map())
    mount = replace(checked_instance("mount", mount, ArmMount, ArmMount))
    directives = LoadModelDirectives(
        parser.package_map().ResolveUrl(MCR_DIRECTIVES_URL)
    )
    if not mount.is_identity:
        weld, = [d.add_weld for d in directives.directives
                 if d.add_weld is not None
                 and (d.add_weld.parent, d.add_weld.child) == ARM_MOUNT_WELD]
        weld.X_PC = Transform(RigidTransform(RollPitchYaw(
            RotationMatrix(mount.rotation())), np.zeros(3)))
    ProcessModelDirectives(directives, plant, parser)
    base = plant.GetModelInstanceByName("mcr_base")
    arm = plant.GetModelInstanceByName("elfin5")
    tool = plant.GetModelInstanceByName("ft300_wiping_tool")
    return McrModel(
        base=base,
        arm=arm,
        tool=tool,
        base_frame=plant.GetFrameByName("base_link", base),
        arm_base_frame=plant.GetFrameByName("base_link", arm),
        flange_frame=plant.GetFrameByName("flange", arm),
        ft_measurement_frame=plant.GetFrameByName("ft300_measurement", tool),
        tcp_frame=plant.GetFrameByName("tcp", tool),
        lidar_frames=tuple(
            plant.GetFrameByName(name, base) for name in LIDAR_FRAMES
        ),
        mount=mount,
    )


def make_mcr_plant(time_step=0.0, mount=None):
    """Returns (plant, model): a finalized plant of the robot alone, its
    arm mounted by `mount` (an ArmMount; the shipped robot's if None)."""
    plant = MultibodyPlant(time_step=time_step)
    model = add_mcr(plant, mount=mount)
    plant.Finalize()
    return plant, model


def joint_position_indices(plant, names, instance):
    """Returns the indices in q of the one-dof joints `names` of `instance`."""
    return np.array(
        [plant.GetJointByName(n, instance).position_start() for n in names]
    )


def joint_velocity_indices(plant, names, instance):
    """Returns the indices in v of the one-dof joints `names` of `instance`."""
    return np.array(
        [plant.GetJointByName(n, instance).velocity_start() for n in names]
    )


class ArmKinematicsValues(NamedTuple):
    """The arm's kinematics at one configuration (see ArmKinematics).

    Attributes:
        J_a: (6, 6) geometric Jacobian of the end effector in T_a, rows
            [v; w] (the paper's order), columns the arm's joint rates.
        p_ee_in_base: (3,) end-effector position in T_b (m).
        X_AE: the end-effector pose in T_a.
    """

    J_a: np.ndarray
    p_ee_in_base: np.ndarray
    X_AE: RigidTransform


class ArmKinematics:
    """J_a and the end-effector position from the robot model.

    The one place where the controller's stages get the arm's kinematics
    (paper, eq. (fk) and eq. (2)). The flexible mount is not measured on the
    real robot, so these are the nominal kinematics: mount at rest, base at
    the origin. T_a is then fixed in T_b and R_ba, the rotation from T_a to
    T_b, is a constant, read from the plant: the identity for the shipped
    robot, model.mount.rotation() for an ArmMount of add_mcr.

    Args:
        plant: a finalized plant that contains the robot; a private plant of
            the robot alone is made if None.
        model: the McrModel of `plant` (required when `plant` is given).
        end_effector_frame: the frame whose origin is the end effector;
            the tool centre point if None.
        mount: the ArmMount of the private plant (only when `plant` is
            None; a given plant carries its own, model.mount).
    """

    def __init__(self, plant=None, model=None, end_effector_frame=None,
                 mount=None):
        if plant is None:
            plant, model = make_mcr_plant(mount=mount)
        elif model is None:
            raise ValueError(
                "model = None is not allowed when plant is given: pass the "
                "McrModel that add_mcr returned for that plant"
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
        self._q_indices = joint_position_indices(plant, ARM_JOINTS, model.arm)
        self._v_indices = joint_velocity_indices(plant, ARM_JOINTS, model.arm)
        joints = [plant.GetJointByName(n, model.arm) for n in ARM_JOINTS]
        self.lower = np.array([j.position_lower_limits()[0] for j in joints])
        self.upper = np.array([j.position_upper_limits()[0] for j in joints])
        self.velocity_limits = np.array(
            [j.velocity_upper_limits()[0] for j in joints]
        )
        self.acceleration_limits = np.array(
            [j.acceleration_upper_limits()[0] for j in joints])
        X_BA = self._arm_base.CalcPose(self._context, self._base)
        self.R_ba = X_BA.rotation().matrix()
        self.mount = model.mount
        # T_a is fixed in T_b (nominal kinematics): p_ee in T_b follows
        # from X_AE, with no third query of the plant.
        self._R_BA, self._p_BA = self.R_ba.copy(), X_BA.translation().copy()
        self._q = self._plant.GetPositions(self._context)
        # Flat indices of J_a's entries in Drake's (6, nv) Jacobian [w; v].
        self._J_a_entries = (
            np.array([3, 4, 5, 0, 1, 2])[:, None] * plant.num_velocities()
            + np.asarray(self._v_indices)[None, :]).ravel()
        self._q_a_key = None
        self._memo = {}

    MEMO_SIZE = 4
    """Configurations whose values `evaluate` remembers (the stages of a
    control tick ask for the same few: measured and commanded)."""

    def _set_arm_positions(self, q_a, key=None):
        """Puts q_a (6,) into the private context; a no-op when it is
        already there, which keeps the plant's kinematics cache valid.
        `key`: q_a.tobytes() of a checked q_a, if known."""
        if key is None:
            q_a = as_float_array("q_a", q_a, (6,))
            key = q_a.tobytes()
        if key != self._q_a_key:
            self._q[self._q_indices] = q_a
            self._plant.SetPositions(self._context, self._q)
            self._q_a_key = key

    def frame_pose(self, q_a, frame):
        """Returns the pose X_AF of `frame` (of this plant) in T_a at arm
        configuration `q_a` (6,)."""
        self._set_arm_positions(q_a)
        return frame.CalcPose(self._context, self._arm_base)

    def evaluate(self, q_a):
        """Returns the ArmKinematicsValues at arm configuration `q_a` (6,).

        The last few configurations' values are remembered (the same q_a
        gives the same values, as fresh copies)."""
        q_a = as_float_array("q_a", q_a, (6,))
        key = q_a.tobytes()
        values = self._memo.get(key)
        if values is None:
            self._set_arm_positions(q_a, key)
            values = self._evaluate_here()
            if len(self._memo) >= self.MEMO_SIZE:
                del self._memo[next(iter(self._memo))]
            self._memo[key] = values
        J_a, p_ee_in_base, X_AE = values
        return ArmKinematicsValues(J_a.copy(), p_ee_in_base.copy(),
                                   RigidTransform(X_AE))

    def _evaluate_here(self):
        """J_a, p_ee (T_b) and X_AE at the configuration of the context."""
        J = self._plant.CalcJacobianSpatialVelocity(
            self._context,
            JacobianWrtVariable.kV,
            self._end_effector,
            np.zeros(3),
            self._arm_base,
            self._arm_base,
        )
        # Drake orders spatial velocities [w; v]; the paper orders [v; w].
        J_a = J.take(self._J_a_entries).reshape(6, 6)
        X_AE = self._end_effector.CalcPose(self._context, self._arm_base)
        p_ee_in_base = self._R_BA @ X_AE.translation() + self._p_BA
        return ArmKinematicsValues(J_a, p_ee_in_base, X_AE)


class MountMode(NamedTuple):
    """One rocking mode of the flexible mount (see mount_rocking_modes)."""

    frequency_hz: float
    damping_ratio: float
    shape: np.ndarray


def mount_rocking_modes(plant, model, q_a=HOME_ARM_POSITIONS):
    """Returns the mount's rocking modes with the arm held at `q_a`.

    The base and the arm are held still, so the mount's two joints theta
    obey M theta'' + C theta' + K theta = 0 about rest, with M the mount
    block of the plant's mass matrix, C the joint damping, and
    K = k I - d tau_g / d theta: the springs less the destabilising gravity
    of the upright mass (an inverted pendulum), the latter by central
    differences of the plant's gravity forces.

    Args:
        plant: a finalized plant of the robot (see make_mcr_plant).
        model: its McrModel.
        q_a: the arm configuration (6,), the home pose by default.

    Returns:
        list[MountMode]: the modes, lowest frequency first; `shape` is the
        mode's direction in (roll, pitch).
    """
    q_a = as_vector("q_a", q_a, 6)
    context = plant.CreateDefaultContext()
    q = plant.GetPositions(context)
    q[joint_position_indices(plant, ARM_JOINTS, model.arm)] = q_a
    plant.SetPositions(context, q)
    iq = joint_position_indices(plant, MOUNT_JOINTS, model.base)
    iv = joint_velocity_indices(plant, MOUNT_JOINTS, model.base)
    M = plant.CalcMassMatrix(context)[np.ix_(iv, iv)]
    springs = {
        element.joint().name(): element.GetStiffness(context)
        for element in _force_elements(plant)
        if isinstance(element, RevoluteSpring)
    }
    joints = [plant.GetJointByName(n, model.base) for n in MOUNT_JOINTS]
    k = np.array([springs.get(j.name(), 0.0) for j in joints])
    C = np.diag([j.default_damping() for j in joints])
    step = 1e-6
    gravity_gradient = np.zeros((2, 2))
    for col, i in enumerate(iq):
        tau = []
        for sign in (1.0, -1.0):
            shifted = q.copy()
            shifted[i] += sign * step
            plant.SetPositions(context, shifted)
            tau.append(plant.CalcGravityGeneralizedForces(context)[iv])
        gravity_gradient[:, col] = (tau[0] - tau[1]) / (2 * step)
    K = np.diag(k) - gravity_gradient
    A = np.block(
        [
            [np.zeros((2, 2)), np.eye(2)],
            [-np.linalg.solve(M, K), -np.linalg.solve(M, C)],
        ]
    )
    eigenvalues, eigenvectors = np.linalg.eig(A)
    modes = []
    for value, vector in zip(eigenvalues, eigenvectors.T, strict=True):
        if value.imag <= 0:
            continue
        shape = np.abs(vector[:2])
        modes.append(
            MountMode(
                frequency_hz=abs(value) / (2 * np.pi),
                damping_ratio=-value.real / abs(value),
                shape=shape / np.linalg.norm(shape),
            )
        )
    return sorted(modes, key=lambda mode: mode.frequency_hz)


def _force_elements(plant):
    return [
        plant.get_force_element(ForceElementIndex(i))
        for i in range(plant.num_force_elements())
    ]

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

import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
from pydrake.math import RigidTransform
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

from drake_wbc.math.validation import as_float_array, as_vector
from drake_wbc.robot.suspension import (
    SUSPENSION_JOINTS,
    SuspensionGains,
    suspended_base_sdf,
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


def add_mcr(plant: MultibodyPlant, parser: Parser = None, suspension=None):
    """Adds the whole robot to `plant` (not yet finalized).

    Args:
        plant: the plant to add to; its scene graph, if registered, receives
            the geometry.
        parser: an existing parser of `plant` whose package map is to be used
            (a new one is made if None).
        suspension: None (the chassis rigid on its planar joints, as
            models/ has it) or the SuspensionGains of a suspension under
            the chassis (drake_wbc.robot.suspension).

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
    directives = LoadModelDirectives(
        parser.package_map().ResolveUrl(MCR_DIRECTIVES_URL)
    )
    if suspension is not None:
        if not isinstance(suspension, SuspensionGains):
            raise ValueError(
                f"suspension = {suspension!r} is not allowed: must be None "
                "or SuspensionGains (drake_wbc.robot.suspension)")
        # The base's file with the suspension's joints added, parsed in
        # its place (the other directives weld to it).
        first = directives.directives[0].add_model
        text = Path(parser.package_map().ResolveUrl(first.file)).read_text()
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "mcr_base_suspended.sdf"
            path.write_text(suspended_base_sdf(text, suspension))
            first.file = f"file://{path}"
            ProcessModelDirectives(directives, plant, parser)
    else:
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
    )


def make_mcr_plant(time_step=0.0, suspension=None):
    """Returns (plant, model): a finalized plant of the robot alone (with
    the suspension of SuspensionGains `suspension`, if any)."""
    plant = MultibodyPlant(time_step=time_step)
    model = add_mcr(plant, suspension=suspension)
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
    T_b, is a constant (the identity for this robot).

    Args:
        plant: a finalized plant that contains the robot; a private plant of
            the robot alone is made if None.
        model: the McrModel of `plant` (required when `plant` is given).
        end_effector_frame: the frame whose origin is the end effector;
            the tool centre point if None.
    """

    def __init__(self, plant=None, model=None, end_effector_frame=None):
        if plant is None:
            plant, model = make_mcr_plant()
        elif model is None:
            raise ValueError(
                "model = None is not allowed when plant is given: pass the "
                "McrModel that add_mcr returned for that plant"
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
    return rocking_modes(plant, model, MOUNT_JOINTS, q_a)


def suspension_modes(plant, model, q_a=HOME_ARM_POSITIONS):
    """The suspension's rocking modes (as mount_rocking_modes, with the
    mount, the base's planar joints and the arm held) of a plant made
    with a suspension; `shape` is in (roll, pitch)."""
    return rocking_modes(plant, model, SUSPENSION_JOINTS, q_a)


def suspension_block(gains, q_a=HOME_ARM_POSITIONS):
    """(I, G): the diagonals of the mass matrix's block and of the gravity
    stiffness d tau_g / d theta (> 0: gravity topples the raised mass) of
    the suspension's joints, with the arm at `q_a` and the suspension of
    SuspensionGains `gains`, at rest."""
    plant, model = make_mcr_plant(suspension=gains)
    M, _, _, gravity = _compliant_block(plant, model, SUSPENSION_JOINTS,
                                        as_vector("q_a", q_a, 6))
    return np.diag(M).copy(), np.diag(gravity).copy()


def rocking_modes(plant, model, joints, q_a=HOME_ARM_POSITIONS):
    """The modes of the spring-damper joints `joints` of the base's model
    instance (all else held still), lowest frequency first (see
    mount_rocking_modes)."""
    q_a = as_vector("q_a", q_a, 6)
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
    gravity gradient d tau_g / d theta of the base's joints `joints`, at
    rest with the arm at q_a."""
    context = plant.CreateDefaultContext()
    q = plant.GetPositions(context)
    q[joint_position_indices(plant, ARM_JOINTS, model.arm)] = q_a
    plant.SetPositions(context, q)
    iq = joint_position_indices(plant, joints, model.base)
    iv = joint_velocity_indices(plant, joints, model.base)
    M = plant.CalcMassMatrix(context)[np.ix_(iv, iv)]
    springs = {
        element.joint().name(): element.GetStiffness(context)
        for element in _force_elements(plant)
        if isinstance(element, RevoluteSpring)
    }
    bodies = [plant.GetJointByName(n, model.base) for n in joints]
    k = np.array([springs.get(j.name(), 0.0) for j in bodies])
    C = np.diag([j.default_damping() for j in bodies])
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


def _force_elements(plant):
    return [
        plant.get_force_element(ForceElementIndex(i))
        for i in range(plant.num_force_elements())
    ]

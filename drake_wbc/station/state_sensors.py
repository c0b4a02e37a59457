"""What the simulated station reports of the robot's own state.

- `BaseOdometry`: the base's pose and twist, as the base's wheel odometry
  reports them (here without drift: the plant's planar joints); the
  station runs the same math as a C++ SymbolicVectorSystem
  (`odometry_system`, fed by `base_state_selection`).
- `GroundTruth`: what no sensor of the real robot measures, for metrics
  only (the motion-capture system of the paper's tracking experiment):
  the end effector's pose and velocity in the world (the base's pose and
  the mount's angles are selections of the plant's state, in C++). The
  controller never reads it.
"""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RollPitchYaw
from pydrake.symbolic import MakeVectorVariable
from pydrake.systems.framework import LeafSystem, LeafSystem_, ValueProducer
from pydrake.systems.primitives import SymbolicVectorSystem

from drake_wbc.math.base_state import BASE_STATE_SIZE
from drake_wbc.robot.model import (
    joint_position_indices,
    joint_velocity_indices,
)
from drake_wbc.stages.support import define_stage


def selection_matrix(indices, size):
    """The matrix that picks `indices` out of a vector of `size`."""
    S = np.zeros((len(indices), size))
    S[np.arange(len(indices)), indices] = 1.0
    return S


def world_to_body_twist(yaw, rates):
    """The base's twist [vx, vy, wz] in T_b from its joints' rates
    [x_dot, y_dot, yaw_dot] at heading `yaw` (the inverse of eq. (3)).
    For double, AutoDiffXd or symbolic scalars."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([c * rates[0] + s * rates[1],
                     -s * rates[0] + c * rates[1], rates[2]])


def odometry_system():
    """BaseOdometry's state_estimated as a stateless SymbolicVectorSystem
    (evaluated in C++): input the base joints' [x, y, yaw, x_dot, y_dot,
    yaw_dot] (6), output [x, y, yaw, vx, vy, wz] (6). Feed it
    `base_state_selection`."""
    x = MakeVectorVariable(6, "x")
    with np.errstate(all="ignore"):  # numpy's checks on symbolic arrays
        twist = world_to_body_twist(x[2], x[3:])
    return SymbolicVectorSystem(input=x,
                                output=np.concatenate([x[:3], twist]))


def base_state_selection(plant, model):
    """The (6, nq + nv) matrix that picks the base joints' positions and
    rates out of the plant's state [q; v]."""
    nq, nv = plant.num_positions(), plant.num_velocities()
    return np.vstack([
        selection_matrix(joint_position_indices(model.base_joints), nq + nv),
        selection_matrix(nq + joint_velocity_indices(model.base_joints),
                         nq + nv)])


@define_stage("BaseOdometry_")
def BaseOdometry_(T):
    class Impl(LeafSystem_[T]):
        """The base's odometry from the plant's state.

        ::

                            ┌──────────────┐
            plant_state ───►│              ├──► pose
                            │ BaseOdometry ├──► state_estimated
                            └──────────────┘

        - plant_state: the whole plant's state [q; v].
        - pose: [x, y, yaw] (3) of T_b in the world.
        - state_estimated: [x, y, yaw, vx, vy, wz] (6): the pose, then
          the twist in T_b, as a base's odometry reports it.

        Args:
            plant: the finalized plant holding the robot.
            model: its RobotModel.
        """

        def _construct(self, plant, model, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._plant, self._model = plant, model
            nq, nv = plant.num_positions(), plant.num_velocities()
            self._select_q = selection_matrix(
                joint_position_indices(model.base_joints),
                nq + nv)
            self._select_v = selection_matrix(
                nq + joint_velocity_indices(model.base_joints),
                nq + nv)
            self._state = self.DeclareVectorInputPort("plant_state", nq + nv)
            self.DeclareVectorOutputPort("pose", 3, self._pose)
            self.DeclareVectorOutputPort("state_estimated", BASE_STATE_SIZE,
                                         self._state_estimated)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other._plant, other._model,
                            converter=converter)

        def _pose(self, context, output):
            output.SetFromVector(self._select_q @ self._state.Eval(context))

        def _state_estimated(self, context, output):
            x = self._state.Eval(context)
            pose, rates = self._select_q @ x, self._select_v @ x
            output.SetFromVector(np.concatenate(
                [pose, world_to_body_twist(pose[2], rates)]))

    return Impl


BaseOdometry = BaseOdometry_[None]


class GroundTruth(LeafSystem):
    """The end effector's true motion, for metrics (double only).

    ::

                           ┌─────────────┐
        plant_state ──────►│ GroundTruth ├──► end_effector_pose
                           │             ├──► end_effector_velocity
                           └─────────────┘

    - end_effector_pose: (6) the tool centre point's position [x, y, z]
      and its orientation as roll, pitch, yaw, in the world.
    - end_effector_velocity: (6) its twist [v; w] in the world, the
      linear part at the tool centre point.

    Both come from one evaluation of the plant's kinematics at its state,
    in a scratch context of this system's own (the plant's body pose and
    velocity ports would convert every body's to Python at each reading:
    5% of a closed loop); so one GroundTruth serves one simulation at a
    time, as every station builds its own. The base's pose and the
    mount's angles are C++ selections of the state beside it
    (station.simulation).

    Args:
        plant: the finalized plant holding the robot.
        model: its RobotModel.
    """

    def __init__(self, plant, model):
        super().__init__()
        self._plant = plant
        self._kinematics = plant.CreateDefaultContext()
        self._tcp = model.tcp_frame
        self._state = self.DeclareVectorInputPort(
            "plant_state", plant.num_positions() + plant.num_velocities())
        self._motion = self.DeclareCacheEntry(
            "end_effector_motion",
            ValueProducer(allocate=lambda: AbstractValue.Make(np.zeros(12)),
                          calc=self._calc_motion),
            prerequisites_of_calc={
                self.input_port_ticket(self._state.get_index())})
        self.DeclareVectorOutputPort(
            "end_effector_pose", 6,
            lambda context, output: output.set_value(
                self._motion.Eval(context)[:6]),
            prerequisites_of_calc={self._motion.ticket()})
        self.DeclareVectorOutputPort(
            "end_effector_velocity", 6,
            lambda context, output: output.set_value(
                self._motion.Eval(context)[6:]),
            prerequisites_of_calc={self._motion.ticket()})

    def _calc_motion(self, context, value):
        """[end_effector_pose; end_effector_velocity] (12)."""
        self._plant.SetPositionsAndVelocities(self._kinematics,
                                              self._state.Eval(context))
        X_W_tcp = self._tcp.CalcPoseInWorld(self._kinematics)
        V_W_tcp = self._tcp.CalcSpatialVelocityInWorld(self._kinematics)
        value.set_value(np.concatenate([
            X_W_tcp.translation(),
            RollPitchYaw(X_W_tcp.rotation()).vector(),
            V_W_tcp.translational(), V_W_tcp.rotational()]))

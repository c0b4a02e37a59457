"""The PD gains of the robot's in-plant actuators (the wheel servo of the
base's velocity loop and the arm's joint servos), sized from the robot's
mass matrix; the drivers (drake_wbc.station.drivers) feed them their
desired states."""

import numpy as np
from pydrake.multibody.tree import PdControllerGains

from drake_wbc.math.validation import as_vector
from drake_wbc.robot.model import (
    joint_position_indices,
    joint_velocity_indices,
    shared_robot_plant,
)


def _mass_matrix(description, arm_positions, mount):
    """(M, model): the robot's mass matrix with the arm at
    `arm_positions` (n,) and mounted by the ArmMount `mount`, everything
    else at rest, and its RobotModel."""
    plant, model = shared_robot_plant(description, mount=mount)
    q_a = as_vector("arm_positions", arm_positions, model.num_arm_joints)
    context = plant.CreateDefaultContext()
    q = plant.GetPositions(context)
    q[joint_position_indices(model.arm_joints)] = q_a
    plant.SetPositions(context, q)
    return plant.CalcMassMatrix(context), model


def _actuators(plant, model, parts=("base", "arm")):
    """The actuator of each joint of RobotModel `model`'s `parts` (its
    base's planar joints, its arm's), in that order; a ValueError naming
    the description's field of a joint that has none."""
    by_joint = {}
    for index in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(index)
        by_joint[actuator.joint().index()] = actuator
    actuators = []
    for part in parts:
        names = getattr(model.description, part).joints
        for i, (name, joint) in enumerate(zip(
                names, getattr(model, f"{part}_joints"), strict=True)):
            if joint.index() not in by_joint:
                raise ValueError(
                    f"{part}.joints[{i}] = {name!r} is not allowed in the "
                    "simulated station: the model gives it no actuator, "
                    "which the station drives it through (Drake makes one "
                    "of a URDF's <transmission> of the joint, or of an "
                    "SDFormat joint, where its effort limit is not 0)")
            actuators.append(by_joint[joint.index()])
    return actuators


def servo_gains(arm_positions, base, arm, description=None, mount=None,
                base_drive_inertia=None):
    """The PD gains of the base's and the arm's actuators.

    The base's joints get a pure velocity servo, p = 0 and d = (M_ii +
    J_i) / servo_time_constant, J_i the drive's own reflected inertia
    (none on rigid wheels); each arm joint a PD loop of `servo_frequency`
    and `damping_ratio` on its diagonal inertia I = max(M_ii,
    min_inertia): p = I w^2, d = 2 zeta I w. M is the robot's mass
    matrix with the arm at `arm_positions` (the mount at rest; the base's
    position does not enter M).

    Args:
        arm_positions: (n,) the arm configuration to size for.
        base: BaseDriverParameters.
        arm: ArmDriverParameters.
        description: the RobotDescription; the shipped robot's if None.
        mount: the robot's ArmMount (as its model has it if None).
        base_drive_inertia: None (rigid wheels) or (3,) J, the drive's
            reflected inertia of the base's x, y and yaw joints in the
            plant (a horizontal compliance's,
            drake_wbc.robot.suspension.SuspensionGains.drive_inertia).

    Returns:
        dict: the joint's scoped name (as the description names it) ->
        PdControllerGains, for `set_servo_gains`.
    """
    M, model = _mass_matrix(description, arm_positions, mount)
    drive = (np.zeros(3) if base_drive_inertia is None
             else as_vector("base_drive_inertia", base_drive_inertia, 3))
    names = model.description
    w = 2.0 * np.pi * arm.servo_frequency
    gains = {}
    for name, i, J in zip(names.base.joints,
                          joint_velocity_indices(model.base_joints), drive,
                          strict=True):
        # M_ii + 0.0 is M_ii: rigid wheels' gains are as they were.
        gains[name] = PdControllerGains(
            p=0.0, d=(M[i, i] + J) / base.servo_time_constant)
    for name, i in zip(names.arm.joints,
                       joint_velocity_indices(model.arm_joints),
                       strict=True):
        inertia = max(M[i, i], arm.min_inertia)
        gains[name] = PdControllerGains(
            p=inertia * w * w, d=2.0 * arm.damping_ratio * inertia * w)
    return gains


def mass_on_wheels(arm_positions, description=None, mount=None):
    """kg, the mass the base's wheels carry: the robot's mass matrix at
    its x joint (the whole robot, which that joint moves), with the arm
    at `arm_positions` (`description`, `mount` as for `servo_gains`)."""
    M, model = _mass_matrix(description, arm_positions, mount)
    i = joint_velocity_indices(model.base_joints)[0]
    return float(M[i, i])


def set_servo_gains(plant, model, gains):
    """Gives the robot's actuators in `plant` (not yet finalized) the PD
    gains of `servo_gains`."""
    names = model.description
    for name, actuator in zip(names.base.joints + names.arm.joints,
                              _actuators(plant, model), strict=True):
        actuator.set_controller_gains(gains[name])


def drive_inertias(arm_positions, arm, description=None, mount=None):
    """The reflected inertia of each arm joint's geared drive, kg m^2:
    min_inertia - M_ii where the joint's own inertia M_ii (the mass
    matrix with the arm at `arm_positions`, as in `servo_gains`) is below
    ArmDriverParameters `arm`.min_inertia, else 0. With it in the plant
    (`set_drive_inertias`) each joint's inertia is the one its gains were
    sized for, so every servo really has `servo_frequency` (without it a
    light wrist joint's loop would be many times faster: 380 Hz for
    joint 6, beyond what a 5 ms plant step resolves).

    `description`, `mount`: as for `servo_gains`.

    Returns:
        dict: the arm joint's scoped name -> rotor inertia (gear ratio 1).
    """
    M, model = _mass_matrix(description, arm_positions, mount)
    return {name: max(arm.min_inertia - M[i, i], 0.0)
            for name, i in zip(model.description.arm.joints,
                               joint_velocity_indices(model.arm_joints),
                               strict=True)}


def set_drive_inertias(plant, model, inertias):
    """Gives the arm's actuators in `plant` (not yet finalized) the
    reflected inertias of `drive_inertias`."""
    for name, actuator in zip(model.description.arm.joints,
                              _actuators(plant, model, ("arm",)),
                              strict=True):
        actuator.set_default_gear_ratio(1.0)
        actuator.set_default_rotor_inertia(inertias[name])

"""The PD gains of the robot's in-plant actuators (the wheel servo of the
base's velocity loop and the arm's joint servos), sized from the robot's
mass matrix; the drivers (drake_wbc.station.drivers) feed them their
desired states."""

import numpy as np
from pydrake.multibody.tree import PdControllerGains

from drake_wbc.math.validation import as_vector
from drake_wbc.robot.model import (
    ARM_JOINTS,
    BASE_JOINTS,
    joint_velocity_indices,
    make_mcr_plant,
)


def servo_gains(arm_positions, base, arm, mount=None):
    """The PD gains of the base's and the arm's actuators.

    The base's joints get a pure velocity servo, p = 0 and d = M_ii /
    servo_time_constant; each arm joint a PD loop of `servo_frequency`
    and `damping_ratio` on its diagonal inertia I = max(M_ii,
    min_inertia): p = I w^2, d = 2 zeta I w. M is the robot's mass
    matrix with the arm at `arm_positions` (the mount at rest; the base's
    position does not enter M).

    Args:
        arm_positions: (6,) the arm configuration to size for.
        base: BaseDriverParameters.
        arm: ArmDriverParameters.
        mount: the robot's ArmMount (the shipped robot's if None).

    Returns:
        dict: joint name -> PdControllerGains, for `set_servo_gains`.
    """
    q_a = as_vector("arm_positions", arm_positions, 6)
    plant, model = make_mcr_plant(mount=mount)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, model.arm, q_a)
    M = plant.CalcMassMatrix(context)
    w = 2.0 * np.pi * arm.servo_frequency
    gains = {}
    for name, i in zip(BASE_JOINTS, joint_velocity_indices(
            plant, BASE_JOINTS, model.base), strict=True):
        gains[name] = PdControllerGains(
            p=0.0, d=M[i, i] / base.servo_time_constant)
    for name, i in zip(ARM_JOINTS, joint_velocity_indices(
            plant, ARM_JOINTS, model.arm), strict=True):
        inertia = max(M[i, i], arm.min_inertia)
        gains[name] = PdControllerGains(
            p=inertia * w * w, d=2.0 * arm.damping_ratio * inertia * w)
    return gains


def set_servo_gains(plant, model, gains):
    """Gives the robot's actuators in `plant` (not yet finalized) the PD
    gains of `servo_gains`."""
    for names, instance in ((BASE_JOINTS, model.base),
                            (ARM_JOINTS, model.arm)):
        for name in names:
            plant.GetJointActuatorByName(name, instance).set_controller_gains(
                gains[name])


def drive_inertias(arm_positions, arm, mount=None):
    """The reflected inertia of each arm joint's geared drive, kg m^2:
    min_inertia - M_ii where the joint's own inertia M_ii (the mass
    matrix with the arm at `arm_positions`, as in `servo_gains`) is below
    ArmDriverParameters `arm`.min_inertia, else 0. With it in the plant
    (`set_drive_inertias`) each joint's inertia is the one its gains were
    sized for, so every servo really has `servo_frequency` (without it a
    light wrist joint's loop would be many times faster: 380 Hz for
    joint 6, beyond what a 5 ms plant step resolves).

    `mount`: the robot's ArmMount (the shipped robot's if None).

    Returns:
        dict: arm joint name -> rotor inertia (gear ratio 1).
    """
    q_a = as_vector("arm_positions", arm_positions, 6)
    plant, model = make_mcr_plant(mount=mount)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, model.arm, q_a)
    M = plant.CalcMassMatrix(context)
    return {name: max(arm.min_inertia - M[i, i], 0.0)
            for name, i in zip(ARM_JOINTS, joint_velocity_indices(
                plant, ARM_JOINTS, model.arm), strict=True)}


def set_drive_inertias(plant, model, inertias):
    """Gives the arm's actuators in `plant` (not yet finalized) the
    reflected inertias of `drive_inertias`."""
    for name in ARM_JOINTS:
        actuator = plant.GetJointActuatorByName(name, model.arm)
        actuator.set_default_gear_ratio(1.0)
        actuator.set_default_rotor_inertia(inertias[name])

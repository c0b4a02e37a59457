"""Wheel slip: the traction limit of the base's wheels on the floor.

The slip law is Coulomb's, as a traction limit on the base's drive: the
floor can push the robot along each of the base's planar axes with at
most the friction force of its wheels,

    |F_x|, |F_y| <= mu m g,    |tau_yaw| <= mu m g rho,

with m the mass on the wheels (the whole robot: the base's drive carries
it, the diagonal of the mass matrix at its x joint), g gravity and rho the
wheels' distance from the footprint's centre (each wheel's friction acting
at its lever about z). When the base's velocity servo asks for more (a
rapid change of the velocity command), the wheels slip and the floor's
force stays at the limit, so the base's acceleration saturates at mu g
however hard the servo pushes; it follows its command again once the
servo's demand falls back below the limit.

In the plant the base's drive force *is* the floor's force on the robot
(the planar joints' actuators, a velocity servo: drake_wbc.station.
servo_gains), so the law is the actuators' effort limits, min(motor
limit, the traction limit) per axis: Drake's in-plant PD controllers
saturate their output at the effort limit, u = max(-e, min(e, u~))
(JointActuator.set_controller_gains; SAP, the station's discrete solver,
respects it). Simplifications, said: the limit is a box per axis of the
world (the x and y joints), not the friction circle of the wheels'
resultant (along a straight run the two agree); the normal force is the
static weight (no load transfer onto the front or rear wheels as the
base brakes or accelerates); static and kinetic friction are the same
mu; and the odometry, which reads the planar joints, sees the base's
true motion, not a spinning wheel's.

EST values (TractionParameters): rubber or polyurethane omnidirectional
wheels on a sealed or painted factory floor grip with mu 0.3 (dusty or
polished, mecanum rollers with little contact) to 0.6 (clean, rubber);
0.45 by default. With the shipped robot's 145 kg that is 640 N along x
and y, below the drives' own 900 N (models/mcr_base.sdf), about 4.4
m/s^2; the wheels sit at (+-0.26, +-0.25) m, rho = 0.36 m.
"""

from dataclasses import dataclass, replace

import numpy as np

from drake_wbc.math.validation import as_scalar, in_closed_range, positive


@dataclass
class TractionParameters:
    """The wheels' grip on the floor (a scenario's `station: traction:`).

    Attributes:
        friction_coefficient: mu, Coulomb's, of the wheels on the floor
            (0.45, EST: 0.3 to 0.6), in [0.05, 1.5].
        wheel_distance: rho, m, the wheels' distance from the footprint's
            centre, the lever of their friction about z, in (0, 2]; None
            (the default) for the robot's own, its description's
            base.wheel_distance (0.36 m on the shipped base), which the
            simulated station puts here (`own_traction`).
    """

    friction_coefficient: float = 0.45
    wheel_distance: float | None = None

    def __post_init__(self):
        in_closed_range("friction_coefficient", self.friction_coefficient,
                        0.05, 1.5)
        if self.wheel_distance is None:
            return
        if positive("wheel_distance", self.wheel_distance) > 2.0:
            raise ValueError(
                f"wheel_distance = {self.wheel_distance!r} m is not allowed:"
                " must lie in (0, 2] m")


def traction_limits(params, mass, gravity):
    """(3,) the floor's largest force along x and y, N, and torque about
    z, N m: mu m g, mu m g, mu m g rho (the module's docstring), for
    TractionParameters `params`, the `mass` on the wheels (kg) and
    `gravity` (m/s^2); its wheel_distance given (`own_traction`)."""
    if params.wheel_distance is None:
        raise ValueError(
            "wheel_distance = None is not allowed here: give the robot's "
            "own (own_traction)")
    mass = positive("mass", as_scalar("mass", mass))
    gravity = positive("gravity", as_scalar("gravity", gravity))
    force = params.friction_coefficient * mass * gravity
    return np.array([force, force, force * params.wheel_distance])


def own_traction(params, base, prefix=""):
    """TractionParameters `params` with its wheel_distance the robot's
    own (`base`, its BaseDescription: base.wheel_distance) where it gives
    none.

    Raises:
        ValueError: naming the field (after `prefix`) when neither gives
            one.
    """
    if params.wheel_distance is not None:
        return params
    if base.wheel_distance is None:
        raise ValueError(
            f"{prefix}wheel_distance is missing, which is not allowed: the "
            "robot's description gives no base.wheel_distance (the wheels' "
            "distance from the footprint's centre, m); give one of them")
    return replace(params, wheel_distance=base.wheel_distance)


def set_traction_limits(plant, model, limits):
    """Lowers the effort limits of the base's actuators in `plant` (not
    yet finalized) to the traction `limits` (3,) where these are below
    the drives' own (x, y, yaw, in the order of model.base_joints)."""
    by_joint = {plant.get_joint_actuator(i).joint().index(): i
                for i in plant.GetJointActuatorIndices()}
    for joint, limit in zip(model.base_joints, limits, strict=True):
        actuator = plant.get_joint_actuator(by_joint[joint.index()])
        actuator.set_effort_limit(min(actuator.effort_limit(),
                                      float(limit)))

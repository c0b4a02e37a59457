"""The shipped robot's joint names, read from its description
(models/mcr.robot.yaml), for the tests that look its joints up in a plant
by name: unscoped (`joint1`, with the model instance beside) and scoped
(`elfin5::joint1`, as the description and the servo gains name them)."""

from drake_wbc.robot.description import shipped_robot

ROBOT = shipped_robot()


def _element(name):
    return name.rsplit("::", 1)[-1]


ARM_JOINTS = tuple(_element(n) for n in ROBOT.arm.joints)
BASE_JOINTS = tuple(_element(n) for n in ROBOT.base.joints)
MOUNT_JOINTS = tuple(_element(n) for n in ROBOT.base.passive_joints)
SCOPED = {_element(n): n for n in
          ROBOT.arm.joints + ROBOT.base.joints + ROBOT.base.passive_joints}
"""Unscoped joint name -> scoped name."""

ROBOT_ACCELERATION_LIMIT = 12.56
"""The Elfin5's joint acceleration limit, rad/s^2 (models/elfin5.sdf), the
same on every joint: what the arm controller brakes at by default."""

BASE_VELOCITY_LIMITS = tuple(ROBOT.base.velocity_limits)
"""The shipped base's own velocity limits [vx, vy, wz]."""
BASE_ACCELERATION_LIMITS = tuple(ROBOT.base.acceleration_limits)
"""The shipped base's own acceleration limits [vx, vy, wz]."""
FOOTPRINT = tuple(ROBOT.base.footprint_half_sizes)
"""The shipped base's footprint half sizes (a, b), m."""
BASE_LIMITS = dict(base_velocity_limits=BASE_VELOCITY_LIMITS,
                   base_acceleration_limits=BASE_ACCELERATION_LIMITS,
                   base_lag=ROBOT.base.velocity_lag, stop_distance=0.1)
"""SafetyParameters' keywords for the shipped base's own limits and stop
distance (what build_controller fills in; a stage built alone is given
them)."""

"""The layout of the base's state, as the station gives it on
`base.state_estimated` (the odometry, simulated or over LCM):

    [x, y, yaw, vx, vy, wz]

the pose [x, y, yaw] in the world (m, m, rad) and the twist
[vx, vy, wz] in T_b (m/s, m/s, rad/s). Every reader of that vector
takes its parts by these names.
"""

BASE_STATE_SIZE = 6
"""The number of entries of the base's state."""

BASE_POSE = slice(0, 3)
"""The pose [x, y, yaw] in the world."""

BASE_YAW = 2
"""The yaw phi_b, the last entry of the pose."""

BASE_TWIST = slice(3, 6)
"""The twist [vx, vy, wz] in T_b."""

BASE_AXES = 3
"""The base's velocity components [vx, vy, wz] (T_b): the size of its
twist, of its velocity command and of its limits."""

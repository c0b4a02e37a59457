"""Demonstrations of a whole-body movement, recorded in pHRI mode, for
teach and repeat (drake_wbc.math.movement).

Recording. `demonstration_from_log` builds the TCP's pose from the
MEASURED arm joints and the base's odometry (base.state_estimated)
through the controller's nominal kinematics (robot_model.ArmKinematics:
mount at rest), the same for a simulated RunLog and for an lcm-logger log
read as a RunLog (drake_wbc.deployment.lcm_logs); the yaw is unwrapped.

Start and stop markers. The demonstration is the interval in which the
worker has pHRI on: the task's S_hri schedule (`teaching_interval`). It
exists on the real robot as on the simulated one (the scenario's task
schedule runs on the controller's clock, which an lcm-logger log keeps),
it is what the worker does anyway to guide the robot, and switching it
off once the robot rests gives a demonstration that ends at rest, as the
DMP fit needs. `drake-wbc teach --start/--stop` overrides it.
"""

import math
from dataclasses import dataclass

import numpy as np

from drake_wbc.math.kernels import body_for, fast_kernel
from drake_wbc.math.validation import as_matrix, as_vector

DIMENSIONS = ("x", "y", "z", "yaw")
"""The recorded (and learned) dimensions of the TCP's pose, in order."""


@dataclass(frozen=True, eq=False)
class Demonstration:
    """One demonstration: sample times and what the robot did.

    Attributes:
        time: (N,) strictly increasing times, s.
        tcp: (N, 4) the TCP's pose [x, y, z, yaw] in the world (m, rad),
            yaw unwrapped.
        base: (N, 3) the base's pose [x, y, yaw] in the world, or None.
        arm: (N, n) the arm's joints (rad), or None.
    """

    time: np.ndarray
    tcp: np.ndarray
    base: np.ndarray | None = None
    arm: np.ndarray | None = None

    def __post_init__(self):
        time = as_vector("time", self.time)
        if time.size < 3:
            raise ValueError(f"time = {time.tolist()!r} is not allowed: "
                             "must hold 3 or more strictly increasing times")
        back = np.nonzero(np.diff(time) <= 0.0)[0]
        if back.size:
            i = int(back[0]) + 1
            raise ValueError(
                f"time[{i}] = {float(time[i])!r} s is not allowed: the times "
                f"must increase strictly (time[{i - 1}] = "
                f"{float(time[i - 1])!r} s; "
                f"{back.size} of the {time.size} samples do not)")
        object.__setattr__(self, "time", time)
        object.__setattr__(self, "tcp", as_matrix("tcp", self.tcp,
                                                  (time.size, 4)))
        for name, width in (("base", 3), ("arm", None)):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, as_matrix(
                    name, value, (time.size, width)))

    @property
    def duration(self):
        """The demonstration's length, s."""
        return float(self.time[-1] - self.time[0])


def tcp_pose_in_world(base_pose, X_BT):
    """The TCP's pose [x, y, z, yaw] in the world from the base's pose
    [x, y, yaw] in the world and the TCP's pose in T_b.

    With the base's heading Rz(yaw) (eq. (3); T_b on the floor): the
    position Rz(yaw) p_BT + [x, y, 0], and the yaw of the roll-pitch-yaw
    angles (R = Rz Ry Rx) of R = Rz(yaw) R_BT, atan2(R[1, 0], R[0, 0]).

    Args:
        base_pose: (3,) [x, y, yaw] of T_b in the world (m, rad).
        X_BT: (3, 4) the TCP's pose [R_BT | p_BT] in T_b.

    A yaw that is not finite has no heading: x, y and the yaw are NaN.

    Returns:
        (4,) [x, y, z, yaw] (float or AutoDiffXd).
    """
    x, y, yaw = base_pose
    c, s = np.cos(yaw), np.sin(yaw)
    r00, r10 = X_BT[0][0], X_BT[1][0]
    px, py, pz = X_BT[0][3], X_BT[1][3], X_BT[2][3]
    return np.array([c * px - s * py + x, s * px + c * py + y, pz,
                     np.arctan2(s * r00 + c * r10, c * r00 - s * r10)])


def _pose_inputs(rng):
    """A random base pose (any heading) and a random TCP pose in T_b; in
    one case in ten an entry of either NaN or infinite."""
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    R *= np.sign(np.linalg.det(R))
    X_BT = np.column_stack([R, rng.uniform(-1.0, 1.0, 3)])
    base_pose = np.r_[rng.uniform(-5.0, 5.0, 2), rng.uniform(-10.0, 10.0)]
    if rng.random() < 0.1:
        pose = base_pose if rng.random() < 0.5 else X_BT
        pose[np.unravel_index(rng.integers(pose.size), pose.shape)] = (
            rng.choice([np.nan, np.inf, -np.inf]))
    return base_pose, X_BT


@fast_kernel(tcp_pose_in_world, sample=_pose_inputs)
def tcp_pose_in_world_float(base_pose, X_BT):
    """`tcp_pose_in_world` in plain floats (math.cos, math.atan2), a
    list: the replay's tracking (MovementTracking), each control tick."""
    x, y, yaw = base_pose
    try:
        c, s = math.cos(yaw), math.sin(yaw)
    except ValueError:  # an infinite yaw: NaN, as np.cos gives
        c = s = math.nan
    (r00, _, _, px), (r10, _, _, py), (_, _, _, pz) = np.asarray(
        X_BT).tolist()
    return [c * px - s * py + x, s * px + c * py + y, pz,
            math.atan2(s * r00 + c * r10, c * r00 - s * r10)]


class TcpPose:
    """The TCP's pose [x, y, z, yaw] in the world from the base's pose
    [x, y, yaw] and the arm's joints (n,), through the nominal kinematics
    (robot_model.ArmKinematics, the controller's: mount at rest, T_b on
    the floor) and `tcp_pose_in_world`. Call it with (base_pose,
    arm_positions); float only.

    Args:
        arm: the robot's ArmKinematics (drake_wbc.robot.model).
    """

    def __init__(self, arm):
        self.arm = arm
        model = arm.model
        X_BA = model.arm_base_frame.CalcPose(
            arm.plant.CreateDefaultContext(),
            model.base_frame).GetAsMatrix34()
        self._R_BA, self._p_BA = X_BA[:, :3].copy(), X_BA[:, 3].copy()
        self._in_world = body_for(tcp_pose_in_world, float)

    def in_base(self, arm_positions):
        """X_BT (3, 4): the TCP's pose [R_BT | p_BT] in T_b at the arm's
        joints, ^bR_a X_AT plus the arm base's origin."""
        X = self._R_BA.dot(self.arm.frame_pose(
            arm_positions, self.arm.model.tcp_frame).GetAsMatrix34())
        X[:, 3] += self._p_BA
        return X

    def __call__(self, base_pose, arm_positions):
        return np.array(self._in_world(base_pose,
                                       self.in_base(arm_positions)))


def tcp_poses(base_pose, arm_positions, arm):
    """The TCP's pose [x, y, z, yaw] (N, 4) in the world from the base's
    pose [x, y, yaw] (N, 3) and the arm's joints (N, n) (TcpPose); yaw
    unwrapped."""
    base_pose = as_matrix("base_pose", base_pose, (None, 3))
    arm_positions = as_matrix("arm_positions", arm_positions,
                              (base_pose.shape[0], arm.num_joints))
    pose = TcpPose(arm)
    poses = np.array([pose(b, q) for b, q in zip(base_pose, arm_positions,
                                                   strict=True)])
    poses[:, 3] = np.unwrap(poses[:, 3])
    return poses


def demonstration_from_log(log, start, stop, arm):
    """The demonstration in `log` (a RunLog) between `start` and `stop`
    (s, inclusive), from the measured joints and the base's odometry
    through `arm`, the robot's ArmKinematics (module docstring).

    Raises:
        ValueError: for a log whose times do not increase strictly, an
            interval that is not one of the log's with 3 or more samples,
            or a sample in it that is not finite (naming the signal and
            its time).
    """
    start, stop = float(start), float(stop)
    time = np.asarray(log.time, dtype=float)
    back = np.nonzero(~(np.diff(time) > 0.0))[0]
    if back.size:
        i = int(back[0]) + 1
        raise ValueError(
            f"the log's time[{i}] = {float(time[i])!r} s is not allowed: a "
            f"log's times must increase strictly (time[{i - 1}] = "
            f"{float(time[i - 1])!r} s)")
    mask = (time >= start - 1e-9) & (time <= stop + 1e-9)
    if not stop > start or np.count_nonzero(mask) < 3:
        span = (f"from {time[0]:.3f} to {time[-1]:.3f} s" if time.size
                else "which holds no sample")
        raise ValueError(
            f"start = {start!r} s, stop = {stop!r} s is not allowed: must "
            f"be an interval of the log ({span}) with 3 or more samples")
    base = np.asarray(log["base.state_estimated"], dtype=float)[mask, :3]
    joints = np.asarray(log["arm.position_measured"], dtype=float)[mask]
    for name, values in (("base.state_estimated", base),
                         ("arm.position_measured", joints)):
        bad = np.nonzero(~np.isfinite(values).all(axis=1))[0]
        if bad.size:
            k = int(bad[0])
            raise ValueError(
                f"{name} = {values[k].tolist()} at t = {time[mask][k]:.3f} s "
                "is not allowed: a demonstration's samples must be finite "
                f"({bad.size} of its {len(values)} are not); give a start "
                "and stop around them")
    return Demonstration(time[mask], tcp_poses(base, joints, arm), base,
                         joints)


def teaching_interval(schedule, duration, default_switch=0.0):
    """(start, stop) of the first interval where S_hri is 1 in a task
    Schedule of phri_switch, as the runner plays it (hold: from the time
    of a value 1 to that of the next 0; linear: S_hri >= 0.5 counts as 1,
    half way between those times; an empty schedule is the parameter
    `default_switch` throughout), clipped to [0, duration]."""
    times = list(schedule.times)
    values = [float(v[0]) for v in schedule.values]
    if not times:
        times, values = [0.0], [float(default_switch)]
    on = [v >= 0.5 for v in values]
    share = 0.5 if schedule.interpolation == "linear" else 0.0

    def change(j):  # where S_hri turns between times[j - 1] and times[j]
        return times[j] - share * (times[j] - times[j - 1])

    for i, is_on in enumerate(on):
        if is_on:
            start = 0.0 if i == 0 else change(i)
            stop = next((change(j) for j in range(i + 1, len(on))
                         if not on[j]), duration)
            return max(start, 0.0), min(stop, duration)
    raise ValueError(
        f"phri_switch = {values!r} is not allowed for teaching: S_hri is "
        "never 1, so there is no demonstration; switch it on while the "
        "worker guides the robot, or give the start and stop times")

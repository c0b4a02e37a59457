"""Experiment 5, intuitive physical human-robot interaction (paper Sec. V,
"Intuitive Human-Robot Interaction", Fig. "hri_pic"; Sec. IV-C).

A hand pushes the tool (scene.hand) with S_hri = 1: the whole body follows
the force through k_hri F_ext of eq. (cdmp-wb), and the intuitive pHRI
mode shares the motion by the local workspace: the arm alone while the
end effector stays within d^l and phi^l of the arm's base, the base as it
leaves them (sigma_xy, sigma_phi of Table (T:motion-mode)).

Stages. The hand's schedule is read as pushes (the intervals where its
force or torque is not zero); pushes less than STAGE_GAP apart form one
stage, and the stages are lettered A, B, ... in order, as in the paper's
figure. A stage runs from its first push to the next stage's first push
(the first from 0, the last to the end of the run).

Per stage S, each metric named `<run>.<S>.<metric>`:

- start_s, end_s; hand_impulse_N_s: the integral of the hand's |F|.
- base_dx_m, base_dy_m, base_rotation_rad: the base's net motion in the
  world (x, y of T_b and its yaw, end minus start); base_path_m its path
  length; base_max_displacement_m and base_max_rotation_rad the largest
  distance and yaw from where it started (ground truth).
- arm_path_m: the path length of the TCP in the plane of T_b (the arm's
  own motion, from the measured joints; its vertical motion, which the
  base cannot share, left out); arm_displacement_m: its net displacement
  in T_b, in 3-D.
- base_share: the base's part of the TCP's motion in the world, the path
  of the point of T_b at the TCP over that path plus arm_path_m; mover:
  "base" (share >= MOVER_SHARE), "arm" (<= 1 - MOVER_SHARE), "both", or
  "none" (less than STILL_PATH in all).
- sigma_xy_min, sigma_phi_min; d_max_m, phi_max_deg: the TCP's largest
  extent and deflection from the arm's base (drake_wbc.math.workspace, the
  controller's nominal kinematics).
- base_speed_command_max_m_s, base_yaw_rate_command_max_rad_s: V_b^ref.
- obstacle_min_distance_m: the least distance from the footprint to a
  static obstacle (inf without any).

And `<run>.stages`, the stages' letters.
"""

import numpy as np

from drake_wbc.experiments.common import (
    new_figure,
    path_length,
    sample_period,
    save_figure,
    static_distances,
)
from drake_wbc.experiments.scenario import (
    controller_arm,
    controller_for,
    footprint_of,
)
from drake_wbc.math import workspace
from drake_wbc.robot.model import ArmKinematics

STAGE_GAP = 1.2
"""s: pushes of the hand at least this far apart start a new stage."""

MOVER_SHARE = 0.7
"""The base's share of the motion above which it is "the" mover (and the
arm's below 1 - MOVER_SHARE)."""

STILL_PATH = 0.01
"""m: a stage in which base and arm move less than this in all: "none"."""

STAGE_METRICS = (
    "start_s", "end_s", "hand_impulse_N_s", "base_dx_m", "base_dy_m",
    "base_rotation_rad", "base_path_m", "base_max_displacement_m",
    "base_max_rotation_rad", "arm_path_m", "arm_displacement_m",
    "base_share", "mover", "sigma_xy_min", "sigma_phi_min", "d_max_m",
    "phi_max_deg", "base_speed_command_max_m_s",
    "base_yaw_rate_command_max_rad_s", "obstacle_min_distance_m",
)
"""The metrics of each stage (module docstring)."""


def hand_pushes(hand):
    """The intervals (start, end) in s where the HandForce `hand` (its
    force or its torque) is not zero, in order."""
    forces = np.linalg.norm(np.asarray(hand.forces, dtype=float).reshape(
        -1, 3), axis=1)
    if hand.torques:
        forces = forces + np.linalg.norm(hand.torques, axis=1)
    pushes = []
    for i in range(len(hand.times) - 1):
        if forces[i] > 0.0 or forces[i + 1] > 0.0:
            start, end = hand.times[i], hand.times[i + 1]
            if pushes and forces[i] > 0.0 and pushes[-1][1] == start:
                pushes[-1] = (pushes[-1][0], end)
            else:
                pushes.append((start, end))
    return pushes


def stages(scenario):
    """The stages [(letter, start, end)] of the scenario's hand schedule
    (module docstring), clipped to its duration; empty without a hand."""
    starts = []
    last_end = -np.inf
    for start, end in hand_pushes(scenario.scene.hand):
        if start - last_end >= STAGE_GAP:
            starts.append(start)
        last_end = end
    starts = [s for s in starts if s < scenario.duration]
    if not starts:
        return []
    starts[0] = 0.0
    ends = starts[1:] + [scenario.duration]
    return [(chr(ord("A") + i), s, e)
            for i, (s, e) in enumerate(zip(starts, ends, strict=True))]


def tcp_in_arm_base(log, arm=None):
    """The TCP's position (N, 3) in T_a and in T_b, from the measured
    joints with the controller's nominal kinematics (mount at rest) of
    `arm` (the run's ArmKinematics, the shipped robot's if None)."""
    arm = arm or ArmKinematics()
    context = arm.plant.CreateDefaultContext()
    X_BA = arm.model.arm_base_frame.CalcPose(context, arm.model.base_frame)
    in_a = np.array([arm.frame_pose(q, arm.model.tcp_frame).translation()
                     for q in log["arm.position_measured"]])
    return in_a, in_a @ X_BA.rotation().matrix().T + X_BA.translation()


def extent_and_deflection(log, arm=None):
    """d (m) and phi (rad) of the TCP, (N,) each (drake_wbc.math.workspace),
    on `arm` as `tcp_in_arm_base`."""
    in_a, _ = tcp_in_arm_base(log, arm)
    return (np.array([workspace.extent(p) for p in in_a]),
            np.array([workspace.deflection(p) for p in in_a]))


def _rotate(yaw, points):
    c, s = np.cos(yaw), np.sin(yaw)
    return np.column_stack([c * points[:, 0] - s * points[:, 1],
                            s * points[:, 0] + c * points[:, 1]])


def stage_metrics(scenario, log, start, end, tcp_b, d, phi, distance):
    """STAGE_METRICS of the samples start <= t <= end."""
    mask = (log.time >= start) & (log.time <= end)
    base = log["truth.base_pose"][mask]
    xy, yaw = base[:, :2], base[:, 2]
    tcp = tcp_b[mask, :2]
    # The point of T_b at the TCP, moved by the base alone, and the TCP
    # moved by the arm alone, step by step (in the world).
    by_base = (_rotate(yaw[1:], tcp[:-1]) + xy[1:]
               - _rotate(yaw[:-1], tcp[:-1]) - xy[:-1])
    by_arm = _rotate(yaw[:-1], tcp[1:] - tcp[:-1])
    base_tcp = float(np.sum(np.linalg.norm(by_base, axis=1)))
    arm_path = float(np.sum(np.linalg.norm(by_arm, axis=1)))
    total = base_tcp + arm_path
    share = base_tcp / total if total > 0.0 else 0.0
    if total < STILL_PATH:
        mover = "none"
    elif share >= MOVER_SHARE:
        mover = "base"
    elif share <= 1.0 - MOVER_SHARE:
        mover = "arm"
    else:
        mover = "both"
    hand = np.linalg.norm(log["truth.hand_force"][mask, :3], axis=1)
    command = log["base.velocity_command"][mask]
    return {
        "start_s": float(start),
        "end_s": float(end),
        "hand_impulse_N_s": float(np.sum(hand) * sample_period(log)),
        "base_dx_m": float(xy[-1, 0] - xy[0, 0]),
        "base_dy_m": float(xy[-1, 1] - xy[0, 1]),
        "base_rotation_rad": float(yaw[-1] - yaw[0]),
        "base_path_m": path_length(xy),
        "base_max_displacement_m": float(np.max(np.linalg.norm(
            xy - xy[0], axis=1))),
        "base_max_rotation_rad": float(np.max(np.abs(yaw - yaw[0]))),
        "arm_path_m": arm_path,
        "arm_displacement_m": float(np.linalg.norm(tcp_b[mask][-1]
                                                   - tcp_b[mask][0])),
        "base_share": float(share),
        "mover": mover,
        "sigma_xy_min": float(np.min(log["sigma_xy"][mask])),
        "sigma_phi_min": float(np.min(log["sigma_phi"][mask])),
        "d_max_m": float(np.max(d[mask])),
        "phi_max_deg": float(np.degrees(np.max(phi[mask]))),
        "base_speed_command_max_m_s": float(np.max(np.linalg.norm(
            command[:, :2], axis=1))),
        "base_yaw_rate_command_max_rad_s": float(np.max(np.abs(
            command[:, 2]))),
        "obstacle_min_distance_m": float(np.min(distance[mask])),
    }


def compute_metrics(scenario, logs):
    """STAGE_METRICS of each stage of each run, and the stages' letters."""
    metrics = {}
    windows = stages(scenario)
    arm = controller_arm(scenario)
    for name, log in logs.items():
        _, tcp_b = tcp_in_arm_base(log, arm)
        d, phi = extent_and_deflection(log, arm)
        distance = static_distances(scenario, log)
        metrics[f"{name}.stages"] = "".join(s for s, _, _ in windows)
        for stage, start, end in windows:
            values = stage_metrics(scenario, log, start, end, tcp_b, d, phi,
                                   distance)
            for key in STAGE_METRICS:
                metrics[f"{name}.{stage}.{key}"] = values[key]
    return metrics


def _shade_stages(axes, windows):
    for i, (stage, start, end) in enumerate(windows):
        for axis in axes:
            if i % 2 == 0:
                axis.axvspan(start, end, color="0.92", zorder=0)
        axes[0].text(0.5 * (start + end), 1.02, stage, ha="center",
                     va="bottom", transform=axes[0].get_xaxis_transform(),
                     fontsize=10, fontweight="bold")


def draw_figures(scenario, logs, folder):
    """Fig. "hri_pic", per run: `phri_<run>.png` (the hand's force,
    sigma_xy and sigma_phi, the base's velocity command, d and phi of the
    TCP against their bands, the stages shaded and lettered) and
    `phri_<run>_top.png` (the base's and the TCP's paths seen from above,
    with the obstacles and the footprint at each stage's start)."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Polygon

    band = controller_for(scenario).workspace.workspace
    windows = stages(scenario)
    paths = []
    arm = controller_arm(scenario)
    for name, log in logs.items():
        t = log.time
        d, phi = extent_and_deflection(log, arm)
        fig, axes = new_figure(5, title="Intuitive pHRI: stages "
                               f"{''.join(s for s, _, _ in windows)} "
                               f"({name})")
        for i, label in enumerate("xyz"):
            axes[0].plot(t, log["truth.hand_force"][:, i], label=label)
        axes[0].set_ylabel("hand force (N)")
        axes[1].plot(t, log["sigma_xy"][:, 0], label=r"$\sigma_{xy}$")
        axes[1].plot(t, log["sigma_phi"][:, 0], "--",
                     label=r"$\sigma_\phi$")
        axes[1].set_ylabel(r"$\sigma$")
        for i, label in enumerate(("$v_x$", "$v_y$", r"$\omega_z$")):
            axes[2].plot(t, log["base.velocity_command"][:, i], label=label)
        axes[2].set_ylabel("$V_b^{ref}$ (m/s, rad/s)")
        axes[3].plot(t, d, label="$d$")
        axes[3].axhspan(band.extent_lower, band.extent_upper, color="r",
                        alpha=0.2, label="$[d^l, d^u]$")
        axes[3].set_ylabel("$d$ (m)")
        axes[4].plot(t, np.degrees(phi), label=r"$\phi$")
        axes[4].axhspan(np.degrees(band.deflection_lower),
                        np.degrees(band.deflection_upper), color="r",
                        alpha=0.2, label=r"$[\phi^l, \phi^u]$")
        axes[4].set_ylabel(r"$\phi$ (deg)")
        _shade_stages(axes, windows)
        for axis in axes:
            axis.legend(loc="upper left", fontsize=7, ncol=3)
        paths.append(save_figure(fig, folder, f"phri_{name}"))
        plt.close(fig)

        base = log["truth.base_pose"]
        tcp = log["truth.end_effector_pose"]
        span = np.ptp(np.vstack([base[:, :2], tcp[:, :2]]), axis=0) + 1.0
        fig, axis = plt.subplots(figsize=(
            8.0, float(np.clip(8.0 * span[1] / span[0], 3.0, 8.0)) + 1.0))
        axis.plot(base[:, 0], base[:, 1], label="base")
        axis.plot(tcp[:, 0], tcp[:, 1], label="TCP")
        for c in scenario.scene.cylinders:
            axis.add_patch(Circle(c.position, c.radius, color="0.5"))
        for box in scenario.scene.boxes:
            half = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]]) * np.array(
                box.size[:2]) / 2
            axis.add_patch(Polygon(_rotate(np.full(4, box.yaw), half)
                                   + box.center[:2], color="0.7"))
        a, b = footprint_of(scenario)
        corners = np.array([[a, b], [-a, b], [-a, -b], [a, -b]])
        for stage, start, _ in windows:
            k = np.searchsorted(t, start)
            x, y, yaw = base[min(k, len(t) - 1)]
            axis.add_patch(Polygon(_rotate(np.full(4, yaw), corners)
                                   + [x, y], fill=False, ec="C0", lw=0.8))
            axis.annotate(stage, (x, y), fontsize=10, fontweight="bold")
        axis.set_aspect("equal")
        axis.grid(True, alpha=0.3)
        axis.set_xlabel("x (m)")
        axis.set_ylabel("y (m)")
        axis.legend(loc="upper left", fontsize=8)
        axis.set_title(f"pHRI seen from above ({name})", fontsize=10)
        paths.append(save_figure(fig, folder, f"phri_{name}_top"))
        plt.close(fig)
    return paths

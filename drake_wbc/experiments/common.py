"""What every run reports, and the tools the experiments share.

`compute_metrics` and `draw_figures` here are those of the `generic`
experiment: per run, the closest approach of the base to any obstacle or
person, the capability of movement, the largest commands and the joint
limit margins, all from ground truth, and the arm's fault where the log
knows it (`arm_fault`: the station's sentence, or "none"); and one
overview figure.
"""

from dataclasses import replace
from pathlib import Path

import numpy as np

from drake_wbc.experiments.scenario import controller_arm, footprint_of
from drake_wbc.math import repulsion
from drake_wbc.math.safety import STATUS_FIELDS
from drake_wbc.station.scene import planar_shapes

BOUNDARY_POINTS_PER_METRE = 200
"""How densely box obstacles' outlines are sampled for distances."""


def window(log, start, end=np.inf):
    """A boolean mask of the log's samples with start <= t < end."""
    return (log.time >= start) & (log.time < end)


def sample_period(log):
    """The log's sample period in s: the median spacing of its times (a
    simulated run's outputs.log_period; an lcm-logger log's is its
    clock's, drake_wbc.deployment.lcm_logs)."""
    return float(np.median(np.diff(log.time)))


def schedule_values(schedule, times, default):
    """A task input's Schedule evaluated at `times`, as the runner plays it
    (drake_wbc.controller.task.schedule_source): (N, k) values, or `default`
    (a number or a sequence) at every time when the schedule is empty."""
    times = np.asarray(times, dtype=float)
    if not schedule.times:
        return np.tile(np.atleast_1d(np.asarray(default, dtype=float)),
                       (len(times), 1))
    knots = np.asarray(schedule.times, dtype=float)
    values = np.asarray(schedule.values, dtype=float)
    if schedule.interpolation == "linear":
        return np.column_stack([np.interp(times, knots, values[:, j])
                                for j in range(values.shape[1])])
    index = np.clip(np.searchsorted(knots, times, side="right") - 1, 0,
                    len(knots) - 1)
    return values[index]


def held_integral(time, rate):
    """The running integral (N, k) from time[0] of `rate` (N, k) sampled at
    `time` (N,) and held over each sample, as the controller holds what it
    reads over a tick: I_0 = 0, I_k = sum over j < k of rate_j (t_(j+1) -
    t_j)."""
    rate = np.asarray(rate, dtype=float)
    steps = rate[:-1] * np.diff(time)[:, None]
    return np.vstack([np.zeros((1, rate.shape[1])), np.cumsum(steps, 0)])


def integrated_deviation(log):
    """x_dist, y_dist, z_dist: int delta_V_ee dt of eq. (deviation), (N, 3),
    from the controller's end_effector_deviation held over each sample
    (`held_integral`), as WholeBodyCdmp integrates it, eq.
    (cdmp-wb-error)."""
    return held_integral(log.time, log["end_effector_deviation"][:, :3])


def band_rms(time, signal, band, mask=None, order=4):
    """RMS of `signal` (N,) band-passed to `band` (low, high) Hz with a
    zero-phase Butterworth filter, over the samples in `mask` (all if
    None). `time` must be evenly sampled."""
    # Imported here: scipy.signal takes 0.7 s to import, which every other
    # command and scenario would pay for nothing.
    from scipy.signal import butter, sosfiltfilt

    fs = 1.0 / np.median(np.diff(time))
    sos = butter(order, band, btype="bandpass", fs=fs, output="sos")
    filtered = sosfiltfilt(sos, np.asarray(signal, dtype=float))
    if mask is not None:
        filtered = filtered[mask]
    return float(np.sqrt(np.mean(filtered**2)))


def _box_outline(box):
    """Points on the outline of a planar box [cx, cy, hx, hy, yaw]."""
    cx, cy, hx, hy, yaw = box
    corners = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy],
                        [hx, hy]])
    points = []
    for start, end in zip(corners[:-1], corners[1:], strict=True):
        n = max(2, int(np.linalg.norm(end - start)
                       * BOUNDARY_POINTS_PER_METRE))
        points.append(start + np.linspace(0.0, 1.0, n)[:, None]
                      * (end - start))
    c, s = np.cos(yaw), np.sin(yaw)
    return np.concatenate(points) @ np.array([[c, s], [-s, c]]) + [cx, cy]


def obstacle_distances(scene, base_pose, footprint, people_positions=None,
                       height=0.2):
    """The distance from the base's footprint to the nearest obstacle or
    person at each sample, from ground truth.

    Args:
        scene: the scenario's Scene.
        base_pose: (N, 3) [x, y, yaw] of T_b in the world.
        footprint: the base's half sizes (a, b) in m (the robot's,
            drake_wbc.experiments.scenario.footprint_of).
        people_positions: (N, 2P) the people's positions, or None.
        height: the height at which static obstacles count (the LIDARs'
            scan plane).

    Returns:
        (N,) distances in m (inf where there is nothing).
    """
    params = repulsion.RepulsiveFieldParameters(half_sizes=footprint)
    circles, boxes = planar_shapes(scene, height)
    radii = [person.radius for person in scene.people]
    outline = (np.concatenate([_box_outline(b) for b in boxes])
               if len(boxes) else np.zeros((0, 2)))
    result = np.full(len(base_pose), np.inf)
    for i, (x, y, yaw) in enumerate(base_pose):
        c, s = np.cos(yaw), np.sin(yaw)
        to_base = np.array([[c, -s], [s, c]])  # rows: world -> T_b, as p @ R

        def in_base(points, x=x, y=y, to_base=to_base):
            return (np.reshape(points, (-1, 2)) - [x, y]) @ to_base

        centres, r = [circles[:, :2]], [circles[:, 2]]
        if people_positions is not None and radii:
            centres.append(np.reshape(people_positions[i], (-1, 2)))
            r.append(np.asarray(radii))
        centres, r = np.concatenate(centres), np.concatenate(r)
        candidates = []
        if len(centres):
            d, _ = repulsion.footprint_distance(in_base(centres), params)
            candidates.append(np.min(d - r))
        if len(outline):
            d, _ = repulsion.footprint_distance(in_base(outline), params)
            candidates.append(np.min(d))
        if candidates:
            result[i] = max(min(candidates), 0.0)
    return result


def static_distances(scenario, log):
    """(N,) the distance from the base's footprint to the nearest static
    obstacle (cylinder or box) at each sample of `log` (a RunLog of
    `scenario`), from ground truth; inf without any (obstacle_distances
    of the scene without its people)."""
    return obstacle_distances(replace(scenario.scene, people=[]),
                              log["truth.base_pose"], footprint_of(scenario))


def person_distances(scenario, log):
    """(N,) the distance from the base's footprint to the nearest person
    at each sample of `log` (a RunLog of `scenario`), from ground truth;
    inf without people (obstacle_distances of the scene's people
    alone)."""
    return obstacle_distances(replace(scenario.scene, cylinders=[], boxes=[]),
                              log["truth.base_pose"], footprint_of(scenario),
                              log.signals.get("truth.people_positions"))


def path_length(points):
    """The length of the path through `points` (N, k), point after point:
    the sum of the distances between consecutive ones (0 for one)."""
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))


def run_metrics(scenario, log):
    """The metrics every run reports (see the module's docstring)."""
    arm = controller_arm(scenario)  # the run's robot
    q = log["arm.position_measured"]
    margin = np.minimum(q - arm.lower, arm.upper - q)
    command = log["arm.position_command"]
    dt = np.diff(log.time)[:, None]
    arm_speed = np.abs(np.diff(command, axis=0)) / dt
    people = log.signals.get("truth.people_positions")
    distance = obstacle_distances(scenario.scene, log["truth.base_pose"],
                                  footprint_of(scenario), people)
    finite = all(np.all(np.isfinite(v)) for v in log.signals.values())
    return {
        "duration_s": float(log.time[-1]),
        "real_time_factor": float(log.real_time_factor),
        "all_finite": bool(finite),
        "min_capability": float(np.min(log["capability"])),
        "min_obstacle_distance_m": float(np.min(distance)),
        "max_base_speed_command_m_s": float(np.max(np.linalg.norm(
            log["base.velocity_command"][:, :2], axis=1))),
        "max_base_yaw_rate_command_rad_s": float(np.max(np.abs(
            log["base.velocity_command"][:, 2]))),
        "max_arm_joint_speed_command_rad_s": float(np.max(arm_speed)),
        "min_joint_limit_margin_rad": float(np.min(margin)),
        **_safety_counts(log),
        # What the simulated station said of its arm (a log of the
        # robot's streams does not know).
        **({} if log.arm_fault is None else {"arm_fault": log.arm_fault}),
    }


def _safety_counts(log):
    """Safe stops (trips) and the time the controller's limits acted on the
    commands, from the controller's diagnostics (none in an older log)."""
    counts = {}
    if "safety_status" in log:
        trips = log["safety_status"][:, STATUS_FIELDS.index("trips")]
        counts["safety_trips"] = int(np.max(trips))
    dt = sample_period(log)
    for name, key in (("base_saturation", "base_saturated_s"),
                      ("arm_limited", "arm_limited_s")):
        if name in log:
            counts[key] = dt * int(np.count_nonzero(log[name][:, 0] > 0.5))
    return counts


def metrics_of_each_run(scenario, logs, metrics_of_run):
    """`metrics_of_run(scenario, log)` of the single run, or of every run
    with its keys prefixed `<run>.`."""
    if len(logs) == 1:
        return metrics_of_run(scenario, next(iter(logs.values())))
    return {f"{name}.{key}": value for name, log in logs.items()
            for key, value in metrics_of_run(scenario, log).items()}


def compute_metrics(scenario, logs):
    """The `generic` experiment: no metrics beyond run_metrics."""
    return {}


def draw_figures(scenario, logs, folder):
    """The `generic` experiment's figure: an overview of each run."""
    import matplotlib.pyplot as plt

    paths = []
    for name, log in logs.items():
        fig, axes = new_figure(4, title=f"{scenario.description} ({name})")
        axes[0].plot(log.time, log["truth.end_effector_velocity"][:, :3])
        axes[0].set_ylabel("$V_{ee}$ (m/s)")
        axes[0].legend(["x", "y", "z"], loc="upper right")
        axes[1].plot(log.time, log["base.velocity_command"])
        axes[1].set_ylabel("$V_b^{ref}$")
        axes[1].legend(["vx", "vy", "wz"], loc="upper right")
        axes[2].plot(log.time, log["capability"][:, 0])
        axes[2].set_ylabel("$C_m$")
        axes[3].plot(log.time, obstacle_distances(
            scenario.scene, log["truth.base_pose"], footprint_of(scenario),
            log.signals.get("truth.people_positions")))
        axes[3].set_ylabel("obstacle (m)")
        paths.append(save_figure(fig, folder, f"overview_{name}"))
        plt.close(fig)
    return paths


def new_figure(rows, title=None, width=8.0, row_height=1.8):
    """A figure of `rows` stacked axes sharing time (s) on x."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(rows, 1, sharex=True, squeeze=False,
                             figsize=(width, 0.8 + row_height * rows))
    axes = axes[:, 0]
    for axis in axes:
        axis.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    if title:
        fig.suptitle(title, fontsize=10)
    return fig, axes


def save_figure(fig, folder, name):
    """Saves `fig` as folder/name.png and returns the path."""
    path = Path(folder) / f"{name}.png"
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path

"""Repeating a taught movement: the learned DMP played by the normal
controller (drake_wbc.math.movement, cdmp.MovementReplay), against the
demonstration it was learned from.

Each run plays its variant's movement (or the controller's). Replay and
demonstration are compared on the TCP's pose from the measured joints and
the base's odometry (demonstration.tcp_poses, as the demonstration was
recorded), time aligned through the phase: replay time since start_time
over the movement's duration at the replay's tau, against the
demonstration's normalised time. Metrics per run, `<run>.<metric>` when
there are several runs:

- path_rms_m: RMS over the demonstration's samples of the TCP's position
  error, replay against demonstration (meaningful for the demonstrated
  goal); path_yaw_rms_rad the same for yaw.
- goal_error_m, goal_yaw_error_rad: the TCP at the end of the run
  against the run's goal.
- velocity_correlation: the correlation coefficient of the TCP's speed
  profiles (|v| of x, y, z), replay against demonstration, time aligned:
  1 for the same shape.
- min_obstacle_distance_m: the least distance from the base's footprint
  to any obstacle (inf without one); d_th_m the repulsion's threshold.
- tau, duration_s: the replay's temporal scaling and length.

A run cut short (`--duration`) is compared over the demonstration's
samples it covers, those up to its end: the path's RMS and the velocity
correlation over them (NaN without any, the correlation NaN with fewer
than MIN_CORRELATED_SAMPLES), the goal errors NaN when the run ends
before the movement does (`short_run_note`).

Figures (`repeat_<run>.png`): the TCP's and the base's paths in the
plane (demonstration, replay, goals, obstacles) and x, y, z and yaw
against normalised time.
"""

import numpy as np

from drake_wbc.experiments.common import (
    new_figure,
    obstacle_distances,
    save_figure,
)
from drake_wbc.experiments.scenario import controller_arm, footprint_of
from drake_wbc.math import movement as mv
from drake_wbc.math.demonstration import tcp_poses

SPEED_FILTER_HZ = 2.0
"""Hz: the speed profiles are low-passed (zero phase) at this before
they are correlated, so that sensor noise does not count as shape."""

MIN_CORRELATED_SAMPLES = 10
"""The fewest of the demonstration's samples a run must cover for its
velocity_correlation (fewer: NaN): the zero-phase filter (second order)
pads 9 samples at each end of a profile."""


def replay_of(scenario, variant_name):
    """The cdmp.MovementReplay that the run `variant_name` plays."""
    for variant in scenario.variants:
        if variant.name == variant_name and variant.movement is not None:
            return variant.movement
    replay = scenario.controller.whole_body_cdmp.movement
    if replay is None:
        raise ValueError(
            f"run {variant_name!r} plays no movement: give the run's or the "
            "controller's whole_body_cdmp.movement")
    return replay


def movement_end(scenario, variant_name):
    """s: when the movement of the run `variant_name` ends (its start
    time and its duration at its tau)."""
    replay = replay_of(scenario, variant_name)
    movement = mv.LearnedMovement.load(mv.resolve_movement_file(replay.file))
    tau = movement.params.tau if replay.tau is None else replay.tau
    return replay.start_time + movement.params.with_tau(tau).duration


def short_run_note(scenario):
    """Why some of the metrics of `scenario` (its duration perhaps cut by
    `drake-wbc run --duration` or `drake-wbc replay --duration`) cover
    part of the movement or will be NaN, in a sentence; None where every
    run lasts past its movement's end."""
    ends = {variant.name: movement_end(scenario, variant.name)
            for variant in scenario.variants}
    name = max(ends, key=ends.get)
    end, duration = ends[name], scenario.duration
    if duration >= end:
        return None
    start = replay_of(scenario, name).start_time
    runs = "the run" if len(ends) == 1 else f"the run {name!r}"
    if duration <= start:
        covered = (f"before its movement starts at {start:g} s: the "
                   "movement's metrics will be nan")
    else:
        covered = ("before its movement does: path_rms_m, "
                   "path_yaw_rms_rad and velocity_correlation are over "
                   f"the {duration - start:.3g} s played, goal_error_m "
                   "and goal_yaw_error_rad will be nan")
    return (f"{runs} ends at {duration:g} s, {covered} (give a --duration "
            f"of at least {end:g} s)")


def replay_comparison(scenario, name, log):
    """(movement, player, u, demo, replayed, target, tcp): the
    demonstration and the replay (the run's TCP poses, sampled at the
    demonstration's normalised times u; NaN at those after the log's
    end, which the run did not reach), the run's absolute goal target
    (4,) and the run's TCP poses (N, 4) at the log's times."""
    replay = replay_of(scenario, name)
    movement = mv.LearnedMovement.load(mv.resolve_movement_file(replay.file))
    player = mv.MovementPlayer(movement, replay)
    demo = movement.demonstrations[0]
    u = (demo.time - demo.time[0]) / demo.duration
    tcp = tcp_poses(log["base.state_estimated"][:, :3],
                    log["arm.position_measured"],
                    controller_arm(scenario))
    # The same turn of the yaw as the demonstration's.
    tcp[:, 3] += 2 * np.pi * np.round((demo.tcp[0, 3] - tcp[0, 3])
                                      / (2 * np.pi))
    t = player.start_time + u * player.params.duration
    replayed = np.column_stack([np.interp(t, log.time, tcp[:, i],
                                          left=np.nan, right=np.nan)
                                for i in range(4)])
    start = movement.start if replay.start is None else np.asarray(
        replay.start)
    target = start + player.goal[list(mv.LEARNED_TWIST_INDICES)]
    return movement, player, u, demo, replayed, target, tcp


def speed_profile(time, positions):
    """|v| (N,) of `positions` (N, 3) at `time` (N,) in s: differences
    (np.gradient), low-passed at SPEED_FILTER_HZ (zero phase, second
    order) where the samples resolve it."""
    from scipy.signal import butter, sosfiltfilt

    v = np.gradient(positions, time, axis=0)
    fs = 1.0 / np.median(np.diff(time))
    if fs > 2.5 * SPEED_FILTER_HZ:
        sos = butter(2, SPEED_FILTER_HZ, fs=fs, output="sos")
        v = sosfiltfilt(sos, v, axis=0)
    return np.linalg.norm(v, axis=1)


def velocity_correlation(u, demonstrated, replayed, demonstration_duration,
                         replay_duration):
    """The correlation coefficient of the TCP's speed profiles (module
    docstring), each on its own clock: the samples at normalised times u
    (N,) of the demonstration's (N, 3) and the replay's (N, 3) positions,
    lasting `demonstration_duration` and `replay_duration` s (the filter
    is at SPEED_FILTER_HZ of time, not of normalised time)."""
    return float(np.corrcoef(
        speed_profile(u * replay_duration, replayed),
        speed_profile(u * demonstration_duration, demonstrated))[0, 1])


def run_metrics(scenario, name, log):
    """The metrics of the module's docstring for one run: over the
    demonstration's samples that the run covers, the goal errors NaN
    when it ends before the movement does."""
    movement, player, u, demo, replayed, target, tcp = replay_comparison(
        scenario, name, log)
    covered = ~np.isnan(replayed[:, 0])
    error = (replayed - demo.tcp)[covered]
    ended = covered[-1]
    nan = float("nan")
    people = log.signals.get("truth.people_positions")
    distance = obstacle_distances(scenario.scene, log["truth.base_pose"],
                                  footprint_of(scenario), people)
    return {
        "path_rms_m": float(np.sqrt(np.mean(np.sum(error[:, :3]**2,
                                                   axis=1))))
        if len(error) else nan,
        "path_yaw_rms_rad": float(np.sqrt(np.mean(error[:, 3]**2)))
        if len(error) else nan,
        "goal_error_m": float(np.linalg.norm(tcp[-1, :3] - target[:3]))
        if ended else nan,
        "goal_yaw_error_rad": float(abs(tcp[-1, 3] - target[3]))
        if ended else nan,
        "velocity_correlation": velocity_correlation(
            u[covered], demo.tcp[covered, :3], replayed[covered, :3],
            demo.duration, player.params.duration)
        if covered.sum() >= MIN_CORRELATED_SAMPLES else nan,
        "min_obstacle_distance_m": float(np.min(distance)),
        "d_th_m": float(scenario.controller.base_cdmp.repulsion.d_th),
        "tau": float(player.params.tau),
        "duration_s": float(player.params.duration),
    }


def compute_metrics(scenario, logs):
    """The metrics of the module's docstring, of each run."""
    metrics = {}
    for name, log in logs.items():
        prefix = "" if len(logs) == 1 else f"{name}."
        metrics.update({prefix + k: v for k, v in run_metrics(
            scenario, name, log).items()})
    return metrics


def draw_figures(scenario, logs, folder):
    """`repeat_<run>.png` of each run (module docstring)."""
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    paths = []
    for name, log in logs.items():
        movement, player, u, demo, replayed, target, tcp = \
            replay_comparison(scenario, name, log)
        fig, axes = new_figure(4, title=f"repeat: demonstration against "
                               f"replay ({name})")
        fig.set_size_inches(11.0, 8.0)
        for axis in axes:
            axis.remove()
        grid = fig.add_gridspec(4, 2)
        plane = fig.add_subplot(grid[:, 0])
        plane.plot(demo.tcp[:, 0], demo.tcp[:, 1], "C0", label="TCP, "
                   "demonstration")
        plane.plot(tcp[:, 0], tcp[:, 1], "C1--", label="TCP, replay")
        if demo.base is not None:
            plane.plot(demo.base[:, 0], demo.base[:, 1], "C2",
                       label="base, demonstration")
        base = log["base.state_estimated"]
        plane.plot(base[:, 0], base[:, 1], "C3--", label="base, replay")
        plane.plot(*movement.goal[:2], "k*", markersize=10,
                   label="demonstrated goal")
        plane.plot(*target[:2], "r+", markersize=12, label="goal")
        for c in scenario.scene.cylinders:
            plane.add_patch(Circle(c.position, c.radius, color="0.5"))
        plane.set_aspect("equal")
        plane.grid(True, alpha=0.3)
        plane.set_xlabel("x (m)")
        plane.set_ylabel("y (m)")
        plane.legend(fontsize=7, loc="best")
        times = (log.time - player.start_time) / player.params.duration
        for i, label in enumerate(("x (m)", "y (m)", "z (m)", "yaw (rad)")):
            axis = fig.add_subplot(grid[i, 1])
            axis.plot(u, demo.tcp[:, i], "C0", label="demonstration")
            axis.plot(times, tcp[:, i], "C1--", label="replay")
            axis.axhline(target[i], color="r", lw=0.6)
            axis.set_ylabel(label)
            axis.grid(True, alpha=0.3)
        axis.set_xlabel("normalised time (replay: from start_time, over "
                        "the duration at its tau)")
        axis.legend(fontsize=7, loc="lower right")
        paths.append(save_figure(fig, folder, f"repeat_{name}"))
        plt.close(fig)
    return paths

"""Experiment 1, trajectory tracking (paper Sec. V-B, Fig. "traj_opt").

A step of the end effector's velocity along x of T_b, shared equally by
base and arm (sigma_xy = 0.5), run with the base filter of eq. (filtering)
and without it. The end effector's true velocity error, e = V_ee - V_ee^ref
along x (the motion-capture measurement of the paper), is split into two
bands:

- the base's band, BASE_BAND, below the mount's rocking mode: where the
  base's slow velocity loop shows. Without the filter the base's lag goes
  uncompensated; with it the arm makes up V_b - V_b^flt (eq.
  (compensation)) and the base receives a command it can follow.
- the mount's band, MOUNT_BAND, around its 5 Hz rocking mode: ringing of
  the flexible structure after the step.

The metrics are the RMS of e in each band while the step lasts, and the
ratio without / with filter (> 1: the filter reduces it).
"""

import numpy as np

from drake_wbc.experiments.common import (
    band_rms,
    new_figure,
    save_figure,
    window,
)

BASE_BAND = (0.6, 3.0)
"""Hz: above the filter's 1 Hz cut-off and below the mount's mode."""

MOUNT_BAND = (3.0, 8.0)
"""Hz: around the mount's 5 Hz rocking mode."""


SETTLING = 0.1
"""s after the step before its peak error counts (the step itself is an
error of 0.1 m/s at the first sample)."""


def step_window(scenario):
    """(start, end) of the reference's step along x, s."""
    schedule = scenario.task.reference_velocity
    times = list(schedule.times) + [scenario.duration]
    for i, value in enumerate(schedule.values):
        if value[0] != 0.0:
            return times[i], min(times[i + 1], scenario.duration)
    raise ValueError("task.reference_velocity has no step along x, which "
                     "the trajectory-tracking experiment needs")


def velocity_error(log):
    """e = V_ee - V_ee^ref along x (world = T_b here), true velocities."""
    return (log["truth.end_effector_velocity"][:, 0]
            - log["reference_velocity"][:, 0])


def compute_metrics(scenario, logs):
    """Per run, the RMS of e in each band while the step lasts, the peak
    of |e| from SETTLING after the step on, and the mount's largest
    rocking; then the ratios of the run
    without the filter to the run with it (when both exist)."""
    start, end = step_window(scenario)
    metrics = {"step_start_s": start, "step_end_s": end}
    for name, log in logs.items():
        mask = window(log, start, end)
        error = velocity_error(log)
        mount = log["truth.mount_angles"]
        metrics[f"{name}.error_rms_base_band_m_s"] = band_rms(
            log.time, error, BASE_BAND, mask)
        metrics[f"{name}.oscillation_rms_mount_band_m_s"] = band_rms(
            log.time, error, MOUNT_BAND, mask)
        settled = window(log, start + SETTLING, end)
        metrics[f"{name}.peak_error_after_step_m_s"] = float(np.max(np.abs(
            error[settled])))
        metrics[f"{name}.mount_rocking_peak_rad"] = float(np.max(np.abs(
            mount[mask] - mount[mask][0])))
    if {"filtered", "unfiltered"} <= logs.keys():
        for key in ("error_rms_base_band_m_s",
                    "oscillation_rms_mount_band_m_s"):
            metrics[f"ratio_unfiltered_to_filtered.{key}"] = (
                metrics[f"unfiltered.{key}"] / metrics[f"filtered.{key}"])
    return metrics


def draw_figures(scenario, logs, folder):
    """Fig. "traj_opt": V_b^ref and the end effector's velocity of each
    run, and the error in the two bands."""
    import matplotlib.pyplot as plt

    start, end = step_window(scenario)
    fig, axes = new_figure(4, title="Trajectory tracking: a 0.1 m/s step "
                           "of the end effector along x of $T_b$")
    for name, log in logs.items():
        label = next((v.label or v.name for v in scenario.variants
                      if v.name == name), name)
        axes[0].plot(log.time, log["base.velocity_command"][:, 0],
                     label=label)
        axes[1].plot(log.time, log["truth.end_effector_velocity"][:, 0],
                     label=label)
        axes[2].plot(log.time, log["truth.end_effector_velocity"][:, 2],
                     label=label)
        axes[3].plot(log.time, velocity_error(log), label=label)
    first = next(iter(logs.values()))
    axes[1].plot(first.time, first["reference_velocity"][:, 0], "k--",
                 lw=0.8, label="$V_{ee}^{ref}$")
    axes[0].set_ylabel("$V_b^{ref}$ x (m/s)")
    axes[1].set_ylabel("$V_{ee}$ x (m/s)")
    axes[2].set_ylabel("$V_{ee}$ z (m/s)")
    axes[3].set_ylabel("error x (m/s)")
    for axis in axes:
        axis.axvspan(start, end, color="0.9", zorder=0)
        axis.legend(loc="upper right", fontsize=7)
    axes[-1].set_xlim(max(0.0, start - 0.5), min(scenario.duration,
                                                 end + 1.5))
    path = save_figure(fig, folder, "trajectory_tracking")
    plt.close(fig)
    return [path]

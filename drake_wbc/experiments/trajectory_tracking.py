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

- the shaking band, SHAKING_BAND, from below a ringing base's mode (3
  Hz in diagrams/trajectory_tracking_shaking.yaml) up past the
  suspension's and the mount's.

The metrics are the RMS of e in each band and in total while the step
lasts, and the ratio without / with filter (> 1: the filter reduces it);
each also after the paper's measurement processing (`measured_velocity`:
the tool's position sampled at 100 Hz, low-pass filtered at 40 rad/s,
velocity by differences), beside the ground truth.
"""

import numpy as np

from drake_wbc.experiments.common import (
    band_rms,
    new_figure,
    save_figure,
    window,
)
from drake_wbc.experiments.scenario import controller_for

BASE_BAND = (0.6, 3.0)
"""Hz: the base's response, from 0.6 Hz, below the base filter's 1 Hz
cut-off (the band holds it), to 3 Hz, below the mount's 5 Hz mode, where
MOUNT_BAND starts."""

MOUNT_BAND = (3.0, 8.0)
"""Hz: around the mount's 5 Hz rocking mode."""

SHAKING_BAND = (1.5, 8.0)
"""Hz: the modes of a shaking base (its velocity loop ringing at 3 Hz, a
suspension at 3 to 5 Hz) and of the mount."""

MEASUREMENT_RATE = 100.0
"""Hz: the paper's motion capture (OptiTrack) rate (Sec. V-B)."""

MEASUREMENT_CUTOFF = 40.0
"""rad/s: the paper's low-pass filter on the measured position."""


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


def short_run_note(scenario):
    """Why some of the metrics of `scenario` (its duration perhaps cut by
    `drake-wbc run --duration`) will be NaN, in a sentence; None where
    the run reaches far enough into the step for all of them."""
    start, _ = step_window(scenario)
    duration = scenario.duration
    if duration <= start:
        return (f"the run ends at {duration:g} s, before the step starts "
                f"at {start:g} s: the step's metrics and the ratios will "
                "be nan (give a --duration past it, e.g. "
                f"{start + 1.0:g} s)")
    if duration < start + SETTLING + scenario.outputs.log_period:
        return (f"the run ends {duration - start:.3g} s into the step, "
                f"before its peak error counts ({SETTLING:g} s after its "
                f"start at {start:g} s): peak_error_after_step_m_s will "
                "be nan")
    return None


def sweep_shortest(scenario):
    """s: the shortest duration of `scenario` whose ratios a sweep
    (drake_wbc.analysis.base_sweep) can take: past the step's start and
    its settling, by one log sample."""
    start, _ = step_window(scenario)
    return start + SETTLING + scenario.outputs.log_period


def velocity_error(log):
    """e = V_ee - V_ee^ref along x (world = T_b here), true velocities."""
    return (log["truth.end_effector_velocity"][:, 0]
            - log["reference_velocity"][:, 0])


def measured_velocity(time, position, rate=MEASUREMENT_RATE,
                      cutoff=MEASUREMENT_CUTOFF):
    """The paper's measurement of the end effector's velocity (Sec. V-B):
    `position` (N,) at `time` (N,) sampled at `rate`, low-pass filtered
    at `cutoff` rad/s (first order, its exact discrete step:
    y_k = y_(k-1) + (1 - e^(-cutoff h)) (p_k - y_(k-1)), h = 1 / rate),
    and the velocity by differences, (y_k - y_(k-1)) / h.

    Returns:
        (t, v): the samples' times and the velocities (the first zero).
    """
    time, position = np.asarray(time, float), np.asarray(position, float)
    h = 1.0 / rate
    t = np.arange(time[0], time[-1] + 0.5 * h, h)
    p = np.interp(t, time, position)
    gain = 1.0 - np.exp(-cutoff * h)
    y = np.empty_like(p)
    y[0] = p[0]
    for k in range(1, len(p)):
        y[k] = y[k - 1] + gain * (p[k] - y[k - 1])
    v = np.zeros_like(y)
    v[1:] = np.diff(y) / h
    return t, v


def measured_error(log):
    """e along x after the paper's processing (`measured_velocity`), on
    the log's samples."""
    t, v = measured_velocity(log.time, log["truth.end_effector_pose"][:, 0])
    return np.interp(log.time, t, v) - log["reference_velocity"][:, 0]


RATIO_KEYS = ("error_rms_base_band_m_s", "oscillation_rms_mount_band_m_s",
              "oscillation_rms_shaking_band_m_s", "error_rms_total_m_s")
"""The metrics whose ratio without / with filter a run reports, in the
ground truth and after the paper's processing (`measured.` before the
key)."""


def error_metrics(time, error, mask):
    """The RMS of the error (N,) in each band and in total over `mask`,
    by RATIO_KEYS; NaN where `mask` holds no sample (a run that ends
    before the step)."""
    if not np.any(mask):
        return dict.fromkeys(RATIO_KEYS, np.nan)
    return dict(zip(RATIO_KEYS, (
        band_rms(time, error, BASE_BAND, mask),
        band_rms(time, error, MOUNT_BAND, mask),
        band_rms(time, error, SHAKING_BAND, mask),
        float(np.sqrt(np.mean(error[mask] ** 2)))), strict=True))


def compute_metrics(scenario, logs):
    """Per run, the RMS of e in each band and in total while the step
    lasts (in the ground truth and after the paper's processing), the
    peak of |e| from SETTLING after the step on, and the mount's largest
    rocking; then the ratios of the run without the filter to the run
    with it (when both exist). A metric whose window the run does not
    reach (`drake-wbc run --duration` shorter than the step's start) is
    NaN."""
    start, end = step_window(scenario)
    metrics = {"step_start_s": start, "step_end_s": end}
    for name, log in logs.items():
        mask = window(log, start, end)
        error = velocity_error(log)
        # A robot without a flexible mount logs no mount angles.
        mount = log.signals.get("truth.mount_angles")
        for key, value in error_metrics(log.time, error, mask).items():
            metrics[f"{name}.{key}"] = value
        for key, value in error_metrics(log.time, measured_error(log),
                                        mask).items():
            metrics[f"{name}.measured.{key}"] = value
        settled = window(log, start + SETTLING, end)
        metrics[f"{name}.peak_error_after_step_m_s"] = (
            float(np.max(np.abs(error[settled]))) if np.any(settled)
            else np.nan)
        if mount is not None and mount.size:
            metrics[f"{name}.mount_rocking_peak_rad"] = (
                float(np.max(np.abs(mount[mask] - mount[mask][0])))
                if np.any(mask) else np.nan)
    if {"filtered", "unfiltered"} <= logs.keys():
        for key in (*RATIO_KEYS, *(f"measured.{k}" for k in RATIO_KEYS)):
            metrics[f"ratio_unfiltered_to_filtered.{key}"] = (
                metrics[f"unfiltered.{key}"] / metrics[f"filtered.{key}"])
    return metrics


def draw_figures(scenario, logs, folder):
    """Fig. "traj_opt": V_b^ref and the end effector's velocity of each
    run (ground truth and after the paper's processing), its z velocity
    and the error."""
    import matplotlib.pyplot as plt

    start, end = step_window(scenario)
    limit = controller_for(scenario).safety.base_acceleration_limits[0]
    fig, axes = new_figure(5, title=(
        "Trajectory tracking: a 0.1 m/s step of the end effector along x "
        "of $T_b$\n($V_b^{ref}$ without the filter is ramped by the "
        f"controller's safety limit, {limit:g} m/s$^2$)"))
    for name, log in logs.items():
        label = next((v.label or v.name for v in scenario.variants
                      if v.name == name), name)
        axes[0].plot(log.time, log["base.velocity_command"][:, 0],
                     label=label)
        axes[1].plot(log.time, log["truth.end_effector_velocity"][:, 0],
                     label=label)
        t, v = measured_velocity(log.time,
                                 log["truth.end_effector_pose"][:, 0])
        axes[2].plot(t, v, label=label)
        axes[3].plot(log.time, log["truth.end_effector_velocity"][:, 2],
                     label=label)
        axes[4].plot(log.time, velocity_error(log), label=label)
    first = next(iter(logs.values()))
    for axis in axes[1:3]:
        axis.plot(first.time, first["reference_velocity"][:, 0], "k--",
                  lw=0.8, label="$V_{ee}^{ref}$")
    axes[0].set_ylabel("$V_b^{ref}$ x (m/s)")
    axes[1].set_ylabel("$V_{ee}$ x (m/s)\ntrue")
    axes[2].set_ylabel("$V_{ee}$ x (m/s)\nmeasured")
    axes[2].set_title(
        f"measured as the paper: position at {MEASUREMENT_RATE:g} Hz, "
        f"low-pass {MEASUREMENT_CUTOFF:g} rad/s, differences", fontsize=8)
    axes[3].set_ylabel("$V_{ee}$ z (m/s)")
    axes[4].set_ylabel("error x (m/s)")
    for axis in axes:
        axis.axvspan(start, end, color="0.9", zorder=0)
        axis.legend(loc="upper right", fontsize=7)
    left, right = max(0.0, start - 0.5), min(scenario.duration, end + 1.5)
    # A run that ends before the step (--duration) is shown whole.
    axes[-1].set_xlim(left if left < right else 0.0, right)
    path = save_figure(fig, folder, "trajectory_tracking")
    plt.close(fig)
    return [path]
